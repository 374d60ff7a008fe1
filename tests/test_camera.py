"""Cameras through the public API (scene.add_camera, camera.render, recording, following, batched
scenes, debug spheres) against references we did not write: the pinhole projection of known
corners, a sphere's analytic silhouette, trimesh's ray casts of URDF visual meshes posed by
yourdfpy's forward kinematics, imageio reading the videos back, and (when an OpenGL context can be
made) moderngl drawing the same triangles."""
import glob
import logging
import os

import numpy as np
import pytest
import torch
import trimesh
import yourdfpy

import genesis_lite as gs
from genesis_lite.solvers.rigid import merge
from genesis_lite.solvers.rigid.urdf import load_urdf
from genesis_lite.vis.visuals import scene_shapes
from tests.conftest import pybullet, warns

KUKA, R2D2 = pybullet("kuka_iiwa", "model.urdf"), pybullet("r2d2.urdf")
KUKA_Q = [0.3, 0.5, -0.2, -1.0, 0.4, 0.8, 0.1]
NO_CONTACT = dict(rigid_options=gs.options.RigidOptions(enable_collision=False))


# ------------------------------------------------------------------ references


def pinhole(pos, lookat, up, fov, res):
    """(world → camera rotation (3, 3) rows x right / y up / z back, focal length px) of Genesis's
    pinhole camera: z = (pos − lookat)/|·|, x = up × z normalised, y = z × x; f = (H/2)/tan(fov/2)."""
    z = np.subtract(pos, lookat) / np.linalg.norm(np.subtract(pos, lookat))
    x = np.cross(up, z) / np.linalg.norm(np.cross(up, z))
    return np.stack([x, np.cross(z, x), z]), res[1] / 2 / np.tan(np.radians(fov) / 2)


def project(points, pos, lookat, up, fov, res):
    """Pixel coordinates (N, 2) (u right, v down; pixel (i, j) spans [j, j+1] × [i, i+1]) and
    depths along the view axis (N,) of world points (N, 3)."""
    rot, f = pinhole(pos, lookat, up, fov, res)
    cam = (np.asarray(points, dtype=np.float64) - pos) @ rot.T
    depth = -cam[:, 2]
    return np.stack([res[0] / 2 + f * cam[:, 0] / depth, res[1] / 2 - f * cam[:, 1] / depth], axis=1), depth


def ray_cast_mask(mesh, pos, lookat, up, fov, res):
    """(H, W) bool: pixel-centre rays of the pinhole camera that hit the trimesh ``mesh`` (trimesh's ray caster)."""
    rot, f = pinhole(pos, lookat, up, fov, res)
    u, v = np.meshgrid(np.arange(res[0]) + 0.5, np.arange(res[1]) + 0.5)
    local = np.stack([(u - res[0] / 2) / f, -(v - res[1] / 2) / f, -np.ones_like(u)], axis=-1).reshape(-1, 3)
    hit = mesh.ray.intersects_any(np.tile(pos, (len(local), 1)), local @ rot)
    return hit.reshape(res[1], res[0])


def iou(a, b):
    return (a & b).sum() / (a | b).sum()


def yourdfpy_visuals(path, cfg):
    """The URDF's visual meshes in the world (root at the origin), posed by yourdfpy at joint
    values ``cfg`` (name → value), concatenated into one trimesh."""
    robot = yourdfpy.URDF.load(path, load_meshes=True, build_scene_graph=True)
    robot.update_cfg(cfg)
    return robot.scene.to_geometry()


# ------------------------------------------------------------------ images


def test_box_on_plane_from_above_pixels_depth_segmentation(f32):
    scene = gs.Scene(**NO_CONTACT)
    plane = scene.add_entity(gs.morphs.Plane())
    box = scene.add_entity(gs.morphs.Box(size=(0.4, 0.3, 0.2), pos=(0.1, -0.05, 0.1), fixed=True),
                           surface=gs.surfaces.Default(color=(1.0, 0.0, 0.0)))
    view = dict(pos=(0.0, 0.0, 3.0), lookat=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0), fov=40, res=(320, 240))
    cam = scene.add_camera(**view)
    sky = scene.add_camera(res=(64, 48), pos=(0.0, 0.0, 3.0), lookat=(0.0, 0.0, 4.0), up=(0.0, 1.0, 0.0))
    scene.build()
    rgb, depth, seg, normal = cam.render(depth=True, segmentation=True, normal=True)
    assert rgb.shape == (240, 320, 3) and rgb.dtype == np.uint8
    assert depth.shape == seg.shape == (240, 320) and depth.dtype == np.float32
    assert normal.shape == (240, 320, 3)
    # the box's top face (z = 0.2) is its whole silhouette from straight above
    corners = np.array([[x, y, 0.2] for x in (-0.1, 0.3) for y in (-0.2, 0.1)])
    uv, _ = project(corners, **view)
    (u0, v0), (u1, v1) = uv.min(axis=0), uv.max(axis=0)
    u, v = np.meshgrid(np.arange(320) + 0.5, np.arange(240) + 0.5)
    inside = (u > u0 + 0.5) & (u < u1 - 0.5) & (v > v0 + 0.5) & (v < v1 - 0.5)
    outside = (u < u0 - 0.5) | (u > u1 + 0.5) | (v < v0 - 0.5) | (v > v1 + 0.5)
    assert inside.sum() > 1500
    assert (seg[inside] == box.links[0].idx).all() and (seg[outside] == plane.links[0].idx).all()
    assert (rgb[inside][:, 0] > 100).all() and (rgb[inside][:, 1:] == 0).all()  # red, shaded
    grey = rgb[outside].astype(int)
    assert (grey[:, 0] > 20).all() and (grey[:, 0] == grey[:, 1]).all() and (grey[:, 1] == grey[:, 2]).all()
    np.testing.assert_allclose(depth[inside], 2.8, rtol=5e-3)
    np.testing.assert_allclose(depth[outside], 3.0, rtol=5e-3)
    assert np.abs(normal[inside | outside] - [0.0, 0.0, 1.0]).max() < 1e-4
    # only what was asked for, as Genesis: None in the other slots
    rgb_only = cam.render()
    assert rgb_only[1:] == (None, None, None) and np.array_equal(rgb_only[0], rgb)
    assert cam.render(rgb=False, depth=True)[0] is None
    # nothing drawn: background colour, depth = far, segmentation -1 (Genesis's background key)
    rgb, depth, seg, _ = sky.render(depth=True, segmentation=True)
    background = np.round(np.array(scene.vis_options.background_color) * 255)
    assert (np.abs(rgb.reshape(-1, 3) - background) <= 1).all()
    assert (depth == sky.far).all() and (seg == -1).all()


def test_sphere_silhouette_matches_its_analytic_projection(f32):
    scene = gs.Scene(**NO_CONTACT)
    ball = scene.add_entity(gs.morphs.Sphere(radius=0.5, fixed=True))
    cam = scene.add_camera(res=(400, 400), pos=(0.0, 0.0, 4.0), lookat=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0), fov=30)
    scene.build()
    _, _, seg, _ = cam.render(rgb=False, segmentation=True)
    # the cone of rays tangent to the sphere has half-angle asin(r/d): a disc of radius f·tan(asin(r/d)) px
    f, r, d = cam.f, 0.5, 4.0
    disc = np.pi * (f * r / np.sqrt(d * d - r * r)) ** 2
    area = (seg == ball.links[0].idx).sum()
    assert abs(area / disc - 1) < 0.01, (area, disc)


def test_primitive_morph_silhouettes_match_trimesh_ray_casts(f32):
    mesh_file = pybullet("kuka_iiwa", "meshes", "link_2.stl")
    shapes = [(gs.morphs.Box(size=(0.3, 0.2, 0.25), pos=(0.0, -0.6, 0.2), euler=(20, 30, 40), fixed=True),
               trimesh.creation.box(extents=(0.3, 0.2, 0.25))),
              (gs.morphs.Cylinder(radius=0.1, height=0.3, pos=(0.0, -0.2, 0.2), euler=(60, 0, 10), fixed=True),
               trimesh.creation.cylinder(radius=0.1, height=0.3, sections=512)),
              (gs.morphs.Capsule(radius=0.08, height=0.2, pos=(0.0, 0.2, 0.2), euler=(0, 50, 0), fixed=True),
               trimesh.creation.capsule(radius=0.08, height=0.2, count=[256, 256])),
              (gs.morphs.Mesh(file=mesh_file, scale=1.5, pos=(0.0, 0.6, 0.1), euler=(90, 0, 0), fixed=True),
               trimesh.load(mesh_file, force="mesh").apply_scale(1.5))]
    scene = gs.Scene(**NO_CONTACT)
    for morph, _ in shapes:
        scene.add_entity(morph)
    view = dict(pos=(1.2, 0.2, 0.8), lookat=(0.0, 0.0, 0.2), up=(0.0, 0.0, 1.0), fov=70, res=(320, 240))
    cam = scene.add_camera(**view)
    scene.build()
    _, _, seg, _ = cam.render(rgb=False, segmentation=True)
    for k, (morph, mesh) in enumerate(shapes):
        pose = trimesh.transformations.quaternion_matrix(morph.quat)
        pose[:3, 3] = morph.pos
        reference = ray_cast_mask(mesh.copy().apply_transform(pose), **view)
        assert reference.sum() > 300, (type(morph).__name__, reference.sum())
        assert iou(seg == k, reference) >= 0.98, (type(morph).__name__, iou(seg == k, reference))


