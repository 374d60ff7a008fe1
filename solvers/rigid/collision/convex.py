"""Convex narrow phase: MuJoCo 4.0's native GJK + EPA ("nativeccd") and its contact rules.

MuJoCo sends these pairs (its table mjCOLLISIONFUNC) to the general convex colliders:
sphere-mesh, capsule-cylinder, capsule-mesh, cylinder-cylinder, cylinder-box, cylinder-mesh,
box-mesh and mesh-mesh to `convex_convex` (MuJoCo's mjc_Convex), plane-mesh to `plane_mesh`
(mjc_PlaneConvex). The oracle is the installed MuJoCo 4.0.0, whose nativeccd differs from the
3.12 sources we hold (changelog 4.0.0 item 27, "improved numerical stability of nativeccd and
multiccd"): where they differ, the GJK, the margin handling, the contact budgets and plane-mesh
below follow 4.0's compiled code (read from libmujoco.so's disassembly); EPA follows the 3.12
sources, the polytope clipping 3.12's with three of the four rules 4.0 changed (item 3, measured).

1. GJK on the Minkowski difference of two support functions, from the geom centres; the next
   iterate is the origin's exact projection on the simplex's line or plane. With a sphere or a
   capsule, or a margin, GJK first measures the distance between the cores (sphere -> point,
   capsule -> segment, margins removed); if they are apart the contact is their closest-point
   pair moved out by the radii and half margins (shallow contact).
2. Otherwise GJK decides intersection, and EPA grows GJK's final simplex into a polytope around
   the origin (a hexahedron from a segment, a bipyramid from a triangle, the tetrahedron itself)
   and expands it toward the face nearest the origin: penetration depth, normal and one witness
   point per geom. Where it stops at its iteration budget, or fails, with a sphere's centre in a
   mesh's hull, the contact is the exact one through the hull's nearest facet instead
   (`_sphere_in_mesh`; MuJoCo keeps its truncated iterate, which depends on its own hull data).
3. Boxes and meshes (budget 4) clip two facing faces, or an edge along a face, found from the
   final EPA face's features: up to 4 contacts (the largest quadrilateral of the clipped
   polygon): MuJoCo's multicontact, as measured against MuJoCo 4.0 (its source was not at hand;
   GJK and EPA agree with it, the rest with 3.12's, which a numpy port matched to 1e-14), where
   4.0 differs from 3.12 in four rules: the most opposed pair of face normals within the
   tolerance (3.12: the first pair); witnesses on both faces' planes (3.12: the clipped point and
   dist d; not taken: `_clip_witnesses` says why); when geom 1's edge is parallel to none of geom 2's faces and
   geom 2's feature is an edge or a vertex too, geom 2's edge against geom 1's faces (3.12: the EPA contact
   alone); and the quad's area is the diagonals' (`_quad_area`). A numpy reference of the four
   rules matched 4.0's contact sets in 3840 of 3840 random poses of two pybullet_data meshes
   (finger tips, ducks, at MuJoCo's hull data). With all four this collider had 4.0's counts in
   240 of 240 and its contacts in its order in 226 (in the rest a clipped edge's two points come
   in the other order); with the three kept, 4.0's counts in 240 and its contacts in 119 (a face
   on face's points 5e-5 to 1e-3 m off); 3.12's rules: counts in 207, contacts in 99.
   Capsules (budget 2) and cylinders (budget 4) get one contact here: MuJoCo 4.0's multi-contact
   for them (and for margins, through the shallow path) is not reproduced; but a
   cylinder standing on a box's face, a mesh's face or a wider cylinder's cap gets four rim points
   of its own form (a box's face within the cap its four corners), one lying on a box's face the
   two ends of its side's line (`_face_cap`); a capsule or cylinder lying on a mesh's face the two
   ends of its line clipped to the face, each a KIND_CORE contact against the face's plane or the
   edge it crosses (`_lying_on_mesh`).

A contact is emitted when dist < margin; its position is the midpoint of the witness points, its
normal points from geom 1 to geom 2 (MuJoCo's convention).

Data. Meshes are convex hulls stored flat (`MeshHulls`, names prefixed hull_): vertices in the
geom frame, the hull's vertex graph (hill climbing), its polygons (coplanar triangles merged)
and per vertex the polygons holding it. Exact agreement with MuJoCo needs MuJoCo's own hull data
(its mesh frame, float32 vertices, qhull's graph order that breaks support ties):
`hulls_from_mujoco` reads it from a compiled MjModel, `mesh_hull` builds the same structure
with trimesh (`pack_hulls` packs several). The GJK simplex, EPA polytope and clipping buffers
live in a per-env workspace (`SCRATCH`: arrays ccd_v, ccd_f, ccd_i indexed [row..., k]); Taichi's
compile time grows with (local array size) x (runtime-indexed accesses): no large local arrays.

Compile time. Everything is inlined and each heavy piece appears once in the code (one support
call per GJK and per EPA loop, one face attachment, one clipping loop). Taichi's CFG
optimisation is still superlinear on it: a kernel calling convex_convex compiles in 156 s with
default options, 11 s with `cfg_optimization=False` (gs.init turns it off for every kernel). The
replay's vertex lookups run in loops for the same reason: a kernel calling convex_evaluate_adjoint
(plane_mesh's beside it) compiles in about 5 s, one calling convex_evaluate in about 2.5 s.

Features (what a backward needs to replay a contact as a closed form of the two poses), one row
of FEATURE_SIZE ints per contact, column 0 the kind; columns 8, 9 hold the forward's contact
normal (of the EPA contact for KIND_CLIP), coded in two ints (octahedral map, ~1e-9 rad):
- KIND_CORE (shallow sphere/capsule/margin contact): columns 1..6 = (id on geom 1, id on geom 2)
  of the final GJK simplex vertices (closest points of the cores), column 7 = their number.
- KIND_EPA: columns 1..6 = (id on geom 1, id on geom 2) of the three vertices of the final EPA
  face (the contact is the projection of the origin on that Minkowski triangle), column 7 = 3.
  Ids: box corner (bit 0: +x, bit 1: +y, bit 2: +z), mesh vertex (mesh-local), 1 / 0 for the
  +z / -z end of a segment, capsule or cylinder, -1 for a sphere's centre. Column 10 (CORE and
  EPA): how each cylinder meets the contact, mode1 + 3 mode2: 0 rim, 1 cap (normal along its
  axis), 2 side (normal across it).
- KIND_CLIP (face/edge clipping): column 1 = clipping face (box face 0..5 = +x,-x,+y,-y,+z,-z, or
  mesh polygon id), column 2 = clipped face (-1 for an edge); columns 3, 4 = the two lines that
  meet at the point (k < 256: edge k -> k+1 of the clipped polygon, 256 + e: side plane e of the
  clipping face, through its edge e -> e+1 and along its normal); columns 5, 6 = the clipped
  edge's vertex ids (-1 for face on face); column 7 = 0 face on face, 1 an edge of geom 1
  clipped by a face of geom 2, 2 an edge of geom 2 clipped by a face of geom 1; column 10 = 1
  when the edge's far end is an EPA support point too (its near end always is: with a margin
  both sit half of it out). The point lies on the clipped feature; the other witness is it
  moved by |dist| against the clipping face's normal, dist = (point - clipping face vertex 0) .
  normal.
- KIND_PLANE (plane-mesh): column 1 = mesh vertex id (the contact is that vertex, moved half its
  depth along the plane normal).
- KIND_FACE_CAP (a cylinder standing on a box's face, a mesh's face or a cylinder's cap,
  `_face_cap`): column 1 = the face (0..5 = +x, -x, +y, -y, +z, -z; a cylinder's caps 4, 5; a
  mesh's polygon id, its axes `_face_frame`'s), column 2 = the rim point
  (0..3 = +u, -u, +v, -v: the face's in-plane axes made perpendicular to the standing axis; 4 =
  LYING, an end of a lying cylinder's side line), column 3 = 1 when that axis is flipped to point
  at the face (lying: the end), column 4 = 1 when the standing cylinder is geom 2, column 5 = EDGE
  (1) when the point is the cap's point under the face's edge (the face ends inside the rim; on a
  mesh, column 6 the edge: from the polygon's vertex at that position to the next; on a
  cylinder's cap, its rim where the point's ray leaves it); or
  column 2 = CORNER (5), column 5 the corner k (at the signs 1 - 2 (k % 2) of the face's first
  in-plane half extent, 1 - 2 (k // 2) of its second) of a box's face within the cap, or the
  position in a mesh polygon's vertex list of its vertex within the cap; or column 2
  = TOWARD (6), the rim point toward the face's centre.

Replay. `convex_evaluate` and `plane_mesh_evaluate` give a contact again from its feature row
as a closed form of the two geom poses; `convex_evaluate_adjoint` and
`plane_mesh_evaluate_adjoint` are those closed forms' hand-written reverses (the colliders never
call them: a backward's kernel does, per contact; and the forward's detect.converge_contacts
makes an iterate on curved supports (`iterated`) its closed form, unless `frozen`). Where the
forward computes the contact from discrete points only (plane-mesh, clipping, GJK between
points, segments, boxes and meshes, EPA between boxes and meshes without margin) the replay is
the forward's own value to rounding. Where the forward iterates on curved supports (EPA with a
sphere, capsule or margin, whose balls it samples at a few directions; any cylinder; a clipped
edge's ends with a margin) the replay is the converged contact those iterations approach, within
the CCD tolerance's effect of the forward (1e-5 m typical, 4e-3 m and 3e-2 rad in the normal at
deep random poses with cylinders): each geom is a core (point, segment, box, mesh) swept by a
ball (sphere and capsule radius, half the margin, a cylinder's disk on its side), or for a
cylinder at its rim by its disk; the normal is the plane normal of the feature's Minkowski
points, else the direction between the cores' closest points. Two cylinder features have forms
of their own: on its cap (`_cap_terms`) the normal is its axis and the point the foot of the
cap's centre on the other geom's feature, where the iterate's point is anywhere on the cap; at
its rim against a vertex, an edge (`_rim_terms`) or another rim (`_rims_terms`) the contact is
where the rim's circle comes closest to that point, line or circle (Newton on the circles'
angles, converged to round-off; the reverse by implicit differentiation). The iterate stays where
no form here is the converged contact (`frozen`: a clipped edge's ends with a margin, offset
along the EPA normal; two cylinders at their rims with both ends of each in the feature) or
where the form is not finite or Newton did not converge.
"""
import numpy as np
import taichi as ti
from taichi.lang import impl

from ... import asset_cache
from ...core import AssetError

# MuJoCo geom type codes (mjtGeom), and two internal "cores": sphere -> point, capsule -> segment
PLANE, HFIELD, SPHERE, CAPSULE, CYLINDER, BOX, MESH = 0, 1, 2, 3, 5, 6, 7
_POINT, _SEGMENT = 100, 101

CCD_ITERATIONS = 35      # mjOption.ccd_iterations (MuJoCo's default): GJK and EPA iterations
CCD_TOLERANCE = 1e-6     # mjOption.ccd_tolerance (MuJoCo's default), m
CONVEX_MAX = 4           # contact budget of convex_convex (MuJoCo 4.0: 4, or 2 with a capsule, 1 with a sphere)
PLANE_MESH_MAX = 4       # contact budget of plane_mesh (MuJoCo 4.0)
# the pairs (type 1, type 2) MuJoCo sends to mjc_Convex, i.e. to convex_convex, and their contact
# budgets in MuJoCo 4.0 (the rule of `_budget`: 1 with a sphere, 2 with a capsule, else 4)
CONVEX_BUDGET = {(SPHERE, MESH): 1, (CAPSULE, CYLINDER): 2, (CAPSULE, MESH): 2, (CYLINDER, CYLINDER): 4,
                 (CYLINDER, BOX): 4, (CYLINDER, MESH): 4, (BOX, MESH): 4, (MESH, MESH): 4}
CONVEX_PAIRS = tuple(CONVEX_BUDGET)
FEATURE_SIZE = 11
KIND_CORE, KIND_EPA, KIND_CLIP, KIND_PLANE, KIND_FACE_CAP = 1, 2, 3, 4, 5
POLYGON_MAX = 32         # vertices of a mesh polygon multi-contact can use (larger: single contact)

# workspace layout (one row per env): 3-vectors, floats, ints
_VERTS = 5 + CCD_ITERATIONS          # EPA polytope vertices (MuJoCo's bound); GJK uses slots 0..7
_FACES = 2 * _VERTS - 4              # live faces of a closed triangulated polytope (slots reused)
_HORIZON = 24                        # MuJoCo's horizon buffer
_CLIP = 2 * POLYGON_MAX              # a polygon clipped by a convex one has at most both counts
_V_VERT, _V_VERT1, _V_VERT2 = 0, _VERTS, 2 * _VERTS          # Minkowski vertex, geom-1, geom-2 point
_V_FACE = 3 * _VERTS                                         # face: projection of the origin
_V_CLIP = _V_FACE + _FACES                                   # clipping face's vertices
_V_SIDE = _V_CLIP + POLYGON_MAX                              # clipping face's side-plane normals
_V_POLY = _V_SIDE + POLYGON_MAX                              # clipped polygon, two buffers
_F_DIST2, _F_SIDE = 0, _FACES                                # face: squared distance; side offsets
_I_ID1, _I_ID2 = 0, _VERTS                                   # vertex ids on geom 1, 2
_I_FVERTS, _I_FADJ, _I_FINDEX = 2 * _VERTS, 2 * _VERTS + _FACES, 2 * _VERTS + 2 * _FACES
_I_MAP, _I_FREE, _I_STACK = _I_FINDEX + _FACES, _I_FINDEX + 2 * _FACES, _I_FINDEX + 3 * _FACES
_I_NEW = _I_STACK + _FACES                                   # faces to attach: verts, adjacency, slot
_I_TAG = _I_NEW + 3 * _HORIZON                               # clipped points' lines (2 per point)
_V_WIT = _V_POLY + 2 * _CLIP                                 # one run's witness points: 4 + 4
_F_WIT = _F_SIDE + POLYGON_MAX                               # their distances
_I_WIT = _I_TAG + 4 * _CLIP                                  # their features (4 x FEATURE_SIZE)
SCRATCH = {"ccd_v": ("v3", _V_WIT + 8), "ccd_f": ("f", _F_WIT + 4), "ccd_i": ("i", _I_WIT + 4 * FEATURE_SIZE)}

_MINVAL = 1e-15                     # mjMINVAL
_MINVAL2 = _MINVAL * _MINVAL
_BIG = 1e30                         # "no value" (MuJoCo: DBL_MAX)
_FLT_MAX = 3.4028234663852886e38    # MuJoCo's exhaustive mesh search starts at -FLT_MAX
_GJK_EPS = 0.5 * (CCD_TOLERANCE * CCD_TOLERANCE)
_OCTAHEDRAL = 1073741824.0          # 2^30: scale of a unit vector's two-int code (encode_direction)
_AXIS_TOL = 1e-9                    # a normal this close to a cylinder's axis (across it): on its cap (side)
_FACE_TOL = 0.996                   # faces aligned within ~5.1 deg
_EDGE_TOL = 0.0888                  # edge parallel to a face within ~5.1 deg
# initial polytopes, one face per entry: vertices (a, b, c), neighbours across ab, bc, ca
_TETRA = ((0, 1, 2, 1, 3, 2), (0, 3, 1, 2, 3, 0), (0, 2, 3, 0, 3, 1), (3, 2, 1, 2, 0, 1))
_HEXA = ((0, 2, 3, 1, 3, 2), (0, 4, 2, 2, 4, 0), (0, 3, 4, 0, 5, 1),
         (1, 3, 2, 5, 0, 4), (1, 2, 4, 3, 1, 5), (1, 4, 3, 4, 2, 3))
_BIPYRAMID = ((4, 0, 1, 1, 3, 2), (4, 2, 0, 2, 4, 0), (4, 1, 2, 0, 5, 1),
              (3, 1, 0, 5, 0, 4), (3, 0, 2, 3, 1, 5), (3, 2, 1, 4, 2, 3))
# box faces 0..5 as 4 corner ids each (bit 0: +x, bit 1: +y, bit 2: +z), in MuJoCo's order, 3 bits a corner
_BOX_FACES = tuple(a | b << 3 | c << 6 | d << 9 for a, b, c, d in
                   ((7, 3, 1, 5), (2, 6, 4, 0), (2, 3, 7, 6), (4, 5, 1, 0), (6, 7, 5, 4), (3, 2, 0, 1)))


# ----------------------------------------------------------------------------- mesh hull data

class MeshHulls:
    """Convex hulls of all meshes of a model, flat numpy arrays (geom frame, m).

    Per mesh m: vertices hull_vert[hull_vertadr[m] + v], v < hull_vertnum[m] (mesh-local ids v
    below); hull_climb[m] (1: supports hill-climb the graph, as MuJoCo for meshes of >= 10
    vertices; 0: exhaustive scan); hull_extrema[27 m + k] (hill-climb seed for each direction
    cell (cx, cy, cz) of {-1, 0, 1}^3, k = 9 (cx + 1) + 3 (cy + 1) + cz + 1).
    Per vertex (absolute index): hull_edgeadr (start of its neighbour list in hull_edge, ended by
    -1; -1 if not on the hull), hull_vert_polyadr, hull_vert_polynum (its polygons in
    hull_polymap, mesh-local polygon ids).
    Per polygon p (absolute = hull_polyadr[m] + local id, hull_polynum[m] of them):
    hull_poly_vertadr[p], hull_poly_vertnum[p] (its vertex ids in hull_poly_vert, counter-
    clockwise seen from outside), hull_poly_normal[p] (outward unit normal).
    """

    FIELDS = ("hull_vert", "hull_vertadr", "hull_vertnum", "hull_climb", "hull_extrema",
              "hull_edgeadr", "hull_edge", "hull_polyadr", "hull_polynum", "hull_poly_vertadr",
              "hull_poly_vertnum", "hull_poly_vert", "hull_poly_normal", "hull_vert_polyadr",
              "hull_vert_polynum", "hull_polymap")

    def __init__(self, **arrays):
        for name in self.FIELDS:
            setattr(self, name, np.asarray(arrays[name]))


# MeshHulls' int arrays, in the order the rigid model packs them into one array (geometry.py): a
# header of HULL_HEADER slots (where each starts, then where the polygon normals start among the
# model's 3-vectors) followed by the arrays
HULL_INT_FIELDS = tuple(name for name in MeshHulls.FIELDS if name not in ("hull_vert", "hull_poly_normal"))
HULL_HEADER = len(HULL_INT_FIELDS) + 1


def _extrema(vertices: np.ndarray, hull_ids: list) -> list:
    """Hill-climb seeds: for each cell (cx, cy, cz) of {-1, 0, 1}^3 the first hull vertex with
    the largest projection on (cx, cy, cz), as MuJoCo's mesh_extrema."""
    cells = np.array([(cx, cy, cz) for cx in (-1, 0, 1) for cy in (-1, 0, 1) for cz in (-1, 0, 1)])
    return [hull_ids[int(i)] for i in np.argmax(vertices[hull_ids] @ cells.T, axis=0)]


def _outline(faces: np.ndarray) -> list:
    """Vertex cycle around a group of coplanar, consistently wound triangles."""
    directed = {(int(f[i]), int(f[(i + 1) % 3])) for f in faces for i in range(3)}
    follow = {a: b for a, b in directed if (b, a) not in directed}
    cycle = [min(follow)]
    while follow[cycle[-1]] != cycle[0]:
        cycle.append(follow[cycle[-1]])
    return cycle


def pack_hulls(meshes: list) -> MeshHulls:
    """Concatenate per-mesh dicts (vert, climb, extrema, neighbours, polygons, normals: mesh_hull's)
    into one MeshHulls."""
    out = {name: [] for name in MeshHulls.FIELDS}
    for mesh in meshes:
        vert_base, poly_base = len(out["hull_vert"]), len(out["hull_poly_vertadr"])
        nvert = len(mesh["vert"])
        out["hull_vert"].extend(mesh["vert"])
        out["hull_vertadr"].append(vert_base)
        out["hull_vertnum"].append(nvert)
        out["hull_climb"].append(int(mesh["climb"]))
        out["hull_extrema"].extend(mesh["extrema"])
        out["hull_polyadr"].append(poly_base)
        out["hull_polynum"].append(len(mesh["polygons"]))
        vert_polys = [[] for _ in range(nvert)]
        for p, polygon in enumerate(mesh["polygons"]):
            out["hull_poly_vertadr"].append(len(out["hull_poly_vert"]))
            out["hull_poly_vertnum"].append(len(polygon))
            out["hull_poly_vert"].extend(polygon)
            out["hull_poly_normal"].append(mesh["normals"][p])
            for v in polygon:
                vert_polys[v].append(p)
        for v in range(nvert):
            neighbours = mesh["neighbours"].get(v)
            out["hull_edgeadr"].append(-1 if neighbours is None else len(out["hull_edge"]))
            if neighbours is not None:
                out["hull_edge"].extend(list(neighbours) + [-1])
            out["hull_vert_polyadr"].append(len(out["hull_polymap"]))
            out["hull_vert_polynum"].append(len(vert_polys[v]))
            out["hull_polymap"].extend(vert_polys[v])
    arrays = {name: np.array(values, dtype=np.int32) for name, values in out.items()}
    for name in ("hull_vert", "hull_poly_normal"):
        arrays[name] = np.array(out[name], dtype=np.float64).reshape(-1, 3)
    return MeshHulls(**arrays)


def mesh_hull(vertices) -> dict:
    """The convex hull (trimesh's, qhull) of (V, 3) vertices (geom frame, m), as ``pack_hulls`` takes it:
    the hull's vertices only; coplanar hull triangles merged into polygons (trimesh's facets), wound
    counter-clockwise seen from outside. Kept in the asset cache, by the vertices' bits. Raises
    AssetError when the hull has no volume (flat or degenerate input)."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    return asset_cache.load_or_compute("hull", [vertices.tobytes()], lambda: (_hull(vertices), ()),
                                       (__file__,), ("trimesh", "scipy", "networkx", "numpy"))


def _hull(vertices: np.ndarray) -> dict:
    """mesh_hull, computed."""
    import trimesh  # (imported when first needed: with scipy it takes ~0.6 s)

    try:
        check = trimesh.convex.convex_hull(vertices)
    except Exception as error:  # qhull raises its own error types on flat or degenerate input
        raise AssetError(f"mesh expected a convex hull with volume, got a degenerate one ({error})") from None
    if len(check.vertices) < 4 or not check.volume > 0:
        raise AssetError(f"mesh expected a convex hull with volume, got {len(check.vertices)} vertices and "
                         f"volume {check.volume}")
    hull = trimesh.Trimesh(vertices=vertices).convex_hull
    vert, faces = np.asarray(hull.vertices), np.asarray(hull.faces)
    in_facet = np.zeros(len(faces), dtype=bool)
    polygons = []
    for facet in hull.facets:
        in_facet[facet] = True
        polygons.append(_outline(faces[facet]))
    polygons += [[int(i) for i in f] for f in faces[~in_facet]]
    normals = []
    for polygon in polygons:
        # a merged facet's normal from all its vertices (Newell's sum about their mean): its first three
        # can lie nearly on one line, and a top 3 µm off flat then gave one 6e-4 rad off (a can's rim
        # points 0.18 mm deep) or 90°
        points = vert[polygon] - vert[polygon].mean(axis=0)
        normal = np.cross(points, np.roll(points, -1, axis=0)).sum(axis=0) if len(polygon) > 3 else np.cross(
            vert[polygon[1]] - vert[polygon[0]], vert[polygon[2]] - vert[polygon[0]])
        normals.append(normal / np.linalg.norm(normal))
    return dict(vert=vert, climb=len(vert) >= 10, extrema=_extrema(vert, list(range(len(vert)))),
                neighbours={v: sorted(n) for v, n in enumerate(hull.vertex_neighbors)},
                polygons=polygons, normals=normals)


def hulls_from_mujoco(model) -> MeshHulls:
    """MeshHulls holding exactly MuJoCo's compiled mesh data (vertices in MuJoCo's mesh frame,
    float32 values, its qhull graph, polygons and extrema): for parity tests against MuJoCo."""
    packed = []
    extrema_all = np.asarray(model.mesh_extrema).reshape(-1)
    for m in range(model.nmesh):
        adr, num = model.mesh_vertadr[m], model.mesh_vertnum[m]
        vert = np.asarray(model.mesh_vert[adr:adr + num], dtype=np.float64)
        graph = model.mesh_graph[model.mesh_graphadr[m]:]
        nhull = graph[0]
        edgeadr, globalid, edges = graph[2:2 + nhull], graph[2 + nhull:2 + 2 * nhull], graph[2 + 2 * nhull:]
        neighbours = {}
        for local in range(nhull):
            ids, i = [], edgeadr[local]
            while edges[i] >= 0:
                ids.append(int(globalid[edges[i]]))
                i += 1
            neighbours[int(globalid[local])] = ids
        padr, pnum = model.mesh_polyadr[m], model.mesh_polynum[m]
        polygons = [list(model.mesh_polyvert[model.mesh_polyvertadr[p]:model.mesh_polyvertadr[p]
                                             + model.mesh_polyvertnum[p]]) for p in range(padr, padr + pnum)]
        packed.append(dict(vert=vert, climb=num >= 10,
                           extrema=[int(globalid[i]) for i in extrema_all[27 * m:27 * m + 27]],
                           neighbours=neighbours, polygons=polygons,
                           normals=list(model.mesh_polynormal[padr:padr + pnum])))
    hulls = pack_hulls(packed)
    # MuJoCo's polygon map, in its own order (mesh-local polygon ids)
    hulls.hull_polymap = np.asarray(model.mesh_polymap, dtype=np.int32)
    hulls.hull_vert_polyadr = np.asarray(model.mesh_polymapadr, dtype=np.int32)
    hulls.hull_vert_polynum = np.asarray(model.mesh_polymapnum, dtype=np.int32)
    return hulls


# ----------------------------------------------------------------------------- small algebra
# Written out term by term in MuJoCo's evaluation order, so results agree to the last bit.

@ti.func
def _dot(a: ti.template(), b: ti.template()):
    """a . b for 3-vectors, summed left to right."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@ti.func
