"""torch.autograd nodes around the solvers.

A differentiable ``scene.step()`` runs at once and is recorded in the open ``Segment``; reading
the state (a getter, a setter, a reset) closes it into one ``_Segment`` node: its inputs are every
solver's state at the start of its first step and the inputs (controls, parameters) that required
grad in its steps, all torch tensors; its outputs are the states after its last step. So a
rollout read at its end is one node, and one read every step a node a step. The node keeps only
what torch saves for it (each step's start state and replay record: ``solver.replay_record()``,
where the rigid constraint solves ended, so that the backward's replay repeats the forward exactly
without iterating; bounded to a few states, else the warm start the step started from) and the
input tensors its steps were given, so a rollout's memory is about one state per step, and
nothing but those inputs outlives the backward: zeroing and freeing are torch's. Getters of
derived quantities (link poses) are ``_Read`` nodes.

With ``SimOptions(checkpoint_interval=k)``, only every k-th step saves its state; a step
without one is recomputed during backward from the nearest checkpoint, which its node saved
with the inputs of the steps between (``Segment._take_replay``: the ``Rollout`` itself holds one
interval; a backward that stops early, as ``autograd.grad`` of a late input, leaves at most an
interval of recomputed states there until its next recomputation). A step whose start state is
not what the step before it returned (a setter replaced it in between) saves its state too: a
recomputation from an earlier checkpoint would not repeat the setter.

Nodes hold the simulator weakly: the simulator holds the newest state, whose grad_fn is a node,
and a strong link back would be a cycle through torch's C++ graph that Python's collector
cannot see (every scene would live for ever).
"""
import collections
import itertools
import operator
import weakref

import torch

from .solvers.core import GradientError

_REQUIRES_GRAD = operator.attrgetter("requires_grad")
# A step a Segment keeps: its index in the rollout; whether it kept its start states, and where they
# (then its replay layout's tensors) are in the segment's saved tensors; its flat inputs as given,
# their requires-grad flags, and the positions of those requiring grad in the segment's tracked
_StepRecord = collections.namedtuple("_StepRecord", "index kept first layout inputs wanted positions")


class Rollout:
    """Per-rollout record (one per ``scene.reset()``): with checkpoint_interval > 1, the newest
    checkpointed state and the inputs of the steps since, from which a segment takes what its
    recomputations need (Segment._take_replay): the rollout itself keeps no more than a checkpoint
    interval."""

    def __init__(self, sim, interval):
        self.sim, self.interval = weakref.ref(sim), interval
        self.generation = sim.generation
        self.checkpoints = {}  # step index → (states at its start (tuple of tensors), warm starts): the newest
        self.inputs = {}  # step index → inputs, of the steps from the newest checkpoint on (interval > 1)
        self._replayed = {}  # step index → (start states, warm starts, replay records) recomputed during backward
        self._last_outputs = ()  # weak references to the states the last closed segment returned
        self._last_inputs = ((), ())  # the newest step's inputs as given (weakly held), and as recorded

    def follows(self, states):
        """Whether ``states`` are the ones the last closed segment returned."""
        return len(self._last_outputs) == len(states) and all(
            ref() is state for ref, state in zip(self._last_outputs, states))

    def keeps_state(self, index, follows):
        """Whether step ``index`` keeps its start states: every interval-th step, and a step whose
        start states do not follow the step before's (``follows`` False: a setter replaced them
        between the two steps, which no recomputation from an earlier checkpoint repeats)."""
        return self.interval == 1 or index % self.interval == 0 or not follows

    def record(self, index, states, inputs, kept, warm_starts):
        if self.interval > 1:  # detached: an input computed from a state would close a cycle through the graph
            if kept:  # (the segments took what they need from before: a long rollout holds one interval)
                self.checkpoints, self.inputs = {}, {}
            given, recorded = self._last_inputs
            same = len(given) == len(inputs)
            # an input given again (a parameter, a control held) shares the step before's record: a
            # detached view a step was ~4 KB of objects (a pendulum's 32-byte state: 11.7 KB a step,
            # more than without checkpoints)
            self.inputs[index] = tuple(recorded[k] if same and t is given[k]() else t.detach()
                                       for k, t in enumerate(inputs))
            # (weakly: an input computed from a state leads through the graph back to this rollout)
            self._last_inputs = (tuple(weakref.ref(t) for t in inputs), self.inputs[index])
            if kept:
                self.checkpoints[index] = (tuple(s.detach() for s in states), warm_starts)

    def stepped(self, outputs):
        """The newest segment returned ``outputs`` (held weakly: a strong link from the rollout, which
        every node of the graph holds, to a state whose grad_fn is a node would be a cycle)."""
        self._last_outputs = tuple(weakref.ref(o) for o in outputs)

    def start_states(self, index, checkpoints, inputs):
        """(states, warm starts, replay records) of step ``index``, recomputed from the checkpoint
        before it (from its warm starts too: the same steps again, bit for bit) in ``checkpoints``
        through the steps' ``inputs`` (a segment's: Segment._take_replay); the steps up to the next
        checkpoint are kept for the calls that follow (backward goes down the steps). The last of
        them was not taken again: its records are None (its replay solves from the warm starts)."""
        if index not in self._replayed:
            first = max(k for k in checkpoints if k <= index)
            states, warm_starts = checkpoints[first]
            self._replayed = {}
            sim = _alive(self.sim)
            with torch.no_grad():
                k = first
                while k + 1 in inputs and k + 1 not in checkpoints:
                    following = sim.forward_step(states, inputs[k], warm_starts)
                    if k > first:  # (a checkpoint's step keeps its states: held here, they outlived the graph)
                        self._replayed[k] = (states, warm_starts, tuple(sim.replay_records))
                    states, warm_starts = following, sim.warm_starts()
                    k += 1
                self._replayed[k] = (states, warm_starts, (None,) * len(states))
            sim.clear_flags()  # (those steps' forward reported their non-finite states)
        return self._replayed.pop(index)


