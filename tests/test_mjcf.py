"""gs.morphs.MJCF against MuJoCo 4 reading the same file (float64).

assets/mjcf/arm.xml (fixed base; default classes, degrees, every orientation form, joint anchors off
the body origin, a body with two joints, a welded body, inertias stated and from geoms, joint
damping / armature / friction loss / limits / springs (stiffness, springref in degrees) / ref,
position and affine general actuators, an included file) and assets/mjcf/crawler.xml (free root,
hinged legs, contact bit masks: only the feet touch the ground, per-geom friction). Each runs under
sinusoidal servo targets in both engines, MuJoCo with the implicitfast integrator (our servos' kv is
implicit), both with the ground plane of the file's worldbody: the trajectories agree to
round-off (measured: arm 2.7e-15 over 400 steps with limit and friction-loss rows active; crawler
6e-14 pyramidal, 3e-13 elliptic over 500 steps with 1-3 foot contacts).
"""
import logging

import mujoco
import numpy as np
import pytest
import torch

import genesis_lite as gs
from genesis_lite.solvers.core import AssetError, InvalidInputError
from genesis_lite.solvers.rigid import contact, mjcf
from tests.conftest import asset, warns
from tests.fd_scan import assert_converged, checked_gradient, directional_errors, pose_loss

ARM, CRAWLER, TREES = asset("mjcf", "arm.xml"), asset("mjcf", "crawler.xml"), asset("mjcf", "trees.xml")
WORLDBODY, CONTACT_PARAMS = asset("mjcf", "worldbody.xml"), asset("mjcf", "contact_params.xml")
JOINT_SOFTNESS, REPLICATE = asset("mjcf", "joint_softness.xml"), asset("mjcf", "replicate.xml")
TENDONS = asset("mjcf", "tendons.xml")


def _pair(path, cone="pyramidal", integrator="implicitfast", requires_grad=False, exclude_ground_plane=False,
          **rigid_options):
    """(MuJoCo model, data, our scene, our entity) of the file (its worldbody's geoms, the floor, in
    both; with ``exclude_ground_plane``, MuJoCo's worldbody planes collide with nothing); MuJoCo with
    ``integrator`` (implicitfast: our servos' kv is implicit; euler where free bodies turn, which
    MuJoCo 4's implicitfast integrates otherwise than its Euler integrator and ours), ours with
    MuJoCo's contact defaults and ``rigid_options``."""
    m = mujoco.MjModel.from_xml_path(str(path))
    m.opt.integrator = {"implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
                        "euler": mujoco.mjtIntegrator.mjINT_EULER}[integrator]
    m.opt.cone = {"pyramidal": mujoco.mjtCone.mjCONE_PYRAMIDAL, "elliptic": mujoco.mjtCone.mjCONE_ELLIPTIC}[cone]
    if exclude_ground_plane:
        planes = (m.geom_bodyid == 0) & (m.geom_type == mujoco.mjtGeom.mjGEOM_PLANE)
        m.geom_contype[planes] = m.geom_conaffinity[planes] = 0
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=m.opt.timestep, requires_grad=requires_grad),
                     rigid_options=gs.options.RigidOptions(enable_mujoco_compatibility=True, friction_cone=cone,
                                                           **rigid_options))
    robot = scene.add_entity(gs.morphs.MJCF(file=str(path), exclude_ground_plane=exclude_ground_plane))
    scene.build()
    return m, mujoco.MjData(m), scene, robot


def _lockstep(m, d, scene, robot, steps, after_step=None):
    """The largest |qpos| and |qvel| difference of ``steps`` steps of both engines side by side;
    ``after_step()`` runs after each."""
    worst = 0.0
    for _ in range(steps):
        mujoco.mj_step(m, d)
        scene.step()
        worst = max(worst, np.abs(robot.get_qpos().numpy() - d.qpos).max(),
                    np.abs(robot.get_dofs_velocity().numpy() - d.qvel).max())
        if after_step is not None:
            after_step()
    return worst


def test_arm_masses_frames_and_trajectory_match_mujoco(f64):
    m, d, scene, robot = _pair(ARM)
    links = {link.name: link for link in robot.links}
    assert [link.name for link in robot.links] == ["base", "shoulder:yaw", "shoulder", "upper:pitch", "upper",
                                                   "mount", "wrist"]
    for body in range(1, m.nbody):
        assert float(links[m.body(body).name].get_mass()) == pytest.approx(m.body_mass[body], rel=1e-14)
    assert robot.get_dofs_kp().tolist() == [40.0, 60.0, 300.0, 5.0]
    assert robot.get_dofs_kv().tolist() == [2.0, 3.0, 20.0, 0.3]
    np.testing.assert_allclose(robot.get_qpos().numpy(), m.qpos0, atol=1e-15)  # the refs: 10°, 0.03 m
    mujoco.mj_kinematics(m, d)
    for body in range(1, m.nbody):  # at q = ref the bodies are where the file puts them
        np.testing.assert_allclose(links[m.body(body).name].get_pos().numpy(), d.xpos[body], atol=1e-14)
    worst, rows = 0.0, 0
    for t in range(400):
        target = 0.5 * np.sin(np.arange(4) + 3.0 * t * m.opt.timestep) * np.array([1.0, 1.0, 0.1, 1.0])
        d.ctrl[:] = target
        robot.control_dofs_position(torch.tensor(target))
        mujoco.mj_step(m, d)
        scene.step()
        worst = max(worst, np.abs(robot.get_dofs_position().numpy() - d.qpos).max(),
                    np.abs(robot.get_dofs_velocity().numpy() - d.qvel).max())
        rows = max(rows, d.nefc)
    assert rows == 5  # four friction-loss rows and the slide's lower limit: not a free run
    assert worst < 1e-12
    mujoco.mj_kinematics(m, d)  # (mj_step leaves the frames of the state it started from)
    for body in range(1, m.nbody):  # a body's link is its frame, wherever its joints' anchors are
        link = links[m.body(body).name]
        np.testing.assert_allclose(link.get_pos().numpy(), d.xpos[body], atol=1e-12)
        assert abs(abs(link.get_quat().numpy() @ d.xquat[body]) - 1.0) < 1e-12
    np.testing.assert_allclose(links["shoulder:yaw"].get_pos().numpy(), d.xanchor[0], atol=1e-12)


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_crawler_with_contact_masks_matches_mujoco(f64, cone):
    m, d, scene, robot = _pair(CRAWLER, cone)
    assert float(robot.get_mass()) == pytest.approx(m.body_mass.sum(), rel=1e-14)
    worst, counts = 0.0, set()
    for t in range(500):
        target = 0.4 * np.sin(np.arange(8) * 0.7 + 8.0 * t * m.opt.timestep)
        d.ctrl[:] = target
        robot.control_dofs_position(torch.tensor(target), dofs_idx_local=list(range(6, 14)))
        mujoco.mj_step(m, d)
        scene.step()
        worst = max(worst, np.abs(robot.get_dofs_velocity().numpy() - d.qvel).max(),
                    np.abs(robot.get_dofs_position().numpy()[6:] - d.qpos[7:]).max(),
                    np.abs(robot.get_pos().numpy() - d.qpos[:3]).max())
        counts.add(d.ncon)
        # only feet touch the plane (the legs' masks share no bit with anything)
        assert all(m.geom(c.geom2).name == "" and m.geom_type[c.geom2] == mujoco.mjtGeom.mjGEOM_SPHERE
                   for c in d.contact[:d.ncon])
    assert counts >= {1, 2, 3}
    assert worst < 1e-11


@pytest.mark.parametrize("cone", ["pyramidal", pytest.param("elliptic", marks=pytest.mark.slow)])
def test_worldbody_geoms_are_a_static_world_link_and_match_mujoco(f64, cone):
    """assets/mjcf/worldbody.xml: the worldbody's floor, ramp and bar (in a <frame>) are one static
    massless link, "world", the entity's last; a block slides on the ramp, a ball lands on the bar,
    a pendulum hinged on the world swings into the floor (MuJoCo's parent filter skips the world),
    a ball excluded from the world (<contact><exclude>) falls through. 1.5 s against MuJoCo 4:
    equal to round-off (measured 6.3e-14 pyramidal, 6.8e-14 elliptic)."""
    m, d, scene, robot = _pair(WORLDBODY, cone, integrator="euler")
    assert [link.name for link in robot.links] == ["block", "ball", "world:pendulum", "pendulum", "ghost", "world"]
    world = robot.links[-1]
    assert world.is_fixed and float(world.get_mass()) == 0.0 and robot.n_geoms == m.ngeom == 7
    assert robot.base_link.name == "block"  # (the bodies keep the file's order and indices)
    velocity = np.zeros(m.nv)
    velocity[m.jnt_dofadr[m.joint("swing").id]] = 4.0
    d.qvel[:] = velocity
    robot.set_dofs_velocity(torch.tensor(velocity))
    ours, theirs = set(), set()

    def note():
        contacts = robot.get_contacts()
        ours.update(frozenset(robot.links[k - robot.link_start].name for k in (int(a), int(b)))
                    for a, b in zip(contacts["link_a"], contacts["link_b"]))
        theirs.update(m.geom(c.geom1).name or m.geom(c.geom2).name for c in d.contact[:d.ncon])

    assert _lockstep(m, d, scene, robot, 750, note) < 1e-10
    assert ours == {frozenset(("world", name)) for name in ("block", "ball", "pendulum")}
    assert theirs == {"floor", "ramp", "bar"}  # (every world geom met a body)
    assert float(robot.get_link("ghost").get_pos()[2]) < -5.0


def _launch(m, d, robot):
    """Start contact_params.xml's bodies moving (both engines): the capsule rolling off, the
    prioritised box sliding, the sphere rolling, the last box spinning."""
    velocity = np.zeros(m.nv)
    for body, dof, value in (("frictionless", 0, 1.0), ("prioritised", 0, -0.5), ("mixed", 1, 0.8),
                             ("direct", 0, 0.6), ("spinning", 5, 10.0)):
        velocity[m.jnt_dofadr[m.body(body).jntadr[0]] + dof] = value
    d.qvel[:] = velocity
    robot.set_dofs_velocity(torch.tensor(velocity))


def _mujoco_geoms(m, scene, robot):
    """MuJoCo's index of each of the entity's geoms (matched by body, in the body's order)."""
    model, seen, order = scene._rigid_solver.model, {}, []
    for g in range(robot.geom_start, robot.geom_start + robot.n_geoms):
        body = robot.links[int(model.geom_link[g]) - robot.link_start].name
        order.append(m.body(body).geomadr[0] + seen.get(body, 0))
        seen[body] = seen.get(body, 0) + 1
    return order


@pytest.mark.parametrize("cone", ["pyramidal", pytest.param("elliptic", marks=pytest.mark.slow)])
def test_geoms_contact_parameters_combine_as_mujocos(f64, cone):
    """assets/mjcf/contact_params.xml: each geom's condim, priority, solmix, solref (standard and
    direct form) and solimp (a partial one over its class's) are read as MuJoCo's compiler reads
    them, and a pair combines them as mj_contactParam (the higher priority's, else condim the
    larger, solref and solimp weighted by solmix, the direct form's solref the smaller, friction
    the larger): a capsule and a ramp of condim 1 slide without friction; 1 s beside MuJoCo 4 with
    the bodies launched, equal to round-off (measured 1.6e-12 pyramidal, 2.0e-13 elliptic)."""
    m, d, scene, robot = _pair(CONTACT_PARAMS, cone, integrator="euler")
    mine, inputs = _mujoco_geoms(m, scene, robot), scene.sim.inputs(scene._rigid_solver)
    np.testing.assert_array_equal(inputs["solref"][0].reshape(-1, 2).numpy(), m.geom_solref[mine])
    np.testing.assert_array_equal(inputs["solimp"][0].reshape(-1, 5).numpy(), m.geom_solimp[mine])
    _launch(m, d, robot)
    dims = set()
    assert _lockstep(m, d, scene, robot, 500, lambda: dims.update(d.contact.dim[:d.ncon].tolist())) < 1e-10
    assert dims == {1, 3} and set(scene._rigid_solver.model.pair_condim.tolist()) == {1, 3}


def test_gradients_through_geoms_contact_parameters_match_finite_differences(f64):
    """contact_params.xml's bodies landing and sliding for 0.2 s (condim-1 contacts, priorities,
    solmix weights, a direct solref): the gradient of their final poses w.r.t. every geom's
    sol_params, and w.r.t. the links' friction ratios, against central differences."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002, requires_grad=True),
                     rigid_options=gs.options.RigidOptions(enable_mujoco_compatibility=True, tolerance=1e-14))
    robot = scene.add_entity(gs.morphs.MJCF(file=CONTACT_PARAMS))
    scene.build()
    m = mujoco.MjModel.from_xml_path(CONTACT_PARAMS)
    start_sol = torch.tensor(np.concatenate([m.geom_solref, m.geom_solimp], axis=1)[_mujoco_geoms(m, scene, robot)])
    moving = [k for k, link in enumerate(robot.links) if not link.is_fixed]
    weights = torch.tensor(np.random.default_rng(3).normal(size=(len(moving), 7)))

    def loss(x, what):
        scene.reset()
        _launch(m, mujoco.MjData(m), robot)
        if what == "sol_params":
            for g in range(robot.n_geoms):
                robot.set_sol_params(x[g], geoms_idx_local=[g])
        else:
            robot.set_friction_ratio(x, links_idx_local=moving)
        for _ in range(100):
            scene.step()
        links = torch.cat([robot.get_links_pos(moving), robot.get_links_quat(moving)], dim=-1)
        return (links * weights).sum()

    for what, start in (("sol_params", start_sol), ("friction", torch.linspace(0.6, 1.4, len(moving)))):
        assert_converged(directional_errors(lambda x: loss(x, what), start), f"contact parameters: {what}")


def _swing(m, d, robot):
    """Start joint_softness.xml's joints towards their limits (both engines)."""
    velocity = np.zeros(m.nv)
    velocity[:12] = [3.0, -4.0, 1.0, 2.0, -3.0, 1.0, 0.5, 0.0, 0.0, 0.0, 0.0, 2.0]
    d.qvel[:] = velocity
    robot.set_dofs_velocity(torch.tensor(velocity))
    return velocity


@pytest.mark.parametrize("cone", ["pyramidal", pytest.param("elliptic", marks=pytest.mark.slow)])
def test_joint_limit_and_friction_loss_softness_as_mujocos(f64, cone):
    """assets/mjcf/joint_softness.xml: each joint's solreflimit, solimplimit, solreffriction and
    solimpfriction (standard and direct forms, partial values over a default class's, a ball
    joint's cone limit, a free joint's friction loss) are read as MuJoCo's compiler reads them
    (clamped as its runtime clamps them) and soften the joint's limit and friction-loss rows: 1.5 s
    beside MuJoCo 4 with the joints swung into their limits, equal to round-off (measured 4.9e-13
    pyramidal, 4.1e-12 elliptic)."""
    m, d, scene, robot = _pair(JOINT_SOFTNESS, cone, integrator="euler")
    solver = scene._rigid_solver
    model = contact.with_row_softness(solver.model, solver.timeconst)
    dofs = slice(robot.dof_start, robot.dof_start + robot.n_dofs)
    limit = np.concatenate([m.jnt_solref, m.jnt_solimp], axis=1)[m.dof_jntid]  # (MuJoCo's: per joint)
    friction = np.concatenate([m.dof_solref, m.dof_solimp], axis=1)
    for ours, theirs in ((model.dof_limit_sol, limit), (model.dof_frictionloss_sol, friction)):
        theirs[:, 2:] = np.clip(theirs[:, 2:], [1e-4, 1e-4, 0.0, 1e-4, 1.0], [0.9999, 0.9999, np.inf, 0.9999, np.inf])
        np.testing.assert_array_equal(ours[dofs], theirs)
    _swing(m, d, robot)
    rows = set()
    assert _lockstep(m, d, scene, robot, 750, lambda: rows.update(d.efc_type[:d.nefc].tolist())) < 1e-10
    assert {mujoco.mjtConstraint.mjCNSTR_LIMIT_JOINT, mujoco.mjtConstraint.mjCNSTR_FRICTION_DOF} <= rows


