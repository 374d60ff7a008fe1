"""Morphs: what shape an entity has and where it starts (Genesis names).

Angles: ``euler`` is (roll, pitch, yaw) in degrees, fixed axes x-y-z as in Genesis;
``quat`` (w, x, y, z) overrides it when given. Lengths in metres.
"""
import dataclasses
import functools
import importlib.util
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np

from .options import check_bool, is_int, named_keywords, real_array
from .solvers.core import InvalidInputError, refuse_grad, warn_user
from .utils import geom, terrain

# Genesis 1.4.5's morph options that genesis_lite does not have (a named error says so, where
# Python's TypeError named neither the morph nor the keyword): every morph's, the primitives',
# the tetrahedral meshing ones (FEM, not here) and the file morphs'
_MORPH = ("offset_pos", "offset_euler", "offset_quat", "enable_custom_vverts")
_PRIMITIVE = _MORPH + ("batch_fixed_verts",)
_TETGEN = ("order", "mindihedral", "minratio", "nobisect", "quality", "maxvolume", "verbose", "force_retet")
_FILE = _MORPH + ("decimate", "decimate_face_num", "decimate_aggressiveness", "watertighten", "convexify",
                  "decompose_object_error_threshold", "decompose_robot_error_threshold", "coacd_options",
                  "recompute_inertia", "align", "batch_fixed_verts")
# taken by Genesis 1.4.5 with a deprecation warning and no effect, as here
_DEPRECATED = ("requires_jac_and_IK", "is_free")


# the assets genesis_lite ships (its drones: urdf/drones/cf2x.urdf, cf2p.urdf, racer.urdf), found
# before genesis-world's under the same relative paths
BUNDLED_ASSETS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "assets")


@functools.cache
def genesis_assets():
    """The folder of genesis-world's bundled assets (Genesis's get_assets_dir(): its xml/, urdf/,
    meshes/…) when that package is installed, else None. Found without importing it."""
    spec = importlib.util.find_spec("genesis")
    folders = list(spec.submodule_search_locations or []) if spec is not None else []
    return next((os.path.join(f, "assets") for f in folders if os.path.isdir(os.path.join(f, "assets"))), None)


def inline_xml(file):
    """Whether a file morph's ``file`` is an XML document itself (Genesis's inline MJCF or URDF: a
    string that parses as XML, here also after leading white space, as a triple-quoted document
    starts) rather than a path."""
    if not (isinstance(file, str) and file.lstrip().startswith("<")):
        return False
    try:
        ET.fromstring(file.strip())
    except ET.ParseError:
        return False
    return True


def _file_path(owner, file, xml=False):
    """A file morph's ``file`` (a path string or os.PathLike) as Genesis resolves it: the path made
    absolute where it exists (a relative one from the working directory), else in genesis_lite's
    own assets (BUNDLED_ASSETS) or genesis-world's (genesis_assets) where it is there, else as given
    (scene.add_entity says it was not found). xml (MJCF, URDF): also, as Genesis's, the document
    itself, as a string (inline_xml) or an xml.etree Element or ElementTree (taken as its
    string)."""
    if xml and isinstance(file, (ET.Element, ET.ElementTree)):
        return ET.tostring(file.getroot() if isinstance(file, ET.ElementTree) else file, encoding="unicode")
    if isinstance(file, os.PathLike):
        file = os.fspath(file)
    what = "a path (a string or os.PathLike)" + (", or the XML document itself" if xml else "")
    if not isinstance(file, str) or not file:
        raise InvalidInputError(f"{owner}: argument 'file' must be {what}, got {file!r}")
    if xml and inline_xml(file):
        return file
    if os.path.exists(file):  # (absolute, as Genesis keeps it: the working directory may change before build)
        return os.path.abspath(file)
    for assets in (BUNDLED_ASSETS, genesis_assets()):
        if assets is not None and os.path.exists(os.path.join(assets, file)):
            return os.path.join(assets, file)
    return file


class _GenesisArmature:
    """default_armature's default (URDF, MJCF): Genesis's 0.1 kg·m² (or kg), or none under
    RigidOptions(enable_mujoco_compatibility=True), where the file's dynamics are MuJoCo's; the
    scene resolves it (a value given, even 0.1, is taken as given, as Genesis does)."""

    def __repr__(self):
        return "0.1 (none under enable_mujoco_compatibility)"


