"""Collision stage of one env's substep: geom poses, a broad phase over the candidate pairs
(built once, geometry.py: bounding spheres, then bounding boxes, as MuJoCo), and each pair's
collider → the contact list.

Colliders: the primitive ones (primitive.py, box.py) and, for meshes and the cylinder pairs
MuJoCo sends to its general convex collider, convex.py's plane_mesh and convex_convex (meshes as
their convex hull; the hull data and the workspace are arrays of the scene's storage, data.py).

The broad phase (``near_pairs``) runs in the smooth stage's kernel and lists each env's near
pairs. The pairs of one kind (type 1, type 2) are handled together (``collide_kind``, a kernel of
its own: a scene compiles the colliders it uses, and no kernel holds them all; every
convex_convex kind may share one kernel, ``kernel_kinds``), which runs in a substep only when some
env has a near pair of its kind (the header's colliders_due mask, read by the host). Contacts are
appended to con_*[s, e, 0 … n_con), kind by kind, in pair order within a kind; a pair's
contacts come in its collider's order, as MuJoCo lists them. More contacts than slots sets the
header's overflow flag (the solver raises) instead of writing past the end.
"""
import warnings

import taichi as ti
from taichi.lang import impl

from ..data import ArrayView, accumulate
from ..geometry import BOX, CAPSULE, CYLINDER, HFIELD, MESH, PLANE, SPHERE
from ..spatial import mat_vec, quat_to_mat
from . import box, convex, hfield, primitive
from .frame import column, contact_frame, contact_frame_adjoint


@ti.func
def geom_poses(d: ti.template(), s, e):
    """geom_xpos[s, e, g] (m) and geom_xmat[s, e, g] (columns: the geom's axes) from its link's pose,
    rounded as MuJoCo's mj_local2Global: the axes are the matrix of the product of the quaternions
    (_turned), so that a geom turned in its body and placed exactly on a plane touches it where
    MuJoCo's does (with the product of the two matrices, a bit off, a capsule's fromto did not)."""
    for g in range(d.n_geoms):
        link = d.geom_link[g]
        d.geom_xpos[s, e, g] = d.xpos[s, e, link] + mat_vec(quat_to_mat(d.xquat[s, e, link]), d.geom_pos[g])
        d.geom_xmat[s, e, g] = quat_to_mat(_turned(d.xquat[s, e, link], d.geom_quat[g]))


@ti.func
def _turned(a, b):
    """The Hamilton product a ⊗ b (4,) rounded as in MuJoCo 4.0's mj_local2Global (its x86-64 build
    sums each component's four products in pairs, (1st + 2nd) + (3rd + 4th), as its mju_mulQuat:
    read in its machine code, checked bit for bit). Its kinematics and integration round as
    spatial.quat_mul, left to right (a drop of two meshes stayed 1e-13 from MuJoCo's over 2 s
    that way, 4e-11 with pairs)."""
    return ti.Vector([(a[0] * b[0] - a[1] * b[1]) + (-(a[2] * b[2]) - a[3] * b[3]),
                      (a[0] * b[1] + a[1] * b[0]) + (a[2] * b[3] - a[3] * b[2]),
                      (a[0] * b[2] - a[1] * b[3]) + (a[2] * b[0] + a[3] * b[1]),
                      (a[0] * b[3] + a[1] * b[2]) + (-(a[2] * b[1]) + a[3] * b[0])])


@ti.func
def _may_touch(d: ti.template(), s, e, pair):
    """Broad phase: False when the pair's bounding volumes are further apart than its margin, so
    that its collider cannot find a contact: the bounding spheres (a plane and a sphere; as
    MuJoCo's, a pair exactly at the margin is kept), then the
    bounding boxes (geom_aabb_*) on the six axes of their faces, apart only beyond the margin, as
    MuJoCo's mj_collideOBB (which MuJoCo runs between bodies of several geoms); a plane tests the
    box's lowest point. The box tests add a slack to the margin (_box_slack: above their round-off
    and above box–box's own tolerance, which keeps contacts a hair apart), so they change which
    colliders run, never a contact."""
    g1, g2 = d.pair_geom1[pair], d.pair_geom2[pair]
    p1, p2 = d.geom_xpos[s, e, g1], d.geom_xpos[s, e, g2]
    margin = d.pair_margin[pair]
    near = False
    if d.geom_type[g1] == PLANE:  # the plane's normal is its z axis
        normal = column(d.geom_xmat[s, e, g1], 2)
        near = normal.dot(p2 - p1) <= margin + d.geom_rbound[g2]  # (as MuJoCo: kept at equality)
        if near:
            centre2, rot2, half2 = _box_of(d, s, e, g2)
            slack = _box_slack(half2.sum() + (centre2 - p1).norm())
            near = normal.dot(centre2 - p1) - _box_radius(rot2, half2, normal) <= margin + slack
    else:
        gap, bound = p1 - p2, d.geom_rbound[g1] + d.geom_rbound[g2] + margin  # MuJoCo's filterSphere
        near = gap[0] * gap[0] + gap[1] * gap[1] + gap[2] * gap[2] <= bound * bound
        if near:
            near = _boxes_overlap(d, s, e, g1, g2, margin)
    return near


