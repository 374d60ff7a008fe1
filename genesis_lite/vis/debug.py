"""Debug drawing (Genesis's ``scene.draw_debug_*``), drawn by debug cameras
(``scene.add_camera(debug=True)``) until cleared: spheres, and triangle meshes made once in world
coordinates — lines and trajectories (cylinders), arrows (a cylinder and a cone whose length is a
quarter of the arrow's and whose radius 1.5 times the body's, Genesis's proportions), coordinate
frames (x, y, z axes as cylinders red, green and blue, a sphere at the origin, as Genesis's) and
boxes (solid, or their twelve edges). A line of zero length, an arrow of zero vector and a
trajectory without two distinct consecutive points draw nothing (None, as Genesis's arrow). They
keep the colour given (alpha is not drawn), have segmentation id −1, stay where they are drawn
while the scene moves, and are drawn once (not per env, as Genesis's tiles them at each env's
offset). The contact-force arrows of an entity added with visualize_contact (``contact_arrows``)
are drawn by debug cameras too, in each drawn env at its offset (Genesis's markers)."""
import functools

import numpy as np
import torch

from ..options import real_array
from ..solvers.core import InvalidInputError, runtime
from .rasterizer import Instances, Spheres
from .visuals import SHARP_EDGE

SECTIONS = 12  # sides of a debug cylinder or cone (Genesis's)
SPHERE_SUBDIVISIONS = 2
AXIS_COLORS = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))  # a frame's x, y, z


def _color(owner, color):
    """(3,) rgb in [0, 1] of a (r, g, b[, a]) colour (a named error otherwise)."""
    rgba = real_array(color)
    if rgba.shape not in ((3,), (4,)) or not np.all((rgba >= 0) & (rgba <= 1)):
        raise InvalidInputError(f"{owner}: argument 'color' must be (r, g, b) or (r, g, b, a) in [0, 1], got {color!r}")
    return rgba[:3]


def _positive(owner, name, value):
    if not (isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
            and 0 < value < np.inf):
        raise InvalidInputError(f"{owner}: argument '{name}' must be a positive finite number (m), got {value!r}")
    return float(value)


def _points(owner, name, value, shape, one=False):
    """``value`` (numpy, list or torch) as a finite float64 array of ``shape`` (None: any length);
    one: a leading None also takes a single item given without that axis."""
    array = real_array(value)
    if one and array.ndim == len(shape) - 1:
        array = array[None]
    if array.ndim != len(shape) or any(n is not None and n != k for n, k in zip(shape, array.shape)) \
            or not np.isfinite(array).all():
        expected = "(" + ", ".join("N" if n is None else str(n) for n in shape) + ")"
        raise InvalidInputError(f"{owner}: argument '{name}' must be finite numbers of shape {expected}, got "
                                f"shape {np.shape(value)}")
    return array


class DebugSpheres:
    """Spheres of ``scene.draw_debug_spheres``: pos (N, 3) float32 m world, radius m, color rgb."""

    def __init__(self, owner, poss, radius, color):
        pos = _points(owner, "poss", poss, (None, 3), one=True)
        self.pos = torch.as_tensor(pos, dtype=torch.float32, device=runtime.device)
        self.radius, self.color = _positive(owner, "radius", radius), _color(owner, color)

    @staticmethod
    def gather(objects):
        """The Spheres of a list of DebugSpheres (seg −1: they belong to no entity); None if none."""
        if not objects:
            return None
        n = [len(obj.pos) for obj in objects]
        device = runtime.device
        radius = torch.cat([torch.full((k,), obj.radius, dtype=torch.float32, device=device)
                            for k, obj in zip(n, objects)])
        color = torch.cat([torch.as_tensor(obj.color, dtype=torch.float32, device=device).expand(k, 3)
                           for k, obj in zip(n, objects)])
        return Spheres(torch.cat([obj.pos for obj in objects]), radius, color,
                       torch.full((sum(n),), -1, dtype=torch.int32, device=device))


