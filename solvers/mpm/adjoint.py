"""The reverse of an MPM step (issue 13): exact hand-written adjoints, in memory bounded by one step.

The autograd graph keeps only a step's start state (B, N · 25) and inputs. ``begin_reverse`` loads it into
frame 0; the replay that follows (base.Solver.backward, or the simulator's shared loop) fills
frames 0..S (frame s: the state before substep s) and keeps, per substep, what the reverse reads
besides the frames: each particle's affine matrix, SVD(F_tmp) (for the materials that take one:
the reverse does not redo it) and gathered velocity, and the updated grid (its listed nodes'
velocity and mass, and the lists). Each substep's reverse then restores that grid — saved after
the update, so a coupler's change to the grid between pre and post coupling is in it, where
rebuilding the grid from frame s would miss it — and runs the stages' adjoints in mirror order
(kernels.py). All of it belongs to the solver, one step's worth: the autograd graph still keeps
only each step's start state and inputs. The saved grid's capacity (nodes per env and substep) starts at the
margin times the nodes the initial particles reach; a replay in which a substep lists more grows
it and replays again. The gradients flow through:
- the state rows, in ``grads`` (the gradient w.r.t. frame s + 1 becomes the one w.r.t. frame s);
- the per-particle parameters E, nu, rho, actu, summed per particle over the substeps;
- gravity and the rigid entities' coupling parameters (the colliders at rest here; the coupler's
  reverse adds the moving shapes'), summed per env in a fixed order.
Every sum runs in a fixed order (serial scatters per env, no atomics): repeated rollouts give
the same bits, and a batched env the bits of a single-env scene.
"""
import numpy as np
import torch

from ..core import runtime
from .. import launch
from ..launch import BoundKernels
from . import kernels, layout
from .constitutive import any_needs_svd

CAPACITY_MARGIN = 1.5  # the saved grid holds this many times the nodes counted (initially, or in a replay)


