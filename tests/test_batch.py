"""Batched scenes (n_envs > 0): every env evolves exactly as it would alone, getters gain a
leading batch dimension, and envs_idx restricts setters to the given envs.
"""
import inspect

import numpy as np
import pytest
import torch

import genesis_lite as gs
from genesis_lite.solvers.rigid.data import SERIAL_LINK_ENVS
from tests.conftest import asset, pybullet

KUKA = pybullet("kuka_iiwa", "model.urdf")
KUKA_FREE = pybullet("kuka_iiwa", "model_free_base.urdf")
N_ENVS = 64
N_STEPS = 50


def _scene(path, n_envs, fixed=True):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01))
    robot = scene.add_entity(gs.morphs.URDF(file=path, fixed=fixed), name="kuka")
    scene.build(n_envs=n_envs)
    return scene, robot


@pytest.fixture(scope="module")
def scenes():
    """(batched scene, its robot, single-env scene, its robot): fixed-base KUKA, float64."""
    gs.init(precision="64", logging_level="warning")
    batched, robot_b = _scene(KUKA, N_ENVS)
    single, robot_s = _scene(KUKA, 0)
    yield batched, robot_b, single, robot_s
    batched.destroy()
    single.destroy()


def _inputs(n_dofs):
    """Random initial states (N_ENVS, n_dofs) ×2 and per-step, per-env forces (N_STEPS, N_ENVS, n_dofs)."""
    rng = np.random.default_rng(1234)
    qpos = rng.uniform(-1.5, 1.5, (N_ENVS, n_dofs))
    qvel = rng.uniform(-2.0, 2.0, (N_ENVS, n_dofs))
    force = rng.normal(0.0, 20.0, (N_STEPS, N_ENVS, n_dofs))
    as_t = lambda a: torch.as_tensor(a, dtype=gs.tc_float, device=gs.device)  # noqa: E731
    return as_t(qpos), as_t(qvel), as_t(force)


def test_batch_equals_single_envs_bitwise(f64, scenes):
    batched, robot_b, single, robot_s = scenes
    qpos, qvel, force = _inputs(robot_b.n_dofs)

    batched.reset()
    robot_b.set_dofs_position(qpos)
    robot_b.set_dofs_velocity(qvel)
    traj_b = [torch.cat([robot_b.get_dofs_position(), robot_b.get_dofs_velocity()], dim=-1)]
    for k in range(N_STEPS):
        robot_b.control_dofs_force(force[k])
        batched.step()
        traj_b.append(torch.cat([robot_b.get_dofs_position(), robot_b.get_dofs_velocity()], dim=-1))
    traj_b = torch.stack(traj_b, dim=1)  # (N_ENVS, N_STEPS + 1, 2 n_dofs)
    assert traj_b.shape == (N_ENVS, N_STEPS + 1, 2 * robot_b.n_dofs)
    assert torch.isfinite(traj_b).all()
    # envs really differ (otherwise comparing them would prove little)
    assert (traj_b[1:, -1] != traj_b[0, -1]).any(dim=-1).all()

    # the same rollouts, one env at a time, in an unbatched scene (reset between them)
    for e in range(N_ENVS):
        single.reset()
        robot_s.set_dofs_position(qpos[e])
        robot_s.set_dofs_velocity(qvel[e])
        traj = [torch.cat([robot_s.get_dofs_position(), robot_s.get_dofs_velocity()])]
        for k in range(N_STEPS):
            robot_s.control_dofs_force(force[k, e])
            single.step()
            traj.append(torch.cat([robot_s.get_dofs_position(), robot_s.get_dofs_velocity()]))
        traj = torch.stack(traj)
        if not torch.equal(traj, traj_b[e]):
            diff = (traj - traj_b[e]).abs()
            step = int(torch.nonzero(diff.amax(dim=1))[0, 0])
            pytest.fail(f"env {e}: batched trajectory differs from the single-env one from step {step} on "
                        f"(max |diff| {diff.max().item():.3g})")
    # the forces mattered: without them env N_ENVS - 1 ends elsewhere
    single.reset()
    robot_s.set_dofs_position(qpos[-1])
    robot_s.set_dofs_velocity(qvel[-1])
    for _ in range(N_STEPS):
        single.step()
    assert (robot_s.get_dofs_position() - traj_b[-1, -1, :robot_s.n_dofs]).abs().max() > 1e-3


