"""Connect and weld equalities (MJCF ``<equality><connect>``: a point of one body held on a point
of another, or of the world; ``<equality><weld>``: a frame held on a frame, position and
orientation) against MuJoCo 4 and finite differences (float64).

assets/mjcf/fourbar.xml: a planar four-bar linkage, three hinges closed on the world by a connect.
assets/mjcf/connects.xml: a ball–hinge–ball arm whose tip site is held on a world site 1 cm
away at the start (site semantics), and a free box and a free sphere joined by a connect (body semantics: the sphere's
anchor, off its centre, and where that point is on the box at qpos0) that fall onto the floor.
assets/mjcf/welds.xml: the same arm's palm site welded to a world site 1 cm and 6° away
(torquescale 0.5), and a lid welded onto a free box (body semantics: relpose taken at qpos0).
MuJoCo 4's rows ask the error's acceleration J q̈ + J̇ q̇ to follow the reference (its mj_Jdotv):
without the J̇ q̇ term ours drifted 6e-4 from MuJoCo in one step.
"""
import mujoco
import numpy as np
import pytest
import torch

import genesis_lite as gs
from genesis_lite.solvers.rigid import contact
from genesis_lite.solvers.rigid.data import SERIAL_LINK_ENVS
from genesis_lite.utils.rotations import quat_to_mat
from tests.conftest import asset
from tests.fd_scan import EPS, assert_converged, directional_errors, pose_loss, repeated_gradients
from tests.test_mjcf import _lockstep, _pair

FOURBAR, CONNECTS, WELDS = (asset("mjcf", name) for name in ("fourbar.xml", "connects.xml", "welds.xml"))


def _gaps(scene, robot):
    """|p1 − p2| (m) of each connect and weld of the scene (its one robot's links' poses now), and
    each weld's turn between its two held frames (rad)."""
    model = scene.sim.slots[0].solver.model
    pos, rot = robot.get_links_pos().detach().numpy(), quat_to_mat(robot.get_links_quat().detach()).numpy()
    frames = [(pos[l - robot.link_start], rot[l - robot.link_start]) if l >= 0 else (np.zeros(3), np.eye(3))
              for l in model.body_eq_link.flatten()]
    gaps = [np.linalg.norm(p1 + r1 @ a1 - p2 - r2 @ a2) for (p1, r1), (p2, r2), a1, a2
            in zip(frames[0::2], frames[1::2], model.body_eq_anchor[0::2], model.body_eq_anchor[1::2])]
    turns = []
    for w, ((_, r1), (_, r2)) in enumerate(list(zip(frames[0::2], frames[1::2]))[model.n_body_eq - model.n_weld:]):
        held1, held2 = (r @ quat_to_mat(torch.tensor(t)).numpy() for r, t in ((r1, model.weld_turn[2 * w]),
                                                                               (r2, model.weld_turn[2 * w + 1])))
        turn = held1.T @ held2  # its angle from 2 sin θ (the axis vector's length) and 2 cos θ (trace − 1)
        axis = np.array([turn[2, 1] - turn[1, 2], turn[0, 2] - turn[2, 0], turn[1, 0] - turn[0, 1]])
        turns.append(np.arctan2(np.linalg.norm(axis), np.trace(turn) - 1))
    return np.array(gaps + turns)


def test_four_bar_linkage_matches_mujoco(f64):
    """2 s from random hinge velocities (the loop's rows from the start): 1e-10 from MuJoCo (2e-13
    measured), and the loop stays closed."""
    m, d, scene, robot = _pair(FOURBAR)
    assert m.neq == 1 and robot.n_dofs == m.nv == 3
    velocity = np.random.default_rng(0).normal(size=m.nv)
    d.qvel[:] = velocity
    robot.set_dofs_velocity(torch.tensor(velocity))
    rows = []
    assert _lockstep(m, d, scene, robot, 1000, lambda: rows.append(d.ne)) < 1e-10
    assert min(rows) == 3
    assert _gaps(scene, robot).max() < 1e-3


@pytest.mark.parametrize("path, cone", [(CONNECTS, "pyramidal"), (WELDS, "pyramidal"),
                                        *(pytest.param(path, "elliptic", marks=pytest.mark.slow)
                                          for path in (CONNECTS, WELDS))])
