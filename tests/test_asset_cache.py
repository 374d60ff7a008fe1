"""The asset cache (solvers/asset_cache.py): what it gives back equals what reading the file gives,
a change to any file read or to the code makes a miss, and nothing about it can fail a build.

Each test points GENESIS_LITE_CACHE_DIR at a folder of its own.
"""
import dataclasses
import json
import os
import subprocess
import sys

import numpy as np
import pybullet_data
import pytest

from genesis_lite.solvers import asset_cache
from genesis_lite.solvers.core import AssetError
from genesis_lite.solvers.rigid import shapes, urdf
from genesis_lite.solvers.rigid.collision import convex
from genesis_lite.solvers.rigid.urdf import load_urdf

KUKA = os.path.join(pybullet_data.getDataPath(), "kuka_iiwa", "model.urdf")
INERTIAL = ('<inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/>'
            '</inertial>')


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """An empty cache folder of the test's own."""
    folder = tmp_path / "cache"
    monkeypatch.setenv("GENESIS_LITE_CACHE_DIR", str(folder))
    return folder


def entries(folder, kind):
    return sorted((folder / kind).glob("*.pkl")) if (folder / kind).is_dir() else []


def assert_same(a, b):
    """Two values (dataclasses, dicts, lists of arrays, numbers, strings) are equal, bit for bit."""
    if dataclasses.is_dataclass(a):
        assert type(a) is type(b)
        for f in dataclasses.fields(a):
            assert_same(getattr(a, f.name), getattr(b, f.name))
    elif isinstance(a, dict):
        assert a.keys() == b.keys()
        for key in a:
            assert_same(a[key], b[key])
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b)
        for x, y in zip(a, b):
            assert_same(x, y)
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()
    else:
        assert a == b or (a != a and b != b), (a, b)


def no_parsing(monkeypatch):
    """Make reading a URDF, a mesh file or a hull fail: what comes back then came from the cache."""
    def fail(*args):
        raise AssertionError("computed, not read from the cache")
    monkeypatch.setattr(urdf, "_parse", fail)
    monkeypatch.setattr(urdf.shapes, "_read_mesh", fail)
    monkeypatch.setattr(convex, "_hull", fail)


def cube_obj(half):
    """An OBJ cube of half extent `half` (m)."""
    corners = [(x, y, z) for x in (-half, half) for y in (-half, half) for z in (-half, half)]
    faces = [(1, 3, 4, 2), (5, 6, 8, 7), (1, 2, 6, 5), (3, 7, 8, 4), (1, 5, 7, 3), (2, 4, 8, 6)]
    return ("".join(f"v {x} {y} {z}\n" for x, y, z in corners)
            + "".join(f"f {a} {b} {c}\nf {a} {c} {d}\n" for a, b, c, d in faces))


def mesh_robot(folder, half=0.1, extra=""):
    """A URDF in `folder` of two links, the second a mesh cube (meshes/cube.obj) of half extent `half`."""
    (folder / "meshes").mkdir(parents=True, exist_ok=True)
    (folder / "meshes" / "cube.obj").write_text(cube_obj(half))
    mesh = '<geometry><mesh filename="meshes/cube.obj"/></geometry>'
    (folder / "robot.urdf").write_text(
        f'<robot name="r"><link name="a">{INERTIAL}</link>'
        f'<link name="b">{INERTIAL}<collision>{mesh}</collision><visual>{mesh}</visual></link>'
        f'<joint name="j" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>'
        f'<limit lower="-1" upper="1" effort="5"/></joint>{extra}</robot>')
    return str(folder / "robot.urdf")


def test_a_robot_read_again_comes_from_the_cache_as_it_was_read(cache, monkeypatch):
    """A KUKA arm's links (meshes, inertias, joints, visuals) from the cache equal those read from
    the file, bit for bit, and reading them parses nothing."""
    first = load_urdf(KUKA)
    assert len(entries(cache, "urdf")) == 1
    no_parsing(monkeypatch)
    assert_same(load_urdf(KUKA), first)


