"""Reverse of the constraint solve, by implicit differentiation at its solution.

The solve (solver.py) returns a = qacc_constrained minimising the convex cost; there its gradient
vanishes: M a − qfrc_smooth − Jᵀ f(J a − aref) = 0, with each row's force f a function of its
jar = J a − aref and of its parameters (aref, R, a friction-loss bound F). Differentiating that
identity with the active set (efc_state) held fixed:

    H da = d qfrc_smooth − dM a + Jᵀ (∂f/∂θ) dθ,   H = M + Σ_quadratic Jᵀ D J + cone blocks,

the Hessian the solve factored last (solver_H, H = L Lᵀ). So one more solve with that factor,
u = H⁻¹ ā, gives every gradient: q̄frc_smooth += u, M̄ −= u aᵀ, and per row, with w = J_r·u,
θ̄ = (∂f/∂θ)·w: a quadratic row (f = −jar/R) has āref = w/R and R̄ = w·jar/R², a saturated
friction-loss row (f = ±F) has F̄ = ±w, a satisfied row nothing. The solve's tolerance, its
iterations and its warm start have no term: the gradient is that of the exact solution at the
point the solve returned.

qfrc_constraint = Jᵀ f, read by the damped integration (linalg.solve_env), equals M a −
qfrc_smooth at the solution, so its gradient reaches a, M and qfrc_smooth through that form.

Rows of single dofs (friction loss, joint limits) pass their parameters' gradients on to q, q̇
and the friction loss (rows.dof_rows_adjoint); contact rows have no adjoint yet (the solver
refuses a backward through a step with contacts).
"""
import taichi as ti

from ..data import accumulate
from .rows import dof_rows_adjoint
from .solver import ALL, LINEARNEG, LINEARPOS, QUADRATIC, cholesky_solve


@ti.func
def _add_mass_grad(d: ti.template(), s, e, x: ti.template(), y: ti.template()):
    """Gradients of the solve's M (mass matrix + armature) ← += x yᵀ, onto the entries that are
    inputs: M[i, j] for j on i's dof path to the root, used at (i, j) and (j, i)."""
    for i in range(d.n_dofs):
        j = i
        while j != -1:
            g = x[s, e, i] * y[s, e, j] + (x[s, e, j] * y[s, e, i] if j != i else 0.0)
            accumulate(d.mass_mat.grad, ti.Vector([s, e, i, j]), g)
            j = d.dof_parent[j]
        accumulate(d.armature.grad, ti.Vector([e, i]), x[s, e, i] * y[s, e, i])


@ti.func
def solve_adjoint(d: ti.template(), s, e):
    """Reverse of frame s's constraint solve: from the gradients of qacc_constrained and
    qfrc_constraint into those of qfrc_smooth, the mass matrix, armature and the single-dof rows'
    inputs. Scratch: solver_Mgrad ← u = H⁻¹ ā, solver_Mv ← q̄frc_constraint − u (M's gradient is
    that times aᵀ)."""
    u, g_mass = d.solver_Mgrad, d.solver_Mv
    for i in range(d.n_dofs):  # ā = q̄acc_constrained + M q̄frc_constraint
        acc = d.qacc_constrained.grad[s, e, i]
        for j in range(d.n_dofs):
            acc += d.solver_M[s, e, i, j] * d.qfrc_constraint.grad[s, e, j]
        u[s, e, i] = acc
    cholesky_solve(d, d.solver_H, u, s, e, ALL)
    for i in range(d.n_dofs):
        accumulate(d.qfrc_smooth.grad, ti.Vector([s, e, i]), u[s, e, i] - d.qfrc_constraint.grad[s, e, i])
        g_mass[s, e, i] = d.qfrc_constraint.grad[s, e, i] - u[s, e, i]
    _add_mass_grad(d, s, e, g_mass, d.qacc_constrained)
    for r in range(d.efc_dof_rows[s, e, 0]):
        i = d.efc_id[s, e, r]
        w = d.efc_J[s, e, r, i] * u[s, e, i]
        state, R = d.efc_state[s, e, r], d.efc_R[s, e, r]
        g_aref, g_R, g_bound = 0.0, 0.0, 0.0
        if state == QUADRATIC:
            g_aref, g_R = w / R, w * d.solver_jar[s, e, r] / (R * R)
        elif state == LINEARNEG:
            g_bound = w
        elif state == LINEARPOS:
            g_bound = -w
        dof_rows_adjoint(d, s, e, r, g_aref, g_R, g_bound)
