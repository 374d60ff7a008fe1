"""URDF → ``list[LinkSpec]``.

yourdfpy parses the XML; everything else (tree order, frames, inertias, meshes, validation)
happens here so that every problem with a file surfaces as an ``AssetError`` that names the
file, the link or joint, what was expected and what was found. A file's links are kept in the
asset cache (solvers/asset_cache.py): a file read before, with the same meshes, is not parsed again.

Supported joints: revolute, continuous (a revolute without limits), prismatic, fixed, and a floating
joint that holds the only child of an empty root link ("world"): that child is the entity's base,
free (Genesis's free joint; the empty root is left out).
Supported collision shapes: box, sphere, cylinder, mesh (any format trimesh reads).
Visuals (``<visual>``, what cameras draw; the physics ignores them): the same shapes, with the
colour of their ``<material>``, given in place or by the name of a material defined at robot
level or in another visual. Textures, and the colours inside mesh files, are not read.
Friction: ``<dynamics friction>`` is the joint's dry friction (LinkSpec.frictionloss); URDF has
no contact friction, so the one pybullet reads, ``<link><contact><lateral_friction value>``,
becomes the friction of that link's collision shapes (GeomSpec.friction). The joint's dry
friction is a friction-loss constraint row, as in MuJoCo.
Servo gains: ``<safety_controller k_position k_velocity>`` are the joint's kp and kv, as Genesis
reads them (LinkSpec.kp, kv; the solver's defaults otherwise).
Mimic joints: ``<mimic joint multiplier offset>`` (defaults 1 and 0) makes the joint follow the
named one, q = multiplier · q_joint + offset, by a joint equality constraint row, as MuJoCo's
``<equality><joint>`` and Genesis's (LinkSpec.mimic); both joints revolute or prismatic.
Ignored: velocity limits, calibration, the safety controller's soft limits (as Genesis); pybullet's
other ``<contact>`` entries (rolling/spinning friction, restitution, stiffness, damping, cfm/erp)
are ignored with a warning.
Checked on the XML itself, where yourdfpy would fill in or drop (urdfdom and MuJoCo refuse):
an ``<inertia>`` needs all six moments and a ``<mass>`` its value; ``xyz``, ``rpy`` and a box's
``size`` hold three numbers; an element a URDF allows once in its parent appears once.
"""
import io
import logging
import os
import re

import numpy as np
from lxml import etree

from .. import asset_cache
from ..core import AssetError, InvalidInputError
from . import shapes, spec
from .spec import GeomSpec, LinkSpec, VisualSpec

_JOINT_TYPES = {"revolute": "revolute", "continuous": "revolute",
                "prismatic": "prismatic", "fixed": "fixed"}
