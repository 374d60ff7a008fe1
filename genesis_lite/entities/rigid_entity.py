"""Rigid entities: a URDF robot or a primitive body, seen through Genesis's getters, setters
and controls. Local indices (links, dofs, qs) count within the entity; envs_idx selects
environments when the scene is batched (n_envs > 0), and every result then gains a leading
batch dimension.
"""
import functools
import math

import numpy as np
import torch

from ..options import check_bool
from ..runtime import logger
from ..solvers.core import InvalidInputError, SceneStateError, refuse_grad, runtime, warn_user
from ..solvers.mpm.layout import coupling_columns
from ..solvers.rigid.merge import merged_into
from ..solvers.rigid.model import BALL, FREE, initial_q
from . import energy, kinematics
from .bounds import shapes_aabb
from ..tensor import wrap
from .common import (EntityIndexing, all_finite, broadcast, is_range, named_argument_errors,
                     replace_columns as _replace, take)
from ..utils.uid import UID
from ..utils.rotations import euler_xyz_to_quat, quat_mul, quat_to_euler_xyz, quat_to_mat, rotate, rotation_vector

_BASE = np.zeros(1, dtype=np.int64)  # the base link's local index, as an index array

_MODES = {"force": 0, "position": 1, "velocity": 2}  # ctrl_mode codes (solvers/rigid/actuation.py)
_NDOFS = {"fixed": 0, "revolute": 1, "prismatic": 1, "free": 6, "ball": 3}
_NQS = {"fixed": 0, "revolute": 1, "prismatic": 1, "free": 7, "ball": 4}


def _ltdl(mass, entity):
    """(B, n, n) symmetric positive definite M → (L (B, n, n) unit lower triangular, D_inv (B, n))
    with M = Lᵀ·diag(1 / D_inv)·L (Genesis's decomposition). With P the order reversal,
    P·M·P = (P·Lᵀ·P)·(P·D·P)·(P·L·P) is an ordinary L′D′L′ᵀ, read off its Cholesky factor
    C = L′·diag(√D′)."""
    chol, info = torch.linalg.cholesky_ex(mass.flip(-2, -1))
    if bool((info != 0).any()):
        raise InvalidInputError(f"entity '{entity}': get_mass_mat(decompose=True) expected a positive definite "
                                f"mass matrix, got a singular one (a moving link left without mass, inertia or "
                                f"armature, e.g. by set_links_mass(0))")
    root = torch.diagonal(chol, dim1=-2, dim2=-1)
    lower = (chol / root[..., None, :]).transpose(-2, -1).flip(-2, -1)
    return lower, 1.0 / root.flip(-1) ** 2


def _mount_vector(who, name, value, n, default):
    """attach's pos or quat: n finite numbers (a quaternion non-zero, normalised), or the default for None."""
    refuse_grad(who, name, value, "where an entity is attached is model data, fixed at build")
    array = np.asarray(default if value is None else value, dtype=np.float64)
    if array.shape != (n,) or not np.all(np.isfinite(array)) or (n == 4 and np.linalg.norm(array) < 1e-9):
        raise InvalidInputError(f"{who} argument '{name}' must be {n} finite numbers"
                                f"{' (a non-zero quaternion w, x, y, z)' if n == 4 else ''}, got {value!r}")
    return array / np.linalg.norm(array) if n == 4 else array


def _finite_length(value):
    """Whether a torsional or rolling friction (m) is allowed: finite and ≥ 0 (NaN is not)."""
    return 0.0 <= value < float("inf")


def _check_sol_params(name, p):
    """(timeconst, dampratio, dmin, dmax, width, midpoint, power) within MuJoCo's ranges (the kernels
    clamp the impedances into [1e-4, 0.9999] as MuJoCo does: dmin or dmax 0 means 1e-4)."""
    standard, direct = p[0] > 0 and p[1] > 0, p[0] <= 0 and p[1] <= 0
    ok = (np.all(np.isfinite(p)) and (standard or direct) and 0 <= p[2] < 1 and 0 <= p[3] < 1 and p[2] <= p[3]
          and p[4] >= 0 and 0 < p[5] < 1 and p[6] >= 1)
    if not ok:
        raise InvalidInputError(f"entity '{name}': argument 'sol_params' expected timeconst and dampratio both > 0 "
                                f"(or both ≤ 0: direct), 0 ≤ dmin ≤ dmax < 1, width ≥ 0, 0 < midpoint < 1, "
                                f"power ≥ 1, got {p.tolist()}")


def _with_link_axis(link, arg, value):
    """``link``'s vector ``value`` (argument ``arg`` of apply_external_wrench: (3,) or (n_envs, 3))
    as the entity's one-link (…, 1, 3); None as given, another shape a named error (what is no
    array passes as given: the entity's check names it)."""
    if value is None:
        return None
    try:
        tensor = value if isinstance(value, torch.Tensor) else torch.as_tensor(np.asarray(value))
    except (TypeError, ValueError, RuntimeError):
        return value
    if tensor.ndim not in (1, 2) or tensor.shape[-1] != 3:
        raise InvalidInputError(f"{link._who}: apply_external_wrench argument '{arg}' must have shape (3,) or "
                                f"(len(envs_idx), 3), got {tuple(tensor.shape)}")
    return tensor.unsqueeze(-2)


@named_argument_errors
class RigidLink:
    """A link: ``name``, ``idx`` (scene-wide), ``idx_local`` (within its entity), ``uid``."""

    def __init__(self, entity, name, idx_local):
        self.entity, self.name, self.idx_local = entity, name, idx_local
        self.uid = UID()

    @property
    def _who(self):
        return f"link '{self.name}' of entity '{self.entity.name}'"

    @property
    def idx(self):
        return self.entity.link_start + self.idx_local

    @property
    def parent_idx(self):
        """The scene-wide index of the parent link, −1 for a root (once built)."""
        return int(self._model("parent_idx").link_parent[self.idx])

    @property
    def is_fixed(self):
        """Whether the link is welded to the world (no moving joint between it and the world; once built)."""
        return bool(self._model("is_fixed").link_static[self.idx])

    @property
    def root_idx(self):
        """The scene-wide index of the root link of its tree (once built)."""
        return int(self._model("root_idx").link_root[self.idx])

    @property
    def is_built(self):
        return self.entity.is_built

    @property
    def joints(self):
        """The joints moving the link against its parent: one, or none for a welded link (a
        body's several MJCF joints make massless links of their own)."""
        return [joint for joint in self.entity.joints if joint.link is self]

    @property
    def n_joints(self):
        return len(self.joints)

    @property
    def n_dofs(self):
        return sum(joint.n_dofs for joint in self.joints)

    @property
    def n_qs(self):
        return sum(joint.n_qs for joint in self.joints)

    @property
    def dof_start(self):
        """Its first dof in the scene's rigid solver (for a welded link, where its dofs would be),
        once built; dof_end one past its last."""
        return int(self._model("dof_start").link_dof0[self.idx])

    @property
    def dof_end(self):
        return self.dof_start + self.n_dofs

    @property
    def q_start(self):
        """Its first coordinate in the scene's rigid solver (as dof_start); q_end one past its last."""
        return int(self._model("q_start").link_q0[self.idx])

    @property
    def q_end(self):
        return self.q_start + self.n_qs

    def _model(self, what):
        """The built scene's rigid model (a named error before build)."""
        self.entity.scene._require_built(f"{self._who}: {what}")
        return self.entity._solver.model

    def _one(self, values):
        """The entity's (…, n_links, k) readout for this link alone: (…, k)."""
        return wrap(values[..., 0, :], self.entity.scene)

    def get_pos(self, envs_idx=None, *, relative=True):
        """World position of the link frame origin, m: (3,) or (n_envs, 3); relative as in
        RigidEntity.get_links_pos."""
        return self._one(self.entity.get_links_pos([self.idx_local], envs_idx, relative=relative))

    def get_quat(self, envs_idx=None, *, relative=True):
        """World orientation (w, x, y, z): (4,) or (n_envs, 4); relative as in get_pos."""
        return self._one(self.entity.get_links_quat([self.idx_local], envs_idx, relative=relative))

    def get_vel(self, envs_idx=None, *, relative=True):
        """World linear velocity of the link frame origin, m/s: (3,) or (n_envs, 3); relative as in
        get_pos."""
        return self._one(self.entity.get_links_vel([self.idx_local], envs_idx, relative=relative))

    def get_ang(self, envs_idx=None):
        """World angular velocity, rad/s: (3,) or (n_envs, 3)."""
        return self._one(self.entity.get_links_ang([self.idx_local], envs_idx))

    def get_mass(self, envs_idx=None):
        """Mass, kg: () or (n_envs,)."""
        return wrap(self.entity.get_links_mass([self.idx_local], envs_idx)[..., 0], self.entity.scene)

    def set_mass(self, mass):
        """Mass, kg: a number, or (n_envs,) one per env; the entity's ``set_links_mass`` for this link
        (differentiable): its inertia stays, as Genesis's. A link welded to the world is skipped with
        a warning, as Genesis."""
        if self.is_fixed:
            warn_user(f"{self._who}: set_mass of a link welded to the world changes nothing (it is never "
                      f"accelerated), skipped as Genesis skips it")
            return
        self.entity.set_links_mass(self._one_link_value(mass, "set_mass", "mass", 0), [self.idx_local])

    def set_inertia(self, inertia):
        """Rotational inertia about the centre of mass, in the link's frame, kg·m²: (3, 3), or
        (n_envs, 3, 3) one per env; the entity's ``set_links_inertia`` for this link (differentiable)."""
        self.entity.set_links_inertia(self._one_link_value(inertia, "set_inertia", "inertia", 2), [self.idx_local])

    def set_COM(self, com):
        """Centre of mass in the link's frame, m: (3,), or (n_envs, 3) one per env; the entity's
        ``set_links_COM`` for this link (differentiable)."""
        self.entity.set_links_COM(self._one_link_value(com, "set_COM", "com", 1), [self.idx_local])

    def get_invweight(self, envs_idx=None):
        """Inverse weights, translational (1/kg) and rotational (1/(kg·m²)): (2,) or (n_envs, 2), as
        ``RigidEntity.get_links_invweight`` for this link."""
        return self._one(self.entity.get_links_invweight([self.idx_local], envs_idx))

    def _one_link_value(self, value, method, arg, element_dims):
        """A link setter's ``value`` (one element of ``element_dims`` dims, or one per env) as the
        entity's setter takes it for this one link: (1, *element) or (n_envs, 1, *element)."""
        dims = value.dim() if isinstance(value, torch.Tensor) else np.ndim(value)
        per_env = dims == element_dims + 1
        if per_env and self.entity.scene.n_envs == 0:
            raise InvalidInputError(f"{self._who}: {method} argument '{arg}' takes one value in a scene without "
                                    f"envs, got {len(value)}")
        if isinstance(value, torch.Tensor):  # (kept in the autograd graph)
            return value[:, None] if per_env else value[None]
        return np.expand_dims(np.asarray(value), 1) if per_env else [value]

    def get_AABB(self, envs_idx=None):
        """The world-axes box holding the link's collision shapes, m: (2, 3) or (n_envs, 2, 3), as
        ``RigidEntity.get_AABB`` for this link alone."""
        return self.entity._aabb([self.idx_local], envs_idx, f"link '{self.name}'")

    def apply_external_wrench(self, force=None, torque=None, envs_idx=None, *, pos=None, ref="link_origin",
                              local=False):
        """``RigidEntity.apply_links_external_wrench`` on this link: force (N), torque (N·m) and pos
        (m) (3,) or, batched, (len(envs_idx), 3)."""
        force, torque, pos = (_with_link_axis(self, arg, value) for arg, value in
                              (("force", force), ("torque", torque), ("pos", pos)))
        self.entity.apply_links_external_wrench(force, torque, [self.idx_local], envs_idx, pos=pos, ref=ref,
                                                local=local)

    def apply_external_force(self, force, envs_idx=None, *, pos=None, ref="link_origin", local=False):
        """``apply_external_wrench`` with a force alone."""
        self.apply_external_wrench(force, None, envs_idx, pos=pos, ref=ref, local=local)

    def apply_external_torque(self, torque, envs_idx=None, *, ref="link_origin", local=False):
        """``apply_external_wrench`` with a torque alone."""
        self.apply_external_wrench(None, torque, envs_idx, ref=ref, local=local)

    def __repr__(self):
        return f"RigidLink({self.name!r}, idx_local={self.idx_local})"


