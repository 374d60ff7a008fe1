"""Hand-written adjoints of the primitive colliders' evaluates (collision/primitive.py) and of the
frame.py helpers they and the box colliders use, against central finite differences.

Each pair: the random and degenerate poses of tests/test_colliders_primitive.py (every feature
branch its decide has), one batched kernel (tests/collider_adjoint.py) comparing the adjoint's 24
pose-gradient numbers per contact with central differences of g·evaluate, feature frozen, random
cotangents g. An eps scan (1e-5 … 1e-8) per pair shows the convergence: the error falls 100× per
decade (the differences' truncation) until rounding takes over. The bar holds for each contact
at its best eps of the scan: near-coincident sphere centres and capsules just past MuJoCo's
parallel test (about 1e-4 rad) have gradients of 1e3–1e4 and an ill-conditioned forward, so
truncation still shows at 1e-6 and rounding already at 1e-7. A wrong adjoint is wrong at every eps.
"""
import numpy as np
import pytest
import taichi as ti

from genesis_lite.solvers.rigid.collision import frame, primitive
from tests.collider_adjoint import cases_from_dicts, check_adjoint, eps_scan, quat_to_mat
from tests.test_colliders_primitive import (EXPECTED_FEATURES, PAIRS, degenerate_cases, parallel_capsule_cases,
                                            random_cases, standing_cylinder_cases)

TOL = 1e-6
EPS = 1e-7  # the stand-in segment collider is well conditioned: one eps
SCAN = (1e-5, 1e-6, 1e-7, 1e-8)
N_RANDOM = 600


