"""Rotations in torch: quaternion products and matrices, rotation vectors, and the intrinsic X-Y-Z
Euler angles ↔ quaternion maps (Genesis's free-joint dof positions).

A free joint's three rotational "dof positions" are intrinsic X-Y-Z Euler angles (a, b, c) in
rad: R = Rx(a)·Ry(b)·Rz(c), scipy's ``Rotation.from_euler("XYZ", [a, b, c])``, as in Genesis
1.4.5 (``utils/geom.py``: ``xyz_to_quat``, ``quat_to_xyz``). Both maps are differentiable;
quat → angles is smooth away from gimbal lock (b = ±π/2), where only a + c (or a − c) is
defined: there a = 0, as in Genesis, and the gradient stays finite.
"""
import torch

_TINY = 1e-36  # under a square root: a finite derivative where cos b = 0
_LOCK = 1e-15  # cos b below this is gimbal lock (Genesis's gs.EPS)


def euler_xyz_to_quat(angles):
    """(..., 3) intrinsic X-Y-Z Euler angles, rad → (..., 4) unit quaternions (w, x, y, z):
    q = qx(a) ⊗ qy(b) ⊗ qz(c)."""
    ca, cb, cc = torch.cos(angles / 2).unbind(-1)
    sa, sb, sc = torch.sin(angles / 2).unbind(-1)
    return torch.stack([ca * cb * cc - sa * sb * sc,
                        sa * cb * cc + ca * sb * sc,
                        ca * sb * cc - sa * cb * sc,
                        ca * cb * sc + sa * sb * cc], dim=-1)


def quat_to_euler_xyz(quat):
    """(..., 4) quaternions (w, x, y, z), any non-zero norm → (..., 3) intrinsic X-Y-Z Euler
    angles, rad: a, c in (−π, π], b in [−π/2, π/2]."""
    w, x, y, z = quat.unbind(-1)
    s = 2.0 / (quat * quat).sum(-1)  # the rotation matrix of q/|q| from q's products
    r00, r01, r02 = 1.0 - s * (y * y + z * z), s * (x * y - w * z), s * (x * z + w * y)
    r10, r11 = s * (x * y + w * z), 1.0 - s * (x * x + z * z)
    r12, r22 = s * (y * z - w * x), 1.0 - s * (x * x + y * y)
    cos_b = torch.sqrt(r00 * r00 + r01 * r01 + _TINY)  # R = Rx·Ry·Rz: r00 = cos b cos c, r01 = −cos b sin c
    locked = cos_b <= _LOCK
    b = torch.atan2(r02, cos_b)
    # at lock r12 = r22 = r01 = r00 = 0; torch's atan2 has derivative 0 at (0, 0), not NaN
    a = torch.where(locked, 0.0, torch.atan2(-r12, r22))
    c = torch.where(locked, torch.atan2(r10, r11), torch.atan2(-r01, r00))
    return torch.stack([a, b, c], dim=-1)


def quat_to_mat(quat):
    """(..., 4) unit quaternions (w, x, y, z) → (..., 3, 3) rotation matrices."""
    w, x, y, z = quat.unbind(-1)
    rows = [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]
    return torch.stack(rows, -1).reshape(*quat.shape[:-1], 3, 3)


def quat_mul(a, b):
    """Hamilton product of (..., 4) quaternions (w, x, y, z)."""
    aw, ax, ay, az = a.unbind(-1)
    bw, bx, by, bz = b.unbind(-1)
    return torch.stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                        aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw], -1)


def rotation_vector(quat):
    """(..., 4) unit quaternions → (..., 3) their rotation vectors (axis × angle, angle ≤ π)."""
    quat = torch.where(quat[..., :1] < 0, -quat, quat)
    sin = quat[..., 1:].norm(dim=-1, keepdim=True)
    angle = 2 * torch.atan2(sin, quat[..., :1])
    return quat[..., 1:] * torch.where(sin > 1e-12, angle / sin.clamp_min(1e-12), 2.0)
