"""Constraint bookkeeping of the rigid solver at build (plain Python around the kernels): how many
contact and row slots a scene needs, the constants MuJoCo computes at the initial pose
(``body_invweight0``, ``dof_invweight0``), and the filter of pairs touching at that pose.
"""
import logging
from dataclasses import replace

import numpy as np
import torch

from ..core import InvalidInputError, runtime
from .collision.detect import BUDGET, COLLIDERS
from .constraint.rows import DEFAULT_SOLIMP, MAXIMP, MINIMP, SMOOTH_SOLIMP  # noqa: F401 (SMOOTH_SOLIMP: solver.py's)
from .constraint.solver import MINVAL  # (the least mass a sliding leaf's 1 / mass divides by)
from .model import BALL, PRISMATIC

_logger = logging.getLogger("genesis_lite")
MAX_PER_MOVING_LINK = 8  # default max_contacts: a box resting on a face touches at up to 8 points
MIN_CONTACTS = 16
PAIR_ARRAYS = ("pair_geom1", "pair_geom2", "pair_condim", "pair_mix", "pair_copy", "pair_margin")


def without_pairs(model, keep=None):
    """The model with only the candidate pairs ``keep`` (bool (N,); None: none, collision off)."""
    keep = np.zeros(len(model.pair_geom1), dtype=bool) if keep is None else keep
    return replace(model, **{name: getattr(model, name)[keep] for name in PAIR_ARRAYS})


SOFTNESS_TABLES = ("dof_limit_sol", "dof_frictionloss_sol", "eq_sol", "body_eq_sol", "ten_limit_sol", "ten_eq_sol",
                   "ten_friction_sol")


def with_row_softness(model, timeconst):
    """The model with the softness of its joint rows (SOFTNESS_TABLES: solref then solimp per dof
    limit, dof friction loss, joint equality, connect or weld, tendon limit, equality or friction
    loss) complete: what the asset left
    unstated (NaN) the scene's (timeconst s, 1) and MuJoCo's default solimp, and every solimp
    within MuJoCo's bounds (its runtime clamps them so; the kernels read them as they are)."""
    default = np.array([timeconst, 1.0, *DEFAULT_SOLIMP])
    lower = [-np.inf, -np.inf, MINIMP, MINIMP, 0.0, MINIMP, 1.0]
    upper = [np.inf, np.inf, MAXIMP, MAXIMP, np.inf, MAXIMP, np.inf]
    complete = lambda table: np.clip(np.where(np.isnan(table), default, table), lower, upper)  # noqa: E731
    return replace(model, **{name: complete(getattr(model, name)) for name in SOFTNESS_TABLES})


def without_uncollidable(model, names):
    """The model without the pairs no collider handles, and a warning naming them (nothing is
    dropped silently). Every pair of the geom types has one (collision/detect.COLLIDERS, meshes
    as their convex hull): this guards a type added without its colliders."""
    kinds = list(zip(model.geom_type[model.pair_geom1].tolist(), model.geom_type[model.pair_geom2].tolist()))
    keep = np.array([kind in COLLIDERS for kind in kinds], dtype=bool)
    if not keep.all():
        dropped = sorted({f"{names[a]}-{names[b]}" for (a, b), k in zip(kinds, keep) if not k})
        _logger.warning(f"scene.build: contacts between {', '.join(dropped)} are not simulated yet (no collider for "
                        f"these shapes): {int((~keep).sum())} of {len(keep)} geom pairs pass through each other")
    return without_pairs(model, keep)


def _pair_budget(model, k):
    """Contacts pair k's collider may give (every pair left has a collider: without_uncollidable)."""
    return BUDGET[int(model.geom_type[model.pair_geom1[k]]), int(model.geom_type[model.pair_geom2[k]])]


def limit_rows(model, options):
    """Limit rows a scene may make at once, limits on: one per scalar dof (at most one of its two
    bounds is violated; settable on any, set_dofs_limit), one per ball joint with a cone limit (its
    first dof's upper bound), one per limited fixed tendon."""
    if not options.enable_joint_limit:
        return 0
    first_of_ball = (model.link_jtype[model.dof_link] == BALL) & (model.link_dof0[model.dof_link] == np.arange(
        model.n_dofs))
    return int((model.dof_q >= 0).sum() + (np.isfinite(model.dof_upper) & first_of_ball).sum()
               + (np.isfinite(model.ten_lower) | np.isfinite(model.ten_upper)).sum())


