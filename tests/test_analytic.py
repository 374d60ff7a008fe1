"""Physics pinned by analytic references, independent of MuJoCo (float64).

Each expected value is derived on paper, from the equations of motion and from the integrator's
own update rule (MuJoCo's semi-implicit Euler with implicit joint damping:
``(M + armature + h·damping) q̈ = τ − bias − damping·q̇``, ``q̇' = q̇ + h·q̈``, ``q' = q + h·q̇'``),
so a wrong sign or term in the solver fails here even where a reference simulator could share
the mistake. Scenes are built once per module (building is the slow part) and reset per use.
"""
import xml.etree.ElementTree as ET

import numpy as np
import pytest

import genesis_lite as gs
from tests.conftest import asset

G = 9.81
_SCENES = {}


def _cached(name, make):
    """The scene ``make()`` builds, once per name and Taichi runtime; callers reset it."""
    key = (name, gs.runtime.epoch)
    if key not in _SCENES:
        _SCENES[key] = make()
    return _SCENES[key]


@pytest.fixture(scope="module")
def urdf_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("urdf")


def _one_joint_urdf(directory, name, joint_type, axis, limits, com, mass, inertia_diag):
    """A base welded to the world, one joint at the world origin, and a link whose centre of mass
    is at ``com`` (in the joint frame) with principal moments ``inertia_diag`` there."""
    ixx, iyy, izz = inertia_diag
    path = directory / f"{name}.urdf"
    path.write_text(f"""<?xml version="1.0"?>
<robot name="{name}">
  <link name="base">
    <inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
  </link>
  <joint name="joint" type="{joint_type}">
    <parent link="base"/><child link="body"/><origin xyz="0 0 0"/><axis xyz="{axis}"/>
    <limit lower="{limits[0]}" upper="{limits[1]}" effort="1e9" velocity="100"/>
  </joint>
  <link name="body">
    <inertial>
      <origin xyz="{com}"/><mass value="{mass}"/>
      <inertia ixx="{ixx}" ixy="0" ixz="0" iyy="{iyy}" iyz="0" izz="{izz}"/>
    </inertial>
  </link>
</robot>
""")
    return str(path)


def _quat_rotate(quat, v):
    """Rotate v (..., 3) by unit quaternions (..., 4) in (w, x, y, z) order."""
    w, u = quat[..., :1], quat[..., 1:]
    return v + 2 * w * np.cross(u, v) + 2 * np.cross(u, np.cross(u, v))


def _urdf_coms(path, robot):
    """(n_links, 3) centre of mass of every link in its own frame, read from the URDF's inertials."""
    coms = {}
    for link in ET.parse(path).getroot().iter("link"):
        origin = link.find("inertial/origin")
        coms[link.get("name")] = [float(x) for x in origin.get("xyz").split()] if origin is not None else [0, 0, 0]
    return np.array([coms[link.name] for link in robot.links])


def _energy(robot, coms):
    """Total energy of a fixed-base robot, J: ½ q̇ᵀ M q̇ (``get_mass_mat``; no armature is set) plus
    Σ m_i g z_i over the links' centres of mass (link pose ⊕ URDF inertial origin)."""
    qd = robot.get_dofs_velocity().numpy()
    kinetic = 0.5 * qd @ robot.get_mass_mat().numpy() @ qd
    com_world = robot.get_links_pos().numpy() + _quat_rotate(robot.get_links_quat().numpy(), coms)
    return kinetic + G * robot.get_links_mass().numpy() @ com_world[:, 2]


# --------------------------------------------------------------------------------------------
# PD servos on a slider: the exact discrete response
# --------------------------------------------------------------------------------------------

SLIDER_MASS, ARMATURE, DAMPING, KP, KV = 2.0, 0.3, 0.5, 50.0, 3.0


