"""The MPM solver in a scene: conservation laws, free fall, batching, the shared substep loop
with the rigid solver, and its errors (issue 12). Physics behaviour per material is in
test_mpm_physics.py, gradients in test_mpm_gradients.py."""
import sys

import numpy as np
import pytest
import torch

import genesis_lite as gs
from genesis_lite.solvers.mpm import layout
from tests.conftest import warns

G = 9.81
DT, SUBSTEPS = 2e-3, 5
SMALL = dict(lower_bound=(-0.3, -0.3, 0.0), upper_bound=(0.3, 0.3, 0.6), grid_density=32)


def _scene(material, n_envs=0, gravity=(0.0, 0.0, -G), pos=(0.0, 0.0, 0.3), size=(0.12, 0.12, 0.12), rigid=False,
           **mpm):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT, substeps=SUBSTEPS, gravity=gravity),
                     mpm_options=gs.options.MPMOptions(**{**SMALL, **mpm}))
    blob = scene.add_entity(gs.morphs.Box(pos=pos, size=size), material=material, name="blob")
    robot = scene.add_entity(gs.morphs.Box(pos=(0.2, 0.2, 0.4), size=(0.05, 0.05, 0.05)), name="cube") if rigid \
        else None
    scene.build(n_envs=n_envs)
    return scene, blob, robot


def _jelly():
    return gs.materials.MPM.Elastic(E=1e5, nu=0.2, rho=1000.0, model="neohooken")


def _state(blob):
    """(n, 25) rows of the blob's particles (env 0)."""
    rows = blob.scene.get_state().mpm.view(blob.scene.sim.slot(blob.scene.mpm_solver).state.shape[0], -1,
                                            layout.WIDTH)
    return rows[0].detach().numpy()


def _spin(blob, omega=(0.0, 0.0, 3.0), drift=(0.2, -0.1, 0.05)):
    """Give the blob a rigid rotation ω (rad/s) about its centre plus a drift (m/s)."""
    pos = blob.get_particles_pos().detach()
    centre = pos.mean(dim=0)
    vel = torch.cross(torch.tensor(omega, dtype=pos.dtype).expand_as(pos), pos - centre, dim=1) + \
        torch.tensor(drift, dtype=pos.dtype)
    blob.set_particles_vel(vel)


def test_free_fall_is_symplectic_euler(f64):
    """Before anything touches: z_n = z0 − g h² n(n+1)/2 (the grid update adds g h, the gather
    moves by the new velocity), for every particle, to 1e-10 m."""
    scene, blob, _ = _scene(_jelly(), pos=(0.0, 0.0, 0.4))
    z0 = blob.get_particles_pos()[:, 2].detach().numpy().copy()
    h, steps = DT / SUBSTEPS, 10
    for _ in range(steps):
        scene.step()
    n = steps * SUBSTEPS
    z = blob.get_particles_pos()[:, 2].detach().numpy()
    assert np.abs(z - (z0 - G * h * h * n * (n + 1) / 2)).max() < 1e-10


def test_mass_on_the_grid_is_the_particles_mass(f64):
    """Every substep the grid's mass equals Σ m_p (B-spline weights sum to 1) to round-off, and
    particle masses (rho · vol) never change."""
    scene, blob, _ = _scene(_jelly())
    _spin(blob)
    scene.step()
    solver = scene.mpm_solver
    particles = float(blob.get_mass())
    solver.begin_step(None)
    solver.substep_pre_coupling(0)  # the grid now holds the scattered mass and momentum
    grid_mass = float(solver.grid[..., 3].sum())
    solver.substep_post_coupling(0)
    solver.end_step(False)
    assert particles == pytest.approx(float(scene.mpm_options.particle_size) ** 3 * 1000.0 * blob.n_particles,
                                      rel=1e-14)
    assert abs(grid_mass - particles) < 1e-13 * particles


