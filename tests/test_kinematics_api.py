"""entity.get_jacobian and entity.inverse_kinematics (genesis_lite/entities/kinematics.py).

The Jacobian against MuJoCo 4's mj_jac at random poses and points (a fixed arm, a free-base
quadruped, prismatic and mimic joints, a batch), and its gradient against finite differences;
inverse kinematics reaching poses the arm can reach, with its options, leaving the scene's state
and its next steps as they were.
"""
import mujoco
import numpy as np
import pytest
import torch

import genesis_lite as gs
from genesis_lite.utils.rotations import quat_to_mat
from tests.conftest import asset, pybullet
from tests.mujoco_ref import bare_spec

KUKA = pybullet("kuka_iiwa", "model.urdf")
ROBOTS = {"kuka": (KUKA, True), "quadruped": (asset("quadruped.urdf"), False),
          "gripper": (asset("mimic_gripper.urdf"), True)}


def _mujoco(path, fixed):
    model = bare_spec(path, free_base=not fixed).compile()
    return model, mujoco.MjData(model)


def _scene(path, fixed, n_envs=0, requires_grad=False):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=requires_grad),
                     rigid_options=gs.options.RigidOptions(enable_collision=False), show_viewer=False)
    robot = scene.add_entity(gs.morphs.URDF(file=path, fixed=fixed))
    scene.build(n_envs=n_envs)
    return scene, robot


def _random_qpos(rng, model):
    q = rng.uniform(-1.0, 1.0, model.nq)
    if model.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE:
        q[3:7] /= np.linalg.norm(q[3:7])
    return q


@pytest.mark.parametrize("name", ROBOTS)
def test_jacobian_matches_mujoco(f64, name):
    """Every link, a random point on it, two random poses in a batch of two: ≤ 1e-12."""
    path, fixed = ROBOTS[name]
    model, data = _mujoco(path, fixed)
    _, robot = _scene(path, fixed, n_envs=2)
    rng = np.random.default_rng(1)
    poses = np.array([_random_qpos(rng, model) for _ in range(2)])
    robot.set_qpos(torch.tensor(poses))
    compared = 0
    for link in robot.links:
        point = rng.normal(size=3) * 0.1
        ours = robot.get_jacobian(link, torch.tensor(point)).numpy()
        assert ours.shape == (2, 6, robot.n_dofs)
        if link.name not in [model.body(b).name for b in range(model.nbody)]:
            continue  # a fixed base: MuJoCo fused it into the world
        body = model.body(link.name).id
        for e in range(2):
            data.qpos[:] = poses[e]
            mujoco.mj_kinematics(model, data)
            mujoco.mj_comPos(model, data)
            jacp, jacr = np.zeros((3, model.nv)), np.zeros((3, model.nv))
            mujoco.mj_jac(model, data, jacp, jacr, data.xpos[body] + data.xmat[body].reshape(3, 3) @ point, body)
            np.testing.assert_allclose(ours[e], np.vstack([jacp, jacr]), atol=1e-12)
            compared += 1
    assert compared >= 2 * 4


def test_jacobian_is_differentiable(f64):
    """d Σ W ⊙ J(q0) / dq0 through a step, against central differences."""
    scene, robot = _scene(KUKA, True, requires_grad=True)
    rng = np.random.default_rng(2)
    q0 = torch.tensor(rng.uniform(-1, 1, robot.n_dofs))
    weights = torch.tensor(rng.normal(size=(6, robot.n_dofs)))
    direction = torch.tensor(rng.normal(size=robot.n_dofs))

    def loss(q):
        scene.reset()
        robot.set_dofs_position(q)
        scene.step()
        return (robot.get_jacobian(robot.links[-1], torch.tensor([0.0, 0.05, 0.1])) * weights).sum()

    x = q0.clone().requires_grad_(True)
    loss(x).backward()
    with torch.no_grad():
        numeric = (loss(q0 + 1e-6 * direction) - loss(q0 - 1e-6 * direction)) / 2e-6
    assert abs(float(x.grad @ direction) - float(numeric)) <= 1e-7 * float(x.grad.norm())


