"""Acceleration stage: qacc = A⁻¹ qfrc_smooth with A = M + diag(armature + h·damping).

The h·damping term makes joint damping implicit, as MuJoCo's Euler integrator does. A is
factored densely (Cholesky, A = L Lᵀ) per env. Taichi's reverse mode gives wrong gradients for
factorisations (TAICHI_NOTES.md), so the adjoint is written by hand: with y = A⁻ᵀ q̄acc,
f̄ += y and Ā −= y qaccᵀ (one more solve with the stored factor).
"""
import taichi as ti


@ti.func
def _factor(d: ti.template(), s, e):
    h = d.consts[0]
    for j in range(d.n_dofs):
        diag = d.mass_mat[s, e, j, j] + d.armature[e, j] + h * d.damping[e, j]
        for k in range(j):
            diag -= d.chol[s, e, j, k] ** 2
        pivot = ti.sqrt(diag)
        d.chol[s, e, j, j] = pivot
        for i in range(j + 1, d.n_dofs):
            value = d.mass_mat[s, e, i, j]
            for k in range(j):
                value -= d.chol[s, e, i, k] * d.chol[s, e, j, k]
            d.chol[s, e, i, j] = value / pivot


@ti.func
def _solve_in_place(d: ti.template(), s, e, x: ti.template()):
    """Overwrite x[s, e, :] (holding b) with A⁻¹ b using the stored factor."""
    for i in range(d.n_dofs):
        value = x[s, e, i]
        for k in range(i):
            value -= d.chol[s, e, i, k] * x[s, e, k]
        x[s, e, i] = value / d.chol[s, e, i, i]
    for r in range(d.n_dofs):
        i = d.n_dofs - 1 - r
        value = x[s, e, i]
        for k in range(i + 1, d.n_dofs):
            value -= d.chol[s, e, k, i] * x[s, e, k]
        x[s, e, i] = value / d.chol[s, e, i, i]


@ti.func
def solve_env(d: ti.template(), s, e):
    _factor(d, s, e)
    for i in range(d.n_dofs):
        d.qacc[s, e, i] = d.qfrc_smooth[s, e, i]
    _solve_in_place(d, s, e, d.qacc)


@ti.kernel
def solve(d: ti.template(), s: ti.i32):
    for e in range(d.n_batch):
        solve_env(d, s, e)


@ti.kernel
def solve_adjoint(d: ti.template(), s: ti.i32):
    """Reverse of ``solve`` for frame s; qfrc_smooth.grad[s] must be zero on entry."""
    h = d.consts[0]
    for e in range(d.n_batch):
        for i in range(d.n_dofs):
            d.qfrc_smooth.grad[s, e, i] = d.qacc.grad[s, e, i]
        _solve_in_place(d, s, e, d.qfrc_smooth.grad)
        for i in range(d.n_dofs):
            y = d.qfrc_smooth.grad[s, e, i]
            for j in range(d.n_dofs):
                d.mass_mat.grad[s, e, i, j] -= y * d.qacc[s, e, j]
            d.armature.grad[e, i] -= y * d.qacc[s, e, i]
            d.damping.grad[e, i] -= h * y * d.qacc[s, e, i]
