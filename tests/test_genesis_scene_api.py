"""Genesis's scene-level API: reset(state, envs_idx), viewer/vis options and build/step
arguments, URDF(merge_fixed_links, links_to_keep), the no-contact warning and the friction
kept in the model (docs/genesis_api.md)."""
import re

import numpy as np
import pytest
import torch

import genesis_lite as gs
from genesis_lite.solvers.rigid import merge, shapes
from genesis_lite.solvers.rigid.spec import GeomSpec, LinkSpec
from genesis_lite.solvers.rigid.urdf import load_urdf
from tests.conftest import asset, pybullet, warns

R2D2, MINITAUR = pybullet("r2d2.urdf"), pybullet("quadruped", "minitaur.urdf")
KUKA = pybullet("kuka_iiwa", "model.urdf")


def _pendulum(requires_grad=True, n_envs=0):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=requires_grad))
    robot = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True))
    scene.build(n_envs=n_envs)
    return scene, robot


# ------------------------------------------------------------------ reset(state, envs_idx)


def _state_mid_rollout(scene, robot):
    """A state taken after 5 steps from an initial position that requires grad (its graph attached)."""
    q0 = torch.tensor([0.4, -0.3], dtype=torch.float64, requires_grad=True)
    robot.set_dofs_position(q0)
    for _ in range(5):
        scene.step()
    state = scene.get_state()
    assert state.rigid.grad_fn is not None
    return state


def test_reset_to_state_from_a_graph_then_backward_matches_fd(f64):
    scene, robot = _pendulum()
    scene.reset(_state_mid_rollout(scene, robot))

    def loss_of(mass, forces):
        for t in range(10):
            robot.control_dofs_force(forces[t])
            if t == 0:
                robot.set_links_mass(mass)
            scene.step()
        return (robot.get_dofs_position() ** 2).sum() + robot.get_links_pos()[-1].sum()

    mass = robot.get_links_mass().detach().clone().requires_grad_(True)
    forces = torch.linspace(-0.5, 0.5, 20, dtype=torch.float64).reshape(10, 2).requires_grad_(True)
    loss_of(mass, forces).backward()  # raised GradientError while the state kept its graph
    d_mass, d_forces = torch.tensor([0.0, 0.3, -0.2], dtype=torch.float64), torch.ones(10, 2, dtype=torch.float64)
    analytic = float(mass.grad @ d_mass + (forces.grad * d_forces).sum())
    with torch.no_grad():
        scene.reset()  # back to the state given to reset(state)
        plus = float(loss_of(mass + 1e-6 * d_mass, forces + 1e-6 * d_forces))
        scene.reset()
        minus = float(loss_of(mass - 1e-6 * d_mass, forces - 1e-6 * d_forces))
    numeric = (plus - minus) / 2e-6
    assert analytic != 0.0 and abs(analytic - numeric) <= 1e-6 * abs(numeric)


def test_reset_state_becomes_the_registered_initial_state(f64):
    scene, robot = _pendulum()
    state = _state_mid_rollout(scene, robot)
    expected = state.rigid.detach().clone()
    scene.reset(state)
    assert not scene.get_state().rigid.requires_grad  # detached, as Genesis stores it
    after_reset = []
    for _ in range(2):
        assert torch.equal(scene.get_state().rigid, expected)
        robot.control_dofs_force([0.3, -0.1])
        for _ in range(4):
            scene.step()
        after_reset.append(robot.get_dofs_position().detach().clone())
        scene.reset()  # plain reset: back to `state`, bit for bit, controls cleared
    assert torch.equal(after_reset[0], after_reset[1])
    assert torch.equal(robot.get_dofs_control_force(), torch.zeros(2, dtype=torch.float64))


@pytest.mark.parametrize("requires_grad", [False, True])
def test_get_state_is_a_snapshot_not_the_scene(f64, requires_grad):
    """Changing a get_state() snapshot in place changes neither the scene nor what reset() returns
    to: right after build the state tensor was the registered initial state itself (an edit moved
    the live scene and every later reset)."""
    scene, robot = _pendulum(requires_grad=requires_grad)
    snapshot = scene.get_state()
    initial = snapshot.rigid.detach().clone()
    with torch.no_grad():
        snapshot.rigid[0, 0] += 1.0
    assert torch.equal(scene.get_state().rigid, initial)
    robot.control_dofs_force([0.3, -0.1])
    for _ in range(3):
        scene.step()
    scene.reset()
    assert torch.equal(scene.get_state().rigid, initial)


def test_getter_results_save_load_and_deepcopy(f64, tmp_path):
    """A getter's gs.Tensor is saved as a plain torch tensor (torch.load's default weights_only=True
    refused the class: Genesis's plain tensors load), and deep-copies (torch's default needed
    new_empty to return the subclass) as torch's rules say: a leaf's data, grad and requires_grad,
    a copy apart; a non-leaf refused."""
    import copy
    scene, robot = _pendulum(requires_grad=False)
    qpos = robot.get_qpos()
    torch.save({"qpos": qpos}, tmp_path / "state.pt")
    loaded = torch.load(tmp_path / "state.pt")["qpos"]
    assert type(loaded) is torch.Tensor and torch.equal(loaded, qpos.as_subclass(torch.Tensor))
    copied = copy.deepcopy({"a": qpos, "b": [qpos]})
    assert isinstance(copied["a"], gs.Tensor) and copied["a"] is copied["b"][0] and copied["a"].scene is scene
    assert torch.equal(copied["a"], qpos) and copied["a"].data_ptr() != qpos.data_ptr()
    leaf = gs.tensor([1.0, 2.0], requires_grad=True)
    (3.0 * leaf).sum().backward()
    twin = copy.deepcopy(leaf)
    assert twin.is_leaf and twin.requires_grad and torch.equal(twin.grad, leaf.grad)
    with pytest.raises(RuntimeError, match="graph leaves"):
        copy.deepcopy(2.0 * leaf)



