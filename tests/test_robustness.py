"""A diverging body stays alone: it neither poisons other bodies nor goes unnoticed; a body far
from the world origin moves as it would at the origin."""
import pytest
import torch

import genesis_lite as gs
from tests.conftest import asset, warns


def _two_pendulums(check_nan=False):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, check_nan=check_nan),
                     rigid_options=gs.options.RigidOptions(enable_joint_limit=False))
    wild = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True), name="wild")
    calm = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True, pos=(1, 0, 0)), name="calm")
    scene.build()
    return scene, wild, calm


def _diverge(wild):
    # an explicit servo far too stiff for dt blows up within a few steps
    wild.set_dofs_force_range([-1e30, -1e30], [1e30, 1e30])
    wild.set_dofs_kp([1e12, 1e12])
    wild.control_dofs_position([1.0, -1.0])


def test_diverging_entity_does_not_touch_others(f64):
    scene, wild, calm = _two_pendulums()
    calm.set_dofs_position([0.3, -0.2])
    reference = []
    for _ in range(30):
        scene.step()
        reference.append(calm.get_dofs_position().clone())
    scene.reset()
    calm.set_dofs_position([0.3, -0.2])
    _diverge(wild)
    for t in range(30):
        scene.step()
        assert torch.equal(calm.get_dofs_position(), reference[t])
    assert not bool(torch.isfinite(wild.get_dofs_position()).all())


def test_check_nan_names_step_and_entities(f64):
    scene, wild, _ = _two_pendulums(check_nan=True)
    _diverge(wild)
    taken = 0
    with pytest.raises(gs.SimulationError, match=r"step \d+.*wild") as info:
        for _ in range(50):
            taken += 1
            scene.step()
    # the diverging entity alone (the message listed every entity of the solver: in a scene of
    # several robots the user could not tell which one; found by an adversarial pass)
    assert "(entities: wild)" in str(info.value), str(info.value)
    assert str(info.value).startswith(f"step {taken - 1}:")  # the step that raised, counted from 0
    # and counted: a caught error, then another step, recorded two steps at one index (a review)
    assert scene.sim.step_index == taken


def test_rigid_blow_up_warns_once_a_rollout_without_check_nan(f64, caplog):
    """Without check_nan a diverging rigid entity is not silent: the first non-finite step warns,
    naming step and entity and pointing to check_nan, once a rollout (again after a reset)."""
    scene, wild, _ = _two_pendulums()
    for rollout in range(2):
        caplog.clear()
        _diverge(wild)
        for _ in range(50):
            scene.step()
        warnings = [r.getMessage() for r in caplog.records if "non-finite" in r.getMessage()]
        assert len(warnings) == 1 and "wild" in warnings[0] and "check_nan" in warnings[0], (rollout, warnings)
        assert not bool(torch.isfinite(wild.get_dofs_position()).all())
        scene.reset()


def test_mpm_blow_up_is_not_hidden_by_the_walls(f64, caplog):
    """A stiff body at a substep far above its stability limit blows up; the walls clamp its NaN
    positions back inside, so without check_nan the scene warns once a rollout (until a reset),
    naming step and entity; with it, the step raises."""
    def blow_up(check_nan):
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=2e-3, substeps=2, check_nan=check_nan),
                         mpm_options=gs.options.MPMOptions(lower_bound=(-0.3, -0.3, 0.0), upper_bound=(0.3, 0.3, 0.6),
                                                           grid_density=32))
        scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.3), size=(0.1, 0.1, 0.1)),
                         material=gs.materials.MPM.Elastic(E=1e9), name="stiff")
        scene.build()
        return scene

    scene = blow_up(False)
    caplog.clear()
    for _ in range(60):
        scene.step()
    warnings = [r.getMessage() for r in caplog.records if "non-finite" in r.getMessage()]
    assert len(warnings) == 1 and "stiff" in warnings[0] and "check_nan" in warnings[0], warnings
    assert not bool(torch.isfinite(scene.entities[0].get_particles_vel()).all())
    scene.reset()  # a new rollout warns again
    caplog.clear()
    for _ in range(60):
        scene.step()
    assert sum("non-finite" in r.getMessage() for r in caplog.records) == 1
    with pytest.raises(gs.SimulationError, match=r"step \d+.*stiff"):
        scene = blow_up(True)
        for _ in range(60):
            scene.step()