def _cross(a: ti.template(), b: ti.template()):
    """a x b for 3-vectors."""
    return ti.Vector([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


@ti.func
def _det3(a: ti.template(), b: ti.template(), c: ti.template()):
    """Determinant of the 3x3 matrix with columns a, b, c: a . (b x c)."""
    return (a[0] * (b[1] * c[2] - b[2] * c[1]) + a[1] * (b[2] * c[0] - b[0] * c[2])
            + a[2] * (b[0] * c[1] - b[1] * c[0]))


@ti.func
def _rot(rot: ti.template(), v):
    """rot @ v (geom frame -> world)."""
    return ti.Vector([rot[0, 0] * v[0] + rot[0, 1] * v[1] + rot[0, 2] * v[2],
                      rot[1, 0] * v[0] + rot[1, 1] * v[1] + rot[1, 2] * v[2],
                      rot[2, 0] * v[0] + rot[2, 1] * v[1] + rot[2, 2] * v[2]])


@ti.func
def _rot_t(rot: ti.template(), v):
    """rot^T @ v (world -> geom frame)."""
    return ti.Vector([rot[0, 0] * v[0] + rot[1, 0] * v[1] + rot[2, 0] * v[2],
                      rot[0, 1] * v[0] + rot[1, 1] * v[1] + rot[2, 1] * v[2],
                      rot[0, 2] * v[0] + rot[1, 2] * v[1] + rot[2, 2] * v[2]])


@ti.func
def _normalize(v):
    """v / |v| as MuJoCo's mju_normalize3 (times the inverse norm; (1, 0, 0) if |v| < 1e-15)."""
    norm = ti.sqrt(_dot(v, v))
    out = ti.Vector([1.0, 0.0, 0.0])
    if norm >= _MINVAL:
        out = v * (1.0 / norm)
    return out


@ti.func
def _sign(x):
    """1.0 for x >= 0, else -1.0."""
    return ti.select(x >= 0, 1.0, -1.0)


@ti.func
def encode_direction(unit):
    """Two ints coding a unit 3-vector (octahedral map, steps of 2^-30: ~1e-9 rad)."""
    p = unit / (ti.abs(unit[0]) + ti.abs(unit[1]) + ti.abs(unit[2]))
    x, y = p[0], p[1]
    if p[2] < 0:  # the lower half folds over the octahedron's edges
        x, y = (1.0 - ti.abs(p[1])) * _sign(p[0]), (1.0 - ti.abs(p[0])) * _sign(p[1])
    return int(ti.round(x * _OCTAHEDRAL)), int(ti.round(y * _OCTAHEDRAL))


@ti.func
def decode_direction(code_x, code_y):
    """The unit 3-vector of an `encode_direction` code."""
    x, y = code_x / _OCTAHEDRAL, code_y / _OCTAHEDRAL
    z = 1.0 - ti.abs(x) - ti.abs(y)
    if z < 0:
        x, y = (1.0 - ti.abs(y)) * _sign(x), (1.0 - ti.abs(x)) * _sign(y)
    return _normalize(ti.Vector([x, y, z]))


@ti.func
def _same_sign(a, b):
    """True when a and b are both > 0 or both < 0."""
    return (a > 0 and b > 0) or (a < 0 and b < 0)


@ti.func
def _wrap(i, n):
    """i mod n for 0 <= i < 2 n (Taichi's Python-style % costs much compile time)."""
    return i - n if i >= n else i


@ti.func
def _pick(i, values: ti.template()):
    """values[i] for a static tuple of int constants and a runtime i (a chain of selects)."""
    out = values[0]
    for j in ti.static(range(1, len(values))):
        out = ti.select(i == j, values[j], out)
    return out


def _packed(table):
    """Face table rows (a, b, c, adj_ab, adj_bc, adj_ca) as two tuples of packed ints."""
    return (tuple(a | b << 10 | c << 20 for a, b, c, *_ in table),
            tuple(x | y << 10 | z << 20 for *_, x, y, z in table))


# ----------------------------------------------------------------------------- workspace

@ti.func
def _vert(ws: ti.template(), row: ti.template(), slot):
    """Minkowski vertex (geom-1 point minus geom-2 point) in workspace slot `slot`."""
    return ws.ccd_v[row + (_V_VERT + slot,)]


@ti.func
def _put_vertex(ws: ti.template(), row: ti.template(), slot, p1, p2, id1, id2):
    """Store support points p1 (geom 1), p2 (geom 2) and their ids in workspace slot `slot`."""
    ws.ccd_v[row + (_V_VERT + slot,)] = p1 - p2
    ws.ccd_v[row + (_V_VERT1 + slot,)] = p1
    ws.ccd_v[row + (_V_VERT2 + slot,)] = p2
    ws.ccd_i[row + (_I_ID1 + slot,)] = id1
    ws.ccd_i[row + (_I_ID2 + slot,)] = id2


@ti.func
def _copy_vertex(ws: ti.template(), row: ti.template(), src, dst):
    """Copy workspace vertex slot src to slot dst."""
    _put_vertex(ws, row, dst, ws.ccd_v[row + (_V_VERT1 + src,)], ws.ccd_v[row + (_V_VERT2 + src,)],
                ws.ccd_i[row + (_I_ID1 + src,)], ws.ccd_i[row + (_I_ID2 + src,)])


@ti.func
def _combine(weights, ws: ti.template(), row: ti.template(), base, slot):
    """sum_s weights[s] * (3-vector at workspace base + slot[s]), s = 0..3, left to right."""
    out = weights[0] * ws.ccd_v[row + (base + slot[0],)]
    for s in ti.static(range(1, 4)):
        out = out + weights[s] * ws.ccd_v[row + (base + slot[s],)]
    return out


# ----------------------------------------------------------------------------- support functions
# A shape is the tuple (kind, mesh, pos, rot, size, margin): kind a geom type or a core, mesh the
# mesh id (-1 if none), pos (3,) m and rot (3, 3) its world pose, size MuJoCo's geom size, margin
# the pair margin (each shape grows by margin / 2). A height field's prism (kind HFIELD, hfield.py)
# is the triangular prism under one triangle of its grid: mesh its grid's number among the hulls
# (hfield.grid_hull: the grid's top vertices, then the same under the base), pos and rot the
# height field's pose, size the triangle's three top vertex ids (as floats, in MuJoCo's prism order).

@ti.func
def _mesh_support(mesh, local_dir, cache, hull: ti.template()):
    """Mesh vertex (mesh-local id) farthest along local_dir (geom frame), found as MuJoCo does:
    hill climbing from the better of the cached vertex and the direction cell's seed, or a scan
    of all vertices starting from the cached one; ties keep the vertex found first."""
    adr = hull.hull_vertadr[mesh]
    climb = hull.hull_climb[mesh]
    best, best_dot = 0, -_FLT_MAX
    if climb:
        cx = int(local_dir[0] > 0.4) - int(local_dir[0] < -0.4) + 1
        cy = int(local_dir[1] > 0.4) - int(local_dir[1] < -0.4) + 1
        cz = int(local_dir[2] > 0.4) - int(local_dir[2] < -0.4) + 1
        best = hull.hull_extrema[27 * mesh + cx * 9 + cy * 3 + cz]
        seed_dot = _dot(local_dir, hull.hull_vert[adr + best])
        if cache >= 0 and not seed_dot > _dot(local_dir, hull.hull_vert[adr + cache]):
            best = cache
        best_dot = _dot(local_dir, hull.hull_vert[adr + best])
    elif cache >= 0:
        best, best_dot = cache, _dot(local_dir, hull.hull_vert[adr + cache])
    # climbing: scan the neighbours of `base`, again from the new best while it moves;
    # exhaustive: scan every vertex once
    base = best
    cursor = hull.hull_edgeadr[adr + base] if climb else 0
    while True:
        candidate = cursor
        if climb:
            candidate = hull.hull_edge[cursor]
        if candidate < 0 or candidate >= hull.hull_vertnum[mesh]:
            if not (climb and best != base):
                break
            base = best
            cursor = hull.hull_edgeadr[adr + base]
        else:
            d = _dot(local_dir, hull.hull_vert[adr + candidate])
            if d > best_dot:
                best_dot, best = d, candidate
            cursor += 1
    return best


@ti.func
def _prism_support(grid, triangle, local_dir, hull: ti.template()):
    """Vertex id (in the height field's grid hull) of a prism farthest along local_dir (the
    height field's frame), as MuJoCo's mjc_prism_support: among the top triangle's three
    vertices (`triangle`, ids as floats), or the three under them on the base when local_dir
    points down; ties keep the first in MuJoCo's prism order."""
    adr, under = hull.hull_vertadr[grid], hull.hull_vertnum[grid] // 2
    base = ti.select(local_dir[2] < 0, under, 0)
    best = base + int(triangle[0])
    best_dot = _dot(local_dir, hull.hull_vert[adr + best])
    for k in ti.static(range(1, 3)):
        vid = base + int(triangle[k])
        d = _dot(local_dir, hull.hull_vert[adr + vid])
        if d > best_dot:
            best, best_dot = vid, d
    return best


@ti.func
def _centre(shape: ti.template(), hull: ti.template()):
    """Where GJK starts on a shape (world, m), MuJoCo's mjc_center: its geom's position; a
    prism's centroid (its six vertices' mean: base, then top)."""
    centre = shape[2]
    if shape[0] == HFIELD:
        adr, under = hull.hull_vertadr[shape[1]], hull.hull_vertnum[shape[1]] // 2
        total = ti.Vector([0.0, 0.0, 0.0])
        for k in ti.static(range(6)):
            total += hull.hull_vert[adr + ti.select(k < 3, under, 0) + int(shape[4][k % 3])]
        centre = _rot(shape[3], total * (1.0 / 6.0)) + shape[2]
    return centre


@ti.func
def _support(shape: ti.template(), direction, cache, hull: ti.template()):
    """Farthest point (world, m) of `shape` along the unit `direction`, and its discrete id
    (box corner bits, mesh vertex, a prism's vertex in its grid, 1 / 0 for the +z / -z end of a
    segment, capsule or cylinder; a sphere or point keeps `cache`, as MuJoCo's vertindex). Only a
    mesh reads `cache`."""
    kind, mesh, pos, rot, size, margin = shape
    point = pos
    feature = cache
    if kind == SPHERE:
        point = size[0] * direction + pos
    elif kind == _SEGMENT:
        along = rot[0, 2] * direction[0] + rot[1, 2] * direction[1] + rot[2, 2] * direction[2]
        half = ti.select(along >= 0, size[1], -size[1])
        point = ti.Vector([rot[0, 2] * half, rot[1, 2] * half, rot[2, 2] * half]) + pos
        feature = int(along >= 0)
    elif kind != _POINT:
        local_dir = _rot_t(rot, direction)
        positive = ti.Vector([int(local_dir[k] >= 0) for k in ti.static(range(3))])
        local = ti.Vector([ti.select(positive[0], size[0], -size[0]), ti.select(positive[1], size[1], -size[1]),
                           ti.select(positive[2], size[2], -size[2])])
        if kind == CAPSULE:
            local = local_dir * size[0]
            local[2] += ti.select(positive[2], size[1], -size[1])
            feature = positive[2]
        elif kind == CYLINDER:
            planar2 = local_dir[0] * local_dir[0] + local_dir[1] * local_dir[1]
            scale = ti.select(planar2 >= _MINVAL2, size[0] / ti.sqrt(planar2), 0.0)
            local = ti.Vector([scale * local_dir[0], scale * local_dir[1], ti.select(positive[2], size[1], -size[1])])
            feature = positive[2]
        elif kind == BOX:
            feature = positive[0] + 2 * positive[1] + 4 * positive[2]
        elif kind == MESH:
            feature = _mesh_support(mesh, local_dir, cache, hull)
            local = hull.hull_vert[hull.hull_vertadr[mesh] + feature]
        elif kind == HFIELD:
            feature = _prism_support(mesh, size, local_dir, hull)
            local = hull.hull_vert[hull.hull_vertadr[mesh] + feature]
        point = _rot(rot, local) + pos
    if margin > 0:
        point += direction * (0.5 * margin)
    return point, feature


@ti.func
def _pick_shape(first, shape1: ti.template(), shape2: ti.template()):
    """shape1 if `first` else shape2 (a run-time choice, field by field)."""
    return (ti.select(first, shape1[0], shape2[0]), ti.select(first, shape1[1], shape2[1]),
            ti.select(first, shape1[2], shape2[2]), ti.select(first, shape1[3], shape2[3]),
            ti.select(first, shape1[4], shape2[4]), ti.select(first, shape1[5], shape2[5]))


@ti.func
def _minkowski(shape1: ti.template(), shape2: ti.template(), direction, cache1, cache2, hull: ti.template()):
    """Support of the Minkowski difference along `direction`: the support points (world) of
    geom 1 along +direction and of geom 2 along -direction, and their ids. One `_support` in a
    loop over the two geoms, so that it is inlined once."""
    p1, p2 = ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0])
    ids = ti.Vector([cache1, cache2])
    for g in range(2):
        first = g == 0
        point, id_g = _support(_pick_shape(first, shape1, shape2), ti.select(first, direction, -direction),
                               ti.select(first, ids[0], ids[1]), hull)
        if first:
            p1, ids[0] = point, id_g
        else:
            p2, ids[1] = point, id_g
    return p1, p2, ids[0], ids[1]


@ti.func
def _discrete(shape1: ti.template(), shape2: ti.template()):
    """True when both shapes are polytopes (box, mesh or prism) without margin: GJK and EPA then
    converge exactly and use tolerance 0 / 1e-15."""
    return ((shape1[0] == BOX or shape1[0] == MESH or shape1[0] == HFIELD)
            and (shape2[0] == BOX or shape2[0] == MESH or shape2[0] == HFIELD) and shape1[5] == 0 and shape2[5] == 0)


# ----------------------------------------------------------------------------- GJK

@ti.func
def _project_origin_line(a, b):
    """Projection of the origin on the line through a and b (b if they coincide)."""
    diff = b - a
    length2 = _dot(diff, diff)
    out = b
    if length2 != 0:
        out = b + (-(_dot(b, diff) / length2)) * diff
    return out


@ti.func
def _project_origin_plane(a, b, c):
    """Projection of the origin on the plane of triangle (a, b, c), and 1 if the triangle is
    degenerate. The normal comes from the first of three edge pairs that is well conditioned."""
    d21, d31, d32 = b - a, c - a, c - b
    degenerate, done = 0, 0
    out = ti.Vector([0.0, 0.0, 0.0])
    for k in ti.static(range(3)):
        normal = _cross(d32, d21) if k == 0 else (_cross(d21, d31) if k == 1 else _cross(d31, d32))
        anchor = b if k == 0 else (a if k == 1 else c)
        if not done:
            nv, nn = _dot(normal, anchor), _dot(normal, normal)
            if nn == 0:
                degenerate, done = 1, 1
            elif k == 2 or (nv != 0 and nn > _MINVAL):
                out = normal * (nv / nn)
                done = 1
    return degenerate, out


@ti.func
def _s1d(a, b):
    """Barycentric weights (wa, wb) of the point of segment ab closest to the origin, from the
    projection's coordinate along the segment's longest axis (Montanari et al. 2017)."""
    p = _project_origin_line(a, b)
    mu_max, pa, pb, pp = a[0] - b[0], a[0], b[0], p[0]
    for k in ti.static(range(1, 3)):
        if ti.abs(a[k] - b[k]) >= ti.abs(mu_max):
            mu_max, pa, pb, pp = a[k] - b[k], a[k], b[k], p[k]
    c1, c2 = pp - pb, pa - pp
    weights = ti.Vector([0.0, 1.0])
    if _same_sign(mu_max, c1) and _same_sign(mu_max, c2):
        weights = ti.Vector([c1 / mu_max, c2 / mu_max])
    return weights


@ti.func
def _area_coords(a, b, c, p):
    """Signed areas (p b c, p c a, p a b) on the coordinate plane where triangle abc's projection
    is largest, and that projection's area (MuJoCo's S2D cofactors)."""
    m1 = b[1] * c[2] - b[2] * c[1] - a[1] * c[2] + a[2] * c[1] + a[1] * b[2] - a[2] * b[1]
    m2 = b[0] * c[2] - b[2] * c[0] - a[0] * c[2] + a[2] * c[0] + a[0] * b[2] - a[2] * b[0]
    m3 = b[0] * c[1] - b[1] * c[0] - a[0] * c[1] + a[1] * c[0] + a[0] * b[1] - a[1] * b[0]
    keep_yz = ti.abs(m1) >= ti.abs(m2) and ti.abs(m1) >= ti.abs(m3)
    keep_xz = not keep_yz and ti.abs(m2) >= ti.abs(m3)
    m_max = ti.select(keep_yz, m1, ti.select(keep_xz, m2, m3))
    x = ti.select(keep_yz, 1, 0)
    y = ti.select(keep_yz or keep_xz, 2, 1)
    px, py, ax, ay, bx, by, cx, cy = p[x], p[y], a[x], a[y], b[x], b[y], c[x], c[y]
    c1 = px * by + py * cx + bx * cy - px * cy - py * bx - cx * by
    c2 = px * cy + py * ax + cx * ay - px * ay - py * cx - ax * cy
    c3 = px * ay + py * bx + ax * by - px * by - py * ax - bx * ay
    return ti.Vector([c1, c2, c3]), m_max


@ti.func
def _s2d(a, b, c):
    """Barycentric weights (wa, wb, wc) of the point of triangle abc closest to the origin (a
    degenerate triangle, e.g. c == b, falls back to segment ab)."""
    degenerate, p = _project_origin_plane(a, b, c)
    weights = ti.Vector([0.0, 0.0, 0.0])
    try_edge = ti.Vector([0, 0, 1])  # edges bc, ac, ab
    if not degenerate:
        cofactors, m_max = _area_coords(a, b, c, p)
        inside = ti.Vector([int(_same_sign(m_max, cofactors[k])) for k in ti.static(range(3))])
        if inside[0] and inside[1] and inside[2]:
            weights = cofactors / m_max
        try_edge = 1 - inside
    dmin = _BIG
    for e in range(3):
        if try_edge[e]:
            u = ti.select(e == 0, b, a)
            v = ti.select(e == 2, b, c)
            w = _s1d(u, v)
            closest = w[0] * u + w[1] * v
            d = _dot(closest, closest)
            if d < dmin:
                dmin = d
                weights = ti.Vector([ti.select(e == 0, 0.0, w[0]),
                                     ti.select(e == 0, w[0], ti.select(e == 1, 0.0, w[1])),
                                     ti.select(e == 2, 0.0, w[1])])
    return weights


@ti.func
def _subdistance(s1, s2, s3, s4, n):
    """Barycentric weights (4,) of the point closest to the origin of the simplex of the first n
    of s1..s4: the origin itself if a tetrahedron encloses it, else the best face that sees it."""
    weights = ti.Vector([1.0, 0.0, 0.0, 0.0])
    if n >= 2:
        try_face = ti.Vector([0, 0, 0, 1])  # faces opposite s1, s2, s3, s4
        if n == 4:
            cof = ti.Vector([-_det3(s2, s3, s4), _det3(s1, s3, s4), -_det3(s1, s2, s4), _det3(s1, s2, s3)])
            m_det = cof[0] + cof[1] + cof[2] + cof[3]
            inside = ti.Vector([int(_same_sign(m_det, cof[k])) for k in ti.static(range(4))])
            try_face = 1 - inside
            if inside[0] and inside[1] and inside[2] and inside[3]:
                weights = cof / m_det
        dmin = _BIG
        for f in range(4):
            if try_face[f]:
                a = ti.select(f == 0, s2, s1)
                b = ti.select(f <= 1, s3, s2)
                c = ti.select(f <= 2, s4, ti.select(n == 2, s2, s3))
                w = _s2d(a, b, c)
                closest = w[0] * a + w[1] * b + w[2] * c
                d = _dot(closest, closest)
                if d < dmin:
                    dmin = d
                    weights = ti.Vector([ti.select(f == 0, 0.0, w[0]),
                                         ti.select(f == 0, w[0], ti.select(f == 1, 0.0, w[1])),
                                         ti.select(f <= 1, w[1], ti.select(f == 2, 0.0, w[2])),
                                         ti.select(f == 3, 0.0, w[2])])
    return weights


@ti.func
def _gjk(shape1: ti.template(), shape2: ti.template(), get_dist, dist_cutoff, cache1, cache2,
         hull: ti.template(), ws: ti.template(), row: ti.template()):
    """MuJoCo 4.0's GJK from the two geom centres (read from its compiled code: unlike the 3.x
    sources there is no tetrahedron walk; the next iterate is the exact projection of the origin
    on the simplex's line or plane). get_dist: distance wanted (sphere/capsule cores, margins),
    stop once it provably exceeds dist_cutoff; else stop as soon as separation is proven.
    One support query per pass; the last pass checks separation at the final iterate.

    Returns (n, x1, x2, dist, separated, cache1, cache2): the final simplex in workspace slots
    0..n-1, the witness points (world), the distance (0: the origin is enclosed; _BIG:
    separation proven early).
    """
    discrete = _discrete(shape1, shape2)
    epsilon = ti.select(discrete, 0.0, _GJK_EPS)
    min_norm = ti.select(discrete or get_dist, _MINVAL, CCD_TOLERANCE)
    x1, x2 = _centre(shape1, hull), _centre(shape2, hull)
    x_k = x1 - x2
    x_norm = ti.sqrt(_dot(x_k, x_k))
    if x_norm < _MINVAL:  # coincident centres: start along x
        x_k, x_norm = ti.Vector([1.0, 0.0, 0.0]), 1.0
    weights = ti.Vector([1.0, 0.0, 0.0, 0.0])
    slot = ti.Vector([0, 1, 2, 3])  # workspace slot of each simplex vertex (4 slots, permuted)
    n, k, separated, decided, final = 0, 0, 0, 0, 0
    while True:
        if final:  # converged: witness points, and a last support to check separation
            if n > 0:
                x1, x2 = _combine(weights, ws, row, _V_VERT1, slot), _combine(weights, ws, row, _V_VERT2, slot)
            if n == 4 or separated or x_norm < _MINVAL:
                break
        p1, p2, cache1, cache2 = _minkowski(shape1, shape2, -(x_k * (1.0 / x_norm)), cache1, cache2, hull)
        s_k = p1 - p2
        lower = _dot(x_k, s_k)  # lower / x_norm bounds the distance from below
        if final:
            separated = int(lower > 0)
            break
        _put_vertex(ws, row, slot[n], p1, p2, cache1, cache2)
        if lower > 0:
            separated = 1
            if not get_dist or (dist_cutoff < _BIG and lower >= dist_cutoff * x_norm):
                decided, n = 1, 0
                break
        if k != 0 and _dot(x_k, x_k - s_k) < epsilon:  # Frank-Wolfe duality gap: converged
            final = 1
            continue
        weights = _subdistance(_vert(ws, row, slot[0]), _vert(ws, row, slot[1]), _vert(ws, row, slot[2]),
                               _vert(ws, row, slot[3]), n + 1)
        kept, dropped, m = ti.Vector([0, 0, 0, 0]), ti.Vector([0, 0, 0, 0]), 0
        n = 0
        for s in ti.static(range(4)):  # keep the vertices with nonzero weight, in order
            if weights[s] != 0:
                kept[n], weights[n] = slot[s], weights[s]
                n += 1
            else:
                dropped[m] = slot[s]
                m += 1
        for s in ti.static(range(4)):
            slot[s] = ti.select(s < n, kept[s], dropped[ti.max(s - n, 0)])
            if s >= n:
                weights[s] = 0.0
        if n == 0:
            decided, separated = 1, 1
            break
        if n == 4:
            final = 1
            continue
        # next iterate: the vertex, or the origin projected on the segment's line / triangle's plane
        a, b = _vert(ws, row, slot[0]), _vert(ws, row, slot[1])
        x_k = _combine(weights, ws, row, _V_VERT, slot)
        if n == 2:
            diff = b - a
            if not _dot(diff, diff) < _MINVAL2:
                x_k = _project_origin_line(a, b)
        elif n == 3:
            degenerate, projection = _project_origin_plane(a, b, _vert(ws, row, slot[2]))
            if not degenerate:
                x_k = projection
        x_norm_prev = x_norm
        x_norm = ti.sqrt(_dot(x_k, x_k))
        k += 1
        if x_norm < ti.select(n == 1, _MINVAL, min_norm) or (k > 1 and ti.abs(x_norm - x_norm_prev) < _MINVAL) \
                or k >= CCD_ITERATIONS:
            final = 1
    dist = _BIG
    if not decided:
        dist = ti.select(n == 4 and not separated, 0.0, x_norm)
    for t in range(8):  # the simplex back to slots 0..3 in order, through slots 4..7
        _copy_vertex(ws, row, ti.select(t < 4, slot[t & 3], t), ti.select(t < 4, t + 4, t - 4))
    return n, x1, x2, dist, separated, cache1, cache2


# ----------------------------------------------------------------------------- EPA

@ti.func
def _origin_in_tetra(p0, p1, p2, p3):
    """True when the origin lies strictly inside tetrahedron (p0, p1, p2, p3)."""
    inside = True
    for k in ti.static(range(4)):
        a, b, c, d = (p0, p1, p2, p3) if k == 0 else ((p1, p2, p3, p0) if k == 1 else (
            (p2, p3, p0, p1) if k == 2 else (p3, p0, p1, p2)))
        normal = _cross(b - a, c - a)
        inside = inside and _same_sign(_dot(normal, d - a), _dot(normal, -a))
    return inside


@ti.func
def _ray_triangle(v1, v2, v3, v4, v5):
    """True when line v1 -> v2 crosses triangle (v3, v4, v5) (three volumes of one sign)."""
    d12, d13, d14, d15 = v2 - v1, v3 - v1, v4 - v1, v5 - v1
    vol1, vol2, vol3 = _det3(d13, d14, d12), _det3(d14, d15, d12), _det3(d15, d13, d12)
    return (vol1 >= 0 and vol2 >= 0 and vol3 >= 0) or (vol1 <= 0 and vol2 <= 0 and vol3 <= 0)


@ti.func
def _on_triangle(a, b, c, p):
    """True when p lies on triangle abc (non-negative barycentrics, distance < 1e-15)."""
    cofactors, m_max = _area_coords(a, b, c, p)
    w = cofactors / m_max
    back = a * w[0] + b * w[1] + c * w[2]
    return w[0] >= 0 and w[1] >= 0 and w[2] >= 0 and ti.sqrt(_dot(back - p, back - p)) < _MINVAL


@ti.func
def _turn120(axis):
    """Rotation matrix of 120 degrees about `axis`."""
    norm = ti.sqrt(_dot(axis, axis))
    u = ti.Vector([axis[0] / norm, axis[1] / norm, axis[2] / norm])
    s, c = 0.86602540378, -0.5
    return ti.Matrix([[c + u[0] * u[0] * (1 - c), u[0] * u[1] * (1 - c) - u[2] * s, u[0] * u[2] * (1 - c) + u[1] * s],
                      [u[1] * u[0] * (1 - c) + u[2] * s, c + u[1] * u[1] * (1 - c), u[1] * u[2] * (1 - c) - u[0] * s],
                      [u[0] * u[2] * (1 - c) - u[1] * s, u[1] * u[2] * (1 - c) + u[0] * s, c + u[2] * u[2] * (1 - c)]])


@ti.func
def _attach_face(ws: ti.template(), row: ti.template(), center, slot, verts, adj):
    """Write face `slot` (vertex slots and neighbour faces packed 10 bits each, a | b << 10 |
    c << 20; neighbours across ab, bc, ca): its outward projection of the origin and that
    point's squared norm, returned; 0 if the triangle is degenerate."""
    ws.ccd_i[row + (_I_FVERTS + slot,)] = verts
    ws.ccd_i[row + (_I_FADJ + slot,)] = adj
    va = _vert(ws, row, verts & 1023)
    degenerate, v = _project_origin_plane(_vert(ws, row, verts >> 20), _vert(ws, row, (verts >> 10) & 1023), va)
    dist2 = 0.0
    if not degenerate:
        if _dot(v, va - center) < 0:
            v = -v
        dist2 = _dot(v, v)
        ws.ccd_v[row + (_V_FACE + slot,)] = v
        ws.ccd_f[row + (_F_DIST2 + slot,)] = dist2
        ws.ccd_i[row + (_I_FINDEX + slot,)] = -1
    return dist2


@ti.func
def _unmap(ws: ti.template(), row: ti.template(), face, nmap, nfree):
    """Delete `face`: off the map (the map's last entry takes its place), slot onto the free
    list. Returns the new (nmap, nfree)."""
    m = ws.ccd_i[row + (_I_FINDEX + face,)]
    if m >= 0:
        nmap -= 1
        last = ws.ccd_i[row + (_I_MAP + nmap,)]
        ws.ccd_i[row + (_I_MAP + m,)] = last
        ws.ccd_i[row + (_I_FINDEX + last,)] = m
    ws.ccd_i[row + (_I_FINDEX + face,)] = -2
    ws.ccd_i[row + (_I_FREE + nfree,)] = face
    return nmap, nfree + 1


