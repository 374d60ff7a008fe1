"""Torsional and rolling friction (MuJoCo's contact condim 4 and 6) against closed-form mechanics
and MuJoCo 4: a sphere spinning on a plane stops at the deceleration μ_t·N / I, a sphere rolling
on it slows at 5 μ_r g / (7 r), and every analytic case also runs in MuJoCo inside the test, to
show we are as close to the closed form as it is (and step for step with it). Then trajectories
of bodies dropped with spin (condim 6, by RigidOptions) and an MJCF file whose geoms state their
own condim and partial friction, against MuJoCo's; and the named errors of bad input.

MuJoCo's defaults on both sides (``enable_mujoco_compatibility``), dt 2 ms, float64.
"""
import mujoco
import numpy as np
import pytest
import torch

import genesis_lite as gs
from tests.conftest import warns
from tests.contact_scenes import Body, ContactScene, build_mujoco, build_ours

G, R, DT = 9.81, 0.1, 0.002  # gravity m/s², the sphere's radius m, time step s


def _lockstep(ours_spec, steps, qvel0, after_build=None, mujoco_spec=None):
    """(ours, MuJoCo's) qvel trajectories (steps, 6) of the one sphere of ``ours_spec`` (MuJoCo's
    model from ``mujoco_spec`` when given), both started at rest on the plane with velocity
    ``qvel0`` (world linear, body angular); ``after_build(entity)`` runs before the first step."""
    scene, (ball,) = build_ours(ours_spec)
    if after_build is not None:
        after_build(ball)
    m = build_mujoco(mujoco_spec or ours_spec, scene._rigid_solver.model)
    d = mujoco.MjData(m)
    ball.set_dofs_velocity(torch.tensor(qvel0, dtype=gs.tc_float))
    d.qvel[:] = qvel0
    ours, theirs = [], []
    for _ in range(steps):
        scene.step()
        mujoco.mj_step(m, d)
        ours.append(ball.get_dofs_velocity().numpy().copy())
        theirs.append(d.qvel.copy())
    return np.array(ours), np.array(theirs)


def _sphere(condim, cone, impratio, friction):
    """A sphere of radius R resting on the plane (its centre at height R), every geom's friction
    ``friction`` (sliding, torsional m, rolling m) and condim ``condim``."""
    return ContactScene([Body("sphere", (R,), pos=(0.0, 0.0, R))], condim=condim, cone=cone, impratio=impratio,
                        friction=friction)


def _slope(t, y):
    return np.polyfit(t, y, 1)[0]


# (cone, impratio, the largest |fitted/analytic − 1| allowed)
SPIN_CASES = [("elliptic", 1.0, 0.01), ("pyramidal", 1.0, 0.30), ("pyramidal", 100.0, 0.01)]


@pytest.mark.parametrize("cone, impratio, tolerance", SPIN_CASES,
                         ids=["elliptic", "pyramidal", "pyramidal-impratio100"])