@ti.func
def _box_slack(scale):
    """Distance (m) the box tests add to the margin for boxes of summed sizes and offsets ``scale``
    (m): above their round-off and above box–box's separation tolerance (box._box_box_eps: 1e-6 and
    1e-13 of the summed sizes in float32 and float64), so that no contact a collider would keep is
    lost; ~1e-6 m in float32."""
    relative = ti.static(1e-5 if impl.get_runtime().default_fp == ti.f32 else 1e-12)
    return relative * scale


@ti.func
def _box_of(d: ti.template(), s, e, g):
    """(centre (3,) m, rotation (3×3, columns the axes), half extents (3,) m) of geom g's bounding
    box in frame s of env e."""
    rot = d.geom_xmat[s, e, g]
    return d.geom_xpos[s, e, g] + mat_vec(rot, d.geom_aabb_center[g]), rot, d.geom_aabb_half[g]


@ti.func
def _box_radius(rot, half, axis):
    """Half the extent (m) of a box (rotation rot, half extents half) along the unit axis (3,)."""
    return (ti.abs(half[0] * column(rot, 0).dot(axis)) + ti.abs(half[1] * column(rot, 1).dot(axis))
            + ti.abs(half[2] * column(rot, 2).dot(axis)))


@ti.func
def _boxes_overlap(d: ti.template(), s, e, g1, g2, margin):
    """Whether the bounding boxes of geoms g1 and g2, grown by margin, overlap along each of the
    six face normals (separating-axis test on those axes, as MuJoCo's mj_collideOBB)."""
    centre1, rot1, half1 = _box_of(d, s, e, g1)
    centre2, rot2, half2 = _box_of(d, s, e, g2)
    offset = centre2 - centre1
    reach_beyond = margin + _box_slack(half1.sum() + half2.sum() + offset.norm())
    overlap = True
    for k in ti.static(range(3)):
        for axis in ti.static((column(rot1, k), column(rot2, k))):
            reach = _box_radius(rot1, half1, axis) + _box_radius(rot2, half2, axis) + reach_beyond
            if reach < ti.abs(offset.dot(axis)):
                overlap = False
    return overlap


@ti.func
def _append(d: ti.template(), s, e, pair, count, position, normal, dist, feature, tangent):
    """Add a collider's first ``count`` contacts (rows of position, normal, dist, feature: (K,)
    one int per contact, or (K, FEATURE_SIZE) for the convex colliders), each contact's feature
    as FEATURE_SIZE ints in con_feature[s, e, FEATURE_SIZE n ...] (a primitive's in the first)."""
    n = d.n_con[s, e, 0]
    for k in ti.static(range(dist.n)):
        if k < count:
            if n < d.contact_capacity:
                d.con_pair[s, e, n] = pair
                for j in ti.static(range(convex.FEATURE_SIZE)):
                    value = 0
                    if ti.static(len(feature.get_shape()) == 2):
                        value = feature[k, j]
                    elif ti.static(j == 0):
                        value = feature[k]
                    d.con_feature[s, e, convex.FEATURE_SIZE * n + j] = value
                d.con_pos[s, e, n] = ti.Vector([position[k, j] for j in ti.static(range(3))])
                d.con_frame[s, e, n] = contact_frame(ti.Vector([normal[k, j] for j in ti.static(range(3))]), tangent)
                d.con_dist[s, e, n] = dist[k]
                n += 1
            else:
                d.overflow[0] = 1
    d.n_con[s, e, 0] = n
    if n > 0:  # the constraint stage has rows to form
        d.constrained[0] = 1


@ti.func
def sort_contacts(d: ti.template(), s, e):
    """Frame s's contacts into candidate-pair order, MuJoCo's (by body pair, then geom pair): the
    colliders run kind by kind and append in kind order. Stable (a pair's contacts keep their
    collider's order), in place; an insertion sort, as the list is sorted within each kind."""
    for c in range(1, d.n_con[s, e, 0]):
        k = c
        while k > 0 and d.con_pair[s, e, k - 1] > d.con_pair[s, e, k]:
            _swap_contacts(d, s, e, k - 1, k)
            k -= 1


