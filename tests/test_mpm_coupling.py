"""Rigid–MPM coupling with rigid shapes at rest (solvers/mpm/colliders.py, solvers/coupling.py):
the particles meet the primitive shapes of links fixed to the world by Genesis's rule.

Checked against references no one here wrote: Genesis 1.4.5 moves the particles the same (its
positions stored by bench/coupling.py); a plane without friction or softness is the MPM
walls' slip boundary (Genesis's and ours), bit for bit up to round-off; a block on an incline
slides with Coulomb's acceleration g (sin θ − μ cos θ) or sticks where μ > tan θ; particles dropped
on each primitive end outside it (trimesh's signed distance). Gradients: float64 central finite
differences through every shape, with friction, restitution and partial influence, and the bits
of a repeated or batched rollout.
"""
import json
import os
import runpy

import numpy as np
import pytest
import taichi as ti
import torch
import trimesh

import genesis_lite as gs
from genesis_lite.solvers.core import InvalidInputError
from genesis_lite.solvers.mpm import colliders as C
from genesis_lite.solvers.mpm import layout
from genesis_lite.solvers.rigid.collision import hfield
from genesis_lite.solvers.rigid.shapes import quat_to_mat

from .fd_scan import checked_gradient
from .test_mpm_gradients import Rollout, assert_bitwise_reproducible, check_all

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


# every test in float64 unless it asks for f32 (conftest's fixtures, per test: conftest runs the
# float32 tests first, and a module-scoped init left the module's later tests in float32)
pytestmark = pytest.mark.usefixtures("f64")


def rotation(axis, degrees):
    """(3, 3) rotation about the unit axis (3,) by degrees."""
    axis = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    a = np.radians(degrees)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K


def collider(kind, pos, rot, size, entity=0, bound=np.inf):
    """A collider row (solvers/mpm/colliders.py) of rigid entity number ``entity`` (whose coupling
    parameters it takes: Rollout's couplings); bound: its bounding radius, m (inf: every node takes
    its distance)."""
    return [kind, *pos, *np.asarray(rot).ravel(), *size, layout.COUPLING_AT + layout.coupling_columns(entity)[0], bound]


COUPLING = (0.3, 0.002, 0.2)  # (μ, ς m, e) of the shapes' entity unless a test says otherwise


# under the gradient tests' block (x, y in ±4 cm, z from 10.4 to 18.4 cm, floor wall at 9.4 cm),
# thrown down at 3 m/s: each shape turned off the grid's axes, reached in the 20 steps
SHAPES = {
    "plane": collider(C.PLANE, (0.0, 0.0, 0.1), rotation((1, 2, 0), 15), (0, 0, 0)),
    "sphere": collider(C.SPHERE, (0.01, -0.005, 0.07), np.eye(3), (0.035, 0, 0)),
    "capsule": collider(C.CAPSULE, (0.0, 0.0, 0.085), rotation((0, 1, 0.3), 80), (0.015, 0.03, 0)),
    "cylinder": collider(C.CYLINDER, (0.0, 0.01, 0.08), rotation((1, 0, 0.2), 70), (0.02, 0.04, 0)),
    "box": collider(C.BOX, (0.0, 0.0, 0.08), rotation((1, 0.5, 0.2), 10), (0.05, 0.03, 0.02)),
}


def hull_planes(vertices):
    """(F, 4): the planes (outward unit normal, offset m) of the triangles of the convex hull of
    ``vertices`` (V, 3) (trimesh's), as colliders.py's HULL data."""
    hull = trimesh.convex.convex_hull(vertices)
    return np.column_stack([hull.face_normals, -np.einsum("ij,ij->i", hull.face_normals, hull.triangles[:, 0])])


# a convex hull of 12 random points (its faces' planes, in its frame), turned and lowered under the block
HULL_PLANES = hull_planes(np.random.default_rng(7).normal(size=(12, 3)) * [0.05, 0.04, 0.02])
SHAPES["hull"] = collider(C.HULL, (0.0, 0.0, 0.08), rotation((0.3, 1, 0.1), 20), (0, len(HULL_PLANES), 0))


# a 6 × 5 height field 24 × 16 cm (its data: size x, size y, nrow, ncol, heights), turned, under the block
HFIELD_DATA = np.array([0.12, 0.08, 6, 5, *(0.03 * np.random.default_rng(8).random(30))])
SHAPES["hfield"] = collider(C.HFIELD, (0.0, 0.0, 0.06), rotation((0.2, 1, 0), 10), (0, 0, 0))