def _servo_map(mode, target, h):
    """(A, c) of the affine map x' = A x + c, x = (q, q̇), that one substep of length h is.

    A horizontal slider has no bias force. With D = m + armature + h·(damping + kv) (both velocity
    terms implicit, as Genesis's default integrator) the solve gives q̈ = (α − β q − γ q̇) / D,
    where the position servo τ = kp (q* − q) − kv q̇ gives (α, β, γ) = (kp q*, kp, kv + damping)
    and the velocity servo τ = kv (q̇* − q̇) gives (kv q̇*, 0, kv + damping). Then q̇' = q̇ + h q̈
    and q' = q + h q̇':
        q̇' = −(hβ/D) q + (1 − hγ/D) q̇ + hα/D,   q' = q + h q̇'.
    """
    D = SLIDER_MASS + ARMATURE + h * (DAMPING + KV)
    alpha, beta = (KP * target, KP) if mode == "position" else (KV * target, 0.0)
    gamma = KV + DAMPING
    velocity_row = np.array([-h * beta / D, 1.0 - h * gamma / D])
    A = np.array([[1.0, 0.0], [0.0, 0.0]]) + np.outer([h, 1.0], velocity_row)
    c = np.array([h, 1.0]) * h * alpha / D
    return A, c


def _slider(urdf_dir, substeps):
    def make():
        path = _one_joint_urdf(urdf_dir, "slider", "prismatic", "1 0 0", (-100, 100), "0 0 0", SLIDER_MASS,
                               (0.01, 0.01, 0.01))
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, substeps=substeps))
        robot = scene.add_entity(gs.morphs.URDF(file=path, fixed=True, default_armature=0.0))
        scene.build()
        robot.set_dofs_kp([KP])
        robot.set_dofs_kv([KV])
        robot.set_dofs_damping([DAMPING])
        robot.set_dofs_armature([ARMATURE])
        return scene, robot
    return _cached(("slider", substeps), make)


@pytest.mark.parametrize("substeps", [1, 2])
@pytest.mark.parametrize("mode, target, q0, v0", [("position", 0.4, -0.1, 0.2), ("velocity", 0.5, 0.1, -0.2)],
                         ids=["position", "velocity"])
def test_pd_servo_slider_matches_discrete_closed_form(f64, urdf_dir, substeps, mode, target, q0, v0):
    """A horizontal slider (2 kg, armature 0.3 kg, damping 0.5 N·s/m) under a position servo
    (kp 50 N/m, kv 3 N·s/m, target 0.4 m) or a velocity servo (kv 3, target 0.5 m/s), 300 steps
    of 10 ms, one or two substeps: every step's (q, q̇) equals the affine recurrence derived from
    the integrator (``_servo_map``) to 1e-10. The map contracts (spectral radius < 1), so
    round-off stays ~1e-14 (measured ≤ 9e-15).

    Any sign or gain error moves the trajectory by orders of magnitude more (the references
    iterated with the mutation, over the 300 steps): kv's sign flipped in the position servo
    (γ 3.5 → −2.5: unstable) by 2 m; the damping's sign flipped in force and solve alike
    (γ 3.5 → 2.5, D 2.335 → 2.325) by 0.06 m (position servo) and 0.15 m/s (velocity servo,
    whose steady state kv q̇*/(kv + b) goes from 0.43 to 0.6 m/s); kp and kv swapped by 0.8 m;
    kv left out of D (an explicit servo, MuJoCo's Euler integrator) by 7e-3 m and 5e-3 m/s.
    """
    scene, robot = _slider(urdf_dir, substeps)
    scene.reset()
    robot.set_dofs_position([q0])
    robot.set_dofs_velocity([v0])
    (robot.control_dofs_position if mode == "position" else robot.control_dofs_velocity)([target])
    A, c = _servo_map(mode, target, 0.01 / substeps)
    x = np.array([q0, v0])
    expected, got = [], []
    for _ in range(300):
        scene.step()
        for _ in range(substeps):
            x = A @ x + c
        expected.append(x)
        got.append([robot.get_dofs_position()[0].item(), robot.get_dofs_velocity()[0].item()])
    expected, got = np.array(expected), np.array(got)
    err = np.abs(got - expected).max(axis=0)
    assert err.max() <= 1e-10, (
        f"{mode} servo, substeps={substeps}: max |q − q_ref| = {err[0]:.3g} m, "
        f"max |q̇ − q̇_ref| = {err[1]:.3g} m/s over 300 steps; the discrete closed form "
        f"(kp={KP}, kv={KV}, damping={DAMPING}, armature={ARMATURE}) must hold to 1e-10")
    # not a trivial match: the servo drives the slider far from its initial position or velocity
    column = 0 if mode == "position" else 1
    assert np.abs(expected[:, column] - (q0, v0)[column]).max() > 0.3


