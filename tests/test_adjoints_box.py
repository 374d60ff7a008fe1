"""Hand-written adjoints of the box colliders' evaluates (solvers/rigid/collision/box.py) against
central finite differences, with the shared harness tests/collider_adjoint.py: for every contact
decide finds, the 24 pose-gradient numbers of a random cotangent, with the feature frozen.

The cases are tests/test_colliders_box.py's (many of each kind of contact) and its exact ties.
The same cases are also run rigidly turned, so that exact rotations no longer round exactly. Box–box
also gets edges beside edges, whose witness points clamp to the edges' ends. Each test runs an eps
scan with one compiled kernel and asserts that every branch of evaluate was checked.
"""
import numpy as np
import pytest

from genesis_lite.solvers.rigid.collision import box
from tests import collider_adjoint as harness
from tests import test_colliders_box as colliders

EPS_SCAN = (1e-5, 1e-6, 1e-7, 1e-8)
TOL = 1e-6  # relative, at eps = 1e-7, where the scan has converged (eps² truncation above it, rounding below)
# Box–box's exact tie "two equal cubes face to face, one turned by 90° about z": the incident edges lie
# along the reference face's side planes to within ~1e-17, so a cut vertex's ratio dp / (dp - dq)
# has gradients of ~1e15: evaluate itself is ill-conditioned there and FD cannot resolve it.
ILL_CONDITIONED = {"box_box": (2,)}


def _case_dict(cases):
    """The harness's case dict of test_colliders_box cases (size1, size2, pose1, pose2, margin, label)."""
    return harness.cases_from_quats([c[2][0] for c in cases], [c[2][1] for c in cases], [c[0] for c in cases],
                                    [c[3][0] for c in cases], [c[3][1] for c in cases], [c[1] for c in cases],
                                    [c[4] for c in cases])


def _turned(cases, rng):
    """The cases with both geoms turned rigidly about the world origin by one random rotation each."""
    turn = harness.quat_to_mat([colliders._random_quat(rng) for _ in cases["margin"]])
    out = dict(cases)
    for g in ("1", "2"):
        out["pos" + g] = np.einsum("nij,nj->ni", turn, cases["pos" + g])
        out["rot" + g] = turn @ cases["rot" + g]
    return out


def _edge_cases(rng, n=300):
    """Edge beside edge (box 1's edge up, box 2's edge down, crossed), shifted sideways up to 1.5x
    the summed sizes and within a wide margin: the closest points clamp to the edges' ends."""
    q, qmul = colliders._quat, colliders._qmul
    cases = []
    for _ in range(n):
        half1, half2 = colliders._sizes(rng, "box"), colliders._sizes(rng, "box")
        q1 = qmul(q(rng.normal(size=3), rng.uniform(0, 0.3)), q([0, 1, 0], np.pi / 4))
        q2 = qmul(q([0, 0, 1], rng.uniform(0.2, 1.4)), q([1, 0, 0], np.pi / 4))
        offset = rng.uniform(-1, 1, 3) * (half1 + half2) * rng.choice([0.5, 1.0, 1.5])
        offset[2] = (colliders._support(q1, half1, [0, 0, 1]) + colliders._support(q2, half2, [0, 0, -1])
                     + rng.uniform(-0.02, 0.05))
        frame, p1 = colliders._random_quat(rng), rng.uniform(-0.5, 0.5, 3)
        cases.append((half1, half2, (p1, qmul(frame, q1)), (p1 + colliders._qrot(frame, offset), qmul(frame, q2)),
                      0.08, "edge beside edge"))
    return cases


def _cases(pair):
    """All the cases of a pair: random, turned copies of them, exact ties, and for box–box edges
    beside edges."""
    rng = np.random.default_rng(7)  # test_colliders_box's seed: its rare branches occur
    random = _case_dict(colliders.CASES[pair](rng))
    ties = [c for k, c in enumerate(colliders._degenerate_cases(pair)) if k not in ILL_CONDITIONED.get(pair, ())]
    parts = [random, _turned(random, rng), _case_dict(ties)]
    if pair == "box_box":
        parts.append(_case_dict(_edge_cases(rng)))
    return harness.merge_cases(*parts)


