"""Headless software rasterizer of the cameras: triangles and sphere impostors, z-buffered, in Taichi.

One frame is five kernels, each compiled once per process (every buffer is an array argument;
resolution, counts and the view are runtime values):

1. ``_transform``: mesh vertices and normals to the camera frame (their instance's pose, then the
   view), and sphere centres.
2. ``_setup``: clears the z-buffer; per primitive (triangles first, then spheres: the primitive id
   orders them) the pixel bounding box of its part between the near and far planes and how many
   TILE × TILE tiles cover it; per face, what the resolve pass needs to shade it (which side the
   camera sees; its normal if flat). A torch ``cumsum`` turns the tile counts into a work list.
3. ``_list_tiles``: the primitive of every work item.
4. ``_raster``: one parallel loop over the tiles, each testing its pixels against its primitive and
   writing ``atomic_min`` of a 64-bit key: float32 depth bits (high word) | primitive id (low word).
   Positive floats order as their bits, so keys order by depth, then by id: the image does not
   depend on the threads' order, two renders are bit-identical. Tiles keep the ground plane (two
   triangles, half the image) from running on one thread, which a GPU could not afford; a small
   triangle or particle is one tile.
5. ``_resolve``: per pixel, from the winning id, the normal, colour and segmentation id, shaded
   with ambient + (1 − ambient)·Lambert from a fixed sun (``Rasterizer(light_dir=...)``, world
   frame, towards the sun; fixed rather than a headlight so that faces keep their shades when the
   camera moves), in the camera frame; only the outputs asked for are written.

Triangles are rasterized homogeneously (Olano & Greer 1997): the ray r = (dx/f, −dy/f, −1) of a pixel
(camera frame; dx, dy: offsets of its centre from the principal point, pixels, rows down) hits a
triangle iff its coordinates in the basis of the three camera-frame vertices are all ≥ 0. They are
the edge functions e_i = ±f·(v_j × v_k)·r, linear in (dx, dy); normalised, the perspective-correct
barycentrics; and the depth is f·|det(v0, v1, v2)| / Σe_i. No clipping: the vertices' basis only
sees what lies in front of the eye, so a triangle with vertices behind the camera cannot wrap
around, and the test near ≤ depth ≤ far cuts the rest. Only the bounding box comes from the
triangle clipped by the near plane. Each edge's cross product is taken in one canonical vertex
order (lexicographic by position), so the two triangles sharing an edge compute bit-identical
functions of opposite signs even where a backend contracts to FMA (CUDA); with the top-left rule
(a pixel on an edge belongs to the side the function grows towards, along +x, else +y) a shared
edge is drawn exactly once. Spheres are impostors: per pixel the exact ray–sphere depth, within
the exact pixel bounds of the projected sphere (tangent planes through the camera's axes).

Depth is the distance along the view axis (metres; background +inf). Everything is float32
whatever ``gs.init(precision=...)`` chose: every float literal in a kernel is cast to ti.f32
(Taichi types bare literals with the default float). No shadows (see :class:`Rasterizer`).
"""
import math

import numpy as np
import taichi as ti
import torch

from ..runtime import require_init
from ..solvers.core import InvalidInputError, runtime

vec3f = ti.types.vector(3, ti.f32)
vec4i = ti.types.vector(4, ti.i32)
mat3f = ti.types.matrix(3, 3, ti.f32)

TILE = 16
"""Side of the square pixel tiles a primitive's bounding box is split into (one work item each)."""
INF_BITS = 0x7F800000
"""Bits of float32 +inf: the high word of an empty pixel's key (depth +inf), above every drawn one's."""

# Layout of the per-frame float32 parameter vector the kernels take (Rasterizer._params).
EYE, ROT, FOCAL, CX, CY, NEAR, FAR, LIGHT, AMBIENT, BACKGROUND, N_PARAMS = 0, 3, 12, 13, 14, 15, 16, 17, 20, 21, 24

Camera = ti.types.struct(eye=vec3f, rot=mat3f, focal=ti.f32, cx=ti.f32, cy=ti.f32, near=ti.f32, far=ti.f32)
"""The view, unpacked once per kernel: eye (world m), rot (world → camera), focal length and principal
point (pixels), near and far planes (m)."""


# ---------------------------------------------------------------------------------------------
# Taichi functions; the raster pass and the setup pass share them (the same bits in both)


@ti.func
def _camera(params: ti.template()):
    """The Camera of the parameter vector."""
    rot = mat3f(0.0)
    for i, j in ti.static(ti.ndrange(3, 3)):
        rot[i, j] = params[ROT + 3 * i + j]
    return Camera(eye=vec3f(params[EYE], params[EYE + 1], params[EYE + 2]), rot=rot, focal=params[FOCAL],
                  cx=params[CX], cy=params[CY], near=params[NEAR], far=params[FAR])


@ti.func
def _pixel_offsets(x, y, camera):
    """Offsets (dx, dy) in pixels of the centre of pixel (column x, row y) from the principal point."""
    return ti.cast(x, ti.f32) + ti.f32(0.5) - camera.cx, ti.cast(y, ti.f32) + ti.f32(0.5) - camera.cy


@ti.func
def _ray(dx, dy, camera):
    """Camera-frame ray through the pixel at offsets (dx, dy), scaled to depth 1 (z = −1)."""
    return vec3f(dx / camera.focal, -dy / camera.focal, ti.f32(-1.0))


@ti.func
def _lex_less(a, b):
    """a < b in lexicographic (x, y, z) order."""
    return a[0] < b[0] or (a[0] == b[0] and (a[1] < b[1] or (a[1] == b[1] and a[2] < b[2])))