# --------------------------------------------------------------------------------------------
# A single pendulum: period, energy, joint limit
# --------------------------------------------------------------------------------------------

PEND_MASS, PEND_LENGTH, PEND_ICOM = 1.0, 0.5, 0.01  # kg, m (pivot to com), kg·m² about the com
PEND_INERTIA = PEND_ICOM + PEND_MASS * PEND_LENGTH ** 2  # about the pivot: 0.26 kg·m²
PEND_DT, LIMIT = 1e-3, 0.5


def _pendulum(urdf_dir, limits_on):
    """A rod pendulum swinging about y, com 0.5 m below the pivot, joint limits ±0.5 rad
    (enforced or not), dt 1 ms."""
    def make():
        path = _one_joint_urdf(urdf_dir, "pendulum", "revolute", "0 1 0", (-LIMIT, LIMIT), f"0 0 {-PEND_LENGTH}",
                               PEND_MASS, (PEND_ICOM, PEND_ICOM, 1e-4))
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=PEND_DT),
                         rigid_options=gs.options.RigidOptions(enable_joint_limit=limits_on))
        robot = scene.add_entity(gs.morphs.URDF(file=path, fixed=True, default_armature=0.0))
        scene.build()
        return scene, robot, _urdf_coms(path, robot)
    return _cached(("pendulum", limits_on), make)


def _run(scene, robot, q0, n_steps, record, every=1):
    """Reset, release from rest at q0 and step n_steps: [record() at the start and after every
    ``every``-th step]."""
    scene.reset()
    robot.set_dofs_position(q0)
    samples = [record()]
    for n in range(1, n_steps + 1):
        scene.step()
        if n % every == 0:
            samples.append(record())
    return samples


def test_small_angle_pendulum_period(f64, urdf_dir):
    """Released from rest at 0.01 rad, the pendulum's period, measured between zero crossings
    (linearly interpolated) over 6 periods, is T₀ = 2π √(I_pivot / (m g l)) = 1.4465 s.

    Bound on |T/T₀ − 1|: the finite amplitude lengthens the period by θ₀²/16 = 6.3e-6; the
    integrator is symplectic Euler here (constant M), whose linearised step turns by
    φ = 2 asin(hω/2) (cos φ = 1 − (hω)²/2), shortening it by (hω)²/24 = 7.9e-7 (ω = 4.34 rad/s);
    linear interpolation at a zero crossing, where the sine is straight, errs by O((hω)³).
    Expected ≈ +5.5e-6; tolerance 2e-5. A 1 % error in the inertia, the mass or g moves T by 5e-3.
    """
    scene, robot, _ = _pendulum(urdf_dir, limits_on=True)  # the limits stay inactive at 0.01 rad
    theta = np.array(_run(scene, robot, [0.01], 9500, lambda: robot.get_dofs_position()[0].item()))
    t = PEND_DT * np.arange(len(theta))
    k = np.nonzero(np.sign(theta[:-1]) != np.sign(theta[1:]))[0]
    crossings = t[k] - theta[k] * PEND_DT / (theta[k + 1] - theta[k])
    period = 2 * (crossings[-1] - crossings[0]) / (len(crossings) - 1)
    expected = 2 * np.pi * np.sqrt(PEND_INERTIA / (PEND_MASS * G * PEND_LENGTH))
    assert len(crossings) >= 12 and np.abs(theta).max() > 0.0099
    assert abs(period / expected - 1) <= 2e-5, (
        f"small-angle period {period:.7f} s over {len(crossings) - 1} half-periods, analytic "
        f"2π√(I/(mgl)) = {expected:.7f} s: relative error {period / expected - 1:.3g} (tolerance 2e-5)")


