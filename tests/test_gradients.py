"""Gradients of rigid rollouts against central finite differences (float64), and the graph's
behaviour across backward calls and resets (SPEC §3).

Each check compares the directional derivative g·v of a scalar loss, for a random unit
direction v, with the fourth-order central difference of L(x + kεv), k = ±1, ±2 (ε = 1e-6;
the fourth order keeps truncation negligible over long, sensitive horizons such as 2 s of a
KUKA arm, where gradients reach 1e5). The error is relative to ‖g‖, the scale of the
gradient: relative to |g·v| alone, a direction nearly orthogonal to g would make round-off
look like error.
"""
import numpy as np
import pytest
import torch

import genesis_lite as gs
from tests.conftest import asset, pybullet

ROBOTS = {"pendulum2": (asset("pendulum2.urdf"), True), "cartpole": (pybullet("cartpole.urdf"), True),
          "kuka": (pybullet("kuka_iiwa", "model.urdf"), True),
          "kuka_free": (pybullet("kuka_iiwa", "model_free_base.urdf"), False),
          "quadruped": (asset("quadruped.urdf"), False),  # a floating base with four branches
          "gripper": (asset("mimic_gripper.urdf"), True)}  # two mimic joints: joint equality rows
KINDS = ("dofs_position", "dofs_velocity", "force", "position_target", "velocity_target", "mass", "damping",
         "armature", "stiffness", "kp", "kv", "gravity", "frictionloss", "force_range", "wrench")
EPS = 1e-6
# fourth-order differences at two eps, the better one counts: round-off grows as eps shrinks
# (measured: the limited quadruped's kp case 6e-8 at 1e-5, 1e-6 at 1e-6, 8e-6 at 1e-7)
EPS_SCAN = (1e-5, 1e-6)
_SCENES = {}


# the parameters a test may set, which keep their value across reset() (as Genesis's): restored
# from the build's before a scene is reused, so that no test depends on the ones run before it
PARAMETERS = ("links_mass", "dofs_damping", "dofs_armature", "dofs_stiffness", "dofs_kp", "dofs_kv",
              "dofs_frictionloss")


def _scene(robot_name, n_envs, substeps, checkpoint_interval=1, limited=False):
    """One scene per configuration (building is the slow part), its parameters as built.
    ``limited``: joint limits on, friction loss 0.05 on every dof and every force clipped to ±1.5
    (a share of the controls clips). The constraint solve runs to 1e-14: the gradient is that of
    the exact solution, and finite differences of a solve stopped at 1e-8 see its stopping
    point move (up to 1e-6 of ‖g‖ here). No collision: these are the gradients of articulated
    dynamics and of the joint rows (contact: tests/test_contact_gradients.py)."""
    key = (robot_name, n_envs, substeps, checkpoint_interval, limited, gs.runtime.epoch)
    if key not in _SCENES:
        path, fixed = ROBOTS[robot_name]
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, substeps=substeps, requires_grad=True,
                                                           checkpoint_interval=checkpoint_interval),
                         rigid_options=gs.options.RigidOptions(enable_joint_limit=limited, tolerance=1e-14,
                                                               enable_collision=False))
        robot = scene.add_entity(gs.morphs.URDF(file=path, fixed=fixed))
        scene.build(n_envs=n_envs)
        if limited:
            bound = torch.full(_batch(n_envs, robot.n_dofs), 1.5, dtype=torch.float64)
            robot.set_dofs_force_range(-bound, bound)
            robot.set_dofs_frictionloss(torch.full(_batch(n_envs, robot.n_dofs), 0.05, dtype=torch.float64))
        built = {name: getattr(robot, f"get_{name}")().detach().clone() for name in PARAMETERS}
        force_range = tuple(bound.clone() for bound in robot.get_dofs_force_range())
        _SCENES[key] = (scene, robot, built, force_range, scene.get_gravity().clone())
    scene, robot, built, force_range, gravity = _SCENES[key]
    for name, value in built.items():
        getattr(robot, f"set_{name}")(value)
    robot.set_dofs_force_range(*force_range)
    scene.set_gravity(gravity)
    scene.reset()
    return scene, robot


