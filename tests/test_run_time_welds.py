"""Welds made at run time (Genesis's ``scene.sim.rigid_solver.add_weld_constraint`` /
``delete_weld_constraint``; genesis_lite/rigid_solver.py) against MuJoCo 4 and finite differences
(float64).

MuJoCo's reference: the same file with a weld equality between the two bodies, inactive at first;
when ours makes the weld, MuJoCo's gets the same data (link 1's origin as the anchor on body 2,
the two bodies' relative turn as relpose, torquescale 1, solref (2 h, 1): Genesis's weld) and is
switched on (``d.eq_active``), and off when ours deletes it.
"""
import mujoco
import numpy as np
import pytest
import torch

import genesis_lite as gs
from genesis_lite.solvers.core import InvalidInputError
from tests.fd_scan import assert_converged, directional_errors, repeated_gradients

BODIES = """<mujoco><option timestep="0.002"/><worldbody>{floor}
<body name="a" pos="0 0 0.3"><freejoint/><geom type="box" size="0.1 0.1 0.1"/></body>
<body name="b" pos="0.05 0.02 0.6" euler="10 20 30"><freejoint/><geom type="box" size="0.05 0.08 0.05"/></body>
<body name="arm" pos="0.6 0 0.5"><joint name="hinge" axis="0 1 0"/><geom type="capsule" fromto="0 0 0 0.2 0 0"
 size="0.03"/></body></worldbody>{equality}</mujoco>"""
FLOOR = '<geom name="floor" type="plane" size="0 0 1"/>'


def _scenes(tmp_path, contact=True, cone="pyramidal", requires_grad=False, n_envs=0, slots=2):
    """(MuJoCo model, data, our scene, our entity) of two free boxes and a hinged arm (on a floor,
    or without collisions), MuJoCo's with an inactive weld between the boxes."""
    path = tmp_path / "bodies.xml"
    path.write_text(BODIES.format(floor=FLOOR if contact else "", equality=""))
    m = mujoco.MjModel.from_xml_string(BODIES.format(
        floor=FLOOR if contact else "", equality='<equality><weld body1="a" body2="b" active="false"/></equality>'))
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER
    m.opt.cone = {"pyramidal": mujoco.mjtCone.mjCONE_PYRAMIDAL, "elliptic": mujoco.mjtCone.mjCONE_ELLIPTIC}[cone]
    if not contact:
        m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002, requires_grad=requires_grad),
                     rigid_options=gs.options.RigidOptions(enable_mujoco_compatibility=True, friction_cone=cone,
                                                           max_dynamic_constraints=slots, enable_collision=contact))
    robot = scene.add_entity(gs.morphs.MJCF(file=str(path)))
    scene.build(n_envs=n_envs)
    return m, mujoco.MjData(m), scene, robot


def _weld_in_mujoco(m, d):
    """Switch MuJoCo's weld on with Genesis's data, taken where the bodies are now."""
    mujoco.mj_kinematics(m, d)
    turn = np.zeros(4)
    mujoco.mju_mulQuat(turn, d.xquat[1] * [1, -1, -1, -1], d.xquat[2])
    m.eq_data[0, :11] = [*d.xmat[2].reshape(3, 3).T @ (d.xpos[1] - d.xpos[2]), 0.0, 0.0, 0.0, *turn, 1.0]
    m.eq_solref[0] = [2 * m.opt.timestep, 1.0]
    d.eq_active[0] = 1


@pytest.mark.parametrize("contact, cone", [(True, "pyramidal"), (False, "pyramidal"),
                                           pytest.param(True, "elliptic", marks=pytest.mark.slow)])