class MPMAdjoint:
    """Mixin of MPMSolver: its backward."""

    grad_input_names = ("E", "nu", "rho", "actu", "gravity", "coupling")

    def _allocate_reverse(self):
        """Arrays of the reverse and of what a replay keeps (called by MPMSolver._allocate when
        requires_grad)."""
        B, N, K, S = self.n_batch, self.n_particles, self.model.grid.n_nodes, self.substeps

        def floats(*shape):
            return torch.zeros(shape, dtype=runtime.tc_float, device=runtime.device)

        self.grads = floats(1, B, N, layout.WIDTH)
        self.grad_params = floats(B, N, len(layout.PARTICLE_INPUTS))
        self.grad_env = floats(*self.env_in.shape)
        self.grad_grid = floats(B, K, 4)
        self.scratch = floats(B, N, 6)
        self.gathered = floats(S, B, N, 3)
        self.svd = floats(*((S, B, N, 21) if any_needs_svd(self.model.kinds, self.model.consts) else (1, 1, 1, 21)))
        self._allocate_saved_grid(self._initial_capacity())

    def _initial_capacity(self):
        """Nodes (per env and substep) the saved grid holds at first: the margin times those the
        initial particles reach (the same cells as kernels' stencil.cell_of), at most K."""
        g = self.model.grid
        base = np.floor(self.model.pos0 * g.density - 0.5).astype(np.int64) - g.lowest
        cells = np.unique(np.clip(base, 0, g.res - 3), axis=0)
        offsets = np.stack(np.meshgrid(*[np.arange(3)] * 3, indexing="ij"), -1).reshape(-1, 3)
        nodes = (cells[:, None, :] + offsets).reshape(-1, 3)
        count = len(np.unique((nodes[:, 0] * g.res[1] + nodes[:, 1]) * g.res[2] + nodes[:, 2]))
        return max(1, min(g.n_nodes, int(np.ceil(CAPACITY_MARGIN * count))))

    def _allocate_saved_grid(self, capacity):
        """saved_grid (S, B, capacity, saved_channels: grid.grid_stage) and saved_nodes (S, B + 1,
        capacity + 1), zeroed."""
        S, B = self.substeps, self.n_batch
        self.saved_grid = torch.zeros((S, B, capacity, self.saved_channels), dtype=runtime.tc_float,
                                      device=runtime.device)
        self.saved_nodes = torch.zeros((S, B + 1, capacity + 1), dtype=torch.int32, device=runtime.device)

    def set_saved_grid_capacity(self, capacity):
        """Reallocate the saved grid for ``capacity`` nodes per env and substep (it grows by itself
        when a replay needs more; tests force a small one)."""
        self._allocate_saved_grid(capacity)
        self._bind()

    def _bind_reverse(self):
        arrays = self._arrays() + [self.grads.view(-1), self.grad_params, self.grad_env, self.grad_grid.view(-1),
                                   self.scratch.view(-1)]
        config = (False, self.serial_chores, self.has_colliders, self.meets_moving)
        # (at Taichi's light opt_level: launch.LIGHT_OPT_LEVEL; the forward kernels, 8-17 % slower there, at 1)
        self.reverse_kernels = BoundKernels(config, arrays, [0] * len(arrays), *kernels.REVERSE_KERNELS,
                                            opt_level=launch.LIGHT_OPT_LEVEL)

    def begin_reverse(self, state, inputs, grad_state_out, warm_start, record=None):
        """Frame 0 ← the step's start state (B, N · 25), the inputs uploaded, grads ← the gradient
        of the step's end state (None: zero), the parameters' gradients zeroed; the next step
        (the replay) keeps what the reverse reads."""
        self.current = 0
        self.replaying = True
        # (the colliders' coupling gradients take a serial pass over every listed node: only when wanted)
        self.coupling_grads = int("coupling" not in self.skipped_grads)
        self.upload_state(state)
        self.upload_inputs(inputs)
        with torch.no_grad():
            if grad_state_out is None:
                self.grads.zero_()
            else:
                self.grads.view(self.n_batch, -1).copy_(grad_state_out)
            self.grad_params.zero_()
            self.grad_env.zero_()

    def end_replay(self):
        """The replay's end (from end_step, before ``current`` moves): if a substep listed more
        nodes than the saved grid holds, grow it to the margin times the largest count and
        replay the step again (same bits: frame 0 and the inputs are untouched): alone, where the
        colliders are the MPM solver's own (its fused substep); with a coupler, whose shapes move
        with the rigid solver, the simulator takes the whole shared loop's replay again
        (replay_again)."""
        self.replaying = False
        need = int(self.saved_nodes[:, self.n_batch, 0].max())
        if need <= self.saved_grid.shape[2]:
            return
        self.set_saved_grid_capacity(int(np.ceil(CAPACITY_MARGIN * need)))
        if self.meets_moving:
            self.regrown = True
            return
        self.replaying = self.nodes_listed = True
        for s in range(self.substeps):
            self.kernels.substep(*self._frames(s))
        self.replaying = self.nodes_listed = False

    def replay_again(self):
        """Whether the shared loop's replay just taken must be taken again: the saved grid grew
        under a coupler (end_replay). Clears the request."""
        regrown, self.regrown = self.regrown, False
        return regrown

    def end_backward(self):
        self.replaying = False

    def substep_post_coupling_backward(self, s):
        self.nodes_listed = True
        self.reverse_kernels.post_coupling_backward(s, self.coupling_grads)

    def substep_pre_coupling_backward(self, s):
        self.reverse_kernels.pre_coupling_backward(s, self.coupling_grads)
        self.nodes_listed = False

    def end_reverse(self):
        grad_state = self.grads.view(self.n_batch, -1).clone()
        grads = {name: self.grad_params[:, :, k].clone() for k, name in enumerate(layout.PARTICLE_INPUTS)}
        at = layout.COUPLING_AT
        grads["gravity"], grads["coupling"] = self.grad_env[:, :at].clone(), self.grad_env[:, at:].clone()
        return grad_state, grads
