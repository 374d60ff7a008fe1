"""RigidEntity methods that behave as Genesis 1.4.5's (parity report §Q1, Q3-Q6): the
``zero_velocity`` keyword of the position setters, a free base's Euler-angle dofs, the actuator
and generalised dof forces, ``control_dofs_position_velocity`` (with finite-difference gradients
of its targets) and the mass matrix with armature and its LᵀDL decomposition.

Numbers quoted from Genesis were measured on the same 1-dof pendulum (PENDULUM below).
"""
import inspect
import logging

import numpy as np
import pytest
import torch
import yourdfpy
from scipy.spatial.transform import Rotation

import genesis_lite as gs
from genesis_lite.utils.rotations import euler_xyz_to_quat, quat_to_euler_xyz
from tests.conftest import asset, pybullet

# A 1-dof pendulum about y: 1 kg at 0.5 m and 0.5 kg at 1 m below the hinge, so gravity pulls with
# 9.81·(1·0.5 + 0.5·1)·sin q = 9.81·sin q N·m; effort 5 N·m, damping 0.5 N·m·s/rad.
PENDULUM = """<?xml version="1.0"?>
<robot name="pend">
  <link name="world"/>
  <joint name="weld" type="fixed"><parent link="world"/><child link="base"/><origin xyz="0 0 1"/></joint>
  <link name="base">
    <inertial><mass value="1.0"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
  </link>
  <joint name="hinge" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="5" velocity="10"/><dynamics damping="0.5"/></joint>
  <link name="arm">
    <inertial><origin xyz="0 0 -0.5"/><mass value="1.0"/>
      <inertia ixx="0.001" iyy="0.001" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial>
  </link>
  <joint name="tip_j" type="fixed"><parent link="arm"/><child link="tip"/><origin xyz="0 0 -1"/></joint>
  <link name="tip">
    <inertial><mass value="0.5"/><inertia ixx="0.001" iyy="0.001" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial>
  </link>
</robot>
"""
KUKA_FREE = pybullet("kuka_iiwa", "model_free_base.urdf")
DT = 0.01


def _t(values):
    return torch.as_tensor(np.asarray(values, dtype=np.float64))


@pytest.fixture(scope="module")
def pendulum(tmp_path_factory):
    """(scene, pendulum): the 1-dof PENDULUM, unbatched, no gradients."""
    gs.init(precision="64", logging_level="warning")
    path = tmp_path_factory.mktemp("urdf") / "pendulum.urdf"
    path.write_text(PENDULUM)
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT))
    robot = scene.add_entity(gs.morphs.URDF(file=str(path), fixed=True), name="pendulum")
    scene.build()
    yield scene, robot
    scene.destroy()


@pytest.fixture(scope="module")
def two_robots():
    """(scene, free KUKA, 2-link pendulum) in one scene with n_envs=2, no gradients."""
    gs.init(precision="64", logging_level="warning")
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT))
    kuka = scene.add_entity(gs.morphs.URDF(file=KUKA_FREE, fixed=False), name="kuka")
    other = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True), name="other")
    scene.build(n_envs=2)
    yield scene, kuka, other
    scene.destroy()


@pytest.fixture(scope="module")
def graph():
    """(scene, 2-link pendulum) with requires_grad, 2 substeps."""
    gs.init(precision="64", logging_level="warning")
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT, substeps=2, requires_grad=True))
    robot = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True), name="pendulum2")
    scene.build()
    yield scene, robot
    scene.destroy()


# -- zero_velocity (§Q1) --------------------------------------------------------------------------------
def _fill_velocities(kuka, other, rng):
    kuka.set_dofs_velocity(_t(rng.uniform(-1, 1, (2, kuka.n_dofs))))
    other.set_dofs_velocity(_t(rng.uniform(-1, 1, (2, other.n_dofs))))
    return kuka.get_dofs_velocity().clone(), other.get_dofs_velocity().clone()


SETTERS = {  # name → (call with envs_idx and zero_velocity), each writing something for one env
    "set_dofs_position": lambda r, envs, **kw: r.set_dofs_position(_t([[0.3]]), [6], envs, **kw),
    "set_qpos": lambda r, envs, **kw: r.set_qpos(_t([[0.2, -0.1]]), [7, 8], envs, **kw),
    "set_pos": lambda r, envs, **kw: r.set_pos(_t([[0.1, 0.2, 0.5]]), envs, **kw),
    "set_quat": lambda r, envs, **kw: r.set_quat(_t([[0.0, 1.0, 0.0, 0.0]]), envs, **kw),
}


@pytest.mark.parametrize("setter", list(SETTERS))
def test_zero_velocity_zeroes_every_dof_of_the_entity_in_the_selected_envs(f64, two_robots, setter):
    scene, kuka, other = two_robots
    scene.reset()
    rng = np.random.default_rng(0)
    kuka_v, other_v = _fill_velocities(kuka, other, rng)
    SETTERS[setter](kuka, [1])  # default zero_velocity=True: all 13 dofs of env 1, whatever was set
    assert torch.equal(kuka.get_dofs_velocity()[1], torch.zeros(kuka.n_dofs, dtype=torch.float64))
    assert torch.equal(kuka.get_dofs_velocity()[0], kuka_v[0])
    assert torch.equal(other.get_dofs_velocity(), other_v), f"{setter} touched another entity"

    kuka_v, _ = _fill_velocities(kuka, other, rng)
    SETTERS[setter](kuka, [0], zero_velocity=False)
    assert torch.equal(kuka.get_dofs_velocity(), kuka_v)

    keyword = inspect.signature(getattr(kuka, setter)).parameters["zero_velocity"]
    assert keyword.kind is inspect.Parameter.KEYWORD_ONLY and keyword.default is True  # as in Genesis


def test_zero_velocity_all_envs_by_default(f64, two_robots):
    scene, kuka, other = two_robots
    scene.reset()
    _fill_velocities(kuka, other, np.random.default_rng(1))
    kuka.set_dofs_position(_t([[0.1], [0.2]]), [7])
    assert not kuka.get_dofs_velocity().any()
    assert other.get_dofs_velocity().all()


def test_zero_all_dofs_velocity_and_default_velocity_as_genesis(f64, two_robots):
    scene, kuka, other = two_robots
    scene.reset()
    rng = np.random.default_rng(2)
    kuka_v, other_v = _fill_velocities(kuka, other, rng)
    position = kuka.get_dofs_position().clone()
    kuka.zero_all_dofs_velocity([1])
    assert not kuka.get_dofs_velocity()[1].any() and torch.equal(kuka.get_dofs_velocity()[0], kuka_v[0])
    assert torch.equal(other.get_dofs_velocity(), other_v) and torch.equal(kuka.get_dofs_position(), position)
    kuka.zero_all_dofs_velocity()
    assert not kuka.get_dofs_velocity().any()
    other.set_dofs_velocity(dofs_idx_local=[1], envs_idx=[0])  # velocity=None: zeros
    assert other.get_dofs_velocity()[0, 1] == 0.0 and torch.equal(other.get_dofs_velocity()[1], other_v[1])
    assert other.get_dofs_velocity()[0, 0] == other_v[0, 0]


def test_zero_velocity_cuts_earlier_velocities_out_of_the_graph(f64, graph):
    """With gradients the zeroed velocities are constants: a velocity set before a position setter
    gets no gradient (it no longer acts); with zero_velocity=False it does."""
    scene, robot = graph
    grads = {}
    for zero in (True, False):
        scene.reset()
        q0 = _t([0.3, -0.2]).requires_grad_(True)
        v0 = _t([0.5, 1.0]).requires_grad_(True)
        robot.set_dofs_velocity(v0)
        robot.set_dofs_position(q0, zero_velocity=zero)
        if zero:
            assert torch.equal(robot.get_dofs_velocity().detach(), torch.zeros(2, dtype=torch.float64))
        for _ in range(5):
            scene.step()
        loss = (robot.get_dofs_position() ** 2).sum() + robot.get_dofs_velocity().sum()
        grads[zero] = torch.autograd.grad(loss, (q0, v0), allow_unused=True)
    assert grads[True][1] is None and grads[True][0].abs().min() > 0
    assert grads[False][1] is not None and grads[False][1].abs().min() > 0


# -- a free base's Euler-angle dofs (§Q3) --------------------------------------------------------------
def _wxyz(rotation):
    xyzw = rotation.as_quat()
    return np.concatenate([xyzw[..., 3:], xyzw[..., :3]], axis=-1)


def _same_rotation(q1, q2, tol):
    """Unit quaternions equal up to sign."""
    return min(np.abs(q1 - q2).max(), np.abs(q1 + q2).max()) <= tol


def test_euler_maps_match_scipy_intrinsic_xyz(f64):
    rng = np.random.default_rng(0)
    angles = np.stack([rng.uniform(-3, 3, 200), rng.uniform(-1.5, 1.5, 200), rng.uniform(-3, 3, 200)], axis=1)
    quat = euler_xyz_to_quat(_t(angles)).numpy()
    ref = _wxyz(Rotation.from_euler("XYZ", angles))
    assert all(_same_rotation(a, b, 1e-14) for a, b in zip(quat, ref))
    back = quat_to_euler_xyz(_t(ref) * 2.5).numpy()  # any norm
    assert np.abs(back - Rotation.from_euler("XYZ", angles).as_euler("XYZ")).max() <= 1e-12
    assert np.abs(back - angles).max() <= 1e-12  # get ∘ set is the identity away from gimbal lock
    # Genesis: set_dofs_position([0, 0, 0, .1, .2, .3]) stores the quaternion (0.98186, 0.06407, 0.09116, 0.15344)
    assert np.allclose(euler_xyz_to_quat(_t([0.1, 0.2, 0.3])).numpy(), [0.98186, 0.06407, 0.09116, 0.15344], atol=1e-5)


def test_euler_maps_are_differentiable(f64):
    rng = np.random.default_rng(1)
    angles = _t(rng.uniform(-1.2, 1.2, (4, 3))).requires_grad_(True)
    assert torch.autograd.gradcheck(euler_xyz_to_quat, (angles,), eps=1e-6, atol=1e-9)
    quat = _t(rng.normal(size=(4, 4))).requires_grad_(True)
    assert torch.autograd.gradcheck(quat_to_euler_xyz, (quat,), eps=1e-6, atol=1e-9)
    # at gimbal lock only a + c is defined (Genesis: a = 0); the gradient stays finite
    locked = euler_xyz_to_quat(_t([[0.4, np.pi / 2, 0.3]])).requires_grad_(True)
    angles = quat_to_euler_xyz(locked)
    assert np.allclose(angles.detach().numpy(), [[0.0, np.pi / 2, 0.7]], atol=1e-7)
    angles.sum().backward()
    assert torch.isfinite(locked.grad).all()
    # quarter turns about y (exact lock: cos b = 0) and x (atan2(0, 0) in the lock formula)
    for quat, expected in (([1.0, 0.0, 1.0, 0.0], [0.0, np.pi / 2, 0.0]),
                           ([1.0, 1.0, 0.0, 0.0], [np.pi / 2, 0.0, 0.0])):
        quarter = _t(quat).requires_grad_(True)
        angles = quat_to_euler_xyz(quarter)
        assert np.allclose(angles.detach().numpy(), expected, rtol=0, atol=1e-15)
        angles.sum().backward()
        assert torch.isfinite(quarter.grad).all(), quat


