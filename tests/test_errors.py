"""Bad input raises a gs.GenesisException subclass whose message names the entity, the argument,
what was expected and what was given (SPEC §5). One test per kind of mistake.

Most tests share one built scene (a 2-dof pendulum named "pendulum"): building compiles
Taichi kernels, which takes seconds.
"""
import inspect
import logging
import math
import os

import numpy as np
import pytest
import torch

import genesis_lite as gs
from tests.conftest import asset, pybullet, warns

ENTITY = "pendulum"
INERTIAL = '<inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial>'
LINK_A = f'<link name="a">{INERTIAL}</link>'
LINK_B = f'<link name="b">{INERTIAL}</link>'


def joint(name, jtype):
    return (f'<joint name="{name}" type="{jtype}"><parent link="a"/><child link="b"/>'
            f'<axis xyz="0 0 1"/></joint>')


def write_urdf(tmp_path, body, name="robot.urdf"):
    path = tmp_path / name
    path.write_text(f'<?xml version="1.0"?>\n<robot name="t">\n{body}\n</robot>\n')
    return str(path)


def raises(cls, fn, *substrings):
    """Call fn, expect `cls` (a GenesisException subclass); every substring must be in the message."""
    with pytest.raises(cls) as info:
        fn()
    assert isinstance(info.value, gs.GenesisException)
    message = str(info.value)
    for part in substrings:
        assert part in message, f"{part!r} missing from the message: {message}"
    return message


@pytest.fixture(scope="module")
def built():
    """(scene, robot): assets/pendulum2.urdf (2 revolute dofs, fixed base) built with n_envs=0."""
    gs.init(precision="64", logging_level="warning")
    scene = gs.Scene()
    robot = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True), name=ENTITY)
    scene.build()
    yield scene, robot
    scene.destroy()


# ------------------------------------------------------------------ assets


def test_missing_urdf_file(f64, tmp_path):
    scene = gs.Scene()
    path = str(tmp_path / "nope.urdf")
    raises(gs.AssetError, lambda: scene.add_entity(gs.morphs.URDF(file=path), name="ghost"),
           "entity 'ghost'", "'file'", "expected an existing URDF file", path)


def test_malformed_xml(f64, tmp_path):
    path = write_urdf(tmp_path, LINK_A + '<link name="b">')  # <link> never closed
    scene = gs.Scene()
    raises(gs.AssetError, lambda: scene.add_entity(gs.morphs.URDF(file=path, fixed=True), name="bot"),
           "entity 'bot'", path, "malformed XML")


def test_unknown_joint_type(f64, tmp_path):
    path = write_urdf(tmp_path, LINK_A + LINK_B + joint("slider", "planar"))
    scene = gs.Scene()
    raises(gs.AssetError, lambda: scene.add_entity(gs.morphs.URDF(file=path, fixed=True), name="bot"),
           "entity 'bot'", path, "joint 'slider'", "'planar'", "supported types are", "revolute", "prismatic")


def test_missing_mesh_in_urdf(f64, tmp_path):
    path = write_urdf(tmp_path, '<link name="a"><collision><geometry><mesh filename="meshes/missing.stl"/>'
                                '</geometry></collision></link>')
    scene = gs.Scene()
    raises(gs.AssetError, lambda: scene.add_entity(gs.morphs.URDF(file=path, fixed=True), name="bot"),
           "entity 'bot'", "link 'a'", "meshes/missing.stl", "not found",
           os.path.join(str(tmp_path), "meshes", "missing.stl"))  # where it looked


def test_missing_mesh_morph(f64, tmp_path):
    path = str(tmp_path / "missing.obj")
    scene = gs.Scene()
    raises(gs.AssetError, lambda: scene.add_entity(gs.morphs.Mesh(file=path), name="blob"),
           "entity 'blob'", "'file'", path, "expected an existing mesh file", "not found")


def test_morph_arguments():
    """A morph names itself and the argument: 'fixed' is a bool (a truthy string welded the body),
    a Plane is always fixed (False was dropped without a word), a capsule says Capsule."""
    raises(gs.InvalidInputError, lambda: gs.morphs.Box(fixed="no"), "Box", "'fixed'", "True or False", "'no'")
    raises(gs.InvalidInputError, lambda: gs.morphs.Plane(fixed=False), "Plane", "'fixed'", "must be True")
    raises(gs.InvalidInputError, lambda: gs.morphs.Capsule(radius=0.0), "Capsule: argument 'radius'", "positive")
    assert gs.morphs.Plane().fixed and not gs.morphs.Box().fixed
    # euler and quat together: one would go unused (quat won without a word; Genesis raises too)
    raises(gs.InvalidInputError, lambda: gs.morphs.Box(euler=(10.0, 0.0, 0.0), quat=(1.0, 0.0, 0.0, 0.0)),
           "Box: arguments 'euler' and 'quat' cannot both be set")
    assert np.allclose(gs.morphs.Box(euler=(0.0, 0.0, 90.0)).quat, [np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)])
    assert gs.morphs.Box().quat.tolist() == [1.0, 0.0, 0.0, 0.0] and gs.morphs.Box().euler.tolist() == [0.0, 0.0, 0.0]
    # a xacro file (Genesis expands it; read as URDF, its macros' links and joints were skipped)
    raises(gs.InvalidInputError, lambda: gs.morphs.URDF(file="robot.urdf.xacro"), "URDF: argument 'file'",
           "xacro files are not supported yet", "robot.urdf.xacro")


