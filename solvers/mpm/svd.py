"""A 3×3 singular value decomposition exact to round-off (one-sided Jacobi), as a Taichi func.

F = U diag(σ) Vᵀ with U, V proper rotations (det = +1) and |σ₀| ≥ |σ₁| ≥ |σ₂|, σ₀, σ₁ ≥ 0: a
reflection (det F < 0) sits in the sign of σ₂, the smallest one — the convention of ``ti.svd``
(McAdams et al.), which Genesis's MPM materials read.

Why not ``ti.svd``: in float64 it rebuilds F only to ~1e-10, so a central finite difference with
h = 1e-6 through a return mapping that rebuilds F = U S Vᵀ is noise. Hestenes' one-sided Jacobi
rotates the columns of A = F V until they are orthogonal (each rotation is orthogonal to
round-off, and the stopping test asks for column cosines below the unit round-off), so
U diag(σ) Vᵀ − F and UᵀU − I, VᵀV − I are a few ulps. Measured (tests/test_mpm_constitutive.py, 809
matrices: random, near I, repeated, inverted, rank-deficient, zero): float64 reconstruction ≤ 1.2e-15
(relative to max |F_ij|), orthogonality ≤ 1.6e-15, singular values within 1.2e-15 of numpy's (ti.svd:
reconstruction 3.5e-10); float32 ≤ 7.4e-7, 6.9e-7, 5.7e-7. Cost ~0.3–0.7 µs per matrix on this 2-core
CPU, mostly waiting on each rotation's divisions and square roots (3.5–4.3 sweeps, 7–9 rotations on
average), which svd3_pair overlaps between two matrices. Its sweep count varies with F, but every F
gives the same result on every run.
"""
import taichi as ti
from taichi.lang import impl

_MAX_SWEEPS = 12  # quadratic convergence: 3–6 sweeps reach round-off for any 3×3


def unit_roundoff():
    """Machine epsilon of the current float type (Python float, read at compile time)."""
    return 1.1920929e-07 if impl.get_runtime().default_fp == ti.f32 else 2.220446049250313e-16


@ti.func
def _rotate_columns(A: ti.template(), V: ti.template(), p: ti.template(), q: ti.template(), tol2):
    """One Jacobi rotation of columns p, q of A (3×3) and V that makes A's columns p, q orthogonal;
    returns 1 if they were not orthogonal to √tol2 (relative cosine), else 0 (nothing done)."""
    alpha = A[0, p] * A[0, p] + A[1, p] * A[1, p] + A[2, p] * A[2, p]
    beta = A[0, q] * A[0, q] + A[1, q] * A[1, q] + A[2, q] * A[2, q]
    gamma = A[0, p] * A[0, q] + A[1, p] * A[1, q] + A[2, p] * A[2, q]
    rotated = 0
    if gamma * gamma > tol2 * (alpha * beta):
        rotated = 1
        # t = tan θ, the smaller root of t² + 2ζt − 1 = 0 with ζ = (β − α) / 2γ (a rotation of at
        # most 45°), written with one division: the rotation's chain of divisions and square roots
        # is what a Jacobi sweep waits on
        d = beta - alpha
        root = ti.sqrt(d * d + 4.0 * gamma * gamma)
        t = 0.0
        if root < ti.math.inf:
            t = (2.0 * gamma) / (ti.abs(d) + root)
            if d < 0.0:
                t = -t
        else:  # d² + 4γ² overflows (float32 columns longer than ~4e9): the ζ form, which does not
            zeta = d / (2.0 * gamma)
            t = 1.0 / (ti.abs(zeta) + ti.sqrt(1.0 + zeta * zeta))
            if zeta < 0.0:
                t = -t
        c = 1.0 / ti.sqrt(1.0 + t * t)
        s = c * t
        for r in ti.static(range(3)):
            ap, aq = A[r, p], A[r, q]
            A[r, p] = c * ap - s * aq
            A[r, q] = s * ap + c * aq
            vp, vq = V[r, p], V[r, q]
            V[r, p] = c * vp - s * vq
            V[r, q] = s * vp + c * vq
    return rotated


@ti.func
def _sweep(A: ti.template(), V: ti.template(), tol2):
    """One cyclic Jacobi sweep (column pairs 01, 02, 12); the number of rotations it made."""
    rotated = _rotate_columns(A, V, 0, 1, tol2)
    rotated += _rotate_columns(A, V, 0, 2, tol2)
    rotated += _rotate_columns(A, V, 1, 2, tol2)
    return rotated