def test_free_base_dofs_are_origin_and_euler_angles(f64, two_robots):
    scene, kuka, _ = two_robots
    scene.reset()
    # Genesis: a base at extrinsic euler (30, 45, 60)° has dofs 3-5 = (-0.4293, 0.8319, 1.0181)
    quat = _wxyz(Rotation.from_euler("xyz", [30, 45, 60], degrees=True))
    kuka.set_quat(_t([quat, quat]))
    assert np.allclose(kuka.get_dofs_position()[:, 3:6].numpy(), [-0.4293, 0.8319, 1.0181], atol=1e-4)
    rng = np.random.default_rng(2)
    dofs = rng.uniform(-1.2, 1.2, (2, kuka.n_dofs))
    kuka.set_dofs_position(_t(dofs))
    qpos = kuka.get_qpos().numpy()
    assert np.array_equal(qpos[:, :3], dofs[:, :3])
    assert np.allclose(kuka.get_pos().numpy(), dofs[:, :3], rtol=0, atol=1e-15)
    for e in range(2):
        assert _same_rotation(qpos[e, 3:7], _wxyz(Rotation.from_euler("XYZ", dofs[e, 3:6])), 1e-14)
    assert np.abs(kuka.get_dofs_position().numpy() - dofs).max() <= 1e-12


def test_free_base_partial_writes_keep_the_other_dofs(f64, two_robots):
    scene, kuka, _ = two_robots
    scene.reset()
    dofs = np.random.default_rng(3).uniform(-1.2, 1.2, (2, kuka.n_dofs))
    kuka.set_dofs_position(_t(dofs))
    qpos = kuka.get_qpos().clone()
    kuka.set_dofs_position(_t([[0.7]]), [4], envs_idx=[1])  # one angle of env 1
    expected = dofs.copy()
    expected[1, 4] = 0.7
    assert np.abs(kuka.get_dofs_position().numpy() - expected).max() <= 1e-12
    assert torch.equal(kuka.get_qpos()[0], qpos[0])
    assert torch.equal(kuka.get_qpos()[1, list(range(3)) + list(range(7, kuka.n_qs))],
                       qpos[1, list(range(3)) + list(range(7, kuka.n_qs))])
    before = kuka.get_qpos().clone()
    kuka.set_dofs_position(_t([[1.5, 0.25], [2.5, -0.25]]), [0, 8])  # linear dofs leave the quaternion alone
    after = kuka.get_qpos()
    assert torch.equal(after[:, 3:7], before[:, 3:7])
    assert after[:, 0].tolist() == [1.5, 2.5]


def test_set_pos_on_a_fixed_entity_says_what_to_do(f64, pendulum):
    _, robot = pendulum
    for call in (lambda: robot.set_pos([0.0, 0.0, 1.0]), lambda: robot.set_quat([1.0, 0.0, 0.0, 0.0])):
        with pytest.raises(gs.InvalidInputError) as info:
            call()
        message = str(info.value)
        for part in ("entity 'pendulum'", "free base", "got a fixed one", "pos/euler", "fixed=False to move it"):
            assert part in message, message


# -- get_dofs_control_force, control_dofs_position_velocity (§Q4, Q6) -----------------------------------
def test_control_force_is_the_command_at_the_current_state(f64, pendulum):
    scene, robot = pendulum
    scene.reset()
    assert robot.get_dofs_control_force().tolist() == [0.0]  # force mode, command 0
    robot.set_dofs_position([0.3])
    robot.control_dofs_position([0.0])
    assert robot.get_dofs_control_force().tolist() == [-5.0]  # Genesis: kp·(0 − 0.3) = −30, clipped to ±5
    robot.set_dofs_force_range([-1000.0], [1000.0])
    try:
        assert np.isclose(float(robot.get_dofs_control_force()), -30.0, rtol=0, atol=1e-12)
        scene.step()  # from then on, the command at the new state (Genesis: −26.2185 after one step)
        q, v = float(robot.get_dofs_position()), float(robot.get_dofs_velocity())
        assert np.isclose(float(robot.get_dofs_control_force()), 100 * (0 - q) - 10 * v, rtol=0, atol=1e-12)
        robot.control_dofs_velocity([1.0])
        assert np.isclose(float(robot.get_dofs_control_force()), 10 * (1.0 - v), rtol=0, atol=1e-12)
        robot.control_dofs_position_velocity([0.5], [2.0])
        assert np.isclose(float(robot.get_dofs_control_force()), 100 * (0.5 - q) + 10 * (2.0 - v), rtol=0, atol=1e-12)
        robot.control_dofs_position([0.5])  # the velocity target goes back to 0
        assert np.isclose(float(robot.get_dofs_control_force()), 100 * (0.5 - q) - 10 * v, rtol=0, atol=1e-12)
        robot.control_dofs_force([3.0])
        assert robot.get_dofs_control_force().tolist() == [3.0]
    finally:
        robot.set_dofs_force_range([-5.0], [5.0])
    robot.control_dofs_position_velocity([0.5], [2.0])
    assert robot.get_dofs_control_force().tolist() == [5.0]  # Genesis: clipped to the effort 5


def test_control_force_on_its_bound_has_the_steps_gradient(f64, tmp_path):
    """A force command exactly on its bound is the bound, in its gradient too: none to the command,
    all to the bound, as the step's reverse takes it (actuation.py; torch.minimum split it 0.5 / 0.5)."""
    path = tmp_path / "pendulum.urdf"
    path.write_text(PENDULUM)
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT, requires_grad=True))
    robot = scene.add_entity(gs.morphs.URDF(file=str(path), fixed=True))
    scene.build()
    command, bound = (torch.tensor([5.0], dtype=torch.float64, requires_grad=True) for _ in range(2))
    robot.set_dofs_force_range(-bound, bound)
    robot.control_dofs_force(command)
    grads = torch.autograd.grad(robot.get_dofs_control_force().sum(), (command, bound))
    assert [float(g) for g in grads] == [0.0, 1.0]


def test_force_range_may_be_unbounded(f64, pendulum):
    """±inf is no bound, as Genesis's default (a Genesis script restoring it works); NaN is refused."""
    scene, robot = pendulum
    scene.reset()
    robot.set_dofs_position([0.3])
    robot.control_dofs_position([0.0])
    robot.set_dofs_force_range([-float("inf")], [float("inf")])
    try:
        assert np.isclose(float(robot.get_dofs_control_force()), -30.0, rtol=0, atol=1e-12)
        with pytest.raises(gs.InvalidInputError, match="argument 'upper' must be free of NaN"):
            robot.set_dofs_force_range([-1.0], [float("nan")])
        # a lower bound of +inf (or an upper of -inf) clipped every force to infinity: the state went NaN
        # (found by an adversarial pass)
        with pytest.raises(gs.InvalidInputError, match="argument 'lower' must be finite or -inf"):
            robot.set_dofs_force_range([float("inf")], [float("inf")])
        with pytest.raises(gs.InvalidInputError, match="argument 'upper' must be finite or inf"):
            robot.set_dofs_force_range([-float("inf")], [-float("inf")])
    finally:
        robot.set_dofs_force_range([-5.0], [5.0])


def test_control_force_mixed_modes_batched(f64, two_robots):
    scene, kuka, other = two_robots
    scene.reset()
    rng = np.random.default_rng(4)
    q, v = rng.uniform(-1, 1, (2, 2)), rng.uniform(-1, 1, (2, 2))
    other.set_dofs_position(_t(q))
    other.set_dofs_velocity(_t(v))
    kp, kv = other.get_dofs_kp().numpy(), other.get_dofs_kv().numpy()
    other.control_dofs_position_velocity(_t([[0.2], [0.3]]), _t([[0.5], [-0.5]]), [0])
    other.control_dofs_velocity(_t([[1.0]]), [1], envs_idx=[1])
    other.control_dofs_force(_t([[0.7]]), [1], envs_idx=[0])
    expected = np.array([
        [kp[0, 0] * (0.2 - q[0, 0]) + kv[0, 0] * (0.5 - v[0, 0]), 0.7],
        [kp[1, 0] * (0.3 - q[1, 0]) + kv[1, 0] * (-0.5 - v[1, 0]), kv[1, 1] * (1.0 - v[1, 1])]])
    lo, hi = other.get_dofs_force_range()
    expected = np.clip(expected, lo.numpy(), hi.numpy())
    assert np.abs(other.get_dofs_control_force().numpy() - expected).max() <= 1e-12
    assert np.abs(other.get_dofs_control_force([1], envs_idx=[1]).numpy() - expected[1:, 1:]).max() <= 1e-12


def test_batched_setters_broadcast_one_row(f64, two_robots):
    """In a batched scene a value of one row applies to every env of envs_idx, as Genesis
    broadcasts; a row per env still sets each its own."""
    scene, kuka, other = two_robots
    scene.reset()
    other.set_dofs_kp(_t([30.0, 40.0]))
    assert other.get_dofs_kp().tolist() == [[30.0, 40.0], [30.0, 40.0]]
    other.set_dofs_kv(_t([1.5]), [1], envs_idx=[1])
    assert other.get_dofs_kv()[:, 1].tolist()[1] == 1.5
    other.set_dofs_position(_t([0.2, -0.1]))
    assert other.get_dofs_position().tolist() == [[0.2, -0.1], [0.2, -0.1]]
    other.set_dofs_position(_t([[0.3, 0.0], [0.4, 0.1]]))
    assert other.get_dofs_position().tolist() == [[0.3, 0.0], [0.4, 0.1]]
    with pytest.raises(gs.InvalidInputError, match=r"\(2, 2\) or \(2,\) for every env \(or one that broadcasts to "
                                                   r"it\), got \(3,\)"):
        other.set_dofs_position(_t([0.1, 0.2, 0.3]))
    # Genesis's broadcasting: a scalar everywhere, one row (1, k) to every env, (B,) to one dof of each env
    other.set_dofs_kp(25.0)
    assert other.get_dofs_kp().tolist() == [[25.0, 25.0], [25.0, 25.0]]
    other.set_dofs_position(_t([[0.5, 0.6]]))
    assert other.get_dofs_position().tolist() == [[0.5, 0.6], [0.5, 0.6]]
    other.set_dofs_velocity(_t([1.0, 2.0]), [1])
    assert other.get_dofs_velocity()[:, 1].tolist() == [1.0, 2.0]
    for bad in (_t([[0.1, 0.2, 0.3]]), _t([[[0.1, 0.2]]] * 2), _t([0.1, 0.2, 0.3])):
        with pytest.raises(gs.InvalidInputError, match="or one that broadcasts to it"):
            other.set_dofs_position(bad)


