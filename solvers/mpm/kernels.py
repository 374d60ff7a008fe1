"""The MPM kernels: one MLS-MPM substep — p2g (p2g.py) → grid update (grid.py) → g2p (g2p.py) —
and its reverse.

Every array is a kernel argument (a torch tensor), so each kernel is compiled once per precision
and serves every scene (solvers/launch.py). The arrays, per scene (B envs, N particles, K grid
nodes, S substeps, cap the saved grid's capacity); those marked "flat" are passed as 1-d views
and indexed through stencil.row_at (per-particle rows) or stencil.node_at (grid nodes), which
costs far less than indexing a 3- or 4-d ndarray (B and N are read off ``params``' shape):

- ``frames`` (S + 1 or 2, B, N, 25, flat): particle state rows (layout.STATE), one frame per
  substep boundary (all of them when the step will be differentiated, else two used in turn);
- ``params`` (B, N, 4): E (Pa), nu, rho (kg/m³), actu per particle; ``env_in`` (B, 3 + 3R) per env:
  gravity (3) m/s², then each rigid entity's coupling μ, ς (m), e (layout.ENV_INPUTS);
- ``kinds`` (N,) int material code, ``consts`` (N, layout.N_CONSTS), ``fiber`` (N, 3) muscle fibre
  directions (as given): the model;
- ``affine`` (S or 1, B, N, 9, flat): each particle's APIC affine momentum matrix, N·s/m²·m, of
  the substep in progress (slot 0), or in a replay of substep s (slot s, kept for the reverse);
- ``svd`` (S, B, N, 21, flat): a replay's SVD of each particle's F_tmp, U (9, row-major), σ (3),
  V (9), per substep, for the materials that take one (constitutive.needs_svd; a 1-sized dummy
  when the solver does not differentiate or no material takes one);
- ``grid`` (B, K, 4), passed flat (stencil.node_count): per node momentum (3, kg·m/s) and mass
  (kg), after the update velocity (m/s) and mass; zero between substeps;
- ``active`` (B + 1, K + 1) int: per env the number of nodes the particles reach, then their
  indices (the grid update and the clearing touch only those); row B holds the largest count;
- ``part_grid`` (B, K, 4, flat), ``part_nodes`` (B + 1, K + 1) int: the second half of the
  particles' scatter (p2g's, then in the reverse g2p's) and its node list, added into grid
  (grad_grid) at once and zeroed (stencil.scatter_spread);
- ``grid_f`` (9 + 18 C + D,): h (s), inv_dx (1/m), vol (m³), walls' lower (3) and upper (3) corners
  (m), then C rigid colliders' rows and their hulls' and height fields' data (colliders.py);
- ``grid_i`` (8,): the grid's lowest node in cells (3), nodes per axis (3), sticky walls (0/1), C;
- ``flags`` (1,) int: set to 1 when a particle's new state is not finite;
- what a replay keeps for the reverse, per substep s (1-sized dummies when the solver does not
  differentiate): ``gathered`` (S, B, N, 3, flat) each particle's gathered velocity (m/s, before the
  walls); ``saved_grid`` (S, B, cap, 4, 7 or 10) the updated grid's listed nodes, (v (3) m/s, M kg,
  with colliders the velocity before them (3), with a coupler the velocity before it (3)) in list
  order; ``saved_nodes`` (S, B + 1, cap + 1) int
  their lists, laid out as ``active`` (the counts are whole even where they exceed cap: the solver
  then grows cap and replays again).

The forward kernels take, after the arrays, src and dst (frames) and keep: −1 in a plain step, s
in a replay of substep s (which then keeps what the reverse reads; a plain step pays nothing).
Every kernel's compile-time argument is a scene's ``config`` = (takes_svd, serial, colliders,
moving): whether any of its materials takes an SVD (p2g.stress_stage: pairs of particles with
interleaved SVDs, or one particle at a time with none; only the kernels that run the stress,
STRESS_KERNELS, are bound with it, the others with False), whether the grid's chores (adding,
copying, zeroing listed nodes) run on the calling thread (grid.py; solver.SERIAL_CHORE_ENVS),
whether the grid meets rigid colliders at rest (colliders.py; a scene without them compiles none
of their code), and whether it meets shapes of moving links (solvers/coupler.py, between
pre_coupling, which then ends with the grid update up to the walls, and post_coupling, which
then starts with the walls).

The reverse kernels (REVERSE_KERNELS) take src and coupling_grads (whether the rigid couplings'
gradients are wanted: the colliders' pass is skipped otherwise) and five more arrays:
- ``grads`` (1, B, N, 25, flat): the gradient of the loss w.r.t. a frame's particle rows — of
  frame s + 1 before substep s's reverse, of frame s after it (overwritten in place, row by row);
- ``grad_params`` (B, N, 4): ∂L/∂(E, nu, rho, actu) per particle, summed over the substeps;
- ``grad_env`` (B, 3 + 3R): ∂L/∂env_in (gravity, the couplings), summed over the substeps;
- ``grad_grid`` (B, K, 4, flat): per node ∂L/∂v (3) of the updated velocity, then ∂L/∂P (3),
  ∂L/∂M; zero between substeps;
- ``scratch`` (B, N, 6, flat): per particle ∂L/∂v' of the gathered velocity (3), and ∂L/∂x
  through g2p (3).

The reverse of substep s (frames s, s + 1 filled by a replay of the step) restores the substep's
updated grid as the replay kept it — after the update, so what a coupler does to the grid
between pre and post coupling is in it, where rebuilding the grid from frame s would miss it —
and runs the adjoints in mirror order: g2p (per particle, with the replay's gathered velocity,
then its scatter into grad_grid serially per env), the grid update (the colliders' coupling
parameters serially per env, then per node, then gravity serially per env), p2g and the stress
(per particle, with the replay's affine matrices and SVDs: the reverse runs no SVD). It takes two launches, post_coupling_backward and
pre_coupling_backward, as the shared loop interleaves a coupler's reverse between them; the
stress adjoint (the costliest to compile) is in the second only.

Scatter order decides round-off: the scatters run serially per env and half of the particles (as
MPM_NOTES measured, faster than atomics on CPU; the two halves on two threads), so results are
deterministic and a batched env equals a single-env scene.
"""
import taichi as ti

