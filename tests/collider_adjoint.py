"""Shared harness for the colliders' hand-written evaluate adjoints (issue 11), against central FD.

A collider's ``<name>_evaluate(pos1, rot1, size1, pos2, rot2, size2, feature)`` gives one contact
(position (3,), normal (3,), dist) as a closed form of the two geom poses with its discrete feature
frozen; ``<name>_evaluate_adjoint(..., feature, g_position, g_normal, g_dist)`` returns the
gradient of g_position·position + g_normal·normal + g_dist·dist with respect to pos1 (3,), rot1
(3, 3), pos2 (3,), rot2 (3, 3) — the rotations' 9 entries taken as independent numbers. This
harness checks those 24 numbers per contact against central finite differences of the same
scalar, the feature frozen at the one decide found at the base pose.

One compiled kernel per (decide, evaluate, adjoint) runs a whole batch in one launch: per case,
decide, then per contact found the adjoint and the 48 perturbed evaluates. The step size eps is
a kernel argument, so an eps scan (eps_scan) reuses the kernel. Use: ``from tests.collider_adjoint
import check_adjoint, eps_scan, cases_from_quats``.

Cases are dicts of float64 arrays (N cases): pos1 (N, 3), rot1 (N, 3, 3), size1 (N, 3), pos2,
rot2, size2 likewise, margin (N,); ``cases_from_quats`` builds one from MuJoCo quaternions and
``cases_from_dicts`` from tests/test_colliders_primitive.py's case dicts. They reach the kernel in
its float: float32 arrays under ``gs.init(precision="32")``.
"""
import mujoco
import numpy as np
import taichi as ti
from taichi.lang import impl

from genesis_lite.solvers.core import runtime

N_INPUTS = 24  # pos1 (3), rot1 (9, row-major), pos2 (3), rot2 (9)
N_COTANGENT = 7  # g_position (3), g_normal (3), g_dist

_KERNELS = {}


@ti.func
def _unit3(j, offset, h):
    """(3,) vector with h at entry j - offset (zero if j is not in offset..offset+2)."""
    return ti.Vector([ti.select(j == offset + i, h, 0.0) for i in ti.static(range(3))])


@ti.func
def _unit33(j, offset, h):
    """(3, 3) matrix with h at row-major entry j - offset (zero if j is not in offset..offset+8)."""
    return ti.Matrix([[ti.select(j == offset + 3 * a + b, h, 0.0) for b in ti.static(range(3))]
                      for a in ti.static(range(3))])


def _kernel(decide, evaluate, adjoint, max_contacts):
    """The batched check kernel of one collider (compiled once per Taichi runtime)."""
    key = (decide, evaluate, adjoint, max_contacts, runtime.epoch)
    if key in _KERNELS:
        return _KERNELS[key]

    @ti.func
    def vec(a: ti.template(), c):
        return ti.Vector([a[c, i] for i in ti.static(range(3))])

    @ti.func
    def mat(a: ti.template(), c):
        return ti.Matrix([[a[c, i, j] for j in ti.static(range(3))] for i in ti.static(range(3))])

    @ti.kernel
    def run(pos1: ti.types.ndarray(), rot1: ti.types.ndarray(), size1: ti.types.ndarray(),
            pos2: ti.types.ndarray(), rot2: ti.types.ndarray(), size2: ti.types.ndarray(),
            margin: ti.types.ndarray(), cotangent: ti.types.ndarray(), eps: float,
            count: ti.types.ndarray(), feature: ti.types.ndarray(), grad: ti.types.ndarray(),
            fd: ti.types.ndarray()):
        for c in range(margin.shape[0]):
            p1, r1, s1 = vec(pos1, c), mat(rot1, c), vec(size1, c)
            p2, r2, s2 = vec(pos2, c), mat(rot2, c), vec(size2, c)
            n, features = decide(p1, r1, s1, p2, r2, s2, margin[c])
            count[c] = n
            for k in range(n):  # a loop, not unrolled: evaluate and adjoint are inlined once
                f = features[k]
                feature[c, k] = f
                g_position = ti.Vector([cotangent[c, k, i] for i in ti.static(range(3))])
                g_normal = ti.Vector([cotangent[c, k, 3 + i] for i in ti.static(range(3))])
                g_dist = cotangent[c, k, 6]
                gp1, gr1, gp2, gr2 = adjoint(p1, r1, s1, p2, r2, s2, f, g_position, g_normal, g_dist)
                for i in ti.static(range(3)):
                    grad[c, k, i] = gp1[i]
                    grad[c, k, 12 + i] = gp2[i]
                    for j in ti.static(range(3)):
                        grad[c, k, 3 + 3 * i + j] = gr1[i, j]
                        grad[c, k, 15 + 3 * i + j] = gr2[i, j]
                for j in range(N_INPUTS):
                    slope = 0.0
                    for side in range(2):  # +eps then -eps
                        h = eps * (1 - 2 * side)
                        p, nrm, d = evaluate(p1 + _unit3(j, 0, h), r1 + _unit33(j, 3, h), s1,
                                             p2 + _unit3(j, 12, h), r2 + _unit33(j, 15, h), s2, f)
                        value = g_position.dot(p) + g_normal.dot(nrm) + g_dist * d
                        slope += value * (1 - 2 * side) / (2 * eps)
                    fd[c, k, j] = slope

    _KERNELS[key] = run
    return run