_XML_DECLARATION = re.compile(rb"<\?xml\s[^>]*\?>")
# what the XML itself must hold (yourdfpy fills in a missing moment as 1, a missing mass as 0,
# keeps the first of two <origin>s and the first 3 of 4 numbers): element → attributes it needs;
# element → attributes of three numbers; parent → the children it may hold once
_REQUIRED = {"inertia": ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"), "mass": ("value",)}
_TRIPLES = {"origin": ("xyz", "rpy"), "axis": ("xyz",), "box": ("size",)}
_ONCE = {"link": ("inertial",), "inertial": ("origin", "mass", "inertia"),
         "joint": ("origin", "axis", "parent", "child", "limit", "dynamics", "mimic", "safety_controller",
                   "calibration"),
         "collision": ("origin", "geometry"), "visual": ("origin", "geometry", "material")}
_logger = logging.getLogger("genesis_lite")
# what a file's links are computed by, for the asset cache's keys
_SOURCES = (__file__, shapes.__file__, spec.__file__)
_PACKAGES = ("yourdfpy", "lxml", "trimesh", "scipy", "numpy")
_DEFAULT_AXIS = np.array([1.0, 0.0, 0.0])  # URDF spec default
# relative tolerance on negative principal moments, for inertias rounded to a few digits
_INERTIA_RTOL = 1e-6


def load_urdf(path: str, entity_name: str | None = None, rho: float | None = None,
              y_up: bool = False, collision: bool = True, text: str | None = None) -> list[LinkSpec]:
    """Links of the URDF file `path` in tree order (root first, parent index < child index).

    Order is depth-first from the root, children in the order their joints appear in the
    file (MuJoCo's body order). The root link gets joint_type "fixed" at the origin with
    joint_name "" (a floating root: at its joint's origin, named by it; _floating_root): the
    entity builder decides how the base is attached, and places it.
    rho: density (kg/m³) used for links without <inertial>, from their collision shapes
    (else their visual shapes); links with neither get mass 0. None: Genesis's default, per link
    (_articulated_links): shapes.ROBOT_DENSITY for a link of the articulation,
    shapes.OBJECT_DENSITY for one outside it.
    collision: False leaves every <collision> out (no collision shapes; a link without <inertial> is
    then weighed from its visuals), as Genesis's morph option.
    y_up: the mesh files are Y-up: each is turned to Z-up when read (shapes.load_mesh; Genesis's
    file_meshes_are_zup=False), before its scale, origin and mass properties.
    entity_name: only used in error messages.
    text: the document itself (Genesis's inline URDF; `path` then only names it in messages, and
    its meshes' relative paths start at the working directory).
    Raises InvalidInputError for bad arguments and AssetError for anything wrong with the
    file or the meshes it references.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise InvalidInputError(f"load_urdf: argument 'path' expected a file path, got {path!r}")
    path = os.fspath(path)
    rho = None if rho is None else float(shapes.check_positive(rho, "rho", "load_urdf"))
    ctx = _Context(path, entity_name, bool(y_up), bool(collision), inline=text is not None)
    where = os.path.abspath(path) if text is None else ctx.folder  # (what names the meshes' places)
    text = _read(ctx) if text is None else text.encode()

    def links_and_warnings():
        return (_links(ctx, text, rho), ctx.warnings), ctx.files

    # (meshes are found from its folder; a substitution's variables are part of what it says)
    inputs = [where.encode(), repr(rho).encode(), text, _environment(text), repr(bool(y_up)).encode(),
              repr(bool(collision)).encode()]
    specs, warnings = asset_cache.load_or_compute("urdf", inputs, links_and_warnings, _SOURCES, _PACKAGES)
    for message in warnings:
        _logger.warning(f"{ctx.where()}: {message}")
    return specs


def _links(ctx: "_Context", text: bytes, rho: float | None) -> list[LinkSpec]:
    """load_urdf's links, from the file's bytes `text`."""
    robot, xml = _parse(ctx, text)
    links, parent_joint, order = _tree_order(ctx, robot)
    order, parent_joint, floating = _floating_root(ctx, links, parent_joint, order)
    friction = _contact_friction(ctx, xml)
    colors = _material_colors(ctx, robot)
    index = {name: i for i, name in enumerate(order)}
    articulated = _articulated_links(order, parent_joint)
    specs = []
    for name in order:
        joint = parent_joint.get(name)
        density = rho if rho is not None else (shapes.ROBOT_DENSITY if name in articulated else shapes.OBJECT_DENSITY)
        spec = _link_spec(ctx, links[name], joint, density, colors)
        for geom in spec.geoms:
            geom.friction = friction.get(name)
        spec.parent = index[joint.parent] if joint is not None else -1
        specs.append(spec)
    if floating is not None:  # the root floats where the joint puts it in the file's frame
        specs[0].joint_name = floating.name
        specs[0].pos, specs[0].quat = _pose(ctx, floating.origin, f"joint '{floating.name}' origin")
    _check_mimics(ctx, specs)
    return specs


def _articulated_links(order, parent_joint) -> set:
    """The names of the links Genesis 1.4.5 weighs as a robot's (its is_robot flag, which picks
    the default density): links rigidly joined (by fixed joints) form a group, started by the root,
    a floating joint or a moving joint; a group is articulated when a moving joint (revolute,
    continuous, prismatic) starts it or hangs from one of its links. So an arm's base, its
    links and the gripper fixed to its flange are articulated, a free box's links are not."""
    group = {}  # link name → its group: a one-element list holding the flag (shared by the group)
    for name in order:  # (parents first)
        joint = parent_joint.get(name)
        if joint is None or joint.type == "floating":
            group[name] = [False]
        elif joint.type == "fixed":
            group[name] = group[joint.parent]
        else:
            group[name] = [True]
            group[joint.parent][0] = True
    return {name for name in order if group[name][0]}


