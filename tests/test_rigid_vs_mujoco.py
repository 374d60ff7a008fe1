"""Contact-free dynamics against MuJoCo loading the same URDF (tests/mujoco_ref.py)."""
import numpy as np
import pytest

from tests import mujoco_ref
from tests.conftest import asset, pybullet
from tests.robot_states import limit_free_scene, qpos_by_name, random_state, scalar_joints, set_state

DT = 0.01
ROBOTS = {
    "pendulum2": (asset("pendulum2.urdf"), False),
    "cartpole": (pybullet("cartpole.urdf"), False),
    "kuka": (pybullet("kuka_iiwa", "model.urdf"), False),
    "kuka_free": (pybullet("kuka_iiwa", "model_free_base.urdf"), True),
}


@pytest.mark.parametrize("name", list(ROBOTS))
@pytest.mark.parametrize("extras", [False, True], ids=["plain", "damping_armature"])
def test_trajectory_matches_mujoco_f64(f64, name, extras):
    path, free = ROBOTS[name]
    scene, robot = limit_free_scene(path, free, DT)
    rng = np.random.default_rng(0)
    joints, base = random_state(robot, rng, free)
    damping = armature = None
    scalar = scalar_joints(robot)
    if extras:
        damping = {j.name: rng.uniform(0.1, 1.0) for j in scalar}
        armature = {j.name: rng.uniform(0.01, 0.2) for j in scalar}
        dofs = [j.dofs_idx_local[0] for j in scalar]
        robot.set_dofs_damping([damping[j.name] for j in scalar], dofs)
        robot.set_dofs_armature([armature[j.name] for j in scalar], dofs)
    set_state(robot, joints, base)
    n_steps = int(round(2.0 / DT))
    ours = [robot.get_qpos().numpy()]
    for _ in range(n_steps):
        scene.step()
        ours.append(robot.get_qpos().numpy())
    ours = qpos_by_name(robot, np.array(ours))

    model = mujoco_ref.load_model(path, free_base=free, dt=DT, damping=damping, armature=armature)
    ref = mujoco_ref.rollout(model, {k: v[0] for k, v in joints.items()}, {k: v[1] for k, v in joints.items()},
                             n_steps, base_qpos=None if base is None else base[0],
                             base_qvel=None if base is None else base[1])
    for key, traj in ours.items():
        err = np.max(np.abs(traj - ref.qpos[key]))
        assert err <= 1e-8, f"{name} joint {key}: max |q - q_mujoco| = {err:.3g} over 2 s"
