"""Kernels are compiled once per process and precision, not per scene: a scene's data are the
kernels' array arguments (solvers/rigid/data.py). Other robots, batch sizes, substep counts and
time steps, and a second live scene of the same robot, reuse every compiled kernel; a contact
scene compiles the collider of each pair kind it has once, for every later scene."""
import pytest
import torch
import trimesh
from taichi.lang import impl

import genesis_lite as gs
from genesis_lite.solvers import coupler, launch
from genesis_lite.solvers.mpm import kernels as mpm_kernels
from genesis_lite.solvers.launch import _COMPILED, BoundKernel
from genesis_lite.solvers.rigid import ik, step
from genesis_lite.solvers.rigid.data import SERIAL_SOLVE_WORK
from tests.conftest import asset, pybullet
from tests import test_contact_gradients


def _n_compiled():
    """Compiled kernel instances Taichi holds, over every kernel of the rigid step."""
    return sum(len(kernel._primal.compiled_kernels) for kernel in _COMPILED)


def _rollout_with_backward(path, fixed, n_envs, substeps, dt):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=dt, substeps=substeps, requires_grad=True),
                     rigid_options=gs.options.RigidOptions(enable_collision=False))
    robot = scene.add_entity(gs.morphs.URDF(file=path, fixed=fixed))
    scene.build(n_envs=n_envs)
    force = torch.full((n_envs, robot.n_dofs) if n_envs else (robot.n_dofs,), 0.1, dtype=torch.float64,
                       requires_grad=True)
    robot.control_dofs_force(force)
    for _ in range(3):
        scene.step()
    read = robot.get_mass_mat().sum().detach() + robot.get_dofs_force().sum().detach()
    (robot.get_links_pos().sum() + robot.get_dofs_velocity().sum() + read).backward()
    assert torch.isfinite(force.grad).all() and force.grad.abs().sum() > 0
    return scene


def test_scenes_share_compiled_kernels(f64):
    """The pendulum stays within its joint limits (one launch a step); the quadruped's calves
    start past theirs (the constraint stage's kernels and its reverse)."""
    first = _rollout_with_backward(asset("pendulum2.urdf"), True, 0, 1, 0.01)
    _rollout_with_backward(asset("quadruped.urdf"), False, 0, 1, 0.01)
    compiled = _n_compiled()
    assert compiled > 0
    # the same robot again while the first scene lives, then other robots, sizes and steps
    second = _rollout_with_backward(asset("pendulum2.urdf"), True, 0, 1, 0.01)
    _rollout_with_backward(pybullet("kuka_iiwa", "model.urdf"), True, 3, 2, 0.005)
    _rollout_with_backward(asset("quadruped.urdf"), False, 2, 3, 0.002)
    assert _n_compiled() == compiled, "a new scene compiled kernels again"
    first.step()
    second.step()


def test_large_batches_share_compiled_kernels(f64):
    """Batches past data.SERIAL_LINK_ENVS run their env loop on the thread pool: one more compiled
    variant, shared in turn by every such scene."""
    _rollout_with_backward(pybullet("kuka_iiwa", "model.urdf"), True, 300, 1, 0.01)
    _rollout_with_backward(asset("quadruped.urdf"), False, 300, 1, 0.01)
    compiled = _n_compiled()
    _rollout_with_backward(pybullet("kuka_iiwa", "model.urdf"), True, 250, 2, 0.005)
    _rollout_with_backward(asset("quadruped.urdf"), False, 200, 2, 0.005)
    assert _n_compiled() == compiled, "a new scene compiled kernels again"


def test_contact_batch_on_the_pool_equals_single_envs(f64):
    """Past data.SERIAL_SOLVE_WORK (env, dof) pairs the constraint solve and its reverse run on the
    thread pool, whatever the link count: a box's gradients there equal a single-env scene's, bit for
    bit. Here, after the test above, it reuses the pool variants of those kernels that the
    quadruped's batches compiled (on its own, 100 s of LLVM on a slow machine)."""
    test_contact_gradients.assert_batch_equals_single(SERIAL_SOLVE_WORK // 6 + 1)  # (a box: 6 dofs)


def _boxes_on_plane(sizes, n_envs):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002))
    scene.add_entity(gs.morphs.Plane())
    for k, size in enumerate(sizes):
        scene.add_entity(gs.morphs.Box(size=size, pos=(0.0, 0.0, 0.5 * size[2] + 0.3 * k)))
    scene.build(n_envs=n_envs)
    for _ in range(3):
        scene.step()
    return scene


def test_contact_scenes_share_compiled_kernels(f64):
    """Plane–box and box–box pairs: a scene of other sizes, counts and batch reuses every kernel."""
    _boxes_on_plane([(0.2, 0.2, 0.2), (0.1, 0.3, 0.2)], 0)
    compiled = _n_compiled()
    _boxes_on_plane([(0.1, 0.1, 0.1)] * 5, 3)
    assert _n_compiled() == compiled, "a new contact scene compiled kernels again"