def test_momentum_is_conserved_without_gravity_or_walls(f64):
    """No gravity, no wall reached: Σ m v is conserved to 1e-12 relative per step while the
    spinning, drifting jelly deforms. APIC's angular momentum about the centre of mass (the
    particles' plus the affine fields' share) is conserved too: measured 1e-14 relative over 20
    steps (MPM_NOTES expected an O(h) drift: it holds for the particles' share alone)."""
    scene, blob, _ = _scene(_jelly(), gravity=(0.0, 0.0, 0.0))
    _spin(blob)
    mass = float(blob.get_mass()) / blob.n_particles

    def momenta():
        rows = _state(blob)
        pos, vel = rows[:, 0:3], rows[:, 3:6]
        centre = pos.mean(axis=0)
        C = rows[:, 6:15].reshape(-1, 3, 3)
        # APIC's angular momentum: Σ m (x × v) plus the affine field's share, m dx²/4 ε : C (Jiang et al. 2015)
        dx = 1.0 / SMALL["grid_density"]
        affine = mass * dx * dx / 4.0 * np.stack([C[:, 2, 1] - C[:, 1, 2], C[:, 0, 2] - C[:, 2, 0],
                                                  C[:, 1, 0] - C[:, 0, 1]], axis=1)
        return mass * vel.sum(axis=0), (mass * np.cross(pos - centre, vel) + affine).sum(axis=0)

    p0, l0 = momenta()
    worst_p = worst_l = 0.0
    for _ in range(20):
        before = momenta()[0]
        scene.step()
        p, l = momenta()
        worst_p = max(worst_p, np.abs(p - before).max() / np.abs(before).max())
        worst_l = max(worst_l, np.abs(l - l0).max() / np.abs(l0).max())
    print(f"linear momentum: worst change per step {worst_p:.2e} relative; angular momentum: drift {worst_l:.2e} "
          f"relative over 20 steps")
    lo, hi = scene.mpm_solver.wall_lower, scene.mpm_solver.wall_upper
    pos = _state(blob)[:, 0:3]
    assert np.all(pos > lo + 0.05) and np.all(pos < hi - 0.05)  # no wall was near
    assert worst_p < 1e-12
    assert worst_l < 1e-10  # APIC with the affine share conserves it too (measured 1e-14)


def test_batched_envs_equal_single_scenes(f64):
    """Env e of a batched scene gives the same bits as a single-env scene started like it."""
    batched, blob_b, _ = _scene(_jelly(), n_envs=2)
    single, blob_s, _ = _scene(_jelly())
    rng = np.random.default_rng(5)
    vel = torch.as_tensor(rng.normal(0.0, 0.3, (2, blob_b.n_particles, 3)))
    blob_b.set_particles_vel(vel)
    blob_s.set_particles_vel(vel[1])
    for _ in range(5):
        batched.step()
        single.step()
    assert torch.equal(blob_b.get_particles_pos()[1], blob_s.get_particles_pos())
    assert torch.equal(blob_b.get_state().F[1], blob_s.get_state().F[0])


def test_material_updates_without_svd_materials_equal_those_beside_them(f64):
    """A scene none of whose materials takes an SVD compiles its stress stage without one, a particle at
    a time (kernels.STRESS_KERNELS); beside a corotated body the stage takes particles in pairs with
    interleaved SVDs. A neo-Hookean jelly moves the same bits either way (its neighbour, 20 cm away,
    never shares a node; each body is one half of the scatter in both scenes)."""
    def jelly_beside(model):
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT, substeps=SUBSTEPS),
                         mpm_options=gs.options.MPMOptions(**SMALL))
        jelly = scene.add_entity(gs.morphs.Box(pos=(-0.15, 0.0, 0.3), size=(0.1, 0.1, 0.1)), material=_jelly())
        scene.add_entity(gs.morphs.Box(pos=(0.15, 0.0, 0.3), size=(0.1, 0.1, 0.1)),
                         material=gs.materials.MPM.Elastic(E=1e5, nu=0.2, model=model))
        scene.build()
        _spin(jelly)
        for _ in range(5):
            scene.step()
        return jelly.get_state()
    among_neo_hookean, beside_corotated = jelly_beside("neohooken"), jelly_beside("corotation")
    assert torch.equal(among_neo_hookean.pos, beside_corotated.pos)
    assert torch.equal(among_neo_hookean.F, beside_corotated.F)


def test_rigid_and_mpm_share_the_substep_loop_bit_for_bit(f64):
    """A scene with rigid and MPM entities runs both through the shared substep loop (split
    kernels, the coupling stage between them); with a moving body that never comes near the
    particles, each evolves exactly as in a scene of its own (fused kernels)."""
    both, blob, cube = _scene(_jelly(), rigid=True)
    assert both.sim.coupler is not None  # (the cube couples: the stage runs, and finds no node)
    alone, blob_alone, _ = _scene(_jelly())
    rigid_only = gs.Scene(sim_options=gs.options.SimOptions(dt=DT, substeps=SUBSTEPS))
    cube_alone = rigid_only.add_entity(gs.morphs.Box(pos=(0.2, 0.2, 0.4), size=(0.05, 0.05, 0.05)), name="cube")
    rigid_only.build()
    assert len(both.sim.slots) == 2 and len(alone.sim.slots) == 1
    for _ in range(10):
        for scene in (both, alone, rigid_only):
            scene.step()
    assert torch.equal(blob.get_particles_pos(), blob_alone.get_particles_pos())
    assert torch.equal(cube.get_pos(), cube_alone.get_pos())
    assert cube.get_pos()[2] < 0.4  # it fell


