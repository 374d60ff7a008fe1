"""A rigid entity's point Jacobian and inverse kinematics (Genesis's ``get_jacobian`` and
``inverse_kinematics``): the Jacobian in torch over the solver's link poses, inverse
kinematics in one kernel (solvers/rigid/ik.py) given the arrays made here.

The Jacobian maps the entity's dof velocities (``get_dofs_velocity``'s convention, MuJoCo's: a
free joint moves along the world axes, then turns about its own axes) to the linear velocity of a
point fixed on a link (rows 0–2, m/s) and the link's angular velocity (rows 3–5, rad/s), both in
the world frame. Column i is dof i's motion: a revolute dof's world axis a turns the point at
x about the joint's origin o (a × (x − o) and a), a prismatic dof moves it along a (a and 0);
dofs not on the link's path to the root are zero. It is built from get_links_pos and
get_links_quat, so it is differentiable wherever they are.

Inverse kinematics is damped least squares (Genesis's method and rules): from the start q, repeat
q ← q + Jᵀ (J Jᵀ + λ² I)⁻¹ r, r the masked errors (position in the world, rotation vector in the
link's frame), each step's components within ±max_step_size, the scalar joints clipped to their
limits (a ball joint turns about its own axes, its cone limit not a goal: the step's rows push it
back); from another start drawn inside the limits when one does not converge (only with limits
respected; ball joints start again where they were). Only the dofs given that move a goal's link
take part. The poses come from the solver's own kinematics at each trial q, in the frame the link
getters use, so the trial q never becomes the scene's state; a mimic joint's
equality is not a goal (the solve may part a Panda's fingers: they meet again in the next steps).
"""
import numpy as np
import torch

from ..solvers.core import InvalidInputError, runtime
from ..solvers.rigid import ik
from ..solvers.rigid.model import REVOLUTE
from ..utils.rotations import rotate


class DofMotions:
    """What the columns of an entity's Jacobian are made of (numpy, per local dof): the local link
    it moves, its axis (in that link's frame, or the world's for a free joint's translations), and
    whether it turns (revolute, a free joint's rotations, a ball joint's) or slides. Made once per
    entity at build (entity._dof_motions); the torch copies and path masks are kept as asked."""

    def __init__(self, entity):
        model = entity._solver.model
        links = model.dof_link[entity.dof_start + np.arange(entity.n_dofs)]
        self.link = links - entity.link_start
        self.axis = model.link_axis[links].astype(np.float64)
        self.turns = model.link_jtype[links] == REVOLUTE
        self.in_world = np.zeros(entity.n_dofs, dtype=bool)
        for dof, _ in entity._free_joints:  # MuJoCo's free joint: world translations, then turns about its axes
            self.axis[dof: dof + 3] = np.eye(3)
            self.turns[dof: dof + 3], self.in_world[dof: dof + 3] = False, True
        for dof, _ in entity._turns:  # a free or ball joint's turns about the link's own axes
            self.axis[dof: dof + 3], self.turns[dof: dof + 3] = np.eye(3), True
        self.parent = model.link_parent[entity.link_start: entity.link_start + entity.n_links] - entity.link_start
        self._paths, self._tensors = {}, {}

    def on_path(self, link):
        """(n_dofs,) bool: the dofs on the path from local link ``link`` to the root."""
        if link not in self._paths:
            path, l = set(), link
            while l >= 0:
                path.add(l)
                l = self.parent[l]
            self._paths[link] = np.isin(self.link, list(path))
        return self._paths[link]

    def tensors(self, dtype, device, link):
        """(axis (n, 3), in_world (n, 1), turns (n, 1), the path mask of local link ``link`` (n, 1))
        as torch tensors of ``dtype`` on ``device``."""
        key = (dtype, device, link)
        if key not in self._tensors:
            self._tensors[key] = (torch.as_tensor(self.axis, dtype=dtype, device=device),
                                  torch.as_tensor(self.in_world, device=device)[:, None],
                                  torch.as_tensor(self.turns, device=device)[:, None],
                                  torch.as_tensor(self.on_path(link), dtype=dtype, device=device)[:, None])
        return self._tensors[key]


def jacobian(motions, pos, quat, link, local_point):
    """(..., 6, n_dofs) Jacobian of the point ``local_point`` (3,) of local link ``link``, given
    every link's world pose pos (..., L, 3), quat (..., L, 4)."""
    axis, in_world, turns, mask = motions.tensors(pos.dtype, pos.device, link)
    point = pos[..., link, :] + rotate(quat[..., link, :], local_point)
    world_axis = torch.where(in_world, axis, rotate(quat[..., motions.link, :], axis))
    lever = point[..., None, :] - pos[..., motions.link, :]
    linear = torch.where(turns, torch.linalg.cross(world_axis, lever), world_axis)
    angular = torch.where(turns, world_axis, torch.zeros_like(world_axis))
    return torch.cat([linear * mask, angular * mask], dim=-1).transpose(-1, -2)