@pytest.mark.parametrize("shape", list(SHAPES))
def test_gradients_through_each_shape_match_fd(shape):
    planes = {"hull": HULL_PLANES, "hfield": HFIELD_DATA}.get(shape, ())
    rollout = Rollout("neohooken", {}, 0, "generic", seed=2, throw=(0.0, 0.0, -3.0), colliders=[SHAPES[shape]],
                      planes=planes, couplings=[COUPLING])
    free = Rollout("neohooken", {}, 0, "generic", seed=2, throw=(0.0, 0.0, -3.0))
    met = rollout.run(rollout.state, rollout.inputs)[0] - free.run(free.state, free.inputs)[0]
    assert abs(met) > 1.0, f"{shape}: the block must meet the shape (loss changed by {met})"
    check_all(rollout, rollout.gradients(), shape, per_particle_only=True)


# (μ, ς, e) and which of them are checked: a sharp surface (ς = 0) has no gradient in ς (its
# influence is a step); with μ = 2, e = 0 the friction stops nodes dead beyond the floor's wall,
# where the wall's kink at zero velocity makes e's one-sided derivatives differ (a restitution
# just above 0 starts them moving inwards)
@pytest.mark.parametrize("friction, softness, restitution, checked", [(0.0, 0.0, 0.0, (0, 2)), (2.0, 0.01, 0.0, (0, 1)),
                                                                      (0.5, 0.0, 1.0, (0, 2))])
def test_gradients_with_other_coupling_parameters_match_fd(friction, softness, restitution, checked):
    """No friction and a sharp surface; high friction with a wide softness (nodes outside the
    shapes partly influenced); a full bounce: with a plane and a box crossing it."""
    shapes = [collider(C.PLANE, (0.0, 0.0, 0.1), rotation((1, 2, 0), 15), (0, 0, 0)),
              collider(C.BOX, (0.02, 0.0, 0.1), rotation((0, 0, 1), 30), (0.02, 0.02, 0.02))]
    rollout = Rollout("neohooken", {}, 0, "generic", seed=3, throw=(0.0, 0.0, -3.0), colliders=shapes,
                      couplings=[(friction, softness, restitution)])
    check_all(rollout, rollout.gradients(), f"μ={friction} ς={softness} e={restitution}", per_particle_only=True,
              coupling_params=checked)


def test_gradients_with_colliders_are_bitwise_reproducible_and_batched_as_single():
    assert_bitwise_reproducible(throw=(0.0, 0.0, -3.0), colliders=[SHAPES["plane"], SHAPES["box"]],
                                couplings=[COUPLING])


# -- the shapes' signed distances and poses ------------------------------------------------------

@ti.kernel
def distances(grid_f: ti.types.ndarray(), points: ti.types.ndarray(), out: ti.types.ndarray()):
    """out (P, 4) ← (d, n) of the first collider of grid_f at each of points (P, 3)."""
    for i in range(points.shape[0]):
        d, n = C.signed_distance(grid_f, C.COLLIDERS_AT, ti.Vector([points[i, 0], points[i, 1], points[i, 2]]))
        out[i, 0] = d
        for k in ti.static(range(3)):
            out[i, 1 + k] = n[k]


def distances_of(row, planes, points):
    """(d (P,), n (P, 3)) of the collider ``row`` (with its hull's ``planes``) at points (P, 3)."""
    grid_f = torch.as_tensor(np.concatenate([np.zeros(C.COLLIDERS_AT), C.packed([row], planes)]))
    out = torch.zeros(len(points), 4, dtype=torch.float64)
    distances(grid_f, torch.as_tensor(points), out)
    return out[:, 0].numpy(), out[:, 1:].numpy()


# each shape as its morph states it, and as trimesh builds it (its own frame)
SHAPE_MESHES = {
    "sphere": (C.SPHERE, (0.05, 0, 0), lambda: trimesh.creation.icosphere(subdivisions=4, radius=0.05)),
    "capsule": (C.CAPSULE, (0.03, 0.04, 0), lambda: trimesh.creation.capsule(height=0.08, radius=0.03, count=[96, 96])),
    "cylinder": (C.CYLINDER, (0.04, 0.03, 0), lambda: trimesh.creation.cylinder(radius=0.04, height=0.06,
                                                                                 sections=256)),
    "box": (C.BOX, (0.05, 0.03, 0.02), lambda: trimesh.creation.box(extents=(0.1, 0.06, 0.04))),
    "hull": (C.HULL, None, lambda: trimesh.convex.convex_hull(np.random.default_rng(3).normal(size=(20, 3)) * 0.04)),
}


