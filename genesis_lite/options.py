"""Scene options (Genesis names). Values are validated when the options are made."""
import functools
import logging
from dataclasses import dataclass, field, fields

import numpy as np
import torch

from .solvers.core import InvalidInputError, refuse_grad, warn_user


def _check_vec3(owner, name, value):
    refuse_grad(owner, name, value, "options are fixed at build; gravity is differentiable through "
                                    "scene.set_gravity")
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):  # a string, None, nested lists of other lengths
        arr = np.full(0, np.nan)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise InvalidInputError(f"{owner}: argument '{name}' must be 3 finite numbers, got {value!r}")
    return tuple(float(v) for v in arr)


def _check_positive(owner, name, value, integer=False):
    number = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))
    ok = number and np.isfinite(value) and value > 0 and (not integer or int(value) == value)
    if not ok:
        kind = "a positive integer" if integer else "a positive finite number"
        raise InvalidInputError(f"{owner}: argument '{name}' must be {kind}, got {value!r}")


def named_keywords(*genesis_only, deprecated=()):
    """Class decorator of an options dataclass: a keyword it does not have raises
    InvalidInputError naming the class, the keyword and the accepted ones (Python's TypeError
    named neither). ``genesis_only``: Genesis 1.4.5's options of that class which genesis_lite
    does not have, so that the message says so rather than "unknown"; ``deprecated``: the ones
    Genesis takes with a warning and ignores, as here."""
    def decorate(cls):
        init, accepted = cls.__init__, [f.name for f in fields(cls)]

        @functools.wraps(init)
        def checked_init(self, *args, **kwargs):
            for name in [name for name in kwargs if name in deprecated]:
                if kwargs.pop(name) is not None:  # (Genesis says nothing of a None)
                    warn_user(f"{cls.__qualname__}: '{name}' is deprecated (as in Genesis) and has no effect.")
            for name in kwargs:
                if name not in accepted:
                    what = "a Genesis option that genesis_lite does not have" if name in genesis_only else "unknown"
                    raise InvalidInputError(f"{cls.__qualname__}: argument '{name}' is {what}; expected one of "
                                            f"{accepted}")
            init(self, *args, **kwargs)
        cls.__init__ = checked_init
        return cls
    return decorate


@named_keywords("substeps_local", "floor_height")
@dataclass
class SimOptions:
    """Time stepping and differentiability.

    dt: step length, s. substeps: integration substeps per step (substep = dt / substeps).
    gravity: (3,) m/s². requires_grad: build the torch autograd graph through every step.
    check_nan: stop at the first non-finite state, naming the step and entity (without it, a
        blow-up warns once: always on the CPU, on a GPU only MPM's, whose particles the walls keep
        at finite positions; reading the rigid solver's flag there would wait for the device).
    checkpoint_interval: with requires_grad, keep the state of every k-th step only and
        recompute the others during backward (memory ÷ k, about one extra forward pass). A step
        whose state a setter replaced keeps its state too (a recomputation would miss the
        setter): with a setter before every step, every state is kept.
    """
    dt: float = 1e-2
    substeps: int = 1
    gravity: tuple = (0.0, 0.0, -9.81)
    requires_grad: bool = False
    check_nan: bool = False
    checkpoint_interval: int = 1

    def __post_init__(self):
        _check_positive("SimOptions", "dt", self.dt)
        _check_positive("SimOptions", "substeps", self.substeps, integer=True)
        _check_positive("SimOptions", "checkpoint_interval", self.checkpoint_interval, integer=True)
        self.gravity = _check_vec3("SimOptions", "gravity", self.gravity)
        self.requires_grad = check_bool("SimOptions", "requires_grad", self.requires_grad)
        self.check_nan = check_bool("SimOptions", "check_nan", self.check_nan)
        self.dt = float(self.dt)
        self.substeps = int(self.substeps)
        self.checkpoint_interval = int(self.checkpoint_interval)


class constraint_solver:
    """``gs.constraint_solver``: how the rigid constraint problem is solved."""
    Newton = "Newton"
    CG = "CG"


class friction_cone:
    """``gs.friction_cone``: pyramidal (MuJoCo's default, edges J_n ± μ J_t) or elliptic (exact)."""
    pyramidal = "pyramidal"
    elliptic = "elliptic"


