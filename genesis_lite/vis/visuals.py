"""What cameras draw: every entity's shapes as triangles in its link frames, with colours.

A URDF entity is drawn from its ``<visual>`` elements (``LinkSpec.visuals``: loaded by
solvers/rigid/urdf.py, moved with their link when fixed links merge); a primitive morph (Box,
Sphere, Cylinder, Capsule, Mesh, Plane, Terrain) from its own shape, i.e. its collision geom (a
Terrain's height field as the triangles of its top). Colours, as in
Genesis: the entity's ``surface.color`` when given (it paints the whole entity), else the URDF
material's colour, else DEFAULT_COLOR. Alpha is not drawn (surfaces are opaque).

Shapes become triangle meshes once: boxes with flat faces, spheres as icospheres of
SPHERE_SUBDIVISIONS, cylinders and capsules with SECTIONS sides, meshes as they are; each is split
along its edges sharper than SHARP_EDGE, so that shading rounds curved surfaces and keeps edges
crisp. A Plane is drawn as a square of PLANE_SIZE m (Genesis's default plane_size) in one colour
(Genesis draws a checker texture).

``SceneVisuals`` is a built scene's drawing for the envs the cameras draw: one MeshSet holding
every shape of every drawn env in its link frame (a horizontal plane once: the envs' drawing
offsets are horizontal, so it is the same plane in every env; another plane once per env),
built once, and per frame the Instances: each shape at its link's world pose, read from the rigid
solver, moved by its env's drawing offset (``scene.envs_offset``), then, for a debug camera, the
debug meshes of debug.py (``with_debug``). An entity drawn with vis_mode "collision" shows its
collision shapes (a mesh as its convex hull) instead of its visual ones.
"""
from dataclasses import dataclass

import numpy as np
import torch

from .. import morphs as gm
from ..utils import rotations
from ..solvers.core import InvalidInputError, SimulationError, runtime, warn_user
from ..solvers.rigid.shapes import hull_mesh, quat_to_mat
from ..solvers.rigid.collision import hfield
from ..solvers.rigid.spec import VisualSpec
from .rasterizer import Instances, MeshSet, Spheres

DEFAULT_COLOR = (0.6, 0.6, 0.6)
PLANE_SIZE = 1000.0
SPHERE_SUBDIVISIONS = 4
SECTIONS = 64
SHARP_EDGE = np.radians(30.0)


@dataclass
class Shape:
    """One drawn shape: its link (scene-wide index), triangles in the link frame (vertices (V, 3) m,
    unit normals (V, 3), faces (F, 3)), rgb colour (3,), its segmentation ids {level: id} and
    whether it is the same in every env (a horizontal plane: drawn once, not per env)."""
    link: int
    mesh: tuple
    color: np.ndarray
    seg: dict
    shared: bool


def scene_shapes(scene):
    """Every shape of a built scene's entities, entity by entity, link by link (list of Shape);
    the "geom" segmentation id is the shape's index in that list."""
    shapes = []
    for entity in scene.entities:
        if not hasattr(entity, "_specs") or not entity.morph.visualization:  # (particles: SceneVisuals.particles)
            continue
        override = None if entity.surface.color is None else np.asarray(entity.surface.color[:3])
        for k, spec in enumerate(entity._specs):
            link = entity.link_start + k
            if entity.vis_mode == "collision":  # (what collides: a shape in some pair, a mesh as its hull)
                visuals = [_geom_visual(g, hull=True) for g in spec.geoms if g.contype or g.conaffinity]
            elif isinstance(entity.morph, (gm.URDF, gm.MJCF)):
                visuals = spec.visuals
            else:
                visuals = [_geom_visual(g) for g in spec.geoms]
            for visual in visuals:
                color = override if override is not None else \
                    np.asarray(DEFAULT_COLOR if visual.rgba is None else visual.rgba[:3])
                seg = {"entity": entity.idx, "link": link, "geom": len(shapes)}
                shapes.append(Shape(link, tessellate(visual), color, seg, _horizontal_plane(spec, visual)))
    return shapes


def _horizontal_plane(spec, visual):
    """Whether ``visual`` is an unbounded plane on a root link welded to the world (a Plane morph's,
    an MJCF worldbody's) whose world normal is ±z (the link's and the visual's turns turn it)."""
    if visual.type != "plane" or spec.parent >= 0 or spec.joint_type != "fixed":
        return False
    normal = quat_to_mat(spec.quat) @ quat_to_mat(visual.quat) @ np.asarray(visual.size, dtype=np.float64)
    return bool(np.all(np.abs(normal[:2]) <= 1e-9 * np.linalg.norm(normal)))


def _geom_visual(geom, hull=False):
    """A collision geom as the VisualSpec that draws it (no colour of its own); hull: a mesh as the
    convex hull the colliders take."""
    vertices, faces = geom.vertices, geom.faces
    if hull and geom.type == "mesh":
        vertices, faces = hull_mesh(vertices)
    if geom.type == "hfield":  # (its top, as its prisms split the cells)
        return VisualSpec("mesh", np.zeros(0), geom.pos, geom.quat, *hfield.surface(geom.size, geom.elevation))
    return VisualSpec(geom.type, geom.size, geom.pos, geom.quat, vertices, faces)