@pytest.mark.parametrize("n_envs", [0, 2])
def test_every_getter_returns_a_gs_tensor_whose_results_are_plain(f64, n_envs):
    """SPEC §2: every getter of the scene, rigid entities, links and MPM entities (no-argument
    calls, dict values and MPM state fields included) returns a gs.Tensor; what torch computes
    from one is a plain torch tensor, as Genesis 1.4.5's getters' results (a subclass result
    doubled the cost of each small op)."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(substeps=10),
                     mpm_options=gs.options.MPMOptions(lower_bound=(-0.5, -0.5, 0.0), upper_bound=(0.5, 0.5, 1.0),
                                                       grid_density=16))
    scene.add_entity(gs.morphs.Plane())
    box = scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(0.0, 0.0, 0.049)))
    robot = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True, pos=(0.3, 0.0, 0.5)))
    jelly = scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(-0.2, 0.0, 0.3)),
                             material=gs.materials.MPM.Muscle())
    scene.build(n_envs=n_envs)
    scene.step()
    values = {"jelly.get_state()." + k: v for k, v in vars(jelly.get_state()).items() if isinstance(v, torch.Tensor)}
    for name, owner in (("scene", scene), ("box", box), ("robot", robot), ("jelly", jelly),
                        ("link", robot.get_link(robot.links[-1].name))):
        for getter in (a for a in dir(owner) if a.startswith("get_") and a != "get_state"):
            try:
                value = getattr(owner, getter)()
            except gs.InvalidInputError as error:  # it takes arguments
                assert "missing a required argument" in str(error), str(error)
                continue
            items = value.items() if isinstance(value, dict) else enumerate(
                value if isinstance(value, tuple) else (value,))
            values.update({f"{name}.{getter}()[{k}]": v for k, v in items if isinstance(v, torch.Tensor)})
    assert len(values) > 40
    plain = [name for name, value in values.items() if not isinstance(value, gs.Tensor)]
    assert not plain, plain
    position = box.get_pos()
    assert type(position * 2.0 + 1.0) is torch.Tensor and type(position[..., 0]) is torch.Tensor

def test_reset_envs_idx_restores_only_those_envs(f64):
    scene, robot = _pendulum(requires_grad=False, n_envs=3)
    initial = scene.get_state().rigid.clone()
    robot.set_dofs_damping([[0.1, 0.2], [0.3, 0.4], [0.5, 0.6]])
    robot.set_dofs_position([[0.1, 0.2], [0.3, 0.4], [0.5, 0.6]])
    robot.control_dofs_force([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]])
    scene.step()
    before = scene.get_state().rigid.clone()
    scene.reset(envs_idx=[1])
    after = scene.get_state().rigid
    assert torch.equal(after[1], initial[1]) and torch.equal(after[[0, 2]], before[[0, 2]])
    np.testing.assert_array_equal(robot.get_dofs_control_force().numpy(), [[1, 2], [0, 0], [5, 6]])
    np.testing.assert_array_equal(robot.get_dofs_damping().numpy(), [[0.1, 0.2], [0.3, 0.4], [0.5, 0.6]])

    scene.reset(scene.get_state(), envs_idx=torch.tensor([2]))  # registers the whole state, resets env 2
    registered = scene.get_state().rigid.clone()
    robot.set_dofs_position([[-1.0, -1.0]] * 3)
    scene.reset()
    assert torch.equal(scene.get_state().rigid, registered)


def test_a_partial_reset_that_cuts_a_graph_warns_once(f64, caplog):
    """A partial reset detaches every env (docs/genesis_api.md): a loss on a kept env then reaches
    nothing, and torch's error said only that it does not require grad."""
    scene, robot = _pendulum(n_envs=2)
    with warns(caplog) as seen:
        scene.reset(envs_idx=[1])  # no graph yet: nothing said
    assert seen == []
    q0 = torch.tensor([[0.3, 0.2], [0.1, 0.1]], dtype=torch.float64, requires_grad=True)
    for envs_idx in ([1], [0, 1]):  # a loss backed through first, or no env kept: nothing lost, nothing said
        robot.set_dofs_position(q0)
        scene.step()
        if envs_idx == [1]:
            robot.get_dofs_position().sum().backward()
        with warns(caplog) as seen:
            scene.reset(envs_idx=envs_idx)
    robot.set_dofs_position(q0)
    scene.step()
    with warns(caplog, "starts a new autograd graph for every env, the ones it keeps too") as seen:
        scene.reset(envs_idx=[1])
        robot.set_dofs_position(q0)
        scene.reset(envs_idx=[0])
    assert len(seen) == 1
    assert not robot.get_dofs_position().requires_grad


@pytest.mark.parametrize("n_envs, envs_idx, expected", [
    (0, [0], "None in a scene built with n_envs=0"), (3, [3], "integers in [-3, 3) or a boolean mask of 3"),
    (3, [-4], "integers in [-3, 3) or a boolean mask of 3"), (3, [0.5], "integers in [-3, 3) or a boolean mask of 3"),
    (3, [[0]], "integers in [-3, 3) or a boolean mask of 3")])
def test_reset_bad_envs_idx(f64, n_envs, envs_idx, expected):
    scene, _ = _pendulum(requires_grad=False, n_envs=n_envs)
    with pytest.raises(gs.InvalidInputError, match=re.escape(f"scene.reset: argument 'envs_idx' must be {expected}, "
                                                             f"got {envs_idx!r}")):
        scene.reset(envs_idx=envs_idx)


