"""Rigid–MPM coupling with shapes of moving links, both ways (solvers/coupler.py): beside Genesis,
momentum exchanged exactly, batched as single envs, refused where gradients are asked for."""
import json
import os
import runpy

import numpy as np
import pytest
import torch

import genesis_lite as gs
from genesis_lite.solvers.core import GradientError

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture(scope="module", autouse=True)
def f64_module():
    gs.init(precision="64", logging_level="warning")


@pytest.fixture
def bench(monkeypatch):
    """bench/coupling.py's functions (its scenes; its folder on the path for its imports)."""
    monkeypatch.syspath_prepend(os.path.join(ROOT, "bench"))
    return runpy.run_path(os.path.join(ROOT, "bench", "coupling.py"))


# per scene of bench/coupling.py: (steps compared, the largest difference allowed in each of its
# column groups (bench COLUMNS: box position m, quaternion, block centre m; pendulum angle rad, rate
# rad/s, block centre m; tumbler hub position m, hub turn rad, elbow rad, block centre m)): about 2.5
# times the gaps measured there (box over its first 100 steps 9.6e-4, 1.8e-2, 1.6e-5; pendulum over
# 400 7.6e-5, 9.1e-4, 8.1e-6; tumbler over 150 9.8e-4, 1.2e-2, 4.1e-5, 2.9e-5): Genesis couples with
# the poses after its rigid substep and applies the force in the next one (coupler.py)
BOUNDS = {"box": (100, (2.5e-3, 4.5e-2, 4e-5)), "pendulum": (400, (2e-4, 2.5e-3, 2e-5)),
          "tumbler": (150, (2.5e-3, 3e-2, 1e-4, 7.5e-5))}


@pytest.mark.parametrize("case", list(BOUNDS))
def test_moving_shapes_move_as_in_genesis(bench, case):
    """bench/coupling.py's moving scenes against Genesis 1.4.5's records (stored by that script): a
    box thrown spinning onto an elastic block on a plane (it lands, tumbles, rests: the shape's
    velocity with its spin, the force back on a free body); a pendulum whose bob swings into the
    block and is stopped by it (a hinge's generalised force, through a lever); a free hub whose
    hinged arm turns while it lands on the block (shapes on a free root and on the link below it:
    the velocity about the tree's root, the force through both joints)."""
    with open(os.path.join(ROOT, "tests", "data", "genesis_coupling_moving.json")) as file:
        expected = np.array(json.load(file)[case])
    steps, bounds = BOUNDS[case]
    bench["STEPS"][case] = steps
    ours = np.array(bench["rollout"](case, *bench["scene_of"](gs, case)))
    for (name, first, end), bound in zip(bench["COLUMNS"][case], bounds):
        gap = np.abs(ours[:, first:end] - expected[:steps, first:end]).max()
        assert gap < bound, f"{case}, {name}: {gap:.3g} from Genesis (bound {bound})"
    if case == "pendulum":  # (it did meet the block: stopped, and swung back)
        assert ours[:, 1].min() < -1.9 and ours[-1, 1] > 0.3


def _floating_scene(n_envs=0, velocities=((1.0, 0.0, 0.0, 0.0, 0.0, 0.0),), morph=None, softness=0.002):
    """Without gravity, far from the walls: an elastic block at rest, a free box (its centre of mass
    at its origin; or ``morph``; coup_softness ``softness`` m) thrown at it spinning (velocities: per
    env, its 6 dof velocities); returns (scene, block, box, particle mass kg)."""
    size = 0.01
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=2e-3, substeps=4, gravity=(0.0, 0.0, 0.0)),
                     mpm_options=gs.options.MPMOptions(lower_bound=(-0.5, -0.5, -0.5), upper_bound=(0.5, 0.5, 0.5),
                                                       grid_density=32, particle_size=size))
    block = scene.add_entity(gs.morphs.Box(pos=(0.05, 0.0, 0.0), size=(0.1, 0.12, 0.1)),
                             material=gs.materials.MPM.Elastic(E=2e4, rho=800.0))
    morph = morph or gs.morphs.Box(pos=(-0.08, 0.01, 0.0), size=(0.05, 0.04, 0.06), euler=(10, 20, 30))
    box = scene.add_entity(morph, material=gs.materials.Rigid(rho=600.0, coup_friction=0.4, coup_restitution=0.3,
                                                              coup_softness=softness))
    scene.build(n_envs=n_envs)
    box.set_dofs_velocity(torch.tensor(velocities, dtype=torch.float64).squeeze(0))
    return scene, block, box, 800.0 * size ** 3