def test_a_weld_made_and_deleted_at_run_time_matches_mujoco(f64, tmp_path, contact, cone):
    """From random velocities: the boxes welded at step 100 (mid-air, turned apart), unwelded at
    step 300 (the pair given in the other order), 0.8 s in both engines, landing on the floor or
    without collisions (a scene whose step is one launch until a weld needs the constraint stage):
    measured 2.6e-13."""
    m, d, scene, robot = _scenes(tmp_path, contact, cone)
    velocity = np.random.default_rng(0).normal(size=m.nv)
    d.qvel[:] = velocity
    robot.set_dofs_velocity(torch.tensor(velocity))
    a, b = robot.get_link("a").idx, robot.get_link("b").idx
    worst, rows = 0.0, []
    for t in range(400):
        if t == 100:
            _weld_in_mujoco(m, d)
            scene.sim.rigid_solver.add_weld_constraint(a, b)
        if t == 300:
            d.eq_active[0] = 0
            scene.sim.rigid_solver.delete_weld_constraint(b, a)
        mujoco.mj_step(m, d)
        scene.step()
        rows.append(d.ne)
        worst = max(worst, np.abs(robot.get_qpos().numpy() - d.qpos).max(),
                    np.abs(robot.get_dofs_velocity().numpy() - d.qvel).max())
    assert worst < 1e-10
    assert rows[99] == 0 and set(rows[100:300]) == {6} and rows[300] == 0
    assert (d.ncon > 0) == contact


def test_welds_per_env_and_batched_equal_single_envs_bitwise(f64, tmp_path):
    """Three envs, the boxes welded in envs 0 and 2 only, env 2's welded twice over (the arm to
    box b too, then box a's weld deleted: the arm's moves up a slot): each env steps as a single
    scene given the same welds, bit for bit."""
    velocity = torch.tensor(np.random.default_rng(5).normal(size=(3, 13)))
    _, _, batched, robot = _scenes(tmp_path, n_envs=3)
    robot.set_dofs_velocity(velocity)
    singles = []
    for e in range(3):
        _, _, scene, single = _scenes(tmp_path)
        single.set_dofs_velocity(velocity[e])
        singles.append((scene, single))
    a, b, arm = (robot.get_link(name).idx for name in ("a", "b", "arm"))
    for t in range(200):
        if t == 50:
            batched.sim.rigid_solver.add_weld_constraint(a, b, envs_idx=[0, 2])
            batched.sim.rigid_solver.add_weld_constraint(b, arm, envs_idx=[2])
            for e in (0, 2):
                singles[e][0].sim.rigid_solver.add_weld_constraint(a, b)
            singles[2][0].sim.rigid_solver.add_weld_constraint(b, arm)
        if t == 120:
            batched.sim.rigid_solver.delete_weld_constraint(a, b, envs_idx=[2])
            singles[2][0].sim.rigid_solver.delete_weld_constraint(a, b)
        batched.step()
        for scene, _ in singles:
            scene.step()
    for e, (_, single) in enumerate(singles):
        assert torch.equal(robot.get_qpos()[e], single.get_qpos())
        assert torch.equal(robot.get_dofs_velocity()[e], single.get_dofs_velocity())


def _rollout(scene, robot, steps, weld_at):
    """A rollout's loss: from the scene's reset (which clears the welds), the boxes welded at step
    ``weld_at``."""
    a, b = robot.get_link("a").idx, robot.get_link("b").idx
    for t in range(steps):
        if t == weld_at:
            scene.sim.rigid_solver.add_weld_constraint(a, b)
        scene.step()
    return (robot.get_qpos() * torch.linspace(-1.0, 1.0, robot.n_qs, dtype=torch.float64)).sum()


@pytest.mark.parametrize("what", ["velocity", "mass", pytest.param("gravity", marks=pytest.mark.slow)])
def test_gradients_through_a_weld_made_mid_rollout_match_finite_differences(f64, tmp_path, what):
    """120 steps, the boxes welded at step 40 (the backward replays the steps before it without the
    weld and those after with it), landing on the floor: the gradient of a weighting of the final
    qpos against central differences."""
    _, _, scene, robot = _scenes(tmp_path, requires_grad=True)
    velocity = torch.tensor(np.random.default_rng(2).normal(0.0, 1.0, robot.n_dofs))
    heavy = [k for k, link in enumerate(robot.links) if float(link.get_mass()) > 0]  # (not the static links)
    start = {"velocity": velocity, "mass": robot.get_links_mass().detach().clone()[heavy],
             "gravity": torch.tensor([0.3, -0.2, -9.81], dtype=torch.float64)}[what]

    def loss(x):
        scene.reset()
        robot.set_dofs_velocity(x if what == "velocity" else velocity)
        if what == "mass":
            robot.set_links_mass(x, links_idx_local=heavy)
        if what == "gravity":
            scene.set_gravity(x)
        return _rollout(scene, robot, 120, 40)

    for seed in range(2):
        assert_converged(directional_errors(loss, start, seed), f"{what}, direction {seed}")


