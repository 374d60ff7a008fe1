"""Quaternion and spatial-algebra helpers (Taichi functions).

Conventions: quaternions are (w, x, y, z); world-frame spatial vectors about a reference point
o (kinematics.reference: its kinematic tree's root link origin): a *motion* vector (w, v) is an
angular velocity w and the linear velocity v of the body point at o; a *force* (n, f) is a torque
n about o and a force f. A link's spatial inertia about o is (m, h, I): mass m (kg), first moment
h = m·(c − o) (kg·m, c the world com) and rotational inertia I about o (kg·m², 3x3).
"""
import taichi as ti

# Products are written out as single expressions: Taichi's ``@`` accumulates into a local.


@ti.func
def mat_vec(m, v):
    """3x3 matrix times 3-vector."""
    return ti.Vector([m[i, 0] * v[0] + m[i, 1] * v[1] + m[i, 2] * v[2] for i in ti.static(range(3))])


@ti.func
def mat_mul(a, b):
    """3x3 matrix product."""
    return ti.Matrix([[a[i, 0] * b[0, j] + a[i, 1] * b[1, j] + a[i, 2] * b[2, j] for j in ti.static(range(3))]
                      for i in ti.static(range(3))])


@ti.func
def dot3(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@ti.func
def quat_mul(a, b):
    return ti.Vector([a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
                      a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
                      a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
                      a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0]])