def test_particles_outside_the_walls_raise(f64):
    scene = gs.Scene(mpm_options=gs.options.MPMOptions(**SMALL))
    with pytest.raises(gs.InvalidInputError, match="entity 'outside'.*inside the MPM walls"):
        scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.02), size=(0.1, 0.1, 0.1)), material=_jelly(), name="outside")


def test_a_grid_too_large_for_memory_raises(f64):
    scene = gs.Scene(mpm_options=gs.options.MPMOptions(lower_bound=(-50, -50, 0), upper_bound=(50, 50, 50),
                                                       grid_density=64))
    scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 1.0), size=(0.05, 0.05, 0.05)), material=_jelly(), name="jelly")
    with pytest.raises(gs.InvalidInputError, match="grid of 6401 × 6401 × 3201 nodes.*GiB"):
        scene.build()


def test_a_shape_with_too_many_particles_for_memory_raises_before_sampling(f64, monkeypatch):
    """A particle_size that fills a shape with more candidate particles than memory holds raises a
    named error at add_entity, before any is made (numpy's MemoryError after minutes, or the
    machine's out-of-memory killer, before): checked against the memory free, here made 1 MiB."""
    import genesis_lite.solvers.mpm.sampling as sampling

    monkeypatch.setattr(sampling, "available_memory", lambda: 2**20)
    scene = gs.Scene(mpm_options=gs.options.MPMOptions(**SMALL, particle_size=0.004))
    scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.2), size=(0.04, 0.04, 0.04)), material=_jelly(), name="small")
    for morph in (gs.morphs.Box(pos=(0.0, 0.0, 0.3), size=(0.2, 0.2, 0.2)),
                  gs.morphs.Sphere(pos=(0.0, 0.0, 0.3), radius=0.1),
                  gs.morphs.Cylinder(pos=(0.0, 0.0, 0.3), radius=0.1, height=0.2)):
        with pytest.raises(gs.InvalidInputError, match=r"entity 'big': particle_size = 0.004 m fills the shape's .* "
                                                       r"1.25e\+05 candidate particles, .* GiB free; use a larger"):
            scene.add_entity(morph, material=_jelly(), name="big")


def test_arrays_beyond_32_bit_indices_raise(f64, monkeypatch):
    """On a machine with memory enough for them, arrays of more than 2³¹ − 1 numbers still raise:
    the kernels' indices are 32-bit (Taichi 1.7), so such an index would wrap. 500 envs of Genesis's
    default domain at 64 cells/m: a grid of 500 × 1.08 M nodes × 4 numbers."""
    import genesis_lite.solvers.mpm.solver as mpm_solver

    monkeypatch.setattr(mpm_solver, "available_memory", lambda: 2**62)  # a machine with memory to spare

    def allocate(self):
        raise AssertionError("allocated: the index check did not stop the build")

    monkeypatch.setattr(mpm_solver.MPMSolver, "_allocate", allocate)
    scene = gs.Scene(mpm_options=gs.options.MPMOptions(grid_density=64))
    scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.5), size=(0.05, 0.05, 0.05)), material=_jelly(), name="jelly")
    with pytest.raises(gs.InvalidInputError, match="entities: jelly.*the grid would hold 2,1.*numbers.*500 env.*"
                                                   "at most 2,147,483,647"):
        scene.build(n_envs=500)


def test_positions_the_walls_clamped_are_accepted_back_in_float32(f32):
    """Particles thrown onto the floor sit on its wall as the kernels round it (float32: 0.19374999
    for a wall at 0.19375); set_particles_pos(get_particles_pos()) takes them back (it compared
    them with the float64 wall and refused)."""
    scene, blob, _ = _scene(gs.materials.MPM.Liquid(), lower_bound=(-0.3, -0.3, 0.1), upper_bound=(0.3, 0.3, 0.7),
                            pos=(0.0, 0.0, 0.3), size=(0.08, 0.08, 0.08))
    blob.set_velocity([0.0, 0.0, -20.0])
    for _ in range(3):
        scene.step()
    pos = blob.get_particles_pos()
    assert float(pos[:, 2].min()) == np.float32(0.1 + 3.0 / 32)  # on the floor's wall, rounded
    blob.set_particles_pos(pos)
    scene.reset(scene.get_state())  # and so does reset(state)


