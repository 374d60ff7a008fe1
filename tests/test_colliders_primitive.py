"""Primitive colliders (collision/primitive.py) and the contact frame (collision/frame.py) against
MuJoCo's d.contact.

Each pair: an MJCF with the two geoms (a plane on a mocap body, every other geom on a free
body), thousands of random poses, sizes and margins (penetrating, within margin, separated)
plus hand-made degenerate poses; MuJoCo's mj_forward gives d.contact, our collider runs on
MuJoCo's own geom_xpos / geom_xmat in one batched kernel per pair. Count, order, positions,
normals, distances and the full contact frame must agree to 1e-12 (float64; they agree to the
bit today, the normals to 1 ulp of MuJoCo's renormalization). Every branch a feature encodes
must occur at least once.
"""
import mujoco
import numpy as np
import pytest
import taichi as ti

from genesis_lite.solvers.core import runtime
from genesis_lite.solvers.rigid.collision import frame, primitive

PLANE, SPHERE, CAPSULE, CYLINDER, BOX = 0, 2, 3, 5, 6
TYPE_NAMES = {PLANE: "plane", SPHERE: "sphere", CAPSULE: "capsule", CYLINDER: "cylinder", BOX: "box"}
TOL = 1e-12
N_RANDOM = 2000

# name: (collider, K, type1, type2)
PAIRS = {
    "plane_sphere": (primitive.plane_sphere, primitive.PLANE_SPHERE_MAX, PLANE, SPHERE),
    "plane_capsule": (primitive.plane_capsule, primitive.PLANE_CAPSULE_MAX, PLANE, CAPSULE),
    "plane_cylinder": (primitive.plane_cylinder, primitive.PLANE_CYLINDER_MAX, PLANE, CYLINDER),
    "plane_box": (primitive.plane_box, primitive.PLANE_BOX_MAX, PLANE, BOX),
    "sphere_sphere": (primitive.sphere_sphere, primitive.SPHERE_SPHERE_MAX, SPHERE, SPHERE),
    "sphere_capsule": (primitive.sphere_capsule, primitive.SPHERE_CAPSULE_MAX, SPHERE, CAPSULE),
    "sphere_cylinder": (primitive.sphere_cylinder, primitive.SPHERE_CYLINDER_MAX, SPHERE, CYLINDER),
    "capsule_capsule": (primitive.capsule_capsule, primitive.CAPSULE_CAPSULE_MAX, CAPSULE, CAPSULE),
}

# Features each pair's cases must exercise (so a branch cannot go untested)
EXPECTED_FEATURES = {
    "plane_sphere": {0},
    "plane_capsule": {0, 1},
    # near rim, far rim, triangle sides; flipped and not; disks parallel to the plane
    "plane_cylinder": {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 12, 13, 14, 15},
    "plane_box": set(range(8)),
    "sphere_sphere": {0, 1, 2},
    # segment interior / +end / -end; centre on the segment (z axes crossing, parallel)
    "sphere_capsule": {0, 1, 2, 3, 6},
    # side, caps, rims; sphere centre on the axis
    "sphere_cylinder": {0, 1, 2, 3, 6, 9, 12},
    # weights both free, one clamped (4 ways), both clamped (4 ways); crossing axes (1);
    # parallel or identical capsules with coinciding sphere centres (11, 20)
    "capsule_capsule": {0, 1, 3, 6, 9, 11, 12, 15, 18, 20, 21, 24},
}


# ---------------------------------------------------------------- MuJoCo side

def _geom_xml(type_code, name):
    return f'<geom name="{name}" type="{TYPE_NAMES[type_code]}" size="0.1 0.1 0.1"/>'


