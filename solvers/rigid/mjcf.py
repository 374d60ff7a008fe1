"""MJCF (MuJoCo's XML) → ``list[LinkSpec]``: the part of the format an articulated rigid robot needs.

Read as MuJoCo's compiler reads it: ``<include>`` files inlined (several ``<default>`` and
``<worldbody>`` sections merge), ``<default>`` classes (nested, ``class`` and ``childclass``),
``<compiler angle meshdir assetdir autolimits eulerseq inertiafromgeom settotalmass balanceinertia>``,
every orientation form (quat, axisangle, euler, xyaxes, zaxis).

Trees: the bodies in ``<worldbody>`` are the roots of one entity's trees, in the file's order
(MuJoCo's body and dof order; the first tree's root is the entity's base, as in Genesis); the
worldbody's own geoms (a floor, obstacles) are on a static massless link named "world" after
them (MuJoCo's body 0; Genesis's link 0: last here, so that the base and every body's index are
those of the file without them), which collides with every tree (MuJoCo's parent filter skips the
world). A root
body is a root link: free with a ``<freejoint>`` (or a joint of type free, its damping, armature and
frictionloss read), welded where it has no joint; a root body hinged, sliding or on a ball joint on the world hangs
from a static link at the world's origin, named "world" (the first, unless the worldbody's geoms'
link has that name; the others "world:body"). Each
body is a link named as the body, at the body's frame (MuJoCo's and Genesis's): a body without a
joint is welded to its parent (not merged, as MuJoCo and Genesis keep it); a body's joints (hinge →
revolute, slide → prismatic, ball → ball) turn massless links named ``body:joint`` at their anchors, since a
LinkSpec joint turns about its link's origin, and the body's link hangs welded from the last of
them, or is that last link where its joint's anchor is the body origin (no extra link: the usual
case). Contacts take a body's links as one body (LinkSpec.same_body), and, as MuJoCo's filter, a
body welded to a moving parent as part of it.

Bodies: mass, com and inertia from ``<inertial>`` (diaginertia with its frame, or fullinertia),
else from the body's geoms as solids of their density (or stated mass), as MuJoCo's
``inertiafromgeom="auto"`` (a mesh: its solid, exact when closed, else its convex hull; MuJoCo's
legacy formula differs for non-convex meshes); "true": from the geoms even where an ``<inertial>``
is given, but for a body without geoms of mass (MuJoCo 4 keeps its ``<inertial>``). Geoms: sphere,
capsule, cylinder, box (sizes, or ``fromto``), ellipsoid (weighed as the ellipsoid; it collides as an
inscribed polytope, shapes.ellipsoid_mesh, with a warning; MuJoCo and Genesis use its exact surface;
three equal semi-axes make a sphere; its ``fromto`` as MuJoCo's: the third semi-axis half its length, the
section round of size[0]), mesh (``<mesh file scale>`` assets, in the file's own coordinates: MuJoCo's
re-centring moves the geom frame, not the surface; found in meshdir or beside the file that
included them; or given by ``vertex`` and ``face``, without faces the vertices' convex hull);
height fields (``<hfield nrow ncol size elevation>`` assets, read as MuJoCo 4's compiler reads
them: MJCFDocument._hfields; massless, in the worldbody or a body welded to it);
contype/conaffinity masks (MuJoCo's pair rule); ``<contact><exclude>``; friction
(sliding, torsional, rolling), condim (1, 3, 4 or 6), solref, solimp,
priority and solmix, which a pair combines as MuJoCo's mj_contactParam (GeomSpec); planes (infinite, as MuJoCo's colliders take them, massless; drawn as
MuJoCo sizes them) in the worldbody or a body welded to it; a geom with contype = conaffinity = 0
only weighs and is drawn; a geom
drawn where its group is 0-2 (MuJoCo's visible groups), coloured by its rgba or material.
Fixed tendons (``<tendon><fixed>``, up to three hinge or slide joints): their limits (range,
solreflimit, solimplimit; a ``<default><tendon>`` class), as MuJoCo's limit rows on the length Σ
coef·q, ``<equality><tendon tendon1 polycoef>``, which holds that length at its value at qpos0
plus polycoef[0] by an equality row (LinkSpec.tendons; tendon2 is refused), and their passive
spring and damper (stiffness, damping, springlength: one rest length or a dead band; by default
the length at the joints' springrefs, MuJoCo's qpos_spring) and friction loss (frictionloss,
solreffriction, solimpfriction: MuJoCo's friction row on the tendon's rate).
Joints: axis, pos, range (limited: MuJoCo's autolimits), damping, armature, frictionloss,
solreflimit, solimplimit, solreffriction and solimpfriction (the softness of its limit and
friction-loss rows),
actuatorfrcrange (|force| bound), stiffness and springref (a spring −stiffness·(q − springref), as
MuJoCo's; Genesis's loader springs to qpos0 whatever springref says), springdamper (stiffness and
damping set at build from the joint's inertia at qpos0, as MuJoCo's compiler: LinkSpec.springdamper),
ref (the initial q, at which the body is where the file puts it: LinkSpec.q0).
Actuators on a joint give its servo (as Genesis reads them): ``position`` kp, kv; ``general``
with an affine bias, kp = −biasprm[1], kv = −biasprm[2]; ``velocity`` kv; forcerange (symmetric)
the |force| bound; a ``motor`` is force control (control_dofs_force). An actuator on a fixed
tendon of hinge and slide joints (the menagerie Panda's gripper) gives the same servo to each of
the tendon's joints that no actuator drives directly, as Genesis approximates it (MuJoCo drives the
tendon, each joint by its coefficient; said in the load's warning).
``<equality><joint>`` with polycoef (c0, c1) makes joint1 follow joint2, q1 − ref1 = c0 + c1 (q2 −
ref2), or without joint2 holds it at q1 − ref1 = c0 (LinkSpec.mimic). ``<equality><connect>``
holds a point of body1 on body2 (or the world): by bodies (anchor in body1's frame; body2's
anchor where that point is at qpos0) or by sites (their positions in their bodies)
(LinkSpec.connects). ``<equality><weld>`` holds a frame of body1 on one
of body2 (or the world), position and orientation: by bodies (anchor in body2's frame; relpose the
pose of body2's frame in body1's, taken at qpos0 where its quaternion is zero, MuJoCo's default)
or by sites (their frames), its turn rows scaled by torquescale (LinkSpec.welds). Either body may
be the world (body1 the world: the same rows with the other sign, the file's body first). An equality's
solref and solimp soften its rows; an inactive one is not loaded; ``<default><equality>`` applies.

Ball joints (MuJoCo's: a quaternion, three dofs about the body's own axes) with damping, armature,
friction loss, a spring (stiffness) and MuJoCo's cone limit (range (0, θ): θ the largest angle of
the turn; limited by autolimits only where range[0] < range[1], as MuJoCo's compiler).
Refused (AssetError naming the element): a ball joint's force range, a limited ball joint's range
not starting at 0, a ball joint followed by a hinge or ball in one body, repeated body, joint, mesh,
material or height-field names, a negative density on a moving body, an ``<inertial>`` whose
principal moments break A + B ≥ C (unless ``<compiler balanceinertia="true">``: set to their mean),
tendons and actuators naming no joint of the file (as MuJoCo refuses them), a mesh's refpos or
refquat other than the identity (MuJoCo moves its geoms by them),
a free joint below a root body, a
``springyield`` (a joint's or a sprung tendon's), a polynomial stiffness (a joint's or a
tendon's; a tendon's damping too), a free joint's stiffness or springdamper, sdf geoms, a height
field from a file or on a moving body, equalities other than joints', connects, welds and
tendons', elements that would add or move bodies and geoms unread (``<composite>``,
``<flexcomp>``…; ``<frame>`` is read: it places its bodies and geoms, and its childclass is
theirs; so is ``<replicate>``, as copies in frames:
MJCFDocument), a solref of mixed form (one number > 0, the other not: MuJoCo warns and takes its
default), a plane on a moving body (as MuJoCo's compiler). Ignored with one warning
naming them: spatial tendons, a fixed tendon's armature, an actuator's damping
and armature (MuJoCo 4 adds them to the joint or tendon it drives), an actuator on
another tendon, ``<contact><pair>``, ``<keyframe>``, ``<option>`` (the scene's
options rule), and attributes that tune MuJoCo's solver, actuator dynamics or the compiler's mass
bounds (a geom's margin and gap, dampratio, timeconst, boundmass…) unless they hold MuJoCo's
defaults.
"""
import logging
import os