@ti.func
def _swap_columns(A: ti.template(), p: ti.template(), q: ti.template()):
    """Swap columns p and q of the 3×3 A in place."""
    for r in ti.static(range(3)):
        A[r, p], A[r, q] = A[r, q], A[r, p]


@ti.func
def _any_perpendicular(u):
    """A unit vector perpendicular to the unit 3-vector u."""
    axis = ti.Vector([1.0, 0.0, 0.0], float)
    if ti.abs(u[1]) <= ti.abs(u[0]) and ti.abs(u[1]) <= ti.abs(u[2]):
        axis = ti.Vector([0.0, 1.0, 0.0], float)
    elif ti.abs(u[2]) <= ti.abs(u[0]):
        axis = ti.Vector([0.0, 0.0, 1.0], float)
    return u.cross(axis).normalized()


@ti.func
def svd3(F):
    """F (3×3) → (U (3×3), sig (3-vector), V (3×3)) with F = U diag(sig) Vᵀ, det U = det V = 1,
    |sig| sorted decreasing, sig[0], sig[1] ≥ 0 and sig[2] carrying det F's sign. Rank-deficient
    F get any orthonormal completion of U."""
    tol2 = ti.static(unit_roundoff() ** 2)
    A = F
    V = ti.Matrix.identity(float, 3)
    sweep = 0
    rotated = 1
    while rotated != 0 and sweep < _MAX_SWEEPS:
        rotated = _sweep(A, V, tol2)
        sweep += 1
    return _factors(A, V)


@ti.func
def svd3_pair(F, G):
    """svd3 of two matrices at once, the same bits as two calls: (U_F, σ_F, V_F, U_G, σ_G, V_G). The
    sweeps of F and G alternate in one loop, so the processor overlaps two independent chains of
    divisions and square roots (10k near-identity matrices, float32: 0.75 ms against 1.15 for
    svd3 one by one). A matrix that has converged makes no rotation in the sweeps it is carried
    through, hence the same bits."""
    tol2 = ti.static(unit_roundoff() ** 2)
    A, B = F, G
    V, W = ti.Matrix.identity(float, 3), ti.Matrix.identity(float, 3)
    sweep = 0
    rotated = 1
    while rotated != 0 and sweep < _MAX_SWEEPS:
        rotated = _sweep(A, V, tol2) + _sweep(B, W, tol2)
        sweep += 1
    U_F, sig_F, V_F = _factors(A, V)
    U_G, sig_G, V_G = _factors(B, W)
    return U_F, sig_F, V_F, U_G, sig_G, V_G


@ti.func
def _factors(A, V):
    """(U, σ, V) from the converged A = F V (orthogonal columns) and V: columns sorted by length,
    V made a rotation (det F's sign in σ₂), U the normalised columns, re-orthogonalised."""
    # sort the columns by length (three compare-swaps), keeping A = F V
    norms = ti.Vector([A[0, k] ** 2 + A[1, k] ** 2 + A[2, k] ** 2 for k in ti.static(range(3))])
    for p, q in ti.static(((0, 1), (1, 2), (0, 1))):
        if norms[p] < norms[q]:
            _swap_columns(A, p, q)
            _swap_columns(V, p, q)
            norms[p], norms[q] = norms[q], norms[p]
    if V.determinant() < 0.0:  # make V a rotation; the sign moves to the last column of A
        for r in ti.static(range(3)):
            A[r, 2] = -A[r, 2]
            V[r, 2] = -V[r, 2]
    a0 = ti.Vector([A[0, 0], A[1, 0], A[2, 0]])
    a1 = ti.Vector([A[0, 1], A[1, 1], A[2, 1]])
    a2 = ti.Vector([A[0, 2], A[1, 2], A[2, 2]])
    tiny = ti.static(unit_roundoff() ** 2)
    u0 = ti.Vector([1.0, 0.0, 0.0], float)
    if norms[0] > tiny:
        u0 = a0 / ti.sqrt(norms[0])
    u1 = a1 - u0.dot(a1) * u0  # re-orthogonalised: exact when a1 is tiny or zero
    u1_norm2 = u1.norm_sqr()
    if u1_norm2 > tiny * ti.max(norms[0], 1.0):
        u1 = u1 / ti.sqrt(u1_norm2)
    else:
        u1 = _any_perpendicular(u0)
    u2 = u0.cross(u1)
    # the column lengths (sorted exactly); a2 = ±|a2| u2 carries det F's sign
    sig = ti.Vector([ti.sqrt(norms[0]), ti.sqrt(norms[1]), ti.sqrt(norms[2])])
    if u2.dot(a2) < 0.0:
        sig[2] = -sig[2]
    U = ti.Matrix.cols([u0, u1, u2])
    return U, sig, V