@ti.func
def _horizon(ws: ti.template(), row: ti.template(), face, w, nmap, nfree):
    """Delete `face` and, depth first in MuJoCo's order, every face connected to it that sees
    w; record each edge between a deleted and a kept face (kept face, its edge index) at _I_NEW.
    Returns (edge count, 1 if the horizon overflowed, nmap, nfree)."""
    nmap, nfree = _unmap(ws, row, face, nmap, nfree)
    ws.ccd_i[row + (_I_STACK,)] = face << 4  # frames: face << 4 | first edge << 2 | edges done
    depth, nedges, overflow = 1, 0, 0
    while depth > 0:
        frame = ws.ccd_i[row + (_I_STACK + depth - 1,)]
        current, first, done = frame >> 4, (frame >> 2) & 3, frame & 3
        if done == ti.select(depth == 1, 3, 2):  # the first face has 3 edges to walk, others 2
            depth -= 1
        else:
            ws.ccd_i[row + (_I_STACK + depth - 1,)] = frame + 1
            edge = _wrap(first + done, 3)
            neighbour = (ws.ccd_i[row + (_I_FADJ + current,)] >> (10 * edge)) & 1023
            if ws.ccd_i[row + (_I_FINDEX + neighbour,)] > -2:
                shared = (ws.ccd_i[row + (_I_FVERTS + current,)] >> (10 * _wrap(edge + 1, 3))) & 1023
                nverts = ws.ccd_i[row + (_I_FVERTS + neighbour,)]
                neighbour_edge = ti.select(nverts & 1023 == shared, 0, ti.select((nverts >> 10) & 1023 == shared, 1, 2))
                v = ws.ccd_v[row + (_V_FACE + neighbour,)]
                if _dot(v, w) - ws.ccd_f[row + (_F_DIST2 + neighbour,)] > _MINVAL:  # it sees w: delete
                    nmap, nfree = _unmap(ws, row, neighbour, nmap, nfree)
                    ws.ccd_i[row + (_I_STACK + depth,)] = (neighbour << 4) | (_wrap(neighbour_edge + 1, 3) << 2)
                    depth += 1
                elif nedges < _HORIZON:
                    ws.ccd_i[row + (_I_NEW + nedges,)] = (neighbour << 2) | neighbour_edge
                    nedges += 1
                else:
                    overflow = 1
    return nedges, overflow, nmap, nfree


@ti.func
def _cone(ws: ti.template(), row: ti.template(), w_slot, nedges, nfaces, nfree):
    """Plan the faces joining vertex w_slot to the horizon edges (at _I_NEW), in order: each gets
    a free slot, its neighbours (previous new face, the kept face, next new face), and the kept
    face now neighbours it. Rewrites _I_NEW as (verts, adjacency, slot) per new face. Returns
    (nfaces, nfree)."""
    for i in range(nedges):
        slot = nfaces
        if nfree > 0:
            nfree -= 1
            slot = ws.ccd_i[row + (_I_FREE + nfree,)]
        else:
            nfaces += 1
        ws.ccd_i[row + (_I_NEW + 2 * _HORIZON + i,)] = slot
    for i in range(nedges):
        kept_edge = ws.ccd_i[row + (_I_NEW + i,)]
        kept, edge = kept_edge >> 2, kept_edge & 3
        kept_verts = ws.ccd_i[row + (_I_FVERTS + kept,)]
        a = (kept_verts >> (10 * edge)) & 1023
        b = (kept_verts >> (10 * _wrap(edge + 1, 3))) & 1023
        slot = ws.ccd_i[row + (_I_NEW + 2 * _HORIZON + i,)]
        adj = ws.ccd_i[row + (_I_FADJ + kept,)]
        ws.ccd_i[row + (_I_FADJ + kept,)] = (adj & ~(1023 << (10 * edge))) | (slot << (10 * edge))
        before = ws.ccd_i[row + (_I_NEW + 2 * _HORIZON + _wrap(i + nedges - 1, nedges),)]
        after = ws.ccd_i[row + (_I_NEW + 2 * _HORIZON + _wrap(i + 1, nedges),)]
        ws.ccd_i[row + (_I_NEW + _HORIZON + i,)] = before | (kept << 10) | (after << 20)
        ws.ccd_i[row + (_I_NEW + i,)] = w_slot | (b << 10) | (a << 20)
    return nfaces, nfree


_TETRA_PACKED, _HEXA_PACKED, _BIPYRAMID_PACKED = _packed(_TETRA), _packed(_HEXA), _packed(_BIPYRAMID)
_EXPAND, _START2, _START3, _START4, _STOP = 0, 2, 3, 4, 5


@ti.func
def _epa(shape1: ti.template(), shape2: ti.template(), n, cache1, cache2, hull: ti.template(),
         ws: ti.template(), row: ti.template()):
    """MuJoCo's EPA from GJK's final simplex (workspace slots 0..n-1, n = 2, 3 or 4): build a
    polytope around the origin (a hexahedron from a segment, a bipyramid from a triangle, the
    tetrahedron itself; a triangle again when the origin lies on a face), then expand it toward
    the face nearest the origin until the support along that face's normal stops growing.

    One pass of the loop = plan (directions of 0..3 support queries, faces to attach), the
    queries, the attachments; stage _STOP ends it.
    Returns (found, face (3,) workspace slots of the final face's vertices, x1, x2 (witness
    points, world), dist (-depth), truncated (1: stopped at CCD_ITERATIONS), cache1, cache2).
    """
    discrete = _discrete(shape1, shape2)
    tolerance = ti.select(discrete, _MINVAL, CCD_TOLERANCE)
    stage = n
    nverts, nfaces, nmap, nfree = n, 0, 0, 0
    center = ti.Vector([0.0, 0.0, 0.0])
    restart = ti.Vector([0, 1, 2])   # the triangle a _START3 pass starts from
    found, failed, k, truncated = 0, 0, 0, 0
    best_verts, best_v, best_dist2 = 0, ti.Vector([0.0, 0.0, 0.0]), 0.0
    upper, upper2, lower, lower2 = _BIG, _BIG, 0.0, 0.0
    while stage != _STOP:
        # ---- plan
        nquery, nnew, nearest = 0, 0, -1
        direction, axis = ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0])
        turn = ti.Matrix.identity(float, 3)
        if stage == _START4:
            center = (((_vert(ws, row, 0) + _vert(ws, row, 1)) + _vert(ws, row, 2)) + _vert(ws, row, 3)) * 0.25
            nnew = 4
        elif stage == _START2:
            a, b = _vert(ws, row, 0), _vert(ws, row, 1)
            center = (a + b) * 0.5
            diff = b - a
            unit = ti.Vector([0.0, 0.0, 0.0])  # the axis along diff's smallest component
            small = ti.min(ti.abs(diff[0]), ti.abs(diff[1]), ti.abs(diff[2]))
            unit[ti.select(ti.abs(diff[0]) == small, 0, ti.select(ti.abs(diff[1]) == small, 1, 2))] = 1.0
            direction, turn, nquery, nnew = _cross(unit, diff), _turn120(diff), 3, 6
        elif stage == _START3:
            for t in range(6):  # triangle `restart` to slots 0..2, through slots 5..7
                src = ti.select(t < 3, restart[ti.min(t, 2)], t + 2)
                _copy_vertex(ws, row, src, ti.select(t < 3, t + 5, t - 3))
            nverts, nfaces, nmap, nfree = 3, 0, 0, 0
            a, b, c = _vert(ws, row, 0), _vert(ws, row, 1), _vert(ws, row, 2)
            center = ((a + b) + c) * (1.0 / 3.0)
            axis = _cross(b - a, c - a)
            if ti.sqrt(_dot(axis, axis)) < _MINVAL:
                stage, failed = _STOP, 1
            else:
                direction, nquery, nnew = -axis, 2, 6
        elif stage == _EXPAND:
            lower2 = _BIG
            for m in range(nmap):
                face = ws.ccd_i[row + (_I_MAP + m,)]
                if ws.ccd_f[row + (_F_DIST2 + face,)] < lower2:
                    nearest, lower2 = face, ws.ccd_f[row + (_F_DIST2 + face,)]
            if k >= CCD_ITERATIONS or nearest < 0 or lower2 > upper2:
                stage = _STOP  # keep the previous nearest face
                truncated = k >= CCD_ITERATIONS
            else:
                found = 1
                best_verts = ws.ccd_i[row + (_I_FVERTS + nearest,)]
                best_v, best_dist2 = ws.ccd_v[row + (_V_FACE + nearest,)], lower2
                if lower2 <= 0:
                    stage = _STOP
                else:
                    lower = ti.sqrt(lower2)
                    direction, nquery = best_v, 1
        # ---- support queries (the only ones of EPA)
        for q in range(nquery):
            norm = ti.sqrt(_dot(direction, direction))
            unit_dir = ti.Vector([1.0, 0.0, 0.0])
            if norm > _MINVAL:
                unit_dir = direction / norm
            p1, p2, cache1, cache2 = _minkowski(shape1, shape2, unit_dir, cache1, cache2, hull)
            _put_vertex(ws, row, nverts, p1, p2, cache1, cache2)
            nverts += 1
            direction = ti.select(stage == _START2, _rot(turn, direction), axis)
        # ---- after the queries: checks, and the horizon's new faces
        a, b, c = _vert(ws, row, 0), _vert(ws, row, 1), _vert(ws, row, 2)
        if stage == _START3 and (_on_triangle(a, b, c, _vert(ws, row, 4)) or _on_triangle(a, b, c, _vert(ws, row, 3))):
            stage, failed = _STOP, 1
        elif stage == _EXPAND:
            w_slot = nverts - 1
            w = _vert(ws, row, w_slot)
            upper_k = _dot(best_v, w) / lower
            if upper_k < upper:
                upper = upper_k
                upper2 = upper * upper
            repeated = 0
            if discrete:  # a support point seen before: converged
                id1, id2 = ws.ccd_i[row + (_I_ID1 + w_slot,)], ws.ccd_i[row + (_I_ID2 + w_slot,)]
                for i in range(w_slot):
                    if ws.ccd_i[row + (_I_ID1 + i,)] == id1 and ws.ccd_i[row + (_I_ID2 + i,)] == id2:
                        repeated = 1
            if upper - lower < tolerance:
                if k == 0 and upper < lower - 1e-10:
                    found = 0
                stage = _STOP
            elif repeated:
                stage = _STOP
            else:
                nedges, overflow, nmap, nfree = _horizon(ws, row, nearest, w, nmap, nfree)
                if nedges < 3 or overflow:
                    stage, found = _STOP, 0
                elif nedges > nfree + _FACES - nfaces:
                    stage = _STOP  # out of face slots (MuJoCo: out of memory): keep this face
                else:
                    nfaces, nfree = _cone(ws, row, w_slot, nedges, nfaces, nfree)
                    nnew = nedges
        # ---- attach the planned faces (the only attachment site)
        restart_face = -1
        for i in range(nnew):
            verts, adj, slot = 0, 0, i
            if stage == _EXPAND:
                verts, adj = ws.ccd_i[row + (_I_NEW + i,)], ws.ccd_i[row + (_I_NEW + _HORIZON + i,)]
                slot = ws.ccd_i[row + (_I_NEW + 2 * _HORIZON + i,)]
            else:
                verts = ti.select(stage == _START4, _pick(i, _TETRA_PACKED[0]), ti.select(
                    stage == _START2, _pick(i, _HEXA_PACKED[0]), _pick(i, _BIPYRAMID_PACKED[0])))
                adj = ti.select(stage == _START4, _pick(i, _TETRA_PACKED[1]), ti.select(
                    stage == _START2, _pick(i, _HEXA_PACKED[1]), _pick(i, _BIPYRAMID_PACKED[1])))
            d2 = _attach_face(ws, row, center, slot, verts, adj)
            if stage == _EXPAND:
                if d2 == 0:
                    stage, found = _STOP, 0
                    break
                if d2 >= lower2 and d2 <= upper2:
                    ws.ccd_i[row + (_I_MAP + nmap,)] = slot
                    ws.ccd_i[row + (_I_FINDEX + slot,)] = nmap
                    nmap += 1
            elif d2 < _MINVAL2:  # the origin lies on this face
                if stage == _START3:
                    stage, failed = _STOP, 1
                else:
                    restart_face = verts
                break
        # ---- next stage
        if stage == _EXPAND:
            if nmap == 0:
                stage = _STOP
            k += 1
        elif stage != _STOP:
            if restart_face >= 0:
                restart = ti.Vector([restart_face & 1023, (restart_face >> 10) & 1023, restart_face >> 20])
                stage = _START3
            elif stage == _START4 and not _origin_in_tetra(_vert(ws, row, 0), _vert(ws, row, 1), _vert(ws, row, 2),
                                                          _vert(ws, row, 3)):
                stage, failed = _STOP, 1
            elif stage == _START2 and not _ray_triangle(_vert(ws, row, 0), _vert(ws, row, 1), _vert(ws, row, 2),
                                                       _vert(ws, row, 3), _vert(ws, row, 4)):
                stage, failed = _STOP, 1
            else:
                nfaces = nnew
                nmap = nnew
                for f in range(nnew):
                    ws.ccd_i[row + (_I_MAP + f,)] = f
                    ws.ccd_i[row + (_I_FINDEX + f,)] = f
                stage = _EXPAND
    # ---- witness points: barycentrics of the origin's projection on the final face
    face = ti.Vector([best_verts & 1023, (best_verts >> 10) & 1023, best_verts >> 20])
    x1, x2 = ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0])
    dist = 0.0
    found = found and not failed
    if found:
        cofactors, m_max = _area_coords(_vert(ws, row, face[0]), _vert(ws, row, face[1]), _vert(ws, row, face[2]),
                                        best_v)
        w = cofactors / m_max
        for s in ti.static(range(3)):
            x1 += w[s] * ws.ccd_v[row + (_V_VERT1 + face[s],)]
            x2 += w[s] * ws.ccd_v[row + (_V_VERT2 + face[s],)]
        dist = -ti.sqrt(best_dist2)
    return found, face, x1, x2, dist, truncated, cache1, cache2


@ti.func
def _sphere_in_mesh(shape1: ti.template(), shape2: ti.template(), hull: ti.template(), ws: ti.template(),
                    row: ti.template()):
    """The exact deep contact of a sphere (shape1) whose centre c lies in a mesh's hull (shape2),
    for where EPA stopped short of it: the foot of c on the nearest facet plane (the nearest
    boundary point of a convex polytope from inside). The facet is the hull polygon whose
    supporting plane (its outward normal, through its farthest vertex) is nearest c; its plane,
    that of three of its vertices spanning it (`_polygon_spread`: a merged polygon is flat only
    to ~0.4°), gives the contact, and the three go to workspace slots 0..2 (ids −1 for the centre,
    as EPA's), so the feature is the closed form `_core_terms` replays. Returns (x1, x2 witness
    points (world), dist = −(depth of the swept shapes))."""
    mesh, centre = shape2[1], shape1[2]
    local = _rot_t(shape2[3], centre - shape2[2])
    vadr, first = hull.hull_vertadr[mesh], hull.hull_polyadr[mesh]
    best, face = -_BIG, 0
    for f in range(hull.hull_polynum[mesh]):
        normal = hull.hull_poly_normal[first + f]
        padr, num = hull.hull_poly_vertadr[first + f], hull.hull_poly_vertnum[first + f]
        support = -_BIG
        for i in range(num):
            support = ti.max(support, _dot(normal, _polygon_point(hull, vadr, padr, num, i)))
        if _dot(normal, local) - support > best:
            best, face = _dot(normal, local) - support, f
    j, k = _polygon_spread(hull, mesh, face)
    padr = hull.hull_poly_vertadr[first + face]
    ids = ti.Vector([hull.hull_poly_vert[padr], hull.hull_poly_vert[padr + j], hull.hull_poly_vert[padr + k]])
    a = hull.hull_vert[vadr + ids[0]]
    outward = _normalize(_cross(hull.hull_vert[vadr + ids[1]] - a, hull.hull_vert[vadr + ids[2]] - a))
    outward *= _sign(_dot(outward, hull.hull_poly_normal[first + face]))
    signed = _dot(outward, local - a)
    outward = _rot(shape2[3], outward)
    for v in ti.static(range(3)):
        _put_vertex(ws, row, v, centre, _rot(shape2[3], hull.hull_vert[vadr + ids[v]]) + shape2[2], -1, ids[v])
    half = 0.5 * shape1[5]
    x1 = centre - (shape1[4][0] + half) * outward
    x2 = centre - (signed - half) * outward
    return x1, x2, signed - shape1[4][0] - shape1[5]


# ----------------------------------------------------------------------------- multi-contact
# Features of a box: faces 0..5 = +x, -x, +y, -y, +z, -z; corners by bits (bit 0: +x, ...).

@ti.func
def _corner_local(size, corner):
    """Geom-frame position of box corner `corner` (half-extents size)."""
    return ti.Vector([ti.select(corner & 1, size[0], -size[0]), ti.select(corner & 2, size[1], -size[1]),
                      ti.select(corner & 4, size[2], -size[2])])


@ti.func
def _box_corner(shape: ti.template(), corner):
    """World position of box corner `corner`."""
    return _rot(shape[3], _corner_local(shape[4], corner)) + shape[2]


@ti.func
def _face_normal_local(shape: ti.template(), face, hull: ti.template()):
    """Geom-frame outward unit normal of box face / mesh polygon `face` (mesh-local id)."""
    local = ti.Vector([0.0, 0.0, 0.0])
    if shape[0] == BOX:
        local[face >> 1] = 1.0 - 2.0 * (face & 1)
    else:
        local = hull.hull_poly_normal[hull.hull_polyadr[shape[1]] + face]
    return local


@ti.func
def _face_normal(shape: ti.template(), face, hull: ti.template()):
    """World outward unit normal of box face / mesh polygon `face` (mesh-local id)."""
    return _rot(shape[3], _face_normal_local(shape, face, hull))


@ti.func
def _faces_at(shape: ti.template(), dim, vids, direction, hull: ti.template()):
    """The faces a feature of `dim` vertices (ids vids) may lie on, as MuJoCo's boxNormals /
    meshNormals: returns (count, up to 3 face ids, from_map); from_map: the faces are the
    vertex's polygons, read with `_face_of`. A box feature that does not pin a face picks the
    face within ~5 deg of `direction` (world), if any."""
    faces = ti.Vector([0, 0, 0])
    count, from_map = 0, 0
    if shape[0] == BOX:
        if dim == 1:
            for axis in ti.static(range(3)):
                faces[axis] = 2 * axis + ti.select(vids[0] & (1 << axis), 0, 1)
            count = 3
        else:
            for axis in ti.static(range(3)):
                bit = 1 << axis
                all_set = (vids[0] & bit) != 0 and (vids[1] & bit) != 0 and (dim == 2 or (vids[2] & bit) != 0)
                none_set = (vids[0] & bit) == 0 and (vids[1] & bit) == 0 and (dim == 2 or (vids[2] & bit) == 0)
                if all_set or none_set:
                    faces[count] = 2 * axis + ti.select(all_set, 0, 1)
                    count += 1
            if count != 4 - dim:  # 1 face for 3 corners, 2 for an edge: else the face near `direction`
                local = _rot_t(shape[3], direction)
                local = local * (1.0 / ti.sqrt(_dot(local, local)))
                count = 0
                for face in range(6):
                    if count == 0 and (1.0 - 2.0 * (face & 1)) * local[face >> 1] > _FACE_TOL:
                        faces[0], count = face, 1
    elif dim == 1:
        count, from_map = hull.hull_vert_polynum[hull.hull_vertadr[shape[1]] + vids[0]], 1
    else:
        # polygons shared by the first two vertices (at most 2), then by the third
        adr = hull.hull_vertadr[shape[1]]
        a_adr, a_num = hull.hull_vert_polyadr[adr + vids[0]], hull.hull_vert_polynum[adr + vids[0]]
        b_adr, b_num = hull.hull_vert_polyadr[adr + vids[1]], hull.hull_vert_polynum[adr + vids[1]]
        for i in range(a_num):
            for j in range(b_num):
                if count < 2 and hull.hull_polymap[a_adr + i] == hull.hull_polymap[b_adr + j]:
                    faces[count] = hull.hull_polymap[a_adr + i]
                    count += 1
        if dim == 3:
            c_adr, c_num = hull.hull_vert_polyadr[adr + vids[2]], hull.hull_vert_polynum[adr + vids[2]]
            shared = 0
            for i in range(count):
                for j in range(c_num):
                    if shared == 0 and faces[i] == hull.hull_polymap[c_adr + j]:
                        faces[0], shared = faces[i], 1
            count = shared
    return count, faces, from_map


@ti.func
def _face_of(shape: ti.template(), vid, faces, from_map, i, hull: ti.template()):
    """Face i of a `_faces_at` list."""
    face = faces[ti.min(i, 2)]
    if from_map:
        face = hull.hull_polymap[hull.hull_vert_polyadr[hull.hull_vertadr[shape[1]] + vid] + i]
    return face


@ti.func
def _edge_at(shape: ti.template(), dim, vids, start, end2, i, hull: ti.template()):
    """Edge i leaving a feature's first vertex (world `start`): the feature itself if it is an
    edge (far end end2), else each box edge / each polygon's edge to the previous vertex at
    the vertex. Returns (unit direction, far end (world), far end id); the count is
    `_edge_count`."""
    end, end_id = end2, vids[1]
    if dim == 1:
        if shape[0] == BOX:
            end_id = vids[0] ^ (1 << i)
            end = _box_corner(shape, end_id)
        else:
            adr = hull.hull_vertadr[shape[1]]
            poly = hull.hull_polyadr[shape[1]] + hull.hull_polymap[hull.hull_vert_polyadr[adr + vids[0]] + i]
            vadr, num = hull.hull_poly_vertadr[poly], hull.hull_poly_vertnum[poly]
            for j in range(num):
                if hull.hull_poly_vert[vadr + j] == vids[0]:
                    end_id = hull.hull_poly_vert[vadr + _wrap(j + num - 1, num)]
            end = _rot(shape[3], hull.hull_vert[adr + end_id]) + shape[2]
    return _normalize(end - start), end, end_id


@ti.func
def _edge_count(shape: ti.template(), dim, vids, hull: ti.template()):
    """Number of edges `_edge_at` enumerates (0 for a face)."""
    count = ti.select(dim == 2, 1, 0)
    if dim == 1:
        count = 3
        if shape[0] == MESH:
            count = hull.hull_vert_polynum[hull.hull_vertadr[shape[1]] + vids[0]]
    return count


@ti.func
def _face_size(shape: ti.template(), face, hull: ti.template()):
    """Number of vertices of box face / mesh polygon `face`."""
    count = 4
    if shape[0] != BOX:
        count = hull.hull_poly_vertnum[hull.hull_polyadr[shape[1]] + face]
    return count


@ti.func
def _face_local(shape: ti.template(), face, i, hull: ti.template()):
    """Geom-frame vertex i of box face / mesh polygon `face`, in MuJoCo's order (a polygon
    reversed: clockwise seen from outside)."""
    local = ti.Vector([0.0, 0.0, 0.0])
    if shape[0] == BOX:
        local = _corner_local(shape[4], (_pick(face, _BOX_FACES) >> (3 * i)) & 7)
    else:
        poly = hull.hull_polyadr[shape[1]] + face
        last = hull.hull_poly_vertadr[poly] + hull.hull_poly_vertnum[poly] - 1
        local = hull.hull_vert[hull.hull_vertadr[shape[1]] + hull.hull_poly_vert[last - i]]
    return local


@ti.func
def _put_face(shape: ti.template(), face, base, ws: ti.template(), row: ti.template(), hull: ti.template()):
    """Write the vertices (world) of box face / mesh polygon `face` at workspace 3-vector slots
    base.., in `_face_local`'s order. Returns the count, 0 for a polygon of more than
    POLYGON_MAX vertices."""
    count = _face_size(shape, face, hull)
    if count > POLYGON_MAX:
        count = 0
    for i in range(count):
        ws.ccd_v[row + (base + i,)] = _rot(shape[3], _face_local(shape, face, i, hull)) + shape[2]
    return count


@ti.func
def _quad_area(a, b, c, d):
    """Area of quadrilateral abcd, half the norm of its diagonals' cross product, in MuJoCo 4.0's
    order of operations (read from its binary: ties between quads that share a repeated vertex
    are decided by round-off). MuJoCo 3.12's area4 was another measure."""
    g = _cross(a - c, b - d)
    return 0.5 * ti.sqrt(_dot(g, g))


@ti.func
def _quad_at(ws: ti.template(), row: ti.template(), base, a, b, c, d):
    """Area of the quadrilateral of workspace points base + (a, b, c, d)."""
    return _quad_area(ws.ccd_v[row + (base + a,)], ws.ccd_v[row + (base + b,)], ws.ccd_v[row + (base + c,)],
                      ws.ccd_v[row + (base + d,)])


@ti.func
def _largest_quad(ws: ti.template(), row: ti.template(), base, npoly):
    """MuJoCo's greedy search for a large quadrilateral among npoly > 4 points at workspace
    slots base..: for each first corner a, advance d while the area grows, and after each step
    c, then b. Returns the 4 indices (relative to base)."""
    a, b, c, d = 0, 1, 2, 3
    best = ti.Vector([0, 1, 2, 3])
    area = _quad_at(ws, row, base, a, b, c, d)
    while a < npoly:
        while True:
            area2 = _quad_at(ws, row, base, a, b, c, _wrap(d + 1, npoly))
            if not area2 > area:
                break
            area, d = area2, _wrap(d + 1, npoly)
            best = ti.Vector([a, b, c, d])
            while True:
                area2 = _quad_at(ws, row, base, a, b, _wrap(c + 1, npoly), d)
                if not area2 > area:
                    break
                area, c = area2, _wrap(c + 1, npoly)
                best = ti.Vector([a, b, c, d])
            while True:
                area2 = _quad_at(ws, row, base, a, _wrap(b + 1, npoly), c, d)
                if not area2 > area:
                    break
                area, b = area2, _wrap(b + 1, npoly)
                best = ti.Vector([a, b, c, d])
        if b == a:
            b = _wrap(b + 1, npoly)
            if c == b:
                c = _wrap(c + 1, npoly)
                if d == c:
                    d = _wrap(d + 1, npoly)
        a += 1
    return best


