"""An MJCF file as MuJoCo's compiler reads it before its bodies (mjcf.py builds the links).

``<include>`` files inlined, the top-level sections checked, the compiler's settings, the
``<default>`` classes (several top-level sections make the main class), an element's attributes
over its class, numbers and frames (every orientation form) read with named errors, the mesh
and material assets, and the record of what is ignored (said in one warning).
"""
import math
import os
from copy import deepcopy as copy_element

import numpy as np
from lxml import etree

from ..core import AssetError
from . import shapes
from .collision import hfield

IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])
ORIENTATIONS = ("quat", "axisangle", "euler", "xyaxes", "zaxis")
# the top-level sections: read here, warned of (_note_ignored_sections), or nothing the physics sees
_SECTIONS = {"compiler", "option", "size", "visual", "statistic", "default", "custom", "extension", "asset",
             "worldbody", "contact", "equality", "tendon", "actuator", "sensor", "keyframe"}
# compiler attributes read here, or with no effect on the model read (paths, threads, frames' storage)
_COMPILER = {"angle", "coordinate", "meshdir", "assetdir", "texturedir", "autolimits", "eulerseq",
             "inertiafromgeom", "settotalmass", "strippath", "usethread", "discardvisual", "fusestatic", "fitaabb",
             "saveinertial", "balanceinertia"}
# a mesh's reference frame, which MuJoCo's compiler moves its geoms by, at the identity
MESH_REFERENCE = {"refpos": np.zeros(3), "refquat": np.array([1.0, 0.0, 0.0, 0.0])}
ACTUATORS = ("general", "motor", "position", "velocity", "intvelocity", "damper", "cylinder", "muscle", "adhesion",
             "plugin")
# MuJoCo's defaults of solver attributes: where one is not read, genesis_lite's rows have it
MJ_DEFAULTS = {"condim": [3.0], "margin": [0.0], "gap": [0.0], "priority": [0.0], "solmix": [1.0],
               "solref": [0.02, 1.0], "solimp": [0.9, 0.95, 0.001, 0.5, 2.0]}

# the attributes of <equality>, <actuator> and <contact> elements that name a body, joint, site or
# geom: the kind each is resolved against (a <replicate>'s copies are named per kind)
_REFERS = {"body1": "body", "body2": "body", "body": "body", "site1": "site", "site2": "site", "site": "site",
           "refsite": "site", "joint1": "joint", "joint2": "joint", "joint": "joint", "jointinparent": "joint",
           "geom1": "geom", "geom2": "geom"}
# array attributes MuJoCo reads in part, the rest left as its default class has them (for an
# actuator, the <general> class's)
_PARTIAL = ("friction", "solref", "solimp", "solreflimit", "solimplimit", "solreffriction", "solimpfriction",
            "gainprm", "biasprm")