def test_setters_take_the_values_at_the_call(f64, graph):
    """A tensor the caller refills in place after a setter (a control buffer reused every step)
    changes neither what the scene holds nor the graph: values are copied at the call, as Genesis
    writes them into its fields; the gradient through a reused buffer equals that through fresh
    tensors, bit for bit."""
    scene, robot = graph
    scene.reset()
    position, gravity = _t([0.3, -0.2]), _t([0.0, 0.0, -9.81])
    robot.set_dofs_position(position)
    scene.set_gravity(gravity)
    position += 1.0
    gravity[2] = 0.0
    assert robot.get_dofs_position().tolist() == [0.3, -0.2] and scene.get_gravity().tolist() == [0.0, 0.0, -9.81]
    forces = _t(np.random.default_rng(3).normal(0.0, 1.0, (4, 2))).requires_grad_(True)

    def rollout(reuse):
        scene.reset()
        buffer = torch.zeros(2, dtype=torch.float64)
        for force in forces:
            if reuse:
                buffer.copy_(force)
            robot.control_dofs_force(buffer if reuse else force * 1.0)
            if reuse:
                buffer.fill_(100.0)  # after the call: must not reach the step
            scene.step()
        final = robot.get_dofs_position()
        (grad,) = torch.autograd.grad(final.sum(), forces)
        return final.detach(), grad

    fresh, reused = rollout(False), rollout(True)
    assert torch.equal(fresh[0], reused[0]) and torch.equal(fresh[1], reused[1])
    assert fresh[1].abs().sum() > 0


def test_control_force_is_differentiable(f64, graph):
    scene, robot = graph
    scene.reset()
    target = _t([0.1, -0.1]).requires_grad_(True)
    robot.control_dofs_position(target)
    (grad,) = torch.autograd.grad(robot.get_dofs_control_force().sum(), target)
    assert torch.equal(grad, robot.get_dofs_kp().detach())


def _rollout(scene, robot, pos_targets, vel_targets, kv, horizon=30):
    """Loss of a servoed rollout of the 2-link pendulum (kp 10; moderate gains stay stable)."""
    scene.reset()
    robot.set_dofs_position([0.3, -0.4])
    robot.set_dofs_velocity([0.5, -0.2])
    robot.set_dofs_kp([10.0, 10.0])
    robot.set_dofs_kv(kv)
    loss = 0.0
    for t in range(horizon):
        robot.control_dofs_position_velocity(pos_targets[t], vel_targets[t])
        scene.step()
        loss = loss + robot.get_links_pos()[-1].sin().sum() * 0.1
    return loss + (robot.get_dofs_position() ** 2).sum() + robot.get_dofs_velocity().cos().sum()


@pytest.mark.parametrize("which", [0, 1, 2], ids=["position", "velocity", "kv"])
def test_position_velocity_targets_gradient_matches_finite_differences(f64, graph, which):
    """The position servo's velocity target and kv through kv·(v* − q̇): hand-written adjoint vs
    fourth-order central differences (relative to the gradient's norm, as in test_gradients)."""
    scene, robot = graph
    rng = np.random.default_rng(5)
    inputs = [_t(rng.uniform(-0.5, 0.5, (30, 2))), _t(rng.uniform(-1, 1, (30, 2))), _t([0.6, 0.9])]
    direction = _t(rng.normal(size=inputs[which].shape))
    direction /= direction.norm()
    x = [t.clone().requires_grad_(k == which) for k, t in enumerate(inputs)]
    _rollout(scene, robot, *x).backward()
    grad = x[which].grad
    analytic = float((grad * direction).sum())
    eps = 1e-6
    with torch.no_grad():
        f = {}
        for k in (-2, -1, 1, 2):
            moved = list(inputs)
            moved[which] = inputs[which] + k * eps * direction
            f[k] = float(_rollout(scene, robot, *moved))
    numeric = (f[-2] - 8 * f[-1] + 8 * f[1] - f[2]) / (12 * eps)
    assert analytic != 0.0
    assert abs(analytic - numeric) <= 1e-6 * float(grad.norm()), (analytic, numeric)


# -- get_dofs_force (§Q4) ------------------------------------------------------------------------------
def test_dofs_force_of_the_pendulum_is_analytic(f64, pendulum):
    """The last step's force, from its start state: actuator (clipped) − damping·q̇ − gravity; zeros
    before a step and after a setter (no step since), as Genesis's buffer before its first step."""
    scene, robot = pendulum
    q, v = 0.3, 0.7
    gravity = 9.81 * np.sin(q)  # N·m, pulling back to q = 0
    for control, expected in ((None, -0.5 * v - gravity), (0.0, -5.0 - 0.5 * v - gravity),
                              (1000.0, 100 * (0.0 - q) - 10 * v - 0.5 * v - gravity)):
        scene.reset()
        robot.set_dofs_position([q])
        robot.set_dofs_velocity([v])
        assert float(robot.get_dofs_force()) == 0.0
        if control is not None:
            robot.set_dofs_force_range([-control - 5.0], [control + 5.0])
            robot.control_dofs_position([0.0])
        scene.step()
        assert np.isclose(float(robot.get_dofs_force()), expected, rtol=0, atol=1e-12), control
    robot.set_dofs_force_range([-5.0], [5.0])


def test_dofs_force_is_what_the_last_step_applied(f64, two_robots):
    """q̇' = q̇ + h·A⁻¹·get_dofs_force() after a step, with A = get_mass_mat() + h·diag(damping + kv
    of the dofs in a servo mode) at its start (semi-implicit Euler, implicit damping and servo kv, as
    Genesis); the actuator's share is get_dofs_control_force() at the start (the same step without
    the controls)."""
    scene, kuka, other = two_robots
    rng = np.random.default_rng(6)
    start = {robot: (_t(rng.uniform(-1, 1, (2, robot.n_dofs))), _t(rng.uniform(-1, 1, (2, robot.n_dofs))))
             for robot in (kuka, other)}
    kuka_forces = _t(rng.uniform(-5, 5, (2, kuka.n_dofs)))

    def from_start(controlled):
        scene.reset()
        for robot, (position, velocity) in start.items():
            robot.set_dofs_position(position)
            robot.set_dofs_velocity(velocity)
        if controlled:
            other.control_dofs_position_velocity(_t([[0.2], [0.3]]), _t([[0.5], [-0.5]]), [0])
            other.control_dofs_velocity(_t([[1.0], [-1.0]]), [1])
            kuka.control_dofs_force(kuka_forces)

    from_start(controlled=True)
    predicted, actuator = {}, {}
    for robot in (kuka, other):
        damping, qvel = robot.get_dofs_damping().numpy(), robot.get_dofs_velocity().numpy()
        if robot is other:  # both its dofs are servoed
            damping = damping + robot.get_dofs_kv().numpy()
        matrix = robot.get_mass_mat().numpy() + DT * np.eye(robot.n_dofs) * damping[:, None, :]
        predicted[robot] = lambda force, qvel=qvel, matrix=matrix: \
            qvel + DT * np.linalg.solve(matrix, force[..., None])[..., 0]
        actuator[robot] = robot.get_dofs_control_force().numpy()
    scene.step()
    forces = {robot: robot.get_dofs_force().numpy() for robot in (kuka, other)}
    for robot in (kuka, other):
        err = np.abs(robot.get_dofs_velocity().numpy() - predicted[robot](forces[robot])).max()
        assert err <= 1e-10, f"{robot.name}: max |q̇' − predicted| = {err:.3g}"
    from_start(controlled=False)
    scene.step()
    for robot in (kuka, other):
        assert np.abs(forces[robot] - robot.get_dofs_force().numpy() - actuator[robot]).max() <= 1e-10, robot.name