def _alive(sim_ref):
    sim = sim_ref()
    if sim is None:
        raise GradientError("backward through a scene that no longer exists: keep the scene (or call backward) "
                            "until the gradients are computed")
    return sim


def _check_generation(sim, generation, what):
    if sim.generation != generation:
        raise GradientError(f"backward through {what} recorded before scene.reset(): the graph belongs to a "
                            f"finished rollout; compute the loss and call backward before resetting the scene")


class Segment:
    """The steps taken since the scene's state was last read (or set): they run at once, and
    become one autograd node when the state is read (``close``), so that a rollout read at its
    end pays torch's per-node costs once (with our node bookkeeping, ~50–65 µs of a pendulum's
    ~225 µs forward and backward step, measured 2026-12-02). Per step it keeps the inputs as
    given (held, not saved: they are the simulator's own tensors, made new by every setter, and
    mostly the same objects every step), which of them require grad, and, for a step that keeps its start state (see
    Rollout.keeps_state), that state and its replay record, saved by torch with the node (freed by
    the backward)."""

    def __init__(self, rollout, states, recording):
        self.rollout, self.start_states, self.outputs = rollout, states, states
        self.recording = recording  # taken with grad enabled (torch.is_grad_enabled()) at its first step
        # some state or input of its steps requires grad: its steps are kept from the first such one
        self.live = recording and any(map(_REQUIRES_GRAD, states))
        self.steps = []  # _StepRecord of each step kept
        self.saved = []  # the kept steps' start states and replay records, saved with the node
        self.tracked = []  # the distinct inputs requiring grad, in the order the node takes them
        self._position = {}  # id(tracked input) → its position in tracked
        self._patterns = {}  # the steps' requires-grad flags, each pattern once
        # (checkpoint_interval > 1) what the recomputation of its steps that keep no start states
        # needs, taken from the rollout as they are recorded: the checkpoints they start from
        # (index → (states, warm starts); saved with the node at close: base_indices, base_layout)
        # and the inputs of the steps from the first of them on (index → inputs, detached)
        self.bases, self.replay = {}, {}
        self.base_indices = self.base_layout = None

    def flags(self, inputs):
        """The requires-grad flags of a next step's ``inputs`` (flat tuple), or None when the segment
        will not keep that step: nothing before it or in it requires grad (torch makes no node of
        such a step; kept, a rollout stepped in a scene with requires_grad but no tensor requiring
        grad, an evaluation, held a state a step until the next read: found by an adversarial pass)."""
        wanted = tuple(map(_REQUIRES_GRAD, inputs))
        if not self.live:
            if not (self.recording and any(wanted)):
                return None
            self.live = True
        return self._patterns.setdefault(wanted, wanted)  # (one tuple for the steps that share it: ~270 bytes a step)

    def add(self, sim, index, inputs, wanted, kept, outputs):
        """Record step ``index`` that went from ``self.outputs`` to ``outputs`` with ``inputs``
        (flat tuple) and their requires-grad flags ``wanted`` (``flags``; None: a step not kept,
        from whose end the segment starts anew), after sim.forward_step."""
        if wanted is None:
            self.start_states = self.outputs = outputs
            return
        positions = tuple(self._track(t) for t in itertools.compress(inputs, wanted))
        if self.rollout.interval > 1:
            self._take_replay(index, kept)
        first, layout = len(self.saved), None
        if kept:  # each solver's replay record, or where it has none the warm start its step started from
            self.saved.extend(self.outputs)
            records = tuple(sim.replay_records)
            if any(record is not None or warm is not None for warm, record in zip(sim.started_from, records)):
                layout = _flatten((tuple(None if record is not None else warm
                                         for warm, record in zip(sim.started_from, records)), records), self.saved)
        self.steps.append(_StepRecord(index, kept, first, layout, inputs, wanted, positions))
        self.outputs = outputs

    def _take_replay(self, index, kept):
        """Take from the rollout what recomputing step ``index`` needs (the rollout lets go of it at
        its next checkpoint): its checkpoint if it keeps one, else, for the first such step, the
        checkpoint before it and the inputs of the steps between; and the step's inputs."""
        rollout = self.rollout
        if kept:
            self.bases[index] = rollout.checkpoints[index]
        elif not self.bases:
            base = max(rollout.checkpoints)  # (the rollout's only one: the newest, before index)
            self.bases[base] = rollout.checkpoints[base]
            self.replay.update((k, rollout.inputs[k]) for k in range(base, index))
        self.replay[index] = rollout.inputs[index]

    def _track(self, tensor):
        position = self._position.get(id(tensor))
        if position is None:
            position = self._position[id(tensor)] = len(self.tracked)
            self.tracked.append(tensor)  # (held: its id stays its own)
        return position

    def close(self, sim):
        """Make the node of these steps, whose outputs are the states after the last step (no node
        when it kept none). Then the segment lets go of those states and of its saved tensors: the
        node holds the segment, a strong link from it to its own outputs would be a cycle through torch's
        graph (see the module's docstring), and torch frees the saved ones with the backward. When
        the node cannot be made (a saved-tensor hook raised, an interrupt), this raises and the
        segment stays as it was, for the next read to close it (it replaces the half-made node
        torch may have given the states; dropped, a backward through them raised an IndexError:
        found by a review)."""
        if self.steps:
            if self.bases:  # saved with the node, so that torch frees them with the graph
                self.base_indices = tuple(self.bases)
                self.base_layout = _flatten(tuple(self.bases.values()), self.saved)
            with torch.enable_grad():
                _Segment.apply(sim, self, *self.start_states, *self.tracked)
        self.rollout.stepped(self.outputs)
        self.outputs = self.start_states = self.saved = self.bases = None