@pytest.mark.parametrize("shape", list(SHAPE_MESHES))
def test_signed_distances_and_normals_are_the_shapes(shape):
    """At 4000 points around each shape, turned and moved: the signed distance against trimesh's
    (of the same shape as a mesh; the curved ones tessellated finely) and the normal against the
    distance's own gradient (central differences, where the distance is smooth). A hull's
    distance is exact inside and a lower bound outside."""
    kind, size, mesh_of = SHAPE_MESHES[shape]
    mesh = mesh_of()
    planes = hull_planes(mesh.vertices) if kind == C.HULL else ()
    size = (0, len(planes), 0) if kind == C.HULL else size
    rot, pos = rotation((1, -2, 0.5), 35), np.array([0.1, -0.2, 0.3])
    row = collider(kind, pos, rot, size)
    local = np.random.default_rng(0).uniform(-0.08, 0.08, (4000, 3))
    d, n = distances_of(row, planes, local @ rot.T + pos)
    expected = -trimesh.proximity.signed_distance(mesh, local)  # trimesh: > 0 inside
    # the curved shapes' tessellation; trimesh's own closest points on a box miss by 1.6e-6 m at 2 of the points
    tessellation = 1e-5 if kind in (C.BOX, C.HULL) else 2e-4
    inside = expected < 0
    np.testing.assert_allclose(d[inside], expected[inside], atol=tessellation + 1e-12)
    if kind == C.HULL:
        assert np.all(d[~inside] <= expected[~inside] + 1e-12) and np.all(d[~inside] > 0)
    else:
        np.testing.assert_allclose(d[~inside], expected[~inside], atol=tessellation + 1e-12)
    h = 1e-7
    steps = [distances_of(row, planes, local @ rot.T + pos + sign * h * axis)[0] for axis in np.eye(3)
             for sign in (1, -1)]
    gradient = np.stack([(steps[2 * k] - steps[2 * k + 1]) / (2 * h) for k in range(3)], axis=1)
    smooth = np.abs(np.linalg.norm(gradient, axis=1) - 1) < 1e-6  # (not across a kink of the distance)
    assert smooth.mean() > 0.9
    np.testing.assert_allclose(n[smooth], gradient[smooth], atol=1e-6)


def surface_heights(vertices, faces, xy):
    """(P,) m: the height of the triangle mesh (vertices, faces) over each point xy (P, 2), by
    trimesh's ray casting (NaN where no triangle is under or over it)."""
    mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=False)
    origins = np.column_stack([xy, np.full(len(xy), 10.0)])
    locations, rays, _ = mesh.ray.intersects_location(origins, np.tile([0.0, 0.0, -1.0], (len(xy), 1)),
                                                      multiple_hits=False)
    heights = np.full(len(xy), np.nan)
    heights[rays] = locations[:, 2]
    return heights


def test_a_height_field_distance_is_to_the_triangle_under_the_point():
    """A height field (the rigid solver's grid and triangles, hfield.surface) turned and moved: at
    2000 points over and beside it, the distance along the normal ends on the surface trimesh's rays
    find (d / n_z = z − height), the normal is the distance's gradient, and beside the rectangle
    the field is far."""
    elevation = np.random.default_rng(4).random((7, 9))
    size = (0.16, 0.09, 0.05, 0.02)
    vertices, faces = hfield.surface(size, elevation)
    grid = [size[0], size[1], 7, 9, *vertices[:, 2]]
    rot, pos = rotation((0.3, -0.4, 1.0), 40), np.array([0.1, 0.0, 0.2])
    row = collider(C.HFIELD, pos, rot, (0, 0, 0))
    local = np.random.default_rng(1).uniform([-0.2, -0.12, -0.05], [0.2, 0.12, 0.1], (2000, 3))
    d, n = distances_of(row, grid, local @ rot.T + pos)
    over = (np.abs(local[:, 0]) <= size[0]) & (np.abs(local[:, 1]) <= size[1])
    assert np.all(d[~over] == C.FAR) and over.mean() > 0.5
    normal = n[over] @ rot  # in the field's frame
    heights = surface_heights(vertices, faces, local[over, :2])
    np.testing.assert_allclose(local[over, 2] - d[over] / normal[:, 2], heights, atol=1e-12)
    h = 1e-7
    steps = [distances_of(row, grid, local[over] @ rot.T + pos + sign * h * axis)[0] for axis in np.eye(3)
             for sign in (1, -1)]
    gradient = np.stack([(steps[2 * k] - steps[2 * k + 1]) / (2 * h) for k in range(3)], axis=1)
    smooth = np.abs(np.linalg.norm(gradient, axis=1) - 1) < 1e-6  # (not across a triangle's edge)
    assert smooth.mean() > 0.9
    np.testing.assert_allclose(n[over][smooth], gradient[smooth], atol=1e-6)


def test_particles_dropped_on_a_terrain_rest_on_it():
    """A block dropped on a fixed gs.morphs.Terrain (a height field) lies on it after 0.3 s: no
    particle below the surface (trimesh's rays on the terrain's triangles, in the world) by more
    than half a cell."""
    terrain = gs.morphs.Terrain(pos=(-0.4, -0.4, -0.05), horizontal_scale=0.1, vertical_scale=0.01,
                                height_field=np.random.default_rng(0).integers(0, 6, (9, 9)))
    scene, block = block_scene(terrain)
    positions = trajectory(scene, block, 150)[-1].numpy()
    model, row = scene._rigid_solver.model, scene.mpm_solver.collider_rows[0]
    assert row[0] == C.HFIELD
    data = scene.mpm_solver.collider_data
    nrow, ncol = int(data[2]), int(data[3])
    size = (data[0], data[1], 1.0, 0.0)
    vertices, faces = hfield.surface(size, data[4: 4 + nrow * ncol].reshape(nrow, ncol))
    world = vertices @ row[4:13].reshape(3, 3).T + row[1:4]
    heights = surface_heights(world, faces, positions[:, :2])
    assert np.all(np.isfinite(heights)) and np.all(positions[:, 2] > heights - 0.5 * DX)
    assert positions[:, 2].min() < heights.max() + 2 * DX  # on it, not held above it


