"""Ball joints (MJCF ``type="ball"``: a quaternion, three dofs turning about the body's own axes)
against MuJoCo 4, closed forms and finite differences (float64).

assets/mjcf/balls.xml has two trees: an arm hanging from the world by a ball joint (a 40° cone
limit, a spring), a hinge, and a box on a ball joint anchored off its body origin (friction loss,
armature, a spring, a 25° cone); and a free sphere dragging four capsules on ball joints onto the
ground. From random velocities both engines run 2 s side by side, cone limits and contacts active
(measured: 1.7e-13 either cone); so do cone limits alone, a turn stored as −q (w < 0), and a ball
joint beside a hinge or slide in one body; ranges are read as MuJoCo's compiler reads them. A
spherical pendulum keeps its energy and vertical angular momentum to first order in the time
step and swings at the physical pendulum's period; gradients through the cone limits, the springs
and the contacts match central differences.
"""
import mujoco
import numpy as np
import pytest
import torch

import genesis_lite as gs
from genesis_lite.solvers.core import InvalidInputError
from genesis_lite.solvers.rigid.data import SERIAL_LINK_ENVS
from genesis_lite.utils.rotations import euler_xyz_to_quat, quat_to_euler_xyz, quat_to_mat
from tests.conftest import asset
from tests.fd_scan import assert_converged, directional_errors, pose_loss
from tests.test_mjcf import _lockstep, _pair, _write

BALLS = asset("mjcf", "balls.xml")
ARM_BALLS = {"shoulder": (0, 40.0), "wrist": (4, 25.0)}  # ball joint → (first dof, cone limit in degrees)


def _turn(quat):
    """Angle (rad) of the turn of each unit quaternion (..., 4)."""
    return 2 * torch.atan2(quat[..., 1:].norm(dim=-1), quat[..., 0].abs())


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_ball_joints_match_mujoco(f64, cone):
    """Both trees from the same random velocities for 3 s in both engines (MuJoCo's Euler
    integrator: the rope's free root turns), with MuJoCo's cone-limit rows and contacts seen."""
    m, d, scene, robot = _pair(BALLS, cone, integrator="euler")
    assert [link.name for link in robot.links] == ["world:arm", "arm", "forearm", "hand:wrist", "hand", "rope",
                                                   "seg1", "seg2", "seg3", "seg4", "world"]  # (last: the floor's)
    assert (robot.n_dofs, robot.n_qs) == (m.nv, m.nq) == (25, 32)
    velocity = np.random.default_rng(0).normal(size=m.nv)
    d.qvel[:] = velocity
    robot.set_dofs_velocity(torch.tensor(velocity))
    seen = {"limits": 0, "contacts": 0}

    def note():
        seen["limits"] = max(seen["limits"], d.nl)
        seen["contacts"] = max(seen["contacts"], len(robot.get_contacts()["position"]))

    assert _lockstep(m, d, scene, robot, 1000, note) < 1e-10
    assert seen["limits"] >= 2 and seen["contacts"] >= 4, seen


def test_cone_limits_alone_match_mujoco(f64, tmp_path):
    """Ball joints whose only rows are their cone limits (no contact pair, no friction loss): the
    one-launch step meets a violated limit and hands the step to the constraint stage (in MuJoCo:
    limit rows from the first swing on; 2.3e-12 measured over 3 s)."""
    path = _write(tmp_path, '<body name="a" pos="0 0 1"><joint name="s" type="ball" range="0 30" damping="0.01"/>'
                            '<geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"/>'
                            '<body name="b" pos="0.3 0 0" quat="0.9 0.1 0.3 0.2">'
                            '<joint name="w" type="ball" pos="0.01 0.02 0" range="0 45" damping="0.01"/>'
                            '<geom type="box" size="0.1 0.03 0.02" pos="0.1 0 0"/></body></body>')
    m, d, scene, robot = _pair(path)
    velocity = np.random.default_rng(0).normal(size=m.nv)
    d.qvel[:] = velocity
    robot.set_dofs_velocity(torch.tensor(velocity))
    assert not scene.sim.slots[0].solver.colliders and robot.n_dofs == 6
    limits = []
    assert _lockstep(m, d, scene, robot, 1500, lambda: limits.append(d.nl)) < 1e-10
    assert max(limits) == 2


