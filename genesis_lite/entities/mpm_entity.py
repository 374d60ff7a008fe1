"""MPM entities: a body of particles (Genesis's MPMEntity), seen through getters and setters of
the MPM solver's state and per-particle inputs (solvers/mpm/layout.py).

Every getter reads the simulator's torch state, so with SimOptions(requires_grad=True) it is
part of the autograd graph; every setter writes out of place, so gradients reach what was set.
Local particle indices count within the entity; in a batched scene (n_envs > 0) results gain a
leading batch dimension and ``envs_idx`` selects environments. Units: m, m/s, Pa, kg/m³, kg.
"""
import numpy as np
import torch

from .. import morphs as gm
from ..materials import MPM
from ..solvers.core import AssetError, InvalidInputError, SceneStateError, refuse_grad, runtime, warn_user
from ..solvers.mpm import layout, sampling
from ..tensor import wrap
from ..utils.uid import UID
from .common import EntityIndexing, all_finite, broadcast, is_range, named_argument_errors, replace_columns


def sample_particles(morph, material, particle_size, wall_lower, wall_upper, seed, name):
    """World positions (n, 3) float64 of the particles of an MPM entity named ``name``: its morph
    (Box, Sphere, Cylinder, Mesh) filled by the material's sampler at ``particle_size`` m
    (``seed`` seeds the random sampler). Every particle must lie strictly between the MPM
    walls (wall_lower, wall_upper (3,) m), as Genesis requires."""
    owner = f"entity '{name}'"
    if morph.fixed and not isinstance(morph, gm.Plane):  # a Plane is always fixed: refused below
        raise InvalidInputError(f"{owner}: argument 'fixed' of gs.morphs.{type(morph).__name__} must be False for an "
                                f"MPM entity (its particles move; only the walls hold them), got True")
    if isinstance(morph, gm.Capsule) or not isinstance(morph, (gm.Box, gm.Sphere, gm.Cylinder, gm.Mesh)):
        raise InvalidInputError(f"{owner}: argument 'morph' of an MPM entity must be gs.morphs.Box, Sphere, Cylinder "
                                f"or Mesh, got {type(morph).__name__}")
    if (morph.contype, morph.conaffinity, morph.collision, morph.visualization) != (0xFFFF, 0xFFFF, True, True):
        raise InvalidInputError(f"{owner}: arguments 'contype', 'conaffinity', 'collision' and 'visualization' of "
                                f"gs.morphs.{type(morph).__name__} are a rigid entity's (Genesis ignores them here): an "
                                f"MPM entity takes the defaults (0xFFFF, 0xFFFF, True, True), got {morph.contype:#x}, "
                                f"{morph.conaffinity:#x}, {morph.collision}, {morph.visualization}")
    shape, dims = _shape(morph)
    try:
        particles = sampling.sample(shape, particle_size, material.sampler, seed, morph.pos, morph.quat, owner=owner,
                                    **dims)
    except AssetError as exc:  # sampling does not know the entity: add it to the message
        raise AssetError(f"{owner}: argument 'file' of gs.morphs.Mesh: {exc}") from exc
    _check_volume(owner, morph, len(particles), particle_size, sampling.shape_volume(shape, **dims))
    _check_inside(owner, "morph", particles, wall_lower, wall_upper, strictly=True)
    return particles


def _shape(morph):
    """(sampling's shape name, its parameters) of a Box, Sphere, Cylinder or Mesh morph."""
    if isinstance(morph, gm.Box):
        return "box", {"size": morph.size}
    if isinstance(morph, gm.Sphere):
        return "sphere", {"radius": float(morph.radius)}
    if isinstance(morph, gm.Cylinder):
        return "cylinder", {"radius": float(morph.radius), "height": float(morph.height)}
    return "mesh", {"file": morph.file, "scale": morph.scale, "y_up": not morph.file_meshes_are_zup}


