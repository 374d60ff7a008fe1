"""Storage of the rigid solver: the model's constants, the per-step inputs, the state frames of
one step and every intermediate quantity, each indexed by substep frame.

Frame f of ``qpos``/``qvel`` is the state before substep f (frame S is the step's result).
Intermediates of substep f live at frame f, so after a single forward replay every substep's
values are there for its hand-written adjoint. Gradients (``.grad``) are that adjoint's
storage (Taichi's autodiff is not used).

**Compiled once for every scene.** All of a scene's data lives in five torch tensors, one per
element type (``ARENAS``: int, float, 3-vector, 4-vector, 3×3 matrix), passed to every kernel as
arguments. Sizes (envs, links, dofs...) and where each array starts are runtime values at the
int arena's start (its header and offsets table), so a kernel is compiled once per float
precision and serves every robot, batch size and substep count; Taichi compiles field-based
kernels per field instance instead (a second scene of the same robot recompiled everything:
20 s). Inside a kernel, ``bind`` turns the arenas into a :class:`RigidView` whose arrays index
like fields: ``d.xpos[s, e, l]``, ``d.mass.grad[e, l]``, ``d.mass_mat[s, e, i, j]``.
"""
import warnings

import numpy as np
import taichi as ti
import torch
from taichi.lang import impl
from taichi.lang.expr import Expr

from ..core import InvalidInputError, runtime
from .spec import TENDON_JOINTS
from .collision.convex import CONVEX_PAIRS, FEATURE_SIZE, HFIELD
from .collision.convex import SCRATCH as CONVEX_SCRATCH
from .constraint.solver import SCRATCH as SOLVER_SCRATCH

BIG = 1e30  # stands for an absent bound
# Up to this many (env, link) pairs the kernels run on the calling thread. In a rollout, handing a
# loop to Taichi's thread pool costs ~100 µs here (its workers fall asleep between steps), while
# one thread does a link's substep in ~0.1 µs forward and ~0.3 µs reverse; measured on the KUKA,
# 256 envs (2048 pairs) ran faster serial (differentiable rollout 157 ms against 196 on the pool,
# its env loop spread out: env_loop), 1024 envs 50% faster on two threads.
SERIAL_LINK_ENVS = 2048
# Up to this many (env, dof) pairs the constraint solve and its reverse run on the calling thread
# too: an env's solve costs several µs to tens (a box on a plane: 16 rows, ~4 µs; the 10-box tower:
# 60 dofs, ~50 µs), so the pool pays off sooner than for the link loops. Measured with 2 threads
# (µs an env-step, calling thread → pool): the box at 128 envs 4.2 → 4.1, 256 envs 4.5 → 2.7; the
# a1 at 256 envs 11.2 → 8.0; the tower at 128 envs 74 → 40.
SERIAL_SOLVE_WORK = 384

# Per-step inputs: name → (width per env, differentiable). Their order is the packing order.
INPUTS = {
    "mass": ("L", True),        # kg
    "com": ("L3", True),        # m: each link's centre of mass in its frame (x, y, z a link)
    # kg·m²: each link's rotational inertia about its centre of mass, in its frame (3 × 3 row-major a link)
    "inertia": ("L9", True),
    "damping": ("D", True),     # N·m·s/rad or N·s/m
    "armature": ("D", True),    # kg·m² or kg
    "stiffness": ("D", True),   # N·m/rad or N/m: a joint spring −stiffness·(q − springref) (actuation.py)
    "kp": ("D", True),          # N·m/rad or N/m
    "kv": ("D", True),          # N·m·s/rad or N·s/m
    "gravity": (3, True),       # m/s²
    "ctrl_force": ("D", True),  # N·m or N
    "ctrl_pos": ("D", True),    # rad or m
    "ctrl_vel": ("D", True),    # rad/s or m/s
    # per link, for one step: an external force (N) at the link origin and a torque (N·m), world
    # frame (entity.apply_links_external_wrench), 6 a link
    "xfrc": ("L6", True),
    "frictionloss": ("D", True),  # N·m or N: dry joint friction, a constraint row (constraint/rows.py)
    # per collision geom: (sliding Coulomb coefficient, torsional m, rolling m), MuJoCo's geom_friction
    # (a pair takes the larger of each; the torsional and rolling ones act at condim 4 and 6)
    "friction": ("G3", True),
    "solref": ("G2", True),     # per geom: (time constant s, damping ratio), or (−stiffness, −damping)
    "solimp": ("G5", True),     # per geom: (d0, dwidth, width m, midpoint, power) of the impedance
    # MuJoCo's body_invweight0 (translation, 1/kg) per link and dof_invweight0 per dof (1/kg or
    # 1/(kg·m²)): the rows' scale (constraint/rows.py), derived from mass and armature at the initial
    # pose (contact.InvweightBasis, with the build's centres of mass), never set by hand
    "invweight_t": ("L", True),
    "invweight_r": ("L", True),  # rotation, 1/(kg·m²): a weld's turn rows
    "invweight_dof": ("D", True),
    "invweight_ten": ("T", True),  # MuJoCo's tendon_invweight0 per limited fixed tendon: J M⁻¹ Jᵀ at q0
    "force_lo": ("D", True),    # N·m or N: the actuator force's bounds
    "force_hi": ("D", True),
    # rad or m: each scalar dof's position limits (±inf: none); a ball joint's first dof's upper: its
    # cone limit's angle, rad (constraint/rows.py)
    "limit_lower": ("D", True),
    "limit_upper": ("D", True),
    # welds made at run time (RigidOptions.max_dynamic_constraints slots, DW): how many are on, then
    # per slot (the first that many on) its two links (model indices, as floats), each link's anchor
    # (3,) m in its frame and each link's held frame's turn (4,) w-x-y-z in its frame: 1 + 16·DW;
    # differentiable in the anchors and turns (taken from the state where a weld is made)
    "dyn_welds": ("DWW", True),
    "ctrl_mode": ("D", False),  # 0 force, 1 position, 2 velocity (see actuation.py)
}
DYN_WELD = 16  # the floats of one run-time weld in dyn_welds

