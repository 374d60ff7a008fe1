"""World-axes bounding boxes of collision shapes at their links' poses, in torch (differentiable
in the poses): what ``RigidEntity.get_AABB`` returns.

Each primitive's box is exact: a box's corners, a sphere's radius, a capsule's segment ends
widened by its radius, a cylinder's two rim circles (along world axis i a circle of radius r
about axis a reaches r·√(1 − a_i²)); a mesh's is its vertices', a height field's its grid's
(top and base). A plane is unbounded: ±inf.
"""
import numpy as np
import torch

from ..solvers.rigid.collision import hfield
from ..utils.rotations import quat_to_mat


def shapes_aabb(shapes, link_pos, link_quat):
    """shapes: (link index, GeomSpec) pairs; link_pos (B, L, 3) m, link_quat (B, L, 4) →
    (B, 2, 3) m: the lower and upper corners of the box holding every shape."""
    lows, highs = [], []
    for link, shape in shapes:
        link_rot = quat_to_mat(link_quat[:, link])
        rot = link_rot @ quat_to_mat(_like(shape.quat, link_pos))  # (B, 3, 3): the shape's axes in the world
        centre = link_pos[:, link] + link_rot @ _like(shape.pos, link_pos)
        if shape.type in ("mesh", "hfield"):
            vertices = shape.vertices if shape.type == "mesh" else hfield.grid_hull(shape.size, shape.elevation)["vert"]
            points = centre[:, None] + _like(vertices, link_pos) @ rot.transpose(-1, -2)
            lows.append(points.amin(dim=1))
            highs.append(points.amax(dim=1))
            continue
        half = _half_extents(shape.type, _like(shape.size, link_pos), rot)
        lows.append(centre - half)
        highs.append(centre + half)
    return torch.stack([torch.stack(lows).amin(dim=0), torch.stack(highs).amax(dim=0)], dim=1)


def _like(values, tensor):
    return torch.as_tensor(np.asarray(values), dtype=tensor.dtype, device=tensor.device)


def _half_extents(kind, size, rot):
    """(B, 3) half extents along the world axes of a primitive of ``size`` (ShapeSpec's: full box
    extents; radius; radius and full length along its z) whose axes are ``rot`` (B, 3, 3)."""
    if kind == "box":
        return rot.abs() @ (size / 2)
    if kind == "sphere":
        return size[0].expand(rot.shape[0], 3)
    if kind == "plane":
        return torch.full_like(rot[:, 0], torch.inf)
    radius, half_length, axis = size[0], size[1] / 2, rot[:, :, 2]
    if kind == "capsule":
        return axis.abs() * half_length + radius
    # cylinder: √(1 − a_i²) as the norm of the other two components (its slope is 0, not NaN, at 0)
    others = torch.stack([axis[:, [1, 2]], axis[:, [0, 2]], axis[:, [0, 1]]], dim=1)
    return axis.abs() * half_length + radius * torch.linalg.vector_norm(others, dim=-1)
