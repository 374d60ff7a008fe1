"""The rigid model: what the articulated bodies *are* (topology, geometry, default parameters).

Built once from every rigid entity's ``LinkSpec`` list; plain numpy, never changed after
build. Parameters a user may set and differentiate (masses, damping, gains...) start from the
defaults here and live in the solver's input tensors.
"""
import functools
from dataclasses import dataclass

import numpy as np

from . import geometry, shapes
from .spec import JOINT_TYPES, TENDON_JOINTS

FIXED, REVOLUTE, PRISMATIC, FREE, BALL = range(5)
JOINT_CODE = {name: code for code, name in enumerate(JOINT_TYPES)}
DOFS_OF = {FIXED: 0, REVOLUTE: 1, PRISMATIC: 1, FREE: 6, BALL: 3}
QS_OF = {FIXED: 0, REVOLUTE: 1, PRISMATIC: 1, FREE: 7, BALL: 4}

DEFAULT_KP = 100.0  # N·m/rad (or N/m), as Genesis
DEFAULT_KV = 10.0   # N·m·s/rad (or N·s/m)
MJ_MINVAL = 1e-15  # MuJoCo's mjMINVAL: a solmix weight below it counts as none
DEFAULT_FRICTION = 1.0  # contact friction coefficient where neither asset nor material states one, as Genesis
# torsional and rolling friction (m) where neither states one: MuJoCo's and Genesis's defaults
DEFAULT_FRICTION_TORSIONAL, DEFAULT_FRICTION_ROLLING = 0.005, 0.0001