@pytest.mark.parametrize("path, cfg", [(KUKA, KUKA_Q), (R2D2, None)], ids=["kuka", "r2d2"])
def test_urdf_visual_silhouette_matches_trimesh_ray_casts(f32, path, cfg):
    scene = gs.Scene(**NO_CONTACT)
    robot = scene.add_entity(gs.morphs.URDF(file=path, fixed=True))
    view = dict(pos=(1.0, 0.8, 1.0), lookat=(0.0, 0.0, 0.5 if cfg else 0.0), up=(0.0, 0.0, 1.0), fov=60,
                res=(200, 150))
    cam = scene.add_camera(**view)
    scene.build()
    names = {joint.name: k for k, joint in enumerate(robot.joints)}
    if cfg:
        robot.set_dofs_position(cfg)
    _, _, seg, _ = cam.render(rgb=False, segmentation=True)
    reference = ray_cast_mask(yourdfpy_visuals(path, {name: cfg[k] for name, k in names.items()} if cfg else {}),
                              **view)
    assert reference.sum() > 2000
    assert iou(seg >= 0, reference) >= 0.98


def test_urdf_material_colours_and_surface_override(f32):
    scene = gs.Scene(**NO_CONTACT)
    robot = scene.add_entity(gs.morphs.URDF(file=KUKA, fixed=True))
    painted = scene.add_entity(gs.morphs.URDF(file=R2D2, pos=(0.0, 1.0, 0.5), fixed=True),
                               surface=gs.surfaces.Default(color=(0.0, 1.0, 0.0, 1.0)))
    cam = scene.add_camera(res=(240, 180), pos=(2.5, 0.5, 1.0), lookat=(0.0, 0.5, 0.5), fov=50)
    scene.build()
    rgb, _, seg, _ = cam.render(segmentation=True)
    # link 3 names the robot-level material "Orange" (1, 0.42, 0.04); links 1, 2 "Blue" (0.5, 0.7, 1)
    orange = rgb[seg == robot.get_link("lbr_iiwa_link_3").idx].astype(int)
    blue = rgb[seg == robot.get_link("lbr_iiwa_link_2").idx].astype(int)
    assert len(orange) > 50 and len(blue) > 50
    assert (orange[:, 0] > orange[:, 1]).all() and (orange[:, 1] > orange[:, 2]).all()
    assert (blue[:, 2] > blue[:, 1]).all() and (blue[:, 1] > blue[:, 0]).all()
    r2d2_ids = [link.idx for link in painted.links]
    green = rgb[np.isin(seg, r2d2_ids)]
    assert len(green) > 500 and (green[:, [0, 2]] == 0).all() and (green[:, 1] > 0).all()


URDF_MATERIALS = """<robot name="colours">
  <link name="a"><visual><geometry><box size="0.1 0.1 0.1"/></geometry>
    <material name="red"><color rgba="1 0 0 1"/></material></visual></link>
  <link name="b"><visual><geometry><sphere radius="0.1"/></geometry><material name="red"/></visual>
    <visual><geometry><cylinder radius="0.1" length="0.2"/></geometry><material name="nope"/></visual></link>
  <joint name="ab" type="fixed"><parent link="a"/><child link="b"/><origin xyz="0 0 0.5"/></joint>
</robot>"""


def test_urdf_visuals_named_materials_and_merging(tmp_path):
    path = tmp_path / "colours.urdf"
    path.write_text(URDF_MATERIALS)
    links = load_urdf(str(path))
    assert [[v.type for v in link.visuals] for link in links] == [["box"], ["sphere", "cylinder"]]
    # "red" is defined inside link a's visual and named by link b's; "nope" is defined nowhere
    assert [v.rgba.tolist() if v.rgba is not None else None for link in links for v in link.visuals] == \
        [[1.0, 0.0, 0.0, 1.0], [1.0, 0.0, 0.0, 1.0], None]
    (merged,) = merge.merge_fixed_links(links)
    assert [v.type for v in merged.visuals] == ["box", "sphere", "cylinder"]
    np.testing.assert_allclose(merged.visuals[1].pos, [0.0, 0.0, 0.5])  # b's visuals move with b's frame
    path.write_text(URDF_MATERIALS.replace('rgba="1 0 0 1"', 'rgba="2 0 0 1"'))
    with pytest.raises(gs.AssetError, match=r"material 'red' color expected rgba: 4 numbers in \[0, 1\], got "
                                            r"\[2.0, 0.0, 0.0, 1.0\]"):
        load_urdf(str(path))


@pytest.mark.parametrize("level", ["entity", "link", "geom"])
def test_segmentation_levels(f32, level):
    scene = gs.Scene(vis_options=gs.options.VisOptions(segmentation_level=level), **NO_CONTACT)
    plane = scene.add_entity(gs.morphs.Plane())
    robot = scene.add_entity(gs.morphs.URDF(file=R2D2, pos=(0.0, 0.0, 0.5), fixed=True))
    cam = scene.add_camera(res=(160, 120), pos=(1.5, 1.0, 1.0), lookat=(0.0, 0.0, 0.4), fov=50)
    scene.build()
    _, _, seg, _ = cam.render(rgb=False, segmentation=True)
    ids = set(np.unique(seg).tolist()) - {-1}  # -1: the sky above the horizon
    if level == "entity":
        assert ids == {plane.idx, robot.idx}
    elif level == "link":
        assert plane.links[0].idx in ids and len(ids & {link.idx for link in robot.links}) >= 5
    else:  # one id per drawn shape: the plane's, then r2d2's 16 visuals
        assert 0 in ids and len(ids) >= 8 and max(ids) <= 16
    colours = cam.render(rgb=False, segmentation=True, colorize_seg=True)[2]
    assert colours.shape == (120, 160, 3) and colours.dtype == np.uint8
    assert len(np.unique(colours.reshape(-1, 3), axis=0)) == len(ids) + 1  # black: the sky


def test_debug_spheres_are_drawn_by_debug_cameras(f32):
    scene = gs.Scene(**NO_CONTACT)
    plane = scene.add_entity(gs.morphs.Plane())
    view = dict(pos=(0.0, 0.0, 3.0), lookat=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0), fov=40, res=(160, 120))
    debug, plain = scene.add_camera(**view, debug=True), scene.add_camera(**view)
    with pytest.raises(gs.SceneStateError, match="draw_debug_spheres.*build"):
        scene.draw_debug_spheres(np.zeros((1, 3)))
    scene.build()
    centres = np.array([[0.0, 0.0, 0.5], [0.4, 0.1, 0.5], [-0.3, -0.2, 0.2]])
    blue = scene.draw_debug_spheres(torch.as_tensor(centres), radius=0.05, color=(0.0, 0.0, 1.0, 0.5))
    red = scene.draw_debug_sphere((0.2, -0.3, 0.5), radius=0.08, color=(1.0, 0.0, 0.0))
    rgb, depth, seg, _ = debug.render(depth=True, segmentation=True)
    uv, _ = project(centres, **view)
    rows, cols = uv[:, 1].astype(int), uv[:, 0].astype(int)
    assert (rgb[rows, cols, 2] > 0).all() and (rgb[rows, cols, :2] == 0).all() and (seg[rows, cols] == -1).all()
    np.testing.assert_allclose(depth[60, 80], 3.0 - 0.5 - 0.05, rtol=5e-3)  # the sphere on the view axis
    (red_u, red_v), = project([[0.2, -0.3, 0.5]], **view)[0]
    assert (rgb[int(red_v), int(red_u)] > 0).tolist() == [True, False, False]
    assert (plain.render(segmentation=True)[2] == plane.links[0].idx).all()  # not a debug camera: no spheres
    scene.clear_debug_object(blue)
    rgb = debug.render()[0]
    assert (rgb[rows, cols, 0] == rgb[rows, cols, 2]).all() and (rgb[rows, cols, 0] > 0).all()  # the grey plane
    assert rgb[int(red_v), int(red_u), 1] == 0  # the other object stays
    scene.clear_debug_objects()
    with pytest.raises(gs.InvalidInputError, match="clear_debug_object.*'obj'"):
        scene.clear_debug_object(red)


