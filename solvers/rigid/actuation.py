"""Force stage: controls, PD servos, joint springs and damping, fixed tendons' springs and dampers
→ qfrc_smooth (joint limits and friction loss are constraint rows: constraint/rows.py).

Control modes per dof (as in Genesis): 0 force (``control_dofs_force``), 1 position
(τ = kp·(q* − q) + kv·(q̇* − q̇), with q̇* = ``ctrl_vel``: 0 after ``control_dofs_position``,
the target of ``control_dofs_position_velocity``), 2 velocity (τ = kv·(q̇* − q̇)); the result is
clipped to the dof's force range. A free or ball joint's rotation dofs take the joint's target
orientation as intrinsic X-Y-Z Euler angles (get_dofs_position's), and q* − q is the rotation
vector of the turn from the joint's quaternion q to the target's, rotvec(q⁻¹ ⊗ q*), in the
joint's own axes, which its dofs turn about (Genesis's free joint the same; its ball joint
takes each Euler angle's difference). Damping −b·q̇ and a joint spring −k·(q − q_ref) (q_ref: the
model's springref, MuJoCo's qpos_spring; a ball joint's dof a: −k·r_a, r the rotation vector of
its turn, MuJoCo's ball spring) are passive; the spring is explicit, as MuJoCo's and
Genesis's integrators take it (neither puts stiffness into the implicit matrix; Genesis's spring
rests at qpos0, the initial position, whatever springref says). Both velocity terms are treated
implicitly by the acceleration stage (linalg.py: h·(b + kv) on A's diagonal, kv of a dof in a
servo mode), as Genesis's default integrator does (approximate_implicitfast, clipped or not;
MuJoCo's implicitfast likewise but without the kv of an actuator clamped by its force range, its
Euler integrator only b): an explicit kv is unstable once h·kv exceeds about twice the dof's
inertia, which the gains of Genesis's examples do at its time steps. A fixed tendon's spring
and damper (MuJoCo's passive tendon force, on its length L = Σ c_j q_j) are explicit, both, as in
MuJoCo's Euler integrator (its implicitfast would take the damper implicitly).
"""
import taichi as ti

from .data import accumulate
from .kinematics import joint_quat, tendon_length, tendon_rate
from .model import BALL, FREE
from .spec import TENDON_JOINTS
from .spatial import (euler_xyz_quat, euler_xyz_quat_adjoint, quat_conj, quat_mul, quat_mul_adjoint,
                      quat_rotation_vector, quat_rotation_vector_adjoint)

FORCE, POSITION, VELOCITY = 0, 1, 2


@ti.func
def in_servo_mode(d: ti.template(), e, i):
    """Whether dof i of env e is in position or velocity control (its kv acts)."""
    return ti.cast(d.ctrl_mode[e, i], ti.i32) != FORCE


@ti.func
def servo_kv(d: ti.template(), e, i):
    """Dof i's velocity gain kv in env e when it is in a servo mode, else 0: what its actuator
    adds to the implicit damping."""
    kv = 0.0
    if in_servo_mode(d, e, i):
        kv = d.kv[e, i]
    return kv


@ti.func
def actuator_force(d: ti.template(), s, e, i, mode, qd):
    """Dof i's actuator command in env e at frame s before clipping."""
    force = d.ctrl_force[e, i]
    if mode != FORCE:
        force = d.kv[e, i] * (d.ctrl_vel[e, i] - qd)
        if mode == POSITION:
            force += d.kp[e, i] * _servo_error(d, s, e, i)
    return force


@ti.func
def _turn_target(d: ti.template(), e, link):
    """(the first rotation dof of the free or ball joint of link ``link``, its servo's target
    quaternion from the targets of its three rotation dofs: intrinsic X-Y-Z Euler angles, rad)."""
    turn0 = d.link_dof0[link] + (3 if d.link_jtype[link] == FREE else 0)
    return turn0, euler_xyz_quat(ti.Vector([d.ctrl_pos[e, turn0 + k] for k in ti.static(range(3))]))