def _contact_rollout(mesh_file):
    """Final positions and dL/dv0 of cylinders lying on a box with icosahedra on top and a sphere
    beside them (the convex kernels: the collider, converge, the collider's reverse; a primitive
    pair's; the constraint solve and its reverse), float64, 2 envs, 60 steps."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002, requires_grad=True))
    scene.add_entity(gs.morphs.Box(pos=(0, 0, 0.05), size=(1, 1, 0.1), fixed=True))
    bodies = []
    for k in range(2):
        bodies.append(scene.add_entity(gs.morphs.Cylinder(pos=(0.3 * k, 0, 0.149), radius=0.05, height=0.1,
                                                          euler=(90, 10 * k, 0))))
        bodies.append(scene.add_entity(gs.morphs.Mesh(file=mesh_file, pos=(0.3 * k, 0.01, 0.245))))
    bodies.append(scene.add_entity(gs.morphs.Sphere(pos=(-0.3, 0, 0.149), radius=0.05)))
    scene.build(n_envs=2)
    v0 = torch.tensor([[0.2, 0.0, -0.1, 0.0, 0.3, 0.5], [0.0, 0.1, 0.0, 1.0, 0.0, 0.0]], dtype=torch.float64,
                      requires_grad=True)
    for body in bodies:
        body.set_dofs_velocity(v0)
    for _ in range(60):
        scene.step()
    positions = torch.stack([body.get_pos() for body in bodies])
    (positions.pow(2).sum() + sum(body.get_quat()[:, 1:].sum() for body in bodies)).backward()
    return positions.detach(), v0.grad


def _welded_rollout():
    """Final positions and dL/dv0 of two boxes welded to each other at run time, sliding on a plane
    with the elliptic cone and torsional and rolling friction, float64, 40 envs (past
    SERIAL_SOLVE_WORK: the solve and its reverse on the thread pool), 20 steps: the variants of the
    constraint solve the contact rollout leaves out."""
    options = gs.options.RigidOptions(friction_cone=gs.friction_cone.elliptic, enable_torsional_friction=True,
                                      enable_rolling_friction=True, max_dynamic_constraints=1)
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.005, requires_grad=True), rigid_options=options)
    scene.add_entity(gs.morphs.Plane())
    boxes = [scene.add_entity(gs.morphs.Box(pos=(0.12 * k, 0, 0.05), size=(0.1, 0.1, 0.1))) for k in range(2)]
    scene.build(n_envs=40)
    assert 40 * 12 > SERIAL_SOLVE_WORK
    scene.sim.rigid_solver.add_weld_constraint(boxes[0].links[0].idx, boxes[1].links[0].idx)
    v0 = torch.linspace(-1.0, 1.0, 40 * 6, dtype=torch.float64).reshape(40, 6).requires_grad_(True)
    boxes[0].set_dofs_velocity(v0)
    for _ in range(20):
        scene.step()
    positions = torch.stack([box.get_pos() for box in boxes])
    positions.pow(2).sum().backward()
    return positions.detach(), v0.grad


def _jointed_rollout():
    """Final joint positions, link positions, mass matrices and dL/d(forces) of a two-link pendulum's
    contact-free rollout (the one-launch step, the reverse without rows, the getters and their
    reverse), float64, 2 envs, 30 steps; then the qpos inverse kinematics finds for its tip."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True),
                     rigid_options=gs.options.RigidOptions(enable_collision=False))
    robot = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True))
    scene.build(n_envs=2)
    forces = torch.linspace(-1.0, 1.0, 30 * 2 * robot.n_dofs, dtype=torch.float64).reshape(30, 2, -1)
    forces.requires_grad_(True)
    robot.set_dofs_position(torch.tensor([[0.3, -0.2], [1.0, 0.5]], dtype=torch.float64))
    for force in forces.unbind(0):
        robot.control_dofs_force(force)
        scene.step()
    q, links, mass = robot.get_dofs_position(), robot.get_links_pos(), robot.get_mass_mat().detach()
    (q.pow(2).sum() + links.sum()).backward()
    tip = robot.links[-1]
    reach = robot.inverse_kinematics(tip, pos=links.detach()[:, -1] * 0.9, max_samples=3, seed=0)
    return q.detach(), links.detach(), mass.detach(), forces.grad, reach