@ti.func
def _edge(a, b, side, focal):
    """Coefficients (A, B, C) of e(dx, dy) = A·dx + B·dy + C for the triangle edge a–b (camera frame),
    positive towards the triangle when side is the sign of its determinant. The cross product is
    taken in canonical order so that the neighbour across the edge gets exactly −(A, B, C)."""
    swap = _lex_less(b, a)
    first, second = a, b
    if swap:
        first, second = b, a
    c = first.cross(second)
    sign = side * ti.select(swap, ti.f32(-1.0), ti.f32(1.0))
    return vec3f(sign * c[0], sign * -c[1], sign * -(c[2] * focal))


@ti.func
def _triangle(v0, v1, v2, focal):
    """Edge functions (rows, opposite v0, v1, v2) and depth scale f·|det| of a camera-frame triangle;
    scale 0 when the triangle's plane passes through the eye (it covers no area)."""
    det = v0.dot(v1.cross(v2))
    side = ti.select(det < 0, ti.f32(-1.0), ti.f32(1.0))
    e0 = _edge(v1, v2, side, focal)
    e1 = _edge(v2, v0, side, focal)
    e2 = _edge(v0, v1, side, focal)
    return mat3f([[e0[0], e0[1], e0[2]], [e1[0], e1[1], e1[2]], [e2[0], e2[1], e2[2]]]), focal * ti.abs(det)


@ti.func
def _covers(e, a, b):
    """The top-left rule: a pixel on an edge (e = 0) belongs to the triangle the edge function
    grows into along +x, or along +y when it is constant in x."""
    return e > 0 or (e == 0 and (a > 0 or (a == 0 and b > 0)))


@ti.func
def _triangle_depth(edges, scale, dx, dy, camera):
    """Depth of the triangle (edges, scale) at the pixel at offsets (dx, dy); −1 when the pixel is
    not covered or the point lies outside [near, far]."""
    e = vec3f(0.0)
    inside = True
    for i in ti.static(range(3)):
        e[i] = edges[i, 0] * dx + edges[i, 1] * dy + edges[i, 2]
        inside = inside and _covers(e[i], edges[i, 0], edges[i, 1])
    total = e[0] + e[1] + e[2]
    depth = ti.f32(-1.0)
    if inside and total > 0:
        depth = scale / total
        if not camera.near <= depth <= camera.far:
            depth = ti.f32(-1.0)
    return depth


@ti.func
def _sphere_depth(centre, radius, ray, camera):
    """Depth of the first point of the sphere (camera-frame centre) along the ray (z = −1) that lies
    in [near, far], −1 when none. The ray misses when its distance to the centre, |c × r| / |r|,
    exceeds the radius: no square root, and the cross product does not cancel catastrophically
    as |c|²|r|² − (c·r)² would for a small sphere far away."""
    ray_sq = ray.dot(ray)
    miss_sq = centre.cross(ray).norm_sqr()
    depth = ti.f32(-1.0)
    if miss_sq <= radius * radius * ray_sq:
        along = centre.dot(ray)
        half_chord = ti.sqrt(radius * radius * ray_sq - miss_sq)
        depth = (along - half_chord) / ray_sq
        if depth < camera.near:  # the near plane cuts the sphere: its far side shows
            depth = (along + half_chord) / ray_sq
        if not camera.near <= depth <= camera.far:
            depth = ti.f32(-1.0)
    return depth


@ti.func
def _write(keys: ti.template(), x, y, depth, prim):
    """atomic_min of the z-buffer key of a hit into keys[y, x]: depth bits (high word) then primitive
    id (low word); the plain read first spares most hidden pixels the atomic."""
    key = (ti.cast(ti.bit_cast(depth, ti.i32), ti.i64) << 32) | ti.cast(prim, ti.i64)
    if key < keys[y, x]:
        ti.atomic_min(keys[y, x], key)


@ti.func
def _pixel_range(lo, hi, size):
    """First and last pixel (clamped to [0, size)) whose centre lies in [lo, hi] (pixels), with a
    margin of 1/100 pixel for rounding (the pixel test itself is exact)."""
    limit = ti.cast(size, ti.f32)  # clamped as floats: casting an infinite bound to int is undefined
    first = ti.cast(ti.ceil(ti.min(ti.max(lo - ti.f32(0.51), ti.f32(-1.0)), limit)), ti.i32)
    last = ti.cast(ti.floor(ti.min(ti.max(hi - ti.f32(0.49), ti.f32(-1.0)), limit)), ti.i32)
    return ti.max(first, 0), ti.min(last, size - 1)


@ti.func
def _triangle_bounds(v0, v1, v2, camera):
    """Screen bounds (xmin, xmax, ymin, ymax, pixels) of the part of a camera-frame triangle in front
    of the near plane (its vertices there and the edges' crossings of the plane); xmin > xmax when
    nothing is in front."""
    near = camera.near
    lo = ti.Vector([ti.f32(ti.math.inf), ti.f32(ti.math.inf)], ti.f32)
    hi = -lo
    verts = [v0, v1, v2]
    for i in ti.static(range(3)):
        a, b = verts[i], verts[(i + 1) % 3]
        for crossing in ti.static(range(2)):
            use = -a[2] >= near
            if ti.static(crossing):
                use = (-a[2] - near) * (-b[2] - near) < 0
            if use:
                point = a
                if ti.static(crossing):
                    point = a + (b - a) * ((-a[2] - near) / (b[2] - a[2]))
                depth = ti.max(-point[2], near)
                screen = ti.Vector([camera.cx + camera.focal * point[0] / depth,
                                    camera.cy - camera.focal * point[1] / depth], ti.f32)
                lo = ti.min(lo, screen)
                hi = ti.max(hi, screen)
    return lo[0], hi[0], lo[1], hi[1]


@ti.func
def _sphere_slopes(u, depth, radius):
    """Slopes (lo, hi) of the two planes through the eye and a camera axis that touch a sphere whose
    centre has coordinate u across that axis and the given depth (> radius): the exact extent of
    the projected sphere along the other image axis, in units of the focal length."""
    s = ti.sqrt(u * u + depth * depth - radius * radius)
    return (u * s - radius * depth) / (depth * s + u * radius), (u * s + radius * depth) / (depth * s - u * radius)


