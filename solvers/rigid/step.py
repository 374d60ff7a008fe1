"""One rigid step, forward and reverse, and moving state, inputs and gradients between the
scene's arenas and torch.

Forward runs every substep of every env in one launch (``advance``, which can also load the
inputs and write out the result). Reverse: ``prepare_reverse`` loads the step's start state,
inputs and output gradient, ``advance`` replays the substeps to refill the frames, then for
each substep, last first, ``reverse_dynamics`` and ``reverse_kinematics`` run the stages'
hand-written adjoints in reverse order; after substep 0 the gradients are written out.
(Fused into one kernel, LLVM took 31 s to compile it; split so, 6 s.) Each env belongs to one
thread, so gradients accumulate without atomics.

Every kernel takes ``schedule`` (compile-time: whether its compute loop, and its data-moving
loops, run on the calling thread; data.RigidData.schedule) and the scene's five arenas
(data.py), and binds them to a view in its env loop: one compiled kernel serves every scene
of the process.
"""
import taichi as ti

from .data import ARENA_TYPES, bind, n_batch
from .actuation import smooth_force, smooth_force_adjoint
from .dynamics import (bias_entry, dof_force, dof_row_adjoint, link_forces, link_forces_adjoint, mass_entry,
                       subtree_sum, subtree_sum_adjoint)
from .integrator import integrate_link, integrate_link_adjoint
from .kinematics import link_kinematics, link_kinematics_adjoint, rotation_gradient
from .linalg import solve_adjoint_env, solve_env


# -- one substep of one env, in stage order, and its reverse --------------------------------------
@ti.func
def down_sweep_env(d: ti.template(), s, e):
    """Root to leaves: each link's pose, inertia, motion subspace, velocity and net force."""
    for l in range(d.n_links):
        link_kinematics(d, s, e, l)
        link_forces(d, s, e, l)


@ti.func
def down_sweep_adjoint_env(d: ti.template(), s, e):
    """Leaves to root: a link's gradients are complete once its children are done. A static link
    (welded to the world) passes on only its motion's gradient (to gravity): its pose depends on
    no input, and its inertia and forces reach no dof."""
    for r in range(d.n_links):
        l = d.n_links - 1 - r
        g_m, g_h, g_i = link_forces_adjoint(d, s, e, l)
        if not d.link_static[l]:
            link_kinematics_adjoint(d, s, e, l, g_m, g_h, g_i)


@ti.func
def position_stages_env(d: ti.template(), s, e):
    """Kinematics, then (leaves to root) composite inertias and subtree forces, then the mass
    matrix and bias forces of env e at frame s."""
    down_sweep_env(d, s, e)
    for r in range(d.n_links):
        subtree_sum(d, s, e, d.n_links - 1 - r)
    for i in range(d.n_dofs):
        dof_force(d, s, e, i)
    for k in range(d.n_pairs):
        mass_entry(d, s, e, k)
    for i in range(d.n_dofs):
        bias_entry(d, s, e, i)


@ti.func
def substep_env(d: ti.template(), s, e):
    """Frame s → frame s + 1."""
    position_stages_env(d, s, e)
    for i in range(d.n_dofs):
        smooth_force(d, s, e, i)
    solve_env(d, s, e)
    for l in range(d.n_links):
        integrate_link(d, s, e, l)


@ti.func
def dynamics_adjoint_env(d: ti.template(), s, e):
    """Gradients at frame s + 1 → frame s and the inputs, down to the link-sweep outputs (frame s
    must hold its forward values); down_sweep_adjoint_env finishes the substep."""
    for l in range(d.n_links):
        integrate_link_adjoint(d, s, e, l)
    solve_adjoint_env(d, s, e)
    for i in range(d.n_dofs):
        smooth_force_adjoint(d, s, e, i)
    for i in range(d.n_dofs):
        dof_row_adjoint(d, s, e, i)
    for l in range(d.n_links):
        subtree_sum_adjoint(d, s, e, l)


@ti.func
def _finite(x):
    return not (ti.math.isinf(x) or ti.math.isnan(x))


A = ti.types.ndarray()  # a torch tensor moving data in or out
I, F, V3, V4, M3 = ARENA_TYPES  # a scene's arenas (data.py)


@ti.kernel
def advance(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, commit: ti.i32, inputs: A, out: A):
    """All substeps of one step for every env in one launch (forward only). Unless empty, inputs
    (B, total input width) are loaded first and the result is written to out (B, Q + D) — each
    a launch saved. commit copies the result into frame 0 and flags any non-finite state."""
    ti.loop_config(serialize=schedule[0])
    for e in range(n_batch(ints)):
        d = bind(ints, f1, v3, v4, m3)
        S = d.substeps
        if inputs.shape[0] > 0:
            _inputs_from(d, e, inputs, 0)
        for s in range(S):
            substep_env(d, s, e)
        for k in range(d.n_qs):
            if not _finite(d.qpos[S, e, k]):
                d.nonfinite[0] = 1
        for k in range(d.n_dofs):
            if not _finite(d.qvel[S, e, k]):
                d.nonfinite[0] = 1
        if out.shape[0] > 0:
            _state_to(d, d.qpos, d.qvel, S, e, out)
        if commit:
            for k in range(d.n_qs):
                d.qpos[0, e, k] = d.qpos[S, e, k]
            for k in range(d.n_dofs):
                d.qvel[0, e, k] = d.qvel[S, e, k]


