"""Position servos on free and ball joints (Genesis's control_dofs_position on a free base): the
three rotation dofs pull toward one target orientation, given as get_dofs_position's Euler
angles, by kp times the rotation vector of the turn to it in the joint's axes
(solvers/rigid/actuation.py). Checked: the force against the axis-angle of R(q)ᵀ R(q*) computed
here from rotation matrices, the body coming to the target pose, a ball joint alike, float64
gradients in the targets, gains and initial state against central differences, and the named
error when the rotation dofs are not given together."""
import numpy as np
import pytest
import torch

import genesis_lite as gs
from tests.fd_scan import checked_gradient

DT = 0.01


def _matrix(euler):
    """R = Rx(a) Ry(b) Rz(c) (numpy)."""
    a, b, c = euler
    rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]])
    return rx @ ry @ rz


def _axis_angle(rotation):
    """The rotation vector of a rotation matrix (angle < π), from its trace and skew part."""
    angle = np.arccos(np.clip((np.trace(rotation) - 1) / 2, -1, 1))
    skew = np.array([rotation[2, 1] - rotation[1, 2], rotation[0, 2] - rotation[2, 0], rotation[1, 0] - rotation[0, 1]])
    return skew * angle / (2 * np.sin(angle))


def _box(gravity=(0.0, 0.0, 0.0), requires_grad=False):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT, requires_grad=requires_grad),
                     rigid_options=gs.options.RigidOptions(gravity=gravity), show_viewer=False)
    box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.1, 0.05), pos=(0.0, 0.0, 0.5), euler=(20.0, -10.0, 40.0)))
    scene.build()
    return scene, box


def test_free_joint_servo_force_is_kp_times_the_turn_to_the_target(f64):
    """At rest (no gravity), the force of each dof after one step (get_dofs_force, the kernel's)
    and get_dofs_control_force: kp·(target − position) on the position dofs, kp·r on the rotation
    dofs, r the axis-angle of R(q)ᵀ R(q*) (the turn in the body's axes)."""
    scene, box = _box()
    kp = torch.tensor([3.0, 2.0, 1.0, 0.5, 0.7, 0.9], dtype=torch.float64)
    box.set_dofs_kp(kp)
    box.set_dofs_kv(torch.zeros(6, dtype=torch.float64))
    start = box.get_dofs_position().clone()
    target = torch.tensor([0.1, -0.2, 0.6, 0.9, -0.6, 1.6], dtype=torch.float64)
    box.control_dofs_position(target)
    turn = _axis_angle(_matrix(start[3:].numpy()).T @ _matrix(target[3:].numpy()))
    expected = kp * torch.cat([target[:3] - start[:3], torch.tensor(turn)])
    torch.testing.assert_close(box.get_dofs_control_force(), expected, rtol=0, atol=1e-12)
    scene.step()
    torch.testing.assert_close(box.get_dofs_force(), expected, rtol=0, atol=1e-12)


def test_a_servoed_free_body_comes_to_its_target_pose(f64):
    """Under gravity, a box held by servos on its six dofs (gains for its 1 kg and small inertia,
    damped) ends at the target: position within kp's sag m g / kp, orientation to 1e-6 rad."""
    scene, box = _box(gravity=(0.0, 0.0, -9.81))
    box.set_dofs_kp(torch.tensor([400.0, 400.0, 400.0, 0.2, 0.2, 0.2], dtype=torch.float64))
    box.set_dofs_kv(torch.tensor([40.0, 40.0, 40.0, 0.02, 0.02, 0.02], dtype=torch.float64))
    target = torch.tensor([0.1, -0.2, 0.6, 2.5, -0.6, 1.6], dtype=torch.float64)  # a turn of ~2.5 rad
    box.control_dofs_position(target)
    for _ in range(400):
        scene.step()
    sag = float(box.get_mass()) * 9.81 / 400.0
    position = box.get_dofs_position()
    torch.testing.assert_close(position[:3], target[:3] - torch.tensor([0.0, 0.0, sag], dtype=torch.float64),
                               rtol=0, atol=1e-6)
    rest = _axis_angle(_matrix(position[3:].numpy()).T @ _matrix(target[3:].numpy()))
    assert np.linalg.norm(rest) < 1e-6 and float(box.get_dofs_velocity().abs().max()) < 1e-5