GENESIS_ARMATURE = _GenesisArmature()


def _armature(owner, value):
    """A morph's default_armature checked: the GENESIS_ARMATURE default, None (none: 0.0) or a
    finite number ≥ 0, as a float."""
    if value is GENESIS_ARMATURE:
        return value
    refuse_grad(owner, "default_armature", value, "it is fixed at build; set_dofs_armature is differentiable")
    try:
        armature = 0.0 if value is None else float(value)
    except (TypeError, ValueError):
        armature = np.nan
    if isinstance(value, (bool, np.bool_, str)) or not np.isfinite(armature) or armature < 0:
        raise InvalidInputError(f"{owner}: argument 'default_armature' must be a finite number ≥ 0 (kg·m² or kg) "
                                f"or None, got {value!r}")
    return armature


_DIFFERENTIABLE_START = ("a morph's pose is fixed at build; a differentiable start is set after scene.build() "
                         "with the entity's setters: set_pos, set_quat, set_dofs_position, an MPM entity's "
                         "set_position")


def _vec(owner, name, value, n):
    refuse_grad(owner, name, value, _DIFFERENTIABLE_START)
    arr = real_array(value)
    if arr.shape != (n,) or not np.all(np.isfinite(arr)):
        raise InvalidInputError(f"{owner}: argument '{name}' must be {n} finite numbers, got {value!r}")
    return arr


def _positive(owner, name, value):
    refuse_grad(owner, name, value, "a shape's size is fixed at build")
    arr = real_array(value)
    if not np.all(np.isfinite(arr)) or not np.all(arr > 0):
        raise InvalidInputError(f"{owner}: argument '{name}' must be positive and finite, got {value!r}")


_GLTF = (".glb", ".gltf")


def _meshes_zup(owner, value, file, default):
    """Genesis's ``file_meshes_are_zup`` as a bool: True, meshes read as they are (Z-up); False,
    turned from Y-up, (X, Y, Z) → (X, −Z, Y) (shapes.load_mesh's y_up); None: ``default``, except a
    glTF file's, False (Genesis's Mesh: glTF is Y-up by its standard)."""
    if value is not None and not isinstance(value, (bool, np.bool_)):
        raise InvalidInputError(f"{owner}: argument 'file_meshes_are_zup' must be True, False or None, got {value!r}")
    if value is None:
        return default and not str(file).lower().endswith(_GLTF)
    return bool(value)


def _isotropic_scale(owner, value):
    """``value`` as one positive factor: a number, or a sequence of three equal ones."""
    _positive(owner, "scale", value)
    factors = np.atleast_1d(np.asarray(value, dtype=np.float64))
    if factors.shape not in ((1,), (3,)) or np.ptp(factors) > 1e-12 * factors.max():
        raise InvalidInputError(f"{owner}: argument 'scale' must be one positive number or three equal ones (the same "
                                f"factor along every axis), got {value!r}")
    return float(factors[0])


def _check_masks(owner, morph):
    """A primitive's or mesh's contype and conaffinity (Genesis's collision bit masks, default
    0xFFFF): integers in [0, 0xFFFFFFFF]. A geom pair may touch when (contype₁ & conaffinity₂) |
    (contype₂ & conaffinity₁) ≠ 0 (MuJoCo's rule; a URDF's shapes have 1 and 1, an MJCF's its
    own); both 0: the body collides with nothing (Genesis makes it no collision shape)."""
    for name in ("contype", "conaffinity"):
        value = getattr(morph, name)
        if not (is_int(value) and 0 <= value <= 0xFFFFFFFF):
            raise InvalidInputError(f"{owner}: argument '{name}' must be an integer bit mask in [0, 0xFFFFFFFF], "
                                    f"got {value!r}")
        setattr(morph, name, int(value))


