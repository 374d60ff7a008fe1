"""Particles of an MPM entity: points filling a shape, in world coordinates.

A shape is sampled in its own frame, then placed by its pose (x_world = R(quat)·x + pos),
as Genesis does. Both samplers start from Genesis's box of candidates over the shape's
local bounding box [lower, upper] (genesis/utils/particle.py, ``_box_to_particles``), with
n_i = max(1, round(extent_i / particle_size)) candidates per axis:
- "regular": the lattice linspace(lower + p/2, upper − p/2, n_i) per axis, spacing
  (extent − p) / (n_i − 1) ≈ p (exactly p when the extent is a multiple of p), so each
  particle stands for a cube of volume ≈ p³ (an axis with one candidate has it in the middle);
- "random": n_x·n_y·n_z points uniform in the box, from a generator seeded by ``seed`` (an int
  or a numpy SeedSequence; Genesis draws from numpy's global generator instead).
The candidates inside the shape are kept: box (all), sphere (|x| ≤ r), cylinder along local z
(x² + y² ≤ r², |z| ≤ h/2), or a watertight triangle mesh (ray parity, trimesh). Genesis tests
its primitives against their triangulated visual meshes (an icosphere, a faceted cylinder),
which are slightly smaller than the exact shapes used here.

Units: metres. Nothing here knows genesis_lite's morphs: the API passes plain parameters.
"""
import numpy as np

from ..core import AssetError, InvalidInputError, available_memory
from ..rigid.shapes import load_mesh, quat_to_mat

SAMPLERS = ("regular", "random")
SHAPES = ("box", "sphere", "cylinder", "mesh")
# bytes a candidate particle takes while a shape is sampled: the lattice's three coordinate arrays
# and their stacked copy, the shape's test and the placed copy (float64)
CANDIDATE_BYTES = 96


def candidates(lower, upper, particle_size, sampler, seed=0):
    """(n, 3) candidate points filling the box [lower, upper] (each (3,), m) at
    ``particle_size`` spacing, by ``sampler`` ("regular" lattice or seeded "random")."""
    lower, upper = np.asarray(lower, dtype=np.float64), np.asarray(upper, dtype=np.float64)
    counts = np.maximum(1, np.round((upper - lower) / particle_size)).astype(np.int64)
    if sampler == "random":
        draws = np.random.default_rng(seed).random((int(np.prod(counts)), 3))
        return lower + draws * (upper - lower)
    half = 0.5 * particle_size
    # one candidate on an axis (extent < 1.5 p) sits at the middle; Genesis's linspace puts it at
    # lower + p/2, outside an extent below p/2
    axes = [np.linspace(lo + half, hi - half, n) if n > 1 else np.array([(lo + hi) / 2.0])
            for lo, hi, n in zip(lower, upper, counts)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def _check_candidates(extent, particle_size, owner):
    """The candidates filling a box of ``extent`` (3,) m at ``particle_size`` must fit in the memory
    free now (CANDIDATE_BYTES each while they are made): a named error before they are made,
    instead of numpy's MemoryError (or the machine's out-of-memory killer) minutes later."""
    count = float(np.prod(np.maximum(1, np.round(extent / particle_size))))
    need, available = count * CANDIDATE_BYTES, available_memory()
    if available is not None and need > available:
        raise InvalidInputError(f"{owner}: particle_size = {particle_size:g} m fills the shape's {np.round(extent, 6)} "
                                f"m bounds with {count:.3g} candidate particles, {need / 2**30:.1f} GiB to sample, "
                                f"expected at most the {available / 2**30:.1f} GiB free; use a larger particle_size")


def box_particles(size, particle_size, sampler, seed=0):
    """(n, 3) local points of a box of full extents ``size`` (3,) m centred at the origin."""
    half = np.asarray(size, dtype=np.float64) / 2.0
    return candidates(-half, half, particle_size, sampler, seed)


def sphere_particles(radius, particle_size, sampler, seed=0):
    """(n, 3) local points of a ball of ``radius`` m centred at the origin."""
    points = candidates(np.full(3, -radius), np.full(3, radius), particle_size, sampler, seed)
    return points[np.linalg.norm(points, axis=1) <= radius]


def cylinder_particles(radius, height, particle_size, sampler, seed=0):
    """(n, 3) local points of a solid cylinder along z (``radius``, ``height`` m), centred."""
    half = np.array([radius, radius, height / 2.0])
    points = candidates(-half, half, particle_size, sampler, seed)
    return points[np.linalg.norm(points[:, :2], axis=1) <= radius]


def mesh_particles(vertices, faces, particle_size, sampler, seed=0, file="<mesh>"):
    """(n, 3) points inside the watertight triangle mesh (vertices (V, 3) m, faces (F, 3)), in
    the mesh's frame. A mesh with holes has no inside: AssetError naming ``file``."""
    import trimesh  # (imported when first needed: with scipy it takes ~0.7 s)

    mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=True)
    if not mesh.is_watertight:
        raise AssetError(f"mesh file '{file}' is not watertight (some edges do not join exactly two triangles), so it "
                         f"has no inside to fill with MPM particles; close its holes first (e.g. trimesh's "
                         f"fill_holes, or a remesher)")
    lower, upper = mesh.bounds
    points = candidates(lower, upper, particle_size, sampler, seed)
    return points[mesh.contains(points)]


