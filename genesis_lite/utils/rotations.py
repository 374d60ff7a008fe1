"""Rotations in torch: quaternion products and matrices, rotation vectors, and the Euler angles ↔
quaternion maps (intrinsic X-Y-Z: Genesis's free-joint dof positions; roll-pitch-yaw: a morph's
``euler``). ``genesis_lite.utils.geom`` offers them under Genesis's names.

A free joint's three rotational "dof positions" are intrinsic X-Y-Z Euler angles (a, b, c) in
rad: R = Rx(a)·Ry(b)·Rz(c), scipy's ``Rotation.from_euler("XYZ", [a, b, c])``, as in Genesis
1.4.5 (``utils/geom.py``: ``xyz_to_quat``, ``quat_to_xyz``). Both maps are differentiable;
quat → angles is smooth away from gimbal lock (b = ±π/2), where only a + c (or a − c) is
defined: there a = 0, as in Genesis, and the gradient stays finite.
"""
import torch

_TINY = 1e-36  # under a square root: a finite derivative where cos b = 0
_LOCK = 1e-15  # cos b below this is gimbal lock (Genesis's gs.EPS)


def euler_xyz_to_quat(angles, rpy=False):
    """(..., 3) Euler angles (a, b, c), rad → (..., 4) unit quaternions (w, x, y, z).

    rpy False: intrinsic X-Y-Z, q = qx(a) ⊗ qy(b) ⊗ qz(c) (a free joint's dof positions);
    rpy True: roll, pitch, yaw about fixed x, y, z, q = qz(c) ⊗ qy(b) ⊗ qx(a) (a morph's ``euler``).
    The two differ only in the sign of the products of three sines."""
    ca, cb, cc = torch.cos(angles / 2).unbind(-1)
    sa, sb, sc = torch.sin(angles / 2).unbind(-1)
    sign = 1.0 if rpy else -1.0
    return torch.stack([ca * cb * cc + sign * sa * sb * sc,
                        sa * cb * cc - sign * ca * sb * sc,
                        ca * sb * cc + sign * sa * cb * sc,
                        ca * cb * sc - sign * sa * sb * cc], dim=-1)


def quat_to_euler_xyz(quat, rpy=False):
    """(..., 4) quaternions (w, x, y, z), any non-zero norm → (..., 3) Euler angles (a, b, c), rad,
    in the convention of ``euler_xyz_to_quat(angles, rpy)``: a, c in (−π, π], b in [−π/2, π/2]."""
    w, x, y, z = quat.unbind(-1)
    s = 2.0 / (quat * quat).sum(-1)  # entries of the rotation matrix of q/|q| from q's products
    sign = -1.0 if rpy else 1.0  # R = Rx·Ry·Rz; rpy: R = Rz·Ry·Rx, the same entries up to signs
    sin_b = s * (w * y + sign * x * z)
    sin_a_cos_b, cos_a_cos_b = s * (w * x - sign * y * z), 1.0 - s * (x * x + y * y)
    sin_c_cos_b, cos_c_cos_b = s * (w * z - sign * x * y), 1.0 - s * (y * y + z * z)
    cos_b = torch.sqrt(cos_c_cos_b * cos_c_cos_b + sin_c_cos_b * sin_c_cos_b + _TINY)
    locked = cos_b <= _LOCK
    b = torch.atan2(sin_b, cos_b)
    # at lock cos b = 0 and only a ± c is defined: a = 0, c from the entries that keep it
    # (torch's atan2 has derivative 0 at (0, 0), not NaN)
    a = torch.where(locked, 0.0, torch.atan2(sin_a_cos_b, cos_a_cos_b))
    c_locked = torch.atan2(s * (w * z + sign * x * y), 1.0 - s * (x * x + z * z))
    c = torch.where(locked, c_locked, torch.atan2(sin_c_cos_b, cos_c_cos_b))
    return torch.stack([a, b, c], dim=-1)


def quat_to_mat(quat):
    """(..., 4) unit quaternions (w, x, y, z) → (..., 3, 3) rotation matrices."""
    w, x, y, z = quat.unbind(-1)
    rows = [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]
    return torch.stack(rows, -1).reshape(*quat.shape[:-1], 3, 3)


def rotate(quat, vectors):
    """(..., 3) ``vectors`` turned by (..., 4) unit quaternions (w, x, y, z), broadcast together:
    v + 2w (u × v) + u × (2 u × v), u = (x, y, z): fewer operations than through quat_to_mat."""
    w, u = quat[..., :1], quat[..., 1:]
    # (linalg.cross broadcasts batch axes of as many dims: the fewer get leading ones)
    u = u.reshape((1,) * (vectors.dim() - u.dim()) + u.shape)
    vectors = vectors.reshape((1,) * (u.dim() - vectors.dim()) + vectors.shape)
    turn = 2.0 * torch.linalg.cross(u, vectors)
    return vectors + w * turn + torch.linalg.cross(u, turn)


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