def _momentum(block, box, particle_mass):
    """(3,) kg·m/s: the particles' and the box's linear momentum."""
    return particle_mass * block.get_particles_vel().sum(dim=-2) + box.get_mass() * box.get_vel()


def test_the_coupling_exchanges_momentum_exactly():
    """The momentum a node loses the shape gains in the same substep (a free body whose centre of
    mass is its origin: its linear momentum changes by h F exactly); the particles' transfers
    conserve theirs: the total stays at its start to round-off while the box pushes the block, spins
    against it and bounces off."""
    scene, block, box, particle_mass = _floating_scene(velocities=((1.0, 0.0, 0.0, 0.0, 3.0, 6.0),))
    start = _momentum(block, box, particle_mass)
    speed = [float(box.get_vel()[0])]
    for _ in range(60):
        scene.step()
        np.testing.assert_allclose(_momentum(block, box, particle_mass).numpy(), start.numpy(), rtol=0, atol=1e-13)
        speed.append(float(box.get_vel()[0]))
    block_vel = block.get_particles_vel().mean(dim=0)
    assert min(speed) < 0.7 and float(block_vel[0]) > 0.05  # (it met the block, which moved off)


@pytest.mark.parametrize("pool", [False, True])
def test_batched_envs_equal_single_scenes_bit_for_bit(pool, monkeypatch):
    """Two envs thrown differently give each the bits of a scene of its own, the envs on the calling
    thread or (pool) on Taichi's thread pool."""
    if pool:  # (the rigid solver's env loops, the coupler's with them, go to the pool above this)
        monkeypatch.setattr("genesis_lite.solvers.rigid.data.SERIAL_LINK_ENVS", 0)
    velocities = ((1.0, 0.1, 0.0, 0.0, 3.0, 6.0), (0.8, -0.1, 0.05, 2.0, 0.0, -4.0))
    batched = _floating_scene(2, velocities)
    singles = [_floating_scene(0, (v,)) for v in velocities]
    for _ in range(30):
        for scene in (batched[0], *(single[0] for single in singles)):
            scene.step()
    for e, single in enumerate(singles):
        assert torch.equal(batched[1].get_particles_pos()[e], single[1].get_particles_pos())
        assert torch.equal(batched[2].get_dofs_velocity()[e], single[2].get_dofs_velocity())
    assert not torch.equal(batched[1].get_particles_pos()[0], batched[1].get_particles_pos()[1])


def test_a_mesh_on_a_moving_link_meets_the_grid_as_its_primitive(tmp_path):
    """A free box mesh (its convex hull's face planes in the coupler's table) thrown spinning into the
    block moves as the Box primitive: the same particles and pose to round-off (the two bodies'
    inertias and distances come from different computations). Sharp (coup_softness 0: the shapes
    act inside only, where the hull's distance is the box's; beside an edge it is a lower bound)."""
    import trimesh

    path = str(tmp_path / "box.obj")
    trimesh.creation.box(extents=(0.05, 0.04, 0.06)).export(path)
    pose = dict(pos=(-0.08, 0.01, 0.0), euler=(10, 20, 30))
    runs = []
    for morph in (gs.morphs.Mesh(file=path, **pose), gs.morphs.Box(size=(0.05, 0.04, 0.06), **pose)):
        scene, block, box, _ = _floating_scene(velocities=((1.0, 0.0, 0.0, 0.0, 3.0, 6.0),), morph=morph,
                                               softness=0.0)
        for _ in range(40):
            scene.step()
        runs.append((block.get_particles_pos(), box.get_dofs_position(), box.get_dofs_velocity()))
    for mesh_values, box_values in zip(*runs):
        np.testing.assert_allclose(mesh_values.numpy(), box_values.numpy(), rtol=0, atol=1e-9)
    assert float(runs[1][2][0]) < 0.7  # (it met the block)


