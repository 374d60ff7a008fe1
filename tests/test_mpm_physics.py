"""MPM behaviour (issue 12, "Behaviour" and "Mixed scene"): each material does what the physics says,
through the scene API, with parameters a user would pick.

Conventions shared by the cases
- Float64 unless stated; 32 cells/m (Genesis's default particle_size 0.01·64/32 = 2 cm) unless a case
  needs more; the substep obeys the solver's stability bound h ≤ 2e-2·dx (and 0.8·dx / wave speed).
- The walls lie 3 cells inside the bounds; the floor wall is at z_floor = lower_z + 3 dx. A body at rest
  on it keeps a gap of about one cell (the grid nodes at or below the wall carry the floor), so heights
  are measured from the wall and only differences of heights are compared across resolutions.
- Shapes are measured on particles tracked by index (a body's top layer, its two halves along an axis),
  which needs no surface reconstruction.
- Each case prints its figures (pytest -s shows them). Heavier variants are marked slow.
"""
import math
import os

import numpy as np
import pytest
import torch

import genesis_lite as gs

MPM = gs.materials.MPM
G = 9.81
BENCH = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "bench")
DT = 2e-3


@pytest.fixture(scope="module", autouse=True)
def one_torch_thread():
    """Per-step particle reads cost ~20 ms each with torch's 2 intra-op threads beside Taichi's on 2
    cores (measured: _particle_rows' indexing; 0.3 ms with 1 thread). The physics is unaffected."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def substeps_for(density, dt=DT):
    """Substeps per step of dt so that the substep h = dt / substeps is ≤ 2e-2·dx (Genesis's bound)."""
    return int(math.ceil(dt / (2e-2 / density) - 1e-9))


def make_scene(density, lower, upper, substeps=None, gravity=(0.0, 0.0, -G), boundary="slip", dt=DT):
    substeps = substeps or substeps_for(density, dt)
    return gs.Scene(sim_options=gs.options.SimOptions(dt=dt, substeps=substeps, gravity=gravity),
                    mpm_options=gs.options.MPMOptions(lower_bound=lower, upper_bound=upper, grid_density=density,
                                                      boundary_condition=boundary))


def floor_of(lower_z, density):
    return lower_z + 3.0 / density


def pos(entity):
    return entity.get_particles_pos().detach().cpu().numpy().astype(np.float64)


def kabsch_residual(rest, now):
    """Per-particle distance (n,) m between the shape ``now`` (n, 3) and the rest shape ``rest`` (n, 3)
    after removing the rigid motion that best aligns them (translation of the centres of mass, the
    least-squares rotation of Kabsch)."""
    a, b = rest - rest.mean(0), now - now.mean(0)
    u, _, vt = np.linalg.svd(b.T @ a)
    d = np.sign(np.linalg.det(u @ vt))
    rotation = u @ np.diag([1.0, 1.0, d]) @ vt  # maps a onto b
    return np.linalg.norm(a @ rotation.T - b, axis=1)


# -- elastic block bounces and recovers its shape -----------------------------------------------------
def test_elastic_block_bounces_and_recovers_rest_shape(f64):
    """A neo-Hookean block (E 1e5 Pa, ν 0.2, 1000 kg/m³, 12 cm) released 25 cm above the floor.

    - First contact: the first step at which the centre of mass (COM) leaves the discrete free fall
      z_n = z0 − g h² n(n+1)/2 (n substeps) by more than 1e-9 m (the walls reach the body through the
      grid a cell before its particles touch the wall). Drop height H = z0 − z_contact.
    - Bounce: the COM's apex after its first minimum climbs above z_contact by ≥ 20 % of H (the block
      leaves the floor again, rather than merely rebounding from its own compression).
    - Rest shape: after 2 s, particle positions relative to the COM, best-fit rotated (Kabsch) onto the
      initial lattice, averaged over the last 0.2 s (the residual vibration), differ from it by at most
      2 % of the block's size for EVERY particle (max, not rms). This includes the static sag under its
      own weight, ρ g L / E ≈ 1 % strain, so it is the physical rest shape on a floor.
    """
    density, size, drop = 32, 0.12, 0.25
    scene = make_scene(density, (-0.3, -0.3, 0.0), (0.3, 0.3, 0.6))
    floor = floor_of(0.0, density)
    block = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, floor + drop), size=(size,) * 3),
                             material=MPM.Elastic(E=1e5, nu=0.2, rho=1000.0, model="neohooken"))
    scene.build()
    h = DT / substeps_for(density)
    substeps = substeps_for(density)
    frames = [pos(block)]
    for _ in range(1000):
        scene.step()
        frames.append(pos(block))
    frames = np.array(frames)
    z = frames[:, :, 2].mean(1)
    n = np.arange(len(z)) * substeps
    free_fall = z[0] - G * h * h * n * (n + 1) / 2
    contact = int(np.argmax(np.abs(z - free_fall) > 1e-9))
    assert contact > 0
    fall_error = np.abs(z[:contact] - free_fall[:contact]).max()
    drop_height = z[0] - z[contact]
    lowest = contact + int(np.argmin(z[contact: contact + 250]))
    apex = lowest + int(np.argmax(z[lowest: lowest + 250]))
    climb = (z[apex] - z[contact]) / drop_height
    rest = frames[0]
    settled = frames[-100:].mean(0)
    residual = kabsch_residual(rest, settled)
    final = kabsch_residual(rest, frames[-1])
    extents = (settled.max(0) - settled.min(0)) / (rest.max(0) - rest.min(0)) - 1.0
    print(f"\nelastic bounce: {block.n_particles} particles, h = {h:.3g} s; free fall to contact (step {contact}) "
          f"exact to {fall_error:.1e} m; drop height H = {drop_height:.4f} m; COM min {z[lowest] - floor:.4f} m, "
          f"apex {z[apex] - floor:.4f} m above the floor wall: climb above contact = {climb:.1%} of H (need ≥ 20 %)"
          f"\n  rest shape after 2 s: max |Δ| / L = {residual.max() / size:.2%} "
          f"(rms {np.sqrt((residual**2).mean()) / size:.2%}; "
          f"last frame alone max {final.max() / size:.2%}); extents change {np.round(extents * 100, 2)} %")
    assert fall_error < 1e-10
    assert climb >= 0.20
    assert residual.max() / size <= 0.02


