"""RigidEntity.get_links_COM / set_links_COM (Genesis's): each link's centre of mass in its frame, a
per-env input the step differentiates. The reference is MuJoCo 4 with the same bodies' body_ipos
moved (its compiled constraint scale kept, as ours is)."""
import mujoco
import numpy as np
import pytest
import torch

import genesis_lite as gs
from tests.fd_scan import checked_gradient
from tests.test_mjcf import _lockstep, _pair, _write

BODIES = ('<geom type="plane" size="5 5 0.1"/>'
          '<body name="arm" pos="0 0 1"><joint name="hinge" axis="0 1 0" damping="0.05"/>'
          '<geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"/>'
          '<body name="slider" pos="0.3 0 0"><joint name="slide" type="slide" axis="1 0 1"/>'
          '<geom type="box" size="0.04 0.03 0.02" pos="0.05 0 0.01"/>'
          '<body name="bob" pos="0.1 0 0"><joint name="ball" type="ball"/>'
          '<geom type="capsule" fromto="0 0 0 0 0.1 -0.2" size="0.02"/></body></body></body>'
          '<body name="box" pos="1 0 0.05"><freejoint/><geom type="box" size="0.1 0.05 0.05" pos="0.02 0 0"/></body>')
SHIFT = {"arm": (0.05, 0.01, -0.02), "bob": (0.02, -0.03, 0.01), "box": (0.04, 0.02, -0.01)}


def _moved(path, m0, robot):
    """(MuJoCo model and data of the file with SHIFT's bodies' centres of mass moved, compiled again —
    patching body_ipos leaves MuJoCo's compiled collision bounds and same-frame flags behind — its
    constraint scale (body_invweight0, dof_invweight0) kept from the original ``m0``, as ours keeps
    the build's), and ours moved alike (set_links_COM)."""
    spec = mujoco.MjSpec.from_file(path)
    com = robot.get_links_COM().clone()
    for name, shift in SHIFT.items():
        body, k = spec.body(name), m0.body(name).id
        np.testing.assert_allclose(com[robot.get_link(name).idx_local].numpy(), m0.body_ipos[k], atol=1e-15)
        body.explicitinertial = True
        body.mass, body.inertia, body.iquat, body.ipos = (m0.body_mass[k], m0.body_inertia[k], m0.body_iquat[k],
                                                          m0.body_ipos[k] + shift)
        com[robot.get_link(name).idx_local] += torch.tensor(shift, dtype=torch.float64)
    m = spec.compile()
    m.opt.integrator, m.opt.cone = m0.opt.integrator, m0.opt.cone
    m.body_invweight0[:], m.dof_invweight0[:] = m0.body_invweight0, m0.dof_invweight0
    robot.set_links_COM(com)
    assert torch.equal(robot.get_links_COM(), com)
    return m, mujoco.MjData(m)


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_moved_centres_of_mass_move_as_mujocos(f64, tmp_path, cone):
    """Three bodies' centres of mass moved (a hinge's, a ball joint's and a free box's sliding on the
    floor, the chain's end hitting it at step ~194): 250 steps as MuJoCo 4 with the same centres
    (measured 1e-13 until that contact, 3e-12 after it; the rocking box then doubles a difference
    every ~30 steps, in both engines alike)."""
    path = _write(tmp_path, BODIES)
    m0, _, scene, robot = _pair(path, cone=cone, integrator="euler")
    m, d = _moved(path, m0, robot)
    d.qvel[:] = np.random.default_rng(1).normal(size=m.nv) * 0.5
    robot.set_dofs_velocity(torch.tensor(d.qvel))
    contacts = []
    assert _lockstep(m, d, scene, robot, 250, after_step=lambda: contacts.append(d.ncon)) < 1e-10
    assert min(contacts[50:]) >= 4 and max(contacts) >= 5


