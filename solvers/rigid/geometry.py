"""Collision geometry of the rigid model, in MuJoCo's conventions, and the geom pairs that may
collide. Built once at scene build (plain numpy).

MuJoCo's conventions are kept so that the colliders can be checked against MuJoCo directly:
type codes (``GEOM_CODE``), half sizes, a plane's normal along its frame's z axis, a pair
ordered by type with the normal pointing from its first geom to its second. Meshes collide as
their convex hull (trimesh); height fields as the prisms of their grid (collision/hfield.py).
"""
import math

import numpy as np

from ..core import AssetError
from . import shapes
from .collision import convex, hfield

# MuJoCo's mjtGeom codes (its collision table is indexed by them)
PLANE, HFIELD, SPHERE, CAPSULE, CYLINDER, BOX, MESH = 0, 1, 2, 3, 5, 6, 7
GEOM_CODE = {"plane": PLANE, "hfield": HFIELD, "sphere": SPHERE, "capsule": CAPSULE, "cylinder": CYLINDER,
             "box": BOX, "mesh": MESH}


def hull_arrays(hulls):
    """The hulls (convex.MeshHulls) as two flat arrays for the kernels: hull_vec (H, 3), every
    hull vertex (m, geom frame) then every polygon's outward unit normal, and hull_int (HI,),
    HULL_HEADER slots (where each of convex.HULL_INT_FIELDS starts in hull_int, then where the
    normals start in hull_vec) followed by those int arrays."""
    fields = [np.asarray(getattr(hulls, name), dtype=np.int32).ravel() for name in convex.HULL_INT_FIELDS]
    header, start = [], convex.HULL_HEADER
    for array in fields:
        header.append(start)
        start += len(array)
    header.append(len(hulls.hull_vert))
    hull_int = np.concatenate([np.array(header, dtype=np.int32)] + fields).astype(np.int32)
    hull_vec = np.concatenate([np.asarray(hulls.hull_vert, dtype=np.float64).reshape(-1, 3),
                               np.asarray(hulls.hull_poly_normal, dtype=np.float64).reshape(-1, 3)])
    return hull_vec, hull_int


def geom_arrays(geoms, link_of, where_of):
    """Per-geom arrays in MuJoCo's conventions from GeomSpecs.

    geoms: list of GeomSpec; link_of[k]: its link; where_of(k): a name for error messages.
    Returns a dict: type (G,) code, link (G,), pos (G, 3) m and quat (G, 4) the geom frame in the
    link frame, size (G, 3) MuJoCo sizes (half extents, radius and half length; a height field's
    half extents x, y and its grid's column count), rbound (G,) m
    radius of a sphere about the geom origin holding it (0 for planes: unbounded), aabb_center and
    aabb_half (G, 3) m the centre and half extents of a box holding it in the geom frame (MuJoCo's
    geom_aabb; zero for planes), centre (G, 3) m a point inside it, in the geom frame (the mean of a
    mesh hull's vertices, which a mesh file's origin need not be; the origin for a primitive), mesh
    (G,) the geom's number among the hulls (-1: not a mesh or height field); and the meshes' convex
    hulls (convex.mesh_hull: vertices, vertex graph, polygons) and the height fields' grids
    (hfield.grid_hull) as hull_vec (H, 3) and hull_int (HI,) (``hull_arrays``). A mesh collides as
    its convex hull; one without volume is an AssetError.
    """
    out = {k: [] for k in ("type", "link", "pos", "quat", "size", "rbound", "aabb_half", "mesh")}
    meshes = []
    for k, geom in enumerate(geoms):
        size, quat, mesh = np.zeros(3), np.asarray(geom.quat, dtype=np.float64), -1
        s = np.asarray(geom.size, dtype=np.float64)
        if geom.type == "box":
            size[:] = s / 2
            rbound = math.sqrt(size[0] * size[0] + size[1] * size[1] + size[2] * size[2])  # (MuJoCo's rounding)
        elif geom.type == "sphere":
            size[0] = rbound = s[0]
        elif geom.type in ("capsule", "cylinder"):
            size[:2] = s[0], s[1] / 2
            rbound = size[0] + size[1] if geom.type == "capsule" else math.sqrt(size[0] * size[0] + size[1] * size[1])
        elif geom.type == "plane":
            quat, rbound = shapes.quat_mul(quat, shapes.quat_z_to(s)), 0.0
        elif geom.type == "hfield":  # its grid is a hull entry (hfield.grid_hull); bounds from it below
            mesh, rbound = len(meshes), 0.0
            meshes.append(hfield.grid_hull(s, geom.elevation))
            size[:] = s[0], s[1], geom.elevation.shape[1]
        else:  # mesh
            mesh = len(meshes)
            try:
                meshes.append(convex.mesh_hull(geom.vertices))
            except AssetError as error:
                raise AssetError(f"{where_of(k)}: {error}") from None
            rbound = 0.0  # set from its hull below
        out["type"].append(GEOM_CODE[geom.type])
        out["link"].append(link_of[k])
        out["pos"].append(np.asarray(geom.pos, dtype=np.float64))
        out["quat"].append(shapes.normalized(quat)[0])
        out["size"].append(size)
        out["rbound"].append(rbound)
        out["aabb_half"].append(_aabb_half(geom.type, size))
        out["mesh"].append(mesh)
    arrays = {k: np.array(v, dtype=np.int32 if k in ("type", "link", "mesh") else np.float64)
              for k, v in out.items()}
    for k, width in (("pos", 3), ("quat", 4), ("size", 3), ("aabb_half", 3)):
        arrays[k] = arrays[k].reshape(-1, width)
    arrays["aabb_center"], arrays["centre"] = np.zeros_like(arrays["aabb_half"]), np.zeros_like(arrays["aabb_half"])
    hulls = convex.pack_hulls(meshes)
    for k, mesh in enumerate(arrays["mesh"]):
        if mesh >= 0:
            adr, num = hulls.hull_vertadr[mesh], hulls.hull_vertnum[mesh]
            vertices = np.asarray(hulls.hull_vert[adr: adr + num], dtype=np.float64).reshape(-1, 3)
            arrays["rbound"][k] = np.linalg.norm(vertices, axis=1).max()
            lowest, highest = vertices.min(axis=0), vertices.max(axis=0)
            arrays["aabb_center"][k], arrays["aabb_half"][k] = (lowest + highest) / 2, (highest - lowest) / 2
            arrays["centre"][k] = vertices.mean(axis=0)  # (a box's centre can lie on the hull: a wedge's)
    arrays["hull_vec"], arrays["hull_int"] = hull_arrays(hulls)
    return arrays