def _reachable(robot, rng, link):
    """A pose of ``link`` the arm reaches at a random qpos (then put back to zero)."""
    robot.set_qpos(torch.tensor(rng.uniform(-1.0, 1.0, robot.n_qs)))
    pos, quat = link.get_pos().clone(), link.get_quat().clone()
    robot.set_qpos(torch.zeros(robot.n_qs))
    return pos, quat


def _reachable_targets(n_envs, seed):
    """(KUKA, its end effector, (n_envs, 3) positions and (n_envs, 4) quaternions it reaches)."""
    _, robot = _scene(KUKA, True, n_envs=n_envs)
    rng = np.random.default_rng(seed)
    ee = robot.links[-1]
    targets = [_reachable(robot, rng, ee) for _ in range(n_envs)]
    pos = torch.stack([t[0][k] for k, t in enumerate(targets)])
    quat = torch.stack([t[1][k] for k, t in enumerate(targets)])
    return robot, ee, pos, quat


def test_inverse_kinematics_reaches_poses(f64):
    """Pose targets the KUKA can reach, from its zero pose: within Genesis's tolerances, in its
    limits, the scene's state unchanged; batched targets per env; a position-only target."""
    robot, ee, pos, quat = _reachable_targets(3, seed=3)
    before = robot.get_qpos().clone()
    qpos, error = robot.inverse_kinematics(ee, pos=pos, quat=quat, return_error=True)
    assert isinstance(qpos, gs.Tensor) and isinstance(error, gs.Tensor)  # (SPEC §2; the error was a plain one)
    assert torch.equal(robot.get_qpos(), before)
    assert (error[:, :3].norm(dim=1) <= 5e-4).all() and (error[:, 3:].norm(dim=1) <= 5e-3).all()
    lower, upper = (torch.tensor(robot._solver.model.dof_lower[:7]), torch.tensor(robot._solver.model.dof_upper[:7]))
    assert ((qpos >= lower) & (qpos <= upper)).all()
    robot.set_qpos(qpos)
    np.testing.assert_allclose((ee.get_pos() - pos).norm(dim=1), error[:, :3].norm(dim=1), atol=1e-12)
    point = torch.tensor([0.0, 0.0, 0.1], dtype=torch.float64)
    only_pos = robot.inverse_kinematics(ee, pos=pos[0], local_point=point, envs_idx=[1])
    robot.set_qpos(only_pos, envs_idx=[1])
    tip = ee.get_pos()[1] + gs_rotate(ee.get_quat()[1], point)
    assert (tip - pos[0]).norm() <= 5e-4


def test_inverse_kinematics_from_a_start_at_the_target_orientation(f64):
    """Envs that start with the target's orientation exactly (its error 0) and 0.1 m off converge
    (Genesis's rule: the best is a sample's last qpos, never the start; taking the start as the
    first best kept it for ever wherever no later iterate's rotation error was as small: env 0
    came back unmoved, 0.1 m off, beside env 1 converged)."""
    scene, robot = _scene(KUKA, True, n_envs=2)
    ee = robot.links[-1]
    robot.set_qpos(torch.tensor([[0.1, 0.5, 0.0, -1.0, 0.0, 0.8, 0.0], [0.2, 0.4, 0.1, -1.1, 0.0, 0.9, 0.1]],
                                dtype=torch.float64))
    pos, quat = ee.get_pos().clone(), ee.get_quat().clone()
    pos[:, 1] += 0.1
    qpos, error = robot.inverse_kinematics(ee, pos=pos, quat=quat, return_error=True)
    assert (error[:, :3].norm(dim=1) <= 5e-4).all() and (error[:, 3:].norm(dim=1) <= 5e-3).all(), error