def test_morph_keywords():
    """A morph's unknown keyword is a named error listing the accepted ones (Python's TypeError named
    neither); Genesis's own that genesis_lite does not have say so."""
    raises(gs.InvalidInputError, lambda: gs.morphs.Box(foo=1), "Box", "'foo' is unknown", "'size', 'lower'")
    raises(gs.InvalidInputError, lambda: gs.morphs.Mesh(file="a.obj", convexify=False), "Mesh", "'convexify' is a Genesis")
    raises(gs.InvalidInputError, lambda: gs.morphs.MJCF(file="a.xml", decimate=True), "MJCF", "'decimate' is a Genesis")
    raises(gs.InvalidInputError, lambda: gs.morphs.Plane(plane_size=(5, 5)), "Plane", "'plane_size' is a Genesis")
    raises(gs.InvalidInputError, lambda: gs.morphs.Capsule(offset_pos=(0, 0, 1)), "Capsule", "'offset_pos' is a Genesis")
    assert gs.morphs.Sphere((0, 0, 1), radius=0.2).radius == 0.2  # positional arguments still work


@pytest.mark.parametrize("morph, file, resolved", [
    ("URDF", "a.urdf", (True, False, False)),   # Genesis's URDF turns meshes unless True
    ("Mesh", "a.obj", (True, False, True)),     # its Mesh: None is True but for glTF
    ("Mesh", "a.glb", (True, False, False)),
])
def test_file_meshes_are_zup(morph, file, resolved):
    """Genesis's file_meshes_are_zup resolved per morph as Genesis resolves it (True, False, None →
    read as they are or turned from Y-up: tests/test_urdf_loader.py checks the turn); the MJCF
    loader takes it and does not read it, as Genesis's; anything else is a named error."""
    make = getattr(gs.morphs, morph)
    for value, as_they_are in zip((True, False, None), resolved):
        assert make(file=file, file_meshes_are_zup=value).file_meshes_are_zup is as_they_are
    gs.morphs.MJCF(file="a.xml", file_meshes_are_zup=False)
    for maker in (make, gs.morphs.MJCF):
        raises(gs.InvalidInputError, lambda: maker(file=file, file_meshes_are_zup="yes"),
               "'file_meshes_are_zup' must be True, False or None")


def test_rigid_material_keywords():
    """An unknown keyword of gs.materials.Rigid is a named error (Python's TypeError named nothing),
    and Genesis's own that genesis_lite does not have say so (its SDF-grid and IPC ones)."""
    raises(gs.InvalidInputError, lambda: gs.materials.Rigid(foo=1), "Rigid", "'foo' is unknown", "'rho', 'friction'")
    raises(gs.InvalidInputError, lambda: gs.materials.Rigid(sdf_cell_size=0.01), "'sdf_cell_size' is a Genesis option")


def test_moving_massless_link_raises_at_build(f64, tmp_path):
    path = write_urdf(tmp_path, LINK_A + '<link name="b"/>' + joint("hinge", "revolute"))
    scene = gs.Scene()
    # (no rotor armature: Genesis's default 0.1 would give the hinge an inertia of its own)
    scene.add_entity(gs.morphs.URDF(file=path, fixed=True, default_armature=None), name="bot")  # loading is fine...
    try:
        raises(gs.AssetError, scene.build, "entity 'bot'", "link 'b'", "no mass or inertia", "expected")
        assert not scene.is_built
        raises(gs.SceneStateError, scene.step, "build()")
    finally:
        scene.destroy()


# ------------------------------------------------------------------ scene lifecycle


def test_step_before_build(f64):
    scene = gs.Scene()
    scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True), name=ENTITY)
    raises(gs.SceneStateError, scene.step, "scene.step", "build()")


def test_setter_before_build(f64):
    scene = gs.Scene()
    robot = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True), name=ENTITY)
    assert (robot.n_dofs, robot.n_links, robot.n_qs) == (2, 3, 2)  # the structure is known at add time
    assert robot.get_joint("joint2").dofs_idx_local == [1]
    raises(gs.SceneStateError, lambda: robot.set_dofs_position([0.1, 0.2]), f"entity '{ENTITY}'", "build()")
    raises(gs.SceneStateError, lambda: robot.get_links_mass(), f"entity '{ENTITY}'", "build()")
    raises(gs.SceneStateError, lambda: robot.get_dofs_position(), f"entity '{ENTITY}'", "build()")


def test_every_entity_method_before_build_raises_a_named_error(f64):
    """Each public method and property of the entities, links and joints, called before build
    with zeros for its required arguments, works or raises a GenesisException: some reached the
    unbuilt model first (get_dofs_velocity, get_mass, set_mass_shift: bare AttributeErrors)."""
    scene = gs.Scene()
    robot = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True), name=ENTITY)
    box = scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1)), name="box")
    blob = scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(0.5, 0.0, 0.5)),
                            material=gs.materials.MPM.Elastic())
    bare = []
    for owner in (robot, box, blob, robot.links[1], robot.joints[1]):
        for name in dir(type(owner)):
            member = getattr(type(owner), name)
            if name.startswith("_") or not (callable(member) or isinstance(member, property)):
                continue
            try:
                if isinstance(member, property):
                    getattr(owner, name)
                else:
                    parameters = list(inspect.signature(member).parameters.values())[1:]
                    getattr(owner, name)(*[0.0 for p in parameters if p.default is p.empty and p.kind in (
                        p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)])
            except gs.GenesisException:
                pass
            except Exception as error:  # noqa: BLE001 (what the test looks for)
                bare.append(f"{type(owner).__name__}.{name}: {type(error).__name__}: {error}")
    assert bare == []


def test_build_twice(f64, built):
    scene, _ = built
    raises(gs.SceneStateError, scene.build, "scene.build", "already built")


def test_add_entity_after_build(f64, built):
    scene, _ = built
    raises(gs.SceneStateError, lambda: scene.add_entity(gs.morphs.Box(), name="late"),
           "scene.add_entity", "already built", "before build()")


