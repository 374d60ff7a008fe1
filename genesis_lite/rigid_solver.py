"""Genesis's ``scene.sim.rigid_solver``: the solver-level calls genesis_lite has — the scene-wide
readouts (``n_links``, ``n_dofs``, ``n_qs``, ``get_links_pos/quat/vel/ang``, ``get_dofs_position/
velocity``, ``get_qpos``: the rigid entities' own readouts side by side, in scene-wide link, dof
and q order, so differentiable as theirs; ``get_error_envs_mask``) and welds made at run time
(Genesis's suction cup: ``add_weld_constraint`` / ``delete_weld_constraint``).

A run-time weld holds two links where they are when it is made: link 1's origin on the same point
of link 2, and their relative turn, by six equality rows (solvers/rigid/constraint/rows.py, as an
MJCF weld's, torquescale 1) stiff as MuJoCo lets a row be (time constant two substeps, Genesis's).
Each env has RigidOptions.max_dynamic_constraints slots; a weld is the rigid solver's input
``dyn_welds`` (solvers/rigid/data.py), so a differentiable rollout's backward replays each step
with the welds it had; a reset clears the welds of the envs it resets, as Genesis's does.
The held point is link 1's origin (Genesis's choice): a weld holds tightest with the link nearer
the other's origin as link 1 (a box welded as link 2 to a static link whose origin is 0.8 m
away sagged 3.9 cm in 0.2 s, as 1.7e-5 m the other way round; MuJoCo's weld alike).
Where a weld is made is taken from the state in the graph: a gradient reaches the state of that
step through the weld's anchor and turn as well as through its rows.
"""
import numpy as np
import torch

from .entities.common import EntityIndexing
from .solvers.core import InvalidInputError, runtime
from .solvers.rigid.data import DYN_WELD
from .tensor import wrap
from .utils.geom import inv_quat, inv_transform_by_trans_quat
from .utils.rotations import quat_mul


