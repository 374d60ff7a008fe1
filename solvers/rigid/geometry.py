"""Collision geometry of the rigid model, in MuJoCo's conventions, and the geom pairs that may
collide. Built once at scene build (plain numpy).

MuJoCo's conventions are kept so that the colliders can be checked against MuJoCo directly:
type codes (``GEOM_CODE``), half sizes, a plane's normal along its frame's z axis, a pair
ordered by type with the normal pointing from its first geom to its second. Meshes collide as
their convex hull (trimesh).
"""
import numpy as np
import trimesh

from ..core import AssetError

# MuJoCo's mjtGeom codes (its collision table is indexed by them)
PLANE, SPHERE, CAPSULE, CYLINDER, BOX, MESH = 0, 2, 3, 5, 6, 7
GEOM_CODE = {"plane": PLANE, "sphere": SPHERE, "capsule": CAPSULE, "cylinder": CYLINDER, "box": BOX, "mesh": MESH}


def _quat_z_to(normal):
    """(4,) w-x-y-z quaternion turning +z onto the unit vector ``normal``."""
    n = np.asarray(normal, dtype=np.float64) / np.linalg.norm(normal)
    w = 1.0 + n[2]
    if w < 1e-12:  # normal = −z: half a turn about x
        return np.array([0.0, 1.0, 0.0, 0.0])
    q = np.array([w, -n[1], n[0], 0.0])  # (1 + z·n, z × n), normalised
    return q / np.linalg.norm(q)


def _quat_mul(a, b):
    aw, av, bw, bv = a[0], np.asarray(a[1:]), b[0], np.asarray(b[1:])
    return np.concatenate([[aw * bw - av @ bv], aw * bv + bw * av + np.cross(av, bv)])


def _convex_hull(geom, where):
    """(V, 3) vertices of the convex hull of a mesh geom, in its frame."""
    try:
        hull = trimesh.convex.convex_hull(np.asarray(geom.vertices, dtype=np.float64))
    except Exception as error:  # qhull raises its own error types on flat or degenerate input
        raise AssetError(f"{where}: mesh expected a convex hull with volume, got a degenerate one ({error})") from None
    if len(hull.vertices) < 4 or not hull.volume > 0:
        raise AssetError(f"{where}: mesh expected a convex hull with volume, got {len(hull.vertices)} vertices and "
                         f"volume {hull.volume}")
    return np.asarray(hull.vertices, dtype=np.float64)


def geom_arrays(geoms, link_of, where_of):
    """Per-geom arrays in MuJoCo's conventions from GeomSpecs.

    geoms: list of GeomSpec; link_of[k]: its link; where_of(k): a name for error messages.
    Returns a dict: type (G,) code, link (G,), pos (G, 3) m and quat (G, 4) the geom frame in the
    link frame, size (G, 3) MuJoCo sizes (half extents, radius and half length), rbound (G,) m
    radius of a sphere about the geom origin holding it (0 for planes: unbounded), hull0 and
    hull_n (G,) each mesh's hull vertices in ``hull_vert`` (H, 3) m, geom frame.
    """
    out = {k: [] for k in ("type", "link", "pos", "quat", "size", "rbound", "hull0", "hull_n")}
    hull_vert = []
    for k, geom in enumerate(geoms):
        size, quat, hull = np.zeros(3), np.asarray(geom.quat, dtype=np.float64), None
        s = np.asarray(geom.size, dtype=np.float64)
        if geom.type == "box":
            size[:] = s / 2
            rbound = np.linalg.norm(size)
        elif geom.type == "sphere":
            size[0] = rbound = s[0]
        elif geom.type in ("capsule", "cylinder"):
            size[:2] = s[0], s[1] / 2
            rbound = size[0] + size[1] if geom.type == "capsule" else np.hypot(size[0], size[1])
        elif geom.type == "plane":
            quat, rbound = _quat_mul(quat, _quat_z_to(s)), 0.0
        else:  # mesh
            hull = _convex_hull(geom, where_of(k))
            rbound = np.max(np.linalg.norm(hull, axis=1))
        out["type"].append(GEOM_CODE[geom.type])
        out["link"].append(link_of[k])
        out["pos"].append(np.asarray(geom.pos, dtype=np.float64))
        out["quat"].append(quat / np.linalg.norm(quat))
        out["size"].append(size)
        out["rbound"].append(rbound)
        out["hull0"].append(len(hull_vert))
        out["hull_n"].append(0 if hull is None else len(hull))
        if hull is not None:
            hull_vert.extend(hull)
    arrays = {k: np.array(v, dtype=np.int32 if k in ("type", "link", "hull0", "hull_n") else np.float64)
              for k, v in out.items()}
    for k, width in (("pos", 3), ("quat", 4), ("size", 3)):
        arrays[k] = arrays[k].reshape(-1, width)
    arrays["hull_vert"] = np.array(hull_vert, dtype=np.float64).reshape(-1, 3)
    return arrays


def candidate_pairs(geom_type, geom_link, link_parent, link_static, link_entity, self_collision=True,
                    adjacent_collision=False):
    """(N, 2) geom pairs that may collide, each ordered as MuJoCo orders it (lower type code
    first, then lower index), in a fixed order.

    Rules (Genesis's, which agree with MuJoCo's defaults except where said): two geoms of one
    link never collide; nor two links both welded to the world; nor parent and child links unless
    ``adjacent_collision`` (MuJoCo's filterparent; the world, parent -1, is nobody's parent here);
    nor two links of one entity unless ``self_collision``. Pairs touching at the initial pose
    are filtered later (they need the colliders).
    """
    pairs = []
    for a in range(len(geom_type)):
        for b in range(a + 1, len(geom_type)):
            la, lb = geom_link[a], geom_link[b]
            if la == lb or (link_static[la] and link_static[lb]):
                continue
            if not adjacent_collision and (link_parent[la] == lb or link_parent[lb] == la):
                continue
            if not self_collision and link_entity[la] == link_entity[lb]:
                continue
            if geom_type[a] == PLANE and geom_type[b] == PLANE:
                continue  # MuJoCo has no plane-plane collider
            pairs.append((a, b) if geom_type[a] <= geom_type[b] else (b, a))
    return np.array(pairs, dtype=np.int32).reshape(-1, 2)

