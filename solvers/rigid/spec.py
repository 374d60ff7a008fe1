"""Plain-numpy description of an articulated body, as loaded from a morph.

A ``LinkSpec`` list is what the URDF loader and the primitive-shape builders produce and
what the rigid model builder consumes. Links are in tree order: ``parent < index``.
"""
from dataclasses import dataclass, field

import numpy as np

JOINT_TYPES = ("fixed", "revolute", "prismatic", "free", "ball")
TENDON_JOINTS = 3  # the most joints of a limited fixed tendon (its row's column slots, data.JOINT_ROW_SLOTS)


@dataclass
class ShapeSpec:
    """A shape attached to a link.

    type: "box" | "sphere" | "cylinder" | "capsule" | "mesh" | "plane" | "hfield"
    size: box (3,) full extents (m); sphere (1,) radius; cylinder/capsule (2,) radius, length
          (axis along local z); plane (3,) normal; mesh: empty; hfield (4,) MuJoCo's size: half
          extents x, y, the top's height at elevation 1, the base's depth (m).
    pos (3,) m and quat (4,) w-x-y-z: the shape's frame in the link frame.
    vertices (V, 3) m and faces (F, 3): the triangle mesh (mesh shapes only, else None).
    """
    type: str
    size: np.ndarray
    pos: np.ndarray = field(default_factory=lambda: np.zeros(3))
    quat: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0, 0.0]))
    vertices: np.ndarray = None
    faces: np.ndarray = None


@dataclass
class GeomSpec(ShapeSpec):
    """A collision shape. friction: Coulomb coefficient of contacts on this shape
    (dimensionless); friction_torsional, friction_rolling (m): its torsional and rolling friction
    (MuJoCo's geom friction's second and third, acting at condim 4 and 6); each None when
    neither the asset nor the material states one (the model then uses its default).
    contype, conaffinity: MuJoCo's collision bit masks (MJCF); two shapes may
    touch when (contype₁ & conaffinity₂) | (contype₂ & conaffinity₁) is non-zero.
    MuJoCo's contact parameters (MJCF; a pair of geoms combines them as mj_contactParam does):
    condim 1 (frictionless), 3 (sliding friction), 4 (and torsional) or 6 (and rolling; at
    least RigidOptions' enable_torsional_friction / enable_rolling_friction make it where it is
    3 or more); solref (2,) (timeconst s, dampratio), or
    (−stiffness, −damping) in the direct form, and solimp (5,) (dmin, dmax, width m, midpoint,
    power), each None for the scene's default; priority: the pair takes the parameters of its
    geom of higher priority; solmix: at equal priority, the weight of this geom's solref and
    solimp in the pair's. elevation: a height field's grid (row r at y = −size y + 2 size y ·
    r / (nrow − 1)), else None."""
    friction: float = None
    friction_torsional: float = None
    friction_rolling: float = None
    contype: int = 1
    conaffinity: int = 1
    condim: int = 3
    solref: np.ndarray = None
    solimp: np.ndarray = None
    priority: int = 0
    solmix: float = 1.0
    elevation: np.ndarray = None  # a height field's normalised grid (nrow, ncol) float32 in [0, 1] (hfield.py)


@dataclass
class VisualSpec(ShapeSpec):
    """A shape drawn by cameras; the physics never reads it. rgba (4,) in [0, 1]: the asset's
    colour (URDF ``<material>``), or None when it gives none (the entity's surface colour, else
    the default, is used)."""
    rgba: np.ndarray = None