MJCF_STATIC = """<mujoco><worldbody>
<geom type="box" size="0.05 0.06 0.07" pos="0.1 0 0" euler="10 20 30"/>
<body name="a" pos="0.2 0.1 0.0" euler="0 0 45">
  <geom type="capsule" size="0.02 0.05" pos="0 0.05 0" euler="90 0 0"/>
  <body name="b" pos="0.1 0 0.05" euler="30 0 0">
    <geom type="cylinder" size="0.03 0.04" pos="0.02 0 0" euler="0 30 0"/>
    <geom type="sphere" size="0.03" pos="0 0.1 0"/>
  </body>
</body>
<body name="c" pos="0 -0.2 0.1"><joint type="hinge"/><geom type="sphere" size="0.02"/></body>
</worldbody></mujoco>"""
INERTIAL = '<inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial>'
URDF_FIXED_CHAIN = f"""<robot name="r">
<link name="base"><collision><origin xyz="0 0 0.01" rpy="0.1 0.2 0.3"/><geometry><box size="0.1 0.1 0.02"/></geometry>
</collision>{INERTIAL}</link>
<link name="arm"><collision><origin xyz="0.05 0 0" rpy="0 1.2 0"/><geometry><cylinder radius="0.01" length="0.1"/>
</geometry></collision>{INERTIAL}</link>
<joint name="j" type="fixed"><parent link="base"/><child link="arm"/><origin xyz="0.1 0 0.05" rpy="0.3 0 0.5"/></joint>
</robot>"""


def _attached(scene):
    table = scene.add_entity(gs.morphs.Box(pos=(0.1, 0.0, 0.1), size=(0.1, 0.1, 0.1), euler=(10, 0, 30), fixed=True))
    ball = scene.add_entity(gs.morphs.Sphere(radius=0.03, pos=(0.3, 0.3, 0.3)))
    ball.attach(table, pos=(0.05, 0.02, 0.07), quat=(0.9, 0.1, 0.2, 0.3))
    return [table, ball]


@pytest.mark.parametrize("assets, n_envs", [("mjcf", 0), ("urdf", 0), ("attached", 2)])
def test_colliders_stand_where_the_rigid_solver_puts_the_shapes(assets, n_envs, tmp_path):
    """Every static collision shape's collider row: its pose is the rigid solver's link pose
    (get_links_pos, get_links_quat) composed with the shape's pose in its link, its size the
    shape's: nested, turned MJCF bodies welded to the world (not the hinged one), a URDF chain of
    fixed joints placed by the morph, a sphere attached to a fixed box."""
    scene = gs.Scene(mpm_options=gs.options.MPMOptions(lower_bound=(-0.5, -0.5, -0.2), upper_bound=(0.5, 0.5, 0.6)))
    if assets == "attached":
        entities = _attached(scene)
    else:
        path = tmp_path / ("r.xml" if assets == "mjcf" else "r.urdf")
        path.write_text(MJCF_STATIC if assets == "mjcf" else URDF_FIXED_CHAIN)
        morph = gs.morphs.MJCF(file=str(path), pos=(0.01, 0.02, 0.03), euler=(5, 10, 15)) if assets == "mjcf" else \
            gs.morphs.URDF(file=str(path), pos=(0.0, 0.1, 0.0), euler=(0, 0, 20), fixed=True)
        entities = [scene.add_entity(morph)]
    scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.3), size=(0.05, 0.05, 0.05)), material=gs.materials.MPM.Elastic())
    scene.build(n_envs=n_envs)
    model, rows = scene._rigid_solver.model, scene.mpm_solver.collider_rows
    link_pos = np.concatenate([e.get_links_pos().reshape(-1, max(1, n_envs), 3)[:, 0].numpy() if n_envs else
                               e.get_links_pos().numpy() for e in entities])
    link_quat = np.concatenate([e.get_links_quat().reshape(-1, max(1, n_envs), 4)[:, 0].numpy() if n_envs else
                                e.get_links_quat().numpy() for e in entities])
    static = [g for g in range(len(model.geom_type)) if model.link_static[model.geom_link[g]]]
    assert len(rows) == len(static) == {"mjcf": 4, "urdf": 2, "attached": 2}[assets]
    for row, g in zip(rows, static):
        link = model.geom_link[g]
        rot = quat_to_mat(link_quat[link])
        np.testing.assert_allclose(row[1:4], link_pos[link] + rot @ model.geom_pos[g], atol=1e-12)
        np.testing.assert_allclose(row[4:13], (rot @ quat_to_mat(model.geom_quat[g])).ravel(), atol=1e-12)
        np.testing.assert_array_equal(row[13:16], model.geom_size[g])


