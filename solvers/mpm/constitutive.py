"""MPM constitutive models (Genesis 1.4.5's materials), forward and hand-written reverse, as Taichi funcs.

Stage: the first step of a substep, per particle. From F_tmp = (I + h C) F (the elastic deformation
gradient advected by the APIC velocity gradient), the particle's material gives
- F_new: the elastic deformation gradient it keeps (after a plastic return mapping, if any),
- Jp_new: its plastic volume ratio (Snow's hardening state, Sand's volume correction),
- tau: the Kirchhoff-type stress (3×3, Pa) that Genesis calls `stress`, before the solver scales it
  by −h · vol · 4 · inv_dx².
As in Genesis's substep: J = det F_tmp; stresses read F_new (F_tmp for liquids and neo-Hookean
models), the rotation U Vᵀ of SVD(F_tmp), the singular values after the return mapping (Sand), and
the OLD Jp (Snow). μ = E / (2(1 + ν)), λ = Eν / ((1 + ν)(1 − 2ν)) are formed here, per particle at run
time, so gradients reach E and ν; the other material parameters are non-differentiable constants
(`encode`).

Reverse: maps through the SVD are isotropic, G = U diag(f(σ)) Vᵀ, and are differentiated through the
singular values (never through dU, dV). With M = Uᵀ Ḡ V, F̄ = U X Vᵀ where X_ii = Σ_k M_kk ∂f_k/∂σ_i and,
for i ≠ j, X_ij = a (M_ij + M_ji)/2 + b (M_ij − M_ji)/2, X_ji = a (M_ij + M_ji)/2 − b (M_ij − M_ji)/2 with
a = (f_i − f_j)/(σ_i − σ_j) and b = (f_i + f_j)/(σ_i + σ_j). When σ_i ≈ σ_j, a is the derivative limit
(∂f_i/∂σ_i − ∂f_j/∂σ_i, averaged over i ↔ j) — exact at F = I, where the U/V-based backward
(1/(σ_j² − σ_i²)) is wrong. At a kink (clamp, yield surface, branch) the reverse replays the forward's
branch: one-sided derivatives.

Stresses through the SVD are formed as τ = U diag(t) Uᵀ (+ λ J (J − 1) I), e.g. t = 2μ (f − 1) f for
Genesis's 2μ (F_new − U Vᵀ) F_newᵀ: equal to round-off, exactly symmetric, and one spectral map to
reverse. Compile cost (cold, float64, 2 cores): ~2.5 s for a kernel calling `constitutive`, ~7 s for one
calling `constitutive_adjoint`; Taichi's passes are superlinear in a loop body's size (both funcs in one
body took 41 s while products with diagonal matrices were written as matrix products; 0 · x is not
folded without fast math), so keep them in separate kernels and multiply by diagonals elementwise.
"""
import math

import numpy as np
import taichi as ti
from taichi.lang import impl

from ..core import InvalidInputError
from .layout import KIND, N_CONSTS
from .svd import svd3, svd3_pair, unit_roundoff

_NEOHOOKEN = KIND["neohooken"]
_ELASTOPLASTIC = KIND["elastoplastic"]
_SNOW = KIND["snow"]
_SAND = KIND["sand"]
_LIQUID = KIND["liquid"]
_MUSCLE_COROTATION = KIND["muscle_corotation"]
_MUSCLE_NEOHOOKEN = KIND["muscle_neohooken"]

_VON_MISES_FLOOR = 0.05  # Genesis clamps singular values to this before their logs (von Mises)
_SAND_FLOOR = 1e-4  # ... and |σ| to this (Sand)
_HARDENING = 10.0  # Snow: μ, λ scaled by exp(10 (1 − Jp))

_DEFAULTS = {
    "corotation": {}, "neohooken": {}, "muscle_corotation": {}, "muscle_neohooken": {},
    "elastoplastic": {"yield_lower": 2.5e-2, "yield_higher": 4.5e-3, "use_von_mises": True,
                      "von_mises_yield_stress": 1e4},
    "snow": {"yield_lower": 2.5e-2, "yield_higher": 4.5e-3, "use_von_mises": False},
    "sand": {"friction_angle": 45.0},
    "liquid": {"viscous": False},
}


