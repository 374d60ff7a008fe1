"""Box colliders: sphere–box, capsule–box and box–box, as MuJoCo 4 computes them.

MuJoCo's mjc_SphereBox, mjc_CapsuleBox and mjc_BoxBox (engine_collision_box.c), reproduced
contact for contact: same count, order, positions, normals and distances. Every collider has
the signature and return described in the package docstring (``collision/__init__.py``)::

    count, position, normal, dist, feature = box_box(pos1, rot1, size1, pos2, rot2, size2, margin)

geom 1 has the lower MuJoCo type (the sphere or capsule; either box for box–box), the normal
points from geom 1 to geom 2, ``margin`` is the pair's margin plus its gap. A geom's frame has
coordinates ``rotᵀ (x - pos)``.

Each collider is a *decide* (the discrete features that give contacts, in MuJoCo's order) and
an *evaluate* (one contact as a closed form of the two poses with its feature frozen); the
collider is decide followed by evaluate per row, so a backward differentiates evaluate (the
feature alone replays a contact). Each section below says what its features encode. Where a
result decides a branch, the arithmetic follows MuJoCo's order of operations (the build runs
without fast math), so the same branch is taken. Decide code, never differentiated, prefers
``ti.select`` to small ``if`` blocks: control flow is what makes Taichi's compile time grow.
Every collider here gives MuJoCo a zero first tangent: build the frame with
``frame.contact_frame(normal[k], zeros)``.

Each evaluate has its hand-written reverse beside it, ``<name>_evaluate_adjoint(pos1, rot1,
size1, pos2, rot2, size2, feature, g_position, g_normal, g_dist) -> (g_pos1, g_rot1, g_pos2,
g_rot2)``: the gradient of g_position·position + g_normal·normal + g_dist·dist with respect to
the poses (rot's 9 entries taken as independent numbers), feature frozen, forward values
recomputed inside; its helpers' reverses (``<helper>_adjoint``) sit beside them. At a kink of
evaluate (a sphere centre exactly on the face it is inside of: depth = |0|) the adjoint takes
the symmetric subgradient 0, as frame.normalize3_adjoint does at a zero vector.
"""
import taichi as ti
from taichi.lang import impl

from ..spatial import dot3, mat_mul, mat_vec
from .frame import (AT_MINUS, AT_PLUS, MINVAL, collider, column, column_adjoint, cross3, cross3_adjoint, normalize3,
                    normalize3_adjoint, segment_pair_params, segment_pair_params_adjoint, segment_pair_state)

SPHERE_BOX_MAX = 1
CAPSULE_BOX_MAX = 2
BOX_BOX_MAX = 8

# feature layouts (see each collider's section)
SPHERE_BOX_INSIDE = 27  # first sphere–box feature of a centre inside the box
SPHERE_BOX_FEATURES = 33  # sphere–box features: 27 clamp patterns + 6 faces
CAPSULE_BASES = 2 + 12 * 9  # capsule segment base codes: 2 ends, 12 box edges x 9 clamp states
_OFF_NONE, _OFF_END, _OFF_SPAN, _OFF_EDGE, _OFF_PLANE = 0, 1, 3, 9, 21  # capsule offset codes
_FACE_TAG_EDGE, _FACE_TAG_RECT = 4, 20  # first box–box face-vertex tags of edge cuts, face corners

_MAXVAL = 1e10  # MuJoCo's mjMAXVAL
_EDGE_BIAS = 1e-6  # relative penalty on an edge axis's separation on near-ties with a face axis
_MAXVERT = 8  # a 4-gon clipped by 4 half-planes has at most 8 vertices
_CLIP_ROWS = _MAXVERT + 1  # a clipping buffer's rows: the polygon's, then one for discarded writes


def _box_box_eps():
    """MuJoCo's rounding scales of box–box for the current float width: (slack on the separation
    tests per metre of summed half sizes, sin² below which an edge cross product is noise, axis
    component below which a supporting corner is ambiguous, squared relative duplicate radius)."""
    if impl.get_runtime().default_fp == ti.f32:
        return 1e-6, 1e-7, 1e-5, 1e-10
    return 1e-13, 1e-16, 1e-9, 1e-14


@ti.func
def _bit(condition):
    """1 if condition else 0, as an i32 (Taichi's comparisons are 1-bit: they overflow in shifts)."""
    return ti.select(condition, 1, 0)


@ti.func
def _mat_t_vec(rot: ti.template(), v: ti.template()):
    """rotᵀ v (3x3, 3-vector), in MuJoCo's order: world vector → the geom's frame."""
    return ti.Vector([rot[0, i] * v[0] + rot[1, i] * v[1] + rot[2, i] * v[2] for i in ti.static(range(3))])


@ti.func
def _mat_t_mat(rot1: ti.template(), rot2: ti.template()):
    """rot1ᵀ rot2 in MuJoCo's order: geom 2's axes (columns) in geom 1's frame."""
    return ti.Matrix([[rot1[0, i] * rot2[0, j] + rot1[1, i] * rot2[1, j] + rot1[2, i] * rot2[2, j]
                       for j in ti.static(range(3))] for i in ti.static(range(3))])


@ti.func
def _mat_t_vec_adjoint(rot: ti.template(), v: ti.template(), g: ti.template()):
    """Reverse of _mat_t_vec(rot, v) given the gradient g (3,) of its result: (g_rot (3, 3), g_v (3,))."""
    return v.outer_product(g), mat_vec(rot, g)


@ti.func
def _mat_vec_adjoint(rot: ti.template(), v: ti.template(), g: ti.template()):
    """Reverse of mat_vec(rot, v) given the gradient g (3,) of its result: (g_rot (3, 3), g_v (3,))."""
    return g.outer_product(v), _mat_t_vec(rot, g)


# ---------------------------------------------------------------- sphere – box
# The nearest box point is the sphere's centre clamped to the box (box frame); a centre inside
# the box leaves through its nearest face.
# feature: SPHERE_BOX_INSIDE + f when the centre is inside the box (f = 2 c + h: the nearest
# face, on axis c; h = 0 its -c side, 1 its +c side); else the clamp pattern sum_c 3^c k_c of
# the centre (k_c = 0 within the slab |x_c| <= half_c, 1 below it, 2 above it): which face,
# edge or corner of the box is nearest.


