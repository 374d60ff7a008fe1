"""Position stage: link poses, spatial inertias and joint motion subspaces from qpos.

Spatial quantities are expressed in the world frame about a point of each kinematic tree, its
root link's origin (MuJoCo's ``cdof`` and ``cinert`` idea, about the root's subtree centre of
mass there), so later stages are plain sweeps over the links. About the world origin instead, a
robot far from it pays for it in round-off: a float32 quadruped at x = 300 m had a mass matrix
that was not positive definite. The outputs of a step do not depend on the point (only their
round-off does), so the reverse takes it as a constant: the gradients stay exact. Inertias are formed
from the *current* inputs here, inside the differentiated step: each link's mass, centre of mass
and rotational inertia (the entity's setters choose whether a new mass scales the inertia).

Each forward function has its hand-written reverse below it (see docs/architecture.md).
"""
import taichi as ti

from .data import accumulate
from .model import BALL, FREE, PRISMATIC, REVOLUTE
from .spec import TENDON_JOINTS
from .spatial import (axis_angle_quat, mat_mul, mat_vec, normalized_adjoint, quat_conj, quat_mul, quat_normalized,
                      quat_to_mat)


@ti.func
def _joint_pose(d: ti.template(), s, e, l):
    """World pose (pos m, quat) of link l from its parent's pose and its joint coordinate."""
    jt = d.link_jtype[l]
    q0 = d.link_q0[l]
    pos = ti.Vector.zero(float, 3)
    quat = ti.Vector([1.0, 0.0, 0.0, 0.0])
    if jt == FREE:  # the coordinates are the world pose, whatever the parent
        pos = ti.Vector([d.qpos[s, e, q0 + k] for k in ti.static(range(3))])
        quat = quat_normalized(joint_quat(d, s, e, l))
    else:
        p = d.link_parent[l]
        if p >= 0:
            pos = d.xpos[s, e, p]
            quat = d.xquat[s, e, p]
        pos = pos + mat_vec(quat_to_mat(quat), d.link_pos0[l])
        quat = quat_mul(quat, d.link_quat0[l])
        if jt == REVOLUTE:
            quat = quat_mul(quat, axis_angle_quat(d.link_axis[l], d.qpos[s, e, q0]))
        elif jt == PRISMATIC:
            pos = pos + mat_vec(quat_to_mat(quat), d.link_axis[l]) * d.qpos[s, e, q0]
        elif jt == BALL:  # turned about its origin by its quaternion, in the joint frame
            quat = quat_mul(quat, quat_normalized(joint_quat(d, s, e, l)))
    return pos, quat


@ti.func
def joint_quat(d: ti.template(), s, e, l):
    """The raw (unnormalised) quaternion (4,) of link l's free or ball joint at frame s (a free
    joint's after its position)."""
    q0 = d.link_q0[l] + (3 if d.link_jtype[l] == FREE else 0)
    return ti.Vector([d.qpos[s, e, q0 + k] for k in ti.static(range(4))])


@ti.func
def reference(d: ti.template(), s, e, l):
    """The point link l's spatial quantities are taken about at frame s: its tree's root link
    origin (world, m). Its root's pose is known before it (parents come first)."""
    return d.xpos[s, e, d.link_root[l]]


@ti.func
def _link_com(d: ti.template(), e, l):
    """Link l's centre of mass in its frame (m): the input com."""
    return ti.Vector([d.com[e, 3 * l + k] for k in ti.static(range(3))])


@ti.func
def _link_rotational_inertia(d: ti.template(), e, l):
    """Link l's rotational inertia about its centre of mass in its frame (kg·m²): the input inertia."""
    return ti.Matrix([[d.inertia[e, 9 * l + 3 * a + b] for b in ti.static(range(3))] for a in ti.static(range(3))])