def test_spinning_sphere_stops_at_torsional_deceleration(f64, cone, impratio, tolerance):
    """A sphere (r 0.1 m) resting on the plane, spinning about the vertical at ω0 = 6 rad/s, with
    torsional friction μ_t = 0.01 m (condim 4): the contact's torque μ_t·N = μ_t·m·g decelerates
    the spin at α = μ_t m g / I = 5 μ_t g / (2 r²) = 24.525 rad/s² while it slips, so it stops at
    ω0/α ≈ 0.25 s. The slope of ω_z(t) fitted over the slipping phase (t > 20 ms, past the
    landing's settling; ω_z > 0.2 ω0, before the soft contact's creep) against α:

    - elliptic, impratio 1 (MuJoCo's default; given, not Genesis's elliptic 100): −24.467
      rad/s², 0.24 % short (ours and MuJoCo alike, to 1e-14): within 1 %;
    - pyramidal, impratio 1: −18.017 rad/s², 0.735 α, in ours and MuJoCo alike: the pyramid's
      regulariser ½ R Σ f_edge² spreads the normal force over every edge, the sliding edge pairs
      (no net tangential force: no torque) too, so only a share of N backs the torsional edge.
      Within 30 %, and with impratio 100 (edges' R a hundred times smaller) the law comes back:
      −24.536 rad/s², 0.04 % off, within 1 %.

    ω_z(t) follows MuJoCo's to ≤ 1e-8 (measured ≤ 1e-13) over 0.7 s; afterwards the spin has
    stopped (|ω_z| < 1 % of ω0 at 0.7 s: measured 1.5e-5 rad/s elliptic, 0.008 pyramidal, 1e-19
    with impratio 100; past the stop it creeps down exponentially, the friction being soft, and
    does not turn back). Without torsional friction (condim 3) the same sphere spins on at ω0 (to
    1e-12; measured exactly): the condim 4 rows are what acts."""
    mu_t, omega0, steps = 0.01, 6.0, 350
    alpha = 5 * mu_t * G / (2 * R * R)
    qvel0 = [0.0, 0.0, 0.0, 0.0, 0.0, omega0]
    t = DT * np.arange(1, steps + 1)
    ours, theirs = _lockstep(_sphere(4, cone, impratio, (1.0, mu_t, 0.0001)), steps, qvel0)
    for engine, qvel in (("ours", ours), ("MuJoCo", theirs)):
        omega = qvel[:, 5]
        slipping = (t > 0.02) & (omega > 0.2 * omega0)
        assert slipping.sum() > 40, (engine, omega[[9, 24, 49]])
        fitted = _slope(t[slipping], omega[slipping])
        assert abs(-fitted / alpha - 1) <= tolerance, (engine, fitted, -alpha)
        assert abs(omega[-1]) < 0.01 * omega0, (engine, omega[-1])  # stopped
        assert omega.min() > -1e-9, engine  # (friction does not turn it back)
    difference = np.abs(ours - theirs).max()
    assert difference <= 1e-8, difference

    ours, theirs = _lockstep(_sphere(3, cone, impratio, (1.0, mu_t, 0.0001)), 100, qvel0)
    for engine, qvel in (("ours", ours), ("MuJoCo", theirs)):
        assert np.abs(qvel[:, 5] - omega0).max() < 1e-12, engine