@dataclass
class RigidModel:
    """Static arrays of all rigid links in the scene (L links, D dofs, Q qs, P mass-matrix pairs,
    G collision geoms).

    Per link: parent (L,) (-1: the world), jtype (L,) joint code, pos0 (L, 3) m and quat0 (L, 4)
    joint frame in the parent, axis (L, 3) in the link frame, com (L, 3) m, inertia0 (L, 3, 3)
    kg·m² about the com, mass0 (L,) kg, dof0/q0 (L,) first dof/q, entity (L,) owner index,
    gravcomp (L,) the share of its weight a force at its com cancels (LinkSpec.gravcomp).
    Per dof: link (D,), q (D,) its q index (-1 inside a free or ball joint: no scalar coordinate),
    damping, armature, kp, kv, stiffness (N·m/rad or N/m) and springref (rad or m) of a joint
    spring −stiffness·(q − springref), springdamper (D, 2) (time constant s, damping ratio; 0: none)
    from which the solver sets the spring's stiffness and the damping at build, lower/upper limits
    (rad or m; a ball joint's upper: its cone limit's angle, rad; the limit inputs' defaults), effort bound, frictionloss (N·m or N, dry joint friction: a constraint
    row), limit_sol and frictionloss_sol (D, 7) the solref and solimp of its limit and friction-loss
    rows (LinkSpec's; NaN: the scene's default, which the solver fills in). pairs (P, 2): (i, j),
    j ≤ i, dof j on the path from dof i to the root — the structural non-zeros of the lower mass
    matrix.
    Per collision geom (geometry.py, MuJoCo's conventions): geom_type (G,) code, geom_link (G,),
    geom_pos (G, 3) m and geom_quat (G, 4) in the link frame, geom_size (G, 3) half sizes m,
    geom_rbound (G,) bounding radius m, geom_aabb_center and geom_aabb_half (G, 3) m a bounding box
    in the geom frame (MuJoCo's geom_aabb), geom_centre (G, 3) m a point inside the geom (geom
    frame; a mesh's hull vertex mean), geom_mesh (G,) its mesh number (-1: none), the meshes'
    convex hulls as hull_vec (H, 3) and hull_int (HI,) (geometry.hull_arrays), geom_friction (G, 3)
    (sliding Coulomb coefficient, torsional m, rolling m), geom_solref (G, 2) and geom_solimp
    (G, 5) the asset's (NaN rows: the scene's default), geom_collides (G,) bool whether its contype or
    conaffinity is set (else it is in no pair: a morph with collision=False). Per candidate geom
    pair (N): pair_geom1/pair_geom2 (ordered as MuJoCo orders them), pair_condim (1, 3, 4 or 6),
    pair_mix the weight of geom1's solref and solimp in the pair's (1 − it geom2's), pair_copy 1
    where the geoms' priorities differ (the pair copies the higher one's friction, solref and
    solimp: pair_mix 1 or 0 says whose), else 0 (solimp mixed,
    solref mixed in the standard form and the smaller in the direct form, friction the larger:
    MuJoCo's mj_contactParam), pair_margin m.
    Per joint equality (E; URDF mimic joints, LinkSpec.mimic): eq_dof1 (E,) the following joint's
    dof, eq_dof2 (E,) the followed one's (−1: none, the joint is held at the offset: MuJoCo's
    joint equality without joint2), eq_coef (E, 2) (offset rad or m, multiplier): the row
    q[eq_dof1] = offset + multiplier · q[eq_dof2] (MuJoCo's joint equality with polycoef (offset,
    multiplier), which relates q − qpos0: the MJCF loader folds the joints' refs into the offset),
    eq_sol (E, 7) its row's solref and solimp (NaN: the scene's, which the solver fills in).
    Per connect or weld (K of them, the connects first, then the W welds; LinkSpec.connects and
    .welds, MuJoCo's connect and weld equalities): body_eq_link (K, 2) its two links (-1: the
    world), body_eq_anchor (2K, 3) m, rows 2k and 2k + 1 the points held together in their links'
    frames (the world's: world coordinates); per weld w: weld_turn (2W, 4) w-x-y-z, rows 2w and 2w
    + 1 the held frames' turns r1, r2 in their links' frames (q1 ⊗ r1 is held to q2 ⊗ r2),
    weld_torquescale (W,) the scale of its turn rows; body_eq_sol (K, 7) their rows' solref and
    solimp, as eq_sol.
    Per limited, held, sprung or rubbing fixed tendon (LinkSpec.tendons, MuJoCo's): its length Σ ten_coef·q over its
    ten_nnz (T,) dofs ten_dof (T, 3) (ascending; ten_coef (T, 3), padded with 0), held in
    [ten_lower, ten_upper] (m or rad; ±inf: no bound) by a limit row of softness ten_limit_sol (T,
    7), as eq_sol; where ten_eq (T,) is 1, held at ten_eq_length (T,) by an equality row of
    softness ten_eq_sol (T, 7) (MuJoCo's tendon equality without tendon2); pulled back by MuJoCo's
    passive tendon spring −ten_stiffness (T,) · (L − rest), rest the nearer end of ten_spring
    (T, 2) (lower, upper; 0 between), and damper −ten_damping (T,) · L̇ (N or N·m, per unit of L);
    held back by a friction row of bound ten_frictionloss (T,) (N or N·m; 0: none) and softness
    ten_friction_sol (T, 7), as eq_sol (MuJoCo's tendon friction loss).
    """
    link_name: list
    link_parent: np.ndarray
    link_jtype: np.ndarray
    link_pos0: np.ndarray
    link_quat0: np.ndarray
    link_axis: np.ndarray
    link_com: np.ndarray
    link_inertia0: np.ndarray
    link_mass0: np.ndarray
    link_dof0: np.ndarray
    link_q0: np.ndarray
    link_entity: np.ndarray
    link_gravcomp: np.ndarray
    dof_link: np.ndarray
    dof_q: np.ndarray
    dof_damping: np.ndarray
    dof_armature: np.ndarray
    dof_stiffness: np.ndarray
    dof_springdamper: np.ndarray
    dof_springref: np.ndarray
    dof_kp: np.ndarray
    dof_kv: np.ndarray
    dof_lower: np.ndarray
    dof_upper: np.ndarray
    dof_effort: np.ndarray
    dof_frictionloss: np.ndarray
    dof_limit_sol: np.ndarray
    dof_frictionloss_sol: np.ndarray
    geom_type: np.ndarray
    geom_link: np.ndarray
    geom_pos: np.ndarray
    geom_quat: np.ndarray
    geom_size: np.ndarray
    geom_rbound: np.ndarray
    geom_aabb_center: np.ndarray
    geom_aabb_half: np.ndarray
    geom_centre: np.ndarray
    geom_mesh: np.ndarray
    hull_vec: np.ndarray
    hull_int: np.ndarray
    geom_friction: np.ndarray
    geom_solref: np.ndarray
    geom_solimp: np.ndarray
    geom_collides: np.ndarray
    pair_geom1: np.ndarray
    pair_geom2: np.ndarray
    pair_condim: np.ndarray
    pair_mix: np.ndarray
    pair_copy: np.ndarray
    pair_margin: np.ndarray
    pairs: np.ndarray
    qpos0: np.ndarray
    eq_dof1: np.ndarray
    eq_dof2: np.ndarray
    eq_coef: np.ndarray
    eq_sol: np.ndarray
    body_eq_link: np.ndarray
    body_eq_anchor: np.ndarray
    weld_turn: np.ndarray
    weld_torquescale: np.ndarray
    body_eq_sol: np.ndarray
    ten_nnz: np.ndarray
    ten_dof: np.ndarray
    ten_coef: np.ndarray
    ten_lower: np.ndarray
    ten_upper: np.ndarray
    ten_limit_sol: np.ndarray
    ten_eq: np.ndarray
    ten_eq_length: np.ndarray
    ten_eq_sol: np.ndarray
    ten_stiffness: np.ndarray
    ten_damping: np.ndarray
    ten_spring: np.ndarray
    ten_frictionloss: np.ndarray
    ten_friction_sol: np.ndarray

    @property
    def n_tendons(self):
        return len(self.ten_lower)

    @property
    def link_inertia(self):
        """(L, 3, 3) kg·m²: the rotational inertia each link starts with (the input "inertia"):
        inertia0, and 0 for a massless link (its stated inertia is dropped, as MuJoCo does)."""
        return self.link_inertia0 * (self.link_mass0 > 0)[:, None, None]

    @property
    def link_static(self):
        """(L,) 1 for a link welded to the world (no dof on it or above it, like a fixed robot's
        base): it never moves, and no dof carries its inertia or forces."""
        return _static_links(self.link_parent, self.link_jtype)

    @property
    def link_root(self):
        """(L,) int32: the root link of each link's kinematic tree (the link itself for a root).
        The tree's spatial quantities are taken about the root link's origin (kinematics.py)."""
        return _roots(self.link_parent)

    @property
    def dof_parent(self):
        """(D,) the dof just above each dof on its path to the root (-1: none). The mass matrix's
        non-zeros follow this tree, so factoring along it creates no fill-in."""
        parent = np.full(self.n_dofs, -1, dtype=np.int32)
        last_dof = {}  # link → its last dof
        for i, l in enumerate(self.dof_link):
            last_dof[int(l)] = i
        for i, l in enumerate(self.dof_link):
            if i > self.link_dof0[l]:
                parent[i] = i - 1
                continue
            ancestor = self.link_parent[l]
            while ancestor >= 0 and int(ancestor) not in last_dof:
                ancestor = self.link_parent[ancestor]
            parent[i] = last_dof[int(ancestor)] if ancestor >= 0 else -1
        return parent

    @property
    def pair_i(self):
        """(P,) the row dof of each mass-matrix pair."""
        return self.pairs[:, 0]

    @property
    def pair_j(self):
        """(P,) the column dof of each mass-matrix pair (an ancestor-or-self of the row's)."""
        return self.pairs[:, 1]

    @property
    def dof_pair0(self):
        """(D,) the first mass-matrix pair of each dof's row (pairs are sorted by row, then column)."""
        return np.searchsorted(self.pairs[:, 0], np.arange(self.n_dofs)).astype(np.int32)

    @property
    def n_links(self):
        return len(self.link_name)

    @property
    def n_dofs(self):
        return len(self.dof_link)

    @property
    def n_qs(self):
        return len(self.qpos0)

    @property
    def n_eq(self):
        return len(self.eq_dof1)

    @property
    def n_body_eq(self):
        """Connects and welds."""
        return len(self.body_eq_link)

    @property
    def n_weld(self):
        return len(self.weld_torquescale)

    @functools.cached_property
    def has_equalities(self):
        """Whether some equality row is always formed (a joint equality, a connect, a weld or a held
        tendon). Kept: every step asks."""
        return self.n_eq + self.n_body_eq + int(self.ten_eq.sum()) > 0