@ti.func
def quat_to_mat(q):
    """Rotation matrix of a unit quaternion, rounded as MuJoCo 4.0's mju_quat2Mat rounds it (its
    diagonal from the squares, paired so: checked bit for bit on random quaternions), so that a
    body placed exactly on a plane is placed there as in MuJoCo (with 1 − 2(y² + z²), a lying
    capsule's end came 2e-17 m below the plane and made a contact MuJoCo does not)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    ww, xx, yy, zz = w * w, x * x, y * y, z * z
    return ti.Matrix([[(ww - yy) + (xx - zz), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                      [2 * (x * y + w * z), (ww + yy) - (xx + zz), 2 * (y * z - w * x)],
                      [2 * (x * z - w * y), 2 * (y * z + w * x), (ww - yy) + (zz - xx)]])


@ti.func
def quat_normalized(q):
    """q / |q|, or q itself where |q| is within 1e-15 of 1, as MuJoCo's mju_normalize4: a quaternion
    a step left unit keeps its bits, so frames equal MuJoCo's to the last bit (one ulp moved a
    nearly flat cylinder's plane contact by 4e-11 m, 1/tilt times). Its adjoint, normalized_adjoint,
    is that of q / |q| throughout: the skip moves the value by under 1e-15 and no derivative."""
    norm = ti.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    out = q
    if ti.abs(norm - 1.0) > 1e-15:
        out = q / norm
    return out


@ti.func
def axis_angle_quat(axis, angle):
    """Rotation by ``angle`` rad about the unit ``axis``."""
    half = 0.5 * angle
    return ti.Vector([ti.cos(half), ti.sin(half) * axis[0], ti.sin(half) * axis[1], ti.sin(half) * axis[2]])


@ti.func
def _euler_factors(angles):
    """The quaternions of the turns by angles (a, b, c) rad about x, y and z, in turn."""
    c, s = ti.cos(0.5 * angles), ti.sin(0.5 * angles)
    return (ti.Vector([c[0], s[0], 0.0, 0.0]), ti.Vector([c[1], 0.0, s[1], 0.0]),
            ti.Vector([c[2], 0.0, 0.0, s[2]]))


@ti.func
def euler_xyz_quat(angles):
    """The unit quaternion of intrinsic X-Y-Z Euler angles (a, b, c) rad: R = Rx(a) Ry(b) Rz(c)."""
    qx, qy, qz = _euler_factors(angles)
    return quat_mul(quat_mul(qx, qy), qz)


@ti.func
def _turn_terms(q):
    """(sign, c, v, l) of the raw quaternion q: q / |q| = sign (c, v) with c ≥ 0 (the turn of at
    most π), l = |v|."""
    n = quat_normalized(q)
    sign = 1.0
    if n[0] < 0.0:
        sign = -1.0
    v = sign * ti.Vector([n[1], n[2], n[3]])
    return sign, sign * n[0], v, v.norm()


@ti.func
def quat_turn(q):
    """(θ rad in [0, π], unit axis (3,)) of the rotation by the raw quaternion q, as MuJoCo's
    mju_quat2Vel of q / |q|: with (c, v) = ±q / |q|, c ≥ 0, θ = 2 atan2(|v|, c) and the axis
    v / |v| ((1, 0, 0) at no turn). θ · axis is the rotation vector (quat_rotation_vector)."""
    _sign, c, v, l = _turn_terms(q)
    axis = ti.Vector([1.0, 0.0, 0.0])
    if l >= 1e-15:  # (MuJoCo's mjMINVAL)
        axis = v / l
    return 2.0 * ti.atan2(l, c), axis


@ti.func
def quat_rotation_vector(q):
    """The rotation vector r (3,) rad of the raw quaternion q: θ · axis, θ ≤ π, as quat_turn's, but
    written r = v · f with f = 2 atan2(l, c) / l (→ 2 / c at no turn), smooth through no turn."""
    _sign, c, v, l = _turn_terms(q)
    f = 2.0 / c
    if l > 1e-15:
        f = 2.0 * ti.atan2(l, c) / l
    return v * f


@ti.func
def quat_integrate(q, omega, h):
    """q ⊗ exp(h·omega/2): rotate by the body-frame angular velocity omega (rad/s) for h s.

    sin(θ/2)/|ω| is written with a tiny offset under the square root so that its derivative
    stays finite at ω = 0 (Taichi evaluates both sides of a select, and |ω|' is NaN at 0)."""
    speed = ti.sqrt(dot3(omega, omega) + 1e-36)
    half = 0.5 * h * speed
    s = ti.sin(half) / speed
    rot = ti.Vector([ti.cos(half), s * omega[0], s * omega[1], s * omega[2]])
    return quat_normalized(quat_mul(quat_normalized(q), rot))


@ti.func
def cross_motion(aw, av, bw, bv):
    """Spatial motion cross product (aw, av) ×m (bw, bv): rate of change of b moving with a."""
    return aw.cross(bw), aw.cross(bv) + av.cross(bw)


@ti.func
def cross_force(aw, av, fn, ff):
    """Spatial force cross product (aw, av) ×f (fn, ff)."""
    return aw.cross(fn) + av.cross(ff), aw.cross(ff)


@ti.func
def inertia_mul(m, h, inertia, w, v):
    """Spatial inertia (m, h, I) times motion (w, v) → momentum force (n, f)."""
    return mat_vec(inertia, w) + h.cross(v), m * v - h.cross(w)


# -- adjoints (reverse mode, hand-written): each takes the forward inputs and the gradient of
# -- the output, and returns the gradients of the inputs ---------------------------------------
@ti.func
def quat_conj(q):
    return ti.Vector([q[0], -q[1], -q[2], -q[3]])


@ti.func
def quat_mul_adjoint(a, b, g):
    """Gradients of a and b from g = ∂L/∂(a ⊗ b): right and left products transpose to conjugates."""
    return quat_mul(g, quat_conj(b)), quat_mul(quat_conj(a), g)


@ti.func
def normalized_adjoint(q, g):
    """Gradient of q from g = ∂L/∂(q / |q|)."""
    norm = ti.sqrt(q.dot(q))
    unit = q / norm
    return (g - unit * unit.dot(g)) / norm


@ti.func
def quat_turn_adjoint(q, g_angle, g_axis):
    """Gradient of the raw quaternion q from the gradients of quat_turn's angle and axis: with
    l = |v|, ∂θ/∂l = 2c / (l² + c²), ∂θ/∂c = −2l / (l² + c²), ∂(v / l)/∂v = (I − â âᵀ) / l, and
    (c, v) = sign · q / |q|."""
    sign, c, v, l = _turn_terms(q)
    square = l * l + c * c
    g_v = ti.Vector.zero(float, 3)
    if l >= 1e-15:  # (no turn: the axis is a constant, and θ's slope along v, 2c v / l, is 0 · g)
        unit = v / l
        g_v = 2.0 * c / square * g_angle * unit + (g_axis - unit * unit.dot(g_axis)) / l
    return sign * normalized_adjoint(q, ti.Vector([-2.0 * l / square * g_angle, g_v[0], g_v[1], g_v[2]]))


@ti.func
def quat_rotation_vector_adjoint(q, g):
    """Gradient of the raw quaternion q from g = ∂L/∂quat_rotation_vector(q): with r = v f(l, c),
    ∂r/∂v = f I + (f_l / l) v vᵀ, ∂r/∂c = v f_c, f_l / l = (2c / (l² + c²) − f) / l² (bounded by
    4 / (3c³); its round-off, times v vᵀ, stays that of g) and f_c = −2 / (l² + c²)."""
    sign, c, v, l = _turn_terms(q)
    square = l * l + c * c
    f, f_l = 2.0 / c, 0.0
    if l > 1e-15:
        f = 2.0 * ti.atan2(l, c) / l
        f_l = (2.0 * c / square - f) / (l * l)
    along = v.dot(g)
    g_v = f * g + f_l * along * v
    return sign * normalized_adjoint(q, ti.Vector([-2.0 / square * along, g_v[0], g_v[1], g_v[2]]))


@ti.func
def euler_xyz_quat_adjoint(angles, g):
    """Gradient of the angles (3,) from g = ∂L/∂euler_xyz_quat(angles) (each factor's derivative is
    half its turn's quarter turn ahead: ∂(cos, sin)(θ/2)/∂θ = ½ (−sin, cos))."""
    qx, qy, qz = _euler_factors(angles)
    g_xy, g_z = quat_mul_adjoint(quat_mul(qx, qy), qz, g)
    g_x, g_y = quat_mul_adjoint(qx, qy, g_xy)
    return 0.5 * ti.Vector([g_x[1] * qx[0] - g_x[0] * qx[1], g_y[2] * qy[0] - g_y[0] * qy[2],
                            g_z[3] * qz[0] - g_z[0] * qz[3]])


@ti.func
def quat_integrate_adjoint(q, omega, h, g):
    """Gradients of q and omega from g = ∂L/∂quat_integrate(q, omega, h)."""
    speed = ti.sqrt(dot3(omega, omega) + 1e-36)
    half = 0.5 * h * speed
    s = ti.sin(half) / speed
    rot = ti.Vector([ti.cos(half), s * omega[0], s * omega[1], s * omega[2]])
    unit_q = quat_normalized(q)
    product = quat_mul(unit_q, rot)
    g_unit_q, g_rot = quat_mul_adjoint(unit_q, rot, normalized_adjoint(product, g))
    g_axis = ti.Vector([g_rot[1], g_rot[2], g_rot[3]])
    g_s = dot3(g_axis, omega)
    g_speed = -g_rot[0] * ti.sin(half) * 0.5 * h + g_s * (ti.cos(half) * 0.5 * h * speed - ti.sin(half)) / speed ** 2
    return normalized_adjoint(q, g_unit_q), s * g_axis + g_speed * omega / speed


@ti.func
def inertia_mul_adjoint(m, h, inertia, w, v, gn, gf):
    """Gradients (m, h, I, w, v) from (gn, gf) = ∂L/∂inertia_mul(m, h, I, w, v)."""
    g_m = dot3(gf, v)
    g_h = v.cross(gn) - w.cross(gf)
    g_inertia = gn.outer_product(w)
    g_w = mat_vec(inertia.transpose(), gn) - gf.cross(h)
    g_v = gn.cross(h) + m * gf
    return g_m, g_h, g_inertia, g_w, g_v