def test_a_changed_mesh_file_is_read_again(cache, tmp_path, monkeypatch):
    """A mesh file rewritten after its URDF was read makes the URDF's entry a miss: its new vertices."""
    path = mesh_robot(tmp_path / "robot", half=0.1)
    assert np.abs(load_urdf(path)[1].geoms[0].vertices).max() == 0.1
    mesh_robot(tmp_path / "robot", half=0.25)
    assert np.abs(load_urdf(path)[1].geoms[0].vertices).max() == 0.25
    no_parsing(monkeypatch)
    assert np.abs(load_urdf(path)[1].geoms[0].vertices).max() == 0.25


def test_the_same_urdf_elsewhere_reads_its_own_meshes(cache, tmp_path):
    """Identical URDF bytes in two folders find the meshes of their own folder."""
    small, large = mesh_robot(tmp_path / "one", half=0.1), mesh_robot(tmp_path / "two", half=0.3)
    assert open(small, "rb").read() == open(large, "rb").read()
    assert np.abs(load_urdf(small)[1].geoms[0].vertices).max() == 0.1
    assert np.abs(load_urdf(large)[1].geoms[0].vertices).max() == 0.3


def test_a_symlinked_urdf_reads_the_meshes_beside_the_link(cache, tmp_path):
    """A URDF linked into another folder finds its relative meshes there, as without the cache."""
    mesh_robot(tmp_path / "one", half=0.1)
    mesh_robot(tmp_path / "two", half=0.3)
    os.remove(tmp_path / "two" / "robot.urdf")
    os.symlink(tmp_path / "one" / "robot.urdf", tmp_path / "two" / "robot.urdf")
    assert np.abs(load_urdf(str(tmp_path / "one" / "robot.urdf"))[1].geoms[0].vertices).max() == 0.1
    assert np.abs(load_urdf(str(tmp_path / "two" / "robot.urdf"))[1].geoms[0].vertices).max() == 0.3


def test_a_mesh_appearing_where_it_is_looked_for_first_is_read(cache, tmp_path):
    """package://pkg/meshes/cube.obj is found as pkg/meshes/cube.obj from pkg/urdf/ (its parent);
    a cube.obj put later at pkg/urdf/pkg/meshes/, looked at first, is what the next load reads."""
    package = tmp_path / "pkg"
    mesh_robot(package, half=0.1)
    (package / "urdf").mkdir()
    text = (package / "robot.urdf").read_text().replace("meshes/cube.obj", "package://pkg/meshes/cube.obj")
    (package / "urdf" / "robot.urdf").write_text(text)
    path = str(package / "urdf" / "robot.urdf")
    assert np.abs(load_urdf(path)[1].geoms[0].vertices).max() == 0.1
    (package / "urdf" / "pkg" / "meshes").mkdir(parents=True)
    (package / "urdf" / "pkg" / "meshes" / "cube.obj").write_text(cube_obj(0.3))
    assert np.abs(load_urdf(path)[1].geoms[0].vertices).max() == 0.3


def test_a_mesh_rewritten_with_its_size_and_time_is_read_again(cache, tmp_path):
    """A mesh file replaced by one of the same size, its modification time set back (cp -p, rsync
    -a, tar): the next load reads the new triangles (the change time and inode differ)."""
    path = mesh_robot(tmp_path, half=0.1)
    mesh = tmp_path / "meshes" / "cube.obj"
    before = os.stat(mesh)
    assert np.abs(load_urdf(path)[1].geoms[0].vertices).max() == 0.1
    replacement = tmp_path / "new.obj"
    replacement.write_text(cube_obj(0.2))
    assert os.stat(replacement).st_size == before.st_size
    os.replace(replacement, mesh)
    os.utime(mesh, ns=(before.st_atime_ns, before.st_mtime_ns))
    assert np.abs(load_urdf(path)[1].geoms[0].vertices).max() == 0.2


