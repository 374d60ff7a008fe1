"""Single-link morphs (box, sphere, cylinder, capsule, mesh, plane) and their mass properties.

Every builder returns a one-element ``list[LinkSpec]``: a root link with joint_type "fixed"
(the entity builder later turns it into a fixed or free base) carrying one geom at the link
origin. Units: metres, kilograms, kg/m³ for densities, kg·m² for inertias.

``geometry_mass_properties`` is also what the URDF loader uses for links without
``<inertial>`` (and ``combined_mass_properties`` the MJCF loader, whose geoms have densities of
their own). The loaders' frame arithmetic is here too, rounded as MuJoCo's compiler rounds it:
``quat_to_mat``, ``quat_mul``, ``normalized``, ``frame_quat``, ``quat_z_to``, ``compose``.
"""
import functools
import math
import os

import numpy as np

from .. import asset_cache
from ..core import AssetError, InvalidInputError
from .collision import hfield
from .spec import GeomSpec, LinkSpec

_IDENTITY_QUAT = (1.0, 0.0, 0.0, 0.0)

# Genesis 1.4.5's densities (kg/m³) for a body whose material states none (materials.Rigid(rho=None)),
# where a mass must come from the shapes: a plain object (a primitive, a mesh, a URDF link outside
# any articulation), an articulated robot's link, and any link under enable_mujoco_compatibility
# (MuJoCo's own default density)
OBJECT_DENSITY, ROBOT_DENSITY, MUJOCO_DENSITY = 600.0, 1500.0, 1000.0


# ------------------------------------------------------------------ argument checks


def check_positive(value, arg: str, owner: str, n: int | None = None) -> np.ndarray:
    """`value` as a float64 array of `n` entries (a scalar when n is None), each finite and > 0.

    Raises InvalidInputError naming `owner`, the argument, what was expected and what was given.
    """
    what = "a positive finite number" if n is None else f"{n} positive finite numbers"
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        arr = None
    shape_ok = arr is not None and arr.shape == (() if n is None else (n,))
    if not shape_ok or not np.all(np.isfinite(arr)) or not np.all(arr > 0):
        raise InvalidInputError(f"{owner}: argument '{arg}' expected {what}, got {value!r}")
    return arr


def _scale3(scale, owner: str) -> np.ndarray:
    """A mesh scale (one positive number or 3 positive numbers) as a (3,) array."""
    if np.ndim(scale) == 0:
        return np.full(3, check_positive(scale, "scale", owner))
    return check_positive(scale, "scale", owner, n=3)


# ------------------------------------------------------------------ rotations


def quat_to_mat(quat) -> np.ndarray:
    """(3, 3) rotation matrix of a unit quaternion (4,) w-x-y-z, rounded as MuJoCo 4.0's
    mju_quat2Mat (and spatial.quat_to_mat in the kernels)."""
    w, x, y, z = np.asarray(quat, dtype=np.float64)
    ww, xx, yy, zz = w * w, x * x, y * y, z * z
    return np.array([
        [(ww - yy) + (xx - zz), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), (ww + yy) - (xx + zz), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), (ww - yy) + (zz - xx)],
    ])


# ------------------------------------------------------------------ analytic inertias


def quat_mul(a, b) -> np.ndarray:
    """Hamilton product a ⊗ b of w-x-y-z quaternions (4,), summed in MuJoCo's order (mju_mulQuat,
    and spatial.quat_mul in the kernels), so that frames composed here round as MuJoCo's compiler
    rounds them."""
    aw, ax, ay, az = (float(v) for v in a)
    bw, bx, by, bz = (float(v) for v in b)
    return np.array([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw])