def _static_links(link_parent, link_jtype):
    static = np.zeros(len(link_parent), dtype=np.int32)
    for l in range(len(link_parent)):  # parents come before their children
        p = link_parent[l]
        static[l] = link_jtype[l] == FIXED and (p < 0 or static[p])
    return static


def initial_q(spec):
    """A LinkSpec joint's qpos at build: a free joint's placement (pos, quat), a ball's identity
    quaternion, a hinge's or slide's q0 (an MJCF ref), none for a fixed joint."""
    if spec.joint_type == "free":
        return list(spec.pos) + list(spec.quat)
    if spec.joint_type == "ball":
        return [1.0, 0.0, 0.0, 0.0]
    return [spec.q0] * QS_OF[JOINT_CODE[spec.joint_type]]


def _roots(link_parent):
    """(L,) int32: the root link of each link's tree, a parent listed before its children."""
    root = np.arange(len(link_parent), dtype=np.int32)
    for l, parent in enumerate(link_parent):
        if parent >= 0:
            root[l] = root[parent]
    return root


def _mass_matrix_pairs(dof_link, link_parent):
    """(P, 2) the pairs (i, j ≤ i) with dof j on dof i's path to the root (its link or an ancestor's),
    sorted by i then j: a walk up each dof's links (comparing every pair of dofs was quadratic:
    seconds at a few thousand dofs)."""
    dofs_of = {}
    for i, l in enumerate(dof_link.tolist()):
        dofs_of.setdefault(l, []).append(i)
    pairs = []
    for i, l in enumerate(dof_link.tolist()):
        on_path = []
        while l >= 0:
            on_path.extend(j for j in dofs_of.get(l, ()) if j <= i)
            l = int(link_parent[l])
        pairs.extend((i, j) for j in sorted(on_path))
    return np.array(pairs, dtype=np.int32).reshape(-1, 2)


