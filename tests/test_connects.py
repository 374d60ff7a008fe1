"""Connect equalities (MJCF ``<equality><connect>``: a point of one body held on a point of
another, or of the world) against MuJoCo 4 and finite differences (float64).

assets/mjcf/fourbar.xml: a planar four-bar linkage, three hinges closed on the world by a connect.
assets/mjcf/connects.xml: a ball–hinge–ball arm whose tip site is held on a world site 1 cm
away at the start (site semantics), and a free box and a free sphere joined by a connect (body semantics: the sphere's
anchor, off its centre, and where that point is on the box at qpos0) that fall onto the floor.
MuJoCo 4's connect rows ask the gap's acceleration J q̈ + J̇ q̇ to follow the reference (its
mj_Jdotv): without the J̇ q̇ term ours drifted 6e-4 from MuJoCo in one step.
"""
import mujoco
import numpy as np
import pytest
import torch

import genesis_lite as gs
from genesis_lite.solvers.rigid.data import SERIAL_LINK_ENVS
from genesis_lite.utils.rotations import quat_to_mat
from tests.conftest import asset
from tests.fd_scan import assert_converged, directional_errors
from tests.test_mjcf import _lockstep, _pair

FOURBAR, CONNECTS = asset("mjcf", "fourbar.xml"), asset("mjcf", "connects.xml")


def _gaps(scene, robot):
    """|p1 − p2| (m) of each connect of the scene (its one robot's links' poses now)."""
    model = scene.sim.slots[0].solver.model
    pos, rot = robot.get_links_pos().detach().numpy(), quat_to_mat(robot.get_links_quat().detach()).numpy()
    out = []
    for (l1, l2), a1, a2 in zip(model.connect_link, model.connect_anchor[0::2], model.connect_anchor[1::2]):
        points = [a if l < 0 else pos[l - robot.link_start] + rot[l - robot.link_start] @ a
                  for l, a in ((l1, a1), (l2, a2))]
        out.append(np.linalg.norm(points[0] - points[1]))
    return np.array(out)


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


@pytest.mark.parametrize("cone", ["pyramidal", pytest.param("elliptic", marks=pytest.mark.slow)])
def test_connects_by_sites_and_bodies_match_mujoco(f64, cone):
    """Both connects, both bodies of the second free, landing on the floor (contacts): 2 s in both
    engines (MuJoCo's Euler integrator: free bodies turn). Measured 3e-11 (pyramidal) and 6e-11
    (elliptic): the solves' tolerance once contacts come."""
    m, d, scene, robot = _pair(CONNECTS, cone, plane=True, integrator="euler")
    model = scene.sim.slots[0].solver.model
    mujoco.mj_setConst(m, d)
    # body semantics: the second anchor is where the first is at qpos0, as MuJoCo's compiler puts it
    np.testing.assert_allclose(model.connect_anchor[2:4], m.eq_data[1, :6].reshape(2, 3), atol=1e-14)
    velocity = np.random.default_rng(0).normal(size=m.nv)
    d.qvel[:] = velocity
    robot.set_dofs_velocity(torch.tensor(velocity))
    seen = {"rows": 99, "contacts": 0}

    def note():
        seen["rows"] = min(seen["rows"], d.ne)
        seen["contacts"] = max(seen["contacts"], len(robot.get_contacts()["position"]))

    assert _lockstep(m, d, scene, robot, 1000, note) < 1e-8
    assert seen == {"rows": 6, "contacts": seen["contacts"]} and seen["contacts"] >= 4, seen
    assert _gaps(scene, robot).max() < 1e-3


@pytest.mark.parametrize("what", ["velocity", "mass", "gravity", *(pytest.param(what, marks=pytest.mark.slow)
                                                                   for what in ("qpos", "force"))])
def test_gradients_through_connects_match_finite_differences(f64, what):
    """Every input a connect's rows touch, 0.3 s from a fast start (the arm's points pulled
    together, the pair landing: contacts); loss a fixed weighting of every link's pose."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002, requires_grad=True))
    scene.add_entity(gs.morphs.Plane())
    robot = scene.add_entity(gs.morphs.MJCF(file=CONNECTS))
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

    for seed in range(2):
        assert_converged(directional_errors(loss, start, seed), f"{what}, direction {seed}")
    assert seen["contacts"] >= 2, seen


def test_repeated_rollouts_give_bit_identical_connect_gradients(f64):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002, requires_grad=True))
    robot = scene.add_entity(gs.morphs.MJCF(file=FOURBAR))
    scene.build()
    grads = []
    for _ in range(2):
        scene.reset()
        start = torch.tensor([1.0, -0.5, 0.3], dtype=torch.float64, requires_grad=True)
        robot.set_dofs_velocity(start)
        for _ in range(100):
            scene.step()
        robot.get_qpos().sum().backward()
        grads.append(start.grad)
    assert torch.equal(grads[0], grads[1]) and bool(grads[0].abs().sum() > 0)


def test_batched_connects_equal_single_envs_bitwise(f64):
    """On the thread pool (enough envs) and alone: the same bits, connects and contacts included."""
    built = []
    for n_envs in (SERIAL_LINK_ENVS // 10 + 1, 0):
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002))
        scene.add_entity(gs.morphs.Plane())
        built.append((scene, scene.add_entity(gs.morphs.MJCF(file=CONNECTS))))
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


def test_placed_connects_hold_the_same_points(f64):
    """A morph placed with pos and quat moves every point a connect holds, those given in the world
    (a <worldbody> site) too: each gap at build is the unplaced file's, and stays finite."""
    gaps = []
    for pos, euler in (((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)), ((1.0, 2.0, 0.5), (0.0, 0.0, 45.0))):
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002))
        robot = scene.add_entity(gs.morphs.MJCF(file=CONNECTS, pos=pos, euler=euler))
        scene.build()
        gaps.append(_gaps(scene, robot))
        for _ in range(50):
            scene.step()
        assert bool(torch.isfinite(robot.get_qpos()).all())
    np.testing.assert_allclose(gaps[1], gaps[0], atol=1e-12)
    assert gaps[0][0] > 0.005  # (the arm starts a little off its hook: the file's site points differ)


@pytest.mark.parametrize("default, loaded", [('<equality active="false"/>', 0), ('<equality solref="0.05 1"/>', 1)])
def test_equality_defaults_are_read(f64, tmp_path, caplog, default, loaded):
    """MuJoCo's <default><equality> (every equality type's active, solref, solimp) applies to a
    connect: an inactive one is not loaded, a solref is said to be ignored."""
    path = tmp_path / "robot.xml"
    path.write_text(f'<mujoco><default>{default}</default><worldbody><body name="b"><joint name="j"/>'
                    f'<geom type="sphere" size="0.1"/></body></worldbody>'
                    f'<equality><connect body1="b" anchor="0.1 0 0"/></equality></mujoco>')
    scene = gs.Scene()
    with caplog.at_level("WARNING", logger="genesis_lite"):
        scene.add_entity(gs.morphs.MJCF(file=str(path)))
    scene.build()
    assert scene.sim.slots[0].solver.model.n_connect == loaded
    said = " ".join(r.getMessage() for r in caplog.records)
    assert ("inactive: not loaded" if not loaded else "<equality><connect solref>") in said, said
