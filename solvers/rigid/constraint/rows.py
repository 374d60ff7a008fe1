"""Constraint rows of one env's substep, as MuJoCo makes them: each contact's Jacobian in its
frame, its impedance from solimp, its reference acceleration from solref, and its regulariser
R from the approximate inverse inertia diagA (``body_invweight0`` at the initial pose, not the
true diagonal of J M⁻¹ Jᵀ).

Rows are appended in contact order from row 0; n_efc[s, e, 0] counts them. Row types are the
solver's (solver.py): ONE_SIDED for a frictionless contact or a pyramid edge, ELLIPTIC_FIRST and
ELLIPTIC_REST for an elliptic cone's block (normal first, then the tangents).

Per contact with condim c, friction μ (pair: the larger geom value), impedance d from the
distance, diagA_t = invweight_t(link 1) + invweight_t(link 2) (rotational alike):
- pyramidal (c > 1): rows J_n ± μ_k J_tk for k < c − 1, each with R = 2 μ_r² R_0, where
  R_0 = (1 − d)/d · diagA_t (1 + μ²) and μ_r = μ / √impratio (MuJoCo's regularised cone);
- elliptic: rows J_n, J_t1, ... with R_n = (1 − d)/d · diagA_t and R_t = R_n / impratio;
- aref = −B·(J q̇) − K·d·(dist − margin) on normal and pyramid rows, −B·(J q̇) on elliptic
  tangents, with K = 1/(dmax² tc² ζ²), B = 2/(dmax tc) (tc ≥ 2h) or the direct form (−k, −b).

Before the contacts come, as in MuJoCo, one row per dof with friction loss F > 0 (FRICTION_LOSS,
J = e_i, aref = −B q̇_i, bound F) and one per violated joint limit (ONE_SIDED, distance
q − lower with J = e_i, or upper − q with J = −e_i). Their R uses diagA = dof_invweight0, their
solref is (timeconst, 1) with the scene's constraint time constant, their solimp MuJoCo's
default. Their adjoint (``dof_rows_adjoint``) takes the solve's implicit gradient of each row's
aref, R and bound back to q, q̇ and the friction loss; contact rows have none yet.
"""
import taichi as ti

from ..data import CONST, accumulate
from ..kinematics import dof_count, dof_motion_at

# row types, as the solver reads them (interfaces agreed with solver.py)
UNUSED, FRICTION_LOSS, ONE_SIDED, ELLIPTIC_FIRST, ELLIPTIC_REST = range(5)

MINVAL = 1e-15  # MuJoCo's mjMINVAL: a floor on every divisor
MINMU = 1e-5  # MuJoCo's mjMINMU: a floor on friction (μ = 0 would leave a pyramid edge no regulariser)
MINIMP, MAXIMP = 0.0001, 0.9999  # MuJoCo's bounds on the impedance
DEFAULT_SOLIMP = (0.9, 0.95, 0.001, 0.5, 2.0)  # MuJoCo's (d0, dmax, width m, midpoint, power)


@ti.func
def _power(a, b):
    out = a * a
    if b == 1.0:
        out = a
    elif b != 2.0:
        out = ti.pow(a, b)
    return out


@ti.func
def impedance(solimp, dist, margin):
    """d(dist) from solimp (d0, dmax, width m, midpoint, power) (5,): d0 at dist = margin rising
    to dmax at |dist − margin| ≥ width along two power curves meeting at the midpoint."""
    d0, dmax, width, mid, power = solimp[0], solimp[1], solimp[2], solimp[3], solimp[4]
    imp = 0.5 * (d0 + dmax)
    if not (d0 == dmax or width <= MINVAL):
        x = ti.abs((dist - margin) / width)
        y = 0.0
        if x >= 1.0:
            y = 1.0
        elif x <= 0.0:
            y = 0.0
        elif power == 1.0:
            y = x
        elif x <= mid:
            y = 1.0 / _power(mid, power - 1.0) * _power(x, power)
        else:
            y = 1.0 - 1.0 / _power(1.0 - mid, power - 1.0) * _power(1.0 - x, power)
        imp = d0 + y * (dmax - d0)
    return imp


