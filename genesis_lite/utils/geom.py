"""Rotations and rigid transforms under Genesis 1.4.5's ``gs.utils.geom`` names and conventions.

Quaternions are (w, x, y, z). ``xyz`` Euler angles are intrinsic X-Y-Z, R = Rx(a)·Ry(b)·Rz(c) (a
free joint's dof positions), or with ``rpy=True`` roll, pitch and yaw about the fixed x, y, z
axes, R = Rz(c)·Ry(b)·Rx(a) (a morph's ``euler``); radians unless ``degrees=True``. A pose's
matrix T is 4×4 homogeneous. Leading batch axes broadcast.

Every function takes torch tensors (differentiable, on their device) or numpy arrays and returns
what it was given: numpy in, numpy out, float32 kept and any other dtype computed in float64.
**Different** from Genesis: lists are taken as numpy arrays, and a numpy array or list next to a
tensor is converted to the tensor's dtype and device (Genesis raises for both); a batch of 4×4
matrices inverts with ``inv_T`` (Genesis's transposes the batch axes too). A quaternion need not
have unit norm wherever it only rotates: the rotation is q/|q|'s, as in Genesis; a zero one gives
NaN in a batch (as Genesis) and a named error alone, as do wrong shapes and non-bool flags.
"""
import functools
import inspect

import numpy as np
import torch

from ..options import check_bool, is_int
from ..solvers.core import InvalidInputError
from . import rotations

__all__ = ["inv_quat", "normalize", "xyz_to_quat", "quat_to_xyz", "quat_to_R", "R_to_quat", "R_to_xyz",
           "euler_to_quat", "euler_to_R", "transform_quat_by_quat", "transform_by_quat", "inv_transform_by_quat",
           "transform_by_trans_quat", "inv_transform_by_trans_quat", "transform_pos_quat_by_trans_quat",
           "inv_transform_pos_quat_by_trans_quat", "axis_angle_to_quat", "quat_to_rotvec", "rotvec_to_quat",
           "slerp", "trans_quat_to_T", "trans_R_to_T", "R_to_T", "trans_to_T", "T_to_trans", "T_to_quat",
           "T_to_trans_quat", "inv_T", "transform_by_R", "transform_by_trans_R", "transform_by_T",
           "inv_transform_by_T", "random_quaternion"]

# |cos θ| above 1 − this (or 4 ulps of 1 in the dtype): the arc is too short for sin θ, interpolate linearly
_SLERP_LINEAR = 1e-15


def _arrays(positional_out=False, **trailing):
    """Decorate a torch function of the named array arguments, each with its trailing shape
    (an int, a tuple, or () for any): numpy arrays and lists become tensors, shapes are checked,
    and the result is numpy again when no argument was a tensor. Genesis's keyword ``out`` (an
    array or tensor of the result's shape) receives a single result and is returned; with
    ``positional_out`` it may also follow the arguments, as Genesis's signature has it there."""
    trailing = {name: (shape,) if isinstance(shape, int) else shape for name, shape in trailing.items()}

    def decorate(fn):
        signature = inspect.signature(fn)

        @functools.wraps(fn)
        def run(*args, out=None, **kwargs):
            if positional_out and out is None and len(args) == len(signature.parameters) + 1:
                *args, out = args
            bound = signature.bind(*args, **kwargs)
            arrays = {name: _array(fn.__name__, name, bound.arguments[name], shape)
                      for name, shape in trailing.items() if bound.arguments.get(name) is not None}
            dtype, device = _common_type(arrays.values())
            for name, array in arrays.items():
                bound.arguments[name] = torch.as_tensor(array, dtype=dtype, device=device)
            try:
                result = fn(*bound.args, **bound.kwargs)
            except RuntimeError as error:  # torch's for batch shapes that do not broadcast (others pass on)
                if isinstance(error, torch.OutOfMemoryError) or "must match the size" not in str(error):
                    raise
                shapes = ", ".join(f"'{name}' {tuple(bound.arguments[name].shape)}" for name in arrays)
                raise InvalidInputError(f"gs.utils.geom.{fn.__name__}: the arguments' shapes do not fit together "
                                        f"(their batch shapes must broadcast), got {shapes} ({error})") from None
            if not any(isinstance(array, torch.Tensor) for array in arrays.values()):
                result = _to_numpy(result)
            return result if out is None else _write(fn.__name__, out, result)
        return run
    return decorate