def test_a_ball_joint_servo_turns_its_link_to_the_target(f64):
    """A ball-jointed pendulum (MJCF, no gravity) turned by a servo on its three dofs to the target's
    Euler angles: get_dofs_position reads them back, to 1e-6 rad."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT), rigid_options=gs.options.RigidOptions(gravity=(0, 0, 0)),
                     show_viewer=False)
    pendulum = scene.add_entity(gs.morphs.MJCF(file=(
        '<mujoco><worldbody><body pos="0 0 1"><joint type="ball"/>'
        '<geom type="capsule" fromto="0 0 0 0 0 -0.5" size="0.03" mass="1"/></body></worldbody></mujoco>')))
    scene.build()
    pendulum.set_dofs_kp(torch.full((3,), 5.0, dtype=torch.float64))
    pendulum.set_dofs_kv(torch.full((3,), 1.0, dtype=torch.float64))
    target = torch.tensor([0.4, -0.3, 0.8], dtype=torch.float64)
    pendulum.control_dofs_position(target)
    for _ in range(600):
        scene.step()
    torch.testing.assert_close(pendulum.get_dofs_position(), target, rtol=0, atol=1e-6)


@pytest.mark.parametrize("what", ["targets", "kp", "start"])
def test_free_joint_servo_gradients_match_central_differences(f64, what):
    """30 steps of a servoed box under gravity; the loss weighs its final position, quaternion and
    velocities. Gradients in the six targets, the six gains kp and the initial velocities (through
    the rotation error's quaternion), against central differences; a repeat keeps its bits."""
    scene, box = _box(gravity=(0.0, 0.0, -9.81), requires_grad=True)
    base = {"targets": torch.tensor([0.1, -0.2, 0.6, 0.9, -0.6, 1.6], dtype=torch.float64),
            "kp": torch.tensor([40.0, 40.0, 40.0, 0.2, 0.3, 0.25], dtype=torch.float64),
            "start": torch.tensor([0.2, -0.1, 0.3, 1.0, -2.0, 3.0], dtype=torch.float64)}
    weights = torch.tensor(np.random.default_rng(0).normal(size=13))

    def loss(value):
        inputs = {**base, what: value}
        scene.reset()
        box.set_dofs_kv(torch.tensor([4.0, 4.0, 4.0, 0.02, 0.02, 0.02], dtype=torch.float64))
        box.set_dofs_kp(inputs["kp"])
        box.set_dofs_velocity(inputs["start"])
        box.control_dofs_position(inputs["targets"])
        for _ in range(30):
            scene.step()
        return (torch.cat([box.get_pos(), box.get_quat(), box.get_dofs_velocity()]) * weights).sum()

    grad = checked_gradient(loss, base[what], f"free-joint servo, {what}")
    assert float(grad[3:].abs().max()) > 0.0  # (the rotation dofs' part is checked, not only the position's)


def test_rotation_dofs_are_driven_together(f64):
    _, box = _box()
    with pytest.raises(gs.InvalidInputError, match=r"three rotation dofs together .* expected all of \[3, 4, 5\] or "
                                                   r"none, got \[0, 1, 2, 5\]"):
        box.control_dofs_position(torch.zeros(4), dofs_idx_local=[0, 1, 2, 5])
    box.control_dofs_position(torch.zeros(3), dofs_idx_local=[0, 1, 2])  # (the position dofs alone)
    box.control_dofs_position(torch.zeros(6))
    with pytest.raises(gs.InvalidInputError, match=r"together in or out of position control"):
        box.control_dofs_force(torch.zeros(1), dofs_idx_local=[5])  # (dofs 3, 4 would turn to a stale target)
    box.control_dofs_force(torch.zeros(3), dofs_idx_local=[3, 4, 5])
    box.control_dofs_velocity(torch.zeros(1), dofs_idx_local=[5])  # (none of them in position control now)

    scene = gs.Scene(show_viewer=False)  # per env: only the envs whose rotation dofs are in position control
    boxes = scene.add_entity(gs.morphs.Box(size=(0.2, 0.1, 0.05), pos=(0.0, 0.0, 0.5)))
    scene.build(n_envs=2)
    boxes.control_dofs_position(torch.zeros(1, 6), envs_idx=[0])
    boxes.control_dofs_force(torch.zeros(1, 1), dofs_idx_local=[5], envs_idx=[1])
    with pytest.raises(gs.InvalidInputError, match=r"together in or out of position control"):
        boxes.control_dofs_force(torch.zeros(2, 1), dofs_idx_local=[5])


BALL_ON_HINGE = ('<mujoco><worldbody><body pos="0 0 1"><joint type="hinge" axis="0 1 0"/>'
                 '<geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03" mass="1"/>'
                 '<body pos="0.3 0 0" quat="0.9 0.3 0.2 0.1"><joint type="ball"/>'
                 '<geom type="capsule" fromto="0 0 0 0 0.1 -0.4" size="0.03" mass="0.7"/></body></body>'
                 '</worldbody></mujoco>')


def _ball_on_hinge(requires_grad=False, gravity=(0.0, 0.0, -9.81)):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT, requires_grad=requires_grad),
                     rigid_options=gs.options.RigidOptions(gravity=gravity, enable_collision=False),
                     show_viewer=False)
    robot = scene.add_entity(gs.morphs.MJCF(file=BALL_ON_HINGE))
    scene.build(n_envs=2)
    return scene, robot