def test_dofs_force_of_a_free_base_is_its_weight_then_nothing_at_rest_on_a_plane(f64):
    """A step from rest in the air: the free base's force is its weight (Genesis's dofs force, as
    MuJoCo's qfrc_smooth + qfrc_constraint); on a plane, once it rests: nothing (the contacts hold
    its weight: Genesis 1.4.5 gives 0 for a resting box too)."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT), show_viewer=False)
    plane = scene.add_entity(gs.morphs.Plane(pos=(0.0, 0.0, -1.0)))
    box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.2, 0.2), pos=(0.0, 0.0, 0.5)))
    scene.build(n_envs=2)
    scene.step()
    weight = box.get_mass().numpy() * -9.81  # N, on the world-linear dofs
    force = box.get_dofs_force().numpy()
    assert len(box.get_contacts(with_entity=plane)["valid_mask"].nonzero()) == 0
    assert np.abs(force[:, [0, 1, 3, 4, 5]]).max() == 0.0 and np.abs(force[:, 2] - weight).max() <= 1e-12
    for _ in range(200):
        scene.step()
    assert box.get_contacts(with_entity=plane)["valid_mask"].sum() == 8
    assert np.abs(box.get_dofs_force().numpy()).max() < 1e-9


def test_dofs_force_is_not_differentiable(f64, graph):
    scene, robot = graph
    scene.reset()
    robot.control_dofs_force(_t([0.1, 0.2]).requires_grad_(True))  # only an input requires grad
    scene.step()
    with pytest.raises(gs.GradientError, match="get_dofs_force"):
        robot.get_dofs_force().sum().backward()


# -- get_mass_mat (§Q5) --------------------------------------------------------------------------------
def test_mass_matrix_includes_armature(f64, pendulum):
    scene, robot = pendulum
    scene.reset()
    assert robot.get_dofs_armature().tolist() == [0.1]  # (Genesis's default_armature)
    assert np.isclose(float(robot.get_mass_mat()), 0.852, rtol=0, atol=1e-12)  # Genesis: 0.752 + armature
    robot.get_mass_mat().zero_()  # a copy: the next call computes it again
    assert np.isclose(float(robot.get_mass_mat()), 0.852, rtol=0, atol=1e-12)
    robot.set_dofs_armature([0.0])
    try:
        assert np.isclose(float(robot.get_mass_mat()), 0.752, rtol=0, atol=1e-12)  # 1·0.5² + 0.001 + 0.5·1² + 0.001
    finally:
        robot.set_dofs_armature([0.1])


def test_mass_matrix_decomposition(f64, two_robots):
    scene, kuka, other = two_robots
    scene.reset()
    rng = np.random.default_rng(7)
    kuka.set_dofs_position(_t(rng.uniform(-1, 1, (2, kuka.n_dofs))))
    armature = kuka.get_dofs_armature().clone()
    kuka.set_dofs_armature(_t(rng.uniform(0.01, 0.1, (2, kuka.n_dofs))))
    try:
        mass = kuka.get_mass_mat()
        lower, d_inv = kuka.get_mass_mat(decompose=True)
        assert lower.shape == (2, kuka.n_dofs, kuka.n_dofs) and d_inv.shape == (2, kuka.n_dofs)
        assert torch.equal(lower.diagonal(dim1=-2, dim2=-1), torch.ones(2, kuka.n_dofs, dtype=torch.float64))
        assert torch.equal(lower.triu(1), torch.zeros_like(lower))
        rebuilt = lower.transpose(-2, -1) @ torch.diag_embed(1.0 / d_inv) @ lower
        assert (rebuilt - mass).abs().max() <= 1e-12 * mass.abs().max()
        one_lower, one_d_inv = kuka.get_mass_mat(envs_idx=[1], decompose=True)
        assert one_lower.shape == (1, kuka.n_dofs, kuka.n_dofs) and torch.allclose(one_d_inv[0], d_inv[1])
        with pytest.raises(gs.InvalidInputError, match="'decompose' must be True or False, got 'no'"):
            kuka.get_mass_mat(decompose="no")  # (was read as true)
    finally:
        kuka.set_dofs_armature(armature)
    lower, d_inv = other.get_mass_mat(decompose=True)  # a two-link chain: d_inv[1] = 1 / M[1, 1]
    assert torch.allclose(d_inv[:, 1], 1.0 / other.get_mass_mat()[:, 1, 1], rtol=1e-14, atol=0)
    # one entity's block of a two-entity scene, its own armature on the diagonal, per env
    before, other_armature = other.get_mass_mat(), other.get_dofs_armature().clone()
    other.set_dofs_armature(other_armature + _t([[0.5, 0.0], [0.0, 0.25]]))
    try:
        added = other.get_mass_mat() - before
        assert torch.allclose(added, torch.diag_embed(_t([[0.5, 0.0], [0.0, 0.25]])), rtol=0, atol=1e-12)
    finally:
        other.set_dofs_armature(other_armature)


# -- friction loss -------------------------------------------------------------------------------------
def test_frictionloss_holds_and_releases_the_pendulum(f64, pendulum):
    """get/set_dofs_frictionloss round trip (the URDF gives none); a bound above the gravity torque
    at 0.5 rad (9.81 sin 0.5 = 4.7 N·m) nearly holds the pendulum (MuJoCo's soft friction lets it
    creep), a bound F below it lets it swing as if the torque were 4.7 − F (the row saturates at
    F while it slides): over 0.2 s it turns (4.7 − 1)/4.7 = 0.79 as far with F = 1; a negative
    bound is refused by name."""
    scene, robot = pendulum
    swings = {}
    scene.reset()
    assert robot.get_dofs_frictionloss().tolist() == [0.0]
    for bound in (0.0, 1.0, 20.0):
        scene.reset()  # friction loss is a parameter: it persists through resets, as damping does
        robot.set_dofs_frictionloss([bound])
        assert robot.get_dofs_frictionloss().tolist() == [bound]
        robot.set_dofs_position([0.5])
        for _ in range(20):
            scene.step()
        swings[bound] = 0.5 - robot.get_dofs_position().item()
    robot.set_dofs_frictionloss([0.0])
    torque = 9.81 * np.sin(0.5)
    assert swings[0.0] > 0.1 and abs(swings[1.0] / swings[0.0] - (torque - 1.0) / torque) < 0.02, swings
    assert 0.0 < swings[20.0] < 0.02 * swings[0.0], swings
    with pytest.raises(gs.InvalidInputError, match="entity 'pendulum': argument 'frictionloss' must be ≥ 0"):
        robot.set_dofs_frictionloss([-1.0])


# -- joint springs -------------------------------------------------------------------------------------
def test_joint_spring_is_the_damped_oscillator_and_refuses_bad_values(f64, pendulum):
    """get/set_dofs_stiffness round trip (a URDF has no springs: 0), persistent through reset, as the
    other dof parameters. Without gravity the pendulum (damping b = 0.5) on a spring k is the
    oscillator I q̈ = −k q − b q̇, I = M[0, 0] (constant for one revolute joint); the step is its
    semi-implicit Euler with the damping implicit and the spring explicit (MuJoCo's and Genesis's
    rule): q̇⁺ = q̇ + h (−k q − b q̇) / (I + h b), q⁺ = q + h q̇⁺. 150 steps from q0 = 0.3 rad at rest
    (two periods) follow that recurrence to round-off. Negative stiffness is refused by name."""
    scene, robot = pendulum
    scene.reset()
    assert robot.get_dofs_stiffness().tolist() == [0.0]
    stiffness, damping = 7.0, float(robot.get_dofs_damping()[0])
    robot.set_dofs_stiffness([stiffness])
    scene.reset()
    assert robot.get_dofs_stiffness().tolist() == [stiffness] and damping == 0.5
    scene.set_gravity((0.0, 0.0, 0.0))
    try:
        robot.set_dofs_position([0.3])
        inertia = float(robot.get_mass_mat()[0, 0])
        q, qd, worst = 0.3, 0.0, 0.0
        for _ in range(150):
            scene.step()
            qd += DT * (-stiffness * q - damping * qd) / (inertia + DT * damping)
            q += DT * qd
            worst = max(worst, abs(robot.get_dofs_position().item() - q), abs(robot.get_dofs_velocity().item() - qd))
        assert worst < 1e-13, worst
    finally:
        scene.set_gravity((0.0, 0.0, -9.81))
        robot.set_dofs_stiffness([0.0])
    with pytest.raises(gs.InvalidInputError, match="entity 'pendulum': argument 'stiffness' must be ≥ 0"):
        robot.set_dofs_stiffness([-1.0])


def test_a_free_joint_takes_no_spring(f64):
    scene = gs.Scene()
    box = scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1)), name="box")
    scene.build()
    box.set_dofs_stiffness(0.0)
    with pytest.raises(gs.InvalidInputError, match=r"entity 'box': argument 'stiffness' must be 0 on the free "
                                                   r"joint's dofs \(local \[2\]\)"):
        box.set_dofs_stiffness([3.0], dofs_idx_local=[2])
    scene.destroy()


def test_genesis_franka_gains_hold_the_arm(f64):
    """Genesis's control_franka tutorial gains (kp up to 4500, kv up to 450) on pybullet's Panda at
    dt 10 ms: the servos' kv is implicit, as Genesis's default integrator makes it, so the arm holds
    its target, off by its gravity torque over kp (measured 7.7e-3 rad) and at rest. (With kv
    explicit, h·kv/inertia ≫ 2 on the distal joints: the arm chattered 0.14 rad off at 4 rad/s.)"""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01))
    arm = scene.add_entity(gs.morphs.URDF(file=pybullet("franka_panda", "panda.urdf"), fixed=True))
    scene.build()
    arm.set_dofs_kp(_t([4500, 4500, 3500, 3500, 2000, 2000, 2000, 100, 100]))
    arm.set_dofs_kv(_t([450, 450, 350, 350, 200, 200, 200, 10, 10]))
    target = _t([0.5, 0.3, 0.0, -1.5, 0.0, 1.5, 0.5, 0.02, 0.02])
    arm.set_dofs_position(target)
    arm.control_dofs_position(target)
    for _ in range(200):
        scene.step()
    assert (arm.get_dofs_position() - target).abs().max() < 0.01
    assert arm.get_dofs_velocity().abs().max() < 1e-6


# -- found porting Genesis scripts (2026-11-28) ------------------------------------------------------
def test_add_entity_takes_genesis_arguments_in_genesis_order(f64):
    """add_entity(morph, material, surface, visualize_contact, vis_mode, name): Genesis's order, so a
    positional visualize_contact is not taken for a name; it must be a bool, vis_mode what the
    cameras can draw, and a name a string."""
    scene = gs.Scene()
    box = scene.add_entity(gs.morphs.Box(), None, None, False, "visual")
    assert box.name == "box_0" and scene.add_entity(gs.morphs.Sphere(), visualize_contact=np.False_).name == "sphere_1"
    for kwargs, arg in [({"visualize_contact": 1}, "visualize_contact"), ({"vis_mode": "sdf"}, "vis_mode"),
                        ({"name": 5}, "name")]:
        with pytest.raises(gs.InvalidInputError, match=f"argument '{arg}'"):
            scene.add_entity(gs.morphs.Sphere(), **kwargs)
    with pytest.raises(gs.InvalidInputError, match="'particle'"):
        scene.add_entity(gs.morphs.Box(), gs.materials.MPM.Elastic(), vis_mode="visual")
    # the surface's vis_mode (every Genesis MPM tutorial sets it), checked alike; add_entity's is taken first
    scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.5), size=(0.1, 0.1, 0.1)), gs.materials.MPM.Elastic(),
                     gs.surfaces.Default(vis_mode="particle"))
    with pytest.raises(gs.InvalidInputError, match="the surface's vis_mode must be None or 'visual' .*got 'particle'"):
        scene.add_entity(gs.morphs.Sphere(), surface=gs.surfaces.Default(color=(1, 0, 0), vis_mode="particle"))
    scene.add_entity(gs.morphs.Sphere(), surface=gs.surfaces.Default(vis_mode="particle"), vis_mode="visual")
    with pytest.raises(gs.InvalidInputError, match="surfaces.Default: argument 'vis_mode' must be None or a str"):
        gs.surfaces.Default(vis_mode=3)
    # Genesis's surface kinds: Default's arguments and drawing, Genesis's default colours, their look refused by name
    kinds = ["BSDF", "Plastic", "Rough", "Smooth", "Reflective", "Collision", "Metal", "Iron", "Aluminium", "Copper",
             "Gold", "Glass", "Water", "Emission"]
    for kind in kinds:
        surface = getattr(gs.surfaces, kind)(color=(0.2, 0.4, 0.6))
        assert isinstance(surface, gs.surfaces.Default) and surface.color == (0.2, 0.4, 0.6)
        with pytest.raises(gs.InvalidInputError, match=f"{kind}: argument 'roughness' is a Genesis option"):
            getattr(gs.surfaces, kind)(roughness=0.5)
        with pytest.raises(gs.InvalidInputError, match=f"surfaces.{kind}: argument 'color'"):
            getattr(gs.surfaces, kind)(color=(2.0, 0.0, 0.0))
    assert gs.surfaces.Collision().color == (0.5, 0.5, 0.5) and gs.surfaces.Water().color == (0.61, 0.98, 0.93)
    assert gs.surfaces.Rough().color is None  # (the asset's own colours)
    tinted = scene.add_entity(gs.morphs.Sphere(pos=(1.0, 0.0, 0.5)), surface=gs.surfaces.Rough(color=(1, 0, 0)))
    assert tinted.surface.color == (1.0, 0.0, 0.0)


def test_tensor_without_data_is_a_named_error(f64, pendulum):
    _, robot = pendulum
    with pytest.raises(gs.InvalidInputError, match="entity 'pendulum'.*'position'.*meta"):
        robot.set_dofs_position(torch.zeros(1, device="meta"))


def test_boolean_masks_select_envs(f64):
    """envs_idx as a boolean mask over the envs (Genesis takes one) in setters, getters and reset."""
    scene = gs.Scene()
    box = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 1.0)))
    scene.build(n_envs=3)
    mask = torch.tensor([False, True, True])
    box.set_pos(torch.tensor([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]), envs_idx=mask)
    assert box.get_pos().tolist() == [[0.0, 0.0, 1.0], [1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]
    assert box.get_pos(envs_idx=np.array([True, False, True])).tolist() == [[0.0, 0.0, 1.0], [4.0, 5.0, 6.0]]
    scene.reset(envs_idx=[False, False, True])
    assert box.get_pos()[2].tolist() == [0.0, 0.0, 1.0] and box.get_pos()[1].tolist() == [1.0, 2.0, 3.0]
    with pytest.raises(gs.InvalidInputError, match=r"boolean mask must have shape \(3,\)"):
        box.set_pos(torch.zeros(1, 3), envs_idx=[True, False])


def test_negative_env_indices_count_from_the_end(f64):
    """An env index in [-n_envs, 0) counts from the end, as Genesis's (setters, getters, scene methods,
    reset); a setter given one env twice (as -1 and n − 1) is refused."""
    scene = gs.Scene()
    box = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 1.0)))
    scene.build(n_envs=3)
    box.set_pos(torch.tensor([[1.0, 2.0, 3.0]]), envs_idx=-1)
    assert box.get_pos().tolist() == [[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [1.0, 2.0, 3.0]]
    assert box.get_pos(envs_idx=torch.tensor([-1, -3])).tolist() == [[1.0, 2.0, 3.0], [0.0, 0.0, 1.0]]
    scene.set_gravity([0.0, 0.0, -1.0], envs_idx=[-2])
    assert scene.get_gravity(envs_idx=[1, -1]).tolist() == [[0.0, 0.0, -1.0], [0.0, 0.0, -9.81]]
    scene.reset(envs_idx=np.array([-1]))
    assert box.get_pos()[2].tolist() == [0.0, 0.0, 1.0]
    with pytest.raises(gs.InvalidInputError, match=r"'envs_idx' must not repeat an index.*\[2\]"):
        box.set_pos(torch.zeros(2, 3), envs_idx=[2, -1])


def test_contacts_have_genesis_normal_and_penetration(f64):
    """get_contacts' normal points from geom b to geom a and penetration is the overlap depth, as
    Genesis's; indices are int32, as Genesis's."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002))
    plane = scene.add_entity(gs.morphs.Plane())
    box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.2, 0.2), pos=(0.0, 0.0, 0.0995)))
    scene.build()
    scene.step()
    contacts = box.get_contacts(with_entity=plane)
    assert len(contacts["geom_a"]) == 4 and all(contacts[k].dtype == torch.int32 for k in ("geom_a", "link_b"))
    assert (contacts["geom_a"] == plane.geom_start).all()  # the plane is geom a: the normal points into it
    assert torch.allclose(contacts["normal"], torch.tensor([0.0, 0.0, -1.0], dtype=torch.float64).expand(4, 3))
    assert torch.allclose(contacts["penetration"], torch.full((4,), 0.0005, dtype=torch.float64), atol=1e-4)
    assert (contacts["penetration"] > 0).all() and (contacts["force_b"][:, 2] > 0).all()
    padded = box.get_contacts(with_entity=plane, is_padded=True)  # the slots, and a valid_mask, as Genesis
    assert padded["valid_mask"].shape == padded["geom_a"].shape == (scene._rigid_solver.data.size["C"],)
    assert torch.equal(padded["position"][padded["valid_mask"]], contacts["position"])


