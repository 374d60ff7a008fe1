"""The Newton constraint solve (solvers/rigid/constraint/solver.py) against MuJoCo's mj_solNewton.

Each scene is simulated in MuJoCo (dense Jacobian) to a few snapshots; at each snapshot MuJoCo's
own inputs (M, qfrc_smooth, efc_J/R/aref/frictionloss, the contacts' dim/mu/friction) are copied
into the interface's rows, with unused slots full of garbage between constraints, and solved by
our `newton_solve` under four variants, each compared with MuJoCo run the same way:
  tight:     tolerance 1e-14, 1000 iterations, from the step's own warm start;
  default:   MuJoCo's defaults, the step's own warm start;
  converged: defaults, warm-started at the exact solution (MuJoCo's start certificate);
  cold:      defaults, a wild warm start (qacc_smooth wins the warm-start test).
All envs of one scene go through one kernel launch; the kernel is compiled once.
"""
import mujoco
import numpy as np
import pytest
import taichi as ti

import genesis_lite as gs
from genesis_lite.solvers import launch
from genesis_lite.solvers.launch import taichi_opt_level
from genesis_lite.solvers.rigid.constraint import solver as cs

EQUALITY, FRICTION_DOF, FRICTION_TENDON, CONTACT_ELLIPTIC = (
    int(mujoco.mjtConstraint.mjCNSTR_EQUALITY), int(mujoco.mjtConstraint.mjCNSTR_FRICTION_DOF),
    int(mujoco.mjtConstraint.mjCNSTR_FRICTION_TENDON), int(mujoco.mjtConstraint.mjCNSTR_CONTACT_ELLIPTIC))
H = 0.002  # MuJoCo's default time step (s)
SNAPSHOTS = (1, 12, 60)  # steps simulated before each snapshot
DEFAULT = dict(iterations=100, tolerance=1e-8, ls_iterations=50, ls_tolerance=0.01)
VARIANTS = {
    "tight": dict(iterations=1000, tolerance=1e-14, ls_iterations=100, ls_tolerance=0.01),
    "default": DEFAULT, "converged": DEFAULT, "cold": DEFAULT,
}

BODIES = """
<mujoco>
  <option jacobian="dense" cone="{cone}" impratio="{impratio}"/>
  <worldbody>
    <geom type="plane" size="5 5 .1" condim="1"/>
    <body pos="0 0 .098" euler="0 2 3"><freejoint/><geom type="box" size=".1 .1 .1" condim="3"/></body>
    <body pos=".01 .02 .29" euler="4 0 10"><freejoint/>
      <geom type="box" size=".08 .06 .1" condim="4" friction=".7 .02 .001"/></body>
    <body pos=".5 0 .099"><freejoint/><geom type="sphere" size=".1" condim="6" friction=".8 .01 .002"/></body>
    <body pos="-.5 0 .048" euler="0 90 0"><freejoint/><geom type="capsule" size=".05 .2" condim="1"/></body>
  </worldbody>
</mujoco>
"""

CHAIN = """
<mujoco>
  <option jacobian="dense" cone="{cone}" impratio="{impratio}"/>
  <worldbody>
    <geom type="plane" size="5 5 .1"/>
    <body pos="0 0 .35">
      <joint name="shoulder" type="hinge" axis="0 1 0" range="-30 30" frictionloss=".3"/>
      <geom type="capsule" fromto="0 0 0 .2 0 0" size=".03"/>
      <body pos=".2 0 0">
        <joint name="elbow" type="hinge" axis="0 1 0" range="-20 60"/>
        <geom type="capsule" fromto="0 0 0 .2 0 0" size=".03"/>
        <body pos=".2 0 0">
          <joint name="roll" type="hinge" axis="1 0 0" frictionloss=".1"/>
          <joint type="hinge" axis="0 1 0" range="-45 45" frictionloss=".05"/>
          <geom type="box" pos=".05 0 0" size=".05 .04 .03" condim="4"/>
        </body>
      </body>
    </body>
    <body pos=".45 0 .06"><freejoint/><geom type="box" size=".06 .06 .06" condim="6"/></body>
    <body pos="-.5 .3 .05"><freejoint/><geom type="sphere" size=".05"/></body>
  </worldbody>
  <equality>
    <joint joint1="elbow" joint2="shoulder" polycoef=".2 -.5 0 0 0"/>
    <joint joint1="roll" joint2="elbow" polycoef="0 .3 0 0 0"/>
  </equality>
</mujoco>
"""