def test_connects_and_welds_by_sites_and_bodies_match_mujoco(f64, path, cone):
    """Both equalities, both bodies of the second free, landing on the floor (contacts): 2 s in
    both engines (MuJoCo's Euler integrator: free bodies turn). Measured 3e-11 (pyramidal) and
    6e-11 (elliptic) with the connects, 2.3e-12 with the welds: the solves' tolerance once
    contacts come."""
    m, d, scene, robot = _pair(path, cone, integrator="euler")
    model = scene.sim.slots[0].solver.model
    mujoco.mj_setConst(m, mujoco.MjData(m))  # (on data of its own: it leaves qpos at qpos0's)
    # body semantics: what is not given is taken at qpos0, as MuJoCo's compiler takes it (a weld's
    # anchors are in the other order there; its turn r1 is MuJoCo's relpose, up to its sign)
    data = m.eq_data[1]
    if path == CONNECTS:
        np.testing.assert_allclose(model.body_eq_anchor[2:4], data[:6].reshape(2, 3), atol=1e-14)
    else:
        np.testing.assert_allclose(model.body_eq_anchor[2:4], [data[3:6], data[0:3]], atol=1e-14)
        turn = model.weld_turn[2] * np.sign(model.weld_turn[2] @ data[6:10])
        np.testing.assert_allclose(turn, data[6:10], atol=1e-14)
        assert model.weld_torquescale.tolist() == [0.5, 1.0]
    velocity = np.random.default_rng(0).normal(size=m.nv)
    d.qvel[:] = velocity
    robot.set_dofs_velocity(torch.tensor(velocity))
    seen = {"rows": 99, "contacts": 0}

    def note():
        seen["rows"] = min(seen["rows"], d.ne)
        seen["contacts"] = max(seen["contacts"], len(robot.get_contacts()["position"]))

    assert _lockstep(m, d, scene, robot, 1000, note) < 1e-8
    assert seen["rows"] == {CONNECTS: 6, WELDS: 12}[path] and seen["contacts"] >= 4, seen
    held = _gaps(scene, robot)
    assert held[:model.n_body_eq].max() < 1e-3  # (a weld's turn rows are softer: the arm's palm turns 18°)
    assert held[model.n_body_eq:].max(initial=0.0) < 0.5


@pytest.mark.parametrize("path, what", [
    (CONNECTS, "velocity"), (CONNECTS, "mass"), (CONNECTS, "gravity"), (WELDS, "velocity"), (WELDS, "mass"),
    *(pytest.param(path, what, marks=pytest.mark.slow) for path, what in (
        (CONNECTS, "qpos"), (CONNECTS, "force"), (WELDS, "qpos"), (WELDS, "gravity"), (WELDS, "force")))])
def test_gradients_through_connects_and_welds_match_finite_differences(f64, path, what):
    """Every input the rows touch, 0.3 s from a fast start (the arm's points and frames pulled
    together, the pair landing: contacts); loss a fixed weighting of every link's pose. (Both
    assets' trees have the same joints.)"""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002, requires_grad=True))
    robot = scene.add_entity(gs.morphs.MJCF(file=path))
    scene.build()
    steps, dofs = 150, robot.n_dofs
    rng = np.random.default_rng(3)
    velocity = torch.tensor(rng.normal(0.0, 2.0, dofs))
    velocity[7:] *= 0.1  # (the pair's free roots gently: it lands)
    weights = torch.tensor(rng.normal(size=(robot.n_links, 7)))
    heavy = [k for k, link in enumerate(robot.links) if float(link.get_mass()) > 0]
    start_qpos = robot.get_qpos().detach().clone()
    start_qpos[0:4] = torch.tensor([0.98, 0.1, -0.1, 0.1], dtype=torch.float64)  # the arm's ball off its connect
    start_qpos[[11, 18]] -= 0.2  # the pair lower: it lands within the rollout
    start = {"qpos": start_qpos, "velocity": velocity, "mass": robot.get_links_mass().detach().clone()[heavy],
             "gravity": torch.tensor([0.5, -0.3, -9.81], dtype=torch.float64),
             "force": torch.tensor(rng.normal(0.0, 0.05, (steps, dofs)))}[what]
    seen = {"contacts": 0}

    def loss(x):
        scene.reset()
        robot.set_qpos(x if what == "qpos" else start_qpos)
        robot.set_dofs_velocity(x if what == "velocity" else velocity)
        if what == "mass":
            robot.set_links_mass(x, links_idx_local=heavy)
        scene.set_gravity(x if what == "gravity" else torch.tensor([0.0, 0.0, -9.81], dtype=torch.float64))
        for t in range(steps):
            if what == "force":
                robot.control_dofs_force(x[t])
            scene.step()
            seen["contacts"] = max(seen["contacts"], len(robot.get_contacts()["position"]))
        return (torch.cat([robot.get_links_pos(), robot.get_links_quat()], -1) * weights).sum()

    eps = tuple(10.0 * step for step in EPS) if what == "gravity" else EPS  # (gravity's scale: 10 m/s²)
    for seed in range(2):
        assert_converged(directional_errors(loss, start, seed, eps), f"{what}, direction {seed}")
    assert seen["contacts"] >= 2, seen


