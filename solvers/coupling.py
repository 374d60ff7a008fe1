"""Rigid–MPM coupling: which rigid collision shapes the MPM grid meets, as the MPM solver's
colliders (mpm/colliders.py: Genesis's LegacyCoupler rule, rigid side).

Coupled today: the primitive shapes (plane, sphere, capsule, cylinder, box) of links fixed to the
world — a chain of fixed joints up to it — of entities whose material couples (Genesis's
``needs_coup``), where the shape collides (a contype or conaffinity; not a morph's collision=False).
Left out, and said so by the scene: shapes on moving links (the particles would need the rigid
velocity and would push back: not yet), and meshes and height fields (Genesis couples them through
SDF grids: not yet).
"""
from dataclasses import dataclass

import numpy as np

from .mpm import colliders
from .rigid import geometry
from .rigid.model import FIXED
from .rigid.shapes import quat_to_mat

COLLIDER_KIND = {geometry.PLANE: colliders.PLANE, geometry.SPHERE: colliders.SPHERE,
                 geometry.CAPSULE: colliders.CAPSULE, geometry.CYLINDER: colliders.CYLINDER,
                 geometry.BOX: colliders.BOX}
KIND_NAME = {code: name for name, code in geometry.GEOM_CODE.items()}


@dataclass(frozen=True)
class Coupling:
    """A rigid entity's coupling parameters (its material's): friction μ, softness ς (m) and
    restitution e of mpm/colliders.py."""
    friction: float
    softness: float
    restitution: float


def _world_fixed_poses(model):
    """{link: (pos (3,) m, rotation (3, 3))} of the links fixed to the world (parents first)."""
    poses = {}
    for link, parent in enumerate(model.link_parent):
        if model.link_jtype[link] != FIXED or (parent >= 0 and parent not in poses):
            continue
        pos, rot = (np.zeros(3), np.eye(3)) if parent < 0 else poses[parent]
        poses[link] = (pos + rot @ model.link_pos0[link], rot @ quat_to_mat(model.link_quat0[link]))
    return poses


def static_colliders(model, couplings):
    """The MPM collider rows (C, colliders.WIDTH) of the rigid model's coupled shapes, and the
    left-out ones as (link, geom type name, why) triples. couplings: per rigid entity (the
    model's link_entity numbers), a Coupling or None (the entity does not couple)."""
    poses, rows, left_out = _world_fixed_poses(model), [], []
    for g, (kind, link) in enumerate(zip(model.geom_type, model.geom_link)):
        coupling = couplings[model.link_entity[link]]
        if coupling is None or not model.geom_collides[g]:
            continue
        if link not in poses:
            left_out.append((int(link), KIND_NAME[int(kind)], "on a moving link"))
            continue
        if int(kind) not in COLLIDER_KIND:
            left_out.append((int(link), KIND_NAME[int(kind)], "not a primitive shape"))
            continue
        pos, rot = poses[link]
        rows.append([COLLIDER_KIND[int(kind)], *(pos + rot @ model.geom_pos[g]),
                     *(rot @ quat_to_mat(model.geom_quat[g])).ravel(), *model.geom_size[g],
                     coupling.friction, coupling.softness, coupling.restitution])
    return np.array(rows, dtype=np.float64).reshape(-1, colliders.WIDTH), left_out