def _cases(name):
    _, _, type1, type2 = PAIRS[name]
    seed = sum(map(ord, name))
    cases = random_cases(type1, type2, N_RANDOM, seed) + degenerate_cases(name)
    if name == "capsule_capsule":
        cases += parallel_capsule_cases(N_RANDOM // 2, seed)
    return cases_from_dicts(cases)


@pytest.mark.parametrize("name", list(PAIRS))
def test_evaluate_adjoint_matches_fd(f64, name):
    K = PAIRS[name][1]
    decide, evaluate, adjoint = (getattr(primitive, name + suffix)
                                 for suffix in ("_decide", "_evaluate", "_evaluate_adjoint"))
    cases = _cases(name)
    _, features, checked = check_adjoint(decide, evaluate, adjoint, K, cases)
    scan, best = eps_scan(decide, evaluate, adjoint, K, cases, SCAN)
    per_eps = ", ".join(f"{e:.0e}: {v:.1e}" for e, v in scan.items())
    print(f"\n{name}: {checked} contacts, features {sorted(set(features.tolist()))}, max relative error "
          f"(each contact at its best eps) {best:.1e}; per eps {per_eps}")
    missing = EXPECTED_FEATURES[name] - set(features.tolist())
    assert not missing, f"{name}: features never checked: {sorted(missing)}"
    assert best <= TOL, f"{name}: adjoint differs from central FD by {best:.3g} (relative)"
    # converged: the error falls from eps 1e-5 to 1e-6 unless it already sits at the rounding floor
    assert scan[1e-6] < scan[1e-5] or scan[1e-5] < 1e-9, f"{name}: FD error does not fall with eps: {scan}"


def test_standing_cylinder_adjoint_matches_fd(f64):
    """Our rule for a cylinder standing on a plane (outside MuJoCo compatibility): its four rim
    points (features STANDING + 4 flipped + k), and MuJoCo's lowest rim point kept beside them
    when tilted beyond RIM_TILT."""
    cases = cases_from_dicts(standing_cylinder_cases(N_RANDOM, 11))
    decide, evaluate, adjoint = (primitive.plane_cylinder_standing_decide, primitive.plane_cylinder_evaluate,
                                 primitive.plane_cylinder_evaluate_adjoint)
    _, features, checked = check_adjoint(decide, evaluate, adjoint, primitive.PLANE_CYLINDER_MAX, cases)
    scan, best = eps_scan(decide, evaluate, adjoint, primitive.PLANE_CYLINDER_MAX, cases, SCAN)
    expected = {primitive.STANDING + k for k in range(8)} | {primitive.NEAR_RIM, 4 + primitive.NEAR_RIM}
    assert expected <= set(features.tolist()), sorted(set(features.tolist()))
    assert best <= TOL, f"standing cylinder: adjoint differs from central FD by {best:.3g} (relative)"
    assert scan[1e-6] < scan[1e-5] or scan[1e-5] < 1e-9, scan


def test_plane_cylinder_adjoint_matches_fd_in_float32(f32):
    """float32 makes the rim direction perpendicular to the axis before normalising it (a float32
    unit axis is off unit by ~1e-7: primitive._across); its adjoint, against float32 central FD at
    the best eps of a scan (rounding ~1e-7 / eps, truncation ~eps²). Without the projection's own
    terms the adjoint is off by 0.3 (relative)."""
    cases = _cases("plane_cylinder")
    decide, evaluate, adjoint = (primitive.plane_cylinder_decide, primitive.plane_cylinder_evaluate,
                                 primitive.plane_cylinder_evaluate_adjoint)
    _, features, _ = check_adjoint(decide, evaluate, adjoint, primitive.PLANE_CYLINDER_MAX, cases)
    _, best = eps_scan(decide, evaluate, adjoint, primitive.PLANE_CYLINDER_MAX, cases, (3e-3, 1e-3, 3e-4))
    assert EXPECTED_FEATURES["plane_cylinder"] <= set(features.tolist())
    assert best <= 2e-3, f"plane–cylinder in float32: adjoint differs from central FD by {best:.3g} (relative)"


# ---------------------------------------------------------------- frame helpers for segments in [-1, 1]
#
# segment_pair_terms / segment_pair_params (used by the box colliders) have no primitive
# collider: a stand-in collider checks their adjoints through the same harness. Geom i's
# segment is pos_i + x_i a_i, a_i = (column 2 of rot_i) × size_i[1]; its "contacts" are the nine
# clamp states; evaluate returns position = the point on segment 1, normal = the point on
# segment 2 and dist = det, so every output of both helpers reaches the loss.

N_STATES = 9


@ti.func
def _segment_inputs(pos1, rot1, size1, pos2, rot2, size2):
    return frame.column(rot1, 2) * size1[1], frame.column(rot2, 2) * size2[1], pos1 - pos2


@ti.func
def _segments_decide(pos1, rot1, size1, pos2, rot2, size2, margin):
    return N_STATES, ti.Vector([state for state in ti.static(range(N_STATES))])


@ti.func
def _segments_evaluate(pos1, rot1, size1, pos2, rot2, size2, feature):
    a1, a2, dif = _segment_inputs(pos1, rot1, size1, pos2, rot2, size2)
    ma, mb, mc, u, v, det = frame.segment_pair_terms(a1, a2, dif)
    x1, x2 = frame.segment_pair_params(ma, mb, mc, u, v, det, feature)
    return pos1 + a1 * x1, pos2 + a2 * x2, det


@ti.func
def _segments_evaluate_adjoint(pos1, rot1, size1, pos2, rot2, size2, feature, g_position, g_normal, g_dist):
    a1, a2, dif = _segment_inputs(pos1, rot1, size1, pos2, rot2, size2)
    ma, mb, mc, u, v, det = frame.segment_pair_terms(a1, a2, dif)
    x1, x2 = frame.segment_pair_params(ma, mb, mc, u, v, det, feature)
    g_ma, g_mb, g_mc, g_u, g_v, g_det = frame.segment_pair_params_adjoint(
        ma, mb, mc, u, v, det, feature, frame.dot3(g_position, a1), frame.dot3(g_normal, a2))
    g_a1, g_a2, g_dif = frame.segment_pair_terms_adjoint(a1, a2, dif, g_ma, g_mb, g_mc, g_u, g_v, g_det + g_dist)
    g_a1 += g_position * x1
    g_a2 += g_normal * x2
    return (g_position + g_dif, frame.column_adjoint(g_a1 * size1[1], 2), g_normal - g_dif,
            frame.column_adjoint(g_a2 * size2[1], 2))


def test_segment_pair_adjoints_match_fd(f64):
    rng = np.random.default_rng(11)
    n = 200
    rots = quat_to_mat(rng.normal(size=(2 * n, 4))).reshape(n, 2, 3, 3)
    size = np.zeros((n, 2, 3))
    size[:, :, 1] = rng.uniform(0.05, 0.5, (n, 2))
    cases = {"pos1": rng.uniform(-0.5, 0.5, (n, 3)), "rot1": rots[:, 0], "size1": size[:, 0],
             "pos2": rng.uniform(-0.5, 0.5, (n, 3)), "rot2": rots[:, 1], "size2": size[:, 1], "margin": np.zeros(n)}
    err, features, checked = check_adjoint(_segments_decide, _segments_evaluate, _segments_evaluate_adjoint,
                                           N_STATES, cases, eps=EPS)
    print(f"\nsegment_pair_terms/params: {checked} (case, state) pairs, max relative error {err:.1e}")
    assert set(features.tolist()) == set(range(N_STATES))
    assert err <= TOL, f"segment_pair adjoints differ from central FD by {err:.3g} (relative)"
