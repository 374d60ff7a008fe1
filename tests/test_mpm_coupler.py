"""Rigid–MPM coupling with shapes of moving links, both ways (solvers/coupler.py): beside Genesis,
momentum exchanged exactly, batched as single envs; its gradients against finite differences."""
import json
import os
import runpy

import numpy as np
import pytest
import taichi as ti
import torch

import genesis_lite as gs
from genesis_lite.solvers.core import InvalidInputError
from genesis_lite.solvers.mpm import colliders as C
from genesis_lite.solvers.mpm import layout

from .fd_scan import assert_converged, checked_gradient, directional_errors

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


# every test in float64 unless it asks for f32 (conftest's fixtures, per test: conftest runs the
# float32 tests first, and a module-scoped init left the module's later tests in float32)
pytestmark = pytest.mark.usefixtures("f64")


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


# -- gradients ----------------------------------------------------------------------------------

@ti.kernel
def _normals(table: ti.types.ndarray(), points: ti.types.ndarray(), out: ti.types.ndarray()):
    """out (P, 13) ← (d, n (3), ∂n/∂p (9, row-major)) of the shape of the row at table[0] at each of
    points (P, 3), in its frame."""
    for i in range(points.shape[0]):
        p = ti.Vector([points[i, 0], points[i, 1], points[i, 2]])
        d, n = C.shape_distance(table, 0, p)
        J = C.normal_jacobian(table, 0, p, d, n)
        out[i, 0] = d
        for a in ti.static(range(3)):
            out[i, 1 + a] = n[a]
            for b in ti.static(range(3)):
                out[i, 4 + 3 * a + b] = J[a, b]


def _normals_of(row, data, points):
    table = torch.as_tensor(C.packed([row], data, at=0))
    out = torch.zeros(len(points), 13, dtype=torch.float64)
    _normals(table, torch.as_tensor(points), out)
    return out.numpy()


# each kind in its frame (pose unused here): size, data (a hull's planes, a height field's grid)
_CUBE = np.array([[1, 0, 0, -0.03], [-1, 0, 0, -0.03], [0, 1, 0, -0.02], [0, -1, 0, -0.02], [0, 0, 1, -0.01],
                  [0, 0, -1, -0.01]], dtype=np.float64)
KINDS = {"plane": (C.PLANE, (0, 0, 0), ()), "sphere": (C.SPHERE, (0.03, 0, 0), ()),
         "capsule": (C.CAPSULE, (0.02, 0.03, 0), ()), "cylinder": (C.CYLINDER, (0.03, 0.02, 0), ()),
         "box": (C.BOX, (0.03, 0.02, 0.01), ()), "hull": (C.HULL, (0, 6, 0), _CUBE.ravel()),
         "hfield": (C.HFIELD, (0, 0, 0), np.array([0.05, 0.04, 3, 4, *np.random.default_rng(2).random(12) * 0.02]))}


@pytest.mark.parametrize("kind", list(KINDS))
def test_the_normal_jacobian_is_the_normal_s_derivative(kind):
    """colliders.normal_jacobian against central differences of the shape's normal, at 2000 points
    around each kind where the normal is smooth (both step sizes agree: not across a region's
    border); the distance's own gradient is the normal."""
    code, size, data = KINDS[kind]
    row = [code, 0, 0, 0, *np.eye(3).ravel(), *size, layout.COUPLING_AT, 1.0]
    points = np.random.default_rng(1).uniform(-0.06, 0.06, (2000, 3))
    at = _normals_of(row, data, points)
    h = 1e-6
    steps = [_normals_of(row, data, points + sign * h * axis) for axis in np.eye(3) for sign in (1, -1)]
    normal_fd = np.stack([(steps[2 * k][:, 1:4] - steps[2 * k + 1][:, 1:4]) / (2 * h) for k in range(3)], axis=2)
    distance_fd = np.stack([(steps[2 * k][:, 0] - steps[2 * k + 1][:, 0]) / (2 * h) for k in range(3)], axis=1)
    half = [_normals_of(row, data, points + sign * h / 2 * axis) for axis in np.eye(3) for sign in (1, -1)]
    normal_half = np.stack([(half[2 * k][:, 1:4] - half[2 * k + 1][:, 1:4]) / h for k in range(3)], axis=2)
    # (a height field beside its rectangle is far: no distance to check there)
    smooth = (np.abs(normal_fd - normal_half).max(axis=(1, 2)) < 1e-6) & (at[:, 0] < C.FAR)
    assert smooth.mean() > 0.5
    np.testing.assert_allclose(at[smooth, 4:].reshape(-1, 3, 3), normal_fd[smooth], atol=1e-6)
    np.testing.assert_allclose(at[smooth, 1:4], distance_fd[smooth], atol=1e-6)


