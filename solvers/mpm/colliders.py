"""Rigid shapes at rest that the MPM grid meets: the rigid side of Genesis's rigid–MPM coupling
(its LegacyCoupler) for shapes fixed to the world — a ground plane, a table, an obstacle — and
its adjoint. The shapes' distances (posed_distance, posed_contact) and the rule (respond) serve
the shapes of moving links too, posed by the rigid solver's frame (solvers/coupler.py), whose
reverse also takes the rule's adjoint in the normal and the influence (respond_adjoint) and the
normal's derivative in the point (normal_jacobian).

In the grid update, after gravity and before the walls (Genesis's order), each node's velocity v
meets every collider in turn. With the collider's signed distance d and outward unit normal n at the
node (analytic: plane, sphere, capsule, cylinder, box, convex mesh) and the rigid material's
coupling friction μ, softness ς and restitution e (coup_friction, coup_softness, coup_restitution),
as Genesis's ``_func_collide_in_rigid_geom`` with the rigid velocity zero:

    w = min(exp(−d / max(ς, 1e-10)), 1)                    the collider's influence
    where w > 0.1 and v·n < 0 (moving into the shape):
        t = v − (v·n) n,  T = sqrt(|t|² + ε)               tangential part (ε: Genesis's gs.EPS)
        t' = t / T · max(0, T + μ v·n)                      Coulomb: slowed by μ times the normal stop
        v ← w (t' − e (v·n) n) + (1 − w) v

A collider is at rest and a node does not move, so d and n are constants of the node: the map is
of v and the coupling parameters (w of ς) alone, piecewise smooth (kinks where v·n = 0 and where
the friction stops the node), and its adjoint (``collide_adjoint``) replays the colliders before
each one to find its input.

Rows live in ``grid_f`` after the walls (COLLIDERS_AT, WIDTH numbers each: kind, position (3) m,
rotation (9, row-major, world from shape), size (3) m, where its rigid entity's (μ, ς, e) start
among the per-env inputs ``env_in`` (COUPLING; layout.COUPLING_AT, coupling_columns), bounding
radius m about the position (BOUND; a plane's: infinite)), their count in ``grid_i[7]``. μ, ς and e are inputs per env, so that they
have gradients (``collide_adjoint`` with ``params``; the coupler's reverse for moving shapes):
∂/∂μ and ∂/∂e of the rule, ∂/∂ς through the influence (``influence_adjoint``); the set of nodes a
collider acts on (the cutoff, the reach) is frozen, as a contact's feature is. A node farther than the bounding
radius plus the influence's reach (ς ln 10, where w falls to the cutoff; twice that, for round-off)
skips the collider's distance: it cannot act there (a scene of many small shapes pays for the
few a node is near).
Sizes follow the rigid geoms' (MuJoCo's) convention: sphere (radius), capsule (radius, half
length of the segment along z), cylinder (radius, half height along z), box (half sizes); a
plane is the half-space below its z = 0 plane (infinite, as in Genesis). A convex mesh (HULL: the
rigid solver's convex hull of a mesh) is the intersection of its faces' half-spaces: its size
holds where its face planes start in ``grid_f`` (after the rows: normal (3), offset (1) m each, in
the shape's frame, n·p + offset ≤ 0 inside) and how many there are; its signed distance is the
largest of the planes' — exact inside and beside a face, a lower bound beside an edge or corner
(which lets the influence reach up to √3 times further there; Genesis samples a mesh's distance
from an SDF grid). A height field (HFIELD; the rigid solver's: MuJoCo's grid, two triangles a cell)
keeps its data after the rows too: size x, size y (m), nrow, ncol, then the nrow·ncol heights (m,
its frame, row by row), its size[0] where they start; its signed distance is to the plane of the
triangle above or below the point (the surface's normal there), over its rectangle only (beside
it: FAR) — a solid below the surface, also under its base.
"""
import numpy as np
import taichi as ti

from .constitutive import genesis_eps