def _aabb_half(geom_type, size):
    """Half extents (3,) m of the box about the geom origin that holds a primitive of MuJoCo sizes
    ``size`` (3,); zeros for a plane (unbounded) and a mesh (set from its hull)."""
    radius, half_length = size[0], size[1]
    return {"box": size, "sphere": np.full(3, radius), "capsule": np.array([radius, radius, radius + half_length]),
            "cylinder": np.array([radius, radius, half_length])}.get(geom_type, np.zeros(3))


def candidate_pairs(geom_type, geom_link, link_parent, link_static, link_tree, self_collision=True,
                    adjacent_collision=False, geom_masks=None, link_body=None, link_weld=None,
                    link_exclusions=None):
    """(N, 2) geom pairs that may collide, each ordered as MuJoCo orders it (lower type code
    first, then lower index), in MuJoCo's order: by link pair (its broad phase's body pairs,
    lower link first, static links as its world body 0 whatever their index), then within a link
    pair by the ordered geoms (its contactSort of a pair whose bodies hold several geoms), so
    contacts come in MuJoCo's order.

    Rules (Genesis's, which agree with MuJoCo's defaults except where said): two geoms of one
    link never collide; nor two links both welded to the world; nor parent and child links unless
    ``adjacent_collision`` (MuJoCo's filterparent; the world, parent -1, is nobody's parent here);
    nor two links of one kinematic tree (``link_tree`` (L,): its root link) unless ``self_collision``
    (an entity is one tree, or several for an MJCF with several root bodies: Genesis's rule is per
    root); nor two geoms whose bit masks
    ``geom_masks`` (G, 2) (contype, conaffinity; None: all 1) share no bit, MuJoCo's rule.
    The rules take links by weld group, as MuJoCo's filter does: ``link_weld`` (L,) names each
    link's group by its first link (a link welded to a moving parent by a fixed joint, or
    continuing its parent's body, is in its parent's group; None: every link its own), so a
    welded child never meets its parent's parent either; a link welded to the world stays its
    own group (MuJoCo's parent filter skips the world). ``link_body`` (L,): each link's body by
    its first link, for the order (None: every link its own; an MJCF body whose joints split it
    into several links is one body).
    ``link_exclusions``: per link, a set of (lower, higher) link pairs that never collide (MJCF
    ``<contact><exclude>``), or None.
    Pairs touching at the initial pose are filtered later (they need the colliders).
    """
    excluded = set().union(*link_exclusions) if link_exclusions else set()
    masks = np.ones((len(geom_type), 2), dtype=np.int64) if geom_masks is None else np.asarray(geom_masks)
    body_of = np.arange(len(link_parent)) if link_body is None else np.asarray(link_body)
    weld_of = np.arange(len(link_parent)) if link_weld is None else np.asarray(link_weld)
    parent_weld = np.array([weld_of[p] if p >= 0 else -1 for p in link_parent], dtype=np.int64)
    pairs = []
    for a in range(len(geom_type)):
        for b in range(a + 1, len(geom_type)):
            la, lb = weld_of[geom_link[a]], weld_of[geom_link[b]]
            if la == lb or (link_static[la] and link_static[lb]):
                continue
            if not adjacent_collision and (parent_weld[la] == lb or parent_weld[lb] == la):
                continue
            if not self_collision and link_tree[la] == link_tree[lb]:
                continue
            if geom_type[a] == PLANE and geom_type[b] == PLANE:
                continue  # MuJoCo has no plane-plane collider
            if not (masks[a, 0] & masks[b, 1] or masks[b, 0] & masks[a, 1]):
                continue
            if (min(geom_link[a], geom_link[b]), max(geom_link[a], geom_link[b])) in excluded:
                continue
            pairs.append((a, b) if geom_type[a] <= geom_type[b] else (b, a))
    body = [-1 if link_static[link] else body_of[link] for link in range(len(link_static))]  # static: MuJoCo's world
    pairs.sort(key=lambda pair: (*sorted((body[geom_link[pair[0]]], body[geom_link[pair[1]]])), *pair))
    return np.array(pairs, dtype=np.int32).reshape(-1, 2)

