"""MuJoCo reference for contact-free articulated dynamics (test support only).

Loads the SAME URDF into MuJoCo (``mujoco`` 4.x) and exposes the quantities our
tests compare against, keyed by URDF joint name so that dof ordering does not
matter.  SI units throughout (m, rad, kg, s, N, N·m).

Model conventions (verified empirically with mujoco 4.0.0):

* MuJoCo's URDF import fuses links attached by ``fixed`` joints into their parent
  (``fusestatic``; a fixed-base root link is fused into the world).  Remaining body
  frames are the URDF link frames; joints sit at the body origin; fused inertias
  are combined exactly (up to round-off of the diagonalisation).
  A link with mass 0 contributes NOTHING when fused (its <inertia> is dropped
  too); a moving body (one with a joint) with mass 0 or zero inertia is
  rejected at compile time.
* dof order = depth-first traversal of the URDF tree, the children of a link taken
  in the order their joints appear in the file.  A free base comes first.
* Free base (``"__base__"``): qpos = [x, y, z, qw, qx, qy, qz] of the root link's
  origin in the world; qvel = [v_world(3), omega_body(3)], where v_world is the
  world-frame velocity of the root link origin and omega_body is the angular
  velocity expressed in the root link's frame.
* Integrator: semi-implicit Euler with implicit joint damping,
  ``(M + h*diag(damping)) qacc = qfrc_smooth``; ``qvel += h*qacc``; qpos is
  integrated with the new qvel; quaternions ``q <- normalize(q ⊗ exp(h*omega_body/2))``.
"""

from __future__ import annotations

import dataclasses
from typing import Mapping, Optional

import mujoco
import numpy as np

BASE = "__base__"  # key / joint name used for the free joint

_DISABLE = (
    mujoco.mjtDisableBit.mjDSBL_CONSTRAINT
    | mujoco.mjtDisableBit.mjDSBL_CONTACT
    | mujoco.mjtDisableBit.mjDSBL_LIMIT
    | mujoco.mjtDisableBit.mjDSBL_EQUALITY
    | mujoco.mjtDisableBit.mjDSBL_FRICTIONLOSS
)


def bare_spec(path: str, free_base: bool = False) -> mujoco.MjSpec:
    """MjSpec of a URDF as it is written (inertias from the file, fixed links fused), without its
    collision geometry (no geoms, no meshes), a free joint on its root when ``free_base``: to
    compile after editing the options or adding bodies."""
    spec = mujoco.MjSpec.from_file(path)
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    spec.compiler.fusestatic = True
    for geom in list(spec.geoms):
        spec.delete(geom)
    for mesh in list(spec.meshes):
        spec.delete(mesh)
    if free_base:
        spec.worldbody.first_body().add_freejoint()
    return spec