class _Segment(torch.autograd.Function):
    @staticmethod
    def forward(ctx, sim, segment, *tensors):
        ctx.sim, ctx.segment = weakref.ref(sim), segment
        # (where each input's gradient goes: _first_wanted; False for one that requires none)
        ctx.edges = tuple(t.grad_fn if t.requires_grad else False for t in tensors)
        # saved as tensors, torch frees them with the graph (attributes of ctx would outlive the backward)
        ctx.save_for_backward(*segment.saved)
        return segment.outputs

    @staticmethod
    def backward(ctx, *grad_states):
        sim, segment, grad_outs = _alive(ctx.sim), ctx.segment, grad_states
        _check_generation(sim, segment.rollout.generation, f"step {segment.steps[-1].index}")
        sim.hold_before_backward()  # the recomputations and replays below overwrite what the last step found
        saved, n_states = ctx.saved_tensors, len(grad_states)
        grads_tracked = [None] * len(segment.tracked)
        first_wanted = _first_wanted(segment, ctx.edges[:n_states], ctx.edges[n_states:])
        bases = None if segment.base_layout is None else \
            dict(zip(segment.base_indices, _unflatten(segment.base_layout, saved)))
        for index, kept, first, layout, inputs, wanted, positions in reversed(segment.steps[first_wanted:]):
            if kept:
                states = saved[first: first + n_states]
                warm_starts, records = (None,) * n_states, (None,) * n_states
                if layout is not None:
                    warm_starts, records = _unflatten(layout, saved)
            else:
                if torch.is_grad_enabled():  # (its start states come from a detached recomputation: see _first_order)
                    raise GradientError(_second_order_message(f"step {index}") + "; with checkpoint_interval > 1 "
                                        "create_graph=True raises at once")
                states, warm_starts, records = segment.rollout.start_states(index, bases, segment.replay)
            with torch.no_grad():
                try:
                    grads = sim.backward_step(states, inputs, grad_states, warm_starts, records, wanted)
                except GradientError as error:  # (which step of the rollout)
                    raise GradientError(f"step {index}'s backward: {error}") from None
            grad_states = grads[:n_states]
            for position, grad in zip(positions, grads[n_states:]):
                held = grads_tracked[position]
                if grad is not None:
                    grads_tracked[position] = grad if held is None else held + grad
            if index == 0:
                sim.check_first_gradients(grads)
        if first_wanted > 0:  # (no gradient of the start states is wanted)
            grad_states = (None,) * n_states
        return (None, None) + _first_order(f"step {segment.steps[0].index}", (*grad_states, *grads_tracked),
                                           (*grad_outs, *saved, *segment.tracked))


