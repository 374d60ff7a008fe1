"""Height fields: MJCF <hfield> geoms and gs.morphs.Terrain (solvers/rigid/collision/hfield.py).

Oracles, all outside this code:
- MuJoCo 4.0's own height field (the same MJCF file, or pybullet_data's a1 on bumpy ground;
  re-synced before every step): equal contacts and velocities after the step for spheres and
  capsules (the a1's feet: 2e-14 … 5e-13 over 1 s), equal contacts for a box face parallel to a
  flat field;
- MuJoCo 4.0's convex collider on each prism given to it as a mesh: our per-prism contacts are its
  contacts (MuJoCo's own height field path gives other ones for polytopes turned against the
  grid, not the prism's least-penetration contact: `test_prisms_collide_as_mujocos_convex_meshes`);
- an exact separating-axis computation of the penetration depth of a box and a prism;
- central finite differences for gradients through height-field contacts.
"""
import itertools

import mujoco
import numpy as np
import pytest
import torch

import genesis_lite as gs
from genesis_lite.solvers.core import AssetError, InvalidInputError
from genesis_lite.solvers.rigid.collision import hfield
from tests.fd_scan import checked_gradient

NROW, NCOL = 9, 11
SIZE = (1.0, 0.8, 0.3, 0.1)
SHAPES = {"sphere": 'type="sphere" size="0.12"', "capsule": 'type="capsule" size="0.06 0.12"',
          "box": 'type="box" size="0.1 0.15 0.08"', "cylinder": 'type="cylinder" size="0.1 0.06"',
          "mesh": 'type="mesh" mesh="tet"'}


def _elevation(seed=0):
    return np.round(np.random.default_rng(seed).uniform(0, 1, (NROW, NCOL)), 6)


def _xml(shape, elevation, body_pos="0.13 0.07 0.6"):
    values = " ".join(f"{v:.6f}" for v in elevation.ravel())
    return f"""<mujoco><option timestep="0.002"/>
<asset><hfield name="h" nrow="{NROW}" ncol="{NCOL}" size="{' '.join(map(str, SIZE))}" elevation="{values}"/>
<mesh name="tet" vertex="0.1 0 0  -0.05 0.09 0  -0.05 -0.09 0  0 0 0.15  0.02 0.03 -0.1"/></asset>
<worldbody><geom type="hfield" hfield="h" pos="0.1 -0.05 0"/>
<body pos="{body_pos}" euler="20 30 10"><freejoint/><geom {SHAPES[shape]}/></body>
</worldbody></mujoco>"""


def _pair(tmp_path, shape, elevation):
    path = tmp_path / f"{shape}.xml"
    path.write_text(_xml(shape, elevation))
    m = mujoco.MjModel.from_xml_path(str(path))
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER  # (free bodies turn: MuJoCo's Euler is ours)
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=m.opt.timestep),
                     rigid_options=gs.options.RigidOptions(enable_mujoco_compatibility=True))
    robot = scene.add_entity(gs.morphs.MJCF(file=str(path)))
    scene.build()
    return m, mujoco.MjData(m), scene, robot


def test_elevation_is_read_as_mujocos_compiler_stores_it(f64, tmp_path):
    """The file's rows from the far edge (MuJoCo 4 flips them), normalised in float32: MuJoCo's
    hfield_data bit for bit; the grid points where MuJoCo puts them."""
    elevation = _elevation()
    m, _, scene, robot = _pair(tmp_path, "sphere", elevation)
    ours = hfield.normalised(elevation[::-1], "test")
    assert np.array_equal(m.hfield_data.reshape(NROW, NCOL), ours)
    grid = hfield.grid_hull(np.array(SIZE), ours)["vert"]
    assert grid.shape == (2 * NROW * NCOL, 3)
    r, c = 3, 7
    assert np.allclose(grid[r * NCOL + c], [2 * SIZE[0] / (NCOL - 1) * c - SIZE[0],
                                            2 * SIZE[1] / (NROW - 1) * r - SIZE[1], ours[r, c] * SIZE[2]])
    assert np.allclose(grid[NROW * NCOL:, 2], -SIZE[3])
    assert float(robot.links[-1].get_mass()) == 0.0 and robot.links[-1].is_fixed