def test_gradients_through_soft_joint_limits_match_finite_differences(f64):
    """joint_softness.xml's joints swung into their limits for 0.3 s (limit rows of either form, a
    ball joint's cone, friction loss, each with the file's softness): the gradient of the final
    pose w.r.t. the initial velocities against central differences."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002, requires_grad=True),
                     rigid_options=gs.options.RigidOptions(enable_mujoco_compatibility=True, tolerance=1e-14))
    robot = scene.add_entity(gs.morphs.MJCF(file=JOINT_SOFTNESS))
    scene.build()
    m = mujoco.MjModel.from_xml_path(JOINT_SOFTNESS)
    start = torch.tensor(_swing(m, mujoco.MjData(m), robot))
    weights = torch.tensor(np.random.default_rng(5).normal(size=m.nq))

    def loss(velocity):
        scene.reset()
        robot.set_dofs_velocity(velocity)
        for _ in range(150):
            scene.step()
        return (robot.get_qpos() * weights).sum()

    for seed in range(2):
        assert_converged(directional_errors(loss, start, seed), f"soft joint limits, direction {seed}")


@pytest.mark.parametrize("cone", ["pyramidal", pytest.param("elliptic", marks=pytest.mark.slow)])
def test_fixed_tendon_limits_match_mujoco(f64, cone):
    """assets/mjcf/tendons.xml: limited fixed tendons (two joints, three with a slide and their own
    softness, two trees', a <default><tendon>) hold their length Σ coef·q in range by limit rows
    whose scale is MuJoCo's tendon_invweight0 (J M⁻¹ Jᵀ, here from the mass and armature inputs);
    1.5 s from random velocities beside MuJoCo 4, equal to round-off (measured 7.6e-13)."""
    m, d, scene, robot = _pair(TENDONS, cone, integrator="euler")
    mujoco.mj_setConst(m, mujoco.MjData(m))
    limited = np.flatnonzero(m.tendon_limited)
    np.testing.assert_allclose(scene.sim.inputs(scene._rigid_solver)["invweight_ten"][0].numpy(),
                               m.tendon_invweight0[limited], rtol=1e-12)
    velocity = np.random.default_rng(0).normal(0.0, 3.0, m.nv)
    velocity[:2] = 4.0, -4.0  # (hip and knee: the hamstring stretches)
    d.qvel[:] = velocity
    robot.set_dofs_velocity(torch.tensor(velocity))
    met = set()
    assert _lockstep(m, d, scene, robot, 750, lambda: met.update(d.efc_id[:d.nefc][d.efc_type[:d.nefc] == 4])) < 1e-10
    assert met == set(limited.tolist()) and len(met) == 3  # (every limited tendon met its limit)


def test_more_tendons_than_dofs_match_mujoco(f64, tmp_path):
    """Three limited fixed tendons on one hinge (q ≥ -0.3 by the first, q ≤ 0.4 by the second,
    q ≤ 0.41 by the third, which the swing's soft limit reaches too), beside MuJoCo 4 for 1 s:
    more tendons than dofs (their arrays sized by the tendons)."""
    tendons = ('<option timestep="0.002"/><tendon>'
               '<fixed range="-0.3 2"><joint joint="j" coef="1"/></fixed>'
               '<fixed range="-2 0.8"><joint joint="j" coef="2"/></fixed>'
               '<fixed range="-0.41 5"><joint joint="j" coef="-1"/></fixed></tendon>')
    path = _write(tmp_path, f'<body name="b" pos="0 0 1"><joint name="j" axis="0 1 0"/>'
                            f'<geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"/></body>', tendons)
    m, d, scene, robot = _pair(path, integrator="euler")
    d.qvel[:] = -6.0  # (into the first tendon's limit; then gravity swings it into the others')
    robot.set_dofs_velocity(torch.tensor([-6.0]))
    met = set()
    assert _lockstep(m, d, scene, robot, 500, lambda: met.update(d.efc_id[:d.nefc][d.efc_type[:d.nefc] == 4])) < 1e-10
    assert robot.n_dofs == 1 and met == {0, 1, 2}


# A hip-knee-ankle chain whose fixed tendon "coupling" (quadruped's of dm_control) an <equality>
# <tendon> holds at its length at qpos0 (the knee's ref in it), with a default class's softness,
# and a second tendon held 1 cm off its rest length, beyond its limit (both rows act)
HELD_TENDONS = ('<body name="thigh" pos="0 0 1"><joint name="hip" axis="0 1 0"/>'
                '<geom type="capsule" fromto="0 0 0 0 0 -0.3" size="0.04"/>'
                '<body name="shin" pos="0 0 -0.3"><joint name="knee" axis="0 1 0" ref="0.2"/>'
                '<geom type="capsule" fromto="0 0 0 0 0 -0.3" size="0.035"/>'
                '<body name="foot" pos="0 0 -0.3"><joint name="ankle" axis="0 1 0"/>'
                '<joint name="toe" type="slide" axis="1 0 0"/>'
                '<geom type="box" size="0.08 0.03 0.02" pos="0.04 0 0"/></body></body></body>')
HELD_TENDONS_EXTRA = ('<option timestep="0.002"/><default><joint damping="0.02"/><default class="coupling">'
                      '<equality solref="0.005 0.5" solimp="0.9 0.95 0.001"/></default></default>'
                      '<tendon><fixed name="coupling"><joint joint="hip" coef=".333"/><joint joint="knee" coef=".333"/>'
                      '<joint joint="ankle" coef=".333"/></fixed><fixed name="slider" range="-0.05 0.005">'
                      '<joint joint="toe" coef="1"/><joint joint="ankle" coef="-0.1"/></fixed></tendon>'
                      '<equality><tendon name="coupling" tendon1="coupling" class="coupling"/>'
                      '<tendon tendon1="slider" polycoef="0.01"/></equality>')


def test_tendon_equalities_hold_as_mujocos(f64, tmp_path):
    """<equality><tendon tendon1 polycoef> (dm_control's quadruped, manipulator and stacker): a fixed
    tendon held at its length at qpos0 plus polycoef[0] by an equality row of its class's softness,
    scaled by MuJoCo's tendon_invweight0; 1 s from fast random velocities beside MuJoCo 4 (both
    rows acting, the second tendon's limit met too)."""
    path = _write(tmp_path, HELD_TENDONS, HELD_TENDONS_EXTRA)
    m, d, scene, robot = _pair(path, integrator="euler")
    d.qvel[:] = velocity = np.random.default_rng(0).normal(0.0, 3.0, m.nv)
    robot.set_dofs_velocity(torch.tensor(velocity))
    kinds = set()
    assert _lockstep(m, d, scene, robot, 500, lambda: kinds.update(d.efc_type[:d.nefc].tolist())) < 1e-10
    assert {mujoco.mjtConstraint.mjCNSTR_EQUALITY, mujoco.mjtConstraint.mjCNSTR_LIMIT_TENDON} <= kinds
    mujoco.mj_forward(m, d)
    assert abs(d.ten_length[0] - m.tendon_length0[0]) < 0.02  # (held, softly)


# A hip-knee chain with a slide at its end and a pendulum beside it, and fixed tendons with
# MuJoCo's passive springs and dampers: one resting where the joints' springrefs put it (the
# default springlength; the knee's ref, its initial angle, elsewhere), one with a dead band (two
# springlengths), one damper alone (one springlength), one limited and sprung
SPRUNG_TENDONS = ('<body name="thigh" pos="0 0 1"><joint name="hip" axis="0 1 0" springref="0.3"/>'
                  '<geom type="capsule" fromto="0 0 0 0 0 -0.3" size="0.04"/>'
                  '<body name="shin" pos="0 0 -0.3"><joint name="knee" axis="0 1 0" ref="10" springref="-0.2"/>'
                  '<geom type="capsule" fromto="0 0 0 0 0 -0.3" size="0.035"/>'
                  '<body name="foot" pos="0 0 -0.3"><joint name="toe" type="slide" axis="1 0 0"/>'
                  '<geom type="box" size="0.08 0.03 0.02" pos="0.04 0 0"/></body></body></body>'
                  '<body name="bob" pos="0.6 0 1"><joint name="swing" axis="1 0 0"/>'
                  '<geom type="capsule" fromto="0 0 0 0 0.3 0" size="0.03"/></body>')
SPRUNG_TENDONS_EXTRA = ('<option timestep="0.002"/><default><joint damping="0.01"/></default><tendon>'
                        '<fixed name="rest" stiffness="8" damping="0.05"><joint joint="hip" coef="0.5"/>'
                        '<joint joint="knee" coef="-0.5"/></fixed>'
                        '<fixed name="band" stiffness="20" springlength="-0.1 0.05"><joint joint="knee" coef="1"/>'
                        '<joint joint="toe" coef="2"/><joint joint="swing" coef="0.3"/></fixed>'
                        '<fixed name="damper" damping="0.3" springlength="0.2"><joint joint="swing" coef="1"/></fixed>'
                        '<fixed name="both" stiffness="3" range="-0.6 0.6" springlength="0.1">'
                        '<joint joint="hip" coef="1"/><joint joint="swing" coef="-1"/></fixed>'
                        '</tendon>')


def test_fixed_tendon_springs_and_dampers_act_as_mujocos(f64, tmp_path):
    """MuJoCo's passive tendon force −k·(L − the nearer end of springlength, 0 inside it) − b·L̇
    along each tendon (its joints' generalised forces c_j·f): the default rest length at the joints'
    springrefs (qpos_spring), a dead band, a damper alone, a spring on a limited tendon; 1 s from
    random velocities beside MuJoCo 4 (Euler: both explicit there), and the potential energy with
    the tendons' spring energy (mjENBL_ENERGY)."""
    path = _write(tmp_path, SPRUNG_TENDONS, SPRUNG_TENDONS_EXTRA)
    m, d, scene, robot = _pair(path, integrator="euler")
    rest = np.deg2rad(0.5 * 0.3 - 0.5 * -0.2)  # (springrefs in the compiler's degrees)
    ours = sorted(scene._rigid_solver.model.ten_spring.tolist())  # (ours listed by first joint, MuJoCo's as written)
    np.testing.assert_allclose(ours, sorted([[rest, rest], [-0.1, 0.05], [0.2, 0.2], [0.1, 0.1]]), rtol=1e-15)
    np.testing.assert_allclose(ours, sorted(m.tendon_lengthspring.tolist()), rtol=1e-15)
    d.qvel[:] = velocity = np.random.default_rng(2).normal(0.0, 3.0, m.nv)
    robot.set_dofs_velocity(torch.tensor(velocity))
    band = []
    assert _lockstep(m, d, scene, robot, 500, lambda: band.append(d.ten_length[1])) < 1e-12
    assert min(band) < -0.1 and max(band) > 0.05  # (the dead band's both ends were passed)
    m.opt.enableflags |= mujoco.mjtEnableBit.mjENBL_ENERGY
    mujoco.mj_forward(m, d)
    welded = -sum(m.body_mass[b] * m.opt.gravity @ d.xipos[b] for b in range(1, m.nbody) if m.body_weldid[b] == 0)
    assert abs(float(robot.get_potential_energy()) - (d.energy[0] - welded)) < 1e-12
    rest = m.tendon_lengthspring
    stretch = d.ten_length - np.clip(d.ten_length, rest[:, 0], rest[:, 1])
    assert 0.5 * (m.tendon_stiffness * stretch ** 2).sum() > 1e-3  # (the tendons' share is there to check)


@pytest.mark.parametrize("what", ["velocity", "mass"])
def test_gradients_through_tendon_springs_match_finite_differences(f64, tmp_path, what):
    """The sprung tendons' chain for 0.3 s: the gradient of every link's pose w.r.t. the initial
    velocities and the masses against central differences."""
    _assert_pose_gradients_converge(_write(tmp_path, SPRUNG_TENDONS, SPRUNG_TENDONS_EXTRA), what, 3.0, 2,
                                    "tendon springs")


# The sprung tendons and two that rub: one with its own solreffriction and solimpfriction, one of
# the scene's softness, across a hinge and the slide
RUBBING_TENDONS_EXTRA = SPRUNG_TENDONS_EXTRA.replace('</tendon>', (
    '<fixed name="rub" frictionloss="0.4" solreffriction="0.01 0.7" solimpfriction="0.8 0.95 0.002">'
    '<joint joint="hip" coef="1"/><joint joint="swing" coef="0.5"/></fixed>'
    '<fixed name="drag" frictionloss="0.2"><joint joint="knee" coef="-0.7"/><joint joint="toe" coef="3"/></fixed>'
    '</tendon>'))


def test_fixed_tendon_friction_loss_acts_as_mujocos(f64, tmp_path):
    """MuJoCo's tendon friction loss: a friction row on the tendon's rate (J = its coefficients,
    bound frictionloss, its solreffriction and solimpfriction or the scene's, scaled by
    tendon_invweight0), after the dofs' friction rows; 1 s from random velocities beside MuJoCo 4,
    both tendons' rows present."""
    m, d, scene, robot = _pair(_write(tmp_path, SPRUNG_TENDONS, RUBBING_TENDONS_EXTRA), integrator="euler")
    d.qvel[:] = velocity = np.random.default_rng(4).normal(0.0, 3.0, m.nv)
    robot.set_dofs_velocity(torch.tensor(velocity))
    rubbed, friction = set(), mujoco.mjtConstraint.mjCNSTR_FRICTION_TENDON
    note = lambda: rubbed.update(d.efc_id[:d.nefc][d.efc_type[:d.nefc] == friction])  # noqa: E731
    assert _lockstep(m, d, scene, robot, 500, note) < 1e-12
    assert rubbed == {4, 5}  # (MuJoCo's tendon ids: the file's order)


def test_tendon_friction_rows_have_their_row_slots(f64, tmp_path):
    """A hinge with friction loss started into its limit and a tendon on it with friction loss:
    three rows at once (the dof's friction, the tendon's, the limit), which the row slots count
    (the tendon's had been left out: it wrote past them, 4.2 rad/s from MuJoCo)."""
    body = ('<body name="b" pos="0 0 1"><joint name="j" axis="0 1 0" range="-0.2 0.2" frictionloss="0.05"/>'
            '<geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"/></body>')
    extra = ('<option timestep="0.002"/><compiler angle="radian"/><tendon><fixed frictionloss="0.1">'
             '<joint joint="j" coef="1"/></fixed></tendon>')
    m, d, scene, robot = _pair(_write(tmp_path, body, extra), integrator="euler")
    d.qpos[:], d.qvel[:] = 0.19, 4.0
    robot.set_qpos(torch.tensor([0.19]))
    robot.set_dofs_velocity(torch.tensor([4.0]))
    rows = []
    assert _lockstep(m, d, scene, robot, 200, lambda: rows.append(d.nefc)) < 1e-6  # (the solves' tolerance)
    assert max(rows) == 3


def test_gradients_through_tendon_friction_loss_match_finite_differences(f64, tmp_path):
    """The rubbing tendons' chain for 0.3 s: the gradient of every link's pose w.r.t. the initial
    velocities against central differences."""
    _assert_pose_gradients_converge(_write(tmp_path, SPRUNG_TENDONS, RUBBING_TENDONS_EXTRA), "velocity", 3.0, 3,
                                    "tendon friction loss")


@pytest.mark.parametrize("change, said", [
    (('springlength="-0.1 0.05"', 'springlength="0.05 -0.1"'),
     r"<tendon><fixed name='band'>: springlength expected lower ≤ upper, got '0.05 -0.1'"),
    (('stiffness="20"', 'stiffness="20" springyield="1"'),
     r"<tendon><fixed name='band'>: a yielding spring is not supported \(attribute 'springyield' = '1'\)"),
    (('stiffness="20"', 'stiffness="20 3"'), r"<tendon><fixed name='band'>: a polynomial stiffness is not supported"),
    (('damping="0.3"', 'damping="0.3 1"'), r"<tendon><fixed name='damper'>: a polynomial damping is not supported"),
    (('frictionloss="0.2"', 'frictionloss="-0.2"'), r"<tendon><fixed name='drag'>: frictionloss expected ≥ 0"),
])
def test_tendon_springs_refuse_what_is_not_modelled(f64, tmp_path, change, said):
    """As MuJoCo's compiler, a springlength above its upper end; not modelled yet, MuJoCo 4's
    yielding (plastic) tendon spring and polynomial stiffness and damping (dropped, they would move
    the tendon otherwise); a negative friction loss (MuJoCo forms no row: refused, not dropped)."""
    with pytest.raises(AssetError, match=said):
        mjcf.load_mjcf(_write(tmp_path, SPRUNG_TENDONS, RUBBING_TENDONS_EXTRA.replace(*change)))


def test_an_actuators_damping_and_armature_are_named_where_ignored(f64, tmp_path, caplog):
    """MuJoCo 4 adds an actuator's damping and armature to the joint (or tendon) it drives; not read
    here, they are named in the load's warning rather than dropped without a word."""
    body = f'<body name="b"><joint name="j" axis="0 1 0"/>{LINK}</body>'
    with warns(caplog, r"<actuator (armature|damping)> \(MuJoCo adds it") as said:
        mjcf.load_mjcf(_write(tmp_path, body, '<actuator><motor joint="j" damping="2" armature="0.1"/></actuator>'))
    assert "<actuator armature> (MuJoCo" in said[0] and "<actuator damping> (MuJoCo" in said[0]
    with warns(caplog, None):
        mjcf.load_mjcf(_write(tmp_path, body, '<actuator><motor joint="j" damping="0"/></actuator>'))


def test_the_most_joint_rows_a_step_can_form_fit_their_slots(f64, tmp_path):
    """Friction loss and a violated limit on every dof and a tendon both held and past its limit
    (two rows of one tendon): every joint row's columns have their slots (the held tendon's row
    once wrote past them: 0.1 apart from MuJoCo), 200 steps as MuJoCo 4's."""
    body = ('<body name="a" pos="0 0 1"><joint name="j1" axis="0 1 0"/>'
            '<geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03" mass="1"/>'
            '<body name="b" pos="0.3 0 0"><joint name="j2" axis="1 0 0"/>'
            '<geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03" mass="1"/></body></body>')
    extra = ('<option timestep="0.002"/><default><joint frictionloss="0.05" range="0.5 1"/></default>'
             '<tendon><fixed name="t" range="0.3 2"><joint joint="j1" coef="1"/><joint joint="j2" coef="1"/></fixed>'
             '</tendon><equality><tendon tendon1="t"/></equality>')
    m, d, scene, robot = _pair(_write(tmp_path, body, extra), integrator="euler")
    rows = []
    assert _lockstep(m, d, scene, robot, 200, lambda: rows.append(d.nefc)) < 1e-10
    assert max(rows) == 6  # (2 friction loss, 2 joint limits, the tendon's equality and limit)


@pytest.mark.parametrize("what", ["velocity", "mass"])
def test_gradients_through_tendon_equalities_match_finite_differences(f64, tmp_path, what):
    """The held tendons' chain for 0.3 s: the gradient of every link's pose w.r.t. the initial
    velocities and the masses (through the rows' scale) against central differences."""
    _assert_pose_gradients_converge(_write(tmp_path, HELD_TENDONS, HELD_TENDONS_EXTRA), what, 3.0, 1,
                                    "tendon equalities")


@pytest.mark.parametrize("equality, said", [
    ('<tendon tendon1="coupling" tendon2="slider"/>', r"tendon2 \(one tendon's length a polynomial of another's\)"),
    ('<tendon tendon1="nowhere"/>', r"tendon1 expected a fixed tendon of the file, got \['nowhere'\]"),
    ('<tendon tendon1="coupling"/><tendon tendon1="coupling"/>', "tendon1 'coupling' expected in one tendon"),
])
def test_tendon_equalities_refuse_what_is_not_supported(f64, tmp_path, equality, said):
    extra = HELD_TENDONS_EXTRA.split("<equality>")[0] + f"<equality>{equality}</equality>"
    with pytest.raises(AssetError, match=said):
        mjcf.load_mjcf(_write(tmp_path, HELD_TENDONS, extra))


def _assert_pose_gradients_converge(path, what, speed, seed, label):
    """The MJCF file's entity 0.3 s from random initial velocities (``speed`` rad/s or m/s, one
    sigma): the gradient of every link's pose w.r.t. those velocities (``what`` "velocity") or
    the masses of the links that have one ("mass") against central differences."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002, requires_grad=True),
                     rigid_options=gs.options.RigidOptions(enable_mujoco_compatibility=True, tolerance=1e-14))
    robot = scene.add_entity(gs.morphs.MJCF(file=path))
    scene.build()
    rng = np.random.default_rng(seed)
    velocity, weights = torch.tensor(rng.normal(0.0, speed, robot.n_dofs)), torch.tensor(rng.normal(size=(robot.n_links, 7)))
    heavy = [k for k, link in enumerate(robot.links) if float(link.get_mass()) > 0]
    if what == "velocity":
        start, apply = velocity, robot.set_dofs_velocity
    else:
        start = robot.get_links_mass().detach().clone()[heavy]

        def apply(mass):
            robot.set_links_mass(mass, links_idx_local=heavy)
            robot.set_dofs_velocity(velocity)
    loss = pose_loss(scene, robot, weights, 150, apply)
    assert_converged(directional_errors(loss, start), f"{label}: {what}")


@pytest.mark.parametrize("what", [pytest.param("velocity", marks=pytest.mark.slow), "mass"])
def test_gradients_through_tendon_limits_match_finite_differences(f64, what):
    """tendons.xml swung into its tendons' limits for 0.3 s: the gradient of every link's pose w.r.t.
    the initial velocities and the links' masses (through the rows' scale, J M⁻¹ Jᵀ) against
    central differences."""
    _assert_pose_gradients_converge(TENDONS, what, 3.0, 1, "tendon limits")


def test_exclude_ground_plane_leaves_out_the_worldbodys_planes(f64):
    """Genesis's option: the floor is gone (the pendulum swings through it), the ramp and the bar
    stay; against MuJoCo with the floor colliding with nothing."""
    m, d, scene, robot = _pair(WORLDBODY, integrator="euler", exclude_ground_plane=True)
    assert robot.n_geoms == m.ngeom - 1
    velocity = np.zeros(m.nv)
    velocity[m.jnt_dofadr[m.joint("swing").id]] = 4.0
    d.qvel[:] = velocity
    robot.set_dofs_velocity(torch.tensor(velocity))
    met = set()

    def note():
        met.update(m.geom(c.geom1).name or m.geom(c.geom2).name for c in d.contact[:d.ncon])
        contacts = robot.get_contacts()
        assert robot.get_link("pendulum").idx not in contacts["link_a"].tolist() + contacts["link_b"].tolist()

    assert _lockstep(m, d, scene, robot, 750, note) < 1e-10
    assert met == {"ramp", "bar"}


def test_a_plane_on_a_body_welded_to_the_world_is_loaded_as_mujoco(f64, tmp_path):
    """MuJoCo's compiler takes a plane on a static body (here a welded root's welded child, tilted
    20°, the plane tilted 30° more in it): a box dropped onto it slides as in MuJoCo."""
    path = _write(tmp_path, '<body name="base" pos="0 0 -0.2"><body name="slope" euler="20 0 0">'
                            '<geom type="plane" size="1 1 0.1" euler="30 0 0"/></body></body><body name="box" pos="0 0 0.1">'
                            '<freejoint/><geom type="box" size="0.05 0.05 0.05"/></body>')
    m, d, scene, robot = _pair(path, integrator="euler")
    assert robot.get_link("slope").is_fixed and robot.n_links == 3  # (no worldbody geoms: no world link)
    assert _lockstep(m, d, scene, robot, 300) < 1e-10
    assert float(robot.get_link("box").get_pos()[1]) < -0.05  # it slid down the slope


def test_a_worldbody_of_geoms_alone_is_one_static_link_and_planes_weigh_nothing(f64, tmp_path):
    """A file of worldbody geoms only (a terrain) is an entity of one static link, which a box
    lands on; a plane's stated mass is no mass (MuJoCo's compiler: 0 on a welded body)."""
    terrain = _write(tmp_path, '<geom type="plane" size="0 0 1"/><geom type="box" size="0.3 0.3 0.1" pos="0 0 0.1"/>')
    scene = gs.Scene()
    ground = scene.add_entity(gs.morphs.MJCF(file=terrain))
    box = scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(0.0, 0.0, 0.4)))
    scene.build()
    assert [link.name for link in ground.links] == ["world"] and ground.n_dofs == 0 and ground.n_geoms == 2
    for _ in range(150):
        scene.step()
    assert float(box.get_pos()[2]) == pytest.approx(0.25, abs=2e-3)  # on the box, not the plane
    path = _write(tmp_path, '<body name="base"><geom type="plane" size="1 1 1" mass="2"/></body>'
                            '<body name="b" pos="0 0 1"><freejoint/><geom type="sphere" size="0.1"/></body>')
    m, _, _, robot = _pair(path)
    assert [float(link.get_mass()) for link in robot.links] == pytest.approx(m.body_mass[1:].tolist(), rel=1e-14)
    assert m.body_mass[1] == 0.0


def test_contact_masks_keep_legs_out_of_the_ground(f64):
    """The crawler's legs, lowered into the ground with its feet, make contacts only at the feet (the
    Plane given the file's floor masks: Genesis's default 0xFFFF would meet the legs' bit 2)."""
    scene = gs.Scene()
    scene.add_entity(gs.morphs.Plane(contype=1, conaffinity=1))
    robot = scene.add_entity(gs.morphs.MJCF(file=CRAWLER, pos=(0.0, 0.0, -0.1), exclude_ground_plane=True))
    scene.build()
    scene.step()
    contacts = robot.get_contacts()
    links = {robot.links[k - robot.link_start].name for k in contacts["link_b"].tolist() + contacts["link_a"].tolist()
             if k >= robot.link_start}
    assert len(contacts["position"]) == 4 and links <= {"leg_fl", "leg_fr", "leg_bl", "leg_br"}  # one a foot