CONSTS = ("h", "timeconst", "impratio", "tolerance", "ls_tolerance")
CONST = {name: k for k, name in enumerate(CONSTS)}  # where each is in the model's "consts"

# Model constants: name → (arena, count). Per link (L), per dof (D), per mass-matrix pair (P).
MODEL = {
    "link_parent": ("i", "L"), "link_root": ("i", "L"), "link_jtype": ("i", "L"), "link_static": ("i", "L"),
    "link_dof0": ("i", "L"), "link_q0": ("i", "L"), "dof_link": ("i", "D"), "dof_q": ("i", "D"), "dof_parent": ("i", "D"),
    "pair_i": ("i", "P"), "pair_j": ("i", "P"), "dof_pair0": ("i", "D"),
    # collision geometry (geometry.py; MuJoCo's conventions) and the candidate geom pairs
    "geom_type": ("i", "G"), "geom_link": ("i", "G"), "geom_mesh": ("i", "G"), "hull_int": ("i", "HI"),
    "pair_geom1": ("i", "N"), "pair_geom2": ("i", "N"), "pair_condim": ("i", "N"), "pair_copy": ("i", "N"),
    "geom_rbound": ("f", "G"), "pair_margin": ("f", "N"), "pair_mix": ("f", "N"),
    "geom_pos": ("v3", "G"), "geom_size": ("v3", "G"), "hull_vec": ("v3", "H"), "geom_quat": ("v4", "G"),
    "geom_aabb_center": ("v3", "G"), "geom_aabb_half": ("v3", "G"), "geom_centre": ("v3", "G"),
    "link_gravcomp": ("f", "L"),
    "dof_springref": ("f", "D"),  # rad or m: where a joint spring is at rest
    "dof_limit_sol": ("f", "D7"), "dof_frictionloss_sol": ("f", "D7"),  # (solref, solimp) of a dof's rows
    # joint equalities (URDF mimic joints; RigidModel says what they hold)
    "eq_dof1": ("i", "E"), "eq_dof2": ("i", "E"), "eq_coef": ("f", "E2"), "eq_sol": ("f", "E7"),
    # connects and welds (points and frames of two links held together; RigidModel says what they hold)
    "body_eq_link": ("i", "K2"), "body_eq_anchor": ("v3", "K2"), "weld_turn": ("v4", "WD2"),
    "weld_torquescale": ("f", "WD"), "body_eq_sol": ("f", "K7"),
    # limited, held, sprung or rubbing fixed tendons (RigidModel says what they hold; TENDON_JOINTS a tendon's joints)
    "ten_nnz": ("i", "T"), "ten_dof": ("i", "T3"), "ten_coef": ("f", "T3"), "ten_lower": ("f", "T"),
    "ten_upper": ("f", "T"), "ten_limit_sol": ("f", "T7"), "ten_eq": ("i", "T"), "ten_eq_length": ("f", "T"),
    "ten_eq_sol": ("f", "T7"), "ten_stiffness": ("f", "T"), "ten_damping": ("f", "T"), "ten_spring": ("f", "T2"),
    "ten_frictionloss": ("f", "T"), "ten_friction_sol": ("f", "T7"),
    # substep h (s), the time constant (s) of the joint rows (equality, limit, friction loss), impratio, solver
    # tolerance and line-search tolerance: runtime values like everything else (CONSTS names them)
    "consts": ("f", len(CONSTS)),
    "link_pos0": ("v3", "L"), "link_axis": ("v3", "L"), "link_com": ("v3", "L"), "link_quat0": ("v4", "L"),
}

JOINT_ROW_SLOTS = max(3, TENDON_JOINTS)  # columns a joint row may have (constraint/rows.py): a ball joint's cone limit, three

