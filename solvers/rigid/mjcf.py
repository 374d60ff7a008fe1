"""MJCF (MuJoCo's XML) → ``list[LinkSpec]``: the part of the format an articulated rigid robot needs.

Read as MuJoCo's compiler reads it: ``<include>`` files inlined (several ``<default>`` and
``<worldbody>`` sections merge), ``<default>`` classes (nested, ``class`` and ``childclass``),
``<compiler angle meshdir assetdir autolimits eulerseq inertiafromgeom>``, every orientation form
(quat, axisangle, euler, xyaxes, zaxis).

Tree: ``<worldbody>`` holds one body tree (one entity). Its root body is the entity's root link:
free with a ``<freejoint>`` (or a joint of type free, its damping and armature read), welded
where it has no joint; a root body hinged or sliding on the world hangs from a static link named
"world". Each body is a link named as the body, at the body's frame (MuJoCo's and Genesis's): a
body without a joint is welded to its parent (not merged, as MuJoCo and Genesis keep it); a
body's joints (hinge → revolute, slide → prismatic) turn massless links named ``body:joint`` at
their anchors, since a LinkSpec joint turns about its link's origin, and the body's link hangs
welded from the last of them, or is that last link where its joint's anchor is the body origin
(no extra link: the usual case). Contacts take a body's links as one body (LinkSpec.same_body),
and, as MuJoCo's and Genesis's filters, a welded body as part of its parent.

Bodies: mass, com and inertia from ``<inertial>`` (diaginertia with its frame, or fullinertia),
else from the body's geoms as solids of their density (or stated mass), as MuJoCo's
``inertiafromgeom="auto"`` (a mesh: its solid, exact when closed, else its convex hull; MuJoCo's
legacy formula differs for non-convex meshes). Geoms: sphere, capsule, cylinder, box (sizes, or
``fromto``), mesh (``<mesh file scale>`` assets, in the file's own coordinates: MuJoCo's
re-centring moves the geom frame, not the surface; found in meshdir or beside the file that
included them); contype/conaffinity masks (MuJoCo's pair rule); ``<contact><exclude>``; friction
(the sliding coefficient); a geom with contype = conaffinity = 0 only weighs and is drawn; a geom
drawn where its group is 0-2 (MuJoCo's visible groups), coloured by its rgba or material.
Joints: axis, pos, range (limited: MuJoCo's autolimits), damping, armature, frictionloss,
actuatorfrcrange (|force| bound).
Actuators on a joint give its servo (as Genesis reads them): ``position`` kp, kv; ``general``
with an affine bias, kp = −biasprm[1], kv = −biasprm[2]; ``velocity`` kv; forcerange (symmetric)
the |force| bound; a ``motor`` is force control (control_dofs_force).
``<equality><joint>`` with polycoef (c0, c1) makes joint1 follow joint2, q1 = c0 + c1 q2 (LinkSpec.mimic).

Refused (AssetError naming the element): ball and further free joints, joint springs (stiffness,
ref), ellipsoid / hfield / sdf geoms, welds and connects, several bodies in ``<worldbody>``,
elements that would add or move bodies and geoms unread (``<frame>``, ``<replicate>``,
``<composite>``…). Ignored with one warning naming them: worldbody geoms (the ground is
``gs.morphs.Plane``), tendons and what acts on them, ``<contact><pair>``, ``<option>`` (the
scene's options rule), and attributes that tune MuJoCo's solver, actuator dynamics or the
compiler's mass bounds (solref, solimp, margin, condim, dampratio, timeconst, boundmass…) unless
they hold MuJoCo's defaults.
"""
import logging
import os

import numpy as np
from lxml import etree

from ..core import AssetError, InvalidInputError
from . import shapes
from .spec import GeomSpec, LinkSpec, VisualSpec
from .urdf import mat_to_quat

_logger = logging.getLogger("genesis_lite")
_IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])
_ORIENTATIONS = ("quat", "axisangle", "euler", "xyaxes", "zaxis")
_FRAME = ("pos",) + _ORIENTATIONS
_NAMES = ("name", "class", "group", "user", "rgba", "material")  # read, or harmless to the physics
# per element: the attributes read here (others are named in the warning of what is ignored)
_READ = {
    "body": _FRAME + ("name", "childclass", "user"),
    "joint": ("name", "class", "type", "pos", "axis", "range", "limited", "damping", "armature", "frictionloss",
              "actuatorfrcrange", "actuatorfrclimited", "stiffness", "ref", "group", "user"),
    "freejoint": ("name", "group", "type"),
    "geom": _FRAME + _NAMES + ("type", "size", "fromto", "mesh", "friction", "contype", "conaffinity", "density",
                               "mass"),
    "inertial": _FRAME + ("mass", "diaginertia", "fullinertia"),
}
_JOINTS = {"hinge": "revolute", "slide": "prismatic"}
# what a body (or the worldbody) may hold: read here, or nothing the physics sees
_BODY_CHILDREN = {"body", "joint", "freejoint", "geom", "inertial", "site", "camera", "light"}
# the top-level sections: read here, warned of (_note_ignored_sections), or nothing the physics sees
_SECTIONS = {"compiler", "option", "size", "visual", "statistic", "default", "custom", "extension", "asset",
             "worldbody", "contact", "equality", "tendon", "actuator", "sensor", "keyframe"}
