"""Constraint solve of one env: MuJoCo's primal Newton method (mj_solNewton), as MuJoCo 4 runs it.

**Cost.** With a0 = M⁻¹ qfrc_smooth (qacc_smooth), jar = J·a − aref per row and D = 1/R,
    qacc = argmin_a  ½ (a − a0)ᵀ M (a − a0) + Σ_rows s(jar),
a convex C¹ piecewise-quadratic (plus the cone) whose force per row is f = −∂s/∂jar:
- friction loss (bound F): Huber, ½ D jar² while |jar| < R F, else F |jar| − ½ R F² (f = ∓F);
- one-sided (limit, frictionless contact, pyramid edge): ½ D jar² while jar < 0, else 0;
- elliptic block (dim rows, N = μ jar₀, U_j = μ_j jar_j, T = |U|): top zone N ≥ μT: 0; bottom
  zone μN + T ≤ 0: Σ ½ D_j jar_j²; middle zone: ½ Dm (N − μT)², Dm = D₀ / (μ² (1 + μ²)).
Each row's state (efc_state, MuJoCo's mjtConstraintState) names its piece: SATISFIED (zero),
QUADRATIC, LINEARNEG / LINEARPOS (friction loss saturated), CONE (middle zone, whole block).

**Islands.** As MuJoCo (islands on by default), the dofs split into islands: kinematic trees
(a tree = the dofs under one root of ``d.dof_parent``) joined by rows that touch both; each
island is solved on its own (own scale, line searches, termination). Dofs no row touches keep
qacc = qacc_smooth. MuJoCo takes a contact's trees from its two geoms' bodies; we take them
from the rows' non-zero Jacobian entries (the same unless a row is exactly zero on a tree).

**Past MuJoCo's stop** (d.converged: our defaults, not enable_mujoco_compatibility). With the
elliptic cone in its middle zone the cost is not piecewise quadratic, and MuJoCo's stop (a
Newton decrement, quadratic in the error, under the tolerance) leaves qacc ~√tolerance from the
solution. The backward differentiates the solution (implicit.py), and the forward map's
derivative differs from it by that error times the Hessian's change, large where a contact
nearly sticks (1/T²): a husky driving on a plane, 40 steps, missed the map's derivative by 6 %
of |g|. One more Newton step squares the error: 1e-8 of |g| there. A pyramidal cost is piecewise
quadratic, so a Newton step with the final states ends exact, but a stop on a small improvement
right after the states changed leaves the line search's point (tolerance 1e-5, float32's default:
a KUKA pushing a box left its 1e-12 trajectory by 1.2e-3 m/s at step 30, and 200 steps' gradient
was 31 % off): both cones take the one more step where the last states changed.

**Warm start** (mj_fwdConstraint): the whole env's cost at qacc_warmstart (constraints + Gauss)
against the constraint cost at qacc_smooth; the lower one starts every island.

**Newton iteration** per island, with scale = 1 / Σ_island M_ii: the gradient g = M a −
qfrc_smooth − Jᵀ f; the Hessian H = M + Jᵀ diag(D·[state = QUADRATIC]) J + Σ_cones J_cᵀ H_c J_c
(H_c the middle zone's dim × dim Hessian in jar), factored densely in each iteration whose
states differ from the last (no incremental updates; the same states and no cone in its middle
zone give the same H, whose factor is kept); direction −H⁻¹ g; an exact line search on the 1-D
piecewise quadratic (PrimalSearch: a Newton step from 0, one-sided Newton steps until the
derivative changes sign, then a bracketed search among the two brackets' Newton points and the
midpoint), converged where |dcost/dα| < tolerance · ls_tolerance · |search| / scale, at most
ls_iterations evaluations.
Start: stop at once if ½ scale gᵀM⁻¹g < tolerance and scale |g| < tolerance (certificate), or
if scale |g| < tolerance and the Newton decrement ½ scale gᵀH⁻¹g < tolerance. After each step:
stop if 0 < scale · improvement < tolerance, scale |g| < tolerance or the decrement <
tolerance; also when the line search returns α = 0 or after ``iterations`` steps.
solver_niter is the sum of the islands' iteration counts (MuJoCo's Σ d.solver_niter).

**For the backward.** At exit d.solver_H holds the lower Cholesky factor L (H = L Lᵀ) of the
whole env's final Hessian, block-diagonal over islands (M's factor on the trees no row touches),
consistent with the final efc_state (the active set) and solver_jar = J qacc − aref (from which
the cone blocks H_c follow): row i from dof solver_env[i] on, among its block's dofs; entries
elsewhere are zero and not kept (``cholesky_solve``). Implicit differentiation solves H u = ḡ
with it.

**Replay.** A backward replays the step to refill its frames. Given the forward's final qacc and
jar (the solver's ``replay_record``), the replay makes every output the solve leaves from them
as its last pass did (``_solve_island``'s first pass, then a stop: states, forces,
qfrc_constraint, the factor): the same bits without a warm start or iterations (the solve's
share of a differentiable box rollout's backward: from ~2 Newton iterations and their line
searches to one pass: a factorisation, an M·qacc product and a solve with the factor). The jar is
the iterations' running sum, not J qacc − aref afresh: forces from a fresh jar differ by round-off
times the stiff rows' D or a near-sticking cone's Hessian, and no longer balance qacc (they made
a husky's forward map noisy at 1e-12, which finite differences saw).

**Checking against MuJoCo.** With islands, MuJoCo copies only the forces back from its island
arrays: after mj_forward, d.efc_state still holds the warm-start test's states (at qacc_smooth);
the solve's final states, which ours equal, are d.iefc_state[d.map_efc2iefc].

**Where we differ from MuJoCo.** An envelope (skyline) Cholesky of M and a fresh one of H in
every iteration that changes a state (MuJoCo: sparse LDLᵀ, rank-one updates of H): round-off
only. The envelope and the rows' column lists (efc_cols) skip exact zeros only, so the results
equal the dense ones bit for bit; M·v sums over M's pairs (add_mul_M), in their order. Every
loop runs over an island's own dofs, rows and envelope, so the cost grows with the scene's
size, not its square. Island trees
from the Jacobian (above). No noslip, no sleeping, warm start always on.
"""
import taichi as ti

# Row types (efc_type) of the interface
UNUSED, FRICTION_LOSS, ONE_SIDED, ELLIPTIC_FIRST, ELLIPTIC_REST, EQUALITY = 0, 1, 2, 3, 4, 5
# MuJoCo's mjtConstraintState (efc_state)
SATISFIED, QUADRATIC, LINEARNEG, LINEARPOS, CONE = 0, 1, 2, 3, 4
# elliptic cone zones
TOP, BOTTOM, MIDDLE = 1, 2, 3
MINVAL = 1e-15  # MuJoCo's mjMINVAL
ALL = -2        # island label standing for every dof and row
MAX_CONTACT_ROWS = 10  # the most rows one contact has (a pyramid of condim 6)
NO_ISLAND = -1  # label of a dof (or row) that no row touches