@ti.func
def _servo_error(d: ti.template(), s, e, i):
    """What dof i's position servo pulls by at frame s: q* − q (rad or m); a free joint's position
    dof: its target less its origin's coordinate; a free or ball joint's rotation dof: its
    component (in the joint's own axes, as its dofs) of the rotation vector of the turn from the
    joint's quaternion to the target's, rotvec(q⁻¹ ⊗ q*)."""
    qi, link = d.dof_q[i], d.dof_link[i]
    error = 0.0
    if qi >= 0:
        error = d.ctrl_pos[e, i] - d.qpos[s, e, qi]
    elif d.link_jtype[link] == FREE and i < d.link_dof0[link] + 3:
        error = d.ctrl_pos[e, i] - d.qpos[s, e, d.link_q0[link] + i - d.link_dof0[link]]
    else:
        turn0, target = _turn_target(d, e, link)
        error = quat_rotation_vector(quat_mul(quat_conj(joint_quat(d, s, e, link)), target))[i - turn0]
    return error


@ti.func
def _servo_error_adjoint(d: ti.template(), s, e, i, g):
    """Reverse of _servo_error: g = ∂L/∂error into the state's qpos and the targets ctrl_pos."""
    qi, link = d.dof_q[i], d.dof_link[i]
    if qi >= 0:
        accumulate(d.ctrl_pos.grad, ti.Vector([e, i]), g)
        accumulate(d.qpos.grad, ti.Vector([s, e, qi]), -g)
    elif d.link_jtype[link] == FREE and i < d.link_dof0[link] + 3:
        accumulate(d.ctrl_pos.grad, ti.Vector([e, i]), g)
        accumulate(d.qpos.grad, ti.Vector([s, e, d.link_q0[link] + i - d.link_dof0[link]]), -g)
    else:
        turn0, target = _turn_target(d, e, link)
        inverse = quat_conj(joint_quat(d, s, e, link))
        g_turn = ti.Vector.zero(float, 3)
        g_turn[i - turn0] = g
        g_inverse, g_target = quat_mul_adjoint(inverse, target, quat_rotation_vector_adjoint(
            quat_mul(inverse, target), g_turn))
        g_quat = quat_conj(g_inverse)
        q0 = d.link_q0[link] + (3 if d.link_jtype[link] == FREE else 0)
        for k in ti.static(range(4)):
            accumulate(d.qpos.grad, ti.Vector([s, e, q0 + k]), g_quat[k])
        g_angles = euler_xyz_quat_adjoint(ti.Vector([d.ctrl_pos[e, turn0 + k] for k in ti.static(range(3))]),
                                          g_target)
        for k in ti.static(range(3)):
            accumulate(d.ctrl_pos.grad, ti.Vector([e, turn0 + k]), g_angles[k])


@ti.func
def _spring_stretch(d: ti.template(), s, e, i):
    """What dof i's spring pulls back at frame s: q − springref (rad or m), a ball joint dof's
    component of its turn's rotation vector (rad), 0 on a free joint."""
    qi = d.dof_q[i]
    stretch = 0.0
    if qi >= 0:
        stretch = d.qpos[s, e, qi] - d.dof_springref[i]
    elif d.link_jtype[d.dof_link[i]] == BALL:
        link = d.dof_link[i]
        stretch = quat_rotation_vector(joint_quat(d, s, e, link))[i - d.link_dof0[link]]
    return stretch


@ti.func
def _spring_stretch_adjoint(d: ti.template(), s, e, i, g):
    """Reverse of _spring_stretch: g = ∂L/∂stretch into the state's qpos."""
    qi = d.dof_q[i]
    if qi >= 0:
        accumulate(d.qpos.grad, ti.Vector([s, e, qi]), g)
    elif d.link_jtype[d.dof_link[i]] == BALL:
        link = d.dof_link[i]
        g_turn = ti.Vector.zero(float, 3)
        g_turn[i - d.link_dof0[link]] = g
        g_raw = quat_rotation_vector_adjoint(joint_quat(d, s, e, link), g_turn)
        for k in ti.static(range(4)):
            accumulate(d.qpos.grad, ti.Vector([s, e, d.link_q0[link] + k]), g_raw[k])


@ti.func
def smooth_force(d: ti.template(), s, e, i):
    qd = d.qvel[s, e, i]
    mode = ti.cast(d.ctrl_mode[e, i], ti.i32)
    force = ti.min(ti.max(actuator_force(d, s, e, i, mode, qd), d.force_lo[e, i]), d.force_hi[e, i])
    force -= d.damping[e, i] * qd
    if d.stiffness[e, i] != 0.0:  # (a free joint's is 0)
        force -= d.stiffness[e, i] * _spring_stretch(d, s, e, i)
    d.qfrc_smooth[s, e, i] = force - d.qfrc_bias[s, e, i]


