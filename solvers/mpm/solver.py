"""The MPM solver: MLS-MPM particles of many materials on one grid (kernels.py), batched over envs.

State per env: every particle's row of layout.STATE, flattened (B, N · 25). Inputs: layout's
per-particle E, nu, rho, actu, the per-env gravity and rigid entities' couplings, and the muscle
fibres. Bookkeeping only: the physics is in the kernels of kernels.py (one launch per substep) and
constitutive.py.
"""
import numpy as np
import taichi as ti
import torch

from ..base import Solver
from ..core import InvalidInputError, available_memory, new_state, runtime, warn_user
from ..launch import BoundKernels
from . import colliders, kernels, layout
from .adjoint import MPMAdjoint
from .constitutive import any_needs_svd, encode
from .model import EntitySpec, Grid, MPMModel

# Genesis's suggested bound on the substep: h ≤ 2e-2 · dx (s, dx in m)
GENESIS_DT_PER_DX = 2e-2
# The explicit substep's elastic wave bound is h ≤ WAVE_CFL · dx / c: measured (a block with small
# random velocities, 100 cells/m, float32 and float64), it blew up at h·c/dx = 1.2 (ν 0.2), 0.95
# (ν 0.45, neo-Hookean and corotated), 0.90 (ν 0.499), stable at 1.10, 0.93, 0.90, 0.85; a block
# hitting the floor at 3-8 m/s blew up from 0.85 (ν 0.499), stable at 0.82. dx/c alone let a ν 0.45
# beam run to NaN without a warning.
WAVE_CFL = 0.8
# Taichi 1.7 indexes an array with 32-bit ints (an index past this wraps: a crash or a wrong write)
MAX_ARRAY_ELEMENTS = 2**31 - 1
# Up to this many envs the grid's chores (adding, copying, zeroing the listed nodes: grid.py) run on
# the calling thread on the CPU, where a hand-off to the thread pool costs ~10-60 µs. Measured, a
# 10k-particle neo-Hookean block per env, float32, ms a substep (best / median of 8 × 50 substeps),
# serial against the pool: 1 env 1.33 / 2.07 against 1.44 / 2.18; 2 envs 3.34 / 3.93 against
# 3.13 / 3.80; 4 envs 5.33 / 6.59 against 4.88 / 6.69; 16 envs 29.8 / 31.3 against 27.2 / 29.7.
SERIAL_CHORE_ENVS = 1