# -- scenes --------------------------------------------------------------------------------------

DX = 1 / 32


def block_scene(rigid=None, material=None, lower_z=-0.2, euler=(0, 0, 0), requires_grad=False):
    """A 10 cm elastic block (2 cm particles, 32 cells/m) at z 0.15–0.25 m above a rigid entity
    ``rigid`` (a morph; None: none) of ``material``; the MPM domain's floor wall 3 cells above
    lower_z."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=2e-3, substeps=8, requires_grad=requires_grad),
                     mpm_options=gs.options.MPMOptions(lower_bound=(-0.5, -0.5, lower_z), upper_bound=(0.5, 0.5, 0.6),
                                                       grid_density=32, particle_size=0.02))
    if rigid is not None:
        scene.add_entity(rigid, material=material or gs.materials.Rigid())
    block = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.2), size=(0.1, 0.1, 0.1), euler=euler),
                             material=gs.materials.MPM.Elastic(E=3e4))
    return scene, block


def trajectory(scene, block, steps, velocity=(0.0, 0.0, 0.0)):
    scene.build()
    block.set_velocity(torch.tensor(velocity, dtype=torch.float64))
    out = []
    for _ in range(steps):
        scene.step()
        out.append(block.get_particles_pos().clone())
    return torch.stack(out)


def test_a_plane_without_friction_or_softness_is_the_slip_wall():
    """The floor wall at z = h and a frictionless, sharp plane at z = h (with the wall far below)
    stop the same nodes' same velocity components: the same trajectory to round-off, for a
    tilted block thrown sideways into it."""
    h = 0.1
    sharp = gs.materials.Rigid(coup_friction=0.0, coup_softness=0.0)
    on_plane = trajectory(*block_scene(gs.morphs.Plane(pos=(0, 0, h)), sharp, euler=(20, 30, 0)), 60, (1.0, 0.5, 0.0))
    on_wall = trajectory(*block_scene(lower_z=h - 3 * DX, euler=(20, 30, 0)), 60, (1.0, 0.5, 0.0))
    assert float(on_wall[..., 2].min()) < h + 0.5 * DX  # it lands
    assert float((on_plane - on_wall).abs().max()) < 1e-12


@pytest.mark.parametrize("friction", [0.2, 0.8])
def test_a_block_on_an_incline_slides_as_coulomb_or_sticks(friction):
    """A block resting on a 30° incline (the plane's normal turned about x) slides down it with
    acceleration g (sin θ − μ cos θ) when μ < tan θ = 0.577, and stays when μ > tan θ: its mean
    velocity along the slope after it settles, against Coulomb's."""
    theta = np.radians(30.0)
    normal, down = np.array([0.0, -np.sin(theta), np.cos(theta)]), np.array([0.0, -np.cos(theta), -np.sin(theta)])
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=1e-3, substeps=8),
                     mpm_options=gs.options.MPMOptions(lower_bound=(-0.6, -0.6, -0.6), upper_bound=(0.6, 0.6, 0.6),
                                                       grid_density=48, particle_size=0.01))
    scene.add_entity(gs.morphs.Plane(normal=tuple(normal)),
                     material=gs.materials.Rigid(coup_friction=friction, coup_softness=0.0))
    centre = 0.04 * normal + 0.1 * (-down)  # resting on the plane (8 cm cube), up the slope
    block = scene.add_entity(gs.morphs.Box(pos=tuple(centre), size=(0.08, 0.08, 0.08), euler=(30, 0, 0)),
                             material=gs.materials.MPM.Elastic(E=1e6, rho=1000.0))
    scene.build()
    speeds = []
    for step in range(200):
        scene.step()
        if step in (99, 199):
            speeds.append(float(block.get_particles_vel().mean(dim=0) @ torch.tensor(down)))
    expected = max(0.0, 9.81 * (np.sin(theta) - friction * np.cos(theta)))
    measured = (speeds[1] - speeds[0]) / 0.1
    assert abs(measured - expected) < (0.1 if expected > 0 else 0.02), (measured, expected)