@ti.kernel
def _respond_both(v: ti.types.ndarray(), n: ti.types.ndarray(), w: ti.f64, mu: ti.f64, e: ti.f64,
                  g: ti.types.ndarray(), out: ti.types.ndarray()):
    """out (10,) ← respond(v, n, w, μ, e)·g, then respond_adjoint's (∂/∂v (3), ∂/∂n (3), ∂/∂w, ∂/∂μ,
    ∂/∂e) of it."""
    for _ in range(1):
        V, N, G = ti.Vector([v[0], v[1], v[2]]), ti.Vector([n[0], n[1], n[2]]), ti.Vector([g[0], g[1], g[2]])
        out[0] = C.respond(V, N, w, mu, e).dot(G)
        g_v, g_n, g_w, g_mu, g_e = C.respond_adjoint(V, N, w, mu, e, G)
        for a in ti.static(range(3)):
            out[1 + a] = g_v[a]
            out[4 + a] = g_n[a]
        out[7], out[8], out[9] = g_w, g_mu, g_e


@pytest.mark.parametrize("mu, restitution", [(0.3, 0.0), (0.05, 0.4), (3.0, 0.2)])
def test_respond_adjoint_is_the_rule_s_derivative(mu, restitution):
    """colliders.respond_adjoint (in the velocity, the normal, the influence, the friction and the
    restitution) against central differences, sliding (μ small) and stopped (μ large), at random
    velocities into the shape."""
    rng = np.random.default_rng(4)
    for _ in range(20):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        v = rng.normal(size=3) - 1.5 * n
        w, g = rng.uniform(0.2, 1.0), rng.normal(size=3)

        def value(v, n, w, mu=mu, restitution=restitution):
            out = torch.zeros(10, dtype=torch.float64)
            _respond_both(torch.as_tensor(v), torch.as_tensor(n), w, mu, restitution, torch.as_tensor(g), out)
            return out.numpy()

        exact, h = value(v, n, w), 1e-6
        numeric = [(value(v + h * a, n, w)[0] - value(v - h * a, n, w)[0]) / (2 * h) for a in np.eye(3)]
        numeric += [(value(v, n + h * a, w)[0] - value(v, n - h * a, w)[0]) / (2 * h) for a in np.eye(3)]
        numeric += [(value(v, n, w + h)[0] - value(v, n, w - h)[0]) / (2 * h)]
        numeric += [(value(v, n, w, mu=mu + h)[0] - value(v, n, w, mu=mu - h)[0]) / (2 * h)]
        numeric += [(value(v, n, w, restitution=restitution + h)[0] - value(v, n, w, restitution=restitution - h)[0])
                    / (2 * h)]
        np.testing.assert_allclose(exact[1:10], numeric, atol=1e-7)