def build_model(entities_links, self_collision=True, adjacent_collision=False, attachments=None, condim_floor=3,
                entity_names=None):
    """Concatenate entities' link lists (each in tree order) into one RigidModel.

    entities_links: list of ``list[LinkSpec]``; a free root joint takes its initial pose from
    the root spec's pos/quat, which are then reset to identity (the qs carry the pose).
    self_collision / adjacent_collision: the pair rules of geometry.candidate_pairs.
    condim_floor: 3, or 4 (torsional friction) or 6 (and rolling) on every geom whose condim is
    less but 3 or more (RigidOptions' enable_torsional_friction, enable_rolling_friction).
    attachments: {entity index: (parent entity index, its link index)}: that entity's first link
    hangs from that link of an earlier entity (its spec's pos/quat: where, in that link's frame;
    its joint fixed), one kinematic tree with it (Genesis's RigidEntity.attach).
    entity_names: each entity's name, for the errors of its geoms (None: the links' names alone).
    """
    rows = {k: [] for k in ("name", "parent", "jtype", "pos0", "quat0", "axis", "com", "inertia0", "mass0",
                            "dof0", "q0", "entity", "gravcomp", "same_body", "excluded")}
    dofs = {k: [] for k in ("link", "q", "damping", "armature", "stiffness", "springref", "springdamper", "lower",
                            "upper", "effort", "frictionloss", "kp", "kv", "limit_sol", "frictionloss_sol")}
    geoms, geom_links, geom_names = [], [], []
    qpos0, equalities, connects, welds, tendons = [], [], [], [], []
    entity_offsets = []
    for entity_idx, links in enumerate(entities_links):
        link_offset = len(rows["name"])
        entity_offsets.append(link_offset)
        attached = (attachments or {}).get(entity_idx)
        joint_dof = {}  # the entity's joint names → their first dof
        for spec in links:
            code = JOINT_CODE[spec.joint_type]
            free = code == FREE
            vector = code in (FREE, BALL)  # dofs without a scalar coordinate: no scalar limit or servo target
            rows["name"].append(spec.name)
            if attached is not None and spec is links[0]:
                rows["parent"].append(entity_offsets[attached[0]] + attached[1])
            else:
                rows["parent"].append(spec.parent + link_offset if spec.parent >= 0 else -1)
            rows["jtype"].append(code)
            rows["pos0"].append(np.zeros(3) if free else spec.pos)
            rows["quat0"].append(np.array([1.0, 0, 0, 0]) if free else spec.quat)
            rows["axis"].append(spec.axis)
            rows["com"].append(spec.com)
            rows["inertia0"].append(spec.inertia)
            rows["mass0"].append(spec.mass)
            rows["dof0"].append(len(dofs["link"]))
            rows["q0"].append(len(qpos0))
            rows["entity"].append(entity_idx)
            rows["gravcomp"].append(spec.gravcomp)
            rows["same_body"].append(spec.same_body)
            link_idx = len(rows["name"]) - 1
            joint_dof[spec.joint_name] = len(dofs["link"])
            for k in range(DOFS_OF[code]):
                dofs["link"].append(link_idx)
                dofs["q"].append(-1 if vector else len(qpos0))
                dofs["damping"].append(float(np.broadcast_to(spec.damping, DOFS_OF[code])[k]))  # (one, or per dof)
                dofs["armature"].append(spec.armature)
                dofs["stiffness"].append(0.0 if free else spec.stiffness)  # (a ball joint's: MuJoCo's ball spring)
                dofs["springref"].append(0.0 if vector else spec.springref)
                dofs["springdamper"].append((0.0, 0.0) if spec.springdamper is None else spec.springdamper)
                dofs["lower"].append(-np.inf if vector else spec.lower)
                dofs["upper"].append(np.inf if free else spec.upper)  # (a ball joint's: its cone's angle)
                dofs["effort"].append(np.inf if vector else spec.effort)
                dofs["frictionloss"].append(spec.frictionloss)  # (a free or ball joint's on each dof, as MuJoCo's)
                dofs["kp"].append(DEFAULT_KP if vector or spec.kp is None else spec.kp)
                dofs["kv"].append(DEFAULT_KV if vector or spec.kv is None else spec.kv)
                for key in ("limit_sol", "frictionloss_sol"):
                    dofs[key].append(_softness(getattr(spec, key)))
            for k, geom in enumerate(spec.geoms):
                geoms.append(geom)
                geom_links.append(link_idx)
                owner = "" if entity_names is None else f"entity '{entity_names[entity_idx]}': "
                geom_names.append(f"{owner}link '{spec.name}' collision geom {k}")
            qpos0.extend(initial_q(spec))
        equalities += [(joint_dof[spec.joint_name], -1 if spec.mimic[0] is None else joint_dof[spec.mimic[0]],
                        spec.mimic[2], spec.mimic[1], _softness(spec.mimic_sol))
                       for spec in links if spec.mimic is not None]
        tendons += [_tendon(tendon, joint_dof) for spec in links for tendon in spec.tendons]
        index = {spec.name: link_offset + k for k, spec in enumerate(links)}
        entity_connects, entity_welds = _body_equalities(links, index)
        connects, welds = connects + entity_connects, welds + entity_welds
        rows["excluded"] += [{(min(link_offset + k, index[other]), max(link_offset + k, index[other]))
                              for other in spec.excluded} for k, spec in enumerate(links)]
    f = np.float64
    dof_link = np.array(dofs["link"], dtype=np.int32)
    link_parent = np.array(rows["parent"], dtype=np.int32)
    return RigidModel(
        link_name=rows["name"], link_parent=link_parent,
        link_jtype=np.array(rows["jtype"], dtype=np.int32),
        link_pos0=np.array(rows["pos0"], dtype=f).reshape(-1, 3),
        link_quat0=np.array(rows["quat0"], dtype=f).reshape(-1, 4),
        link_axis=np.array(rows["axis"], dtype=f).reshape(-1, 3),
        link_com=np.array(rows["com"], dtype=f).reshape(-1, 3),
        link_inertia0=np.array(rows["inertia0"], dtype=f).reshape(-1, 3, 3),
        link_mass0=np.array(rows["mass0"], dtype=f),
        link_dof0=np.array(rows["dof0"], dtype=np.int32), link_q0=np.array(rows["q0"], dtype=np.int32),
        link_entity=np.array(rows["entity"], dtype=np.int32), link_gravcomp=np.array(rows["gravcomp"], dtype=f),
        dof_link=dof_link, dof_q=np.array(dofs["q"], dtype=np.int32),
        dof_damping=np.array(dofs["damping"], dtype=f), dof_armature=np.array(dofs["armature"], dtype=f),
        dof_stiffness=np.array(dofs["stiffness"], dtype=f), dof_springref=np.array(dofs["springref"], dtype=f),
        dof_springdamper=np.array(dofs["springdamper"], dtype=f).reshape(-1, 2),
        dof_kp=np.array(dofs["kp"], dtype=f), dof_kv=np.array(dofs["kv"], dtype=f),
        dof_lower=np.array(dofs["lower"], dtype=f), dof_upper=np.array(dofs["upper"], dtype=f),
        dof_effort=np.array(dofs["effort"], dtype=f), dof_frictionloss=np.array(dofs["frictionloss"], dtype=f),
        dof_limit_sol=np.array(dofs["limit_sol"], dtype=f).reshape(-1, 7),
        dof_frictionloss_sol=np.array(dofs["frictionloss_sol"], dtype=f).reshape(-1, 7),
        **_geoms(geoms, geom_links, geom_names), **_pairs(geoms, geom_links, rows, self_collision, adjacent_collision,
                                                      condim_floor),
        pairs=_mass_matrix_pairs(dof_link, link_parent),
        qpos0=np.array(qpos0, dtype=f), eq_dof1=np.array([q[0] for q in equalities], dtype=np.int32),
        eq_dof2=np.array([q[1] for q in equalities], dtype=np.int32),
        eq_coef=np.array([q[2:4] for q in equalities], dtype=f).reshape(-1, 2),
        eq_sol=np.array([q[4] for q in equalities], dtype=f).reshape(-1, 7),
        body_eq_link=np.array([c[:2] for c in connects + welds], dtype=np.int32).reshape(-1, 2),
        body_eq_anchor=np.array([c[2:4] for c in connects + welds], dtype=f).reshape(-1, 3),
        weld_turn=np.array([w[4:6] for w in welds], dtype=f).reshape(-1, 4),
        weld_torquescale=np.array([w[6] for w in welds], dtype=f),
        body_eq_sol=np.array([c[-1] for c in connects + welds], dtype=f).reshape(-1, 7),
        ten_nnz=np.array([len(t[0]) for t in tendons], dtype=np.int32),
        ten_dof=np.array([_padded(t[0], 0) for t in tendons], dtype=np.int32).reshape(-1, TENDON_JOINTS),
        ten_coef=np.array([_padded(t[1], 0.0) for t in tendons], dtype=f).reshape(-1, TENDON_JOINTS),
        ten_lower=np.array([t[2] for t in tendons], dtype=f), ten_upper=np.array([t[3] for t in tendons], dtype=f),
        ten_limit_sol=np.array([t[4] for t in tendons], dtype=f).reshape(-1, 7),
        ten_eq=np.array([t[5] for t in tendons], dtype=np.int32),
        ten_eq_length=np.array([t[6] for t in tendons], dtype=f),
        ten_eq_sol=np.array([t[7] for t in tendons], dtype=f).reshape(-1, 7),
        ten_stiffness=np.array([t[8][0] for t in tendons], dtype=f),
        ten_damping=np.array([t[8][1] for t in tendons], dtype=f),
        ten_spring=np.array([t[8][2:] for t in tendons], dtype=f).reshape(-1, 2),
        ten_frictionloss=np.array([t[9] for t in tendons], dtype=f),
        ten_friction_sol=np.array([t[10] for t in tendons], dtype=f).reshape(-1, 7))


