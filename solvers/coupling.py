"""Rigid–MPM coupling: which rigid collision shapes the MPM grid meets, as colliders (mpm/colliders.py:
Genesis's LegacyCoupler rule, rigid side).

Coupled: the shapes (plane, sphere, capsule, cylinder, box; meshes as the rigid solver takes them,
their convex hulls; height fields) of entities whose material couples (Genesis's ``needs_coup``),
where the shape collides (a contype or conaffinity; not a morph's collision=False). Those of links
fixed to the world (a chain of fixed joints up to it) are the MPM solver's colliders at rest; those
of moving links meet the grid in the coupling stage (solvers/coupler.py), both ways.
"""
import numpy as np

from .mpm import colliders, layout
from .rigid import geometry
from .rigid.collision import convex
from .rigid.shapes import quat_to_mat

COLLIDER_KIND = {geometry.PLANE: colliders.PLANE, geometry.SPHERE: colliders.SPHERE,
                 geometry.CAPSULE: colliders.CAPSULE, geometry.CYLINDER: colliders.CYLINDER,
                 geometry.BOX: colliders.BOX, geometry.MESH: colliders.HULL, geometry.HFIELD: colliders.HFIELD}


def _static_poses(model):
    """{link: (pos (3,) m, rotation (3, 3))} of the links welded to the world (model.link_static;
    parents first, each static link's parent static too)."""
    poses = {}
    for link in np.flatnonzero(model.link_static):
        parent = model.link_parent[link]
        pos, rot = (np.zeros(3), np.eye(3)) if parent < 0 else poses[parent]
        poses[link] = (pos + rot @ model.link_pos0[link], rot @ quat_to_mat(model.link_quat0[link]))
    return poses


def _hull_field(model, name, k):
    """Entry k of the model's hull int array ``name`` (convex.HULL_INT_FIELDS; geometry.hull_arrays)."""
    header = model.hull_int
    return int(header[header[convex.HULL_INT_FIELDS.index(name)] + k])


def _hull_vertices(model, mesh):
    """(V, 3) m: the vertices of the model's convex hull number ``mesh``."""
    adr = _hull_field(model, "hull_vertadr", mesh)
    return model.hull_vec[adr: adr + _hull_field(model, "hull_vertnum", mesh)]


def _hull_planes(model, mesh):
    """(F, 4): the face planes (outward unit normal, offset m; n·p + offset ≤ 0 inside) of the
    model's convex hull number ``mesh``: its polygons, as the rigid colliders take them."""
    vertices, first = _hull_vertices(model, mesh), _hull_field(model, "hull_polyadr", mesh)
    normals_at = int(model.hull_int[convex.HULL_HEADER - 1])  # (the normals follow the vertices in hull_vec)
    planes = []
    for p in range(first, first + _hull_field(model, "hull_polynum", mesh)):
        normal = model.hull_vec[normals_at + p]
        corner = vertices[_hull_field(model, "hull_poly_vert", _hull_field(model, "hull_poly_vertadr", p))]
        planes.append([*normal, -normal @ corner])
    return np.array(planes)


def _shape_data(model, g, start):
    """(size (3,), data (D,), bounding radius m) of geom g's collider (colliders.py), its data to be
    placed at ``start`` among all colliders' data: a mesh's hull's face planes, a height field's
    grid; none for a primitive, whose size is the geom's."""
    kind, size = model.geom_type[g], model.geom_size[g]
    if kind == geometry.MESH:
        faces = _hull_planes(model, model.geom_mesh[g])
        return (start, len(faces), 0.0), faces.ravel(), model.geom_rbound[g]
    if kind == geometry.HFIELD:
        points = _hull_vertices(model, model.geom_mesh[g])  # its top grid, then its base
        top, ncol = points[: len(points) // 2], int(size[2])
        grid = np.array([size[0], size[1], len(top) // ncol, ncol, *top[:, 2]])
        return (start, 0.0, 0.0), grid, float(np.linalg.norm(points, axis=1).max())
    return size, np.zeros(0), np.inf if kind == geometry.PLANE else model.geom_rbound[g]


def rigid_colliders(model, coupled):
    """The colliders of the rigid model's coupled shapes: (static, moving). static: (rows (C, colliders.WIDTH),
    data (D,)) of the shapes fixed to the world (colliders.packed); moving: (rows, data, geoms (C', 2) int:
    each row's rigid geom and its link) of the others, whose rows' poses are unused (the rigid frame's
    are taken: coupler.py). coupled: per rigid entity (the model's link_entity numbers), whether it
    couples; a row's coupling parameters are its entity's, among the MPM solver's per-env inputs."""
    poses = _static_poses(model)
    tables = {True: ([], [], []), False: ([], [], [])}  # at rest? → (rows, data, geoms)
    for g, (kind, link) in enumerate(zip(model.geom_type, model.geom_link)):
        entity = model.link_entity[link]
        if not coupled[entity] or not model.geom_collides[g]:
            continue
        rows, data, geoms = tables[link in poses]
        pos, rot = np.zeros(3), np.eye(3)
        if link in poses:
            link_pos, link_rot = poses[link]
            pos, rot = link_pos + link_rot @ model.geom_pos[g], link_rot @ quat_to_mat(model.geom_quat[g])
        size, shape_data, bound = _shape_data(model, g, sum(len(d) for d in data))
        data.append(shape_data)
        geoms.append((g, link))
        rows.append([COLLIDER_KIND[int(kind)], *pos, *rot.ravel(), *size,
                     layout.COUPLING_AT + layout.coupling_columns(entity)[0], bound])

    def packed(rows, data, geoms):
        return (np.array(rows, dtype=np.float64).reshape(-1, colliders.WIDTH), np.concatenate([np.zeros(0), *data]),
                np.array(geoms, dtype=np.int32).reshape(-1, 2))

    static, moving = packed(*tables[True]), packed(*tables[False])
    return static[:2], moving