def _drop_scene(body, n_envs=0):
    """Differentiable, float64: a jelly block on a coupled plane and the rigid body ``body`` (morph,
    material) above it, 32 cells/m, dt 2 ms in 4 substeps; returns (scene, block, body)."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=2e-3, substeps=4, requires_grad=True),
                     mpm_options=gs.options.MPMOptions(lower_bound=(-0.5, -0.5, -0.2), upper_bound=(0.5, 0.5, 0.6),
                                                       grid_density=32))
    scene.add_entity(gs.morphs.Plane(), material=gs.materials.Rigid(coup_friction=0.5))
    block = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.06), size=(0.12, 0.12, 0.08)),
                             material=gs.materials.MPM.Elastic(E=3e4))
    rigid = scene.add_entity(*body)
    scene.build(n_envs=n_envs)
    return scene, block, rigid


BODIES = {
    "box": (gs.morphs.Box(pos=(0.02, 0.0, 0.14), size=(0.06, 0.05, 0.04), euler=(10, 5, 20)),
            gs.materials.Rigid(rho=400, coup_friction=0.3, coup_softness=0.004)),
    "tumbler": (gs.morphs.MJCF(file=os.path.join(ROOT, "assets", "mjcf", "tumbler.xml"), pos=(0.0, 0.0, -0.12)),
                gs.materials.Rigid(coup_friction=0.3, coup_softness=0.004)),
}
STEPS = 30


@pytest.mark.parametrize("body", list(BODIES))
def test_gradients_through_moving_shapes_match_fd(body):
    """A free box, and a free hub whose hinged arm turns (capsule, sphere; shapes on a floating root
    and the link below it), land on the jelly block: the gradient of a loss on both (particle heights,
    the body's dofs) in the body's initial dof velocities and in the particles' initial velocities,
    against central differences (eps scans; each converged to 1e-5), bit-identical when repeated."""
    scene, block, rigid = _drop_scene(BODIES[body])
    start = torch.tensor([0.3, 0.1, -0.8, 1.0, 2.0, 4.0, 2.0][:rigid.n_dofs], dtype=torch.float64)
    weights = torch.linspace(0.5, 1.5, block.n_particles, dtype=torch.float64)

    def rollout(dofs_velocity, particle_velocity=None):
        scene.reset()
        if particle_velocity is not None:
            block.set_particles_vel(particle_velocity)
        rigid.set_dofs_velocity(dofs_velocity)
        for _ in range(STEPS):
            scene.step()
        return (block.get_particles_pos()[:, 2] * weights).sum() + 10 * rigid.get_dofs_position().sum()

    checked_gradient(rollout, start, f"{body}: the body's initial dof velocities")
    particles = torch.tensor([0.1, 0.0, -0.3], dtype=torch.float64).repeat(block.n_particles, 1)
    assert_converged(directional_errors(lambda v: rollout(start, v), particles), f"{body}: particle velocities")
    assert float(rigid.get_dofs_velocity()[2]) > -0.5  # (it met the block: slowed from −0.8 m/s and more)


def test_gradients_of_a_pendulum_swinging_into_the_block_match_fd():
    """The pendulum (a hinge) released so that its bob sweeps through the jelly, which stands on the
    domain's floor wall (the walls after the coupler): the block's centre and the swing's angle in
    the initial angle and the jelly's Young's modulus, against central differences."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=2e-3, substeps=4, requires_grad=True),
                     mpm_options=gs.options.MPMOptions(lower_bound=(-0.5, -0.5, -0.04), upper_bound=(0.5, 0.5, 0.6),
                                                       grid_density=32))
    block = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.1), size=(0.12, 0.12, 0.08)),
                             material=gs.materials.MPM.Elastic(E=3e4))
    arm = scene.add_entity(gs.morphs.MJCF(file=os.path.join(ROOT, "assets", "mjcf", "pendulum_bob.xml")),
                           material=gs.materials.Rigid(coup_friction=0.2, coup_softness=0.004))
    scene.build()

    def rollout(angle, E=None):
        scene.reset()
        arm.set_dofs_position(angle)
        arm.set_dofs_velocity(torch.tensor([-3.0], dtype=torch.float64))
        if E is not None:
            block.set_material_params(E=E)
        for _ in range(STEPS):
            scene.step()
        return block.get_particles_pos()[:, 0].mean() * 10 + arm.get_dofs_position().sum()

    angle = torch.tensor([0.35], dtype=torch.float64)
    checked_gradient(rollout, angle, "pendulum: its initial angle")
    assert_converged(directional_errors(lambda E: rollout(angle, E), torch.tensor(3e4, dtype=torch.float64),
                                        eps=(1e-1, 1e-2, 1e-3, 1e-4)), "pendulum: Young's modulus")


