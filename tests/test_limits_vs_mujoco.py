"""Joint limits and dof friction loss as constraint rows, against MuJoCo 4 (float64).

The KUKA iiwa (7 revolute joints, all limited) without collision (MuJoCo's copy has no geoms):
each case sets the same state
in both simulators — joints spread over their range and up to 0.1 rad past either bound, random
velocities — takes one step and compares qvel (≤ 1e-10). With joint damping MuJoCo integrates
the constraint force through the damped matrix, without it the solve's own acceleration: both
are covered, and friction loss both stuck (large bound) and sliding (small bound). A trajectory
of 1 s, falling onto the limits under gravity with friction loss, stays within 1e-8 of MuJoCo's.
"""
import mujoco
import numpy as np
import pytest
import torch

import genesis_lite as gs
from tests.conftest import pybullet
from tests.mujoco_ref import bare_spec

KUKA = pybullet("kuka_iiwa", "model.urdf")
DT = 0.002
_SCENES = {}


def _mujoco(damping, frictionloss):
    spec = bare_spec(KUKA)
    for joint in spec.joints:
        joint.frictionloss = frictionloss
        joint.damping = [damping, 0.0, 0.0]
    spec.option.timestep = DT
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_EULER
    spec.option.gravity = np.array([0.0, 0.0, -9.81])
    model = spec.compile()
    assert model.jnt_limited.all()
    return model, mujoco.MjData(model)


def _ours(damping, frictionloss):
    key = gs.runtime.epoch
    if key not in _SCENES:
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT),
                         rigid_options=gs.options.RigidOptions(enable_mujoco_compatibility=True,
                                                               enable_collision=False))
        robot = scene.add_entity(gs.morphs.URDF(file=KUKA, fixed=True))
        scene.build()
        _SCENES[key] = scene, robot
    scene, robot = _SCENES[key]
    scene.reset()
    robot.set_dofs_damping([damping] * robot.n_dofs)
    robot.set_dofs_frictionloss([frictionloss] * robot.n_dofs)
    return scene, robot


def _set(robot, data, qpos, qvel):
    data.qpos[:], data.qvel[:] = qpos, qvel
    data.qacc_warmstart[:] = 0.0
    robot.set_dofs_position(torch.tensor(qpos))
    robot.set_dofs_velocity(torch.tensor(qvel))


@pytest.mark.parametrize("damping,frictionloss", [(0.0, 0.0), (0.5, 0.0), (0.0, 0.3), (0.5, 5.0)])
def test_one_step_from_states_at_and_past_the_limits(f64, damping, frictionloss):
    model, data = _mujoco(damping, frictionloss)
    scene, robot = _ours(damping, frictionloss)
    rng = np.random.default_rng(1)
    low, high = model.jnt_range.T
    worst, rows = 0.0, []
    for _ in range(12):
        near = rng.random(model.nv) < 0.5  # these joints within 0.1 rad of a bound, either side
        bound = np.where(rng.random(model.nv) < 0.5, low, high)
        qpos = np.where(near, bound + rng.uniform(-0.1, 0.1, model.nv), rng.uniform(low, high))
        _set(robot, data, qpos, rng.normal(size=model.nv))
        mujoco.mj_step(model, data)
        scene.step()
        worst = max(worst, np.abs(robot.get_dofs_velocity().numpy() - data.qvel).max())
        rows.append(data.nefc)
    assert worst <= 1e-10, f"qvel after one step differs from MuJoCo's by {worst:.3g}"
    limit_rows = np.array(rows) - (model.nv if frictionloss > 0 else 0)
    assert limit_rows.max() > 0 and limit_rows.sum() >= 6, "too few states past a limit to test the limit rows"


def test_trajectory_onto_the_limits(f64):
    """1 s from rest at 1.5 rad off the home pose, under gravity, damping 0.1, friction loss 0.2:
    several joints swing into their limits; no re-syncing."""
    model, data = _mujoco(0.1, 0.2)
    scene, robot = _ours(0.1, 0.2)
    qpos = np.array([0.0, 1.5, 0.0, -1.5, 0.0, 1.5, 0.0])
    _set(robot, data, qpos, np.zeros(model.nv))
    worst, hits = 0.0, 0
    for _ in range(500):
        mujoco.mj_step(model, data)
        scene.step()
        worst = max(worst, np.abs(robot.get_dofs_position().numpy() - data.qpos).max())
        hits += data.nefc > model.nv
    assert worst <= 1e-8, f"joint positions drift from MuJoCo's by {worst:.3g} rad over 1 s"
    assert hits > 50, f"only {hits} steps with a limit row: the trajectory does not test the limits"