GEM = trimesh.creation.icosahedron().apply_scale((0.09, 0.07, 0.05))  # a convex mesh
MESHES = {  # trimesh's primitives, for its signed distance
    "sphere": lambda size: trimesh.creation.icosphere(subdivisions=5, radius=size[0]),
    "capsule": lambda size: trimesh.creation.capsule(height=2 * size[1], radius=size[0], count=[64, 64]),
    "cylinder": lambda size: trimesh.creation.cylinder(radius=size[0], height=2 * size[1], sections=128),
    "box": lambda size: trimesh.creation.box(extents=2 * np.asarray(size)),
    "mesh": lambda size: GEM,
}
MORPHS = {
    "sphere": lambda path: gs.morphs.Sphere(pos=(0.01, 0.0, 0.0), radius=0.06, fixed=True),
    "capsule": lambda path: gs.morphs.Capsule(pos=(0.0, 0.0, 0.0), radius=0.04, height=0.2, euler=(0, 80, 20),
                                              fixed=True),
    "cylinder": lambda path: gs.morphs.Cylinder(pos=(0.0, 0.01, 0.0), radius=0.05, height=0.12, euler=(70, 0, 0),
                                                fixed=True),
    "box": lambda path: gs.morphs.Box(pos=(0.0, 0.0, 0.0), size=(0.16, 0.1, 0.06), euler=(10, 5, 30), fixed=True),
    "mesh": lambda path: gs.morphs.Mesh(file=exported(GEM, path), pos=(0.0, 0.01, 0.0), euler=(15, 0, 40), fixed=True),
}


def exported(mesh, path):
    """``path``, where ``mesh`` (trimesh) is written."""
    mesh.export(path)
    return path


@pytest.mark.parametrize("shape", list(MORPHS))
def test_particles_dropped_on_a_fixed_shape_stay_outside_it(shape, tmp_path):
    """A block dropped on a fixed primitive or convex mesh (Genesis's morph, its collision shape)
    comes to lie on it: after 0.3 s no particle is inside it by more than half a cell (trimesh's
    signed distance to the same shape), and the block has stopped above it (it would fall through
    to z < −0.1)."""
    scene, block = block_scene(MORPHS[shape](str(tmp_path / "gem.obj")), lower_z=-0.4)
    positions = trajectory(scene, block, 150)[-1].numpy()
    model, row = scene._rigid_solver.model, scene.mpm_solver.collider_rows[0]
    assert {2: "sphere", 3: "capsule", 5: "cylinder", 6: "box", 7: "mesh"}[int(model.geom_type[0])] == shape
    local = (positions - row[1:4]) @ row[4:13].reshape(3, 3)  # in the shape's frame
    depth = trimesh.proximity.signed_distance(MESHES[shape](model.geom_size[0]), local)  # > 0 inside
    assert depth.max() < 0.5 * DX, f"{shape}: a particle {depth.max():.4f} m inside"
    assert positions[:, 2].min() > -0.1


@pytest.mark.parametrize("n_envs", [0, 2])
def test_loss_backward_through_a_scene_with_a_ground_plane_matches_fd(n_envs):
    """loss.backward() through a rigid–MPM scene (the shared substep loop, the autograd node) with
    a tilted ground: the initial velocities' gradient against central differences."""
    from .fd_scan import assert_converged, directional_errors
    scene, block = block_scene(gs.morphs.Plane(pos=(0.0, 0.0, 0.12), normal=(0.1, 0.2, 1.0)),
                               gs.materials.Rigid(coup_friction=0.4, coup_softness=0.005), requires_grad=True)
    scene.build(n_envs=n_envs)
    rng = np.random.default_rng(0)
    weights = torch.as_tensor(rng.normal(size=(block.n_particles, 3)))

    def loss(vel):
        scene.reset()
        block.set_particles_vel(vel)
        for _ in range(15):
            scene.step()
        return (block.get_particles_pos() * weights).sum()

    shape = (block.n_particles, 3) if n_envs == 0 else (n_envs, block.n_particles, 3)
    vel = torch.as_tensor(rng.normal(0.0, 0.3, shape)) + torch.tensor([0.5, 0.0, -2.0], dtype=torch.float64)
    assert_converged(directional_errors(loss, vel), "initial velocities")


def test_particles_move_as_genesis_moves_them(monkeypatch):
    """bench/coupling.py's block thrown onto a tilted plane and a fixed sphere (friction, softness,
    restitution): its particles at steps 50 and 100 against Genesis 1.4.5's (stored by that script;
    measured there 2.1e-9 and 3.9e-9 m apart, round-off grown by the rollout)."""
    bench = os.path.join(ROOT, "bench")
    monkeypatch.syspath_prepend(bench)
    scene, block, _ = runpy.run_path(os.path.join(bench, "coupling.py"))["scene_of"](gs, "static")
    with open(os.path.join(ROOT, "tests", "data", "genesis_coupling.json")) as file:
        reference = json.load(file)
    block.set_velocity(torch.tensor([1.5, 0.0, -1.0], dtype=torch.float64).repeat(block.n_particles, 1))
    for step in range(1, 101):
        scene.step()
        if step in reference["steps"]:
            expected = np.array(reference["positions"][reference["steps"].index(step)])
            gap = np.linalg.norm(block.get_particles_pos().numpy() - expected, axis=1).max()
            assert gap < 1e-6, f"step {step}: {gap:.3g} m from Genesis"