class Target:
    """One goal of inverse_kinematics: local link ``link``'s point ``point`` (3,) at ``pos``
    (B', 3) and the link turned to ``quat`` (B', 4) (None: not asked), with the masks of the error
    components that count: position along the world axes, rotation about the link's own axes;
    one rotation axis given means that axis of the link is to be aligned with the target's, so the
    two others are the components kept (Genesis's rule)."""

    def __init__(self, link, point, pos, quat, pos_mask, rot_mask):
        self.link, self.point, self.pos, self.quat = link, point, pos, quat
        rot_mask = list(rot_mask)
        if sum(rot_mask) == 1:
            rot_mask = [not keep for keep in rot_mask]
        self.mask = torch.tensor([*pos_mask, *rot_mask], dtype=runtime.tc_float, device=runtime.device)
        if pos is None:
            self.mask[:3] = 0.0
        if quat is None:
            self.mask[3:] = 0.0


class _Joints:
    """The solve's view of the entity's qpos: the qs of its scalar dofs, their limits (rad or m;
    each env's of ``envs``, as set_dofs_limit left them) when respected, and which of them move
    (``moving``: local dofs given and on the path of a goal's link; only they step, are clipped and
    are drawn again)."""

    def __init__(self, entity, respect_limits, moving, envs):
        model = entity._solver.model
        self.free = entity._free_joints  # (first local dof, first local q) of each free joint
        self.turns = entity._turns  # and of each joint's rotation stored as a quaternion (free, ball)
        self.dofs = np.flatnonzero(~np.isin(np.arange(entity.n_dofs), entity._quat_joint_dofs))
        dofs = entity.dof_start + self.dofs
        self.qs = model.dof_q[dofs] - entity.q_start
        self.limited = respect_limits
        device = runtime.device
        inputs = entity._sim().inputs(entity._solver)
        rows, columns = (torch.as_tensor(index, device=device) for index in (envs, dofs))
        self.lower, self.upper = (inputs[name][rows][:, columns].detach() for name in ("limit_lower", "limit_upper"))
        self.moving = torch.as_tensor(moving[self.dofs], device=device)
        self.revolute = torch.as_tensor(model.link_jtype[model.dof_link[dofs]] == REVOLUTE, device=device)
        # the kernel's joints (ik.py): (kind, local dof, local q, index among the scalar ones)
        self.table = ([[ik.FREE_MOVE, dof, q, -1] for dof, q in self.free] + [[ik.TURN, dof, q, -1] for dof, q in self.turns]
                      + [[ik.SCALAR, dof, q, k] for k, (dof, q) in enumerate(zip(self.dofs.tolist(), self.qs.tolist()))])
        self.limits = torch.stack([self.lower, self.upper], -1)  # (B', scalar dofs, 2)

    def clipped(self, q):
        """q with its moving scalar joints within their limits (when respected)."""
        if not self.limited:
            return q
        q = q.clone()
        inside = torch.maximum(torch.minimum(q[:, self.qs], self.upper), self.lower)
        q[:, self.qs] = torch.where(self.moving, inside, q[:, self.qs])
        return q

    def samples(self, q, generator, count):
        """(count, B', n_qs): q (within the limits) with its moving scalar joints drawn uniformly
        within their limits: a revolute joint limited on one side within a turn from that limit,
        one without limits in [−π, π]; a prismatic one not limited on both sides keeps its value."""
        has_lower, has_upper = torch.isfinite(self.lower), torch.isfinite(self.upper)
        lower = torch.where(has_lower, self.lower, torch.where(has_upper, self.upper - 2.0 * np.pi, -np.pi))
        upper = torch.where(has_upper, self.upper, torch.where(has_lower, self.lower + 2.0 * np.pi, np.pi))
        draw = lower + torch.rand(count, q.shape[0], len(self.qs), generator=generator, dtype=q.dtype).to(q.device) * (
            upper - lower)
        out = self.clipped(q).expand(count, *q.shape).clone()
        drawn = self.moving & ((has_lower & has_upper) | self.revolute)
        out[..., self.qs] = torch.where(drawn, draw, out[..., self.qs])
        return out


def checked_mask(mask, name, who):
    """A mask of 3 booleans, as a list."""
    values = list(mask) if isinstance(mask, (list, tuple, np.ndarray, torch.Tensor)) else None
    if values is None or len(values) != 3 or not all(isinstance(v, (bool, np.bool_)) or v in (0, 1) for v in values):
        raise InvalidInputError(f"{who} argument '{name}' must be 3 booleans, got {mask!r}")
    return [bool(v) for v in values]