def _batch(n_envs, *shape):
    return (n_envs, *shape) if n_envs else shape


def _nominal(kind, robot, n_envs, horizon, rng):
    """A nominal value of the input kind (float64 tensor) and a random unit direction."""
    n = robot.n_dofs
    values = {
        "dofs_position": rng.uniform(-0.5, 0.5, _batch(n_envs, n)),
        "dofs_velocity": rng.uniform(-1, 1, _batch(n_envs, n)),
        "force": rng.uniform(-2, 2, (horizon, *_batch(n_envs, n))),
        "position_target": rng.uniform(-0.5, 0.5, (horizon, *_batch(n_envs, n))),
        "velocity_target": rng.uniform(-1, 1, (horizon, *_batch(n_envs, n))),
        "mass": robot.get_links_mass().detach().numpy() * rng.uniform(0.8, 1.2, _batch(n_envs, robot.n_links)),
        "damping": rng.uniform(0.1, 1.0, _batch(n_envs, n)),
        "armature": rng.uniform(0.01, 0.1, _batch(n_envs, n)),
        # a free joint's dofs have no spring
        "stiffness": rng.uniform(0.5, 5.0, _batch(n_envs, n)) * (np.arange(n) >= (6 if robot.is_free else 0)),
        "kp": rng.uniform(5, 15, _batch(n_envs, n)),
        "kv": rng.uniform(0.2, 1, _batch(n_envs, n)),
        "gravity": np.array([0.5, -0.3, -9.81]) + np.zeros(_batch(n_envs, 3)),
        "frictionloss": rng.uniform(0.02, 0.2, _batch(n_envs, n)),
        "force_range": np.stack([rng.uniform(-1.8, -1.2, _batch(n_envs, n)), rng.uniform(1.2, 1.8, _batch(n_envs, n))]),
        "base_pos": rng.uniform(-1, 1, _batch(n_envs, 3)),
        "base_quat": rng.normal(size=_batch(n_envs, 4)),
        # per step and link: a force (N), a torque (N·m) and where the force acts (link frame, m)
        "wrench": rng.uniform(-2, 2, (horizon, *_batch(n_envs, robot.n_links, 9))) * np.repeat([1.0, 0.05], [6, 3]),
    }
    value = torch.tensor(values[kind], dtype=torch.float64)
    direction = torch.tensor(rng.normal(size=value.shape), dtype=torch.float64)
    if kind in ("mass", "stiffness"):  # massless links stay massless (a negative mass is rejected), free dofs
        direction = direction * (value > 0)  # springless
    return value, direction / direction.norm()