def test_a_box_mesh_is_the_box(tmp_path):
    """A fixed mesh of a box (its convex hull's six face planes) and the Box primitive in the same
    pose give the particles the same bits (its centre off the grid's nodes: a node equidistant from
    two faces takes either face's normal, which the two shapes break differently)."""
    path = exported(trimesh.creation.box(extents=(0.16, 0.1, 0.06)), str(tmp_path / "box.obj"))
    pose = dict(pos=(0.005, 0.003, 0.002), euler=(10, 5, 30), fixed=True)
    positions = [trajectory(*block_scene(morph, gs.materials.Rigid(coup_softness=0.0)), 150)
                 for morph in (gs.morphs.Mesh(file=path, **pose), gs.morphs.Box(size=(0.16, 0.1, 0.06), **pose))]
    assert torch.equal(*positions)
    lowest = float(positions[0][-1, :, 2].min())
    assert 0.0 < lowest < 0.06  # landed on the box's top, about 4 cm up (it would fall through to the floor at −0.1)


@pytest.mark.float32
def test_float32_batched_envs_with_colliders_agree_bit_for_bit(f32):
    """float32, two envs thrown alike onto a tilted plane and a fixed box: the same particle bits and
    the same finite gradients in both envs."""
    scene, block = block_scene(gs.morphs.Plane(pos=(0.0, 0.0, 0.12), normal=(0.1, 0.2, 1.0)),
                               gs.materials.Rigid(coup_friction=0.4, coup_softness=0.005), requires_grad=True)
    scene.add_entity(gs.morphs.Box(pos=(0.04, 0.0, 0.1), size=(0.05, 0.05, 0.05), euler=(0, 0, 30), fixed=True))
    scene.build(n_envs=2)
    vel = torch.tensor([0.5, 0.0, -2.0], dtype=torch.float32).repeat(2, block.n_particles, 1).requires_grad_()
    block.set_particles_vel(vel)
    for _ in range(15):
        scene.step()
    positions = block.get_particles_pos()
    (positions * torch.linspace(-1.0, 1.0, positions.numel()).view_as(positions)[0]).sum().backward()
    assert torch.equal(positions[0], positions[1])
    assert torch.isfinite(vel.grad).all() and torch.equal(vel.grad[0], vel.grad[1]) and vel.grad.abs().sum() > 0


def test_which_shapes_couple():
    """Fixed primitives of coupling materials are the MPM solver's colliders; a moving body's meet the
    grid in the coupling stage (test_mpm_coupler.py); needs_coup=False and collision=False do not
    couple."""
    scene = gs.Scene(mpm_options=gs.options.MPMOptions(lower_bound=(-0.5, -0.5, -0.2), upper_bound=(0.5, 0.5, 0.6)))
    plane = scene.add_entity(gs.morphs.Plane(), material=gs.materials.Rigid(coup_friction=0.7, coup_softness=0.01,
                                                                             coup_restitution=0.5))
    scene.add_entity(gs.morphs.Box(pos=(0.3, 0.0, 0.05), size=(0.1, 0.1, 0.1), fixed=True),
                     material=gs.materials.Rigid(needs_coup=False))
    scene.add_entity(gs.morphs.Box(pos=(0.0, 0.3, 0.05), size=(0.1, 0.1, 0.1), fixed=True, collision=False))
    ball = scene.add_entity(gs.morphs.Sphere(pos=(-0.3, 0.0, 0.3), radius=0.05), name="ball")
    scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.2), size=(0.05, 0.05, 0.05)), material=gs.materials.MPM.Sand())
    scene.build()
    rows = scene.mpm_solver.collider_rows
    assert rows.shape == (1, C.WIDTH) and rows[0, 0] == C.PLANE
    # its coupling: the first rigid entity's columns of the per-env inputs; a plane has no bounding radius
    np.testing.assert_array_equal(rows[0, 16:18], [layout.COUPLING_AT, np.inf])
    np.testing.assert_array_equal(scene.mpm_solver.env_in[0, 3:6].numpy(), [0.7, 0.01, 0.5])
    np.testing.assert_array_equal(plane.get_coupling().numpy(), [0.7, 0.01, 0.5])
    owner = scene.sim.coupler.rigid.model.link_entity[scene.sim.coupler.geoms[:, 1].numpy()]
    assert scene.sim.coupler.geoms.shape == (1, 2) and owner[0] == 3  # the fourth rigid entity's sphere
    assert scene.coupled_entities == {plane, ball}


