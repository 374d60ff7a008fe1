"""MPM constitutive models (solvers/mpm/constitutive.py, svd.py): the forward against Genesis 1.4.5's
material formulas re-evaluated here in numpy, the hand-written reverse against central finite
differences for every material at F = I, at repeated singular values, at generic F, on and off the
yield surfaces, and the SVD's accuracy in float64 and float32.

One test kernel evaluates forward and reverse for a batch of cases (compiled once per precision).
"""
import math

import numpy as np
import pytest
import taichi as ti

from genesis_lite.solvers.mpm.constitutive import any_needs_svd, constitutive, constitutive_adjoint, encode, needs_svd
from genesis_lite.solvers.mpm.layout import KIND, N_CONSTS
from genesis_lite.solvers.mpm.svd import svd3, svd3_pair


@ti.func
def _mat(a: ti.template(), n):
    """Row n of a (n, 3, 3) ndarray as a 3×3 ti.Matrix."""
    return ti.Matrix([[a[n, i, j] for j in ti.static(range(3))] for i in ti.static(range(3))])


@ti.func
def _vec3(a: ti.template(), n):
    """Row n of a (n, 3) ndarray as a 3-vector."""
    return ti.Vector([a[n, i] for i in ti.static(range(3))])


@ti.func
def _store(a: ti.template(), n, m):
    """Write the 3×3 m into row n of a (n, 3, 3) ndarray."""
    for i, j in ti.static(ti.ndrange(3, 3)):
        a[n, i, j] = m[i, j]


@ti.kernel
def _evaluate(kind: ti.types.ndarray(), consts: ti.types.ndarray(), scalars: ti.types.ndarray(),
              fiber: ti.types.ndarray(), F: ti.types.ndarray(), g_F_new: ti.types.ndarray(),
              g_tau: ti.types.ndarray(), F_new: ti.types.ndarray(), tau: ti.types.ndarray(),
              g_F: ti.types.ndarray(), out: ti.types.ndarray()):
    """Per case n: scalars[n] = (E, nu, actu, Jp, g_Jp_new) → F_new[n], tau[n], g_F[n] (3×3) and
    out[n] = (Jp_new, g_Jp, g_E, g_nu, g_actu)."""
    for n in range(kind.shape[0]):
        consts_n = ti.Vector([consts[n, i] for i in ti.static(range(N_CONSTS))])
        F_tmp = _mat(F, n)
        fiber_n = _vec3(fiber, n)
        F_next, Jp_next, stress = constitutive(kind[n], consts_n, scalars[n, 0], scalars[n, 1], scalars[n, 2],
                                               fiber_n, F_tmp, scalars[n, 3])
        grad_F, grad_Jp, grad_E, grad_nu, grad_actu = constitutive_adjoint(
            kind[n], consts_n, scalars[n, 0], scalars[n, 1], scalars[n, 2], fiber_n, F_tmp, scalars[n, 3],
            _mat(g_F_new, n), scalars[n, 4], _mat(g_tau, n))
        _store(F_new, n, F_next)
        _store(tau, n, stress)
        _store(g_F, n, grad_F)
        out[n, 0] = Jp_next
        out[n, 1] = grad_Jp
        out[n, 2] = grad_E
        out[n, 3] = grad_nu
        out[n, 4] = grad_actu


@ti.kernel
def _decompose(F: ti.types.ndarray(), U: ti.types.ndarray(), sig: ti.types.ndarray(), V: ti.types.ndarray()):
    for n in range(F.shape[0]):
        u, s, v = svd3(_mat(F, n))
        _store(U, n, u)
        _store(V, n, v)
        for i in ti.static(range(3)):
            sig[n, i] = s[i]