def test_a_mesh_changed_or_removed_while_read_is_no_entry(cache, tmp_path, monkeypatch):
    """A mesh file rewritten just after it is read: the entry holds what was read with the file as
    it was before, so the next load reads the new file; removed instead, the load still succeeds."""
    path = mesh_robot(tmp_path, half=0.1)
    mesh = tmp_path / "meshes" / "cube.obj"
    read = urdf.shapes._read_mesh

    def read_then_rewrite(name):
        out = read(name)
        mesh.write_text(cube_obj(0.25))
        return out
    monkeypatch.setattr(urdf.shapes, "_read_mesh", read_then_rewrite)
    assert np.abs(load_urdf(path)[1].geoms[0].vertices).max() == 0.1
    monkeypatch.setattr(urdf.shapes, "_read_mesh", read)
    assert np.abs(load_urdf(path)[1].geoms[0].vertices).max() == 0.25

    gone = tmp_path / "gone.obj"
    gone.write_text(cube_obj(0.4))
    monkeypatch.setattr(urdf.shapes, "_read_mesh", lambda name: (read(name), os.remove(name))[0])
    assert np.abs(shapes.mesh_link(str(gone))[0].geoms[0].vertices).max() == 0.4


def test_meshes_that_name_other_files_are_not_kept(cache, tmp_path):
    """A glTF mesh keeps its triangles in a buffer file beside it, which the cache would not watch:
    neither it nor the URDF naming it is stored, so a new buffer is read."""
    import trimesh

    path = mesh_robot(tmp_path)
    for half in (0.1, 0.3):
        for name, data in trimesh.creation.box(extents=(2 * half,) * 3).export(file_type="gltf").items():
            (tmp_path / "meshes" / name).write_bytes(data)
        text = (tmp_path / "robot.urdf").read_text().replace("cube.obj", "model.gltf")
        (tmp_path / "robot.urdf").write_text(text)
        assert np.abs(load_urdf(path)[1].geoms[0].vertices).max() == pytest.approx(half)
    assert not entries(cache, "urdf") and not entries(cache, "mesh")


def test_density_is_part_of_the_key(cache, tmp_path):
    """A link without <inertial> weighs rho × its volume, whatever density was read before."""
    box = '<collision><geometry><box size="1 1 1"/></geometry></collision>'
    (tmp_path / "r.urdf").write_text(f'<robot name="r"><link name="a">{box}</link></robot>')
    assert load_urdf(str(tmp_path / "r.urdf"), rho=1000.0)[0].mass == 1000.0
    assert load_urdf(str(tmp_path / "r.urdf"), rho=500.0)[0].mass == 500.0


def test_warnings_are_said_each_time_with_the_entity_named(cache, tmp_path, caplog):
    """A URDF's warning (an ignored <contact> entry) is said when the links come from the cache too,
    naming that entity."""
    ignored = ('<link name="c"><contact><rolling_friction value="0.1"/></contact></link><joint name="k" '
               'type="revolute"><parent link="b"/><child link="c"/><axis xyz="0 0 1"/></joint>')
    path = mesh_robot(tmp_path, extra=ignored)
    for name in ("first", "second"):
        caplog.clear()
        load_urdf(path, entity_name=name)
        said = [r.getMessage() for r in caplog.records if "rolling_friction are not simulated" in r.getMessage()]
        assert len(said) == 1 and f"entity '{name}'" in said[0]
    assert len(entries(cache, "urdf")) == 1


def test_a_failure_is_not_stored(cache, tmp_path):
    """A URDF whose mesh is missing raises each time and leaves no entry."""
    path = mesh_robot(tmp_path)
    os.remove(tmp_path / "meshes" / "cube.obj")
    for _ in range(2):
        with pytest.raises(AssetError, match="cube.obj"):
            load_urdf(path)
    assert not entries(cache, "urdf")


@pytest.mark.parametrize("where", ["a file", "off"])
def test_an_unusable_or_disabled_cache_changes_nothing(tmp_path, monkeypatch, where):
    """A cache folder that is a file (cannot be written), or GENESIS_LITE_CACHE_DIR="" (off): the
    robot reads as without, and nothing is stored."""
    blocker = tmp_path / "blocker"
    blocker.write_text("")
    monkeypatch.setenv("GENESIS_LITE_CACHE_DIR", str(blocker) if where == "a file" else "")
    path = mesh_robot(tmp_path / "robot")
    assert_same(load_urdf(path), load_urdf(path))
    assert blocker.read_text() == "" and sorted(os.listdir(tmp_path)) == ["blocker", "robot"]