def encode(kind_name, params):
    """(layout.KIND code, numpy float64 array of N_CONSTS) of a material given by name and a dict of
    its non-differentiable parameters (Genesis's names and defaults; missing ones take the default).

    consts per kind (unused slots 0):
    - corotation, neohooken, muscle_corotation, muscle_neohooken: none;
    - elastoplastic: [use_von_mises (1 or 0), yield_lower, yield_higher, von_mises_yield_stress (Pa)];
      von Mises yields where ‖dev log σ‖ > von_mises_yield_stress / (2μ), else singular values are
      clamped to [1 − yield_lower, 1 + yield_higher];
    - snow: [0, yield_lower, yield_higher, 0] (use_von_mises=True is refused, as in Genesis);
    - sand: [α, 0, 0, 0], the Drucker–Prager coefficient α = √(2/3) · 2 sin φ / (3 − sin φ) of
      friction_angle φ (degrees);
    - liquid: [viscous (1 or 0), 0, 0, 0] (inviscid: μ = 0, λ still from E and ν).
    """
    if kind_name not in KIND:
        raise InvalidInputError(f"MPM material kind must be one of {sorted(KIND)}, got {kind_name!r}")
    values = dict(_DEFAULTS[kind_name])
    unknown = sorted(set(params) - set(values))
    if unknown:
        raise InvalidInputError(f"MPM material {kind_name!r} has no parameter(s) {unknown}")
    values.update(params)
    consts = np.zeros(N_CONSTS)
    if kind_name == "elastoplastic":
        consts[:] = (float(bool(values["use_von_mises"])), values["yield_lower"], values["yield_higher"],
                     values["von_mises_yield_stress"])
    elif kind_name == "snow":
        if values["use_von_mises"]:
            raise InvalidInputError("Snow does not support use_von_mises=True.")
        consts[1:3] = values["yield_lower"], values["yield_higher"]
    elif kind_name == "sand":
        sin_phi = math.sin(math.radians(values["friction_angle"]))
        consts[0] = math.sqrt(2.0 / 3.0) * 2.0 * sin_phi / (3.0 - sin_phi)
    elif kind_name == "liquid":
        consts[0] = float(bool(values["viscous"]))
    return KIND[kind_name], consts


def genesis_eps():
    """Genesis's gs.EPS for the current float type (the guard inside its norms)."""
    return max(1e-15, unit_roundoff())


def _tie_tolerance():
    """Relative gap |σ_i − σ_j| below which divided differences give way to derivatives: about the
    cube root of the unit round-off, where both errors (round-off / gap, gap²) are ~ε^(2/3)."""
    return 1e-5 if impl.get_runtime().default_fp == ti.f64 else 5e-3


@ti.func
def _lame(E, nu):
    """Lamé's (μ, λ) (Pa) of Young's modulus E (Pa) and Poisson ratio ν."""
    return E / (2.0 * (1.0 + nu)), E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))


@ti.func
def _lame_derivatives(E, nu):
    """(∂μ/∂E, ∂μ/∂ν, ∂λ/∂E, ∂λ/∂ν) of `_lame`."""
    denom = (1.0 + nu) * (1.0 - 2.0 * nu)
    return (1.0 / (2.0 * (1.0 + nu)), -E / (2.0 * (1.0 + nu) ** 2), nu / denom,
            E * (1.0 + 2.0 * nu * nu) / (denom * denom))


@ti.func
def needs_svd(kind, consts):
    """Whether the material reads SVD(F_tmp): all but neo-Hookean ones and the inviscid liquid."""
    return not (kind == _NEOHOOKEN or kind == _MUSCLE_NEOHOOKEN or (kind == _LIQUID and consts[0] < 0.5))


def any_needs_svd(kinds, consts):
    """Whether any particle of kinds (N,) with consts (N, N_CONSTS) (numpy) reads SVD(F_tmp):
    `needs_svd` on the host."""
    kinds, consts = np.asarray(kinds), np.asarray(consts)
    spared = (kinds == _NEOHOOKEN) | (kinds == _MUSCLE_NEOHOOKEN) | ((kinds == _LIQUID) & (consts[:, 0] < 0.5))
    return bool((~spared).any())


@ti.func
def _diag(v):
    """3×3 diagonal matrix of a 3-vector."""
    return ti.Matrix([[v[0], 0.0, 0.0], [0.0, v[1], 0.0], [0.0, 0.0, v[2]]], float)


@ti.func
def _scale_columns(M, b):
    """M diag(b) (3×3), without the products by zeros of a matrix product."""
    return ti.Matrix([[M[i, j] * b[j] for j in ti.static(range(3))] for i in ti.static(range(3))])