def test_a_differentiable_scene_refuses_moving_shapes_and_names_them():
    """requires_grad with coupled shapes on moving links: a named error at build (no gradient would
    pass through them); needs_coup=False leaves them out, and the scene builds."""
    for needs_coup in (True, False):
        scene = gs.Scene(sim_options=gs.options.SimOptions(requires_grad=True),
                         mpm_options=gs.options.MPMOptions(lower_bound=(-0.5, -0.5, -0.2), upper_bound=(0.5, 0.5, 0.6)))
        scene.add_entity(gs.morphs.Plane())
        scene.add_entity(gs.morphs.Sphere(pos=(0.3, 0.0, 0.3), radius=0.05), name="ball",
                         material=gs.materials.Rigid(needs_coup=needs_coup))
        scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.2), size=(0.1, 0.1, 0.1)), material=gs.materials.MPM.Sand())
        if needs_coup:
            with pytest.raises(GradientError, match=r"scene.build: MPM particles meet rigid shapes on moving links "
                                                    r"\(entity 'ball': sphere of link '\w+'\) forward only"):
                scene.build()
        else:
            scene.build()
            assert scene.sim.coupler is None and len(scene.mpm_solver.collider_rows) == 1  # (the plane)


def _pile_beside_a_jelly(max_contacts):
    """A pyramid of 30 boxes (4 cm; 4 × 4, 3 × 3, 2 × 2, 1: each on four below it) forming on a plane,
    beside an elastic block a box is dropped on; RigidOptions(max_contacts=max_contacts); returns
    (scene, rigid bodies, block)."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, substeps=4),
                     rigid_options=gs.options.RigidOptions(max_contacts=max_contacts),
                     mpm_options=gs.options.MPMOptions(lower_bound=(-0.4, -0.3, -0.1), upper_bound=(0.3, 0.3, 0.4),
                                                       grid_density=32))
    scene.add_entity(gs.morphs.Plane())
    size = 0.04
    places = [(1.004 * size * (i + level / 2), 1.004 * size * (j + level / 2), (0.5 + 1.2 * level) * size)
              for level in range(4) for j in range(4 - level) for i in range(4 - level)]
    bodies = [scene.add_entity(gs.morphs.Box(size=(size,) * 3, pos=pos)) for pos in places]
    block = scene.add_entity(gs.morphs.Box(pos=(-0.2, 0.0, 0.05), size=(0.1, 0.1, 0.1)),
                             material=gs.materials.MPM.Elastic(E=3e4))
    bodies.append(scene.add_entity(gs.morphs.Box(size=(0.04, 0.04, 0.04), pos=(-0.2, 0.0, 0.16))))
    scene.build()
    return scene, bodies, block


def test_contact_slots_growing_mid_step_keep_the_coupled_trajectory():
    """RigidOptions(max_contacts=None) doubles the rigid contact slots as a pile forms (new arrays
    inside a substep's pre-coupling half: the coupler binds to them); the scene, a box landing on a
    jelly block beside the pile, moves bit for bit as one sized for the worst case from the start."""
    grown, sized = _pile_beside_a_jelly(None), _pile_beside_a_jelly(10 ** 4)
    start = grown[0]._rigid_solver.data.size["C"]
    for _ in range(40):
        for scene, _, _ in (grown, sized):
            scene.step()
    assert grown[0]._rigid_solver.data.size["C"] > start
    assert torch.equal(grown[2].get_particles_pos(), sized[2].get_particles_pos())
    for a, b in zip(grown[1], sized[1]):
        assert torch.equal(a.get_qpos(), b.get_qpos())
    assert float(grown[1][-1].get_pos()[2]) < 0.14  # (the box met the block, 10 cm tall: it rests on it)
