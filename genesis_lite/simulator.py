"""The simulator behind a scene: owns the solvers, the current state and inputs as torch
tensors, and steps them — through autograd nodes when ``requires_grad``, directly otherwise.

The Taichi copy of a solver's state is authoritative between steps when no graph is built
(torch reads it lazily); with ``requires_grad`` the torch tensor is (it is the graph's node
value) and Taichi is re-synchronised only when something else (a backward pass) used it.
"""
import itertools
import math
import operator
import weakref

import numpy as np
import torch

from . import autograd
from .runtime import keep_large_blocks_off_the_heap, logger
from .entities.common import is_range, replace_columns
from .solvers.core import GradientError, SceneStateError, SimulationError


def _restored(table, source, envs):
    """``source`` (B, W) when ``envs`` is None, else a detached copy of ``table`` (B, W) whose
    rows ``envs`` come from ``source``."""
    if envs is None:
        return source
    out = table.detach().clone()
    rows = torch.as_tensor(envs, device=out.device)
    out[rows] = source[rows]
    return out


def _zero_unreached_envs(grad_outs, grads):
    """In a batched step's ``grads`` (tensors (B, …) or None), the rows of the envs that no
    gradient reaches (their output gradients ``grad_outs`` all exactly zero) set to zero, when some
    gradient is not finite: envs are independent, so zero is those rows' exact value, where the
    adjoints' 0 · NaN of an env whose state went non-finite gave NaN (and an input the envs share,
    a policy's weight, got NaN from an env its loss left out). Tested by each gradient's sum
    (NaN and inf carry through it; one overflowing only takes the exact path below, which changes
    nothing then): a third of an elementwise test's cost, ~20 µs a 256-env KUKA step."""
    grads = [g for g in grads if g is not None]
    if grads[0].shape[0] == 1 or all(math.isfinite(float(g.sum())) for g in grads):
        return
    reached = torch.zeros(grads[0].shape[0], dtype=torch.bool, device=grads[0].device)
    for out in grad_outs:
        reached |= (out != 0).flatten(1).any(dim=1)
    for g in grads:
        g[~reached] = 0.0


def refuse_inference_mode(what):
    """Raise under torch.inference_mode(): the states and inputs made there are inference tensors,
    which torch refuses to save for a backward or to change outside the mode (when version counters
    still told inputs apart, a control set there was taken, and every later step, outside the
    mode too, raised torch's own error from deep inside)."""
    if torch.is_inference_mode_enabled():
        raise SceneStateError(f"{what}: genesis_lite does not run under torch.inference_mode() (torch refuses to "
                              f"save the tensors made there for a backward); use torch.no_grad() instead")


class SolverSlot:
    """One solver with its current torch state/inputs and what Taichi holds of them."""

    def __init__(self, solver):
        self.solver = solver
        self.state = None  # (B, width) torch tensor; None: read lazily from Taichi
        self.inputs = None  # name → (B, width)
        self.input_names = ()  # the inputs' names in the solver's default_inputs order (set at build)
        self.uploaded_state = None  # the tensor Taichi's frame 0 equals (None: unknown)
        self.uploaded_inputs = None  # (tensor, ...): Taichi's inputs equal
        self.derived = None  # (state, value) cache of the last derived read
        self.warned_nonfinite = False  # _check_finite warned once since the last reset
        # the parameters the last reset detached from a graph and not set since (their names)
        self.detached_params = set()
        # the last step's readouts (solver.last_step_readouts: contacts, dofs forces and accelerations): (B,) bool of
        # the envs whose state a reset or setter replaced since (None: none), and the readouts as
        # the step left them, kept before a backward's replays overwrite the solver's (None: the
        # solver still holds them)
        self.replaced_envs = None
        self.held_readouts = None
        # (state, warm start): the solver's warm start for that state as the forward left it, kept
        # while a backward's replays overwrite the solver's (None: the solver holds it)
        self.held_warm_start = None
        # the setters' writes into the state since it last changed otherwise (a step, a reset),
        # made into a detached copy of it (None: none), and the (width,) bool mask of the columns
        # they wrote in every env (None: none yet; False: not tracked, no graph to cut): write_state
        self.fresh, self.written = None, None