def test_getters_have_batch_dim(f64, scenes):
    batched, robot, _, _ = scenes
    batched.reset()
    B, D, L = N_ENVS, robot.n_dofs, robot.n_links
    shapes = {
        "get_dofs_position": (B, D), "get_dofs_velocity": (B, D), "get_qpos": (B, robot.n_qs),
        "get_links_pos": (B, L, 3), "get_links_quat": (B, L, 4), "get_links_vel": (B, L, 3),
        "get_links_ang": (B, L, 3), "get_pos": (B, 3), "get_quat": (B, 4), "get_vel": (B, 3), "get_ang": (B, 3),
        "get_links_mass": (B, L), "get_mass": (B,), "get_mass_mat": (B, D, D), "get_dofs_kp": (B, D),
        "get_dofs_kv": (B, D), "get_dofs_damping": (B, D), "get_dofs_armature": (B, D),
        "get_dofs_control_force": (B, D),
    }
    for name, shape in shapes.items():
        value = getattr(robot, name)()
        assert tuple(value.shape) == shape, f"{name}: {tuple(value.shape)} != {shape}"
        assert isinstance(value, gs.Tensor) and value.dtype == torch.float64
    lo, hi = robot.get_dofs_force_range()
    assert lo.shape == hi.shape == (B, D)
    assert robot.get_link("lbr_iiwa_link_7").get_pos().shape == (B, 3)
    assert batched.get_gravity().shape == (B, 3)
    # a subset of envs: leading dim = len(envs_idx), in the order given
    envs = [5, 2, 63]
    assert robot.get_dofs_position(envs_idx=envs).shape == (3, D)
    assert robot.get_links_pos(envs_idx=envs).shape == (3, L, 3)
    assert robot.get_mass_mat(envs_idx=envs).shape == (3, D, D)
    assert robot.get_dofs_position(dofs_idx_local=[1, 3], envs_idx=[7]).shape == (1, 2)


def test_getters_of_every_env_equal_those_of_listed_envs_and_are_copies(f64, scenes):
    """Every getter that takes envs_idx: None (every env, read without an env gather) equals all
    envs listed, and a listed subset equals those rows of it, in the order given; a result is the
    caller's own copy (writing into it changes no later read)."""
    batched, robot, _, _ = scenes
    batched.reset()
    robot.set_dofs_velocity(torch.linspace(-1.0, 1.0, N_ENVS * robot.n_dofs, dtype=torch.float64).reshape(N_ENVS, -1))
    batched.step()
    envs = [5, 2, 63]
    # (get_coupling: only where MPM particles meet the entity, test_mpm_coupler.py)
    getters = [name for name in dir(robot) if name.startswith("get_") and name != "get_coupling"
               and "envs_idx" in inspect.signature(getattr(robot, name)).parameters]
    assert {"get_pos", "get_links_pos", "get_dofs_position", "get_qpos", "get_links_mass"} <= set(getters)
    for name in getters:
        getter = getattr(robot, name)
        every = getter()
        for part, listed, subset in zip(*(value if isinstance(value, tuple) else (value,) for value in
                                          (every, getter(envs_idx=list(range(N_ENVS))), getter(envs_idx=envs)))):
            assert torch.equal(part, listed), name
            assert torch.equal(part[envs], subset), name
        first = every[0] if isinstance(every, tuple) else every
        kept = first.clone()
        first.add_(1.0)
        again = getter()
        assert torch.equal(again[0] if isinstance(again, tuple) else again, kept), name