@ti.func
def _swap_contacts(d: ti.template(), s, e, a, b):
    """Exchange contacts a and b of frame s (everything a collider wrote of them)."""
    d.con_pair[s, e, a], d.con_pair[s, e, b] = d.con_pair[s, e, b], d.con_pair[s, e, a]
    d.con_pos[s, e, a], d.con_pos[s, e, b] = d.con_pos[s, e, b], d.con_pos[s, e, a]
    d.con_frame[s, e, a], d.con_frame[s, e, b] = d.con_frame[s, e, b], d.con_frame[s, e, a]
    d.con_dist[s, e, a], d.con_dist[s, e, b] = d.con_dist[s, e, b], d.con_dist[s, e, a]
    for j in range(convex.FEATURE_SIZE):
        fa, fb = convex.FEATURE_SIZE * a + j, convex.FEATURE_SIZE * b + j
        d.con_feature[s, e, fa], d.con_feature[s, e, fb] = d.con_feature[s, e, fb], d.con_feature[s, e, fa]


@ti.func
def _pair_poses(d: ti.template(), s, e, g1, g2):
    """(pos1, rot1, size1, pos2, rot2, size2) of geoms g1 and g2 at frame s: a primitive
    collider's (and its evaluate's) first arguments."""
    return (d.geom_xpos[s, e, g1], d.geom_xmat[s, e, g1], d.geom_size[g1],
            d.geom_xpos[s, e, g2], d.geom_xmat[s, e, g2], d.geom_size[g2])


def _posed(collider):
    """A primitive collider called with the two geoms' poses and sizes at frame s."""
    @ti.func
    def call(d: ti.template(), s, e, g1, g2, margin):
        p1, r1, z1, p2, r2, z2 = _pair_poses(d, s, e, g1, g2)
        return collider(p1, r1, z1, p2, r2, z2, margin)
    return call


class HullView:
    """Kernel-scope view of the meshes' hulls in a RigidView ``d`` with convex.MeshHulls' names
    (the ``hull`` argument of the convex colliders): d.hull_vec holds the vertices then the
    polygon normals, d.hull_int a header of where each int array starts, then the arrays
    (geometry.hull_arrays). Each start is loaded once, into a local."""
    _data_oriented = True

    def __init__(self, d):
        ints, vecs = d.hull_int, d.hull_vec
        for k, name in enumerate(convex.HULL_INT_FIELDS):
            setattr(self, name, ArrayView(ints.arena, impl.expr_init(ints.start + ints[k]), (1,)))
        self.hull_vert = vecs
        self.hull_poly_normal = ArrayView(vecs.arena, impl.expr_init(vecs.start + ints[len(convex.HULL_INT_FIELDS)]),
                                          (1,))


# HullView runs as Python while Taichi builds a kernel, on purpose: it only creates the view
warnings.filterwarnings("ignore", message='.*Calling non-taichi function "HullView"', category=SyntaxWarning)


@ti.func
def _plane_mesh(d: ti.template(), s, e, g1, g2, margin):
    """convex.plane_mesh on geoms g1 (the plane) and g2 (a mesh) at frame s."""
    return convex.plane_mesh(d.geom_xpos[s, e, g1], d.geom_xmat[s, e, g1], d.geom_size[g1], d.geom_xpos[s, e, g2],
                             d.geom_xmat[s, e, g2], d.geom_size[g2], d.geom_mesh[g2], d.geom_centre[g2], margin,
                             HullView(d))


@ti.func
def _convex_convex(d: ti.template(), s, e, g1, g2, margin):
    """convex.convex_convex on geoms g1 and g2 at frame s, env e's row of the workspace (the
    types are run-time values: one compiled kernel serves every convex pair kind)."""
    return convex.convex_convex(d.geom_type[g1], d.geom_xpos[s, e, g1], d.geom_xmat[s, e, g1], d.geom_size[g1],
                                d.geom_mesh[g1], d.geom_type[g2], d.geom_xpos[s, e, g2], d.geom_xmat[s, e, g2],
                                d.geom_size[g2], d.geom_mesh[g2], margin, HullView(d), d, (e,))


@ti.func
def _plane_cylinder(d: ti.template(), s, e, g1, g2, margin):
    """primitive.plane_cylinder (MuJoCo's) under enable_mujoco_compatibility, else
    plane_cylinder_standing (a standing cylinder on four rim points)."""
    p1, r1, z1, p2, r2, z2 = _pair_poses(d, s, e, g1, g2)
    count, position, normal, dist = 0, ti.Matrix.zero(float, primitive.PLANE_CYLINDER_MAX, 3), \
        ti.Matrix.zero(float, primitive.PLANE_CYLINDER_MAX, 3), ti.Vector.zero(float, primitive.PLANE_CYLINDER_MAX)
    feature = ti.Vector.zero(ti.i32, primitive.PLANE_CYLINDER_MAX)
    if d.converged:
        count, position, normal, dist, feature = primitive.plane_cylinder_standing(p1, r1, z1, p2, r2, z2, margin)
    else:
        count, position, normal, dist, feature = primitive.plane_cylinder(p1, r1, z1, p2, r2, z2, margin)
    return count, position, normal, dist, feature


