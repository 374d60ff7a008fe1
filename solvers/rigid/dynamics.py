"""Velocity and inertia stages: recursive Newton–Euler bias forces and the joint-space mass
matrix by composite rigid bodies, all in the world frame about each tree's reference point
(kinematics.reference; Featherstone).

Each forward function has its hand-written reverse further down (see docs/architecture.md).
"""
import taichi as ti

from .model import BALL, FREE, PRISMATIC, REVOLUTE
from .data import accumulate
from .kinematics import reference
from .spatial import cross_force, cross_motion, dot3, inertia_mul, inertia_mul_adjoint


@ti.func
def _dof_motion(d: ti.template(), s, e, dof, vw, vv):
    """A dof's velocity (cdof·q̇) and velocity-product acceleration ((v × cdof)·q̇), the axis
    moving with velocity (vw, vv)."""
    qd = d.qvel[s, e, dof]
    sw, sv = d.cdof_w[s, e, dof], d.cdof_v[s, e, dof]
    dw, dv = cross_motion(vw, vv, sw, sv)
    return sw * qd, sv * qd, dw * qd, dv * qd


@ti.func
def _turning_frame(d: ti.template(), s, e, jt, dof0, vv):
    """(vt (3,) m/s, first rotation dof) of a free or ball joint whose dofs start at dof0, vv its
    parent's linear velocity: a free joint's translation dofs are fixed world axes, and its
    rotation axes move with the translating frame (their own rotation adds ω × ω = 0), as in
    MuJoCo's mj_comVel; a ball joint's rotations move with the parent."""
    vt, turn0 = vv, dof0
    if jt == FREE:
        vt = vv + ti.Vector([d.qvel[s, e, dof0 + k] for k in ti.static(range(3))])
        turn0 = dof0 + 3
    return vt, turn0


@ti.func
def _link_motion(d: ti.template(), s, e, l):
    """Spatial velocity and acceleration (at zero qacc, gravity as a base acceleration) of link l."""
    p = d.link_parent[l]
    vw, vv, aw = ti.Vector.zero(float, 3), ti.Vector.zero(float, 3), ti.Vector.zero(float, 3)
    av = -ti.Vector([d.gravity[e, 0], d.gravity[e, 1], d.gravity[e, 2]])
    if p >= 0:
        vw, vv, aw, av = d.cvel_w[s, e, p], d.cvel_v[s, e, p], d.cacc_w[s, e, p], d.cacc_v[s, e, p]
    jt = d.link_jtype[l]
    dof0 = d.link_dof0[l]
    w, v, dw, dv = vw, vv, aw, av
    if jt == REVOLUTE or jt == PRISMATIC:  # the axis moves with the parent
        w1, v1, dw1, dv1 = _dof_motion(d, s, e, dof0, vw, vv)
        w, v, dw, dv = vw + w1, vv + v1, aw + dw1, av + dv1
    elif jt == FREE or jt == BALL:
        vt, turn0 = _turning_frame(d, s, e, jt, dof0, vv)
        v = vt
        for k in ti.static(range(3)):
            wk, vk, dwk, dvk = _dof_motion(d, s, e, turn0 + k, vw, vt)
            w, v, dw, dv = w + wk, v + vk, dw + dwk, dv + dvk
    return w, v, dw, dv


@ti.func
def _external(d: ti.template(), e, l):
    """(force N, torque N·m) applied to link l at its origin this step, world frame (xfrc)."""
    return (ti.Vector([d.xfrc[e, 6 * l + k] for k in ti.static(range(3))]),
            ti.Vector([d.xfrc[e, 6 * l + 3 + k] for k in ti.static(range(3))]))


@ti.func
def link_forces(d: ti.template(), s, e, l):
    """cvel, cacc and the net force link l needs (f = I·a + v ×* I·v, less the external wrench:
    its torque about the reference, τ + (x_l − ref) × f, and f, and less the gravity compensation's
    force at the centre of mass); parent first."""
    vw, vv, aw, av = _link_motion(d, s, e, l)
    d.cvel_w[s, e, l], d.cvel_v[s, e, l] = vw, vv
    d.cacc_w[s, e, l], d.cacc_v[s, e, l] = aw, av
    m, h, inertia = d.cinert_m[s, e, l], d.cinert_h[s, e, l], d.cinert_i[s, e, l]
    fn, ff = inertia_mul(m, h, inertia, aw, av)
    pn, pf = inertia_mul(m, h, inertia, vw, vv)
    cn, cf = cross_force(vw, vv, pn, pf)
    if d.wrench:
        force, torque = _external(d, e, l)
        lever = d.xpos[s, e, l] - reference(d, s, e, l)
        fn, ff = fn - (torque + lever.cross(force)), ff - force
    if d.gravcomp:
        lift = _gravity_compensated(d, e, l)
        fn, ff = fn + h.cross(lift), ff + m * lift
    d.cfrc_n[s, e, l], d.cfrc_f[s, e, l] = fn + cn, ff + cf  # the up sweep adds the children's