def test_envs_idx_setters_change_only_those_envs(f64, scenes):
    batched, robot, _, _ = scenes
    batched.reset()
    B, D = N_ENVS, robot.n_dofs
    rng = np.random.default_rng(7)
    base_q = torch.as_tensor(rng.uniform(-1, 1, (B, D)))
    robot.set_dofs_position(base_q)
    envs = torch.tensor([3, 17, 40])
    others = torch.ones(B, dtype=torch.bool)
    others[envs] = False

    def check(getter, new, label):
        now = getter()
        assert torch.equal(now[envs], new), f"{label}: the chosen envs did not get the new values"
        return now[others]

    # state
    before_q, before_v = robot.get_dofs_position().clone(), robot.get_dofs_velocity().clone()
    new_q = torch.as_tensor(rng.uniform(-1, 1, (3, D)))
    robot.set_dofs_position(new_q, envs_idx=envs)
    assert torch.equal(check(robot.get_dofs_position, new_q, "position"), before_q[others])
    new_v = torch.as_tensor(rng.uniform(-1, 1, (3, 2)))
    robot.set_dofs_velocity(new_v, dofs_idx_local=[0, 6], envs_idx=envs)
    now_v = robot.get_dofs_velocity()
    assert torch.equal(now_v[envs][:, [0, 6]], new_v)
    assert torch.equal(now_v[envs][:, 1:6], before_v[envs][:, 1:6])
    assert torch.equal(now_v[others], before_v[others])
    # parameters and controls
    params = {"set_links_mass": "get_links_mass", "set_dofs_damping": "get_dofs_damping", "set_dofs_kp": "get_dofs_kp"}
    saved = {setter: getattr(robot, getter)().clone() for setter, getter in params.items()}
    try:
        for setter, getter, cols in (("set_links_mass", "get_links_mass", robot.n_links),
                                     ("set_dofs_damping", "get_dofs_damping", D), ("set_dofs_kp", "get_dofs_kp", D),
                                     ("control_dofs_force", "get_dofs_control_force", D)):
            before = getattr(robot, getter)().clone()
            new = torch.as_tensor(rng.uniform(0.5, 2.0, (3, cols)))
            getattr(robot, setter)(new, envs_idx=envs)
            assert torch.equal(check(getattr(robot, getter), new, setter), before[others]), setter
        # one step later the untouched envs are exactly where they are without any of those calls
        batched.step()
        after = robot.get_dofs_position()[others]
        batched.reset()  # clears controls; parameters (mass, damping, kp) persist, for the chosen envs only
        robot.set_dofs_position(base_q)
        batched.step()
        assert torch.equal(robot.get_dofs_position()[others], after)
    finally:  # parameters persist across reset: give the shared scene its defaults back
        for setter, value in saved.items():
            getattr(robot, setter)(value)


def test_free_base_envs_idx(f64):
    scene, robot = _scene(KUKA_FREE, 4, fixed=False)
    try:
        assert robot.is_free and robot.n_dofs == 13 and robot.n_qs == 14
        before_dofs, before_qpos = robot.get_dofs_position().clone(), robot.get_qpos().clone()
        envs = [1, 3]
        new = torch.tensor([[0.1, 0.2, 0.3, 0.0, 0.0, 0.5], [-0.1, 0.0, 0.4, 0.3, 0.0, 0.0]], dtype=torch.float64)
        robot.set_dofs_position(new, dofs_idx_local=list(range(6)), envs_idx=envs)
        after = robot.get_dofs_position()
        assert torch.allclose(after[envs, :6], new, atol=1e-12)
        assert torch.equal(after[envs, 6:], before_dofs[envs, 6:])
        assert torch.equal(robot.get_qpos()[[0, 2]], before_qpos[[0, 2]])
        robot.set_pos(torch.tensor([[1.0, 2.0, 3.0]], dtype=torch.float64), envs_idx=[2])
        assert torch.equal(robot.get_pos()[2], torch.tensor([1.0, 2.0, 3.0], dtype=torch.float64))
        assert torch.equal(robot.get_qpos()[0], before_qpos[0])
        quat = torch.tensor([[0.0, 1.0, 0.0, 0.0]], dtype=torch.float64)
        robot.set_quat(quat, envs_idx=[0])
        assert torch.allclose(robot.get_quat()[0], quat[0], atol=1e-12)
        assert torch.equal(robot.get_qpos()[2, :3], torch.tensor([1.0, 2.0, 3.0], dtype=torch.float64))
        scene.step()
        assert torch.isfinite(robot.get_qpos()).all()
    finally:
        scene.destroy()