@ti.func
def _hfield_collide(d: ti.template(), s, e, pair, g1, g2):
    """Frame s's contacts of a height field (g1) with a convex geom (g2), appended (hfield.py):
    the prisms of the cells under g2's bounding box whose top reaches its bottom, row by row, one
    convex CCD each (convex.prism_convex), at most hfield.HFIELD_MAX contacts, in MuJoCo's order.
    Without the pair's margin: every pair's is 0 (model.pair_margin; MuJoCo's height field raises
    the prisms' tops by it and grows g2 by half of it, which a margin here would have to take)."""
    pos1, rot1, size1, grid = d.geom_xpos[s, e, g1], d.geom_xmat[s, e, g1], d.geom_size[g1], d.geom_mesh[g1]
    pos2, rot2 = d.geom_xpos[s, e, g2], d.geom_xmat[s, e, g2]
    hull = HullView(d)
    ncol = int(size1[2])
    nrow = hull.hull_vertnum[grid] // 2 // ncol
    lowest, highest = hfield.local_box(pos1, rot1, pos2, rot2, d.geom_aabb_center[g2], d.geom_aabb_half[g2])
    rmin, rmax, cmin, cmax = hfield.cell_range(size1, nrow, lowest, highest)
    adr, count = hull.hull_vertadr[grid], 0
    for r in range(rmin, rmax):
        for c in range(cmin + 1, cmax + 1):
            for i in range(2):
                triangle = hfield.triangle(r, c, i, ncol)
                top = ti.max(hull.hull_vert[adr + int(triangle[0])][2], hull.hull_vert[adr + int(triangle[1])][2],
                             hull.hull_vert[adr + int(triangle[2])][2])
                if count < hfield.HFIELD_MAX and top >= lowest[2]:  # (MuJoCo's prism height test)
                    found, position, normal, dist, feature = convex.prism_convex(
                        pos1, rot1, grid, triangle, d.geom_type[g2], pos2, rot2, d.geom_size[g2], d.geom_mesh[g2],
                        hull, d, (e,))
                    if found:
                        _append(d, s, e, pair, 1, position, normal, dist, feature, ti.Vector.zero(float, 3))
                        count += 1


# (type 1, type 2) → (collider, its contact budget, whether MuJoCo's frame takes geom 2's axis as
# its first tangent; the convex colliders' contacts take MuJoCo's default frame)
P, B = primitive, box
PRIMITIVES = {(PLANE, SPHERE): (P.plane_sphere, P.PLANE_SPHERE_MAX, False),
              (PLANE, CAPSULE): (P.plane_capsule, P.PLANE_CAPSULE_MAX, True),
              (PLANE, CYLINDER): (P.plane_cylinder, P.PLANE_CYLINDER_MAX, False),
              (PLANE, BOX): (P.plane_box, P.PLANE_BOX_MAX, False),
              (SPHERE, SPHERE): (P.sphere_sphere, P.SPHERE_SPHERE_MAX, False),
              (SPHERE, CAPSULE): (P.sphere_capsule, P.SPHERE_CAPSULE_MAX, False),
              (SPHERE, CYLINDER): (P.sphere_cylinder, P.SPHERE_CYLINDER_MAX, False),
              (CAPSULE, CAPSULE): (P.capsule_capsule, P.CAPSULE_CAPSULE_MAX, False),
              (SPHERE, BOX): (B.sphere_box, B.SPHERE_BOX_MAX, False),
              (CAPSULE, BOX): (B.capsule_box, B.CAPSULE_BOX_MAX, False),
              (BOX, BOX): (B.box_box, B.BOX_BOX_MAX, False)}
CONVEX = {(PLANE, MESH): (_plane_mesh, convex.PLANE_MESH_MAX, False),
          **{kind: (_convex_convex, budget, False) for kind, budget in convex.CONVEX_BUDGET.items()}}
COLLIDERS = {**{kind: (_posed(collider), tangent) for kind, (collider, _, tangent) in PRIMITIVES.items()},
             **{kind: (collider, tangent) for kind, (collider, _, tangent) in CONVEX.items()},
             (PLANE, CYLINDER): (_plane_cylinder, False)}
