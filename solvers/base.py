"""The interface every solver implements, so that the scene and the autograd glue treat
rigid bodies, MPM and later solvers alike.

A solver's *state* is one torch tensor (B, state_width) per scene; its *inputs* (controls and
physical parameters) are named torch tensors (B, width) applied at the next step. The solver
keeps its own copy of both in its kernels' arrays and moves them on request.

**The shared substep loop.** A step of a scene with several solvers (and, with coupling, a
coupler between them) runs, for each substep s, every solver's ``substep_pre_coupling(s)``,
then the coupling, then every solver's ``substep_post_coupling(s)`` (Genesis's order). Its
reverse runs in mirror order, after a replay of the step's forward that leaves each substep's
intermediates in place:

    begin_step(inputs)                              begin_reverse(state, inputs, grad, warm_start, record)
    for s in substeps:                              (the forward loop, replaying the step; check_replay)
        pre_coupling(s) of every solver             for s in reversed(substeps):
        couple(s)                                       post_coupling_backward(s), solvers reversed
        post_coupling(s) of every solver                couple_backward(s)
    end_step(download) → new state                      pre_coupling_backward(s), solvers reversed
                                                    end_reverse() → (grad of state, grads of inputs)

A solver alone in a scene runs ``advance``/``backward`` instead: the same loop with nothing in
between, which a solver may fuse into fewer launches (the rigid solver takes a contact-free step
in one launch, the MPM solver a substep in one). The simulator picks (genesis_lite/simulator.py).
Fused or not, a step gives the same bits: the same stage functions run in the same order.
"""
from collections.abc import Mapping

import torch