def test_morph_pose_places_the_files_world_and_fixed_welds_the_free_root(f64):
    scene = gs.Scene(sim_options=gs.options.SimOptions(gravity=(0.0, 0.0, -9.81)))
    free = scene.add_entity(gs.morphs.MJCF(file=CRAWLER, pos=(1.0, 2.0, 0.5), euler=(0.0, 0.0, 90.0)))
    welded = scene.add_entity(gs.morphs.MJCF(file=CRAWLER, pos=(-1.0, 0.0, 0.0), fixed=True))
    scene.build()
    assert free.n_dofs == 14 and welded.n_dofs == 8
    np.testing.assert_allclose(free.get_pos().numpy(), [1.0, 2.0, 0.75], atol=1e-15)  # root at 0.25 in the file
    np.testing.assert_allclose(free.get_quat().numpy(), [np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)], atol=1e-15)
    for _ in range(10):
        scene.step()
    assert free.get_pos().numpy()[2] < 0.74 and welded.get_pos().numpy().tolist() == [-1.0, 0.0, 0.25]


def _numbers(values):
    return " ".join(repr(float(v)) for v in values)


ORIENTED = {  # attribute: (a random value of it, the compiler element)
    "euler": (lambda rng: rng.uniform(-180, 180, 3), ""),
    "euler ZyX radian": (lambda rng: rng.uniform(-3, 3, 3), '<compiler angle="radian" eulerseq="ZyX"/>'),
    "axisangle": (lambda rng: np.append(rng.normal(size=3), rng.uniform(-180, 180)), ""),
    "quat": (lambda rng: rng.normal(size=4), ""),
    "xyaxes": (lambda rng: rng.normal(size=6), ""),
    "zaxis": (lambda rng: rng.normal(size=3), ""),
    "fromto": (lambda rng: rng.normal(size=6), ""),
    "quat in a turned frame": (lambda rng: rng.normal(size=4), ""),
}


@pytest.mark.parametrize("attribute", list(ORIENTED))
def test_frames_are_mujocos_bits(f64, tmp_path, attribute):
    """Geom frames given by each orientation attribute, bodies turned by it and their hinge axes
    compile to MuJoCo's bits (geom_quat, geom_size, geom_pos, body quaternions up to sign, joint
    axes; geoms in a turned <frame> too): its degrees / 180 π, its quaternion products and its
    normalisation, which leaves a vector within 1e-14 of unit alone. With numpy's norm and
    deg2rad, 40–80 % were a bit off, and a geom placed exactly on a plane touched it where
    MuJoCo's did not (test_contact_vs_mujoco's geoms turned in their body)."""
    draw, compiler = ORIENTED[attribute]
    key = attribute.split()[0]
    rng = np.random.default_rng(sum(map(ord, attribute)))
    values = [draw(rng) for _ in range(40)]
    geoms = [f'<geom type="capsule" size="0.05 0.1" {key}="{_numbers(v)}"/>' for v in values]
    if attribute.endswith("frame"):  # composed with the frame's turn by MuJoCo's compiler
        geoms = [f'<frame quat="{_numbers(rng.normal(size=4))}">{geom}</frame>' for geom in geoms]
    bodies = "".join(f'<body pos="0 0 0.1" {key}="{_numbers(v)}"><joint axis="{_numbers(rng.normal(size=3))}"/>'
                     f'<geom size="0.01"/>' for v in values if key != "fromto") + "</body>" * len(values)
    path = _write(tmp_path, f'<body name="b"><freejoint/>{"".join(geoms)}</body>{bodies if key != "fromto" else ""}', compiler)
    m = mujoco.MjModel.from_xml_path(path)
    scene = gs.Scene(show_viewer=False)
    scene.add_entity(gs.morphs.MJCF(file=path))
    scene.build()
    model = scene._rigid_solver.model
    ours = model.geom_link == 0
    assert np.array_equal(_w_up(model.geom_quat[ours]), _w_up(m.geom_quat[m.geom_bodyid == 1]))
    assert np.array_equal(model.geom_size[ours], m.geom_size[m.geom_bodyid == 1])
    assert np.array_equal(model.geom_pos[ours], m.geom_pos[m.geom_bodyid == 1])
    if key != "fromto":
        hinged = model.link_jtype == model.link_jtype[-1]
        assert hinged.sum() == len(values)
        assert np.array_equal(model.link_axis[hinged], m.jnt_axis[1:])
        assert np.array_equal(_w_up(model.link_quat0[hinged]), _w_up(m.body_quat[2:]))


def _w_up(quats):
    """(N, 4) quaternions signed so that w >= 0 (the same turns)."""
    return np.where(quats[:, :1] < 0, -quats, quats)


def _write(tmp_path, body, extra=""):
    path = tmp_path / "robot.xml"
    path.write_text(f"<mujoco>{extra}<worldbody>{body}</worldbody></mujoco>")
    return str(path)


LINK = '<geom type="sphere" size="0.1"/>'


