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

Joint rows (equalities, friction loss, joint limits) pass their parameters' gradients on to q, q̇,
the friction loss and dof_invweight0 (rows.dof_rows_adjoint), contact rows theirs on to the
contact's frame, position, distance and parameters (rows.contact_rows_adjoint).
"""
import taichi as ti

from ..data import accumulate
from .rows import contact_included, contact_rows_adjoint, dof_rows_adjoint, row_times, rows_per_contact
from .solver import CONE, LINEARNEG, LINEARPOS, QUADRATIC, add_mul_M, cholesky_solve, cone_coordinates, \
    cone_hessian_entry


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
    qfrc_constraint into those of qfrc_smooth, the mass matrix, armature and the joint and
    contact rows' inputs. Scratch: solver_Mgrad ← u = H⁻¹ ā, solver_Mv ← q̄frc_constraint − u (M's gradient is
    that times aᵀ)."""
    u, g_mass = d.solver_Mgrad, d.solver_Mv
    for i in range(d.n_dofs):  # ā = q̄acc_constrained + M q̄frc_constraint
        u[s, e, i] = d.qacc_constrained.grad[s, e, i]
    add_mul_M(d, s, e, d.n_dofs, False, d.qfrc_constraint.grad, u)
    cholesky_solve(d, u, s, e)
    for i in range(d.n_dofs):
        accumulate(d.qfrc_smooth.grad, ti.Vector([s, e, i]), u[s, e, i] - d.qfrc_constraint.grad[s, e, i])
        g_mass[s, e, i] = d.qfrc_constraint.grad[s, e, i] - u[s, e, i]
    _add_mass_grad(d, s, e, g_mass, d.qacc_constrained)
    for r in range(d.efc_dof_rows[s, e, 0]):
        w = row_times(d, s, e, r, u)
        state = d.efc_state[s, e, r]
        g_aref, g_R, g_bound = 0.0, 0.0, 0.0
        if state == QUADRATIC:
            g_aref, g_R = _quadratic_row(d, s, e, r, w)
        elif state == LINEARNEG:
            g_bound = w
        elif state == LINEARPOS:
            g_bound = -w
        dof_rows_adjoint(d, s, e, r, g_aref, g_R, g_bound)
    for c in range(d.n_con[s, e, 0]):
        if contact_included(d, s, e, c):
            _contact_adjoint(d, s, e, c)


@ti.func
def _quadratic_row(d: ti.template(), s, e, r, w):
    """(āref, R̄) of row r in its quadratic piece (f = −jar/R), w = J_r·u."""
    R = d.efc_R[s, e, r]
    return w / R, w * d.solver_jar[s, e, r] / (R * R)


@ti.func
def _cone_adjoint(d: ti.template(), s, e, r, w):
    """(āref, R̄, μ̄) (each (d.row_slots,)) of the elliptic block at row r in the middle zone,
    w_j = J_j·u.
    There f_0 = −D_0 (jar_0 − T) / (1 + μ²) and f_j = −f_0 μ_j² jar_j / T (T = |μ_j jar_j|,
    μ = efc_mu of the normal row, μ_j of tangent j): āref = H_c w (H_c the block's Hessian
    in jar, as the solve has it), R̄_0 = −(w·f)/R_0, μ̄ = −2μ (w·f)/(1 + μ²), and μ̄_j through T."""
    dim, mu = d.efc_dim[s, e, r], d.efc_mu[s, e, r]
    N, Tsqr = cone_coordinates(d, s, e, r)
    T = ti.sqrt(Tsqr)
    g_aref = ti.Vector.zero(float, d.row_slots)
    g_R, g_mu = ti.Vector.zero(float, d.row_slots), ti.Vector.zero(float, d.row_slots)
    w_force, tangential = 0.0, 0.0  # w·f, and S = Σ_{k≥1} w_k μ_k² jar_k
    for a in range(dim):
        for b in range(dim):
            g_aref[a] += cone_hessian_entry(d, s, e, r, a, b, N, T) * w[b]
        w_force += w[a] * d.efc_force[s, e, r + a]
        if a > 0:
            mu_a = d.efc_mu[s, e, r + a]
            tangential += w[a] * mu_a * mu_a * d.solver_jar[s, e, r + a]
    g_R[0] = -w_force / d.efc_R[s, e, r]
    g_mu[0] = -2.0 * mu / (1.0 + mu * mu) * w_force
    kappa, f0 = 1.0 / (d.efc_R[s, e, r] * (1.0 + mu * mu)), d.efc_force[s, e, r]
    for j in range(1, dim):
        mu_j, jar_j = d.efc_mu[s, e, r + j], d.solver_jar[s, e, r + j]
        dT = mu_j * jar_j * jar_j / T  # ∂T/∂μ_j
        g_mu[j] = kappa * dT * (w[0] - tangential / T) - f0 * (2.0 * w[j] * mu_j * jar_j / T - dT * tangential / Tsqr)
    return g_aref, g_R, g_mu


@ti.func
def _contact_adjoint(d: ti.template(), s, e, c):
    """Contact c's rows: their implicit gradients (quadratic rows as above, an elliptic block in
    its middle zone by _cone_adjoint, satisfied rows none), then rows.contact_rows_adjoint."""
    first = d.con_efc[s, e, c]
    n = rows_per_contact(d, d.pair_condim[d.con_pair[s, e, c]])
    w, force = ti.Vector.zero(float, d.row_slots), ti.Vector.zero(float, d.row_slots)
    col0, ncol = d.efc_col0[s, e, first], d.efc_ncol[s, e, first]  # (the contact's rows share its columns)
    for j in range(n):
        for a in range(ncol):
            i = d.efc_cols[s, e, col0 + a]
            w[j] += d.efc_J[s, e, first + j, i] * d.solver_Mgrad[s, e, i]
        force[j] = d.efc_force[s, e, first + j]
    g_aref = ti.Vector.zero(float, d.row_slots)
    g_R, g_mu = ti.Vector.zero(float, d.row_slots), ti.Vector.zero(float, d.row_slots)
    in_cone = False
    if ti.static(d.elliptic):  # (a pyramidal solve has no cone state: its kernels leave this out)
        in_cone = d.efc_state[s, e, first] == CONE
    if in_cone:
        g_aref, g_R, g_mu = _cone_adjoint(d, s, e, first, w)
    else:
        for j in range(n):
            if d.efc_state[s, e, first + j] == QUADRATIC:
                aref_j, R_j = _quadratic_row(d, s, e, first + j, w[j])
                g_aref[j], g_R[j] = aref_j, R_j
    contact_rows_adjoint(d, s, e, c, force, g_aref, g_R, g_mu)