def test_a_corrupt_entry_is_a_miss(cache, tmp_path):
    """An entry cut short (a disk filled mid-write by another program) is read as absent, and rewritten."""
    path = mesh_robot(tmp_path)
    first = load_urdf(path)
    [entry] = entries(cache, "urdf")
    entry.write_bytes(entry.read_bytes()[:50])
    assert_same(load_urdf(path), first)
    assert entry.stat().st_size > 50


def test_a_change_to_the_code_makes_a_new_key(tmp_path):
    """The key holds the source of the modules that compute the value: an edit makes another key."""
    source = tmp_path / "reader.py"
    source.write_text("x = 1\n")
    before = asset_cache._digest("urdf", [b"file"], (str(source),), ("numpy",))
    source.write_text("x = 2\n")
    asset_cache._code_digest.cache_clear()
    assert asset_cache._digest("urdf", [b"file"], (str(source),), ("numpy",)) != before
    assert asset_cache._digest("urdf", [b"fil", b"e"], (str(source),), ("numpy",)) != \
        asset_cache._digest("urdf", [b"file", b""], (str(source),), ("numpy",))


def test_hulls_from_the_cache_equal_the_computed_ones(cache, monkeypatch):
    """A mesh's convex hull (vertices, graph, polygons, normals) from the cache equals the computed
    one; a flat mesh raises each time."""
    rng = np.random.default_rng(3)
    vertices = rng.normal(size=(60, 3))
    computed = convex.mesh_hull(vertices)
    assert len(entries(cache, "hull")) == 1
    for _ in range(2):
        with pytest.raises(AssetError, match="convex hull with volume"):
            convex.mesh_hull(np.c_[vertices[:, :2], np.zeros(60)])
    monkeypatch.setattr(convex, "_hull", lambda v: (_ for _ in ()).throw(AssertionError("computed")))
    assert_same(convex.mesh_hull(vertices), computed)


def test_a_mesh_body_read_again_comes_from_the_cache(cache, tmp_path, monkeypatch):
    """A mesh morph's link (triangles, mass, com, inertia) from the cache equals the computed one."""
    path = tmp_path / "cube.obj"
    path.write_text(cube_obj(0.2))
    first = shapes.mesh_link(str(path), scale=(1.0, 2.0, 0.5), rho=700.0)
    assert first[0].mass == pytest.approx(700.0 * 0.4 * 0.8 * 0.2) and len(entries(cache, "mass")) == 1
    monkeypatch.setattr(shapes, "_mesh_mass_properties", lambda *args: (_ for _ in ()).throw(AssertionError))
    assert_same(shapes.mesh_link(str(path), scale=(1.0, 2.0, 0.5), rho=700.0), first)


_CHILD = r"""
import json, sys
import genesis_lite as gs
gs.init(precision="64", logging_level="error")
scene = gs.Scene()
robot = scene.add_entity(gs.morphs.URDF(file=sys.argv[1], fixed=True))
scene.build()
scene.step()
print(json.dumps({"imported": [m for m in ("yourdfpy", "trimesh", "scipy") if m in sys.modules],
                  "links": robot.get_links_pos().tolist()}))
"""


def test_a_fresh_process_builds_a_robot_read_before_without_trimesh(cache):
    """The second process to build a KUKA arm imports neither yourdfpy, trimesh nor scipy (~0.6 s),
    and steps it the same."""
    def run():
        out = subprocess.run([sys.executable, "-c", _CHILD, KUKA], capture_output=True, text=True, check=True,
                             env={**os.environ, "GENESIS_LITE_CACHE_DIR": str(cache)})
        return json.loads(out.stdout.strip().splitlines()[-1])
    first, second = run(), run()
    assert first["imported"] == ["yourdfpy", "trimesh", "scipy"] and second["imported"] == []
    assert second["links"] == first["links"]
