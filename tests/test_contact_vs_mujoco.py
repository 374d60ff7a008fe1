"""Contact, step for step against MuJoCo: from the same state, one step gives the same
velocities (≤ 1e-8), dofs forces (get_dofs_force: MuJoCo's qfrc_smooth + qfrc_constraint) and the
same contacts (count, geoms, positions; the colliders' normals,
frames and distances are compared with MuJoCo's in tests/test_colliders_*.py) for every
primitive pair, both friction cones, default and non-default solref, solimp and impratio.

Each case is one batched scene whose envs start from different MuJoCo states near contact
(penetrating up to a few mm, or just apart), with random velocities.
"""
import copy

import mujoco
import numpy as np
import pytest
import taichi as ti
import torch

import genesis_lite as gs
from tests.contact_scenes import GRIPPER, Body, ContactScene, build_mujoco, build_ours

N_STATES = 24
rng_seed = 7


def _random_quat(rng):
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


def _touching_states(m, rng, n, depth=(-0.002, 0.003)):
    """n (qpos, qvel) of MuJoCo model m with every free body placed so that its geoms are at a
    signed distance in -depth from the others (shifted along z, or along the centre line)."""
    d = mujoco.MjData(m)
    states = []
    n_bodies = m.nbody - 1
    for _ in range(n):
        qpos = m.qpos0.copy()
        for b in range(n_bodies):
            qpos[7 * b: 7 * b + 3] = rng.uniform(-0.05, 0.05, 3) + [0.0, 0.0, 0.3 * (b + 1)]
            qpos[7 * b + 3: 7 * b + 7] = _random_quat(rng)
        has_plane = m.ngeom > n_bodies
        for b in range(n_bodies):  # body b down onto what is below it (the plane or body b - 1)
            if b == 0 and not has_plane:
                continue
            below = b - 1
            target = -rng.uniform(*depth)
            for _ in range(8):
                d.qpos[:] = qpos
                mujoco.mj_kinematics(m, d)
                g2 = m.body_geomadr[b + 1]
                g1 = 0 if below < 0 else m.body_geomadr[below + 1]  # the plane is geom 0
                dist = mujoco.mj_geomDistance(m, d, g1, g2, 10.0, None)
                qpos[7 * b + 2] -= dist - target
        qvel = rng.uniform(-1.0, 1.0, m.nv)
        states.append((qpos, qvel))
    return states


def _mujoco_step(m, qpos, qvel):
    d = mujoco.MjData(m)
    d.qpos[:], d.qvel[:] = qpos, qvel
    mujoco.mj_step(m, d)
    return d


def _set_ours(entities, qpos, qvel):
    for b, entity in enumerate(entities):
        entity.set_qpos(torch.as_tensor(qpos[:, 7 * b: 7 * b + 7], dtype=gs.tc_float), zero_velocity=False)
        entity.set_dofs_velocity(torch.as_tensor(qvel[:, 6 * b: 6 * b + 6], dtype=gs.tc_float))


def _contacts_mujoco(d):
    return [(c.geom[0], c.geom[1], c.pos.copy()) for c in d.contact[: d.ncon]]


