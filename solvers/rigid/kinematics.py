"""Position stage: link poses, spatial inertias and joint motion subspaces from qpos.

Everything is expressed in the world frame about the world origin (MuJoCo's ``cdof`` and
``cinert`` idea), so later stages are plain sweeps over the links. Inertias are derived from
the *current* masses here, inside the differentiated step: a link's rotational inertia scales
with its mass (constant shape, uniform density change).

Each forward function has its hand-written reverse below it (see docs/architecture.md).
"""
import taichi as ti

from .data import accumulate
from .model import FREE, PRISMATIC, REVOLUTE
from .spatial import (axis_angle_quat, mat_mul, mat_vec, normalized_adjoint, quat_mul, quat_mul_adjoint,
                      quat_normalized, quat_to_mat, quat_to_mat_adjoint)


@ti.func
def _joint_pose(d: ti.template(), s, e, l):
    """World pose (pos m, quat) of link l from its parent's pose and its joint coordinate."""
    jt = d.link_jtype[l]
    q0 = d.link_q0[l]
    pos = ti.Vector.zero(float, 3)
    quat = ti.Vector([1.0, 0.0, 0.0, 0.0])
    if jt == FREE:  # the coordinates are the world pose, whatever the parent
        pos = ti.Vector([d.qpos[s, e, q0 + k] for k in ti.static(range(3))])
        quat = quat_normalized(ti.Vector([d.qpos[s, e, q0 + 3 + k] for k in ti.static(range(4))]))
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
    return pos, quat


@ti.func
def _link_inertia(d: ti.template(), s, e, l, pos, rot):
    """Spatial inertia (m, h, I about the origin) of link l alone."""
    m = d.mass[e, l]
    com = pos + mat_vec(rot, d.link_com[l])
    inertia_com = mat_mul(mat_mul(rot, d.link_inertia0[l] * (m * d.link_inv_mass0[l])), rot.transpose())
    inertia = inertia_com + m * ((com[0] ** 2 + com[1] ** 2 + com[2] ** 2) * ti.Matrix.identity(float, 3)
                                 - com.outer_product(com))
    d.cinert_m[s, e, l] = m
    d.cinert_h[s, e, l] = m * com
    d.cinert_i[s, e, l] = inertia
    # composite inertia starts as the link's own; the up sweep adds the children's
    d.crb_m[s, e, l], d.crb_h[s, e, l], d.crb_i[s, e, l] = m, m * com, inertia


@ti.func
def _motion_subspace(d: ti.template(), s, e, l, pos, rot):
    """cdof (angular, linear-at-origin) of each dof of link l."""
    jt = d.link_jtype[l]
    dof0 = d.link_dof0[l]
    if jt == REVOLUTE:
        axis = mat_vec(rot, d.link_axis[l])
        d.cdof_w[s, e, dof0] = axis
        d.cdof_v[s, e, dof0] = pos.cross(axis)
    elif jt == PRISMATIC:
        d.cdof_w[s, e, dof0] = ti.Vector.zero(float, 3)
        d.cdof_v[s, e, dof0] = mat_vec(rot, d.link_axis[l])
    elif jt == FREE:
        # MuJoCo's free joint: world-frame translation, then rotation about body-frame axes.
        for k in ti.static(range(3)):
            axis = ti.Vector([rot[0, k], rot[1, k], rot[2, k]])
            d.cdof_w[s, e, dof0 + k] = ti.Vector.zero(float, 3)
            d.cdof_v[s, e, dof0 + k] = ti.Vector.unit(3, k, float)
            d.cdof_w[s, e, dof0 + 3 + k] = axis
            d.cdof_v[s, e, dof0 + 3 + k] = pos.cross(axis)


@ti.func
def link_kinematics(d: ti.template(), s, e, l):
    """Pose, spatial inertia and motion subspace of link l (its parent's pose must be known)."""
    pos, quat = _joint_pose(d, s, e, l)
    d.xpos[s, e, l] = pos
    d.xquat[s, e, l] = quat
    rot = quat_to_mat(quat)
    _link_inertia(d, s, e, l, pos, rot)
    _motion_subspace(d, s, e, l, pos, rot)


# -- reverse mode ----------------------------------------------------------------------------
@ti.func
def _motion_subspace_adjoint(d: ti.template(), s, e, l, pos, rot):
    """Gradients (pos, rot) from those of link l's cdof."""
    jt = d.link_jtype[l]
    dof0 = d.link_dof0[l]
    axis = d.link_axis[l]
    g_pos = ti.Vector.zero(float, 3)
    g_rot = ti.Matrix.zero(float, 3, 3)
    if jt == REVOLUTE:
        gw, gv = d.cdof_w.grad[s, e, dof0], d.cdof_v.grad[s, e, dof0]
        g_pos = mat_vec(rot, axis).cross(gv)  # cdof_v = pos × cdof_w
        g_rot = (gw + gv.cross(pos)).outer_product(axis)
    elif jt == PRISMATIC:
        g_rot = d.cdof_v.grad[s, e, dof0].outer_product(axis)
    elif jt == FREE:
        for k in ti.static(range(3)):  # rotation axes are rot's columns; translations are constant
            gw, gv = d.cdof_w.grad[s, e, dof0 + 3 + k], d.cdof_v.grad[s, e, dof0 + 3 + k]
            column = ti.Vector([rot[0, k], rot[1, k], rot[2, k]])
            g_pos += column.cross(gv)
            g_column = gw + gv.cross(pos)
            for r in ti.static(range(3)):
                g_rot[r, k] = g_column[r]
    return g_pos, g_rot