@pytest.mark.parametrize("cone, tolerance", [("elliptic", 0.01), ("pyramidal", 0.05)])
def test_rolling_sphere_slows_at_rolling_deceleration(f64, cone, tolerance):
    """A sphere (r 0.1 m) rolling without slipping on the plane at v0 = 1 m/s (ω_y = v0/r), with
    rolling friction μ_r = 0.005 m (condim 6, impratio 1): the torque μ_r·N against the rolling
    with the friction force F at the contact, m a = −F and I a/r = F r − μ_r m g, slow it at a =
    μ_r g / (r (1 + I/(m r²))) = 5 μ_r g / (7 r) = 0.35036 m/s². μ_r is set after build on the
    sphere only (entity.set_friction_rolling; the plane keeps MuJoCo's 0.0001): the contact takes
    the larger, as MuJoCo's model with 0.005 on both geoms. The slope of v_x(t) fitted over 50
    ms-0.5 s (past the landing's settling) against a:

    - elliptic: −0.35026 m/s², 0.03 % short (ours and MuJoCo alike): within 1 %;
    - pyramidal: −0.34074 m/s², 2.7 % short (ours and MuJoCo alike; the pyramid's edges mix the
      rolling rows with the normal and sliding ones, as for the spin above): within 5 %.

    It rolls (|v_x − r ω_y| < 2 cm/s, 2 % of v0; measured 1.6 and 8.4 mm/s), following MuJoCo to
    ≤ 1e-8 (measured ≤ 6e-15). At condim 4 (torsional rows, no rolling ones) the same sphere rolls
    on at constant speed: fitted slope < 0.1 % of a (measured 1e-5 m/s², the landing's settling)."""
    mu_r, v0, steps = 0.005, 1.0, 250
    a = 5 * mu_r * G / (7 * R)
    qvel0 = [v0, 0.0, 0.0, 0.0, v0 / R, 0.0]
    t = DT * np.arange(1, steps + 1)
    fitting = t > 0.05
    ours, theirs = _lockstep(_sphere(6, cone, 1.0, (1.0, 0.01, 0.0001)), steps, qvel0,
                             after_build=lambda ball: ball.set_friction_rolling(mu_r),
                             mujoco_spec=_sphere(6, cone, 1.0, (1.0, 0.01, mu_r)))
    for engine, qvel in (("ours", ours), ("MuJoCo", theirs)):
        fitted = _slope(t[fitting], qvel[fitting, 0])
        assert abs(-fitted / a - 1) <= tolerance, (engine, fitted, -a)
        slip = np.abs(qvel[:, 0] - R * qvel[:, 4]).max()
        assert slip < 0.02 * v0, (engine, slip)  # rolling, not sliding
    difference = np.abs(ours - theirs).max()
    assert difference <= 1e-8, difference

    ours, theirs = _lockstep(_sphere(4, cone, 1.0, (1.0, 0.01, mu_r)), steps, qvel0)
    for engine, qvel in (("ours", ours), ("MuJoCo", theirs)):
        fitted = _slope(t[fitting], qvel[fitting, 0])
        assert abs(fitted) < 1e-3 * a, (engine, fitted)
        assert qvel[-1, 0] > 0.999 * v0, (engine, qvel[-1, 0])


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_dropped_with_spin_and_condim_6_follows_mujoco(f64, cone):
    """A sphere and a tilted box dropped (0.1 m and 0.05 m above the plane) with sideways velocity
    and spin, every geom condim 6 (RigidOptions(enable_torsional_friction, enable_rolling_friction))
    and friction (0.8, 0.02 m, 0.01 m), MuJoCo's defaults otherwise (impratio 1): landing,
    bouncing, tumbling and rolling for 0.5 s at dt 2 ms, no re-sync, qpos and qvel within 1e-6 of
    MuJoCo's (measured ≤ 6e-14). MuJoCo's contacts are condim 6, and its condim-3 model of the
    same scene ends > 1e-3 away (measured: 3.3 and 4.4 rad/s in qvel), so the tolerance sees
    the rows."""
    bodies = [Body("sphere", (R,), pos=(0.0, 0.0, 0.2)),
              Body("box", (0.2, 0.3, 0.1), pos=(0.8, 0.0, 0.25), quat=(0.9, 0.3, 0.2, 0.1))]
    spec = ContactScene(bodies, condim=6, friction=(0.8, 0.02, 0.01), cone=cone)
    qvel0 = np.array([1.0, 0.5, 0.0, 3.0, -2.0, 5.0, -0.5, 1.0, 0.0, -2.0, 4.0, 6.0])
    scene, entities = build_ours(spec)
    models = {condim: build_mujoco(ContactScene(bodies, condim=condim, friction=(0.8, 0.02, 0.01), cone=cone),
                                   scene._rigid_solver.model) for condim in (6, 3)}
    datas = {condim: mujoco.MjData(m) for condim, m in models.items()}
    for b, entity in enumerate(entities):
        entity.set_dofs_velocity(torch.tensor(qvel0[6 * b: 6 * b + 6], dtype=gs.tc_float))
    for d in datas.values():
        d.qvel[:] = qvel0
    worst, dims, touching = 0.0, set(), 0
    for _ in range(250):
        scene.step()
        for condim, m in models.items():
            mujoco.mj_step(m, datas[condim])
        d = datas[6]
        qpos = np.concatenate([e.get_qpos().numpy() for e in entities])
        qvel = np.concatenate([e.get_dofs_velocity().numpy() for e in entities])
        worst = max(worst, np.abs(qpos - d.qpos).max(), np.abs(qvel - d.qvel).max())
        dims |= {int(c.dim) for c in d.contact[: d.ncon]}
        touching += d.ncon > 0
    assert worst <= 1e-6, worst
    assert dims == {6} and touching > 100  # (condim 6 contacts, for most of the run)
    assert np.abs(datas[3].qvel - datas[6].qvel).max() > 1e-3


