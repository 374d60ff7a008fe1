"""Constraint rows of one env's substep, as MuJoCo makes them: each contact's Jacobian in its
frame, its impedance from solimp, its reference acceleration from solref, and its regulariser
R from the approximate inverse inertia diagA (``body_invweight0`` at the initial pose, not the
true diagonal of J M⁻¹ Jᵀ; per env, from the mass and armature inputs: the inputs invweight_t
and invweight_dof, contact.InvweightBasis).

Rows are appended in contact order from row 0; n_efc[s, e, 0] counts them. Row types are the
solver's (solver.py): ONE_SIDED for a frictionless contact or a pyramid edge, ELLIPTIC_FIRST and
ELLIPTIC_REST for an elliptic cone's block (normal first, then the tangents).

Per contact with condim c (1 normal; 3 and two sliding tangents; 4 and a torsional direction,
the turn about the normal; 6 and two rolling directions, the turns about the tangents: MuJoCo's
directions, in which J_k is the contact frame's row k of the linear Jacobian for k < 3 and of
the angular one after), friction μ_k of direction k (sliding μ, torsional, rolling: its geoms'
combined, contact_params), impedance d from the distance, diagA_t = invweight_t(link 1) +
invweight_t(link 2) (rotational alike):
- pyramidal (c > 1): rows J_n ± μ_k J_k for the c − 1 directions k after the normal, each with R =
  2 μ_r² R_0, where R_0 = (1 − d)/d · diagA_t (1 + μ²) and μ_r = μ / √impratio (MuJoCo's
  regularised cone);
- elliptic: rows J_n, J_1, ... with R_n = (1 − d)/d · diagA_t and R_k = R_n / impratio · μ² / μ_k²;
- aref = −B·(J q̇) − K·d·(dist − margin) on normal and pyramid rows, −B·(J q̇) on elliptic
  tangents, with K = 1/(dmax² tc² ζ²), B = 2/(dmax tc) (tc ≥ 2h) or the direct form (−k, −b).

Before the contacts come, as in MuJoCo, the joint rows: one per joint equality (EQUALITY, always
in its quadratic: a URDF mimic, distance q_a − offset − multiplier · q_b with J = e_a −
multiplier · e_b, diagA the sum of the two dofs'), one per dof with friction loss F > 0
(FRICTION_LOSS, J = e_i, aref = −B q̇_i, bound F) and one per violated joint limit (ONE_SIDED,
distance q − lower with J = e_i, or upper − q with J = −e_i; a ball joint's cone limit, MuJoCo's:
distance θmax − θ with J = −axis on its three dofs, θ and axis its turn's angle and unit axis),
then one per violated limit of a fixed tendon (its length L = Σ coef·q: L − lower with J = coef
on its dofs, or upper − L with J = −coef; diagA its invweight_ten, MuJoCo's tendon_invweight0);
a tendon's friction loss (FRICTION_LOSS, J = coef) comes after the dofs'.
Their R uses diagA = dof_invweight0 (a ball joint's first dof's); their solref and solimp are
the model's per row owner (dof_limit_sol, dof_frictionloss_sol, eq_sol: MJCF's solreflimit,
solimplimit, solreffriction, solimpfriction, an equality's solref and solimp; else the scene's
(timeconst, 1) with its constraint time constant and MuJoCo's default solimp).
Their adjoint (``dof_rows_adjoint``) takes the solve's implicit gradient of each row's
aref, R and bound back to q, q̇, the friction loss and dof_invweight0 (``contact_rows_adjoint``
likewise for contact rows, into body_invweight0 among others).
"""
import taichi as ti

from ..data import BIG, CONST, DYN_WELD, JOINT_ROW_SLOTS, accumulate
from ..kinematics import dof_count, dof_motion_at, joint_quat, reference, tendon_length
from ..model import BALL
from ..spec import TENDON_JOINTS
from ..spatial import quat_conj, quat_mul, quat_to_mat, quat_turn, quat_turn_adjoint

# row types, as the solver reads them (interfaces agreed with solver.py)
UNUSED, FRICTION_LOSS, ONE_SIDED, ELLIPTIC_FIRST, ELLIPTIC_REST, EQUALITY = range(6)

MINVAL = 1e-15  # MuJoCo's mjMINVAL: a floor on every divisor
MINMU = 1e-5  # MuJoCo's mjMINMU: a floor on friction (μ = 0 would leave a pyramid edge no regulariser)
MINIMP, MAXIMP = 0.0001, 0.9999  # MuJoCo's bounds on the impedance
DEFAULT_SOLIMP = (0.9, 0.95, 0.001, 0.5, 2.0)  # MuJoCo's (d0, dmax, width m, midpoint, power)
# RigidOptions(smooth_contact=True)'s: the impedance starts at 0 at contact onset (d0 = 0, clamped to
# MINIMP as MuJoCo does), so the contact force grows from zero with depth instead of jumping
SMOOTH_SOLIMP = (0.0, 0.95, 0.001, 0.5, 2.0)


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
    """(friction (3,): sliding, torsional m, rolling m; solref (2,), solimp (5,)) of a geom pair in
    env e, as MuJoCo's mj_contactParam combines its geoms' (each friction at least MINMU): with w
    the pair's mix (geom1's weight), the solimps mixed, w·solimp₁ + (1 − w)·solimp₂; where the
    priorities differ (pair_copy, w 1 or 0) the friction and solref of the higher one too; else
    the larger friction of each kind and the solrefs mixed (their minimum in direct form)."""
    g1, g2, w, copy = d.pair_geom1[pair], d.pair_geom2[pair], d.pair_mix[pair], d.pair_copy[pair]
    a = ti.Vector([d.solref[e, 2 * g1], d.solref[e, 2 * g1 + 1]])
    b = ti.Vector([d.solref[e, 2 * g2], d.solref[e, 2 * g2 + 1]])
    solref = ti.min(a, b)
    if copy or (a[0] > 0 and b[0] > 0):
        solref = w * a + (1.0 - w) * b
    solimp = ti.Vector([w * d.solimp[e, 5 * g1 + k] + (1.0 - w) * d.solimp[e, 5 * g2 + k]
                        for k in ti.static(range(5))])
    friction = ti.Vector([MINMU, MINMU, MINMU])
    for k in ti.static(range(3 if d.max_condim > 3 else 1)):  # (the sliding one alone where no row takes the rest)
        f1, f2 = d.friction[e, 3 * g1 + k], d.friction[e, 3 * g2 + k]
        friction[k] = ti.max(MINMU, w * f1 + (1.0 - w) * f2 if copy else ti.max(f1, f2))
    return friction, solref, _clamped_solimp(solimp)


@ti.func
def direction_friction(friction, k):
    """μ_k of contact direction k after the normal (0, 1 sliding; 2 torsional; 3, 4 rolling) from
    the pair's friction (3,) (contact_params)."""
    return friction[0] if k < 2 else (friction[1] if k == 2 else friction[2])


@ti.func
def _zero_rows(d: ti.template(), s, e, base, first, count, ncol):
    """Rows first… (count) ← 0 in their ncol columns (efc_cols[base …]). No reader looks
    past a row's columns, so the rest of the row is left as it was (zeroing whole rows cost
    rows × dofs a substep: 86k stores with 60 boxes on a plane)."""
    for r in range(first, first + count):
        for a in range(ncol):
            d.efc_J[s, e, r, d.efc_cols[s, e, base + a]] = 0.0


@ti.func
def _add_link_jacobian(d: ti.template(), s, e, link, pos, frame, sign, first, condim, pyramidal, friction):
    """Add sign × (link's Jacobian at pos in the contact's directions) into the contact's rows
    first…: every dof on the link's path to the root moves the point by cdof_v + cdof_w × (pos −
    reference) and turns it by cdof_w (kinematics.dof_motion_at); the directions are the frame's
    rows, of the linear motion then (condim > 3) of the angular one."""
    a = link
    while a >= 0:
        dof0 = d.link_dof0[a]
        for i in range(dof0, dof0 + dof_count(d, a)):
            linear, angular = dof_motion_at(d, s, e, i, pos)
            v = _directions(d, frame, linear, angular, condim)
            if condim == 1:
                accumulate(d.efc_J, ti.Vector([s, e, first, i]), sign * v[0])
            elif pyramidal:
                for k in ti.static(range(d.max_condim - 1)):  # edge pair k: J_n ± μ_k J_k
                    if k < condim - 1:
                        mu_k = direction_friction(friction, k)
                        accumulate(d.efc_J, ti.Vector([s, e, first + 2 * k, i]), sign * (v[0] + mu_k * v[k + 1]))
                        accumulate(d.efc_J, ti.Vector([s, e, first + 2 * k + 1, i]), sign * (v[0] - mu_k * v[k + 1]))
            else:
                for k in ti.static(range(d.max_condim)):
                    if k < condim:
                        accumulate(d.efc_J, ti.Vector([s, e, first + k, i]), sign * v[k])
        a = d.link_parent[a]


@ti.func
def _directions(d: ti.template(), frame, linear, angular, condim):
    """(6,) a motion's components along the contact's directions: frame @ linear, then (condim >
    3; else zeros) frame @ angular."""
    v, w = frame @ linear, ti.Vector.zero(float, 3)
    if ti.static(d.max_condim > 3):
        if condim > 3:
            w = frame @ angular
    return ti.Vector([v[0], v[1], v[2], w[0], w[1], w[2]])


@ti.func
def rows_per_contact(d: ti.template(), condim):
    n = condim
    if condim > 1 and not d.elliptic:
        n = 2 * (condim - 1)
    return n