# Work arrays of the solve, indexed [s, e, k] (D, R) or [s, e, i, j] (DD). Element "i": int32.
SCRATCH = {
    "solver_H": ("f", "DD"),          # Hessian H (lower triangle), factored in place: L, H = L Lᵀ
    "solver_Ma": ("f", "D"),          # M qacc
    "solver_Mv": ("f", "D"),          # M search
    "solver_grad": ("f", "D"),        # cost gradient in qacc
    "solver_Mgrad": ("f", "D"),       # H⁻¹ grad (M⁻¹ grad for the start certificate)
    "solver_search": ("f", "D"),      # search direction
    "solver_jar": ("f", "R"),         # J qacc − aref
    "solver_Jv": ("f", "R"),          # J search
    "solver_tree": ("i", "D"),        # union-find parent of a tree's root dof (−1: no row)
    "solver_dof_tree": ("i", "D"),    # root dof of a dof's kinematic tree
    "solver_dof_island": ("i", "D"),  # island of a dof: its root tree's root dof, or −1
    "solver_row_island": ("i", "R"),  # island of a row
    "solver_dofs": ("i", "D"),        # the dofs of the island being solved, ascending
    "solver_rows": ("i", "R"),        # its used rows (elliptic tails included), ascending
    "solver_pos": ("i", "D"),         # a dof's position in solver_dofs
    "solver_first": ("i", "D"),       # envelope of its H: per position a, the first b where H[a, b] may be ≠ 0
    "solver_reach": ("i", "D"),       # per position a, a bound on the last b whose envelope reaches a
    "solver_inv": ("f", "D"),         # per position, 1 / L's diagonal entry (−1: a deficient pivot)
    "solver_env": ("i", "D"),         # per dof, the first dof of its row of the final factor (the backward's)
    "solver_head": ("i", "D"),        # per island label, its first used row (−1: none)
    "solver_dof_next": ("i", "D"),    # the next dof of a dof's island (−1: the last)
    "solver_row_next": ("i", "R"),    # the next used row of a row's island (−1: the last)
}


# ----------------------------------------------------------------------------- islands
@ti.func
def _find(d: ti.template(), s, e, t):
    """Union-find root of active tree t."""
    while d.solver_tree[s, e, t] != t:
        t = d.solver_tree[s, e, t]
    return t


@ti.func
def _find_islands(d: ti.template(), s, e):
    """Label dofs and rows with their island: trees joined by every used row's non-zero Jacobian
    entries; an island is named by its smallest tree (MuJoCo's canonical root)."""
    for i in range(d.n_dofs):  # a dof's parent comes before it
        parent = d.dof_parent[i]
        d.solver_dof_tree[s, e, i] = i if parent == -1 else d.solver_dof_tree[s, e, parent]
        d.solver_tree[s, e, i] = NO_ISLAND
    for r in range(d.n_efc[s, e, 0]):
        if d.efc_type[s, e, r] != UNUSED:
            first = NO_ISLAND
            col0 = d.efc_col0[s, e, r]
            for a in range(d.efc_ncol[s, e, r]):
                i = d.efc_cols[s, e, col0 + a]
                if d.efc_J[s, e, r, i] != 0.0:
                    t = d.solver_dof_tree[s, e, i]
                    if d.solver_tree[s, e, t] == NO_ISLAND:
                        d.solver_tree[s, e, t] = t
                    if first == NO_ISLAND:
                        first = t
                    else:  # link the larger root under the smaller
                        u, v = _find(d, s, e, first), _find(d, s, e, t)
                        d.solver_tree[s, e, ti.max(u, v)] = ti.min(u, v)
    for i in range(d.n_dofs):
        t = d.solver_dof_tree[s, e, i]
        label = NO_ISLAND
        if d.solver_tree[s, e, t] != NO_ISLAND:
            label = _find(d, s, e, t)
        d.solver_dof_island[s, e, i] = label
    for r in range(d.n_efc[s, e, 0]):  # an elliptic block's rows share one island
        t = d.efc_type[s, e, r]
        if t != ELLIPTIC_REST:
            count = d.efc_dim[s, e, r] if t == ELLIPTIC_FIRST else 1
            label = NO_ISLAND
            if t != UNUSED:
                col0 = d.efc_col0[s, e, r]
                for q in range(count):
                    for a in range(d.efc_ncol[s, e, r]):
                        i = d.efc_cols[s, e, col0 + a]
                        if label == NO_ISLAND and d.efc_J[s, e, r + q, i] != 0.0:
                            label = d.solver_dof_island[s, e, i]
            for q in range(count):
                d.solver_row_island[s, e, r + q] = label
    _link_islands(d, s, e)


@ti.func
def _link_islands(d: ti.template(), s, e):
    """Each island's dofs and used rows as ascending linked lists (solver_dof_next from the island's
    label, its smallest dof; solver_row_next from solver_head[label]), so that selecting an island
    costs its own size: 60 boxes apart on a plane are 60 islands, and a scan of every dof and row
    per island cost more than their solves."""
    for i in range(d.n_dofs):
        d.solver_head[s, e, i] = -1
    for q in range(d.n_dofs):  # descending, each dof put before the island's list so far
        i = d.n_dofs - 1 - q
        label = d.solver_dof_island[s, e, i]
        if label != NO_ISLAND:
            d.solver_dof_next[s, e, i] = d.solver_head[s, e, label]
            d.solver_head[s, e, label] = i
    for i in range(d.n_dofs):
        d.solver_head[s, e, i] = -1
    for q in range(d.n_efc[s, e, 0]):
        r = d.n_efc[s, e, 0] - 1 - q
        label = d.solver_row_island[s, e, r]
        if d.efc_type[s, e, r] != UNUSED and label != NO_ISLAND:
            d.solver_row_next[s, e, r] = d.solver_head[s, e, label]
            d.solver_head[s, e, label] = r


@ti.func
def _select(d: ti.template(), s, e, k):
    """solver_dofs ← island k's dofs, solver_rows ← its used rows (k = ALL: every dof and used
    row), both ascending; solver_pos ← each listed dof's position. Returns their counts (n, m).
    Every loop of the solve runs over these lists, and a row's products over its non-zero columns
    (efc_cols): the sums keep the dense order, less exact zeros, so the results are the dense
    ones bit for bit."""
    n, m = 0, 0
    if k == ALL:
        n = d.n_dofs
        for i in range(n):
            d.solver_dofs[s, e, i] = d.solver_pos[s, e, i] = i
        for r in range(d.n_efc[s, e, 0]):
            if d.efc_type[s, e, r] != UNUSED:
                d.solver_rows[s, e, m] = r
                m += 1
    else:
        i = k
        while i != -1:
            d.solver_dofs[s, e, n] = i
            d.solver_pos[s, e, i] = n
            n += 1
            i = d.solver_dof_next[s, e, i]
        r = d.solver_head[s, e, k]
        while r != -1:
            d.solver_rows[s, e, m] = r
            m += 1
            r = d.solver_row_next[s, e, r]
    return n, m


@ti.func
def _row_dot(d: ti.template(), s, e, r, x: ti.template()):
    """J_r · x[s, e] over row r's non-zero columns."""
    acc = 0.0
    col0 = d.efc_col0[s, e, r]
    for a in range(d.efc_ncol[s, e, r]):
        i = d.efc_cols[s, e, col0 + a]
        acc += d.efc_J[s, e, r, i] * x[s, e, i]
    return acc