def test_gradients_of_a_servoed_blade_pushing_sand_match_fd():
    """examples/sand_push.py's chain, short: a blade on an x–y carriage (two slide joints; position
    servos) pushes a sand pile (Drucker–Prager, plastic) over a coupled plane; the sand's centre and
    the carriage's dofs in the servo targets (held over the rollout), against central differences,
    bit-identical when repeated; the blade moved the sand."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=2e-3, substeps=5, requires_grad=True),
                     mpm_options=gs.options.MPMOptions(lower_bound=(-0.3, -0.3, -0.1), upper_bound=(0.5, 0.3, 0.3),
                                                       grid_density=40, particle_size=0.0125))
    scene.add_entity(gs.morphs.Plane(), material=gs.materials.Rigid(coup_friction=0.5))
    paddle = scene.add_entity(gs.morphs.MJCF(file=os.path.join(ROOT, "assets", "mjcf", "paddle.xml"),
                                             pos=(-0.08, 0.0, 0.0)), material=gs.materials.Rigid(coup_friction=0.3))
    sand = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.035), size=(0.1, 0.1, 0.06)),
                            material=gs.materials.MPM.Sand(friction_angle=30.0))
    scene.build()
    paddle.set_dofs_kp(torch.tensor([2000.0, 2000.0], dtype=torch.float64))
    paddle.set_dofs_kv(torch.tensor([90.0, 90.0], dtype=torch.float64))

    def rollout(servo_target):
        scene.reset()
        for _ in range(STEPS):
            paddle.control_dofs_position(servo_target)
            scene.step()
        centre = sand.get_particles_pos().mean(dim=0)
        return 10 * (centre[0] + 2 * centre[1]) + paddle.get_dofs_position().sum()

    target = torch.tensor([0.12, 0.03], dtype=torch.float64)
    with torch.no_grad():
        rollout(target)
    assert float(sand.get_particles_pos()[:, 0].mean()) > 5e-3  # (pushed: its centre starts at 0)
    checked_gradient(rollout, target, "sand push: the servo targets")


COUPLING_SIZES = torch.tensor([1.0, 0.01, 1.0], dtype=torch.float64)  # of (μ, ς m, e): the FD directions' scales


def test_gradients_in_the_coupling_parameters_match_fd():
    """The box landing on the jelly (a shape of a moving link: the coupler) and the plane under the
    jelly, which is thrown along it (a shape at rest: the MPM grid update; its softness reaching
    the nodes above it): the loss in each one's coupling friction, softness and restitution
    (set_coupling), against central differences, bit-identical when repeated; each of the six
    has a gradient."""
    scene, block, box = _drop_scene(BODIES["box"])
    plane = scene.entities[0]
    start = torch.tensor([0.3, 0.1, -0.8, 1.0, 2.0, 4.0], dtype=torch.float64)
    weights = torch.linspace(0.5, 1.5, block.n_particles, dtype=torch.float64)

    def rollout(scaled):  # (6,): the box's (μ, ς, e), then the plane's, each over its size
        scene.reset()
        box.set_coupling(*(scaled[:3] * COUPLING_SIZES))
        plane.set_coupling(*(scaled[3:] * COUPLING_SIZES))
        box.set_dofs_velocity(start)
        block.set_particles_vel(torch.tensor([0.5, 0.2, -0.3], dtype=torch.float64).repeat(block.n_particles, 1))
        for _ in range(STEPS):
            scene.step()
        return (block.get_particles_pos() * weights[:, None]).sum() + 10 * box.get_dofs_position().sum()

    value = torch.tensor([0.3, 0.4, 0.2, 0.5, 2.0, 0.1], dtype=torch.float64)
    grad = checked_gradient(rollout, value, "coupling parameters of a moving box and a plane at rest")
    assert (grad.abs() > 1e-3 * grad.abs().max()).all(), grad


def _landing(n_envs, material, box_coupling=None):
    """The box of BODIES, of ``material``, landing on the jelly, 20 steps; its coupling the material's
    or set per env (box_coupling: friction, softness, restitution, each (n_envs,)): (particles,
    box dofs)."""
    scene, block, box = _drop_scene((BODIES["box"][0], material), n_envs=n_envs)
    if box_coupling is not None:
        box.set_coupling(*box_coupling)
    box.set_dofs_velocity(torch.tensor([0.3, 0.1, -0.8, 1.0, 2.0, 4.0], dtype=torch.float64))
    for _ in range(20):
        scene.step()
    return block.get_particles_pos(), box.get_dofs_position()


def test_set_coupling_per_env_is_the_material_s_coupling():
    """Two envs given two couplings by set_coupling: env 0 has the bits of a scene whose material
    holds its values, env 1 those of the material's own (BODIES["box"]), and they differ."""
    material = BODIES["box"][1]
    other = (0.8, 0.01, 0.4)
    own = (material.coup_friction, material.coup_softness, material.coup_restitution)
    batched = _landing(2, material, [torch.tensor(pair, dtype=torch.float64) for pair in zip(other, own)])
    given = _landing(0, gs.materials.Rigid(rho=400, coup_friction=other[0], coup_softness=other[1],
                                           coup_restitution=other[2]))
    built = _landing(0, material)
    for k in range(2):
        assert torch.equal(batched[k][0], given[k]) and torch.equal(batched[k][1], built[k])
    assert not torch.equal(given[0], built[0])


