"""gs.morphs.Drone and DroneEntity.set_propellers_rpm (float64).

References: MuJoCo 4 flying the same rigid body under the rotors' wrench computed from its own
state (xfrc_applied at the centre of mass), and closed forms: the hover speed holds the drone
still, and a yaw command turns it by the implicit-damping recursion. Then gradients through the
rotor speeds against central differences, a repeat's bits, batching, and bad input.
"""
import mujoco
import numpy as np
import pytest
import torch

import genesis_lite as gs
from tests.conftest import warns
from tests.fd_scan import checked_gradient

DT, G = 0.01, 9.81
CF2X, RACER = "urdf/drones/cf2x.urdf", "urdf/drones/racer.urdf"


def _scene(file=CF2X, n_envs=0, requires_grad=False, substeps=1, euler=(5.0, -3.0, 20.0), **morph):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT, substeps=substeps, requires_grad=requires_grad),
                     show_viewer=False)
    drone = scene.add_entity(gs.morphs.Drone(file=file, pos=(0.1, -0.2, 1.0), euler=euler, **morph))
    scene.build(n_envs=n_envs)
    return scene, drone


def _hover(drone):
    return float(np.sqrt(float(drone.get_mass().reshape(-1)[0]) * G / (4.0 * drone.KF)))


def _mujoco(drone, substeps):
    """MuJoCo 4's free body of the drone's mass, centre of mass and inertia (its base's: the rotors
    are massless), the base's rotational damping, and the rotors' centres in its frame."""
    env0 = (lambda values: values[0]) if drone.scene.n_envs else (lambda values: values)
    spec = mujoco.MjSpec()
    spec.option.timestep = DT / substeps
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_EULER
    spec.option.gravity = [0.0, 0.0, -G]
    inertia = env0(drone.get_links_inertia())[0].numpy()
    assert np.allclose(inertia, np.diag(np.diag(inertia)))
    body = spec.worldbody.add_body(name="drone", mass=float(env0(drone.get_mass())),
                                   ipos=env0(drone.get_links_COM())[0].numpy(),
                                   inertia=np.diag(inertia))
    body.add_freejoint()
    model = spec.compile()
    model.dof_damping[3:] = env0(drone.get_dofs_damping())[3:].numpy()
    rotors = env0(drone.get_links_COM())[[1, 2, 3, 4]].numpy()  # (the rotor links' frames are the base's)
    return model, rotors


def _rotor_wrench(model, data, rotors, rpm, kf, km, spin):
    """(force (3,), torque (3,)) in world axes about the body's centre of mass at data's qpos:
    thrust kf·ω² along the body's z at each rotor, drag torque spin·km·ω² about it."""
    mujoco.mj_kinematics(model, data)  # (after mj_step, xmat is still the step's start's)
    rot, com = data.xmat[1].reshape(3, 3), data.xipos[1]
    force, torque = np.zeros(3), np.zeros(3)
    for point, w, s in zip(rotors, rpm, spin):
        thrust = rot @ np.array([0.0, 0.0, kf * w * w])
        force += thrust
        torque += np.cross(data.xpos[1] + rot @ point - com, thrust) + rot @ np.array([0.0, 0.0, s * km * w * w])
    return force, torque


@pytest.mark.parametrize("file,spin_sign", [(CF2X, 1.0), (RACER, -1.0)])
@pytest.mark.parametrize("n_envs", [0, 2])
def test_drone_flies_as_mujocos_body_under_its_rotors_wrench(f64, file, spin_sign, n_envs):
    """150 steps of random speeds about hover, both drones (RACE's drag torque reversed), single and
    batched: position, orientation and velocities equal MuJoCo's to 1e-10."""
    model_name = "RACE" if spin_sign < 0 else "CF2X"
    scene, drone = _scene(file, n_envs=n_envs, model=model_name)
    model, rotors = _mujoco(drone, 1)
    hover, batch = _hover(drone), max(n_envs, 1)
    rpm = hover * (1.0 + 0.08 * np.random.default_rng(3).uniform(-1, 1, size=(150, batch, 4)))
    datas = [mujoco.MjData(model) for _ in range(batch)]
    start = np.concatenate([drone.get_pos().numpy().reshape(-1, 3)[0], drone.get_quat().numpy().reshape(-1, 4)[0]])
    for data in datas:
        data.qpos[:] = start
        mujoco.mj_forward(model, data)
    spin = spin_sign * np.array(drone.morph.propellers_spin, dtype=float)
    for step in range(150):
        drone.set_propellers_rpm(rpm[step] if n_envs else rpm[step, 0])
        scene.step()
        for e, data in enumerate(datas):
            wrench = _rotor_wrench(model, data, rotors, rpm[step, e], drone.KF, drone.KM, spin)
            data.xfrc_applied[1] = np.concatenate(wrench)
            mujoco.mj_step(model, data)
    ours = np.concatenate([getter().numpy().reshape(batch, -1) for getter in
                           (drone.get_pos, drone.get_quat, drone.get_vel, drone.get_ang)], axis=1)
    for e, data in enumerate(datas):
        mujoco.mj_kinematics(model, data)
        theirs = np.concatenate([data.qpos, data.qvel[:3], data.xmat[1].reshape(3, 3) @ data.qvel[3:]])
        assert np.abs(ours[e] - theirs).max() < 1e-10, (e, ours[e] - theirs)
    assert np.abs(ours[:, :3] - start[:3]).max() > 0.05  # (it flew somewhere)