SCENES = {
    "bodies-pyramidal": (BODIES, "pyramidal", 1.0),
    "bodies-elliptic": (BODIES, "elliptic", 4.0),
    "chain-pyramidal": (CHAIN, "pyramidal", 2.0),
    "chain-elliptic": (CHAIN, "elliptic", 1.0),
}


def _set_options(m, opts):
    for name, value in opts.items():
        setattr(m.opt, name, value)


def _rows(m, d):
    """MuJoCo's efc rows in the interface's terms, in MuJoCo's order: (type, dim, mu) per row.
    EQUALITY → EQUALITY; FRICTION_DOF/TENDON → FRICTION_LOSS (efc_floss = efc_frictionloss); LIMIT_*, CONTACT_FRICTIONLESS
    and CONTACT_PYRAMIDAL → ONE_SIDED; CONTACT_ELLIPTIC: row efc_address → ELLIPTIC_FIRST with the
    contact's dim and mu (the regularised cone's μ), row efc_address + j → ELLIPTIC_REST with
    mu = friction[j − 1]. efc_J, efc_R, efc_aref copy over row by row."""
    kind = np.zeros(d.nefc, int)
    dim = np.zeros(d.nefc, int)
    mu = np.zeros(d.nefc)
    for r in range(d.nefc):
        t = d.efc_type[r]
        if t == EQUALITY:
            kind[r] = cs.EQUALITY
        elif t in (FRICTION_DOF, FRICTION_TENDON):
            kind[r] = cs.FRICTION_LOSS
        elif t == CONTACT_ELLIPTIC:
            c = d.efc_id[r]
            j = r - d.contact.efc_address[c]
            kind[r] = cs.ELLIPTIC_FIRST if j == 0 else cs.ELLIPTIC_REST
            dim[r] = d.contact.dim[c]
            mu[r] = d.contact.mu[c] if j == 0 else d.contact.friction[c][j - 1]
        else:
            kind[r] = cs.ONE_SIDED
    return kind, dim, mu


def _slots(kind):
    """Slot of each MuJoCo row, and the slot count: an unused slot goes before every row whose
    index is a multiple of 3, unless it is inside an elliptic block."""
    slot, k = np.zeros(len(kind), int), 0
    for r in range(len(kind)):
        if kind[r] != cs.ELLIPTIC_REST and r % 3 == 0:
            k += 1
        slot[r] = k
        k += 1
    return slot, k


def _final_states(d):
    """MuJoCo's efc_state at the solution. With islands, mj_fwdConstraint copies back only the
    forces: d.efc_state keeps the warm-start test's states (at qacc_smooth), the solve's own are
    in d.iefc_state, in island order."""
    if d.nisland == 0:
        return d.efc_state[:d.nefc].copy()
    return d.iefc_state[d.map_efc2iefc[:d.nefc]].copy()


def _final_hessian(m, d, M):
    """MuJoCo's Hessian at its solution: M + Σ_quadratic D J_rᵀ J_r + Σ_cone J_cᵀ con.H J_c."""
    nv, nefc = m.nv, d.nefc
    J = d.efc_J[:nefc * nv].reshape(nefc, nv)
    state = _final_states(d)
    quadratic = state == int(mujoco.mjtConstraintState.mjCNSTRSTATE_QUADRATIC)
    H = M + (J[quadratic].T / d.efc_R[:nefc][quadratic]) @ J[quadratic]
    for c in range(d.ncon):
        first, dim = d.contact.efc_address[c], d.contact.dim[c]
        if first >= 0 and state[first] == int(mujoco.mjtConstraintState.mjCNSTRSTATE_CONE):
            Jc = J[first:first + dim]
            H += Jc.T @ d.contact.H[c][:dim * dim].reshape(dim, dim) @ Jc
    return H