def test_repeated_rollouts_give_bit_identical_run_time_weld_gradients(f64, tmp_path):
    _, _, scene, robot = _scenes(tmp_path, requires_grad=True)
    velocity = np.random.default_rng(4).normal(0.0, 1.0, robot.n_dofs)
    grads = repeated_gradients(scene, robot, velocity, lambda: _rollout(scene, robot, 100, 30))
    assert torch.equal(grads[0], grads[1]) and bool(grads[0].abs().sum() > 0)


def test_bad_welds_are_named(f64, tmp_path):
    _, _, scene, robot = _scenes(tmp_path, slots=1)
    solver = scene.sim.rigid_solver
    a, b, arm = (robot.get_link(name).idx for name in ("a", "b", "arm"))
    world = robot.get_link("world:arm").idx
    floor = robot.get_link("world").idx
    with pytest.raises(InvalidInputError, match=r"expected two different links, got link \d+ twice"):
        solver.add_weld_constraint(a, a)
    with pytest.raises(InvalidInputError, match=r"are both welded to the world; expected one that moves"):
        solver.add_weld_constraint(world, floor)
    for bad in (99, -1, [a, b], 1.0):
        with pytest.raises(InvalidInputError, match=r"argument 'link1_idx' must be one link index in \[0, \d+\) "
                                                    r"\(a link's idx; the world is not a link\)"):
            solver.add_weld_constraint(bad, a)
    with pytest.raises(InvalidInputError, match=r"argument 'envs_idx' must be None in a scene built with n_envs=0"):
        solver.add_weld_constraint(a, b, envs_idx=[0])
    with pytest.raises(InvalidInputError, match=r"links \(\d+, \d+\) are not welded in envs \[0\]"):
        solver.delete_weld_constraint(a, b)
    solver.add_weld_constraint(a, b)
    with pytest.raises(InvalidInputError, match=r"are already welded in envs \[0\]"):
        solver.add_weld_constraint(b, a)
    with pytest.raises(InvalidInputError, match=r"no free weld slot in envs \[0\]: expected fewer than "
                                                r"RigidOptions\(max_dynamic_constraints=1\) welds there"):
        solver.add_weld_constraint(a, arm)
    _, _, plain, _ = _scenes(tmp_path, slots=0)
    with pytest.raises(InvalidInputError, match=r"the scene has no run-time weld slots; expected "
                                                r"RigidOptions\(max_dynamic_constraints=n\)"):
        plain.sim.rigid_solver.add_weld_constraint(a, b)
    with pytest.raises(InvalidInputError, match=r"'max_dynamic_constraints' must be an integer >= 0, got -1"):
        gs.options.RigidOptions(max_dynamic_constraints=-1)


def test_a_reset_clears_the_welds_of_the_envs_it_resets(f64, tmp_path):
    """As Genesis's: scene.reset() clears every env's welds, reset(envs_idx) those envs' only; an
    empty envs_idx welds nothing; deleting a weld moves the env's last into its slot (Genesis's)."""
    _, _, scene, robot = _scenes(tmp_path, n_envs=2, slots=3)
    solver = scene.sim.rigid_solver
    a, b, arm = (robot.get_link(name).idx for name in ("a", "b", "arm"))
    solver.add_weld_constraint(a, b, envs_idx=[])
    assert scene.sim.inputs(scene._rigid_solver)["dyn_welds"][:, 0].tolist() == [0.0, 0.0]
    solver.add_weld_constraint(a, b)
    solver.add_weld_constraint(b, arm)
    solver.add_weld_constraint(a, arm, envs_idx=[1])
    solver.delete_weld_constraint(b, a, envs_idx=[1])
    table = scene.sim.inputs(scene._rigid_solver)["dyn_welds"]
    assert table[:, 0].tolist() == [2.0, 2.0]
    assert table[1, [1, 2, 17, 18]].tolist() == [a, arm, b, arm]  # (the last, a–arm, in the gap)
    scene.reset(envs_idx=[0])
    assert scene.sim.inputs(scene._rigid_solver)["dyn_welds"][:, 0].tolist() == [0.0, 2.0]
    solver.add_weld_constraint(a, b, envs_idx=[0])  # (free again in env 0)
    scene.reset()
    assert scene.sim.inputs(scene._rigid_solver)["dyn_welds"][:, 0].tolist() == [0.0, 0.0]