class link_ref_frame:
    """``gs.link_ref_frame``: where a per-link quantity is taken: the link frame's origin, the
    link's centre of mass (link_COM), or the centre of mass of the kinematic tree the link is in
    (root_COM), as Genesis's (whose members are IntEnums)."""
    root_COM = "root_com"
    link_COM = "link_com"
    link_origin = "link_origin"


class _TimeBased:
    """A solver option ``dt`` (Genesis's TimeBasedMixin): the solver's substep, s, or None
    (SimOptions.dt / SimOptions.substeps). A given dt must divide SimOptions.dt an integer number
    of times, and that number is the substeps of every solver (the scene checks that the solvers
    given one agree)."""

    def _check_dt(self, owner):
        if self.dt is not None:
            self.dt = _check_float(owner, "dt", self.dt, 0.0, np.inf, "a positive finite number (s) or None")

    def substeps(self, sim_options):
        """The substeps per scene step: SimOptions.substeps when dt is None, else SimOptions.dt /
        dt, which must be an integer (as Genesis). A SimOptions.substeps other than 1 (taken as
        "not asked for": Genesis also refuses an explicit 1) must then agree."""
        if self.dt is None:
            return sim_options.substeps
        owner = type(self).__name__
        ratio = sim_options.dt / self.dt
        count = int(round(ratio))
        if count < 1 or abs(count * self.dt - sim_options.dt) > 1e-9 * sim_options.dt:
            raise InvalidInputError(f"{owner}: argument 'dt' must divide SimOptions.dt = {sim_options.dt:g} s an "
                                    f"integer number of times, got {self.dt:g} s (ratio {ratio:g})")
        if sim_options.substeps != 1 and count != sim_options.substeps:
            raise InvalidInputError(f"{owner}: argument 'dt' = {self.dt:g} s makes {count} substeps per step, but "
                                    f"SimOptions.substeps = {sim_options.substeps}; set one or the other")
        return count


# defaults that depend on enable_mujoco_compatibility: MuJoCo's, else Genesis's
MUJOCO_TIMECONST, GENESIS_TIMECONST = 0.02, 0.01
MUJOCO_ITERATIONS, GENESIS_ITERATIONS = 100, 25


@named_keywords("disable_constraint", "multiplier_collision_broad_phase",
           "integrator", "IK_max_targets", "noslip_iterations", "noslip_tolerance", "contact_resolution",
           "contact_pruning_tolerance", "sparse_solve",
           "use_hibernation", "hibernation_thresh_vel", "enable_multi_contact",
           "use_gjk_collision", "enable_contact_patch", "broadphase_traversal")