# ----------------------------------------------------------------------------- envelope algebra
# H is factored within its envelope (profile): row a's entries from position solver_first[a] on,
# where first[a] is at or before its first non-zero. A Cholesky factor has no fill-in left of it,
# so the factor and solves skip those columns (free bodies stacked in a chain give a banded H,
# bodies apart a block-diagonal one) and nothing left of it is written or read: the cost follows
# the envelope, not the square of the dofs (the constraint stage of 60 boxes apart on a plane:
# 0.43 → 0.17 ms a substep, float32).
# The envelope is structural (the dofs' trees and the rows' columns), so it may hold exact zeros;
# they add exact zeros, and the results are the dense ones bit for bit.
@ti.func
def _tree_envelope(d: ti.template(), s, e, n):
    """solver_first[a] ← the position of its dof's tree root: M's envelope (M[i, j] ≠ 0 only for dof
    j on dof i's path to the root). The n dofs of solver_dofs hold whole trees."""
    _tree_first(d, s, e, n)
    _reach(d, s, e, n, d.solver_first)


@ti.func
def _tree_first(d: ti.template(), s, e, n):
    for a in range(n):
        d.solver_first[s, e, a] = d.solver_pos[s, e, d.solver_dof_tree[s, e, d.solver_dofs[s, e, a]]]


@ti.func
def _island_envelope(d: ti.template(), s, e, k, n, m):
    """solver_first ← the envelope of island k's H = M + Jᵀ D J + cone blocks over its n dofs and m
    rows (solver_dofs, solver_rows): M's, widened to each row's first column in the island (the
    rows of every state: the envelope stays while the states change)."""
    _tree_first(d, s, e, n)
    for q in range(m):
        r = d.solver_rows[s, e, q]
        col0, low = d.efc_col0[s, e, r], -1
        for c in range(d.efc_ncol[s, e, r]):  # ascending; a column whose entries are all exactly
            i = d.efc_cols[s, e, col0 + c]    # zero may lie outside the island
            if d.solver_dof_island[s, e, i] == k:
                a = d.solver_pos[s, e, i]
                if low == -1:
                    low = a
                d.solver_first[s, e, a] = ti.min(d.solver_first[s, e, a], low)
    _reach(d, s, e, n, d.solver_first)


@ti.func
def _reach(d: ti.template(), s, e, n, first: ti.template()):
    """solver_reach[a] ← max(a, the last b < n with first[s, e, b] ≤ a): no row past it has an
    entry in column a (the backward substitution's bound). first: solver_first (positions), or
    solver_env (dofs)."""
    for a in range(n):
        d.solver_reach[s, e, a] = a
    for b in range(n):
        f = first[s, e, b]
        d.solver_reach[s, e, f] = ti.max(d.solver_reach[s, e, f], b)
    for a in range(1, n):
        d.solver_reach[s, e, a] = ti.max(d.solver_reach[s, e, a], d.solver_reach[s, e, a - 1])


@ti.func
def _cholesky(d: ti.template(), s, e, n):
    """In place, solver_H (lower triangle of a symmetric positive matrix on the n dofs of
    solver_dofs, envelope in solver_first) ← its Cholesky factor L, row by row. As
    mju_cholFactor, a pivot below MINVAL is raised to MINVAL and its column cleared."""
    base = d.solver_dofs[s, e, 0]  # the dofs run base, base + 1, ...: no lookup of a position's dof
    if n == 0 or d.solver_dofs[s, e, n - 1] != base + n - 1:
        base = -1
    for a in range(n):
        i, fa = d.solver_dofs[s, e, a], d.solver_first[s, e, a]
        for b in range(fa, a):
            j, inv = d.solver_dofs[s, e, b], d.solver_inv[s, e, b]
            value = 0.0  # (under a deficient pivot: its column cleared)
            if not inv < 0.0:
                value = _subtract_products(d, s, e, d.solver_H[s, e, i, j], i, j,
                                           ti.max(fa, d.solver_first[s, e, b]), b, base) * inv
            d.solver_H[s, e, i, j] = value
        pivot = _subtract_products(d, s, e, d.solver_H[s, e, i, i], i, i, fa, a, base)
        deficient = pivot < MINVAL
        if deficient:
            pivot = MINVAL
        lii = ti.sqrt(pivot)
        d.solver_H[s, e, i, i] = lii
        d.solver_inv[s, e, a] = ti.select(deficient, -1.0, 1.0 / lii)


@ti.func
def _subtract_products(d: ti.template(), s, e, acc, i, j, lo, hi, base):
    """acc − Σ_c H[i, k_c] H[j, k_c] over positions c = lo … hi − 1 in turn, k_c the dof at position
    c of solver_dofs, or base + c where base ≥ 0 (the dofs run contiguously: the usual island,
    whose inner loop then reads no position's dof)."""
    if base >= 0:
        for c in range(lo, hi):
            acc -= d.solver_H[s, e, i, base + c] * d.solver_H[s, e, j, base + c]
    else:
        for c in range(lo, hi):
            k = d.solver_dofs[s, e, c]
            acc -= d.solver_H[s, e, i, k] * d.solver_H[s, e, j, k]
    return acc


@ti.func
def _factor_solve(d: ti.template(), x: ti.template(), s, e, n):
    """In place, x[s, e] ← (L Lᵀ)⁻¹ x[s, e] on the n dofs of solver_dofs (L in solver_H from
    ``_cholesky``, envelope in solver_first and solver_reach)."""
    for a in range(n):
        i = d.solver_dofs[s, e, a]
        acc = x[s, e, i]
        for b in range(d.solver_first[s, e, a], a):
            j = d.solver_dofs[s, e, b]
            acc -= d.solver_H[s, e, i, j] * x[s, e, j]
        x[s, e, i] = acc / d.solver_H[s, e, i, i]
    for q in range(n):
        a = n - 1 - q
        i = d.solver_dofs[s, e, a]
        acc = x[s, e, i]
        for b in range(a + 1, d.solver_reach[s, e, a] + 1):
            if d.solver_first[s, e, b] <= a:
                j = d.solver_dofs[s, e, b]
                acc -= d.solver_H[s, e, j, i] * x[s, e, j]
        x[s, e, i] = acc / d.solver_H[s, e, i, i]


@ti.func
def _block(d: ti.template(), s, e, i):
    """The diagonal block of the final factor that dof i is in: its island's label, or its tree's
    root where no row touches it (a tree root is its tree's smallest dof, an island's label its
    smallest: the two never clash)."""
    label = d.solver_dof_island[s, e, i]
    return ti.select(label == NO_ISLAND, d.solver_dof_tree[s, e, i], label)