PLANE, SPHERE, CAPSULE, CYLINDER, BOX, HULL, HFIELD = range(7)
FAR = 1e6  # m: a height field's distance beside its rectangle (no influence)
WIDTH = 18
COUPLING, BOUND = 16, 17  # a row's fields: where its entity's (μ, ς, e) start in env_in; its bounding radius
COLLIDERS_AT = 9  # grid_f: h, inv_dx, vol, the walls' lower (3) and upper (3) corners, then the colliders
INFLUENCE_CUTOFF = 0.1  # Genesis's: a collider acts on a node where its influence exceeds this


def packed(rows, data, at=COLLIDERS_AT):
    """The colliders' part of grid_f (a table starting at grid_f[at]): rows (C, WIDTH), then the data
    of the hulls and height fields (D,) (their face planes, 4 numbers each; their grids); the size[0]
    of a HULL or HFIELD row, given as where its data start in ``data``, becomes their index in the
    whole array."""
    rows = np.array(rows, dtype=np.float64).reshape(-1, WIDTH)
    with_data = (rows[:, 0] == HULL) | (rows[:, 0] == HFIELD)
    rows[with_data, 13] = at + rows.size + rows[with_data, 13]
    return np.concatenate([rows.ravel(), np.asarray(data, dtype=np.float64).ravel()])


@ti.func
def _rotation(grid_f: ti.template(), at):
    return ti.Matrix([[grid_f[at + 4 + 3 * i + j] for j in ti.static(range(3))] for i in ti.static(range(3))])


@ti.func
def _box_distance(p, half):
    """(d, n) of the point p (3,) in a box's frame: exact distance outside (to the nearest face,
    edge or corner), the nearest face's inside."""
    q = ti.abs(p) - half
    side = ti.Vector([1.0 if p[i] >= 0.0 else -1.0 for i in ti.static(range(3))])
    out = ti.max(q, 0.0)
    d = out.norm()
    n = ti.Vector([0.0, 0.0, 1.0])
    if d > 0.0:
        n = side * out / d
    else:
        axis, d = 0, q[0]
        for i in ti.static(range(1, 3)):
            if q[i] > d:
                axis, d = i, q[i]
        n = ti.Vector([side[i] if i == axis else 0.0 for i in ti.static(range(3))])
    return d, n


@ti.func
def _cylinder_distance(p, radius, half_height):
    """(d, n) of the point p (3,) in a cylinder's frame (axis z): exact, with the rim's corner
    region outside."""
    rho = ti.sqrt(p[0] * p[0] + p[1] * p[1])
    radial = ti.Vector([1.0, 0.0, 0.0])  # (on the axis: any direction across it)
    if rho > 0.0:
        radial = ti.Vector([p[0] / rho, p[1] / rho, 0.0])
    axial = ti.Vector([0.0, 0.0, 1.0 if p[2] >= 0.0 else -1.0])
    d_side, d_cap = rho - radius, ti.abs(p[2]) - half_height
    d = ti.max(d_side, d_cap)
    n = axial
    if d_side > 0.0 and d_cap > 0.0:
        d = ti.sqrt(d_side * d_side + d_cap * d_cap)
        n = (d_side * radial + d_cap * axial) / d
    elif d_side > d_cap:
        n = radial
    return d, n


@ti.func
def signed_distance(grid_f: ti.template(), at, x):
    """(d m, n (3,) world) of the point x (3,) m to the collider whose row starts at grid_f[at]."""
    return posed_distance(grid_f, at, _rotation(grid_f, at), _position(grid_f, at), x)


@ti.func
def posed_distance(grid_f: ti.template(), at, R, pos, x):
    """(d m, n (3,) world) of the point x (3,) m to the shape of the row at grid_f[at] posed at pos
    (3,) m, turned by R (3, 3, world from shape): the row's own pose, or a moving link's."""
    d, n = shape_distance(grid_f, at, R.transpose() @ (x - pos))
    return d, R @ n


@ti.func
def _position(grid_f: ti.template(), at):
    return ti.Vector([grid_f[at + 1], grid_f[at + 2], grid_f[at + 3]])