def test_reset_to_a_state_with_particles_outside_the_walls_raises(f64):
    """A SimState made or edited by hand is checked as set_particles_pos checks positions: one with
    particles past a wall was taken, and the next step put the whole body on that wall."""
    scene, blob, _ = _scene(_jelly(), n_envs=2)
    state = scene.get_state()
    before = blob.get_particles_pos()
    rows = state.mpm.clone().view(2, -1, layout.WIDTH)
    rows[1, 3, 2] = 0.7  # one particle of env 1 above the top wall (0.6 − 3 cells)
    with pytest.raises(gs.InvalidInputError, match="scene.reset, entity 'blob': argument 'state' must put every "
                                                   "particle inside the MPM walls"):
        scene.reset(gs.SimState(scene, [rows.view(2, -1)], state.groups))
    assert torch.equal(blob.get_particles_pos(), before)  # nothing was reset


def test_a_substep_above_the_stability_limit_warns(f64, caplog):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=1e-2, substeps=1), mpm_options=gs.options.MPMOptions(**SMALL))
    scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.3), size=(0.1, 0.1, 0.1)), material=_jelly(), name="jelly")
    with warns(caplog, "entities: jelly.*exceeds the stability limit") as found:
        scene.build()
    build_line = test_a_substep_above_the_stability_limit_warns.__code__.co_firstlineno + 4
    assert found[0].endswith(f"({__file__}:{build_line})")  # at the user's line


def test_a_material_made_stiffer_than_the_substep_allows_warns(f64, caplog):
    """set_material_params checks the substep against the new stiffness too (E 1e10 after build ran
    to NaN without a word before the step that blew up); a softer value does not warn."""
    scene, blob, _ = _scene(_jelly())
    with warns(caplog, None):
        blob.set_material_params(E=2e5)
    with warns(caplog, "entities: blob.*exceeds the stability limit.*dx / wave speed") as found:
        blob.set_material_params(E=1e10)
    assert f"({__file__}:" in found[0]  # at the user's line