@ti.func
def _contact_scalars(d: ti.template(), s, e, c):
    """What contact c's rows are made of besides its Jacobian: (condim, friction (3,) (sliding μ,
    torsional, rolling), solref, solimp, impedance, K, B, R_0, R_1, μ_reg, diagA_t): R_0 = (1 −
    d)/d · diagA_t (times 1 + μ² on a pyramid), R_1 = R_0 / impratio, μ_reg = μ √(R_1/R_0)."""
    pair = d.con_pair[s, e, c]
    condim = d.pair_condim[pair]
    friction, solref, solimp = contact_params(d, e, pair)
    mu = friction[0]
    l1, l2 = d.geom_link[d.pair_geom1[pair]], d.geom_link[d.pair_geom2[pair]]
    tran = d.invweight_t[e, l1] + d.invweight_t[e, l2]
    imp = impedance(solimp, d.con_dist[s, e, c], d.pair_margin[pair])
    k, b = stiffness_damping(solref, solimp[1], d.consts[CONST["h"]])
    r0 = ti.max(MINVAL, (1.0 - imp) * (tran + mu * mu * tran if condim > 1 and not d.elliptic else tran) / imp)
    r1 = r0 / ti.max(MINVAL, d.consts[CONST["impratio"]])
    return condim, friction, solref, solimp, imp, k, b, r0, r1, mu * ti.sqrt(r1 / r0), tran


@ti.func
def contact_included(d: ti.template(), s, e, c):
    """Whether contact c of frame s makes rows: as MuJoCo (its exclude flag), only below its pair's
    margin. A contact exactly at it (a body placed exactly on a plane) is listed, pushes nothing."""
    return d.con_dist[s, e, c] < d.pair_margin[d.con_pair[s, e, c]]


