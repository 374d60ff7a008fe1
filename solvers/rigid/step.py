"""One rigid step, forward and reverse, and moving state, inputs and gradients between the
scene's arenas and torch.

Forward runs every substep of every env in one launch (``advance``, which can also load the
inputs and write out the result) when no constraint row arises: no contact pair, no friction
loss, and (checked per env and substep) no violated joint limit. Otherwise a substep is two
stage kernels: smooth, then constrain (the rows, the solve and finish's integration) when some
env has a row to form (the header's ``constrained`` flag), else finish; and one collider kernel
per pair kind between the two (see below; the constraint solve inlined into ``advance`` took
LLVM 100 s to compile); an env that advance stops at a limit is taken again from its start by
those, which then skip the other envs. Both ways give the same bits when no row arises.

Reverse: ``prepare_reverse`` loads the step's start state, inputs and output gradient, the
forward replays the substeps to refill the frames, then for each substep, last first,
``reverse_dynamics`` and ``reverse_kinematics`` run the stages' hand-written adjoints in
reverse order; after substep 0 the gradients are written out.
(Fused into one kernel, LLVM took 31 s to compile it; split so, 6 s.) Each env belongs to one
thread, so gradients accumulate without atomics.

Every kernel takes ``schedule`` (compile-time: whether its compute loop, and its data-moving
loops, run on the calling thread; data.RigidData.schedule) and the scene's five arenas
(data.py), and binds them to a view in its env loop: one compiled kernel serves every scene
of the process.
"""
import taichi as ti

from .data import ARENA_TYPES, CONST, accumulate, bind, env_loop, env_of, n_batch
from .actuation import smooth_force, smooth_force_adjoint, tendon_spring, tendon_spring_adjoint
from .collision.detect import (collide_adjoint_kind, collide_kind, converge_contacts, flag_inexact, geom_poses,
                               geom_poses_adjoint, near_pairs, replay_exact, sort_contacts)
from .constraint.implicit import solve_adjoint
from .constraint.rows import contact_force, contact_included, contact_rows, dof_rows, dof_rows_arise, limit_violated
from .constraint.solver import newton_solve
from .dynamics import (bias_entry, dof_force, dof_row_adjoint, link_forces, link_forces_adjoint, mass_entry,
                       subtree_sum, subtree_sum_adjoint)
from .integrator import integrate_link, integrate_link_adjoint
from .kinematics import dof_count, dof_motion_at, link_kinematics, link_kinematics_adjoint, reference, rotation_gradient
from .spatial import mat_vec, quat_to_mat
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
def constraint_env(d: ti.template(), s, e, replaying):
    """Rows of frame s (joint rows, then its contacts', in MuJoCo's order), then the
    constraint solve → qacc_constrained and qfrc_constraint[s, e] (replaying: qacc_constrained
    holds the forward's solution: constraint/solver.py's "Replay")."""
    sort_contacts(d, s, e)
    rows = dof_rows(d, s, e)
    for c in range(d.n_con[s, e, 0]):
        if not replay_exact(d, s, e, c):
            flag_inexact(d, s, e, c)
        d.con_efc[s, e, c] = rows
        if contact_included(d, s, e, c):
            rows += contact_rows(d, s, e, c, rows)
    d.n_efc[s, e, 0] = rows
    if rows > 0:  # (else qfrc_constraint stays smooth_substep's zero)
        for k in range(d.n_pairs):  # the solve's M: symmetric, with armature (other entries stay 0)
            i, j = d.pair_i[k], d.pair_j[k]
            d.solver_M[s, e, i, j] = d.solver_M[s, e, j, i] = d.mass_mat[s, e, i, j]
        for i in range(d.n_dofs):
            accumulate(d.solver_M, ti.Vector([s, e, i, i]), d.armature[e, i])
        newton_solve(d, s, e, d.iterations, d.consts[CONST["tolerance"]], d.ls_iterations,
                     d.consts[CONST["ls_tolerance"]], replaying)
        for i in range(d.n_dofs):  # the next solve starts from this solution
            d.qacc_constrained[s, e, i] = d.qacc_warmstart[e, i] = d.qacc[s, e, i]


