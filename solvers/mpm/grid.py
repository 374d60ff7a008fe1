"""The grid update: nodal momentum to velocity, gravity, the rigid colliders and the domain
walls (Genesis's grid op); then the touched nodes are cleared for the next substep; and the
update's adjoint.

Forward, per listed node i: v_i = mask_i ⊙ collide(P_i / M_i + h g), collide the rigid shapes at
rest (colliders.py; none: the identity), mask_i zeroing the components a wall stops. The adjoint
reads the mask off the updated grid (see ``wall_mask``), so the grid a replay keeps (its listed
nodes' (v, M), with colliders also the velocity they were given, ``saved_grid``, and the list,
``saved_nodes``) is all the reverse needs: ``restore_stage`` puts it back.

The loops that only move, add or zero the listed nodes' values (``serial``, a compile-time
argument: in a single-env scene on the CPU, solver.SERIAL_CHORE_ENVS) and those over the envs'
counts run serially on the calling thread: a parallel loop is a task of Taichi's thread pool,
which wakes its sleeping workers and then waits to be woken itself, ~10 µs at best and ~60 µs
typically on these 2-core machines (8 empty parallel loops: 70–160 µs best, 420–520 µs median a launch;
serial: 15–30 µs), more than zeroing or copying one env's few thousand nodes. A 10k-particle
substep's small tasks went from 0.15 to 0.05 ms (medians; kernel profiler). The update itself
(a division per node) stays parallel; on a GPU every loop does (one GPU thread would do it all).
"""
import taichi as ti

from .colliders import collide, collide_adjoint
from .stencil import node_count, node_at, node_vector


@ti.func
def merge_stage(serial: ti.template(), grid: ti.template(), active: ti.template(), part_grid: ti.template(),
                part_nodes: ti.template(), grid_i: ti.template()):
    """The second half's scatter (part_grid, its nodes in part_nodes) added into the grid, serially
    per env in part_nodes' order; its nodes the first half did not reach are listed in active; the
    part_grid nodes are zeroed for the next substep."""
    K = node_count(grid_i)
    ti.loop_config(serialize=serial)
    for e in range(active.shape[0] - 1):
        count = active[e, 0]
        for k in range(part_nodes[e, 0]):
            n = part_nodes[e, k + 1]
            at = node_at(e, n, K)
            if grid[at + 3] == 0.0:
                count += 1
                active[e, count] = n
            for c in ti.static(range(4)):
                grid[at + c] = grid[at + c] + part_grid[at + c]
                part_grid[at + c] = 0.0
        active[e, 0] = count


@ti.func
def largest_count(active: ti.template()):
    """Row B, column 0 of ``active`` ← the largest env's node count (the grid loops' bound)."""
    ti.loop_config(serialize=True)
    for once in range(1):
        B = active.shape[0] - 1
        most = 0
        for e in range(B):
            most = ti.max(most, active[e, 0])
        active[B, 0] = most


@ti.func
def grid_stage(colliders: ti.template(), walls: ti.template(), grid: ti.template(), active: ti.template(),
               env_in: ti.template(), grid_f: ti.template(), grid_i: ti.template(), saved_grid: ti.template(),
               saved_nodes: ti.template(), keep):
    """Momentum → velocity, gravity, the rigid colliders at rest (colliders.py; compiled in when
    ``colliders``), then the walls (Genesis's grid op, restitution 0) unless ``walls`` is False (the
    shapes of moving links come first: solvers/coupler.py, then walls_stage). When keep ≥ 0 (a
    replay), the updated grid is also kept for the reverse: its listed nodes' (v, M), and with
    colliders the velocity before them (3), and the lists into slot ``keep`` of saved_grid /
    saved_nodes, as far as their capacity goes (the counts are kept whole: the solver grows the
    capacity and replays again when one exceeds it)."""
    h, dx, K = grid_f[0], 1.0 / grid_f[1], node_count(grid_i)
    B = active.shape[0] - 1
    for e, k in ti.ndrange(B, active[B, 0]):
        if k < active[e, 0]:
            n = active[e, k + 1]
            at = node_at(e, n, K)
            free = node_vector(grid, at) / grid[at + 3] + h * ti.Vector([env_in[e, 0], env_in[e, 1], env_in[e, 2]])
            pos = node_position(n, dx, grid_i)
            v = free
            if ti.static(colliders):
                v = collide(grid_f, grid_i[7], pos, free, env_in, e)
            if ti.static(walls):
                v = wall_velocity(pos, v, grid_f, grid_i[6])
            for c in ti.static(range(3)):
                grid[at + c] = v[c]
            if keep >= 0 and k < saved_grid.shape[2]:
                saved_nodes[keep, e, k + 1] = n
                for c in ti.static(range(3)):  # (without the walls: the coupler's input; walls_stage keeps 0:4)
                    saved_grid[keep, e, k, c if ti.static(walls) else 7 + c] = v[c]
                saved_grid[keep, e, k, 3] = grid[at + 3]
                if ti.static(colliders):  # their input, for their adjoint
                    for c in ti.static(range(3)):
                        saved_grid[keep, e, k, 4 + c] = free[c]
    if keep >= 0:
        for e in range(B + 1):
            saved_nodes[keep, e, 0] = active[e, 0]