def _body_equalities(links, index):
    """(connects, welds) of an entity's links (LinkSpec.connects, .welds): (link 1, link 2, anchor 1
    (3,), anchor 2 (3,)) per connect, and those and (turn 1 (4,), turn 2 (4,), torquescale) per weld,
    links as model indices (``index``: name → index; the world -1), what is missing (one side's
    anchor, or frame) from the other side's at q0 (MuJoCo's compiler: at qpos0)."""
    if not any(spec.connects or spec.welds for spec in links):
        return [], []
    poses = dict(zip((spec.name for spec in links), _initial_poses(links)))
    poses[""] = (np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]))  # the world
    connects, welds = [], []
    for spec in links:
        this = poses[spec.name]
        for other, anchor, other_anchor, softness in spec.connects:
            if anchor is None:
                anchor = _in_frame(this, _at(poses[other], other_anchor))
            if other_anchor is None:
                other_anchor = _in_frame(poses[other], _at(this, anchor))
            connects.append((index[spec.name], index[other] if other else -1, np.asarray(anchor, dtype=np.float64),
                             np.asarray(other_anchor, dtype=np.float64), _softness(softness)))
        for other, anchor, other_anchor, turn, other_turn, torquescale, softness in spec.welds:
            if other_anchor is None:  # (then this link's frame is given)
                other_anchor = _in_frame(poses[other], _at(this, anchor))
                other_turn = _turn_onto(poses[other], this, turn)
            other_anchor, other_turn = (np.asarray(v, dtype=np.float64) for v in (other_anchor, other_turn))
            if anchor is None:
                anchor = _in_frame(this, _at(poses[other], other_anchor))
            if turn is None:
                turn = _turn_onto(this, poses[other], other_turn)
            welds.append((index[spec.name], index[other] if other else -1, np.asarray(anchor, dtype=np.float64),
                          other_anchor, np.asarray(turn, dtype=np.float64) / np.linalg.norm(turn),
                          other_turn / np.linalg.norm(other_turn), float(torquescale), _softness(softness)))
    return connects, welds