@ti.func
def _sphere_box_feature(centre: ti.template(), half: ti.template()):
    """(feature, gap) of a sphere centre (box frame, m) against a box of half sizes `half`.

    gap: |clamped - centre| (m), 0 inside. feature: the clamp pattern, or SPHERE_BOX_INSIDE + face
    when gap <= MINVAL (face: the smallest |±half_c - centre_c|, first one on ties, -x first).
    """
    clamped = ti.Vector([ti.select(centre[c] < -half[c], -half[c], ti.select(centre[c] > half[c], half[c], centre[c]))
                         for c in ti.static(range(3))])
    pattern = 0
    for c in ti.static(range(3)):
        pattern += 3**c * ti.select(centre[c] < -half[c], 1, ti.select(centre[c] > half[c], 2, 0))
    _, gap = normalize3(clamped - centre)
    closest = (half[0] + half[1] + half[2]) * 2
    face = 0
    for f in ti.static(range(6)):
        depth = ti.abs((1.0 if f % 2 else -1.0) * half[f // 2] - centre[f // 2])
        face = ti.select(closest > depth, f, face)
        closest = ti.min(closest, depth)
    return ti.select(gap <= MINVAL, SPHERE_BOX_INSIDE + face, pattern), gap


@ti.func
def _sphere_box_clamped(centre: ti.template(), half: ti.template(), feature):
    """The box point nearest to an outside centre (box frame) of clamp pattern `feature`."""
    return ti.Vector([ti.select(feature // 3**c % 3 == 1, -half[c], ti.select(feature // 3**c % 3 == 2, half[c],
                                                                                 centre[c]))
                      for c in ti.static(range(3))])


@ti.func
def _sphere_box_local(centre: ti.template(), radius, half: ti.template(), feature):
    """(position, normal, dist) in the box frame of a sphere (centre, radius) against a box.

    Outside (clamp pattern): normal = unit (clamped - centre), position midway between the box
    point and the sphere's deepest point, dist = gap - radius. Inside (face f): normal = the
    inward normal of face f, dist = -(depth below face f) - radius, position = centre moved
    along the normal by (radius - depth)/2.
    """
    position = centre
    normal = ti.Vector.zero(float, 3)
    dist = 0.0
    if feature >= SPHERE_BOX_INSIDE:
        f = feature - SPHERE_BOX_INSIDE
        c = f // 2
        side = 1.0 if f % 2 else -1.0
        depth = ti.abs(side * half[c] - centre[c])
        normal[c] = -side
        position[c] = centre[c] + normal[c] * ((radius - depth) / 2)
        dist = -depth - radius
    else:
        clamped = _sphere_box_clamped(centre, half, feature)
        unit, gap = normalize3(clamped - centre)
        deepest = centre + unit * radius
        position = clamped * 0.5 + deepest * 0.5
        normal = unit
        dist = gap - radius
    return position, normal, dist


@ti.func
def _sphere_box_local_adjoint(centre: ti.template(), radius, half: ti.template(), feature, g_position: ti.template(),
                              g_normal: ti.template(), g_dist):
    """Reverse of _sphere_box_local: the gradient (3,) of the centre (box frame) from those of
    (position, normal, dist). Inside, the face's normal is constant; outside, the clamped
    coordinates are the box's (constant) except within the slab, where they follow the centre."""
    g_centre = ti.Vector.zero(float, 3)
    if feature >= SPHERE_BOX_INSIDE:
        f = feature - SPHERE_BOX_INSIDE
        c = f // 2
        side = 1.0 if f % 2 else -1.0
        below = side * half[c] - centre[c]  # depth = |below|: its slope is 0 at 0 (torch's abs)
        depth_slope = ti.select(below < 0, 1.0, ti.select(below > 0, -1.0, 0.0))  # d depth / d centre_c
        g_centre = g_position
        g_centre[c] += (g_position[c] * side * 0.5 - g_dist) * depth_slope
    else:
        clamped = _sphere_box_clamped(centre, half, feature)
        g_diff = normalize3_adjoint(clamped - centre, g_normal + g_position * (0.5 * radius), g_dist)
        follows = ti.Vector([ti.select(feature // 3**c % 3 == 0, 1.0, 0.0) for c in ti.static(range(3))])
        g_centre = g_position * 0.5 - g_diff + (g_position * 0.5 + g_diff) * follows
    return g_centre


@ti.func
def _sphere_box_world(centre: ti.template(), radius, pos2: ti.template(), rot2: ti.template(), half: ti.template(),
                      feature):
    """_sphere_box_local's contact in the world: (position m, normal, dist m)."""
    position, normal, dist = _sphere_box_local(centre, radius, half, feature)
    return mat_vec(rot2, position) + pos2, mat_vec(rot2, normal), dist


@ti.func
def _sphere_box_world_adjoint(centre: ti.template(), radius, rot2: ti.template(), half: ti.template(), feature,
                              g_position: ti.template(), g_normal: ti.template(), g_dist):
    """Reverse of _sphere_box_world: (g_centre (3,), g_rot2 (3, 3)); pos2's gradient is g_position."""
    position, normal, _ = _sphere_box_local(centre, radius, half, feature)
    g_rot2, g_local_position = _mat_vec_adjoint(rot2, position, g_position)
    g_rot2_normal, g_local_normal = _mat_vec_adjoint(rot2, normal, g_normal)
    return (_sphere_box_local_adjoint(centre, radius, half, feature, g_local_position, g_local_normal, g_dist),
            g_rot2 + g_rot2_normal)


@ti.func
def sphere_box_decide(pos1: ti.template(), rot1: ti.template(), size1: ti.template(), pos2: ti.template(),
                      rot2: ti.template(), size2: ti.template(), margin):
    """(count, feature (1,)) of sphere (radius size1[0]) – box (half sizes size2): one contact
    when the gap between the centre and the box, less the radius, is <= margin."""
    centre = _mat_t_vec(rot2, pos1 - pos2)
    sb, gap = _sphere_box_feature(centre, size2)
    feature = ti.Vector.zero(ti.i32, SPHERE_BOX_MAX)
    count = 0
    if not gap - size1[0] > margin:
        feature[0] = sb
        count = 1
    return count, feature


@ti.func
def sphere_box_evaluate(pos1: ti.template(), rot1: ti.template(), size1: ti.template(), pos2: ti.template(),
                        rot2: ti.template(), size2: ti.template(), feature):
    """(position, normal, dist) of the sphere–box contact with its feature frozen (world)."""
    centre = _mat_t_vec(rot2, pos1 - pos2)
    return _sphere_box_world(centre, size1[0], pos2, rot2, size2, feature)


@ti.func
def sphere_box_evaluate_adjoint(pos1: ti.template(), rot1: ti.template(), size1: ti.template(), pos2: ti.template(),
                                rot2: ti.template(), size2: ti.template(), feature, g_position: ti.template(),
                                g_normal: ti.template(), g_dist):
    """Reverse of sphere_box_evaluate: (g_pos1 (3,), g_rot1 (3, 3), g_pos2 (3,), g_rot2 (3, 3)) from
    the gradients of (position, normal, dist); rot1 (the sphere's) does not enter: g_rot1 = 0."""
    rel = pos1 - pos2
    centre = _mat_t_vec(rot2, rel)
    g_centre, g_rot2 = _sphere_box_world_adjoint(centre, size1[0], rot2, size2, feature, g_position, g_normal, g_dist)
    g_rot2_centre, g_rel = _mat_t_vec_adjoint(rot2, rel, g_centre)
    return g_rel, ti.Matrix.zero(float, 3, 3), g_position - g_rel, g_rot2 + g_rot2_centre


sphere_box = collider(sphere_box_decide, sphere_box_evaluate, SPHERE_BOX_MAX,
                       "Sphere – box (mjc_SphereBox): at most 1 contact.")


# ---------------------------------------------------------------- capsule – box
# MuJoCo finds the capsule-axis point nearest to the box (an end against a face, or the closest
# points of the axis and one of the 12 box edges), then a "sensible" second axis point when the
# axis lies along the box, and collides a sphere of the capsule's radius at each with the box.
# All of it works in the box frame: pos = the capsule's centre, halfaxis = its half-length times
# its unit axis; an axis point is pos + t halfaxis, t in [-1, 1].
# feature = sb + SPHERE_BOX_FEATURES seg: sb the sphere–box feature of the sphere at t, and the
# segment code seg = base + CAPSULE_BASES offset fixes t's closed form:
#   base 0 / 1: t0 = -1 / +1 (an end nearest to a box face);
#   base 2 + 9 edge + state: t0 = x2 of the closest points of box edge `edge` (_box_edge; its
#     parameter x1) and the axis (parameter x2), with the clamp state 3 s1 + s2 of (x1, x2)
#     frozen (frame.py's segment_pair_params codes);
#   offset (MuJoCo's "secondpos", for the second sphere): _OFF_NONE: t = t0; _OFF_END + h: the
#     -1 / +1 end; _OFF_SPAN + 2 c + (m > 0): t0 + m 2 half_c / |halfaxis_c| (across the box
#     along axis c); _OFF_EDGE + 4 c + 2 (m > 0) + (σ > 0): t0 + m half_c (1 + σ x1) /
#     |halfaxis_c| (along the nearest edge to its end); _OFF_PLANE + 2 c + (σ > 0): the point
#     where the axis crosses the plane x_c = σ half_c.


@ti.func
def _capsule_in_box(pos1: ti.template(), rot1: ti.template(), size1: ti.template(), pos2: ti.template(),
                    rot2: ti.template()):
    """(pos, axis, halfaxis): the capsule's centre, unit axis and half axis in the box frame."""
    pos = _mat_t_vec(rot2, pos1 - pos2)
    axis = _mat_t_vec(rot2, column(rot1, 2))
    return pos, axis, axis * size1[1]


@ti.func
def _capsule_in_box_adjoint(pos1: ti.template(), rot1: ti.template(), size1: ti.template(), pos2: ti.template(),
                            rot2: ti.template(), g_pos: ti.template(), g_halfaxis: ti.template()):
    """Reverse of _capsule_in_box from the gradients of pos and halfaxis (axis's own is not used):
    (g_pos1, g_rot1, g_pos2, g_rot2)."""
    g_rot2, g_rel = _mat_t_vec_adjoint(rot2, pos1 - pos2, g_pos)
    g_rot2_axis, g_column = _mat_t_vec_adjoint(rot2, column(rot1, 2), g_halfaxis * size1[1])
    return g_rel, column_adjoint(g_column, 2), -g_rel, g_rot2 + g_rot2_axis


@ti.func
def _box_edge(edge):
    """(j, corner) of box edge `edge` (0 … 11): it runs along axis j from `corner` (bit c: + side
    on axis c; bit j is 0), edges ordered by axis, then by corner (MuJoCo's order)."""
    j = edge // 4
    r = edge % 4
    return j, (r & ((1 << j) - 1)) | ((r >> j) << (j + 1))


@ti.func
def _edge_corner(half: ti.template(), j, corner):
    """Start of the box edge along axis j from `corner` (box frame): coordinate j is 0."""
    return ti.Vector([ti.select(c == j, 0.0, ti.select(corner & (1 << c), half[c], -half[c]))
                      for c in ti.static(range(3))])


@ti.func
def _edge_axis_terms(pos: ti.template(), halfaxis: ti.template(), halflength, half: ti.template(), j, corner):
    """MuJoCo's quadratic terms (ma, mb, mc, u, v, det) of the box edge (j, corner), parameter x1
    (edge point start + x1 half_j e_j), against the capsule axis, parameter x2 (pos + x2 halfaxis)."""
    dif = _edge_corner(half, j, corner) - pos
    ma = half[j] * half[j]
    mb = -half[j] * halfaxis[j]
    mc = halflength * halflength
    u = -half[j] * dif[j]
    v = dot3(halfaxis, dif)
    return ma, mb, mc, u, v, ma * mc - mb * mb


@ti.func
def _edge_axis_params(pos: ti.template(), halfaxis: ti.template(), halflength, half: ti.template(), edge, state):
    """(x1, x2) of the box edge – capsule axis closest points, clamp state frozen."""
    j, corner = _box_edge(edge)
    ma, mb, mc, u, v, det = _edge_axis_terms(pos, halfaxis, halflength, half, j, corner)
    return segment_pair_params(ma, mb, mc, u, v, det, state)


@ti.func
def _edge_axis_params_adjoint(pos: ti.template(), halfaxis: ti.template(), halflength, half: ti.template(), edge,
                              state, g_x1, g_x2):
    """Reverse of _edge_axis_params: (g_pos, g_halfaxis) from the gradients of (x1, x2). ma and mc
    are constants (box size, capsule half-length)."""
    j, corner = _box_edge(edge)
    ma, mb, mc, u, v, det = _edge_axis_terms(pos, halfaxis, halflength, half, j, corner)
    _, g_mb, _, g_u, g_v, g_det = segment_pair_params_adjoint(ma, mb, mc, u, v, det, state, g_x1, g_x2)
    g_mb -= 2 * mb * g_det
    dif = _edge_corner(half, j, corner) - pos
    g_dif = halfaxis * g_v
    g_dif[j] -= half[j] * g_u
    g_halfaxis = dif * g_v
    g_halfaxis[j] -= half[j] * g_mb
    return -g_dif, g_halfaxis


@ti.func
def _capsule_base_params(pos: ti.template(), halfaxis: ti.template(), halflength, half: ti.template(), base):
    """(x1, t0) of a segment base code: the edge parameter (0 for an end) and the axis parameter."""
    x1 = 0.0
    t = 2.0 * base - 1.0
    if base >= 2:
        x1, t = _edge_axis_params(pos, halfaxis, halflength, half, (base - 2) // 9, (base - 2) % 9)
    return x1, t


@ti.func
def _plane_offset(off):
    """(c, side) of a plane offset code: the point where the axis crosses x_c = side half_c."""
    return (off - _OFF_PLANE) // 2, 1.0 if (off - _OFF_PLANE) % 2 else -1.0


@ti.func
def _capsule_param(pos: ti.template(), halfaxis: ti.template(), halflength, half: ti.template(), seg):
    """Axis parameter t (point pos + t halfaxis) of a segment code seg (the capsule–box section)."""
    x1, t = _capsule_base_params(pos, halfaxis, halflength, half, seg % CAPSULE_BASES)
    off = seg // CAPSULE_BASES
    if off >= _OFF_PLANE:
        c, side = _plane_offset(off)
        mul = -t  # the base is an end; the offset runs towards the other end
        start = pos[c] + halfaxis[c] * -mul
        t = (side * half[c] - start) / halfaxis[c] * mul * mul + t
    elif off >= _OFF_EDGE:
        k = off - _OFF_EDGE
        c = k // 4
        sign = 1.0 if k // 2 % 2 else -1.0
        sigma = 1.0 if k % 2 else -1.0
        t = half[c] * (1.0 + sigma * x1) / ti.abs(halfaxis[c]) * sign + t
    elif off >= _OFF_SPAN:
        c = (off - _OFF_SPAN) // 2
        sign = 1.0 if (off - _OFF_SPAN) % 2 else -1.0
        t = 2 * half[c] / ti.abs(halfaxis[c]) * sign + t
    elif off >= _OFF_END:
        t = 2.0 * (off - _OFF_END) - 1.0
    return t


@ti.func
def _capsule_param_adjoint(pos: ti.template(), halfaxis: ti.template(), halflength, half: ti.template(), seg, g_t):
    """Reverse of _capsule_param: (g_pos, g_halfaxis) from the gradient of t. An end (base or
    offset) is a constant; an offset adds a term in one |halfaxis_c| (and x1 along an edge)."""
    base = seg % CAPSULE_BASES
    off = seg // CAPSULE_BASES
    x1, t = _capsule_base_params(pos, halfaxis, halflength, half, base)
    g_pos = ti.Vector.zero(float, 3)
    g_halfaxis = ti.Vector.zero(float, 3)
    g_x1 = 0.0
    g_t0 = g_t
    if off >= _OFF_PLANE:  # t0 + (side half_c - start_c)/h_c mul², start_c = pos_c - mul h_c; t0 = -mul is an end
        c, side = _plane_offset(off)
        mul = -t
        h = halfaxis[c]
        g_start = -g_t * mul * mul / h
        g_pos[c] = g_start
        g_halfaxis[c] = -g_t * (side * half[c] - pos[c] + mul * h) / (h * h) * mul * mul - mul * g_start
        g_t0 = 0.0
    elif off >= _OFF_EDGE:  # t0 + sign half_c (1 + sigma x1)/|h_c|
        k = off - _OFF_EDGE
        c = k // 4
        sign = 1.0 if k // 2 % 2 else -1.0
        sigma = 1.0 if k % 2 else -1.0
        g_x1 = g_t * sign * half[c] * sigma / ti.abs(halfaxis[c])
        g_halfaxis[c] = -g_t * sign * half[c] * (1.0 + sigma * x1) / ti.abs(halfaxis[c]) / halfaxis[c]
    elif off >= _OFF_SPAN:  # t0 + sign 2 half_c/|h_c|
        c = (off - _OFF_SPAN) // 2
        sign = 1.0 if (off - _OFF_SPAN) % 2 else -1.0
        g_halfaxis[c] = -g_t * sign * 2 * half[c] / ti.abs(halfaxis[c]) / halfaxis[c]
    elif off >= _OFF_END:
        g_t0 = 0.0
    if base >= 2:
        g_pos_base, g_halfaxis_base = _edge_axis_params_adjoint(pos, halfaxis, halflength, half, (base - 2) // 9,
                                                                (base - 2) % 9, g_x1, g_t0)
        g_pos += g_pos_base
        g_halfaxis += g_halfaxis_base
    return g_pos, g_halfaxis


@ti.func
def _capsule_sphere_centre(pos: ti.template(), halfaxis: ti.template(), t, pos2: ti.template(), rot2: ti.template()):
    """Box-frame centre of the sphere at axis parameter t, through the world as MuJoCo rounds it."""
    world = mat_vec(rot2, pos + halfaxis * t) + pos2
    return _mat_t_vec(rot2, world - pos2)


@ti.func
def _capsule_sphere_centre_adjoint(pos: ti.template(), halfaxis: ti.template(), t, pos2: ti.template(),
                                   rot2: ti.template(), g_centre: ti.template()):
    """Reverse of _capsule_sphere_centre: (g_pos, g_halfaxis, g_t, g_rot2). pos2 is added, then
    taken away: its gradients cancel exactly (none returned); rot2 enters twice."""
    point = pos + halfaxis * t
    world = mat_vec(rot2, point) + pos2
    g_rot2_back, g_world = _mat_t_vec_adjoint(rot2, world - pos2, g_centre)
    g_rot2_out, g_point = _mat_vec_adjoint(rot2, point, g_world)
    return g_point, g_point * t, dot3(g_point, halfaxis), g_rot2_back + g_rot2_out


@ti.func
def _capsule_nearest(pos: ti.template(), halfaxis: ti.template(), halflength, half: ti.template(), bestmax):
    """MuJoCo's search for the capsule-axis point nearest to the box.

    Returns (cltype, base, t, x1, clface, clcorner, cledge): cltype -3/-1 when the -1/+1 end is
    nearest to a face (clface: the one axis along which it lies outside the box, -1 inside),
    else 3 s1 + s2 with MuJoCo's clamp codes (0 at -1, 1 inside, 2 at +1) of the edge
    parameter x1 and the axis parameter t, s1 being MuJoCo's flag (segment_pair_state: an end's
    code where x1 was re-solved inside the edge); -4 when nothing was found. base: the segment
    base code (the true clamp state); clcorner: the edge's corner MuJoCo names from s1 (its +1
    end when s1 = 2); cledge: the edge's axis.
    """
    best = bestmax
    cltype = -4
    base = 0
    t = 0.0
    x1 = 0.0
    clface = -1
    clcorner = 0
    cledge = 0
    for e in range(2):  # the ends: an end nearest to a face (outside along at most one axis)
        end = 2.0 * e - 1.0
        point = pos + halfaxis * end
        outside = 0
        face = -1
        for c in ti.static(range(3)):
            out = point[c] < -half[c] or point[c] > half[c]
            outside += _bit(out)
            face = ti.select(out, c, face)
        clamped = ti.Vector([ti.max(-half[c], ti.min(half[c], point[c])) for c in ti.static(range(3))])
        d2 = dot3(clamped - point, clamped - point)
        better = outside <= 1 and d2 < best
        best = ti.select(better, d2, best)
        t = ti.select(better, end, t)
        cltype = ti.select(better, 2 * e - 3, cltype)
        clface = ti.select(better, face, clface)
        base = ti.select(better, e, base)
    for edge in range(12):  # the box edges; parallel ones (det < MINVAL) are skipped
        j, corner = _box_edge(edge)
        ma, mb, mc, u, v, det = _edge_axis_terms(pos, halfaxis, halflength, half, j, corner)
        state, flag = segment_pair_state(ma, mb, mc, u, v, det)
        ex, et = segment_pair_params(ma, mb, mc, u, v, det, state)
        gap = _edge_corner(half, j, corner) - pos + halfaxis * -et
        gap[j] += half[j] * ex
        d2 = dot3(gap, gap)
        better = ti.abs(det) >= MINVAL and d2 < best - MINVAL
        s1 = 1 + _bit(flag == AT_PLUS) - _bit(flag == AT_MINUS)  # (MuJoCo's flag, not always x1's clamp)
        s2 = 1 + _bit(state % 3 == AT_PLUS) - _bit(state % 3 == AT_MINUS)
        best = ti.select(better, d2, best)
        t = ti.select(better, et, t)
        x1 = ti.select(better, ex, x1)
        cltype = ti.select(better, 3 * s1 + s2, cltype)
        clcorner = ti.select(better, corner + (1 << j) * (s1 // 2), clcorner)
        cledge = ti.select(better, j, cledge)
        base = ti.select(better, 2 + 9 * edge + state, base)
    return cltype, base, t, x1, clface, clcorner, cledge


@ti.func
def _span_offset(c, sign):
    """Offset code of t + sign 2 half_c/|halfaxis_c| (the axis crosses the box along c)."""
    return _OFF_SPAN + 2 * c + _bit(sign > 0)


@ti.func
def _end_offset(sign):
    """Offset code of the axis end t = sign."""
    return _OFF_END + _bit(sign > 0)


@ti.func
def _capsule_second(pos: ti.template(), axis: ti.template(), halfaxis: ti.template(), half: ti.template(), cltype, t,
                    x1, clface, clcorner, cledge):
    """MuJoCo's second sphere ("secondpos"): its offset code, _OFF_NONE when there is none.

    Corner nearest: along the box edge the axis is most aligned with (axis_c² > 0.5) or across
    the face it lies along, up to the axis end or the far side of the box. Edge nearest, crossing
    it (an X, not a T): along the face the axis is flatter to. End nearest to a face: towards
    the other end, stopped where the axis leaves the box's slabs. Each candidate stop is one
    offset code; the smallest distance along the axis wins (first on ties). The three cases are
    evaluated side by side (a decision only: no gradient flows here) and the nearest one's kept.
    """
    axisdir = _bit(halfaxis[0] > 0) + 2 * _bit(halfaxis[1] > 0) + 4 * _bit(halfaxis[2] > 0)
    # a box corner is nearest, unless the axis points at or away from it
    rel = axisdir ^ clcorner
    flip = rel == 3 or rel == 5 or rel == 6  # the axis runs towards -c rather than +c
    mul = ti.select(flip, -1.0, 1.0)
    single = ti.select(flip, 7 - rel, rel)  # 1, 2 or 4: the box axis c the corner differs along
    c = ti.select(single == 1, 0, ti.select(single == 2, 1, 2))
    stop = 2 * half[c] / ti.abs(halfaxis[c])
    off_along = ti.select(stop < ti.select(flip, 1 + t, 1 - t), _span_offset(c, mul), _end_offset(mul))
    second = ti.select(flip, 1 - t, 1 + t)
    off_across = _end_offset(-mul)
    for k in ti.static(range(1, 3)):
        ck = (c + k) % 3
        stop = 2 * half[ck] / ti.abs(halfaxis[ck])
        off_across = ti.select(stop < second, _span_offset(ck, -mul), off_across)
        second = ti.min(stop, second)
    off_corner = ti.select(rel == 0 or rel == 7, _OFF_NONE, ti.select(axis[c] * axis[c] > 0.5, off_along, off_across))
    # the middle of a box edge is nearest, and the axis crosses it
    rel = (axisdir ^ clcorner) & (7 - (1 << cledge))
    c = cledge
    c1 = ti.select(ti.abs(axis[(c + 1) % 3]) > ti.abs(axis[(c + 2) % 3]), (c + 2) % 3, (c + 1) % 3)
    c2 = 3 - c - c1
    up = rel & (1 << c2) != 0
    mul = ti.select(up, 1.0, -1.0)
    second = ti.select(up, 1 - t, 1 + t)
    stop = 2 * half[c2] / ti.abs(halfaxis[c2])
    off_edge = ti.select(stop < second, _span_offset(c2, mul), _end_offset(mul))
    second = ti.min(stop, second)
    sigma = ti.select((axisdir & (1 << c) != 0) == up, -1.0, 1.0)
    stop = half[c] * (1.0 + sigma * x1) / ti.abs(halfaxis[c])
    off_edge = ti.select(stop < second, _OFF_EDGE + 4 * c + 2 * _bit(mul > 0) + _bit(sigma > 0), off_edge)
    off_edge = ti.select(rel == 1 or rel == 2 or rel == 4, off_edge, _OFF_NONE)
    # an end is nearest to a face, outside the box
    mul = ti.select(cltype == -3, 1.0, -1.0)
    start = pos + halfaxis * -mul
    second = 2.0
    off_face = _end_offset(mul)
    for c in ti.static(range(3)):
        for h in ti.static(range(2)):  # the + side first
            stop = ((1.0 - 2.0 * h) * half[c] - start[c]) / halfaxis[c] * mul
            better = c != clface and stop > 0 and stop < second
            off_face = ti.select(better, _OFF_PLANE + 2 * c + 1 - h, off_face)
            second = ti.select(better, stop, second)
    off_face = ti.select(clface == -1, _OFF_NONE, off_face)
    return ti.select(cltype >= 0, ti.select(cltype // 3 != 1, off_corner, off_edge),
                     ti.select(cltype == -4, _OFF_NONE, off_face))


@ti.func
def capsule_box_decide(pos1: ti.template(), rot1: ti.template(), size1: ti.template(), pos2: ti.template(),
                       rot2: ti.template(), size2: ti.template(), margin):
    """(count, feature (2,)) of capsule (radius size1[0], half-length size1[1], axis = its z) –
    box (half sizes size2): MuJoCo's nearest axis point, then its second one if any, each kept
    when its sphere is within margin of the box (so the second may be the only contact)."""
    pos, axis, halfaxis = _capsule_in_box(pos1, rot1, size1, pos2, rot2)
    radius = size1[0]
    bestmax = margin + 2 * (radius + size1[1] + size2[0] + size2[1] + size2[2])
    cltype, base, t, x1, clface, clcorner, cledge = _capsule_nearest(pos, halfaxis, size1[1], size2, bestmax)
    off = _capsule_second(pos, axis, halfaxis, size2, cltype, t, x1, clface, clcorner, cledge)
    feature = ti.Vector.zero(ti.i32, CAPSULE_BOX_MAX)
    count = 0
    if cltype != -4:
        for q in range(1 + _bit(off != _OFF_NONE)):
            seg = base + CAPSULE_BASES * off * q
            centre = _capsule_sphere_centre(pos, halfaxis, _capsule_param(pos, halfaxis, size1[1], size2, seg), pos2,
                                            rot2)
            sb, gap = _sphere_box_feature(centre, size2)
            if not gap - radius > margin:
                feature[count] = sb + SPHERE_BOX_FEATURES * seg
                count += 1
    return count, feature


@ti.func
def capsule_box_evaluate(pos1: ti.template(), rot1: ti.template(), size1: ti.template(), pos2: ti.template(),
                         rot2: ti.template(), size2: ti.template(), feature):
    """(position, normal, dist) of a capsule–box contact with its feature frozen (world)."""
    pos, _, halfaxis = _capsule_in_box(pos1, rot1, size1, pos2, rot2)
    t = _capsule_param(pos, halfaxis, size1[1], size2, feature // SPHERE_BOX_FEATURES)
    centre = _capsule_sphere_centre(pos, halfaxis, t, pos2, rot2)
    return _sphere_box_world(centre, size1[0], pos2, rot2, size2, feature % SPHERE_BOX_FEATURES)


@ti.func
def capsule_box_evaluate_adjoint(pos1: ti.template(), rot1: ti.template(), size1: ti.template(), pos2: ti.template(),
                                 rot2: ti.template(), size2: ti.template(), feature, g_position: ti.template(),
                                 g_normal: ti.template(), g_dist):
    """Reverse of capsule_box_evaluate: (g_pos1 (3,), g_rot1 (3, 3), g_pos2 (3,), g_rot2 (3, 3))
    from the gradients of (position, normal, dist); of rot1 only column 2 (the axis) enters."""
    pos, _, halfaxis = _capsule_in_box(pos1, rot1, size1, pos2, rot2)
    seg = feature // SPHERE_BOX_FEATURES
    t = _capsule_param(pos, halfaxis, size1[1], size2, seg)
    centre = _capsule_sphere_centre(pos, halfaxis, t, pos2, rot2)
    off = seg // CAPSULE_BASES
    if off >= _OFF_PLANE:  # the sphere lies on the plane x_c = side half_c (exactly, but for rounding): put it
        c, side = _plane_offset(off)  # there, so that a depth from that face sits at its kink (slope 0)
        centre[c] = side * size2[c]
    g_centre, g_rot2 = _sphere_box_world_adjoint(centre, size1[0], rot2, size2, feature % SPHERE_BOX_FEATURES,
                                                 g_position, g_normal, g_dist)
    g_pos, g_halfaxis, g_t, g_rot2_centre = _capsule_sphere_centre_adjoint(pos, halfaxis, t, pos2, rot2, g_centre)
    g_pos_t, g_halfaxis_t = _capsule_param_adjoint(pos, halfaxis, size1[1], size2, seg, g_t)
    g_pos1, g_rot1, g_pos2, g_rot2_in = _capsule_in_box_adjoint(pos1, rot1, size1, pos2, rot2, g_pos + g_pos_t,
                                                                g_halfaxis + g_halfaxis_t)
    return g_pos1, g_rot1, g_pos2 + g_position, g_rot2 + g_rot2_centre + g_rot2_in


capsule_box = collider(capsule_box_decide, capsule_box_evaluate, CAPSULE_BOX_MAX,
                        "Capsule – box (mjc_CapsuleBox): at most 2 contacts.")


# ---------------------------------------------------------------- box – box
# Stage 1, separating axes: the 15 candidate directions (3 face normals per box, 9 edge cross
# products), the one of largest separation wins (faces preferred on near-ties); any separation
# beyond margin means no contact. Stage 2: a face axis clips the incident box's face most
# opposed to the reference face against the reference face's four side planes (Sutherland–
# Hodgman), every clipped vertex within margin is a contact; an edge axis gives one contact
# between the supporting edges. Everything runs in box 1's frame (rot: box 2's axes as columns,
# pos21 / pos12: each centre in the other's frame).
# feature: bits 0-3 the winning axis `code` (0-2 box 1's face axis a, 3-5 box 2's face axis
# a = code - 3, 6 + 3 i + j box 1's axis i × box 2's axis j).
#   Face contact (code < 6): bit 4 sgn > 0 (the incident box lies on the reference box's +a
#   side), bit 5 tinc > 0 and bits 6-7 binc (the incident face: axis binc of the incident box,
#   its tinc side), bits 8-12 the clipped polygon's vertex: 0-3 the incident face's corner k,
#   _FACE_TAG_EDGE + 4 k + p its edge k (corner k to k + 1) cut by the reference face's side
#   plane p (0: x <= lx, 1: -x <= lx, 2: y <= ly, 3: -y <= ly), _FACE_TAG_RECT + 2 px + py - 2
#   the reference face's corner on side planes px, py (lifted onto the incident face's plane).
#   Edge contact (code >= 6): bit 4 the axis was negated to point from box 1 to box 2, bits 5-8
#   the + side of the supporting edges' corners (box 1's on its axes i+1, i+2, box 2's on its
#   axes j+1, j+2), bit 9 the edges are parallel to working precision, bits 10-15 the frozen
#   clamp states (2 bits each: 0 free, 1 low, 2 high) of the witness parameters s, t, s.


@ti.func
def _box_pair(pos1: ti.template(), rot1: ti.template(), pos2: ti.template(), rot2: ti.template()):
    """(rot = rot1ᵀ rot2, pos21 = box 2's centre in box 1's frame, pos12 = box 1's in box 2's)."""
    return _mat_t_mat(rot1, rot2), _mat_t_vec(rot1, pos2 - pos1), _mat_t_vec(rot2, pos1 - pos2)


@ti.func
def _box_pair_adjoint(pos1: ti.template(), rot1: ti.template(), pos2: ti.template(), rot2: ti.template(),
                      g_rot: ti.template(), g_pos21: ti.template(), g_pos12: ti.template()):
    """Reverse of _box_pair: (g_pos1, g_rot1, g_pos2, g_rot2) from the gradients of (rot, pos21, pos12)."""
    g_rot1, g_rel21 = _mat_t_vec_adjoint(rot1, pos2 - pos1, g_pos21)
    g_rot2, g_rel12 = _mat_t_vec_adjoint(rot2, pos1 - pos2, g_pos12)
    g_rot1 += mat_mul(rot2, g_rot.transpose())  # rot = rot1ᵀ rot2
    g_rot2 += mat_mul(rot1, g_rot)
    return g_rel12 - g_rel21, g_rot1, g_rel21 - g_rel12, g_rot2


@ti.func
def _edge_axis(rot: ti.template(), i, j):
    """Unit e_i × (box 2's axis j), box 1's frame, normalised as MuJoCo (component i is 0)."""
    unit, _ = normalize3(_edge_cross(rot, i, j))
    return unit


@ti.func
def _edge_cross(rot: ti.template(), i, j):
    """e_i × (box 2's axis j) in box 1's frame, not normalised."""
    axis = ti.Vector.zero(float, 3)
    axis[(i + 1) % 3] = -rot[(i + 2) % 3, j]
    axis[(i + 2) % 3] = rot[(i + 1) % 3, j]
    return axis


@ti.func
def _edge_axis_adjoint(rot: ti.template(), i, j, g_unit: ti.template()):
    """Reverse of _edge_axis: the gradient (3, 3) of rot from that of the unit axis."""
    g_axis = normalize3_adjoint(_edge_cross(rot, i, j), g_unit, 0.0)
    g_rot = ti.Matrix.zero(float, 3, 3)
    g_rot[(i + 2) % 3, j] = -g_axis[(i + 1) % 3]
    g_rot[(i + 1) % 3, j] = g_axis[(i + 2) % 3]
    return g_rot


@ti.func
def _separating_axis(rot: ti.template(), pos21: ti.template(), pos12: ti.template(), size1: ti.template(),
                     size2: ti.template(), septol):
    """MuJoCo's separating-axis search: (separated, code, sep_best, code_face, sep_face).

    separated: some axis separates the boxes by more than septol (m). code: the axis of largest
    separation (box–box feature codes), an edge axis only when it beats the best face axis by a
    relative _EDGE_BIAS; code_face / sep_face: the best face axis and its separation (m).
    """
    par_eps = ti.static(_box_box_eps()[1])
    best = -_MAXVAL
    code = -1
    separated = False
    for f in range(6):  # face axes: axis k of box 1 (f < 3) or of box 2 (f >= 3)
        k = f % 3
        on1 = f < 3
        radius = 0.0  # the other box's support radius along the axis
        for c in ti.static(range(3)):
            radius += ti.abs(ti.select(on1, rot[k, c], rot[c, k])) * ti.select(on1, size2[c], size1[c])
        sep = ti.abs(ti.select(on1, pos21[k], pos12[k])) - ti.select(on1, size1[k], size2[k]) - radius
        separated = separated or sep > septol
        code = ti.select(sep > best, f, code)
        best = ti.max(sep, best)
    sep_face = best
    code_face = code
    for ij in range(9):  # edge pairs: the cross product's components i1, i2 in box 1's frame
        i, j = ij // 3, ij % 3
        i1, i2, j1, j2 = (i + 1) % 3, (i + 2) % 3, (j + 1) % 3, (j + 2) % 3
        norm2 = rot[i2, j] * rot[i2, j] + rot[i1, j] * rot[i1, j]
        valid = norm2 >= par_eps  # else the edges are parallel: a face axis covers the direction
        inv = 1 / ti.sqrt(norm2)
        ax1 = -rot[i2, j] * inv
        ax2 = rot[i1, j] * inv
        radius1 = size1[i1] * ti.abs(ax1) + size1[i2] * ti.abs(ax2)
        a2_1 = ax1 * rot[i1, j1] + ax2 * rot[i2, j1]
        a2_2 = ax1 * rot[i1, j2] + ax2 * rot[i2, j2]
        radius2 = size2[j1] * ti.abs(a2_1) + size2[j2] * ti.abs(a2_2)
        sep = ti.abs(ax1 * pos21[i1] + ax2 * pos21[i2]) - radius1 - radius2
        separated = separated or (valid and sep > septol)
        better = valid and sep - _EDGE_BIAS * ti.abs(sep) > best and sep > sep_face
        code = ti.select(better, 6 + ij, code)
        best = ti.select(better, sep, best)
    return separated, code, best, code_face, sep_face


@ti.func
def _face_for_aliased_edge(rot: ti.template(), code, sep_best, code_face, sep_face):
    """MuJoCo's substitution: a winning edge axis within ~8° of the best face axis (|cos| > 0.99)
    gives way to the face unless it separates more by 5 % of the face's depth. Returns the code."""
    if code >= 6:
        axis = _edge_axis(rot, (code - 6) // 3, (code - 6) % 3)
        face_dot = 0.0
        if code_face < 3:
            face_dot = ti.abs(axis[code_face])
        else:
            f = code_face - 3
            face_dot = ti.abs(axis[0] * rot[0, f] + axis[1] * rot[1, f] + axis[2] * rot[2, f])
        if face_dot > 0.99 and sep_best < sep_face + 0.05 * ti.abs(sep_face) + MINVAL:
            code = code_face
    return code


# ---------------------------------------------------------------- box – box: edge contact


@ti.func
def _clip_state(x, limit):
    """Which way mju_clip(x, -limit, limit) goes: 0 inside, 1 at -limit, 2 at +limit."""
    return ti.select(x < -limit, 1, ti.select(x > limit, 2, 0))


@ti.func
def _clip_apply(x, state, limit):
    """x clipped as a frozen _clip_state says."""
    return ti.select(state == 1, -limit, ti.select(state == 2, limit, x))


@ti.func
def _edge_witness_terms(rot: ti.template(), pos21: ti.template(), size1: ti.template(), size2: ti.template(), i, j,
                        corners):
    """(c1, cc, c2, d2, e) of the edges (i, j) from `corners` (_edge_witness), box 1's frame: c1 box 1's
    edge centre, cc box 2's in box 2's frame, c2 = rot cc + pos21, d2 box 2's axis j, e = c2 - c1."""
    i1, i2, j1, j2 = (i + 1) % 3, (i + 2) % 3, (j + 1) % 3, (j + 2) % 3
    c1 = ti.Vector.zero(float, 3)
    c1[i1] = ti.select(corners & 1, size1[i1], -size1[i1])
    c1[i2] = ti.select(corners & 2, size1[i2], -size1[i2])
    cc = ti.Vector.zero(float, 3)
    cc[j1] = ti.select(corners & 4, size2[j1], -size2[j1])
    cc[j2] = ti.select(corners & 8, size2[j2], -size2[j2])
    c2 = mat_vec(rot, cc) + pos21
    d2 = ti.Vector([rot[0, j], rot[1, j], rot[2, j]])
    return c1, cc, c2, d2, c2 - c1


@ti.func
def _edge_witness(rot: ti.template(), pos21: ti.template(), size1: ti.template(), size2: ti.template(), i, j, corners,
                  states, replay: ti.template()):
    """Closest points of box 1's edge along axis i and box 2's edge along axis j (box 1's frame).

    corners (bits 0-3): the edges' corners are on the + side of box 1's axes i+1, i+2 and box 2's
    axes j+1, j+2. Parameters: s along e_i (|s| <= size1[i]) and t along box 2's axis j: solved
    unclamped (s = 0 when the edges are parallel, 1 - b² < MINVAL), then s clipped, t re-solved
    and clipped, s re-solved and clipped. states (bit 0: parallel; bits 1-2, 3-4, 5-6: the three
    _clip_state's) are decided here (replay False) or frozen (replay True). Returns
    (p1, p2, states): p1 on box 1's edge, p2 on box 2's.
    """
    c1, cc, c2, d2, e = _edge_witness_terms(rot, pos21, size1, size2, i, j, corners)
    b = d2[i]  # cosine between the edges
    denom = 1 - b * b
    d1e = e[i]
    d2e = dot3(d2, e)
    st = states
    if ti.static(not replay):
        st = _bit(denom < MINVAL)
    s = 0.0
    if st & 1 == 0:
        s = (d1e - b * d2e) / denom
    if ti.static(not replay):
        st |= _clip_state(s, size1[i]) << 1
    s = _clip_apply(s, (st >> 1) & 3, size1[i])
    t = b * s - d2e
    if ti.static(not replay):
        st |= _clip_state(t, size2[j]) << 3
    t = _clip_apply(t, (st >> 3) & 3, size2[j])
    s = d1e + b * t
    if ti.static(not replay):
        st |= _clip_state(s, size1[i]) << 5
    s = _clip_apply(s, (st >> 5) & 3, size1[i])
    p1 = c1
    p1[i] += s
    return p1, c2 + d2 * t, st


@ti.func
def _edge_witness_adjoint(rot: ti.template(), pos21: ti.template(), size1: ti.template(), size2: ti.template(), i, j,
                          corners, states, g_p1: ti.template(), g_p2: ti.template()):
    """Reverse of _edge_witness (states frozen): (g_rot, g_pos21) from the gradients of (p1, p2).
    A clipped parameter is a constant; parallel edges start from the constant s = 0."""
    _, cc, _, d2, e = _edge_witness_terms(rot, pos21, size1, size2, i, j, corners)
    b = d2[i]
    denom = 1 - b * b
    d2e = dot3(d2, e)
    s0 = 0.0
    if states & 1 == 0:
        s0 = (e[i] - b * d2e) / denom
    s1 = _clip_apply(s0, (states >> 1) & 3, size1[i])
    t = _clip_apply(b * s1 - d2e, (states >> 3) & 3, size2[j])
    # s2 = d1e + b t, then clipped into p1[i]
    g_s2 = ti.select((states >> 5) & 3 == 0, g_p1[i], 0.0)
    g_t = dot3(d2, g_p2) + g_s2 * b
    g_b = g_s2 * t
    g_d1e = g_s2
    # t = b s1 - d2e, clipped
    g_t = ti.select((states >> 3) & 3 == 0, g_t, 0.0)
    g_b += g_t * s1
    g_d2e = -g_t
    # s0 = (d1e - b d2e) / (1 - b²), clipped
    g_s0 = ti.select((states >> 1) & 3 == 0 and states & 1 == 0, g_t * b, 0.0)
    g_d1e += g_s0 / denom
    g_d2e -= g_s0 * b / denom
    g_b += (2 * b * s0 - d2e) * g_s0 / denom
    g_e = d2 * g_d2e
    g_e[i] += g_d1e
    g_c2 = g_p2 + g_e  # p2 = c2 + d2 t, e = c2 - c1
    g_rot = g_c2.outer_product(cc)  # c2 = rot cc + pos21
    g_d2 = g_p2 * t + e * g_d2e
    for r in ti.static(range(3)):
        g_rot[r, j] += g_d2[r]
    g_rot[i, j] += g_b
    return g_rot, g_c2


@ti.func
def _oriented_edge_axis(rot: ti.template(), i, j, flip):
    """The edge axis (i, j), negated when flip (so that it points from box 1 towards box 2)."""
    return _edge_axis(rot, i, j) * ti.select(flip, -1.0, 1.0)


@ti.func
def _edge_decide(rot: ti.template(), pos21: ti.template(), size1: ti.template(), size2: ti.template(), code, septol):
    """(hit, feature) of the edge contact of axis `code` (>= 6).

    The supporting corners follow the axis's signs (box 1's: along +axis, box 2's: along -axis);
    a component below the ambiguity scale makes both signs support (at most one per box): all
    choices are tried and the closest witness pair kept (first on ties). hit: its distance along
    the axis is <= septol.
    """
    sgn_eps = ti.static(_box_box_eps()[2])
    i, j = (code - 6) // 3, (code - 6) % 3
    i1, i2, j1, j2 = (i + 1) % 3, (i + 2) % 3, (j + 1) % 3, (j + 2) % 3
    flip = dot3(_edge_axis(rot, i, j), pos21) < 0
    axis = _oriented_edge_axis(rot, i, j, flip)
    a2 = _mat_t_vec(rot, axis)  # the axis in box 2's frame
    corners = _bit(axis[i1] >= 0) + 2 * _bit(axis[i2] >= 0) + 4 * _bit(a2[j1] < 0) + 8 * _bit(a2[j2] < 0)
    # the corner bit that may flip on either box (0 for none)
    amb1 = ti.select(ti.abs(axis[i1]) < sgn_eps, 1, ti.select(ti.abs(axis[i2]) < sgn_eps, 2, 0))
    amb2 = ti.select(ti.abs(a2[j1]) < sgn_eps, 4, ti.select(ti.abs(a2[j2]) < sgn_eps, 8, 0))
    n2 = 1 + _bit(amb2 != 0)
    best = _MAXVAL
    best_corners = corners
    best_states = 0
    dist = 0.0
    for v in range(n2 * (1 + _bit(amb1 != 0))):  # box 1's choice outer, box 2's inner
        tried = corners ^ (amb1 * (v // n2)) ^ (amb2 * (v % n2))
        p1, p2, st = _edge_witness(rot, pos21, size1, size2, i, j, tried, 0, False)
        gap = p2 - p1
        gap2 = dot3(gap, gap)
        closer = gap2 < best
        best = ti.select(closer, gap2, best)
        best_corners = ti.select(closer, tried, best_corners)
        best_states = ti.select(closer, st, best_states)
        dist = ti.select(closer, dot3(gap, axis), dist)
    feature = code | (_bit(flip) << 4) | (best_corners << 5) | (best_states << 9)
    return not dist > septol, feature


@ti.func
def _edge_points(rot: ti.template(), pos21: ti.template(), size1: ti.template(), size2: ti.template(), feature):
    """(p1, p2, axis) of an edge contact, box 1's frame: its witness pair and its oriented axis."""
    code = feature & 15
    i, j = (code - 6) // 3, (code - 6) % 3
    p1, p2, _ = _edge_witness(rot, pos21, size1, size2, i, j, (feature >> 5) & 15, feature >> 9, True)
    return p1, p2, _oriented_edge_axis(rot, i, j, (feature >> 4) & 1)


@ti.func
def _edge_evaluate(rot1: ti.template(), pos1: ti.template(), rot: ti.template(), pos21: ti.template(),
                   size1: ti.template(), size2: ti.template(), feature):
    """(position, normal, dist) of an edge contact (world): midpoint of the witness pair, the
    axis as normal, the witness gap along it as distance."""
    p1, p2, axis = _edge_points(rot, pos21, size1, size2, feature)
    mid = (p1 + p2) * 0.5
    return mat_vec(rot1, mid) + pos1, mat_vec(rot1, axis), dot3(p2 - p1, axis)


@ti.func
def _edge_evaluate_adjoint(rot1: ti.template(), rot: ti.template(), pos21: ti.template(), size1: ti.template(),
                           size2: ti.template(), feature, g_position: ti.template(), g_normal: ti.template(), g_dist):
    """Reverse of _edge_evaluate: (g_rot1, g_rot, g_pos21); pos1's gradient is g_position."""
    p1, p2, axis = _edge_points(rot, pos21, size1, size2, feature)
    code = feature & 15
    i, j = (code - 6) // 3, (code - 6) % 3
    corners, states = (feature >> 5) & 15, feature >> 9
    flip = ti.select((feature >> 4) & 1, -1.0, 1.0)
    g_rot1, g_mid = _mat_vec_adjoint(rot1, (p1 + p2) * 0.5, g_position)
    g_rot1_normal, g_axis = _mat_vec_adjoint(rot1, axis, g_normal)
    g_gap = axis * g_dist  # dist = (p2 - p1)·axis
    g_rot, g_pos21 = _edge_witness_adjoint(rot, pos21, size1, size2, i, j, corners, states, g_mid * 0.5 - g_gap,
                                           g_mid * 0.5 + g_gap)
    g_rot += _edge_axis_adjoint(rot, i, j, (g_axis + (p2 - p1) * g_dist) * flip)
    return g_rot1 + g_rot1_normal, g_rot, g_pos21


# ---------------------------------------------------------------- box – box: face contact
# Face coordinates of a reference face (axis a of the reference box, on the side sgn of the
# incident box): x, y along the reference box's axes a+1, a+2, z = height above the face plane
# (negative inside the reference box). The incident face is a parallelogram: centre cx and
# half-edge vectors du, dv; corner k is cx + su du + sv dv with (su, sv) = (1, 1), (-1, 1),
# (-1, -1), (1, -1) for k = 0 … 3.


@ti.func
def _incident_axes(rot: ti.template(), ref1):
    """The incident box's axes (columns) in the reference box's frame: rot, or rotᵀ if box 2 is
    the reference."""
    return ti.select(ref1, rot, rot.transpose())


@ti.func
def _incident_face(rinc: ti.template(), pos21: ti.template(), pos12: ti.template(), size1: ti.template(),
                   size2: ti.template(), code, sgn, binc, tinc):
    """(cx, du, dv, lim) of reference face `code` (< 6) and incident face (binc, side tinc).

    rinc: _incident_axes. cx, du, dv: the incident face's centre and half-edge vectors (face
    coordinates, m); lim: the reference face's half extents along x, y (m).
    """
    ref1 = code < 3
    a = code % 3
    sizeref = ti.select(ref1, size1, size2)
    sizeinc = ti.select(ref1, size2, size1)
    posoi = ti.select(ref1, pos21, pos12)
    bu, bv = (binc + 1) % 3, (binc + 2) % 3
    cx = ti.Vector.zero(float, 3)
    du = ti.Vector.zero(float, 3)
    dv = ti.Vector.zero(float, 3)
    for r in ti.static(range(3)):
        c = (a + 1 + r) % 3  # x, y, z = reference axes a+1, a+2, a
        cx[r] = posoi[c] + tinc * sizeinc[binc] * rinc[c, binc]
        du[r] = sizeinc[bu] * rinc[c, bu]
        dv[r] = sizeinc[bv] * rinc[c, bv]
    cx[2] = sgn * cx[2] - sizeref[a]
    du[2] *= sgn
    dv[2] *= sgn
    return cx, du, dv, ti.Vector([sizeref[(a + 1) % 3], sizeref[(a + 2) % 3]])


@ti.func
def _incident_face_adjoint(size1: ti.template(), size2: ti.template(), code, sgn, binc, tinc, g_cx: ti.template(),
                           g_du: ti.template(), g_dv: ti.template()):
    """Reverse of _incident_face: (g_rinc (3, 3), g_posoi (3,)) from the gradients of (cx, du, dv);
    posoi is pos21 when box 1 is the reference (code < 3), else pos12."""
    a = code % 3
    sizeinc = ti.select(code < 3, size2, size1)
    bu, bv = (binc + 1) % 3, (binc + 2) % 3
    g_rinc = ti.Matrix.zero(float, 3, 3)
    g_posoi = ti.Vector.zero(float, 3)
    for r in ti.static(range(3)):
        flip = sgn if r == 2 else 1.0  # the height (r = 2) is measured along sgn
        c = (a + 1 + r) % 3
        g_posoi[c] = g_cx[r] * flip
        g_rinc[c, binc] += g_cx[r] * flip * tinc * sizeinc[binc]
        g_rinc[c, bu] += g_du[r] * flip * sizeinc[bu]
        g_rinc[c, bv] += g_dv[r] * flip * sizeinc[bv]
    return g_rinc, g_posoi


@ti.func
def _face_corner(cx: ti.template(), du: ti.template(), dv: ti.template(), k):
    """Corner k (0 … 3) of the incident face, face coordinates."""
    su, sv = _corner_signs(k)
    return cx + su * du + sv * dv


@ti.func
def _corner_signs(k):
    """(su, sv) of the incident face's corner k: (1, 1), (-1, 1), (-1, -1), (1, -1)."""
    return ti.select(k == 0 or k == 3, 1.0, -1.0), ti.select(k < 2, 1.0, -1.0)


@ti.func
def _face_vertex(cx: ti.template(), du: ti.template(), dv: ti.template(), lim: ti.template(), tag):
    """Clipped-face vertex `tag` (face coordinates): an incident corner, an incident edge cut by a
    side plane of the reference face, or a reference-face corner lifted onto the incident plane."""
    k = ti.select(tag < _FACE_TAG_EDGE, tag, (tag - _FACE_TAG_EDGE) // 4) % 4  # the corner, or the edge's first
    v = _face_corner(cx, du, dv, k)
    if tag >= _FACE_TAG_RECT:
        x = ti.select((tag - _FACE_TAG_RECT) // 2, -lim[0], lim[0])
        y = ti.select((tag - _FACE_TAG_RECT) % 2, -lim[1], lim[1])
        nx = du[1] * dv[2] - du[2] * dv[1]  # incident face normal du × dv
        ny = du[2] * dv[0] - du[0] * dv[2]
        nz = du[0] * dv[1] - du[1] * dv[0]  # nonzero: binc is the incident face most facing the reference
        v = ti.Vector([x, y, cx[2] - (nx * (x - cx[0]) + ny * (y - cx[1])) / nz])
    elif tag >= _FACE_TAG_EDGE:
        plane = (tag - _FACE_TAG_EDGE) % 4
        q = _face_corner(cx, du, dv, (k + 1) % 4)
        c = plane // 2
        sign = 1.0 - 2.0 * (plane % 2)
        dp = sign * v[c] - lim[c]
        dq = sign * q[c] - lim[c]
        v = v + (dp / (dp - dq)) * (q - v)
    return v


@ti.func
def _face_vertex_adjoint(cx: ti.template(), du: ti.template(), dv: ti.template(), lim: ti.template(), tag,
                         g_v: ti.template()):
    """Reverse of _face_vertex: (g_cx, g_du, g_dv) from the gradient of the vertex. A reference
    corner's x, y are constants; its z is the incident plane's height there."""
    k = ti.select(tag < _FACE_TAG_EDGE, tag, (tag - _FACE_TAG_EDGE) // 4) % 4
    g_cx = ti.Vector.zero(float, 3)
    g_du = ti.Vector.zero(float, 3)
    g_dv = ti.Vector.zero(float, 3)
    g_start = g_v  # the gradient of corner k, and of corner k + 1 (a cut edge's end)
    g_end = ti.Vector.zero(float, 3)
    if tag >= _FACE_TAG_RECT:  # z = cx_z - (n_x (x - cx_x) + n_y (y - cx_y)) / n_z, n = du × dv
        g_start = ti.Vector.zero(float, 3)
        rel_x = ti.select((tag - _FACE_TAG_RECT) // 2, -lim[0], lim[0]) - cx[0]
        rel_y = ti.select((tag - _FACE_TAG_RECT) % 2, -lim[1], lim[1]) - cx[1]
        n = cross3(du, dv)
        g_rise = -g_v[2] / n[2]  # rise = n_x rel_x + n_y rel_y
        g_n = ti.Vector([g_rise * rel_x, g_rise * rel_y, -g_rise * (n[0] * rel_x + n[1] * rel_y) / n[2]])
        g_cx = ti.Vector([-g_rise * n[0], -g_rise * n[1], g_v[2]])
        g_du, g_dv = cross3_adjoint(du, dv, g_n)
    elif tag >= _FACE_TAG_EDGE:  # v + lam (q - v), lam = dp / (dp - dq)
        plane = (tag - _FACE_TAG_EDGE) % 4
        v = _face_corner(cx, du, dv, k)
        q = _face_corner(cx, du, dv, (k + 1) % 4)
        c = plane // 2
        sign = 1.0 - 2.0 * (plane % 2)
        dp = sign * v[c] - lim[c]
        dq = sign * q[c] - lim[c]
        lam = dp / (dp - dq)
        g_lam = dot3(g_v, q - v) / ((dp - dq) * (dp - dq))
        g_start = g_v * (1 - lam)
        g_start[c] -= sign * g_lam * dq
        g_end = g_v * lam
        g_end[c] += sign * g_lam * dp
    su, sv = _corner_signs(k)
    su1, sv1 = _corner_signs((k + 1) % 4)
    return g_cx + g_start + g_end, g_du + g_start * su + g_end * su1, g_dv + g_start * sv + g_end * sv1


@ti.func
def _clip_incident_face(cx: ti.template(), du: ti.template(), dv: ti.template(), lim: ti.template()):
    """Sutherland–Hodgman clipping of the incident face by the reference face's side planes
    (x <= lx, -x <= lx, y <= ly, -y <= ly, in that order), as MuJoCo: a pass whose vertices are
    all inside leaves the polygon as it is; a vertex on a plane (d = 0) is inside; an edge is cut
    only when it strictly crosses. Returns (n, poly, tag, at): the n vertices of the clipped
    polygon in face coordinates (z interpolated) are rows at … at + n - 1 of poly (18, 3), with
    their _face_vertex tags. Each vertex also carries the line its outgoing edge lies on
    (incident edge 0-3, side plane 4-7), so that a cut knows what it cuts.
    """
    poly = ti.Matrix.zero(float, 2 * _CLIP_ROWS, 3)  # two buffers: the polygon is at rows at … at + n - 1
    tag = ti.Vector.zero(ti.i32, 2 * _CLIP_ROWS)
    line = ti.Vector.zero(ti.i32, 2 * _CLIP_ROWS)
    for k in range(4):
        corner = _face_corner(cx, du, dv, k)
        for c in ti.static(range(3)):
            poly[k, c] = corner[c]
        tag[k] = k
        line[k] = k
    n = 4
    at = 0
    for plane in range(4):
        c = plane // 2
        sign = 1.0 - 2.0 * (plane % 2)
        inside = True
        for k in range(n):
            inside = inside and sign * poly[at + k, c] - lim[c] <= 0
        if not inside:
            to = _CLIP_ROWS - at
            m = 0
            for k in range(n):
                k1 = (k + 1) % n
                dp = sign * poly[at + k, c] - lim[c]
                dq = sign * poly[at + k1, c] - lim[c]
                # keep p (written to the next free row, which counts only if kept); its outgoing
                # edge runs along the plane if q is cut off
                for cc in ti.static(range(3)):
                    poly[to + m, cc] = poly[at + k, cc]
                tag[to + m] = tag[at + k]
                line[to + m] = ti.select(dp == 0 and dq > 0, 4 + plane, line[at + k])
                m += _bit(dp <= 0 and m < _MAXVERT)
                # the cut point where the edge p q strictly crosses the plane
                t = dp / (dp - dq)
                for cc in ti.static(range(3)):
                    poly[to + m, cc] = poly[at + k, cc] + t * (poly[at + k1, cc] - poly[at + k, cc])
                cut = line[at + k]
                tag[to + m] = ti.select(cut < 4, _FACE_TAG_EDGE + 4 * cut + plane,
                                        _FACE_TAG_RECT + 2 * (cut - 4) + plane - 2)
                line[to + m] = ti.select(dp < 0, 4 + plane, cut)
                m += _bit(((dp < 0 and dq > 0) or (dp > 0 and dq < 0)) and m < _MAXVERT)
            at = to
            n = m
    return n, poly, tag, at


@ti.func
def _face_decide(rot: ti.template(), pos21: ti.template(), pos12: ti.template(), size1: ti.template(),
                 size2: ti.template(), code, margin):
    """(count, feature (8,)) of the face contact of axis `code` (< 6): the clipped incident face's
    vertices with z <= margin, in polygon order, near-duplicates (closer in x, y than a
    DUPEPS-relative radius to an earlier one) dropped."""
    dupe_eps = ti.static(_box_box_eps()[3])
    ref1 = code < 3
    a = code % 3
    sgn = ti.select(ti.select(ref1, pos21[a], pos12[a]) >= 0, 1.0, -1.0)
    rinc = _incident_axes(rot, ref1)
    binc = 0
    for k in range(1, 3):  # the incident face most opposed to the reference normal
        if ti.abs(rinc[a, k]) > ti.abs(rinc[a, binc]):
            binc = k
    tinc = ti.select(sgn * rinc[a, binc] > 0, -1.0, 1.0)
    cx, du, dv, lim = _incident_face(rinc, pos21, pos12, size1, size2, code, sgn, binc, tinc)
    n, poly, tag, at = _clip_incident_face(cx, du, dv, lim)
    dupe2 = dupe_eps * (lim[0] * lim[0] + lim[1] * lim[1])
    head = code | (_bit(sgn > 0) << 4) | (_bit(tinc > 0) << 5) | (binc << 6)
    kept = ti.Matrix.zero(float, BOX_BOX_MAX, 2)
    feature = ti.Vector.zero(ti.i32, BOX_BOX_MAX)
    count = 0
    for k in range(at, at + n):
        dupe = False
        for q in range(count):
            dx = kept[q, 0] - poly[k, 0]
            dy = kept[q, 1] - poly[k, 1]
            dupe = dupe or dx * dx + dy * dy < dupe2
        keep = not (poly[k, 2] > margin or dupe)
        kept[count, 0] = poly[k, 0]  # row `count` is free: it counts only if kept
        kept[count, 1] = poly[k, 1]
        feature[count] = ti.select(keep, head | (tag[k] << 8), 0)
        count += _bit(keep)
    return count, feature


@ti.func
def _feature_incident_face(rot: ti.template(), pos21: ti.template(), pos12: ti.template(), size1: ti.template(),
                           size2: ti.template(), feature):
    """_incident_face (cx, du, dv, lim) of a face contact's feature."""
    code = feature & 15
    return _incident_face(_incident_axes(rot, code < 3), pos21, pos12, size1, size2, code,
                          ti.select((feature >> 4) & 1, 1.0, -1.0), (feature >> 6) & 3,
                          ti.select((feature >> 5) & 1, 1.0, -1.0))


@ti.func
def _face_point(rot1: ti.template(), rot2: ti.template(), rot: ti.template(), pos21: ti.template(),
                pos12: ti.template(), size1: ti.template(), size2: ti.template(), feature):
    """(v, local, rotref) of a face contact: its vertex v (face coordinates), the contact point
    `local` in the reference box's frame (midway between the face plane and v's height) and that
    box's rotation."""
    code = feature & 15
    ref1 = code < 3
    a = code % 3
    cx, du, dv, lim = _feature_incident_face(rot, pos21, pos12, size1, size2, feature)
    v = _face_vertex(cx, du, dv, lim, (feature >> 8) & 31)
    local = ti.Vector.zero(float, 3)
    local[(a + 1) % 3] = v[0]
    local[(a + 2) % 3] = v[1]
    local[a] = ti.select((feature >> 4) & 1, 1.0, -1.0) * (ti.select(ref1, size1[a], size2[a]) + 0.5 * v[2])
    return v, local, ti.select(ref1, rot1, rot2)


@ti.func
def _face_evaluate(pos1: ti.template(), rot1: ti.template(), pos2: ti.template(), rot2: ti.template(),
                   rot: ti.template(), pos21: ti.template(), pos12: ti.template(), size1: ti.template(),
                   size2: ti.template(), feature):
    """(position, normal, dist) of a face contact (world): the vertex's (x, y) on the reference
    face, midway between the face plane and the incident surface along the normal; normal along
    the reference face's axis, from box 1 to box 2; dist = the vertex's height z."""
    v, local, rotref = _face_point(rot1, rot2, rot, pos21, pos12, size1, size2, feature)
    code = feature & 15
    ref1 = code < 3
    a = code % 3
    nsign = ti.select(ref1, 1.0, -1.0) * ti.select((feature >> 4) & 1, 1.0, -1.0)
    normal = ti.Vector([nsign * rotref[0, a], nsign * rotref[1, a], nsign * rotref[2, a]])
    return mat_vec(rotref, local) + ti.select(ref1, pos1, pos2), normal, v[2]


@ti.func
def _face_evaluate_adjoint(pos1: ti.template(), rot1: ti.template(), pos2: ti.template(), rot2: ti.template(),
                           rot: ti.template(), pos21: ti.template(), pos12: ti.template(), size1: ti.template(),
                           size2: ti.template(), feature, g_position: ti.template(), g_normal: ti.template(), g_dist):
    """Reverse of _face_evaluate: (g_posref, g_rotref, g_rot, g_posoi) — the gradients of the
    reference box's pose (box 1's when code < 3, else box 2's), of rot and of posoi (pos21 when
    code < 3, else pos12)."""
    _, local, rotref = _face_point(rot1, rot2, rot, pos21, pos12, size1, size2, feature)
    cx, du, dv, lim = _feature_incident_face(rot, pos21, pos12, size1, size2, feature)
    code = feature & 15
    ref1 = code < 3
    a = code % 3
    sgn = ti.select((feature >> 4) & 1, 1.0, -1.0)
    g_rotref, g_local = _mat_vec_adjoint(rotref, local, g_position)
    nsign = ti.select(ref1, sgn, -sgn)
    for r in ti.static(range(3)):
        g_rotref[r, a] += nsign * g_normal[r]
    g_v = ti.Vector([g_local[(a + 1) % 3], g_local[(a + 2) % 3], 0.5 * sgn * g_local[a] + g_dist])
    g_cx, g_du, g_dv = _face_vertex_adjoint(cx, du, dv, lim, (feature >> 8) & 31, g_v)
    g_rinc, g_posoi = _incident_face_adjoint(size1, size2, code, sgn, (feature >> 6) & 3,
                                             ti.select((feature >> 5) & 1, 1.0, -1.0), g_cx, g_du, g_dv)
    return g_position, g_rotref, _incident_axes(g_rinc, ref1), g_posoi


@ti.func
def box_box_decide(pos1: ti.template(), rot1: ti.template(), size1: ti.template(), pos2: ti.template(),
                   rot2: ti.template(), size2: ti.template(), margin):
    """(count, feature (8,)) of box (half sizes size1) – box (size2): the separating axis, then
    the clipped face's vertices or the one edge contact (features: the box–box section)."""
    sep_eps = ti.static(_box_box_eps()[0])
    rot, pos21, pos12 = _box_pair(pos1, rot1, pos2, rot2)
    septol = margin + sep_eps * (size1[0] + size1[1] + size1[2] + size2[0] + size2[1] + size2[2])
    separated, code, sep_best, code_face, sep_face = _separating_axis(rot, pos21, pos12, size1, size2, septol)
    count = 0
    feature = ti.Vector.zero(ti.i32, BOX_BOX_MAX)
    if not separated:
        code = _face_for_aliased_edge(rot, code, sep_best, code_face, sep_face)
        if code >= 6:
            hit, edge_feature = _edge_decide(rot, pos21, size1, size2, code, septol)
            if hit:
                feature[0] = edge_feature
                count = 1
        else:
            count, feature = _face_decide(rot, pos21, pos12, size1, size2, code, margin)
    return count, feature


@ti.func
def box_box_evaluate(pos1: ti.template(), rot1: ti.template(), size1: ti.template(), pos2: ti.template(),
                     rot2: ti.template(), size2: ti.template(), feature):
    """(position, normal, dist) of a box–box contact with its feature frozen (world)."""
    rot, pos21, pos12 = _box_pair(pos1, rot1, pos2, rot2)
    position = ti.Vector.zero(float, 3)
    normal = ti.Vector.zero(float, 3)
    dist = 0.0
    if feature & 15 >= 6:
        position, normal, dist = _edge_evaluate(rot1, pos1, rot, pos21, size1, size2, feature)
    else:
        position, normal, dist = _face_evaluate(pos1, rot1, pos2, rot2, rot, pos21, pos12, size1, size2, feature)
    return position, normal, dist


@ti.func
def box_box_evaluate_adjoint(pos1: ti.template(), rot1: ti.template(), size1: ti.template(), pos2: ti.template(),
                             rot2: ti.template(), size2: ti.template(), feature, g_position: ti.template(),
                             g_normal: ti.template(), g_dist):
    """Reverse of box_box_evaluate: (g_pos1 (3,), g_rot1 (3, 3), g_pos2 (3,), g_rot2 (3, 3)) from
    the gradients of (position, normal, dist)."""
    rot, pos21, pos12 = _box_pair(pos1, rot1, pos2, rot2)
    zero3 = ti.Vector.zero(float, 3)
    zero33 = ti.Matrix.zero(float, 3, 3)
    g_pos1, g_rot1, g_pos2, g_rot2 = g_position, zero33, zero3, zero33  # an edge contact's position is box 1's
    g_rot, g_pos21, g_pos12 = zero33, zero3, zero3
    if feature & 15 >= 6:
        g_rot1, g_rot, g_pos21 = _edge_evaluate_adjoint(rot1, rot, pos21, size1, size2, feature, g_position, g_normal,
                                                        g_dist)
    else:
        ref1 = feature & 15 < 3
        g_posref, g_rotref, g_rot, g_posoi = _face_evaluate_adjoint(pos1, rot1, pos2, rot2, rot, pos21, pos12, size1,
                                                                    size2, feature, g_position, g_normal, g_dist)
        g_pos1, g_rot1 = ti.select(ref1, g_posref, zero3), ti.select(ref1, g_rotref, zero33)
        g_pos2, g_rot2 = ti.select(ref1, zero3, g_posref), ti.select(ref1, zero33, g_rotref)
        g_pos21, g_pos12 = ti.select(ref1, g_posoi, zero3), ti.select(ref1, zero3, g_posoi)
    p1, r1, p2, r2 = _box_pair_adjoint(pos1, rot1, pos2, rot2, g_rot, g_pos21, g_pos12)
    return g_pos1 + p1, g_rot1 + r1, g_pos2 + p2, g_rot2 + r2


box_box = collider(box_box_decide, box_box_evaluate, BOX_BOX_MAX,
                    "Box – box (mjc_BoxBox): at most 8 contacts (a clipped face's vertices, or one edge contact).")