@dataclass
class Morph:
    """Initial placement shared by every morph: pos (3,) m; euler (3,) degrees (extrinsic x-y-z) or
    quat (w, x, y, z), not both (neither: no rotation). fixed: welded to the world (no free joint).
    visualization, collision (a rigid entity's, as Genesis's; not both False): drawn by cameras;
    its shapes collide (False: in no contact pair)."""
    pos: tuple = (0.0, 0.0, 0.0)
    euler: tuple = None
    quat: tuple = None
    fixed: bool = False
    visualization: bool = True
    collision: bool = True

    def __post_init__(self):
        owner = type(self).__name__
        self.pos = _vec(owner, "pos", self.pos, 3)
        if self.euler is not None and self.quat is not None:  # (as Genesis: one of them would go unused)
            raise InvalidInputError(f"{owner}: arguments 'euler' and 'quat' cannot both be set, got euler "
                                    f"{self.euler!r} and quat {self.quat!r}")
        if self.quat is None:
            self.euler = _vec(owner, "euler", (0.0, 0.0, 0.0) if self.euler is None else self.euler, 3)
            self.quat = geom.euler_to_quat(self.euler)  # (Genesis's: roll-pitch-yaw, degrees)
        else:
            q = _vec(owner, "quat", self.quat, 4)
            if np.linalg.norm(q) < 1e-9:
                raise InvalidInputError(f"{owner}: argument 'quat' must be a non-zero quaternion (w, x, y, z), "
                                        f"got {self.quat!r}")
            self.quat = q / np.linalg.norm(q)
        for name in ("fixed", "visualization", "collision"):  # ('no' would weld the body)
            setattr(self, name, check_bool(owner, name, getattr(self, name)))
        if not (self.visualization or self.collision):  # (Genesis's rule: the entity would be nothing)
            raise InvalidInputError(f"{owner}: arguments 'visualization' and 'collision' cannot both be False")
        self._check()

    def _check(self):
        pass


@named_keywords(*_FILE, "prioritize_urdf_material", "xacro_args", deprecated=_DEPRECATED)
@dataclass
class URDF(Morph):
    """A robot from a URDF file; mesh paths may be relative or ``package://``. ``file``: a path (str or
    os.PathLike), found as given, else among genesis-world's bundled assets when that package is
    installed (Genesis's rule: "urdf/go2/urdf/go2.urdf"); so are MJCF's and Mesh's. A URDF's or
    MJCF's ``file`` may also be the XML document itself (a string, or an xml.etree Element), as
    Genesis's: its relative paths (meshes, includes) then start at the working directory.

    scale: the robot grown by this factor, of the same densities, as Genesis's (lengths × s,
    masses × s³, inertias × s⁵; gains, damping, friction and effort limits the file's:
    solvers/rigid/scale.py). A positive number, or three equal ones (Genesis's rule: a URDF scales
    the same along every axis).
    file_meshes_are_zup: True (Genesis's default): meshes are read as they are (Z-up); False or None:
    every mesh of the file is turned from Y-up, (X, Y, Z) → (X, −Z, Y), as Genesis's loader.
    default_armature: armature (kg·m² or kg) of every revolute and prismatic dof (a motor's rotor;
    as Genesis, not a free base's), as URDF has no tag for it; None: none. Genesis's default: 0.1,
    none under RigidOptions(enable_mujoco_compatibility=True) (GENESIS_ARMATURE).
    merge_fixed_links: merge every link attached by a fixed joint into its parent, as Genesis
    (and MuJoCo) do: one rigid body, same physics, fewer links. The merged link keeps the
    parent's name; the merged-away names no longer exist. The root link is never merged.
    links_to_keep: names of links that must not be merged away (sequence of str).
    (solvers/rigid/merge.py says how, and where the link order differs from Genesis's.)"""
    file: str = None
    scale: float = 1.0
    default_armature: float = GENESIS_ARMATURE
    merge_fixed_links: bool = True
    links_to_keep: tuple = ()
    file_meshes_are_zup: bool = True

    def _check(self):
        owner = type(self).__name__
        self.file = _file_path(owner, self.file, xml=True)
        if self.file.lower().endswith(".xacro"):  # (its macros would be skipped as unknown elements)
            raise InvalidInputError(f"{owner}: argument 'file': xacro files are not supported yet (Genesis expands "
                                    f"them with the xacro package), got {self.file!r}; expand it first: "
                                    f"xacro robot.urdf.xacro > robot.urdf")
        self.scale = _isotropic_scale(owner, self.scale)
        self.file_meshes_are_zup = _meshes_zup(owner, self.file_meshes_are_zup, self.file, False)
        self.default_armature = _armature(owner, self.default_armature)
        if not isinstance(self.merge_fixed_links, (bool, np.bool_)):
            raise InvalidInputError(f"{owner}: argument 'merge_fixed_links' must be True or False, "
                                    f"got {self.merge_fixed_links!r}")
        keep = self.links_to_keep
        if not isinstance(keep, (list, tuple, set, frozenset)) or not all(isinstance(name, str) for name in keep):
            raise InvalidInputError(f"{owner}: argument 'links_to_keep' must be a sequence of link names (str), "
                                    f"got {keep!r}")
        if keep and not self.merge_fixed_links:  # it would be ignored: say so instead
            raise InvalidInputError(f"{owner}: argument 'links_to_keep' names links to keep from merging, so it needs "
                                    f"merge_fixed_links=True, got links_to_keep={tuple(keep)!r} with "
                                    f"merge_fixed_links=False")
        self.merge_fixed_links, self.links_to_keep = bool(self.merge_fixed_links), tuple(keep)


