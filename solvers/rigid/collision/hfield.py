"""Height fields (MuJoCo's hfield geom): a grid of elevations over a rectangle, colliding with
convex geoms as MuJoCo 4.0's mjc_ConvexHField does.

Model (MuJoCo's conventions). A height field of nrow × ncol elevations e[r, c] in [0, 1]
(MuJoCo's normalised float32 data) and size (x, y, z, base) m spans x ∈ [−size x, size x],
y ∈ [−size y, size y] of its geom frame; the grid point (r, c) is at x = dx·c − size x,
y = dy·r − size y (dx = 2 size x / (ncol − 1), dy = 2 size y / (nrow − 1)), its top at
z = e[r, c]·size z, and the solid reaches down to the base at z = −base. Each grid cell is two
triangles, and each triangle with the base under it a triangular prism: a convex solid.

Data. A height field is one entry of the model's hulls (`grid_hull`): its grid's top points
(id r·ncol + c), then the same points on the base (id + nrow·ncol), no graph, no polygons; its
geom's size holds (size x, size y, ncol). A prism is a convex shape of kind HFIELD
(convex.py): the grid's hull, the height field's pose, and its top triangle's three ids.

Collision (`cell_range`, `triangle`, convex.prism_convex). The other geom's bounding box in the
height field's frame picks the grid cells under it (MuJoCo's sub-grid bounds, from the geom's
support extents there: the box holds them, so it picks the same cells or more, and a cell more
has its prisms apart from the geom); row by row, cell by cell, the cell's two prisms whose top
reaches the box's bottom each run one convex CCD (GJK, then EPA when they overlap) as MuJoCo's
mjc_penetration: at most one contact a prism, at most HFIELD_MAX a pair, in MuJoCo's order. A
contact's feature is the CCD's (vertex ids on the prism are grid ids), so its reverse is
convex_convex's closed form (convex.convex_evaluate) with the prism's vertices.
"""
import numpy as np
import taichi as ti

from ...core import AssetError
from ..spatial import mat_vec

HFIELD_MAX = 50  # contacts of one geom with a height field (MuJoCo's mjMAXCONPAIR)
MAX_POINTS = 2 ** 24  # grid points of one height field: ids travel as floats (exact in float32 up to 2^24)


def normalised(elevation, where):
    """MuJoCo's compiled elevation data: ``elevation`` (nrow, ncol) shifted to start at 0 and
    scaled to [0, 1] (left at 0 when flat), in float32 as MuJoCo's compiler computes it."""
    data = np.array(elevation, dtype=np.float32)
    if data.ndim != 2 or min(data.shape) < 2:
        raise AssetError(f"{where}: height field expected elevations on a grid of at least 2 × 2, got shape "
                         f"{data.shape}")
    if data.size > MAX_POINTS:
        raise AssetError(f"{where}: height field expected at most {MAX_POINTS} grid points, got {data.size}")
    if not np.isfinite(data).all():
        raise AssetError(f"{where}: height field expected finite elevations, got {int((~np.isfinite(data)).sum())} "
                         f"that are not")
    low, high = np.float32(data.min()), np.float32(data.max())
    data = data - low
    if high - low > np.float32(np.finfo(np.float32).eps):  # (MuJoCo's mjEPS, compared in float32)
        data = data / (high - low)
    return data


def grid_hull(size, elevation) -> dict:
    """The height field of MuJoCo ``size`` (4,) m and normalised ``elevation`` (nrow, ncol) as one
    entry of the model's hulls (convex.pack_hulls' dict): its top grid points, then the same on
    its base, in the geom frame (m); no graph (supports scan), no polygons."""
    nrow, ncol = elevation.shape
    dx, dy = (2.0 * size[0]) / (ncol - 1), (2.0 * size[1]) / (nrow - 1)
    rows, cols = np.meshgrid(np.arange(nrow), np.arange(ncol), indexing="ij")
    x, y = (dx * cols - size[0]).ravel(), (dy * rows - size[1]).ravel()
    top = np.stack([x, y, elevation.astype(np.float64).ravel() * size[2]], axis=1)
    base = np.stack([x, y, np.full(x.shape, -size[3])], axis=1)
    return dict(vert=np.concatenate([top, base]), climb=False, extrema=[0] * 27, neighbours={}, polygons=[],
                normals=[])


@ti.func
def local_box(pos1, rot1, pos2, rot2, box_centre2, box_half2):
    """The box (lowest, highest corners (3,) m) in the height field's frame (pos1, rot1) that
    holds a geom's bounding box (centre box_centre2 and half extents box_half2 in its frame at
    pos2, rot2)."""
    turn = rot1.transpose() @ rot2
    centre = rot1.transpose() @ (pos2 + mat_vec(rot2, box_centre2) - pos1)
    half = ti.abs(turn) @ box_half2
    return centre - half, centre + half


@ti.func
def cell_range(size1, nrow, lowest, highest):
    """MuJoCo's sub-grid bounds of a box (lowest, highest (3,) m, height field frame) over a height
    field of size (size x, size y, ·) and nrow rows: (rmin, rmax, cmin, cmax), the prisms of rows
    rmin ≤ r < rmax and columns cmin < c ≤ cmax."""
    ncol = int(size1[2])
    width, depth = 2.0 * size1[0], 2.0 * size1[1]
    # MuJoCo's expressions, clamped before the int conversion (a far box must not overflow it)
    cmin = int(ti.max(ti.floor((lowest[0] + size1[0]) / width * (ncol - 1)), 0.0))
    cmax = int(ti.min(ti.ceil((highest[0] + size1[0]) / width * (ncol - 1)), ncol - 1.0))
    rmin = int(ti.max(ti.floor((lowest[1] + size1[1]) / depth * (nrow - 1)), 0.0))
    rmax = int(ti.min(ti.ceil((highest[1] + size1[1]) / depth * (nrow - 1)), nrow - 1.0))
    return rmin, rmax, cmin, cmax


@ti.func
def triangle(r, c, i, ncol):
    """The top vertex ids (3,) (as floats) of the prism i (0, 1) of the cell left of column c on
    row r, in MuJoCo's prism order (mjc_ConvexHField adds the grid points (r + 1, c), (r, c) column
    by column and keeps the last three)."""
    upper, lower = (r + 1) * ncol, r * ncol
    ids = ti.Vector([upper + c - 1, lower + c - 1, upper + c], dt=float)
    if i == 1:
        ids = ti.Vector([lower + c - 1, upper + c, lower + c], dt=float)
    return ids


def surface(size, elevation):
    """The height field's top as a triangle mesh to draw: (vertices (nrow·ncol, 3) m, faces (F, 3)),
    two triangles a cell, as the prisms split it, wound counter-clockwise seen from above."""
    nrow, ncol = elevation.shape
    vertices = grid_hull(size, elevation)["vert"][: nrow * ncol]
    r, c = np.meshgrid(np.arange(nrow - 1), np.arange(1, ncol), indexing="ij")
    upper, lower = ((r + 1) * ncol).ravel(), (r * ncol).ravel()
    c = c.ravel()
    first = np.stack([upper + c - 1, lower + c - 1, upper + c], axis=1)
    second = np.stack([lower + c - 1, lower + c, upper + c], axis=1)
    return vertices, np.concatenate([first, second]).astype(np.int64)