def _rollout(scene, robot, kind, value, horizon):
    """Loss of a rollout in which ``kind`` takes ``value``; every other input is fixed."""
    rng = np.random.default_rng(7)
    scene.reset()
    n_envs = scene.n_envs
    q0 = torch.tensor(rng.uniform(-0.3, 0.3, _batch(n_envs, robot.n_dofs)))
    qd0 = torch.tensor(rng.uniform(-0.5, 0.5, _batch(n_envs, robot.n_dofs)))
    if robot.is_free:
        q0[..., :3] = 0.0
    robot.set_dofs_position(value if kind == "dofs_position" else q0)
    robot.set_dofs_velocity(value if kind == "dofs_velocity" else qd0)
    setters = {"mass": robot.set_links_mass, "damping": robot.set_dofs_damping, "armature": robot.set_dofs_armature,
               "stiffness": robot.set_dofs_stiffness, "frictionloss": robot.set_dofs_frictionloss,
               "kp": robot.set_dofs_kp, "kv": robot.set_dofs_kv, "gravity": scene.set_gravity,
               "force_range": lambda v: robot.set_dofs_force_range(v[0], v[1]),
               # the base setters come after the velocities: keep them (set_pos/set_quat zero them by default)
               "base_pos": lambda v: robot.set_pos(v, zero_velocity=False),
               "base_quat": lambda v: robot.set_quat(v, zero_velocity=False)}
    if kind in ("position_target", "velocity_target"):  # moderate gains: explicit PD stays stable
        robot.set_dofs_kp(torch.full(_batch(n_envs, robot.n_dofs), 10.0))
        robot.set_dofs_kv(torch.full(_batch(n_envs, robot.n_dofs), 0.5))
    if kind in setters:
        setters[kind](value)
    if kind in ("kp", "kv"):  # gains act through a position servo
        kind, value = "position_target", torch.full((horizon, *_batch(n_envs, robot.n_dofs)), 0.2)
    if kind == "force_range":  # forces of which a share clips at either bound
        kind, value = "force", torch.tensor(rng.uniform(-2.5, 2.5, (horizon, *_batch(n_envs, robot.n_dofs))))
    controls = {"force": robot.control_dofs_force, "position_target": robot.control_dofs_position,
                "velocity_target": robot.control_dofs_velocity,
                "wrench": lambda v, dofs: robot.apply_links_external_wrench(v[..., :3], v[..., 3:6], pos=v[..., 6:],
                                                                            local=True)}
    dofs = np.arange(6, robot.n_dofs) if robot.is_free and kind == "position_target" else None
    loss = 0.0
    for t in range(horizon):
        if kind in controls:
            controls[kind](value[t] if dofs is None else value[t][..., dofs], dofs)
        scene.step()
        if t == horizon // 2:  # a getter mid-rollout is part of the loss too
            loss = loss + robot.get_links_pos()[..., -1, :].sin().sum()
    loss = loss + (robot.get_dofs_position() ** 2).sum() + robot.get_dofs_velocity().cos().sum()
    return loss + robot.get_links_quat()[..., -1, :].sum() + robot.get_links_vel()[..., -1, :].sum()


def _check(robot_name, kind, horizon, substeps=1, n_envs=0, seed=0, limited=False):
    scene, robot = _scene(robot_name, n_envs, substeps, limited=limited)
    value, direction = _nominal(kind, robot, n_envs, horizon, np.random.default_rng(seed))
    x = value.clone().requires_grad_(True)
    _rollout(scene, robot, kind, x, horizon).backward()
    analytic = float((x.grad * direction).sum())
    numeric = {}
    with torch.no_grad():
        for eps in EPS_SCAN:
            f = {k: float(_rollout(scene, robot, kind, value + k * eps * direction, horizon)) for k in (-2, -1, 1, 2)}
            numeric[eps] = (f[-2] - 8 * f[-1] + 8 * f[1] - f[2]) / (12 * eps)
    errors = {eps: abs(analytic - fd) / max(float(x.grad.norm()), 1e-3) for eps, fd in numeric.items()}
    scan = ", ".join(f"eps {eps:.0e}: FD {numeric[eps]:.10g} (rel {err:.2g})" for eps, err in errors.items())
    assert min(errors.values()) <= 1e-6, f"{robot_name} {kind} T={horizon}: autodiff {analytic:.10g} vs {scan}"
    assert analytic != 0.0, f"{robot_name} {kind}: zero gradient cannot be checked"


@pytest.mark.parametrize("kind", KINDS)
def test_pendulum_every_input(f64, kind):
    _check("pendulum2", kind, horizon=50, substeps=2)


@pytest.mark.parametrize("kind", ["force", "mass", "dofs_velocity", "gravity", "kp"])
def test_pendulum_batched(f64, kind):
    _check("pendulum2", kind, horizon=20, n_envs=4)


@pytest.mark.parametrize("robot_name", ["cartpole", "kuka"])
@pytest.mark.parametrize("kind", ["dofs_position", "force", "mass", "damping", "armature", "stiffness"])
def test_robots(f64, robot_name, kind):
    _check(robot_name, kind, horizon=10)


@pytest.mark.parametrize("kind", ["base_pos", "base_quat", "dofs_velocity", "force", "position_target", "stiffness"])
def test_free_base(f64, kind):
    _check("kuka_free", kind, horizon=10)