BUDGET = {kind: budget for kind, (_, budget, _) in {**PRIMITIVES, **CONVEX}.items()}  # contacts a pair may give
# One kernel may serve every convex_convex pair kind (``kernel_kinds``): it is the slowest to compile
ALL_CONVEX = "convex"
COLLIDERS[ALL_CONVEX] = (_convex_convex, False)
# and one every height field's pair kind (a convex geom on a height field: _hfield_collide, which appends)
HFIELD_PAIRS = tuple((HFIELD, kind) for kind in (SPHERE, CAPSULE, CYLINDER, BOX, MESH))
ALL_HFIELD = "hfield"
COLLIDERS.update({kind: (None, False) for kind in (*HFIELD_PAIRS, ALL_HFIELD)})
BUDGET.update({kind: hfield.HFIELD_MAX for kind in HFIELD_PAIRS})
GROUPS = {ALL_CONVEX: convex.CONVEX_PAIRS, ALL_HFIELD: HFIELD_PAIRS}  # the kernels that serve several kinds

# Each collider kernel's bit in the header's colliders_due mask: a kernel runs in a substep only
# when the broad phase (near_pairs) found a pair of its kind in some env
KERNEL_BIT = {kind: bit for bit, kind in enumerate([*sorted(PRIMITIVES), (PLANE, MESH), ALL_CONVEX, ALL_HFIELD])}


@ti.func
def near_pairs(d: ti.template(), s, e):
    """The broad phase of frame s: near_pairs[s, e, 0 … n_near) ← the candidate pairs whose
    bounding volumes come within their margin (ascending; the colliders take only these); the
    header's colliders_due mask gets the bits (KERNEL_BIT) of the kernels they need."""
    n, due = 0, 0
    for pair in range(d.n_candidates):
        if _may_touch(d, s, e, pair):
            d.near_pairs[s, e, n] = pair
            n += 1
            type1, type2 = d.geom_type[d.pair_geom1[pair]], d.geom_type[d.pair_geom2[pair]]
            for kind in ti.static(list(KERNEL_BIT)):
                if _of_kind(type1, type2, kind):
                    due |= ti.static(1 << KERNEL_BIT[kind])
    d.n_near[s, e, 0] = n
    if due != 0:
        ti.atomic_or(d.colliders_due[0], due)


def _model_kinds(model):
    """The (type 1, type 2) kinds of the model's candidate pairs."""
    return {(int(model.geom_type[a]), int(model.geom_type[b])) for a, b in zip(model.pair_geom1, model.pair_geom2)}


def kernel_kinds(model):
    """The collider kernels a model needs: a pair kind (type 1, type 2) each, except that every
    convex_convex pair is handled by one kernel (ALL_CONVEX) and every height field pair by
    another (ALL_HFIELD), primitive kinds first, sorted."""
    kinds = _model_kinds(model)
    grouped = [group for group, members in GROUPS.items() if kinds & set(members)]
    return sorted(kinds - set(convex.CONVEX_PAIRS) - set(HFIELD_PAIRS)) + grouped


@ti.func
def _of_kind(type1, type2, kind: ti.template()):
    """Whether a pair of geom types (type1 <= type2) is handled by the kernel of ``kind``."""
    match = False
    if ti.static(kind in GROUPS):
        for other in ti.static(GROUPS[kind]):
            match = match or (type1 == other[0] and type2 == other[1])
    else:
        match = type1 == kind[0] and type2 == kind[1]
    return match


@ti.func
def collide_kind(d: ti.template(), s, e, kind: ti.template()):
    """Frame s's contacts of env e from the candidate pairs of one kind (type 1, type 2), or of
    every convex_convex kind (kind ALL_CONVEX), in pair order, appended to the contact list."""
    collider, axis_tangent = ti.static(COLLIDERS[kind])
    for q in range(d.n_near[s, e, 0]):  # the broad phase's pairs (near_pairs)
        pair = d.near_pairs[s, e, q]
        g1, g2 = d.pair_geom1[pair], d.pair_geom2[pair]
        if ti.static(kind == ALL_HFIELD):
            if _of_kind(d.geom_type[g1], d.geom_type[g2], kind):
                _hfield_collide(d, s, e, pair, g1, g2)
        elif _of_kind(d.geom_type[g1], d.geom_type[g2], kind):
            count, position, normal, dist, feature = collider(d, s, e, g1, g2, d.pair_margin[pair])
            tangent = ti.Vector.zero(float, 3)
            if ti.static(axis_tangent):
                tangent = ti.Vector([d.geom_xmat[s, e, g2][k, 2] for k in ti.static(range(3))])
            _append(d, s, e, pair, count, position, normal, dist, feature, tangent)