def worst_case_contacts(model):
    """The most contacts the candidate pairs can make in one env (each pair kind's budget)."""
    return sum(_pair_budget(model, k) for k in range(len(model.pair_geom1)))


def capacity(model, options, contacts=None):
    """(contact slots C, row slots R) per env: C the pairs' worst case, capped by max_contacts
    (default: MAX_PER_MOVING_LINK per moving link with geometry, at least MIN_CONTACTS, which the
    solver doubles while a step finds more: the given ``contacts`` then); R
    enough rows for C contacts of the largest condim under the cone, one per joint equality, three
    per connect, six per weld (and run-time weld slot), one per held fixed tendon, one per limited
    dof and limited fixed tendon (at most one of its two bounds is violated), one per dof for
    friction loss (settable on any) and one per fixed tendon with friction loss."""
    worst = worst_case_contacts(model)
    if contacts is not None:
        cap = contacts
    elif options.max_contacts is not None:
        cap = int(options.max_contacts)
    else:
        moving = len(set(model.geom_link[model.link_static[model.geom_link] == 0].tolist()))
        cap = max(MIN_CONTACTS, MAX_PER_MOVING_LINK * moving)
    contacts = min(worst, cap)
    condim = int(model.pair_condim.max()) if len(model.pair_condim) else 1
    rows_per_contact = condim if options.friction_cone == "elliptic" or condim == 1 else 2 * (condim - 1)
    joint_rows = (model.n_eq + 3 * model.n_body_eq + 3 * model.n_weld + 6 * options.max_dynamic_constraints
                  + int(model.ten_eq.sum()) + limit_rows(model, options) + model.n_dofs
                  + int((model.ten_frictionloss > 0).sum()))
    return contacts, contacts * rows_per_contact + joint_rows