def _common_type(arrays):
    """The dtype and device every argument is converted to: the first floating tensor's, else the
    default dtype on the first tensor's device; with no tensor, float32 if a float32 array is
    given, else float64."""
    tensors = [array for array in arrays if isinstance(array, torch.Tensor)]
    floating = [tensor for tensor in tensors if tensor.is_floating_point()]
    if floating:
        return floating[0].dtype, floating[0].device
    if tensors:
        return torch.get_default_dtype(), tensors[0].device
    single = any(array.dtype == np.float32 for array in arrays)
    return torch.float32 if single else torch.float64, torch.device("cpu")


def _array(fn, name, value, shape):
    """``value`` as a tensor or a contiguous numpy array (torch cannot view negative strides),
    checked to hold numbers with the trailing ``shape``."""
    try:
        array = value if isinstance(value, torch.Tensor) else np.ascontiguousarray(value)
    except ValueError as error:  # ragged nested lists
        raise InvalidInputError(f"gs.utils.geom.{fn}: argument '{name}' must be an array, got {value!r}") from error
    if isinstance(array, torch.Tensor):
        numbers = array.dtype != torch.bool and not array.is_complex()
    else:
        numbers = array.dtype.kind in "fiu"
    if not numbers:
        raise InvalidInputError(f"gs.utils.geom.{fn}: argument '{name}' must hold real numbers, got dtype "
                                f"{array.dtype}")
    if len(array.shape) < len(shape) or tuple(array.shape[len(array.shape) - len(shape):]) != shape:
        expected = "(..., " + ", ".join(str(n) for n in shape) + ")"
        raise InvalidInputError(f"gs.utils.geom.{fn}: argument '{name}' must have shape {expected}, "
                                f"got {tuple(array.shape)}")
    return array


def _write(fn, out, result):
    if isinstance(result, tuple) or tuple(out.shape) != tuple(result.shape):
        shape = "pair" if isinstance(result, tuple) else tuple(result.shape)
        raise InvalidInputError(f"gs.utils.geom.{fn}: argument 'out' must have the result's shape {shape}, "
                                f"got {tuple(out.shape)}")
    out[...] = torch.as_tensor(result, dtype=out.dtype) if isinstance(out, torch.Tensor) else np.asarray(result)
    return out


def _to_numpy(result):
    if isinstance(result, tuple):
        return tuple(_to_numpy(part) for part in result)
    return result.detach().cpu().numpy()


def _rotation(fn, name, quat):
    """quat / |quat| (..., 4): the rotation of a quaternion of any norm. A single zero or
    non-finite quaternion is a named error; in a batch its row is NaN, as Genesis's (a diverged
    env's row, which a training loop resets, and no wait for the device a check would be)."""
    norm = torch.linalg.vector_norm(quat, dim=-1, keepdim=True)
    if quat.dim() == 1 and not (0 < float(norm) < torch.inf):
        raise InvalidInputError(f"gs.utils.geom.{fn}: argument '{name}' must be a non-zero finite quaternion "
                                f"(w, x, y, z), got {quat.detach().cpu().numpy()}")
    return quat / norm


# ---- quaternions and Euler angles ----

@_arrays(quat=4)
def inv_quat(quat):
    """(..., 4) → (..., 4) the conjugate: the inverse rotation (of a unit quaternion, its inverse)."""
    return torch.cat([quat[..., :1], -quat[..., 1:]], dim=-1)


@_arrays(x=())
def normalize(x, eps=1e-12):
    """x / |x| along the last axis, |x| clamped below at ``eps``."""
    return x / torch.linalg.vector_norm(x, dim=-1, keepdim=True).clamp_min(eps)


@_arrays(xyz=3)
def xyz_to_quat(xyz, rpy=False, degrees=False):
    """(..., 3) Euler angles → (..., 4) unit quaternions (conventions: the module's docstring)."""
    rpy, degrees = check_bool("gs.utils.geom.xyz_to_quat", "rpy", rpy), \
        check_bool("gs.utils.geom.xyz_to_quat", "degrees", degrees)
    return rotations.euler_xyz_to_quat(torch.deg2rad(xyz) if degrees else xyz, rpy=rpy)