@pytest.mark.parametrize("shape, bound", [("sphere", 1e-6), ("capsule", 1e-10)])
def test_round_shapes_on_a_height_field_step_like_mujoco(f64, tmp_path, shape, bound):
    """A spinning sphere or capsule dropped on a random height field, 400 steps re-synced from
    MuJoCo before each: every step's contacts are MuJoCo's (count, position, depth) and qvel after
    it agrees (measured: capsule 3.7e-12; sphere 1.6e-7 in one step where the sphere's centre is
    deep in a prism and EPA samples it, else ≤ 1e-11)."""
    m, d, scene, robot = _pair(tmp_path, shape, _elevation())
    d.qvel[:] = [0.8, -0.5, 0.0, 3.0, -2.0, 5.0]
    touched, worst = 0, 0.0
    for _ in range(400):
        robot.set_qpos(torch.tensor(d.qpos))
        robot.set_dofs_velocity(torch.tensor(d.qvel))
        mujoco.mj_step(m, d)
        scene.step()
        contacts = robot.get_contacts()
        assert len(contacts["position"]) == d.ncon
        if d.ncon:
            touched += 1
            theirs = np.array([c.pos for c in d.contact[:d.ncon]])
            assert np.abs(contacts["position"].numpy() - theirs).max() < 1e-6
            assert np.abs(-contacts["penetration"].numpy() - d.contact.dist[:d.ncon]).max() < 1e-6
        worst = max(worst, np.abs(robot.get_dofs_velocity().numpy() - d.qvel).max())
    assert touched > 200 and worst < bound


def test_a_flat_box_face_on_a_flat_field_touches_where_mujoco_does(f64, tmp_path):
    """A box lying 1 mm into a flat 3 × 3 field: MuJoCo's six contacts (one a prism under it, at
    the EPA's witness points), bit for bit in position and depth."""
    path = tmp_path / "flat.xml"
    path.write_text("""<mujoco><asset><hfield name="h" nrow="3" ncol="3" size="1 1 0.5 0.1"/></asset>
<worldbody><geom type="hfield" hfield="h"/>
<body pos="0.13 0.07 0.099"><freejoint/><geom type="box" size="0.2 0.1 0.1"/></body></worldbody></mujoco>""")
    m = mujoco.MjModel.from_xml_path(str(path))
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    scene = gs.Scene(rigid_options=gs.options.RigidOptions(enable_mujoco_compatibility=True))
    robot = scene.add_entity(gs.morphs.MJCF(file=str(path)))
    scene.build()
    scene.step()
    contacts = robot.get_contacts()
    assert d.ncon == len(contacts["position"]) == 6
    assert np.abs(contacts["position"].numpy() - np.array([c.pos for c in d.contact[:6]])).max() < 1e-12
    assert np.abs(contacts["penetration"].numpy() - 1e-3).max() < 1e-12


def _box_corners(pos, rot, half):
    return np.array([pos + rot @ (half * np.array(s)) for s in itertools.product((-1, 1), repeat=3)])


def _sat_depth(a, b):
    """The least overlap (m) of two convex polytopes (vertex arrays) over the separating-axis
    candidates (face normals and edge cross products): their exact penetration depth."""
    import scipy.spatial

    axes = [e[:3] for points in (a, b) for e in scipy.spatial.ConvexHull(points).equations]
    for ea in (a[j] - a[i] for i in range(len(a)) for j in range(i + 1, len(a))):
        for eb in (b[j] - b[i] for i in range(len(b)) for j in range(i + 1, len(b))):
            cross = np.cross(ea, eb)
            if np.linalg.norm(cross) > 1e-9:
                axes.append(cross / np.linalg.norm(cross))
    return min(min((a @ n).max() - (b @ n).min(), (b @ n).max() - (a @ n).min()) for n in axes)