from .g2p import gather_adjoint_stage, gather_stage
from .grid import (clear_adjoint_stage, clear_stage, grid_stage, largest_count, merge_stage, restore_stage,
                   update_adjoint_stage, walls_adjoint_stage, walls_stage)
from .layout import WIDTH
from .p2g import p2g_adjoint_stage, scatter_stage, stress_stage
from .stencil import row_at

A = ti.types.ndarray()


@ti.kernel
def substep(config: ti.template(), frames: A, params: A, env_in: A, kinds: A, consts: A, fiber: A, affine: A, svd: A,
            grid: A, active: A, part_grid: A, part_nodes: A, grid_f: A, grid_i: A, flags: A, gathered: A,
            saved_grid: A, saved_nodes: A, src: ti.i32, dst: ti.i32, keep: ti.i32):
    """A whole substep from frame src to frame dst, in one launch (no coupling)."""
    stress_stage(config[0], frames, params, kinds, consts, fiber, affine, svd, grid_f, src, dst, keep)
    scatter_stage(frames, params, affine, grid, active, part_grid, part_nodes, grid_f, grid_i, src, ti.max(keep, 0))
    merge_stage(config[1], grid, active, part_grid, part_nodes, grid_i)
    largest_count(active)
    grid_stage(config[2], True, grid, active, env_in, grid_f, grid_i, saved_grid, saved_nodes, keep)
    gather_stage(frames, params, grid, grid_f, grid_i, flags, gathered, src, dst, keep)
    clear_stage(config[1], grid, active, grid_i)


@ti.kernel
def pre_coupling(config: ti.template(), frames: A, params: A, env_in: A, kinds: A, consts: A, fiber: A,
                 affine: A, svd: A, grid: A, active: A, part_grid: A, part_nodes: A,
                 grid_f: A, grid_i: A, flags: A, gathered: A, saved_grid: A, saved_nodes: A,
                 src: ti.i32, dst: ti.i32, keep: ti.i32):
    """The substep up to where the coupler acts: stress and p2g (the grid holds momentum and mass),
    and, where shapes of moving links meet the grid (config[3]), the grid update up to the walls
    (the grid holds velocity and mass)."""
    stress_stage(config[0], frames, params, kinds, consts, fiber, affine, svd, grid_f, src, dst, keep)
    scatter_stage(frames, params, affine, grid, active, part_grid, part_nodes, grid_f, grid_i, src, ti.max(keep, 0))
    merge_stage(config[1], grid, active, part_grid, part_nodes, grid_i)
    largest_count(active)
    if ti.static(config[3]):
        grid_stage(config[2], False, grid, active, env_in, grid_f, grid_i, saved_grid, saved_nodes, keep)


@ti.kernel
def post_coupling(config: ti.template(), frames: A, params: A, env_in: A, kinds: A, consts: A, fiber: A,
                  affine: A, svd: A, grid: A, active: A, part_grid: A, part_nodes: A,
                  grid_f: A, grid_i: A, flags: A, gathered: A, saved_grid: A, saved_nodes: A,
                  src: ti.i32, dst: ti.i32, keep: ti.i32):
    """The rest of the substep: grid update (or, after the coupler's moving shapes, its walls), g2p,
    grid cleared."""
    if ti.static(config[3]):
        walls_stage(grid, active, grid_f, grid_i, saved_grid, keep)
    else:
        grid_stage(config[2], True, grid, active, env_in, grid_f, grid_i, saved_grid, saved_nodes, keep)
    gather_stage(frames, params, grid, grid_f, grid_i, flags, gathered, src, dst, keep)
    clear_stage(config[1], grid, active, grid_i)