# A plane and free bodies whose geoms state their own condim and friction (a partial friction ends
# in MuJoCo's defaults 0.005 m and 0.0001 m); the floor's torsional and rolling friction are below
# theirs, so each pair takes the body's (the larger); the puck's priority makes its condim 1 win.
MJCF = """<mujoco><worldbody>
<geom name="floor" type="plane" size="0 0 1" friction="0.6 0.001 0.00001"/>
<body name="spinner" pos="0 0 0.1"><freejoint/><geom type="sphere" size="0.1" condim="4" friction="0.7 0.02"/></body>
<body name="roller" pos="1 0 0.1"><freejoint/><geom type="sphere" size="0.1" condim="6" friction="0.9 0.01"/></body>
<body name="log" pos="0 1 0.06"><freejoint/>
  <geom type="capsule" size="0.05 0.1" euler="90 0 0" condim="6" friction="0.8 0.03 0.02"/></body>
<body name="puck" pos="1 1 0.05" euler="0 0 20"><freejoint/>
  <geom type="box" size="0.1 0.08 0.04" condim="1" priority="1"/></body>
<body name="block" pos="2 0 0.06"><freejoint/><geom type="box" size="0.1 0.1 0.05" condim="3" friction="0.5"/></body>
</worldbody></mujoco>"""
# per body: its geom's (sliding, torsional, rolling) friction and its contact's condim with the floor
MJCF_GEOMS = {"spinner": ((0.7, 0.02, 0.0001), 4), "roller": ((0.9, 0.01, 0.0001), 6),
              "log": ((0.8, 0.03, 0.02), 6), "puck": ((1.0, 0.005, 0.0001), 1), "block": ((0.5, 0.005, 0.0001), 3)}


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_mjcf_condim_and_friction_step_like_mujoco(f64, cone, tmp_path, caplog):
    """gs.morphs.MJCF of a file whose geoms state condim 4, 6, 1 (by priority over the floor's 3)
    and 3, and friction in full, partly ("0.7 0.02": rolling MuJoCo's 0.0001, which acts at the
    roller's condim 6, above the floor's 0.00001) or not at all: loaded without a warning (the old
    one said condim 4 and 6 were taken as 3), the model holds the file's friction (geom_friction
    (G, 3)) and each floor pair's condim as MuJoCo's contacts have it (pair_condim); bodies set
    spinning, rolling and sliding step as MuJoCo's model of the same file (its Euler integrator,
    impratio 1) for 0.3 s within 1e-6 in qpos and qvel (measured ≤ 7e-15)."""
    path = tmp_path / "spin_roll.xml"
    path.write_text(MJCF)
    m = mujoco.MjModel.from_xml_path(str(path))
    m.opt.cone = {"pyramidal": mujoco.mjtCone.mjCONE_PYRAMIDAL, "elliptic": mujoco.mjtCone.mjCONE_ELLIPTIC}[cone]
    d = mujoco.MjData(m)
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=m.opt.timestep),
                     rigid_options=gs.options.RigidOptions(enable_mujoco_compatibility=True, friction_cone=cone,
                                                           impratio=1.0), show_viewer=False)
    with warns(caplog, None):
        robot = scene.add_entity(gs.morphs.MJCF(file=str(path)))
        scene.build()

    model = scene._rigid_solver.model
    body_of_geom = [model.link_name[link] for link in model.geom_link]
    assert model.geom_friction.shape == (len(MJCF_GEOMS) + 1, 3)
    for g, body in enumerate(body_of_geom):
        expected = MJCF_GEOMS[body][0] if body in MJCF_GEOMS else (0.6, 0.001, 0.00001)  # (else the floor)
        np.testing.assert_allclose(model.geom_friction[g], expected, rtol=1e-15)
        if body in MJCF_GEOMS:
            np.testing.assert_allclose(m.geom_friction[m.body(body).geomadr[0]], expected, rtol=1e-15)
    floor_condim = {}
    for g1, g2, condim in zip(model.pair_geom1, model.pair_geom2, model.pair_condim):
        names = {body_of_geom[g1], body_of_geom[g2]}
        if not names <= set(MJCF_GEOMS):
            floor_condim[(names & set(MJCF_GEOMS)).pop()] = int(condim)
    assert floor_condim == {body: condim for body, (_, condim) in MJCF_GEOMS.items()}

    qvel0 = np.concatenate([[0.3, 0.0, 0.0, 0.0, 0.0, 8.0],   # spinner: spins, slides sideways
                            [1.0, 0.0, 0.0, 0.0, 10.0, 0.0],  # roller: rolls at 1 m/s
                            [0.5, 0.0, 0.0, 0.0, 10.0, 3.0],  # log: rolls on its side, turning
                            [0.8, 0.2, 0.0, 0.0, 0.0, 2.0],   # puck: slides, spins (frictionless)
                            [0.5, 0.0, 0.0, 0.0, 0.0, 4.0]])  # block: slides, spins
    robot.set_dofs_velocity(torch.tensor(qvel0, dtype=gs.tc_float))
    d.qvel[:] = qvel0
    worst, mujoco_condim = 0.0, {}
    for _ in range(150):
        scene.step()
        mujoco.mj_step(m, d)
        worst = max(worst, np.abs(robot.get_qpos().numpy() - d.qpos).max(),
                    np.abs(robot.get_dofs_velocity().numpy() - d.qvel).max())
        for c in d.contact[: d.ncon]:
            mujoco_condim[m.body(m.geom_bodyid[max(c.geom)]).name] = int(c.dim)
    assert worst <= 1e-6, worst
    assert mujoco_condim == floor_condim  # (every body touched the floor; MuJoCo's contacts have its condim)
    assert abs(d.qvel[5 + 18]) > 1.9  # the frictionless puck spins on (2 rad/s)