class InvweightBasis:
    """What MuJoCo's body_invweight0 and dof_invweight0 (mj_setConst) are made of at the initial
    pose q0, where they depend on nothing but the masses, the rotational inertias and the armature:
    M(q0) = Σ_l (mass_l K_l + J_ω,lᵀ I_l J_ω,l) + diag(armature), K_l = J_v,lᵀ J_v,l, with J_l (6, D)
    the Jacobian of link l's centre of mass (J_ω in the link's frame, where its inertia I_l is
    given), taken with its build's centre of mass (set_links_COM leaves the scale as MuJoCo leaves
    its compiled one). ``__call__`` gives the rows' scale per env from the mass, inertia and
    armature inputs, in torch, so that their gradients reach them (Genesis recomputes the scale
    when those change, as mj_setConst does):
    - invweight_t per link (1/kg): the mean of the translational diagonal of J_l M⁻¹ J_lᵀ, and
      invweight_r (1/(kg·m²)) of its rotational one (read by welds' turn rows only: contacts have
      condim ≤ 3; and by get_links_invweight); zero for links welded to the world;
    - invweight_dof per dof: the diagonal of M⁻¹, averaged over a free joint's three translations
      and its three rotations, and over a ball joint's three rotations;
    - invweight_ten per fixed tendon: J M⁻¹ Jᵀ, J its coefficients on its dofs (MuJoCo's
      tendon_invweight0, never simplified);
    - but on a sliding leaf (``sliding_leaves``: MuJoCo's body_simple = 2), 1 / mass for
      invweight_t and invweight_dof, and 0 for invweight_r, as MuJoCo takes them there (armature
      left out).
    M is block-diagonal over the kinematic trees (a link's Jacobian is non-zero on its tree's dofs
    only), so everything is kept and inverted per tree, trees of one shape batched together: a
    dense (links, dofs, dofs) K made a scene of 192 free bodies take 14 s and 4 GB to build, and
    one of 512 could not be built."""

    def __init__(self, solver):
        m = solver.model
        jac = torch.empty((1, m.n_links, 6, m.n_dofs), dtype=runtime.tc_float, device=runtime.device)
        solver.kernels.read_com_jacobians(jac)  # (env 0's: every env starts at q0)
        jac = jac[0].double().cpu().numpy()
        self.n_links, self.n_dofs = m.n_links, m.n_dofs
        self.groups = []  # per tree shape: (links (T, l), dofs (T, n), K (T, l, n, n), J (T, l, 6, n), average (T, n, n))
        for links, dofs in _same_shaped_trees(m):
            J = jac[links[:, :, None, None], np.arange(6)[None, None, :, None], dofs[:, None, None, :]]
            K = np.einsum("tlki,tlkj->tlij", J[:, :, :3], J[:, :, :3])
            for t in range(len(dofs)):
                solver.check_positive_definite(_mass_matrix(np, m.link_mass0[links[t]], m.link_inertia[links[t]],
                                                            m.dof_armature[dofs[t]], K[t], J[t]), dofs=dofs[t])
            # dof_invweight0 = diag(M⁻¹) @ average: a free joint's translations and rotations, a ball
            # joint's rotations averaged
            average = np.tile(np.eye(dofs.shape[1]), (len(dofs), 1, 1))
            for first in np.flatnonzero(m.dof_q[dofs[0]] < 0)[::3]:  # (alike in a group: _same_shaped_trees)
                average[:, first: first + 3, first: first + 3] = 1.0 / 3.0
            moving = (m.link_static[links] == 0)
            self.groups.append([torch.as_tensor(a, device=runtime.device) for a in (links, dofs)]
                               + [torch.as_tensor(a, dtype=torch.float64, device=runtime.device)
                                  for a in (K, J * moving[:, :, None, None], average)])
        ten_J = np.zeros((m.n_tendons, m.n_dofs))
        for t in range(m.n_tendons):
            ten_J[t, m.ten_dof[t, :m.ten_nnz[t]]] = m.ten_coef[t, :m.ten_nnz[t]]
        self.ten_J = torch.as_tensor(ten_J, device=runtime.device)
        simple = sliding_leaves(m)
        self.simple_links = torch.as_tensor(np.flatnonzero(simple), device=runtime.device)
        self.simple_dofs = torch.as_tensor(np.flatnonzero(simple[m.dof_link]), device=runtime.device)
        self.simple_dof_links = torch.as_tensor(m.dof_link[self.simple_dofs.cpu().numpy()], device=runtime.device)

    def __call__(self, mass, inertia, armature, check_positive_definite):
        """(invweight_t (B, L), invweight_r (B, L), invweight_dof (B, D), invweight_ten (B, T)) in mass's dtype, from mass
        (B, L) kg, inertia (B, 9 L) kg·m² (the input's layout) and armature (B, D); a singular M goes to
        check_positive_definite (RigidSolver's: it names the link).
        Computed in float64, one env at a time (trees batched, the same batches in every env):
        batched linear algebra over envs may sum in another order for another batch size, and a
        batched env must equal a single-env scene bit for bit."""
        if mass.shape[0] == 0 or mass.shape[1] == 0 or armature.shape[1] == 0:  # (no env, link or dof)
            return (torch.zeros_like(mass), torch.zeros_like(mass), torch.zeros_like(armature),
                    mass.new_zeros((mass.shape[0], len(self.ten_J))))
        inertia = inertia.reshape(inertia.shape[0], -1, 3, 3)
        rows = [self._one_env(mass[e].double(), inertia[e].double(), armature[e].double(), check_positive_definite)
                for e in range(mass.shape[0])]
        return tuple(torch.stack([r[k] for r in rows]).to(mass.dtype) for k in range(4))

    def _one_env(self, mass, inertia, armature, check_positive_definite):
        """(L,), (L,), (D,), (T,) for one env's mass (L,), inertia (L, 3, 3) and armature (D,); a
        singular M (a mass set to zero) is an InvalidInputError naming the link."""
        translational, rotational = mass.new_zeros(self.n_links), mass.new_zeros(self.n_links)
        per_dof, per_tendon = mass.new_zeros(self.n_dofs), mass.new_zeros(len(self.ten_J))
        for links, dofs, K, J, average in self.groups:
            matrix = _mass_matrix(torch, mass[links], inertia[links], armature[dofs], K, J)
            # a tree whose M is near singular (a pivot of its LDLᵀ, Cholesky's L_ii², under 1e-5 of its
            # diagonal: the float32 check's share, above float64's) goes to the check, which raises where
            # the scene's precision cannot step it (an inertia with a zero principal moment, turned:
            # no pivot is exactly zero, M⁻¹'s entries are 1e18)
            factor, info = torch.linalg.cholesky_ex(matrix.detach())
            pivots, diagonal = (torch.diagonal(a, dim1=-2, dim2=-1) for a in (factor ** 2, matrix.detach()))
            for t in torch.nonzero((info != 0) | (pivots <= 1e-5 * diagonal).any(-1)).flatten().tolist():
                check_positive_definite(matrix[t].detach().cpu().numpy(), InvalidInputError, dofs[t].cpu().numpy())
            inverse = torch.linalg.inv(matrix)
            # the means of J M⁻¹ Jᵀ's translational and rotational diagonals, each by an einsum of its own
            # (one of six rows sums in another order) (a block's trace is frame-free: J_ω is in the link's)
            translation, rotation = [torch.einsum("tlri,tij,tlrj->tlr", J[:, :, rows], inverse, J[:, :, rows])
                                     .sum(-1).flatten() / 3.0 for rows in (slice(0, 3), slice(3, 6))]
            translational = translational.index_put((links.flatten(),), translation)
            rotational = rotational.index_put((links.flatten(),), rotation)
            per_dof = per_dof.index_put((dofs.flatten(),),
                                        torch.einsum("ti,tij->tj", torch.diagonal(inverse, dim1=1, dim2=2),
                                                     average).flatten())
            if len(self.ten_J):  # (M block-diagonal: each tree's share of J M⁻¹ Jᵀ)
                on_trees = self.ten_J[:, dofs]
                per_tendon = per_tendon + torch.einsum("kti,tij,ktj->k", on_trees, inverse, on_trees)
        if len(self.simple_links):
            inverse_mass = 1.0 / mass.clamp(min=MINVAL)
            translational = translational.index_put((self.simple_links,), inverse_mass[self.simple_links])
            rotational = rotational.index_put((self.simple_links,), mass.new_zeros(len(self.simple_links)))
            per_dof = per_dof.index_put((self.simple_dofs,), inverse_mass[self.simple_dof_links])
        return translational, rotational, per_dof, per_tendon