import numpy as np

from ..core import InvalidInputError
from . import shapes
from .collision import hfield
from .mjcf_document import (ACTUATORS, IDENTITY, MJ_DEFAULTS, ORIENTATIONS, MJCFDocument, axis_angle, is_default,
                            norm, over)
from .spec import TENDON_JOINTS, GeomSpec, LinkSpec, VisualSpec

_logger = logging.getLogger("genesis_lite")
_FRAME = ("pos",) + ORIENTATIONS
_NAMES = ("name", "class", "group", "user", "rgba", "material")  # read, or harmless to the physics
# per element: the attributes read here (others are named in the warning of what is ignored)
_READ = {
    "body": _FRAME + ("name", "childclass", "user", "gravcomp"),
    "joint": ("name", "class", "type", "pos", "axis", "range", "limited", "damping", "armature", "frictionloss",
              "actuatorfrcrange", "actuatorfrclimited", "stiffness", "springref", "ref", "springdamper", "springyield",
              "group", "user", "solreflimit", "solimplimit", "solreffriction", "solimpfriction"),
    "freejoint": ("name", "group", "type"),
    "geom": _FRAME + _NAMES + ("type", "size", "fromto", "mesh", "hfield", "friction", "contype", "conaffinity",
                               "density", "mass", "condim", "solref", "solimp", "priority", "solmix"),
    "inertial": _FRAME + ("mass", "diaginertia", "fullinertia"),
}
_JOINTS = {"hinge": "revolute", "slide": "prismatic", "ball": "ball"}
# what a body (or the worldbody) may hold: read here, or nothing the physics sees
_BODY_CHILDREN = {"body", "joint", "freejoint", "geom", "inertial", "site", "camera", "light", "frame"}
_FRAME_CHILDREN = {"body", "geom", "site", "camera", "light", "frame"}
_PRIMITIVES = ("sphere", "capsule", "cylinder", "box")
MJ_FRICTION = (1.0, 0.005, 0.0001)  # MuJoCo's default geom friction: sliding, torsional m, rolling m
_MJ_RGBA = np.array([0.5, 0.5, 0.5, 1.0])  # MuJoCo's default geom colour


def load_mjcf(path: str, entity_name: str | None = None, exclude_ground_plane: bool = False,
              text: str | None = None) -> list[LinkSpec]:
    """Links of the MJCF file `path` in tree order (MuJoCo's body order, parent index < child
    index), one tree a root body, then the static "world" link of the worldbody's geoms if it has
    some. A root link's joint is "free" or "fixed" as the file says, at its body's pose (in the
    world frame of the file). entity_name: only used in messages. exclude_ground_plane: leave out
    the worldbody's plane geoms, those in its <frame>s and those a default class makes planes too
    (Genesis's option, which leaves out only the worldbody's own children written type="plane"):
    for a scene with a ground of its own. text: the document itself (Genesis's inline MJCF; `path`
    then only names it in messages, and relative paths start at the working directory). Raises
    InvalidInputError for bad arguments and AssetError for anything wrong with the file."""
    if not isinstance(path, (str, os.PathLike)):
        raise InvalidInputError(f"load_mjcf: argument 'path' expected a file path, got {path!r}")
    if not isinstance(exclude_ground_plane, (bool, np.bool_)):
        raise InvalidInputError(f"load_mjcf: argument 'exclude_ground_plane' expected True or False, got "
                                f"{exclude_ground_plane!r}")
    reader = _Reader(os.fspath(path), entity_name, text)
    links = reader.links(bool(exclude_ground_plane))
    if reader.ignored:
        _logger.warning(f"{reader.where()}: ignored (genesis_lite does not model them): "
                        + "; ".join(sorted(reader.ignored)))
    return links


