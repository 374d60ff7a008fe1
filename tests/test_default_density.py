"""Genesis's default density: ``gs.materials.Rigid()`` (rho None) weighs a body whose mass the
asset does not state at 600 kg/m³ when it is a plain object, 1500 when it belongs to an
articulated robot and 1000 under ``enable_mujoco_compatibility``, as genesis-world 1.4.5 does
(its engine/entities/rigid_entity: ``RHO_OBJECT``, ``RHO_ROBOT``, ``RHO_MUJOCO`` and the links'
``is_robot`` flag)."""
import numpy as np
import pytest

import genesis_lite as gs
from genesis_lite.solvers.rigid import shapes
from genesis_lite.solvers.rigid.urdf import load_urdf

# links without <inertial>, so that every mass comes from the shapes
ARM = """<robot name="arm">
  <link name="base"><collision><geometry><box size="0.2 0.2 0.1"/></geometry></collision></link>
  <link name="upper"><collision><origin xyz="0 0 0.2"/><geometry><box size="0.05 0.05 0.4"/></geometry></collision></link>
  <link name="tool"><collision><origin xyz="0 0 0.05"/><geometry><sphere radius="0.05"/></geometry></collision></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/><origin xyz="0 0 0.05"/>
    <axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="10" velocity="1"/></joint>
  <joint name="flange" type="fixed"><parent link="upper"/><child link="tool"/><origin xyz="0 0 0.4"/></joint>
</robot>"""
OBJECT = """<robot name="thing">
  <link name="body"><collision><geometry><box size="0.2 0.2 0.1"/></geometry></collision></link>
  <link name="handle"><collision><origin xyz="0 0 0.1"/><geometry><cylinder radius="0.02" length="0.1"/></geometry>
    </collision></link>
  <joint name="glue" type="fixed"><parent link="body"/><child link="handle"/><origin xyz="0 0 0.05"/></joint>
</robot>"""
# a base whose fixed child comes before its moving one, and a floating body below: the fixed child
# shares the base's flag, which the moving child sets afterwards; the floating body starts its own
TREE = """<robot name="tree">
  <link name="world"/>
  <link name="base"><collision><geometry><box size="0.1 0.1 0.1"/></geometry></collision></link>
  <link name="cover"><collision><geometry><box size="0.1 0.1 0.01"/></geometry></collision></link>
  <link name="leg"><collision><geometry><box size="0.02 0.02 0.2"/></geometry></collision></link>
  <link name="foot"><collision><geometry><sphere radius="0.02"/></geometry></collision></link>
  <joint name="free" type="floating"><parent link="world"/><child link="base"/></joint>
  <joint name="lid" type="fixed"><parent link="base"/><child link="cover"/></joint>
  <joint name="hip" type="continuous"><parent link="base"/><child link="leg"/><axis xyz="0 1 0"/></joint>
  <joint name="ankle" type="fixed"><parent link="leg"/><child link="foot"/></joint>
</robot>"""
VOLUMES = {"base": 0.2 * 0.2 * 0.1, "upper": 0.05 * 0.05 * 0.4, "tool": 4 / 3 * np.pi * 0.05 ** 3,
           "body": 0.2 * 0.2 * 0.1, "handle": np.pi * 0.02 ** 2 * 0.1}


