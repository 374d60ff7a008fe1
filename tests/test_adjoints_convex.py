"""The convex colliders' contacts replayed from their feature rows (convex.py: convex_evaluate,
plane_mesh_evaluate) and the replays' hand-written adjoints, on the random poses of
tests/test_colliders_convex.py (spheres, capsules, cylinders, boxes and three meshes, margin 0
and MARGIN; plane-mesh poses beside them) and on aligned poses (a cylinder's cap square on a
face, a cap or a lying capsule: measure zero among random poses; `_aligned_cases`).

Replay: each contact the forward found is evaluated again from its feature; where the closed form
is the forward's own computation (polytope cores: plane-mesh, face clipping, GJK between points,
segments, boxes and meshes, EPA between boxes and meshes without margin) it agrees to EXACT.
Where the forward iterates on a curved support (EPA with a sphere, capsule or margin, whose balls
it samples at a few directions; anything with a cylinder; the ends of a clipped edge with a
margin, which are EPA support points) the replay is the converged closed form, and the forward is
within its CCD tolerance of it (APPROX; detect.converge_contacts makes the forward's contact that
form unless enable_mujoco_compatibility).

Adjoint: the 24 pose-gradient numbers of each contact (random cotangents) against central
differences of the replay, feature frozen, over an eps scan; the bar holds for each contact at
its best eps, and every branch of the closed form is covered (BRANCHES).

Two compiled kernels check every case, both colliders: one the adjoints, one the replays and the
48 perturbed evaluates (one launch per eps); together they compile faster than one.
"""
import collections

import mujoco
import numpy as np
import pytest
import taichi as ti

import genesis_lite as gs
from genesis_lite.solvers.launch import LIGHT_OPT_LEVEL, taichi_opt_level
from genesis_lite.solvers.rigid.collision import convex as cv
from tests.collider_adjoint import N_COTANGENT, N_INPUTS, _unit3, _unit33
from tests.test_colliders_convex import (MARGIN, TYPES, VEC3, _convex_cases, _geom, _Harness, _hull, _model,
                                         _random_quat)

EXACT = 1e-9     # m: replays of the forward's own closed form
APPROX = 5e-3    # m: replays of the converged closed form, against the forward's CCD iterate (measured 4.4e-3)
# the same for their unit normals: EPA's normal on curved supports converges slowly at depth (the
# distance is second order in it): measured 3.4e-2 for a cylinder's rim 6 cm deep in a capsule
NORMAL_APPROX = 5e-2
TOL = 1e-6       # relative error of the adjoint against central differences, at each contact's best eps
SCAN = (1e-5, 1e-6, 1e-7, 1e-8)
K = max(cv.CONVEX_MAX, cv.PLANE_MESH_MAX)
F = cv.FEATURE_SIZE
# branches of the closed form (see _branch) the random poses must reach
BRANCHES = {"plane", "core m=0", "core m=1", "core m=2", "epa m=2", "cylinder rim", "cylinder cap", "cylinder side",
            "cap on a point", "cap on a line", "cap on a plane", "cap of geom 1", "cap of geom 2",
            "rim on a point", "rim on a line", "rim on a rim", "rim on a rim holding both ends", "rim of geom 1",
            "rim of geom 2", "rim on its side", "clip face-face", "clip edge of geom 1", "clip edge of geom 2",
            "clip vertex", "clip edge x side plane", "clip side x side plane", "clip edge with margin",
            "cylinder standing on a box face", "cylinder standing on a mesh face", "cylinder lying on a face",
            "cap under a box face's edge", "cap under a mesh face's edge", "lying across a box face's edge",
            "box face's corner on a cap", "rim point toward a box face's centre",
            "mesh face's corner on a cap", "rim point toward a mesh face's centre", "cap under another cap's rim"}


@ti.func
def _vec(a: ti.template(), c, g):
    return ti.Vector([a[c, g, i] for i in ti.static(range(3))])


@ti.func
def _mat(a: ti.template(), c, g):
    return ti.Matrix([[a[c, g, i, j] for j in ti.static(range(3))] for i in ti.static(range(3))])