@ti.func
def _clip(nclip, npoly, normal, direction, ws: ti.template(), row: ti.template()):
    """MuJoCo's polygonClip: clip the polygon at workspace slots _V_POLY.. (npoly points, lines
    tagged at _I_TAG) by the side planes of the face at _V_CLIP.. (nclip points, outward plane
    normal `normal`), keep the points behind the face and pick at most 4: the largest quad of
    more than 4, the two farthest of a clipped edge. Writes the witness pairs of each point
    (`_clip_witnesses`; `direction`: the clipped face's normal, or −normal for an edge) with
    their distances and tags at the _WIT places. Returns their number."""
    is_edge = npoly == 2
    face0 = ws.ccd_v[row + (_V_CLIP,)]
    for e in range(nclip):  # side planes through each edge, containing the normal
        a, b = ws.ccd_v[row + (_V_CLIP + e,)], ws.ccd_v[row + (_V_CLIP + _wrap(e + 1, nclip),)]
        side = _normalize(_cross(b - a, (a + normal) - a))
        ws.ccd_v[row + (_V_SIDE + e,)] = side
        ws.ccd_f[row + (_F_SIDE + e,)] = _dot(side, a)
    src = 0  # Sutherland-Hodgman, from one buffer of _CLIP points to the other
    for e in range(nclip):
        dst = _CLIP - src
        nout = 0
        a, side, offset = ws.ccd_v[row + (_V_CLIP + e,)], ws.ccd_v[row + (_V_SIDE + e,)], ws.ccd_f[row + (_F_SIDE + e,)]
        for i in range(npoly):
            j = _wrap(i + 1, npoly)
            p, q = ws.ccd_v[row + (_V_POLY + src + i,)], ws.ccd_v[row + (_V_POLY + src + j,)]
            p_in, q_in = _dot(p - a, side) > -_MINVAL, _dot(q - a, side) > -_MINVAL
            if (p_in or q_in) and not (p_in and q_in):  # PQ crosses the side plane
                pq = q - p
                denom = _dot(side, pq)
                if denom != 0:
                    t = (offset - _dot(side, p)) / denom
                    if t >= 0.0 and t <= 1.0 and nout < _CLIP:
                        line = ws.ccd_i[row + (_I_TAG + 2 * (src + i) + 1,)]  # PQ's line
                        ws.ccd_v[row + (_V_POLY + dst + nout,)] = p + t * pq
                        ws.ccd_i[row + (_I_TAG + 2 * (dst + nout),)] = ti.select(p_in, line, 256 + e)
                        ws.ccd_i[row + (_I_TAG + 2 * (dst + nout) + 1,)] = ti.select(p_in, 256 + e, line)
                        nout += 1
            if q_in and nout < _CLIP:
                ws.ccd_v[row + (_V_POLY + dst + nout,)] = q
                for t in ti.static(range(2)):
                    ws.ccd_i[row + (_I_TAG + 2 * (dst + nout) + t,)] = ws.ccd_i[row + (_I_TAG + 2 * (src + j) + t,)]
                nout += 1
        src, npoly = dst, nout
    kept = 0
    for i in range(npoly):  # keep the points behind the clipping face
        point = ws.ccd_v[row + (_V_POLY + src + i,)]
        if _dot(point - face0, normal) <= 0:
            ws.ccd_v[row + (_V_POLY + src + kept,)] = point
            for t in ti.static(range(2)):
                ws.ccd_i[row + (_I_TAG + 2 * (src + kept) + t,)] = ws.ccd_i[row + (_I_TAG + 2 * (src + i) + t,)]
            kept += 1
    picks = ti.Vector([0, 1, 2, 3])
    nx = ti.min(kept, 4)
    if kept > 4:
        picks = _largest_quad(ws, row, _V_POLY + src, kept)
    elif is_edge and kept > 2:  # a clipped edge: its two farthest points
        nx = 2
        farthest = 0.0
        for i in range(kept):
            for j in range(i + 1, kept):
                diff = ws.ccd_v[row + (_V_POLY + src + j,)] - ws.ccd_v[row + (_V_POLY + src + i,)]
                if _dot(diff, diff) > farthest:
                    farthest = _dot(diff, diff)
                    picks[0], picks[1] = i, j
    for i in range(nx):
        point = ws.ccd_v[row + (_V_POLY + src + picks[i],)]
        x1, x2, d = _clip_witnesses(ti.select(is_edge, 2, 0), face0, normal, direction, point)
        ws.ccd_v[row + (_V_WIT + i,)] = x1
        ws.ccd_v[row + (_V_WIT + 4 + i,)] = x2
        ws.ccd_f[row + (_F_WIT + i,)] = d
        for t in ti.static(range(2)):
            ws.ccd_i[row + (_I_WIT + i * FEATURE_SIZE + 3 + t,)] = ws.ccd_i[row + (_I_TAG + 2 * (src + picks[i]) + t,)]
    return nx


@ti.func
def _simplex_dim(vids, points):
    """Distinct ids among a feature's 3 vertex ids (3 x 3 world points): its dimension 1, 2 or
    3; for 2, the distinct pair moved to the front (ids and points)."""
    dim = 3
    if vids[0] == vids[1]:
        dim = 1
        if vids[0] != vids[2]:
            dim = 2
            vids[1] = vids[2]
            for c in ti.static(range(3)):
                points[1, c] = points[2, c]
    elif vids[2] == vids[0] or vids[2] == vids[1]:
        dim = 2
    return dim, vids, points


@ti.func
def _multicontact(shape1: ti.template(), shape2: ti.template(), slots, nslots, x1, x2, hull: ti.template(),
                  ws: ti.template(), row: ti.template()):
    """MuJoCo's multi-contact between two polytopes (boxes, meshes): from the features of the
    final EPA face on each geom (workspace slots `slots`), find the most opposed two facing faces
    (normals within ~5 deg), else an edge of the lower-dimensional feature parallel to a face of
    the other geom (then, when that is geom 1's and geom 2's feature is no face, geom 2's edge
    against geom 1's faces), and clip one by the other (`_clip`). Writes up to 4 witness pairs at the _WIT places with
    KIND_CLIP features. Returns their number, 0 when nothing aligns (keep the EPA contact)."""
    nx = 0
    polytopes = (shape1[0] == BOX or shape1[0] == MESH) and (shape2[0] == BOX or shape2[0] == MESH)
    if polytopes and not ((shape1[0] == MESH and hull.hull_polynum[shape1[1]] == 0)
                          or (shape2[0] == MESH and hull.hull_polynum[shape2[1]] == 0)):
        s = ti.Vector([slots[0], slots[ti.select(nslots >= 2, 1, 0)], slots[ti.select(nslots > 2, 2, 0)]])
        ids1 = ti.Vector([ws.ccd_i[row + (_I_ID1 + s[k],)] for k in ti.static(range(3))])
        ids2 = ti.Vector([ws.ccd_i[row + (_I_ID2 + s[k],)] for k in ti.static(range(3))])
        pts1 = ti.Matrix.rows([ws.ccd_v[row + (_V_VERT1 + s[k],)] for k in ti.static(range(3))])
        pts2 = ti.Matrix.rows([ws.ccd_v[row + (_V_VERT2 + s[k],)] for k in ti.static(range(3))])
        dim1, ids1, pts1 = _simplex_dim(ids1, pts1)
        dim2, ids2, pts2 = _simplex_dim(ids2, pts2)
        count1, faces1, map1 = _faces_at(shape1, dim1, ids1, x1 - x2, hull)
        count2, faces2, map2 = _faces_at(shape2, dim2, ids2, x2 - x1, hull)
        # facing faces: the most opposed pair within the tolerance (MuJoCo 4.0, measured; 3.12
        # took the first pair (i, j) in order)
        pair_i, pair_j, edge_geom = -1, -1, 0
        most = -_FACE_TOL
        for i in range(count1):
            normal1 = _face_normal(shape1, _face_of(shape1, ids1[0], faces1, map1, i, hull), hull)
            for j in range(count2):
                normal2 = _face_normal(shape2, _face_of(shape2, ids2[0], faces2, map2, j, hull), hull)
                if _dot(normal1, normal2) < most:
                    most, pair_i, pair_j = _dot(normal1, normal2), i, j
        # else an edge of the lower-dimensional feature parallel to one of the other's faces;
        # when geom 1's finds none and geom 2's feature is an edge or a vertex too, geom 2's edge
        # against geom 1's faces (MuJoCo 4.0, measured: 3.12 kept the EPA contact)
        first_edge = ti.select(dim1 < 3 and dim1 <= dim2, 1, ti.select(dim2 < 3, 2, 0))
        tries = ti.select(pair_i >= 0 or first_edge == 0, 0, ti.select(first_edge == 1 and dim2 < 3, 2, 1))
        start, end2 = ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0])
        for attempt in range(tries):
            if pair_i >= 0:
                break
            edge_geom = ti.select(attempt == 0, first_edge, 3 - first_edge)
            start = ti.select(edge_geom == 1, ti.Vector([pts1[0, 0], pts1[0, 1], pts1[0, 2]]),
                              ti.Vector([pts2[0, 0], pts2[0, 1], pts2[0, 2]]))
            end2 = ti.select(edge_geom == 1, ti.Vector([pts1[1, 0], pts1[1, 1], pts1[1, 2]]),
                             ti.Vector([pts2[1, 0], pts2[1, 1], pts2[1, 2]]))
            nedges = ti.select(edge_geom == 1, _edge_count(shape1, dim1, ids1, hull),
                               _edge_count(shape2, dim2, ids2, hull))
            nfaces = ti.select(edge_geom == 1, count2, count1)
            for f in range(nfaces):
                face_normal = ti.Vector([0.0, 0.0, 0.0])
                if edge_geom == 1:
                    face_normal = _face_normal(shape2, _face_of(shape2, ids2[0], faces2, map2, f, hull), hull)
                else:
                    face_normal = _face_normal(shape1, _face_of(shape1, ids1[0], faces1, map1, f, hull), hull)
                for e in range(nedges):
                    if pair_i < 0:
                        direction = ti.Vector([0.0, 0.0, 0.0])
                        if edge_geom == 1:
                            direction, _, _ = _edge_at(shape1, dim1, ids1, start, end2, e, hull)
                        else:
                            direction, _, _ = _edge_at(shape2, dim2, ids2, start, end2, e, hull)
                        if ti.abs(_dot(direction, face_normal)) < _EDGE_TOL:
                            pair_i, pair_j = e, f
        if pair_i >= 0:
            # the clipping face (`clip_shape` = 1 or 2) and the clipped polygon
            clip_face, clipped_face = -1, -1
            nclip, npoly = 0, 2
            normal, direction = ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0])
            edge_a, edge_b = -1, -1
            if edge_geom == 0:
                clip_face = _face_of(shape1, ids1[0], faces1, map1, pair_i, hull)
                clipped_face = _face_of(shape2, ids2[0], faces2, map2, pair_j, hull)
                nclip = _put_face(shape1, clip_face, _V_CLIP, ws, row, hull)
                npoly = _put_face(shape2, clipped_face, _V_POLY, ws, row, hull)
                normal = _face_normal(shape1, clip_face, hull)
                direction = _face_normal(shape2, clipped_face, hull)
            else:
                end = ti.Vector([0.0, 0.0, 0.0])
                if edge_geom == 1:
                    _, end, edge_b = _edge_at(shape1, dim1, ids1, start, end2, pair_i, hull)
                    edge_a = ids1[0]
                    clip_face = _face_of(shape2, ids2[0], faces2, map2, pair_j, hull)
                    nclip = _put_face(shape2, clip_face, _V_CLIP, ws, row, hull)
                    normal = _face_normal(shape2, clip_face, hull)
                else:
                    _, end, edge_b = _edge_at(shape2, dim2, ids2, start, end2, pair_i, hull)
                    edge_a = ids2[0]
                    clip_face = _face_of(shape1, ids1[0], faces1, map1, pair_j, hull)
                    nclip = _put_face(shape1, clip_face, _V_CLIP, ws, row, hull)
                    normal = _face_normal(shape1, clip_face, hull)
                ws.ccd_v[row + (_V_POLY,)] = start
                ws.ccd_v[row + (_V_POLY + 1,)] = end
                direction = -normal
            for v in range(npoly):  # point v of the clipped polygon joins its edges v - 1 and v
                ws.ccd_i[row + (_I_TAG + 2 * v,)] = _wrap(v + npoly - 1, npoly)
                ws.ccd_i[row + (_I_TAG + 2 * v + 1,)] = v
            if nclip >= 3 and npoly >= 2:
                nx = _clip(nclip, npoly, normal, direction, ws, row)
            for c in range(nx):
                if edge_geom == 1:  # the clipped edge is geom 1's: swap the witnesses
                    w1, w2 = ws.ccd_v[row + (_V_WIT + c,)], ws.ccd_v[row + (_V_WIT + 4 + c,)]
                    ws.ccd_v[row + (_V_WIT + c,)], ws.ccd_v[row + (_V_WIT + 4 + c,)] = w2, w1
                base = _I_WIT + c * FEATURE_SIZE
                ws.ccd_i[row + (base,)] = KIND_CLIP
                ws.ccd_i[row + (base + 1,)] = clip_face
                ws.ccd_i[row + (base + 2,)] = clipped_face
                ws.ccd_i[row + (base + 5,)] = edge_a
                ws.ccd_i[row + (base + 6,)] = edge_b
                ws.ccd_i[row + (base + 7,)] = edge_geom
                for t in ti.static(range(8, 10)):  # the EPA contact's normal, as the first row holds it
                    ws.ccd_i[row + (base + t,)] = ws.ccd_i[row + (_I_WIT + t,)]
                ws.ccd_i[row + (base + 10,)] = int(ti.select(edge_geom == 1, dim1, dim2) == 2)
    return nx


# ----------------------------------------------------------------------------- one CCD run

@ti.func
def _cylinder_modes(shape1: ti.template(), shape2: ti.template(), normal):
    """How each cylinder meets a CORE / EPA contact of unit `normal`, mode1 + 3 mode2: 0 at its
    rim (or not a cylinder), 1 on its cap (normal along the axis: the supports span the cap's
    plane), 2 on its side (normal across the axis: the disk acts as a ball). Exact in the forward:
    a face of the final polytope is in a cap's plane, or contains the axis, to rounding."""
    modes = 0
    for g in ti.static(range(2)):
        shape = shape1 if g == 0 else shape2
        along = ti.abs(shape[3][0, 2] * normal[0] + shape[3][1, 2] * normal[1] + shape[3][2, 2] * normal[2])
        mode = ti.select(along >= 1.0 - _AXIS_TOL, 1, ti.select(along <= _AXIS_TOL, 2, 0))
        modes += ti.select(shape[0] == CYLINDER, mode, 0) * (1 if g == 0 else 3)
    return modes


@ti.func
def _write_witness(shape1: ti.template(), shape2: ti.template(), ws: ti.template(), row: ti.template(), x1, x2,
                   dist, kind, slots, nslots):
    """Store the run's witness pair (world points on geom 1 and 2, at the _WIT places' first
    row), its distance and its feature row: kind, the ids on geom 1 and 2 of the vertices in
    workspace slots `slots[:nslots]`, nslots, the code of the normal x1 - x2, and each
    cylinder's mode (`_cylinder_modes`)."""
    ws.ccd_v[row + (_V_WIT,)] = x1
    ws.ccd_v[row + (_V_WIT + 4,)] = x2
    ws.ccd_f[row + (_F_WIT,)] = dist
    base = _I_WIT
    normal = _normalize(x1 - x2)
    ws.ccd_i[row + (base,)] = kind
    ws.ccd_i[row + (base + 7,)] = nslots
    ws.ccd_i[row + (base + 8,)], ws.ccd_i[row + (base + 9,)] = encode_direction(normal)
    ws.ccd_i[row + (base + 10,)] = _cylinder_modes(shape1, shape2, normal)
    for s in range(3):
        id1, id2 = -1, -1
        if s < nslots:
            id1, id2 = ws.ccd_i[row + (_I_ID1 + slots[s],)], ws.ccd_i[row + (_I_ID2 + slots[s],)]
        ws.ccd_i[row + (base + 1 + 2 * s,)] = id1
        ws.ccd_i[row + (base + 2 + 2 * s,)] = id2


@ti.func
def _ccd(shape1: ti.template(), shape2: ti.template(), multi, hull: ti.template(), ws: ti.template(),
         row: ti.template()):
    """One MuJoCo 4.0 mjc_ccd run. With a sphere or capsule, or a margin, GJK first measures the
    distance between the cores (sphere -> point, capsule -> segment, margins removed); if they
    are apart the contact is their closest-point pair inflated by the radii and half margins.
    Otherwise (deep) GJK + EPA on the full shapes. Then multi-contact when `multi`.
    Writes nx witness pairs (points on each geom, distance without margin, feature) at the
    workspace's _WIT places; the run yields contacts when their smallest distance is < 0.
    Returns nx."""
    kind1, kind2, margin = shape1[0], shape2[0], shape1[5]
    round1 = kind1 == SPHERE or kind1 == CAPSULE
    round2 = kind2 == SPHERE or kind2 == CAPSULE
    full1 = 0.5 * margin + ti.select(round1, shape1[4][0], 0.0)
    full2 = 0.5 * margin + ti.select(round2, shape2[4][0], 0.0)
    cache1, cache2 = -1, -1
    nx, done = 0, 0
    for core in range(2):  # pass 0: cores without margin (if any); pass 1: the full shapes
        if done or (core == 0 and not (round1 or round2 or margin > 0)):
            continue
        shrink1, shrink2 = core == 0 and round1, core == 0 and round2
        s1 = (ti.select(shrink1, ti.select(kind1 == SPHERE, _POINT, _SEGMENT), kind1), shape1[1], shape1[2],
              shape1[3], shape1[4], ti.select(core == 0, 0.0, margin))
        s2 = (ti.select(shrink2, ti.select(kind2 == SPHERE, _POINT, _SEGMENT), kind2), shape2[1], shape2[2],
              shape2[3], shape2[4], ti.select(core == 0, 0.0, margin))
        cutoff = ti.select(core == 0, full1 + full2, 0.0)
        n, x1, x2, dist, separated, cache1, cache2 = _gjk(s1, s2, cutoff > 0, cutoff, cache1, cache2, hull, ws, row)
        kind, slots, nslots = KIND_CORE, ti.Vector([0, 1, 2]), n
        if core == 0:
            if dist > CCD_TOLERANCE:  # shallow: inflate the cores' closest points
                done = 1
                if full1 != 0 or full2 != 0:
                    normal = _normalize(x2 - x1)
                    x1 += full1 * normal
                    x2 += (-full2) * normal
                    dist -= full1 + full2
                nx = 1
        else:
            done = 1
            if dist <= CCD_TOLERANCE and n > 1 and not separated:
                found, face, x1, x2, dist, truncated, cache1, cache2 = _epa(s1, s2, n, cache1, cache2, hull, ws,
                                                                           row)
                nx, kind, slots, nslots = found, KIND_EPA, face, 3
                if kind1 == SPHERE and kind2 == MESH and (truncated or not found):
                    # a sphere's centre in a mesh's hull (pass 0: its core touches): EPA's curved
                    # polytope around many hull facets can stop far from the nearest one (20° off,
                    # 35 iterations, a KUKA link's hull), or fail; the exact answer is cheap here
                    x1, x2, dist = _sphere_in_mesh(s1, s2, hull, ws, row)
                    nx, face = 1, ti.Vector([0, 1, 2])
                    slots = face
        if nx == 1:
            _write_witness(s1, s2, ws, row, x1, x2, dist, kind, slots, nslots)
            if multi and kind == KIND_EPA:  # MuJoCo 4.0's clipping for shallow contacts is not reproduced
                nx = ti.max(nx, _multicontact(s1, s2, slots, nslots, x1, x2, hull, ws, row))
    return nx


# ----------------------------------------------------------------------------- colliders

@ti.func
def _budget(type1, type2):
    """MuJoCo 4.0's contact budget of one convex pair: 4 between boxes, meshes and cylinders, 2
    for a capsule against a capsule or one of those, else 1."""
    flat1 = type1 == BOX or type1 == MESH or type1 == CYLINDER
    flat2 = type2 == BOX or type2 == MESH or type2 == CYLINDER
    budget = 1
    if flat1 and flat2:
        budget = 4
    elif (type1 == CAPSULE and (flat2 or type2 == CAPSULE)) or (type2 == CAPSULE and flat1):
        budget = 2
    return budget


@ti.func
def convex_convex(type1, pos1, rot1, size1, mesh1, type2, pos2, rot2, size2, mesh2, margin,
                  hull: ti.template(), ws: ti.template(), row: ti.template()):
    """Contacts between two convex geoms (MuJoCo 4.0's mjc_Convex, nativeccd), for the pairs
    sphere-mesh, capsule-cylinder, capsule-mesh, cylinder-cylinder, cylinder-box, cylinder-mesh,
    box-mesh, mesh-mesh (type1 <= type2, MuJoCo's type codes).

    pos (3,) m and rot (3, 3) (columns = geom axes) are world poses, size MuJoCo's geom sizes,
    mesh the mesh id in `hull` (-1 if not a mesh), margin (m) the pair's margin (+ gap); hull
    holds the meshes (MeshHulls' arrays), ws[row..., :] this env's workspace (SCRATCH).
    Returns count (0..CONVEX_MAX), position (CONVEX_MAX, 3) world m, normal (CONVEX_MAX, 3) from
    geom 1 to geom 2, dist (CONVEX_MAX,) m, feature (CONVEX_MAX, FEATURE_SIZE) (module doc).
    """
    position, normal = ti.Matrix.zero(float, CONVEX_MAX, 3), ti.Matrix.zero(float, CONVEX_MAX, 3)
    dist = ti.Vector.zero(float, CONVEX_MAX)
    feature = ti.Matrix.zero(ti.i32, CONVEX_MAX, FEATURE_SIZE)
    nx = _ccd((type1, mesh1, pos1, rot1, size1, margin), (type2, mesh2, pos2, rot2, size2, margin),
              _budget(type1, type2) > 1, hull, ws, row)
    deepest = _BIG
    for i in range(nx):
        deepest = ti.min(deepest, ws.ccd_f[row + (_F_WIT + i,)])
    count = 0
    if deepest < 0:
        count = nx
        for i in ti.static(range(CONVEX_MAX)):
            if i < nx:
                x1, x2 = ws.ccd_v[row + (_V_WIT + i,)], ws.ccd_v[row + (_V_WIT + 4 + i,)]
                point, unit = (x1 + x2) * 0.5, _normalize(x1 - x2)
                for c in ti.static(range(3)):
                    position[i, c], normal[i, c] = point[c], unit[c]
                dist[i] = margin + ws.ccd_f[row + (_F_WIT + i,)]
                for c in ti.static(range(FEATURE_SIZE)):
                    feature[i, c] = ws.ccd_i[row + (_I_WIT + i * FEATURE_SIZE + c,)]
    # a cylinder standing on a box's face or a wider cylinder's cap (cap or rim), or lying on either (side)
    mode1, mode2 = feature[0, 10] % 3, feature[0, 10] // 3
    on_box = type2 == BOX  # (standing on its cap or rim, or lying on its side)
    # the narrower cylinder stands (or lies) on the other (a capsule lies on the cylinder)
    second = int(type1 == CYLINDER and type2 == CYLINDER and size2[0] < size1[0])
    on_cap = type2 == CYLINDER and ti.select(second == 0, mode2, mode1) != 2  # (the wider met at its cap or rim)
    lies = type1 == CAPSULE and type2 == CYLINDER  # (a capsule on a cylinder's cap: only lying, `_face_cap`)
    if (type1 == CYLINDER or lies) and count <= 1 and (on_box or on_cap or type2 == MESH):
        # the collider's normal picks a lying cylinder's face; when it found none, the centres' line
        met = _normalize(ti.select(count == 1, ti.Vector([normal[0, c] for c in ti.static(range(3))]), pos2 - pos1))
        n_face, face_position, face_normal, face_dist, face_feature, upright, off_face, on_face, toward, corners = \
            _face_cap((type1, mesh1, pos1, rot1, size1, margin), (type2, mesh2, pos2, rot2, size2, margin), second,
                      met, hull)
        # the collider's contact stays first when tilted beyond RIM_TILT on its rim (the lowest rim
        # point, which the four points, a square inscribed in the rim, reach only when the tilt is
        # along an axis) or when some point fell off the face (the cap over the edge meets the box
        # there or under its centre); never beside a box face's corners
        keep = int(count == 1 and not corners and (off_face or (ti.select(second == 0, mode1, mode2) == 0 and ti.static(
            np.cos(STANDING_TILT)) <= upright <= ti.static(np.cos(RIM_TILT)))))
        agree = met[0] * toward[0] + met[1] * toward[1] + met[2] * toward[2]
        # the collider met the cylinder across the face (else elsewhere: a can on the floor whose rim
        # touches a low box's side has its centre above the box's top, whose plane is not where
        # they meet: a rim point on that face 4 cm "deep" launched it at 13 m/s); its normal may point
        # the wrong way (its iterate at a pose exactly touching, 2 r deep: a kick of 16 rad/s), and
        # then the face's points replace it even when there are none
        across = on_face and ti.abs(agree) >= ti.static(np.cos(STANDING_TILT))
        deepest_face = _BIG
        for i in ti.static(range(CONVEX_MAX)):
            if i < n_face:
                deepest_face = ti.min(deepest_face, face_dist[i])
        if count == 0:  # GJK found them apart within its tolerance: only points as shallow (MISSED_DEPTH)
            across = on_face and deepest_face >= -MISSED_DEPTH
        if across and agree < 0.0:
            keep, count = 0, 0
        if across and n_face > 0:
            shallowest = -1
            if keep and n_face == CONVEX_MAX:  # (the budget: the shallowest point gives way)
                shallowest = 0
                for i in ti.static(range(1, CONVEX_MAX)):
                    if face_dist[i] > face_dist[shallowest]:
                        shallowest = i
            slot = keep
            for i in ti.static(range(CONVEX_MAX)):
                if i < n_face and i != shallowest:
                    for c in ti.static(range(3)):
                        position[slot, c], normal[slot, c] = face_position[i, c], face_normal[i, c]
                    dist[slot] = face_dist[i]
                    for c in ti.static(range(FEATURE_SIZE)):
                        feature[slot, c] = face_feature[i, c]
                    slot += 1
            count = slot
    # a capsule or cylinder lying on a mesh's face: the two ends of its line (the collider's one
    # contact let a capsule on a mesh box see-saw at 0.07 m/s for good, MuJoCo's two rest)
    if (type1 == CAPSULE or type1 == CYLINDER) and type2 == MESH and count == 1:
        count, position, normal, dist, feature = _lying_on_mesh(
            (type1, mesh1, pos1, rot1, size1, margin), (type2, mesh2, pos2, rot2, size2, margin), hull, count,
            position, normal, dist, feature)
    return count, position, normal, dist, feature


@ti.func
def prism_convex(pos1, rot1, grid, triangle, type2, pos2, rot2, size2, mesh2, hull: ti.template(),
                 ws: ti.template(), row: ti.template()):
    """The contact of one height-field prism (geom 1: the prism under `triangle` of the grid hull
    `grid`, hfield.py) with a convex geom (geom 2), as MuJoCo's mjc_ConvexHField takes it from
    mjc_penetration: one mjc_ccd run without multi-contact, no margin. Arguments and the contact
    (found, position (1, 3), normal (1, 3), dist (1,), feature (1, FEATURE_SIZE)) as
    convex_convex's, for at most one contact."""
    position, normal = ti.Matrix.zero(float, 1, 3), ti.Matrix.zero(float, 1, 3)
    dist, feature = ti.Vector.zero(float, 1), ti.Matrix.zero(ti.i32, 1, FEATURE_SIZE)
    nx = _ccd((HFIELD, grid, pos1, rot1, triangle, 0.0), (type2, mesh2, pos2, rot2, size2, 0.0), False, hull, ws,
              row)
    found = nx > 0 and ws.ccd_f[row + (_F_WIT,)] < 0
    if found:
        x1, x2 = ws.ccd_v[row + (_V_WIT,)], ws.ccd_v[row + (_V_WIT + 4,)]
        point, unit = (x1 + x2) * 0.5, _normalize(x1 - x2)
        for c in ti.static(range(3)):
            position[0, c], normal[0, c] = point[c], unit[c]
        dist[0] = ws.ccd_f[row + (_F_WIT,)]
        for c in ti.static(range(FEATURE_SIZE)):
            feature[0, c] = ws.ccd_i[row + (_I_WIT + c,)]
    return int(found), position, normal, dist, feature