@ti.func
def contact_rows(d: ti.template(), s, e, c, first):
    """Rows first… of contact c at frame s: Jacobian, R, aref, type. Returns how many rows."""
    pair = d.con_pair[s, e, c]
    pyramidal = not d.elliptic
    condim, friction, _solref, _solimp, imp, k, b, r0, r1, mu_reg, _tran = _contact_scalars(d, s, e, c)
    mu = friction[0]
    n = rows_per_contact(d, condim)
    frame, pos = d.con_frame[s, e, c], d.con_pos[s, e, c]
    l1, l2 = d.geom_link[d.pair_geom1[pair]], d.geom_link[d.pair_geom2[pair]]
    ncol = _path_columns(d, s, e, c * d.n_dofs, l1, l2)
    _zero_rows(d, s, e, c * d.n_dofs, first, n, ncol)
    _add_link_jacobian(d, s, e, l1, pos, frame, -1.0, first, condim, pyramidal, friction)
    _add_link_jacobian(d, s, e, l2, pos, frame, 1.0, first, condim, pyramidal, friction)
    dist, margin = d.con_dist[s, e, c], d.pair_margin[pair]
    for j in range(n):
        r = first + j
        d.efc_col0[s, e, r], d.efc_ncol[s, e, r] = c * d.n_dofs, ncol
        velocity = row_times(d, s, e, r, d.qvel)
        kind, reg, aref = ONE_SIDED, r0, -b * velocity - k * imp * (dist - margin)
        mu_row = mu_reg  # efc_mu: the normal row's μ_reg; a pyramid edge's, an elliptic row's μ_k
        if condim > 1 and pyramidal:
            reg = 2.0 * mu_reg * mu_reg * r0
            if j > 0:
                mu_row = direction_friction(friction, j // 2)
        elif condim > 1:
            kind = ELLIPTIC_FIRST if j == 0 else ELLIPTIC_REST
            if j > 0:  # the other directions: no position term, R_k = R_1 μ² / μ_k²
                mu_row = direction_friction(friction, j - 1)
                reg, aref = r1 * mu * mu / (mu_row * mu_row), -b * velocity
        d.efc_type[s, e, r], d.efc_R[s, e, r], d.efc_aref[s, e, r] = kind, reg, aref
        d.efc_dim[s, e, r], d.efc_id[s, e, r], d.efc_floss[s, e, r] = condim, c, 0.0
        d.efc_mu[s, e, r] = mu_row
    return n


@ti.func
def _path_columns(d: ti.template(), s, e, base, l1, l2):
    """The columns where rows between links l1 and l2 (-1: the world) can be non-zero (the dofs on
    their paths to the root: MuJoCo's sparse Jacobian), ascending, into efc_cols[s, e, base …].
    Returns their count. The two paths are walked together, the larger link first (a parent comes before
    its children, and a link's dofs after its parent's), which lists the dofs descending; then
    the list is reversed."""
    n = 0
    a, b = l1, l2
    while a >= 0 or b >= 0:
        link = ti.max(a, b)
        dof0 = d.link_dof0[link]
        count = dof_count(d, link)
        for k in range(count):
            d.efc_cols[s, e, base + n + k] = dof0 + count - 1 - k
        n += count
        if a == link:
            a = d.link_parent[a]
        if b == link:
            b = d.link_parent[b]
    for k in range(n // 2):
        lo, hi = d.efc_cols[s, e, base + k], d.efc_cols[s, e, base + n - 1 - k]
        d.efc_cols[s, e, base + k], d.efc_cols[s, e, base + n - 1 - k] = hi, lo
    return n


@ti.func
def row_times(d: ti.template(), s, e, r, x: ti.template()):
    """J_r · x[s, e] (x (D,) a frame array: q̇ gives the row's velocity, m/s or rad/s), over the
    row's non-zero columns."""
    out = 0.0
    col0 = d.efc_col0[s, e, r]
    for a in range(d.efc_ncol[s, e, r]):
        i = d.efc_cols[s, e, col0 + a]
        out += d.efc_J[s, e, r, i] * x[s, e, i]
    return out


# -- reverse of a contact's rows ---------------------------------------------------------------------
@ti.func
def impedance_gradient(solimp, dist, margin):
    """(∂d/∂dist 1/m, ∂d/∂solimp (5,)) of ``impedance``: d = d0 + y(x) (dmax − d0), x = |dist −
    margin| / width, y the two power curves (y = x^p / mid^(p−1) up to the midpoint, 1 − (1 −
    x)^p / (1 − mid)^(p−1) after it); y is flat outside 0 < x < 1."""
    d0, dmax, width, mid, power = solimp[0], solimp[1], solimp[2], solimp[3], solimp[4]
    g_dist, g_solimp = 0.0, ti.Vector([0.5, 0.5, 0.0, 0.0, 0.0], dt=float)
    if not (d0 == dmax or width <= MINVAL):
        x = ti.abs((dist - margin) / width)
        y, dy, dy_mid, dy_power = 0.0, 0.0, 0.0, 0.0  # y and its partials in x, mid and power
        if x >= 1.0:
            y = 1.0
        elif x > 0.0:
            if x <= mid:
                y = _power(x, power) / _power(mid, power - 1.0)
                dy = power * _power(x, power - 1.0) / _power(mid, power - 1.0)
                dy_mid, dy_power = -(power - 1.0) * y / mid, y * (ti.log(x) - ti.log(mid))
            else:
                rest = _power(1.0 - x, power) / _power(1.0 - mid, power - 1.0)  # 1 − y
                y = 1.0 - rest
                dy = power * _power(1.0 - x, power - 1.0) / _power(1.0 - mid, power - 1.0)
                dy_mid = -(power - 1.0) * rest / (1.0 - mid)
                dy_power = -rest * (ti.log(1.0 - x) - ti.log(1.0 - mid))
        span = dmax - d0
        g_dist = span * dy / width * (1.0 if dist - margin > 0.0 else -1.0)
        g_solimp = ti.Vector([1.0 - y, y, -span * dy * x / width, span * dy_mid, span * dy_power])
    return g_dist, g_solimp


@ti.func
def _stiffness_damping_adjoint(solref, dmax, h, g_k, g_b):
    """Reverse of ``stiffness_damping``: (∂L/∂solref (2,), ∂L/∂dmax) from ∂L/∂K and ∂L/∂B (a
    floored divisor, or the time constant held at 2h, passes nothing). A time constant exactly at
    2h (the default 0.01 s with dt 0.01 and two substeps, MuJoCo's 0.02 s with one) passes half:
    the map's kink, whose one-sided derivatives are the full one and zero; half is what central
    differences converge to (as the friction ties of _contact_params_adjoint)."""
    g_solref, g_dmax = ti.Vector.zero(float, 2), 0.0
    k, b = stiffness_damping(solref, dmax, h)
    if solref[0] > 0:
        tc, ratio = ti.max(solref[0], 2.0 * h), solref[1]
        through_tc = 1.0 if solref[0] > 2.0 * h else 0.5 if solref[0] == 2.0 * h else 0.0
        if dmax * dmax * tc * tc * ratio * ratio > MINVAL:  # K = 1/(dmax tc ζ)²
            g_dmax -= 2.0 * k / dmax * g_k
            g_solref[1] -= 2.0 * k / ratio * g_k
            g_solref[0] -= through_tc * 2.0 * k / tc * g_k
        if dmax * tc > MINVAL:  # B = 2/(dmax tc)
            g_dmax -= b / dmax * g_b
            g_solref[0] -= through_tc * b / tc * g_b
    else:  # direct: K = −solref₀/dmax², B = −solref₁/dmax
        if dmax * dmax > MINVAL:
            g_solref[0] -= g_k / (dmax * dmax)
            g_dmax -= 2.0 * k / dmax * g_k
        if dmax > MINVAL:
            g_solref[1] -= g_b / dmax
            g_dmax -= b / dmax * g_b
    return g_solref, g_dmax


@ti.func
def _to_extreme(grad: ti.template(), e, i, j, a, b, g):
    """grad[e, i] or grad[e, j] += g: to the larger of the values a (at i) and b (at j), half to
    each where they tie (see _contact_params_adjoint)."""
    if a == b:
        accumulate(grad, ti.Vector([e, i]), 0.5 * g)
        accumulate(grad, ti.Vector([e, j]), 0.5 * g)
    else:
        accumulate(grad, ti.Vector([e, i if a > b else j]), g)


@ti.func
def _contact_params_adjoint(d: ti.template(), e, pair, g_friction, g_solref, g_solimp):
    """Reverse of ``contact_params``: the pair's friction (3,), solref and (clamped) solimp
    gradients onto its geoms' inputs in env e (each friction: the geom whose value the pair took,
    unless the floor MINMU won).
    Where the larger of two geoms' values is taken and they tie (both at the default friction,
    say), it follows either geom's upward and neither's downward: each gets half, the derivative
    that central differences converge to (all to one geom left the other's zero: a body's
    friction fitted against a plane at the same default never moved)."""
    g1, g2, w, copy = d.pair_geom1[pair], d.pair_geom2[pair], d.pair_mix[pair], d.pair_copy[pair]
    for k in ti.static(range(3 if d.max_condim > 3 else 1)):
        f1, f2 = d.friction[e, 3 * g1 + k], d.friction[e, 3 * g2 + k]
        if copy:
            if w * f1 + (1.0 - w) * f2 > MINMU:
                _to_mix(d.friction.grad, e, 3 * g1 + k, 3 * g2 + k, w, g_friction[k])
        elif ti.max(f1, f2) > MINMU:
            _to_extreme(d.friction.grad, e, 3 * g1 + k, 3 * g2 + k, f1, f2, g_friction[k])
    a0, b0 = d.solref[e, 2 * g1], d.solref[e, 2 * g2]
    for k in ti.static(range(2)):
        a, b = d.solref[e, 2 * g1 + k], d.solref[e, 2 * g2 + k]
        if copy or (a0 > 0 and b0 > 0):  # mixed
            _to_mix(d.solref.grad, e, 2 * g1 + k, 2 * g2 + k, w, g_solref[k])
        else:  # the smaller
            _to_extreme(d.solref.grad, e, 2 * g1 + k, 2 * g2 + k, -a, -b, g_solref[k])
    lower = ti.Vector([MINIMP, MINIMP, 0.0, MINIMP, 1.0])
    upper = ti.Vector([MAXIMP, MAXIMP, BIG, MAXIMP, BIG])
    for k in ti.static(range(5)):
        mixed = w * d.solimp[e, 5 * g1 + k] + (1.0 - w) * d.solimp[e, 5 * g2 + k]
        if lower[k] <= mixed and mixed <= upper[k]:  # else clamped
            _to_mix(d.solimp.grad, e, 5 * g1 + k, 5 * g2 + k, w, g_solimp[k])


@ti.func
def _to_mix(grad: ti.template(), e, i, j, w, g):
    """grad[e, i] += w·g and grad[e, j] += (1 − w)·g: the reverse of w·a + (1 − w)·b."""
    accumulate(grad, ti.Vector([e, i]), w * g)
    accumulate(grad, ti.Vector([e, j]), (1.0 - w) * g)


@ti.func
def _frame_coefficients(d: ti.template(), n, condim, friction, by_row):
    """Σ_rows c_rk by_row[r] per contact direction k (6,: normal, tangents, then the turns about
    them: _directions), where row r's Jacobian is Σ_k c_rk J_k: one row (condim 1), the pyramid's
    edges J_n ± μ_k J_k, or the elliptic rows J_k."""
    out = ti.Vector.zero(float, 6)
    if n == 1 or d.elliptic:
        for j in ti.static(range(d.max_condim)):
            out[j] = by_row[j] if j < n else 0.0
    else:
        for k in ti.static(range(d.max_condim - 1)):
            if k < condim - 1:
                plus, minus = by_row[2 * k], by_row[2 * k + 1]
                out[0] += plus + minus
                out[k + 1] = direction_friction(friction, k) * (plus - minus)
    return out


@ti.func
def _jacobian_adjoint(d: ti.template(), s, e, frame, pos, link, sign, g_u, g_w, b, condim):
    """Reverse of one link's share of rows in ``frame`` (3, 3) at point ``pos`` (3,) m
    (``_add_link_jacobian``): with J̄_k = g_u[k] u − g_w[k] w̃ per contact direction k (6,; u =
    H⁻¹ā, w̃ = qacc + B q̇; see contact_rows_adjoint), into cdof_v, cdof_w and q̇ (aref's velocity
    term −B J q̇) at frame s. Returns (∂L/∂frame (3, 3), ∂L/∂pos (3,), Σ_i J_k,i u_i (6,), Σ_i
    J_k,i w̃_i (6,))."""
    g_frame, g_pos = ti.Matrix.zero(float, 3, 3), ti.Vector.zero(float, 3)
    j_u, j_w = ti.Vector.zero(float, 6), ti.Vector.zero(float, 6)
    a = link
    while a >= 0:
        dof0 = d.link_dof0[a]
        for i in range(dof0, dof0 + dof_count(d, a)):
            linear, angular = dof_motion_at(d, s, e, i, pos)
            u, w = d.solver_Mgrad[s, e, i], d.qacc_constrained[s, e, i] + b * d.qvel[s, e, i]
            g_rows = sign * (g_u * u - g_w * w)  # ∂L/∂(J_k,i) per direction k
            g_linear_rows = ti.Vector([g_rows[0], g_rows[1], g_rows[2]])  # ∂L/∂(frame @ linear)
            g_frame += g_linear_rows.outer_product(linear)
            g_linear = frame.transpose() @ g_linear_rows
            arm = pos - reference(d, s, e, a)  # (the reference is a constant of the reverse: kinematics.py)
            g_angular = arm.cross(g_linear)
            if ti.static(d.max_condim > 3):
                if condim > 3:  # ∂L/∂(frame @ angular)
                    g_angular_rows = ti.Vector([g_rows[3], g_rows[4], g_rows[5]])
                    g_frame += g_angular_rows.outer_product(angular)
                    g_angular += frame.transpose() @ g_angular_rows
            accumulate(d.cdof_v.grad, ti.Vector([s, e, i]), g_linear)
            accumulate(d.cdof_w.grad, ti.Vector([s, e, i]), g_angular)
            g_pos += g_linear.cross(angular)
            along = sign * _directions(d, frame, linear, angular, condim)  # J_k,i
            accumulate(d.qvel.grad, ti.Vector([s, e, i]), -b * g_w.dot(along))
            j_u += along * u
            j_w += along * w
        a = d.link_parent[a]
    return g_frame, g_pos, j_u, j_w


@ti.func
def _linear_only(g):
    """(6,) per-direction coefficients of _jacobian_adjoint from the linear directions' g (3,)."""
    return ti.Vector([g[0], g[1], g[2], 0.0, 0.0, 0.0])


@ti.func
def contact_rows_adjoint(d: ti.template(), s, e, c, force, g_aref, g_R, g_mu):
    """Reverse of ``contact_rows`` for contact c at frame s, from its rows' solved forces f_j and
    the solve's implicit gradients of their aref, R and efc_mu (each (d.row_slots,), rows past
    the contact's unused), with u = H⁻¹ā in solver_Mgrad. The Jacobian's gradient is J̄_j =
    f_j u − āref_j (qacc + B q̇) (the solve's stationarity, and aref's −B J q̇). Into: con_pos,
    con_frame and con_dist's gradients (the collider's reverse takes them on), cdof and q̇ at frame
    s, and the friction, solref and solimp inputs."""
    pair = d.con_pair[s, e, c]
    condim, friction, solref, solimp, imp, k, b, r0, r1, mu_reg, tran = _contact_scalars(d, s, e, c)
    mu = friction[0]
    n = rows_per_contact(d, condim)
    pyramid = condim > 1 and not d.elliptic
    g_u = _frame_coefficients(d, n, condim, friction, force)
    g_w = _frame_coefficients(d, n, condim, friction, g_aref)
    l1, l2 = d.geom_link[d.pair_geom1[pair]], d.geom_link[d.pair_geom2[pair]]
    frame, pos = d.con_frame[s, e, c], d.con_pos[s, e, c]
    f1, p1, u1, w1 = _jacobian_adjoint(d, s, e, frame, pos, l1, -1.0, g_u, g_w, b, condim)
    f2, p2, u2, w2 = _jacobian_adjoint(d, s, e, frame, pos, l2, 1.0, g_u, g_w, b, condim)
    j_u, j_w = u1 + u2, w1 + w2
    g_friction = ti.Vector.zero(float, 3)  # ∂L/∂(sliding μ, torsional, rolling) of the pair
    g_mu_reg, g_r0, g_k, g_b, g_imp = 0.0, 0.0, 0.0, 0.0, 0.0
    if pyramid:  # J_n ± μ_k J_k
        for t in ti.static(range(d.max_condim - 1)):
            if t < condim - 1:
                kind = ti.static(0 if t < 2 else (1 if t == 2 else 2))
                g_friction[kind] += ((force[2 * t] - force[2 * t + 1]) * j_u[t + 1]
                                     - (g_aref[2 * t] - g_aref[2 * t + 1]) * j_w[t + 1])
    dist, margin = d.con_dist[s, e, c], d.pair_margin[pair]
    g_dist = 0.0
    for j in range(n):
        g_b -= row_times(d, s, e, d.con_efc[s, e, c] + j, d.qvel) * g_aref[j]
        if not (d.elliptic and j > 0):  # rows with the position term −K d (dist − margin)
            g_k -= imp * (dist - margin) * g_aref[j]
            g_imp -= k * (dist - margin) * g_aref[j]
            g_dist -= k * imp * g_aref[j]
        if pyramid:  # R = 2 μ_reg² R_0
            g_r0 += 2.0 * mu_reg * mu_reg * g_R[j]
            g_mu_reg += 4.0 * mu_reg * r0 * g_R[j]
        elif j == 0:  # R_0, and the cone's μ_reg
            g_r0 += g_R[j]
            g_mu_reg += g_mu[j]
        else:  # elliptic direction j − 1: R_j = R_0 / impratio · μ² / μ_j², and its μ_j
            kind = 0 if j < 3 else (1 if j == 3 else 2)
            mu_j = direction_friction(friction, j - 1)
            R_j = r1 * mu * mu / (mu_j * mu_j)
            g_r0 += g_R[j] * R_j / r0
            if kind > 0:  # (a sliding direction's μ² / μ_j² is 1)
                g_friction[0] += g_R[j] * 2.0 * R_j / mu
                g_friction[kind] -= g_R[j] * 2.0 * R_j / mu_j
            g_friction[kind] += g_mu[j]
    g_friction[0] += g_mu_reg * ti.sqrt(r1 / r0)
    scale = tran + mu * mu * tran if pyramid else tran
    if (1.0 - imp) * scale / imp > MINVAL:  # else R_0 is its floor
        g_imp -= scale / (imp * imp) * g_r0
        if pyramid:
            g_friction[0] += (1.0 - imp) / imp * 2.0 * mu * tran * g_r0
        # diagA = invweight_t of both links (body_invweight0, from their masses: contact.InvweightBasis)
        g_tran = (1.0 - imp) / imp * (1.0 + mu * mu if pyramid else 1.0) * g_r0
        accumulate(d.invweight_t.grad, ti.Vector([e, l1]), g_tran)
        accumulate(d.invweight_t.grad, ti.Vector([e, l2]), g_tran)
    slope, g_solimp = impedance_gradient(solimp, dist, margin)
    g_dist += slope * g_imp
    g_solimp *= g_imp
    g_solref, g_dmax = _stiffness_damping_adjoint(solref, solimp[1], d.consts[CONST["h"]], g_k, g_b)
    g_solimp[1] += g_dmax
    _contact_params_adjoint(d, e, pair, g_friction, g_solref, g_solimp)
    accumulate(d.con_pos.grad, ti.Vector([s, e, c]), p1 + p2)
    accumulate(d.con_frame.grad, ti.Vector([s, e, c]), f1 + f2)
    accumulate(d.con_dist.grad, ti.Vector([s, e, c]), g_dist)


@ti.func
def contact_force(d: ti.template(), s, e, c):
    """Force of contact c on its second geom in the contact frame (normal, tangent 1, tangent 2;
    N) from its rows' solved forces: a pyramid's normal force is the sum of its edges', its
    friction along tangent k the difference of edge pair k's times μ (MuJoCo's mj_contactForce;
    the torsional and rolling torques of condim 4 and 6 are left out, as Genesis's readouts)."""
    first = d.con_efc[s, e, c]
    condim = d.pair_condim[d.con_pair[s, e, c]]
    out = ti.Vector.zero(float, 3)  # (a contact without rows pushes nothing)
    if contact_included(d, s, e, c):
        if condim == 1:
            out[0] = d.efc_force[s, e, first]
        elif d.elliptic:
            out = ti.Vector([d.efc_force[s, e, first + k] for k in ti.static(range(3))])
        else:
            mu = d.efc_mu[s, e, first + 1]
            for k in ti.static(range(d.max_condim - 1)):
                if k < condim - 1:
                    plus, minus = d.efc_force[s, e, first + 2 * k], d.efc_force[s, e, first + 2 * k + 1]
                    out[0] += plus + minus
                    if ti.static(k < 2):
                        out[k + 1] = (plus - minus) * mu
    return out


# -- joint rows: equalities, friction loss and joint limits ------------------------------------------
@ti.func
def _softness(table: ti.template(), i):
    """(solref (2,), solimp (5,)) of the rows of owner i (a dof, an equality): ``table`` the model's
    7 numbers per owner for that kind of row (dof_limit_sol, dof_frictionloss_sol, eq_sol,
    body_eq_sol; complete and clamped at build: contact.with_row_softness)."""
    return (ti.Vector([table[7 * i + k] for k in ti.static(range(2))]),
            ti.Vector([table[7 * i + 2 + k] for k in ti.static(range(5))]))


@ti.func
def _joint_row_scalars(d: ti.template(), s, e, r, dist, velocity, scale, solref, solimp):
    """Row r's R and aref from its distance (m or rad), velocity J·q̇, diagA ``scale`` (the
    dof_invweight0 of its dofs) and its softness (solref (2,), solimp (5,))."""
    imp = impedance(solimp, dist, 0.0)
    k, b = stiffness_damping(solref, solimp[1], d.consts[CONST["h"]])
    d.efc_R[s, e, r] = ti.max(MINVAL, (1.0 - imp) / imp * scale)
    d.efc_aref[s, e, r] = -b * velocity - k * imp * dist
    d.efc_mu[s, e, r] = 0.0


@ti.func
def _dof_row(d: ti.template(), s, e, r, i, sign, dist, softness: ti.template()):
    """Row r on dof i alone (J = sign·e_i) at distance dist (m or rad; 0 for friction loss): its
    Jacobian (its one column: no reader looks past a row's columns), R and aref, its softness dof
    i's in the model table ``softness`` (_softness)."""
    d.efc_J[s, e, r, i] = sign
    slot = d.joint_columns + JOINT_ROW_SLOTS * r
    d.efc_col0[s, e, r], d.efc_ncol[s, e, r] = slot, 1
    d.efc_cols[s, e, slot] = i
    solref, solimp = _softness(softness, i)
    _joint_row_scalars(d, s, e, r, dist, sign * d.qvel[s, e, i], d.invweight_dof[e, i], solref, solimp)
    d.efc_dim[s, e, r], d.efc_id[s, e, r] = 1, i


@ti.func
def _equality_terms(d: ti.template(), s, e, k):
    """(a, b, multiplier, distance) of joint equality k at frame s: its dofs (the following one,
    the followed one, −1 when it is held at its offset alone) and q_a − offset − multiplier · q_b
    (m or rad)."""
    a, b = d.eq_dof1[k], d.eq_dof2[k]
    multiplier = d.eq_coef[2 * k + 1]
    followed = d.qpos[s, e, d.dof_q[ti.max(b, 0)]]  # (dof 0's when none: not used)
    dist = d.qpos[s, e, d.dof_q[a]] - d.eq_coef[2 * k] - (multiplier * followed if b >= 0 else 0.0)
    return a, b, multiplier, dist


@ti.func
def _equality_row(d: ti.template(), s, e, r, k):
    """Row r for joint equality k (MuJoCo's joint equality): J = e_a − multiplier · e_b (e_a alone
    without b), its distance from _equality_terms, diagA its dofs' dof_invweight0."""
    a, b, multiplier, dist = _equality_terms(d, s, e, k)
    d.efc_J[s, e, r, a] = 1.0
    slot = d.joint_columns + JOINT_ROW_SLOTS * r
    d.efc_col0[s, e, r], d.efc_ncol[s, e, r] = slot, 1
    d.efc_cols[s, e, slot] = a
    velocity, scale = d.qvel[s, e, a], d.invweight_dof[e, a]
    if b >= 0:
        d.efc_J[s, e, r, b] = -multiplier
        d.efc_ncol[s, e, r] = 2
        d.efc_cols[s, e, slot], d.efc_cols[s, e, slot + 1] = ti.min(a, b), ti.max(a, b)
        velocity -= multiplier * d.qvel[s, e, b]
        scale += d.invweight_dof[e, b]
    solref, solimp = _softness(d.eq_sol, k)
    _joint_row_scalars(d, s, e, r, dist, velocity, scale, solref, solimp)
    d.efc_dim[s, e, r], d.efc_id[s, e, r] = 1, k
    d.efc_type[s, e, r], d.efc_floss[s, e, r] = EQUALITY, 0.0


@ti.func
def _limit_side(d: ti.template(), s, e, i):
    """(sign, distance) of dof i's violated joint limit at frame s: (1, q − lower) below it,
    (−1, upper − q) above it, (0, 0) within or without limits (no row)."""
    sign, dist = 0.0, 0.0
    qi = d.dof_q[i]
    if d.limits_enabled and qi >= 0:
        q = d.qpos[s, e, qi]
        if q - d.limit_lower[e, i] < 0.0:
            sign, dist = 1.0, q - d.limit_lower[e, i]
        elif d.limit_upper[e, i] - q < 0.0:
            sign, dist = -1.0, d.limit_upper[e, i] - q
    return sign, dist


@ti.func
def _ball_limit(d: ti.template(), s, e, i):
    """(1 if violated else 0, distance θmax − θ rad, unit axis (3,)) of the cone limit of the ball
    joint whose first dof is i at frame s; 0 where dof i is no limited ball joint's first dof."""
    violated, dist, axis = 0, 0.0, ti.Vector.zero(float, 3)
    link = d.dof_link[i]
    if d.limits_enabled and d.link_jtype[link] == BALL and d.link_dof0[link] == i and d.limit_upper[e, i] < BIG:
        angle, turn_axis = quat_turn(joint_quat(d, s, e, link))
        dist, axis = d.limit_upper[e, i] - angle, turn_axis
        if dist < 0.0:
            violated = 1
    return violated, dist, axis


@ti.func
def _tendon_side(d: ti.template(), s, e, t):
    """(sign, distance) of tendon t's violated limit at frame s, its length L = Σ coef·q: (1, L −
    lower) below it, (−1, upper − L) above it, (0, 0) within or with limits off (no row)."""
    sign, dist = 0.0, 0.0
    if d.limits_enabled:
        length = tendon_length(d, s, e, t)
        if length - d.ten_lower[t] < 0.0:
            sign, dist = 1.0, length - d.ten_lower[t]
        elif d.ten_upper[t] - length < 0.0:
            sign, dist = -1.0, d.ten_upper[t] - length
    return sign, dist


@ti.func
def limit_violated(d: ti.template(), s, e):
    """1 if some joint or tendon limit of env e is violated at frame s (a limit row would arise),
    else 0."""
    violated = 0
    if d.limits_enabled:
        for i in range(d.n_dofs):
            sign, _dist = _limit_side(d, s, e, i)
            cone, _cone_dist, _axis = _ball_limit(d, s, e, i)  # (Taichi: one name, one type)
            if sign != 0.0 or cone != 0:
                violated = 1
        for t in range(d.n_tendons):
            tendon_sign, _tendon_dist = _tendon_side(d, s, e, t)
            if tendon_sign != 0.0:
                violated = 1
    return violated


@ti.func
def dof_rows_arise(d: ti.template(), s, e):
    """1 if env e forms joint rows at frame s (a joint equality, connect or weld, a run-time weld,
    friction loss on some dof, or a violated limit)."""
    arise = limit_violated(d, s, e)
    if d.n_eq > 0 or d.n_body_eq > 0 or dynamic_welds(d, e) > 0:
        arise = 1
    for t in range(d.n_tendons):
        if d.ten_eq[t] or d.ten_frictionloss[t] > 0.0:
            arise = 1
    for i in range(d.n_dofs):
        if d.frictionloss[e, i] > 0.0:
            arise = 1
    return arise


@ti.func
def dof_rows(d: ti.template(), s, e):
    """Rows 0… of frame s, in MuJoCo's order of kinds: every joint equality (in tree order; MuJoCo
    lists a URDF's mimics in the file's joint order), every connect's three, every weld's six (in
    tree order; MuJoCo lists equalities in the file's order, mixing kinds: the same rows, rounded
    otherwise where the orders differ), the run-time welds' six in the order they were made,
    friction loss of every dof with F > 0, then of every tendon with F > 0, then every violated
    joint limit, then every violated tendon limit (MuJoCo's order).
    Returns how many (also kept in efc_dof_rows[s, e, 0])."""
    rows = 0
    for k in range(d.n_eq):
        _equality_row(d, s, e, rows, k)
        rows += 1
    if ti.static(d.body_eqs):
        for k in range(d.n_body_eq + dynamic_welds(d, e)):
            rows += _body_eq_rows(d, s, e, rows, k)
    for t in range(d.n_tendons):
        if d.ten_eq[t]:
            _tendon_row(d, s, e, rows, t, 1.0, tendon_length(d, s, e, t) - d.ten_eq_length[t], EQUALITY,
                        d.ten_eq_sol)
            rows += 1
    for i in range(d.n_dofs):
        bound = d.frictionloss[e, i]
        if bound > 0.0:
            _dof_row(d, s, e, rows, i, 1.0, 0.0, d.dof_frictionloss_sol)
            d.efc_type[s, e, rows], d.efc_floss[s, e, rows] = FRICTION_LOSS, bound
            rows += 1
    for t in range(d.n_tendons):
        if d.ten_frictionloss[t] > 0.0:
            _tendon_row(d, s, e, rows, t, 1.0, 0.0, FRICTION_LOSS, d.ten_friction_sol)
            d.efc_floss[s, e, rows] = d.ten_frictionloss[t]
            rows += 1
    for i in range(d.n_dofs):
        sign, dist = _limit_side(d, s, e, i)
        if sign != 0.0:
            _dof_row(d, s, e, rows, i, sign, dist, d.dof_limit_sol)
            d.efc_type[s, e, rows], d.efc_floss[s, e, rows] = ONE_SIDED, 0.0
            rows += 1
        cone, cone_dist, axis = _ball_limit(d, s, e, i)
        if cone != 0:
            _ball_limit_row(d, s, e, rows, i, cone_dist, axis)
            rows += 1
    for t in range(d.n_tendons):
        tendon_sign, tendon_dist = _tendon_side(d, s, e, t)
        if tendon_sign != 0.0:
            _tendon_row(d, s, e, rows, t, tendon_sign, tendon_dist, ONE_SIDED, d.ten_limit_sol)
            rows += 1
    d.efc_dof_rows[s, e, 0] = rows
    return rows


@ti.func
def _tendon_row(d: ti.template(), s, e, r, t, sign, dist, kind, sol: ti.template()):
    """Row r for tendon t (MuJoCo's), a violated limit (kind ONE_SIDED, softness sol ten_limit_sol),
    its equality (EQUALITY, ten_eq_sol) or its friction loss (FRICTION_LOSS, ten_friction_sol; the
    caller sets the bound): J = sign·coef on its dofs (ascending: its columns), at distance dist (m
    or rad), diagA its invweight_ten (tendon_invweight0); its id n_dofs + t (the reverse tells it
    from a dof's row so)."""
    slot, first = d.joint_columns + JOINT_ROW_SLOTS * r, TENDON_JOINTS * t
    d.efc_col0[s, e, r], d.efc_ncol[s, e, r] = slot, d.ten_nnz[t]
    velocity = 0.0
    for k in range(first, first + d.ten_nnz[t]):
        i = d.ten_dof[k]
        d.efc_J[s, e, r, i] = sign * d.ten_coef[k]
        d.efc_cols[s, e, slot + k - first] = i
        velocity += sign * d.ten_coef[k] * d.qvel[s, e, i]
    solref, solimp = _softness(sol, t)
    _joint_row_scalars(d, s, e, r, dist, velocity, d.invweight_ten[e, t], solref, solimp)
    d.efc_dim[s, e, r], d.efc_id[s, e, r] = 1, d.n_dofs + t
    d.efc_type[s, e, r], d.efc_floss[s, e, r] = kind, 0.0


@ti.func
def _tendon_row_adjoint(d: ti.template(), s, e, r, g_aref, g_R):
    """Reverse of _tendon_row for row r (a limit's, an equality's or a friction loss's) from its
    implicit gradients (aref, R): into q and q̇ of the tendon's dofs at frame s and its
    invweight_ten (its Jacobian is constant; its friction loss the model's)."""
    t = d.efc_id[s, e, r] - d.n_dofs
    sign, dist = 1.0, 0.0  # (a friction loss's row: J = coef, no distance)
    solref, solimp = _softness(d.ten_friction_sol, t)
    if d.efc_type[s, e, r] == EQUALITY:
        dist = tendon_length(d, s, e, t) - d.ten_eq_length[t]
        solref, solimp = _softness(d.ten_eq_sol, t)
    elif d.efc_type[s, e, r] == ONE_SIDED:
        sign, dist = _tendon_side(d, s, e, t)
        solref, solimp = _softness(d.ten_limit_sol, t)
    g_dist, damping, g_scale = _joint_row_scalars_adjoint(d, dist, d.invweight_ten[e, t], g_aref, g_R, solref, solimp)
    accumulate(d.invweight_ten.grad, ti.Vector([e, t]), g_scale)
    if d.efc_type[s, e, r] == FRICTION_LOSS:  # (its distance is no function of q)
        g_dist = 0.0
    for k in range(TENDON_JOINTS * t, TENDON_JOINTS * t + d.ten_nnz[t]):
        i, c = d.ten_dof[k], sign * d.ten_coef[k]
        accumulate(d.qvel.grad, ti.Vector([s, e, i]), -damping * c * g_aref)
        accumulate(d.qpos.grad, ti.Vector([s, e, d.dof_q[i]]), c * g_dist)


@ti.func
def _ball_limit_row(d: ti.template(), s, e, r, i, dist, axis):
    """Row r for the cone limit of the ball joint whose first dof is i: J = −axis on its three
    dofs, at distance dist (rad), diagA its first dof's dof_invweight0 (MuJoCo's)."""
    slot = d.joint_columns + JOINT_ROW_SLOTS * r
    d.efc_col0[s, e, r], d.efc_ncol[s, e, r] = slot, 3
    velocity = 0.0
    for k in ti.static(range(3)):
        d.efc_J[s, e, r, i + k] = -axis[k]
        d.efc_cols[s, e, slot + k] = i + k
        velocity -= axis[k] * d.qvel[s, e, i + k]
    solref, solimp = _softness(d.dof_limit_sol, i)
    _joint_row_scalars(d, s, e, r, dist, velocity, d.invweight_dof[e, i], solref, solimp)
    d.efc_dim[s, e, r], d.efc_id[s, e, r] = 1, i
    d.efc_type[s, e, r], d.efc_floss[s, e, r] = ONE_SIDED, 0.0


@ti.func
def dof_rows_adjoint(d: ti.template(), s, e, r, g_aref, g_R, g_bound):
    """Reverse of ``_dof_row`` and ``_equality_row`` for row r (< efc_dof_rows) given the gradients
    of its aref, R and friction-loss bound: into q, q̇ at frame s, the friction-loss and limit
    inputs and dof_invweight0. The row's dofs: (first, second) with Jacobian entries (c1, c2); second = −1
    for a single-dof row. (An equality's offset and multiplier are the model's: no gradient.) A
    ball joint's cone limit: _ball_limit_adjoint; a connect's or weld's rows: _body_eq_row_adjoint."""
    t = d.efc_type[s, e, r]
    body_eq = 0
    if ti.static(d.body_eqs):
        if d.n_eq <= r and r < d.n_eq + 3 * d.n_connect + 6 * (d.n_weld + dynamic_welds(d, e)):
            _body_eq_row_adjoint(d, s, e, r, g_aref, g_R)
            body_eq = 1
    if body_eq == 0:
        if d.efc_id[s, e, r] >= d.n_dofs:  # (a joint equality's id is its index: below n_dofs)
            _tendon_row_adjoint(d, s, e, r, g_aref, g_R)
        else:  # (nested: Taichi's `and` would read dof_link past its end for a tendon's id)
            if t == ONE_SIDED and d.link_jtype[d.dof_link[d.efc_id[s, e, r]]] == BALL:
                _ball_limit_adjoint(d, s, e, r, g_aref, g_R)
            else:
                _scalar_row_adjoint(d, s, e, r, t, g_aref, g_R, g_bound)


@ti.func
def _scalar_row_adjoint(d: ti.template(), s, e, r, t, g_aref, g_R, g_bound):
    """dof_rows_adjoint for a row of type t on one dof, or an equality's two."""
    first, second, c1, c2, dist = d.efc_id[s, e, r], -1, 0.0, 0.0, 0.0
    solref, solimp = _softness(d.dof_frictionloss_sol, first)
    if t == EQUALITY:
        solref, solimp = _softness(d.eq_sol, first)
        a, b, multiplier, distance = _equality_terms(d, s, e, first)
        first, second, c1, c2, dist = a, b, 1.0, -multiplier, distance
    else:
        c1 = d.efc_J[s, e, r, first]
        if t != FRICTION_LOSS:
            _, dist = _limit_side(d, s, e, first)
            solref, solimp = _softness(d.dof_limit_sol, first)
    scale = d.invweight_dof[e, first] + (d.invweight_dof[e, second] if second >= 0 else 0.0)
    g_dist, damping, g_scale = _joint_row_scalars_adjoint(d, dist, scale, g_aref, g_R, solref, solimp)
    accumulate(d.invweight_dof.grad, ti.Vector([e, first]), g_scale)
    if second >= 0:
        accumulate(d.invweight_dof.grad, ti.Vector([e, second]), g_scale)
    accumulate(d.qvel.grad, ti.Vector([s, e, first]), -damping * c1 * g_aref)
    if second >= 0:
        accumulate(d.qvel.grad, ti.Vector([s, e, second]), -damping * c2 * g_aref)
    if t == FRICTION_LOSS:
        accumulate(d.frictionloss.grad, ti.Vector([e, first]), g_bound)
    else:  # a limit or an equality: aref and R depend on the distance
        accumulate(d.qpos.grad, ti.Vector([s, e, d.dof_q[first]]), c1 * g_dist)
        if second >= 0:
            accumulate(d.qpos.grad, ti.Vector([s, e, d.dof_q[second]]), c2 * g_dist)
        elif t == ONE_SIDED:  # a limit: dist = q − lower (c1 = 1) or upper − q (c1 = −1)
            if c1 > 0.0:
                accumulate(d.limit_lower.grad, ti.Vector([e, first]), -g_dist)
            else:
                accumulate(d.limit_upper.grad, ti.Vector([e, first]), g_dist)


@ti.func
def _joint_row_scalars_adjoint(d: ti.template(), dist, scale, g_aref, g_R, solref, solimp):
    """Reverse of _joint_row_scalars' R = (1 − imp)/imp · scale and aref's −K imp dist (its
    softness solref, solimp: the model's, no gradient): returns (∂L/∂dist, B, ∂L/∂scale), the last
    0 where R is at its floor."""
    k, damping = stiffness_damping(solref, solimp[1], d.consts[CONST["h"]])
    imp = impedance(solimp, dist, 0.0)
    g_imp, g_scale = -k * dist * g_aref, 0.0
    if (1.0 - imp) / imp * scale > MINVAL:
        g_scale = (1.0 - imp) / imp * g_R
        g_imp -= scale / (imp * imp) * g_R
    slope, _solimp_slope = impedance_gradient(solimp, dist, 0.0)
    return -k * imp * g_aref + slope * g_imp, damping, g_scale


@ti.func
def _ball_limit_adjoint(d: ti.template(), s, e, r, g_aref, g_R):
    """Reverse of _ball_limit_row for row r: from its implicit gradients (aref, R) and, as the row's
    Jacobian −axis depends on q, J̄_k = f u_k − āref (qacc_k + B q̇_k) (the solve's stationarity,
    and aref's −B J q̇; u = H⁻¹ā in solver_Mgrad), into the ball joint's quaternion, q̇ and its
    first dof's dof_invweight0 (the cone's angle is the model's: set_dofs_limit refuses a ball joint)."""
    i = d.efc_id[s, e, r]
    raw = joint_quat(d, s, e, d.dof_link[i])
    angle, axis = quat_turn(raw)
    solref, solimp = _softness(d.dof_limit_sol, i)
    g_dist, damping, g_scale = _joint_row_scalars_adjoint(d, d.limit_upper[e, i] - angle, d.invweight_dof[e, i],
                                                          g_aref, g_R, solref, solimp)
    accumulate(d.invweight_dof.grad, ti.Vector([e, i]), g_scale)
    g_angle = -g_dist  # dist = θmax − θ
    force = d.efc_force[s, e, r]
    g_axis = ti.Vector.zero(float, 3)
    for a in ti.static(range(3)):
        w = d.qacc_constrained[s, e, i + a] + damping * d.qvel[s, e, i + a]
        g_axis[a] = -(force * d.solver_Mgrad[s, e, i + a] - g_aref * w)  # J = −axis
        accumulate(d.qvel.grad, ti.Vector([s, e, i + a]), damping * axis[a] * g_aref)  # aref ∋ −B (−axis) · q̇
    g_raw = quat_turn_adjoint(raw, g_angle, g_axis)
    q0 = d.link_q0[d.dof_link[i]]
    for k in ti.static(range(4)):
        accumulate(d.qpos.grad, ti.Vector([s, e, q0 + k]), g_raw[k])


# -- connects and welds: two links' points (and frames) held together ------------------------------
# A weld's turn rows hold e = τ vec(a ⊗ b), a = (q2 ⊗ r2)⁻¹ and b = q1 ⊗ r1 (q the links' quaternions, r the
# held frames' turns in them, τ the torquescale), as MuJoCo's; a world-frame turn δ of link 1 makes b
# (1, δ/2) ⊗ b and of link 2 makes a a ⊗ (1, −δ/2), so ė = ½ τ vec(a ⊗ (0, ω1 − ω2) ⊗ b): the rows'
# Jacobian.
@ti.func
def _link_point(d: ti.template(), s, e, link, anchor):
    """World position (3,) m at frame s of the point at ``anchor`` (3,) m in the link's frame (the
    world's, link -1: the anchor itself)."""
    out = anchor
    if link >= 0:
        out = d.xpos[s, e, link] + quat_to_mat(d.xquat[s, e, link]) @ anchor
    return out


@ti.func
def _link_point_adjoint(d: ti.template(), s, e, link, point, g_point):
    """Reverse of _link_point: ∂L/∂point (3,) onto the link's origin and small world-frame turn."""
    if link >= 0:
        accumulate(d.xpos.grad, ti.Vector([s, e, link]), g_point)
        accumulate(d.xrot_grad, ti.Vector([s, e, link]), (point - d.xpos[s, e, link]).cross(g_point))


@ti.func
def _link_rotation(d: ti.template(), s, e, link):
    """(quaternion (4,), angular velocity (3,) rad/s, velocity-product angular acceleration (3,)
    rad/s²) of the link at frame s, world frame; the world's: (identity, 0, 0)."""
    quat, w, alpha = ti.Vector([1.0, 0.0, 0.0, 0.0], dt=float), ti.Vector.zero(float, 3), ti.Vector.zero(float, 3)
    if link >= 0:
        quat, w, alpha = d.xquat[s, e, link], d.cvel_w[s, e, link], d.cacc_w[s, e, link]
    return quat, w, alpha


@ti.func
def _point_bias_acceleration(d: ti.template(), s, e, link, point):
    """J̇ q̇ (3,) m/s² of a point fixed on the link (at ``point`` (3,) m at frame s): its acceleration
    at zero qacc without gravity, a + α × o + ω × (v + ω × o), o the point's offset from the tree's
    reference and (ω, v), (α, a) the link's velocity and velocity-product acceleration there (cacc
    less the base's −gravity; MuJoCo's mj_jacDot · q̇). The world's: 0."""
    out = ti.Vector.zero(float, 3)
    if link >= 0:
        offset = point - reference(d, s, e, link)
        w = d.cvel_w[s, e, link]
        gravity = ti.Vector([d.gravity[e, k] for k in ti.static(range(3))])
        out = (d.cacc_v[s, e, link] + gravity + d.cacc_w[s, e, link].cross(offset)
               + w.cross(d.cvel_v[s, e, link] + w.cross(offset)))
    return out


@ti.func
def _point_bias_acceleration_adjoint(d: ti.template(), s, e, link, point, g_acc):
    """Reverse of _point_bias_acceleration: ∂L/∂(J̇ q̇) (3,) into the link's cvel, cacc and gravity;
    returns ∂L/∂point (3,) (the reference is a constant of the reverse, as everywhere)."""
    g_point = ti.Vector.zero(float, 3)
    if link >= 0:
        offset = point - reference(d, s, e, link)
        w, alpha = d.cvel_w[s, e, link], d.cacc_w[s, e, link]
        pvel = d.cvel_v[s, e, link] + w.cross(offset)
        g_pvel = g_acc.cross(w)
        accumulate(d.cacc_v.grad, ti.Vector([s, e, link]), g_acc)
        accumulate(d.cacc_w.grad, ti.Vector([s, e, link]), offset.cross(g_acc))
        accumulate(d.cvel_w.grad, ti.Vector([s, e, link]), pvel.cross(g_acc) + offset.cross(g_pvel))
        accumulate(d.cvel_v.grad, ti.Vector([s, e, link]), g_pvel)
        for k in ti.static(range(3)):
            accumulate(d.gravity.grad, ti.Vector([e, k]), g_acc[k])
        g_point = g_acc.cross(alpha) + g_pvel.cross(w)
    return g_point


@ti.func
def _pure(v):
    """The quaternion (0, v) of a 3-vector."""
    return ti.Vector([0.0, v[0], v[1], v[2]], dt=float)


@ti.func
def _sandwich(a, y, b):
    """vec(a ⊗ y ⊗ b) (3,): the vector part."""
    q = quat_mul(quat_mul(a, y), b)
    return ti.Vector([q[1], q[2], q[3]])


@ti.func
def _sandwich_adjoint(a, y, b, g):
    """Reverse of _sandwich for unit a, b given ∂L/∂vec (3,): (∂L/∂y (4,), ∂L/∂δ1 (3,), ∂L/∂δ2
    (3,)), δ1 a world turn of b ((1, δ1/2) ⊗ b) and δ2 of a (a ⊗ (1, −δ2/2))."""
    y_bar = quat_mul(quat_mul(quat_conj(a), _pure(g)), quat_conj(b))
    yv, bv = ti.Vector([y[1], y[2], y[3]]), ti.Vector([y_bar[1], y_bar[2], y_bar[3]])
    g1 = 0.5 * (-y_bar[0] * yv + y[0] * bv + bv.cross(yv))
    g2 = 0.5 * (y_bar[0] * yv - y[0] * bv - yv.cross(bv))
    return y_bar, g1, g2


@ti.func
def dynamic_welds(d: ti.template(), e):
    """How many run-time welds env e has (their rows follow the model's connects' and welds')."""
    count = 0
    if ti.static(d.body_eqs):
        count = ti.cast(d.dyn_welds[e, 0], ti.i32)
    return count


@ti.func
def _dynamic_weld(d: ti.template(), k, first):
    """Column in dyn_welds of body equality k's float ``first`` (data.INPUTS' dyn_welds: 0, 1 its
    links; 2… its anchors; 8… its turns), k ≥ n_body_eq (a run-time weld)."""
    return 1 + DYN_WELD * (k - d.n_body_eq) + first


@ti.func
def _vector_at(d: ti.template(), e, column, n: ti.template()):
    """The n floats of env e's dyn_welds from ``column``, as a vector."""
    return ti.Vector([d.dyn_welds[e, column + c] for c in ti.static(range(n))], dt=float)


@ti.func
def _body_eq_terms(d: ti.template(), s, e, k):
    """(link 1, link 2, point 1 (3,) m, point 2 (3,) m) of connect or weld k at frame s (the model's,
    then env e's run-time welds): its two anchors in the world."""
    l1, l2 = 0, 0
    anchor1, anchor2 = ti.Vector.zero(float, 3), ti.Vector.zero(float, 3)
    if k < d.n_body_eq:
        l1, l2 = d.body_eq_link[2 * k], d.body_eq_link[2 * k + 1]
        anchor1, anchor2 = d.body_eq_anchor[2 * k], d.body_eq_anchor[2 * k + 1]
    else:
        l1 = ti.cast(d.dyn_welds[e, _dynamic_weld(d, k, 0)], ti.i32)
        l2 = ti.cast(d.dyn_welds[e, _dynamic_weld(d, k, 1)], ti.i32)
        anchor1 = _vector_at(d, e, _dynamic_weld(d, k, 2), 3)
        anchor2 = _vector_at(d, e, _dynamic_weld(d, k, 5), 3)
    return l1, l2, _link_point(d, s, e, l1, anchor1), _link_point(d, s, e, l2, anchor2)


@ti.func
def _weld_frames(d: ti.template(), s, e, k, l1, l2):
    """(a (4,), b (4,), τ) of weld k (a body equality: the model's, then env e's run-time welds,
    whose τ is 1) at frame s (see above). (Either sign of a quaternion gives the same force: a
    sign flips e, J and J̇ q̇ together, and Jᵀ f with them.)"""
    q1, _w1, _a1 = _link_rotation(d, s, e, l1)
    q2, _w2, _a2 = _link_rotation(d, s, e, l2)
    turn1, turn2, torquescale = ti.Vector.zero(float, 4), ti.Vector.zero(float, 4), 1.0
    if k < d.n_body_eq:
        w = k - d.n_connect
        turn1, turn2, torquescale = d.weld_turn[2 * w], d.weld_turn[2 * w + 1], d.weld_torquescale[w]
    else:
        turn1 = _vector_at(d, e, _dynamic_weld(d, k, 8), 4)
        turn2 = _vector_at(d, e, _dynamic_weld(d, k, 12), 4)
    return quat_conj(quat_mul(q2, turn2)), quat_mul(q1, turn1), torquescale


@ti.func
def _turn_bias(d: ti.template(), s, e, l1, l2):
    """y (4,) of a weld's J̇ q̇ = ½ τ vec(a ⊗ y ⊗ b) (MuJoCo's mj_Jdotv: ė's time derivative at zero
    qacc): y = −½ (0, ω2) ⊗ (0, Δω) + (0, Δα) + ½ (0, Δω) ⊗ (0, ω1), Δ link 1's less link 2's."""
    _q1, w1, alpha1 = _link_rotation(d, s, e, l1)
    _q2, w2, alpha2 = _link_rotation(d, s, e, l2)
    dw = w1 - w2
    return -0.5 * quat_mul(_pure(w2), _pure(dw)) + _pure(alpha1 - alpha2) + 0.5 * quat_mul(_pure(dw), _pure(w1))


@ti.func
def _turn_bias_adjoint(d: ti.template(), s, e, l1, l2, y_bar):
    """Reverse of _turn_bias's y given ∂L/∂y (4,): into both links' cvel_w and cacc_w."""
    _q1, w1, _alpha1 = _link_rotation(d, s, e, l1)
    _q2, w2, _alpha2 = _link_rotation(d, s, e, l2)
    dw = w1 - w2
    yw, yv = y_bar[0], ti.Vector([y_bar[1], y_bar[2], y_bar[3]])
    # (0, p) ⊗ (0, r) = (−p·r, p × r): ∂/∂p = −ȳ_w r + r × ȳ_v, ∂/∂r = −ȳ_w p + ȳ_v × p
    g_w2 = -0.5 * (-yw * dw + dw.cross(yv))
    g_dw = -0.5 * (-yw * w2 + yv.cross(w2)) + 0.5 * (-yw * w1 + w1.cross(yv))
    g_w1 = 0.5 * (-yw * dw + yv.cross(dw)) + g_dw
    g_w2 -= g_dw
    for link, g_w, g_alpha in ti.static(((l1, g_w1, yv), (l2, g_w2, -yv))):
        if link >= 0:
            accumulate(d.cvel_w.grad, ti.Vector([s, e, link]), g_w)
            accumulate(d.cacc_w.grad, ti.Vector([s, e, link]), g_alpha)


@ti.func
def _add_turn_jacobian(d: ti.template(), s, e, link, a, b, scale, first):
    """Add the turn rows' Jacobian of the link's path into rows first… first + 2: ``scale`` (½ τ
    for link 1, −½ τ for link 2) × vec(a ⊗ (0, cdof_w) ⊗ b) per dof."""
    l = link
    while l >= 0:
        dof0 = d.link_dof0[l]
        for i in range(dof0, dof0 + dof_count(d, l)):
            v = scale * _sandwich(a, _pure(d.cdof_w[s, e, i]), b)
            for k in ti.static(range(3)):
                accumulate(d.efc_J, ti.Vector([s, e, first + k, i]), v[k])
        l = d.link_parent[l]


@ti.func
def _turn_jacobian_adjoint(d: ti.template(), s, e, link, a, b, scale, k, force, g_aref, damping):
    """Reverse of _add_turn_jacobian for turn row k of the link's path: J̄ = f u − āref (qacc + B q̇)
    per dof, into cdof_w and q̇; returns ∂L/∂δ1, ∂L/∂δ2 (3,) (a's and b's turns, _sandwich_adjoint)."""
    g1, g2 = ti.Vector.zero(float, 3), ti.Vector.zero(float, 3)
    axis = ti.Vector([1.0 if k == c else 0.0 for c in ti.static(range(3))], dt=float)
    l = link
    while l >= 0:
        dof0 = d.link_dof0[l]
        for i in range(dof0, dof0 + dof_count(d, l)):
            y = _pure(d.cdof_w[s, e, i])
            u, w = d.solver_Mgrad[s, e, i], d.qacc_constrained[s, e, i] + damping * d.qvel[s, e, i]
            y_bar, h1, h2 = _sandwich_adjoint(a, y, b, scale * (force * u - g_aref * w) * axis)
            accumulate(d.cdof_w.grad, ti.Vector([s, e, i]), ti.Vector([y_bar[1], y_bar[2], y_bar[3]]))
            accumulate(d.qvel.grad, ti.Vector([s, e, i]), -damping * g_aref * scale * _sandwich(a, y, b).dot(axis))
            g1 += h1
            g2 += h2
        l = d.link_parent[l]
    return g1, g2


@ti.func
def _turn_error(d: ti.template(), s, e, k, l1, l2):
    """(turn error e (3,), a (4,), b (4,), τ) of connect or weld k (links l1, l2) at frame s (a
    connect's: 0, its a, b and τ unused)."""
    a, b = ti.Vector([1.0, 0.0, 0.0, 0.0], dt=float), ti.Vector([1.0, 0.0, 0.0, 0.0], dt=float)
    turn, torquescale = ti.Vector.zero(float, 3), 0.0
    if k >= d.n_connect:
        a, b, torquescale = _weld_frames(d, s, e, k, l1, l2)
        turn = torquescale * _sandwich(a, ti.Vector([1.0, 0.0, 0.0, 0.0], dt=float), b)
    return turn, a, b, torquescale


@ti.func
def _body_eq_softness(d: ti.template(), k):
    """(solref (2,), solimp (5,)) of body equality k's rows: the model's (body_eq_sol), or for a
    run-time weld a time constant of two substeps (Genesis's: as stiff as MuJoCo lets a row be)
    and MuJoCo's default solimp."""
    solref, solimp = ti.Vector([2.0 * d.consts[CONST["h"]], 1.0]), ti.Vector(DEFAULT_SOLIMP, dt=float)
    if k < d.n_body_eq:
        solref, solimp = _softness(d.body_eq_sol, k)
    return solref, solimp


@ti.func
def _body_eq_scalars(d: ti.template(), e, k, l1, l2, dist):
    """(impedance, K 1/s², B 1/s, diagA of the point rows, of the turn rows) of body equality k's
    rows (links l1, l2) at |error| = dist, as MuJoCo makes them: the impedance of the whole error's
    norm, diagA the two links' invweight_t (turn rows: invweight_r; the world's 0), its softness
    _body_eq_softness's."""
    solref, solimp = _body_eq_softness(d, k)
    imp = impedance(solimp, dist, 0.0)
    stiffness, b = stiffness_damping(solref, solimp[1], d.consts[CONST["h"]])
    translation, rotation = 0.0, 0.0
    for link in ti.static((l1, l2)):
        if link >= 0:
            translation += d.invweight_t[e, link]
            rotation += d.invweight_r[e, link]
    return imp, stiffness, b, translation, rotation


@ti.func
def _body_eq_rows(d: ti.template(), s, e, first, k):
    """Rows first… of connect or weld k (MuJoCo's): row j < 3 holds p1 − p2 along world axis j, J =
    J_p(link 1, p1) − J_p(link 2, p2) (the two points' Jacobians); a weld's rows 3… 5 its turn error
    e (see above). aref = −B J q̇ − K d error_j − J̇ q̇ (MuJoCo 4's: the rows ask the error's
    acceleration J q̈ + J̇ q̇ to follow the reference). Returns how many rows (3 or 6)."""
    l1, l2, p1, p2 = _body_eq_terms(d, s, e, k)
    gap = p1 - p2
    turn, a, b, torquescale = _turn_error(d, s, e, k, l1, l2)
    n = 3 if k < d.n_connect else 6
    base = d.body_eq_columns + k * d.n_dofs
    ncol = _path_columns(d, s, e, base, l1, l2)
    _zero_rows(d, s, e, base, first, n, ncol)
    world = ti.Matrix.identity(float, 3)
    _add_link_jacobian(d, s, e, l1, p1, world, 1.0, first, 3, False, ti.Vector.zero(float, 3))
    _add_link_jacobian(d, s, e, l2, p2, world, -1.0, first, 3, False, ti.Vector.zero(float, 3))
    dist = ti.sqrt(gap.dot(gap) + turn.dot(turn))
    imp, stiffness, damping, translation, rotation = _body_eq_scalars(d, e, k, l1, l2, dist)
    bias = _point_bias_acceleration(d, s, e, l1, p1) - _point_bias_acceleration(d, s, e, l2, p2)
    turn_bias = ti.Vector.zero(float, 3)
    if n == 6:
        _add_turn_jacobian(d, s, e, l1, a, b, 0.5 * torquescale, first + 3)
        _add_turn_jacobian(d, s, e, l2, a, b, -0.5 * torquescale, first + 3)
        turn_bias = 0.5 * torquescale * _sandwich(a, _turn_bias(d, s, e, l1, l2), b)
    for j in ti.static(range(6)):
        if j < n:
            r = first + j
            error, scale, jdv = gap[j % 3], translation, bias[j % 3]
            if ti.static(j >= 3):
                error, scale, jdv = turn[j - 3], rotation, turn_bias[j - 3]
            d.efc_col0[s, e, r], d.efc_ncol[s, e, r] = base, ncol
            d.efc_R[s, e, r] = ti.max(MINVAL, (1.0 - imp) / imp * scale)
            d.efc_aref[s, e, r] = -damping * row_times(d, s, e, r, d.qvel) - stiffness * imp * error - jdv
            d.efc_type[s, e, r], d.efc_floss[s, e, r], d.efc_mu[s, e, r] = EQUALITY, 0.0, 0.0
            d.efc_dim[s, e, r], d.efc_id[s, e, r] = 1, k
    return n


@ti.func
def _body_eq_row_adjoint(d: ti.template(), s, e, r, g_aref, g_R):
    """Reverse of _body_eq_rows for row r (row j of connect or weld k) from its implicit gradients
    (aref, R) and, as its Jacobian depends on q, J̄ = f u − āref (qacc + B q̇) (as the contact
    rows'): into cdof, q̇, both links' poses (through the points and the turn), their cvel and cacc
    (J̇ q̇), gravity, invweight_t and invweight_r at frame s."""
    k = d.efc_id[s, e, r]
    j = r - d.n_eq - 3 * k - 3 * ti.max(0, k - d.n_connect)  # (a weld's rows: six)
    l1, l2, p1, p2 = _body_eq_terms(d, s, e, k)
    gap = p1 - p2
    turn, a, b, torquescale = _turn_error(d, s, e, k, l1, l2)
    dist = ti.sqrt(gap.dot(gap) + turn.dot(turn))
    imp, stiffness, damping, translation, rotation = _body_eq_scalars(d, e, k, l1, l2, dist)
    axis = ti.Vector([1.0 if j % 3 == c else 0.0 for c in ti.static(range(3))], dt=float)
    error, scale = gap.dot(axis), translation
    if j >= 3:
        error, scale = turn.dot(axis), rotation
    g_imp = -stiffness * error * g_aref
    if (1.0 - imp) / imp * scale > MINVAL:  # else R is its floor
        for link in ti.static((l1, l2)):
            if link >= 0:
                if j < 3:
                    accumulate(d.invweight_t.grad, ti.Vector([e, link]), (1.0 - imp) / imp * g_R)
                else:
                    accumulate(d.invweight_r.grad, ti.Vector([e, link]), (1.0 - imp) / imp * g_R)
        g_imp -= scale / (imp * imp) * g_R
    slope = 0.0
    if dist > MINVAL:  # (the impedance is flat at no error)
        _solref, solimp = _body_eq_softness(d, k)
        slope, _solimp_slope = impedance_gradient(solimp, dist, 0.0)
        slope /= dist
    g_gap, g_turn = slope * g_imp * gap, slope * g_imp * turn
    force, world = d.efc_force[s, e, r], ti.Matrix.identity(float, 3)
    g_p1, g_p2 = ti.Vector.zero(float, 3), ti.Vector.zero(float, 3)
    g_turn1, g_turn2 = ti.Vector.zero(float, 3), ti.Vector.zero(float, 3)  # ∂L/∂ the links' world turns
    if j < 3:
        g_gap -= stiffness * imp * g_aref * axis
        g_u, g_w = _linear_only(force * axis), _linear_only(g_aref * axis)
        _f1, g_p1, _u1, _w1 = _jacobian_adjoint(d, s, e, world, p1, l1, 1.0, g_u, g_w, damping, 3)
        _f2, g_p2, _u2, _w2 = _jacobian_adjoint(d, s, e, world, p2, l2, -1.0, g_u, g_w, damping, 3)
        g_p1 += _point_bias_acceleration_adjoint(d, s, e, l1, p1, -g_aref * axis)
        g_p2 += _point_bias_acceleration_adjoint(d, s, e, l2, p2, g_aref * axis)
    else:
        g_turn -= stiffness * imp * g_aref * axis
        h1, h2 = _turn_jacobian_adjoint(d, s, e, l1, a, b, 0.5 * torquescale, j - 3, force, g_aref, damping)
        m1, m2 = _turn_jacobian_adjoint(d, s, e, l2, a, b, -0.5 * torquescale, j - 3, force, g_aref, damping)
        y_bar, n1, n2 = _sandwich_adjoint(a, _turn_bias(d, s, e, l1, l2), b, -0.5 * torquescale * g_aref * axis)
        _turn_bias_adjoint(d, s, e, l1, l2, y_bar)
        g_turn1, g_turn2 = h1 + m1 + n1, h2 + m2 + n2
    if k >= d.n_connect:  # the turn error's own dependence on the two frames
        _y_bar, e1, e2 = _sandwich_adjoint(a, ti.Vector([1.0, 0.0, 0.0, 0.0], dt=float), b, torquescale * g_turn)
        g_turn1 += e1
        g_turn2 += e2
    _link_point_adjoint(d, s, e, l1, p1, g_gap + g_p1)
    _link_point_adjoint(d, s, e, l2, p2, g_p2 - g_gap)
    for link, g in ti.static(((l1, g_turn1), (l2, g_turn2))):
        if link >= 0:
            accumulate(d.xrot_grad, ti.Vector([s, e, link]), g)
    if k >= d.n_body_eq:
        _dynamic_weld_adjoint(d, s, e, k, l1, l2, g_gap + g_p1, g_p2 - g_gap, g_turn1, g_turn2)


@ti.func
def _dynamic_weld_adjoint(d: ti.template(), s, e, k, l1, l2, g_point1, g_point2, g_turn1, g_turn2):
    """Into run-time weld k's data (dyn_welds.grad; the links' model indices, both ≥ 0): each
    anchor's gradient R_lᵀ ∂L/∂point from its world point's, and each held frame's turn r's from
    the gradient of that frame's world turn δ (b = q1 ⊗ r1 turned to (1, δ1/2) ⊗ b: ∂L/∂r1 =
    2 conj(q1) ⊗ (0, ∂L/∂δ1) ⊗ b, tangent to the unit sphere; a's likewise for r2, conj(a) = q2 ⊗ r2)."""
    a, b, _torquescale = _weld_frames(d, s, e, k, l1, l2)
    q1, _w1, _a1 = _link_rotation(d, s, e, l1)
    q2, _w2, _a2 = _link_rotation(d, s, e, l2)
    pulls = ((_dynamic_weld(d, k, 2), quat_to_mat(q1).transpose() @ g_point1),
             (_dynamic_weld(d, k, 5), quat_to_mat(q2).transpose() @ g_point2))
    turns = ((_dynamic_weld(d, k, 8), 2.0 * quat_mul(quat_mul(quat_conj(q1), _pure(g_turn1)), b)),
             (_dynamic_weld(d, k, 12), 2.0 * quat_mul(quat_mul(quat_conj(q2), _pure(g_turn2)), quat_conj(a))))
    for column, g in ti.static(pulls + turns):
        for c in ti.static(range(g.n)):
            accumulate(d.dyn_welds.grad, ti.Vector([e, column + c]), g[c])
