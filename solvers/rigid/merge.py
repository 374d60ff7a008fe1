"""Merging links attached by fixed joints into their parent (``URDF(merge_fixed_links=True)``).

A link welded to its parent moves with it, so the two are one rigid body: merging them changes
no physics (the merged mass, com and inertia are exact) and leaves fewer links to simulate.
Genesis and MuJoCo (``fusestatic``) merge the same links.
"""
from dataclasses import replace

import numpy as np

from ..core import InvalidInputError
from .shapes import compose, quat_to_mat
from .spec import LinkSpec, ShapeSpec


def merge_fixed_links(links: list[LinkSpec], links_to_keep=(), owner: str = "merge_fixed_links") -> list[LinkSpec]:
    """``links`` (tree order) with every link attached by a fixed joint merged into its parent.

    Deepest links first, as Genesis: a merged child C's contents are re-expressed in its
    parent P's frame (C's frame in P is its joint frame T): C's collision geoms and visuals move
    to P, C's children are re-parented to P with their joint frames composed with T, and P's mass,
    com and inertia become those of the two bodies together (parallel-axis theorem). The merged link
    keeps P's name and joint; ``P.merged`` records C's name and its fixed joint's name.
    A massless part adds nothing, not even its inertia, as the model drops the inertia of
    massless links (MuJoCo does the same); nor does a part weighed from its shapes (a URDF link
    without <inertial>) merged with one whose mass the file states, as in Genesis (_merge_into).

    Never merged: the root (links[0]) and the links named in ``links_to_keep`` (their own fixed
    children are still merged into them). The remaining links keep their relative order, so a
    re-parented child takes its merged parent's place among its new siblings (MuJoCo's order;
    Genesis re-sorts siblings by link declaration order) and parent < child still holds.

    links: list[LinkSpec] in tree order (parent < index); not modified (specs are copied).
    links_to_keep: iterable of link names; a name that is no link raises InvalidInputError.
    owner: who is asking, for error messages (e.g. "entity 'robot': gs.morphs.URDF").
    Returns a new list[LinkSpec] in tree order.
    """
    keep = _names_to_keep(links, links_to_keep, owner)
    links = [_copy(spec) for spec in links]
    alive = [True] * len(links)
    for k in reversed(range(1, len(links))):  # children before their parents: deepest first
        child = links[k]
        if child.joint_type != "fixed" or child.name in keep:
            continue
        _merge_into(links[child.parent], child)
        for j in range(k + 1, len(links)):
            if alive[j] and links[j].parent == k:
                _reparent(links[j], child)
        alive[k] = False
    index = np.cumsum(alive) - 1  # old index → new index of the surviving links
    out = [spec for spec, a in zip(links, alive) if a]
    for spec in out:
        spec.parent = int(index[spec.parent]) if spec.parent >= 0 else -1
    return out


def merged_into(links: list[LinkSpec], name: str) -> str | None:
    """The name of the link that ``name`` was merged into, or None if no link absorbed it."""
    for spec in links:
        if any(merged == name for merged, _ in spec.merged):
            return spec.name
    return None


def _names_to_keep(links, links_to_keep, owner):
    keep = set(links_to_keep)
    unknown = sorted(keep - {spec.name for spec in links})
    if unknown:
        raise InvalidInputError(f"{owner}: argument 'links_to_keep' expected names of links of the file, "
                                f"got unknown names {unknown} (links: {[spec.name for spec in links]})")
    return keep


def _copy(spec: LinkSpec) -> LinkSpec:
    """A copy whose fields may be reassigned without touching ``spec`` (geoms and visuals are
    copied on move)."""
    return replace(spec, geoms=list(spec.geoms), visuals=list(spec.visuals), merged=list(spec.merged))


def _merge_into(parent: LinkSpec, child: LinkSpec) -> None:
    """Add ``child`` (welded to ``parent`` at its joint frame) to ``parent``, in place. Masses as
    Genesis's merge_inertia: where one of the two states its mass and the other was weighed from
    its shapes (LinkSpec.mass_stated), the stated one's alone (the shapes move, their weight
    does not), unless the stated one is massless (Genesis weighs a moving link of mass 0 from its
    shapes again); else both together."""
    rot = quat_to_mat(child.quat)
    placed = (child.mass, child.pos + rot @ child.com, rot @ child.inertia @ rot.T)
    if child.mass_stated and not parent.mass_stated and child.mass > 0:
        parent.mass, parent.com, parent.inertia = placed
        parent.mass_stated = True
    elif child.mass_stated == parent.mass_stated:
        parent.mass, parent.com, parent.inertia = combine_inertia((parent.mass, parent.com, parent.inertia), placed)
    parent.geoms = parent.geoms + [_moved(geom, child.pos, child.quat) for geom in child.geoms]
    parent.visuals = parent.visuals + [_moved(visual, child.pos, child.quat) for visual in child.visuals]
    parent.merged = parent.merged + [(child.name, child.joint_name)] + child.merged


def combine_inertia(a, b):
    """(mass kg, com (3,) m, inertia (3, 3) kg·m² about that com) of two bodies (each such a
    triple, in the same frame and axes) held together. A massless body counts for nothing."""
    parts = [p for p in (a, b) if p[0] > 0]
    if not parts:
        return 0.0, np.asarray(a[1], dtype=np.float64), np.zeros((3, 3))
    mass = sum(m for m, _, _ in parts)
    com = sum(m * np.asarray(c) for m, c, _ in parts) / mass
    inertia = np.zeros((3, 3))
    for m, c, i in parts:
        d = np.asarray(c) - com
        inertia += i + m * (d @ d * np.eye(3) - np.outer(d, d))  # parallel-axis theorem
    return float(mass), com, 0.5 * (inertia + inertia.T)


def _reparent(spec: LinkSpec, removed: LinkSpec) -> None:
    """``spec`` was a child of ``removed``: attach it to ``removed``'s parent, same world pose."""
    spec.parent = removed.parent
    spec.pos, spec.quat = compose(removed.pos, removed.quat, spec.pos, spec.quat)


def _moved(geom: ShapeSpec, pos, quat) -> ShapeSpec:
    """A copy of ``geom`` (a collision geom or a visual) placed in the frame in which (pos, quat)
    is the pose of its old frame."""
    new_pos, new_quat = compose(pos, quat, geom.pos, geom.quat)
    return replace(geom, pos=new_pos, quat=new_quat)