class RigidJoint:
    """The joint attaching a link to its parent: ``type`` is "fixed", "revolute", "prismatic", "ball" or "free";
    ``uid``."""

    def __init__(self, entity, name, type, link, dofs_idx_local, qs_idx_local):
        self.entity, self.name, self.type, self.link = entity, name, type, link
        self.dofs_idx_local, self.qs_idx_local = dofs_idx_local, qs_idx_local
        self.uid = UID()

    @property
    def n_dofs(self):
        return len(self.dofs_idx_local)

    @property
    def n_qs(self):
        return len(self.qs_idx_local)

    @property
    def idx_local(self):
        """The joint's place in its entity's ``joints``."""
        return self.entity.joints.index(self)

    @property
    def idx(self):
        """Its place among the scene's rigid joints (once built)."""
        return self.entity.joint_start + self.idx_local

    @property
    def is_built(self):
        return self.entity.is_built

    @property
    def dof_start(self):
        """Its first dof in the scene's rigid solver (once built); dof_end one past its last."""
        return self.entity.dof_start + self.dofs_idx_local[0]

    @property
    def dof_end(self):
        return self.dof_start + self.n_dofs

    @property
    def q_start(self):
        """Its first coordinate in the scene's rigid solver (once built); q_end one past its last."""
        return self.entity.q_start + self.qs_idx_local[0]

    @property
    def q_end(self):
        return self.q_start + self.n_qs

    @property
    def init_qpos(self):
        """(n_qs,) numpy: the joint's coordinates in its entity's init_qpos, as Genesis's."""
        return self.entity.init_qpos[self.qs_idx_local]

    @property
    def dofs_idx(self):
        """The joint's dofs in the scene's rigid solver (available once the scene is built)."""
        return [self.entity.dof_start + i for i in self.dofs_idx_local]

    @property
    def qs_idx(self):
        """The joint's generalized coordinates in the scene's rigid solver (once built)."""
        return [self.entity.q_start + i for i in self.qs_idx_local]

    def get_anchor_pos(self, envs_idx=None):
        """The joint's anchor in the world, m: (3,) or (n_envs, 3), as Genesis's and MuJoCo's xanchor:
        the point of its parent's side where it sits, taken at its coordinate's initial value (a
        slide's does not move with its own coordinate); a free joint's, its body's position."""
        return self.entity._out(self._anchor(envs_idx)[0])

    def get_anchor_axis(self, envs_idx=None):
        """The joint's axis in the world: (3,) or (n_envs, 3), as Genesis's and MuJoCo's xaxis: a
        hinge's or slide's axis; a ball joint's its parent side's z axis; a free joint's the world's z."""
        return self.entity._out(self._anchor(envs_idx)[1])

    def _anchor(self, envs_idx):
        """(anchor (B', 3) m, axis (B', 3)) of the joint in the world (the entity's envs_idx rows)."""
        entity = self.entity
        model, link = entity._solver.model, entity.link_start + self.link.idx_local
        envs = torch.as_tensor(entity._envs(envs_idx), device=runtime.device)
        poses = entity._sim().derived(entity._solver)[envs]  # (B', L, 13): every link of the solver
        as_tensor = functools.partial(torch.as_tensor, dtype=poses.dtype, device=poses.device)
        z = as_tensor([0.0, 0.0, 1.0]).expand(len(envs), 3)
        if self.type == "free":
            return poses[:, link, :3], z
        parent = int(model.link_parent[link])
        if parent >= 0:
            origin, turn = poses[:, parent, :3], quat_to_mat(poses[:, parent, 3:7])
        else:  # (the world: a root's pos0 is its placement)
            origin, turn = torch.zeros_like(z), torch.eye(3, dtype=z.dtype, device=z.device).expand(len(z), 3, 3)
        frame = turn @ quat_to_mat(as_tensor(model.link_quat0[link]))
        axis = frame @ (z[0] if self.type == "ball" else as_tensor(model.link_axis[link]))
        anchor = origin + turn @ as_tensor(model.link_pos0[link])
        if self.type == "prismatic":  # (at its initial coordinate, where an MJCF ref puts the body)
            anchor = anchor + axis * float(model.qpos0[model.dof_q[entity.dof_start + self.dofs_idx_local[0]]])
        return anchor, axis

    def __getattr__(self, name):
        """Genesis's deprecated singular names (dof_idx_local, dof_idx, q_idx_local, q_idx): an int
        for a joint of one dof (or coordinate), None for none, else the list; with Genesis's warning."""
        plural = {"dof_idx": "dofs_idx", "dof_idx_local": "dofs_idx_local", "q_idx": "qs_idx",
                  "q_idx_local": "qs_idx_local"}.get(name)
        if plural is None:
            raise AttributeError(f"'RigidJoint' object has no attribute {name!r}")
        logger.warning(f"RigidJoint.{name} is deprecated (as in Genesis); use '{plural}' instead")
        values = getattr(self, plural)
        return values[0] if len(values) == 1 else None if not values else values

    def __repr__(self):
        return f"RigidJoint({self.name!r}, type={self.type!r}, dofs_idx_local={self.dofs_idx_local})"


class RigidEntityState:
    """Genesis's RigidEntityState: the base link's pose, pos (B, 3) m and quat (B, 4) (w, x, y,
    z), B = max(1, n_envs) as Genesis's; copies, differentiable."""

    def __init__(self, entity, pos, quat):
        self.entity, self.pos, self.quat = entity, pos, quat