@ti.func
def smooth_env(d: ti.template(), s, e):
    """Frame s's position stages and smooth force (everything before the solve)."""
    position_stages_env(d, s, e)
    for i in range(d.n_dofs):
        smooth_force(d, s, e, i)
    for t in range(d.n_tendons):
        tendon_spring(d, s, e, t)


@ti.func
def finish_substep_env(d: ti.template(), s, e, rows: ti.template()):
    """Frame s's acceleration and integration → frame s + 1 (rows: after a constraint stage)."""
    solve_env(d, s, e, rows)
    for l in range(d.n_links):
        integrate_link(d, s, e, l)


@ti.func
def substep_env(d: ti.template(), s, e):
    """Frame s → frame s + 1 without constraint rows (n_efc = 0 tells the reverse so)."""
    smooth_env(d, s, e)
    d.n_efc[s, e, 0] = 0
    finish_substep_env(d, s, e, False)


@ti.func
def dynamics_adjoint_env(d: ti.template(), s, e, rows: ti.template()):
    """Gradients at frame s + 1 → frame s and the inputs, down to the link-sweep outputs (frame s
    must hold its forward values); down_sweep_adjoint_env finishes the substep."""
    for l in range(d.n_links):
        integrate_link_adjoint(d, s, e, l)
    solve_adjoint_env(d, s, e, rows)
    if ti.static(rows):
        if d.n_efc[s, e, 0] > 0:
            solve_adjoint(d, s, e)
    for t in range(d.n_tendons):
        tendon_spring_adjoint(d, s, e, t)
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
    """All substeps of one step for every env in one launch (forward only), for a step without
    contact pairs or friction loss. Unless empty, inputs (B, total input width) are loaded first
    and the result is written to out (B, Q + D) — each a launch saved. commit copies the result
    into frame 0 and flags any non-finite state. An env that meets a violated joint limit at a
    substep stops there, uncommitted, with needs_rows set (and the header's rows_needed): the
    constrained stage kernels then take the step for it (solver.run_step)."""
    ti.loop_config(serialize=schedule[0])
    for t in range(env_loop(ints, schedule[0])):
        e = env_of(ints, t, schedule[0])
        if e >= 0:
            d = bind(ints, f1, v3, v4, m3)
            S = d.substeps
            if inputs.shape[0] > 0:
                _inputs_from(d, e, inputs, 0)
            violated = 0
            for s in range(S):
                if violated == 0:
                    violated = limit_violated(d, s, e)
                    if violated == 0:
                        substep_env(d, s, e)
            d.needs_rows[e, 0] = violated
            if violated:
                d.rows_needed[0] = 1
            else:
                _end_step(d, e, commit, out)


@ti.func
def _end_step(d: ti.template(), e, commit, out: ti.template()):
    """After the last substep: write the result to out (unless empty), and with commit flag a
    non-finite state and copy it into frame 0 (uncommitted, a backward's replay: its forward step
    flagged it already, and a flag left by the replay was reported at the next rollout's first
    step)."""
    S = d.substeps
    for k in range(d.n_qs):
        if commit and not _finite(d.qpos[S, e, k]):
            d.nonfinite[0] = 1
    for k in range(d.n_dofs):
        if commit and not _finite(d.qvel[S, e, k]):
            d.nonfinite[0] = 1
    if out.shape[0] > 0:
        _state_to(d, d.qpos, d.qvel, S, e, out)
    if commit:
        for k in range(d.n_qs):
            d.qpos[0, e, k] = d.qpos[S, e, k]
        for k in range(d.n_dofs):
            d.qvel[0, e, k] = d.qvel[S, e, k]