# Per-frame arrays: name → (arena, count per env, has a gradient). "DD": a (D, D) matrix per env.
FRAMES = {
    "qpos": ("f", "Q", True), "qvel": ("f", "D", True),
    "xpos": ("v3", "L", True), "xquat": ("v4", "L", False),
    # a link's own inertia has no gradient array: its gradient is its subtree sum's (crb)
    "cinert_m": ("f", "L", False), "cinert_h": ("v3", "L", False), "cinert_i": ("m3", "L", False),
    "crb_m": ("f", "L", True), "crb_h": ("v3", "L", True), "crb_i": ("m3", "L", True),
    "cdof_w": ("v3", "D", True), "cdof_v": ("v3", "D", True),
    "cvel_w": ("v3", "L", True), "cvel_v": ("v3", "L", True),
    "cacc_w": ("v3", "L", True), "cacc_v": ("v3", "L", True),
    "cfrc_n": ("v3", "L", True), "cfrc_f": ("v3", "L", True),
    "dof_force_n": ("v3", "D", False), "dof_force_f": ("v3", "D", False),
    "mass_mat": ("f", "DD", True),
    "qfrc_bias": ("f", "D", True), "qfrc_smooth": ("f", "D", True), "qacc": ("f", "D", True),
    "factor": ("f", "DD", False),  # LᵀDL factor of M + diag(armature + h·damping)
    # contact (collision.py): geom poses, then the contacts found (count in n_con[s, e, 0])
    "geom_xpos": ("v3", "G", True), "geom_xmat": ("m3", "G", True),  # gradient of xmat: ∂L/∂ each entry
    "n_con": ("i", 1, False), "con_pair": ("i", "C", False), "con_feature": ("i", "CF", False),
    "con_pos": ("v3", "C", True), "con_frame": ("m3", "C", True), "con_dist": ("f", "C", True),
    "con_efc": ("i", "C", False),  # each contact's first row
    "n_near": ("i", 1, False), "near_pairs": ("i", "N", False),  # the broad phase's pairs (collision/detect.py)
    # constraint rows (constraint/rows.py; n_efc[s, e, 0] in use) and the solve (constraint/solver.py)
    "n_efc": ("i", 1, False), "efc_dof_rows": ("i", 1, False),  # rows in use; of them, the joint rows first
    "efc_type": ("i", "R", False), "efc_dim": ("i", "R", False),
    "efc_id": ("i", "R", False), "efc_state": ("i", "R", False),
    "efc_J": ("f", "RD", False),
    # each row's non-zero columns: efc_cols[efc_col0 …] (efc_ncol of them, ascending), a contact's
    # rows sharing its list (from c·D), a joint row r (an equality's two dofs, a single dof, a ball joint's
    # three) at joint_row_columns + JOINT_ROW_SLOTS·r, a connect's or weld's rows (body equality k)
    # sharing a list at body_eq_columns + k·D
    "efc_col0": ("i", "R", False), "efc_ncol": ("i", "R", False), "efc_cols": ("i", "CD", False), "efc_R": ("f", "R", False), "efc_aref": ("f", "R", False),
    "efc_floss": ("f", "R", False), "efc_mu": ("f", "R", False), "efc_force": ("f", "R", False),
    "solver_M": ("f", "DD", False), "qacc_smooth": ("f", "D", False), "qacc_constrained": ("f", "D", True),
    "qfrc_constraint": ("f", "D", True), "solver_niter": ("i", 1, False),
    # the solve's work arrays (the final Hessian factor among them, for the backward)
    **{name: (arena, count, False) for name, (arena, count) in SOLVER_SCRATCH.items()},
}
# Per-env arrays that persist from step to step: name → (arena, count per env), indexed [e, k]
PER_ENV = {"qacc_warmstart": ("f", "D"),  # the constraint solve's start: the last substep's solution
           "needs_rows": ("i", 1),  # 1: the one-launch step met a violated joint limit (step.advance)
           # the convex colliders' workspace (collision/convex.py), when the scene has such pairs
           **{name: (arena, f"ws:{name}") for name, (arena, _) in CONVEX_SCRATCH.items()}}
# a link's rotation is differentiated as a small world-frame turn δθ, not through its quaternion
# (see kinematics.py): xrot_grad is ∂L/∂δθ, a gradient with no value array
GRAD_ONLY = {"xrot_grad": ("v3", "L")}

ARENAS = ("i", "f", "v3", "v4", "m3")
ELEMENT = {"i": (), "f": (), "v3": (3,), "v4": (4,), "m3": (3, 3)}  # each arena's element shape
# the kernels' annotations of the arenas: Taichi takes the float type from the tensors, the
# element shape from the annotation (so one kernel source serves both precisions)
ARENA_TYPES = (ti.types.ndarray(dtype=ti.i32, ndim=1), ti.types.ndarray(ndim=1),
               ti.types.ndarray(dtype=ti.types.vector(3, float), ndim=1),
               ti.types.ndarray(dtype=ti.types.vector(4, float), ndim=1),
               ti.types.ndarray(dtype=ti.types.matrix(3, 3, float), ndim=1))