def _model(type1, type2):
    """Two bodies, geom g1 of type1 then g2 of type2; planes on mocap bodies, others free."""
    bodies = []
    for name, type_code in (("g1", type1), ("g2", type2)):
        if type_code == PLANE:
            bodies.append(f'<body mocap="true">{_geom_xml(type_code, name)}</body>')
        else:
            bodies.append(f'<body><freejoint/>{_geom_xml(type_code, name)}</body>')
    m = mujoco.MjModel.from_xml_string(f"<mujoco><worldbody>{''.join(bodies)}</worldbody></mujoco>")
    # sizes change per case: make the broadphase bounds too large to ever filter a pair out
    for g in range(2):
        if m.geom_type[g] != PLANE:
            m.geom_rbound[g] = 100.0
            m.geom_aabb[g, 3:] = 100.0
    return m


def _set_pose(m, d, g, pos, quat):
    body = m.geom_bodyid[g]
    if m.body_mocapid[body] >= 0:
        d.mocap_pos[m.body_mocapid[body]] = pos
        d.mocap_quat[m.body_mocapid[body]] = quat
    else:
        adr = m.jnt_qposadr[m.body_jntadr[body]]
        d.qpos[adr:adr + 3] = pos
        d.qpos[adr + 3:adr + 7] = quat


def mujoco_contacts(type1, type2, cases, K):
    """Run MuJoCo on every case; returns our kernel's inputs and MuJoCo's contacts.

    cases: list of dicts with pos (2, 3), quat (2, 4), size (2, 3), margin (2,), gap (2,) for
    geoms 1 and 2. Returns inputs (pos, rot, size, margin+gap) and, per case, count and
    (K, ...) arrays of pos, frame (3, 3), dist.
    """
    m = _model(type1, type2)
    d = mujoco.MjData(m)
    n = len(cases)
    pos = np.zeros((n, 2, 3))
    rot = np.zeros((n, 2, 3, 3))
    size = np.zeros((n, 2, 3))
    margin = np.zeros(n)
    ref = {"count": np.zeros(n, np.int32), "pos": np.zeros((n, K, 3)), "frame": np.zeros((n, K, 3, 3)),
           "dist": np.zeros((n, K))}
    for c, case in enumerate(cases):
        for g in range(2):
            m.geom_size[g] = case["size"][g]
            m.geom_margin[g] = case["margin"][g]
            m.geom_gap[g] = case["gap"][g]
            _set_pose(m, d, g, case["pos"][g], case["quat"][g])
        mujoco.mj_forward(m, d)
        pos[c] = d.geom_xpos[:2]
        rot[c] = d.geom_xmat[:2].reshape(2, 3, 3)
        size[c] = m.geom_size[:2]
        margin[c] = (m.geom_margin[0] + m.geom_margin[1]) + (m.geom_gap[0] + m.geom_gap[1])
        ref["count"][c] = d.ncon
        for k in range(d.ncon):
            con = d.contact[k]
            assert tuple(con.geom) == (0, 1), "MuJoCo ordered the pair differently"
            ref["pos"][c, k] = con.pos
            ref["frame"][c, k] = con.frame.reshape(3, 3)
            ref["dist"][c, k] = con.dist
    return (pos, rot, size, margin), ref


# ---------------------------------------------------------------- our side

_KERNELS = {}