def _snapshot_cases(m, d, rng):
    """Inputs and MuJoCo's answers at the current state under every variant."""
    _set_options(m, DEFAULT)
    mujoco.mj_forward(m, d)
    nv, nefc = m.nv, d.nefc
    M = np.zeros((nv, nv))
    mujoco.mj_fullM(m, d, M)
    kind, dim, mu = _rows(m, d)
    inputs = dict(M=M, qfrc_smooth=d.qfrc_smooth.copy(), kind=kind, dim=dim, mu=mu,
                  J=d.efc_J[:nefc * nv].reshape(nefc, nv).copy(), R=d.efc_R[:nefc].copy(),
                  aref=d.efc_aref[:nefc].copy(), floss=d.efc_frictionloss[:nefc].copy(),
                  dof_parent=m.dof_parentid.copy(), condims=set(d.contact.dim[:d.ncon].tolist()))
    natural = d.qacc_warmstart.copy()
    work = mujoco.MjData(m)
    cases = []
    for variant, opts in VARIANTS.items():
        mujoco.mj_copyData(work, m, d)
        if variant == "converged":
            work.qacc_warmstart[:] = cases[0]["mj"]["qacc"]
        elif variant == "cold":
            work.qacc_warmstart[:] = rng.normal(0.0, 300.0, nv)
        else:
            work.qacc_warmstart[:] = natural
        _set_options(m, opts)
        mujoco.mj_forward(m, work)
        mj = dict(qacc=work.qacc.copy(), qacc_smooth=work.qacc_smooth.copy(),
                  force=work.efc_force[:nefc].copy(), state=_final_states(work),
                  qfrc_constraint=work.qfrc_constraint.copy(),
                  niter=int(work.solver_niter[:max(work.nisland, 1)].sum()), nisland=work.nisland,
                  hessian=_final_hessian(m, work, M))
        cases.append(dict(variant=variant, opts=opts, warmstart=work.qacc_warmstart.copy(), mj=mj, **inputs))
    _set_options(m, DEFAULT)
    return cases


def _scene_cases(xml, cone, impratio, seed):
    m = mujoco.MjModel.from_xml_string(xml.format(cone=cone, impratio=impratio))
    d = mujoco.MjData(m)
    rng = np.random.default_rng(seed)
    d.qvel[:] = rng.normal(0.0, 0.6, m.nv)
    cases, done = [], 0
    for steps in SNAPSHOTS:
        for _ in range(steps - done):
            mujoco.mj_step(m, d)
        done = steps
        d.qvel[:] += rng.normal(0.0, 0.3, m.nv)  # a kick: contacts change state at the snapshot
        cases += _snapshot_cases(m, d, rng)
    return cases