@ti.func
def _scale_rows(a, M):
    """diag(a) M (3×3)."""
    return ti.Matrix([[a[i] * M[i, j] for j in ti.static(range(3))] for i in ti.static(range(3))])


@ti.func
def _von_mises(ys, mu, sig):
    """ElastoPlastic's von Mises return mapping of the singular values sig → (moved (0/1), f (3),
    ∂f/∂σ (3×3, [k, i] = ∂f_k/∂σ_i), ∂f/∂μ (3)); ys: yield stress (Pa)."""
    floor = ti.max(sig, _VON_MISES_FLOOR)
    dfloor = ti.select(sig > _VON_MISES_FLOOR, 1.0, 0.0)
    eps = ti.log(floor)
    eps_hat = eps - eps.sum() / 3.0
    norm = ti.sqrt(eps_hat.norm_sqr() + ti.static(genesis_eps()))
    moved = 0
    f = sig
    df = ti.Matrix.identity(float, 3)
    df_dmu = ti.Vector.zero(float, 3)
    if norm - ys / (2.0 * mu) > 0.0:  # yields: the deviatoric log strain shrinks to the yield radius
        moved = 1
        eps_new = eps - ((norm - ys / (2.0 * mu)) / norm) * eps_hat
        f = ti.exp(eps_new)
        c = ys / (2.0 * mu * norm)  # eps_new = mean(eps) + c · eps_hat
        deps = ti.Matrix.identity(float, 3) * c + (1.0 - c) / 3.0 - (c / (norm * norm)) * eps_hat.outer_product(
            eps_hat)
        df = _scale_rows(f, _scale_columns(deps, dfloor / floor))
        df_dmu = -(c / mu) * f * eps_hat
    return moved, f, df, df_dmu


@ti.func
def _sand(alpha, mu, lam, sig, Jp):
    """Sand's Drucker–Prager projection (Klár et al. 2016, Genesis's form) of the singular values
    sig with volume correction Jp → (f (3), ∂f/∂σ (3×3), ∂f/∂Jp (3), ∂f/∂μ (3), ∂f/∂λ (3), Jp_new,
    ∂Jp_new/∂σ (3), ∂Jp_new/∂Jp)."""
    mag = ti.max(ti.abs(sig), _SAND_FLOOR)
    dmag = ti.select(ti.abs(sig) > _SAND_FLOOR, ti.select(sig < 0.0, -1.0, 1.0), 0.0)
    eps = ti.log(mag)
    trace = eps.sum() + Jp
    f = ti.Vector([1.0, 1.0, 1.0], float)
    deps = ti.Matrix.zero(float, 3, 3)  # ∂ log f / ∂ eps
    deps_dJp = ti.Vector.zero(float, 3)
    deps_dkappa = ti.Vector.zero(float, 3)
    Jp_new = trace
    dJp_new = dmag / mag
    dJp_new_dJp = 1.0
    if trace < 0.0:  # compression: project onto the cone; in expansion (else) F_new is the rotation
        Jp_new = 0.0
        dJp_new = ti.Vector.zero(float, 3)
        dJp_new_dJp = 0.0
        eps_hat = eps - trace / 3.0
        norm = ti.sqrt(eps_hat.norm_sqr() + ti.static(genesis_eps()))
        kappa = (3.0 * lam + 2.0 * mu) / (2.0 * mu)
        gamma = norm + kappa * trace * alpha
        f = ti.exp(eps - (ti.max(0.0, gamma) / norm) * eps_hat)
        deps = ti.Matrix.identity(float, 3)
        if gamma > 0.0:  # log f = trace/3 − q eps_hat, q = κ α trace / norm
            q = kappa * alpha * trace / norm
            mean_hat = eps_hat.sum() / 3.0
            dnorm = (eps_hat - mean_hat) / norm  # ∂norm/∂eps; ∂norm/∂Jp = −mean_hat / norm
            dq = kappa * alpha * (1.0 / norm - trace * dnorm / (norm * norm))
            dq_dJp = kappa * alpha * (1.0 + trace * mean_hat / (norm * norm)) / norm
            deps = (ti.Matrix.identity(float, 3) * (-q) + (1.0 + q) / 3.0) - eps_hat.outer_product(dq)
            deps_dJp = (1.0 + q) / 3.0 - dq_dJp * eps_hat
            deps_dkappa = -(alpha * trace / norm) * eps_hat
    df = _scale_rows(f, _scale_columns(deps, dmag / mag))
    df_dkappa = f * deps_dkappa
    return (f, df, f * deps_dJp, df_dkappa * (-3.0 * lam / (2.0 * mu * mu)), df_dkappa * (1.5 / mu), Jp_new,
            dJp_new, dJp_new_dJp)


