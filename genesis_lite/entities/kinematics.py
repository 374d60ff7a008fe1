"""A rigid entity's point Jacobian and inverse kinematics (Genesis's ``get_jacobian`` and
``inverse_kinematics``), in torch over the solver's link poses.

The Jacobian maps the entity's dof velocities (``get_dofs_velocity``'s convention, MuJoCo's: a
free base moves along the world axes, then turns about its own axes) to the linear velocity of a
point fixed on a link (rows 0–2, m/s) and the link's angular velocity (rows 3–5, rad/s), both in
the world frame. Column i is dof i's motion: a revolute dof's world axis a turns the point at
x about the joint's origin o (a × (x − o) and a), a prismatic dof moves it along a (a and 0);
dofs not on the link's path to the root are zero. It is built from get_links_pos and
get_links_quat, so it is differentiable wherever they are.

Inverse kinematics is damped least squares (Genesis's method): from the start q, repeat
q ← q + Jᵀ (J Jᵀ + λ² I)⁻¹ r, r the masked (position, rotation-vector) error, each step at most
max_step_size long and clipped to the joint limits; from another start drawn inside the limits
when a start does not converge. The poses come from the solver's own kinematics at each trial q,
which never becomes the scene's state.
"""
import numpy as np
import torch

from ..solvers.core import runtime
from ..solvers.rigid.model import REVOLUTE
from .rotations import quat_mul, quat_to_mat, rotation_vector


class DofMotions:
    """What the columns of an entity's Jacobian are made of (numpy, per local dof): the local link
    it moves, its axis (in that link's frame, or the world's for a free base's translations), and
    whether it turns (revolute, a free base's rotations) or slides."""

    def __init__(self, entity):
        model = entity._solver.model
        links = model.dof_link[entity.dof_start + np.arange(entity.n_dofs)]
        self.link = links - entity.link_start
        self.axis = model.link_axis[links].astype(np.float64)
        self.turns = model.link_jtype[links] == REVOLUTE
        self.in_world = np.zeros(entity.n_dofs, dtype=bool)
        if entity.is_free:  # MuJoCo's free joint: world translations, then turns about the body's axes
            self.axis[:6] = np.vstack([np.eye(3), np.eye(3)])
            self.turns[:6], self.in_world[:3] = [False] * 3 + [True] * 3, True
        self.parent = model.link_parent[entity.link_start: entity.link_start + entity.n_links] - entity.link_start

    def on_path(self, link):
        """(n_dofs,) bool: the dofs on the path from local link ``link`` to the root."""
        path, l = set(), link
        while l >= 0:
            path.add(l)
            l = self.parent[l]
        return np.isin(self.link, list(path))


def jacobian(motions, pos, quat, link, local_point):
    """(..., 6, n_dofs) Jacobian of the point ``local_point`` (3,) of local link ``link``, given
    every link's world pose pos (..., L, 3), quat (..., L, 4)."""
    rot = quat_to_mat(quat)
    point = pos[..., link, :] + (rot[..., link, :, :] @ local_point[:, None])[..., 0]
    axis = torch.as_tensor(motions.axis, dtype=pos.dtype, device=pos.device)
    link_rot = rot[..., motions.link, :, :]  # (..., n, 3, 3)
    world_axis = torch.where(torch.as_tensor(motions.in_world, device=pos.device)[:, None], axis,
                             (link_rot @ axis[:, :, None])[..., 0])
    turns = torch.as_tensor(motions.turns, device=pos.device)[:, None]
    lever = point[..., None, :] - pos[..., motions.link, :]
    linear = torch.where(turns, torch.linalg.cross(world_axis, lever), world_axis)
    angular = torch.where(turns, world_axis, torch.zeros_like(world_axis))
    mask = torch.as_tensor(motions.on_path(link), dtype=pos.dtype, device=pos.device)[:, None]
    return torch.cat([linear * mask, angular * mask], dim=-1).transpose(-1, -2)


class Target:
    """inverse_kinematics' goal per selected env: position (B', 3) or None, quat (B', 4) or None,
    and the masks (6,) of the error components that count."""

    def __init__(self, pos, quat, pos_mask, rot_mask):
        self.pos, self.quat = pos, quat
        self.mask = torch.tensor([*pos_mask, *rot_mask], dtype=runtime.tc_float, device=runtime.device)
        if pos is None:
            self.mask[:3] = 0.0
        if quat is None:
            self.mask[3:] = 0.0

    def error(self, point, link_quat):
        """(B', 6) masked (position, rotation vector) from the link's pose to the goal, world frame."""
        out = torch.zeros(point.shape[0], 6, dtype=point.dtype, device=point.device)
        if self.pos is not None:
            out[:, :3] = self.pos - point
        if self.quat is not None:
            conjugate = link_quat * torch.tensor([1.0, -1.0, -1.0, -1.0], dtype=point.dtype, device=point.device)
            out[:, 3:] = rotation_vector(quat_mul(self.quat, conjugate))
        return out * self.mask


