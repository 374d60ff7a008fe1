"""The scene: entities are added, then ``build(n_envs)`` fixes everything and ``step()`` runs.

Lifecycle errors (step before build, build twice, add after build) raise SceneStateError.
"""
import os

import numpy as np

from . import morphs as gm
from .entities import RigidEntity
from .solvers.core import AssetError, InvalidInputError, SceneStateError
from .materials import Rigid
from .options import RigidOptions, SimOptions
from .runtime import require_init, runtime
from .simulator import Simulator
from .solvers.rigid import shapes, urdf
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
    def __init__(self, sim_options=None, rigid_options=None, show_viewer=False):
        require_init("gs.Scene")
        self.sim_options = sim_options or SimOptions()
        self.rigid_options = rigid_options or RigidOptions()
        for arg, value, kind in (("sim_options", self.sim_options, SimOptions),
                                 ("rigid_options", self.rigid_options, RigidOptions)):
            if not isinstance(value, kind):
                raise InvalidInputError(f"gs.Scene: argument '{arg}' must be gs.options.{kind.__name__}, "
                                        f"got {type(value).__name__}")
        self.show_viewer = show_viewer
        self.entities = []
        self.rigid_solver = RigidSolver(self.sim_options, self.rigid_options)
        self.sim = None
        self.n_envs = 0
        self._epoch = runtime.epoch

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

    def build(self, n_envs=0):
        """Allocate and compile for ``n_envs`` environments (0: no batch dimension)."""
        if self.is_built:
            raise SceneStateError("scene.build: the scene is already built; build() may be called once")
        if not (isinstance(n_envs, (int, np.integer)) and n_envs >= 0):
            raise InvalidInputError(f"scene.build: argument 'n_envs' must be an integer ≥ 0, got {n_envs!r}")
        if not self.entities:
            raise SceneStateError("scene.build: the scene has no entity; add one with scene.add_entity()")
        self.n_envs = int(n_envs)
        sim = Simulator(self.sim_options, [self.rigid_solver])
        try:
            sim.build(self.n_envs)
        except Exception:  # e.g. a massless moving link: free the fields allocated so far
            self.rigid_solver.destroy()
            raise
        self.sim = sim
        for entity in self.entities:
            entity._on_build()

    def _require_built(self, what):
        if self._epoch != runtime.epoch:
            raise SceneStateError(f"{what}: gs.init() was called again after this scene was made; build a new scene")
        if not self.is_built:
            raise SceneStateError(f"{what}: call scene.build() first")
        return self.sim

    # -- running ----------------------------------------------------------------------------
    def step(self):
        """Advance by ``dt`` (``substeps`` integration substeps)."""
        self._require_built("scene.step").step()

    def reset(self, state=None):
        """Return to the state at build (or ``state`` from get_state()); controls are cleared,
        parameters kept, and a new autograd graph starts (backward on the old one raises)."""
        sim = self._require_built("scene.reset")
        if state is not None and not (isinstance(state, SimState) and state.scene is self):
            raise InvalidInputError(f"scene.reset: argument 'state' must come from this scene's get_state(), "
                                    f"got {type(state).__name__}")
        sim.reset(None if state is None else state.states)

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
        """Free the scene's Taichi fields."""
        self.rigid_solver.destroy()
        self.sim = None


def _links_of(morph, material, name):
    """The morph's LinkSpec list, its root joint set from the morph's placement."""
    if isinstance(morph, gm.URDF):
        if not os.path.isfile(morph.file):
            # name the argument and what was expected, as every error message does
            raise AssetError(f"entity '{name}': argument 'file' of gs.morphs.URDF expected an existing URDF file, "
                             f"got '{morph.file}' (not found; relative paths start at {os.getcwd()})")
        links = urdf.load_urdf(morph.file, entity_name=name, rho=material.rho)
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
    root = links[0]
    root.joint_type = "fixed" if morph.fixed else "free"
    root.pos, root.quat = np.asarray(morph.pos, dtype=float), np.asarray(morph.quat, dtype=float)
    return links