def test_a_stability_warning_is_said_again_only_when_worse(f64, caplog):
    """An optimisation loop that sets the same too-stiff material or too-fast velocity every
    iteration is warned once (an independent probe saw three warnings a rollout), and again when a
    later value is worse than any warned."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT, substeps=SUBSTEPS),
                     mpm_options=gs.options.MPMOptions(**SMALL))
    blob, drop = (scene.add_entity(gs.morphs.Box(pos=(x, 0.0, 0.3), size=(0.08, 0.08, 0.08)), material=_jelly(),
                                   name=name) for x, name in ((-0.1, "blob"), (0.1, "drop")))
    scene.build()
    speed = 1.2 * (1.0 / SMALL["grid_density"]) / (DT / SUBSTEPS)
    for E, said in ((1e10, True), (1e10, False), (5e9, False), (1e11, True), (2e5, False)):
        with warns(caplog, "exceeds the stability limit" if said else None):
            blob.set_material_params(E=E)
    for body, scale, said in ((blob, 1.0, True), (blob, 1.0, False), (blob, 0.9, False), (drop, 0.9, True),
                              (blob, 1.5, True)):  # (each entity's own: a second one is told of its own speed)
        with warns(caplog, f"entity '{body.name}': set_particles_vel: .* grid cells a substep" if said else None):
            body.set_velocity([0.0, scale * speed, 0.0])


@pytest.mark.parametrize("ratio, warned", [(0.75, False), (0.9, True)])
def test_the_wave_bound_keeps_a_margin_below_dx_over_c(f64, caplog, ratio, warned):
    """A nearly incompressible block (ν 0.45) at a substep h = ratio·dx/c (c the elastic wave
    speed): explicit MPM blows up there from ratio 0.95 (measured, neo-Hookean and corotated, and
    from 0.90 at ν 0.499), so 0.9 warns and 0.75 runs quietly (dx/c alone let 0.95 run to NaN
    without a word)."""
    E, nu, rho = 2e6, 0.45, 1000.0  # the wave bound below 2e-2·dx
    wave = np.sqrt(E * (1 - nu) / ((1 + nu) * (1 - 2 * nu)) / rho)
    dx = 1.0 / SMALL["grid_density"]
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=ratio * dx / wave, substeps=1),
                     mpm_options=gs.options.MPMOptions(**SMALL))
    scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.3), size=(0.1, 0.1, 0.1)),
                     material=gs.materials.MPM.Elastic(E=E, nu=nu, rho=rho), name="block")
    with warns(caplog, "entities: block.*exceeds the stability limit.*0.8·dx / wave speed" if warned else None):
        scene.build()


@pytest.mark.parametrize("cells, warned", [(0.8, False), (1.2, True)])
def test_a_speed_past_a_cell_a_substep_warns(f64, caplog, cells, warned):
    """Explicit MPM is unstable past one grid cell a substep (measured: a neo-Hookean block thrown at
    1.6 cells a substep turned to NaN at its first step, unwarned): set_velocity says so."""
    scene, blob, _ = _scene(_jelly())
    speed = cells * (1.0 / SMALL["grid_density"]) / (DT / SUBSTEPS)
    with warns(caplog, "entity 'blob': set_particles_vel: .* crosses 1.2 grid cells a substep" if warned else None):
        blob.set_velocity([0.0, speed, 0.0])


@pytest.mark.parametrize("size, warned", [(0.9, False), (1.5, True)])
def test_particles_coarser_than_the_cells_warn(f64, caplog, size, warned):
    """particle_size above the cell size dx: a body's particles couple weakly through the grid (from
    3·dx on not at all: measured, a pushed particle moves none of its neighbours)."""
    dx = 1.0 / SMALL["grid_density"]
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT, substeps=SUBSTEPS),
                     mpm_options=gs.options.MPMOptions(**SMALL, particle_size=size * dx))
    scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.3), size=(0.2, 0.2, 0.2)), material=_jelly(), name="block")
    with warns(caplog, "entities: block.*particle_size .* exceeds the grid's cell size" if warned else None):
        scene.build()


@pytest.mark.parametrize("scale", [1.0, 2.0])
def test_cameras_draw_the_particles(f64, scale):
    """A camera draws each particle as a sphere of half the particle size (times
    VisOptions.particle_size_scale) in its entity's colour, with the entity's segmentation id;
    from straight above, the jelly's particles fill its projected square, grown by the spheres'
    extra radius on each side (touching spheres: at least π/4 of it, the lower layers show
    through the gaps) and nothing outside it."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT, substeps=SUBSTEPS),
                     mpm_options=gs.options.MPMOptions(**SMALL),
                     vis_options=gs.options.VisOptions(particle_size_scale=scale))
    scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.3), size=(0.12, 0.12, 0.12)), material=_jelly(), name="jelly",
                     surface=gs.surfaces.Default(color=(0.9, 0.2, 0.2)))
    camera = scene.add_camera(res=(200, 200), pos=(0.0, 0.0, 1.3), lookat=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0),
                              fov=30)
    scene.build()
    rgb, _, seg, _ = camera.render(rgb=True, segmentation=True)
    drawn = seg == 0
    size = scene.mpm_options.particle_size
    top = 0.3 + 0.06 - size / 2.0  # the top layer's centres
    focal = 100.0 / np.tan(np.radians(15.0))
    side = (0.12 + (scale - 1.0) * size) * focal / (1.3 - top - (scale - 1.0) * size / 2)  # pixels
    rows, cols = np.nonzero(drawn)
    extent = max(rows.max() - rows.min() + 1, cols.max() - cols.min() + 1)
    assert side - 3 <= extent <= side + 2
    assert np.pi / 4 < drawn.sum() / side ** 2 <= 1.0
    assert rgb[drawn].mean(axis=0)[0] > 2 * rgb[drawn].mean(axis=0)[1]  # red


@pytest.mark.parametrize("level, box_id, jelly_id", [("link", 0, 1), ("geom", 0, 1), ("entity", 1, 0)])
def test_particle_segmentation_ids_differ_from_the_rigid_ones(f64, level, box_id, jelly_id):
    """A jelly (entity 0) left of a rigid box (entity 1, link 0, shape 0), seen from above: at the
    link and geom levels the particles' id comes after the rigid ones (it was the entity index, 0,
    the box's link id); at the entity level, the entity indices."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT, substeps=SUBSTEPS),
                     mpm_options=gs.options.MPMOptions(**SMALL),
                     vis_options=gs.options.VisOptions(segmentation_level=level))
    scene.add_entity(gs.morphs.Box(pos=(-0.12, 0.0, 0.3), size=(0.1, 0.1, 0.1)), material=_jelly(), name="jelly")
    scene.add_entity(gs.morphs.Box(pos=(0.12, 0.0, 0.3), size=(0.1, 0.1, 0.1), fixed=True), name="box")
    camera = scene.add_camera(res=(200, 100), pos=(0.0, 0.0, 1.3), lookat=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0), fov=30)
    scene.build()
    _, _, seg, _ = camera.render(rgb=False, segmentation=True)
    assert set(np.unique(seg).tolist()) == {-1, box_id, jelly_id}
    assert np.nonzero(seg == jelly_id)[1].max() < 100 < np.nonzero(seg == box_id)[1].min()


def test_scene_gravity_reaches_every_solver(f64):
    """scene.set_gravity sets the rigid and the MPM solver's gravity alike."""
    scene, blob, cube = _scene(_jelly(), rigid=True)
    scene.set_gravity((0.0, 0.0, 0.0))
    before = blob.get_particles_pos().clone()
    for _ in range(3):
        scene.step()
    assert torch.equal(blob.get_particles_pos(), before)
    assert float(cube.get_pos()[2]) == 0.4
    assert torch.equal(scene.get_gravity(), torch.zeros(3, dtype=torch.float64))