def _check_step(spec, n_states=N_STATES, entity=0, mass_scale=None):
    """One step from MuJoCo's states: velocities, and the contacts of ``entities[entity]`` (its
    get_contacts) against MuJoCo's contacts that involve its geoms, in order. mass_scale
    (n_states, bodies): each env's masses (and so inertias) scaled after build, in MuJoCo by a
    model per env with body_mass and body_inertia scaled and mj_setConst (body_invweight0 anew)."""
    spec.n_envs = n_states
    scene, entities = build_ours(spec)
    m = build_mujoco(spec, scene._rigid_solver.model)
    rng = np.random.default_rng(rng_seed)
    states = _touching_states(m, rng, n_states)
    qpos = np.array([q for q, _ in states])
    qvel = np.array([v for _, v in states])
    models = [m] * n_states
    if mass_scale is not None:
        models = [_scaled(m, scales) for scales in mass_scale]
        for b, body in enumerate(entities):
            body.set_mass(body.get_mass() * torch.as_tensor(mass_scale[:, b], dtype=gs.tc_float))  # (inertia too)
    _set_ours(entities, qpos, qvel)
    scene.step()
    ours_qvel = np.concatenate([e.get_dofs_velocity().cpu().numpy() for e in entities], axis=1)
    ours_force = np.concatenate([e.get_dofs_force().cpu().numpy() for e in entities], axis=1)
    contacts = entities[entity].get_contacts()
    geom_map = _geom_map(scene, m, spec)
    mine = set(range(entities[entity].geom_start, entities[entity].geom_start + entities[entity].n_geoms))
    n_touching = 0
    for k in range(n_states):
        d = _mujoco_step(models[k], qpos[k], qvel[k])
        assert np.allclose(ours_qvel[k], d.qvel, rtol=0, atol=1e-8), (k, ours_qvel[k] - d.qvel)
        force = d.qfrc_smooth + d.qfrc_constraint  # Genesis's dofs force: the step's, contacts included
        assert np.allclose(ours_force[k], force, rtol=0, atol=1e-6 * (1 + np.abs(force).max())), \
            (k, ours_force[k] - force)
        expected = [c for c in _contacts_mujoco(d) if c[0] in mine or c[1] in mine]
        valid = contacts["valid_mask"][k]
        ours = [(int(a), int(b), p) for a, b, p in zip(contacts["geom_a"][k][valid], contacts["geom_b"][k][valid],
                                                      contacts["position"][k][valid].cpu().numpy())]
        assert len(ours) == len(expected), (k, len(ours), len(expected))
        for (a, b, p), (g1, g2, pos) in zip(ours, expected):
            assert (geom_map[a], geom_map[b]) == (g1, g2)
            assert np.allclose(p, pos, rtol=0, atol=1e-10)
        n_touching += len(expected) > 0
    assert n_touching >= n_states // 2, "most states must touch"


def _scaled(m, scales):
    """A copy of MuJoCo model m with free body b's mass and inertia times scales[b], its constants
    (body_invweight0, dof_invweight0) recomputed."""
    scaled = copy.deepcopy(m)
    for b, scale in enumerate(scales):
        scaled.body_mass[b + 1] *= scale
        scaled.body_inertia[b + 1] *= scale
    mujoco.mj_setConst(scaled, mujoco.MjData(scaled))
    return scaled


def _geom_map(scene, m, spec):
    """Our global geom index → MuJoCo's (same order: the plane first, then one per body)."""
    return {k: k for k in range(m.ngeom)}


PLANE_SHAPES = [Body("sphere", (0.1,)), Body("capsule", (0.05, 0.2)), Body("box", (0.2, 0.3, 0.1)),
                Body("cylinder", (0.08, 0.2))]


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
@pytest.mark.parametrize("body", PLANE_SHAPES, ids=lambda b: b.shape)
def test_plane_pairs_step_like_mujoco(f64, body, cone):
    _check_step(ContactScene([body], cone=cone))


PAIRS = [("sphere", "sphere"), ("sphere", "capsule"), ("capsule", "capsule"), ("sphere", "box"),
         ("capsule", "box"), ("box", "box")]
SHAPE = {"sphere": Body("sphere", (0.1,)), "capsule": Body("capsule", (0.05, 0.2)), "box": Body("box", (0.2, 0.3, 0.1))}


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
@pytest.mark.parametrize("pair", PAIRS, ids="-".join)
def test_body_pairs_step_like_mujoco(f64, pair, cone):
    _check_step(ContactScene([SHAPE[pair[0]], SHAPE[pair[1]]], plane=False, cone=cone))