@ti.func
def _return_map(kind, consts, mu, lam, sig, Jp):
    """The plastic return mapping of the singular values σ of F_tmp → (moved: 1 if F_new =
    U diag(f) Vᵀ, else F_new is F_tmp (or J^(1/3) I for liquids); f (3); ∂f/∂σ (3×3, [k, i]); ∂f/∂Jp,
    ∂f/∂μ, ∂f/∂λ (3 each); Jp_new; ∂Jp_new/∂σ (3); ∂Jp_new/∂Jp; piece (3): the piece of a piecewise
    map each σ is on, −1, 0 or 1 (the clamp's below, inside, above; 0 where the map has no pieces
    per σ: von Mises and Sand move all three together, or none))."""
    piece = ti.Vector.zero(float, 3)
    moved = 0
    f = sig
    df = ti.Matrix.identity(float, 3)
    df_dJp = ti.Vector.zero(float, 3)
    df_dmu = ti.Vector.zero(float, 3)
    df_dlam = ti.Vector.zero(float, 3)
    Jp_new = Jp
    dJp_new = ti.Vector.zero(float, 3)
    dJp_new_dJp = 1.0
    if kind == _ELASTOPLASTIC and consts[0] > 0.5:
        moved, f, df, df_dmu = _von_mises(consts[3], mu, sig)
    elif kind == _ELASTOPLASTIC or kind == _SNOW:  # singular values clamped to [1 − lower, 1 + upper]
        moved = 1
        f = ti.min(ti.max(sig, 1.0 - consts[1]), 1.0 + consts[2])
        inside = ti.select((sig > 1.0 - consts[1]) & (sig < 1.0 + consts[2]), 1.0, 0.0)
        df = _diag(inside)
        piece = ti.select(sig >= 1.0 + consts[2], 1.0, 0.0) - ti.select(sig <= 1.0 - consts[1], 1.0, 0.0)
        if kind == _SNOW:  # what the clamp removed goes to the plastic volume ratio
            ratio = sig / f
            dJp_new_dJp = ratio[0] * ratio[1] * ratio[2]
            Jp_new = Jp * dJp_new_dJp
            dJp_new = Jp_new * (1.0 - inside) / sig
    elif kind == _SAND:
        moved = 1
        f, df, df_dJp, df_dmu, df_dlam, Jp_new, dJp_new, dJp_new_dJp = _sand(consts[0], mu, lam, sig, Jp)
    return moved, f, df, df_dJp, df_dmu, df_dlam, Jp_new, dJp_new, dJp_new_dJp, piece


@ti.func
def _effective_lame(kind, consts, mu, lam, Jp):
    """(μ, λ) the stress uses: Snow's hardened by exp(10 (1 − Jp)) (old Jp), the inviscid liquid's
    μ = 0; and the hardening factor (1 elsewhere)."""
    hardening = 1.0
    if kind == _SNOW:
        hardening = ti.exp(_HARDENING * (1.0 - Jp))
    mu_eff = mu * hardening
    if kind == _LIQUID and consts[0] < 0.5:
        mu_eff = 0.0
    return mu_eff, lam * hardening, hardening


@ti.func
def _stress_spectrum(kind, mu, lam, f):
    """The stress's singular-frame values t (τ = U diag(t) Uᵀ, + λ J (J − 1) I but for Sand) from the
    singular values f of the G it reads (F_new, or F_tmp), with μ, λ the effective ones →
    (t (3), ∂t/∂f (3×3, [i, j]), ∂t/∂μ (3), ∂t/∂λ (3)).
    - corotated, t = 2μ (f − 1) f: 2μ (G − U Vᵀ) Gᵀ with G = U diag(f) Vᵀ;
    - Sand, t = 2μ log f + λ Σ log f: Genesis's U diag((2μ log f + λ Σ log f) / f) Vᵀ F_newᵀ."""
    t = 2.0 * mu * (f - 1.0) * f
    dt = _diag(2.0 * mu * (2.0 * f - 1.0))
    dt_dmu = 2.0 * (f - 1.0) * f
    dt_dlam = ti.Vector.zero(float, 3)
    if kind == _SAND:
        logs = ti.log(f)
        t = 2.0 * mu * logs + lam * logs.sum()
        dt = _scale_columns(ti.Matrix.identity(float, 3) * (2.0 * mu) + lam, 1.0 / f)
        dt_dmu = 2.0 * logs
        dt_dlam = ti.Vector([1.0, 1.0, 1.0], float) * logs.sum()
    return t, dt, dt_dmu, dt_dlam