# The int arena starts with a header of sizes and flags, then the offsets table (OFFSETS: where
# every array starts, which follows from the sizes by ``layout``, and the strides kernels need).
# E joint equalities, K connects and welds, WD welds of them (RigidModel), DW run-time weld slots
# (RigidOptions.max_dynamic_constraints; their data are the input dyn_welds), T limited fixed
# tendons. W: all inputs' width per env; GW: the differentiable ones', which come first. G geoms,
# N candidate geom pairs, H hull vertices, C contact slots, R constraint rows per env (see
# RigidData); HI the meshes' hull ints (geometry.py), WS 1 when the convex colliders need their
# workspace (CONVEX_SCRATCH), else 0; converged 1 (not enable_mujoco_compatibility) when curved
# convex contacts are their converged closed form (collision/detect.py: converge_contacts) and the
# elliptic solve takes a Newton step past MuJoCo's stop (constraint/solver.py); constrained a flag:
# some env of the substep has a constraint row to form (a contact, a joint equality, friction
# loss, a violated limit); colliders_due a mask of the collider kernels the substep's near pairs
# need (collision/detect.py: KERNEL_BIT); inexact_pair, inexact_env, inexact_substep: where the
# last inexact contact was (the backward's error names it); capped a flag: a constraint solve
# stopped at its iteration limit before its tolerance; gravcomp 1 when some link's gravity is
# compensated (RigidModel.link_gravcomp), else its force stage is skipped.
SIZES = ("B", "L", "D", "Q", "P", "E", "K", "WD", "DW", "T", "S", "W", "GW", "limits", "nonfinite", "G", "N",
         "H", "C", "R", "cone", "iterations", "ls_iterations", "overflow", "rows_needed", "HI", "WS", "inexact", "converged",
         "constrained", "colliders_due", "inexact_pair", "inexact_env", "inexact_substep", "wrench", "capped",
         "gravcomp")
HEADER = {name: k for k, name in enumerate(SIZES)}
# the header's slots a step raises or the host sets, not sizes (what a grown copy keeps: take_over)
FLAGS = ("nonfinite", "overflow", "rows_needed", "inexact", "constrained", "colliders_due", "inexact_pair",
         "inexact_env", "inexact_substep", "wrench", "capped")
assert len(HEADER) == len(SIZES), "one slot a size"
_REGIONS = [("i", False)] + [(a, g) for g in (False, True) for a in ("f", "v3", "v4", "m3")]  # (arena, gradients?)

assert [diff for _, diff in INPUTS.values()] == sorted((diff for _, diff in INPUTS.values()), reverse=True), \
    "differentiable inputs come first"


def input_width(name, model, n_dyn_welds):
    width, n_geoms = INPUTS[name][0], len(model.geom_type)
    return {"L": model.n_links, "L3": 3 * model.n_links, "L6": 6 * model.n_links, "L9": 9 * model.n_links,
            "D": model.n_dofs, "G": n_geoms,
            "G2": 2 * n_geoms, "G3": 3 * n_geoms, "G5": 5 * n_geoms, "T": model.n_tendons,
            "DWW": 1 + DYN_WELD * n_dyn_welds}.get(width, width)


def _region_members(arena, grads):
    """(name, count) of the arrays in an arena's frame region (values, or gradients)."""
    if not grads:
        return [(n, c) for n, (a, c, _) in FRAMES.items() if a == arena]
    return ([(n, c) for n, (a, c, g) in FRAMES.items() if a == arena and g]
            + [(n, c) for n, (a, c) in GRAD_ONLY.items() if a == arena])


def layout(size, ints_begin):
    """Where every array starts in its arena, from the sizes ``size`` (name → value, SIZES), the
    int arena's arrays from ``ints_begin`` on (after the header and the offsets table).

    Returns (start, end): start["model:NAME"], ["inputs"], ["inputs.grad"] (B, W),
    ["frame:NAME"], ["grad:NAME"], and per frame region ["region:ARENA:GRADS"] and
    ["stride:ARENA:GRADS"] (one frame of all its arrays); end[ARENA, GRADS] is where the arena's
    values (GRADS False) or gradients end. Model arrays come first, then (float arena) the
    inputs and their gradients, then per arena the frames of its arrays — frame s of all of them,
    then frame s + 1... — then their gradients laid out alike, so that zeroing the gradients of
    frames 0 … k − 1 is one contiguous sweep per arena."""
    B = size["B"]
    count = _counts(size)
    end = {"i": ints_begin, "f": 0, "v3": 0, "v4": 0, "m3": 0}
    start = {}
    for name, (arena, c) in MODEL.items():
        start[f"model:{name}"] = end[arena]
        end[arena] += count[c]
    start["inputs"], start["inputs.grad"] = end["f"], end["f"] + B * size["W"]
    end["f"] = start["inputs.grad"] + B * size["W"]
    for name, (arena, c) in PER_ENV.items():
        start[f"env:{name}"] = end[arena]
        end[arena] += B * count[c]
    stop = {("i", False): end["i"], ("i", True): end["i"]}
    for arena, grads in _REGIONS:
        region = offset = end[arena]
        for name, c in _region_members(arena, grads):
            start[f"{'grad' if grads else 'frame'}:{name}"] = offset
            offset += B * count[c]
        start[f"region:{arena}:{grads}"], start[f"stride:{arena}:{grads}"] = region, offset - region
        end[arena] = stop[arena, grads] = region + (size["S"] + 1) * (offset - region)
    stop["i", True] = stop["i", False]  # no integer array has a gradient
    return start, stop


