"""Contact-free dynamics against MuJoCo loading the same URDF (tests/mujoco_ref.py)."""
import numpy as np
import pytest
import torch

import genesis_lite as gs
from tests import mujoco_ref
from tests.conftest import asset, pybullet

DT = 0.01
ROBOTS = {
    "pendulum2": (asset("pendulum2.urdf"), False),
    "cartpole": (pybullet("cartpole.urdf"), False),
    "kuka": (pybullet("kuka_iiwa", "model.urdf"), False),
    "kuka_free": (pybullet("kuka_iiwa", "model_free_base.urdf"), True),
}


def _scene(path, free, n_envs=0, requires_grad=False):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT, requires_grad=requires_grad),
                     rigid_options=gs.options.RigidOptions(enable_joint_limit=False))
    robot = scene.add_entity(gs.morphs.URDF(file=path, fixed=not free))
    scene.build(n_envs=n_envs)
    return scene, robot


def _random_state(robot, rng, free):
    """Joint name → (q, qd) for the 1-dof joints; base qpos/qvel for a free robot."""
    joints = {j.name: (rng.uniform(-1, 1), rng.uniform(-2, 2)) for j in robot.joints if j.type in ("revolute",
                                                                                                    "prismatic")}
    base = None
    if free:
        quat = rng.normal(size=4)
        base = (np.concatenate([rng.uniform(-1, 1, 3), quat / np.linalg.norm(quat)]), rng.uniform(-1, 1, 6))
    return joints, base


def _set_ours(robot, joints, base):
    qpos = robot.get_qpos().numpy().copy()
    qvel = np.zeros(robot.n_dofs)
    for joint in robot.joints:
        if joint.name in joints:
            qpos[joint.qs_idx_local[0]], qvel[joint.dofs_idx_local[0]] = joints[joint.name]
    if base is not None:
        qpos[:7], qvel[:6] = base
    robot.set_qpos(qpos)
    robot.set_dofs_velocity(qvel)


def _ours_by_name(robot, qpos):
    out = {j.name: qpos[..., j.qs_idx_local[0]] for j in robot.joints if j.type in ("revolute", "prismatic")}
    if robot.is_free:
        out[mujoco_ref.BASE] = qpos[..., :7]
    return out


@pytest.mark.parametrize("name", list(ROBOTS))
@pytest.mark.parametrize("extras", [False, True], ids=["plain", "damping_armature"])
def test_trajectory_matches_mujoco_f64(f64, name, extras):
    path, free = ROBOTS[name]
    scene, robot = _scene(path, free)
    rng = np.random.default_rng(0)
    joints, base = _random_state(robot, rng, free)
    damping = armature = None
    scalar = [j for j in robot.joints if j.type in ("revolute", "prismatic")]
    if extras:
        damping = {j.name: rng.uniform(0.1, 1.0) for j in scalar}
        armature = {j.name: rng.uniform(0.01, 0.2) for j in scalar}
        dofs = [j.dofs_idx_local[0] for j in scalar]
        robot.set_dofs_damping([damping[j.name] for j in scalar], dofs)
        robot.set_dofs_armature([armature[j.name] for j in scalar], dofs)
    else:  # the URDF's own damping applies on both sides
        pass
    _set_ours(robot, joints, base)
    n_steps = int(round(2.0 / DT))
    ours = [robot.get_qpos().numpy()]
    for _ in range(n_steps):
        scene.step()
        ours.append(robot.get_qpos().numpy())
    ours = _ours_by_name(robot, np.array(ours))

    model = mujoco_ref.load_model(path, free_base=free, dt=DT, damping=damping, armature=armature)
    ref = mujoco_ref.rollout(model, {k: v[0] for k, v in joints.items()}, {k: v[1] for k, v in joints.items()},
                             n_steps, base_qpos=None if base is None else base[0],
                             base_qvel=None if base is None else base[1])
    for key, traj in ours.items():
        err = np.max(np.abs(traj - ref.qpos[key]))
        assert err <= 1e-8, f"{name} joint {key}: max |q - q_mujoco| = {err:.3g} over 2 s"