@ti.kernel
def write_state(config: ti.template(), frames: A, params: A, env_in: A, kinds: A, consts: A, fiber: A,
                affine: A, svd: A, grid: A, active: A, part_grid: A, part_nodes: A,
                grid_f: A, grid_i: A, flags: A, gathered: A, saved_grid: A, saved_nodes: A,
                f: ti.i32, src: A):
    """Frame f ← src (B, N · 25)."""
    B, N = params.shape[0], params.shape[1]
    for e, p in ti.ndrange(B, N):
        at = row_at(f, e, p, B, N, WIDTH)
        for k in range(WIDTH):
            frames[at + k] = src[e, p * WIDTH + k]


@ti.kernel
def read_state(config: ti.template(), frames: A, params: A, env_in: A, kinds: A, consts: A, fiber: A,
               affine: A, svd: A, grid: A, active: A, part_grid: A, part_nodes: A,
               grid_f: A, grid_i: A, flags: A, gathered: A, saved_grid: A, saved_nodes: A,
               f: ti.i32, dst: A):
    """dst (B, N · 25) ← frame f."""
    B, N = params.shape[0], params.shape[1]
    for e, p in ti.ndrange(B, N):
        at = row_at(f, e, p, B, N, WIDTH)
        for k in range(WIDTH):
            dst[e, p * WIDTH + k] = frames[at + k]


KERNELS = (post_coupling, write_state, read_state)
STRESS_KERNELS = (substep, pre_coupling)  # bound with the scene's takes_svd (the others with False)


@ti.kernel
def post_coupling_backward(config: ti.template(), frames: A, params: A, env_in: A, kinds: A, consts: A, fiber: A,
                           affine: A, svd: A, grid: A, active: A, part_grid: A, part_nodes: A,
                           grid_f: A, grid_i: A, flags: A, gathered: A,
                           saved_grid: A, saved_nodes: A, grads: A, grad_params: A, grad_env: A, grad_grid: A,
                           scratch: A, src: ti.i32, coupling_grads: ti.i32):
    """Substep src's updated grid restored (as the replay kept it), then the reverse of
    post_coupling (g2p and the grid update): grad_grid ← (∂L/∂P, ∂L/∂M), grad_env += its part.
    With a coupler (config[3]) the reverse stops at the walls: grad_grid ← ∂L/∂v after the coupler,
    the grid's velocity the one before it (the coupler's reverse, then pre_coupling_backward's)."""
    restore_stage(config[1], grid, active, saved_grid, saved_nodes, grid_i, src)
    gather_adjoint_stage(config[1], frames, params, grid, gathered, grads, scratch, grad_grid, part_grid, active,
                         grid_f, grid_i, src)
    if ti.static(config[3]):
        walls_adjoint_stage(grid, grad_grid, active, grid_f, grid_i, saved_grid, src)
    else:
        update_adjoint_stage(config[1], config[2], True, grid, grad_grid, active, env_in, grad_env, grid_f, grid_i,
                             saved_grid, src, coupling_grads)


@ti.kernel
def pre_coupling_backward(config: ti.template(), frames: A, params: A, env_in: A, kinds: A, consts: A, fiber: A,
                          affine: A, svd: A, grid: A, active: A, part_grid: A, part_nodes: A,
                          grid_f: A, grid_i: A, flags: A, gathered: A,
                          saved_grid: A, saved_nodes: A, grads: A, grad_params: A, grad_env: A, grad_grid: A,
                          scratch: A, src: ti.i32, coupling_grads: ti.i32):
    """The reverse of pre_coupling (p2g and the stress): grads ← the gradient of frame src,
    grad_params += their part; the touched nodes cleared. With a coupler (config[3]) the grid
    update's reverse up to the walls comes first (the coupler's reverse came between)."""
    if ti.static(config[3]):
        update_adjoint_stage(config[1], config[2], False, grid, grad_grid, active, env_in, grad_env, grid_f, grid_i,
                             saved_grid, src, coupling_grads)
    p2g_adjoint_stage(frames, params, kinds, consts, fiber, affine, svd, grads, grad_params, grad_grid, scratch,
                      grid_f, grid_i, src)
    clear_adjoint_stage(config[1], grid, grad_grid, active, grid_i)


REVERSE_KERNELS = (post_coupling_backward, pre_coupling_backward)