class _Reader(MJCFDocument):
    """The bodies, joints, geoms, equalities, actuators and exclusions of a read file."""

    def ignore_unread(self, element, attrs: dict):
        """Note the element's attributes not read here, but those at MuJoCo's default (which the
        simulation has: nothing is lost)."""
        for key, value in attrs.items():
            if key not in _READ[element.tag] and not is_default(key, value):
                self.ignored.add(f"<{element.tag} {key}>")

    # ---------------------------------------------------------------- tree

    def links(self, exclude_ground_plane: bool) -> list[LinkSpec]:
        """The file's links (load_mjcf's), equalities, servos and exclusions on them (without the
        worldbody's planes if ``exclude_ground_plane``)."""
        worldbodies = self.root.findall("worldbody")  # (several sections, through includes, make one)
        if not worldbodies:
            raise self.error("<worldbody> is missing")
        bodies = [member for worldbody in worldbodies for member in self._members(worldbody, "body", "main")]
        for worldbody in worldbodies:
            self._check_children(worldbody, "<worldbody>")
        world_geoms = [member for worldbody in worldbodies for member in self._members(worldbody, "geom", "main")
                       if not (exclude_ground_plane and self.attrs(*member[:2]).get("type") == "plane")]
        if not bodies and not world_geoms:
            raise self.error("<worldbody> expected at least one <body> or geom, got none")
        kinds = {"body": ("body",), "joint": ("joint", "freejoint")}
        names = {kind: [element.get("name") for worldbody in worldbodies for element in worldbody.iter(*tags)
                        if element.get("name")] for kind, tags in kinds.items()}
        for kind, named in names.items():  # (MuJoCo refuses repeated ones too)
            repeated = sorted({name for name in named if named.count(name) > 1})
            if repeated:
                raise self.error(f"{kind} names expected unique, got repeated names {repeated}")
        self.body_names, self.joint_names = set(names["body"]), set(names["joint"])
        links = []
        self.static_links = set()  # the links welded to the world (the only ones a plane may be on)
        self.sites = {}  # site name → (its body's name, its position (3,) m and turn (4,) in the body's frame)
        for worldbody in worldbodies:
            self._sites(worldbody, "main", "world")
        self.world_link = bool(world_geoms)  # (the world's geoms' link takes the name "world")
        for root, childclass, outer in bodies:  # several trees: one entity, as Genesis and MuJoCo load them
            try:
                self._body(root, -1, childclass, links, outer)
            except RecursionError:  # (MuJoCo's parser stops at ~500 nested elements; ours goes to ~600 bodies)
                raise self.error(f"body {root.get('name')!r}: its bodies nest too deep to be read") from None
        if world_geoms:  # MuJoCo's body 0: static, massless, its geoms collide with every tree's
            links.append(_link("world", -1, "", "fixed", np.zeros(3), IDENTITY.copy()))
            self.static_links.add(len(links) - 1)
            self._geoms(world_geoms, links[-1], "<worldbody>", static=True)
        names = [link.name for link in links]
        repeated = sorted({name for name in names if names.count(name) > 1})
        if repeated:  # (a joint's link named after its body and joint, or a world link, met a body's name)
            raise self.error(f"link names expected unique, got repeated names {repeated}")
        self._set_total_mass(links)
        self._equalities(links)
        self._tendons(links)
        self._actuators(links)
        self._exclusions(links)
        return links

    def _set_total_mass(self, links):
        """``<compiler settotalmass>`` > 0: every body's mass and inertia scaled by one factor, so that
        they sum to it (MuJoCo's compiler; deprecated in MuJoCo 3.3, still applied by MuJoCo 4)."""
        total = sum(link.mass for link in links)
        if self.settotalmass > 0 and total > 0:
            scale = self.settotalmass / total
            for link in links:
                link.mass, link.inertia = link.mass * scale, link.inertia * scale

    def _body(self, body, parent: int, childclass: str, links: list, outer):
        """Append the links of `body` and of its subtree: the body's link at its MuJoCo frame,
        after a massless link at the anchor of each joint whose anchor or place in the chain
        keeps it from being the body's (a LinkSpec joint turns about its link's origin).
        outer: (pos, quat) of the <frame>s it sits in, in its parent's frame."""
        attrs = self.attrs(body, childclass)
        childclass = body.get("childclass", childclass)
        name = attrs.get("name") or self._unnamed(f"body{len(links)}")
        what = f"body {name!r}"
        self.ignore_unread(body, attrs)
        self._check_children(body, what)
        pos, quat = shapes.compose(*outer, *self.frame(attrs, what))
        joints = [j for j in body if j.tag in ("joint", "freejoint")]
        if parent < 0 and (not joints or self._is_free(joints[0], childclass)):
            if len(joints) > 1:
                raise self.error(f"{what}: a free joint must be its body's only joint, got {len(joints)} joints")
            links.append(_link(name, -1, (joints[0].get("name") or name) if joints else "",
                               "free" if joints else "fixed", pos, quat))
            if joints:
                self._free_joint(joints[0], childclass, links[-1], what)
            else:
                self.static_links.add(len(links) - 1)
        else:
            if parent < 0:  # hinged or sliding on the world: on a static link at the world's origin, one
                # a tree, so that each root body stays a tree of its own (the pair rules go by tree)
                taken = self.world_link or any(link.name == "world" for link in links)
                world = f"world:{name}" if taken else "world"
                links.append(_link(world, -1, "", "fixed", np.zeros(3), IDENTITY.copy()))
                parent = len(links) - 1
            self._joint_chain(joints, childclass, name, what, parent, pos, quat, links)
            if not joints and parent in self.static_links:
                self.static_links.add(len(links) - 1)
        self._contents(body, childclass, links[-1], what, len(links) - 1 in self.static_links)
        links[-1].gravcomp = self.numbers(attrs, "gravcomp", 1, what, default=[0.0])[0]  # (on the link of its mass)
        self._sites(body, childclass, name)
        index = len(links) - 1
        for child, child_class, child_outer in self._members(body, "body", childclass):
            self._body(child, index, child_class, links, child_outer)

    def _unnamed(self, stem: str) -> str:
        """A name for an unnamed body: ``stem``, or with a suffix where a body of the file has it."""
        name, k = stem, 0
        while name in self.body_names:
            k += 1
            name = f"{stem}_{k}"
        return name

    def _sites(self, body, childclass: str, name: str):
        """Note the frames of the body's sites (in its frame; a ``fromto`` site at its middle, its z
        axis from ``to`` to ``from``, as MuJoCo 4's compiler turns it)."""
        for element, site_class, outer in self._members(body, "site", childclass):
            attrs = self.attrs(element, site_class)
            what = f"body {name!r} site {attrs.get('name')!r}"
            pos, quat = self.frame(attrs, what)
            if "fromto" in attrs:
                pos, quat, _ = self._fromto(attrs, what)
            if attrs.get("name") in self.sites:  # (MuJoCo refuses them too)
                raise self.error(f"{what}: site names expected unique, got {attrs['name']!r} twice")
            if attrs.get("name") is not None:
                self.sites[attrs["name"]] = (name, *shapes.compose(*outer, pos, quat))

    def _joint_chain(self, joints, childclass, name, what, parent, pos, quat, links):
        """The links of a body with `joints` (maybe none) hanging from link `parent`, at (pos, quat)
        in its frame: one a joint, at the joint's anchor (the chain's later ones in the frame the
        earlier joints turned, as MuJoCo composes them), then the body's own link welded at the body
        frame unless the last joint's anchor is the body origin."""
        kinds = [self.attrs(joint, childclass).get("type", "hinge") for joint in joints]
        if "ball" in kinds and any(kind in ("hinge", "ball") for kind in kinds[kinds.index("ball") + 1:]):
            raise self.error(f"{what}: a ball joint followed by a hinge or ball joint in one body is refused, as "
                             f"MuJoCo refuses it, got joints of types {kinds}")
        anchor = np.zeros(3)
        for k, joint in enumerate(joints):
            offset = self._anchor(joint, childclass)
            last = k == len(joints) - 1 and not np.any(offset)
            spec = self._joint(joint, childclass, name if last else f"{name}:{joint.get('name') or k}", what)
            spec.parent, spec.same_body = (len(links) - 1, True) if k else (parent, False)
            spec.pos, spec.quat = (offset - anchor, IDENTITY.copy()) if k else \
                (pos + shapes.quat_to_mat(quat) @ offset, quat)
            self._at_ref(spec)
            anchor = offset
            links.append(spec)
        if not joints:
            links.append(_link(name, parent, f"{name}_fixed", "fixed", pos, quat))
        elif np.any(anchor):
            links.append(_link(name, len(links) - 1, f"{name}_fixed", "fixed", -anchor, IDENTITY.copy()))
            links[-1].same_body = True

    @staticmethod
    def _at_ref(spec: LinkSpec):
        """MuJoCo's body frame is (pos, quat) when the joint is at its ``ref`` (spec.q0): the link's
        frame, which a LinkSpec joint moves from q = 0, is that frame turned (or slid) by −ref about
        the joint's axis, which the joint's own motion commutes with."""
        if spec.joint_type == "revolute":
            spec.quat = shapes.quat_mul(spec.quat, axis_angle(spec.axis, -spec.q0))
        elif spec.joint_type == "prismatic":
            spec.pos = spec.pos - spec.q0 * shapes.quat_to_mat(spec.quat) @ spec.axis

    def _members(self, element, tag: str, childclass: str, outer=(np.zeros(3), IDENTITY)):
        """(child, its class context, (pos, quat) of the <frame>s around it) of the children named
        `tag` of a body, the worldbody or a <frame>, those inside <frame>s too (a frame places its
        children, and its childclass is theirs), in the file's order."""
        for child in element:
            if child.tag == tag:
                yield child, childclass, outer
            elif child.tag == "frame":
                attrs = self.attrs(child, childclass)
                self._check_children(child, f"<frame name={attrs.get('name')!r}>", _FRAME_CHILDREN)
                placed = shapes.compose(*outer, *self.frame(attrs, f"<frame name={attrs.get('name')!r}>"))
                yield from self._members(child, tag, child.get("childclass", childclass), placed)

    def _check_children(self, element, what: str, allowed=None):
        """Refuse what a body (or the worldbody, a frame) holds that is not read here and changes
        the model (<composite>, <flexcomp>, …: their bodies and geoms would go missing)."""
        allowed = _BODY_CHILDREN if allowed is None else allowed
        unknown = [child.tag for child in element if child.tag not in allowed]
        if unknown:
            raise self.error(f"{what}: {unknown} not supported (it may hold {sorted(allowed)})")

    def _is_free(self, joint, childclass) -> bool:
        return joint.tag == "freejoint" or self.attrs(joint, childclass).get("type") == "free"

    def _free_joint(self, joint, childclass, link: LinkSpec, what: str):
        """A free root joint's damping, armature and friction loss (on its six dofs, as MuJoCo's),
        and the friction loss's softness (a limit's: a free joint has none, as in MuJoCo)."""
        attrs = self.attrs(joint, childclass)
        what = f"{what} joint {attrs.get('name') or link.name!r}"
        read = ("damping", "armature", "frictionloss", "solreflimit", "solimplimit", "solreffriction", "solimpfriction")
        self.ignore_unread(joint, {k: v for k, v in attrs.items() if k not in read})
        self._refuse_unmodelled(attrs, what)
        if self._non_negative(attrs, "stiffness", what) != 0.0 or self._springdamper(attrs, what) is not None:
            # (MuJoCo's would spring the pose; Genesis refuses)
            raise self.error(f"{what}: a free joint's spring is not supported (stiffness or springdamper given)")
        for key in ("damping", "armature", "frictionloss"):
            setattr(link, key, self._non_negative(attrs, key, what))
        self._joint_softness(link, attrs, what)

    def _anchor(self, joint, childclass) -> np.ndarray:
        """(3,) m: where the joint turns, in its body's frame."""
        attrs = self.attrs(joint, childclass)
        return self.numbers(attrs, "pos", 3, f"joint {attrs.get('name')!r}", default=np.zeros(3))

    def _joint(self, joint, childclass: str, link_name: str, what: str) -> LinkSpec:
        """A massless link named `link_name` that the hinge, slide or ball `joint` turns (its frame
        and parent are the chain's to set): axis, limits, damping, armature, friction loss, force
        bound (a ball joint: _ball)."""
        attrs = self.attrs(joint, childclass)
        name = attrs.get("name") or link_name
        what = f"{what} joint {name!r}"
        self.ignore_unread(joint, attrs)
        kind = "free" if joint.tag == "freejoint" else attrs.get("type", "hinge")
        if kind not in _JOINTS:
            raise self.error(f"{what}: type expected hinge, slide or ball (or free on the root body), got {kind!r}")
        self._refuse_unmodelled(attrs, what)
        if kind == "ball":
            return self._ball(attrs, link_name, name, what)
        axis = self.numbers(attrs, "axis", 3, what, default=[0.0, 0.0, 1.0])
        norm(self, axis, what)
        axis = shapes.normalized(axis)[0]
        spec = _link(link_name, -1, name, _JOINTS[kind], np.zeros(3), IDENTITY.copy(), axis)
        for key in ("damping", "armature", "frictionloss", "stiffness"):
            setattr(spec, key, self._non_negative(attrs, key, what))
        spec.springdamper = self._springdamper(attrs, what)
        scale = np.deg2rad(1.0) if kind == "hinge" and self.degree else 1.0  # angles in the file → rad
        spec.springref = self.numbers(attrs, "springref", 1, what, default=[0.0])[0] * scale
        spec.q0 = self.numbers(attrs, "ref", 1, what, default=[0.0])[0] * scale
        if self._limited(attrs, "range", "limited", self._range_given(attrs, "range", what), what):
            low, high = self.numbers(attrs, "range", 2, what, default=[0.0, 0.0])
            if not low < high:
                raise self.error(f"{what}: range expected lower < upper, got {attrs.get('range')!r}")
            spec.lower, spec.upper = low * scale, high * scale
        spec.effort = self._force_bound(attrs, "actuatorfrcrange", "actuatorfrclimited", what)
        self._joint_softness(spec, attrs, what)
        return spec

    def _ball(self, attrs: dict, link_name: str, name: str, what: str) -> LinkSpec:
        """A ball joint's massless link (MuJoCo's ball: its axis, ref and springref unread, as
        MuJoCo's): damping, armature, friction loss and stiffness (MuJoCo's ball spring, to the
        identity) on its three dofs; a cone limit as MuJoCo's compiler reads ``range``: limited
        when ``limited="true"``, or by autolimits where range[0] < range[1]; then range[0] must be
        0 and the larger value is the largest angle of the turn (0 or less: the joint is held)."""
        spec = _link(link_name, -1, name, "ball", np.zeros(3), IDENTITY.copy())
        for key in ("damping", "armature", "frictionloss", "stiffness"):
            setattr(spec, key, self._non_negative(attrs, key, what))
        spec.springdamper = self._springdamper(attrs, what)
        low, high = self.numbers(attrs, "range", 2, what, default=[0.0, 0.0])
        if self._limited(attrs, "range", "limited", "range" in attrs and low < high, what):
            if low != 0.0:
                raise self.error(f"{what}: a ball joint's range expected (0, largest angle), as MuJoCo's, got "
                                 f"{attrs.get('range')!r}")
            spec.upper = max(0.0, high) * (np.deg2rad(1.0) if self.degree else 1.0)
        if self._force_bound(attrs, "actuatorfrcrange", "actuatorfrclimited", what) < np.inf:
            raise self.error(f"{what}: a ball joint's actuatorfrcrange is not supported yet, got "
                             f"{attrs['actuatorfrcrange']!r}")
        self._joint_softness(spec, attrs, what)
        return spec

    def _refuse_unmodelled(self, attrs: dict, what: str):
        """Refuse what would move the joint or tendon otherwise if it were dropped: a spring that
        yields (``springyield``)."""
        if np.any(self.numbers(attrs, "springyield", 1, what, default=np.zeros(1)) != 0.0):
            raise self.error(f"{what}: a yielding spring is not supported (attribute 'springyield' = "
                             f"{attrs['springyield']!r})")

    def _springdamper(self, attrs: dict, what: str):
        """A joint's ``springdamper`` (time constant s, damping ratio): None for none (0 0), else both
        positive, as MuJoCo 4's compiler requires; the solver then sets the joint's stiffness and
        damping at build from its inertia at qpos0."""
        given = self.numbers(attrs, "springdamper", 2, what, default=np.zeros(2))
        if np.all(given == 0):
            return None
        if not np.all(given > 0):
            raise self.error(f"{what}: springdamper expected two positive values (or 0 0: none), as MuJoCo's, "
                             f"got {attrs['springdamper']!r}")
        return float(given[0]), float(given[1])

    def _limited(self, attrs, key: str, limited_key: str, has_range: bool, what: str) -> bool:
        """Whether a range ``key`` binds: its ``limited_key`` "true", or "auto" (its default) with a
        range given (``has_range``) under the compiler's autolimits (_refuse_unflagged_range first)."""
        self._refuse_unflagged_range(attrs, key, limited_key, what)
        limited = attrs.get(limited_key, "auto")
        return limited == "true" or (limited == "auto" and self.autolimits and has_range)

    def _range_given(self, attrs, key: str, what: str) -> bool:
        """Whether a range ``key`` is given other than (0, 0), MuJoCo's default, which its compiler
        reads as no range (its autolimits limit where range[0] < range[1]; a range given the other
        way round is refused below rather than left unlimited)."""
        return key in attrs and bool(np.any(self.numbers(attrs, key, 2, what) != 0.0))

    def _refuse_unflagged_range(self, attrs, key: str, limited_key: str, what: str):
        """With autolimits off, a range other than (0, 0) given without its ``limited_key`` is refused,
        as MuJoCo's compiler refuses it (it was dropped here)."""
        if not self.autolimits and attrs.get(limited_key, "auto") == "auto" and self._range_given(attrs, key, what):
            raise self.error(f"{what}: '{key}' given without '{limited_key}' under <compiler autolimits=\"false\">, "
                             f"as MuJoCo's compiler refuses it; set {limited_key}=\"true\" (or \"false\"), or "
                             f"autolimits=\"true\"")

    def _force_bound(self, attrs, key: str, limited_key: str, what: str) -> float:
        """|force| bound (N·m or N) of a force range, inf when there is none."""
        if not self._limited(attrs, key, limited_key, self._range_given(attrs, key, what), what):
            return np.inf
        low, high = self.numbers(attrs, key, 2, what, default=[0.0, 0.0])
        if low != -high or high <= 0:
            raise self.error(f"{what}: {key} expected a symmetric range (-f, f) with f > 0 (genesis_lite bounds "
                             f"|force|), got {attrs.get(key)!r}")
        return float(high)

    # ---------------------------------------------------------------- a body's contents

    def _contents(self, body, childclass: str, link: LinkSpec, what: str, static: bool):
        """The body's geoms, visuals and mass properties on its link (at the body frame; static:
        welded to the world)."""
        solids = self._geoms(self._members(body, "geom", childclass), link, what, static)
        inertial = body.find("inertial")
        # (inertiafromgeom "true" overrides an <inertial> where the body has geoms: MuJoCo 4 keeps it
        # on a body without, measured; it was dropped, the body massless)
        from_geoms = self.inertiafromgeom == "true" and any(mass > 1e-14 for _, mass, *_ in solids)  # (MuJoCo's mjEPS)
        if inertial is not None and not from_geoms:
            link.mass, link.com, link.inertia = self._inertial(inertial, what)
        elif self.inertiafromgeom != "false":
            link.mass, link.com, link.inertia = shapes.combined_mass_properties(solids)
            if any(geom.type == "mesh" and not shapes.encloses_solid(geom.vertices, geom.faces) for geom, *_ in solids):
                self.ignored.add(f"{what}: an open mesh's own inertia (here its convex hull's; MuJoCo integrates "
                                 f"the open surface)")

    def _geoms(self, members, link: LinkSpec, what: str, static: bool) -> list:
        """Put the geoms ``members`` (_members's) on the link, as collision shapes (unless both
        their contype and conaffinity are 0) and as visuals (groups 0-2, MuJoCo's visible ones);
        returns each one's (GeomSpec, mass kg, com (3,), inertia (3, 3)) in its own frame. A plane
        only on a link welded to the world (MuJoCo's compiler refuses it elsewhere)."""
        solids = []
        for k, (element, geom_class, outer) in enumerate(members):
            attrs = self.attrs(element, geom_class)
            self.ignore_unread(element, attrs)
            where = f"{what} geom {attrs.get('name') or k}"
            geom, density, mass, axes = self._geom(attrs, where)
            if geom.type == "plane" and not static:
                raise self.error(f"{where}: a plane only in the worldbody or a body welded to it (MuJoCo's compiler "
                                 f"refuses it elsewhere), got one on a moving body")
            if density < 0 and not static:  # (MuJoCo's compiler refuses it too: it took mass away)
                raise self.error(f"{where}: attribute 'density' expected >= 0 on a moving body, got "
                                 f"{attrs['density']!r}")
            if geom.type == "hfield" and not static:
                raise self.error(f"{where}: a height field only in the worldbody or a body welded to it (on a moving "
                                 f"body: not yet), got one on a moving body")
            geom.pos, geom.quat = shapes.compose(*outer, geom.pos, geom.quat)
            solids.append((geom, *_solid(geom, density, mass, axes)))
            contype, conaffinity = (self._bits(attrs, key, where) for key in ("contype", "conaffinity"))
            if contype or conaffinity:
                geom.contype, geom.conaffinity = contype, conaffinity
                link.geoms.append(geom)
            if self.numbers(attrs, "group", 1, where, default=[0])[0] <= 2:
                link.visuals.append(self._visual(geom, attrs))
        return solids

    def _fromto(self, attrs: dict, what: str):
        """(centre (3,) m, quaternion (4,), half length m) of a geom's or site's ``fromto``: z from `to`
        to `from`, as MuJoCo's compiler turns it (mjuu_z2quat of from − to), rounded as it rounds."""
        ends = self.numbers(attrs, "fromto", 6, what)
        norm(self, ends[3:] - ends[:3], what)
        towards_from = ends[:3] - ends[3:]
        return (ends[:3] + ends[3:]) / 2.0, shapes.quat_z_to(towards_from), shapes.normalized(towards_from)[1] / 2

    def _geom(self, attrs: dict, what: str):
        """(GeomSpec in the body frame, density kg/m³, stated mass kg or None, an ellipsoid's semi-axes
        (3,) m where the GeomSpec is its polytope, else None) of a <geom>."""
        kind = attrs.get("type", "sphere")
        if kind in _PRIMITIVES + ("ellipsoid",) and "mesh" in attrs:  # (it was read as the size given)
            raise self.error(f"{what}: a {kind} fitted to mesh {attrs['mesh']!r} (MuJoCo's fit-to-mesh) is not "
                             f"supported yet; give the {kind}'s size, or type=\"mesh\"")
        pos, quat = self.frame(attrs, what)
        size = self.numbers(attrs, "size", (1, 2, 3), what, default=np.zeros(3))
        size = np.concatenate([size, np.zeros(3 - len(size))])
        if "fromto" in attrs and kind in ("capsule", "cylinder", "box", "ellipsoid"):
            pos, quat, size[2 if kind in ("box", "ellipsoid") else 1] = self._fromto(attrs, what)
            if kind in ("box", "ellipsoid"):  # (MuJoCo 4: a square, or round, section of half side size[0])
                size[1] = size[0]
        if kind == "plane":  # infinite to the colliders, as MuJoCo's (its size only draws it)
            geom = GeomSpec("plane", np.array([0.0, 0.0, 1.0]), pos, quat)
        elif kind == "mesh":
            vertices, faces = self.mesh(attrs.get("mesh"), what)
            geom = GeomSpec("mesh", np.zeros(0), pos, quat, vertices=vertices, faces=faces)
        elif kind == "hfield":  # (its size is its asset's: the geom's own is not read, as MuJoCo's)
            hfield_size, elevation = self.hfield(attrs.get("hfield"), what)
            geom = GeomSpec("hfield", hfield_size, pos, quat, elevation=elevation)
        elif kind == "ellipsoid" and not np.all(size > 0):
            raise self.error(f"{what}: ellipsoid size expected 3 positive numbers, got {attrs.get('size')!r}")
        elif kind == "ellipsoid" and not (size[0] == size[1] == size[2]):
            vertices, faces = shapes.ellipsoid_mesh(size)
            geom = GeomSpec("mesh", np.zeros(0), pos, quat, vertices=vertices, faces=faces)
            self.ignored.add("<geom type='ellipsoid'>: its surface (it collides as the inscribed polytope of "
                             f"{len(vertices)} vertices, within 0.39 % of its surface; its mass and "
                             f"inertia are the ellipsoid's)")
        elif kind in _PRIMITIVES or kind == "ellipsoid":  # (an ellipsoid of three equal semi-axes: a sphere)
            kind = "sphere" if kind == "ellipsoid" else kind
            n = {"sphere": 1, "capsule": 2, "cylinder": 2, "box": 3}[kind]
            if not np.all(size[:n] > 0):
                raise self.error(f"{what}: {kind} size expected {n} positive numbers, got {attrs.get('size')!r}")
            full = {"sphere": size[:1], "capsule": size[:2] * [1, 2], "cylinder": size[:2] * [1, 2],
                    "box": size * 2}[kind]
            geom = GeomSpec(kind, full, pos, quat)
        else:
            kinds = _PRIMITIVES + ("ellipsoid", "mesh", "plane", "hfield")
            raise self.error(f"{what}: geom type expected one of {kinds}, got {kind!r}")
        friction = self.numbers(attrs, "friction", (1, 2, 3), what, default=[1.0])
        # (a partial one ends in MuJoCo's defaults; a value under MuJoCo's floor 1e-5 acts as it, as there)
        friction = [*friction, *MJ_FRICTION[len(friction):]]
        geom.friction, geom.friction_torsional, geom.friction_rolling = (float(f) for f in friction)
        self._contact_params(geom, attrs, what)
        density = self.numbers(attrs, "density", 1, what, default=[1000.0])[0]
        mass = self._non_negative(attrs, "mass", what) if "mass" in attrs else None
        return geom, density, mass, size if geom.type == "mesh" and kind == "ellipsoid" else None

    def _contact_params(self, geom: GeomSpec, attrs: dict, what: str):
        """The geom's condim, solref, solimp (where the file states them: a partial solimp ends in
        MuJoCo's defaults), priority and solmix."""
        condim = self._integer(attrs, "condim", 3, what)
        if condim not in (1, 3, 4, 6):
            raise self.error(f"{what}: attribute 'condim' expected 1, 3, 4 or 6 (as MuJoCo's compiler), "
                             f"got {attrs['condim']!r}")
        geom.condim = condim
        geom.solref, geom.solimp = (self._softness(attrs, key, what) for key in ("solref", "solimp"))
        geom.priority = self._integer(attrs, "priority", 0, what)
        geom.solmix = float(self.numbers(attrs, "solmix", 1, what, default=[1.0])[0])

    def _softness(self, attrs: dict, key: str, what: str):
        """Attribute ``key`` (a solref (2,) or solimp (5,) by its name) where the file states it, a
        partial one ending in MuJoCo's defaults; else None."""
        if not attrs.get(key, "").split():  # (MuJoCo takes an empty value as none)
            return None
        default = MJ_DEFAULTS["solref" if key.startswith("solref") else "solimp"]
        given = self.numbers(attrs, key, tuple(range(1, len(default) + 1)), what)
        value = np.concatenate([given, default[len(given):]])
        if key.startswith("solref") and (value[0] > 0) != (value[1] > 0):
            raise self.error(f"{what}: attribute {key!r} expected both numbers > 0 (time constant, damping ratio) "
                             f"or both ≤ 0 (−stiffness, −damping), got {attrs[key]!r} (MuJoCo warns of a mixed "
                             f"format and takes its default)")
        return value

    def _integer(self, attrs: dict, key: str, default: int, what: str) -> int:
        """Attribute ``key`` as MuJoCo reads an int: digits only (not 1.0, nor 1e3)."""
        text = attrs.get(key, str(default)).strip()
        if not text.lstrip("+-").isdigit():
            raise self.error(f"{what}: attribute {key!r} expected an integer, got {attrs[key]!r}")
        return int(text)

    def _joint_softness(self, spec: LinkSpec, attrs: dict, what: str):
        """The joint's limit and friction-loss solref and solimp (LinkSpec.limit_sol,
        .frictionloss_sol)."""
        spec.limit_sol = self._row_softness(attrs, "solreflimit", "solimplimit", what)
        spec.frictionloss_sol = self._row_softness(attrs, "solreffriction", "solimpfriction", what)

    def _row_softness(self, attrs: dict, ref_key: str, imp_key: str, what: str) -> np.ndarray:
        """(7,) a row's solref then solimp from attributes ``ref_key`` and ``imp_key``, NaN where the
        file states neither (the scene's default then)."""
        ref, imp = self._softness(attrs, ref_key, what), self._softness(attrs, imp_key, what)
        return np.concatenate([np.full(2, np.nan) if ref is None else ref, np.full(5, np.nan) if imp is None else imp])

    def _visual(self, geom: GeomSpec, attrs: dict) -> VisualSpec:
        """The geom as drawn: its shape, but a plane of positive half sizes (MuJoCo's x, y) as that
        rectangle (a mesh), one with a zero as an unbounded plane (visuals.py)."""
        rgba = None
        if "rgba" in attrs:
            rgba = self.numbers(attrs, "rgba", 4, "geom")
        elif attrs.get("material") in self.materials:
            rgba = self.materials[attrs["material"]]
        rgba = rgba if rgba is None or not np.array_equal(rgba, _MJ_RGBA) else None
        if geom.type == "hfield":
            vertices, faces = hfield.surface(geom.size, geom.elevation)
            return VisualSpec("mesh", np.zeros(0), geom.pos, geom.quat, vertices, faces, rgba)
        half = self.numbers(attrs, "size", (1, 2, 3), "geom", default=np.zeros(3))[:2]
        if geom.type == "plane" and len(half) == 2 and np.all(half > 0):
            corners = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
            return VisualSpec("mesh", np.zeros(0), geom.pos, geom.quat, corners * [*half, 0.0],
                              np.array([[0, 1, 2], [0, 2, 3]]), rgba)
        return VisualSpec(geom.type, geom.size, geom.pos, geom.quat, geom.vertices, geom.faces, rgba)

    def _inertial(self, inertial, what: str):
        attrs = dict(inertial.attrib)
        what = f"{what} <inertial>"
        self.ignore_unread(inertial, attrs)
        com, quat = self.frame(attrs, what)
        mass = self._non_negative(attrs, "mass", what) if "mass" in attrs else self.numbers(attrs, "mass", 1, what)
        if "fullinertia" in attrs:
            if any(key in attrs for key in ORIENTATIONS):  # (MuJoCo's schema: the matrix has its axes)
                raise self.error(f"{what}: fullinertia expected without an orientation, got "
                                 f"{[key for key in ORIENTATIONS if key in attrs]}")
            xx, yy, zz, xy, xz, yz = self.numbers(attrs, "fullinertia", 6, what)
            inertia = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
        else:
            inertia = np.diag(self.numbers(attrs, "diaginertia", 3, what, default=np.zeros(3)))
        rot = shapes.quat_to_mat(quat)
        inertia = rot @ inertia @ rot.T
        moments = np.linalg.eigvalsh(0.5 * (inertia + inertia.T))
        if moments[0] < -1e-6 * max(abs(inertia).max(), 1e-300):
            raise self.error(f"{what}: inertia expected positive semi-definite, got {inertia.tolist()}")
        if moments[0] + moments[1] < moments[2] - max(1e-14, 1e-10 * moments[2]):  # (MuJoCo's compiler refuses it)
            if not self.balanceinertia:
                raise self.error(f"{what}: inertia expected principal moments with A + B >= C, as a body's, got "
                                 f"{moments.tolist()} (MuJoCo's <compiler balanceinertia=\"true\"> balances them)")
            return float(mass), com, np.eye(3) * moments.mean()  # (balanced: the three set to their mean)
        return float(mass), com, 0.5 * (inertia + inertia.T)

    # ---------------------------------------------------------------- equalities and actuators

    def _equalities(self, links: list[LinkSpec]):
        """<equality>: <joint> (a mimic), <connect> and <weld> (LinkSpec.connects, .welds), <tendon>
        (self.tendon_equalities, which _tendons reads); only those get here (MJCFDocument refuses the
        others)."""
        self.tendon_equalities = {}  # fixed tendon's name → (offset m or rad, softness (7,))
        for equality in self.root.iter("equality"):
            for element in equality:
                attrs = self._equality_attrs(element)
                what = f"<equality><{element.tag} name={attrs.get('name')!r}>"
                if attrs.get("active", "true") == "false":  # (MuJoCo can switch it on later; here it stays off)
                    self.ignored.add(f"{what} (inactive: not loaded)")
                    continue
                softness = self._row_softness(attrs, "solref", "solimp", what)
                if element.tag == "joint":
                    self._joint_equality(attrs, links, what, softness)
                elif element.tag == "tendon":
                    self._tendon_equality(attrs, what, softness)
                elif element.tag == "connect":
                    self._connect(attrs, links, what, softness)
                else:
                    self._weld(attrs, links, what, softness)

    def _equality_attrs(self, element) -> dict:
        """An equality's attributes over its class's ``<default><equality>`` (MuJoCo's defaults
        for every equality type: active, solref, solimp; MuJoCo's schema allows no other there)."""
        cls = element.get("class", "main")
        if cls not in self.defaults and cls != "main":
            raise self.error(f"<equality><{element.tag}>: class {cls!r} is not a <default> class")
        default = self.defaults.get(cls, {}).get("equality", {})
        return over({k: v for k, v in default.items() if k in ("active", "solref", "solimp")}, element.attrib)

    def _joint_equality(self, attrs: dict, links: list[LinkSpec], what: str, softness: np.ndarray):
        """<equality><joint joint1 joint2 polycoef>: joint1 follows joint2 (LinkSpec.mimic), or without
        joint2 is held at q1 − ref1 = polycoef[0], its row as soft as ``softness`` says
        (LinkSpec.mimic_sol)."""
        by_joint = {link.joint_name: link for link in links if link.joint_type in ("revolute", "prismatic")}
        followed = attrs.get("joint2")
        for key in ("joint1", "joint2") if followed is not None else ("joint1",):
            if attrs.get(key) not in by_joint:
                raise self.error(f"{what}: {key} expected a hinge or slide joint of the file, got {attrs.get(key)!r}")
        for key in attrs:
            if key not in ("name", "class", "joint1", "joint2", "polycoef", "active", "solref", "solimp"):
                self.ignored.add(f"<equality><joint {key}>")
        if by_joint[attrs["joint1"]].mimic is not None:
            raise self.error(f"{what}: joint1 {attrs['joint1']!r} expected in one joint equality as joint1, got a "
                             f"second (more are not supported yet)")
        coef = np.array([0.0, 1.0, 0.0, 0.0, 0.0])  # (MuJoCo's; a shorter polycoef keeps the rest)
        given = self.numbers(attrs, "polycoef", (1, 2, 3, 4, 5), what, default=[])
        coef[:len(given)] = given
        if followed is not None and np.any(coef[2:] != 0):
            raise self.error(f"{what}: polycoef expected a linear map (its last three 0), got {coef.tolist()}")
        # MuJoCo's row holds q1 − ref1 = c0 + c1 (q2 − ref2): an offset c0 + ref1 − c1 ref2 on q;
        # without joint2, q1 − ref1 = c0 (MuJoCo reads no other coefficient)
        multiplier, ref2 = (0.0, 0.0) if followed is None else (float(coef[1]), by_joint[followed].q0)
        offset = float(coef[0] + by_joint[attrs["joint1"]].q0 - multiplier * ref2)
        by_joint[attrs["joint1"]].mimic = (followed, multiplier, offset)
        by_joint[attrs["joint1"]].mimic_sol = softness

    def _tendon_equality(self, attrs: dict, what: str, softness: np.ndarray):
        """<equality><tendon tendon1 polycoef>: fixed tendon1's length L held at L0 + polycoef[0] (L0:
        its length at qpos0), MuJoCo's row; tendon2 (L a polynomial of another's) is not supported yet."""
        for key in attrs:
            if key not in ("name", "class", "tendon1", "tendon2", "polycoef", "active", "solref", "solimp"):
                self.ignored.add(f"<equality><tendon {key}>")
        if "tendon2" in attrs:
            raise self.error(f"{what}: tendon2 (one tendon's length a polynomial of another's) is not supported yet")
        tendon = attrs.get("tendon1")
        if tendon in self.tendon_equalities:
            raise self.error(f"{what}: tendon1 {tendon!r} expected in one tendon equality, got a second")
        offset = self.numbers(attrs, "polycoef", (1, 2, 3, 4, 5), what, default=[0.0])[0]
        self.tendon_equalities[tendon] = (float(offset), softness)

    def _connect(self, attrs: dict, links: list[LinkSpec], what: str, softness: np.ndarray):
        """<equality><connect>: by bodies (body1, body2 or the world, anchor in body1's frame: body2's
        anchor is where that point is at qpos0) or by sites (site1, site2: their positions), as
        MuJoCo's compiler reads them; its rows as soft as ``softness`` says."""
        self._only(attrs, "connect", ("anchor",))
        if "site1" in attrs or "site2" in attrs:
            (body1, anchor1, _), (body2, anchor2, _) = self._site_pair(attrs, ("body1", "body2", "anchor"), what)
        else:
            body1, body2 = self._body_pair(attrs, links, what)
            anchor1, anchor2 = self.numbers(attrs, "anchor", 3, what), None
        if body1 == "world":  # the same rows, with the opposite sign
            (body1, anchor1), (body2, anchor2) = (body2, anchor2), (body1, anchor1)
        self._by_body(links)[body1].connects += (("" if body2 == "world" else body2, anchor1, anchor2, softness),)

    def _weld(self, attrs: dict, links: list[LinkSpec], what: str, softness: np.ndarray):
        """<equality><weld>: by bodies (body1, body2 or the world; anchor (default 0) in body2's frame;
        relpose (pos in body1's frame, quat): where its quat is zero, MuJoCo's default, both taken as
        they are at qpos0) or by sites (site1, site2: their frames), and torquescale, as MuJoCo's
        compiler reads them; its rows as soft as ``softness`` says."""
        self._only(attrs, "weld", ("anchor", "relpose", "torquescale"))
        torquescale = float(self.numbers(attrs, "torquescale", 1, what, default=[1.0])[0])
        if "site1" in attrs or "site2" in attrs:
            first, second = self._site_pair(attrs, ("body1", "body2", "anchor", "relpose"), what)
        else:
            body1, body2 = self._body_pair(attrs, links, what)
            relpose = self.numbers(attrs, "relpose", 7, what, default=[0, 1, 0, 0, 0, 0, 0])
            first = (body1, *((relpose[:3], relpose[3:]) if np.any(relpose[3:]) else (None, None)))
            second = (body2, self.numbers(attrs, "anchor", 3, what, default=np.zeros(3)), IDENTITY.copy())
        if first[0] == "world":  # the same rows, with the opposite sign
            first, second = second, first
        (body1, anchor1, turn1), (body2, anchor2, turn2) = first, second
        self._by_body(links)[body1].welds += (("" if body2 == "world" else body2, anchor1, anchor2, turn1, turn2,
                                               torquescale, softness),)

    def _only(self, attrs: dict, tag: str, own: tuple):
        """Note an equality's attributes that are not read (``own``: its kind's besides the common)."""
        for key in attrs:
            if key not in ("name", "class", "body1", "body2", "site1", "site2", "active", "solref", "solimp") + own:
                self.ignored.add(f"<equality><{tag} {key}>")

    @staticmethod
    def _by_body(links: list[LinkSpec]) -> dict:
        return {link.name: link for link in links}

    def _body_pair(self, attrs: dict, links: list[LinkSpec], what: str) -> tuple[str, str]:
        """(body1, body2) of an equality by bodies: bodies of the file or the world (body2's default)."""
        names = set(self._by_body(links)) | {"world"}
        body1, body2 = attrs.get("body1"), attrs.get("body2", "world")
        for key, name in (("body1", body1), ("body2", body2)):
            if name not in names:
                raise self.error(f"{what}: {key} expected a body of the file, got {name!r}")
        if body1 == body2:
            raise self.error(f"{what}: expected two different bodies, got {body1!r} twice")
        return body1, body2

    def _site_pair(self, attrs: dict, refused: tuple, what: str):
        """((body, position (3,), turn (4,)) of site1, the same of site2) of an equality by sites."""
        for key in refused:
            if key in attrs:
                raise self.error(f"{what}: expected sites or bodies, got site1/site2 with {key!r}")
        for key in ("site1", "site2"):
            if attrs.get(key) not in self.sites:
                raise self.error(f"{what}: {key} expected a site of the file, got {attrs.get(key)!r}")
        first, second = self.sites[attrs["site1"]], self.sites[attrs["site2"]]
        if first[0] == second[0]:
            raise self.error(f"{what}: expected two different bodies, got {first[0]!r} twice")
        return first, second

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
                if "world" in names and "world" not in by_body:  # (the worldbody has no geoms)
                    continue
                for name in names:
                    if name not in by_body:
                        raise self.error(f"<contact><exclude body1={names[0]!r} body2={names[1]!r}>: expected bodies "
                                         f"of the file, got {name!r}")
                by_body[names[0]].excluded += (names[1],)

    def _tendons(self, links: list[LinkSpec]):
        """<tendon><fixed>: a limited one (its length Σ coef·q of hinge and slide joints, range,
        solreflimit, solimplimit), one a tendon equality holds (self.tendon_equalities), one with
        a spring or damper (stiffness, damping, springlength: _spring_length) or friction loss
        (frictionloss, solreffriction, solimpfriction) on the link of its first joint
        (LinkSpec.tendons); its other attributes (armature…) and spatial tendons are named in the
        warning of what is ignored (a fixed tendon without any of them does nothing, as in
        MuJoCo)."""
        by_joint = {link.joint_name: link for link in links if link.joint_type in ("revolute", "prismatic")}
        held = dict(self.tendon_equalities)
        for section in self.root.iter("tendon"):
            for element in section:
                attrs = self.attrs(element, "main")
                what = f"<tendon><{element.tag} name={attrs.get('name')!r}>"
                if element.tag != "fixed":
                    if attrs.get("name") in held:
                        raise self.error(f"<equality><tendon tendon1={attrs['name']!r}>: tendon1 expected a fixed "
                                         f"tendon (a {element.tag} one is not supported yet)")
                    self.ignored.add(f"<tendon><{element.tag}>")
                    continue
                for key, value in attrs.items():
                    at_zero = key in ("margin", "armature") and \
                        not any(self.numbers(attrs, key, (1, 2), what))  # (MuJoCo's default: no effect)
                    if key not in ("name", "class", "limited", "range", "solreflimit", "solimplimit", "group",
                                   "rgba", "width", "material", "user", "stiffness", "damping", "springlength",
                                   "frictionloss", "solreffriction", "solimpfriction") \
                            and not is_default(key, value) and not at_zero:
                        self.ignored.add(f"<tendon><fixed {key}>")
                limited = self._limited(attrs, "range", "limited", self._range_given(attrs, "range", what), what)
                equality = held.pop(attrs.get("name"), None)
                stiffness, damping = (self._tendon_coefficient(attrs, key, what) for key in ("stiffness", "damping"))
                if stiffness:
                    self._refuse_unmodelled(attrs, what)
                frictionloss = float(self.numbers(attrs, "frictionloss", 1, what, default=[0.0])[0])
                if frictionloss < 0:  # (MuJoCo takes it and forms no row: refused rather than dropped)
                    raise self.error(f"{what}: frictionloss expected ≥ 0, got {attrs['frictionloss']!r}")
                if not (limited or equality or stiffness or damping or frictionloss):
                    unknown = [child.get("joint") for child in element if child.get("joint") not in by_joint]
                    if unknown:  # (it does nothing, but MuJoCo refuses it)
                        raise self.error(f"{what}: expected <joint joint coef> children naming hinge or slide joints "
                                         f"of the file, got {unknown}")
                    continue
                lower, upper = (self.numbers(attrs, "range", 2, what, default=[0.0, 0.0]) if limited
                                else (-np.inf, np.inf))
                if not lower < upper:
                    raise self.error(f"{what}: range expected lower < upper, got {attrs.get('range')!r}")
                joints, coefs = self._tendon_joints(element, by_joint, what)
                if equality is not None:  # (held at its length at qpos0 plus the offset)
                    rest = sum(c * by_joint[joint].q0 for joint, c in zip(joints, coefs))
                    equality = (rest + equality[0], equality[1])
                spring = None
                if stiffness or damping:
                    spring = (stiffness, damping, *self._spring_length(attrs, joints, coefs, by_joint, what))
                friction = None
                if frictionloss:
                    friction = (frictionloss, self._row_softness(attrs, "solreffriction", "solimpfriction", what))
                by_joint[joints[0]].tendons += ((tuple(joints), tuple(coefs), float(lower), float(upper),
                                                 self._row_softness(attrs, "solreflimit", "solimplimit", what),
                                                 equality, spring, friction),)
        if held:
            raise self.error(f"<equality><tendon>: tendon1 expected a fixed tendon of the file, got {sorted(held)}")

    def _tendon_coefficient(self, attrs: dict, key: str, what: str):
        """A fixed tendon's stiffness or damping (N/m or N·m/rad, per unit of its length); MuJoCo's
        polynomial form (several numbers) is refused."""
        values = self.numbers(attrs, key, tuple(range(1, 5)), what, default=[0.0])
        if len(values) > 1:
            raise self.error(f"{what}: a polynomial {key} is not supported yet, got {attrs[key]!r}")
        return float(values[0])

    def _spring_length(self, attrs: dict, joints, coefs, by_joint: dict, what: str):
        """(lower, upper) m or rad: where a fixed tendon's spring rests (MuJoCo's springlength: one
        value for both; "-1 -1", the default, its length at the joints' springrefs, MuJoCo's
        qpos_spring)."""
        given = self.numbers(attrs, "springlength", (1, 2), what, default=[-1.0, -1.0])
        lower, upper = float(given[0]), float(given[-1])
        if lower == -1.0 and upper == -1.0:
            lower = upper = float(sum(c * by_joint[joint].springref for joint, c in zip(joints, coefs)))
        if lower > upper:  # (MuJoCo's compiler refuses it too)
            raise self.error(f"{what}: springlength expected lower ≤ upper, got {attrs.get('springlength')!r}")
        return lower, upper

    def _tendon_joints(self, element, by_joint: dict, what: str):
        """(joint names, coefficients) of a fixed tendon's <joint joint coef> children (hinge or
        slide joints of the file; at most TENDON_JOINTS of them)."""
        joints, coefs = [], []
        for child in element:
            attrs = self.attrs(child, "main")
            if child.tag != "joint" or attrs.get("joint") not in by_joint:
                raise self.error(f"{what}: expected <joint joint coef> children naming hinge or slide joints of the "
                                 f"file, got <{child.tag} joint={attrs.get('joint')!r}>")
            joints.append(attrs["joint"])
            coefs.append(float(self.numbers(attrs, "coef", 1, what, default=[0.0])[0]))
        repeated = sorted({joint for joint in joints if joints.count(joint) > 1})
        if repeated:  # (MuJoCo refuses them too)
            raise self.error(f"{what}: joints expected once each, got {repeated} repeated")
        if not 0 < len(joints) <= TENDON_JOINTS:
            raise self.error(f"{what}: a limited, held, sprung or rubbing fixed tendon expected 1 to {TENDON_JOINTS} "
                             f"joints (more are not supported yet), got {len(joints)}")
        return joints, coefs

    def _actuators(self, links: list[LinkSpec]):
        """Each actuator of a hinge or slide joint as the joint's servo (_servo); then each one of a
        fixed tendon (_tendon_servo), for the joints no actuator drives directly."""
        by_joint = {link.joint_name: link for link in links if link.joint_type in ("revolute", "prismatic")}
        on_tendons, driven = [], set()
        for section in self.root.iter("actuator"):
            for element in section:
                attrs = self.attrs(element, "main")
                named = f"name={attrs['name']!r}" if attrs.get("name") else \
                    " ".join(f"{k}={attrs[k]!r}" for k in ("joint", "tendon", "site", "body") if k in attrs)
                what = f"<actuator><{element.tag} {named}>"
                self._note_mixed_defaults(element, what)
                for key in ("ctrlrange", "forcerange"):  # (every actuator's, read or not, as MuJoCo's compiler;
                    if not (key == "ctrlrange" and element.tag == "damper"):  # a damper's control is limited)
                        self._refuse_unflagged_range(attrs, key, key.replace("range", "limited"), what)
                if "joint" in attrs and attrs["joint"] not in self.joint_names:  # (MuJoCo refuses it too)
                    raise self.error(f"{what}: joint expected a joint of the file, got {attrs['joint']!r}")
                if "tendon" in attrs:
                    on_tendons.append((element.tag, attrs, what))
                elif attrs.get("joint") in by_joint:
                    self._servo(element.tag, attrs, by_joint[attrs["joint"]], what)
                    driven.add(attrs["joint"])
                else:
                    self.ignored.add(f"{what} (it drives no hinge or slide joint)")
        for kind, attrs, what in on_tendons:
            self._tendon_servo(kind, attrs, what, by_joint, driven)

    def _note_mixed_defaults(self, element, what: str):
        """Name an actuator whose class holds defaults of other actuator types: MuJoCo keeps one
        actuator default a class, which each type's element writes over (a <position> without kp
        takes kp from a <general> default's gainprm, a <general> a <position> default's servo),
        where here each type reads its own and <general>'s (an independent probe: kp 1 and 20 where
        MuJoCo's were 20 and 50)."""
        cls = element.get("class", "main")
        others = [tag for tag in ACTUATORS if tag != element.tag and self.defaults.get(cls, {}).get(tag)]
        if others:
            self.ignored.add(f"{what}: the defaults of other actuator types in its class {cls!r} "
                             f"({', '.join(f'<{tag}>' for tag in others)}; MuJoCo keeps one actuator default a class: "
                             f"its gains may differ from MuJoCo's)")

    def _tendon_servo(self, kind: str, attrs: dict, what: str, by_joint: dict, driven: set):
        """An actuator of a fixed tendon of hinge and slide joints, as Genesis approximates it: its
        servo gains and force bound on each of the tendon's joints that no actuator drives directly
        (MuJoCo applies one tendon force, times each joint's coefficient: not modelled; named in the
        load's warning)."""
        joints = None
        for section in self.root.iter("tendon"):
            for element in section:
                if element.tag == "fixed" and self.attrs(element, "main").get("name") == attrs["tendon"]:
                    joints = [self.attrs(child, "main").get("joint") for child in element if child.tag == "joint"]
        if not joints or any(joint not in by_joint for joint in joints):
            self.ignored.add(f"{what} (it drives no fixed tendon of hinge and slide joints)")
            return
        free = [joint for joint in joints if joint not in driven]
        self.ignored.add(f"{what}: approximated as Genesis does, its gains and force bound on each of the "
                         f"tendon's joints {free} (MuJoCo drives the tendon, each joint by its coefficient)")
        for joint in free:
            self._servo(kind, attrs, by_joint[joint], what)

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
        for key in ("damping", "armature"):  # (MuJoCo 4 adds them to what the actuator drives)
            if np.any(self.numbers(attrs, key, (1, 2, 3), what, default=[0.0]) != 0.0):
                self.ignored.add(f"<actuator {key}> (MuJoCo adds it to the driven joint's or tendon's)")


