"""Grid to particle (g2p): each particle gathers velocity and its APIC affine field from the 27
nodes around it, moves, and is kept inside the walls; and its adjoint.

Forward, per particle (v_i the updated node velocities, w_i the stencil weights at fx):
    v' = Σ w_i v_i,  C' = 4 inv_dx Σ w_i v_i ⊗ (offset_i − fx),  x' = clamp(x + h v'),
    and the velocity component moving out through a wall it has reached is zeroed.
The walls are piecewise: the adjoint differentiates the branch taken (read off v' as the replay
kept it). The gather's reverse is one pass, run serially per env and half of the particles
(deterministic, no atomics): it scatters into the nodes' velocity gradients and, in the same
stencil loop, sums each node's u_i · v_i ∂w_i/∂fx for the position's gradient through the
weights; C''s (offset − fx) term is taken once per particle (Σ w_i v_i = v').
"""
import taichi as ti

from .layout import WIDTH
from .stencil import (axis_offsets, cell_of, column_terms, matrix_row, node_at, node_count, node_vector, row_at,
                      row_matrix, row_vector, scatter_half, scatter_spread, stencil_row, store_matrix, store_vector,
                      transposed_times, weight_grads, weights)


@ti.func
def gather_velocity(grid: ti.template(), e, base, fx, inv_dx, grid_i: ti.template()):
    """(v' (3,) m/s, C' (3×3) 1/s) gathered from env e's updated grid (flat, node_count) around a
    particle. The weights and offsets factor per axis (w = W[i, 0] W[j, 1] W[k, 2], offset − fx =
    (O[i, 0], O[j, 1], O[k, 2])), so the sums run axis by axis, innermost z: per node two 3-vector
    multiply-adds where a weight and an outer product per node took five."""
    W, O, K = weights(fx), axis_offsets(fx), node_count(grid_i)
    vel = ti.Vector.zero(float, 3)
    C_x, C_y, C_z = ti.Vector.zero(float, 3), ti.Vector.zero(float, 3), ti.Vector.zero(float, 3)
    for i in range(3):
        # Σ over j, k of W[j, 1] W[k, 2] v, and of that times O[j, 1], and times O[k, 2]
        plane, plane_y, plane_z = ti.Vector.zero(float, 3), ti.Vector.zero(float, 3), ti.Vector.zero(float, 3)
        for j in range(3):
            line_at = node_at(e, stencil_row(grid_i, base, i, j), K)
            line, line_z = ti.Vector.zero(float, 3), ti.Vector.zero(float, 3)
            for k in range(3):
                v = node_vector(grid, line_at + 4 * k)
                line += W[k, 2] * v
                line_z += (W[k, 2] * O[k, 2]) * v
            plane += W[j, 1] * line
            plane_y += (W[j, 1] * O[j, 1]) * line
            plane_z += W[j, 1] * line_z
        vel += W[i, 0] * plane
        C_x += (W[i, 0] * O[i, 0]) * plane
        C_y += W[i, 0] * plane_y
        C_z += W[i, 0] * plane_z
    return vel, (4.0 * inv_dx) * ti.Matrix.cols([C_x, C_y, C_z])