# ------------------------------------------------------------------ names and indices


def test_duplicate_entity_name(f64):
    scene = gs.Scene()
    scene.add_entity(gs.morphs.Box(), name="crate")
    raises(gs.InvalidInputError, lambda: scene.add_entity(gs.morphs.Sphere(), name="crate"),
           "scene.add_entity", "'name'", "'crate'", "entity 0")
    scene.add_entity(gs.morphs.Sphere())  # a generated name
    raises(gs.InvalidInputError, lambda: scene.add_entity(gs.morphs.Sphere(), name="sphere_1"), "'sphere_1'")
    scene.add_entity(gs.morphs.Box(), name="box_3")
    assert scene.add_entity(gs.morphs.Box()).name == "box_4"  # generated names skip taken ones


def test_unknown_link_name(f64, built):
    _, robot = built
    raises(gs.InvalidInputError, lambda: robot.get_link("hand"),
           f"entity '{ENTITY}'", "'name'", "'base'", "'link1'", "'link2'", "'hand'")


def test_unknown_joint_name(f64, built):
    _, robot = built
    raises(gs.InvalidInputError, lambda: robot.get_joint("elbow"),
           f"entity '{ENTITY}'", "'name'", "'joint1'", "'joint2'", "'elbow'")


def test_dofs_idx_local_out_of_range(f64, built):
    _, robot = built
    raises(gs.InvalidInputError, lambda: robot.set_dofs_position([1.0], dofs_idx_local=[5]),
           f"entity '{ENTITY}'", "'dofs_idx_local'", "[-2, 2)", "[5]")
    raises(gs.InvalidInputError, lambda: robot.get_dofs_velocity(dofs_idx_local=[-3]),
           "'dofs_idx_local'", "[-2, 2)", "[-3]")
    raises(gs.InvalidInputError, lambda: robot.control_dofs_force([1.0], dofs_idx_local=[0.5]),
           "'dofs_idx_local'", "integers", "[0.5]")



def test_dofs_idx_local_as_a_slice(f64, built):
    """Genesis takes a slice of local dofs (its go2 example: slice(6, 18)); it was refused."""
    _, robot = built
    robot.set_dofs_position([0.3], dofs_idx_local=slice(1, 2))
    assert robot.get_dofs_position(slice(-1, None)).tolist() == [0.3]
    assert robot.get_dofs_position(slice(None)).shape == (2,)
    # and, as Genesis, indices from the end and boolean masks
    assert robot.get_dofs_position(-1).tolist() == robot.get_dofs_position([-1]).tolist() == [0.3]
    assert robot.get_dofs_position(np.array([False, True])).tolist() == [0.3]


def test_arguments_a_method_does_not_take(f64, built):
    """A Genesis argument genesis_lite does not have yet (or a typo) names the entity or scene, the
    method, the argument and what the method takes, where Python's TypeError named neither."""
    scene, robot = built
    raises(gs.InvalidInputError, lambda: robot.set_qpos([0.0, 0.0], relative=True), f"entity '{ENTITY}'",
           "set_qpos", "'relative'", "'qs_idx_local'", "docs/genesis_api.md")
    raises(gs.InvalidInputError, lambda: robot.get_ang(relative=True), "get_ang", "'relative'", "['envs_idx']")
    raises(gs.InvalidInputError, lambda: robot.get_link(robot.links[-1].name).get_pos(0, 1),
           f"link '{robot.links[-1].name}' of entity '{ENTITY}'", "get_pos", "too many positional arguments")
    raises(gs.InvalidInputError, lambda: scene.step(foo=1), "gs.Scene", "step", "'foo'", "'update_visualizer'")
    raises(gs.InvalidInputError, lambda: gs.Scene(profiling_options=None), "gs.Scene", "'profiling_options'",
           "'sim_options'")
    raises(gs.InvalidInputError, lambda: gs.surfaces.Default(smooth=False), "Default", "'smooth'",
           "a Genesis option that genesis_lite does not have", "['color', 'vis_mode']")

def test_genesis_arguments_with_nothing_to_do_here_are_taken_and_checked(f64, built, caplog):
    """Genesis's arguments that change nothing here (how it compiles, logs or sizes its buffers,
    readouts it defers) are taken, checked; those that would change something raise."""
    scene, robot = built
    gs.init(precision="64", logging_level="warning", performance_mode=True, theme="raw", logger_verbose_time=True,
            use_deterministic_algorithms=False, eps=1e-15)
    assert scene.is_built  # (the same runtime: nothing restarted)
    raises(gs.InvalidInputError, lambda: gs.init(precision="64", eps=1e-12), "gs.init", "'eps'", "1e-15")
    raises(gs.InvalidInputError, lambda: gs.init(precision="64", performance_mode="yes"), "'performance_mode'")
    raises(gs.InvalidInputError, lambda: gs.init(precision="64", theme="blue"), "'theme'")
    # checked before a restart: a string stopped the runtime, and the next gs.init did nothing
    raises(gs.InvalidInputError, lambda: gs.init(precision="64", debug="yes"), "gs.init", "'debug'", "'yes'")
    assert scene.is_built
    assert (gs.tc_bool, gs.np_bool, gs.tc_int, gs.np_int) == (torch.bool, np.bool_, torch.int32, np.int32)
    options = gs.options.RigidOptions(max_collision_pairs=300, box_box_detection=True)
    assert (options.max_collision_pairs, options.box_box_detection) == (300, True)
    raises(gs.InvalidInputError, lambda: gs.options.RigidOptions(box_box_detection=False), "'box_box_detection'",
           "MuJoCo's box–box collider")
    raises(gs.InvalidInputError, lambda: gs.options.RigidOptions(max_collision_pairs=-1), "'max_collision_pairs'")
    with caplog.at_level(logging.WARNING, logger="genesis_lite"):
        gs.Scene(show_FPS=False)
        assert not caplog.records
        gs.Scene(show_FPS=True)
    assert "show_FPS=True prints nothing here" in caplog.records[-1].getMessage()
    robot.set_qpos([0.1, 0.2], skip_forward=True)
    robot.set_dofs_velocity([0.5, 0.0], skip_forward=True)
    assert robot.get_qpos().tolist() == [0.1, 0.2] and robot.get_dofs_velocity().tolist() == [0.5, 0.0]
    robot.zero_all_dofs_velocity(skip_forward=False)
    raises(gs.InvalidInputError, lambda: robot.set_qpos([0.1, 0.2], skip_forward=1), "'skip_forward'", "True or False")
    with pytest.raises(AttributeError, match="scene.sim.rigid_solver has no 'set_dofs_kp'.*entity.set_dofs_kp"):
        scene.sim.rigid_solver.set_dofs_kp()
    assert not hasattr(scene.sim.rigid_solver, "links_info")