def test_joints_answer_genesis_deprecated_singular_names(f64, pendulum, caplog):
    _, robot = pendulum
    hinge = robot.get_joint("hinge")
    assert hinge.dof_idx_local == hinge.dofs_idx_local[0] and isinstance(hinge.dof_idx_local, int)
    assert hinge.dof_idx == robot.dof_start + hinge.dofs_idx_local[0] and hinge.q_idx_local == hinge.qs_idx_local[0]
    assert any("dof_idx_local is deprecated" in r.getMessage() for r in caplog.records)
    with pytest.raises(AttributeError, match="no attribute 'dofs_index'"):
        hinge.dofs_index



def test_joint_and_scene_indices_as_genesis(f64):
    """RigidJoint's n_qs, idx_local, dof/q start and end, and the scene's substeps, requires_grad,
    entity_names, get_entity (by name or uid) and base_joint, as Genesis's (a Genesis user's port met them
    missing)."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(substeps=2), show_viewer=False)
    scene.add_entity(gs.morphs.Plane(), name="floor")
    box = scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(0.0, 0.0, 0.5)), name="box")
    arm = scene.add_entity(gs.morphs.URDF(file=pybullet("kuka_iiwa", "model.urdf"), fixed=True), name="arm")
    scene.build()
    assert (scene.substeps, scene.requires_grad, scene.entity_names) == (2, False, ("floor", "box", "arm"))
    assert scene.get_entity("box") is box and scene.get_entity(name="arm") is arm
    with pytest.raises(gs.InvalidInputError, match=r"get_entity: argument 'name' must be the name of an entity of the "
                                                   r"scene \['floor', 'box', 'arm'\], got 'cup'"):
        scene.get_entity("cup")
    # Genesis's uid: 32 random hex digits, looked up by their first seven (its entity_name tutorial)
    uids = [entity.uid for entity in (scene.get_entity("floor"), box, arm)]
    assert len({str(uid) for uid in uids}) == 3 and all(len(str(uid)) == 32 for uid in uids)
    assert scene.get_entity(uid=box.uid.short()) is box and box.uid.match(str(box.uid))
    assert f"{box.uid}" == f"<{box.uid.short()}>" and box.uid.full() == f"{str(box.uid)[:7]}-{str(box.uid)[7:]}"
    with pytest.raises(gs.InvalidInputError, match=r"get_entity: argument 'uid' must be the short uid of an entity"):
        scene.get_entity(uid="zzzzzzz")
    with pytest.raises(gs.InvalidInputError, match=r"get_entity: expected one of the arguments 'name' and 'uid'"):
        scene.get_entity("box", uid=box.uid.short())
    root = box.joints[0]
    assert (root.n_dofs, root.n_qs, root.idx_local, root.dof_start, root.dof_end, root.q_start, root.q_end) == (
        6, 7, 0, 0, 6, 0, 7)
    assert box.base_joint is root and list(box.base_joint.dofs_idx) == list(range(6))
    with pytest.raises(gs.InvalidInputError, match=r"entity 'arm': base_joint: the base link .* is welded"):
        arm.base_joint
    last = arm.joints[-1]
    assert (last.n_qs, last.idx_local, last.dof_start, last.dof_end, last.q_start, last.q_end) == (
        1, 6, 12, 13, 13, 14)


@pytest.mark.parametrize("n_envs", [0, 2])
def test_rigid_entity_state_as_genesis(f64, n_envs):
    """get_state() holds the base link's pos and quat with a leading env axis (of 1 without envs), as
    Genesis's RigidEntityState (its differentiable tests' losses read box.get_state().pos); copies
    in the graph: a loss on them backpropagates as one on get_pos()."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(requires_grad=True), show_viewer=False)
    box = scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(0.0, 0.0, 1.0)))
    scene.build(n_envs=n_envs)
    B = max(1, n_envs)
    velocity = torch.zeros((*((n_envs,) if n_envs else ()), 6), dtype=torch.float64)
    velocity[..., 0] = 1.0
    velocity.requires_grad_(True)
    box.set_dofs_velocity(velocity)
    for _ in range(3):
        scene.step()
    state = box.get_state()
    assert state.pos.shape == (B, 3) and state.quat.shape == (B, 4) and isinstance(state.pos, gs.Tensor)
    assert torch.equal(state.pos, box.get_pos().reshape(B, 3)) and torch.equal(state.quat, box.get_quat().reshape(B, 4))
    grad, = torch.autograd.grad(state.pos[..., 0].sum(), velocity, retain_graph=True)
    reference, = torch.autograd.grad(box.get_pos()[..., 0].sum(), velocity)
    assert torch.equal(grad, reference) and float(grad[..., 0].sum()) > 0

def test_mass_of_an_entity_leaves_out_the_links_welded_to_the_world(f64):
    """get_mass sums the links that move, as Genesis's (a fixed base is never accelerated: its mass
    is the world's): a fixed Panda weighs all but its 2.9 kg base, a free one every link."""
    scene = gs.Scene(rigid_options=gs.options.RigidOptions(enable_collision=False), show_viewer=False)
    fixed = scene.add_entity(gs.morphs.URDF(file=pybullet("franka_panda", "panda.urdf"), fixed=True))
    free = scene.add_entity(gs.morphs.URDF(file=pybullet("franka_panda", "panda.urdf"), pos=(1.0, 0.0, 0.0)))
    scene.build(n_envs=2)
    links = fixed.get_links_mass()
    assert torch.equal(fixed.get_mass(), links[:, 1:].sum(-1)) and float(links[0, 0]) > 0
    assert torch.equal(free.get_mass(), free.get_links_mass().sum(-1))
    fixed.set_links_mass(np.array([50.0]), [0])  # the base: no change
    assert torch.equal(fixed.get_mass(), links[:, 1:].sum(-1))


def test_rigid_dt_sets_the_substeps_as_genesis(f64):
    """RigidOptions(dt) is the rigid substep (Genesis 1.4.5): SimOptions(dt=0.02) with
    RigidOptions(dt=0.01) runs exactly as SimOptions(dt=0.02, substeps=2)."""
    gs.init(precision="64", logging_level="warning")
    trajectories = []
    for sim, rigid in (({"substeps": 2}, {}), ({}, {"dt": 0.01}), ({"substeps": 2}, {"dt": 0.01})):
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.02, **sim),
                         rigid_options=gs.options.RigidOptions(**rigid))
        robot = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True))
        scene.build()
        assert scene.substeps == 2
        robot.set_dofs_position(_t([1.0, -0.5]))
        for _ in range(20):
            scene.step()
        trajectories.append(robot.get_dofs_position().clone())
        scene.destroy()
    assert torch.equal(trajectories[0], trajectories[1]) and torch.equal(trajectories[0], trajectories[2])
    assert not torch.equal(trajectories[0], _t([1.0, -0.5]))
    conflicts = [({"substeps": 2}, {"dt": 0.02}, {}, "RigidOptions: argument 'dt' = 0.02 s makes 1 substeps per "
                  "step, but SimOptions.substeps = 2"),
                 ({}, {"dt": 0.015}, {}, "RigidOptions: argument 'dt' must divide SimOptions.dt = 0.02 s"),
                 ({}, {"dt": 0.01}, {"dt": 0.005}, "the solvers must integrate at one rate (one substep count per "
                  "step), got RigidOptions dt = 0.01 s (2 substeps), MPMOptions dt = 0.005 s (4 substeps)")]
    for sim, rigid, mpm, message in conflicts:
        with pytest.raises(gs.InvalidInputError) as info:
            gs.Scene(sim_options=gs.options.SimOptions(dt=0.02, **sim), rigid_options=gs.options.RigidOptions(**rigid),
                     mpm_options=gs.options.MPMOptions(**mpm))
        assert message in str(info.value)
    with pytest.raises(gs.InvalidInputError, match="RigidOptions: argument 'dt'"):
        gs.options.RigidOptions(dt=-0.01)