def offsets(size, ints_begin):
    """What the kernels read of the offsets table (OFFSETS, in the int arena after the header):
    every array's start (``layout``), each input's start and its gradient's (the inputs' start
    plus the input's column), the per-env count of every frame and per-env array (their env
    stride) and where the constraint rows' column lists start. Computed here once, each a single
    load inside a kernel: summed there from the sizes, every array access carried its start's
    whole sum (dozens of size products) into LLVM's scalar evolution, whose loop strength
    reduction was most of a kernel's cold compile."""
    start, _ = layout(size, ints_begin)
    count = _counts(size)
    table = dict(start)
    column = 0
    for name, (width, _) in INPUTS.items():
        table[f"input:{name}"] = start["inputs"] + column
        table[f"input.grad:{name}"] = start["inputs.grad"] + column
        column += count.get(width, width)
    for c in dict.fromkeys([c for _, c, _ in FRAMES.values()] + [c for _, c in PER_ENV.values()]
                           + [c for _, c in GRAD_ONLY.values()]):
        table[f"count:{c}"] = count[c]
    table["joint_columns"], table["body_eq_columns"] = joint_row_columns(size), body_eq_columns(size)
    return table


def _has_convex_pairs(model):
    """Whether a candidate pair goes to convex CCD (convex_convex, or a height field's prisms: its
    workspace is then allocated)."""
    kinds = zip(model.geom_type[model.pair_geom1].tolist(), model.geom_type[model.pair_geom2].tolist())
    return any(kind in CONVEX_PAIRS or kind[0] == HFIELD for kind in kinds)


def joint_row_columns(size):
    """Where the joint rows' column slots start in efc_cols (JOINT_ROW_SLOTS a row, from row 0):
    after the contacts' lists (D a contact)."""
    return size["C"] * size["D"]


def body_eq_columns(size):
    """Where the connects' and welds' column lists start in efc_cols (D each: its rows' list; the
    run-time welds' after the model's): after the joint rows' slots (at most a row per joint
    equality, three per connect, six per weld and per run-time weld slot, two per dof, three per
    tendon: its equality's, its friction loss's and its limit's). K counts connects and welds, WD
    the welds, DW the run-time weld slots."""
    rows = size["E"] + 3 * size["K"] + 3 * size["WD"] + 6 * size["DW"] + 2 * size["D"] + 3 * size["T"]
    return joint_row_columns(size) + JOINT_ROW_SLOTS * rows


def _counts(size):
    """Element count per env of each count name used in MODEL and FRAMES."""
    D, R = size["D"], size["R"]
    return {"L": size["L"], "D": D, "Q": size["Q"], "P": size["P"], "DD": D * D, "G": size["G"], "N": size["N"],
            "H": size["H"], "C": size["C"], "CF": FEATURE_SIZE * size["C"], "HI": size["HI"], "R": R, "RD": R * D,
            "CD": body_eq_columns(size) + (size["K"] + size["DW"]) * D, "DWW": 1 + DYN_WELD * size["DW"],
            "E": size["E"], "E2": 2 * size["E"], "E7": 7 * size["E"], "K2": 2 * size["K"], "K7": 7 * size["K"],
            "T": size["T"], "T2": 2 * size["T"], "T3": TENDON_JOINTS * size["T"], "T7": 7 * size["T"],
            "WD": size["WD"], "WD2": 2 * size["WD"],
            "G2": 2 * size["G"], "G3": 3 * size["G"], "G5": 5 * size["G"],
            "L3": 3 * size["L"], "L6": 6 * size["L"], "L9": 9 * size["L"],
            "D7": 7 * D, 1: 1,
            len(CONSTS): len(CONSTS),
            **{f"ws:{name}": size["WS"] * n for name, (_, n) in CONVEX_SCRATCH.items()}}


# the offsets table's slots in the int arena, after the header (its entries' values depend on the
# sizes, their names do not); the int arena's arrays start after it
OFFSETS = {key: len(SIZES) + k for k, key in enumerate(offsets(dict.fromkeys(SIZES, 1), 0))}
INTS_BEGIN = len(SIZES) + len(OFFSETS)