@pytest.mark.parametrize("body, extra, said", [
    (f'<body name="b"><joint name="j" type="cone"/>{LINK}</body>', "", "joint 'j': type expected hinge, slide or ball"),
    (f'<body name="b"><joint name="j" type="ball" actuatorfrcrange="-1 1"/>{LINK}</body>', "",
     "a ball joint's actuatorfrcrange is not supported yet"),
    (f'<body name="b"><joint name="j" type="ball" range="10 40"/>{LINK}</body>', "",
     "a ball joint's range expected (0, largest angle)"),
    (f'<body name="b"><joint name="j" type="ball"/><joint name="k"/>{LINK}</body>', "",
     "a ball joint followed by a hinge or ball joint in one body is refused"),
    (f'<body name="b"><freejoint springdamper="0.2 1"/>{LINK}</body>', "", "a free joint's spring"),
    (f'<body name="b"><joint name="j" springdamper="0.1 0"/>{LINK}</body>', "",
     "springdamper expected two positive values"),
    (f'<body name="b"><joint name="j" stiffness="3" springyield="5"/>{LINK}</body>', "", "a yielding spring"),
    ("", "", "<worldbody> expected at least one <body> or geom, got none"),
    (f'<body name="b"><geom type="sdf" size="0.1 0.2 0.3"/></body>', "", "geom type expected one of"),
    (f'<body name="b"><geom type="ellipsoid" size="0.1 0 0.3"/></body>', "", "ellipsoid size expected 3 positive"),
    (f'<geom type="hfield"/><body name="b">{LINK}</body>', "", "<worldbody> geom 0: height field None is not an"),
    (f'<geom type="sdf"/><body name="b">{LINK}</body>', "", "<worldbody> geom 0: geom type expected one of"),
    (f'<body name="b"><joint name="j"/>{LINK}<geom name="p" type="plane" size="1 1 1"/></body>', "",
     "body 'b' geom p: a plane only in the worldbody or a body welded to it"),
    (f'<body name="b"><body name="c"><joint name="k"/>{LINK}<geom type="plane" size="1 1 1"/></body></body>', "",
     "body 'c' geom 1: a plane only in the worldbody or a body welded to it"),
    (f'<body name="b"><geom type="mesh" mesh="nope"/></body>', "", "mesh 'nope' is not an <asset><mesh>"),
    (f'<body name="b"><joint name="j"/>{LINK}</body>', '<asset><mesh name="m" vertex="0 0 0 1 0 0 0 1 0 0 0"/></asset>',
     "<mesh name='m'>: attribute 'vertex' expected at least four vertices of three numbers, got 11 numbers"),
    (f'<body name="b"><joint name="j"/>{LINK}</body>', '<asset><mesh name="m" vertex="0 0 0 1 0 0 0 1 0 1 1 0"/></asset>',
     "<mesh name='m'>: the convex hull of 4 vertices spans no volume"),
    (f'<body name="b"><joint name="j"/>{LINK}</body>',
     '<asset><mesh name="m" vertex="0 0 0 1 0 0 0 1 0 0 0 1" face="0 1 4"/></asset>',
     "<mesh name='m'>: attribute 'face' expected triangles of vertex indices in [0, 4), got '0 1 4'"),
    (f'<body name="b"><joint name="j"/>{LINK}</body>', '<asset><mesh vertex="0 0 0 1 0 0 0 1 0 0 0 1"/></asset>',
     "a mesh without a file expected a name"),
    (f'<body name="b"><joint name="j"/>{LINK}</body>',
     '<asset><mesh name="m" vertex="0 0 0 1 0 0 0 1 0 0 0 1" face="0 2 1.0"/></asset>',
     "attribute 'face' expected triangles of vertex indices in [0, 4), got '0 2 1.0'"),
    (f'<body name="b"><joint name="j"/>{LINK}</body>',
     '<asset><mesh name="m" vertex="0 0 0 1 0 0 0 1 0 0 0 1" face="0 2 1"/></asset>',
     "<mesh name='m'>: its faces enclose no volume"),
    (f'<body name="b"><joint name="j"/>{LINK}</body>', '<asset><mesh name="m" builtin="sphere" params="3"/></asset>',
     "expected a mesh from a file or from its vertices (attribute 'file' or 'vertex'), got neither (builtin"),
    (f'<body name="b" childclass="x">{LINK}</body>', "", "class 'x' is not a <default> class"),
    (f'<body name="b"><inertial mass="1" quat="1 0 0 0" fullinertia="1 1 1 0 0 0"/>{LINK}</body>', "",
     "fullinertia expected without an orientation"),
    (f'<body name="b"><joint name="j" range="1"/>{LINK}</body>', "", "attribute 'range' expected 2 finite numbers"),
    (f'<body name="b"><body name="c"><joint name="j"/><freejoint/>{LINK}</body></body>', "", "type expected hinge"),
    (f'<body name="b"><joint name="j"/>{LINK}</body>', '<equality><flex flex="f"/></equality>',
     "<equality><flex> is not supported"),
    (f'<body name="b"><joint name="j"/>{LINK}</body>', '<equality><weld body1="b" relpose="0 0 0 1"/></equality>',
     "<equality><weld name=None>: attribute 'relpose' expected 7 finite numbers"),
    (f'<body name="b"><joint name="j"/>{LINK}</body>', '<equality><connect body1="b" body2="c" anchor="0 0 0"/>'
     '</equality>', "<equality><connect name=None>: body2 expected a body of the file, got 'c'"),
    (f'<body name="b"><joint name="j"/>{LINK}<site name="s"/></body>', '<equality><connect site1="s" site2="t"/>'
     '</equality>', "site2 expected a site of the file, got 't'"),
    (f'<body name="b"><joint name="j"/>{LINK}<site name="s"/></body>',
     '<equality><connect site1="s" site2="s"/></equality>', "expected two different bodies, got 'b' twice"),
    (f'<body name="b"><joint name="j"/>{LINK}</body>', '<equality><connect body1="b"/></equality>',
     "attribute 'anchor' is missing"),
    (f'<body name="b"><joint name="j"/>{LINK}<body name="c"><joint name="k"/>{LINK}</body></body>',
     '<equality><joint joint1="j" joint2="k"/><joint joint1="j" polycoef="0.1 0 0 0 0"/></equality>',
     "joint1 'j' expected in one joint equality as joint1, got a second"),
    (f'<body name="b"><joint name="j"/>{LINK}</body>', '<equality><joint joint2="j"/></equality>',
     "joint1 expected a hinge or slide joint of the file, got None"),
    (f'<body name="b"><joint name="j"/>{LINK}</body>', '<equality><weld body1="world"/></equality>',
     "<equality><weld name=None>: expected two different bodies, got 'world' twice"),
    (f'<body name="b"><joint name="j"/>{LINK}<site name="s"/></body>',
     '<equality><connect site1="s" site2="s" body1="b"/></equality>', "expected sites or bodies, got site1/site2 with"),
    (f'<site name="s"/><body name="b"><joint name="j"/>{LINK}<site name="s"/></body>', "",
     "site names expected unique, got 's' twice"),
    (f'<body name="b"><joint name="j"/>{LINK}</body>', '<actuator><position joint="j" forcerange="-1 2"/></actuator>',
     "forcerange expected a symmetric range"),
    (f'<body name="b"><freejoint/><joint type="free" name="f" stiffness="2"/>{LINK}</body>', "",
     "a free joint must be its body's only joint"),
    (f'<body name="b"><joint type="free" name="f" stiffness="2"/>{LINK}</body>', "",
     "a free joint's spring is not supported"),
    (f'<body name="b"><joint name="j" stiffness="-2"/>{LINK}</body>', "", "attribute 'stiffness' expected >= 0"),
    (f'<body name="b"><joint name="j"/>{LINK}<body name="b">{LINK}</body></body>', "",
     "body names expected unique, got repeated names ['b']"),
    (f'<body name="b"><joint name="j"/><geom type="sphere" size="0.1" contype="1.5"/></body>', "",
     "attribute 'contype' expected a non-negative integer"),
    (f'<body name="b"><joint name="j"/><geom type="sphere" size="0.1" condim="2"/></body>', "",
     "attribute 'condim' expected 1, 3, 4 or 6 (as MuJoCo's compiler), got '2'"),
    (f'<body name="b"><joint name="j"/><geom type="sphere" size="0.1" priority="1e3"/></body>', "",
     "attribute 'priority' expected an integer, got '1e3'"),
    (f'<body name="b"><joint name="j"/><geom type="sphere" size="0.1" condim="3.0"/></body>', "",
     "attribute 'condim' expected an integer, got '3.0'"),
    (f'<body name="b"><joint name="j"/><geom type="sphere" size="0.1" solref="0.02 0"/></body>', "",
     "attribute 'solref' expected both numbers > 0 (time constant, damping ratio) or both ≤ 0"),
    (f'<body name="b"><joint name="j" range="-1 1" solreflimit="-800 10"/>{LINK}</body>', "",
     "joint 'j': attribute 'solreflimit' expected both numbers > 0"),
    (f'<body name="b"><joint name="j"/>{LINK}</body>', '<replicate count="0"/>', "<mujoco> holds sections"),
    (f'<body name="b"><joint name="j"/>{LINK}</body>',
     '<tendon><fixed range="0 1"><joint joint="j" coef="1"/><joint joint="j" coef="2"/></fixed></tendon>',
     "<tendon><fixed name=None>: joints expected once each, got ['j'] repeated"),
    (f'<body name="b"><joint name="j"/>{LINK}<body name="c"><joint name="k"/>{LINK}<body name="e"><joint name="l"/>'
     f'{LINK}<body name="f"><joint name="n"/>{LINK}</body></body></body></body>',
     '<tendon><fixed range="0 1">' + "".join(f'<joint joint="{j}" coef="1"/>' for j in "jkln") + '</fixed></tendon>',
     "a limited, held, sprung or rubbing fixed tendon expected 1 to 3 joints (more are not supported yet), got 4"),
    (f'<body name="b"><joint name="j"/>{LINK}</body>', '<tendon><fixed range="0 1"><joint joint="x"/></fixed></tendon>',
     "expected <joint joint coef> children naming hinge or slide joints of the file, got <joint joint='x'>"),
    (f'<replicate count="2.5"><body name="b">{LINK}</body></replicate>', "",
     "<replicate>: attribute 'count' expected a positive integer, got '2.5'"),
    (f'<body name="base">{LINK}</body><replicate count="3"><body name="b"><freejoint/>{LINK}</body></replicate>',
     '<equality><connect body1="b" body2="base" anchor="0 0 0"/></equality>',
     "<equality><connect name=None>: names ['b'] inside a <replicate> and ['base'] outside it"),
    (f'<body name="b"><joint name="j"/><geom type="sphere" size="0.1" solimp="0.9 0.95 0.001 0.5 2 3"/></body>', "",
     "attribute 'solimp' expected 1 or 2 or 3 or 4 or 5 finite numbers"),
    # what MuJoCo 4's compiler refuses (each was loaded: the later of two names won, mass was taken away)
    (f'<body name="b"><joint name="j"/>{LINK}<body name="c"><joint name="j"/>{LINK}</body></body>', "",
     "joint names expected unique, got repeated names ['j']"),
    (f'<body name="b"><joint name="j"/><geom type="mesh" mesh="m"/></body>',
     '<asset><mesh name="m" vertex="0 0 0 1 0 0 0 1 0 0 0 1"/>'
     '<mesh name="m" vertex="0 0 0 2 0 0 0 2 0 0 0 2"/></asset>',
     "<mesh name='m'>: mesh names expected unique, got 'm' twice"),
    (f'<body name="b"><joint name="j"/>{LINK}</body>',
     '<asset><material name="red" rgba="1 0 0 1"/><material name="red"/></asset>',
     "material names expected unique, got 'red' twice"),
    (f'<body name="b"><joint name="j"/><geom type="mesh" mesh="m"/></body>',
     '<asset><mesh name="m" refpos="0.5 0 0" vertex="0 0 0 1 0 0 0 1 0 0 0 1"/></asset>',
     "<mesh name='m'>: attributes ['refpos'] are not supported yet"),
    (f'<body name="b"><joint name="j"/><geom type="sphere" size="0.1" density="-100"/></body>', "",
     "attribute 'density' expected >= 0 on a moving body, got '-100'"),
    (f'<body name="b"><joint name="j"/>{LINK}</body>', '<asset><hfield name="h" nrow="2" ncol="2" size="1 1 0.1 0.1"/>'
     '<hfield name="h" nrow="3" ncol="3" size="1 1 0.1 0.1"/></asset>', "height field names expected unique"),
    (f'<body name="b"><joint name="j" type="ball"/>{LINK}</body>',
     '<tendon><fixed><joint joint="j" coef="1"/></fixed></tendon>',
     "naming hinge or slide joints of the file, got ['j']"),
    (f'<body name="b"><joint name="j"/><inertial pos="0 0 0" mass="1" diaginertia="0.01 0.01 0.03"/></body>', "",
     "<inertial>: inertia expected principal moments with A"),
    (f'<body name="b"><joint name="j"/>{LINK}</body>', '<tendon><fixed><joint joint="typo" coef="1"/></fixed></tendon>',
     "expected <joint joint coef> children naming hinge or slide joints of the file, got ['typo']"),
    (f'<body name="b"><joint name="j"/>{LINK}</body>', '<actuator><motor joint="typo"/></actuator>',
     "<actuator><motor joint='typo'>: joint expected a joint of the file, got 'typo'"),
    (f'<body name="b"><joint name="j" range="1 -1"/>{LINK}</body>', "", "range expected lower < upper, got '1 -1'"),
])
def test_unsupported_or_malformed_files_are_named(f64, tmp_path, body, extra, said):
    scene = gs.Scene()
    with pytest.raises(AssetError, match=f"MJCF '.*robot.xml' \\(entity '.*'\\): .*{_escaped(said)}"):
        scene.add_entity(gs.morphs.MJCF(file=_write(tmp_path, body, extra)))


def test_what_mujoco_reads_as_no_range_or_names_itself_loads(f64, tmp_path):
    """Ranges of 0 0 (MuJoCo's default, "no range" under autolimits: they were refused as lower ≥
    upper), and an unnamed body beside a body named as the name generated for it (refused as a
    repeated name), load as MuJoCo 4 loads them."""
    body = (f'<body><joint name="h" range="0 0" actuatorfrcrange="0 0"/>{LINK}<body name="body0"><joint name="k"/>'
            f'{LINK}</body></body>')
    path = _write(tmp_path, body, '<actuator><motor joint="k" forcerange="0 0"/></actuator>')
    scene = gs.Scene()
    robot = scene.add_entity(gs.morphs.MJCF(file=path))
    scene.build()
    model = mujoco.MjModel.from_xml_path(str(path))
    assert model.jnt_limited.tolist() == [0, 0] and model.jnt_actfrclimited.tolist() == [0, 0]
    lower, upper = robot.get_dofs_limit()
    assert torch.isinf(lower).all() and torch.isinf(upper).all()
    assert (robot.get_dofs_force_range()[1] >= 1e30).all()  # (unbounded)
    assert len({link.name for link in robot.links}) == robot.n_links and "body0" in [l.name for l in robot.links]



def test_what_mujoco_loads_beside_what_it_refuses_loads(f64, tmp_path):
    """A world geom of negative density, a mesh's identity refpos/refquat, and an inertia breaking
    A + B ≥ C under <compiler balanceinertia="true"> (its moments set to their mean), as MuJoCo 4."""
    body = ('<geom type="box" size="1 1 0.1" pos="0 0 -0.1" density="-100"/><body name="b" pos="0 0 1">'
            '<joint name="j"/><inertial pos="0 0 0" mass="2" diaginertia="0.01 0.02 0.05"/>'
            '<geom type="mesh" mesh="m" contype="0" conaffinity="0" mass="0"/></body>')
    extra = ('<compiler balanceinertia="true"/><asset><mesh name="m" refpos="0 0 0" refquat="1 0 0 0" '
             'vertex="0 0 0 0.1 0 0 0 0.1 0 0 0 0.1"/></asset>')
    path = _write(tmp_path, body, extra)
    model = mujoco.MjModel.from_xml_path(str(path))
    scene = gs.Scene()
    robot = scene.add_entity(gs.morphs.MJCF(file=path))
    scene.build()
    (spec,) = [spec for spec in robot._specs if spec.name == "b"]
    np.testing.assert_allclose(spec.inertia, np.diag(model.body_inertia[model.body("b").id]), atol=1e-15)


@pytest.mark.parametrize("depth", [300, 1500])
def test_a_long_chain_of_nested_bodies_loads_or_is_named(f64, tmp_path, depth):
    """300 nested bodies (a rope), which MuJoCo 4 loads, were refused as XML nested too deep; past
    Python's recursion (MuJoCo's parser stops at ~500 elements) the error is named."""
    chain = "".join(f'<body name="b{k}" pos="0 0 -0.01"><joint axis="0 1 0"/><geom size="0.003"/>'
                    for k in range(depth))
    path = _write(tmp_path, f'<body name="top" pos="0 0 5">{chain}{"</body>" * depth}</body>')
    if depth < 500:
        assert gs.Scene().add_entity(gs.morphs.MJCF(file=path)).n_dofs == depth
    else:
        with pytest.raises(AssetError, match="body 'top': its bodies nest too deep to be read"):
            gs.Scene().add_entity(gs.morphs.MJCF(file=path))


def _escaped(text):
    return "".join("\\" + c if c in "()[]<>.*'" else c for c in text)


def test_what_is_ignored_is_said_once(f64, tmp_path, caplog):
    extra = ('<option timestep="0.01"/><tendon><fixed name="t" stiffness="0" armature="0.5"><joint joint="j" coef="1"/>'
             '</fixed></tendon><actuator><motor tendon="t"/></actuator>')
    path = _write(tmp_path, f'<geom type="plane" size="1 1 1"/><body name="b"><joint name="j" margin="0.1"/>{LINK}'
                            f'<geom type="box" size="0.1 0.1 0.1" condim="3" solref="0.02 1"/></body>', extra)
    with caplog.at_level(logging.WARNING, logger="genesis_lite"):
        gs.Scene().add_entity(gs.morphs.MJCF(file=path))
    said = [r.getMessage() for r in caplog.records if "ignored" in r.getMessage()]
    assert len(said) == 1
    for part in ("<option>", "<joint margin>", "<actuator><motor", "<tendon><fixed armature>"):
        assert part in said[0]
    assert "condim" not in said[0] and "solref" not in said[0]  # MuJoCo's defaults: nothing is lost
    assert "stiffness" not in said[0]  # (a tendon's zero spring is MuJoCo's default: nothing is lost)



def test_an_actuator_on_a_tendon_drives_its_joints_as_genesis_approximates_it(f64, tmp_path, caplog):
    """The menagerie Panda's gripper: a position actuator on a fixed tendon of two slide joints.
    Genesis puts its gains and force bound on each of the tendon's joints but one an actuator drives
    directly (here the first, whatever the order in the file); so does genesis_lite, and says so; an
    actuator on an unknown tendon is only named. Where several actuators reach one joint (s1: two
    tendons), the later's gains and the tightest bound act, as for a joint's own actuators (Genesis
    parses none there: s1 would keep no servo)."""
    fingers = "".join(f'<body name="f{k}" pos="{0.1 * k} 0 0"><joint name="s{k}" type="slide" axis="1 0 0"/>{LINK}'
                      f'</body>' for k in range(3))
    extra = ('<tendon><fixed name="split"><joint joint="s1" coef="0.5"/><joint joint="s2" coef="0.5"/></fixed>'
             '<fixed name="whole"><joint joint="s0" coef="1"/><joint joint="s1" coef="1"/></fixed></tendon>'
             '<actuator><position tendon="whole" kp="30" kv="3" forcerange="-5 5"/>'
             '<position joint="s0" kp="7" kv="0.7"/>'
             '<general tendon="split" biastype="affine" gainprm="100" biasprm="0 -100 -10" forcerange="-20 20"/>'
             '<motor tendon="nothing"/></actuator>')
    with caplog.at_level(logging.WARNING, logger="genesis_lite"):
        scene = gs.Scene()
        robot = scene.add_entity(gs.morphs.MJCF(file=_write(tmp_path, f'<body name="base">{LINK}{fingers}</body>',
                                                          extra)))
        scene.build()
    assert robot.get_dofs_kp().tolist() == [7.0, 100.0, 100.0]  # s1: the later of its two tendon actuators
    assert robot.get_dofs_kv().tolist() == [0.7, 10.0, 10.0]
    upper = robot.get_dofs_force_range()[1].tolist()
    assert upper[0] >= 1e30 and upper[1:] == [5.0, 20.0]  # unbounded; the tighter of s1's two; s2's
    said = " ".join(r.getMessage() for r in caplog.records)
    assert "approximated as Genesis does" in said and "['s1', 's2']" in said and "['s1']" in said
    assert "tendon='nothing'> (it drives no fixed tendon" in said

def test_an_open_mesh_weighing_its_hull_is_said(f64, tmp_path, caplog):
    """A body weighed from an open mesh (a tetrahedron missing a face) is named: its mass is its
    convex hull's here, MuJoCo integrates the open surface; a closed one is not named."""
    tetrahedron = '<mesh name="{}" vertex="0 0 0  .1 0 0  0 .1 0  0 0 .1" face="0 2 1  0 1 3  0 3 2{}"/>'
    extra = f'<asset>{tetrahedron.format("open", "")}{tetrahedron.format("closed", "  1 2 3")}</asset>'
    path = _write(tmp_path, '<body name="a"><freejoint/><geom type="mesh" mesh="open"/></body>'
                            '<body name="b" pos="1 0 0"><freejoint/><geom type="mesh" mesh="closed"/></body>', extra)
    with caplog.at_level(logging.WARNING, logger="genesis_lite"):
        gs.Scene().add_entity(gs.morphs.MJCF(file=path))
    said = " ".join(r.getMessage() for r in caplog.records)
    assert "body 'a': an open mesh's own inertia" in said and "body 'b'" not in said