@ti.func
def _iterated_kind(d: ti.template(), s, e, c):
    """(iterated, frozen) of contact c of frame s (convex.iterated, convex.frozen; False, False
    for a contact of another collider than convex_convex)."""
    pair = d.con_pair[s, e, c]
    type1, type2 = d.geom_type[d.pair_geom1[pair]], d.geom_type[d.pair_geom2[pair]]
    iterated, held = False, False
    if _of_kind(type1, type2, ALL_CONVEX) or _of_kind(type1, type2, ALL_HFIELD):
        feature, margin = _feature_row(d, s, e, c), d.pair_margin[pair]
        iterated, held = convex.iterated(type1, type2, margin, feature), convex.frozen(type1, type2, margin, feature)
    return iterated, held


# a converged form this far from the iterate (times the smaller geom's bounding radius) is refused
FORM_APART = 0.1


@ti.func
def converge_contacts(d: ti.template(), s, e):
    """Frame s's convex_convex contacts that are not their closed form (convex.iterated: CCD
    iterates on curved supports, clipping corners on mesh polygons) become the closed form of
    their feature (convex.convex_evaluate): the step is then a closed form of the poses between feature changes,
    whose reverse is exact. Not where the closed form keeps part of the iterate (convex.frozen),
    nor where it is not finite (a degenerate feature) or its distance is FORM_APART from the
    iterate's (the inexact flag is raised: a backward over the step raises); where the iterate
    touches to within the CCD tolerance, the feature oriented either way, whichever form is
    nearer the iterate. Run after the colliders, as a kernel of its own (in theirs, it compiled 7 s
    slower)."""
    for c in range(d.n_con[s, e, 0]):
        iterated, held = _iterated_kind(d, s, e, c)
        if iterated and not held:
            pair = d.con_pair[s, e, c]
            g1, g2 = d.pair_geom1[pair], d.pair_geom2[pair]
            bar = FORM_APART * ti.min(d.geom_rbound[g1], d.geom_rbound[g2])
            iterate = d.con_dist[s, e, c]
            position, normal, dist, refused, gap = ti.Vector.zero(float, 3), ti.Vector.zero(float, 3), 0.0, True, 0.0
            for turn in range(2):  # one evaluation's call site (inlined once)
                # touching to within the CCD tolerance, the iterate's normal (its witness points'
                # difference, ~1e-9 m) has a sign of round-off, which orients the feature: its form
                # then took the far side (a can resting against a box's side: 2 r deep in most
                # steps; a thin rod's far side is within FORM_APART): of the two orientations, the
                # form nearer the iterate is taken
                if turn == 0 or ti.abs(iterate) < convex.CCD_TOLERANCE:
                    if turn == 1:
                        _flip_orientation(d, s, e, c)
                    form_position, form_normal, form_dist = _convex_replay(d, s, e, g1, g2, c)
                    total = form_position.sum() + form_normal.sum() + form_dist  # NaN or ±inf if one is not finite
                    # a form far from the iterate solved for another stationary point (a can beside
                    # a low box got one 2 r deep, sideways, and was launched at 18 m/s; in float32 a
                    # wide can over a box's corner one 113 mm deep): the iterate stays (up to 3 mm
                    # apart at deep random poses)
                    form_gap = ti.abs(form_dist - iterate)
                    form_refused = ti.math.isnan(total) or ti.math.isinf(total) or form_gap > bar
                    if turn == 0 or (not form_refused and (refused or form_gap < gap)):
                        position, normal, dist, refused, gap = form_position, form_normal, form_dist, form_refused, \
                            form_gap
                    elif turn == 1:
                        _flip_orientation(d, s, e, c)  # (the feature as the collider recorded it)
            if refused:
                flag_inexact(d, s, e, c)
            else:
                d.con_pos[s, e, c] = position
                d.con_frame[s, e, c] = contact_frame(normal, ti.Vector.zero(float, 3))
                d.con_dist[s, e, c] = dist


@ti.func
def _flip_orientation(d: ti.template(), s, e, c):
    """Contact c's feature oriented the other way: its normal's code (columns 8, 9) negated."""
    at = convex.FEATURE_SIZE * c
    code = d.con_feature[s, e, at + 8], d.con_feature[s, e, at + 9]
    flipped = convex.encode_direction(-convex.decode_direction(code[0], code[1]))
    d.con_feature[s, e, at + 8], d.con_feature[s, e, at + 9] = flipped[0], flipped[1]


# -- reverse: a contact's gradients (position, frame, distance) → its geoms' poses → their links ------
def _posed_reverse(evaluate, adjoint):
    """A primitive evaluate and its adjoint called on contact c's geoms at frame s with its
    recorded feature: (evaluate → (position, normal, dist), adjoint(g_position, g_normal, g_dist)
    → (g_pos1, g_rot1, g_pos2, g_rot2))."""
    @ti.func
    def replay(d: ti.template(), s, e, g1, g2, c):
        p1, r1, z1, p2, r2, z2 = _pair_poses(d, s, e, g1, g2)
        return evaluate(p1, r1, z1, p2, r2, z2, d.con_feature[s, e, convex.FEATURE_SIZE * c])

    @ti.func
    def reverse(d: ti.template(), s, e, g1, g2, c, g_position, g_normal, g_dist):
        p1, r1, z1, p2, r2, z2 = _pair_poses(d, s, e, g1, g2)
        return adjoint(p1, r1, z1, p2, r2, z2, d.con_feature[s, e, convex.FEATURE_SIZE * c], g_position, g_normal,
                       g_dist)
    return replay, reverse