def test_a_turn_stored_past_half_a_turn_reads_as_mujocos(f64):
    """A quaternion with w < 0 (the same turn as −q) and not of unit length: the shoulder turned
    50° against its 40° cone, its spring pulling; MuJoCo 4 reads the turn through its wrap past π
    alike (200 steps), and the gradient w.r.t. that quaternion matches central differences."""
    m, d, scene, robot = _pair(BALLS, integrator="euler", requires_grad=True)
    turn = -1.3 * euler_xyz_to_quat(torch.tensor([0.0, np.deg2rad(50.0), 0.0], dtype=torch.float64))
    qpos = robot.get_qpos().detach().clone()
    qpos[0:4] = turn
    d.qpos[:] = qpos.numpy()
    robot.set_qpos(qpos)
    limits = []
    assert _lockstep(m, d, scene, robot, 200, lambda: limits.append(d.nl)) < 1e-10
    assert limits[0] >= 1
    weights = torch.tensor(np.random.default_rng(8).normal(size=(robot.n_links, 7)))
    loss = pose_loss(scene, robot, weights, 100, robot.set_qpos)

    for seed in range(2):
        assert_converged(directional_errors(loss, qpos, seed), f"w < 0, direction {seed}")


@pytest.mark.parametrize("joint, compiler, cone", [
    ('range="0 40"', "", 40.0), ('range="40 0"', "", None), ('range="0 0"', "", None), ('limited="true"', "", 0.0),
    ('limited="true" range="0 -10"', "", 0.0), ('limited="false" range="0 40"', "", None),
    ('range="0 0.5"', 'angle="radian"', np.rad2deg(0.5)),
])
def test_a_ball_joints_range_is_read_as_mujocos_compiler_reads_it(f64, tmp_path, joint, compiler, cone):
    """Limited when limited="true", or by autolimits where range[0] < range[1]; the cone's angle
    the larger value (0 holds the joint): each dof's upper bound from get_dofs_limit, checked
    against MuJoCo's jnt_limited and jnt_range."""
    path = _write(tmp_path, f'<body><joint name="b" type="ball" {joint}/><geom type="sphere" size="0.1"/></body>',
                  f"<compiler {compiler}/>")
    m = mujoco.MjModel.from_xml_path(path)
    assert bool(m.jnt_limited[0]) == (cone is not None)
    scene = gs.Scene()
    robot = scene.add_entity(gs.morphs.MJCF(file=path))
    scene.build()
    lower, upper = robot.get_dofs_limit()
    expected = np.inf if cone is None else np.deg2rad(cone)
    assert torch.equal(lower, torch.full((3,), -np.inf, dtype=torch.float64))
    torch.testing.assert_close(upper, torch.full((3,), expected, dtype=torch.float64), rtol=1e-15, atol=0)
    if cone is not None:
        assert np.isclose(max(m.jnt_range[0]), max(0.0, np.deg2rad(cone)), rtol=1e-15, atol=0)


