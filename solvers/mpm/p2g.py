"""Particle to grid (p2g): each particle's material update and stress, then the scatter of its
mass and APIC momentum to the 27 nodes around it; and their adjoints.

Forward, per particle p of env e (h the substep, κ = 4 h vol inv_dx²):
    F_tmp = (I + h C) F;  (F', Jp', τ) = constitutive(F_tmp, Jp);  A = −κ τ + m C  (m = ρ vol)
    P_i += w_i (m v + A (x_i − x)),  M_i += w_i m   over the 27 nodes i (x_i − x = (offset − fx) dx).
The scatter's reverse is a gather (parallel over particles): every particle reads the gradients
(∂L/∂P_i, ∂L/∂M_i) of its nodes; then the stress's adjoint, with the affine matrix and SVD(F_tmp)
the replay kept. Terms that are the same for every node (A's part through x_i − x, Aᵀ Σ w ∂L/∂P_i)
are taken once per particle; the per-node products of A with the offsets come from per-axis rows
(stencil.column_terms).
"""
import taichi as ti

from .constitutive import constitutive_adjoint_decomposed, constitutive_decomposed, decompose_pair, needs_svd
from .layout import SVD_WIDTH, WIDTH
from .stencil import (axis_offsets, cell_of, column_terms, matrix_row, node_at, node_count, node_vector, row_at,
                      row_matrix, row_vector, scatter_half, scatter_spread, stencil_row, store_matrix, store_vector,
                      transposed_times, weight_grads, weights)