@ti.func
def _gravity_compensated(d: ti.template(), e, l):
    """c·g (3,) m/s², the share c = link_gravcomp[l] of gravity a force −c·m·g at link l's centre of
    mass cancels (MuJoCo's body gravcomp, Genesis's gravity_compensation). The base acceleration −g
    puts (−h × g, −m g) into the link's force (inertia_mul at zero turn rate); the compensation takes
    (−h × c g, −m c g) out of it, i.e. the force the link needs loses m c g at its centre of mass."""
    return d.link_gravcomp[l] * ti.Vector([d.gravity[e, k] for k in ti.static(range(3))])


@ti.func
def subtree_sum(d: ti.template(), s, e, l):
    """Add link l's composite inertia and subtree force into its parent's; run leaves first.
    crb and cfrc start as each link's own (written by the down sweep), so once a link's
    children are done its values are its subtree's."""
    p = d.link_parent[l]
    if p >= 0:
        accumulate(d.crb_m, ti.Vector([s, e, p]), d.crb_m[s, e, l])
        accumulate(d.crb_h, ti.Vector([s, e, p]), d.crb_h[s, e, l])
        accumulate(d.crb_i, ti.Vector([s, e, p]), d.crb_i[s, e, l])
        accumulate(d.cfrc_n, ti.Vector([s, e, p]), d.cfrc_n[s, e, l])
        accumulate(d.cfrc_f, ti.Vector([s, e, p]), d.cfrc_f[s, e, l])


@ti.func
def dof_force(d: ti.template(), s, e, i):
    """F_i = (composite inertia of link(i)) cdof_i: the force moving dof i at unit rate takes."""
    l = d.dof_link[i]
    fn, ff = inertia_mul(d.crb_m[s, e, l], d.crb_h[s, e, l], d.crb_i[s, e, l], d.cdof_w[s, e, i], d.cdof_v[s, e, i])
    d.dof_force_n[s, e, i], d.dof_force_f[s, e, i] = fn, ff


@ti.func
def mass_entry(d: ti.template(), s, e, k):
    """Mass-matrix pair k: M[i, j] = cdof_j · F_i (dof j on the path from dof i to the root)."""
    i, j = d.pair_i[k], d.pair_j[k]
    value = dot3(d.cdof_w[s, e, j], d.dof_force_n[s, e, i]) + dot3(d.cdof_v[s, e, j], d.dof_force_f[s, e, i])
    d.mass_mat[s, e, i, j] = value
    if i != j:
        d.mass_mat[s, e, j, i] = value


@ti.func
def bias_entry(d: ti.template(), s, e, i):
    """qfrc_bias[i] = cdof_i · (net force of the subtree of link(i)): Coriolis, centrifugal, gravity."""
    l = d.dof_link[i]
    d.qfrc_bias[s, e, i] = dot3(d.cdof_w[s, e, i], d.cfrc_n[s, e, l]) + dot3(d.cdof_v[s, e, i], d.cfrc_f[s, e, l])


# -- reverse mode: each function below undoes the one of the same name above, for one env -----
@ti.func
def _dof_motion_adjoint(sw, sv, qd, vw, vv, gw, gv, gdw, gdv):
    """Gradients (q̇, cdof w, cdof v, moving-frame vw, vv) of _dof_motion from those of its outputs."""
    g_qd = dot3(sw, gw) + dot3(sv, gv) + dot3(vw.cross(sw), gdw) + dot3(vw.cross(sv) + vv.cross(sw), gdv)
    g_sw = qd * (gw + gdw.cross(vw) + gdv.cross(vv))
    g_sv = qd * (gv + gdv.cross(vw))
    return g_qd, g_sw, g_sv, qd * (sw.cross(gdw) + sv.cross(gdv)), qd * sw.cross(gdv)


@ti.func
def _one_dof_adjoint(d: ti.template(), s, e, dof, vw, vv, gw, gv, gdw, gdv):
    """Reverse of one _dof_motion term: q̇ and cdof gradients stored; the frame's returned."""
    g_qd, g_sw, g_sv, g_vw, g_vv = _dof_motion_adjoint(d.cdof_w[s, e, dof], d.cdof_v[s, e, dof],
                                                       d.qvel[s, e, dof], vw, vv, gw, gv, gdw, gdv)
    accumulate(d.qvel.grad, ti.Vector([s, e, dof]), g_qd)
    accumulate(d.cdof_w.grad, ti.Vector([s, e, dof]), g_sw)
    accumulate(d.cdof_v.grad, ti.Vector([s, e, dof]), g_sv)
    return g_vw, g_vv