@ti.func
def shape_distance(grid_f: ti.template(), at, p):
    """(d m, n (3,) in the shape's frame) of the point p (3,) m, in the shape's frame, to the shape
    of the row at grid_f[at]."""
    kind = ti.cast(grid_f[at], ti.i32)
    a, b = grid_f[at + 13], grid_f[at + 14]
    d, n = p[2], ti.Vector([0.0, 0.0, 1.0])  # PLANE
    if kind == SPHERE:
        r = p.norm()
        d = r - a
        if r > 0.0:
            n = p / r
    elif kind == CAPSULE:
        q = p - ti.Vector([0.0, 0.0, ti.min(ti.max(p[2], -b), b)])
        r = q.norm()
        d, n = r - a, ti.Vector([1.0, 0.0, 0.0])
        if r > 0.0:
            n = q / r
    elif kind == CYLINDER:
        d, n = _cylinder_distance(p, a, b)
    elif kind == BOX:
        d, n = _box_distance(p, ti.Vector([a, b, grid_f[at + 15]]))
    elif kind == HULL:
        d, n = _hull_distance(grid_f, ti.cast(a, ti.i32), ti.cast(b, ti.i32), p)
    elif kind == HFIELD:
        d, n = _hfield_distance(grid_f, ti.cast(a, ti.i32), p)
    return d, n


@ti.func
def _hfield_distance(grid_f: ti.template(), first, p):
    """(d, n) of the point p (3,) in a height field's frame (its data from grid_f[first]): over its
    rectangle, the signed distance to the plane of the grid triangle above or below p and that
    plane's upward normal; beside it, FAR."""
    sx, sy = grid_f[first], grid_f[first + 1]
    nrow, ncol = ti.cast(grid_f[first + 2], ti.i32), ti.cast(grid_f[first + 3], ti.i32)
    d, n = FAR, ti.Vector([0.0, 0.0, 1.0])
    if ti.abs(p[0]) <= sx and ti.abs(p[1]) <= sy:
        dx, dy = 2.0 * sx / (ncol - 1), 2.0 * sy / (nrow - 1)
        fu, fv = (p[0] + sx) / dx, (p[1] + sy) / dy
        c, r = ti.min(ti.cast(ti.floor(fu), ti.i32), ncol - 2), ti.min(ti.cast(ti.floor(fv), ti.i32), nrow - 2)
        u, v = fu - c, fv - r
        at = first + 4 + r * ncol + c  # the cell's corner (r, c); MuJoCo's diagonal joins it to (r + 1, c + 1)
        h00, h10, h01, h11 = grid_f[at], grid_f[at + 1], grid_f[at + ncol], grid_f[at + ncol + 1]
        slope_u, slope_v = h11 - h01, h01 - h00  # the triangle (r, c), (r + 1, c), (r + 1, c + 1)
        if v < u:  # the triangle (r, c), (r, c + 1), (r + 1, c + 1)
            slope_u, slope_v = h10 - h00, h11 - h10
        up = ti.Vector([-slope_u / dx, -slope_v / dy, 1.0])
        n = up / up.norm()
        d = (p[2] - (h00 + slope_u * u + slope_v * v)) * n[2]
    return d, n


@ti.func
def _hull_distance(grid_f: ti.template(), first, count, p):
    """(d, n) of the point p (3,) in a convex hull's frame: the largest of its ``count`` face planes'
    signed distances (those from grid_f[first]) and that face's normal (the first of ties)."""
    n = ti.Vector([grid_f[first], grid_f[first + 1], grid_f[first + 2]])
    d = n.dot(p) + grid_f[first + 3]
    for f in range(1, count):
        at = first + 4 * f
        normal = ti.Vector([grid_f[at], grid_f[at + 1], grid_f[at + 2]])
        distance = normal.dot(p) + grid_f[at + 3]
        if distance > d:
            d, n = distance, normal
    return d, n


@ti.func
def coupling_at(table: ti.template(), at):
    """The column of env_in where the (μ, ς, e) of the row at table[at] start."""
    return ti.cast(table[at + COUPLING], ti.i32)


@ti.func
def coupling(table: ti.template(), at, env_in: ti.template(), e):
    """(μ, ς m, e) of the row at table[at] in env e: its rigid entity's, among env e's inputs."""
    col = coupling_at(table, at)
    return env_in[e, col], env_in[e, col + 1], env_in[e, col + 2]


