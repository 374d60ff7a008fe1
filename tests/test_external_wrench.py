"""entity.apply_links_external_wrench against MuJoCo 4's xfrc_applied (float64).

MuJoCo's wrench acts at each body's centre of mass (force, then torque, world frame); ours is
given as Genesis's: a force at a point (world, or in the link or centre-of-mass frame with
local=True) and a torque. Both are set from random states, one step taken, qvel compared: a
KUKA arm (fixed base), and a free box beside it, batched. Then: the wrench lasts one step, calls
before a step add up, and bad arguments raise.
"""
import mujoco
import numpy as np
import pytest
import torch

import genesis_lite as gs
from tests.conftest import pybullet
from tests.mujoco_ref import bare_spec

KUKA = pybullet("kuka_iiwa", "model.urdf")
DT = 0.01


def _mujoco():
    spec = bare_spec(KUKA)
    mass, half = 1000.0 * 0.2 * 0.1 * 0.04, np.array([0.1, 0.05, 0.02])  # our box's (ρ 1000 kg/m³)
    box = spec.worldbody.add_body(name="box", pos=[1.0, 0.0, 0.5], ipos=[0.0, 0.0, 0.0], mass=mass,
                                  inertia=mass / 3.0 * (half @ half - half ** 2))
    box.add_freejoint()
    spec.option.timestep = DT
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_EULER
    model = spec.compile()
    return model, mujoco.MjData(model)


def _ours(n_envs):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT),
                     rigid_options=gs.options.RigidOptions(enable_collision=False, enable_mujoco_compatibility=True),
                     show_viewer=False)
    robot = scene.add_entity(gs.morphs.URDF(file=KUKA, fixed=True))
    box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.1, 0.04), pos=(1.0, 0.0, 0.5)), material=gs.materials.Rigid(rho=1000.0))
    scene.build(n_envs=n_envs)
    return scene, robot, box


def _mujoco_wrench(data, body, force, torque, point):
    """xfrc_applied of a world force at a world point and a world torque."""
    data.xfrc_applied[body, :3] += force
    data.xfrc_applied[body, 3:] += torque + np.cross(point - data.xipos[body], force)


@pytest.mark.parametrize("ref, local", [("link_origin", False), ("link_origin", True), ("link_com", True),
                                        ("link_com", False)])
def test_one_step_matches_mujoco(f64, ref, local):
    model, data = _mujoco()
    scene, robot, box = _ours(n_envs=2)
    rng = np.random.default_rng(3)
    links, nq = [2, 5, 7], model.nq
    qpos = np.tile(model.qpos0, (2, 1))
    qpos[:, :7] = rng.uniform(-1.0, 1.0, (2, 7))
    qvel = rng.normal(size=(2, model.nv))
    robot.set_dofs_position(torch.tensor(qpos[:, :7]))
    robot.set_dofs_velocity(torch.tensor(qvel[:, :7]))
    box.set_dofs_velocity(torch.tensor(qvel[:, 7:]))
    force, torque = rng.normal(size=(2, 3, 3)) * 5.0, rng.normal(size=(2, 3, 3))
    point = rng.normal(size=(2, 3, 3)) * 0.1 + (0.0 if local else 0.5)
    robot.apply_links_external_wrench(torch.tensor(force), torch.tensor(torque), links, pos=torch.tensor(point),
                                      ref=ref, local=local)
    box_force, box_torque = rng.normal(size=(2, 1, 3)), rng.normal(size=(2, 1, 3)) * 0.1
    box.apply_links_external_wrench(torch.tensor(box_force), torch.tensor(box_torque), ref=ref, local=local)
    scene.step()
    for e in range(2):
        data.qpos[:], data.qvel[:], data.xfrc_applied[:] = qpos[e], qvel[e], 0.0
        mujoco.mj_kinematics(model, data)
        for k, link in enumerate(links):
            body = model.body(robot.links[link].name).id
            rot = data.xmat[body].reshape(3, 3)
            origin = data.xpos[body] if ref == "link_origin" else data.xipos[body]
            f, t = (rot @ force[e, k], rot @ torque[e, k]) if local else (force[e, k], torque[e, k])
            at = origin + rot @ point[e, k] if local else point[e, k]
            _mujoco_wrench(data, body, f, t, at)
        body = model.body("box").id
        rot = data.xmat[body].reshape(3, 3)
        f, t = (rot @ box_force[e, 0], rot @ box_torque[e, 0]) if local else (box_force[e, 0], box_torque[e, 0])
        _mujoco_wrench(data, body, f, t, data.xpos[body])  # (the box's origin is its centre of mass)
        mujoco.mj_step(model, data)
        ours = torch.cat([robot.get_dofs_velocity()[e], box.get_dofs_velocity()[e]]).numpy()
        np.testing.assert_allclose(ours, data.qvel, atol=1e-10)


