"""Acceleration stage: qacc = A⁻¹ qfrc_smooth with A = M + diag(armature + h·(damping + kv_servo)).

The h·damping term makes joint damping implicit, as MuJoCo's Euler integrator does, and h·kv_servo
(kv of a dof in position or velocity control, actuation.servo_kv) the servo's velocity term, as
Genesis's default integrator does (and MuJoCo's implicitfast, for servos within their force range).

A is factored as A = Lᵀ D L along the dof tree (Featherstone's LTDL): L[k, i] is non-zero only for
dofs i on the path from k to the root, so there is no fill-in, the cost is Σ depth², and
separate bodies never mix (a NaN in one stays there). Taichi's reverse mode gives wrong
gradients for factorisations (TAICHI_NOTES.md), so the adjoint is written by hand: with
y = A⁻¹ q̄acc (A is symmetric), f̄ += y and Ā −= y qaccᵀ — one more solve with the stored factor.
In a step with a constraint stage the force includes qfrc_constraint, or the acceleration is the
solve's own (see _undamped_solution); the solve's adjoint is constraint/implicit.py.
"""
import taichi as ti

from .actuation import in_servo_mode, servo_kv
from .data import accumulate


@ti.func
def _factor(d: ti.template(), s, e, damped: ti.template()):
    """factor[s, e] ← D (diagonal) and L (strictly lower, on the dof tree) of A (damped: False,
    of M + diag(armature), MuJoCo's M)."""
    h = d.consts[0]
    for k in range(d.n_dofs):
        j = k
        while j != -1:
            d.factor[s, e, k, j] = d.mass_mat[s, e, k, j]
            j = d.dof_parent[j]
        diagonal = d.armature[e, k]
        if ti.static(damped):
            diagonal += h * (d.damping[e, k] + servo_kv(d, e, k))
        accumulate(d.factor, ti.Vector([s, e, k, k]), diagonal)
    for r in range(d.n_dofs):
        k = d.n_dofs - 1 - r
        i = d.dof_parent[k]
        while i != -1:
            ratio = d.factor[s, e, k, i] / d.factor[s, e, k, k]
            j = i
            while j != -1:
                accumulate(d.factor, ti.Vector([s, e, i, j]), -ratio * d.factor[s, e, k, j])
                j = d.dof_parent[j]
            d.factor[s, e, k, i] = ratio
            i = d.dof_parent[i]


@ti.func
def _solve_in_place(d: ti.template(), s, e, x: ti.template()):
    """Overwrite x[s, e, :] (holding b) with A⁻¹ b: solve Lᵀ, then D, then L."""
    for r in range(d.n_dofs):
        k = d.n_dofs - 1 - r
        i = d.dof_parent[k]
        while i != -1:
            accumulate(x, ti.Vector([s, e, i]), -d.factor[s, e, k, i] * x[s, e, k])
            i = d.dof_parent[i]
    for k in range(d.n_dofs):
        x[s, e, k] = x[s, e, k] / d.factor[s, e, k, k]
    for k in range(d.n_dofs):
        i = d.dof_parent[k]
        while i != -1:
            accumulate(x, ti.Vector([s, e, k]), -d.factor[s, e, k, i] * x[s, e, i])
            i = d.dof_parent[i]


@ti.func
def _undamped_solution(d: ti.template(), s, e):
    """Whether frame s integrates the constraint solve's own acceleration: it had rows and no dof
    is damped (joint damping or a servo's kv). MuJoCo does so; with damping the constraint force,
    solved for with M alone, goes through the damped matrix like every other force."""
    return d.n_efc[s, e, 0] > 0 and not _damped(d, e)


@ti.func
def _damped(d: ti.template(), e):
    """Whether a dof of env e is damped: joint damping or a servo's kv, A ≠ M."""
    damped = False
    for i in range(d.n_dofs):
        damped = damped or d.damping[e, i] != 0.0 or servo_kv(d, e, i) != 0.0
    return damped


