"""The coupling stage: MPM particles and the rigid shapes of moving links, both ways (Genesis's
LegacyCoupler rule, mpm/colliders.py, with the shape's velocity), between the solvers' halves of
each substep of the shared loop (solvers/base.py).

At substep s, after the rigid smooth stage of frame s (its links' poses and velocities, its smooth
force) and the MPM grid update up to the walls (each listed node's velocity v and mass M): per env,
per coupled shape of a moving link (rigid geom g on link l, in the rigid geoms' order) and per node
within the shape's reach (a box of nodes around it, in the grid's order),

    u = v_l + ω_l × (x − o)            the shape's velocity at the node x (its link's motion; o the
                                        point the rigid solver's link velocities are taken about)
    v ← u + respond(v − u)              colliders.respond: the node's velocity relative to the shape
    f = −M Δv / h                       the force the node's change of momentum puts on the shape, at x

The forces are summed per shape about its position p_g (F = Σ f, τ = Σ (x − p_g) × f) and enter
the rigid substep as the generalised force Jᵀ(p_g) (F, τ), added to qfrc_smooth[s] before its
solve: the momentum the grid loses the link gains in the same substep (the exchange conserves
momentum). Genesis's rule is the same, timed otherwise: it couples the grid of substep s with the
poses after its rigid substep s and applies the force in rigid substep s + 1 (also across steps,
outside the state). Per node the shapes at rest (the MPM grid update's colliders) act before these
(Genesis: all shapes in its geom order), the walls after.

Cost: a shape visits its box of nodes every substep, near particles or not (a plane on a moving
link: the whole grid). Deterministic: an env's shapes and nodes go in a fixed order on one thread,
so a batched env equals a single-env scene.

Its reverse (couple_adjoint) runs between the solvers' reverse halves (docs/architecture.md,
"Rigid–MPM coupling"): it reads qfrc_smooth's gradient at frame s and the grid's gradient after
the stage, and adds to the grid's before it, the nodes' masses', the rigid frame's geom poses
(onto their links), link velocities and dofs' motions, and the shapes' coupling parameters (μ, ς,
e: the MPM solver's per-env input, grad_env). The set of nodes a shape acts on is frozen (the
influence's cutoff and the reach), as a contact's feature is.
"""
import taichi as ti
import torch

from .core import runtime
from .launch import BoundKernel
from .mpm import colliders
from .mpm.grid import node_position
from .mpm.stencil import node_at, node_count, node_vector
from .rigid.collision.detect import geom_pose_adjoint
from .rigid.data import ARENA_TYPES, ARENAS, ELEMENT, accumulate, bind, n_batch
from .rigid.kinematics import dof_count, dof_motion_at, reference

I, F, V3, V4, M3 = ARENA_TYPES
A = ti.types.ndarray()


@ti.kernel
def couple(serial: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, grid: A, env_in: A, grid_f: A, grid_i: A,
           shapes: A, geoms: A, s: ti.i32):
    """Substep s's coupling stage (the module's): every env's shapes of moving links (shapes: their
    rows and data, colliders.packed from 0; geoms (C, 2): each one's rigid geom and link) against
    the MPM grid (flat, as the MPM kernels take it, with env_in, whose couplings the rows point
    into, grid_f and grid_i)."""
    ti.loop_config(serialize=serial)
    for e in range(n_batch(ints)):
        d = bind(ints, f1, v3, v4, m3)
        for c in range(geoms.shape[0]):
            force, torque = _meet(d, grid, env_in, grid_f, grid_i, shapes, geoms, c, s, e, False)
            _add_generalised_force(d, s, e, geoms[c, 1], d.geom_xpos[s, e, geoms[c, 0]], force, torque)


@ti.func
def _shape(d: ti.template(), shapes: ti.template(), geoms: ti.template(), env_in: ti.template(), c, s, e):
    """Shape c at frame s of env e: (its row's start in the shapes' table, its position (3,) m, its
    rotation (3, 3), the point its link's velocity is taken about (3,) m, the link's angular (3,)
    rad/s and linear velocity there (3,) m/s, its coupling (μ, ς m, e) (3,))."""
    g, l, at = geoms[c, 0], geoms[c, 1], c * colliders.WIDTH
    mu, softness, restitution = colliders.coupling(shapes, at, env_in, e)
    return (at, d.geom_xpos[s, e, g], d.geom_xmat[s, e, g], reference(d, s, e, l), d.cvel_w[s, e, l],
            d.cvel_v[s, e, l], ti.Vector([mu, softness, restitution]))