def test_aabb_bounds_the_shapes_as_genesis(f64, tmp_path):
    """get_AABB against the bounds of fine triangle meshes of the same shapes (trimesh), batched and
    not; turned shapes; a mesh; differentiable in the pose."""
    import trimesh
    gs.init(precision="64", logging_level="warning")
    rng = np.random.default_rng(3)
    hull = trimesh.creation.icosphere(subdivisions=1, radius=0.1)
    hull.vertices *= [1.0, 0.5, 2.0]
    hull.export(tmp_path / "hull.obj")
    morphs = {"box": (gs.morphs.Box(size=(0.2, 0.1, 0.4)), trimesh.creation.box((0.2, 0.1, 0.4))),
              "sphere": (gs.morphs.Sphere(radius=0.1), trimesh.creation.icosphere(6, 0.1)),
              "capsule": (gs.morphs.Capsule(radius=0.05, height=0.3),
                          trimesh.creation.capsule(height=0.3, radius=0.05, count=[256, 256])),
              "cylinder": (gs.morphs.Cylinder(radius=0.1, height=0.4),
                           trimesh.creation.cylinder(radius=0.1, height=0.4, sections=2048)),
              "mesh": (gs.morphs.Mesh(file=str(tmp_path / "hull.obj")), hull)}
    for n_envs in (0, 3):
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT, gravity=(0, 0, 0)))
        entities = {name: scene.add_entity(morph) for name, (morph, _) in morphs.items()}
        scene.build(n_envs=n_envs)
        batch = max(n_envs, 1)
        for name, entity in entities.items():
            pos, quat = rng.normal(size=(batch, 3)), rng.normal(size=(batch, 4))
            quat /= np.linalg.norm(quat, axis=1, keepdims=True)
            entity.set_pos(_t(pos if n_envs else pos[0]))
            entity.set_quat(_t(quat if n_envs else quat[0]))
            box = entity.get_AABB().numpy().reshape(batch, 2, 3)
            for e in range(batch):
                mesh = morphs[name][1].copy()
                mesh.apply_transform(trimesh.transformations.quaternion_matrix(quat[e]))
                mesh.apply_translation(pos[e])
                assert np.abs(box[e] - mesh.bounds).max() < 2e-5, (name, n_envs, box[e], mesh.bounds)
        if n_envs:
            assert entities["box"].get_AABB(envs_idx=[2]).shape == (1, 2, 3)
        scene.destroy()
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT, requires_grad=True))
    cylinder = scene.add_entity(gs.morphs.Cylinder(radius=0.1, height=0.4))
    scene.build()
    pos = _t([0.1, 0.2, 0.3]).requires_grad_(True)
    cylinder.set_pos(pos)
    cylinder.get_AABB()[1].sum().backward()  # upright: the rim's slope in x, y is 0, not NaN
    assert torch.equal(pos.grad, _t([1.0, 1.0, 1.0]))
    scene.destroy()
    # turned, every kind against central differences (float64), in the links' positions and quaternions
    from genesis_lite.entities.bounds import shapes_aabb
    from genesis_lite.solvers.rigid.spec import GeomSpec
    shapes = [(0, GeomSpec("box", np.array([0.2, 0.1, 0.4]), pos=np.array([0.1, 0.0, 0.0]))),
              (1, GeomSpec("capsule", np.array([0.05, 0.3]))), (1, GeomSpec("cylinder", np.array([0.1, 0.4]),
                                                                              quat=np.array([0.9, 0.3, 0.0, 0.1]))),
              (2, GeomSpec("mesh", np.zeros(0), vertices=hull.vertices))]
    link_pos = _t(rng.normal(size=(2, 3, 3))).requires_grad_(True)
    link_quat = _t(rng.normal(size=(2, 3, 4)))
    link_quat = (link_quat / link_quat.norm(dim=-1, keepdim=True)).requires_grad_(True)
    for chosen in ([0], [1], [2], [3], [0, 1, 2, 3]):
        assert torch.autograd.gradcheck(lambda p, q: shapes_aabb([shapes[k] for k in chosen], p, q),
                                        (link_pos, link_quat))


MERGED_BOXES = """<robot name="merged">
  <link name="base"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0.1 0 0.05" rpy="0.3 0 0.2"/><geometry><box size="0.2 0.1 0.05"/></geometry></collision></link>
  <link name="bracket"><inertial><mass value="0.5"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0 0.05 0" rpy="0 0.4 0"/><geometry><box size="0.05 0.3 0.1"/></geometry></collision></link>
  <link name="arm"><inertial><mass value="0.5"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0.15 0 0" rpy="0 0 0.7"/><geometry><box size="0.3 0.04 0.04"/></geometry></collision></link>
  <joint name="weld" type="fixed"><parent link="base"/><child link="bracket"/><origin xyz="0 0.2 0.1" rpy="0.5 0 0"/></joint>
  <joint name="hinge" type="revolute"><parent link="bracket"/><child link="arm"/><origin xyz="0 0.3 0" rpy="0 0 0.3"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="10" velocity="10"/></joint>
</robot>"""


def test_aabb_of_merged_links_and_offset_shapes_matches_the_urdf(f64, tmp_path):
    """A fixed link merged into its parent and shapes offset and turned in their links: the box of
    the URDF's collision boxes posed by yourdfpy's forward kinematics (trimesh's bounds, exact for
    boxes), at two joint angles."""
    gs.init(precision="64", logging_level="warning")
    path = tmp_path / "merged.urdf"
    path.write_text(MERGED_BOXES)
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT))
    robot = scene.add_entity(gs.morphs.URDF(file=str(path), fixed=True))
    scene.build()
    assert robot.n_links == 2  # (the bracket merged into the base)
    reference = yourdfpy.URDF.load(str(path), build_collision_scene_graph=True, load_collision_meshes=True)
    for angle in (0.0, 1.1):
        robot.set_dofs_position(_t([angle]))
        reference.update_cfg([angle])
        assert np.abs(robot.get_AABB().numpy() - reference.collision_scene.bounds).max() < 1e-12
    scene.destroy()


def test_link_level_getters_aabb_and_wrench_as_the_entity_s(f64, tmp_path):
    """RigidLink's get_vel/get_ang/get_mass/get_AABB, parent_idx, is_fixed and
    apply_external_force/torque/wrench (Genesis's link API) are the entity's for that link: the
    readouts equal its rows, the links' boxes make up the entity's, parents as in the URDF, and a
    link's wrench moves the scene as the entity's call for that link does (bit for bit)."""
    path = tmp_path / "merged.urdf"
    path.write_text(MERGED_BOXES)
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT), show_viewer=False)
    robot = scene.add_entity(gs.morphs.URDF(file=str(path), fixed=True))
    box = scene.add_entity(gs.morphs.Box(size=(0.1, 0.2, 0.3), pos=(2.0, 0.0, 1.0)))
    scene.build(n_envs=2)
    robot.set_dofs_velocity(_t([[0.7], [-0.4]]))
    box.set_dofs_velocity(_t([[0.1, 0.2, 0.3, 1.0, -2.0, 0.5], [0.0, 0.0, 0.0, 0.3, 0.0, 0.0]]))
    scene.step()
    for entity in (robot, box):
        for k, link in enumerate(entity.links):
            for getter, rows in ((link.get_vel, entity.get_links_vel), (link.get_ang, entity.get_links_ang),
                                 (link.get_pos, entity.get_links_pos)):
                assert torch.equal(getter(), rows()[:, k]) and torch.equal(getter([1]), rows(envs_idx=[1])[:, k])
            assert torch.equal(link.get_mass(), entity.get_links_mass()[:, k])
    boxes = torch.stack([link.get_AABB() for link in robot.links])
    assert torch.equal(torch.stack([boxes[:, :, 0].amin(0), boxes[:, :, 1].amax(0)], 1), robot.get_AABB())
    assert not torch.equal(boxes[0], boxes[1])
    assert torch.equal(box.links[0].get_AABB(), box.get_AABB())
    reference = yourdfpy.URDF.load(str(path))
    child = reference.joint_map[robot.joints[0].name].child
    assert [link.parent_idx for link in robot.links] == [-1, robot.links[0].idx] and robot.links[1].name == child
    assert [robot.links[0].is_fixed, robot.links[1].is_fixed, box.links[0].is_fixed] == [True, False, False]
    force, torque, pos = _t([[0.0, 3.0, 1.0], [1.0, 0.0, 0.0]]), _t([[0.5, 0.0, 0.0], [0.0, 0.0, -1.0]]), \
        _t([[2.0, 0.1, 1.0], [2.0, 0.0, 1.2]])
    state = scene.get_state()
    box.apply_links_external_wrench(force[:, None], torque[:, None], [0], pos=pos[:, None])
    scene.step()
    expected = box.get_dofs_velocity().clone()
    for apply in (lambda link: link.apply_external_wrench(force, torque, pos=pos),
                  lambda link: (link.apply_external_force(force, pos=pos), link.apply_external_torque(torque))):
        scene.reset(state)
        apply(box.links[0])
        scene.step()
        assert torch.equal(box.get_dofs_velocity(), expected)
    scene.destroy()
    (tmp_path / "pendulum.urdf").write_text(PENDULUM)
    scene = gs.Scene(show_viewer=False)
    shapeless = scene.add_entity(gs.morphs.URDF(file=str(tmp_path / "pendulum.urdf"), fixed=True))
    scene.build()
    with pytest.raises(gs.InvalidInputError, match=r"entity 'urdf_0': get_AABB needs collision shapes, link 'arm' "
                                                   r"has none"):
        shapeless.links[1].get_AABB()
    for value, shape in ((1.0, r"\(\)"), ([[1.0, 2.0]], r"\(1, 2\)"), (np.zeros((1, 1, 3)), r"\(1, 1, 3\)")):
        with pytest.raises(gs.InvalidInputError, match=r"link 'arm' of entity 'urdf_0': apply_external_wrench argument "
                                                       r"'force' must have shape \(3,\) or \(len\(envs_idx\), 3\), "
                                                       rf"got {shape}"):
            shapeless.links[1].apply_external_force(value)
    unbuilt = gs.Scene(show_viewer=False).add_entity(gs.morphs.Box())
    for what in ("parent_idx", "is_fixed"):
        with pytest.raises(gs.SceneStateError, match=rf"link 'box' of entity 'box_0': {what}: call scene.build\(\) "
                                                     r"first"):
            getattr(unbuilt.links[0], what)


def test_genesis_batch_info_switches_are_accepted(f64):
    """RigidOptions(batch_links_info, batch_joints_info, batch_dofs_info), which every Genesis
    domain-randomisation script sets, are accepted (ours keeps every parameter per env whatever
    they say: per-env values work either way) and checked as booleans."""
    for flag in (True, False):
        options = gs.options.RigidOptions(batch_links_info=flag, batch_joints_info=flag, batch_dofs_info=flag)
        scene = gs.Scene(rigid_options=options, show_viewer=False)
        robot = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True))
        scene.build(n_envs=2)
        kp, mass = robot.get_dofs_kp().clone(), robot.get_links_mass().clone()
        robot.set_dofs_kp(_t([[10.0, 20.0]]), envs_idx=[1])
        robot.set_links_mass(_t([[3.0]]), [1], envs_idx=[0])
        assert torch.equal(robot.get_dofs_kp(), torch.stack([kp[0], _t([10.0, 20.0])]))
        assert robot.get_links_mass()[0, 1] == 3.0 and torch.equal(robot.get_links_mass()[1], mass[1])
        scene.destroy()
    with pytest.raises(gs.InvalidInputError, match=r"RigidOptions: argument 'batch_dofs_info' must be True or False"):
        gs.options.RigidOptions(batch_dofs_info="yes")