@ti.kernel
def _decompose_pairs(F: ti.types.ndarray(), partner: ti.types.ndarray(), U: ti.types.ndarray(),
                     sig: ti.types.ndarray(), V: ti.types.ndarray(), U2: ti.types.ndarray(), sig2: ti.types.ndarray(),
                     V2: ti.types.ndarray()):
    """svd3_pair of F[n] with F[partner[n]]: rows n of U, sig, V get F[n]'s factors, of U2, sig2, V2
    its partner's."""
    for n in range(F.shape[0]):
        u, s, v, u2, s2, v2 = svd3_pair(_mat(F, n), _mat(F, partner[n]))
        _store(U, n, u)
        _store(V, n, v)
        _store(U2, n, u2)
        _store(V2, n, v2)
        for i in ti.static(range(3)):
            sig[n, i] = s[i]
            sig2[n, i] = s2[i]


def run(cases, dtype=np.float64):
    """cases: list of dicts (material, params, E, nu, actu, fiber, F, Jp, g_F_new, g_Jp_new, g_tau) →
    dict of numpy arrays (F_new, Jp_new, tau, g_F, g_Jp, g_E, g_nu, g_actu), one row per case."""
    n = len(cases)
    codes = np.array([encode(c["material"], c["params"])[0] for c in cases], np.int32)
    consts = np.array([encode(c["material"], c["params"])[1] for c in cases], dtype)
    scalars = np.array([[c["E"], c["nu"], c["actu"], c["Jp"], c["g_Jp_new"]] for c in cases], dtype)
    fiber = np.array([c["fiber"] for c in cases], dtype)
    F = np.array([c["F"] for c in cases], dtype)
    g_F_new = np.array([c["g_F_new"] for c in cases], dtype)
    g_tau = np.array([c["g_tau"] for c in cases], dtype)
    F_new, tau, g_F = (np.zeros((n, 3, 3), dtype) for _ in range(3))
    out = np.zeros((n, 5), dtype)
    _evaluate(codes, consts, scalars, fiber, F, g_F_new, g_tau, F_new, tau, g_F, out)
    return {"F_new": F_new, "tau": tau, "g_F": g_F, "Jp_new": out[:, 0], "g_Jp": out[:, 1], "g_E": out[:, 2],
            "g_nu": out[:, 3], "g_actu": out[:, 4]}


# ---------------------------------------------------------------- Genesis's formulas, in numpy

def genesis_svd(F):
    """ti.svd's conventions: U, V rotations, S diagonal, a reflection in the last singular value."""
    U, s, Vt = np.linalg.svd(F)
    V = Vt.T.copy()
    if np.linalg.det(U) < 0:
        U[:, 2] *= -1
        s[2] *= -1
    if np.linalg.det(V) < 0:
        V[:, 2] *= -1
        s[2] *= -1
    return U, np.diag(s), V