@ti.func
def gather_stage(frames: ti.template(), params: ti.template(), grid: ti.template(), grid_f: ti.template(),
                 grid_i: ti.template(), flags: ti.template(), gathered: ti.template(), src, dst, keep):
    """g2p: new velocity, affine field C and position; particles kept inside the walls. When
    keep ≥ 0 (a replay), the gathered velocity (before the walls) → gathered's slot ``keep``; a
    non-finite position raises flags[0] in a plain step only (a replay's repeats its forward's,
    reported then: raised again, the next rollout's first step reported it)."""
    h, inv_dx = grid_f[0], grid_f[1]
    B, N = params.shape[0], params.shape[1]
    for e, p in ti.ndrange(B, N):
        pos = row_vector(frames, row_at(src, e, p, B, N, WIDTH))
        base, fx = cell_of(pos, inv_dx, grid_i)
        vel, C = gather_velocity(grid, e, base, fx, inv_dx, grid_i)
        moved = pos + h * vel
        for c in ti.static(range(3)):
            if keep < 0 and not (ti.abs(moved[c]) < ti.math.inf):  # NaN or ±inf
                flags[0] = 1
        pos_new, vel_new = wall_particle(moved, vel, grid_f)
        if keep >= 0:
            store_vector(gathered, row_at(keep, e, p, B, N, 3), vel)
        dst_at = row_at(dst, e, p, B, N, WIDTH)
        store_vector(frames, dst_at, pos_new)
        store_vector(frames, dst_at + 3, vel_new)
        store_matrix(frames, dst_at + 6, C)


@ti.func
def wall_particle(pos, vel, grid_f: ti.template()):
    """(pos, vel) of a particle after the walls: clamped inside them, with the velocity
    component moving out through a wall it has reached zeroed (Genesis's impose_pos_vel)."""
    v = vel
    for c in ti.static(range(3)):
        if wall_blocks(pos, vel, grid_f, c):
            v[c] = 0.0
    lower = ti.Vector([grid_f[3], grid_f[4], grid_f[5]])
    upper = ti.Vector([grid_f[6], grid_f[7], grid_f[8]])
    return ti.max(ti.min(pos, upper), lower), v


@ti.func
def wall_blocks(pos, vel, grid_f: ti.template(), c: ti.template()):
    """Whether component c of vel (3,) moves out through a wall that pos (3,) has reached."""
    return (pos[c] >= grid_f[6 + c] and vel[c] >= 0.0) or (pos[c] <= grid_f[3 + c] and vel[c] <= 0.0)


@ti.func
def node_gradient_rows(g_C, O, inv_dx):
    """Node i's velocity v_i enters v' and C' as w_i u_i · v_i, u_i = ∂L/∂v' + 4 inv_dx ∂L/∂C'
    (offset_i − fx): (U_x, U_y, U_z), 3×3 each, with u at node (i, j, k) = ∂L/∂v' + row i of U_x
    + row j of U_y + row k of U_z (summed in that order), from ∂L/∂C' (3×3) and the nodes'
    offsets per axis O = axis_offsets(fx) (cells)."""
    scaled = (4.0 * inv_dx) * g_C
    return column_terms(scaled, O, 0), column_terms(scaled, O, 1), column_terms(scaled, O, 2)


@ti.func
def gather_adjoint_stage(serial: ti.template(), frames: ti.template(), params: ti.template(), grid: ti.template(),
                         gathered: ti.template(), grads: ti.template(), scratch: ti.template(),
                         grad_grid: ti.template(), part_grid: ti.template(), active: ti.template(),
                         grid_f: ti.template(), grid_i: ti.template(), src):
    """Reverse of g2p, from the gradient of frame dst's pos, vel, C (grads' rows), the gathered
    velocity the replay kept (gathered's slot src) and the restored updated grid: each node's
    velocity gradient (grad_grid 0:3, zero before) += w_i u_i (node_gradient_rows); per particle,
    scratch 0:3 ← ∂L/∂v' (the gathered velocity), scratch 3:6 ← ∂L/∂x through the move and the
    stencil weights of the gather. Deterministic, on two threads (stencil.scatter_spread): the first
    half of each env's particles scatter into grad_grid, the second into part_grid (0:3), which is
    then added over the listed nodes (active) and zeroed."""
    B, N = params.shape[0], params.shape[1]
    for t in range(2 * B * scatter_spread(B)):
        working, e, second, first, end = scatter_half(t, B, N)
        if working and second == 0:
            gather_adjoint_range(frames, grid, gathered, grads, scratch, grad_grid, grid_f, grid_i, src, e, first, end,
                                 B, N)
        elif working:
            gather_adjoint_range(frames, grid, gathered, grads, scratch, part_grid, grid_f, grid_i, src, e, first, end,
                                 B, N)
    K = node_count(grid_i)
    ti.loop_config(serialize=serial)  # only adds: for a few envs a thread-pool task costs more (grid.py)
    for e, k in ti.ndrange(B, active[B, 0]):
        if k < active[e, 0]:
            at = node_at(e, active[e, k + 1], K)
            for c in ti.static(range(3)):
                grad_grid[at + c] = grad_grid[at + c] + part_grid[at + c]
                part_grid[at + c] = 0.0