def _spinning_quadruped(at):
    """Final qvel and link velocities of the quadruped thrown tumbling, its legs swinging, in zero
    gravity for 1 s from base position ``at`` (3,) m."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, gravity=(0.0, 0.0, 0.0)))
    robot = scene.add_entity(gs.morphs.URDF(file=asset("quadruped.urdf"), pos=at))
    scene.build()
    robot.set_dofs_velocity(torch.tensor([0.5, 0.2, 0.1, 3.0, 2.0, 1.0] + [1.0] * (robot.n_dofs - 6)))
    for _ in range(100):
        scene.step()
    return robot.get_dofs_velocity(), robot.get_links_vel()


def test_far_from_the_origin_float32_moves_as_at_the_origin(f32):
    """Spatial quantities are taken about each tree's root link (kinematics.reference), not the world
    origin, so float32 pays for a body's distance from the origin only in the resolution of its
    positions. About the origin (before), the same throw 30 m away ended with velocities 18 % off
    and 300 m away the mass matrix was not positive definite (build raised); now 1e-5 and 1e-4
    (measured 2026-11-28; the positions' resolution: 2e-6 m at 30 m, 3e-5 m at 300 m)."""
    qvel, links_vel = _spinning_quadruped((0.0, 0.0, 1.0))
    for distance, bound in ((30.0, 1e-4), (300.0, 1e-3)):
        far_qvel, far_links_vel = _spinning_quadruped((distance, -distance, 1.0))
        assert (far_qvel - qvel).norm() / qvel.norm() < bound, distance
        assert (far_links_vel - links_vel).norm() / links_vel.norm() < bound, distance


@pytest.mark.parametrize("checkpoint_interval", [1, 4])
def test_a_backward_through_a_blow_up_leaves_no_warning_for_the_next_rollout(f64, caplog, checkpoint_interval):
    """A backward replays the steps of its rollout, the non-finite ones too (and between
    checkpoints takes them again): that flags nothing, so the next, finite rollout is not reported
    non-finite at its first step (it was, naming every entity, rigid and MPM alike; found by a
    gradient probe, and with checkpoints by a review)."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=1e-3, substeps=2, requires_grad=True,
                                                       checkpoint_interval=checkpoint_interval),
                     rigid_options=gs.options.RigidOptions(enable_joint_limit=False),
                     mpm_options=gs.options.MPMOptions(lower_bound=(-0.3, -0.3, 0.0), upper_bound=(0.3, 0.3, 0.6),
                                                       grid_density=32))
    wild = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True, pos=(1, 0, 0)), name="wild")
    jelly = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.3), size=(0.1, 0.1, 0.1)),
                             material=gs.materials.MPM.Elastic(E=1e5), name="jelly")
    scene.build()
    rho = torch.tensor(1000.0, requires_grad=True)
    for blow_up, steps in ((True, 60), (False, 3)):
        scene.reset()
        caplog.clear()
        if blow_up:
            with warns(caplog, "stability limit"):
                jelly.set_material_params(E=1e10, rho=rho)
            _diverge(wild)
        else:
            jelly.set_material_params(E=1e5, rho=rho)
        for _ in range(steps):
            scene.step()
        warnings = [r.getMessage() for r in caplog.records if "non-finite" in r.getMessage()]
        assert len(warnings) == (2 if blow_up else 0), warnings  # once per solver
        (wild.get_dofs_position().sum() + jelly.get_particles_pos().sum()).backward()


def test_a_diverged_env_leaves_the_others_gradients_finite(f64):
    """Envs are independent: a loss that leaves out an env whose state went non-finite gets
    finite, exact gradients in what the envs share (a policy's weight). The reverse of that env
    multiplied its zero gradients by NaN partials (0 · NaN), and an external wrench's offset was
    inf − inf at the link origin; both gave NaN (found by a gradient probe). Against central
    differences."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True),
                     rigid_options=gs.options.RigidOptions(enable_joint_limit=False))
    box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.3, 0.1), pos=(0.0, 0.0, 3.0)),
                           material=gs.materials.Rigid(rho=200.0))  # light enough for env 1 to tumble to inf
    arm = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True, pos=(1, 0, 0)))
    scene.build(n_envs=2)
    force = torch.tensor([[[1.0, 0.0, 0.0]], [[0.0, 0.0, 0.0]]], dtype=torch.float64)
    torque = torch.tensor([[[0.0, 0.0, 0.0]], [[3.0, -2.0, 1.0]]], dtype=torch.float64)  # env 1 tumbles to inf

    def final_positions(gain):
        scene.reset()
        arm.set_dofs_force_range(-1e30 * torch.ones(2, 2), 1e30 * torch.ones(2, 2))
        arm.set_dofs_kp([[0.0, 0.0], [1e12, 1e12]])  # env 1's explicit servo far too stiff
        arm.control_dofs_position([[1.0, -1.0]], envs_idx=[1])
        for _ in range(50):
            box.apply_links_external_wrench(force=gain * force, torque=gain * torque, links_idx_local=[0])
            arm.control_dofs_force(gain * torch.tensor([[0.3, -0.2]], dtype=torch.float64), envs_idx=[0])
            scene.step()
        return box.get_pos(), arm.get_dofs_position()

    gain = torch.tensor(1.0, dtype=torch.float64, requires_grad=True)
    pos, q = final_positions(gain)
    assert not bool(torch.isfinite(pos[1]).all()) and not bool(torch.isfinite(q[1]).all())
    (pos[0].sum() + q[0].sum()).backward()
    with torch.no_grad():
        ends = [final_positions(torch.tensor(1.0 + eps, dtype=torch.float64)) for eps in (1e-6, -1e-6)]
        central = sum(float(p[0].sum() + a[0].sum()) * sign for (p, a), sign in zip(ends, (1, -1))) / 2e-6
    assert float(gain.grad) == pytest.approx(central, rel=1e-6)


@pytest.mark.parametrize("check_nan", [False, True])
def test_a_gradient_that_is_not_finite_is_reported(f64, caplog, check_nan):
    """An unstable forward can stay finite while its exact derivative overflows (sand at E 1e8 in
    float32: the gradient inf by step 19, nothing said; found by an MPM probe). The gradient that
    reaches the rollout's first step is checked once a backward: not finite, it warns once a
    rollout, under check_nan too (a warning: the state's gradient has entries no input reaches).
    Here a loss whose slope is infinite."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True, check_nan=check_nan))
    robot = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True))
    scene.build()
    velocity = torch.tensor([0.5, -0.2], dtype=torch.float64, requires_grad=True)
    for slope, reset, reported in ((1.0, True, 0), (torch.inf, True, 1), (torch.inf, False, 0), (torch.inf, True, 1)):
        if reset:
            scene.reset()
            robot.set_dofs_velocity(velocity)
        caplog.clear()
        velocity.grad = None
        for _ in range(5):
            scene.step()
        (robot.get_dofs_position() * slope).sum().backward(retain_graph=True)  # (no reset: once a rollout)
        assert len([r for r in caplog.records if "is not finite" in r.getMessage()]) == reported
        assert bool(torch.isfinite(velocity.grad).all()) == (slope == 1.0)