@ti.func
def _link_motion_adjoint(d: ti.template(), s, e, l, gw, gv, gaw, gav):
    """Reverse of _link_motion from the gradients of link l's velocity (gw, gv) and acceleration."""
    p = d.link_parent[l]
    pp = ti.max(p, 0)
    zero = ti.Vector.zero(float, 3)
    vw = d.cvel_w[s, e, pp] if p >= 0 else zero
    vv = d.cvel_v[s, e, pp] if p >= 0 else zero
    jt = d.link_jtype[l]
    dof0 = d.link_dof0[l]
    g_vw, g_vv = gw, gv  # the parent's velocity passes straight through
    if jt == REVOLUTE or jt == PRISMATIC:
        w, v = _one_dof_adjoint(d, s, e, dof0, vw, vv, gw, gv, gaw, gav)
        g_vw += w
        g_vv += v
    elif jt == FREE or jt == BALL:
        vt, turn0 = _turning_frame(d, s, e, jt, dof0, vv)
        g_vt = gv
        for k in ti.static(range(3)):
            w, v = _one_dof_adjoint(d, s, e, turn0 + k, vw, vt, gw, gv, gaw, gav)
            g_vw += w
            g_vt += v
        if jt == FREE:
            for k in ti.static(range(3)):
                accumulate(d.qvel.grad, ti.Vector([s, e, dof0 + k]), g_vt[k])
        g_vv = g_vt
    if p >= 0:
        accumulate(d.cvel_w.grad, ti.Vector([s, e, p]), g_vw)
        accumulate(d.cvel_v.grad, ti.Vector([s, e, p]), g_vv)
        accumulate(d.cacc_w.grad, ti.Vector([s, e, p]), gaw)
        accumulate(d.cacc_v.grad, ti.Vector([s, e, p]), gav)
    else:  # a root's base acceleration is −gravity
        for k in ti.static(range(3)):
            accumulate(d.gravity.grad, ti.Vector([e, k]), -gav[k])


@ti.func
def link_forces_adjoint(d: ti.template(), s, e, l):
    """Reverse of link_forces; returns the gradient (m, h, I) of link l's own inertia, which
    link_kinematics_adjoint takes next. Link l's force and inertia gradients are those of its
    subtree's sums (subtree_sum_adjoint has run). A static link's inertia and forces reach no
    dof: only its motion's gradient flows (to gravity)."""
    gw, gv = d.cvel_w.grad[s, e, l], d.cvel_v.grad[s, e, l]
    gaw, gav = d.cacc_w.grad[s, e, l], d.cacc_v.grad[s, e, l]
    g_m, g_h, g_i = 0.0, ti.Vector.zero(float, 3), ti.Matrix.zero(float, 3, 3)
    if not d.link_static[l]:
        vw, vv = d.cvel_w[s, e, l], d.cvel_v[s, e, l]
        aw, av = d.cacc_w[s, e, l], d.cacc_v[s, e, l]
        m, h, inertia = d.cinert_m[s, e, l], d.cinert_h[s, e, l], d.cinert_i[s, e, l]
        gn, gf = d.cfrc_n.grad[s, e, l], d.cfrc_f.grad[s, e, l]
        gm, gh, gi, g_aw, g_av = inertia_mul_adjoint(m, h, inertia, aw, av, gn, gf)
        pn, pf = inertia_mul(m, h, inertia, vw, vv)
        # (cn, cf) = (vw × pn + vv × pf, vw × pf)
        gm2, gh2, gi2, gvw, gvv = inertia_mul_adjoint(m, h, inertia, vw, vv, gn.cross(vw),
                                                      gn.cross(vv) + gf.cross(vw))
        # the external wrench: ∂/∂τ = −gn, ∂/∂f = −gf − gn × lever, and the lever x_l − ref (as
        # everywhere, the reference's own gradient is left out: the dynamics do not depend on it)
        if d.wrench:
            force, _ = _external(d, e, l)
            lever = d.xpos[s, e, l] - reference(d, s, e, l)
            accumulate(d.xpos.grad, ti.Vector([s, e, l]), gn.cross(force))
            g_force = -gf - gn.cross(lever)
            for k in ti.static(range(3)):
                accumulate(d.xfrc.grad, ti.Vector([e, 6 * l + k]), g_force[k])
                accumulate(d.xfrc.grad, ti.Vector([e, 6 * l + 3 + k]), -gn[k])
        if d.gravcomp:  # (h × c g, m c g): ∂/∂m = gf · c g, ∂/∂h = c g × gn, ∂/∂g = c (gn × h + m gf)
            lift = _gravity_compensated(d, e, l)
            gm += dot3(gf, lift)
            gh += lift.cross(gn)
            g_lift = d.link_gravcomp[l] * (gn.cross(h) + m * gf)
            for k in ti.static(range(3)):
                accumulate(d.gravity.grad, ti.Vector([e, k]), g_lift[k])
        g_m = d.crb_m.grad[s, e, l] + gm + gm2
        g_h = d.crb_h.grad[s, e, l] + gh + gh2
        g_i = d.crb_i.grad[s, e, l] + gi + gi2
        gw += gvw + pn.cross(gn) + pf.cross(gf)
        gv += gvv + pf.cross(gn)
        gaw += g_aw
        gav += g_av
    _link_motion_adjoint(d, s, e, l, gw, gv, gaw, gav)
    return g_m, g_h, g_i