@ti.func
def cholesky_solve(d: ti.template(), x: ti.template(), s, e):
    """In place, x[s, e] ← H⁻¹ x[s, e] on every dof with the final factor (solver_H = L, H = L Lᵀ):
    the backward's solve. Row i of L holds its entries from dof solver_env[i] on among the dofs
    of its block; every other entry is zero and not stored. Scratch: solver_reach (in dofs)."""
    n = d.n_dofs
    _reach(d, s, e, n, d.solver_env)
    for i in range(n):
        block, acc = _block(d, s, e, i), x[s, e, i]
        for j in range(d.solver_env[s, e, i], i):
            if _block(d, s, e, j) == block:
                acc -= d.solver_H[s, e, i, j] * x[s, e, j]
        x[s, e, i] = acc / d.solver_H[s, e, i, i]
    for q in range(n):
        i = n - 1 - q
        block, acc = _block(d, s, e, i), x[s, e, i]
        for j in range(i + 1, d.solver_reach[s, e, i] + 1):
            if d.solver_env[s, e, j] <= i and _block(d, s, e, j) == block:
                acc -= d.solver_H[s, e, j, i] * x[s, e, j]
        x[s, e, i] = acc / d.solver_H[s, e, i, i]


@ti.func
def _dot(d: ti.template(), a: ti.template(), b: ti.template(), s, e, n):
    """a[s, e] · b[s, e] over the n dofs of solver_dofs."""
    acc = 0.0
    for p in range(n):
        i = d.solver_dofs[s, e, p]
        acc += a[s, e, i] * b[s, e, i]
    return acc


@ti.func
def _mul_M(d: ti.template(), s, e, n, x: ti.template(), out: ti.template()):
    """out[s, e] ← M x[s, e] on the n dofs of solver_dofs (an island's, or every dof)."""
    for p in range(n):
        out[s, e, d.solver_dofs[s, e, p]] = 0.0
    add_mul_M(d, s, e, n, True, x, out)


@ti.func
def add_mul_M(d: ti.template(), s, e, n, listed: ti.template(), x: ti.template(), out: ti.template()):
    """out[s, e] += M x[s, e] on n dofs (listed: those of solver_dofs; else dofs 0 … n − 1) over M's
    non-zero entries only: the model's mass-matrix pairs (dof j on dof i's path to the root,
    sorted by i then j; they never join two islands). Each dof's terms come in ascending column
    order, as a dense product adds them. (A dense product: the tower's 60 dofs made 3600 terms a
    call, its pairs 210.)"""
    for p in range(n):
        i = p
        if ti.static(listed):
            i = d.solver_dofs[s, e, p]
        q = d.dof_pair0[i]
        while q < d.n_pairs and d.pair_i[q] == i:
            j = d.pair_j[q]
            m_ij = d.solver_M[s, e, i, j]
            out[s, e, i] = out[s, e, i] + m_ij * x[s, e, j]
            if i != j:
                out[s, e, j] = out[s, e, j] + m_ij * x[s, e, i]
            q += 1


@ti.func
def _set_jar(d: ti.template(), s, e, m):
    """jar ← J qacc − aref on the m rows of solver_rows."""
    for q in range(m):
        r = d.solver_rows[s, e, q]
        d.solver_jar[s, e, r] = _row_dot(d, s, e, r, d.qacc) - d.efc_aref[s, e, r]


# ----------------------------------------------------------------------------- cost pieces
@ti.func
def _cone_zone(N, Tsqr, mu):
    """Zone of an elliptic cone at normal N = μ jar₀ and tangential T² = Σ U_j²; returns (zone, T)."""
    zone, T = TOP, 0.0
    if Tsqr <= 0.0:
        if N < 0.0:
            zone = BOTTOM
    else:
        T = ti.sqrt(Tsqr)
        if N >= mu * T:
            zone = TOP
        elif mu * N + T <= 0.0:
            zone = BOTTOM
        else:
            zone = MIDDLE
    return zone, T


@ti.func
def _update_constraints(d: ti.template(), s, e, m):
    """mj_constraintUpdate on the m rows of solver_rows: efc_state and efc_force from solver_jar.
    Returns (the constraint cost Σ s(jar), changed): changed is 1 when the Hessian these states
    give may differ from the one the previous states gave: a row changed state, or an elliptic
    block is in its middle zone (whose Hessian follows jar)."""
    cost, changed = 0.0, 0
    for q in range(m):
        r = d.solver_rows[s, e, q]
        t = d.efc_type[s, e, r]
        if t != ELLIPTIC_REST:  # a block counts by its first row
            previous = d.efc_state[s, e, r]
            jar, R = d.solver_jar[s, e, r], d.efc_R[s, e, r]
            D = 1.0 / R
            if t == FRICTION_LOSS:
                F = d.efc_floss[s, e, r]
                if jar <= -R * F:
                    cost += -0.5 * R * F * F - F * jar
                    d.efc_force[s, e, r], d.efc_state[s, e, r] = F, LINEARNEG
                elif jar >= R * F:
                    cost += -0.5 * R * F * F + F * jar
                    d.efc_force[s, e, r], d.efc_state[s, e, r] = -F, LINEARPOS
                else:
                    cost += 0.5 * D * jar * jar
                    d.efc_force[s, e, r], d.efc_state[s, e, r] = -D * jar, QUADRATIC
            elif t == ONE_SIDED or t == EQUALITY:  # an equality is always in its quadratic
                if jar >= 0.0 and t == ONE_SIDED:
                    d.efc_force[s, e, r], d.efc_state[s, e, r] = 0.0, SATISFIED
                else:
                    cost += 0.5 * D * jar * jar
                    d.efc_force[s, e, r], d.efc_state[s, e, r] = -D * jar, QUADRATIC
            elif ti.static(d.elliptic):  # (an elliptic block's first row; a pyramidal solve has none)
                cost += _update_cone(d, s, e, r)
            state = d.efc_state[s, e, r]
            if state != previous or state == CONE:
                changed = 1
    return cost, changed


@ti.func
def cone_coordinates(d: ti.template(), s, e, r):
    """(N, T²) of the elliptic block at row r: N = μ jar₀ and T² = Σ_j (μ_j jar_j)²."""
    N = d.solver_jar[s, e, r] * d.efc_mu[s, e, r]
    Tsqr = 0.0
    for j in range(1, d.efc_dim[s, e, r]):
        u = d.solver_jar[s, e, r + j] * d.efc_mu[s, e, r + j]
        Tsqr += u * u
    return N, Tsqr


@ti.func
def _update_cone(d: ti.template(), s, e, r):
    """State and forces of the elliptic block starting at row r; returns its cost."""
    dim, mu = d.efc_dim[s, e, r], d.efc_mu[s, e, r]
    N, Tsqr = cone_coordinates(d, s, e, r)
    zone, T = _cone_zone(N, Tsqr, mu)
    cost, state = 0.0, SATISFIED
    if zone == TOP:
        for j in range(dim):
            d.efc_force[s, e, r + j] = 0.0
    elif zone == BOTTOM:
        state = QUADRATIC
        for j in range(dim):
            jar = d.solver_jar[s, e, r + j]
            D = 1.0 / d.efc_R[s, e, r + j]
            cost += 0.5 * D * jar * jar
            d.efc_force[s, e, r + j] = -D * jar
    else:
        state = CONE
        Dm = (1.0 / d.efc_R[s, e, r]) / (mu * mu * (1.0 + mu * mu))
        gap = N - mu * T
        cost = 0.5 * Dm * gap * gap
        f0 = -Dm * gap * mu
        d.efc_force[s, e, r] = f0
        for j in range(1, dim):
            fr = d.efc_mu[s, e, r + j]
            d.efc_force[s, e, r + j] = -f0 / T * (d.solver_jar[s, e, r + j] * fr) * fr
    for j in range(dim):
        d.efc_state[s, e, r + j] = state
    return cost