def test_a_hinge_on_the_world_hangs_from_a_static_world_link_and_angles_follow_the_compiler(f64, tmp_path):
    body = (f'<body name="pendulum" pos="0 0 1" euler="0 0 90"><joint name="swing" axis="1 0 0" range="-45 45"/>'
            f'<geom type="capsule" fromto="0 0 0 0 0 -0.5" size="0.02"/></body>')
    for angle, limit in (("degree", np.pi / 4), ("radian", 45.0)):
        path = _write(tmp_path, body, f'<compiler angle="{angle}"/>')
        scene = gs.Scene()
        robot = scene.add_entity(gs.morphs.MJCF(file=path))
        scene.build()
        assert [link.name for link in robot.links] == ["world", "pendulum"] and robot.n_dofs == 1
        assert robot.get_dofs_limit()[1].tolist() == pytest.approx([limit], rel=1e-15)
        quat = robot.get_link("pendulum").get_quat().numpy()
        expected = [np.sqrt(0.5), 0, 0, np.sqrt(0.5)] if angle == "degree" else [np.cos(45), 0, 0, np.sin(45)]
        np.testing.assert_allclose(quat * np.sign(quat[0]), np.array(expected) * np.sign(expected[0]), atol=1e-15)


def test_springdamper_sets_stiffness_and_damping_as_mujocos_compiler(f64, tmp_path):
    """<joint springdamper="tc ζ"> (dm_control's dog): stiffness I / (tc ζ)² and damping 2 I / tc,
    I = n / Σ dof_invweight0 over the joint's dofs at qpos0 (MuJoCo's compiler: a hinge and a slide
    of a chain, a ball joint's three dofs, a default class's, a joint's own stiffness replaced, one
    of class main left as it is); the values and 300 steps as MuJoCo 4's."""
    body = ('<body name="arm" pos="0 0 1"><joint name="hinge" axis="0 1 0" springdamper="0.1 0.7" stiffness="5"/>'
            '<geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"/>'
            '<body name="slider" pos="0.3 0 0" childclass="sd"><joint name="slide" type="slide" axis="1 0 1"/>'
            '<geom type="box" size="0.04 0.03 0.02" pos="0.05 0 0.01"/>'
            '<body name="bob" pos="0.1 0 0"><joint name="ball" type="ball" springdamper="0.05 1.2"/>'
            '<geom type="capsule" fromto="0 0 0 0 0.1 -0.2" size="0.02"/>'
            '<body name="tip" pos="0 0.1 -0.2"><joint name="wrist" class="main" axis="1 0 0" damping="0.3"/>'
            '<geom type="sphere" size="0.03"/></body></body></body></body>')
    extra = ('<default><default class="sd"><joint springdamper="0.2 0.5"/></default></default>'
             '<compiler angle="radian"/>')
    m, d, scene, robot = _pair(_write(tmp_path, body, extra), integrator="euler")
    dofs = [robot.get_joint(m.joint(j).name).dofs_idx_local[0] for j in range(m.njnt)]
    for j in range(m.njnt):  # (MuJoCo keeps a ball's stiffness per joint, its damping per dof)
        assert float(robot.get_dofs_stiffness()[dofs[j]]) == pytest.approx(m.jnt_stiffness[j], rel=1e-12)
    np.testing.assert_allclose(robot.get_dofs_damping().numpy(), m.dof_damping, rtol=1e-12)
    assert m.dof_damping[-1] == 0.3 and m.jnt_stiffness[0] != 5.0  # (the wrist's own; the hinge's replaced)
    d.qvel[:] = np.random.default_rng(3).normal(size=m.nv)
    robot.set_dofs_velocity(torch.tensor(d.qvel))
    assert _lockstep(m, d, scene, robot, 300) < 1e-10


def test_settotalmass_scales_every_body_as_mujocos_compiler(f64, tmp_path, monkeypatch):
    """<compiler settotalmass> (dm_control's cheetah): every body's mass and inertia scaled by one
    factor to that total, as MuJoCo 4's compiler (it warns the attribute is deprecated, into a
    MUJOCO_LOG.TXT of the working directory: the test's own folder): the masses and 200 steps (the
    box sliding on the floor) as MuJoCo's."""
    from tests.test_link_com import BODIES
    monkeypatch.chdir(tmp_path)
    path = _write(tmp_path, BODIES, '<compiler settotalmass="7.5"/>')
    m, d, scene, robot = _pair(path, integrator="euler")
    assert m.body_mass.sum() == pytest.approx(7.5, rel=1e-14)
    for link in robot.links:
        if link.name in {m.body(b).name for b in range(m.nbody)}:
            assert float(link.get_mass()) == pytest.approx(m.body_mass[m.body(link.name).id], rel=1e-14)
    d.qvel[:] = np.random.default_rng(2).normal(size=m.nv) * 0.5
    robot.set_dofs_velocity(torch.tensor(d.qvel))
    assert _lockstep(m, d, scene, robot, 200) < 1e-11


@pytest.mark.parametrize("path", [ARM, REPLICATE, "bodies"])
def test_joint_anchors_and_axes_are_mujocos(f64, tmp_path, path):
    """RigidJoint.get_anchor_pos / get_anchor_axis (Genesis's) equal MuJoCo's xanchor / xaxis at a
    random pose: hinges and slides with anchors off their body origins and refs (arm.xml: a slide's
    anchor stays where its ref puts it), replicated hinges in turned frames, a ball joint (its
    parent side's z) and a free joint (its position, the world's z), in every env."""
    from tests.test_link_com import BODIES
    path = _write(tmp_path, BODIES) if path == "bodies" else path
    m = mujoco.MjModel.from_xml_path(path)
    d = mujoco.MjData(m)
    scene = gs.Scene()
    robot = scene.add_entity(gs.morphs.MJCF(file=path))
    scene.build(n_envs=2)
    rng = np.random.default_rng(0)
    d.qpos[:] = m.qpos0
    for j in range(m.njnt):
        kind, q = int(m.jnt_type[j]), d.qpos[m.jnt_qposadr[j]:]
        if kind in (mujoco.mjtJoint.mjJNT_HINGE.value, mujoco.mjtJoint.mjJNT_SLIDE.value):
            q[0] += rng.normal(0.0, 0.3)
        else:  # a ball's or a free joint's turn
            turn = rng.normal(size=4)
            q[0 if kind == mujoco.mjtJoint.mjJNT_BALL.value else 3:][:4] = turn / np.linalg.norm(turn)
    robot.set_qpos(torch.tensor(np.stack([d.qpos, m.qpos0])))
    mujoco.mj_kinematics(m, d)
    kinds = set()
    names = {m.joint(k).name for k in range(m.njnt)}
    for joint in robot.joints:  # (an unnamed joint: its body's only one)
        j = m.joint(joint.name).id if joint.name in names else int(m.body(joint.link.name).jntadr[0])
        pos, axis = joint.get_anchor_pos(), joint.get_anchor_axis()
        assert pos.shape == axis.shape == (2, 3)
        np.testing.assert_allclose(pos[0].numpy(), d.xanchor[j], atol=1e-14)
        np.testing.assert_allclose(axis[0].numpy(), d.xaxis[j], atol=1e-14)
        kinds.add(joint.type)
    assert kinds >= ({"revolute", "prismatic"} if path == ARM else {"revolute"} if path == REPLICATE
                     else {"revolute", "prismatic", "ball", "free"})
    single = gs.Scene()
    alone = single.add_entity(gs.morphs.MJCF(file=path))
    single.build()
    alone.set_qpos(torch.tensor(d.qpos))
    for joint, twin in zip(alone.joints, robot.joints):  # without envs: (3,), as Genesis's (it gave (1, 3))
        pos, axis = joint.get_anchor_pos(), joint.get_anchor_axis()
        assert pos.shape == axis.shape == (3,)
        assert torch.equal(pos, twin.get_anchor_pos()[0]) and torch.equal(axis, twin.get_anchor_axis()[0])


def test_morph_arguments_are_checked(f64):
    with pytest.raises(InvalidInputError, match=r"MJCF: argument 'file' must be a path \(a string or os.PathLike\)"):
        gs.morphs.MJCF(file=3)
    with pytest.raises(AssetError, match="argument 'file' of gs.morphs.MJCF expected an existing MJCF file"):
        gs.Scene().add_entity(gs.morphs.MJCF(file="no_such.xml"))
    with pytest.raises(InvalidInputError, match="MJCF: argument 'scale' must be one positive number or three equal"):
        gs.morphs.MJCF(file=ARM, scale=(1.0, 2.0, 1.0))
    with pytest.raises(InvalidInputError, match="MJCF: argument 'exclude_ground_plane' must be True or False"):
        gs.morphs.MJCF(file=ARM, exclude_ground_plane="yes")


def test_an_inactive_joint_equality_is_not_loaded(f64, tmp_path, caplog):
    arms = "".join(f'<body name="arm{k}" pos="{0.3 * k} 0 1"><joint name="j{k}" axis="0 1 0"/>'
                   f'<geom type="capsule" fromto="0 0 0 0.2 0 -0.3" size="0.02"/></body>' for k in (1, 2))
    path = _write(tmp_path, f'<body name="frame"><geom type="box" size="0.05 0.05 0.05"/>{arms}</body>',
                  '<equality><joint joint1="j2" joint2="j1" polycoef="0.2 -0.5 0 0 0" active="false"/></equality>')
    with caplog.at_level(logging.WARNING, logger="genesis_lite"):
        m, d, scene, robot = _pair(path)
    assert any("inactive: not loaded" in r.getMessage() for r in caplog.records)
    for _ in range(100):
        mujoco.mj_step(m, d)
        scene.step()
    assert np.abs(robot.get_dofs_velocity().numpy() - d.qvel).max() < 1e-12


@pytest.mark.parametrize("refs", [(0.0, 0.0), (20.0, -35.0)])
def test_joint_equality_follows_polycoef_as_mujoco(f64, tmp_path, refs):
    """Two pendulums hinged on the world's static link, the second held to c0 + c1 · the first;
    with joint refs (degrees) MuJoCo's row relates the positions relative to them, q2 − ref2 =
    c0 + c1 (q1 − ref1), and the bodies start at their file poses with q = ref."""
    arms = "".join(f'<body name="arm{k}" pos="{0.3 * k} 0 1"><joint name="j{k}" axis="0 1 0" damping="0.01" '
                   f'ref="{ref}"/><geom type="capsule" fromto="0 0 0 0.2 0 -0.3" size="0.02"/></body>'
                   for k, ref in zip((1, 2), refs))
    path = _write(tmp_path, f'<body name="frame"><geom type="box" size="0.05 0.05 0.05"/>{arms}</body>',
                  '<equality><joint joint1="j2" joint2="j1" polycoef="0.2 -0.5 0 0 0"/></equality>')
    m, d, scene, robot = _pair(path)
    assert robot.n_dofs == 2
    np.testing.assert_allclose(robot.get_dofs_position().numpy(), np.deg2rad(refs), atol=1e-15)
    worst = _lockstep(m, d, scene, robot, 500)
    q = robot.get_dofs_position().numpy() - np.deg2rad(refs)
    assert abs(q[1] - (0.2 - 0.5 * q[0])) < 0.01 and abs(q[0]) > 0.1  # held while it swings
    assert worst < 1e-11


HELD = ('<body name="a" pos="0 0 1"><joint name="j1" axis="0 1 0" ref="10" damping="0.02"/>'
        '<geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"/><body name="b" pos="0.3 0 0">'
        '<joint name="j2" axis="0 1 0"/><geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"/>'
        '<body name="c" pos="0.3 0 0"><joint name="j3" type="slide" axis="1 0 0"/>'
        '<geom type="box" size="0.05 0.03 0.03"/></body></body></body>')
# j1 held at ref + 0.3 rad (MuJoCo reads no coefficient but c0 without joint2), j3 following j2
HELD_EQUALITIES = ('<equality><joint joint1="j1" polycoef="{}"/>'
                   '<joint joint1="j3" joint2="j2" polycoef="0.05 0.1" solref="0.05 1"/></equality>')


@pytest.mark.parametrize("polycoef", ["0.3 5 1 0 0", "0.3"])
def test_a_joint_equality_without_joint2_holds_the_joint_as_mujoco(f64, tmp_path, polycoef):
    """MuJoCo's joint equality without joint2 holds joint1 at q1 − ref1 = polycoef[0] (a row on
    that one dof, diagA its dof_invweight0): a chain whose first hinge starts 0.3 rad off its held
    angle and swings there, beside MuJoCo 4 for 1 s. A short polycoef keeps MuJoCo's (0, 1, 0, 0,
    0) for the rest."""
    m, d, scene, robot = _pair(_write(tmp_path, HELD, HELD_EQUALITIES.format(polycoef)), integrator="euler")
    worst = _lockstep(m, d, scene, robot, 500)
    assert abs(robot.get_dofs_position()[0].item() - np.deg2rad(10) - 0.3) < 0.01  # held
    assert worst < 1e-11


@pytest.mark.parametrize("what", ["velocity", pytest.param("mass", marks=pytest.mark.slow)])
def test_gradients_through_a_held_joint_match_finite_differences(f64, tmp_path, what):
    """The held chain above for 0.3 s: the gradient of every link's pose w.r.t. the initial
    velocities and the links' masses (through the rows' scale) against central differences."""
    _assert_pose_gradients_converge(_write(tmp_path, HELD, HELD_EQUALITIES.format("0.3")), what, 2.0, 2, "held joint")


def test_meshes_given_by_their_vertices_match_mujoco(f64, tmp_path):
    """<mesh vertex face>: a box given by its corners and an inner point, no faces (MuJoCo's
    compiler takes their convex hull), scaled; an octahedron with its faces. Both dropped on a
    plane, tilted, beside MuJoCo 4 for 2 s (dyadic coordinates: MuJoCo keeps mesh vertices in
    float32; meshes symmetric about their principal axes: MuJoCo re-centres a mesh's frame on them)."""
    corners = " ".join(f"{x} {y} {z}" for x in (-1, 1) for y in (-1, 1) for z in (-1, 1))
    half = np.array([0.125, 0.0625, 0.09375])
    octahedron = " ".join(f"{sign * h * (axis == k)}" for axis, h in enumerate(half) for sign in (1, -1) for k in range(3))
    faces = " ".join(" ".join(map(str, (x, y, z) if (x == 0) ^ (y == 3) ^ (z == 5) else (x, z, y)))
                     for x in (0, 1) for y in (2, 3) for z in (4, 5))  # (outwards: by the octant's sign)
    extra = (f'<option timestep="0.002"/><asset><mesh name="box" vertex="{corners} 0 0.5 0" scale="0.0625 0.125 0.0625"/>'
             f'<mesh name="octahedron" vertex="{octahedron}" face="{faces}"/></asset>')
    body = ('<geom type="plane" size="0 0 1"/><body name="box" pos="0 0 0.3" euler="5 10 0"><freejoint/>'
            '<geom type="mesh" mesh="box"/></body><body name="octahedron" pos="0.4 0 0.3" euler="10 20 30">'
            '<freejoint/><geom type="mesh" mesh="octahedron"/></body>')
    m, d, scene, robot = _pair(_write(tmp_path, body, extra), integrator="euler")
    masses = {link.name: float(link.get_mass()) for link in robot.links}
    assert masses["box"] == m.body_mass[1] == 1000 * 0.125 * 0.25 * 0.125
    assert masses["octahedron"] == pytest.approx(m.body_mass[2], rel=1e-15)
    assert _lockstep(m, d, scene, robot, 1000) < 1e-11
    assert robot.get_qpos()[2].item() == pytest.approx(0.0625, abs=1e-3)  # (the box at rest on a face)