def _pair_kernel(name):
    """One compiled kernel per pair: the collider and contact_frame on a batch of cases."""
    key = (name, runtime.epoch)
    if key in _KERNELS:
        return _KERNELS[key]
    collide, K, type1, type2 = PAIRS[name]
    axis_tangent = type1 == PLANE and type2 == CAPSULE  # MuJoCo's only non-zero tangent hint

    @ti.kernel
    def run(pos: ti.types.ndarray(), rot: ti.types.ndarray(), size: ti.types.ndarray(),
            margin: ti.types.ndarray(), count: ti.types.ndarray(), position: ti.types.ndarray(),
            normal: ti.types.ndarray(), dist: ti.types.ndarray(), feature: ti.types.ndarray(),
            frames: ti.types.ndarray()):
        for c in range(margin.shape[0]):
            p = [ti.Vector([pos[c, g, i] for i in ti.static(range(3))]) for g in ti.static(range(2))]
            s = [ti.Vector([size[c, g, i] for i in ti.static(range(3))]) for g in ti.static(range(2))]
            r = [ti.Matrix([[rot[c, g, i, j] for j in ti.static(range(3))] for i in ti.static(range(3))])
                 for g in ti.static(range(2))]
            n, pk, nk, dk, fk = collide(p[0], r[0], s[0], p[1], r[1], s[1], margin[c])
            count[c] = n
            tangent = ti.Vector.zero(float, 3)
            if ti.static(axis_tangent):
                tangent = frame.column(r[1], 2)
            for k in ti.static(range(K)):
                dist[c, k] = dk[k]
                feature[c, k] = fk[k]
                fr = frame.contact_frame(ti.Vector([nk[k, i] for i in ti.static(range(3))]), tangent)
                for i in ti.static(range(3)):
                    position[c, k, i] = pk[k, i]
                    normal[c, k, i] = nk[k, i]
                    for j in ti.static(range(3)):
                        frames[c, k, i, j] = fr[i, j]

    _KERNELS[key] = run
    return run


def run_collider(name, inputs):
    pos, rot, size, margin = inputs
    K = PAIRS[name][1]
    n = len(margin)
    out = {"count": np.zeros(n, np.int32), "pos": np.zeros((n, K, 3)), "normal": np.zeros((n, K, 3)),
           "dist": np.zeros((n, K)), "feature": np.zeros((n, K), np.int32), "frame": np.zeros((n, K, 3, 3))}
    _pair_kernel(name)(pos, rot, size, margin, out["count"], out["pos"], out["normal"], out["dist"],
                       out["feature"], out["frame"])
    return out


# ---------------------------------------------------------------- cases