def place_world(links: list[LinkSpec], pos, quat) -> None:
    """Place the file's world frame at `pos` (3,) m, `quat` (4,) w-x-y-z: each root link's pose
    (one a body tree) becomes (pos, quat) ∘ its pose in the file, and so does each point and frame
    a connect or weld holds in the world."""
    for root in (link for link in links if link.parent < 0):
        root.pos, root.quat = shapes.compose(pos, quat, root.pos, root.quat)
    for link in links:  # a connect's or weld's point and frame given in the world move with it too
        link.connects = tuple((other, anchor, shapes.compose(pos, quat, other_anchor, IDENTITY)[0]
                               if other == "" and other_anchor is not None else other_anchor, softness)
                              for other, anchor, other_anchor, softness in link.connects)
        welds = []
        for other, anchor, other_anchor, turn, other_turn, torquescale, softness in link.welds:
            if other == "" and other_anchor is not None:  # (None: this link's frame at q0, already placed)
                other_anchor, other_turn = shapes.compose(pos, quat, other_anchor, other_turn)
            welds.append((other, anchor, other_anchor, turn, other_turn, torquescale, softness))
        link.welds = tuple(welds)


# -------------------------------------------------------------------- helpers


def _link(name, parent, joint_name, joint_type, pos, quat, axis=(0.0, 0.0, 1.0)) -> LinkSpec:
    return LinkSpec(name=name, parent=parent, joint_name=joint_name, joint_type=joint_type,
                    pos=np.asarray(pos, dtype=np.float64), quat=np.asarray(quat, dtype=np.float64),
                    axis=np.asarray(axis, dtype=np.float64), mass=0.0, com=np.zeros(3), inertia=np.zeros((3, 3)))


def _solid(geom: GeomSpec, density: float, mass: float | None, ellipsoid=None):
    """(mass kg, com (3,) m, inertia (3, 3) kg·m²) of a geom in its own frame: a solid of its
    density, or scaled to its stated mass (MuJoCo's rule); ``ellipsoid``: the semi-axes (3,) m of
    the ellipsoid whose polytope the geom is (weighed as the ellipsoid)."""
    if ellipsoid is not None:
        (own_mass, inertia), com = shapes.ellipsoid_mass_inertia(ellipsoid, density), np.zeros(3)
    else:
        own_mass, com, inertia = shapes.geom_mass_properties(geom, density)
    if mass is None or geom.type in ("plane", "hfield"):  # (no weight, its stated mass neither: a static ground)
        return own_mass, com, inertia
    return mass, com, inertia * (mass / own_mass) if own_mass > 0 else np.zeros((3, 3))