# -- liquid spreads ------------------------------------------------------------------------------------
def test_liquid_block_spreads(f64):
    """A 16 × 16 × 16 cm block of Genesis's default Liquid (inviscid, E 1e6, ν 0.2) resting on the floor
    spreads under gravity. Height of the body: twice its COM height above the floor wall, the height of
    a uniform layer with that COM (robust to stray droplets); also the 95th percentile of particle
    heights. Pass: after 1 s, both < 25 % of the initial height (0.16 m)."""
    density, size = 32, 0.16
    scene = make_scene(density, (-0.5, -0.5, 0.0), (0.5, 0.5, 0.4))
    floor = floor_of(0.0, density)
    water = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, floor + size / 2 + 0.005), size=(size,) * 3),
                             material=MPM.Liquid())
    scene.build()
    start = pos(water)
    for _ in range(500):
        scene.step()
    end = pos(water)

    def heights(p):
        return 2.0 * (p[:, 2].mean() - floor), np.quantile(p[:, 2] - floor, 0.95)

    h0, q0 = heights(start)
    h1, q1 = heights(end)
    radius = np.quantile(np.hypot(end[:, 0] - end[:, 0].mean(), end[:, 1] - end[:, 1].mean()), 0.95)
    print(f"\nliquid: {water.n_particles} particles; layer height 2·COM {h0:.4f} → {h1:.4f} m ({h1 / size:.1%} of "
          f"the block's {size} m), 95th percentile {q0:.4f} → {q1:.4f} m ({q1 / size:.1%}); 95 % of particles "
          f"within r = {radius:.3f} m (block half-width {size / 2} m)")
    assert np.isfinite(end).all()
    assert h1 < 0.25 * size and q1 < 0.25 * size