def normalized(v) -> tuple[np.ndarray, float]:
    """(v / |v|, |v|) of a vector v, rounded as MuJoCo's compiler rounds it (mjuu_normvec): the
    squares summed in order; a vector already unit within 1e-14 is left as it is, and one whose
    squares sum below 1e-14 too, its length then taken as 0. (With numpy's norm and an unconditional
    division a geom turned by ``euler`` was a bit off MuJoCo's and touched a plane MuJoCo's did not.)"""
    v = np.array(v, dtype=np.float64)
    total = 0.0
    for x in v:
        total += x * x
    if total < 1e-14:
        return v, 0.0
    length = math.sqrt(total)
    return (v / length if abs(length - 1.0) > 1e-14 else v), length


def frame_quat(x, y, z) -> np.ndarray:
    """(4,) w-x-y-z quaternion of the turn whose matrix has columns x, y, z (3,) (orthonormal), as
    MuJoCo's compiler converts a frame (mjuu_frame2quat): the largest of |w|, |x|, |y|, |z| from the
    diagonal, the other three from sums and differences of off-diagonal pairs divided by it."""
    a = np.array([x, y, z], dtype=np.float64)  # a[c, r]: row r of column c
    if a[0, 0] + a[1, 1] + a[2, 2] > 0:
        w = 0.5 * math.sqrt(1 + a[0, 0] + a[1, 1] + a[2, 2])
        q = [w, 0.25 * (a[1, 2] - a[2, 1]) / w, 0.25 * (a[2, 0] - a[0, 2]) / w, 0.25 * (a[0, 1] - a[1, 0]) / w]
    elif a[0, 0] > a[1, 1] and a[0, 0] > a[2, 2]:
        v = 0.5 * math.sqrt(1 + a[0, 0] - a[1, 1] - a[2, 2])
        q = [0.25 * (a[1, 2] - a[2, 1]) / v, v, 0.25 * (a[1, 0] + a[0, 1]) / v, 0.25 * (a[2, 0] + a[0, 2]) / v]
    elif a[1, 1] > a[2, 2]:
        v = 0.5 * math.sqrt(1 - a[0, 0] + a[1, 1] - a[2, 2])
        q = [0.25 * (a[2, 0] - a[0, 2]) / v, 0.25 * (a[1, 0] + a[0, 1]) / v, v, 0.25 * (a[2, 1] + a[1, 2]) / v]
    else:
        v = 0.5 * math.sqrt(1 - a[0, 0] - a[1, 1] + a[2, 2])
        q = [0.25 * (a[0, 1] - a[1, 0]) / v, 0.25 * (a[2, 0] + a[0, 2]) / v, 0.25 * (a[2, 1] + a[1, 2]) / v, v]
    return normalized(q)[0]


def quat_z_to(direction) -> np.ndarray:
    """(4,) w-x-y-z quaternion of the smallest turn taking +z onto ``direction`` (3,), as MuJoCo's
    compiler takes it (a zaxis, a fromto): about z × n by atan2(|z × n|, n_z); where |z × n| < 1e-7,
    about x by 0 or half a turn (its threshold, measured: a zaxis 1e-7 off −z turns about x, 1.01e-7
    off about y; a threshold of 1.4e-6 here turned such frames half a turn about the other axis).
    Also a Plane morph's normal (a normal within 1e-7 of ±z is ±z)."""
    n, _ = normalized(direction)
    axis, sine = normalized([-n[1], n[0], 0.0])  # z × n
    if sine < 1e-10:  # (its squares below 1e-14: sine 0)
        axis = np.array([1.0, 0.0, 0.0])
    half = math.atan2(sine, n[2]) / 2
    return np.array([math.cos(half), *(math.sin(half) * axis)])


def compose(pos_a, quat_a, pos_b, quat_b) -> tuple[np.ndarray, np.ndarray]:
    """Pose b (pos (3,), quat (4,)) given in frame a, expressed in frame a's parent:
    (pos_a + R_a pos_b, quat_a ⊗ quat_b), unit, w ≥ 0."""
    pos = np.asarray(pos_a, dtype=np.float64) + quat_to_mat(quat_a) @ np.asarray(pos_b, dtype=np.float64)
    quat, _ = normalized(quat_mul(quat_a, quat_b))
    return pos, (-quat if quat[0] < 0 else quat)


