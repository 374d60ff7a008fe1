"""The scene: entities are added, then ``build(n_envs)`` fixes everything and ``step()`` runs.

Lifecycle errors (step before build, build twice, add after build) raise SceneStateError.
Genesis's viewer and visualisation arguments are accepted and validated; there is no viewer or
camera yet, so they change nothing (``show_viewer=True`` raises rather than being ignored).
"""
import os

import numpy as np
import torch

from . import morphs as gm
from .entities import RigidEntity
from .solvers.core import AssetError, InvalidInputError, SceneStateError
from .materials import Rigid
from .options import RigidOptions, SimOptions, ViewerOptions, VisOptions, check_bool, is_int
from .runtime import require_init, runtime
from .simulator import Simulator
from .solvers.rigid import merge, shapes, urdf
from .solvers.rigid.solver import RigidSolver
from .surfaces import Default


class SimState:
    """A snapshot of every solver's state (torch tensors, kept in the graph when differentiable)."""

    def __init__(self, scene, states):
        self.scene, self.states = scene, states

    @property
    def rigid(self):
        return self.states[0]




class Scene:
    """Entities, options and, once built, the simulator.

    sim_options, rigid_options: gs.options.SimOptions / RigidOptions (None: defaults).
    viewer_options, vis_options: gs.options.ViewerOptions / VisOptions (None: defaults), kept
    for the viewer and cameras of a later release. show_viewer: False or None (Genesis's
    default); True raises, as there is no interactive viewer yet.
    """

    def __init__(self, sim_options=None, rigid_options=None, viewer_options=None, vis_options=None,
                 show_viewer=False):
        require_init("gs.Scene")
        self.sim_options = sim_options or SimOptions()
        self.rigid_options = rigid_options or RigidOptions()
        self.viewer_options = viewer_options or ViewerOptions()
        self.vis_options = vis_options or VisOptions()
        for arg, value, kind in (("sim_options", self.sim_options, SimOptions),
                                 ("rigid_options", self.rigid_options, RigidOptions),
                                 ("viewer_options", self.viewer_options, ViewerOptions),
                                 ("vis_options", self.vis_options, VisOptions)):
            if not isinstance(value, kind):
                raise InvalidInputError(f"gs.Scene: argument '{arg}' must be gs.options.{kind.__name__}, "
                                        f"got {type(value).__name__}")
        no_viewer = show_viewer is None or (isinstance(show_viewer, (bool, np.bool_)) and not show_viewer)
        if not no_viewer:
            raise InvalidInputError(f"gs.Scene: argument 'show_viewer' must be False or None: genesis_lite has no "
                                    f"interactive viewer yet (cameras and rendering come with a later release), "
                                    f"got {show_viewer!r}")
        self.show_viewer = False
        self.entities = []
        self.rigid_solver = RigidSolver(self.sim_options, self.rigid_options)
        self.sim = None
        self.n_envs = 0
        self._epoch = runtime.epoch
        self._destroyed = False

    # -- building ---------------------------------------------------------------------------
    @property
    def is_built(self):
        return self.sim is not None

    def add_entity(self, morph, material=None, surface=None, name=None):
        """Add a rigid entity from a morph; returns the entity."""
        if self.is_built:
            raise SceneStateError("scene.add_entity: the scene is already built; add every entity before build()")
        if not isinstance(morph, gm.Morph):
            raise InvalidInputError(f"scene.add_entity: argument 'morph' must be a gs.morphs object, "
                                    f"got {type(morph).__name__}")
        material = material or Rigid()
        if not isinstance(material, Rigid):
            raise InvalidInputError(f"scene.add_entity: argument 'material' must be gs.materials.Rigid (other "
                                    f"materials need solvers not built yet), got {type(material).__name__}")
        name = name or f"{type(morph).__name__.lower()}_{len(self.entities)}"
        links = _links_of(morph, material, name)
        entity = RigidEntity(self, len(self.entities), name, morph, material, surface or Default(), links,
                             self.rigid_solver)
        self.entities.append(entity)
        return entity

    def build(self, n_envs=0, env_spacing=(0.0, 0.0), n_envs_per_row=None, center_envs_at_origin=True):
        """Allocate and compile for ``n_envs`` environments (0: no batch dimension).

        env_spacing (2,) m, n_envs_per_row (None: ceil(sqrt(n_envs))), center_envs_at_origin:
        where each env is drawn, as Genesis: ``envs_offset`` (max(1, n_envs), 3) m, env k in
        row k // n_envs_per_row (x) and column k % n_envs_per_row (y). For rendering only: every
        env is simulated at the origin and positions never include the offset.
        """
        if self.is_built:
            raise SceneStateError("scene.build: the scene is already built; build() may be called once")
        if not is_int(n_envs) or n_envs < 0:
            raise InvalidInputError(f"scene.build: argument 'n_envs' must be an integer ≥ 0, got {n_envs!r}")
        if not self.entities:
            raise SceneStateError("scene.build: the scene has no entity; add one with scene.add_entity()")
        self.n_envs_per_row, self.envs_offset = _envs_layout(max(1, int(n_envs)), env_spacing, n_envs_per_row,
                                                             center_envs_at_origin)
        rendered = self.vis_options.rendered_envs_idx
        if rendered is not None and any(k >= max(1, n_envs) for k in rendered):
            raise InvalidInputError(f"scene.build: VisOptions argument 'rendered_envs_idx' must be env indices "
                                    f"below {max(1, n_envs)} (n_envs={n_envs}), got {rendered}")
        self.n_envs = int(n_envs)
        self.env_spacing = tuple(float(v) for v in env_spacing)
        sim = Simulator(self.sim_options, [self.rigid_solver])
        try:
            sim.build(self.n_envs)
        except Exception:  # e.g. a massless moving link: free the arrays allocated so far
            self.rigid_solver.destroy()
            raise
        self.sim = sim
        for entity in self.entities:
            entity._on_build()

    def _require_built(self, what):
        if self._epoch != runtime.epoch:
            raise SceneStateError(f"{what}: gs.init() was called again after this scene was made; build a new scene")
        if self._destroyed:
            raise SceneStateError(f"{what}: the scene was destroyed (scene.destroy()); build a new scene")
        if not self.is_built:
            raise SceneStateError(f"{what}: call scene.build() first")
        return self.sim

    # -- running ----------------------------------------------------------------------------
    def step(self, update_visualizer=True, refresh_visualizer=True):
        """Advance by ``dt`` (``substeps`` integration substeps).

        update_visualizer, refresh_visualizer: Genesis's switches for the viewer and cameras,
        accepted (True or False) and without effect until those exist."""
        if update_visualizer is not True or refresh_visualizer is not True:  # the common case costs two tests
            check_bool("scene.step", "update_visualizer", update_visualizer)
            check_bool("scene.step", "refresh_visualizer", refresh_visualizer)
        self._require_built("scene.step").step()

    def reset(self, state=None, envs_idx=None):
        """Return to the registered initial state (the state at build), or to ``state`` from
        get_state(), which then becomes the registered initial state (as Genesis).

        envs_idx: reset only these envs of a batched scene; the others keep their state and
        controls. Controls are cleared, parameters kept. A new autograd graph starts: every
        state and parameter is detached (``state`` too, even one taken mid-rollout from a graph),
        and a backward through the previous graph raises GradientError.
        """
        sim = self._require_built("scene.reset")
        if state is not None and not (isinstance(state, SimState) and state.scene is self):
            given = "a SimState of another scene" if isinstance(state, SimState) else type(state).__name__
            raise InvalidInputError(f"scene.reset: argument 'state' must come from this scene's get_state(), "
                                    f"got {given}")
        sim.reset(None if state is None else state.states, self._envs_idx("scene.reset", envs_idx))

    def _envs_idx(self, what, envs_idx):
        """``envs_idx`` (None, int, sequence, array or tensor) as an int64 array (None stays None)."""
        if envs_idx is None:
            return None
        if isinstance(envs_idx, torch.Tensor):
            envs_idx = envs_idx.detach().cpu().numpy()
        idx = np.atleast_1d(np.asarray(envs_idx))
        if self.n_envs == 0 or idx.ndim != 1 or idx.dtype.kind not in "iu" or \
                (idx.size and (idx.min() < 0 or idx.max() >= self.n_envs)):
            expected = "None in a scene built with n_envs=0" if self.n_envs == 0 else \
                f"integers in [0, {self.n_envs})"
            raise InvalidInputError(f"{what}: argument 'envs_idx' must be {expected}, got {envs_idx!r}")
        return idx.astype(np.int64)

    def get_state(self):
        sim = self._require_built("scene.get_state")
        return SimState(self, [sim.state(slot.solver) for slot in sim.slots])

    def set_gravity(self, gravity, envs_idx=None):
        """Gravity, m/s²: (3,) or (n_envs, 3); differentiable."""
        sim = self._require_built("scene.set_gravity")
        sim.check_grad_allowed(gravity, "scene", "gravity")
        probe = self.entities[0]
        envs = probe._envs(envs_idx)
        values = probe._values(gravity, 3, envs, "gravity")
        probe._write_input("gravity", np.arange(3), envs, values)

    def get_gravity(self, envs_idx=None):
        """Gravity, m/s²: (3,) or (n_envs, 3)."""
        self._require_built("scene.get_gravity")
        probe = self.entities[0]
        return probe._out(probe._read_input("gravity", np.arange(3), envs_idx))

    @property
    def t(self):
        """Steps taken since the last reset."""
        return self.sim.step_index if self.sim else 0

    @property
    def dt(self):
        return self.sim_options.dt

    def destroy(self):
        """Free the scene's arrays (its solvers' data); the scene cannot step afterwards."""
        self.rigid_solver.destroy()
        self.sim = None
        self._destroyed = True