def test_prisms_collide_as_mujocos_convex_meshes(f64, tmp_path):
    """A tilted box pressed into a flat 3 × 3 field: each contact is the one MuJoCo 4.0's convex
    collider gives for its prism loaded as a mesh (multi-contact off), and its depth the exact
    separating-axis depth of box and prism (MuJoCo's own height field path reports 10.5 and 6.3 mm
    there along the box's axis, shallower than the exact 16.2 and 15.3 mm: module docstring)."""
    quat = np.array([0.999, 0.02, 0.03, 0.01]) / np.linalg.norm([0.999, 0.02, 0.03, 0.01])
    pos, half = np.array([0.13, 0.07, 0.0995]), np.array([0.2, 0.1, 0.1])
    path = tmp_path / "tilted.xml"
    path.write_text(f"""<mujoco><asset><hfield name="h" nrow="3" ncol="3" size="1 1 0.5 0.1"/></asset>
<worldbody><geom type="hfield" hfield="h"/><body pos="{' '.join(map(str, pos))}" quat="{' '.join(map(str, quat))}">
<freejoint/><geom type="box" size="{' '.join(map(str, half))}"/></body></worldbody></mujoco>""")
    scene = gs.Scene(rigid_options=gs.options.RigidOptions(enable_mujoco_compatibility=True))
    robot = scene.add_entity(gs.morphs.MJCF(file=str(path)))
    scene.build()
    scene.step()
    contacts = robot.get_contacts()
    corners = _box_corners(pos, _rot(quat), half)
    point = lambda i: (i % 3 - 1.0, i // 3 - 1.0)  # noqa: E731 (grid id → x, y)
    depths, positions = [], []
    for triangle in ([4, 1, 5], [4, 8, 5]):  # the two prisms under the box's low corners
        vertices = [(*point(i), -0.1) for i in triangle] + [(*point(i), 0.0) for i in triangle]
        depths.append(_sat_depth(corners, np.array(vertices)))
        xml = f"""<mujoco><asset><mesh name="p" vertex="{' '.join(f'{v:g}' for v in np.ravel(vertices))}"/></asset>
<worldbody><geom type="mesh" mesh="p"/><body pos="{' '.join(map(str, pos))}" quat="{' '.join(map(str, quat))}">
<freejoint/><geom type="box" size="{' '.join(map(str, half))}"/></body></worldbody></mujoco>"""
        m = mujoco.MjModel.from_xml_string(xml)
        m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_MULTICCD
        d = mujoco.MjData(m)
        mujoco.mj_forward(m, d)
        assert d.ncon == 1
        positions.append(d.contact[0].pos.copy())
        assert abs(-d.contact[0].dist - depths[-1]) < 1e-9
    assert len(contacts["position"]) == 2
    # (MuJoCo stores the prism mesh re-centred, in float32: a witness on an edge moves by ~6e-9 m)
    assert np.abs(contacts["position"].numpy() - np.array(positions)).max() < 1e-7
    assert np.abs(contacts["penetration"].numpy() - np.array(depths)).max() < 1e-9


def _rot(quat):
    w, x, y, z = quat
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _terrain_scene(shape, requires_grad=False, precision_dt=0.01, n_envs=0):
    heights = np.random.default_rng(1).integers(0, 40, (12, 10)).astype(float)
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=precision_dt, requires_grad=requires_grad))
    terrain = scene.add_entity(gs.morphs.Terrain(height_field=heights, horizontal_scale=0.25, vertical_scale=0.005))
    morph = {"sphere": gs.morphs.Sphere(radius=0.1, pos=(1.2, 1.1, 0.35)),
             "box": gs.morphs.Box(size=(0.2, 0.15, 0.1), pos=(0.7, 0.6, 0.35), euler=(10, 20, 30)),
             "capsule": gs.morphs.Capsule(radius=0.05, height=0.2, pos=(1.0, 1.3, 0.35), euler=(80, 0, 20))}[shape]
    body = scene.add_entity(morph)
    scene.build(n_envs=n_envs)
    return scene, terrain, body, heights


@pytest.mark.parametrize("precision", ["32", "64"])
@pytest.mark.parametrize("shape", ["sphere", "box", "capsule"])
def test_bodies_land_and_stay_on_a_terrain(precision, shape):
    """Dropped on a Genesis-style Terrain (heights in vertical_scale units, point (i, j) at (i, j)
    · horizontal_scale), each body lands and stays on it (rolling or sliding down its slopes),
    in float32 too: once landed, at most 5 mm in and touching it in most steps; never below its
    lowest point."""
    gs.init(precision=precision, logging_level="warning")
    scene, terrain, body, heights = _terrain_scene(shape)
    touching = 0
    for step in range(300):
        scene.step()
        depth = body.get_contacts()["penetration"]
        if step >= 100:  # (landing at ~2.5 m/s, one step of 10 ms goes 2.5 cm in, as on a plane)
            assert not len(depth) or float(depth.max()) < 5e-3, (step, depth)
            touching += len(depth) > 0
    assert touching > 150
    pos = body.get_pos().numpy()
    assert np.isfinite(pos).all() and heights.min() * 0.005 < pos[2] < heights.max() * 0.005 + 0.2
    assert terrain.get_AABB().numpy()[1, 2] == pytest.approx(heights.max() * 0.005)