def test_debug_arrows_lines_frames_boxes_and_trajectories(f32):
    """Genesis's draw_debug_arrow/line/frame(s)/box/trajectory: triangle meshes in world
    coordinates that debug cameras draw (seg −1) where they were put, with Genesis's arrow
    proportions (the head a quarter of the length, 1.5× the body's radius), a frame's axes red,
    green and blue, a box's edges only; cleared by clear_debug_object(s); bad arguments named."""
    scene = gs.Scene(**NO_CONTACT)
    scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(5.0, 5.0, -5.0)), gs.materials.Rigid(rho=1000))
    view = dict(pos=(0.0, 0.0, 5.0), lookat=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0), fov=40, res=(240, 240))
    cam, plain = scene.add_camera(**view, debug=True), scene.add_camera(**view)
    scene.build()

    def drawn(camera=cam):
        points, hit = camera.render_pointcloud()
        return points[hit], camera.render()[0][hit]

    arrow = scene.draw_debug_arrow((-1.0, 0.0, 0.0), (2.0, 0.0, 0.0), radius=0.05, color=(0.0, 1.0, 0.0, 1.0))
    points, colours = drawn()
    assert len(drawn(plain)[0]) == 0 and (colours[:, 1] > colours[:, 0]).all() and (colours[:, 2] == 0).all()
    assert points[:, 0].min() == pytest.approx(-1.0, abs=0.02)
    assert points[:, 0].max() == pytest.approx(1.0, abs=0.06)  # (the tip: thinner than a pixel of 1.5 cm)
    pixel = 2 * 5.0 * np.tan(np.radians(20.0)) / 240  # m: the drawn widths are within a pixel of these
    body, head = points[points[:, 0] < 0.4], points[(points[:, 0] > 0.5) & (points[:, 0] < 0.55)]
    assert 0.05 - pixel <= np.abs(body[:, 1]).max() <= 0.05
    assert 0.075 * (1 - 0.05 / 0.5) - pixel <= np.abs(head[:, 1]).max() <= 0.075  # the cone near its base
    assert scene.draw_debug_arrow((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)) is None  # nothing to draw, as Genesis
    scene.clear_debug_object(arrow)
    assert len(drawn()[0]) == 0

    turned = np.eye(4)
    turned[:3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]  # its x axis along world y, y along −x
    scene.draw_debug_frame(turned, axis_length=1.0, origin_size=0.05, axis_radius=0.03)
    points, colours = drawn()
    along_y = (points[:, 1] > 0.3) & (np.abs(points[:, 0]) < 0.1)
    along_minus_x = (points[:, 0] < -0.3) & (np.abs(points[:, 1]) < 0.1)
    assert (colours[along_y].argmax(1) == 0).all() and (colours[along_minus_x].argmax(1) == 1).all()
    assert along_y.sum() > 100 and along_minus_x.sum() > 100 and not ((points[:, 0] > 0.3).any())
    assert points[:, :2].max() == pytest.approx(1.0, abs=0.02)  # cylinders: no arrow head beyond
    scene.clear_debug_objects()

    scene.draw_debug_box([[-1.0, -1.0, -0.5], [1.0, 1.0, 0.5]], wireframe_radius=0.02)
    points = drawn()[0]
    assert len(points) > 100 and (np.abs(points[:, :2]).max(1) > 0.97).all()  # none inside: the edges only
    scene.clear_debug_objects()
    scene.draw_debug_box([[-1.0, -1.0, -0.5], [1.0, 1.0, 0.5]], wireframe=False)
    assert np.abs(drawn()[0][:, 2] - 0.5).max() < 1e-2  # the solid box's top face hides the rest
    normals = cam.render(rgb=False, normal=True)[3][120, 120]
    np.testing.assert_allclose(normals, [0.0, 0.0, 1.0], atol=1e-3)  # flat faces, not corner-averaged normals
    scene.clear_debug_objects()

    scene.draw_debug_line((0.0, -1.0, 0.0), (0.0, 1.0, 0.0), radius=0.02)
    scene.draw_debug_trajectory(np.array([[0.5, -1.0, 0.0], [0.5, 0.0, 0.0], [1.0, 0.0, 0.0]]), radius=0.02)
    points = drawn()[0]
    on_line = np.abs(points[:, 0]) < 0.03
    assert on_line.sum() > 50 and np.abs(points[~on_line, 0] - 0.5).min() < 0.03 and points[:, 0].max() > 0.97
    assert scene.draw_debug_line((0, 0, 0), (0, 0, 0)) is None  # nothing to draw, as a zero arrow
    assert scene.draw_debug_trajectory([[0.0, 0.0, 0.0]]) is None
    for call, match in ((lambda: scene.draw_debug_arrow((0, 0, 0), (1, 0, 0), radius=-1), "'radius'"),
                        (lambda: scene.draw_debug_box([[0, 0, 0], [-1, 1, 1]]), "'bounds'"),
                        (lambda: scene.draw_debug_frame(np.eye(3)), "'T'"),
                        (lambda: scene.draw_debug_trajectory([0, 0, 0]), "'poss'"),
                        (lambda: scene.draw_debug_line((0, 0, 0), (1, 0, 0), color=(2, 0, 0)), "'color'")):
        with pytest.raises(gs.InvalidInputError, match=match):
            call()


def test_vis_mode_collision_draws_the_collision_shapes(f32, tmp_path):
    """add_entity(vis_mode="collision") (or the surface's), as Genesis's: the cameras draw the
    entity's collision shapes instead of its visual ones (a URDF whose visual box hides inside its
    collision sphere: the depth on the view axis is the sphere's top, not the box's), a mesh as the
    convex hull it collides as (a ring's hole filled)."""
    urdf = tmp_path / "two_faces.urdf"
    urdf.write_text('<robot name="two_faces"><link name="body"><inertial><mass value="1"/><inertia ixx="1" iyy="1" '
                    'izz="1" ixy="0" ixz="0" iyz="0"/></inertial><visual><geometry><box size="0.1 0.1 0.1"/></geometry>'
                    '</visual><collision><geometry><sphere radius="0.3"/></geometry></collision></link></robot>')
    view = dict(pos=(0.0, 0.0, 3.0), lookat=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0), fov=30, res=(64, 64))
    depths = {}
    for mode, given_to_add_entity in (("visual", False), ("collision", False), ("collision", True)):
        scene = gs.Scene(**NO_CONTACT)
        morph = gs.morphs.URDF(file=str(urdf), fixed=True)
        if given_to_add_entity:
            scene.add_entity(morph, vis_mode=mode)
        else:
            scene.add_entity(morph, surface=gs.surfaces.Default(vis_mode=mode))
        cam = scene.add_camera(**view)
        scene.build()
        depths[mode, given_to_add_entity] = float(cam.render(rgb=False, depth=True)[1][32, 32])
    assert depths["visual", False] == pytest.approx(3.0 - 0.05, abs=2e-3)
    assert depths["collision", False] == depths["collision", True] == pytest.approx(3.0 - 0.3, abs=5e-3)
    # a mesh collides as its convex hull, and is drawn so: a ring's hole is filled
    import trimesh
    ring = tmp_path / "ring.obj"
    trimesh.creation.torus(major_radius=0.3, minor_radius=0.1).export(ring)
    for mode, hole_depth in (("visual", None), ("collision", 3.0 - 0.1)):
        scene = gs.Scene(**NO_CONTACT)
        scene.add_entity(gs.morphs.Mesh(file=str(ring), fixed=True), vis_mode=mode)
        cam = scene.add_camera(**view)
        scene.build()
        depth = float(cam.render(rgb=False, depth=True)[1][32, 32])
        assert depth == pytest.approx(hole_depth, abs=5e-3) if hole_depth else depth >= cam.far * 0.99, (mode, depth)