def test_ellipsoids_weigh_and_move_as_mujocos_and_rest_on_their_polytope(f64, tmp_path, caplog):
    """An ellipsoid geom is weighed as the ellipsoid (m = ρ·4/3·π·abc, I = m (b² + c²) / 5...) and
    collides as its inscribed polytope (shapes.ellipsoid_mesh; MuJoCo uses the exact surface), with a
    warning. A pendulum of a tilted ellipsoid bob and a free ellipsoid tumbling in the air move as in
    MuJoCo 4 (the same mass properties: to round-off); an ellipsoid dropped on the floor rests at
    MuJoCo's height, flat and balanced on the tip of an axis (the tips are vertices of the polytope,
    symmetric about the principal planes); three equal semi-axes load a sphere."""
    extra = '<option timestep="0.002" gravity="0 0 -9.81"/>'
    body = ('<body name="arm" pos="0 0 1.5"><joint name="hinge" axis="0 1 0"/>'
            '<geom type="ellipsoid" size="0.05 0.08 0.12" pos="0.2 0.05 -0.1" euler="20 30 40" density="700"/></body>'
            '<body name="tumbler" pos="1 0 2" euler="10 50 -20"><freejoint/>'
            '<geom type="ellipsoid" size="0.03 0.07 0.1" contype="0" conaffinity="0"/></body>')
    m, d, scene, robot = _pair(_write(tmp_path, body, extra), integrator="euler")
    d.qvel[0], d.qvel[4:7] = 2.0, [3.0, -5.0, 8.0]  # (the tumbler spins about all three axes)
    robot.set_dofs_velocity(d.qvel.copy())
    masses = {link.name: float(link.get_mass()) for link in robot.links}
    assert masses["arm"] == pytest.approx(700 * 4 / 3 * np.pi * 0.05 * 0.08 * 0.12, rel=1e-14)
    assert masses["tumbler"] == pytest.approx(m.body_mass[2], rel=1e-14)
    assert _lockstep(m, d, scene, robot, 500) < 1e-10

    for size, euler, height in (("0.1 0.06 0.04", "0 0 0", 0.04), ("0.1 0.06 0.04", "0 90 0", 0.1),
                                ("0.05 0.05 0.12", "0 0 0", 0.12)):  # (flat, and balanced on a tip)
        egg = (f'<geom type="plane" size="0 0 1"/><body name="egg" pos="0 0 {height + 0.05}" euler="{euler}">'
               f'<freejoint/><geom type="ellipsoid" size="{size}"/></body>')
        with caplog.at_level(logging.WARNING, logger="genesis_lite"):
            m, d, scene, robot = _pair(_write(tmp_path, egg, extra), integrator="euler")
        for _ in range(500):
            mujoco.mj_step(m, d)
            scene.step()
        assert d.qpos[2] == pytest.approx(height, abs=5e-4)  # (at rest on that semi-axis, the contact soft)
        # measured 0.06-0.16 mm higher than MuJoCo, whose one contact sinks 0.37 mm: the polytope's
        # vertex and its neighbours make 3-4 contacts sharing the weight, each sinking less
        assert robot.get_qpos()[2].item() == pytest.approx(d.qpos[2], abs=2.5e-4), (size, euler)
    assert any("<geom type='ellipsoid'>: its surface" in r.getMessage() for r in caplog.records)
    along = _write(tmp_path, '<body name="b"><freejoint/><geom type="ellipsoid" size="0.03" fromto="0 0 0 0.2 0 0.2"/>'
                              '</body>')  # (fromto: the third semi-axis half its length, the section round)
    m, scene_along = mujoco.MjModel.from_xml_path(along), gs.Scene()
    link = scene_along.add_entity(gs.morphs.MJCF(file=along)).links[0]
    scene_along.build()
    assert float(link.get_mass()) == pytest.approx(m.body_mass[1], rel=1e-14)
    (spec,) = mjcf.load_mjcf(along)
    np.testing.assert_allclose(spec.com, m.body_ipos[1], atol=1e-15)
    ball = _write(tmp_path, '<body name="b"><freejoint/><geom type="ellipsoid" size="0.1 0.1 0.1"/></body>')
    (link,) = mjcf.load_mjcf(ball)
    assert [geom.type for geom in link.geoms] == ["sphere"] and link.geoms[0].size.tolist() == [0.1]


def test_a_bodys_links_are_one_body_to_contacts(f64, tmp_path):
    """A forearm hinged off its origin, turned after build onto its parent (pairs touching at the
    build pose are filtered anyway): parent and child bodies do not collide (MuJoCo's
    filterparent), though the forearm's link hangs from a massless anchor link."""
    path = _write(tmp_path, '<body name="base"><geom type="box" size="0.05 0.05 0.05" pos="0 0 -0.2"/>'
                            '<body name="upper"><joint name="j1" axis="0 1 0"/><geom type="capsule" '
                            'fromto="0 0 0 0 0 0.3" size="0.03"/><body name="fore" pos="0 0 0.4">'
                            '<joint name="j2" pos="0 0 -0.03" axis="0 1 0"/><geom type="capsule" '
                            'fromto="0.02 0 0 0.25 0 0" size="0.03"/></body></body></body>')
    m, d, scene, robot = _pair(path)
    assert [link.name for link in robot.links] == ["base", "upper", "fore:j2", "fore"]
    d.qpos[:] = [0.0, np.pi / 2]  # the forearm down along the upper arm, 3 cm from its axis
    robot.set_dofs_position(torch.tensor(d.qpos))
    mujoco.mj_step(m, d)
    scene.step()
    assert d.ncon == 0 and len(robot.get_contacts()["position"]) == 0
    assert np.abs(robot.get_dofs_velocity().numpy() - d.qvel).max() < 1e-14


def test_welded_children_and_excluded_bodies_do_not_collide_as_mujoco(f64, tmp_path):
    """MuJoCo's filter by weld group: a hand welded to the forearm is the forearm's body, so it
    never meets the upper arm (the forearm's parent) though it lies in it; <contact><exclude>
    turns the upper arm and a side arm across it off, and without it they touch, in both engines."""
    arm = ('<body name="base"><geom type="box" size="0.05 0.05 0.05" pos="0 0 -0.3"/>'
           '<body name="upper"><joint name="j1" axis="0 1 0"/><geom type="capsule" fromto="0 0 0 0 0 0.3" size="0.03"/>'
           '<body name="fore" pos="0 0 0.3"><joint name="j2" axis="0 1 0"/><geom type="capsule" '
           'fromto="0 0 0 0.1 0 0" size="0.02"/><body name="hand" pos="0.1 0 0"><geom type="box" '
           'size="0.03 0.03 0.03" pos="0.05 0 0"/></body>'
           '<body name="side" pos="0 0.1 0"><joint name="j3" axis="1 0 0"/><geom type="capsule" '
           'fromto="0 0 0 0 0 0.2" size="0.03"/></body></body></body></body>')
    for exclude, expected in (('<contact><exclude body1="upper" body2="side"/></contact>', 0), ("", 1)):
        m, d, scene, robot = _pair(_write(tmp_path, arm, exclude))
        assert [link.name for link in robot.links] == ["base", "upper", "fore", "hand", "side"]
        d.qpos[:] = [0.0, 1.5, 1.0]  # the hand folded onto the upper arm, the side arm across it
        robot.set_dofs_position(torch.tensor(d.qpos))
        mujoco.mj_step(m, d)
        scene.step()
        ours = robot.get_contacts()
        assert d.ncon == len(ours["position"]) == expected
        assert np.abs(robot.get_dofs_velocity().numpy() - d.qvel).max() < 1e-12


def test_sections_merge_and_free_root_joints_and_box_segments_read_as_mujoco(f64, tmp_path):
    """Two <default> and two <worldbody> sections (one from an include), a free root joint's
    damping and armature, a box from a segment (square section, MuJoCo 4): the compiled masses,
    inertias and a fall with drag equal MuJoCo's."""
    (tmp_path / "more.xml").write_text('<mujoco><default><geom density="500"/></default>'
                                       '<worldbody><geom type="plane" size="1 1 1"/></worldbody></mujoco>')
    path = tmp_path / "robot.xml"
    path.write_text('<mujoco><default><joint damping="0.5" armature="0.02"/></default><include file="more.xml"/>'
                    '<option gravity="0 0 -9.81"/><worldbody><body name="b" pos="0 0 1"><joint type="free"/>'
                    '<geom type="box" fromto="0 0 0 0.3 0.1 0" size="0.02 0.05"/>'
                    '<body name="c" pos="0.3 0 0"><joint name="h" axis="0 0 1"/><geom type="sphere" size="0.05"/>'
                    '</body></body></worldbody></mujoco>')
    m, d, scene, robot = _pair(str(path))
    # (the included floor: the static world link, last, massless as MuJoCo's body 0)
    assert [float(link.get_mass()) for link in robot.links] == pytest.approx(np.roll(m.body_mass, -1).tolist(), rel=1e-14)
    assert robot.get_dofs_damping().tolist() == [0.5] * 7 and robot.get_dofs_armature().tolist() == [0.02] * 7
    d.qvel[:] = robot.get_dofs_velocity().numpy()
    d.qvel[6] = 3.0
    robot.set_dofs_velocity(torch.tensor(d.qvel))
    for _ in range(100):
        mujoco.mj_step(m, d)
        scene.step()
    assert np.abs(robot.get_dofs_velocity().numpy() - d.qvel).max() < 1e-12


@pytest.mark.parametrize("case, contacts", [("two_joints", 0), ("static_sibling", 1)])
def test_pair_rules_follow_mujocos_bodies(f64, tmp_path, case, contacts):
    """A body with two hinges folded onto its parent: one body to contacts (its two links), so it
    does not collide with its parent (MuJoCo's filterparent); an arm swung into a stand welded to
    its static root: the stand is the world's to MuJoCo, whose parent filter skips the world, so
    they collide (its group is not the root's)."""
    body = {"two_joints": '<body name="P"><joint name="jp" axis="0 1 0"/><geom type="capsule" fromto="0 0 0 0 0 '
                          '0.3" size="0.03"/><body name="B" pos="0 0 0.3"><joint name="b1" axis="0 1 0"/><joint '
                          'name="b2" axis="1 0 0"/><geom type="capsule" fromto="0.08 0 0 0.3 0 0" size="0.03"/>'
                          '</body></body>',
            "static_sibling": '<body name="stand" pos="0.25 0 0.1"><geom type="box" size="0.05 0.05 0.15"/></body>'
                              '<body name="l1" pos="0 0 0.1"><joint name="j" axis="0 1 0"/><geom type="capsule" '
                              'fromto="0 0 0 0 0 0.3" size="0.02"/></body>'}[case]
    path = _write(tmp_path, f'<body name="base"><geom type="box" size="0.05 0.05 0.05" pos="0 0 -0.3"/>{body}</body>')
    m, d, scene, robot = _pair(path)
    d.qpos[:] = [0.0, 1.6, 0.0] if case == "two_joints" else [1.2]  # folded onto the parent / into the stand
    robot.set_dofs_position(torch.tensor(d.qpos))
    mujoco.mj_step(m, d)
    scene.step()
    assert d.ncon == len(robot.get_contacts()["position"]) == contacts
    assert np.abs(robot.get_dofs_velocity().numpy() - d.qvel).max() < 1e-12


@pytest.mark.parametrize("element", ['<composite type="particle" count="2 2 2" spacing="0.1"><geom size="0.01"/>'
                                     '</composite>', '<frame><composite type="particle" count="2 1 1"/></frame>'])
def test_elements_that_would_add_bodies_or_geoms_unread_are_refused(f64, tmp_path, element):
    path = _write(tmp_path, f'<body name="b"><joint name="j"/>{LINK}{element}</body>')
    with pytest.raises(AssetError, match=r"\['composite'\] not supported"):
        gs.Scene().add_entity(gs.morphs.MJCF(file=path))


def test_partial_arrays_end_as_their_default_classes_as_mujocos(f64, tmp_path):
    """A value of fewer numbers than its default class's replaces only its first ones (an actuator's
    biasprm over <default><general>'s, a geom's solimp); an empty solimp is none: as MuJoCo."""
    path = _write(tmp_path, '<body name="b"><joint name="j" axis="0 1 0"/><geom type="sphere" size="0.1" solimp="0.8"/>'
                            '<geom type="box" size="0.1 0.1 0.1" solimp=""/></body>',
                  '<default><general biastype="affine" biasprm="0 -100 -10"/><geom solimp="0.7 0.8 0.01 0.3 3"/>'
                  '</default><actuator><general joint="j" gainprm="50" biasprm="0 -50"/></actuator>')
    m = mujoco.MjModel.from_xml_path(path)
    scene = gs.Scene()
    robot = scene.add_entity(gs.morphs.MJCF(file=path))
    scene.build()
    assert (float(robot.get_dofs_kp()[0]), float(robot.get_dofs_kv()[0])) == (50.0, 10.0) == tuple(-m.actuator_biasprm[0, 1:3])
    mine = _mujoco_geoms(m, scene, robot)
    np.testing.assert_array_equal(scene.sim.inputs(scene._rigid_solver)["solimp"][0].reshape(-1, 5).numpy(),
                                  m.geom_solimp[mine])


def test_a_replicated_name_is_resolved_against_its_own_kind(f64, tmp_path):
    """A servo on a hinge named like a replicated body drives that hinge, once (MuJoCo resolves a
    joint name against joints only)."""
    path = _write(tmp_path, f'<body name="base"><joint name="arm"/>{LINK}</body>'
                            f'<replicate count="3" offset="0.3 0 0"><body name="arm"><freejoint/>{LINK}</body></replicate>',
                  '<actuator><position name="servo" joint="arm" kp="7"/></actuator>')
    m = mujoco.MjModel.from_xml_path(path)
    scene = gs.Scene()
    robot = scene.add_entity(gs.morphs.MJCF(file=path))
    scene.build()
    kp = robot.get_dofs_kp().numpy()
    assert m.nu == 1 and robot.n_dofs == 1 + 3 * 6 and kp[0] == 7.0 and (kp[1:] != 7.0).all()


def test_replicate_expands_as_mujocos_reader(f64):
    """assets/mjcf/replicate.xml: nested replicas turned and offset, one inside a body and one in a
    frame with a childclass; the links are MuJoCo's bodies (names suffixed as its reader suffixes
    them, poses to round-off), the connect, servos and contact exclusion naming replicated bodies
    are copied per replica (MuJoCo's counts), and 0.5 s with the servos driving match MuJoCo 4."""
    m, d, scene, robot = _pair(REPLICATE, integrator="euler")
    model = scene._rigid_solver.model
    bodies = {m.body(b).name: b for b in range(1, m.nbody)}
    ours = {link.name: k for k, link in enumerate(robot.links) if ":" not in link.name and link.name != "world"}
    assert set(ours) == set(bodies) and "block1_2" in ours and "pendulum09" in ours and "peg3" in ours
    mujoco.mj_forward(m, d)
    for name, k in ours.items():
        np.testing.assert_allclose(robot.links[k].get_pos().numpy(), d.xpos[bodies[name]], atol=1e-14)
        np.testing.assert_allclose(robot.links[k].get_quat().numpy(), d.xquat[bodies[name]], atol=1e-14)
    assert (model.n_body_eq, int((model.dof_kp[robot.dof_start:] == 10.0).sum())) == (m.neq, m.nu) == (6, 10)
    pegs, rack = [ours[f"peg{k}"] + robot.link_start for k in range(4)], ours["rack"] + robot.link_start
    pairs = set(zip(model.geom_link[model.pair_geom1].tolist(), model.geom_link[model.pair_geom2].tolist()))
    assert not pairs & {(a, b) for peg in pegs for a, b in ((rack, peg), (peg, rack))}
    robot.control_dofs_position(np.full(10, 0.4), [robot.get_joint(f"hinge{k:02d}").dof_idx_local for k in range(10)])
    d.ctrl[:] = 0.4
    assert _lockstep(m, d, scene, robot, 250) < 1e-10


def test_frames_place_their_bodies_and_geoms_as_mujoco(f64, tmp_path):
    """Nested <frame>s around the root body, geoms and a body (each turned: euler, axisangle), one
    with a childclass its geoms take: frames and masses as MuJoCo compiles them, 300 steps of the
    hinged arm (a geom of it in a frame: its inertia) to round-off."""
    body = ('<frame pos="0 0 0.2" euler="0 0 30"><body name="base" pos="0.1 0 0">'
            '<geom type="box" size="0.05 0.05 0.05" pos="0 0 -0.3"/>'
            '<frame pos="0 0 0.1" euler="20 0 0" childclass="red">'
            '<geom type="capsule" fromto="0 -0.3 0 0.1 -0.3 0.1" size="0.02"/>'
            '<frame pos="0 0.05 0" axisangle="1 0 0 15"><body name="arm" pos="0 0 0.05">'
            '<joint name="j" axis="0 1 0" pos="0.01 0 0"/><geom type="capsule" fromto="0 0 0 0.2 0 0" size="0.02"/>'
            '<frame pos="0.2 0 0" euler="0 30 0"><geom type="box" size="0.02 0.01 0.03" pos="0 0 0.04"/></frame>'
            '</body></frame></frame></body></frame>')
    m, d, scene, robot = _pair(_write(tmp_path, body, '<default><default class="red"><geom density="700"/></default>'
                                                      '</default>'))
    mujoco.mj_forward(m, d)
    for name in ("base", "arm"):
        body_id, link = m.body(name).id, robot.get_link(name)
        assert float(link.get_mass()) == pytest.approx(m.body_mass[body_id], rel=1e-14)
        np.testing.assert_allclose(link.get_pos().numpy(), d.xpos[body_id], atol=1e-14)
        assert abs(abs(link.get_quat().numpy() @ d.xquat[body_id]) - 1.0) < 1e-14
    worst = 0.0
    for _ in range(300):
        mujoco.mj_step(m, d)
        scene.step()
        worst = max(worst, np.abs(robot.get_dofs_velocity().numpy() - d.qvel).max())
    assert worst < 1e-12