def tessellate(visual):
    """(vertices (V, 3) m, unit normals (V, 3), faces (F, 3)) of a VisualSpec in its link's frame."""
    import trimesh  # (imported when first needed: with scipy it takes ~0.7 s)

    size = np.asarray(visual.size, dtype=np.float64)
    if visual.type == "box":
        mesh = trimesh.creation.box(extents=size)
    elif visual.type == "sphere":
        mesh = trimesh.creation.icosphere(subdivisions=SPHERE_SUBDIVISIONS, radius=size[0])
    elif visual.type == "cylinder":
        mesh = trimesh.creation.cylinder(radius=size[0], height=size[1], sections=SECTIONS)
    elif visual.type == "capsule":
        mesh = trimesh.creation.capsule(height=size[1], radius=size[0], count=[SECTIONS // 2, SECTIONS])
    elif visual.type == "mesh":
        mesh = trimesh.Trimesh(visual.vertices, visual.faces, process=False)
    elif visual.type == "plane":
        mesh = _plane(size)
    else:
        raise InvalidInputError(f"tessellate: VisualSpec type must be one of box, sphere, cylinder, capsule, mesh, "
                                f"plane, got {visual.type!r}")
    mesh = trimesh.graph.smooth_shade(mesh, angle=SHARP_EDGE, facet_minarea=None)
    rot = trimesh.transformations.quaternion_matrix(visual.quat)[:3, :3]
    return (mesh.vertices @ rot.T + visual.pos, mesh.vertex_normals @ rot.T, np.asarray(mesh.faces))


def _plane(normal):
    """A square of PLANE_SIZE m through the origin, orthogonal to ``normal`` (3,), facing it."""
    import trimesh

    half = PLANE_SIZE / 2
    square = np.array([[-half, -half, 0.0], [half, -half, 0.0], [half, half, 0.0], [-half, half, 0.0]])
    turn = trimesh.geometry.align_vectors([0.0, 0.0, 1.0], normal)[:3, :3]
    return trimesh.Trimesh(square @ turn.T, [[0, 1, 2], [0, 2, 3]], process=False)


def _particle_seg(entity, k, level, scene, n_shapes):
    """Segmentation id of the k-th particle entity: its entity index at the "entity" level; at the
    "link" and "geom" levels, one past the scene's links (shapes), then one per particle entity,
    so that no particle id is a rigid link's (shape's) id."""
    if level == "entity":
        return entity.idx
    n_links = sum(e.n_links for e in scene.entities if hasattr(e, "_specs"))
    return (n_links if level == "link" else n_shapes) + k


class SceneVisuals:
    """The drawing of a built scene in the envs ``envs`` (batch rows, int sequence): the MeshSet,
    built here once (None when nothing has a shape), with one instance per (env, shape), and the
    Instances of a frame (``instances``). Segmentation ids at ``segmentation_level``."""

    def __init__(self, scene, envs, segmentation_level):
        shapes = scene_shapes(scene)
        rows = [(env, shape) for shape in shapes for env in (envs[:1] if shape.shared else envs)]
        self.parts = [shape.mesh for _, shape in rows]  # (a debug camera's MeshSet adds the debug meshes' to them)
        self.meshes = MeshSet.from_parts(self.parts) if rows else None
        self._debug_parts = self._debug_meshes = None  # with_debug's last debug parts and their MeshSet
        device = runtime.device
        env = np.array([env for env, _ in rows], dtype=np.int64)
        self._env = torch.as_tensor(env, device=device)
        self._link = torch.as_tensor([shape.link for _, shape in rows], dtype=torch.int64, device=device)
        self._offset = torch.as_tensor(scene.envs_offset[env].reshape(-1, 3), dtype=torch.float32, device=device)
        self._color = torch.as_tensor(np.array([shape.color for _, shape in rows]).reshape(-1, 3),
                                      dtype=torch.float32, device=device)
        self._seg = torch.as_tensor([shape.seg[segmentation_level] for _, shape in rows], dtype=torch.int32,
                                    device=device)

        self._particle_scale = scene.vis_options.particle_size_scale
        particle_entities = [e for e in scene.entities if hasattr(e, "n_particles")]
        self._particles = [(e, np.asarray(DEFAULT_COLOR if e.surface.color is None else e.surface.color[:3]),
                            _particle_seg(e, k, segmentation_level, scene, len(shapes)))
                           for k, e in enumerate(particle_entities)]
        self._envs = torch.as_tensor(np.asarray(envs), dtype=torch.int64, device=device)
        self._batched = scene.n_envs > 0
        self._link_who = {link.idx: link._who for entity in scene._rigid_entities() for link in entity.links}
        self._envs_offset = torch.as_tensor(scene.envs_offset[np.asarray(envs)], dtype=torch.float32, device=device)
        self._left_out = set()  # the envs the last frame was drawn without (instances() warned of them)

    def particles(self, extra=None):
        """The Spheres of every MPM entity's particles in the drawn envs (radius: half the particle
        size times VisOptions.particle_size_scale, as Genesis's rasterizer; colour: the entity's
        surface colour; segmentation id: _particle_seg's), then those of ``extra`` (Spheres or
        None); None when there are none. (Particle positions are always finite: the walls clamp
        them, even where a blown-up velocity is not.)"""
        parts = [] if extra is None else [extra]
        for entity, color, seg in self._particles:
            with torch.no_grad():
                pos = entity.get_particles_pos(envs_idx=self._envs if entity.scene.n_envs else None)
            pos = pos.reshape(-1, len(self._envs), entity.n_particles, 3) if entity.scene.n_envs else pos[None, None]
            pos = (pos[0].to(torch.float32) + self._envs_offset[:, None, :]).reshape(-1, 3)
            n = len(pos)
            radius = entity.particle_size / 2.0 * self._particle_scale
            parts.append(Spheres(pos, torch.full((n,), radius, dtype=torch.float32,
                                                 device=pos.device),
                                 torch.as_tensor(color, dtype=torch.float32, device=pos.device).expand(n, 3),
                                 torch.full((n,), seg, dtype=torch.int32, device=pos.device)))
        if not parts:
            return None
        return parts[0] if len(parts) == 1 else Spheres(torch.cat([q.pos for q in parts]),
                                                        torch.cat([q.radius for q in parts]),
                                                        torch.cat([q.color for q in parts]),
                                                        torch.cat([q.seg for q in parts]))

    def instances(self, owner, links):
        """The Instances of the frame whose link kinematics are ``links`` (B, L, ≥ 7): per instance
        its link's world pose (position m, quaternion) as float32, moved by its env's offset; None
        when nothing has a shape. A shape whose pose is not finite (its env blew up) is left out
        (collapsed to a point), with a warning, while some drawn env has none; else it raises.
        owner: the caller, for messages."""
        if self.meshes is None or links is None:
            return None
        rows = links[self._env, self._link]
        rot = rotations.quat_to_mat(rows[:, 3:7]).to(torch.float32)
        pos = rows[:, :3].to(torch.float32) + self._offset
        # (checked as drawn: a float64 pose past float32's range is finite, its float32 not)
        finite = torch.isfinite(pos).all(-1) & torch.isfinite(rot).flatten(1).all(-1)
        if bool(finite.all()):
            self._left_out = set()
            return Instances(rot, pos, self._color, self._seg)
        blown = set(self._env[~finite].tolist())
        k = int(torch.nonzero(~finite)[0, 0])
        if not self._batched or blown >= set(self._envs.tolist()):  # nothing left to draw
            _not_finite(owner, f"the pose of {self._link_who[int(self._link[k])]}",
                        int(self._env[k]) if self._batched else None)
        # (an env that blew up among others, as RL runs meet them: the others are drawn, and its
        # shapes whose pose is finite; the others collapse to a point, a triangle that covers no pixel)
        warn = not blown <= self._left_out
        self._left_out = blown
        if warn:
            warn_user(f"{owner}: env(s) {sorted(blown)} drawn without the shapes whose pose is not finite (in float32, "
                      f"as drawn; the simulation blew up there), such as {self._link_who[int(self._link[k])]}; the "
                      f"other envs are drawn whole (said again when an env blows up anew)")
        hidden = ~finite
        return Instances(rot.masked_fill(hidden[:, None, None], 0.0), pos.masked_fill(hidden[:, None], 0.0),
                         self._color, self._seg)

    def with_debug(self, instances, debug):
        """(MeshSet, Instances) of the scene's shapes (their frame's ``instances``, None when
        nothing has a shape) followed by the debug meshes ``debug`` (DebugMesh.instances' pair):
        the MeshSet built again only when the debug meshes' parts change."""
        parts, extra = debug
        kept = self._debug_parts
        if kept is None or len(kept) != len(parts) or any(a is not b for a, b in zip(kept, parts)):
            self._debug_parts, self._debug_meshes = parts, MeshSet.from_parts(self.parts + parts)
        if instances is None:
            return self._debug_meshes, extra
        joined = [torch.cat([getattr(instances, name), getattr(extra, name)])
                  for name in ("rot", "pos", "color", "seg")]
        return self._debug_meshes, Instances(*joined)


def _not_finite(owner, what, env):
    """The error of a drawing whose state is not finite (a simulation that blew up: with
    SimOptions(check_nan=False), the default, the step only warns)."""
    where = "" if env is None else f" in env {env}"
    raise SimulationError(f"{owner}: {what}{where} is not finite (in float32, as drawn): the scene's state cannot be "
                          f"drawn (the simulation blew up; SimOptions(check_nan=True) raises at the step that makes it "
                          f"so)")