def _floating_root(ctx: "_Context", links, parent_joint, order):
    """(order, parent_joint, the floating joint or None) of a file whose root is an empty link (no
    mass, collision or visual shapes: a "world") holding its one child on a ``floating`` joint: that
    child floats in the world (Genesis's free joint), so the empty root is left out and the child
    becomes the root, at the joint's origin (the entity's base: free unless the morph fixes it).
    Any other floating joint raises: a free joint below a body is not modelled (MuJoCo's compiler
    refuses one too)."""
    floating = [joint for joint in parent_joint.values() if joint.type == "floating"]
    if not floating:
        return order, parent_joint, None
    root, joint = links[order[0]], floating[0]
    children = [child for child, parent in parent_joint.items() if parent.parent == root.name]
    empty = (root.inertial is None or not root.inertial.mass) and not root.collisions and not root.visuals
    if len(floating) > 1 or joint.parent != root.name or len(children) != 1 or not empty:
        raise ctx.error(f"joint '{joint.name}' is floating: expected the file's one floating joint, holding the only "
                        f"child of an empty root link (no mass, collision or visual shapes), which then floats in the "
                        f"world; got {len(floating)} floating joint(s), this one on link '{joint.parent}' (root "
                        f"'{root.name}': {len(children)} child link(s), {'empty' if empty else 'not empty'})")
    return order[1:], {child: parent for child, parent in parent_joint.items() if parent is not joint}, joint


class _Context:
    """Where an error happened (the file, its folder and the entity, for messages), and whether its
    meshes are read as Y-up (load_urdf's y_up)."""

    def __init__(self, path: str, entity_name: str | None, y_up: bool = False, collision: bool = True,
                 inline: bool = False):
        self.path, self.y_up = path, y_up  # (y_up: the mesh files are Y-up, see load_urdf)
        self.collision = collision  # (False: the <collision> elements are left out, see load_urdf)
        self.folder = os.getcwd() if inline else os.path.dirname(os.path.abspath(path))  # (meshes start here)
        self.entity = entity_name
        self.files = []  # asset_cache.snapshot of the mesh files read and of the places looked at before; None:
        # a mesh file may name others (the links are not to be cached)
        self.warnings = []  # what to warn of, said after the file and entity name

    def where(self) -> str:
        """The file (and entity) name, as messages start."""
        return f"URDF '{self.path}'" + (f" (entity '{self.entity}')" if self.entity else "")

    def error(self, msg: str) -> AssetError:
        """An AssetError prefixed with the file (and entity) name."""
        return AssetError(f"{self.where()}: {msg}")


# ------------------------------------------------------------------ parsing and tree


def _read(ctx: _Context) -> bytes:
    """The file's bytes."""
    if not os.path.isfile(ctx.path):
        raise ctx.error("file not found")
    try:
        with open(ctx.path, "rb") as f:
            return f.read()
    except OSError as exc:  # a folder, no permission
        raise ctx.error(f"cannot read file: {exc.strerror or exc}") from exc


# roslaunch's substitution args, as a URDF made by xacro may keep them in attribute values
# (pybullet_data's husky.urdf: xyz="$(optenv HUSKY_IMU_XYZ 0.19 0 0.149)")
_SUBSTITUTION = re.compile(r"\$\((\w+)((?:\s+[^\s()]+)*)\s*\)")
_ENV_NAME = re.compile(rb"\$\((?:opt)?env\s+(\w+)")


def _environment(text: bytes) -> bytes:
    """The environment variables the file's $(optenv …) and $(env …) name, with their values now."""
    names = sorted(set(_ENV_NAME.findall(text)))
    return repr([(name, os.environ.get(name.decode())) for name in names]).encode()


def _substitute_env(ctx: _Context, xml) -> bool:
    """In the attribute values of the parsed file (comments aside), roslaunch's environment
    substitutions done: $(optenv NAME default…) → the variable NAME if set, else the default (the
    words after the name; none: empty), and $(env NAME) → the variable, which must be set. Any
    other $(…) (find, arg, eval: xacro's) is an AssetError saying to expand the file with xacro
    first. Returns whether anything was replaced."""
    def replace(match):
        kind, words = match.group(1), match.group(2).split()
        name = words[0] if words else ""
        if kind == "optenv" and name:
            return os.environ.get(name, " ".join(words[1:]))
        if kind == "env" and len(words) == 1:
            if name not in os.environ:
                raise ctx.error(f"$(env {name}) names an environment variable that is not set")
            return os.environ[name]
        raise ctx.error(f"{match.group(0)!r} is a xacro/roslaunch substitution genesis_lite does not expand "
                        f"(only $(optenv NAME default) and $(env NAME)); expand the file with xacro first")

    replaced = False
    for element in xml.iter():  # (a comment has no attributes)
        for key, value in element.attrib.items():
            if "$(" in value:
                element.set(key, _SUBSTITUTION.sub(replace, value))
                replaced = True
    return replaced


