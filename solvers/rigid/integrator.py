"""Integration stage: semi-implicit Euler as MuJoCo's default integrator.

q̇' = q̇ + h·q̈, then q' = q ⊕ h·q̇' (positions use the *new* velocity). A free joint's
position moves with its world linear velocity and its quaternion (a ball joint's too) rotates by
the body-frame angular velocity: quat' = quat ⊗ exp(h·ω/2), renormalised.
"""
import taichi as ti

from .model import BALL, FREE, PRISMATIC, REVOLUTE
from .data import accumulate
from .kinematics import joint_quat
from .spatial import quat_integrate, quat_integrate_adjoint


@ti.func
def _omega_at(d: ti.template(), s, e, k):
    return ti.Vector([d.qvel[s, e, k + j] for j in ti.static(range(3))])


@ti.func
def integrate_link(d: ti.template(), s, e, l):
    h = d.consts[0]
    jt = d.link_jtype[l]
    dof0, q0 = d.link_dof0[l], d.link_q0[l]
    if jt == REVOLUTE or jt == PRISMATIC:
        qd = d.qvel[s, e, dof0] + h * d.qacc[s, e, dof0]
        d.qvel[s + 1, e, dof0] = qd
        d.qpos[s + 1, e, q0] = d.qpos[s, e, q0] + h * qd
    elif jt == FREE or jt == BALL:
        shift = 3 if jt == FREE else 0  # the rotation's first dof and q past the translation's
        for k in ti.static(range(6)):
            if k < 3 + shift:
                d.qvel[s + 1, e, dof0 + k] = d.qvel[s, e, dof0 + k] + h * d.qacc[s, e, dof0 + k]
        for k in ti.static(range(3)):
            if k < shift:
                d.qpos[s + 1, e, q0 + k] = d.qpos[s, e, q0 + k] + h * d.qvel[s + 1, e, dof0 + k]
        quat = quat_integrate(joint_quat(d, s, e, l), _omega_at(d, s + 1, e, dof0 + shift), h)
        for k in ti.static(range(4)):
            d.qpos[s + 1, e, q0 + shift + k] = quat[k]


@ti.func
def _velocity_adjoint(d: ti.template(), s, e, dof, g_qd):
    """g_qd = ∂L/∂q̇[s+1] in total: it reaches q̇[s] and, times h, q̈[s]."""
    accumulate(d.qvel.grad, ti.Vector([s, e, dof]), g_qd)
    accumulate(d.qacc.grad, ti.Vector([s, e, dof]), d.consts[0] * g_qd)


@ti.func
def integrate_link_adjoint(d: ti.template(), s, e, l):
    """Reverse of integrate_link: gradients at frame s+1 → frame s and qacc[s]."""
    h = d.consts[0]
    jt = d.link_jtype[l]
    dof0, q0 = d.link_dof0[l], d.link_q0[l]
    gq, gv = d.qpos.grad, d.qvel.grad
    if jt == REVOLUTE or jt == PRISMATIC:
        accumulate(gq, ti.Vector([s, e, q0]), gq[s + 1, e, q0])
        _velocity_adjoint(d, s, e, dof0, gv[s + 1, e, dof0] + h * gq[s + 1, e, q0])
    elif jt == FREE or jt == BALL:
        shift = 3 if jt == FREE else 0
        g_quat_new = ti.Vector([gq[s + 1, e, q0 + shift + k] for k in ti.static(range(4))])
        g_quat, g_omega = quat_integrate_adjoint(joint_quat(d, s, e, l), _omega_at(d, s + 1, e, dof0 + shift),
                                                 h, g_quat_new)
        for k in ti.static(range(3)):
            if k < shift:
                accumulate(gq, ti.Vector([s, e, q0 + k]), gq[s + 1, e, q0 + k])
                _velocity_adjoint(d, s, e, dof0 + k, gv[s + 1, e, dof0 + k] + h * gq[s + 1, e, q0 + k])
        for k in ti.static(range(3)):
            _velocity_adjoint(d, s, e, dof0 + shift + k, gv[s + 1, e, dof0 + shift + k] + g_omega[k])
        for k in ti.static(range(4)):
            accumulate(gq, ti.Vector([s, e, q0 + shift + k]), g_quat[k])
