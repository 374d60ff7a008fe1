"""The rigid solver: articulated bodies in reduced coordinates (see README for the physics).

State per env: [qpos (Q), qvel (D)]. Inputs per env: INPUTS in data.py. Everything here is
bookkeeping around the kernels of the stage modules; no Python loop runs over envs, links or
dofs at step time.
"""
import itertools
import logging
import math
import operator

import numpy as np
import torch

from ..base import GradColumns, Solver, tensor_bytes
from ..core import AssetError, GradientError, SimulationError, new_state, runtime
from .. import launch
from ..launch import BoundKernel, BoundKernels
from . import contact, ik, step
from .collision import detect
from .constraint.solver import MINVAL
from .data import ARENAS, BIG, DYN_WELD, ELEMENT, HEADER, INPUTS, RigidData
from .geometry import GEOM_CODE
from .model import build_model

_logger = logging.getLogger("genesis_lite")

# A step's replay record (replay_record) is kept with its graph node while it holds at most this
# many states' worth of numbers an env: a box on a plane ~2 (qacc 6, up to 16 rows' jar, against a
# 13-number state), the a1 standing ~1; three boxes with 10 substeps ~17, whose replay then solves
# again from the warm start (as fast as the forward, in a state's memory).
REPLAY_RECORD_STATES = 4

def _pair_name(kind):
    """'box–mesh' for a pair kind (type 1, type 2)."""
    names = {code: name for name, code in GEOM_CODE.items()}
    return f"{names[kind[0]]}–{names[kind[1]]}"