@ti.func
def _lying_on_mesh(shape1: ti.template(), shape2: ti.template(), hull: ti.template(), count, position, normal, dist,
                   feature):
    """A capsule or cylinder (geom 1) lying on a face of a mesh (geom 2): its axis within LYING_TILT
    of the face's plane, the collider's one contact's normal (row 0 of `normal`) within _FACE_TOL of
    the face's inward normal. Its line, clipped to the face (seen along the face's normal), touches
    it at the clipped line's two ends, each a KIND_CORE contact (`_core_evaluate`, its closed form,
    whose adjoint is the core's): an end of the line over the face against the plane of three of
    the face's vertices (`_polygon_spread`), or where the line crosses an edge of the face, the
    line against that edge (a line lying across a narrower face). When both are within the margin,
    they replace the contacts (count, position, normal, dist, feature: convex_convex's), the deeper
    first; else those are returned as they are."""
    rot1, rot2, mesh2, margin = shape1[3], shape2[3], shape2[1], shape1[5]
    met = ti.Vector([normal[0, c] for c in ti.static(range(3))])
    ends_position, ends_normal = ti.Matrix.zero(float, 2, 3), ti.Matrix.zero(float, 2, 3)
    ends_dist = ti.Vector.zero(float, 2)
    rows = ti.Matrix.zero(ti.i32, 2, FEATURE_SIZE)
    kept = 0
    axis = _column(rot1, 2)
    if ti.abs(_dot(axis, met)) <= ti.static(np.sin(LYING_TILT)):
        face, facing = _facing_polygon(hull, mesh2, _rot_t(rot2, -met))
        if facing >= ti.static(_FACE_TOL):
            poly = hull.hull_polyadr[mesh2] + face
            vadr, vert_adr, num = hull.hull_vertadr[mesh2], hull.hull_poly_vertadr[poly], hull.hull_poly_vertnum[poly]
            local_n = hull.hull_poly_normal[poly]
            inward = -_rot(rot2, local_n)
            code = encode_direction(inward)
            # the line (mesh frame) clipped to the face: t in [low, high] over it, and the edges cut there
            start = _rot_t(rot2, shape1[2] - axis * shape1[4][1] - shape2[2])
            low, high, low_edge, high_edge = _clip_line(hull, mesh2, face, start,
                                                        _rot_t(rot2, 2.0 * shape1[4][1] * axis), 0.0, 1.0)
            if low < high:
                j, k = _polygon_spread(hull, mesh2, face)
                for end in range(2):  # one evaluation: inlined once
                    edge = ti.select(end == 0, low_edge, high_edge)
                    row = ti.Vector([KIND_CORE, end, hull.hull_poly_vert[vert_adr], end,
                                     hull.hull_poly_vert[vert_adr + j], end, hull.hull_poly_vert[vert_adr + k], 3,
                                     code[0], code[1], _cylinder_modes(shape1, shape2, inward)])
                    if edge >= 0:  # the line against the edge it crosses
                        first, second = hull.hull_poly_vert[vert_adr + edge], hull.hull_poly_vert[
                            vert_adr + _wrap(edge + 1, num)]
                        row[1], row[2], row[3], row[4], row[5], row[6] = 0, first, 1, first, 0, second
                    point, unit, depth = _core_evaluate(shape1, shape2, row, hull)
                    kept += int(depth < margin)
                    for c in ti.static(range(3)):
                        ends_position[end, c], ends_normal[end, c] = point[c], unit[c]
                    ends_dist[end] = depth
                    for c in ti.static(range(FEATURE_SIZE)):
                        rows[end, c] = row[c]
    if kept == 2:
        deeper = ti.select(ends_dist[1] < ends_dist[0], 1, 0)
        for i in ti.static(range(2)):
            end = ti.select(i == 0, deeper, 1 - deeper)
            for c in ti.static(range(3)):
                position[i, c], normal[i, c] = ends_position[end, c], ends_normal[end, c]
            dist[i] = ends_dist[end]
            for c in ti.static(range(FEATURE_SIZE)):
                feature[i, c] = rows[end, c]
    return ti.select(kept == 2, 2, count), position, normal, dist, feature


@ti.func
def _facing_polygon(hull: ti.template(), mesh, up):
    """(polygon id (mesh-local), the cosine of its normal with `up`) of the polygon that faces
    direction `up` (the mesh's frame, unit) most among those at the mesh's vertex farthest along it."""
    vadr, padr = hull.hull_vertadr[mesh], hull.hull_polyadr[mesh]
    farthest = _mesh_support(mesh, up, -1, hull)
    face, facing = 0, -2.0
    for i in range(hull.hull_vert_polynum[vadr + farthest]):
        poly = hull.hull_polymap[hull.hull_vert_polyadr[vadr + farthest] + i]
        along = _dot(up, hull.hull_poly_normal[padr + poly])
        if along > facing:
            face, facing = poly, along
    return face, facing


@ti.func
def _clip_line(hull: ti.template(), mesh, face, start, along, low, high):
    """The line start + t along (the mesh's frame), t in [low, high], clipped to polygon `face`'s
    prism (seen along its normal): (low, high) over the face (low >= high: it misses), and the
    edges (from the polygon's vertex at that position to the next) it enters and leaves through
    (-1 where the bound given stays). A lying line's ends (`_lying_on_mesh`), a rim point's ray
    from the cap's centre (`_face_cap`: the edge it leaves through, EDGE)."""
    poly = hull.hull_polyadr[mesh] + face
    vadr, padr, num = hull.hull_vertadr[mesh], hull.hull_poly_vertadr[poly], hull.hull_poly_vertnum[poly]
    low_edge, high_edge = -1, -1
    for i in range(num):
        a = _polygon_point(hull, vadr, padr, num, i)
        side = _cross(_polygon_point(hull, vadr, padr, num, i + 1) - a, hull.hull_poly_normal[poly])  # (outward)
        at, rate = -_dot(side, start - a), -_dot(side, along)  # over the face where at + rate t >= 0
        if rate > 0.0 and -at / rate > low:
            low, low_edge = -at / rate, i
        elif rate < 0.0 and -at / rate < high:
            high, high_edge = -at / rate, i
        elif rate == 0.0 and at < 0.0:
            low = high + 1.0  # (parallel to this edge, outside it)
    return low, high, low_edge, high_edge


@ti.func
def _polygon_spread(hull: ti.template(), mesh, face):
    """Positions (j, k) in polygon `face` of the mesh such that vertices 0, j, k span it well: j
    the farthest from vertex 0, k the farthest from their line (three fixed positions, 0, n/3,
    2n/3, could lie on one nearly straight edge of many vertices, whose foot was then centimetres
    off)."""
    poly = hull.hull_polyadr[mesh] + face
    vadr, padr, num = hull.hull_vertadr[mesh], hull.hull_poly_vertadr[poly], hull.hull_poly_vertnum[poly]
    first = _polygon_point(hull, vadr, padr, num, 0)
    j, k, far, wide = 1, 2, -1.0, -1.0
    for i in range(1, num):
        span = _polygon_point(hull, vadr, padr, num, i) - first
        if _dot(span, span) > far:
            j, far = i, _dot(span, span)
    line = _polygon_point(hull, vadr, padr, num, j) - first
    for i in range(1, num):
        area = _cross(line, _polygon_point(hull, vadr, padr, num, i) - first)
        if _dot(area, area) > wide:
            k, wide = i, _dot(area, area)
    return j, k


@ti.func
def _on_polygon(hull: ti.template(), mesh, face, point, skip):
    """Whether `point` (the mesh's frame) lies over polygon `face` (mesh-local id) of the mesh: its
    foot on the polygon's plane left of each edge, counter-clockwise seen from outside, but edge
    `skip` (from vertex `skip` to the next; -1: none), which the point lies on by construction."""
    poly = hull.hull_polyadr[mesh] + face
    vadr, padr, num = hull.hull_vertadr[mesh], hull.hull_poly_vertadr[poly], hull.hull_poly_vertnum[poly]
    inside = True
    for j in range(num):
        a = _polygon_point(hull, vadr, padr, num, j)
        if j != skip and _dot(_cross(_polygon_point(hull, vadr, padr, num, j + 1) - a, point - a),
                              hull.hull_poly_normal[poly]) < 0.0:
            inside = False
    return inside


@ti.func
def _polygon_point(hull: ti.template(), vadr, padr, num, i):
    """Mesh-frame vertex number i (wrapped) of the polygon whose vertex list is at padr."""
    return hull.hull_vert[vadr + hull.hull_poly_vert[padr + _wrap(i, num)]]


@ti.func
def _quad_on(hull: ti.template(), vadr, padr, num, s, b, c, d):
    """Area of quadrilateral (s, b, c, d) of a polygon: half the norm of its diagonals' cross
    product (mesh frame)."""
    a_c = _polygon_point(hull, vadr, padr, num, s) - _polygon_point(hull, vadr, padr, num, c)
    b_d = _polygon_point(hull, vadr, padr, num, b) - _polygon_point(hull, vadr, padr, num, d)
    g = _cross(a_c, b_d)
    return 0.5 * ti.sqrt(_dot(g, g))


@ti.func
def plane_mesh(pos1, rot1, size1, pos2, rot2, size2, mesh2, centre2, margin, hull: ti.template()):
    """Contacts between a plane (geom 1: normal = its z axis, through pos1) and a mesh (geom 2),
    as MuJoCo 4.0's mjc_PlaneConvex (read from its compiled code): the mesh's support vertex
    along -normal, then the other vertices of the hull polygon at it that faces the plane most
    (for more than 4, a large quadrilateral through the support vertex, grown greedily), those
    within `margin` of the plane and on the plane's side of the mesh centre. Contacts at the
    vertices moved half their depth along the normal.

    Arguments as convex_convex (size1, size2 unused, no workspace), and centre2 (3,): the mesh's
    centre in its frame (its hull's vertex mean: always inside). MuJoCo's test is against the geom's origin, which
    is the mesh's centre there (it moves a mesh's frame to its centre of mass); a mesh file's
    origin may lie anywhere (at its base, below it), where that test dropped every vertex but the
    deepest and the body never came to rest. Returns as convex_convex, budget PLANE_MESH_MAX;
    features KIND_PLANE with the vertex id.
    """
    position = ti.Matrix.zero(float, PLANE_MESH_MAX, 3)
    normal_out = ti.Matrix.zero(float, PLANE_MESH_MAX, 3)
    dist = ti.Vector.zero(float, PLANE_MESH_MAX)
    feature = ti.Matrix.zero(ti.i32, PLANE_MESH_MAX, FEATURE_SIZE)
    normal = ti.Vector([rot1[0, 2], rot1[1, 2], rot1[2, 2]])
    local_n = _rot_t(rot2, normal)
    vadr = hull.hull_vertadr[mesh2]
    deepest = _mesh_support(mesh2, _rot_t(rot2, -normal), -1, hull)
    count = 0
    point = _rot(rot2, hull.hull_vert[vadr + deepest]) + pos2
    depth = _dot(normal, point - pos1)
    if depth <= margin:
        # the polygon at the support vertex that faces the plane most
        face, facing = -1, 1.0
        padr = hull.hull_vert_polyadr[vadr + deepest]
        for i in range(hull.hull_vert_polynum[vadr + deepest]):
            poly = hull.hull_polymap[padr + i]
            d = _dot(local_n, hull.hull_poly_normal[hull.hull_polyadr[mesh2] + poly])
            if facing > d:
                face = poly
            facing = ti.min(d, facing)
        picks = ti.Vector([0, 1, 2, 3])
        num = 1
        vert_adr = 0
        if face >= 0:
            poly = hull.hull_polyadr[mesh2] + face
            vert_adr, num = hull.hull_poly_vertadr[poly], hull.hull_poly_vertnum[poly]
            s = 0
            for j in range(num):
                if s == 0 and hull.hull_poly_vert[vert_adr + j] == deepest:
                    s = j
            picks = ti.Vector([s, _wrap(s + 1, num), _wrap(s + 2, num), _wrap(s + 3, num)])
            if num >= 5:  # grow a large quadrilateral s, b, c, d: advance d, then c, then b
                b, c, d = picks[1], picks[2], picks[3]
                area = _quad_on(hull, vadr, vert_adr, num, s, b, c, d)
                while True:
                    area2 = _quad_on(hull, vadr, vert_adr, num, s, b, c, _wrap(d + 1, num))
                    if area >= area2:
                        break
                    d, area = _wrap(d + 1, num), area2
                    while True:
                        area2 = _quad_on(hull, vadr, vert_adr, num, s, b, _wrap(c + 1, num), d)
                        if not area < area2:
                            break
                        c, area = _wrap(c + 1, num), area2
                    while True:
                        area2 = _quad_on(hull, vadr, vert_adr, num, s, _wrap(b + 1, num), c, d)
                        if not area < area2:
                            break
                        b, area = _wrap(b + 1, num), area2
                picks = ti.Vector([s, b, c, d])
                num = 4
        centre = _rot(rot2, centre2) + pos2  # (world)
        for k in ti.static(range(PLANE_MESH_MAX)):
            vertex = deepest
            keep = k == 0
            if k > 0 and k < num:
                vertex = hull.hull_poly_vert[vert_adr + picks[k]]
                point = _rot(rot2, hull.hull_vert[vadr + vertex]) + pos2
                depth = _dot(normal, point - pos1)
                keep = depth <= margin and not _dot(normal, point - centre) > 0
            if keep:
                contact = point + normal * (depth * -0.5)
                for c in ti.static(range(3)):
                    position[count, c], normal_out[count, c] = contact[c], normal[c]
                dist[count] = depth
                feature[count, 0], feature[count, 1] = KIND_PLANE, vertex
                count += 1
    return count, position, normal_out, dist, feature


# ----------------------------------------------------------------------------- replay
# A contact replayed from its feature row as a closed form of the two geom poses, and that closed
# form's hand-written reverse. The colliders never call these: detect.converge_contacts makes an
# iterate its closed form in the forward, and a backward calls the reverses per contact.
# pos (3,) m, rot (3, 3) as 9 independent numbers (a non-orthonormal rot gives the formula's value,
# the rotation gradient is its projection); the adjoints return d(g_position . position +
# g_normal . normal + g_dist . dist) / d(pos1, rot1, pos2, rot2).

@ti.func
def _normalize_adjoint(v, g):
    """Gradient with respect to v of g . _normalize(v); 0 below the 1e-15 floor, where
    _normalize is the constant (1, 0, 0)."""
    norm = ti.sqrt(_dot(v, v))
    out = ti.Vector([0.0, 0.0, 0.0])
    if norm >= _MINVAL:
        unit = v * (1.0 / norm)
        out = (g - unit * _dot(unit, g)) * (1.0 / norm)
    return out


@ti.func
def _witness_adjoint(x1, x2, g_position, g_normal):
    """Gradients with respect to the witness points x1, x2 of g_position . (x1 + x2) / 2 +
    g_normal . _normalize(x1 - x2), the contact's position and normal."""
    g_delta = _normalize_adjoint(x1 - x2, g_normal)
    return 0.5 * g_position + g_delta, 0.5 * g_position - g_delta


@ti.func
def _support_local(shape: ti.template(), vid, hull: ti.template()):
    """Geom-frame point of a `_support` id: box corner, mesh or prism vertex, the +z (1) / -z (0) end of
    a capsule's or cylinder's segment (size[1] from the centre); the centre for a sphere or
    id < 0."""
    local = ti.Vector([0.0, 0.0, 0.0])
    if vid >= 0:
        if shape[0] == BOX:
            local = _corner_local(shape[4], vid)
        elif shape[0] == MESH or shape[0] == HFIELD:
            local = hull.hull_vert[hull.hull_vertadr[shape[1]] + vid]
        elif shape[0] == CAPSULE or shape[0] == CYLINDER:
            local[2] = ti.select(vid == 1, shape[4][1], -shape[4][1])
    return local


@ti.func
def _ball(shape: ti.template(), mode):
    """Radius (m) of the ball that sweeps a geom's core in CCD: the sphere's or capsule's radius,
    a cylinder's on its side (mode 2: the normal is across the axis, where its disk acts as a
    ball), plus half the pair margin (shape[5])."""
    radius = ti.select(shape[0] == SPHERE or shape[0] == CAPSULE or mode == 2, shape[4][0], 0.0)
    return 0.5 * shape[5] + radius


@ti.func
def _disk_local(shape: ti.template(), mode, direction):
    """Geom-frame support point, along the world `direction`, of a cylinder's disk (radius
    size[0] in its xy plane; the cylinder is its segment swept by it) at its rim (mode 0): 0 for
    other kinds and modes and along the axis, as `_support`."""
    local = ti.Vector([0.0, 0.0, 0.0])
    if shape[0] == CYLINDER and mode == 0:
        local_dir = _rot_t(shape[3], direction)
        planar2 = local_dir[0] * local_dir[0] + local_dir[1] * local_dir[1]
        if planar2 >= _MINVAL2:
            scale = shape[4][0] / ti.sqrt(planar2)
            local = ti.Vector([scale * local_dir[0], scale * local_dir[1], 0.0])
    return local


@ti.func
def _disk_adjoint(shape: ti.template(), mode, direction, g_disk):
    """Reverse of disk = rot @ _disk_local(shape, mode, direction): (g_direction (3,), g_rot
    (3, 3)) from g_disk (3,)."""
    g_direction, g_rot = ti.Vector([0.0, 0.0, 0.0]), ti.Matrix.zero(float, 3, 3)
    if shape[0] == CYLINDER and mode == 0:
        local_dir = _rot_t(shape[3], direction)
        planar2 = local_dir[0] * local_dir[0] + local_dir[1] * local_dir[1]
        if planar2 >= _MINVAL2:
            scale = shape[4][0] / ti.sqrt(planar2)
            g_local = _rot_t(shape[3], g_disk)
            along = (g_local[0] * local_dir[0] + g_local[1] * local_dir[1]) / planar2
            # local = size[0] * (l_x, l_y) / |(l_x, l_y)|, l = rot^T direction
            g_dir_local = ti.Vector([scale * (g_local[0] - along * local_dir[0]),
                                     scale * (g_local[1] - along * local_dir[1]), 0.0])
            g_direction = _rot(shape[3], g_dir_local)
            g_rot = g_disk.outer_product(_disk_local(shape, mode, direction)) + direction.outer_product(g_dir_local)
    return g_direction, g_rot


@ti.func
def _vertex_ids(feature):
    """The distinct (id on geom 1, id on geom 2) pairs among a KIND_CORE / KIND_EPA feature's
    feature[7] vertices, in order: (m = their number - 1, ids on geom 1 (3,), ids on geom 2 (3,));
    slots past m repeat vertex 0."""
    ids1 = ti.Vector([feature[1], feature[3], feature[5]])
    ids2 = ti.Vector([feature[2], feature[4], feature[6]])
    keep1 = feature[7] > 1 and (ids1[1] != ids1[0] or ids2[1] != ids2[0])
    keep2 = feature[7] > 2 and (ids1[2] != ids1[0] or ids2[2] != ids2[0]) and (
        not keep1 or ids1[2] != ids1[1] or ids2[2] != ids2[1])
    m = int(keep1) + int(keep2)
    second = ti.select(keep1, 1, 2)
    out1 = ti.Vector([ids1[0], ti.select(m > 0, ids1[second], ids1[0]), ti.select(m == 2, ids1[2], ids1[0])])
    out2 = ti.Vector([ids2[0], ti.select(m > 0, ids2[second], ids2[0]), ti.select(m == 2, ids2[2], ids2[0])])
    return m, out1, out2


@ti.func
def _core_locals(shape1: ti.template(), shape2: ti.template(), ids1, ids2, hull: ti.template()):
    """Geom-frame points (3 rows per geom) of the vertices of a CORE / EPA feature (ids (3,) per
    geom)."""
    local1, local2 = ti.Matrix.zero(float, 3, 3), ti.Matrix.zero(float, 3, 3)
    for v in range(6):  # one lookup in a loop: inlined once
        first = v < 3
        j = ti.select(first, v, v - 3)
        point = _support_local(_pick_shape(first, shape1, shape2), ti.select(first, ids1, ids2)[j], hull)
        for c in ti.static(range(3)):
            if first:
                local1[j, c] = point[c]
            else:
                local2[j, c] = point[c]
    return local1, local2


@ti.func
def _core_terms(shape1: ti.template(), shape2: ti.template(), feature, hull: ti.template()):
    """The closed form of a KIND_CORE / KIND_EPA contact, every intermediate returned (its
    adjoint recomputes them). Each geom is a core (point, segment, box, mesh) swept by a ball
    (`_ball`) and, for a cylinder at its rim, by a disk (`_disk_local`). The feature's vertices
    give points a_j on core 1 and b_j on core 2 (j <= m, distinct pairs), w_j = a_j - b_j; the
    contact normal n (from geom 1 to geom 2) is
    - m = 2: the unit normal of the plane of the w_j (the final EPA face or GJK triangle),
      oriented as the forward's normal u (feature columns 8, 9);
    - m < 2: the direction from the closest point of the w_j's line (or point) to the origin
      (the cores' closest points; a cylinder at its rim whose feature holds both its ends, its
      axis, is then met on its side, as the converged contact is).
    The balls and disks add their supports along n (geom 1) and -n (geom 2) to every vertex;
    the witness points x1, x2 apply the weights (lam: of w_1 - w_0, w_2 - w_0) of the point of
    that (moved) line or plane closest to the origin to each geom's points.
    Returns (m, locals of a_j (3 rows), locals of b_j, a_0..2, b_0..2, modes (2,), u, pre (n
    before normalising), n, disk 1, disk 2, lam (2,), x1, x2)."""
    m, ids1, ids2 = _vertex_ids(feature)
    modes = ti.Vector([feature[10] % 3, feature[10] // 3])
    local1, local2 = _core_locals(shape1, shape2, ids1, ids2, hull)
    a0, a1, a2 = [_rot(shape1[3], ti.Vector([local1[j, c] for c in ti.static(range(3))])) + shape1[2]
                  for j in ti.static(range(3))]
    b0, b1, b2 = [_rot(shape2[3], ti.Vector([local2[j, c] for c in ti.static(range(3))])) + shape2[2]
                  for j in ti.static(range(3))]
    w0, e1, e2 = a0 - b0, (a1 - b1) - (a0 - b0), (a2 - b2) - (a0 - b0)
    u = decode_direction(feature[8], feature[9])
    pre = _cross(e1, e2)
    if m == 2:
        pre = pre * _sign(_dot(pre, u))
    else:
        pre = -w0
        if m == 1:
            pre = pre - e1 * (_dot(e1, pre) / _dot(e1, e1))
    n = _normalize(pre)
    disk1 = _rot(shape1[3], _disk_local(shape1, modes[0], n))
    disk2 = _rot(shape2[3], _disk_local(shape2, modes[1], n))
    w0_swept = w0 + (_ball(shape1, modes[0]) + _ball(shape2, modes[1])) * n + disk1 + disk2
    lam = ti.Vector([0.0, 0.0])
    g11, g12, g22 = _dot(e1, e1), _dot(e1, e2), _dot(e2, e2)
    r1, r2 = -_dot(e1, w0_swept), -_dot(e2, w0_swept)
    if m == 2:
        det = g11 * g22 - g12 * g12
        lam = ti.Vector([(g22 * r1 - g12 * r2) / det, (g11 * r2 - g12 * r1) / det])
    elif m == 1:
        lam[0] = r1 / g11
    x1 = a0 + lam[0] * (a1 - a0) + lam[1] * (a2 - a0) + _ball(shape1, modes[0]) * n + disk1
    x2 = b0 + lam[0] * (b1 - b0) + lam[1] * (b2 - b0) - _ball(shape2, modes[1]) * n - disk2
    return m, local1, local2, a0, a1, a2, b0, b1, b2, modes, u, pre, n, disk1, disk2, lam, x1, x2


@ti.func
def _core_evaluate(shape1: ti.template(), shape2: ti.template(), feature, hull: ti.template()):
    """(position, normal, dist) of a KIND_CORE / KIND_EPA contact (`_core_terms`): the witness
    points' midpoint, n, and margin minus the swept shapes' overlap along n."""
    terms = _core_terms(shape1, shape2, feature, hull)
    n, x1, x2 = terms[12], terms[16], terms[17]
    return (x1 + x2) * 0.5, n, shape1[5] - _dot(x1 - x2, n)


@ti.func
def _core_evaluate_adjoint(shape1: ti.template(), shape2: ti.template(), feature, hull: ti.template(),
                           g_position, g_normal, g_dist):
    """Reverse of `_core_evaluate`: (g_pos1, g_rot1, g_pos2, g_rot2)."""
    m, local1, local2, a0, a1, a2, b0, b1, b2, modes, u, pre, n, disk1, disk2, lam, x1, x2 = _core_terms(
        shape1, shape2, feature, hull)
    ball1, ball2 = _ball(shape1, modes[0]), _ball(shape2, modes[1])
    w0, e1, e2 = a0 - b0, (a1 - b1) - (a0 - b0), (a2 - b2) - (a0 - b0)
    g_x1 = 0.5 * g_position - g_dist * n
    g_x2 = 0.5 * g_position + g_dist * n
    g_n = g_normal - g_dist * (x1 - x2) + ball1 * g_x1 - ball2 * g_x2
    g_a = ti.Matrix.rows([(1.0 - lam[0] - lam[1]) * g_x1, lam[0] * g_x1, lam[1] * g_x1])
    g_b = ti.Matrix.rows([(1.0 - lam[0] - lam[1]) * g_x2, lam[0] * g_x2, lam[1] * g_x2])
    g_lam = ti.Vector([_dot(g_x1, a1 - a0) + _dot(g_x2, b1 - b0), _dot(g_x1, a2 - a0) + _dot(g_x2, b2 - b0)])
    # lam = G^-1 r, G the Gram matrix of e1, e2, r = -(e1, e2) . w0_swept
    w0_swept = w0 + (ball1 + ball2) * n + disk1 + disk2
    g11, g12, g22 = _dot(e1, e1), _dot(e1, e2), _dot(e2, e2)
    g_r = ti.Vector([0.0, 0.0])
    if m == 2:
        det = g11 * g22 - g12 * g12
        g_r = ti.Vector([(g22 * g_lam[0] - g12 * g_lam[1]) / det, (g11 * g_lam[1] - g12 * g_lam[0]) / det])
    elif m == 1:
        g_r[0] = g_lam[0] / g11
    g_e1 = -2.0 * g_r[0] * lam[0] * e1 - (g_r[0] * lam[1] + g_r[1] * lam[0]) * e2 - g_r[0] * w0_swept
    g_e2 = -2.0 * g_r[1] * lam[1] * e2 - (g_r[0] * lam[1] + g_r[1] * lam[0]) * e1 - g_r[1] * w0_swept
    g_w0 = -g_r[0] * e1 - g_r[1] * e2  # through w0_swept
    g_n += (ball1 + ball2) * g_w0
    g_n1, g_rot1 = _disk_adjoint(shape1, modes[0], n, g_x1 + g_w0)
    g_n2, g_rot2 = _disk_adjoint(shape2, modes[1], n, g_w0 - g_x2)
    g_pre = _normalize_adjoint(pre, g_n + g_n1 + g_n2)
    if m == 2:  # pre = +-e1 x e2
        g_cross = g_pre * _sign(_dot(_cross(e1, e2), u))
        g_e1 += _cross(e2, g_cross)
        g_e2 += _cross(g_cross, e1)
    else:
        g_base = g_pre
        if m == 1:  # pre = base - e1 t, t = e1 . base / e1 . e1, base = -w0
            t = -_dot(e1, w0) / g11
            g_t = -_dot(g_pre, e1)
            g_e1 += -t * g_pre + g_t * (-w0 - 2.0 * t * e1) / g11
            g_base += g_t * e1 / g11
        g_w0 -= g_base
    g_w = ti.Matrix.rows([g_w0 - g_e1 - g_e2, g_e1, g_e2])
    g_a += g_w
    g_b -= g_w
    g_pos1, g_pos2 = ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0])
    for j in ti.static(range(3)):
        ga = ti.Vector([g_a[j, c] for c in ti.static(range(3))])
        gb = ti.Vector([g_b[j, c] for c in ti.static(range(3))])
        g_pos1 += ga
        g_pos2 += gb
        g_rot1 += ga.outer_product(ti.Vector([local1[j, c] for c in ti.static(range(3))]))
        g_rot2 += gb.outer_product(ti.Vector([local2[j, c] for c in ti.static(range(3))]))
    return g_pos1, g_rot1, g_pos2, g_rot2


# A cylinder on its cap (mode 1): the forward's supports on it are rim points at angles the feature
# does not keep, and a flat cap against an edge or face touches along a line or patch. The closed
# form takes the cap's axis as the normal and, on the other geom, the point of its feature (vertex,
# line or plane) nearest the cap's centre: the foot of the cap's centre, as a single contact of a
# flat-on-flat patch is (no torque from it for a can standing square on a face).
@ti.func
def _cap_side(shape1: ti.template(), shape2: ti.template(), feature):
    """0 when no cylinder of a CORE / EPA contact is on its cap; else which geom (1, 2) the cap
    closed form stands on: the one on its cap, or of two, the smaller radius (the contact lies
    under that cap, which a cap it rests on holds)."""
    cap1 = shape1[0] == CYLINDER and feature[10] % 3 == 1
    cap2 = shape2[0] == CYLINDER and feature[10] // 3 == 1
    side = ti.select(cap1, 1, ti.select(cap2, 2, 0))
    if cap1 and cap2 and shape2[4][0] < shape1[4][0]:
        side = 2
    return side