@ti.func
def _link_inertia(d: ti.template(), s, e, l, pos, rot):
    """Spatial inertia (m, h, I about the reference) of link l alone; pos: its origin relative to
    the reference."""
    m = d.mass[e, l]
    com = pos + mat_vec(rot, _link_com(d, e, l))
    inertia_com = mat_mul(mat_mul(rot, _link_rotational_inertia(d, e, l)), rot.transpose())
    inertia = inertia_com + m * ((com[0] ** 2 + com[1] ** 2 + com[2] ** 2) * ti.Matrix.identity(float, 3)
                                 - com.outer_product(com))
    d.cinert_m[s, e, l] = m
    d.cinert_h[s, e, l] = m * com
    d.cinert_i[s, e, l] = inertia
    # composite inertia starts as the link's own; the up sweep adds the children's
    d.crb_m[s, e, l], d.crb_h[s, e, l], d.crb_i[s, e, l] = m, m * com, inertia


@ti.func
def _motion_subspace(d: ti.template(), s, e, l, pos, rot):
    """cdof (angular, linear at the reference) of each dof of link l; pos: its origin relative to
    the reference."""
    jt = d.link_jtype[l]
    dof0 = d.link_dof0[l]
    if jt == REVOLUTE:
        axis = mat_vec(rot, d.link_axis[l])
        d.cdof_w[s, e, dof0] = axis
        d.cdof_v[s, e, dof0] = pos.cross(axis)
    elif jt == PRISMATIC:
        d.cdof_w[s, e, dof0] = ti.Vector.zero(float, 3)
        d.cdof_v[s, e, dof0] = mat_vec(rot, d.link_axis[l])
    elif jt == FREE or jt == BALL:
        # MuJoCo's free joint: world-frame translation, then rotation about body-frame axes; a
        # ball joint: those rotations alone
        turn0 = dof0 + (3 if jt == FREE else 0)
        for k in ti.static(range(3)):
            axis = ti.Vector([rot[0, k], rot[1, k], rot[2, k]])
            if jt == FREE:
                d.cdof_w[s, e, dof0 + k] = ti.Vector.zero(float, 3)
                d.cdof_v[s, e, dof0 + k] = ti.Vector.unit(3, k, float)
            d.cdof_w[s, e, turn0 + k] = axis
            d.cdof_v[s, e, turn0 + k] = pos.cross(axis)


@ti.func
def link_kinematics(d: ti.template(), s, e, l):
    """Pose, spatial inertia and motion subspace of link l (its parent's pose must be known)."""
    pos, quat = _joint_pose(d, s, e, l)
    d.xpos[s, e, l] = pos
    d.xquat[s, e, l] = quat
    rot = quat_to_mat(quat)
    relative = pos - reference(d, s, e, l)
    _link_inertia(d, s, e, l, relative, rot)
    _motion_subspace(d, s, e, l, relative, rot)


# -- reverse mode ----------------------------------------------------------------------------
# A link's pose gradient is carried as (g_pos, g_rot): ∂L/∂(a shift of its origin) and
# ∂L/∂(a small world-frame rotation δθ of the link, R → (I + [δθ]×) R). Every quantity of the
# link rotates with it, so each term is a cross product, and passing the gradient to the joint
# and the parent takes one dot and one cross product — no quaternion algebra, no sin or cos.
@ti.func
def _motion_subspace_adjoint(d: ti.template(), s, e, l, pos, rot):
    """(g_pos, g_rot) from the gradients of link l's cdof (δw = δθ × w, δv = δpos × w + pos × δw;
    pos relative to the reference, a constant here)."""
    jt = d.link_jtype[l]
    dof0 = d.link_dof0[l]
    g_pos = ti.Vector.zero(float, 3)
    g_rot = ti.Vector.zero(float, 3)
    if jt == REVOLUTE:
        gv = d.cdof_v.grad[s, e, dof0]
        axis = d.cdof_w[s, e, dof0]
        g_pos = axis.cross(gv)
        g_rot = axis.cross(d.cdof_w.grad[s, e, dof0] + gv.cross(pos))
    elif jt == PRISMATIC:
        g_rot = d.cdof_v[s, e, dof0].cross(d.cdof_v.grad[s, e, dof0])
    elif jt == FREE or jt == BALL:
        turn0 = dof0 + (3 if jt == FREE else 0)
        for k in ti.static(range(3)):  # rotation axes are rot's columns; translations are constant
            gv = d.cdof_v.grad[s, e, turn0 + k]
            axis = ti.Vector([rot[0, k], rot[1, k], rot[2, k]])
            g_pos += axis.cross(gv)
            g_rot += axis.cross(d.cdof_w.grad[s, e, turn0 + k] + gv.cross(pos))
    return g_pos, g_rot