@named_keywords(*_FILE, "prioritize_urdf_material", deprecated=_DEPRECATED + ("COM_link_name",))
@dataclass
class Drone(URDF):
    """A multirotor from a URDF whose ``<properties>`` element states its rotors' coefficients kf
    (thrust per rpm², N) and km (drag torque per rpm², N·m), as Genesis's drones; scene.add_entity
    makes it a DroneEntity, flown by set_propellers_rpm. genesis_lite ships three (written here,
    from the published figures): "urdf/drones/cf2x.urdf" (a Crazyflie 2.x, rotors in an X),
    "cf2p.urdf" (in a +) and "racer.urdf", found under those relative paths as Genesis's bundled
    ones are.

    Its base is always free (Genesis's rule: ``fixed`` is refused). propellers_link_name: the
    rotors' links (kept from merging); each rotor's thrust acts along its link's z axis at its
    centre of mass, its drag torque about that axis with the sign of propellers_spin (1:
    counter-clockwise, −1: clockwise, seen from above), reversed for model "RACE" (Genesis's
    models "CF2X", "CF2P", "RACE"). (Genesis turns them by the link's inertial frame: the same
    for massless rotors, as its drones' and ours, or an inertial frame without rpy.)
    default_base_ang_damping_scale: the free base's rotational dofs get damping (N·m·s/rad) of
    this times the drone's mass (Genesis's 1e-5; None: none). propellers_link_names: Genesis's
    deprecated name of propellers_link_name (a warning). The rest as URDF's."""
    model: str = "CF2X"
    propellers_link_name: tuple = ("prop0_link", "prop1_link", "prop2_link", "prop3_link")
    propellers_spin: tuple = (-1, 1, -1, 1)
    default_base_ang_damping_scale: float = 1e-5
    propellers_link_names: tuple = None

    def _check(self):
        if self.propellers_link_names is not None:  # (Genesis's deprecated alias)
            warn_user("Drone: 'propellers_link_names' is deprecated (as in Genesis); use 'propellers_link_name'")
            if tuple(self.propellers_link_name) != Drone.propellers_link_name:
                raise InvalidInputError("Drone: arguments 'propellers_link_names' and 'propellers_link_name' cannot "
                                        f"both be given, got {self.propellers_link_names!r} and "
                                        f"{self.propellers_link_name!r}")
            self.propellers_link_name, self.propellers_link_names = self.propellers_link_names, None
        if self.fixed:
            raise InvalidInputError("Drone: argument 'fixed' must be False (a drone's base is free, as Genesis's), "
                                    "got True")
        if self.model not in ("CF2X", "CF2P", "RACE"):
            raise InvalidInputError(f"Drone: argument 'model' must be 'CF2X', 'CF2P' or 'RACE', got {self.model!r}")
        names = self.propellers_link_name
        if isinstance(names, str) or not isinstance(names, (list, tuple)) or not names or \
                not all(isinstance(n, str) for n in names) or len(set(names)) != len(names):
            raise InvalidInputError(f"Drone: argument 'propellers_link_name' must be a sequence of distinct link names "
                                    f"(str), got {names!r}")
        spin = self.propellers_spin
        if not isinstance(spin, (list, tuple, np.ndarray)) or len(spin) != len(names) or \
                not all(isinstance(k, (int, float, np.integer, np.floating)) and not isinstance(k, bool) and
                        k in (-1, 1) for k in spin):
            raise InvalidInputError(f"Drone: argument 'propellers_spin' must hold 1 (counter-clockwise) or -1 "
                                    f"(clockwise) for each of the {len(names)} propellers, got {spin!r}")
        scale = self.default_base_ang_damping_scale
        refuse_grad("Drone", "default_base_ang_damping_scale", scale, "it is fixed at build; set_dofs_damping is "
                    "differentiable")
        if scale is not None and not (isinstance(scale, (int, float, np.floating, np.integer)) and
                                      not isinstance(scale, bool) and np.isfinite(scale) and scale >= 0):
            raise InvalidInputError(f"Drone: argument 'default_base_ang_damping_scale' must be a finite number ≥ 0 "
                                    f"(N·m·s/rad per kg) or None, got {scale!r}")
        self.propellers_link_name, self.propellers_spin = tuple(names), tuple(int(k) for k in spin)
        if self.merge_fixed_links:  # (the rotors' links carry their thrust: never merged away)
            self.links_to_keep = tuple(dict.fromkeys((*self.links_to_keep, *names)))
        super()._check()