def place(points, pos, quat):
    """Local points (n, 3) → world: R(quat)·x + pos (quat (4,) w-x-y-z, normalised here)."""
    quat = np.asarray(quat, dtype=np.float64)
    rotation = quat_to_mat(quat / np.linalg.norm(quat))
    return points @ rotation.T + np.asarray(pos, dtype=np.float64)


def shape_volume(shape, *, size=None, radius=None, height=None, file=None, scale=1.0, y_up=False):
    """Volume, m³, of the shape ``sample`` fills (its parameters; a mesh's from its closed
    surface by the divergence theorem)."""
    if shape == "box":
        return float(np.prod(size))
    if shape == "sphere":
        return 4.0 / 3.0 * np.pi * radius ** 3
    if shape == "cylinder":
        return np.pi * radius ** 2 * height
    vertices, faces = load_mesh(file, scale, y_up)
    corners = vertices[faces]  # (F, 3 corners, 3)
    return abs(float(np.einsum("ij,ij->", corners[:, 0], np.cross(corners[:, 1], corners[:, 2])))) / 6.0


def sample(shape, particle_size, sampler="regular", seed=0, pos=(0.0, 0.0, 0.0), quat=(1.0, 0.0, 0.0, 0.0), *,
           size=None, radius=None, height=None, file=None, scale=1.0, y_up=False, owner="sampling"):
    """World particle positions (n, 3) float64, m, of ``shape`` ("box": size (3,); "sphere":
    radius; "cylinder": radius, height (along local z); "mesh": file and scale, one number or
    (3,), y_up: a Y-up file, shapes.load_mesh) posed at pos (3,) m and quat (4,) w-x-y-z, at
    ``particle_size`` (m) spacing.

    Raises InvalidInputError (naming ``owner``) for an unknown shape or sampler, or when the
    shape is too small to hold one particle; AssetError for a missing, unreadable or open mesh.
    """
    if sampler not in SAMPLERS:
        raise InvalidInputError(f"{owner}: argument 'sampler' must be one of {list(SAMPLERS)}, got {sampler!r}")
    if not (np.isfinite(particle_size) and particle_size > 0):
        raise InvalidInputError(f"{owner}: argument 'particle_size' must be a positive finite number (m), "
                                f"got {particle_size!r}")
    if shape == "box":
        _check_candidates(np.asarray(size, dtype=np.float64), particle_size, owner)
        local = box_particles(size, particle_size, sampler, seed)
    elif shape == "sphere":
        _check_candidates(np.full(3, 2.0 * radius), particle_size, owner)
        local = sphere_particles(radius, particle_size, sampler, seed)
    elif shape == "cylinder":
        _check_candidates(np.array([2.0 * radius, 2.0 * radius, height]), particle_size, owner)
        local = cylinder_particles(radius, height, particle_size, sampler, seed)
    elif shape == "mesh":
        vertices, faces = load_mesh(file, scale, y_up)
        _check_candidates(vertices.max(axis=0) - vertices.min(axis=0), particle_size, owner)
        local = mesh_particles(vertices, faces, particle_size, sampler, seed, file)
    else:
        raise InvalidInputError(f"{owner}: argument 'shape' must be one of {list(SHAPES)}, got {shape!r}")
    if len(local) == 0:
        raise InvalidInputError(f"{owner}: the {shape} holds no particle at particle_size = {particle_size:g} m; "
                                f"expected a shape larger than the particles (or a smaller particle_size)")
    return place(local, pos, quat)