def _random_quats(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _random_size(rng, type_code):
    if type_code == PLANE:
        return np.array([1.0, 1.0, 0.1])
    if type_code == BOX:
        return rng.uniform(0.05, 0.4, 3)
    return np.array([rng.uniform(0.05, 0.3), rng.uniform(0.05, 0.4), 0.0])


def _bound(type_code, size):
    """Bounding-sphere radius of a geom (its farthest point from the centre)."""
    if type_code == SPHERE:
        return size[0]
    if type_code == CAPSULE:
        return size[0] + size[1]
    if type_code == CYLINDER:
        return np.hypot(size[0], size[1])
    return np.linalg.norm(size)


def _random_margins(rng):
    """(margin, gap) per geom: zero half the time, else up to 5 cm split over the two geoms."""
    margin = np.zeros(2) if rng.random() < 0.5 else rng.uniform(0, 0.025, 2)
    gap = np.zeros(2) if rng.random() < 0.8 else rng.uniform(0, 0.01, 2)
    return margin, gap


def random_cases(type1, type2, n, seed):
    """Poses spread from deep penetration to clear separation (about half in contact)."""
    rng = np.random.default_rng(seed)
    quats = _random_quats(rng, 2 * n).reshape(n, 2, 4)
    cases = []
    for c in range(n):
        size = np.array([_random_size(rng, type1), _random_size(rng, type2)])
        margin, gap = _random_margins(rng)
        pos1 = rng.uniform(-1, 1, 3)
        b2 = _bound(type2, size[1])
        if type1 == PLANE:
            rot1 = _quat_mat(quats[c, 0])
            lateral = rot1[:, :2] @ rng.uniform(-1, 1, 2)
            pos2 = pos1 + lateral + rot1[:, 2] * rng.uniform(-b2, 1.3 * b2)
        else:
            direction = rng.normal(size=3)
            direction /= np.linalg.norm(direction)
            pos2 = pos1 + direction * rng.uniform(0, 1.3) * (_bound(type1, size[0]) + b2)
        cases.append({"pos": np.array([pos1, pos2]), "quat": quats[c], "size": size, "margin": margin,
                      "gap": gap})
    return cases


def parallel_capsule_cases(n, seed):
    """Capsule pairs with axes parallel, anti-parallel or tilted by 1e-6 … 1e-3 rad (MuJoCo's
    parallel test is sin² <= 1e-8), side by side and overlapping along the axis."""
    rng = np.random.default_rng(seed)
    cases = []
    for c in range(n):
        q1 = _random_quats(rng, 1)[0]
        turn = [0.0, 1.0, 0.0, 0.0] if c % 3 == 1 else [1.0, 0.0, 0.0, 0.0]
        angle = 0.0 if c % 2 else 10.0 ** rng.uniform(-6, -3)
        tilt = [np.cos(angle / 2), 0.0, np.sin(angle / 2), 0.0]
        q2 = np.zeros(4)
        mujoco.mju_mulQuat(q2, q1, np.array(turn))
        mujoco.mju_mulQuat(q2, q2.copy(), np.array(tilt))
        rot1 = _quat_mat(q1)
        size = np.array([_random_size(rng, CAPSULE), _random_size(rng, CAPSULE)])
        pos1 = rng.uniform(-1, 1, 3)
        pos2 = pos1 + rot1 @ [rng.uniform(-0.3, 0.3), 0.0, rng.uniform(-0.9, 0.9)]
        margin, gap = _random_margins(rng)
        cases.append({"pos": np.array([pos1, pos2]), "quat": np.array([q1, q2]), "size": size,
                      "margin": margin, "gap": gap})
    return cases


def standing_cylinder_cases(n, seed, tilt_max=0.1):
    """Cylinders standing on a plane (either way up), their axis tilted up to ``tilt_max`` rad
    from the normal (a quarter within 0.01 rad, some exactly upright), spun about it, their lowest
    rim point from 3 mm above the plane to 6 mm below."""
    rng = np.random.default_rng(seed)
    cases = []
    for c in range(n):
        q1 = _random_quats(rng, 1)[0]
        turn = [0.0, 1.0, 0.0, 0.0] if c % 2 else [1.0, 0.0, 0.0, 0.0]
        tilt = 0.0 if c % 10 == 0 else rng.uniform(0.0, 0.01) if c % 4 == 0 else rng.uniform(0.0, tilt_max)
        heading, spin = rng.uniform(0.0, 2 * np.pi, 2)
        q2 = np.zeros(4)
        mujoco.mju_mulQuat(q2, q1, np.array(turn))
        for step in ([np.cos(tilt / 2), np.sin(tilt / 2) * np.cos(heading), np.sin(tilt / 2) * np.sin(heading), 0.0],
                     [np.cos(spin / 2), 0.0, 0.0, np.sin(spin / 2)]):
            mujoco.mju_mulQuat(q2, q2.copy(), np.array(step))
        size = np.array([_random_size(rng, PLANE), _random_size(rng, CYLINDER)])
        rot1 = _quat_mat(q1)
        pos1 = rng.uniform(-1, 1, 3)
        height = size[1, 1] * np.cos(tilt) + size[1, 0] * np.sin(tilt) - rng.uniform(-0.003, 0.006)
        pos2 = pos1 + rot1[:, :2] @ rng.uniform(-1, 1, 2) + rot1[:, 2] * height
        margin, gap = _random_margins(rng)
        cases.append({"pos": np.array([pos1, pos2]), "quat": np.array([q1, q2]), "size": size, "margin": margin,
                      "gap": gap})
    return cases


def _quat_mat(q):
    m = np.zeros(9)
    mujoco.mju_quat2Mat(m, q)
    return m.reshape(3, 3)


ID = [1.0, 0.0, 0.0, 0.0]
FLIP_X = [0.0, 1.0, 0.0, 0.0]          # 180° about x: z -> -z, exact
QUARTER_X = [np.sqrt(0.5), np.sqrt(0.5), 0.0, 0.0]  # z -> -y
TILT = [0.9, 0.3, 0.2, 0.1]


def _case(pos1, quat1, size1, pos2, quat2, size2, margin=0.0):
    q = np.array([quat1, quat2], dtype=float)
    return {"pos": np.array([pos1, pos2], dtype=float), "quat": q / np.linalg.norm(q, axis=1, keepdims=True),
            "size": np.array([size1, size2], dtype=float), "margin": np.array([margin, 0.0]),
            "gap": np.zeros(2)}


PL = [1.0, 1.0, 0.1]


def degenerate_cases(name):
    """Hand-made poses on MuJoCo's special branches (dyadic numbers: exact arithmetic)."""
    o = [0.25, 0.5, 0.125]
    if name == "plane_sphere":
        return [_case(o, ID, PL, o, ID, [0.25, 0, 0]), _case(o, TILT, PL, o, ID, [0.25, 0, 0]),
                _case(o, ID, PL, [0.25, 0.5, 0.375], ID, [0.25, 0, 0])]
    if name == "plane_capsule":  # upright (tangent hint parallel to the normal), lying, upside down
        return [_case(o, ID, PL, [0.25, 0.5, 0.5], ID, [0.125, 0.25, 0]),
                _case(o, ID, PL, [0.25, 0.5, 0.25], QUARTER_X, [0.125, 0.25, 0]),
                _case(o, ID, PL, [0.25, 0.5, 0.5], FLIP_X, [0.125, 0.25, 0], 0.25),
                _case(o, TILT, PL, o, TILT, [0.125, 0.25, 0])]
    if name == "plane_cylinder":  # disks parallel (flipped or not), axis in the plane, tilted
        return [_case(o, ID, PL, [0.25, 0.5, 0.25], ID, [0.125, 0.25, 0]),
                _case(o, ID, PL, [0.25, 0.5, 0.25], FLIP_X, [0.125, 0.25, 0], 0.5),
                _case(o, ID, PL, [0.25, 0.5, 0.125], QUARTER_X, [0.125, 0.25, 0]),
                _case(o, TILT, PL, o, TILT, [0.125, 0.25, 0], 0.25),
                _case(o, ID, PL, [0.25, 0.5, 0.375], ID, [0.25, 0.25, 0], 0.25)]
    if name == "plane_box":  # face down (equal corners), upside down, edge down
        return [_case(o, ID, PL, [0.25, 0.5, 0.25], ID, [0.25, 0.125, 0.125]),
                _case(o, ID, PL, [0.25, 0.5, 0.25], FLIP_X, [0.25, 0.125, 0.125], 0.125),
                _case(o, ID, PL, [0.25, 0.5, 0.25], [np.cos(np.pi / 8), np.sin(np.pi / 8), 0, 0],
                      [0.25, 0.125, 0.125]),
                _case(o, ID, PL, o, ID, [0.25, 0.125, 0.125])]
    if name == "sphere_sphere":  # coincident centres: z axes crossing, parallel, anti-parallel
        return [_case(o, ID, [0.25, 0, 0], o, TILT, [0.125, 0, 0]),
                _case(o, ID, [0.25, 0, 0], o, ID, [0.125, 0, 0]),
                _case(o, ID, [0.25, 0, 0], o, FLIP_X, [0.125, 0, 0]),
                _case(o, TILT, [0.25, 0, 0], o, TILT, [0.125, 0, 0])]
    if name == "sphere_capsule":  # centre on the segment (middle, off-centre), on the axis beyond an end
        r = [0.125, 0, 0]
        cap = [0.125, 0.25, 0]
        return [_case(o, TILT, r, o, ID, cap), _case(o, ID, r, o, ID, cap),
                _case([0.25, 0.5, 0.25], QUARTER_X, r, o, ID, cap),
                _case([0.25, 0.5, 0.25], ID, r, o, ID, cap),
                _case([0.25, 0.5, 0.5], ID, r, o, ID, cap), _case([0.25, 0.5, -0.25], TILT, r, o, ID, cap),
                _case([0.25, 0.5, 0.375], TILT, r, o, ID, cap)]
    if name == "sphere_cylinder":  # centre at the centre, on the axis (cap nearer / side nearer), on a rim
        r = [0.125, 0, 0]
        cyl = [0.25, 0.375, 0]
        return [_case(o, ID, r, o, ID, cyl), _case(o, TILT, r, o, ID, cyl),
                _case([0.25, 0.5, 0.375], ID, r, o, ID, cyl),
                _case([0.25, 0.5, -0.125], QUARTER_X, r, o, ID, cyl),
                _case([0.25, 0.5, 0.625], ID, r, o, ID, cyl),
                _case([0.5, 0.5, 0.5], ID, r, o, ID, cyl),
                _case([0.25, 0.5, 0.125], ID, r, o, ID, [0.125, 0.375, 0]),
                _case([0.25, 0.75, -0.375], ID, r, o, ID, cyl)]
    if name == "capsule_capsule":  # parallel, anti-parallel, collinear, identical, crossing, tilted copies,
        cap1 = [0.125, 0.25, 0]     # and axes 1e-5 rad apart (parallel to MuJoCo) or 1e-3 rad (not)
        cap2 = [0.0625, 0.375, 0]
        side = [0.375, 0.5, 0.25]
        return [_case(o, ID, cap1, side, ID, cap2), _case(o, ID, cap1, side, FLIP_X, cap2),
                _case(o, ID, cap1, [0.25, 0.5, 0.625], ID, cap2), _case(o, ID, cap1, o, ID, cap1),
                _case(o, ID, cap1, o, QUARTER_X, cap2), _case(o, TILT, cap1, side, TILT, cap2),
                _case(o, TILT, cap1, o, TILT, cap2), _case(o, ID, cap1, [0.25, 0.5, 1.0], ID, cap2, 0.5),
                _case(o, ID, cap1, [0.5, 0.5, 0.75], ID, cap2), _case(o, ID, cap1, side, [1, 5e-6, 0, 0], cap2),
                _case(o, ID, cap1, side, [1, 5e-4, 0, 0], cap2),
                _case(o, TILT, cap1, side, [0.9, 0.3, 0.2, 0.10001], cap2)]
    raise KeyError(name)


# ---------------------------------------------------------------- tests

def compare(name, ref, out):
    """Assert equal counts and contacts; returns the largest differences."""
    np.testing.assert_array_equal(out["count"], ref["count"], err_msg=f"{name}: contact counts")
    K = PAIRS[name][1]
    used = np.arange(K)[None, :] < ref["count"][:, None]
    err = {
        "pos": np.abs(out["pos"] - ref["pos"]).max(axis=2)[used],
        "normal": np.abs(out["normal"] - ref["frame"][:, :, 0]).max(axis=2)[used],
        "dist": np.abs(out["dist"] - ref["dist"])[used],
        "frame": np.abs(out["frame"] - ref["frame"]).max(axis=(2, 3))[used],
    }
    worst = {key: float(e.max(initial=0.0)) for key, e in err.items()}
    for key, e in worst.items():
        assert e < TOL, f"{name}: {key} differs from MuJoCo by {e:.3g}"
    return worst


@pytest.mark.parametrize("name", list(PAIRS))
def test_collider_matches_mujoco(f64, name):
    _, K, type1, type2 = PAIRS[name]
    seed = sum(map(ord, name))
    cases = random_cases(type1, type2, N_RANDOM, seed) + degenerate_cases(name)
    if name == "capsule_capsule":
        cases += parallel_capsule_cases(N_RANDOM // 2, seed)
    inputs, ref = mujoco_contacts(type1, type2, cases, K)
    out = run_collider(name, inputs)
    worst = compare(name, ref, out)
    used = np.arange(K)[None, :] < out["count"][:, None]
    seen = set(out["feature"][used].tolist())
    missing = EXPECTED_FEATURES[name] - seen
    assert not missing, f"{name}: features never exercised: {sorted(missing)}"
    histogram = np.bincount(ref["count"], minlength=K + 1)
    print(f"\n{name}: {len(cases)} cases, contacts per case {histogram.tolist()}, features {sorted(seen)}, "
          f"max |diff| " + ", ".join(f"{k} {v:.1e}" for k, v in worst.items()))


# contact_frame on its own: MuJoCo's frames of plane–sphere contacts (normal = the plane's z axis,
# no tangent hint) and plane–capsule contacts (hint = the capsule axis), normals near the |n_y| = 0.5
# switch of the default hint

_FRAME_KERNELS = {}


def _frame_kernel():
    key = runtime.epoch
    if key not in _FRAME_KERNELS:
        @ti.kernel
        def run(normal: ti.types.ndarray(), tangent: ti.types.ndarray(), frames: ti.types.ndarray()):
            for c in range(normal.shape[0]):
                fr = frame.contact_frame(ti.Vector([normal[c, i] for i in ti.static(range(3))]),
                                         ti.Vector([tangent[c, i] for i in ti.static(range(3))]))
                for i in ti.static(range(3)):
                    for j in ti.static(range(3)):
                        frames[c, i, j] = fr[i, j]

        _FRAME_KERNELS[key] = run
    return _FRAME_KERNELS[key]


def _z_to(n):
    """Unit quaternion turning the z axis onto unit n (n != -z)."""
    q = np.array([1.0 + n[2], -n[1], n[0], 0.0])
    return q / np.linalg.norm(q)


def _switch_normals(rng, n):
    """Unit normals with n_y = ±0.5 + δ, δ from 0 to 1e-6 either side, and random ones."""
    deltas = np.array([0.0, 1e-16, -1e-16, 1e-13, -1e-13, 1e-9, -1e-9, 1e-6, -1e-6])
    out = []
    for c in range(n):
        if c % 3 == 2:
            v = rng.normal(size=3)
        else:
            y = rng.choice([0.5, -0.5]) + rng.choice(deltas)
            phi = rng.uniform(0, np.pi)  # x, z with z > 0 keeps _z_to well defined
            rho = np.sqrt(1 - y * y)
            v = np.array([rho * np.cos(phi), y, rho * np.sin(phi)])
        out.append(v / np.linalg.norm(v) * (1 if v[2] > -0.9 else -1))
    return out


def test_contact_frame_matches_mujoco(f64):
    rng = np.random.default_rng(7)
    normals, tangents, frames = [], [], []
    for type2 in (SPHERE, CAPSULE):
        m = _model(PLANE, type2)
        d = mujoco.MjData(m)
        m.geom_size[1] = [0.1, 0.2, 0]
        for n in _switch_normals(rng, 300):
            quat2 = _random_quats(rng, 1)[0] if rng.random() < 0.8 else _z_to(n)  # some capsules along n
            _set_pose(m, d, 0, np.zeros(3), _z_to(n))
            _set_pose(m, d, 1, -0.05 * n, quat2)
            mujoco.mj_forward(m, d)
            assert d.ncon >= 1
            for con in d.contact[:d.ncon]:
                normals.append(d.geom_xmat[0].reshape(3, 3)[:, 2].copy())
                tangents.append(d.geom_xmat[1].reshape(3, 3)[:, 2].copy() if type2 == CAPSULE else np.zeros(3))
                frames.append(con.frame.reshape(3, 3).copy())
    normals, tangents, frames = np.array(normals), np.array(tangents), np.array(frames)
    out = np.zeros_like(frames)
    _frame_kernel()(normals, tangents, out)
    no_hint = ~tangents.any(axis=1)
    y_hint = no_hint & (np.abs(normals[:, 1]) < 0.5)
    assert y_hint.sum() > 20 and (no_hint & ~y_hint).sum() > 20, "both default hints must be exercised"
    worst = np.abs(out - frames).max()
    assert worst < TOL, f"contact frame differs from MuJoCo by {worst:.3g}"
    print(f"\ncontact_frame: {len(frames)} frames, {int(no_hint.sum())} without hint, max |diff| {worst:.1e}")