class MJCFDocument:
    """One file's reading: where errors happen, the compiler's settings, the default classes and
    the assets, and what is ignored."""

    def __init__(self, path: str, entity_name: str | None, text: str | None = None):
        """path: the file's, or with ``text`` (the document itself, Genesis's inline MJCF) what messages
        call it; its relative paths (includes, meshes) then start at the working directory."""
        self.path, self.entity = path, entity_name
        self.folder = os.getcwd() if text is not None else os.path.dirname(os.path.abspath(path))
        self.ignored = set()  # what the warning lists
        self.included_from = {}  # an included file's <mesh> elements → that file's folder
        root = self._inlined(path, text=text)
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
        self.balanceinertia = compiler.get("balanceinertia", "false") == "true"
        self.settotalmass = float(self.numbers(compiler, "settotalmass", 1, "<compiler>", default=[-1.0])[0])
        for replicate in reversed(list(root.iter("replicate"))):  # (the innermost first: its suffix comes first)
            self._replicate(replicate)
        self.meshdir_given = compiler.get("meshdir", compiler.get("assetdir", ""))
        self.meshdir = os.path.join(self.folder, self.meshdir_given)
        self.defaults = {}
        for default in root.findall("default"):
            self._read_defaults(default, {}, "main")
        self.meshes, self.materials = self._assets()
        self.hfields = self._hfields()
        self._note_ignored_sections()

    # ---------------------------------------------------------------- file, messages

    def where(self) -> str:
        return f"MJCF '{self.path}'" + (f" (entity '{self.entity}')" if self.entity else "")

    def error(self, msg: str) -> AssetError:
        return AssetError(f"{self.where()}: {msg}")

    def _inlined(self, path: str, seen=(), text=None):
        """The root element of `path` (or of the document ``text``) with every ``<include file>``
        replaced by the children of the included file's root (paths relative to the main file's
        folder, else to the including file's, as MuJoCo takes them)."""
        if path in seen:
            raise AssetError(f"MJCF '{self.path}': <include> cycle through '{path}'")
        parser = etree.XMLParser(remove_comments=True, huge_tree=True)  # (a chain of bodies nests past 256)
        try:
            root = etree.parse(path, parser).getroot() if text is None else etree.fromstring(text.encode(), parser)
        except (OSError, etree.XMLSyntaxError) as exc:
            raise AssetError(f"MJCF '{path}': not a readable XML file ({exc})") from exc
        for include in list(root.iter("include")):
            file = include.get("file")
            if not file:
                raise AssetError(f"MJCF '{path}': <include> expected a 'file' attribute")
            included = os.path.join(self.folder, file)
            if not os.path.isfile(included) and text is None:  # (MuJoCo also takes one relative to the including file)
                included = os.path.join(os.path.dirname(os.path.abspath(path)), file)
            child = self._inlined(included, seen + (path,))
            for mesh in child.iter("mesh"):
                self.included_from.setdefault(mesh, os.path.dirname(os.path.abspath(included)))
            parent, at = include.getparent(), include.getparent().index(include)
            parent.remove(include)
            for k, element in enumerate(child):
                parent.insert(at + k, element)
        return root

    def _replicate(self, replicate):
        """A <replicate count offset euler sep childclass> as ``count`` <frame>s (with its childclass)
        holding copies of its children, as MuJoCo's reader attaches them: copy i turned by the
        orientation of i·euler (the compiler's angle unit and eulerseq), placed at the sum of the
        offsets each turned by the copies before it, every name in it suffixed by sep then i in as
        many digits as count has; then the elements that name something inside (_replicate_refs)."""
        what = "<replicate>"
        unknown = sorted(set(replicate.attrib) - {"count", "offset", "euler", "sep", "childclass"})
        if unknown:
            raise self.error(f"{what}: attributes expected among count, offset, euler, sep, childclass, got {unknown}")
        count = replicate.get("count", "")
        if not count.strip().isdigit() or int(count) < 1:
            raise self.error(f"{what}: attribute 'count' expected a positive integer, got {count!r}")
        count = int(count)
        offset = self.numbers(replicate.attrib, "offset", 3, what, default=np.zeros(3))
        euler = self.numbers(replicate.attrib, "euler", 3, what, default=np.zeros(3))
        suffixes = [replicate.get("sep", "") + str(i).zfill(len(str(count))) for i in range(count)]
        parent, at, pos = replicate.getparent(), replicate.getparent().index(replicate), np.zeros(3)
        parent.remove(replicate)
        for i, suffix in enumerate(suffixes):
            _, quat = self.frame({"euler": " ".join(repr(float(i * a)) for a in euler)}, what)
            frame = etree.Element("frame", pos=" ".join(map(repr, pos.tolist())), quat=" ".join(map(repr, quat.tolist())))
            if "childclass" in replicate.attrib:
                frame.set("childclass", replicate.get("childclass"))
            for child in replicate:
                copy = copy_element(child)
                for element in (e for e in copy.iter() if "name" in e.attrib):
                    element.set("name", element.get("name") + suffix)
                frame.append(copy)
            parent.insert(at + i, frame)
            pos = pos + shapes.quat_to_mat(quat) @ offset  # (MuJoCo's frameaccum)
        self._replicate_refs(replicate, suffixes)

    def _replicate_refs(self, replicate, suffixes: list):
        """Copy per replica (``suffixes``) each <equality>, <actuator> and <contact> element that
        names a body, joint, site or geom inside ``replicate`` (each name against its own kind, as
        MuJoCo resolves them), those names and its own suffixed alike (MuJoCo's self-attach). An
        equality or actuator naming things both inside and outside (but the world) is refused:
        MuJoCo drops it from the copies without a word. An exclusion's names outside stay as they
        are (MuJoCo's)."""
        inside = {kind: set() for kind in ("body", "joint", "site", "geom")}
        for element in replicate.iter():
            kind = "joint" if element.tag == "freejoint" else element.tag
            if kind in inside and element.get("name"):
                inside[kind].add(element.get("name"))
        for section in (s for s in self.root if s.tag in ("equality", "actuator", "contact")):
            for element in list(section):
                refs = {key: _REFERS[key] for key in element.attrib if key in _REFERS}
                ours = [key for key, kind in refs.items() if element.get(key) in inside[kind]]
                if not ours:
                    continue
                others = [key for key in refs if key not in ours and element.get(key) != "world"]
                if others and section.tag != "contact":
                    raise self.error(f"<{section.tag}><{element.tag} name={element.get('name')!r}>: names "
                                     f"{[element.get(k) for k in ours]} inside a <replicate> and "
                                     f"{[element.get(k) for k in others]} outside it (MuJoCo leaves such an "
                                     f"element out without a word); expected all inside, or the world")
                at = section.index(element)
                section.remove(element)
                for i, suffix in enumerate(suffixes):
                    copy = copy_element(element)
                    for key in ours + (["name"] if "name" in copy.attrib else []):
                        copy.set(key, copy.get(key) + suffix)
                    section.insert(at + i, copy)

    def _note_ignored_sections(self):
        """Note the sections that act on the model and are not read; refuse equalities other
        than joints', connects and welds."""
        for tag in ("option", "sensor", "keyframe"):
            if self.root.find(tag) is not None and len(self.root.find(tag)) + len(self.root.find(tag).attrib):
                self.ignored.add(f"<{tag}>" + (" (the scene's SimOptions and RigidOptions rule)" if tag == "option"
                                               else ""))
        for element in self.root.iter("equality"):
            for constraint in element:
                if constraint.tag not in ("joint", "connect", "weld", "tendon"):
                    raise self.error(f"<equality><{constraint.tag}> is not supported (only <joint>, <connect>, "
                                     f"<weld> and <tendon> equalities)")

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
            own[child.tag] = over(own.get(child.tag, {}), child.attrib)
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
        out = dict(classes.get("general", {})) if element.tag in ACTUATORS else {}
        tag = "tendon" if element.getparent() is not None and element.getparent().tag == "tendon" else element.tag
        return over(over(out, classes.get(tag, {})), element.attrib)

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

    # ---------------------------------------------------------------- frames

    def frame(self, attrs: dict, what: str) -> tuple[np.ndarray, np.ndarray]:
        """Position (3,) m and w-x-y-z quaternion (4,) of an element's frame."""
        pos = self.numbers(attrs, "pos", 3, what, default=np.zeros(3))
        given = [k for k in ORIENTATIONS if k in attrs]
        if len(given) > 1:
            raise self.error(f"{what}: expected at most one orientation, got {given}")
        if not given:
            return pos, IDENTITY.copy()
        kind = given[0]
        if kind == "quat":
            q = self.numbers(attrs, "quat", 4, what)
        elif kind == "axisangle":
            v = self.numbers(attrs, "axisangle", 4, what)
            q = axis_angle(v[:3], self._angle(v[3]))
        elif kind == "euler":
            q = IDENTITY.copy()
            for axis_name, angle in zip(self.eulerseq, self.numbers(attrs, "euler", 3, what)):
                turn = axis_angle(np.eye(3)["xyz".index(axis_name.lower())], self._angle(angle))
                q = shapes.quat_mul(q, turn) if axis_name.islower() else shapes.quat_mul(turn, q)
                q = shapes.normalized(q)[0]
        elif kind == "xyaxes":
            v = self.numbers(attrs, "xyaxes", 6, what)
            norm(self, v[:3], what)
            x = shapes.normalized(v[:3])[0]
            y = v[3:] - x * (x[0] * v[3] + x[1] * v[4] + x[2] * v[5])
            norm(self, y, what)
            y = shapes.normalized(y)[0]
            z = shapes.normalized([x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]])[0]
            q = shapes.frame_quat(x, y, z)
        else:
            z = self.numbers(attrs, "zaxis", 3, what)
            norm(self, z, what)
            q = shapes.quat_z_to(z)
        if not np.linalg.norm(q) > 1e-12:
            raise self.error(f"{what}: attribute {kind!r} expected a non-zero rotation, got {attrs[kind]!r}")
        return pos, shapes.normalized(q)[0]

    def _angle(self, value: float) -> float:
        """An angle attribute in rad (degrees converted as MuJoCo's compiler rounds them: / 180 π)."""
        return float(value) / 180.0 * np.pi if self.degree else float(value)

    # ---------------------------------------------------------------- assets

    def _assets(self):
        """({mesh name: (source, scale (3,))}, {material name: rgba (4,)}); a mesh's source: its
        candidate files, or (vertices (V, 3), faces (F, 3)) given in the file (``vertex``, ``face``;
        without faces, the vertices' convex hull, as MuJoCo's compiler takes it)."""
        meshes, materials, material_names = {}, {}, set()
        for asset in self.root.findall("asset"):
            for mesh in asset.findall("mesh"):
                attrs = self.attrs(mesh, "main")
                if "file" not in attrs and "vertex" not in attrs:
                    raise self.error(f"<mesh name={attrs.get('name')!r}>: expected a mesh from a file or from its "
                                     f"vertices (attribute 'file' or 'vertex'), got neither"
                                     + (" (builtin meshes are not supported yet)" if "builtin" in attrs else ""))
                if "file" not in attrs and "name" not in attrs:  # (MuJoCo's compiler refuses it too)
                    raise self.error("<mesh vertex=...>: a mesh without a file expected a name, got none")
                name = attrs.get("name") or os.path.splitext(os.path.basename(attrs["file"]))[0]
                what = f"<mesh name={name!r}>"
                if name in meshes:  # (MuJoCo refuses it too; the later one replaced the first)
                    raise self.error(f"{what}: mesh names expected unique, got {name!r} twice")
                moved = sorted(key for key, identity in MESH_REFERENCE.items() if key in attrs
                               and np.any(self.numbers(attrs, key, len(identity), what) != identity))
                if moved:  # (MuJoCo moves the geoms using the mesh by them: unread, each would stand elsewhere)
                    raise self.error(f"{what}: attributes {moved} are not supported yet, got "
                                     f"{[attrs[key] for key in moved]}; move the mesh's vertices instead")
                for key in attrs:
                    if key not in ("name", "class", "file", "scale", "content_type", "vertex", "face", *MESH_REFERENCE):
                        self.ignored.add(f"<mesh {key}> (a mesh's volume and inertia are its solid's, exact for "
                                         f"a closed mesh, its convex hull's for an open one)")
                scale = self.numbers(attrs, "scale", 3, what, default=np.ones(3))
                if "file" in attrs:
                    folders = [self.meshdir] + ([os.path.join(self.included_from[mesh], self.meshdir_given),
                                                 self.included_from[mesh]] if mesh in self.included_from else [])
                    meshes[name] = ([os.path.join(folder, attrs["file"]) for folder in folders], scale)
                else:
                    meshes[name] = (self._given_mesh(attrs, what), scale)
            for material in asset.findall("material"):
                attrs = self.attrs(material, "main")
                if "name" in attrs and attrs["name"] in material_names:  # (MuJoCo refuses it too)
                    raise self.error(f"<material name={attrs['name']!r}>: material names expected unique, got "
                                     f"{attrs['name']!r} twice")
                material_names.add(attrs.get("name"))
                if "name" in attrs and "rgba" in attrs:
                    materials[attrs["name"]] = self.numbers(attrs, "rgba", 4, f"<material name={attrs['name']!r}>")
        return meshes, materials

    def _hfields(self):
        """{name: (size (4,) m, elevation (nrow, ncol) normalised)} of the ``<asset><hfield>``s given
        by nrow, ncol, size and (optional, else flat) elevation, as MuJoCo 4's compiler reads them
        (its rows from the far edge, y = +size y, then hfield.normalised); one from a file (PNG or
        MuJoCo's binary) is not read yet."""
        hfields = {}
        for asset in self.root.findall("asset"):
            for element in asset.findall("hfield"):
                attrs = self.attrs(element, "main")
                what = f"<hfield name={attrs.get('name')!r}>"
                if "file" in attrs:
                    raise self.error(f"{what}: a height field from a file is not supported yet; give nrow, ncol and "
                                     f"elevation")
                if "name" not in attrs:
                    raise self.error(f"{what}: expected a name, got none")
                if attrs["name"] in hfields:  # (MuJoCo refuses it too)
                    raise self.error(f"{what}: height field names expected unique, got {attrs['name']!r} twice")
                nrow, ncol = (self._grid_count(attrs, key, what) for key in ("nrow", "ncol"))
                size = self.numbers(attrs, "size", 4, what)
                if not np.all(size > 0):  # (MuJoCo's compiler refuses it too)
                    raise self.error(f"{what}: attribute 'size' expected 4 positive numbers, got {attrs['size']!r}")
                elevation = (self.numbers(attrs, "elevation", nrow * ncol, what) if "elevation" in attrs
                             else np.zeros(nrow * ncol))
                try:
                    # (the file's first row is the grid's last, at y = +size y: MuJoCo 4's compiler flips them)
                    grid = np.reshape(elevation, (nrow, ncol))[::-1]
                    hfields[attrs["name"]] = (size, hfield.normalised(grid, what))
                except AssetError as exc:
                    raise self.error(str(exc)) from exc
        return hfields

    def _grid_count(self, attrs: dict, key: str, what: str) -> int:
        """A height field's ``nrow`` or ``ncol``: an integer ≥ 2 (MuJoCo refuses other numbers)."""
        text = attrs.get(key, "").strip()
        if not (text.lstrip("+").isdigit() and int(text) >= 2):
            raise self.error(f"{what}: attribute {key!r} expected an integer >= 2, got {attrs.get(key)!r}")
        return int(text)

    def hfield(self, name: str, what: str):
        """(size (4,) m, normalised elevation (nrow, ncol)) of the height field asset ``name``."""
        if name not in self.hfields:
            raise self.error(f"{what}: height field {name!r} is not an <asset><hfield>")
        return self.hfields[name]

    def _given_mesh(self, attrs: dict, what: str):
        """(vertices (V, 3), faces (F, 3)) of a mesh given by its ``vertex`` and ``face`` attributes."""
        vertices = self.numbers(attrs, "vertex", len(attrs["vertex"].split()), what)
        if len(vertices) % 3 or len(vertices) < 12:
            raise self.error(f"{what}: attribute 'vertex' expected at least four vertices of three numbers, "
                             f"got {len(vertices)} numbers")
        vertices = vertices.reshape(-1, 3)
        if "face" not in attrs:
            try:
                return shapes.hull_mesh(vertices)
            except AssetError as exc:
                raise self.error(f"{what}: {exc}") from exc
        words = attrs["face"].split()
        faces = np.array([int(word) if word.lstrip("-").isdigit() else -1 for word in words], dtype=np.int64)
        if len(faces) % 3 or not len(faces) or np.any(faces < 0) or np.any(faces >= len(vertices)):
            raise self.error(f"{what}: attribute 'face' expected triangles of vertex indices in [0, "
                             f"{len(vertices)}), got {attrs['face']!r}")
        faces = faces.reshape(-1, 3)
        if not abs(shapes.enclosed_volume(vertices, faces)) > 1e-9 * np.ptp(vertices, axis=0).max() ** 3:
            raise self.error(f"{what}: its faces enclose no volume (MuJoCo's compiler refuses it too)")
        return vertices, faces

    def mesh(self, name: str, what: str):
        """(vertices (V, 3) m, faces (F, 3)) of the mesh asset `name`, scaled."""
        if name not in self.meshes:
            raise self.error(f"{what}: mesh {name!r} is not an <asset><mesh>")
        source, scale = self.meshes[name]
        if isinstance(source, tuple):
            return shapes.scaled_mesh(*source, scale)
        candidates = source
        found = [file for file in candidates if os.path.isfile(file)]
        if not found:  # (MuJoCo looks in meshdir, and beside the file that included the mesh)
            raise self.error(f"{what}: mesh file not found; tried {candidates}")
        file = found[0]
        try:
            return shapes.load_mesh(file, scale)
        except AssetError as exc:
            raise self.error(f"{what}: {exc}") from exc

    def _non_negative(self, attrs, key, what) -> float:
        """Attribute `key` as a number ≥ 0 (0 by default)."""
        value = self.numbers(attrs, key, 1, what, default=[0.0])[0]
        if value < 0:
            raise self.error(f"{what}: attribute {key!r} expected >= 0, got {attrs[key]!r}")
        return float(value)

    def _bits(self, attrs: dict, key: str, what: str) -> int:
        """A contact bit mask: a non-negative integer (1 by default)."""
        value = self.numbers(attrs, key, 1, what, default=[1])[0]
        if value != int(value) or value < 0:
            raise self.error(f"{what}: attribute {key!r} expected a non-negative integer, got {attrs[key]!r}")
        return int(value)