@ti.func
def stress_stage(takes_svd: ti.template(), frames: ti.template(), params: ti.template(), kinds: ti.template(),
                 consts: ti.template(), fiber: ti.template(), affine: ti.template(), svd: ti.template(),
                 grid_f: ti.template(), src, dst, keep):
    """Per particle: the material update F, Jp → frame dst, and the affine momentum matrix →
    affine's slot max(keep, 0). A replay (keep = s ≥ 0) keeps what the reverse reads: the affine
    matrix in slot s, and SVD(F_tmp) in svd's slot s for the materials that take one.
    takes_svd (compile time): whether any of the scene's materials takes an SVD. Then particles go
    two at a time (2q, 2q + 1), their SVDs interleaved (constitutive.decompose_pair: the Jacobi
    sweeps wait on divisions and square roots, which two independent ones overlap); else one at a
    time, with no SVD (the pairs' structure cost a neo-Hookean substep 3–5 %)."""
    h = grid_f[0]
    B, N = params.shape[0], params.shape[1]
    if ti.static(takes_svd):
        for e, pair in ti.ndrange(B, (N + 1) // 2):
            first, second = 2 * pair, ti.min(2 * pair + 1, N - 1)
            C_first, F_first = deformation(frames, row_at(src, e, first, B, N, WIDTH), h)
            C_second, F_second = deformation(frames, row_at(src, e, second, B, N, WIDTH), h)
            J_first, U_first, sig_first, V_first, J_second, U_second, sig_second, V_second = decompose_pair(
                kinds[first], material_consts(consts, first), F_first, kinds[second], material_consts(consts, second),
                F_second)
            for half in range(1 + int(second > first)):  # one call site: the material code is inlined once
                p, C, F_tmp, J, U, sig, V = first, C_first, F_first, J_first, U_first, sig_first, V_first
                if half == 1:
                    p, C, F_tmp, J, U, sig, V = second, C_second, F_second, J_second, U_second, sig_second, V_second
                material_update(takes_svd, frames, params, kinds, consts, fiber, affine, svd, grid_f, src, dst, keep,
                                e, p, C, F_tmp, J, U, sig, V)
    else:
        for e, p in ti.ndrange(B, N):
            C, F_tmp = deformation(frames, row_at(src, e, p, B, N, WIDTH), h)
            identity = ti.Matrix.identity(float, 3)  # the SVD of a material that takes none (as decompose)
            material_update(takes_svd, frames, params, kinds, consts, fiber, affine, svd, grid_f, src, dst, keep, e,
                            p, C, F_tmp, F_tmp.determinant(), identity, ti.Vector([1.0, 1.0, 1.0], float), identity)


@ti.func
def deformation(frames: ti.template(), src_at, h):
    """(C, F_tmp = (I + h C) F) of the particle row at src_at."""
    C = row_matrix(frames, src_at + 6)
    return C, (ti.Matrix.identity(float, 3) + h * C) @ row_matrix(frames, src_at + 15)


@ti.func
def material_consts(consts: ti.template(), p):
    """Particle p's material constants (layout.N_CONSTS vector; constitutive.encode says what)."""
    return ti.Vector([consts[p, 0], consts[p, 1], consts[p, 2], consts[p, 3]])


@ti.func
def material_update(takes_svd: ti.template(), frames: ti.template(), params: ti.template(), kinds: ti.template(),
                    consts: ti.template(), fiber: ti.template(), affine: ti.template(), svd: ti.template(),
                    grid_f: ti.template(), src, dst, keep, e, p, C, F_tmp, J, U, sig, V):
    """stress_stage for particle p of env e, given its C, F_tmp and decomposition (J, U, σ, V)."""
    h, vol, inv_dx = grid_f[0], grid_f[2], grid_f[1]
    B, N = params.shape[0], params.shape[1]
    kind, c = kinds[p], material_consts(consts, p)
    if ti.static(takes_svd):  # (else svd is a 1-sized dummy)
        if keep >= 0 and needs_svd(kind, c):
            svd_at = row_at(keep, e, p, B, N, SVD_WIDTH)
            store_matrix(svd, svd_at, U)
            store_vector(svd, svd_at + 9, sig)
            store_matrix(svd, svd_at + 12, V)
    d = ti.Vector([fiber[p, 0], fiber[p, 1], fiber[p, 2]])
    F_new, Jp_new, tau = constitutive_decomposed(kind, c, params[e, p, 0], params[e, p, 1], params[e, p, 3], d, F_tmp,
                                                 frames[row_at(src, e, p, B, N, WIDTH) + 24], J, U, sig, V)
    dst_at = row_at(dst, e, p, B, N, WIDTH)
    store_matrix(frames, dst_at + 15, F_new)
    frames[dst_at + 24] = Jp_new
    mass = params[e, p, 2] * vol
    aff = (-h * vol * 4.0 * inv_dx * inv_dx) * tau + mass * C
    store_matrix(affine, row_at(ti.max(keep, 0), e, p, B, N, 9), aff)


@ti.func
def scatter_stage(frames: ti.template(), params: ti.template(), affine: ti.template(), grid: ti.template(),
                  active: ti.template(), part_grid: ti.template(), part_nodes: ti.template(), grid_f: ti.template(),
                  grid_i: ti.template(), src, slot):
    """p2g, deterministic, on two threads (stencil.scatter_spread): each env's first half of the
    particles scattered into grid (listing its nodes in active), the second into part_grid
    (listing in part_nodes); merge_stage then adds the second into the first. The affine matrices
    are read from affine's slot ``slot``."""
    B, N = params.shape[0], params.shape[1]
    for t in range(2 * B * scatter_spread(B)):
        working, e, second, first, end = scatter_half(t, B, N)
        if working and second == 0:
            scatter_range(frames, params, affine, grid, active, grid_f, grid_i, src, slot, e, first, end)
        elif working:
            scatter_range(frames, params, affine, part_grid, part_nodes, grid_f, grid_i, src, slot, e, first, end)


@ti.func
def scatter_range(frames: ti.template(), params: ti.template(), affine: ti.template(), grid: ti.template(),
                  nodes: ti.template(), grid_f: ti.template(), grid_i: ti.template(), src, slot, e, first, end):
    """Env e's particles first..end − 1 scattered into ``grid`` (flat B · K · 4: momentum, mass),
    serially in particle order; ``nodes`` (B + 1, K + 1) lists each node on first touch (count, then
    nodes)."""
    inv_dx, vol, K = grid_f[1], grid_f[2], node_count(grid_i)
    B, N = params.shape[0], params.shape[1]
    count = 0
    for p in range(first, end):
        src_at = row_at(src, e, p, B, N, WIDTH)
        base, fx = cell_of(row_vector(frames, src_at), inv_dx, grid_i)
        mass = params[e, p, 2] * vol
        momentum = mass * row_vector(frames, src_at + 3)
        aff = row_matrix(affine, row_at(slot, e, p, B, N, 9))
        W = weights(fx)
        # aff @ (x_i − x) per node from per-axis rows, summed in a matrix product's order
        D = axis_offsets(fx) / inv_dx
        A_x, A_y, A_z = column_terms(aff, D, 0), column_terms(aff, D, 1), column_terms(aff, D, 2)
        for i in range(3):
            for j in range(3):
                row = stencil_row(grid_i, base, i, j)
                line_at = node_at(e, row, K)
                w_ij = W[i, 0] * W[j, 1]
                aff_ij = matrix_row(A_x, i) + matrix_row(A_y, j)
                for k in range(3):
                    at = line_at + 4 * k
                    w = w_ij * W[k, 2]
                    contribution = w * (momentum + (aff_ij + matrix_row(A_z, k)))
                    old_mass = grid[at + 3]
                    for c in ti.static(range(3)):
                        grid[at + c] = grid[at + c] + contribution[c]
                    grid[at + 3] = old_mass + w * mass
                    if old_mass == 0.0 and w * mass > 0.0:
                        count += 1
                        nodes[e, count] = row + k
    nodes[e, 0] = count


@ti.func
def scatter_reverse(grad_grid: ti.template(), env_at, base, W, dW, D, aff, momentum, mass, grid_i: ti.template()):
    """One particle's gather of its 27 nodes' (∂L/∂P_i, ∂L/∂M_i) (grad_grid, env starting at
    env_at), the reverse of P_i += w_i (m v + A (x_i − x)), M_i += w_i m with the weights
    and offsets (D, m) taken as fixed, and of the weights' dependence on fx:
    (Σ w ∂L/∂P (3), Σ w ∂L/∂P ⊗ (x_i − x) (3×3), Σ w ∂L/∂M, Σ s_i ∂w_i/∂fx (3)) with
    s_i = ∂L/∂P_i · (m v + A (x_i − x)) + ∂L/∂M_i m. The weights, offsets and derivatives factor
    per axis (w = W[i, 0] W[j, 1] W[k, 2]), so the sums run axis by axis, innermost z: per node the
    scalar s and five multiply-adds (as g2p's gather_velocity)."""
    # A (x_i − x) at node (i, j, k) = row i of A_x + row j of A_y + row k of A_z
    A_x, A_y, A_z = column_terms(aff, D, 0), column_terms(aff, D, 1), column_terms(aff, D, 2)
    g_momentum, g_x, g_y, g_z = (ti.Vector.zero(float, 3), ti.Vector.zero(float, 3), ti.Vector.zero(float, 3),
                                 ti.Vector.zero(float, 3))
    g_mass = 0.0
    g_fx = ti.Vector.zero(float, 3)
    for i in range(3):
        plane, plane_y, plane_z = ti.Vector.zero(float, 3), ti.Vector.zero(float, 3), ti.Vector.zero(float, 3)
        plane_M, plane_s, plane_s_y, plane_s_z = 0.0, 0.0, 0.0, 0.0
        for j in range(3):
            line_at = env_at + 4 * stencil_row(grid_i, base, i, j)
            moved_ij = momentum + (matrix_row(A_x, i) + matrix_row(A_y, j))
            line, line_z = ti.Vector.zero(float, 3), ti.Vector.zero(float, 3)
            line_M, line_s, line_s_z = 0.0, 0.0, 0.0
            for k in range(3):
                at = line_at + 4 * k
                g_P, g_M = node_vector(grad_grid, at), grad_grid[at + 3]
                s = g_P.dot(moved_ij + matrix_row(A_z, k)) + g_M * mass
                line += W[k, 2] * g_P
                line_z += (W[k, 2] * D[k, 2]) * g_P
                line_M += W[k, 2] * g_M
                line_s += W[k, 2] * s
                line_s_z += dW[k, 2] * s
            plane += W[j, 1] * line
            plane_y += (W[j, 1] * D[j, 1]) * line
            plane_z += W[j, 1] * line_z
            plane_M += W[j, 1] * line_M
            plane_s += W[j, 1] * line_s
            plane_s_y += dW[j, 1] * line_s
            plane_s_z += W[j, 1] * line_s_z
        g_momentum += W[i, 0] * plane
        g_x += (W[i, 0] * D[i, 0]) * plane
        g_y += W[i, 0] * plane_y
        g_z += W[i, 0] * plane_z
        g_mass += W[i, 0] * plane_M
        g_fx += ti.Vector([dW[i, 0] * plane_s, W[i, 0] * plane_s_y, W[i, 0] * plane_s_z])
    return g_momentum, ti.Matrix.cols([g_x, g_y, g_z]), g_mass, g_fx


@ti.func
def p2g_adjoint_stage(frames: ti.template(), params: ti.template(), kinds: ti.template(), consts: ti.template(),
                      fiber: ti.template(), affine: ti.template(), svd: ti.template(), grads: ti.template(),
                      grad_params: ti.template(), grad_grid: ti.template(), scratch: ti.template(),
                      grid_f: ti.template(), grid_i: ti.template(), src):
    """Reverse of the scatter and the stress, per particle (parallel): the gather of the nodes'
    (∂L/∂P, ∂L/∂M) (grad_grid) and the material's adjoint turn the gradient of frame dst's F, Jp
    (grads) and g2p's partial position gradient (scratch 3:6) into the gradient of frame src's
    whole row (written over grads' row), and add the parameters' gradients (grad_params: E, nu,
    rho, actu) per particle. The affine matrices and SVD(F_tmp) are the replay's (slot src)."""
    h, inv_dx, vol, K = grid_f[0], grid_f[1], grid_f[2], node_count(grid_i)
    B, N = params.shape[0], params.shape[1]
    for e, p in ti.ndrange(B, N):
        src_at, grad_at = row_at(src, e, p, B, N, WIDTH), row_at(0, e, p, B, N, WIDTH)
        pos, vel = row_vector(frames, src_at), row_vector(frames, src_at + 3)
        base, fx = cell_of(pos, inv_dx, grid_i)
        mass = params[e, p, 2] * vol
        aff = row_matrix(affine, row_at(src, e, p, B, N, 9))
        momentum = mass * vel
        W, dW = weights(fx), weight_grads(fx)
        # the node offsets (a − fx_c) dx per axis c and offset a (D[a, c])
        D = axis_offsets(fx) / inv_dx
        g_momentum, g_aff, g_mass, g_fx = scatter_reverse(grad_grid, node_at(e, 0, K), base, W, dW, D, aff,
                                                          momentum, mass, grid_i)
        # the nodes' offsets x_i − x = (offset − fx) dx in P_i: −dx Aᵀ Σ w ∂L/∂P_i, once per particle
        g_fx -= transposed_times(aff, g_momentum) / inv_dx
        # the stress: A = −κ τ + m C, F_tmp = (I + h C) F
        C, F = row_matrix(frames, src_at + 6), row_matrix(frames, src_at + 15)
        g_mass += g_momentum.dot(vel) + (g_aff * C).sum()
        g_C = mass * g_aff
        step = ti.Matrix.identity(float, 3) + h * C
        F_tmp = step @ F
        kind = kinds[p]
        c = ti.Vector([consts[p, 0], consts[p, 1], consts[p, 2], consts[p, 3]])
        d = ti.Vector([fiber[p, 0], fiber[p, 1], fiber[p, 2]])
        # SVD(F_tmp) as the replay kept it (identities where the material takes none, as decompose)
        U = ti.Matrix.identity(float, 3)
        sig = ti.Vector([1.0, 1.0, 1.0], float)
        V = ti.Matrix.identity(float, 3)
        if needs_svd(kind, c):
            svd_at = row_at(src, e, p, B, N, SVD_WIDTH)
            U, sig, V = row_matrix(svd, svd_at), row_vector(svd, svd_at + 9), row_matrix(svd, svd_at + 12)
        g_F_tmp, g_Jp, g_E, g_nu, g_actu = constitutive_adjoint_decomposed(
            kind, c, params[e, p, 0], params[e, p, 1], params[e, p, 3], d, F_tmp, frames[src_at + 24],
            F_tmp.determinant(), U, sig, V, row_matrix(grads, grad_at + 15), grads[grad_at + 24],
            (-h * vol * 4.0 * inv_dx * inv_dx) * g_aff)
        g_C += h * g_F_tmp @ F.transpose()
        g_pos = row_vector(scratch, row_at(0, e, p, B, N, 6) + 3) + inv_dx * g_fx
        store_vector(grads, grad_at, g_pos)
        store_vector(grads, grad_at + 3, mass * g_momentum)
        store_matrix(grads, grad_at + 6, g_C)
        store_matrix(grads, grad_at + 15, step.transpose() @ g_F_tmp)
        grads[grad_at + 24] = g_Jp
        grad_params[e, p, 0] = grad_params[e, p, 0] + g_E
        grad_params[e, p, 1] = grad_params[e, p, 1] + g_nu
        grad_params[e, p, 2] = grad_params[e, p, 2] + vol * g_mass
        grad_params[e, p, 3] = grad_params[e, p, 3] + g_actu