def _parse(ctx: _Context, text: bytes):
    """(the yourdfpy Robot of the file's bytes `text`, its lxml root element).

    The XML is checked strictly first, because yourdfpy otherwise falls back to a lenient
    parser that silently drops elements.
    """
    import yourdfpy  # (imported when first needed: it imports trimesh and scipy, ~0.6 s)

    text, xml = _strict_xml(ctx, text)
    if xml.tag != "robot":
        raise ctx.error(f"root element expected <robot>, got <{xml.tag}>")
    if _substitute_env(ctx, xml):
        text = etree.tostring(xml)
    _check_elements(ctx, xml)
    try:
        # non-finite xyz/rpy make numpy warn while composing the origin; we reject them later
        with np.errstate(invalid="ignore", over="ignore"):
            urdf = yourdfpy.URDF.load(io.BytesIO(text), build_scene_graph=False,
                                      load_meshes=False, load_collision_meshes=False)
    except Exception as exc:  # yourdfpy raises KeyError, ValueError, AttributeError...
        raise ctx.error(f"cannot parse: {type(exc).__name__}: {exc}") from exc
    return urdf.robot, xml


def _strict_xml(ctx: _Context, text: bytes):
    """(`text`, its root element) if it is well-formed XML, else the same for `text` without
    its XML declarations if that is.

    Many URDFs in the wild (most of pybullet_data's) declare version "0.0" or put the
    declaration after a comment, which strict parsers reject although the rest of the
    document is fine. The declaration is only dropped when needed since it names the encoding.
    """
    parser = etree.XMLParser(remove_blank_text=True)
    try:
        return text, etree.fromstring(text, parser)
    except Exception:  # lxml.etree.XMLSyntaxError, ValueError...
        text = _XML_DECLARATION.sub(b"", text)
    try:
        return text, etree.fromstring(text, parser)
    except Exception as exc:
        raise ctx.error(f"malformed XML: {exc}") from exc


def _check_elements(ctx: _Context, xml) -> None:
    """Raise where the XML lacks what yourdfpy would invent or holds what it would drop (_REQUIRED,
    _TRIPLES, _ONCE), naming the link or joint."""
    for element in xml.iter():
        parent = element.getparent()
        if not isinstance(element.tag, str) or parent is None:
            continue
        owner = next((a for a in element.iterancestors() if a.tag in ("link", "joint")), None)
        where = f"{owner.tag} '{owner.get('name')}'" if owner is not None else f"<{parent.tag}>"
        if parent.tag in _ONCE and element.tag in _ONCE[parent.tag] and parent.index(element) != parent.index(
                parent.find(element.tag)):
            raise ctx.error(f"{where}: <{parent.tag}> expected one <{element.tag}>, got "
                            f"{len(parent.findall(element.tag))}")
        if element.tag in _REQUIRED and parent.tag == "inertial":
            missing = [a for a in _REQUIRED[element.tag] if a not in element.attrib]
            if missing:
                raise ctx.error(f"{where} inertial <{element.tag}> expected the attributes "
                                f"{', '.join(_REQUIRED[element.tag])}, got one without {', '.join(missing)}")
        for attribute in _TRIPLES.get(element.tag, ()):
            if attribute in element.attrib and len(element.get(attribute).split()) != 3:
                raise ctx.error(f"{where}: <{element.tag} {attribute}> expected 3 numbers, got "
                                f"{element.get(attribute)!r}")


def _tree_order(ctx: _Context, robot):
    """(links by name, parent joint by child link name, link names depth-first from the root)."""
    links = {}
    for link in robot.links:
        if link.name in links:
            raise ctx.error(f"link '{link.name}' is defined twice")
        links[link.name] = link
    if not links:
        raise ctx.error("no <link> element")
    parent_joint, children, joint_names = {}, {name: [] for name in links}, set()
    for joint in robot.joints:
        if joint.name in joint_names:
            raise ctx.error(f"joint '{joint.name}' is defined twice")
        joint_names.add(joint.name)
        for role, link in (("parent", joint.parent), ("child", joint.child)):
            if link not in links:
                raise ctx.error(f"joint '{joint.name}': {role} link '{link}' is not defined")
        if joint.child in parent_joint:
            raise ctx.error(f"link '{joint.child}' is the child of two joints: "
                            f"'{parent_joint[joint.child].name}' and '{joint.name}'")
        parent_joint[joint.child] = joint
        children[joint.parent].append(joint.child)
    roots = [name for name in links if name not in parent_joint]
    if len(roots) != 1:
        raise ctx.error(f"expected exactly one root link (a link that is no joint's child), "
                        f"found {len(roots)}: {roots}")
    order, stack = [], [roots[0]]
    while stack:  # iterative: long chains (ropes) would exceed Python's recursion limit
        name = stack.pop()
        order.append(name)
        stack.extend(reversed(children[name]))
    if len(order) != len(links):
        unreachable = sorted(set(links) - set(order))
        raise ctx.error(f"links {unreachable} are not connected to the root '{roots[0]}' "
                        f"(the joints form a cycle)")
    return links, parent_joint, order