TORSION_ROLL_SCENES = {"sphere-plane": ([SHAPE["sphere"]], True), "box-plane": ([SHAPE["box"]], True),
                       "capsule-box": ([SHAPE["capsule"], SHAPE["box"]], False),
                       "box-box": ([SHAPE["box"], Body("box", (0.1, 0.15, 0.08))], True)}


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
@pytest.mark.parametrize("condim", [4, 6])
@pytest.mark.parametrize("scene_name", list(TORSION_ROLL_SCENES))
def test_torsional_and_rolling_friction_step_like_mujoco(f64, scene_name, condim, cone):
    """Contacts of condim 4 (torsional friction: a row on the turn about the normal) and 6 (and
    rolling: rows on the turns about the tangents), by RigidOptions' enable_torsional_friction and
    enable_rolling_friction and materials.Rigid's friction_torsional and friction_rolling, step as
    MuJoCo's geoms of that condim and friction (large enough to act: 0.03 m and 0.02 m), with
    impratio 3 (the elliptic rows' R_k = R_1 μ²/μ_k²)."""
    bodies, plane = TORSION_ROLL_SCENES[scene_name]
    _check_step(ContactScene(bodies, plane=plane, cone=cone, condim=condim, friction=(0.8, 0.03, 0.02),
                             impratio=3.0))


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_masses_set_after_build_step_like_mujoco(f64, cone):
    """A box on a box on the plane, each env its own masses, set after build: the rows' scale
    (body_invweight0) follows them as MuJoCo's mj_setConst makes it (the box–box contact's diagA
    is 1/m₁ + 1/m₂ for free boxes; with the build's constants, qvel differs by ~1e-2)."""
    scales = np.random.default_rng(3).uniform(0.3, 3.0, (N_STATES, 2))
    _check_step(ContactScene([SHAPE["box"], Body("box", (0.1, 0.15, 0.08))], cone=cone), mass_scale=scales)


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_damped_box_lands_with_mujocos_warm_start(f64, cone):
    """After a step without constraint rows MuJoCo's next solve starts from qacc_smooth = M⁻¹
    qfrc_smooth, undamped even where dofs are damped (the damped acceleration is a local of its
    integrator): a damped box falling onto the plane keeps MuJoCo's warm start every step, and
    with the elliptic cone, whose solve stops where its start leads it, lands as MuJoCo's."""
    spec = ContactScene([Body("box", (0.2, 0.15, 0.1), pos=(0.0, 0.0, 0.075), quat=(0.99, 0.05, 0.1, 0.0))],
                        cone=cone)
    scene, (box,) = build_ours(spec)
    m = build_mujoco(spec, scene._rigid_solver.model)
    m.dof_damping[:] = 2.0
    box.set_dofs_damping(torch.full((6,), 2.0, dtype=torch.float64))
    d = mujoco.MjData(m)
    d.qpos[:] = box.get_qpos().numpy()
    d.qvel[:] = [0.6, -0.3, 0.0, 0.0, 0.0, 4.0]
    box.set_dofs_velocity(torch.as_tensor(d.qvel.copy()))
    landed = False
    for _ in range(60):
        scene.step()
        mujoco.mj_step(m, d)
        landed |= d.nefc > 0
        warm = scene._rigid_solver.warm_start()[0].numpy()
        assert np.abs(warm - d.qacc_warmstart).max() < 1e-9 * (1.0 + np.abs(d.qacc_warmstart).max())
    assert landed and d.nefc > 0
    assert np.abs(box.get_qpos().numpy() - d.qpos).max() < 1e-12
    assert np.abs(box.get_dofs_velocity().numpy() - d.qvel).max() < 1e-11


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_non_default_parameters_step_like_mujoco(f64, cone):
    _check_step(ContactScene([Body("box", (0.2, 0.3, 0.1))], cone=cone, impratio=3.0, solref=(0.05, 0.7),
                             solimp=(0.8, 0.99, 0.004, 0.3, 3.0)))


@pytest.mark.parametrize("form", ["standard", "direct"])
def test_two_geoms_parameters_mix_like_mujoco(f64, form):
    """A contact averages its geoms' solimp, averages their standard solref or takes the smaller
    direct one, as MuJoCo mixes two geoms of equal solmix and priority."""
    plane, box = {"standard": ((0.03, 0.8), (0.015, 1.2)), "direct": ((-8000.0, -60.0), (-12000.0, -40.0))}[form]
    params = [(*plane, 0.85, 0.97, 0.002, 0.4, 2.0), (*box, 0.7, 0.9, 0.0005, 0.6, 3.0)]
    _check_step(ContactScene([Body("box", (0.2, 0.3, 0.1))], sol_per_geom=params))


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_mixed_kinds_keep_mujoco_contact_order(f64, cone):
    """A stack whose pair kinds interleave (box–box below sphere–box): the colliders run kind by
    kind, and the contacts are then listed as MuJoCo lists them, by body pair: the same rows in
    the same order, so the same rounding."""
    _check_step(ContactScene([SHAPE["box"], SHAPE["box"], SHAPE["sphere"]], cone=cone), entity=1)