def box_inertia(size, mass: float) -> np.ndarray:
    """(3, 3) inertia (kg·m²) about the centre of a solid box of full extents `size` (3,) m."""
    x2, y2, z2 = np.square(np.asarray(size, dtype=np.float64))
    return mass / 12.0 * np.diag([y2 + z2, x2 + z2, x2 + y2])


def sphere_inertia(radius: float, mass: float) -> np.ndarray:
    """(3, 3) inertia (kg·m²) about the centre of a solid sphere."""
    return np.eye(3) * 0.4 * mass * radius**2


def cylinder_inertia(radius: float, length: float, mass: float) -> np.ndarray:
    """(3, 3) inertia (kg·m²) about the centre of a solid cylinder whose axis is z."""
    ixx = mass * (3.0 * radius**2 + length**2) / 12.0
    return np.diag([ixx, ixx, 0.5 * mass * radius**2])


def capsule_mass_inertia(radius: float, length: float, rho: float) -> tuple[float, np.ndarray]:
    """Mass (kg) and (3, 3) inertia (kg·m²) about the centre of a capsule along z.

    The capsule is a cylinder of `length` plus two hemispheres of `radius`. A hemisphere of
    mass m_h has inertia 2/5 m_h r² about any diameter of its flat face, its centroid sits 3r/8
    from that face, so by the parallel-axis theorem about the capsule centre (at distance
    d = length/2 + 3r/8 from the centroid) it contributes m_h (2/5 r² - 9/64 r² + d²).
    """
    m_cyl = rho * np.pi * radius**2 * length
    m_hemi = rho * 2.0 / 3.0 * np.pi * radius**3
    d = 0.5 * length + 3.0 / 8.0 * radius
    i_hemi = m_hemi * ((0.4 - 9.0 / 64.0) * radius**2 + d**2)
    inertia = cylinder_inertia(radius, length, m_cyl)
    inertia += np.diag([2 * i_hemi, 2 * i_hemi, 2 * 0.4 * m_hemi * radius**2])
    return m_cyl + 2 * m_hemi, inertia


def ellipsoid_mass_inertia(axes, rho: float) -> tuple[float, np.ndarray]:
    """Mass (kg) and (3, 3) inertia (kg·m²) about the centre of a solid ellipsoid of semi-axes
    `axes` (3,) m along x, y, z: m = ρ·4/3·π·abc, I_xx = m (b² + c²) / 5 (and cyclically)."""
    a, b, c = (float(v) for v in axes)
    mass = rho * 4.0 / 3.0 * np.pi * a * b * c
    return mass, mass / 5.0 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])


# An ellipsoid collides as a polytope inscribed in it: the octahedron's faces cut into this many
# rows, their points pushed out onto the unit sphere (1026 vertices), stretched to the semi-axes.
# Symmetric about the three principal planes (the tips of the axes are vertices: an ellipsoid
# standing on one balances as the true one does); every ray from the centre meets its surface
# within 0.39 % of the ellipsoid's.
ELLIPSOID_ROWS = 16


def ellipsoid_mesh(axes) -> tuple[np.ndarray, np.ndarray]:
    """(V, 3) vertices and (F, 3) outward faces of the convex polytope inscribed in the ellipsoid
    of semi-axes `axes` (3,) m along x, y, z (ELLIPSOID_ROWS)."""
    import itertools

    import trimesh  # (imported when first needed, as load_mesh)
    n = ELLIPSOID_ROWS
    lattice = np.array([(sx * i, sy * j, sz * (n - i - j)) for i in range(n + 1) for j in range(n + 1 - i)
                        for sx, sy, sz in itertools.product((1, -1), repeat=3)], dtype=np.float64)
    unit = np.unique(lattice, axis=0)  # (the octants share their edges' points)
    unit /= np.linalg.norm(unit, axis=1, keepdims=True)
    hull = trimesh.convex.convex_hull(unit * np.asarray(axes, dtype=np.float64))
    return np.asarray(hull.vertices), np.asarray(hull.faces)