def _grad_scene(n_envs=0, checkpoint_interval=1):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT, substeps=4, requires_grad=True,
                                                       checkpoint_interval=checkpoint_interval),
                     mpm_options=gs.options.MPMOptions(**SMALL))
    blob = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.16), size=(0.1, 0.1, 0.1)), material=_jelly(), name="blob")
    scene.build(n_envs=n_envs)
    return scene, blob


def _rollout(scene, blob, vel, E, steps=20):
    """Loss of a rollout that lands the jelly on the floor: its final positions · fixed weights."""
    scene.reset()
    blob.set_particles_vel(vel)
    blob.set_material_params(E=E)
    for _ in range(steps):
        scene.step()
    weights = torch.as_tensor(np.random.default_rng(3).normal(size=(blob.n_particles, 3)))
    return (blob.get_particles_pos() * weights).sum()


@pytest.mark.parametrize("n_envs", [0, 2])
def test_loss_backward_through_the_scene_matches_fd(f64, n_envs):
    """loss.backward() through 20 scene steps (4 substeps, the jelly hitting the floor) gives the
    initial velocities' and E's gradients that central differences converge to (eps scan)."""
    from tests.fd_scan import assert_converged, directional_errors
    scene, blob = _grad_scene(n_envs)
    shape = (blob.n_particles, 3) if n_envs == 0 else (n_envs, blob.n_particles, 3)
    vel = torch.as_tensor(np.random.default_rng(1).normal(0.0, 0.5, shape)) + torch.tensor([0.0, 0.0, -1.0],
                                                                                          dtype=torch.float64)
    E = torch.tensor(1e5, dtype=torch.float64)
    assert_converged(directional_errors(lambda v: _rollout(scene, blob, v, E), vel), "initial velocities")
    assert_converged(directional_errors(lambda e: _rollout(scene, blob, vel, e * 1e5), torch.tensor(1.0,
                     dtype=torch.float64)), "E")


def test_gradients_are_bit_identical_on_repeat_and_with_checkpoints(f64):
    """The same rollout twice gives the same gradient bits, and so does checkpoint_interval=3."""
    grads = []
    for interval in (1, 1, 3):
        scene, blob = _grad_scene(checkpoint_interval=interval)
        vel = torch.zeros(blob.n_particles, 3, dtype=torch.float64, requires_grad=True)
        _rollout(scene, blob, vel, 1e5, steps=10).backward()
        grads.append(vel.grad)
    assert torch.equal(grads[0], grads[1]) and torch.equal(grads[0], grads[2])


def test_muscle_fibres_set_between_steps_or_before_backward_reach_the_gradient(f64):
    """Fibre directions are an input every step records (solvers/mpm/layout.py): set_muscle between
    two steps changes the steps after it in the backward too, and set_muscle after the rollout (for
    the next episode, say) changes nothing of the recorded graph. The actuation's gradient against
    central FD, and bit for bit against an undisturbed backward (before the fix, the backward read
    whatever fibres the solver held: −0.147 against FD −0.017; −0.202 against +0.257)."""
    from tests.fd_scan import assert_converged, directional_errors
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT, substeps=4, requires_grad=True),
                     mpm_options=gs.options.MPMOptions(**SMALL))
    muscle = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.2), size=(0.1, 0.1, 0.1)),
                              material=gs.materials.MPM.Muscle(E=1e5), name="muscle")
    scene.build()
    weights = torch.as_tensor(np.random.default_rng(0).normal(size=(muscle.n_particles, 3)))

    def rollout(actu, switch_at=None):
        scene.reset()
        muscle.set_muscle(muscle_direction=[0.0, 0.0, 1.0])
        muscle.set_actuation(actu)
        for k in range(6):
            if k == switch_at:
                muscle.set_muscle(muscle_direction=[1.0, 0.0, 0.0])
            scene.step()
        return (muscle.get_particles_pos() * weights).sum()

    actu = torch.tensor(0.2, dtype=torch.float64)
    assert_converged(directional_errors(lambda a: rollout(a, switch_at=3), actu), "actuation, fibres switched at step 3")
    grads = []
    for change_before_backward in (False, True):
        a = actu.clone().requires_grad_(True)
        loss = rollout(a)
        if change_before_backward:
            muscle.set_muscle(muscle_direction=[1.0, 0.0, 0.0])
        loss.backward()
        grads.append(a.grad)
    assert torch.equal(grads[0], grads[1])


