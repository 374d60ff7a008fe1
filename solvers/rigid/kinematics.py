"""Position stage: link poses, spatial inertias and joint motion subspaces from qpos.

Everything is expressed in the world frame about the world origin (MuJoCo's ``cdof`` and
``cinert`` idea), so later stages are plain sweeps over the links. Inertias are derived from
the *current* masses here, inside the differentiated step: a link's rotational inertia scales
with its mass (constant shape, uniform density change).
"""
import taichi as ti

from .model import FREE, PRISMATIC, REVOLUTE
from .spatial import axis_angle_quat, quat_mul, quat_normalized, quat_to_mat


@ti.func
def _joint_pose(d: ti.template(), s, e, l):
    """World pose (pos m, quat) of link l from its parent's pose and its joint coordinate."""
    p = d.link_parent[l]
    pp = ti.max(p, 0)  # a valid index even for roots; the value is only used when p >= 0
    pos = d.link_pos0[l]
    quat = d.link_quat0[l]
    if p >= 0:
        pos = d.xpos[s, e, pp] + quat_to_mat(d.xquat[s, e, pp]) @ pos
        quat = quat_mul(d.xquat[s, e, pp], quat)
    jt = d.link_jtype[l]
    q0 = d.link_q0[l]
    if jt == REVOLUTE:
        quat = quat_mul(quat, axis_angle_quat(d.link_axis[l], d.qpos[s, e, q0]))
    elif jt == PRISMATIC:
        pos = pos + quat_to_mat(quat) @ d.link_axis[l] * d.qpos[s, e, q0]
    elif jt == FREE:
        pos = ti.Vector([d.qpos[s, e, q0], d.qpos[s, e, q0 + 1], d.qpos[s, e, q0 + 2]])
        quat = quat_normalized(ti.Vector([d.qpos[s, e, q0 + 3], d.qpos[s, e, q0 + 4],
                                          d.qpos[s, e, q0 + 5], d.qpos[s, e, q0 + 6]]))
    return pos, quat


@ti.func
def _link_inertia(d: ti.template(), s, e, l, pos, rot):
    """Spatial inertia (m, h, I about the origin) of link l alone, and its start as composite."""
    m = d.mass[e, l]
    m0 = d.link_mass0[l]
    scale = m / m0 if m0 > 0 else 0.0  # a massless link has no inertia either (as in MuJoCo)
    com = pos + rot @ d.link_com[l]
    inertia_com = rot @ (d.link_inertia0[l] * scale) @ rot.transpose()
    eye = ti.Matrix.identity(float, 3)
    inertia = inertia_com + m * (com.dot(com) * eye - com.outer_product(com))
    d.cinert_m[s, e, l] = m
    d.cinert_h[s, e, l] = m * com
    d.cinert_i[s, e, l] = inertia
    d.crb_m[s, e, l] = m
    d.crb_h[s, e, l] = m * com
    d.crb_i[s, e, l] = inertia


@ti.func
def _motion_subspace(d: ti.template(), s, e, l, pos, rot):
    """cdof (angular, linear-at-origin) of each dof of link l."""
    jt = d.link_jtype[l]
    dof0 = d.link_dof0[l]
    if jt == REVOLUTE:
        axis = rot @ d.link_axis[l]
        d.cdof_w[s, e, dof0] = axis
        d.cdof_v[s, e, dof0] = pos.cross(axis)
    elif jt == PRISMATIC:
        d.cdof_w[s, e, dof0] = ti.Vector.zero(float, 3)
        d.cdof_v[s, e, dof0] = rot @ d.link_axis[l]
    elif jt == FREE:
        # MuJoCo's free joint: world-frame translation, then rotation about body-frame axes.
        for k in ti.static(range(3)):
            unit = ti.Vector.unit(3, k, float)
            axis = ti.Vector([rot[0, k], rot[1, k], rot[2, k]])
            d.cdof_w[s, e, dof0 + k] = ti.Vector.zero(float, 3)
            d.cdof_v[s, e, dof0 + k] = unit
            d.cdof_w[s, e, dof0 + 3 + k] = axis
            d.cdof_v[s, e, dof0 + 3 + k] = pos.cross(axis)


@ti.func
def kinematics_env(d: ti.template(), s, e):
    """Forward kinematics of env e at frame s: one sweep over the links in tree order."""
    for l in range(d.n_links):
        pos, quat = _joint_pose(d, s, e, l)
        d.xpos[s, e, l] = pos
        d.xquat[s, e, l] = quat
        rot = quat_to_mat(quat)
        _link_inertia(d, s, e, l, pos, rot)
        _motion_subspace(d, s, e, l, pos, rot)


@ti.kernel
def kinematics(d: ti.template(), s: ti.i32):
    for e in range(d.n_batch):
        kinematics_env(d, s, e)