# ------------------------------------------------------------------ viewer, vis, build and step arguments


def test_viewer_and_vis_options_defaults_are_genesis():
    viewer = gs.options.ViewerOptions()
    assert (viewer.res, viewer.run_in_thread, viewer.refresh_rate, viewer.realtime_factor, viewer.camera_pos,
            viewer.camera_lookat, viewer.camera_up, viewer.camera_fov, viewer.enable_help_text,
            viewer.enable_default_keybinds, viewer.enable_gui, viewer.max_FPS) == (
        None, None, 60, 1.0, (3.5, 0.5, 2.5), (0.0, 0.0, 0.5), (0.0, 0.0, 1.0), 40, True, True, False, None)
    vis = gs.options.VisOptions()
    assert (vis.show_world_frame, vis.world_frame_size, vis.show_link_frame, vis.link_frame_size, vis.show_cameras,
            vis.shadow, vis.plane_reflection, vis.split_envs, vis.background_color, vis.ambient_light,
            vis.segmentation_level, vis.render_particle_as, vis.particle_size_scale, vis.contact_force_scale,
            vis.n_support_neighbors, vis.rendered_envs_idx) == (
        False, 1.0, False, 0.2, False, True, False, False, (0.04, 0.08, 0.12), (0.1, 0.1, 0.1), "link", "sphere",
        1.0, 0.01, 12, None)
    assert vis.lights == [{"type": "directional", "dir": (-1.0, -1.0, -1.0), "color": (1.0, 1.0, 1.0),
                           "intensity": 5.0}]
    assert gs.options.ViewerOptions(max_FPS=30).refresh_rate == 30  # Genesis's deprecated alias


@pytest.mark.parametrize("kind, arg, value", [
    ("ViewerOptions", "res", (640,)), ("ViewerOptions", "refresh_rate", 0), ("ViewerOptions", "camera_fov", 180),
    ("ViewerOptions", "camera_pos", (0, 1)), ("ViewerOptions", "enable_gui", "yes"),
    ("ViewerOptions", "realtime_factor", -1.0), ("VisOptions", "shadow", 1),
    ("VisOptions", "background_color", (2, 0, 0)),
    ("VisOptions", "segmentation_level", "pixel"), ("VisOptions", "rendered_envs_idx", [-1]),
    ("VisOptions", "link_frame_size", 0.0), ("VisOptions", "lights", [{"type": "spot"}])])
def test_viewer_and_vis_options_bad_values(kind, arg, value):
    with pytest.raises(gs.InvalidInputError, match=rf"{kind}: argument '{arg}.* must be .*got"):
        getattr(gs.options, kind)(**{arg: value})


def test_scene_keeps_viewer_and_vis_options(f64):
    viewer, vis = gs.options.ViewerOptions(camera_fov=30), gs.options.VisOptions(show_world_frame=True)
    scene = gs.Scene(viewer_options=viewer, vis_options=vis, show_viewer=None)
    assert scene.viewer_options is viewer and scene.vis_options is vis and scene.show_viewer is False
    with pytest.raises(gs.InvalidInputError, match="'vis_options' must be gs.options.VisOptions, got ViewerOptions"):
        gs.Scene(vis_options=viewer)


@pytest.mark.parametrize("show_viewer", [True, 1, "yes"])
def test_show_viewer_raises(f64, show_viewer):
    with pytest.raises(gs.InvalidInputError, match="'show_viewer' must be False or None: .*no interactive viewer "
                                                    "yet .*cameras .*later release.*got"):
        gs.Scene(show_viewer=show_viewer)


def test_build_env_layout_is_genesis_and_leaves_the_physics(f64):
    finals = []
    for kwargs in ({}, dict(env_spacing=(1.0, 2.0)), dict(env_spacing=(1.0, 2.0), n_envs_per_row=2,
                                                          center_envs_at_origin=False)):
        scene = gs.Scene()
        robot = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True))
        scene.build(n_envs=5, **kwargs)
        robot.set_dofs_position(torch.full((5, 2), 0.3, dtype=torch.float64))
        for _ in range(3):
            scene.step(update_visualizer=False, refresh_visualizer=False)
        finals.append(robot.get_links_pos())
        if kwargs.get("n_envs_per_row") == 2:  # rows along x, columns along y, not centred
            assert scene.n_envs_per_row == 2
            np.testing.assert_array_equal(scene.envs_offset, [[0, 0, 0], [0, 2, 0], [1, 0, 0], [1, 2, 0], [2, 0, 0]])
        elif kwargs:  # ceil(sqrt(5)) = 3 per row, centred on the bounding box
            assert scene.n_envs_per_row == 3 and scene.env_spacing == (1.0, 2.0)
            np.testing.assert_array_equal(scene.envs_offset,
                                          [[-0.5, -2, 0], [-0.5, 0, 0], [-0.5, 2, 0], [0.5, -2, 0], [0.5, 0, 0]])
        else:
            np.testing.assert_array_equal(scene.envs_offset, np.zeros((5, 3)))
    assert torch.equal(finals[0], finals[1]) and torch.equal(finals[0], finals[2])


@pytest.mark.parametrize("kwargs, arg", [(dict(env_spacing=(1.0,)), "env_spacing"),
                                         (dict(env_spacing=(1.0, np.nan)), "env_spacing"),
                                         (dict(n_envs_per_row=0), "n_envs_per_row"),
                                         (dict(center_envs_at_origin="yes"), "center_envs_at_origin"),
                                         (dict(n_envs=True), "n_envs")])