class RigidData:
    """The arenas of one scene's rigid solver (B envs, S substeps, sizes from the model).

    ``arenas`` are the kernels' array arguments, in ARENAS order; ``schedule`` is their one
    compile-time argument: whether the compute loops and the data-moving loops run on the
    calling thread (see SERIAL_LINK_ENVS); ``solve_schedule`` is that of the kernels that run
    the constraint solve or its reverse (SERIAL_SOLVE_WORK).
    """

    def __init__(self, model, n_batch, substeps, requires_grad, settings):
        """settings: limits (joint limits on?), consts (CONSTS values), contacts (C) and rows (R)
        per env, cone (1: elliptic), iterations and ls_iterations of the solve."""
        on_cpu = runtime.arch == ti.cpu
        # (compute loops, data-moving loops) on the calling thread? On the CPU small batches and
        # every data move are (a hand-off to the pool costs more, see SERIAL_LINK_ENVS); on a GPU
        # nothing is (one GPU thread would do it all)
        self.schedule = (on_cpu and n_batch * max(1, model.n_links) <= SERIAL_LINK_ENVS, on_cpu)
        # the same for the kernels of the constraint stage (SERIAL_SOLVE_WORK)
        self.solve_schedule = (self.schedule[0] and n_batch * max(1, model.n_dofs) <= SERIAL_SOLVE_WORK, on_cpu)
        n_geoms = len(model.geom_type)
        self.widths = [input_width(name, model, settings["dyn_welds"]) for name in INPUTS]
        self.input_total = sum(self.widths)
        self.grad_total = sum(w for w, (_, diff) in zip(self.widths, INPUTS.values()) if diff)
        self.grad_input_names = [n for n, (_, diff) in INPUTS.items() if diff] if requires_grad else []
        self.size = {"B": n_batch, "L": model.n_links, "D": model.n_dofs, "Q": model.n_qs, "P": len(model.pairs),
                     "E": model.n_eq, "K": model.n_body_eq, "WD": model.n_weld, "DW": settings["dyn_welds"],
                     "T": model.n_tendons,
                     "S": substeps, "W": self.input_total, "GW": self.grad_total,
                     "limits": int(bool(settings["limits"])), "nonfinite": 0, "G": n_geoms,
                     "N": len(model.pair_geom1), "H": len(model.hull_vec), "C": settings["contacts"],
                     "R": settings["rows"], "cone": settings["cone"], "iterations": settings["iterations"],
                     "ls_iterations": settings["ls_iterations"], "overflow": 0, "rows_needed": 0,
                     "HI": len(model.hull_int), "WS": int(_has_convex_pairs(model)), "inexact": 0,
                     "converged": int(bool(settings["converged"])), "constrained": 0,
                     "colliders_due": 0, "inexact_pair": 0, "inexact_env": 0, "inexact_substep": 0, "wrench": 0,
                     "capped": 0, "gravcomp": int(np.any(model.link_gravcomp != 0))}
        self.start, stop = layout(self.size, INTS_BEGIN)
        length = {a: stop[a, bool(requires_grad)] for a in ARENAS}  # no gradient storage without gradients
        if max(length.values()) >= 2 ** 31:  # indices inside kernels are 32-bit
            raise InvalidInputError(f"rigid solver: n_envs={n_batch} with substeps={substeps} (requires_grad="
                                    f"{bool(requires_grad)}) expected arrays of fewer than 2**31 elements, got "
                                    f"{max(length.values())}; use fewer envs or substeps per scene")
        values = {a: np.zeros((max(1, length[a]), *ELEMENT[a]), dtype=np.int32 if a == "i" else runtime.np_float)
                  for a in ARENAS}
        self._fill(values, model, settings["consts"])
        # torch owns the memory (freed with the scene, whatever Taichi does meanwhile)
        self.arenas = [torch.from_numpy(values[a]).to(runtime.device) for a in ARENAS]
        # the header's flags, read after every step with contacts: on the CPU a numpy view of the
        # int arena (~0.1 µs a read, against ~15 µs for a torch scalar read and write)
        self.header = self.arenas[0].numpy() if self.arenas[0].device.type == "cpu" else self.arenas[0]
        self.flags_on_host = isinstance(self.header, np.ndarray)  # a read costs no wait for a device
        self._frame_views = {}  # (name, s) → frame()'s view, made once (a step reads some every time)
        self._env_views = {}  # name → per_env()'s view, likewise

    def _fill(self, values, model, consts):
        """Header, model and consts (CONSTS) into the arenas."""
        values["i"][: len(SIZES)] = [self.size[name] for name in SIZES]
        table = offsets(self.size, INTS_BEGIN)
        values["i"][len(SIZES): INTS_BEGIN] = [table[key] for key in OFFSETS]
        for name, (arena, _) in MODEL.items():
            array = np.asarray(consts if name == "consts" else getattr(model, name))
            if arena in ("i", "f"):  # scalar arenas: a (E, 2) array goes in row by row
                array = array.reshape(-1)
            if len(array):
                begin = self.start[f"model:{name}"]
                # floats finite, so no inf·0 in gradients
                values[arena][begin: begin + len(array)] = array if arena == "i" else np.clip(array, -BIG, BIG)

    def take_flag(self, name):
        """The header's flag ``name`` if a step raised it ("nonfinite": a non-finite state;
        "overflow": more contacts than slots; "rows_needed": an env of the one-launch step met a
        joint limit; "inexact": a contact came from a collider whose replay is not exact;
        "constrained": a substep's smooth stage or colliders found a constraint row to form;
        "colliders_due": the mask of collider kernels a substep needs; "capped": a constraint solve
        stopped at its iteration limit before its tolerance) since the last call, which
        clears it. Returns its value (an int, 0 when not raised)."""
        slot = HEADER[name]
        flag = int(self.header[slot])
        if flag:
            self.header[slot] = 0
        return flag

    def per_env(self, name):
        """The (B, count) torch view of a PER_ENV array (made once: a contact step reads one twice)."""
        if name not in self._env_views:
            arena, count = PER_ENV[name]
            begin, n = self.start[f"env:{name}"], self.size["B"] * _counts(self.size)[count]
            self._env_views[name] = self.arenas[ARENAS.index(arena)][begin: begin + n].view(self.size["B"], -1)
        return self._env_views[name]

    def frame(self, name, s):
        """The (B, count) torch view of frame s of a FRAMES array (its values)."""
        if (name, s) not in self._frame_views:
            arena, count, _ = FRAMES[name]
            begin = self.start[f"frame:{name}"] + s * self.start[f"stride:{arena}:False"]
            n = self.size["B"] * _counts(self.size)[count]
            self._frame_views[name, s] = self.arenas[ARENAS.index(arena)][begin: begin + n].view(self.size["B"], -1)
        return self._frame_views[name, s]

    def width(self, name):
        return self.widths[list(INPUTS).index(name)]

    def take_over(self, old):
        """Copy what ``old`` (the same model and batch, fewer contact slots) holds: the header's flags,
        the inputs, the per-env arrays and every frame's values, an array of contacts or rows into
        the first slots of its longer one. Gradients are not copied: every reverse zeroes them first
        (step.prepare_reverse). efc_cols, whose joint rows' slots follow the contacts' lists, is copied
        so too: a substep's lists are written by its constraint stage and read by nothing after it (a
        backward replays the step), so earlier substeps' lists out of place are never read."""
        for name in FLAGS:
            self.header[HEADER[name]] = old.header[HEADER[name]]
        floats = ARENAS.index("f")
        self.arenas[floats][self.start["inputs"]:self.start["inputs.grad"]] = \
            old.arenas[floats][old.start["inputs"]:old.start["inputs.grad"]]
        for name in PER_ENV:
            self.per_env(name).copy_(old.per_env(name))
        for name in FRAMES:
            for s in range(self.size["S"] + 1):
                before = old.frame(name, s)
                self.frame(name, s)[:, :before.shape[1]] = before