@pytest.mark.parametrize("shape", ["sphere", "box"])
def test_gradients_through_terrain_contacts_match_finite_differences(f64, shape):
    """Initial velocity → position after 40 steps sliding and rolling over the terrain: the
    gradient converges to central differences, and a repeated rollout keeps its bits."""
    scene, _, body, _ = _terrain_scene(shape, requires_grad=True)
    for _ in range(30):  # (to contact first)
        scene.step()
    state = scene.get_state()
    weights = torch.tensor([0.3, -0.7, 1.1, 0.2, 0.5, -0.4], dtype=torch.float64)

    def loss(velocity):
        scene.reset(state)
        body.set_dofs_velocity(velocity)
        for _ in range(40):
            scene.step()
        return (torch.cat([body.get_pos(), body.get_quat()[1:]]) * weights).sum()

    start = torch.tensor([0.4, -0.3, 0.0, 1.0, 0.5, -0.8], dtype=torch.float64)
    assert float(checked_gradient(loss, start, f"{shape} on a terrain").norm()) > 0


def test_terrain_in_a_batch_steps_each_env_as_alone(f64):
    """Two envs of a batched terrain scene step as two single-env scenes do, bit for bit."""
    scene, _, body, _ = _terrain_scene("box", n_envs=2)
    alone, _, body_alone, _ = _terrain_scene("box")
    velocity = torch.tensor([[0.4, -0.3, 0.0, 1.0, 0.5, -0.8], [0.0, 0.2, 0.0, -1.0, 0.0, 0.3]], dtype=torch.float64)
    body.set_dofs_velocity(velocity)
    for _ in range(60):
        scene.step()
    for env in range(2):
        alone.reset()
        body_alone.set_dofs_velocity(velocity[env])
        for _ in range(60):
            alone.step()
        assert torch.equal(body.get_qpos()[env], body_alone.get_qpos())


@pytest.mark.parametrize("kwargs, said", [
    ({"height_field": np.zeros(4)}, "2-d array of finite real heights"),
    ({"height_field": np.array([[0.0, np.nan], [0.0, 0.0]])}, "2-d array of finite real heights"),
    ({"height_field": np.zeros((3, 3)) + 1j}, "finite real heights"),  # (numpy took the real part)
    ({"height_field": np.ones((3, 3), dtype=bool)}, "finite real heights"),
    ({"height_field": np.zeros((3, 3)), "horizontal_scale": -1.0}, "'horizontal_scale' must be positive"),
    ({"height_field": np.zeros((3, 3)), "fixed": False}, "always fixed"),
    ({"height_field": np.zeros((3, 3)), "n_subterrains": (2, 2)}, r"\['n_subterrains'\] generate subterrains"),
    ({"height_field": np.zeros((3, 3)), "subterrain_types": "wave_terrain"}, "give one or the other"),
])
def test_terrain_bad_input_is_named(kwargs, said):
    with pytest.raises(InvalidInputError, match=said):
        gs.morphs.Terrain(**kwargs)


@pytest.mark.parametrize("asset, body, said", [
    ('<hfield name="h" nrow="2" ncol="2" size="1 1 0.1 0.1" file="terrain.png"/>', "", "from a file"),
    ('<hfield name="h" nrow="2" ncol="2" size="1 1 0 0.1"/>', "", "4 positive numbers"),
    ('<hfield name="h" nrow="2" ncol="2" size="1 1 0.1 0.1" elevation="1 2 3"/>', "", "'elevation' expected 4"),
    ('<hfield name="h" nrow="-2" ncol="3" size="1 1 0.1 0.1"/>', "", "'nrow' expected an integer >= 2"),
    ('<hfield name="h" nrow="2" ncol="2.5" size="1 1 0.1 0.1"/>', "", "'ncol' expected an integer >= 2"),
    ('<hfield name="h" nrow="2" ncol="2" size="1 1 0.1 0.1"/>', '<geom type="hfield" hfield="g"/>',
     "'g' is not an <asset><hfield>"),
    ('<hfield name="h" nrow="2" ncol="2" size="1 1 0.1 0.1"/>',
     '<body><freejoint/><geom type="hfield" hfield="h"/></body>', "height field only in the worldbody"),
])
def test_mjcf_height_field_bad_input_is_named(f64, tmp_path, asset, body, said):
    path = tmp_path / "bad.xml"
    body = body or '<geom type="hfield" hfield="h"/>'
    path.write_text(f"<mujoco><asset>{asset}</asset><worldbody>{body}"
                    f"<body pos='0 0 1'><freejoint/><geom size='0.1'/></body></worldbody></mujoco>")
    with pytest.raises(AssetError, match=said):
        scene = gs.Scene()
        scene.add_entity(gs.morphs.MJCF(file=str(path)))
        scene.build()