def _mpm_rollout():
    """Final particle positions and dL/dv0 of an elastic block dropped towards a fixed rigid box, a
    free sphere beside it (the MPM's forward and reverse kernels with a collider at rest and a moving
    one, the coupler's), float64, 5 steps of 10 substeps."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=2e-3, substeps=10, requires_grad=True),
                     mpm_options=gs.options.MPMOptions(lower_bound=(-0.2, -0.2, -0.1), upper_bound=(0.2, 0.2, 0.3),
                                                       grid_density=32))
    scene.add_entity(gs.morphs.Box(pos=(0, 0, 0.03), size=(0.4, 0.4, 0.06), fixed=True), material=gs.materials.Rigid())
    jelly = scene.add_entity(gs.morphs.Box(pos=(0, 0, 0.1), size=(0.08, 0.08, 0.08)),
                             material=gs.materials.MPM.Elastic())
    scene.add_entity(gs.morphs.Sphere(pos=(0.07, 0, 0.1), radius=0.02))
    scene.build()
    v0 = torch.linspace(-0.5, 0.5, 3 * jelly.n_particles, dtype=torch.float64).reshape(-1, 3).requires_grad_(True)
    jelly.set_particles_vel(v0)
    for _ in range(5):
        scene.step()
    positions = jelly.get_particles_pos()
    positions.pow(2).sum().backward()
    return positions.detach(), v0.grad


# the kernels at launch.SOLVE_OPT_LEVEL (besides the constraint solve's reverse), and those always at 1
SOLVE = (step.constrain, ik.inverse_kinematics)
ONE = (*mpm_kernels.KERNELS, *mpm_kernels.STRESS_KERNELS, coupler.couple, coupler.couple_adjoint)


def _record_compiles(monkeypatch):
    """{(kernel name, its kind: "light", "solve" (SOLVE or the constraint solve's reverse) or "one"
    (ONE)): {opt_level}} of each kernel compiled (or loaded from the offline cache) from now on:
    BoundKernel resolves a kernel's code once per Taichi runtime."""
    compiled = {}
    resolve = BoundKernel._resolve

    def recording(self, program, args):
        kind = "one" if self.kernel in ONE else "solve" if self.kernel in SOLVE or (
            self.kernel is step.reverse_dynamics and self.template[1] == 1) else "light"
        compiled.setdefault((self.kernel.__name__, kind), set()).add(impl.current_cfg().opt_level)
        return resolve(self, program, args)
    monkeypatch.setattr(BoundKernel, "_resolve", recording)
    return compiled


@pytest.mark.slow
@pytest.mark.restarts
def test_light_kernels_compute_the_same_bits_at_taichi_default_opt_level(f64, tmp_path, monkeypatch):
    """Every rigid kernel but those of an iterative solve, and the MPM's reverse kernels, compile at
    Taichi's opt_level 0 (launch.LIGHT_OPT_LEVEL: no whole-kernel common-subexpression elimination,
    most of their compile time), the constraint solve, its reverse and inverse kinematics at
    launch.SOLVE_OPT_LEVEL (1 for users, 0 in the test suite: tests/conftest.py); a contact rollout,
    a welded one (the solve's elliptic, condim-6, equality and thread-pool variants), a jointed one
    with inverse kinematics and an MPM one through them and their gradients are the same bits in the
    suite's setting, the users' and with every kernel at Taichi's default, 1. Taichi keeps a
    kernel's first compile for its runtime's life, so each setting runs in a new runtime."""
    mesh_file = str(tmp_path / "ico.obj")
    trimesh.creation.icosphere(subdivisions=1, radius=0.05).export(mesh_file)
    compiled = _record_compiles(monkeypatch)
    rollouts = []
    settings = dict.fromkeys(((launch.LIGHT_OPT_LEVEL, launch.SOLVE_OPT_LEVEL), (launch.LIGHT_OPT_LEVEL, 1), (1, 1)))
    for light, solve in settings:
        monkeypatch.setattr(launch, "LIGHT_OPT_LEVEL", light)
        monkeypatch.setattr(launch, "SOLVE_OPT_LEVEL", solve)
        gs.destroy()
        gs.init(precision="64", logging_level="warning")
        rollouts.append((*_contact_rollout(mesh_file), *_jointed_rollout(), *_mpm_rollout(), *_welded_rollout()))
        names = {name for name, _ in compiled}
        assert {"collide", "collide_adjoint", "converge", "smooth_substep", "reverse_kinematics", "advance",
                "read_mass_matrix", "read_links", "pre_coupling_backward", "post_coupling_backward"} <= names
        assert {("constrain", "solve"), ("reverse_dynamics", "solve"), ("inverse_kinematics", "solve"),
                ("reverse_dynamics", "light"),
                ("pre_coupling", "one"), ("post_coupling", "one"), ("couple", "one"), ("couple_adjoint", "one")} \
            <= set(compiled)
        levels = {"light": light, "solve": solve, "one": 1}
        assert compiled == {(name, kind): {levels[kind]} for name, kind in compiled}, compiled
        compiled.clear()
    assert len(rollouts) == 3 and all(rollouts[0][k].abs().sum() > 0 for k in (1, 5, 8, 10))  # the gradients
    for other in rollouts[1:]:
        for a, b in zip(rollouts[0], other):
            assert torch.equal(a, b), (a - b).abs().max()