@pytest.mark.parametrize("precision, path, fixed", [
    ("32", KUKA_FREE, False),
    ("64", pybullet("quadruped", "minitaur.urdf"), False),
    ("64", pybullet("r2d2.urdf"), False),
    ("64", pybullet("cartpole.urdf"), True),
])
def test_batch_equals_single_envs_other_robots(precision, path, fixed):
    """(Last in the module: a change of precision restarts Taichi, which ends the module's scenes;
    the float32 case runs in conftest's float32 group.) Bitwise
    equality must not hinge on one robot: batched and single-env scenes run kernels
    compiled for different loop schedules (data.RigidData.schedule), and floating-point contraction could
    differ between them. Substeps > 1, float32 too; eight of the envs are replayed alone."""
    gs.init(precision=precision, logging_level="warning")
    single = gs.Scene(sim_options=gs.options.SimOptions(dt=0.005, substeps=2))
    robot_s = single.add_entity(gs.morphs.URDF(file=path, fixed=fixed))
    single.build()
    n_envs = SERIAL_LINK_ENVS // robot_s.n_links + 1  # the smallest batch that runs on the thread pool
    batched = gs.Scene(sim_options=gs.options.SimOptions(dt=0.005, substeps=2))
    robot_b = batched.add_entity(gs.morphs.URDF(file=path, fixed=fixed))
    batched.build(n_envs=n_envs)
    assert not batched.sim.slots[0].solver.data.schedule[0] and single.sim.slots[0].solver.data.schedule[0]
    built = [(batched, robot_b), (single, robot_s)]
    rng = np.random.default_rng(5)
    D, steps = robot_b.n_dofs, 20
    as_t = lambda a: torch.as_tensor(a, dtype=gs.tc_float)  # noqa: E731
    qpos, qvel = as_t(rng.uniform(-0.5, 0.5, (n_envs, D))), as_t(rng.uniform(-1, 1, (n_envs, D)))
    force = as_t(rng.normal(0, 1, (steps, n_envs, D)))
    robot_b.set_dofs_position(qpos)
    robot_b.set_dofs_velocity(qvel)
    for k in range(steps):
        robot_b.control_dofs_force(force[k])
        batched.step()
    for e in range(0, n_envs, n_envs // 8):
        single.reset()
        robot_s.set_dofs_position(qpos[e])
        robot_s.set_dofs_velocity(qvel[e])
        for k in range(steps):
            robot_s.control_dofs_force(force[k, e])
            single.step()
        for getter in ("get_qpos", "get_dofs_velocity"):
            alone, together = getattr(robot_s, getter)(), getattr(robot_b, getter)()[e]
            assert torch.equal(alone, together), f"env {e} {getter}: max |diff| {(alone - together).abs().max():.3g}"
    for scene, _ in built:
        scene.destroy()


def test_setting_one_envs_mass_recomputes_its_rows_scale_only(f64):
    """set_links_mass / set_dofs_armature with envs_idx recompute the rows' scale (invweight, from
    M at the initial pose) of the envs whose mass or armature changed, and keep the others' (it
    recomputed every env: 80 ms a call at 1024 envs): the result equals recomputing all of them,
    bit for bit, and the untouched envs keep theirs."""
    scene = gs.Scene(show_viewer=False)
    scene.add_entity(gs.morphs.Plane())
    box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.3, 0.1), pos=(0, 0, 0.05)))
    arm = scene.add_entity(gs.morphs.URDF(file=asset("arm3.urdf"), fixed=True, pos=(1, 0, 0)))
    scene.build(n_envs=3)
    solver = scene._rigid_solver
    before = scene.sim.inputs(solver)
    box.set_links_mass(torch.tensor([[2.5]], dtype=torch.float64), envs_idx=[1])
    arm.set_dofs_armature(torch.tensor([[0.1, 0.2, 0.3]], dtype=torch.float64), envs_idx=[2])
    after = scene.sim.inputs(solver)
    full = solver.derive_inputs(after)
    for name in ("invweight_t", "invweight_dof"):
        assert torch.equal(after[name], full[name]), name
        assert torch.equal(after[name][0], before[name][0]), name
    assert not torch.equal(after["invweight_t"][1], before["invweight_t"][1])
    assert not torch.equal(after["invweight_dof"][2], before["invweight_dof"][2])


