"""RigidEntity.set_dofs_limit (Genesis's): each scalar dof's position limits, a per-env input the
step differentiates, set on a dof limited at build or not. The reference is MuJoCo 4 with the same
joints' jnt_range (and jnt_limited) changed at run time."""
import mujoco
import numpy as np
import pytest
import torch

import genesis_lite as gs
from tests.fd_scan import checked_gradient, pose_loss
from tests.test_mjcf import _write

# a hinge limited in the file (HINGE_RANGE), a slide that is not, a hinge under it, a ball (no
# scalar limit)
HINGE_RANGE = 'range="-1 1"'
CHAIN = ('<body name="arm" pos="0 0 1"><joint name="hinge" axis="0 1 0" ' + HINGE_RANGE + ' damping="0.05"/>'
         '<geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"/>'
         '<body name="slider" pos="0.3 0 0"><joint name="slide" type="slide" axis="1 0 1"/>'
         '<geom type="box" size="0.04 0.03 0.02" pos="0.05 0 0.01"/>'
         '<body name="tip" pos="0.1 0 0"><joint name="wrist" axis="0 0 1"/>'
         '<geom type="capsule" fromto="0 0 0 0 0.1 -0.2" size="0.02"/>'
         '<body name="bob" pos="0 0.1 -0.2"><joint name="ball" type="ball"/>'
         '<geom type="sphere" size="0.03" pos="0.05 0 0"/></body></body></body></body>')
EXTRA = '<compiler angle="radian" autolimits="true"/><option integrator="Euler"/>'
# per env: (lower, upper) of hinge, slide, wrist (rad, m, rad); env 1 keeps the file's (the slide
# and the wrist unlimited)
LIMITS = ([-0.3, -0.05, -0.4], [0.2, 0.02, 0.5])


def _scene(path, n_envs, requires_grad=False):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002, requires_grad=requires_grad),
                     rigid_options=gs.options.RigidOptions(enable_mujoco_compatibility=True))
    robot = scene.add_entity(gs.morphs.MJCF(file=path))
    scene.build(n_envs=n_envs)
    return scene, robot


@pytest.mark.parametrize("hinge_range", [HINGE_RANGE, ""])
def test_limits_set_at_run_time_hold_as_mujocos(f64, tmp_path, hinge_range):
    """Env 0's hinge, slide and wrist given limits (the slide's and the wrist's where the file has
    none), env 1 left as built: 300 steps from a fast start (the hinge held at its upper bound, the
    slide at its lower, the wrist meeting both) as MuJoCo 4's with the same ranges set at run time
    (measured 4e-12, and 1.4e-10 with the file's hinge range once its capsules' fromto frames took
    MuJoCo's rounding: a fast chain meeting its bounds amplifies round-off; env 1, a free swinging
    chain, as the file's: 2e-11; asserted below 5e-10); get_dofs_limit reads
    them back, a reset keeps them. Also where the file limits no joint (no limit row until set)."""
    path = _write(tmp_path, CHAIN.replace(HINGE_RANGE, hinge_range), EXTRA)
    scene, robot = _scene(path, 2)
    scalar = [robot.get_joint(name).dofs_idx_local[0] for name in ("hinge", "slide", "wrist")]
    robot.set_dofs_limit(*LIMITS, dofs_idx_local=scalar, envs_idx=[0])
    scene.reset()
    lower, upper = robot.get_dofs_limit(scalar)
    assert lower[0].tolist() == LIMITS[0] and upper[0].tolist() == LIMITS[1]
    hinge_bound = 1.0 if hinge_range else np.inf
    assert lower[1].tolist() == [-hinge_bound, -np.inf, -np.inf] and upper[1].tolist() == [hinge_bound, np.inf, np.inf]
    models = [mujoco.MjModel.from_xml_path(path) for _ in range(2)]
    for k, name in enumerate(("hinge", "slide", "wrist")):
        joint = models[0].joint(name).id
        models[0].jnt_limited[joint] = 1
        models[0].jnt_range[joint] = LIMITS[0][k], LIMITS[1][k]
    datas = [mujoco.MjData(m) for m in models]
    velocity = np.array([3.0, 1.0, -4.0, 2.0, -1.0, 3.0])
    for d in datas:
        d.qvel[:] = velocity
    robot.set_dofs_velocity(torch.tensor(np.tile(velocity, (2, 1))))
    worst, limit_rows = 0.0, 0
    for _ in range(300):
        scene.step()
        for e, (m, d) in enumerate(zip(models, datas)):
            mujoco.mj_step(m, d)
            worst = max(worst, np.abs(robot.get_qpos()[e].numpy() - d.qpos).max(),
                        np.abs(robot.get_dofs_velocity()[e].numpy() - d.qvel).max())
        limit_rows = max(limit_rows, int((datas[0].efc_type == mujoco.mjtConstraint.mjCNSTR_LIMIT_JOINT).sum()))
    assert worst < 5e-10 and limit_rows >= 2
    q = robot.get_qpos()[0, [robot.get_joint(name).qs_idx_local[0] for name in ("hinge", "slide", "wrist")]]
    assert (q > torch.tensor(LIMITS[0]) - 0.05).all() and (q < torch.tensor(LIMITS[1]) + 0.05).all()