@ti.func
def _is_neohookean(kind):
    return kind == _NEOHOOKEN or kind == _MUSCLE_NEOHOOKEN


@ti.func
def _is_muscle(kind):
    return kind == _MUSCLE_COROTATION or kind == _MUSCLE_NEOHOOKEN


@ti.func
def decompose(kind, consts, F_tmp):
    """(J = det F_tmp, U, σ (3,), V) with F_tmp = U diag(σ) Vᵀ for the kinds that need the SVD;
    identities for the others (which never read them)."""
    U = ti.Matrix.identity(float, 3)
    sig = ti.Vector([1.0, 1.0, 1.0], float)
    V = ti.Matrix.identity(float, 3)
    if needs_svd(kind, consts):
        U, sig, V = svd3(F_tmp)
    return F_tmp.determinant(), U, sig, V


@ti.func
def decompose_pair(kind_F, consts_F, F, kind_G, consts_G, G):
    """`decompose` of two particles at once, the same bits as two calls: (J_F, U_F, σ_F, V_F, J_G,
    U_G, σ_G, V_G). Their SVDs run interleaved (svd.svd3_pair), a material that takes none
    carried through as the identity (its SVD: identities, as decompose gives it)."""
    U_F, V_F, U_G, V_G = (ti.Matrix.identity(float, 3), ti.Matrix.identity(float, 3), ti.Matrix.identity(float, 3),
                          ti.Matrix.identity(float, 3))
    sig_F, sig_G = ti.Vector([1.0, 1.0, 1.0], float), ti.Vector([1.0, 1.0, 1.0], float)
    svd_F, svd_G = needs_svd(kind_F, consts_F), needs_svd(kind_G, consts_G)
    if svd_F or svd_G:
        U_F, sig_F, V_F, U_G, sig_G, V_G = svd3_pair(ti.select(svd_F, F, ti.Matrix.identity(float, 3)),
                                                     ti.select(svd_G, G, ti.Matrix.identity(float, 3)))
    return F.determinant(), U_F, sig_F, V_F, G.determinant(), U_G, sig_G, V_G


@ti.func
def constitutive(kind, consts, E, nu, actu, fiber, F_tmp, Jp):
    """One particle's material update: kind (i32, layout.KIND), consts (N_CONSTS vector, see
    `encode`), E (Pa), nu, actu (muscle actuation, 0 elsewhere), fiber (3-vector, muscle fibre
    direction), F_tmp = (I + h C) F (3×3), Jp (plastic volume ratio) → (F_new (3×3), Jp_new, tau (3×3,
    Pa)) as Genesis 1.4.5 computes them (to round-off)."""
    J, U, sig, V = decompose(kind, consts, F_tmp)
    return constitutive_decomposed(kind, consts, E, nu, actu, fiber, F_tmp, Jp, J, U, sig, V)


@ti.func
def constitutive_decomposed(kind, consts, E, nu, actu, fiber, F_tmp, Jp, J, U, sig, V):
    """`constitutive` given F_tmp's decomposition (J, U, σ, V) = decompose(kind, consts, F_tmp)."""
    mu, lam = _lame(E, nu)
    # (the derivatives are the reverse's; unused here, the compiler drops them)
    moved, f, df, df_dJp, df_dmu, df_dlam, Jp_new, dJp_new, dJp_new_dJp, _ = _return_map(kind, consts, mu, lam, sig, Jp)
    F_new = F_tmp
    if moved != 0:
        F_new = _scale_columns(U, f) @ V.transpose()
    elif kind == _LIQUID:
        F_new = ti.Matrix.identity(float, 3) * ti.pow(J, 1.0 / 3.0)
    mu_eff, lam_eff, hardening = _effective_lame(kind, consts, mu, lam, Jp)
    tau = ti.Matrix.zero(float, 3, 3)
    if _is_neohookean(kind):
        tau = mu * (F_tmp @ F_tmp.transpose()) + ti.Matrix.identity(float, 3) * (lam * ti.log(J) - mu)
    else:
        t, dt, dt_dmu, dt_dlam = _stress_spectrum(kind, mu_eff, lam_eff, f)
        tau = _scale_columns(U, t) @ U.transpose()
        if kind != _SAND:
            tau += ti.Matrix.identity(float, 3) * (lam_eff * J * (J - 1.0))
    if _is_muscle(kind):  # active fibre stress E·actu·(F d)(F d)ᵀ
        stretched = F_tmp @ fiber
        tau += E * actu * stretched.outer_product(stretched)
    return F_new, Jp_new, tau