@ti.kernel
def prepare_reverse(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, src: A):
    """src (B, state | inputs | gradient of the end state): every gradient ← 0, frame 0 and the
    inputs ← the step's start, then the last frame's state gradient ← the seed."""
    _clear_grads(schedule, ints, f1, v3, v4, m3, True)
    ti.loop_config(serialize=schedule[1])  # moving data: on the CPU cheaper than a thread hand-off (see below)
    for e in range(n_batch(ints)):
        d = bind(ints, f1, v3, v4, m3)
        width = d.n_qs + d.n_dofs
        _state_from(d, d.qpos, d.qvel, 0, e, src, 0)
        _inputs_from(d, e, src, width)
        _state_from(d, d.qpos.grad, d.qvel.grad, d.substeps, e, src, width + d.input_total)


@ti.kernel
def reverse_dynamics(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, s: ti.i32):
    """Adjoints of substep s from the integration back to the subtree sums."""
    ti.loop_config(serialize=schedule[0])
    for e in range(n_batch(ints)):
        dynamics_adjoint_env(bind(ints, f1, v3, v4, m3), s, e)


@ti.kernel
def reverse_kinematics(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, s: ti.i32, dst: A):
    """Adjoint of substep s's down sweep; after substep 0 the gradients go to dst (B, state
    gradient | differentiable input gradients), as _read_grads_env lays it out."""
    ti.loop_config(serialize=schedule[0])
    for e in range(n_batch(ints)):
        d = bind(ints, f1, v3, v4, m3)
        down_sweep_adjoint_env(d, s, e)
        if s == 0:
            _read_grads_env(d, e, dst)


@ti.kernel
def down_sweep(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3):
    """Link poses and velocities at frame 0 (what the link getters read)."""
    ti.loop_config(serialize=schedule[0])
    for e in range(n_batch(ints)):
        down_sweep_env(bind(ints, f1, v3, v4, m3), 0, e)


@ti.kernel
def down_sweep_adjoint(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, src: A, dst: A):
    """src (B, L, 13): gradient of read_links' output → dst: gradient of the frame-0 state (as
    _read_grads_env lays it out). The down sweep at frame 0 must be current."""
    _clear_grads(schedule, ints, f1, v3, v4, m3, False)
    ti.loop_config(serialize=schedule[1])
    for e in range(n_batch(ints)):
        d = bind(ints, f1, v3, v4, m3)
        for l in range(d.n_links):
            for k in ti.static(range(3)):
                d.xpos.grad[0, e, l][k] = src[e, l, k]
                d.cvel_w.grad[0, e, l][k] = src[e, l, 7 + k]
                d.cvel_v.grad[0, e, l][k] = src[e, l, 10 + k]
            g_quat = ti.Vector([src[e, l, 3 + k] for k in ti.static(range(4))])
            d.xrot_grad[0, e, l] = rotation_gradient(d.xquat[0, e, l], g_quat)
    ti.loop_config(serialize=schedule[0])
    for e in range(n_batch(ints)):
        d = bind(ints, f1, v3, v4, m3)
        down_sweep_adjoint_env(d, 0, e)
        _read_grads_env(d, e, dst)


@ti.kernel
def position_stages(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3):
    """Mass matrix and bias at frame 0."""
    ti.loop_config(serialize=schedule[0])
    for e in range(n_batch(ints)):
        position_stages_env(bind(ints, f1, v3, v4, m3), 0, e)


# -- moving data: on the CPU serial loops on the calling thread. A parallel loop costs a thread-pool hand-off
# -- (~100 µs here in a rollout) whatever its size, more than copying a few floats of every env
@ti.func
def _state_from(d: ti.template(), qpos: ti.template(), qvel: ti.template(), s, e, src: ti.template(), offset):
    """Frame s of (qpos, qvel) (values or gradients) of env e ← src[e, offset:] (Q + D)."""
    for k in range(d.n_qs):
        qpos[s, e, k] = src[e, offset + k]
    for k in range(d.n_dofs):
        qvel[s, e, k] = src[e, offset + d.n_qs + k]


@ti.func
def _state_to(d: ti.template(), qpos: ti.template(), qvel: ti.template(), s, e, dst: ti.template()):
    """dst[e, :Q + D] ← frame s of (qpos, qvel) of env e."""
    for k in range(d.n_qs):
        dst[e, k] = qpos[s, e, k]
    for k in range(d.n_dofs):
        dst[e, d.n_qs + k] = qvel[s, e, k]