def test_single_pendulum_energy_bounded(f64, urdf_dir):
    """Released from rest at 2 rad, no damping, 10 s at dt 1 ms. With a constant mass matrix the
    integrator is symplectic Euler (q̇' = q̇ + h τ_g(q)/I, q' = q + h q̇'), which conserves the
    modified energy Ẽ = E + (h/2) q̇ τ_g(q), τ_g = −m g l sin q, up to O(h²): so E itself
    oscillates by O(h) (≤ (h/2) max|q̇ τ_g| ≈ 1.3e-2 J) without any secular drift.

    Checks, sampling every 10 ms: |Ẽ − Ẽ₀| ≤ 1e-4 J (measured 1.5e-5), the largest |E − E₀|
    over the last second is within 5 % of that over the first (measured: 2e-4 apart),
    and E does move by O(h) (> 5e-3 J), so the read-out is not trivially constant. Energy comes
    from ``get_mass_mat`` and the links' com heights.
    """
    scene, robot, coms = _pendulum(urdf_dir, limits_on=False)

    def sample():
        q, qd = robot.get_dofs_position()[0].item(), robot.get_dofs_velocity()[0].item()
        torque = -PEND_MASS * G * PEND_LENGTH * np.sin(q)
        return _energy(robot, coms), 0.5 * PEND_DT * qd * torque

    energy, correction = np.array(_run(scene, robot, [2.0], 10000, sample, every=10)).T
    deviation = energy - energy[0]
    modified = np.abs(deviation + correction - correction[0]).max()
    first, last = np.abs(deviation[:101]).max(), np.abs(deviation[-100:]).max()
    assert modified <= 1e-4, f"modified energy E + (h/2) q̇ τ_g drifts by {modified:.3g} J over 10 s (bound 1e-4 J)"
    assert last <= 1.05 * first, (
        f"energy error grows: max |E − E0| = {first:.4g} J in the first second, {last:.4g} J in the last")
    assert first > 5e-3


