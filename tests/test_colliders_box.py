"""Box colliders (solvers/rigid/collision/box.py) against MuJoCo's mjc_SphereBox, mjc_CapsuleBox
and mjc_BoxBox: for many poses per pair (resting, shallow and deep penetration, within the margin,
separated), the contacts MuJoCo lists in d.contact after mj_forward — count, order, positions,
normals, distances — must be ours. One compiled kernel per collider runs a whole batch of cases.
"""
import mujoco
import numpy as np
import pytest
import taichi as ti

from genesis_lite.solvers.rigid.collision import box

TOL = 1e-10  # m (positions, distances) and unit (normals)
TYPE_NAME = {"sphere_box": ("sphere", "box"), "capsule_box": ("capsule", "box"), "box_box": ("box", "box")}
COLLIDERS = {"sphere_box": (box.sphere_box, box.SPHERE_BOX_MAX), "capsule_box": (box.capsule_box, box.CAPSULE_BOX_MAX),
             "box_box": (box.box_box, box.BOX_BOX_MAX)}
_KERNELS = {}


# ---------------------------------------------------------------- rotations


def _quat(axis, angle):
    """(4,) w-x-y-z quaternion of a rotation by `angle` (rad) about `axis`."""
    axis = np.asarray(axis, dtype=np.float64)
    axis = axis / np.linalg.norm(axis)
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis])


def _qmul(a, b):
    """Quaternion product a b (w-x-y-z)."""
    return np.array([a[0] * b[0] - a[1:] @ b[1:], *(a[0] * b[1:] + b[0] * a[1:] + np.cross(a[1:], b[1:]))])


def _qrot(q, v):
    """Vector v rotated by the unit quaternion q."""
    return _qmul(_qmul(q, np.array([0.0, *v])), q * np.array([1, -1, -1, -1]))[1:]


def _random_quat(rng):
    """A uniformly random unit quaternion."""
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


# ---------------------------------------------------------------- MuJoCo oracle