@dataclass
class LinkSpec:
    """One link and the joint that attaches it to its parent.

    parent: index of the parent link in the list, -1 for the root.
    joint_type: one of JOINT_TYPES; "free" only for a root (6 dofs, 7 qs); "ball" (MuJoCo's ball
    joint: 3 dofs, the angular velocity in the link frame; 4 qs, the unit quaternion turning the
    link frame from (pos, quat), identity at start) anywhere.
    pos (3,) m, quat (4,) w-x-y-z: joint frame in the parent link frame (for the root: in the world).
    axis (3,): unit joint axis in the joint frame (= the child link frame).
    mass kg; com (3,) m in the link frame; inertia (3, 3) kg·m² about the com, link-frame axes.
    damping N·m·s/rad (or N·s/m), one value for all the joint's dofs or one per dof; armature kg·m²
    (or kg); frictionloss N·m (or N): the joint's dry friction (URDF ``<dynamics friction>``; a
    friction-loss constraint row).
    stiffness N·m/rad (or N/m) and springref rad (or m): a joint spring −stiffness·(q − springref)
    (MJCF ``stiffness``, ``springref``); a ball joint's is −stiffness·r on its dofs, r the
    rotation vector of its turn (MuJoCo's ball spring); a free joint has none.
    springdamper (2,) (time constant s, damping ratio) or None: MJCF ``springdamper``, which sets
    stiffness and damping at build from the joint's inertia at q0 (MuJoCo's compiler; see
    RigidSolver._with_springdamper).
    q0 rad (or m): a revolute or prismatic joint's initial position (MJCF ``ref``: the link frame is
    (pos, quat) at q = 0 whatever q0 is; the loader moved it).
    lower/upper: joint limits, rad or m (-inf/inf when unlimited; a ball joint's upper: the largest
    angle of its turn, MuJoCo's cone limit); effort: |force| bound (inf when none).
    kp N·m/rad (or N/m), kv N·m·s/rad (or N·s/m): the joint's servo gains, None for the solver's
    defaults.
    limit_sol, frictionloss_sol: (7,) the solref (2,) then solimp (5,) of the joint's limit and
    friction-loss rows (MJCF solreflimit, solimplimit, solreffriction, solimpfriction; MuJoCo's
    solref and solimp forms), NaN where the asset states none (the scene's default then), or
    None for all NaN.
    merged: (link name, fixed joint name) of every link merged into this one (merge.py), for
    error messages about names that no longer exist.
    visuals: VisualSpec list, what cameras draw of the link (URDF ``<visual>``; empty for
    primitive morphs, which are drawn from their geoms).
    mimic: (joint name, multiplier, offset) when this scalar joint follows another of the same
    entity, q = multiplier · q_other + offset (URDF ``<mimic>``): a joint equality constraint row
    (constraint/rows.py), as MuJoCo's and Genesis's; (None, 0, offset): the joint is held at q =
    offset (MJCF's joint equality without joint2); None otherwise. mimic_sol: (7,) its row's
    solref then solimp, as limit_sol (MJCF's equality solref and solimp), or None.
    same_body: the link continues its parent's body (MJCF: the links of one body's joints, which
    LinkSpec joints' frames split): contact rules take the two as one body.
    mass_stated: the asset states the link's mass (False: weighed from its shapes, a URDF link
    without <inertial> or its <mass>); merging fixed links adds a weighed part to a stated one
    not (merge.py).
    tendons: (joint names, their coefficients, lower, upper, softness (7,) as limit_sol, equality,
    spring, friction) per limited, held, sprung or rubbing fixed tendon whose first joint is this
    link's (MJCF
    ``<tendon><fixed>``, MuJoCo's: its length L = Σ coef·q, in [lower, upper] m or rad by a limit
    row (±inf: none), constraint/rows.py); equality: None, or (length m or rad, softness (7,))
    where an ``<equality><tendon>`` holds it at that length; spring: None, or (stiffness, damping,
    rest lower, rest upper): MuJoCo's passive tendon force −stiffness·(L − the nearer rest end, 0
    between them) − damping·L̇ (actuation.py); friction: None, or (friction loss N or N·m, softness
    (7,)): MuJoCo's friction row on L̇ (constraint/rows.py).
    excluded: names of links of the same entity this link's shapes never collide with (MJCF
    ``<contact><exclude>``).
    connects: (other link's name, or "" for the world; anchor (3,) m in this link's frame, or None:
    where the other's anchor is at q0; the other's anchor (3,) m in its frame, or None: where this
    anchor is at q0; not both None; its rows' solref then solimp (7,) as limit_sol, or None) per
    ball-and-socket constraint holding a point of this link on a point of another (MJCF ``<equality><connect>``,
    MuJoCo's connect: three equality rows, constraint/rows.py).
    welds: (other link's name, or "" for the world; anchor (3,) m in this link's frame, or None:
    where the other's anchor is at q0; the other's anchor (3,) m in its frame; turn (4,) w-x-y-z
    of this link's held frame in its frame, or None: the one that makes the two held frames one
    at q0; the other's (4,); torquescale; its rows' solref and solimp as a connect's; the other's
    anchor and turn may be None instead, then this link's are given and the other's held frame is
    theirs at q0) per weld holding a frame of this link on a frame of another, position and
    orientation (MJCF ``<equality><weld>``, MuJoCo's weld: six equality rows, the turn's three
    scaled by torquescale).
    gravcomp: the share of the link's weight a force at its centre of mass cancels, −gravcomp·m·g
    (MJCF ``<body gravcomp>``, MuJoCo's passive gravity compensation; Genesis's material
    ``gravity_compensation`` sets it on every link of an entity): 0 none, 1 all, above 1 buoyancy.
    """
    name: str
    parent: int
    joint_name: str
    joint_type: str
    pos: np.ndarray
    quat: np.ndarray
    axis: np.ndarray
    mass: float
    com: np.ndarray
    inertia: np.ndarray
    damping: float | tuple = 0.0
    frictionloss: float = 0.0
    armature: float = 0.0
    stiffness: float = 0.0
    springref: float = 0.0
    springdamper: tuple = None
    q0: float = 0.0
    lower: float = -np.inf
    upper: float = np.inf
    effort: float = np.inf
    kp: float = None
    kv: float = None
    limit_sol: np.ndarray = None
    frictionloss_sol: np.ndarray = None
    geoms: list = field(default_factory=list)
    merged: list = field(default_factory=list)
    visuals: list = field(default_factory=list)
    mimic: tuple = None
    mimic_sol: np.ndarray = None
    tendons: tuple = ()
    same_body: bool = False
    mass_stated: bool = True
    excluded: tuple = ()
    connects: tuple = ()
    welds: tuple = ()
    gravcomp: float = 0.0