@pytest.mark.parametrize("path", [FOURBAR, WELDS])
def test_repeated_rollouts_give_bit_identical_connect_and_weld_gradients(f64, path):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002, requires_grad=True))
    robot = scene.add_entity(gs.morphs.MJCF(file=path))
    scene.build()
    velocity = np.random.default_rng(1).normal(0.0, 0.5, robot.n_dofs)

    def rollout():
        for _ in range(100):
            scene.step()
        return robot.get_qpos().sum()

    grads = repeated_gradients(scene, robot, velocity, rollout)
    assert torch.equal(grads[0], grads[1]) and bool(grads[0].abs().sum() > 0)


@pytest.mark.slow  # (its own constraint kernels, on the thread pool: 50 s of compiling)
def test_batched_welds_equal_single_envs_bitwise(f64):
    """On the thread pool (enough envs) and alone: the same bits, welds (their point rows are a
    connect's) and contacts included."""
    built = []
    for n_envs in (SERIAL_LINK_ENVS // 10 + 1, 0):
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002))
        built.append((scene, scene.add_entity(gs.morphs.MJCF(file=WELDS))))
        scene.build(n_envs=n_envs)
    (batched, robot_b), (single, robot_s) = built
    velocity = torch.tensor(np.random.default_rng(6).normal(0.0, 1.0, (batched.n_envs, robot_b.n_dofs)))
    robot_b.set_dofs_velocity(velocity)
    for _ in range(100):
        batched.step()
    for e in (0, batched.n_envs - 1):
        single.reset()
        robot_s.set_dofs_velocity(velocity[e])
        for _ in range(100):
            single.step()
        assert torch.equal(robot_b.get_qpos()[e], robot_s.get_qpos())


@pytest.mark.parametrize("path", [CONNECTS, WELDS])
def test_placed_connects_and_welds_hold_the_same_points(f64, path):
    """A morph placed with pos and quat moves every point and frame a connect or weld holds, those
    given in the world (a <worldbody> site) too: each gap and turn at build is the unplaced
    file's, and stays finite."""
    gaps = []
    for pos, euler in (((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)), ((1.0, 2.0, 0.5), (10.0, 0.0, 45.0))):
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002))
        robot = scene.add_entity(gs.morphs.MJCF(file=path, pos=pos, euler=euler))
        scene.build()
        gaps.append(_gaps(scene, robot))
        for _ in range(50):
            scene.step()
        assert bool(torch.isfinite(robot.get_qpos()).all())
    np.testing.assert_allclose(gaps[1], gaps[0], atol=1e-12)
    assert gaps[0][0] > 0.005  # (the arm starts a little off its hook: the file's site points differ)
    if path == WELDS:
        assert gaps[0][-2] > 0.05  # (and turned 6° from it)