@ti.func
def cone_hessian_entry(d: ti.template(), s, e, r, a, b, N, T):
    """Entry (a, b) of the middle zone's Hessian of the block at row r in jar (MuJoCo's con->H):
    Dm s_a s_b [∂²(N − μT)²/2 / ∂U_a ∂U_b] with s = (μ, μ_1, ...)."""
    mu = d.efc_mu[s, e, r]
    Dm = (1.0 / d.efc_R[s, e, r]) / (mu * mu * (1.0 + mu * mu))
    Ua = d.solver_jar[s, e, r + a] * d.efc_mu[s, e, r + a]
    Ub = d.solver_jar[s, e, r + b] * d.efc_mu[s, e, r + b]
    h = 1.0
    if a == 0 and b > 0:
        h = -mu / T * Ub
    elif a > 0 and b == 0:
        h = -mu / T * Ua
    elif a > 0:
        h = mu * N / (T * T * T) * Ua * Ub
        if a == b:
            h += mu * mu - mu * N / T
    return Dm * d.efc_mu[s, e, r + a] * d.efc_mu[s, e, r + b] * h


@ti.func
def _factor_hessian(d: ti.template(), s, e, k, n, m):
    """solver_H ← Cholesky factor of H = M + Jᵀ D_quadratic J + cone blocks on island k's n dofs
    (solver_dofs) and m rows (solver_rows), within its envelope (set here)."""
    _island_envelope(d, s, e, k, n, m)
    for a in range(n):
        i = d.solver_dofs[s, e, a]
        for b in range(d.solver_first[s, e, a], a + 1):
            j = d.solver_dofs[s, e, b]
            d.solver_H[s, e, i, j] = d.solver_M[s, e, i, j]
    q = 0
    while q < m:  # consecutive rows sharing a column list (a contact's) together, an elliptic block alone
        r = d.solver_rows[s, e, q]
        count = 1
        while (q + count < m and count < MAX_CONTACT_ROWS and d.solver_rows[s, e, q + count] == r + count
               and d.efc_col0[s, e, r + count] == d.efc_col0[s, e, r]
               and d.efc_type[s, e, r + count] != ELLIPTIC_FIRST):
            count += 1
        _add_quadratic_rows(d, s, e, r, count)
        if ti.static(d.elliptic):  # (a block's rows are all in its cone, or none)
            if d.efc_type[s, e, r] == ELLIPTIC_FIRST and d.efc_state[s, e, r] == CONE:
                _add_cone_hessian(d, s, e, r)
        q += count
    _cholesky(d, s, e, n)


@ti.func
def _add_quadratic_rows(d: ti.template(), s, e, r, count):
    """solver_H += Σ_k J_kᵀ J_k / R_k over the QUADRATIC rows among r … r + count − 1, which share
    one column list (a contact's rows), as ``_add_outer`` of each row in turn would add them (an
    elliptic block's cone Hessian comes after its rows, which are then not QUADRATIC): each
    entry takes the rows' terms in row order, zeros skipped (the same bits), but is read and
    written once for the group and its column and island once (4 pyramid rows: a third of the
    memory traffic; the Hessian was a third of a box's replayed solve)."""
    col0, island = d.efc_col0[s, e, r], d.solver_row_island[s, e, r]
    h = ti.Vector.zero(float, MAX_CONTACT_ROWS)
    for k in ti.static(range(MAX_CONTACT_ROWS)):
        if k < count and d.efc_state[s, e, r + k] == QUADRATIC:
            h[k] = 1.0 / d.efc_R[s, e, r + k]
    for a in range(d.efc_ncol[s, e, r]):
        i = d.efc_cols[s, e, col0 + a]
        hJ = ti.Vector.zero(float, MAX_CONTACT_ROWS)
        live = False
        for k in ti.static(range(MAX_CONTACT_ROWS)):
            if k < count and h[k] != 0.0:  # (a row in another state adds nothing, NaN or not)
                hJ[k] = h[k] * d.efc_J[s, e, r + k, i]
                live = live or hJ[k] != 0.0
        if live:
            for b in range(a + 1):
                j = d.efc_cols[s, e, col0 + b]
                if d.solver_dof_island[s, e, j] == island:
                    acc = d.solver_H[s, e, i, j]
                    for k in ti.static(range(MAX_CONTACT_ROWS)):
                        if k < count and hJ[k] != 0.0:
                            acc = acc + hJ[k] * d.efc_J[s, e, r + k, j]
                    d.solver_H[s, e, i, j] = acc


@ti.func
def _add_outer(d: ti.template(), s, e, ra, rb, h):
    """solver_H += h J_raᵀ J_rb (lower triangle) over the non-zero columns the two rows share
    (rows of one contact) in their island (a listed column whose entries are all exactly zero may
    lie outside it, beyond the kept envelope). The terms go in the dense order (i, then j ≤ i),
    zeros skipped."""
    col0, island = d.efc_col0[s, e, ra], d.solver_row_island[s, e, ra]
    for a in range(d.efc_ncol[s, e, ra]):
        i = d.efc_cols[s, e, col0 + a]
        hJ = h * d.efc_J[s, e, ra, i]
        if hJ != 0.0:
            for b in range(a + 1):
                j = d.efc_cols[s, e, col0 + b]
                if d.solver_dof_island[s, e, j] == island:
                    # written out: an array's += is an atomic add in Taichi (a locked loop on the CPU)
                    d.solver_H[s, e, i, j] = d.solver_H[s, e, i, j] + hJ * d.efc_J[s, e, rb, j]


@ti.func
def _add_cone_hessian(d: ti.template(), s, e, r):
    """solver_H += J_cᵀ H_c J_c for the elliptic block at row r (middle zone)."""
    dim = d.efc_dim[s, e, r]
    N, Tsqr = cone_coordinates(d, s, e, r)
    T = ti.sqrt(Tsqr)
    for a in range(dim):
        for b in range(dim):
            _add_outer(d, s, e, r + a, r + b, cone_hessian_entry(d, s, e, r, a, b, N, T))


@ti.func
def _update_gradient(d: ti.template(), s, e, n, m):
    """qfrc_constraint = Jᵀ f and grad = M qacc − qfrc_smooth − qfrc_constraint on the n dofs of
    solver_dofs (rows: the m of solver_rows)."""
    _constraint_force(d, s, e, n, m)
    for p in range(n):
        i = d.solver_dofs[s, e, p]
        d.solver_grad[s, e, i] = d.solver_Ma[s, e, i] - d.qfrc_smooth[s, e, i] - d.qfrc_constraint[s, e, i]