@ti.func
def _link_inertia_adjoint(d: ti.template(), s, e, l, pos, rot, g_m, g_h, g_i):
    """(g_pos, g_rot) from the gradient (g_m, g_h, g_i) of link l's spatial inertia; the mass's
    is stored (pos relative to the reference, a constant here)."""
    m = d.mass[e, l]
    arm = mat_vec(rot, _link_com(d, e, l))  # com − pos, rotating with the link
    com = pos + arm
    trace = g_i.trace()
    g_sym = g_i + g_i.transpose()
    g_com = m * (g_h + 2.0 * trace * com - mat_vec(g_sym, com))
    # rotated inertia about the com: W = R I Rᵀ symmetric, and a rotation moves it by
    # δW = [δθ]× W − W [δθ]×, so ∂L/∂δθ is the axial vector of P − Pᵀ, P = W g_sym
    p = mat_mul(mat_mul(mat_mul(rot, _link_rotational_inertia(d, e, l)), rot.transpose()), g_sym)
    g_mass = g_m + g_h.dot(com) + trace * com.dot(com) - com.dot(mat_vec(g_i, com))
    accumulate(d.mass.grad, ti.Vector([e, l]), g_mass)
    g_local = mat_vec(rot.transpose(), g_com)  # the com input turns with the link
    for k in ti.static(range(3)):
        accumulate(d.com.grad, ti.Vector([e, 3 * l + k]), g_local[k])
    g_inertia = mat_mul(mat_mul(rot.transpose(), g_i), rot)  # the inertia input turns with the link
    for a, b in ti.static(ti.ndrange(3, 3)):
        accumulate(d.inertia.grad, ti.Vector([e, 9 * l + 3 * a + b]), g_inertia[a, b])
    g_rot = arm.cross(g_com) + ti.Vector([p[1, 2] - p[2, 1], p[2, 0] - p[0, 2], p[0, 1] - p[1, 0]])
    return g_com, g_rot


@ti.func
def _joint_pose_adjoint(d: ti.template(), s, e, l, pos, quat, g_pos, g_rot):
    """Reverse of _joint_pose: link l's complete (g_pos, g_rot) → its joint coordinates and its
    parent's pose (the parent's origin shifts it, the parent's rotation turns it about there)."""
    p = d.link_parent[l]
    jt = d.link_jtype[l]
    q0 = d.link_q0[l]
    if jt == REVOLUTE:  # the axis in the world is cdof_w
        accumulate(d.qpos.grad, ti.Vector([s, e, q0]), g_rot.dot(d.cdof_w[s, e, d.link_dof0[l]]))
    elif jt == PRISMATIC:
        accumulate(d.qpos.grad, ti.Vector([s, e, q0]), g_pos.dot(d.cdof_v[s, e, d.link_dof0[l]]))
    elif jt == FREE:  # δquat = ½ (0, δθ) ⊗ quat, quat = raw / |raw|
        raw = joint_quat(d, s, e, l)
        g_raw = normalized_adjoint(raw, 2.0 * quat_mul(ti.Vector([0.0, g_rot[0], g_rot[1], g_rot[2]]), quat))
        for k in ti.static(range(3)):
            accumulate(d.qpos.grad, ti.Vector([s, e, q0 + k]), g_pos[k])
        for k in ti.static(range(4)):
            accumulate(d.qpos.grad, ti.Vector([s, e, q0 + 3 + k]), g_raw[k])
    elif jt == BALL:  # quat = before ⊗ n, n = raw / |raw|: δn = ½ (0, R_beforeᵀ δθ) ⊗ n
        raw = joint_quat(d, s, e, l)
        before = d.link_quat0[l]  # the joint frame's world orientation
        if p >= 0:
            before = quat_mul(d.xquat[s, e, p], before)
        local = mat_vec(quat_to_mat(before).transpose(), g_rot)
        g_raw = normalized_adjoint(raw, 2.0 * quat_mul(ti.Vector([0.0, local[0], local[1], local[2]]),
                                                       quat_normalized(raw)))
        for k in ti.static(range(4)):
            accumulate(d.qpos.grad, ti.Vector([s, e, q0 + k]), g_raw[k])
    if p >= 0 and jt != FREE:  # a free joint's pose does not depend on its parent's
        accumulate(d.xpos.grad, ti.Vector([s, e, p]), g_pos)
        accumulate(d.xrot_grad, ti.Vector([s, e, p]), g_rot + (pos - d.xpos[s, e, p]).cross(g_pos))