def test_coupling_setters_refuse_what_they_cannot_take():
    scene, block, box = _drop_scene(BODIES["box"])
    loose = gs.Scene()
    ball = loose.add_entity(gs.morphs.Sphere(radius=0.1))
    loose.build()
    with pytest.raises(InvalidInputError, match="set_coupling: its shapes meet no MPM particles"):
        ball.set_coupling(friction=0.2)
    with pytest.raises(gs.SceneStateError, match="build"):
        gs.Scene().add_entity(gs.morphs.Sphere(radius=0.1)).set_coupling(friction=0.2)
    for options, morph, said in ((gs.options.LegacyCouplerOptions(rigid_mpm=False), gs.morphs.Plane(), "rigid_mpm=False"),
                                 (None, gs.morphs.Box(size=(0.1, 0.1, 0.1), fixed=True, collision=False),
                                  "0 colliding shape")):
        uncoupled = gs.Scene(coupler_options=options)
        shape = uncoupled.add_entity(morph)
        uncoupled.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.2), size=(0.05, 0.05, 0.05)),
                             material=gs.materials.MPM.Elastic())
        uncoupled.build()
        with pytest.raises(InvalidInputError, match=f"get_coupling: its shapes meet no MPM particles.*{said}"):
            shape.get_coupling()
    for arg, value, expected in (("friction", -0.1, ">= 0"), ("softness", float("nan"), "finite"),
                                 ("restitution", 1.5, r"in \[0, 1\]")):
        with pytest.raises(InvalidInputError, match=f"argument '{arg}' must be .*{expected}"):
            box.set_coupling(**{arg: value})
    with pytest.raises(InvalidInputError, match="argument 'friction' must have shape"):
        box.set_coupling(friction=[0.1, 0.2])
    with pytest.raises(InvalidInputError, match="argument 'restitution' must be in"):  # (nothing written)
        box.set_coupling(friction=0.6, restitution=2.0)
    np.testing.assert_allclose(box.get_coupling().numpy(), [0.3, 0.004, 0.0])
    box.set_coupling(restitution=0.3)
    scene.reset()  # (a parameter: kept)
    np.testing.assert_allclose(box.get_coupling().numpy(), [0.3, 0.004, 0.3])
    scene, block, box = _drop_scene(BODIES["box"], n_envs=3)
    box.set_coupling(friction=torch.tensor([0.5, 0.7], dtype=torch.float64), envs_idx=[2, 0])
    np.testing.assert_allclose(box.get_coupling(envs_idx=[0, 2])[:, 0].numpy(), [0.7, 0.5])
    np.testing.assert_allclose(box.get_coupling()[:, 0].numpy(), [0.7, 0.3, 0.5])