def test_build_bad_arguments(f64, kwargs, arg):
    scene = gs.Scene()
    scene.add_entity(gs.morphs.Box())
    with pytest.raises(gs.InvalidInputError, match=f"scene.build: argument '{arg}' must be .*got"):
        scene.build(**kwargs)


def test_rendered_envs_idx_checked_at_build(f64):
    scene = gs.Scene(vis_options=gs.options.VisOptions(rendered_envs_idx=[0, 4]))
    scene.add_entity(gs.morphs.Box())
    with pytest.raises(gs.InvalidInputError, match=r"'rendered_envs_idx' must be env indices below 4 .*got \(0, 4\)"):
        scene.build(n_envs=4)


def test_step_bad_visualizer_flag(f64):
    scene, _ = _pendulum(requires_grad=False)
    with pytest.raises(gs.InvalidInputError, match="scene.step: argument 'refresh_visualizer' must be True or False"):
        scene.step(refresh_visualizer=None)


# ------------------------------------------------------------------ merge_fixed_links


def _entity(path, **morph_kwargs):
    scene = gs.Scene(rigid_options=gs.options.RigidOptions(enable_joint_limit=False, enable_collision=False))
    robot = scene.add_entity(gs.morphs.URDF(file=path, fixed=morph_kwargs.pop("fixed", False), **morph_kwargs))
    scene.build()
    return scene, robot


def test_kuka_has_no_fixed_joint_to_merge():
    links = load_urdf(KUKA)
    merged = merge.merge_fixed_links(links)
    assert [(s.name, s.parent, s.mass) for s in merged] == [(s.name, s.parent, s.mass) for s in links]


def test_r2d2_merged_as_genesis(f64):
    _, robot = _entity(R2D2)
    assert robot.n_links == 9 and robot.n_dofs == 14
    assert [link.name for link in robot.links] == [
        "base_link", "right_front_wheel", "right_back_wheel", "left_front_wheel", "left_back_wheel", "gripper_pole",
        "left_gripper", "right_gripper", "head"]
    np.testing.assert_allclose(robot.get_links_mass().numpy(), [50, 1, 1, 1, 1, 0.05, 0.1, 0.1, 11], rtol=1e-15)
    model = robot._solver.model
    assert np.bincount(model.geom_link, minlength=9).tolist() == [5, 1, 1, 1, 1, 1, 2, 2, 2]
    _, unmerged = _entity(R2D2, merge_fixed_links=False)
    assert unmerged.n_links == 16


def test_minitaur_merged_as_genesis(f64):
    _, robot = _entity(MINITAUR)
    assert robot.n_links == 17 and robot.n_dofs == 22
    mass = dict(zip((link.name for link in robot.links), robot.get_links_mass().numpy()))
    assert mass["base_chassis_link"] == pytest.approx(3.2, rel=1e-15)
    assert all(mass[name] == pytest.approx(0.3, rel=1e-15) for name in mass if name.startswith("motor_"))