# -- inside kernels ------------------------------------------------------------------------------
def _subscript(array, index):
    return impl.subscript(None, array, index)


def _components(index):
    """Index components from a tuple or a Taichi vector expression."""
    if isinstance(index, (tuple, list)):
        return list(index)
    if isinstance(index, Expr) and index.is_tensor():
        return [_subscript(index, k) for k in range(index.get_shape()[0])]
    return [index]


class ArrayView:
    """One array inside an arena, indexed like a field: element [i0, i1, ...] is arena[start +
    Σ i_k·stride_k]; ``grad`` is the view of its gradient (None when it has none)."""
    _data_oriented = True  # lets Taichi keep the object itself in kernel scope

    def __init__(self, arena, start, strides, grad=None):
        self.arena, self.start, self.strides, self.grad = arena, start, strides, grad

    def __getitem__(self, index):
        offset = self.start
        for i, stride in zip(_components(index), self.strides):
            offset = offset + i * stride
        return _subscript(self.arena, offset)


class Region:
    """The gradients of one arena: frame k of all of them is [start + k·stride, start + (k+1)·stride);
    shape: the arena's element shape (ELEMENT)."""
    _data_oriented = True

    def __init__(self, arena, start, stride, shape):
        self.arena, self.start, self.stride, self.shape = arena, start, stride, shape