def test_hover_speed_holds_the_drone_and_a_yaw_command_turns_it_by_the_closed_form(f64):
    """At ω = √(m g / 4 kf) on every rotor the drone stays where it is, still. Rotors 0 and 2 (spin
    −1) at ω_a and 1 and 3 (spin +1) at ω_b with ω_a² + ω_b² = 2 ω_hover² keep the thrust and yaw
    it alone: Izz ω' = τ − b ω, with τ = 2 km (ω_b² − ω_a²) and b the base's damping (Genesis's 1e-5
    × mass), taken implicitly: ω_{n+1} = (Izz ω_n + h τ) / (Izz + h b)."""
    scene, drone = _scene(euler=(0.0, 0.0, 20.0))
    hover, start = _hover(drone), drone.get_pos().clone()
    for _ in range(100):
        drone.set_propellers_rpm([hover] * 4)
        scene.step()
    assert torch.abs(drone.get_pos() - start).max() < 1e-12 and torch.abs(drone.get_vel()).max() < 1e-12
    izz, b = float(drone.get_links_inertia()[0, 2, 2]), float(drone.get_dofs_damping()[5])
    assert b == pytest.approx(1e-5 * 0.027, rel=1e-12)
    turn = drone.get_ang().numpy()
    w_a, w_b = hover * np.sqrt(0.9), hover * np.sqrt(1.1)
    tau = 2.0 * drone.KM * (w_b ** 2 - w_a ** 2)
    w, x, y, z = drone.get_links_quat()[0].tolist()
    body_z = np.array([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])  # the yaw axis
    omega = 0.0
    for _ in range(50):
        drone.set_propellers_rpm([w_a, w_b, w_a, w_b])
        scene.step()
        omega = (izz * omega + DT * tau) / (izz + DT * b)
    assert np.abs(drone.get_ang().numpy() - turn - omega * body_z).max() < 1e-12 * max(1.0, omega)
    assert torch.abs(drone.get_pos() - start).max() < 1e-12  # (no net force, no tilt: it turns in place)
    assert omega > 1.0


def test_rotor_speeds_last_one_step_and_are_set_once_a_step(f64):
    """The rotors' wrench acts for the step after the call (then the drone falls freely); a second
    call before the step is refused (Genesis's rule); after scene.reset the count starts again."""
    scene, drone = _scene(euler=(0.0, 0.0, 0.0))
    drone.set_propellers_rpm([_hover(drone)] * 4)
    with pytest.raises(gs.SceneStateError, match="set_propellers_rpm can only be called once per step"):
        drone.set_propellers_rpm([_hover(drone)] * 4)
    scene.step()
    assert abs(float(drone.get_vel()[2])) < 1e-12
    scene.step()
    assert float(drone.get_vel()[2]) == pytest.approx(-G * DT, rel=1e-12)
    scene.reset()
    drone.set_propellers_rpm([0.0] * 4)
    scene.step()
    drone.set_propellers_rpm([0.0] * 4)


def test_substeps_apply_the_rotors_at_each_substep_as_mujocos(f64):
    """substeps = 3: the wrench, computed at the call, acts at each substep (MuJoCo stepping h/3
    with the same world-axes wrench)."""
    scene, drone = _scene(substeps=3)
    model, rotors = _mujoco(drone, 3)
    data = mujoco.MjData(model)
    data.qpos[:] = np.concatenate([drone.get_pos().numpy(), drone.get_quat().numpy()])
    mujoco.mj_forward(model, data)
    rpm = _hover(drone) * np.array([1.05, 0.97, 1.0, 1.02])
    spin = np.array(drone.morph.propellers_spin, dtype=float)
    for _ in range(40):
        drone.set_propellers_rpm(rpm)
        scene.step()
        data.xfrc_applied[1] = np.concatenate(_rotor_wrench(model, data, rotors, rpm, drone.KF, drone.KM, spin))
        for _ in range(3):
            mujoco.mj_step(model, data)
    assert np.abs(drone.get_pos().numpy() - data.qpos[:3]).max() < 1e-10
    assert np.abs(drone.get_quat().numpy() - data.qpos[3:]).max() < 1e-10