def _quat_matrix(q):
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def test_a_ball_joint_servo_turns_from_the_joints_own_orientation(f64):
    """A ball joint below a hinge, its body turned in the parent: the servo's force on its three dofs
    is kp times the axis-angle of R_jointᵀ R(q*), R_joint the ball's own turn (its qpos), not the
    link's world orientation (2 envs at random poses; at rest, no gravity, no kv: get_dofs_force,
    the kernel's, is that force alone)."""
    scene, robot = _ball_on_hinge(gravity=(0.0, 0.0, 0.0))
    qpos = torch.tensor([[0.3, 0.7, -0.2, 0.4, 0.5], [-1.0, 0.1, 0.9, -0.3, 0.2]], dtype=torch.float64)
    qpos[:, 1:] /= qpos[:, 1:].norm(dim=1, keepdim=True)
    robot.set_qpos(qpos)
    kp = torch.tensor([0.0, 2.0, 3.0, 4.0], dtype=torch.float64)
    robot.set_dofs_kp(kp)
    robot.set_dofs_kv(torch.zeros(4, dtype=torch.float64))
    targets = torch.tensor([[0.2, -0.5, 0.9], [2.5, 1.2, -2.9]], dtype=torch.float64)
    robot.control_dofs_position(targets, dofs_idx_local=[1, 2, 3])
    expected = torch.tensor(np.array([_axis_angle(_quat_matrix(qpos[e, 1:].numpy()).T @ _matrix(targets[e].numpy()))
                                      for e in range(2)])) * kp[1:]
    torch.testing.assert_close(robot.get_dofs_control_force()[:, 1:], expected, rtol=0, atol=1e-12)
    scene.step()
    torch.testing.assert_close(robot.get_dofs_force()[:, 1:], expected, rtol=0, atol=1e-12)


@pytest.mark.parametrize("what", ["targets", "start"])
def test_ball_joint_servo_gradients_match_central_differences(f64, what):
    """20 steps of the ball on the hinge under gravity with its servo; gradients in the three Euler
    targets (both envs) and in the initial velocities, against central differences."""
    scene, robot = _ball_on_hinge(requires_grad=True)
    base = {"targets": torch.tensor([[0.2, -0.5, 0.9], [2.5, 1.2, -2.9]], dtype=torch.float64),
            "start": torch.tensor([[0.5, 1.0, -2.0, 0.7], [-0.3, 0.4, 0.2, -1.5]], dtype=torch.float64)}
    weights = torch.tensor(np.random.default_rng(1).normal(size=(2, 9)))

    def loss(value):
        inputs = {**base, what: value}
        scene.reset()
        robot.set_dofs_kp(torch.tensor([0.0, 2.0, 3.0, 4.0], dtype=torch.float64))
        robot.set_dofs_kv(torch.tensor([0.0, 0.1, 0.1, 0.1], dtype=torch.float64))
        robot.set_dofs_velocity(inputs["start"])
        robot.control_dofs_position(inputs["targets"], dofs_idx_local=[1, 2, 3])
        for _ in range(20):
            scene.step()
        return (torch.cat([robot.get_qpos(), robot.get_dofs_velocity()], dim=1) * weights).sum()

    checked_gradient(loss, base[what], f"ball-joint servo, {what}")