def load_model(
    urdf_path,
    free_base: bool = False,
    dt: float = 0.01,
    damping: Optional[Mapping[str, float]] = None,
    armature: Optional[Mapping[str, float]] = None,
    keep_geoms: bool = False,
) -> mujoco.MjModel:
    """Load a URDF into a contact/constraint-free MuJoCo model.

    Args:
      urdf_path: path to the URDF (meshes resolved relative to its directory).
      free_base: give the URDF root link a free joint named ``"__base__"``
        (located at the root link origin).  The root link must have mass > 0
        (MuJoCo rejects massless moving bodies).
      dt: timestep [s].  Integrator: Euler (implicit damping, MuJoCo default).
      damping: joint name -> viscous damping [N·m·s/rad or N·s/m]; overrides URDF
        ``<dynamics damping>``.  Other joints keep the URDF value.
      armature: joint name -> armature (rotor inertia added to M's diagonal)
        [kg·m² or kg]; default 0.
      keep_geoms: by default all geoms/meshes are stripped (contacts are off and
        inertias come only from ``<inertial>``), so mesh loading cannot fail.

    Gravity is (0, 0, -9.81) m/s².  Contacts, joint limits, equality constraints
    and frictionloss are disabled (frictionloss also zeroed, limits unset).
    Links without ``<inertial>`` get zero mass (``inertiafromgeom`` is off, unlike
    MuJoCo's URDF default which would give them geom-based mass at 1000 kg/m³).
    """
    spec = mujoco.MjSpec.from_file(str(urdf_path))
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    spec.compiler.fusestatic = True
    spec.compiler.alignfree = False  # keep free-joint frame = URDF root link frame
    if not keep_geoms:
        for g in list(spec.geoms):
            spec.delete(g)
        for me in list(spec.meshes):
            spec.delete(me)
    if free_base:
        roots = spec.worldbody.bodies  # direct children of the world
        if len(roots) != 1:
            raise ValueError(f"expected one URDF root link, got {[b.name for b in roots]}")
        fj = roots[0].add_freejoint()
        fj.name = BASE

    names = {j.name for j in spec.joints}
    for kind, table in (("damping", damping), ("armature", armature)):
        unknown = set(table or {}) - names
        if unknown:
            raise KeyError(f"{kind}: unknown joints {sorted(unknown)}")
    for j in spec.joints:
        j.frictionloss = 0.0
        j.limited = mujoco.mjtLimited.mjLIMITED_FALSE
        if damping and j.name in damping:
            j.damping = [float(damping[j.name]), 0.0, 0.0]  # MuJoCo 4: polynomial coefficients
        if armature and j.name in armature:
            j.armature = float(armature[j.name])

    opt = spec.option
    opt.timestep = float(dt)
    opt.integrator = mujoco.mjtIntegrator.mjINT_EULER
    opt.gravity = np.array([0.0, 0.0, -9.81])
    opt.disableflags = int(opt.disableflags) | int(_DISABLE)
    return spec.compile()


def dof_names(model: mujoco.MjModel) -> list[str]:
    """Joint name of each MuJoCo dof, length nv; free-joint dofs are
    ``"__base__:0".."__base__:5"`` (0-2 linear world, 3-5 angular body frame)."""
    out = []
    for i in range(model.nv):
        j = int(model.dof_jntid[i])
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
            out.append(f"{BASE}:{i - int(model.jnt_dofadr[j])}")
        else:
            out.append(model.joint(j).name)
    return out


def _joints(model):
    """[(key, type, qposadr, dofadr)] for all joints; free joint keyed "__base__"."""
    out = []
    for j in range(model.njnt):
        t = model.jnt_type[j]
        if t == mujoco.mjtJoint.mjJNT_BALL:
            raise NotImplementedError("ball joints are not supported")
        key = BASE if t == mujoco.mjtJoint.mjJNT_FREE else model.joint(j).name
        out.append((key, t, int(model.jnt_qposadr[j]), int(model.jnt_dofadr[j])))
    return out


def _set_state(model, data, qpos, qvel, base_qpos, base_qvel):
    """Reset data to qpos0 / zero velocity, then apply the given dicts."""
    mujoco.mj_resetData(model, data)
    joints = {k: (t, qa, da) for k, t, qa, da in _joints(model)}
    for src, what in ((qpos, "qpos"), (qvel, "qvel")):
        unknown = set(src or {}) - (set(joints) - {BASE})
        if unknown:
            raise KeyError(f"{what}: unknown joints {sorted(unknown)}")
    for name, v in (qpos or {}).items():
        data.qpos[joints[name][1]] = float(v)
    for name, v in (qvel or {}).items():
        data.qvel[joints[name][2]] = float(v)
    if base_qpos is not None or base_qvel is not None:
        if BASE not in joints:
            raise KeyError("model has no free base (load_model(..., free_base=True))")
        _, qa, da = joints[BASE]
        if base_qpos is not None:
            data.qpos[qa:qa + 7] = np.asarray(base_qpos, float)
        if base_qvel is not None:
            data.qvel[da:da + 6] = np.asarray(base_qvel, float)