@ti.func
def smooth_force_adjoint(d: ti.template(), s, e, i):
    """Reverse of smooth_force: ∂L/∂qfrc_smooth[s, e, i] → state, bias and the inputs."""
    g = d.qfrc_smooth.grad[s, e, i]
    qd = d.qvel[s, e, i]
    mode = ti.cast(d.ctrl_mode[e, i], ti.i32)
    kp, kv = d.kp[e, i], d.kv[e, i]
    g_qd = -g * d.damping[e, i]
    accumulate(d.qfrc_bias.grad, ti.Vector([s, e, i]), -g)
    accumulate(d.damping.grad, ti.Vector([e, i]), -g * qd)
    if d.stiffness[e, i] != 0.0:
        _spring_stretch_adjoint(d, s, e, i, -g * d.stiffness[e, i])
    accumulate(d.stiffness.grad, ti.Vector([e, i]), -g * _spring_stretch(d, s, e, i))
    force = actuator_force(d, s, e, i, mode, qd)
    g_force = 0.0  # a clipped force is its bound (at the bound itself too)
    if d.force_lo[e, i] < force and force < d.force_hi[e, i]:
        g_force = g
    elif force <= d.force_lo[e, i]:
        accumulate(d.force_lo.grad, ti.Vector([e, i]), g)
    else:
        accumulate(d.force_hi.grad, ti.Vector([e, i]), g)
    if mode == FORCE:
        accumulate(d.ctrl_force.grad, ti.Vector([e, i]), g_force)
    else:  # the velocity term, shared by both servos
        accumulate(d.kv.grad, ti.Vector([e, i]), g_force * (d.ctrl_vel[e, i] - qd))
        accumulate(d.ctrl_vel.grad, ti.Vector([e, i]), g_force * kv)
        g_qd -= g_force * kv
    if mode == POSITION:
        accumulate(d.kp.grad, ti.Vector([e, i]), g_force * _servo_error(d, s, e, i))
        _servo_error_adjoint(d, s, e, i, g_force * kp)
    accumulate(d.qvel.grad, ti.Vector([s, e, i]), g_qd)


@ti.func
def _tendon_stretch(d: ti.template(), s, e, t):
    """Fixed tendon t's length at frame s less the nearer end of its spring's rest range, 0 inside
    it (m or rad)."""
    length, stretch = tendon_length(d, s, e, t), 0.0
    if length > d.ten_spring[2 * t + 1]:
        stretch = length - d.ten_spring[2 * t + 1]
    elif length < d.ten_spring[2 * t]:
        stretch = length - d.ten_spring[2 * t]
    return stretch


@ti.func
def tendon_spring(d: ti.template(), s, e, t):
    """Add fixed tendon t's spring and damper, f = −k·stretch − b·L̇ along the tendon (N or N·m), to
    qfrc_smooth: c_j·f on each of its dofs j (after smooth_force has written them)."""
    if d.ten_stiffness[t] != 0.0 or d.ten_damping[t] != 0.0:
        force = -d.ten_stiffness[t] * _tendon_stretch(d, s, e, t) - d.ten_damping[t] * tendon_rate(d, s, e, t)
        for k in range(TENDON_JOINTS * t, TENDON_JOINTS * t + d.ten_nnz[t]):
            d.qfrc_smooth[s, e, d.ten_dof[k]] += d.ten_coef[k] * force


@ti.func
def tendon_spring_adjoint(d: ti.template(), s, e, t):
    """Reverse of tendon_spring: ∂L/∂qfrc_smooth → the state's qpos and qvel (g_f = Σ c_j g_j; the
    stretch's slope is 1 outside the rest range, 0 inside)."""
    if d.ten_stiffness[t] != 0.0 or d.ten_damping[t] != 0.0:
        g_force = 0.0
        for k in range(TENDON_JOINTS * t, TENDON_JOINTS * t + d.ten_nnz[t]):
            g_force += d.ten_coef[k] * d.qfrc_smooth.grad[s, e, d.ten_dof[k]]
        g_length = 0.0
        if _tendon_stretch(d, s, e, t) != 0.0:
            g_length = -d.ten_stiffness[t] * g_force
        g_rate = -d.ten_damping[t] * g_force
        for k in range(TENDON_JOINTS * t, TENDON_JOINTS * t + d.ten_nnz[t]):
            dof, coef = d.ten_dof[k], d.ten_coef[k]
            accumulate(d.qpos.grad, ti.Vector([s, e, d.dof_q[dof]]), coef * g_length)
            accumulate(d.qvel.grad, ti.Vector([s, e, dof]), coef * g_rate)