@named_argument_errors
class RigidEntity(EntityIndexing):
    """A rigid entity. Units: m, rad, kg, s, N, N·m; quaternions (w, x, y, z)."""

    def __init__(self, scene, idx, name, morph, material, surface, link_specs, solver):
        self.scene, self.idx, self.name = scene, idx, name
        self.morph, self.material, self.surface = morph, material, surface
        self.uid = UID()  # (Genesis's: scene.get_entity(uid=...) finds the entity by its short form)
        self._specs = link_specs
        self._solver = solver
        self._solver_idx = solver.add_entity(name, link_specs)
        self.attached_to = None  # (parent entity, its RigidLink) once attach hangs this one from it
        self.n_links = len(link_specs)
        self.n_geoms = sum(len(spec.geoms) for spec in link_specs)
        self._link_geoms = np.cumsum([0] + [len(spec.geoms) for spec in link_specs])  # local geoms per link
        self._friction = self._friction_ratio = None  # set_friction's and set_friction_ratio's (_friction_ratios)
        self._friction_generation = None  # the rollout they were set in
        self.links = [RigidLink(self, spec.name, k) for k, spec in enumerate(link_specs)]
        self._take_joints()

    def _take_joints(self):
        """n_dofs, n_qs, whether the base is free and the joints, from the specs. The structure is
        known as soon as the entity is added (as in Genesis), so argument checks work before build;
        the scene-wide offsets (link_start, dof_start, q_start) only exist after build (see
        __getattr__)."""
        specs = self._specs
        self.n_dofs = sum(_NDOFS[spec.joint_type] for spec in specs)
        self.n_qs = sum(_NQS[spec.joint_type] for spec in specs)
        self._free = specs[0].joint_type == "free"
        # Joints that move (a free root's too), as in Genesis: a fixed joint is no RigidJoint. Same
        # local numbering as _on_build derives from the model.
        self.joints, dof, q = [], 0, 0
        for link, spec in zip(self.links, specs):
            nd, nq = _NDOFS[spec.joint_type], _NQS[spec.joint_type]
            if nd:
                name = spec.joint_name or ("root_joint" if spec.joint_type == "free" else f"{spec.name}_joint")
                self.joints.append(RigidJoint(self, name, spec.joint_type, link, list(range(dof, dof + nd)),
                                              list(range(q, q + nq))))
            dof, q = dof + nd, q + nq

    def attach(self, parent_entity, parent_link_name=None, pos=None, quat=None):
        """Hang this entity's base link from a link of ``parent_entity`` (added before it), before
        build, as Genesis's: the base's free joint goes (it is welded to that link), and the two
        are one kinematic tree (one body to the contact rules where welded: a gripper's base and
        the arm's flange never collide). parent_link_name: that link's name (None: the parent's
        last link that is not a static root; Genesis 1.4.5 raises). pos (3,) m and quat (4,) w-x-y-z:
        the base's pose in that link's frame, as Genesis places it (a base pose the file states goes,
        as the morph's does); neither given: the morph's pos and quat and the file's base pose after
        them, as at load; one given: the other's identity. Gravity compensation stays each entity's
        own (Genesis's follows the tree's root entity). Differentiable as any scene (Genesis refuses
        requires_grad)."""
        who = f"entity '{self.name}': attach"
        if self.scene.is_built:
            raise SceneStateError(f"{who}: the scene is already built; attach entities before scene.build()")
        if not isinstance(parent_entity, RigidEntity) or parent_entity.scene is not self.scene:
            raise InvalidInputError(f"{who} argument 'parent_entity' must be a rigid entity of the same scene, got "
                                    f"{parent_entity!r}")
        if parent_entity is self or parent_entity.idx > self.idx:
            raise InvalidInputError(f"{who} argument 'parent_entity' must be an entity added before this one "
                                    f"(Genesis's rule), got entity '{parent_entity.name}' (added "
                                    f"{'as this one' if parent_entity is self else 'after it'})")
        if self.attached_to is not None:
            raise InvalidInputError(f"{who}: the entity is already attached to entity '{self.attached_to[0].name}'")
        link = (parent_entity._default_mount_link() if parent_link_name is None
                else parent_entity.get_link(parent_link_name))
        base = self._specs[0]
        if pos is not None or quat is not None:  # (the file's own base pose goes with the morph's, as in Genesis)
            mount = (_mount_vector(who, "pos", pos, 3, (0.0, 0.0, 0.0)),
                     _mount_vector(who, "quat", quat, 4, (1.0, 0.0, 0.0, 0.0)))  # (both checked before either is set)
            base.pos, base.quat = mount
        base.joint_type = "fixed"
        self._take_joints()
        self._solver.attach(self._solver_idx, parent_entity._solver_idx, link.idx_local)
        self.attached_to = (parent_entity, link)

    def _default_mount_link(self):
        """The link attach takes when none is named: the last that is not a root welded in place
        (an MJCF's static link of its worldbody's geoms comes last), Genesis's "latest link"."""
        for link, spec in zip(reversed(self.links), reversed(self._specs)):
            if spec.parent >= 0 or spec.joint_type != "fixed":
                return link
        return self.links[-1]

    _BUILD_ATTRS = ("link_start", "dof_start", "q_start", "geom_start", "joint_start", "_dof_q", "_free_joints",
                    "_ball_joints", "_turns", "_quat_joint_dofs", "_dof_motions")

    def __getattr__(self, attr):
        # only reached when normal lookup fails: a build-time attribute used before build()
        if attr in RigidEntity._BUILD_ATTRS:
            raise SceneStateError(f"entity '{self.__dict__.get('name')}': call scene.build() first "
                                  f"(needed for '{attr}')")
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {attr!r}")

    # -- structure --------------------------------------------------------------------------
    def _on_build(self):
        """Scene-wide offsets of this entity's links, dofs and qs (known once the model is built)."""
        model = self._solver.model
        mine = np.flatnonzero(model.link_entity == self._solver_idx)
        self.link_start = int(mine[0])
        self.dof_start = int(model.link_dof0[mine[0]])
        self.q_start = int(model.link_q0[mine[0]])
        # the entity's geoms are contiguous: the model lists them link by link, entity by entity
        self.geom_start = int(np.searchsorted(model.geom_link, mine[0]))
        entities = self.scene._rigid_entities()
        self.joint_start = sum(entity.n_joints for entity in entities[:entities.index(self)])
        # (first local dof, first local q) of each free joint: the base's, and those of later trees'
        # free roots (an MJCF with several bodies in its worldbody)
        first = [(int(model.link_dof0[l]) - self.dof_start, int(model.link_q0[l]) - self.q_start) for l in mine]
        jtype = model.link_jtype[mine]
        self._free_joints = [at for at, jt in zip(first, jtype) if jt == FREE]
        self._ball_joints = [at for at, jt in zip(first, jtype) if jt == BALL]
        # (first local dof, first local q) of every joint's rotation stored as a quaternion: a free
        # joint's last three dofs, a ball joint's three
        self._turns = sorted([(dof + 3, q + 3) for dof, q in self._free_joints] + self._ball_joints)
        # the dofs of free and ball joints: no scalar coordinate, so no position servo (and no scalar spring)
        self._quat_joint_dofs = np.array([dof + k for (dof, _), jt in zip(first, jtype) if jt in (FREE, BALL)
                                          for k in range(6 if jt == FREE else 3)], dtype=np.int64)
        # per local dof: its column in the state's qpos; a free joint's linear dofs are its origin's
        # columns, rotational dofs (Euler angles, stored as a quaternion) -1
        self._dof_q = model.dof_q[self.dof_start: self.dof_start + self.n_dofs].astype(np.int64)
        for dof, q in self._free_joints:
            self._dof_q[dof: dof + 3] = self.q_start + q + np.arange(3)
        self._dof_motions = kinematics.DofMotions(self)  # (the Jacobian's columns: get_jacobian, inverse kinematics)
        self._inputs_held = {}  # input name → (tensor, as numpy, memo): _input_array

    @property
    def n_joints(self):
        return len(self.joints)

    @property
    def link_end(self):
        """One past the entity's last link in the scene's rigid solver (once built; dof_end, q_end, geom_end,
        joint_end alike)."""
        return self.link_start + self.n_links

    @property
    def dof_end(self):
        return self.dof_start + self.n_dofs

    @property
    def geom_end(self):
        return self.geom_start + self.n_geoms

    @property
    def joint_end(self):
        return self.joint_start + self.n_joints

    @property
    def q_end(self):
        return self.q_start + self.n_qs

    @property
    def is_free(self):
        return self._free

    @property
    def base_link(self):
        """The entity's first link (its first tree's root), as Genesis's."""
        return self.links[0]

    @property
    def base_joint(self):
        """The base link's joint, as Genesis's (a free base's: its 6 dofs). A base welded to the
        world has no RigidJoint here (Genesis keeps a fixed joint object): a named error."""
        if not self.joints or self.joints[0].link is not self.base_link:
            raise InvalidInputError(f"entity '{self.name}': base_joint: the base link '{self.base_link.name}' is "
                                    f"welded to the world; only joints that move are RigidJoints here "
                                    f"({[joint.name for joint in self.joints]})")
        return self.joints[0]

    @property
    def base_link_idx(self):
        """The base link's index in the scene's rigid solver (once built), as Genesis's."""
        return self.base_link.idx

    @property
    def is_built(self):
        """Whether the entity's scene is built, as Genesis's."""
        return self.scene.is_built

    @property
    def is_attached(self):
        """Whether ``attach`` hung this entity from another, as Genesis's."""
        return self.attached_to is not None

    @property
    def init_qpos(self):
        """(n_qs,) numpy: the entity's qpos at build (each joint's initial position: an MJCF ref, a
        free base's placement), as Genesis's; before build from its links' joints."""
        if not self.scene.is_built:
            return np.array([q for spec in self._specs for q in initial_q(spec)], dtype=np.float64)
        return self._solver.model.qpos0[self.q_start: self.q_start + self.n_qs].copy()

    def get_link(self, name=None, uid=None):
        """The link named ``name``, else the one whose uid holds the digits ``uid`` (Genesis's)."""
        if name is None:
            return self._by_uid("get_link", self.links, uid)
        for link in self.links:
            if link.name == name:
                return link
        host = merged_into(self._specs, name)
        if host is not None:
            raise InvalidInputError(f"entity '{self.name}': get_link argument 'name': link {name!r} was merged into "
                                    f"link {host!r} (it hangs on a fixed joint, and gs.morphs.URDF(merge_fixed_links"
                                    f"=True) merges such links); use get_link({host!r}), or load with "
                                    f"links_to_keep=[{name!r}] or merge_fixed_links=False")
        raise InvalidInputError(f"entity '{self.name}': get_link argument 'name' must be one of "
                                f"{[link.name for link in self.links]}, got {name!r}")

    def get_joint(self, name=None, uid=None):
        """The joint named ``name``, else the one whose uid holds the digits ``uid`` (Genesis's)."""
        if name is None:
            return self._by_uid("get_joint", self.joints, uid)
        for joint in self.joints:
            if joint.name == name:
                return joint
        fixed = [spec.name for spec in self._specs if spec.joint_type == "fixed" and spec.joint_name == name]
        fixed += [host.name for host in self._specs for _, joint in host.merged if joint == name]
        if fixed:
            raise InvalidInputError(f"entity '{self.name}': get_joint argument 'name': {name!r} is a fixed joint "
                                    f"(of link {fixed[0]!r}); as in Genesis, only joints that move are RigidJoints: "
                                    f"{[joint.name for joint in self.joints]}")
        raise InvalidInputError(f"entity '{self.name}': get_joint argument 'name' must be one of "
                                f"{[joint.name for joint in self.joints]}, got {name!r}")

    def _by_uid(self, who, members, uid):
        if uid is None:
            raise InvalidInputError(f"entity '{self.name}': {who} missing a required argument: 'name' or 'uid'")
        for member in members:  # (the first that holds them, as Genesis's)
            if isinstance(uid, str) and uid and uid in str(member.uid):
                return member
        raise InvalidInputError(f"entity '{self.name}': {who} argument 'uid' must be digits of a uid of "
                                f"{[member.uid.short() for member in members]}, got {uid!r}")

    # -- argument checking ----------------------------------------------------------------------
    # -- raw state/input access -------------------------------------------------------------------
    def _read(self, columns, envs_idx):
        return self._rows(columns, None if envs_idx is None else self._envs(envs_idx))

    def _rows(self, columns, envs):
        """State columns of the envs ``envs`` (int array; None: every env): (len(envs) or B,
        len(columns))."""
        return take(self._sim().state(self._solver), envs, columns)

    def _write(self, columns, envs, values, zero_velocity=False):
        """State columns ← values (len(envs), len(columns)) in envs, out of place. zero_velocity:
        every dof velocity of the entity there ← 0 too, in the same write (so with gradients
        those columns are constants: nothing set before flows through them)."""
        if zero_velocity:
            columns = np.concatenate([columns, self._vel_columns(np.arange(self.n_dofs))])
            values = torch.cat([values, values.new_zeros(len(envs), self.n_dofs)], dim=1)
        self._sim().write_state(self._solver, envs, columns, values)

    def _read_input(self, name, columns, envs_idx):
        envs = None if envs_idx is None else self._envs(envs_idx)
        return take(self._sim().inputs(self._solver)[name], envs, columns)

    def _link_columns(self, links, width):
        """The columns of the entity's ``links`` (local indices) in a per-link input of ``width``
        values a link (com: x, y, z; inertia: its 3 × 3 row-major)."""
        return (width * (self.link_start + np.asarray(links))[:, None] + np.arange(width)).reshape(-1)

    def _links_com(self, links, envs_idx):
        """(B', len(links), 3) m: the links' centres of mass in their frames (the input com)."""
        value = self._read_input("com", self._link_columns(links, 3), envs_idx)
        return value.reshape(value.shape[0], len(links), 3)

    def _links_inertia(self, links, envs_idx):
        """(B', len(links), 3, 3) kg·m²: the links' rotational inertias about their centres of mass,
        in their frames (the input inertia)."""
        value = self._read_input("inertia", self._link_columns(links, 9), envs_idx)
        return value.reshape(value.shape[0], len(links), 3, 3)

    def _write_input(self, name, columns, envs, values):
        sim = self._sim()
        sim.set_input(self._solver, name, _replace(sim.inputs(self._solver)[name], envs, columns, values))

    def _set_dofs_input(self, name, value, dofs_idx_local, envs_idx, arg):
        dofs = self._local(dofs_idx_local, self.n_dofs, "dofs_idx_local", distinct=True)
        envs = self._envs(envs_idx, distinct=True)
        self._write_input(name, self.dof_start + dofs, envs, self._values(value, len(dofs), envs, arg))

    def _get_dofs_input(self, name, dofs_idx_local, envs_idx):
        dofs = self._local(dofs_idx_local, self.n_dofs, "dofs_idx_local")
        return self._out(self._read_input(name, self.dof_start + dofs, envs_idx))

    # -- dof state ------------------------------------------------------------------------------
    def _qpos_columns(self):
        return self._solver_q(np.arange(self.n_qs))

    @property
    def _model(self):
        """The built scene's rigid model (a named error before build)."""
        self._sim()
        return self._solver.model

    def _solver_q(self, local_qs):
        return self.q_start + np.asarray(local_qs)

    def _vel_columns(self, dofs):
        return self._model.n_qs + self.dof_start + dofs

    def _dofs_position_all(self, envs_idx):
        """(B', n_dofs) dof positions; a free joint's are its origin and Euler angles, a ball
        joint's Euler angles."""
        qpos = self._read(self._qpos_columns(), envs_idx)
        scalar = qpos[:, torch.as_tensor(np.maximum(self._dof_q - self.q_start, 0), device=runtime.device)]
        pieces, done = [], 0
        for dof, q in self._turns:
            pieces += [scalar[:, done: dof], quat_to_euler_xyz(qpos[:, q: q + 4])]
            done = dof + 3
        return torch.cat(pieces + [scalar[:, done:]], dim=1) if pieces else scalar

    def get_dofs_position(self, dofs_idx_local=None, envs_idx=None):
        """Joint positions, rad or m: (n,) or (n_envs, n), each joint's q as MuJoCo's qpos (an MJCF
        joint with a ``ref``: absolute, not relative to it as Genesis's). A free joint's first three
        dofs are the world position of its link origin (m), the next three its orientation as
        intrinsic X-Y-Z Euler angles (rad, R = Rx(a)·Ry(b)·Rz(c), as in Genesis); get_qpos gives the
        quaternion. A ball joint's three dofs are its turn from the joint frame, as intrinsic X-Y-Z
        Euler angles too (Genesis's)."""
        dofs = self._local(dofs_idx_local, self.n_dofs, "dofs_idx_local")
        columns = self._dof_q[dofs]
        if (columns >= 0).all():  # no Euler angle asked for: the state's columns (5x faster)
            return self._out(self._read(columns, envs_idx))
        return self._out(self._dofs_position_all(envs_idx)[:, torch.as_tensor(dofs, device=runtime.device)])

    def set_dofs_position(self, position, dofs_idx_local=None, envs_idx=None, *, zero_velocity=True):
        """Set joint positions, rad or m: (n,) or (len(envs_idx), n); a free joint's dofs as in
        get_dofs_position. Setting some of its Euler angles keeps the others' current values
        (read back from its quaternion). zero_velocity (Genesis's default after a jump): first
        set every dof velocity of the entity to 0 in the selected envs (all if envs_idx is None)."""
        dofs = self._local(dofs_idx_local, self.n_dofs, "dofs_idx_local", distinct=True)
        envs = self._envs(envs_idx, distinct=True)
        values = self._values(position, len(dofs), envs, "position")
        columns = self._dof_q[dofs]
        turned = columns < 0  # Euler angles of free and ball joints
        kept_columns, kept_values = [columns[~turned]], [values[:, ~turned]]
        for dof, q in self._turns:
            mine = turned & (dofs >= dof) & (dofs < dof + 3)
            if mine.any():
                quat_columns = self._solver_q(q + np.arange(4))
                kept_columns.append(quat_columns)
                kept_values.append(euler_xyz_to_quat(self._turn_euler(envs, quat_columns, dofs[mine] - dof,
                                                                      values[:, mine])))
        self._write(np.concatenate(kept_columns), envs, torch.cat(kept_values, dim=1), zero_velocity)

    def _turn_euler(self, envs, quat_columns, axes, angles):
        """(len(envs), 3) Euler angles of the free or ball joint whose quaternion is in ``quat_columns``:
        ``angles`` (len(envs), k) at ``axes`` (k ints in 0-2), the current ones elsewhere."""
        rows = torch.arange(len(envs), device=runtime.device)[:, None]
        axes = torch.as_tensor(axes, device=runtime.device)[None, :]
        if len(set(axes.flatten().tolist())) == 3:  # all set: the current orientation is not read
            return angles.new_zeros(len(envs), 3).index_put((rows, axes), angles)
        current = quat_to_euler_xyz(self._rows(quat_columns, envs))
        return current.index_put((rows, axes), angles)

    def get_dofs_velocity(self, dofs_idx_local=None, envs_idx=None):
        """Joint velocities, rad/s or m/s (a free joint: world linear, body-frame angular; a ball
        joint: body-frame angular)."""
        dofs = self._local(dofs_idx_local, self.n_dofs, "dofs_idx_local")
        return self._out(self._read(self._vel_columns(dofs), envs_idx))

    def set_dofs_velocity(self, velocity=None, dofs_idx_local=None, envs_idx=None, *, skip_forward=False):
        """Joint velocities, rad/s or m/s, as get_dofs_velocity gives them; None: zeros (Genesis's
        default). skip_forward: Genesis's (a setter's links' poses and velocities then wait for
        the next step there): taken, as a bool; here the readouts always follow the state set."""
        check_bool(self._who, "skip_forward", skip_forward)
        dofs = self._local(dofs_idx_local, self.n_dofs, "dofs_idx_local", distinct=True)
        envs = self._envs(envs_idx, distinct=True)
        values = self._values(0.0 if velocity is None else velocity, len(dofs), envs, "velocity")
        self._write(self._vel_columns(dofs), envs, values)

    def zero_all_dofs_velocity(self, envs_idx=None, *, skip_forward=False):
        """Every dof velocity of the entity ← 0 in envs_idx (all envs if None), as Genesis's."""
        self.set_dofs_velocity(None, None, envs_idx, skip_forward=skip_forward)

    def get_qpos(self, qs_idx_local=None, envs_idx=None):
        """Generalised positions (n_qs,): a free joint stores position then quaternion, a ball joint
        its quaternion."""
        qs = self._local(qs_idx_local, self.n_qs, "qs_idx_local")
        return self._out(self._read(self._solver_q(qs), envs_idx))

    def set_qpos(self, qpos, qs_idx_local=None, envs_idx=None, *, zero_velocity=True, skip_forward=False):
        """Generalised positions (n,) or (len(envs_idx), n); zero_velocity as in set_dofs_position,
        skip_forward as in set_dofs_velocity."""
        check_bool(self._who, "skip_forward", skip_forward)
        qs = self._local(qs_idx_local, self.n_qs, "qs_idx_local", distinct=True)
        envs = self._envs(envs_idx, distinct=True)
        values = self._values(qpos, len(qs), envs, "qpos")
        for _, q in self._turns:  # each free or ball joint's quaternion as this write leaves it
            written = [k for k in range(q, q + 4) if k in qs.tolist()]
            if written:
                quats = self._rows(self._solver_q(np.arange(q, q + 4)), envs).detach().clone()
                quats[:, [k - q for k in written]] = values[:, [qs.tolist().index(k) for k in written]].detach()
                self._check_quat(quats, "qpos")
        self._write(self._solver_q(qs), envs, values, zero_velocity)

    def _check_quat(self, quats, arg):
        """quats (n, 4): a zero quaternion has no orientation (the kinematics would make NaN)."""
        if bool((quats.detach().norm(dim=-1) == 0).any()):
            raise InvalidInputError(f"entity '{self.name}': argument '{arg}' must hold non-zero quaternions (w, x, y, "
                                    f"z), got {quats.detach().cpu().numpy()}")

    def _require_free(self, what):
        # Genesis moves a fixed entity's welded base too; ours keeps a fixed base in the model
        if not self._free:
            raise InvalidInputError(f"entity '{self.name}': {what} needs a free base (a morph with fixed=False), "
                                    f"got a fixed one; place a fixed entity with its morph's pos/euler before "
                                    f"scene.build(), or create it with fixed=False to move it (an MJCF tree "
                                    f"other than the first moves by set_dofs_position or set_qpos)")

    def set_pos(self, pos, envs_idx=None, *, zero_velocity=True, relative=True, skip_forward=False):
        """Base position in the world, m: (3,) or (len(envs_idx), 3) (free base only);
        zero_velocity as in set_dofs_position, relative as in get_links_pos, skip_forward as in
        set_dofs_velocity."""
        check_bool(self._who, "skip_forward", skip_forward)
        check_bool(self._who, "relative", relative)
        self._require_free("set_pos")
        envs = self._envs(envs_idx, distinct=True)
        self._write(self._solver_q([0, 1, 2]), envs, self._values(pos, 3, envs, "pos"), zero_velocity)

    def set_quat(self, quat, envs_idx=None, *, zero_velocity=True, relative=True, skip_forward=False):
        """Base orientation (w, x, y, z): (4,) or (len(envs_idx), 4) (free base only); normalised by
        the kinematics; zero_velocity as in set_dofs_position, relative as in get_links_pos,
        skip_forward as in set_dofs_velocity."""
        check_bool(self._who, "skip_forward", skip_forward)
        check_bool(self._who, "relative", relative)
        self._require_free("set_quat")
        envs = self._envs(envs_idx, distinct=True)
        values = self._values(quat, 4, envs, "quat")
        self._check_quat(values, "quat")
        self._write(self._solver_q([3, 4, 5, 6]), envs, values, zero_velocity)

    # -- link kinematics ----------------------------------------------------------------------------
    def _links(self, links_idx_local, envs_idx, columns):
        links = self._local(links_idx_local, self.n_links, "links_idx_local")
        return self._link_rows(links, envs_idx, columns)

    def _link_rows(self, links, envs_idx, columns):
        """_links of checked local link indices ``links`` (int array)."""
        envs = None if envs_idx is None else self._envs(envs_idx)
        return take(self._sim().derived(self._solver), envs, self.link_start + links)[..., columns]

    def get_state(self):
        """RigidEntityState of every env: the base link's pos and quat, with a leading env axis
        (of 1 without envs), as Genesis's (its differentiable tests read ``box.get_state().pos``)."""
        base = self._link_rows(_BASE, None, slice(0, 7))[:, 0]
        return RigidEntityState(self, wrap(base[:, :3].clone(), self.scene), wrap(base[:, 3:].clone(), self.scene))

    def get_links_pos(self, links_idx_local=None, envs_idx=None, *, ref="link_origin", relative=True):
        """Link positions in the world, m: (n_links, 3) or (n_envs, n_links, 3), at ``ref``
        (gs.link_ref_frame, as Genesis's): the link frame's origin ("link_origin"), the link's
        centre of mass ("link_com", Genesis's link_COM) or the centre of mass of the kinematic tree
        the link is in ("root_com", root_COM: every link with the same root, welded base
        included). relative: Genesis's choice between its authored and its internal link origins
        (shifted by its morphs' offsets and inertial alignment), which are the same here (a
        bool). A massless tree's (a plane's) centre of mass is its link origin."""
        links = self._local(links_idx_local, self.n_links, "links_idx_local")
        ref = self._link_ref(ref, "get_links_pos", relative, roots=True)
        if ref == "link_origin":
            return self._out(self._link_rows(links, envs_idx, slice(0, 3)))
        if ref == "link_com":
            return self._out(self._coms_world(links, envs_idx)[0])
        return self._out(self._trees_com(links, envs_idx))

    def get_links_quat(self, links_idx_local=None, envs_idx=None, *, relative=True):
        """Link orientations in the world (w, x, y, z); relative as in get_links_pos."""
        check_bool(self._who, "relative", relative)
        return self._out(self._links(links_idx_local, envs_idx, slice(3, 7)))

    def get_links_ang(self, links_idx_local=None, envs_idx=None):
        """Link angular velocities in the world frame, rad/s."""
        return self._out(self._links(links_idx_local, envs_idx, slice(7, 10)))

    def get_links_vel(self, links_idx_local=None, envs_idx=None, *, ref="link_origin", relative=True):
        """Linear velocities in the world frame, m/s, of the link frame origins ("link_origin") or
        of the links' centres of mass ("link_com": v + ω × (R c)), as Genesis's; relative as in
        get_links_pos."""
        links = self._local(links_idx_local, self.n_links, "links_idx_local")
        if self._link_ref(ref, "get_links_vel", relative, roots=False) == "link_origin":
            return self._out(self._link_rows(links, envs_idx, slice(10, 13)))
        offset, kinematics = self._coms_world(links, envs_idx)[1:]
        return self._out(kinematics[..., 10:13] + torch.linalg.cross(kinematics[..., 7:10], offset))

    def _link_ref(self, ref, method, relative, roots):
        """``ref`` checked (a gs.link_ref_frame; root_com where ``roots``) and ``relative`` a bool."""
        check_bool(self._who, "relative", relative)
        allowed = ("link_origin", "link_com") + (("root_com",) if roots else ())
        if ref not in allowed:
            raise InvalidInputError(f"{self._who}: {method} argument 'ref' must be one of gs.link_ref_frame's "
                                    f"{allowed}, got {ref!r}")
        return ref

    def _coms_world(self, links, envs_idx):
        """The links' centres of mass in the world (B', n, 3) m, their offsets from the link origins
        (world axes) and the links' kinematics (B', n, 13)."""
        kinematics = self._link_rows(links, envs_idx, slice(0, 13))
        offset = rotate(kinematics[..., 3:7], self._links_com(links, envs_idx))
        return kinematics[..., :3] + offset, offset, kinematics

    def _trees_com(self, links, envs_idx):
        """(B', n, 3) m: the centre of mass of each link's kinematic tree (every link of the scene
        with the same root link, the model's link_root), mass-weighted; a massless tree's (a
        plane's) is the link's origin."""
        sim = self._sim()
        model = self._solver.model
        roots = model.link_root
        members = torch.as_tensor(roots[None, :] == roots[self.link_start + links][:, None], dtype=runtime.tc_float,
                                  device=runtime.device)  # (n, L) scene links in each link's tree
        every = np.arange(model.n_links)
        envs = None if envs_idx is None else self._envs(envs_idx)
        kinematics = take(sim.derived(self._solver), envs, every)
        com = take(sim.inputs(self._solver)["com"], envs, np.arange(3 * model.n_links)).reshape(-1, model.n_links, 3)
        mass = take(sim.inputs(self._solver)["mass"], envs, every)  # (B', L) kg
        centres = kinematics[..., :3] + rotate(kinematics[..., 3:7], com)
        tree_mass = (mass @ members.T)[..., None]  # (B', n, 1)
        weighted = ((mass[..., None, :] * members) @ centres) / torch.where(tree_mass > 0, tree_mass, 1.0)
        return torch.where(tree_mass > 0, weighted, kinematics[:, self.link_start + links, :3])

    def _base(self, envs_idx, columns):
        """The base link's ``columns`` of its kinematics: (k,) or (len(envs), k)."""
        return self._out(self._link_rows(_BASE, envs_idx, columns)[..., 0, :])

    def get_pos(self, envs_idx=None, *, relative=True):
        """Base link position, m; relative as in get_links_pos."""
        check_bool(self._who, "relative", relative)
        return self._base(envs_idx, slice(0, 3))

    def get_quat(self, envs_idx=None, *, relative=True):
        """Base link orientation (w, x, y, z); relative as in get_links_pos."""
        check_bool(self._who, "relative", relative)
        return self._base(envs_idx, slice(3, 7))

    def get_vel(self, envs_idx=None, *, relative=True):
        """Base link origin's linear velocity, m/s; relative as in get_links_pos."""
        check_bool(self._who, "relative", relative)
        return self._base(envs_idx, slice(10, 13))

    def get_ang(self, envs_idx=None):
        return self._base(envs_idx, slice(7, 10))

    def get_AABB(self, envs_idx=None):
        """The world-axes box holding the entity's collision shapes at their current poses, m: (2, 3)
        or (n_envs, 2, 3), [lower corner, upper corner], as Genesis's. Exact for primitives (Genesis
        bounds their triangle meshes' vertices: a turned cylinder's box 1e-4 m smaller at 0.1 m
        radius); a plane is unbounded (±inf). Differentiable in the link poses."""
        return self._aabb(range(self.n_links), envs_idx, "the entity")

    def _aabb(self, links_idx_local, envs_idx, whose):
        """get_AABB of the shapes of ``links_idx_local`` (``whose``: what they are, for the error)."""
        links = list(links_idx_local)
        shapes = [(k, geom) for k, link in enumerate(links) for geom in self._specs[link].geoms]
        if not shapes:
            raise InvalidInputError(f"entity '{self.name}': get_AABB needs collision shapes, {whose} has none")
        poses = self._links(links, envs_idx, slice(0, 7))
        return self._out(shapes_aabb(shapes, poses[..., :3], poses[..., 3:]))

    # -- external wrenches ----------------------------------------------------------------------------
    def _link_vectors(self, value, n_links, envs, arg, method="apply_links_external_wrench", element=(3,)):
        """User (n, *element) or, batched, (len(envs), n, *element) values, or any shape that broadcasts
        to it as Genesis's (a (3,) vector for every link and env) → (len(envs), n, *element); method:
        whose argument."""
        shape = (n_links, *element) if self.scene.n_envs == 0 else (len(envs), n_links, *element)
        given = self._tensor(value, arg, shape)
        tensor = broadcast(given, shape)
        if tensor is None:
            raise InvalidInputError(f"entity '{self.name}': {method} argument '{arg}' must have "
                                    f"shape {shape} (or one that broadcasts to it), got {tuple(given.shape)}")
        width = n_links * int(np.prod(element))
        flat = tensor.reshape(*shape[:-1 - len(element)], width)
        return self._values(flat, width, envs, arg).reshape(-1, n_links, *element)

    def apply_links_external_wrench(self, force=None, torque=None, links_idx_local=None, envs_idx=None, *,
                                    pos=None, ref="link_origin", local=False):
        """Apply a force (N) and a torque (N·m) to links for the next step (Genesis's): ``force``,
        ``torque`` (n, 3) or (len(envs), n, 3); the force acts at ``pos`` (world, or with local an
        offset in the ref frame) else at the ref frame's origin: the link origin ("link_origin") or
        its centre of mass ("link_com"); local: force, torque and pos in the link's axes (for
        "link_com" too; Genesis takes its inertial frame's there). Calls before a step add up; the
        step applies them at each substep as the call left them in world axes (the force's point
        moves with the link origin, its offset does not turn with the link) and then forgets them.
        Differentiable in force, torque and pos."""
        who = f"entity '{self.name}': apply_links_external_wrench"
        if force is None and torque is None:
            raise InvalidInputError(f"{who} expected 'force' or 'torque', got neither")
        if force is None and pos is not None:
            raise InvalidInputError(f"{who} argument 'pos' needs a 'force' (a torque acts the same anywhere)")
        if ref not in ("link_origin", "link_com"):
            raise InvalidInputError(f"{who} argument 'ref' must be gs.link_ref_frame.link_origin ('link_origin') or "
                                    f"link_COM ('link_com'), got {ref!r}")
        if not isinstance(local, (bool, np.bool_)):
            raise InvalidInputError(f"{who} argument 'local' must be a bool, got {local!r}")
        links = self._local(links_idx_local, self.n_links, "links_idx_local", distinct=True)
        envs = self._envs(envs_idx, distinct=True)
        vectors = [None if value is None else self._link_vectors(value, len(links), envs, name)
                   for value, name in ((force, "force"), (torque, "torque"), (pos, "pos"))]
        self._apply_wrench(links, envs_idx, *vectors, ref, local)

    def _apply_wrench(self, links, envs_idx, f, t, point, ref, local):
        """apply_links_external_wrench of checked arguments: local link indices ``links`` (n,), f, t
        and point (len(envs), n, 3) or None (force, torque, pos; not both f and t None)."""
        envs = self._envs(envs_idx)
        pose = self._links(links, envs_idx, slice(0, 7))  # (len(envs), n, 7): origin, quaternion
        origin = pose[..., :3]
        f = torch.zeros_like(origin) if f is None else f
        t = torch.zeros_like(origin) if t is None else t
        # what is given in the link's axes, turned into the world's in one rotation: the force and
        # torque (local), the centre of mass (ref "link_com"), the point's offset (pos, local)
        given = ([f, t] if local else []) + ([self._links_com(links, envs_idx)] if ref == "link_com" else []) \
            + ([point] if point is not None and local else [])
        turned = list(rotate(pose[..., None, 3:], torch.stack(given, dim=-2)).unbind(-2)) if given else []
        if local:
            f, t = turned.pop(0), turned.pop(0)
        # the force's point as an offset from the link origin (world axes), none at the origin
        # itself: taken as point − origin there, a diverged env's inf − inf made it NaN, and
        # through the cross product the gradient of every input these envs share
        offset = turned.pop(0) if ref == "link_com" else None
        if point is not None:
            offset = point - origin if not local else turned.pop(0) + (0.0 if offset is None else offset)
        moment = t if offset is None else t + torch.linalg.cross(offset, f)
        self._add_wrench(links, envs, torch.cat([f, moment], dim=-1).reshape(len(envs), -1))

    def _add_wrench(self, links, envs, wrench):
        """The step's external wrench of local links ``links`` (n,) in envs ``envs`` (int array)
        += ``wrench`` (len(envs), 6n): per link force then moment about its origin, world axes."""
        columns = (6 * (self.link_start + links)[:, None] + np.arange(6)).ravel()
        self._write_input("xfrc", columns, envs, take(self._sim().inputs(self._solver)["xfrc"], envs, columns) + wrench)

    # -- Jacobian and inverse kinematics (entities/kinematics.py) -----------------------------------
    def _own_link(self, link, what):
        """The local index of ``link``, a RigidLink of this entity."""
        if not (isinstance(link, RigidLink) and link.entity is self):
            raise InvalidInputError(f"entity '{self.name}': {what} argument 'link' must be one of this entity's "
                                    f"links (entity.links, entity.get_link(name)), got {link!r}")
        return link.idx_local

    def _local_point(self, local_point, what):
        """(3,) float tensor of a point in the link frame, m (the origin when None)."""
        if local_point is None:
            return torch.zeros(3, dtype=runtime.tc_float, device=runtime.device)
        point = self._tensor(local_point, "local_point", "3 numbers")
        if point.shape != (3,):
            raise InvalidInputError(f"entity '{self.name}': {what} argument 'local_point' must hold 3 numbers (m, "
                                    f"in the link frame), got shape {tuple(point.shape)}")
        if not all_finite(point):
            raise InvalidInputError(f"entity '{self.name}': {what} argument 'local_point' must be finite, got "
                                    f"{point.tolist()}")
        return point

    def get_jacobian(self, link, local_point=None):
        """Jacobian (6, n_dofs) or (n_envs, 6, n_dofs) of the point ``local_point`` (3,) m in the
        frame of ``link`` (a RigidLink of this entity; its origin when None): rows 0–2 map the dof
        velocities to the point's linear velocity, rows 3–5 to the link's angular velocity, world
        frame (entities/kinematics.py). Differentiable, as the link poses it is made of."""
        if self.n_dofs == 0:
            raise InvalidInputError(f"entity '{self.name}': get_jacobian expected an entity with dofs, got none")
        local = self._own_link(link, "get_jacobian")
        point = self._local_point(local_point, "get_jacobian")
        pos, quat = self._links(None, None, slice(0, 3)), self._links(None, None, slice(3, 7))
        return self._out(kinematics.jacobian(self._dof_motions, pos, quat, local, point))

    def inverse_kinematics(self, link, pos=None, quat=None, local_point=None, init_qpos=None,
                           respect_joint_limit=True, max_samples=50, max_solver_iters=20, damping=0.01,
                           pos_tol=5e-4, rot_tol=5e-3, pos_mask=(True, True, True), rot_mask=(True, True, True),
                           max_step_size=0.5, seed=None, dofs_idx_local=None, return_error=False, envs_idx=None):
        """qpos (n_qs,) or (len(envs), n_qs) that puts ``local_point`` of ``link`` at ``pos`` (3,)
        (or one per env) and turns the link to ``quat`` (4,) (w, x, y, z), world frame; None: that
        part is free. Genesis's arguments and defaults: damped least squares (damping) from
        init_qpos (else the current qpos) for at most max_solver_iters steps of at most
        max_step_size, restarted up to max_samples times (from draws within the joint limits with
        respect_joint_limit, else from where the last run ended) until the position error ≤ pos_tol
        m and the rotation error ≤ rot_tol rad; pos_mask: the world axes the position counts along,
        rot_mask: all three, or the one axis of the link to align with the target's
        (entities/kinematics.py); only dofs_idx_local move. return_error: also the (…, 6) error
        (position m, world; rotation vector rad, link frame) of the qpos returned, the best found. The
        scene's state is not changed; not differentiable."""
        out = self.inverse_kinematics_multilink(
            [link], None if pos is None else [pos], None if quat is None else [quat],
            None if local_point is None else [local_point], init_qpos, respect_joint_limit, max_samples,
            max_solver_iters, damping, pos_tol, rot_tol, pos_mask, rot_mask, max_step_size, seed, dofs_idx_local,
            return_error, envs_idx)
        return (out[0], wrap(out[1][..., 0, :], self.scene)) if return_error else out

    def inverse_kinematics_multilink(self, links, poss=None, quats=None, local_points=None, init_qpos=None,
                                     respect_joint_limit=True, max_samples=50, max_solver_iters=20, damping=0.01,
                                     pos_tol=5e-4, rot_tol=5e-3, pos_mask=(True, True, True),
                                     rot_mask=(True, True, True), max_step_size=0.5, seed=None, dofs_idx_local=None,
                                     return_error=False, envs_idx=None):
        """inverse_kinematics for several links at once (Genesis's): ``poss``, ``quats``,
        ``local_points`` list one target (or None) per link of ``links`` (None or []: none); the
        tolerances hold for every link, errors (…, n_links, 6)."""
        who = f"entity '{self.name}': inverse_kinematics"
        for name, value in (("pos", poss), ("quat", quats), ("local_point", local_points), ("init_qpos", init_qpos)):
            refuse_grad(who, name, value, "the solve is iterative; differentiate get_jacobian or the rollout instead")
        def listed(values, name):
            try:
                return list(values)
            except TypeError:
                raise InvalidInputError(f"{who} argument '{name}' must be a list of one entry per link, got "
                                        f"{type(values).__name__}") from None

        links = listed(links, "links")
        envs = self._envs(envs_idx)

        def per_link(values, name):
            values = listed(values, name) if values is not None else []
            if values and len(values) != len(links):
                raise InvalidInputError(f"{who} argument '{name}' expected one entry per link ({len(links)}), got "
                                        f"{len(values)}")
            return values or [None] * len(links)

        pos_mask = kinematics.checked_mask(pos_mask, "pos_mask", who)
        rot_mask = kinematics.checked_mask(rot_mask, "rot_mask", who)
        if sum(rot_mask) == 2:
            raise InvalidInputError(f"{who} argument 'rot_mask' must align no axis, one or all three (as Genesis), "
                                    f"got {rot_mask}")
        goals = []
        for link, pos, quat, point in zip(links, per_link(poss, "poss"), per_link(quats, "quats"),
                                          per_link(local_points, "local_points")):
            goal_pos = None if pos is None else self._values(pos, 3, envs, "pos").detach()
            goal_quat = None if quat is None else self._values(quat, 4, envs, "quat").detach()
            if goal_quat is not None:
                self._check_quat(goal_quat, "quat")
                goal_quat = goal_quat / goal_quat.norm(dim=1, keepdim=True)
            goals.append(kinematics.Target(self._own_link(link, "inverse_kinematics"),
                                           self._local_point(point, "inverse_kinematics"), goal_pos, goal_quat,
                                           pos_mask, rot_mask))
        if not goals or all(target.pos is None and target.quat is None for target in goals):
            raise InvalidInputError(f"{who} expected a target 'pos' or 'quat', got neither")
        dofs = self._local(dofs_idx_local, self.n_dofs, "dofs_idx_local")
        if len(dofs) == 0:
            raise InvalidInputError(f"{who} argument 'dofs_idx_local' must name at least one dof, got none")
        start = self._read(self._qpos_columns(), envs_idx).detach() if init_qpos is None else \
            self._values(init_qpos, self.n_qs, envs, "init_qpos").detach()
        for _, q in self._turns if init_qpos is not None else ():
            self._check_quat(start[:, q: q + 4], "init_qpos")
        options = kinematics.checked_options(who, respect_joint_limit=respect_joint_limit, max_samples=max_samples,
                                             max_solver_iters=max_solver_iters, damping=damping, pos_tol=pos_tol,
                                             rot_tol=rot_tol, max_step_size=max_step_size, seed=seed)
        qpos, error = kinematics.solve_ik(self, goals, start, envs, dofs, options)
        return (self._out(qpos), self._out(error)) if return_error else self._out(qpos)

    # -- energy -------------------------------------------------------------------------------------
    def get_kinetic_energy(self, envs_idx=None):
        """Kinetic energy of the entity, J: () or (len(envs_idx),), as Genesis's (the links' and their
        rotors' through armature: MuJoCo's ½ q̇ᵀ M q̇; energy.py). Differentiable."""
        return self._out(energy.kinetic(self, envs_idx))

    def get_potential_energy(self, envs_idx=None):
        """Potential energy of the entity, J: () or (len(envs_idx),), as Genesis's: gravity on the
        links that move, −Σ m g · p_com, and the joint springs, Σ ½ stiffness (q − springref)²
        (Genesis's about qpos0; a ball joint's Σ ½ stiffness r², r its turn's rotation vector, as
        MuJoCo's; energy.py). Differentiable."""
        return self._out(energy.potential(self, envs_idx))

    def get_total_energy(self, envs_idx=None):
        """Kinetic plus potential energy, J: () or (len(envs_idx),). Differentiable."""
        return self._out(energy.kinetic(self, envs_idx) + energy.potential(self, envs_idx))

    # -- parameters ---------------------------------------------------------------------------------
    def get_links_mass(self, links_idx_local=None, envs_idx=None):
        links = self._local(links_idx_local, self.n_links, "links_idx_local")
        return self._out(self._read_input("mass", self.link_start + links, envs_idx))

    def set_links_mass(self, mass, links_idx_local=None, envs_idx=None):
        """Link masses, kg; their rotational inertias stay as they are, as Genesis's (set_mass scales
        them with the mass; set_links_inertia sets them). Differentiable."""
        links = self._local(links_idx_local, self.n_links, "links_idx_local", distinct=True)
        envs = self._envs(envs_idx, distinct=True)
        values = self._refuse_negative("mass", self._values(mass, len(links), envs, "mass"), " kg")
        self._write_input("mass", self.link_start + links, envs, values)

    def set_mass_shift(self, mass_shift, links_idx_local=None, envs_idx=None):
        """Genesis's domain randomisation: each link's mass ← the build's + mass_shift, kg ((n,) or
        (n_envs, n)); not cumulative. As set_links_mass: the inertia stays; differentiable."""
        links = self._local(links_idx_local, self.n_links, "links_idx_local", distinct=True)
        envs = self._envs(envs_idx, distinct=True)
        build = torch.as_tensor(self._model.link_mass0[self.link_start + links], dtype=runtime.tc_float,
                                device=runtime.device)
        values = build + self._values(mass_shift, len(links), envs, "mass_shift")
        if bool((values.detach() < 0).any()):
            raise InvalidInputError(f"entity '{self.name}': argument 'mass_shift' must leave every mass ≥ 0 kg (the "
                                    f"build's {build.cpu().numpy()} kg), got masses {values.detach().cpu().numpy()}")
        self._write_input("mass", self.link_start + links, envs, values)

    def set_COM_shift(self, com_shift, links_idx_local=None, envs_idx=None):
        """Genesis's domain randomisation: each link's centre of mass ← the build's + com_shift, m
        ((n, 3) or (n_envs, n, 3), in the link's frame); not cumulative. As set_links_COM, differentiable."""
        links = self._local(links_idx_local, self.n_links, "links_idx_local", distinct=True)
        envs = self._envs(envs_idx, distinct=True)
        build = torch.as_tensor(self._model.link_com[self.link_start + links], dtype=runtime.tc_float,
                                device=runtime.device)
        self._write_links_com(links, envs, build + self._link_vectors(com_shift, len(links), envs, "com_shift",
                                                                      "set_COM_shift"))

    def get_links_COM(self, links_idx_local=None, envs_idx=None):
        """Each link's centre of mass in its frame, m: (n, 3) or (n_envs, n, 3), as Genesis's."""
        links = self._local(links_idx_local, self.n_links, "links_idx_local")
        return self._out(self._links_com(links, envs_idx))

    def set_links_COM(self, com, links_idx_local=None, envs_idx=None):
        """Each link's centre of mass in its frame, m: (n, 3) or (n_envs, n, 3) (Genesis's); its
        inertia stays the same about it. Differentiable. The constraint rows' scale (MuJoCo's
        body_invweight0, get_dofs_invweight) stays that of the build's centres of mass, as MuJoCo's
        stays its compiled one (Genesis recomputes it)."""
        links = self._local(links_idx_local, self.n_links, "links_idx_local", distinct=True)
        envs = self._envs(envs_idx, distinct=True)
        self._write_links_com(links, envs, self._link_vectors(com, len(links), envs, "com", "set_links_COM"))

    def _write_links_com(self, links, envs, values):
        """The input com of ``links`` in ``envs`` ← values (len(envs), len(links), 3) m."""
        self._write_input("com", self._link_columns(links, 3), envs, values.reshape(len(envs), -1))

    def get_links_inertia(self, links_idx_local=None, envs_idx=None):
        """Each link's rotational inertia about its centre of mass, in its frame, kg·m²: (n, 3, 3) or
        (n_envs, n, 3, 3) (Genesis's in its inertial frame: the same where the asset's inertial
        frame is the link's, as in most URDFs; MJCF's principal frames differ). A massless link's
        starts at 0 (its stated inertia dropped, as MuJoCo drops it)."""
        links = self._local(links_idx_local, self.n_links, "links_idx_local")
        return self._out(self._links_inertia(links, envs_idx))

    def set_links_inertia(self, inertia, links_idx_local=None, envs_idx=None):
        """Each link's rotational inertia about its centre of mass, in its frame, kg·m²: (n, 3, 3) or
        (n_envs, n, 3, 3) (Genesis's); symmetric (taken as (I + Iᵀ)/2) with principal moments ≥ 0
        that satisfy the triangle inequality A + B ≥ C (MuJoCo's compiler's check: a rigid body's
        moments do), else a named error. The constraint rows' scale (get_dofs_invweight) follows it, as
        with the masses. Differentiable."""
        links = self._local(links_idx_local, self.n_links, "links_idx_local", distinct=True)
        envs = self._envs(envs_idx, distinct=True)
        values = self._link_vectors(inertia, len(links), envs, "inertia", "set_links_inertia", element=(3, 3))
        self._check_inertia(values.detach(), links)
        values = 0.5 * (values + values.transpose(-1, -2))
        self._write_input("inertia", self._link_columns(links, 9), envs, values.reshape(len(envs), -1))

    def _check_inertia(self, inertia, links):
        """A named error unless every (3, 3) of ``inertia`` (B, n, 3, 3) is symmetric with moments ≥ 0
        meeting A + B ≥ C (to round-off: 1e-6 of the largest entry, or of 1e-12 kg·m²)."""
        scale = inertia.abs().amax(dim=(-2, -1)).clamp(min=1e-12)
        tolerance = 1e-6 * scale
        asymmetry = (inertia - inertia.transpose(-1, -2)).abs().amax(dim=(-2, -1))
        moments = torch.linalg.eigvalsh(0.5 * (inertia + inertia.transpose(-1, -2)).double())
        triangle = moments[..., 0] + moments[..., 1] - moments[..., 2]
        bad = (asymmetry > tolerance) | (moments[..., 0] < -tolerance) | (triangle < -tolerance)
        if bool(bad.any()):
            env, k = (int(i) for i in torch.nonzero(bad)[0])
            name = self.links[int(links[k])].name
            raise InvalidInputError(
                f"entity '{self.name}': set_links_inertia argument 'inertia' of link '{name}' must be a symmetric "
                f"3 × 3 with principal moments ≥ 0 kg·m² meeting A + B ≥ C (a rigid body's), got "
                f"{inertia[env, k].cpu().numpy().tolist()} (moments {moments[env, k].cpu().numpy().tolist()})")

    def get_mass(self, envs_idx=None):
        """Total mass of the links that move, kg: () or (n_envs,). As Genesis's, links welded to the
        world are left out (never accelerated, their mass is the world's)."""
        static = self._model.link_static[self.link_start: self.link_start + self.n_links]
        moving = self.link_start + np.flatnonzero(static == 0)
        return self._out(self._read_input("mass", moving, envs_idx).sum(-1))

    def set_mass(self, mass, envs_idx=None):
        """Total mass of the links that move, kg: () or (len(envs_idx),), as Genesis's: every such
        link's mass (and its rotational inertia with it) scaled by one factor, their ratios kept.
        Differentiable."""
        static = self._model.link_static[self.link_start: self.link_start + self.n_links]
        moving = self.link_start + np.flatnonzero(static == 0)
        if not len(moving):
            raise InvalidInputError(f"entity '{self.name}': set_mass needs a link that moves; every link is welded "
                                    f"to the world, whose mass it is")
        envs = self._envs(envs_idx, distinct=True)
        given = self._tensor(mass, "mass", () if self.scene.n_envs == 0 else (len(envs),))
        if self.scene.n_envs == 0 and tuple(given.shape) == (1,):  # (a one-element tensor, as set_links_mass takes)
            given = given[0]
        total = self._values(given[..., None] if given.dim() == 1 else given, 1, envs, "mass")
        self._refuse_negative("mass", total, " kg")
        links_mass = self._read_input("mass", moving, envs_idx)
        ratio = total / links_mass.sum(-1, keepdim=True)
        self._write_input("mass", moving, envs, links_mass * ratio)
        local = moving - self.link_start  # (a body of the same shape made heavier: its inertias scale alike)
        inertia = self._links_inertia(local, envs_idx) * ratio[:, :, None, None]
        self._write_input("inertia", self._link_columns(local, 9), envs, inertia.reshape(len(envs), -1))

    def _refuse_negative(self, name, values, unit=""):
        """values (a tensor), after a named error if any is negative."""
        if bool((values.detach() < 0).any()):
            raise InvalidInputError(f"entity '{self.name}': argument '{name}' must be ≥ 0{unit}, got "
                                    f"{values.detach().cpu().numpy()}")
        return values

    def _nonnegative(self, name):
        def setter(value, dofs_idx_local=None, envs_idx=None):
            dofs = self._local(dofs_idx_local, self.n_dofs, "dofs_idx_local", distinct=True)
            envs = self._envs(envs_idx, distinct=True)
            values = self._refuse_negative(name, self._values(value, len(dofs), envs, name))
            self._write_input(name, self.dof_start + dofs, envs, values)
        return setter

    def set_dofs_kp(self, kp, dofs_idx_local=None, envs_idx=None):
        """Position gains, N·m/rad or N/m."""
        self._nonnegative("kp")(kp, dofs_idx_local, envs_idx)

    def set_dofs_kv(self, kv, dofs_idx_local=None, envs_idx=None):
        """Velocity gains, N·m·s/rad or N·s/m."""
        self._nonnegative("kv")(kv, dofs_idx_local, envs_idx)

    def set_dofs_damping(self, damping, dofs_idx_local=None, envs_idx=None):
        """Joint damping, N·m·s/rad or N·s/m."""
        self._nonnegative("damping")(damping, dofs_idx_local, envs_idx)

    def set_dofs_stiffness(self, stiffness, dofs_idx_local=None, envs_idx=None):
        """Joint spring stiffness, N·m/rad or N/m: a passive force −stiffness·(q − springref) on each
        dof, springref the asset's (MJCF ``springref``) or 0 (Genesis springs to qpos0, the
        initial position: an MJCF's ``ref``, else 0). Explicit in the step, as in MuJoCo and
        Genesis. A ball joint's dof a is pulled by −stiffness·r_a, r the rotation vector of its turn
        (MuJoCo's ball spring; Genesis: −stiffness times its Euler angle), one stiffness for its
        three dofs (MuJoCo's: another on each would push with a force no energy has). A free joint's
        dofs take none (0 only). Differentiable."""
        dofs = self._local(dofs_idx_local, self.n_dofs, "dofs_idx_local", distinct=True)
        envs = self._envs(envs_idx, distinct=True)
        values = self._refuse_negative("stiffness", self._values(stiffness, len(dofs), envs, "stiffness"))
        free = np.isin(dofs, [dof + k for dof, _ in self._free_joints for k in range(6)])
        if free.any() and bool((values.detach()[:, torch.as_tensor(free, device=values.device)] != 0).any()):
            raise InvalidInputError(f"entity '{self.name}': argument 'stiffness' must be 0 on the free joint's dofs "
                                    f"(local {dofs[free].tolist()}), got {values.detach().cpu().numpy()}")
        for dof, _ in self._ball_joints:
            mine = (dofs >= dof) & (dofs < dof + 3)
            if mine.any():
                current = self._sim().inputs(self._solver)["stiffness"][torch.as_tensor(envs, device=runtime.device)]
                after = current[:, self.dof_start + dof: self.dof_start + dof + 3].detach().clone()
                after[:, torch.as_tensor(dofs[mine] - dof, device=after.device)] = values.detach()[
                    :, torch.as_tensor(mine, device=after.device)]
                if bool((after != after[:, :1]).any()):
                    raise InvalidInputError(f"entity '{self.name}': argument 'stiffness' must be equal on the three "
                                            f"dofs of a ball joint (local {list(range(dof, dof + 3))}: one spring, "
                                            f"as MuJoCo's), would be {after.cpu().numpy()}")
        self._write_input("stiffness", self.dof_start + dofs, envs, values)

    def set_dofs_frictionloss(self, frictionloss, dofs_idx_local=None, envs_idx=None):
        """Dry joint friction, N·m or N: a friction-loss constraint row (MuJoCo's) resisting the
        dof's motion up to this bound. Differentiable where positive (at 0 the dof has no row and
        the gradient is 0: start a fit from a small positive value)."""
        self._nonnegative("frictionloss")(frictionloss, dofs_idx_local, envs_idx)

    def set_dofs_armature(self, armature, dofs_idx_local=None, envs_idx=None):
        """Rotor inertia added to the mass matrix diagonal, kg·m² or kg."""
        self._nonnegative("armature")(armature, dofs_idx_local, envs_idx)

    def get_dofs_kp(self, dofs_idx_local=None, envs_idx=None):
        return self._get_dofs_input("kp", dofs_idx_local, envs_idx)

    def get_dofs_kv(self, dofs_idx_local=None, envs_idx=None):
        return self._get_dofs_input("kv", dofs_idx_local, envs_idx)

    def get_dofs_damping(self, dofs_idx_local=None, envs_idx=None):
        return self._get_dofs_input("damping", dofs_idx_local, envs_idx)

    def get_dofs_stiffness(self, dofs_idx_local=None, envs_idx=None):
        return self._get_dofs_input("stiffness", dofs_idx_local, envs_idx)

    def get_dofs_frictionloss(self, dofs_idx_local=None, envs_idx=None):
        return self._get_dofs_input("frictionloss", dofs_idx_local, envs_idx)

    def get_dofs_armature(self, dofs_idx_local=None, envs_idx=None):
        return self._get_dofs_input("armature", dofs_idx_local, envs_idx)

    def get_links_invweight(self, links_idx_local=None, envs_idx=None):
        """Each link's inverse weights, translational (1/kg) and rotational (1/(kg·m²)): (n, 2) or
        (n_envs, n, 2), as Genesis's and MuJoCo's body_invweight0: the mean of the translational and
        of the rotational diagonal of J M⁻¹ Jᵀ at the initial pose, J the Jacobian of the link's
        centre of mass (0 for a link welded to the world); recomputed when masses or armature change
        (differentiable)."""
        links = self.link_start + self._local(links_idx_local, self.n_links, "links_idx_local")
        pair = [self._read_input(name, links, envs_idx) for name in ("invweight_t", "invweight_r")]
        return self._out(torch.stack(pair, dim=-1))

    def get_dofs_invweight(self, dofs_idx_local=None, envs_idx=None):
        """Each dof's inverse weight, 1/kg or 1/(kg·m²), as Genesis's and MuJoCo's dof_invweight0: the
        diagonal of M⁻¹ at the initial pose (a free joint's averaged over its three translations and
        over its three rotations, a ball joint's over its rotations), which scales the constraint
        rows' softness; recomputed when masses or armature change (differentiable)."""
        return self._get_dofs_input("invweight_dof", dofs_idx_local, envs_idx)

    def set_dofs_force_range(self, lower, upper, dofs_idx_local=None, envs_idx=None):
        """Bounds on the actuator force, N·m or N (±inf: none, Genesis's default); differentiable (a
        clipped force is its bound)."""
        dofs = self._local(dofs_idx_local, self.n_dofs, "dofs_idx_local", distinct=True)
        envs = self._envs(envs_idx, distinct=True)
        lo = self._values(lower, len(dofs), envs, "lower", infinite=True)
        hi = self._values(upper, len(dofs), envs, "upper", infinite=True)
        if bool((lo > hi).any()):
            raise InvalidInputError(f"entity '{self.name}': argument 'lower' must be ≤ 'upper', got "
                                    f"{lo.cpu().numpy()} and {hi.cpu().numpy()}")
        for name, bound, wrong in (("lower", lo, float("inf")), ("upper", hi, -float("inf"))):
            if bool((bound == wrong).any()):  # (both at +inf clipped every force to inf: the state NaN)
                raise InvalidInputError(f"entity '{self.name}': argument '{name}' must be finite or "
                                        f"{-wrong}, got {bound.detach().cpu().numpy()}")
        self._write_input("force_lo", self.dof_start + dofs, envs, lo)
        self._write_input("force_hi", self.dof_start + dofs, envs, hi)

    def get_dofs_limit(self, dofs_idx_local=None, envs_idx=None):
        """(lower, upper) position limits of the dofs, rad or m, each (n,) or (n_envs, n), as Genesis's:
        the asset's or set_dofs_limit's (±inf where a joint has none: continuous, free); a ball
        joint's dofs (−inf, its cone limit's angle) each (Genesis: ±inf, it ignores the limit); the
        rows enforce them unless RigidOptions(enable_joint_limit=False)."""
        return (self._get_dofs_input("limit_lower", dofs_idx_local, envs_idx),
                self._get_dofs_input("limit_upper", dofs_idx_local, envs_idx))

    def set_dofs_limit(self, lower, upper, dofs_idx_local=None, envs_idx=None):
        """Position limits of scalar dofs (hinge, slide), rad or m: lower and upper each (n,) or
        (n_envs, n), as Genesis's (±inf: no bound), on a dof limited by its asset or not; a limit
        row holds them (MuJoCo's, with the joint's limit softness). A ball or free joint's dofs
        have no position of their own to bound: refused. Differentiable (a met bound moves the
        row's reference)."""
        dofs = self._local(dofs_idx_local, self.n_dofs, "dofs_idx_local", distinct=True)
        envs = self._envs(envs_idx, distinct=True)
        turning = dofs[np.isin(dofs, self._quat_joint_dofs)]
        if len(turning):
            raise InvalidInputError(f"entity '{self.name}': set_dofs_limit got dofs {turning.tolist()} of a ball or "
                                    f"free joint (a turn, no scalar position to bound); expected hinge or slide dofs")
        lo = self._values(lower, len(dofs), envs, "lower", infinite=True)
        hi = self._values(upper, len(dofs), envs, "upper", infinite=True)
        if bool((lo.detach() > hi.detach()).any() or (lo.detach() == math.inf).any()
                or (hi.detach() == -math.inf).any()):
            raise InvalidInputError(f"entity '{self.name}': set_dofs_limit argument 'lower' must be ≤ 'upper', "
                                    f"lower < +inf and upper > −inf, got {lo.detach().cpu().numpy()} and "
                                    f"{hi.detach().cpu().numpy()}")
        self._write_input("limit_lower", self.dof_start + dofs, envs, lo)
        self._write_input("limit_upper", self.dof_start + dofs, envs, hi)

    def get_dofs_force_range(self, dofs_idx_local=None, envs_idx=None):
        return (self._get_dofs_input("force_lo", dofs_idx_local, envs_idx),
                self._get_dofs_input("force_hi", dofs_idx_local, envs_idx))

    # -- contacts -----------------------------------------------------------------------------------
    def get_contacts(self, with_entity=None, exclude_self_contact=False, is_padded=False):
        """The contacts of the last step's last substep that involve this entity (Genesis's format): a dict of
        geom_a, geom_b, link_a, link_b (global indices, int32), position (m), normal (unit, world,
        from geom b to geom a, as Genesis), penetration (m, > 0 when the geoms overlap), force_a and
        force_b (N, world: the contact's force on geom a and on geom b). Shapes (n, ...) in an unbatched
        scene; (n_envs, C, ...) with a valid_mask (n_envs, C) in a batched one, C the most contacts
        of the scene in one env (as Genesis: the entity's are the valid ones); with is_padded C is
        the scene's contact slots, and an unbatched scene's come as (C, ...) with a valid_mask too.
        with_entity: only contacts with that entity (itself: self-contacts only);
        exclude_self_contact: drop those. Not differentiable (a backward through position or forces
        raises)."""
        if not (with_entity is None or (isinstance(with_entity, RigidEntity) and with_entity.scene is self.scene)):
            raise InvalidInputError(f"entity '{self.name}': argument 'with_entity' must be a rigid entity of the same "
                                    f"scene or None, got {with_entity!r}")
        if not isinstance(exclude_self_contact, (bool, np.bool_)):
            raise InvalidInputError(f"entity '{self.name}': argument 'exclude_self_contact' must be True or False, "
                                    f"got {exclude_self_contact!r}")
        if not isinstance(is_padded, (bool, np.bool_)):
            raise InvalidInputError(f"entity '{self.name}': argument 'is_padded' must be True or False, got "
                                    f"{is_padded!r}")
        raw = self._sim().contacts(self._solver, "get_contacts", trimmed=not is_padded)
        if self.scene.n_envs and not is_padded:  # (each env's contacts come first in its slots)
            raw = raw[:, :int((raw[..., 0] >= 0).sum(dim=-1).max())]
        model = self._solver.model
        geom_a, geom_b = raw[..., 0].long(), raw[..., 1].long()
        links = torch.as_tensor(model.geom_link, device=runtime.device, dtype=torch.long)
        # an empty slot's link is -1, as its geom (Genesis's padding), not link 0's (often the ground's)
        link_a, link_b = (torch.where(g >= 0, links[g.clamp(min=0)], -1) for g in (geom_a, geom_b))
        mine = lambda g, entity: (g >= entity.geom_start) & (g < entity.geom_start + entity.n_geoms)
        a_mine, b_mine = mine(geom_a, self), mine(geom_b, self)
        if with_entity is self:
            if exclude_self_contact:
                raise InvalidInputError(f"entity '{self.name}': with_entity=self asks for self-contacts, which "
                                        f"exclude_self_contact=True removes")
            valid = a_mine & b_mine
        else:
            valid = (a_mine ^ b_mine) if exclude_self_contact else (a_mine | b_mine)
            if with_entity is not None:
                valid &= mine(geom_a, with_entity) | mine(geom_b, with_entity)
        valid &= geom_a >= 0
        out = {"geom_a": geom_a.int(), "geom_b": geom_b.int(), "link_a": link_a.int(), "link_b": link_b.int(),
               "position": raw[..., 2:5], "normal": -raw[..., 9:12], "penetration": -raw[..., 8],
               "force_a": -raw[..., 5:8], "force_b": raw[..., 5:8]}
        if self.scene.n_envs == 0 and not is_padded:
            return {k: wrap(v[0][valid[0]], self.scene) for k, v in out.items()}
        out["valid_mask"] = valid
        return {k: wrap(v[0] if self.scene.n_envs == 0 else v, self.scene) for k, v in out.items()}

    def get_links_net_contact_force(self, envs_idx=None):
        """(n_links, 3) or (n_envs, n_links, 3) N, world: the sum of the contact forces of the last
        step's last substep on each link of the entity. Not differentiable (a backward raises)."""
        total = self._sim().links_contact_force(self._solver, "get_links_net_contact_force")
        if envs_idx is not None:
            total = total[torch.as_tensor(self._envs(envs_idx), device=runtime.device)]
        return self._out(total[:, self.link_start: self.link_start + self.n_links])

    # -- contact parameters -----------------------------------------------------------------------
    def set_friction(self, friction):
        """Coulomb friction coefficient of every collision geom of the entity (a contact takes the
        larger of its two geoms' values), in [0.01, 5] as Genesis: a number, or a 0-d tensor,
        differentiable. As Genesis's, it keeps each env's friction ratio: a geom's friction is
        friction × ratio (set_friction_ratio)."""
        # (float32 holds 0.01 a little below it, 5.0 exactly: bounds within float32's round-off)
        value = self._friction_scalar(friction, "friction", lambda v: 0.01 * (1 - 1e-6) <= v <= 5.0,
                                      "a number in [0.01, 5.0]")
        self._set_friction_kind(0, value)

    def set_friction_torsional(self, friction_torsional):
        """Torsional friction (m: the radius of the patch sliding friction acts over) of every
        collision geom of the entity, ≥ 0, as Genesis's: a number or a 0-d tensor, differentiable.
        A contact takes the larger of its geoms' values; it resists spin at condim 4 and 6
        (RigidOptions(enable_torsional_friction=True), or an MJCF geom's condim). Scaled by the
        friction ratio (set_friction_ratio), as Genesis."""
        self._set_friction_kind(1, self._friction_scalar(friction_torsional, "friction_torsional", _finite_length,
                                                         "a finite number >= 0 (m)"))

    def set_friction_rolling(self, friction_rolling):
        """Rolling friction (m) of every collision geom of the entity, ≥ 0, as Genesis's: a number
        or a 0-d tensor, differentiable. A contact takes the larger of its geoms' values; it resists
        rolling at condim 6 (RigidOptions(enable_rolling_friction=True), or an MJCF geom's condim).
        Scaled by the friction ratio (set_friction_ratio), as Genesis."""
        self._set_friction_kind(2, self._friction_scalar(friction_rolling, "friction_rolling", _finite_length,
                                                         "a finite number >= 0 (m)"))

    def _friction_scalar(self, value, arg, ok, expected):
        """``value`` as a 0-d tensor (kept in the graph); a named error saying ``expected`` unless
        it is one number with ok(number)."""
        try:
            out = None if isinstance(value, (bool, np.bool_)) else self._tensor(value, arg, "()")
        except InvalidInputError:  # not numbers: the message below says what is expected
            out = None
        if out is None or out.dim() != 0 or not ok(float(out.detach())):
            raise InvalidInputError(f"entity '{self.name}': argument '{arg}' must be {expected}, got {value!r}")
        return out

    def _set_friction_kind(self, kind, value):
        """Friction of kind ``kind`` (0 sliding, 1 torsional, 2 rolling) of every geom ← value (0-d)."""
        friction, _ratio = self._friction_ratios()  # (made from the build's values at the first call)
        columns = [value.expand(self.n_geoms) if k == kind else friction[:, k] for k in range(3)]
        self._friction = torch.stack(columns, dim=1)
        self._write_friction(np.arange(self.n_geoms), self._envs(None))

    def set_friction_ratio(self, friction_ratio, links_idx_local=None, envs_idx=None):
        """Friction ratio (one per link, ≥ 0) of the geoms of the given links, per env: a geom's
        friction is its friction (the asset's or material's, or set_friction's) × its ratio (1 at
        first), as Genesis's, whichever of the two is set last. Differentiable."""
        links = self._local(links_idx_local, self.n_links, "links_idx_local", distinct=True)
        envs = self._envs(envs_idx, distinct=True)
        ratio = self._values(friction_ratio, len(links), envs, "friction_ratio")
        ratio = self._refuse_negative("friction_ratio", ratio)
        counts = torch.as_tensor(np.diff(self._link_geoms)[links], device=runtime.device)
        geoms = np.concatenate([np.arange(self._link_geoms[l], self._link_geoms[l + 1]) for l in links] + [[]])
        geoms = geoms.astype(np.int64)
        self._friction_ratios()  # (the table exists)
        self._friction_ratio = _replace(self._friction_ratio, envs, geoms, torch.repeat_interleave(ratio, counts, dim=1))
        self._write_friction(geoms, envs)

    def _friction_ratios(self):
        """(friction (n_geoms, 3): sliding, torsional, rolling; ratio (B, n_geoms)) of the entity's
        geoms, made at the first call
        from the build's friction and ratios of 1; detached after a reset, as the scene's
        parameters (a graph from the rollout before would be backpropagated through again)."""
        generation = self._sim().generation
        if self._friction_ratio is None:
            model = self._solver.model
            self._friction = torch.as_tensor(model.geom_friction[self.geom_start: self.geom_start + self.n_geoms],
                                             dtype=runtime.tc_float, device=runtime.device)
            self._friction_ratio = torch.ones(self._solver.n_batch, self.n_geoms, dtype=runtime.tc_float,
                                              device=runtime.device)
        elif self._friction_generation != generation:
            self._friction, self._friction_ratio = self._friction.detach(), self._friction_ratio.detach()
        self._friction_generation = generation
        return self._friction, self._friction_ratio

    def _write_friction(self, geoms, envs):
        """The input "friction" of the entity's geoms ``geoms`` (local) in ``envs`` ← friction × ratio
        (each of its three kinds)."""
        friction, ratio = self._friction_ratios()
        index = torch.as_tensor(geoms, device=runtime.device, dtype=torch.long)
        rows = torch.as_tensor(envs, device=runtime.device, dtype=torch.long)
        values = friction[index] * ratio[rows][:, index, None]  # (envs, geoms, 3)
        columns = (3 * (self.geom_start + np.asarray(geoms, dtype=np.int64))[:, None] + np.arange(3)).ravel()
        self._write_input("friction", columns, envs, values.reshape(len(envs), -1))

    def set_sol_params(self, sol_params, geoms_idx_local=None, envs_idx=None):
        """Contact softness of the entity's geoms (all by default): 7 numbers, Genesis's and
        MuJoCo's (timeconst s, dampratio, dmin, dmax, width m, midpoint, power) = solref then
        solimp, for every env of envs_idx or (len(envs_idx), 7) one row per env; timeconst and
        dampratio both ≤ 0 mean MuJoCo's direct form (−stiffness, −damping). A contact combines
        its two geoms' values as MuJoCo does (averaged, unless an MJCF priority or solmix says
        otherwise). Differentiable (a time constant raised to 2·dt/substeps has none; one exactly
        there, half: docs/genesis_api.md)."""
        geoms = self._local(geoms_idx_local, self.n_geoms, "geoms_idx_local", distinct=True)
        envs = self._envs(envs_idx, distinct=True)
        params = self._tensor(sol_params, "sol_params", f"(7,) or {(len(envs), 7)}")  # (in the graph: differentiable)
        if params.shape not in ((7,), (len(envs), 7)):
            raise InvalidInputError(f"entity '{self.name}': argument 'sol_params' must be 7 numbers (timeconst, "
                                    f"dampratio, dmin, dmax, width, midpoint, power), or 7 per env of envs_idx "
                                    f"{(len(envs), 7)}, got shape {tuple(params.shape)}")
        for row in params.detach().cpu().numpy().reshape(-1, 7):
            _check_sol_params(self.name, row)
        columns = self.geom_start + geoms
        params = params.expand(len(envs), 7)
        ref = params[:, :2].repeat(1, len(geoms))
        imp = params[:, 2:].repeat(1, len(geoms))
        self._write_input("solref", (2 * columns[:, None] + np.arange(2)).ravel(), envs, ref)
        self._write_input("solimp", (5 * columns[:, None] + np.arange(5)).ravel(), envs, imp)

    # -- coupling with MPM particles ----------------------------------------------------------------
    def set_coupling(self, friction=None, softness=None, restitution=None, envs_idx=None):
        """How the entity's shapes meet MPM particles (solvers/mpm/colliders.py), per env: the
        Coulomb friction μ ≥ 0, the softness ς ≥ 0 (m: how far outside a shape its influence
        reaches) and the restitution e in [0, 1] — its material's coup_friction, coup_softness and
        coup_restitution at build. Each a number for every env of envs_idx, or one per env of
        envs_idx; one not given keeps its values. Differentiable: the particles' and the bodies'
        motion through the rule (the set of grid nodes a shape acts on is taken as fixed)."""
        sim = self._sim()
        self._require_coupled("set_coupling")
        envs = self._envs(envs_idx, distinct=True)
        columns, values = [], []  # (all checked before any is written)
        for k, (arg, value, upper) in enumerate((("friction", friction, math.inf), ("softness", softness, math.inf),
                                                 ("restitution", restitution, 1.0))):
            if value is None:
                continue
            given = self._values(value, 1, envs, arg)
            numbers = given.detach().cpu().numpy()
            if not ((numbers >= 0.0) & (numbers <= upper)).all():
                bound = "in [0, 1]" if upper == 1.0 else ">= 0"
                raise InvalidInputError(f"{self._who}: set_coupling argument '{arg}' must be {bound}, got "
                                        f"{numbers.ravel()}")
            columns.append(coupling_columns(self._solver_idx)[k])
            values.append(given)
        if columns:
            mpm = self.scene.mpm_solver
            sim.set_input(mpm, "coupling", _replace(sim.inputs(mpm)["coupling"], envs, columns,
                                                    torch.cat(values, dim=1)))

    def _require_coupled(self, method):
        """A named error unless the MPM particles meet the entity's shapes (scene.coupled_entities)."""
        if self not in self.scene.coupled_entities:
            model = self._solver.model
            colliding = int(model.geom_collides[model.link_entity[model.geom_link] == self._solver_idx].sum())
            raise InvalidInputError(f"{self._who}: {method}: its shapes meet no MPM particles (expected a scene "
                                    f"with MPM entities and the rigid–MPM coupler, and a material with "
                                    f"needs_coup=True and colliding shapes), got material "
                                    f"needs_coup={self.material.needs_coup}, {colliding} colliding shape(s), MPM "
                                    f"entities: {self.scene.mpm_solver is not None}, coupler_options.rigid_mpm="
                                    f"{self.scene.coupler_options.rigid_mpm}")

    def get_coupling(self, envs_idx=None):
        """(3,) or (n_envs, 3): the coupling friction μ, softness ς (m) and restitution e with MPM
        particles (set_coupling)."""
        sim = self._sim()
        self._require_coupled("get_coupling")
        envs = self._envs(envs_idx)
        return self._out(take(sim.inputs(self.scene.mpm_solver)["coupling"], envs, coupling_columns(self._solver_idx)))

    # -- control ------------------------------------------------------------------------------------
    def _control(self, method, mode, targets, dofs_idx_local, envs_idx):
        """Switch the dofs to ``mode`` with ``targets``: {input name: (value, argument name)}; a value
        None is the constant 0 (written only where the input holds something else)."""
        dofs = self._local(dofs_idx_local, self.n_dofs, "dofs_idx_local", distinct=True)
        envs = self._envs(envs_idx, distinct=True)
        columns = self.dof_start + dofs
        modes, every_dof_in = self._input_array("ctrl_mode")  # (memo: {mode code: every dof in it}; no graph)
        for dof, _ in self._turns:
            given = np.count_nonzero((dofs >= dof) & (dofs < dof + 3))  # (dofs are distinct)
            if 0 < given < 3 and (mode == "position" or (
                    modes[envs[:, None], self.dof_start + dof + np.arange(3)] == _MODES["position"]).any()):
                raise InvalidInputError(f"entity '{self.name}': {method} drives a free or ball joint's three rotation "
                                        f"dofs together in or out of position control (their targets are one "
                                        f"orientation, as Euler angles): dofs_idx_local expected all of "
                                        f"{list(range(dof, dof + 3))} or none, got {dofs.tolist()}")
        checked = {name: self._values(value, len(dofs), envs, arg) for name, (value, arg) in targets.items()
                   if value is not None}  # every argument checked before anything is written
        for name in targets:
            if name in checked:
                self._write_input(name, columns, envs, checked[name])
            elif not self._holds_zeros(name, columns, envs):
                self._write_input(name, columns, envs, torch.zeros(len(envs), len(dofs), dtype=runtime.tc_float,
                                                                   device=runtime.device))
        code = _MODES[mode]
        if dofs_idx_local is None and envs_idx is None:  # (a control call every step: answered once per modes)
            if code not in every_dof_in:
                every_dof_in[code] = bool((modes[:, self.dof_start: self.dof_start + self.n_dofs] == code).all())
            held = every_dof_in[code]
        else:
            held = bool((modes[envs[:, None], columns] == code).all())
        if not held:  # a new tensor only on a change
            self._write_input("ctrl_mode", columns, envs, torch.full((len(envs), len(dofs)), float(code),
                                                                     dtype=runtime.tc_float, device=runtime.device))

    def _input_array(self, name):
        """(the solver's input ``name`` as a numpy array (B, W), a memo dict for answers about it),
        kept while the input is the same tensor (inputs are never changed in place: every setter
        makes a new one): a control call every step reads the modes, and the targets it zeroes,
        ~3 µs each."""
        tensor = self._sim().inputs(self._solver)[name]
        held = self._inputs_held.get(name)
        if held is None or held[0] is not tensor:
            held = self._inputs_held[name] = (tensor, tensor.detach().cpu().numpy(), {})
        return held[1], held[2]

    def _holds_zeros(self, name, columns, envs):
        """The input ``name`` is 0 at (envs, columns) and no graph stands behind it."""
        if self._sim().inputs(self._solver)[name].requires_grad:
            return False
        held, memo = self._input_array(name)
        if "zero" not in memo:
            memo["zero"] = not held.any()
        return memo["zero"] or not held[envs[:, None], columns].any()  # (the first test is cheaper)

    def control_dofs_force(self, force, dofs_idx_local=None, envs_idx=None):
        """Apply joint forces (N·m or N) during the next steps, until changed; clipped to the force
        range (set_dofs_force_range). Differentiable: a clipped command gets no gradient, one
        exactly on its bound none either (the derivative from outside; step inside to optimise)."""
        self._control("control_dofs_force", "force", {"ctrl_force": (force, "force")}, dofs_idx_local, envs_idx)

    def control_dofs_position(self, position, dofs_idx_local=None, envs_idx=None):
        """PD servo to target positions (rad or m) at rest: τ = kp·(target − q) − kv·q̇, clipped to
        the force range. A free or ball joint's three rotation dofs take a target orientation as
        get_dofs_position gives it (intrinsic X-Y-Z Euler angles), all three together, and
        target − q is the rotation vector of the turn from the joint's orientation to it, in the
        joint's axes (Genesis's free joint the same; its ball joint takes each Euler angle's
        difference)."""
        self._control("control_dofs_position", "position", {"ctrl_pos": (position, "position"),
                                                            "ctrl_vel": (None, "velocity")}, dofs_idx_local, envs_idx)

    def control_dofs_position_velocity(self, position, velocity, dofs_idx_local=None, envs_idx=None):
        """PD servo to target positions (rad or m) and velocities (rad/s or m/s):
        τ = kp·(position − q) + kv·(velocity − q̇), clipped to the force range."""
        self._control("control_dofs_position_velocity", "position",
                      {"ctrl_pos": (position, "position"), "ctrl_vel": (velocity, "velocity")},
                      dofs_idx_local, envs_idx)

    def control_dofs_velocity(self, velocity, dofs_idx_local=None, envs_idx=None):
        """Velocity servo to target velocities (rad/s or m/s): τ = kv·(target − q̇), clipped to the
        force range."""
        self._control("control_dofs_velocity", "velocity", {"ctrl_vel": (velocity, "velocity")}, dofs_idx_local,
                      envs_idx)

    def get_dofs_control_force(self, dofs_idx_local=None, envs_idx=None):
        """The actuator force, N·m or N: (n,) or (n_envs, n), as Genesis computes it: each dof's
        command recomputed from the current state and targets, clipped to the force range — force
        mode: the command; velocity: kv·(v* − q̇); position: kp·(q* − q) + kv·(v* − q̇). No damping
        or gravity (get_dofs_force has them), no constraint forces. Differentiable."""
        dofs = self._local(dofs_idx_local, self.n_dofs, "dofs_idx_local")
        columns = self.dof_start + dofs
        read = {name: self._read_input(name, columns, envs_idx) for name in
                ("ctrl_mode", "ctrl_force", "ctrl_vel", "kp", "kv", "force_lo", "force_hi")}
        error = self._servo_error(envs_idx)[:, torch.as_tensor(dofs, device=runtime.device)]
        qd = self._read(self._vel_columns(dofs), envs_idx)
        servo = read["kv"] * (read["ctrl_vel"] - qd)
        mode = read["ctrl_mode"]
        force = torch.where(mode == _MODES["position"], read["kp"] * error + servo,
                            torch.where(mode == _MODES["velocity"], servo, read["ctrl_force"]))
        lo, hi = read["force_lo"], read["force_hi"]
        # a force on its bound is the bound, in its gradient too (the step's convention, actuation.py)
        return self._out(torch.where((lo < force) & (force < hi), force, torch.where(force <= lo, lo, hi)))

    def _servo_error(self, envs_idx):
        """(B', n_dofs) what each dof's position servo pulls by (solvers/rigid/actuation.py):
        target − q; a free or ball joint's rotation dofs: the rotation vector of q⁻¹ ⊗ q*, q* the
        quaternion of their three targets (Euler angles), in the joint's axes."""
        target = self._read_input("ctrl_pos", self.dof_start + np.arange(self.n_dofs), envs_idx)
        qpos = self._read(self._qpos_columns(), envs_idx)
        # each dof's q column (a turn's: column 0, replaced below)
        error = target - qpos[:, torch.as_tensor(np.maximum(self._dof_q - self.q_start, 0), device=runtime.device)]
        if not self._turns:
            return error
        pieces, done = [], 0
        for dof, q in self._turns:
            quat = qpos[:, q: q + 4] / qpos[:, q: q + 4].norm(dim=1, keepdim=True)
            turn = quat_mul(quat * quat.new_tensor([1.0, -1.0, -1.0, -1.0]), euler_xyz_to_quat(target[:, dof: dof + 3]))
            pieces += [error[:, done: dof], rotation_vector(turn)]
            done = dof + 3
        return torch.cat(pieces + [error[:, done:]], dim=1)

    # -- dynamics queries ---------------------------------------------------------------------------
    def get_dofs_force(self, dofs_idx_local=None, envs_idx=None):
        """Generalised force on the dofs in the last step's last substep, N·m or N: (n,) or
        (n_envs, n), as Genesis 1.4.5's: clipped actuator force − damping·q̇ − the joint springs'
        stiffness·(q − springref) (a ball joint's stiffness·r) + the fixed tendons' springs and
        dampers (MJCF) − bias (gravity less its compensation,
        Coriolis, centrifugal) at that substep's start, + the MPM particles' push on coupled shapes of
        moving links (solvers/coupler.py), plus the constraint forces (joint limits, friction loss,
        contacts) of its solve (MuJoCo's qfrc_smooth + qfrc_constraint): a body resting on the ground
        feels none. Zeros in an env
        before its first step and after a reset or setter replaced its state. Not differentiable."""
        return self._last_step_dofs(self._sim().dofs_force(self._solver), dofs_idx_local, envs_idx)

    def get_dofs_acc(self, dofs_idx_local=None, envs_idx=None):
        """Accelerations the last step's last substep integrated, rad/s² or m/s²: (n,) or
        (n_envs, n), as Genesis 1.4.5's: q̇' = q̇ + h·q̈ (a free joint's as its velocities: world
        linear, body-frame angular), joint damping and servo kv implicit in it (MuJoCo's qacc
        leaves its Euler integrator's implicit damping out: equal where no dof is damped). Zeros
        in an env before its first step and after a reset or setter replaced its state. Not
        differentiable (the next state's velocity carries it)."""
        return self._last_step_dofs(self._sim().dofs_acc(self._solver), dofs_idx_local, envs_idx)

    def get_links_acc(self, links_idx_local=None, envs_idx=None, *, relative=True):
        """Classical linear acceleration of each link's origin, world frame, m/s²: (n, 3) or
        (n_envs, n, 3), as Genesis's, in the last step's last substep (the state it started from and
        the acceleration it integrated, as get_dofs_acc's: with joint damping the implicitly damped
        one; gravity not in it: a body at rest reads 0, a falling one g).
        relative: Genesis's choice between the authored link origin and its solver's internal one;
        ours are one, so both read the same. Zeros in an env before its first step and after a reset
        or setter replaced its state. Not differentiable."""
        check_bool(f"entity '{self.name}': get_links_acc", "relative", relative)
        return self._links_acc("get_links_acc", links_idx_local, envs_idx, slice(0, 3))

    def get_links_acc_ang(self, links_idx_local=None, envs_idx=None):
        """Angular acceleration of each link, world frame, rad/s²: (n, 3) or (n_envs, n, 3), as
        Genesis's, in the last step's last substep (as get_links_acc). Not differentiable."""
        return self._links_acc("get_links_acc_ang", links_idx_local, envs_idx, slice(3, 6))

    def _links_acc(self, what, links_idx_local, envs_idx, part):
        links = self._local(links_idx_local, self.n_links, "links_idx_local")
        full = self._sim().links_acc(self._solver, what)
        envs = torch.as_tensor(self._envs(envs_idx), device=runtime.device)
        return self._out(full[envs][:, torch.as_tensor(self.link_start + links, device=runtime.device), part])

    def _last_step_dofs(self, full, dofs_idx_local, envs_idx):
        """The entity's columns ``dofs_idx_local`` and rows ``envs_idx`` of a (B, D) readout."""
        dofs = self._local(dofs_idx_local, self.n_dofs, "dofs_idx_local")
        envs = torch.as_tensor(self._envs(envs_idx), device=runtime.device)
        return self._out(full[envs][:, torch.as_tensor(self.dof_start + dofs, device=runtime.device)])

    def get_mass_mat(self, envs_idx=None, decompose=False):
        """Joint-space mass matrix M with armature on its diagonal (as in Genesis), kg·m² or kg:
        (n_dofs, n_dofs) or (n_envs, n_dofs, n_dofs); Genesis also adds dt·damping and dt·kv there
        after a step, ours never. decompose: (L, D_inv) instead, L (…, n, n) unit lower triangular
        and D_inv (…, n) such that M = Lᵀ·diag(1 / D_inv)·L. Not differentiable."""
        check_bool(self._who, "decompose", decompose)
        full = self._sim().mass_matrix(self._solver)  # (its backward raises)
        envs = self._envs(envs_idx)
        mass = full if is_range(envs, full.shape[0]) else full[torch.as_tensor(envs, device=runtime.device)]
        if self.n_dofs != full.shape[1]:
            block = slice(self.dof_start, self.dof_start + self.n_dofs)
            mass = mass[:, block, block].contiguous()
        if not decompose:
            return self._out(mass)
        lower, d_inv = _ltdl(mass, self.name)
        return self._out(lower), self._out(d_inv)

    def __repr__(self):
        return f"{type(self).__name__}({self.name!r}, n_links={len(self._specs)})"