@ti.func
def _cap_other_locals(other: ti.template(), mode_o, ids, count, hull: ti.template()):
    """(k, geom-frame points (3 rows)) of the feature of the geom facing a cap: its distinct ids
    among the first `count` of `ids` (3,) (k + 1 of them), or, a cylinder on its own cap (mode_o
    1), its cap's centre and that point moved one unit along its x and y axes (k = 2). Rows past
    k repeat row 0."""
    keep1 = count > 1 and ids[1] != ids[0]
    keep2 = count > 2 and ids[2] != ids[0] and ids[2] != ids[1]
    second = ti.select(keep1, ids[1], ids[2])
    k = int(keep1) + int(keep2)
    chosen = ti.Vector([ids[0], ti.select(k > 0, second, ids[0]), ti.select(k == 2, ids[2], ids[0])])
    flat = other[0] == CYLINDER and mode_o == 1
    if flat:
        k = 2
    local = ti.Matrix.zero(float, 3, 3)
    for j in range(3):  # one lookup in a loop: inlined once
        point = _support_local(other, ti.select(flat, ids[0], chosen[j]), hull)
        if flat and j > 0:
            point[j - 1] += 1.0
        for c in ti.static(range(3)):
            local[j, c] = point[c]
    return k, local


@ti.func
def _cap_terms(shape1: ti.template(), shape2: ti.template(), feature, hull: ti.template()):
    """The cap closed form (see above), every intermediate returned. The cap's geom C (side
    `_cap_side`), the other O. n = C's axis oriented as the forward's normal u (from geom 1 to
    geom 2). q = the point nearest C's cap centre c of the flat through O's points o_j (Gram
    solve for mu, weights of f_j = o_j - o_0); O's witness is q moved by its ball and disk
    against n (as `_core_terms`'), C's is that point projected on the cap's plane, moved by C's
    ball (half the margin). sgn = +1 when C is geom 1.
    Returns (first, C, O, c local, O's locals, k, c, o_0..2, mu (2,), q, pre, n, disk_O, x_C,
    x_O, sgn, O's mode)."""
    first = _cap_side(shape1, shape2, feature) == 1
    cap, other = _pick_shape(first, shape1, shape2), _pick_shape(not first, shape1, shape2)
    mode_o = ti.select(first, feature[10] // 3, feature[10] % 3)
    ids_o = ti.select(first, ti.Vector([feature[2], feature[4], feature[6]]),
                      ti.Vector([feature[1], feature[3], feature[5]]))
    c_local = _support_local(cap, ti.select(first, feature[1], feature[2]), hull)
    k, o_local = _cap_other_locals(other, mode_o, ids_o, feature[7], hull)
    if other[0] == CYLINDER and mode_o == 0 and k > 0:  # "at its rim" with both ends: on its side (`_rim_terms`)
        mode_o = 2
    c = _rot(cap[3], c_local) + cap[2]
    o0, o1, o2 = [_rot(other[3], ti.Vector([o_local[j, i] for i in ti.static(range(3))])) + other[2]
                  for j in ti.static(range(3))]
    sgn = ti.select(first, 1.0, -1.0)
    u = decode_direction(feature[8], feature[9])
    axis = ti.Vector([cap[3][0, 2], cap[3][1, 2], cap[3][2, 2]])
    pre = axis * _sign(_dot(axis, u))
    n = _normalize(pre)
    f1, f2, to_c = o1 - o0, o2 - o0, c - o0
    g11, g12, g22 = _dot(f1, f1), _dot(f1, f2), _dot(f2, f2)
    r1, r2 = _dot(f1, to_c), _dot(f2, to_c)
    mu = ti.Vector([0.0, 0.0])
    if k == 2:
        det = g11 * g22 - g12 * g12
        mu = ti.Vector([(g22 * r1 - g12 * r2) / det, (g11 * r2 - g12 * r1) / det])
    elif k == 1:
        mu[0] = r1 / g11
    q = o0 + mu[0] * f1 + mu[1] * f2
    disk_o = _rot(other[3], _disk_local(other, mode_o, n))
    x_o = q - sgn * (_ball(other, mode_o) * n + disk_o)
    x_c = x_o + _dot(c - x_o, n) * n + sgn * _ball(cap, 1) * n
    return first, cap, other, c_local, o_local, k, c, o0, o1, o2, mu, q, pre, n, disk_o, x_c, x_o, sgn, mode_o


@ti.func
def _cap_evaluate(shape1: ti.template(), shape2: ti.template(), feature, hull: ti.template()):
    """(position, normal, dist) of a contact of a cylinder on its cap (`_cap_terms`)."""
    terms = _cap_terms(shape1, shape2, feature, hull)
    first, n, x_c, x_o = terms[0], terms[13], terms[15], terms[16]
    x1, x2 = ti.select(first, x_c, x_o), ti.select(first, x_o, x_c)
    return (x1 + x2) * 0.5, n, shape1[5] - _dot(x1 - x2, n)


@ti.func
def _cap_evaluate_adjoint(shape1: ti.template(), shape2: ti.template(), feature, hull: ti.template(),
                          g_position, g_normal, g_dist):
    """Reverse of `_cap_evaluate`: (g_pos1, g_rot1, g_pos2, g_rot2)."""
    first, cap, other, c_local, o_local, k, c, o0, o1, o2, mu, q, pre, n, disk_o, x_c, x_o, sgn, mode_o = \
        _cap_terms(shape1, shape2, feature, hull)
    x1, x2 = ti.select(first, x_c, x_o), ti.select(first, x_o, x_c)
    g_x1, g_x2 = 0.5 * g_position - g_dist * n, 0.5 * g_position + g_dist * n
    g_n = g_normal - g_dist * (x1 - x2)
    g_xc, g_xo = ti.select(first, g_x1, g_x2), ti.select(first, g_x2, g_x1)
    # x_c = x_o + ((c - x_o) . n) n + sgn ball_c n
    along = _dot(g_xc, n)
    g_xo += g_xc - along * n
    g_c = along * n
    g_n += _dot(c - x_o, n) * g_xc + along * (c - x_o) + sgn * _ball(cap, 1) * g_xc
    # x_o = q - sgn (ball_o n + disk_o)
    g_q = g_xo
    g_n -= sgn * _ball(other, mode_o) * g_xo
    g_dir, g_rot_o = _disk_adjoint(other, mode_o, n, -sgn * g_xo)
    g_n += g_dir
    # q = o0 + mu . f, mu = G^-1 r, G the Gram matrix of f1, f2, r = f . (c - o0)
    f1, f2, to_c = o1 - o0, o2 - o0, c - o0
    g11, g12, g22 = _dot(f1, f1), _dot(f1, f2), _dot(f2, f2)
    g_mu = ti.Vector([_dot(f1, g_q), _dot(f2, g_q)])
    g_r = ti.Vector([0.0, 0.0])
    if k == 2:
        det = g11 * g22 - g12 * g12
        g_r = ti.Vector([(g22 * g_mu[0] - g12 * g_mu[1]) / det, (g11 * g_mu[1] - g12 * g_mu[0]) / det])
    elif k == 1:
        g_r[0] = g_mu[0] / g11
    g_f1 = mu[0] * g_q - 2.0 * g_r[0] * mu[0] * f1 - (g_r[0] * mu[1] + g_r[1] * mu[0]) * f2 + g_r[0] * to_c
    g_f2 = mu[1] * g_q - 2.0 * g_r[1] * mu[1] * f2 - (g_r[0] * mu[1] + g_r[1] * mu[0]) * f1 + g_r[1] * to_c
    g_to_c = g_r[0] * f1 + g_r[1] * f2
    g_c += g_to_c
    g_o = ti.Matrix.rows([g_q - g_f1 - g_f2 - g_to_c, g_f1, g_f2])
    # n = normalize(pre), pre = +-C's axis (column 2 of its rotation)
    g_pre = _normalize_adjoint(pre, g_n)
    g_rot_c = g_c.outer_product(c_local)
    for i in ti.static(range(3)):
        g_rot_c[i, 2] += g_pre[i] * _sign(_dot(pre, ti.Vector([cap[3][0, 2], cap[3][1, 2], cap[3][2, 2]])))
    g_pos_o = ti.Vector([0.0, 0.0, 0.0])
    for j in ti.static(range(3)):
        row = ti.Vector([g_o[j, i] for i in ti.static(range(3))])
        g_pos_o += row
        g_rot_o += row.outer_product(ti.Vector([o_local[j, i] for i in ti.static(range(3))]))
    return (ti.select(first, g_c, g_pos_o), ti.select(first, g_rot_c, g_rot_o),
            ti.select(first, g_pos_o, g_c), ti.select(first, g_rot_o, g_rot_c))


# A cylinder standing on a box's face or on a wider cylinder's cap: the cap form above is one
# contact, at the foot of the cap's centre, which holds no torque (a can on a box rocked at ~0.1
# m/s), and a can a little tilted is met at one rim point. Instead, a cylinder standing on the face
# (its axis within STANDING_TILT of the face's normal) touches it at four points of the rim of its
# disk nearer the face: where the face's two in-plane axes (a cap's: its cylinder's x and y),
# made perpendicular to the cylinder's axis, point (±u, ±v), each a contact when within the margin
# (KIND_FACE_CAP: column 1 the face, 0..5 = +x, -x, +y, -y, +z, -z, a cylinder's caps 4 and 5;
# column 2 the point, 0..3 = +u, -u, +v, -v; column 3 1 when the standing axis is flipped to point
# at the face; column 4 1 when the standing cylinder is geom 2). Each is a smooth closed form of
# the two poses: the rule MuJoCo uses on a plane (the lowest rim point and an inscribed triangle)
# follows the tilt's direction, which turns without bound as the tilt vanishes (its gradients did
# not converge for a can sliding on its cap). Tilted more than RIM_TILT on its rim, the rim contact
# (the lowest rim point) stays with the deepest three. The face is chosen from the poses alone.
# Points off the face (a can over the cap's rim) are left out, and the collider's own contact stays
# beside those on it; on a box, a point whose face ends inside the rim is the cap's point under that
# edge instead (EDGE), and a face within the cap touches at its corners (CORNER). Of two cylinders,
# the narrower stands on the other. MuJoCo 4.0 gives up to 4 contacts here by its own rule, not
# reproduced.
STANDING_TILT = 0.1  # rad
# Tilted more than this (on its rim), the cylinder keeps its rim contact (the lowest rim point) with
# the four points: else, tilted along a diagonal, the square they form met the face 0.29 r sin(tilt)
# higher than the rim does, a jump of ~1 mm in depth at STANDING_TILT for a 3.3 cm can (a 17 g
# kick). Below it the rim point's direction turns too fast with the tilt for a gradient (~r/tilt).
RIM_TILT = 0.01  # rad
# A cylinder lying on a box's face (its axis within LYING_TILT of the face's plane, met on its
# side) touches it at the two ends of its side's line nearest the face (KIND_FACE_CAP with column 2
# = LYING, column 3 the end): the same closed form with t = -n and a = ±axis. One contact (the
# side's, wherever the iterate put it) let a lying can see-saw: 0.5 m/s for good. A capsule lying
# on a cylinder's cap likewise (its ends' balls' lowest points: the same form, e its end's centre).
# An end beyond a box face's side (a can lying across a narrower box) is slid back along the axis
# onto that side's plane (column 5 = EDGE, column 6 the side's face code, `_lying_exit`): p = q -
# slide a, q the end's point, slide = (q - a point of the side) . its normal / (a . its normal),
# where the side line crosses the edge, as MuJoCo 4.0's two contacts there (on the collider's one
# contact the can see-sawed at 0.28 m/s; now both creep in yaw alike, ~0.01 rad/s). Tilted more, the
# iterate's contact is the lower end's anyway and the other end is higher by 2 h sin(tilt); the
# gate is narrow because a tenth of random poses lie within 0.1 rad of a face's plane, where the
# contacts are compared with MuJoCo's.
LYING = 4
LYING_TILT = 0.02  # rad
# A box's face that ends inside the standing cylinder's rim along a point's axis (a box on a wider
# can's cap, a wide can on a narrower box) cuts the contact short of the rim: the point is then the
# cap's point whose foot on the face lies on that edge (column 5 = EDGE), reach = (the face's half
# extent − the cap centre's offset along t) / |d_raw| from the cap's centre instead of the radius —
# the same point where the edge meets the rim, so the switch is continuous. With rim points only, a
# 10 cm box on a 20 cm can's cap kept one contact and rocked at 1 rad/s, a 40 cm can on a 30 cm box
# at 0.3. On a mesh's polygon the edge is the one the point's ray from the cap's centre leaves the
# polygon through (`_clip_line`), reach = (a point of its line − e) . its outward normal / (the
# ray's direction . that normal), the box's formula for a box (`_edge_line`).
EDGE = 1
# A box's face that lies within the standing cylinder's cap (a box on a wider can) touches it at its
# four corners (column 2 = CORNER, column 5 the corner): dist = (corner − e) . a from the cap's plane
# along the cap's normal, which is the normal. The points under the face's edges would let a corner
# of a tilted box sink in first (a box set 2° tilted on a can was kicked 4 mm up in float32). A
# mesh's polygon touches at up to four of its vertices (`_mesh_corners`; column 5 the vertex's
# position in the polygon's list): with the rim points alone, all off the face, a mesh box on a
# wider can kept the collider's one contact and rocked at 0.35 m/s (MuJoCo 4.0 rests).
CORNER = 5
# GJK in float32 finds a cylinder resting on a face apart now and then (a can on a free box: 8 % of
# its steps with no contact, rocking at 0.04 m/s): then the face's points still count when none is
# deeper than this (resting, 0.03 mm; a rim point on a face's plane far from where they meet, cm).
MISSED_DEPTH = 1e-4  # m
# A box's face partly within the cap, some rim (or edge) point off it: the face's corners within the
# cap join the points on it, rim points giving way beyond CONVEX_MAX, and the collider's contact
# does not (a box whose face missed the can's axis kept it beside two points and rocked at 0.13
# rad/s). Corners are not added beside four points on the face: the deepest four of up to seven
# then changed from step to step, and a box 3 cm off a can's axis, tilted 3°, rocked at 0.25 rad/s.
FACE_CANDIDATES = 9
# ... and the rim point toward the face's centre joins them (column 2 = TOWARD: t = the face's
# centre − the cap's, made perpendicular to the axis), kept before rim points: the corners near the
# can's axis and a rim point along a box axis did not surround a box centred 7–9 cm off the axis of
# a 10 cm can (it rocked at up to 1 rad/s, in 8 of 40 random poses).
TOWARD = 6


@ti.func
def _column(rot, k):
    """Column k of a 3×3 rotation (a geom's axis k, world frame) for a run-time k (frame.column
    takes a compile-time one, as every collider's call has)."""
    return ti.Vector([rot[0, k], rot[1, k], rot[2, k]])


@ti.func
def _half_extent(base: ti.template(), axis):
    """The base's half extent along its axis `axis` (a box's half size; a cylinder's half-length
    along z, the only axis of its caps)."""
    return ti.select(base[0] == CYLINDER, base[4][1], base[4][axis])


@ti.func
def _unit_axis(axis):
    """The unit vector along axis 0, 1 or 2 (a run-time index)."""
    return ti.Vector([ti.select(axis == 0, 1.0, 0.0), ti.select(axis == 1, 1.0, 0.0), ti.select(axis == 2, 1.0, 0.0)])


@ti.func
def _face_frame(base: ti.template(), feature, hull: ti.template()):
    """Face `feature[1]` of the base and point `feature[2]`'s in-plane axis, in the base's frame:
    (the face's outward normal, a point of the face (a box's or cap's centre, a mesh polygon's
    vertex 0), t (point k: ± the face's first in-plane axis for k = 0, 1, ± the second for 2, 3;
    lying, the inward normal), the base axis t is along (a box's; 0 on a mesh, whose axes are the
    direction of its polygon's first edge and the normal × it: a box mesh's face's axes, as a box's;
    along the diagonal, its two edge points could lie on one line and it rocked), its
    middle (a box face's centre, a mesh polygon's vertices' mean: where TOWARD points))."""
    n_local, centre_local, t_local, t_axis = ti.Vector.zero(float, 3), ti.Vector.zero(float, 3), \
        ti.Vector.zero(float, 3), 0
    middle_local = ti.Vector.zero(float, 3)
    if base[0] == MESH:
        poly = hull.hull_polyadr[base[1]] + feature[1]
        vadr, padr, num = hull.hull_vertadr[base[1]], hull.hull_poly_vertadr[poly], hull.hull_poly_vertnum[poly]
        n_local = hull.hull_poly_normal[poly]
        centre_local = _polygon_point(hull, vadr, padr, num, 0)
        if feature[2] == TOWARD:
            for i in range(num):
                middle_local += _polygon_point(hull, vadr, padr, num, i)
            middle_local /= num
        first = _normalize(_polygon_point(hull, vadr, padr, num, 1) - centre_local)
        t_local = (1.0 - 2.0 * (feature[2] % 2)) * ti.select(feature[2] // 2 == 0, first, _cross(n_local, first))
        if feature[2] == LYING:
            t_local = -n_local
    else:
        face_axis, face_sign = feature[1] // 2, 1.0 - 2.0 * (feature[1] % 2)
        n_local = face_sign * _unit_axis(face_axis)
        centre_local = n_local * _half_extent(base, face_axis)
        t_axis = (face_axis + 1 + feature[2] // 2) % 3
        t_local = (1.0 - 2.0 * (feature[2] % 2)) * _unit_axis(t_axis)
        if feature[2] == LYING:  # the end (feature[3]) of the side's line nearest the face
            t_axis, t_local = face_axis, -n_local
        middle_local = centre_local
    return n_local, centre_local, t_local, t_axis, middle_local


@ti.func
def _face_cap_terms(stand: ti.template(), base: ti.template(), feature, hull: ti.template()):
    """Rim point `feature[2]` of the standing cylinder on face `feature[1]` of the base (see
    above), every intermediate: (the face's outward normal, a point of it and t in the base's frame
    (`_face_frame`), n (the face's outward normal), centre (that point), t's base axis, a (the
    standing axis towards the face; lying, towards the end), t (the in-plane axis; lying, -n;
    TOWARD, the face's centre - e), d_raw = t - (t.a) a, e (the cap's centre; lying, the end's),
    edge (the reach of the face's edge from e along d_raw, `EDGE`), p = e + reach unit(d_raw)
    (the rim point, reach the radius; the edge's point, reach = edge), depth = (p - centre) . n, the
    face's middle, the edge's line's point and normal (`_edge_line`) in the base's frame)."""
    rot1, size1, rot2 = stand[3], stand[4], base[3]
    n_local, centre_local, t_local, t_axis, middle_local = _face_frame(base, feature, hull)
    n = _rot(rot2, n_local)
    centre = base[2] + _rot(rot2, centre_local)
    a = (1.0 - 2.0 * feature[3]) * _column(rot1, 2)
    e = stand[2] + a * size1[1]
    t = _rot(rot2, t_local)
    if feature[2] == TOWARD:
        t = base[2] + _rot(rot2, middle_local) - e
    d_raw = t - _dot(t, a) * a
    u = _normalize(d_raw)
    # the edge's point p = e + edge u on its line: (p - line) . out = 0
    line_local, out_local = _edge_line(base, feature, hull, centre_local, t_local, t_axis,
                                       _rot_t(rot2, e - base[2]), _rot_t(rot2, u))
    line, out = base[2] + _rot(rot2, line_local), _rot(rot2, out_local)
    edge = _dot(line - e, out) / ti.max(_dot(u, out), _MINVAL)
    p = e + ti.select(feature[5] == EDGE, edge, size1[0]) * u
    if feature[2] == LYING:  # its end's point q, on an edge (EDGE) slid back along a onto the side's plane
        q = e + size1[0] * u
        edge = _dot(q - line, out) / ti.max(_dot(a, out), _MINVAL)
        p = q - ti.select(feature[5] == EDGE, edge, 0.0) * a
    return (n_local, centre_local, t_local, n, centre, t_axis, a, t, d_raw, e, edge, p, _dot(p - centre, n), middle_local,
            line_local, out_local)


@ti.func
def _edge_line(base: ti.template(), feature, hull: ti.template(), centre_local, t_local, t_axis, e_local, u_local):
    """(a point of its line, its outward normal in the face's plane (of any length)) in the base's
    frame, of the face's edge that an EDGE point lies on: a box face's edge across t (the face's
    centre + half extent t, t), a mesh polygon's edge from its vertex feature[6] to the next
    (that vertex, (the next - it) × the polygon's normal), or a cylinder's cap's rim's tangent
    where the ray from e_local along u_local (the rim point's, in the base's frame) leaves the
    disk (the rim point there, its direction from the cap's centre; the centre and a zero normal
    where the ray misses the disk). The tangent is recomputed from the poses at every evaluation
    and its reverse holds it fixed in the base's frame: exact, as the ray meets the rim's circle
    where the tangent touches it, so turning the tangent about the rim moves the ray's crossing
    only to second order."""
    line_local, out_local = centre_local + _half_extent(base, t_axis) * t_local, t_local  # (a box's)
    if base[0] == CYLINDER:  # |m + reach w| = radius in the cap's plane (z: the cylinder's axis)
        ww = u_local[0] * u_local[0] + u_local[1] * u_local[1]
        mw = e_local[0] * u_local[0] + e_local[1] * u_local[1]
        mm = e_local[0] * e_local[0] + e_local[1] * e_local[1]
        discriminant = mw * mw - ww * (mm - base[4][0] * base[4][0])
        line_local, out_local = centre_local, ti.Vector([0.0, 0.0, 0.0])
        if discriminant >= 0.0 and ww > _MINVAL:
            reach = (ti.sqrt(discriminant) - mw) / ww
            out_local = ti.Vector([e_local[0] + reach * u_local[0], e_local[1] + reach * u_local[1], 0.0]) / base[4][0]
            line_local = centre_local + base[4][0] * out_local
    elif feature[2] == LYING and base[0] == BOX:  # the side (face code feature[6]) the lying line crosses
        edge_axis = feature[6] // 2
        out_local = (1.0 - 2.0 * (feature[6] % 2)) * _unit_axis(edge_axis)
        line_local = centre_local + base[4][edge_axis] * out_local
    elif base[0] == MESH:
        poly = hull.hull_polyadr[base[1]] + feature[1]
        vadr, padr, num = hull.hull_vertadr[base[1]], hull.hull_poly_vertadr[poly], hull.hull_poly_vertnum[poly]
        line_local = _polygon_point(hull, vadr, padr, num, feature[6])
        out_local = _cross(_polygon_point(hull, vadr, padr, num, feature[6] + 1) - line_local,
                           hull.hull_poly_normal[poly])
    return line_local, out_local


@ti.func
def _lying_exit(base: ti.template(), face_axis, a, q):
    """(face code of the box's side whose plane the lying line's end q (world) crossed going out along
    a, how far back along a that plane lies from q (> 0: q is beyond it)): of the face's two
    in-plane axes, the one whose side plane q lies farthest beyond, counted along a."""
    code, back = 0, -_BIG
    for turn in ti.static((1, 2)):
        axis = (face_axis + turn) % 3
        column = _column(base[3], axis)
        heading = _dot(a, column)
        side = ti.select(heading >= 0.0, 1.0, -1.0)
        beyond = (side * _dot(q - base[2], column) - base[4][axis]) / ti.max(ti.abs(heading), _MINVAL)
        if beyond > back:
            code, back = 2 * axis + ti.select(heading >= 0.0, 0, 1), beyond
    return code, back


@ti.func
def _face_corner_local(base: ti.template(), feature, hull: ti.template()):
    """Corner `feature[5]` of the base's face `feature[1]` in the base's frame (see CORNER): a box
    face's corner at the signs 1 - 2 (k % 2), 1 - 2 (k // 2) of its in-plane half extents, or a
    mesh polygon's vertex at that position of its list."""
    q_local = ti.Vector([0.0, 0.0, 0.0])
    if base[0] == MESH:
        poly = hull.hull_polyadr[base[1]] + feature[1]
        q_local = _polygon_point(hull, hull.hull_vertadr[base[1]], hull.hull_poly_vertadr[poly],
                                 hull.hull_poly_vertnum[poly], feature[5])
    else:
        face_axis, face_sign = feature[1] // 2, 1.0 - 2.0 * (feature[1] % 2)
        u_axis, v_axis = (face_axis + 1) % 3, (face_axis + 2) % 3
        u_sign, v_sign = 1.0 - 2.0 * (feature[5] % 2), 1.0 - 2.0 * (feature[5] // 2)
        size2 = base[4]
        for k in ti.static(range(3)):
            if k == face_axis:
                q_local[k] = face_sign * size2[k]
            if k == u_axis:
                q_local[k] = u_sign * size2[k]
            if k == v_axis:
                q_local[k] = v_sign * size2[k]
    return q_local


@ti.func
def _corner_terms(stand: ti.template(), base: ti.template(), feature, hull: ti.template()):
    """Corner `feature[5]` of the base's face `feature[1]` against the standing cylinder's cap (see
    CORNER): (the corner in the base's frame, a, e, q (the corner), dist = (q - e) . a, its offset
    from e across a (its squared length: whether it lies within the cap))."""
    q_local = _face_corner_local(base, feature, hull)
    q = base[2] + _rot(base[3], q_local)
    a = (1.0 - 2.0 * feature[3]) * _column(stand[3], 2)
    e = stand[2] + a * stand[4][1]
    dist = _dot(q - e, a)
    return q_local, a, e, q, dist, (q - e) - dist * a


@ti.func
def _mesh_corners(stand: ti.template(), base: ti.template(), face, flip, hull: ti.template()):
    """(positions in polygon `face` of the mesh base of up to four of its vertices within the
    standing cylinder's cap (CORNER; -1 where fewer): all of them when four or fewer, else four
    spread among them: the first, the farthest from it, the farthest from their line and the
    farthest on that line's other side; how many of its vertices lie within the cap; its vertex
    count). Four spread over the whole polygon left some within the cap out: an octagon across
    a can's rim sank 5 mm on one of those, uncontacted, and rocked at 2.3 rad/s."""
    poly = hull.hull_polyadr[base[1]] + face
    vadr, padr, num = hull.hull_vertadr[base[1]], hull.hull_poly_vertadr[poly], hull.hull_poly_vertnum[poly]
    corners, n_in = ti.Vector([-1, -1, -1, -1]), 0
    line, side = ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0])
    best = ti.Vector([-1.0, -1.0, 0.0])  # (the farthest's, the widest's, the other side's measure)
    for step in range(4 * num):  # four passes over the vertices (one call site: inlined once)
        sweep, i = step // num, step % num
        offset = _corner_terms(stand, base, ti.Vector([KIND_FACE_CAP, face, CORNER, flip, 0, i, 0, 0, 0, 0, 0]),
                               hull)[5]
        if _dot(offset, offset) <= stand[4][0] * stand[4][0]:
            point = _polygon_point(hull, vadr, padr, num, i)
            span = point - _polygon_point(hull, vadr, padr, num, ti.max(corners[0], 0))
            if sweep == 0:
                if n_in < 4:
                    corners[n_in] = i
                n_in += 1
            elif n_in > 4:
                measure = _dot(span, span)  # sweep 1: from the first
                if sweep == 2:
                    measure = _cross(line, span).norm_sqr()  # from their line
                elif sweep == 3:
                    measure = -_dot(_cross(line, span), side)  # on its other side
                if measure > best[sweep - 1]:
                    best[sweep - 1] = measure
                    corners[sweep] = i
        if step == 2 * num - 1 and n_in > 4:  # (after sweep 1: the line from the first to the farthest)
            line = _polygon_point(hull, vadr, padr, num, corners[1]) - _polygon_point(hull, vadr, padr, num, corners[0])
        if step == 3 * num - 1 and n_in > 4:  # (after sweep 2; none on the other side: -1)
            side = _cross(line, _polygon_point(hull, vadr, padr, num, corners[2])
                          - _polygon_point(hull, vadr, padr, num, corners[0]))
            corners[3] = -1
    return corners, n_in, num


@ti.func
def _face_cap(shape1: ti.template(), shape2: ti.template(), second, normal, hull: ti.template()):
    """The face contacts of a cylinder standing on a box's face or a cylinder's cap, or lying on
    either, or a capsule lying on a cylinder's cap (see above):
    `second` 1 when the standing one is geom 2; `normal` the collider's (from geom 1 to 2), whose
    axis picks the face of a cylinder lying on a box (standing, the face comes from the poses).
    Returns
    (count, position (CONVEX_MAX, 3), normal (CONVEX_MAX, 3), dist (CONVEX_MAX,), feature
    (CONVEX_MAX, FEATURE_SIZE)) as convex_convex's (the points on the face), the cosine of the
    standing axis's tilt from the face's normal, whether a point within the margin fell off the
    face (a can over the box's edge), whether the cylinder stands (or lies) on the face, the
    face's normal from geom 1 to geom 2, and whether a box face's corner is among the points;
    count 0 when it does not stand on the face."""
    stand, base = _pick_shape(second == 0, shape1, shape2), _pick_shape(second == 1, shape1, shape2)
    rot2, size2 = base[3], base[4]
    axis1 = _column(stand[3], 2)
    # the face from the geometry alone (the collider's normal may point the wrong way at a pose
    # exactly touching, which picked the far face: a can launched at 10 m/s): the base's axis
    # nearest the standing axis (a cylinder's caps: its z), on the side of the standing centre
    face_axis, aligned = 2, _dot(axis1, _column(rot2, 2))
    if base[0] == BOX:
        for k in ti.static(range(2)):
            cosine = _dot(axis1, _column(rot2, k))
            if ti.abs(cosine) > ti.abs(aligned):
                face_axis, aligned = k, cosine
    lying = False
    apart = stand[2] - base[2]
    outside = ti.abs(_dot(apart, _column(rot2, face_axis))) > _half_extent(base, face_axis)  # (beyond the face)
    if base[0] == BOX and (ti.abs(aligned) < ti.static(np.cos(STANDING_TILT)) or not outside):  # lying?
        best = -1.0
        for k in ti.static(range(3)):
            along = ti.abs(_dot(normal, _column(rot2, k)))
            if along > best:
                face_axis, best = k, along
        aligned = _dot(axis1, _column(rot2, face_axis))
        lying = ti.abs(aligned) <= ti.static(np.sin(LYING_TILT))
    elif base[0] == CYLINDER:  # lying on the wider cylinder's cap (its only face)
        lying = ti.abs(aligned) <= ti.static(np.sin(LYING_TILT))
    above = _dot(apart, _column(rot2, face_axis))
    face = 2 * face_axis + ti.select(above >= 0.0, 0, 1)  # the face on the standing cylinder's side
    outward = _column(rot2, face_axis) * (1.0 - 2.0 * (face % 2))  # its normal
    centre = base[2] + outward * _half_extent(base, face_axis)
    flip = ti.select(aligned * (1.0 - 2.0 * (face % 2)) > 0.0, 1, 0)  # the axis turned to point into the face
    if base[0] == MESH:
        # the polygon facing the cylinder's axis most, turned toward the cylinder: the axis's way whose
        # face has the cylinder's centre outside its plane (the mesh's origin, which the file sets
        # anywhere, does not tell: above the can's centre it picked the bottom face)
        for way in range(2):  # (one lookup: inlined once)
            if way == 0 or above <= 0.0:
                face = _facing_polygon(hull, base[1], _rot_t(rot2, axis1 * (1.0 - 2.0 * way)))[0]
                poly = hull.hull_polyadr[base[1]] + face
                outward = _rot(rot2, hull.hull_poly_normal[poly])
                vertex = _polygon_point(hull, hull.hull_vertadr[base[1]], hull.hull_poly_vertadr[poly],
                                        hull.hull_poly_vertnum[poly], 0)
                centre = base[2] + _rot(rot2, vertex)
                above = _dot(stand[2] - centre, outward)
        aligned = _dot(axis1, outward)
        flip = ti.select(aligned > 0.0, 1, 0)
    position, out_normal = ti.Matrix.zero(float, CONVEX_MAX, 3), ti.Matrix.zero(float, CONVEX_MAX, 3)
    dist = ti.Vector.zero(float, CONVEX_MAX)
    feature = ti.Matrix.zero(ti.i32, CONVEX_MAX, FEATURE_SIZE)
    count, off_face = 0, False
    # upright on the face, its centre outside the face's plane (a can lying on a box, its axis along
    # the box's x, does not stand on the box's x face)
    standing = (ti.abs(aligned) >= ti.static(np.cos(STANDING_TILT)) or lying) and ti.abs(above) > _half_extent(
        base, face_axis)
    if base[0] == MESH:  # (lying on a mesh: _lying_on_mesh)
        standing = ti.abs(aligned) >= ti.static(np.cos(STANDING_TILT)) and above > 0.0
    if stand[0] == CAPSULE:  # a capsule only lies on the face (upright, its end's ball meets it at one point)
        standing = standing and lying
    # the face's corners within the cap (a box's, or a mesh polygon's `_mesh_corners`); all of them
    # (the face within the cap): the corners alone
    corner_at, n_within, n_vertices = ti.Vector([0, 1, 2, 3]), 0, 0
    if base[0] == MESH:
        corner_at, n_within, n_vertices = _mesh_corners(stand, base, face, flip, hull)
    inside = ti.Vector([0, 0, 0, 0])
    n_corners = 0
    for k in ti.static(range(4)):
        offset = _corner_terms(stand, base, ti.Vector([KIND_FACE_CAP, face, CORNER, flip, second, ti.max(corner_at[k], 0),
                                                       0, 0, 0, 0, 0]), hull)[5]
        inside[k] = int(base[0] != CYLINDER and corner_at[k] >= 0 and not lying
                        and _dot(offset, offset) <= stand[4][0] * stand[4][0])
        n_corners += int(corner_at[k] >= 0)
    corners = inside.sum() > 0 and inside.sum() == n_corners and n_within == n_vertices  # (a mesh: all within)
    # candidates: the rim (or edge) points, then, where one fell off the face, the corners within the
    # cap and the rim point toward the face's centre (a box whose face misses the can's axis)
    cand_position, cand_normal = ti.Matrix.zero(float, FACE_CANDIDATES, 3), ti.Matrix.zero(float, FACE_CANDIDATES, 3)
    cand_dist = ti.Vector.zero(float, FACE_CANDIDATES)
    cand_feature = ti.Matrix.zero(ti.i32, FACE_CANDIDATES, FEATURE_SIZE)
    n_cand, with_corner = 0, False
    for k in range(ti.select(lying, 2, ti.select(corners or base[0] == CYLINDER, 4, 9))):  # one evaluation: inlined once
        row = ti.Vector([KIND_FACE_CAP, face, k, flip, second, 0, 0, 0, 0, 0, 0])
        if lying:  # its two line ends
            row[2], row[3] = LYING, k
        elif k == 8:
            row[2] = TOWARD
        elif corners or k >= 4:
            row[2], row[5] = CORNER, ti.max(corner_at[k % 4], 0)
        # the face ends inside the rim (a rim point would be off it): a box's or mesh's edge, a cylinder's
        # rim (equal cans offset by 1 mm kept the collider's contact and one rim point and rocked at 0.4
        # rad/s: the rims of ±v missed the other cap by 1e-5 m)
        if row[2] <= LYING and not (base[0] == CYLINDER and lying):
            terms = _face_cap_terms(stand, base, row, hull)
            edge, reach = terms[10], stand[4][0]
            if base[0] == CYLINDER and (terms[15].norm_sqr() == 0.0 or edge < 0.0):  # (the ray misses, or
                edge = _BIG                                                          # leaves behind e)
            if lying:  # an end beyond a box face's edge: the line where it crosses the edge (a face code)
                row[6], edge = _lying_exit(base, face_axis, terms[6], terms[9] + stand[4][0] * _normalize(terms[8]))
                edge, reach = stand[4][1] - edge, stand[4][1]
            elif base[0] == MESH:  # (the polygon's edge the point's ray leaves it through)
                clipped = _clip_line(hull, base[1], face, _rot_t(rot2, terms[9] - base[2]),
                                     _rot_t(rot2, _normalize(terms[8])), -_BIG, _BIG)
                row[6], edge = ti.max(clipped[3], 0), clipped[1]  # (_BIG when it leaves through none)
            if -reach < edge and edge < reach:
                row[5] = EDGE
            else:
                row[6] = 0
        point, unit, depth = _face_cap_evaluate(shape1, shape2, row, hull)
        is_corner = row[2] == CORNER
        # (within the margin; a corner within the cap, and beside rim points, as the rim point toward
        # the face's centre, only where one fell off)
        wanted = ti.select(is_corner, inside[k % 4] == 1 and (corners or off_face), row[2] != TOWARD or off_face)
        if standing and depth <= shape1[5] and wanted:
            offset = point - centre
            inplane = ti.Vector([0.0, 0.0])  # the point from the face's centre, along its in-plane axes
            on_face = True
            for turn in ti.static((1, 2)):  # the face's in-plane axes
                side_axis = (face_axis + turn) % 3
                inplane[turn - 1] = _dot(offset, _column(rot2, side_axis))
                # (an edge's point is on its edge, a corner on two, by construction, up to round-off)
                across_edge = is_corner or (row[5] == EDGE and side_axis == ti.select(
                    lying, row[6] // 2, (face_axis + 1 + k // 2) % 3))
                if base[0] == BOX and ti.abs(inplane[turn - 1]) > size2[side_axis] and not across_edge:
                    on_face = False
            if base[0] == CYLINDER and inplane.norm_sqr() > size2[0] * size2[0] and row[5] != EDGE:
                on_face = False
            if base[0] == MESH and not is_corner and not _on_polygon(
                    hull, base[1], face, _rot_t(rot2, point - base[2]), ti.select(row[5] == EDGE, row[6], -1)):
                on_face = False
            off_face = off_face or not on_face
            if on_face:
                for c in ti.static(range(3)):
                    cand_position[n_cand, c], cand_normal[n_cand, c] = point[c], unit[c]
                cand_dist[n_cand] = depth
                for c in ti.static(range(FEATURE_SIZE)):
                    cand_feature[n_cand, c] = row[c]
                n_cand += 1
                with_corner = with_corner or is_corner
    # beyond the budget, rim (or edge) points give way, the last first: the corners within the cap and
    # the point toward the face's centre stay (the deepest four flipped from step to step on a
    # resting box: a rock at 0.02 rad/s)
    dropped = ti.Vector.zero(ti.i32, FACE_CANDIDATES)
    excess = n_cand - CONVEX_MAX
    for j in ti.static(range(FACE_CANDIDATES)):
        i = FACE_CANDIDATES - 1 - j
        if excess > 0 and i < n_cand and cand_feature[i, 2] < LYING:
            dropped[i] = 1
            excess -= 1
    for i in ti.static(range(FACE_CANDIDATES)):
        if i < n_cand and dropped[i] == 0:
            for c in ti.static(range(3)):
                position[count, c], out_normal[count, c] = cand_position[i, c], cand_normal[i, c]
            dist[count] = cand_dist[i]
            for c in ti.static(range(FEATURE_SIZE)):
                feature[count, c] = cand_feature[i, c]
            count += 1
    toward = outward * ti.select(second == 0, -1.0, 1.0)  # the face's normal, from geom 1 to geom 2
    return count, position, out_normal, dist, feature, ti.abs(aligned), off_face, standing, toward, with_corner


@ti.func
def _face_cap_evaluate(shape1: ti.template(), shape2: ti.template(), feature, hull: ti.template()):
    """(position, normal from geom 1 to 2, dist) of a KIND_FACE_CAP contact: the rim point moved
    half its depth along the face's normal, the face's normal into the base (from the standing
    cylinder) or out of it (when the standing one is geom 2), the depth."""
    second = feature[4]
    stand, base = _pick_shape(second == 0, shape1, shape2), _pick_shape(second == 1, shape1, shape2)
    position, unit, depth = ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0]), 0.0
    if feature[2] == CORNER:  # the corner q and the cap's normal a
        corner = _corner_terms(stand, base, feature, hull)
        a, q, dist = corner[1], corner[3], corner[4]
        position, unit, depth = q - a * (0.5 * dist), a, dist
    else:  # the rim (or edge) point p and the face's normal n
        terms = _face_cap_terms(stand, base, feature, hull)
        n, p, dist = terms[3], terms[11], terms[12]
        position, unit, depth = p - n * (0.5 * dist), -n, dist
    return position, unit * ti.select(second == 0, 1.0, -1.0), depth


@ti.func
def _face_cap_evaluate_adjoint(shape1: ti.template(), shape2: ti.template(), feature, hull: ti.template(),
                               g_position, g_normal, g_dist):
    """Reverse of `_face_cap_evaluate`: (g_pos1, g_rot1, g_pos2, g_rot2)."""
    second = feature[4]
    stand, base = _pick_shape(second == 0, shape1, shape2), _pick_shape(second == 1, shape1, shape2)
    g_stand, g_base = ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0])
    g_rot_stand, g_rot_base = ti.Matrix.zero(float, 3, 3), ti.Matrix.zero(float, 3, 3)
    if feature[2] == CORNER:
        g_stand, g_rot_stand, g_base, g_rot_base = _corner_adjoint(stand, base, feature, hull, g_position, g_normal,
                                                                   g_dist)
    else:
        g_stand, g_rot_stand, g_base, g_rot_base = _face_cap_adjoint(stand, base, feature, hull, g_position,
                                                                     g_normal, g_dist)
    first = second == 0
    return (ti.select(first, g_stand, g_base), ti.select(first, g_rot_stand, g_rot_base),
            ti.select(first, g_base, g_stand), ti.select(first, g_rot_base, g_rot_stand))


