"""Cameras: headless pinhole views of a scene, drawn by the software rasterizer (rasterizer.py),
with Genesis 1.4.5's names, arguments and defaults (``gs.vis.camera.Camera``).

A camera is added with ``scene.add_camera`` (before or after ``scene.build``; Genesis only
allows before). ``render`` draws the scene's current state: the link poses are read from the
rigid solver where they live (no copy of the state), converted to float32 per drawn shape; the
triangles (visuals.SceneVisuals) are built once per scene, at the first render.

Frames: ``pos``/``lookat`` are world coordinates of the camera's env (env_idx); the camera looks
along −z of its frame, x right, y up (OpenGL). In a batched scene every rendered env
(``VisOptions.rendered_envs_idx``, all by default) is drawn at its offset ``scene.envs_offset``,
and the camera stands at its pose plus its own env's offset, as Genesis's rasterizer does with
``split_envs=False``.

Images, as Genesis returns them: rgb (H, W, 3) uint8; depth (H, W) float32 m along the view axis,
``far`` where nothing is drawn; segmentation (H, W) int32: the ids of
``VisOptions.segmentation_level`` ("link" by default: the scene-wide link index, as RigidLink.idx;
"entity": entity.idx; "geom": the drawn shape's scene-wide index; an MPM entity's particles, at the
link and geom levels, the ids after the rigid ones, one per MPM entity), −1 where nothing is drawn
(Genesis returns its own compacted indices instead, 0 for nothing); normal (H, W, 3) float32 world-frame unit
normals, 0 where nothing is drawn. Debug objects (``scene.draw_debug_*``: vis/debug.py) are drawn by
debug cameras only (``debug=True``), as in Genesis, with segmentation −1, and so are the
contact-force arrows of entities added with ``visualize_contact`` (Genesis's markers).

A camera attached to a link (``attach(link, offset_T)``) is put at the link's pose times the
offset before each render and recorded frame; ``render_pointcloud`` turns the depth image into
points on the pixel-centre rays (world or OpenCV camera frame).

Recording, two ways (recorder.py writes MP4 or GIF): Genesis 1.4.5's
``start_recording(save_to_filename, fps)`` … ``stop_recording()`` takes a frame as the scene steps,
one every round(realtime_factor / (fps · dt)) steps (ViewerOptions' realtime_factor, None: 1; at
least one step; the video's rate is then realtime_factor / (steps · dt), with a warning where that
is not fps), streamed to the file, whether or not ``render()`` is
called; earlier Genesis's ``start_recording()``, then every ``render()`` appends its rgb frame,
and ``stop_recording(save_to_filename, fps)`` writes the file.

Not supported (clear errors): GUI windows, the thinlens and fisheye models and the raytracer's
arguments, ``antialiasing``, VisOptions that draw more than the scene (world/link frames, camera
frustums, plane reflection), per-env images (``split_envs=True``) and custom lights. Not drawn:
shadows (``VisOptions.shadow``), textures, transparency.
"""
import logging
import os
import sys
import time

import numpy as np
import torch

from ..entities import RigidEntity
from ..entities.rigid_entity import RigidLink
from ..options import _check_float, _check_vec3, check_bool, is_int
from ..solvers.core import InvalidInputError, SceneStateError, SimulationError, runtime
from ..utils.geom import R_to_quat, quat_to_R
from .debug import DebugMesh
from .rasterizer import Rasterizer, View
from .recorder import Recording, check_target

logger = logging.getLogger("genesis_lite")
MAX_RES = 16384  # pixels a side (a 16k × 16k frame's buffers already take ~5 GB)

# VisOptions whose non-default values cameras cannot honour (their defaults draw nothing extra)
UNSUPPORTED_VIS_OPTIONS = ("show_world_frame", "show_link_frame", "show_cameras", "plane_reflection", "split_envs",
                           "ambient_light", "lights", "visualize_mpm_boundary")
_GOLDEN = 0.618033988749895  # hue step of the segmentation colours: neighbouring ids differ