def test_visualize_contact_draws_each_contact_force_on_the_entity(f32):
    """add_entity(visualize_contact=True) (Genesis's): a debug camera draws an arrow of each contact
    force on the entity, from the contact point, VisOptions.contact_force_scale m/N long (a box
    at rest on a plane: four arrows up from its bottom corners, a quarter of its weight each, out
    through its top), as Genesis's markers only its debug cameras draw; an entity without the
    flag, and MPM particles, draw none (the latter refused)."""
    scale, size = 0.05, 0.2
    scene = gs.Scene(vis_options=gs.options.VisOptions(contact_force_scale=scale))
    scene.add_entity(gs.morphs.Plane())
    box = scene.add_entity(gs.morphs.Box(size=(size, size, size), pos=(0.0, 0.0, size / 2)), visualize_contact=True)
    other = scene.add_entity(gs.morphs.Box(size=(size, size, size), pos=(1.0, 0.0, size / 2)))
    view = dict(pos=(0.5, -1.6, 0.4), lookat=(0.5, 0.0, 0.4), up=(0.0, 0.0, 1.0), fov=50, res=(320, 320))
    cam, plain = scene.add_camera(**view, debug=True), scene.add_camera(**view)
    scene.build()
    for _ in range(50):
        scene.step()
    weight = float(box.get_mass()) * 9.81
    points, hit = cam.render_pointcloud()
    rgb = cam.render()[0]
    cyan = hit & (rgb[..., 1] > 120) & (rgb[..., 2] > 120) & (rgb[..., 0] < 60)
    above = points[cyan]
    assert len(above) > 50 and np.abs(np.abs(above[:, 0]) - size / 2).max() < 0.02  # at the corners' x
    assert above[:, 2].max() == pytest.approx(scale * weight / 4, abs=0.03)  # the arrow's tip
    assert not (cyan & (np.abs(points[..., 0] - 1.0) < 0.2)).any()  # the other box has none
    rgb = plain.render()[0]
    assert not ((rgb[..., 1] > 120) & (rgb[..., 2] > 120) & (rgb[..., 0] < 60)).any()  # not a debug camera
    drawn = scene._contact_arrows()
    assert drawn and scene._contact_arrows() is drawn  # kept while the contacts stay
    fresh = gs.Scene()
    with pytest.raises(gs.InvalidInputError, match="'visualize_contact' must be a bool"):
        fresh.add_entity(gs.morphs.Box(), visualize_contact="yes")
    with pytest.raises(gs.InvalidInputError, match="'visualize_contact'.*Elastic"):
        fresh.add_entity(gs.morphs.Box(), gs.materials.MPM.Elastic(), visualize_contact=True)


def test_near_plane_clipping(f32):
    scene = gs.Scene(**NO_CONTACT)
    plane = scene.add_entity(gs.morphs.Plane())
    behind = scene.add_entity(gs.morphs.Box(size=(0.5, 0.5, 0.5), pos=(-1.0, 0.0, 1.0), fixed=True))
    view = dict(pos=(0.0, 0.0, 1.0), lookat=(1.0, 0.0, 1.0), up=(0.0, 0.0, 1.0), fov=60, res=(160, 120))
    cam = scene.add_camera(**view, near=0.1)
    scene.build()
    _, depth, seg, _ = cam.render(depth=True, segmentation=True)
    assert behind.links[0].idx not in seg  # behind the camera: nothing drawn
    # the ground plane crosses the near plane: below the horizon each row sees it at h·f/(v − cy)
    rows = np.arange(66, 120)  # nearer than far (20 m)
    expected = 1.0 * cam.f / (rows + 0.5 - 60.0)
    np.testing.assert_allclose(depth[rows, :], np.repeat(expected[:, None], 160, axis=1), rtol=5e-3)
    assert (seg[:60] == -1).all() and (seg[rows] == plane.links[0].idx).all()


# ------------------------------------------------------------------ following, batched scenes


def test_follow_entity_keeps_the_entity_at_the_image_centre(f32):
    scene = gs.Scene(**NO_CONTACT)
    box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.2, 0.2), pos=(0.0, 0.0, 2.0)))
    cam = scene.add_camera(res=(160, 120), pos=(2.0, 1.0, 2.5), lookat=(0.0, 0.0, 2.0), fov=40)
    cam.follow_entity(box)  # before build: the offset is measured at build
    still = scene.add_camera(res=(160, 120), pos=(2.0, 1.0, 2.5), lookat=(0.0, 0.0, 2.0), fov=40)
    scene.build()
    box.set_dofs_velocity([1.0, -0.5, 0.0, 0.0, 0.0, 0.0])
    for _ in range(40):
        scene.step()
    from_solver = still.render(rgb=False, segmentation=True)[2]  # the link poses read where the step left them
    pos = box.get_pos().numpy()  # the state is now a tensor: poses come from it
    assert np.array_equal(still.render(rgb=False, segmentation=True)[2], from_solver)
    for camera, centred in ((cam, True), (still, False)):
        seg = camera.render(rgb=False, segmentation=True)[2]
        v, u = np.nonzero(seg == box.links[0].idx)
        off_centre = np.hypot(u.mean() + 0.5 - 80, v.mean() + 0.5 - 60) if len(u) else np.inf
        assert (off_centre < 2.0) == centred, off_centre
    np.testing.assert_allclose(cam.pos - pos, [2.0, 1.0, 0.5], atol=1e-4)
    np.testing.assert_allclose(cam.lookat, pos, atol=1e-4)
    cam.follow_entity(box, fixed_axis=(None, None, 3.0))
    scene.step()
    cam.render()
    assert cam.pos[2] == pytest.approx(3.0)


def test_env_idx_draws_its_env_at_its_offset(f32):
    scene = gs.Scene(**NO_CONTACT)
    box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.2, 0.2), pos=(0.0, 0.0, 1.0)))
    view = dict(pos=(0.0, 0.0, 3.0), lookat=(0.0, 0.0, 1.0), up=(0.0, 1.0, 0.0), fov=40, res=(160, 120))
    cams = [scene.add_camera(**view, env_idx=k) for k in range(3)]
    scene.build(n_envs=3, env_spacing=(10.0, 10.0))
    box.set_pos(np.array([[0.0, 0.0, 1.0], [0.3, 0.0, 1.0], [-0.3, 0.2, 1.0]]))
    for k, cam in enumerate(cams):
        np.testing.assert_allclose(cam.pos, np.array(view["pos"]) + scene.envs_offset[k], atol=1e-5)
        seg = cam.render(rgb=False, segmentation=True)[2]
        v, u = np.nonzero(seg == box.links[0].idx)
        top = box.get_pos().numpy()[k] + [0.0, 0.0, 0.1]
        (expected_u, expected_v), = project([top], **view)[0]
        assert abs(u.mean() + 0.5 - expected_u) < 1.0 and abs(v.mean() + 0.5 - expected_v) < 1.0


def test_rendered_envs_idx_and_bad_env_idx(f32):
    scene = gs.Scene(vis_options=gs.options.VisOptions(rendered_envs_idx=[1]), **NO_CONTACT)
    scene.add_entity(gs.morphs.Box(size=(0.2, 0.2, 0.2), pos=(0.0, 0.0, 1.0)))
    cam = scene.add_camera()
    bad = scene.add_camera(env_idx=0)
    with pytest.raises(gs.InvalidInputError, match=r"camera 1: argument 'env_idx' must be one of the rendered envs "
                                                   r"\[1\].*got 0"):
        scene.build(n_envs=2)
    scene = gs.Scene(**NO_CONTACT)
    scene.add_entity(gs.morphs.Box())
    scene.build(n_envs=2)
    assert scene.add_camera().env_idx == 0
    with pytest.raises(gs.InvalidInputError, match=r"camera 1: argument 'env_idx' .*got 5"):
        scene.add_camera(env_idx=5)
    assert cam.env_idx == 1 and bad.env_idx == 0  # the default: the first rendered env


def test_a_plane_other_than_horizontal_is_drawn_in_every_env(f32):
    """A wall (normal +y) stands in each env at its drawing offset (a horizontal plane is the same
    plane in every env and drawn once; a wall is not): each env's camera, 2 m in front of its own
    wall, sees it 2 m away (it saw env 0's wall, 6 m away, from env 1)."""
    scene = gs.Scene(**NO_CONTACT)
    scene.add_entity(gs.morphs.Plane(pos=(0.0, -1.0, 0.0), normal=(0.0, 1.0, 0.0)))
    cams = [scene.add_camera(res=(32, 24), pos=(0.0, 1.0, 0.5), lookat=(0.0, -1.0, 0.5), env_idx=k) for k in range(2)]
    scene.build(n_envs=2, env_spacing=(4.0, 4.0))
    for cam in cams:
        depth = cam.render(rgb=False, depth=True)[1]
        assert depth[12, 16] == pytest.approx(2.0, abs=1e-4)