# -- a substep with constraint rows: one kernel per stage (inlined into one, LLVM compiled for many
# -- minutes), a collider kernel per pair kind present in the scene, compiled for those only
@ti.func
def _skipped(d: ti.template(), e, flagged_only):
    """With flagged_only, the stage kernels take only the envs advance left to them (needs_rows)."""
    return flagged_only and d.needs_rows[e, 0] == 0


@ti.kernel
def smooth_substep(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, s: ti.i32, inputs: A,
                   flagged_only: ti.i32):
    """Frame s up to the smooth force, then the geom poses and the broad phase (near pairs, the
    header's colliders_due mask); the contact list emptied and the frame left as one without
    rows (the constraint stage, if it runs, overwrites that); the header's ``constrained`` flag
    raised if the env has dof rows to form. At s = 0 the inputs (unless empty) are loaded first."""
    ti.loop_config(serialize=schedule[0])
    for t in range(env_loop(ints, schedule[0])):
        e = env_of(ints, t, schedule[0])
        if e >= 0:
            d = bind(ints, f1, v3, v4, m3)
            if not _skipped(d, e, flagged_only):
                if s == 0 and inputs.shape[0] > 0:
                    _inputs_from(d, e, inputs, 0)
                smooth_env(d, s, e)
                geom_poses(d, s, e)
                near_pairs(d, s, e)
                d.n_con[s, e, 0] = d.n_efc[s, e, 0] = 0
                for i in range(d.n_dofs):
                    d.qfrc_constraint[s, e, i] = 0.0
                if dof_rows_arise(d, s, e):
                    d.constrained[0] = 1


@ti.kernel
def collide(config: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, s: ti.i32):
    """Frame s's contacts of the pairs of one kind; config = (schedule, (type 1, type 2))."""
    ti.loop_config(serialize=config[0][0])
    for t in range(env_loop(ints, config[0][0])):
        e = env_of(ints, t, config[0][0])
        if e >= 0:
            collide_kind(bind(ints, f1, v3, v4, m3), s, e, config[1])


@ti.kernel
def converge(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, s: ti.i32):
    """Frame s's curved convex contacts made the closed form of their feature (after the colliders)."""
    ti.loop_config(serialize=schedule[0])
    for t in range(env_loop(ints, schedule[0])):
        e = env_of(ints, t, schedule[0])
        if e >= 0:
            converge_contacts(bind(ints, f1, v3, v4, m3), s, e)


@ti.kernel
def constrain(config: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, s: ti.i32, flagged_only: ti.i32,
              replaying: ti.i32, commit: ti.i32, out: A):
    """Frame s's constraint rows and solve, then what finish_substep does (frame s → s + 1, and
    after the last substep the end of a step): one launch where two took ~3 µs more at one env.
    config = (schedule, elliptic, body_eqs, max_condim): the cone is compiled in, so a scene loads
    only its own cone's code (the elliptic cone's is a third of the kernel), the connects' and
    welds' rows only where the scene has some, the torsional and rolling rows where it has them
    (RigidView); replaying: a backward's replay given the forward's solutions (constraint_env)."""
    ti.loop_config(serialize=config[0][0])
    for t in range(env_loop(ints, config[0][0])):
        e = env_of(ints, t, config[0][0])
        if e >= 0:
            d = bind(ints, f1, v3, v4, m3, cone=config[1], body_eqs=config[2], max_condim=config[3])
            if not _skipped(d, e, flagged_only):
                constraint_env(d, s, e, replaying)
                _finish_env(d, s, e, commit, out)


@ti.kernel
def finish_substep(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, s: ti.i32, commit: ti.i32,
                   out: A, flagged_only: ti.i32):
    """Frame s → frame s + 1; after the last substep, what advance does at the end of a step."""
    ti.loop_config(serialize=schedule[0])
    for t in range(env_loop(ints, schedule[0])):
        e = env_of(ints, t, schedule[0])
        if e >= 0:
            d = bind(ints, f1, v3, v4, m3)
            if not _skipped(d, e, flagged_only):
                _finish_env(d, s, e, commit, out)


