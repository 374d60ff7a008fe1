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
so a batched env equals a single-env scene. Forward only: a scene that differentiates is refused
at build, naming these shapes (genesis_lite/scene.py; the MPM solver's set_colliders backs it).
"""
import taichi as ti
import torch

from .core import runtime
from .launch import BoundKernel
from .mpm import colliders
from .mpm.grid import node_position
from .mpm.stencil import node_at, node_count, node_vector
from .rigid.data import ARENA_TYPES, ARENAS, ELEMENT, bind, n_batch
from .rigid.kinematics import dof_count, dof_motion_at, reference

I, F, V3, V4, M3 = ARENA_TYPES
A = ti.types.ndarray()


@ti.kernel
def couple(serial: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, grid: A, grid_f: A, grid_i: A,
           shapes: A, geoms: A, s: ti.i32):
    """Substep s's coupling stage (the module's): every env's shapes of moving links (shapes: their
    rows and data, colliders.packed from 0; geoms (C, 2): each one's rigid geom and link) against
    the MPM grid (flat, as the MPM kernels take it, with grid_f and grid_i)."""
    ti.loop_config(serialize=serial)
    for e in range(n_batch(ints)):
        d = bind(ints, f1, v3, v4, m3)
        for c in range(geoms.shape[0]):
            force, torque = _meet(d, grid, grid_f, grid_i, shapes, geoms[c, 0], geoms[c, 1], c, s, e)
            _add_generalised_force(d, s, e, geoms[c, 1], d.geom_xpos[s, e, geoms[c, 0]], force, torque)


@ti.func
def _meet(d: ti.template(), grid: ti.template(), grid_f: ti.template(), grid_i: ti.template(),
          shapes: ti.template(), g, l, c, s, e):
    """Shape c (rigid geom g of link l) against env e's nodes within its reach, at frame s: their
    velocities after it; returns the force (3,) N and torque (3,) N·m about the geom's position that
    the nodes put on it."""
    at = c * colliders.WIDTH
    pos, R = d.geom_xpos[s, e, g], d.geom_xmat[s, e, g]
    about, spin, drift = reference(d, s, e, l), d.cvel_w[s, e, l], d.cvel_v[s, e, l]
    h, dx, K = grid_f[0], 1.0 / grid_f[1], node_count(grid_i)
    lo, hi = _node_box(pos, colliders.reach(shapes, at), dx, grid_i)
    force, torque = ti.Vector.zero(float, 3), ti.Vector.zero(float, 3)
    for i in range(lo[0], hi[0]):
        for j in range(lo[1], hi[1]):
            for k in range(lo[2], hi[2]):
                n = (i * grid_i[4] + j) * grid_i[5] + k
                node = node_at(e, n, K)
                mass = grid[node + 3]
                if mass > 0.0:  # (a node the particles reach)
                    x = node_position(n, dx, grid_i)
                    acts, normal, w, mu, restitution = colliders.posed_contact(shapes, at, R, pos, x)
                    if acts:
                        v = node_vector(grid, node)
                        u = drift + spin.cross(x - about)
                        new = u + colliders.respond(v - u, normal, w, mu, restitution)
                        for a in ti.static(range(3)):
                            grid[node + a] = new[a]
                        f = (-mass / h) * (new - v)
                        force += f
                        torque += (x - pos).cross(f)
    return force, torque


@ti.func
def _node_box(pos, radius, dx, grid_i: ti.template()):
    """(lo, hi) (3,) int: the grid nodes within ``radius`` m of ``pos`` lie in lo ≤ index < hi on each
    axis (clipped to the grid; empty where the ball misses it)."""
    lo, hi = ti.Vector([0, 0, 0]), ti.Vector([0, 0, 0])
    for a in ti.static(range(3)):
        res = ti.cast(grid_i[3 + a], float)
        first = ti.floor((pos[a] - radius) / dx) - grid_i[a]
        last = ti.floor((pos[a] + radius) / dx) - grid_i[a]
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
        data = self.rigid.data
        if self._bound[0] is not data:  # (new arenas when the rigid contact slots grow)
            arrays = [*data.arenas, self.mpm.grid.view(-1), self.mpm.grid_f, self.mpm.grid_i, self.shapes,
                      self.geoms]
            dims = [len(ELEMENT[a]) for a in ARENAS] + [0] * 5
            self._bound = (data, BoundKernel(couple, data.schedule[0], arrays, dims))
        self._bound[1](s)