# ------------------------------------------------------------------ meshes


# mesh formats whose file holds the whole mesh (textures aside: not read), which the asset cache
# keeps; others (glTF, COLLADA...) may name further files, whose changes it would not see
SELF_CONTAINED_MESH = (".stl", ".obj", ".ply", ".off", ".glb")


@functools.lru_cache(maxsize=64)
def _load_mesh_cached(file: tuple) -> tuple[np.ndarray, np.ndarray]:
    """Raw (V, 3) vertices and (F, 3) faces of the mesh file of ``file``, its asset_cache.snapshot
    (taken before reading it); kept because robots reuse meshes (a quadruped's four legs), here
    and in the asset cache, by the snapshot, so that edited files are read again."""
    path = file[0]

    def read():
        return _read_mesh(path), [file] if path.lower().endswith(SELF_CONTAINED_MESH) else None

    vertices, faces = asset_cache.load_or_compute("mesh", [path.encode()], read, (__file__,), ("trimesh", "numpy"))
    vertices.flags.writeable = False
    faces.flags.writeable = False
    return vertices, faces


def _read_mesh(path: str) -> tuple[np.ndarray, np.ndarray]:
    """(V, 3) vertices and (F, 3) faces of a mesh file, read by trimesh."""
    import trimesh  # (imported when first needed: with scipy it takes ~0.6 s)

    # skip_materials: textures are irrelevant to physics and slow to decode.
    mesh = trimesh.load(path, force="mesh", skip_materials=True)
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)


def load_mesh(path: str, scale=1.0, y_up=False) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) m and triangle faces (F, 3) of the mesh file `path`, scaled by `scale`.

    scale: one number or (3,) per-axis factors. A mirroring scale (odd number of negative
    factors) flips the faces so that normals keep pointing outwards.
    y_up: the file is Y-up: its vertices are turned to Z-up first, (X, Y, Z) → (X, −Z, Y) (a turn
    about x: faces keep their orientation), then scaled, as Genesis's file_meshes_are_zup=False.
    Raises AssetError when the file is missing, unreadable or holds no triangles.
    """
    if not os.path.isfile(path):
        raise AssetError(f"mesh file '{path}' does not exist")
    try:
        vertices, faces = _load_mesh_cached(asset_cache.snapshot(os.path.realpath(path)))
    except Exception as exc:  # trimesh raises many types for bad files
        raise AssetError(f"cannot load mesh file '{path}': {type(exc).__name__}: {exc}") from exc
    if len(faces) == 0:
        raise AssetError(f"mesh file '{path}' has no triangles")
    if not np.all(np.isfinite(vertices)):
        raise AssetError(f"mesh file '{path}' has non-finite (NaN or inf) vertex coordinates")
    if y_up:
        vertices = np.stack([vertices[:, 0], -vertices[:, 2], vertices[:, 1]], axis=1)
    return scaled_mesh(vertices, faces, scale)


def scaled_mesh(vertices, faces, scale=1.0) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) scaled by ``scale`` (one number or (3,) per-axis factors) and faces (F, 3),
    flipped when the scale mirrors (an odd number of negative factors), so that normals keep
    pointing outwards."""
    scale = np.broadcast_to(np.asarray(scale, dtype=np.float64), (3,))
    faces = faces[:, ::-1] if np.prod(np.sign(scale)) < 0 else faces
    return vertices * scale, faces.copy()


def enclosed_volume(vertices, faces) -> float:
    """Signed volume (m³) the triangles ``faces`` (F, 3) of ``vertices`` (V, 3) sweep from their
    area-weighted centroid, as MuJoCo's compiler measures a mesh: a closed outward mesh's volume;
    0 for flat ones (one triangle, a plane of them)."""
    corners = np.asarray(vertices, dtype=np.float64)[faces]  # (F, 3 corners, 3)
    areas = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    centre = (areas[:, None] * corners.mean(axis=1)).sum(axis=0) / max(areas.sum(), 1e-300)
    arms = corners - centre
    return float(np.einsum("fi,fi->", arms[:, 0], np.cross(arms[:, 1], arms[:, 2])) / 6.0)