@ti.func
def _finish_env(d: ti.template(), s, e, commit, out: ti.template()):
    """Frame s → frame s + 1 (rows or not: n_efc says); after the last substep, _end_step."""
    finish_substep_env(d, s, e, True)
    if s == d.substeps - 1:
        _end_step(d, e, commit, out)


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
def reverse_dynamics(config: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, s: ti.i32):
    """Adjoints of substep s from the integration back to the subtree sums; config = (schedule,
    rows, elliptic, body_eqs, max_condim), rows: the step had a constraint stage; the rest compiled
    in, as constrain's (False, False, 3 without rows)."""
    ti.loop_config(serialize=config[0][0])
    for t in range(env_loop(ints, config[0][0])):
        e = env_of(ints, t, config[0][0])
        if e >= 0:
            d = bind(ints, f1, v3, v4, m3, cone=config[2], body_eqs=config[3], max_condim=config[4])
            dynamics_adjoint_env(d, s, e, config[1])


@ti.kernel
def collide_adjoint(config: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, s: ti.i32):
    """Reverse of frame s's contacts of one pair kind (into the geoms' pose gradients); config =
    (schedule, (type 1, type 2)). Runs between reverse_dynamics and reverse_kinematics."""
    ti.loop_config(serialize=config[0][0])
    for t in range(env_loop(ints, config[0][0])):
        e = env_of(ints, t, config[0][0])
        if e >= 0:
            collide_adjoint_kind(bind(ints, f1, v3, v4, m3), s, e, config[1])


@ti.kernel
def reverse_kinematics(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, s: ti.i32, dst: A):
    """Adjoint of substep s's geom poses (when it had contacts) and down sweep; after substep 0
    the gradients go to dst (B, state gradient | differentiable input gradients), as
    _read_grads_env lays it out."""
    ti.loop_config(serialize=schedule[0])
    for t in range(env_loop(ints, schedule[0])):
        e = env_of(ints, t, schedule[0])
        if e >= 0:
            d = bind(ints, f1, v3, v4, m3)
            if d.n_con[s, e, 0] > 0:
                geom_poses_adjoint(d, s, e)
            down_sweep_adjoint_env(d, s, e)
            if s == 0:
                _read_grads_env(d, e, dst)


@ti.kernel
def down_sweep(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, f: ti.i32):
    """Link poses and velocities of the state (frame 0) at frame f, for the adjoint of a link
    getter (down_sweep_adjoint), which takes frame 0. The getters themselves (read_links, and
    read_mass_matrix) sweep the last frame, which no substep's stages use, so that the last
    step's intermediates stay for its readouts (read_links_acc, read_contacts...) and its reverse."""
    ti.loop_config(serialize=schedule[0])
    for t in range(env_loop(ints, schedule[0])):
        e = env_of(ints, t, schedule[0])
        if e >= 0:
            d = bind(ints, f1, v3, v4, m3)
            _state_at(d, e, f)
            down_sweep_env(d, f, e)


@ti.func
def _state_at(d: ti.template(), e, f):
    """Frame f's (qpos, qvel) of env e ← frame 0's, the state (f = 0: nothing to do)."""
    if f != 0:
        for k in range(d.n_qs):
            d.qpos[f, e, k] = d.qpos[0, e, k]
        for k in range(d.n_dofs):
            d.qvel[f, e, k] = d.qvel[0, e, k]


