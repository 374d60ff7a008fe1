"""Force stage: controls, PD servos, joint damping and soft joint limits → qfrc_smooth.

Control modes per dof (as in Genesis): 0 force (``control_dofs_force``), 1 position
(τ = kp·(q* − q) − kv·q̇), 2 velocity (τ = kv·(q̇* − q̇)); the result is clipped to the dof's
force range. Damping −b·q̇ is passive (and treated implicitly by the solve, as MuJoCo does).
A limit pushes back like a critically damped spring with time constant ``limit_timeconst``,
scaled by the dof's own inertia M[i, i], and only ever pushes out of the violated bound.
"""
import taichi as ti

FORCE, POSITION, VELOCITY = 0, 1, 2


@ti.func
def smooth_force(d: ti.template(), s, e, i):
    qd = d.qvel[s, e, i]
    qi = d.dof_q[i]
    q = d.qpos[s, e, ti.max(qi, 0)]  # free-joint dofs have no scalar q; never used for them
    mode = ti.cast(d.ctrl_mode[e, i], ti.i32)
    force = d.ctrl_force[e, i]
    if mode == POSITION:
        force = d.kp[e, i] * (d.ctrl_pos[e, i] - q) - d.kv[e, i] * qd
    elif mode == VELOCITY:
        force = d.kv[e, i] * (d.ctrl_vel[e, i] - qd)
    force = ti.min(ti.max(force, d.force_lo[e, i]), d.force_hi[e, i])
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
