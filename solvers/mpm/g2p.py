"""Grid to particle (g2p): each particle gathers velocity and its APIC affine field from the 27
nodes around it, moves, and is kept inside the walls; and its adjoint.

Forward, per particle (v_i the updated node velocities, w_i the stencil weights at fx):
    v' = Σ w_i v_i,  C' = 4 inv_dx Σ w_i v_i ⊗ (offset_i − fx),  x' = clamp(x + h v'),
    and the velocity component moving out through a wall it has reached is zeroed.
The walls are piecewise: the adjoint differentiates the branch taken. The gather's reverse is a
scatter into the nodes' velocity gradients, run serially per env (deterministic, no atomics).
"""
import taichi as ti

from .stencil import (cell_of, row_matrix, row_vector, stencil_node, stencil_weight_grad, store_matrix, store_vector,
                      weight_grads, weights)


@ti.func
def gather_velocity(grid: ti.template(), e, base, fx, inv_dx, grid_i: ti.template()):
    """(v' (3,) m/s, C' (3×3) 1/s) gathered from env e's updated grid around a particle."""
    vel = ti.Vector.zero(float, 3)
    C = ti.Matrix.zero(float, 3, 3)
    W = weights(fx)
    for i in range(3):
        for j in range(3):
            for k in range(3):
                n, offset, w = stencil_node(grid_i, base, W, i, j, k)
                v = ti.Vector([grid[e, n, 0], grid[e, n, 1], grid[e, n, 2]])
                vel += w * v
                C += (4.0 * inv_dx * w) * v.outer_product(offset - fx)
    return vel, C


@ti.func
def gather_stage(frames: ti.template(), grid: ti.template(), grid_f: ti.template(), grid_i: ti.template(),
                 flags: ti.template(), src, dst):
    """g2p: new velocity, affine field C and position; particles kept inside the walls."""
    h, inv_dx = grid_f[0], grid_f[1]
    for e, p in ti.ndrange(frames.shape[1], frames.shape[2]):
        pos = row_vector(frames, src, e, p, 0)
        base, fx = cell_of(pos, inv_dx, grid_i)
        vel, C = gather_velocity(grid, e, base, fx, inv_dx, grid_i)
        moved = pos + h * vel
        for c in ti.static(range(3)):
            if not (ti.abs(moved[c]) < ti.math.inf):  # NaN or ±inf
                flags[0] = 1
        pos_new, vel_new = wall_particle(moved, vel, grid_f)
        store_vector(frames, dst, e, p, 0, pos_new)
        store_vector(frames, dst, e, p, 3, vel_new)
        store_matrix(frames, dst, e, p, 6, C)


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
def gather_adjoint_stage(frames: ti.template(), grid: ti.template(), grads: ti.template(), scratch: ti.template(),
                         grid_f: ti.template(), grid_i: ti.template(), src):
    """Reverse of g2p, per particle (parallel), from the gradient of frame dst's pos, vel, C
    (grads' rows) and the rebuilt updated grid: scratch 0:3 ← ∂L/∂v' (the gathered velocity),
    scratch 3:6 ← ∂L/∂x through the move and the stencil weights of the gather."""
    h, inv_dx = grid_f[0], grid_f[1]
    for e, p in ti.ndrange(frames.shape[1], frames.shape[2]):
        pos = row_vector(frames, src, e, p, 0)
        base, fx = cell_of(pos, inv_dx, grid_i)
        vel, _ = gather_velocity(grid, e, base, fx, inv_dx, grid_i)
        moved = pos + h * vel
        g_pos_new, g_vel_new = row_vector(grads, 0, e, p, 0), row_vector(grads, 0, e, p, 3)
        g_C = row_matrix(grads, 0, e, p, 6)
        g_moved = ti.Vector.zero(float, 3)
        g_vel = ti.Vector.zero(float, 3)
        for c in ti.static(range(3)):
            if grid_f[3 + c] <= moved[c] and moved[c] <= grid_f[6 + c]:  # not clamped
                g_moved[c] = g_pos_new[c]
            if not wall_blocks(moved, vel, grid_f, c):
                g_vel[c] = g_vel_new[c]
        g_vel += h * g_moved
        g_fx = ti.Vector.zero(float, 3)
        W, dW = weights(fx), weight_grads(fx)
        for i in range(3):
            for j in range(3):
                for k in range(3):
                    n, offset, w = stencil_node(grid_i, base, W, i, j, k)
                    dw = stencil_weight_grad(W, dW, i, j, k)
                    v = ti.Vector([grid[e, n, 0], grid[e, n, 1], grid[e, n, 2]])
                    g_C_v = g_C.transpose() @ v
                    g_fx += (g_vel.dot(v) + 4.0 * inv_dx * g_C_v.dot(offset - fx)) * dw - (4.0 * inv_dx * w) * g_C_v
        g_pos = g_moved + inv_dx * g_fx
        for c in ti.static(range(3)):
            scratch[e, p, c] = g_vel[c]
            scratch[e, p, 3 + c] = g_pos[c]


@ti.func
def gather_adjoint_scatter(frames: ti.template(), grads: ti.template(), scratch: ti.template(),
                           grad_grid: ti.template(), grid_f: ti.template(), grid_i: ti.template(), src):
    """Reverse of g2p into the grid, serial per env (particle order: deterministic): each node's
    velocity gradient (grad_grid 0:3, zero before) += w (∂L/∂v' + 4 inv_dx ∂L/∂C' (offset − fx))."""
    inv_dx = grid_f[1]
    for e in range(frames.shape[1]):
        for p in range(frames.shape[2]):
            base, fx = cell_of(row_vector(frames, src, e, p, 0), inv_dx, grid_i)
            g_vel = ti.Vector([scratch[e, p, 0], scratch[e, p, 1], scratch[e, p, 2]])
            g_C = row_matrix(grads, 0, e, p, 6)
            W = weights(fx)
            for i in range(3):
                for j in range(3):
                    for k in range(3):
                        n, offset, w = stencil_node(grid_i, base, W, i, j, k)
                        g_v = w * (g_vel + (4.0 * inv_dx) * (g_C @ (offset - fx)))
                        for c in ti.static(range(3)):
                            grad_grid[e, n, c] = grad_grid[e, n, c] + g_v[c]