def genesis_material(c):
    """(F_new, Jp_new, stress) as Genesis 1.4.5's MPM substep computes them (materials/MPM/*.py,
    mpm_solver.py p2g: J = det S, stress from S_new, F_new, F_tmp and the old Jp)."""
    name, p, E, nu, F_tmp, Jp = c["material"], c["params"], c["E"], c["nu"], c["F"], c["Jp"]
    eps_guard = 1e-15  # gs.EPS in float64
    mu, lam = E / (2 * (1 + nu)), E * nu / ((1 + nu) * (1 - 2 * nu))
    if name == "liquid" and not p.get("viscous", False):
        mu = 0.0
    U, S, V = genesis_svd(F_tmp)
    J = np.linalg.det(S)
    I = np.eye(3)
    F_new, S_new, Jp_new = F_tmp, S, Jp
    if name in ("elastoplastic", "snow"):
        lower, upper = p.get("yield_lower", 2.5e-2), p.get("yield_higher", 4.5e-3)
        if name == "elastoplastic" and p.get("use_von_mises", True):
            S_new = np.maximum(S, 0.05)
            epsilon = np.log(np.diag(S_new))
            epsilon_hat = epsilon - epsilon.sum() / 3
            norm = np.sqrt(epsilon_hat @ epsilon_hat + eps_guard)
            delta_gamma = norm - p.get("von_mises_yield_stress", 1e4) / (2 * mu)
            if delta_gamma > 0:
                epsilon = epsilon - delta_gamma / norm * epsilon_hat
                S_new = np.diag(np.exp(epsilon))
                F_new = U @ S_new @ V.T
        else:
            S_new = np.diag(np.clip(np.diag(S), 1 - lower, 1 + upper))
            if name == "snow":
                Jp_new = Jp * np.prod(np.diag(S) / np.diag(S_new))
            F_new = U @ S_new @ V.T
    elif name == "sand":
        sin_phi = math.sin(math.radians(p.get("friction_angle", 45.0)))
        alpha = math.sqrt(2 / 3) * 2 * sin_phi / (3 - sin_phi)
        epsilon = np.log(np.maximum(np.abs(np.diag(S)), 1e-4))
        tr = epsilon.sum() + Jp
        epsilon_hat = epsilon - tr / 3
        norm = np.sqrt(epsilon_hat @ epsilon_hat + eps_guard)
        S_new = I.copy()
        if tr >= 0:
            Jp_new = tr
        else:
            Jp_new = 0.0
            delta_gamma = norm + (3 * lam + 2 * mu) / (2 * mu) * tr * alpha
            S_new = np.diag(np.exp(epsilon - max(0, delta_gamma) / norm * epsilon_hat))
        F_new = U @ S_new @ V.T
    elif name == "liquid":
        F_new = I * J ** (1 / 3)
    R = U @ V.T
    if name in ("neohooken", "muscle_neohooken"):
        stress = mu * F_tmp @ F_tmp.T + I * (lam * np.log(J) - mu)
    elif name == "snow":
        h = np.exp(10 * (1 - Jp))
        stress = 2 * mu * h * (F_new - R) @ F_new.T + I * lam * h * J * (J - 1)
    elif name == "sand":
        s = np.diag(S_new)
        center = np.diag(2 * mu * np.log(s) / s + lam * np.log(s).sum() / s)
        stress = U @ center @ V.T @ F_new.T
    elif name == "liquid":
        stress = 2 * mu * (F_tmp - R) @ F_tmp.T + I * lam * J * (J - 1)
    else:  # corotation, elastoplastic (the base stress), muscle_corotation
        stress = 2 * mu * (F_new - R) @ F_new.T + I * lam * J * (J - 1)
    if name.startswith("muscle"):
        d = np.asarray(c["fiber"])
        stress = stress + E * c["actu"] * F_tmp @ np.outer(d, d) @ F_tmp.T
    return F_new, Jp_new, stress


# ---------------------------------------------------------------- cases

def _rotation(rng):
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return Q * np.sign(np.linalg.det(Q))


def _stretch(rng, s):
    """R₁ diag(s) R₂ᵀ with random rotations."""
    return _rotation(rng) @ np.diag(s) @ _rotation(rng).T


