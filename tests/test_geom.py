"""gs.utils.geom against scipy's rotations (a reference written elsewhere), on torch and numpy.

Conventions checked: quaternions (w, x, y, z); ``xyz`` Euler angles intrinsic X-Y-Z (scipy "XYZ"),
``rpy=True`` extrinsic x-y-z (scipy "xyz"); Genesis 1.4.5's ranges, its sign rule in R_to_quat
and the first angle 0 at gimbal lock (compared with Genesis itself while writing this module:
every function agreed with Genesis's torch code to 1e-12 on 64 random and 8 special inputs).
"""
import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation, Slerp

import genesis_lite as gs
from genesis_lite.utils import geom

RNG = np.random.default_rng(7)
N = 50
QUATS = RNG.normal(size=(N, 4)) * RNG.uniform(0.5, 2.0, (N, 1))  # any norm
ANGLES = RNG.uniform(-np.pi, np.pi, (N, 3)) * [1.0, 0.5, 1.0]
VECS = RNG.normal(size=(N, 3))


def _scipy(quat):
    """(w, x, y, z) of any norm → scipy's Rotation (scalar last)."""
    return Rotation.from_quat(np.roll(quat / np.linalg.norm(quat, axis=-1, keepdims=True), -1, axis=-1))


def _same_rotation(q1, q2):
    return np.minimum(np.abs(q1 - q2).max(-1), np.abs(q1 + q2).max(-1)).max()


@pytest.mark.parametrize("rpy, order", [(False, "XYZ"), (True, "xyz")])
def test_euler_angles_as_scipy(rpy, order):
    quat = geom.xyz_to_quat(ANGLES, rpy=rpy)
    assert _same_rotation(np.roll(quat, -1, axis=-1), Rotation.from_euler(order, ANGLES).as_quat()) < 1e-14
    assert np.allclose(np.linalg.norm(quat, axis=-1), 1.0, atol=1e-15)
    # back from quaternions of any norm: scipy's angles (b within ±π/2 in both)
    assert np.abs(geom.quat_to_xyz(QUATS, rpy=rpy) - _scipy(QUATS).as_euler(order)).max() < 1e-12
    assert np.abs(geom.quat_to_xyz(quat, rpy=rpy) - ANGLES).max() < 1e-12
    degrees = geom.quat_to_xyz(QUATS, rpy=rpy, degrees=True)
    assert np.abs(degrees - _scipy(QUATS).as_euler(order, degrees=True)).max() < 1e-10
    assert np.abs(geom.xyz_to_quat(np.degrees(ANGLES), rpy=rpy, degrees=True) - quat).max() < 1e-15
    R = geom.quat_to_R(QUATS)
    assert np.abs(geom.R_to_xyz(R, rpy=rpy) - _scipy(QUATS).as_euler(order)).max() < 1e-12