@pytest.mark.parametrize("default, loaded", [('<equality active="false"/>', 0), ('<equality solref="0.05 1"/>', 1)])
def test_equality_defaults_are_read(f64, tmp_path, caplog, default, loaded):
    """MuJoCo's <default><equality> (every equality type's active, solref, solimp) applies to a
    connect: an inactive one is not loaded (said in a warning), a solref softens its rows."""
    path = tmp_path / "robot.xml"
    path.write_text(f'<mujoco><default>{default}</default><worldbody><body name="b"><joint name="j"/>'
                    f'<geom type="sphere" size="0.1"/></body></worldbody>'
                    f'<equality><connect body1="b" anchor="0.1 0 0"/></equality></mujoco>')
    scene = gs.Scene()
    with caplog.at_level("WARNING", logger="genesis_lite"):
        scene.add_entity(gs.morphs.MJCF(file=str(path)))
    scene.build()
    model = scene.sim.slots[0].solver.model
    assert model.n_body_eq == loaded
    said = " ".join(r.getMessage() for r in caplog.records)
    if loaded:
        assert "ignored" not in said and model.body_eq_sol[0, :2].tolist() == [0.05, 1.0], said
    else:
        assert "inactive: not loaded" in said, said


def _softened(path, tmp_path):
    """A copy of connects.xml or welds.xml whose equalities have their own solref and solimp
    (standard and direct forms, a partial solimp over <default><equality>'s), and a joint equality
    of a second hinge h2b added beside h2 (h2 follows it), as soft as its solref says."""
    text = open(path).read().replace("<equality>", '<default><equality solimp="0.8 0.9 0.02 0.4 3"/></default>'
                                                   '<equality><joint joint1="h2" joint2="h2b" solref="0.05 0.7"/>', 1)
    for plain, soft in (
            ('<joint name="h2" type="hinge" axis="0 1 0.3" damping="0.01"/>',
             '<joint name="h2" type="hinge" axis="0 1 0.3" damping="0.01"/><joint name="h2b" axis="1 0 0"/>'),
            ('<connect site1="tip" site2="hook"/>', '<connect site1="tip" site2="hook" solref="-900 -20"/>'),
            ('<weld site1="palm" site2="mount"', '<weld site1="palm" site2="mount" solimp="0.5 0.7"'),
            ('<connect body1="ball"', '<connect solref="0.04 1.5" body1="ball"'),
            ('<weld body1="lid"', '<weld solref="0.08 0.6" solimp="0.95" body1="lid"')):
        text = text.replace(plain, soft)
    file = tmp_path / "soft.xml"
    file.write_text(text)
    return str(file)


@pytest.mark.parametrize("path", [CONNECTS, WELDS])
def test_equalities_solref_and_solimp_soften_their_rows_as_mujocos(f64, tmp_path, path):
    """Each equality's solref and solimp (_softened) are read as MuJoCo's compiler reads them and
    soften its rows as in MuJoCo: 1 s beside MuJoCo 4 (Euler: free bodies turn) from the files'
    start, off their constraints, both solves to 1e-14: equal to round-off (measured 1.6e-12
    either file; with MuJoCo's tolerance, 3e-8)."""
    file = _softened(path, tmp_path)
    m, d, scene, robot = _pair(file, integrator="euler", tolerance=1e-14)
    m.opt.tolerance = 1e-14
    model = contact.with_row_softness(scene._rigid_solver.model, scene._rigid_solver.timeconst)
    ours = np.concatenate([model.eq_sol, model.body_eq_sol])
    theirs = np.concatenate([m.eq_solref, np.clip(m.eq_solimp, [1e-4, 1e-4, 0, 1e-4, 1], [0.9999, 0.9999, 1, 0.9999, 9])],
                            axis=1)
    assert sorted(map(tuple, ours)) == sorted(map(tuple, theirs)) and len(ours) == 3
    assert _lockstep(m, d, scene, robot, 500) < 1e-10