def make_cases():
    """(label, case) per material × deformation, each away from the kinks by more than the FD steps."""
    rng = np.random.default_rng(7)
    tie = _stretch(rng, [1.1, 1.1, 0.9])
    generic = np.eye(3) + 0.08 * rng.normal(size=(3, 3))
    # singular values 2e-6 apart (the derivative limit) and 4e-5 apart (divided differences)
    near_tie = _stretch(rng, [1.1, 1.1 + 2e-6, 0.9])
    near_tie_wider = _stretch(rng, [1.1, 1.1 + 4e-5, 0.9])
    elastic = {"identity": np.eye(3), "repeated": tie, "nearly repeated": near_tie, "generic": generic}
    # two singular values 8e-6 apart on either side of the clamp's upper bound 1.0045, off the
    # middle (the divided difference, 1/4: the derivative limit's 1/2 was 20 % off the gradient);
    # FD steps of 1e-8 resolve their turn
    straddle = _stretch(rng, [1.0045 + 6e-6, 1.0045 - 2e-6, 0.99])
    # the same 2.3e-3 apart: inside float32's tie band (5e-3), outside float64's
    straddle_wider = _stretch(rng, [1.0045 + 3e-4, 1.0045 - 2e-3, 0.99])
    table = [
        ("corotation", {}, elastic, 1.0),
        ("neohooken", {}, elastic, 1.0),
        ("muscle_corotation", {}, elastic, 1.0),
        ("muscle_neohooken", {}, elastic, 1.0),
        ("liquid", {}, elastic, 1.0),
        ("liquid", {"viscous": True}, elastic, 1.0),
        # von Mises: yield radius 1e4 / (2μ) = 0.012 at E = 1e6, ν = 0.2
        ("elastoplastic", {}, {"identity": np.eye(3), "repeated (yields)": tie, "generic (yields)": generic,
                               "nearly repeated (yields)": near_tie, "nearly repeated, wider (yields)": near_tie_wider,
                               "elastic": _stretch(rng, [1.006, 0.999, 0.995])}, 1.0),
        # clamp to [0.975, 1.0045]: σ inside, all outside, mixed
        ("elastoplastic", {"use_von_mises": False},
         {"identity": np.eye(3), "inside": _stretch(rng, [1.003, 0.99, 0.98]), "repeated (clamped)": tie,
          "mixed": _stretch(rng, [1.02, 1.001, 0.96]), "nearly repeated across the bound (clamped)": straddle,
          "across the bound, 2.3e-3 apart (clamped)": straddle_wider}, 1.0),
        ("snow", {}, {"identity": np.eye(3), "inside": _stretch(rng, [1.003, 0.99, 0.98]),
                      "repeated (clamped)": tie, "mixed": _stretch(rng, [1.02, 1.001, 0.96]),
                      "nearly repeated across the bound (clamped)": straddle,
                      "across the bound, 2.3e-3 apart (clamped)": straddle_wider}, 0.97),
        ("sand", {}, {"identity (expansion)": np.eye(3), "repeated (expansion)": tie,
                      "compressed (inside cone)": _stretch(rng, [0.96, 0.955, 0.95]),
                      "compressed (projected)": _stretch(rng, [1.2, 1.0, 0.75]),
                      "repeated compressed (inside cone)": _stretch(rng, [0.9, 0.9, 0.97]),
                      "repeated compressed (projected)": _stretch(rng, [1.15, 1.15, 0.7])}, None),
    ]
    cases = []
    for material, params, deformations, Jp in table:
        for label, F in deformations.items():
            fiber = rng.normal(size=3)
            sand_Jp = 0.01 if "expansion" in label else 0.002
            cases.append((f"{material}{params} {label}", {
                "material": material, "params": params, "E": 1e6, "nu": 0.2 if material != "sand" else 0.3,
                "actu": 0.4 if material.startswith("muscle") else 0.0, "fiber": fiber / np.linalg.norm(fiber),
                "F": F, "Jp": sand_Jp if Jp is None else Jp, "g_Jp_new": rng.normal(),
                "g_F_new": rng.normal(size=(3, 3)), "g_tau": rng.normal(size=(3, 3)) / 1e5}))
    return cases


def _inputs(case):
    """The differentiable inputs as a vector (F (9), Jp, E / E₀, nu, actu) of unit scale."""
    return np.concatenate([case["F"].ravel(), [case["Jp"], 1.0, case["nu"], case["actu"]]])


def _with_inputs(case, x):
    out = dict(case)
    out.update(F=x[:9].reshape(3, 3), Jp=x[9], E=case["E"] * x[10], nu=x[11], actu=x[12])
    return out


def _loss(result, case, n):
    return (np.sum(case["g_F_new"] * result["F_new"][n]) + case["g_Jp_new"] * result["Jp_new"][n]
            + np.sum(case["g_tau"] * result["tau"][n]))


FD_EPS = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8)
F32_REVERSE_BAR = 3e-5  # relative; measured ≤ 7e-6