@ti.func
def subtree_sum_adjoint(d: ti.template(), s, e, l):
    """crb[l] and cfrc[l] are link l's own value plus its children's sums, so each child's sum
    takes the gradient of its parent's (run roots first): afterwards the gradient of a link's
    sum is also that of its own inertia and force. A static link's sums reach no dof."""
    p = d.link_parent[l]
    if p >= 0 and not d.link_static[l]:
        accumulate(d.crb_m.grad, ti.Vector([s, e, l]), d.crb_m.grad[s, e, p])
        accumulate(d.crb_h.grad, ti.Vector([s, e, l]), d.crb_h.grad[s, e, p])
        accumulate(d.crb_i.grad, ti.Vector([s, e, l]), d.crb_i.grad[s, e, p])
        accumulate(d.cfrc_n.grad, ti.Vector([s, e, l]), d.cfrc_n.grad[s, e, p])
        accumulate(d.cfrc_f.grad, ti.Vector([s, e, l]), d.cfrc_f.grad[s, e, p])


@ti.func
def dof_row_adjoint(d: ti.template(), s, e, i):
    """Reverse of bias_entry, of row i of the mass matrix (mass_entry) and of dof_force for dof
    i. M[i, j] = cdof_j · F_i along the dof tree, so the gradient of F_i is summed over the row
    in registers and goes straight on to the composite inertia and cdof_i."""
    l = d.dof_link[i]
    sw, sv = d.cdof_w[s, e, i], d.cdof_v[s, e, i]
    g = d.qfrc_bias.grad[s, e, i]
    accumulate(d.cdof_w.grad, ti.Vector([s, e, i]), g * d.cfrc_n[s, e, l])
    accumulate(d.cdof_v.grad, ti.Vector([s, e, i]), g * d.cfrc_f[s, e, l])
    accumulate(d.cfrc_n.grad, ti.Vector([s, e, l]), g * sw)
    accumulate(d.cfrc_f.grad, ti.Vector([s, e, l]), g * sv)
    fn, ff = d.dof_force_n[s, e, i], d.dof_force_f[s, e, i]
    g_fn, g_ff = ti.Vector.zero(float, 3), ti.Vector.zero(float, 3)
    j = i
    while j != -1:  # the dofs on the path from i to the root: row i's structural entries
        g_ij = d.mass_mat.grad[s, e, i, j] + (d.mass_mat.grad[s, e, j, i] if i != j else 0.0)
        g_fn += g_ij * d.cdof_w[s, e, j]
        g_ff += g_ij * d.cdof_v[s, e, j]
        accumulate(d.cdof_w.grad, ti.Vector([s, e, j]), g_ij * fn)
        accumulate(d.cdof_v.grad, ti.Vector([s, e, j]), g_ij * ff)
        j = d.dof_parent[j]
    gm, gh, gi, gw, gv = inertia_mul_adjoint(d.crb_m[s, e, l], d.crb_h[s, e, l], d.crb_i[s, e, l], sw, sv, g_fn, g_ff)
    accumulate(d.crb_m.grad, ti.Vector([s, e, l]), gm)
    accumulate(d.crb_h.grad, ti.Vector([s, e, l]), gh)
    accumulate(d.crb_i.grad, ti.Vector([s, e, l]), gi)
    accumulate(d.cdof_w.grad, ti.Vector([s, e, i]), gw)
    accumulate(d.cdof_v.grad, ti.Vector([s, e, i]), gv)