def over(below: dict, above: dict) -> dict:
    """Attributes ``above`` over ``below``; a value of a _PARTIAL key with fewer numbers than the
    one below replaces only its first ones (MuJoCo reads such arrays into its default's)."""
    out = dict(below)
    for key, value in above.items():
        under = below.get(key, "").split() if key in _PARTIAL else []
        given = value.split()
        out[key] = " ".join(given + under[len(given):]) if len(given) < len(under) else value
    return out


def is_default(key: str, value: str) -> bool:
    """Whether attribute `key` holds MuJoCo's default (MJ_DEFAULTS)."""
    try:
        return key in MJ_DEFAULTS and [float(v) for v in value.split()] == MJ_DEFAULTS[key]
    except ValueError:
        return False


def norm(reader: MJCFDocument, v: np.ndarray, what: str) -> float:
    n = float(np.linalg.norm(v))
    if not n > 1e-12:
        raise reader.error(f"{what}: expected a non-zero vector, got {v.tolist()}")
    return n


def axis_angle(axis, angle: float) -> np.ndarray:
    """(4,) quaternion of a turn by angle (rad) about axis (3,), as MuJoCo's compiler rounds it."""
    half = angle / 2
    return np.array([math.cos(half), *(math.sin(half) * shapes.normalized(axis)[0])])