@dataclasses.dataclass
class Trajectory:
    """Rollout result.  ``qpos[name]``: (n_steps+1,) for hinge/slide joints
    [rad or m], (n_steps+1, 7) for ``"__base__"`` (pos, quat wxyz).
    ``qvel[name]``: (n_steps+1,) resp. (n_steps+1, 6) [v_world, omega_body].
    Row 0 is the initial state.  ``traj[name]`` is a shortcut for ``traj.qpos[name]``."""

    qpos: dict
    qvel: dict
    time: np.ndarray  # (n_steps+1,) [s]

    def __getitem__(self, name):
        return self.qpos[name]


def rollout(
    model: mujoco.MjModel,
    qpos0: Optional[Mapping[str, float]],
    qvel0: Optional[Mapping[str, float]],
    n_steps: int,
    base_qpos=None,
    base_qvel=None,
    tau: Optional[Mapping[str, object]] = None,
) -> Trajectory:
    """Simulate ``n_steps`` calls of ``mj_step`` from the given state.

    Args:
      qpos0 / qvel0: joint name -> initial position / velocity (missing joints:
        URDF zero position, zero velocity).
      base_qpos: (7,) free-base [x, y, z, qw, qx, qy, qz] (need not be unit).
      base_qvel: (6,) free-base [v_world, omega_body].
      tau: optional joint name -> generalized force [N·m or N], a scalar (held
        constant) or an (n_steps,) array; applied through ``qfrc_applied``.
        ``"__base__"`` takes a (6,) or (n_steps, 6) array in dof coordinates.
    """
    data = mujoco.MjData(model)
    _set_state(model, data, qpos0, qvel0, base_qpos, base_qvel)
    joints = _joints(model)
    qp = np.empty((n_steps + 1, model.nq))
    qv = np.empty((n_steps + 1, model.nv))
    t = np.empty(n_steps + 1)
    frc = np.zeros((n_steps, model.nv))
    if tau:
        slots = {k: (da, 6 if typ == mujoco.mjtJoint.mjJNT_FREE else 1) for k, typ, _, da in joints}
        for name, v in tau.items():
            da, n = slots[name]
            frc[:, da:da + n] = np.broadcast_to(np.asarray(v, float).reshape(-1, n), (n_steps, n))
    qp[0], qv[0], t[0] = data.qpos, data.qvel, data.time
    for k in range(n_steps):
        data.qfrc_applied[:] = frc[k]
        mujoco.mj_step(model, data)
        qp[k + 1], qv[k + 1], t[k + 1] = data.qpos, data.qvel, data.time
    out_p, out_v = {}, {}
    for key, typ, qa, da in joints:
        if typ == mujoco.mjtJoint.mjJNT_FREE:
            out_p[key], out_v[key] = qp[:, qa:qa + 7].copy(), qv[:, da:da + 6].copy()
        else:
            out_p[key], out_v[key] = qp[:, qa].copy(), qv[:, da].copy()
    return Trajectory(out_p, out_v, t)


def mass_matrix_and_bias(
    model: mujoco.MjModel,
    qpos: Optional[Mapping[str, float]],
    qvel: Optional[Mapping[str, float]],
    base_qpos=None,
    base_qvel=None,
):
    """Joint-space mass matrix and bias force at a state (after ``mj_forward``).

    Returns:
      M: (nv, nv) dense mass matrix, armature included on the diagonal.
      bias: (nv,) ``qfrc_bias`` = C(q, qd) qd + g(q) (gravity included; damping
        and applied forces are NOT included).  Equation of motion:
        M qacc + bias = tau - damping * qd.
      dof_names: (nv,) list, joint name of each row/column (see ``dof_names``).
    """
    data = mujoco.MjData(model)
    _set_state(model, data, qpos, qvel, base_qpos, base_qvel)
    mujoco.mj_forward(model, data)
    M = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, M)
    return M, data.qfrc_bias.copy(), dof_names(model)