@ti.func
def _clamped_solimp(solimp):
    """solimp within MuJoCo's bounds: d0, dmax, midpoint in [1e-4, 0.9999], width ≥ 0, power ≥ 1."""
    return ti.Vector([ti.min(MAXIMP, ti.max(MINIMP, solimp[0])), ti.min(MAXIMP, ti.max(MINIMP, solimp[1])),
                      ti.max(0.0, solimp[2]), ti.min(MAXIMP, ti.max(MINIMP, solimp[3])), ti.max(1.0, solimp[4])])


@ti.func
def stiffness_damping(solref, dmax, h):
    """(K 1/s², B 1/s) of aref = −B v − K d (dist − margin): from (time constant, damping ratio)
    with the time constant at least 2h (MuJoCo's refsafe), or direct (−stiffness, −damping)."""
    k, b = -solref[0] / ti.max(MINVAL, dmax * dmax), -solref[1] / ti.max(MINVAL, dmax)
    if solref[0] > 0:
        tc = ti.max(solref[0], 2.0 * h)
        k = 1.0 / ti.max(MINVAL, dmax * dmax * tc * tc * solref[1] * solref[1])
        b = 2.0 / ti.max(MINVAL, dmax * tc)
    return k, b


@ti.func
def contact_params(d: ti.template(), e, pair):
    """(friction, solref (2,), solimp (5,)) of a geom pair in env e: the larger friction (at
    least MINMU), the average of the solrefs (their minimum in direct form) and of the solimps,
    as MuJoCo mixes two geoms of equal solmix and priority."""
    g1, g2 = d.pair_geom1[pair], d.pair_geom2[pair]
    a = ti.Vector([d.solref[e, 2 * g1], d.solref[e, 2 * g1 + 1]])
    b = ti.Vector([d.solref[e, 2 * g2], d.solref[e, 2 * g2 + 1]])
    solref = ti.min(a, b)
    if a[0] > 0 and b[0] > 0:
        solref = 0.5 * a + 0.5 * b
    solimp = ti.Vector([0.5 * d.solimp[e, 5 * g1 + k] + 0.5 * d.solimp[e, 5 * g2 + k] for k in ti.static(range(5))])
    return ti.max(MINMU, d.friction[e, g1], d.friction[e, g2]), solref, _clamped_solimp(solimp)


@ti.func
def _zero_rows(d: ti.template(), s, e, first, count):
    for r in range(first, first + count):
        for i in range(d.n_dofs):
            d.efc_J[s, e, r, i] = 0.0


@ti.func
def _add_link_jacobian(d: ti.template(), s, e, link, pos, frame, sign, first, condim, pyramidal, mu):
    """Add sign × (link's point Jacobian at pos, in the contact frame) into the contact's rows
    first…: every dof on the link's path to the root moves the point by cdof_v + cdof_w × pos."""
    a = link
    while a >= 0:
        dof0 = d.link_dof0[a]
        for i in range(dof0, dof0 + dof_count(d, a)):
            linear, _ = dof_motion_at(d, s, e, i, pos)
            v = frame @ linear
            if condim == 1:
                d.efc_J[s, e, first, i] += sign * v[0]
            elif pyramidal:
                for k in ti.static(range(2)):  # condim 3: two tangents
                    d.efc_J[s, e, first + 2 * k, i] += sign * (v[0] + mu * v[k + 1])
                    d.efc_J[s, e, first + 2 * k + 1, i] += sign * (v[0] - mu * v[k + 1])
            else:
                for k in ti.static(range(3)):
                    d.efc_J[s, e, first + k, i] += sign * v[k]
        a = d.link_parent[a]


@ti.func
def rows_per_contact(d: ti.template(), condim):
    n = condim
    if condim > 1 and not d.elliptic:
        n = 2 * (condim - 1)
    return n