class RigidSolver(Solver):
    """Owns the rigid model (immutable), its Taichi data and the default inputs."""

    #: inputs that keep their value across ``scene.reset()`` (controls do not)
    persistent_inputs = ("mass", "com", "inertia", "damping", "armature", "stiffness", "kp", "kv", "gravity",
                         "force_lo", "force_hi", "limit_lower", "limit_upper", "frictionloss", "friction", "solref",
                         "solimp", "invweight_t", "invweight_r", "invweight_dof", "invweight_ten")

    transient_inputs = ("xfrc",)

    def __init__(self, sim_options, rigid_options):
        self.sim_options, self.rigid_options = sim_options, rigid_options
        self.entity_links = []  # one list[LinkSpec] per rigid entity, in add order
        self.entity_names = []
        self.attachments = {}  # entity index → (parent entity index, its link index): see attach
        self.model = self.data = None
        self._inputs_seen = {}  # name → the input tensor _note_inputs last checked
        self.friction = self.welds_on = False  # some dof has friction loss; some env a run-time weld
        self._packed = {}  # reverse or not → the buffer _pack_inputs writes, its parts' column views and the
        #                    input tensors they hold (_new_packing)
        self.substeps = sim_options.substeps
        self.gravity = rigid_options.gravity or sim_options.gravity  # (3,) m/s²: the default input
        self._commit = 1  # 0 while a backward replays a step: its frames stay for the reverse
        self._replaying = 0  # 1 while a backward replays a step given its replay_record (the solutions)
        self._warned_capped = False  # _check_capped warned
        self._stepped = False  # a step was taken (the last step's readouts are zeros before)
        self.invweight_basis = None  # contact.InvweightBasis, taken at build
        self._clear_substep_record()

    def _clear_substep_record(self):
        """Per substep of the step being taken (forward or replay), for its reverse: whether its
        constraint stage ran, and the mask of its collider kernels that ran (detect.KERNEL_BIT)."""
        self._rows_in_substep, self._colliders_in_substep = [False] * self.substeps, [0] * self.substeps

    # -- building ---------------------------------------------------------------------------
    def add_entity(self, name, links):
        """Register an entity's links; returns its index among rigid entities."""
        self.entity_links.append(links)
        self.entity_names.append(name)
        return len(self.entity_links) - 1

    def attach(self, entity, parent_entity, parent_link):
        """Hang entity's first link (its joint fixed, its spec's pose the mount in the parent link's
        frame) from link ``parent_link`` of the earlier entity ``parent_entity`` (indices as
        add_entity returns them), before build."""
        self.attachments[entity] = (parent_entity, parent_link)

    def build(self, n_envs):
        options = self.rigid_options
        self.invweight_basis = None  # until at_initial_pose takes it for this model
        condim_floor = 6 if options.enable_rolling_friction else 4 if options.enable_torsional_friction else 3
        self.model = build_model(self.entity_links, options.enable_self_collision, options.enable_adjacent_collision,
                                 self.attachments, condim_floor, self.entity_names)
        if not options.enable_collision:
            self.model = contact.without_pairs(self.model)
        self.model = contact.without_uncollidable(self.model, {v: k for k, v in GEOM_CODE.items()})
        self.n_batch = max(1, n_envs)
        self._nothing = torch.empty((0, 0), dtype=runtime.tc_float, device=runtime.device)  # an unused array argument
        self.state_width = self.model.n_qs + self.model.n_dofs
        self._check_mass_matrix()
        self.worst_contacts = contact.worst_case_contacts(self.model)  # (what the slots may grow to)
        self._allocate()  # what needs kernels at the initial pose: then the final storage
        self.model = contact.at_initial_pose(self, options.enable_neutral_collision)
        self.worst_contacts = contact.worst_case_contacts(self.model)
        self._allocate(self.data.size["C"])  # (as many slots as the initial pose took)
        self.grad_input_names = tuple(self.data.grad_input_names)
        # column widths of backward's output: state gradient, then each differentiable input's
        self.grad_widths = [self.state_width] + [self.data.width(name) for name in self.grad_input_names]
        ends = np.cumsum(self.grad_widths).tolist()
        self._grad_spans = {name: (ends[k], ends[k + 1]) for k, name in enumerate(self.grad_input_names)}
        state = self._initial_state()
        self.upload_state(state)
        return state

    def _allocate(self, contacts=None):
        """The scene's arenas and kernels for the current model, holding the default inputs;
        contacts: see _make_storage."""
        self._make_storage(contacts)
        self._wrench = 0  # the header's "wrench" flag as last written (the new arenas' is 0)
        self.default_inputs = self._default_inputs()
        self.upload_inputs(self.default_inputs)

    def _make_storage(self, contacts=None):
        """self.data (RigidData) for the current model with ``contacts`` slots per env (None: the
        options' capacity, contact.capacity), and the kernels bound to its arenas."""
        options, sim = self.rigid_options, self.sim_options
        h = sim.dt / sim.substeps
        bits = 64 if runtime.tc_float == torch.float64 else 32
        self.timeconst, self.iterations, self.tolerance, impratio = options.resolved(bits)
        contacts, rows = contact.capacity(self.model, options, contacts)
        settings = {"limits": options.enable_joint_limit, "contacts": contacts, "rows": rows,
                    "cone": int(options.friction_cone == "elliptic"), "iterations": self.iterations,
                    "ls_iterations": options.ls_iterations, "converged": not options.enable_mujoco_compatibility,
                    "dyn_welds": options.max_dynamic_constraints,
                    "consts": [h, self.timeconst, impratio, self.tolerance, options.ls_tolerance]}
        self.data = RigidData(contact.with_row_softness(self.model, self.timeconst), self.n_batch, sim.substeps,
                              sim.requires_grad, settings)
        element_dims = [len(ELEMENT[a]) for a in ARENAS]
        schedule, arenas = self.data.schedule, self.data.arenas
        # (read at bind time: the test suite sets them)
        light, solve = launch.LIGHT_OPT_LEVEL, launch.SOLVE_OPT_LEVEL  # solve: the constraint solve and IK's
        self.kernels = BoundKernels(schedule, arenas, element_dims, *step.KERNELS, opt_level=light)
        m = self.model
        self.inexact_kinds = detect.inexact_kinds(m)  # pair kinds whose contacts may not be closed forms
        # (its bits in the header's colliders_due mask, kernel) of each collider kernel
        self.colliders = [(1 << detect.KERNEL_BIT[kind], BoundKernel(step.collide, (schedule, kind), arenas,
                                                                     element_dims, light))
                          for kind in detect.kernel_kinds(m)]
        if self.data.size["converged"] and self.inexact_kinds:  # convex contacts → their closed forms
            ccd = (1 << detect.KERNEL_BIT[detect.ALL_CONVEX]) | (1 << detect.KERNEL_BIT[detect.ALL_HFIELD])
            self.colliders.append((ccd, BoundKernel(step.converge, schedule, arenas, element_dims, light)))
        # the reverse of a substep, without and with the constraint stage
        solve_schedule, elliptic = self.data.solve_schedule, bool(settings["cone"])
        body_eqs = m.n_body_eq > 0 or options.max_dynamic_constraints > 0
        # 6: the torsional and rolling rows compiled in (condim 4 too: one kernel fewer to compile), 3: not
        max_condim = 6 if m.pair_condim.max(initial=3) > 3 else 3
        self.constrain = BoundKernel(step.constrain, (solve_schedule, elliptic, body_eqs, max_condim), arenas,
                                     element_dims, solve)
        self.reverse_kernel = [BoundKernel(step.reverse_dynamics, (schedule, 0, False, False, 3), arenas,
                                           element_dims, light),
                               BoundKernel(step.reverse_dynamics, (solve_schedule, 1, elliptic, body_eqs, max_condim),
                                           arenas, element_dims, solve)]
        self.collider_reverses = [(detect.KERNEL_BIT[kind], BoundKernel(step.collide_adjoint, (schedule, kind),
                                                                        arenas, element_dims, light))
                                  for kind in detect.differentiable_kinds(m)]
        self._inverse_kinematics = {serial: BoundKernel(ik.inverse_kinematics, serial, arenas, element_dims, solve)
                                    for serial in (False, True)}

    def _default_inputs(self):
        m, B, slots = self.model, self.n_batch, self.rigid_options.max_dynamic_constraints
        effort = np.minimum(m.dof_effort, BIG)
        per_env = {
            "mass": m.link_mass0, "com": m.link_com.reshape(-1), "inertia": m.link_inertia.reshape(-1),
            "damping": m.dof_damping, "armature": m.dof_armature,
            "stiffness": m.dof_stiffness, "kp": m.dof_kp, "kv": m.dof_kv, "gravity": np.array(self.gravity),
            "ctrl_force": np.zeros(m.n_dofs), "ctrl_pos": np.zeros(m.n_dofs), "ctrl_vel": np.zeros(m.n_dofs),
            "xfrc": np.zeros(6 * m.n_links),
            "frictionloss": m.dof_frictionloss, "force_lo": -effort, "force_hi": effort,
            "limit_lower": m.dof_lower, "limit_upper": m.dof_upper,
            "ctrl_mode": np.zeros(m.n_dofs), "dyn_welds": np.zeros(1 + DYN_WELD * slots),
            "friction": m.geom_friction.reshape(-1), **self._default_softness(),
            "invweight_t": np.zeros(m.n_links), "invweight_r": np.zeros(m.n_links), "invweight_dof": np.zeros(m.n_dofs),
            "invweight_ten": np.zeros(m.n_tendons)}
        assert per_env.keys() == INPUTS.keys()
        inputs = {name: torch.as_tensor(np.tile(np.asarray(v, dtype=np.float64), (B, 1)), dtype=runtime.tc_float,
                                        device=runtime.device) for name, v in per_env.items()}
        return self._with_springdamper(self.derive_inputs(inputs))

    def _with_springdamper(self, inputs):
        """``inputs`` with the stiffness and damping of every joint given a springdamper (time constant
        tc, damping ratio ζ; model.dof_springdamper) as MuJoCo's compiler sets them (AutoSpringDamper)
        from the joint's inertia I = n / Σ dof_invweight0 over its n dofs: stiffness I / (tc ζ)²,
        damping 2 I / tc, on each of its dofs. Once, from the build's scale (the inputs' defaults),
        as MuJoCo's compile: later mass or armature changes leave them."""
        m = self.model
        given = np.flatnonzero((m.dof_springdamper > 0).all(1))
        if not len(given) or self.invweight_basis is None:  # (no scale before the basis: the first allocation)
            return inputs
        invweight = inputs["invweight_dof"].double()
        stiffness, damping = inputs["stiffness"].clone(), inputs["damping"].clone()
        for link in np.unique(m.dof_link[given]):
            dofs = torch.as_tensor(np.flatnonzero(m.dof_link == link), device=runtime.device)
            timeconst, ratio = m.dof_springdamper[int(dofs[0])]
            inertia = len(dofs) / invweight[:, dofs].sum(1, keepdim=True).clamp(min=MINVAL)
            stiffness[:, dofs] = (inertia / max(MINVAL, (timeconst * ratio) ** 2)).to(stiffness.dtype)
            damping[:, dofs] = (2.0 * inertia / max(MINVAL, timeconst)).to(damping.dtype)
        return {**inputs, "stiffness": stiffness, "damping": damping}

    def _default_softness(self):
        """The inputs "solref" and "solimp": each geom's from its asset, else the scene's default."""
        m = self.model
        default = {"solref": [self.timeconst, 1.0],
                   "solimp": contact.SMOOTH_SOLIMP if self.rigid_options.smooth_contact else contact.DEFAULT_SOLIMP}
        return {name: np.where(np.isnan(given), np.asarray(default[name], dtype=np.float64), given).ravel()
                for name, given in (("solref", m.geom_solref), ("solimp", m.geom_solimp))}

    derived_from = ("mass", "inertia", "armature")
    derived_inputs = ("invweight_t", "invweight_r", "invweight_dof", "invweight_ten")

    def derive_inputs(self, inputs, previous=None):
        """``inputs`` with the rows' scale (invweight_t, invweight_r, invweight_dof, invweight_ten) recomputed from
        their mass, inertia and armature (contact.InvweightBasis; differentiable); zeros before the basis exists
        (the first allocation at build, which forms no rows). With ``previous`` and no gradient anywhere
        (those inputs, nor the previous scale: its graph would stay attached), only the envs
        where one of them changed are recomputed (setting one env's mass recomputed all: 80
        ms a call at 1024 envs)."""
        if self.invweight_basis is None:
            return inputs
        sources = [inputs[name] for name in self.derived_from]
        envs = slice(None)
        if previous is not None and not any(t.requires_grad for t in (
                *sources, *(previous[name] for name in self.derived_inputs))):
            changed = torch.stack([(inputs[name] != previous[name]).any(1) for name in self.derived_from]).any(0)
            envs = torch.nonzero(changed).flatten()
        derived = dict(zip(self.derived_inputs, self.invweight_basis(*(t[envs] for t in sources),
                                                                     self.check_positive_definite)))
        if isinstance(envs, torch.Tensor):  # (the others keep theirs)
            derived = {name: previous[name].index_put((envs,), value) for name, value in derived.items()}
        return {**inputs, **derived}

    def _initial_state(self):
        qpos = np.tile(self.model.qpos0, (self.n_batch, 1))
        qvel = np.zeros((self.n_batch, self.model.n_dofs))
        return torch.as_tensor(np.concatenate([qpos, qvel], axis=1), dtype=runtime.tc_float, device=runtime.device)

    def _check_mass_matrix(self):
        """A dof with no mass or inertia behind it makes M singular: say which link, at build time."""
        m = self.model
        subtree_mass = m.link_mass0.copy()
        subtree_inertia = np.trace(m.link_inertia0, axis1=1, axis2=2) * (m.link_mass0 > 0)
        for l in reversed(range(m.n_links)):  # children have higher indices than their parent
            if m.link_parent[l] >= 0:
                subtree_mass[m.link_parent[l]] += subtree_mass[l]
                subtree_inertia[m.link_parent[l]] += subtree_inertia[l]
        for i, link in enumerate(m.dof_link):
            if subtree_mass[link] > 0 or subtree_inertia[link] > 0 or m.dof_armature[i] > 0:
                continue
            entity = self.entity_names[m.link_entity[link]]
            raise AssetError(f"entity '{entity}': link '{m.link_name[link]}' moves (dof {i}) but it and its children "
                             f"have no mass or inertia (an <inertial> of mass 0 — which pybullet reads as a static "
                             f"body — or none); expected an <inertial> with positive mass, or collision geometry to "
                             f"derive it from, or armature on the joint, or fixed=True for a body that does not move")

    def check_positive_definite(self, mass_matrix, error=AssetError, dofs=None):
        """M (n, n) with armature at the initial pose, of one kinematic tree's dofs ``dofs`` (None:
        every dof), must be positive definite: else raise ``error`` naming the link of the first dof
        whose pivot vanishes (a massless root carrying a joint, an inertia with a zero principal
        moment under a free joint, ...), at build time or when masses or armature are set. A pivot
        counts as vanished below a round-off share of its own diagonal entry (M comes in the
        scene's precision)."""
        share = 1e-10 if runtime.tc_float == torch.float64 else 1e-5
        reduced = mass_matrix.astype(np.float64)
        for i in range(len(reduced)):  # Gaussian elimination in dof order: pivot i of M's LDLᵀ
            pivot = reduced[i, i]
            if not pivot > share * mass_matrix[i, i]:
                m = self.model
                dof = i if dofs is None else int(dofs[i])
                link = m.dof_link[dof]
                raise error(f"entity '{self.entity_names[m.link_entity[link]]}': link '{m.link_name[link]}' "
                            f"(dof {dof}) expected a positive definite mass matrix, got a pivot of {pivot:.3g} "
                            f"against a diagonal entry of {mass_matrix[i, i]:.3g}: this dof moves no mass or "
                            f"inertia that the dofs before it do not move already (a massless base under a free "
                            f"joint, a zero principal moment of inertia); give the links positive masses and "
                            f"inertias with positive principal moments, or armature on the joint")
            reduced[i + 1:, i + 1:] -= np.outer(reduced[i + 1:, i], reduced[i, i + 1:]) / pivot

    # -- moving data ------------------------------------------------------------------------
    def _empty(self, width):
        return torch.empty((self.n_batch, width), dtype=runtime.tc_float, device=runtime.device)

    def upload_state(self, state, envs=None):
        """(write_state clears every env's warm start: the other envs' are put back, so that a
        setter or reset of some envs leaves the others' steps as they were, bit for bit.)"""
        others = None
        if envs is not None and self._constrained():
            others = torch.ones(self.n_batch, dtype=torch.bool, device=runtime.device)
            others[torch.as_tensor(envs, device=runtime.device)] = False
            kept = self.data.per_env("qacc_warmstart")[others].clone()
        self.kernels.write_state(0, state.detach().contiguous())
        if others is not None:
            self.data.per_env("qacc_warmstart")[others] = kept

    def download_state(self):
        out = new_state((self.n_batch, self.state_width), self.own_state_pages)
        self.kernels.read_state(0, out)
        return out

    def upload_inputs(self, inputs):
        self._note_inputs(inputs)
        self.kernels.write_inputs(self._pack_inputs(inputs))

    def _note_inputs(self, inputs):
        """Tell the kernels whether the inputs hold an external wrench (the header's "wrench": set
        by apply_links_external_wrench, else the build's zeros, whose force stage and its
        gradients the kernels then skip). Keep whether they give some dof friction loss (or the
        model a tendon's) or a limit (or the model a tendon limit), and some env a run-time weld
        (constraint rows).
        Checked again only for another frictionloss (limit, dyn_welds) tensor (inputs are never
        changed in place: see _pack_inputs): a rollout passes the same one every step, and the
        check costs ~15 µs of torch amid a step (a tenth of a small robot's differentiable step)."""
        wrench = int(inputs["xfrc"] is not self.default_inputs["xfrc"])
        if wrench != self._wrench:  # (kept on the host: reading a GPU header would wait for the device)
            self.data.header[HEADER["wrench"]] = self._wrench = wrench
        if self._changed(inputs, "frictionloss"):  # (or the model a tendon's)
            self.friction = bool((inputs["frictionloss"] > 0).any()) or bool((self.model.ten_frictionloss > 0).any())
        if self._changed(inputs, "limit_lower") | self._changed(inputs, "limit_upper"):  # (both noted)
            tendon_limits = np.isfinite(self.model.ten_lower).any() or np.isfinite(self.model.ten_upper).any()
            self.limited = self.rigid_options.enable_joint_limit and (bool(tendon_limits) or bool(
                (inputs["limit_lower"] > -math.inf).any() or (inputs["limit_upper"] < math.inf).any()))
        if self._changed(inputs, "dyn_welds"):
            self.welds_on = bool((inputs["dyn_welds"][:, 0] > 0).any())

    def _changed(self, inputs, name):
        """Whether inputs[name] is another tensor than at the last call."""
        tensor = inputs[name]
        if self._inputs_seen.get(name) is tensor:
            return False
        self._inputs_seen[name] = tensor  # (held: its id stays its own)
        return True

    def _constrained(self):
        """Whether a step may have constraint rows: contact pairs, joint equalities, connects, welds,
        joint limits or friction loss."""
        return bool(self.colliders) or self.model.has_equalities or self.limited or self.friction or self.welds_on

    def _pack_inputs(self, inputs, state=None, grad_state_out=None):
        """(B, width) of every input in INPUTS order; for a reverse, with the step's start
        ``state`` before and ``grad_state_out`` after. The kernels read values only: no graph is
        built (nor does Taichi see a tensor that requires grad). Written into a buffer kept for
        each of the two layouts and reused by the next call: the kernels read it before that. (A
        new tensor a step was a new memory mapping once it reached 128 KiB, glibc's mmap threshold
        being fixed there (runtime.keep_large_blocks_off_the_heap): its page faults cost a KUKA's
        256-env differentiable rollout 18 %.) An input is copied only where another tensor
        replaced it since the buffer took it (by identity: inputs are never changed in place, every
        setter makes a new tensor: entities/common.replace_columns), into a view of its columns
        made with the buffer: a control call each step copies its own columns (a 1024-env KUKA: 310
        µs a step for all; a concatenation of all ~30 parts cost a small robot's reverse step 12
        µs). Which ones changed is found by C-level maps: a loop over the parts in Python cost more
        than the copy. A reverse's state and gradient are copied always (the gradient may be the
        caller's grad_outputs, refilled in place between two torch.autograd.grad calls: found by an
        adversarial pass)."""
        reverse = state is not None
        if reverse not in self._packed:
            self._packed[reverse] = self._new_packing(reverse)
        buffer, columns, around, held = self._packed[reverse]
        tensors = list(map(inputs.__getitem__, INPUTS))
        for k in itertools.compress(range(len(tensors)), map(operator.is_not, tensors, held)):
            columns[k].copy_(tensors[k].detach())
        held[:] = tensors
        if reverse:
            around[0].copy_(state.detach())
            around[1].copy_(grad_state_out.detach())
        return buffer

    def _new_packing(self, reverse):
        """(buffer, views of its inputs' columns, views of the state's and its gradient's columns
        around them when ``reverse`` (else ()), the inputs' tensors it holds: none yet)."""
        state = [self.state_width] if reverse else []
        ends = np.cumsum([*state, *(self.data.width(name) for name in INPUTS), *state]).tolist()
        buffer = self._empty(ends[-1])
        columns = [buffer[:, start:end] for start, end in zip([0, *ends[:-1]], ends)]
        if reverse:
            return buffer, columns[1:-1], (columns[0], columns[-1]), [None] * len(INPUTS)
        return buffer, columns, (), [None] * len(INPUTS)

    # -- stepping ---------------------------------------------------------------------------
    def advance(self, inputs=None, download=False):
        out = new_state((self.n_batch, self.state_width), self.own_state_pages) if download else self._nothing
        if inputs is not None:
            self._note_inputs(inputs)
        self.run_step(self._nothing if inputs is None else self._pack_inputs(inputs), out, commit=self._commit)
        self._step_taken()
        return out if download else None

    def _step_taken(self):
        """After a step, alone (advance) or in the shared loop (end_step): a replay ends with its
        step; more contacts than slots raise; a differentiable forward step warns when its solve
        stopped short (on the CPU, where the flag is read without waiting for a device)."""
        forward = self._commit
        self._commit, self._replaying, self._stepped = 1, 0, True
        if self.data.size["N"]:
            self._check_overflow()
        if forward and self.sim_options.requires_grad and self.data.flags_on_host:
            self._check_capped()

    def _check_capped(self):
        """Warn (once) when a differentiable step's constraint solve stopped at its iteration
        limit: the backward differentiates the converged solution (constraint/implicit.py), so a
        step short of it gets a gradient off by what the solve had left (a box sliding with
        iterations=2: 0.67 of the gradient, the sign flipped)."""
        if self.data.take_flag("capped") and not self._warned_capped:
            self._warned_capped = True
            _logger.warning(f"rigid solver (entities: {', '.join(self.entity_names)}): a constraint solve stopped at "
                            f"its iteration limit (RigidOptions(iterations={self.iterations})) before its tolerance "
                            f"({self.tolerance:g}); gradients through such a step are those of the converged solution, "
                            f"not of the step taken: raise iterations (warned once)")

    def _check_overflow(self):
        """Raise if the step had more contacts than slots."""
        if self.data.take_flag("overflow"):
            raise SimulationError(f"rigid solver (entities: {', '.join(self.entity_names)}): more contacts than the "
                                  f"{self.data.size['C']} slots per env in this step (it was taken without the "
                                  f"extra ones); expected RigidOptions(max_contacts=...) above that (this scene's "
                                  f"pairs can make up to {self.worst_contacts}; the default, None, grows the slots "
                                  f"as needed on the CPU and gives a GPU {contact.MAX_PER_MOVING_LINK} per moving link)")

    def run_step(self, inputs, out, commit):
        """One step's kernels. Without contact pairs, equalities or friction loss, one launch
        for all substeps (advance), which leaves the envs meeting a joint limit to the constraint
        stage; else, or for those envs, the stage kernels of each substep (_substep)."""
        flagged_only = 0
        self._clear_substep_record()
        if not (self.colliders or self.model.has_equalities or self.friction or self.welds_on):
            self.kernels.advance(commit, inputs, out)
            if not (self.limited and self.data.take_flag("rows_needed")):
                return
            inputs, flagged_only = self._nothing, 1  # advance loaded them
        for s in range(self.sim_options.substeps):
            self._substep(s, inputs if s == 0 else self._nothing, out, commit, flagged_only)

    def detect_contacts(self):
        """Frame 0's contacts at the uploaded state (the first substep's stages up to the colliders;
        no step is taken)."""
        self._smooth_and_collide(0, self._nothing, 0)
        self.data.take_flag("constrained")

    def _smooth_and_collide(self, s, inputs, flagged_only):
        """Frame s's smooth stage and colliders (inputs and flagged_only: see _substep). Where an env
        found more contacts than slots and the slots may grow (RigidOptions(max_contacts=None), up to
        the pairs' worst case; on the CPU, where the flag is read without waiting for a device), they
        double (_grow_contacts) and the two stages run again from frame s, which the growth kept: a
        pile gets its slots as it forms, with the trajectory of a scene sized for it from the start."""
        self.kernels.smooth_substep(s, inputs, flagged_only)
        self._collide(s)
        while self.data.flags_on_host and self.data.header[HEADER["overflow"]] and self._may_grow():
            self._grow_contacts()
            self.kernels.smooth_substep(s, self._nothing, flagged_only)  # (the inputs came over with the growth)
            self._collide(s)

    def _may_grow(self):
        return self.rigid_options.max_contacts is None and self.data.size["C"] < self.worst_contacts

    def _grow_contacts(self):
        """Twice the contact slots (at most the worst case) and the rows they need: new arenas holding
        everything the old ones did (RigidData.take_over), the kernels bound to them; the overflow
        flag cleared."""
        old = self.data
        self._make_storage(min(2 * old.size["C"], self.worst_contacts))
        self.data.take_over(old)
        self.data.take_flag("overflow")
        _logger.debug(f"rigid solver (entities: {', '.join(self.entity_names)}): contact slots per env grown from "
                      f"{old.size['C']} to {self.data.size['C']}")

    def _collide(self, s):
        """Frame s's collider kernels that its near pairs need (every one on a GPU, where reading
        the mask would wait for the device)."""
        due = self.data.take_flag("colliders_due") if self.data.flags_on_host else -1
        self._colliders_in_substep[s] = due
        for bits, collide in self.colliders:
            if due & bits:
                collide(s)

    def _substep(self, s, inputs, out, commit, flagged_only):
        """Substep s as two stage kernels (smooth, then constrain or, without rows, finish) with the
        colliders between them (one kernel per pair kind: see collision/detect.py); inputs (loaded
        when not empty), out (the result, at the last substep, when not empty), commit: see
        step.finish_substep; flagged_only: only the envs that advance left to the constraint stage."""
        self._smooth_and_collide(s, inputs, flagged_only)
        self._finish_substep(s, out, commit, flagged_only)

    def _finish_substep(self, s, out, commit, flagged_only):
        """The rest of substep s after its smooth stage and colliders (see _substep)."""
        # the solve only where some env has a row to form (the frame is one without rows until
        # then): a scene out of contact never loads the solve's kernel (tens of seconds of LLVM in
        # a fresh process) nor runs it; on a GPU the flag is not read (a wait for the device)
        found = self.data.take_flag("constrained") if self.data.flags_on_host else 1  # read, so cleared, always
        rows = bool(flagged_only or found)
        self._rows_in_substep[s] = rows  # the reverse of a substep without rows skips the solve's
        if rows:  # (which then also finishes the substep)
            self.constrain(s, flagged_only, self._replaying, commit, out)
        else:
            self.kernels.finish_substep(s, commit, out, flagged_only)

    # -- the shared substep loop (solvers/base.py): the smooth stage and colliders of frame s come --
    # -- before coupling (a coupler reads the frame's poses, and adds its forces to qfrc_smooth), --
    # -- the solve and the integration after it --
    def begin_step(self, inputs):
        self._clear_substep_record()
        if inputs is not None:
            self._note_inputs(inputs)
        self._step_inputs = self._nothing if inputs is None else self._pack_inputs(inputs)

    def substep_pre_coupling(self, s):
        self._smooth_and_collide(s, self._step_inputs if s == 0 else self._nothing, 0)

    def substep_post_coupling(self, s):
        self._finish_substep(s, self._nothing, self._commit, 0)

    def end_step(self, download):
        result = self.download_state() if download and self._commit else None
        self._step_taken()
        return result

    def nonfinite(self):
        """True once any step produced a non-finite state (resets the flag)."""
        return self.data.take_flag("nonfinite")

    @property
    def watches_nonfinite(self):
        # on the CPU the flag is a read of host memory; on a GPU it would wait for the device
        return self.data.flags_on_host

    def entity_columns(self):
        """Each entity's qpos columns, then its qvel columns (its links are contiguous in the model,
        entity by entity)."""
        m = self.model
        first = [int(np.flatnonzero(m.link_entity == k)[0]) for k in range(len(self.entity_names))]
        q, d = [*(int(m.link_q0[l]) for l in first), m.n_qs], [*(int(m.link_dof0[l]) for l in first), m.n_dofs]
        return [(name, np.r_[q[k]:q[k + 1], m.n_qs + d[k]:m.n_qs + d[k + 1]]) for k, name in enumerate(self.entity_names)]

    def warm_start(self):
        """(B, D) copy of the constraint solve's warm start (what the next step's solve starts
        from), or None when no step can have a solve."""
        return self.data.per_env("qacc_warmstart").clone() if self._constrained() else None

    def set_warm_start(self, warm_start):
        """The warm start ← ``warm_start`` (from ``warm_start()``; None: leave it)."""
        if warm_start is not None:
            self.data.per_env("qacc_warmstart").copy_(warm_start)

    def replay_record(self):
        """What the solves of the step just taken ended at, or None when no substep had a
        constraint stage: per substep, the constrained acceleration (B, D) and the rows' jar
        (B, rows up to the most any env used), or None for a substep without the stage. Given it,
        the step's replay makes the solve's outputs without iterating (constraint/solver.py,
        "Replay"). None on a GPU (the record's row count would wait for the device every
        substep) and where the record would exceed REPLAY_RECORD_STATES states (many rows or
        substeps): that step's replay solves again from its warm start, which the graph keeps."""
        if not (any(self._rows_in_substep) and self.data.flags_on_host):
            return None
        used = [int(self.data.frame("n_efc", s).max()) if rows else 0 for s, rows in enumerate(self._rows_in_substep)]
        width = sum(self.model.n_dofs + n for n, rows in zip(used, self._rows_in_substep) if rows)
        if width > REPLAY_RECORD_STATES * self.state_width:
            return None
        return [(self.data.frame("qacc_constrained", s).clone(), self.data.frame("solver_jar", s)[:, :n].clone())
                if rows else None for s, (n, rows) in enumerate(zip(used, self._rows_in_substep))]

    def begin_reverse(self, state, inputs, grad_state_out, warm_start, record=None):
        """Load the step's start state, inputs and output gradient, and the warm start the forward
        step started from or its replay_record: its replay (uncommitted) then repeats it exactly
        (see step.py)."""
        self._note_inputs(inputs)
        packed = self._pack_inputs(inputs, state, grad_state_out)
        self._grads = self._empty(sum(self.grad_widths))
        self.kernels.prepare_reverse(packed)
        self.data.take_flag("inexact")
        self.set_warm_start(warm_start)
        for s, solution in enumerate(record or ()):
            if solution is not None:
                self.data.frame("qacc_constrained", s).copy_(solution[0])
                self.data.frame("solver_jar", s)[:, :solution[1].shape[1]].copy_(solution[1])
        self._replaying = int(record is not None)
        self._commit = 0

    def substep_post_coupling_backward(self, s):
        """Substep s's reverse from its integration back to the smooth force and the link sweep's
        outputs (qfrc_smooth's gradient is then whole: a coupler's reverse reads it)."""
        self.reverse_kernel[self._rows_in_substep[s]](s)

    def check_replay(self):
        """A GradientError if the replay flagged a contact without an exact gradient."""
        if self.data.take_flag("inexact"):  # the replay's contacts
            where = self._inexact_contact()
            if self.rigid_options.enable_mujoco_compatibility:
                why = (f"under RigidOptions(enable_mujoco_compatibility=True) the convex collider's contacts are "
                       f"MuJoCo's iterates on curved shapes and margins (and its clipping corners on mesh "
                       f"polygons), which have no exact gradient: {where}; expected "
                       f"enable_mujoco_compatibility=False (their converged contacts)")
            else:
                why = (f"{where} kept the convex collider's iterate (two cylinders at their rims with both ends "
                       f"of each in the contact's feature, or a feature whose form is not finite, not converged, "
                       f"or another stationary point far from the iterate), which has no exact gradient; expected "
                       f"other contact features, or RigidOptions(enable_collision=False)")
            raise GradientError(f"rigid solver (entities: {', '.join(self.entity_names)}): this step had no exact "
                                f"gradient: {why}")

    def _inexact_contact(self):
        """'the cylinder–box contact of link 'a' of entity 'A' and link 'b' of entity 'B' (env e,
        substep s)': the last contact a replay flagged inexact (the header keeps where it was)."""
        m, header = self.model, self.data.header
        pair, env, substep = (int(header[HEADER[name]]) for name in ("inexact_pair", "inexact_env", "inexact_substep"))
        g1, g2 = int(m.pair_geom1[pair]), int(m.pair_geom2[pair])
        links = [int(m.geom_link[g]) for g in (g1, g2)]
        sides = " and ".join(f"link '{m.link_name[l]}' of entity '{self.entity_names[m.link_entity[l]]}'" for l in links)
        return (f"the {_pair_name((int(m.geom_type[g1]), int(m.geom_type[g2])))} contact of {sides} (env {env}, "
                f"substep {substep})")

    def end_backward(self):
        self._commit, self._replaying = 1, 0
        if self.data.flags_on_host:  # (a replay that solved again may have raised it: not a forward step's)
            self.data.take_flag("capped")

    def substep_pre_coupling_backward(self, s):
        """The rest of substep s's reverse (the contacts' colliders, the geom poses and the down
        sweep), separate kernels: fused, they compile slower."""
        for bit, reverse in self.collider_reverses:
            if self._colliders_in_substep[s] >> bit & 1:  # else that kind has no contact to reverse
                reverse(s)
        self.kernels.reverse_kinematics(s, self._grads)

    def end_reverse(self):
        return self._split_grads(self._grads)

    def _split_grads(self, out):
        """(the state's gradient, the inputs' as a GradColumns) from out (B, sum(grad_widths)); the
        inputs' views are made when asked for (a step's backward wants a few of ~20)."""
        return out[:, :self.state_width], GradColumns(out, self._grad_spans)

    # -- derived quantities at the uploaded state ----------------------------------------------
    def links_kinematics(self):
        """(B, L, 13): link origin pos (3), quat (4), angular velocity ω (3) and the link origin's linear
        velocity v (3), world frame."""
        out = torch.empty((self.n_batch, self.model.n_links, 13), dtype=runtime.tc_float, device=runtime.device)
        # (swept at the frame no stage of a step uses: the last step's stay, step.down_sweep)
        self.kernels.read_links(self.substeps, out)
        return out

    def links_kinematics_backward(self, grad_links):
        """Gradient of the uploaded state from a gradient of ``links_kinematics``'s output."""
        self.kernels.down_sweep(0)
        out = self._empty(sum(self.grad_widths))
        self.kernels.down_sweep_adjoint(grad_links.contiguous(), out)
        return self._split_grads(out)[0]

    def inverse_kinematics(self, serial, *arrays):
        """Inverse kinematics of one entity at the uploaded state (ik.py: what ``arrays`` hold;
        serial: the envs one after another on the calling thread, as an env met twice needs)."""
        self._inverse_kinematics[serial](*arrays)

    def mass_matrix(self):
        """(B, D, D) joint-space mass matrix, armature on its diagonal, at the uploaded state."""
        out = torch.empty((self.n_batch, self.model.n_dofs, self.model.n_dofs), dtype=runtime.tc_float,
                          device=runtime.device)
        self.kernels.read_mass_matrix(self.substeps, out)  # (at the last frame: see links_kinematics)
        return out

    def dofs_dynamics(self):
        """(B, 2, D) the last step's last substep's generalised force, constraint forces included
        (row 0), and the acceleration it integrated (row 1) (step.read_dofs_dynamics; zeros before
        any step)."""
        out = torch.empty((self.n_batch, 2, self.model.n_dofs), dtype=runtime.tc_float, device=runtime.device)
        self.kernels.read_dofs_dynamics(out)
        return out

    def links_acc(self):
        """(B, L, 6) the last step's last substep's classical linear acceleration of each link's
        origin (m/s², gravity out) and its angular acceleration (rad/s²), world frame
        (step.read_links_acc; zeros before any step)."""
        out = torch.zeros((self.n_batch, self.model.n_links, 6), dtype=runtime.tc_float, device=runtime.device)
        if self._stepped:
            self.kernels.read_links_acc(out)
        return out

    def contacts(self, substep=-1, trimmed=False):
        """(B, W, 12) the contacts of the last step's ``substep`` (see step.read_contacts; each env's
        come first in its slots, rows past its count have geom −1 and zeros): W = C, the contact
        slots (0 without candidate pairs), or with ``trimmed`` the most contacts of one env (a
        1024-env step's readout of its few contacts a fraction of the slots' C)."""
        substep %= self.sim_options.substeps
        width = self.data.size["C"]
        if trimmed and width:
            width = int(self.data.frame("n_con", substep).max())
        out = torch.empty((self.n_batch, width, 12), dtype=runtime.tc_float, device=runtime.device)
        if width:
            self.kernels.read_contacts(substep, out)
        return out

    def links_contact_force(self, substep=-1):
        """(B, L, 3) N, world: the sum of the contact forces on each link in the last step's
        ``substep`` (step.read_links_contact_force; zeros without candidate pairs)."""
        shape, due = (self.n_batch, self.model.n_links, 3), bool(self.data.size["C"])
        out = (torch.empty if due else torch.zeros)(shape, dtype=runtime.tc_float, device=runtime.device)
        if due:  # (the kernel writes every element)
            self.kernels.read_links_contact_force(substep % self.sim_options.substeps, out)
        return out

    last_step_readouts = ("contacts", "links_contact_force", "dofs_dynamics", "links_acc")

    @staticmethod
    def without_last_step(readout, value, envs):
        """``value`` of ``readout`` (contacts (B, C, 12), dofs_dynamics (B, 2, D), links_acc (B, L, 6))
        as if the envs of the bool mask ``envs`` (B,) had taken no step: no contacts (rows as the
        unused ones: geom −1, the rest 0), no force, no acceleration."""
        out = value.clone()
        out[envs] = 0.0
        if readout == "contacts":
            out[envs, :, :2] = -1.0
        return out

    def memory_bytes(self):
        """The arenas' bytes, and those of the tensors among the solver's attributes."""
        return tensor_bytes(list(vars(self).values()) + ([] if self.data is None else [self.data.arenas]))

    def destroy(self):
        """Free the arenas and the input packs (the compiled kernels stay, for every later scene)."""
        self.data = self.kernels = None
        self._packed, self._inputs_seen = {}, {}