@ti.func
def walls_stage(grid: ti.template(), active: ti.template(), grid_f: ti.template(), grid_i: ti.template(),
                saved_grid: ti.template(), keep):
    """The walls on the updated grid's listed nodes (grid_stage's last part, where the shapes of
    moving links come between); a replay (keep ≥ 0) keeps the result as grid_stage does (0:4 of
    saved_grid: v, M), the velocity before the coupler being in 7:10."""
    dx, K = 1.0 / grid_f[1], node_count(grid_i)
    B = active.shape[0] - 1
    for e, k in ti.ndrange(B, active[B, 0]):
        if k < active[e, 0]:
            n = active[e, k + 1]
            at = node_at(e, n, K)
            v = wall_velocity(node_position(n, dx, grid_i), node_vector(grid, at), grid_f, grid_i[6])
            for c in ti.static(range(3)):
                grid[at + c] = v[c]
            if keep >= 0 and k < saved_grid.shape[2]:
                for c in ti.static(range(3)):
                    saved_grid[keep, e, k, c] = v[c]
                saved_grid[keep, e, k, 3] = grid[at + 3]


@ti.func
def walls_adjoint_stage(grid: ti.template(), grad_grid: ti.template(), active: ti.template(), grid_f: ti.template(),
                        grid_i: ti.template(), saved_grid: ti.template(), s):
    """Reverse of walls_stage, per listed node of substep s's restored grid: grad_grid's velocity
    gradient (0:3) through the walls' mask; then the grid's velocity ← the one before the coupler
    (saved_grid 7:10), what the coupler's reverse and grid_adjoint_stage read."""
    dx, K = 1.0 / grid_f[1], node_count(grid_i)
    B = active.shape[0] - 1
    for e, k in ti.ndrange(B, active[B, 0]):
        if k < active[e, 0]:
            n = active[e, k + 1]
            at = node_at(e, n, K)
            mask = wall_mask(node_position(n, dx, grid_i), node_vector(grid, at), grid_f, grid_i[6])
            for c in ti.static(range(3)):
                grad_grid[at + c] = mask[c] * grad_grid[at + c]
                grid[at + c] = saved_grid[s, e, k, 7 + c]


@ti.func
def restore_stage(serial: ti.template(), grid: ti.template(), active: ti.template(), saved_grid: ti.template(),
                  saved_nodes: ti.template(), grid_i: ti.template(), s):
    """The updated grid of substep s and its node lists (``active``), as the replay kept them
    (grid_stage), back in place of the zeros between substeps."""
    B, K = active.shape[0] - 1, node_count(grid_i)
    ti.loop_config(serialize=serial)
    for e, k in ti.ndrange(B, saved_nodes[s, B, 0]):
        if k < saved_nodes[s, e, 0]:
            n = saved_nodes[s, e, k + 1]
            active[e, k + 1] = n
            at = node_at(e, n, K)
            for c in ti.static(range(4)):
                grid[at + c] = saved_grid[s, e, k, c]
    ti.loop_config(serialize=True)
    for e in range(B + 1):
        active[e, 0] = saved_nodes[s, e, 0]