def rotor_coefficients(file, who):
    """(kf N/rpm², km N·m/rpm²) of a drone's URDF (a path to a file that exists, or the document
    itself): its <properties kf km> element's, numbers ≥ 0; ``who`` names the entity."""
    root = ET.fromstring(file.strip()) if inline_xml(file) else ET.parse(file).getroot()
    properties = root.find("properties")
    attrs = {} if properties is None else properties.attrib
    try:
        kf, km = float(attrs["kf"]), float(attrs["km"])
    except (KeyError, ValueError):
        kf = km = float("nan")
    if not (np.isfinite(kf) and np.isfinite(km) and kf >= 0 and km >= 0):
        where = "<inline URDF>" if inline_xml(file) else repr(file)
        raise InvalidInputError(f"{who}: argument 'file' of gs.morphs.Drone expected a URDF whose <properties> element "
                                f"states the rotors' kf and km (numbers ≥ 0), got {where} with "
                                f"<properties {attrs}>")
    return kf, km


@named_keywords(*_FILE, deprecated=_DEPRECATED)
@dataclass
class MJCF(Morph):
    """A robot (or a scene of bodies) from an MJCF (MuJoCo XML) file: the bodies in its worldbody
    are the trees of one entity, the first one's root its base, read as MuJoCo's compiler reads
    it (solvers/rigid/mjcf.py says which elements, and what is refused or ignored with a warning).
    pos/euler/quat place the file's world frame (each root body keeps its pose in it: Genesis's
    offset, applied on the left); a root body is free where the file gives it a free joint,
    welded otherwise; fixed=True welds the base where it starts. Each body is a link (none is
    merged), its joints' parameters, its actuators' servo gains and the file's contact bit masks
    are the file's. The worldbody's geoms (a floor, obstacles) are a static link "world", the
    entity's last; exclude_ground_plane=True leaves out its planes (Genesis's option: for a scene
    that has a ground of its own, e.g. gs.morphs.Plane). scale: the bodies grown by this factor,
    as Genesis's (URDF's scale; an actuator's gains times scale³, Genesis's MJCF rule:
    solvers/rigid/scale.py). file_meshes_are_zup: taken and not read, as Genesis's MJCF loader.
    default_armature: armature (kg·m² or kg) of every hinge and slide dof whose armature the file
    leaves at 0 (a motor's rotor; the file's own armature is kept), as Genesis; None: none.
    Genesis's default: 0.1, none under RigidOptions(enable_mujoco_compatibility=True)."""
    file: str = None
    scale: float = 1.0
    exclude_ground_plane: bool = False
    file_meshes_are_zup: bool = True
    default_armature: float = GENESIS_ARMATURE

    def _check(self):
        self.file = _file_path("MJCF", self.file, xml=True)
        self.scale = _isotropic_scale("MJCF", self.scale)
        _meshes_zup("MJCF", self.file_meshes_are_zup, self.file, True)  # (checked; not read, as Genesis's loader)
        if not isinstance(self.exclude_ground_plane, (bool, np.bool_)):
            raise InvalidInputError(f"MJCF: argument 'exclude_ground_plane' must be True or False, "
                                    f"got {self.exclude_ground_plane!r}")
        self.exclude_ground_plane = bool(self.exclude_ground_plane)
        self.default_armature = _armature("MJCF", self.default_armature)