@pytest.mark.parametrize("shape, size", [("capsule", (0.05, 0.3)), ("cylinder", (0.08, 0.2)), ("box", (0.2, 0.3, 0.1))])
def test_bodies_placed_exactly_on_the_plane_step_like_mujoco(f64, shape, size):
    """Lying exactly on the plane, a quaternion typed as (√½, √½, 0, 0) (|q|² = 1 + 2e-16): MuJoCo
    keeps it (its normalisation skips a norm within 1e-15 of 1) and rounds the rotation matrix its
    way, so both ends sit at distance 0, listed and pushing nothing (a contact makes rows below the
    margin only). With 1 − 2(y² + z²), one end came 2e-17 m under the plane and its contact kicked
    the body into a 0.08 rad/s spin MuJoCo does not have; contacts at the margin made rows."""
    h = 0.7071067811865476
    for quat in ((h, h, 0.0, 0.0), (h, 0.0, h, 0.0)):
        z = size[0] if shape != "box" else size[2] / 2.0
        spec = ContactScene([Body(shape, size, pos=(0.0, 0.0, z), quat=quat)])
        scene, (body,) = build_ours(spec)
        m = build_mujoco(spec, scene._rigid_solver.model)
        d = mujoco.MjData(m)
        d.qpos[:] = body.get_qpos().numpy()
        scene.step()
        mujoco.mj_step(m, d)
        assert np.abs(body.get_dofs_velocity().numpy() - d.qvel).max() <= 1e-12, (shape, quat)
        contacts = body.get_contacts()
        assert contacts["geom_a"].numel() == d.ncon, (shape, quat)
        if d.nefc == 0:
            assert torch.all(contacts["force_a"] == 0.0), (shape, quat)


TURNED_GEOMS = {  # a geom whose frame is turned in its body (MJCF)
    "capsule fromto": '<geom type="capsule" fromto="0 0 0 0.2 0 0" size="0.03"/>',
    "capsule quat": '<inertial pos="0 0 0" mass="1" diaginertia="0.01 0.01 0.01"/>'
                    '<geom type="capsule" size="0.03 0.1" quat="0.8 0.6 0 0" pos="0.05 0 0"/>',
    "box euler": '<inertial pos="0 0 0" mass="1" diaginertia="0.01 0.01 0.01"/>'
                 '<geom type="box" size="0.05 0.04 0.03" euler="0.3 0.2 0.1"/>',
}


@pytest.mark.parametrize("geom", list(TURNED_GEOMS))
def test_geoms_turned_in_their_body_placed_exactly_on_the_plane_step_like_mujoco(f64, tmp_path, geom):
    """A free body whose geom is turned in it, in 32 orientations, its lowest point exactly on the
    plane in MuJoCo's arithmetic, falling at 0.3 m/s: after a step the same contacts and
    velocities (≤ 1e-10). The geom's axes are the matrix of the quaternions' product, as MuJoCo's
    (a product of matrices, a bit off, and the MJCF frames' rounding flipped contacts at distance 0
    in 9 of 64 orientations and moved qvel by up to 0.5 m/s)."""
    path = tmp_path / "turned.xml"
    path.write_text(f'<mujoco><worldbody><geom type="plane" size="0 0 1"/><body name="b"><freejoint/>'
                    f'{TURNED_GEOMS[geom]}</body></worldbody></mujoco>')
    m = mujoco.MjModel.from_xml_path(str(path))
    d = mujoco.MjData(m)
    rng = np.random.default_rng(sum(map(ord, geom)))
    n = 32
    qpos, qvel = np.zeros((n, 7)), np.tile([0.1, 0.0, -0.3, 0.5, -0.2, 0.1], (n, 1))
    for e in range(n):
        d.qpos[:] = [0.0, 0.0, 0.5, *_random_quat(rng)]
        for _ in range(3):  # the lowest point onto the plane, in MuJoCo's arithmetic
            mujoco.mj_kinematics(m, d)
            rot, centre, size = d.geom_xmat[1].reshape(3, 3), d.geom_xpos[1], m.geom_size[1]
            if m.geom_type[1] == mujoco.mjtGeom.mjGEOM_BOX:
                d.qpos[2] -= centre[2] - np.abs(rot[2]) @ size
            else:
                d.qpos[2] -= centre[2] - abs(rot[2, 2]) * size[1] - size[0]
        qpos[e] = d.qpos
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002), show_viewer=False,
                     rigid_options=gs.options.RigidOptions(enable_mujoco_compatibility=True))
    body = scene.add_entity(gs.morphs.MJCF(file=str(path)))
    scene.build(n_envs=n)
    body.set_qpos(torch.as_tensor(qpos), zero_velocity=False)
    body.set_dofs_velocity(torch.as_tensor(qvel))
    scene.step()
    counts = body.get_contacts()["valid_mask"].sum(1).numpy()
    for e in range(n):
        d.qpos[:], d.qvel[:] = qpos[e], qvel[e]
        mujoco.mj_step(m, d)
        assert counts[e] == d.ncon, (geom, e)
        assert np.abs(body.get_dofs_velocity()[e].numpy() - d.qvel).max() <= 1e-10, (geom, e)