@ti.func
def _corner_adjoint(stand: ti.template(), base: ti.template(), feature, hull: ti.template(), g_position, g_normal,
                    g_dist):
    """Reverse of a CORNER contact: (g_pos, g_rot) of the standing cylinder, then of the base."""
    q_local, a, e, q, dist, across = _corner_terms(stand, base, feature, hull)
    # position = q - a dist / 2, normal = ±a, dist = (q - e) . a, e = stand's pos + a h
    g_total = g_dist - 0.5 * _dot(g_position, a)
    g_q = g_position + g_total * a
    g_e = -g_total * a
    g_a = (ti.select(feature[4] == 0, 1.0, -1.0) * g_normal - (0.5 * dist) * g_position + g_total * (q - e)
           + stand[4][1] * g_e)
    g_rot_stand = ti.Matrix.zero(float, 3, 3)
    a_sign = 1.0 - 2.0 * feature[3]
    for r in ti.static(range(3)):
        g_rot_stand[r, 2] = a_sign * g_a[r]
    # q = the base's pos + its rotation times the corner's local position
    return g_e, g_rot_stand, g_q, g_q.outer_product(q_local)


@ti.func
def _face_cap_adjoint(stand: ti.template(), base: ti.template(), feature, hull: ti.template(), g_position,
                      g_normal, g_dist):
    """Reverse of a rim, edge or lying contact: (g_pos, g_rot) of the standing cylinder, then of the
    base."""
    second = feature[4]
    size1 = stand[4]
    n_local, centre_local, t_local, n, centre, t_axis, a, t, d_raw, e, edge, p, depth, middle_local, line_local, \
        out_local = _face_cap_terms(stand, base, feature, hull)
    # position = p - n depth / 2, normal = ∓n, dist = depth = (p - centre) . n
    g_depth = g_dist - 0.5 * _dot(g_position, n)
    g_n = ti.select(second == 0, -1.0, 1.0) * g_normal - (0.5 * depth) * g_position + g_depth * (p - centre)
    g_p = g_position + g_depth * n
    g_centre = -g_depth * n
    # p = e + reach u, u = unit(d_raw), e = stand's pos + a h, d_raw = t - (t . a) a
    lying = feature[2] == LYING
    reach = ti.select(feature[5] == EDGE and not lying, edge, size1[0])
    u = _normalize(d_raw)
    g_u = reach * g_p
    g_e, g_t = g_p, ti.Vector([0.0, 0.0, 0.0])
    g_line, g_out, g_a_slide = ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0])
    line, out = base[2] + _rot(base[3], line_local), _rot(base[3], out_local)
    if feature[5] == EDGE and lying:  # p = q - slide a, q = e + r u, slide = edge = (q - line) . out / (a . out)
        g_numerator = -_dot(g_p, a) / ti.max(_dot(a, out), _MINVAL)
        g_e += g_numerator * out
        g_u += (size1[0] * g_numerator) * out
        g_line = -g_numerator * out
        g_out = g_numerator * (e + size1[0] * u - line) - (g_numerator * edge) * a
        g_a_slide = -edge * g_p - (g_numerator * edge) * out
    elif feature[5] == EDGE:  # reach = (line - e) . out / (u . out), line and out the edge's (`_edge_line`)
        g_numerator = _dot(g_p, u) / ti.max(_dot(u, out), _MINVAL)
        g_line = g_numerator * out
        g_e -= g_line
        g_out = g_numerator * (line - e) - (g_numerator * edge) * u
        g_u -= (g_numerator * edge) * out
    g_draw = _normalize_adjoint(d_raw, g_u)
    g_t += g_draw - a * _dot(a, g_draw)
    g_middle = ti.Vector([0.0, 0.0, 0.0])
    if feature[2] == TOWARD:  # t = the base's pos + its rotation times the face's middle - e
        g_middle = g_t
        g_e -= g_t
    g_a = size1[1] * g_e - t * _dot(a, g_draw) - _dot(t, a) * g_draw + g_a_slide
    # n, centre - the base's pos and t (not TOWARD's) are the base's rotation times their local vectors
    g_rot_stand = ti.Matrix.zero(float, 3, 3)
    a_sign = 1.0 - 2.0 * feature[3]
    for r in ti.static(range(3)):
        g_rot_stand[r, 2] = a_sign * g_a[r]
    g_rot_base = (g_n.outer_product(n_local) + g_centre.outer_product(centre_local)
                  + g_line.outer_product(line_local) + g_out.outer_product(out_local))
    if feature[2] == TOWARD:
        g_rot_base += g_middle.outer_product(middle_local)
    else:
        g_rot_base += g_t.outer_product(t_local)
    return g_e, g_rot_stand, g_centre + g_middle + g_line, g_rot_base


# A cylinder meeting a vertex, an edge or another cylinder's rim at its rim (m < 2 in `_core_terms`):
# the contact is where the rim's circle comes closest to that point, line or circle, at the angles
# where the distance is stationary. Newton on the angles from the forward's normal finds them to
# round-off in a few iterations; the reverse differentiates the stationarity condition (the implicit
# function theorem), not the iterations.
RIM_NEWTON = 12  # Newton iterations (quadratic from a start within EPA's tolerance)


def _newton_tolerance():
    """Largest accepted stationarity residual after RIM_NEWTON iterations, relative to its terms'
    size (read at compile time: the square root of the float type's unit round-off). Larger, the
    solve did not converge and the implicit reverse would not be the forward's derivative."""
    return 3.5e-4 if impl.get_runtime().default_fp == ti.f32 else 1.5e-8


@ti.func
def _circle(shape: ti.template(), e_local, th):
    """A cylinder's rim at angle th: (its end's centre e (world; e_local in the geom frame), the
    point k = e + R (cos th xh + sin th yh), dk/dth), xh, yh the geom's x and y axes, R its radius."""
    e = _rot(shape[3], e_local) + shape[2]
    xh = ti.Vector([shape[3][0, 0], shape[3][1, 0], shape[3][2, 0]])
    yh = ti.Vector([shape[3][0, 1], shape[3][1, 1], shape[3][2, 1]])
    cos, sin = ti.cos(th), ti.sin(th)
    return e, e + shape[4][0] * (cos * xh + sin * yh), shape[4][0] * (cos * yh - sin * xh)


@ti.func
def _circle_adjoint(shape: ti.template(), e_local, th, g_k, g_dk):
    """Reverse of `_circle`'s k and dk/dth at a fixed th: (g_pos, g_rot)."""
    cos, sin, radius = ti.cos(th), ti.sin(th), shape[4][0]
    g_xh = radius * (cos * g_k - sin * g_dk)
    g_yh = radius * (sin * g_k + cos * g_dk)
    g_rot = g_k.outer_product(e_local)
    for i in ti.static(range(3)):
        g_rot[i, 0] += g_xh[i]
        g_rot[i, 1] += g_yh[i]
    return g_k, g_rot


@ti.func
def _start_angle(shape: ti.template(), direction):
    """The angle of a cylinder's rim support along the world `direction` (`_disk_local`)."""
    local = _rot_t(shape[3], direction)
    return ti.atan2(local[1], local[0])


@ti.func
def _rim_side(shape1: ti.template(), shape2: ti.template(), feature):
    """0 unless a geom of a CORE / EPA contact is a cylinder at its rim (mode 0) with a single end
    in the feature, meeting the other geom's vertex or edge (m < 2), the other not at a rim of its
    own with one end (`_two_rims`); else which (1, 2). An other cylinder "at its rim" with both its
    ends in the feature is met on its side (the iterate's normal, a little off its axis's normal,
    made it a rim: `_rim_terms`)."""
    m, ids1, ids2 = _vertex_ids(feature)
    rim1 = shape1[0] == CYLINDER and feature[10] % 3 == 0
    rim2 = shape2[0] == CYLINDER and feature[10] // 3 == 0
    one1 = ids1[1] == ids1[0] and ids1[2] == ids1[0]
    one2 = ids2[1] == ids2[0] and ids2[2] == ids2[0]
    side = 0
    if m < 2:
        if rim1 and one1 and not (rim2 and one2):
            side = 1
        elif rim2 and one2 and not (rim1 and one1):
            side = 2
    return side


@ti.func
def _rim_terms(shape1: ti.template(), shape2: ti.template(), feature, hull: ti.template()):
    """The rim-on-a-point-or-line form (see above), every intermediate returned. The rim's geom C
    (side `_rim_side`): its circle k(th) (`_circle`); the other O: the point o0 and, for an edge,
    the line o0 + t f. th stationary for |Q (k(th) - o0)|^2, Q the projection across f (the
    identity for a point), g' its second derivative (> 0 at the minimum Newton is to find, else
    the form is flagged invalid); l the line's point nearest k, d = k - l, n = d oriented as the
    forward's normal u; C's witness k moved by its ball (half the margin) along n, O's l by its
    ball against n; sgn = +1 when C is geom 1.
    Returns (first, C, O, mode_o, locals (e, o0, o1 as rows), line, o0, f, th, k, dk/dth, t, pre,
    n, x_c, x_o, sgn, g', valid)."""
    first = _rim_side(shape1, shape2, feature) == 1
    rim, other = _pick_shape(first, shape1, shape2), _pick_shape(not first, shape1, shape2)
    mode_o = ti.select(first, feature[10] // 3, feature[10] % 3)
    if other[0] == CYLINDER and mode_o == 0:  # both its ends in the feature: on its side
        mode_o = 2
    m, ids1, ids2 = _vertex_ids(feature)
    ids_r, ids_o = ti.select(first, ids1, ids2), ti.select(first, ids2, ids1)
    local = ti.Matrix.zero(float, 3, 3)
    for j in range(3):  # one lookup in a loop: inlined once
        point = _support_local(_pick_shape(j == 0, rim, other), ti.select(j == 0, ids_r[0], ids_o[ti.max(j - 1, 0)]),
                               hull)
        for c in ti.static(range(3)):
            local[j, c] = point[c]
    rows = [ti.Vector([local[j, c] for c in ti.static(range(3))]) for j in ti.static(range(3))]
    o0 = _rot(other[3], rows[1]) + other[2]
    f = _rot(other[3], rows[2] - rows[1])
    line = m == 1
    ff = ti.select(line, _dot(f, f), 1.0)
    sgn = ti.select(first, 1.0, -1.0)
    u = decode_direction(feature[8], feature[9])
    th = _start_angle(rim, sgn * u)
    k, k1, v = ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0])
    gp, converged = 0.0, False
    for it in range(RIM_NEWTON + 1):  # the last pass only evaluates at the converged th
        e, k_th, k1_th = _circle(rim, rows[0], th)
        k, k1 = k_th, k1_th
        v = k - o0
        qv = v - ti.select(line, _dot(f, v) / ff, 0.0) * f
        qk1 = k1 - ti.select(line, _dot(f, k1) / ff, 0.0) * f
        gp = _dot(qk1, k1) - _dot(qv, k - e)  # d2/dth2 of |Q v|^2 / 2 (k'' = e - k)
        residual = _dot(qv, k1)
        if it < RIM_NEWTON:
            th -= residual / gp
        else:
            converged = ti.abs(residual) <= ti.static(_newton_tolerance()) * ti.sqrt(_dot(qv, qv) * _dot(k1, k1))
    t = ti.select(line, _dot(f, v) / ff, 0.0)
    d = v - t * f
    pre = d * _sign(_dot(d, u))
    n = _normalize(pre)
    x_c = k + sgn * _ball(rim, 0) * n
    x_o = o0 + t * f - sgn * _ball(other, mode_o) * n
    return first, rim, other, mode_o, local, line, o0, f, th, k, k1, t, pre, n, x_c, x_o, sgn, gp, gp > 0 and converged


@ti.func
def _nan_unless(valid):
    """0 if valid, else NaN (added to a form's outputs: converge_contacts then keeps the iterate)."""
    return ti.select(valid, 0.0, ti.math.nan)


@ti.func
def _rim_evaluate(shape1: ti.template(), shape2: ti.template(), feature, hull: ti.template()):
    """(position, normal, dist) of a cylinder's rim on a vertex or an edge (`_rim_terms`); NaN
    where Newton did not end at a minimum."""
    terms = _rim_terms(shape1, shape2, feature, hull)
    first, n, x_c, x_o, bad = terms[0], terms[13], terms[14], terms[15], _nan_unless(terms[18])
    x1, x2 = ti.select(first, x_c, x_o), ti.select(first, x_o, x_c)
    return (x1 + x2) * 0.5 + bad, n + bad, shape1[5] - _dot(x1 - x2, n) + bad


