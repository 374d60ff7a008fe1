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
from .constraint.rows import DEFAULT_SOLIMP, SMOOTH_SOLIMP  # noqa: F401 (the geoms' defaults, read by solver.py)

_logger = logging.getLogger("genesis_lite")
MAX_PER_MOVING_LINK = 8  # default max_contacts: a box resting on a face touches at up to 8 points
MIN_CONTACTS = 16


def without_pairs(model, keep=None):
    """The model with only the candidate pairs ``keep`` (bool (N,); None: none, collision off)."""
    keep = np.zeros(len(model.pair_geom1), dtype=bool) if keep is None else keep
    return replace(model, pair_geom1=model.pair_geom1[keep], pair_geom2=model.pair_geom2[keep],
                   pair_condim=model.pair_condim[keep], pair_margin=model.pair_margin[keep])


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


def limited_dofs(model, options):
    """Dofs whose joint limits may make a row: scalar joints with a finite bound, limits on."""
    if not options.enable_joint_limit:
        return 0
    finite = np.isfinite(model.dof_lower) | np.isfinite(model.dof_upper)
    return int((finite & (model.dof_q >= 0)).sum())


def worst_case_contacts(model):
    """The most contacts the candidate pairs can make in one env (each pair kind's budget)."""
    return sum(_pair_budget(model, k) for k in range(len(model.pair_geom1)))


def capacity(model, options):
    """(contact slots C, row slots R) per env: C the pairs' worst case, capped by max_contacts
    (default: MAX_PER_MOVING_LINK per moving link with geometry, at least MIN_CONTACTS); R
    enough rows for C contacts of the largest condim under the cone, one per limited dof (at
    most one of its two bounds is violated) and one per dof for friction loss (settable on any)."""
    worst = worst_case_contacts(model)
    if options.max_contacts is not None:
        cap = int(options.max_contacts)
    else:
        moving = len(set(model.geom_link[model.link_static[model.geom_link] == 0].tolist()))
        cap = max(MIN_CONTACTS, MAX_PER_MOVING_LINK * moving)
    contacts = min(worst, cap)
    condim = int(model.pair_condim.max()) if len(model.pair_condim) else 1
    rows_per_contact = condim if options.friction_cone == "elliptic" or condim == 1 else 2 * (condim - 1)
    return contacts, contacts * rows_per_contact + limited_dofs(model, options) + model.n_dofs


class InvweightBasis:
    """What MuJoCo's body_invweight0 and dof_invweight0 (mj_setConst) are made of at the initial
    pose q0, where they depend on nothing but the masses and the armature: M(q0) = Σ_l mass_l K_l +
    diag(armature) (a link's inertia scales with its mass: K_l is M of link l alone at 1 kg), and
    J_l (6, D) the Jacobian of link l's centre of mass. ``__call__`` gives the rows' scale per env
    from the mass and armature inputs, in torch, so that their gradients reach mass and armature
    (Genesis recomputes them when those change, as mj_setConst does):
    - invweight_t per link (1/kg): the mean of the translational diagonal of J_l M⁻¹ J_lᵀ; zero for
      links welded to the world (the rotational one is not read: condim ≤ 3);
    - invweight_dof per dof: the diagonal of M⁻¹, averaged over a free joint's three translations
      and its three rotations."""

    def __init__(self, solver):
        m = solver.model
        D = m.n_dofs
        jac = torch.empty((solver.n_batch, m.n_links, 6, D), dtype=runtime.tc_float, device=runtime.device)
        solver.kernels.read_com_jacobians(jac)
        jac = jac[0].double().cpu().numpy()
        # M of each link alone at unit mass (M is linear in the masses): J_vᵀ J_v + J_ωᵀ (I_l / m_l) J_ω,
        # J_ω in the link's frame, where its inertia is given (a massless link's is dropped)
        unit_inertia = m.link_inertia0 * m.link_inv_mass0[:, None, None]
        K = (np.einsum("lki,lkj->lij", jac[:, :3], jac[:, :3])
             + np.einsum("lki,lkn,lnj->lij", jac[:, 3:], unit_inertia, jac[:, 3:]))
        solver.check_positive_definite(np.einsum("l,lij->ij", m.link_mass0, K) + np.diag(m.dof_armature))
        # dof_invweight0 = diag(M⁻¹) @ average: a free joint's translations and rotations averaged
        average = np.eye(D)
        for first in np.flatnonzero(m.dof_q < 0)[::3]:
            average[first: first + 3, first: first + 3] = 1.0 / 3.0
        # K (L, D, D), J (L, 3, D) the translational rows, moving (L,), average (D, D): float64
        self.consts = [torch.as_tensor(a, dtype=torch.float64, device=runtime.device)
                       for a in (K, jac[:, :3], (m.link_static == 0), average)]

    def __call__(self, mass, armature, check_positive_definite):
        """(invweight_t (B, L), invweight_dof (B, D)) in mass's dtype, from mass (B, L) kg and armature
        (B, D); a singular M goes to check_positive_definite (RigidSolver's: it names the link).
        Computed in float64, one env at a time: batched linear algebra (inverse, matrix products)
        may sum in another order for another batch size, and a batched env must equal a single-env
        scene bit for bit (~50 µs an env, when mass or armature is set)."""
        if mass.shape[1] == 0 or armature.shape[1] == 0:
            return torch.zeros_like(mass), torch.zeros_like(armature)
        rows = [self._one_env(mass[e: e + 1].double(), armature[e: e + 1].double(), check_positive_definite)
                for e in range(mass.shape[0])]
        return (torch.cat([r[0] for r in rows]).to(mass.dtype), torch.cat([r[1] for r in rows]).to(mass.dtype))

    def _one_env(self, mass, armature, check_positive_definite):
        """(1, L), (1, D) for one env's mass (1, L) and armature (1, D); a singular M (a mass set
        to zero) is an InvalidInputError naming the link."""
        K, J, moving, average = self.consts
        matrix = (mass[0, :, None, None] * K).sum(0) + torch.diag(armature[0])
        inverse, info = torch.linalg.inv_ex(matrix)
        if info.item() != 0:
            check_positive_definite(matrix.detach().cpu().numpy(), InvalidInputError)
            torch.linalg.inv(matrix)  # singular below the check's share: torch's own error
        translational = torch.einsum("lri,ij,lrj->l", J, inverse, J) / 3.0 * moving
        return translational[None], (torch.diagonal(inverse) @ average)[None]


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
    ``neutral_collision``, the pairs of one entity touching at the initial pose (Genesis's rule).
    The solver's storage must hold the initial state."""
    solver.upload_state(solver._initial_state())
    solver.invweight_basis = InvweightBasis(solver)
    model = solver.model
    if neutral_collision or not len(model.pair_geom1):
        return model
    entity = model.link_entity[model.geom_link]
    same = entity[model.pair_geom1] == entity[model.pair_geom2]
    return without_pairs(model, ~(same & _touching_pairs(solver)))