def test_constitutive_matches_genesis_and_finite_differences(f64):
    labelled = make_cases()
    cases = [c for _, c in labelled]
    # every FD evaluation in the same launch: case × input × eps × sign
    probes = []
    for case in cases:
        x = _inputs(case)
        for k in range(x.size):
            for eps in FD_EPS:
                for sign in (1.0, -1.0):
                    step = x.copy()
                    step[k] += sign * eps
                    probes.append(_with_inputs(case, step))
    result = run(cases + probes)
    n_in, n_eps = 13, len(FD_EPS)
    failures = []
    for n, (label, case) in enumerate(labelled):
        # forward: Genesis's formulas
        F_new, Jp_new, stress = genesis_material(case)
        forward_error = max(np.abs(result["F_new"][n] - F_new).max(), abs(result["Jp_new"][n] - Jp_new),
                            np.abs(result["tau"][n] - stress).max() / max(np.abs(stress).max(), case["E"] * 1e-3))
        # reverse: central differences, best eps per input
        analytic = np.concatenate([result["g_F"][n].ravel(), [result["g_Jp"][n], result["g_E"][n] * case["E"],
                                                              result["g_nu"][n], result["g_actu"][n]]])
        base = len(cases) + n * n_in * n_eps * 2
        central = np.zeros((n_eps, n_in))
        for k in range(n_in):
            for e, eps in enumerate(FD_EPS):
                row = base + (k * n_eps + e) * 2
                central[e, k] = (_loss(result, cases[n], row) - _loss(result, cases[n], row + 1)) / (2 * eps)
        errors = np.abs(central - analytic).min(axis=0) / np.abs(analytic).max()
        if forward_error > 1e-12 or errors.max() > 1e-6:
            failures.append(f"{label}: forward {forward_error:.1e}, reverse {errors.max():.1e} (input {errors.argmax()})")
    assert not failures, "\n".join(failures)


def test_yield_branches_are_exercised(f64):
    """The cases named on/off a yield surface really sit on the branch their label says."""
    labelled = make_cases()
    result = run([c for _, c in labelled])
    for n, (label, case) in enumerate(labelled):
        moved = not np.allclose(result["F_new"][n], case["F"], atol=1e-12, rtol=0)
        if case["material"] in ("elastoplastic", "snow"):
            expected = any(word in label for word in ("yields", "clamped", "mixed"))
            assert moved == expected, label
        if case["material"] == "sand":
            expansion = "expansion" in label
            assert (result["Jp_new"][n] > 0) == expansion, label
            sig_new = np.linalg.svd(result["F_new"][n], compute_uv=False)
            if expansion:  # F_new is the rotation U Vᵀ
                assert np.abs(sig_new - 1).max() < 1e-12, label
            else:
                moved = np.abs(sig_new - np.linalg.svd(case["F"], compute_uv=False)).max() > 1e-6
                assert moved == ("projected" in label), label


def _svd_matrices(dtype):
    """809 test matrices (n, 3, 3): random, near the identity, repeated, inverted, rank-deficient, zero."""
    rng = np.random.default_rng(3)
    F = np.concatenate([rng.normal(size=(400, 3, 3)), np.eye(3) + 0.02 * rng.normal(size=(400, 3, 3)),
                        [np.eye(3), np.diag([1.1, 1.1, 0.9]), _stretch(rng, [1.1, 1.1, 0.9]),
                         _stretch(rng, [1.0, 1.0, 1.0 + 1e-9]), np.diag([1.0, 1.0, -1.0]), _stretch(rng, [2, 1, -0.5]),
                         _stretch(rng, [1.0, 1e-3, 1e-9]), np.diag([1.0, 0.0, 0.0]), np.zeros((3, 3))]])
    return F.astype(dtype)