def test_gradcheck_on_64_particles(f64):
    """torch.autograd.gradcheck: the Jacobian of 5 steps (4 substeps each, the block landing)
    from 64 particles' initial velocities and E to their final positions, against torch's FD."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT, substeps=4, requires_grad=True),
                     mpm_options=gs.options.MPMOptions(**SMALL))
    blob = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.14), size=(0.08, 0.08, 0.08)), material=_jelly())
    scene.build()
    assert blob.n_particles == 64

    pos0 = blob.get_particles_pos().detach().clone()

    def final_positions(vel, E):
        # gradcheck differentiates its first output after evaluating the function again: the
        # rollout sets the whole state (set_particles_pos resets vel, C, F, Jp) rather than
        # scene.reset(), which would close that first graph (as tests/test_autograd_graph.py)
        blob.set_particles_pos(pos0)
        blob.set_particles_vel(vel)
        blob.set_material_params(E=E * 1e5)
        for _ in range(5):
            scene.step()
        assert float(blob.get_particles_vel()[:, 2].max().detach()) > -1.0  # the floor stopped some (free fall: −2.1 m/s)
        return blob.get_particles_pos().as_subclass(torch.Tensor)

    vel = torch.as_tensor(np.random.default_rng(2).normal(0.0, 0.3, (64, 3)) - [0.0, 0.0, 2.0]).requires_grad_()
    E = torch.ones(64, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(final_positions, (vel, E), eps=1e-6, atol=1e-6, rtol=1e-5,
                                    check_undefined_grad=False)  # as tests/test_autograd_graph.py


def _rss_mib():
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("VmRSS")) / 1024


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc and /proc/self/status")
@pytest.mark.parametrize("edge, n_particles", [(0.2, 1000), (0.16, 512)])
def test_checkpointed_rollout_memory_grows_by_its_checkpoints_only(f64, edge, n_particles):
    """1000 particles (a 195 KiB state), 300 differentiable steps, checkpoint_interval=100: the
    graph holds 3 states, and so does the process. glibc raised its mmap threshold after a large
    block was freed (done below on purpose), and the heap then grew by one state a step (57 MiB
    here) although each was freed; runtime.keep_large_blocks_off_the_heap, called when a
    differentiable scene is built, keeps it fixed. 512 particles (100 KiB, under the threshold):
    each freed state was a hole in the heap that the graph's small allocations split, and it grew
    by a state a step all the same (58 states here); core.new_state maps such states. Asserted:
    under 20 states."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT, substeps=4, requires_grad=True, checkpoint_interval=100),
                     mpm_options=gs.options.MPMOptions(**SMALL))
    blob = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.25), size=(edge,) * 3), material=_jelly())
    scene.build()
    assert blob.n_particles == n_particles
    state_mib = blob.n_particles * layout.WIDTH * 8 / 2**20
    torch.ones(2**20).sum()  # a large block freed at once: what raises glibc's threshold
    blob.set_particles_vel(torch.zeros(3, dtype=torch.float64, requires_grad=True))
    scene.step()
    start = _rss_mib()
    for _ in range(300):
        scene.step()
    growth = _rss_mib() - start
    assert growth < 20 * state_mib, f"RSS grew {growth:.1f} MiB over 300 steps, {growth / state_mib:.0f} states"