def test_euler_ranges_and_gimbal_lock_as_genesis():
    # half turns: the first and last angles are +π, not −π (atan2 of a +0)
    half_turns = np.array([[0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
    assert np.allclose(geom.quat_to_xyz(half_turns), [[np.pi, 0, 0], [np.pi, 0, np.pi], [0, 0, np.pi]])
    # at gimbal lock (b = ±π/2) the first angle is 0 and the last carries the rotation about the locked axis
    for rpy in (False, True):
        for b in (np.pi / 2, -np.pi / 2):
            quat = geom.xyz_to_quat([0.4, b, 0.3], rpy=rpy)
            angles = geom.quat_to_xyz(quat, rpy=rpy)
            assert angles[0] == 0.0 and abs(angles[1] - b) < 1e-7 and abs(angles[2] - 0.3) > 0.05
            assert _same_rotation(geom.xyz_to_quat(angles, rpy=rpy), quat) < 1e-14
    # the morph's euler is roll-pitch-yaw in degrees (euler_to_quat, Genesis's)
    assert _same_rotation(gs.morphs.Box(euler=(10.0, -20.0, 95.0)).quat,
                          np.roll(Rotation.from_euler("xyz", [10, -20, 95], degrees=True).as_quat(), 1)) < 1e-15


def test_matrices_and_quaternions_as_scipy():
    R = geom.quat_to_R(QUATS)
    assert np.abs(R - _scipy(QUATS).as_matrix()).max() < 1e-14
    quat = geom.R_to_quat(R)
    assert _same_rotation(quat, QUATS / np.linalg.norm(QUATS, axis=-1, keepdims=True)) < 1e-14
    # Genesis's sign: w > 0 where the trace is positive, else the largest diagonal entry's component
    trace = np.trace(R, axis1=-2, axis2=-1)
    largest = np.argmax(np.diagonal(R, axis1=-2, axis2=-1)[:, ::-1], -1)
    pick = np.where(trace > 0, 0, 3 - largest)
    assert np.all(quat[np.arange(N), pick] > 0)
    assert np.abs(geom.euler_to_R([10.0, -20.0, 95.0])
                  - Rotation.from_euler("xyz", [10, -20, 95], degrees=True).as_matrix()).max() < 1e-15
    assert np.abs(geom.inv_quat(QUATS) - QUATS * [1, -1, -1, -1]).max() == 0.0


def test_rotating_and_composing_as_scipy():
    Q2 = RNG.normal(size=(N, 4))
    assert np.abs(geom.transform_by_quat(VECS, QUATS) - _scipy(QUATS).apply(VECS)).max() < 1e-14
    assert np.abs(geom.inv_transform_by_quat(VECS, QUATS) - _scipy(QUATS).inv().apply(VECS)).max() < 1e-14
    # v then u: R_u·R_v
    composed = geom.transform_quat_by_quat(Q2, QUATS)
    assert _same_rotation(np.roll(composed, -1, -1), (_scipy(QUATS) * _scipy(Q2)).as_quat()) < 1e-14
    pos, quat = geom.transform_pos_quat_by_trans_quat(VECS, Q2, VECS[::-1], QUATS)
    assert np.abs(pos - (VECS[::-1] + _scipy(QUATS).apply(VECS))).max() < 1e-14
    back_pos, back_quat = geom.inv_transform_pos_quat_by_trans_quat(pos, quat, VECS[::-1], QUATS)
    assert np.abs(back_pos - VECS).max() < 1e-13
    assert _same_rotation(back_quat, Q2 / np.linalg.norm(Q2, axis=-1, keepdims=True)) < 1e-14
    points = geom.transform_by_trans_quat(VECS, VECS[::-1], QUATS)
    assert np.abs(geom.inv_transform_by_trans_quat(points, VECS[::-1], QUATS) - VECS).max() < 1e-13


def test_rotation_vectors_axis_angle_and_slerp_as_scipy():
    unit = QUATS / np.linalg.norm(QUATS, axis=-1, keepdims=True)
    assert np.abs(geom.quat_to_rotvec(QUATS) - _scipy(QUATS).as_rotvec()).max() < 1e-13
    rotvecs = _scipy(QUATS).as_rotvec()
    assert _same_rotation(geom.rotvec_to_quat(rotvecs), unit) < 1e-14
    angle = RNG.uniform(-4, 4, N)
    quat = geom.axis_angle_to_quat(angle, VECS)
    expected = Rotation.from_rotvec(VECS / np.linalg.norm(VECS, axis=-1, keepdims=True) * angle[:, None])
    assert _same_rotation(np.roll(quat, -1, -1), expected.as_quat()) < 1e-14
    t = RNG.uniform(0, 1, N)
    for i in range(0, N - 1, 7):  # scipy's Slerp runs along the shorter arc too
        flip = 1.0 if unit[i] @ unit[i + 1] >= 0 else -1.0
        key = Rotation.from_quat(np.roll([unit[i], flip * unit[i + 1]], -1, -1))
        expected = np.roll(Slerp([0, 1], key)(t[i]).as_quat(), 1)
        assert _same_rotation(geom.slerp(QUATS[i], QUATS[i + 1], t[i]), expected) < 1e-13
    ends = geom.slerp(QUATS[:5], QUATS[5:10], np.array([0.0] * 5))
    assert np.abs(ends - unit[:5]).max() < 1e-15


def test_homogeneous_transforms():
    unit = QUATS / np.linalg.norm(QUATS, axis=-1, keepdims=True)
    T = geom.trans_quat_to_T(VECS, QUATS)
    expected = np.tile(np.eye(4), (N, 1, 1))
    expected[:, :3, :3], expected[:, :3, 3] = _scipy(QUATS).as_matrix(), VECS
    assert np.abs(T - expected).max() < 1e-14
    assert np.abs(geom.inv_T(T) - np.linalg.inv(expected)).max() < 1e-13
    trans, quat = geom.T_to_trans_quat(T)
    assert np.abs(trans - VECS).max() == 0.0 and _same_rotation(quat, unit) < 1e-14
    points = RNG.normal(size=(N, 6, 3))  # N points to a matrix, and one
    homogeneous = np.einsum("bij,bnj->bni", expected, np.concatenate([points, np.ones((N, 6, 1))], -1))
    assert np.abs(geom.transform_by_T(points, T) - homogeneous[..., :3]).max() < 1e-13
    assert np.abs(geom.transform_by_T(points[:, 0], T) - homogeneous[:, 0, :3]).max() < 1e-13
    assert np.abs(geom.inv_transform_by_T(geom.transform_by_T(points, T), T) - points).max() < 1e-13
    assert np.abs(geom.transform_by_R(points, T[:, :3, :3]) - np.einsum("bij,bnj->bni", T[:, :3, :3], points)).max() < 1e-14
    assert np.abs(geom.trans_R_to_T(VECS, T[:, :3, :3]) - T).max() == 0.0
    assert np.abs(geom.R_to_T(T[0, :3, :3])[:3, 3]).max() == 0.0
    assert np.abs(geom.trans_to_T(VECS[0])[:3, :3] - np.eye(3)).max() == 0.0
    out = np.empty((N, 4, 4))
    assert geom.trans_quat_to_T(VECS, QUATS, out=out) is out and np.abs(out - T).max() == 0.0
    rotvecs = np.empty((N, 3))  # (Genesis's quat_to_rotvec and rotvec_to_quat take out after the argument)
    assert geom.quat_to_rotvec(QUATS, rotvecs) is rotvecs and np.abs(rotvecs - geom.quat_to_rotvec(QUATS)).max() == 0
    quats = np.empty((N, 4))
    assert geom.rotvec_to_quat(rotvecs, quats) is quats and np.abs(quats - geom.rotvec_to_quat(rotvecs)).max() == 0


def test_types_devices_and_gradients():
    q32 = QUATS.astype(np.float32)
    assert geom.quat_to_xyz(q32).dtype == np.float32  # numpy in, numpy out, float32 kept
    assert geom.quat_to_xyz(QUATS.tolist()).dtype == np.float64  # lists as numpy
    quat = torch.tensor(QUATS[:6], requires_grad=True)
    angles = geom.quat_to_xyz(quat)
    assert isinstance(angles, torch.Tensor) and angles.dtype == torch.float64
    assert torch.autograd.gradcheck(lambda q: geom.quat_to_xyz(q, rpy=True), (quat,))
    assert torch.autograd.gradcheck(lambda q: geom.R_to_quat(geom.quat_to_R(q)), (quat,))
    two = torch.tensor(QUATS[6:12], requires_grad=True)
    t = torch.tensor(RNG.uniform(0, 1, 6), requires_grad=True)
    assert torch.autograd.gradcheck(geom.slerp, (quat, two, t))
    # rotations by zero and by nearly equal quaternions keep finite gradients
    zero = torch.zeros(3, dtype=torch.float64, requires_grad=True)
    geom.rotvec_to_quat(zero).sum().backward()
    assert torch.isfinite(zero.grad).all()
    same = quat[:1].detach().clone().requires_grad_(True)
    geom.slerp(same, same.detach(), 0.3).sum().backward()
    assert torch.isfinite(same.grad).all()
    # a list next to a tensor takes the tensor's type
    assert geom.transform_by_quat([1.0, 0.0, 0.0], quat.float()).dtype == torch.float32
    # in a batch a zero quaternion's row is NaN (a diverged env's), the others exact, as Genesis's
    rows = geom.transform_by_quat(np.ones((2, 3)), np.array([[0.0, 0, 0, 0], [1.0, 0, 0, 0]]))
    assert np.isnan(rows[0]).all() and np.array_equal(rows[1], np.ones(3))
    # float32 slerp between equal or nearly equal quaternions interpolates linearly, not 0 / 0
    near = torch.tensor([[0.6, 0.8, 0.0, 0.0], [0.6, 0.8, 1e-4, 0.0]])
    assert torch.isfinite(geom.slerp(near[0], near, torch.tensor([0.3, 0.7]))).all()


@pytest.mark.parametrize("call, match", [
    (lambda: geom.quat_to_xyz(np.zeros(3)), r"quat_to_xyz: argument 'quat' must have shape \(\.\.\., 4\), got \(3,\)"),
    (lambda: geom.transform_by_quat(np.zeros((2, 4)), np.ones(4)), r"argument 'v' must have shape \(\.\.\., 3\)"),
    (lambda: geom.inv_T(np.eye(3)), r"argument 'T' must have shape \(\.\.\., 4, 4\)"),
    (lambda: geom.xyz_to_quat("abc"), r"argument 'xyz' must hold real numbers"),
    (lambda: geom.quat_to_R([[1, 0, 0, 0], [1, 0]]), r"argument 'quat' must be an array"),
    (lambda: geom.transform_by_R(np.zeros((2, 2, 2, 3)), np.eye(3)), r"transform_by_R: argument 'pos'"),
    (lambda: geom.quat_to_R(np.ones(4), out=np.empty(3)), r"argument 'out' must have the result's shape"),
    (lambda: geom.quat_to_R(np.zeros(4)), r"quat_to_R: argument 'quat' must be a non-zero finite quaternion"),
    (lambda: geom.transform_by_quat(np.ones(3), [0.0, 0, 0, 0]), r"transform_by_quat: argument 'quat' must be a non-"),
    (lambda: geom.quat_to_xyz([np.nan, 0, 0, 1]), r"quat_to_xyz: argument 'quat' must be a non-zero finite"),
    (lambda: geom.slerp(np.ones((3, 4)), np.ones(4), [0.1, 0.2]), r"slerp: argument 't' must broadcast to the quat"),
    (lambda: geom.xyz_to_quat(np.zeros(3), rpy="yes"), r"xyz_to_quat: argument 'rpy' must be True or False"),
    (lambda: geom.quat_to_xyz(np.ones(4), degrees=1), r"quat_to_xyz: argument 'degrees' must be True or False"),
    (lambda: geom.quat_to_R(torch.ones(4, dtype=torch.complex64)), r"argument 'quat' must hold real numbers"),
    (lambda: geom.random_quaternion(2.5), r"random_quaternion: argument 'batch_size' must be a non-negative integer"),
    (lambda: geom.transform_by_quat(np.zeros((5, 3)), np.ones((4, 4))),
     r"transform_by_quat: the arguments' shapes do not fit together .* 'v' \(5, 3\), 'quat' \(4, 4\)"),
])
def test_bad_input_is_named(call, match):
    with pytest.raises(gs.InvalidInputError, match=match):
        call()


def test_genesis_names():
    assert gs.utils.geom is geom
    for name in ("quat_to_xyz", "transform_by_quat", "inv_quat", "transform_quat_by_quat", "xyz_to_quat"):
        assert callable(getattr(gs.utils.geom, name))


def test_every_function_is_at_gs_top_level_too():
    """Genesis's ``from .utils.geom import *``: its examples call gs.transform_quat_by_quat etc."""
    for name in geom.__all__:
        assert getattr(gs, name) is getattr(geom, name), name