@_arrays(quat=4)
def quat_to_xyz(quat, rpy=False, degrees=False):
    """(..., 4) quaternions, any non-zero norm → (..., 3) Euler angles, the first and last in
    (−π, π], the middle in [−π/2, π/2]; at gimbal lock the first is 0, as Genesis's."""
    rpy, degrees = check_bool("gs.utils.geom.quat_to_xyz", "rpy", rpy), \
        check_bool("gs.utils.geom.quat_to_xyz", "degrees", degrees)
    angles = rotations.quat_to_euler_xyz(_rotation("quat_to_xyz", "quat", quat), rpy=rpy)
    return torch.rad2deg(angles) if degrees else angles


@_arrays(quat=4)
def quat_to_R(quat):
    """(..., 4) quaternions, any non-zero norm → (..., 3, 3) rotation matrices."""
    return rotations.quat_to_mat(_rotation("quat_to_R", "quat", quat))


@_arrays(R=(3, 3))
def R_to_quat(R):
    """(..., 3, 3) rotation matrices → (..., 4) unit quaternions, w > 0 where the trace is positive,
    else the component of R's largest diagonal entry (the last of ties) positive, as Genesis's."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = (row.unbind(-1) for row in R.unbind(-2))
    trace = r00 + r11 + r22
    # each row is 4 q_i q: the one of the largest |q_i| divides best
    rows = torch.stack([torch.stack([1 + trace, r21 - r12, r02 - r20, r10 - r01], -1),
                        torch.stack([r21 - r12, 1 + r00 - r11 - r22, r01 + r10, r02 + r20], -1),
                        torch.stack([r02 - r20, r01 + r10, 1 - r00 + r11 - r22, r12 + r21], -1),
                        torch.stack([r10 - r01, r02 + r20, r12 + r21, 1 - r00 - r11 + r22], -1)], -2)
    last_largest = 3 - torch.stack([r22, r11, r00], -1).argmax(-1)
    pick = torch.where(trace > 0, 0, last_largest)
    quat = rows.gather(-2, pick[..., None, None].expand(*pick.shape, 1, 4))[..., 0, :]
    return normalize(quat)


@_arrays(R=(3, 3))
def R_to_xyz(R, rpy=False, degrees=False):
    """(..., 3, 3) rotation matrices → (..., 3) Euler angles (as ``quat_to_xyz``)."""
    return quat_to_xyz(R_to_quat(R), rpy=rpy, degrees=degrees)


@_arrays(euler_xyz=3)
def euler_to_quat(euler_xyz):
    """(..., 3) roll, pitch, yaw in degrees about the fixed x, y, z axes (a morph's ``euler``) →
    (..., 4) unit quaternions."""
    return xyz_to_quat(euler_xyz, rpy=True, degrees=True)


@_arrays(euler_xyz=3)
def euler_to_R(euler_xyz):
    """(..., 3) roll, pitch, yaw in degrees about the fixed x, y, z axes → (..., 3, 3)."""
    return quat_to_R(euler_to_quat(euler_xyz))


@_arrays(v=4, u=4)
def transform_quat_by_quat(v, u):
    """The rotation v followed by u: u ⊗ v (R_u·R_v), normalised."""
    return normalize(rotations.quat_mul(u, v))


@_arrays(angle=(), axis=3)
def axis_angle_to_quat(angle, axis):
    """(...) angles, rad, about (..., 3) axes of any non-zero length → (..., 4) unit quaternions."""
    half = angle[..., None] / 2
    return normalize(torch.cat([torch.cos(half), normalize(axis) * torch.sin(half)], dim=-1))


@_arrays(positional_out=True, quat=4)  # (Genesis's quat_to_rotvec(quat, out=None))
def quat_to_rotvec(quat):
    """(..., 4) quaternions → (..., 3) rotation vectors: axis × angle, angle in [0, π]."""
    return rotations.rotation_vector(_rotation("quat_to_rotvec", "quat", quat))


@_arrays(positional_out=True, rotvec=3)  # (Genesis's rotvec_to_quat(rotvec, out=None))
def rotvec_to_quat(rotvec):
    """(..., 3) rotation vectors (axis × angle, rad) → (..., 4) unit quaternions, w ≥ 0 for
    angles up to π."""
    angle = torch.linalg.vector_norm(rotvec, dim=-1, keepdim=True)
    # sin(θ/2)/θ as a sinc: smooth, and exact at θ = 0
    return torch.cat([torch.cos(angle / 2), rotvec * torch.sinc(angle / (2 * torch.pi)) / 2], dim=-1)


@_arrays(q0=4, q1=4, t=())
def slerp(q0, q1, t):
    """Spherical linear interpolation from q0 (t = 0) to q1 (t = 1) along the shorter arc: (..., 4)
    quaternions of any non-zero norm, t (...) or a number → (..., 4) unit quaternions."""
    q0, q1 = _rotation("slerp", "q0", q0), _rotation("slerp", "q1", q1)
    try:
        torch.broadcast_shapes(t.shape, q0.shape[:-1], q1.shape[:-1])
    except RuntimeError:
        raise InvalidInputError(f"gs.utils.geom.slerp: argument 't' must broadcast to the quaternions' batch shape "
                                f"{tuple(torch.broadcast_shapes(q0.shape[:-1], q1.shape[:-1]))}, got "
                                f"{tuple(t.shape)}") from None
    cos = (q0 * q1).sum(-1, keepdim=True)
    q1 = torch.where(cos < 0, -q1, q1)
    cos, t = cos.abs(), t[..., None]
    linear = cos > 1 - max(_SLERP_LINEAR, 4 * torch.finfo(cos.dtype).eps)
    angle = torch.acos(torch.where(linear, 0.0, cos))  # (acos's slope is infinite at 1, even where unused)
    sin = torch.where(linear, 1.0, torch.sin(angle))
    w0 = torch.where(linear, 1 - t, torch.sin((1 - t) * angle) / sin)
    w1 = torch.where(linear, t, torch.sin(t * angle) / sin)
    return w0 * q0 + w1 * q1


def random_quaternion(batch_size):
    """(batch_size, 4) unit quaternions uniform over rotations (numpy's global generator, which
    ``gs.init(seed=...)`` seeds)."""
    if not is_int(batch_size) or batch_size < 0:
        raise InvalidInputError(f"gs.utils.geom.random_quaternion: argument 'batch_size' must be a non-negative "
                                f"integer, got {batch_size!r}")
    u1, u2, u3 = np.random.rand(3, batch_size)
    return np.stack([np.sqrt(1 - u1) * np.sin(2 * np.pi * u2), np.sqrt(1 - u1) * np.cos(2 * np.pi * u2),
                     np.sqrt(u1) * np.sin(2 * np.pi * u3), np.sqrt(u1) * np.cos(2 * np.pi * u3)], axis=1)


# ---- points and poses ----

@_arrays(v=3, quat=4)
def transform_by_quat(v, quat):
    """(..., 3) vectors rotated by (..., 4) quaternions of any non-zero norm."""
    return rotations.rotate(_rotation("transform_by_quat", "quat", quat), v)


@_arrays(pos=3, quat=4)
def inv_transform_by_quat(pos, quat):
    """(..., 3) vectors rotated by the inverse of (..., 4) quaternions."""
    return transform_by_quat(pos, inv_quat(quat))


@_arrays(pos=3, trans=3, quat=4)
def transform_by_trans_quat(pos, trans, quat):
    """Points (..., 3) of a frame at (trans, quat) in the parent frame."""
    return transform_by_quat(pos, quat) + trans


@_arrays(pos=3, trans=3, quat=4)
def inv_transform_by_trans_quat(pos, trans, quat):
    """Points (..., 3) of the parent frame in the frame at (trans, quat)."""
    return inv_transform_by_quat(pos - trans, quat)


@_arrays(pos=3, quat=4, t_trans=3, t_quat=4)
def transform_pos_quat_by_trans_quat(pos, quat, t_trans, t_quat):
    """A pose (pos, quat) in the frame at (t_trans, t_quat) → the same pose in the parent frame."""
    return t_trans + transform_by_quat(pos, t_quat), transform_quat_by_quat(quat, t_quat)


@_arrays(pos=3, quat=4, t_trans=3, t_quat=4)
def inv_transform_pos_quat_by_trans_quat(pos, quat, t_trans, t_quat):
    """A pose (pos, quat) in the parent frame → the same pose in the frame at (t_trans, t_quat)."""
    t_quat_inv = inv_quat(t_quat)
    return transform_by_quat(pos - t_trans, t_quat_inv), transform_quat_by_quat(quat, t_quat_inv)


@_arrays(pos=3, R=(3, 3))
def transform_by_R(pos, R):
    """Points rotated by (..., 3, 3) matrices: one point (..., 3) a matrix, or N points
    (..., N, 3) a matrix."""
    if pos.dim() == R.dim():
        return pos @ R.transpose(-1, -2)
    if pos.dim() == R.dim() - 1:
        return (R @ pos[..., None])[..., 0]
    raise InvalidInputError(f"gs.utils.geom.transform_by_R: argument 'pos' must have shape (..., 3) or "
                            f"(..., N, 3) for R of shape {tuple(R.shape)}, got {tuple(pos.shape)}")


@_arrays(pos=3, trans=3, R=(3, 3))
def transform_by_trans_R(pos, trans, R):
    """Points (as ``transform_by_R``) of frames at (trans (..., 3), R (..., 3, 3))."""
    return transform_by_R(pos, R) + (trans[..., None, :] if pos.dim() == R.dim() else trans)


@_arrays(trans=3, R=(3, 3))
def trans_R_to_T(trans=None, R=None):
    """(..., 3) translations and (..., 3, 3) rotations, either left out for none → (..., 4, 4)."""
    if trans is None and R is None:
        return torch.eye(4, dtype=torch.float64)
    if R is None:
        R = torch.eye(3, dtype=trans.dtype, device=trans.device)
    if trans is None:
        trans = torch.zeros(3, dtype=R.dtype, device=R.device)
    batch = torch.broadcast_shapes(trans.shape[:-1], R.shape[:-2])
    top = torch.cat([R.expand(*batch, 3, 3), trans.expand(*batch, 3)[..., None]], dim=-1)
    bottom = torch.tensor([0.0, 0.0, 0.0, 1.0], dtype=top.dtype, device=top.device).expand(*batch, 1, 4)
    return torch.cat([top, bottom], dim=-2)


@_arrays(trans=3, quat=4)
def trans_quat_to_T(trans=None, quat=None):
    """(..., 3) translations and (..., 4) quaternions, either left out for none → (..., 4, 4)."""
    return trans_R_to_T(trans, None if quat is None else quat_to_R(quat))


@_arrays(R=(3, 3))
def R_to_T(R):
    """(..., 3, 3) rotations → (..., 4, 4) with no translation."""
    return trans_R_to_T(None, R)


@_arrays(trans=3)
def trans_to_T(trans):
    """(..., 3) translations → (..., 4, 4) with no rotation."""
    return trans_R_to_T(trans, None)


@_arrays(T=(4, 4))
def T_to_trans(T):
    """(..., 4, 4) → (..., 3) translations."""
    return T[..., :3, 3]


@_arrays(T=(4, 4))
def T_to_quat(T):
    """(..., 4, 4) → (..., 4) unit quaternions."""
    return R_to_quat(T[..., :3, :3])


@_arrays(T=(4, 4))
def T_to_trans_quat(T):
    """(..., 4, 4) → ((..., 3) translations, (..., 4) unit quaternions)."""
    return T_to_trans(T), T_to_quat(T)


@_arrays(T=(4, 4))
def inv_T(T):
    """(..., 4, 4) rigid transforms → their inverses."""
    R_inv = T[..., :3, :3].transpose(-1, -2)
    return trans_R_to_T(-(R_inv @ T[..., :3, 3:])[..., 0], R_inv)


@_arrays(pos=3, T=(4, 4))
def transform_by_T(pos, T):
    """Points (as ``transform_by_R``) of frames at (..., 4, 4)."""
    return transform_by_trans_R(pos, T[..., :3, 3], T[..., :3, :3])


@_arrays(pos=3, T=(4, 4))
def inv_transform_by_T(pos, T):
    """Points (as ``transform_by_R``) of the parent frame in frames at (..., 4, 4)."""
    trans = T[..., :3, 3]
    return transform_by_R(pos - (trans[..., None, :] if pos.dim() == T.dim() else trans),
                          T[..., :3, :3].transpose(-1, -2))