def test_follow_entity_refuses_a_camera_at_the_base_before_anything_is_built(f32):
    """A camera standing at the followed entity's base (within float32's rounding of its position:
    the view would point where the rounding does) is refused; told before build, the build raises
    before anything is built, and a build after moving the camera works."""
    scene = gs.Scene(**NO_CONTACT)
    box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.2, 0.2), pos=(0.1, 0.3, 0.7)))
    cam = scene.add_camera(pos=(0.1, 0.3, 0.7), lookat=(1.0, 0.0, 0.7))
    other = scene.add_camera(pos=(2.0, 0.0, 1.0), lookat=(0.0, 0.0, 0.5))
    cam.follow_entity(box)
    with pytest.raises(gs.InvalidInputError, match="camera 0.follow_entity: the camera must not stand at the base of "
                                                   "entity 'box_0'"):
        scene.build(n_envs=2)
    assert not scene.is_built and not cam.is_built and other.env_idx is None
    cam.set_pose(pos=(1.0, 0.3, 0.7))
    scene.build()
    assert cam.env_idx is None and other.render(rgb=False, segmentation=True)[2].max() == box.links[0].idx
    cam.set_pose(pos=box.get_pos().numpy().astype(np.float64))  # the base, as float32 gives it back
    with pytest.raises(gs.InvalidInputError, match="must not stand at the base"):
        cam.follow_entity(box)
    cam.set_pose(pos=(0.1, 0.3, 0.7))  # the base up to float32 rounding (~1e-8 m off)
    with pytest.raises(gs.InvalidInputError, match="must not stand at the base"):
        cam.follow_entity(box)
    with pytest.raises(gs.InvalidInputError, match="'rendered_envs_idx' must be env indices .*at least one"):
        gs.options.VisOptions(rendered_envs_idx=[])


def test_pointcloud_points_lie_on_the_drawn_surfaces(f32):
    """render_pointcloud's points, pixel by pixel, on the plane (z = 0) or on the box's faces they
    were drawn from (segmentation), nothing where the sky is; the camera-frame cloud is the world
    one seen through the extrinsics (OpenCV axes: z the depth)."""
    scene = gs.Scene(**NO_CONTACT)
    plane = scene.add_entity(gs.morphs.Plane())
    half, centre = np.array([0.2, 0.15, 0.1]), np.array([0.1, -0.05, 0.1])
    box = scene.add_entity(gs.morphs.Box(size=tuple(2 * half), pos=tuple(centre), fixed=True))
    cam = scene.add_camera(res=(160, 120), pos=(1.2, 0.9, 0.8), lookat=(0.0, 0.0, 0.1), fov=50, far=6.0)
    scene.build()
    seg = cam.render(rgb=False, segmentation=True)[2]
    points, mask = cam.render_pointcloud()
    assert points.shape == (120, 160, 3) and mask.shape == (120, 160)
    assert np.array_equal(mask, seg >= 0) and 0 < mask.mean() < 1  # the sky beyond far: masked
    on_plane, on_box = seg == plane.links[0].idx, seg == box.links[0].idx
    assert on_plane.sum() > 1000 and on_box.sum() > 500
    np.testing.assert_allclose(points[on_plane][:, 2], 0.0, atol=1e-4)  # float32 depth of a 1000 m square
    face_distance = np.abs(np.abs(points[on_box] - centre) / half).max(axis=1)  # 1 on the box's faces
    np.testing.assert_allclose(face_distance, 1.0, atol=2e-4)
    local, _ = cam.render_pointcloud(world_frame=False)
    depth = cam.render(rgb=False, depth=True)[1]
    np.testing.assert_allclose(local[..., 2], depth, rtol=1e-6)
    world = local @ np.linalg.inv(cam.extrinsics)[:3, :3].T + np.linalg.inv(cam.extrinsics)[:3, 3]
    np.testing.assert_allclose(world[mask], points[mask], atol=1e-5)


def test_pose_getters_and_projection_matrix(f32):
    """Genesis's pose getters (torch tensors) agree with the camera's properties; get_quat turns the
    camera's axes; the projection matrix sends a corner of a box to the pixel the pinhole
    projection gives it, near to depth −1 and far to +1 in normalised device coordinates."""
    scene = gs.Scene(**NO_CONTACT)
    scene.add_entity(gs.morphs.Box(size=(0.2, 0.2, 0.2), pos=(0.0, 0.0, 1.0)))
    view = dict(pos=(2.0, -1.0, 1.5), lookat=(0.0, 0.3, 0.8), up=(0.0, 0.0, 1.0), fov=35, res=(200, 100))
    cam = scene.add_camera(**view, near=0.2, far=9.0, env_idx=1)
    scene.build(n_envs=2, env_spacing=(3.0, 3.0))
    offset = scene.envs_offset[1]
    for getter, value in ((cam.get_pos, cam.pos), (cam.get_lookat, cam.lookat), (cam.get_up, cam.up),
                          (cam.get_transform, cam.transform)):
        tensor = getter()
        assert isinstance(tensor, torch.Tensor) and tensor.dtype == gs.tc_float
        np.testing.assert_allclose(tensor.numpy(), value, atol=1e-6)
    np.testing.assert_allclose(cam.get_pos().numpy(), np.array(view["pos"]) + offset, atol=1e-6)
    axes = cam.transform[:3, :3]
    np.testing.assert_allclose(gs.utils.geom.quat_to_R(cam.get_quat()).numpy(), axes, atol=1e-6)
    corner = np.array([0.1, -0.1, 1.1])
    (u, v), depth = (x[0] for x in project([corner], **view))
    camera_frame = np.linalg.inv(cam.transform.astype(np.float64)) @ np.append(corner + offset, 1.0)
    clip = cam.projection_matrix @ camera_frame
    np.testing.assert_allclose(clip[:2] / clip[3], [2 * u / 200 - 1, 1 - 2 * v / 100], atol=1e-5)
    for distance, ndc in ((0.2, -1.0), (9.0, 1.0)):
        clip = cam.projection_matrix @ [0.0, 0.0, -distance, 1.0]
        assert clip[2] / clip[3] == pytest.approx(ndc)
    with pytest.raises(gs.InvalidInputError, match=r"camera 0.get_pos: argument 'envs_idx' must be None .*env 1\), "
                                                   r"got \[0\]"):
        cam.get_pos([0])


def test_attached_camera_rides_its_link(f32):
    """A camera attached to a tumbling box's link with an offset stands, at every render and every
    recorded step, at the link's pose times the offset; the box sits where the offset says in the
    image (its centre 0.5 m ahead along the camera's −z: the image centre, depth 0.5 − 0.1 m to the
    face). detach keeps the pose; attach and follow_entity exclude each other; errors name the
    argument."""
    scene = gs.Scene(**NO_CONTACT)
    box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.2, 0.2), pos=(0.0, 0.0, 2.0)))
    other = gs.Scene(**NO_CONTACT).add_entity(gs.morphs.Box())
    cam = scene.add_camera(res=(80, 60), fov=40)
    offset = np.eye(4)
    offset[:3, :3] = gs.utils.geom.quat_to_R(gs.utils.geom.xyz_to_quat(np.array([90.0, 0.0, 90.0]), rpy=True,
                                                                     degrees=True))
    offset[:3, 3] = offset[:3, :3] @ [0.0, 0.0, 0.5]  # the box's centre 0.5 m ahead of the camera
    cam.attach(box.links[0], torch.tensor(offset))
    scene.build()
    box.set_dofs_velocity([0.3, -0.2, 0.5, 2.0, -1.0, 3.0])
    for _ in range(30):
        scene.step()
        seg, depth = (cam.render(rgb=False, depth=True, segmentation=True)[i] for i in (2, 1))
        link_pose = gs.utils.geom.trans_quat_to_T(box.get_pos().numpy().astype(np.float64),
                                                  box.get_quat().numpy().astype(np.float64))
        np.testing.assert_allclose(cam.transform, link_pose @ offset, atol=2e-5)
        assert (seg[28:32, 38:42] == box.links[0].idx).all()
        np.testing.assert_allclose(depth[29:31, 39:41], 0.4, atol=1e-3)
    cam.detach()
    still = cam.transform
    scene.step()
    cam.render()
    np.testing.assert_array_equal(cam.transform, still)
    with pytest.raises(gs.SceneStateError, match=r"camera 0.move_to_attach: the camera is not attached"):
        cam.move_to_attach()
    cam.attach(box.links[0], offset)
    state = scene.get_state()
    for _ in range(5):  # a force at float32's largest: the box's pose overflows
        box.links[0].apply_external_force([3e38, 0.0, 0.0])
        scene.step()
    with pytest.raises(gs.SimulationError, match=r"camera 0.move_to_attach: the pose of link 'box' of entity 'box_0' "
                                                 r"is not finite"):
        cam.render()
    scene.reset(state)
    cam.detach()
    cam.follow_entity(box)
    with pytest.raises(gs.SceneStateError, match=r"camera 0.attach: the camera follows entity 'box_0'; call "
                                                 r"unfollow_entity\(\) first"):
        cam.attach(box.links[0], offset)
    cam.unfollow_entity()
    cam.attach(box.links[0], offset)
    with pytest.raises(gs.SceneStateError, match=r"camera 0.follow_entity: the camera is attached to link 'box' of "
                                                 r"entity 'box_0'; call detach\(\) first"):
        cam.follow_entity(box)
    bad = np.eye(4)
    bad[0, 0] = 2.0
    for link, transform, message in ((box, offset, r"argument 'rigid_link' must be a RigidLink .*got RigidEntity"),
                                     (other.links[0], offset, r"argument 'rigid_link' must be of this camera's "
                                                              r"scene, got link 'box' of entity 'box_0' of another"),
                                     (box.links[0], bad, r"argument 'offset_T' must be a finite \(4, 4\) pose"),
                                     (box.links[0], np.eye(3), r"argument 'offset_T' must be a finite \(4, 4\)"),
                                     (box.links[0], "eye", r"argument 'offset_T' must be a finite \(4, 4\)")):
        with pytest.raises(gs.InvalidInputError, match=r"camera 0.attach: " + message):
            cam.attach(link, transform)