@ti.func
def _link_inertia_adjoint(d: ti.template(), s, e, l, pos, rot):
    """Gradients (pos, rot) from those of link l's spatial inertia; the mass's is stored."""
    m = d.mass[e, l]
    com = pos + mat_vec(rot, d.link_com[l])
    g_m, g_h, g_i = d.cinert_m.grad[s, e, l], d.cinert_h.grad[s, e, l], d.cinert_i.grad[s, e, l]
    trace = g_i.trace()
    com_sq = com.dot(com)
    g_sym = g_i + g_i.transpose()
    g_com = m * (g_h + 2.0 * trace * com - mat_vec(g_sym, com))
    # I = R I0 Rᵀ · m/m0 with I0 symmetric: only g_sym matters, and with W = g_sym R I0,
    # ∂/∂R = W · m/m0 and ∂/∂m of the rotated term = ½ Σ(W ∘ R) / m0 (two products, not six)
    weighted = mat_mul(mat_mul(g_sym, rot), d.link_inertia0[l])
    g_mass = (g_m + g_h.dot(com) + trace * com_sq - com.dot(mat_vec(g_i, com))
              + 0.5 * (weighted * rot).sum() * d.link_inv_mass0[l])
    accumulate(d.mass.grad, ti.Vector([e, l]), g_mass)
    g_rot = weighted * (m * d.link_inv_mass0[l]) + g_com.outer_product(d.link_com[l])
    return g_com, g_rot


@ti.func
def _joint_pose_adjoint(d: ti.template(), s, e, l, g_pos, g_quat):
    """Reverse of _joint_pose: gradients to the joint coordinates and the parent's pose."""
    p = d.link_parent[l]
    pp = ti.max(p, 0)
    parent_quat = d.xquat[s, e, pp] if p >= 0 else ti.Vector([1.0, 0.0, 0.0, 0.0])
    jt = d.link_jtype[l]
    q0 = d.link_q0[l]
    axis = d.link_axis[l]
    frame_quat = quat_mul(parent_quat, d.link_quat0[l])
    g_frame_quat = g_quat
    if jt == REVOLUTE:
        turn = axis_angle_quat(axis, d.qpos[s, e, q0])  # (cos θ/2, sin θ/2 · axis), axis a unit vector
        g_frame_quat, g_turn = quat_mul_adjoint(frame_quat, turn, g_quat)
        sin_half = turn[1] * axis[0] + turn[2] * axis[1] + turn[3] * axis[2]
        g_axis_part = g_turn[1] * axis[0] + g_turn[2] * axis[1] + g_turn[3] * axis[2]
        g_angle = 0.5 * (-sin_half * g_turn[0] + turn[0] * g_axis_part)
        accumulate(d.qpos.grad, ti.Vector([s, e, q0]), g_angle)
    elif jt == PRISMATIC:
        slide = d.qpos[s, e, q0]
        g_frame_quat += quat_to_mat_adjoint(frame_quat, g_pos.outer_product(axis) * slide)
        accumulate(d.qpos.grad, ti.Vector([s, e, q0]), g_pos.dot(mat_vec(quat_to_mat(frame_quat), axis)))
    elif jt == FREE:
        raw = ti.Vector([d.qpos[s, e, q0 + 3 + k] for k in ti.static(range(4))])
        g_raw = normalized_adjoint(raw, g_quat)
        for k in ti.static(range(3)):
            accumulate(d.qpos.grad, ti.Vector([s, e, q0 + k]), g_pos[k])
        for k in ti.static(range(4)):
            accumulate(d.qpos.grad, ti.Vector([s, e, q0 + 3 + k]), g_raw[k])
    if p >= 0 and jt != FREE:  # a free joint's pose does not depend on its parent's
        g_parent_quat = (quat_mul_adjoint(parent_quat, d.link_quat0[l], g_frame_quat)[0]
                         + quat_to_mat_adjoint(parent_quat, g_pos.outer_product(d.link_pos0[l])))
        accumulate(d.xpos.grad, ti.Vector([s, e, p]), g_pos)
        accumulate(d.xquat.grad, ti.Vector([s, e, p]), g_parent_quat)


@ti.func
def link_kinematics_adjoint(d: ti.template(), s, e, l):
    """Reverse of link_kinematics (gradients of link l's outputs must be complete)."""
    pos, quat = d.xpos[s, e, l], d.xquat[s, e, l]
    rot = quat_to_mat(quat)
    g_pos_m, g_rot_m = _motion_subspace_adjoint(d, s, e, l, pos, rot)
    g_pos_i, g_rot_i = _link_inertia_adjoint(d, s, e, l, pos, rot)
    g_quat = d.xquat.grad[s, e, l] + quat_to_mat_adjoint(quat, g_rot_m + g_rot_i)
    _joint_pose_adjoint(d, s, e, l, d.xpos.grad[s, e, l] + g_pos_m + g_pos_i, g_quat)