class _Joints:
    """The entity's qpos layout for the solve: the qs of its scalar dofs (scalar) and their
    limits, rad or m (±inf where none, or not respected)."""

    def __init__(self, entity, respect_limits):
        model = entity._solver.model
        dofs = entity.dof_start + np.arange(entity.n_dofs)
        first = 6 if entity.is_free else 0
        self.free = entity.is_free
        self.dofs = np.arange(first, entity.n_dofs)
        self.qs = model.dof_q[dofs[first:]] - entity.q_start
        device = runtime.device
        self.lower = torch.as_tensor(model.dof_lower[dofs[first:]], dtype=runtime.tc_float, device=device)
        self.upper = torch.as_tensor(model.dof_upper[dofs[first:]], dtype=runtime.tc_float, device=device)
        if not respect_limits:
            self.lower, self.upper = torch.full_like(self.lower, -np.inf), torch.full_like(self.upper, np.inf)

    def moved(self, q, step):
        """q (B', n_qs) moved by a dof-space step (B', n_dofs): a free base's position along the
        world axes and its quaternion turned about its own (q ⊗ exp(ω/2)), the scalar joints by
        theirs, clipped to the limits."""
        q = q.clone()
        if self.free:
            q[:, :3] += step[:, :3]
            half = step[:, 3:6] / 2
            angle = half.norm(dim=1, keepdim=True)
            turn = torch.cat([torch.cos(angle), half * torch.sinc(angle / np.pi)], dim=1)
            quat = quat_mul(q[:, 3:7], turn)
            q[:, 3:7] = quat / quat.norm(dim=1, keepdim=True)
        scalar = q[:, self.qs] + step[:, self.dofs]
        q[:, self.qs] = torch.maximum(torch.minimum(scalar, self.upper), self.lower)
        return q

    def sample(self, q, generator, moving):
        """q with its scalar joints among the local dofs ``moving`` (int array) drawn uniformly
        within their limits ([−π, π] where unlimited)."""
        lower = torch.where(torch.isfinite(self.lower), self.lower, -np.pi)
        upper = torch.where(torch.isfinite(self.upper), self.upper, np.pi)
        draw = lower + torch.rand(q.shape[0], len(self.qs), generator=generator, dtype=q.dtype).to(q.device) * (
            upper - lower)
        drawn = torch.as_tensor(np.isin(self.dofs, moving), device=q.device)
        q = q.clone()
        q[:, self.qs] = torch.where(drawn, draw, q[:, self.qs])
        return q


def _poses_at(entity, q, envs):
    """World poses (pos (B', L, 3), quat (B', L, 4)) of the entity's links with its qpos at q
    (B', n_qs) in envs, from the solver's kinematics; the scene's state is not changed."""
    sim = entity._sim()
    state = sim.state(entity._solver).detach().clone()
    rows = torch.as_tensor(envs, device=state.device)
    state[rows[:, None], torch.as_tensor(entity._qpos_columns(), device=state.device)] = q
    links = sim.kinematics_at(entity._solver, state)[rows, entity.link_start: entity.link_start + entity.n_links]
    return links[..., 0:3], links[..., 3:7]


def _norms(error):
    """(B', 2): the largest position and rotation error over the goals, of errors (B', K, 6)."""
    return torch.stack([error[..., :3].norm(dim=-1).amax(-1), error[..., 3:].norm(dim=-1).amax(-1)], -1)


def solve_ik(entity, goals, start, envs, dofs, options):
    """Damped least squares from ``start`` (B', n_qs) in the selected envs ``envs`` (int array),
    moving the local dofs ``dofs``, toward every goal of ``goals``: (local link, Target, local
    point (3,)) each, their errors and Jacobians stacked. options: respect_joint_limit,
    max_samples, max_solver_iters, damping, pos_tol, rot_tol, max_step_size, seed. Returns (the
    best qpos (B', n_qs) each env reached, its errors (B', K, 6))."""
    motions, joints = DofMotions(entity), _Joints(entity, options["respect_joint_limit"])
    generator = torch.Generator().manual_seed(0 if options["seed"] is None else int(options["seed"]))
    moving = torch.zeros(entity.n_dofs, dtype=start.dtype, device=start.device)
    moving[torch.as_tensor(dofs, device=start.device)] = 1.0
    eye = torch.eye(6 * len(goals), dtype=start.dtype, device=start.device)
    q, best_q, best_error = start.clone(), start.clone(), None
    for _ in range(options["max_samples"]):
        for _ in range(options["max_solver_iters"] + 1):
            pos, quat = _poses_at(entity, q, envs)
            error = torch.stack([target.error(pos[:, link] + (quat_to_mat(quat[:, link]) @ point[:, None])[..., 0],
                                              quat[:, link]) for link, target, point in goals], 1)
            if best_error is None:
                best_error = error
            better = _norms(error).sum(1) < _norms(best_error).sum(1)
            best_q[better], best_error[better] = q[better], error[better]
            norms = _norms(best_error)
            done = (norms[:, 0] <= options["pos_tol"]) & (norms[:, 1] <= options["rot_tol"])
            if bool(done.all()):
                return best_q, best_error
            J = torch.cat([jacobian(motions, pos, quat, link, point) * target.mask[:, None]
                           for link, target, point in goals], 1) * moving
            residual = error.reshape(error.shape[0], -1, 1)
            step = (J.transpose(1, 2) @ torch.linalg.solve(J @ J.transpose(1, 2) + options["damping"] ** 2 * eye,
                                                           residual))[..., 0]
            step = step * (options["max_step_size"] / step.norm(dim=1, keepdim=True).clamp_min(options["max_step_size"]))
            q = joints.moved(q, step)
        q = torch.where(done[:, None], best_q, joints.sample(start, generator, dofs))
    return best_q, best_error