@ti.func
def gather_adjoint_range(frames: ti.template(), grid: ti.template(), gathered: ti.template(), grads: ti.template(),
                         scratch: ti.template(), grad_grid: ti.template(), grid_f: ti.template(),
                         grid_i: ti.template(), src, e, first, end, B, N):
    """g2p's reverse for env e's particles first..end − 1 (of B envs of N particles), serially in
    particle order: their nodes' velocity gradients (grad_grid 0:3) += w_i u_i, and their rows of
    scratch."""
    h, inv_dx, K = grid_f[0], grid_f[1], node_count(grid_i)
    for p in range(first, end):
        pos = row_vector(frames, row_at(src, e, p, B, N, WIDTH))
        base, fx = cell_of(pos, inv_dx, grid_i)
        vel = row_vector(gathered, row_at(src, e, p, B, N, 3))
        moved = pos + h * vel
        grad_at = row_at(0, e, p, B, N, WIDTH)
        g_pos_new, g_vel_new = row_vector(grads, grad_at), row_vector(grads, grad_at + 3)
        g_C = row_matrix(grads, grad_at + 6)
        g_moved = ti.Vector.zero(float, 3)
        g_vel = ti.Vector.zero(float, 3)
        for c in ti.static(range(3)):
            if grid_f[3 + c] <= moved[c] and moved[c] <= grid_f[6 + c]:  # not clamped
                g_moved[c] = g_pos_new[c]
            if not wall_blocks(moved, vel, grid_f, c):
                g_vel[c] = g_vel_new[c]
        g_vel += h * g_moved
        # C''s own (offset − fx) gives −4 inv_dx ∂L/∂C'ᵀ Σ w_i v_i = −4 inv_dx ∂L/∂C'ᵀ v' (v' as the
        # replay kept it), once per particle; the weights give Σ (u_i · v_i) ∂w_i/∂fx
        g_fx = -(4.0 * inv_dx) * transposed_times(g_C, vel)
        W, dW, O = weights(fx), weight_grads(fx), axis_offsets(fx)
        U_x, U_y, U_z = node_gradient_rows(g_C, O, inv_dx)
        for i in range(3):
            for j in range(3):
                line_at = node_at(e, stencil_row(grid_i, base, i, j), K)
                w_ij, dw_x, dw_y = W[i, 0] * W[j, 1], dW[i, 0] * W[j, 1], W[i, 0] * dW[j, 1]
                u_ij = g_vel + matrix_row(U_x, i) + matrix_row(U_y, j)
                for k in range(3):
                    at = line_at + 4 * k
                    dw = ti.Vector([dw_x * W[k, 2], dw_y * W[k, 2], w_ij * dW[k, 2]])
                    v = node_vector(grid, at)
                    u = u_ij + matrix_row(U_z, k)
                    g_fx += v.dot(u) * dw
                    g_v = (w_ij * W[k, 2]) * u
                    for c in ti.static(range(3)):
                        grad_grid[at + c] = grad_grid[at + c] + g_v[c]
        scratch_at = row_at(0, e, p, B, N, 6)
        store_vector(scratch, scratch_at, g_vel)
        store_vector(scratch, scratch_at + 3, g_moved + inv_dx * g_fx)