def test_geom_frames_round_as_mujocos(f64):
    """The geoms' world axes (detect._turned, spatial.quat_to_mat) are MuJoCo 4.0's to the bit: its
    mju_mulQuat and mju_quat2Mat on random quaternions (unit and not)."""
    from genesis_lite.solvers.rigid.collision.detect import _turned
    from genesis_lite.solvers.rigid.spatial import quat_to_mat

    @ti.kernel
    def products(a: ti.types.ndarray(), b: ti.types.ndarray(), product: ti.types.ndarray(),
                 matrix: ti.types.ndarray()):
        for k in range(a.shape[0]):
            qa = ti.Vector([a[k, i] for i in ti.static(range(4))])
            qb = ti.Vector([b[k, i] for i in ti.static(range(4))])
            qab, rot = _turned(qa, qb), quat_to_mat(qa)
            for i in ti.static(range(4)):
                product[k, i] = qab[i]
            for i, j in ti.static(ti.ndrange(3, 3)):
                matrix[k, 3 * i + j] = rot[i, j]

    rng = np.random.default_rng(11)
    a, b = rng.normal(size=(2000, 4)), rng.normal(size=(2000, 4))
    a[:1000] /= np.linalg.norm(a[:1000], axis=1, keepdims=True)
    product, matrix = np.zeros((2000, 4)), np.zeros((2000, 9))
    products(a, b, product, matrix)
    for k in range(2000):
        theirs_product, theirs_matrix = np.zeros(4), np.zeros(9)
        mujoco.mju_mulQuat(theirs_product, a[k], b[k])
        mujoco.mju_quat2Mat(theirs_matrix, a[k])
        assert np.array_equal(product[k], theirs_product), k
        assert k >= 1000 or np.array_equal(matrix[k], theirs_matrix), k


_HALF_TURN_Y = "0.7071067811865476 0 0.7071067811865476 0"