@ti.func
def node_position(n, dx, grid_i: ti.template()):
    """Position (3,) m of flat node n."""
    node = ti.Vector([n // (grid_i[4] * grid_i[5]), n // grid_i[5] % grid_i[4], n % grid_i[5]])
    return (node + ti.Vector([grid_i[0], grid_i[1], grid_i[2]])) * dx


@ti.func
def wall_velocity(pos, v, grid_f: ti.template(), sticky):
    """Velocity (3,) m/s at pos (3,) m after the walls: a component moving out through a wall
    it has reached is zeroed (slip), or all of them (sticky)."""
    out = v
    beyond = 0
    for c in ti.static(range(3)):
        if (pos[c] >= grid_f[6 + c] and v[c] >= 0.0) or (pos[c] <= grid_f[3 + c] and v[c] <= 0.0):
            out[c] = 0.0
            beyond = 1
    if sticky and beyond:
        out = ti.Vector.zero(float, 3)
    return out


@ti.func
def clear_stage(serial: ti.template(), grid: ti.template(), active: ti.template(), grid_i: ti.template()):
    """Zero the nodes this substep touched, and the counts."""
    B, K = active.shape[0] - 1, node_count(grid_i)
    ti.loop_config(serialize=serial)
    for e, k in ti.ndrange(B, active[B, 0]):
        if k < active[e, 0]:
            at = node_at(e, active[e, k + 1], K)
            for c in ti.static(range(4)):
                grid[at + c] = 0.0
    ti.loop_config(serialize=True)
    for e in range(B + 1):
        active[e, 0] = 0


@ti.func
def wall_mask(pos, v, grid_f: ti.template(), sticky):
    """The mask (3,) of 0/1 that wall_velocity applied at a node at pos (3,) m whose updated
    velocity is v (3,): a component beyond a wall that the walls did not zero points strictly
    inwards (nonzero), so it was zeroed iff it is zero now; sticky walls zero all or none."""
    mask = ti.Vector([1.0, 1.0, 1.0])
    stopped = 0
    for c in ti.static(range(3)):
        if (pos[c] >= grid_f[6 + c] or pos[c] <= grid_f[3 + c]) and v[c] == 0.0:
            mask[c] = 0.0
            stopped = 1
    if sticky and stopped:
        mask = ti.Vector.zero(float, 3)
    return mask


@ti.func
def grid_adjoint_stage(colliders: ti.template(), walls: ti.template(), grid: ti.template(), grad_grid: ti.template(),
                       active: ti.template(), env_in: ti.template(), grad_env: ti.template(), grid_f: ti.template(),
                       grid_i: ti.template(), saved_grid: ti.template(), s):
    """Reverse of substep s's update, per listed node (parallel): grad_grid's velocity gradient
    (0:3) → (∂L/∂P (0:3), ∂L/∂M (3)); the grid's velocity is replaced by the gradient of the
    velocity after gravity, for the gravity sum (gravity_adjoint_stage). Without ``walls`` (a coupler
    between: walls_adjoint_stage and its reverse came first) the grid holds the velocity before the
    coupler, the gradient is past the walls, and ∂L/∂M adds to the coupler's."""
    h, dx, K = grid_f[0], 1.0 / grid_f[1], node_count(grid_i)
    B = active.shape[0] - 1
    for e, k in ti.ndrange(B, active[B, 0]):
        if k < active[e, 0]:
            n = active[e, k + 1]
            at = node_at(e, n, K)
            v = node_vector(grid, at)
            mass = grid[at + 3]
            pos = node_position(n, dx, grid_i)
            g_v = node_vector(grad_grid, at)
            if ti.static(walls):
                g_v = wall_mask(pos, v, grid_f, grid_i[6]) * g_v
            free = v  # where the mask passes and no collider acts, v = P / M + h g
            if ti.static(colliders):
                free = ti.Vector([saved_grid[s, e, k, 4 + c] for c in ti.static(range(3))])
                g_v = collide_adjoint(grid_f, grid_i[7], pos, free, g_v, env_in, e, grad_env, False)
            velocity = free - h * ti.Vector([env_in[e, 0], env_in[e, 1], env_in[e, 2]])  # P / M
            for c in ti.static(range(3)):
                grad_grid[at + c] = g_v[c] / mass
                grid[at + c] = g_v[c]
            g_mass = -g_v.dot(velocity) / mass
            if ti.static(not walls):
                g_mass += grad_grid[at + 3]
            grad_grid[at + 3] = g_mass


@ti.func
def gravity_adjoint_stage(serial: ti.template(), grid: ti.template(), active: ti.template(),
                          grad_env: ti.template(), grid_f: ti.template(), grid_i: ti.template()):
    """grad_env's gravity (B, 0:3) += h Σ mask ⊙ ∂L/∂v over env e's listed nodes, serially in list order
    (deterministic), from what grid_adjoint_stage left in the grid."""
    h, K = grid_f[0], node_count(grid_i)
    B = active.shape[0] - 1
    ti.loop_config(serialize=serial)
    for e in range(B):
        total = ti.Vector.zero(float, 3)
        for k in range(active[e, 0]):
            total += node_vector(grid, node_at(e, active[e, k + 1], K))
        for c in ti.static(range(3)):
            grad_env[e, c] = grad_env[e, c] + h * total[c]


@ti.func
def update_adjoint_stage(serial: ti.template(), colliders: ti.template(), walls: ti.template(), grid: ti.template(),
                         grad_grid: ti.template(), active: ti.template(), env_in: ti.template(),
                         grad_env: ti.template(), grid_f: ti.template(), grid_i: ti.template(),
                         saved_grid: ti.template(), s, coupling_grads):
    """Reverse of substep s's grid update (from the walls' when ``walls``; else after the coupler's
    reverse): the colliders' coupling parameters (when ``coupling_grads``), then per node, then
    gravity's sum."""
    if ti.static(colliders):
        coupling_adjoint_stage(serial, walls, grid, grad_grid, active, env_in, grad_env, grid_f, grid_i, saved_grid, s,
                               coupling_grads)
    grid_adjoint_stage(colliders, walls, grid, grad_grid, active, env_in, grad_env, grid_f, grid_i, saved_grid, s)
    gravity_adjoint_stage(serial, grid, active, grad_env, grid_f, grid_i)


@ti.func
def coupling_adjoint_stage(serial: ti.template(), walls: ti.template(), grid: ti.template(),
                           grad_grid: ti.template(), active: ti.template(), env_in: ti.template(),
                           grad_env: ti.template(), grid_f: ti.template(), grid_i: ti.template(),
                           saved_grid: ti.template(), s, wanted):
    """grad_env += ∂L/∂(μ, ς, e) of the colliders at rest, summed serially per env over its listed
    nodes in list order (deterministic), before grid_adjoint_stage overwrites what it reads:
    grad_grid's velocity gradient (through the walls' mask when ``walls``; else past them
    already) and the velocity before the colliders (saved_grid 4:7). Nothing unless ``wanted``."""
    dx, K = 1.0 / grid_f[1], node_count(grid_i)
    B = active.shape[0] - 1
    ti.loop_config(serialize=serial)
    for e in range(B * wanted):
        for k in range(active[e, 0]):
            n = active[e, k + 1]
            at = node_at(e, n, K)
            pos = node_position(n, dx, grid_i)
            g_v = node_vector(grad_grid, at)
            if ti.static(walls):
                g_v = wall_mask(pos, node_vector(grid, at), grid_f, grid_i[6]) * g_v
            free = ti.Vector([saved_grid[s, e, k, 4 + c] for c in ti.static(range(3))])
            collide_adjoint(grid_f, grid_i[7], pos, free, g_v, env_in, e, grad_env, True)


@ti.func
def clear_adjoint_stage(serial: ti.template(), grid: ti.template(), grad_grid: ti.template(), active: ti.template(),
                        grid_i: ti.template()):
    """Zero the nodes this substep touched, in the restored grid and its gradient, and the counts."""
    B, K = active.shape[0] - 1, node_count(grid_i)
    ti.loop_config(serialize=serial)
    for e, k in ti.ndrange(B, active[B, 0]):
        if k < active[e, 0]:
            at = node_at(e, active[e, k + 1], K)
            for c in ti.static(range(4)):
                grid[at + c] = 0.0
                grad_grid[at + c] = 0.0
    ti.loop_config(serialize=True)
    for e in range(B + 1):
        active[e, 0] = 0