def _mujoco_case(pair, size1, size2, pose1, pose2, margin):
    """MuJoCo's geom poses and contacts for one case: two free bodies, one geom each (geom 0 is
    the pair's first geom; the margin is set on it alone, so the pair's margin is exactly it)."""
    t1, t2 = TYPE_NAME[pair]
    s1 = " ".join(repr(float(x)) for x in size1[: {"sphere": 1, "capsule": 2, "box": 3}[t1]])
    s2 = " ".join(repr(float(x)) for x in size2)
    xml = f"""<mujoco><worldbody>
      <body><freejoint/><geom type="{t1}" size="{s1}" margin="{margin!r}"/></body>
      <body><freejoint/><geom type="{t2}" size="{s2}"/></body>
    </worldbody></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    d.qpos[:] = np.concatenate([pose1[0], pose1[1], pose2[0], pose2[1]])
    mujoco.mj_forward(m, d)
    con = d.contact[: d.ncon]
    assert all(tuple(c.geom) == (0, 1) for c in con)
    return (d.geom_xpos.copy(), d.geom_xmat.reshape(2, 3, 3).copy(), np.array([c.pos for c in con]).reshape(-1, 3),
            np.array([c.frame[:3] for c in con]).reshape(-1, 3), np.array([c.dist for c in con]))


# ---------------------------------------------------------------- our colliders, batched


def _kernel(pair):
    """One compiled kernel per collider: every case n of a batch through the collider, and the
    contacts of given features (replay_feature[n, :replay_count[n]]) evaluated at the same poses."""
    if pair in _KERNELS:
        return _KERNELS[pair]
    collider, K = COLLIDERS[pair]
    evaluate = getattr(box, pair + "_evaluate")

    @ti.kernel
    def run(pos: ti.types.ndarray(), rot: ti.types.ndarray(), size: ti.types.ndarray(), margin: ti.types.ndarray(),
            replay_count: ti.types.ndarray(), replay_feature: ti.types.ndarray(), count: ti.types.ndarray(),
            position: ti.types.ndarray(), normal: ti.types.ndarray(), dist: ti.types.ndarray(),
            feature: ti.types.ndarray(), replayed: ti.types.ndarray()):
        for n in range(margin.shape[0]):
            p1 = ti.Vector([pos[n, 0, i] for i in ti.static(range(3))])
            p2 = ti.Vector([pos[n, 1, i] for i in ti.static(range(3))])
            r1 = ti.Matrix([[rot[n, 0, i, j] for j in ti.static(range(3))] for i in ti.static(range(3))])
            r2 = ti.Matrix([[rot[n, 1, i, j] for j in ti.static(range(3))] for i in ti.static(range(3))])
            s1 = ti.Vector([size[n, 0, i] for i in ti.static(range(3))])
            s2 = ti.Vector([size[n, 1, i] for i in ti.static(range(3))])
            c, p, nrm, d, f = collider(p1, r1, s1, p2, r2, s2, margin[n])
            count[n] = c
            for k in ti.static(range(K)):
                for i in ti.static(range(3)):
                    position[n, k, i] = p[k, i]
                    normal[n, k, i] = nrm[k, i]
                dist[n, k] = d[k]
                feature[n, k] = f[k]
            for k in range(replay_count[n]):  # rows: position (3), normal (3), dist
                rp, rn, rd = evaluate(p1, r1, s1, p2, r2, s2, replay_feature[n, k])
                for i in ti.static(range(3)):
                    replayed[n, k, i] = rp[i]
                    replayed[n, k, 3 + i] = rn[i]
                replayed[n, k, 6] = rd

    _KERNELS[pair] = (run, K)
    return _KERNELS[pair]


def _ours(pair, pos, rot, size, margin, replay_count=None, replay_feature=None):
    """Our collider on a batch: pos (N, 2, 3), rot (N, 2, 3, 3), size (N, 2, 3), margin (N,); and
    the replay of features (N, K) (the first replay_count (N,) of each case) at these poses."""
    run, K = _kernel(pair)
    N = len(margin)
    if replay_count is None:
        replay_count, replay_feature = np.zeros(N, np.int32), np.zeros((N, K), np.int32)
    out = dict(count=np.zeros(N, np.int32), position=np.zeros((N, K, 3)), normal=np.zeros((N, K, 3)),
               dist=np.zeros((N, K)), feature=np.zeros((N, K), np.int32), replayed=np.zeros((N, K, 7)))
    run(pos, rot, size, margin, replay_count, replay_feature, out["count"], out["position"], out["normal"],
        out["dist"], out["feature"], out["replayed"])
    return out


def _compare(pair, cases):
    """Run the cases [(size1, size2, pose1, pose2, margin, label)] through MuJoCo and ours; return
    (failure messages, our outputs, number of MuJoCo contacts per case, our inputs)."""
    refs = [_mujoco_case(pair, *c[:5]) for c in cases]
    pos = np.array([r[0] for r in refs])
    rot = np.array([r[1] for r in refs])
    size = np.array([[c[0], c[1]] for c in cases], dtype=np.float64)
    margin = np.array([c[4] for c in cases], dtype=np.float64)
    out = _ours(pair, pos, rot, size, margin)
    failures = []
    for n, (case, ref) in enumerate(zip(cases, refs)):
        _, _, ref_pos, ref_normal, ref_dist = ref
        count = out["count"][n]
        if count != len(ref_dist):
            failures.append(f"{case[5]} #{n}: {count} contacts, MuJoCo {len(ref_dist)}")
            continue
        for name, ours, theirs in (("position", out["position"][n, :count], ref_pos),
                                   ("normal", out["normal"][n, :count], ref_normal),
                                   ("dist", out["dist"][n, :count], ref_dist)):
            err = np.max(np.abs(ours - theirs), initial=0.0)
            if not err <= TOL:
                failures.append(f"{case[5]} #{n}: {name} off by {err:.2e}")
    return failures, out, np.array([len(r[4]) for r in refs]), (pos, rot, size, margin)


# ---------------------------------------------------------------- cases


def _sizes(rng, kind):
    """Half sizes of a geom: sphere (r, 0, 0), capsule (r, half-length, 0), box (3 half sizes)."""
    if kind == "sphere":
        return np.array([rng.uniform(0.05, 0.3), 0.0, 0.0])
    if kind == "capsule":
        return np.array([rng.uniform(0.03, 0.2), rng.uniform(0.05, 0.4), 0.0])
    return rng.uniform(0.05, 0.4, size=3)


def _sphere_box_cases(rng):
    """Sphere centres inside the box, resting on a face, and around faces, edges and corners."""
    cases = []
    for n in range(240):
        r, half = _sizes(rng, "sphere"), _sizes(rng, "box")
        qbox = IDENTITY if n % 4 == 0 else _random_quat(rng)
        pbox = rng.uniform(-0.5, 0.5, 3)
        mode = n % 6
        if mode == 0:  # centre inside the box (the nearest face decides)
            local = rng.uniform(-0.9, 0.9, 3) * half
        elif mode == 1:  # resting on a face, slightly in or out
            axis = rng.integers(3)
            local = rng.uniform(-0.9, 0.9, 3) * half
            local[axis] = rng.choice([-1, 1]) * (half[axis] + r[0] + rng.uniform(-0.01, 0.005))
        else:  # anywhere around: faces, edges, corners, in, out (within or beyond the margin)
            direction = rng.normal(size=3)
            local = half * np.sign(direction) * rng.uniform(0.3, 1.0, 3) + direction / np.linalg.norm(direction) * (
                r[0] + rng.uniform(-0.6, 0.1 if mode < 5 else 0.5) * r[0])
        margin = [0.0, 0.02, 0.0][n % 3]
        cases.append((r, half, (pbox + _qrot(qbox, local), _random_quat(rng)), (pbox, qbox), margin, f"mode {mode}"))
    return cases


def _capsule_box_cases(rng):
    """Capsules lying on a face (axis along a box axis or not, tilted), standing on an end,
    crossing an edge, and anywhere around the box."""
    cases = []
    for n in range(360):
        cap, half = _sizes(rng, "capsule"), _sizes(rng, "box")
        qbox = IDENTITY if n % 3 == 0 else _random_quat(rng)
        pbox = rng.uniform(-0.5, 0.5, 3)
        mode = n % 6
        face = rng.integers(3)
        sign = rng.choice([-1, 1])
        if mode == 0:  # lying on a face, axis along a box axis (parallel), resting
            along = (face + rng.integers(1, 3)) % 3
            qcap = _z_to(np.eye(3)[along] * rng.choice([-1, 1]))
            local = rng.uniform(-0.8, 0.8, 3) * half
            local[face] = sign * (half[face] + cap[0] + rng.uniform(-0.005, 0.003))
        elif mode == 1:  # lying on a face, axis in the face plane at a random angle, or tilted slightly
            normal = np.eye(3)[face]
            in_plane = np.cross(normal, rng.normal(size=3))
            tilt = rng.choice([0.0, rng.uniform(-0.3, 0.3)])
            direction = in_plane / np.linalg.norm(in_plane) * np.cos(tilt) + normal * np.sin(tilt)
            qcap = _z_to(direction)
            local = rng.uniform(-0.8, 0.8, 3) * half
            local[face] = sign * (half[face] + cap[0] + abs(np.sin(tilt)) * cap[1] + rng.uniform(-0.01, 0.003))
        elif mode == 2:  # an end against a face
            qcap = _z_to(np.eye(3)[face] * sign + rng.normal(size=3) * 0.3)
            local = rng.uniform(-0.8, 0.8, 3) * half
            local[face] = sign * (half[face] + cap[0] + cap[1] * abs(_qrot(qcap, [0, 0, 1])[face])
                                  + rng.uniform(-0.02, 0.005))
        elif mode == 3:  # crossing an edge
            qcap = _random_quat(rng)
            local = half * np.sign(rng.normal(size=3))
            local[face] = 0.0
            local += rng.normal(size=3) * cap[0]
        else:  # anywhere around
            qcap = _random_quat(rng)
            local = rng.normal(size=3) * (half + cap[0] + 0.5 * cap[1])
        margin = [0.0, 0.01, 0.0, 0.03][n % 4]
        cases.append((cap, half, (pbox + _qrot(qbox, local), _qmul(qbox, qcap)), (pbox, qbox), margin,
                      f"mode {mode}"))
    return cases


def _z_to(direction):
    """A quaternion turning +z onto `direction`."""
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    axis = np.cross([0.0, 0.0, 1.0], d)
    if np.linalg.norm(axis) < 1e-12:
        return IDENTITY if d[2] > 0 else np.array([0.0, 1.0, 0.0, 0.0])
    return _quat(axis, np.arccos(np.clip(d[2], -1, 1)))


def _box_box_cases(rng):
    """Poses in a frame F (random, or the world for half of them): box 1 at F's origin, box 2 above
    it, each mode a kind of contact; depth: penetration (< 0) or gap of the closest features."""
    cases = []
    for n in range(540):
        half1, half2 = _sizes(rng, "box"), _sizes(rng, "box")
        qf = IDENTITY if n % 2 == 0 else _random_quat(rng)
        q1 = IDENTITY
        mode = n % 9
        depth = rng.choice([rng.uniform(-0.01, 0.0), rng.uniform(0.0, 0.004), rng.uniform(-0.1, -0.01)])
        offset = rng.uniform(-1, 1, 3) * half1
        if mode == 0:  # face to face, aligned (half of them centred)
            q2 = IDENTITY
            offset *= rng.choice([0.0, 1.0])
        elif mode == 1:  # face to face, rotated about the normal
            q2 = _quat([0, 0, 1], rng.uniform(-np.pi, np.pi))
        elif mode == 2:  # face to face, slightly tilted
            q2 = _qmul(_quat(rng.normal(size=3), rng.uniform(0.0, 0.05)), _quat([0, 0, 1], rng.uniform(-3, 3)))
        elif mode == 3:  # an edge on the face
            q2 = _qmul(_quat([0, 0, 1], rng.uniform(-3, 3)), _quat([1, 0, 0], np.pi / 4 + rng.uniform(-0.02, 0.02)))
        elif mode == 4:  # a corner on the face
            q2 = _qmul(_quat([0, 0, 1], rng.uniform(-3, 3)),
                       _qmul(_quat([1, 0, 0], np.arctan(np.sqrt(0.5))), _quat([0, 1, 0], np.pi / 4)))
            offset *= 0.8
        elif mode == 5:  # edge across edge
            q1 = _quat([0, 1, 0], np.pi / 4)
            q2 = _qmul(_quat([0, 0, 1], rng.uniform(0.3, 1.3)), _quat([1, 0, 0], np.pi / 4))
            offset *= 0.1
        elif mode in (6, 7):  # edge beside edge, within a wide margin (witness points clamp to edge ends)
            q1 = _qmul(_quat(rng.normal(size=3), rng.uniform(0, 0.3)), _quat([0, 1, 0], np.pi / 4))
            q2 = _qmul(_quat([0, 0, 1], rng.uniform(0.2, 1.4)), _quat([1, 0, 0], np.pi / 4))
            offset = rng.uniform(-1.5, 1.5, 3) * (half1 + half2)
            depth = rng.uniform(0.0, 0.05)
        if mode < 8:
            offset[2] = _support(q1, half1, [0, 0, 1]) + _support(q2, half2, [0, 0, -1]) + depth
        else:  # random, deep to separated
            q2 = _random_quat(rng)
            offset = rng.normal(size=3) * (half1 + half2) * 0.8
        p1 = rng.uniform(-0.5, 0.5, 3)
        margin = 0.06 if mode in (6, 7) else [0.0, 0.01, 0.0, 0.002][n % 4]
        cases.append((half1, half2, (p1, _qmul(qf, q1)), (p1 + _qrot(qf, offset), _qmul(qf, q2)), margin,
                      f"mode {mode}"))
    return cases


def _support(q, half, direction):
    """Support distance of a box (half sizes, orientation q) along a unit direction (world)."""
    local = _qrot(q * np.array([1, -1, -1, -1]), direction)
    return float(np.abs(local) @ half)


def _degenerate_cases(pair):
    """Exact ties and alignments (world-aligned box at the origin, so coordinates stay exact)."""
    origin, ry90, rz90 = np.zeros(3), _quat([0, 1, 0], np.pi / 2), _quat([0, 0, 1], np.pi / 2)
    ry45, rx90 = _quat([0, 1, 0], np.pi / 4), _quat([1, 0, 0], np.pi / 2)
    cube, slab = np.array([0.1, 0.1, 0.1]), np.array([0.2, 0.1, 0.05])
    box_pose = (origin, IDENTITY)
    if pair == "sphere_box":
        r = np.array([0.05, 0.0, 0.0])
        centres = [(cube, [0, 0, 0]), (cube, [0.1, 0.0, 0.0]), (cube, [0.1, 0.1, 0.1]), (slab, [0.17, 0.07, 0.0]),
                   (slab, [0.2, 0.1, 0.05 + 0.05]), (slab, [0.0, 0.0, -0.1])]
        return [(r, half, (np.array(c, dtype=float), IDENTITY), box_pose, 0.0, f"degenerate {k}")
                for k, (half, c) in enumerate(centres)]
    if pair == "capsule_box":
        cap = np.array([0.03, 0.15, 0.0])
        poses = [([0, 0, 0.05 + 0.03 - 0.001], ry90), ([0.05, 0.03, 0.05 + 0.03 + 0.001], ry90),
                 ([0, 0, 0.05 + 0.15 + 0.03 - 0.002], IDENTITY), ([0, 0, 0], ry90), ([0, 0, 0], IDENTITY),
                 ([0.2 + 0.02, 0.0, 0.05 + 0.02], rx90), ([0.2, 0.1, 0.05 + 0.029], ry90),
                 ([0.0, 0.1 + 0.15 + 0.03 - 0.001, 0.0], rx90)]
        return [(cap, slab, (np.array(c, dtype=float), q), box_pose, 0.005 * (k % 2), f"degenerate {k}")
                for k, (c, q) in enumerate(poses)]
    above = np.array([0.0, 0.0, 0.199])
    edge_up = 0.1 * np.sqrt(2)
    poses = [((origin, IDENTITY), (origin, IDENTITY)), ((origin, IDENTITY), (above, IDENTITY)),
             ((origin, IDENTITY), (above, rz90)), ((origin, IDENTITY), (np.array([0.2, 0.2, 0.2]), IDENTITY)),
             ((origin, ry45), (np.array([0, 0, 2 * edge_up - 0.001]), _qmul(_quat([0, 0, 1], 1e-9), ry45))),
             ((origin, ry45), (np.array([0, 0, 2 * edge_up - 0.001]), _qmul(rz90, ry45))),
             ((origin, ry45), (np.array([0, 0, 2 * edge_up + 0.001]), _qmul(rz90, ry45))),
             ((origin, IDENTITY), (np.array([0.01, 0.02, 0.0]), _quat([1, 1, 0], 0.3)))]
    return [(cube, cube * (0.5 if k == 7 else 1.0), p1, p2, 0.002 * (k % 2), f"degenerate {k}")
            for k, (p1, p2) in enumerate(poses)]


CASES = {"sphere_box": _sphere_box_cases, "capsule_box": _capsule_box_cases, "box_box": _box_box_cases}


# ---------------------------------------------------------------- tests


@pytest.mark.parametrize("pair", ["sphere_box", "capsule_box", "box_box"])
def test_matches_mujoco(f64, pair):
    """Same contacts as MuJoCo (count, order, position, normal, dist) on every case, and every
    kind of contact occurs: none, and for box–box faces, edges and full 8-point manifolds."""
    cases = CASES[pair](np.random.default_rng(7)) + _degenerate_cases(pair)
    failures, out, ref_count, _ = _compare(pair, cases)
    assert not failures, f"{len(failures)} of {len(cases)} cases differ:\n" + "\n".join(failures[:20])
    counts = np.bincount(ref_count)  # cases with 0, 1, ... contacts: none to the full budget occur
    assert counts[0] > 0 and counts[-1] > 0 and len(counts) == COLLIDERS[pair][1] + 1, counts
    if pair == "box_box":  # face and edge axes, clipped corners and cuts, clamped edge witnesses all occur
        features = np.concatenate([f[:c] for f, c in zip(out["feature"], out["count"])])
        edge, face = features[features & 15 >= 6], features[features & 15 < 6]
        assert len(edge) > 20 and np.sum(edge >> 10 != 0) >= 2
        assert all(np.sum((face >> 8 >= lo) & (face >> 8 < hi)) > 20 for lo, hi in ((0, 4), (4, 20), (20, 24)))


def _turn(rot, rng, angle):
    """Rotations (..., 3, 3) turned by `angle` (rad) about random axes (Rodrigues)."""
    axis = rng.normal(size=rot.shape[:-1])
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    k = np.zeros(rot.shape)
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -axis[..., 2], axis[..., 1], -axis[..., 0]
    k -= np.swapaxes(k, -1, -2)
    return (np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k) @ rot


@pytest.mark.parametrize("pair", ["sphere_box", "capsule_box", "box_box"])
def test_frozen_features(f64, pair):
    """Each contact's evaluate, its feature frozen, is a continuous closed form of the poses (what
    a backward differentiates): moving both geoms by ~1e-6 moves the replayed contacts by
    O(1e-6), and where the decision is unchanged the replay is the collider's own result."""
    rng = np.random.default_rng(3)
    cases = CASES[pair](rng)[:120]
    _, base, _, (pos, rot, size, margin) = _compare(pair, cases)
    eps = 1e-6
    pos_b, rot_b = pos + rng.normal(size=pos.shape) * eps, _turn(rot, rng, eps)
    moved = _ours(pair, pos_b, rot_b, size, margin, base["count"], base["feature"])
    touching = base["count"] > 0
    same = touching & (moved["count"] == base["count"]) & np.all(moved["feature"] == base["feature"], axis=1)
    assert same.sum() >= 0.5 * touching.sum(), (same.sum(), touching.sum())  # aligned cases sit on ties
    for n in np.flatnonzero(touching):
        c = base["count"][n]
        replay = moved["replayed"][n, :c]
        assert np.all(np.abs(replay - _rows(base, n)) < 1e3 * eps), (cases[n][5], n)
        if same[n]:
            assert np.array_equal(replay, _rows(moved, n)), (cases[n][5], n)