def _svd_batch(dtype):
    F = _svd_matrices(dtype)
    U, V = np.zeros_like(F), np.zeros_like(F)
    sig = np.zeros((len(F), 3), dtype)
    _decompose(F, U, sig, V)
    F, U, sig, V = (a.astype(np.float64) for a in (F, U, sig, V))
    scale = np.maximum(np.abs(F).max(axis=(1, 2)), 1e-300)
    rebuilt = np.einsum("nij,nj,nkj->nik", U, sig, V)
    eye = np.eye(3)
    return {"reconstruction": (np.abs(rebuilt - F).max(axis=(1, 2)) / scale).max(),
            "orthogonality": max(np.abs(np.einsum("nji,njk->nik", U, U) - eye).max(),
                                 np.abs(np.einsum("nji,njk->nik", V, V) - eye).max()),
            "det": max(np.abs(np.linalg.det(U) - 1).max(), np.abs(np.linalg.det(V) - 1).max()),
            "sorted": bool(np.all(np.abs(sig[:, 0]) >= np.abs(sig[:, 1])) and np.all(np.abs(sig[:, 1]) >= np.abs(sig[:, 2]))),
            "signs": bool(np.all(sig[:, :2] >= 0) and np.all(sig[:-2, 2] * np.linalg.det(F[:-2]) > 0)),
            "values": (np.abs(np.abs(sig) - np.linalg.svd(F, compute_uv=False)).max(axis=1) / scale).max()}


@ti.kernel
def _device_needs_svd(kind: ti.types.ndarray(), consts: ti.types.ndarray(), out: ti.types.ndarray()):
    for n in range(kind.shape[0]):
        out[n] = int(needs_svd(kind[n], ti.Vector([consts[n, k] for k in ti.static(range(N_CONSTS))])))


def test_host_and_kernels_agree_on_which_materials_take_an_svd(f64):
    """The solver compiles its stress stage for any_needs_svd (the host's answer: without an SVD
    material, no SVD at all); the kernels branch on needs_svd. They must agree for every kind and
    flag, or a material that takes an SVD would get identities for it."""
    cases = [encode(name, {}) for name in KIND] + [encode("liquid", {"viscous": True}),
                                                   encode("elastoplastic", {"use_von_mises": False})]
    kinds = np.array([kind for kind, _ in cases], dtype=np.int32)
    consts = np.stack([c for _, c in cases])
    out = np.zeros(len(cases), dtype=np.int32)
    _device_needs_svd(kinds, consts, out)
    host = [any_needs_svd(kinds[n:n + 1], consts[n:n + 1]) for n in range(len(cases))]
    assert out.astype(bool).tolist() == host
    assert host.count(False) == 3  # neo-Hookean, its muscle, the inviscid liquid


@pytest.mark.parametrize("dtype", [np.float64, pytest.param(np.float32, marks=pytest.mark.float32)])
def test_svd_pair_gives_each_matrix_the_bits_of_its_own_svd(dtype, request):
    """The stress stage decomposes particles two at a time (svd3_pair): each must get exactly what
    svd3 gives it alone, whatever its partner needs (partners drawn from the whole batch: random,
    near the identity, degenerate, zero)."""
    request.getfixturevalue("f64" if dtype == np.float64 else "f32")
    F = _svd_matrices(dtype)
    partner = np.random.default_rng(4).permutation(len(F)).astype(np.int32)
    alone = [np.zeros_like(F), np.zeros((len(F), 3), dtype), np.zeros_like(F)]
    paired = [np.zeros_like(a) for a in alone + alone]
    _decompose(F, *alone)
    _decompose_pairs(F, partner, *paired)
    for a, first, second in zip(alone, paired[:3], paired[3:]):
        assert np.array_equal(first, a) and np.array_equal(second, a[partner])


def test_svd_float32_with_columns_whose_squared_difference_overflows(f32):
    """Columns of length ~5e9 in float32: their squared lengths fit (~2.5e19) but the rotation's
    (β − α)² + 4γ² overflows; the rotation then takes the ζ = (β − α)/2γ form (a blown-up state
    must still decompose exactly, as before the one-division form)."""
    rng = np.random.default_rng(5)
    F = np.concatenate([[[[5e9, 1e3, 0.0], [0.0, 1e8, 0.0], [0.0, 0.0, 1.0]]],
                        rng.normal(size=(20, 3, 3)) * np.array([6e9, 1e8, 1.0])]).astype(np.float32)
    U, V = np.zeros_like(F), np.zeros_like(F)
    sig = np.zeros((len(F), 3), np.float32)
    _decompose(F, U, sig, V)
    reference = np.linalg.svd(F.astype(np.float64), compute_uv=False)
    scale = np.abs(F).max(axis=(1, 2))
    assert (np.abs(np.abs(sig) - reference).max(axis=1) / scale).max() <= 3e-6
    rebuilt = np.einsum("nij,nj,nkj->nik", U.astype(np.float64), sig.astype(np.float64), V.astype(np.float64))
    assert (np.abs(rebuilt - F).max(axis=(1, 2)) / scale).max() <= 3e-6