def _write(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def test_urdf_links_are_weighed_as_a_robots_or_an_objects(tmp_path):
    """load_urdf(rho=None): the links rigidly joined to a moving joint's parent or child are a
    robot's (1500 kg/m³), the others an object's (600); a stated rho weighs every link."""
    def densities(text, name, rho=None):
        links = load_urdf(_write(tmp_path, name, text), rho=rho)
        return {link.name: link.mass / shapes.geometry_mass_properties(link.geoms, 1.0)[0] for link in links}

    robot, plain = shapes.ROBOT_DENSITY, shapes.OBJECT_DENSITY
    np.testing.assert_allclose(list(densities(ARM, "arm.urdf").values()), [robot] * 3, rtol=1e-12)
    np.testing.assert_allclose(list(densities(OBJECT, "object.urdf").values()), [plain] * 2, rtol=1e-12)
    tree = densities(TREE, "tree.urdf")
    assert list(tree) == ["base", "cover", "leg", "foot"]
    np.testing.assert_allclose(list(tree.values()), [robot] * 4, rtol=1e-12)
    np.testing.assert_allclose(list(densities(ARM, "arm2.urdf", 250.0).values()), [250.0] * 3, rtol=1e-12)


def test_scene_defaults_are_genesis_masses(f64, tmp_path):
    """Link masses of a default-material scene against genesis-world 1.4.5's for the same files
    (measured with its backend cpu, merge_fixed_links=False: Box 0.1 m 0.6 kg; the arm's upper
    link 1.5 kg and tool 0.785398 kg; the object's body 2.4 kg and handle 0.075398 kg; under
    enable_mujoco_compatibility the box 1.0 kg, upper 1.0 kg, body 4.0 kg). Where Genesis differs,
    left out: a link welded to the world weighs 0 there (its mass moves nothing; ours is weighed
    like the others), and under MuJoCo compatibility a fixed child of a link weighs 0 there."""
    arm, thing = _write(tmp_path, "arm.urdf", ARM), _write(tmp_path, "object.urdf", OBJECT)
    genesis = {False: {"box": 0.6, "upper": 1.5, "tool": 0.785398, "body": 2.4, "handle": 0.075398},
               True: {"box": 1.0, "upper": 1.0, "body": 4.0}}
    for compatible, expected in genesis.items():
        scene = gs.Scene(rigid_options=gs.options.RigidOptions(enable_mujoco_compatibility=compatible))
        entities = [scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(0, 0, 1))),
                    scene.add_entity(gs.morphs.URDF(file=arm, fixed=True, merge_fixed_links=False)),
                    scene.add_entity(gs.morphs.URDF(file=thing, pos=(1, 0, 0.5), merge_fixed_links=False)),
                    scene.add_entity(gs.morphs.Sphere(radius=0.1, pos=(2, 0, 1)),
                                     material=gs.materials.Rigid(rho=300.0))]
        scene.build()
        masses = {link.name: float(link.get_mass()) for entity in entities for link in entity.links}
        for name, mass in expected.items():
            assert masses[name] == pytest.approx(mass, abs=1e-6), (compatible, name)
        assert masses["sphere"] == pytest.approx(300.0 * 4 / 3 * np.pi * 0.1 ** 3, rel=1e-12)  # a stated rho
        density = shapes.MUJOCO_DENSITY if compatible else shapes.ROBOT_DENSITY
        assert masses["base"] == pytest.approx(density * VOLUMES["base"], rel=1e-12)
    assert gs.materials.Rigid().rho is None
    for bad in (0.0, -1.0, float("nan"), True, "600"):
        with pytest.raises(gs.InvalidInputError, match="materials.Rigid: argument 'rho' must be a positive finite"):
            gs.materials.Rigid(rho=bad)


def test_a_moving_link_of_mass_zero_is_weighed_from_its_shapes_as_genesis(tmp_path, caplog):
    """A link on a moving joint whose <inertial> states mass 0 but which has shapes is weighed
    from them, with a warning, as Genesis 1.4.5 weighs it (1.5 kg for this hinged 0.1 m box at the
    robot density); one on a fixed joint keeps its 0 (Genesis too)."""
    zero = '<inertial><mass value="0"/><inertia ixx="0" iyy="0" izz="0" ixy="0" ixz="0" iyz="0"/></inertial>'
    box = '<collision><geometry><box size="0.1 0.1 0.1"/></geometry></collision>'
    path = _write(tmp_path, "zero.urdf", f"""<robot name="z"><link name="base">{box}</link>
      <link name="arm">{zero}{box}</link><link name="tag">{zero}{box}</link>
      <joint name="h" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 1 0"/>
        <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
      <joint name="f" type="fixed"><parent link="base"/><child link="tag"/></joint></robot>""")
    with caplog.at_level("WARNING", logger="genesis_lite"):
        links = {link.name: link for link in load_urdf(path)}
    assert links["arm"].mass == pytest.approx(1.5, rel=1e-12) and not links["arm"].mass_stated
    assert links["tag"].mass == 0.0 and links["tag"].mass_stated
    assert any("link 'arm' moves and its <inertial> states mass 0" in r.getMessage() for r in caplog.records)
