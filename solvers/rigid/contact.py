"""Constraint bookkeeping of the rigid solver at build (plain Python around the kernels): how many
contact and row slots a scene needs, the constants MuJoCo computes at the initial pose
(``body_invweight0``, ``dof_invweight0``), and the filter of pairs touching at that pose.
"""
import logging
from dataclasses import replace

import numpy as np
import torch

from ..core import runtime
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


def capacity(model, options):
    """(contact slots C, row slots R) per env: C the pairs' worst case, capped by max_contacts
    (default: MAX_PER_MOVING_LINK per moving link with geometry, at least MIN_CONTACTS); R
    enough rows for C contacts of the largest condim under the cone, one per limited dof (at
    most one of its two bounds is violated) and one per dof for friction loss (settable on any)."""
    worst = sum(_pair_budget(model, k) for k in range(len(model.pair_geom1)))
    if options.max_contacts is not None:
        cap = int(options.max_contacts)
    else:
        moving = len(set(model.geom_link[model.link_static[model.geom_link] == 0].tolist()))
        cap = max(MIN_CONTACTS, MAX_PER_MOVING_LINK * moving)
    contacts = min(worst, cap)
    condim = int(model.pair_condim.max()) if len(model.pair_condim) else 1
    rows_per_contact = condim if options.friction_cone == "elliptic" or condim == 1 else 2 * (condim - 1)
    return contacts, contacts * rows_per_contact + limited_dofs(model, options) + model.n_dofs


def _invweight(solver):
    """MuJoCo's constants of the rows' scale at the initial pose, env 0's parameters (the
    scene's defaults), M with armature:
    - body_invweight0 per link (translation 1/kg, rotation 1/(kg·m²)): the mean of the
      translational and rotational diagonal of J M⁻¹ Jᵀ, J the Jacobian of the link's centre of
      mass; zero for links welded to the world;
    - dof_invweight0 per dof: the diagonal of M⁻¹, averaged over a free joint's three
      translations and its three rotations."""
    m = solver.model
    mass_matrix = solver.mass_matrix()[0].double().cpu().numpy() + np.diag(m.dof_armature)
    solver.check_positive_definite(mass_matrix)
    jac = torch.empty((solver.n_batch, m.n_links, 6, m.n_dofs), dtype=runtime.tc_float, device=runtime.device)
    solver.kernels.read_com_jacobians(jac)
    jac = jac[0].double().cpu().numpy()
    inv_jt = np.linalg.solve(mass_matrix, jac.transpose(0, 2, 1)) if m.n_dofs else np.zeros((m.n_links, 0, 6))
    a = jac @ inv_jt  # (L, 6, 6)
    diag = np.diagonal(a, axis1=1, axis2=2)
    moving = m.link_static == 0
    dof_inv = np.diag(np.linalg.inv(mass_matrix)).copy() if m.n_dofs else np.zeros(0)
    free = np.flatnonzero(m.dof_q < 0)  # a free joint's 6 dofs, in order (translation, rotation)
    for first in free[::3]:
        dof_inv[first: first + 3] = dof_inv[first: first + 3].mean()
    return diag[:, :3].mean(axis=1) * moving, diag[:, 3:].mean(axis=1) * moving, dof_inv


def _touching_pairs(solver):
    """Candidate pairs with a contact at the initial pose (env 0): the first substep of a step
    that is not committed finds them."""
    solver.run_step(solver._nothing, solver._nothing, commit=0)
    if solver.data.take_flag("overflow"):
        _logger.warning(f"scene.build: more contacts at the initial pose than the {solver.data.size['C']} slots per "
                        f"env: pairs beyond them are not filtered as touching; raise RigidOptions(max_contacts=...)")
    for flag in ("inexact", "nonfinite"):
        solver.data.take_flag(flag)
    found = solver.contacts(substep=0)[0].cpu().numpy()
    found = found[found[:, 0] >= 0]
    model = solver.model
    geoms = set(zip(found[:, 0].astype(int).tolist(), found[:, 1].astype(int).tolist()))
    return np.array([(g1, g2) in geoms for g1, g2 in zip(model.pair_geom1.tolist(), model.pair_geom2.tolist())],
                    dtype=bool)


def at_initial_pose(solver, neutral_collision):
    """The solver's model with body_invweight0 and dof_invweight0 filled and, unless
    ``neutral_collision``, without the pairs of one entity touching at the initial pose
    (Genesis's rule). The solver's storage must hold the initial state."""
    solver.upload_state(solver._initial_state())
    inv_t, inv_r, inv_dof = _invweight(solver)
    model = replace(solver.model, link_invweight_t=inv_t, link_invweight_r=inv_r, dof_invweight0=inv_dof)
    if neutral_collision or not len(model.pair_geom1):
        return model
    entity = model.link_entity[model.geom_link]
    same = entity[model.pair_geom1] == entity[model.pair_geom2]
    return without_pairs(model, ~(same & _touching_pairs(solver)))
