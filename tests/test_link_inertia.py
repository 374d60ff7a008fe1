"""RigidEntity.get_links_inertia / set_links_inertia (Genesis's): each link's rotational inertia about
its centre of mass, in its frame, a per-env input the step differentiates; and Genesis's rule that
a link's mass setters leave its inertia (set_links_mass, RigidLink.set_mass, set_mass_shift) while
the entity's set_mass scales it. The reference is MuJoCo 4 compiled with the same masses and
inertias (its body_inertia and body_iquat: our link-frame matrix's eigen-decomposition)."""
import mujoco
import numpy as np
import pytest
import torch

import genesis_lite as gs
from tests.fd_scan import checked_gradient, pose_loss
from tests.test_link_com import BODIES
from tests.test_mjcf import _lockstep, _pair, _write

# new inertias (kg·m², in the link's frame; full matrices: the principal axes turned off the link's)
INERTIA = {"bob": [[3e-4, 4e-5, -2e-5], [4e-5, 2e-4, 3e-5], [-2e-5, 3e-5, 2.5e-4]],
           "box": [[1.4e-3, -2e-4, 1e-4], [-2e-4, 2.2e-3, 0.0], [1e-4, 0.0, 2.9e-3]]}
MASS = {"arm": 0.9, "box": 7.0}  # kg (the arm keeps its inertia: Genesis's set_links_mass)


def _principal(inertia):
    """MuJoCo's body_inertia (principal moments) and body_iquat (w, x, y, z) of a link-frame matrix."""
    moments, axes = np.linalg.eigh(np.asarray(inertia))
    if np.linalg.det(axes) < 0:
        axes[:, 0] = -axes[:, 0]
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, axes.reshape(-1))
    return moments, quat


def _changed(path, m0, robot):
    """MuJoCo's model of the file compiled with MASS's masses and INERTIA's inertias (its constraint
    scale recomputed by its compiler, as Genesis and ours recompute it), and ours changed alike."""
    spec = mujoco.MjSpec.from_file(path)
    inertia = robot.get_links_inertia().clone()
    for name in sorted(set(MASS) | set(INERTIA)):
        body, k = spec.body(name), m0.body(name).id
        body.explicitinertial = True
        body.mass, body.inertia, body.iquat, body.ipos = m0.body_mass[k], m0.body_inertia[k], m0.body_iquat[k], m0.body_ipos[k]
        if name in MASS:
            body.mass = MASS[name]
        if name in INERTIA:
            body.inertia, body.iquat = _principal(INERTIA[name])
            inertia[robot.get_link(name).idx_local] = torch.tensor(INERTIA[name], dtype=torch.float64)
    m = spec.compile()
    m.opt.integrator, m.opt.cone = m0.opt.integrator, m0.opt.cone
    links = [robot.get_link(name).idx_local for name in MASS]
    robot.set_links_mass(torch.tensor(list(MASS.values()), dtype=torch.float64), links_idx_local=links)
    robot.set_links_inertia(inertia)
    assert torch.equal(robot.get_links_inertia(), inertia)
    return m, mujoco.MjData(m)


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_set_inertias_and_masses_move_as_mujocos(f64, tmp_path, cone):
    """A ball joint's and a free box's inertias set (full matrices), the arm's and the box's masses
    set (the arm keeping its inertia): the constraint scale as MuJoCo's compiler makes it, and 250
    steps (the box sliding on the floor, the chain's end landing on it) as MuJoCo 4's with the
    same bodies, kinetic energy included."""
    path = _write(tmp_path, BODIES)
    m0, _, scene, robot = _pair(path, cone=cone, integrator="euler")
    m, d = _changed(path, m0, robot)
    moving = [robot.get_link(m.body(b).name).idx_local for b in range(1, m.nbody)]
    np.testing.assert_allclose(robot.get_links_invweight()[moving].numpy(),
                               np.stack([m.body_invweight0[1:, 0], m.body_invweight0[1:, 1]], -1), rtol=1e-12)
    np.testing.assert_allclose(robot.get_dofs_invweight().numpy(), m.dof_invweight0, rtol=1e-12)
    d.qvel[:] = np.random.default_rng(1).normal(size=m.nv) * 0.5
    robot.set_dofs_velocity(torch.tensor(d.qvel))
    contacts = []
    assert _lockstep(m, d, scene, robot, 250, after_step=lambda: contacts.append(d.ncon)) < 1e-10
    assert min(contacts[50:]) >= 4 and max(contacts) >= 5
    m.opt.enableflags |= mujoco.mjtEnableBit.mjENBL_ENERGY
    mujoco.mj_forward(m, d)
    assert float(robot.get_kinetic_energy()) == pytest.approx(d.energy[1], rel=1e-12)