class Simulator:
    def __init__(self, sim_options, solvers):
        self.options = sim_options
        self.requires_grad = sim_options.requires_grad
        self.slots = [SolverSlot(s) for s in solvers]
        self._slot_of = {slot.solver: slot for slot in self.slots}  # (setters and getters look one up)
        self.generation = 0
        self.step_index = 0
        # each step and full reset clears every env's transient inputs (an external wrench): the
        # count of those clears tells whether one set before is still pending (a partial reset keeps
        # the other envs')
        self.transient_clears = 0
        self.rollout = None
        self.segment = None  # the open autograd.Segment: the steps recorded since the state was last read or set
        self.started_from = []  # the solvers' warm starts the last forward_step started from
        self.replay_records = []  # and each solver's replay_record() after it
        self.warned_graph_cut = False  # _warn_graph_cut warned since the last reset
        self.warned_gradient = False  # check_first_gradients warned since the last reset
        self.warned_partial_reset = False  # _warn_partial_reset warned (once a scene)
        self.stepped_back = False  # a step's backward ran since the last reset
        self.rigid_solver = None  # Genesis's scene.sim.rigid_solver (rigid_solver.RigidSolverView), set by the scene
        self.coupler = None  # the coupling stage of the shared substep loop (solvers/coupler.py), set by the scene
        self.flat_input_names = ()  # (solver index, input name) of each of _grad_inputs' inputs (set at build)
        self._skipped = {}  # requires-grad flags of the flat inputs → _skipped_grads' sets

    def build(self, n_envs):
        for slot in self.slots:
            slot.initial_state = slot.solver.build(n_envs)
            slot.solver.own_state_pages = self.options.requires_grad and self.options.checkpoint_interval > 1
            slot.input_names = tuple(slot.solver.default_inputs)
            # when nothing (scene or autograd graph) can reach this simulator any more, its
            # solvers' arrays are freed (a graph's nodes may still hold a solver object)
            weakref.finalize(self, slot.solver.destroy)
        self.flat_input_names = tuple((k, name) for k, slot in enumerate(self.slots) for name in slot.input_names)
        if self.requires_grad:  # a rollout frees a state a step: keep its memory returnable
            keep_large_blocks_off_the_heap()
        self.reset()

    # -- state and inputs ---------------------------------------------------------------------
    def slot(self, solver):
        return self._slot_of[solver]

    def state(self, solver):
        if self.segment is not None:  # (reading the state makes the steps before it a node of the graph)
            self._close_segment()
        slot = self.slot(solver)
        if slot.state is None:
            slot.state = slot.uploaded_state = solver.download_state()
        return slot.state

    def set_state(self, solver, state, envs=None):
        """The state of ``solver`` ← state (B, width), of which the rows ``envs`` (int array; None:
        all) changed: a reset or a setter, after which those envs have no contacts until the next
        step (Genesis clears its collider when a state is set)."""
        refuse_inference_mode(f"setting the {type(solver).__name__}'s state")
        self._close_segment()  # (the other solvers' states stay in the graph)
        slot = self.slot(solver)
        if envs is not None and slot.held_warm_start is not None and slot.held_warm_start[0] is slot.state:
            solver.set_warm_start(slot.held_warm_start[1])  # the other envs keep theirs (upload_state)
        solver.upload_state(state, envs)
        if slot.replaced_envs is None:
            slot.replaced_envs = np.zeros(state.shape[0], dtype=bool)
        slot.replaced_envs[slice(None) if envs is None else envs] = True
        slot.state = slot.uploaded_state = state
        slot.derived = slot.held_warm_start = None
        slot.fresh, slot.written = None, None

    def write_state(self, solver, envs, columns, values):
        """State columns ``columns`` of the envs ``envs`` (int arrays) ← values (len(envs),
        len(columns)), out of place: a setter's write. A state in a graph is also written, write by
        write, into a detached copy of it (``fresh``: the writes alone, taken at the call in its
        grad mode); once those writes have written every column in every env, that copy, equal in
        value, becomes the state: written over by two setters (positions, then velocities), the
        state still led back through their index_put to the graph before, and a truncated-BPTT
        loop's backward to that chunk's freed graph."""
        slot = self.slot(solver)
        state = self.state(solver)
        fresh, written = slot.fresh, slot.written
        if written is None:  # the first write since: tracked when there is a graph to cut
            fresh, written = (state.detach(), np.zeros(state.shape[1], dtype=bool)) if state.requires_grad \
                else (None, False)
        if written is False:
            self.set_state(solver, replace_columns(state, envs, columns, values), envs)
            slot.written = False
            return
        fresh = replace_columns(fresh, envs, columns, values)
        if is_range(envs, state.shape[0]):  # (the columns written in every env count: the usual setter)
            written = written.copy()
            written[columns] = True
        if written.all():
            self.set_state(solver, fresh, None)
            slot.written = False  # (the state's graph reaches only what the writes gave: not tracked further)
        else:
            self.set_state(solver, replace_columns(state, envs, columns, values), envs)
            slot.fresh, slot.written = fresh, written  # (after set_state, which may raise and resets them)

    def inputs(self, solver):
        return self.slot(solver).inputs

    def set_input(self, solver, name, value):
        """Input ``name`` of ``solver`` ← value; the inputs derived from it (solver.derived_from:
        the rigid rows' scale from mass and armature) are recomputed, in the graph."""
        refuse_inference_mode(f"setting the {type(solver).__name__}'s input '{name}'")
        previous = self.slot(solver).inputs
        inputs = {**previous, name: value}
        if name in solver.derived_from:
            inputs = solver.derive_inputs(inputs, previous)
        slot = self.slot(solver)
        slot.inputs = inputs
        # a parameter set (or derived) anew is no longer the one a reset detached
        slot.detached_params = {n for n in slot.detached_params if inputs[n] is previous[n]}

    def _sync(self, slot, state, inputs):
        """Make Taichi hold ``state`` (None: what it holds) and ``inputs``, uploading only what differs."""
        self._sync_state(slot, state)
        pending = self._pending_inputs(slot, inputs)
        if pending is not None:
            slot.solver.upload_inputs(pending)

    @staticmethod
    def _sync_state(slot, state):
        """Upload ``state`` unless Taichi holds it; uploading clears the warm start, which is put
        back where a backward took it from this very state (so a rollout steps on after a backward
        bit for bit as without it)."""
        if state is not None and slot.uploaded_state is not state:
            slot.solver.upload_state(state)
            slot.uploaded_state = state
            if slot.held_warm_start is not None and slot.held_warm_start[0] is state:
                slot.solver.set_warm_start(slot.held_warm_start[1])

    @staticmethod
    def _pending_inputs(slot, inputs):
        """``inputs`` if Taichi does not hold them yet (recorded as held from now on), else None. By
        identity: inputs are never changed in place (every setter makes a new tensor)."""
        tensors = tuple(inputs.values())
        known = slot.uploaded_inputs
        if known is not None and len(known) == len(tensors) and all(map(operator.is_, tensors, known)):
            return None
        slot.uploaded_inputs = tensors
        return inputs

    # -- stepping ---------------------------------------------------------------------------
    def reset(self, states=None, envs=None):
        """Back to the initial states, or to ``states`` (one (B, width) tensor per solver), which
        become the initial states of every later reset. ``envs`` (int array): only those envs
        are reset, the others keep their current state (and controls).

        Controls are cleared, parameters kept. Everything is detached, so a new graph starts:
        a backward through the previous one raises, and a state taken mid-rollout brings no
        graph along (nor does a parameter: set differentiable ones after reset())."""
        self._close_segment()
        if envs is not None:
            self._warn_partial_reset(envs)
        self.stepped_back = False
        if states is not None:
            for slot, state in zip(self.slots, states):
                slot.initial_state = state.detach().clone()  # the caller's tensor may change later
        self.generation += 1
        self.step_index = 0
        self.transient_clears += envs is None
        self.clear_flags()
        self.rollout = autograd.Rollout(self, self.options.checkpoint_interval)
        self.warned_graph_cut = self.warned_gradient = False
        for slot in self.slots:
            slot.warned_nonfinite = False
            defaults = slot.solver.default_inputs
            current = slot.inputs or defaults
            # (kept from an earlier reset until set again or warned: a reset before the loop's first
            # finds them detached already)
            slot.detached_params |= {name for name in slot.solver.persistent_inputs
                                     if current[name].requires_grad and name not in slot.solver.derived_inputs}
            # (inputs derived from persistent ones are persistent too: detached, they still match)
            slot.inputs = {name: current[name].detach() if name in slot.solver.persistent_inputs
                           else _restored(current[name], defaults[name], envs) for name in defaults}
            current_state = None if envs is None else self.state(slot.solver)
            self.set_state(slot.solver, _restored(current_state, slot.initial_state, envs), envs)

    def _warn_partial_reset(self, envs):
        """A reset of some envs (int array) detaches every env, as a full one (a graph per env would
        cost a graph per env): a loss on the envs it kept then reaches nothing set before it, and
        torch's backward says only that the loss does not require grad. Warned once a scene, when it
        cuts a graph that no backward went through and keeps some env."""
        kept = len(set(np.asarray(envs).tolist())) < self.slots[0].solver.n_batch
        if not self.warned_partial_reset and kept and not self.stepped_back and any(
                (slot.state is not None and slot.state.requires_grad)
                or any(value.requires_grad for value in (slot.inputs or {}).values()) for slot in self.slots):
            self.warned_partial_reset = True
            logger.warning("scene.reset(envs_idx=...) starts a new autograd graph for every env, the ones it keeps "
                           "too: losses computed after it reach no tensor set before it; call backward before a "
                           "partial reset (warned once)")

    def clear_flags(self):
        """Drop the solvers' non-finite flags: steps taken again (a checkpoint's recompute) raise
        them for states their forward reported already; left, the next rollout's first step was
        blamed (and its one warning used up)."""
        for slot in self.slots:
            slot.solver.nonfinite()

    def step(self):
        if self.requires_grad:
            self._record_step()
        elif len(self.slots) == 1:  # the hot path of small scenes: no lists (~0.4 µs a step)
            slot = self.slots[0]
            self._sync_state(slot, slot.state)
            slot.solver.advance(self._pending_inputs(slot, slot.inputs))
            slot.state = slot.uploaded_state = None
        else:
            for slot in self.slots:
                self._sync_state(slot, slot.state)
            self._advance([self._pending_inputs(slot, slot.inputs) for slot in self.slots], download=False)
            for slot in self.slots:
                slot.state = None
                slot.uploaded_state = None
        for slot in self.slots:
            slot.derived = slot.replaced_envs = slot.held_readouts = slot.held_warm_start = None
            slot.fresh, slot.written = None, None
            for name in slot.solver.transient_inputs:  # (the build's tensor: no upload when unused)
                if slot.inputs[name] is not slot.solver.default_inputs[name]:
                    slot.inputs = {**slot.inputs, name: slot.solver.default_inputs[name]}
        # (counted first: a caught check_nan error, then another step, recorded two steps at one index)
        self.step_index += 1
        self.transient_clears += 1
        self._check_finite()

    def _record_step(self):
        """One step, recorded in the open autograd.Segment (a new one after the state was read or
        set; under torch.no_grad(), one of its own that makes no node)."""
        recording = torch.is_grad_enabled()
        flat_inputs = self._grad_inputs()
        segment, follows = self.segment, True
        if segment is None or not recording:
            self._close_segment()
            states = tuple(self.state(slot.solver) for slot in self.slots)
            if not recording:
                self._warn_graph_cut(states + flat_inputs)
            segment = self.segment = autograd.Segment(self.rollout, states, recording)
            follows = self.rollout.follows(states)
        wanted = segment.flags(flat_inputs)
        kept = self.rollout.keeps_state(self.step_index, follows)
        outs = self.forward_step(segment.outputs, flat_inputs, record=kept and wanted is not None)
        self.rollout.record(self.step_index, segment.outputs, flat_inputs, kept, tuple(self.started_from))
        segment.add(self, self.step_index, flat_inputs, wanted, kept, outs)
        for slot, out in zip(self.slots, outs):
            slot.state = slot.uploaded_state = out
        if not recording:
            self._close_segment()

    def _close_segment(self):
        """The open segment's steps become one node of the graph (autograd.Segment.close; if that
        raises, the segment stays open)."""
        if self.segment is not None:
            self.segment.close(self)
            self.segment = None  # (not before: see close)

    def _warn_graph_cut(self, tensors):
        """A step under torch.no_grad() is not recorded, as any torch op there: what required grad
        before it reaches no later loss through it. Legitimate (a warm-up), but easy to do by
        accident (a step inside an evaluation block), so warned once per rollout when it cuts a
        graph."""
        if not self.warned_graph_cut and any(t.requires_grad for t in tensors):
            self.warned_graph_cut = True
            logger.warning(f"scene.step() under torch.no_grad() at step {self.step_index}: the step is not "
                           f"recorded, so gradients of later losses stop here (state and inputs set before "
                           f"it get none through it)")

    def _grad_inputs(self):
        """Every solver's inputs, in its default_inputs' order, as one tuple."""
        # (C-level calls: a step's ~30 inputs a solver)
        return tuple(itertools.chain.from_iterable(map(slot.inputs.__getitem__, slot.input_names)
                                                   for slot in self.slots))

    def _split_inputs(self, flat):
        out, k = [], 0
        for slot in self.slots:
            out.append(dict(zip(slot.input_names, flat[k: k + len(slot.input_names)])))
            k += len(slot.input_names)
        return out

    def warm_starts(self):
        """Each solver's warm start (solver.warm_start()), as a tuple."""
        return tuple(slot.solver.warm_start() for slot in self.slots)

    def forward_step(self, states, flat_inputs, warm_starts=None, record=True):
        """One step from the given states and inputs (no graph), and from ``warm_starts`` when
        given (else what the solvers hold); returns the new states. ``started_from`` keeps the
        warm starts the step started from (a checkpoint's, to take the steps after it again),
        ``replay_records``, when ``record``, what lets its backward's replay repeat it
        (solver.replay_record(); else Nones)."""
        self.started_from, pending = [], []
        for k, (slot, state, inputs) in enumerate(zip(self.slots, states, self._split_inputs(flat_inputs))):
            self._sync_state(slot, state)  # uploading a state clears the warm start
            if warm_starts is not None:
                slot.solver.set_warm_start(warm_starts[k])
            self.started_from.append(slot.solver.warm_start())
            pending.append(self._pending_inputs(slot, inputs))
        outs = self._advance(pending, download=True)
        self.replay_records = [slot.solver.replay_record() if record else None for slot in self.slots]
        for slot, out in zip(self.slots, outs):
            slot.uploaded_state = out
        return tuple(outs)

    def _advance(self, inputs, download):
        """One step of every solver from the uploaded states, after uploading ``inputs`` (one dict
        or None per solver): a solver alone advances on its own, several share the substep loop
        (solvers/base.py); returns the new states when ``download`` (else Nones)."""
        if len(self.slots) == 1:
            return [self.slots[0].solver.advance(inputs[0], download=download)]
        solvers = [slot.solver for slot in self.slots]
        for solver, pending in zip(solvers, inputs):
            solver.begin_step(pending)
        for s in range(self.options.substeps):
            for solver in solvers:
                solver.substep_pre_coupling(s)
            if self.coupler is not None:  # rigid shapes of moving links and the MPM grid (solvers/coupler.py)
                self.coupler.couple(s)
            for solver in solvers:
                solver.substep_post_coupling(s)
        return [solver.end_step(download) for solver in solvers]

    def backward_step(self, states, flat_inputs, grad_states, warm_starts, records, wanted):
        """Gradients of one step's states and of the flat inputs whose ``wanted`` flag is True (in
        their order), given the gradients of its outputs and, per solver, its replay record or
        else the warm start it started from (its replay then repeats it exactly; None for both
        where the solver needs neither). The caller holds what the last step left first
        (hold_before_backward)."""
        split = self._split_inputs(flat_inputs)
        self.stepped_back = True
        try:
            for slot, skipped in zip(self.slots, self._skipped_grads(wanted)):
                slot.solver.skipped_grads = skipped
            if len(self.slots) == 1:
                results = [self.slots[0].solver.backward(states[0], split[0], grad_states[0], warm_starts[0],
                                                         records[0])]
            else:
                results = self._backward_shared(states, split, grad_states, warm_starts, records)
        finally:  # (also when it raised midway: the next step is a forward one, from its own state)
            for slot in self.slots:
                slot.uploaded_state = slot.uploaded_inputs = None  # Taichi holds this old step now
                slot.solver.skipped_grads = frozenset()
                slot.solver.end_backward()
        grads = [grad_state for grad_state, _ in results]
        # (a few of ~30 inputs a solver)
        grads += [results[solver][1].get(name) for solver, name in itertools.compress(self.flat_input_names, wanted)]
        _zero_unreached_envs(grad_states, grads)
        return grads

    def _skipped_grads(self, wanted):
        """Per solver, the names of its inputs whose flag in ``wanted`` is False (solver.skipped_grads),
        kept per pattern of flags: a rollout has a few, and the sets cost ~3 µs a step."""
        skipped = self._skipped.get(wanted)
        if skipped is None:
            if len(self._skipped) >= 64:  # (patterns that come and go)
                self._skipped.clear()
            skipped = self._skipped[wanted] = [
                frozenset(name for (solver, name), want in zip(self.flat_input_names, wanted) if solver == k and not want)
                for k in range(len(self.slots))]
        return skipped

    def check_first_gradients(self, grads):
        """After the backward of a rollout's first step (its gradients ``grads``, tensors or None):
        parameters its reset detached warn (_check_detached_parameters); a gradient that is not
        finite warns once a rollout. An unstable forward (MPM's stability warning at
        build) can stay finite while its exact derivative overflows (sand at E 1e8: particles at 700
        m/s, the gradient inf by step 19), which nothing else would say. A warning, not an error,
        also under check_nan: the state's gradient holds columns no input requiring grad reaches
        (a loss with an infinite slope in one body's pose leaves another's inputs finite). Checked
        once a backward, not each step (a reduction over the state: a tenth of a small scene's
        reverse step)."""
        self._check_detached_parameters()
        if self.warned_gradient or all(g is None or bool(torch.isfinite(g).all()) for g in grads):
            return
        self.warned_gradient = True
        logger.warning("the gradient reaching the rollout's first step is not finite (inf or NaN) in some entries: "
                       "the loss's own slope, a state that went non-finite, or an unstable forward whose exact "
                       "derivative overflowed (reduce dt; see the warnings at build and in the rollout); check the "
                       "gradients of your inputs")

    def _check_detached_parameters(self):
        """Warn (once a rollout: the reset after it no longer finds them in a graph) when the reset
        that began the rollout detached parameters set from tensors requiring grad and none was set
        again: the loss being differentiated cannot reach those tensors, whose .grad then stays
        as it was, silently (a friction set once before a loop of reset, rollout, backward)."""
        lost = [f"{type(slot.solver).__name__}'s {', '.join(sorted(slot.detached_params))}" for slot in self.slots
                if slot.detached_params]
        if lost:
            for slot in self.slots:
                slot.detached_params = set()
            logger.warning(f"scene.reset() detached the parameters set before it from tensors requiring grad "
                           f"({'; '.join(lost)}), and they were not set again: this backward does not reach those "
                           f"tensors (they keep their values, not their graph); set them after reset() to train "
                           f"them")

    def _backward_shared(self, states, inputs, grad_states, warm_starts, records):
        """The shared substep loop's reverse (solvers/base.py): load, replay, then mirror order."""
        solvers = [slot.solver for slot in self.slots]
        replayed = False
        while not replayed:  # (again when a solver's replay storage grew: Solver.replay_again)
            for solver, state, pending, grad, warm_start, record in zip(solvers, states, inputs, grad_states,
                                                                        warm_starts, records):
                solver.begin_reverse(state, pending, grad, warm_start, record)
            self._advance([None] * len(solvers), download=False)
            replayed = not any([solver.replay_again() for solver in solvers])
        for solver in solvers:  # (before any reverse stage: one that raised would leave a solver half reversed)
            solver.check_replay()
        for s in reversed(range(self.options.substeps)):
            for solver in reversed(solvers):
                solver.substep_post_coupling_backward(s)
            if self.coupler is not None:
                self.coupler.couple_backward(s)
            for solver in reversed(solvers):
                solver.substep_pre_coupling_backward(s)
        return [solver.end_reverse() for solver in solvers]

    def _check_finite(self):
        """With check_nan, raise at the first non-finite state; without, warn once per solver that
        watches its state (Solver.watches_nonfinite: the rigid solver where its flag is on the host,
        MPM always, as its particles stay inside the walls, NaN or not)."""
        for slot in self.slots:
            if not (self.options.check_nan or slot.solver.watches_nonfinite) or not slot.solver.nonfinite():
                continue
            message = (f"step {self.step_index - 1}: the {type(slot.solver).__name__} state became non-finite "
                       f"(entities: {', '.join(self._nonfinite_entities(slot))}); reduce dt, check inputs and "
                       f"parameters")
            if self.options.check_nan:
                raise SimulationError(message)
            if not slot.warned_nonfinite:
                slot.warned_nonfinite = True
                why = f": {slot.solver.hides_nonfinite}" if slot.solver.hides_nonfinite else ""
                logger.warning(f"{message}{why}; SimOptions(check_nan=True) raises here")

    def _nonfinite_entities(self, slot):
        """The names of the entities whose state is not finite in some env (every entity of the
        solver where none is: a non-finite value the state does not hold)."""
        state = self.state(slot.solver).detach()
        names = [name for name, columns in slot.solver.entity_columns()
                 if not bool(torch.isfinite(state[:, torch.as_tensor(columns, device=state.device)]).all())]
        return names or slot.solver.entity_names

    # -- derived quantities -------------------------------------------------------------------
    def derived(self, solver):
        """Link kinematics (B, L, 13) of the current state, differentiable when it requires grad."""
        slot = self.slot(solver)
        state = self.state(solver)
        graph = self.requires_grad and torch.is_grad_enabled() and state.requires_grad
        # a value read under torch.no_grad() (a camera's, a logger's) serves no later read that needs the graph
        if slot.derived is None or slot.derived[0] is not state or (graph and slot.derived[1].grad_fn is None):
            if graph:
                value = autograd.read(self, solver, state)
            else:
                value = self.read_derived(solver, state)
            slot.derived = (state, value)
        return slot.derived[1]

    def read_derived(self, solver, state):
        slot = self.slot(solver)
        self._sync(slot, state, slot.inputs)
        return solver.links_kinematics()

    def at_state(self, solver, compute):
        """``compute()`` with Taichi holding the scene's current state and inputs of ``solver``
        (a kernel that reads them and makes no graph: inverse kinematics)."""
        state = self.state(solver)
        slot = self.slot(solver)
        self._sync(slot, state, slot.inputs)
        return compute()

    def read_derived_backward(self, solver, state, grad):
        slot = self.slot(solver)
        self.hold_before_backward()  # (state may be an older one: its upload clears the warm start)
        self._sync(slot, state, slot.inputs)
        out = solver.links_kinematics_backward(grad)
        slot.uploaded_state = None
        _zero_unreached_envs([grad], [out])
        return out

    def mass_matrix(self, solver):
        """(B, D, D) joint-space mass matrix, armature on its diagonal, at the current state
        (solver.mass_matrix); not differentiable (see _query)."""
        return self._query(solver, "get_mass_mat", solver.mass_matrix)

    def dofs_force(self, solver):
        """(B, D) the last step's generalised dof forces, constraint forces included
        (solver.dofs_dynamics' row 0; see _last_step)."""
        return self._last_step(solver, "get_dofs_force", "dofs_dynamics")[:, 0]

    def dofs_acc(self, solver):
        """(B, D) the accelerations the last step integrated (solver.dofs_dynamics' row 1; see
        _last_step)."""
        return self._last_step(solver, "get_dofs_acc", "dofs_dynamics")[:, 1]

    def links_acc(self, solver, what):
        """(B, L, 6) the last step's links' classical linear and angular accelerations (solver.links_acc;
        see _last_step)."""
        return self._last_step(solver, what, "links_acc")

    def contacts(self, solver, what, trimmed=False):
        """(B, W, 12) the last step's contacts (solver.contacts, trimmed or not; see _last_step: after
        a backward, the held ones, all C slots)."""
        return self._last_step(solver, what, "contacts", trimmed=trimmed)

    def links_contact_force(self, solver, what):
        """(B, L, 3) the last step's contact force on each link (solver.links_contact_force; see
        _last_step)."""
        return self._last_step(solver, what, "links_contact_force")

    def _last_step(self, solver, what, readout, **options):
        """The last step's ``readout`` (one of solver.last_step_readouts), as if no step had been
        taken in the envs replaced since (set_state: reset, setters), as a value whose backward
        raises when the state requires grad: read-outs of the step's collision and constraint
        solve, not differentiable (the state's gradient carries their effect), and a gradient must
        never stop silently."""
        slot = self.slot(solver)
        value = getattr(solver, readout)(**options) if slot.held_readouts is None else slot.held_readouts[readout]
        if slot.replaced_envs is not None:
            value = solver.without_last_step(readout, value, torch.as_tensor(slot.replaced_envs, device=value.device))
        return value if slot.state is None else autograd.not_differentiable(what, self.state(solver), value)

    def hold_before_backward(self):
        """Keep what a backward's replays and uploads overwrite of the last step: each solver's
        last-step readouts, and its warm start while Taichi still holds the scene's state (the
        forward's then; a replayed step or an upload of an older state has cleared it)."""
        for slot in self.slots:
            if slot.held_readouts is None:
                slot.held_readouts = {name: getattr(slot.solver, name)() for name in slot.solver.last_step_readouts}
            self._hold_warm_start(slot)

    @staticmethod
    def _hold_warm_start(slot):
        """Keep the solver's warm start with the scene's state while Taichi holds that state (the
        warm start is then the forward's), unless one is kept already."""
        if slot.held_warm_start is None and slot.uploaded_state is slot.state:
            slot.held_warm_start = (slot.state, slot.solver.warm_start())

    def _query(self, solver, what, compute):
        """``compute()`` at the current state and inputs, as a value whose backward raises when
        the state or any input requires grad: it depends on all of them, and a gradient must
        never stop silently."""
        value = self.at_state(solver, compute)
        state, slot = self.state(solver), self.slot(solver)
        anchor = next((t for t in (state, *slot.inputs.values()) if t.requires_grad), state)
        return autograd.not_differentiable(what, anchor, value)

    def check_grad_allowed(self, value, entity, arg):
        if isinstance(value, torch.Tensor) and value.requires_grad and not self.requires_grad:
            raise GradientError(f"entity '{entity}': argument '{arg}' requires grad but the scene was built without "
                                f"gradients; create it with gs.Scene(sim_options=gs.options.SimOptions("
                                f"requires_grad=True))")