@named_keywords(*_PRIMITIVE, *_TETGEN, deprecated=_DEPRECATED)
@dataclass
class Box(Morph):
    """A box; size (3,) full extents, m. Or, as Genesis, its corners ``lower`` and ``upper``
    (3,) m, given together, which set pos (their midpoint) and size (their difference) and take
    priority over both; lower and upper are filled from pos and size otherwise."""
    size: tuple = (1.0, 1.0, 1.0)
    lower: tuple = None
    upper: tuple = None
    contype: int = 0xFFFF
    conaffinity: int = 0xFFFF

    def _check(self):
        _check_masks("Box", self)
        if (self.lower is None) != (self.upper is None):
            raise InvalidInputError(f"Box: arguments 'lower' and 'upper' must be given together, got lower="
                                    f"{self.lower!r} and upper={self.upper!r}")
        if self.lower is not None:
            lower, upper = _vec("Box", "lower", self.lower, 3), _vec("Box", "upper", self.upper, 3)
            if not np.all(upper > lower):
                raise InvalidInputError(f"Box: argument 'upper' must exceed 'lower' on every axis, got lower="
                                        f"{lower.tolist()} and upper={upper.tolist()}")
            self.pos, self.size = (lower + upper) / 2.0, upper - lower
        self.size = _vec("Box", "size", self.size, 3)
        _positive("Box", "size", self.size)
        self.lower, self.upper = self.pos - self.size / 2.0, self.pos + self.size / 2.0


@named_keywords(*_PRIMITIVE, *_TETGEN, deprecated=_DEPRECATED)
@dataclass
class Sphere(Morph):
    """A sphere of ``radius`` m."""
    radius: float = 0.5
    contype: int = 0xFFFF
    conaffinity: int = 0xFFFF

    def _check(self):
        _check_masks("Sphere", self)
        _positive("Sphere", "radius", self.radius)


@named_keywords(*_PRIMITIVE, *_TETGEN, deprecated=_DEPRECATED)
@dataclass
class Cylinder(Morph):
    """A cylinder along local z: ``radius`` and ``height`` in m."""
    radius: float = 0.5
    height: float = 1.0
    contype: int = 0xFFFF
    conaffinity: int = 0xFFFF

    def _check(self):
        _check_masks(type(self).__name__, self)
        _positive(type(self).__name__, "radius", self.radius)
        _positive(type(self).__name__, "height", self.height)


@named_keywords(*_PRIMITIVE, *_TETGEN, deprecated=_DEPRECATED)
@dataclass
class Capsule(Cylinder):
    """A capsule along local z: ``height`` is the length of the cylindrical part, m."""


@named_keywords(*_FILE, *_TETGEN, "group_by_material",
           "merge_submeshes_for_collision", deprecated=_DEPRECATED)
@dataclass
class Mesh(Morph):
    """A rigid body (or an MPM body's particles) from a mesh file (any format trimesh reads),
    scaled by ``scale``. file_meshes_are_zup, as Genesis's: True, read as it is (Z-up); False, turned
    from Y-up first, (X, Y, Z) → (X, −Z, Y); None (the default): True, but False for a glTF file
    (.glb, .gltf: Y-up by its standard)."""
    file: str = None
    scale: float = 1.0
    file_meshes_are_zup: bool = None
    contype: int = 0xFFFF
    conaffinity: int = 0xFFFF

    def _check(self):
        _check_masks("Mesh", self)
        self.file = _file_path("Mesh", self.file)
        _positive("Mesh", "scale", self.scale)
        self.file_meshes_are_zup = _meshes_zup("Mesh", self.file_meshes_are_zup, self.file, True)


@named_keywords(*_PRIMITIVE, "plane_size", "tile_size", deprecated=_DEPRECATED)
@dataclass
class Plane(Morph):
    """The ground: an infinite static half-space (always fixed) bounded by the plane through pos
    whose normal is ``normal`` (3,) in the morph's frame (euler / quat turn it), pointing out of
    the solid side: by default +z, the half-space below z = pos[2]."""
    fixed: bool = True
    normal: tuple = (0.0, 0.0, 1.0)
    contype: int = 0xFFFF
    conaffinity: int = 0xFFFF

    def _check(self):
        _check_masks("Plane", self)
        if not self.fixed:  # (Genesis's rule too)
            raise InvalidInputError("Plane: argument 'fixed' must be True (a plane is always fixed), got False")
        normal = _vec("Plane", "normal", self.normal, 3)
        if not np.linalg.norm(normal) > 1e-9:
            raise InvalidInputError(f"Plane: argument 'normal' must be a non-zero 3-vector, got {self.normal!r}")
        self.normal = normal / np.linalg.norm(normal)


