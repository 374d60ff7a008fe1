"""Primitive colliders: plane, sphere, capsule and cylinder pairs, and plane–box.

MuJoCo's mjc_PlaneSphere, mjc_PlaneCapsule, mjc_PlaneCylinder, mjc_PlaneBox, mjc_SphereSphere,
mjc_SphereCapsule, mjc_SphereCylinder and mjc_CapsuleCapsule (engine_collision_primitive.c;
capsule–capsule as MuJoCo 4.0 does it, which is not that file: see its section), reproduced
contact for contact: same count, order, positions, normals and distances, to the bit in float64
(outside RigidOptions' enable_mujoco_compatibility a cylinder standing on a plane touches it at four
rim points instead: STANDING, detect._plane_cylinder).

Every collider has the signature and return described in the package docstring (``collision/__init__.py``)::

    count, position, normal, dist, feature = plane_box(pos1, rot1, size1, pos2, rot2, size2, margin)

with K (the ``*_MAX`` constant) rows; geom 1 has the lower MuJoCo type, the normal points from
geom 1 to geom 2. ``margin`` is what MuJoCo hands its colliders: the pair's margin plus its gap.
A contact is emitted when its distance is <= margin (MuJoCo's test, boundary included).

Each collider is a *decide* (which discrete features give contacts, in MuJoCo's order) and an
*evaluate* (one contact as a closed form of the two poses with its feature frozen); the
collider is decide followed by evaluate per row, so the backward can differentiate evaluate.
The features are documented at each collider.

Each evaluate has its hand-written reverse right after it (issue 11's backward)::

    g_pos1, g_rot1, g_pos2, g_rot2 = plane_box_evaluate_adjoint(pos1, rot1, size1, pos2, rot2, size2, feature,
                                                                g_position, g_normal, g_dist)

the gradients of g_position·position + g_normal·normal + g_dist·dist with respect to the
positions (3,) and to the rotations' 9 entries taken as independent numbers (3, 3), exactly as
evaluate's float formula uses them, feature frozen; sizes get none. Intermediates are
recomputed, nothing is stored. Where a frozen feature sits on a kink (coincident sphere centres)
the adjoint takes the symmetric subgradient 0, as documented at _sphere_sphere_evaluate_adjoint.

Contact frame: every collider here passes MuJoCo a zero first tangent except plane–capsule,
which passes the capsule axis (column 2 of rot2); build the frame with
``frame.contact_frame(normal[k], tangent)``.
"""
import numpy as np
import taichi as ti
from taichi.lang import impl

from ..spatial import dot3, mat_vec
from .convex import RIM_TILT, STANDING_TILT
from .frame import (AT_MINUS, AT_PLUS, FREE, MINVAL, collider, column, column_adjoint, cross3, cross3_adjoint,
                    normalize3, normalize3_adjoint, segment_weight_states, segment_weight_terms,
                    segment_weight_terms_adjoint, segment_weights, segment_weights_adjoint)

PLANE_SPHERE_MAX = 1
PLANE_CAPSULE_MAX = 2
PLANE_CYLINDER_MAX = 4
PLANE_BOX_MAX = 4
SPHERE_SPHERE_MAX = 1
SPHERE_CAPSULE_MAX = 1
SPHERE_CYLINDER_MAX = 1
CAPSULE_CAPSULE_MAX = 2


# ---------------------------------------------------------------- two building blocks
#
# MuJoCo builds most primitive pairs from a point-versus-plane test and a sphere-versus-sphere
# test on derived points (a capsule's end, the nearest point of a segment, a cylinder's rim).

@ti.func
def _plane_point_evaluate(plane_pos, plane_normal, centre, radius):
    """Contact of a sphere (centre, radius) with a plane (a point on it, unit normal).

    Returns (position, normal, dist): dist = height of the centre above the plane - radius,
    position halfway between the plane and the sphere's lowest point, normal = plane_normal.
    """
    dist = dot3(centre - plane_pos, plane_normal) - radius
    position = centre + plane_normal * (-dist / 2 - radius)
    return position, plane_normal, dist


@ti.func
def _plane_point_evaluate_adjoint(plane_pos, plane_normal, centre, radius, g_position, g_normal, g_dist):
    """Reverse of _plane_point_evaluate: (g_plane_pos, g_plane_normal, g_centre) (3,) each."""
    _, _, dist = _plane_point_evaluate(plane_pos, plane_normal, centre, radius)
    g_dist_all = g_dist - 0.5 * dot3(g_position, plane_normal)
    g_plane_normal = g_normal + g_position * (-dist / 2 - radius) + (centre - plane_pos) * g_dist_all
    return -plane_normal * g_dist_all, g_plane_normal, g_position + plane_normal * g_dist_all


@ti.func
def _plane_point_hit(plane_pos, plane_normal, centre, radius, margin):
    """Whether MuJoCo's plane–sphere test emits a contact (height <= margin + radius)."""
    return dot3(centre - plane_pos, plane_normal) <= margin + radius


# Sphere–sphere normal cases (the `ss` feature of every collider built on sphere–sphere)
CENTRES_APART = 0       # normal = unit (c2 - c1)
CENTRES_COINCIDE = 1    # |c2 - c1| < MINVAL: normal = unit (z1 × z2), the geoms' z axes
AXES_ALIGNED = 2        # ... and |z1 × z2| < MINVAL too: normal = world x


@ti.func
def _sphere_sphere_decide(c1, r1, c2, r2, z1, z2, margin):
    """(hit, ss) of MuJoCo's sphere–sphere test on centres c1, c2 and radii r1, r2.

    hit: |c1 - c2| <= margin + r1 + r2 (compared squared, as MuJoCo). ss: the normal case.
    """
    dif = c1 - c2
    reach = margin + r1 + r2
    hit = dot3(dif, dif) <= reach * reach
    _, gap = normalize3(c2 - c1)
    ss = CENTRES_APART
    if gap < MINVAL:
        _, axes_sine = normalize3(cross3(z1, z2))
        ss = CENTRES_COINCIDE if axes_sine >= MINVAL else AXES_ALIGNED
    return hit, ss