@pytest.mark.parametrize("joints", [("hinge", "ball"), ("slide", "ball"), ("ball", "slide")])
def test_a_ball_joint_beside_another_in_one_body_moves_as_mujocos(f64, tmp_path, joints):
    """A body's joints are composed in order (a ball joint after a hinge turns about the hinge's
    turned frame; a slide after a ball slides along its turned axis), anchors off the origin: 1 s
    from random velocities, to round-off (spinning at up to 23 rad/s, the last bits' differences
    grow to 4.5e-11–1.4e-10 as the loader's or the kernels' rounding changes)."""
    chain = "".join(f'<joint name="j{k}" type="{kind}" axis="0.3 1 0.2" pos="0.01 0.02 {0.03 * k}"/>'
                    for k, kind in enumerate(joints))
    path = _write(tmp_path, f'<body name="a" pos="0 0 1" euler="10 20 30">{chain}<geom type="capsule" '
                            f'fromto="0 0 0 0.3 0.1 0" size="0.03"/></body>')
    m, d, scene, robot = _pair(path)
    velocity = np.random.default_rng(9).normal(size=m.nv)
    d.qvel[:] = velocity
    robot.set_dofs_velocity(torch.tensor(velocity))
    assert _lockstep(m, d, scene, robot, 500) < 5e-10


def _pendulum(tmp_path, dt):
    """A sphere (r 5 cm, 1000 kg/m³) 0.5 m below a ball joint on the world; no damping."""
    path = _write(tmp_path, '<body name="bob" pos="0 0 2"><joint name="pivot" type="ball"/>'
                            '<geom type="sphere" size="0.05" pos="0 0 -0.5" density="1000"/></body>')
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=dt))
    robot = scene.add_entity(gs.morphs.MJCF(file=path))
    scene.build()
    return scene, robot


def test_spherical_pendulum_conserves_energy_and_vertical_momentum_to_first_order(f64, tmp_path):
    """Tilted 0.3 rad and spinning (body-frame ω (0, 1, 2) rad/s): gravity has no moment about the
    vertical through the pivot, so L_z is conserved, and so is the energy. The semi-implicit Euler
    step keeps both to O(h): over 4 s the largest deviation (sampled every 5 steps) halves with the
    time step (measured ratios 0.50, 0.50; MuJoCo's Euler integrator drifts alike, the same bits to
    1e-8), and is at h = 1 ms under 2 % (L_z) and 4e-4 (energy) of their values (measured 0.97 %,
    2.0e-4)."""
    deviations = []
    for dt in (2e-3, 1e-3):
        scene, robot = _pendulum(tmp_path, dt)
        mass, radius, arm = float(robot.links[1].get_mass()), 0.05, 0.5
        spin = 0.4 * mass * radius ** 2
        inertia = torch.diag(torch.tensor([spin + mass * arm ** 2, spin + mass * arm ** 2, spin], dtype=torch.float64))
        robot.set_dofs_position(torch.tensor([0.3, 0.0, 0.0]))
        robot.set_dofs_velocity(torch.tensor([0.0, 1.0, 2.0]))

        def vertical_momentum():  # about the pivot: R I_pivot Rᵀ ω, world z
            rot = quat_to_mat(robot.get_links_quat()[1])
            return float((rot @ inertia @ rot.T @ robot.get_links_ang()[1])[2])

        momentum, energy = vertical_momentum(), float(robot.get_total_energy())
        worst = np.zeros(2)
        for _ in range(int(round(4.0 / dt / 5))):
            for _ in range(5):
                scene.step()
            worst = np.maximum(worst, [abs(vertical_momentum() - momentum), abs(float(robot.get_total_energy())
                                                                                   - energy)])
        deviations.append(worst / [abs(momentum), abs(energy)])
    ratio = deviations[1] / deviations[0]
    assert np.all((0.45 < ratio) & (ratio < 0.55)), f"deviation ratios (L_z, E) at h/2: {ratio}"
    assert deviations[1][0] < 2e-2 and deviations[1][1] < 4e-4, deviations