@ti.func
def _evaluate(type1, pos1, rot1, size1, mesh1, type2, pos2, rot2, size2, mesh2, margin, feature, hull: ti.template()):
    """The replay of either collider (geom 1 a plane: plane_mesh's)."""
    position, normal, dist = ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0]), 0.0
    if type1 == cv.PLANE:
        position, normal, dist = cv.plane_mesh_evaluate(pos1, rot1, size1, pos2, rot2, size2, mesh2, feature, hull)
    else:
        position, normal, dist = cv.convex_evaluate(type1, pos1, rot1, size1, mesh1, type2, pos2, rot2, size2, mesh2,
                                                    margin, feature, hull)
    return position, normal, dist


@ti.func
def _contact(types: ti.template(), sizes: ti.template(), meshes: ti.template(), pos: ti.template(),
             rot: ti.template(), margins: ti.template(), feature: ti.template(), cotangent: ti.template(), c, k):
    """Case c's inputs and its contact k's feature and cotangent, from the batch arrays."""
    geoms = (types[c, 0], _vec(pos, c, 0), _mat(rot, c, 0), _vec(sizes, c, 0), meshes[c, 0], types[c, 1],
             _vec(pos, c, 1), _mat(rot, c, 1), _vec(sizes, c, 1), meshes[c, 1], margins[c])
    f = ti.Vector([feature[c, k, j] for j in ti.static(range(F))])
    g_position = ti.Vector([cotangent[c, k, i] for i in ti.static(range(3))])
    g_normal = ti.Vector([cotangent[c, k, 3 + i] for i in ti.static(range(3))])
    return geoms, f, g_position, g_normal, cotangent[c, k, 6]


@ti.kernel
def _adjoint_kernel(types: ti.types.ndarray(), sizes: ti.types.ndarray(), meshes: ti.types.ndarray(),
                    pos: ti.types.ndarray(), rot: ti.types.ndarray(), margins: ti.types.ndarray(),
                    count: ti.types.ndarray(), feature: ti.types.ndarray(), cotangent: ti.types.ndarray(),
                    hull_vec: VEC3, hull_int: ti.types.ndarray(), grad: ti.types.ndarray()):
    for c, k in ti.ndrange(types.shape[0], K):
        hull = _hull(hull_vec, hull_int)
        if k < count[c]:
            geoms, f, g_position, g_normal, g_dist = _contact(types, sizes, meshes, pos, rot, margins, feature,
                                                              cotangent, c, k)
            t1, p1, r1, s1, m1, t2, p2, r2, s2, m2, margin = geoms
            gp1, gr1, gp2, gr2 = ti.Vector([0.0, 0.0, 0.0]), ti.Matrix.zero(float, 3, 3), ti.Vector(
                [0.0, 0.0, 0.0]), ti.Matrix.zero(float, 3, 3)
            if t1 == cv.PLANE:
                gp1, gr1, gp2, gr2 = cv.plane_mesh_evaluate_adjoint(p1, r1, s1, p2, r2, s2, m2, f, hull, g_position,
                                                                    g_normal, g_dist)
            else:
                gp1, gr1, gp2, gr2 = cv.convex_evaluate_adjoint(t1, p1, r1, s1, m1, t2, p2, r2, s2, m2, margin, f,
                                                                hull, g_position, g_normal, g_dist)
            for i in ti.static(range(3)):
                grad[c, k, i], grad[c, k, 12 + i] = gp1[i], gp2[i]
                for j in ti.static(range(3)):
                    grad[c, k, 3 + 3 * i + j], grad[c, k, 15 + 3 * i + j] = gr1[i, j], gr2[i, j]


