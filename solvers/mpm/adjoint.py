"""The reverse of an MPM step (issue 13): exact hand-written adjoints, in memory bounded by one step.

A step's autograd node keeps only its start state (B, N · 25). ``begin_reverse`` loads it into
frame 0, the replay that follows (base.Solver.backward, or the simulator's shared loop) fills
frames 0..S (frame s: the state before substep s), and each substep's reverse then rebuilds that
substep's grid from frame s — the grid is never stored — and runs the stages' adjoints in mirror
order (kernels.py). The gradients flow through:
- the state rows, in ``grads`` (the gradient w.r.t. frame s + 1 becomes the one w.r.t. frame s);
- the per-particle parameters E, nu, rho, actu, summed per particle over the substeps;
- gravity, summed per env in a fixed order.
Every sum runs in a fixed order (serial scatters per env, no atomics): repeated rollouts give
the same bits, and a batched env the bits of a single-env scene.
"""
import torch

from ..core import runtime
from ..launch import BoundKernels
from . import kernels, layout


class MPMAdjoint:
    """Mixin of MPMSolver: its backward."""

    grad_input_names = ("E", "nu", "rho", "actu", "gravity")

    def _allocate_reverse(self):
        """Arrays and kernels of the reverse (called by MPMSolver._allocate when requires_grad)."""
        B, N, K = self.n_batch, self.n_particles, self.model.grid.n_nodes

        def floats(*shape):
            return torch.zeros(shape, dtype=runtime.tc_float, device=runtime.device)

        self.grads = floats(1, B, N, layout.WIDTH)
        self.grad_params = floats(B, N, len(layout.PARTICLE_INPUTS))
        self.grad_gravity = floats(B, 3)
        self.grad_grid = floats(B, K, 4)
        self.scratch = floats(B, N, 6)
        arrays = [self.frames, self.params, self.gravity_in, self.kinds, self.consts, self.fiber, self.affine,
                  self.grid, self.active, self.grid_f, self.grid_i, self.flags, self.grads, self.grad_params,
                  self.grad_gravity, self.grad_grid, self.scratch]
        self.reverse_kernels = BoundKernels(0, arrays, [0] * len(arrays), *kernels.REVERSE_KERNELS)

    def begin_reverse(self, state, inputs, grad_state_out, warm_start):
        """Frame 0 ← the step's start state (B, N · 25), the inputs uploaded, grads ← the gradient
        of the step's end state (None: zero), the parameters' gradients zeroed."""
        self.current = 0
        self.upload_state(state)
        self.upload_inputs(inputs)
        with torch.no_grad():
            if grad_state_out is None:
                self.grads.zero_()
            else:
                self.grads.view(self.n_batch, -1).copy_(grad_state_out)
            self.grad_params.zero_()
            self.grad_gravity.zero_()

    def substep_post_coupling_backward(self, s):
        self.reverse_kernels.post_coupling_backward(s)

    def substep_pre_coupling_backward(self, s):
        self.reverse_kernels.pre_coupling_backward(s)

    def end_reverse(self):
        grad_state = self.grads.view(self.n_batch, -1).clone()
        grads = {name: self.grad_params[:, :, k].clone() for k, name in enumerate(layout.PARTICLE_INPUTS)}
        grads["gravity"] = self.grad_gravity.clone()
        return grad_state, grads