def _thrown_on_a_plane(n_envs):
    """Differentiable, float64: a jelly block thrown along a coupled plane (its softness reaching the
    nodes above it), 32 cells/m, dt 2 ms in 4 substeps; returns (scene, plane, block, loss), where
    loss(coupling, velocity) runs 20 steps after a reset with the plane's (μ, ς, e) ← coupling
    ((3,) or (n_envs, 3)) and the particles' velocity ← velocity (3,), and weighs the particles'
    final positions."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=2e-3, substeps=4, requires_grad=True),
                     mpm_options=gs.options.MPMOptions(lower_bound=(-0.5, -0.5, -0.2), upper_bound=(0.5, 0.5, 0.6),
                                                       grid_density=32))
    plane = scene.add_entity(gs.morphs.Plane())
    block = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.05), size=(0.12, 0.12, 0.08)),
                             material=gs.materials.MPM.Elastic(E=3e4))
    scene.build(n_envs=n_envs)
    weights = torch.linspace(0.5, 1.5, 3 * block.n_particles, dtype=torch.float64).view(-1, 3)

    def loss(coupling, velocity):
        scene.reset()
        plane.set_coupling(*coupling.unbind(-1))
        block.set_particles_vel(velocity.expand(block.n_particles, 3))
        for _ in range(20):
            scene.step()
        return (block.get_particles_pos() * weights).sum()
    return scene, plane, block, loss


PLANE_COUPLINGS = torch.tensor([[0.4, 0.02, 0.3], [0.8, 0.01, 0.1]], dtype=torch.float64)
THROW = torch.tensor([0.6, 0.2, -0.4], dtype=torch.float64)


def test_gradients_in_a_plane_s_coupling_match_fd_and_batch_as_single_envs():
    """Through the scene (no moving shape: the grid update's own reverse): the plane's coupling
    friction, softness and restitution against central differences, bit-identical when repeated;
    two envs given two couplings each have the gradient bits of their single-env scene; the
    particles' velocity gradient keeps its bits whether the coupling's is taken or not."""
    _, _, _, loss = _thrown_on_a_plane(0)
    sizes = torch.tensor([1.0, 0.01, 1.0], dtype=torch.float64)  # (μ, ς m, e): the FD directions' scales
    scaled = checked_gradient(lambda x: loss(x * sizes, THROW), PLANE_COUPLINGS[0] / sizes, "the plane's coupling")
    assert (scaled.abs() > 1e-3 * scaled.abs().max()).all(), scaled

    def gradients(loss, coupling, wanted):
        coupling, velocity = coupling.clone().requires_grad_(wanted), THROW.clone().requires_grad_(True)
        loss(coupling, velocity).backward()
        return coupling.grad, velocity.grad

    single = [gradients(loss, coupling, True) for coupling in PLANE_COUPLINGS]
    assert torch.equal(gradients(loss, PLANE_COUPLINGS[0], False)[1], single[0][1])
    single = [coupling for coupling, _ in single]
    _, _, _, batched_loss = _thrown_on_a_plane(2)
    batched, _ = gradients(batched_loss, PLANE_COUPLINGS, True)
    for e in range(2):
        assert torch.equal(batched[e], single[e]), (batched[e], single[e])


def test_coupler_options_rigid_mpm_false_lets_the_particles_through():
    """Genesis's LegacyCouplerOptions(rigid_mpm=False): no collider, no coupling stage; the block falls
    through the plane; a wrong type or value is a named error."""
    block_z = []
    for rigid_mpm in (True, False):
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=2e-3, substeps=8),
                         mpm_options=gs.options.MPMOptions(lower_bound=(-0.5, -0.5, -0.2), upper_bound=(0.5, 0.5, 0.6),
                                                           grid_density=32, particle_size=0.02),
                         coupler_options=gs.options.LegacyCouplerOptions(rigid_mpm=rigid_mpm))
        scene.add_entity(gs.morphs.Plane(pos=(0.0, 0.0, 0.1)))
        scene.add_entity(gs.morphs.Sphere(pos=(0.3, 0.0, 0.3), radius=0.05), name="ball")
        block = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.2), size=(0.1, 0.1, 0.1)),
                                 material=gs.materials.MPM.Elastic(E=3e4))
        scene.build()
        assert len(scene.mpm_solver.collider_rows) == int(rigid_mpm) and (scene.sim.coupler is None) != rigid_mpm
        for _ in range(100):
            scene.step()
        block_z.append(float(block.get_particles_pos()[:, 2].min()))
    assert block_z[0] > 0.1 - 0.5 * DX and block_z[1] < 0.0  # on the plane; through it, 10 cm below
    with pytest.raises(InvalidInputError, match="LegacyCouplerOptions: argument 'rigid_mpm' must be True or False"):
        gs.options.LegacyCouplerOptions(rigid_mpm=1)
    with pytest.raises(InvalidInputError, match="'coupler_options' must be gs.options.LegacyCouplerOptions"):
        gs.Scene(coupler_options=gs.options.SimOptions())


@pytest.mark.parametrize("name, value", [("coup_friction", -0.1), ("coup_softness", float("nan")),
                                         ("coup_restitution", 1.5), ("coup_friction", "high"),
                                         ("needs_coup", 1)])
def test_bad_coupling_parameters_are_refused(name, value):
    with pytest.raises(InvalidInputError, match=f"materials.Rigid: argument '{name}'"):
        gs.materials.Rigid(**{name: value})