def test_spherical_pendulum_swings_at_the_physical_pendulums_period(f64, tmp_path):
    """Small swings (0.02 rad) about one axis: T = 2π √(I_pivot / (m g l)), I_pivot = ⅖ m r² + m l²
    (measured 2.4e-5 off at h = 1 ms: the amplitude's θ²/16 correction)."""
    dt = 1e-3
    scene, robot = _pendulum(tmp_path, dt)
    mass, radius, arm = float(robot.links[1].get_mass()), 0.05, 0.5
    period = 2 * np.pi * np.sqrt((0.4 * mass * radius ** 2 + mass * arm ** 2) / (mass * 9.81 * arm))
    robot.set_dofs_position(torch.tensor([0.02, 0.0, 0.0]))
    angle = []
    for _ in range(int(5 * period / dt)):
        scene.step()
        angle.append(float(robot.get_dofs_position()[0]))
    angle = np.array(angle)
    time = (np.arange(len(angle)) + 1) * dt
    down = [time[k] + angle[k] * dt / (angle[k] - angle[k + 1]) for k in range(len(angle) - 1)
            if angle[k] > 0 >= angle[k + 1]]
    assert len(down) >= 4
    assert abs(np.diff(down).mean() / period - 1) < 1e-4


def _arm_turns(robot):
    """The arm's two ball joints' turn angles (rad)."""
    qpos = robot.get_qpos()
    return torch.stack([_turn(qpos[0:4]), _turn(qpos[5:9])])


