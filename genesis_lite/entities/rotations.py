"""Rotation-vector ↔ quaternion maps in torch, smooth at zero rotation.

A free joint's "dof positions" are its origin (m) and its orientation as a rotation vector
(rad, axis × angle), the chart in which its angular dofs move. The tiny offset under the
square roots keeps the derivative finite at zero rotation.
"""
import torch

_TINY = 1e-36


def rotvec_to_quat(rotvec):
    """(..., 3) rotation vectors → (..., 4) unit quaternions (w, x, y, z)."""
    angle = torch.sqrt((rotvec * rotvec).sum(-1, keepdim=True) + _TINY)
    return torch.cat([torch.cos(angle / 2), torch.sin(angle / 2) / angle * rotvec], dim=-1)


def quat_to_rotvec(quat):
    """(..., 4) quaternions (any norm, w ≥ 0 preferred) → (..., 3) rotation vectors, angle ≤ π."""
    quat = quat * torch.where(quat[..., :1] < 0, -1.0, 1.0)
    w, xyz = quat[..., :1], quat[..., 1:]
    sine = torch.sqrt((xyz * xyz).sum(-1, keepdim=True) + _TINY)
    return 2.0 * torch.atan2(sine, w) / sine * xyz
