"""Exact MPM gradients (issue 13): the hand-written reverse of a step (solvers/mpm/adjoint.py) against
central finite differences, float64, over 20 steps of 4 substeps, and its bitwise properties.

Each case builds the solver directly (MPMSolver), runs a rollout from a start state with its inputs,
and takes the loss Σ w · (final particle rows) for fixed random weights w; its gradient comes from
the solver's backward, step by step in reverse from each step's start state (what the autograd node
keeps). Every scene compiles the same kernels (data are arguments), once for the whole file.
"""
import numpy as np
import pytest
import torch

import genesis_lite as gs
from genesis_lite.solvers.mpm.solver import MPMSolver

from .fd_scan import EPS, assert_converged

STEPS, DT, SUBSTEPS = 20, 2e-3, 4
# a 0.6 × 0.6 × 0.4 m domain at 32 cells/m (walls at 3 cells); a block of 5³ particles 2 cm apart
# whose lowest layer starts 1 cm above the floor's wall, so that the walls act during the rollout
LOWER, UPPER, DENSITY, SPACING = (-0.3, -0.3, 0.0), (0.3, 0.3, 0.4), 32, 0.02
E, NU, RHO = 3e4, 0.3, 800.0

MATERIALS = {  # name → (kind, non-differentiable params)
    "neohooken": ("neohooken", {}),
    "corotation": ("corotation", {}),
    "elastoplastic_von_mises": ("elastoplastic", {"von_mises_yield_stress": 300.0}),
    "elastoplastic_clamp": ("elastoplastic", {"use_von_mises": False}),
    "elastoplastic_elastic": ("elastoplastic", {"von_mises_yield_stress": 1e6}),
    "snow": ("snow", {}),
    "sand": ("sand", {}),
    "liquid_viscous": ("liquid", {"viscous": True}),
    "liquid": ("liquid", {}),
    "muscle_neohooken": ("muscle_neohooken", {}),
    "muscle_corotation": ("muscle_corotation", {}),
}


# every test in float64 unless it asks for f32 (conftest's fixtures, per test: conftest runs the
# float32 tests first, and a module-scoped init left the module's later tests in float32)
pytestmark = pytest.mark.usefixtures("f64")


class Rollout:
    """A scene of one block of material ``kind`` and its loss L(start state, inputs).

    start: "generic" (random velocities, affine fields, deformations and positions jittered) or
    "rest" (F = I, C = 0, v = 0: every particle starts at the repeated singular values of F = I;
    Sand at F = 0.99 I: at F = I it would sit on its cone's apex, the kink between tension and
    compression, where round-off picks the branch)."""

    def __init__(self, kind, params, n_envs, start, seed=0, requires_grad=True, sticky=False, throw=(0.0, 0.0, 0.0),
                 colliders=(), planes=(), couplings=()):
        """throw (3,) m/s: added to every particle's initial velocity; colliders, planes: rigid shapes
        at rest (solvers/mpm/colliders.py rows and hull planes); couplings (R, 3): the (μ, ς, e) of
        the rigid entities the rows name."""
        self.solver = MPMSolver(DT, SUBSTEPS, (0.0, 0.0, -9.81), DENSITY, SPACING, LOWER, UPPER, sticky,
                                requires_grad)
        self.solver.set_colliders(colliders, planes)
        self.solver.set_couplings(couplings)
        lattice = np.arange(5) * SPACING
        block = np.stack(np.meshgrid(lattice, lattice, lattice, indexing="ij"), -1).reshape(-1, 3)
        jp = 0.0 if kind == "sand" else 1.0  # Sand's Jp is a log-volume correction (Genesis's _default_Jp)
        self.solver.add_entity("block", kind, params, E, NU, RHO, jp, block + np.array([-0.04, -0.04, 3 / 32 + 0.01]))
        state = self.solver.build(n_envs)
        B, N = self.solver.n_batch, self.solver.n_particles
        self.B, self.N = B, N
        rng = np.random.default_rng(seed)
        rows = state.view(B, N, 25).clone()
        if start == "generic":
            rows[:, :, 0:3] += torch.tensor(rng.normal(size=(B, N, 3)) * 0.003)
            rows[:, :, 3:6] = torch.tensor(rng.normal(size=(B, N, 3)) * 0.5)
            rows[:, :, 6:15] = torch.tensor(rng.normal(size=(B, N, 9)) * 0.5)
            # compressed by 3 % (so that Sand, which carries no stress in tension, is loaded)
            rows[:, :, 15:24] = 0.97 * rows[:, :, 15:24] + torch.tensor(rng.normal(size=(B, N, 9)) * 0.02)
        elif kind == "sand":
            rows[:, :, 15:24] *= 0.99
        rows[:, :, 3:6] += torch.tensor(throw, dtype=torch.float64)
        self.state = rows.view(B, -1)
        self.inputs = {name: value.clone() for name, value in self.solver.default_inputs.items()}
        self.inputs["E"] *= torch.tensor(1.0 + 0.2 * rng.random((B, N)))
        if kind.startswith("muscle"):
            fibers = rng.normal(size=(N, 3))
            self.inputs["fiber"] = torch.tensor(fibers / np.linalg.norm(fibers, axis=1, keepdims=True)).view(1, -1) \
                .repeat(B, 1)
            self.inputs["actu"] = torch.tensor(rng.random((B, N)) * 0.5)
        self.weights = torch.tensor(rng.normal(size=(B, N * 25)))
        self.rng = rng

    def run(self, state, inputs, keep=False):
        """(loss, the start state of every step when ``keep``)."""
        solver = self.solver
        solver.current = 0
        solver.upload_state(state)
        solver.upload_inputs(inputs)
        starts = []
        for _ in range(STEPS):
            if keep:
                starts.append(solver.download_state())
            solver.advance()
        return float((solver.download_state() * self.weights).sum()), starts

    def gradients(self):
        """(∂L/∂start state (B, N·25), {input: ∂L/∂input}), step by step in reverse."""
        _, starts = self.run(self.state, self.inputs, keep=True)
        grad = self.weights.clone()
        totals = {name: torch.zeros_like(self.inputs[name]) for name in self.solver.grad_input_names}
        for start in reversed(starts):
            grad, grad_inputs = self.solver.backward(start, self.inputs, grad)
            for name in totals:
                totals[name] = totals[name] + grad_inputs[name]
        return grad, totals

    def state_direction(self, columns):
        """A random direction (B, N·25) in the given columns of every particle's row."""
        d = torch.zeros(self.B, self.N, 25, dtype=torch.float64)
        d[:, :, columns] = torch.tensor(self.rng.normal(size=(self.B, self.N, len(columns))))
        return d.view(self.B, -1)

    def check(self, grads, what, name, direction, scale):
        """Directional derivative along scale · direction (direction: unit norm; name: "state" or
        an input's) against central FD at EPS, relative to scale · ‖gradient over the direction's
        support‖ (as tests/fd_scan.py measures: round-off that a rollout amplifies, largest through
        the SVD-based materials, makes a directional derivative that is small by chance noisy)."""
        grad = grads[0] if name == "state" else grads[1][name]
        direction = direction / direction.norm()
        analytic = scale * float((grad * direction).sum())
        norm = scale * float((grad * (direction != 0)).norm())
        assert norm > 0.0, f"{what}: zero gradient cannot be checked"
        errors = {}
        for eps in EPS:
            losses = []
            for sign in (1.0, -1.0):
                step = sign * eps * scale * direction
                state = self.state + step if name == "state" else self.state
                inputs = dict(self.inputs)
                if name != "state":
                    inputs[name] = inputs[name] + step
                losses.append(self.run(state, inputs)[0])
            errors[eps] = (analytic - (losses[0] - losses[1]) / (2 * eps)) / norm
        assert_converged(errors, what)