@pytest.mark.parametrize("what", ["qpos", "velocity", "stiffness", "damping", "mass", "force"])
def test_gradients_through_ball_joints_match_finite_differences(f64, what):
    """Every differentiable input a ball joint touches, 0.4 s from a fast start: the arm against
    both cone limits, the rope landing (contacts); loss a fixed weighting of every link's pose."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002, requires_grad=True))
    robot = scene.add_entity(gs.morphs.MJCF(file=BALLS))
    scene.build()
    steps, dofs = 200, robot.n_dofs
    rng = np.random.default_rng(3)
    velocity = torch.tensor(rng.normal(0.0, 2.0, dofs))
    weights = torch.tensor(rng.normal(size=(robot.n_links, 7)))
    heavy = [k for k, link in enumerate(robot.links) if float(link.get_mass()) > 0]
    start_qpos = robot.get_qpos().detach().clone()
    start_qpos[0:4] = euler_xyz_to_quat(torch.tensor([0.2, -0.3, 0.1], dtype=torch.float64)) * 1.1  # (not unit)
    start_qpos[11] = 0.1  # the rope's root lower: it lands within the rollout
    springs = [k for k in range(dofs) if not 7 <= k < 13]  # (the rope's free root has none)
    spring_dofs = torch.tensor([3, 1, 3, 3, 3, 3, 3])  # one stiffness a joint: shoulder, elbow, wrist, the rope's
    start = {"qpos": start_qpos, "velocity": velocity,
             "stiffness": torch.linspace(0.1, 0.6, len(spring_dofs), dtype=torch.float64),
             "damping": torch.full((dofs,), 0.02, dtype=torch.float64),
             "mass": robot.get_links_mass().detach().clone()[heavy],
             "force": torch.tensor(rng.normal(0.0, 0.05, (steps, dofs)))}[what]
    seen = {"turn": torch.zeros(2, dtype=torch.float64), "contacts": 0}

    def loss(x):
        scene.reset()
        robot.set_qpos(x if what == "qpos" else start_qpos)
        robot.set_dofs_velocity(x if what == "velocity" else velocity)
        if what == "stiffness":
            robot.set_dofs_stiffness(x.repeat_interleave(spring_dofs), dofs_idx_local=springs)
        elif what == "damping":
            robot.set_dofs_damping(x)
        elif what == "mass":
            robot.set_links_mass(x, links_idx_local=heavy)
        for t in range(steps):
            if what == "force":
                robot.control_dofs_force(x[t])
            scene.step()
            seen["turn"] = torch.maximum(seen["turn"], _arm_turns(robot).detach())
            seen["contacts"] = max(seen["contacts"], len(robot.get_contacts()["position"]))
        return (torch.cat([robot.get_links_pos(), robot.get_links_quat()], -1) * weights).sum()

    for seed in range(2):
        assert_converged(directional_errors(loss, start, seed), f"{what}, direction {seed}")
    limits = torch.tensor([np.deg2rad(limit) for _, limit in ARM_BALLS.values()], dtype=torch.float64)
    assert bool((seen["turn"] > limits).all()) and seen["contacts"] >= 2, seen  # both cones and the ground met


def test_repeated_rollouts_give_bit_identical_ball_joint_gradients(f64):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002, requires_grad=True))
    robot = scene.add_entity(gs.morphs.MJCF(file=BALLS))
    scene.build()
    velocity = torch.tensor(np.random.default_rng(4).normal(0.0, 2.0, robot.n_dofs))
    grads = []
    for _ in range(2):
        scene.reset()
        start = velocity.clone().requires_grad_(True)
        robot.set_dofs_velocity(start)
        for _ in range(100):
            scene.step()
        robot.get_qpos().sum().backward()
        grads.append(start.grad)
    assert torch.equal(grads[0], grads[1])


def test_batched_ball_joints_equal_single_envs_bitwise(f64):
    """On the thread pool (enough envs) and alone: the same bits, cone limits and contacts included."""
    built = []
    for n_envs in (SERIAL_LINK_ENVS // 10 + 1, 0):
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002, substeps=2))
        built.append((scene, scene.add_entity(gs.morphs.MJCF(file=BALLS))))
        scene.build(n_envs=n_envs)
    (batched, robot_b), (single, robot_s) = built
    n_envs = batched.n_envs
    velocity = torch.tensor(np.random.default_rng(6).normal(0.0, 2.0, (n_envs, robot_b.n_dofs)))
    velocity[:, 7:13] *= 0.1  # (the rope's free root gently: it stays on the ground)
    qpos = robot_s.get_qpos().detach().clone()
    qpos[11] = 0.05  # the rope's root near the ground: it lands at once
    robot_b.set_qpos(qpos.expand(n_envs, -1))
    robot_b.set_dofs_velocity(velocity)
    touched = torch.zeros(n_envs, dtype=torch.bool)
    for _ in range(40):
        batched.step()
        touched |= robot_b.get_contacts()["valid_mask"].any(1).cpu()
    assert bool(touched.all())
    for e in (0, n_envs // 2, n_envs - 1):
        single.reset()
        robot_s.set_qpos(qpos)
        robot_s.set_dofs_velocity(velocity[e])
        for _ in range(40):
            single.step()
        assert torch.equal(robot_s.get_qpos(), robot_b.get_qpos()[e])
        assert torch.equal(robot_s.get_dofs_velocity(), robot_b.get_dofs_velocity()[e])


def test_a_ball_joints_dofs_read_and_set_euler_angles(f64):
    """As Genesis's: a ball joint's three dof positions are intrinsic X-Y-Z Euler angles of its
    quaternion; setting some keeps the others; its dof velocities are the body-frame angular
    velocity (the link's world ω is R_link times them)."""
    scene = gs.Scene()
    robot = scene.add_entity(gs.morphs.MJCF(file=BALLS))
    scene.build()
    robot.set_qpos(euler_xyz_to_quat(torch.tensor([-0.4, 0.7, 0.2], dtype=torch.float64)), qs_idx_local=[0, 1, 2, 3])
    angles = torch.tensor([0.3, -0.2, 0.5], dtype=torch.float64)
    robot.set_dofs_position(angles, dofs_idx_local=[4, 5, 6])
    torch.testing.assert_close(robot.get_qpos()[5:9], euler_xyz_to_quat(angles), rtol=0, atol=1e-15)
    torch.testing.assert_close(robot.get_dofs_position([4, 5, 6]), angles, rtol=0, atol=1e-14)
    robot.set_dofs_position(torch.tensor([0.1], dtype=torch.float64), dofs_idx_local=[5])
    torch.testing.assert_close(robot.get_dofs_position([4, 5, 6]), torch.tensor([0.3, 0.1, 0.5], dtype=torch.float64),
                               rtol=0, atol=1e-14)
    torch.testing.assert_close(robot.get_dofs_position([0, 1, 2]), torch.tensor([-0.4, 0.7, 0.2], dtype=torch.float64),
                               rtol=0, atol=1e-14)
    omega = torch.tensor([0.4, -1.0, 2.0], dtype=torch.float64)
    robot.set_dofs_velocity(omega, dofs_idx_local=[4, 5, 6])
    hand = robot.get_link("hand")
    torch.testing.assert_close(hand.get_ang(), quat_to_mat(hand.get_quat()) @ omega, rtol=0, atol=1e-14)


def test_jacobian_and_energy_of_ball_joints_match_mujoco(f64):
    """get_jacobian of the hand's box centre (mj_jac) and the energies with ball springs
    (mjENBL_ENERGY: MuJoCo's ½ k |r|², r the turn's rotation vector) at a random state; the
    potential's stiffness gradient is ½ r² per dof."""
    m = mujoco.MjModel.from_xml_path(BALLS)
    m.opt.enableflags |= mujoco.mjtEnableBit.mjENBL_ENERGY
    d = mujoco.MjData(m)
    scene = gs.Scene(sim_options=gs.options.SimOptions(requires_grad=True))
    robot = scene.add_entity(gs.morphs.MJCF(file=BALLS))
    scene.build()
    rng = np.random.default_rng(7)
    qpos = m.qpos0.copy()
    for first in (0, 5, 12, 16, 20, 24, 28):  # every quaternion (the arm's balls, the rope's root and balls)
        quat = rng.normal(size=4)
        qpos[first: first + 4] = quat / np.linalg.norm(quat)
    qpos[4] = 0.4
    d.qpos[:], d.qvel[:] = qpos, rng.normal(size=m.nv)
    mujoco.mj_forward(m, d)
    stiffness = torch.tensor(np.repeat(m.jnt_stiffness, [3, 1, 3, 6, 3, 3, 3, 3]), requires_grad=True)
    robot.set_qpos(torch.tensor(qpos))
    robot.set_dofs_velocity(torch.tensor(d.qvel))
    robot.set_dofs_stiffness(stiffness)
    hand = robot.get_link("hand")
    point = np.array([0.08, 0.0, 0.0])
    jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    mujoco.mj_jac(m, d, jacp, jacr, d.xpos[3] + d.xmat[3].reshape(3, 3) @ point, 3)  # (body 3: the hand)
    np.testing.assert_allclose(robot.get_jacobian(hand, torch.tensor(point)).detach().numpy(),
                               np.vstack([jacp, jacr]), rtol=0, atol=1e-14)
    kinetic, potential = robot.get_kinetic_energy(), robot.get_potential_energy()
    assert abs(kinetic.item() - d.energy[1]) < 1e-13 and abs(potential.item() - d.energy[0]) < 1e-13
    potential.backward()
    turns = []
    for first in (0, 5, 16, 20, 24, 28):  # the ball joints' rotation vectors (mju_subQuat from the identity)
        turn = np.zeros(3)
        mujoco.mju_subQuat(turn, qpos[first: first + 4], np.array([1.0, 0, 0, 0]))
        turns.append(turn)
    expected = np.concatenate([turns[0], [0.0], turns[1], np.zeros(6), *turns[2:]]) ** 2 / 2
    expected[3] = (qpos[4] - m.qpos_spring[4]) ** 2 / 2
    np.testing.assert_allclose(stiffness.grad.numpy(), expected, rtol=1e-12, atol=1e-15)


def test_inverse_kinematics_turns_ball_joints(f64):
    """The hand's pose at a random arm state is found again from the rest pose, moving the two
    ball joints and the hinge (limits not respected: the target is reachable)."""
    scene = gs.Scene()
    robot = scene.add_entity(gs.morphs.MJCF(file=BALLS))
    scene.build()
    hand = robot.get_link("hand")
    robot.set_dofs_position(torch.tensor([0.3, -0.4, 0.2, 0.5, 0.2, 0.3, -0.6], dtype=torch.float64),
                            dofs_idx_local=list(range(7)))
    pos, quat = hand.get_pos().clone(), hand.get_quat().clone()
    robot.set_dofs_position(torch.zeros(7, dtype=torch.float64), dofs_idx_local=list(range(7)))
    qpos, error = robot.inverse_kinematics(hand, pos=pos, quat=quat, respect_joint_limit=False,
                                           max_solver_iters=100, dofs_idx_local=list(range(7)), return_error=True)
    assert float(error[:3].norm()) < 5e-4 and float(error[3:].norm()) < 5e-3
    robot.set_qpos(qpos)
    torch.testing.assert_close(hand.get_pos(), pos, rtol=0, atol=5e-4)
    # a ball joint left out keeps its quaternion bit for bit, also one a little off unit norm (a step
    # of zero turned and normalised it)
    start = qpos.clone()
    start[:4] = torch.tensor([1.0, 1e-3, 0.0, 0.0], dtype=torch.float64)
    qpos = robot.inverse_kinematics(hand, pos=pos + 0.01, init_qpos=start, dofs_idx_local=[3, 4, 5, 6])
    assert torch.equal(qpos[:4], start[:4]) and not torch.equal(qpos[4:], start[4:])
    # two of a ball joint's three dofs move it (a first version of the above left it still)
    robot.set_dofs_position(torch.tensor([0.0, 0.3, -0.2, 0, 0, 0, 0], dtype=torch.float64), dofs_idx_local=range(7))
    pos = hand.get_pos().clone()
    robot.set_dofs_position(torch.zeros(7, dtype=torch.float64), dofs_idx_local=list(range(7)))
    qpos, error = robot.inverse_kinematics(hand, pos=pos, respect_joint_limit=False, max_solver_iters=100,
                                           dofs_idx_local=[1, 2], return_error=True)
    assert float(error[:3].norm()) < 5e-4


def test_ball_joint_inputs_are_checked(f64):
    """A zero quaternion, a position servo on a part of a ball joint's dofs and unequal stiffness on its
    three dofs (a spring no energy has) are named errors; a ball spring is accepted, a free
    joint's is not (the MJCF attributes a ball joint does not take:
    test_mjcf.test_unsupported_or_malformed_files_are_named)."""
    scene = gs.Scene()
    robot = scene.add_entity(gs.morphs.MJCF(file=BALLS))
    scene.build()
    with pytest.raises(InvalidInputError, match="non-zero quaternions"):
        robot.set_qpos(torch.zeros(4, dtype=torch.float64), qs_idx_local=[0, 1, 2, 3])
    with pytest.raises(InvalidInputError, match="three rotation dofs together"):
        robot.control_dofs_position(torch.zeros(2), dofs_idx_local=[0, 1])
    robot.set_dofs_stiffness(torch.ones(3), dofs_idx_local=[4, 5, 6])
    with pytest.raises(InvalidInputError, match="free joint's dofs"):
        robot.set_dofs_stiffness(torch.ones(3), dofs_idx_local=[7, 8, 9])
    for values, dofs in (([1.0, 2.0, 1.0], [4, 5, 6]), ([2.0], [5])):  # (one spring a ball joint, as MuJoCo's)
        with pytest.raises(InvalidInputError, match="equal on the three dofs of a ball joint"):
            robot.set_dofs_stiffness(torch.tensor(values), dofs_idx_local=dofs)
    robot.set_dofs_stiffness(torch.tensor([2.0, 2.0, 2.0, 0.5]), dofs_idx_local=[4, 5, 6, 3])