def test_inverse_kinematics_of_several_links(f64):
    """inverse_kinematics_multilink: the elbow's position and the flange's pose of a pose the KUKA
    reaches, at once; errors per link."""
    _, robot = _scene(KUKA, True)
    rng = np.random.default_rng(6)
    elbow, flange = robot.links[4], robot.links[-1]
    robot.set_qpos(torch.tensor(rng.uniform(-1.0, 1.0, 7)))
    goals = elbow.get_pos().clone(), flange.get_pos().clone(), flange.get_quat().clone()
    robot.set_qpos(torch.zeros(7))
    qpos, error = robot.inverse_kinematics_multilink([elbow, flange], poss=[goals[0], goals[1]],
                                                     quats=[None, goals[2]], return_error=True)
    assert error.shape == (2, 6) and (error[:, :3].norm(dim=1) <= 5e-4).all() and error[1, 3:].norm() <= 5e-3
    robot.set_qpos(qpos)
    assert (elbow.get_pos() - goals[0]).norm() <= 5e-4 and (flange.get_pos() - goals[1]).norm() <= 5e-4
    with pytest.raises(gs.InvalidInputError, match=r"argument 'poss' expected one entry per link \(2\), got 1"):
        robot.inverse_kinematics_multilink([elbow, flange], poss=[goals[0]])


def gs_rotate(quat, vector):
    """quat (4,) applied to vector (3,)."""
    return quat_to_mat(quat) @ vector


def test_inverse_kinematics_moves_only_the_dofs_given(f64):
    _, robot = _scene(KUKA, True)
    rng = np.random.default_rng(4)
    start = torch.tensor(rng.uniform(-0.5, 0.5, 7))
    robot.set_qpos(start)
    target = robot.links[-1].get_pos() + torch.tensor([0.05, -0.03, 0.02])
    qpos = robot.inverse_kinematics(robot.links[-1], pos=target, dofs_idx_local=[0, 1, 3])
    assert torch.equal(qpos[[2, 4, 5, 6]], start[[2, 4, 5, 6]]) and not torch.equal(qpos, start)


def test_inverse_kinematics_aligns_one_axis(f64):
    """rot_mask with one axis: that axis of the link turns onto the target's (Genesis's rule; a
    rotation about it is free), here the flange's z pointing down; two axes raise."""
    _, robot = _scene(KUKA, True)
    flange = robot.links[-1]
    down = torch.tensor([0.0, 1.0, 0.0, 0.0], dtype=torch.float64)  # z → −z
    target = torch.tensor([0.45, 0.1, 0.5], dtype=torch.float64)
    qpos, error = robot.inverse_kinematics(flange, pos=target, quat=down, rot_mask=[False, False, True],
                                           return_error=True)
    robot.set_qpos(qpos)
    z_axis = quat_to_mat(flange.get_quat())[:, 2]
    assert float(z_axis[2]) < -np.cos(5e-3) and (flange.get_pos() - target).norm() <= 5e-4
    assert float(error[5]) == 0.0  # (the rotation about the aligned axis does not count)
    with pytest.raises(gs.InvalidInputError, match="'rot_mask' must align no axis, one or all three"):
        robot.inverse_kinematics(flange, quat=down, rot_mask=[True, True, False])


@pytest.mark.parametrize("respect_joint_limit", [True, False])
def test_inverse_kinematics_moves_only_the_path_to_the_link(f64, respect_joint_limit):
    """A Panda reaching for an unreachable point with its hand: its fingers (not on the path to
    the hand) stay, limits respected or not; a dof outside dofs_idx_local that starts past its
    limit stays there too, and the others still reach a reachable target."""
    _, robot = _scene(pybullet("franka_panda", "panda.urdf"), True)
    start = robot.get_qpos().clone()
    start[-2:] = torch.tensor([0.01, 0.02])
    robot.set_qpos(start)
    qpos = robot.inverse_kinematics(robot.get_link("panda_link7"), pos=[3.0, 0.0, 0.5],
                                    respect_joint_limit=respect_joint_limit, max_samples=3)
    assert torch.isfinite(qpos).all() and torch.equal(qpos[-2:], start[-2:])
    _, kuka = _scene(KUKA, True)
    beyond = torch.tensor([0.2, 0.6, 0.1, -1.0, 0.3, 0.5, 3.2], dtype=torch.float64)  # joint 6's limit: ±3.05
    kuka.set_qpos(beyond)
    goal = kuka.links[-1].get_pos() + torch.tensor([0.02, 0.02, -0.02], dtype=torch.float64)
    qpos, error = kuka.inverse_kinematics(kuka.links[-1], pos=goal, dofs_idx_local=[0, 1, 2, 3, 4, 5],
                                          respect_joint_limit=respect_joint_limit, return_error=True)
    assert float(qpos[6]) == 3.2 and error[:3].norm() <= 5e-4