@ti.func
def _met(shapes: ti.template(), at, pos, R, about, spin, drift, params, x, v):
    """(acts, the velocity after the shape) of a node at x (3,) m with velocity v (3,) m/s, against the
    shape of the row at ``at`` posed at (pos, R) moving with (spin, drift) about ``about``, with
    coupling params (μ, ς, e)."""
    acts, _, normal, w = colliders.posed_contact(shapes, at, R, pos, x, params[1])
    new = v
    if acts:
        u = drift + spin.cross(x - about)
        new = u + colliders.respond(v - u, normal, w, params[0], params[2])
    return acts, new


@ti.func
def _before(d: ti.template(), shapes: ti.template(), geoms: ti.template(), env_in: ti.template(), c, s, e, x, v):
    """The velocity before shape c of a node at x whose velocity before the stage is v: shapes
    0 … c − 1 replayed."""
    out = v
    for k in range(c):
        at, pos, R, about, spin, drift, params = _shape(d, shapes, geoms, env_in, k, s, e)
        _, out = _met(shapes, at, pos, R, about, spin, drift, params, x, out)
    return out


@ti.func
def _meet(d: ti.template(), grid: ti.template(), env_in: ti.template(), grid_f: ti.template(), grid_i: ti.template(),
          shapes: ti.template(), geoms: ti.template(), c, s, e, replay: ti.template()):
    """Shape c against env e's nodes within its reach, at frame s: their velocities after it (or,
    ``replay``, the grid left as it is: it holds the velocities before the stage, from which the
    earlier shapes are replayed); returns the force (3,) N and torque (3,) N·m about the shape's
    position that the nodes put on it."""
    at, pos, R, about, spin, drift, params = _shape(d, shapes, geoms, env_in, c, s, e)
    h, dx, K = grid_f[0], 1.0 / grid_f[1], node_count(grid_i)
    lo, hi = _node_box(pos, colliders.reach(shapes, at, params[1]), dx, grid_i)
    force, torque = ti.Vector.zero(float, 3), ti.Vector.zero(float, 3)
    for i in range(lo[0], hi[0]):
        for j in range(lo[1], hi[1]):
            for k in range(lo[2], hi[2]):
                n = (i * grid_i[4] + j) * grid_i[5] + k
                node = node_at(e, n, K)
                mass = grid[node + 3]
                if mass > 0.0:  # (a node the particles reach)
                    x = node_position(n, dx, grid_i)
                    v = node_vector(grid, node)
                    if ti.static(replay):
                        v = _before(d, shapes, geoms, env_in, c, s, e, x, v)
                    acts, new = _met(shapes, at, pos, R, about, spin, drift, params, x, v)
                    if acts:
                        if ti.static(not replay):
                            for a in ti.static(range(3)):
                                grid[node + a] = new[a]
                        f = (-mass / h) * (new - v)
                        force += f
                        torque += (x - pos).cross(f)
    return force, torque


@ti.func
def _node_box(pos, radius, dx, grid_i: ti.template()):
    """(lo, hi) (3,) int: the grid nodes within ``radius`` m of ``pos`` lie in lo ≤ index < hi on each
    axis (clipped to the grid; empty where the ball misses it, or where the pose is not finite: a
    body that blew up meets no node)."""
    lo, hi = ti.Vector([0, 0, 0]), ti.Vector([0, 0, 0])
    for a in ti.static(range(3)):
        res = ti.cast(grid_i[3 + a], float)
        first = ti.floor((pos[a] - radius) / dx) - grid_i[a]
        last = ti.floor((pos[a] + radius) / dx) - grid_i[a]
        if first == first and last == last:  # (not NaN)
            lo[a] = ti.cast(ti.min(ti.max(first, 0.0), res), ti.i32)
            hi[a] = ti.cast(ti.min(ti.max(last + 1.0, 0.0), res), ti.i32)
    return lo, hi


@ti.func
def _add_generalised_force(d: ti.template(), s, e, l, point, force, torque):
    """qfrc_smooth[s, e] += Jᵀ (force, torque) of link l at ``point`` (world, m): every dof on the
    link's path to the root, as the contact rows' Jacobian (constraint/rows.py)."""
    a = l
    while a >= 0:
        dof0 = d.link_dof0[a]
        for i in range(dof0, dof0 + dof_count(d, a)):
            linear, angular = dof_motion_at(d, s, e, i, point)
            d.qfrc_smooth[s, e, i] = d.qfrc_smooth[s, e, i] + linear.dot(force) + angular.dot(torque)
        a = d.link_parent[a]