@ti.func
def _spectral_adjoint(M, sig, f, df, piece):
    """Reverse of G = U diag(f(σ)) Vᵀ through F = U diag(σ) Vᵀ in the singular frame: M = Uᵀ Ḡ V
    (3×3) → X (3×3) with F̄ = U X Vᵀ. f (3), df[k, i] = ∂f_k/∂σ_i, piece (3) as _return_map's.
    Two σ closer than the tie tolerance take the limit of the divided difference (f_i − f_j) /
    (σ_i − σ_j), the derivatives' mean, where f is smooth between them; on two pieces of a kinked
    map (a clamp's bound between them) the divided difference itself, which the limit misses (its
    numerator has no cancellation there: a bound minus a σ). Measured: 20 % off central differences
    in float64, a flipped sign in float32, for a snow particle whose σ straddle a bound 8e-6 apart."""
    X = ti.Matrix.zero(float, 3, 3)
    for i in ti.static(range(3)):
        X[i, i] = M[0, 0] * df[0, i] + M[1, 1] * df[1, i] + M[2, 2] * df[2, i]
    for i, j in ti.static(((0, 1), (0, 2), (1, 2))):
        gap = sig[i] - sig[j]
        sym = 0.5 * (df[i, i] - df[j, i] + df[j, j] - df[i, j])  # the limit σ_i → σ_j
        if piece[i] != piece[j] or ti.abs(gap) > ti.static(_tie_tolerance()) * ti.max(ti.abs(sig[i]), ti.abs(sig[j])):
            sym = (f[i] - f[j]) / gap
        total = sig[i] + sig[j]
        if ti.abs(total) < ti.static(unit_roundoff() ** 2):  # σ_j = −σ_i exactly: infinite, keep finite
            total = ti.static(unit_roundoff() ** 2)
        skew = (f[i] + f[j]) / total
        m_sym = 0.5 * (M[i, j] + M[j, i])
        m_skew = 0.5 * (M[i, j] - M[j, i])
        X[i, j] = sym * m_sym + skew * m_skew
        X[j, i] = sym * m_sym - skew * m_skew
    return X


@ti.func
def constitutive_adjoint(kind, consts, E, nu, actu, fiber, F_tmp, Jp, g_F_new, g_Jp_new, g_tau):
    """Reverse of `constitutive` at the same inputs: the adjoints g_F_new (3×3), g_Jp_new, g_tau (3×3)
    of its outputs → (g_F_tmp (3×3), g_Jp, g_E, g_nu, g_actu). Recomputes the forward; replays its
    branches (one-sided derivatives at kinks). No gradient to consts or fiber."""
    J, U, sig, V = decompose(kind, consts, F_tmp)
    return constitutive_adjoint_decomposed(kind, consts, E, nu, actu, fiber, F_tmp, Jp, J, U, sig, V, g_F_new,
                                           g_Jp_new, g_tau)