def _first_wanted(segment, state_edges, tracked_edges):
    """The position in segment.steps of the first step whose reverse this backward needs: 0 when
    the start states' gradient is wanted, else the first step given an input whose gradient is.
    torch prunes a graph to the paths that reach what a backward asks for (``autograd.grad(loss,
    [a late control])``), and a node a step ran only the steps after the control; a segment asks
    torch's engine which of its inputs' nodes it will run (``_will_engine_execute_node``, which
    torch's own checkpointing uses; every input here has a node: setters make them, none is a
    leaf; a leaf's edge, None, counts as wanted). Found by an adversarial pass: the whole segment
    ran, and a step before the control without an exact gradient raised."""
    will_run = getattr(torch._C, "_will_engine_execute_node", None)

    def needed(edge):
        if edge is False:
            return False
        try:
            return edge is None or will_run is None or will_run(edge)
        except RuntimeError:  # (where torch cannot tell: as wanted)
            return True

    if any(map(needed, state_edges)):
        return 0
    wanted = {k for k, edge in enumerate(tracked_edges) if needed(edge)}
    return next((k for k, step in enumerate(segment.steps) if not wanted.isdisjoint(step.positions)),
                len(segment.steps))


def _flatten(tree, tensors):
    """``tree`` (tensors and Nones in nested tuples and lists) with each tensor replaced by its
    index in ``tensors``, to which it is appended."""
    if isinstance(tree, torch.Tensor):
        tensors.append(tree)
        return len(tensors) - 1
    if isinstance(tree, (tuple, list)):
        return tuple(_flatten(branch, tensors) for branch in tree)
    return None


def _unflatten(layout, tensors):
    """The tree ``_flatten`` took apart (its lists as tuples)."""
    if isinstance(layout, int):
        return tensors[layout]
    if isinstance(layout, tuple):
        return tuple(_unflatten(branch, tensors) for branch in layout)
    return None


class _Read(torch.autograd.Function):
    """A derived quantity of one solver's state (e.g. link poses), differentiable in the state."""

    @staticmethod
    def forward(ctx, sim, solver, generation, state):
        ctx.sim, ctx.solver, ctx.generation = weakref.ref(sim), solver, generation
        ctx.save_for_backward(state)
        return sim.read_derived(solver, state)

    @staticmethod
    def backward(ctx, grad):
        sim = _alive(ctx.sim)
        _check_generation(sim, ctx.generation, "a link getter")
        (state,) = ctx.saved_tensors
        with torch.no_grad():
            grad_state = sim.read_derived_backward(ctx.solver, state, grad)
        return None, None, None, *_first_order("a link getter", (grad_state,), (grad, state))


def read(sim, solver, state):
    return _Read.apply(sim, solver, sim.generation, state)


class _NotDifferentiable(torch.autograd.Function):
    """Passes a value through; its backward raises, so no gradient stops silently."""

    @staticmethod
    def forward(ctx, message, value, *anchors):
        ctx.message = message
        return value.clone()

    @staticmethod
    def backward(ctx, grad):
        raise GradientError(ctx.message)


def not_differentiable(what, anchor, value):
    """Attach ``value`` (computed from ``anchor``, a tensor of the graph) to the graph with a
    backward that raises."""
    if not anchor.requires_grad:
        return value
    return _NotDifferentiable.apply(
        f"{what} is not differentiable; detach it (.detach()) before using it in a loss", value, anchor)


def _first_order(what, grads, anchors):
    """A backward's results ``grads``, computed from ``anchors`` (its output gradients, saved
    tensors and inputs): as they are, unless torch asked for a graph of them (``create_graph=True``); then each
    is attached to every anchor that requires grad through a node whose backward raises. The
    simulator's gradients are first-order only, and torch's ``once_differentiable`` is not enough:
    its error node hangs off the results alone, so ``torch.autograd.grad(g, inputs=...)`` pruned it
    whenever another path led to the inputs and the simulator's second-order part dropped out of a
    mixed derivative without a word (5.6 % off the finite difference, found by an adversarial
    pass). A step that kept no start state (checkpoint_interval > 1) has none to anchor to (it is
    recomputed, detached, from the checkpoint): its backward raises at once under create_graph
    (the simulator's part of a mixed derivative dropped out there too, found by a review)."""
    if not torch.is_grad_enabled():
        return grads
    anchors = [a for a in anchors if isinstance(a, torch.Tensor) and a.requires_grad]
    if not anchors:
        return grads
    message = _second_order_message(what) + " and is being differentiated again"
    return tuple(g if g is None else _NotDifferentiable.apply(message, g, *anchors) for g in grads)


def _second_order_message(what):
    return (f"second derivatives through the simulator are not supported: the gradient of {what} was taken "
            f"with create_graph=True")
