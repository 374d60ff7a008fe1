"""The interface every solver implements, so that the scene and the autograd glue treat
rigid bodies, MPM and later solvers alike.

A solver's *state* is one torch tensor (B, state_width) per scene; its *inputs* (controls and
physical parameters) are named torch tensors (B, width) applied at the next step. The solver
keeps its own copy of both in its kernels' arrays and moves them on request.
"""


class Solver:
    """Abstract solver. B is the number of environments (1 when the scene is not batched)."""

    #: input names whose gradients ``backward`` returns, in order
    grad_input_names = ()
    #: inputs that keep their value across ``scene.reset()`` (parameters; controls are cleared)
    persistent_inputs = ()
    #: name → (B, width) tensor of every input's value at build (set by ``build``)
    default_inputs = None
    #: names of the solver's entities, for error messages
    entity_names = ()

    def build(self, n_envs):
        """Allocate for max(1, n_envs) environments; return the initial state (B, width)."""
        raise NotImplementedError

    def upload_state(self, state):
        """Taichi state ← state (B, width)."""
        raise NotImplementedError

    def download_state(self):
        """The current Taichi state as a new torch tensor (B, width)."""
        raise NotImplementedError

    def upload_inputs(self, inputs):
        """Taichi inputs ← dict name → (B, width) tensors."""
        raise NotImplementedError

    def advance(self, inputs=None, download=False):
        """Run one step from the uploaded state, after uploading ``inputs`` (name → (B, width))
        when given (else the uploaded ones hold); the result becomes the current state, and is
        returned as a new tensor (B, width) when ``download`` (else None)."""
        raise NotImplementedError

    def nonfinite(self):
        """True once a step produced a non-finite state since the last call."""
        raise NotImplementedError

    def warm_start(self):
        """A copy of what a step carries over besides its state and inputs without it changing
        the result beyond a tolerance (the rigid solver's constraint-solve warm start), or None."""
        raise NotImplementedError

    def set_warm_start(self, warm_start):
        """Restore ``warm_start()``'s value (None: leave it)."""
        raise NotImplementedError

    def backward(self, state, inputs, grad_state_out, warm_start=None):
        """Reverse of the step from ``state`` (B, width) with ``inputs`` (name → (B, width)).

        Returns (grad of the start state (B, width), {name: grad (B, width)} for grad_input_names).
        """
        raise NotImplementedError

    def destroy(self):
        """Free the solver's arrays."""
        raise NotImplementedError
