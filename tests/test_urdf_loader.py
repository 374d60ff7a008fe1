"""URDF loader and primitive-shape builders: frames, inertias, mesh paths, errors.

References: hand computations, trimesh's numerical mass properties of fine meshes, MuJoCo's
own URDF compiler, and every URDF shipped with pybullet_data.
"""
import glob
import os
import re
import shutil

import mujoco
import numpy as np
import pybullet_data
import pytest
import trimesh

from genesis_lite.solvers.core import AssetError, GenesisException, InvalidInputError
from genesis_lite.solvers.rigid import merge, shapes
from genesis_lite.solvers.rigid.spec import JOINT_TYPES, GeomSpec
from genesis_lite.solvers.rigid.urdf import load_urdf, mat_to_quat, resolve_mesh_path

ASSETS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "assets")
PYBULLET = pybullet_data.getDataPath()
BOX_OBJ = os.path.join(ASSETS, "mesh_robot", "meshes", "link.obj")


def rot_x(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_y(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rot_z(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def by_name(specs):
    return {s.name: s for s in specs}


def write_urdf(tmp_path, body, name="robot.urdf"):
    """Write a URDF whose <robot> contains `body`; returns its path."""
    path = tmp_path / name
    path.write_text(f'<?xml version="1.0"?>\n<robot name="t">\n{body}\n</robot>\n')
    return str(path)


LINK = '<link name="{}"><inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial></link>'


def joint(name, jtype, parent="a", child="b", extra=""):
    return f'<joint name="{name}" type="{jtype}"><parent link="{parent}"/><child link="{child}"/>{extra}</joint>'


# ------------------------------------------------------------------ tree, joints, frames


def test_pendulum2_tree_and_joints():
    specs = load_urdf(os.path.join(ASSETS, "pendulum2.urdf"))
    assert [s.name for s in specs] == ["base", "link1", "link2"]
    assert [s.parent for s in specs] == [-1, 0, 1]
    assert [s.joint_type for s in specs] == ["fixed", "revolute", "revolute"]
    assert [s.joint_name for s in specs] == ["", "joint1", "joint2"]
    base, link1, link2 = specs
    np.testing.assert_array_equal(base.pos, 0)
    np.testing.assert_array_equal(base.quat, [1, 0, 0, 0])
    np.testing.assert_allclose(link1.pos, [0, 0.1, 0])
    np.testing.assert_allclose(link2.axis, [0, 1, 0])
    assert (link1.lower, link1.upper, link1.effort) == (-3.0, 3.0, 50.0)
    assert link2.damping == 0.05 and link1.damping == 0.0
    assert [g.type for g in link2.geoms] == ["cylinder", "sphere"]
    np.testing.assert_allclose(link2.geoms[0].size, [0.02, 0.4])


def test_inertia_rotated_by_inertial_rpy():
    link2 = load_urdf(os.path.join(ASSETS, "pendulum2.urdf"))[2]
    inertia = np.array([[0.011, -0.0008, 0.0012], [-0.0008, 0.012, 0.0004], [0.0012, 0.0004, 0.002]])
    rot = rot_z(0.5) @ rot_y(-0.2) @ rot_x(0.3)  # URDF rpy = fixed-axis x, then y, then z
    np.testing.assert_allclose(link2.inertia, rot @ inertia @ rot.T, atol=1e-15)
    np.testing.assert_allclose(link2.com, [-0.005, 0.002, -0.2])
    assert link2.mass == 0.8


def test_joint_quaternion_from_rpy():
    wrist = by_name(load_urdf(os.path.join(ASSETS, "arm3.urdf")))["hand"]
    np.testing.assert_allclose(wrist.quat, [np.cos(np.pi / 4), 0, np.sin(np.pi / 4), 0], atol=1e-15)
    np.testing.assert_allclose(wrist.pos, [0, 0, -0.15])


def test_mat_to_quat_round_trip():
    rng = np.random.default_rng(0)
    quats = np.vstack([rng.normal(size=(200, 4)), np.eye(4), [[0, 1, 1, 0], [1e-9, 0, 0, 1]]])
    for q in quats:
        q = q / np.linalg.norm(q)
        q = -q if q[0] < 0 else q
        got = mat_to_quat(shapes.quat_to_mat(q))
        assert np.allclose(got, q, atol=1e-12) or (abs(q[0]) < 1e-8 and np.allclose(got, -q, atol=1e-12))


def test_arm3_joint_kinds_and_limits():
    specs = by_name(load_urdf(os.path.join(ASSETS, "arm3.urdf")))
    assert list(specs) == ["base", "upper", "slider", "hand", "ee"]
    assert [s.joint_type for s in specs.values()] == ["fixed", "revolute", "prismatic", "revolute", "fixed"]
    np.testing.assert_allclose(specs["slider"].axis, [0, 0, 1])  # "0 0 2" normalised
    hand = specs["hand"]  # continuous
    assert (hand.lower, hand.upper, hand.effort) == (-np.inf, np.inf, np.inf)
    assert (specs["slider"].lower, specs["slider"].upper) == (-0.1, 0.2)
    assert (specs["upper"].damping, specs["upper"].frictionloss) == (0.1, 0.02)
    assert specs["ee"].joint_name == "ee_joint" and specs["ee"].parent == 3


def test_depth_first_order_follows_joint_order(tmp_path):
    # joints listed b-branch first although link c is declared before b
    body = "".join(LINK.format(n) for n in "acbd") + joint("j1", "fixed", "a", "b") + \
        joint("j2", "fixed", "a", "c") + joint("j3", "fixed", "b", "d")
    specs = load_urdf(write_urdf(tmp_path, body))
    assert [s.name for s in specs] == ["a", "b", "d", "c"]
    assert [s.parent for s in specs] == [-1, 0, 1, 0]


def test_quadruped():
    specs = load_urdf(os.path.join(ASSETS, "quadruped.urdf"))
    assert len(specs) == 13 and specs[0].name == "body"
    assert sum(s.joint_type == "revolute" for s in specs) == 12
    assert all(np.isfinite(s.lower) and np.isfinite(s.upper) for s in specs[1:])
    np.testing.assert_allclose(sum(s.mass for s in specs), 5.0 + 4 * 1.3)


def test_pybullet_cartpole_and_kuka():
    cart = load_urdf(os.path.join(PYBULLET, "cartpole.urdf"))
    assert [(s.name, s.joint_type) for s in cart] == [
        ("slideBar", "fixed"), ("cart", "prismatic"), ("pole", "revolute")]
    assert cart[2].lower == -np.inf  # continuous
    kuka = load_urdf(os.path.join(PYBULLET, "kuka_iiwa", "model.urdf"))
    assert [s.name for s in kuka] == [f"lbr_iiwa_link_{i}" for i in range(8)]
    assert [s.parent for s in kuka] == list(range(-1, 7))
    assert all(s.joint_type == "revolute" and s.damping == 0.5 for s in kuka[1:])
    assert all(g.type == "mesh" and g.vertices.shape[1] == 3 for s in kuka for g in s.geoms)


def _mujoco_model(urdf_path, tmp_path):
    """MuJoCo's compile of the URDF, keeping every body (no fusing of fixed joints)."""
    text = re.sub(r"<\?xml[^>]*\?>", "", open(urdf_path).read())
    compiler = (f'<mujoco><compiler fusestatic="false" discardvisual="true" strippath="false" '
                f'meshdir="{os.path.dirname(urdf_path)}"/></mujoco>')
    text = re.sub(r"(<robot[^>]*>)", r"\1" + compiler, text, count=1)
    path = tmp_path / "mj.urdf"
    path.write_text(text)
    return mujoco.MjModel.from_xml_path(str(path))


@pytest.mark.parametrize("path", [
    os.path.join(ASSETS, "pendulum2.urdf"), os.path.join(ASSETS, "arm3.urdf"),
    os.path.join(ASSETS, "quadruped.urdf"), os.path.join(PYBULLET, "cartpole.urdf"),
    os.path.join(PYBULLET, "kuka_iiwa", "model.urdf")], ids=os.path.basename)
def test_matches_mujoco_urdf_compiler(path, tmp_path):
    specs = load_urdf(path, rho=shapes.MUJOCO_DENSITY)  # (MuJoCo's compiler weighs at its density)
    model = _mujoco_model(path, tmp_path)
    assert [model.body(i).name for i in range(1, model.nbody)] == [s.name for s in specs]
    for i, spec in enumerate(specs[1:], start=2):
        body = model.body(i)
        np.testing.assert_allclose(spec.pos, body.pos, atol=1e-12)
        np.testing.assert_allclose(spec.quat, body.quat * np.sign(body.quat[0] or 1), atol=1e-12)
    for i, spec in enumerate(specs, start=1):
        body = model.body(i)
        rot = shapes.quat_to_mat(body.iquat)
        np.testing.assert_allclose(spec.mass, body.mass[0], rtol=1e-12)
        np.testing.assert_allclose(spec.inertia, rot @ np.diag(body.inertia) @ rot.T, atol=1e-12)
        if spec.mass > 0:
            np.testing.assert_allclose(spec.com, body.ipos, atol=1e-12)


# ------------------------------------------------------------------ mass properties


def test_inertia_from_box_collision():
    slider = by_name(load_urdf(os.path.join(ASSETS, "arm3.urdf"), rho=500.0))["slider"]
    x, y, z = 0.04, 0.05, 0.2
    mass = 500.0 * x * y * z
    rot = rot_z(0.3)
    box = mass / 12 * np.diag([y * y + z * z, x * x + z * z, x * x + y * y])
    np.testing.assert_allclose(slider.mass, mass)
    np.testing.assert_allclose(slider.com, [0, 0, -0.05], atol=1e-15)
    np.testing.assert_allclose(slider.inertia, rot @ box @ rot.T, atol=1e-15)


def test_link_without_inertial_or_geometry_is_massless(tmp_path):
    specs = load_urdf(write_urdf(tmp_path, '<link name="a"/>'))
    assert specs[0].mass == 0 and not specs[0].inertia.any() and specs[0].geoms == []


def test_inertia_from_visual_when_no_collision(tmp_path):
    body = '<link name="a"><visual><geometry><sphere radius="0.1"/></geometry></visual></link>'
    (a,) = load_urdf(write_urdf(tmp_path, body), rho=1000.0)
    np.testing.assert_allclose(a.mass, 1000 * 4 / 3 * np.pi * 1e-3)
    assert a.geoms == []  # visuals never collide


def _fine_mesh(kind, r, h):
    if kind == "sphere":
        return trimesh.creation.icosphere(subdivisions=5, radius=r)
    if kind == "cylinder":
        return trimesh.creation.cylinder(radius=r, height=h, sections=256)
    if kind == "capsule":
        return trimesh.creation.capsule(height=h, radius=r, count=[128, 128])
    return trimesh.creation.box(extents=(r, h, 0.3))


@pytest.mark.parametrize("kind", ["sphere", "cylinder", "capsule", "box"])
def test_primitive_inertia_matches_fine_mesh(kind):
    r, h, rho = 0.15, 0.6, 700.0
    build = {"sphere": lambda: shapes.sphere_link(r, rho), "cylinder": lambda: shapes.cylinder_link(r, h, rho),
             "capsule": lambda: shapes.capsule_link(r, h, rho), "box": lambda: shapes.box_link((r, h, 0.3), rho)}
    (link,) = build[kind]()
    mesh = _fine_mesh(kind, r, h)
    mesh.density = rho
    assert link.joint_type == "fixed" and link.parent == -1 and link.name == kind
    np.testing.assert_allclose(link.mass, mesh.mass, rtol=1e-2)
    np.testing.assert_allclose(link.inertia, mesh.moment_inertia, rtol=1e-2,
                               atol=1e-2 * np.abs(mesh.moment_inertia).max())
    np.testing.assert_allclose(link.com, 0, atol=1e-12)


def test_mesh_link_watertight_and_open():
    size = np.array([0.1, 0.1, 0.2]) * [2, 1, 1]
    (link,) = shapes.mesh_link(BOX_OBJ, scale=(2, 1, 1), rho=1000.0)
    mass = 1000 * np.prod(size)
    np.testing.assert_allclose(link.mass, mass)
    np.testing.assert_allclose(link.inertia, shapes.box_inertia(size, mass), atol=1e-12)
    # an open mesh (one face removed) falls back to its convex hull: the same box
    geom = link.geoms[0]
    mass2, com2, inertia2 = shapes.mesh_mass_properties(geom.vertices, geom.faces[1:], 1000.0)
    np.testing.assert_allclose([mass2, *com2], [mass, 0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(inertia2, link.inertia, atol=1e-12)


def test_geometry_mass_properties_parallel_axis():
    a = GeomSpec("sphere", np.array([0.1]), pos=np.array([0.5, 0, 0]))
    b = GeomSpec("sphere", np.array([0.1]), pos=np.array([-0.5, 0, 0]))
    mass, com, inertia = shapes.geometry_mass_properties([a, b], 1000.0)
    m1 = 1000 * 4 / 3 * np.pi * 0.1**3
    np.testing.assert_allclose(mass, 2 * m1)
    np.testing.assert_allclose(com, 0, atol=1e-15)
    i0 = 0.4 * m1 * 0.01
    np.testing.assert_allclose(np.diag(inertia), [2 * i0, 2 * i0 + 2 * m1 * 0.25, 2 * i0 + 2 * m1 * 0.25])


def test_plane_link():
    (plane,) = shapes.plane_link()
    assert plane.mass == 0 and plane.geoms[0].type == "plane"
    np.testing.assert_array_equal(plane.geoms[0].size, [0, 0, 1])


@pytest.mark.parametrize("call, arg", [
    (lambda: shapes.box_link((1, -1, 1)), "size"), (lambda: shapes.box_link((1, 1)), "size"),
    (lambda: shapes.sphere_link(np.nan), "radius"), (lambda: shapes.cylinder_link(1, 0), "height"),
    (lambda: shapes.capsule_link(0.1, 0.2, rho=-1), "rho"), (lambda: shapes.mesh_link(BOX_OBJ, 0), "scale"),
    (lambda: load_urdf(os.path.join(ASSETS, "arm3.urdf"), rho=0), "rho"), (lambda: load_urdf(None), "path")])
def test_bad_arguments(call, arg):
    with pytest.raises(InvalidInputError, match=f"'{arg}' expected"):
        call()


# ------------------------------------------------------------------ mesh paths


def test_package_and_relative_mesh_paths():
    specs = by_name(load_urdf(os.path.join(ASSETS, "mesh_robot", "urdf", "mesh_robot.urdf"), rho=1000.0))
    box = trimesh.load(BOX_OBJ, force="mesh")
    np.testing.assert_allclose(specs["base"].geoms[0].vertices, box.vertices)
    np.testing.assert_allclose(specs["arm"].geoms[0].vertices, box.vertices * [1, 1, 2])
    arm = specs["arm"]  # no <inertial>: a solid 0.1 x 0.1 x 0.4 box 0.2 m above the joint
    mass = 1000 * 0.1 * 0.1 * 0.4
    np.testing.assert_allclose(arm.mass, mass)
    np.testing.assert_allclose(arm.com, [0, 0, 0.2], atol=1e-12)
    np.testing.assert_allclose(arm.inertia, shapes.box_inertia([0.1, 0.1, 0.4], mass), atol=1e-12)


def test_package_uri_found_in_ancestor_folder(tmp_path):
    # ros-style workspace: ws/src/pkg/{urdf,meshes}, URDF nested two folders deep
    pkg = tmp_path / "ws" / "src" / "pkg"
    (pkg / "meshes").mkdir(parents=True)
    (pkg / "urdf" / "robots").mkdir(parents=True)
    shutil.copy(BOX_OBJ, pkg / "meshes" / "m.obj")
    found, tried = resolve_mesh_path("package://pkg/meshes/m.obj", str(pkg / "urdf" / "robots"))
    assert found == str(pkg / "meshes" / "m.obj") and found in tried
    assert resolve_mesh_path(BOX_OBJ, "/nowhere") == (BOX_OBJ, [BOX_OBJ])
    # another package's mesh, where the URDF's own package has a file of the same name (it was taken)
    gripper = tmp_path / "ws" / "src" / "gripper" / "meshes"
    gripper.mkdir(parents=True)
    shutil.copy(BOX_OBJ, gripper / "m.obj")
    found, _ = resolve_mesh_path("package://gripper/meshes/m.obj", str(pkg / "urdf" / "robots"))
    assert found == str(gripper / "m.obj")
    # a package folder named otherwise than its package: the path without the package's name
    found, _ = resolve_mesh_path("package://pkg_description/meshes/m.obj", str(pkg / "urdf" / "robots"))
    assert found == str(pkg / "meshes" / "m.obj")


def test_absolute_mesh_path(tmp_path):
    body = f'<link name="a"><collision><geometry><mesh filename="{BOX_OBJ}"/></geometry></collision></link>'
    (a,) = load_urdf(write_urdf(tmp_path, body), rho=1000.0)
    np.testing.assert_allclose(a.mass, 1000 * 0.002)


# ------------------------------------------------------------------ errors


def test_missing_file(tmp_path):
    path = str(tmp_path / "nope.urdf")
    with pytest.raises(AssetError, match="nope.urdf.*not found"):
        load_urdf(path)


def test_malformed_xml(tmp_path):
    path = tmp_path / "broken.urdf"
    path.write_text('<robot name="x"><link name="a"></robot>')
    with pytest.raises(AssetError, match="broken.urdf.*malformed XML"):
        load_urdf(str(path))


@pytest.mark.parametrize("jtype", ["planar", "ball"])
def test_unsupported_joint_type(tmp_path, jtype):
    path = write_urdf(tmp_path, LINK.format("a") + LINK.format("b") + joint("hip", jtype))
    with pytest.raises(AssetError) as info:
        load_urdf(path, entity_name="dog")
    msg = str(info.value)
    for part in ("robot.urdf", "'hip'", f"'{jtype}'", "revolute, continuous, prismatic, fixed", "dog"):
        assert part in msg


def test_missing_mesh(tmp_path):
    body = '<link name="foot"><collision><geometry><mesh filename="package://p/missing.stl"/></geometry></collision></link>'
    with pytest.raises(AssetError) as info:
        load_urdf(write_urdf(tmp_path, body))
    msg = str(info.value)
    for part in ("robot.urdf", "'foot'", "package://p/missing.stl", "tried", str(tmp_path / "p" / "missing.stl")):
        assert part in msg


def test_unreadable_mesh(tmp_path):
    (tmp_path / "bad.stl").write_bytes(b"solid x\nfacet normal nonsense\n")
    body = '<link name="shin"><collision><geometry><mesh filename="bad.stl"/></geometry></collision></link>'
    with pytest.raises(AssetError, match="robot.urdf.*'shin'.*bad.stl"):
        load_urdf(write_urdf(tmp_path, body))


@pytest.mark.parametrize("body, words", [
    (LINK.format("a").replace('value="1"', 'value="-2"'), ["'a'", "mass"]),
    (LINK.format("a").replace('izz="1"', 'izz="-1"'), ["'a'", "inertia", "principal moments"]),
    (LINK.format("a") + LINK.format("b") + joint("j", "revolute", extra='<axis xyz="0 0 0"/>'), ["'j'", "axis"]),
    (LINK.format("a") + LINK.format("b"), ["root", "'a'", "'b'"]),
    (LINK.format("a") + joint("j", "fixed", "a", "zz"), ["'j'", "'zz'"]),
    (LINK.format("a") + LINK.format("b") + joint("j", "fixed") + joint("k", "fixed", "b", "a"), ["root"]),
    (LINK.format("a") + LINK.format("b") + joint("j", "prismatic", extra='<dynamics damping="fast"/>'),
     ["'j'", "damping", "'fast'"]),
    ('<link name="a"><collision><geometry><box size="1 0 1"/></geometry></collision></link>', ["'a'", "box"]),
    ('<link name="a"><collision><geometry><capsule radius="1" length="1"/></geometry></collision></link>',
     ["capsule"]),
    ('<link name="a"/><joint name="j"><parent link="a"/></joint>', ["cannot parse"]),
    # what yourdfpy would fill in (izz 1, mass 0) or drop (a 4th number, a second element)
    (LINK.format("a").replace(' izz="1"', ""), ["link 'a'", "<inertia>", "without izz"]),
    (LINK.format("a").replace('<mass value="1"/>', "<mass/>"), ["link 'a'", "<mass>", "without value"]),
    (LINK.format("a") + LINK.format("b") + joint("j", "revolute", extra='<origin xyz="0 0 1 0"/>'),
     ["joint 'j'", "<origin xyz>", "3 numbers", "'0 0 1 0'"]),
    (LINK.format("a") + LINK.format("b") + joint("j", "revolute", extra='<axis xyz="0 0 1"/><axis xyz="1 0 0"/>'),
     ["joint 'j'", "one <axis>", "got 2"]),
    ('<link name="a"><collision><geometry><box size="1 1"/></geometry></collision></link>', ["link 'a'", "<box size>"]),
    ('<link name="a"><inertial><mass value="1"/></inertial><inertial><mass value="2"/></inertial></link>',
     ["link 'a'", "one <inertial>"]),
], ids=["neg-mass", "neg-inertia", "zero-axis", "two-roots", "unknown-link", "cycle", "bad-number",
        "zero-box", "unknown-geometry", "no-child", "moment-missing", "mass-value-missing", "four-numbers",
        "two-axes", "box-two-sizes", "two-inertials"])
def test_invalid_content(tmp_path, body, words):
    with pytest.raises(AssetError) as info:
        load_urdf(write_urdf(tmp_path, body))
    for word in ["robot.urdf", *words]:
        assert word in str(info.value)


def test_safety_controller_gains_mimics_and_contact_warning(tmp_path, caplog):
    """<safety_controller k_position k_velocity> are the joint's servo gains (Genesis reads them
    so), None without; <mimic> becomes the joint's (joint, multiplier, offset), defaults 1 and 0
    (a joint equality row: tests/test_equality_vs_mujoco.py); pybullet's <contact> entries other
    than lateral_friction warn, once, listed."""
    gains = '<safety_controller k_position="7" k_velocity="3" soft_lower_limit="-0.5" soft_upper_limit="0.5"/>'
    contact = '<contact><lateral_friction value="0.5"/><rolling_friction value="0.1"/><restitution value="1"/></contact>'
    body = (LINK.format("a") + LINK.format("b") + f'<link name="c">{contact}</link>' + '<link name="d"/>'
            + joint("j", "revolute", extra=gains) + joint("k", "revolute", "b", "c", extra='<mimic joint="j" multiplier="-1"/>')
            + joint("m", "prismatic", "c", "d", extra='<mimic joint="k"/>'))
    specs = by_name(load_urdf(write_urdf(tmp_path, body)))
    assert (specs["b"].kp, specs["b"].kv) == (7.0, 3.0) and (specs["c"].kp, specs["c"].kv) == (None, None)
    assert (specs["b"].mimic, specs["c"].mimic, specs["d"].mimic) == (None, ("j", -1.0, 0.0), ("k", 1.0, 0.0))
    said = [r.getMessage() for r in caplog.records if "<contact> entries" in r.getMessage()]
    assert len(said) == 1 and "restitution, rolling_friction are not simulated" in said[0]


@pytest.mark.parametrize("moments", [(1.0, 1.0, 1.9), (1.0, 1.0, 2.1), (0.3, 1.0, 1.29), (0.3, 1.0, 1.31),
                                     (0.0, 1.0, 1.0)], ids=str)
def test_an_inertia_breaking_the_triangle_inequality_warns_where_mujoco_rejects_it(tmp_path, caplog, moments):
    """Principal moments with A + B < C belong to no rigid body: MuJoCo's compiler rejects them,
    our loader simulates them as given and warns (Genesis loads such URDFs: pybullet_data's xArm
    and mini cheetah have them). The tensor is given in a turned frame (off-diagonal terms)."""
    turn = shapes.quat_to_mat(np.array([0.9, 0.3, -0.2, 0.25]) / np.linalg.norm([0.9, 0.3, -0.2, 0.25]))
    inertia = turn @ np.diag(moments) @ turn.T
    values = " ".join(f'{name}="{float(inertia[i, j])!r}"' for name, (i, j) in
                      zip(("ixx", "iyy", "izz", "ixy", "ixz", "iyz"), ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))))
    body = (LINK.format("a") + f'<link name="b"><inertial><mass value="1"/><inertia {values}/></inertial></link>'
            + joint("j", "revolute", extra='<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/>'))
    path = write_urdf(tmp_path, body)
    load_urdf(path)
    warned = any("link 'b' inertial" in r.getMessage() and "triangle inequality" in r.getMessage()
                 for r in caplog.records)
    try:
        _mujoco_model(path, tmp_path)
        rejected = False
    except ValueError as error:
        rejected = "A + B >= C" in str(error)
    assert warned == rejected == (moments[0] + moments[1] < moments[2])

def test_a_mimic_on_a_fixed_joint_warns(tmp_path, caplog):
    body = (LINK.format("a") + LINK.format("b") + LINK.format("c") + joint("j", "revolute")
            + joint("f", "fixed", "b", "c", extra='<mimic joint="j"/>'))
    specs = by_name(load_urdf(write_urdf(tmp_path, body)))
    assert specs["c"].mimic is None
    assert any("joint 'f' is fixed: its <mimic> is ignored" in r.getMessage() for r in caplog.records)


@pytest.mark.parametrize("target, given", [("k", "itself"), ("f", "a fixed joint"), ("x", "no joint of this file")])
def test_a_mimic_of_no_scalar_joint_raises(tmp_path, target, given):
    body = (LINK.format("a") + LINK.format("b") + LINK.format("c") + joint("f", "fixed")
            + joint("k", "revolute", "b", "c", extra=f'<mimic joint="{target}"/>'))
    with pytest.raises(AssetError, match=f"joint 'k' mimic expected another revolute or prismatic joint, got "
                                         f"'{target}' \\({given}\\)"):
        load_urdf(write_urdf(tmp_path, body))


# ------------------------------------------------------------------ every pybullet_data URDF

ALL_PYBULLET_URDFS = sorted(os.path.relpath(p, PYBULLET)
                            for p in glob.glob(os.path.join(PYBULLET, "**", "*.urdf"), recursive=True))


def _check_tree(specs):
    assert specs and specs[0].parent == -1
    for i, s in enumerate(specs):
        assert i == 0 or 0 <= s.parent < i
        assert s.joint_type in JOINT_TYPES
        assert np.isclose(np.linalg.norm(s.axis), 1.0) and np.isclose(np.linalg.norm(s.quat), 1.0)
        assert np.isfinite(s.mass) and s.mass >= 0
        assert np.all(np.isfinite(s.com)) and np.all(np.isfinite(s.inertia))
        np.testing.assert_allclose(s.inertia, s.inertia.T, atol=1e-12 * max(1.0, np.abs(s.inertia).max()))
        assert s.lower <= s.upper and s.effort >= 0 and s.damping >= 0 and s.frictionloss >= 0
        for g in s.geoms:
            assert g.type != "mesh" or (g.vertices.shape[1] == 3 and g.faces.shape[1] == 3)


@pytest.mark.parametrize("rel_path", ALL_PYBULLET_URDFS)
def test_every_pybullet_urdf_loads_or_raises_asset_error(rel_path):
    try:
        specs = load_urdf(os.path.join(PYBULLET, rel_path))
    except GenesisException as exc:
        assert rel_path.split("/")[-1] in str(exc)
        return
    _check_tree(specs)


@pytest.mark.parametrize("shape, drawn", [('<sphere radius="0"/>', False), ('<cylinder radius="0" length="0.1"/>', False),
                                          ('<box size="0.1 0 0"/>', False), ('<box size="0.1 0 0.2"/>', True),
                                          ('<cylinder radius="0.1" length="0"/>', True)])
def test_a_visual_of_zero_size_weighs_nothing_and_draws_what_it_has(tmp_path, shape, drawn):
    """A visual primitive with a zero dimension holds no volume; it is drawn when it has a surface
    (a flat box or disc, as pybullet draws them) and dropped when it has none (laikago_toes.urdf's
    toe markers: spheres of radius 0). Its origin is still checked; a negative size stays an error,
    and so does a collision shape of zero size."""
    marker = f'<visual><geometry>{shape}</geometry></visual>'
    solid = '<visual><geometry><sphere radius="0.1"/></geometry></visual>'
    (a,) = load_urdf(write_urdf(tmp_path, f'<link name="a">{marker}{solid}</link>'), rho=1000.0)
    assert [v.type for v in a.visuals] == ([shape[1:4].replace("cyl", "cylinder")] if drawn else []) + ["sphere"]
    np.testing.assert_allclose(a.mass, 1000 * 4 / 3 * np.pi * 1e-3)  # the solid sphere's alone
    (b,) = load_urdf(write_urdf(tmp_path, f'<link name="b">{marker}</link>', name="marker_only.urdf"), rho=1000.0)
    assert len(b.visuals) == drawn and b.mass == 0
    with pytest.raises(AssetError, match="non-negative finite"):
        negative = shape.replace('"0"', '"-0.1"').replace(" 0 ", " -0.1 ").replace(" 0\"", " -0.1\"")
        load_urdf(write_urdf(tmp_path, f'<link name="c"><visual><geometry>{negative}</geometry></visual></link>',
                             name="negative.urdf"))
    with pytest.raises(AssetError, match="origin"):
        load_urdf(write_urdf(tmp_path, f'<link name="n"><visual><origin xyz="nan 0 0"/><geometry>{shape}</geometry>'
                                       f'</visual></link>', name="nan_origin.urdf"))
    with pytest.raises(AssetError, match="positive finite"):
        load_urdf(write_urdf(tmp_path, f'<link name="d"><collision><geometry>{shape}</geometry></collision></link>',
                             name="zero_collision.urdf"))


def test_roslaunch_environment_substitutions_are_expanded(tmp_path, monkeypatch):
    """$(optenv NAME default) takes the variable or the default, $(env NAME) the variable (an error
    when unset), as roslaunch does (pybullet_data's husky.urdf keeps one); any other substitution
    ($(find ...), $(arg ...)) is an AssetError saying to run xacro, unless in a comment (xarm6's
    file has one). A changed variable is seen through the asset cache."""
    body = ('<!-- <xacro:gripper attach_to="$(arg prefix)link6"/> -->' + LINK.format("a") + LINK.format("b")
            + '<joint name="j" type="fixed"><parent link="a"/><child link="b"/>'
              '<origin xyz="$(optenv GL_TEST_XYZ 0.1 0.2 0.3)" rpy="$(env GL_TEST_RPY)"/></joint>')
    path = write_urdf(tmp_path, body)
    monkeypatch.delenv("GL_TEST_XYZ", raising=False)
    monkeypatch.setenv("GL_TEST_RPY", "0 0 0")
    np.testing.assert_allclose(by_name(load_urdf(path))["b"].pos, [0.1, 0.2, 0.3])
    monkeypatch.setenv("GL_TEST_XYZ", "1 2 3")
    np.testing.assert_allclose(by_name(load_urdf(path))["b"].pos, [1.0, 2.0, 3.0])
    monkeypatch.delenv("GL_TEST_RPY")
    with pytest.raises(AssetError, match=r"\$\(env GL_TEST_RPY\).*not set"):
        load_urdf(path)
    found = write_urdf(tmp_path, LINK.format("a").replace('value="1"', 'value="$(arg mass)"', 1), name="arg.urdf")
    with pytest.raises(AssetError, match="expand the file with xacro"):
        load_urdf(found)


# ------------------------------------------------------------------ a floating root, a massless <inertial>
FLOATING = ('<link name="world"/>'
            '<joint name="float" type="floating"><parent link="world"/><child link="box"/>'
            '<origin xyz="0.1 0 0.2" rpy="0 0 0.5"/></joint>'
            '<link name="box"><inertial><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial>'
            '<collision><geometry><box size="0.1 0.2 0.3"/></geometry></collision></link>')


def test_floating_joint_under_an_empty_root_makes_its_child_the_root(tmp_path, caplog):
    """Genesis's tower assets: an empty "world" root holds the body on a floating joint. The body
    is the root (the empty one left out), at the joint's origin, named by it; its <inertial> states
    no mass, so it is weighed from its box at rho (no warning: its inertia is all zeros)."""
    (box,) = load_urdf(write_urdf(tmp_path, FLOATING), rho=500.0)
    assert (box.name, box.parent, box.joint_name, box.joint_type) == ("box", -1, "float", "fixed")
    np.testing.assert_allclose(box.pos, [0.1, 0.0, 0.2])
    np.testing.assert_allclose(box.quat, [np.cos(0.25), 0, 0, np.sin(0.25)], atol=1e-15)
    mass = 500.0 * 0.1 * 0.2 * 0.3
    np.testing.assert_allclose(box.mass, mass, rtol=1e-14)
    np.testing.assert_allclose(box.inertia, mass / 12 * np.diag([0.13, 0.10, 0.05]), rtol=1e-12)
    assert not [r for r in caplog.records if r.levelname == "WARNING"]


@pytest.mark.parametrize("body", [
    FLOATING.replace('<link name="world"/>', LINK.format("world")),  # a root with mass
    LINK.format("a") + LINK.format("b") + LINK.format("c") + joint("j", "revolute", "a", "b", '<axis xyz="0 0 1"/>')
    + joint("float", "floating", "b", "c"),  # below a moving link
])
def test_other_floating_joints_raise(tmp_path, body):
    with pytest.raises(AssetError, match=r"joint 'float' is floating: expected the file's one floating joint"):
        load_urdf(write_urdf(tmp_path, body), entity_name="ball")


def test_inertial_without_mass_is_weighed_from_shapes_with_a_warning(tmp_path, caplog):
    body = ('<link name="a"><inertial><origin xyz="0 0 1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/>'
            '</inertial><collision><geometry><sphere radius="0.1"/></geometry></collision></link>')
    (a,) = load_urdf(write_urdf(tmp_path, body), rho=1000.0)
    np.testing.assert_allclose(a.mass, 1000 * 4 / 3 * np.pi * 1e-3)
    np.testing.assert_allclose(a.com, 0.0, atol=1e-15)
    assert any("states no <mass>" in r.getMessage() for r in caplog.records)


def test_floating_urdf_entity_falls_freely(f64, tmp_path):
    """The floating body is the entity's base: free, at the morph pose composed with the joint's
    origin, falling as semi-implicit Euler integrates gravity (z_n = z_0 − g·dt²·n(n+1)/2); fixed=True
    welds it."""
    import genesis_lite as gs
    path = write_urdf(tmp_path, FLOATING)
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, gravity=(0.0, 0.0, -9.81)))
    free = scene.add_entity(gs.morphs.URDF(file=path, pos=(1.0, 0.0, 2.0)))
    welded = scene.add_entity(gs.morphs.URDF(file=path, pos=(-1.0, 0.0, 2.0), fixed=True))
    scene.build()
    assert free.n_dofs == 6 and welded.n_dofs == 0 and [link.name for link in free.links] == ["box"]
    np.testing.assert_allclose(free.get_pos(), [1.1, 0.0, 2.2], atol=1e-15)
    for _ in range(20):
        scene.step()
    np.testing.assert_allclose(free.get_pos(), [1.1, 0.0, 2.2 - 9.81 * 0.01 ** 2 * 20 * 21 / 2], rtol=0, atol=1e-12)
    np.testing.assert_allclose(welded.get_pos(), [-0.9, 0.0, 2.2], atol=1e-15)


def test_a_root_at_the_files_origin_keeps_the_morphs_quaternion(f64):
    """Only a floating root's file pose is composed with the morph's: other roots take the morph's
    quaternion as given, sign and bits (composing renormalised it and turned w ≥ 0)."""
    import genesis_lite as gs
    scene = gs.Scene()
    quat = np.array([-0.5, 0.5, 0.5, 0.5])
    boxes = [scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(k, 0.0, 1.0), quat=quat)) for k in range(2)]
    turned = scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(2.0, 0.0, 1.0), euler=(0.0, 0.0, 270.0)))
    scene.build()
    np.testing.assert_array_equal(boxes[0].get_quat(), quat)
    np.testing.assert_array_equal(turned.get_quat(), turned.morph.quat)
    assert turned.morph.quat[0] < 0  # (Genesis's quaternion for that turn)