def checked_options(who, **given):
    """The solve's options, checked: limits respected or not (a bool), at least one sample,
    iterations ≥ 0, damping and step size > 0, tolerances ≥ 0, a seed int or None."""
    counts = {"max_samples": 1, "max_solver_iters": 0}
    for name, least in counts.items():
        value = given[name]
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < least:
            raise InvalidInputError(f"{who} argument '{name}' must be an integer >= {least}, got {value!r}")
    for name, positive in (("damping", True), ("max_step_size", True), ("pos_tol", False), ("rot_tol", False)):
        value = given[name]
        ok = isinstance(value, (int, float, np.floating)) and not isinstance(value, bool) and np.isfinite(value) \
            and (value > 0 if positive else value >= 0)
        if not ok:
            raise InvalidInputError(f"{who} argument '{name}' must be a finite number {'> 0' if positive else '>= 0'}, "
                                    f"got {value!r}")
    if not isinstance(given["respect_joint_limit"], (bool, np.bool_)):
        raise InvalidInputError(f"{who} argument 'respect_joint_limit' must be a bool, got "
                                f"{given['respect_joint_limit']!r}")
    seed = given["seed"]
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer))):
        raise InvalidInputError(f"{who} argument 'seed' must be an integer or None, got {seed!r}")
    return {name: (float(v) if name in ("damping", "max_step_size", "pos_tol", "rot_tol") else v)
            for name, v in given.items()}


def solve_ik(entity, goals, start, envs, dofs, options):
    """Damped least squares from ``start`` (B', n_qs) in the selected envs ``envs`` (int array),
    moving the local dofs ``dofs`` (those on the goals' links' paths), toward every Target of
    ``goals``, their errors and Jacobian rows stacked; each step scaled so that no component
    exceeds max_step_size. Genesis's rule, per env: a sample runs up to max_solver_iters steps
    and stops where every goal is within pos_tol and rot_tol (that qpos is the answer); else its
    last qpos becomes the best where no goal's position or rotation error is worse than the best
    one's (the first sample's always), and the next sample starts from a qpos drawn within the
    limits where they are respected, else from where the last one ended. One kernel runs it all
    (solvers/rigid/ik.py), the starts drawn beforehand.
    options: respect_joint_limit, max_samples, max_solver_iters, damping, pos_tol, rot_tol,
    max_step_size, seed. Returns (the best qpos (B', n_qs), its errors (B', K, 6))."""
    motions = entity._dof_motions
    on_path = np.logical_or.reduce([motions.on_path(target.link) for target in goals])
    moving = on_path & np.isin(np.arange(entity.n_dofs), dofs)
    joints = _Joints(entity, options["respect_joint_limit"], moving, envs)
    generator = torch.Generator().manual_seed(0 if options["seed"] is None else int(options["seed"]))
    samples = options["max_samples"]
    starts = torch.cat([joints.clipped(start)[None], joints.samples(start, generator, samples - 1)]) \
        if joints.limited else start[None]
    rows, K, D = len(envs), len(goals), entity.n_dofs
    solver = entity._solver
    ints = lambda values: torch.tensor(values, dtype=torch.int32, device=start.device)  # noqa: E731
    floats = lambda *shape: torch.zeros(shape, dtype=start.dtype, device=start.device)  # noqa: E731
    # one env's frame holds one row's trial poses: an env met twice takes its rows in turn; else the
    # rows go to the thread pool from two on (a row's solve outweighs a hand-off, unlike a link's substep)
    serial = rows < 2 or len(np.unique(envs)) < rows
    sizes = ints([entity.q_start, entity.dof_start, entity.link_start, entity.link_start + entity.n_links, samples,
                  options["max_solver_iters"], int(joints.limited), 1 if serial else max(1, 1024 // rows),
                  len(joints.table)])
    spec = torch.cat([torch.stack([target.point.to(start.dtype) for target in goals]),
                      torch.stack([target.mask.to(start.dtype) for target in goals])], 1).contiguous()
    identity = torch.tensor([1.0, 0.0, 0.0, 0.0], dtype=start.dtype, device=start.device)
    targets = torch.stack([torch.cat([floats(rows, 3) if target.pos is None else target.pos.to(start.dtype),
                                      identity.expand(rows, 4) if target.quat is None else target.quat.to(start.dtype)],
                                     1) for target in goals], 1).contiguous()
    options_array = torch.tensor([options["damping"], options["pos_tol"], options["rot_tol"], options["max_step_size"]],
                                 dtype=start.dtype, device=start.device)
    best_q, best_err = floats(rows, entity.n_qs), floats(rows, K, 6)
    arrays = (ints(envs), sizes, ints(joints.table).reshape(-1, 4), joints.limits.contiguous(), ints(moving),
              ints([entity.link_start + target.link for target in goals]), spec, targets, starts.contiguous(),
              options_array, floats(rows, 6 * K, D), floats(rows, 6 * K, 6 * K), floats(rows, 6 * K, 2),
              floats(rows, entity.n_qs), floats(rows, D), best_q, best_err)
    entity._sim().at_state(solver, lambda: solver.inverse_kinematics(serial, *arrays))
    return best_q, best_err