@pytest.mark.parametrize("path", [R2D2, MINITAUR])
def test_merged_model_has_the_same_dynamics(f64, path):
    """Merging moves no dof (ours keeps the dof order), so mass matrices and trajectories compare as they are."""
    results = []
    for merge_fixed_links in (False, True):
        scene, robot = _entity(path, merge_fixed_links=merge_fixed_links)
        rng = np.random.default_rng(0)
        qpos = rng.uniform(-1, 1, robot.n_qs)
        qpos[3:7] /= np.linalg.norm(qpos[3:7])
        robot.set_qpos(qpos)
        robot.set_dofs_velocity(rng.uniform(-1, 1, robot.n_dofs))
        mass_mat = robot.get_mass_mat().numpy()
        robot.control_dofs_force(rng.uniform(-0.2, 0.2, robot.n_dofs))
        for _ in range(20):
            scene.step()
        poses = dict(zip((link.name for link in robot.links), robot.get_links_pos().numpy()))
        results.append((mass_mat, robot.get_qpos().numpy(), robot.get_dofs_velocity().numpy(), poses))
    (m0, q0, v0, poses0), (m1, q1, v1, poses1) = results
    np.testing.assert_allclose(m1, m0, rtol=0, atol=1e-12 * np.abs(m0).max())
    np.testing.assert_allclose(q1, q0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(v1, v0, rtol=0, atol=1e-12)
    for name, pos in poses1.items():  # the merged links keep their parent's frame
        np.testing.assert_allclose(pos, poses0[name], rtol=0, atol=1e-12)


def _box_link(name, parent, pos, quat, size, joint_type="fixed"):
    geom = GeomSpec("box", np.array(size))
    mass, com, inertia = shapes.geometry_mass_properties([geom], 1000.0)
    return LinkSpec(name=name, parent=parent, joint_name=f"{name}_joint", joint_type=joint_type, pos=np.array(pos),
                    quat=np.array(quat), axis=np.array([0.0, 0.0, 1.0]), mass=mass, com=com, inertia=inertia,
                    geoms=[geom])


def test_merge_combines_mass_properties_exactly_and_reparents():
    turn = np.array([np.cos(0.35), np.sin(0.35), 0.0, 0.0])  # 0.7 rad about x
    links = [_box_link("root", -1, [0, 0, 0], [1, 0, 0, 0], [0.2, 0.3, 0.4]),
             _box_link("welded", 0, [0.5, 0.1, -0.2], turn, [0.1, 0.1, 0.6]),
             _box_link("grandchild", 1, [0.0, 0.0, 0.3], [1, 0, 0, 0], [0.1, 0.1, 0.1], joint_type="revolute"),
             _box_link("sibling", 0, [-0.5, 0, 0], [1, 0, 0, 0], [0.1, 0.2, 0.1], joint_type="revolute")]
    merged = merge.merge_fixed_links(links)
    assert [(s.name, s.parent) for s in merged] == [("root", -1), ("grandchild", 0), ("sibling", 0)]
    assert merged[0].merged == [("welded", "welded_joint")] and links[0].geoms != merged[0].geoms  # input untouched
    # the same two boxes placed in the root frame directly
    moved = GeomSpec("box", np.array([0.1, 0.1, 0.6]), pos=np.array([0.5, 0.1, -0.2]), quat=turn)
    mass, com, inertia = shapes.geometry_mass_properties([links[0].geoms[0], moved], 1000.0)
    root = merged[0]
    assert root.mass == pytest.approx(mass, rel=1e-14)
    np.testing.assert_allclose(root.com, com, rtol=0, atol=1e-15)
    np.testing.assert_allclose(root.inertia, inertia, rtol=0, atol=1e-15)
    np.testing.assert_allclose(root.geoms[1].pos, moved.pos, atol=1e-15)
    np.testing.assert_allclose(root.geoms[1].quat, moved.quat, atol=1e-15)
    # the grandchild's joint frame: the welded link's frame composed with its own
    np.testing.assert_allclose(merged[1].pos, [0.5, 0.1, -0.2] + shapes.quat_to_mat(turn) @ [0, 0, 0.3], atol=1e-15)
    np.testing.assert_allclose(merged[1].quat, turn, atol=1e-15)


def test_merge_massless_part_adds_nothing():
    links = [_box_link("root", -1, [0, 0, 0], [1, 0, 0, 0], [0.2, 0.3, 0.4]),
             _box_link("marker", 0, [1.0, 0, 0], [1, 0, 0, 0], [0.1, 0.1, 0.1])]
    links[1].mass = 0.0  # its inertia stays non-zero: the model ignores it, so must the merge
    root = merge.merge_fixed_links(links)[0]
    assert root.mass == links[0].mass
    np.testing.assert_array_equal(root.com, links[0].com)
    np.testing.assert_array_equal(root.inertia, links[0].inertia)


def test_links_to_keep(f64):
    _, robot = _entity(R2D2, links_to_keep=["left_tip", "box"])
    names = [link.name for link in robot.links]
    assert robot.n_links == 11 and "left_tip" in names and "box" in names and "right_tip" not in names
    assert names.index("left_tip") > names.index("left_gripper")
    with pytest.raises(gs.InvalidInputError, match=r"entity 'urdf_0': gs.morphs.URDF: argument 'links_to_keep' "
                                                   r"expected names of links of the file, got unknown names \['tip'\]"):
        _entity(R2D2, links_to_keep=["tip"])


@pytest.mark.parametrize("kwargs, arg", [(dict(merge_fixed_links=1), "merge_fixed_links"),
                                         (dict(links_to_keep="box"), "links_to_keep"),
                                         (dict(links_to_keep=[3]), "links_to_keep")])
def test_urdf_merge_arguments_checked(kwargs, arg):
    with pytest.raises(gs.InvalidInputError, match=f"URDF: argument '{arg}' must be .*got"):
        gs.morphs.URDF(file=R2D2, **kwargs)


def test_merged_into_names_the_absorbing_link():
    merged = merge.merge_fixed_links(load_urdf(R2D2))
    assert merge.merged_into(merged, "right_base") == "base_link"
    assert merge.merged_into(merged, "left_tip") == "left_gripper"
    assert merge.merged_into(merged, "head") is None


def test_joints_are_the_moving_ones(f64):
    """As in Genesis: a fixed joint is no RigidJoint; a free root's joint is 'root_joint' (r2d2:
    the root and 8 moving joints of its 16 links; a fixed KUKA: its 7 revolute joints)."""
    _, r2d2 = _entity(R2D2)
    assert r2d2.n_joints == 9 and r2d2.joints[0].name == "root_joint" and r2d2.joints[0].type == "free"
    assert all(joint.n_dofs > 0 for joint in r2d2.joints)
    assert sum(joint.n_dofs for joint in r2d2.joints) == r2d2.n_dofs
    scene = gs.Scene()
    kuka = scene.add_entity(gs.morphs.URDF(file=KUKA, fixed=True))
    assert [joint.name for joint in kuka.joints] == [f"lbr_iiwa_joint_{k}" for k in range(1, 8)]
    assert [joint.dofs_idx_local for joint in kuka.joints] == [[k] for k in range(7)]
    with pytest.raises(gs.InvalidInputError, match="'left_base_joint' is a fixed joint \\(of link 'base_link'\\)"):
        r2d2.get_joint("left_base_joint")


def test_get_link_of_a_merged_away_name(f64):
    _, robot = _entity(R2D2)
    with pytest.raises(gs.InvalidInputError, match="'right_base' was merged into link 'base_link'"):
        robot.get_link("right_base")


# ------------------------------------------------------------------ which geom pairs may collide; friction kept


def _candidate_pairs(morphs, **options):
    scene = gs.Scene(rigid_options=gs.options.RigidOptions(**options))
    for morph in morphs:
        scene.add_entity(morph)
    scene.build()
    model = scene._rigid_solver.model
    return list(zip(model.pair_geom1.tolist(), model.pair_geom2.tolist()))


def test_plane_and_free_box_may_collide_ordered_as_mujoco(f64):
    assert _candidate_pairs([gs.morphs.Box(pos=(0, 0, 1)), gs.morphs.Plane()]) == [(1, 0)]  # plane first


@pytest.mark.parametrize("case", ["plane alone", "box alone", "two fixed boxes", "parent and child",
                                  "collision off"])
def test_no_candidate_pair_when_nothing_can_touch(f64, tmp_path, case):
    morphs = {"plane alone": [gs.morphs.Plane()], "box alone": [gs.morphs.Box()],
              "two fixed boxes": [gs.morphs.Box(fixed=True), gs.morphs.Box(fixed=True, pos=(0, 0, 0.5))],
              "parent and child": [gs.morphs.URDF(file=_friction_urdf(tmp_path), fixed=True)],  # adjacent only
              "collision off": [gs.morphs.Plane(), gs.morphs.Box(pos=(0, 0, 1))]}[case]
    assert _candidate_pairs(morphs, enable_collision=case != "collision off") == []


def test_pair_rules_self_adjacent_and_neutral(f64, tmp_path):
    arm = lambda: [gs.morphs.URDF(file=_friction_urdf(tmp_path), fixed=True)]  # parent a (1 box), child b (2)
    assert _candidate_pairs(arm()) == []
    assert len(_candidate_pairs(arm(), enable_adjacent_collision=True, enable_neutral_collision=True)) == 2
    # the two boxes overlap at the initial pose: a neutral pair, dropped unless enabled
    assert _candidate_pairs(arm(), enable_adjacent_collision=True) == []
    assert _candidate_pairs(arm(), enable_adjacent_collision=True, enable_self_collision=False,
                            enable_neutral_collision=True) == []


def _friction_urdf(tmp_path, lateral="0.3"):
    contact = "" if lateral is None else f'<contact><lateral_friction value="{lateral}"/></contact>'
    box = '<collision><geometry><box size="0.1 0.1 0.1"/></geometry></collision>'
    inertial = '<inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial>'
    path = tmp_path / "friction.urdf"
    path.write_text(f'<robot name="f"><link name="a">{inertial}{box}</link>'
                    f'<link name="b">{inertial}{contact}{box}{box}</link>'
                    f'<joint name="j" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>'
                    f'<dynamics damping="0.1" friction="0.7"/></joint></robot>')
    return str(path)


def test_friction_kept_in_the_model(f64, tmp_path):
    path = _friction_urdf(tmp_path)
    scene = gs.Scene()
    scene.add_entity(gs.morphs.URDF(file=path, fixed=True))
    scene.add_entity(gs.morphs.URDF(file=path, fixed=True), material=gs.materials.Rigid(friction=0.5))
    scene.add_entity(gs.morphs.Box(), material=gs.materials.Rigid(friction=2.0))
    scene.build()
    model = scene._rigid_solver.model
    # file: link a states nothing (Genesis's default 1.0), b's <contact><lateral_friction> 0.3; the material wins
    np.testing.assert_array_equal(model.geom_friction[:, 0], [1.0, 0.3, 0.3, 0.5, 0.5, 0.5, 2.0])
    np.testing.assert_array_equal(model.geom_friction[:, 1:], [[0.005, 0.0001]] * 7)  # MuJoCo's and Genesis's defaults
    np.testing.assert_array_equal(model.geom_link, [0, 1, 1, 2, 3, 3, 4])
    np.testing.assert_array_equal(model.dof_frictionloss, [0.7, 0.7, 0, 0, 0, 0, 0, 0])  # the box's free dofs: 0


@pytest.mark.parametrize("lateral", ["-1", "abc"])
def test_bad_lateral_friction(tmp_path, lateral):
    with pytest.raises(gs.AssetError, match="link 'b' contact lateral_friction value expected a .*number"):
        load_urdf(_friction_urdf(tmp_path, lateral))


@pytest.mark.parametrize("friction", [0.0, 6.0, "1", True])
def test_material_friction_range_is_genesis(friction):
    with pytest.raises(gs.InvalidInputError, match=r"argument 'friction' must be a number in \[0.01, 5.0\]"):
        gs.materials.Rigid(friction=friction)


def test_primitive_bit_masks_filter_contacts_as_genesis(f64):
    """Genesis's collision/contype.py: primitives' contype and conaffinity (default 0xFFFF, the
    plane's too) pick the pairs that touch, (contype₁ & conaffinity₂) | (contype₂ & conaffinity₁)
    ≠ 0: red (1) and green (2) pass through each other onto the floor, blue (3) lands on both; a
    box of masks 0 falls through everything and a default one lands on blue."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01))
    scene.add_entity(gs.morphs.Plane())
    boxes = {name: scene.add_entity(gs.morphs.Box(pos=(x, 0.0, z), size=(0.1, 0.1, 0.1), **masks))
             for name, x, z, masks in (("red", 0.025, 0.5, dict(contype=1, conaffinity=1)),
                                       ("green", -0.025, 1.0, dict(contype=2, conaffinity=2)),
                                       ("blue", 0.0, 1.5, dict(contype=3, conaffinity=3)),
                                       ("ghost", 0.5, 0.5, dict(contype=0, conaffinity=0)),
                                       ("plain", 0.0, 2.0, {}))}
    scene.build()
    for _ in range(200):
        scene.step()
    z = {name: box.get_pos()[2].item() for name, box in boxes.items()}
    assert z["red"] == pytest.approx(0.05, abs=2e-3) and z["green"] == pytest.approx(0.05, abs=2e-3), z
    assert z["blue"] == pytest.approx(0.15, abs=3e-3) and z["plain"] == pytest.approx(0.25, abs=4e-3), z
    assert z["ghost"] < -1.0  # (through the floor)
    for bad in (-1, 2 ** 32, 1.5, True):
        with pytest.raises(gs.InvalidInputError, match="argument 'contype' must be an integer bit mask"):
            gs.morphs.Sphere(contype=bad)
    particles = gs.Scene(mpm_options=gs.options.MPMOptions(lower_bound=(-1, -1, 0), upper_bound=(1, 1, 1)))
    with pytest.raises(gs.InvalidInputError, match="'contype', 'conaffinity', 'collision' and 'visualization' of "
                                                   "gs.morphs.Box are a rigid entity's"):
        particles.add_entity(gs.morphs.Box(pos=(0, 0, 0.5), size=(0.1, 0.1, 0.1), contype=2),
                             material=gs.materials.MPM.Elastic())


def test_morph_collision_and_visualization_switches_as_genesis(f64):
    """Morph(collision=False): the entity's shapes in no contact pair (a URDF robot falls through
    the floor); visualization=False: cameras do not draw it (its pixels are the floor's); both False
    is refused, as in Genesis."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01),
                     vis_options=gs.options.VisOptions(segmentation_level="entity"))
    plane = scene.add_entity(gs.morphs.Plane())
    ghost = scene.add_entity(gs.morphs.URDF(file=pybullet("r2d2.urdf"), pos=(0, 0, 0.6), collision=False))
    hidden = scene.add_entity(gs.morphs.Box(pos=(2.0, 0.0, 0.05), size=(0.1, 0.1, 0.1), visualization=False))
    camera = scene.add_camera(res=(32, 32), pos=(2.0, 0.0, 1.0), lookat=(2.0, 0.0, 0.0), up=(0.0, 1.0, 0.0), fov=20)
    scene.build()
    for _ in range(100):
        scene.step()
    assert ghost.get_pos()[2].item() < -1.0 and hidden.get_pos()[2].item() == pytest.approx(0.05, abs=2e-3)
    segmentation = camera.render(rgb=False, segmentation=True)[2]
    assert np.unique(np.asarray(segmentation)).tolist() == [plane.idx]  # (the box below the camera: not drawn)
    with pytest.raises(gs.InvalidInputError, match="'visualization' and 'collision' cannot both be False"):
        gs.morphs.Sphere(visualization=False, collision=False)