@pytest.mark.parametrize("kind", ["box", "capsule"])
def test_bounding_spheres_exactly_touching_keep_the_pair(f64, kind):
    """MuJoCo's broad phase drops a pair only when its bounding spheres are strictly further apart
    than the margin: boxes corner on corner (distance exactly 0, listed) and capsules end to end
    (−6e-17, two contacts with rows) are found, as MuJoCo finds them (ours dropped both pairs)."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002, gravity=(0, 0, 0)),
                     rigid_options=gs.options.RigidOptions(enable_mujoco_compatibility=True), show_viewer=False)
    if kind == "box":
        poses, size = [((0, 0, 0.1), None), ((0.2, 0.2, 0.2), None)], "0.1 0.1 0.05"
        first = [scene.add_entity(gs.morphs.Box(size=(0.2, 0.2, 0.1), pos=pos)) for pos, _ in poses][0]
    else:
        quat = (np.sqrt(0.5), 0.0, np.sqrt(0.5), 0.0)
        poses, size = [((0, 0, 0.1), _HALF_TURN_Y), ((0.26, 0, 0.1), _HALF_TURN_Y)], "0.03 0.1"
        first = [scene.add_entity(gs.morphs.Capsule(radius=0.03, height=0.2, pos=pos, quat=quat))
                 for pos, _ in poses][0]
    scene.build()
    bodies = "".join(f'<body pos="{" ".join(map(str, pos))}"{f" quat={chr(34)}{q}{chr(34)}" if q else ""}>'
                     f'<freejoint/><geom type="{kind}" size="{size}"/></body>' for pos, q in poses)
    m = mujoco.MjModel.from_xml_string(f'<mujoco><option gravity="0 0 0"/><worldbody>{bodies}</worldbody></mujoco>')
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    scene.step()
    ours = first.get_contacts()
    assert d.ncon > 0 and len(ours["geom_a"]) == d.ncon
    assert np.allclose(-ours["penetration"].numpy(), [c.dist for c in d.contact[:d.ncon]], rtol=0, atol=1e-15)


def test_bounding_radii_are_mujocos_bits(f64):
    """Boxes' and cylinders' bounding radii are MuJoCo's to the bit (its sqrt of the summed squares;
    a norm or hypot differed in the last bit for ~15 % of sizes), so that pairs exactly at the
    margin are kept or dropped as MuJoCo's broad phase does."""
    rng = np.random.default_rng(0)
    halves = [[float(x) for x in rng.uniform(0.001, 2.0, 3)] for _ in range(60)]
    scene = gs.Scene(show_viewer=False)
    for h in halves:
        scene.add_entity(gs.morphs.Box(size=tuple(2 * x for x in h)))
        scene.add_entity(gs.morphs.Cylinder(radius=h[0], height=2 * h[1]))
    scene.build()
    geoms = "".join(f'<geom type="box" size="{h[0]!r} {h[1]!r} {h[2]!r}"/><geom type="cylinder" size="{h[0]!r} {h[1]!r}"/>'
                    for h in halves)
    m = mujoco.MjModel.from_xml_string(f"<mujoco><worldbody>{geoms}</worldbody></mujoco>")
    assert np.array_equal(scene._rigid_solver.model.geom_rbound, m.geom_rbound)


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_a_gripper_squeezing_a_cube_moves_as_mujoco(f64, cone, tmp_path):
    """Two prismatic fingers on a fixed palm (sliding leaves: MuJoCo scales their contact rows by
    1 / mass, tests/test_dynamics_vs_mujoco.py) squeeze a free cube with constant forces while it
    slips down between them: 1 s against MuJoCo loading the same URDF stays within 1e-10 (with
    the fingers' rows scaled as every other body's: 3e-4 to 5e-4 m apart)."""
    path = tmp_path / "gripper.urdf"
    path.write_text(GRIPPER)
    dt, force, steps = 0.002, np.array([0.5, 0.4]), 500
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=dt), show_viewer=False,
                     rigid_options=gs.options.RigidOptions(enable_mujoco_compatibility=True, friction_cone=cone))
    gripper = scene.add_entity(gs.morphs.URDF(file=str(path), fixed=True))
    cube = scene.add_entity(gs.morphs.Box(size=(0.04, 0.04, 0.04), pos=(0.0, 0.0, 0.1)))
    scene.build()
    try:
        model = scene._rigid_solver.model
        spec = mujoco.MjSpec.from_file(str(path))
        spec.compiler.fusestatic = True
        spec.option.timestep = dt
        spec.option.cone = mujoco.mjtCone.mjCONE_PYRAMIDAL if cone == "pyramidal" else mujoco.mjtCone.mjCONE_ELLIPTIC
        body = spec.worldbody.add_body(name="cube", pos=[0.0, 0.0, 0.1], mass=float(model.link_mass0[-1]),
                                       inertia=np.diag(model.link_inertia0[-1]).tolist())
        body.explicitinertial, body.ipos = True, [0.0, 0.0, 0.0]  # (unset, it compiled 0.1 m off the origin)
        body.add_freejoint()
        body.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.02, 0.02, 0.02])
        m = spec.compile()
        assert [int(m.body(name).simple[0]) for name in ("left", "right")] == [2, 2]
        d = mujoco.MjData(m)
        d.qfrc_applied[:2] = force
        gripper.control_dofs_force(force)
        worst = 0.0
        for _ in range(steps):
            scene.step()
            mujoco.mj_step(m, d)
            ours = np.concatenate([gripper.get_qpos().numpy(), cube.get_qpos().numpy()])
            worst = max(worst, np.abs(ours - d.qpos).max())
        assert d.qpos[4] < 0.1 - 1e-3  # the cube slipped (2-4 mm)
        assert worst < 1e-10, f"max |qpos - MuJoCo's| over 1 s: {worst:.3g}"
    finally:
        scene.destroy()