def test_prisms_take_mujocos_vertex_order(f64):
    """hfield.triangle gives each prism's top vertices in the order of mjc_ConvexHField's shift
    register (its addPrismVert adds the grid points (r + 1, c), (r, c) column by column and keeps
    the last three): the order breaks support ties, so it decides contacts on flat ground."""
    import taichi as ti

    nrow, ncol = 4, 5

    @ti.kernel
    def ids(table: ti.types.ndarray()):
        for r, c, i in ti.ndrange(nrow - 1, (1, ncol), 2):
            triangle = hfield.triangle(r, c, i, ncol)
            for k in ti.static(range(3)):
                table[r, c - 1, i, k] = triangle[k]

    table = np.zeros((nrow - 1, ncol - 1, 2, 3))
    ids(table)
    for r in range(nrow - 1):
        register = [(r + 1) * ncol, r * ncol]  # (cmin = 0: its two points come first)
        for c in range(1, ncol):
            for i in range(2):
                register.append((r + 1 - i) * ncol + c)
                assert list(table[r, c - 1, i]) == register[-3:], (r, c, i)


def test_generated_subterrains_have_their_shapes(f64):
    """gs.morphs.Terrain without a height_field: Genesis's subterrain grid (shared edges), each
    kind's shape as defined (genesis_lite/utils/terrain.py; the kinds without chance measured equal
    to Genesis 1.4.5's heights to float32 rounding), reproducible unless randomize."""
    hs, vs = 0.25, 0.005
    default = gs.morphs.Terrain()
    assert default.height_field.shape == (3 * 48 + 1, 3 * 48 + 1)
    assert np.array_equal(default.height_field, gs.morphs.Terrain().height_field)
    assert not np.array_equal(default.height_field, gs.morphs.Terrain(randomize=True).height_field)
    kinds = [["sloped_terrain", "stairs_terrain"], ["pyramid_stairs_terrain", "wave_terrain"]]
    field = gs.morphs.Terrain(n_subterrains=(2, 2), subterrain_size=(4.0, 3.0), subterrain_types=kinds,
                              subterrain_parameters={"sloped_terrain": {"slope": 0.4}}).height_field
    rows, cols = 17, 13
    assert field.shape == (2 * rows - 1, 2 * cols - 1)
    sloped = field[:rows - 1, :cols - 1]  # (the shared edges take the higher neighbour)
    top = int(0.4 * hs / vs * rows)
    assert np.allclose(sloped, (top * np.arange(rows - 1) / rows)[:, None])
    stairs = field[:rows - 1, cols:]
    width, rise = int(0.75 / hs), int(-0.1 / vs)
    assert np.array_equal(stairs[:, 0], [rise * (k // width + 1) if k < rows // width * width else 0
                                         for k in range(rows - 1)])
    pyramid = gs.morphs.Terrain(n_subterrains=(1, 1), subterrain_size=(4.0, 4.0),
                                subterrain_types="pyramid_stairs_terrain").height_field
    levels = sorted(set(pyramid.ravel()), reverse=True)  # (down from the rim: step -0.1 m)
    assert levels == [rise * k for k in range(len(levels))] and len(levels) == 3
    assert np.array_equal(pyramid, pyramid[::-1, ::-1]) and pyramid[8, 8] == levels[-1]
    wave = field[rows:, cols:]
    assert np.abs(wave).max() <= 0.1 / vs + 1e-9 and np.abs(wave).max() > 0.05 / vs
    stones = gs.morphs.Terrain(n_subterrains=(1, 1), subterrain_size=(6.0, 6.0),
                               subterrain_types="stepping_stones_terrain").height_field
    assert stones.min() == int(-10.0 / vs) and stones.max() <= 0.2 / vs
    uniform = gs.morphs.Terrain(n_subterrains=(1, 1), subterrain_size=(6.0, 6.0),
                                subterrain_types="random_uniform_terrain").height_field
    assert np.array_equal(uniform, np.rint(uniform)) and np.abs(uniform).max() <= 0.1 / vs


def test_every_kind_builds_on_the_smallest_subterrains(f64):
    """Each kind on subterrains of one cell (2 × 2 points), and of one cell by many, is finite."""
    for kind in terrain_kinds():
        for size in ((0.25, 0.25), (0.25, 3.0), (3.0, 0.25)):
            heights = gs.morphs.Terrain(n_subterrains=(2, 1), subterrain_size=size, subterrain_types=kind).height_field
            assert np.isfinite(heights).all() and heights.shape == (2 * round(size[0] / 0.25) + 1,
                                                                   round(size[1] / 0.25) + 1), kind


def terrain_kinds():
    from genesis_lite.utils import terrain
    return list(terrain.DEFAULTS)


def test_a_ball_rolls_down_generated_stairs_and_a_box_rests_on_flat_ground(f64):
    """Stairs going down along x (Genesis's default step -0.1 m): a ball set on the top step at
    the far edge rolls off and ends lower; a box on the flat subterrain comes to rest on it."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01))
    scene.add_entity(gs.morphs.Terrain(n_subterrains=(2, 1), subterrain_size=(3.0, 3.0),
                                       subterrain_types=[["stairs_terrain"], ["flat_terrain"]]))
    ball = scene.add_entity(gs.morphs.Sphere(radius=0.1, pos=(0.3, 1.5, 0.0)))
    box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.2, 0.2), pos=(4.5, 1.5, 0.2)))
    scene.build()
    ball.set_dofs_velocity(torch.tensor([1.5, 0.0, 0.0, 0.0, 0.0, 0.0]))
    for _ in range(200):
        scene.step()
    assert float(ball.get_pos()[2]) < -0.2 and float(ball.get_pos()[0]) > 1.0
    assert float(box.get_pos()[2]) == pytest.approx(0.1, abs=2e-3)
    assert float(np.linalg.norm(box.get_vel().numpy())) < 1e-3


@pytest.mark.parametrize("kwargs, said", [
    ({"n_subterrains": (0, 2)}, "'n_subterrains' must be two integers >= 1"),
    ({"subterrain_size": (1.1, 2.0)}, "'subterrain_size' must be two positive multiples"),
    ({"n_subterrains": (1, 2), "subterrain_types": [["flat_terrain"]]}, "'subterrain_types' must be"),
    ({"subterrain_types": "lava_terrain"}, "expected kinds among"),
    ({"subterrain_parameters": {"wave_terrain": {"waves": 3}}}, "'subterrain_parameters' expected"),
    ({"randomize": "yes"}, "'randomize'"),
    ({"name": 3}, "'name' must be a string"),
    ({"uv_scale": 2.0}, "'uv_scale' is a Genesis option"),
    ({"n_subterrains": [1, [2]]}, "'n_subterrains' must be two integers"),
    ({"subterrain_size": ("a", "b")}, "'subterrain_size' must be two positive multiples"),
    ({"subterrain_size": (1e-12, 12.0)}, "'subterrain_size' must be two positive multiples"),
    ({"subterrain_types": None}, "'subterrain_types' must be"),
    ({"n_subterrains": (1, 1), "subterrain_types": [[["flat_terrain"]]]}, "expected kinds among"),
    ({"subterrain_parameters": 0}, "'subterrain_parameters' must be a dict"),
    ({"subterrain_parameters": {"wave_terrain": None}}, "'subterrain_parameters' expected"),
    ({"subterrain_parameters": {"pyramid_stairs_terrain": {"step_width": 0.1}}}, "'step_width' of pyramid_stairs"),
    ({"subterrain_parameters": {"stairs_terrain": {"step_width": -1.0}}}, "'step_width' of stairs"),
    ({"subterrain_parameters": {"stepping_stones_terrain": {"stone_distance": -0.25}}}, "'stone_distance'"),
    ({"subterrain_parameters": {"random_uniform_terrain": {"min_height": 0.2}}}, "'max_height' of random"),
    ({"subterrain_parameters": {"random_uniform_terrain": {"downsampled_scale": 0}}}, "'downsampled_scale'"),
    ({"subterrain_parameters": {"fractal_terrain": {"levels": 64}}}, "'levels' of fractal"),
    ({"subterrain_parameters": {"sloped_terrain": {"slope": float("nan")}}}, "'slope' of sloped_terrain must be a"),
    ({"subterrain_parameters": {"wave_terrain": {"amplitude": None}}}, "'amplitude' of wave_terrain must be a"),
    ({"subterrain_parameters": {"wave_terrain": {"num_waves": float("inf")}}}, "'num_waves' of wave_terrain"),
    ({"subterrain_parameters": {"discrete_obstacles_terrain": {"max_size": 0.5}}}, "'max_size' of discrete"),
])
def test_generated_terrain_bad_input_is_named(kwargs, said):
    with pytest.raises(InvalidInputError, match=said):
        gs.morphs.Terrain(**kwargs)


def _a1_on_terrain_mujoco(path, heights, hs, corner, cone):
    """tests.contact_scenes.a1_mujoco's a1 with its plane replaced by MuJoCo's height field of
    ``heights`` (nx, ny) m at corner + (i, j)·hs, as gs.morphs.Terrain lays it: rows along y (an
    MjSpec's data from the near edge: only MuJoCo's XML reader flips the rows), its lowest point at
    the geom's z, base 1 m."""
    from tests.contact_scenes import a1_mujoco
    from tests.test_a1_vs_mujoco import DT, KP, KV, STAND, Z

    nx, ny = heights.shape
    low, high = heights.min(), heights.max()
    half = ((nx - 1) * hs / 2, (ny - 1) * hs / 2)

    def ground(spec):
        field = spec.add_hfield(name="terrain", nrow=ny, ncol=nx, size=[half[0], half[1], high - low, 1.0],
                                userdata=np.asarray(heights.T, dtype=np.float32).ravel().tolist())
        spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_HFIELD, hfieldname=field.name,
                                pos=[corner[0] + half[0], corner[1] + half[1], low])

    m, d = a1_mujoco(path, Z, STAND, KP, KV, DT, ground)
    m.opt.cone = {"pyramidal": mujoco.mjtCone.mjCONE_PYRAMIDAL, "elliptic": mujoco.mjtCone.mjCONE_ELLIPTIC}[cone]
    return m, d