def test_a_urdf_without_collision_is_weighed_from_its_visuals_as_genesis(f64, tmp_path):
    """URDF(collision=False) leaves the <collision> elements out, as Genesis does: a link without
    <inertial> is then weighed from its visuals (Genesis 1.4.5: 0.6 kg for this 0.1 m visual box,
    its 0.2 m collision box aside)."""
    path = tmp_path / "two_boxes.urdf"
    path.write_text('<robot name="r"><link name="l"><collision><geometry><box size="0.2 0.2 0.2"/></geometry>'
                    '</collision><visual><geometry><box size="0.1 0.1 0.1"/></geometry></visual></link></robot>')
    scene = gs.Scene()
    plain = scene.add_entity(gs.morphs.URDF(file=str(path)))
    ghost = scene.add_entity(gs.morphs.URDF(file=str(path), pos=(1, 0, 0), collision=False))
    scene.build()
    assert float(plain.get_mass()) == pytest.approx(600.0 * 0.2 ** 3, rel=1e-12)
    assert float(ghost.get_mass()) == pytest.approx(600.0 * 0.1 ** 3, rel=1e-12) and ghost.n_geoms == 0


def test_solver_level_readouts_are_the_entities_side_by_side(f64):
    """scene.sim.rigid_solver's get_links_pos/quat/vel/ang, get_dofs_position/velocity and get_qpos
    by scene-wide indices (link.idx, entity.dof_start + local) equal the entities' own readouts,
    batched or not, differentiable as theirs; get_error_envs_mask flags the env whose state went
    non-finite (a box tumbling to inf under a torque, as in test_robustness); scene.rigid_solver is
    that object, as Genesis's (a named error before build)."""
    for n_envs in (0, 2):
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True))
        scene.add_entity(gs.morphs.Plane())
        arm = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True, pos=(0, 0, 1)))
        box = scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(1, 0, 0.5)))
        scene.build(n_envs=n_envs)
        solver = scene.sim.rigid_solver
        assert (solver.n_links, solver.n_dofs, solver.n_qs) == (1 + arm.n_links + 1, arm.n_dofs + 6, arm.n_qs + 7)
        speed = torch.tensor(0.7, dtype=torch.float64, requires_grad=True)
        arm.set_dofs_velocity(speed * torch.ones(arm.n_dofs, dtype=torch.float64).expand(
            *([n_envs] if n_envs else []), arm.n_dofs))
        for _ in range(3):
            scene.step()
        links, dofs = [box.links[0].idx, arm.links[-1].idx], [box.dof_start + 2, arm.dof_start + 1]
        for name in ("pos", "quat", "vel", "ang"):
            mine = getattr(solver, f"get_links_{name}")(links)
            theirs = torch.stack([getattr(box, f"get_links_{name}")()[..., 0, :],
                                  getattr(arm, f"get_links_{name}")()[..., -1, :]], dim=-2)
            assert torch.equal(mine, theirs), name
        assert torch.equal(solver.get_dofs_position(dofs), torch.stack(
            [box.get_dofs_position()[..., 2], arm.get_dofs_position()[..., 1]], dim=-1))
        assert torch.equal(solver.get_qpos()[..., box.q_start:box.q_start + 7], box.get_qpos())
        grad, = torch.autograd.grad(solver.get_links_pos(links[1:]).sum(), speed, retain_graph=True)
        expected, = torch.autograd.grad(arm.get_links_pos()[..., -1, :].sum(), speed)
        assert torch.equal(grad, expected) and float(grad) != 0.0
        assert not solver.get_error_envs_mask().any()
        with pytest.raises(gs.InvalidInputError, match="scene.sim.rigid_solver"):
            solver.get_links_pos([solver.n_links])
    heavy = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01))
    tumbler = heavy.add_entity(gs.morphs.Box(size=(0.2, 0.3, 0.1), pos=(0, 0, 3)), material=gs.materials.Rigid(rho=200.0))
    with pytest.raises(gs.SceneStateError, match="scene.rigid_solver: the scene is not built"):
        heavy.rigid_solver
    assert getattr(heavy, "rigid_solver", None) is None  # (read as absent, as hasattr does)
    heavy.build(n_envs=2)
    for _ in range(50):
        tumbler.apply_links_external_wrench(torque=[[[0.0, 0.0, 0.0]], [[3.0, -2.0, 1.0]]], links_idx_local=[0])
        heavy.step()
    assert heavy.sim.rigid_solver.get_error_envs_mask().tolist() == [False, True]
    # Genesis's go2 example asks scene.rigid_solver itself (the same object as scene.sim.rigid_solver)
    assert heavy.rigid_solver is heavy.sim.rigid_solver
    assert heavy.rigid_solver.get_error_envs_mask().tolist() == [False, True]