@ti.func
def _constraint_force(d: ti.template(), s, e, n, m):
    """qfrc_constraint = Jᵀ f on the n dofs of solver_dofs (the m rows of solver_rows, scattered in
    row order)."""
    for p in range(n):
        d.qfrc_constraint[s, e, d.solver_dofs[s, e, p]] = 0.0
    for q in range(m):
        r = d.solver_rows[s, e, q]
        f = d.efc_force[s, e, r]
        col0 = d.efc_col0[s, e, r]
        for a in range(d.efc_ncol[s, e, r]):
            i = d.efc_cols[s, e, col0 + a]
            d.qfrc_constraint[s, e, i] = d.qfrc_constraint[s, e, i] + d.efc_J[s, e, r, i] * f


# ----------------------------------------------------------------------------- line search
@ti.func
def _friction_cost(x, F, RF, D):
    """Huber cost of a friction-loss row at jar = x (bound F, RF = R F)."""
    cost = F * (-0.5 * RF + x)
    if -RF < x and x < RF:
        cost = 0.5 * D * x * x
    elif x <= -RF:
        cost = F * (-0.5 * RF - x)
    return cost


@ti.func
def _friction_zone(x, RF):
    zone = 1
    if -RF < x and x < RF:
        zone = 0
    elif x <= -RF:
        zone = -1
    return zone


@ti.func
def _friction_cost_change(x0, x, F, RF, D):
    """cost(x) − cost(x0) of a friction-loss row, without cancellation inside one piece."""
    z0, z = _friction_zone(x0, RF), _friction_zone(x, RF)
    change = _friction_cost(x, F, RF, D) - _friction_cost(x0, F, RF, D)
    if z0 == 0 and z == 0:
        change = 0.5 * D * (x - x0) * (x + x0)
    elif z0 == -1 and z == -1:
        change = F * (x0 - x)
    elif z0 == 1 and z == 1:
        change = F * (x - x0)
    return change


@ti.func
def _cone_cost_change(alpha, q0, q1, q2, U0, V0, UU, UV, VV, mu, Dm):
    """cost(α) − cost(0) of an elliptic block along the search (MuJoCo's ellipticCostDif);
    q0..q2: its bottom-zone quadratic ½ jarᵀDjar, jvᵀDjar, ½ jvᵀDjv. Returns (change, zone, T)."""
    zone0, T0 = _cone_zone(U0, UU, mu)
    N = U0 + alpha * V0
    zone, T = _cone_zone(N, UU + alpha * (2.0 * UV + alpha * VV), mu)
    change = 0.0
    if zone0 == BOTTOM and zone == BOTTOM:
        change = alpha * alpha * q2 + alpha * q1
    elif zone0 == MIDDLE and zone == MIDDLE:  # rationalised: no cancellation
        dT = alpha * (2.0 * UV + alpha * VV) / (T + T0)
        dgap = alpha * V0 - mu * dT
        change = 0.5 * Dm * dgap * (2.0 * (U0 - mu * T0) + dgap)
    elif zone0 == MIDDLE and zone == BOTTOM:
        gap0 = mu * U0 + T0
        change = alpha * (alpha * q2 + q1) + 0.5 * Dm * gap0 * gap0
    elif zone0 == BOTTOM and zone == MIDDLE:
        gap = mu * N + T
        change = alpha * (alpha * q2 + q1) - 0.5 * Dm * gap * gap
    elif zone0 == TOP and zone == BOTTOM:
        change = alpha * alpha * q2 + alpha * q1 + q0
    elif zone0 == TOP and zone == MIDDLE:
        gap = N - mu * T
        change = 0.5 * Dm * gap * gap
    elif zone0 == MIDDLE and zone == TOP:
        gap0 = U0 - mu * T0
        change = -0.5 * Dm * gap0 * gap0
    elif zone0 == BOTTOM and zone == TOP:
        change = -q0
    return change, zone, T


@ti.func
def _eval_cone(d: ti.template(), s, e, r, alpha):
    """(cost change, d/dα, d²/dα²) of the elliptic block at row r at step α."""
    dim, mu = d.efc_dim[s, e, r], d.efc_mu[s, e, r]
    q0, q1, q2, UU, UV, VV = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    for j in range(dim):
        jar, jv = d.solver_jar[s, e, r + j], d.solver_Jv[s, e, r + j]
        D = 1.0 / d.efc_R[s, e, r + j]
        DJ = D * jar
        q0 += jar * DJ
        q1 += jv * DJ
        q2 += jv * D * jv
        if j > 0:
            fr = d.efc_mu[s, e, r + j]
            U, V = jar * fr, jv * fr
            UU += U * U
            UV += U * V
            VV += V * V
    q0 *= 0.5
    q2 *= 0.5
    U0, V0 = d.solver_jar[s, e, r] * mu, d.solver_Jv[s, e, r] * mu
    Dm = (1.0 / d.efc_R[s, e, r]) / (mu * mu * (1.0 + mu * mu))
    change, zone, T = _cone_cost_change(alpha, q0, q1, q2, U0, V0, UU, UV, VV, mu, Dm)
    d0, d1 = 0.0, 0.0
    if zone == BOTTOM:
        d0, d1 = 2.0 * alpha * q2 + q1, 2.0 * q2
    elif zone == MIDDLE:
        N = U0 + alpha * V0
        T1 = (UV + alpha * VV) / T
        T2 = VV / T - (UV + alpha * VV) * T1 / (T * T)
        slope = V0 - mu * T1
        d0 = Dm * (N - mu * T) * slope
        d1 = Dm * (slope * slope + (N - mu * T) * (-mu * T2))
    return change, d0, d1


@ti.func
def _eval(d: ti.template(), s, e, m, alpha, gauss1, gauss2):
    """Point (α, cost(α) − cost(0), d/dα, d²/dα²) of the island's cost (rows: the m of
    solver_rows) along solver_search (MuJoCo's PrimalEval); gauss1, gauss2: the Gauss term's
    linear and quadratic coefficients."""
    cost, d0, d1 = 0.0, 0.0, 0.0
    quad = ti.Vector([0.0, gauss1, gauss2])  # summed active quadratics, shifted by cost(0)
    for q in range(m):
        r = d.solver_rows[s, e, q]
        t = d.efc_type[s, e, r]
        if t != ELLIPTIC_REST:
            jar, jv = d.solver_jar[s, e, r], d.solver_Jv[s, e, r]
            D = 1.0 / d.efc_R[s, e, r]
            if t == FRICTION_LOSS:
                F = d.efc_floss[s, e, r]
                RF = d.efc_R[s, e, r] * F
                x = jar + alpha * jv
                cost += _friction_cost_change(jar, x, F, RF, D)
                if -RF < x and x < RF:
                    d0 += D * x * jv
                    d1 += D * jv * jv
                elif x <= -RF:
                    d0 += -F * jv
                else:
                    d0 += F * jv
            elif t == ONE_SIDED or t == EQUALITY:
                DJ = D * jar
                q0 = 0.5 * (jar * DJ)
                cost0 = 0.0
                if jar < 0.0 or t == EQUALITY:
                    cost0 = q0
                if jar + alpha * jv < 0.0 or t == EQUALITY:
                    quad += ti.Vector([q0 - cost0, jv * DJ, 0.5 * (jv * D * jv)])
                else:
                    cost -= cost0
            elif ti.static(d.elliptic):  # (an elliptic block's first row)
                c, c1, c2 = _eval_cone(d, s, e, r, alpha)
                cost += c
                d0 += c1
                d1 += c2
    cost += alpha * alpha * quad[2] + alpha * quad[1] + quad[0]
    d0 += 2.0 * alpha * quad[2] + quad[1]
    d1 += 2.0 * quad[2]
    if d1 <= 0.0:  # cannot happen for a convex cost; MuJoCo's guard
        d1 = MINVAL
    return ti.Vector([alpha, cost, d0, d1])