@ti.func
def _rim_evaluate_adjoint(shape1: ti.template(), shape2: ti.template(), feature, hull: ti.template(),
                          g_position, g_normal, g_dist):
    """Reverse of `_rim_evaluate`: (g_pos1, g_rot1, g_pos2, g_rot2); through th by the implicit
    function theorem on its stationarity, dth = -(dg / dinputs) / g'."""
    first, rim, other, mode_o, local, line, o0, f, th, k, k1, t, pre, n, x_c, x_o, sgn, gp, _ = \
        _rim_terms(shape1, shape2, feature, hull)
    x1, x2 = ti.select(first, x_c, x_o), ti.select(first, x_o, x_c)
    g_x1, g_x2 = 0.5 * g_position - g_dist * n, 0.5 * g_position + g_dist * n
    g_xc, g_xo = ti.select(first, g_x1, g_x2), ti.select(first, g_x2, g_x1)
    g_n = g_normal - g_dist * (x1 - x2) + sgn * _ball(rim, 0) * g_xc - sgn * _ball(other, mode_o) * g_xo
    g_d = _normalize_adjoint(pre, g_n) * _sign(_dot(pre, k - o0 - t * f))
    # d = v - t f, t = f . v / ff (0 for a point), v = k - o0; x_o's line point o0 + t f
    ff = ti.select(line, _dot(f, f), 1.0)
    v = k - o0
    g_t = _dot(f, g_xo - g_d)
    g_v = g_d + ti.select(line, g_t / ff, 0.0) * f
    g_f = t * (g_xo - g_d) + ti.select(line, g_t / ff, 0.0) * (v - 2.0 * t * f)
    g_k = g_xc + g_v
    g_o0 = g_xo - g_v
    # th's own dependence: g(th, inputs) = Q v . dk/dth = 0, its partials times lam
    lam = -_dot(g_k, k1) / gp
    qv = v - ti.select(line, _dot(f, v) / ff, 0.0) * f
    qk1 = k1 - ti.select(line, _dot(f, k1) / ff, 0.0) * f
    g_k += lam * qk1
    g_o0 -= lam * qk1
    fv, fk1 = _dot(f, v), _dot(f, k1)
    g_f += ti.select(line, lam, 0.0) * (2.0 * fv * fk1 * f / ff - v * fk1 - k1 * fv) / ff
    e_local = ti.Vector([local[0, c] for c in ti.static(range(3))])
    g_pos_c, g_rot_c = _circle_adjoint(rim, e_local, th, g_k, lam * qv)
    o_local0 = ti.Vector([local[1, c] for c in ti.static(range(3))])
    o_local1 = ti.Vector([local[2, c] for c in ti.static(range(3))])
    g_rot_o = g_o0.outer_product(o_local0) + g_f.outer_product(o_local1 - o_local0)
    return (ti.select(first, g_pos_c, g_o0), ti.select(first, g_rot_c, g_rot_o),
            ti.select(first, g_o0, g_pos_c), ti.select(first, g_rot_o, g_rot_c))


@ti.func
def _two_rims(shape1: ti.template(), shape2: ti.template(), feature):
    """Whether a CORE / EPA contact is two cylinders meeting at their rims, one end each (m = 0)."""
    m, _, _ = _vertex_ids(feature)
    return (m == 0 and shape1[0] == CYLINDER and shape2[0] == CYLINDER and feature[10] % 3 == 0
            and feature[10] // 3 == 0)


@ti.func
def _rims_terms(shape1: ti.template(), shape2: ti.template(), feature, hull: ti.template()):
    """Two rims (see above), every intermediate returned: the angles (a, b) stationary for
    |k_1(a) - k_2(b)|^2 / 2, Newton on its gradient G = (d . dk_1/da, -d . dk_2/db), d = k_1 - k_2,
    with its Hessian H (positive definite at the minimum Newton is to find, else the form is
    flagged invalid); n = d oriented as the forward's normal u; each witness its k moved by its
    ball (half the margin) along n (geom 1) or against it (geom 2).
    Returns (locals (each end's centre as a row), a, b, k_1, dk_1, k_2, dk_2, (h11, h12, h22), pre,
    n, x1, x2, valid)."""
    local = ti.Matrix.zero(float, 2, 3)
    for j in range(2):  # one lookup in a loop: inlined once
        point = _support_local(_pick_shape(j == 0, shape1, shape2), feature[1 + j], hull)
        for c in ti.static(range(3)):
            local[j, c] = point[c]
    e1_local = ti.Vector([local[0, c] for c in ti.static(range(3))])
    e2_local = ti.Vector([local[1, c] for c in ti.static(range(3))])
    u = decode_direction(feature[8], feature[9])
    a, b = _start_angle(shape1, u), _start_angle(shape2, -u)
    k_1, dk_1, k_2, dk_2 = [ti.Vector([0.0, 0.0, 0.0]) for _ in ti.static(range(4))]
    hess, converged = ti.Vector([0.0, 0.0, 0.0]), False
    for it in range(RIM_NEWTON + 1):  # the last pass only evaluates at the converged angles
        e_1, k_1a, dk_1a = _circle(shape1, e1_local, a)
        e_2, k_2b, dk_2b = _circle(shape2, e2_local, b)
        k_1, dk_1, k_2, dk_2 = k_1a, dk_1a, k_2b, dk_2b
        d = k_1 - k_2
        hess = ti.Vector([_dot(dk_1, dk_1) - _dot(d, k_1 - e_1), -_dot(dk_1, dk_2),
                          _dot(dk_2, dk_2) + _dot(d, k_2 - e_2)])
        g1, g2 = _dot(d, dk_1), -_dot(d, dk_2)
        if it < RIM_NEWTON:
            det = hess[0] * hess[2] - hess[1] * hess[1]
            a -= (hess[2] * g1 - hess[1] * g2) / det
            b -= (hess[0] * g2 - hess[1] * g1) / det
        else:
            scale = ti.sqrt(_dot(d, d) * (_dot(dk_1, dk_1) + _dot(dk_2, dk_2)))
            converged = ti.max(ti.abs(g1), ti.abs(g2)) <= ti.static(_newton_tolerance()) * scale
    d = k_1 - k_2
    pre = d * _sign(_dot(d, u))
    n = _normalize(pre)
    x1 = k_1 + _ball(shape1, 0) * n
    x2 = k_2 - _ball(shape2, 0) * n
    valid = hess[0] > 0 and hess[0] * hess[2] - hess[1] * hess[1] > 0 and converged
    return local, a, b, k_1, dk_1, k_2, dk_2, hess, pre, n, x1, x2, valid


@ti.func
def _rims_evaluate(shape1: ti.template(), shape2: ti.template(), feature, hull: ti.template()):
    """(position, normal, dist) of two cylinders meeting at their rims (`_rims_terms`); NaN where
    Newton did not end at a minimum."""
    terms = _rims_terms(shape1, shape2, feature, hull)
    n, x1, x2, bad = terms[9], terms[10], terms[11], _nan_unless(terms[12])
    return (x1 + x2) * 0.5 + bad, n + bad, shape1[5] - _dot(x1 - x2, n) + bad


@ti.func
def _rims_evaluate_adjoint(shape1: ti.template(), shape2: ti.template(), feature, hull: ti.template(),
                           g_position, g_normal, g_dist):
    """Reverse of `_rims_evaluate`: (g_pos1, g_rot1, g_pos2, g_rot2); through the angles by the
    implicit function theorem on G = 0: d(a, b) = -H^-1 dG / dinputs."""
    local, a, b, k_1, dk_1, k_2, dk_2, hess, pre, n, x1, x2, _ = _rims_terms(shape1, shape2, feature, hull)
    g_x1, g_x2 = 0.5 * g_position - g_dist * n, 0.5 * g_position + g_dist * n
    g_n = g_normal - g_dist * (x1 - x2) + _ball(shape1, 0) * g_x1 - _ball(shape2, 0) * g_x2
    d = k_1 - k_2
    g_d = _normalize_adjoint(pre, g_n) * _sign(_dot(pre, d))
    g_k1, g_k2 = g_x1 + g_d, g_x2 - g_d
    # the angles' own dependence: lam = -H^-1 (dL/da, dL/db), then lam . dG/dinputs
    g_a, g_b = _dot(g_k1, dk_1), _dot(g_k2, dk_2)
    det = hess[0] * hess[2] - hess[1] * hess[1]
    lam1 = -(hess[2] * g_a - hess[1] * g_b) / det
    lam2 = -(hess[0] * g_b - hess[1] * g_a) / det
    g_k1 += lam1 * dk_1 - lam2 * dk_2
    g_k2 += lam2 * dk_2 - lam1 * dk_1
    e1_local = ti.Vector([local[0, c] for c in ti.static(range(3))])
    e2_local = ti.Vector([local[1, c] for c in ti.static(range(3))])
    g_pos1, g_rot1 = _circle_adjoint(shape1, e1_local, a, g_k1, lam1 * d)
    g_pos2, g_rot2 = _circle_adjoint(shape2, e2_local, b, g_k2, -lam2 * d)
    return g_pos1, g_rot1, g_pos2, g_rot2


@ti.func
def _clip_point_local(shape: ti.template(), feature, i, hull: ti.template()):
    """Geom-frame vertex i of a KIND_CLIP contact's clipped polygon: the clipped face's
    (`_face_local` order), or for an edge (feature[7] > 0) its ends feature[5], feature[6]."""
    local = ti.Vector([0.0, 0.0, 0.0])
    if feature[7] > 0:
        local = _support_local(shape, ti.select(i == 0, feature[5], feature[6]), hull)
    else:
        local = _face_local(shape, feature[2], i, hull)
    return local


@ti.func
def _solve_planes(n0, p0, n1, p1, n2, p2):
    """The point on the three planes through p_i with normals n_i, and the inverse of the matrix
    with rows n_i."""
    inverse = ti.Matrix.rows([n0, n1, n2]).inverse()
    return inverse @ ti.Vector([_dot(n0, p0), _dot(n1, p1), _dot(n2, p2)]), inverse


@ti.func
def _clip_terms(shape1: ti.template(), shape2: ti.template(), feature, hull: ti.template()):
    """The closed form of a KIND_CLIP contact, every intermediate returned (its adjoint
    recomputes them). The clipping face is on geom 2 when an edge of geom 1 is clipped
    (feature[7] = 1), else on geom 1; the clipped polygon on the other geom. The point lies on
    two of the forward's clipping lines (module doc): both polygon edges (their shared
    vertex), a polygon edge k and a side plane e (the edge's line, as the planes through it
    along cross(edge, N) and cross(edge, cross(edge, N)), N the clipping face's normal, meets the
    plane through clipping edge e and N), or two side planes e, f (they meet the clipped face's
    plane).
    Returns (clip-side locals C (rows: vertices 0, e, e + 1, f, f + 1 of the clipping face), N's
    local, clipped-side locals P (rows: vertices 0, k or the vertex, k + 1), the clipped face
    normal's local, their world values C_*, N, P_* (a clipped edge's ends moved as the forward's
    are, below), D, the number of side planes, the three planes' normals n0, n1, n2 and the
    points q1, q2 of the last two (the first passes through C_e), the point and the inverse of
    the matrix with rows n_i)."""
    edge_geom = feature[7]
    clip = _pick_shape(edge_geom != 1, shape1, shape2)
    other = _pick_shape(edge_geom == 1, shape1, shape2)
    nclip, npoly = _face_size(clip, feature[1], hull), 2
    if edge_geom == 0:
        npoly = _face_size(other, feature[2], hull)
    tag0, tag1 = feature[3], feature[4]
    sides = int(tag0 >= 256) + int(tag1 >= 256)
    # (a polygon vertex, no side plane: side 0 stands in, its vertices read and unused; tag − 256
    # read outside the face's vertex list and crashed the backward of a mesh on a mesh)
    side_e = ti.select(sides == 0, 0, ti.select(tag0 >= 256, tag0, tag1) - 256)
    side_f = ti.select(sides == 2, tag1 - 256, side_e)
    line = ti.select(tag0 < 256, tag0, tag1)
    first = ti.select(sides == 0, tag1, ti.select(sides == 2, 0, line))
    clip_ids = ti.Vector([0, side_e, _wrap(side_e + 1, nclip), side_f, _wrap(side_f + 1, nclip)])
    poly_ids = ti.Vector([0, first, _wrap(first + 1, npoly)])
    local_c, local_p = ti.Matrix.zero(float, 5, 3), ti.Matrix.zero(float, 3, 3)
    for v in range(8):  # one lookup in a loop: inlined once
        if v < 5:
            point = _face_local(clip, feature[1], clip_ids[v], hull)
            for c in ti.static(range(3)):
                local_c[v, c] = point[c]
        else:
            point = _clip_point_local(other, feature, poly_ids[v - 5], hull)
            for c in ti.static(range(3)):
                local_p[v - 5, c] = point[c]
    local_n = _face_normal_local(clip, feature[1], hull)
    local_d = ti.Vector([0.0, 0.0, 0.0])
    if edge_geom == 0:
        local_d = _face_normal_local(other, feature[2], hull)
    c0, ce, ce1, cf, cf1 = [_rot(clip[3], ti.Vector([local_c[j, c] for c in ti.static(range(3))])) + clip[2]
                            for j in ti.static(range(5))]
    # a clipped edge's ends are the EPA support points (feature[10]: the far end too): with a
    # margin they sit half of it out along the EPA normal u (geom 1) or against it (geom 2)
    start = 0.5 * clip[5] * ti.select(edge_geom == 1, 1.0, ti.select(edge_geom == 2, -1.0, 0.0)) * decode_direction(
        feature[8], feature[9])
    p0, pa, pb = [_rot(other[3], ti.Vector([local_p[j, c] for c in ti.static(range(3))])) + other[2]
                  + ti.select(poly_ids[j] == 0 or feature[10] == 1, start, ti.Vector([0.0, 0.0, 0.0]))
                  for j in ti.static(range(3))]
    normal, face_d = _rot(clip[3], local_n), _rot(other[3], local_d)
    # the planes: side e, then the polygon edge's two planes or side f and the clipped face
    edge = pb - pa
    across = _cross(edge, normal)
    n0 = _cross(ce1 - ce, normal)
    n1 = ti.select(sides == 2, _cross(cf1 - cf, normal), across)
    n2 = ti.select(sides == 2, face_d, _cross(edge, across))
    q1 = ti.select(sides == 2, cf, pa)
    q2 = ti.select(sides == 2, p0, pa)
    point, inverse = pa, ti.Matrix.identity(float, 3)
    if sides > 0:
        point, inverse = _solve_planes(n0, ce, n1, q1, n2, q2)
    return (local_c, local_n, local_p, local_d, c0, ce, ce1, cf, cf1, normal, p0, pa, pb, face_d, sides,
            n0, n1, n2, q1, q2, point, inverse)


@ti.func
def _clip_witnesses(edge_geom, c0, normal, face_d, point):
    """The witness pair (x1, x2, geom 1's first) and the distance d of a clipped point (MuJoCo
    3.12's witnessOnFace): the point, and it moved |d| against the clipped face's normal D =
    ``face_d`` (or along the clipping face's normal N = ``normal`` for a clipped edge), d = (point
    − c0)·N its height over the clipping face (c0 a vertex). MuJoCo 4.0 puts a face on face's
    witnesses on both planes instead (x1 = point − d N, x2 = x1 − ((x1 − point)·D) D, dist = −d
    N·D, measured): tried, it made the FD scan of a KUKA pushing a box (200 steps, elliptic,
    substeps 2) fail to converge, where this form converges; not kept."""
    d = _dot(point - c0, normal)
    moved = point - ti.select(edge_geom == 0, face_d, -normal) * ti.abs(d)
    return ti.select(edge_geom == 1, point, moved), ti.select(edge_geom == 1, moved, point), d


@ti.func
def _clip_witnesses_adjoint(edge_geom, c0, normal, face_d, point, g_x1, g_x2, g_dist):
    """Reverse of `_clip_witnesses`: (g_c0, g_normal, g_face_d, g_point)."""
    d = _dot(point - c0, normal)
    g_moved = ti.select(edge_geom == 1, g_x2, g_x1)
    direction = ti.select(edge_geom == 0, face_d, -normal)
    g_d = g_dist - _sign(d) * _dot(g_moved, direction) * ti.select(d == 0, 0.0, 1.0)
    g_direction = -ti.abs(d) * g_moved
    g_face_d = ti.select(edge_geom == 0, g_direction, ti.Vector([0.0, 0.0, 0.0]))
    g_normal = ti.select(edge_geom == 0, ti.Vector([0.0, 0.0, 0.0]), -g_direction) + g_d * (point - c0)
    return -g_d * normal, g_normal, g_face_d, g_x1 + g_x2 + g_d * normal


@ti.func
def _clip_evaluate(shape1: ti.template(), shape2: ti.template(), feature, hull: ti.template()):
    """(position, normal, dist) of a KIND_CLIP contact (`_clip_terms`); dist = margin + d, as
    the forward's."""
    terms = _clip_terms(shape1, shape2, feature, hull)  # c0, N, D, the point: entries 4, 9, 13, 20
    x1, x2, d = _clip_witnesses(feature[7], terms[4], terms[9], terms[13], terms[20])
    return (x1 + x2) * 0.5, _normalize(x1 - x2), shape1[5] + d


@ti.func
def _side_plane_adjoint(a, b, normal, g_plane):
    """Reverse of plane normal = (b - a) x normal: (g_a, g_b, g_normal) from g_plane."""
    g_edge = _cross(normal, g_plane)
    return -g_edge, g_edge, _cross(g_plane, b - a)


@ti.func
def _clip_evaluate_adjoint(shape1: ti.template(), shape2: ti.template(), feature, hull: ti.template(),
                           g_position, g_normal, g_dist):
    """Reverse of `_clip_evaluate`: (g_pos1, g_rot1, g_pos2, g_rot2)."""
    (local_c, local_n, local_p, local_d, c0, ce, ce1, cf, cf1, normal, p0, pa, pb, face_d, sides,
     n0, n1, n2, q1, q2, point, inverse) = _clip_terms(shape1, shape2, feature, hull)
    edge_geom = feature[7]
    x1, x2, d = _clip_witnesses(edge_geom, c0, normal, face_d, point)
    g_x1, g_x2 = _witness_adjoint(x1, x2, g_position, g_normal)
    g_c0, g_normal_c, g_face_d, g_point = _clip_witnesses_adjoint(edge_geom, c0, normal, face_d, point, g_x1, g_x2,
                                                                  g_dist)
    g_c = ti.Matrix.zero(float, 5, 3)  # rows: c0, ce, ce1, cf, cf1
    g_p = ti.Matrix.zero(float, 3, 3)  # rows: p0, pa, pb
    for c in ti.static(range(3)):
        g_c[0, c] = g_c0[c]
    if sides == 0:
        for c in ti.static(range(3)):
            g_p[1, c] = g_point[c]
    else:  # point = M^-1 h, rows of M the plane normals n_i, h_i = n_i . q_i
        y = inverse.transpose() @ g_point
        g_n0, g_n1, g_n2 = y[0] * (ce - point), y[1] * (q1 - point), y[2] * (q2 - point)
        g_ce, g_ce1, g_nrm = _side_plane_adjoint(ce, ce1, normal, g_n0)
        g_ce += y[0] * n0
        g_normal_c += g_nrm
        g_q1, g_q2 = y[1] * n1, y[2] * n2
        g_cf, g_cf1, g_pa, g_pb = (ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0]),
                                   ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0]))
        if sides == 2:
            g_cf, g_cf1, g_nrm = _side_plane_adjoint(cf, cf1, normal, g_n1)
            g_cf += g_q1
            g_normal_c += g_nrm
            g_face_d += g_n2
            for c in ti.static(range(3)):
                g_p[0, c] = g_q2[c]
        else:  # n1 = edge x N, n2 = edge x n1, edge = pb - pa, both planes through pa
            edge = pb - pa
            g_across = g_n1 + _cross(g_n2, edge)
            g_edge = _cross(n1, g_n2) + _cross(normal, g_across)
            g_normal_c += _cross(g_across, edge)
            g_pa = g_q1 + g_q2 - g_edge
            g_pb = g_edge
        rows = (g_ce, g_ce1, g_cf, g_cf1)
        for j in ti.static(range(4)):
            for c in ti.static(range(3)):
                g_c[j + 1, c] += rows[j][c]
        for c in ti.static(range(3)):
            g_p[1, c] += g_pa[c]
            g_p[2, c] += g_pb[c]
    g_pos_c, g_pos_p = ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0])
    g_rot_c, g_rot_p = g_normal_c.outer_product(local_n), g_face_d.outer_product(local_d)
    for j in ti.static(range(5)):
        g_cj = ti.Vector([g_c[j, c] for c in ti.static(range(3))])
        g_pos_c += g_cj
        g_rot_c += g_cj.outer_product(ti.Vector([local_c[j, c] for c in ti.static(range(3))]))
    for j in ti.static(range(3)):
        g_pj = ti.Vector([g_p[j, c] for c in ti.static(range(3))])
        g_pos_p += g_pj
        g_rot_p += g_pj.outer_product(ti.Vector([local_p[j, c] for c in ti.static(range(3))]))
    clip_first = edge_geom != 1
    return (ti.select(clip_first, g_pos_c, g_pos_p), ti.select(clip_first, g_rot_c, g_rot_p),
            ti.select(clip_first, g_pos_p, g_pos_c), ti.select(clip_first, g_rot_p, g_rot_c))


@ti.func
def convex_evaluate(type1, pos1, rot1, size1, mesh1, type2, pos2, rot2, size2, mesh2, margin, feature,
                    hull: ti.template()):
    """One contact of `convex_convex` replayed from its feature row (FEATURE_SIZE ints, a
    ti.Vector), a closed form of the two geom poses: (position (3,) world m, normal (3,) from
    geom 1 to geom 2, dist m). Arguments as convex_convex's; `hull` as there."""
    shape1, shape2 = (type1, mesh1, pos1, rot1, size1, margin), (type2, mesh2, pos2, rot2, size2, margin)
    position, normal, dist = ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0]), 0.0
    if feature[0] == KIND_FACE_CAP:
        position, normal, dist = _face_cap_evaluate(shape1, shape2, feature, hull)
    elif feature[0] == KIND_CLIP:
        position, normal, dist = _clip_evaluate(shape1, shape2, feature, hull)
    elif _cap_side(shape1, shape2, feature) != 0:
        position, normal, dist = _cap_evaluate(shape1, shape2, feature, hull)
    elif _rim_side(shape1, shape2, feature) != 0:
        position, normal, dist = _rim_evaluate(shape1, shape2, feature, hull)
    elif _two_rims(shape1, shape2, feature):
        position, normal, dist = _rims_evaluate(shape1, shape2, feature, hull)
    else:
        position, normal, dist = _core_evaluate(shape1, shape2, feature, hull)
    return position, normal, dist


@ti.func
def convex_evaluate_adjoint(type1, pos1, rot1, size1, mesh1, type2, pos2, rot2, size2, mesh2, margin, feature,
                            hull: ti.template(), g_position, g_normal, g_dist):
    """Reverse of `convex_evaluate`: the gradients of g_position . position + g_normal . normal
    + g_dist * dist with respect to pos1 (3,), rot1 (3, 3) (its 9 entries), pos2, rot2:
    (g_pos1, g_rot1, g_pos2, g_rot2). Exact for the closed form; where it is constant (a
    normal of a vector under 1e-15, _normalize's fallback) its derivative is 0."""
    shape1, shape2 = (type1, mesh1, pos1, rot1, size1, margin), (type2, mesh2, pos2, rot2, size2, margin)
    g_pos1, g_pos2 = ti.Vector([0.0, 0.0, 0.0]), ti.Vector([0.0, 0.0, 0.0])
    g_rot1, g_rot2 = ti.Matrix.zero(float, 3, 3), ti.Matrix.zero(float, 3, 3)
    if feature[0] == KIND_FACE_CAP:
        g_pos1, g_rot1, g_pos2, g_rot2 = _face_cap_evaluate_adjoint(shape1, shape2, feature, hull, g_position, g_normal,
                                                                    g_dist)
    elif feature[0] == KIND_CLIP:
        g_pos1, g_rot1, g_pos2, g_rot2 = _clip_evaluate_adjoint(shape1, shape2, feature, hull, g_position,
                                                                g_normal, g_dist)
    elif _cap_side(shape1, shape2, feature) != 0:
        g_pos1, g_rot1, g_pos2, g_rot2 = _cap_evaluate_adjoint(shape1, shape2, feature, hull, g_position,
                                                               g_normal, g_dist)
    elif _rim_side(shape1, shape2, feature) != 0:
        g_pos1, g_rot1, g_pos2, g_rot2 = _rim_evaluate_adjoint(shape1, shape2, feature, hull, g_position,
                                                               g_normal, g_dist)
    elif _two_rims(shape1, shape2, feature):
        g_pos1, g_rot1, g_pos2, g_rot2 = _rims_evaluate_adjoint(shape1, shape2, feature, hull, g_position,
                                                                g_normal, g_dist)
    else:
        g_pos1, g_rot1, g_pos2, g_rot2 = _core_evaluate_adjoint(shape1, shape2, feature, hull, g_position,
                                                                g_normal, g_dist)
    return g_pos1, g_rot1, g_pos2, g_rot2


@ti.func
def iterated(type1, type2, margin, feature):
    """Whether a `convex_convex` contact (its feature row) is not the closed form `convex_evaluate`
    gives but near it: the forward's CCD iterate on a curved support, within the CCD tolerance's
    effect (anything with a cylinder; EPA with a sphere, a capsule or a margin; a clipped edge with
    a margin: its ends are EPA support points), or a corner of the clipping face (two side planes)
    on a mesh's polygon, which the forward interpolates along the clipped polygon's edges and the
    closed form puts on the plane of its vertex 0 and normal: the same where the polygon is
    planar, ~1e-4 m apart on a hull's merged facets that are not (pybullet's Panda finger), where
    the gradient of the closed form then missed the forward's derivative."""
    round_ = type1 == SPHERE or type1 == CAPSULE or type2 == SPHERE or type2 == CAPSULE
    curved = type1 == CYLINDER or type2 == CYLINDER or (feature[0] == KIND_EPA and (margin > 0 or round_))
    corner = feature[0] == KIND_CLIP and feature[7] == 0 and feature[3] >= 256 and feature[4] >= 256 and type2 == MESH
    return feature[0] != KIND_FACE_CAP and (curved or (feature[0] == KIND_CLIP and feature[7] > 0 and margin > 0)
                                            or corner)


@ti.func
def frozen(type1, type2, margin, feature):
    """Whether `convex_evaluate` is not this contact's converged form, so that the forward keeps
    the iterate (detect.converge_contacts) and a backward over it raises: a clipped edge's ends with
    a margin (their half-margin offset is along the iterate's normal), and two cylinders "at their
    rims" with both ends of each in the feature (m = 1: `_core_terms` would take a line through
    both axes, neither cylinder's side)."""
    m, ids1, ids2 = _vertex_ids(feature)
    rims = type1 == CYLINDER and type2 == CYLINDER and feature[10] % 3 == 0 and feature[10] // 3 == 0
    ends = (ids1[1] != ids1[0] or ids1[2] != ids1[0]) and (ids2[1] != ids2[0] or ids2[2] != ids2[0])
    return (feature[0] == KIND_CLIP and feature[7] > 0 and margin > 0) or (feature[0] != KIND_CLIP and rims
                                                                            and m == 1 and ends)


@ti.func
def plane_mesh_evaluate(pos1, rot1, size1, pos2, rot2, size2, mesh2, feature, hull: ti.template()):
    """One contact of `plane_mesh` replayed from its feature row (KIND_PLANE, vertex id):
    (position, normal, dist) of mesh vertex feature[1] against the plane (normal: rot1's z
    column). Arguments as plane_mesh's (sizes unused)."""
    normal = ti.Vector([rot1[0, 2], rot1[1, 2], rot1[2, 2]])
    point = _rot(rot2, hull.hull_vert[hull.hull_vertadr[mesh2] + feature[1]]) + pos2
    depth = _dot(normal, point - pos1)
    return point + normal * (depth * -0.5), normal, depth


@ti.func
def plane_mesh_evaluate_adjoint(pos1, rot1, size1, pos2, rot2, size2, mesh2, feature, hull: ti.template(),
                                g_position, g_normal, g_dist):
    """Reverse of `plane_mesh_evaluate`: (g_pos1, g_rot1, g_pos2, g_rot2)."""
    normal = ti.Vector([rot1[0, 2], rot1[1, 2], rot1[2, 2]])
    local = hull.hull_vert[hull.hull_vertadr[mesh2] + feature[1]]
    point = _rot(rot2, local) + pos2
    depth = _dot(normal, point - pos1)
    g_depth = g_dist - 0.5 * _dot(g_position, normal)
    g_plane = g_normal - 0.5 * depth * g_position + g_depth * (point - pos1)
    g_point = g_position + g_depth * normal
    g_rot1 = ti.Matrix.zero(float, 3, 3)
    for r in ti.static(range(3)):
        g_rot1[r, 2] = g_plane[r]
    return -g_depth * normal, g_rot1, g_point, g_point.outer_product(local)
