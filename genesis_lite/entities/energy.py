"""A rigid entity's mechanical energy (Genesis's ``get_kinetic_energy``, ``get_potential_energy``
and ``get_total_energy``), in torch over the solver's link states and the entity's inputs, so it is
differentiable wherever they are.

Kinetic: Σ ½ m |v_c|² + ½ ωᵀ I_c ω over the links (v_c the velocity of the link's centre of mass,
I_c its inertia about it in world axes: the input inertia, turned, as the step's) plus
Σ ½ armature · q̇² over the dofs (the rotors): MuJoCo's ½ q̇ᵀ M q̇, armature on M's diagonal.
Potential: −Σ m g · p_c over the links that move (a link welded to the world adds a constant, left
out as Genesis leaves it out) plus Σ ½ stiffness (q − springref)² over the joint springs (a ball
joint's: Σ_a ½ stiffness_a r_a², r the rotation vector of its turn, MuJoCo's) and Σ ½ k x² over
the fixed tendons' springs (x: the length's distance from its rest range, MuJoCo's).
"""
import numpy as np
import torch

from ..solvers.core import runtime
from ..utils.rotations import quat_to_mat, rotation_vector


def _links(entity, envs_idx):
    """(mass (B', L) kg, centre-of-mass position (B', L, 3) m, its velocity (B', L, 3) m/s, angular
    velocity (B', L, 3) rad/s, world rotation (B', L, 3, 3)) of the entity's links."""
    state = entity._links(None, envs_idx, slice(0, 13))
    pos, rot, ang, vel = state[..., :3], quat_to_mat(state[..., 3:7]), state[..., 7:10], state[..., 10:13]
    links = entity.link_start + np.arange(entity.n_links)
    lever = (rot @ entity._links_com(np.arange(entity.n_links), envs_idx)[..., None])[..., 0]
    mass = entity._read_input("mass", links, envs_idx)
    return mass, pos + lever, vel + torch.linalg.cross(ang, lever), ang, rot


def kinetic(entity, envs_idx):
    """(B',) J: the entity's kinetic energy."""
    mass, _, com_vel, ang, rot = _links(entity, envs_idx)
    inertia = rot @ entity._links_inertia(np.arange(entity.n_links), envs_idx) @ rot.transpose(-1, -2)
    spin = (ang[..., None, :] @ inertia @ ang[..., :, None])[..., 0, 0]
    dofs = np.arange(entity.n_dofs)
    armature = entity._read_input("armature", entity.dof_start + dofs, envs_idx)
    qd = entity._read(entity._vel_columns(dofs), envs_idx)
    return 0.5 * ((mass * (com_vel ** 2).sum(-1) + spin).sum(-1) + (armature * qd ** 2).sum(-1))


def potential(entity, envs_idx):
    """(B',) J: the entity's gravitational energy (links that move) and its joint springs'."""
    mass, com_pos, _, _, _ = _links(entity, envs_idx)
    model = entity._solver.model
    moving = torch.as_tensor(model.link_static[entity.link_start + np.arange(entity.n_links)] == 0,
                             device=runtime.device)
    gravity = entity._read_input("gravity", np.arange(3), envs_idx)
    height = -(mass * moving * (com_pos * gravity[:, None, :]).sum(-1)).sum(-1)
    dofs = entity.dof_start + np.flatnonzero(~np.isin(np.arange(entity.n_dofs), entity._quat_joint_dofs))
    q = entity._read(model.dof_q[dofs], envs_idx)  # the scalar joints' (a ball joint's spring below; a free one has none)
    stiffness = entity._read_input("stiffness", dofs, envs_idx)
    rest = torch.as_tensor(model.dof_springref[dofs], dtype=q.dtype, device=q.device)
    springs = 0.5 * (stiffness * (q - rest) ** 2).sum(-1)
    for dof, first in entity._ball_joints:
        quat = entity._read(entity._solver_q(first + np.arange(4)), envs_idx)
        turn = rotation_vector(quat / quat.norm(dim=-1, keepdim=True))
        springs = springs + 0.5 * (entity._read_input("stiffness", entity.dof_start + dof + np.arange(3), envs_idx)
                                   * turn ** 2).sum(-1)
    return height + springs + _tendon_springs(entity, envs_idx)


def _tendon_springs(entity, envs_idx):
    """(B',) J: Σ ½ k x² over the entity's sprung fixed tendons, x = L − clamp(L, rest lower, rest
    upper), L = Σ c_j q_j."""
    model = entity._solver.model
    mine = (model.ten_dof[:, 0] >= entity.dof_start) & (model.ten_dof[:, 0] < entity.dof_start + entity.n_dofs)
    tendons = np.flatnonzero(mine & (model.ten_stiffness != 0))
    if not len(tendons):
        return 0.0
    coef = torch.as_tensor(model.ten_coef[tendons], device=runtime.device)  # (T', 3), 0 past a tendon's joints
    columns = np.maximum(model.dof_q[model.ten_dof[tendons]], 0)  # (a padding slot's column, its coef 0)
    q = entity._read(columns.reshape(-1), envs_idx).reshape(-1, *coef.shape)
    length = (coef.to(q.dtype) * q).sum(-1)
    rest = torch.as_tensor(model.ten_spring[tendons], dtype=q.dtype, device=q.device)
    stretch = length - torch.minimum(torch.maximum(length, rest[:, 0]), rest[:, 1])
    stiffness = torch.as_tensor(model.ten_stiffness[tendons], dtype=q.dtype, device=q.device)
    return 0.5 * (stiffness * stretch ** 2).sum(-1)