# ------------------------------------------------------------------ Y-up mesh files (file_meshes_are_zup)
def _box_files(tmp_path):
    """An .obj and a .glb of one box, extents 0.1 × 0.2 × 0.3 m, its centre at (0.01, 0.02, 0.03)."""
    box = trimesh.creation.box(extents=(0.1, 0.2, 0.3))
    box.apply_translation((0.01, 0.02, 0.03))
    paths = {kind: str(tmp_path / f"box.{kind}") for kind in ("obj", "glb")}
    for kind, path in paths.items():
        box.export(path)
    return paths


def test_y_up_meshes_are_turned_to_z_up(f64, tmp_path):
    """A Y-up mesh is turned (X, Y, Z) → (X, −Z, Y) before anything else reads it, as Genesis's
    file_meshes_are_zup=False: a rigid Mesh, an MPM body's particles, and a URDF's meshes, collision
    and weighed too (Genesis 1.4.5 turns only a URDF's visual meshes: its collision shapes and masses
    come from MuJoCo's reading, unturned; here the shape drawn is the one that collides); a glTF Mesh
    is Y-up unless told otherwise (Genesis's None)."""
    import genesis_lite as gs
    paths = _box_files(tmp_path)
    urdf = write_urdf(tmp_path, '<link name="box"><collision><geometry><mesh filename="box.obj"/></geometry>'
                                '</collision></link>')
    scene = gs.Scene()
    at = (0.0, 0.0, 0.5)
    entities = {
        "obj as it is": scene.add_entity(gs.morphs.Mesh(file=paths["obj"], pos=at, fixed=True)),
        "obj turned": scene.add_entity(gs.morphs.Mesh(file=paths["obj"], pos=at, fixed=True, file_meshes_are_zup=False)),
        "glb (None: turned)": scene.add_entity(gs.morphs.Mesh(file=paths["glb"], pos=at, fixed=True)),
        "glb as it is": scene.add_entity(gs.morphs.Mesh(file=paths["glb"], pos=at, fixed=True, file_meshes_are_zup=True)),
        "urdf as it is": scene.add_entity(gs.morphs.URDF(file=urdf, pos=at, fixed=True)),
        "urdf turned": scene.add_entity(gs.morphs.URDF(file=urdf, pos=at, fixed=True, file_meshes_are_zup=False)),
    }
    scene.build()
    mpm = gs.Scene(mpm_options=gs.options.MPMOptions(lower_bound=(-1.0, -1.0, 0.0), upper_bound=(1.0, 1.0, 1.0)))
    particles = mpm.add_entity(gs.morphs.Mesh(file=paths["obj"], pos=at, file_meshes_are_zup=False),
                               material=gs.materials.MPM.Elastic())
    mpm.build()
    as_it_is = np.array([[0.01, 0.02, 0.03], [0.1, 0.2, 0.3]])  # (centre, extents)
    turned = np.array([[0.01, -0.03, 0.02], [0.1, 0.3, 0.2]])
    for name, entity in entities.items():
        low, high = entity.get_AABB().numpy()
        expected = as_it_is if "as it is" in name else turned
        np.testing.assert_allclose([(low + high) / 2 - at, high - low], expected, atol=1e-7, err_msg=name)  # (glb: f32)
    mass = shapes.OBJECT_DENSITY * 0.1 * 0.2 * 0.3  # (a lone link: Genesis's density of a plain object)
    for name in ("urdf as it is", "urdf turned"):  # (weighed from the turned box: the same mass, its com turned)
        np.testing.assert_allclose(entities[name].get_links_mass().numpy(), [mass], rtol=1e-9)
    spread = particles.get_particles_pos().numpy()
    np.testing.assert_allclose(spread.max(axis=0) - spread.min(axis=0), [0.1, 0.3, 0.2], atol=0.03)