def _check_volume(owner, morph, count, particle_size, volume):
    """Warn when the particles' volume (count · particle_size³, which makes the mass) is off the
    morph's volume m³ by more than 2× either way: particles too coarse for the shape (Genesis
    samples and weighs them alike, without a word)."""
    ratio = count * particle_size ** 3 / volume if volume > 0 else np.inf  # (a flat mesh has none)
    if not 0.5 <= ratio <= 2.0:
        # (a mesh whose surface crosses itself: its volume counts the overlaps, its inside, by ray
        # parity, leaves them empty)
        overlap = " or its surface overlaps itself (the overlaps are left empty)" if isinstance(morph, gm.Mesh) else ""
        warn_user(f"{owner}: its {count} particle(s) of particle_size {particle_size:g} m hold {ratio:.3g}× the "
                  f"volume of its {type(morph).__name__} ({volume:.3g} m³), and its mass is ρ · that volume: "
                  f"particle_size is too coarse for the shape{overlap}; lower MPMOptions particle_size (at most "
                  f"{volume ** (1.0 / 3.0) / 4.0:.3g} m puts 4 or more particles across it)")


def _check_inside(owner, arg, positions, wall_lower, wall_upper, strictly):
    """Raise unless every position (…, 3) (numpy) lies between the walls: ``strictly`` for a morph's
    particles (Genesis's check), else on them too, where the solver keeps particles that reach a
    wall (g2p.wall_particle), so that what get_particles_pos returns is accepted back."""
    # (in the positions' precision: the kernels clamp particles onto the walls rounded to it)
    lower, upper = np.asarray(wall_lower).astype(positions.dtype), np.asarray(wall_upper).astype(positions.dtype)
    inside = (np.all(positions > lower) and np.all(positions < upper)) if strictly else \
        (np.all(positions >= lower) and np.all(positions <= upper))
    if not inside:
        flat = positions.reshape(-1, 3)
        where = "strictly inside the MPM walls" if strictly else "inside the MPM walls (or on them)"
        raise InvalidInputError(f"{owner}: argument '{arg}' must put every particle {where} "
                                f"(MPMOptions lower_bound / upper_bound, 3 cells inside them): between "
                                f"{lower.tolist()} and {upper.tolist()} m, got particles spanning "
                                f"{flat.min(0).tolist()} to {flat.max(0).tolist()} m")


class MPMEntityState:
    """One entity's particle state (torch views, differentiable): pos, vel (B, n, 3); C, F
    (B, n, 3, 3); Jp (B, n), B = max(1, n_envs) as Genesis's."""

    def __init__(self, entity, pos, vel, C, F, Jp):
        self.entity = entity
        self.pos, self.vel, self.C, self.F, self.Jp = pos, vel, C, F, Jp