@dataclass
class RigidOptions(_TimeBased):
    """Rigid solver switches (Genesis 1.4.5's names and defaults unless said).

    dt: the rigid substep, s, or None (SimOptions.dt / SimOptions.substeps), as in Genesis
        (``_TimeBased``): RigidOptions(dt=0.01) with SimOptions(dt=0.02) steps in 2 substeps.

    enable_collision: contacts between collision shapes. Pair rules: enable_self_collision (two
        links of one kinematic tree: an entity, or one of an MJCF's root bodies' trees, as Genesis's
        rule is per root), enable_adjacent_collision (parent and child links),
        enable_neutral_collision (pairs of one tree already touching at the initial pose).
    enable_joint_limit: joint limits, as constraint rows of the contact solve (time constant
        constraint_timeconst, critically damped, MuJoCo's default solimp).
    constraint_solver: Newton (CG is not implemented). iterations (None: 25, or MuJoCo's 100
        under enable_mujoco_compatibility), tolerance (None: 1e-12 in float64, MuJoCo's 1e-8 under
        enable_mujoco_compatibility, 1e-5 in float32), ls_iterations, ls_tolerance: the solve's
        limits (a differentiable step whose solve stops at `iterations` before its tolerance warns
        once on the CPU: its gradient is the converged solution's). The float64 default is tighter than
        Genesis's 1e-8 because gradients are those of the exact solution: at 1e-8 MuJoCo's
        Newton-decrement test can stop an elliptic solve
        early (a mesh pressed into a box, sliding at one contact: the decrement 4e-9 with a
        scaled gradient of 5e-4), and the forward map's derivative then differed from the
        gradient by 1e-3 of its norm; one or two more Newton steps, no measurable cost in the a1
        and box-tower scenes. So under enable_mujoco_compatibility (1e-8) a gradient through rows
        the solve leaves that loose can be off by 1e-4 … 2e-3 of its norm (a chain of ball joints
        with friction loss on every dof, measured 2026-11-30); give ``tolerance=1e-14`` there when
        the gradients matter.
    friction_cone: pyramidal or elliptic. impratio: friction-to-normal impedance ratio (None: 1
        with the pyramidal cone, 100 with the elliptic one, as Genesis; 1 with
        enable_mujoco_compatibility).
    constraint_timeconst: time constant s of the joint rows (joint equalities of URDF mimic joints,
        MJCF connects and welds, joint limits, friction loss) and of every
        geom without its own solref (None: 0.01 as Genesis, or MuJoCo's 0.02 under
        enable_mujoco_compatibility).
    max_contacts: contact slots per env, more contacts stop the simulation with an error; None:
        8 per moving link (at least 16, at most the candidate pairs' worst case) to start with,
        doubled whenever a substep finds more (on the CPU; a GPU keeps them), up to the worst case.
    enable_mujoco_compatibility: MuJoCo's defaults exactly (time constant 0.02 s, 100
        iterations, impratio 1), for scenes compared with MuJoCo; and the convex collider's contacts
        on curved shapes (with a cylinder; a sphere or capsule deep in a mesh) are MuJoCo's CCD
        iterates rather than the converged closed form of their feature (within 6e-5 m at touching
        poses; a cylinder on its cap touches at the foot of the cap's centre, the iterate anywhere
        on the cap), which have no exact gradient (a backward over one raises GradientError).
        Not MuJoCo's either way: a cylinder standing or lying on a box, cylinder or mesh face gets
        its own rim points or line ends (MuJoCo's extra contacts from geoms turned by ±1e-3 rad are
        not reproduced), and a sphere whose centre is in a mesh's hull, where EPA stops at its
        budget, the nearest facet. Outside it only, a cylinder standing on a plane touches at four
        rim points too (MuJoCo's inscribed triangle turns with the tilt: no gradient at upright).
    max_dynamic_constraints: weld slots per env for welds made at run time
        (``scene.sim.rigid_solver.add_weld_constraint``); 0 by default, where Genesis's is 8: each slot
        adds six rows to every env's constraint capacity, and a scene with slots compiles the weld
        rows into its constraint kernels (seconds of a cold compile), so a scene asks for them.
    max_collision_pairs: Genesis's capacity of its broad phase's candidate pairs (a non-negative
        integer, default 150): taken, with nothing to size here (every candidate pair of the
        scene is listed at build; max_contacts bounds the contacts).
    box_box_detection: Genesis's switch to MuJoCo's box–box collider for box pairs (its default
        False collides them by its generic convex collider): ours always uses MuJoCo's, so True
        is taken and False (given) raises; None (default): ours.
    batch_links_info, batch_joints_info, batch_dofs_info: Genesis's switches that let link, joint
        and dof parameters (masses, gains, friction…) differ per env; ours always may (every
        parameter is stored per env), so either value works, as True does in Genesis.
    gravity: (3,) m/s² or None (SimOptions.gravity): the rigid bodies' own gravity, as Genesis's
        (its IK examples float a robot with (0, 0, 0)); scene.set_gravity sets it with every
        solver's.
    enable_torsional_friction, enable_rolling_friction: contacts also resist spin about their
        normal (condim 4), and rolling about their tangents too (condim 6; needs torsional), with
        the torsional and rolling friction (m) of materials.Rigid (set_friction_torsional,
        set_friction_rolling), as Genesis's switches; rows and cones as MuJoCo's condim 4 and 6.
        They raise every geom's condim of 3 or more (an MJCF geom's own condim 4 or 6 holds
        without them, as in MuJoCo; Genesis ignores the file's condim).
    smooth_contact (ours): the solimp of every geom whose asset states none (an MJCF geom's
        solimp is kept) becomes (0, 0.95, 0.001, 0.5, 2), whose impedance starts at zero at
        contact onset, so a contact's force grows from zero with depth instead of jumping
        (MuJoCo's default d0 = 0.9 jumps): the step is then a smooth map through contact onset,
        for gradients. Needs friction_cone=elliptic (the pyramid's edges add kinks). Joint limits
        keep MuJoCo's default solimp; set_sol_params still sets any geom's.
    """
    enable_collision: bool = True
    enable_self_collision: bool = True
    enable_adjacent_collision: bool = False
    enable_neutral_collision: bool = False
    enable_joint_limit: bool = True
    constraint_solver: str = constraint_solver.Newton
    iterations: int = None
    tolerance: float = None
    ls_iterations: int = 50
    ls_tolerance: float = 1e-2
    friction_cone: str = friction_cone.pyramidal
    impratio: float = None
    constraint_timeconst: float = None
    max_contacts: int = None
    enable_mujoco_compatibility: bool = False
    smooth_contact: bool = False
    dt: float = None  # (the fields before keep their positions: new ones come after)
    batch_links_info: bool = False
    batch_joints_info: bool = False
    batch_dofs_info: bool = False
    max_dynamic_constraints: int = 0
    max_collision_pairs: int = 150
    box_box_detection: bool = None
    gravity: tuple = None
    enable_torsional_friction: bool = False
    enable_rolling_friction: bool = False

    def __post_init__(self):
        owner = "RigidOptions"
        if self.gravity is not None:
            self.gravity = _check_vec3(owner, "gravity", self.gravity)
        if not (is_int(self.max_collision_pairs) and self.max_collision_pairs >= 0):
            raise InvalidInputError(f"{owner}: argument 'max_collision_pairs' must be an integer >= 0, got "
                                    f"{self.max_collision_pairs!r}")
        if self.box_box_detection is not None and not (isinstance(self.box_box_detection, (bool, np.bool_))
                                                       and self.box_box_detection):
            raise InvalidInputError(f"{owner}: argument 'box_box_detection' must be True or None: box pairs always "
                                    f"collide by MuJoCo's box–box collider here (Genesis's True), got "
                                    f"{self.box_box_detection!r}")
        if not (isinstance(self.max_dynamic_constraints, (int, np.integer)) and not isinstance(
                self.max_dynamic_constraints, (bool, np.bool_)) and self.max_dynamic_constraints >= 0):
            raise InvalidInputError(f"{owner}: argument 'max_dynamic_constraints' must be an integer >= 0, got "
                                    f"{self.max_dynamic_constraints!r}")
        self.max_dynamic_constraints = int(self.max_dynamic_constraints)
        self._check_dt(owner)
        for name in ("enable_collision", "enable_self_collision", "enable_adjacent_collision",
                     "enable_neutral_collision", "enable_joint_limit", "enable_mujoco_compatibility",
                     "smooth_contact", "batch_links_info", "batch_joints_info", "batch_dofs_info",
                     "enable_torsional_friction", "enable_rolling_friction"):
            setattr(self, name, check_bool(owner, name, getattr(self, name)))
        if self.enable_rolling_friction and not self.enable_torsional_friction:
            raise InvalidInputError(f"{owner}: argument 'enable_rolling_friction' requires "
                                    f"enable_torsional_friction=True (as Genesis: MuJoCo's condim 6 adds rolling "
                                    f"to condim 4's torsional friction)")
        if self.constraint_solver != constraint_solver.Newton:
            raise InvalidInputError(f"{owner}: argument 'constraint_solver' expected gs.constraint_solver.Newton "
                                    f"(CG is not implemented), got {self.constraint_solver!r}")
        self.ls_iterations = _check_positive_int(owner, "ls_iterations", self.ls_iterations)
        for name in ("iterations", "tolerance", "impratio", "constraint_timeconst", "max_contacts"):
            if getattr(self, name) is not None:
                _check_positive(owner, name, getattr(self, name), integer=name in ("iterations", "max_contacts"))
        _check_positive(owner, "ls_tolerance", self.ls_tolerance)
        _check_choice(owner, "friction_cone", self.friction_cone, (friction_cone.pyramidal, friction_cone.elliptic))
        if self.smooth_contact and self.friction_cone != friction_cone.elliptic:
            raise InvalidInputError(f"{owner}: argument 'smooth_contact' needs friction_cone="
                                    f"gs.friction_cone.elliptic (the pyramid's edges make the map kink), got "
                                    f"friction_cone={self.friction_cone!r}")

    def resolved(self, precision_bits):
        """(timeconst s, iterations, tolerance, impratio) after the defaults that depend on other
        options: MuJoCo's under enable_mujoco_compatibility, else Genesis's."""
        compat = self.enable_mujoco_compatibility
        tolerance = self.tolerance or (1e-5 if precision_bits == 32 else 1e-8 if compat else 1e-12)
        impratio = self.impratio or (100.0 if self.friction_cone == friction_cone.elliptic and not compat else 1.0)
        timeconst = self.constraint_timeconst or (MUJOCO_TIMECONST if compat else GENESIS_TIMECONST)
        iterations = self.iterations or (MUJOCO_ITERATIONS if compat else GENESIS_ITERATIONS)
        return timeconst, int(iterations), tolerance, impratio