def test_merging_a_weighed_part_into_a_stated_one_keeps_the_stated_mass_as_genesis(tmp_path):
    """Genesis's merge_inertia: a fixed child without <inertial> adds no mass to a parent whose
    file states one (a pad on r: r keeps its 2 kg), a parent without one takes its stated child's
    alone (arm, no <inertial>, takes its tip's 0.5 kg at the tip), two weighed parts weigh together
    (the sensor and the bracket on base). Genesis 1.4.5 on the first two: r 2.0 kg, arm 0.5 kg."""
    stated = '<inertial><mass value="{}"/><inertia ixx="0.01" iyy="0.02" izz="0.03" ixy="0" ixz="0" iyz="0"/></inertial>'
    box = '<collision><geometry><box size="{0} {0} {0}"/></geometry></collision>'
    fixed = '<joint name="{}" type="fixed"><parent link="{}"/><child link="{}"/><origin xyz="0 0 0.2"/></joint>'
    body = (f'<link name="r">{stated.format(2.0)}{box.format(0.1)}</link><link name="pad">{box.format(0.06)}</link>'
            f'<link name="arm">{box.format(0.05)}</link><link name="tip">{stated.format(0.5)}{box.format(0.04)}</link>'
            f'<link name="base">{box.format(0.1)}</link><link name="sensor">{box.format(0.02)}</link>'
            '<joint name="h" type="revolute"><parent link="r"/><child link="arm"/><origin xyz="0 0 0.2"/>'
            '<axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="10" velocity="1"/></joint>'
            '<joint name="k" type="continuous"><parent link="r"/><child link="base"/><axis xyz="1 0 0"/></joint>'
            + fixed.format("t", "arm", "tip") + fixed.format("p", "r", "pad") + fixed.format("s", "base", "sensor"))
    path = write_urdf(tmp_path, body)
    merged = by_name(merge.merge_fixed_links(load_urdf(path, rho=1000.0)))
    assert list(merged) == ["r", "arm", "base"]
    assert merged["r"].mass == 2.0 and np.allclose(merged["r"].com, 0) and np.allclose(merged["r"].inertia, np.diag(
        [0.01, 0.02, 0.03]))
    assert merged["arm"].mass == 0.5 and np.allclose(merged["arm"].com, [0, 0, 0.2])
    assert np.allclose(merged["arm"].inertia, np.diag([0.01, 0.02, 0.03]))
    assert merged["base"].mass == pytest.approx(1000.0 * (0.1 ** 3 + 0.02 ** 3), rel=1e-12)
    # a massless stated child leaves its weighed parent weighed (Genesis weighs a moving link of
    # mass 0 from its shapes again)
    path = write_urdf(tmp_path, f'<link name="a">{box.format(0.1)}</link><link name="z">{stated.format(0.0)}</link>'
                                + fixed.format("f", "a", "z"), name="zero.urdf")
    (alone,) = merge.merge_fixed_links(load_urdf(path, rho=1000.0))
    assert alone.mass == pytest.approx(1.0, rel=1e-12) and not alone.mass_stated