def _contact_friction(ctx: _Context, xml) -> dict:
    """Link name → ``<contact><lateral_friction value>`` (pybullet's contact friction coefficient)
    for the links that state one; yourdfpy does not read ``<contact>``, so it comes from the XML.
    The other entries of ``<contact>`` warn (once, listed)."""
    out, ignored = {}, set()
    for link in xml.iterfind("link"):
        ignored.update(child.tag for child in link.iterfind("contact/*")
                       if isinstance(child.tag, str) and child.tag != "lateral_friction")
        element = link.find("contact/lateral_friction")
        if element is None:
            continue
        what = f"link '{link.get('name')}' contact lateral_friction value"
        if element.get("value") is None:
            raise ctx.error(f"{what} expected a number >= 0, got no 'value' attribute")
        out[link.get("name")] = _number(ctx, element.get("value"), 0.0, what, 0.0)
    if ignored:
        ctx.warnings.append(f"<contact> entries {', '.join(sorted(ignored))} are not simulated (only "
                            f"lateral_friction is read)")
    return out


# ------------------------------------------------------------------ one link


def _link_spec(ctx: _Context, link, joint, rho: float, colors: dict) -> LinkSpec:
    """LinkSpec of `link` attached by `joint` (None for the root); `parent` is set by the caller.
    colors: material name → rgba (see _material_colors)."""
    geoms = [_geom(ctx, link.name, c.geometry, c.origin) for c in link.collisions] if ctx.collision else []
    visuals = [v for v in (_visual(ctx, link.name, v, colors) for v in link.visuals) if _drawable(v)]
    moving = joint is not None and joint.type != "fixed"
    mass, com, inertia, stated = _inertial(ctx, link, geoms, rho, moving)
    spec = LinkSpec(name=link.name, parent=-1, joint_name="", joint_type="fixed",
                    pos=np.zeros(3), quat=np.array([1.0, 0.0, 0.0, 0.0]),
                    axis=_DEFAULT_AXIS.copy(), mass=mass, com=com, inertia=inertia, geoms=geoms,
                    visuals=visuals, mass_stated=stated)
    if joint is not None:
        _apply_joint(ctx, spec, joint)
    return spec


def _apply_joint(ctx: _Context, spec: LinkSpec, joint) -> None:
    """Fill the joint fields of `spec` from a yourdfpy Joint."""
    if joint.type not in _JOINT_TYPES:
        raise ctx.error(f"joint '{joint.name}' has type '{joint.type}'; supported types are "
                        f"{', '.join(_JOINT_TYPES)}")
    spec.joint_name, spec.joint_type = joint.name, _JOINT_TYPES[joint.type]
    spec.pos, spec.quat = _pose(ctx, joint.origin, f"joint '{joint.name}' origin")
    spec.axis = _axis(ctx, joint)
    for tag, field in (("damping", "damping"), ("friction", "frictionloss")):
        value = getattr(joint.dynamics, tag, None)
        setattr(spec, field, _number(ctx, value, 0.0, f"joint '{joint.name}' {tag}", 0.0))
    spec.lower, spec.upper, spec.effort = _limits(ctx, joint)
    gains = joint.safety_controller
    spec.kp = _number(ctx, getattr(gains, "k_position", None), None, f"joint '{joint.name}' k_position", 0.0)
    spec.kv = _number(ctx, getattr(gains, "k_velocity", None), None, f"joint '{joint.name}' k_velocity", 0.0)
    if joint.mimic is not None and spec.joint_type == "fixed":
        ctx.warnings.append(f"joint '{joint.name}' is fixed: its <mimic> is ignored")
    elif joint.mimic is not None:
        what = f"joint '{joint.name}' mimic"
        spec.mimic = (joint.mimic.joint, _number(ctx, joint.mimic.multiplier, 1.0, f"{what} multiplier"),
                      _number(ctx, joint.mimic.offset, 0.0, f"{what} offset"))


def _check_mimics(ctx: _Context, specs: list) -> None:
    """Every mimic names another revolute or prismatic joint of the file."""
    types = {spec.joint_name: spec.joint_type for spec in specs if spec.joint_name}
    for spec in specs:
        if spec.mimic is not None:
            target = spec.mimic[0]
            if types.get(target) not in ("revolute", "prismatic") or target == spec.joint_name:
                given = ("itself" if target == spec.joint_name else f"a {types[target]} joint" if target in types
                         else "no joint of this file")
                raise ctx.error(f"joint '{spec.joint_name}' mimic expected another revolute or prismatic joint, got "
                                f"'{target}' ({given})")