@ti.kernel
def down_sweep_adjoint(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, src: A, dst: A):
    """src (B, L, 13): gradient of read_links' output → dst: gradient of the frame-0 state (as
    _read_grads_env lays it out). The down sweep at frame 0 must be current."""
    _clear_grads(schedule, ints, f1, v3, v4, m3, False)
    ti.loop_config(serialize=schedule[1])
    for e in range(n_batch(ints)):
        d = bind(ints, f1, v3, v4, m3)
        for l in range(d.n_links):
            # v = cvel_v + ω × (pos − reference), the reference a constant (kinematics.py)
            g_pos = ti.Vector([src[e, l, k] for k in ti.static(range(3))])
            g_w = ti.Vector([src[e, l, 7 + k] for k in ti.static(range(3))])
            g_v = ti.Vector([src[e, l, 10 + k] for k in ti.static(range(3))])
            w, arm = d.cvel_w[0, e, l], d.xpos[0, e, l] - reference(d, 0, e, l)
            d.xpos.grad[0, e, l] = g_pos + g_v.cross(w)
            d.cvel_w.grad[0, e, l] = g_w + arm.cross(g_v)
            d.cvel_v.grad[0, e, l] = g_v
            g_quat = ti.Vector([src[e, l, 3 + k] for k in ti.static(range(4))])
            d.xrot_grad[0, e, l] = rotation_gradient(d.xquat[0, e, l], g_quat)
    ti.loop_config(serialize=schedule[0])
    for t in range(env_loop(ints, schedule[0])):
        e = env_of(ints, t, schedule[0])
        if e >= 0:
            d = bind(ints, f1, v3, v4, m3)
            down_sweep_adjoint_env(d, 0, e)
            _read_grads_env(d, e, dst)


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
    """Frame s ← src (B, Q + D): qpos then qvel of every env. The constraint solve's warm start
    is cleared too (as MuJoCo's reset does): a step then depends on its start state alone, so a
    rollout repeated from the same state, alone or in a batch, gives the same bits."""
    ti.loop_config(serialize=schedule[1])
    for e in range(n_batch(ints)):
        d = bind(ints, f1, v3, v4, m3)
        _state_from(d, d.qpos, d.qvel, s, e, src, 0)
        for k in range(d.n_dofs):
            d.qacc_warmstart[e, k] = 0.0


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
    # a literal zero: ti.zero(x) is x·0, which without fast math reads every element and keeps NaN
    for k in range(region.start, region.start + frames * region.stride):
        if ti.static(len(region.shape) == 0):
            region.arena[k] = 0.0
        elif ti.static(len(region.shape) == 1):
            region.arena[k] = ti.Vector.zero(float, region.shape[0])
        else:
            region.arena[k] = ti.Matrix.zero(float, region.shape[0], region.shape[1])


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
def read_links(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, f: ti.i32, dst: A):
    """dst (B, L, 13) ← the link pos, quat, ω and v of the link origin (world frame) of the state
    (frame 0), swept at frame f (see down_sweep) by the env's own thread (one launch: as two,
    the sweep and the copy, a link getter after a step took ~3 µs more of launching)."""
    ti.loop_config(serialize=schedule[0])
    for t in range(env_loop(ints, schedule[0])):
        e = env_of(ints, t, schedule[0])
        if e >= 0:
            d = bind(ints, f1, v3, v4, m3)
            _state_at(d, e, f)
            down_sweep_env(d, f, e)
            for l in range(d.n_links):
                w, pos = d.cvel_w[f, e, l], d.xpos[f, e, l]
                v = d.cvel_v[f, e, l] + w.cross(pos - reference(d, f, e, l))
                for k in ti.static(range(3)):
                    dst[e, l, k] = pos[k]
                    dst[e, l, 7 + k] = w[k]
                    dst[e, l, 10 + k] = v[k]
                for k in ti.static(range(4)):
                    dst[e, l, 3 + k] = d.xquat[f, e, l][k]