@ti.func
def _newton_point(p):
    """α of the 1-D Newton step from point p = (α, cost, d/dα, d²/dα²)."""
    return p[0] - p[2] / p[3]


@ti.func
def _update_bracket(p, c0, c1, c2):
    """MuJoCo's updateBracket: move bracket end p to any candidate with a derivative of p's sign
    and a smaller magnitude. Returns (new p, moved)."""
    moved = 0
    for c in ti.static([c0, c1, c2]):
        if p[2] < 0.0 and c[2] < 0.0 and p[2] < c[2]:
            p, moved = c, 1
        elif p[2] > 0.0 and c[2] > 0.0 and p[2] > c[2]:
            p, moved = c, 1
    return p, moved


# Phases of the line search: which point the evaluation just made is
_P0, _P1_FIRST, _P1_ONE_SIDED, _P1_NEXT_SETUP, _MID, _P1_NEXT, _P2_NEXT, _BRACKET = 0, 1, 2, 3, 4, 5, 6, 7


@ti.func
def _line_search(d: ti.template(), s, e, k, n, m, tolerance, ls_iterations, scale):
    """Exact line search of island k (solver_dofs, solver_rows: n dofs, m rows) along
    solver_search (MuJoCo's PrimalSearch), written as one loop with a single evaluation site.
    Sets solver_Mv and solver_Jv. Returns (α, improvement = cost(0) − cost(α)); α = 0 when the
    search is degenerate or nothing improves."""
    snorm = ti.sqrt(_dot(d, d.solver_search, d.solver_search, s, e, n))
    alpha, improvement = 0.0, 0.0
    if snorm >= MINVAL:
        gtol = tolerance * snorm / scale
        _mul_M(d, s, e, n, d.solver_search, d.solver_Mv)
        for q in range(m):
            r = d.solver_rows[s, e, q]
            d.solver_Jv[s, e, r] = _row_dot(d, s, e, r, d.solver_search)
        gauss1 = _dot(d, d.solver_search, d.solver_Ma, s, e, n) - _dot(d, d.qfrc_smooth, d.solver_search, s, e, n)
        gauss2 = 0.5 * _dot(d, d.solver_search, d.solver_Mv, s, e, n)

        zero = ti.Vector([0.0, 0.0, 0.0, 0.0])
        p0, p1, p2, p1next, p2next, pmid, best = zero, zero, zero, zero, zero, zero, zero
        phase, n_eval, x, direction, p2_pending, done = _P0, 0, 0.0, 1.0, 0, 0
        while not done:
            if phase == _BRACKET:  # head of the bracketed loop: evaluate no point here
                if n_eval < ls_iterations:
                    x, phase = 0.5 * (p1[0] + p2[0]), _MID
                else:  # out of evaluations: the better bracket end if it improves
                    done = 1
                    if p1[1] <= p2[1] and p1[1] < 0.0:
                        best = p1
                    elif p2[1] <= p1[1] and p2[1] < 0.0:
                        best = p2
                    else:
                        best = p0
                continue
            p = _eval(d, s, e, m, x, gauss1, gauss2)
            n_eval += 1
            if phase == _P0:
                p0, x, phase = p, _newton_point(p), _P1_FIRST
            elif phase == _P1_FIRST or phase == _P1_ONE_SIDED:
                p1 = p
                converged = ti.abs(p[2]) < gtol and p[1] < 0.0
                if phase == _P1_FIRST:
                    converged = ti.abs(p[2]) < gtol and (p[0] == 0.0 or p[1] < 0.0)
                    direction = 1.0 if p[2] < 0.0 else -1.0
                    p2 = p0
                if converged:
                    best, done = p1, 1
                elif p1[2] * direction <= -gtol and n_eval < ls_iterations:
                    p2, x, phase = p1, _newton_point(p1), _P1_ONE_SIDED
                elif n_eval >= ls_iterations:  # could not bracket
                    best, done = p1, 1
                else:
                    p2next, x, phase = p1, _newton_point(p1), _P1_NEXT_SETUP
            elif phase == _P1_NEXT_SETUP:
                p1next, phase = p, _BRACKET
            elif phase == _MID:
                pmid = p
                best_i, best_cost = -1, 0.0
                i = 0
                for c in ti.static([p1next, p2next, pmid]):
                    if ti.abs(c[2]) < gtol and (best_i == -1 or c[1] < best_cost):
                        best_i, best_cost, best = i, c[1], c
                    i += 1
                if best_i >= 0:
                    done = 1
                else:
                    p1, moved1 = _update_bracket(p1, p1next, p2next, pmid)
                    p2, moved2 = _update_bracket(p2, p1next, p2next, pmid)
                    if moved1 == 0 and moved2 == 0:  # round-off reached: take the midpoint
                        best, done = pmid, 1
                    elif moved1 == 1:
                        x, phase, p2_pending = _newton_point(p1), _P1_NEXT, moved2
                    else:
                        x, phase = _newton_point(p2), _P2_NEXT
            elif phase == _P1_NEXT:
                p1next, phase = p, _BRACKET
                if p2_pending == 1:
                    x, phase = _newton_point(p2), _P2_NEXT
            else:  # _P2_NEXT
                p2next, phase = p, _BRACKET
        alpha, improvement = best[0], -best[1]
    return alpha, improvement