def _tendon(tendon, joint_dof):
    """(dofs, coefficients, lower, upper, softness, held (0 or 1), held length, its softness, spring
    (stiffness, damping, rest lower, rest upper), friction loss, its softness) of a LinkSpec tendon,
    its joints' dofs in ascending order (the rows' columns)."""
    joints, coefs, lower, upper, softness, equality, spring, friction = tendon
    order = sorted(range(len(joints)), key=lambda k: joint_dof[joints[k]])
    held = (1, equality[0], _softness(equality[1])) if equality is not None else (0, 0.0, _softness(None))
    rubbing = (friction[0], _softness(friction[1])) if friction is not None else (0.0, _softness(None))
    return ([joint_dof[joints[k]] for k in order], [coefs[k] for k in order], lower, upper, _softness(softness),
            *held, (0.0, 0.0, 0.0, 0.0) if spring is None else tuple(spring), *rubbing)


def _padded(values, pad):
    """``values`` filled with ``pad`` to TENDON_JOINTS entries (a tendon's row of ten_dof, ten_coef)."""
    return list(values) + [pad] * (TENDON_JOINTS - len(values))


def _softness(given):
    """(7,) a row's solref and solimp as LinkSpec gives them (None: all NaN, the scene's)."""
    return np.full(7, np.nan) if given is None else np.asarray(given, dtype=np.float64)