# ------------------------------------------------------------------ recording


def test_recording_writes_mp4_and_gif_read_back_by_imageio(f32, tmp_path, caplog):
    import imageio.v2 as imageio

    scene = gs.Scene(**NO_CONTACT)
    scene.add_entity(gs.morphs.Box(size=(0.3, 0.3, 0.3), pos=(0.0, 0.0, 1.0)))
    cam = scene.add_camera(res=(161, 121), pos=(2.0, 0.0, 0.5), lookat=(0.0, 0.0, 0.5), fov=50)
    scene.build()
    frames = []
    for target in ("buffered.mp4", "buffered.gif"):
        cam.start_recording()
        for k in range(12):
            scene.step()
            frames.append(cam.render()[0])
            if k == 5:  # a paused recording skips renders
                cam.pause_recording()
                cam.render()
                cam.start_recording()
        cam.stop_recording(str(tmp_path / target), fps=20)
    # Genesis 1.4.5's: the steps take the frames, one every round(1 / (fps · dt)) = 4 steps at 25 fps, dt 0.01 s;
    # render() adds none
    scene.reset()
    cam.start_recording(str(tmp_path / "streamed.mp4"), fps=25)
    stepped = []
    for k in range(12):
        scene.step()
        if k % 4 == 3:
            stepped.append(cam.render()[0])
    cam.stop_recording()
    for name, fps, expected in (("buffered.mp4", 20, frames[:12]), ("streamed.mp4", 25, stepped)):
        reader = imageio.get_reader(str(tmp_path / name))
        video = np.stack([frame for frame in reader])  # list() would ask len(): inf
        assert video.shape == (len(expected), 122, 162, 3)  # padded to even dimensions (yuv420p)
        assert reader.get_meta_data()["fps"] == fps
        for k in (0, -1):  # lossy, but the same picture
            assert np.abs(video[k, :121, :161].astype(int) - expected[k]).mean() < 6
    assert len(stepped) == 3 and np.abs(stepped[0].astype(int) - stepped[-1]).mean() > 0.1  # the box fell
    with caplog.at_level(logging.WARNING, logger="genesis_lite"):  # a frame every 3 steps: 33.3 fps
        cam.start_recording(str(tmp_path / "rate.mp4"), fps=30)
    assert "fps=30 is not reachable" in caplog.text and "recording at fps=33.3333 instead" in caplog.text
    for _ in range(6):
        scene.step()
    cam.stop_recording()
    rate = imageio.get_reader(str(tmp_path / "rate.mp4"))
    assert len([frame for frame in rate]) == 2 and abs(rate.get_meta_data()["fps"] - 100 / 3) < 0.01
    # a pause takes no frame and leaves no gap: counted afresh on resuming (4 steps a frame)
    cam.start_recording(str(tmp_path / "paused.mp4"), fps=25)
    for steps in (2, 5, 4):
        for _ in range(steps):
            scene.step()
        if steps == 2:
            cam.pause_recording()
        elif steps == 5:
            cam.start_recording()
    cam.stop_recording()
    assert len([frame for frame in imageio.get_reader(str(tmp_path / "paused.mp4"))]) == 1
    # a second of video shows realtime_factor seconds: at 0.5, a frame every 2 steps at 25 fps
    slow = gs.Scene(viewer_options=gs.options.ViewerOptions(realtime_factor=0.5), **NO_CONTACT)
    slow.add_entity(gs.morphs.Box(size=(0.3, 0.3, 0.3), pos=(0.0, 0.0, 1.0)))
    slow_cam = slow.add_camera(res=(32, 24), pos=(2.0, 0.0, 0.5), lookat=(0.0, 0.0, 0.5))
    slow.build()
    slow_cam.start_recording(str(tmp_path / "slow.mp4"), fps=25)
    for _ in range(8):
        slow.step()
    slow_cam.stop_recording()
    assert len([frame for frame in imageio.get_reader(str(tmp_path / "slow.mp4"))]) == 4
    gif = imageio.mimread(str(tmp_path / "buffered.gif"))
    assert len(gif) == 12 and gif[0].shape[:2] == (121, 161)
    assert np.abs(gif[-1][..., :3].astype(int) - frames[-1]).mean() < 6
    # a GIF's delays: 1/fps rounded to hundredths of a second (Pillow truncates), at least two
    from PIL import Image

    for fps, delay in ((20, 50), (60, 20), (30, 30), (7, 140)):
        cam.start_recording()
        for k in range(3):  # frames that differ (Pillow merges equal ones, adding their delays)
            cam.set_pose(pos=(2.0, 0.6 * k, 0.5))
            cam.render()
        cam.stop_recording(str(tmp_path / f"{fps}.gif"), fps=fps)
        with Image.open(tmp_path / f"{fps}.gif") as image:
            assert image.info["duration"] == delay, fps
    with pytest.raises(gs.InvalidInputError, match="'save_to_filename' must name a file, got .*a folder"):
        os.makedirs(tmp_path / "folder.mp4")
        cam.start_recording(str(tmp_path / "folder.mp4"))


def test_a_buffered_mp4_above_60_fps_keeps_its_frames(f32, tmp_path):
    """A recording named as it stops is encoded at 60 fps as it goes and timed at the fps given when
    saved: its last frame lasted ~1/50 s whatever the fps, so readers decoded 13 frames of 12 at
    100 fps and 28 at 1000 (independent probe, 2026-12-02); now as many as recorded, at the fps."""
    import imageio.v2 as imageio

    scene = gs.Scene(**NO_CONTACT)
    scene.add_entity(gs.morphs.Box(size=(0.3, 0.3, 0.3), pos=(0.0, 0.0, 0.5)))
    cam = scene.add_camera(res=(32, 24), pos=(2.0, 0.0, 0.5), lookat=(0.0, 0.0, 0.5))
    scene.build()
    for fps in (100, 1000):
        cam.start_recording()
        for k in range(12):
            cam.set_pose(pos=(2.0, 0.05 * k, 0.5))
            cam.render()
        cam.stop_recording(str(tmp_path / f"{fps}.mp4"), fps=fps)
        reader = imageio.get_reader(str(tmp_path / f"{fps}.mp4"))
        assert len([frame for frame in reader]) == 12, fps
        if fps == 100:  # (imageio's reader says 0 for 1000 fps, as for a file streamed at that rate)
            assert reader.get_meta_data()["fps"] == fps and reader.get_meta_data()["duration"] == 0.12


def test_a_state_that_blew_up_gives_a_named_error_and_no_frames(f32, tmp_path, caplog):
    """A box thrown by a force past float32's range: the step warns (check_nan is off) and the state
    is not finite. render() names the link whose pose it cannot draw (it named an internal
    argument, 'rot'), a camera following the box says so, and a recording streamed to a file leaves
    those steps' frames out, with one warning, and says how many at its end, instead of making
    scene.step() raise (independent probe, 2026-12-02)."""
    _check_blown_up_drawing(tmp_path, caplog, 3e38)


def test_a_float64_state_past_float32s_range_is_not_drawable_either(f64, tmp_path, caplog):
    """As above in float64, where the box's position (~1e296 m) stays finite but its float32, as the
    rasterizer draws it, does not (a review found the float64 rows checked before the cast)."""
    _check_blown_up_drawing(tmp_path, caplog, 1e300)