@ti.kernel
def couple_adjoint(serial: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, grid: A, grad_grid: A, env_in: A,
                   grad_env: A, grid_f: A, grid_i: A, shapes: A, geoms: A, s: ti.i32):
    """Reverse of substep s's coupling stage. The grid holds each listed node's velocity before the
    stage and its mass (the MPM reverse put them back), grad_grid (flat, as grid) ∂L/∂v after the
    stage (0:3; becomes ∂L/∂v before it) and 3 the mass's gradient (+= the stage's part); the rigid
    frame s's qfrc_smooth gradient is whole (the rigid solver's reverse of the solve and the
    integration ran). Per env, the shapes in reverse order: their wrench's forward replayed (the
    earlier shapes replayed per node), its Jᵀ's reverse (into the dofs' motions, cdof), then the
    nodes' reverse (into the shape's pose, onto its link's origin and turn, its link's velocity,
    cvel, and its coupling parameters, grad_env: the MPM solver's). Gradients at the rigid solver's
    reference point take it as fixed, as its own reverse does (kinematics.py)."""
    ti.loop_config(serialize=serial)
    for e in range(n_batch(ints)):
        d = bind(ints, f1, v3, v4, m3)
        C = geoms.shape[0]
        for back in range(C):
            c = C - 1 - back
            force, torque = _meet(d, grid, env_in, grid_f, grid_i, shapes, geoms, c, s, e, True)
            pos = d.geom_xpos[s, e, geoms[c, 0]]
            g_force, g_torque, g_pos = _generalised_force_adjoint(d, s, e, geoms[c, 1], pos, force, torque)
            _meet_adjoint(d, grid, grad_grid, env_in, grad_env, grid_f, grid_i, shapes, geoms, c, s, e, g_force,
                          g_torque, g_pos)


@ti.func
def _generalised_force_adjoint(d: ti.template(), s, e, l, point, force, torque):
    """Reverse of _add_generalised_force from qfrc_smooth's gradient at frame s: (∂L/∂force (3,),
    ∂L/∂torque (3,), ∂L/∂point (3,)); the dofs' motions' gradients (cdof) accumulated."""
    g_force, g_torque, g_point = ti.Vector.zero(float, 3), ti.Vector.zero(float, 3), ti.Vector.zero(float, 3)
    a = l
    while a >= 0:
        dof0 = d.link_dof0[a]
        for i in range(dof0, dof0 + dof_count(d, a)):
            g = d.qfrc_smooth.grad[s, e, i]
            linear, angular = dof_motion_at(d, s, e, i, point)
            g_force += g * linear
            g_torque += g * angular
            arm = point - reference(d, s, e, d.dof_link[i])
            accumulate(d.cdof_v.grad, ti.Vector([s, e, i]), g * force)
            accumulate(d.cdof_w.grad, ti.Vector([s, e, i]), g * (arm.cross(force) + torque))
            g_point += g * force.cross(angular)
        a = d.link_parent[a]
    return g_force, g_torque, g_point