@pytest.mark.parametrize("n_envs", [0, 2])
def test_gradients_through_inertias_match_finite_differences(f64, tmp_path, n_envs):
    """The gradient of the bodies' final poses after 120 steps (the box sliding on the floor) w.r.t.
    every moving link's inertia (a symmetric perturbation) against central differences, per env
    when batched; a repeated rollout keeps its bits."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.004, requires_grad=True))
    robot = scene.add_entity(gs.morphs.MJCF(file=_write(tmp_path, BODIES)))
    scene.build(n_envs=n_envs)
    heavy = [k for k, link in enumerate(robot.links) if float(link.get_mass().flatten()[0]) > 0]
    start = robot.get_links_inertia(links_idx_local=heavy).detach().clone()
    velocity = torch.tensor(np.random.default_rng(4).normal(size=(max(n_envs, 1), robot.n_dofs)) * 0.4)
    weights = torch.tensor(np.random.default_rng(5).normal(size=(max(n_envs, 1), robot.n_links, 7)))

    def start_from(x):
        robot.set_links_inertia(0.5 * (x + x.transpose(-1, -2)), links_idx_local=heavy)
        robot.set_dofs_velocity(velocity if n_envs else velocity[0])

    loss = pose_loss(scene, robot, weights if n_envs else weights[0], 120, start_from)
    assert checked_gradient(loss, start, "inertias").abs().max() > 0


def test_mass_setters_leave_the_inertia_and_set_mass_scales_it_as_genesis(f64, tmp_path):
    """Genesis's rule: set_links_mass, RigidLink.set_mass and set_mass_shift change a link's mass
    alone; the entity's set_mass scales every moving link's inertia with its mass; the link setters
    (set_inertia, set_COM, get_invweight) are the entity's for one link, per env when batched."""
    scene = gs.Scene()
    robot = scene.add_entity(gs.morphs.MJCF(file=_write(tmp_path, BODIES)))
    scene.build(n_envs=2)
    inertia0 = robot.get_links_inertia().clone()
    box, bob = robot.get_link("box"), robot.get_link("bob")
    robot.set_links_mass([3.0], links_idx_local=[box.idx_local])
    bob.set_mass(0.5)
    robot.set_mass_shift([0.1], links_idx_local=[robot.get_link("arm").idx_local])
    assert torch.equal(robot.get_links_inertia(), inertia0)
    mass = robot.get_links_mass().clone()
    robot.set_mass(2.0 * robot.get_mass()[0], envs_idx=[0])
    np.testing.assert_allclose(robot.get_links_mass()[0].numpy(), 2.0 * mass[0].numpy(), rtol=1e-15)
    np.testing.assert_allclose(robot.get_links_inertia()[0].numpy(), 2.0 * inertia0[0].numpy(), rtol=1e-15)
    assert torch.equal(robot.get_links_inertia()[1], inertia0[1])
    turned = torch.tensor(INERTIA["box"], dtype=torch.float64)
    box.set_inertia(torch.stack([turned, 2.0 * turned]))
    assert torch.equal(robot.get_links_inertia()[:, box.idx_local], torch.stack([turned, 2.0 * turned]))
    box.set_COM([0.01, 0.0, 0.0])
    assert robot.get_links_COM()[:, box.idx_local].tolist() == [[0.01, 0.0, 0.0]] * 2
    assert torch.equal(box.get_invweight(), robot.get_links_invweight()[:, box.idx_local])
    assert box.get_invweight()[0, 1] > box.get_invweight()[1, 1] > 0  # (the lighter turn moves more)