def encloses_solid(vertices, faces) -> bool:
    """Whether the triangles ``faces`` (F, 3) of ``vertices`` (V, 3) bound a solid, outwards: with
    equal vertices merged, every edge met twice, once each way, and a positive enclosed volume
    (mesh_mass_properties integrates such a mesh, any other its convex hull; the MJCF loader names
    those)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    _, index = np.unique(vertices, axis=0, return_inverse=True)
    corners = index.reshape(-1)[np.asarray(faces)]
    edges = np.concatenate([corners[:, [0, 1]], corners[:, [1, 2]], corners[:, [2, 0]]])
    directed, counts = np.unique(edges, axis=0, return_counts=True)
    reverse = {tuple(edge) for edge in directed[:, ::-1].tolist()}
    paired = all(tuple(edge) in reverse for edge in directed.tolist())
    return bool(np.all(counts == 1) and paired and enclosed_volume(vertices, faces) > 0)


def hull_mesh(vertices) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (H, 3) and outward faces (F, 3) of the convex hull of ``vertices`` (V, 3).
    Raises AssetError when they span no volume (fewer than four, or coplanar)."""
    import trimesh
    vertices = np.asarray(vertices, dtype=np.float64)
    extent = float(np.ptp(vertices, axis=0).max()) if len(vertices) else 0.0
    try:
        with np.errstate(all="ignore"):  # (trimesh divides by a flat hull's zero volume)
            hull = trimesh.Trimesh(vertices, process=False).convex_hull
            volume = float(hull.volume)
    except Exception:  # qhull fails on fewer than four points
        volume = 0.0
    if not volume > 1e-9 * extent ** 3:  # (qhull joggles coplanar points into a sliver)
        raise AssetError(f"the convex hull of {len(vertices)} vertices spans no volume")
    return np.asarray(hull.vertices, dtype=np.float64), np.asarray(hull.faces, dtype=np.int64)


def mesh_mass_properties(vertices, faces, rho: float) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass (kg), com (3,) m and inertia (3, 3) kg·m² about the com, in the mesh frame.

    A closed, outward-oriented mesh is integrated as a solid. Any other mesh (open, or with
    inconsistent winding) uses its convex hull instead, which is also what the contact code
    sees. A flat or degenerate mesh has no volume and gets mass 0. Kept in the asset cache.
    """
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    inputs = [vertices.tobytes(), faces.tobytes(), repr(float(rho)).encode()]
    return asset_cache.load_or_compute("mass", inputs, lambda: (_mesh_mass_properties(vertices, faces, rho), ()),
                                       (__file__,), ("trimesh", "scipy", "numpy"))


def _mesh_mass_properties(vertices, faces, rho: float) -> tuple[float, np.ndarray, np.ndarray]:
    """mesh_mass_properties, computed by trimesh."""
    import trimesh

    mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=True)
    if not encloses_solid(vertices, faces):
        try:
            mesh = mesh.convex_hull
        except Exception:  # qhull fails on coplanar points: the shape has no volume
            return 0.0, np.zeros(3), np.zeros((3, 3))
        if mesh.volume <= 0:
            return 0.0, np.zeros(3), np.zeros((3, 3))
    mesh.density = rho
    return float(mesh.mass), np.array(mesh.center_mass), np.array(mesh.moment_inertia)


# ------------------------------------------------------------------ geometry → mass properties


def geom_mass_properties(geom: GeomSpec, rho: float) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass (kg), com (3,) m and inertia (3, 3) kg·m² about the com of one solid geom of
    density `rho`, all in the geom's own frame. Planes have mass 0."""
    size = np.asarray(geom.size, dtype=np.float64)
    zero = np.zeros(3)
    if geom.type == "box":
        mass = rho * float(np.prod(size))
        return mass, zero, box_inertia(size, mass)
    if geom.type == "sphere":
        mass = rho * 4.0 / 3.0 * np.pi * size[0] ** 3
        return mass, zero, sphere_inertia(size[0], mass)
    if geom.type == "cylinder":
        mass = rho * np.pi * size[0] ** 2 * size[1]
        return mass, zero, cylinder_inertia(size[0], size[1], mass)
    if geom.type == "capsule":
        mass, inertia = capsule_mass_inertia(size[0], size[1], rho)
        return mass, zero, inertia
    if geom.type == "mesh":
        return mesh_mass_properties(geom.vertices, geom.faces, rho)
    if geom.type in ("plane", "hfield"):  # (static ground: no mass)
        return 0.0, zero, np.zeros((3, 3))
    raise InvalidInputError(f"geom_mass_properties: geom type expected one of box, sphere, "
                            f"cylinder, capsule, mesh, plane, hfield, got {geom.type!r}")


