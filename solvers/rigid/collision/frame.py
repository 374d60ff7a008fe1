"""Contact frame and small geometry helpers shared by the colliders.

Conventions (the package docstring): vectors are world-frame 3-vectors (m for points),
rotations are 3x3 matrices whose columns are a geom's axes in the world. Where a result decides
a branch (a distance against a margin, a clamp), the arithmetic follows MuJoCo's order of
operations so the same branch is taken; the build runs without fast math, so these functions
reproduce MuJoCo's doubles, not just its formulas.

The helpers the colliders' evaluates use have hand-written reverses beside them, named
``<helper>_adjoint`` (column, cross3, normalize3, segment_pair_terms, segment_pair_params,
segment_weight_terms, segment_weights): given the helper's inputs and the gradients of its
outputs they return the gradients of its inputs, for the same frozen state where it has one.
"""
import taichi as ti

from ..spatial import dot3

MINVAL = 1e-15  # MuJoCo's mjMINVAL: below it a length or determinant counts as zero

# Clamp states of a segment parameter x in [-1, 1] (segment_pair_state); FREE also for weights
FREE, AT_PLUS, AT_MINUS = 0, 1, 2


@ti.func
def column(rot, j: ti.template()):
    """Column j of a 3x3 matrix: geom axis j (world) when rot is a geom's rotation."""
    return ti.Vector([rot[0, j], rot[1, j], rot[2, j]])


@ti.func
def column_adjoint(g_column, j: ti.template()):
    """Reverse of column: the (3, 3) gradient of rot, g_column (3,) in column j, zeros elsewhere."""
    g_rot = ti.Matrix.zero(float, 3, 3)
    for i in ti.static(range(3)):
        g_rot[i, j] = g_column[i]
    return g_rot