@ti.data_oriented
class _View:
    """The interface's arrays as Taichi fields for one substep frame (s = 0) and n_envs envs."""

    def __init__(self, n_envs, n_dofs, n_rows):
        self.n_envs, self.n_dofs, self.n_rows = n_envs, n_dofs, n_rows
        self.elliptic = True  # the elliptic cone's code compiled in (RigidView's cone): the scenes mix both cones
        self.converged = 0  # MuJoCo's stop (no Newton step past it): its iterates and counts
        E, D, R = n_envs, n_dofs, n_rows
        shapes = {"D": (1, E, D), "DD": (1, E, D, D), "R": (1, E, R), "RD": (1, E, R, D)}
        for name in ("qfrc_smooth", "qacc_smooth", "qacc", "qfrc_constraint", "qacc_constrained"):
            setattr(self, name, ti.field(float, shape=(1, E, D)))  # (qacc_constrained: a replay's, not used here)
        for name in ("efc_mu", "efc_R", "efc_aref", "efc_floss", "efc_force"):
            setattr(self, name, ti.field(float, shape=(1, E, R)))
        for name in ("efc_type", "efc_dim", "efc_state"):
            setattr(self, name, ti.field(ti.i32, shape=(1, E, R)))
        self.solver_M = ti.field(float, shape=(1, E, D, D))
        self.efc_J = ti.field(float, shape=(1, E, R, D))
        # every row's non-zero columns: all of them (efc_cols[0 … D) = 0 … D − 1), a valid superset
        self.efc_col0, self.efc_ncol = ti.field(ti.i32, shape=(1, E, R)), ti.field(ti.i32, shape=(1, E, R))
        self.efc_cols = ti.field(ti.i32, shape=(1, E, D))
        self.efc_ncol.fill(D)
        self.efc_cols.from_numpy(np.tile(np.arange(D, dtype=np.int32), (1, E, 1)))
        self.qacc_warmstart = ti.field(float, shape=(E, D))
        self.solver_niter = ti.field(ti.i32, shape=(1, E))
        self.capped = ti.field(ti.i32, shape=1)  # (the iteration-limit flag: RigidView's header entry)
        self.n_efc = ti.field(ti.i32, shape=(1, E, 1))  # rows in use: every slot (unused ones hold garbage)
        self.n_efc.fill(R)
        self.dof_parent = ti.field(ti.i32, shape=D)
        # M's non-zero pairs (i, j ≤ i): all of them, a valid superset (M·v adds exact zeros)
        lower = np.array([(i, j) for i in range(D) for j in range(i + 1)], dtype=np.int32)
        self.n_pairs = len(lower)
        self.pair_i, self.pair_j = ti.field(ti.i32, shape=self.n_pairs), ti.field(ti.i32, shape=self.n_pairs)
        self.pair_i.from_numpy(lower[:, 0])
        self.pair_j.from_numpy(lower[:, 1])
        self.dof_pair0 = ti.field(ti.i32, shape=D)  # where each dof's pairs start (i (i + 1) / 2)
        self.dof_pair0.from_numpy(np.array([i * (i + 1) // 2 for i in range(D)], dtype=np.int32))
        for name, (element, count) in cs.SCRATCH.items():
            setattr(self, name, ti.field(float if element == "f" else ti.i32, shape=shapes[count]))
        self.opt_iterations = ti.field(ti.i32, shape=E)
        self.opt_tolerance = ti.field(float, shape=E)
        self.opt_ls_iterations = ti.field(ti.i32, shape=E)
        self.opt_ls_tolerance = ti.field(float, shape=E)

    def load(self, cases, rng):
        """Copy the cases (one model) into envs 0..; padding dofs are free and unconstrained."""
        E, D, R = self.n_envs, self.n_dofs, self.n_rows
        nv = cases[0]["M"].shape[0]
        parent = np.full(D, -1, np.int32)
        parent[:nv] = cases[0]["dof_parent"]
        self.dof_parent.from_numpy(parent)
        arrays = {name: np.zeros(field.shape, np.int32 if field.dtype == ti.i32 else np.float64)
                  for name, field in self._inputs().items()}
        arrays["solver_M"][0, :] = np.eye(D)
        # unused slots hold garbage that must be skipped
        arrays["efc_J"][:] = rng.normal(size=(1, E, R, D))
        arrays["efc_R"][:] = 1.0
        arrays["efc_aref"][:] = rng.normal(size=(1, E, R))
        arrays["efc_dim"][:], arrays["efc_mu"][:], arrays["efc_floss"][:] = 3, 0.5, 0.1
        for e, c in enumerate(cases):
            slot, _ = _slots(c["kind"])
            arrays["solver_M"][0, e, :nv, :nv] = c["M"]
            arrays["qfrc_smooth"][0, e, :nv] = c["qfrc_smooth"]
            arrays["qacc_warmstart"][e, :nv] = c["warmstart"]
            arrays["efc_J"][0, e, :, nv:] = 0.0
            for name, key in (("efc_type", "kind"), ("efc_dim", "dim"), ("efc_mu", "mu"), ("efc_R", "R"),
                              ("efc_aref", "aref"), ("efc_floss", "floss")):
                arrays[name][0, e, slot] = c[key]
            arrays["efc_J"][0, e, slot, :nv] = c["J"]
            arrays["opt_iterations"][e] = c["opts"]["iterations"]
            arrays["opt_tolerance"][e] = c["opts"]["tolerance"]
            arrays["opt_ls_iterations"][e] = c["opts"]["ls_iterations"]
            arrays["opt_ls_tolerance"][e] = c["opts"]["ls_tolerance"]
        for name, field in self._inputs().items():
            field.from_numpy(arrays[name])
        self.solver_H.fill(0.0)  # the solve keeps only its blocks' envelopes: the rest reads as zero

    def _inputs(self):
        names = ("solver_M", "qfrc_smooth", "efc_type", "efc_dim", "efc_mu", "efc_J", "efc_R", "efc_aref",
                 "efc_floss", "qacc_warmstart", "opt_iterations", "opt_tolerance", "opt_ls_iterations",
                 "opt_ls_tolerance")
        return {name: getattr(self, name) for name in names}


@ti.kernel
def _solve_all(v: ti.template()):
    for e in range(v.n_envs):
        cs.newton_solve(v, 0, e, v.opt_iterations[e], v.opt_tolerance[e], v.opt_ls_iterations[e],
                        v.opt_ls_tolerance[e], 0)


@pytest.fixture(scope="module")
def results():
    """Every case of every scene, with our answers (ours) beside MuJoCo's (mj)."""
    gs.init(precision="64", logging_level="warning")
    scenes = {name: _scene_cases(xml, cone, ratio, seed)
              for seed, (name, (xml, cone, ratio)) in enumerate(SCENES.items())}
    all_cases = [c for cases in scenes.values() for c in cases]
    view = _View(max(len(cases) for cases in scenes.values()), max(c["M"].shape[0] for c in all_cases),
                 max(_slots(c["kind"])[1] for c in all_cases) + 2)
    rng = np.random.default_rng(7)
    for name, cases in scenes.items():
        view.load(cases, rng)
        with taichi_opt_level(launch.SOLVE_OPT_LEVEL):  # compiled as the solver compiles its solve
            _solve_all(view)
        out = {key: getattr(view, key).to_numpy()[0] for key in
               ("qacc", "qacc_smooth", "efc_force", "efc_state", "qfrc_constraint", "solver_niter", "solver_H")}
        for e, c in enumerate(cases):
            nv, (slot, _) = c["M"].shape[0], _slots(c["kind"])
            unused = np.ones(view.n_rows, bool)
            unused[slot] = False
            c["scene"] = name
            c["ours"] = dict(qacc=out["qacc"][e, :nv], qacc_smooth=out["qacc_smooth"][e, :nv],
                             force=out["efc_force"][e, slot], state=out["efc_state"][e, slot],
                             qfrc_constraint=out["qfrc_constraint"][e, :nv], niter=int(out["solver_niter"][e]),
                             unused_force=out["efc_force"][e, unused], unused_state=out["efc_state"][e, unused],
                             pad_qacc=out["qacc"][e, nv:], factor=out["solver_H"][e])
    return all_cases


def _rel(a, b):
    return np.max(np.abs(a - b), initial=0.0) / max(1.0, np.max(np.abs(b), initial=0.0))


def test_scenes_cover_every_row_type(results):
    """The scenes exercise joint equalities, friction loss, one-sided rows, elliptic blocks of dim
    3, 4, 6, pyramids of condim 1, 3, 4, 6, several islands and a multi-tree island."""
    kinds = {k for c in results for k in c["kind"]}
    assert kinds == {cs.EQUALITY, cs.FRICTION_LOSS, cs.ONE_SIDED, cs.ELLIPTIC_FIRST, cs.ELLIPTIC_REST}
    assert {3, 4, 6} <= {int(x) for c in results for x in c["dim"]}
    assert {1, 3, 4, 6} <= set().union(*(c["condims"] for c in results if not c["dim"].any()))
    states = {int(x) for c in results for x in c["mj"]["state"]}
    assert states == {cs.SATISFIED, cs.QUADRATIC, cs.LINEARNEG, cs.LINEARPOS, cs.CONE}
    assert max(c["mj"]["nisland"] for c in results) >= 3
    assert {c["variant"] for c in results if c["mj"]["niter"] == 0} >= {"converged"}


def test_tight_solution_matches_mujoco(results):
    """Both converged tightly: qacc and forces agree to 1e-10 relative."""
    for c in (c for c in results if c["variant"] == "tight"):
        ours, mj = c["ours"], c["mj"]
        assert _rel(ours["qacc"], mj["qacc"]) < 1e-10, c["scene"]
        assert _rel(ours["force"], mj["force"]) < 1e-10, c["scene"]
        assert _rel(ours["qfrc_constraint"], mj["qfrc_constraint"]) < 1e-10, c["scene"]
        assert _rel(ours["qacc_smooth"], mj["qacc_smooth"]) < 1e-12, c["scene"]


def test_default_options_match_mujoco_step(results):
    """Same options as MuJoCo's defaults, same warm start: qvel after a 2 ms step agrees to 1e-8
    (in fact far closer: the same iterates), and the iteration counts are equal."""
    for c in (c for c in results if c["variant"] != "tight"):
        ours, mj = c["ours"], c["mj"]
        assert np.max(np.abs(ours["qacc"] - mj["qacc"])) * H < 1e-8, (c["scene"], c["variant"])
        assert _rel(ours["qacc"], mj["qacc"]) < 1e-9, (c["scene"], c["variant"])
        assert _rel(ours["force"], mj["force"]) < 1e-9, (c["scene"], c["variant"])
        assert ours["niter"] == mj["niter"], (c["scene"], c["variant"])


def test_states_match_mujoco(results):
    for c in results:
        np.testing.assert_array_equal(c["ours"]["state"], c["mj"]["state"], err_msg=f"{c['scene']} {c['variant']}")


def test_final_hessian_factor(results):
    """solver_H holds L (lower, H = L Lᵀ) of MuJoCo's Hessian at the solution, cone blocks included;
    padding dofs carry M's factor (identity)."""
    for c in (c for c in results if c["variant"] == "tight"):
        L, nv = c["ours"]["factor"], c["M"].shape[0]
        assert not np.any(np.triu(L, 1))
        H = L @ L.T
        assert _rel(H[:nv, :nv], c["mj"]["hessian"]) < 1e-9, c["scene"]
        np.testing.assert_array_equal(H[nv:, nv:], np.eye(len(L) - nv))
        assert not np.any(H[nv:, :nv])


def test_unused_slots_and_padding_untouched(results):
    """Unused row slots (garbage Jacobians) get no force; padding dofs stay at qacc_smooth = 0."""
    for c in results:
        assert not np.any(c["ours"]["unused_force"])
        assert not np.any(c["ours"]["unused_state"])
        assert not np.any(c["ours"]["pad_qacc"])