@ti.func
def _sphere_sphere_evaluate(c1, r1, c2, r2, z1, z2, ss):
    """Contact (position, normal, dist) of two spheres with the normal case ss frozen.

    dist = |c2 - c1| - r1 - r2; position = c1 + normal (r1 + dist/2), halfway between the
    surfaces. z1, z2 (the geoms' z axes) orient the normal only when the centres coincide.
    """
    dif = c1 - c2
    dist = ti.sqrt(dot3(dif, dif)) - r1 - r2
    normal, _ = normalize3(c2 - c1)
    if ss == CENTRES_COINCIDE:
        normal, _ = normalize3(cross3(z1, z2))
    elif ss == AXES_ALIGNED:
        normal = ti.Vector([1.0, 0.0, 0.0])
    position = normal * (r1 + dist / 2) + c1
    return position, normal, dist


@ti.func
def _sphere_sphere_evaluate_adjoint(c1, r1, c2, r2, z1, z2, ss, g_position, g_normal, g_dist):
    """Reverse of _sphere_sphere_evaluate: (g_c1, g_c2, g_z1, g_z2) (3,) each.

    With the centres coinciding (|c2 - c1| < MINVAL) dist passes no gradient: |c2 - c1| has a kink
    at 0, whose symmetric subgradient is 0 (normalize3_adjoint); the normal is unit(z1 × z2)
    (CENTRES_COINCIDE) or a constant (AXES_ALIGNED).
    """
    _, normal, dist = _sphere_sphere_evaluate(c1, r1, c2, r2, z1, z2, ss)
    g_normal_all = g_normal + g_position * (r1 + dist / 2)
    g_gap = g_dist + 0.5 * dot3(g_position, normal)  # dist = |c2 - c1| - r1 - r2
    g_unit = ti.Vector.zero(float, 3)
    g_z1 = ti.Vector.zero(float, 3)
    g_z2 = ti.Vector.zero(float, 3)
    if ss == CENTRES_APART:
        g_unit = g_normal_all
    elif ss == CENTRES_COINCIDE:
        g_z1, g_z2 = cross3_adjoint(z1, z2, normalize3_adjoint(cross3(z1, z2), g_normal_all, 0.0))
    g_c2 = normalize3_adjoint(c2 - c1, g_unit, g_gap)
    return g_position - g_c2, g_c2, g_z1, g_z2


# ---------------------------------------------------------------- plane – sphere
# feature: always 0 (one contact: the sphere's lowest point).

@ti.func
def plane_sphere_decide(pos1, rot1, size1, pos2, rot2, size2, margin):
    """(count, feature (1,)) of plane (geom 1, normal = its z axis) – sphere (radius size2[0])."""
    count = 0
    if _plane_point_hit(pos1, column(rot1, 2), pos2, size2[0], margin):
        count = 1
    return count, ti.Vector.zero(ti.i32, PLANE_SPHERE_MAX)


@ti.func
def plane_sphere_evaluate(pos1, rot1, size1, pos2, rot2, size2, feature):
    """(position, normal, dist) of the plane–sphere contact."""
    return _plane_point_evaluate(pos1, column(rot1, 2), pos2, size2[0])


@ti.func
def plane_sphere_evaluate_adjoint(pos1, rot1, size1, pos2, rot2, size2, feature, g_position, g_normal, g_dist):
    """Reverse of plane_sphere_evaluate: (g_pos1 (3,), g_rot1 (3, 3), g_pos2 (3,), g_rot2 (3, 3))."""
    g_pos1, g_n, g_pos2 = _plane_point_evaluate_adjoint(pos1, column(rot1, 2), pos2, size2[0], g_position, g_normal,
                                                        g_dist)
    return g_pos1, column_adjoint(g_n, 2), g_pos2, ti.Matrix.zero(float, 3, 3)


plane_sphere = collider(plane_sphere_decide, plane_sphere_evaluate, PLANE_SPHERE_MAX,
                         "Plane – sphere (mjc_PlaneSphere): at most 1 contact.")


# ---------------------------------------------------------------- plane – capsule
# feature: which end of the capsule's segment: 0 the +z end (pos2 + h z2), 1 the -z end.
# Each end is tested as a sphere of the capsule's radius, +z end first.

@ti.func
def _capsule_end(pos, rot, size, end):
    """End `end` (0: +z, 1: -z) of a capsule's segment (world, m); size = (radius, half-length)."""
    segment = column(rot, 2) * size[1]
    point = pos + segment
    if end == 1:
        point = pos - segment
    return point


@ti.func
def plane_capsule_decide(pos1, rot1, size1, pos2, rot2, size2, margin):
    """(count, feature (2,)) of plane – capsule: the ends within margin, +z end first."""
    feature = ti.Vector.zero(ti.i32, PLANE_CAPSULE_MAX)
    count = 0
    for end in ti.static(range(2)):
        if _plane_point_hit(pos1, column(rot1, 2), _capsule_end(pos2, rot2, size2, end), size2[0], margin):
            feature[count] = end
            count += 1
    return count, feature


@ti.func
def plane_capsule_evaluate(pos1, rot1, size1, pos2, rot2, size2, feature):
    """(position, normal, dist) of the plane – capsule-end contact `feature`."""
    return _plane_point_evaluate(pos1, column(rot1, 2), _capsule_end(pos2, rot2, size2, feature), size2[0])


@ti.func
def plane_capsule_evaluate_adjoint(pos1, rot1, size1, pos2, rot2, size2, feature, g_position, g_normal, g_dist):
    """Reverse of plane_capsule_evaluate: (g_pos1 (3,), g_rot1 (3, 3), g_pos2 (3,), g_rot2 (3, 3))."""
    g_pos1, g_n, g_end = _plane_point_evaluate_adjoint(pos1, column(rot1, 2), _capsule_end(pos2, rot2, size2, feature),
                                                       size2[0], g_position, g_normal, g_dist)
    end_sign = ti.select(feature == 1, -1.0, 1.0)  # end = pos2 ± z2 h
    return g_pos1, column_adjoint(g_n, 2), g_end, column_adjoint(g_end * (end_sign * size2[1]), 2)


plane_capsule = collider(plane_capsule_decide, plane_capsule_evaluate, PLANE_CAPSULE_MAX,
                          "Plane – capsule (mjc_PlaneCapsule): at most 2 contacts; "
                          "MuJoCo's first tangent is the capsule axis.")