#: MPMOptions.boundary_condition's choices: what the domain walls do to the grid velocity
MPM_BOUNDARY_CONDITIONS = ("slip", "sticky")


@named_keywords()
@dataclass
class MPMOptions(_TimeBased):
    """The MPM solver's options (Genesis 1.4.5's names and defaults, plus boundary_condition).

    dt: the MPM substep, s, or None (SimOptions.dt / SimOptions.substeps), as RigidOptions.dt.
    gravity: (3,) m/s² or None (SimOptions.gravity).
    particle_size: particle diameter, m; None: 0.01 · 64 / grid_density (resolved here, as
        Genesis). A particle's volume is particle_size³ and its mass rho · particle_size³.
    grid_density: grid cells per metre (dx = 1 / grid_density).
    enable_CPIC: Genesis's compatible PIC for thin rigid colliders; only False (not yet).
    lower_bound, upper_bound: (3,) m, the domain. Its walls lie 3 cells inside it
        (wall_bounds()): particles are clamped to them, and a particle must start strictly
        between them.
    boundary_condition (ours): what the walls do to the grid velocity at the nodes beyond
        them: "slip" (Genesis's: the component into the wall is zeroed, the tangential one
        kept) or "sticky" (where a component moves into the wall, every component is zeroed:
        the material sticks to the walls, and leaves them freely).
    use_sparse_grid, leaf_block_size: deprecated in Genesis, without effect (a warning when set).
    """
    dt: float = None
    gravity: tuple = None
    particle_size: float = None
    grid_density: float = 64
    enable_CPIC: bool = False
    lower_bound: tuple = (-1.0, -1.0, 0.0)
    upper_bound: tuple = (1.0, 1.0, 1.0)
    boundary_condition: str = "slip"
    use_sparse_grid: bool = False
    leaf_block_size: int = 8

    def __post_init__(self):
        owner = "MPMOptions"
        self._check_dt(owner)
        if self.gravity is not None:
            self.gravity = _check_vec3(owner, "gravity", self.gravity)
        self.grid_density = _check_float(owner, "grid_density", self.grid_density, 0.0, np.inf,
                                         "a positive finite number (cells per m)")
        if self.particle_size is None:
            self.particle_size = 0.01 * 64.0 / self.grid_density
        self.particle_size = _check_float(owner, "particle_size", self.particle_size, 0.0, np.inf,
                                          "a positive finite number (m) or None")
        if check_bool(owner, "enable_CPIC", self.enable_CPIC):
            raise InvalidInputError(f"{owner}: argument 'enable_CPIC' must be False: CPIC couples MPM with thin "
                                    f"rigid objects, which genesis_lite does not have yet, got True")
        self.enable_CPIC = False
        self.lower_bound = _check_vec3(owner, "lower_bound", self.lower_bound)
        self.upper_bound = _check_vec3(owner, "upper_bound", self.upper_bound)
        lower, upper = self.wall_bounds()
        if not np.all(upper > lower):
            raise InvalidInputError(f"{owner}: arguments 'lower_bound' and 'upper_bound' must leave room inside the "
                                    f"walls, 3 cells (3 / grid_density = {3.0 / self.grid_density:g} m) inside them "
                                    f"on each side: upper_bound − lower_bound > {6.0 / self.grid_density:g} m on "
                                    f"every axis, got {self.lower_bound} and {self.upper_bound}")
        _check_choice(owner, "boundary_condition", self.boundary_condition, MPM_BOUNDARY_CONDITIONS)
        if check_bool(owner, "use_sparse_grid", self.use_sparse_grid):
            logging.getLogger("genesis_lite").warning("MPMOptions: 'use_sparse_grid' is deprecated and has no effect.")
        if not is_int(self.leaf_block_size):
            raise InvalidInputError(f"{owner}: argument 'leaf_block_size' must be an integer (deprecated, without "
                                    f"effect), got {self.leaf_block_size!r}")
        if self.leaf_block_size != 8:
            logging.getLogger("genesis_lite").warning("MPMOptions: 'leaf_block_size' is deprecated and has no effect.")

    @property
    def dx(self):
        """Grid cell size, m."""
        return 1.0 / self.grid_density

    def wall_bounds(self):
        """(lower (3,), upper (3,)) m numpy: the walls, 3 cells inside the domain (Genesis's safety
        padding). Particles are kept within them; a sampled or set particle must lie strictly
        between them."""
        pad = 3.0 / self.grid_density
        return np.asarray(self.lower_bound) + pad, np.asarray(self.upper_bound) - pad