@pytest.mark.parametrize("inertia, said", [
    ([[1.0, 0.2, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], "symmetric"),
    (np.diag([1.0, 1.0, -0.1]), r"moments \[-0.1"),
    (np.diag([0.1, 0.1, 0.3]), "A \\+ B ≥ C"),
])
def test_set_links_inertia_refuses_what_no_rigid_body_has(f64, tmp_path, inertia, said):
    scene = gs.Scene()
    robot = scene.add_entity(gs.morphs.MJCF(file=_write(tmp_path, BODIES)))
    scene.build()
    before = robot.get_links_inertia().clone()
    with pytest.raises(gs.InvalidInputError, match=f"set_links_inertia argument 'inertia' of link 'box' .*{said}"):
        robot.set_links_inertia([inertia], links_idx_local=[robot.get_link("box").idx_local])
    assert torch.equal(robot.get_links_inertia(), before)


def test_an_inertia_leaving_a_free_body_unturnable_is_refused(f64, tmp_path):
    """A free box given a principal moment of 0 about a turned axis (no pivot of M is exactly zero:
    M⁻¹'s entries were 1e18, the state NaN at the fourth step; in float32 the rotational invweight
    came out negative) raises the named error of a singular mass matrix, the inertia unchanged."""
    scene = gs.Scene()
    robot = scene.add_entity(gs.morphs.MJCF(file=_write(tmp_path, BODIES)))
    scene.build()
    before = robot.get_links_inertia().clone()
    turn = np.linalg.qr(np.random.default_rng(0).normal(size=(3, 3)))[0]
    flat = turn @ np.diag([0.0, 1e-3, 1e-3]) @ turn.T
    with pytest.raises(gs.InvalidInputError, match="link 'box' .* expected a positive definite mass matrix"):
        robot.set_links_inertia(flat, links_idx_local=[robot.get_link("box").idx_local])
    assert torch.equal(robot.get_links_inertia(), before)


def test_set_links_inertia_checks_its_shapes(f64, tmp_path):
    scene = gs.Scene()
    robot = scene.add_entity(gs.morphs.MJCF(file=_write(tmp_path, BODIES)))
    scene.build(n_envs=2)
    with pytest.raises(gs.InvalidInputError, match=r"set_links_inertia argument 'inertia' must have shape \(2, 1, 3, 3\)"):
        robot.set_links_inertia(torch.zeros(2, 2, 3, 3), links_idx_local=[1])
    with pytest.raises(gs.InvalidInputError, match="finite"):
        robot.set_links_inertia(torch.full((3, 3), float("nan")), links_idx_local=[1])
    with pytest.raises(gs.InvalidInputError, match="set_inertia argument 'inertia' takes one value"):
        scene0 = gs.Scene()
        single = scene0.add_entity(gs.morphs.MJCF(file=_write(tmp_path, BODIES)))
        scene0.build()
        single.get_link("box").set_inertia(np.stack([np.eye(3)] * 2))
    robot.set_links_inertia(np.eye(3) * 0.01, links_idx_local=[1], envs_idx=[1])  # (a (3, 3) broadcasts)
    inertia = robot.get_links_inertia(links_idx_local=[1])
    assert inertia.shape == (2, 1, 3, 3) and torch.equal(inertia[1, 0], torch.eye(3, dtype=torch.float64) * 0.01)
    assert not torch.equal(inertia[0, 0], inertia[1, 0])