# -- sand: the friction angle ----------------------------------------------------------------------------
def _sand_layer_on_tilted_floor(friction_angle, offset, seconds=0.3):
    """A sand layer (60 × 20 × 8 cm, Sand(friction_angle), random sampler) on a sticky floor, under gravity
    tilted by friction_angle ∓ offset degrees in two envs. Returns, per env, the mean downhill
    displacement (m) of the top layer's central particles (|x| < 10 cm, away from the layer's ends whose
    vertical faces collapse at any angle) over the first and second halves of the run."""
    density = 32
    scene = make_scene(density, (-0.5, -0.2, 0.0), (0.5, 0.2, 0.3), boundary="sticky")
    floor = floor_of(0.0, density)
    sand = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, floor + 0.041), size=(0.6, 0.2, 0.08)),
                            material=MPM.Sand(friction_angle=friction_angle))
    scene.build(n_envs=2)
    tilt = np.radians([friction_angle - offset, friction_angle + offset])
    scene.set_gravity(torch.tensor(np.stack([G * np.sin(tilt), 0.0 * tilt, -G * np.cos(tilt)], 1)))
    start = pos(sand)
    steps = int(round(seconds / DT))
    for _ in range(steps // 2):
        scene.step()
    middle = pos(sand)
    for _ in range(steps - steps // 2):
        scene.step()
    end = pos(sand)
    out = []
    for e in range(2):
        top = (np.abs(start[e, :, 0]) < 0.1) & (start[e, :, 2] > start[e, :, 2].max() - 0.02)
        out.append(((middle[e, top, 0] - start[e, top, 0]).mean(), (end[e, top, 0] - middle[e, top, 0]).mean()))
    return out


def _check_tilt(friction_angle):
    (hold_1, hold_2), (flow_1, flow_2) = _sand_layer_on_tilted_floor(friction_angle, 7.0)
    print(f"\nsand φ = {friction_angle}°: top of a layer on a floor tilted {friction_angle - 7}° moves "
          f"{hold_1 * 1e3:.2f} then {hold_2 * 1e3:.2f} mm (first / second 0.15 s); tilted {friction_angle + 7}°: "
          f"{flow_1 * 1e3:.2f} then {flow_2 * 1e3:.2f} mm")
    assert flow_2 > 1.3 * flow_1  # above φ + 7°: the layer avalanches (accelerates)
    assert hold_2 <= 1.1 * hold_1  # below φ − 7°: it does not accelerate (settling creep at most)
    assert flow_1 + flow_2 > 5.0 * (hold_1 + hold_2)


def test_sand_slope_holds_within_7_degrees_below_friction_angle_and_flows_above(f64):
    """The friction angle as the stability limit of a slope, quasi-statically (a tilted-floor test of the
    angle of repose): a layer on a floor tilted φ − 7° holds, φ + 7° avalanches. Drucker–Prager's yield in
    simple shear, ‖dev τ‖ = 3α |p| with α = √(2/3)·2 sin φ / (3 − sin φ), gives τ/σ = 3α/√2
    = tan 34.7°
    for φ = 30° (tan 46.9° for 45°), inside the ±7° band. See test_sand_column_collapse_slope for the
    pile left by a collapsing column."""
    _check_tilt(30.0)


@pytest.mark.slow
def test_sand_slope_holds_below_friction_angle_and_flows_above_45(f64):
    """As above at Genesis's default friction angle, 45°."""
    _check_tilt(45.0)


@pytest.mark.slow
@pytest.mark.parametrize("friction_angle", [30.0, 45.0])
def test_sand_column_collapse_slope(f64, friction_angle, monkeypatch):
    """bench/sand_pile.py's column (r 15 cm, h 15 cm, aspect 1) on a sticky (rough) floor collapses into
    a pile; its flank slope (sand_pile.pile_slope) is measured after 1 s. A collapse is dynamic: the
    grains run out past the angle of repose, so the deposit is shallower than φ (measured 21.3° for
    30°, 28.5° for 45°; 17.7° at 32 and 17.1° at 64 cells/m for an aspect-2 column at 30°: not a
    resolution effect). Asserted: a pile forms (slope > 10°) and no flank is steeper than the
    friction allows (< φ + 7°).

    Genesis 1.4.5 leaves the same pile (bench/sand_pile.py runs both; its floor a plane with
    Coulomb friction 5 or 100): 20.3–22.2° for 30°, 26.8–29.6° for 45° (ours on that plane: 21.3°
    and 26.0°). So ±7° of φ for every φ is
    out of reach of Genesis's sand model itself, not of this code. Session 12 (φ 25–45°, aspect
    0.25–1, 32/48/64 cells/m, cones steeper than φ, a falling stream): the deposit's slope rises
    ~0.4° per degree of φ and levels off at 29–31°, the same at every resolution. Klár et al.'s
    volume correction leaves a particle that has expanded stress-free until it is compressed
    again: 70–85 % of the flowing grains and 40–47 % of the deposit are in that state, so friction
    does not act on the material that runs out. Conversely the Drucker–Prager cone, fitted to
    compression, lets an axisymmetric pile stand far above φ (a 60° cone with φ 45° holds). Not
    within ±7° even at 30° (21.3°, 8.7° below; Genesis 20.3–22.2°). Asserted besides: the slope
    within 3° of the measured one (a change of the sand model or the walls shows)."""
    monkeypatch.syspath_prepend(BENCH)
    import sand_pile
    scene, sand, floor = sand_pile.column(gs, friction_angle)
    angle, radii, heights = sand_pile.collapse(scene, sand, floor, 500)
    print(f"\nsand column φ = {friction_angle}°: deposit flank slope {angle:.1f}°; profile r {np.round(radii, 3)} "
          f"h {np.round(heights, 3)}")
    assert 10.0 < angle < friction_angle + 7.0
    assert abs(angle - {30.0: 21.3, 45.0: 28.5}[friction_angle]) < 3.0


# -- plasticity under a press ------------------------------------------------------------------------------
LOAD_TIME, RELAX_TIME, BLOCK = 0.2, 0.4, 0.12


@pytest.fixture(scope="module")
def pressed():
    """Three 12 cm blocks on the floor, side by side in one grid: ElastoPlastic (von Mises, yield 1e4 Pa),
    Snow and, as the control, Elastic, all E = 1e6 Pa (Genesis's base), ν 0.2. The load: a weight on
    each, an elastic block of the same footprint, 12 cm tall, ρ = 2e4 kg/m³ (E 1e6), i.e. 2.4e4 Pa on the
    block's top, twice the von Mises yield (uniaxial √(3/2)·1e4 Pa) and past Snow's lateral yield (its
    singular values clamp at 1 + 4.5e-3), 2.4 % strain for the elastic control. After 0.2 s the weights
    are removed (laid on the floor far away with set_particles_pos); 0.4 s to relax; the relaxed height
    and the loaded ones are averaged over the last 0.1 s of each phase (the blocks vibrate).
    (A press by setting the top layer's velocity, even before every substep, compressed the blocks by
    under 3 %: p2g averages the top layer's momentum with the layers below it.)
    Returns {name: (height ratios (1, loaded, relaxed), volume ratio mean(det F (· Jp for Snow)),
    mean Jp, finite)}; height = mean z of the top layer − mean z of the bottom layer (tracked particles)."""
    gs.init(precision="64", logging_level="warning")
    density = 32
    scene = make_scene(density, (-0.6, -0.5, 0.0), (0.6, 0.5, 0.6))
    floor = floor_of(0.0, density)
    materials = {"elastoplastic": MPM.ElastoPlastic(E=1e6, nu=0.2), "snow": MPM.Snow(E=1e6, nu=0.2),
                 "elastic": MPM.Elastic(E=1e6, nu=0.2)}
    spots = (-0.3, 0.0, 0.3)
    bodies, weights = {}, {}
    for (name, material), x in zip(materials.items(), spots):
        bodies[name] = scene.add_entity(gs.morphs.Box(pos=(x, 0.0, floor + 0.03 + BLOCK / 2), size=(BLOCK,) * 3),
                                        material=material, name=name)
        weights[name] = scene.add_entity(gs.morphs.Box(pos=(x, 0.0, floor + 0.03 + 1.5 * BLOCK), size=(BLOCK,) * 3),
                                         material=MPM.Elastic(E=1e6, nu=0.2, rho=2e4), name=f"weight_{name}")
    scene.build()
    layers = {}
    for name, body in bodies.items():
        p = pos(body)
        layers[name] = (p[:, 2] > p[:, 2].max() - 0.01, p[:, 2] < p[:, 2].min() + 0.01)

    def height(name):
        p = pos(bodies[name])
        top, bottom = layers[name]
        return p[top, 2].mean() - p[bottom, 2].mean()

    start = {name: height(name) for name in bodies}
    load_steps, window = int(round(LOAD_TIME / DT)), 50
    loaded = {name: 0.0 for name in bodies}
    for i in range(load_steps):
        scene.step()
        if i >= load_steps - window:
            for name in bodies:
                loaded[name] += height(name) / window
    for weight, x in zip(weights.values(), spots):  # lay each weight down on the floor, clear of the blocks
        weight.set_particles_pos(torch.tensor(_lay_down(pos(weight), x, -0.25, floor)))
    relax_steps = int(round(RELAX_TIME / DT))
    relaxed = {name: 0.0 for name in bodies}
    for i in range(relax_steps):
        scene.step()
        if i >= relax_steps - window:
            for name in bodies:
                relaxed[name] += height(name) / window
    out = {}
    for name, body in bodies.items():
        state = body.get_state()
        volume = (torch.linalg.det(state.F) * (state.Jp if name == "snow" else 1.0)).mean().item()
        out[name] = ((1.0, loaded[name] / start[name], relaxed[name] / start[name]), volume, state.Jp.mean().item(),
                     bool(np.isfinite(pos(body)).all()))
    for name, ((_, h_load, h_end), volume, jp, _) in out.items():
        print(f"\nload {name}: height ×{h_load:.3f} under the weight, ×{h_end:.3f} 0.4 s after its removal; "
              f"volume ratio (det F{' · Jp' if name == 'snow' else ''}) {volume:.3f}; mean Jp {jp:.3f}", end="")
    return out


def _lay_down(points, x, y, floor):
    """The weight's particles (n, 3) turned on their side (z ↔ y) and set on the floor at (x, y)."""
    local = points - points.mean(0)
    local = local[:, [0, 2, 1]]
    return local + np.array([x, y, floor + 0.03 - local[:, 2].min()])


def test_elastoplastic_block_stays_deformed_after_load(pressed):
    """The von Mises block keeps its compression (elastic spring-back ≈ yield / E = 1 %), while the
    elastic control, loaded the same way, recovers its height."""
    (_, loaded, relaxed), _, _, finite = pressed["elastoplastic"]
    (_, loaded_el, relaxed_el), _, _, _ = pressed["elastic"]
    assert finite
    assert loaded < 0.9 and loaded_el < 0.99  # the load did compress both
    assert relaxed < 0.9  # stays deformed
    assert relaxed_el > 0.97  # the control springs back: the deformation left is plasticity


def test_snow_compresses_and_stays_compressed(pressed):
    """Snow under the weight loses height and keeps the loss after the weight is gone (the elastic control
    recovers). Unconfined, its volume is not asserted: Genesis's snow clamps lateral stretch at
    1 + 4.5e-3, so a free block flows sideways and its Jp (plastic volume) can grow (printed)."""
    (_, loaded, relaxed), volume, jp, finite = pressed["snow"]
    assert finite
    assert loaded < 0.9
    assert relaxed < 0.9
    assert pressed["elastic"][0][2] > 0.97


# -- muscle ---------------------------------------------------------------------------------------------------
def test_muscle_contracts_along_its_fibres(f64):
    """Three 12 cm Muscle blocks (Genesis's defaults: neo-Hookean, E 1e6 Pa, ν 0.2) without gravity: fibres
    along x with actuation +0.1, fibres along y with +0.1, fibres along x with −0.1. Genesis adds
    E·actu·(F d)(F d)ᵀ to the Kirchhoff stress: a positive actuation is a tension along d, which an
    unloaded body relieves by shortening along d (about actu·100 % strain at small strain), a negative one
    by lengthening. Length along an axis: mean coordinate of the particles of one half minus that of the
    other (halves fixed at the start), averaged over the last 0.1 s of 0.4 s."""
    density = 32
    scene = make_scene(density, (-0.5, -0.3, 0.0), (0.5, 0.3, 0.6), gravity=(0.0, 0.0, 0.0))
    cases = (("x+", (1.0, 0.0, 0.0), 0.1, -0.25), ("y+", (0.0, 1.0, 0.0), 0.1, 0.0),
             ("x-", (1.0, 0.0, 0.0), -0.1, 0.25))
    bodies = {name: scene.add_entity(gs.morphs.Box(pos=(x, 0.0, 0.3), size=(BLOCK,) * 3), material=MPM.Muscle(),
                                     name=f"muscle_{name}") for name, _, _, x in cases}
    scene.build()
    for name, direction, actu, _ in cases:
        bodies[name].set_muscle(muscle_direction=direction)
        bodies[name].set_actuation(actu)
    start = {name: pos(body) for name, body in bodies.items()}

    def lengths(name, p):
        p0 = start[name]
        out = []
        for axis in range(3):
            upper = p0[:, axis] > p0[:, axis].mean()
            out.append(p[upper, axis].mean() - p[~upper, axis].mean())
        return np.array(out)

    base = {name: lengths(name, start[name]) for name in bodies}
    acc = {name: np.zeros(3) for name in bodies}
    for i in range(200):
        scene.step()
        if i >= 150:
            for name, body in bodies.items():
                acc[name] += lengths(name, pos(body)) / 50
    strain = {name: acc[name] / base[name] - 1.0 for name in bodies}
    for name, _, actu, _ in cases:
        print(f"\nmuscle fibres {name[0]}, actu {actu:+}: strain x, y, z = {np.round(strain[name] * 100, 2)} %", end="")
    sx, sy, sn = strain["x+"], strain["y+"], strain["x-"]
    assert sx[0] < -0.03 and sx[0] < sx[1] - 0.03 and sx[0] < sx[2] - 0.03  # shortens along x, not across
    assert sy[1] < -0.03 and sy[1] < sy[0] - 0.03 and sy[1] < sy[2] - 0.03  # the fibre direction decides
    assert sn[0] > 0.03  # negative actuation lengthens


# -- grid resolution ---------------------------------------------------------------------------------------
RESOLUTION_MATERIALS = {
    "elastic": lambda: MPM.Elastic(E=1e5, nu=0.2), "elastoplastic": lambda: MPM.ElastoPlastic(),
    "snow": lambda: MPM.Snow(), "sand": lambda: MPM.Sand(friction_angle=30.0), "liquid": lambda: MPM.Liquid(),
    "muscle": lambda: MPM.Muscle(),
}
STIFF_ELASTIC = {"stiff elastic": lambda: MPM.Elastic(E=1e6, nu=0.2)}
DOMAIN = ((-1.6, -1.1), (1.6, 1.1))  # (x, y) of the lower and upper bounds: room for six bodies 1 m apart


def _com_trajectories(density, substeps, seconds, side=BLOCK, drop=0.1, names=tuple(RESOLUTION_MATERIALS),
                      domain=DOMAIN, ramp=0.0):
    """COM trajectories (steps + 1, 3) per material at ``density`` cells/m (particle_size Genesis's default
    0.64/density): each material a cube of ``side`` m, its bottom ``drop`` m above the floor wall, the
    cubes 1 m apart in one grid of ``domain``'s (x, y) extent (checked not to meet), or one alone at the
    centre; muscle actuated at 0.1 along x, from the start, or raised to it linearly over the first
    ``ramp`` s. Also the smallest gap between two bodies at the end (m; inf for one or beyond 10 cm)."""
    (x_low, y_low), (x_high, y_high) = domain
    scene = make_scene(density, (x_low, y_low, 0.0), (x_high, y_high, max(0.6, drop + side + 0.3)),
                       substeps=substeps)
    floor = floor_of(0.0, density)
    spots = [(x, y) for y in (-0.5, 0.5) for x in (-1.0, 0.0, 1.0)] if len(names) > 1 else [(0.0, 0.0)]
    bodies = {name: scene.add_entity(gs.morphs.Box(pos=(x, y, floor + drop + side / 2), size=(side,) * 3),
                                     material={**RESOLUTION_MATERIALS, **STIFF_ELASTIC}[name](), name=name)
              for name, (x, y) in zip(names, spots)}
    scene.build()
    if "muscle" in bodies:
        bodies["muscle"].set_muscle(muscle_direction=(1.0, 0.0, 0.0))
    tracks = {name: [pos(body).mean(0)] for name, body in bodies.items()}
    for step in range(int(round(seconds / DT))):
        if "muscle" in bodies and step * DT <= ramp + DT:
            bodies["muscle"].set_actuation(0.1 * min(1.0, step * DT / ramp) if ramp > 0.0 else 0.1)
        scene.step()
        for name, body in bodies.items():
            tracks[name].append(pos(body).mean(0))
    last = {name: pos(body) for name, body in bodies.items()}
    gap = min((_xy_gap(last[a], last[b]) for a in last for b in last if a < b), default=np.inf)
    return {name: np.array(t) - t[0] for name, t in tracks.items()}, gap


def _xy_gap(a, b, reach=0.1, chunk=256):
    """The smallest distance (m) in x, y (the larger of the two) between a particle of a (n, 3) and one of b
    (m, 3), or inf when none are within ``reach``: only the particles within reach of the other body's
    bounding box are compared, ``chunk`` at a time (two 110k-particle bodies in one comparison: 180 GB)."""
    def near(points, other):
        low, high = other[:, :2].min(0) - reach, other[:, :2].max(0) + reach
        return points[((points[:, :2] >= low) & (points[:, :2] <= high)).all(1), :2]
    a_near, b_near = near(a, b), near(b, a)
    if not len(b_near):
        return np.inf
    gap = min((np.abs(a_near[i:i + chunk, None] - b_near[None]).max(-1).min() for i in range(0, len(a_near), chunk)),
              default=np.inf)
    return gap if gap <= reach else np.inf


def _resolution_errors(seconds, densities=(32, 64), substeps=8, **bodies):
    """Each material at two grid densities (cells/m; particle_size following Genesis's default: 2 and
    1 cm at 32 and 64), the same substep h = 2 ms / substeps (within both stability bounds, so only
    space is refined). COM displacement from the start, error = max over time of |Δ_coarse(t) −
    Δ_fine(t)| / max over time |Δ_fine(t)|, per material; printed."""
    coarse_density, fine_density = densities
    coarse, gap_coarse = _com_trajectories(coarse_density, substeps, seconds, **bodies)
    fine, gap_fine = _com_trajectories(fine_density, substeps, seconds, **bodies)
    errors = {}
    for name in coarse:
        scale = np.linalg.norm(fine[name], axis=1).max()
        errors[name] = np.linalg.norm(coarse[name] - fine[name], axis=1).max() / scale
        print(f"\nresolution {name}: COM travel {scale:.4f} m; max |Δ{coarse_density} − Δ{fine_density}| = "
              f"{errors[name]:.1%} of it (final COM z: {coarse[name][-1, 2]:+.4f} vs {fine[name][-1, 2]:+.4f} m)",
              end="")
    print(f"\nsmallest gap between two bodies at the end: {gap_coarse:.3f} m ({coarse_density}), {gap_fine:.3f} m "
          f"({fine_density})")
    assert min(gap_coarse, gap_fine) > 0.0  # the liquid's thin front comes within 8 mm of a neighbour at 64 cells/m
    return errors


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="measured 0.4 s: sand, liquid within 4 %, elastoplastic and snow ~16 %, elastic "
                   "and muscle ~45 %: the floor carries a body ~1 dx above its wall (1.5 cm more at 32 than at 64 "
                   "cells/m, ~15 % of the 10 cm travel) and the coarse grid damps the rebound; Genesis's walls and "
                   "transfers (ours match Genesis to 1e-10), not a solver bug")
def test_com_trajectories_agree_across_grid_resolutions(f64):
    """12 cm cubes (3.8 cells across at 32 cells/m) dropped 10 cm, 0.4 s: fall, impact, spreading or
    bouncing. Pass: < 10 % for every material."""
    errors = _resolution_errors(0.4)
    assert max(errors.values()) < 0.10, errors


@pytest.mark.slow
def test_resolved_com_trajectories_agree_across_grid_resolutions(f64):
    """24 cm cubes (7.7 cells across at 32 cells/m) dropped 30 cm, 0.6 s: the floor's offset of ~1 dx
    (above) is ~5 % of the travel; the sand and the liquid, which spread over the floor (a few grains of
    sand splash 0.9 m at 64 cells/m), each in a grid of its own.
    Measured 2026-11-24: elastic (E 1e5) 5.4 %, elastoplastic 3.6 %, snow 5.5 %, sand 1.0 %, liquid
    3.6 % — asserted < 10 %. The stiffer bodies' rebounds converge more slowly in space: at 32 and 64
    cells/m Elastic(E=1e6) 12.4 %, Muscle() unactuated 10.6 %, actuated 18.7 %; see
    test_stiff_com_trajectories_agree_at_64_and_128_cells_per_metre for them."""
    for names in (("elastic", "elastoplastic", "snow"), ("sand",), ("liquid",)):
        errors = _resolution_errors(0.6, side=0.24, drop=0.3, names=names)
        assert max(errors.values()) < 0.10, errors


@pytest.mark.slow
def test_stiff_com_trajectories_agree_at_64_and_128_cells_per_metre(f64):
    """The stiff bodies of the test above, Elastic(E=1e6, nu=0.2) and Muscle() (E 1e6) actuated at 0.1
    along x, a grid step finer: 24 cm cubes dropped 30 cm, 0.6 s, at 64 and 128 cells/m (15.4 and 30.7
    cells across; 13 824 and 110 592 particles each), h = 1.25e-4 s. A coarse grid damps a stiff body's
    rebound (its apex 11 cm below the start at 32 cells/m, 5 cm at 64 and 128). Measured 2026-11-28:
    stiff elastic 2.7 %, muscle 2.8 % (the stiff elastic at 32 and 64 cells/m with this h: 25 %).
    Asserted < 10 %.
    The actuation is raised over the first 0.1 s, as a muscle is activated: switched on at once, it
    starts an undamped axial oscillation (~70 Hz: a 24 cm body at a wave speed of ~33 m/s) whose phase
    at the impact, 0.25 s later, decides how high the block rebounds; its frequency follows the grid, so
    that case's trajectories part by 45 % between 64 and 128 cells/m (with 16 or 32 substeps a step:
    not the time step)."""
    errors = _resolution_errors(0.6, densities=(64, 128), substeps=16, side=0.24, drop=0.3,
                                names=("stiff elastic", "muscle"), domain=((-1.4, -0.9), (0.4, -0.1)), ramp=0.1)
    assert max(errors.values()) < 0.10, errors


# -- mixed scene ---------------------------------------------------------------------------------------------
def _mixed_scene(density, seconds):
    """Elastic jelly, sand, water and snow in one 0.8 × 0.8 × 0.8 m grid: water and sand blocks side by
    side on the floor, a jelly cube dropped onto them and a snow ball onto the jelly and sand, so that
    they land on and splash into each other. Returns (all positions finite, all
    velocities finite, inside the walls, particle count, final positions)."""
    scene = make_scene(density, (-0.4, -0.4, 0.0), (0.4, 0.4, 0.8))
    floor = floor_of(0.0, density)
    bodies = [
        scene.add_entity(gs.morphs.Box(pos=(-0.05, -0.05, floor + 0.09), size=(0.16, 0.16, 0.16)),
                         material=MPM.Liquid(), name="water"),
        scene.add_entity(gs.morphs.Box(pos=(0.1, 0.1, floor + 0.09), size=(0.16, 0.16, 0.16)),
                         material=MPM.Sand(), name="sand"),
        scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, floor + 0.35), size=(0.12, 0.12, 0.12)),
                         material=MPM.Elastic(E=1e5, nu=0.2, model="neohooken"), name="jelly"),
        scene.add_entity(gs.morphs.Sphere(pos=(0.1, -0.1, floor + 0.5), radius=0.08),
                         material=MPM.Snow(), name="snow"),
    ]
    scene.build()
    lower, upper = gs.options.MPMOptions(lower_bound=(-0.4, -0.4, 0.0), upper_bound=(0.4, 0.4, 0.8),
                                         grid_density=density).wall_bounds()
    finite_pos = finite_vel = inside = True
    for step in range(int(round(seconds / DT))):
        scene.step()
        if step % 50 == 49:
            for body in bodies:
                p = pos(body)
                v = body.get_particles_vel().detach().cpu().numpy()
                finite_pos &= bool(np.isfinite(p).all())
                finite_vel &= bool(np.isfinite(v).all())
                inside &= bool(np.all(p >= lower - 1e-6) and np.all(p <= upper + 1e-6))
    return finite_pos, finite_vel, inside, sum(b.n_particles for b in bodies), {b.name: pos(b) for b in bodies}


def _check_mixed(density, precision):
    finite_pos, finite_vel, inside, n, final = _mixed_scene(density, 2.0)
    tops = {name: round(float(p[:, 2].max()), 3) for name, p in final.items()}
    print(f"\nmixed scene float{precision}, {density} cells/m, {n} particles, 2 s: positions finite {finite_pos}, "
          f"velocities finite {finite_vel}, inside the walls {inside}; highest particle per body {tops}")
    assert finite_pos and finite_vel and inside


def test_mixed_scene_float64(f64):
    _check_mixed(32, 64)


def test_mixed_scene_float32(f32):
    _check_mixed(32, 32)


@pytest.mark.slow
@pytest.mark.parametrize("precision", ["32", "64"])
def test_mixed_scene_fine_grid(precision):
    gs.init(precision=precision, logging_level="warning")
    _check_mixed(64, precision)