def test_inverse_kinematics_draws_restarts_within_a_one_sided_limit(f64):
    """A revolute joint limited on one side (set_dofs_limit with an infinite bound): the restarts are
    drawn within a turn of its limit, so the joint reaches the target's angle a turn away, inside the
    limit (drawn in [−π, π], a restart near the angle outside the limit was solved and returned)."""
    _, robot = _scene(KUKA, True)
    ee = robot.links[-1]
    reaching = torch.tensor([1.0, 0.6, 0.0, -1.0, 0.0, 0.5, 0.0], dtype=torch.float64)
    robot.set_qpos(reaching)
    target = ee.get_pos().clone()
    robot.set_qpos(torch.zeros(7, dtype=torch.float64))
    robot.set_dofs_limit([-np.inf], [0.2], dofs_idx_local=[0])
    start = reaching.clone()
    start[0] = 0.0
    qpos, error = robot.inverse_kinematics(ee, pos=target, init_qpos=start, dofs_idx_local=[0], pos_tol=0.05,
                                           return_error=True)
    assert float(qpos[0]) <= 0.2 and float(error[:3].norm()) <= 0.05
    assert abs(float(qpos[0]) - (1.0 - 2.0 * np.pi)) < 0.2


def test_inverse_kinematics_without_limits_runs_every_sample_from_the_last_ones_end(f64):
    """respect_joint_limit=False: no restart is drawn, and, as Genesis's, each of max_samples
    samples goes on from where the last ended (it ran one sample: max_samples ignored). Pose
    targets the KUKA reaches from its zero pose only in more steps of max_step_size 0.05 than one
    sample's 20."""
    robot, ee, pos, quat = _reachable_targets(4, seed=5)

    def solve(samples):
        _, error = robot.inverse_kinematics(ee, pos=pos, quat=quat, respect_joint_limit=False, max_step_size=0.05,
                                            max_samples=samples, return_error=True)
        return (error[:, :3].norm(dim=1) <= 5e-4) & (error[:, 3:].norm(dim=1) <= 5e-3)

    assert not solve(1).any() and solve(50).all()


@pytest.mark.parametrize("option, value, words", [
    ("max_samples", 0, "'max_samples' must be an integer >= 1"),
    ("max_solver_iters", -3, "'max_solver_iters' must be an integer >= 0"),
    ("damping", 0.0, "'damping' must be a finite number > 0"),
    ("damping", float("nan"), "'damping' must be a finite number > 0"),
    ("max_step_size", -1.0, "'max_step_size' must be a finite number > 0"),
    ("pos_tol", -1e-3, "'pos_tol' must be a finite number >= 0"),
    ("pos_mask", [1, 1], "'pos_mask' must be 3 booleans"),
    ("respect_joint_limit", "no", "'respect_joint_limit' must be a bool"),
    ("dofs_idx_local", [], "'dofs_idx_local' must name at least one dof"),
])
def test_inverse_kinematics_checks_its_options(f64, option, value, words):
    _, robot = _scene(KUKA, True)
    with pytest.raises(gs.InvalidInputError, match=words):
        robot.inverse_kinematics(robot.links[-1], pos=[0.4, 0.0, 0.6], **{option: value})


def test_inverse_kinematics_keeps_the_next_steps(f64):
    """A solve between steps of a scene with constraint rows (a box resting on the plane, limits)
    leaves the steps after it as they were, bit for bit (the trial poses' uploads keep the
    constraint solve's warm start)."""
    def run(solve):
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01), show_viewer=False)
        scene.add_entity(gs.morphs.Plane())
        box = scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(1.0, 0.0, 0.06)))
        robot = scene.add_entity(gs.morphs.URDF(file=KUKA, fixed=True))
        scene.build()
        box.set_dofs_velocity(torch.tensor([0.3, 0.1, 0.0, 0.0, 0.0, 1.0]))
        for step in range(10):
            if solve and step == 5:
                robot.inverse_kinematics(robot.links[-1], pos=torch.tensor([0.3, 0.2, 0.8]))
            scene.step()
        return box.get_dofs_velocity()
    assert torch.equal(run(True), run(False))