def _rows(out, n):
    """Case n's contacts as rows (position, normal, dist), as the kernel writes replays."""
    c = out["count"][n]
    return np.concatenate([out["position"][n, :c], out["normal"][n, :c], out["dist"][n, :c, None]], axis=1)


def test_capsule_across_a_box_top_matches_mujoco(f64):
    """Capsules lying across a box's top face (random yaw, small tilts, hanging over edges): where
    clamping the capsule's axis parameter re-solves the edge parameter inside the edge, MuJoCo's
    mjraw_CapsuleBox keeps the edge parameter's first clamp flag, which chooses its second contact
    (found by an adversarial pass: 1 contact where ours had 2, the same point twice, in ~1 % of
    such poses; qvel 2e-2 off after one step)."""
    rng = np.random.default_rng(44)
    cap, half, cases = np.array([0.05, 0.1, 0.0]), np.array([0.1, 0.15, 0.05]), []
    for n in range(2000):
        yaw, tilt = rng.uniform(0, 2 * np.pi), rng.normal(0, 0.2)
        quat = _qmul(_quat([0, 0, 1], yaw), _qmul(_quat([1, 0, 0], np.pi / 2 + tilt), np.array([1.0, 0, 0, 0])))
        centre = np.array([rng.uniform(-0.2, 0.2), rng.uniform(-0.25, 0.25),
                           0.1 + abs(np.sin(tilt)) * 0.1 - rng.uniform(0, 0.01)])
        cases.append((cap, half, (centre, quat), (np.zeros(3), np.array([1.0, 0, 0, 0])), 0.0, f"lying {n}"))
    failures, _, ref_count, _ = _compare("capsule_box", cases)
    assert not failures, f"{len(failures)} of {len(cases)} cases differ:\n" + "\n".join(failures[:20])
    assert np.sum(ref_count == 1) > 100 and np.sum(ref_count == 2) > 100