TWO_GEOMS = """<robot name="two"><link name="a"><inertial><mass value="1"/>
  <inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
  <collision><origin xyz="-0.06 0 0"/><geometry><box size="0.1 0.1 0.1"/></geometry></collision>
  <collision><origin xyz="0.06 0 0"/><geometry><sphere radius="0.05"/></geometry></collision></link></robot>"""


@pytest.mark.parametrize("plane", [False, True], ids=["no plane", "plane added last"])
@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_contacts_of_a_body_with_two_geoms_come_in_mujocos_order(f64, cone, plane, tmp_path):
    """A free body holding a box (geom 0) and a sphere (geom 1), a ball on each (geoms 2, 3):
    MuJoCo lists contacts body pair by body pair, and within a pair by its ordered geoms, (1, 2)
    then (3, 0); by geom pair, ours were (3, 0), (1, 2) (the rows permuted: the same motion to
    round-off). Found by the MuJoCo probe. A plane added last (our geom 4, MuJoCo's world geom 0)
    is MuJoCo's world body: its contacts come first (a review found them after the balls')."""
    path = tmp_path / "two.urdf"
    path.write_text(TWO_GEOMS)
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002, gravity=(0, 0, -1.0)),
                     rigid_options=gs.options.RigidOptions(enable_mujoco_compatibility=True, friction_cone=cone))
    body = scene.add_entity(gs.morphs.URDF(file=str(path)))
    balls = [scene.add_entity(gs.morphs.Sphere(radius=0.04, pos=(x, 0.0, 0.088))) for x in (0.06, -0.06)]
    if plane:
        scene.add_entity(gs.morphs.Plane(pos=(0.0, 0.0, -0.05)))
    scene.build()
    model = scene._rigid_solver.model
    spec = mujoco.MjSpec.from_file(str(path))
    if plane:
        spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0.0, 0.0, 1.0], pos=[0.0, 0.0, -0.05])
    spec.compiler.alignfree = False
    spec.worldbody.bodies[0].add_freejoint()
    spec.option.timestep, spec.option.gravity = 0.002, [0.0, 0.0, -1.0]
    spec.option.cone = getattr(mujoco.mjtCone, f"mjCONE_{cone.upper()}")
    for ball in balls:
        link = ball.link_start
        added = spec.worldbody.add_body(pos=ball.get_pos().tolist(), mass=float(model.link_mass0[link]),
                                        inertia=np.diag(model.link_inertia0[link]).tolist())
        added.explicitinertial, added.ipos = True, [0.0, 0.0, 0.0]
        added.add_freejoint()
        added.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.04, 0.0, 0.0])
    m = spec.compile()
    d = mujoco.MjData(m)
    for _ in range(3):
        scene.step()
        mujoco.mj_step(m, d)
    ours = scene._rigid_solver.contacts()[0].numpy()
    mujoco_geom = [1, 2, 3, 4, 0] if plane else [0, 1, 2, 3]  # (MuJoCo numbers the world's geoms first)
    ours = [(mujoco_geom[int(row[0])], mujoco_geom[int(row[1])]) for row in ours if row[0] >= 0]
    theirs = [tuple(int(g) for g in contact.geom) for contact in d.contact[:d.ncon]]
    assert ours == theirs and theirs[-2:] == ([(2, 3), (4, 1)] if plane else [(1, 2), (3, 0)])
    assert not plane or len(theirs) > 2
    state = np.concatenate([body.get_qpos().numpy()] + [ball.get_qpos().numpy() for ball in balls])
    assert np.abs(state - d.qpos).max() < 1e-14
