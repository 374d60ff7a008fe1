"""Growing a robot by a factor (``URDF(scale=s)``), as Genesis's morph ``scale`` does.

The scaled robot is geometrically similar to the file's, of the same densities: every length
times s (joint frames, centres of mass, collision and visual shapes, meshes, a prismatic joint's
limits and start), every mass times s³, every inertia times s⁵. What is not a length, mass or
inertia stays the file's, as in Genesis: joint damping, friction loss, effort limits, servo gains,
friction. So, with no damping, servos, springs, armature, limits met or contacts, the scaled
robot under the same gravity moves as the file's at √s its pace: q_s(t) = q(t / √s) for angles,
s · q(t / √s) for lengths (tests/test_urdf_scale.py checks exactly that).
"""
from dataclasses import replace

import numpy as np

from .spec import LinkSpec, ShapeSpec

# joint types whose coordinate is a length (m), scaled; the others' are angles
_LENGTH_JOINTS = ("prismatic",)


def scaled_links(links: list[LinkSpec], s: float) -> list[LinkSpec]:
    """``links`` grown by the factor ``s`` > 0 (module docstring); a new list, ``links`` is left
    as it is. A mimic (q = multiplier · q_other + offset) keeps its meaning in the scaled
    coordinates: its offset times s where the follower's coordinate is a length, its multiplier
    times s_follower / s_followed (s for a length, 1 for an angle), as Genesis's. For a URDF's links:
    they hold no tendons, connects or welds (MJCF's), which this does not scale."""
    assert not any(link.tendons or link.connects or link.welds for link in links), "MJCF constraints are not scaled"
    joint_types = {link.joint_name: link.joint_type for link in links}
    return [_scaled_link(link, s, joint_types) for link in links]


def _scaled_link(link: LinkSpec, s: float, joint_types: dict) -> LinkSpec:
    length = s if link.joint_type in _LENGTH_JOINTS else 1.0  # the scale of the joint's coordinate
    mimic = link.mimic
    if mimic is not None:
        followed, multiplier, offset = mimic
        followed_scale = s if joint_types.get(followed) in _LENGTH_JOINTS else 1.0
        mimic = (followed, multiplier * length / followed_scale, offset * length)
    return replace(link, pos=link.pos * s, com=link.com * s, mass=link.mass * s ** 3, inertia=link.inertia * s ** 5,
                   lower=link.lower * length, upper=link.upper * length, q0=link.q0 * length,
                   springref=link.springref * length, mimic=mimic,
                   geoms=[_scaled_shape(geom, s) for geom in link.geoms],
                   visuals=[_scaled_shape(visual, s) for visual in link.visuals])


def _scaled_shape(shape: ShapeSpec, s: float) -> ShapeSpec:
    """A copy of the collision or visual shape grown by s about its link's frame (a plane's size
    is its normal: unchanged)."""
    size = shape.size if shape.type == "plane" else np.asarray(shape.size, dtype=np.float64) * s
    vertices = None if shape.vertices is None else np.asarray(shape.vertices, dtype=np.float64) * s
    return replace(shape, pos=np.asarray(shape.pos, dtype=np.float64) * s, size=size, vertices=vertices)