def test_bad_torsional_and_rolling_input_is_named(f64):
    """Rolling friction without torsional (MuJoCo's condim 6 is condim 4's rows and two more), a
    negative, infinite, NaN or boolean friction length: each a gs.InvalidInputError naming the
    argument."""
    with pytest.raises(gs.InvalidInputError, match="enable_rolling_friction"):
        gs.options.RigidOptions(enable_rolling_friction=True)
    for name in ("friction_torsional", "friction_rolling"):
        for bad in (-1, float("inf"), float("nan")):
            with pytest.raises(gs.InvalidInputError, match=name):
                gs.materials.Rigid(**{name: bad})
    scene = gs.Scene(show_viewer=False)
    ball = scene.add_entity(gs.morphs.Sphere(radius=R))
    scene.build()
    for setter, bad in ((ball.set_friction_rolling, -0.1), (ball.set_friction_torsional, float("nan")),
                        (ball.set_friction_rolling, float("inf")), (ball.set_friction_torsional, True),
                        (ball.set_friction_rolling, torch.tensor([0.1, 0.2]))):
        name = setter.__name__[len("set_"):]
        with pytest.raises(gs.InvalidInputError, match=name):
            setter(bad)
    ball.set_friction_torsional(0.02)  # (good values pass: a number, a 0-d tensor)
    ball.set_friction_rolling(torch.tensor(0.001, dtype=gs.tc_float))