@ti.func
def cross3(a, b):
    """a × b of two 3-vectors, written out in MuJoCo's order."""
    return ti.Vector([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


@ti.func
def cross3_adjoint(a, b, g_cross):
    """Reverse of cross3: (g_a, g_b) = (b × g, g × a) for the gradient g_cross (3,) of a × b."""
    return cross3(b, g_cross), cross3(g_cross, a)


@ti.func
def normalize3(v):
    """(v / |v|, |v|) for a 3-vector, as MuJoCo's mju_normalize3.

    A vector shorter than MINVAL becomes the world x axis (1, 0, 0); the returned length is
    still the true |v|, so callers can detect that case. Scales by the reciprocal, as MuJoCo.
    """
    norm = ti.sqrt(dot3(v, v))
    unit = ti.Vector([1.0, 0.0, 0.0])
    if norm >= MINVAL:
        unit = v * (1.0 / norm)
    return unit, norm


@ti.func
def normalize3_adjoint(v, g_unit, g_norm):
    """Reverse of normalize3: the gradient (3,) of v given those of unit (3,) and norm.

    |v| >= MINVAL: (g_unit - u (u·g_unit)) / |v| + g_norm u, u = v / |v|. Shorter, where
    normalize3 takes v for zero: 0 (the unit is the constant x axis, and the norm's kink at v = 0
    has the symmetric subgradient 0, which is also what a central difference sees there).
    """
    norm = ti.sqrt(dot3(v, v))
    g_v = ti.Vector.zero(float, 3)
    if norm >= MINVAL:
        unit = v * (1.0 / norm)
        g_v = (g_unit - unit * dot3(unit, g_unit)) / norm + unit * g_norm
    return g_v


@ti.func
def contact_frame(normal, tangent):
    """MuJoCo's mjContact.frame (mju_makeFrame) as a 3x3 matrix of rows (n, t1, t2).

    normal: (3,) the collider's contact normal, geom 1 → geom 2 (renormalized here, as MuJoCo).
    tangent: (3,) a first tangent hint: MuJoCo's colliders pass zeros, except plane–capsule which
    passes the capsule axis. A hint with squared length < 0.25 is replaced by the world y axis
    when |n_y| < 0.5, else by the world z axis — a discontinuous choice of basis. The hint is then
    made orthogonal to n and normalized (x axis if it vanishes); t2 = n × t1.
    """
    n, _ = normalize3(normal)
    hint = tangent
    if dot3(hint, hint) < 0.25:
        hint = ti.Vector([0.0, 0.0, 1.0])
        if n[1] < 0.5 and n[1] > -0.5:
            hint = ti.Vector([0.0, 1.0, 0.0])
    t1, _ = normalize3(hint - n * dot3(n, hint))
    t2 = cross3(n, t1)
    return ti.Matrix.rows([n, t1, t2])


# ---------------------------------------------------------------- closest points of two segments, x in [-1, 1]
#
# MuJoCo's older "line-line" step (mjc_CapsuleBox's segment test; MuJoCo 3's capsule–capsule).
# Segment i is the set c_i + x_i a_i, x_i in [-1, 1] (a_i: half-segment vector, e.g. a capsule's
# axis times its half-length). The squared distance |c1 + x1 a1 - c2 - x2 a2|² is, up to a
# constant, ½ ma x1² + mb x1 x2 + ½ mc x2² - u x1 - v x2 with the coefficients below (MuJoCo's
# names and signs). A pair of clamp states (s1, s2), each FREE / AT_PLUS / AT_MINUS, coded
# state = 3 s1 + s2, fixes the closed form of (x1, x2): a clamped parameter is ±1, a free one
# minimizes the quadratic given the other (both free: the 2x2 solve).


@ti.func
def segment_pair_terms(a1, a2, dif):
    """Quadratic coefficients (ma, mb, mc, u, v, det) of two segments; dif = c1 - c2.

    ma = a1·a1, mb = -a1·a2, mc = a2·a2, u = -a1·dif, v = a2·dif, det = ma mc - mb² (length⁴;
    MuJoCo treats |det| < MINVAL as parallel).
    """
    ma = dot3(a1, a1)
    mb = -dot3(a1, a2)
    mc = dot3(a2, a2)
    u = -dot3(a1, dif)
    v = dot3(a2, dif)
    return ma, mb, mc, u, v, ma * mc - mb * mb


@ti.func
def segment_pair_terms_adjoint(a1, a2, dif, g_ma, g_mb, g_mc, g_u, g_v, g_det):
    """Reverse of segment_pair_terms: (g_a1, g_a2, g_dif) (3,) each, given the gradients of its
    six outputs (det = ma mc - mb² passes its gradient on through ma, mb, mc)."""
    ma, mb, mc, _, _, _ = segment_pair_terms(a1, a2, dif)
    g_ma_all = g_ma + g_det * mc
    g_mb_all = g_mb - 2.0 * g_det * mb
    g_mc_all = g_mc + g_det * ma
    g_a1 = a1 * (2.0 * g_ma_all) - a2 * g_mb_all - dif * g_u
    g_a2 = a2 * (2.0 * g_mc_all) - a1 * g_mb_all + dif * g_v
    return g_a1, g_a2, a2 * g_v - a1 * g_u


@ti.func
def clamp_value(state):
    """The parameter value of a clamped state: +1 for AT_PLUS, -1 for AT_MINUS."""
    return ti.select(state == AT_PLUS, 1.0, -1.0)


@ti.func
def clamp_state(x):
    """Which way MuJoCo's mju_clip(x, -1, 1) goes: FREE, AT_PLUS (x > 1) or AT_MINUS (x < -1)."""
    state = FREE
    if x < -1.0:
        state = AT_MINUS
    elif x > 1.0:
        state = AT_PLUS
    return state


@ti.func
def segment_pair_params(ma, mb, mc, u, v, det, state):
    """Closed-form segment parameters (x1, x2) of a frozen clamp state (3 s1 + s2).

    Both free: the 2x2 solve (needs det != 0); one clamped to ±1: the other minimizes given it,
    x2 = (v - mb x1)/mc or x1 = (u - mb x2)/ma (no clip: the state says it is inside).
    """
    s1 = state // 3
    s2 = state % 3
    x1 = 0.0
    x2 = 0.0
    if s1 == FREE and s2 == FREE:
        x1 = (mc * u - mb * v) / det
        x2 = (ma * v - mb * u) / det
    elif s2 == FREE:
        x1 = clamp_value(s1)
        x2 = (v - mb * x1) / mc
    elif s1 == FREE:
        x2 = clamp_value(s2)
        x1 = (u - mb * x2) / ma
    else:
        x1 = clamp_value(s1)
        x2 = clamp_value(s2)
    return x1, x2


@ti.func
def segment_pair_params_adjoint(ma, mb, mc, u, v, det, state, g_x1, g_x2):
    """Reverse of segment_pair_params for the same frozen state: the gradients (g_ma, g_mb,
    g_mc, g_u, g_v, g_det) given those of x1, x2. det is an input of its own (chain it through
    segment_pair_terms_adjoint); a clamped parameter (±1) passes no gradient. Both clamped: 0.
    """
    x1, x2 = segment_pair_params(ma, mb, mc, u, v, det, state)
    s1 = state // 3
    s2 = state % 3
    g_ma = 0.0
    g_mb = 0.0
    g_mc = 0.0
    g_u = 0.0
    g_v = 0.0
    g_det = 0.0
    if s1 == FREE and s2 == FREE:  # x1 det = mc u - mb v, x2 det = ma v - mb u
        h1 = g_x1 / det
        h2 = g_x2 / det
        g_ma = h2 * v
        g_mb = -h1 * v - h2 * u
        g_mc = h1 * u
        g_u = h1 * mc - h2 * mb
        g_v = h2 * ma - h1 * mb
        g_det = -h1 * x1 - h2 * x2
    elif s2 == FREE:  # x2 mc = v - mb x1
        h2 = g_x2 / mc
        g_v = h2
        g_mb = -h2 * x1
        g_mc = -h2 * x2
    elif s1 == FREE:  # x1 ma = u - mb x2
        h1 = g_x1 / ma
        g_u = h1
        g_mb = -h1 * x2
        g_ma = -h1 * x1
    return g_ma, g_mb, g_mc, g_u, g_v, g_det


@ti.func
def segment_pair_state(ma, mb, mc, u, v, det):
    """MuJoCo's clamping of the closest points of two non-parallel segments (|det| >= MINVAL).

    Solve unconstrained; if x1 leaves [-1, 1], clamp it and re-solve x2; if x2 then leaves
    [-1, 1], clamp it and re-solve x1, clipped. Returns (the final clamp state 3 s1 + s2, whose
    closed form segment_pair_params reproduces; x1's clamp flag as MuJoCo's mjraw_CapsuleBox
    reports it): where clamping x2 re-solves x1 inside [-1, 1], MuJoCo keeps x1's flag from the
    first solve (at an end, though x1 is free), and the flag chooses the capsule–box contacts.
    """
    x1 = (mc * u - mb * v) / det
    x2 = (ma * v - mb * u) / det
    s1 = clamp_state(x1)
    flag = s1
    s2 = FREE
    if s1 != FREE:
        x2 = (v - mb * clamp_value(s1)) / mc
    if x2 > 1.0 or x2 < -1.0:
        s2 = clamp_state(x2)
        s1 = clamp_state((u - mb * clamp_value(s2)) / ma)
        if s1 != FREE:
            flag = s1
    return 3 * s1 + s2, flag


# ---------------------------------------------------------------- closest points of two segments, weights in [0, 1]
#
# MuJoCo 4's segment–segment step (mjc_segWeights, used by mjc_CapsuleCapsule). Segment P runs
# from p0 to p1, segment Q from q0 to q1; points are p0 + s d1 and q0 + t d2 with weights s, t in
# [0, 1] and d1 = p1 - p0, d2 = q1 - q0, r = p0 - q0. With a = d1·d1, b = d1·d2, c = d1·r,
# e = d2·d2, f = d2·r: t given s is (b s + f)/e, s given t is (b t - c)/a, and both free
# s = (d1×d2)·(d2×r)/|d1×d2|². A weight state is FREE, AT_START (weight 0) or AT_END (weight 1);
# the pair state 3 s_state + t_state fixes the closed form (segment_weights).
AT_START, AT_END = 1, 2
PARALLEL_SINE_SQR = 1e-8  # |d1×d2|² <= 1e-8 |d1|²|d2|² (about 1e-4 rad): parallel segments
SHORT_SQR = 1e-15  # |d|² <= 1e-15 m²: a segment shrunk to a point


@ti.func
def segment_weight_terms(p0, p1, q0, q1):
    """(d1, d2, r, a, b, c, e, f) of segments p0→p1 and q0→q1 (see the block comment)."""
    d1 = p1 - p0
    d2 = q1 - q0
    r = p0 - q0
    return d1, d2, r, dot3(d1, d1), dot3(d1, d2), dot3(d1, r), dot3(d2, d2), dot3(r, d2)


@ti.func
def segment_weight_terms_adjoint(p0, p1, q0, q1, g_d1, g_d2, g_r, g_a, g_b, g_c, g_e, g_f):
    """Reverse of segment_weight_terms: (g_p0, g_p1, g_q0, g_q1) (3,) each, given the gradients
    of its outputs (d1, d2, r (3,) each; a, b, c, e, f scalars)."""
    d1, d2, r, _, _, _, _, _ = segment_weight_terms(p0, p1, q0, q1)
    g_d1_all = g_d1 + d1 * (2.0 * g_a) + d2 * g_b + r * g_c
    g_d2_all = g_d2 + d1 * g_b + d2 * (2.0 * g_e) + r * g_f
    g_r_all = g_r + d1 * g_c + d2 * g_f
    return g_r_all - g_d1_all, g_d1_all, -g_r_all - g_d2_all, g_d2_all


@ti.func
def weight_value(state):
    """The weight of a clamped state: 0 for AT_START, 1 for AT_END."""
    return ti.select(state == AT_END, 1.0, 0.0)


@ti.func
def weight_state(w):
    """Which way MuJoCo clamps a weight to [0, 1]: AT_START (w < 0), AT_END (w > 1) or FREE."""
    state = FREE
    if w < 0.0:
        state = AT_START
    elif w > 1.0:
        state = AT_END
    return state


@ti.func
def segment_weights(d1, d2, r, a, b, c, e, f, state):
    """Closed-form weights (s, t) of a frozen pair state 3 s_state + t_state.

    Both free: s from the cross products, t = (b s + f)/e; one clamped: the other given it (no
    clamp: the state says it is inside); both clamped: 0 or 1 each.
    """
    s_state = state // 3
    t_state = state % 3
    s = weight_value(s_state)
    t = weight_value(t_state)
    if s_state == FREE and t_state == FREE:
        normal = cross3(d1, d2)
        s = dot3(normal, cross3(d2, r)) / dot3(normal, normal)
        t = (b * s + f) / e
    elif t_state == FREE:
        t = (b * s + f) / e
    elif s_state == FREE:
        s = (b * t - c) / a
    return s, t


@ti.func
def segment_weights_adjoint(d1, d2, r, a, b, c, e, f, state, g_s, g_t):
    """Reverse of segment_weights for the same frozen state: the gradients (g_d1, g_d2, g_r (3,)
    each, g_a, g_b, g_c, g_e, g_f) given those of s and t (chain them through
    segment_weight_terms_adjoint). A clamped weight (0 or 1) passes no gradient; both free, s's
    gradient collects t's share (t = (b s + f)/e) before going through the cross products.
    """
    s, t = segment_weights(d1, d2, r, a, b, c, e, f, state)
    s_state = state // 3
    t_state = state % 3
    g_d1 = ti.Vector.zero(float, 3)
    g_d2 = ti.Vector.zero(float, 3)
    g_r = ti.Vector.zero(float, 3)
    g_a = 0.0
    g_b = 0.0
    g_c = 0.0
    g_e = 0.0
    g_f = 0.0
    if t_state == FREE:  # t e = b s + f
        h = g_t / e
        g_b = h * s
        g_f = h
        g_e = -h * t
        g_s += h * b
    if s_state == FREE and t_state == FREE:  # s = (n·w) / (n·n), n = d1 × d2, w = d2 × r
        normal = cross3(d1, d2)
        across = cross3(d2, r)
        area_sqr = dot3(normal, normal)
        g_normal = across * (g_s / area_sqr) - normal * (2.0 * g_s * s / area_sqr)
        g_d1, g_d2 = cross3_adjoint(d1, d2, g_normal)
        g_d2_across, g_r = cross3_adjoint(d2, r, normal * (g_s / area_sqr))
        g_d2 += g_d2_across
    elif s_state == FREE:  # s a = b t - c
        h = g_s / a
        g_b = h * t
        g_c = -h
        g_a = -h * s
    return g_d1, g_d2, g_r, g_a, g_b, g_c, g_e, g_f


@ti.func
def _pair_state(s_state, s, a, b, c, e, f):
    """Pair state once s is chosen (s_state; s its value, used when FREE): t given s; if t leaves
    [0, 1], t is clamped and s recomputed given it, then clamped (MuJoCo's order)."""
    if s_state != FREE:
        s = weight_value(s_state)
    t_state = weight_state((b * s + f) / e)
    if t_state != FREE:
        s_state = weight_state((b * weight_value(t_state) - c) / a)
    return 3 * s_state + t_state


@ti.func
def segment_weight_states(d1, d2, r, a, b, c, e, f):
    """MuJoCo 4's weight pairs of two segments: (n, state0, state1), n = 1 or 2 pair states.

    A segment with |d|² <= SHORT_SQR is its start point. Non-parallel segments: one pair, the
    closest points (s free, clamped; then _pair_state). Parallel segments: two pairs, from P's
    start (s = 0) and from P's end (s = 1), each completed by _pair_state.
    """
    n = 1
    state0 = 3 * AT_START + AT_START  # both segments are points: their starts
    state1 = 0
    if a <= SHORT_SQR:
        if e > SHORT_SQR:
            state0 = 3 * AT_START + weight_state(f / e)
    elif e <= SHORT_SQR:
        state0 = 3 * weight_state(-c / a) + AT_START
    else:
        normal = cross3(d1, d2)
        area_sqr = dot3(normal, normal)
        if area_sqr > a * PARALLEL_SINE_SQR * e:
            s = dot3(normal, cross3(d2, r)) / area_sqr
            state0 = _pair_state(weight_state(s), s, a, b, c, e, f)
        else:
            n = 2
            state0 = _pair_state(AT_START, 0.0, a, b, c, e, f)
            state1 = _pair_state(AT_END, 1.0, a, b, c, e, f)
    return n, state0, state1


def collider(decide, evaluate, max_contacts, doc):
    """The collider of a decide/evaluate pair: decide, then evaluate each found contact's row.

    Rows k >= count stay zero (features too).
    """

    @ti.func
    def collide(pos1, rot1, size1, pos2, rot2, size2, margin):
        count, feature = decide(pos1, rot1, size1, pos2, rot2, size2, margin)
        position = ti.Matrix.zero(float, max_contacts, 3)
        normal = ti.Matrix.zero(float, max_contacts, 3)
        dist = ti.Vector.zero(float, max_contacts)
        for k in range(count):  # a loop, not unrolled: evaluate is inlined once
            p, n, d = evaluate(pos1, rot1, size1, pos2, rot2, size2, feature[k])
            for i in ti.static(range(3)):
                position[k, i] = p[i]
                normal[k, i] = n[i]
            dist[k] = d
        return count, position, normal, dist, feature

    collide.__doc__ = doc
    return collide


@ti.func
def contact_frame_adjoint(normal, tangent, g_frame):
    """Reverse of contact_frame: (∂L/∂normal, ∂L/∂tangent) (3,) each from ∂L/∂frame (3, 3, rows
    n, t1, t2), with the choice of hint (the given tangent, or a world axis) frozen; the
    tangent's gradient is 0 when a world axis replaced it."""
    n, _norm = normalize3(normal)
    hint, given = tangent, 1.0
    if dot3(hint, hint) < 0.25:
        hint, given = ti.Vector([0.0, 0.0, 1.0]), 0.0
        if n[1] < 0.5 and n[1] > -0.5:
            hint = ti.Vector([0.0, 1.0, 0.0])
    m = hint - n * dot3(n, hint)
    t1, _m_norm = normalize3(m)
    g_t2 = ti.Vector([g_frame[2, k] for k in ti.static(range(3))])
    g_n = ti.Vector([g_frame[0, k] for k in ti.static(range(3))]) + cross3(t1, g_t2)  # t2 = n × t1
    g_t1 = ti.Vector([g_frame[1, k] for k in ti.static(range(3))]) + cross3(g_t2, n)
    g_m = normalize3_adjoint(m, g_t1, 0.0)
    g_n -= dot3(n, hint) * g_m + hint * dot3(n, g_m)
    return normalize3_adjoint(normal, g_n, 0.0), given * (g_m - n * dot3(n, g_m))
