"""Test support: contact- and limit-free robot scenes, random states keyed by joint name (so
they can be handed to MuJoCo, whose dof order may differ), and reading our qpos back by name."""
import numpy as np

import genesis_lite as gs
from tests import mujoco_ref


def limit_free_scene(path, free, dt, n_envs=0):
    """The robot without joint limits and contacts (as mujoco_ref loads it)."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=dt),
                     rigid_options=gs.options.RigidOptions(enable_joint_limit=False, enable_collision=False))
    robot = scene.add_entity(gs.morphs.URDF(file=path, fixed=not free, default_armature=0.0), name="robot")
    scene.build(n_envs=n_envs)
    return scene, robot


def scalar_joints(robot):
    return [j for j in robot.joints if j.type in ("revolute", "prismatic")]


def random_state(robot, rng, free, q_range=1.0):
    """({joint name: (q, q̇)}, None or (base qpos (7,), base qvel (6,)))."""
    joints = {j.name: (rng.uniform(-q_range, q_range), rng.uniform(-2, 2)) for j in scalar_joints(robot)}
    base = None
    if free:
        quat = rng.normal(size=4)
        base = (np.concatenate([rng.uniform(-1, 1, 3), quat / np.linalg.norm(quat)]), rng.uniform(-1.5, 1.5, 6))
    return joints, base


def set_state(robot, joints, base):
    qpos = robot.get_qpos().numpy().copy()
    qvel = np.zeros(robot.n_dofs)
    for joint in scalar_joints(robot):
        qpos[joint.qs_idx_local[0]], qvel[joint.dofs_idx_local[0]] = joints[joint.name]
    if base is not None:
        qpos[:7], qvel[:6] = base
    robot.set_qpos(qpos)
    robot.set_dofs_velocity(qvel)


def qpos_by_name(robot, qpos):
    """(..., n_qs) → {joint name: (...,)} (and the free base's (..., 7) under mujoco_ref.BASE)."""
    out = {j.name: qpos[..., j.qs_idx_local[0]] for j in scalar_joints(robot)}
    if robot.is_free:
        out[mujoco_ref.BASE] = qpos[..., :7]
    return out