# ---------------------------------------------------------------- plane – cylinder
# feature = point + 4 flipped + 8 flat.
#   flipped: the cylinder axis a is replaced by -a so that it points towards the plane (n·a > 0).
#   flat: the disks are parallel to the plane (|a (n·a) - n|² < _flat_across2()), so the rim direction
#         is the cylinder's x axis instead of the plane normal's component across the axis.
#   point: NEAR_RIM the lowest rim point of the disk nearer the plane; FAR_RIM the same rim
#          direction on the other disk; SIDE_A / SIDE_B the two other corners of an equilateral
#          triangle inscribed in the near disk (±60° either side of the opposite direction).
# MuJoCo emits nothing unless NEAR_RIM is within margin; then FAR_RIM if within margin, then
# SIDE_A and SIDE_B together if their (common) distance is within margin.
NEAR_RIM, FAR_RIM, SIDE_A, SIDE_B = 0, 1, 2, 3


def _single_precision():
    """True when the kernels compute in float32 (decided at compile time)."""
    return impl.get_runtime().default_fp == ti.f32


# |a (n·a) - n|² below which the disks count as flat (at compile time). float64: MuJoCo's MINVAL².
# float32: (1e-5)². There a unit axis is off unit by ~1e-7 (a quaternion turned 45° about z
# gives R[2, 2] = 0.99999994), which puts an across of that size along the axis: with MINVAL² an
# upright can's "rim" was its axis, rim points 0.4 m above or below the disk, and a can standing
# on the floor fell through it. Flat below 1e-5 rad, the triangle's points lie at most r 1e-5 / 2
# above the lowest rim point; above it, the across is made perpendicular to the axis before it
# is normalised (float32 only), so that the ~1e-7 along the axis cannot tilt the rim out of its disk.
def _flat_across2():
    return 1e-10 if _single_precision() else MINVAL * MINVAL


@ti.func
def _plane_cylinder_terms(pos1, rot1, pos2, rot2, size2, flipped, flat):
    """Shared plane–cylinder quantities for frozen (flipped, flat).

    Returns n (plane normal), axis_h (axis towards the plane times half-length), rim (radius
    vector in the near disk towards the plane), dist0 (height of the cylinder centre), axis_drop
    = (n·a) h and rim_drop = n·rim (heights of the disk centre and rim point relative to it).
    """
    n = column(rot1, 2)
    axis = column(rot2, 2)
    along = dot3(n, axis)
    if flipped:
        axis = -axis
        along = -along
    dist0 = dot3(pos2 - pos1, n)
    rim = _across(axis, along, n)
    if flat:
        rim = column(rot2, 0) * size2[0]
    else:
        rim = rim * (size2[0] / ti.sqrt(dot3(rim, rim)))
    return n, axis * size2[1], rim, dist0, along * size2[1], dot3(rim, n)


@ti.func
def _across(axis, along, n):
    """The plane normal's component across the cylinder axis, negated: a (n·a) - n (3,); in float32
    made perpendicular to the axis (_flat_across2)."""
    across = axis * along - n
    if ti.static(_single_precision()):
        across -= axis * dot3(axis, across)
    return across


@ti.func
def _plane_cylinder_terms_adjoint(pos1, rot1, pos2, rot2, size2, flipped, flat, g_n, g_axis_h, g_rim, g_dist0,
                                  g_axis_drop, g_rim_drop):
    """Reverse of _plane_cylinder_terms: (g_pos1 (3,), g_rot1 (3, 3), g_pos2 (3,), g_rot2 (3, 3)) given
    the gradients of its six outputs (n, axis_h, rim (3,); dist0, axis_drop, rim_drop)."""
    n, _, rim, _, _, _ = _plane_cylinder_terms(pos1, rot1, pos2, rot2, size2, flipped, flat)
    sign = ti.select(flipped != 0, -1.0, 1.0)
    axis = column(rot2, 2) * sign
    along = dot3(n, axis)
    g_rim_all = g_rim + n * g_rim_drop
    g_n_all = g_n + rim * g_rim_drop + (pos2 - pos1) * g_dist0
    g_axis = g_axis_h * size2[1]
    g_along = g_axis_drop * size2[1]
    g_rot2 = ti.Matrix.zero(float, 3, 3)
    if flat:
        g_rot2 = column_adjoint(g_rim_all * size2[0], 0)
    else:  # rim = R unit(across), across = axis along - n (float32: projected off the axis)
        raw = axis * along - n
        g_across = normalize3_adjoint(_across(axis, along, n), g_rim_all * size2[0], 0.0)
        if ti.static(_single_precision()):  # across = raw - axis (axis·raw)
            g_axis -= g_across * dot3(axis, raw) + raw * dot3(axis, g_across)
            g_across -= axis * dot3(axis, g_across)
        g_axis += g_across * along
        g_along += dot3(g_across, axis)
        g_n_all -= g_across
    g_n_all += axis * g_along
    g_axis += n * g_along
    g_rot2 += column_adjoint(g_axis * sign, 2)
    return -n * g_dist0, column_adjoint(g_n_all, 2), n * g_dist0, g_rot2


@ti.func
def plane_cylinder_decide(pos1, rot1, size1, pos2, rot2, size2, margin):
    """(count, feature (4,)) of plane – cylinder (size2 = radius, half-length)."""
    n = column(rot1, 2)
    axis = column(rot2, 2)
    along = dot3(n, axis)
    across = axis * along - n
    flipped = 1 if along > 0 else 0
    flat = 1 if dot3(across, across) < ti.static(_flat_across2()) else 0
    _, _, _, dist0, axis_drop, rim_drop = _plane_cylinder_terms(pos1, rot1, pos2, rot2, size2, flipped, flat)
    base = 4 * flipped + 8 * flat
    feature = ti.Vector.zero(ti.i32, PLANE_CYLINDER_MAX)
    count = 0
    if dist0 + axis_drop + rim_drop <= margin:
        feature[0] = base + NEAR_RIM
        count = 1
        if dist0 - axis_drop + rim_drop <= margin:
            feature[count] = base + FAR_RIM
            count += 1
        if dist0 + axis_drop + (-rim_drop * 0.5) <= margin:
            feature[count] = base + SIDE_A
            feature[count + 1] = base + SIDE_B
            count += 2
    return count, feature