@ti.func
def _contact(grid_f: ti.template(), c, x, env_in: ti.template(), e):
    """(acts, d, n, w, μ, ς, e) of collider c at the node x in env e: acts where its influence w
    passes the cutoff."""
    at = COLLIDERS_AT + c * WIDTH
    mu, softness, restitution = coupling(grid_f, at, env_in, e)
    acts, d, n, w = posed_contact(grid_f, at, _rotation(grid_f, at), _position(grid_f, at), x, softness)
    return acts, d, n, w, mu, softness, restitution


@ti.func
def reach(table: ti.template(), at, softness):
    """How far (m) from its position the shape of the row at table[at] can act with softness ς
    (m): its bounding radius and the influence's reach (twice ς ln(1 / cutoff), for round-off)."""
    return table[at + BOUND] + 2.0 * ti.static(np.log(1.0 / INFLUENCE_CUTOFF)) * ti.max(softness, 1e-10)


@ti.func
def posed_contact(table: ti.template(), at, R, pos, x, softness):
    """(acts, d m, n (3,), w) at the node x of the shape of the row at table[at] posed at pos (3,) m,
    turned by R (posed_distance), with softness ς (m): acts where its influence w passes the cutoff
    (beyond the reach, d is FAR)."""
    acts, d, n, w = 0, FAR, ti.Vector([0.0, 0.0, 1.0]), 0.0
    if (x - pos).norm() < reach(table, at, softness):
        d, n = posed_distance(table, at, R, pos, x)
        w = ti.min(ti.exp(-d / ti.max(softness, 1e-10)), 1.0)
        acts = w > INFLUENCE_CUTOFF
    return acts, d, n, w


@ti.func
def influence_adjoint(d, w, softness, g_w):
    """(∂L/∂d, ∂L/∂ς) of the influence w = min(exp(−d / max(ς, 1e-10)), 1) at distance d from
    g_w = ∂L/∂w (inside, d ≤ 0, w is 1 whatever d and ς)."""
    g_d, g_softness = 0.0, 0.0
    if d > 0.0:
        clamped = ti.max(softness, 1e-10)
        g_d = -w / clamped * g_w
        if softness > 1e-10:
            g_softness = w * d / (clamped * clamped) * g_w
    return g_d, g_softness


@ti.func
def respond(v, n, w, mu, e):
    """The node's velocity after one collider (the module's rule; v unchanged unless v·n < 0)."""
    out = v
    vn = v.dot(n)
    if vn < 0.0:
        t = v - vn * n
        T = ti.sqrt(t.dot(t) + ti.static(genesis_eps()))
        slid = t / T * ti.max(0.0, T + vn * mu)
        out = w * (slid - e * vn * n) + (1.0 - w) * v
    return out


@ti.func
def respond_adjoint(v, n, w, mu, e, g):
    """(∂L/∂v, ∂L/∂n, ∂L/∂w, ∂L/∂μ, ∂L/∂e) of respond at (v, n, w, μ, e) from g = ∂L/∂(its output)."""
    g_v, g_n, g_w, g_mu, g_e = g, ti.Vector.zero(float, 3), 0.0, 0.0, 0.0
    vn = v.dot(n)
    if vn < 0.0:
        t = v - vn * n
        T = ti.sqrt(t.dot(t) + ti.static(genesis_eps()))
        slide = ti.max(0.0, T + vn * mu)
        G = w * g
        g_e = -vn * n.dot(G)
        g_vn = -e * n.dot(G)
        g_t = ti.Vector.zero(float, 3)
        if slide > 0.0:  # slid = t (1 + μ vn / T)
            tg = t.dot(G)
            g_t = (1.0 + mu * vn / T) * G - (mu * vn * tg / (T * T * T)) * t
            g_vn += mu * tg / T
            g_mu = vn * tg / T
        g_vn -= n.dot(g_t)  # (t = v − vn n)
        g_v = (1.0 - w) * g + g_t + g_vn * n
        g_n = -e * vn * G - vn * g_t + g_vn * v
        g_w = g.dot(t / T * slide - e * vn * n - v)
    return g_v, g_n, g_w, g_mu, g_e


