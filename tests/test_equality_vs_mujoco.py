"""Joint equalities (URDF <mimic>) as constraint rows, against MuJoCo 4 (float64).

assets/mimic_gripper.urdf: an arm swinging under gravity, a palm on a wrist, two prismatic fingers
of which the right mirrors the left (multiplier −1) and a thumb on another axis following the
wrist (multiplier 0.5, offset 0.2 rad). MuJoCo reads the same file and makes the same two joint
equalities (polycoef (offset, multiplier), its default solref and solimp). Each case sets the same
state in both, the mimics off their targets by up to 0.2, random velocities, takes one step and
compares qvel; a trajectory of 1 s from such a state stays with MuJoCo's.
"""
import re

import mujoco
import numpy as np
import pytest
import torch

import genesis_lite as gs
from tests.conftest import asset

GRIPPER = asset("mimic_gripper.urdf")
DT = 0.002
_SCENES = {}


def _mujoco():
    spec = mujoco.MjSpec.from_file(GRIPPER)
    spec.option.timestep = DT
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_EULER
    spec.option.gravity = np.array([0.0, 0.0, -9.81])
    model = spec.compile()
    assert model.neq == 2 and (model.eq_type == mujoco.mjtEq.mjEQ_JOINT).all()
    return model, mujoco.MjData(model)


def _ours(n_envs=0, urdf=GRIPPER):
    key = (n_envs, urdf, gs.runtime.epoch)
    if key not in _SCENES:
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT),
                         rigid_options=gs.options.RigidOptions(enable_mujoco_compatibility=True))
        robot = scene.add_entity(gs.morphs.URDF(file=urdf, fixed=True))
        scene.build(n_envs=n_envs)
        _SCENES[key] = scene, robot
    scene, robot = _SCENES[key]
    scene.reset()
    return scene, robot


def _random_state(rng, nv):
    """Joint positions with the mimics up to 0.2 off their targets, and random velocities."""
    qpos = rng.uniform(-0.5, 0.5, nv)
    qpos[3] = -qpos[2] + rng.uniform(-0.2, 0.2)
    qpos[4] = 0.2 + 0.5 * qpos[1] + rng.uniform(-0.2, 0.2)
    return qpos, rng.normal(size=nv)


def _set(robot, data, qpos, qvel):
    data.qpos[:], data.qvel[:] = qpos, qvel
    data.qacc_warmstart[:] = 0.0
    robot.set_dofs_position(torch.tensor(qpos))
    robot.set_dofs_velocity(torch.tensor(qvel))


def test_one_step_from_states_off_the_equalities(f64):
    model, data = _mujoco()
    scene, robot = _ours()
    rng = np.random.default_rng(2)
    worst = 0.0
    for _ in range(12):
        _set(robot, data, *_random_state(rng, model.nv))
        mujoco.mj_step(model, data)
        scene.step()
        assert data.nefc == 2  # the two equality rows, no limit reached
        worst = max(worst, np.abs(robot.get_dofs_velocity().numpy() - data.qvel).max())
    assert worst <= 1e-10, f"qvel after one step differs from MuJoCo's by {worst:.3g}"


def test_trajectory_pulled_onto_the_equalities(f64, tmp_path):
    """1 s from a state off both equalities under gravity, no re-syncing: positions within 1e-8
    of MuJoCo's; the mimics end on their targets (the soft rows' residual under load), where
    without the equalities the thumb goes its own way."""
    model, data = _mujoco()
    scene, robot = _ours()
    qpos = np.array([0.3, -0.4, 0.1, 0.05, 0.6])
    _set(robot, data, qpos, np.zeros(model.nv))
    worst = 0.0
    for _ in range(500):
        mujoco.mj_step(model, data)
        scene.step()
        worst = max(worst, np.abs(robot.get_dofs_position().numpy() - data.qpos).max())
    assert worst <= 1e-8, f"joint positions drift from MuJoCo's by {worst:.3g} over 1 s"
    q = robot.get_dofs_position().numpy()
    assert abs(q[3] + q[2]) < 1e-3 and abs(q[4] - 0.2 - 0.5 * q[1]) < 1e-3, q
    unmimicked = tmp_path / "gripper.urdf"  # the same file without its <mimic> elements
    unmimicked.write_text(re.sub(r"<mimic [^>]*/>", "", open(GRIPPER).read()))
    free_scene, free = _ours(urdf=str(unmimicked))
    free.set_dofs_position(torch.tensor(qpos))
    for _ in range(500):
        free_scene.step()
    q = free.get_dofs_position().numpy()
    assert abs(q[4] - 0.2 - 0.5 * q[1]) > 0.02, q


def test_batched_envs_equal_single_ones(f64):
    """Each env of a batch steps as a scene of its own, bit for bit."""
    rng = np.random.default_rng(5)
    states = [_random_state(rng, 5) for _ in range(3)]
    batch_scene, batch = _ours(n_envs=3)
    batch.set_dofs_position(torch.tensor(np.array([s[0] for s in states])))
    batch.set_dofs_velocity(torch.tensor(np.array([s[1] for s in states])))
    for _ in range(20):
        batch_scene.step()
    for k, (qpos, qvel) in enumerate(states):
        scene, robot = _ours()
        robot.set_dofs_position(torch.tensor(qpos))
        robot.set_dofs_velocity(torch.tensor(qvel))
        for _ in range(20):
            scene.step()
        assert torch.equal(robot.get_dofs_position(), batch.get_dofs_position()[k])