SCALES = {"E": E, "nu": 0.1, "rho": RHO, "actu": 1.0, "gravity": 10.0, "coupling": 0.1}  # of the inputs' directions
# a coupling direction's relative sizes in (μ, ς m, e)
COUPLING_SIZES = (1.0, 0.01, 1.0)


def check_all(rollout, grads, name, per_particle_only=False, coupling_params=(0, 1, 2)):
    """Position, velocity (and, unless per_particle_only, the affine field and the deformation),
    each parameter per particle (and entity-wide unless per_particle_only), gravity, and the rigid
    entities' coupling parameters (those numbered in coupling_params: 0 μ, 1 ς, 2 e) where colliders
    point at them."""
    fields = (("pos", range(0, 3), 0.01), ("vel", range(3, 6), 1.0))
    if not per_particle_only:
        fields += (("C", range(6, 15), 1.0), ("F", range(15, 24), 0.1))
    for what, columns, scale in fields:
        rollout.check(grads, f"{name}: initial {what}", "state", rollout.state_direction(list(columns)), scale)
    params = ("E", "nu", "rho") + (("actu",) if name.startswith("muscle") else ())
    shape = (rollout.B, rollout.N)
    for param in params:
        per_particle = torch.tensor(rollout.rng.normal(size=shape))
        rollout.check(grads, f"{name}: per-particle {param}", param, per_particle, SCALES[param])
        if not per_particle_only:
            rollout.check(grads, f"{name}: entity {param}", param, torch.ones(shape, dtype=torch.float64),
                          SCALES[param])
    rollout.check(grads, f"{name}: gravity", "gravity", torch.tensor(rollout.rng.normal(size=(rollout.B, 3))),
                  SCALES["gravity"])
    R = len(rollout.solver.couplings)
    for k, what in enumerate(("μ", "ς", "e")):  # each rigid entity's, where colliders point at them
        if R and k in coupling_params:
            direction = np.zeros((rollout.B, R, 3))
            direction[:, :, k] = rollout.rng.normal(size=(rollout.B, R)) * COUPLING_SIZES[k]
            rollout.check(grads, f"{name}: coupling {what}", "coupling", torch.tensor(direction.reshape(rollout.B, -1)),
                          SCALES["coupling"] * COUPLING_SIZES[k])