def test_envs_idx_without_batch(f64, built):
    _, robot = built
    raises(gs.InvalidInputError, lambda: robot.set_dofs_position([0.1, 0.2], envs_idx=[0]),
           f"entity '{ENTITY}'", "'envs_idx'", "None", "n_envs=0", "[0]")
    raises(gs.InvalidInputError, lambda: robot.get_dofs_position(envs_idx=[0]), "'envs_idx'", "n_envs=0")


def test_repeated_index_in_a_write(f64):
    """A setter given the same dof (env, particle...) twice would keep either value (torch's
    index_put leaves it undefined): refused, naming the argument and the index, and nothing is
    written. Getters may repeat an index (a column read twice)."""
    gs.init(precision="64", logging_level="warning")
    scene = gs.Scene()
    robot = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True), name=ENTITY)
    scene.build(n_envs=3)
    before = robot.get_dofs_position().clone()
    raises(gs.InvalidInputError, lambda: robot.set_dofs_position([0.1, 0.2], dofs_idx_local=[1, 1]),
           f"entity '{ENTITY}'", "'dofs_idx_local'", "[1] more than once")
    raises(gs.InvalidInputError, lambda: robot.control_dofs_force([[1.0, 2.0]] * 3, dofs_idx_local=[0, 0]),
           "'dofs_idx_local'", "[0] more than once")
    raises(gs.InvalidInputError, lambda: robot.set_dofs_kp([[5.0, 6.0]] * 3, envs_idx=torch.tensor([2, 0, 2])),
           "'envs_idx'", "[2] more than once")
    raises(gs.InvalidInputError, lambda: scene.set_gravity([[0.0, 0.0, -1.0]] * 2, envs_idx=[1, 1]),
           "scene.set_gravity", "'envs_idx'", "[1] more than once")
    assert torch.equal(robot.get_dofs_position(), before)
    assert robot.get_dofs_position(dofs_idx_local=[1, 1], envs_idx=[0, 0]).shape == (2, 2)
    scene.destroy()


# ------------------------------------------------------------------ values


def test_wrong_shape(f64, built):
    _, robot = built
    before = robot.get_dofs_position().clone()
    raises(gs.InvalidInputError, lambda: robot.set_dofs_position([1.0, 2.0, 3.0]),
           f"entity '{ENTITY}'", "'position'", "(2,)", "(3,)")
    raises(gs.InvalidInputError, lambda: robot.control_dofs_force(torch.zeros(1, 2)),
           f"entity '{ENTITY}'", "'force'", "(2,)", "(1, 2)")
    assert torch.equal(robot.get_dofs_position(), before)  # a rejected call changes nothing


def test_non_numeric_and_complex_values(f64, built):
    _, robot = built
    raises(gs.InvalidInputError, lambda: robot.set_dofs_position(["a", "b"]),
           f"entity '{ENTITY}'", "'position'", "(2,)")
    raises(gs.InvalidInputError, lambda: robot.set_dofs_velocity(torch.zeros(2, dtype=torch.complex64)),
           f"entity '{ENTITY}'", "'velocity'", "real", "complex")
    # what a float conversion turns into numbers (NaN, 1.0, 0.5) without a word
    raises(gs.InvalidInputError, lambda: robot.set_dofs_position(None), "'position'", "real numbers", "NoneType")
    raises(gs.InvalidInputError, lambda: robot.set_dofs_velocity([True, False]), "'velocity'", "bool")
    raises(gs.InvalidInputError, lambda: robot.set_dofs_velocity(torch.ones(2, dtype=torch.bool)), "'velocity'", "bool")
    raises(gs.InvalidInputError, lambda: robot.set_dofs_velocity(["0.5", "1"]), "'velocity'", "strings")
    raises(gs.InvalidInputError, lambda: robot.set_dofs_velocity([[0.5], [1.0, 2.0]]), "'velocity'", "list")


def test_nan_input(f64, built):
    _, robot = built
    before = robot.get_dofs_position().clone()
    raises(gs.InvalidInputError, lambda: robot.set_dofs_position([0.1, math.nan]),
           f"entity '{ENTITY}'", "'position'", "finite", "nan")
    raises(gs.InvalidInputError, lambda: robot.set_dofs_velocity(torch.tensor([math.inf, 0.0])),
           f"entity '{ENTITY}'", "'velocity'", "finite", "inf")
    raises(gs.InvalidInputError, lambda: robot.control_dofs_position(np.array([np.nan, 0.0])),
           f"entity '{ENTITY}'", "'position'", "finite")
    raises(gs.InvalidInputError, lambda: robot.get_jacobian(robot.links[-1], local_point=[math.nan, 0.0, 0.0]),
           f"entity '{ENTITY}'", "get_jacobian", "'local_point'", "finite", "nan")
    assert torch.equal(robot.get_dofs_position(), before)


