"""One rigid step, forward and reverse: the stage order, and moving state, inputs and
gradients between the Taichi fields and torch.

Forward runs every substep of every env in one fused launch (``advance``), built from the
same per-item functions as the stage kernels. Reverse replays that launch to refill the
frames, then runs each stage's gradient kernel backwards, substep by substep.
"""
import taichi as ti

from .actuation import smooth_force
from .dynamics import bias_entry, dof_force, link_forces, mass_entry, subtree_sum
from .integrator import integrate_link
from .kinematics import link_kinematics
from .linalg import solve, solve_adjoint, solve_env


# -- per-env stage functions: the stages of one substep, in order -------------------------------
@ti.func
def down_sweep_env(d: ti.template(), s, e):
    """Root to leaves: each link's pose, inertia, motion subspace, velocity and net force."""
    for l in range(d.n_links):
        link_kinematics(d, s, e, l)
        link_forces(d, s, e, l)


@ti.func
def up_sweep_env(d: ti.template(), s, e):
    """Leaves to root: composite inertias and subtree forces."""
    for i in range(d.n_links):
        subtree_sum(d, s, e, d.n_links - 1 - i)


# -- stage kernels (reverse mode runs their .grad; Taichi needs one serial loop per kernel) ------
@ti.kernel
def down_sweep(d: ti.template(), s: ti.i32):
    for e in range(d.n_batch):
        down_sweep_env(d, s, e)


@ti.kernel
def up_sweep(d: ti.template(), s: ti.i32):
    for e in range(d.n_batch):
        up_sweep_env(d, s, e)


@ti.kernel
def joint_forces(d: ti.template(), s: ti.i32):
    """Mass matrix, bias forces, then actuation, each parallel over (env, dof or pair)."""
    for e, i in ti.ndrange(d.n_batch, d.n_dofs):
        dof_force(d, s, e, i)
    for e, k in ti.ndrange(d.n_batch, d.n_pairs):
        mass_entry(d, s, e, k)
    for e, i in ti.ndrange(d.n_batch, d.n_dofs):
        bias_entry(d, s, e, i)
    for e, i in ti.ndrange(d.n_batch, d.n_dofs):
        smooth_force(d, s, e, i)


@ti.kernel
def integrate(d: ti.template(), s: ti.i32):
    for e, l in ti.ndrange(d.n_batch, d.n_links):
        integrate_link(d, s, e, l)


# Stage kernels of one substep, in forward order. Reverse mode walks it backwards; the
# solve's adjoint is hand-written (see linalg.py), every other stage uses Taichi's .grad.
STAGES = (down_sweep, up_sweep, joint_forces, solve, integrate)
ADJOINTS = {solve: solve_adjoint}


@ti.func
def _finite(x):
    return not (ti.math.isinf(x) or ti.math.isnan(x))


@ti.func
def position_stages_env(d: ti.template(), s, e):
    """Kinematics, bias forces and mass matrix of env e at frame s."""
    down_sweep_env(d, s, e)
    up_sweep_env(d, s, e)
    for i in range(d.n_dofs):
        dof_force(d, s, e, i)
    for k in range(d.n_pairs):
        mass_entry(d, s, e, k)
    for i in range(d.n_dofs):
        bias_entry(d, s, e, i)


@ti.kernel
def advance(d: ti.template(), commit: ti.i32):
    """All substeps of one step for every env in one launch (forward only); commit copies the
    result into frame 0 and flags any non-finite state."""
    S = d.substeps
    for e in range(d.n_batch):
        for s in range(S):
            position_stages_env(d, s, e)
            for i in range(d.n_dofs):
                smooth_force(d, s, e, i)
            solve_env(d, s, e)
            for l in range(d.n_links):
                integrate_link(d, s, e, l)
        for k in range(d.n_qs):
            if not _finite(d.qpos[S, e, k]):
                d.nonfinite[0] = 1
        for k in range(d.n_dofs):
            if not _finite(d.qvel[S, e, k]):
                d.nonfinite[0] = 1
        if commit:
            for k in range(d.n_qs):
                d.qpos[0, e, k] = d.qpos[S, e, k]
            for k in range(d.n_dofs):
                d.qvel[0, e, k] = d.qvel[S, e, k]


@ti.kernel
def position_stages(d: ti.template(), s: ti.i32):
    for e in range(d.n_batch):
        position_stages_env(d, s, e)


def reverse_substep(d, s):
    """Gradient kernels of substep s in reverse stage order (frame s must hold its forward values)."""
    for stage in reversed(STAGES):
        ADJOINTS.get(stage, stage.grad)(d, s)


# -- moving data: one parallel loop over envs per kernel, since every parallel loop is a task
# -- that costs a thread-pool hand-off (tens of µs here) whatever its size ----------------------
@ti.kernel
def write_state(d: ti.template(), s: ti.i32, src: ti.types.ndarray()):
    """Frame s ← src (B, Q + D): qpos then qvel of every env."""
    for e in range(d.n_batch):
        for k in range(d.n_qs):
            d.qpos[s, e, k] = src[e, k]
        for k in range(d.n_dofs):
            d.qvel[s, e, k] = src[e, d.n_qs + k]