def _check_blown_up_drawing(tmp_path, caplog, force):
    import imageio.v2 as imageio

    scene = gs.Scene(**NO_CONTACT)
    box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.2, 0.2), pos=(0.0, 0.0, 0.5)), name="box")
    cam = scene.add_camera(res=(64, 48), pos=(2.0, 0.0, 1.0), lookat=(0.0, 0.0, 0.5), fov=40)
    follower = scene.add_camera(res=(16, 16), pos=(2.0, 0.0, 1.0), lookat=(0.0, 0.0, 0.5))
    scene.build()
    follower.follow_entity(box)
    cam.start_recording(str(tmp_path / "blown.mp4"), fps=100)  # a frame a step
    scene.step()
    drawable = 1
    with caplog.at_level(logging.WARNING, logger="genesis_lite"):
        for _ in range(3):
            box.links[0].apply_external_force([force, 0.0, force])
            scene.step()
            drawable += bool(torch.isfinite(box.get_pos().float()).all())
        left_out = [r.getMessage() for r in caplog.records if "left out of the recording" in r.getMessage()]
        assert len(left_out) == 1 and "the pose of link 'box' of entity 'box' is not finite" in left_out[0]
        cam.stop_recording()
    assert drawable < 4 and f"{4 - drawable} frames were left out of" in caplog.text
    assert len([frame for frame in imageio.get_reader(str(tmp_path / "blown.mp4"))]) == drawable
    with pytest.raises(gs.SimulationError, match="camera .*render: the pose of link 'box' of entity 'box' is not "
                                                 r"finite \(in float32, as drawn\): the scene's state cannot be drawn"):
        cam.render(depth=True)
    with pytest.raises(gs.SimulationError, match="follow_entity: the position of entity 'box' is not finite"):
        follower.render()


def test_an_env_that_blew_up_is_left_out_of_the_others_drawing(f32, caplog):
    """A camera drawing several envs draws those whose state is finite, with a warning naming the env
    that blew up (said again only when an env blows up anew), as an RL run meets it; it raised, and a
    recording lost every frame, as long as that env was not reset. Nothing left to draw raises."""
    scene = gs.Scene(**NO_CONTACT)
    box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.2, 0.2), pos=(0.0, 0.0, 0.5)), name="box")
    cam = scene.add_camera(res=(64, 48), pos=(3.0, 0.0, 1.5), lookat=(0.0, 0.0, 0.5), fov=60)
    scene.build(n_envs=3, env_spacing=(1.0, 1.0))
    scene.step()
    whole = cam.render(rgb=False, segmentation=True)[2]
    for _ in range(3):
        box.links[0].apply_external_force([3e38, 0.0, 3e38], envs_idx=[1])
        scene.step()
    assert not bool(torch.isfinite(box.get_pos()[1]).all()) and bool(torch.isfinite(box.get_pos()[[0, 2]]).all())
    with warns(caplog, r"camera 0.render: env\(s\) \[1\] drawn without the shapes whose pose is not finite .*link "
                       r"'box' of entity 'box'"):
        drawn = cam.render(rgb=False, segmentation=True)[2]
    with warns(caplog, None):  # said once
        cam.render(rgb=False)
    boxes = lambda seg: int((seg == box.links[0].idx).sum())  # noqa: E731
    assert 0 < boxes(drawn) < boxes(whole)  # two boxes of three (they fell 0.04 s: about the same pixels)
    scene.reset(envs_idx=[1])
    cam.render()
    for _ in range(3):
        box.links[0].apply_external_force([3e38, 0.0, 3e38], envs_idx=[1])
        scene.step()
    with warns(caplog, r"env\(s\) \[1\] drawn without"):  # (blown up anew after its reset)
        cam.render()
    for _ in range(3):
        box.links[0].apply_external_force([3e38, 0.0, 3e38], envs_idx=[0, 2])
        scene.step()
    with pytest.raises(gs.SimulationError, match="camera 0.render: the pose of link 'box' of entity 'box' in env 0 is "
                                                 "not finite"):
        cam.render()


@pytest.mark.restarts  # (conftest: last in the float32 group)
def test_scenes_ending_finish_their_recordings(f32, tmp_path, caplog):
    """gs.destroy (and a restarting gs.init, and the interpreter's exit) end every scene, whose
    cameras finish a streamed recording's file (Genesis's atexit destroy does); a buffered one,
    without a file, is dropped with a warning; a streamed one without frames too, its ffmpeg
    process ended (it stayed alive, one a scene)."""
    import imageio.v2 as imageio

    scene = gs.Scene(**NO_CONTACT)
    scene.add_entity(gs.morphs.Box(size=(0.3, 0.3, 0.3), pos=(0.0, 0.0, 1.0)))
    streamed = scene.add_camera(res=(32, 24), pos=(2.0, 0.0, 0.5), lookat=(0.0, 0.0, 0.5))
    buffered = scene.add_camera(res=(32, 24), pos=(2.0, 0.0, 0.5), lookat=(0.0, 0.0, 0.5))
    idle = gs.Scene(**NO_CONTACT)
    idle.add_entity(gs.morphs.Box())
    idle_camera = idle.add_camera(res=(32, 24))
    scene.build()
    idle.build()
    running = _ffmpeg_children()
    idle_camera.start_recording(str(tmp_path / "never.mp4"))  # its scene never steps
    assert _ffmpeg_children() == running + 1
    streamed.start_recording(str(tmp_path / "streamed.mp4"), fps=100)  # a frame a step (dt 0.01 s)
    buffered.start_recording()
    for _ in range(30):
        scene.step()
        buffered.render()
    gs.init(precision="64")  # a restart ends the scenes of the runtime before
    with pytest.raises(gs.SceneStateError):
        scene.step()
    assert len([frame for frame in imageio.get_reader(str(tmp_path / "streamed.mp4"))]) == 30  # (len(): inf)
    assert any("camera 1: a recording of 30 frames was dropped" in r.getMessage() for r in caplog.records)
    assert _ffmpeg_children() == running and not (tmp_path / "never.mp4").exists()  # (no header-only file)
    with pytest.raises(gs.SceneStateError, match="camera 0.stop_recording: the scene was destroyed"):
        streamed.stop_recording()  # (it said the camera was not recording)
    gs.init(precision="32")


def _ffmpeg_children():
    """How many ffmpeg processes this process started that still run (Linux's /proc)."""
    count = 0
    for stat in glob.glob("/proc/[0-9]*/stat"):
        try:
            with open(stat) as file:
                name, rest = file.read().rsplit(")", 1)
        except OSError:  # (it ended meanwhile)
            continue
        count += int(rest.split()[1]) == os.getpid() and "ffmpeg" in name
    return count


# ------------------------------------------------------------------ errors