@pytest.mark.parametrize("what", ["targets", "masses", "stiffness"])
def test_gradients_through_an_mjcf_robot_match_finite_differences(f64, what):
    """The crawler (free root, legs at anchors, contacts on its feet only) driven by per-step servo
    targets for 60 steps: the gradient of its final pose w.r.t. the targets, the links' masses and
    joint springs on the legs against central differences (its massless anchor links and contact
    masks in the reverse too)."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.005, requires_grad=True))
    scene.add_entity(gs.morphs.Plane())
    robot = scene.add_entity(gs.morphs.MJCF(file=CRAWLER, pos=(0.0, 0.0, -0.04), exclude_ground_plane=True))
    scene.build()
    steps, legs = 60, list(range(6, 14))
    heavy = [k for k, link in enumerate(robot.links) if float(link.get_mass()) > 0]  # (not the anchor links)
    weights = torch.tensor([0.7, -1.1, 0.4, 0.9, -0.3, 0.5, 0.8], dtype=torch.float64)
    start = {"targets": 0.3 * torch.sin(torch.arange(steps * 8, dtype=torch.float64) * 0.1).reshape(steps, 8),
             "masses": robot.get_links_mass().detach().clone()[heavy],
             "stiffness": torch.linspace(0.5, 2.0, 8, dtype=torch.float64)}[what]

    touching = []

    def loss(x):
        scene.reset()
        if what == "masses":
            robot.set_links_mass(x, links_idx_local=heavy)
        robot.set_dofs_stiffness(x if what == "stiffness" else 0.0, dofs_idx_local=legs)
        for t in range(steps):
            robot.control_dofs_position(x[t] if what == "targets" else start_targets[t], dofs_idx_local=legs)
            scene.step()
            touching.append(len(robot.get_contacts()["position"]))
        return (torch.cat([robot.get_pos(), robot.get_quat()]) * weights).sum()

    start_targets = 0.3 * torch.sin(torch.arange(steps * 8, dtype=torch.float64) * 0.1).reshape(steps, 8)
    loss(start)
    assert max(touching) >= 2  # the feet on the ground
    for seed in range(2):
        assert_converged(directional_errors(loss, start, seed), f"crawler {what}, direction {seed}")


# -- several body trees in one file ---------------------------------------------------------------------
def _trees(cone="pyramidal", requires_grad=False):
    """(MuJoCo model and data with the Euler integrator, our scene, entity) of assets/mjcf/trees.xml;
    the free bodies turn, and MuJoCo 4's implicitfast integrates a turning free body otherwise than
    its Euler integrator (ours: Euler with implicit damping), so the reference is Euler here."""
    return _pair(TREES, cone, integrator="euler", requires_grad=requires_grad)


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_several_trees_are_one_entity_and_match_mujoco(f64, cone):
    """Five root bodies (a static post, a free box, a pendulum and a block on the world, a free ball
    dropped onto the box) are one entity's trees in MuJoCo's body and dof order; 3 s against MuJoCo
    4, the ball landing on the box, both on the floor: equal to round-off at the end (measured
    2.3e-12 pyramidal), and at every step within the solve's tolerance (MuJoCo's 1e-8): a solve
    that stops an iteration sooner in one engine moved the ball's spin by 2.8e-9 for one step
    (pyramidal; elsewhere ≤ 3e-12)."""
    m, d, scene, robot = _trees(cone)
    assert [link.name for link in robot.links] == ["post", "box", "world:pendulum", "pendulum", "tip", "ball",
                                                   "world:slider", "slider", "world"]  # (last: the floor's)
    assert robot.n_dofs == m.nv and robot.n_qs == m.nq and not robot.is_free  # the base: the static post
    assert robot.base_link.name == "post"
    np.testing.assert_allclose(robot.get_qpos().numpy(), d.qpos, atol=1e-15)
    pairs = set()

    def note_pairs():
        contacts = robot.get_contacts()
        pairs.update(tuple(sorted((int(a), int(b)))) for a, b in zip(contacts["link_a"], contacts["link_b"]))

    worst = _lockstep(m, d, scene, robot, 1500, note_pairs)
    ball, box = (robot.get_link(name).idx for name in ("ball", "box"))
    assert (min(ball, box), max(ball, box)) in pairs  # the trees touched each other
    assert worst < 1e-8, worst
    assert _lockstep(m, d, scene, robot, 1) < 1e-10


@pytest.mark.parametrize("self_collision", [True, False])
def test_root_bodies_touching_at_the_start_are_separate_trees(f64, tmp_path, self_collision):
    """A box resting on a post, two root bodies of one file: they are two trees, so neither the
    initial-pose filter nor enable_self_collision=False (Genesis's rules, per root) drops their
    pair; nor does it drop a pendulum hinged on the world swinging into another (each on a static
    link of its own). Against MuJoCo 4 (Euler), 300 steps: the box stays on the post."""
    bodies = ('<body name="post" pos="0 0 0.15"><geom type="box" size="0.05 0.05 0.15"/></body>'
              '<body name="box" pos="0 0 0.349"><freejoint/><geom type="box" size="0.05 0.05 0.05"/></body>'
              '<body name="arm1" pos="-0.3 0.5 0.5"><joint axis="0 1 0"/>'  # raised 45°: falls into arm2
              '<geom type="capsule" fromto="0 0 0 0.212 0 0.212" size="0.03"/></body>'
              '<body name="arm2" pos="-0.02 0.5 0.7"><joint axis="0 1 0"/>'  # hanging
              '<geom type="capsule" fromto="0 0 0 0 0 -0.3" size="0.03"/></body>')
    m, d, scene, robot = _pair(_write(tmp_path, bodies), integrator="euler",
                               enable_self_collision=self_collision)
    assert [link.name for link in robot.links] == ["post", "box", "world", "arm1", "world:arm2", "arm2"]
    arms = {robot.get_link(name).idx for name in ("arm1", "arm2")}
    met = []

    def note_arms():
        contacts = robot.get_contacts()
        met.extend({int(a), int(b)} == arms for a, b in zip(contacts["link_a"], contacts["link_b"]))

    worst = _lockstep(m, d, scene, robot, 300, note_arms)
    arms_met = any(met)
    assert abs(float(robot.get_link("box").get_pos()[2]) - 0.35) < 1e-3
    assert arms_met and worst < 1e-10, worst


def test_the_state_api_reads_every_free_tree(f64):
    """The ball's free joint (local dofs 8-13, qs 9-15): its dof positions are its origin and Euler
    angles, set_dofs_position turns its quaternion, set_qpos refuses a zero quaternion for it and
    control_dofs_position a part of its rotation dofs; set_pos needs a free base (the post is welded). The Jacobian of a
    point on the ball and on the pendulum's tip equals MuJoCo's mj_jac (free dofs: world translations,
    turns about the body's axes)."""
    m, d, scene, robot = _trees()
    assert robot._free_joints == [(0, 0), (8, 9)]
    euler = torch.tensor([0.3, -0.2, 0.5], dtype=torch.float64)
    robot.set_dofs_position(euler, dofs_idx_local=[11, 12, 13])
    np.testing.assert_allclose(robot.get_dofs_position()[11:14].numpy(), euler.numpy(), atol=1e-14)
    box_euler = robot.get_dofs_position()[3:6].clone()
    robot.set_dofs_position(torch.tensor([-0.4, 0.1], dtype=torch.float64), dofs_idx_local=[13, 4])  # one each
    np.testing.assert_allclose(robot.get_dofs_position()[[3, 4, 5, 11, 12, 13]].numpy(),
                               [box_euler[0], 0.1, box_euler[2], 0.3, -0.2, -0.4], atol=1e-14)
    np.testing.assert_allclose(robot.get_dofs_position()[8:11].numpy(), [0.02, 0.01, 0.55], atol=1e-15)
    quat = robot.get_qpos()[12:16].numpy()
    assert abs(np.linalg.norm(quat) - 1.0) < 1e-14 and abs(quat[0] - 1.0) > 1e-3
    with pytest.raises(InvalidInputError, match="non-zero quaternions"):
        robot.set_qpos(torch.zeros(4, dtype=torch.float64), qs_idx_local=[12, 13, 14, 15])
    with pytest.raises(InvalidInputError, match=r"three rotation dofs together .* expected all of \[11, 12, 13\] or none"):
        robot.control_dofs_position(torch.zeros(2, dtype=torch.float64), dofs_idx_local=[7, 12])
    with pytest.raises(InvalidInputError, match="set_pos needs a free base"):
        robot.set_pos((0.0, 0.0, 1.0))
    d.qpos[:] = robot.get_qpos().numpy()
    mujoco.mj_kinematics(m, d)
    mujoco.mj_comPos(m, d)
    for name, point in (("ball", np.array([0.01, -0.02, 0.03])), ("tip", np.array([0.1, 0.0, 0.02]))):
        body = m.body(name).id
        jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
        mujoco.mj_jac(m, d, jacp, jacr, d.xpos[body] + d.xmat[body].reshape(3, 3) @ point, body)
        ours = robot.get_jacobian(robot.get_link(name), torch.tensor(point)).numpy()
        np.testing.assert_allclose(ours, np.vstack([jacp, jacr]), atol=1e-13)


def test_gradients_through_several_trees_match_finite_differences(f64):
    """The ball's initial velocity (6 dofs of the second free joint) → the box's pose after the ball
    has landed on it (0.4 s): through tree-to-tree contact, against central differences."""
    _, _, scene, robot = _trees(requires_grad=True)
    weights = torch.tensor([0.7, -1.1, 0.4, 0.9, -0.3, 0.5, 0.8], dtype=torch.float64)

    def loss(velocity):
        scene.reset()
        robot.set_dofs_velocity(velocity, dofs_idx_local=list(range(8, 14)))
        for _ in range(200):
            scene.step()
        return (robot.get_qpos()[:7] * weights).sum()

    start = torch.tensor([0.1, -0.05, -0.5, 0.3, 0.2, -0.1], dtype=torch.float64)
    for seed in range(2):
        assert_converged(directional_errors(loss, start, seed), f"trees, direction {seed}")


# -- energy ---------------------------------------------------------------------------------------------
def test_energy_matches_mujoco_and_differentiates(f64):
    """get_kinetic_energy / get_potential_energy of the arm (armature, springs with springref, a base
    welded to the world) at random states in a batch of two against MuJoCo 4's energy (mjENBL_ENERGY):
    kinetic equal (½ q̇ᵀ M q̇, armature on M), potential equal but for the welded base's constant
    gravity term, which MuJoCo counts and Genesis (and ours) leave out. Gradients: ∂KE/∂q̇ = M q̇ and
    ∂PE/∂stiffness = ½ (q − springref)², exactly."""
    m = mujoco.MjModel.from_xml_path(ARM)
    m.opt.enableflags |= mujoco.mjtEnableBit.mjENBL_ENERGY
    d = mujoco.MjData(m)
    scene = gs.Scene(sim_options=gs.options.SimOptions(requires_grad=True))
    robot = scene.add_entity(gs.morphs.MJCF(file=ARM))
    scene.build(n_envs=2)
    rng = np.random.default_rng(0)
    qpos = m.qpos0 + rng.uniform(-0.3, 0.3, (2, m.nq)) * np.array([1.0, 1.0, 0.1, 1.0])
    qvel = torch.tensor(rng.uniform(-1.0, 1.0, (2, m.nv)), requires_grad=True)
    stiffness = torch.tensor(rng.uniform(1.0, 5.0, (2, m.nv)), requires_grad=True)
    robot.set_qpos(torch.tensor(qpos))
    robot.set_dofs_velocity(qvel)
    robot.set_dofs_stiffness(stiffness)
    kinetic, potential = robot.get_kinetic_energy(), robot.get_potential_energy()
    assert kinetic.shape == potential.shape == (2,)
    torch.testing.assert_close(robot.get_total_energy(), kinetic + potential, rtol=0, atol=0)
    for e in range(2):
        m.jnt_stiffness[:] = stiffness[e].detach().numpy()
        d.qpos[:], d.qvel[:] = qpos[e], qvel[e].detach().numpy()
        mujoco.mj_forward(m, d)
        welded = -sum(m.body_mass[b] * m.opt.gravity @ d.xipos[b] for b in range(1, m.nbody) if m.body_weldid[b] == 0)
        assert abs(float(kinetic[e]) - d.energy[1]) < 1e-14
        assert abs(float(potential[e]) - (d.energy[0] - welded)) < 1e-13
    (kinetic.sum() + potential.sum()).backward()
    mass = robot.get_mass_mat().detach()
    torch.testing.assert_close(qvel.grad, (mass @ qvel.detach()[..., None])[..., 0], rtol=1e-13, atol=1e-15)
    rest = torch.tensor(m.qpos_spring)
    torch.testing.assert_close(stiffness.grad, 0.5 * (torch.tensor(qpos) - rest) ** 2, rtol=1e-13, atol=1e-15)


def test_a_unit_quaternion_keeps_its_bits_as_in_mujoco(f64, tmp_path):
    """A free joint's quaternion within 1e-15 of unit length is used as it is, not divided by its
    norm (MuJoCo's mju_normalize4): a cylinder lying nearly flat on the plane (tilt 5e-7 rad), whose
    plane contacts MuJoCo's formula takes from the frame with a 1/tilt gain, gets MuJoCo's depths to
    round-off (measured: to the bit); divided by a norm of 1 − 1.1e-16 they moved by 4e-11 m and the
    next velocity by 4.5e-9."""
    path = tmp_path / "puck.xml"
    path.write_text('<mujoco><worldbody><geom type="plane" size="5 5 .1"/><body name="puck" pos="0 0 0.2">'
                    '<freejoint/><geom type="cylinder" size="0.05 0.02"/></body></worldbody></mujoco>')
    qpos = np.array([0.3, 0.18, 0.016758054649733983, 0.9999999999999677, 2.404238666617504e-11,
                     -2.539800566832556e-07, -6.589691763852792e-13])
    assert 0 < abs(np.linalg.norm(qpos[3:]) - 1.0) < 1e-15
    m, d, scene, robot = _pair(path, integrator="euler")
    d.qpos[:] = qpos
    mujoco.mj_step(m, d)
    robot.set_qpos(torch.tensor(qpos))
    scene.step()
    ours = sorted(robot.get_contacts()["penetration"].tolist())
    theirs = sorted(-c.dist for c in d.contact[:d.ncon])
    # (a bound, not bit equality, which would rest on two compilers' rounding: the division moved them 4e-11)
    assert len(ours) == len(theirs) and np.abs(np.subtract(ours, theirs)).max() < 1e-15
    assert np.abs(robot.get_dofs_velocity().numpy() - d.qvel).max() < 1e-15


def test_dofs_acc_is_mujocos_qacc_and_the_step_integrates_it(f64):
    """get_dofs_acc (Genesis's) over 600 steps of the trees (a ball landing on a box, the joint
    damping set to 0 on both sides: MuJoCo's qacc leaves its Euler integrator's implicit damping
    out) equals MuJoCo's qacc; with damping back, the velocity the step leaves is q̇ + h·acc. Zeros
    before the first step and after a reset, as get_dofs_force."""
    m, d, scene, robot = _trees()
    assert not robot.get_dofs_acc().any()
    m.dof_damping[:] = 0.0
    robot.set_dofs_damping(0.0)
    worst, scale = 0.0, 0.0
    for _ in range(600):
        mujoco.mj_step(m, d)
        scene.step()
        worst = max(worst, np.abs(robot.get_dofs_acc().numpy() - d.qacc).max())
        scale = max(scale, np.abs(d.qacc).max())
    assert worst < 1e-8 * scale, (worst, scale)
    scene.reset()
    assert not robot.get_dofs_acc().any()
    robot.set_dofs_damping(torch.full((robot.n_dofs,), 0.5, dtype=torch.float64))
    robot.set_dofs_velocity(torch.linspace(-1.0, 1.0, robot.n_dofs, dtype=torch.float64))
    before = robot.get_dofs_velocity().clone()
    scene.step()
    torch.testing.assert_close(robot.get_dofs_velocity(), before + m.opt.timestep * robot.get_dofs_acc(),
                               rtol=0, atol=1e-14)


def test_a_free_joints_friction_loss_is_read_as_mujoco(f64, tmp_path):
    """`<joint type="free" frictionloss>` puts a friction-loss row on each of the six dofs, as
    MuJoCo's: a tilted box thrown spinning onto the plane, 500 steps, equal to MuJoCo 4 (Euler)."""
    path = tmp_path / "box.xml"
    path.write_text('<mujoco><option timestep="0.002"/><worldbody><geom type="plane" size="5 5 .1"/>'
                    '<body name="box" pos="0 0 0.5" euler="10 20 30"><joint type="free" frictionloss="0.3"/>'
                    '<geom type="box" size="0.1 0.08 0.05"/></body></worldbody></mujoco>')
    m, d, scene, robot = _pair(path, integrator="euler")
    assert robot.get_dofs_frictionloss().tolist() == [0.3] * 6
    d.qvel[:] = [1.0, 0.5, 2.0, 3.0, -2.0, 1.0]
    robot.set_dofs_velocity(torch.tensor(d.qvel.copy()))
    worst = _lockstep(m, d, scene, robot, 500)
    assert worst < 1e-12, worst


GRAVCOMP_BODIES = (
    # a hinge, a slide and a ball joint in a chain, each body compensated differently (above 1: lifted), and
    # two free bodies, one lifted beyond its weight and one left to fall
    '<body name="arm" pos="0 0 1" gravcomp="0.4"><joint name="hinge" axis="0 1 0" damping="0.05"/>'
    '<geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"/>'
    '<body name="slider" pos="0.3 0 0" gravcomp="1"><joint name="slide" type="slide" axis="1 0 1"/>'
    '<geom type="box" size="0.04 0.03 0.02" pos="0.05 0 0.01"/>'
    '<body name="bob" pos="0.1 0 0" gravcomp="1.7"><joint name="ball" type="ball"/>'
    '<geom type="capsule" fromto="0 0 0 0 0.1 -0.2" size="0.02"/></body></body></body>'
    '<body name="float" pos="1 0 1" gravcomp="1.2"><freejoint/><geom type="box" size="0.1 0.05 0.02"/></body>'
    '<body name="fall" pos="-1 0 1"><freejoint/><geom type="box" size="0.1 0.05 0.02"/></body>')


def test_body_gravcomp_lifts_its_share_of_the_weight_as_mujocos(f64, tmp_path):
    """MJCF <body gravcomp>: MuJoCo's passive force −gravcomp·m·g at the body's centre of mass."""
    m, d, scene, robot = _pair(_write(tmp_path, GRAVCOMP_BODIES), integrator="euler")
    assert m.body_gravcomp.tolist() == [0.0, 0.4, 1.0, 1.7, 1.2, 0.0]
    rng = np.random.default_rng(5)
    d.qpos[:] = m.qpos0 + np.concatenate([rng.uniform(-0.5, 0.5, 2), np.zeros(m.nq - 2)])
    d.qvel[:] = rng.normal(size=m.nv) * 0.5
    robot.set_qpos(torch.tensor(d.qpos))
    robot.set_dofs_velocity(torch.tensor(d.qvel))
    start = {body: (d.qpos[m.jnt_qposadr[m.body_jntadr[m.body(body).id]] + 2],
                    d.qvel[m.jnt_dofadr[m.body_jntadr[m.body(body).id]] + 2]) for body in ("float", "fall")}
    n, h = 300, m.opt.timestep
    assert _lockstep(m, d, scene, robot, n) < 1e-11
    for body, weight_left in (("float", 1.0 - 1.2), ("fall", 1.0)):  # semi-implicit Euler's free flight
        z0, vz0 = start[body]
        expected = z0 + n * h * vz0 - weight_left * 9.81 * h * h * n * (n + 1) / 2
        assert float(robot.get_link(body).get_pos()[2]) == pytest.approx(expected, abs=1e-12)


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_gravcomp_bodies_in_contact_move_as_mujocos(f64, tmp_path, cone):
    """A compensated box sliding and spinning on the floor (lighter on it: less friction; it rocks on
    its edges, then rests) and a compensated pendulum swinging onto it, 400 steps: MuJoCo's
    trajectory (measured 7e-15)."""
    body = ('<geom type="plane" size="5 5 0.1"/>'
            '<body name="box" pos="0 0 0.05" gravcomp="0.6"><freejoint/><geom type="box" size="0.1 0.05 0.05" '
            'friction="0.5"/></body>'
            '<body name="arm" pos="0.35 0 0.3" gravcomp="0.3"><joint type="hinge" axis="0 1 0"/>'
            '<geom type="capsule" fromto="0 0 0 0.3 0 -0.2" size="0.03"/></body>')
    m, d, scene, robot = _pair(_write(tmp_path, body), cone=cone, integrator="euler")
    d.qvel[:] = [0.8, 0.3, 0.0, 0.0, 0.0, 1.5, 0.0]
    robot.set_dofs_velocity(torch.tensor(d.qvel))
    contacts = []
    assert _lockstep(m, d, scene, robot, 400, after_step=lambda: contacts.append(d.ncon)) < 1e-12
    assert sum(n > 0 for n in contacts) > 300 and contacts[-1] == 5  # (rocking, then at rest, the arm on the box)


@pytest.mark.parametrize("what", ["masses", "gravity", "velocity"])
def test_gradients_through_gravity_compensation_match_finite_differences(f64, tmp_path, what):
    """The bodies above (each compensated differently, a ball joint and free bodies among them), 150
    steps: the gradient of their final poses w.r.t. the links' masses, gravity and the initial
    velocities against central differences (the compensation's force scales with both), and a
    repeated rollout's gradient keeps its bits."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.004, requires_grad=True))
    robot = scene.add_entity(gs.morphs.MJCF(file=_write(tmp_path, GRAVCOMP_BODIES)))
    scene.build()
    heavy = [k for k, link in enumerate(robot.links) if float(link.get_mass()) > 0]
    velocity = torch.tensor(np.random.default_rng(2).normal(size=robot.n_dofs) * 0.5)
    gravity = torch.tensor([0.3, -0.2, -9.81], dtype=torch.float64)
    start = {"masses": robot.get_links_mass().detach().clone()[heavy], "gravity": gravity, "velocity": velocity}[what]

    def set_input(x):
        robot.set_dofs_velocity(x if what == "velocity" else velocity)
        if what == "masses":
            robot.set_links_mass(x, links_idx_local=heavy)
        scene.set_gravity(x if what == "gravity" else gravity)

    weights = torch.tensor(np.random.default_rng(3).normal(size=(robot.n_links, 7)))
    checked_gradient(pose_loss(scene, robot, weights, 150, set_input), start, f"gravity compensation, {what}")


ACC_BODIES = ('<geom type="plane" size="5 5 0.1"/>'
              '<body name="arm" pos="0 0 1"><joint name="hinge" axis="0 1 0"/>'
              '<geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"/>'
              '<body name="slider" pos="0.3 0 0"><joint name="slide" type="slide" axis="1 0 1"/>'
              '<geom type="box" size="0.04 0.03 0.02" pos="0.05 0 0.01"/>'
              '<body name="bob" pos="0.1 0 0"><joint name="ball" type="ball"/>'
              '<geom type="capsule" fromto="0 0 0 0 0.1 -0.2" size="0.02"/></body></body></body>'
              '<body name="box" pos="1 0 0.06"><freejoint/><geom type="box" size="0.1 0.05 0.05" pos="0.02 0 0"/></body>')


def test_links_acc_is_each_origins_acceleration_as_mujocos(f64, tmp_path):
    """get_links_acc: the classical linear acceleration of each link origin in the last step (its start
    state, the acceleration it integrated), gravity out, and get_links_acc_ang its angular acceleration:
    MuJoCo 4's mj_objectAcceleration of the body frame (after mj_rnePostConstraint; plus gravity), for a hinge, slide and ball chain swinging and a
    box (its centre of mass off its origin) landing and spinning on the floor, 200 steps, read after
    the link poses and the mass matrix at the new state were; zeros before the first step and after
    a reset; a box at rest reads zero. (The state's integrated acceleration: MuJoCo's where no joint
    is damped, as here; damping makes ours the implicitly damped one, as get_dofs_acc's.)"""
    m, d, scene, robot = _pair(_write(tmp_path, ACC_BODIES), integrator="euler")
    assert torch.equal(robot.get_links_acc(), torch.zeros(robot.n_links, 3, dtype=torch.float64))
    d.qvel[:] = np.random.default_rng(1).normal(size=m.nv)
    robot.set_dofs_velocity(torch.tensor(d.qvel))
    names, worst, touching = ("arm", "slider", "bob", "box"), 0.0, 0
    for _ in range(200):
        mujoco.mj_forward(m, d)
        mujoco.mj_rnePostConstraint(m, d)
        expected = []
        for name in names:
            acc = np.zeros(6)
            mujoco.mj_objectAcceleration(m, d, mujoco.mjtObj.mjOBJ_XBODY, m.body(name).id, acc, 0)
            expected.append(np.concatenate([acc[3:] + m.opt.gravity, acc[:3]]))
        touching += d.ncon > 0
        mujoco.mj_step(m, d)
        scene.step()
        robot.get_links_pos(), robot.get_mass_mat()  # (readouts at the new state leave the last step's be)
        links = [robot.get_link(name).idx_local for name in names]
        ours = torch.cat([robot.get_links_acc(links_idx_local=links), robot.get_links_acc_ang(links)], -1).numpy()
        worst = max(worst, np.abs(ours - np.array(expected)).max())
    print(f"\nget_links_acc and get_links_acc_ang against MuJoCo: {worst:.1e} (m/s², rad/s²) at worst")
    assert worst < 1e-9 and touching > 100
    scene.reset()
    assert torch.equal(robot.get_links_acc(), torch.zeros(robot.n_links, 3, dtype=torch.float64))
    for _ in range(300):  # (the box comes to rest on the floor)
        scene.step()
    assert float(robot.get_links_acc(links_idx_local=[robot.get_link("box").idx_local]).abs().max()) < 1e-6


def _compiled_both_ways(path):
    """(MjModel, MjData at qpos0, MuJoCo's mass matrix there, our entity built from the file alone,
    collisions off, without Genesis's default armature: MuJoCo's none)."""
    m = mujoco.MjModel.from_xml_path(path)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    mass = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, mass)
    scene = gs.Scene(rigid_options=gs.options.RigidOptions(enable_collision=False))
    robot = scene.add_entity(gs.morphs.MJCF(file=path, default_armature=None))
    scene.build()
    return m, d, mass, robot


@pytest.mark.parametrize("tilt", [1e-6, 1.01e-7, 1e-7, 5e-8])
def test_a_zaxis_next_to_minus_z_turns_as_mujocos(f64, tmp_path, tilt):
    """A frame whose zaxis lies within 1.4e-6 of −z was turned half a turn about x, where MuJoCo's
    compiler turns one more than 1e-7 off it about the axis z × n (independent probe, 2026-12-02: a
    pendulum's mass matrix 5× MuJoCo's, its trajectory apart at once): the link poses at qpos0
    equal MuJoCo's xquat on both sides of its threshold, for bodies, geoms and fromto capsules."""
    body = (f'<body name="a"><joint type="hinge" axis="0 1 0"/>{LINK}'
            f'<body name="b" pos="0.2 0 0" zaxis="{tilt!r} 0 -1"><joint type="hinge" axis="1 0 0"/>'
            f'<geom type="box" size="0.05 0.02 0.01" pos="0.1 0 0" zaxis="0 {tilt!r} -1"/>'
            f'<geom type="capsule" size="0.01" fromto="0 0 0 {tilt!r} 0 -0.3"/></body></body>')
    m, d, mass, robot = _compiled_both_ways(_write(tmp_path, body))
    for name in ("a", "b"):  # (a root hinged on the world hangs from a static link of its own)
        quat = robot.get_link(name).get_quat().numpy()
        np.testing.assert_allclose(quat * np.sign(quat @ d.xquat[m.body(name).id]), d.xquat[m.body(name).id],
                                   atol=1e-15)
    # the box's and the capsule's frames in their body's, MuJoCo's to round-off (a fromto's z from `to` to `from`)
    np.testing.assert_allclose(robot._solver.model.geom_quat[robot.geom_start + 1: robot.geom_start + 3],
                               m.geom_quat[1:3], rtol=0, atol=3e-16)
    np.testing.assert_allclose(robot.get_mass_mat().numpy(), mass, atol=1e-14)


@pytest.mark.parametrize("case", ["joint", "ball", "actuatorfrcrange", "forcerange", "ctrlrange", "tendon"])
def test_a_range_without_its_flag_under_autolimits_false_is_refused_as_mujoco_refuses_it(f64, tmp_path, case):
    """<compiler autolimits="false">: a range given without its limited flag made the limit vanish
    silently (independent probe: a joint with range ±0.2 and force bound 0.5 reached 235 rad); MuJoCo
    4's compiler refuses the file, and so do we, naming the element and attribute. With the flag
    given, both load it."""
    joint = {"joint": '<joint name="j" range="-0.2 0.2"/>', "ball": '<joint name="j" type="ball" range="0 0.5"/>',
             "actuatorfrcrange": '<joint name="j" actuatorfrcrange="-0.5 0.5"/>'}.get(case, '<joint name="j"/>')
    flagged = {"joint": ' limited="true"', "ball": ' limited="true"', "actuatorfrcrange": ' actuatorfrclimited="true"'}
    extra = {"forcerange": '<actuator><motor joint="j" forcerange="-1 1"{}/></actuator>',
             "ctrlrange": '<actuator><motor joint="j" ctrlrange="-1 1"{}/></actuator>',
             "tendon": '<tendon><fixed name="t" range="-0.1 0.1"{}><joint joint="j" coef="1"/></fixed></tendon>'}
    flag = {"forcerange": ' forcelimited="true"', "ctrlrange": ' ctrllimited="true"', "tendon": ' limited="true"'}
    key = {"joint": "range", "ball": "range", "tendon": "range"}.get(case, case)
    for given in (False, True):
        body = f'<body name="b">{joint.replace("/>", flagged[case] + "/>") if given and case in flagged else joint}' \
               f'{LINK}</body>'
        after = extra[case].format(flag[case] if given else "") if case in extra else ""
        path = tmp_path / f"{case}_{given}.xml"
        path.write_text(f'<mujoco><compiler autolimits="false"/><worldbody>{body}</worldbody>{after}</mujoco>')
        if given:
            mujoco.MjModel.from_xml_path(str(path))
            mjcf.load_mjcf(str(path))
            continue
        with pytest.raises(ValueError, match="limited"):
            mujoco.MjModel.from_xml_path(str(path))
        with pytest.raises(gs.AssetError, match=f"'{key}' given without '.*limited' under <compiler "
                                                f"autolimits=\"false\">, as MuJoCo's compiler refuses it"):
            mjcf.load_mjcf(str(path))


def test_under_autolimits_false_a_zero_range_loads_and_an_unread_actuator_s_range_is_refused(f64, tmp_path):
    """Beside the test above: MuJoCo refuses a range other than (0, 0) only, and checks the control
    range of an actuator genesis_lite does not read too (one on a site), but for a damper's, whose
    control its shortcut limits (a review found the first two otherwise)."""
    cases = (('<joint name="j" range="0 0"/>', "", None),
             ('<joint name="j"/>', '<actuator><damper joint="j" kv="1" ctrlrange="0 1"/></actuator>', None),
             ('<joint name="j"/>', '<actuator><motor site="s" ctrlrange="-1 1"/></actuator>', "ctrlrange"))
    for joint, actuators, refused in cases:
        path = _write(tmp_path, f'<body name="b">{joint}<site name="s"/>{LINK}</body>',
                      f'<compiler autolimits="false"/>{actuators}')
        if refused is None:
            mujoco.MjModel.from_xml_path(path)
            mjcf.load_mjcf(path)
            continue
        with pytest.raises(ValueError, match="limited"):
            mujoco.MjModel.from_xml_path(path)
        with pytest.raises(gs.AssetError, match=f"<actuator><motor site='s'>: '{refused}' given without"):
            mjcf.load_mjcf(path)


def test_a_primitive_fitted_to_a_mesh_is_refused(f64, tmp_path):
    """MuJoCo fits a primitive geom with a ``mesh`` attribute to that mesh (its size, position and
    mass from the mesh); it was read as the size given, silently (independent probe: a body of
    4.19 kg where MuJoCo's weighs 0.565), or without a size refused for its size."""
    (tmp_path / "w.obj").write_text("v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0 0 0.1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    for geom in ('<geom type="sphere" size="0.1" mesh="w"/>', '<geom type="box" mesh="w"/>'):
        path = _write(tmp_path, f'<body name="a"><joint/>{geom}</body>', '<asset><mesh name="w" file="w.obj"/></asset>')
        mujoco.MjModel.from_xml_path(path)  # (MuJoCo loads it)
        with pytest.raises(gs.AssetError, match=r"body 'a' geom 0: a (sphere|box) fitted to mesh 'w' \(MuJoCo's "
                                                r"fit-to-mesh\) is not supported yet"):
            mjcf.load_mjcf(path)


def test_inertiafromgeom_true_keeps_the_inertial_of_a_body_without_geoms(f64, tmp_path):
    """<compiler inertiafromgeom="true">: a body's geoms override its <inertial>, but MuJoCo 4 keeps
    the <inertial> of a body without geoms (its documentation says "true" overrides it; measured);
    that body was massless here (independent probe: 1 s apart by 0.4 rad). The masses and the mass
    matrix equal MuJoCo's."""
    body = ('<body name="a"><joint axis="0 1 0"/><inertial pos="0.1 0 0" mass="0.4" diaginertia="1e-3 2e-3 3e-3"/>'
            '<geom type="box" size="0.1 0.1 0.1" density="0"/>'  # (a geom of no mass: as none, MuJoCo's)
            '<body name="b" pos="0.2 0 0"><joint axis="0 1 0"/><inertial pos="0 0 0" mass="5" diaginertia="1 1 1"/>'
            f'{LINK}</body></body>')
    m, _, mass, robot = _compiled_both_ways(_write(tmp_path, body, '<compiler inertiafromgeom="true"/>'))
    assert [float(robot.get_link(name).get_mass()) for name in ("a", "b")] == pytest.approx(m.body_mass[1:], abs=1e-15)
    np.testing.assert_allclose(robot.get_mass_mat().numpy(), mass, atol=1e-14)


def test_actuators_over_defaults_of_other_actuator_types_are_named(f64, tmp_path, caplog):
    """MuJoCo keeps one actuator default a class, which each actuator type's element writes over; here
    each type reads its own defaults and <general>'s, so an actuator of a class holding defaults of
    other types may get other gains than MuJoCo's (independent probe: a <position> without kp under
    a <general> servo default, kp 1 here, 20 in MuJoCo): the load's warning names it; one of a class
    with its own type's defaults alone is not named."""
    extra = ('<default><default class="g"><general gainprm="20" biastype="affine" biasprm="0 -20 -3"/></default>'
             '<default class="k"><position kp="50" kv="4"/></default>'
             '<default class="own"><position kp="7"/></default></default>'
             '<actuator><position name="p1" class="g" joint="j1"/><general name="g2" class="k" joint="j2"/>'
             '<position name="p3" class="own" joint="j3"/></actuator>')
    body = ''.join(f'<body name="b{k}" pos="{k} 0 0"><joint name="j{k}" axis="0 1 0"/>{LINK}</body>' for k in (1, 2, 3))
    with warns(caplog, "defaults of other actuator types") as said:
        mjcf.load_mjcf(_write(tmp_path, body, extra))
    assert "<actuator><position name='p1'>: the defaults of other actuator types in its class 'g' (<general>" \
        in said[0] and "<actuator><general name='g2'>: the defaults of other actuator types in its class 'k' " \
        "(<position>" in said[0]
    assert "name='p3'" not in said[0]