def test_default_armature_is_genesis_rotor_unless_mujoco_compatible(f64, tmp_path):
    """Genesis 1.4.5's default_armature (URDF and MJCF): 0.1 on every hinge and slide dof whose
    armature the file leaves at 0 (an MJCF's own armature kept; a free joint's dofs and a ball's
    none); none under enable_mujoco_compatibility unless given; None: none."""
    mjcf = tmp_path / "chain.xml"
    mjcf.write_text('<mujoco><worldbody><body name="a"><freejoint/><geom size="0.1"/>'
                    '<body name="b" pos="0 0 0.3"><joint name="h" armature="0.02"/><geom size="0.1"/>'
                    '<body name="c" pos="0 0 0.3"><joint name="s" type="slide"/><geom size="0.1"/>'
                    '<body name="d" pos="0 0 0.3"><joint name="k" type="ball"/><geom size="0.1"/>'
                    '</body></body></body><body name="e" pos="0.3 0 0"><joint name="p" axis="1 0 0"/>'
                    '<joint name="q" axis="0 1 0" pos="0 0 0.1"/><geom size="0.1"/></body></body></worldbody></mujoco>')
    cases = [({}, False, 0.1), ({}, True, 0.0), ({"default_armature": 0.1}, True, 0.1),
             ({"default_armature": None}, False, 0.0), ({"default_armature": 0.03}, False, 0.03)]
    for given, compatible, rotor in cases:
        scene = gs.Scene(rigid_options=gs.options.RigidOptions(enable_collision=False,
                                                               enable_mujoco_compatibility=compatible))
        urdf = scene.add_entity(gs.morphs.URDF(file=asset("arm3.urdf"), fixed=True, **given))
        chain = scene.add_entity(gs.morphs.MJCF(file=str(mjcf), **given))
        scene.build()
        assert urdf.get_dofs_armature().tolist() == [rotor] * 3, (given, compatible)
        # (body e moves by two hinges: one link of two dofs in Genesis, which gives it no rotor)
        assert chain.get_dofs_armature().tolist() == [0.0] * 6 + [0.02, rotor] + [0.0] * 5, (given, compatible)
        scene.destroy()


