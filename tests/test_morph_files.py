"""Where a file morph's path leads, as Genesis resolves it (its FileMorph): a path string or an
os.PathLike, found as given (relative to the working directory), else among genesis-world's
bundled assets when that package is installed ("xml/franka_emika_panda/panda.xml"); a path found
in neither is a named error saying where it was looked for."""
import pathlib

import pytest
import torch

import genesis_lite as gs
from genesis_lite import morphs
from tests.conftest import asset

PENDULUM = asset("pendulum2.urdf")


@pytest.fixture
def genesis_package(tmp_path, monkeypatch):
    """A stand-in genesis-world package (its assets folder holding a copy of our pendulum and a
    one-body MJCF) found on sys.path, as an installed one is."""
    assets = tmp_path / "site" / "genesis" / "assets"
    (assets / "urdf").mkdir(parents=True)
    (assets / "xml").mkdir()
    (tmp_path / "site" / "genesis" / "__init__.py").write_text("raise ImportError('never imported')\n")
    (assets / "urdf" / "pendulum.urdf").write_text(pathlib.Path(PENDULUM).read_text())
    (assets / "xml" / "ball.xml").write_text('<mujoco><worldbody><body name="ball"><freejoint/>'
                                             '<geom type="sphere" size="0.1"/></body></worldbody></mujoco>')
    monkeypatch.syspath_prepend(str(tmp_path / "site"))
    morphs.genesis_assets.cache_clear()
    yield str(assets)
    morphs.genesis_assets.cache_clear()


def test_genesis_asset_paths_resolve_to_its_bundled_assets(f64, genesis_package, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # (no urdf/ or xml/ folder here)
    assert gs.morphs.URDF(file="urdf/pendulum.urdf").file == f"{genesis_package}/urdf/pendulum.urdf"
    scene = gs.Scene()
    pendulum = scene.add_entity(gs.morphs.URDF(file="urdf/pendulum.urdf", fixed=True))
    ball = scene.add_entity(gs.morphs.MJCF(file=pathlib.Path("xml/ball.xml")))
    scene.build()
    assert pendulum.n_dofs == 2 and ball.n_dofs == 6
    (tmp_path / "xml").mkdir()  # a file of that path here comes first, as in Genesis
    (tmp_path / "xml" / "ball.xml").write_text('<mujoco><worldbody><body name="box"><freejoint/>'
                                               '<geom type="box" size="0.1 0.1 0.1"/></body></worldbody></mujoco>')
    morph = gs.morphs.MJCF(file="xml/ball.xml")
    assert morph.file == str(tmp_path / "xml" / "ball.xml")  # (absolute, as Genesis's: a later chdir keeps it)
    monkeypatch.chdir(genesis_package)
    scene = gs.Scene()
    assert scene.add_entity(morph).links[0].name == "box"


def test_paths_found_nowhere_say_where_they_were_looked_for(f64, genesis_package, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(gs.AssetError, match=f"'urdf/go2.urdf' \\(not found; relative paths start at {tmp_path}, then "
                                            f"genesis_lite's assets, {morphs.BUNDLED_ASSETS}, then genesis-world's "
                                            f"bundled assets, {genesis_package}\\)"):
        gs.Scene().add_entity(gs.morphs.URDF(file="urdf/go2.urdf"))
    with pytest.raises(gs.AssetError, match="gs.morphs.Mesh expected an existing mesh file, got 'meshes/no.obj' "
                                            r"\(not found; relative paths start at"):
        gs.Scene().add_entity(gs.morphs.Mesh(file="meshes/no.obj"))
    monkeypatch.setattr(morphs.importlib.util, "find_spec", lambda name: None)
    morphs.genesis_assets.cache_clear()
    with pytest.raises(gs.AssetError, match="genesis-world's bundled assets where that package is installed "
                                            r"\(it is not\)"):
        gs.Scene().add_entity(gs.morphs.MJCF(file="xml/franka_emika_panda/panda.xml"))


def test_a_pathlike_file_is_taken_as_its_path(f64):
    scene = gs.Scene()
    robot = scene.add_entity(gs.morphs.URDF(file=pathlib.Path(PENDULUM), fixed=True))
    scene.build()
    assert robot.n_dofs == 2 and gs.morphs.Mesh(file=pathlib.Path("a.obj")).file == "a.obj"  # (not found: as given)
    with pytest.raises(gs.InvalidInputError, match=r"Mesh: argument 'file' must be a path \(a string or os.PathLike\)"):
        gs.morphs.Mesh(file=None)


def test_an_inline_document_loads_as_its_file(f64, tmp_path, monkeypatch):
    """Genesis's inline MJCF and URDF: the document as a string, or an xml.etree Element, builds the
    robot its file builds (the same trajectory, bit for bit), its relative mesh paths from the
    working directory."""
    import xml.etree.ElementTree as ET
    arm = pathlib.Path(asset("mjcf", "crawler.xml")).read_text()
    mesh_robot = pathlib.Path(asset("mesh_robot", "urdf", "mesh_robot.urdf"))
    monkeypatch.chdir(mesh_robot.parent)  # (its meshes: "../meshes/link.obj" and a package:// one)
    trajectories = []
    for morphs_of in ((lambda: gs.morphs.MJCF(file=asset("mjcf", "crawler.xml")),
                       lambda: gs.morphs.URDF(file=str(mesh_robot))),
                      (lambda: gs.morphs.MJCF(file=arm), lambda: gs.morphs.URDF(file=mesh_robot.read_text())),
                      (lambda: gs.morphs.MJCF(file=ET.fromstring(arm)),
                       lambda: gs.morphs.URDF(file=ET.ElementTree(ET.fromstring(mesh_robot.read_text()))))):
        scene = gs.Scene(show_viewer=False)
        crawler = scene.add_entity(morphs_of[0]())
        robot = scene.add_entity(morphs_of[1]())
        scene.build()
        for _ in range(20):
            scene.step()
        trajectories.append(torch.cat([crawler.get_qpos(), robot.get_qpos()]))
    assert torch.equal(trajectories[0], trajectories[1]) and torch.equal(trajectories[0], trajectories[2])
    with pytest.raises(gs.AssetError, match=r"MJCF '<inline MJCF>' \(entity 'bad'\): root element expected <mujoco>"):
        gs.Scene().add_entity(gs.morphs.MJCF(file="<robot/>"), name="bad")


def test_inline_documents_as_written_in_code(f64):
    """A triple-quoted document (leading white space, an XML declaration naming another encoding than
    the str's: the names as written), and text that is not well-formed XML or not the morph's kind
    named as such, not as a missing file."""
    body = '''
        <?xml version="1.0" encoding="ISO-8859-1"?>
        <mujoco><worldbody><body name="bé"><freejoint/><geom type="sphere" size="0.1"/></body></worldbody></mujoco>
    '''
    scene = gs.Scene()
    ball = scene.add_entity(gs.morphs.MJCF(file=body))
    assert [link.name for link in ball.links] == ["bé"]
    with pytest.raises(gs.AssetError, match=r"gs.morphs.MJCF expected an existing MJCF file or an XML document, "
                                            r"got text that is not well-formed XML \(mismatched tag: line 1"):
        gs.Scene().add_entity(gs.morphs.MJCF(file="<mujoco><worldbody><body></worldbody></mujoco>"))
    with pytest.raises(gs.AssetError, match=r"URDF '<inline URDF>'.*root element expected <robot>, got <mujoco>"):
        gs.Scene().add_entity(gs.morphs.URDF(file=body))