def test_plain_masses_after_differentiable_ones_leave_the_old_graph(f64):
    """Masses requiring grad, a rollout and its backward, then plain masses (one env's unchanged):
    the rows' scale of the unchanged env was kept from the old, differentiable one, with its
    graph, and the next rollout's backward failed through the freed graph of the first. Now the
    scale keeps no graph, and a new rollout's backward runs."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True), show_viewer=False)
    box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.2, 0.2), pos=(0, 0, 0.099)))
    scene.build(n_envs=2)
    mass = box.get_links_mass().detach().clone()
    box.set_links_mass(mass.clone().requires_grad_(True))
    for _ in range(3):
        scene.step()
    box.get_dofs_position()[:, 2].sum().backward()
    plain = mass.clone()
    plain[1] *= 2.0
    box.set_links_mass(plain)
    assert not scene.sim.inputs(scene._rigid_solver)["invweight_t"].requires_grad
    scene.reset()
    velocity = torch.zeros((2, 6), dtype=torch.float64, requires_grad=True)
    box.set_dofs_velocity(velocity)
    for _ in range(3):
        scene.step()
    box.get_dofs_position()[:, 2].sum().backward()
    assert velocity.grad is not None


@pytest.mark.parametrize("how", ["setter", "reset"])
def test_setting_some_envs_leaves_the_others_steps_bit_for_bit(f64, how):
    """The constraint solve's warm start carries over from step to step in every env; writing the
    state of some envs (a setter or a reset with envs_idx) clears it in those envs only: the other
    envs step on as if nothing happened, bit for bit (it was cleared in every env, moving the
    others' solves within their tolerance)."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01),
                     rigid_options=gs.options.RigidOptions(friction_cone="elliptic"), show_viewer=False)
    scene.add_entity(gs.morphs.Plane())
    box = scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(0.0, 0.0, 0.0499)))
    scene.build(n_envs=3)

    def rollout(write):
        scene.reset()
        box.set_dofs_velocity(torch.tensor([[1.0, 0.2, 0.0, 0.0, 0.0, 0.5], [0.8, -0.2, 0.0, 0.0, 0.0, -0.5],
                                            [0.3, 0.6, 0.0, 0.0, 0.0, 2.0]], dtype=torch.float64))
        ends = []
        for k in range(20):
            if write and k == 8:
                if how == "setter":
                    box.set_dofs_position(torch.tensor([[0.5, 0.0, 0.2, 0.0, 0.0, 0.0]], dtype=torch.float64),
                                          envs_idx=[1])
                else:
                    scene.reset(envs_idx=[1])
            scene.step()
            ends.append(box.get_dofs_velocity()[[0, 2]].clone())
        return torch.stack(ends)

    assert torch.equal(rollout(True), rollout(False))
