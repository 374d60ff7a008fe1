"""The scene: entities are added, then ``build(n_envs)`` fixes everything and ``step()`` runs.

Lifecycle errors (step before build, build twice, add after build) raise SceneStateError.
Cameras (``add_camera``, vis/camera.py) render the scene headless, before or after build (Genesis
only before); they read ``vis_options`` and draw the debug objects of ``draw_debug_*``.
There is no interactive viewer: ``show_viewer=True`` raises rather than being ignored, and
``viewer_options`` are validated and kept for it.
"""
import collections
import dataclasses
import os
import re
import xml.etree.ElementTree as ET

import numpy as np
import torch

from . import morphs as gm
from .entities import DroneEntity, MPMEntity, RigidEntity
from .entities.common import EntityIndexing, named_argument_errors, replace_columns
from .entities.mpm_entity import sample_particles
from .solvers.core import AssetError, InvalidInputError, SceneStateError, warn_user
from .materials import MPM, Rigid
from .options import (LegacyCouplerOptions, MPMOptions, RigidOptions, SimOptions, ViewerOptions, VisOptions,
                      check_bool, is_int)
from .rigid_solver import RigidSolverView
from .runtime import free_dropped_scenes, require_init, runtime, track
from .simulator import Simulator, refuse_inference_mode
from .solvers.coupler import Coupler
from .solvers.coupling import rigid_colliders
from .solvers.mpm.solver import MPMSolver
from .solvers.rigid import merge, mjcf, scale, shapes, urdf
from .solvers.rigid.solver import RigidSolver
from .surfaces import Default
from .vis.camera import Camera
from .vis import debug as debug_draw
from .vis.visuals import SceneVisuals
from .vis.visualizer import Visualizer


class SimState:
    """A snapshot of every solver's state (torch tensors, kept in the graph when differentiable),
    and of the control Genesis keeps in its state: ``groups``, each muscle entity's actuation per
    group, from which reset(state) writes its particles' again."""

    def __init__(self, scene, states, groups):
        self.scene, self.states, self.groups = scene, states, groups

    @property
    def rigid(self):
        """The rigid solver's state (B, n_qs + n_dofs), or None without rigid entities."""
        return self._of(self.scene._rigid_solver)

    @property
    def mpm(self):
        """The MPM solver's state (B, n_particles · 25) (solvers/mpm/layout.py), or None."""
        return self._of(self.scene.mpm_solver)

    def _of(self, solver):
        slots = self.scene._require_built("SimState").slots
        return next((state for slot, state in zip(slots, self.states) if slot.solver is solver), None)


def _kind(value):
    """What ``value`` is, for an error message: a tensor's dtype, device and shape, a sequence's
    length, else its type."""
    if isinstance(value, torch.Tensor):
        layout = "" if value.layout == torch.strided else f"{value.layout} "
        return f"a {layout}{value.dtype} tensor on {value.device} of shape {tuple(value.shape)}"
    if isinstance(value, (list, tuple)):
        return f"a {type(value).__name__} of {len(value)}"
    return type(value).__name__


class _NoRigidSolver(SceneStateError, AttributeError):
    """scene.rigid_solver where there is none yet: a SceneStateError that hasattr() and
    getattr(scene, "rigid_solver", default) read as an absent attribute."""