def test_joint_limit_holds(f64, urdf_dir):
    """A constant 4 N·m torque pushes the pendulum toward its upper limit (0.5 rad); gravity
    resists with m g l sin q ≤ 4.9 N·m, too weak to stop it before 2.45 rad.

    The limit is a soft constraint row (MuJoCo's model, as documented): at rest (q̈ = q̇ = 0) past
    the bound by p its force is f = aref / R with aref = K·d·p, R = (1 − d)/d · A, where
    K = 1/(dmax² tc²) (time constant tc = 0.01 s, damping ratio 1), A = 1/I_pivot (M⁻¹ at the
    initial pose) and the impedance d(p) rises from d0 = 0.9 along 0.9 + 0.05·2(p/w)² (w =
    0.001 rad, p < w/2). So the rest angle q = 0.5 + p solves K d² I p / (1 − d) = 4 − m g l
    sin q: p = 7.1e-5 rad. It holds for any dt; the transient (critically damped, 0.01 s) has
    died out well below 1e-9 rad over the last 0.1 s of the 1 s run, where the angle must match
    to 1e-9 rad, and it must never overshoot the bound by more than 0.05 rad. Without limits
    the pendulum ends far past the bound (q > 1.5 rad after 1 s).
    """
    torque, tc, (d0, dmax, width, mid) = 4.0, 0.01, (0.9, 0.95, 0.001, 0.5)

    def excess(p):  # the row's force minus the net torque it must hold
        x = min(p / width, 1.0)
        d = d0 + (dmax - d0) * (x * x / mid if x <= mid else 1.0 - (1.0 - x) ** 2 / (1.0 - mid))
        stiffness = 1.0 / (dmax * tc) ** 2
        held = torque - PEND_MASS * G * PEND_LENGTH * np.sin(LIMIT + p)
        return stiffness * d * d * PEND_INERTIA * p / (1.0 - d) - held

    low, high = 0.0, 0.01
    for _ in range(200):  # bisection: excess rises with p
        low, high = ((low + high) / 2, high) if excess((low + high) / 2) < 0 else (low, (low + high) / 2)
    p = (low + high) / 2
    rest = LIMIT + p
    runs = {}
    for limits_on in (True, False):
        scene, robot, _ = _pendulum(urdf_dir, limits_on)
        scene.reset()
        robot.control_dofs_force([torque])
        angles = []
        for _ in range(1000):
            scene.step()
            angles.append(robot.get_dofs_position()[0].item())
        runs[limits_on] = np.array(angles)
    held = runs[True][-100:]
    assert np.abs(held - rest).max() <= 1e-9, (
        f"with limits on, the pendulum rests at {held[-1]:.10f} rad; expected the limit row's "
        f"{rest:.10f} rad (bound {LIMIT} rad + penetration {p:.4g} rad, where its force holds the torque)")
    assert runs[True].max() <= LIMIT + 0.05, f"overshoots the limit {LIMIT} rad to {runs[True].max():.4f} rad"
    free = runs[False][-1]
    assert free > 1.5, f"without limits the pendulum should pass {LIMIT} rad by far; it ends at {free:.3f} rad"


# --------------------------------------------------------------------------------------------
# A double pendulum's energy; a free body's torque-free precession
# --------------------------------------------------------------------------------------------


def _double_pendulum(substeps):
    def make():
        path = asset("pendulum2.urdf")
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=1e-3, substeps=substeps),
                         rigid_options=gs.options.RigidOptions(enable_joint_limit=False))
        robot = scene.add_entity(gs.morphs.URDF(file=path, fixed=True, default_armature=0.0))
        scene.build()
        robot.set_dofs_damping([0.0, 0.0])
        return scene, robot, _urdf_coms(path, robot)
    return _cached(("double_pendulum", substeps), make)


def test_double_pendulum_energy_error_is_first_order(f64):
    """``pendulum2.urdf`` (off-diagonal inertias, offset coms), no damping, released from rest at
    (2, −1) rad, 2 s at h = 1 ms and at h = 0.5 ms (two substeps), energy every 10 ms.

    Here M depends on q and the bias forces are explicit, so the step is not symplectic: the
    energy error does grow secularly, ~0.1 J/s at h = 1 ms (MuJoCo's Euler, run on the same
    URDF, drifts identically), and a "bounded drift" check would be false. What must hold is that
    the continuous dynamics conserve energy and the error is the first-order integrator's:
    E_h(t) − E₀ = h e(t) + O(h²). So: |ΔE_h − 2 ΔE_{h/2}| ≤ 2 % of max|ΔE_h| at every sample
    (measured 0.7 %), and max|ΔE_h| ≤ 0.25 J (measured 0.18 J; E swings between kinetic and
    potential by ~10 J). A force doing spurious work (a Coriolis sign, a stray damping or gravity
    term) leaves an error that does not halve with h.
    """
    deviations = []
    for substeps in (1, 2):
        scene, robot, coms = _double_pendulum(substeps)
        energy = np.array(_run(scene, robot, [2.0, -1.0], 2000, lambda: _energy(robot, coms), every=10))
        deviations.append(energy - energy[0])
    coarse, fine = deviations
    largest = np.abs(coarse).max()
    residual = np.abs(coarse - 2 * fine).max()
    assert largest <= 0.25, f"energy error {largest:.4g} J over 2 s at h = 1 ms (bound 0.25 J)"
    assert residual <= 0.02 * largest, (
        f"energy error not first order in h: max |ΔE(h) − 2 ΔE(h/2)| = {residual:.3g} J against "
        f"max |ΔE(h)| = {largest:.3g} J")