def test_set_mass_scales_the_moving_links_as_genesis(f64):
    """set_mass(total): the links that move keep their ratios and their inertias scale with them
    (Genesis's), so the mass matrix scales by the same factor; per env; the welded base untouched;
    differentiable (each link's mass is its share of the total); an all-welded entity refuses."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(requires_grad=True),
                     rigid_options=gs.options.RigidOptions(enable_collision=False), show_viewer=False)
    fixed = scene.add_entity(gs.morphs.URDF(file=pybullet("franka_panda", "panda.urdf"), fixed=True))
    # (no rotor armature: it does not scale with the mass, and the mass matrix is checked to scale)
    free = scene.add_entity(gs.morphs.URDF(file=KUKA_FREE, pos=(1.0, 0.0, 0.0), default_armature=None))
    wall = scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(0.0, 2.0, 0.0), fixed=True))
    scene.build(n_envs=2)
    free.set_dofs_position(_t([0.0, 0.0, 0.5, 0.3, -0.2, 0.1, 0.4, 0.5, -0.2, -1.0, 0.4, 0.8, 0.1]))
    links, matrix, total = free.get_links_mass().clone(), free.get_mass_mat().clone(), free.get_mass().clone()
    target = _t([2.0, 0.5]) * total
    free.set_mass(target)
    assert torch.allclose(free.get_mass(), target, rtol=1e-14, atol=0)
    assert torch.allclose(free.get_links_mass(), links * _t([[2.0], [0.5]]), rtol=1e-14, atol=0)
    assert torch.allclose(free.get_mass_mat(), matrix * _t([2.0, 0.5])[:, None, None], rtol=1e-12, atol=1e-14)
    base = fixed.get_links_mass()[:, 0].clone()
    share = fixed.get_links_mass()[0, 1:] / fixed.get_mass()[0]
    mass = torch.tensor(7.0, dtype=torch.float64, requires_grad=True)
    fixed.set_mass(mass, envs_idx=[1])
    assert torch.equal(fixed.get_links_mass()[:, 0], base) and float(fixed.get_mass()[1]) == pytest.approx(7.0)
    grad, = torch.autograd.grad(fixed.get_links_mass()[1, 1:].sum() + fixed.get_links_mass()[1, 3], mass)
    assert float(grad) == pytest.approx(1.0 + float(share[2]), rel=1e-12)
    with pytest.raises(gs.InvalidInputError, match=r"entity 'box_2': set_mass needs a link that moves"):
        wall.set_mass(1.0)
    with pytest.raises(gs.InvalidInputError, match=r"entity 'urdf_1': argument 'mass' must be ≥ 0 kg"):
        free.set_mass(-1.0)


def test_link_set_mass_is_set_links_mass_of_that_link(f64, caplog):
    """RigidLink.set_mass (Genesis's): a number for every env or one per env, differentiable, as the
    entity's set_links_mass of that link; a link welded to the world is skipped with a warning."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(requires_grad=True))
    arm = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True))
    scene.build(n_envs=2)
    link, before = arm.links[-1], arm.get_links_mass().detach().clone()
    link.set_mass(2.5)
    assert arm.get_links_mass()[:, -1].tolist() == [2.5, 2.5]
    mass = torch.tensor([1.0, 3.0], dtype=torch.float64, requires_grad=True)
    link.set_mass(mass)
    masses = arm.get_links_mass()
    assert masses[:, -1].tolist() == [1.0, 3.0] and torch.equal(masses[:, :-1], before[:, :-1])
    grad, = torch.autograd.grad(masses[:, -1].sum(), mass)
    assert grad.tolist() == [1.0, 1.0]
    with caplog.at_level(logging.WARNING, logger="genesis_lite"):
        arm.links[0].set_mass(4.0)
    assert "welded to the world changes nothing" in caplog.records[-1].getMessage()
    assert torch.equal(arm.get_links_mass()[:, 0], before[:, 0])


def test_set_mass_takes_a_one_element_tensor_in_a_scene_without_envs(f64):
    scene = gs.Scene(show_viewer=False)
    box = scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1)))
    scene.build()
    box.set_mass(torch.tensor([1.3], dtype=torch.float64))  # (as set_links_mass takes it; it raised)
    assert float(box.get_mass()) == pytest.approx(1.3, rel=1e-15)


def test_dofs_limits_as_the_urdf_gives_them(f64, two_robots):
    """get_dofs_limit: the URDF's joint ranges (yourdfpy's reading), ±inf on the free base's dofs,
    one row per env, a selection of dofs and envs."""
    scene, kuka, other = two_robots
    lower, upper = kuka.get_dofs_limit()
    assert lower.shape == upper.shape == (2, kuka.n_dofs)
    reference = yourdfpy.URDF.load(KUKA_FREE)
    ranges = [(j.limit.lower, j.limit.upper) for j in reference.robot.joints if j.type == "revolute"]
    assert np.array_equal(lower[0, 6:].numpy(), [r[0] for r in ranges])
    assert np.array_equal(upper[1, 6:].numpy(), [r[1] for r in ranges])
    assert np.isinf(lower[:, :6].numpy()).all() and (lower[:, :6] < 0).all() and (upper[:, :6] > 0).all()
    low, high = kuka.get_dofs_limit([7, 9], envs_idx=[1])
    assert torch.equal(low, lower[1:, [7, 9]]) and torch.equal(high, upper[1:, [7, 9]])


def test_gravity_compensation_cancels_its_share_of_gravity_on_its_entity_alone(f64):
    """materials.Rigid(gravity_compensation=c), Genesis's: the entity moves as under gravity × (1 − c)
    (Genesis scales its entity's gravity so), every link of it (a URDF arm's and a free box's), while
    an entity beside it keeps the whole of gravity; c = 1 holds an arm at rest where it is."""
    kuka = pybullet("kuka_iiwa", "model.urdf")
    gravity = np.array([0.4, -0.3, -9.81])
    pose = torch.tensor([0.3, 0.5, -0.2, -1.0, 0.4, 0.6, 0.1], dtype=torch.float64)

    def run(compensation, scale):
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, gravity=tuple(gravity * scale)),
                         rigid_options=gs.options.RigidOptions(enable_collision=False), show_viewer=False)
        material = gs.materials.Rigid(gravity_compensation=compensation)
        arm = scene.add_entity(gs.morphs.URDF(file=kuka, fixed=True), material=material)
        box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.1, 0.05), pos=(1.0, 0.0, 1.0)), material=material)
        free = scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(-1.0, 0.0, 1.0)))  # uncompensated
        scene.build()
        arm.set_dofs_position(pose)
        box.set_dofs_velocity([0.1, 0.0, 0.2, 0.5, 0.2, 1.0])
        free.set_dofs_velocity([0.0, 0.3, 0.1, 0.2, 0.0, 0.4])
        for _ in range(60):
            scene.step()
        return [entity.get_qpos() for entity in (arm, box, free)]

    for compensation in (0.3, 1.0, 1.6):
        arm, box, free = run(compensation, 1.0)
        arm_scaled, box_scaled, _ = run(None, 1.0 - compensation)
        _, _, free_alone = run(None, 1.0)
        assert torch.allclose(arm, arm_scaled, rtol=0, atol=1e-13) and torch.allclose(box, box_scaled, rtol=0, atol=1e-13)
        assert torch.equal(free, free_alone)
        if compensation == 1.0:
            assert torch.allclose(arm, pose, rtol=0, atol=1e-14)
    assert not torch.allclose(run(0.3, 1.0)[0], run(None, 1.0)[0], atol=1e-3)  # (it does act)


@pytest.mark.parametrize("value", ["high", float("nan"), float("inf"), [0.5], True])
def test_gravity_compensation_must_be_a_finite_number(value):
    with pytest.raises(gs.InvalidInputError, match="materials.Rigid: argument 'gravity_compensation' must be a finite"):
        gs.materials.Rigid(gravity_compensation=value)


def test_dofs_invweight_is_genesis_and_follows_the_mass(f64):
    """get_dofs_invweight: the diagonal of M⁻¹ at the initial pose, a free joint's averaged over its
    translations and its rotations (MuJoCo's dof_invweight0): the KUKA's as Genesis 1.4.5 gives them
    (measured: the same 12 digits), a free box's from its mass and inertia: a doubled link mass halves
    its translations' (the inertia stays, as Genesis's), a doubled entity mass both (set_mass scales
    the inertia with it)."""
    scene = gs.Scene()
    arm = scene.add_entity(gs.morphs.URDF(file=pybullet("kuka_iiwa", "model.urdf"), fixed=True))
    box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.1, 0.05), pos=(1.0, 0.0, 1.0)), material=gs.materials.Rigid(rho=600.0))
    scene.build(n_envs=2)
    genesis = [5.730415972718, 0.72402122071, 7.801932128421, 3.96298012273, 9.165145388492, 9.255846263355,
               9.902734720426]
    np.testing.assert_allclose(arm.get_dofs_invweight(envs_idx=[1])[0].numpy(), genesis, rtol=1e-10)
    mass, sides = 600.0 * 0.2 * 0.1 * 0.05, np.array([0.2, 0.1, 0.05])
    inertia = mass / 12.0 * (sides @ sides - sides ** 2)
    expected = [1.0 / mass] * 3 + [np.mean(1.0 / inertia)] * 3
    np.testing.assert_allclose(box.get_dofs_invweight().numpy(), [expected] * 2, rtol=1e-12)
    box.set_links_mass([2.0 * mass], envs_idx=[1])
    first = np.array([expected[0], expected[3]])  # (dofs 0 and 3: a translation, a rotation)
    np.testing.assert_allclose(box.get_dofs_invweight([0, 3]).numpy(), [first, first / [2.0, 1.0]], rtol=1e-12)
    box.set_links_mass([mass], envs_idx=[1])
    box.set_mass(2.0 * mass, envs_idx=[1])
    np.testing.assert_allclose(box.get_dofs_invweight([0, 3]).numpy(), [first, first / 2.0], rtol=1e-12)


def test_links_invweight_is_genesis_and_mujocos_body_invweight0(f64):
    """get_links_invweight: (translational, rotational) per link, the means of the two diagonals of
    J M⁻¹ Jᵀ at the initial pose (J the Jacobian of the link's centre of mass; MuJoCo's
    body_invweight0): the KUKA's as Genesis 1.4.5 gives them (measured: the same 12 digits; its
    base, welded to the world, 0), a free box's (1/m, the mean of 1/I), batched shapes."""
    scene = gs.Scene()
    arm = scene.add_entity(gs.morphs.URDF(file=pybullet("kuka_iiwa", "model.urdf"), fixed=True))
    box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.1, 0.05), pos=(1.0, 0.0, 1.0)), material=gs.materials.Rigid(rho=600.0))
    scene.build(n_envs=2)
    genesis = [[0.0, 0.0], [1.719124791815e-03, 1.910138657573], [4.192814266018e-03, 2.151479064476],
               [3.048313478522e-02, 3.763862842595], [3.786127982366e-02, 4.207191533463],
               [4.692571091148e-02, 6.616963451510], [8.598418947399e-02, 9.481771350234],
               [1.524314942187e-01, 1.266521174839e+01]]
    invweight = arm.get_links_invweight()
    assert invweight.shape == (2, arm.n_links, 2)
    np.testing.assert_allclose(invweight[1].numpy(), genesis, rtol=1e-10, atol=1e-15)
    mass, sides = 600.0 * 0.2 * 0.1 * 0.05, np.array([0.2, 0.1, 0.05])
    inertia = mass / 12.0 * (sides @ sides - sides ** 2)
    np.testing.assert_allclose(box.get_links_invweight(envs_idx=[0]).numpy(), [[[1.0 / mass, np.mean(1.0 / inertia)]]],
                               rtol=1e-12)