class Camera:
    """A pinhole camera of ``scene`` (see the module docstring); made by ``scene.add_camera``,
    whose arguments it takes (Genesis's): res (width, height) pixels; pos, lookat (3,) m; up (3,);
    fov: vertical field of view, degrees; near, far: clipping distances, m; env_idx: the env it
    belongs to in a batched scene (None: the first rendered env); debug: also draw debug objects.
    model must be "pinhole"; GUI False; aperture, focus_dist, spp, denoise (thinlens and raytracer
    settings) at their defaults."""

    def __init__(self, scene, idx, model="pinhole", res=(320, 320), pos=(0.5, 2.5, 3.5), lookat=(0.5, 0.5, 0.5),
                 up=(0.0, 0.0, 1.0), fov=30, aperture=2.0, focus_dist=None, GUI=False, spp=256, denoise=None,
                 near=0.1, far=20.0, env_idx=None, debug=False):
        self._scene, self._idx = scene, idx
        self._name = owner = f"camera {idx}"
        _check_unsupported(owner, model, GUI, aperture, focus_dist, spp, denoise)
        _check_vis_options(owner, scene.vis_options)
        if not (isinstance(res, (tuple, list)) and len(res) == 2 and all(is_int(r) and 0 < r <= MAX_RES for r in res)):
            raise InvalidInputError(f"{owner}: argument 'res' must be (width, height), 2 positive integers (pixels) up "
                                    f"to {MAX_RES}, got {res!r}")
        self._res = (int(res[0]), int(res[1]))
        self._fov = _check_float(owner, "fov", fov, 0.0, 180.0, "a vertical field of view in (0, 180) degrees")
        if self.f > np.finfo(np.float32).max:  # (the rasterizer's float32 drew an empty image)
            raise InvalidInputError(f"{owner}: argument 'fov' must leave a focal length float32 can hold, got {fov!r} "
                                    f"degrees: {self.f:.3g} pixels")
        # (the rasterizer's depths are float32: a farther far made the background's depth inf)
        largest = float(np.nextafter(np.float64(np.finfo(np.float32).max), np.inf))  # (the bounds are open)
        self._near = _check_float(owner, "near", near, 0.0, largest, "a positive distance (m) that float32 can hold")
        self._far = _check_float(owner, "far", far, self._near, largest,
                                 f"a distance (m) > near ({near}) that float32 can hold")
        if env_idx is not None and not (is_int(env_idx) and env_idx >= 0):
            raise InvalidInputError(f"{owner}: argument 'env_idx' must be None or an env index (integer ≥ 0), "
                                    f"got {env_idx!r}")
        self._env_idx_arg = self._env_idx = None if env_idx is None else int(env_idx)  # (the argument, kept:
        # a build that raises leaves no default behind)
        self._debug = check_bool(owner, "debug", debug)
        self._pos = self._lookat = self._up = None
        self.set_pose(pos=pos, lookat=lookat, up=up)
        self._rasterizer = Rasterizer(self._res, background=scene.vis_options.background_color)
        self._follow = None  # (entity, offset (3,) or None until build, fixed_axis, smoothing, fix_orientation)
        self._attached = None  # (link, (4, 4) float64 camera pose in the link's frame)
        self._recording, self._paused = None, False
        self._steps_per_frame = self._steps_to_frame = 1  # a recording started with a file: steps a frame
        self._is_built = False

    # -- life cycle ---------------------------------------------------------------------------
    def _bind_env(self):
        """Check env_idx and settle its default once the scene's n_envs is known, and that the camera
        does not stand at the base of an entity it was told to follow (scene.build, before the
        simulator is made, or add_camera after build)."""
        rendered = self._scene._rendered_envs()
        self._env_idx = self._env_idx_arg
        if self._scene.n_envs == 0:
            if self._env_idx is not None:
                raise InvalidInputError(f"{self._name}: argument 'env_idx' must be None in a scene built with "
                                        f"n_envs=0, got {self._env_idx}")
        elif self._env_idx is None:
            self._env_idx = int(rendered[0])
        elif self._env_idx not in rendered:
            raise InvalidInputError(f"{self._name}: argument 'env_idx' must be one of the rendered envs "
                                    f"{rendered.tolist()} (VisOptions.rendered_envs_idx, n_envs={self._scene.n_envs}), "
                                    f"got {self._env_idx}")
        followed = None if self._follow is None or self._follow[1] is not None else self._follow[0]
        if followed is not None and getattr(followed, "attached_to", None) is None:  # followed before build: the
            self._apart(f"{self._name}.follow_entity", followed, followed.morph.pos)  # base starts at its morph's pos
        # (an attached entity's base starts where its parent link puts it: _on_build measures it there)

    def _on_build(self):
        """The scene is built: the camera can render."""
        self._is_built = True
        if self._follow is not None and self._follow[1] is None:  # followed before build: measure now
            entity, _, fixed_axis, smoothing, fix_orientation = self._follow
            self.follow_entity(entity, fixed_axis, smoothing, fix_orientation)

    def _require_built(self, what):
        self._scene._require_built(f"{self._name}.{what}")

    # -- pose ---------------------------------------------------------------------------------
    def set_pose(self, transform=None, pos=None, lookat=None, up=None, envs_idx=None):
        """Move the camera: ``transform`` (4, 4) camera → env-world pose (the camera looks along
        its −z, up is its y), or any of pos, lookat (3,) m and up (3,) (the others kept).
        envs_idx must be None (one pose: the camera renders one image)."""
        owner = f"{self._name}.set_pose"
        if envs_idx is not None:
            raise InvalidInputError(f"{owner}: argument 'envs_idx' must be None (per-env poses need "
                                    f"VisOptions(split_envs=True), which is not supported), got {envs_idx!r}")
        if transform is not None:
            if pos is not None or lookat is not None or up is not None:
                raise InvalidInputError(f"{owner}: give either 'transform' or ('pos', 'lookat', 'up'), got both")
            pos, lookat, up = _transform_to_pose(owner, transform)
        pos = self._pos if pos is None else np.array(_check_vec3(owner, "pos", pos))
        lookat = self._lookat if lookat is None else np.array(_check_vec3(owner, "lookat", lookat))
        up = self._up if up is None else np.array(_check_vec3(owner, "up", up))
        _camera_axes(owner, pos, lookat, up)  # refuses a degenerate pose before anything changes
        self._pos, self._lookat, self._up = pos, lookat, up

    def _offset(self):
        """(3,) m: where the camera's env is drawn (0 in an unbatched scene or before build)."""
        if not self._is_built or self._env_idx is None:
            return np.zeros(3)
        return self._scene.envs_offset[self._env_idx]

    @property
    def pos(self):
        """(3,) float32 m, world (the env's offset included, as Genesis)."""
        return (self._pos + self._offset()).astype(np.float32)

    @property
    def lookat(self):
        """(3,) float32 m, world."""
        return (self._lookat + self._offset()).astype(np.float32)

    @property
    def up(self):
        """(3,) float32: the camera's y axis (up in the image), world."""
        return _camera_axes(self._name, self._pos, self._lookat, self._up)[:, 1].astype(np.float32)

    @property
    def transform(self):
        """(4, 4) float32: camera → world pose (columns: x right, y up, z backwards, position)."""
        return self._world_transform().astype(np.float32)

    def _world_transform(self):
        """(4, 4) float64 camera → world pose."""
        transform = np.eye(4)
        transform[:3, :3] = _camera_axes(self._name, self._pos, self._lookat, self._up)
        transform[:3, 3] = self._pos + self._offset()
        return transform

    @property
    def extrinsics(self):
        """(4, 4) world → camera transform in the OpenCV convention (y down, looking along +z)."""
        transform = self.transform.astype(np.float64)
        transform[:3, 1:3] *= -1
        return np.linalg.inv(transform)

    @property
    def intrinsics(self):
        """(3, 3) pinhole matrix [[f, 0, cx], [0, f, cy], [0, 0, 1]], pixels."""
        return np.array([[self.f, 0.0, self.cx], [0.0, self.f, self.cy], [0.0, 0.0, 1.0]])

    @property
    def f(self):
        """Focal length, pixels: (height / 2) / tan(fov / 2)."""
        return 0.5 * self._res[1] / np.tan(np.radians(0.5 * self._fov))

    @property
    def cx(self):
        return 0.5 * self._res[0]

    @property
    def cy(self):
        return 0.5 * self._res[1]

    @property
    def projection_matrix(self):
        """(4, 4) OpenGL projection (camera frame → clip space) of the field of view, aspect ratio,
        near and far planes, as Genesis's."""
        aspect, tan = self.aspect_ratio, np.tan(np.radians(0.5 * self._fov))
        near, far = self._near, self._far
        return np.array([[1.0 / (aspect * tan), 0.0, 0.0, 0.0], [0.0, 1.0 / tan, 0.0, 0.0],
                         [0.0, 0.0, (far + near) / (near - far), 2.0 * far * near / (near - far)],
                         [0.0, 0.0, -1.0, 0.0]])

    def _pose_tensor(self, what, value, envs_idx):
        """Genesis's pose getters: ``value`` as a torch tensor (gs.tc_float, gs.device); envs_idx must
        be None (a rasterized camera has one pose, in its env)."""
        if envs_idx is not None:
            where = "" if self._env_idx is None else f", in its env {self._env_idx}"
            raise InvalidInputError(f"{self._name}.{what}: argument 'envs_idx' must be None (the camera has one "
                                    f"pose{where}), got {envs_idx!r}")
        return torch.as_tensor(np.asarray(value, dtype=np.float64), dtype=runtime.tc_float, device=runtime.device)

    def get_pos(self, envs_idx=None):
        """(3,) m, world (the env's offset included), a torch tensor."""
        return self._pose_tensor("get_pos", self._pos + self._offset(), envs_idx)

    def get_lookat(self, envs_idx=None):
        """(3,) m, world, a torch tensor."""
        return self._pose_tensor("get_lookat", self._lookat + self._offset(), envs_idx)

    def get_up(self, envs_idx=None):
        """(3,): the camera's y axis in the world, a torch tensor."""
        return self._pose_tensor("get_up", _camera_axes(self._name, self._pos, self._lookat, self._up)[:, 1],
                                 envs_idx)

    def get_quat(self, envs_idx=None):
        """(4,) (w, x, y, z): the camera's orientation (axes as ``transform``'s), a torch tensor."""
        return self._pose_tensor("get_quat", R_to_quat(_camera_axes(self._name, self._pos, self._lookat,
                                                                           self._up)), envs_idx)

    def get_transform(self, envs_idx=None):
        """(4, 4) camera → world pose (as ``transform``), a torch tensor."""
        return self._pose_tensor("get_transform", self._world_transform(), envs_idx)

    idx = property(lambda self: self._idx, doc="The camera's index in the scene.")
    model = property(lambda self: "pinhole")
    res = property(lambda self: self._res, doc="(width, height) pixels.")
    fov = property(lambda self: self._fov, doc="Vertical field of view, degrees.")
    near = property(lambda self: self._near)
    far = property(lambda self: self._far)
    aspect_ratio = property(lambda self: self._res[0] / self._res[1])
    env_idx = property(lambda self: self._env_idx, doc="The env the camera belongs to (None: unbatched scene).")
    debug = property(lambda self: self._debug)
    GUI = property(lambda self: False)
    is_built = property(lambda self: self._is_built)

    # -- attached to a link -------------------------------------------------------------------
    def attach(self, rigid_link, offset_T):
        """Mount the camera on ``rigid_link`` (a RigidLink of this scene, e.g. ``entity.get_link(name)``):
        from now on every render and recorded frame first puts the camera at the link's pose times
        ``offset_T`` ((4, 4) camera pose in the link's frame: it looks along the offset's −z, up its
        y), as Genesis's; ``move_to_attach()`` does so at once."""
        owner = f"{self._name}.attach"
        self._check_mount(owner, "rigid_link", rigid_link, attaching=True)
        if isinstance(offset_T, torch.Tensor):
            offset_T = offset_T.detach().cpu().numpy()
        _transform_to_pose(owner, offset_T, "offset_T")
        self._attached = (rigid_link, np.array(offset_T, dtype=np.float64))

    def _check_mount(self, owner, name, target, attaching):
        """Refuse to attach a following camera or to follow with an attached one, and a ``target``
        (argument ``name``: attach's link when ``attaching``, else follow_entity's rigid entity)
        that is not of this scene."""
        if attaching and self._follow is not None:
            raise SceneStateError(f"{owner}: the camera follows entity '{self._follow[0].name}'; call "
                                  f"unfollow_entity() first")
        if not attaching and self._attached is not None:
            raise SceneStateError(f"{owner}: the camera is attached to {self._attached[0]._who}; call detach() "
                                  f"first")
        kind, what = (RigidLink, "a RigidLink (entity.get_link(name) or entity.links[i])") if attaching else \
            (RigidEntity, "a rigid entity (the camera follows its base link)")
        if not isinstance(target, kind):
            raise InvalidInputError(f"{owner}: argument '{name}' must be {what}, got {type(target).__name__} "
                                    f"{getattr(target, 'name', target)!r}")
        entity = target.entity if attaching else target
        if entity.scene is not self._scene:
            raise InvalidInputError(f"{owner}: argument '{name}' must be of this camera's scene, got "
                                    f"{getattr(target, '_who', repr(entity.name))} of another scene")

    def detach(self):
        """Unmount the camera; it keeps its current pose (nothing when it is not attached)."""
        self._attached = None

    def move_to_attach(self):
        """Put the camera at its link's current pose (in the camera's env) times its offset."""
        owner = f"{self._name}.move_to_attach"
        if self._attached is None:
            raise SceneStateError(f"{owner}: the camera is not attached to a link; call attach(rigid_link, offset_T) "
                                  f"first")
        self._require_built("move_to_attach")
        link, offset = self._attached
        envs_idx = None if self._scene.n_envs == 0 else [self._env_idx]
        link_pose = np.eye(4)
        link_pose[:3, 3] = link.get_pos(envs_idx).detach().cpu().numpy().astype(np.float64).reshape(3)
        quat = link.get_quat(envs_idx).detach().cpu().numpy().astype(np.float64).reshape(4)
        if not (np.isfinite(link_pose).all() and np.isfinite(quat).all()):
            raise SimulationError(f"{owner}: the pose of {link._who} is not finite (position "
                                  f"{link_pose[:3, 3].tolist()}, quaternion {quat.tolist()}); the camera cannot "
                                  f"ride it")
        link_pose[:3, :3] = quat_to_R(quat)  # (normalised: a float32 pose's is unit to round-off only)
        pos, lookat, up = _transform_to_pose(owner, link_pose @ offset)
        self.set_pose(pos=pos, lookat=lookat, up=up)

    # -- following an entity ------------------------------------------------------------------
    def follow_entity(self, entity, fixed_axis=(None, None, None), smoothing=None, fix_orientation=False):
        """Follow ``entity`` (its base) from now on: at each render the camera keeps the offset it
        has now (measured at build when the scene is not built yet) to the entity and looks at it.
        fixed_axis: (3,) None (free) or a world coordinate (m) the camera's position keeps on that
        axis; smoothing: None or in [0, 1): the weight of the camera's previous position and lookat
        (exponential smoothing); fix_orientation: keep the orientation, only move."""
        owner = f"{self._name}.follow_entity"
        self._check_mount(owner, "entity", entity, attaching=False)
        if not (isinstance(fixed_axis, (tuple, list)) and len(fixed_axis) == 3):
            raise InvalidInputError(f"{owner}: argument 'fixed_axis' must be 3 entries, each None or a coordinate "
                                    f"(m), got {fixed_axis!r}")
        fixed_axis = tuple(None if v is None else _check_float(owner, "fixed_axis", v, -np.inf, np.inf, "finite")
                           for v in fixed_axis)
        numeric = isinstance(smoothing, (int, float, np.integer, np.floating)) and not isinstance(smoothing, bool)
        if smoothing is not None and not (numeric and 0 <= smoothing < 1):
            raise InvalidInputError(f"{owner}: argument 'smoothing' must be None or a number in [0, 1), got "
                                    f"{smoothing!r}")
        check_bool(owner, "fix_orientation", fix_orientation)
        offset = None
        if self._is_built:
            offset = self._apart(owner, entity, self._entity_pos(entity))
        self._follow = (entity, offset, fixed_axis, smoothing, bool(fix_orientation))

    def _apart(self, owner, entity, base):
        """The camera's offset (3,) m from the followed entity's base at ``base`` (3,) m; raise when it
        stands there (within 1 µm per metre from the origin: float32 positions come back rounded,
        and the view would point where the rounding does)."""
        offset = self._pos - base
        if np.linalg.norm(offset) <= 1e-6 * (1.0 + np.linalg.norm(base)):
            raise InvalidInputError(f"{owner}: the camera must not stand at the base of entity '{entity.name}' "
                                    f"(pos {self._pos.tolist()}, the base at {base.tolist()}); move it away first")
        return offset

    def unfollow_entity(self):
        """Stop following; the camera keeps its current pose."""
        self._follow = None

    def _entity_pos(self, entity):
        """(3,) float64 m: the entity's base position in the camera's env."""
        pos = entity.get_pos(None if self._scene.n_envs == 0 else [self._env_idx])
        return pos.detach().cpu().numpy().astype(np.float64).reshape(3)

    def _update_following(self):
        """Move the camera after its followed entity (Genesis's update: the previous position relative
        to the offset is pulled to the entity, smoothed; lookat follows unless the orientation is fixed)."""
        entity, offset, fixed_axis, smoothing, fix_orientation = self._follow
        target = self._entity_pos(entity)
        # (past float32's range, as drawn, or so far that the offset vanishes in its rounding: blown up)
        if not np.abs(target).max() < np.finfo(np.float32).max or np.array_equal(target + offset, target):
            raise SimulationError(f"{self._name}.follow_entity: the position of entity '{entity.name}' is not finite "
                                  f"(in float32, as drawn) or too far to keep the camera's offset from it "
                                  f"({target.tolist()}); the camera cannot follow it (the simulation blew up)")
        weight = 0.0 if smoothing is None else smoothing
        pos = weight * (self._pos - offset) + (1.0 - weight) * target + offset
        for axis, value in enumerate(fixed_axis):
            if value is not None:
                pos[axis] = value
        lookat = self._lookat + (pos - self._pos) if fix_orientation else \
            weight * self._lookat + (1.0 - weight) * target
        self.set_pose(pos=pos, lookat=lookat)

    # -- rendering ----------------------------------------------------------------------------
    def render(self, rgb=True, depth=False, segmentation=False, colorize_seg=False, normal=False,
               antialiasing=False, force_render=False):
        """Draw the scene's current state: (rgb (H, W, 3) uint8, depth (H, W) float32 m,
        segmentation (H, W) int32 ids — or (H, W, 3) uint8 colours with colorize_seg —, normal
        (H, W, 3) float32), None for each one not asked for (see the module docstring).
        force_render: accepted (every call renders). While recording without a file named at
        start, the rgb frame is appended."""
        owner = f"{self._name}.render"
        flags = dict(rgb=rgb, depth=depth, segmentation=segmentation, colorize_seg=colorize_seg, normal=normal,
                     antialiasing=antialiasing, force_render=force_render)
        for name, value in flags.items():
            check_bool(owner, name, value)
        if antialiasing:
            raise InvalidInputError(f"{owner}: argument 'antialiasing' must be False (Genesis applies it with its "
                                    f"BatchRenderer only), got True")
        self._require_built("render")
        recording = self._recording is not None and not self._paused and not self._recording.streamed
        images = self._draw(owner, rgb=rgb or recording, depth=depth, segmentation=segmentation, normal=normal)
        if recording:
            self._recording.add(images["rgb"])
        if depth:
            np.minimum(images["depth"], self._far, out=images["depth"])  # nothing drawn: far, as Genesis
        seg = images.get("segmentation")
        if seg is not None and colorize_seg:
            seg = colorize_segmentation(seg)
        return images["rgb"] if rgb else None, images.get("depth"), seg, images.get("normal")

    def render_pointcloud(self, world_frame=True):
        """The depth image as points, as Genesis's: ((H, W, 3) float64 m, (H, W) bool). A pixel's point
        lies on the ray through its centre at the drawn depth: world coordinates, or with
        world_frame False the camera's OpenCV frame (x right, y down, z forward); the mask is True
        where something is drawn between near and far."""
        owner = f"{self._name}.render_pointcloud"
        check_bool(owner, "world_frame", world_frame)
        self._require_built("render_pointcloud")
        depth = np.minimum(self._draw(owner, depth=True)["depth"], self._far).astype(np.float64)
        rows, cols = np.meshgrid(np.arange(self._res[1]), np.arange(self._res[0]), indexing="ij")
        points = np.stack([depth * (cols + 0.5 - self.cx) / self.f, depth * (rows + 0.5 - self.cy) / self.f, depth],
                          axis=-1)
        if world_frame:
            opencv_to_world = self._world_transform() @ np.diag([1.0, -1.0, -1.0, 1.0])
            points = points @ opencv_to_world[:3, :3].T + opencv_to_world[:3, 3]
        return points, (self._near < depth) & (depth < self._far * (1.0 - 1e-3))

    def _draw(self, owner, **images):
        """The images the rasterizer draws of the scene's current state (``images``: which; owner:
        the caller, for messages; a state that is not finite raises SimulationError). Its
        buffers, made at the first render and kept, are made outside torch.inference_mode() even
        under it (inference tensors kept there broke every later render outside it)."""
        if self._attached is not None:
            self.move_to_attach()
        elif self._follow is not None:
            self._update_following()
        scene = self._scene
        with torch.inference_mode(False):
            drawing = scene._camera_visuals()
            view = View(self._pos + self._offset(), self._lookat + self._offset(), self._up, self._fov, self._near,
                        self._far, self._res)
            meshes, instances = drawing.meshes, drawing.instances(owner, scene._link_kinematics())
            spheres, debug_meshes = scene._debug_drawing() if self._debug else (None, [])
            extra = DebugMesh.instances(debug_meshes + scene._contact_arrows()) if self._debug else None
            if extra is not None:
                meshes, instances = drawing.with_debug(instances, extra)
            return self._rasterizer.render(view, meshes, instances, drawing.particles(spheres), **images)

    # -- recording ----------------------------------------------------------------------------
    def start_recording(self, save_to_filename=None, fps=None):
        """Start recording. With ``save_to_filename`` (.mp4 or .gif), Genesis 1.4.5's: the scene's
        steps take the frames, one every round(realtime_factor / (fps · dt)) steps (fps default
        60), streamed to that file; without, every render() appends its frame, kept in memory until
        stop_recording names the file. After pause_recording, resumes the same recording
        (arguments must then be None)."""
        owner = f"{self._name}.start_recording"
        self._require_built("start_recording")
        if self._recording is not None:
            if not self._paused:
                raise SceneStateError(f"{owner}: the camera is already recording; call stop_recording() first")
            if save_to_filename is not None or fps is not None:
                raise InvalidInputError(f"{owner}: resuming a paused recording keeps its file and fps: arguments "
                                        f"must be None, got {save_to_filename!r} and {fps!r}")
            self._paused = False
            if self._recording.streamed:  # counted afresh, as Genesis's: the pause leaves no gap
                self._steps_to_frame = self._steps_per_frame
            return
        if save_to_filename is None and fps is not None:
            raise InvalidInputError(f"{owner}: argument 'fps' needs 'save_to_filename' (without a file, give fps to "
                                    f"stop_recording), got fps={fps!r}")
        if save_to_filename is not None:
            save_to_filename, fps = check_target(owner, save_to_filename, fps)
            fps = self._step_rate(fps)
        self._recording, self._paused = Recording(self._name, self._res, save_to_filename, fps), False

    def _step_rate(self, fps):
        """The video rate of a recording taking a frame every whole number of steps, as close to
        ``fps`` as the scene's dt allows, a second of video showing ViewerOptions.realtime_factor
        (None: 1) seconds of simulated time (Genesis's rule); sets the steps between frames."""
        dt, pace = self._scene.dt, self._scene.viewer_options.realtime_factor or 1.0
        self._steps_per_frame = self._steps_to_frame = max(1, round(pace / (fps * dt)))
        reached = pace / (self._steps_per_frame * dt)
        if abs(reached - fps) > 1e-9 * fps:
            logger.warning(f"{self._name}.start_recording: fps={fps:g} is not reachable with a frame every whole "
                           f"number of steps of dt={dt:g} s; recording at fps={reached:g} instead")
        return reached

    def _after_step(self):
        """scene.step's: a recording started with a file takes its frame every steps_per_frame steps."""
        if self._recording is None or self._paused or not self._recording.streamed:
            return
        self._steps_to_frame -= 1
        if self._steps_to_frame <= 0:
            self._steps_to_frame = self._steps_per_frame
            try:
                frame = self._draw(f"{self._name} (recording)", rgb=True)["rgb"]
            except SimulationError as error:  # the step stands (it warned, without check_nan): no frame
                if not self._recording.skipped:
                    logger.warning(f"{error}; its frames are left out of the recording (warned once)")
                self._recording.skipped += 1
                return
            self._recording.add(frame)

    def pause_recording(self):
        """Stop appending frames until start_recording() resumes; the frames so far are kept."""
        if self._recording is None or self._paused:
            raise SceneStateError(f"{self._name}.pause_recording: the camera is not recording; call "
                                  f"start_recording() first")
        self._paused = True

    def stop_recording(self, save_to_filename=None, fps=None):
        """Finish the recording and write its file: the one named at start (then both arguments must
        be None), else ``save_to_filename`` (.mp4 or .gif; None: Genesis's default name
        ``<script>_cam_<idx>_<date>_<time>.mp4`` in the working folder) at ``fps`` (default 60)."""
        owner = f"{self._name}.stop_recording"
        if self._recording is None:
            self._scene._require_alive(owner)  # (its end finished or dropped the recording: say so)
            raise SceneStateError(f"{owner}: the camera is not recording; call start_recording() first")
        skipped = self._recording.skipped
        if self._recording.n_frames == 0:  # the recording goes on
            how = (f"the {skipped} frames due were left out, the scene's state not finite" if skipped else
                   f"step the scene while recording (a frame every {self._steps_per_frame} steps)"
                   if self._recording.streamed else "call camera.render() while recording (each render appends a "
                   "frame)")
            raise SceneStateError(f"{owner}: no frame was recorded; {how}")
        if not self._recording.streamed and save_to_filename is None:
            script = os.path.splitext(os.path.basename(sys.argv[0] or "python"))[0] or "python"
            save_to_filename = f"{script}_cam_{self._idx}_{time.strftime('%Y%m%d_%H%M%S')}.mp4"
        target = self._recording.target(save_to_filename, fps)  # a bad argument: the recording goes on
        recording, self._recording = self._recording, None
        recording.save(*target)
        if skipped:
            logger.warning(f"{owner}: {skipped} frames were left out of {target[0]!r}, the scene's state not finite: "
                           f"the video is that much shorter than the time it covers")

    def _close(self):
        """The scene is destroyed: finish a streamed recording's file (as Genesis does); a buffered
        one has no file yet and is dropped, with a warning when it held frames, as is a streamed
        one without frames (its encoder stopped: it would leave no valid video)."""
        recording, self._recording = self._recording, None
        if recording is not None and recording.streamed and recording.n_frames:
            recording.save(*recording.target())
        elif recording is not None:
            if recording.n_frames:
                logger.warning(f"{self._name}: a recording of {recording.n_frames} frames was dropped with its scene "
                               f"(it had no file: stop_recording(save_to_filename) saves one)")
            recording.discard()

    def __repr__(self):
        return f"Camera(idx={self._idx}, res={self._res}, pos={self._pos.tolist()}, lookat={self._lookat.tolist()})"