@pytest.mark.parametrize("n_envs", [0, 2])
def test_gradients_through_rotor_speeds_match_finite_differences(f64, n_envs):
    """L = ‖p_T − target‖² + ‖ω_T‖² after 25 steps, in the speeds ω_t = hover (1 + u_t) (T × 4,
    per env): central differences along random directions, and a repeat's bits."""
    scene, drone = _scene(n_envs=n_envs, requires_grad=True)
    hover, target = _hover(drone), torch.tensor([0.3, -0.1, 1.2], dtype=torch.float64)
    shape = (25, n_envs, 4) if n_envs else (25, 4)
    u0 = torch.tensor(np.random.default_rng(5).uniform(-0.1, 0.1, size=shape))

    def loss(u):
        scene.reset()
        for t in range(u.shape[0]):
            drone.set_propellers_rpm(hover * (1.0 + u[t]))
            scene.step()
        return ((drone.get_pos() - target) ** 2).sum() + (drone.get_ang() ** 2).sum()

    grad = checked_gradient(loss, u0, f"drone rotor speeds, n_envs {n_envs}")
    assert grad.abs().max() > 0.0 and grad[0].abs().max() > 0.0  # (the first step's speeds matter)


def test_gradients_through_the_start_pose_the_rotors_turn_with(f64):
    """The rotors' wrench is turned into world axes by the rotor links' poses: the gradient of the
    final pose and turn rate w.r.t. the base's start quaternion (set_quat) flows through them as
    through the dynamics; central differences, 20 steps of uneven speeds."""
    scene, drone = _scene(requires_grad=True, euler=(0.0, 0.0, 0.0))
    hover = _hover(drone)
    rpm = torch.tensor(hover * (1.0 + 0.1 * np.random.default_rng(9).uniform(-1, 1, size=(20, 4))))
    quat0 = torch.tensor([0.95, 0.2, -0.15, 0.1], dtype=torch.float64)
    quat0 = quat0 / quat0.norm()

    def loss(quat):
        scene.reset()
        drone.set_quat(quat)
        for t in range(rpm.shape[0]):
            drone.set_propellers_rpm(rpm[t])
            scene.step()
        return (drone.get_pos() ** 2).sum() + (drone.get_ang() ** 2).sum() + (drone.get_quat() * quat0).sum()

    checked_gradient(loss, quat0, "drone start quaternion")


def test_a_partial_reset_keeps_the_others_rotor_speeds_pending(f64):
    """Speeds set, then some envs reset: the others' wrench is still pending, so a second call before
    the step is refused (it would double their thrust); after the step one call is allowed."""
    scene, drone = _scene(n_envs=2, euler=(0.0, 0.0, 0.0))
    hover = _hover(drone)
    drone.set_propellers_rpm([hover] * 4)
    scene.reset(envs_idx=[0])
    with pytest.raises(gs.SceneStateError, match="once per step .*a reset of some envs keeps the others'"):
        drone.set_propellers_rpm([hover] * 4)
    scene.step()
    vz = drone.get_vel()[:, 2]
    assert float(vz[0]) == pytest.approx(-G * DT, rel=1e-12) and abs(float(vz[1])) < 1e-12  # (env 0's cleared)
    drone.set_propellers_rpm([hover] * 4)


def test_batched_drones_fly_as_single_ones(f64):
    """Env e of a batch of 3 gives the bits of a single-env scene with env e's speeds."""
    scene, drone = _scene(n_envs=3)
    hover = _hover(drone)
    rpm = hover * (1.0 + 0.05 * np.random.default_rng(7).uniform(-1, 1, size=(30, 3, 4)))
    for t in range(30):
        drone.set_propellers_rpm(rpm[t])
        scene.step()
    batched = torch.cat([drone.get_pos(), drone.get_quat()], dim=-1)
    for e in range(3):
        scene, drone = _scene()
        for t in range(30):
            drone.set_propellers_rpm(rpm[t, e])
            scene.step()
        assert torch.equal(torch.cat([drone.get_pos(), drone.get_quat()]), batched[e])


def test_deprecated_morph_arguments_warn_as_genesis(f64, caplog):
    with warns(caplog, "'propellers_link_names' is deprecated"):
        morph = gs.morphs.Drone(file=CF2X, propellers_link_names=("prop1_link", "prop0_link"), propellers_spin=(1, -1))
    assert morph.propellers_link_name == ("prop1_link", "prop0_link") and morph.propellers_link_names is None
    with warns(caplog, "'COM_link_name' is deprecated"):
        gs.morphs.Drone(file=CF2X, COM_link_name="center_of_mass_link")