@named_argument_errors
class Scene:
    """Entities, options and, once built, the simulator.

    sim_options, rigid_options, mpm_options: gs.options.SimOptions / RigidOptions / MPMOptions
    (None: defaults).
    viewer_options, vis_options: gs.options.ViewerOptions / VisOptions (None: defaults); the
    cameras read vis_options, viewer_options are kept for an interactive viewer of a later release.
    show_viewer: False or None (Genesis's default); True raises, as there is no interactive viewer.
    show_FPS: Genesis's (deprecated there): no FPS line is printed here, so True warns once.
    coupler_options: gs.options.LegacyCouplerOptions (None: defaults): whether the MPM particles
    meet the rigid shapes (rigid_mpm).
    """

    def __init__(self, sim_options=None, rigid_options=None, viewer_options=None, vis_options=None,
                 show_viewer=False, mpm_options=None, show_FPS=None, coupler_options=None):
        require_init("gs.Scene")
        if show_FPS is not None and check_bool("gs.Scene", "show_FPS", show_FPS):
            warn_user("gs.Scene: show_FPS=True prints nothing here (genesis_lite logs no FPS line; Genesis 1.4.5 "
                      "deprecates the argument too)")
        self.sim_options = sim_options or SimOptions()
        self.rigid_options = rigid_options or RigidOptions()
        self.viewer_options = viewer_options or ViewerOptions()
        self.vis_options = vis_options or VisOptions()
        self.mpm_options = mpm_options or MPMOptions()
        self.coupler_options = coupler_options or LegacyCouplerOptions()
        for arg, value, kind in (("sim_options", self.sim_options, SimOptions),
                                 ("rigid_options", self.rigid_options, RigidOptions),
                                 ("mpm_options", self.mpm_options, MPMOptions),
                                 ("coupler_options", self.coupler_options, LegacyCouplerOptions),
                                 ("viewer_options", self.viewer_options, ViewerOptions),
                                 ("vis_options", self.vis_options, VisOptions)):
            if not isinstance(value, kind):
                raise InvalidInputError(f"gs.Scene: argument '{arg}' must be gs.options.{kind.__name__}, "
                                        f"got {type(value).__name__}")
        no_viewer = show_viewer is None or (isinstance(show_viewer, (bool, np.bool_)) and not show_viewer)
        if not no_viewer:
            raise InvalidInputError(f"gs.Scene: argument 'show_viewer' must be False or None: genesis_lite has no "
                                    f"interactive viewer yet — use headless cameras for images and videos "
                                    f"(scene.add_camera(...), camera.render(), camera.start_recording()); a viewer "
                                    f"may come in a later release, got {show_viewer!r}")
        self.show_viewer = False
        self._initial_groups = {}  # the muscles' group actuation of the registered initial state (else zeros)
        self.entities = []
        self.sim_options = dataclasses.replace(self.sim_options, substeps=self._substeps())
        self._rigid_solver = RigidSolver(self.sim_options, self.rigid_options)
        self.mpm_solver = None  # made with the first MPM entity
        self.coupled_entities = set()  # the rigid entities whose shapes the MPM particles meet (set at build)
        self.sim = None
        self.n_envs = 0
        self._epoch = runtime.epoch
        self._destroyed = False
        self._cameras = []
        self.visualizer = Visualizer(self)  # (Genesis's scene.visualizer: its headless calls)
        self._drawing = None  # SceneVisuals of the cameras, made at the first render
        self._debug_objects, self._debug_gathered = [], None  # vis/debug.py's; gathered for drawing when drawn
        self._contact_drawing = None  # (starts, vectors, arrows) of visualize_contact's last drawn contacts
        track(self)  # last: a scene whose options raised is no scene to end

    def _substeps(self):
        """The substeps of every solver: those a solver's dt asks for (they must agree), else
        SimOptions.substeps. (Genesis checks only the solvers that have entities.)"""
        asked = {type(o).__name__: o for o in (self.rigid_options, self.mpm_options) if o.dt is not None}
        counts = {name: o.substeps(self.sim_options) for name, o in asked.items()}
        if len(set(counts.values())) > 1:
            said = ", ".join(f"{name} dt = {asked[name].dt:g} s ({count} substeps)" for name, count in counts.items())
            raise InvalidInputError(f"gs.Scene: the solvers must integrate at one rate (one substep count per step), "
                                    f"got {said}")
        return next(iter(counts.values()), self.sim_options.substeps)

    # -- building ---------------------------------------------------------------------------
    @property
    def is_built(self):
        return self.sim is not None

    @property
    def rigid_solver(self):
        """Genesis's ``scene.rigid_solver``: the same object as ``scene.sim.rigid_solver``
        (genesis_lite/rigid_solver.py: its scene-wide readouts, ``get_error_envs_mask``, run-time
        welds), once the scene is built with rigid entities."""
        if self.sim is None or self.sim.rigid_solver is None:
            why = "has no rigid entity" if self.sim is not None else "is not built yet (scene.build())"
            raise _NoRigidSolver(f"scene.rigid_solver: the scene {why}; the rigid solver's calls need a built "
                                 f"scene with rigid entities")
        return self.sim.rigid_solver

    def add_entity(self, morph, material=None, surface=None, visualize_contact=False, vis_mode=None, name=None):
        """Add an entity from a morph: rigid (material gs.materials.Rigid, the default) or MPM
        particles (a gs.materials.MPM material); returns the entity. Genesis's arguments in
        Genesis's order; visualize_contact (a rigid entity): debug cameras draw an arrow of each
        contact force on it (vis/debug.py); vis_mode is what the cameras draw (None: "visual" for a
        rigid entity, its visual shapes, or "collision", its collision shapes, as Genesis's;
        "particle" for particles)."""
        self._require_alive("scene.add_entity")
        if self.is_built:
            raise SceneStateError("scene.add_entity: the scene is already built; add every entity before build()")
        if not isinstance(morph, gm.Morph):
            raise InvalidInputError(f"scene.add_entity: argument 'morph' must be a gs.morphs object, "
                                    f"got {type(morph).__name__}")
        material = material or Rigid()
        if not isinstance(material, (Rigid, MPM.Base)):
            raise InvalidInputError(f"scene.add_entity: argument 'material' must be gs.materials.Rigid or a "
                                    f"gs.materials.MPM material, got {type(material).__name__}")
        if surface is not None and not isinstance(surface, Default):
            raise InvalidInputError(f"scene.add_entity: argument 'surface' must be gs.surfaces.Default or None, "
                                    f"got {type(surface).__name__}")
        particles = isinstance(material, MPM.Base)
        if not isinstance(visualize_contact, (bool, np.bool_)) or (visualize_contact and particles):
            raise InvalidInputError(f"scene.add_entity: argument 'visualize_contact' must be a bool (True: debug "
                                    f"cameras draw the contact forces on a rigid entity), got {visualize_contact!r} "
                                    f"for a {type(material).__name__} entity")
        drawn = ("particle",) if isinstance(material, MPM.Base) else ("visual", "collision")
        given, arg = (vis_mode, "argument 'vis_mode'") if vis_mode is not None or surface is None else \
            (surface.vis_mode, "the surface's vis_mode")  # (add_entity's, when given, is taken: Genesis's rule)
        if given not in (None, *drawn):
            raise InvalidInputError(f"scene.add_entity: {arg} must be None or {' or '.join(map(repr, drawn))} (what "
                                    f"the cameras draw of a {type(material).__name__} entity), got {given!r}")
        if name is not None and not isinstance(name, str):
            raise InvalidInputError(f"scene.add_entity: argument 'name' must be a str or None, got "
                                    f"{type(name).__name__} {name!r}")
        taken = [entity.name for entity in self.entities]  # errors and readouts name entities: one each
        if name is None:
            name = next(f"{type(morph).__name__.lower()}_{k}" for k in range(len(taken), 2 * len(taken) + 1)
                        if f"{type(morph).__name__.lower()}_{k}" not in taken)
        elif name in taken:
            raise InvalidInputError(f"scene.add_entity: argument 'name' must differ from the names of the scene's "
                                    f"entities, got {name!r}, which entity {taken.index(name)} has")
        if isinstance(material, MPM.Base):
            return self._add_mpm_entity(morph, material, surface, name)
        links = _links_of(morph, material, name, self.rigid_options.enable_mujoco_compatibility)
        if not morph.collision:  # (Genesis's morph option: its shapes in no contact pair; a URDF's are left out)
            for geom in (geom for link in links for geom in link.geoms):
                geom.contype = geom.conaffinity = 0
        kind = DroneEntity if isinstance(morph, gm.Drone) else RigidEntity
        entity = kind(self, len(self.entities), name, morph, material, surface or Default(), links, self._rigid_solver)
        entity.vis_mode = given or "visual"  # (what the cameras draw of it: vis/visuals.py)
        entity.visualize_contact = bool(visualize_contact)  # (arrows of its contact forces: vis/debug.py)
        self.entities.append(entity)
        return entity

    def _add_mpm_entity(self, morph, material, surface, name):
        """Particles sampled from the morph's volume at MPMOptions.particle_size."""
        if self.mpm_solver is None:
            o, sim = self.mpm_options, self.sim_options
            self.mpm_solver = MPMSolver(sim.dt, sim.substeps, o.gravity or sim.gravity, o.grid_density, o.particle_size,
                                        o.lower_bound, o.upper_bound, o.boundary_condition == "sticky",
                                        sim.requires_grad)
        solver = self.mpm_solver
        # (a spawn key: SeedSequence((s, k)) would equal SeedSequence(s) at k = 0, numpy padding with zeros)
        seed = len(self.entities) if runtime.seed is None else np.random.SeedSequence(runtime.seed,
                                                                                        spawn_key=(len(self.entities),))
        positions = sample_particles(morph, material, self.mpm_options.particle_size, solver.wall_lower,
                                     solver.wall_upper, seed=seed, name=name)
        start = solver.add_entity(name, material.solver_kind, material.solver_params(), material.E, material.nu,
                                  material.rho, material.default_Jp, positions)
        entity = MPMEntity(self, len(self.entities), name, morph, material, surface or Default(), solver, start,
                           len(positions), particles=positions)
        self.entities.append(entity)
        return entity

    def _rigid_entities(self):
        """The rigid entities, in their solver's order (the rigid model's link_entity numbers)."""
        return [e for e in self.entities if isinstance(e, RigidEntity)]

    def _solvers(self):
        """The solvers that have entities, rigid first."""
        rigid = any(isinstance(e, RigidEntity) for e in self.entities)
        return [s for s in (self._rigid_solver if rigid else None, self.mpm_solver) if s is not None]

    def build(self, n_envs=0, env_spacing=(0.0, 0.0), n_envs_per_row=None, center_envs_at_origin=True):
        """Allocate and compile for ``n_envs`` environments (0: no batch dimension).

        env_spacing (2,) m, n_envs_per_row (None: ceil(sqrt(n_envs))), center_envs_at_origin:
        where each env is drawn, as Genesis: ``envs_offset`` (max(1, n_envs), 3) m, env k in
        row k // n_envs_per_row (x) and column k % n_envs_per_row (y). For rendering only: every
        env is simulated at the origin and positions never include the offset.
        """
        require_init("scene.build")
        self._require_alive("scene.build")  # (a destroyed scene is not built again: nothing could step it)
        if self.is_built:
            raise SceneStateError("scene.build: the scene is already built; build() may be called once")
        refuse_inference_mode("scene.build")
        if not is_int(n_envs) or n_envs < 0:
            raise InvalidInputError(f"scene.build: argument 'n_envs' must be an integer ≥ 0, got {n_envs!r}")
        if not self.entities:
            raise SceneStateError("scene.build: the scene has no entity; add one with scene.add_entity()")
        spacing = _checked_spacing(env_spacing, n_envs_per_row, center_envs_at_origin)
        rendered = self.vis_options.rendered_envs_idx
        if rendered is not None and any(k >= max(1, n_envs) for k in rendered):
            raise InvalidInputError(f"scene.build: VisOptions argument 'rendered_envs_idx' must be env indices "
                                    f"below {max(1, n_envs)} (n_envs={n_envs}), got {rendered}")
        self.n_envs = int(n_envs)
        self.env_spacing = tuple(float(v) for v in env_spacing)
        for camera in self._cameras:  # their env_idx checked before anything is allocated
            camera._bind_env()
        solvers = self._solvers()
        if self.mpm_solver in solvers:  # (the default of the MPM solver's input "coupling")
            self.mpm_solver.set_couplings([(e.material.coup_friction, e.material.coup_softness,
                                            e.material.coup_restitution) for e in self._rigid_entities()])
        free_dropped_scenes()  # (before this scene allocates)
        sim = Simulator(self.sim_options, solvers)
        try:
            sim.build(self.n_envs)
            if len(solvers) > 1 and self.coupler_options.rigid_mpm:
                self._couple(sim)
        except Exception:  # e.g. a massless moving link: free the arrays allocated so far
            for solver in solvers:
                solver.destroy()
            raise
        self._footprint = sum(solver.memory_bytes() for solver in solvers)
        self.sim = sim
        self.n_envs_per_row, self.envs_offset = _envs_layout(max(1, self.n_envs), spacing, n_envs_per_row,
                                                             center_envs_at_origin)
        if self._rigid_solver in solvers:
            sim.rigid_solver = RigidSolverView(self)
        for entity in self.entities:
            entity._on_build()
        for camera in self._cameras:
            camera._on_build()

    def _couple(self, sim):
        """Rigid–MPM coupling (solvers/coupling.py): the coupled rigid shapes fixed to the world become
        the MPM grid's colliders, those of moving links meet it in the coupling stage (solvers/coupler.py)."""
        rigid, entities = self._rigid_solver, self._rigid_entities()
        (rows, data), (moving_rows, moving_data, geoms) = rigid_colliders(rigid.model,
                                                                          [e.material.needs_coup for e in entities])
        self.mpm_solver.set_colliders(rows, data, moving=len(geoms) > 0)
        if len(geoms):
            sim.coupler = Coupler(rigid, self.mpm_solver, moving_rows, moving_data, geoms)
        model = rigid.model
        colliding = np.unique(model.link_entity[model.geom_link[model.geom_collides]])
        self.coupled_entities = {entities[k] for k in colliding if entities[k].material.needs_coup}

    def _held_bytes(self):
        """Bytes of the solvers' arrays the scene holds (0 before build and once destroyed)."""
        return 0 if self.sim is None else self._footprint

    def _require_alive(self, what):
        if self._destroyed:
            raise SceneStateError(f"{what}: the scene was destroyed (scene.destroy(), gs.destroy(), or gs.init() "
                                  f"restarting the runtime); build a new scene")
        if self._epoch != runtime.epoch:
            raise SceneStateError(f"{what}: gs.init() was called again after this scene was made; build a new scene")

    def _require_built(self, what):
        self._require_alive(what)
        if not self.is_built:
            raise SceneStateError(f"{what}: call scene.build() first")
        return self.sim

    # -- cameras and debug drawing ----------------------------------------------------------
    def add_camera(self, model="pinhole", res=(320, 320), pos=(0.5, 2.5, 3.5), lookat=(0.5, 0.5, 0.5),
                   up=(0.0, 0.0, 1.0), fov=30, aperture=2.0, focus_dist=None, GUI=False, spp=256, denoise=None,
                   near=0.1, far=20.0, env_idx=None, debug=False):
        """A headless pinhole camera (Genesis's arguments and defaults; vis/camera.py says what each
        does and which are refused): res (width, height) pixels, pos / lookat (3,) m, up (3,), fov
        vertical degrees, near / far m, env_idx (batched scenes), debug (draws debug spheres too).
        Before or after build (Genesis: before only). Returns the Camera."""
        self._require_alive("scene.add_camera")
        camera = Camera(self, len(self._cameras), model, res, pos, lookat, up, fov, aperture, focus_dist, GUI, spp,
                        denoise, near, far, env_idx, debug)
        if self.is_built:
            camera._bind_env()
            camera._on_build()
        self._cameras.append(camera)
        return camera

    def draw_debug_sphere(self, pos, radius=0.01, color=(1.0, 0.0, 0.0, 0.5)):
        """One debug sphere at ``pos`` (3,) m world; see draw_debug_spheres."""
        return self._add_debug("scene.draw_debug_sphere",
                               lambda owner: debug_draw.DebugSpheres(owner, pos, radius, color))

    def draw_debug_spheres(self, poss, radius=0.01, color=(1.0, 0.0, 0.0, 0.5)):
        """Spheres of ``radius`` m at ``poss`` (N, 3) m world (numpy or torch; copied now), drawn by
        debug cameras (``add_camera(debug=True)``) until cleared; color (r, g, b[, a]) in [0, 1],
        alpha not drawn (vis/debug.py). Returns the object to pass to clear_debug_object."""
        return self._add_debug("scene.draw_debug_spheres",
                               lambda owner: debug_draw.DebugSpheres(owner, poss, radius, color))

    def draw_debug_line(self, start, end, radius=0.002, color=(1.0, 0.0, 0.0, 0.5)):
        """A cylinder of ``radius`` m from ``start`` to ``end`` (3,) m world, as draw_debug_spheres
        (equal ends: nothing drawn, None)."""
        return self._add_debug("scene.draw_debug_line",
                               lambda owner: debug_draw.line(owner, start, end, radius, color))

    def draw_debug_arrow(self, pos, vec=(0, 0, 1), radius=0.01, color=(1.0, 0.0, 0.0, 0.5)):
        """An arrow from ``pos`` along ``vec`` (3,) m world (body radius m), as draw_debug_spheres;
        a zero ``vec`` draws nothing and returns None, as Genesis's."""
        return self._add_debug("scene.draw_debug_arrow",
                               lambda owner: debug_draw.arrow(owner, pos, vec, radius, color))

    def draw_debug_frame(self, T, axis_length=1.0, origin_size=0.015, axis_radius=0.01, color=None):
        """A coordinate frame at the pose ``T`` (4, 4): its x, y, z axes as cylinders of
        ``axis_length`` m and radius ``axis_radius``, red, green and blue (or all ``color``), and a
        sphere of ``origin_size`` m at its origin."""
        return self._add_debug("scene.draw_debug_frame", lambda owner: debug_draw.frames(
            owner, T, axis_length, origin_size, axis_radius, color))

    def draw_debug_frames(self, Ts, axis_length=1.0, origin_size=0.015, axis_radius=0.01, color=None):
        """Frames at the poses ``Ts`` (N, 4, 4), as draw_debug_frame, as one object."""
        return self._add_debug("scene.draw_debug_frames", lambda owner: debug_draw.frames(
            owner, Ts, axis_length, origin_size, axis_radius, color))

    def draw_debug_box(self, bounds, color=(1.0, 0.0, 0.0, 1.0), wireframe=True, wireframe_radius=0.0015):
        """The world-axes box ``bounds`` (2, 3) m [lower, upper] (get_AABB's form): its edges as
        cylinders of ``wireframe_radius`` m, or solid (wireframe False)."""
        return self._add_debug("scene.draw_debug_box",
                               lambda owner: debug_draw.box(owner, bounds, color, wireframe, wireframe_radius))

    def draw_debug_trajectory(self, poss, radius=0.002, color=(1.0, 0.5, 0.0, 0.8)):
        """Cylinders of ``radius`` m joining the consecutive points ``poss`` (N, 3) m world (none
        distinct: nothing drawn, None)."""
        return self._add_debug("scene.draw_debug_trajectory",
                               lambda owner: debug_draw.trajectory(owner, poss, radius, color))

    def _add_debug(self, owner, make):
        """Keep the debug object ``make(owner)`` (checked there; None: nothing to draw) for debug cameras."""
        self._require_built(owner)
        obj = make(owner)
        if obj is not None:
            self._debug_objects.append(obj)
            self._debug_gathered = None
        return obj

    def clear_debug_object(self, obj):
        """Stop drawing one object returned by a draw_debug_* call."""
        if not any(obj is mine for mine in self._debug_objects):
            raise InvalidInputError(f"scene.clear_debug_object: argument 'obj' must be a debug object of this scene "
                                    f"(returned by a draw_debug_* call and not cleared yet), got {obj!r}")
        self._debug_objects = [mine for mine in self._debug_objects if mine is not obj]
        self._debug_gathered = None

    def clear_debug_objects(self):
        """Stop drawing every debug object."""
        self._debug_objects, self._debug_gathered = [], None

    def _debug_drawing(self):
        """(the Spheres of the debug spheres or None, the list of DebugMesh), gathered once per change."""
        if self._debug_gathered is None:
            objects = self._debug_objects
            spheres = [o for o in objects if isinstance(o, debug_draw.DebugSpheres)]
            meshes = [o for o in objects if isinstance(o, debug_draw.DebugMesh)]
            self._debug_gathered = (debug_draw.DebugSpheres.gather(spheres), meshes)
        return self._debug_gathered

    def _contact_arrows(self):
        """The DebugMesh arrows of the contact forces on the entities added with
        visualize_contact, in the drawn envs (each at its env's drawing offset); the same objects
        while the contacts stay the same (the debug cameras' MeshSet is then kept)."""
        flagged = [entity for entity in self.entities if getattr(entity, "visualize_contact", False)]
        if not flagged:
            return []
        envs = self._rendered_envs()
        segments = [debug_draw.contact_segments(entity, envs, self.envs_offset[envs],
                                                self.vis_options.contact_force_scale) for entity in flagged]
        starts, vectors = (np.concatenate(part) for part in zip(*segments))
        kept = self._contact_drawing
        if kept is None or not (np.array_equal(kept[0], starts) and np.array_equal(kept[1], vectors)):
            self._contact_drawing = kept = (starts, vectors, debug_draw.contact_arrows(starts, vectors))
        return kept[2]

    def _rendered_envs(self):
        """The envs cameras draw (batch rows): VisOptions.rendered_envs_idx, else all."""
        rendered = self.vis_options.rendered_envs_idx
        return np.arange(max(1, self.n_envs)) if rendered is None else np.asarray(rendered, dtype=np.int64)

    def _camera_visuals(self):
        """The cameras' SceneVisuals, made at the first render (the scene is built)."""
        if self._drawing is None:
            self._drawing = SceneVisuals(self, self._rendered_envs(), self.vis_options.segmentation_level)
        return self._drawing

    def _link_kinematics(self):
        """(B, L, 13) link kinematics of the current state, read where the state lives: from the
        solver when it holds the state (after an ordinary step; nothing is downloaded), else from
        the state tensor (detached); None without rigid entities."""
        if self._rigid_solver not in self._solvers():
            return None
        if self.sim.slot(self._rigid_solver).state is None:
            return self._rigid_solver.links_kinematics()
        return self.sim.derived(self._rigid_solver).detach()

    # -- running ----------------------------------------------------------------------------
    def step(self, update_visualizer=True, refresh_visualizer=True):
        """Advance by ``dt`` (``substeps`` integration substeps).

        update_visualizer, refresh_visualizer: Genesis's switches for the viewer and cameras,
        accepted (True or False) and without effect: cameras draw when render() is called, and
        when a recording started with a file takes its frame (Genesis's too)."""
        if update_visualizer is not True or refresh_visualizer is not True:  # the common case costs two tests
            check_bool("scene.step", "update_visualizer", update_visualizer)
            check_bool("scene.step", "refresh_visualizer", refresh_visualizer)
        refuse_inference_mode("scene.step")
        self._require_built("scene.step").step()
        for camera in self._cameras:  # a recording started with a file takes its frames as the scene steps
            camera._after_step()

    def reset(self, state=None, envs_idx=None):
        """Return to the registered initial state (the state at build), or to ``state`` from
        get_state(), which then becomes the registered initial state (as Genesis).

        envs_idx: reset only these envs of a batched scene; the others keep their state and
        controls. Controls are cleared, parameters kept. A new autograd graph starts: every
        state and parameter is detached (``state`` too, even one taken mid-rollout from a graph),
        and a backward through the previous graph raises GradientError.
        """
        sim = self._require_built("scene.reset")
        refuse_inference_mode("scene.reset")
        if state is not None and not (isinstance(state, SimState) and state.scene is self):
            given = "a SimState of another scene" if isinstance(state, SimState) else type(state).__name__
            raise InvalidInputError(f"scene.reset: argument 'state' must come from this scene's get_state(), "
                                    f"got {given}")
        envs = None if envs_idx is None else _SceneArguments(self, "reset")._envs(envs_idx)
        sim.reset(None if state is None else self._checked_states(state), envs)
        if state is not None:
            self._initial_groups = state.groups
        for muscle in self._muscles():
            muscle.restore_groups(self._initial_groups.get(muscle), envs)

    def _checked_states(self, state):
        """``state``'s tensors, checked as the setters check values (a SimState can be made by hand,
        or from a saved one): one per solver, each real numbers with data, of its solver's state
        shape, finite, with non-zero quaternions in each rigid entity's free and ball joints and
        every MPM particle inside the walls. Returned on gs.device in gs.tc_float."""
        slots = self.sim.slots
        if not isinstance(state.states, (list, tuple)) or len(state.states) != len(slots):
            raise InvalidInputError(f"scene.reset: argument 'state' must hold one state tensor per solver "
                                    f"({', '.join(type(slot.solver).__name__ for slot in slots)}), got "
                                    f"{_kind(state.states)}")
        checked = []
        for slot, tensor in zip(slots, state.states):
            who = f"scene.reset: argument 'state' ({type(slot.solver).__name__}'s)"
            expected = tuple(self.sim.state(slot.solver).shape)
            if not isinstance(tensor, torch.Tensor) or tensor.is_meta or tensor.layout != torch.strided \
                    or not tensor.is_floating_point():
                raise InvalidInputError(f"{who} must be a real tensor with values of shape {expected}, got "
                                        f"{_kind(tensor)}")
            if tuple(tensor.shape) != expected:
                raise InvalidInputError(f"{who} must have shape {expected}, got {tuple(tensor.shape)}")
            tensor = tensor.detach().to(device=runtime.device, dtype=runtime.tc_float)
            if not bool(torch.isfinite(tensor).all()):
                raise InvalidInputError(f"{who} must be finite, got NaN or inf at (env, column) "
                                        f"{torch.nonzero(~torch.isfinite(tensor))[0].tolist()}")
            checked.append(tensor)
        solvers = [slot.solver for slot in slots]
        for entity in self.entities:
            if isinstance(entity, MPMEntity):
                entity._check_state(checked[solvers.index(entity._solver)], "scene.reset")
            if isinstance(entity, RigidEntity):
                rigid = checked[solvers.index(entity._solver)]
                for joint in entity.joints:
                    for q in {q for _, q in entity._turns} & set(joint.qs_idx_local):  # its quaternion's first
                        zero = torch.nonzero(rigid[:, entity._solver_q(np.arange(q, q + 4))].norm(dim=-1) == 0)
                        if len(zero):
                            raise InvalidInputError(f"scene.reset: argument 'state' must hold non-zero quaternions "
                                                    f"(w, x, y, z), got a zero one for joint '{joint.name}' of "
                                                    f"entity '{entity.name}' in env {int(zero[0])}")
        return checked

    def get_state(self):
        """A snapshot of every solver's state: copies (in the graph when differentiable), never the
        simulator's own tensors, so that changing it in place changes neither the scene nor the
        state a plain reset() returns to (the state at build is that tensor until a step)."""
        sim = self._require_built("scene.get_state")
        muscles = {entity: entity.held_groups() for entity in self._muscles()}
        return SimState(self, [sim.state(slot.solver).clone() for slot in sim.slots], muscles)

    def _muscles(self):
        return [entity for entity in self.entities if isinstance(entity, MPMEntity) and entity.is_muscle]

    def set_gravity(self, gravity, envs_idx=None):
        """Gravity of every solver, m/s²: (3,) or (n_envs, 3); differentiable."""
        sim = self._require_built("scene.set_gravity")
        probe = _SceneArguments(self, "set_gravity")
        envs = probe._envs(envs_idx, distinct=True)
        values = probe._values(gravity, 3, envs, "gravity")
        for slot in sim.slots:
            sim.set_input(slot.solver, "gravity", replace_columns(slot.inputs["gravity"], envs, np.arange(3), values))

    def get_gravity(self, envs_idx=None):
        """Gravity, m/s²: (3,) or (n_envs, 3): the first solver's (the rigid solver's when there is
        one; an MPMOptions(gravity=...) of its own shows in the MPM solver only, until set_gravity
        sets every solver's)."""
        sim = self._require_built("scene.get_gravity")
        probe = _SceneArguments(self, "get_gravity")
        envs = torch.as_tensor(probe._envs(envs_idx), device=runtime.device)
        return probe._out(sim.inputs(sim.slots[0].solver)["gravity"][envs])

    @property
    def t(self):
        """Steps taken since the last reset."""
        return self.sim.step_index if self.sim else 0

    @property
    def dt(self):
        return self.sim_options.dt

    @property
    def substeps(self):
        return self.sim_options.substeps

    @property
    def requires_grad(self):
        return self.sim_options.requires_grad

    @property
    def entity_names(self):
        return tuple(entity.name for entity in self.entities)

    def get_entity(self, name=None, *, uid=None):
        """The entity named ``name``, or whose uid's short form (``entity.uid.short()``, seven hex
        digits) is ``uid``: one of the two, as Genesis's lookup."""
        if name is None and uid is None:
            raise InvalidInputError("scene.get_entity: missing a required argument: 'name' or 'uid'")
        if name is not None and uid is not None:
            raise InvalidInputError(f"scene.get_entity: expected one of the arguments 'name' and 'uid', got both "
                                    f"(name={name!r}, uid={uid!r})")
        if name is not None:
            match = [entity for entity in self.entities if entity.name == name]
            known = f"the name of an entity of the scene {list(self.entity_names)}"
        else:
            match = [entity for entity in self.entities if entity.uid.match(uid, short_only=True)]
            known = f"the short uid of an entity of the scene {[e.uid.short() for e in self.entities]}"
        if not match:
            raise InvalidInputError(f"scene.get_entity: argument '{'name' if name is not None else 'uid'}' must be "
                                    f"{known}, got {name if name is not None else uid!r}")
        return match[0]

    def destroy(self):
        """Free the scene's arrays (its solvers' data) and finish the cameras' streamed recordings;
        the scene cannot step afterwards."""
        for solver in self._solvers():
            solver.destroy()
        self.sim = None
        self._destroyed = True
        self._finish_recordings()  # last: a failing video file leaves the scene destroyed all the same

    def _finish_recordings(self):
        """Each camera's streamed recording finished (its file written), a buffered one dropped."""
        for camera in self._cameras:
            camera._close()