def test_batched_gradients_equal_single_scenes_bit_for_bit():
    """Two envs dropped differently, the box's coupling friction differing too: each env's gradients
    (in the box's initial velocity and its friction) have the bits of its own single-env scene."""
    starts = torch.tensor([[0.3, 0.1, -0.8, 1.0, 2.0, 4.0], [0.1, -0.2, -0.6, -2.0, 0.5, 1.0]], dtype=torch.float64)
    frictions = torch.tensor([0.3, 0.6], dtype=torch.float64)

    def gradients(scene, block, rigid, start, friction):
        v, mu = start.clone().requires_grad_(True), friction.clone().requires_grad_(True)
        rigid.set_dofs_velocity(v)
        rigid.set_coupling(friction=mu)
        for _ in range(20):
            scene.step()
        (block.get_particles_pos()[..., 2].sum() + rigid.get_dofs_position().sum()).backward()
        return v.grad, mu.grad

    batched = gradients(*_drop_scene(BODIES["box"], n_envs=2), starts, frictions)
    for e in range(2):
        single = gradients(*_drop_scene(BODIES["box"]), starts[e], frictions[e])
        assert torch.equal(batched[0][e], single[0]) and torch.equal(batched[1][e], single[1])
    assert not torch.equal(batched[0][0], batched[0][1]) and (batched[1] != 0).all()


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


def test_a_saved_grid_grown_in_the_replay_keeps_the_gradient():
    """A replay that lists more grid nodes than the saved grid holds grows it and takes the shared
    loop's replay again (the coupler's shapes move with the rigid solver): the gradient keeps its bits
    (against a scene whose saved grid was large from the start)."""
    grads, capacities = [], []
    for capacity in (4, None):
        scene, block, rigid = _drop_scene(BODIES["box"])
        if capacity:
            scene.mpm_solver.set_saved_grid_capacity(capacity)
        v = torch.tensor([0.3, 0.1, -0.8, 1.0, 2.0, 4.0], dtype=torch.float64, requires_grad=True)
        rigid.set_dofs_velocity(v)
        for _ in range(20):
            scene.step()
        (block.get_particles_pos()[:, 2].sum() + rigid.get_dofs_position().sum()).backward()
        grads.append(v.grad)
        capacities.append(scene.mpm_solver.saved_grid.shape[2])
    assert capacities[0] > 4 and torch.equal(grads[0], grads[1])