class MPMSolver(MPMAdjoint, Solver):
    persistent_inputs = layout.PERSISTENT_INPUTS
    hides_nonfinite = ("its particles are kept inside the walls (g2p.wall_particle), so their positions look "
                       "finite while velocities and deformation are NaN")
    watches_nonfinite = True

    def __init__(self, dt, substeps, gravity, grid_density, particle_size, lower_bound, upper_bound, sticky,
                 requires_grad):
        """dt: step, s; substeps per step; gravity (3,) m/s²; grid_density cells per m; particle_size
        (a particle's edge, m: its volume is particle_size³); lower/upper_bound (3,) m; sticky walls
        (else slip); requires_grad: keep every substep's particles for the backward."""
        self.dt, self.substeps, self.gravity = dt, substeps, np.asarray(gravity, dtype=np.float64)
        self.requires_grad = requires_grad
        grid = Grid(float(grid_density), np.asarray(lower_bound, dtype=np.float64),
                    np.asarray(upper_bound, dtype=np.float64))
        self.particle_size = float(particle_size)
        self.model = MPMModel(grid, self.particle_size ** 3, bool(sticky))
        self.entity_names = []
        self.wall_lower, self.wall_upper = grid.wall_lower, grid.wall_upper
        self.collider_rows, self.collider_data = np.zeros((0, colliders.WIDTH)), np.zeros(0)
        self.couplings = np.zeros((0, 3))  # per rigid entity: its (μ, ς, e) at build (set_couplings)
        self.meets_moving = False  # a coupler brings shapes of moving links (set_colliders)
        self.regrown = False  # a replay under a coupler outgrew the saved grid (adjoint.end_replay)
        # the worst excess each stability warning has reported (the substep over its limit; cells a
        # substep, per call and entity): an optimisation loop setting the same values every iteration
        # is told once
        self.warned_excess = {}

    def set_colliders(self, rows, data=(), moving=False):
        """Rigid shapes at rest the grid meets, before the first step: colliders.py's rows (C,
        colliders.WIDTH) and the data of its hulls and height fields (colliders.packed); moving:
        whether a coupler (solvers/coupler.py) brings shapes of moving links between the substep's
        halves (its walls then wait for them)."""
        self.collider_rows = np.asarray(rows, dtype=np.float64).reshape(-1, colliders.WIDTH)
        self.collider_data = np.asarray(data, dtype=np.float64).ravel()
        self.meets_moving = bool(moving)
        if hasattr(self, "grid_f"):  # built: the boundary arrays again
            self._check_indices()  # (the saved grid keeps more a node with colliders)
            self._allocate_boundaries()
            if self.requires_grad:
                self._allocate_saved_grid(self.saved_grid.shape[2])
            self._bind()

    def set_couplings(self, couplings):
        """Before build: the (μ, ς m, e) of each of the scene's R rigid entities (R, 3), the default
        of the input "coupling" (B, 3R) that the colliders' rows point into (layout.COUPLING_AT, coupling_columns)."""
        self.couplings = np.asarray(couplings, dtype=np.float64).reshape(-1, 3)

    # -- building ---------------------------------------------------------------------------
    def add_entity(self, name, kind, params, E, nu, rho, Jp, positions):
        """Register an entity's particles (n, 3) m of a material kind (layout.KIND name) with its
        non-differentiable params, E (Pa), nu, rho (kg/m³) and initial Jp; returns the index of
        its first particle."""
        positions = np.asarray(positions, dtype=np.float64)
        self.model.check_inside(name, positions, "its particles")
        start = sum(len(s.positions) for s in self.model.entities)
        self.model.entities.append(EntitySpec(name, kind, dict(params), E, nu, rho, Jp, positions, start))
        self.entity_names.append(name)
        return start

    def build(self, n_envs):
        self.model.finish(encode)
        self.n_batch, m = max(1, n_envs), self.model
        self.serial_chores = runtime.arch == ti.cpu and self.n_batch <= SERIAL_CHORE_ENVS
        self.n_particles = m.n_particles
        self.state_width = m.n_particles * layout.WIDTH
        self._check_memory()
        self._check_indices()
        self._check_substep()
        self._check_resolution()
        self._allocate()
        self.default_inputs = self._default_inputs()
        self.upload_inputs(self.default_inputs)
        state = self._initial_state()
        self.upload_state(state)
        return state

    def _memory_bytes(self):
        """Bytes the solver's arrays take: the grid (4 floats and a list int per node and env, twice:
        p2g scatters half of the particles into a second grid) and
        the particle frames, plus, when it differentiates, what a replay keeps per substep (affine
        matrix, gathered velocity and, for the materials that take one, the SVD: 12 or 33 floats
        per particle) and the gradients' grid and rows."""
        size = torch.finfo(runtime.tc_float).bits // 8
        B, N, K, S = self.n_batch, self.model.n_particles, self.model.grid.n_nodes, self.substeps
        frames = S + 1 if self.requires_grad else 2
        floats = B * (2 * K * 4 + frames * N * layout.WIDTH)
        if self.requires_grad:
            kept = 9 + 3 + (21 if any_needs_svd(self.model.kinds, self.model.consts) else 0)
            floats += B * (S * N * kept + K * 4 + N * (layout.WIDTH + 10))
        return floats * size + 2 * B * K * 4

    def _check_memory(self):
        """The grid and the particle arrays must fit in the memory available now (a named error,
        not a crash)."""
        need, available = self._memory_bytes(), available_memory()
        if available is not None and need > available:
            g = self.model.grid
            raise InvalidInputError(f"MPM solver (entities: {', '.join(self.entity_names)}): the grid of "
                                    f"{' × '.join(str(int(r)) for r in g.res)} nodes and {self.model.n_particles} "
                                    f"particles × {self.n_batch} env(s) need {need / 2**30:.1f} GiB, expected at most "
                                    f"the {available / 2**30:.1f} GiB available; lower MPMOptions grid_density, "
                                    f"tighten lower_bound/upper_bound or use fewer particles")

    def _largest_array(self):
        """(numbers, name) of the largest array the kernels index; the replay's saved grid at the
        largest capacity it can grow to (every node, every substep)."""
        B, N, K, S = self.n_batch, self.model.n_particles, self.model.grid.n_nodes, self.substeps
        frames = S + 1 if self.requires_grad else 2
        sizes = {"the particle frames": frames * B * N * layout.WIDTH, "the grid": B * K * 4}
        if self.requires_grad:
            sizes["the replay's saved grid"] = S * B * K * self.saved_channels
            if any_needs_svd(self.model.kinds, self.model.consts):
                sizes["the replay's SVDs"] = S * B * N * layout.SVD_WIDTH
        name = max(sizes, key=sizes.get)
        return sizes[name], name

    def _check_indices(self):
        """No array may hold more numbers than the kernels' 32-bit indices reach (a named error, not
        a wrapped index)."""
        numbers, name = self._largest_array()
        if numbers > MAX_ARRAY_ELEMENTS:
            g = self.model.grid
            raise InvalidInputError(f"MPM solver (entities: {', '.join(self.entity_names)}): {name} would hold "
                                    f"{numbers:,} numbers (a grid of {' × '.join(str(int(r)) for r in g.res)} "
                                    f"nodes, {self.model.n_particles} particles, {self.n_batch} env(s), "
                                    f"{self.substeps} substeps), expected at most {MAX_ARRAY_ELEMENTS:,}, what "
                                    f"Taichi's 32-bit indices reach; lower MPMOptions grid_density, tighten "
                                    f"lower_bound/upper_bound, or use fewer particles, envs or substeps")

    def _check_substep(self):
        """At build: check_substep with the materials' parameters."""
        m = self.model
        self.check_substep(m.defaults["E"], m.defaults["nu"], m.defaults["rho"])

    def check_substep(self, E, nu, rho):
        """Warn when the substep exceeds the stability limit for particles of Young's modulus E (Pa),
        Poisson ratio nu and density rho (kg/m³), arrays of one shape: Genesis's suggested
        h ≤ 2e-2·dx, and the elastic wave's CFL bound h ≤ WAVE_CFL·dx / c with c = √((λ + 2μ)/ρ)
        of the stiffest particle (also after set_material_params raises a stiffness); only past the
        worst excess warned before (_worse)."""
        m, h = self.model, self.dt / self.substeps
        E, nu, rho = np.asarray(E, dtype=np.float64), np.asarray(nu, dtype=np.float64), np.asarray(rho, dtype=np.float64)
        modulus = E * (1 - nu) / ((1 + nu) * (1 - 2 * nu))  # λ + 2μ
        wave = float(np.sqrt(np.max(modulus / rho))) if modulus.size else 0.0
        wave_limit = WAVE_CFL * m.grid.dx / wave if wave > 0 else np.inf
        limit = min(GENESIS_DT_PER_DX * m.grid.dx, wave_limit)
        if self._worse("substep", h / limit):
            warn_user(f"MPM solver (entities: {', '.join(self.entity_names)}): the substep dt / substeps = "
                      f"{h:.3g} s exceeds the stability limit {limit:.3g} s (min of 2e-2·dx = "
                      f"{GENESIS_DT_PER_DX * m.grid.dx:.3g} s and {WAVE_CFL:g}·dx / wave speed = {wave_limit:.3g} s); "
                      f"the simulation may blow up: raise SimOptions substeps or lower dt (said again only for a "
                      f"worse one)")

    def _worse(self, kind, excess):
        """Whether ``excess`` (> 1: past the bound) is worse than any the ``kind`` warning reported;
        it is then the worst."""
        if excess <= self.warned_excess.get(kind, 1.0):
            return False
        self.warned_excess[kind] = excess
        return True

    def _check_resolution(self):
        """Warn when particles are coarser than the grid's cells: a body's particles then couple
        weakly through the nodes they share, and from 3·dx apart (a quadratic kernel's reach) share
        none and move as free particles (measured: one pushed particle moves none of its 63
        neighbours at 3·dx, all of them at 2·dx)."""
        dx = self.model.grid.dx
        if self.particle_size > dx:
            warn_user(f"MPM solver (entities: {', '.join(self.entity_names)}): particle_size "
                      f"{self.particle_size:.3g} m exceeds the grid's cell size dx = {dx:.3g} m: fewer than one "
                      f"particle a cell, a body's particles couple weakly (from 3·dx on, not at all); lower "
                      f"MPMOptions particle_size (Genesis's default is 0.64·dx) or grid_density")

    def check_speed(self, speed, who):
        """Warn when a speed (m/s) given to particles crosses more than a grid cell in a substep:
        explicit MPM's transfers are unstable past that (measured: a neo-Hookean block thrown at
        1.6 cells a substep turned to NaN at its first step); only past the fastest ``who`` warned of
        before. who: the call and its entity, for the message."""
        h, dx = self.dt / self.substeps, self.model.grid.dx
        if self._worse(("speed", who), speed * h / dx):
            warn_user(f"{who}: a particle speed of {speed:.3g} m/s crosses {speed * h / dx:.3g} grid cells a "
                      f"substep (dt / substeps = {h:.3g} s, dx = {dx:.3g} m): past one cell a substep the "
                      f"simulation may blow up; raise SimOptions substeps (said again here only for a faster one)")

    def _allocate(self):
        m, B, N = self.model, self.n_batch, self.model.n_particles
        S, g = self.substeps, m.grid

        def floats(*shape):
            return torch.zeros(shape, dtype=runtime.tc_float, device=runtime.device)

        def ints(*shape):
            return torch.zeros(shape, dtype=torch.int32, device=runtime.device)

        self.n_frames = S + 1 if self.requires_grad else 2
        self.frames = floats(self.n_frames, B, N, layout.WIDTH)
        self.params = floats(B, N, len(layout.PARTICLE_INPUTS))
        self.env_in = floats(B, layout.COUPLING_AT + self.couplings.size)
        self.kinds = torch.as_tensor(m.kinds, device=runtime.device)
        self.consts = torch.as_tensor(m.consts, dtype=runtime.tc_float, device=runtime.device)
        self.fiber = floats(N, 3)  # uploaded from the input "fiber" (layout)
        self.affine = floats(S if self.requires_grad else 1, B, N, 9)
        self.grid = floats(B, g.n_nodes, 4)
        self.active = ints(B + 1, g.n_nodes + 1)
        self.part_grid, self.part_nodes = floats(B, g.n_nodes, 4), ints(B + 1, g.n_nodes + 1)  # p2g's second half
        self._allocate_boundaries()
        self.flags = ints(1)
        self.current = 0  # the frame holding the current state
        self.replaying = False  # set by begin_reverse until the replay's end_step: keep what the reverse reads
        self.nodes_listed = False  # a substep's launch listed grid nodes that its last launch has not cleared
        if self.requires_grad:
            self._allocate_reverse()
        else:  # what a replay keeps: never written by plain steps
            self.svd, self.gathered = floats(1, 1, 1, 21), floats(1, 1, 1, 3)
            self.saved_grid, self.saved_nodes = floats(1, 1, 1, 4), ints(1, 1, 1)
        self._bind()

    @property
    def has_colliders(self):
        return len(self.collider_rows) > 0

    @property
    def saved_channels(self):
        """Numbers a replay keeps per listed node and substep (grid.grid_stage): v, M; with colliders
        the velocity before them; with a coupler the velocity before it (7:10)."""
        return 10 if self.meets_moving else (7 if self.has_colliders else 4)

    def _allocate_boundaries(self):
        """grid_f and grid_i (kernels.py): the step, the grid, the walls and the colliders."""
        m, g = self.model, self.model.grid
        self.grid_f = torch.as_tensor([self.dt / self.substeps, g.density, m.vol, *g.wall_lower, *g.wall_upper,
                                       *colliders.packed(self.collider_rows, self.collider_data)],
                                      dtype=runtime.tc_float, device=runtime.device)
        self.grid_i = torch.as_tensor([*g.lowest, *g.res, int(m.sticky), len(self.collider_rows)], dtype=torch.int32,
                                      device=runtime.device)

    def _arrays(self):
        """The forward kernels' arrays, in their order; the particle rows and the grids flat
        (stencil.row_at, stencil.node_count)."""
        return [self.frames.view(-1), self.params, self.env_in, self.kinds, self.consts, self.fiber,
                self.affine.view(-1), self.svd.view(-1), self.grid.view(-1), self.active, self.part_grid.view(-1),
                self.part_nodes, self.grid_f, self.grid_i, self.flags, self.gathered.view(-1), self.saved_grid,
                self.saved_nodes]

    def _bind(self):
        """Bind the kernels to the arrays (again after the saved grid grows)."""
        arrays = self._arrays()
        dims = [0] * len(arrays)
        takes_svd = any_needs_svd(self.model.kinds, self.model.consts)
        config = (self.serial_chores, self.has_colliders, self.meets_moving)
        self.kernels = BoundKernels((False, *config), arrays, dims, *kernels.KERNELS).bind(
            (takes_svd, *config), arrays, dims, *kernels.STRESS_KERNELS)
        if self.requires_grad:
            self._bind_reverse()

    def _default_inputs(self):
        m, B = self.model, self.n_batch
        values = {"E": m.defaults["E"], "nu": m.defaults["nu"], "rho": m.defaults["rho"],
                  "actu": np.zeros(m.n_particles), "gravity": self.gravity, "coupling": self.couplings.ravel(),
                  "fiber": np.tile(layout.DEFAULT_FIBER, m.n_particles)}
        return {name: torch.as_tensor(np.tile(v, (B, 1)), dtype=runtime.tc_float, device=runtime.device)
                for name, v in values.items()}

    def _initial_state(self):
        m = self.model
        rows = np.zeros((m.n_particles, layout.WIDTH))
        rows[:, 0:3] = m.pos0
        rows[:, 15:24] = np.eye(3).ravel()
        rows[:, 24] = m.Jp0
        return torch.as_tensor(np.tile(rows.ravel(), (self.n_batch, 1)), dtype=runtime.tc_float,
                               device=runtime.device)

    # -- moving data ------------------------------------------------------------------------
    def upload_state(self, state, envs=None):
        self.kernels.write_state(self.current, state.detach().contiguous())

    def download_state(self):
        out = new_state((self.n_batch, self.state_width), self.own_state_pages)
        self.kernels.read_state(self.current, out)
        return out

    def upload_inputs(self, inputs):
        with torch.no_grad():
            self.params.copy_(torch.stack([inputs[name] for name in layout.PARTICLE_INPUTS], dim=-1))
            self.env_in.copy_(torch.cat([inputs[name] for name in layout.ENV_INPUTS], dim=1))
            self.fiber.copy_(inputs["fiber"][0].view(-1, 3))

    # -- stepping ---------------------------------------------------------------------------
    def begin_step(self, inputs):
        self.clear_listed_nodes()
        if inputs is not None:
            self.upload_inputs(inputs)

    def clear_listed_nodes(self):
        """The grid empty again where a substep stopped between its launches (an error or an
        interrupt between pre and post coupling, or between a substep's reverse launches): the
        next scatter would add to the nodes it left. Every launch after the first of a substep's
        keeps the grid's listed nodes; the last clears them."""
        if self.nodes_listed:
            for array in [self.grid, self.active, self.part_grid, self.part_nodes] + (
                    [self.grad_grid] if self.requires_grad else []):
                array.zero_()
            self.nodes_listed = False

    def _frames(self, s):
        """(source frame, destination frame, keep) of substep s of the step that starts at
        ``current``; keep: s in a replay (the kernels keep what the reverse reads), else −1."""
        return ((self.current + s) % self.n_frames, (self.current + s + 1) % self.n_frames,
                s if self.replaying else -1)

    def substep_pre_coupling(self, s):
        self.nodes_listed = True
        self.kernels.pre_coupling(*self._frames(s))

    def substep_post_coupling(self, s):
        self.kernels.post_coupling(*self._frames(s))
        self.nodes_listed = False

    def end_step(self, download):
        if self.replaying:
            self.end_replay()
        self.current = (self.current + self.substeps) % self.n_frames
        return self.download_state() if download else None

    def advance(self, inputs=None, download=False):
        """A whole step, one launch per substep (kernels.substep fuses pre and post coupling)."""
        self.begin_step(inputs)
        self.nodes_listed = True  # (a launch that raised midway: its nodes may stay listed)
        for s in range(self.substeps):
            self.kernels.substep(*self._frames(s))
        self.nodes_listed = False
        return self.end_step(download)

    def nonfinite(self):
        flagged = bool(self.flags[0])
        self.flags.zero_()
        return flagged

    def entity_columns(self):
        """Each entity's particles' rows (layout.WIDTH columns a particle)."""
        return [(e.name, np.arange(e.start * layout.WIDTH, (e.start + len(e.positions)) * layout.WIDTH))
                for e in self.model.entities]

    def warm_start(self):
        return None

    def set_warm_start(self, warm_start):
        pass

    def destroy(self):
        self.kernels = self.reverse_kernels = self.frames = self.grid = None