def adjoint_vs_fd(decide, evaluate, adjoint, max_contacts, cases, seed=0, eps=1e-6):
    """Adjoint and central-FD gradients of every contact decide finds in `cases`.

    Cotangents (g_position, g_normal, g_dist) are standard normal, drawn from `seed` (the same
    for every eps). Returns a dict: count (N,), feature (N, K), grad and fd (N, K, 24) (inputs
    in the order pos1, rot1 row-major, pos2, rot2), cotangent (N, K, 7), and `used` (N, K),
    True where row k is a contact.
    """
    n = len(cases["margin"])
    rng = np.random.default_rng(seed)
    real = np.float32 if impl.get_runtime().default_fp == ti.f32 else np.float64  # the kernels' float
    out = {"count": np.zeros(n, np.int32), "feature": np.zeros((n, max_contacts), np.int32),
           "grad": np.zeros((n, max_contacts, N_INPUTS), real), "fd": np.zeros((n, max_contacts, N_INPUTS), real),
           "cotangent": rng.normal(size=(n, max_contacts, N_COTANGENT)).astype(real)}
    args = [np.ascontiguousarray(cases[key], dtype=real)
            for key in ("pos1", "rot1", "size1", "pos2", "rot2", "size2", "margin")]
    _kernel(decide, evaluate, adjoint, max_contacts)(*args, out["cotangent"], eps, out["count"], out["feature"],
                                                     out["grad"], out["fd"])
    out["used"] = np.arange(max_contacts)[None, :] < out["count"][:, None]
    return out


def relative_errors(out):
    """Per contact: max over the 24 inputs of |adj - fd| / max(1e-8, |fd|_inf of that contact)."""
    grad, fd = out["grad"][out["used"]], out["fd"][out["used"]]
    scale = np.maximum(1e-8, np.abs(fd).max(axis=1))
    return np.abs(grad - fd).max(axis=1) / scale


def check_adjoint(decide, evaluate, adjoint, max_contacts, cases, seed=0, eps=1e-6):
    """Compare a collider's evaluate adjoint with central FD on a batch of cases.

    cases: dict of float64 numpy arrays pos1 (N,3), rot1 (N,3,3), size1 (N,3), pos2, rot2, size2
    (N,3), margin (N,). For each case, decide at the base pose gives the features; for each contact
    k found, random cotangents (g_position, g_normal, g_dist); the adjoint's 24 pose-gradient
    numbers are compared with central finite differences of g·evaluate(...) on each of the 24
    inputs (pos1 3, rot1 9, pos2 3, rot2 9 entries), feature frozen. Returns (max relative error
    over cases, array of the features seen, number of contacts checked). Relative error:
    |adj − fd| / max(1e-8, |fd|_inf over the 24 of that contact).
    """
    out = adjoint_vs_fd(decide, evaluate, adjoint, max_contacts, cases, seed, eps)
    err = relative_errors(out)
    return float(err.max(initial=0.0)), out["feature"][out["used"]], int(out["used"].sum())


def eps_scan(decide, evaluate, adjoint, max_contacts, cases, epss=(1e-5, 1e-6, 1e-7, 1e-8), seed=0):
    """The adjoint against central FD for each step size in `epss` (one kernel, a launch per eps).

    Returns (errors, best): errors {eps: max relative error over the contacts}; best: the max
    over the contacts of each contact's smallest error across the scan. FD truncation falls as
    eps² and rounding grows as 1/eps, so ill-conditioned contacts (nearly parallel capsules,
    near-coincident centres: gradients of 1e3–1e4) are accurate only at their own eps; a wrong
    adjoint is wrong at every eps.
    """
    per_eps = {eps: relative_errors(adjoint_vs_fd(decide, evaluate, adjoint, max_contacts, cases, seed, eps))
               for eps in epss}
    best = np.min(np.stack(list(per_eps.values())), axis=0)
    return {eps: float(err.max(initial=0.0)) for eps, err in per_eps.items()}, float(best.max(initial=0.0))


# ---------------------------------------------------------------- building cases

def quat_to_mat(quat):
    """(N, 3, 3) rotation matrices of (N, 4) quaternions (w, x, y, z), normalized first (MuJoCo's)."""
    quat = np.asarray(quat, dtype=np.float64).reshape(-1, 4)
    out = np.zeros((len(quat), 9))
    for i, q in enumerate(quat):
        mujoco.mju_quat2Mat(out[i], q / np.linalg.norm(q))
    return out.reshape(-1, 3, 3)


def cases_from_quats(pos1, quat1, size1, pos2, quat2, size2, margin):
    """The harness's case dict from poses given as positions (N, 3) and quaternions (N, 4)."""
    as3 = lambda a: np.asarray(a, dtype=np.float64).reshape(-1, 3)  # noqa: E731
    return {"pos1": as3(pos1), "rot1": quat_to_mat(quat1), "size1": as3(size1), "pos2": as3(pos2),
            "rot2": quat_to_mat(quat2), "size2": as3(size2), "margin": np.asarray(margin, dtype=np.float64)}


def cases_from_dicts(cases):
    """The harness's case dict from a list of test_colliders_primitive case dicts (pos (2, 3), quat
    (2, 4), size (2, 3), margin (2,), gap (2,)); the pair's margin is margin + gap, as MuJoCo's."""
    stack = lambda key, g: np.array([c[key][g] for c in cases], dtype=np.float64)  # noqa: E731
    margin = np.array([c["margin"][0] + c["margin"][1] + (c["gap"][0] + c["gap"][1]) for c in cases])
    return cases_from_quats(stack("pos", 0), stack("quat", 0), stack("size", 0), stack("pos", 1),
                            stack("quat", 1), stack("size", 1), margin)


def merge_cases(*parts):
    """One case dict of several, concatenated in order."""
    return {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