def geometry_mass_properties(geoms, rho: float) -> tuple[float, np.ndarray, np.ndarray]:
    """Combined mass (kg), com (3,) m and inertia (3, 3) kg·m² about that com, in the link frame,
    of solid `geoms` (list of GeomSpec placed at their pos/quat) of uniform density `rho`.

    Overlapping geoms are counted twice, as in MuJoCo. No geoms (or only planes) → mass 0,
    com 0, zero inertia.
    """
    return combined_mass_properties([(geom, *geom_mass_properties(geom, rho)) for geom in geoms])


def combined_mass_properties(parts) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass (kg), com (3,) m and inertia (3, 3) kg·m² about the com, in the link frame, of
    [(GeomSpec, mass, com (3,), inertia (3, 3))]: each part's mass properties in its geom's own
    frame, placed at the geom's pos/quat. No mass → 0, com 0, zero inertia."""
    placed = []
    for geom, mass, com, inertia in parts:
        rot = quat_to_mat(geom.quat)
        placed.append((mass, np.asarray(geom.pos) + rot @ com, rot @ inertia @ rot.T))
    total = sum(m for m, _, _ in placed)
    if total <= 0:
        return 0.0, np.zeros(3), np.zeros((3, 3))
    com = sum(m * c for m, c, _ in placed) / total
    inertia = np.zeros((3, 3))
    for mass, c, rot_inertia in placed:
        d = c - com
        # parallel-axis theorem: shift each part's inertia from its own com to the link com
        inertia += rot_inertia + mass * (d @ d * np.eye(3) - np.outer(d, d))
    return float(total), com, inertia


# ------------------------------------------------------------------ link builders


def _single_link(name: str, geom: GeomSpec, rho: float) -> list[LinkSpec]:
    """One fixed root link holding `geom`, with the geom's solid mass properties."""
    mass, com, inertia = geometry_mass_properties([geom], rho)
    return [LinkSpec(
        name=name, parent=-1, joint_name="", joint_type="fixed",
        pos=np.zeros(3), quat=np.array(_IDENTITY_QUAT), axis=np.array([0.0, 0.0, 1.0]),
        mass=mass, com=com, inertia=inertia, geoms=[geom],
    )]


def box_link(size, rho: float = 1000.0, name: str = "box") -> list[LinkSpec]:
    """A solid box of full extents `size` (3,) m and density `rho` kg/m³, centred at the origin."""
    size = check_positive(size, "size", "box_link", n=3)
    rho = check_positive(rho, "rho", "box_link")
    return _single_link(name, GeomSpec("box", size), float(rho))


def sphere_link(radius: float, rho: float = 1000.0, name: str = "sphere") -> list[LinkSpec]:
    """A solid sphere of `radius` m and density `rho` kg/m³, centred at the link origin."""
    radius = check_positive(radius, "radius", "sphere_link")
    rho = check_positive(rho, "rho", "sphere_link")
    return _single_link(name, GeomSpec("sphere", np.array([radius])), float(rho))