def _mass_matrix(xp, mass, inertia, armature, K, J):
    """M at q0 of trees of one shape, in numpy or torch (xp): mass (..., l) kg, inertia (..., l, 3, 3)
    kg·m², armature (..., n) and K (..., l, n, n), J (..., l, 6, n) as InvweightBasis keeps them."""
    rotation = J[..., 3:, :]
    links = (mass[..., None, None] * K).sum(-3) + xp.einsum("...lai,...lab,...lbj->...ij", rotation, inertia, rotation)
    return links + (np.diag(armature) if xp is np else torch.diag_embed(armature))


def sliding_leaves(model):
    """(L,) bool: the links whose rows' scale MuJoCo takes as 1 / mass (its body_simple = 2, which
    mj_setConst special-cases), those that
    - move on prismatic joints only, each along a link axis (one axis component above 1e-14);
    - carry no other link (a leaf) and hang from the world or from a link welded to it directly
      (a URDF root link named "world" is the world, as MuJoCo's URDF reader takes it);
    - have their centre of mass at the link origin (1e-6 m) and their principal axes along the
      link's, in descending order of moment: MuJoCo compiles the inertia into a principal frame
      whose axes it orders by descending moment, and takes a body as simple only where that
      frame is the link's own (to 1e-6 of a unit quaternion: no Jacobi rotation wider than
      2e-6 rad; off-diagonal entries under 1e-12 rotate nothing); read here from the inertia
      about the centre of mass in the link frame."""
    parent, static = model.link_parent, model.link_static
    world = np.array([parent[l] < 0 and model.link_name[l] == "world" for l in range(model.n_links)], dtype=bool)
    has_child = np.zeros(model.n_links, dtype=bool)
    has_child[parent[parent >= 0]] = True
    out = np.zeros(model.n_links, dtype=bool)
    for l in range(model.n_links):
        p = parent[l]
        attached = p < 0 or world[p] or (static[p] and (parent[p] < 0 or world[parent[p]]))
        axis_aligned = int((np.abs(model.link_axis[l]) > 1e-14).sum()) == 1
        out[l] = (model.link_jtype[l] == PRISMATIC and axis_aligned and not has_child[l] and attached
                  and bool(np.all(np.abs(model.link_com[l]) < 1e-6)) and _principal_and_ordered(model.link_inertia0[l]))
    return out