# ----------------------------------------------------------------------------- drivers
@ti.func
def _solve_island(d: ti.template(), s, e, k, iterations, tolerance, ls_iterations, ls_tolerance, replaying):
    """Newton iterations on island k from the current qacc (mj_solPrimal); returns (their count,
    1 when they stopped at ``iterations`` before a stopping test held, else 0).
    Leaves qacc, efc_force/state, qfrc_constraint and the factored final H of the island.
    replaying: qacc and solver_jar hold the forward's final values ("Replay"): the first pass,
    which then is the forward's last, makes the outputs again and returns (0, 0) (one copy of the
    pass's code in the kernel, not two: the constraint solve's kernel compiled in 27.6 s instead of
    34.6, a box on a plane, float64)."""
    n, m = _select(d, s, e, k)
    inertia = 0.0
    for p in range(n):
        i = d.solver_dofs[s, e, p]
        inertia += d.solver_M[s, e, i, i]
    scale = 1.0 / inertia
    _mul_M(d, s, e, n, d.qacc, d.solver_Ma)
    if not replaying:
        _set_jar(d, s, e, m)
    niter, first, improvement, polished, capped = 0, 1, 0.0, 0, 0
    while True:
        _, changed = _update_constraints(d, s, e, m)
        _update_gradient(d, s, e, n, m)
        gradient = scale * ti.sqrt(_dot(d, d.solver_grad, d.solver_grad, s, e, n))
        # The island's block of solver_H holds M's factor until its first Hessian: the first
        # pass solves with it for the duality gap ½ gᵀM⁻¹g (a good warm start needs no Newton
        # step), then with H for the Newton decrement ½ gᵀH⁻¹g; later passes only with H.
        certificate, decrement = 0, 0.0
        n_solves = 1 + (first and not replaying)
        for attempt in range(n_solves):
            if attempt == n_solves - 1:
                # also where the certificate stops (the backward needs it); after a step that left
                # every state (and so H) as it was, the island's block still holds H's factor
                if first or changed:
                    _factor_hessian(d, s, e, k, n, m)
            else:  # M's factor, in the island's positions
                _tree_envelope(d, s, e, n)
            for p in range(n):
                i = d.solver_dofs[s, e, p]
                d.solver_Mgrad[s, e, i] = d.solver_grad[s, e, i]
            _factor_solve(d, d.solver_Mgrad, s, e, n)
            decrement = ti.max(0.0, 0.5 * scale * _dot(d, d.solver_grad, d.solver_Mgrad, s, e, n))
            if attempt == 0 and first:
                certificate = decrement < tolerance and gradient < tolerance
        if replaying:
            break
        stop = 0
        if first:
            stop = certificate or (gradient < tolerance and decrement < tolerance)
            first = 0
        else:
            niter += 1
            stop = (improvement > 0.0 and improvement < tolerance) or gradient < tolerance \
                or decrement < tolerance
            if stop and changed and d.converged and not polished:  # (see "Past MuJoCo's stop" above)
                stop, polished = 0, 1
        if stop or niter >= iterations:
            capped = int(not stop and not polished)  # (a polishing step beyond the stop is not short of it)
            break
        for p in range(n):
            i = d.solver_dofs[s, e, p]
            d.solver_search[s, e, i] = -d.solver_Mgrad[s, e, i]
        alpha, ls_improvement = _line_search(d, s, e, k, n, m, tolerance * ls_tolerance, ls_iterations, scale)
        if alpha == 0.0:
            break
        for p in range(n):
            i = d.solver_dofs[s, e, p]
            d.qacc[s, e, i] = d.qacc[s, e, i] + alpha * d.solver_search[s, e, i]
            d.solver_Ma[s, e, i] = d.solver_Ma[s, e, i] + alpha * d.solver_Mv[s, e, i]
        for q in range(m):
            r = d.solver_rows[s, e, q]
            d.solver_jar[s, e, r] = d.solver_jar[s, e, r] + alpha * d.solver_Jv[s, e, r]
        improvement = scale * ls_improvement
    _note_factor_rows(d, s, e, n)
    return niter, capped


@ti.func
def _note_factor_rows(d: ti.template(), s, e, n):
    """solver_env ← where each of the n dofs' rows of the island's final factor starts, for the
    backward (cholesky_solve)."""
    for a in range(n):
        d.solver_env[s, e, d.solver_dofs[s, e, a]] = d.solver_dofs[s, e, d.solver_first[s, e, a]]


@ti.func
def _warm_start(d: ti.template(), s, e, n, m):
    """qacc ← qacc_warmstart if its total cost is not above the constraint cost of qacc_smooth
    (the Gauss term vanishes there), else qacc_smooth; unconstrained dofs take qacc_smooth.
    solver_dofs and solver_rows hold every dof (n) and used row (m)."""
    cost_warm, cost_smooth = 0.0, 0.0
    for trial in range(2):  # 0: the warm start, 1: qacc_smooth
        for i in range(d.n_dofs):
            d.qacc[s, e, i] = d.qacc_warmstart[e, i] if trial == 0 else d.qacc_smooth[s, e, i]
        _set_jar(d, s, e, m)
        cost, _ = _update_constraints(d, s, e, m)
        if trial == 0:
            _mul_M(d, s, e, n, d.qacc, d.solver_Ma)
            for i in range(d.n_dofs):
                cost += 0.5 * (d.solver_Ma[s, e, i] - d.qfrc_smooth[s, e, i]) \
                    * (d.qacc[s, e, i] - d.qacc_smooth[s, e, i])
            cost_warm = cost
        else:
            cost_smooth = cost
    for i in range(d.n_dofs):
        if cost_warm <= cost_smooth and d.solver_dof_island[s, e, i] != NO_ISLAND:
            d.qacc[s, e, i] = d.qacc_warmstart[e, i]


@ti.func
def newton_solve(d: ti.template(), s, e, iterations, tolerance, ls_iterations, ls_tolerance, replaying):
    """Constrained acceleration of env e at substep frame s (see the module docstring); replaying:
    qacc_constrained[s, e] and solver_jar[s, e] hold the forward's final values, from which the
    outputs are made again without a warm start or iterations ("Replay").

    Reads solver_M (D, D) kg·m² / kg, qfrc_smooth (D,) N·m / N, the n_efc[s, e, 0] rows efc_type, efc_dim,
    efc_mu, efc_J (R, D) with their non-zero columns (efc_col0, efc_ncol, efc_cols), efc_R, efc_aref,
    efc_floss, qacc_warmstart[e] (D,) and dof_parent.
    Writes qacc_smooth, qacc (D,) rad/s² / m/s², efc_force (R,), efc_state (R,), qfrc_constraint
    (D,), solver_niter, the capped flag (an island stopped at ``iterations``), and the SCRATCH
    arrays (solver_H: the final Hessian's factor).
    iterations, ls_iterations: limits; tolerance, ls_tolerance: MuJoCo's opt values."""
    _find_islands(d, s, e)
    n, m = _select(d, s, e, ALL)
    _tree_envelope(d, s, e, n)
    for i in range(d.n_dofs):  # M within its envelope (the upper triangle is never written)
        root = d.solver_dof_tree[s, e, i]
        for j in range(root, i + 1):
            d.solver_H[s, e, i, j] = d.solver_M[s, e, i, j]
        d.solver_env[s, e, i] = root
        d.qacc_smooth[s, e, i] = d.qfrc_smooth[s, e, i]
        d.qfrc_constraint[s, e, i] = 0.0
    # M's factor: qacc_smooth now; each island replaces its block with its Hessian's factor,
    # unconstrained dofs keep it (H = M there)
    _cholesky(d, s, e, n)
    _factor_solve(d, d.qacc_smooth, s, e, n)
    for r in range(d.n_efc[s, e, 0]):
        d.efc_force[s, e, r], d.efc_state[s, e, r] = 0.0, SATISFIED
    niter = 0
    if replaying:  # (solver_jar holds the forward's too)
        for i in range(d.n_dofs):
            d.qacc[s, e, i] = d.qacc_constrained[s, e, i]
    else:
        _warm_start(d, s, e, n, m)
    for k in range(d.n_dofs):
        if d.solver_tree[s, e, k] == k:  # k is an island's canonical root
            island_niter, capped = _solve_island(d, s, e, k, iterations, tolerance, ls_iterations, ls_tolerance,
                                                 replaying)
            niter += island_niter
            if capped:  # (every writer writes 1)
                d.capped[0] = 1
    d.solver_niter[s, e] = niter