@named_argument_errors
class MPMEntity(EntityIndexing):
    """Particles of one material in the MPM solver: rows particle_start … particle_start +
    n_particles − 1 of its state and per-particle inputs.

    particles: the sampled world positions (n, 3) (sample_particles), whose offsets from
    morph.pos set_position uses to move the body as a whole.
    The solver provides: ``wall_lower`` / ``wall_upper`` (3,) numpy m and ``particle_size`` m.
    """

    def __init__(self, scene, idx, name, morph, material, surface, solver, particle_start, n_particles,
                 particles=None):
        self.scene, self.idx, self.name = scene, idx, name
        self.morph, self.material, self.surface = morph, material, surface
        self.uid = UID()  # (Genesis's: scene.get_entity(uid=...) finds the entity by its short form)
        self._solver = solver
        self.particle_start, self.n_particles = int(particle_start), int(n_particles)
        self.init_particles = None if particles is None else np.asarray(particles, dtype=np.float64)
        if self.init_particles is not None and self.init_particles.shape != (self.n_particles, 3):
            raise InvalidInputError(f"entity '{name}': argument 'particles' must have shape {(self.n_particles, 3)}, "
                                    f"got {self.init_particles.shape}")
        self._muscle_group = np.zeros(self.n_particles, dtype=np.int64)
        # (B, n_groups) each env's group actuation as set_actuation gave it (None: never given), and
        # the simulator's generation (reset count) it was set in: set_muscle moves particles to
        # their new groups' actuation
        self._group_actuation, self._actuation_generation = None, None

    def _on_build(self):
        """Nothing to resolve: the particle rows are known when the entity is added."""

    @property
    def particle_end(self):
        return self.particle_start + self.n_particles

    @property
    def particle_size(self):
        """Particle diameter, m (MPMOptions.particle_size)."""
        return self._solver.particle_size

    # -- raw state/input access -------------------------------------------------------------------
    def _particle_rows(self, envs, first=0, last=layout.WIDTH):
        """(len(envs), n_particles, last − first) columns first..last of the entity's state rows in
        envs ``envs`` (int array), a copy (never a view a caller could change the state through),
        made of those columns only (gathering whole rows first cost ~20 ms for 10k particles)."""
        state = self._sim().state(self._solver)
        rows = state.reshape(state.shape[0], -1, layout.WIDTH)[:, self.particle_start: self.particle_end, first:last]
        return rows.clone() if is_range(envs, state.shape[0]) else rows[torch.as_tensor(envs, device=rows.device)]

    def _check_state(self, state, owner):
        """Raise unless the positions in ``state`` (a scene state tensor of the solver's, (B,
        n_particles · WIDTH)) put this entity's particles inside the walls, as set_particles_pos
        requires (the kernels would clamp them onto a wall). owner: the caller, for the message."""
        rows = state.reshape(state.shape[0], -1, layout.WIDTH)[:, self.particle_start: self.particle_end]
        _check_inside(f"{owner}, entity '{self.name}'", "state", rows[..., slice(*layout.STATE["pos"])].cpu().numpy(),
                      self._solver.wall_lower, self._solver.wall_upper, strictly=False)

    def _field(self, name, envs_idx):
        """State field ``name`` (layout.STATE) of every particle: (…, n, width)."""
        return self._out(self._particle_rows(self._envs(envs_idx), *layout.STATE[name]))

    def _write_fields(self, names, parts, envs, values):
        """State fields ``names`` (consecutive in layout.STATE) of particles ``parts`` (local int
        array) in envs ← values (len(envs), len(parts), their total width), out of place."""
        first, last = layout.STATE[names[0]][0], layout.STATE[names[-1]][1]
        columns = ((self.particle_start + parts)[:, None] * layout.WIDTH + np.arange(first, last)[None, :]).ravel()
        self._sim().write_state(self._solver, envs, columns, values.reshape(len(envs), len(columns)))

    def _write_input(self, name, parts, envs, values):
        """Per-particle input ``name`` of particles ``parts`` in envs ← values (len(envs), len(parts))."""
        sim = self._sim()
        table = sim.inputs(self._solver)[name]
        sim.set_input(self._solver, name, replace_columns(table, envs, self.particle_start + parts, values))

    def _particle_values(self, value, n_parts, element, envs, arg):
        """User values → (len(envs), n_parts, *element) tensor, broadcast to (n_parts, *element)
        (unbatched scene) or (len(envs), n_parts, *element) (batched) as Genesis broadcasts
        (``common.broadcast``): (*element,) applies to every particle, (n_parts, *element) to every
        env, (len(envs), *element) one per env. Finite."""
        target = (n_parts, *element) if self.scene.n_envs == 0 else (len(envs), n_parts, *element)
        given = self._tensor(value, arg, target)
        tensor = broadcast(given, target)
        if tensor is None:
            per_env = f", {(len(envs), *element)} one per env" if self.scene.n_envs else ""
            raise InvalidInputError(f"entity '{self.name}': argument '{arg}' must have shape {target} (or one that "
                                    f"broadcasts to it, e.g. {tuple(element) or '()'} for every particle{per_env}), "
                                    f"got {tuple(given.shape)}")
        if not all_finite(tensor.detach()):
            raise InvalidInputError(f"entity '{self.name}': argument '{arg}' must be finite, got NaN or inf")
        return tensor.reshape(len(envs), n_parts, *element)

    # -- particle state ---------------------------------------------------------------------------
    def get_particles_pos(self, envs_idx=None):
        """Particle positions, m: (n_particles, 3) or (n_envs, n_particles, 3)."""
        return self._field("pos", envs_idx)

    def get_particles_vel(self, envs_idx=None):
        """Particle velocities, m/s: (n_particles, 3) or (n_envs, n_particles, 3)."""
        return self._field("vel", envs_idx)

    def set_particles_pos(self, poss, particles_idx_local=None, envs_idx=None):
        """Particle positions, m: (n, 3) for the particles of particles_idx_local (all by
        default), (len(envs_idx), n, 3) per env, or anything broadcasting to it. As Genesis, the
        particles set start afresh: velocity 0, C = 0, F = I, Jp at the material's rest value.
        Every position must lie inside the MPM walls (on them included). Differentiable in ``poss``."""
        parts = self._local(particles_idx_local, self.n_particles, "particles_idx_local", distinct=True)
        envs = self._envs(envs_idx, distinct=True)
        pos = self._particle_values(poss, len(parts), (3,), envs, "poss")
        _check_inside(f"entity '{self.name}'", "poss", pos.detach().cpu().numpy(), self._solver.wall_lower,
                      self._solver.wall_upper, strictly=False)
        rest = pos.new_zeros(len(envs), len(parts), layout.WIDTH - 3)  # vel, C, F, Jp after pos
        rest[..., _span("F", 3)] = torch.eye(3, dtype=pos.dtype, device=pos.device).reshape(9)
        rest[..., _span("Jp", 3)] = self.material.default_Jp
        self._write_fields(("pos", "vel", "C", "F", "Jp"), parts, envs, torch.cat([pos, rest], dim=-1))

    def set_particles_vel(self, vels, particles_idx_local=None, envs_idx=None):
        """Particle velocities, m/s: shapes as set_particles_pos (a (3,) value sets every
        particle's). Differentiable in ``vels``."""
        parts = self._local(particles_idx_local, self.n_particles, "particles_idx_local", distinct=True)
        envs = self._envs(envs_idx, distinct=True)
        values = self._particle_values(vels, len(parts), (3,), envs, "vels")
        if values.numel():
            speed = float(values.detach().norm(dim=-1).max())
            self._solver.check_speed(speed, f"entity '{self.name}': set_particles_vel")
        self._write_fields(("vel",), parts, envs, values)

    def set_position(self, value, envs_idx=None):
        """Genesis's set_position: (n_particles, 3) or (len(envs_idx), n_particles, 3) sets every
        particle (set_particles_pos); (3,) or (len(envs_idx), 3) moves the body as a whole so
        that its origin (where morph.pos put it) is there, the particles at their sampled
        offsets. A (n, 3) value with n == n_particles is per particle (as Genesis); a (1, 3) one
        in a scene without envs, a centre (as Genesis, and as set_velocity takes it)."""
        tensor = self._tensor(value, "value", "(3,) or (n_particles, 3)")
        if self.scene.n_envs == 0 and tuple(tensor.shape) == (1, 3) and self.n_particles != 1:
            tensor = tensor[0]
        if tensor.dim() == 1 or (tensor.dim() == 2 and tensor.shape[0] != self.n_particles):
            if tensor.shape[-1] != 3 or (tensor.dim() == 2 and self.scene.n_envs == 0):
                centres = "(3,)" if self.scene.n_envs == 0 else "(3,) or (len(envs_idx), 3)"
                raise InvalidInputError(f"entity '{self.name}': argument 'value' must be a centre {centres} or the "
                                        f"particles' positions ({self.n_particles}, 3), got {tuple(tensor.shape)}")
            if self.init_particles is None:
                raise SceneStateError(f"entity '{self.name}': set_position with a centre needs the sampled "
                                      f"particles, which the scene did not give the entity")
            centres = self._values(tensor, 3, self._envs(envs_idx, distinct=True), "value")  # (len(envs), 3)
            offsets = torch.as_tensor(self.init_particles - np.asarray(self.morph.pos), dtype=centres.dtype,
                                      device=centres.device)
            tensor = offsets + centres[:, None, :]  # (len(envs), n_particles, 3)
            # (checked here so that the message names this call's argument, not set_particles_pos's)
            _check_inside(f"entity '{self.name}'", "value", tensor.detach().cpu().numpy(), self._solver.wall_lower,
                          self._solver.wall_upper, strictly=False)
            tensor = tensor[0] if self.scene.n_envs == 0 else tensor
        self.set_particles_pos(tensor, None, envs_idx)

    def set_velocity(self, vels, envs_idx=None):
        """Genesis's set_velocity: every particle's velocity, m/s ((3,), (n_particles, 3) or
        (len(envs_idx), n_particles, 3))."""
        self.set_particles_vel(vels, None, envs_idx)

    def get_state(self):
        """MPMEntityState of every env: pos, vel, C, F, Jp (differentiable torch views), each with a
        leading env axis, of 1 in a scene built without envs, as Genesis's (its idiom
        ``get_state().pos[0]``, every particle of env 0, took particle 0 when the axis was dropped)."""
        rows = self._particle_rows(self._envs(None))
        lead = rows.shape[:-1]
        field = lambda name, shape: wrap(rows[..., slice(*layout.STATE[name])].reshape(*lead, *shape), self.scene)
        return MPMEntityState(self, field("pos", (3,)), field("vel", (3,)), field("C", (3, 3)), field("F", (3, 3)),
                              field("Jp", ()))

    # -- material parameters ------------------------------------------------------------------------
    def set_material_params(self, E=None, nu=None, rho=None, particles_idx_local=None, envs_idx=None):
        """Young's modulus E (Pa, > 0), Poisson ratio nu (in (−1, 0.5)) and density rho (kg/m³,
        > 0) of the particles (all by default): a scalar for all, (n,) per particle,
        (len(envs_idx), n) per env and particle. None leaves a parameter as it is. Differentiable
        (Genesis's are compile-time constants). Every value is checked before any is written."""
        parts = self._local(particles_idx_local, self.n_particles, "particles_idx_local", distinct=True)
        envs = self._envs(envs_idx, distinct=True)
        limits = {"E": (0.0, np.inf, "> 0 (Pa)"), "nu": (-1.0, 0.5, "in (−1, 0.5)"),
                  "rho": (0.0, np.inf, "> 0 (kg/m³)")}
        checked = {}
        for name, value in (("E", E), ("nu", nu), ("rho", rho)):
            if value is None:
                continue
            values = self._particle_values(value, len(parts), (), envs, name)
            lo, hi, what = limits[name]
            held = values.detach()
            if not bool(((held > lo) & (held < hi)).all()):
                raise InvalidInputError(f"entity '{self.name}': argument '{name}' must be {what}, got values from "
                                        f"{held.min().item():g} to {held.max().item():g}")
            checked[name] = values
        for name, values in checked.items():
            self._write_input(name, parts, envs, values)
        if checked:  # a stiffer or lighter material may need a shorter substep
            inputs = self._sim().inputs(self._solver)
            columns = torch.as_tensor(self.particle_start + parts, device=runtime.device)
            rows = torch.as_tensor(envs, device=runtime.device)
            self._solver.check_substep(*(inputs[name][rows][:, columns].detach().cpu().numpy()
                                         for name in ("E", "nu", "rho")))

    def get_mass(self, envs_idx=None):
        """Total mass, kg: Σ rho · particle_size³, () or (n_envs,); differentiable in rho."""
        envs = torch.as_tensor(self._envs(envs_idx), device=runtime.device)
        rho = self._sim().inputs(self._solver)["rho"][envs][:, self.particle_start: self.particle_end]
        return self._out(rho.sum(-1) * self.particle_size ** 3)

    # -- muscles ---------------------------------------------------------------------------------------
    @property
    def is_muscle(self):
        return isinstance(self.material, MPM.Muscle)

    def held_groups(self):
        """(B, n_groups) a detached copy of the groups' actuation, for a state snapshot."""
        return self._group_actuations().detach().clone()

    def restore_groups(self, table, envs):
        """At a reset: the groups' actuation of the envs ``envs`` (None: all) ← ``table`` (B,
        n_groups, a held_groups() of the registered state; None: zeros, the build's), and the
        particles' actuation from it (the reset cleared it, as a control)."""
        current = self._group_actuations()
        source = torch.zeros_like(current) if table is None else table
        rows = np.arange(current.shape[0]) if envs is None else envs
        self._group_actuation = replace_columns(current.detach(), rows, np.arange(current.shape[1]), source[rows])
        self._write_actuation(rows)

    def _require_muscle(self, method):
        if not self.is_muscle:
            raise InvalidInputError(f"entity '{self.name}': {method} needs a gs.materials.MPM.Muscle entity, got "
                                    f"{type(self.material).__qualname__}")

    def set_actuation(self, actus, envs_idx=None):
        """Muscle actuation per group (no unit): a scalar for all groups, (n_groups,), or
        (len(envs_idx), n_groups); each particle takes its group's value (set_muscle) until the
        next call or scene.reset(). Differentiable in ``actus``."""
        self._require_muscle("set_actuation")
        envs = self._envs(envs_idx, distinct=True)
        n_groups = self.material.n_groups
        target = (n_groups,) if self.scene.n_envs == 0 else (len(envs), n_groups)
        given = self._tensor(actus, "actus", target)
        groups = broadcast(given, target)
        if groups is None:
            raise InvalidInputError(f"entity '{self.name}': argument 'actus' must have shape {target} (one value per "
                                    f"muscle group), or be one number, got {tuple(given.shape)}")
        if not all_finite(groups.detach()):
            raise InvalidInputError(f"entity '{self.name}': argument 'actus' must be finite, got NaN or inf")
        groups = groups.reshape(len(envs), n_groups)
        self._group_actuation = replace_columns(self._group_actuations(), envs, np.arange(n_groups), groups)
        self._write_actuation(envs)

    def _group_actuations(self):
        """(B, n_groups) the groups' actuation as set_actuation last set it (zeros at first);
        detached after a reset, as the scene's parameters (a graph from the rollout before would be
        backpropagated through again)."""
        sim = self._sim()
        if self._group_actuation is None:
            n_batch = sim.inputs(self._solver)["actu"].shape[0]
            self._group_actuation = torch.zeros(n_batch, self.material.n_groups, dtype=runtime.tc_float,
                                                device=runtime.device)
        elif self._actuation_generation != sim.generation:
            self._group_actuation = self._group_actuation.detach()
        self._actuation_generation = sim.generation
        return self._group_actuation

    def _write_actuation(self, envs):
        """The input "actu" of the envs ``envs`` ← each particle's group's actuation."""
        groups = self._group_actuations()[torch.as_tensor(envs, device=runtime.device)]
        per_particle = groups[:, torch.as_tensor(self._muscle_group, device=groups.device)]
        self._write_input("actu", np.arange(self.n_particles), envs, per_particle)

    def _actuation_held(self):
        """The envs (int array) whose "actu" input still holds what set_actuation wrote for this
        entity's particles (a reset writes both again, the registered state's)."""
        held = self._sim().inputs(self._solver)["actu"][:, self.particle_start: self.particle_end].detach()
        expected = self._group_actuations().detach()[:, torch.as_tensor(self._muscle_group, device=held.device)]
        return np.flatnonzero((held == expected).all(dim=1).cpu().numpy())

    def set_muscle(self, muscle_group=None, muscle_direction=None):
        """Genesis's set_muscle: muscle_group (n_particles,) integers in [0, n_groups) (all 0 at
        first): each particle takes its new group's actuation at once, as set_actuation last set it
        (Genesis reads a particle's group at every step); muscle_direction (n_particles, 3) or (3,)
        fibre directions d, taken as given, as Genesis (the active stress E·actu·(F d)(F d)ᵀ grows
        with |d|²: one of length 2 pulls 4× as hard; (0, 0, 1) at first). Not differentiable: a
        tensor that requires grad raises GradientError."""
        self._require_muscle("set_muscle")
        self._sim()
        for name, value in (("muscle_group", muscle_group), ("muscle_direction", muscle_direction)):
            refuse_grad(f"entity '{self.name}'", name, value, "a muscle's groups and fibres are model data; its "
                        "actuation (set_actuation) is differentiable")
        if muscle_group is not None:
            group = muscle_group.detach().cpu().numpy() if isinstance(muscle_group, torch.Tensor) else \
                np.asarray(muscle_group)
            n_groups = self.material.n_groups
            if group.shape != (self.n_particles,) or group.dtype.kind not in "iu" or \
                    (group.size and (group.min() < 0 or group.max() >= n_groups)):
                raise InvalidInputError(f"entity '{self.name}': argument 'muscle_group' must be {self.n_particles} "
                                        f"integers in [0, {n_groups}), got shape {group.shape} of {group.dtype}")
            # (the envs a reset cleared keep no actuation; none to move before set_actuation)
            held = self._actuation_held() if self._group_actuation is not None else ()
            self._muscle_group = group.astype(np.int64)
            if len(held):
                self._write_actuation(held)
        if muscle_direction is not None:
            directions = np.asarray(muscle_direction.detach().cpu().numpy() if isinstance(muscle_direction,
                                    torch.Tensor) else muscle_direction, dtype=np.float64)
            if directions.shape not in ((3,), (self.n_particles, 3)):
                raise InvalidInputError(f"entity '{self.name}': argument 'muscle_direction' must have shape (3,) or "
                                        f"{(self.n_particles, 3)}, got {directions.shape}")
            directions = np.broadcast_to(directions, (self.n_particles, 3)).copy()
            if not np.all(np.isfinite(directions)):
                raise InvalidInputError(f"entity '{self.name}': argument 'muscle_direction' must hold finite "
                                        f"vectors, got a non-finite one")
            self._write_fibers(directions)

    def _write_fibers(self, directions):
        """The solver's input "fiber" (B, N · 3; every env alike) ← the directions (n, 3) of
        this entity's particles: an input, so that each step records the fibres it ran with."""
        sim = self._sim()
        table = sim.inputs(self._solver)["fiber"]
        columns = 3 * self.particle_start + np.arange(3 * self.n_particles)
        values = torch.as_tensor(directions, dtype=table.dtype, device=table.device).reshape(1, -1)
        sim.set_input(self._solver, "fiber", replace_columns(table, np.arange(table.shape[0]), columns,
                                                             values.expand(table.shape[0], -1)))

    def get_muscle_group(self):
        """(n_particles,) int64 tensor: each particle's muscle group."""
        self._require_muscle("get_muscle_group")
        return wrap(torch.as_tensor(self._muscle_group, device=runtime.device), self.scene)

    def __repr__(self):
        return f"MPMEntity({self.name!r}, {type(self.material).__qualname__}, n_particles={self.n_particles})"


def _span(name, skip):
    """The columns of state field ``name`` in a row from which the first ``skip`` columns were dropped."""
    first, last = layout.STATE[name]
    return slice(first - skip, last - skip)