# -- visualisation (no viewer or camera exists yet: these are validated and stored for them) ---------

def check_bool(owner, name, value):
    if not isinstance(value, (bool, np.bool_)):
        raise InvalidInputError(f"{owner}: argument '{name}' must be True or False, got {value!r}")
    return bool(value)


def _check_optional(check, owner, name, value, *args):
    return None if value is None else check(owner, name, value, *args)


def real_array(value):
    """``value`` (numbers, a list, numpy or torch) as a float64 numpy array, or one NaN where it is not
    real numbers (strings, bools, complex, objects, ragged lists, tensors without data: numpy would
    turn "2" and True into 2.0 and 1.0), for the callers' named errors."""
    if isinstance(value, torch.Tensor):
        value = value.detach().cpu().numpy() if value.layout == torch.strided and not value.is_meta else np.nan
    try:
        array = np.asarray(value)
    except (TypeError, ValueError):
        return np.full(1, np.nan)
    return array.astype(np.float64) if array.dtype.kind in "iuf" else np.full(1, np.nan)


def is_int(value):
    """An integer, and not a bool (which Python counts as one)."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def _is_positive_int(value):
    return is_int(value) and value > 0


def _check_positive_int(owner, name, value):
    if not _is_positive_int(value):
        raise InvalidInputError(f"{owner}: argument '{name}' must be a positive integer, got {value!r}")
    return int(value)


def _check_float(owner, name, value, lo, hi, what):
    """A finite number in the open interval (lo, hi)."""
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))
    if not (ok and np.isfinite(value) and lo < value < hi):
        raise InvalidInputError(f"{owner}: argument '{name}' must be {what}, got {value!r}")
    return float(value)


def _check_color(owner, name, value):
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        arr = np.full(0, np.nan)
    if arr.shape != (3,) or not np.all((arr >= 0) & (arr <= 1)):
        raise InvalidInputError(f"{owner}: argument '{name}' must be 3 numbers in [0, 1] (RGB), got {value!r}")
    return tuple(float(v) for v in arr)


def _check_choice(owner, name, value, choices):
    if value not in choices:
        raise InvalidInputError(f"{owner}: argument '{name}' must be one of {list(choices)}, got {value!r}")
    return value


@named_keywords()
@dataclass
class LegacyCouplerOptions:
    """Which solvers interact (Genesis 1.4.5's names and defaults: all True). rigid_mpm: the MPM
    particles meet the rigid shapes (solvers/coupling.py); False: they pass through them, as
    Genesis's. The other pairs name solvers genesis_lite does not have (SPH, PBD, FEM): in
    Genesis, too, a pair without both its solvers in the scene does nothing."""
    rigid_mpm: bool = True
    rigid_sph: bool = True
    rigid_pbd: bool = True
    rigid_fem: bool = True
    mpm_sph: bool = True
    mpm_pbd: bool = True
    fem_mpm: bool = True
    fem_sph: bool = True

    def __post_init__(self):
        for name in ("rigid_mpm", "rigid_sph", "rigid_pbd", "rigid_fem", "mpm_sph", "mpm_pbd", "fem_mpm", "fem_sph"):
            setattr(self, name, check_bool("LegacyCouplerOptions", name, getattr(self, name)))


@named_keywords()
@dataclass
class ViewerOptions:
    """The interactive viewer's options (Genesis 1.4.5's names and defaults). No viewer exists yet
    (cameras are headless: scene.add_camera): ``gs.Scene(show_viewer=True)`` raises; these are
    validated and kept for it.

    res: (2,) pixels or None (the display's). run_in_thread: None (platform default) or bool.
    refresh_rate: frames/s. realtime_factor: playback speed (1.0: real time) or None (as fast
    as possible). camera_pos, camera_lookat (m), camera_up: the camera pose (3,) each.
    camera_fov: vertical field of view, degrees. enable_help_text, enable_default_keybinds,
    enable_gui: viewer overlays. max_FPS: deprecated alias of refresh_rate (as Genesis).
    """
    res: tuple = None
    run_in_thread: bool = None
    refresh_rate: int = 60
    realtime_factor: float = 1.0
    camera_pos: tuple = (3.5, 0.5, 2.5)
    camera_lookat: tuple = (0.0, 0.0, 0.5)
    camera_up: tuple = (0.0, 0.0, 1.0)
    camera_fov: float = 40
    enable_help_text: bool = True
    enable_default_keybinds: bool = True
    enable_gui: bool = False
    max_FPS: int = None

    def __post_init__(self):
        owner = "ViewerOptions"
        if self.res is not None:
            pair = isinstance(self.res, (list, tuple)) and len(self.res) == 2
            if not (pair and all(map(_is_positive_int, self.res))):
                raise InvalidInputError(f"{owner}: argument 'res' must be 2 positive integers (pixels) or None, "
                                        f"got {self.res!r}")
            self.res = tuple(int(v) for v in self.res)
        self.run_in_thread = _check_optional(check_bool, owner, "run_in_thread", self.run_in_thread)
        self.refresh_rate = _check_positive_int(owner, "refresh_rate", self.refresh_rate)
        self.realtime_factor = _check_optional(_check_float, owner, "realtime_factor", self.realtime_factor,
                                               0.0, np.inf, "a positive finite number or None")
        for name in ("camera_pos", "camera_lookat", "camera_up"):
            setattr(self, name, _check_vec3(owner, name, getattr(self, name)))
        if not np.any(self.camera_up):
            raise InvalidInputError(f"{owner}: argument 'camera_up' must be a non-zero vector, got {self.camera_up}")
        self.camera_fov = _check_float(owner, "camera_fov", self.camera_fov, 0.0, 180.0,
                                       "a number of degrees in (0, 180)")
        for name in ("enable_help_text", "enable_default_keybinds", "enable_gui"):
            setattr(self, name, check_bool(owner, name, getattr(self, name)))
        if self.max_FPS is not None:
            self.max_FPS = _check_positive_int(owner, "max_FPS", self.max_FPS)
            if self.refresh_rate not in (60, self.max_FPS):  # 60: the default, i.e. not set
                raise InvalidInputError(f"{owner}: arguments 'max_FPS' (deprecated) and 'refresh_rate' are the "
                                        f"same setting; give only 'refresh_rate', got {self.max_FPS} and "
                                        f"{self.refresh_rate}")
            self.refresh_rate = self.max_FPS


_LIGHT_KEYS = {"directional": ("dir", "color", "intensity"), "point": ("pos", "color", "intensity"),
               "ambient": ("color", "intensity")}


def _default_lights():
    return [{"type": "directional", "dir": (-1.0, -1.0, -1.0), "color": (1.0, 1.0, 1.0), "intensity": 5.0}]


def _check_lights(owner, value):
    """A list of light dicts: {"type": "directional", "dir", "color", "intensity"}, {"type": "point",
    "pos", "color", "intensity"} or {"type": "ambient", "color", "intensity"} (Genesis's fields)."""
    if not isinstance(value, (list, tuple)):
        raise InvalidInputError(f"{owner}: argument 'lights' must be a list of light dicts, got {value!r}")
    lights = []
    for k, light in enumerate(value):
        kind = light.get("type", "directional") if isinstance(light, dict) else None
        keys = _LIGHT_KEYS.get(kind)
        if keys is None or set(light) - {"type", *keys} or set(keys) - set(light):
            raise InvalidInputError(f"{owner}: argument 'lights[{k}]' must be a dict with 'type' one of "
                                    f"{list(_LIGHT_KEYS)} and exactly the keys of that type {_LIGHT_KEYS}, "
                                    f"got {light!r}")
        lights.append({"type": kind, **{name: _check_light_value(owner, f"lights[{k}].{name}", light[name])
                                        for name in keys}})
    return lights


def _check_light_value(owner, name, value):
    if name.endswith(".color"):
        return _check_color(owner, name, value)
    if name.endswith(".intensity"):
        return _check_float(owner, name, value, -np.inf, np.inf, "a finite number")
    return _check_vec3(owner, name, value)  # dir or pos


@named_keywords()
@dataclass
class VisOptions:
    """What is drawn, whatever the viewer or camera (Genesis 1.4.5's names and defaults). Cameras
    (genesis_lite/vis/camera.py) read background_color, segmentation_level, rendered_envs_idx,
    particle_size_scale and contact_force_scale (the arrows a debug camera draws of an entity
    added with visualize_contact); adding a camera raises for non-default values of what they cannot draw
    yet (world, link and camera frames, plane reflection, split_envs, ambient_light, lights, the
    MPM boundary); shadow draws no shadow. As Genesis's rasterizer, they draw particles as spheres
    whatever render_particle_as (the raytracer's).

    show_world_frame / show_link_frame / show_cameras: draw those frames (sizes in m).
    shadow, plane_reflection: rendering effects. split_envs: cameras render each env on its
    own (else all envs side by side, at the offsets of ``scene.build(env_spacing=…)``).
    background_color, ambient_light: RGB in [0, 1]. visualize_{mpm,sph,pbd}_boundary: solver
    bounds. segmentation_level: "entity" | "link" | "geom". render_particle_as: "sphere" | "tet";
    particle_size_scale (> 0). contact_force_scale: m/N of contact arrows (> 0).
    n_support_neighbors: particles per visual vertex. rendered_envs_idx: env indices or None
    (all; checked against n_envs at build). lights: list of light dicts (see _check_lights).
    """
    show_world_frame: bool = False
    world_frame_size: float = 1.0
    show_link_frame: bool = False
    link_frame_size: float = 0.2
    show_cameras: bool = False
    shadow: bool = True
    plane_reflection: bool = False
    split_envs: bool = False
    background_color: tuple = (0.04, 0.08, 0.12)
    ambient_light: tuple = (0.1, 0.1, 0.1)
    visualize_mpm_boundary: bool = False
    visualize_sph_boundary: bool = False
    visualize_pbd_boundary: bool = False
    segmentation_level: str = "link"
    render_particle_as: str = "sphere"
    particle_size_scale: float = 1.0
    contact_force_scale: float = 0.01
    n_support_neighbors: int = 12
    rendered_envs_idx: tuple = None
    lights: list = field(default_factory=_default_lights)

    def __post_init__(self):
        owner = "VisOptions"
        for name in ("show_world_frame", "show_link_frame", "show_cameras", "shadow", "plane_reflection",
                     "split_envs", "visualize_mpm_boundary", "visualize_sph_boundary", "visualize_pbd_boundary"):
            setattr(self, name, check_bool(owner, name, getattr(self, name)))
        for name in ("world_frame_size", "link_frame_size", "particle_size_scale", "contact_force_scale"):
            setattr(self, name, _check_float(owner, name, getattr(self, name), 0.0, np.inf, "a positive finite number"))
        for name in ("background_color", "ambient_light"):
            setattr(self, name, _check_color(owner, name, getattr(self, name)))
        _check_choice(owner, "segmentation_level", self.segmentation_level, ("entity", "link", "geom"))
        _check_choice(owner, "render_particle_as", self.render_particle_as, ("sphere", "tet"))
        self.n_support_neighbors = _check_positive_int(owner, "n_support_neighbors", self.n_support_neighbors)
        if self.rendered_envs_idx is not None:
            idx = self.rendered_envs_idx
            if isinstance(idx, (str, bytes)) or not hasattr(idx, "__iter__") or not list(idx) or \
                    not all(isinstance(i, (int, np.integer)) and not isinstance(i, bool) and i >= 0 for i in idx):
                raise InvalidInputError(f"{owner}: argument 'rendered_envs_idx' must be env indices (integers ≥ 0, at "
                                        f"least one) or None, got {idx!r}")
            self.rendered_envs_idx = tuple(int(i) for i in idx)
        self.lights = _check_lights(owner, self.lights)
