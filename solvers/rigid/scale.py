"""Growing a robot by a factor (``URDF(scale=s)``, ``MJCF(scale=s)``), as Genesis's morph ``scale``.

The scaled robot is geometrically similar to the file's, of the same densities: every length
times s (joint frames, centres of mass, collision and visual shapes, meshes, a prismatic joint's
limits, start and spring reference, the anchors of connects and welds), every mass times s³, every
inertia times s⁵. What is not a length, mass or inertia stays the file's, as in Genesis: joint
damping, stiffness, friction loss, effort limits, friction, the softness of constraint rows; so do
a URDF's servo gains, while an MJCF actuator's gains take s³ (Genesis's MJCF loader: its gain and
bias times s³). So, with no damping, servos, springs, armature, limits met, contacts or equality rows
(the softness of constraint rows, time constants and solimp widths, is the scene's, not scaled), the
scaled robot under the same gravity moves as the file's at √s its pace: q_s(t) = q(t / √s) for
angles, s · q(t / √s) for lengths (tests/test_morph_scale.py checks exactly that).

A relation between joints keeps its meaning in the scaled coordinates (lengths × s): a mimic's
offset takes s_f and its multiplier s_f / s_d (s for a length coordinate, 1 for an angle; f the
follower, d the followed), as Genesis's; a fixed tendon's length Σ coef · q keeps its unit, a
length when all its joints slide (its range × s), else that of its hinges (its slide joints'
coefficients ÷ s).
"""
from dataclasses import replace

import numpy as np

from .spec import LinkSpec, ShapeSpec

# joint types whose coordinate is a length (m), scaled; the others' are angles
_LENGTH_JOINTS = ("prismatic",)


def scaled_links(links: list[LinkSpec], s: float, gains: float = 1.0) -> list[LinkSpec]:
    """``links`` grown by the factor ``s`` > 0 (module docstring); servo gains kp and kv that the
    file states (not None) times ``gains`` (1 for a URDF, s³ for an MJCF's actuators: Genesis's
    loaders). A new list; ``links`` is left as it is."""
    joint_scale = {link.joint_name: s if link.joint_type in _LENGTH_JOINTS else 1.0 for link in links}
    return [_scaled_link(link, s, gains, joint_scale) for link in links]


def _scaled_link(link: LinkSpec, s: float, gains: float, joint_scale: dict) -> LinkSpec:
    length = s if link.joint_type in _LENGTH_JOINTS else 1.0  # the scale of the joint's coordinate
    mimic = link.mimic
    if mimic is not None:
        followed, multiplier, offset = mimic
        mimic = (followed, multiplier * length / joint_scale.get(followed, 1.0), offset * length)
    return replace(link, pos=link.pos * s, com=link.com * s, mass=link.mass * s ** 3, inertia=link.inertia * s ** 5,
                   lower=link.lower * length, upper=link.upper * length, q0=link.q0 * length,
                   springref=link.springref * length, mimic=mimic,
                   kp=None if link.kp is None else link.kp * gains, kv=None if link.kv is None else link.kv * gains,
                   geoms=[_scaled_shape(geom, s) for geom in link.geoms],
                   visuals=[_scaled_shape(visual, s) for visual in link.visuals],
                   tendons=tuple(_scaled_tendon(tendon, s, joint_scale) for tendon in link.tendons),
                   connects=tuple(_scaled_anchors(connect, s) for connect in link.connects),
                   welds=tuple(_scaled_anchors(weld, s) for weld in link.welds))


def _scaled_shape(shape: ShapeSpec, s: float) -> ShapeSpec:
    """A copy of the collision or visual shape grown by s about its link's frame (a plane's size
    is its normal: unchanged)."""
    size = shape.size if shape.type == "plane" else np.asarray(shape.size, dtype=np.float64) * s
    vertices = None if shape.vertices is None else np.asarray(shape.vertices, dtype=np.float64) * s
    return replace(shape, pos=np.asarray(shape.pos, dtype=np.float64) * s, size=size, vertices=vertices)


def _scaled_tendon(tendon, s, joint_scale):
    """A fixed tendon (joints, coefficients, lower, upper, softness, equality, spring, friction) in
    the scaled coordinates (its spring's stiffness and damping and its friction loss the file's, as
    a joint's)."""
    joints, coefs, lower, upper, softness, equality, spring, friction = tendon
    scales = np.array([joint_scale[joint] for joint in joints])
    if np.all(scales == s):  # a length: its range, held length and spring's rest grow
        return (joints, tuple(coefs), lower * s, upper * s, softness, equality and (equality[0] * s, equality[1]),
                spring and (*spring[:2], spring[2] * s, spring[3] * s), friction)
    return (joints, tuple(float(c) for c in np.asarray(coefs, dtype=np.float64) / scales), lower, upper, softness,
            equality, spring, friction)


def _scaled_anchors(constraint, s):
    """A connect or weld (other link, anchor, other's anchor, ...) with its anchors (m; None: where
    the other's is at q0) grown by s."""
    other, anchor, other_anchor, *rest = constraint
    return (other, None if anchor is None else np.asarray(anchor, dtype=np.float64) * s,
            None if other_anchor is None else np.asarray(other_anchor, dtype=np.float64) * s, *rest)