# compiler attributes read here, or with no effect on the model read (paths, threads, frames' storage)
_COMPILER = {"angle", "coordinate", "meshdir", "assetdir", "texturedir", "autolimits", "eulerseq",
             "inertiafromgeom", "strippath", "usethread", "alignfree", "discardvisual", "fusestatic", "fitaabb",
             "saveinertial"}
_PRIMITIVES = ("sphere", "capsule", "cylinder", "box")
_ACTUATORS = ("general", "motor", "position", "velocity", "intvelocity", "damper", "cylinder", "muscle", "adhesion",
              "plugin")
_MJ_RGBA = np.array([0.5, 0.5, 0.5, 1.0])  # MuJoCo's default geom colour
# MuJoCo's defaults of attributes not read here, which genesis_lite's contacts and rows have
_MJ_DEFAULTS = {"condim": [3.0], "margin": [0.0], "gap": [0.0], "priority": [0.0], "solmix": [1.0],
                "solref": [0.02, 1.0], "solimp": [0.9, 0.95, 0.001, 0.5, 2.0]}


def load_mjcf(path: str, entity_name: str | None = None) -> list[LinkSpec]:
    """Links of the MJCF file `path` in tree order (MuJoCo's body order, parent index < child
    index). The root link's joint is "free" or "fixed" as the file says, at the root body's pose
    (in the world frame of the file). entity_name: only used in messages.
    Raises InvalidInputError for bad arguments and AssetError for anything wrong with the file."""
    if not isinstance(path, (str, os.PathLike)):
        raise InvalidInputError(f"load_mjcf: argument 'path' expected a file path, got {path!r}")
    reader = _Reader(os.fspath(path), entity_name)
    links = reader.links()
    if reader.ignored:
        _logger.warning(f"{reader.where()}: ignored (genesis_lite does not model them): "
                        + "; ".join(sorted(reader.ignored)))
    return links