class Solver:
    """Abstract solver. B is the number of environments (1 when the scene is not batched)."""

    def derive_inputs(self, inputs, previous=None):
        """``inputs`` (name → (B, width)) with the inputs derived from others recomputed (none here);
        ``previous``: the inputs before one of them was set (None: none), whose derived values an
        env whose sources did not change may keep."""
        return inputs

    #: input names whose gradients ``backward`` returns, in order
    grad_input_names = ()
    #: inputs whose gradient the next backward may leave out (no tensor requiring grad reaches them:
    #: set by the simulator before each backward); a solver skips the work where it can
    skipped_grads = frozenset()
    #: inputs that keep their value across ``scene.reset()`` (parameters; controls are cleared)
    persistent_inputs = ()
    #: name → (B, width) tensor of every input's value at build (set by ``build``)
    default_inputs = None
    #: inputs that last one step: back to their value at build after every step (an external wrench)
    transient_inputs = ()
    #: inputs from which ``derive_inputs`` computes others (recomputed whenever one is set)
    derived_from = ()
    #: the inputs ``derive_inputs`` computes (never set by a user)
    derived_inputs = ()
    #: methods reading what the last step left (the rigid solver's contacts and dofs forces):
    #: kept before a backward's replays overwrite it; ``without_last_step`` blanks replaced envs
    last_step_readouts = ()
    #: names of the solver's entities, for error messages
    entity_names = ()
    #: substeps per step
    substeps = 1
    #: why a blown-up state can look finite (MPM's walls clamp NaN positions back inside), or None; the
    #: simulator's warning says it
    hides_nonfinite = None
    #: whether the simulator reads ``nonfinite()`` after every step also without check_nan, to warn
    #: once: where reading it is cheap (no wait for a device) or a blow-up would look finite
    watches_nonfinite = False
    #: whether ``download_state`` gives each state pages of its own (core.new_state): set by the
    #: simulator in a checkpointed differentiable scene, whose states are freed while its graph grows
    own_state_pages = False

    def build(self, n_envs):
        """Allocate for max(1, n_envs) environments; return the initial state (B, width)."""
        raise NotImplementedError

    def upload_state(self, state, envs=None):
        """Taichi state ← state (B, width), new in ``envs`` (int array; None: every env): what a
        solver carries over from step to step besides the state (the rigid warm start) is
        cleared there, and only there."""
        raise NotImplementedError

    def download_state(self):
        """The current Taichi state as a new torch tensor (B, width)."""
        raise NotImplementedError

    def upload_inputs(self, inputs):
        """Taichi inputs ← dict name → (B, width) tensors."""
        raise NotImplementedError

    # -- one step, substep by substep (the shared loop) -------------------------------------------
    def begin_step(self, inputs):
        """Start a step from the uploaded state, after uploading ``inputs`` (None: those held)."""
        raise NotImplementedError

    def substep_pre_coupling(self, s):
        """Substep s up to where a coupler acts."""
        raise NotImplementedError

    def substep_post_coupling(self, s):
        """The rest of substep s."""
        raise NotImplementedError

    def end_step(self, download):
        """Finish the step: its result becomes the current state, returned as a new tensor
        (B, width) when ``download`` (else None)."""
        raise NotImplementedError

    def begin_reverse(self, state, inputs, grad_state_out, warm_start, record=None):
        """Load a step's start state, inputs, the gradient of its end state and what makes its
        replay repeat it (its ``replay_record()``, else the warm start it started from; None where
        the step needs neither), for a replay (begin_step(None), the substeps) and then the
        reverse."""
        raise NotImplementedError

    def check_replay(self):
        """After the replay, before any reverse stage (of any solver): raise GradientError if the
        replayed step has no exact gradient (the rigid solver's inexact contacts); nothing here."""

    def replay_again(self):
        """After a replay in the shared loop: whether it must be taken again (the solver's replay
        storage grew and, its state moving with another solver's, it cannot replay alone)."""
        return False

    def substep_post_coupling_backward(self, s):
        raise NotImplementedError

    def substep_pre_coupling_backward(self, s):
        raise NotImplementedError

    def end_reverse(self):
        """(grad of the start state (B, width), {name: grad (B, width)} for grad_input_names: a
        dict or a GradColumns)."""
        raise NotImplementedError

    # -- one step, alone ------------------------------------------------------------------------
    def advance(self, inputs=None, download=False):
        """One whole step (the loop above with no coupler); see begin_step and end_step."""
        self.begin_step(inputs)
        for s in range(self.substeps):
            self.substep_pre_coupling(s)
            self.substep_post_coupling(s)
        return self.end_step(download)

    def backward(self, state, inputs, grad_state_out, warm_start=None, record=None):
        """Reverse of the step from ``state`` (B, width) with ``inputs`` (name → (B, width));
        returns end_reverse()'s gradients."""
        self.begin_reverse(state, inputs, grad_state_out, warm_start, record)
        self.advance()  # the replay
        self.check_replay()
        for s in reversed(range(self.substeps)):
            self.substep_post_coupling_backward(s)
            self.substep_pre_coupling_backward(s)
        return self.end_reverse()

    def end_backward(self):
        """After a step's backward, finished or not (an error, an interrupt): the next step is a
        forward one (a replay's settings cleared)."""

    def nonfinite(self):
        """True once a step produced a non-finite state since the last call."""
        raise NotImplementedError

    def entity_columns(self):
        """[(entity name, the int array of its state's columns)], in the order of entity_names."""
        raise NotImplementedError

    def warm_start(self):
        """A copy of what a step carries over besides its state and inputs without it changing
        the result beyond a tolerance (the rigid solver's constraint-solve warm start), or None."""
        raise NotImplementedError

    def set_warm_start(self, warm_start):
        """Restore ``warm_start()``'s value (None: leave it)."""
        raise NotImplementedError

    def replay_record(self):
        """After a step: a copy of what lets its backward's replay repeat it without the warm start
        (the rigid solver's constraint-solve solutions, from which the replay skips the solve's
        iterations), or None where the replay needs nothing."""
        return None

    def destroy(self):
        """Free the solver's arrays."""
        raise NotImplementedError

    def memory_bytes(self):
        """Bytes of the torch tensors among the solver's attributes (inside lists, tuples and dicts
        too), each storage counted once: what its build allocated."""
        return tensor_bytes(vars(self).values())


def tensor_bytes(values):
    """Bytes of the storages of the torch tensors among ``values`` and inside their lists, tuples
    and dicts, each storage counted once."""
    storages = {}

    def visit(value):
        if isinstance(value, torch.Tensor):
            storages[value.untyped_storage().data_ptr()] = value.untyped_storage().nbytes()
        elif isinstance(value, (list, tuple)):
            for item in value:
                visit(item)
        elif isinstance(value, dict):
            for item in value.values():
                visit(item)

    for value in values:
        visit(value)
    return sum(storages.values())


class GradColumns(Mapping):
    """{input name: its (B, width) gradient}, a read-only mapping of column views of one (B, total)
    tensor made when looked up: a step's backward wants the few inputs that require grad, of ~20
    (a view costs about a microsecond, all of them a tenth of a small robot's backward step)."""

    def __init__(self, grads, spans):
        """grads (B, total); spans: name → (first column, end column)."""
        self.grads, self.spans = grads, spans

    def __getitem__(self, name):
        first, end = self.spans[name]
        return self.grads[:, first:end]

    def __iter__(self):
        return iter(self.spans)

    def __len__(self):
        return len(self.spans)