@pytest.mark.slow
def test_a_5000_step_rollout_with_checkpoints_stays_in_bounded_memory(f32):
    """10k particles, 5000 differentiable steps, checkpoint_interval=100: the graph keeps one
    state (25 floats per particle, 1 MiB) every 100 steps, and a backward replays one 100-step
    segment at a time (100 MiB); without checkpoints the graph would hold 1 MiB per step, 5 GiB.
    Measured RSS growth: 58 MiB after the forward, 78 MiB at the backward's peak (146 and 255
    before runtime.keep_large_blocks_off_the_heap); asserted < 200 MiB, and the gradient finite."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=2e-4, substeps=1, requires_grad=True,
                                                       checkpoint_interval=100),
                     mpm_options=gs.options.MPMOptions())
    blob = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.4), size=(0.22, 0.22, 0.22)), material=_jelly())
    scene.build()
    assert blob.n_particles == 10648

    vel = torch.zeros(blob.n_particles, 3, requires_grad=True)
    scene.reset()
    blob.set_particles_vel(vel)
    scene.step()
    start = _rss_mib()
    for _ in range(4999):
        scene.step()
    after_forward = _rss_mib()
    blob.get_particles_pos()[:, 2].sum().backward()
    peak = max(after_forward, _rss_mib())
    print(f"RSS growth: forward {after_forward - start:.0f} MiB, with backward {peak - start:.0f} MiB")
    assert torch.isfinite(vel.grad).all() and vel.grad.abs().sum() > 0
    assert peak - start < 200


def test_muscle_groups_set_after_the_actuation_move_as_set_before_it(f64):
    """set_actuation then set_muscle(muscle_group=...) gives the same steps, bit for bit, as the
    two calls the other way round (as in Genesis, whose kernels read each particle's group at every
    step: the groups set after the actuation had no effect here, the block never contracted)."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT, substeps=4, gravity=(0.0, 0.0, 0.0)),
                     mpm_options=gs.options.MPMOptions(**SMALL))
    muscle = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.2), size=(0.1, 0.1, 0.1)),
                              material=gs.materials.MPM.Muscle(E=1e5, n_groups=2), name="muscle")
    scene.build()
    groups = np.ones(muscle.n_particles, dtype=np.int64)
    trajectories = []
    for actuation_first in (True, False):
        scene.reset()
        muscle.set_muscle(muscle_group=np.zeros(muscle.n_particles, dtype=np.int64), muscle_direction=[1.0, 0.0, 0.0])
        if actuation_first:
            muscle.set_actuation([0.0, 0.5])
        muscle.set_muscle(muscle_group=groups)
        if not actuation_first:
            muscle.set_actuation([0.0, 0.5])
        for _ in range(5):
            scene.step()
        trajectories.append(muscle.get_particles_pos())
    assert torch.equal(trajectories[0], trajectories[1])
    start = muscle.init_particles[:, 0]
    assert float(trajectories[0][:, 0].max() - trajectories[0][:, 0].min()) < start.max() - start.min()  # it contracts


def test_reset_to_a_state_restores_the_muscles_actuation(f64):
    """A muscle's actuation is part of the state, as Genesis keeps it in each particle's: reset
    to a state from get_state() goes on contracting as the rollout it came from (it cleared the
    actuation, and the replayed muscle went slack: an MPM probe beside Genesis), so does a plain
    reset() afterwards (the state is then the registered one), and a partial reset restores only
    those envs' actuation. The groups' actuation is the state's too: a particle set_muscle then
    moves to another group takes that group's value in the state (a review's find)."""
    scene, muscle, _ = _scene(gs.materials.MPM.Muscle(E=1e5, n_groups=2), n_envs=2, gravity=(0.0, 0.0, 0.0))
    muscle.set_muscle(muscle_direction=(1.0, 0.0, 0.0))
    muscle.set_actuation([[0.5, 0.7], [0.3, 0.9]])  # every particle in group 0
    for _ in range(3):
        scene.step()
    state = scene.get_state()
    for _ in range(4):
        scene.step()
    reference = muscle.get_particles_pos().clone()
    for reset in (lambda: scene.reset(state), lambda: scene.reset()):
        muscle.set_actuation([[0.1, 0.1], [0.1, 0.1]])
        reset()
        for _ in range(4):
            scene.step()
        assert torch.equal(muscle.get_particles_pos(), reference)
    muscle.set_actuation([[0.0, 0.0], [0.0, 0.0]])
    scene.reset(envs_idx=[1])  # env 1 back to the state and its actuation 0.3; env 0 keeps 0
    actu = lambda: scene.sim.inputs(scene.mpm_solver)["actu"][:, 0]  # noqa: E731 (particle 0's, per env)
    assert torch.equal(actu(), torch.tensor([0.0, 0.3], dtype=torch.float64))
    muscle.set_actuation([[0.0, 0.1], [0.0, 0.1]])
    scene.reset(state)
    muscle.set_muscle(muscle_group=np.ones(muscle.n_particles, dtype=np.int64))
    assert torch.equal(actu(), torch.tensor([0.7, 0.9], dtype=torch.float64))