def _principal_and_ordered(inertia):
    """The link axes are the principal axes of ``inertia`` (3, 3), with moments descending (see
    sliding_leaves)."""
    for i, j in ((0, 1), (0, 2), (1, 2)):
        off, gap = abs(inertia[i, j]), abs(inertia[j, j] - inertia[i, i])
        if off >= 1e-12 and off >= 2e-6 * gap:  # (tan 2φ = 2 off / gap: a turn φ of 2e-6 rad or more)
            return False
    return bool(inertia[0, 0] + 1e-12 >= inertia[1, 1] and inertia[1, 1] + 1e-12 >= inertia[2, 2])


def _same_shaped_trees(model):
    """[(links (T, l), dofs (T, n))]: the kinematic trees with dofs, grouped by their numbers of
    links and dofs and where their free and ball joints' dofs are, ascending within each tree (a tree: the
    dofs under one root dof, and the links whose path to the root first meets one of them; links
    welded to the world belong to none)."""
    parent = model.dof_parent
    root = np.arange(model.n_dofs)
    for i in range(model.n_dofs):  # a dof's parent comes before it
        if parent[i] >= 0:
            root[i] = root[parent[i]]
    link_root = np.full(model.n_links, -1)
    for l in range(model.n_links):  # a parent link comes before its children
        own = np.flatnonzero(model.dof_link == l)
        above = model.link_parent[l]
        link_root[l] = root[own[0]] if len(own) else (link_root[above] if above >= 0 else -1)
    groups = {}
    for r in np.unique(root):
        links, dofs = np.flatnonzero(link_root == r), np.flatnonzero(root == r)
        groups.setdefault((len(links), tuple((model.dof_q[dofs] < 0).tolist())), []).append((links, dofs))
    return [(np.array([l for l, _ in trees]), np.array([d for _, d in trees])) for trees in groups.values()]


def _touching_pairs(solver):
    """Candidate pairs with a contact at the initial pose (env 0), from the colliders alone (the
    constraint solve is neither run nor compiled for it)."""
    solver.detect_contacts()
    if solver.data.take_flag("overflow"):
        _logger.warning(f"scene.build: more contacts at the initial pose than the {solver.data.size['C']} slots per "
                        f"env: pairs beyond them are not filtered as touching; raise RigidOptions(max_contacts=...) "
                        f"(this scene's pairs can make up to {worst_case_contacts(solver.model)})")
    solver.data.take_flag("inexact")
    found = solver.contacts(substep=0)[0].cpu().numpy()
    found = found[found[:, 0] >= 0]
    model = solver.model
    geoms = set(zip(found[:, 0].astype(int).tolist(), found[:, 1].astype(int).tolist()))
    return np.array([(g1, g2) in geoms for g1, g2 in zip(model.pair_geom1.tolist(), model.pair_geom2.tolist())],
                    dtype=bool)


def at_initial_pose(solver, neutral_collision):
    """(The basis of the rows' scale, solver.invweight_basis, set;) the solver's model without, unless
    ``neutral_collision``, the pairs of one kinematic tree touching at the initial pose (Genesis's
    rule, per root: an MJCF's separate root bodies may start touching, a box resting on a post).
    The solver's storage must hold the initial state."""
    solver.upload_state(solver._initial_state())
    solver.invweight_basis = InvweightBasis(solver)
    model = solver.model
    if neutral_collision or not len(model.pair_geom1):
        return model
    tree = model.link_root[model.geom_link]
    same = tree[model.pair_geom1] == tree[model.pair_geom2]
    return without_pairs(model, ~(same & _touching_pairs(solver)))