@ti.func
def _sphere_bounds(centre, radius, camera):
    """Screen bounds (xmin, xmax, ymin, ymax, pixels) of a camera-frame sphere: exact when it lies in
    front of the near plane; when the plane cuts it, those of the box around its part in front (the
    box's projection is the hull of its corners'); xmin > xmax when it lies outside [near, far]."""
    depth = -centre[2]
    xmin, xmax, ymin, ymax = ti.f32(1.0), ti.f32(0.0), ti.f32(1.0), ti.f32(0.0)
    if depth - radius > camera.near and depth - radius <= camera.far:
        x_lo, x_hi = _sphere_slopes(centre[0], depth, radius)
        y_lo, y_hi = _sphere_slopes(centre[1], depth, radius)
        xmin, xmax = camera.cx + camera.focal * x_lo, camera.cx + camera.focal * x_hi
        ymin, ymax = camera.cy - camera.focal * y_hi, camera.cy - camera.focal * y_lo
    elif camera.near <= depth + radius and depth - radius <= camera.far:
        xmin, xmax = ti.f32(ti.math.inf), ti.f32(-ti.math.inf)
        ymin, ymax = xmin, xmax
        for corner in ti.static(range(8)):
            x = centre[0] + ti.f32(ti.static(corner % 2 * 2.0 - 1.0)) * radius
            y = centre[1] + ti.f32(ti.static(corner // 2 % 2 * 2.0 - 1.0)) * radius
            corner_depth = depth + radius if ti.static(corner // 4) else camera.near
            xmin = ti.min(xmin, camera.cx + camera.focal * x / corner_depth)
            xmax = ti.max(xmax, camera.cx + camera.focal * x / corner_depth)
            ymin = ti.min(ymin, camera.cy - camera.focal * y / corner_depth)
            ymax = ti.max(ymax, camera.cy - camera.focal * y / corner_depth)
    return xmin, xmax, ymin, ymax


@ti.func
def _shading(v0, v1, v2, n0, n1, n2):
    """(normal, facing) of a camera-frame face with vertex normals n, for the resolve pass. facing: +1
    when the camera sees the side the vertex normals point to, −1 when it sees the back (two-sided
    surfaces, e.g. the ground from below), the same over the whole face (its plane misses the eye).
    normal: a flat face's (equal vertex normals) normal times facing, which spares its pixels the
    interpolation; 0 for a smooth face."""
    geometric = (v1 - v0).cross(v2 - v0)
    if geometric.dot(n0 + n1 + n2) < 0:
        geometric = -geometric
    facing = ti.select(geometric.dot(v0) > 0, ti.f32(-1.0), ti.f32(1.0))
    normal = vec3f(0.0)
    if all(n0 == n1) and all(n0 == n2):
        normal = n0 * facing
    return ti.Vector([normal[0], normal[1], normal[2], facing], ti.f32)


@ti.func
def _unit(v):
    """v / |v|, 0 for v = 0 (opposed vertex normals), in float32 (Taichi's norm() adds a literal 0.0,
    a float64 under gs.init(precision="64"))."""
    return v / ti.max(ti.sqrt(v.norm_sqr()), ti.f32(1e-30))


@ti.func
def _face_normal(v0, v1, v2, n0, n1, n2, ray):
    """Camera-frame unit normal at the ray's hit of a camera-frame face, interpolated from the vertex
    normals n with the perspective-correct barycentrics: the ray's coordinates in the vertices'
    basis, normalised to sum 1."""
    weights = vec3f(v1.cross(v2).dot(ray), v2.cross(v0).dot(ray), v0.cross(v1).dot(ray))
    bary = weights / weights.sum()
    return _unit(bary[0] * n0 + bary[1] * n1 + bary[2] * n2)


# ---------------------------------------------------------------------------------------------
# kernels

_f32_1 = ti.types.ndarray(dtype=ti.f32, ndim=1)
_i32_1 = ti.types.ndarray(dtype=ti.i32, ndim=1)
_vec3_1 = ti.types.ndarray(dtype=vec3f, ndim=1)
_mat3_1 = ti.types.ndarray(dtype=mat3f, ndim=1)
_face_1 = ti.types.ndarray(dtype=ti.types.vector(3, ti.i32), ndim=1)
_box_1 = ti.types.ndarray(dtype=vec4i, ndim=1)
_vec4_1 = ti.types.ndarray(dtype=ti.types.vector(4, ti.f32), ndim=1)
_key_2 = ti.types.ndarray(dtype=ti.i64, ndim=2)


@ti.kernel
def _transform(n_vertices: ti.i32, n_spheres: ti.i32, params: _f32_1, local_vertices: _vec3_1, local_normals: _vec3_1,
               vertex_instance: _i32_1, inst_rot: _mat3_1, inst_pos: _vec3_1, sphere_pos: _vec3_1,
               cam_vertices: _vec3_1, cam_normals: _vec3_1, cam_spheres: _vec3_1):
    """Mesh vertices and normals (local frame of their instance) and sphere centres (world) to the
    camera frame (m)."""
    camera = _camera(params)
    for v in range(n_vertices):
        inst = vertex_instance[v]
        cam_vertices[v] = camera.rot @ (inst_rot[inst] @ local_vertices[v] + inst_pos[inst] - camera.eye)
        cam_normals[v] = camera.rot @ (inst_rot[inst] @ local_normals[v])
    for s in range(n_spheres):
        cam_spheres[s] = camera.rot @ (sphere_pos[s] - camera.eye)


@ti.kernel
def _setup(n_faces: ti.i32, n_spheres: ti.i32, width: ti.i32, height: ti.i32, params: _f32_1, faces: _face_1,
           cam_vertices: _vec3_1, cam_normals: _vec3_1, cam_spheres: _vec3_1, sphere_radius: _f32_1, prim_box: _box_1,
           prim_tiles: _i32_1, face_shading: _vec4_1, keys: _key_2):
    """Per primitive (faces, then spheres): its clamped pixel box (x0, y0, x1, y1 inclusive) and its
    number of tiles (0 when it is culled: off screen, behind the near plane, beyond the far one);
    per face, its shading (_shading: which side the camera sees, flat or smooth).
    And the z-buffer keys (H, W) cleared (here rather than with torch: torch's thread pool stalls
    when other processes hold the cores)."""
    camera = _camera(params)
    for y in range(height):
        for x in range(width):
            keys[y, x] = ti.cast(INF_BITS, ti.i64) << 32
    for p in range(n_faces + n_spheres):
        xmin, xmax, ymin, ymax = ti.f32(1.0), ti.f32(0.0), ti.f32(1.0), ti.f32(0.0)
        if p < n_faces:
            face = faces[p]
            v0, v1, v2 = cam_vertices[face[0]], cam_vertices[face[1]], cam_vertices[face[2]]
            beyond = ti.min(-v0[2], -v1[2], -v2[2]) > camera.far
            _edges, scale = _triangle(v0, v1, v2, camera.focal)
            if scale > 0 and not beyond:
                xmin, xmax, ymin, ymax = _triangle_bounds(v0, v1, v2, camera)
            face_shading[p] = _shading(v0, v1, v2, cam_normals[face[0]], cam_normals[face[1]], cam_normals[face[2]])
        else:
            xmin, xmax, ymin, ymax = _sphere_bounds(cam_spheres[p - n_faces], sphere_radius[p - n_faces], camera)
        x0, x1 = _pixel_range(xmin, xmax, width)
        y0, y1 = _pixel_range(ymin, ymax, height)
        tiles = 0
        if xmin <= xmax and ymin <= ymax and x0 <= x1 and y0 <= y1:
            tiles = ((x1 - x0) // TILE + 1) * ((y1 - y0) // TILE + 1)
        prim_box[p] = vec4i(x0, y0, x1, y1)
        prim_tiles[p] = tiles


@ti.kernel
def _list_tiles(n_prims: ti.i32, prim_tiles: _i32_1, prim_end: _i32_1, tile_prim: _i32_1):
    """The primitive of every work item; prim_end: inclusive prefix sum of prim_tiles."""
    for p in range(n_prims):
        start = prim_end[p] - prim_tiles[p]
        for k in range(prim_tiles[p]):
            tile_prim[start + k] = p


@ti.kernel
def _raster(n_tiles: ti.i32, n_faces: ti.i32, params: _f32_1, faces: _face_1, cam_vertices: _vec3_1,
            cam_spheres: _vec3_1, sphere_radius: _f32_1, prim_box: _box_1, prim_tiles: _i32_1, prim_end: _i32_1,
            tile_prim: _i32_1, keys: _key_2):
    """Every pixel of every tile against the tile's primitive, into the z-buffer keys (H, W)."""
    camera = _camera(params)
    for w in range(n_tiles):
        p = tile_prim[w]
        box = prim_box[p]
        x_start, y_start = box[0], box[1]
        if prim_tiles[p] > 1:  # spares the common single tile two integer divisions
            k = w - (prim_end[p] - prim_tiles[p])
            tiles_x = (box[2] - box[0]) // TILE + 1
            x_start += (k % tiles_x) * TILE
            y_start += (k // tiles_x) * TILE
        x_stop, y_stop = ti.min(x_start + TILE, box[2] + 1), ti.min(y_start + TILE, box[3] + 1)
        if p < n_faces:
            face = faces[p]
            edges, scale = _triangle(cam_vertices[face[0]], cam_vertices[face[1]], cam_vertices[face[2]],
                                     camera.focal)
            for y in range(y_start, y_stop):
                for x in range(x_start, x_stop):
                    dx, dy = _pixel_offsets(x, y, camera)
                    depth = _triangle_depth(edges, scale, dx, dy, camera)
                    if depth > 0:
                        _write(keys, x, y, depth, p)
        else:
            centre, radius = cam_spheres[p - n_faces], sphere_radius[p - n_faces]
            for y in range(y_start, y_stop):
                for x in range(x_start, x_stop):
                    dx, dy = _pixel_offsets(x, y, camera)
                    depth = _sphere_depth(centre, radius, _ray(dx, dy, camera), camera)
                    if depth > 0:
                        _write(keys, x, y, depth, p)


@ti.kernel
def _resolve(width: ti.i32, height: ti.i32, n_faces: ti.i32, want_rgb: ti.i32, want_depth: ti.i32,
             want_seg: ti.i32, want_normal: ti.i32, params: _f32_1, keys: _key_2, faces: _face_1,
             cam_vertices: _vec3_1, cam_normals: _vec3_1, face_shading: _vec4_1, face_instance: _i32_1,
             inst_color: _vec3_1,
             inst_seg: _i32_1, cam_spheres: _vec3_1, sphere_radius: _f32_1, sphere_color: _vec3_1,
             sphere_seg: _i32_1, rgb: ti.types.ndarray(dtype=ti.u8, ndim=3),
             depth_out: ti.types.ndarray(dtype=ti.f32, ndim=2), seg_out: ti.types.ndarray(dtype=ti.i32, ndim=2),
             normal_out: ti.types.ndarray(dtype=vec3f, ndim=2)):
    """Per pixel, the winner of the z-buffer shaded: rgb (H, W, 3) uint8, depth (H, W) m (+inf where
    empty), segmentation (H, W) (−1 where empty), world normals (H, W, 3) (0 where empty); only the
    outputs whose want_* flag is set are written. Lighting in the camera frame (LIGHT holds the
    sun's direction there)."""
    camera = _camera(params)
    light = vec3f(params[LIGHT], params[LIGHT + 1], params[LIGHT + 2])
    ambient = params[AMBIENT]
    background = vec3f(params[BACKGROUND], params[BACKGROUND + 1], params[BACKGROUND + 2])
    for y in range(height):  # rows in parallel: a flat ndrange pays a division per pixel
        for x in range(width):
            high = ti.cast(keys[y, x] >> 32, ti.i32)
            color = background
            depth = ti.f32(ti.math.inf)
            seg = -1
            normal = vec3f(0.0)  # camera frame
            if high < INF_BITS:
                p = ti.cast(keys[y, x], ti.i32)  # the low word
                depth = ti.bit_cast(high, ti.f32)
                dx, dy = _pixel_offsets(x, y, camera)
                ray = _ray(dx, dy, camera)
                if p < n_faces:
                    face = faces[p]
                    shading = face_shading[p]
                    normal = vec3f(shading[0], shading[1], shading[2])
                    if all(normal == 0):  # a smooth face
                        normal = _face_normal(cam_vertices[face[0]], cam_vertices[face[1]], cam_vertices[face[2]],
                                              cam_normals[face[0]], cam_normals[face[1]], cam_normals[face[2]],
                                              ray) * shading[3]
                    color, seg = inst_color[face_instance[p]], inst_seg[face_instance[p]]
                else:
                    s = p - n_faces
                    normal = _unit(depth * ray - cam_spheres[s])
                    if normal.dot(ray) > 0:  # the inside of a sphere cut by the near plane
                        normal = -normal
                    color, seg = sphere_color[s], sphere_seg[s]
                color *= ambient + (ti.f32(1.0) - ambient) * ti.max(normal.dot(light), ti.f32(0.0))
            if want_rgb:
                for c in ti.static(range(3)):
                    rgb[y, x, c] = ti.cast(ti.min(ti.max(color[c], ti.f32(0.0)), ti.f32(1.0)) * ti.f32(255.0)
                                           + ti.f32(0.5), ti.u8)
            if want_depth:
                depth_out[y, x] = depth
            if want_seg:
                seg_out[y, x] = seg
            if want_normal:
                normal_out[y, x] = camera.rot.transpose() @ normal


# ---------------------------------------------------------------------------------------------
# Python side


def _tensor(owner, name, value, dtype, shape):
    """value as a contiguous torch tensor of dtype on the runtime's device, checked against shape
    (a tuple whose None entries match any size)."""
    if isinstance(value, np.ndarray):
        value = np.ascontiguousarray(value)  # torch takes no negative strides (a[::-1])
    try:
        tensor = torch.as_tensor(value, dtype=dtype, device=runtime.device).contiguous()
    except (TypeError, ValueError, RuntimeError) as error:
        raise InvalidInputError(f"{owner}: argument '{name}' must be an array of {dtype}, got {type(value).__name__}"
                                f" ({error})") from None
    if tensor.dim() != len(shape) or any(want is not None and got != want for got, want in zip(tensor.shape, shape)):
        expected = "(" + ", ".join("N" if want is None else str(want) for want in shape) + ")"
        raise InvalidInputError(f"{owner}: argument '{name}' must have shape {expected}, got {tuple(tensor.shape)}")
    if tensor.is_floating_point() and not torch.isfinite(tensor).all():
        raise InvalidInputError(f"{owner}: argument '{name}' must be finite, got non-finite values")
    return tensor


def _rows(owner, **arrays):
    """The common leading size of arrays (name → tensor); a clear error when they differ."""
    sizes = {name: tensor.shape[0] for name, tensor in arrays.items()}
    if len(set(sizes.values())) > 1:
        raise InvalidInputError(f"{owner}: arguments {', '.join(sizes)} must have as many rows, got {sizes}")
    return next(iter(sizes.values()))


class MeshSet:
    """The triangles of every drawn shape in its own (local) frame, concatenated; built once, never per frame.

    vertices (V, 3) float32 m, local frame of their instance; normals (V, 3) float32 (per vertex,
    normalised here, interpolated over the faces: a mesh that wants flat faces duplicates its vertices,
    e.g. trimesh's ``unmerge_vertices``; a face whose three normals are equal is shaded flat, faster;
    zero normals get the ambient light only); faces (F ≥ 1, 3) int32 vertex indices; face_instance
    (F,) int32: the instance of each face (every face of a vertex must share it). Accepts numpy
    arrays or torch tensors (converted to the runtime's device).
    """

    def __init__(self, vertices, normals, faces, face_instance):
        self.vertices = _tensor("MeshSet", "vertices", vertices, torch.float32, (None, 3))
        self.normals = _tensor("MeshSet", "normals", normals, torch.float32, (None, 3))
        self.normals = self.normals / self.normals.norm(dim=1, keepdim=True).clamp_min(1e-30)
        self.faces = _tensor("MeshSet", "faces", faces, torch.int32, (None, 3))
        self.face_instance = _tensor("MeshSet", "face_instance", face_instance, torch.int32, (None,))
        n_vertices = _rows("MeshSet", vertices=self.vertices, normals=self.normals)
        self.n_faces = _rows("MeshSet", faces=self.faces, face_instance=self.face_instance)
        if self.n_faces == 0:
            raise InvalidInputError("MeshSet: argument 'faces' must hold at least one face, got none")
        if self.faces.min() < 0 or self.faces.max() >= n_vertices:
            raise InvalidInputError(f"MeshSet: argument 'faces' must hold vertex indices in [0, {n_vertices}), got "
                                    f"[{int(self.faces.min())}, {int(self.faces.max())}]")
        if self.face_instance.min() < 0:
            raise InvalidInputError(f"MeshSet: argument 'face_instance' must be ≥ 0, got "
                                    f"{int(self.face_instance.min())}")
        self.vertex_instance = self._vertex_instance(n_vertices)
        self.n_instances = int(self.face_instance.max()) + 1

    def _vertex_instance(self, n_vertices):
        """(V,) int32: the instance of each vertex (0 for vertices no face uses)."""
        per_corner = self.face_instance.repeat_interleave(3)
        vertex_instance = torch.zeros(n_vertices, dtype=torch.int32, device=runtime.device)
        vertex_instance[self.faces.reshape(-1).long()] = per_corner
        shared = vertex_instance[self.faces.long()] != self.face_instance[:, None]
        if shared.any():
            face = int(shared.any(dim=1).nonzero()[0, 0])
            raise InvalidInputError(f"MeshSet: argument 'faces' must not share vertices between instances, got face "
                                    f"{face} ({self.faces[face].tolist()}) of instance {int(self.face_instance[face])} "
                                    f"using a vertex of another instance")
        return vertex_instance

    @classmethod
    def from_parts(cls, parts):
        """A MeshSet of one instance per part (its index in the list): parts is a list of
        (vertices (V_k, 3), normals (V_k, 3), faces (F_k, 3)) numpy arrays in the instance's frame."""
        if not parts:
            raise InvalidInputError("MeshSet.from_parts: argument 'parts' must hold at least one part, got none")
        vertices, normals, faces, face_instance, offset = [], [], [], [], 0
        for index, (part_vertices, part_normals, part_faces) in enumerate(parts):
            vertices.append(np.asarray(part_vertices, np.float32).reshape(-1, 3))
            normals.append(np.asarray(part_normals, np.float32).reshape(-1, 3))
            faces.append(np.asarray(part_faces, np.int64).reshape(-1, 3) + offset)
            face_instance.append(np.full(len(faces[-1]), index, np.int32))
            offset += len(vertices[-1])
        return cls(np.concatenate(vertices), np.concatenate(normals), np.concatenate(faces).astype(np.int32),
                   np.concatenate(face_instance))


class Instances:
    """Per-frame world poses and looks of the I instances of a MeshSet.

    rot (I, 3, 3) float32, pos (I, 3) float32 m: local → world (world = rot @ local + pos); color
    (I, 3) float32 in [0, 1]; seg (I,) int32: the id written to the segmentation image.
    """

    def __init__(self, rot, pos, color, seg):
        self.rot = _tensor("Instances", "rot", rot, torch.float32, (None, 3, 3))
        self.pos = _tensor("Instances", "pos", pos, torch.float32, (None, 3))
        self.color = _tensor("Instances", "color", color, torch.float32, (None, 3))
        self.seg = _tensor("Instances", "seg", seg, torch.int32, (None,))
        self.n = _rows("Instances", rot=self.rot, pos=self.pos, color=self.color, seg=self.seg)


class Spheres:
    """Particles / debug spheres: pos (N, 3) float32 m world, radius (N,) float32 m (> 0), color
    (N, 3) float32 in [0, 1], seg (N,) int32."""

    def __init__(self, pos, radius, color, seg):
        self.pos = _tensor("Spheres", "pos", pos, torch.float32, (None, 3))
        self.radius = _tensor("Spheres", "radius", radius, torch.float32, (None,))
        self.color = _tensor("Spheres", "color", color, torch.float32, (None, 3))
        self.seg = _tensor("Spheres", "seg", seg, torch.int32, (None,))
        self.n = _rows("Spheres", pos=self.pos, radius=self.radius, color=self.color, seg=self.seg)
        if self.n and self.radius.min() <= 0:
            raise InvalidInputError(f"Spheres: argument 'radius' must be > 0, got {float(self.radius.min())}")


class View:
    """A pinhole camera: pos, lookat, up (3,) world m; fov: vertical field of view, degrees; near, far
    m; res (width, height) pixels. The camera looks along −z of its frame, x right, y up (OpenGL);
    image rows go down. Pixel (column u, row v) centres sit at (u + 0.5, v + 0.5); the principal point
    is the image centre and the focal length f = (height / 2) / tan(fov / 2) pixels, so a camera-frame
    point (x, y, z) lands at (width / 2 + f·x/(−z), height / 2 − f·y/(−z))."""

    def __init__(self, pos, lookat, up, fov, near=0.05, far=100.0, res=(640, 480)):
        self.pos = self._vector("pos", pos)
        self.lookat = self._vector("lookat", lookat)
        self.up = self._vector("up", up)
        if not 0 < fov < 180:
            raise InvalidInputError(f"View: argument 'fov' must be in (0, 180) degrees, got {fov}")
        if not 0 < near < far < math.inf:
            raise InvalidInputError(f"View: arguments 'near', 'far' must satisfy 0 < near < far < inf, got "
                                    f"near={near}, far={far}")
        if len(res) != 2 or any(int(r) != r or r < 1 for r in res):
            raise InvalidInputError(f"View: argument 'res' must be (width, height) positive ints, got {res}")
        self.fov, self.near, self.far, self.res = float(fov), float(near), float(far), (int(res[0]), int(res[1]))
        self.rotation = self._rotation()

    @staticmethod
    def _vector(name, value):
        vector = np.asarray(value, np.float64).reshape(-1)
        if vector.shape != (3,) or not np.isfinite(vector).all():
            raise InvalidInputError(f"View: argument '{name}' must be 3 finite numbers, got {value!r}")
        return vector

    def _rotation(self):
        """(3, 3) world → camera rotation: rows are the camera's x (right), y (up), z (backwards) axes."""
        back = self.pos - self.lookat
        if np.linalg.norm(back) == 0:
            raise InvalidInputError(f"View: arguments 'pos' and 'lookat' must differ, got both {self.pos.tolist()}")
        back /= np.linalg.norm(back)
        right = np.cross(self.up, back)
        if np.linalg.norm(right) < 1e-9 * np.linalg.norm(self.up):
            raise InvalidInputError(f"View: argument 'up' must not be parallel to the view direction, got "
                                    f"up={self.up.tolist()}, pos - lookat={(self.pos - self.lookat).tolist()}")
        right /= np.linalg.norm(right)
        return np.stack([right, np.cross(back, right), back])

    @property
    def focal(self):
        """Focal length in pixels (square pixels)."""
        return self.res[1] / 2 / math.tan(math.radians(self.fov) / 2)

    @property
    def intrinsics(self):
        """(3, 3) pinhole matrix K for pixel coordinates with y down and the camera looking along +z
        (the computer-vision convention; camera frame there = diag(1, −1, −1) · this frame)."""
        return np.array([[self.focal, 0, self.res[0] / 2], [0, self.focal, self.res[1] / 2], [0, 0, 1]])

    @property
    def extrinsics(self):
        """(4, 4) world → camera transform (this camera frame: x right, y up, looking along −z)."""
        transform = np.eye(4)
        transform[:3, :3] = self.rotation
        transform[:3, 3] = -self.rotation @ self.pos
        return transform


class Rasterizer:
    """Renders Views of a MeshSet posed by Instances plus Spheres into numpy images of size res.

    res (width, height) pixels; light_dir (3,) world, towards the sun (need not be unit); ambient:
    the light every surface gets, the rest (1 − ambient) is Lambert's from the sun; background
    (3,) rgb in [0, 1] (Genesis's default). The z-buffer and scratch buffers are kept between
    renders and grow when a scene needs more. Shadows are not drawn: a shadow map is a second pass
    of every primitive from the sun, and rendering the KUKA + 10k particle scene from the sun into a
    512 × 512 map took as long as the 640 × 480 frame itself (the ground covers the whole map).
    """

    def __init__(self, res, light_dir=(0.4, 0.3, 1.0), ambient=0.3, background=(0.04, 0.08, 0.12)):
        require_init("Rasterizer")
        if len(res) != 2 or any(int(r) != r or r < 1 for r in res):
            raise InvalidInputError(f"Rasterizer: argument 'res' must be (width, height) positive ints, got {res}")
        self.res = (int(res[0]), int(res[1]))
        light = np.asarray(light_dir, np.float64).reshape(-1)
        if light.shape != (3,) or not np.linalg.norm(light) > 0:
            raise InvalidInputError(f"Rasterizer: argument 'light_dir' must be a non-zero 3-vector, got {light_dir!r}")
        if not 0 <= ambient <= 1:
            raise InvalidInputError(f"Rasterizer: argument 'ambient' must be in [0, 1], got {ambient}")
        self.light_dir, self.ambient = light / np.linalg.norm(light), float(ambient)
        self.background = np.asarray(background, np.float64).reshape(3)
        width, height = self.res
        self.keys = torch.empty((height, width), dtype=torch.int64, device=runtime.device)
        self._scratch = {}

    def _buffer(self, name, rows, dtype, tail=()):
        """A contiguous (max(rows, 1), *tail) scratch tensor, reallocated (larger) only when rows grows."""
        rows = max(rows, 1)
        buffer = self._scratch.get(name)
        if buffer is None or buffer.shape[0] < rows:
            buffer = self._scratch[name] = torch.empty((max(rows, 3 * rows // 2),) + tail, dtype=dtype,
                                                       device=runtime.device)
        return buffer[:rows]

    def _params(self, view):
        """The kernels' float32 parameter vector (layout: the EYE... constants)."""
        params = np.empty(N_PARAMS, np.float32)
        params[EYE:EYE + 3] = view.pos
        params[ROT:ROT + 9] = view.rotation.reshape(-1)
        params[[FOCAL, CX, CY, NEAR, FAR]] = view.focal, view.res[0] / 2, view.res[1] / 2, view.near, view.far
        params[LIGHT:LIGHT + 3] = view.rotation @ self.light_dir  # shading is done in the camera frame
        params[AMBIENT] = self.ambient
        params[BACKGROUND:BACKGROUND + 3] = self.background
        return torch.from_numpy(params).to(runtime.device)

    def render(self, view, meshes=None, instances=None, spheres=None, rgb=True, depth=False, segmentation=False,
               normal=False):
        """Render view. meshes (MeshSet) and instances (Instances, at least meshes.n_instances) go
        together and may both be None; spheres (Spheres) may be None.

        Returns a dict of fresh numpy arrays for what was asked: "rgb" (H, W, 3) uint8; "depth" (H, W)
        float32 m along the view axis, +inf where nothing is drawn; "segmentation" (H, W) int32, −1
        where nothing is drawn; "normal" (H, W, 3) float32 world-frame unit normals of the visible
        side, 0 where nothing is drawn.
        """
        self._check(view, meshes, instances, spheres)
        frame = dict(self._mesh_args(meshes, instances), **self._sphere_args(spheres), params=self._params(view),
                     n_faces=meshes.n_faces if meshes is not None else 0,
                     n_vertices=meshes.vertices.shape[0] if meshes is not None else 0,
                     n_spheres=spheres.n if spheres is not None else 0)
        self._transform(frame)
        self._bin(frame)
        _raster(frame["n_tiles"], frame["n_faces"], frame["params"], frame["faces"], frame["cam_vertices"],
                frame["cam_spheres"], frame["radius"], frame["prim_box"], frame["prim_tiles"], frame["prim_end"],
                frame["tile_prim"], self.keys)
        return self._resolve(frame, dict(rgb=rgb, depth=depth, segmentation=segmentation, normal=normal))

    def _transform(self, frame):
        """Vertices, normals and sphere centres to the camera frame: adds them to frame (a render's
        tensors and counts, by name)."""
        frame["cam_vertices"] = self._buffer("cam_vertices", frame["n_vertices"], torch.float32, (3,))
        frame["cam_normals"] = self._buffer("cam_normals", frame["n_vertices"], torch.float32, (3,))
        frame["cam_spheres"] = self._buffer("cam_spheres", frame["n_spheres"], torch.float32, (3,))
        _transform(frame["n_vertices"], frame["n_spheres"], frame["params"], frame["vertices"], frame["normals"],
                   frame["vertex_instance"], frame["rot"], frame["pos"], frame["sphere_pos"], frame["cam_vertices"],
                   frame["cam_normals"], frame["cam_spheres"])

    def _bin(self, frame):
        """Clear the z-buffer, bound every primitive and list the tiles covering them: adds the
        primitives' boxes, tile counts and their prefix sums, the faces' shading, the tiles'
        primitives and their number to frame."""
        n_prims = frame["n_faces"] + frame["n_spheres"]
        prim_box = frame["prim_box"] = self._buffer("prim_box", n_prims, torch.int32, (4,))
        prim_tiles = frame["prim_tiles"] = self._buffer("prim_tiles", n_prims, torch.int32)
        prim_end = frame["prim_end"] = self._buffer("prim_end", n_prims, torch.int32)
        frame["face_shading"] = self._buffer("face_shading", frame["n_faces"], torch.float32, (4,))
        _setup(frame["n_faces"], frame["n_spheres"], self.res[0], self.res[1], frame["params"], frame["faces"],
               frame["cam_vertices"], frame["cam_normals"], frame["cam_spheres"], frame["radius"], prim_box, prim_tiles,
               frame["face_shading"], self.keys)
        frame["n_tiles"] = 0
        if n_prims:
            torch.cumsum(prim_tiles[:n_prims], 0, dtype=torch.int32, out=prim_end[:n_prims])
            frame["n_tiles"] = int(prim_end[n_prims - 1])  # on CUDA, the frame's one wait for the device
        frame["tile_prim"] = self._buffer("tile_prim", frame["n_tiles"], torch.int32)
        _list_tiles(n_prims, prim_tiles, prim_end, frame["tile_prim"])

    def _resolve(self, frame, wanted):
        """Run the resolve pass into fresh output tensors; the numpy arrays asked for (wanted: name → bool)."""
        width, height = self.res
        shapes = dict(rgb=((3,), torch.uint8), depth=((), torch.float32), segmentation=((), torch.int32),
                      normal=((3,), torch.float32))
        outputs = {name: torch.empty(((height, width) if wanted[name] else (1, 1)) + tail, dtype=dtype,
                                     device=runtime.device) for name, (tail, dtype) in shapes.items()}
        _resolve(width, height, frame["n_faces"], int(bool(wanted["rgb"])), int(bool(wanted["depth"])),
                 int(bool(wanted["segmentation"])), int(bool(wanted["normal"])), frame["params"], self.keys,
                 frame["faces"], frame["cam_vertices"], frame["cam_normals"], frame["face_shading"],
                 frame["face_instance"], frame["color"], frame["seg"], frame["cam_spheres"], frame["radius"],
                 frame["sphere_color"], frame["sphere_seg"], outputs["rgb"], outputs["depth"], outputs["segmentation"],
                 outputs["normal"])
        return {name: outputs[name].cpu().numpy() for name in shapes if wanted[name]}

    def _check(self, view, meshes, instances, spheres):
        """Clear errors for arguments of the wrong kind or that do not fit together."""
        kinds = dict(view=(view, View, False), meshes=(meshes, MeshSet, True), instances=(instances, Instances, True),
                     spheres=(spheres, Spheres, True))
        for name, (value, kind, optional) in kinds.items():
            if not isinstance(value, kind) and not (optional and value is None):
                raise InvalidInputError(f"Rasterizer.render: argument '{name}' must be a {kind.__name__}"
                                        f"{' or None' if optional else ''}, got {type(value).__name__}")
        if view.res != self.res:
            raise InvalidInputError(f"Rasterizer.render: argument 'view' must have res {self.res} (the rasterizer's),"
                                    f" got {view.res}")
        if (meshes is None) != (instances is None):
            raise InvalidInputError(f"Rasterizer.render: arguments 'meshes' and 'instances' must both be given or both"
                                    f" be None, got {type(meshes).__name__} and {type(instances).__name__}")
        if meshes is not None and instances.n < meshes.n_instances:
            raise InvalidInputError(f"Rasterizer.render: argument 'instances' must hold at least the "
                                    f"{meshes.n_instances} instances the MeshSet uses, got {instances.n}")

    def _mesh_args(self, meshes, instances):
        """The mesh and instance tensors the kernels take, by name; one-row stand-ins when there are none."""
        if meshes is None:
            return self._stand_ins("mesh", vertices=(3,), vertex_instance=(), faces=(3,), normals=(3,),
                                   face_instance=(), rot=(3, 3), pos=(3,), color=(3,), seg=())
        return dict(vertices=meshes.vertices, vertex_instance=meshes.vertex_instance, faces=meshes.faces,
                    normals=meshes.normals, face_instance=meshes.face_instance, rot=instances.rot, pos=instances.pos,
                    color=instances.color, seg=instances.seg)

    def _sphere_args(self, spheres):
        """The sphere tensors the kernels take, by name; one-row stand-ins when there are none."""
        if spheres is None or spheres.n == 0:
            return self._stand_ins("sphere", sphere_pos=(3,), radius=(), sphere_color=(3,), sphere_seg=())
        return dict(sphere_pos=spheres.pos, radius=spheres.radius, sphere_color=spheres.color, sphere_seg=spheres.seg)

    def _stand_ins(self, kind, **tails):
        """One-row tensors of the given trailing shapes (int32 for indices and ids, else float32), for
        kernels' arguments that a count of 0 keeps them from reading."""
        integer = {"vertex_instance", "faces", "face_instance", "seg", "sphere_seg"}
        return {name: self._buffer(f"{kind}_{name}", 1, torch.int32 if name in integer else torch.float32, tail)
                for name, tail in tails.items()}