@ti.kernel
def _replay_kernel(types: ti.types.ndarray(), sizes: ti.types.ndarray(), meshes: ti.types.ndarray(),
                   pos: ti.types.ndarray(), rot: ti.types.ndarray(), margins: ti.types.ndarray(),
                   count: ti.types.ndarray(), feature: ti.types.ndarray(), cotangent: ti.types.ndarray(),
                   hull_vec: VEC3, hull_int: ti.types.ndarray(), eps: float, replay: ti.types.ndarray(),
                   fd: ti.types.ndarray()):
    for c, k in ti.ndrange(types.shape[0], K):
        hull = _hull(hull_vec, hull_int)
        if k < count[c]:
            geoms, f, g_position, g_normal, g_dist = _contact(types, sizes, meshes, pos, rot, margins, feature,
                                                              cotangent, c, k)
            t1, p1, r1, s1, m1, t2, p2, r2, s2, m2, margin = geoms
            for run in range(2 * N_INPUTS + 1):  # input run // 2 moved by +eps, -eps; the last run: the replay
                j = ti.select(run == 2 * N_INPUTS, -1, run // 2)
                sign = ti.select(run % 2 == 0, 1.0, -1.0)
                h = eps * sign
                p, n, d = _evaluate(t1, p1 + _unit3(j, 0, h), r1 + _unit33(j, 3, h), s1, m1, t2,
                                    p2 + _unit3(j, 12, h), r2 + _unit33(j, 15, h), s2, m2, margin, f, hull)
                if j < 0:
                    for i in ti.static(range(3)):
                        replay[c, k, i], replay[c, k, 3 + i] = p[i], n[i]
                    replay[c, k, 6] = d
                else:
                    fd[c, k, j] += sign * (g_position.dot(p) + g_normal.dot(n) + g_dist * d) / (2.0 * eps)


def _plane_cases(harness, rng):
    """Random plane-mesh poses (the plane tilted, each mesh above, on and in it; every third
    one flat): (types, sizes, meshes, pos, rot, margins) and the forward's contacts."""
    out = collections.defaultdict(list)
    for margin in (0.0, MARGIN):
        for mesh in range(3):
            m = _model('<geom type="plane" size="1 1 0.1" euler="0.1 0.2 0"/>', _geom("mesh", mesh, margin))
            d = mujoco.MjData(m)
            for k in range(40):
                quat = _random_quat(rng) if k % 3 else np.array([1.0, 0, 0, 0])
                d.qpos[:] = np.concatenate([[0.01, 0.02, rng.uniform(-0.05, 0.12)], quat])
                mujoco.mj_forward(m, d)
                out["types"].append((cv.PLANE, cv.MESH))
                out["sizes"].append(np.zeros((2, 3)))
                out["meshes"].append((-1, m.geom_dataid[1]))
                out["pos"].append(d.geom_xpos.copy())
                out["rot"].append(d.geom_xmat.reshape(2, 3, 3).copy())
                out["margins"].append(margin)
    batch = {key: np.array(value) for key, value in out.items()}
    forward = harness.plane_mesh(batch["meshes"][:, 1], batch["pos"], batch["rot"], batch["margins"])
    return batch, forward


# a cylinder's cap square on a face, a cap or a lying capsule (measure zero among random poses):
# (geom 1, geom 2, geom 1's turn in geom 2's frame, geom 1's half extent along geom 2's axis, the
# two geoms' (radius, half-length) where not test_colliders_convex's)
_QUARTER = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # a quarter turn about x: a capsule lying
_TILTED_QUARTER = np.array([[1.0, 0, 0], [0, np.cos(0.01), -np.sin(0.01)], [0, np.sin(0.01), np.cos(0.01)]]) @ _QUARTER
ALIGNED = [("capsule", "cylinder", _QUARTER, 0.05, None), ("cylinder", "cylinder", np.eye(3), 0.1, None),
           ("cylinder", "box", np.eye(3), 0.1, None),
           # cans small enough to stand on the box's face or the other's cap: four rim points
           # (convex._face_cap), the standing one geom 1 or geom 2
           ("cylinder", "box", np.eye(3), 0.05, ((0.03, 0.05), None)),
           ("cylinder", "cylinder", np.eye(3), 0.05, ((0.03, 0.05), None)),
           ("cylinder", "cylinder", np.eye(3), 0.1, (None, (0.03, 0.1))),
           ("cylinder", "box", _QUARTER, 0.03, ((0.03, 0.05), None)),  # a small can lying on the box
           ("cylinder", "box", _QUARTER, 0.03, ((0.03, 0.12), None)),  # ... or across it (its ends beyond)
           ("cylinder", "cylinder", _QUARTER, 0.03, ((0.03, 0.05), None)),  # ... or on the other's cap
           # a box's face within a wider can's cap (its corners), or ending inside its rim (the points
           # under its edges)
           ("cylinder", "box", np.eye(3), 0.05, ((0.1, 0.05), (0.05, 0.04))),
           ("cylinder", "box", np.eye(3), 0.05, ((0.12, 0.05), None)),
           # a small box's face off the can's axis (its corners within the cap, the rim point toward it)
           ("cylinder", "box", np.eye(3), 0.05, ((0.04, 0.05), (0.02, 0.02))),
           # a capsule or a can lying on a mesh's face (convex._lying_on_mesh: the two ends of its line),
           # flat and tilted 0.01 rad (a can's ends then meet it at their rims), and a can standing on it
           # (four rim points, some off the face)
           ("capsule", "mesh", _QUARTER, 0.02, ((0.02, 0.025), None)),
           ("cylinder", "mesh", _QUARTER, 0.02, ((0.02, 0.025), None)),
           ("capsule", "mesh", _TILTED_QUARTER, 0.02, ((0.02, 0.025), None)),
           ("cylinder", "mesh", _TILTED_QUARTER, 0.02, ((0.02, 0.025), None)),
           # ... longer than the face (0.12 m along its y): the line against the edges it crosses
           ("capsule", "mesh", _QUARTER, 0.02, ((0.02, 0.08), None)),
           ("cylinder", "mesh", _TILTED_QUARTER, 0.02, ((0.02, 0.08), None)),
           ("cylinder", "mesh", np.eye(3), 0.05, ((0.03, 0.05), None)),
           # a mesh's face within a wider can's cap (its polygon's vertices), or partly (those within
           # the cap, the rim points on the face and the rim point toward the face's middle)
           ("cylinder", "mesh", np.eye(3), 0.05, ((0.1, 0.05), None)),
           ("cylinder", "mesh", np.eye(3), 0.05, ((0.07, 0.05), None)),
           # equal cans up to 9 cm off each other's axis (r 5 cm): the cap's points under the other's rim
           # (EDGE), and beyond its rim (rim points off the cap) the collider's contact, a cap on a plane
           ("cylinder", "cylinder", np.eye(3), 0.1, ((0.05, 0.1), (0.05, 0.1)), 0.09)]
ALIGNED_MESH = 1  # geom 2's mesh where it is one: the box mesh (half extents 0.05, 0.06, 0.08 in MuJoCo's frame)
_HALF_AXIS = {"cylinder": 0.1, "box": 0.06, "mesh": 0.08}  # geom 2's half extent along its z axis (SIZES)


def _aligned_cases(rng, per_pair=20):
    """Poses of ALIGNED: geom 2 at a random pose, geom 1 turned as listed (or also flipped end
    for end), above or below geom 2 along its axis, 1..8 mm into it, up to 3 cm (or the case's
    sixth entry, m) off centre along each of geom 2's other axes:
    (name, types, sizes, meshes, pos, rot) as _convex_cases' (no MuJoCo contacts)."""
    cases = []
    for kind1, kind2, turn, half1, resized, *spread in ALIGNED:
        mesh2 = ALIGNED_MESH if kind2 == "mesh" else -1
        m = _model(f'<body><freejoint/>{_geom(kind1, None, 0.0)}</body>', _geom(kind2, mesh2, 0.0))
        for _ in range(per_pair):
            rot2 = np.zeros(9)
            mujoco.mju_quat2Mat(rot2, _random_quat(rng))
            rot2 = rot2.reshape(3, 3)
            side = rng.choice([-1.0, 1.0])
            flip = np.diag([1.0, -1.0, -1.0]) if rng.uniform() < 0.5 else np.eye(3)
            across = spread[0] if spread else 0.03
            offset = [*rng.uniform(-across, across, 2), side * (half1 + _HALF_AXIS[kind2] - rng.uniform(1e-3, 8e-3))]
            pos2 = rng.normal(size=3) * 0.1
            pos = np.array([pos2 + rot2 @ offset, pos2])
            sizes = m.geom_size.copy()
            for g, size in enumerate(resized or (None, None)):
                if size is not None:
                    sizes[g, :2] = size
            cases.append((f"aligned {kind1}-{kind2}", (TYPES[kind1], TYPES[kind2]), sizes, (-1, mesh2), pos,
                          np.array([rot2 @ turn @ flip, rot2])))
    return cases


def _convex_batch(harness):
    """The random convex_convex poses of test_colliders_convex (margin 0 and MARGIN) and the aligned
    ones (margin 0), as a batch, with the forward's contacts and the pair names."""
    parts, names = [], []
    rng = np.random.default_rng(5)
    for index, margin in ((0, 0.0), (1, MARGIN), (2, 0.0)):
        cases = _convex_cases(margin, per_pair=100, seed=index) if index < 2 else _aligned_cases(rng)
        forward = harness.convex([c[1] for c in cases], np.array([c[2] for c in cases]), [c[3] for c in cases],
                                 np.array([c[4] for c in cases]), np.array([c[5] for c in cases]),
                                 np.full(len(cases), margin))
        parts.append(({"types": np.array([c[1] for c in cases]), "sizes": np.array([c[2] for c in cases]),
                       "meshes": np.array([c[3] for c in cases]), "pos": np.array([c[4] for c in cases]),
                       "rot": np.array([c[5] for c in cases]), "margins": np.full(len(cases), margin)}, forward))
        names += [c[0] for c in cases]
    return parts, names


def _pad(forward):
    """A collider's (count, position, normal, dist, feature) with K contact rows."""
    count, position, normal, dist, feature = forward
    pad = ((0, 0), (0, K - position.shape[1]))
    return (count, np.pad(position, pad + ((0, 0),)), np.pad(normal, pad + ((0, 0),)), np.pad(dist, pad),
            np.pad(feature, pad + ((0, 0),)))


FROZEN_RIMS = "two rims holding both ends of each (the iterate kept)"  # convex.frozen


def _vertex_count(f):
    """m of the closed form (convex._vertex_ids)."""
    pairs = list(dict.fromkeys(zip(f[1:1 + 2 * f[7]:2], f[2:2 + 2 * f[7]:2])))
    return len(pairs) - 1


def _branch(f, types, margin):
    """The branches of the closed form a contact (feature row f, geom types) takes."""
    if f[0] == cv.KIND_PLANE:
        return {"plane"}
    if f[0] == cv.KIND_FACE_CAP:
        face = "mesh face" if types[1] == cv.MESH else "box face"
        if f[2] == cv.CORNER:
            return {f"{face}'s corner on a cap"}
        if f[2] == cv.TOWARD:
            return {f"rim point toward a {face}'s centre"}
        standing = "cylinder standing on a mesh face" if types[1] == cv.MESH else "cylinder standing on a box face"
        if f[2] == cv.LYING:
            return {"cylinder lying on a face"} | ({"lying across a box face's edge"} if f[5] == cv.EDGE else set())
        if f[5] == cv.EDGE and types[1 - f[4]] == cv.CYLINDER:  # (the base: the geom not standing)
            return {standing, "cap under another cap's rim"}
        return {standing} | ({f"cap under a {face}'s edge"} if f[5] == cv.EDGE else set())
    if f[0] == cv.KIND_CLIP:
        tags = int(f[3] >= 256) + int(f[4] >= 256)
        out = {["clip face-face", "clip edge of geom 1", "clip edge of geom 2"][f[7]],
               ["clip vertex", "clip edge x side plane", "clip side x side plane"][tags]}
        return out | ({"clip edge with margin"} if f[7] and margin > 0 else set())
    m, modes = _vertex_count(f), (f[10] % 3, f[10] // 3)
    out = {"cylinder " + ("rim", "cap", "side")[modes[g]] for g in range(2) if types[g] == cv.CYLINDER}
    caps = [g for g in range(2) if types[g] == cv.CYLINDER and modes[g] == 1]
    rims = [g for g in range(2) if types[g] == cv.CYLINDER and modes[g] == 0]
    one_end = [len(set(f[1 + g:1 + 2 * f[7]:2])) == 1 for g in range(2)]
    single = [g for g in rims if one_end[g] and not (1 - g in rims and one_end[1 - g])]  # convex._rim_side
    if caps:  # convex._cap_terms; the flat of the geom facing the cap (convex._cap_other_locals)
        other_ids = set(f[2 - caps[0]:1 + 2 * f[7]:2]) if len(caps) == 1 else {0, 1, 2}
        out |= {("cap on a point", "cap on a line", "cap on a plane")[len(other_ids) - 1]}
        out |= {f"cap of geom {caps[0] + 1}"} if len(caps) == 1 else set()
    elif m < 2 and single:  # convex._rim_terms
        out |= {("rim on a point", "rim on a line")[m], f"rim of geom {single[0] + 1}"}
        if 1 - single[0] in rims:
            out.add("rim on a rim holding both ends")  # the other cylinder met on its side
    elif m == 0 and len(rims) == 2:
        out.add("rim on a rim")  # convex._rims_terms
    elif m == 1 and len(rims) == 2:
        out.add(FROZEN_RIMS)
    else:  # convex._core_terms
        out.add(("core" if f[0] == cv.KIND_CORE else "epa") + f" m={m}")
        if m < 2 and rims:
            out.add("rim on its side")  # a rim feature holding both ends: its axis, met on its side
    return out


def _exact(f, types, margin):
    """Whether a contact's closed form is the forward's own computation (module doc)."""
    if f[0] == cv.KIND_FACE_CAP:
        return True  # (the four rim points: the forward evaluates the same closed form)
    curved = cv.CYLINDER in types or (f[0] == cv.KIND_EPA and (margin > 0 or cv.SPHERE in types
                                                                or cv.CAPSULE in types))
    return not curved and not (f[0] == cv.KIND_CLIP and f[7] > 0 and margin > 0)


@pytest.fixture(scope="module")
def results():
    """Every case's forward contacts, their replays, and the adjoint against central differences at
    each eps of SCAN (one kernel)."""
    gs.init(precision="64", logging_level="warning")
    harness = _Harness()
    rng = np.random.default_rng(11)
    parts, names = _convex_batch(harness)
    plane_batch, plane_forward = _plane_cases(harness, rng)
    parts.append((plane_batch, plane_forward))
    names += ["plane-mesh"] * len(plane_batch["margins"])
    batch = {key: np.concatenate([p[0][key] for p in parts]) for key in parts[0][0]}
    forward = [np.concatenate(column) for column in zip(*[_pad(p[1]) for p in parts])]
    count, position, normal, dist, feature = forward
    n = len(names)
    cotangent = rng.normal(size=(n, K, N_COTANGENT))
    args = (batch["types"].astype(np.int32), batch["sizes"], batch["meshes"].astype(np.int32), batch["pos"],
            batch["rot"], batch["margins"], count, feature, cotangent)
    grad = np.zeros((n, K, N_INPUTS))
    with taichi_opt_level(LIGHT_OPT_LEVEL):  # as the solver compiles its collider kernels (the same bits)
        _adjoint_kernel(*args, harness.hull_vec, harness.hull_int, grad)
        scan = {}
        for eps in SCAN:
            replay, fd = np.zeros((n, K, 7)), np.zeros((n, K, N_INPUTS))
            _replay_kernel(*args, harness.hull_vec, harness.hull_int, eps, replay, fd)
            scan[eps] = np.abs(grad - fd).max(axis=2) / np.maximum(1e-8, np.abs(fd).max(axis=2))
    rows = [(i, k) for i in range(n) for k in range(count[i])]
    forward_rows = np.concatenate([position, normal, dist[..., None]], axis=2)
    return {"rows": rows, "names": names, "count": count, "feature": feature, "types": batch["types"],
            "margins": batch["margins"], "replay_error": np.abs(replay - forward_rows), "scan": scan}


def test_replay_matches_forward(results):
    """Each contact's replay equals the forward's contact: to EXACT where the closed form is the
    forward's own; where the forward iterates on curves, position and distance to APPROX (the CCD
    tolerance's effect) and the normal to NORMAL_APPROX, except a cylinder's point on its cap (the
    iterate's is anywhere on the cap, the closed form's the foot of its centre: convex._cap_terms),
    and not where the forward keeps the iterate (convex.frozen). Every replay is finite.
    Errors below are in units of each bar."""
    r, feature = results, results["feature"]
    exact, approx = collections.defaultdict(list), collections.defaultdict(list)
    for i, k in r["rows"]:
        f = feature[i, k]
        key = (r["names"][i], int(f[0]), float(r["margins"][i]))
        errors = r["replay_error"][i, k]
        assert np.isfinite(errors).all(), (key, f)
        if FROZEN_RIMS in _branch(f, r["types"][i], r["margins"][i]):
            continue  # the forward keeps the iterate (convex.frozen)
        if _exact(f, r["types"][i], r["margins"][i]):
            exact[key].append(errors.max() / EXACT)
        else:
            on_cap = "cylinder cap" in _branch(f, r["types"][i], r["margins"][i])
            approx[key].append(max(0.0 if on_cap else errors[:3].max() / APPROX, errors[3:6].max() / NORMAL_APPROX,
                                   errors[6] / APPROX))
    print()
    for key in sorted(set(exact) | set(approx)):
        e, a = np.array(exact[key]), np.array(approx[key])
        print(f"{key[0]:18s} kind {key[1]} margin {key[2]}: exact-form {len(e):3d} max {e.max(initial=0):.1e}"
              f" | converged-form {len(a):3d} max {a.max(initial=0):.1e}, "
              f"{np.mean(a * APPROX <= EXACT) if len(a) else 0:.0%} within {EXACT:g}")
    everything = [e for values in exact.values() for e in values]
    print(f"{len(everything)} of {len(r['rows'])} contacts have the forward's closed form")
    assert {key[1] for key in exact} == {cv.KIND_CORE, cv.KIND_EPA, cv.KIND_CLIP, cv.KIND_PLANE, cv.KIND_FACE_CAP}
    assert max(everything) <= 1.0
    assert max(e for values in approx.values() for e in values) <= 1.0


def test_lying_on_a_mesh_face_touches_at_both_ends(results):
    """A capsule or a can lying on a mesh's face (ALIGNED) touches it at the two ends of its line
    clipped to the face (convex._lying_on_mesh; the collider alone gave one contact, and they
    see-sawed): two KIND_CORE contacts, each an end of the line (its id thrice) or the line where it
    crosses an edge (both ends, two of the face's vertices), whose adjoints the test below checks."""
    for name in ("aligned capsule-mesh", "aligned cylinder-mesh"):
        cases = [i for i, n in enumerate(results["names"]) if n == name and results["count"][i] == 2
                 and results["feature"][i, 0, 0] == cv.KIND_CORE]
        rows = [results["feature"][i, k] for i in cases for k in range(2)]
        ends = [f for f in rows if f[1] == f[3] == f[5]]
        crossings = [f for f in rows if (f[1], f[3], f[5]) == (0, 1, 0) and f[2] == f[4] != f[6]]
        assert len(cases) == 60 and len(ends) + len(crossings) == 120, (name, len(cases), len(ends), len(crossings))
        assert len(ends) >= 80 and len(crossings) >= 10, (name, len(ends), len(crossings))


def test_adjoint_matches_central_differences(results):
    """The adjoint's 24 pose gradients against central differences of the replay (feature
    frozen), every branch of the closed form covered; per eps the worst contact, and each
    contact at its best eps within TOL."""
    r, feature = results, results["feature"]
    rows = tuple(np.array(r["rows"]).T)
    scan = {eps: err[rows] for eps, err in r["scan"].items()}
    best = np.min(np.stack(list(scan.values())), axis=0)
    seen = collections.Counter()
    worst = collections.defaultdict(float)
    for index, (i, k) in enumerate(r["rows"]):
        for branch in _branch(feature[i, k], r["types"][i], r["margins"][i]):
            seen[branch] += 1
            worst[branch] = max(worst[branch], best[index])
    print(f"\n{len(best)} contacts; worst relative error per eps: "
          + ", ".join(f"{eps:.0e}: {err.max():.1e}" for eps, err in scan.items()))
    for branch in sorted(seen):
        print(f"  {branch:24s} {seen[branch]:4d} contacts, worst at best eps {worst[branch]:.1e}")
    assert not BRANCHES - set(seen), f"branches never reached: {sorted(BRANCHES - set(seen))}"
    assert best.max() <= TOL, f"adjoint differs from central differences by {best.max():.3g} (relative)"
    assert scan[1e-6].max() < scan[1e-5].max(), "central differences do not converge to the adjoint"