def _check_unsupported(owner, model, GUI, aperture, focus_dist, spp, denoise):
    """Refuse what only Genesis's windows, thinlens/fisheye models and raytracer do."""
    if model != "pinhole":
        raise InvalidInputError(f"{owner}: argument 'model' must be 'pinhole' (the thinlens and fisheye models need "
                                f"Genesis's raytracer and batch renderer), got {model!r}")
    if GUI is not False:
        raise InvalidInputError(f"{owner}: argument 'GUI' must be False: genesis_lite's cameras are headless (show "
                                f"the images with matplotlib, or record a video), got {GUI!r}")
    for name, value, default in (("aperture", aperture, 2.0), ("focus_dist", focus_dist, None), ("spp", spp, 256),
                                 ("denoise", denoise, None)):
        if value is not default and value != default:
            raise InvalidInputError(f"{owner}: argument '{name}' is a thinlens/raytracer setting and must keep its "
                                    f"default {default!r} with the rasterized pinhole camera, got {value!r}")


def _check_vis_options(owner, vis_options):
    """Refuse the VisOptions set away from their defaults that cameras would have to ignore."""
    default = type(vis_options)()
    for name in UNSUPPORTED_VIS_OPTIONS:
        if getattr(vis_options, name) != getattr(default, name):
            raise InvalidInputError(f"{owner}: VisOptions argument '{name}' must keep its default "
                                    f"{getattr(default, name)!r}: genesis_lite's cameras do not draw it, got "
                                    f"{getattr(vis_options, name)!r}")