def test_a_refused_backward_leaves_the_next_steps_as_they_were():
    """A backward the rigid solver refuses (a MuJoCo-compatible curved contact: a can tilted on its
    rim, coupled, beside a falling jelly) raises before any solver's reverse stage runs: the steps
    after it move the particles as a scene that never tried (a half-run MPM reverse left its grid
    filled, which the next scatter added to)."""
    def scene_of():
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True),
                         rigid_options=gs.options.RigidOptions(enable_mujoco_compatibility=True),
                         mpm_options=gs.options.MPMOptions(lower_bound=(-0.5, -0.5, -0.2), upper_bound=(0.5, 0.5, 0.6),
                                                           grid_density=16))
        scene.add_entity(gs.morphs.Box(size=(1.0, 1.0, 0.2), pos=(0, 0, -0.1), fixed=True))
        can = scene.add_entity(gs.morphs.Cylinder(radius=0.05, height=0.2, euler=(np.degrees(0.3), 0, 0),
                                                  pos=(0, 0, 0.1 * np.cos(0.3) + 0.05 * np.sin(0.3) - 1e-3)))
        jelly = scene.add_entity(gs.morphs.Box(pos=(0.25, 0.25, 0.3), size=(0.1, 0.1, 0.1)),
                                 material=gs.materials.MPM.Elastic(E=3e4))
        scene.build()
        return scene, can, jelly

    tried, untouched = scene_of(), scene_of()
    for scene, can, _ in (tried, untouched):
        can.set_dofs_velocity(torch.zeros(6, dtype=torch.float64, requires_grad=True))
        scene.step()
    with pytest.raises(gs.GradientError, match="enable_mujoco_compatibility"):
        (tried[1].get_pos().sum() + tried[2].get_particles_pos().sum()).backward()
    for _ in range(5):
        for scene, _, _ in (tried, untouched):
            scene.step()
    assert torch.equal(tried[2].get_particles_pos(), untouched[2].get_particles_pos())


class _Interrupt(Exception):
    """What a Ctrl-C between two launches would raise (KeyboardInterrupt stands in badly: pytest stops)."""


@pytest.mark.parametrize("where", ["couple", "couple_backward", "mpm alone: between its reverse launches"])
def test_an_interrupted_step_or_backward_leaves_the_next_rollout_as_a_fresh_scene_s(where, monkeypatch):
    """A step or backward stopped between two launches (an error, Ctrl-C) with the MPM grid's nodes
    listed: between the grid update and the coupler, between the coupler's reverse and the grid
    update's, or, MPM alone, between a substep's two reverse launches. The next rollout (after
    reset) moves the particles and takes the gradient as a scene that was never stopped (the nodes
    a stopped launch left would be added to by the next scatter)."""
    alone = where.startswith("mpm alone")

    def scene_of():
        if alone:
            scene = gs.Scene(sim_options=gs.options.SimOptions(dt=2e-3, substeps=4, requires_grad=True),
                             mpm_options=gs.options.MPMOptions(lower_bound=(-0.5, -0.5, -0.2),
                                                               upper_bound=(0.5, 0.5, 0.6), grid_density=32))
            block = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.06), size=(0.12, 0.12, 0.08)),
                                     material=gs.materials.MPM.Elastic(E=3e4))
            scene.build()
            return scene, block, None
        return _drop_scene(BODIES["box"])

    def rollout(scene, block, rigid):
        scene.reset()
        v = torch.tensor([0.3, 0.1, -0.8], dtype=torch.float64, requires_grad=True)
        block.set_velocity(v)
        if rigid is not None:
            rigid.set_dofs_velocity(torch.tensor([0.3, 0.1, -0.8, 1.0, 2.0, 4.0], dtype=torch.float64))
        for _ in range(12):
            scene.step()
        (block.get_particles_pos()[:, 2].sum() + (0 if rigid is None else rigid.get_dofs_position().sum())).backward()
        return block.get_particles_pos().detach(), v.grad

    stopped, fresh = scene_of(), scene_of()
    target = stopped[0].mpm_solver if alone else stopped[0].sim.coupler
    method = "substep_pre_coupling_backward" if alone else where
    calls = iter(range(1000))

    def stop_once(original):
        def wrapped(s):
            if next(calls) == 5:  # (once, mid-rollout: its nodes are listed)
                raise _Interrupt
            return original(s)
        return wrapped

    monkeypatch.setattr(target, method, stop_once(getattr(target, method)))
    with pytest.raises(_Interrupt):
        rollout(*stopped)
    for a, b in zip(rollout(*stopped), rollout(*fresh)):
        assert torch.equal(a, b)