def test_drone_properties_as_genesis(f64):
    scene, drone = _scene()
    assert isinstance(drone, gs.entities.DroneEntity) and isinstance(drone, gs.entities.RigidEntity)
    assert (drone.KF, drone.KM, drone.n_propellers, drone.model) == (3.16e-10, 7.94e-12, 4, "CF2X")
    assert drone.propellers_idx.tolist() == [drone.link_start + k for k in (1, 2, 3, 4)]
    assert drone.propellers_spin.tolist() == [-1.0, 1.0, -1.0, 1.0]
    assert [link.name for link in drone.links] == ["base_link", "prop0_link", "prop1_link", "prop2_link", "prop3_link"]
    assert drone.get_dofs_damping()[:3].abs().max() == 0.0  # (the base's rotational dofs only)
    assert drone.get_dofs_armature().abs().max() == 0.0  # (a free base takes no rotor armature)
    _, no_damping = _scene(default_base_ang_damping_scale=None)
    assert no_damping.get_dofs_damping().abs().max() == 0.0


def test_bad_drone_input_raises(f64, tmp_path):
    with pytest.raises(gs.InvalidInputError, match="Drone: argument 'fixed' must be False"):
        gs.morphs.Drone(file=CF2X, fixed=True)
    with pytest.raises(gs.InvalidInputError, match="Drone: argument 'model' must be 'CF2X', 'CF2P' or 'RACE', got 'X'"):
        gs.morphs.Drone(file=CF2X, model="X")
    with pytest.raises(gs.InvalidInputError, match="argument 'propellers_spin' must hold 1 .* for each of the 4"):
        gs.morphs.Drone(file=CF2X, propellers_spin=(1, -1, 1))
    with pytest.raises(gs.InvalidInputError, match="argument 'propellers_spin' must hold 1"):
        gs.morphs.Drone(file=CF2X, propellers_spin=(1, -1, 1, 0.5))
    assert gs.morphs.Drone(file=CF2X, propellers_spin=(1.0, -1.0, 1, -1)).propellers_spin == (1, -1, 1, -1)
    with pytest.raises(gs.InvalidInputError, match="argument 'propellers_link_name' must be a sequence of distinct"):
        gs.morphs.Drone(file=CF2X, propellers_link_name="prop0_link")
    with pytest.raises(gs.InvalidInputError, match="'default_base_ang_damping_scale' must be a finite number ≥ 0"):
        gs.morphs.Drone(file=CF2X, default_base_ang_damping_scale=-1.0)
    with pytest.raises(gs.InvalidInputError, match="'propellers_link_names' and 'propellers_link_name' cannot both"):
        gs.morphs.Drone(file=CF2X, propellers_link_names=("a",), propellers_link_name=("b",), propellers_spin=(1,))
    with pytest.raises(gs.InvalidInputError, match=r"entity 'drone_0': argument 'propellers_link_name' of "
                                                   r"gs.morphs.Drone expected links of the file, got \['rotor'\]"):
        gs.Scene().add_entity(gs.morphs.Drone(file=CF2X, propellers_link_name=("prop0_link", "rotor"),
                                              propellers_spin=(1, -1)))
    plain = tmp_path / "plain.urdf"
    plain.write_text(open(gs.morphs.Drone(file=CF2X).file).read().replace('kf="3.16e-10" ', ""))
    with pytest.raises(gs.InvalidInputError, match="expected a URDF whose <properties> element states the rotors' kf "
                                                   r"and km \(numbers ≥ 0\)"):
        gs.Scene().add_entity(gs.morphs.Drone(file=str(plain)))
    scene, drone = _scene()
    with pytest.raises(gs.InvalidInputError, match="entity 'drone_0': argument 'propellers_rpm' must be ≥ 0"):
        drone.set_propellers_rpm([1.0, -1.0, 1.0, 1.0])
    with pytest.raises(gs.InvalidInputError, match="argument 'propellers_rpm' must be finite"):
        drone.set_propellers_rpm([1.0, np.nan, 1.0, 1.0])
    with pytest.raises(gs.InvalidInputError, match=r"argument 'propellers_rpm' must have shape \(4,\)"):
        drone.set_propellers_rpm([1.0, 1.0, 1.0])
    with pytest.raises(gs.GradientError):
        drone.set_propellers_rpm(torch.ones(4, dtype=torch.float64, requires_grad=True))
    drone.set_propellers_rpm([1.0] * 4)  # (the refused calls set nothing: one call is still allowed)
    with pytest.raises(gs.SceneStateError):
        drone.set_propellers_rpm([1.0] * 4)
