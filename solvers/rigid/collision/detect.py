"""Collision stage of one env's substep: geom poses, a bounding-sphere broad phase over the
candidate pairs (built once, geometry.py), and each pair's collider → the contact list.

The pairs of one kind (type 1, type 2) are handled together (``collide_kind``, a kernel of its
own: a scene compiles the colliders it uses, and no kernel holds them all). Contacts are
appended to con_*[s, e, 0 … n_con), kind by kind, in pair order within a kind; a pair's
contacts come in its collider's order, as MuJoCo lists them. More contacts than slots sets the
header's overflow flag (the solver raises) instead of writing past the end.
"""
import taichi as ti

from ..geometry import BOX, CAPSULE, CYLINDER, PLANE, SPHERE
from ..spatial import mat_mul, mat_vec, quat_to_mat
from . import box, primitive
from .frame import contact_frame


@ti.func
def geom_poses(d: ti.template(), s, e):
    """geom_xpos[s, e, g] (m) and geom_xmat[s, e, g] (columns: the geom's axes) from its link's pose."""
    for g in range(d.n_geoms):
        link = d.geom_link[g]
        rot = quat_to_mat(d.xquat[s, e, link])
        d.geom_xpos[s, e, g] = d.xpos[s, e, link] + mat_vec(rot, d.geom_pos[g])
        d.geom_xmat[s, e, g] = mat_mul(rot, quat_to_mat(d.geom_quat[g]))


@ti.func
def _may_touch(d: ti.template(), s, e, pair):
    """Broad phase: False when the pair's bounding spheres (or a plane and a bounding sphere) are
    further apart than its margin, so that its collider cannot find a contact."""
    g1, g2 = d.pair_geom1[pair], d.pair_geom2[pair]
    p1, p2 = d.geom_xpos[s, e, g1], d.geom_xpos[s, e, g2]
    gap = (p2 - p1).norm() - d.geom_rbound[g1] - d.geom_rbound[g2]
    if d.geom_type[g1] == PLANE:  # the plane's normal is its z axis
        normal = ti.Vector([d.geom_xmat[s, e, g1][k, 2] for k in ti.static(range(3))])
        gap = normal.dot(p2 - p1) - d.geom_rbound[g2]
    return gap < d.pair_margin[pair]


@ti.func
def _append(d: ti.template(), s, e, pair, count, position, normal, dist, feature, tangent):
    """Add a collider's first ``count`` contacts (rows of position, normal, dist, feature)."""
    n = d.n_con[s, e, 0]
    for k in ti.static(range(dist.n)):
        if k < count:
            if n < d.contact_capacity:
                d.con_pair[s, e, n] = pair
                d.con_feature[s, e, n] = feature[k]
                d.con_pos[s, e, n] = ti.Vector([position[k, j] for j in ti.static(range(3))])
                d.con_frame[s, e, n] = contact_frame(ti.Vector([normal[k, j] for j in ti.static(range(3))]), tangent)
                d.con_dist[s, e, n] = dist[k]
                n += 1
            else:
                d.overflow[0] = 1
    d.n_con[s, e, 0] = n


def _posed(collider):
    """A primitive collider called with the two geoms' poses and sizes at frame s."""
    @ti.func
    def call(d: ti.template(), s, e, g1, g2, margin):
        return collider(d.geom_xpos[s, e, g1], d.geom_xmat[s, e, g1], d.geom_size[g1],
                        d.geom_xpos[s, e, g2], d.geom_xmat[s, e, g2], d.geom_size[g2], margin)
    return call


# (type 1, type 2) → (collider, its contact budget, whether MuJoCo's frame takes geom 2's axis as
# its first tangent)
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
COLLIDERS = {kind: (_posed(collider), tangent) for kind, (collider, _, tangent) in PRIMITIVES.items()}
BUDGET = {kind: budget for kind, (_, budget, _) in PRIMITIVES.items()}  # contacts a pair may give


@ti.func
def collide_kind(d: ti.template(), s, e, kind: ti.template()):
    """Frame s's contacts of env e from the candidate pairs of one kind (type 1, type 2), in pair
    order, appended to the contact list."""
    collider, axis_tangent = ti.static(COLLIDERS[kind])
    for pair in range(d.n_candidates):
        g1, g2 = d.pair_geom1[pair], d.pair_geom2[pair]
        if d.geom_type[g1] == kind[0] and d.geom_type[g2] == kind[1] and _may_touch(d, s, e, pair):
            count, position, normal, dist, feature = collider(d, s, e, g1, g2, d.pair_margin[pair])
            tangent = ti.Vector.zero(float, 3)
            if ti.static(axis_tangent):
                tangent = ti.Vector([d.geom_xmat[s, e, g2][k, 2] for k in ti.static(range(3))])
            _append(d, s, e, pair, count, position, normal, dist, feature, tangent)