def test_default_armature_on_motor_joints_only_and_urdf_gains(f64):
    """As Genesis: URDF(default_armature) goes to revolute and prismatic dofs, not to a free base's
    (which then falls at exactly g: one Euler step from rest, vz = −g·dt); the Panda's
    <safety_controller k_position k_velocity> are its arm joints' kp and kv (Genesis 1.4.5: kv 40)."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01),
                     rigid_options=gs.options.RigidOptions(enable_collision=False))
    arm = scene.add_entity(gs.morphs.URDF(file=asset("arm3.urdf"), pos=(0, 0, 1), default_armature=0.1))
    panda = scene.add_entity(gs.morphs.URDF(file=pybullet("franka_panda/panda.urdf"), fixed=True))
    scene.build()
    assert arm.get_dofs_armature().tolist() == [0.0] * 6 + [0.1] * (arm.n_dofs - 6)
    scene.step()
    assert arm.get_dofs_velocity()[2].item() == pytest.approx(-9.81 * 0.01, rel=1e-12)
    assert panda.get_dofs_kp().tolist() == [100.0] * 9
    assert panda.get_dofs_kv().tolist() == [40.0] * 7 + [10.0] * 2  # the fingers have no safety controller


def test_rigid_options_gravity_is_the_rigid_bodies_own(f64):
    """RigidOptions(gravity=...) (Genesis's; its IK examples float a robot with (0, 0, 0)) is the
    rigid solver's gravity in place of SimOptions.gravity: a free box falls by it, z_n = z_0 +
    g dt² n(n + 1)/2 (semi-implicit Euler), none at all with zeros; get_gravity reports it and
    set_gravity still sets it; a bad one is a named error."""
    dt, steps = 0.01, 20
    for g in (-2.0, 0.0):
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=dt, gravity=(0.0, 0.0, -9.81)),
                         rigid_options=gs.options.RigidOptions(gravity=(0.0, 0.0, g)))
        box = scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(0.0, 0.0, 5.0)))
        scene.build()
        assert scene.get_gravity().tolist() == [0.0, 0.0, g]
        for _ in range(steps):
            scene.step()
        assert float(box.get_pos()[2]) == pytest.approx(5.0 + g * dt ** 2 * steps * (steps + 1) / 2, abs=1e-12)
        assert box.get_pos()[:2].abs().max() == 0.0
    scene.set_gravity((0.0, 0.0, -1.0))
    assert scene.get_gravity().tolist() == [0.0, 0.0, -1.0]
    with pytest.raises(gs.InvalidInputError, match="RigidOptions: argument 'gravity'"):
        gs.options.RigidOptions(gravity=(0.0, -9.81))