@pytest.mark.parametrize("cone", ["pyramidal", pytest.param("elliptic", marks=pytest.mark.slow)])
def test_a1_on_a_height_field_steps_like_mujoco(f64, cone):
    """pybullet_data's a1 under moving PD targets on bumpy ground (a Terrain of ±4 mm heights,
    10 cm apart, under it; MuJoCo's height field of the same data), re-synced from MuJoCo before
    each of 500 steps: in every step whose contacts are the feet's (spheres, whose height-field
    contacts are MuJoCo 4.0's; most steps), qvel and qpos ≤ 1e-7 from MuJoCo's and the same
    contacts (count, positions to 1e-9 m)."""
    from tests.conftest import pybullet
    from tests.test_a1_vs_mujoco import STEPS, _build_ours, resynced_step

    path = pybullet("a1", "a1.urdf")
    heights = np.random.default_rng(2).uniform(-0.004, 0.004, (21, 21))
    hs = 0.1
    scene, robot, legs = _build_ours(path, cone, gs.morphs.Terrain(height_field=heights, horizontal_scale=hs,
                                                                   vertical_scale=1.0, pos=(-1.0, -1.0, 0.0)))
    m, d = _a1_on_terrain_mujoco(path, heights, hs, (-1.0, -1.0), cone)
    feet = {g for g in range(m.ngeom) if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE}
    compared = 0
    for step in range(STEPS):
        dv, dq = resynced_step(scene, robot, legs, m, d, step)
        if not {int(c.geom[1]) for c in d.contact[:d.ncon]} <= feet:
            continue  # (a calf box or the trunk on the ground: MuJoCo 4.0's polytope contacts, module docstring)
        assert dv <= 1e-7 and dq <= 1e-7, (step, dv, dq)
        contacts = robot.get_contacts()
        assert len(contacts["position"]) == d.ncon, step
        if d.ncon:
            theirs = np.array([c.pos for c in d.contact[:d.ncon]])
            assert np.abs(contacts["position"].numpy() - theirs).max() <= 1e-9, step
            compared += 1
    assert compared > 0.8 * STEPS, compared