@ti.func
def solve_env(d: ti.template(), s, e, rows: ti.template()):
    """qacc = A⁻¹ (qfrc_smooth + qfrc_constraint), or the solve's qacc_constrained (see
    _undamped_solution); rows: whether the step has a constraint stage (compile time).

    The next constraint solve starts from this step's MuJoCo qacc (mj_advance's warm start): the
    solve's, which constraint_env stored, else qacc_smooth = M⁻¹ qfrc_smooth, without damping (its
    damped acceleration is a local of MuJoCo's integrator): factored apart only where a dof is
    damped, before A's factor, which the reverse reads. A step without a constraint stage (rows
    False: a scene without contact pairs takes its row-less steps fused) keeps the damped
    acceleration: the rows it may meet later (limits, equalities, friction loss) are piecewise
    quadratic, which the solve ends exactly from any start."""
    warm_started = False
    if ti.static(rows):
        warm_started = d.n_efc[s, e, 0] > 0
        if not warm_started and _damped(d, e):
            _factor(d, s, e, False)
            for i in range(d.n_dofs):
                d.qacc[s, e, i] = d.qfrc_smooth[s, e, i]
            _solve_in_place(d, s, e, d.qacc)
            for i in range(d.n_dofs):
                d.qacc_warmstart[e, i] = d.qacc[s, e, i]
            warm_started = True
    _factor(d, s, e, True)
    for i in range(d.n_dofs):
        d.qacc[s, e, i] = d.qfrc_smooth[s, e, i]
        if ti.static(rows):
            accumulate(d.qacc, ti.Vector([s, e, i]), d.qfrc_constraint[s, e, i])
    _solve_in_place(d, s, e, d.qacc)
    if ti.static(rows):
        if _undamped_solution(d, s, e):
            for i in range(d.n_dofs):
                d.qacc[s, e, i] = d.qacc_constrained[s, e, i]
    if not warm_started:  # undamped and without rows: qacc is M⁻¹ qfrc_smooth
        for i in range(d.n_dofs):
            d.qacc_warmstart[e, i] = d.qacc[s, e, i]


@ti.func
def solve_adjoint_env(d: ti.template(), s, e, rows: ti.template()):
    """Reverse of ``solve_env`` for frame s. Sets qfrc_smooth.grad[s, e] and, with rows, the
    gradients of qacc_constrained and qfrc_constraint (the constraint solve's adjoint takes them
    on), and adds to the gradients of M, armature, damping and a servo's kv."""
    h = d.consts[0]
    undamped = False
    if ti.static(rows):
        undamped = _undamped_solution(d, s, e)
        for i in range(d.n_dofs):
            d.qacc_constrained.grad[s, e, i] = d.qacc.grad[s, e, i] if undamped else 0.0
    for i in range(d.n_dofs):
        d.qfrc_smooth.grad[s, e, i] = 0.0 if undamped else d.qacc.grad[s, e, i]
    if undamped:  # damping still has its (one-sided) derivative at 0: any damping > 0 gives A⁻¹(...)
        y = d.solver_search  # the solve's scratch, free in the reverse
        for i in range(d.n_dofs):
            y[s, e, i] = d.qacc.grad[s, e, i]
        _solve_in_place(d, s, e, y)
        for i in range(d.n_dofs):
            _accumulate_damping_grad(d, e, i, -h * y[s, e, i] * d.qacc[s, e, i])
    else:
        _solve_in_place(d, s, e, d.qfrc_smooth.grad)
        for i in range(d.n_dofs):
            y = d.qfrc_smooth.grad[s, e, i]
            j = i  # only the structural entries of M (on the dof tree) are inputs of the solve
            while j != -1:
                g = y * d.qacc[s, e, j] + (d.qfrc_smooth.grad[s, e, j] * d.qacc[s, e, i] if j != i else 0.0)
                accumulate(d.mass_mat.grad, ti.Vector([s, e, i, j]), -g)
                j = d.dof_parent[j]
            accumulate(d.armature.grad, ti.Vector([e, i]), -y * d.qacc[s, e, i])
            _accumulate_damping_grad(d, e, i, -h * y * d.qacc[s, e, i])
    if ti.static(rows):
        for i in range(d.n_dofs):
            d.qfrc_constraint.grad[s, e, i] = 0.0 if undamped or d.n_efc[s, e, 0] == 0 \
                else d.qfrc_smooth.grad[s, e, i]


@ti.func
def _accumulate_damping_grad(d: ti.template(), e, i, g):
    """g = h·∂L/∂A[i, i], added to damping's gradient and, for a dof in a servo mode, to kv's: both
    enter A[i, i] as h·(damping + kv_servo)."""
    accumulate(d.damping.grad, ti.Vector([e, i]), g)
    if in_servo_mode(d, e, i):
        accumulate(d.kv.grad, ti.Vector([e, i]), g)