@ti.func
def plane_cylinder_evaluate(pos1, rot1, size1, pos2, rot2, size2, feature):
    """(position, normal, dist) of the plane – cylinder contact `feature`."""
    point = feature % 4
    n = column(rot1, 2)
    dist = 0.0
    position = ti.Vector.zero(float, 3)
    if feature >= STANDING:
        rim_point = _standing_point(rot1, pos2, rot2, size2, (feature // 4) % 2, point)
        dist = dot3(rim_point - pos1, n)
        position = rim_point + n * (-dist * 0.5)
    else:
        position, dist = _mujoco_point(pos1, rot1, pos2, rot2, size2, feature)
    return position, n, dist


@ti.func
def _mujoco_point(pos1, rot1, pos2, rot2, size2, feature):
    """(position, dist) of one of MuJoCo's plane – cylinder points (features below STANDING)."""
    point = feature % 4
    n, axis_h, rim, dist0, axis_drop, rim_drop = _plane_cylinder_terms(
        pos1, rot1, pos2, rot2, size2, (feature // 4) % 2, (feature // 8) % 2)
    dist = 0.0
    position = ti.Vector.zero(float, 3)
    if point == NEAR_RIM:
        dist = dist0 + axis_drop + rim_drop
        position = pos2 + rim + axis_h + n * (-dist * 0.5)
    elif point == FAR_RIM:
        dist = dist0 - axis_drop + rim_drop
        position = pos2 + rim - axis_h + n * (-dist * 0.5)
    else:
        dist = dist0 + axis_drop + (-rim_drop * 0.5)
        sideways, _ = normalize3(cross3(rim, axis_h))
        sideways = sideways * (size2[0] * ti.sqrt(3.0) / 2)
        if point == SIDE_B:
            sideways = -sideways
        position = pos2 + sideways + axis_h + rim * (-0.5) + n * (-dist * 0.5)
    return position, dist


@ti.func
def plane_cylinder_evaluate_adjoint(pos1, rot1, size1, pos2, rot2, size2, feature, g_position, g_normal, g_dist):
    """Reverse of plane_cylinder_evaluate: (g_pos1 (3,), g_rot1 (3, 3), g_pos2 (3,), g_rot2 (3, 3)).

    Every point is position = pos2 + rim_w rim + axis_w axis_h (+ sideways) - n dist / 2 with
    dist = dist0 + axis_w axis_drop + rim_w rim_drop: axis_w = -1 for FAR_RIM, rim_w = -1/2 for
    the triangle's sides, else 1.
    """
    point = feature % 4
    _, _, dist = plane_cylinder_evaluate(pos1, rot1, size1, pos2, rot2, size2, feature)
    g_pos1, g_rot1, g_pos2, g_rot2 = ti.Vector.zero(float, 3), ti.Matrix.zero(float, 3, 3), \
        ti.Vector.zero(float, 3), ti.Matrix.zero(float, 3, 3)
    if feature >= STANDING:
        g_pos1, g_rot1, g_pos2, g_rot2 = _standing_adjoint(pos1, rot1, pos2, rot2, size2, (feature // 4) % 2, point,
                                                           dist, g_position, g_normal, g_dist)
    else:
        g_pos1, g_rot1, g_pos2, g_rot2 = _mujoco_points_adjoint(pos1, rot1, size1, pos2, rot2, size2, feature, dist,
                                                                g_position, g_normal, g_dist)
    return g_pos1, g_rot1, g_pos2, g_rot2


@ti.func
def _mujoco_points_adjoint(pos1, rot1, size1, pos2, rot2, size2, feature, dist, g_position, g_normal, g_dist):
    """plane_cylinder_evaluate_adjoint for MuJoCo's points (features below STANDING)."""
    point = feature % 4
    n, axis_h, rim, _, _, _ = _plane_cylinder_terms(pos1, rot1, pos2, rot2, size2, (feature // 4) % 2,
                                                    (feature // 8) % 2)
    axis_w = ti.select(point == FAR_RIM, -1.0, 1.0)
    rim_w = ti.select(point == SIDE_A or point == SIDE_B, -0.5, 1.0)
    g_dist_all = g_dist - 0.5 * dot3(g_position, n)
    g_axis_h = g_position * axis_w
    g_rim = g_position * rim_w
    if point == SIDE_A or point == SIDE_B:  # sideways = ±(R √3/2) unit(rim × axis_h)
        scale = ti.select(point == SIDE_B, -1.0, 1.0) * (size2[0] * ti.sqrt(3.0) / 2)
        g_rim_side, g_axis_side = cross3_adjoint(
            rim, axis_h, normalize3_adjoint(cross3(rim, axis_h), g_position * scale, 0.0))
        g_rim += g_rim_side
        g_axis_h += g_axis_side
    g_pos1, g_rot1, g_pos2, g_rot2 = _plane_cylinder_terms_adjoint(
        pos1, rot1, pos2, rot2, size2, (feature // 4) % 2, (feature // 8) % 2, g_normal + g_position * (-dist * 0.5),
        g_axis_h, g_rim, g_dist_all, g_dist_all * axis_w, g_dist_all * rim_w)
    return g_pos1, g_rot1, g_pos2 + g_position, g_rot2


plane_cylinder = collider(plane_cylinder_decide, plane_cylinder_evaluate, PLANE_CYLINDER_MAX,
                           "Plane – cylinder (mjc_PlaneCylinder): at most 4 contacts.")


# A cylinder standing on the plane (its axis within STANDING_TILT of the normal), outside
# enable_mujoco_compatibility: MuJoCo's points above (the lowest rim point and an inscribed
# triangle) turn with the direction of the tilt, which has no limit at zero tilt: the step map
# jumps there (a can exactly upright, tilted 1e-8 rad one way or the other: its pose 30 steps
# later 8e-4 apart) and its gradient grows as 1/tilt. As on a box's face (convex._face_cap), it
# touches at four points of the rim of its disk nearer the plane, where the plane's x and y
# axes, made perpendicular to the cylinder's axis, point (±u, ±v): feature STANDING + 4 flipped
# + k, k = 0..3 for +x, -x, +y, -y, each a contact when within the margin, a smooth closed form
# of the poses. Tilted more than RIM_TILT on its rim, MuJoCo's lowest rim point stays first with
# the deepest three.
STANDING = 16


@ti.func
def _standing_point(rot1, pos2, rot2, size2, flipped, k):
    """Rim point k (3,) of the near disk of a standing cylinder (see STANDING)."""
    axis = column(rot2, 2) * (1.0 - 2.0 * flipped)
    t = ti.select(k // 2 == 0, column(rot1, 0), column(rot1, 1)) * (1.0 - 2.0 * (k % 2))
    direction, _ = normalize3(t - axis * dot3(axis, t))
    return pos2 + axis * size2[1] + direction * size2[0]


@ti.func
def _standing_adjoint(pos1, rot1, pos2, rot2, size2, flipped, k, dist, g_position, g_normal, g_dist):
    """Reverse of a STANDING feature's evaluate: position = p - n dist / 2, dist = n·(p - pos1),
    p = pos2 + a h + r unit(t - a (a·t))."""
    n = column(rot1, 2)
    sign = 1.0 - 2.0 * flipped
    axis = column(rot2, 2) * sign
    t_sign = 1.0 - 2.0 * (k % 2)
    t = ti.select(k // 2 == 0, column(rot1, 0), column(rot1, 1)) * t_sign
    rim_point = _standing_point(rot1, pos2, rot2, size2, flipped, k)
    g_dist_all = g_dist - 0.5 * dot3(g_position, n)
    g_point = g_position + n * g_dist_all
    g_n = g_normal - g_position * (dist * 0.5) + (rim_point - pos1) * g_dist_all
    along = dot3(axis, t)
    g_raw = normalize3_adjoint(t - axis * along, g_point * size2[0], 0.0)
    g_t = g_raw - axis * dot3(axis, g_raw)
    g_axis = g_point * size2[1] - g_raw * along - t * dot3(axis, g_raw)
    g_rot1 = column_adjoint(g_n, 2)
    if k // 2 == 0:
        g_rot1 += column_adjoint(g_t * t_sign, 0)
    else:
        g_rot1 += column_adjoint(g_t * t_sign, 1)
    return -n * g_dist_all, g_rot1, g_point, column_adjoint(g_axis * sign, 2)


@ti.func
def plane_cylinder_standing_decide(pos1, rot1, size1, pos2, rot2, size2, margin):
    """(count, feature (4,)): MuJoCo's plane – cylinder features, or for a standing cylinder the
    four rim points within the margin (see STANDING), after MuJoCo's lowest rim point when it is
    tilted beyond RIM_TILT (then the deepest three)."""
    count, feature = plane_cylinder_decide(pos1, rot1, size1, pos2, rot2, size2, margin)
    n = column(rot1, 2)
    along = dot3(n, column(rot2, 2))
    if ti.abs(along) >= ti.static(np.cos(STANDING_TILT)):
        flipped = 1 if along > 0 else 0
        keep = 1 if count > 0 and ti.abs(along) <= ti.static(np.cos(RIM_TILT)) else 0
        dists = ti.Vector([dot3(_standing_point(rot1, pos2, rot2, size2, flipped, k) - pos1, n)
                           for k in ti.static(range(4))])
        within, shallowest, shallowest_dist = 0, 0, dists[0]
        for k in ti.static(range(4)):
            within += 1 if dists[k] <= margin else 0
            if dists[k] > shallowest_dist:
                shallowest, shallowest_dist = k, dists[k]
        shallowest = ti.select(keep == 1 and within == 4, shallowest, -1)  # (the budget: it gives way)
        rim_feature = feature[0]
        feature = ti.Vector.zero(ti.i32, PLANE_CYLINDER_MAX)
        feature[0] = rim_feature
        count = keep
        for k in ti.static(range(4)):
            if dists[k] <= margin and k != shallowest:
                feature[count] = STANDING + 4 * flipped + k
                count += 1
    return count, feature


plane_cylinder_standing = collider(plane_cylinder_standing_decide, plane_cylinder_evaluate, PLANE_CYLINDER_MAX,
                                   "Plane – cylinder, a standing cylinder on four rim points (STANDING): at most 4.")


# ---------------------------------------------------------------- plane – box
# feature: the corner index c in 0..7, corner = (±sx, ±sy, ±sz) in the box frame with bit 0, 1, 2
# of c set for +x, +y, +z. MuJoCo keeps the first four corners, in index order, that are within
# margin and on the plane's side of the box centre (n·(R v) <= 0).

@ti.func
def _box_corner_offset(rot, size, corner):
    """World offset from a box's centre to its corner `corner` (0..7), m."""
    local = ti.Vector([ti.select((corner & 1) != 0, size[0], -size[0]),
                       ti.select((corner & 2) != 0, size[1], -size[1]),
                       ti.select((corner & 4) != 0, size[2], -size[2])])
    return mat_vec(rot, local)


@ti.func
def plane_box_decide(pos1, rot1, size1, pos2, rot2, size2, margin):
    """(count, feature (4,)) of plane – box (size2 = half-extents)."""
    n = column(rot1, 2)
    centre_height = dot3(pos2 - pos1, n)
    feature = ti.Vector.zero(ti.i32, PLANE_BOX_MAX)
    count = 0
    for corner in range(8):
        drop = dot3(n, _box_corner_offset(rot2, size2, corner))
        if count < PLANE_BOX_MAX and centre_height + drop <= margin and drop <= 0:
            feature[count] = corner
            count += 1
    return count, feature


@ti.func
def plane_box_evaluate(pos1, rot1, size1, pos2, rot2, size2, feature):
    """(position, normal, dist) of the plane – box-corner contact `feature`."""
    n = column(rot1, 2)
    offset = _box_corner_offset(rot2, size2, feature)
    dist = dot3(pos2 - pos1, n) + dot3(n, offset)
    return offset + pos2 + n * (-dist / 2), n, dist


@ti.func
def plane_box_evaluate_adjoint(pos1, rot1, size1, pos2, rot2, size2, feature, g_position, g_normal, g_dist):
    """Reverse of plane_box_evaluate: (g_pos1 (3,), g_rot1 (3, 3), g_pos2 (3,), g_rot2 (3, 3))."""
    _, n, dist = plane_box_evaluate(pos1, rot1, size1, pos2, rot2, size2, feature)
    offset = _box_corner_offset(rot2, size2, feature)
    local = _box_corner_offset(ti.Matrix.identity(float, 3), size2, feature)
    g_dist_all = g_dist - 0.5 * dot3(g_position, n)
    g_offset = g_position + n * g_dist_all  # also pos2's gradient: offset and pos2 enter alike
    g_n = g_normal + g_position * (-dist / 2) + (pos2 - pos1 + offset) * g_dist_all
    return -n * g_dist_all, column_adjoint(g_n, 2), g_offset, g_offset.outer_product(local)


plane_box = collider(plane_box_decide, plane_box_evaluate, PLANE_BOX_MAX,
                      "Plane – box (mjc_PlaneBox): at most 4 contacts.")


# ---------------------------------------------------------------- sphere – sphere
# feature: the sphere–sphere normal case ss (CENTRES_APART, CENTRES_COINCIDE, AXES_ALIGNED).

@ti.func
def sphere_sphere_decide(pos1, rot1, size1, pos2, rot2, size2, margin):
    """(count, feature (1,)) of sphere – sphere."""
    hit, ss = _sphere_sphere_decide(pos1, size1[0], pos2, size2[0], column(rot1, 2), column(rot2, 2), margin)
    return ti.select(hit, 1, 0), ti.Vector([ss])


@ti.func
def sphere_sphere_evaluate(pos1, rot1, size1, pos2, rot2, size2, feature):
    """(position, normal, dist) of the sphere–sphere contact."""
    return _sphere_sphere_evaluate(pos1, size1[0], pos2, size2[0], column(rot1, 2), column(rot2, 2), feature)


@ti.func
def sphere_sphere_evaluate_adjoint(pos1, rot1, size1, pos2, rot2, size2, feature, g_position, g_normal, g_dist):
    """Reverse of sphere_sphere_evaluate: (g_pos1 (3,), g_rot1 (3, 3), g_pos2 (3,), g_rot2 (3, 3)).
    The rotations get a gradient only when the centres coincide (the normal is unit(z1 × z2))."""
    g_pos1, g_pos2, g_z1, g_z2 = _sphere_sphere_evaluate_adjoint(pos1, size1[0], pos2, size2[0], column(rot1, 2),
                                                                 column(rot2, 2), feature, g_position, g_normal,
                                                                 g_dist)
    return g_pos1, column_adjoint(g_z1, 2), g_pos2, column_adjoint(g_z2, 2)


sphere_sphere = collider(sphere_sphere_decide, sphere_sphere_evaluate, SPHERE_SPHERE_MAX,
                          "Sphere – sphere (mjc_SphereSphere): at most 1 contact.")


# ---------------------------------------------------------------- sphere – capsule
# feature = 3 clamp + ss. clamp: where the sphere centre's projection on the capsule segment
# lies: FREE inside, AT_PLUS clipped to the +z end, AT_MINUS to the -z end; the sphere is then
# tested against a sphere of the capsule's radius there; ss: its normal case.

@ti.func
def _capsule_nearest(pos1, pos2, rot2, size2, clamp):
    """Point of the capsule's segment nearest pos1 (its axial coordinate clipped per clamp)."""
    axis = column(rot2, 2)
    x = dot3(axis, pos1 - pos2)
    if clamp == AT_PLUS:
        x = size2[1]
    elif clamp == AT_MINUS:
        x = -size2[1]
    return axis * x + pos2


@ti.func
def _axial_adjoint(pos1, pos2, axis, g_x):
    """Reverse of x = axis·(pos1 - pos2): (g_pos1, g_pos2, g_axis) (3,) each."""
    return axis * g_x, -axis * g_x, (pos1 - pos2) * g_x


@ti.func
def _capsule_nearest_adjoint(pos1, pos2, rot2, size2, clamp, g_nearest):
    """Reverse of _capsule_nearest: (g_pos1, g_pos2, g_axis) (3,) each; a clamped x (±h) passes none."""
    axis = column(rot2, 2)
    x = dot3(axis, pos1 - pos2)
    g_x = dot3(g_nearest, axis)
    if clamp == AT_PLUS:
        x = size2[1]
        g_x = 0.0
    elif clamp == AT_MINUS:
        x = -size2[1]
        g_x = 0.0
    g_pos1, g_pos2, g_axis = _axial_adjoint(pos1, pos2, axis, g_x)
    return g_pos1, g_pos2 + g_nearest, g_axis + g_nearest * x


@ti.func
def sphere_capsule_decide(pos1, rot1, size1, pos2, rot2, size2, margin):
    """(count, feature (1,)) of sphere (geom 1) – capsule (geom 2)."""
    axis = column(rot2, 2)
    x = dot3(axis, pos1 - pos2)
    clamp = FREE
    if x < -size2[1]:
        clamp = AT_MINUS
    elif x > size2[1]:
        clamp = AT_PLUS
    hit, ss = _sphere_sphere_decide(pos1, size1[0], _capsule_nearest(pos1, pos2, rot2, size2, clamp), size2[0],
                                    column(rot1, 2), axis, margin)
    return ti.select(hit, 1, 0), ti.Vector([3 * clamp + ss])


@ti.func
def sphere_capsule_evaluate(pos1, rot1, size1, pos2, rot2, size2, feature):
    """(position, normal, dist) of the sphere – capsule contact `feature`."""
    nearest = _capsule_nearest(pos1, pos2, rot2, size2, feature // 3)
    return _sphere_sphere_evaluate(pos1, size1[0], nearest, size2[0], column(rot1, 2), column(rot2, 2),
                                   feature % 3)


@ti.func
def sphere_capsule_evaluate_adjoint(pos1, rot1, size1, pos2, rot2, size2, feature, g_position, g_normal, g_dist):
    """Reverse of sphere_capsule_evaluate: (g_pos1 (3,), g_rot1 (3, 3), g_pos2 (3,), g_rot2 (3, 3))."""
    nearest = _capsule_nearest(pos1, pos2, rot2, size2, feature // 3)
    g_pos1, g_nearest, g_z1, g_z2 = _sphere_sphere_evaluate_adjoint(
        pos1, size1[0], nearest, size2[0], column(rot1, 2), column(rot2, 2), feature % 3, g_position, g_normal,
        g_dist)
    g_pos1_near, g_pos2, g_axis = _capsule_nearest_adjoint(pos1, pos2, rot2, size2, feature // 3, g_nearest)
    return g_pos1 + g_pos1_near, column_adjoint(g_z1, 2), g_pos2, column_adjoint(g_z2 + g_axis, 2)


sphere_capsule = collider(sphere_capsule_decide, sphere_capsule_evaluate, SPHERE_CAPSULE_MAX,
                           "Sphere – capsule (mjc_SphereCapsule): at most 1 contact.")


# ---------------------------------------------------------------- sphere – cylinder
# feature = 3 kind + ss. kind: which part of the cylinder the sphere centre faces:
#   SIDE: level with the barrel (|x| < h): sphere–sphere with the axis point at the centre's
#         level and the cylinder's radius;
#   TOP_CAP / BOTTOM_CAP: over a disk (distance from the axis < radius): sphere against the cap's
#         plane (outward normal ±axis, normal then reversed to point sphere → cylinder);
#   TOP_RIM / BOTTOM_RIM: beyond both: sphere–sphere with the nearest rim point, radius 0.
# A centre inside the cylinder takes the nearer of side and cap (cap only when strictly nearer).
# ss: the sphere–sphere normal case (0 for caps).
SIDE, TOP_CAP, BOTTOM_CAP, TOP_RIM, BOTTOM_RIM = 0, 1, 2, 3, 4


@ti.func
def _cylinder_target(pos1, pos2, rot2, size2, kind):
    """The cylinder point the sphere centre pos1 is tested against, for a frozen kind.

    Returns (point, radius): SIDE: the axis point level with pos1 and the cylinder radius;
    caps: the cap's centre (radius unused, 0); rims: the rim point nearest pos1 and 0.
    """
    axis = column(rot2, 2)
    x = dot3(axis, pos1 - pos2)
    along = axis * x
    point = along + pos2
    radius = 0.0
    if kind == SIDE:
        radius = size2[0]
    else:
        end = axis * ti.select(kind == TOP_CAP or kind == TOP_RIM, size2[1], -size2[1])
        if kind == TOP_CAP or kind == BOTTOM_CAP:
            point = pos2 + end
        else:
            across = pos1 - pos2 - along
            point = end + across * (size2[0] / ti.sqrt(dot3(across, across))) + pos2
    return point, radius


@ti.func
def _cylinder_target_adjoint(pos1, pos2, rot2, size2, kind, g_point):
    """Reverse of _cylinder_target's point: (g_pos1, g_pos2, g_axis) (3,) each."""
    axis = column(rot2, 2)
    x = dot3(axis, pos1 - pos2)
    g_pos1 = ti.Vector.zero(float, 3)
    g_pos2 = g_point
    g_axis = ti.Vector.zero(float, 3)
    g_along = g_point  # SIDE: point = along + pos2
    if kind != SIDE:
        g_axis = g_point * ti.select(kind == TOP_CAP or kind == TOP_RIM, size2[1], -size2[1])
        g_along = ti.Vector.zero(float, 3)
        if kind == TOP_RIM or kind == BOTTOM_RIM:  # + R unit(across), across = pos1 - pos2 - along
            g_across = normalize3_adjoint(pos1 - pos2 - axis * x, g_point * size2[0], 0.0)
            g_pos1 = g_across
            g_pos2 -= g_across
            g_along = -g_across
    g_pos1_x, g_pos2_x, g_axis_x = _axial_adjoint(pos1, pos2, axis, dot3(g_along, axis))  # along = axis x
    return g_pos1 + g_pos1_x, g_pos2 + g_pos2_x, g_axis + g_along * x + g_axis_x


@ti.func
def _cap_normal(rot2, kind):
    """Outward normal of the cap of kind TOP_CAP (+axis) or BOTTOM_CAP (-axis)."""
    axis = column(rot2, 2)
    if kind == BOTTOM_CAP:
        axis = -axis
    return axis


@ti.func
def sphere_cylinder_decide(pos1, rot1, size1, pos2, rot2, size2, margin):
    """(count, feature (1,)) of sphere (geom 1) – cylinder (geom 2, size = radius, half-length)."""
    axis = column(rot2, 2)
    offset = pos1 - pos2
    x = dot3(axis, offset)
    across = offset - axis * x
    across_sqr = dot3(across, across)
    side = ti.abs(x) < size2[1]
    cap = across_sqr < size2[0] * size2[0]
    if side and cap:
        if size2[1] - ti.abs(x) < size2[0] - ti.sqrt(across_sqr):
            side = False
        else:
            cap = False
    kind = SIDE
    if not side:
        kind = ti.select(cap, TOP_CAP, TOP_RIM) + ti.select(x > 0, 0, 1)
    point, radius = _cylinder_target(pos1, pos2, rot2, size2, kind)
    hit = False
    ss = CENTRES_APART
    if cap:
        hit = _plane_point_hit(point, _cap_normal(rot2, kind), pos1, size1[0], margin)
    else:
        hit, ss = _sphere_sphere_decide(pos1, size1[0], point, radius, column(rot1, 2), axis, margin)
    return ti.select(hit, 1, 0), ti.Vector([3 * kind + ss])


@ti.func
def sphere_cylinder_evaluate(pos1, rot1, size1, pos2, rot2, size2, feature):
    """(position, normal, dist) of the sphere – cylinder contact `feature`."""
    kind = feature // 3
    point, radius = _cylinder_target(pos1, pos2, rot2, size2, kind)
    position = ti.Vector.zero(float, 3)
    normal = ti.Vector.zero(float, 3)
    dist = 0.0
    if kind == TOP_CAP or kind == BOTTOM_CAP:
        position, normal, dist = _plane_point_evaluate(point, _cap_normal(rot2, kind), pos1, size1[0])
        normal = -normal
    else:
        position, normal, dist = _sphere_sphere_evaluate(pos1, size1[0], point, radius, column(rot1, 2),
                                                         column(rot2, 2), feature % 3)
    return position, normal, dist


@ti.func
def sphere_cylinder_evaluate_adjoint(pos1, rot1, size1, pos2, rot2, size2, feature, g_position, g_normal, g_dist):
    """Reverse of sphere_cylinder_evaluate: (g_pos1 (3,), g_rot1 (3, 3), g_pos2 (3,), g_rot2 (3, 3))."""
    kind = feature // 3
    point, radius = _cylinder_target(pos1, pos2, rot2, size2, kind)
    g_pos1 = ti.Vector.zero(float, 3)
    g_point = ti.Vector.zero(float, 3)
    g_z1 = ti.Vector.zero(float, 3)
    g_axis = ti.Vector.zero(float, 3)
    if kind == TOP_CAP or kind == BOTTOM_CAP:  # the cap's plane test (normal ±axis), its normal reversed
        g_point, g_cap, g_pos1 = _plane_point_evaluate_adjoint(point, _cap_normal(rot2, kind), pos1, size1[0],
                                                               g_position, -g_normal, g_dist)
        g_axis = g_cap * ti.select(kind == BOTTOM_CAP, -1.0, 1.0)
    else:
        g_pos1, g_point, g_z1, g_axis = _sphere_sphere_evaluate_adjoint(
            pos1, size1[0], point, radius, column(rot1, 2), column(rot2, 2), feature % 3, g_position, g_normal,
            g_dist)
    g_pos1_target, g_pos2, g_axis_target = _cylinder_target_adjoint(pos1, pos2, rot2, size2, kind, g_point)
    return g_pos1 + g_pos1_target, column_adjoint(g_z1, 2), g_pos2, column_adjoint(g_axis + g_axis_target, 2)


sphere_cylinder = collider(sphere_cylinder_decide, sphere_cylinder_evaluate, SPHERE_CYLINDER_MAX,
                            "Sphere – cylinder (mjc_SphereCylinder): at most 1 contact.")


# ---------------------------------------------------------------- capsule – capsule
# MuJoCo 4.0's mjc_CapsuleCapsule (it differs from the C source of MuJoCo 3 copied in
# mujoco_src/, which clamps x in [-1, 1] and tries four end candidates when parallel): the
# segments run from the -z end to the +z end of each capsule, and frame.segment_weight_states
# gives one pair of weights (non-parallel) or two (parallel within about 1e-4 rad: from capsule
# 1's -z end, then from its +z end); each pair is tested as two spheres at those points.
# feature = 3 state + ss. state = 3 s_state + t_state: the weight states (frame.FREE / AT_START
# / AT_END) on capsule 1 and 2, fixing the closed form (frame.segment_weights); ss: the
# spheres' normal case.

@ti.func
def _capsule_segment(pos, rot, size):
    """(start, end) of a capsule's segment: its -z end and +z end (world, m)."""
    half = column(rot, 2) * size[1]
    return pos - half, pos + half


@ti.func
def _capsule_segment_adjoint(size, g_start, g_end):
    """Reverse of _capsule_segment: (g_pos, g_axis) (3,) each, axis = column 2 of rot."""
    return g_start + g_end, (g_end - g_start) * size[1]


@ti.func
def _capsule_pair_terms(pos1, rot1, size1, pos2, rot2, size2):
    """Segment-weight terms (frame.segment_weight_terms) and segment starts of two capsules."""
    start1, end1 = _capsule_segment(pos1, rot1, size1)
    start2, end2 = _capsule_segment(pos2, rot2, size2)
    d1, d2, r, a, b, c, e, f = segment_weight_terms(start1, end1, start2, end2)
    return start1, start2, d1, d2, r, a, b, c, e, f


@ti.func
def _capsule_pair_points(pos1, rot1, size1, pos2, rot2, size2, state):
    """Sphere centres (c1, c2) on the two capsule segments for a frozen weight-pair state."""
    start1, start2, d1, d2, r, a, b, c, e, f = _capsule_pair_terms(pos1, rot1, size1, pos2, rot2, size2)
    s, t = segment_weights(d1, d2, r, a, b, c, e, f, state)
    return d1 * s + start1, d2 * t + start2


@ti.func
def _capsule_pair_points_adjoint(pos1, rot1, size1, pos2, rot2, size2, state, g_c1, g_c2):
    """Reverse of _capsule_pair_points: (g_pos1, g_axis1, g_pos2, g_axis2) (3,) each, axes = column
    2 of the rotations; through the frozen weights' closed form (frame.segment_weights_adjoint)."""
    start1, end1 = _capsule_segment(pos1, rot1, size1)
    start2, end2 = _capsule_segment(pos2, rot2, size2)
    d1, d2, r, a, b, c, e, f = segment_weight_terms(start1, end1, start2, end2)
    s, t = segment_weights(d1, d2, r, a, b, c, e, f, state)
    g_d1, g_d2, g_r, g_a, g_b, g_c, g_e, g_f = segment_weights_adjoint(d1, d2, r, a, b, c, e, f, state,
                                                                       dot3(g_c1, d1), dot3(g_c2, d2))
    g_start1, g_end1, g_start2, g_end2 = segment_weight_terms_adjoint(
        start1, end1, start2, end2, g_d1 + g_c1 * s, g_d2 + g_c2 * t, g_r, g_a, g_b, g_c, g_e, g_f)
    g_pos1, g_axis1 = _capsule_segment_adjoint(size1, g_start1 + g_c1, g_end1)
    g_pos2, g_axis2 = _capsule_segment_adjoint(size2, g_start2 + g_c2, g_end2)
    return g_pos1, g_axis1, g_pos2, g_axis2


@ti.func
def capsule_capsule_decide(pos1, rot1, size1, pos2, rot2, size2, margin):
    """(count, feature (2,)) of capsule – capsule (sizes = radius, half-length)."""
    _, _, d1, d2, r, a, b, c, e, f = _capsule_pair_terms(pos1, rot1, size1, pos2, rot2, size2)
    n, state0, state1 = segment_weight_states(d1, d2, r, a, b, c, e, f)
    feature = ti.Vector.zero(ti.i32, CAPSULE_CAPSULE_MAX)
    count = 0
    for k in range(n):
        state = ti.select(k == 0, state0, state1)
        c1, c2 = _capsule_pair_points(pos1, rot1, size1, pos2, rot2, size2, state)
        hit, ss = _sphere_sphere_decide(c1, size1[0], c2, size2[0], column(rot1, 2), column(rot2, 2), margin)
        if hit:
            feature[count] = 3 * state + ss
            count += 1
    return count, feature


@ti.func
def capsule_capsule_evaluate(pos1, rot1, size1, pos2, rot2, size2, feature):
    """(position, normal, dist) of the capsule – capsule contact `feature`."""
    c1, c2 = _capsule_pair_points(pos1, rot1, size1, pos2, rot2, size2, feature // 3)
    return _sphere_sphere_evaluate(c1, size1[0], c2, size2[0], column(rot1, 2), column(rot2, 2), feature % 3)


@ti.func
def capsule_capsule_evaluate_adjoint(pos1, rot1, size1, pos2, rot2, size2, feature, g_position, g_normal, g_dist):
    """Reverse of capsule_capsule_evaluate: (g_pos1 (3,), g_rot1 (3, 3), g_pos2 (3,), g_rot2 (3, 3))."""
    c1, c2 = _capsule_pair_points(pos1, rot1, size1, pos2, rot2, size2, feature // 3)
    g_c1, g_c2, g_z1, g_z2 = _sphere_sphere_evaluate_adjoint(c1, size1[0], c2, size2[0], column(rot1, 2),
                                                             column(rot2, 2), feature % 3, g_position, g_normal,
                                                             g_dist)
    g_pos1, g_axis1, g_pos2, g_axis2 = _capsule_pair_points_adjoint(pos1, rot1, size1, pos2, rot2, size2,
                                                                    feature // 3, g_c1, g_c2)
    return g_pos1, column_adjoint(g_z1 + g_axis1, 2), g_pos2, column_adjoint(g_z2 + g_axis2, 2)


capsule_capsule = collider(capsule_capsule_decide, capsule_capsule_evaluate, CAPSULE_CAPSULE_MAX,
                            "Capsule – capsule (MuJoCo 4.0's mjc_CapsuleCapsule): at most 2 contacts.")