@ti.func
def contact_rows(d: ti.template(), s, e, c, first):
    """Rows first… of contact c at frame s: Jacobian, R, aref, type. Returns how many rows."""
    pair = d.con_pair[s, e, c]
    condim = d.pair_condim[pair]
    pyramidal = not d.elliptic
    n = rows_per_contact(d, condim)
    mu, solref, solimp = contact_params(d, e, pair)
    frame, pos = d.con_frame[s, e, c], d.con_pos[s, e, c]
    l1, l2 = d.geom_link[d.pair_geom1[pair]], d.geom_link[d.pair_geom2[pair]]
    _zero_rows(d, s, e, first, n)
    _add_link_jacobian(d, s, e, l1, pos, frame, -1.0, first, condim, pyramidal, mu)
    _add_link_jacobian(d, s, e, l2, pos, frame, 1.0, first, condim, pyramidal, mu)
    tran = d.link_invweight_t[l1] + d.link_invweight_t[l2]
    dist, margin = d.con_dist[s, e, c], d.pair_margin[pair]
    imp = impedance(solimp, dist, margin)
    k, b = stiffness_damping(solref, solimp[1], d.consts[CONST["h"]])
    impratio = d.consts[CONST["impratio"]]
    r0 = ti.max(MINVAL, (1.0 - imp) * (tran + mu * mu * tran if condim > 1 and pyramidal else tran) / imp)
    r1 = r0 / ti.max(MINVAL, impratio)
    mu_reg = mu * ti.sqrt(r1 / r0)
    for j in range(n):
        r = first + j
        velocity = 0.0
        for i in range(d.n_dofs):
            velocity += d.efc_J[s, e, r, i] * d.qvel[s, e, i]
        kind, reg, aref = ONE_SIDED, r0, -b * velocity - k * imp * (dist - margin)
        if condim > 1 and pyramidal:
            reg = 2.0 * mu_reg * mu_reg * r0
        elif condim > 1:
            kind = ELLIPTIC_FIRST if j == 0 else ELLIPTIC_REST
            if j > 0:  # tangent rows: no position term, R_t = R_n / impratio
                reg, aref = r1, -b * velocity
        d.efc_type[s, e, r], d.efc_R[s, e, r], d.efc_aref[s, e, r] = kind, reg, aref
        d.efc_dim[s, e, r], d.efc_id[s, e, r], d.efc_floss[s, e, r] = condim, c, 0.0
        d.efc_mu[s, e, r] = mu_reg if j == 0 else mu
    return n


@ti.func
def contact_force(d: ti.template(), s, e, c):
    """Force of contact c on its second geom in the contact frame (normal, tangent 1, tangent 2;
    N) from its rows' solved forces: a pyramid's normal force is the sum of its edges', its
    friction along tangent k the difference of edge pair k's times μ (MuJoCo's mj_contactForce)."""
    first = d.con_efc[s, e, c]
    condim = d.pair_condim[d.con_pair[s, e, c]]
    out = ti.Vector([d.efc_force[s, e, first], 0.0, 0.0])
    if condim > 1:
        if d.elliptic:
            out = ti.Vector([d.efc_force[s, e, first + k] for k in ti.static(range(3))])
        else:
            mu = d.efc_mu[s, e, first + 1]
            out = ti.Vector.zero(float, 3)
            for k in ti.static(range(2)):
                plus, minus = d.efc_force[s, e, first + 2 * k], d.efc_force[s, e, first + 2 * k + 1]
                out[0] += plus + minus
                out[k + 1] = (plus - minus) * mu
    return out


# -- rows of single dofs: friction loss and joint limits --------------------------------------------
@ti.func
def _dof_row(d: ti.template(), s, e, r, i, sign, dist):
    """Row r on dof i alone (J = sign·e_i) at distance dist (m or rad; 0 for friction loss): its
    Jacobian, R and aref, with the scene's time constant and MuJoCo's default solimp."""
    for j in range(d.n_dofs):
        d.efc_J[s, e, r, j] = 0.0
    d.efc_J[s, e, r, i] = sign
    solimp = ti.Vector(DEFAULT_SOLIMP, dt=float)
    imp = impedance(solimp, dist, 0.0)
    k, b = stiffness_damping(ti.Vector([d.consts[CONST["timeconst"]], 1.0]), solimp[1], d.consts[CONST["h"]])
    d.efc_R[s, e, r] = ti.max(MINVAL, (1.0 - imp) / imp * d.dof_invweight0[i])
    d.efc_aref[s, e, r] = -b * sign * d.qvel[s, e, i] - k * imp * dist
    d.efc_dim[s, e, r], d.efc_id[s, e, r], d.efc_mu[s, e, r] = 1, i, 0.0