@ti.kernel
def read_links_acc(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, dst: A):
    """dst (B, L, 6) ← each link's classical linear acceleration of its origin (m/s²) and angular
    acceleration α (rad/s²), world frame, in the last step's last substep: the link's spatial
    acceleration at its tree's reference — cacc (the velocity products and the base's −gravity,
    taken back out here) plus Σ cdof·q̈ over the dofs from the root down to it — its linear part
    moved to the origin, a + α × r + ω × (v + ω × r), r = origin − reference (as
    _point_bias_acceleration moves it, q̈ added)."""
    ti.loop_config(serialize=schedule[1])
    for e in range(n_batch(ints)):
        d = bind(ints, f1, v3, v4, m3)
        s = d.substeps - 1
        gravity = ti.Vector([d.gravity[e, k] for k in ti.static(range(3))])
        for l in range(d.n_links):
            alpha, acc = d.cacc_w[s, e, l], d.cacc_v[s, e, l] + gravity
            j = l
            while j >= 0:  # (the dofs from link l up to its root)
                for i in range(d.link_dof0[j], d.link_dof0[j] + dof_count(d, j)):
                    alpha += d.cdof_w[s, e, i] * d.qacc[s, e, i]
                    acc += d.cdof_v[s, e, i] * d.qacc[s, e, i]
                j = d.link_parent[j]
            w, r = d.cvel_w[s, e, l], d.xpos[s, e, l] - reference(d, s, e, l)
            out = acc + alpha.cross(r) + w.cross(d.cvel_v[s, e, l] + w.cross(r))
            for k in ti.static(range(3)):
                dst[e, l, k], dst[e, l, 3 + k] = out[k], alpha[k]


@ti.kernel
def read_mass_matrix(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, f: ti.i32, dst: A):
    """dst (B, D, D) ← the mass matrix of the state (frame 0), armature on its diagonal, computed
    at frame f (see down_sweep) by the position stages and written out by the env's own thread
    (one launch where there were two; with the entity's indexing trimmed, get_mass_mat of a
    one-env KUKA 60 → 22 µs)."""
    ti.loop_config(serialize=schedule[0])
    for t in range(env_loop(ints, schedule[0])):
        e = env_of(ints, t, schedule[0])
        if e >= 0:
            d = bind(ints, f1, v3, v4, m3)
            _state_at(d, e, f)
            position_stages_env(d, f, e)
            for i, j in ti.ndrange(d.n_dofs, d.n_dofs):
                dst[e, i, j] = d.mass_mat[f, e, i, j]
            for i in range(d.n_dofs):
                dst[e, i, i] += d.armature[e, i]


@ti.kernel
def read_dofs_dynamics(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, dst: A):
    """dst (B, 2, D) ← the last step's last substep's generalised force (row 0: its smooth force,
    clipped actuator force − damping·q̇ − joint springs + tendon springs and dampers − bias at that
    substep's start, plus its constraint force: joint limits, friction loss, contacts, none where
    the substep had no rows,
    as the one-launch step leaves qfrc_constraint as it was; Genesis's dofs force) and the
    acceleration it integrated (row 1: q̇' = q̇ + h·q̈, implicit damping included)."""
    ti.loop_config(serialize=schedule[1])
    for e in range(n_batch(ints)):
        d = bind(ints, f1, v3, v4, m3)
        s = d.substeps - 1
        for i in range(d.n_dofs):
            dst[e, 0, i] = d.qfrc_smooth[s, e, i]
            if d.n_efc[s, e, 0] > 0:
                dst[e, 0, i] += d.qfrc_constraint[s, e, i]
            dst[e, 1, i] = d.qacc[s, e, i]