def _checked_spacing(env_spacing, n_envs_per_row, center):
    """build's layout arguments checked (before anything is allocated); returns env_spacing (2,) m."""
    try:
        spacing = np.asarray(env_spacing, dtype=np.float64)
    except (TypeError, ValueError):
        spacing = np.full(0, np.nan)
    if spacing.shape != (2,) or not np.all(np.isfinite(spacing)):
        raise InvalidInputError(f"scene.build: argument 'env_spacing' must be 2 finite numbers (m), "
                                f"got {env_spacing!r}")
    if n_envs_per_row is not None and (not is_int(n_envs_per_row) or n_envs_per_row <= 0):
        raise InvalidInputError(f"scene.build: argument 'n_envs_per_row' must be a positive integer or None, "
                                f"got {n_envs_per_row!r}")
    check_bool("scene.build", "center_envs_at_origin", center)
    return spacing


def _envs_layout(n_batch, spacing, n_envs_per_row, center):
    """(envs per row, offsets (n_batch, 3) m): where each env is drawn (Genesis's layout; see
    Scene.build), once the solvers took n_batch (their size checks come first)."""
    per_row = n_envs_per_row or int(np.ceil(np.sqrt(n_batch)))
    k = np.arange(n_batch)
    offset = np.stack([k // per_row * spacing[0], k % per_row * spacing[1], np.zeros(n_batch)], axis=-1)
    if center:
        offset -= (offset.max(axis=0) + offset.min(axis=0)) / 2.0
    return per_row, offset


def _add_rotor_armature(links, morph, mujoco_compatible):
    """A motor's rotor on each joint one could drive, as Genesis's loader adds it: the morph's
    default_armature on the revolute or prismatic dof of every body moving by that one dof (not a
    free base's, nor those of an MJCF body of several joints, whose links here share its body:
    LinkSpec.same_body), where the file leaves its armature at 0; its default
    (morphs.GENESIS_ARMATURE) 0.1, none under MuJoCo compatibility."""
    armature = morph.default_armature
    if armature is gm.GENESIS_ARMATURE:
        armature = 0.0 if mujoco_compatible else 0.1
    body = list(range(len(links)))
    for k, link in enumerate(links):  # (parents first)
        body[k] = body[link.parent] if link.same_body else k
    joints_of = collections.Counter(body[k] for k, link in enumerate(links) if link.joint_type != "fixed")
    for k, link in enumerate(links):
        if link.joint_type in ("revolute", "prismatic") and joints_of[body[k]] == 1 and not link.armature:
            link.armature = armature


_XML_DECLARATION = re.compile(r"^<\?xml[^>]*\?>")


def _xml_error(text):
    """Why ``text`` does not parse as XML (ElementTree's message: what and where)."""
    try:
        ET.fromstring(text)
    except ET.ParseError as err:
        return str(err)
    return "it parses"


def _not_found():
    """Where a file morph's relative path was looked for (gm._file_path), for its error."""
    assets = gm.genesis_assets()
    return (f"not found; relative paths start at {os.getcwd()}, then genesis_lite's assets, {gm.BUNDLED_ASSETS}, "
            + (f"then genesis-world's bundled assets, {assets}" if assets else
               "then genesis-world's bundled assets where that package is installed (it is not)"))


def _links_of(morph, material, name, mujoco_compatible):
    """The morph's LinkSpec list (fixed links merged when the morph asks, friction and gravity
    compensation from the material when it states them), its root joint set from the morph's placement. Where a mass
    comes from the shapes and the material states no density, Genesis's default density:
    shapes.MUJOCO_DENSITY under enable_mujoco_compatibility, else a URDF's by articulation
    (urdf.load_urdf) and shapes.OBJECT_DENSITY for a primitive or a mesh."""
    rho = material.rho if material.rho is not None else shapes.MUJOCO_DENSITY if mujoco_compatible else None
    object_rho = rho or shapes.OBJECT_DENSITY  # (a primitive or a mesh is an object)
    inline = isinstance(morph, (gm.URDF, gm.MJCF)) and gm.inline_xml(morph.file)
    # (a str is decoded already: its declaration's encoding would mislead the loaders' byte parsers)
    text = _XML_DECLARATION.sub("", morph.file.strip(), count=1) if inline else None
    path = f"<inline {type(morph).__name__}>" if inline else getattr(morph, "file", None)
    if not inline and isinstance(morph, (gm.URDF, gm.MJCF, gm.Mesh)) and not os.path.isfile(path):
        # name the argument and what was expected, as every error message does
        kind = type(morph).__name__
        expected = f"an existing {'mesh' if kind == 'Mesh' else kind} file"
        if kind != "Mesh" and morph.file.lstrip().startswith("<"):  # (an inline document that does not parse)
            raise AssetError(f"entity '{name}': argument 'file' of gs.morphs.{kind} expected {expected} or an XML "
                             f"document, got text that is not well-formed XML ({_xml_error(morph.file)})")
        raise AssetError(f"entity '{name}': argument 'file' of gs.morphs.{kind} expected {expected}, got "
                         f"'{morph.file}' ({_not_found()})")
    if isinstance(morph, gm.URDF):
        links = urdf.load_urdf(path, entity_name=name, rho=rho, y_up=not morph.file_meshes_are_zup,
                               collision=morph.collision, text=text)
        if isinstance(morph, gm.Drone):
            _check_rotors(links, morph, name)
        if morph.merge_fixed_links:
            links = merge.merge_fixed_links(links, morph.links_to_keep,
                                            owner=f"entity '{name}': gs.morphs.{type(morph).__name__}")
        if morph.scale != 1.0:
            links = scale.scaled_links(links, morph.scale)  # (a URDF's gains: the file's, as Genesis's)
        _add_rotor_armature(links, morph, mujoco_compatible)
    elif isinstance(morph, gm.MJCF):
        links = mjcf.load_mjcf(path, entity_name=name, exclude_ground_plane=morph.exclude_ground_plane, text=text)
        if morph.scale != 1.0:
            links = scale.scaled_links(links, morph.scale, gains=morph.scale ** 3)
        _add_rotor_armature(links, morph, mujoco_compatible)
        mjcf.place_world(links, morph.pos, morph.quat)
        if morph.fixed:
            links[0].joint_type = "fixed"
        return _with_material(links, material)
    elif isinstance(morph, gm.Box):
        links = shapes.box_link(morph.size, object_rho)
    elif isinstance(morph, gm.Sphere):
        links = shapes.sphere_link(morph.radius, object_rho)
    elif isinstance(morph, gm.Capsule):
        links = shapes.capsule_link(morph.radius, morph.height, object_rho)
    elif isinstance(morph, gm.Cylinder):
        links = shapes.cylinder_link(morph.radius, morph.height, object_rho)
    elif isinstance(morph, gm.Mesh):
        try:
            links = shapes.mesh_link(morph.file, morph.scale, object_rho, y_up=not morph.file_meshes_are_zup)
        except AssetError as exc:  # shapes does not know the entity: add it to the message
            raise AssetError(f"entity '{name}': argument 'file' of gs.morphs.Mesh: {exc}") from exc
    elif isinstance(morph, gm.Plane):
        links = shapes.plane_link(morph.normal)
    elif isinstance(morph, gm.Terrain):
        links = shapes.terrain_link(morph.height_field * morph.vertical_scale, morph.horizontal_scale, morph.BASE)
    else:
        raise InvalidInputError(f"scene.add_entity: morph type {type(morph).__name__} is not supported")
    if not isinstance(morph, gm.URDF):  # a primitive's or mesh's bit masks (both 0: in no pair, drawn still)
        for geom in links[0].geoms:
            geom.contype, geom.conaffinity = morph.contype, morph.conaffinity
    root = links[0]
    root.joint_type = "fixed" if morph.fixed else "free"
    pos, quat = np.asarray(morph.pos, dtype=float), np.asarray(morph.quat, dtype=float)
    if np.any(root.pos) or np.any(root.quat != (1.0, 0.0, 0.0, 0.0)):  # a URDF's floating root (urdf.py)
        pos, quat = shapes.compose(pos, quat, root.pos, root.quat)
    root.pos, root.quat = pos, quat  # (else the morph's quaternion as given: compose would renormalise and flip it)
    if isinstance(morph, gm.Drone) and morph.default_base_ang_damping_scale:  # (Genesis's, by the drone's mass)
        root.damping = (0.0,) * 3 + (morph.default_base_ang_damping_scale * sum(link.mass for link in links),) * 3
    return _with_material(links, material)


def _check_rotors(links, morph, name):
    """A drone's propellers_link_name names links of its file."""
    names = [link.name for link in links]
    missing = [n for n in morph.propellers_link_name if n not in names]
    if missing:
        raise InvalidInputError(f"entity '{name}': argument 'propellers_link_name' of gs.morphs.Drone expected links "
                                f"of the file, got {missing} (its links: {names})")


def _with_material(links, material):
    """``links`` with the material's frictions (sliding, torsional, rolling), where it states them,
    on every geom, and its gravity compensation, where it states one, on every link (each
    overrides the asset's, as Genesis)."""
    for name in ("friction", "friction_torsional", "friction_rolling"):
        if getattr(material, name) is not None:
            for geom in (geom for link in links for geom in link.geoms):
                setattr(geom, name, getattr(material, name))
    if material.gravity_compensation is not None:
        for link in links:
            link.gravcomp = material.gravity_compensation
    return links


class _SceneArguments(EntityIndexing):
    """Parses a scene method's arguments (gravity, envs_idx) as an entity's setters do; its errors
    name the method."""

    def __init__(self, scene, method):
        self.scene, self.name, self._method = scene, "scene", method

    @property
    def _who(self):
        return f"scene.{self._method}"