class RigidSolverView(EntityIndexing):
    """``scene.sim.rigid_solver`` of a built scene with rigid entities (Genesis's name)."""

    def __init__(self, scene):
        self.scene = scene
        self._solver = scene._rigid_solver

    @property
    def _who(self):
        return "scene.sim.rigid_solver"

    def __getattr__(self, name):
        # (only for names not found: Genesis's other solver-level calls say where to look)
        if name.startswith("_"):
            raise AttributeError(name)
        raise AttributeError(f"{self._who} has no '{name}' (its calls here: the scene-wide readouts "
                             f"get_links_pos/quat/vel/ang, get_dofs_position/velocity, get_qpos, "
                             f"get_error_envs_mask, and add_weld_constraint, delete_weld_constraint); "
                             f"Genesis's other solver-level calls are the entities' here (entity.set_dofs_kp..., "
                             f"scene-wide link and dof indices as link.idx, entity.dof_start): "
                             f"docs/genesis_api.md lists them")

    # -- scene-wide readouts: the rigid entities' side by side ---------------------------------------
    def _rigid_entities(self):
        return self.scene._rigid_entities()

    @property
    def n_links(self):
        return sum(entity.n_links for entity in self._rigid_entities())

    @property
    def n_dofs(self):
        return sum(entity.n_dofs for entity in self._rigid_entities())

    @property
    def n_qs(self):
        return sum(entity.n_qs for entity in self._rigid_entities())

    def _joined(self, getter, idx, n, arg, envs_idx, **options):
        """Every rigid entity's ``getter(None, envs_idx, **options)`` (…, n_k[, width]) joined
        along its entity axis (links: −2, dofs and qs: −1), then the scene-wide indices ``idx``
        (None: all)."""
        self._envs(envs_idx)  # (its errors name this solver)
        picked = self._local(idx, n, arg)
        parts = [getattr(entity, getter)(None, envs_idx, **options) for entity in self._rigid_entities()]
        axis = -2 if arg == "links_idx" else -1
        joined = torch.cat([part.as_subclass(torch.Tensor) for part in parts], dim=axis)
        index = torch.as_tensor(picked, device=joined.device)
        return wrap(joined.index_select(joined.dim() + axis, index), self.scene)

    def get_links_pos(self, links_idx=None, envs_idx=None, *, ref="link_origin", relative=True):
        """World positions of the links at ``ref`` (the entities' get_links_pos), m: (n, 3) or
        (n_envs, n, 3), scene-wide link indices (link.idx) ``links_idx`` (None: all)."""
        return self._joined("get_links_pos", links_idx, self.n_links, "links_idx", envs_idx, ref=ref,
                            relative=relative)

    def get_links_quat(self, links_idx=None, envs_idx=None):
        """World orientations (w, x, y, z): (n, 4) or (n_envs, n, 4)."""
        return self._joined("get_links_quat", links_idx, self.n_links, "links_idx", envs_idx)

    def get_links_vel(self, links_idx=None, envs_idx=None, *, ref="link_origin", relative=True):
        """World linear velocities of the links at ``ref`` (the entities' get_links_vel), m/s: (n, 3)
        or (n_envs, n, 3)."""
        return self._joined("get_links_vel", links_idx, self.n_links, "links_idx", envs_idx, ref=ref,
                            relative=relative)

    def get_links_ang(self, links_idx=None, envs_idx=None):
        """World angular velocities, rad/s: (n, 3) or (n_envs, n, 3)."""
        return self._joined("get_links_ang", links_idx, self.n_links, "links_idx", envs_idx)

    def get_dofs_position(self, dofs_idx=None, envs_idx=None):
        """Dof positions (rad or m; a free or ball joint's turn as Euler angles, as the entities'):
        (n,) or (n_envs, n), scene-wide dof indices (entity.dof_start + local)."""
        return self._joined("get_dofs_position", dofs_idx, self.n_dofs, "dofs_idx", envs_idx)

    def get_dofs_velocity(self, dofs_idx=None, envs_idx=None):
        """Dof velocities (rad/s or m/s): (n,) or (n_envs, n)."""
        return self._joined("get_dofs_velocity", dofs_idx, self.n_dofs, "dofs_idx", envs_idx)

    def get_qpos(self, qs_idx=None, envs_idx=None):
        """Generalised positions (n,) or (n_envs, n), scene-wide q indices."""
        return self._joined("get_qpos", qs_idx, self.n_qs, "qs_idx", envs_idx)

    def get_error_envs_mask(self):
        """(max(n_envs, 1),) bool: the envs whose rigid state is not finite (Genesis's mask of the
        envs in error, to reset)."""
        rows = [torch.cat([entity.get_qpos().as_subclass(torch.Tensor).detach(),
                           entity.get_dofs_velocity().as_subclass(torch.Tensor).detach()], dim=-1).reshape(
            max(self.scene.n_envs, 1), -1) for entity in self._rigid_entities()]
        return ~torch.isfinite(torch.cat(rows, dim=-1)).all(dim=-1)

    def add_weld_constraint(self, link1_idx, link2_idx, envs_idx=None):
        """Weld link ``link2_idx`` to link ``link1_idx`` (scene-wide link indices, Genesis's
        ``link.idx``) as they are now, in the envs ``envs_idx`` (None: every env): see the module.
        Refused (InvalidInputError) for one link twice, two links welded to the world, a pair
        already welded in a selected env, or an env without a free slot. No env selected: nothing."""
        links, envs, table = self._pair(link1_idx, link2_idx, envs_idx, "add_weld_constraint")
        if not len(envs):
            return
        welded = self._slots_of(table, envs, links) >= 0
        if welded.any():
            raise InvalidInputError(f"{self._who}.add_weld_constraint: links {links} are already welded in envs "
                                    f"{envs[welded].tolist()}; expected a pair not welded there")
        count = table[torch.as_tensor(envs, device=table.device), 0].detach().long()
        full = (count >= self._solver.rigid_options.max_dynamic_constraints).cpu().numpy()
        if full.any():
            raise InvalidInputError(f"{self._who}.add_weld_constraint: no free weld slot in envs "
                                    f"{envs[full].tolist()}: expected fewer than "
                                    f"RigidOptions(max_dynamic_constraints="
                                    f"{self._solver.rigid_options.max_dynamic_constraints}) welds there")
        # (in the graph when the state requires grad: where the weld is made depends on it)
        kinematics = self.scene.sim.derived(self._solver)[torch.as_tensor(envs, device=runtime.device)]
        (p1, q1), (p2, q2) = ((kinematics[:, link, :3], kinematics[:, link, 3:7]) for link in links)
        anchor2 = inv_transform_by_trans_quat(p1, p2, q2)  # link 1's origin, on link 2
        turn1 = quat_mul(inv_quat(q1), q2)  # link 2's frame in link 1's
        identity = torch.zeros_like(q2)
        identity[:, 0] = 1.0
        weld = torch.cat([torch.tensor(links).to(p1).expand(len(envs), 2), torch.zeros_like(p1), anchor2, turn1,
                          identity], dim=1)
        rows = torch.as_tensor(envs, device=table.device)
        columns = 1 + DYN_WELD * count[:, None] + torch.arange(DYN_WELD, device=table.device)
        table[rows[:, None], columns] = weld
        table[rows, 0] += 1.0
        self.scene.sim.set_input(self._solver, "dyn_welds", table)

    def delete_weld_constraint(self, link1_idx, link2_idx, envs_idx=None):
        """Remove the weld of the two links (either order) in the envs ``envs_idx`` (None: every
        env); the env's last weld takes its slot (Genesis's order of rows). Refused
        (InvalidInputError) where the pair is not welded (Genesis passes over such an env)."""
        links, envs, table = self._pair(link1_idx, link2_idx, envs_idx, "delete_weld_constraint")
        if not len(envs):
            return
        slots = self._slots_of(table, envs, links)
        if (slots < 0).any():
            raise InvalidInputError(f"{self._who}.delete_weld_constraint: links {links} are not welded in envs "
                                    f"{envs[slots < 0].tolist()}; expected a welded pair (add_weld_constraint)")
        for env, slot in zip(envs.tolist(), slots.tolist()):
            count = int(table[env, 0].detach())
            gap, last = 1 + DYN_WELD * slot, 1 + DYN_WELD * (count - 1)
            table[env, gap: gap + DYN_WELD] = table[env, last: last + DYN_WELD].clone()
            table[env, last: last + DYN_WELD] = 0.0
            table[env, 0] = count - 1
        self.scene.sim.set_input(self._solver, "dyn_welds", table)

    def _pair(self, link1_idx, link2_idx, envs_idx, call):
        """((link 1, link 2) as ints, the envs (int64 array), a copy of the welds' input) of a call."""
        self.scene._require_built(f"{self._who}.{call}")
        if not self._solver.rigid_options.max_dynamic_constraints:
            raise InvalidInputError(f"{self._who}.{call}: the scene has no run-time weld slots; expected "
                                    f"RigidOptions(max_dynamic_constraints=n) with n ≥ 1 (0 by default here, "
                                    f"Genesis's 8)")
        n_links = self._solver.model.n_links
        links = tuple(self._link(idx, n_links, arg, call) for idx, arg in ((link1_idx, "link1_idx"),
                                                                            (link2_idx, "link2_idx")))
        if links[0] == links[1]:
            raise InvalidInputError(f"{self._who}.{call}: expected two different links, got link {links[0]} twice")
        static = self._solver.model.link_static[list(links)]
        if static.all():
            raise InvalidInputError(f"{self._who}.{call}: links {links} are both welded to the world; expected "
                                    f"one that moves")
        envs = self._envs(envs_idx, distinct=True)
        return links, envs, self.scene.sim.inputs(self._solver)["dyn_welds"].clone()

    def _link(self, idx, n_links, arg, call):
        """One scene-wide link index (an int, or a numpy or torch scalar: Genesis's suction cup
        passes np.array(link.idx)) in [0, n_links) (no count from the end: Genesis refuses −1, the
        world, as a link)."""
        value = idx.detach().cpu().numpy() if isinstance(idx, torch.Tensor) else np.asarray(idx)
        if value.size != 1 or value.dtype.kind not in "iu" or not 0 <= int(value.reshape(())) < n_links:
            raise InvalidInputError(f"{self._who}.{call}: argument '{arg}' must be one link index in [0, {n_links}) "
                                    f"(a link's idx; the world is not a link), got {idx!r}")
        return int(value.reshape(()))

    @staticmethod
    def _slots_of(table, envs, links):
        """(len(envs),) numpy: each env's slot holding the pair (either order), -1 where none does."""
        rows = table[torch.as_tensor(envs, device=table.device)].detach().cpu()
        count = rows[:, 0].long()
        pairs = rows[:, 1:].reshape(len(envs), -1, DYN_WELD)[:, :, :2].long()  # (n, slots, 2)
        on = torch.arange(pairs.shape[1])[None, :] < count[:, None]
        match = on & (((pairs[..., 0] == links[0]) & (pairs[..., 1] == links[1]))
                      | ((pairs[..., 0] == links[1]) & (pairs[..., 1] == links[0])))
        return torch.where(match.any(1), match.int().argmax(1), -1).numpy()