def test_free_body_torque_free_precession(f64):
    """A free 0.1 × 0.2 × 0.4 m box (distinct principal moments I = m/12 (b² + c², a² + c², a² + b²)),
    no gravity, spun at ω_body = (0.4, 2, 0.3) rad/s (near the unstable intermediate axis),
    2 s at dt 1 ms. A free joint's angular dofs are the body-frame ω, so L = R I ω_body.

    - World-frame angular momentum: ‖L(t) − L(0)‖ ≤ 2e-3 ‖L(0)‖. The step updates ω explicitly
      (L_body' = L + h L × ω) and turns R by the new ω; the two cancel to first order, leaving
      O(h² |ω|² |L|) per step, O(T h max|ω|²) ≈ 1e-2 over the run; measured 9.2e-4.
    - Kinetic energy ½ ωᵀ I ω: explicit Euler on Euler's equations raises it by exactly
      ½ h² (L × ω)ᵀ I⁻¹ (L × ω) per step (the first-order term ω·(L × ω) vanishes); the total
      change must equal that sum to 1e-9 relative (measured 2e-12) and stay ≤ 3e-3 of E₀
      (measured 1.4e-3).
    - Precession happens: ω in the world turns by more than 0.3 rad from its start (measured
      0.63 rad) while L stays put, so the checks cannot pass on a body that does not tumble.
    - The com (the box's origin) drifts at its initial world velocity, to round-off (1e-12 m/s).
    """
    def make():
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=1e-3, gravity=(0, 0, 0)))
        box = scene.add_entity(gs.morphs.Box(size=(0.1, 0.2, 0.4)))
        scene.build()
        return scene, box
    scene, box = _cached("box", make)
    scene.reset()
    h, (a, b, c) = 1e-3, (0.1, 0.2, 0.4)
    inertia = box.get_links_mass()[0].item() / 12 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
    box.set_dofs_velocity([0.1, -0.2, 0.05, 0.4, 2.0, 0.3])
    velocity, quat = [], []
    for n in range(2001):
        if n:
            scene.step()
        velocity.append(box.get_dofs_velocity().numpy())
        quat.append(box.get_quat().numpy())
    velocity, quat = np.array(velocity), np.array(quat)
    omega = velocity[:, 3:]
    momentum_body = inertia * omega
    momentum = _quat_rotate(quat, momentum_body)
    drift = np.linalg.norm(momentum - momentum[0], axis=1).max() / np.linalg.norm(momentum[0])
    energy = 0.5 * (omega * momentum_body).sum(axis=1)
    gain = 0.5 * h ** 2 * (np.cross(momentum_body, omega)[:-1] ** 2 / inertia).sum()
    omega_world = _quat_rotate(quat, omega)
    directions = omega_world / np.linalg.norm(omega_world, axis=1, keepdims=True)
    turned = np.arccos(np.clip(directions @ directions[0], -1, 1)).max()
    assert drift <= 2e-3, f"world angular momentum R I ω moves by {drift:.3g} of |L| over 2 s (bound 2e-3)"
    assert abs((energy[-1] - energy[0]) / gain - 1) <= 1e-9, (
        f"kinetic energy changed by {energy[-1] - energy[0]:.6g} J; explicit Euler predicts "
        f"Σ ½ h² |L × ω|²_I⁻¹ = {gain:.6g} J")
    assert np.abs(energy - energy[0]).max() <= 3e-3 * energy[0]
    assert turned > 0.3, f"ω turned only {turned:.3g} rad in the world: no precession to test"
    assert np.abs(velocity[:, :3] - [0.1, -0.2, 0.05]).max() <= 1e-12, "the free body's com velocity changed"