@ti.kernel
def read_com_jacobians(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, dst: A):
    """dst (b, L, 6, D) ← each link's centre-of-mass Jacobian at the frame-0 state of envs 0 … b − 1
    (b ≤ B), after the link poses there (rows: linear velocity of the com, world frame; then
    angular velocity, in the link's own frame, where its inertia is given: M = Σ_l Jᵀ diag(m_l,
    I_l) J)."""
    ti.loop_config(serialize=schedule[0])
    for e in range(dst.shape[0]):
        d = bind(ints, f1, v3, v4, m3)
        for l in range(d.n_links):  # (parents first: a link's pose needs its parent's)
            link_kinematics(d, 0, e, l)
        for l in range(d.n_links):
            rot = quat_to_mat(d.xquat[0, e, l])
            com = d.xpos[0, e, l] + mat_vec(rot, d.link_com[l])
            for i in range(d.n_dofs):
                for k in ti.static(range(6)):
                    dst[e, l, k, i] = 0.0
            a = l
            while a >= 0:
                for i in range(d.link_dof0[a], d.link_dof0[a] + dof_count(d, a)):
                    linear, angular = dof_motion_at(d, 0, e, i, com)
                    angular = mat_vec(rot.transpose(), angular)
                    for k in ti.static(range(3)):
                        dst[e, l, k, i] = linear[k]
                        dst[e, l, 3 + k, i] = angular[k]
                a = d.link_parent[a]


@ti.kernel
def read_contacts(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, s: ti.i32, dst: A):
    """dst (B, W, 12) ← substep s's contacts in the first W slots (W ≤ C): geom 1, geom 2 (as
    floats), position (3, m), force on geom 2 (3, N, world; −it acts on geom 1), distance (m),
    normal (3, geom 1 → geom 2); rows past n_con: geom −1, the rest 0."""
    ti.loop_config(serialize=schedule[1])
    for e in range(n_batch(ints)):
        d = bind(ints, f1, v3, v4, m3)
        for c in range(dst.shape[1]):
            dst[e, c, 0], dst[e, c, 1] = -1.0, -1.0
            for k in ti.static(range(2, 12)):
                dst[e, c, k] = 0.0
            if c < d.n_con[s, e, 0]:
                pair = d.con_pair[s, e, c]
                force = d.con_frame[s, e, c].transpose() @ contact_force(d, s, e, c)
                dst[e, c, 0], dst[e, c, 1] = d.pair_geom1[pair], d.pair_geom2[pair]
                for k in ti.static(range(3)):
                    dst[e, c, 2 + k] = d.con_pos[s, e, c][k]
                    dst[e, c, 5 + k] = force[k]
                    dst[e, c, 9 + k] = d.con_frame[s, e, c][0, k]
                dst[e, c, 8] = d.con_dist[s, e, c]


@ti.kernel
def read_links_contact_force(schedule: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, s: ti.i32, dst: A):
    """dst (B, L, 3) ← the sum of substep s's contact forces on each link (N, world): a contact's
    force on geom 2 (read_contacts') on its link, its opposite on geom 1's, in contact order."""
    ti.loop_config(serialize=schedule[1])
    for e in range(n_batch(ints)):
        d = bind(ints, f1, v3, v4, m3)
        for l, k in ti.ndrange(d.n_links, 3):
            dst[e, l, k] = 0.0
        for c in range(d.n_con[s, e, 0]):
            pair = d.con_pair[s, e, c]
            force = d.con_frame[s, e, c].transpose() @ contact_force(d, s, e, c)
            first, second = d.geom_link[d.pair_geom1[pair]], d.geom_link[d.pair_geom2[pair]]
            for k in ti.static(range(3)):
                dst[e, first, k] = dst[e, first, k] - force[k]
                dst[e, second, k] = dst[e, second, k] + force[k]


#: what solver.py launches (through solvers.launch, with the scene's arenas; reverse_dynamics,
#: collide and constrain with a config of their own: constrain's is the solve's schedule and the cone)
KERNELS = (advance, prepare_reverse, reverse_kinematics, down_sweep, down_sweep_adjoint,
           write_state, read_state, write_inputs, read_links, read_links_acc, read_mass_matrix,
           read_dofs_dynamics,
           read_com_jacobians, read_contacts, read_links_contact_force, smooth_substep, finish_substep)
