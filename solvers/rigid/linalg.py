"""Acceleration stage: qacc = A⁻¹ qfrc_smooth with A = M + diag(armature + h·damping).

The h·damping term makes joint damping implicit, as MuJoCo's Euler integrator does. A is
factored as A = Lᵀ D L along the dof tree (Featherstone's LTDL): L[k, i] is non-zero only for
dofs i on the path from k to the root, so there is no fill-in, the cost is Σ depth², and
separate bodies never mix (a NaN in one stays there). Taichi's reverse mode gives wrong
gradients for factorisations (TAICHI_NOTES.md), so the adjoint is written by hand: with
y = A⁻¹ q̄acc (A is symmetric), f̄ += y and Ā −= y qaccᵀ — one more solve with the stored factor.
"""
import taichi as ti

from .data import accumulate


@ti.func
def _factor(d: ti.template(), s, e):
    """factor[s, e] ← D (diagonal) and L (strictly lower, on the dof tree) of A."""
    h = d.consts[0]
    for k in range(d.n_dofs):
        j = k
        while j != -1:
            d.factor[s, e, k, j] = d.mass_mat[s, e, k, j]
            j = d.dof_parent[j]
        accumulate(d.factor, ti.Vector([s, e, k, k]), d.armature[e, k] + h * d.damping[e, k])
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
def solve_env(d: ti.template(), s, e):
    """qacc = A⁻¹ (qfrc_smooth + qfrc_constraint): the constraint force, solved for with M alone,
    goes through the damped matrix like every other force (MuJoCo's Euler integrator). Without
    damping MuJoCo integrates the constraint solve's own acceleration, which differs from that
    by the solve's tolerance: so do we."""
    _factor(d, s, e)
    undamped = True
    for i in range(d.n_dofs):
        d.qacc[s, e, i] = d.qfrc_smooth[s, e, i]
        if d.row_capacity > 0:
            d.qacc[s, e, i] += d.qfrc_constraint[s, e, i]
            undamped = undamped and d.damping[e, i] == 0.0
    _solve_in_place(d, s, e, d.qacc)
    if d.row_capacity > 0 and undamped and d.n_efc[s, e, 0] > 0:
        for i in range(d.n_dofs):
            d.qacc[s, e, i] = d.qacc_constrained[s, e, i]
    elif d.row_capacity > 0 and d.n_efc[s, e, 0] == 0:  # the next solve starts from this acceleration
        # (MuJoCo's rule; after a solve, constraint_env already stored the solve's own)
        for i in range(d.n_dofs):
            d.qacc_warmstart[e, i] = d.qacc[s, e, i]


@ti.func
def solve_adjoint_env(d: ti.template(), s, e):
    """Reverse of ``solve_env`` for frame s. Sets qfrc_smooth.grad[s, e] (the solve is the only
    reader of qfrc_smooth) and adds to the gradients of M, armature and damping."""
    h = d.consts[0]
    for i in range(d.n_dofs):
        d.qfrc_smooth.grad[s, e, i] = d.qacc.grad[s, e, i]
    _solve_in_place(d, s, e, d.qfrc_smooth.grad)
    for i in range(d.n_dofs):
        y = d.qfrc_smooth.grad[s, e, i]
        j = i  # only the structural entries of M (on the dof tree) are inputs of the solve
        while j != -1:
            g = y * d.qacc[s, e, j] + (d.qfrc_smooth.grad[s, e, j] * d.qacc[s, e, i] if j != i else 0.0)
            accumulate(d.mass_mat.grad, ti.Vector([s, e, i, j]), -g)
            j = d.dof_parent[j]
        accumulate(d.armature.grad, ti.Vector([e, i]), -y * d.qacc[s, e, i])
        accumulate(d.damping.grad, ti.Vector([e, i]), -h * y * d.qacc[s, e, i])