@ti.func
def constitutive_adjoint_decomposed(kind, consts, E, nu, actu, fiber, F_tmp, Jp, J, U, sig, V, g_F_new, g_Jp_new,
                                    g_tau):
    """`constitutive_adjoint` given F_tmp's decomposition (J, U, σ, V) = decompose(kind, consts,
    F_tmp) (the MPM reverse reads the one its replay kept rather than redo the SVD)."""
    mu, lam = _lame(E, nu)
    dmu_dE, dmu_dnu, dlam_dE, dlam_dnu = _lame_derivatives(E, nu)
    # f, df: the singular values of F_new (of F_tmp where the map leaves it: f = σ, df = I)
    moved, f, df, df_dJp, df_dmu, df_dlam, Jp_new, dJp_new, dJp_new_dJp, piece = _return_map(kind, consts, mu, lam,
                                                                                             sig, Jp)
    mu_eff, lam_eff, hardening = _effective_lame(kind, consts, mu, lam, Jp)

    g_F = ti.Matrix.zero(float, 3, 3)  # world-frame part of g_F_tmp
    X = ti.Matrix.zero(float, 3, 3)  # singular-frame part: g_F_tmp += U X Vᵀ
    svd = needs_svd(kind, consts)
    M = g_F_new  # g_F_new in the singular frame (U = V = I without an SVD: no products by them)
    if svd:
        M = U.transpose() @ g_F_new @ V
    g_f = ti.Vector([M[0, 0], M[1, 1], M[2, 2]]) * ti.select(moved != 0, 1.0, 0.0)  # ∂L/∂f, f's own inputs
    g_J = 0.0
    g_mu = 0.0
    g_lam = 0.0
    g_mu_eff = 0.0
    g_lam_eff = 0.0
    g_E = 0.0
    g_actu = 0.0
    trace = g_tau.trace()
    if _is_neohookean(kind):
        g_F += mu * (g_tau + g_tau.transpose()) @ F_tmp
        g_J += trace * lam / J
        g_mu += (g_tau * (F_tmp @ F_tmp.transpose())).sum() - trace
        g_lam += trace * ti.log(J)
    else:  # τ = U diag(t) Uᵀ = G Rᵀ with G = U diag(t) Vᵀ, R = U Vᵀ: Ḡ = τ̄ R, R̄ = τ̄ᵀ G
        t, dt, dt_dmu, dt_dlam = _stress_spectrum(kind, mu_eff, lam_eff, f)
        W = U.transpose() @ g_tau @ U
        g_t = ti.Vector([W[0, 0], W[1, 1], W[2, 2]])
        X += _spectral_adjoint(W, sig, t, dt @ df, piece)
        X += _spectral_adjoint(_scale_columns(W.transpose(), t), sig, ti.Vector([1.0, 1.0, 1.0], float),
                               ti.Matrix.zero(float, 3, 3), ti.Vector.zero(float, 3))
        g_f += dt.transpose() @ g_t
        g_mu_eff += g_t.dot(dt_dmu)
        g_lam_eff += g_t.dot(dt_dlam)
        if kind != _SAND:
            g_lam_eff += trace * J * (J - 1.0)
            g_J += trace * lam_eff * (2.0 * J - 1.0)
    if _is_muscle(kind):
        stretched = F_tmp @ fiber
        active = (g_tau * stretched.outer_product(stretched)).sum()
        g_F += E * actu * ((g_tau + g_tau.transpose()) @ stretched).outer_product(fiber)
        g_E += actu * active
        g_actu += E * active
    # effective (μ, λ) → (μ, λ, Jp): Snow's hardening, the inviscid liquid's μ = 0
    if not (kind == _LIQUID and consts[0] < 0.5):
        g_mu += g_mu_eff * hardening
    g_lam += g_lam_eff * hardening
    g_Jp = g_Jp_new * dJp_new_dJp + g_f.dot(df_dJp)
    if kind == _SNOW:
        g_Jp += -_HARDENING * hardening * (g_mu_eff * mu + g_lam_eff * lam)
    g_mu += g_f.dot(df_dmu)
    g_lam += g_f.dot(df_dlam)
    # F_new → F_tmp
    if moved != 0:
        X += _spectral_adjoint(M, sig, f, df, piece)
    elif kind == _LIQUID:  # F_new = J^(1/3) I
        g_J += g_F_new.trace() * ti.pow(J, 1.0 / 3.0) / (3.0 * J)
    else:
        X += M
    X += _diag(g_Jp_new * dJp_new)
    # J = det F_tmp: ∂J/∂F = cofactor matrix
    cofactor = ti.Matrix([[F_tmp[(i + 1) % 3, (j + 1) % 3] * F_tmp[(i + 2) % 3, (j + 2) % 3]
                           - F_tmp[(i + 1) % 3, (j + 2) % 3] * F_tmp[(i + 2) % 3, (j + 1) % 3]
                           for j in ti.static(range(3))] for i in ti.static(range(3))])
    if svd:
        X = U @ X @ V.transpose()
    g_F += g_J * cofactor + X
    g_E += g_mu * dmu_dE + g_lam * dlam_dE
    g_nu = g_mu * dmu_dnu + g_lam * dlam_dnu
    return g_F, g_Jp, g_E, g_nu, g_actu