def test_errors_name_the_camera_argument_and_value(f32, tmp_path):
    scene = gs.Scene(**NO_CONTACT)
    scene.add_entity(gs.morphs.Box())
    cam = scene.add_camera()
    with pytest.raises(gs.SceneStateError, match=r"camera 0.render: call scene.build\(\) first"):
        cam.render()
    cases = [(dict(res=(0, 10)), r"camera 1: argument 'res' must be \(width, height\).*got \(0, 10\)"),
             (dict(res=(64.5, 48)), r"argument 'res'.*got \(64.5, 48\)"),
             (dict(res=(200000, 200000)), r"argument 'res'.* up to 16384, got \(200000, 200000\)"),
             (dict(fov=180), r"camera 1: argument 'fov' must be a vertical field of view in \(0, 180\).*got 180"),
             (dict(fov=1e-37), r"argument 'fov' must leave a focal length float32 can hold, got 1e-37 degrees"),
             (dict(pos=(0, 0, np.nan)), r"camera 1.set_pose: argument 'pos' must be 3 finite numbers"),
             (dict(pos=(1, 2, 3), lookat=(1, 2, 3)), r"'pos' and 'lookat' must differ, got both \[1.0, 2.0, 3.0\]"),
             (dict(pos=(0, 0, 3), lookat=(0, 0, 0)), r"argument 'up' must be a vector not parallel"),
             (dict(near=1.0, far=0.5), r"argument 'far' must be a distance \(m\) > near \(1.0\) that float32 can hold"),
             (dict(far=1e39), r"argument 'far' must be a distance .* that float32 can hold, got 1e\+39"),
             (dict(near=1e39), r"argument 'near' must be a positive distance \(m\) that float32 can hold"),
             (dict(GUI=True), r"argument 'GUI' must be False.*headless"),
             (dict(model="thinlens"), r"argument 'model' must be 'pinhole'"),
             (dict(spp=64), r"argument 'spp' is a thinlens/raytracer setting"),
             (dict(env_idx=-1), r"argument 'env_idx' must be None or an env index")]
    for kwargs, message in cases:
        with pytest.raises(gs.InvalidInputError, match=message):
            scene.add_camera(**kwargs)
    scene.add_camera(far=float(np.finfo(np.float32).max))  # (the largest float32 itself)
    for name in ("show_world_frame", "visualize_mpm_boundary"):
        with pytest.raises(gs.InvalidInputError, match=rf"VisOptions argument '{name}' must keep its default"):
            gs.Scene(vis_options=gs.options.VisOptions(**{name: True})).add_camera()
    scene.build()
    with pytest.raises(gs.SceneStateError, match=r"camera 0.stop_recording: the camera is not recording"):
        cam.stop_recording()
    with pytest.raises(gs.InvalidInputError, match=r"'save_to_filename' must be a path ending in one of "
                                                   r"\('.mp4', '.gif'\), got '.*clip.avi'"):
        cam.start_recording(str(tmp_path / "clip.avi"))
    cam.start_recording()
    with pytest.raises(gs.SceneStateError, match="already recording"):
        cam.start_recording()
    with pytest.raises(gs.SceneStateError, match="no frame was recorded"):
        cam.stop_recording(str(tmp_path / "a.mp4"))
    cam.render()
    # a file that cannot be created (ffmpeg failed without a word: the video was lost, or its frames)
    with pytest.raises(gs.InvalidInputError, match=r"camera 0: argument 'save_to_filename' must be a file that can be "
                                                   r"written, got '/proc/clip.mp4' \("):
        cam.stop_recording("/proc/clip.mp4")
    with pytest.raises(gs.InvalidInputError, match=r"argument 'antialiasing' must be False"):
        cam.render(antialiasing=True)
    with pytest.raises(gs.InvalidInputError, match=r"follow_entity: argument 'entity' must be a rigid entity .*, "
                                                   r"got str 'box'"):
        cam.follow_entity("box")
    for transform in (np.diag([-1.0, 1.0, 1.0, 1.0]), np.vstack([np.eye(4)[:3], [5.0, 5.0, 5.0, 7.0]])):
        with pytest.raises(gs.InvalidInputError, match=r"'transform' must be a finite \(4, 4\) pose .*det \+1"):
            cam.set_pose(transform=transform)  # a mirror, a last row that is not (0, 0, 0, 1)
    cam.render()
    cam.stop_recording(str(tmp_path / "a.gif"))  # the recording went on after the errors
    with pytest.raises(gs.InvalidInputError, match=r"camera 0.start_recording: argument 'save_to_filename' must be a "
                                                   r"file that can be written, got '/proc/clip.gif'"):
        cam.start_recording("/proc/clip.gif")
    cam.start_recording(str(tmp_path / "b.mp4"), fps=30)
    cam.render()  # adds no frame to a recording started with a file: its steps do
    with pytest.raises(gs.SceneStateError, match=r"no frame was recorded; step the scene while recording \(a frame "
                                                 r"every 3 steps\)"):
        cam.stop_recording()
    for _ in range(3):
        scene.step()
    with pytest.raises(gs.InvalidInputError, match=r"stop_recording arguments 'save_to_filename' and 'fps' must be "
                                                   r"None for a recording started with a filename"):
        cam.stop_recording(str(tmp_path / "c.mp4"))
    cam.stop_recording()
    assert (tmp_path / "a.gif").is_file() and (tmp_path / "b.mp4").is_file()


# ------------------------------------------------------------------ an OpenGL cross-check


def gl_silhouette(triangles, pos, lookat, up, fov, res, near=0.1, far=20.0):
    """(H, W) bool silhouette of world triangles (N, 3, 3) drawn by OpenGL (moderngl, standalone EGL
    context) with the same pinhole camera; skips the test when no context can be made."""
    moderngl = pytest.importorskip("moderngl")
    try:
        ctx = moderngl.create_standalone_context(backend="egl")
    except Exception as error:  # no EGL / Mesa on this machine
        pytest.skip(f"no standalone OpenGL context: {error}")
    rot, _ = pinhole(pos, lookat, up, fov, res)
    view = np.eye(4)
    view[:3, :3], view[:3, 3] = rot, -rot @ pos
    t = np.tan(np.radians(fov) / 2)
    proj = np.array([[1 / (t * res[0] / res[1]), 0, 0, 0], [0, 1 / t, 0, 0],
                     [0, 0, (far + near) / (near - far), 2 * far * near / (near - far)], [0, 0, -1, 0]])
    program = ctx.program(vertex_shader="#version 330\nuniform mat4 mvp; in vec3 p;"
                                        "void main() { gl_Position = mvp * vec4(p, 1.0); }",
                          fragment_shader="#version 330\nout vec4 c; void main() { c = vec4(1.0); }")
    program["mvp"].write((proj @ view).T.astype("f4").tobytes())
    vao = ctx.vertex_array(program, ctx.buffer(triangles.astype("f4").tobytes()), "p")
    fbo = ctx.simple_framebuffer(res)
    fbo.use()
    fbo.clear(0.0, 0.0, 0.0, 1.0)
    vao.render(moderngl.TRIANGLES)
    image = np.frombuffer(fbo.read(components=1), dtype=np.uint8).reshape(res[1], res[0])
    ctx.release()
    return image[::-1] > 0  # OpenGL's rows go up


def test_silhouette_matches_opengl(f32):
    scene = gs.Scene(**NO_CONTACT)
    robot = scene.add_entity(gs.morphs.URDF(file=KUKA, fixed=True))
    view = dict(pos=np.array([1.0, 0.8, 1.0]), lookat=np.array([0.0, 0.0, 0.5]), up=np.array([0.0, 0.0, 1.0]),
                fov=60, res=(240, 180))
    cam = scene.add_camera(**view)
    scene.build()
    robot.set_dofs_position(KUKA_Q)
    _, _, seg, _ = cam.render(rgb=False, segmentation=True)
    mesh = yourdfpy_visuals(KUKA, {joint.name: KUKA_Q[k] for k, joint in enumerate(robot.joints)})
    silhouette = gl_silhouette(mesh.vertices[mesh.faces], **view)
    assert silhouette.sum() > 2000
    assert iou(seg >= 0, silhouette) >= 0.98


def test_an_mjcf_worldbodys_planes_are_drawn_as_mujoco_sizes_them(f32, tmp_path):
    """An MJCF worldbody's plane of size 0 is an unbounded floor, drawn once for every env (as a
    Plane morph's); one of half sizes (x, y) is that rectangle: a camera looking down at a 0.4 m
    tile's edge sees the tile on one side and the floor 1 m below it on the other."""
    path = tmp_path / "scene.xml"
    path.write_text('<mujoco><worldbody><geom type="plane" size="0 0 1"/>'
                    '<geom type="plane" size="0.2 0.2 0.1" pos="0.2 0 1" contype="0" conaffinity="0"/>'
                    '<body name="b" pos="3 0 0.5"><freejoint/><geom type="sphere" size="0.1"/></body>'
                    '</worldbody></mujoco>')
    scene = gs.Scene(**NO_CONTACT)
    scene.add_entity(gs.morphs.MJCF(file=str(path)))
    cam = scene.add_camera(res=(32, 24), pos=(0.0, 0.0, 3.0), lookat=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0))
    scene.build(n_envs=2)
    shapes = scene_shapes(scene)
    assert [shape.shared for shape in shapes] == [False, True, False]  # (the sphere, the floor, the tile)
    depth = cam.render(rgb=False, depth=True)[1]
    assert depth[12, 20] == pytest.approx(2.0, abs=1e-3)  # the tile (x > 0)
    assert depth[12, 10] == pytest.approx(3.0, abs=1e-3)  # the floor beside it


def test_visualizer_update_after_setters_and_render_shows_them(f32):
    """Genesis's headless scripts move a robot by setters, call scene.visualizer.update() and
    render: the render shows the moved state (every render draws the current state, so update has
    nothing to sync); its arguments are checked, cameras listed, viewer None, other names a named
    AttributeError."""
    scene = gs.Scene(**NO_CONTACT)
    box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.2, 0.2), pos=(0.0, 0.0, 2.0)))
    cam = scene.add_camera(res=(80, 60), pos=(3.0, 0.0, 2.0), lookat=(0.0, 0.0, 2.0), fov=40)
    scene.build()
    before = cam.render(rgb=False, segmentation=True)[2]
    box.set_pos([0.0, 0.5, 2.0])
    scene.visualizer.update()
    scene.visualizer.update(force=False, auto=True)
    after = cam.render(rgb=False, segmentation=True)[2]
    columns = [np.nonzero(seg == box.links[0].idx)[1].mean() for seg in (before, after)]
    assert columns[1] > columns[0] + 5  # moved right in the image (+y is right, looking along −x)
    assert scene.visualizer.cameras == [cam] and scene.visualizer.viewer is None
    with pytest.raises(gs.InvalidInputError, match="scene.visualizer.update: argument 'force'"):
        scene.visualizer.update(force=1)
    with pytest.raises(AttributeError, match="scene.visualizer has no 'context'"):
        scene.visualizer.context