@pytest.mark.parametrize("path", [pytest.param(CONNECTS, marks=pytest.mark.slow), WELDS])
def test_gradients_through_soft_equalities_match_finite_differences(f64, tmp_path, path):
    """_softened's equalities, 0.3 s from a fast start: the gradient of every link's pose w.r.t. the
    initial velocities against central differences (the rows' softness in the reverse too)."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002, requires_grad=True),
                     rigid_options=gs.options.RigidOptions(tolerance=1e-14))
    robot = scene.add_entity(gs.morphs.MJCF(file=_softened(path, tmp_path)))
    scene.build()
    rng = np.random.default_rng(4)
    start, weights = torch.tensor(rng.normal(0.0, 1.0, robot.n_dofs)), torch.tensor(rng.normal(size=(robot.n_links, 7)))
    loss = pose_loss(scene, robot, weights, 150, robot.set_dofs_velocity)
    assert_converged(directional_errors(loss, start), f"soft equalities of {path}")


def test_a_weld_with_its_relpose_matches_mujoco(f64, tmp_path):
    """A free box welded to the world at a given relpose (not its start pose: it is pulled there),
    a slid body welded to it with an anchor, and a free capsule held by a ``fromto`` site (its z
    axis along the segment, as MuJoCo places it) on a world site: 0.6 s in both engines."""
    path = tmp_path / "robot.xml"
    path.write_text('<mujoco><worldbody><site name="w" pos="1 0 1.1" euler="0 80 5"/>'
                    '<body name="box" pos="0.1 0 1" euler="0 10 0"><freejoint/>'
                    '<geom type="box" size="0.1 0.2 0.05"/></body>'
                    '<body name="slider" pos="0 0.5 1"><joint name="s" type="slide" axis="0 1 0"/>'
                    '<geom type="sphere" size="0.05"/></body>'
                    '<body name="cap" pos="1 0 1"><freejoint/><geom type="capsule" fromto="0 0 0 0.2 0 0" size="0.03"/>'
                    '<site name="f" type="capsule" size="0.01" fromto="0 0 0 0.2 0 0.02"/></body></worldbody>'
                    '<equality><weld body1="box" relpose="0.05 0 1.02 0.99 0 0.1 0.05" torquescale="2"/>'
                    '<weld body1="slider" body2="box" anchor="0.02 0.4 0"/><weld site1="f" site2="w"/></equality>'
                    '</mujoco>')
    m, d, scene, robot = _pair(str(path), integrator="euler")
    assert _lockstep(m, d, scene, robot, 300) < 1e-10
    assert d.ne == 18


def test_the_world_as_body1_matches_mujoco(f64, tmp_path):
    """The world as body1 of equalities by bodies (MuJoCo's anchors then given in the world): a free
    box hung on a world point by a connect, a free box welded to the world at a given relpose (it
    is pulled there) and one welded where it starts (relpose left to MuJoCo's compiler: at qpos0),
    with an anchor; 0.6 s in both engines. Placed with a morph pose, the gaps at build are the
    unplaced file's."""
    path = tmp_path / "robot.xml"
    path.write_text('<mujoco><worldbody>'
                    '<body name="hung" pos="0 0 1" euler="0 20 0"><freejoint/><geom type="box" size="0.1 0.05 0.05"/>'
                    '</body>'
                    '<body name="pulled" pos="1 0 1"><freejoint/><geom type="box" size="0.1 0.2 0.05"/></body>'
                    '<body name="held" pos="0 1 1" euler="30 0 0"><freejoint/><geom type="capsule" size="0.03" '
                    'fromto="0 0 0 0.2 0 0"/></body></worldbody>'
                    '<equality><connect body1="world" body2="hung" anchor="0.1 0 1.05"/>'
                    '<weld body1="world" body2="pulled" relpose="1.05 0 1.02 0.99 0 0.1 0.05" torquescale="2"/>'
                    '<weld body1="world" body2="held" anchor="0.2 0 0"/></equality></mujoco>')
    m, d, scene, robot = _pair(str(path), integrator="euler")
    gaps = _gaps(scene, robot)
    assert gaps[[0, 2]].max() < 1e-15 and gaps[1] > 0.05  # (hung and held where they start; pulled not)
    assert _lockstep(m, d, scene, robot, 300) < 1e-10
    assert d.ne == 15
    placed = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002))
    placed_robot = placed.add_entity(gs.morphs.MJCF(file=str(path), pos=(1.0, 2.0, 0.5), euler=(10.0, 0.0, 45.0)))
    placed.build()
    np.testing.assert_allclose(_gaps(placed, placed_robot), gaps, atol=1e-12)