@ti.func
def _meet_adjoint(d: ti.template(), grid: ti.template(), grad_grid: ti.template(), env_in: ti.template(),
                  grad_env: ti.template(), grid_f: ti.template(), grid_i: ti.template(), shapes: ti.template(),
                  geoms: ti.template(), c, s, e, g_force, g_torque, g_pos):
    """Reverse of shape c's _meet at frame s of env e, given the gradients of its force, torque and
    position (from its Jᵀ: g_force, g_torque, g_pos, each (3,)): grad_grid's nodes (as couple_adjoint
    says), the shape's pose, its link's velocity and its coupling parameters' gradients."""
    at, pos, R, about, spin, drift, params = _shape(d, shapes, geoms, env_in, c, s, e)
    mu, softness, restitution = params[0], params[1], params[2]
    h, dx, K = grid_f[0], 1.0 / grid_f[1], node_count(grid_i)
    lo, hi = _node_box(pos, colliders.reach(shapes, at, softness), dx, grid_i)
    g_R, g_spin, g_drift = ti.Matrix.zero(float, 3, 3), ti.Vector.zero(float, 3), ti.Vector.zero(float, 3)
    g_params = ti.Vector.zero(float, 3)
    for i in range(lo[0], hi[0]):
        for j in range(lo[1], hi[1]):
            for k in range(lo[2], hi[2]):
                n = (i * grid_i[4] + j) * grid_i[5] + k
                node = node_at(e, n, K)
                mass = grid[node + 3]
                if mass > 0.0:
                    x = node_position(n, dx, grid_i)
                    v = _before(d, shapes, geoms, env_in, c, s, e, x, node_vector(grid, node))
                    acts, _, normal, w = colliders.posed_contact(shapes, at, R, pos, x, softness)
                    if acts:
                        # forward: p = Rᵀ (x − pos), (d, n_p) = shape_distance(p), n = R n_p, w = min(e^(−d/ς), 1),
                        # u = drift + spin × (x − about), v' = u + respond(v − u), f = −M (v' − v) / h
                        p = R.transpose() @ (x - pos)
                        distance, normal_p = colliders.shape_distance(shapes, at, p)
                        u = drift + spin.cross(x - about)
                        new = u + colliders.respond(v - u, normal, w, mu, restitution)
                        f = (-mass / h) * (new - v)
                        g_f = g_force + g_torque.cross(x - pos)  # (torque += (x − pos) × f)
                        g_pos -= f.cross(g_torque)
                        g_new = node_vector(grad_grid, node) - (mass / h) * g_f
                        g_rel, g_n, g_w, g_mu, g_e = colliders.respond_adjoint(v - u, normal, w, mu, restitution,
                                                                               g_new)
                        g_distance, g_softness = colliders.influence_adjoint(distance, w, softness, g_w)
                        g_params += ti.Vector([g_mu, g_softness, g_e])
                        g_u = g_new - g_rel
                        g_drift += g_u
                        g_spin += (x - about).cross(g_u)
                        g_R += g_n.outer_product(normal_p)
                        turn = colliders.normal_jacobian(shapes, at, p, distance, normal_p)  # ∂n_p/∂p
                        g_p = g_distance * normal_p + turn.transpose() @ (R.transpose() @ g_n)
                        g_pos -= R @ g_p
                        g_R += (x - pos).outer_product(g_p)
                        g_v = (mass / h) * g_f + g_rel
                        for a in ti.static(range(3)):
                            grad_grid[node + a] = g_v[a]
                        grad_grid[node + 3] = grad_grid[node + 3] - (new - v).dot(g_f) / h
    l = geoms[c, 1]
    geom_pose_adjoint(d, s, e, geoms[c, 0], g_pos, g_R)
    accumulate(d.cvel_w.grad, ti.Vector([s, e, l]), g_spin)
    accumulate(d.cvel_v.grad, ti.Vector([s, e, l]), g_drift)
    col = colliders.coupling_at(shapes, at)
    for a in ti.static(range(3)):
        grad_env[e, col + a] = grad_env[e, col + a] + g_params[a]


class Coupler:
    """The coupling stage of one scene: its rigid and MPM solvers and the shapes of moving links
    that meet the grid (coupling.rigid_colliders' ``moving``: rows, data, geoms)."""

    def __init__(self, rigid, mpm, rows, data, geoms):
        self.rigid, self.mpm = rigid, mpm
        self.shapes = torch.as_tensor(colliders.packed(rows, data, at=0), dtype=runtime.tc_float,
                                      device=runtime.device)
        self.geoms = torch.as_tensor(geoms, dtype=torch.int32, device=runtime.device).reshape(-1, 2)
        self._bound = (None, None)  # (the rigid data it is bound to, the kernel)

    def couple(self, s):
        """Substep s's coupling stage (after every solver's substep_pre_coupling(s))."""
        self._kernels()[0](s)

    def couple_backward(self, s):
        """Its reverse (after every solver's substep_post_coupling_backward(s), before their
        substep_pre_coupling_backward(s))."""
        self._kernels()[1](s)

    def _kernels(self):
        """(couple, couple_adjoint) bound to the solvers' arrays (again when the rigid contact slots
        grew: new arenas; the adjoint only where the MPM solver differentiates)."""
        data = self.rigid.data
        if self._bound[0] is not data:
            arenas, dims = list(data.arenas), [len(ELEMENT[a]) for a in ARENAS]
            mpm, serial = self.mpm, data.schedule[0]
            forward = BoundKernel(couple, serial, [*arenas, mpm.grid.view(-1), mpm.env_in, mpm.grid_f, mpm.grid_i,
                                                   self.shapes, self.geoms], dims + [0] * 6)
            reverse = None
            if mpm.requires_grad:
                reverse = BoundKernel(couple_adjoint, serial, [*arenas, mpm.grid.view(-1), mpm.grad_grid.view(-1),
                                                               mpm.env_in, mpm.grad_env, mpm.grid_f, mpm.grid_i,
                                                               self.shapes, self.geoms], dims + [0] * 8)
            self._bound = (data, (forward, reverse))
        return self._bound[1]