@pytest.mark.parametrize("n_envs", [0, 2])
def test_neohooken_every_input_matches_fd(n_envs):
    rollout = Rollout("neohooken", {}, n_envs, "generic")
    check_all(rollout, rollout.gradients(), f"neohooken n_envs={n_envs}")


@pytest.mark.parametrize("start", ["generic", "rest"])
@pytest.mark.parametrize("material", [m for m in MATERIALS if m != "neohooken"])
def test_material_matches_fd(material, start):
    kind, params = MATERIALS[material]
    rollout = Rollout(kind, params, 0, start, seed=1)
    check_all(rollout, rollout.gradients(), f"{material} ({start})", per_particle_only=True)


@pytest.mark.parametrize("sticky", [False, True])
def test_walls_match_fd(sticky):
    """A block thrown into the floor: particles clamped to the wall with their outward velocity
    zeroed, and nodes beyond the wall stopped (slip: their outward component; sticky: all)."""
    rollout = Rollout("neohooken", {}, 0, "generic", seed=2, sticky=sticky, throw=(0.0, 0.0, -6.0))
    _, starts = rollout.run(rollout.state, rollout.inputs, keep=True)
    clamped = sum(int((start.view(rollout.N, 25)[:, 2] == float(LOWER[2] + 3 / DENSITY)).sum()) for start in starts)
    assert clamped > 0, "the particles must reach the floor's wall"
    check_all(rollout, rollout.gradients(), f"walls (sticky={sticky})", per_particle_only=True)


def test_gradients_are_bitwise_reproducible():
    assert_bitwise_reproducible()


def assert_bitwise_reproducible(**rollout_args):
    """Repeated rollouts, and env 0 of a batch against a single-env scene, give the same bits
    (neohooken blocks; rollout_args: more of Rollout's arguments)."""
    single = Rollout("neohooken", {}, 0, "generic", **rollout_args)
    first, again = single.gradients(), single.gradients()
    assert torch.equal(first[0], again[0])
    assert all(torch.equal(first[1][name], again[1][name]) for name in first[1])
    batch = Rollout("neohooken", {}, 2, "generic", seed=5, **rollout_args)  # env 1 differs; env 0 ← the single's
    batch.state[0], batch.weights[0] = single.state[0], single.weights[0]
    for name in batch.inputs:
        batch.inputs[name][0] = single.inputs[name][0]
    batched = batch.gradients()
    assert torch.equal(batched[0][0], first[0][0])
    assert all(torch.equal(batched[1][name][0], first[1][name][0]) for name in first[1])


def test_forward_with_requires_grad_is_bitwise_plain():
    plain, graded = Rollout("neohooken", {}, 2, "generic", requires_grad=False), Rollout("neohooken", {}, 2, "generic")
    plain.run(plain.state, plain.inputs)
    graded.run(graded.state, graded.inputs)
    assert torch.equal(plain.solver.download_state(), graded.solver.download_state())


def test_a_saved_grid_too_small_grows_and_gives_the_same_bits():
    """The replay keeps each substep's updated grid for the reverse, up to a capacity of nodes
    per env and substep; one forced far below what the block reaches overflows in the first
    replay, which grows it and replays again: the gradients keep the bits they have with room
    for the whole grid."""
    reference = Rollout("neohooken", {}, 2, "generic", seed=3)
    reference.solver.set_saved_grid_capacity(reference.solver.model.grid.n_nodes)
    expected = reference.gradients()
    rollout = Rollout("neohooken", {}, 2, "generic", seed=3)
    rollout.solver.set_saved_grid_capacity(4)
    grads = rollout.gradients()
    assert rollout.solver.saved_grid.shape[2] > 4
    assert torch.equal(grads[0], expected[0])
    assert all(torch.equal(grads[1][name], expected[1][name]) for name in expected[1])


@pytest.mark.parametrize("n_envs", [0, 2])
def test_the_shared_substep_loop_gives_the_bits_of_the_solver_alone(n_envs):
    """A scene of several solvers runs a step's backward as simulator._backward_shared does: its
    replay goes through the split pre/post coupling kernels, which keep the grid for the reverse
    as the fused substep does: with no coupler between the halves, the same gradient bits."""
    rollout = Rollout("neohooken", {}, n_envs, "generic", seed=4, throw=(0.0, 0.0, -3.0))
    fused = rollout.gradients()
    _, starts = rollout.run(rollout.state, rollout.inputs, keep=True)
    solver, grad = rollout.solver, rollout.weights.clone()
    totals = {name: torch.zeros_like(rollout.inputs[name]) for name in solver.grad_input_names}
    for start in reversed(starts):
        solver.begin_reverse(start, rollout.inputs, grad, None)
        solver.begin_step(None)
        for s in range(SUBSTEPS):
            solver.substep_pre_coupling(s)
            solver.substep_post_coupling(s)
        solver.end_step(False)
        for s in reversed(range(SUBSTEPS)):
            solver.substep_post_coupling_backward(s)
            solver.substep_pre_coupling_backward(s)
        grad, grad_inputs = solver.end_reverse()
        totals = {name: totals[name] + grad_inputs[name] for name in totals}
    assert torch.equal(grad, fused[0])
    assert all(torch.equal(totals[name], fused[1][name]) for name in totals)