@pytest.mark.parametrize("n_envs", [0, 2])
def test_gradients_through_centres_of_mass_match_finite_differences(f64, tmp_path, n_envs):
    """The gradient of the bodies' final poses after 120 steps (the box on the floor, sliding) w.r.t.
    every link's centre of mass against central differences, per env when batched; a repeated
    rollout keeps its bits."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.004, requires_grad=True))
    robot = scene.add_entity(gs.morphs.MJCF(file=_write(tmp_path, BODIES)))
    scene.build(n_envs=n_envs)
    start = robot.get_links_COM().detach().clone()
    velocity = torch.tensor(np.random.default_rng(4).normal(size=(max(n_envs, 1), robot.n_dofs)) * 0.4)
    weights = torch.tensor(np.random.default_rng(5).normal(size=(max(n_envs, 1), robot.n_links, 7)))

    def loss(com):
        scene.reset()
        robot.set_links_COM(com)
        robot.set_dofs_velocity(velocity if n_envs else velocity[0])
        for _ in range(120):
            scene.step()
        pose = torch.cat([robot.get_links_pos(), robot.get_links_quat()], -1)
        return (pose * (weights if n_envs else weights[0])).sum()

    assert checked_gradient(loss, start, "centres of mass").abs().max() > 0


def test_energy_and_a_wrench_at_the_com_take_the_moved_centre(f64, tmp_path):
    """The potential energy (MuJoCo's mj_energyPos with body_ipos moved) and apply_links_external_wrench
    with ref="link_com" (MuJoCo's xfrc_applied, which acts at the centre of mass) follow set_links_COM."""
    path = _write(tmp_path, BODIES)
    m0, _, scene, robot = _pair(path, integrator="euler")
    m, d = _moved(path, m0, robot)
    mujoco.mj_forward(m, d)
    moving = [m.body(name).id for name in ("arm", "slider", "bob", "box")]
    expected = -sum(m.body_mass[b] * (m.opt.gravity @ d.xipos[b]) for b in moving)
    assert float(robot.get_potential_energy()) == pytest.approx(expected, rel=1e-13)
    force = np.array([1.0, -2.0, 3.0])
    robot.apply_links_external_wrench(torch.tensor(force[None]), links_idx_local=[robot.get_link("box").idx_local],
                                      ref="link_com")
    d.xfrc_applied[m.body("box").id, :3] = force
    mujoco.mj_step(m, d)
    scene.step()
    np.testing.assert_allclose(robot.get_dofs_velocity().numpy(), d.qvel, atol=1e-12)


def test_set_links_com_checks_its_arguments(f64, tmp_path):
    scene = gs.Scene()
    robot = scene.add_entity(gs.morphs.MJCF(file=_write(tmp_path, BODIES)))
    scene.build(n_envs=2)
    with pytest.raises(gs.InvalidInputError, match=r"set_links_COM argument 'com' must have shape \(2, 1, 3\)"):
        robot.set_links_COM(torch.zeros(2, 2, 3), links_idx_local=[1])
    with pytest.raises(gs.InvalidInputError, match="finite"):
        robot.set_links_COM(torch.full((3,), float("nan")), links_idx_local=[1])
    robot.set_links_COM([0.0, 0.1, 0.0], links_idx_local=[1], envs_idx=[1])  # (a (3,) vector broadcasts)
    com = robot.get_links_COM(links_idx_local=[1])
    assert com.shape == (2, 1, 3) and com[1, 0].tolist() == [0.0, 0.1, 0.0] and com[0, 0].tolist() != [0.0, 0.1, 0.0]


def test_mass_and_com_shifts_move_from_the_builds_values_as_genesis(f64, tmp_path):
    """Genesis's domain randomisation (examples/rigid/domain_randomization.py): set_mass_shift and
    set_COM_shift set the build's values plus the shift (not cumulative), per env, and differentiate
    as set_links_mass and set_links_COM do (the gradient of a rollout w.r.t. the shift is theirs)."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.004, requires_grad=True))
    robot = scene.add_entity(gs.morphs.MJCF(file=_write(tmp_path, BODIES)))
    scene.build(n_envs=2)
    mass0, com0 = robot.get_links_mass().detach().clone(), robot.get_links_COM().detach().clone()
    heavy = [robot.get_link(name).idx_local for name in ("arm", "bob", "box")]
    mass_shift, com_shift = torch.tensor([[0.1, -0.05, 0.2]] * 2), torch.tensor([[[0.01, 0.0, -0.02]] * 3] * 2)
    for _ in range(2):  # (twice: not cumulative)
        robot.set_mass_shift(mass_shift, links_idx_local=heavy)
        robot.set_COM_shift(com_shift, links_idx_local=heavy)
    assert torch.allclose(robot.get_links_mass()[:, heavy], mass0[:, heavy] + mass_shift, rtol=0, atol=1e-15)
    assert torch.allclose(robot.get_links_COM()[:, heavy], com0[:, heavy] + com_shift, rtol=0, atol=1e-15)

    def final_height(setter, value):
        scene.reset()
        setter(value)
        for _ in range(40):
            scene.step()
        return robot.get_links_pos()[..., 2].sum()

    for shift_setter, setter, base in (
            (lambda x: robot.set_mass_shift(x, links_idx_local=heavy),
             lambda x: robot.set_links_mass(x, links_idx_local=heavy), mass0[:, heavy]),
            (lambda x: robot.set_COM_shift(x, links_idx_local=heavy),
             lambda x: robot.set_links_COM(x, links_idx_local=heavy), com0[:, heavy])):
        shift = torch.zeros_like(base, requires_grad=True)
        final_height(shift_setter, shift).backward()
        value = base.clone().requires_grad_(True)
        final_height(setter, value).backward()
        assert shift.grad.abs().max() > 0 and torch.equal(shift.grad, value.grad)
    with pytest.raises(gs.InvalidInputError, match="'mass_shift' must leave every mass ≥ 0 kg"):
        robot.set_mass_shift([-100.0, 0.0, 0.0], links_idx_local=heavy)
    with pytest.raises(gs.InvalidInputError, match=r"set_COM_shift argument 'com_shift' must have shape"):
        robot.set_COM_shift(torch.zeros(2, 2, 3), links_idx_local=heavy)