def test_a_limit_set_on_a_scene_without_rows_holds_as_mujocos(f64, tmp_path):
    """A pendulum without limits or contact pairs (its steps take the one-launch path, which leaves
    rows to the constraint stage only where limits exist) given a limit at run time: it stops there
    as MuJoCo's with that range (200 steps)."""
    path = _write(tmp_path, '<body name="arm" pos="0 0 1"><joint name="hinge" axis="0 1 0"/>'
                            '<geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"/></body>', EXTRA)
    scene, robot = _scene(path, 0)
    robot.set_dofs_limit([-0.2], [0.3])
    m = mujoco.MjModel.from_xml_path(path)
    m.jnt_limited[0], m.jnt_range[0] = 1, (-0.2, 0.3)
    d = mujoco.MjData(m)
    d.qvel[0] = 2.0
    robot.set_dofs_velocity([2.0])
    worst = 0.0
    for _ in range(200):
        scene.step()
        mujoco.mj_step(m, d)
        worst = max(worst, abs(float(robot.get_qpos()[0]) - d.qpos[0]), abs(float(robot.get_dofs_velocity()[0]) - d.qvel[0]))
    assert worst < 1e-12 and d.efc_type.size == 1 and float(robot.get_qpos()[0]) > 0.25


@pytest.mark.parametrize("n_envs", [0, 2])
def test_gradients_through_limits_match_finite_differences(f64, tmp_path, n_envs):
    """The gradient of the links' final poses after 150 steps w.r.t. the limits (lower and upper)
    against central differences, per env when batched (five of the six bounds met, the hinge's lower
    not); a repeated rollout keeps its bits."""
    scene, robot = _scene(_write(tmp_path, CHAIN, EXTRA), n_envs, requires_grad=True)
    scalar = [robot.get_joint(name).dofs_idx_local[0] for name in ("hinge", "slide", "wrist")]
    start = torch.tensor(LIMITS, dtype=torch.float64)
    if n_envs:
        start = torch.stack([start, start * 0.8])
    velocity = torch.tensor([3.0, 1.0, -4.0, 2.0, -1.0, 3.0], dtype=torch.float64)
    weights = torch.tensor(np.random.default_rng(5).normal(size=(robot.n_links, 7)))

    def start_from(x):
        robot.set_dofs_limit(x[..., 0, :], x[..., 1, :], dofs_idx_local=scalar)
        robot.set_dofs_velocity(velocity if not n_envs else velocity.expand(n_envs, -1))

    loss = pose_loss(scene, robot, weights, 150, start_from)
    gradient = checked_gradient(loss, start, "limits")
    assert int((gradient != 0).sum()) == 5 * max(n_envs, 1)


def test_set_dofs_limit_checks_its_arguments(f64, tmp_path):
    """lower > upper, a ball or free joint's dofs (no scalar position to bound), NaN and wrong shapes
    raise named errors, leaving the limits as they were; ±inf frees a dof."""
    scene, robot = _scene(_write(tmp_path, CHAIN + '<body name="box" pos="1 0 1"><freejoint/>'
                                 '<geom type="box" size="0.1 0.1 0.1"/></body>', EXTRA), 2)
    before = robot.get_dofs_limit()
    hinge = robot.get_joint("hinge").dofs_idx_local[0]
    with pytest.raises(gs.InvalidInputError, match="set_dofs_limit argument 'lower' must be ≤ 'upper'"):
        robot.set_dofs_limit([0.5], [0.1], dofs_idx_local=[hinge])
    for joint in ("ball", "box"):
        with pytest.raises(gs.InvalidInputError, match="set_dofs_limit .* of a ball or free joint"):
            robot.set_dofs_limit([-0.1], [0.1], dofs_idx_local=[robot.get_joint(joint).dofs_idx_local[1]])
    with pytest.raises(gs.InvalidInputError, match="lower < \\+inf and upper > −inf"):
        robot.set_dofs_limit([np.inf], [np.inf], dofs_idx_local=[hinge])
    with pytest.raises(gs.InvalidInputError, match="NaN"):
        robot.set_dofs_limit([float("nan")], [0.1], dofs_idx_local=[hinge])
    with pytest.raises(gs.InvalidInputError, match=r"argument 'upper' must have shape \(2, 1\)"):
        robot.set_dofs_limit([0.0], torch.zeros(3, 1), dofs_idx_local=[hinge])
    assert all(torch.equal(a, b) for a, b in zip(robot.get_dofs_limit(), before))
    robot.set_dofs_limit([-np.inf], [np.inf], dofs_idx_local=[hinge], envs_idx=[1])
    assert robot.get_dofs_limit([hinge])[1][:, 0].tolist() == [1.0, np.inf]


def test_inverse_kinematics_keeps_within_limits_set_at_run_time(f64, tmp_path):
    """inverse_kinematics(respect_joint_limit=True) clips to each env's current limits."""
    scene, robot = _scene(_write(tmp_path, CHAIN, EXTRA), 2)
    hinge = robot.get_joint("hinge").dofs_idx_local[0]
    robot.set_dofs_limit([-0.1], [0.1], dofs_idx_local=[hinge], envs_idx=[0])
    goal = torch.tensor([[0.2, 0.0, 1.2]] * 2, dtype=torch.float64)  # (reached at hinge ≈ −0.6)
    qpos = robot.inverse_kinematics(robot.get_link("tip"), pos=goal, dofs_idx_local=[hinge], max_samples=2)
    q = qpos[:, robot.get_joint("hinge").qs_idx_local[0]]
    assert -0.1 <= float(q[0]) <= 0.1 and float(q[1]) < -0.2