def test_values_that_are_not_numbers(f64, built):
    """Strings, complex numbers, sparse tensors, a zero slice step and a missing link list are
    named errors (each was Python's, numpy's or torch's bare one)."""
    scene, robot = built
    for call, substrings in [
            (lambda: gs.morphs.Box(pos="abc"), ("Box", "'pos'", "3 finite numbers", "'abc'")),
            (lambda: gs.morphs.Box(size=(1j, 1, 1)), ("Box", "'size'", "3 finite numbers")),
            (lambda: gs.morphs.Plane(normal="abc"), ("Plane", "'normal'")),
            (lambda: robot.set_sol_params("x"), (f"entity '{ENTITY}'", "'sol_params'", "real numbers", "strings")),
            (lambda: robot.set_dofs_position([0.1], dofs_idx_local=slice(0, 2, 0)),
             ("'dofs_idx_local'", "non-zero step")),
            (lambda: robot.set_dofs_position(torch.tensor([0.1, 0.2]).to_sparse()), ("'position'", "sparse")),
            (lambda: robot.set_dofs_position([0.1], dofs_idx_local=torch.tensor([1]).to_sparse()),
             ("'dofs_idx_local'", "dense tensor", "sparse")),
            (lambda: robot.inverse_kinematics_multilink(None, poss=[[0.3, 0.0, 0.5]]),
             (f"entity '{ENTITY}'", "'links'", "a list of one entry per link", "NoneType")),
            (lambda: scene.draw_debug_spheres("x"), ("scene.draw_debug_spheres", "'poss'", "finite numbers")),
            (lambda: scene.draw_debug_sphere((0.0, 0.0, 0.0), color="red"), ("'color'", "'red'"))]:
        raises(gs.InvalidInputError, call, *substrings)


def test_debug_drawing_takes_tensors_in_a_graph(f64, built):
    """A pose read from a differentiable scene (a tensor that requires grad) is drawn as it is: a
    single sphere or frame raised numpy's bare error on it."""
    scene, _ = built
    point = torch.tensor([0.1, 0.2, 0.3], dtype=torch.float64, requires_grad=True)
    frame = torch.eye(4, dtype=torch.float64).requires_grad_(True)
    for made in (scene.draw_debug_sphere(point), scene.draw_debug_frame(frame)):
        scene.clear_debug_object(made)


def test_negative_mass(f64, built):
    _, robot = built
    before = robot.get_links_mass().clone()
    raises(gs.InvalidInputError, lambda: robot.set_links_mass([-1.0], links_idx_local=[1]),
           f"entity '{ENTITY}'", "'mass'", "≥ 0", "-1")
    assert torch.equal(robot.get_links_mass(), before)


def test_requires_grad_tensor_without_requires_grad(f64, built):
    _, robot = built
    target = torch.zeros(2, dtype=torch.float64, requires_grad=True)
    raises(gs.GradientError, lambda: robot.set_dofs_position(target),
           f"entity '{ENTITY}'", "'position'", "requires grad", "SimOptions(requires_grad=True)")
    raises(gs.GradientError, lambda: robot.control_dofs_force(target * 2.0),
           f"entity '{ENTITY}'", "'force'", "SimOptions(requires_grad=True)")
    robot.set_dofs_position(target.detach())  # detaching is the other way out


def test_requires_grad_tensor_where_no_gradient_flows():
    """Morph poses and sizes and options are read as plain numbers: a tensor that requires grad
    raises GradientError naming the argument and where gradients do flow (it was torch's raw
    "Can't call numpy() on Tensor that requires grad"; found by an adversarial pass)."""
    grad = torch.tensor([0.0, 0.0, 0.15], dtype=torch.float64, requires_grad=True)
    raises(gs.GradientError, lambda: gs.morphs.Box(pos=grad), "Box: argument 'pos' is not differentiable",
           "set_pos")
    raises(gs.GradientError, lambda: gs.morphs.Box(size=grad + 1.0), "Box: argument 'size'", "fixed at build")
    raises(gs.GradientError, lambda: gs.morphs.Sphere(radius=grad[2] * 1.0), "Sphere: argument 'radius'")
    raises(gs.GradientError, lambda: gs.options.SimOptions(gravity=grad), "SimOptions: argument 'gravity'",
           "scene.set_gravity")
    raises(gs.GradientError, lambda: gs.morphs.Box(pos=[grad[0], 0.0, 0.0]), "Box: argument 'pos'")  # (in a list)
    raises(gs.GradientError, lambda: gs.morphs.URDF(file="robot.urdf", default_armature=grad[2] * 1.0),
           "URDF: argument 'default_armature'", "set_dofs_armature")  # (float() took it silently)
    assert gs.morphs.Box(pos=grad.detach()).pos.tolist() == [0.0, 0.0, 0.15]  # detached: plain values


def test_set_pos_on_fixed_base(f64, built):
    _, robot = built
    raises(gs.InvalidInputError, lambda: robot.set_pos([0.0, 0.0, 1.0]), f"entity '{ENTITY}'", "set_pos",
           "free base", "fixed")
    raises(gs.InvalidInputError, lambda: robot.set_quat([1.0, 0.0, 0.0, 0.0]), f"entity '{ENTITY}'",
           "set_quat", "free base", "fixed")