@ti.func
def _limit_side(d: ti.template(), s, e, i):
    """(sign, distance) of dof i's violated joint limit at frame s: (1, q − lower) below it,
    (−1, upper − q) above it, (0, 0) within or without limits (no row)."""
    sign, dist = 0.0, 0.0
    qi = d.dof_q[i]
    if d.limits_enabled and qi >= 0:
        q = d.qpos[s, e, qi]
        if q - d.dof_lower[i] < 0.0:
            sign, dist = 1.0, q - d.dof_lower[i]
        elif d.dof_upper[i] - q < 0.0:
            sign, dist = -1.0, d.dof_upper[i] - q
    return sign, dist


@ti.func
def limit_violated(d: ti.template(), s, e):
    """1 if some joint limit of env e is violated at frame s (a limit row would arise), else 0."""
    violated = 0
    if d.limits_enabled:
        for i in range(d.n_dofs):
            sign, _ = _limit_side(d, s, e, i)
            if sign != 0.0:
                violated = 1
    return violated


@ti.func
def dof_rows(d: ti.template(), s, e):
    """Rows 0… of frame s: friction loss of every dof with F > 0, then every violated joint
    limit. Returns how many (also kept in efc_dof_rows[s, e, 0])."""
    rows = 0
    for i in range(d.n_dofs):
        bound = d.frictionloss[e, i]
        if bound > 0.0:
            _dof_row(d, s, e, rows, i, 1.0, 0.0)
            d.efc_type[s, e, rows], d.efc_floss[s, e, rows] = FRICTION_LOSS, bound
            rows += 1
    for i in range(d.n_dofs):
        sign, dist = _limit_side(d, s, e, i)
        if sign != 0.0:
            _dof_row(d, s, e, rows, i, sign, dist)
            d.efc_type[s, e, rows], d.efc_floss[s, e, rows] = ONE_SIDED, 0.0
            rows += 1
    d.efc_dof_rows[s, e, 0] = rows
    return rows


@ti.func
def _impedance_slope(solimp, dist, margin):
    """∂impedance/∂dist (1/m) of ``impedance``: zero outside |dist − margin| < width."""
    d0, dmax, width, mid, power = solimp[0], solimp[1], solimp[2], solimp[3], solimp[4]
    slope = 0.0
    if not (d0 == dmax or width <= MINVAL):
        x = ti.abs((dist - margin) / width)
        dy = 0.0
        if 0.0 < x and x < 1.0:
            if power == 1.0:
                dy = 1.0
            elif x <= mid:
                dy = power / _power(mid, power - 1.0) * _power(x, power - 1.0)
            else:
                dy = power / _power(1.0 - mid, power - 1.0) * _power(1.0 - x, power - 1.0)
        slope = (dmax - d0) * dy / width * (1.0 if dist - margin > 0.0 else -1.0)
    return slope


@ti.func
def dof_rows_adjoint(d: ti.template(), s, e, r, g_aref, g_R, g_bound):
    """Reverse of ``_dof_row`` for row r (< efc_dof_rows) given the gradients of its aref, R and
    friction-loss bound: into q, q̇ at frame s and the friction-loss input."""
    i = d.efc_id[s, e, r]
    sign = d.efc_J[s, e, r, i]
    solimp = ti.Vector(DEFAULT_SOLIMP, dt=float)
    k, b = stiffness_damping(ti.Vector([d.consts[CONST["timeconst"]], 1.0]), solimp[1], d.consts[CONST["h"]])
    accumulate(d.qvel.grad, ti.Vector([s, e, i]), -b * sign * g_aref)
    if d.efc_type[s, e, r] == FRICTION_LOSS:
        accumulate(d.frictionloss.grad, ti.Vector([e, i]), g_bound)
    else:  # a limit: aref and R depend on the distance
        _, dist = _limit_side(d, s, e, i)
        imp, slope = impedance(solimp, dist, 0.0), _impedance_slope(solimp, dist, 0.0)
        g_imp = -k * dist * g_aref
        if (1.0 - imp) / imp * d.dof_invweight0[i] > MINVAL:  # else R is its floor
            g_imp -= d.dof_invweight0[i] / (imp * imp) * g_R
        g_dist = -k * imp * g_aref + slope * g_imp
        accumulate(d.qpos.grad, ti.Vector([s, e, d.dof_q[i]]), sign * g_dist)