def _camera_axes(owner, pos, lookat, up):
    """(3, 3) columns: the camera's x (right), y (up), z (backwards) axes in the world; a clear
    error when pos = lookat or up is parallel to the view direction."""
    back = pos - lookat
    if not np.linalg.norm(back) > 0:
        raise InvalidInputError(f"{owner}: arguments 'pos' and 'lookat' must differ, got both {pos.tolist()}")
    back = back / np.linalg.norm(back)
    right = np.cross(up, back)
    if not np.linalg.norm(right) > 1e-9 * np.linalg.norm(up):
        raise InvalidInputError(f"{owner}: argument 'up' must be a vector not parallel to the view direction, got "
                                f"up={up.tolist()} with lookat - pos={(lookat - pos).tolist()}")
    right /= np.linalg.norm(right)
    return np.stack([right, np.cross(back, right), back], axis=1)


def _transform_to_pose(owner, transform, name="transform"):
    """(pos, lookat, up) of a (4, 4) camera → world transform (argument ``name``): lookat 1 m ahead
    along −z, up = y."""
    try:
        matrix = np.asarray(transform, dtype=np.float64)
    except (TypeError, ValueError):
        matrix = np.full(0, np.nan)
    rot = matrix[:3, :3] if matrix.shape == (4, 4) else None
    if rot is None or not np.isfinite(matrix).all() or not np.allclose(rot.T @ rot, np.eye(3), atol=1e-5) or \
            np.linalg.det(rot) < 0 or not np.allclose(matrix[3], [0.0, 0.0, 0.0, 1.0], atol=1e-6):
        raise InvalidInputError(f"{owner}: argument '{name}' must be a finite (4, 4) pose whose top-left 3×3 is a "
                                f"rotation (det +1) and last row (0, 0, 0, 1), got {transform!r}")
    return matrix[:3, 3], matrix[:3, 3] - rot[:, 2], rot[:, 1]


def colorize_segmentation(seg):
    """(H, W) int segmentation ids → (H, W, 3) uint8 colours: one saturated hue per id (neighbouring
    ids far apart on the colour wheel), black for −1 (nothing)."""
    hue = np.mod(seg * _GOLDEN, 1.0)[..., None]
    rgb = np.clip(np.abs(np.mod(hue * 6.0 + np.array([0.0, 4.0, 2.0]), 6.0) - 3.0) - 1.0, 0.0, 1.0)
    return np.where(seg[..., None] < 0, 0, rgb * 255 + 0.5).astype(np.uint8)