@pytest.mark.parametrize("kwargs, arg, given", [
    ({"dt": -0.01}, "'dt'", "-0.01"),
    ({"dt": 0.0}, "'dt'", "0.0"),
    ({"dt": math.nan}, "'dt'", "nan"),
    ({"substeps": 0}, "'substeps'", "0"),
    ({"substeps": 2.5}, "'substeps'", "2.5"),
    ({"gravity": (0.0, -9.81)}, "'gravity'", "-9.81"),
    ({"dt": "0.01"}, "'dt'", "'0.01'"),
    ({"dt": True}, "'dt'", "True"),
    ({"gravity": "down"}, "'gravity'", "'down'"),
    ({"requires_grad": "no"}, "'requires_grad'", "'no'"),
    ({"requires_grad": 1}, "'requires_grad'", "1"),
    ({"check_nan": "no"}, "'check_nan'", "'no'"),
], ids=["dt_negative", "dt_zero", "dt_nan", "substeps_zero", "substeps_fraction", "gravity_shape", "dt_string",
        "dt_bool", "gravity_string", "requires_grad_string", "requires_grad_int", "check_nan_string"])
def test_invalid_sim_options(f64, kwargs, arg, given):
    raises(gs.InvalidInputError, lambda: gs.options.SimOptions(**kwargs), "SimOptions", arg, "must be", given)


@pytest.mark.parametrize("options, name, what", [
    ("RigidOptions", "use_hibernation", "a Genesis option that genesis_lite does not have"),
    ("RigidOptions", "limit_timeconst", "unknown"),
    ("SimOptions", "floor_height", "a Genesis option that genesis_lite does not have"),
    ("VisOptions", "shadows", "unknown"),
    ("ViewerOptions", "fov", "unknown"),
])
def test_unknown_option_keyword(f64, options, name, what):
    """A keyword an options class lacks names the class, the keyword, why, and what is accepted."""
    raises(gs.InvalidInputError, lambda: getattr(gs.options, options)(**{name: 1}), options, f"'{name}'", what,
           "expected one of")


@pytest.mark.parametrize("morph", ["Box", "Sphere", "Plane", "URDF", "Mesh"])
def test_genesis_deprecated_morph_keywords_warn_and_are_ignored(f64, caplog, morph):
    """requires_jac_and_IK and is_free, which Genesis 1.4.5 takes with a deprecation warning and
    ignores, are taken so too (older Genesis scripts pass them)."""
    file = {"file": "x"} if morph in ("URDF", "Mesh") else {}
    with warns(caplog, f"{morph}: 'requires_jac_and_IK' is deprecated .*no effect"):
        made = getattr(gs.morphs, morph)(requires_jac_and_IK=True, **file)
    assert not hasattr(made, "requires_jac_and_IK")
    with warns(caplog, f"{morph}: 'is_free' is deprecated"):
        getattr(gs.morphs, morph)(is_free=False, **file)
    with warns(caplog, None):  # (Genesis says nothing of a None)
        getattr(gs.morphs, morph)(is_free=None, **file)


def test_smooth_contact_needs_the_elliptic_cone(f64):
    raises(gs.InvalidInputError, lambda: gs.options.RigidOptions(smooth_contact=True), "RigidOptions",
           "'smooth_contact'", "elliptic", "'pyramidal'")


def test_invalid_options_object(f64):
    raises(gs.InvalidInputError, lambda: gs.Scene(sim_options={"dt": 0.01}), "'sim_options'", "SimOptions",
           "dict")


@pytest.mark.parametrize("value", [-0.1, math.nan, "heavy", True])
def test_invalid_default_armature(f64, value):
    raises(gs.InvalidInputError, lambda: gs.morphs.URDF(file=asset("pendulum2.urdf"), default_armature=value),
           "URDF", "'default_armature'", "≥ 0", repr(value))
    raises(gs.InvalidInputError, lambda: gs.morphs.MJCF(file=asset("mjcf", "arm.xml"), default_armature=value),
           "MJCF", "'default_armature'", "≥ 0", repr(value))


def test_default_armature_reaches_every_joint_dof(f64):
    """Genesis's URDF option: armature on every revolute and prismatic dof (URDF has no tag for
    it), not on the free base's."""
    scene = gs.Scene()
    robot = scene.add_entity(gs.morphs.URDF(file=asset("quadruped.urdf"), default_armature=0.05))
    scene.build()
    expected = torch.full((robot.n_dofs,), 0.05, dtype=torch.float64)
    expected[:6] = 0.0
    assert torch.equal(robot.get_dofs_armature(), expected)
    scene.destroy()


def test_destroyed_scene_says_so(f64):
    """Everything on a destroyed scene raises a named error: adding a camera returned one that failed
    at its first render, adding an entity and building again allocated a simulator nothing could
    step, and a state taken before raised an AttributeError (an independent probe, 2026-12-02)."""
    scene = gs.Scene()
    scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True))
    scene.build()
    state = scene.get_state()
    scene.destroy()
    for call, what in ((scene.step, "scene.step"), (scene.add_camera, "scene.add_camera"),
                       (lambda: scene.add_entity(gs.morphs.Box()), "scene.add_entity"),
                       (scene.build, "scene.build"), (lambda: state.rigid, "SimState")):
        with pytest.raises(gs.SceneStateError, match=f"{what}: the scene was destroyed"):
            call()


def test_reset_to_another_scenes_state(f64, built):
    scene, _ = built
    other = gs.Scene()
    other.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True))
    other.build()
    with pytest.raises(gs.InvalidInputError, match="must come from this scene's get_state\\(\\), got a SimState of "
                                                   "another scene"):
        scene.reset(other.get_state())
    other.destroy()