def cylinder_link(radius: float, height: float, rho: float = 1000.0,
                  name: str = "cylinder") -> list[LinkSpec]:
    """A solid cylinder (axis z, total `height` m, `radius` m), centred at the link origin."""
    radius = check_positive(radius, "radius", "cylinder_link")
    height = check_positive(height, "height", "cylinder_link")
    rho = check_positive(rho, "rho", "cylinder_link")
    return _single_link(name, GeomSpec("cylinder", np.array([radius, height])), float(rho))


def capsule_link(radius: float, height: float, rho: float = 1000.0,
                 name: str = "capsule") -> list[LinkSpec]:
    """A solid capsule along z: a cylinder of `height` m between the two hemisphere centres,
    capped by hemispheres of `radius` m (total length height + 2 radius), centred at the origin."""
    radius = check_positive(radius, "radius", "capsule_link")
    height = check_positive(height, "height", "capsule_link")
    rho = check_positive(rho, "rho", "capsule_link")
    return _single_link(name, GeomSpec("capsule", np.array([radius, height])), float(rho))


def mesh_link(file: str, scale=1.0, rho: float = 1000.0, name: str | None = None, y_up=False) -> list[LinkSpec]:
    """A solid triangle mesh read from `file` (any format trimesh reads), scaled by `scale`
    (one number or (3,) per axis), with the mesh's own origin as the link origin (y_up: a Y-up
    file, turned to Z-up first: load_mesh).

    Watertight, outward-oriented meshes get their exact solid mass properties; other meshes
    (open, badly wound) use their convex hull's. The geom keeps the original triangles.
    name defaults to the file's base name without extension.
    Raises InvalidInputError for bad arguments, AssetError for a missing or unreadable file.
    """
    if not isinstance(file, (str, os.PathLike)):
        raise InvalidInputError(f"mesh_link: argument 'file' expected a path, got {file!r}")
    scale = _scale3(scale, "mesh_link")
    rho = check_positive(rho, "rho", "mesh_link")
    vertices, faces = load_mesh(os.fspath(file), scale, y_up)
    name = name or os.path.splitext(os.path.basename(os.fspath(file)))[0]
    geom = GeomSpec("mesh", np.zeros(0), vertices=vertices, faces=faces)
    return _single_link(name, geom, float(rho))


def terrain_link(heights, horizontal_scale: float, base: float, name: str = "terrain") -> list[LinkSpec]:
    """A static height field (mass 0) of ``heights`` (nx, ny) m at grid points ``horizontal_scale``
    m apart, point (i, j) at (i·horizontal_scale, j·horizontal_scale, heights[i, j]) in the link
    frame (Genesis's Terrain), solid down to ``base`` m below its lowest point: a MuJoCo hfield
    geom (collision/hfield.py: its grid's rows run along y, so its elevation is heights
    transposed, normalised to [0, 1] over the heights' range)."""
    heights = np.asarray(heights, dtype=np.float64)
    low, high = heights.min(), heights.max()
    elevation = hfield.normalised(heights.T, f"{name}: height field")
    half = (np.array(heights.shape, dtype=np.float64) - 1) * horizontal_scale / 2
    size = np.array([half[0], half[1], high - low if high > low else 1.0, base])
    geom = GeomSpec("hfield", size, pos=np.array([half[0], half[1], low]), elevation=elevation)
    return _single_link(name, geom, 1.0)


def plane_link(normal=(0.0, 0.0, 1.0), name: str = "plane") -> list[LinkSpec]:
    """A static infinite plane through the link origin with unit ``normal`` (3,) in the link frame
    (mass 0; the plane's size is its normal: geometry.py turns the geom frame's z onto it)."""
    return _single_link(name, GeomSpec("plane", np.asarray(normal, dtype=float)), 1.0)
