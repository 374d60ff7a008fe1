"""Integration stage: semi-implicit Euler as MuJoCo's default integrator.

q̇' = q̇ + h·q̈, then q' = q ⊕ h·q̇' (positions use the *new* velocity). A free joint's
position moves with its world linear velocity and its quaternion rotates by the body-frame
angular velocity: quat' = quat ⊗ exp(h·ω/2), renormalised.
"""
import taichi as ti

from .model import FREE, PRISMATIC, REVOLUTE
from .spatial import quat_integrate


@ti.func
def integrate_link(d: ti.template(), s, e, l):
    h = d.consts[0]
    jt = d.link_jtype[l]
    dof0, q0 = d.link_dof0[l], d.link_q0[l]
    if jt == REVOLUTE or jt == PRISMATIC:
        qd = d.qvel[s, e, dof0] + h * d.qacc[s, e, dof0]
        d.qvel[s + 1, e, dof0] = qd
        d.qpos[s + 1, e, q0] = d.qpos[s, e, q0] + h * qd
    elif jt == FREE:
        for k in ti.static(range(6)):
            d.qvel[s + 1, e, dof0 + k] = d.qvel[s, e, dof0 + k] + h * d.qacc[s, e, dof0 + k]
        for k in ti.static(range(3)):
            d.qpos[s + 1, e, q0 + k] = d.qpos[s, e, q0 + k] + h * d.qvel[s + 1, e, dof0 + k]
        quat = ti.Vector([d.qpos[s, e, q0 + 3], d.qpos[s, e, q0 + 4], d.qpos[s, e, q0 + 5], d.qpos[s, e, q0 + 6]])
        omega = ti.Vector([d.qvel[s + 1, e, dof0 + 3], d.qvel[s + 1, e, dof0 + 4], d.qvel[s + 1, e, dof0 + 5]])
        quat = quat_integrate(quat, omega, h)
        for k in ti.static(range(4)):
            d.qpos[s + 1, e, q0 + 3 + k] = quat[k]
