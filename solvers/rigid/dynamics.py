"""Velocity and inertia stages: recursive Newton–Euler bias forces and the joint-space mass
matrix by composite rigid bodies, all in the world frame about the origin (Featherstone).

Each link's quantities are written once per frame; sums over subtrees use ``+=`` only, in
reverse tree order, so Taichi's reverse mode differentiates them exactly.
"""
import taichi as ti

from .model import FREE, PRISMATIC, REVOLUTE
from .spatial import cross_force, cross_motion, inertia_mul


@ti.func
def _link_motion(d: ti.template(), s, e, l):
    """Spatial velocity and acceleration (at zero qacc, gravity as a base acceleration) of link l."""
    p = d.link_parent[l]
    pp = ti.max(p, 0)
    vw = ti.Vector.zero(float, 3)
    vv = ti.Vector.zero(float, 3)
    aw = ti.Vector.zero(float, 3)
    av = -ti.Vector([d.gravity[e, 0], d.gravity[e, 1], d.gravity[e, 2]])
    if p >= 0:
        vw, vv = d.cvel_w[s, e, pp], d.cvel_v[s, e, pp]
        aw, av = d.cacc_w[s, e, pp], d.cacc_v[s, e, pp]
    jt = d.link_jtype[l]
    dof0 = d.link_dof0[l]
    if jt == REVOLUTE or jt == PRISMATIC:
        qd = d.qvel[s, e, dof0]
        sw, sv = d.cdof_w[s, e, dof0], d.cdof_v[s, e, dof0]
        dw, dv = cross_motion(vw, vv, sw, sv)  # d(cdof)/dt: the axis moves with the parent
        vw, vv = vw + sw * qd, vv + sv * qd
        aw, av = aw + dw * qd, av + dv * qd
    elif jt == FREE:
        # Translation dofs are fixed world axes; the rotation axes move with the translating
        # frame (their own rotation contributes ω × ω = 0), as in MuJoCo's mj_comVel.
        vv = vv + ti.Vector([d.qvel[s, e, dof0], d.qvel[s, e, dof0 + 1], d.qvel[s, e, dof0 + 2]])
        rw = ti.Vector.zero(float, 3)
        rv = ti.Vector.zero(float, 3)
        for k in ti.static(range(3, 6)):
            qd = d.qvel[s, e, dof0 + k]
            sw, sv = d.cdof_w[s, e, dof0 + k], d.cdof_v[s, e, dof0 + k]
            dw, dv = cross_motion(vw, vv, sw, sv)
            rw, rv = rw + sw * qd, rv + sv * qd
            aw, av = aw + dw * qd, av + dv * qd
        vw, vv = vw + rw, vv + rv
    return vw, vv, aw, av


@ti.func
def bias_sweeps_env(d: ti.template(), s, e):
    """cvel, cacc, per-link net forces, then subtree sums of forces and composite inertias."""
    for l in range(d.n_links):
        vw, vv, aw, av = _link_motion(d, s, e, l)
        d.cvel_w[s, e, l], d.cvel_v[s, e, l] = vw, vv
        d.cacc_w[s, e, l], d.cacc_v[s, e, l] = aw, av
        m, h, inertia = d.cinert_m[s, e, l], d.cinert_h[s, e, l], d.cinert_i[s, e, l]
        fn, ff = inertia_mul(m, h, inertia, aw, av)
        pn, pf = inertia_mul(m, h, inertia, vw, vv)
        cn, cf = cross_force(vw, vv, pn, pf)
        d.cfrc_n[s, e, l], d.cfrc_f[s, e, l] = fn + cn, ff + cf
    for i in range(d.n_links):
        l = d.n_links - 1 - i
        p = d.link_parent[l]
        if p >= 0:
            d.cfrc_n[s, e, p] += d.cfrc_n[s, e, l]
            d.cfrc_f[s, e, p] += d.cfrc_f[s, e, l]
            d.crb_m[s, e, p] += d.crb_m[s, e, l]
            d.crb_h[s, e, p] += d.crb_h[s, e, l]
            d.crb_i[s, e, p] += d.crb_i[s, e, l]


@ti.func
def mass_entry(d: ti.template(), s, e, k):
    """Mass-matrix pair k: M[i, j] = cdof_i · (composite inertia of link(i)) cdof_j."""
    i, j = d.pair_i[k], d.pair_j[k]
    l = d.dof_link[i]
    fn, ff = inertia_mul(d.crb_m[s, e, l], d.crb_h[s, e, l], d.crb_i[s, e, l], d.cdof_w[s, e, j],
                         d.cdof_v[s, e, j])
    value = d.cdof_w[s, e, i].dot(fn) + d.cdof_v[s, e, i].dot(ff)
    d.mass_mat[s, e, i, j] = value
    if i != j:
        d.mass_mat[s, e, j, i] = value


@ti.func
def bias_entry(d: ti.template(), s, e, i):
    """qfrc_bias[i] = cdof_i · (net force of the subtree of link(i)): Coriolis, centrifugal, gravity."""
    l = d.dof_link[i]
    d.qfrc_bias[s, e, i] = d.cdof_w[s, e, i].dot(d.cfrc_n[s, e, l]) + d.cdof_v[s, e, i].dot(d.cfrc_f[s, e, l])


@ti.kernel
def bias_sweeps(d: ti.template(), s: ti.i32):
    for e in range(d.n_batch):
        bias_sweeps_env(d, s, e)


@ti.kernel
def joint_space(d: ti.template(), s: ti.i32):
    """Mass matrix and bias force, parallel over (env, pair) and (env, dof)."""
    for e, k in ti.ndrange(d.n_batch, d.n_pairs):
        mass_entry(d, s, e, k)
    for e, i in ti.ndrange(d.n_batch, d.n_dofs):
        bias_entry(d, s, e, i)