def _clamped_axes(sb):
    """Sphere–box features (n,) → how many axes the nearest box point is clamped on (0 inside)."""
    return sum(np.where(sb < box.SPHERE_BOX_INSIDE, (sb // 3**c) % 3 != 0, False) for c in range(3))


def _branches(pair, feature):
    """The set of evaluate's branches the features (n,) exercise (names, see EXPECTED)."""
    seen = set()
    if pair == "box_box":
        code = feature & 15
        face, edge = feature[code < 6], feature[code >= 6]
        tag = face >> 8
        seen |= {f"face {c}" for c in np.unique(face & 15)}
        seen |= {name for name, m in (("corner", tag < 4), ("cut", (tag >= 4) & (tag < 20)), ("rect", tag >= 20))
                 if m.any()}
        seen |= {"edge"} if len(edge) else set()
        seen |= {f"edge clip {k}" for k, shift in enumerate((10, 12, 14)) if np.any((edge >> shift) & 3)}
        return seen
    sb = feature % box.SPHERE_BOX_FEATURES
    seen |= {f"inside face {f}" for f in np.unique(sb[sb >= box.SPHERE_BOX_INSIDE] - box.SPHERE_BOX_INSIDE)}
    seen |= {f"clamped {k}" for k in np.unique(_clamped_axes(sb)) if k}
    if pair == "capsule_box":
        seg = feature // box.SPHERE_BOX_FEATURES
        base, off = seg % box.CAPSULE_BASES, seg // box.CAPSULE_BASES
        kinds = np.select([off >= box._OFF_PLANE, off >= box._OFF_EDGE, off >= box._OFF_SPAN, off >= box._OFF_END],
                          ["plane", "along edge", "span", "end"], "none")
        seen |= {f"offset {k}" for k in np.unique(kinds)}
        seen |= {f"edge base state {s}" for s in np.unique((base[base >= 2] - 2) % 9)}
        seen |= {"end base"} if np.any(base < 2) else set()
        seen |= {"plane offset inside"} if np.any((kinds == "plane") & (sb >= box.SPHERE_BOX_INSIDE)) else set()
    return seen


_SPHERE = {f"inside face {f}" for f in range(6)} | {f"clamped {k}" for k in (1, 2, 3)}
EXPECTED = {
    "sphere_box": _SPHERE,
    # edge base states 3 s1 + s2 (frame.py: 0 free, 1 at +1, 2 at -1): both free (0), x2 clamped (1, 2),
    # x1 clamped (3), both (5)
    "capsule_box": _SPHERE | {f"offset {k}" for k in ("none", "end", "span", "along edge", "plane")}
    | {"end base", "plane offset inside"} | {f"edge base state {s}" for s in (0, 1, 2, 3, 5)},
    # the witness parallel bit (1 - b² < MINVAL on a valid edge axis) needs |sin| in [1e-8, 3e-8]: not drawn
    "box_box": {f"face {c}" for c in range(6)} | {"corner", "cut", "rect", "edge"}
    | {f"edge clip {k}" for k in range(3)},
}


@pytest.mark.parametrize("pair", ["sphere_box", "capsule_box", "box_box"])
def test_adjoint_matches_fd(f64, pair):
    """Every contact's adjoint equals central FD of its evaluate (24 pose numbers, relative error
    <= TOL at eps 1e-7), and every branch of evaluate was checked."""
    cases = _cases(pair)
    args = (getattr(box, pair + "_decide"), getattr(box, pair + "_evaluate"), getattr(box, pair + "_evaluate_adjoint"),
            colliders.COLLIDERS[pair][1], cases)
    results = {eps: harness.check_adjoint(*args, eps=eps) for eps in EPS_SCAN}  # one kernel: eps is an argument
    scan = {eps: err for eps, (err, _, _) in results.items()}
    print(pair, "max relative error per eps:", {eps: f"{err:.1e}" for eps, err in scan.items()})
    assert scan[1e-7] <= TOL, scan
    _, features, checked = results[1e-7]
    assert checked > 300, checked
    missing = EXPECTED[pair] - _branches(pair, features)
    assert not missing, missing