def test_reset_to_a_bad_state(f64):
    """A SimState made or edited by hand is checked as the setters check values: a wrong shape,
    a meta tensor, NaN or a zero quaternion raised nothing (the kernels read past a short tensor,
    a meta one crashed the process)."""
    scene = gs.Scene()
    box = scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(0.0, 0.0, 0.5)), name="box")
    scene.build(n_envs=2)
    good = scene.get_state()
    for states, substrings in [
            ([], ("one state tensor per solver (RigidSolver)", "got a list of 0")),
            ([good.rigid, good.rigid], ("one state tensor per solver", "got a list of 2")),
            ([None], ("RigidSolver's) must be a real tensor with values of shape (2, 13)", "got NoneType")),
            ([good.rigid.to("meta")], ("shape (2, 13)", "got a torch.float64 tensor on meta")),
            ([good.rigid.long()], ("real tensor", "got a torch.int64 tensor")),
            ([good.rigid.to_sparse()], ("real tensor with values", "got a torch.sparse_coo torch.float64 tensor")),
            ([good.rigid[:, :5]], ("must have shape (2, 13), got (2, 5)",)),
            ([good.rigid.index_fill(1, torch.tensor([2]), math.nan)], ("must be finite", "(env, column) [0, 2]")),
            ([good.rigid.index_fill(1, torch.tensor([3, 4, 5, 6]), 0.0)],
             ("scene.reset: argument 'state' must hold non-zero quaternions", "joint 'root_joint'",
              "entity 'box' in env 0"))]:
        raises(gs.InvalidInputError, lambda: scene.reset(gs.SimState(scene, states, good.groups)), *substrings)
    moved = good.rigid.clone().float()  # another float dtype is taken, as by the setters
    moved[1, :3] = torch.tensor([1.0, 2.0, 3.0])
    scene.reset(gs.SimState(scene, [moved], good.groups))
    assert box.get_pos().tolist() == [[0.0, 0.0, 0.5], [1.0, 2.0, 3.0]]
    scene.destroy()


def test_zero_quaternion(f64):
    scene = gs.Scene()
    box = scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1)), name="box")
    scene.build()
    with pytest.raises(gs.InvalidInputError, match="entity 'box': argument 'quat' must hold non-zero"):
        box.set_quat([0.0, 0.0, 0.0, 0.0])
    with pytest.raises(gs.InvalidInputError, match="entity 'box': argument 'qpos' must hold non-zero"):
        box.set_qpos([0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0])
    box.set_qpos([0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    # a write of part of the quaternion is checked on the quaternion it leaves (w = 0 here left none)
    with pytest.raises(gs.InvalidInputError, match="entity 'box': argument 'qpos' must hold non-zero"):
        box.set_qpos([0.0], qs_idx_local=[3])
    box.set_qpos([0.0, 1.0], qs_idx_local=[3, 5])
    assert box.get_qpos()[3:].tolist() == [0.0, 0.0, 1.0, 0.0]
    scene.destroy()


def test_links_to_keep_without_merging():
    with pytest.raises(gs.InvalidInputError, match="'links_to_keep' .* needs merge_fixed_links=True"):
        gs.morphs.URDF(file=asset("pendulum2.urdf"), merge_fixed_links=False, links_to_keep=["link1"])


# -- contact parameters and shapes ------------------------------------------------------------------
def _box_on_plane():
    scene = gs.Scene()
    plane = scene.add_entity(gs.morphs.Plane())
    box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.2, 0.2), pos=(0, 0, 0.1)))
    scene.build()
    return plane, box


@pytest.mark.parametrize("friction", [-0.5, 0.0, 6.0, float("nan"), "high"])
def test_friction_out_of_range(f64, friction):
    _, box = _box_on_plane()
    with pytest.raises(gs.InvalidInputError, match=r"entity 'box_1': argument 'friction' must be a number in \[0.01"):
        box.set_friction(friction)


def test_negative_friction_ratio(f64):
    _, box = _box_on_plane()
    with pytest.raises(gs.InvalidInputError, match="argument 'friction_ratio' must be ≥ 0"):
        box.set_friction_ratio([-1.0])


@pytest.mark.parametrize("params", [(0.02, -1.0, 0.9, 0.95, 0.001, 0.5, 2.0),  # mixed solref signs
                                    (0.02, 1.0, 0.96, 0.95, 0.001, 0.5, 2.0),  # dmin > dmax
                                    (0.02, 1.0, 0.9, 1.0, 0.001, 0.5, 2.0),    # dmax = 1
                                    (0.02, 1.0, 0.9, 0.95, -0.001, 0.5, 2.0),  # negative width
                                    (0.02, 1.0, 0.9, 0.95, 0.001, 1.5, 2.0),   # midpoint ≥ 1
                                    (0.02, 1.0, 0.9, 0.95, 0.001, 0.5, 0.5)])  # power < 1
def test_sol_params_out_of_range(f64, params):
    _, box = _box_on_plane()
    with pytest.raises(gs.InvalidInputError, match="argument 'sol_params' expected timeconst and dampratio"):
        box.set_sol_params(params)


def test_sol_params_at_the_impedance_bounds_are_clamped_as_mujoco_does(f64):
    """dmin = dmax = 0 is in the range the message states (0 ≤ dmin ≤ dmax < 1) and was refused; the
    kernels clamp impedances to MuJoCo's [1e-4, 0.9999], so a box resting on a plane steps as with
    1e-4, bit for bit."""
    finals = []
    for dmin_dmax in (0.0, 1e-4):
        plane, box = _box_on_plane()
        for entity in (plane, box):  # (a contact mixes its two geoms' parameters)
            entity.set_sol_params((0.02, 1.0, dmin_dmax, dmin_dmax, 0.001, 0.5, 2.0))
        for _ in range(20):
            box.scene.step()
        finals.append(box.get_pos())
    assert torch.equal(*finals) and bool(torch.isfinite(finals[0]).all())


