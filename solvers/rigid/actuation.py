"""Force stage: controls, PD servos, joint damping and soft joint limits → qfrc_smooth.

Control modes per dof (as in Genesis): 0 force (``control_dofs_force``), 1 position
(τ = kp·(q* − q) + kv·(q̇* − q̇), with q̇* = ``ctrl_vel``: 0 after ``control_dofs_position``,
the target of ``control_dofs_position_velocity``), 2 velocity (τ = kv·(q̇* − q̇)); the result is
clipped to the dof's force range. Damping −b·q̇ is passive (and treated implicitly by the solve,
as MuJoCo does).
A limit pushes back like a critically damped spring with time constant ``limit_timeconst``,
scaled by the dof's own inertia M[i, i], and only ever pushes out of the violated bound.
"""
import taichi as ti

from .data import accumulate

FORCE, POSITION, VELOCITY = 0, 1, 2


@ti.func
def actuator_force(d: ti.template(), e, i, mode, q, qd):
    """Dof i's actuator command in env e before clipping."""
    force = d.ctrl_force[e, i]
    if mode != FORCE:
        force = d.kv[e, i] * (d.ctrl_vel[e, i] - qd)
        if mode == POSITION:
            force += d.kp[e, i] * (d.ctrl_pos[e, i] - q)
    return force


@ti.func
def smooth_force(d: ti.template(), s, e, i):
    qd = d.qvel[s, e, i]
    qi = d.dof_q[i]
    q = d.qpos[s, e, ti.max(qi, 0)]  # free-joint dofs have no scalar q; never used for them
    mode = ti.cast(d.ctrl_mode[e, i], ti.i32)
    force = ti.min(ti.max(actuator_force(d, e, i, mode, q, qd), d.force_lo[e, i]), d.force_hi[e, i])
    force -= d.damping[e, i] * qd
    if d.limits_enabled and qi >= 0:
        stiffness, damping = d.consts[1], d.consts[2]
        below = d.dof_lower[i] - q
        above = q - d.dof_upper[i]
        inertia = d.mass_mat[s, e, i, i]
        if below > 0:
            force += inertia * ti.max(stiffness * below - damping * qd, 0.0)
        if above > 0:
            force -= inertia * ti.max(stiffness * above + damping * qd, 0.0)
    d.qfrc_smooth[s, e, i] = force - d.qfrc_bias[s, e, i]


@ti.func
def smooth_force_adjoint(d: ti.template(), s, e, i):
    """Reverse of smooth_force: ∂L/∂qfrc_smooth[s, e, i] → state, bias, M[i, i] and the inputs."""
    g = d.qfrc_smooth.grad[s, e, i]
    qd = d.qvel[s, e, i]
    qi = d.dof_q[i]
    q = d.qpos[s, e, ti.max(qi, 0)]
    mode = ti.cast(d.ctrl_mode[e, i], ti.i32)
    kp, kv = d.kp[e, i], d.kv[e, i]
    g_q, g_qd = 0.0, -g * d.damping[e, i]
    accumulate(d.qfrc_bias.grad, ti.Vector([s, e, i]), -g)
    accumulate(d.damping.grad, ti.Vector([e, i]), -g * qd)
    if d.limits_enabled and qi >= 0:
        stiffness, damping = d.consts[1], d.consts[2]
        inertia = d.mass_mat[s, e, i, i]
        push_up = stiffness * (d.dof_lower[i] - q) - damping * qd
        push_down = stiffness * (q - d.dof_upper[i]) + damping * qd
        g_inertia = 0.0
        if d.dof_lower[i] - q > 0 and push_up > 0:
            g_inertia += g * push_up
            g_q -= g * inertia * stiffness
            g_qd -= g * inertia * damping
        if q - d.dof_upper[i] > 0 and push_down > 0:
            g_inertia -= g * push_down
            g_q -= g * inertia * stiffness
            g_qd -= g * inertia * damping
        accumulate(d.mass_mat.grad, ti.Vector([s, e, i, i]), g_inertia)
    force = actuator_force(d, e, i, mode, q, qd)
    g_force = g if d.force_lo[e, i] < force and force < d.force_hi[e, i] else 0.0  # a clipped force is constant
    if mode == FORCE:
        accumulate(d.ctrl_force.grad, ti.Vector([e, i]), g_force)
    else:  # the velocity term, shared by both servos
        accumulate(d.kv.grad, ti.Vector([e, i]), g_force * (d.ctrl_vel[e, i] - qd))
        accumulate(d.ctrl_vel.grad, ti.Vector([e, i]), g_force * kv)
        g_qd -= g_force * kv
    if mode == POSITION:
        accumulate(d.kp.grad, ti.Vector([e, i]), g_force * (d.ctrl_pos[e, i] - q))
        accumulate(d.ctrl_pos.grad, ti.Vector([e, i]), g_force * kp)
        g_q -= g_force * kp
    accumulate(d.qpos.grad, ti.Vector([s, e, ti.max(qi, 0)]), g_q)
    accumulate(d.qvel.grad, ti.Vector([s, e, i]), g_qd)