def test_svd_float64(f64):
    stats = _svd_batch(np.float64)
    assert stats["sorted"] and stats["signs"], stats
    assert stats["reconstruction"] <= 1e-14 and stats["orthogonality"] <= 1e-14 and stats["det"] <= 1e-14, stats
    assert stats["values"] <= 1e-14, stats


def test_svd_float32(f32):
    stats = _svd_batch(np.float32)
    assert stats["sorted"] and stats["signs"], stats
    assert stats["reconstruction"] <= 3e-6 and stats["orthogonality"] <= 3e-6 and stats["det"] <= 3e-6, stats
    assert stats["values"] <= 3e-6, stats


def _reference_gradient(case, eps=1e-6):
    """Central differences of Genesis's formulas (numpy, float64) in the scaled inputs of _inputs."""
    x = _inputs(case)
    grad = np.zeros(x.size)
    for k in range(x.size):
        values = []
        for sign in (1.0, -1.0):
            step = x.copy()
            step[k] += sign * eps
            probe = _with_inputs(case, step)
            F_new, Jp_new, stress = genesis_material(probe)
            values.append(np.sum(case["g_F_new"] * F_new) + case["g_Jp_new"] * Jp_new + np.sum(case["g_tau"] * stress))
        grad[k] = (values[0] - values[1]) / (2 * eps)
    return grad


def test_float32(f32):
    """The same funcs in float32: forward against Genesis's formulas, reverse against central
    differences of those formulas in float64."""
    # (not the pair 8e-6 apart across a bound: float32's round-off of their singular values and
    # vectors, ~1e-7 / 8e-6, is ~1 % of the divided difference there)
    labelled = [(label, case) for label, case in make_cases() if "nearly repeated across" not in label]
    result = run([c for _, c in labelled], np.float32)
    failures = []
    for n, (label, case) in enumerate(labelled):
        F_new, Jp_new, stress = genesis_material(case)
        forward_error = max(np.abs(result["F_new"][n] - F_new).max(), abs(result["Jp_new"][n] - Jp_new),
                            np.abs(result["tau"][n] - stress).max() / case["E"])
        analytic = np.concatenate([result["g_F"][n].ravel(), [result["g_Jp"][n], result["g_E"][n] * case["E"],
                                                              result["g_nu"][n], result["g_actu"][n]]])
        reference = _reference_gradient(case)
        reverse_error = np.abs(analytic - reference).max() / np.abs(reference).max()
        if forward_error > 2e-6 or reverse_error > F32_REVERSE_BAR:
            failures.append(f"{label}: forward {forward_error:.1e}, reverse {reverse_error:.1e}")
    assert not failures, "\n".join(failures)


def test_encode():
    code, consts = encode("sand", {"friction_angle": 30.0})
    assert code == KIND["sand"] and consts.shape == (N_CONSTS,)
    assert consts[0] == pytest.approx(math.sqrt(2 / 3) * 2 * 0.5 / 2.5)
    assert list(encode("elastoplastic", {})[1]) == [1.0, 2.5e-2, 4.5e-3, 1e4]
    assert list(encode("snow", {"yield_lower": 0.1})[1]) == [0.0, 0.1, 4.5e-3, 0.0]
    assert encode("liquid", {"viscous": True})[1][0] == 1.0
    with pytest.raises(ValueError):
        encode("snow", {"use_von_mises": True})
    with pytest.raises(ValueError):
        encode("clay", {})
    with pytest.raises(ValueError):
        encode("sand", {"friction": 30.0})