@ti.func
def rotation_gradient(quat, g_quat):
    """g_rot of a link from the gradient of its unit quaternion: δquat = ½ (0, δθ) ⊗ quat, so
    g_rot = ½ vec(g_quat ⊗ quat*) (the part of g_quat along quat changes nothing)."""
    g = quat_mul(g_quat, quat_conj(quat))
    return 0.5 * ti.Vector([g[1], g[2], g[3]])


@ti.func
def link_kinematics_adjoint(d: ti.template(), s, e, l, g_m, g_h, g_i):
    """Reverse of link_kinematics, given the gradient (g_m, g_h, g_i) of link l's inertia (the
    gradients of its other outputs must be complete)."""
    pos, quat = d.xpos[s, e, l], d.xquat[s, e, l]
    rot = quat_to_mat(quat)
    relative = pos - reference(d, s, e, l)
    g_pos_m, g_rot_m = _motion_subspace_adjoint(d, s, e, l, relative, rot)
    g_pos_i, g_rot_i = _link_inertia_adjoint(d, s, e, l, relative, rot, g_m, g_h, g_i)
    g_rot = d.xrot_grad[s, e, l] + g_rot_m + g_rot_i
    _joint_pose_adjoint(d, s, e, l, pos, quat, d.xpos.grad[s, e, l] + g_pos_m + g_pos_i, g_rot)


@ti.func
def dof_count(d: ti.template(), link):
    """Dofs of a link's joint: 6 (free), 3 (ball), 1 (hinge, slide) or 0 (fixed)."""
    jt = d.link_jtype[link]
    return 6 if jt == FREE else (3 if jt == BALL else (1 if jt == REVOLUTE or jt == PRISMATIC else 0))


@ti.func
def dof_motion_at(d: ti.template(), s, e, i, point):
    """(linear, angular) velocity at ``point`` (world, m) of the body dof i moves, per unit of
    its velocity: cdof_v + cdof_w × (point − reference) and cdof_w (the spatial motion about the
    reference, moved to the point)."""
    angular = d.cdof_w[s, e, i]
    return d.cdof_v[s, e, i] + angular.cross(point - reference(d, s, e, d.dof_link[i])), angular


@ti.func
def tendon_length(d: ti.template(), s, e, t):
    """Fixed tendon t's length L = Σ c_j q_j at frame s (m or rad; its joints hinge or slide)."""
    length = 0.0
    for k in range(TENDON_JOINTS * t, TENDON_JOINTS * t + d.ten_nnz[t]):
        length += d.ten_coef[k] * d.qpos[s, e, d.dof_q[d.ten_dof[k]]]
    return length


@ti.func
def tendon_rate(d: ti.template(), s, e, t):
    """Fixed tendon t's rate L̇ = Σ c_j q̇_j at frame s (m/s or rad/s)."""
    rate = 0.0
    for k in range(TENDON_JOINTS * t, TENDON_JOINTS * t + d.ten_nnz[t]):
        rate += d.ten_coef[k] * d.qvel[s, e, d.ten_dof[k]]
    return rate