def _turn_onto(pose, other_pose, other_turn):
    """The turn r (4,) w-x-y-z of a frame held at ``pose`` that is the frame ``other_turn`` held at
    ``other_pose`` (q ⊗ r = q_other ⊗ r_other; poses (position (3,), w-x-y-z (4,)))."""
    return shapes.quat_mul(shapes.quat_mul(pose[1] * [1, -1, -1, -1], other_pose[1]), other_turn)


def _at(pose, point):
    """World position (3,) of ``point`` (3,) given in the frame pose = (position (3,), w-x-y-z (4,))."""
    return pose[0] + shapes.quat_to_mat(pose[1]) @ point


def _in_frame(pose, point):
    """``point`` (3,) in the world → in the frame pose = (position (3,), w-x-y-z (4,))."""
    return shapes.quat_to_mat(pose[1]).T @ (point - pose[0])


def _initial_poses(links):
    """[(position (3,) m, w-x-y-z (4,))] of each link in the world at q0 (a tree in order): a free
    root at its spec's pose, a ball joint unturned (its q0), a hinge or slide at its q0."""
    poses = []
    for spec in links:
        parent = (np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])) if spec.parent < 0 else poses[spec.parent]
        pos, quat = shapes.compose(*parent, spec.pos, spec.quat)
        if spec.joint_type == "revolute":
            quat = shapes.quat_mul(quat, np.array([np.cos(spec.q0 / 2), *np.sin(spec.q0 / 2) * spec.axis]))
        elif spec.joint_type == "prismatic":
            pos = pos + shapes.quat_to_mat(quat) @ spec.axis * spec.q0
        poses.append((pos, quat))
    return poses