@pytest.mark.parametrize("kind", ["base_quat", "dofs_velocity", "force", "mass", "gravity", "wrench"])
def test_branching_tree(f64, kind):
    """Sibling subtrees (the up sweep's chains) and a floating base."""
    _check("quadruped", kind, horizon=10)


@pytest.mark.parametrize("kind", ["dofs_position", "dofs_velocity", "force", "kp", "mass", "armature", "frictionloss",
                                  "force_range"])
def test_limits_and_force_range(f64, kind):
    """Joint limits pushing (the calves start past their upper bound 0), friction loss (sliding
    and stuck dofs) and clipped forces: the constraint solve's implicit gradient."""
    _check("quadruped", kind, horizon=20, limited=True)


@pytest.mark.parametrize("kind", ["dofs_position", "dofs_velocity", "force", "mass", "damping", "armature", "kp",
                                  "gravity"])
def test_joint_equalities(f64, kind):
    """Through the joint equality rows of two mimic joints (one prismatic finger mirroring
    another, a thumb following the wrist): their distances, velocities and diagA."""
    _check("gripper", kind, horizon=20)


def test_joint_equalities_repeat_bit_for_bit(f64):
    """Two rollouts through the equality rows, batched, give the same gradient bits."""
    scene, robot = _scene("gripper", 2, 2)
    value, _ = _nominal("mass", robot, 2, 20, np.random.default_rng(3))
    grads = []
    for _ in range(2):
        x = value.clone().requires_grad_(True)
        _rollout(scene, robot, "mass", x, 20).backward()
        grads.append(x.grad)
    assert torch.equal(*grads) and grads[0].abs().sum() > 0


def test_limits_and_force_range_are_at_work(f64):
    """The rollouts of test_limits_and_force_range differ from unlimited ones."""
    forces, _ = _nominal("force", _scene("quadruped", 0, 1)[1], 0, 20, np.random.default_rng(0))
    with torch.no_grad():
        losses = [float(_rollout(*_scene("quadruped", 0, 1, limited=limited), "force", forces, 20))
                  for limited in (False, True)]
    assert abs(losses[0] - losses[1]) > 1e-3 * abs(losses[0]), losses


@pytest.mark.slow
@pytest.mark.parametrize("robot_name", ["pendulum2", "cartpole", "kuka"])
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("horizon", [10, 50, 100, 200])
@pytest.mark.parametrize("substeps,n_envs", [(1, 0), (3, 0), (1, 4)])
def test_full_matrix(f64, robot_name, kind, horizon, substeps, n_envs):
    _check(robot_name, kind, horizon, substeps, n_envs)


def test_damping_gradient_at_zero_with_rows(f64):
    """All damping 0 with constraint rows at work: the step integrates the solve's own acceleration
    (MuJoCo's rule), yet any damping > 0 takes the damped path, so the gradient at 0 is that
    path's one-sided derivative: against second-order one-sided differences along a positive
    direction."""
    scene, robot = _scene("quadruped", 0, 1, limited=True)
    horizon = 20
    direction = torch.tensor(np.random.default_rng(3).uniform(0.1, 1.0, robot.n_dofs), dtype=torch.float64)
    direction = direction / direction.norm()
    x = torch.zeros(robot.n_dofs, dtype=torch.float64, requires_grad=True)
    damping = robot.get_dofs_damping().clone()  # a parameter: it outlives resets, restore it after
    try:
        _rollout(scene, robot, "damping", x, horizon).backward()
        with torch.no_grad():
            f = [float(_rollout(scene, robot, "damping", k * EPS * direction, horizon)) for k in (0, 1, 2)]
    finally:
        robot.set_dofs_damping(damping)
    analytic = float((x.grad * direction).sum())
    numeric = (-3 * f[0] + 4 * f[1] - f[2]) / (2 * EPS)
    err = abs(analytic - numeric) / max(float(x.grad.norm()), 1e-3)
    assert err <= 1e-5 and analytic != 0.0, f"damping at 0: autodiff {analytic:.10g} vs one-sided FD {numeric:.10g}"