# (type 1, type 2) → (replay, reverse) of its collider, for the kinds that have a reverse (every
# primitive kind, plane–mesh; convex_convex's replay is approximate on curved shapes: not yet)
_NAMES = {(PLANE, SPHERE): (P, "plane_sphere"), (PLANE, CAPSULE): (P, "plane_capsule"),
          (PLANE, CYLINDER): (P, "plane_cylinder"), (PLANE, BOX): (P, "plane_box"),
          (SPHERE, SPHERE): (P, "sphere_sphere"), (SPHERE, CAPSULE): (P, "sphere_capsule"),
          (SPHERE, CYLINDER): (P, "sphere_cylinder"), (CAPSULE, CAPSULE): (P, "capsule_capsule"),
          (SPHERE, BOX): (B, "sphere_box"), (CAPSULE, BOX): (B, "capsule_box"), (BOX, BOX): (B, "box_box")}
REVERSES = {kind: _posed_reverse(getattr(module, f"{name}_evaluate"), getattr(module, f"{name}_evaluate_adjoint"))
            for kind, (module, name) in _NAMES.items()}


@ti.func
def _feature_row(d: ti.template(), s, e, c):
    """Contact c's recorded feature: FEATURE_SIZE ints (the convex colliders' layout)."""
    return ti.Vector([d.con_feature[s, e, convex.FEATURE_SIZE * c + j] for j in ti.static(range(convex.FEATURE_SIZE))])


@ti.func
def _plane_mesh_replay(d: ti.template(), s, e, g1, g2, c):
    return convex.plane_mesh_evaluate(d.geom_xpos[s, e, g1], d.geom_xmat[s, e, g1], d.geom_size[g1],
                                      d.geom_xpos[s, e, g2], d.geom_xmat[s, e, g2], d.geom_size[g2], d.geom_mesh[g2],
                                      _feature_row(d, s, e, c), HullView(d))


@ti.func
def _plane_mesh_reverse(d: ti.template(), s, e, g1, g2, c, g_position, g_normal, g_dist):
    return convex.plane_mesh_evaluate_adjoint(d.geom_xpos[s, e, g1], d.geom_xmat[s, e, g1], d.geom_size[g1],
                                              d.geom_xpos[s, e, g2], d.geom_xmat[s, e, g2], d.geom_size[g2],
                                              d.geom_mesh[g2], _feature_row(d, s, e, c), HullView(d), g_position,
                                              g_normal, g_dist)


REVERSES[(PLANE, MESH)] = (_plane_mesh_replay, _plane_mesh_reverse)


@ti.func
def _convex_replay(d: ti.template(), s, e, g1, g2, c):
    return convex.convex_evaluate(d.geom_type[g1], d.geom_xpos[s, e, g1], d.geom_xmat[s, e, g1], d.geom_size[g1],
                                  d.geom_mesh[g1], d.geom_type[g2], d.geom_xpos[s, e, g2], d.geom_xmat[s, e, g2],
                                  d.geom_size[g2], d.geom_mesh[g2], d.pair_margin[d.con_pair[s, e, c]],
                                  _feature_row(d, s, e, c), HullView(d))


@ti.func
def _convex_reverse(d: ti.template(), s, e, g1, g2, c, g_position, g_normal, g_dist):
    return convex.convex_evaluate_adjoint(d.geom_type[g1], d.geom_xpos[s, e, g1], d.geom_xmat[s, e, g1],
                                          d.geom_size[g1], d.geom_mesh[g1], d.geom_type[g2], d.geom_xpos[s, e, g2],
                                          d.geom_xmat[s, e, g2], d.geom_size[g2], d.geom_mesh[g2],
                                          d.pair_margin[d.con_pair[s, e, c]], _feature_row(d, s, e, c), HullView(d),
                                          g_position, g_normal, g_dist)


# convex_convex's replay is its forward's own closed form between polytopes (boxes, meshes) without
# margin; on a curved geom (sphere, capsule, cylinder) or with a margin the forward iterates (EPA
# samples the balls, the cylinder's rim) and the replay is the converged form, up to the CCD
# tolerance away (tests/test_adjoints_convex.py). Unless converge_contacts made the forward's
# contact that form (and no direction is frozen), a backward over such a contact raises.
REVERSES[ALL_CONVEX] = REVERSES[ALL_HFIELD] = (_convex_replay, _convex_reverse)