class _Reader:
    """One file's reading: where errors happen, the compiler's settings, the default classes and
    the assets, and what is ignored."""

    def __init__(self, path: str, entity_name: str | None):
        self.path, self.entity = path, entity_name
        self.ignored = set()  # what the warning lists
        self.included_from = {}  # an included file's <mesh> elements → that file's folder
        root = self._inlined(path)
        if root.tag != "mujoco":
            raise self.error(f"root element expected <mujoco>, got <{root.tag}>")
        self.root = root
        unknown = [child.tag for child in root if child.tag not in _SECTIONS]
        if unknown:
            raise self.error(f"<mujoco> holds sections genesis_lite does not read: {unknown} (it reads "
                             f"{sorted(_SECTIONS)})")
        compiler = {k: v for c in root.iter("compiler") for k, v in c.attrib.items()}
        for key in compiler:
            if key not in _COMPILER:
                self.ignored.add(f"<compiler {key}>")
        self.degree = compiler.get("angle", "degree") == "degree"
        if compiler.get("coordinate", "local") != "local":
            raise self.error("<compiler coordinate> expected 'local' (MuJoCo 2.3.3 and later's only one), got "
                             f"{compiler['coordinate']!r}")
        self.autolimits = compiler.get("autolimits", "true") == "true"
        self.eulerseq = compiler.get("eulerseq", "xyz")
        if len(self.eulerseq) != 3 or any(c not in "xyzXYZ" for c in self.eulerseq):
            raise self.error(f"<compiler eulerseq> expected 3 of x, y, z, X, Y, Z, got {self.eulerseq!r}")
        self.inertiafromgeom = compiler.get("inertiafromgeom", "auto")
        folder = os.path.dirname(os.path.abspath(path))
        self.meshdir_given = compiler.get("meshdir", compiler.get("assetdir", ""))
        self.meshdir = os.path.join(folder, self.meshdir_given)
        self.defaults = {}
        for default in root.findall("default"):
            self._read_defaults(default, {}, "main")
        self.meshes, self.materials = self._assets()
        self._note_ignored_sections()

    # ---------------------------------------------------------------- file, messages

    def where(self) -> str:
        return f"MJCF '{self.path}'" + (f" (entity '{self.entity}')" if self.entity else "")

    def error(self, msg: str) -> AssetError:
        return AssetError(f"{self.where()}: {msg}")

    def _inlined(self, path: str, seen=()):
        """The root element of `path` with every ``<include file>`` replaced by the children of
        the included file's root (paths relative to the main file's folder, as MuJoCo's)."""
        if path in seen:
            raise AssetError(f"MJCF '{self.path}': <include> cycle through '{path}'")
        try:
            root = etree.parse(path, etree.XMLParser(remove_comments=True)).getroot()
        except (OSError, etree.XMLSyntaxError) as exc:
            raise AssetError(f"MJCF '{path}': not a readable XML file ({exc})") from exc
        for include in list(root.iter("include")):
            file = include.get("file")
            if not file:
                raise AssetError(f"MJCF '{path}': <include> expected a 'file' attribute")
            included = os.path.join(os.path.dirname(os.path.abspath(self.path)), file)
            child = self._inlined(included, seen + (path,))
            for mesh in child.iter("mesh"):
                self.included_from.setdefault(mesh, os.path.dirname(os.path.abspath(included)))
            parent, at = include.getparent(), include.getparent().index(include)
            parent.remove(include)
            for k, element in enumerate(child):
                parent.insert(at + k, element)
        return root

    def _note_ignored_sections(self):
        for tag in ("tendon", "option", "sensor"):
            if self.root.find(tag) is not None and len(self.root.find(tag)) + len(self.root.find(tag).attrib):
                self.ignored.add(f"<{tag}>" + (" (the scene's SimOptions and RigidOptions rule)" if tag == "option"
                                               else ""))
        for element in self.root.iter("equality"):
            for constraint in element:
                if constraint.tag != "joint":
                    raise self.error(f"<equality><{constraint.tag}> is not supported (only <joint> equalities)")

    # ---------------------------------------------------------------- defaults and attributes

    def _read_defaults(self, element, inherited: dict, name: str):
        """Class `name` from its <default> element over the `inherited` class; the top-level
        <default> sections (several, through includes) all add to the main class, as MuJoCo's."""
        if name in self.defaults and name != "main":
            raise self.error(f"<default class={name!r}> defined twice")
        own = self.defaults.get(name) or {tag: dict(attrs) for tag, attrs in inherited.items()}
        for child in element:
            if child.tag == "default":
                continue
            own.setdefault(child.tag, {}).update(child.attrib)
        self.defaults[name] = own
        for child in element.findall("default"):
            if "class" not in child.attrib:
                raise self.error("a nested <default> expected a 'class' attribute")
            self._read_defaults(child, own, child.get("class"))

    def attrs(self, element, childclass: str) -> dict:
        """The element's attributes over those of its default class (its own ``class``, else the
        enclosing body's childclass, else the main class)."""
        cls = element.get("class", childclass)
        if cls not in self.defaults and cls != "main":
            raise self.error(f"<{element.tag} name={element.get('name')!r}>: class {cls!r} is not a <default> class")
        classes = self.defaults.get(cls, {})
        out = dict(classes.get("general", {})) if element.tag in _ACTUATORS else {}
        out.update(classes.get(element.tag, {}))
        out.update(element.attrib)
        return out

    def numbers(self, attrs: dict, key: str, n: int | tuple, what: str, default=None) -> np.ndarray:
        """(n,) finite numbers of attribute `key` (n may be a tuple of allowed counts)."""
        if key not in attrs:
            if default is None:
                raise self.error(f"{what}: attribute '{key}' is missing")
            return np.asarray(default, dtype=np.float64)
        try:
            values = np.array([float(v) for v in attrs[key].split()], dtype=np.float64)
        except ValueError:
            values = np.full(0, np.nan)
        counts = n if isinstance(n, tuple) else (n,)
        if len(values) not in counts or not np.all(np.isfinite(values)):
            raise self.error(f"{what}: attribute '{key}' expected {' or '.join(map(str, counts))} finite numbers, "
                             f"got {attrs[key]!r}")
        return values

    def ignore_unread(self, element, attrs: dict):
        """Note the element's attributes not read here, but those at MuJoCo's default (which the
        simulation has: nothing is lost)."""
        for key, value in attrs.items():
            if key not in _READ[element.tag] and not _is_default(key, value):
                self.ignored.add(f"<{element.tag} {key}>")

    # ---------------------------------------------------------------- frames

    def frame(self, attrs: dict, what: str) -> tuple[np.ndarray, np.ndarray]:
        """Position (3,) m and w-x-y-z quaternion (4,) of an element's frame."""
        pos = self.numbers(attrs, "pos", 3, what, default=np.zeros(3))
        given = [k for k in _ORIENTATIONS if k in attrs]
        if len(given) > 1:
            raise self.error(f"{what}: expected at most one orientation, got {given}")
        if not given:
            return pos, _IDENTITY.copy()
        kind = given[0]
        if kind == "quat":
            q = self.numbers(attrs, "quat", 4, what)
        elif kind == "axisangle":
            v = self.numbers(attrs, "axisangle", 4, what)
            q = _axis_angle(v[:3], self._angle(v[3]))
        elif kind == "euler":
            q = _IDENTITY.copy()
            for axis_name, angle in zip(self.eulerseq, self.numbers(attrs, "euler", 3, what)):
                turn = _axis_angle(np.eye(3)["xyz".index(axis_name.lower())], self._angle(angle))
                q = _quat_mul(q, turn) if axis_name.islower() else _quat_mul(turn, q)
        elif kind == "xyaxes":
            v = self.numbers(attrs, "xyaxes", 6, what)
            x = v[:3] / _norm(self, v[:3], what)
            y = v[3:] - x * (x @ v[3:])
            y = y / _norm(self, y, what)
            q = mat_to_quat(np.stack([x, y, np.cross(x, y)], axis=1))
        else:
            z = self.numbers(attrs, "zaxis", 3, what)
            q = _quat_z_to(z / _norm(self, z, what))
        if not np.linalg.norm(q) > 1e-12:
            raise self.error(f"{what}: attribute {kind!r} expected a non-zero rotation, got {attrs[kind]!r}")
        return pos, q / np.linalg.norm(q)

    def _angle(self, value: float) -> float:
        return np.deg2rad(value) if self.degree else float(value)

    # ---------------------------------------------------------------- assets

    def _assets(self):
        meshes, materials = {}, {}
        for asset in self.root.findall("asset"):
            for mesh in asset.findall("mesh"):
                attrs = self.attrs(mesh, "main")
                if "file" not in attrs:
                    raise self.error(f"<mesh name={attrs.get('name')!r}>: only meshes from a file are supported "
                                     f"(attribute 'file' missing)")
                name = attrs.get("name", os.path.splitext(os.path.basename(attrs["file"]))[0])
                for key in attrs:
                    if key not in ("name", "class", "file", "scale", "content_type"):
                        self.ignored.add(f"<mesh {key}> (a mesh's volume and inertia are its solid's, exact for "
                                         f"a closed mesh, its convex hull's for an open one)")
                scale = self.numbers(attrs, "scale", 3, f"<mesh name={name!r}>", default=np.ones(3))
                folders = [self.meshdir] + ([os.path.join(self.included_from[mesh], self.meshdir_given),
                                             self.included_from[mesh]] if mesh in self.included_from else [])
                meshes[name] = ([os.path.join(folder, attrs["file"]) for folder in folders], scale)
            for material in asset.findall("material"):
                attrs = self.attrs(material, "main")
                if "name" in attrs and "rgba" in attrs:
                    materials[attrs["name"]] = self.numbers(attrs, "rgba", 4, f"<material name={attrs['name']!r}>")
        return meshes, materials

    def mesh(self, name: str, what: str):
        if name not in self.meshes:
            raise self.error(f"{what}: mesh {name!r} is not an <asset><mesh>")
        candidates, scale = self.meshes[name]
        found = [file for file in candidates if os.path.isfile(file)]
        if not found:  # (MuJoCo looks in meshdir, and beside the file that included the mesh)
            raise self.error(f"{what}: mesh file not found; tried {candidates}")
        file = found[0]
        try:
            return shapes.load_mesh(file, scale)
        except AssetError as exc:
            raise self.error(f"{what}: {exc}") from exc

    # ---------------------------------------------------------------- tree

    def links(self) -> list[LinkSpec]:
        worldbodies = self.root.findall("worldbody")  # (several sections, through includes, make one)
        if not worldbodies:
            raise self.error("<worldbody> is missing")
        bodies = [body for worldbody in worldbodies for body in worldbody.findall("body")]
        if len(bodies) != 1:
            raise self.error(f"<worldbody> expected one body tree (one entity), got {len(bodies)} bodies "
                             f"{[b.get('name') for b in bodies]}; load each as its own entity")
        if any(worldbody.findall("geom") for worldbody in worldbodies):
            self.ignored.add("<worldbody> geoms (add the ground as gs.morphs.Plane)")
        for worldbody in worldbodies:
            self._check_children(worldbody, "<worldbody>")
        links = []
        self._body(bodies[0], parent=-1, childclass="main", links=links)
        self._equalities(links)
        self._actuators(links)
        self._exclusions(links)
        return links

    def _body(self, body, parent: int, childclass: str, links: list):
        """Append the links of `body` and of its subtree: the body's link at its MuJoCo frame,
        after a massless link at the anchor of each joint whose anchor or place in the chain
        keeps it from being the body's (a LinkSpec joint turns about its link's origin)."""
        attrs = self.attrs(body, childclass)
        childclass = body.get("childclass", childclass)
        name = attrs.get("name") or f"body{len(links)}"
        what = f"body {name!r}"
        self.ignore_unread(body, attrs)
        self._check_children(body, what)
        pos, quat = self.frame(attrs, what)
        joints = [j for j in body if j.tag in ("joint", "freejoint")]
        if parent < 0 and (not joints or self._is_free(joints[0], childclass)):
            if len(joints) > 1:
                raise self.error(f"{what}: a free joint must be its body's only joint, got {len(joints)} joints")
            links.append(_link(name, -1, (joints[0].get("name") or name) if joints else "",
                               "free" if joints else "fixed", pos, quat))
            if joints:
                self._free_joint(joints[0], childclass, links[-1], what)
        else:
            if parent < 0:  # hinged or sliding on the world
                links.append(_link("world", -1, "", "fixed", np.zeros(3), _IDENTITY.copy()))
                parent = 0
            self._joint_chain(joints, childclass, name, what, parent, pos, quat, links)
        self._contents(body, childclass, links[-1], what)
        index = len(links) - 1
        for child in body.findall("body"):
            self._body(child, index, childclass, links)

    def _joint_chain(self, joints, childclass, name, what, parent, pos, quat, links):
        """The links of a body with `joints` (maybe none) hanging from link `parent`, at (pos, quat)
        in its frame: one a joint, at the joint's anchor (the chain's later ones in the frame the
        earlier joints turned, as MuJoCo composes them), then the body's own link welded at the body
        frame unless the last joint's anchor is the body origin."""
        anchor = np.zeros(3)
        for k, joint in enumerate(joints):
            offset = self._anchor(joint, childclass)
            last = k == len(joints) - 1 and not np.any(offset)
            spec = self._joint(joint, childclass, name if last else f"{name}:{joint.get('name') or k}", what)
            spec.parent, spec.same_body = (len(links) - 1, True) if k else (parent, False)
            spec.pos, spec.quat = (offset - anchor, _IDENTITY.copy()) if k else \
                (pos + shapes.quat_to_mat(quat) @ offset, quat)
            anchor = offset
            links.append(spec)
        if not joints:
            links.append(_link(name, parent, f"{name}_fixed", "fixed", pos, quat))
        elif np.any(anchor):
            links.append(_link(name, len(links) - 1, f"{name}_fixed", "fixed", -anchor, _IDENTITY.copy()))
            links[-1].same_body = True

    def _check_children(self, element, what: str):
        """Refuse what a body (or the worldbody) holds that is not read here and changes the model
        (<frame>, <replicate>, <composite>, …: their bodies and geoms would go missing)."""
        unknown = [child.tag for child in element if child.tag not in _BODY_CHILDREN]
        if unknown:
            raise self.error(f"{what}: {unknown} not supported (a body may hold {sorted(_BODY_CHILDREN)})")

    def _is_free(self, joint, childclass) -> bool:
        return joint.tag == "freejoint" or self.attrs(joint, childclass).get("type") == "free"

    def _free_joint(self, joint, childclass, link: LinkSpec, what: str):
        """A free root joint's damping and armature (on its six dofs, as MuJoCo's)."""
        attrs = self.attrs(joint, childclass)
        what = f"{what} joint {attrs.get('name') or link.name!r}"
        self.ignore_unread(joint, {k: v for k, v in attrs.items() if k not in ("damping", "armature")})
        link.damping, link.armature = (self._non_negative(attrs, key, what) for key in ("damping", "armature"))
        if self.numbers(attrs, "frictionloss", 1, what, default=[0.0])[0] != 0:
            self.ignored.add("<joint frictionloss> of a free joint")

    def _anchor(self, joint, childclass) -> np.ndarray:
        attrs = self.attrs(joint, childclass)
        return self.numbers(attrs, "pos", 3, f"joint {attrs.get('name')!r}", default=np.zeros(3))

    def _joint(self, joint, childclass: str, link_name: str, what: str) -> LinkSpec:
        attrs = self.attrs(joint, childclass)
        name = attrs.get("name") or link_name
        what = f"{what} joint {name!r}"
        self.ignore_unread(joint, attrs)
        kind = "free" if joint.tag == "freejoint" else attrs.get("type", "hinge")
        if kind not in _JOINTS:
            raise self.error(f"{what}: type expected hinge or slide (or free on the root body), got {kind!r}")
        for key in ("stiffness", "ref"):
            if self.numbers(attrs, key, 1, what, default=[0.0])[0] != 0.0:
                raise self.error(f"{what}: joint springs are not supported (attribute {key!r} = {attrs[key]!r})")
        axis = self.numbers(attrs, "axis", 3, what, default=[0.0, 0.0, 1.0])
        axis = axis / _norm(self, axis, what)
        spec = _link(link_name, -1, name, _JOINTS[kind], np.zeros(3), _IDENTITY.copy(), axis)
        for key in ("damping", "armature", "frictionloss"):
            setattr(spec, key, self._non_negative(attrs, key, what))
        limited = attrs.get("limited", "auto")
        if limited == "true" or (limited == "auto" and self.autolimits and "range" in attrs):
            low, high = self.numbers(attrs, "range", 2, what, default=[0.0, 0.0])
            scale = np.deg2rad(1.0) if kind == "hinge" and self.degree else 1.0
            if not low < high:
                raise self.error(f"{what}: range expected lower < upper, got {attrs.get('range')!r}")
            spec.lower, spec.upper = low * scale, high * scale
        spec.effort = self._force_bound(attrs, "actuatorfrcrange", "actuatorfrclimited", what)
        return spec

    def _non_negative(self, attrs, key, what) -> float:
        value = self.numbers(attrs, key, 1, what, default=[0.0])[0]
        if value < 0:
            raise self.error(f"{what}: attribute {key!r} expected >= 0, got {attrs[key]!r}")
        return float(value)

    def _force_bound(self, attrs, key: str, limited_key: str, what: str) -> float:
        """|force| bound (N·m or N) of a force range, inf when there is none."""
        limited = attrs.get(limited_key, "auto")
        if not (limited == "true" or (limited == "auto" and self.autolimits and key in attrs)):
            return np.inf
        low, high = self.numbers(attrs, key, 2, what, default=[0.0, 0.0])
        if low != -high or high <= 0:
            raise self.error(f"{what}: {key} expected a symmetric range (-f, f) with f > 0 (genesis_lite bounds "
                             f"|force|), got {attrs.get(key)!r}")
        return float(high)

    # ---------------------------------------------------------------- a body's contents

    def _contents(self, body, childclass: str, link: LinkSpec, what: str):
        """The body's geoms, visuals and mass properties on its link (at the body frame)."""
        solids = []
        for k, element in enumerate(body.findall("geom")):
            attrs = self.attrs(element, childclass)
            self.ignore_unread(element, attrs)
            where = f"{what} geom {attrs.get('name') or k}"
            geom, density, mass = self._geom(attrs, where)
            solids.append((geom, density, mass))
            contype, conaffinity = (int(self.numbers(attrs, key, 1, where, default=[1])[0]) for key in
                                    ("contype", "conaffinity"))
            if contype or conaffinity:
                geom.contype, geom.conaffinity = contype, conaffinity
                link.geoms.append(geom)
            if self.numbers(attrs, "group", 1, where, default=[0])[0] <= 2:
                link.visuals.append(self._visual(geom, attrs))
        inertial = body.find("inertial")
        if inertial is not None and self.inertiafromgeom != "true":
            link.mass, link.com, link.inertia = self._inertial(inertial, what)
        elif self.inertiafromgeom != "false":
            link.mass, link.com, link.inertia = _solids_mass_properties(solids)

    def _geom(self, attrs: dict, what: str):
        """(GeomSpec in the body frame, density kg/m³, stated mass kg or None) of a <geom>."""
        kind = attrs.get("type", "sphere")
        pos, quat = self.frame(attrs, what)
        size = self.numbers(attrs, "size", (1, 2, 3), what, default=np.zeros(3))
        size = np.concatenate([size, np.zeros(3 - len(size))])
        if "fromto" in attrs and kind in ("capsule", "cylinder", "box"):
            ends = self.numbers(attrs, "fromto", 6, what)
            axis = ends[3:] - ends[:3]
            size[2 if kind == "box" else 1] = np.linalg.norm(axis) / 2.0
            if kind == "box":  # (MuJoCo 4: a square section of half side size[0])
                size[1] = size[0]
            pos, quat = (ends[:3] + ends[3:]) / 2.0, _quat_z_to(axis / _norm(self, axis, what))
        if kind == "mesh":
            vertices, faces = self.mesh(attrs.get("mesh"), what)
            geom = GeomSpec("mesh", np.zeros(0), pos, quat, vertices=vertices, faces=faces)
        elif kind in _PRIMITIVES:
            n = {"sphere": 1, "capsule": 2, "cylinder": 2, "box": 3}[kind]
            if not np.all(size[:n] > 0):
                raise self.error(f"{what}: {kind} size expected {n} positive numbers, got {attrs.get('size')!r}")
            full = {"sphere": size[:1], "capsule": size[:2] * [1, 2], "cylinder": size[:2] * [1, 2],
                    "box": size * 2}[kind]
            geom = GeomSpec(kind, full, pos, quat)
        else:
            raise self.error(f"{what}: geom type expected one of {_PRIMITIVES + ('mesh',)}, got {kind!r}")
        friction = self.numbers(attrs, "friction", (1, 2, 3), what, default=[1.0])
        geom.friction = float(friction[0])
        density = self.numbers(attrs, "density", 1, what, default=[1000.0])[0]
        mass = self.numbers(attrs, "mass", 1, what)[0] if "mass" in attrs else None
        return geom, density, mass

    def _visual(self, geom: GeomSpec, attrs: dict) -> VisualSpec:
        rgba = None
        if "rgba" in attrs:
            rgba = self.numbers(attrs, "rgba", 4, "geom")
        elif attrs.get("material") in self.materials:
            rgba = self.materials[attrs["material"]]
        return VisualSpec(geom.type, geom.size, geom.pos, geom.quat, geom.vertices, geom.faces,
                          rgba if rgba is None or not np.array_equal(rgba, _MJ_RGBA) else None)

    def _inertial(self, inertial, what: str):
        attrs = dict(inertial.attrib)
        what = f"{what} <inertial>"
        self.ignore_unread(inertial, attrs)
        com, quat = self.frame(attrs, what)
        mass = self._non_negative(attrs, "mass", what) if "mass" in attrs else self.numbers(attrs, "mass", 1, what)
        if "fullinertia" in attrs:
            if any(key in attrs for key in _ORIENTATIONS):  # (MuJoCo's schema: the matrix has its axes)
                raise self.error(f"{what}: fullinertia expected without an orientation, got "
                                 f"{[key for key in _ORIENTATIONS if key in attrs]}")
            xx, yy, zz, xy, xz, yz = self.numbers(attrs, "fullinertia", 6, what)
            inertia = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
        else:
            inertia = np.diag(self.numbers(attrs, "diaginertia", 3, what, default=np.zeros(3)))
        rot = shapes.quat_to_mat(quat)
        inertia = rot @ inertia @ rot.T
        if np.linalg.eigvalsh(0.5 * (inertia + inertia.T))[0] < -1e-6 * max(abs(inertia).max(), 1e-300):
            raise self.error(f"{what}: inertia expected positive semi-definite, got {inertia.tolist()}")
        return float(mass), com, 0.5 * (inertia + inertia.T)

    # ---------------------------------------------------------------- equalities and actuators

    def _equalities(self, links: list[LinkSpec]):
        by_joint = {link.joint_name: link for link in links if link.joint_type in ("revolute", "prismatic")}
        for equality in self.root.iter("equality"):
            for element in equality:
                attrs = self.attrs(element, "main")
                what = f"<equality><joint joint1={attrs.get('joint1')!r}>"
                for key in ("joint1", "joint2"):
                    if attrs.get(key) not in by_joint:
                        raise self.error(f"{what}: {key} expected a hinge or slide joint of the file, "
                                         f"got {attrs.get(key)!r}")
                coef = self.numbers(attrs, "polycoef", 5, what, default=[0, 1, 0, 0, 0])
                if np.any(coef[2:] != 0):
                    raise self.error(f"{what}: polycoef expected a linear map (its last three 0), got {coef.tolist()}")
                for key in ("solref", "solimp"):
                    if key in attrs:
                        self.ignored.add(f"<equality><joint {key}> (the scene's constraint time constant rules)")
                by_joint[attrs["joint1"]].mimic = (attrs["joint2"], float(coef[1]), float(coef[0]))

    def _exclusions(self, links: list[LinkSpec]):
        """<contact><exclude body1 body2>: the two bodies' shapes never collide; <contact><pair>
        (pairs with their own parameters) is not read (said in the warning)."""
        by_body = {link.name: link for link in links}
        for section in self.root.iter("contact"):
            for element in section:
                if element.tag != "exclude":
                    self.ignored.add(f"<contact><{element.tag}>")
                    continue
                names = [element.get(key) for key in ("body1", "body2")]
                for name in names:
                    if name not in by_body:
                        raise self.error(f"<contact><exclude body1={names[0]!r} body2={names[1]!r}>: expected bodies "
                                         f"of the file, got {name!r}")
                by_body[names[0]].excluded += (names[1],)

    def _actuators(self, links: list[LinkSpec]):
        by_joint = {link.joint_name: link for link in links}
        for section in self.root.iter("actuator"):
            for element in section:
                attrs = self.attrs(element, "main")
                named = f"name={attrs['name']!r}" if attrs.get("name") else \
                    " ".join(f"{k}={attrs[k]!r}" for k in ("joint", "tendon", "site", "body") if k in attrs)
                what = f"<actuator><{element.tag} {named}>"
                link = by_joint.get(attrs.get("joint"))
                if link is None or link.joint_type not in ("revolute", "prismatic"):
                    self.ignored.add(f"{what} (it drives no hinge or slide joint)")
                    continue
                self._servo(element.tag, attrs, link, what)

    def _servo(self, kind: str, attrs: dict, link: LinkSpec, what: str):
        """The joint's servo gains and force bound from an actuator (Genesis's reading)."""
        for key in ("dampratio", "timeconst", "dyntype", "dynprm", "gaintype", "inheritrange"):
            if key in attrs and not (key == "dyntype" and attrs[key] == "none") \
                    and not (key == "gaintype" and attrs[key] == "fixed"):
                self.ignored.add(f"<actuator {key}> (servos act at once, kv as given)")
        if kind == "position":
            link.kp = self.numbers(attrs, "kp", 1, what, default=[1.0])[0]
            link.kv = self.numbers(attrs, "kv", 1, what, default=[0.0])[0]
        elif kind == "velocity":
            link.kv = self.numbers(attrs, "kv", 1, what, default=[1.0])[0]
        elif kind == "general" and attrs.get("biastype", "none") == "affine":
            gain = self.numbers(attrs, "gainprm", tuple(range(1, 11)), what, default=[1.0])
            bias = np.concatenate([self.numbers(attrs, "biasprm", tuple(range(1, 11)), what, default=[0.0]),
                                   np.zeros(3)])
            link.kp, link.kv = -bias[1], -bias[2]
            if bias[0] != 0 or gain[0] != -bias[1]:
                self.ignored.add(f"{what}: gain {gain[0]} and bias {bias[:3].tolist()} (a servo here pulls to its "
                                 f"target with kp = -biasprm[1] = {-bias[1]}, the target in joint units)")
        elif kind == "general" and np.any(self.numbers(attrs, "gainprm", tuple(range(1, 11)), what,
                                                       default=[1.0])[:1] != 1):
            self.ignored.add(f"{what}: gainprm (a motor's force is the joint force given)")
        elif kind != "motor" and kind != "general":
            self.ignored.add(f"{what} (type {kind})")
            return
        if "gear" in attrs and np.any(self.numbers(attrs, "gear", (1, 6), what)[:1] != 1):
            self.ignored.add("<actuator gear> (controls are the joints' forces and positions)")
        bound = self._force_bound(attrs, "forcerange", "forcelimited", what)
        link.effort = min(link.effort, bound)
        for key in ("ctrlrange", "ctrllimited"):
            if key in attrs:
                self.ignored.add(f"<actuator {key}>")