class DebugMesh:
    """Triangles of a debug line, arrow, frame, box or trajectory: ``parts``, a list of
    ((vertices (V, 3) m world, unit normals (V, 3), faces (F, 3)), rgb (3,)) pairs."""

    def __init__(self, parts):
        self.parts = parts

    @staticmethod
    def instances(objects):
        """(the parts' meshes, their Instances: identity poses, their colours, seg −1) of a list of
        DebugMesh; None if none."""
        parts = [part for obj in objects for part in obj.parts]
        if not parts:
            return None
        device, n = runtime.device, len(parts)
        rot = torch.eye(3, dtype=torch.float32, device=device).expand(n, 3, 3)
        color = torch.as_tensor(np.array([rgb for _, rgb in parts]), dtype=torch.float32, device=device)
        return [mesh for mesh, _ in parts], Instances(rot, torch.zeros(n, 3, dtype=torch.float32, device=device), color,
                                                      torch.full((n,), -1, dtype=torch.int32, device=device))


def _mesh(trimesh_mesh):
    """(vertices, normals, faces), split at sharp edges as the scene's shapes (visuals.tessellate):
    a box's faces and a cylinder's caps shaded flat, its side smooth."""
    import trimesh

    mesh = trimesh.graph.smooth_shade(trimesh_mesh, angle=SHARP_EDGE, facet_minarea=None)
    return np.asarray(mesh.vertices), np.asarray(mesh.vertex_normals), np.asarray(mesh.faces)


def _cylinder(start, end, radius):
    import trimesh

    return _mesh(trimesh.creation.cylinder(radius=radius, segment=np.stack([start, end]), sections=SECTIONS))


def _sphere(centre, radius):
    import trimesh

    return _mesh(trimesh.creation.icosphere(subdivisions=SPHERE_SUBDIVISIONS, radius=radius).apply_translation(centre))


def line(owner, start, end, radius, color):
    """A cylinder of ``radius`` from ``start`` to ``end`` (3,) m."""
    start, end = _points(owner, "start", start, (3,)), _points(owner, "end", end, (3,))
    radius, rgb = _positive(owner, "radius", radius), _color(owner, color)
    if np.linalg.norm(end - start) == 0:
        return None
    return DebugMesh([(_cylinder(start, end, radius), rgb)])


@functools.cache
def _unit_arrow():
    """(vertices, normals, faces) of an arrow along +z from 0 to 1: a shaft of radius 1 to 0.75,
    a cone of radius 1.5 from there to the tip (Genesis's proportions once scaled by
    diag(radius, radius, length)), split at sharp edges; made once."""
    import trimesh

    shaft = trimesh.creation.cylinder(radius=1.0, segment=[[0.0, 0.0, 0.0], [0.0, 0.0, 0.75]], sections=SECTIONS)
    head = trimesh.creation.cone(radius=1.5, height=0.25, sections=SECTIONS).apply_translation([0.0, 0.0, 0.75])
    return _mesh(trimesh.util.concatenate([shaft, head]))


def arrow(owner, pos, vec, radius, color):
    """An arrow from ``pos`` along ``vec`` (3,) m, its shaft of ``radius`` m; None for a zero
    vector (nothing drawn, as Genesis). The unit arrow scaled by diag(radius, radius, |vec|) and
    turned onto vec (its normals by the inverse scale, renormalised)."""
    import trimesh

    pos, vec = _points(owner, "pos", pos, (3,)), _points(owner, "vec", vec, (3,))
    radius, rgb = _positive(owner, "radius", radius), _color(owner, color)
    length = float(np.linalg.norm(vec))
    if length == 0:
        return None
    vertices, normals, faces = _unit_arrow()
    turn = trimesh.geometry.align_vectors([0.0, 0.0, 1.0], vec / length)[:3, :3]
    scale = np.array([radius, radius, length])
    normals = normals / scale
    normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    return DebugMesh([(((vertices * scale) @ turn.T + pos, normals @ turn.T, faces), rgb)])


def frames(owner, Ts, axis_length, origin_size, axis_radius, color):
    """Coordinate frames at the (N, 4, 4) poses ``Ts``: x, y, z axes, cylinders of ``axis_length``
    m along T's columns (red, green, blue, or all ``color``), and a sphere of radius
    ``origin_size`` m at the origin (white, or ``color``)."""
    Ts = _points(owner, "T", Ts, (None, 4, 4), one=True)
    length, size = _positive(owner, "axis_length", axis_length), _positive(owner, "origin_size", origin_size)
    radius = _positive(owner, "axis_radius", axis_radius)
    rgbs = AXIS_COLORS if color is None else [_color(owner, color)] * 3
    parts = []
    for T in Ts:
        origin = T[:3, 3]
        parts.append((_sphere(origin, size), np.ones(3) if color is None else rgbs[0]))
        parts += [(_cylinder(origin, origin + length * T[:3, k], radius), rgbs[k]) for k in range(3)]
    return DebugMesh(parts)