def test_bad_arguments_raise(f64):
    scene = gs.Scene(show_viewer=False)
    robot = scene.add_entity(gs.morphs.URDF(file=KUKA, fixed=True))
    other = scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(1.0, 0.0, 0.06)))
    scene.build()
    with pytest.raises(gs.InvalidInputError, match="argument 'link' must be one of this entity's links"):
        robot.get_jacobian(other.links[0])
    with pytest.raises(gs.InvalidInputError, match="'local_point' must hold 3 numbers"):
        robot.get_jacobian(robot.links[-1], [0.0, 1.0])
    with pytest.raises(gs.InvalidInputError, match="expected a target 'pos' or 'quat', got neither"):
        robot.inverse_kinematics(robot.links[-1])
    with pytest.raises(gs.InvalidInputError, match="'quat' must hold non-zero quaternions"):
        robot.inverse_kinematics(robot.links[-1], quat=[0.0, 0.0, 0.0, 0.0])
    fixed_box = gs.Scene(show_viewer=False)
    static = fixed_box.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), fixed=True))
    fixed_box.build()
    with pytest.raises(gs.InvalidInputError, match="get_jacobian expected an entity with dofs"):
        static.get_jacobian(static.links[0])
    with pytest.raises(gs.InvalidInputError, match="'init_qpos' must hold non-zero quaternions"):
        other.inverse_kinematics(other.links[0], pos=[0.0, 0.0, 0.5], init_qpos=torch.zeros(7))


def test_inverse_kinematics_of_many_envs_is_each_envs_own(f64):
    """300 envs (rows on the thread pool) each solve their own reachable pose as that env alone does
    (one row, on the calling thread), bit for bit; an env given twice (solved one row after the
    other, on one frame) solves both of its targets, each as alone."""
    scene, robot = _scene(KUKA, True, n_envs=300)
    rng = np.random.default_rng(8)
    ee = robot.links[-1]
    robot.set_qpos(torch.tensor(rng.uniform(-1.0, 1.0, (300, 7))))
    pos, quat = ee.get_pos().clone(), ee.get_quat().clone()
    robot.set_qpos(torch.zeros(300, 7, dtype=torch.float64))
    qpos, error = robot.inverse_kinematics(ee, pos=pos, quat=quat, return_error=True)
    assert (error[:, :3].norm(dim=1) <= 5e-4).all() and (error[:, 3:].norm(dim=1) <= 5e-3).all()
    for env in (0, 151, 299):
        alone = robot.inverse_kinematics(ee, pos=pos[env], quat=quat[env], envs_idx=[env])
        assert torch.equal(alone[0], qpos[env])
    twice = robot.inverse_kinematics(ee, pos=pos[[3, 4]], quat=quat[[3, 4]], envs_idx=[5, 5])
    for row, goal in enumerate((3, 4)):
        assert torch.equal(twice[row], robot.inverse_kinematics(ee, pos=pos[goal], quat=quat[goal], envs_idx=[5])[0])


def test_inverse_kinematics_mid_rollout_keeps_the_gradient(f64):
    """A solve between steps of a differentiable rollout (its trial poses in the getters' frame)
    leaves the loss and its gradient in the initial velocities as without it, bit for bit."""
    scene, robot = _scene(KUKA, True, requires_grad=True)
    ee = robot.links[-1]

    def run(solve):
        scene.reset()
        v0 = torch.tensor([0.3, -0.2, 0.1, 0.4, -0.1, 0.2, 0.3], dtype=torch.float64, requires_grad=True)
        robot.set_dofs_velocity(v0)
        for step in range(8):
            if solve and step == 4:
                robot.inverse_kinematics(ee, pos=torch.tensor([0.3, 0.2, 0.8]))
            scene.step()
        loss = (ee.get_pos() ** 2).sum() + (robot.get_dofs_velocity() ** 2).sum()
        loss.backward()
        return loss.detach(), v0.grad
    (loss, grad), (loss_ik, grad_ik) = run(False), run(True)
    assert torch.equal(loss, loss_ik) and torch.equal(grad, grad_ik)
