"""torch.autograd nodes around the solvers.

Each ``scene.step()`` is one ``_Step`` node: inputs are every solver's state at the start of
the step and its differentiable inputs (controls, parameters) — all torch tensors; outputs are
the states after the step. A node keeps only what torch saves for it (its start state and its
inputs) and each solver's replay record (``solver.replay_record()``: where the rigid constraint
solves ended, so that the backward's replay repeats the forward exactly without iterating; bounded
to a few states, else the warm start the step started from), so a rollout's
memory is about one state per step, and nothing outlives the graph: zeroing and freeing are
torch's. Getters of derived quantities (link poses) are ``_Read`` nodes.

With ``SimOptions(checkpoint_interval=k)``, only every k-th step saves its state; a step
without one is recomputed from the nearest checkpoint by its ``Rollout`` during backward. A step
whose start state is not what the step before it returned (a setter replaced it in between)
saves its state too: a recomputation from an earlier checkpoint would not repeat the setter.

Nodes hold the simulator weakly: the simulator holds the newest state, whose grad_fn is a node,
and a strong link back would be a cycle through torch's C++ graph that Python's collector
cannot see (every scene would live for ever).
"""
import itertools
import operator
import weakref

import torch

from .solvers.core import GradientError

_REQUIRES_GRAD = operator.attrgetter("requires_grad")


class Rollout:
    """Per-rollout record (one per ``scene.reset()``): checkpointed states and step inputs."""

    def __init__(self, sim, interval):
        self.sim, self.interval = weakref.ref(sim), interval
        self.generation = sim.generation
        self.checkpoints = {}  # step index → (states at its start (tuple of tensors), warm starts)
        self.inputs = {}  # step index → inputs (only when interval > 1)
        self._replayed = {}  # step index → (start states, warm starts, replay records) recomputed during backward
        self._last_outputs = ()  # weak references to the states the newest step returned
        self._last_inputs = ((), ())  # the newest step's inputs as given (weakly held), and as recorded

    def keeps_state(self, index, states):
        """Whether step ``index``, starting from ``states``, keeps them: every interval-th step, and
        a step whose start states are not the ones the step before returned (a setter replaced
        them between the two steps, which no recomputation from an earlier checkpoint repeats)."""
        follows = len(self._last_outputs) == len(states) and all(
            ref() is state for ref, state in zip(self._last_outputs, states))
        return self.interval == 1 or index % self.interval == 0 or not follows

    def record(self, index, states, inputs, kept, warm_starts):
        if self.interval > 1:  # detached: an input computed from a state would close a cycle through the graph
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
        """The newest step returned ``outputs`` (held weakly: a strong link from the rollout, which
        every node of the graph holds, to a state whose grad_fn is a node would be a cycle)."""
        self._last_outputs = tuple(weakref.ref(o) for o in outputs)

    def start_states(self, index):
        """(states, warm starts, replay records) of step ``index``, recomputed from the checkpoint
        before it (from its warm starts too: the same steps again, bit for bit); the steps up to
        the next checkpoint are kept for the calls that follow (backward goes down the steps).
        The last of them was not taken again: its records are None (its replay solves from the
        warm starts)."""
        if index not in self._replayed:
            first = max(k for k in self.checkpoints if k <= index)
            states, warm_starts = self.checkpoints[first]
            self._replayed = {}
            sim = _alive(self.sim)
            with torch.no_grad():
                k = first
                while k + 1 in self.inputs and k + 1 not in self.checkpoints:
                    following = sim.forward_step(states, self.inputs[k], warm_starts)
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


class _Step(torch.autograd.Function):
    @staticmethod
    def forward(ctx, sim, rollout, index, kept, inputs, wanted, *states_and_tracked):
        n_states = len(states_and_tracked) - sum(wanted)
        states = states_and_tracked[:n_states]
        outs = sim.forward_step(states, inputs, record=kept)
        ctx.sim, ctx.rollout, ctx.index, ctx.n_states, ctx.kept = weakref.ref(sim), rollout, index, n_states, kept
        ctx.wanted = wanted
        rollout.record(index, states, inputs, kept, tuple(sim.started_from))
        saved, replay = list((*states, *inputs) if kept else inputs), []
        if kept:  # each solver's replay record, or where it has none the warm start its step started from
            records = tuple(sim.replay_records)
            warm_starts = tuple(None if record is not None else warm for warm, record in zip(sim.started_from, records))
            ctx.replay_layout = _flatten((warm_starts, records), replay)
        # saved as tensors, torch frees them with the graph (attributes of ctx would outlive the backward)
        ctx.n_saved = len(saved)
        ctx.save_for_backward(*saved, *replay)
        return outs

    @staticmethod
    def backward(ctx, *grad_states):
        sim = _alive(ctx.sim)
        _check_generation(sim, ctx.rollout.generation, f"step {ctx.index}")
        sim.hold_before_backward()  # the replays below overwrite what the last step found
        saved, replay = ctx.saved_tensors[: ctx.n_saved], ctx.saved_tensors[ctx.n_saved:]
        if ctx.kept:
            states, inputs = saved[: ctx.n_states], saved[ctx.n_states:]
            warm_starts, records = _unflatten(ctx.replay_layout, replay)
        else:
            if torch.is_grad_enabled():  # (its start states come from a detached recomputation: see _first_order)
                raise GradientError(_second_order_message(f"step {ctx.index}") + "; with checkpoint_interval > 1 "
                                    "create_graph=True raises at once")
            (states, warm_starts, records), inputs = ctx.rollout.start_states(ctx.index), saved
        with torch.no_grad():
            try:
                grads = sim.backward_step(states, inputs, grad_states, warm_starts, records, ctx.wanted)
            except GradientError as error:  # (which step of the rollout)
                raise GradientError(f"step {ctx.index}'s backward: {error}") from None
        grads = (*grads[: ctx.n_states], *itertools.compress(grads[ctx.n_states:], ctx.wanted))
        if ctx.index == 0:
            sim.check_first_gradients(grads)
        return (None,) * 6 + _first_order(f"step {ctx.index}", grads, (*grad_states, *saved))


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


def step(sim, rollout, index, states, inputs):
    """Run one differentiable step; returns the new states (tuple of tensors). The node's tensor
    arguments are the states and the inputs that require grad; the other inputs (most of ~20
    parameters and controls a step) reach it in a tuple: torch's bookkeeping costs per tensor
    argument, in the forward and again in the backward."""
    wanted = tuple(map(_REQUIRES_GRAD, inputs))
    tracked = itertools.compress(inputs, wanted)
    outs = _Step.apply(sim, rollout, index, rollout.keeps_state(index, states), inputs, wanted, *states, *tracked)
    rollout.stepped(outs)
    return outs


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
    """A backward's results ``grads``, computed from ``anchors`` (its output gradients and saved
    tensors): as they are, unless torch asked for a graph of them (``create_graph=True``); then each
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