@ti.func
def _inputs_from(d: ti.template(), e, src: ti.template(), offset):
    """Every input of env e ← src[e, offset:] (total input width, in INPUTS order)."""
    for k in range(d.input_total):
        d.inputs[e, k] = src[e, offset + k]


@ti.kernel
def write_state(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, s: ti.i32, src: A):
    """Frame s ← src (B, Q + D): qpos then qvel of every env."""
    ti.loop_config(serialize=schedule[1])
    for e in range(n_batch(ints)):
        d = bind(ints, f1, v3, v4, m3)
        _state_from(d, d.qpos, d.qvel, s, e, src, 0)


@ti.kernel
def read_state(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, s: ti.i32, dst: A):
    ti.loop_config(serialize=schedule[1])
    for e in range(n_batch(ints)):
        d = bind(ints, f1, v3, v4, m3)
        _state_to(d, d.qpos, d.qvel, s, e, dst)


@ti.kernel
def write_inputs(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, src: A):
    """Every input ← its columns of src (B, total width), in INPUTS order."""
    ti.loop_config(serialize=schedule[1])
    for e in range(n_batch(ints)):
        _inputs_from(bind(ints, f1, v3, v4, m3), e, src, 0)


@ti.func
def _read_grads_env(d: ti.template(), e, dst: ti.template()):
    """dst[e] (Q + D + differentiable input widths) ← state gradient at frame 0, then the
    gradients of the differentiable inputs (the first columns of the inputs)."""
    _state_to(d, d.qpos.grad, d.qvel.grad, 0, e, dst)
    for k in range(d.grad_total):
        dst[e, d.n_qs + d.n_dofs + k] = d.inputs.grad[e, k]


@ti.func
def _zero_frames(region: ti.template(), frames):
    for k in range(region.start, region.start + frames * region.stride):
        region.arena[k] = ti.zero(region.arena[k])


@ti.func
def _clear_grads(schedule: ti.template(), ints: ti.template(), f1: ti.template(), v3: ti.template(),
                 v4: ti.template(), m3: ti.template(), whole_step: ti.template()):
    """Every input gradient and every gradient of frames 0 … S − 1 (whole_step) or of frame 0
    ← 0: one contiguous sweep per arena (data.py lays the gradients out frame by frame), ~21 GB/s
    here. A loop of its own, before the loops that seed gradients (no env races another)."""
    ti.loop_config(serialize=schedule[1])
    for _ in range(1):
        d = bind(ints, f1, v3, v4, m3)
        if ti.static(whole_step):
            _zero_grads(d, d.substeps)
        else:
            _zero_grads(d, 1)


@ti.func
def _zero_grads(d: ti.template(), frames):
    for r in ti.static(range(len(d.regions))):
        _zero_frames(d.regions[r], frames)
    for e in range(d.n_batch):
        for k in range(d.input_total):
            d.inputs.grad[e, k] = 0.0


@ti.kernel
def read_links(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, dst: A):
    """dst (B, L, 13) ← frame-0 link pos, quat, cvel (ω, v at the origin)."""
    ti.loop_config(serialize=schedule[1])
    for e in range(n_batch(ints)):
        d = bind(ints, f1, v3, v4, m3)
        for l in range(d.n_links):
            for k in ti.static(range(3)):
                dst[e, l, k] = d.xpos[0, e, l][k]
                dst[e, l, 7 + k] = d.cvel_w[0, e, l][k]
                dst[e, l, 10 + k] = d.cvel_v[0, e, l][k]
            for k in ti.static(range(4)):
                dst[e, l, 3 + k] = d.xquat[0, e, l][k]


@ti.kernel
def read_mass_matrix(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, dst: A):
    ti.loop_config(serialize=schedule[1])
    for e in range(n_batch(ints)):
        d = bind(ints, f1, v3, v4, m3)
        for i, j in ti.ndrange(d.n_dofs, d.n_dofs):
            dst[e, i, j] = d.mass_mat[0, e, i, j]


@ti.kernel
def read_dofs_force(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, dst: A):
    """dst (B, D) ← qfrc_smooth at frame 0 (the position stages and the force stage run there):
    the force the next step's solve is given, at the current state and inputs."""
    ti.loop_config(serialize=schedule[0])
    for e in range(n_batch(ints)):
        d = bind(ints, f1, v3, v4, m3)
        position_stages_env(d, 0, e)
        for i in range(d.n_dofs):
            smooth_force(d, 0, e, i)
            dst[e, i] = d.qfrc_smooth[0, e, i]


#: what solver.py launches (through solvers.launch, with the scene's arenas)
KERNELS = (advance, prepare_reverse, reverse_dynamics, reverse_kinematics, down_sweep, down_sweep_adjoint,
           position_stages, write_state, read_state, write_inputs, read_links, read_mass_matrix, read_dofs_force)