@ti.func
def normal_jacobian(grid_f: ti.template(), at, p, d, n):
    """∂n/∂p (3, 3) of shape_distance's normal n at the point p (3,) in the shape's frame, given its
    (d, n) there (the distance's own gradient in p is n): zero on faces and planes (a hull's, a height field's
    triangles, a box inside, a cylinder's caps), (I − n nᵀ)/r around a point, segment, edge or rim
    at distance r, the radial part (P − r̂ r̂ᵀ)/ρ where a cylinder's side is nearest (inside too)."""
    kind = ti.cast(grid_f[at], ti.i32)
    a, b = grid_f[at + 13], grid_f[at + 14]
    J = ti.Matrix.zero(float, 3, 3)
    ring = ti.Matrix([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]])  # the xy plane's projector
    # (at a centre, on a segment or on an axis the normal is shape_distance's fixed one: J stays 0)
    if kind == SPHERE and p.norm() > 0.0:
        J = (ti.Matrix.identity(float, 3) - n.outer_product(n)) / p.norm()
    elif kind == CAPSULE and d + a > 0.0:
        along = ti.Matrix.identity(float, 3)
        if -b < p[2] and p[2] < b:  # (the segment's side: the clamp follows p's height)
            along = ring
        J = (ti.Matrix.identity(float, 3) - n.outer_product(n)) / (d + a) @ along
    elif kind == CYLINDER:
        rho = ti.sqrt(p[0] * p[0] + p[1] * p[1])
        d_side, d_cap = rho - a, ti.abs(p[2]) - b
        if rho > 0.0:
            radial = ti.Vector([p[0], p[1], 0.0]) / rho
            turn = (ring - radial.outer_product(radial)) / rho  # ∂radial/∂p
            if d_side > 0.0 and d_cap > 0.0:  # the rim: n = (p − the nearest rim point) / d
                J = (ti.Matrix.identity(float, 3) - n.outer_product(n)) / d @ (ti.Matrix.identity(float, 3) - a * turn)
            elif d_side > d_cap:  # the side nearest (inside too)
                J = turn
    elif kind == BOX:
        q = ti.abs(p) - ti.Vector([a, b, grid_f[at + 15]])
        if d > 0.0:  # outside: n = side ⊙ max(q, 0) / d
            outside = ti.Matrix([[1.0 if (i == j and q[i] > 0.0) else 0.0 for j in ti.static(range(3))]
                                 for i in ti.static(range(3))])
            J = (ti.Matrix.identity(float, 3) - n.outer_product(n)) / d @ outside
    return J


@ti.func
def collide(grid_f: ti.template(), count, x, v, env_in: ti.template(), e):
    """The velocity v (3,) m/s of env e's node at x (3,) m after the ``count`` colliders, in order."""
    out = v
    for c in range(count):
        acts, _, n, w, mu, _, restitution = _contact(grid_f, c, x, env_in, e)
        if acts:
            out = respond(out, n, w, mu, restitution)
    return out


@ti.func
def collide_adjoint(grid_f: ti.template(), count, x, v, g, env_in: ti.template(), e, grad_env: ti.template(),
                    params: ti.template()):
    """∂L/∂v of ``collide`` at env e's node x whose velocity before the colliders was v, from
    g = ∂L/∂(its output): collider c's input is found by replaying colliders 0 … c − 1 (a node
    meets few). With ``params``, each collider's ∂L/∂(μ, ς, e) is added to grad_env[e] at its
    columns (not atomically: one thread an env)."""
    out = g
    for back in range(count):
        c = count - 1 - back
        acts, d, n, w, mu, softness, restitution = _contact(grid_f, c, x, env_in, e)
        if acts:
            before = v
            for k in range(c):
                acts_k, _, n_k, w_k, mu_k, _, e_k = _contact(grid_f, k, x, env_in, e)
                if acts_k:
                    before = respond(before, n_k, w_k, mu_k, e_k)
            g_v, _, g_w, g_mu, g_e = respond_adjoint(before, n, w, mu, restitution, out)
            if ti.static(params):
                _, g_softness = influence_adjoint(d, w, softness, g_w)
                col = coupling_at(grid_f, COLLIDERS_AT + c * WIDTH)
                grad_env[e, col] = grad_env[e, col] + g_mu
                grad_env[e, col + 1] = grad_env[e, col + 1] + g_softness
                grad_env[e, col + 2] = grad_env[e, col + 2] + g_e
            out = g_v
    return out