@ti.func
def flag_inexact(d: ti.template(), s, e, c):
    """Raise the header's inexact flag for contact c of frame s, env e, and keep where it was (the
    backward's error names the pair, env and substep): the first to raise it writes (envs on the
    thread pool would mix their three values)."""
    if ti.atomic_or(d.inexact[0], 1) == 0:
        d.inexact_where[0], d.inexact_where[1], d.inexact_where[2] = d.con_pair[s, e, c], e, s


@ti.func
def replay_exact(d: ti.template(), s, e, c):
    """Whether contact c of frame s replays exactly: it is its collider's closed form, or a
    convex_convex iterate made that closed form (converge_contacts) with no direction frozen."""
    iterated, held = _iterated_kind(d, s, e, c)
    return not iterated or (d.converged and not held)


def inexact_kinds(model):
    """The model's candidate pair kinds (type 1, type 2) whose contacts may not be their closed
    form (convex.iterated): every convex_convex kind, with or without a margin, as each has a
    curved geom (CCD iterates) or a mesh (clipping corners on its polygons), and every height
    field kind (CCD too); box–box goes to box.py, whose contacts are closed forms."""
    return sorted(kind for kind in _model_kinds(model) if kind in convex.CONVEX_PAIRS or kind in HFIELD_PAIRS)



def differentiable_kinds(model):
    """Which of the model's collider kernels (kernel_kinds) have a reverse."""
    return [kind for kind in kernel_kinds(model) if kind in REVERSES]


@ti.func
def collide_adjoint_kind(d: ti.template(), s, e, kind: ti.template()):
    """Reverse of frame s's contacts of one pair kind: each contact's gradients (con_pos,
    con_frame, con_dist; from the rows' reverse) through its frame and its collider's closed
    form (feature frozen) into geom_xpos.grad and geom_xmat.grad (∂L/∂ each entry)."""
    replay, reverse = ti.static(REVERSES[kind])
    _, axis_tangent = ti.static(COLLIDERS[kind])
    for c in range(d.n_con[s, e, 0]):
        pair = d.con_pair[s, e, c]
        g1, g2 = d.pair_geom1[pair], d.pair_geom2[pair]
        if _of_kind(d.geom_type[g1], d.geom_type[g2], kind):
            position, normal, dist = replay(d, s, e, g1, g2, c)  # the normal before the frame renormalises it
            tangent = ti.Vector.zero(float, 3)
            if ti.static(axis_tangent):
                tangent = column(d.geom_xmat[s, e, g2], 2)
            g_normal, g_tangent = contact_frame_adjoint(normal, tangent, d.con_frame.grad[s, e, c])
            g_pos1, g_rot1, g_pos2, g_rot2 = reverse(d, s, e, g1, g2, c, d.con_pos.grad[s, e, c], g_normal,
                                                     d.con_dist.grad[s, e, c])
            if ti.static(axis_tangent):
                for k in ti.static(range(3)):
                    g_rot2[k, 2] += g_tangent[k]
            accumulate(d.geom_xpos.grad, ti.Vector([s, e, g1]), g_pos1)
            accumulate(d.geom_xmat.grad, ti.Vector([s, e, g1]), g_rot1)
            accumulate(d.geom_xpos.grad, ti.Vector([s, e, g2]), g_pos2)
            accumulate(d.geom_xmat.grad, ti.Vector([s, e, g2]), g_rot2)


@ti.func
def geom_poses_adjoint(d: ti.template(), s, e):
    """Reverse of geom_poses: each geom's gradients onto its link's pose (geom_pose_adjoint)."""
    for g in range(d.n_geoms):
        geom_pose_adjoint(d, s, e, g, d.geom_xpos.grad[s, e, g], d.geom_xmat.grad[s, e, g])


@ti.func
def geom_pose_adjoint(d: ti.template(), s, e, g, g_pos, g_mat):
    """Geom g's pose gradients at frame s (g_pos (3,) of geom_xpos, g_mat (3, 3) of geom_xmat) onto
    its link's origin and small turn δθ (a turn moves the geom's centre by δθ × (centre − origin)
    and each axis by δθ × axis)."""
    link, mat = d.geom_link[g], d.geom_xmat[s, e, g]
    g_rot = (d.geom_xpos[s, e, g] - d.xpos[s, e, link]).cross(g_pos)
    for j in ti.static(range(3)):
        g_rot += column(mat, j).cross(column(g_mat, j))
    accumulate(d.xpos.grad, ti.Vector([s, e, link]), g_pos)
    accumulate(d.xrot_grad, ti.Vector([s, e, link]), g_rot)