def _envs_layout(n_batch, env_spacing, n_envs_per_row, center):
    """(envs per row, offsets (n_batch, 3) m): where each env is drawn (Genesis's layout; see
    Scene.build)."""
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
    per_row = n_envs_per_row or int(np.ceil(np.sqrt(n_batch)))
    k = np.arange(n_batch)
    offset = np.stack([k // per_row * spacing[0], k % per_row * spacing[1], np.zeros(n_batch)], axis=-1)
    if center:
        offset -= (offset.max(axis=0) + offset.min(axis=0)) / 2.0
    return per_row, offset


def _links_of(morph, material, name):
    """The morph's LinkSpec list (fixed links merged when the morph asks, friction from the
    material when it states one), its root joint set from the morph's placement."""
    if isinstance(morph, gm.URDF):
        if not os.path.isfile(morph.file):
            # name the argument and what was expected, as every error message does
            raise AssetError(f"entity '{name}': argument 'file' of gs.morphs.URDF expected an existing URDF file, "
                             f"got '{morph.file}' (not found; relative paths start at {os.getcwd()})")
        links = urdf.load_urdf(morph.file, entity_name=name, rho=material.rho)
        if morph.merge_fixed_links:
            links = merge.merge_fixed_links(links, morph.links_to_keep, owner=f"entity '{name}': gs.morphs.URDF")
        for link in links:
            link.armature = morph.default_armature
    elif isinstance(morph, gm.Box):
        links = shapes.box_link(morph.size, material.rho)
    elif isinstance(morph, gm.Sphere):
        links = shapes.sphere_link(morph.radius, material.rho)
    elif isinstance(morph, gm.Capsule):
        links = shapes.capsule_link(morph.radius, morph.height, material.rho)
    elif isinstance(morph, gm.Cylinder):
        links = shapes.cylinder_link(morph.radius, morph.height, material.rho)
    elif isinstance(morph, gm.Mesh):
        try:
            links = shapes.mesh_link(morph.file, morph.scale, material.rho)
        except AssetError as exc:  # shapes does not know the entity: add it to the message
            raise AssetError(f"entity '{name}': argument 'file' of gs.morphs.Mesh: {exc}") from exc
    elif isinstance(morph, gm.Plane):
        links = shapes.plane_link()
    else:
        raise InvalidInputError(f"scene.add_entity: morph type {type(morph).__name__} is not supported")
    if material.friction is not None:  # the material's friction overrides the asset's, as Genesis
        for geom in (geom for link in links for geom in link.geoms):
            geom.friction = material.friction
    root = links[0]
    root.joint_type = "fixed" if morph.fixed else "free"
    root.pos, root.quat = np.asarray(morph.pos, dtype=float), np.asarray(morph.quat, dtype=float)
    return links
