"""Per-stage adjoints of the contact rows against central finite differences (float64): the
impedance's derivative in the distance and its five solimp parameters, and the contact frame's
reverse (normal and first-tangent hint → the frame's rows), at random points of every branch.
The whole chain (rows, implicit solve, colliders) is checked on rollouts in
tests/test_contact_gradients.py.
"""
import numpy as np
import taichi as ti

from genesis_lite.solvers.rigid.collision.frame import contact_frame, contact_frame_adjoint
from genesis_lite.solvers.rigid.constraint.rows import impedance, impedance_gradient

EPS = 1e-7


@ti.kernel
def _impedance_kernel(args: ti.types.ndarray(), out: ti.types.ndarray()):
    """args (N, 7): solimp (5), dist, margin → out (N, 7): d, ∂d/∂dist, ∂d/∂solimp (5)."""
    for n in range(args.shape[0]):
        solimp = ti.Vector([args[n, k] for k in ti.static(range(5))])
        g_dist, g_solimp = impedance_gradient(solimp, args[n, 5], args[n, 6])
        out[n, 0], out[n, 1] = impedance(solimp, args[n, 5], args[n, 6]), g_dist
        for k in ti.static(range(5)):
            out[n, 2 + k] = g_solimp[k]


def test_impedance_gradient(f64):
    rng = np.random.default_rng(0)
    n = 400
    solimp = np.stack([rng.uniform(0.05, 0.5, n), rng.uniform(0.6, 0.99, n), rng.uniform(0.001, 0.02, n),
                       rng.uniform(0.2, 0.8, n), rng.choice([1.0, 2.0, 2.7, 4.0], n)], axis=1)
    x = rng.uniform(0.02, 1.3, n)  # |dist − margin| / width: both power curves and the flat part
    margin = rng.uniform(0.0, 0.01, n)
    dist = margin - x * solimp[:, 2] * rng.choice([-1.0, 1.0], n)
    args = np.concatenate([solimp, dist[:, None], margin[:, None]], axis=1)
    base = np.zeros((n, 7))
    _impedance_kernel(args, base)
    for j, column in enumerate([5, 0, 1, 2, 3, 4]):  # dist, then solimp
        ends = []
        for sign in (1.0, -1.0):
            moved = args.copy()
            moved[:, column] += sign * EPS
            out = np.zeros((n, 7))
            _impedance_kernel(moved, out)
            ends.append(out[:, 0])
        numeric = (ends[0] - ends[1]) / (2 * EPS)
        analytic = base[:, 1 + j]
        kink = np.abs(np.abs(dist - margin) / solimp[:, 2] - solimp[:, 3]) < 1e-4  # the midpoint: y is C¹
        err = np.abs(analytic - numeric)[~kink] / (1e-3 + np.abs(numeric[~kink]))
        assert err.max() < 1e-5, (column, err.max())
    assert (x > 1).any() and (x < solimp[:, 3]).any() and ((x > solimp[:, 3]) & (x < 1)).any()


@ti.kernel
def _frame_kernel(args: ti.types.ndarray(), weights: ti.types.ndarray(), out: ti.types.ndarray()):
    """args (N, 6): normal, tangent hint; weights (N, 3, 3) → out (N, 7): Σ weights·frame, and
    its gradients in the normal (3) and the hint (3)."""
    for n in range(args.shape[0]):
        normal = ti.Vector([args[n, k] for k in ti.static(range(3))])
        tangent = ti.Vector([args[n, 3 + k] for k in ti.static(range(3))])
        g_frame = ti.Matrix([[weights[n, i, j] for j in ti.static(range(3))] for i in ti.static(range(3))])
        g_normal, g_tangent = contact_frame_adjoint(normal, tangent, g_frame)
        out[n, 0] = (contact_frame(normal, tangent) * g_frame).sum()
        for k in ti.static(range(3)):
            out[n, 1 + k], out[n, 4 + k] = g_normal[k], g_tangent[k]


def test_contact_frame_adjoint(f64):
    """Normals of every direction and length near 1, with and without a hint (plane–capsule's
    capsule axis): the frame's rows n, t1 = unit(hint − n (n·hint)), t2 = n × t1."""
    rng = np.random.default_rng(1)
    n = 600
    normal = rng.normal(size=(n, 3))
    normal *= rng.uniform(0.9, 1.1, (n, 1)) / np.linalg.norm(normal, axis=1, keepdims=True)
    hint = rng.normal(size=(n, 3))
    hint /= np.linalg.norm(hint, axis=1, keepdims=True)
    hint[: n // 2] = 0.0  # no hint: a world axis (y, or z when the normal is near y)
    args = np.concatenate([normal, hint], axis=1)
    weights = rng.normal(size=(n, 3, 3))
    base = np.zeros((n, 7))
    _frame_kernel(args, weights, base)
    for column in range(6):
        ends = []
        for sign in (1.0, -1.0):
            moved = args.copy()
            moved[:, column] += sign * EPS
            out = np.zeros((n, 7))
            _frame_kernel(moved, weights, out)
            ends.append(out[:, 0])
        numeric = (ends[0] - ends[1]) / (2 * EPS)
        err = np.abs(base[:, 1 + column] - numeric) / (1e-3 + np.abs(numeric))
        if column >= 3:  # a replaced hint has no gradient
            assert np.all(base[: n // 2, 1 + column] == 0.0)
        assert err.max() < 1e-5, (column, err.max())
    assert (np.abs(normal[: n // 2, 1]) >= 0.5).any() and (np.abs(normal[: n // 2, 1]) < 0.5).any()