@ti.kernel
def read_state(d: ti.template(), s: ti.i32, dst: ti.types.ndarray()):
    for e in range(d.n_batch):
        for k in range(d.n_qs):
            dst[e, k] = d.qpos[s, e, k]
        for k in range(d.n_dofs):
            dst[e, d.n_qs + k] = d.qvel[s, e, k]


@ti.kernel
def write_inputs(d: ti.template(), src: ti.types.ndarray()):
    """Every input field ← its columns of src (B, total width), in INPUTS order."""
    for e in range(d.n_batch):
        for f in ti.static(range(len(d.input_fields))):
            for k in range(d.input_widths[f]):
                d.input_fields[f][e, k] = src[e, d.input_offsets[f] + k]


@ti.kernel
def read_grads(d: ti.template(), dst: ti.types.ndarray()):
    """dst (B, Q + D + differentiable input widths) ← state gradient at frame 0, then input gradients."""
    for e in range(d.n_batch):
        for k in range(d.n_qs):
            dst[e, k] = d.qpos.grad[0, e, k]
        for k in range(d.n_dofs):
            dst[e, d.n_qs + k] = d.qvel.grad[0, e, k]
        for f in ti.static(range(len(d.grad_input_fields))):
            for k in range(d.grad_input_widths[f]):
                dst[e, d.grad_input_offsets[f] + k] = d.grad_input_fields[f].grad[e, k]


@ti.func
def _zero_frames_grad(fld: ti.template(), e):
    """Zero env e of a (frames, B, ...) gradient field."""
    for J in ti.grouped(ti.ndrange(fld.shape[0], *fld.shape[2:])):
        fld.grad[J[0], e, *[J[k] for k in ti.static(range(1, J.n))]] = 0


@ti.func
def _clear_grads_env(d: ti.template(), e):
    for group in ti.static(d.grad_frame_groups):  # groups of ≤ 32: Taichi warns past that
        for f in ti.static(range(len(group))):
            _zero_frames_grad(group[f], e)
    for f in ti.static(range(len(d.grad_input_fields))):
        for k in range(d.grad_input_widths[f]):
            d.grad_input_fields[f].grad[e, k] = 0


@ti.kernel
def clear_grads(d: ti.template()):
    for e in range(d.n_batch):
        _clear_grads_env(d, e)


@ti.kernel
def prepare_reverse(d: ti.template(), src: ti.types.ndarray()):
    """src (B, state | inputs | state gradient): frame 0 ← start state, inputs ← their
    columns, every gradient ← 0, then the last frame's state gradient ← the output gradient."""
    for e in range(d.n_batch):
        width = d.n_qs + d.n_dofs
        for k in range(d.n_qs):
            d.qpos[0, e, k] = src[e, k]
        for k in range(d.n_dofs):
            d.qvel[0, e, k] = src[e, d.n_qs + k]
        for f in ti.static(range(len(d.input_fields))):
            for k in range(d.input_widths[f]):
                d.input_fields[f][e, k] = src[e, width + d.input_offsets[f] + k]
        _clear_grads_env(d, e)
        seed = width + d.input_total
        for k in range(d.n_qs):
            d.qpos.grad[d.substeps, e, k] = src[e, seed + k]
        for k in range(d.n_dofs):
            d.qvel.grad[d.substeps, e, k] = src[e, seed + d.n_qs + k]


@ti.kernel
def read_links(d: ti.template(), dst: ti.types.ndarray()):
    """dst (B, L, 13) ← frame-0 link pos, quat, cvel (ω, v at the origin)."""
    for e, l in ti.ndrange(d.n_batch, d.n_links):
        for k in ti.static(range(3)):
            dst[e, l, k] = d.xpos[0, e, l][k]
            dst[e, l, 7 + k] = d.cvel_w[0, e, l][k]
            dst[e, l, 10 + k] = d.cvel_v[0, e, l][k]
        for k in ti.static(range(4)):
            dst[e, l, 3 + k] = d.xquat[0, e, l][k]


@ti.kernel
def write_links_grad(d: ti.template(), src: ti.types.ndarray()):
    for e, l in ti.ndrange(d.n_batch, d.n_links):
        for k in ti.static(range(3)):
            d.xpos.grad[0, e, l][k] = src[e, l, k]
            d.cvel_w.grad[0, e, l][k] = src[e, l, 7 + k]
            d.cvel_v.grad[0, e, l][k] = src[e, l, 10 + k]
        for k in ti.static(range(4)):
            d.xquat.grad[0, e, l][k] = src[e, l, 3 + k]


@ti.kernel
def read_mass_matrix(d: ti.template(), dst: ti.types.ndarray()):
    for e, i, j in ti.ndrange(d.n_batch, d.n_dofs, d.n_dofs):
        dst[e, i, j] = d.mass_mat[0, e, i, j]