def test_mesh_without_a_hull(f64, tmp_path):
    flat = tmp_path / "flat.obj"  # every vertex in one plane: no convex hull with volume
    flat.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n")
    scene = gs.Scene()
    scene.add_entity(gs.morphs.Plane())
    scene.add_entity(gs.morphs.Mesh(file=str(flat), pos=(0, 0, 1)), name="tile")
    with pytest.raises(gs.GenesisException, match="entity 'tile': link 'flat' collision geom 0: .*convex hull"):
        scene.build()


@pytest.mark.parametrize("path,link", [(pybullet("cartpole.urdf"), "cart"),
                                       (pybullet("random_urdfs", "000", "000.urdf"), "random_obj_000")])
def test_singular_mass_matrix_names_the_link(f64, path, link):
    """A free base on a massless root (cartpole's slideBar carries the cart's prismatic joint: the
    cart moves no mass the base does not), or an inertia with a zero principal moment (izz = 0
    under a free joint's rotation), makes M singular: a named AssetError at build, not numpy's
    LinAlgError or a NaN on the first step (no rotor armature, which would give the dofs an inertia)."""
    scene = gs.Scene(rigid_options=gs.options.RigidOptions(enable_collision=False))
    scene.add_entity(gs.morphs.URDF(file=path, fixed=False, default_armature=None), name="bot")
    raises(gs.AssetError, scene.build, "entity 'bot'", f"link '{link}'", "positive definite mass matrix")


def test_zero_inertia_set_after_build_names_the_link(f64):
    """An inertia set to zero where it leaves M singular (a wheel's spin dof moves nothing else; its
    mass does not turn it): a named InvalidInputError, not torch's LinAlgError, and the inertias
    stay as they were (no rotor armature, which would give the wheel's dof an inertia)."""
    scene = gs.Scene(rigid_options=gs.options.RigidOptions(enable_collision=False))
    robot = scene.add_entity(gs.morphs.URDF(file=pybullet("r2d2.urdf"), default_armature=None), name="r2d2")
    scene.build(n_envs=2)
    before = robot.get_links_inertia().clone()
    wheel = [link.name for link in robot.links].index("left_front_wheel")
    raises(gs.InvalidInputError, lambda: robot.set_links_inertia(np.zeros((3, 3)), links_idx_local=[wheel],
                                                                 envs_idx=[1]),
           "entity 'r2d2'", "link 'left_front_wheel'", "positive definite mass matrix")
    assert torch.equal(robot.get_links_inertia(), before)
    before = robot.get_links_mass().clone()
    # no env selected (RL code passes done.nonzero()[:, 0], empty on most steps): nothing changes
    qpos = robot.get_qpos().clone()
    robot.set_links_mass([1.0], links_idx_local=[0], envs_idx=[])
    robot.set_qpos(torch.zeros(0, robot.n_qs, dtype=torch.float64), envs_idx=torch.zeros(0, dtype=torch.long))
    scene.reset(envs_idx=[])  # a plain empty list (numpy reads it as floats) too
    assert torch.equal(robot.get_links_mass(), before) and torch.equal(robot.get_qpos(), qpos)
    assert robot.get_qpos(envs_idx=[]).shape == (0, robot.n_qs)


def test_scene_gravity_errors_name_the_scene_method(f64, built):
    scene, _ = built
    raises(gs.InvalidInputError, lambda: scene.set_gravity([0.0, -9.81]), "scene.set_gravity", "'gravity'", "(3,)")
    raises(gs.InvalidInputError, lambda: scene.get_gravity(envs_idx=[0]), "scene.get_gravity", "'envs_idx'", "n_envs=0")
    message = raises(gs.InvalidInputError, lambda: scene.set_gravity([0.0, 0.0, math.nan]), "scene.set_gravity")
    assert ENTITY not in message


def test_inference_mode_is_refused_by_name(f64):
    """Under torch.inference_mode() build, step, reset, setters and controls raise a SceneStateError
    that says to use torch.no_grad() (torch's own error came from deep inside: inference tensors carry no version
    counter, which the scene reads); under no_grad the scene steps."""
    scene = gs.Scene()
    scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True), name=ENTITY)
    with torch.inference_mode(), pytest.raises(gs.SceneStateError, match=r"scene.build: .*inference_mode.*no_grad"):
        scene.build()
    scene.build()
    with torch.inference_mode(), pytest.raises(gs.SceneStateError, match=r"scene.step: .*inference_mode.*no_grad"):
        scene.step()
    # a control, a setter or a reset taken there left inference tensors in the scene, and every later
    # step, outside the mode too, raised torch's bare error (found by a Genesis port: rsl_rl steps there)
    robot = scene.entities[0]
    refused = {"control_dofs_position": lambda: robot.control_dofs_position(torch.zeros(2)),
               "set_dofs_kp": lambda: robot.set_dofs_kp(torch.ones(2)),
               "zero_all_dofs_velocity": robot.zero_all_dofs_velocity, "reset": scene.reset,
               "set_gravity": lambda: scene.set_gravity((0.0, 0.0, -1.0))}
    for name, call in refused.items():
        with torch.inference_mode(), pytest.raises(gs.SceneStateError, match=r"inference_mode.*no_grad"):
            call()
    # queries that only read the scene run there (and a render there leaves later renders working)
    camera = scene.add_camera(res=(16, 12))
    with torch.inference_mode():
        robot.get_jacobian(robot.links[-1], local_point=torch.zeros(3))
        robot.inverse_kinematics(robot.links[-1], pos=torch.tensor([0.1, 0.0, 0.5]))
        robot.get_dofs_position()
        camera.render()
    camera.render()
    with torch.no_grad():
        scene.step()