def place_world(links: list[LinkSpec], pos, quat) -> None:
    """Place the file's world frame at `pos` (3,) m, `quat` (4,) w-x-y-z: the root link's pose
    becomes (pos, quat) ∘ its pose in the file."""
    root = links[0]
    root.pos = np.asarray(pos, dtype=np.float64) + shapes.quat_to_mat(quat) @ root.pos
    root.quat = _quat_mul(np.asarray(quat, dtype=np.float64), root.quat)


# -------------------------------------------------------------------- helpers


def _link(name, parent, joint_name, joint_type, pos, quat, axis=(0.0, 0.0, 1.0)) -> LinkSpec:
    return LinkSpec(name=name, parent=parent, joint_name=joint_name, joint_type=joint_type,
                    pos=np.asarray(pos, dtype=np.float64), quat=np.asarray(quat, dtype=np.float64),
                    axis=np.asarray(axis, dtype=np.float64), mass=0.0, com=np.zeros(3), inertia=np.zeros((3, 3)))


def _solids_mass_properties(solids) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass, com and inertia about the com (body frame) of [(GeomSpec, density, stated mass or
    None)]: each geom a solid of its density, or scaled to its stated mass (MuJoCo's rule)."""
    parts = []
    for geom, density, mass in solids:
        own_mass, com, inertia = shapes.geom_mass_properties(geom, density)
        if mass is not None:
            inertia = inertia * (mass / own_mass) if own_mass > 0 else np.zeros((3, 3))
            own_mass = mass
        rot = shapes.quat_to_mat(geom.quat)
        parts.append((own_mass, geom.pos + rot @ com, rot @ inertia @ rot.T))
    total = sum(m for m, _, _ in parts)
    if total <= 0:
        return 0.0, np.zeros(3), np.zeros((3, 3))
    com = sum(m * c for m, c, _ in parts) / total
    inertia = sum(i + m * ((c - com) @ (c - com) * np.eye(3) - np.outer(c - com, c - com)) for m, c, i in parts)
    return float(total), com, inertia


def _is_default(key: str, value: str) -> bool:
    """Whether attribute `key` holds MuJoCo's default (_MJ_DEFAULTS)."""
    try:
        return key in _MJ_DEFAULTS and [float(v) for v in value.split()] == _MJ_DEFAULTS[key]
    except ValueError:
        return False


def _norm(reader: _Reader, v: np.ndarray, what: str) -> float:
    n = float(np.linalg.norm(v))
    if not n > 1e-12:
        raise reader.error(f"{what}: expected a non-zero vector, got {v.tolist()}")
    return n


def _axis_angle(axis, angle: float) -> np.ndarray:
    axis = np.asarray(axis, dtype=np.float64)
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis / np.linalg.norm(axis)])


def _quat_mul(a, b) -> np.ndarray:
    return np.concatenate([[a[0] * b[0] - a[1:] @ b[1:]], a[0] * b[1:] + b[0] * a[1:] + np.cross(a[1:], b[1:])])


def _quat_z_to(z: np.ndarray) -> np.ndarray:
    """The smallest turn taking +z onto the unit vector z (MuJoCo's mju_quatZ2Vec)."""
    w = 1.0 + z[2]
    if w < 1e-14:
        return np.array([0.0, 1.0, 0.0, 0.0])
    q = np.array([w, -z[1], z[0], 0.0])
    return q / np.linalg.norm(q)