class RigidView:
    """Kernel-scope view of one scene's arenas: sizes (``n_links``...) as local variables and
    every array of MODEL, INPUTS, FRAMES and GRAD_ONLY as an :class:`ArrayView`. ``cone``: the
    friction cone as a compile-time value (True: elliptic), for the kernels of the constraint
    solve and its reverse, which then leave the other cone's code out; None: read at run time.
    ``body_eqs``: whether connects' and welds' rows are compiled into those kernels (a compile-time
    value: their code made a cold compile of a box on a plane's 15-20 s longer each).
    ``max_condim``: the largest contact condim those kernels handle, 3 or 6 (3: the torsional and
    rolling rows' code left out, as a scene without them needs: the box's constrain ran ~15 %
    slower at 1024 envs with it in; a scene of condim 4 takes 6's kernels); ``row_slots`` the
    most rows a contact then has (a pyramid's 2 (condim − 1)), the length of the reverse's
    per-row vectors."""
    _data_oriented = True

    def __init__(self, ints, f1, v3, v4, m3, cone=None, body_eqs=True, max_condim=6):
        arenas = dict(zip(ARENAS, (ints, f1, v3, v4, m3)))
        size = {name: impl.expr_init(_subscript(ints, k)) for name, k in HEADER.items()}
        at = {key: impl.expr_init(_subscript(ints, k)) for key, k in OFFSETS.items()}  # (see offsets)
        self.n_batch, self.n_links, self.n_dofs, self.n_qs = size["B"], size["L"], size["D"], size["Q"]
        self.n_pairs, self.substeps, self.input_total, self.grad_total = size["P"], size["S"], size["W"], size["GW"]
        self.n_eq, self.n_body_eq, self.n_weld, self.n_tendons = size["E"], size["K"], size["WD"], size["T"]
        self.n_connect, self.body_eqs = size["K"] - size["WD"], body_eqs  # (the connects come first)
        self.max_condim, self.row_slots = max_condim, 2 * (max_condim - 1)
        self.joint_columns, self.body_eq_columns = at["joint_columns"], at["body_eq_columns"]
        self.limits_enabled = size["limits"]
        self.n_geoms, self.n_candidates = size["G"], size["N"]
        self.contact_capacity = size["C"]
        self.elliptic = size["cone"] if cone is None else bool(cone)
        self.iterations, self.ls_iterations = size["iterations"], size["ls_iterations"]
        self.converged = size["converged"]
        self.wrench = size["wrench"]  # 1 when the step's inputs hold an external wrench (xfrc)
        self.gravcomp = size["gravcomp"]  # 1 when some link's gravity is compensated (link_gravcomp)
        self.nonfinite = ArrayView(ints, HEADER["nonfinite"], (1,))  # set by the NaN check
        self.overflow = ArrayView(ints, HEADER["overflow"], (1,))  # set when contacts exceed their slots
        self.rows_needed = ArrayView(ints, HEADER["rows_needed"], (1,))  # set when an env's needs_rows is
        # set when a contact's collider has no exact replay (collision/detect.py: replay_exact)
        self.inexact = ArrayView(ints, HEADER["inexact"], (1,))
        self.inexact_where = ArrayView(ints, HEADER["inexact_pair"], (1,))  # [0] pair, [1] env, [2] substep
        # set when an env of the substep has a constraint row to form (the host then runs the solve)
        self.constrained = ArrayView(ints, HEADER["constrained"], (1,))
        self.colliders_due = ArrayView(ints, HEADER["colliders_due"], (1,))  # bits of the collider kernels due
        self.capped = ArrayView(ints, HEADER["capped"], (1,))  # set when a solve stops at its iteration limit
        for name, (arena, _) in MODEL.items():
            setattr(self, name, ArrayView(arenas[arena], at[f"model:{name}"], (1,)))
        row = (self.input_total, 1)  # [e, column]
        self.inputs = ArrayView(f1, at["inputs"], row, ArrayView(f1, at["inputs.grad"], row))
        for name in INPUTS:
            setattr(self, name, ArrayView(f1, at[f"input:{name}"], row, ArrayView(f1, at[f"input.grad:{name}"], row)))
        for name, (arena, c) in PER_ENV.items():
            setattr(self, name, ArrayView(arenas[arena], at[f"env:{name}"], (at[f"count:{c}"], 1)))
        for name, (arena, c, has_grad) in FRAMES.items():
            grad = None
            if has_grad:
                grad = ArrayView(arenas[arena], at[f"grad:{name}"], self._frame_strides(at, arena, c, size, True))
            setattr(self, name, ArrayView(arenas[arena], at[f"frame:{name}"],
                                          self._frame_strides(at, arena, c, size, False), grad))
        for name, (arena, c) in GRAD_ONLY.items():
            setattr(self, name, ArrayView(arenas[arena], at[f"grad:{name}"],
                                          self._frame_strides(at, arena, c, size, True)))
        self.regions = [Region(arenas[a], at[f"region:{a}:True"], at[f"stride:{a}:True"], ELEMENT[a])
                        for a in ARENAS[1:]]

    @staticmethod
    def _frame_strides(at, arena, c, size, grads):
        frame = at[f"stride:{arena}:{grads}"]
        if c in ("DD", "RD"):  # [s, e, i, j]
            return frame, at[f"count:{c}"], size["D"], 1
        return frame, at[f"count:{c}"], 1  # [s, e, k]


@ti.func
def n_batch(ints: ti.template()):
    """The number of envs (the header's first slot): the bound of every kernel's env loop."""
    return ints[0]


@ti.func
def env_loop(ints: ti.template(), serial: ti.template()):
    """The iteration count of a compute kernel's env loop (its iteration t runs env ``env_of(t)``):
    the envs, or, on the thread pool (``serial`` False), the envs spread out to 1024 iterations:
    Taichi 1.7's CPU backend hands a parallel loop out in tasks of 512 iterations, so 129 to 512
    envs ran on one thread (a box on a plane at 256 envs: 4.0 µs an env-step on 1.0 core, 2.6 on
    1.7 at 1024)."""
    n = n_batch(ints)
    if ti.static(not serial):
        n *= _spread(ints)
    return n


@ti.func
def env_of(ints: ti.template(), t, serial: ti.template()):
    """The env of iteration t of an ``env_loop``, or -1 for the spread's idle iterations."""
    e = t
    if ti.static(not serial):
        spread = _spread(ints)
        e = ti.select(t % spread == 0, t // spread, -1)
    return e


@ti.func
def _spread(ints: ti.template()):
    return ti.max(1, 1024 // n_batch(ints))


def bind(ints, f1, v3, v4, m3, cone=None, body_eqs=True, max_condim=6):
    """Called inside a kernel (in the env loop): the :class:`RigidView` of the arenas (cone,
    body_eqs, max_condim: see RigidView)."""
    return RigidView(ints, f1, v3, v4, m3, cone, body_eqs, max_condim)


# bind runs as Python while Taichi builds a kernel, on purpose: it only creates the view
warnings.filterwarnings("ignore", message='.*Calling non-taichi function "bind"', category=SyntaxWarning)


@ti.func
def accumulate(fld: ti.template(), index, value):
    """fld[index] += value without an atomic. The step kernels give each env to one thread, so
    nothing else writes there, and Taichi's ``+=`` is an atomic costing several plain adds on CPU."""
    fld[index] = fld[index] + value