def _geoms(geoms, geom_links, geom_names):
    arrays = geometry.geom_arrays(geoms, geom_links, lambda k: geom_names[k])
    out = {k if k.startswith("hull_") else f"geom_{k}": v for k, v in arrays.items()}
    defaults = (DEFAULT_FRICTION, DEFAULT_FRICTION_TORSIONAL, DEFAULT_FRICTION_ROLLING)
    out["geom_friction"] = np.array(
        [[default if value is None else value
          for value, default in zip((g.friction, g.friction_torsional, g.friction_rolling), defaults)]
         for g in geoms], dtype=np.float64).reshape(-1, 3)
    for name, n in (("solref", 2), ("solimp", 5)):
        out[f"geom_{name}"] = np.array([np.full(n, np.nan) if getattr(g, name) is None else getattr(g, name)
                                        for g in geoms], dtype=np.float64).reshape(-1, n)
    out["geom_collides"] = np.array([bool(g.contype or g.conaffinity) for g in geoms], dtype=bool)
    return out


def _pairs(geoms, geom_links, rows, self_collision, adjacent_collision, condim_floor):
    link_parent = np.array(rows["parent"], dtype=np.int32)
    static = _static_links(link_parent, np.array(rows["jtype"]))
    types = np.array([geometry.GEOM_CODE[g.type] for g in geoms], dtype=np.int32)
    masks = np.array([(g.contype, g.conaffinity) for g in geoms], dtype=np.int64).reshape(-1, 2)
    body, weld = np.arange(len(link_parent)), np.arange(len(link_parent))
    for link, same in enumerate(rows["same_body"]):  # (parents first)
        parent = link_parent[link]
        body[link] = body[parent] if same else link
        # (a link welded to the world stays its own group: MuJoCo's parent filter skips the world)
        welded = same or (rows["jtype"][link] == FIXED and not static[link])
        weld[link] = weld[parent] if parent >= 0 and welded else link
    pairs = geometry.candidate_pairs(types, np.array(geom_links, dtype=np.int32), link_parent, static,
                                     _roots(link_parent), self_collision, adjacent_collision, masks, body, weld,
                                     rows["excluded"])
    return {"pair_geom1": pairs[:, 0].copy(), "pair_geom2": pairs[:, 1].copy(),
            **_pair_params(geoms, pairs, condim_floor),
            "pair_margin": np.zeros(len(pairs))}


def _pair_params(geoms, pairs, condim_floor):
    """pair_condim, pair_mix, pair_copy (RigidModel) of the (N, 2) geom pairs, as MuJoCo's
    mj_contactParam combines two geoms: the higher priority's, or at equal priority the larger
    condim and solmix weights (a weight below MuJoCo's mjMINVAL counts as zero; both zero: 0.5);
    a geom's condim raised to condim_floor where it is 3 or more (build_model)."""
    condim, mix, copy = (np.zeros(len(pairs), dtype=t) for t in (np.int32, np.float64, np.int32))
    dims = [max(g.condim, condim_floor) if g.condim >= 3 else g.condim for g in geoms]
    for k, (a, b) in enumerate(pairs.tolist()):
        g1, g2 = geoms[a], geoms[b]
        if g1.priority != g2.priority:
            first = g1.priority > g2.priority
            condim[k], mix[k], copy[k] = dims[a if first else b], float(first), 1
            continue
        condim[k] = max(dims[a], dims[b])
        weighs1, weighs2 = g1.solmix >= MJ_MINVAL, g2.solmix >= MJ_MINVAL
        mix[k] = (g1.solmix / (g1.solmix + g2.solmix) if weighs1 and weighs2
                  else 0.5 if weighs1 == weighs2 else float(weighs1))
    return {"pair_condim": condim, "pair_mix": mix, "pair_copy": copy}