def box(owner, bounds, color, wireframe, wireframe_radius):
    """The axis-aligned box ``bounds`` (2, 3) m [lower, upper]: solid, or its 12 edges as
    cylinders of ``wireframe_radius``."""
    import trimesh

    bounds = _points(owner, "bounds", bounds, (2, 3))
    if not np.all(bounds[1] > bounds[0]):
        raise InvalidInputError(f"{owner}: argument 'bounds' must be [lower, upper] with lower < upper on each axis, "
                                f"got {bounds.tolist()}")
    if not isinstance(wireframe, (bool, np.bool_)):
        raise InvalidInputError(f"{owner}: argument 'wireframe' must be a bool, got {wireframe!r}")
    rgb = _color(owner, color)
    if not wireframe:
        return DebugMesh([(_mesh(trimesh.creation.box(bounds=bounds)), rgb)])
    radius = _positive(owner, "wireframe_radius", wireframe_radius)
    corners = np.array([[bounds[i, 0], bounds[j, 1], bounds[k, 2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    edges = [(a, b) for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1]  # differ on one axis
    return DebugMesh([(_cylinder(corners[a], corners[b], radius), rgb) for a, b in edges])


def trajectory(owner, poss, radius, color):
    """Cylinders of ``radius`` joining the consecutive points of ``poss`` (N, 3) m (repeated points
    skipped)."""
    poss = _points(owner, "poss", poss, (None, 3))
    radius, rgb = _positive(owner, "radius", radius), _color(owner, color)
    pairs = [(a, b) for a, b in zip(poss[:-1], poss[1:]) if np.linalg.norm(b - a) > 0]
    return DebugMesh([(_cylinder(a, b, radius), rgb) for a, b in pairs]) if pairs else None


CONTACT_FORCE_COLOR = (0.0, 0.9, 0.8)  # Genesis's
CONTACT_ARROW_RADIUS = 0.005  # m (Genesis's, which thins it for links smaller than 12.5 cm)


def contact_segments(entity, envs, offsets, scale):
    """(starts (N, 3), vectors (N, 3)) m of the arrows of the contact forces on ``entity``'s
    links in the last step's last substep (get_contacts' force_a / force_b on its side of each
    contact), from each contact's position, ``scale`` m/N long, in the envs ``envs`` (batch rows)
    moved by ``offsets`` (len(envs), 3) m; non-finite ones (a diverged env's) left out."""
    contacts = {name: value.detach().cpu().numpy() if hasattr(value, "detach") else value
                for name, value in entity.get_contacts(is_padded=entity.scene.n_envs == 0).items()}
    valid = contacts.get("valid_mask", np.ones(contacts["link_a"].shape, dtype=bool))
    if entity.scene.n_envs == 0:
        contacts = {name: value[None] for name, value in contacts.items()}
        valid = valid[None]
    links = np.arange(entity.link_start, entity.link_start + entity.n_links)
    starts, vectors = [np.zeros((0, 3))], [np.zeros((0, 3))]
    for env, offset in zip(envs, offsets):
        for side in ("a", "b"):
            mine = valid[env] & np.isin(contacts[f"link_{side}"][env], links)
            starts.append(contacts["position"][env][mine] + offset)
            vectors.append(scale * contacts[f"force_{side}"][env][mine])
    starts, vectors = np.concatenate(starts), np.concatenate(vectors)
    finite = np.isfinite(starts).all(1) & np.isfinite(vectors).all(1)
    return starts[finite], vectors[finite]


def contact_arrows(starts, vectors):
    """The DebugMesh arrows of contact_segments (Genesis's cyan, CONTACT_ARROW_RADIUS; zero
    forces draw nothing)."""
    arrows = (arrow("visualize_contact", start, vector, CONTACT_ARROW_RADIUS, CONTACT_FORCE_COLOR)
              for start, vector in zip(starts, vectors))
    return [drawn for drawn in arrows if drawn is not None]