@named_keywords(*_MORPH, "from_stored", "uv_scale", "batch_fixed_verts")
@dataclass
class Terrain(Morph):
    """Static ground of varying height: a height field (Genesis's Terrain, MuJoCo's hfield;
    solvers/rigid/collision/hfield.py). Its heights, in units of ``vertical_scale`` (m), at grid
    points ``horizontal_scale`` (m) apart, point (i, j) at (i·horizontal_scale, j·horizontal_scale)
    in the morph's frame (pos, euler / quat), as Genesis's: ``height_field`` (nx, ny) when given,
    else Genesis's generated subterrains (genesis_lite/utils/terrain.py): n_subterrains (x, y) of
    subterrain_size (x, y) m, each of its kind in subterrain_types (one name, or a list of
    n_subterrains[0] lists of n_subterrains[1]), with subterrain_parameters {kind: {name: value}}
    over the kinds' defaults, drawn at random (the random kinds) from a generator seeded 0 unless
    ``randomize``. Each grid cell is two triangles; the ground is solid beneath them, down to
    ``BASE`` below its lowest point (Genesis's prisms end at its lowest point: a body pressed below
    it there is in none). Always fixed. ``name``: Genesis's key of its cache of generated terrains
    (none here: a terrain is generated when its morph is made, in milliseconds). A height_field
    given with subterrain arguments away from their defaults is refused (Genesis ignores them)."""
    fixed: bool = True
    height_field: object = None
    horizontal_scale: float = 0.25
    vertical_scale: float = 0.005
    n_subterrains: tuple = (3, 3)
    subterrain_size: tuple = (12.0, 12.0)
    subterrain_types: object = (("flat_terrain", "random_uniform_terrain", "stepping_stones_terrain"),
                                ("pyramid_sloped_terrain", "discrete_obstacles_terrain", "wave_terrain"),
                                ("random_uniform_terrain", "pyramid_stairs_terrain", "sloped_terrain"))
    subterrain_parameters: dict = None
    randomize: bool = False
    name: str = None
    contype: int = 0xFFFF
    conaffinity: int = 0xFFFF

    BASE = 1.0  # m: how deep the ground is solid below its lowest point

    def _check(self):
        _check_masks("Terrain", self)
        if not self.fixed:
            raise InvalidInputError("Terrain: argument 'fixed' must be True (a terrain is always fixed), got False")
        _positive("Terrain", "horizontal_scale", self.horizontal_scale)
        _positive("Terrain", "vertical_scale", self.vertical_scale)
        self.horizontal_scale, self.vertical_scale = float(self.horizontal_scale), float(self.vertical_scale)
        if self.name is not None and not isinstance(self.name, str):
            raise InvalidInputError(f"Terrain: argument 'name' must be a string or None, got {self.name!r}")
        self.randomize = check_bool("Terrain", "randomize", self.randomize)
        if self.height_field is None:
            self.height_field = self._generated()
        else:
            self._no_subterrains()
        refuse_grad("Terrain", "height_field", self.height_field, "a terrain's heights are fixed at build")
        try:
            given = np.asarray(self.height_field.cpu() if hasattr(self.height_field, "cpu") else self.height_field)
        except (TypeError, ValueError):
            given = np.full(1, np.nan)
        # (real numbers only: numpy would take a complex one's real part, a bool as 0 or 1)
        heights = given.astype(np.float64) if given.dtype.kind in "iuf" else np.full(1, np.nan)
        if heights.ndim != 2 or min(heights.shape) < 2 or not np.all(np.isfinite(heights)):
            raise InvalidInputError(f"Terrain: argument 'height_field' must be a 2-d array of finite real heights of "
                                    f"at least 2 × 2 points, got {_described(self.height_field)}")
        self.height_field = heights

    def _generated(self):
        """The heights of Genesis's subterrains (terrain.height_field), the arguments checked."""
        counts = self.n_subterrains
        if not (isinstance(counts, (tuple, list, np.ndarray)) and len(counts) == 2
                and all(is_int(n) and n >= 1 for n in counts)):
            raise InvalidInputError(f"Terrain: argument 'n_subterrains' must be two integers >= 1, got {counts!r}")
        counts = [int(n) for n in counts]
        try:
            size = np.asarray(self.subterrain_size, dtype=np.float64)
        except (TypeError, ValueError):
            size = np.full(1, np.nan)
        cells = size / self.horizontal_scale
        if size.shape != (2,) or not np.all(np.isfinite(size)) or not np.all(np.round(cells) >= 1) \
                or np.abs(cells - np.round(cells)).max() > 1e-9 * max(cells.max(), 1.0):
            raise InvalidInputError(f"Terrain: argument 'subterrain_size' must be two positive multiples of "
                                    f"horizontal_scale = {self.horizontal_scale:g} m, got {self.subterrain_size!r}")
        return terrain.height_field(counts, size, self._kinds(counts), self._parameters(), self.horizontal_scale,
                                    self.vertical_scale, np.random.default_rng(None if self.randomize else 0))

    def _no_subterrains(self):
        """With a height_field given, the subterrain arguments left at their defaults (they would go
        unused)."""
        defaults = {f.name: f.default for f in dataclasses.fields(Terrain) if f.name in _SUBTERRAIN_ARGS}
        changed = [name for name, value in defaults.items() if not _same(getattr(self, name), value)]
        if changed:
            raise InvalidInputError(f"Terrain: arguments {changed} generate subterrains, which a given height_field "
                                    f"replaces; give one or the other")

    def _kinds(self, counts):
        """subterrain_types as n_subterrains[0] lists of n_subterrains[1] known kinds."""
        kinds = self.subterrain_types
        if isinstance(kinds, str):
            kinds = [[kinds] * counts[1] for _ in range(counts[0])]
        shaped = (isinstance(kinds, (tuple, list)) and len(kinds) == counts[0]
                  and all(isinstance(row, (tuple, list)) and len(row) == counts[1] for row in kinds))
        if not shaped:
            raise InvalidInputError(f"Terrain: argument 'subterrain_types' must be a kind's name or n_subterrains = "
                                    f"{tuple(counts)} of them (a list of lists), got {kinds!r}")
        unknown = [kind for row in kinds for kind in row if not (isinstance(kind, str) and kind in terrain.DEFAULTS)]
        if unknown:
            raise InvalidInputError(f"Terrain: argument 'subterrain_types' expected kinds among "
                                    f"{list(terrain.DEFAULTS)}, got {unknown}")
        return [list(row) for row in kinds]

    def _parameters(self):
        """Every kind's parameters: the defaults, updated by subterrain_parameters, checked."""
        parameters = {kind: dict(values) for kind, values in terrain.DEFAULTS.items()}
        given = {} if self.subterrain_parameters is None else self.subterrain_parameters
        if not isinstance(given, dict):
            raise InvalidInputError(f"Terrain: argument 'subterrain_parameters' must be a dict {{kind: {{name: "
                                    f"value}}}} or None, got {given!r}")
        for kind, values in given.items():
            if kind not in parameters or not isinstance(values, dict) or not set(values) <= set(parameters[kind]):
                raise InvalidInputError(f"Terrain: argument 'subterrain_parameters' expected, per kind among "
                                        f"{list(parameters)}, a dict of its parameters "
                                        f"{parameters.get(kind, {})}, got {kind!r}: {values!r}")
            parameters[kind].update(values)
            wrong = terrain.problem(kind, parameters[kind], self.horizontal_scale)
            if wrong:
                raise InvalidInputError(f"Terrain: argument 'subterrain_parameters': {wrong}")
        return parameters


_SUBTERRAIN_ARGS = ("n_subterrains", "subterrain_size", "subterrain_types", "subterrain_parameters", "randomize")


def _same(value, default):
    """Whether an argument equals its default (sequences compared as nested lists)."""
    try:
        return bool(np.array_equal(np.asarray(value, dtype=object), np.asarray(default, dtype=object))) \
            if isinstance(default, tuple) else value == default
    except (TypeError, ValueError):
        return False


def _described(value):
    """A short description of an array-like argument for an error message: its shape, or its repr."""
    shape = getattr(value, "shape", None)
    return f"shape {tuple(shape)}" if shape is not None else repr(value)[:80]