def _axis(ctx: _Context, joint) -> np.ndarray:
    """Unit joint axis (3,). A fixed joint's axis is irrelevant, so a zero one is tolerated."""
    axis = np.asarray(joint.axis, dtype=np.float64)
    norm = np.linalg.norm(axis) if axis.shape == (3,) else np.nan
    if joint.type == "fixed" and not norm > 0:
        return _DEFAULT_AXIS.copy()
    if not (np.isfinite(norm) and norm > 1e-12):
        raise ctx.error(f"joint '{joint.name}' axis expected 3 finite numbers, not all zero, "
                        f"got {joint.axis}")
    return axis / norm


def _limits(ctx: _Context, joint) -> tuple[float, float, float]:
    """(lower, upper, effort). Continuous joints and missing bounds are unlimited; missing
    effort is unbounded. lower > upper also means unlimited: Bullet's convention (its own
    defaults are lower=0, upper=-1), which pybullet_data's files rely on."""
    limit, what = joint.limit, f"joint '{joint.name}' limit"
    effort = _number(ctx, getattr(limit, "effort", None), np.inf, f"{what} effort", 0.0)
    if joint.type in ("continuous", "fixed") or limit is None:
        return -np.inf, np.inf, effort
    lower = _number(ctx, limit.lower, -np.inf, f"{what} lower")
    upper = _number(ctx, limit.upper, np.inf, f"{what} upper")
    if lower > upper:
        return -np.inf, np.inf, effort
    return lower, upper, effort


def _number(ctx: _Context, value, default: float, what: str, minimum: float = -np.inf) -> float:
    """`value` (None, a number or a string from the XML) as a float; `default` when None (None
    stays None). Infinite values are only accepted as defaults."""
    if value is None:
        return None if default is None else float(default)
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ctx.error(f"{what} expected a number, got {value!r}") from None
    if not np.isfinite(x) or x < minimum:
        bound = "" if minimum == -np.inf else f" >= {minimum}"
        raise ctx.error(f"{what} expected a finite number{bound}, got {value!r}")
    return x


def _pose(ctx: _Context, origin, what: str) -> tuple[np.ndarray, np.ndarray]:
    """Position (3,) m and w-x-y-z quaternion (4,) of a yourdfpy 4x4 origin (None = identity).

    yourdfpy builds the matrix from rpy as R = Rz(yaw) Ry(pitch) Rx(roll), the URDF convention.
    """
    if origin is None:
        return np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])
    origin = np.asarray(origin, dtype=np.float64)
    if not np.all(np.isfinite(origin)):
        raise ctx.error(f"{what} expected finite xyz and rpy, got non-finite values")
    return origin[:3, 3].copy(), mat_to_quat(origin[:3, :3])