def test_a_wrench_lasts_one_step_and_calls_add_up(f64):
    scene, robot, _ = _ours(n_envs=0)
    force = torch.tensor([[20.0, 5.0, 0.0]])  # (at the zero pose the arm stands upright: x turns its y joints)

    def velocities(calls):
        """(qpos, qvel after step 1, qvel after step 2) with the wrench given in ``calls`` parts."""
        scene.reset()
        for _ in range(calls):
            robot.apply_links_external_wrench(force / calls, links_idx_local=[6])
        scene.step()
        first = robot.get_qpos().clone(), robot.get_dofs_velocity().clone()
        scene.step()
        return (*first, robot.get_dofs_velocity())

    once, twice, none = velocities(1), velocities(2), velocities(0)
    np.testing.assert_allclose(once[1], twice[1], atol=1e-12)
    assert (once[1] - none[1]).abs().max() > 1e-3
    # the second step had no wrench: from the same state, a step without one is the same
    scene.reset()
    robot.set_qpos(once[0])
    robot.set_dofs_velocity(once[1])
    scene.step()
    np.testing.assert_allclose(robot.get_dofs_velocity(), once[2], atol=1e-12)


def test_a_wrench_broadcasts_as_genesis(f64):
    """Genesis broadcasts a wrench: a (3,) force acts on every link given and in every env, one of
    shape (B, 3) per env on every link (here B = 3 and 2 links: (n, 3) would be per link); the same
    as the full (B, n, 3) array."""
    scene, robot, _ = _ours(n_envs=3)

    def velocity(force):
        scene.reset()
        robot.apply_links_external_wrench(force, links_idx_local=[5, 6])
        scene.step()
        return robot.get_dofs_velocity()
    per_env = torch.tensor([[20.0, 5.0, 0.0], [0.0, -8.0, 3.0], [1.0, 1.0, 1.0]])
    full = per_env[:, None, :].expand(3, 2, 3)
    assert torch.equal(velocity(per_env), velocity(full))
    assert torch.equal(velocity([20.0, 5.0, 0.0]), velocity(per_env[:1, None, :].expand(3, 2, 3)))
    assert not torch.equal(velocity(per_env)[0], velocity(per_env)[1])


def test_bad_arguments_raise(f64):
    _, robot, _ = _ours(n_envs=0)
    with pytest.raises(gs.InvalidInputError, match="expected 'force' or 'torque', got neither"):
        robot.apply_links_external_wrench()
    with pytest.raises(gs.InvalidInputError, match="'pos' needs a 'force'"):
        robot.apply_links_external_wrench(torque=[[0.0, 0.0, 1.0]], links_idx_local=[1], pos=[[0.0, 0.0, 0.0]])
    with pytest.raises(gs.InvalidInputError, match="'ref' must be gs.link_ref_frame.link_origin"):
        robot.apply_links_external_wrench(force=[[0.0, 0.0, 1.0]], links_idx_local=[1], ref="root_com")
    with pytest.raises(gs.InvalidInputError, match="'local' must be a bool"):
        robot.apply_links_external_wrench(force=[[0.0, 0.0, 1.0]], links_idx_local=[1], local="False")
    with pytest.raises(gs.InvalidInputError, match=r"'force' must have shape \(2, 3\) \(or one that broadcasts to "
                                                   r"it\), got \(3, 3\)"):
        robot.apply_links_external_wrench(force=[[0.0, 0.0, 1.0]] * 3, links_idx_local=[1, 2])