def test_entity_build_facts_are_genesis(f64):
    """is_built, is_attached, base_link_idx and init_qpos (Genesis's properties): the qpos at build,
    an MJCF joint's ref and a free base's placement in it, MuJoCo's qpos0; the same before build."""
    import mujoco
    scene = gs.Scene()
    arm = scene.add_entity(gs.morphs.MJCF(file=asset("mjcf", "arm.xml")))
    box = scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(0.5, 0.2, 0.3)))
    gripper = scene.add_entity(gs.morphs.Box(size=(0.05, 0.05, 0.05)))
    gripper.attach(arm, "wrist")
    assert not arm.is_built and gripper.is_attached and not box.is_attached
    before = [entity.init_qpos for entity in (arm, box, gripper)]
    scene.build()
    assert all(np.array_equal(a, entity.init_qpos) for a, entity in zip(before, (arm, box, gripper)))
    assert arm.is_built and box.base_link_idx == box.link_start == arm.n_links
    np.testing.assert_allclose(arm.init_qpos, mujoco.MjModel.from_xml_path(asset("mjcf", "arm.xml")).qpos0,
                               atol=1e-15)
    assert box.init_qpos.tolist() == [0.5, 0.2, 0.3, 1.0, 0.0, 0.0, 0.0] and gripper.init_qpos.size == 0


def test_link_reference_frames_batched_and_checked(f64):
    """gs.link_ref_frame in get_links_pos/vel (and the solver's scene-wide ones): batched with
    envs_idx as the all-env read's rows; a box's centre of mass moved per env (set_links_COM) is
    where the reads put it, its velocity v + ω × r, its tree's its own (the other box is another
    tree), a plane's its origin; root_COM refused for velocities, a bad ref or relative by name,
    before build a SceneStateError."""
    scene = gs.Scene()
    plane = scene.add_entity(gs.morphs.Plane())
    boxes = [scene.add_entity(gs.morphs.Box(size=(0.1, 0.2, 0.3), pos=(x, 0.0, 1.0))) for x in (0.0, 1.0)]
    with pytest.raises(gs.SceneStateError):
        boxes[0].get_links_pos(ref=gs.link_ref_frame.root_COM)
    scene.build(n_envs=3)
    box = boxes[1]
    shifts = torch.tensor([[[0.01, -0.02, 0.03]], [[0.0, 0.0, 0.0]], [[-0.03, 0.02, 0.01]]], dtype=torch.float64)
    box.set_links_COM(shifts)  # a centre of mass of its own in each env
    box.set_dofs_velocity(torch.tensor([[0.1, 0.2, 0.3, 1.0, -2.0, 0.5]], dtype=torch.float64).repeat(3, 1))
    scene.step()
    origin, quat = box.get_links_pos(), box.get_links_quat()
    centre = origin + gs.transform_by_quat(shifts, quat)
    for ref, expected in (("link_origin", origin), ("link_COM", centre), ("root_COM", centre)):
        every = box.get_links_pos(ref=getattr(gs.link_ref_frame, ref))
        assert every.shape == (3, 1, 3) and torch.equal(box.get_links_pos(envs_idx=[2, 0], ref=getattr(
            gs.link_ref_frame, ref)), every[[2, 0]])
        assert torch.allclose(every, expected, atol=1e-14, rtol=0), ref
    assert torch.equal(scene.sim.rigid_solver.get_links_pos([2], ref=gs.link_ref_frame.link_COM, relative=False),
                       box.get_links_pos(ref=gs.link_ref_frame.link_COM))
    velocity = box.get_links_vel() + torch.linalg.cross(box.get_links_ang(), centre - origin)
    assert torch.allclose(box.get_links_vel(ref=gs.link_ref_frame.link_COM), velocity, atol=1e-14, rtol=0)
    assert torch.equal(box.get_links_vel(envs_idx=[1, 2], ref=gs.link_ref_frame.link_COM),
                       box.get_links_vel(ref=gs.link_ref_frame.link_COM)[[1, 2]])
    # a massless tree (the plane): its link origin, not 0/0
    assert torch.equal(plane.get_links_pos(ref=gs.link_ref_frame.root_COM), plane.get_links_pos())
    with pytest.raises(gs.InvalidInputError, match="get_links_vel argument 'ref' must be one of"):
        box.get_links_vel(ref=gs.link_ref_frame.root_COM)
    with pytest.raises(gs.InvalidInputError, match="get_links_pos argument 'ref'"):
        box.get_links_pos(ref="centre")
    with pytest.raises(gs.InvalidInputError, match="'relative'"):
        box.get_links_pos(relative=1)
    # Genesis's pose getters and setters all take relative (its authored and internal link origins,
    # one here); docs/genesis_api.md said so and get_pos, get_quat, get_vel, set_pos, set_quat refused it
    link = box.links[0]
    for method in (box.get_pos, box.get_quat, box.get_vel, box.get_links_quat, link.get_pos, link.get_quat,
                   link.get_vel):
        assert torch.equal(method(relative=False), method()), method.__name__
        with pytest.raises(gs.InvalidInputError, match="'relative'"):
            method(relative=1)
    pos, quat = box.get_pos(), box.get_quat()
    box.set_pos(pos + 0.1, relative=False)
    box.set_quat(quat, relative=True)
    assert torch.allclose(box.get_pos(), pos + 0.1, atol=1e-15, rtol=0)
    with pytest.raises(gs.InvalidInputError, match="'relative'"):
        box.set_quat(quat, relative="yes")


def test_link_reference_frame_readouts_are_differentiable_f64(f64):
    """get_links_pos(ref=link_COM / root_COM) and get_links_vel(ref=link_COM) of a tumbling
    two-link body after 5 steps: their gradient in the initial dof velocities and in the links'
    centres of mass (set_links_COM) agrees with central differences, and a repeat keeps its bits."""
    from tests.fd_scan import checked_gradient
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True, gravity=(0.0, 0.0, -9.81)))
    arm = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), pos=(0.0, 0.0, 2.0)))
    scene.build()

    def readouts():
        return torch.cat([arm.get_links_pos(ref=gs.link_ref_frame.link_COM).reshape(-1),
                          arm.get_links_pos(ref=gs.link_ref_frame.root_COM).reshape(-1),
                          arm.get_links_vel(ref=gs.link_ref_frame.link_COM).reshape(-1)])

    def after_steps(velocity=None, com=None):
        scene.reset()
        if com is not None:
            arm.set_links_COM(com)
        arm.set_dofs_velocity(torch.linspace(-0.5, 0.8, arm.n_dofs, dtype=torch.float64) if velocity is None
                              else velocity)
        for _ in range(5):
            scene.step()
        values = readouts()
        return (values * torch.linspace(0.3, 1.7, len(values), dtype=torch.float64)).sum()

    assert arm.n_links >= 2
    velocity = torch.linspace(-0.5, 0.8, arm.n_dofs, dtype=torch.float64)
    assert checked_gradient(lambda v: after_steps(velocity=v), velocity, "initial velocity").abs().max() > 0
    com = torch.tensor([[0.01, -0.02, 0.05]] * arm.n_links, dtype=torch.float64)
    assert checked_gradient(lambda c: after_steps(com=c), com, "centres of mass").abs().max() > 0


def test_links_and_entities_know_their_dof_and_coordinate_ranges(f64):
    """Genesis's RigidLink.joints/n_joints/n_dofs/n_qs/dof_start/dof_end/q_start/q_end and the entity's
    link_end/dof_end/q_end (an independent probe of Genesis's API found them missing): a welded plane
    link (no joint, an empty range where its dofs would be), a free box (6 dofs, 7 coordinates) and a
    fixed KUKA (one hinge a link); each link's range is its joint's, the ranges tile the entity's."""
    scene = gs.Scene()
    plane = scene.add_entity(gs.morphs.Plane())
    box = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 1.0), size=(0.1, 0.1, 0.1)))
    arm = scene.add_entity(gs.morphs.URDF(file=pybullet("kuka_iiwa", "model.urdf"), fixed=True))
    with pytest.raises(gs.SceneStateError, match="call scene.build"):
        arm.links[1].dof_start
    scene.build()
    (ground,), (body,) = plane.links, box.links
    assert (ground.n_joints, ground.n_dofs, ground.n_qs, ground.dof_start, ground.dof_end) == (0, 0, 0, 0, 0)
    assert body.joints == box.joints and (body.n_dofs, body.n_qs, body.dof_start, body.q_end) == (6, 7, 0, 7)
    assert (box.link_end, box.dof_end, box.q_end) == (2, 6, 7)
    assert (arm.link_start, arm.link_end, arm.dof_start, arm.dof_end, arm.q_start, arm.q_end) == (2, 10, 6, 13, 7, 14)
    assert arm.links[0].n_joints == 0 and arm.links[0].dof_start == arm.links[0].dof_end == 6
    starts = [link.dof_start for link in arm.links[1:]]
    assert starts == [joint.dof_start for joint in arm.joints] == list(range(6, 13))
    assert [link.q_start for link in arm.links[1:]] == [joint.q_start for joint in arm.joints]
    assert sum(link.n_dofs for link in arm.links) == arm.n_dofs and arm.links[-1].dof_end == arm.dof_end
    assert body.joints[0].init_qpos.tolist() == [0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0]  # (Genesis's joint.init_qpos)
    assert np.concatenate([joint.init_qpos for joint in arm.joints]).tolist() == arm.init_qpos.tolist()
    # geom_end, joint_start/joint_end and a joint's scene-wide idx (a second probe found them missing)
    assert (plane.geom_end, box.geom_start, box.geom_end, arm.geom_start) == (1, 1, 2, 2) and arm.geom_end > 2
    assert (plane.joint_start, plane.joint_end, box.joint_start, box.joint_end) == (0, 0, 0, 1)
    assert (arm.joint_start, arm.joint_end) == (1, 8) and [joint.idx for joint in arm.joints] == list(range(1, 8))
    assert [link.root_idx for link in box.links + arm.links] == [1] + [2] * arm.n_links
    assert body.is_built and arm.joints[0].is_built
    # Genesis's get_link / get_joint by uid (digits of it)
    assert arm.get_link(uid=arm.links[3].uid.short()) is arm.links[3]
    assert arm.get_joint(uid=str(arm.joints[2].uid)[5:20]) is arm.joints[2]
    for call, said in ((lambda: arm.get_link(), "get_link missing a required argument: 'name' or 'uid'"),
                       (lambda: arm.get_joint(uid="not hex"), "get_joint argument 'uid' must be digits of a uid")):
        with pytest.raises(gs.InvalidInputError, match=said):
            call()