def mat_to_quat(rot: np.ndarray) -> np.ndarray:
    """Unit quaternion (4,) w-x-y-z with w >= 0 of a (3, 3) rotation matrix.

    Shepperd's method: branch on the largest of w, x, y, z so the division is well conditioned.
    """
    m = rot
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    cands = [trace, m[0, 0], m[1, 1], m[2, 2]]
    k = int(np.argmax(cands))
    if k == 0:
        s = 2.0 * np.sqrt(max(1.0 + trace, 0.0))
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    else:
        i, j, l = [(0, 1, 2), (1, 2, 0), (2, 0, 1)][k - 1]
        s = 2.0 * np.sqrt(max(1.0 + m[i, i] - m[j, j] - m[l, l], 0.0))
        q = [0.0, 0.0, 0.0, 0.0]
        q[0] = (m[l, j] - m[j, l]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (m[j, i] + m[i, j]) / s
        q[1 + l] = (m[l, i] + m[i, l]) / s
    q = np.array(q)
    q /= np.linalg.norm(q)
    return -q if q[0] < 0 else q


# ------------------------------------------------------------------ inertial


def _inertial(ctx: _Context, link, geoms: list, rho: float, moving: bool):
    """(mass kg, com (3,) m, inertia (3, 3) kg·m² about the com in link axes, whether the file
    states the mass) of a link.

    From <inertial> when present and stating a mass (inertia rotated by the inertial origin:
    R I Rᵀ); otherwise from the collision geoms, else the visual geoms (a flat or empty one holds no
    volume), as solids of density rho (Genesis too weighs a link whose <inertial> has no <mass>,
    and a ``moving`` one (on a joint that is not fixed) whose stated mass is 0 and that has shapes).
    """
    inertial = link.inertial
    if (moving and inertial is not None and inertial.mass is not None and (geoms or link.visuals)
            and _number(ctx, inertial.mass, 0.0, f"link '{link.name}' inertial mass") == 0.0):
        ctx.warnings.append(f"link '{link.name}' moves and its <inertial> states mass 0: weighed from its shapes, "
                            f"as Genesis weighs it")
        inertial = None
    if inertial is not None and inertial.mass is None:  # (an inertia scales with the mass: alone it says nothing)
        stated = inertial.origin is not None or (inertial.inertia is not None and np.any(inertial.inertia))
        if stated:
            ctx.warnings.append(f"link '{link.name}': its <inertial> states no <mass>, so its mass, centre of mass "
                                f"and inertia come from its shapes (its <origin> and <inertia> are not used)")
        inertial = None
    if inertial is None:
        if not geoms:
            geoms = [_geom(ctx, link.name, v.geometry, v.origin, visual=True) for v in link.visuals]
        mass, com, inertia = shapes.geometry_mass_properties(geoms, rho)
        return mass, com, inertia, False
    what = f"link '{link.name}' inertial"
    mass = _number(ctx, inertial.mass, 0.0, f"{what} mass")
    if mass < 0:
        raise ctx.error(f"{what} mass expected >= 0, got {mass}")
    com, quat = _pose(ctx, inertial.origin, f"{what} origin")
    inertia = np.zeros((3, 3)) if inertial.inertia is None else np.asarray(inertial.inertia, float)
    if not np.all(np.isfinite(inertia)):
        raise ctx.error(f"{what} inertia expected finite values, got {inertia.tolist()}")
    rot = shapes.quat_to_mat(quat)
    inertia = rot @ inertia @ rot.T
    inertia = 0.5 * (inertia + inertia.T)
    moments = np.linalg.eigvalsh(inertia)
    if moments[0] < -_INERTIA_RTOL * max(abs(moments[-1]), 1e-300):
        raise ctx.error(f"{what} inertia expected positive semi-definite (principal moments "
                        f">= 0), got principal moments {moments.tolist()}")
    if moments[0] + moments[1] < moments[2] * (1.0 - _INERTIA_RTOL):  # (ascending: the one that can fail)
        ctx.warnings.append(f"{what}: its principal moments {moments.tolist()} break the triangle inequality "
                            f"A + B >= C that every rigid body's satisfy (MuJoCo's compiler rejects such an "
                            f"inertia); simulated as given")
    return mass, com, inertia, True


# ------------------------------------------------------------------ geometry


def _geom(ctx: _Context, link_name: str, geometry, origin, visual=False) -> GeomSpec:
    """GeomSpec of a yourdfpy Geometry placed at `origin` in the link frame. A visual primitive
    may have zero dimensions (a flat box or disc, or a marker: laikago_toes.urdf's toes are
    spheres of radius 0); a collision shape may not (nothing to collide with)."""
    pos, quat = _pose(ctx, origin, f"link '{link_name}' geometry origin")
    where = f"link '{link_name}'"
    if geometry is None:
        raise ctx.error(f"{where}: <geometry> is missing")
    if geometry.box is not None:
        size = _sizes(ctx, geometry.box.size, 3, f"{where} box size", visual)
        return GeomSpec("box", size, pos, quat)
    if geometry.sphere is not None:
        size = _sizes(ctx, [geometry.sphere.radius], 1, f"{where} sphere radius", visual)
        return GeomSpec("sphere", size, pos, quat)
    if geometry.cylinder is not None:
        size = _sizes(ctx, [geometry.cylinder.radius, geometry.cylinder.length], 2,
                      f"{where} cylinder radius/length", visual)
        return GeomSpec("cylinder", size, pos, quat)
    if geometry.mesh is not None:
        vertices, faces = _mesh(ctx, link_name, geometry.mesh)
        return GeomSpec("mesh", np.zeros(0), pos, quat, vertices=vertices, faces=faces)
    raise ctx.error(f"{where}: <geometry> expected one of box, sphere, cylinder, mesh")


def _drawable(visual: VisualSpec) -> bool:
    """Whether a visual has a surface to draw: not a sphere or cylinder of radius 0, nor a box
    with two zero sides (a point or a segment draws nothing, in pybullet too; a flat box or disc
    is drawn)."""
    if visual.type in ("sphere", "cylinder"):
        return bool(visual.size[0] > 0)
    return visual.type != "box" or int(np.count_nonzero(visual.size == 0)) <= 1


def _visual(ctx: _Context, link_name: str, visual, colors: dict) -> VisualSpec:
    """VisualSpec of a yourdfpy Visual: its shape as _geom reads it, and its material's colour
    (None when it has none or names no known colour)."""
    geom = _geom(ctx, link_name, visual.geometry, visual.origin, visual=True)
    material = visual.material
    if material is None:
        rgba = None
    elif material.color is None:
        rgba = colors.get(material.name)
    else:
        rgba = _rgba(ctx, material.color.rgba, f"link '{link_name}' visual material color")
    return VisualSpec(geom.type, geom.size, geom.pos, geom.quat, geom.vertices, geom.faces, rgba)


def _material_colors(ctx: _Context, robot) -> dict:
    """Material name → rgba (4,) of every named material that states a colour: those defined at
    robot level, then those defined inside a visual (URDF lets any visual name them); the first
    definition of a name wins."""
    materials = list(robot.materials) + [v.material for link in robot.links for v in link.visuals]
    colors = {}
    for material in materials:
        if material is not None and material.name and material.color is not None:
            colors.setdefault(material.name, _rgba(ctx, material.color.rgba, f"material '{material.name}' color"))
    return colors


def _rgba(ctx: _Context, values, what: str) -> np.ndarray:
    """(4,) rgba in [0, 1] from a URDF ``<color rgba>``."""
    arr = np.asarray(values, dtype=np.float64)
    if arr.shape != (4,) or not np.all((arr >= 0) & (arr <= 1)):
        raise ctx.error(f"{what} expected rgba: 4 numbers in [0, 1], got {np.asarray(values).tolist()}")
    return arr


def _sizes(ctx: _Context, values, n: int, what: str, zero_allowed=False) -> np.ndarray:
    """(n,) positive (or, zero_allowed, non-negative) finite dimensions (m)."""
    try:
        arr = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        arr = np.full(0, np.nan)
    if arr.shape != (n,) or not np.all(np.isfinite(arr)) or not np.all(arr >= 0 if zero_allowed else arr > 0):
        raise ctx.error(f"{what} expected {n} {'non-negative' if zero_allowed else 'positive'} finite number(s), "
                        f"got {values}")
    return arr


def _mesh(ctx: _Context, link_name: str, mesh) -> tuple[np.ndarray, np.ndarray]:
    """Scaled vertices (V, 3) m and faces (F, 3) of a <mesh> element."""
    scale = np.atleast_1d(np.asarray(1.0 if mesh.scale is None else mesh.scale, dtype=np.float64))
    if scale.shape not in ((1,), (3,)) or not np.all(np.isfinite(scale)) or np.any(scale == 0):
        raise ctx.error(f"link '{link_name}' mesh '{mesh.filename}' scale expected 1 or 3 "
                        f"finite non-zero numbers, got {scale.tolist()}")
    found, tried = resolve_mesh_path(mesh.filename or "", ctx.folder)
    if found is None:
        raise ctx.error(f"link '{link_name}': mesh file '{mesh.filename}' not found; "
                        f"tried {tried}")
    if ctx.files is not None and found.lower().endswith(shapes.SELF_CONTAINED_MESH):
        ctx.files += [asset_cache.snapshot(candidate) for candidate in tried[:tried.index(found) + 1]]
    else:
        ctx.files = None
    try:
        return shapes.load_mesh(found, np.broadcast_to(scale, (3,)), ctx.y_up)
    except AssetError as exc:
        raise ctx.error(f"link '{link_name}': {exc}") from exc


def resolve_mesh_path(filename: str, folder: str) -> tuple[str | None, list[str]]:
    """(existing path or None, candidate paths tried) for a URDF mesh `filename`.

    Absolute paths are used as is; relative ones are relative to `folder` (the URDF's).
    `package://pkg/rest` is looked up as `pkg/rest` in `folder` and each of its parents, then as
    `rest` there (a package folder named otherwise), which finds the usual layouts
    pkg/urdf/robot.urdf + pkg/meshes/x.stl, and another package's file before a file of the same
    name in the URDF's own.
    """
    name = filename[len("file://"):] if filename.startswith("file://") else filename
    if name.startswith("package://"):
        rest = name[len("package://"):]
        tails = [rest, rest.split("/", 1)[1]] if "/" in rest else [rest]
        candidates = [os.path.join(base, tail) for tail in tails for base in _ancestors(folder)]
    elif os.path.isabs(name):
        candidates = [name]
    else:
        candidates = [os.path.join(folder, name)]
    for candidate in candidates:
        if os.path.isfile(candidate):
            return candidate, candidates
    return None, candidates


def _ancestors(folder: str) -> list[str]:
    """`folder` and its parent folders up to the filesystem root."""
    out = [folder]
    while os.path.dirname(out[-1]) != out[-1]:
        out.append(os.path.dirname(out[-1]))
    return out
