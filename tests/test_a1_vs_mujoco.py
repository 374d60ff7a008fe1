"""pybullet_data's a1 quadruped under PD control on a plane, step for step against MuJoCo.

The same URDF is loaded by both (MuJoCo through tests.contact_scenes.a1_mujoco: free base, a
plane, position actuators of the same gains on the twelve leg joints, the URDF's effort limits as
their force range). The PD targets move: a small sinusoid per joint on the standing pose, so the
base sways, the feet press, slide and lift (the contact count changes between 0 and 4 during the
run), and the solve is never a trivial rest. Before every step our state is set to MuJoCo's
(qpos, qvel: same layout, a free base's quaternion (w, x, y, z) and world linear / body angular
velocity, then the leg joints in URDF order) and MuJoCo's warm start is cleared, as setting our
state clears ours (each step then starts its solve from the state alone, qacc_smooth or zero,
on both sides); both step once; then over 1 s of steps:

- qvel and qpos after the step agree to ≤ 1e-7 (the issue's bar);
- the contact list of the step equals MuJoCo's ``d.contact``: count, geom pairs (our global
  geom indices are MuJoCo's: the plane first, then the URDF's collision geoms in the same order,
  fixed links fused into their parents on both sides), positions to 1e-12 m and world contact
  forces (MuJoCo's ``mj_contactForce``, up to ~200 N here) to 1e-8 N, in MuJoCo's order (by body
  pair: when a calf box (plane–box) touches along with the feet (plane–sphere), as it does for
  a moment with the pyramidal cone, its contacts come between the feet's).

Measured (both cones): qvel within 1e-13, qpos 1e-15, contact positions 1e-15 m, forces 2e-12 N;
0 to 4 contacts, the count changing 30-45 times in the second. Without clearing MuJoCo's warm
start the elliptic cone differs by up to 2e-5: its Newton solve stops at tolerance 1e-8 on the
cost, which leaves qvel that far from the converged solution, and where it stops depends on
where it starts (the pyramidal cone's solve ends exactly, whatever its start).

Nothing is excluded in MuJoCo. Our a1 collides its cylinder self-pairs too (the convex
collider) but skips pairs touching at the initial pose (``enable_neutral_collision`` False);
MuJoCo keeps every pair of non-adjacent bodies. In this
motion MuJoCo finds no contact but plane ones (the feet, and for a moment a calf box; its contact
list, compared above, would show any self-contact), so the difference does not matter here.
No joint comes within 0.1 rad of its limit either (checked), so neither side makes limit rows.
"""
import mujoco
import numpy as np
import pytest
import torch

import genesis_lite as gs
from tests.conftest import pybullet
from tests.contact_scenes import a1_mujoco

STAND = np.tile([0.0, 0.8, -1.5], 4)  # hip, thigh, calf of each leg (rad)
AMPLITUDE = np.tile([0.12, 0.25, 0.3], 4)  # rad
FREQUENCY = np.array([1.0, 1.3, 1.7, 1.1, 1.4, 1.9, 0.9, 1.2, 1.6, 1.05, 1.5, 1.8]) * 1.5  # Hz
PHASE = np.linspace(0.0, 2 * np.pi, 12, endpoint=False)
Z, KP, KV, DT, STEPS = 0.305, 100.0, 2.0, 0.002, 500  # m, N·m/rad, N·m·s/rad, s, 1 s


def _targets(t):
    """The 12 PD targets (rad) at time t (s)."""
    return STAND + AMPLITUDE * np.sin(2 * np.pi * FREQUENCY * t + PHASE)


def _build_ours(path, cone, ground=None):
    """(scene, robot, leg dof indices): a plane (or the morph ``ground``) and the URDF's a1 with a
    free base at height Z, MuJoCo's defaults, PD gains KP and KV on the legs."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT),
                     rigid_options=gs.options.RigidOptions(enable_mujoco_compatibility=True, friction_cone=cone),
                     show_viewer=False)
    scene.add_entity(gs.morphs.Plane() if ground is None else ground)
    robot = scene.add_entity(gs.morphs.URDF(file=path, pos=(0, 0, Z)))
    scene.build()
    legs = np.arange(6, robot.n_dofs)
    robot.set_dofs_kp(np.full(len(legs), KP), legs)
    robot.set_dofs_kv(np.full(len(legs), KV), legs)
    return scene, robot, legs


def resynced_step(scene, robot, legs, m, d, step):
    """One step of both engines from MuJoCo's state (qpos, qvel; its warm start cleared, as setting
    ours clears ours) under the PD targets of ``step``; returns the largest |qvel| and |qpos|
    difference after it."""
    as_ours = lambda a: torch.as_tensor(a, dtype=gs.tc_float)  # noqa: E731
    d.ctrl[:] = _targets(step * DT)
    robot.set_qpos(as_ours(d.qpos), zero_velocity=False)
    robot.set_dofs_velocity(as_ours(d.qvel))
    robot.control_dofs_position(as_ours(d.ctrl), legs)
    d.qacc_warmstart[:] = 0.0
    scene.step()
    mujoco.mj_step(m, d)
    return (np.abs(robot.get_dofs_velocity().cpu().numpy() - d.qvel).max(),
            np.abs(robot.get_qpos().cpu().numpy() - d.qpos).max())


def _mujoco_contacts(m, d):
    """[(geom1, geom2, position (3,), world force on geom2 (3,))] of MuJoCo's last step."""
    out = []
    wrench = np.zeros(6)
    for k, c in enumerate(d.contact[: d.ncon]):
        mujoco.mj_contactForce(m, d, k, wrench)
        frame = c.frame.reshape(3, 3)  # rows: normal (geom1 → geom2), tangents
        out.append((int(c.geom[0]), int(c.geom[1]), c.pos.copy(), frame.T @ wrench[:3]))
    return out


def _ours_contacts(robot):
    """[(geom a, geom b, position (3,), world force on geom b (3,))] of our last step."""
    c = robot.get_contacts()
    return list(zip(c["geom_a"].tolist(), c["geom_b"].tolist(), c["position"].cpu().numpy(),
                    c["force_b"].cpu().numpy()))


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_a1_steps_like_mujoco(f64, cone):
    """1 s of re-synced steps: qvel and qpos ≤ 1e-7 from MuJoCo's, the same contacts each step."""
    path = pybullet("a1", "a1.urdf")
    scene, robot, legs = _build_ours(path, cone)
    m, d = a1_mujoco(path, Z, STAND, KP, KV, DT)
    m.opt.cone = {"pyramidal": mujoco.mjtCone.mjCONE_PYRAMIDAL, "elliptic": mujoco.mjtCone.mjCONE_ELLIPTIC}[cone]
    lower, upper = m.jnt_range[1:, 0], m.jnt_range[1:, 1]
    counts, touched, limit_gap, base_start = [], set(), np.inf, d.qpos[:3].copy()
    for step in range(STEPS):
        dv, dq = resynced_step(scene, robot, legs, m, d, step)
        assert dv <= 1e-7 and dq <= 1e-7, (step, dv, dq)
        ours, theirs = _ours_contacts(robot), _mujoco_contacts(m, d)
        assert len(ours) == len(theirs), (step, ours, theirs)
        for (a, b, pos, force), (g1, g2, pos_mj, force_mj) in zip(ours, theirs):
            assert (a, b) == (g1, g2), (step, ours, theirs)
            assert np.abs(pos - pos_mj).max() <= 1e-12, (step, a, b, pos - pos_mj)
            assert np.abs(force - force_mj).max() <= 1e-8, (step, a, b, force, force_mj)
        counts.append(len(theirs))
        touched.update(c[1] for c in theirs)
        limit_gap = min(limit_gap, float(np.min(np.minimum(d.qpos[7:] - lower, upper - d.qpos[7:]))))
    # a hard case: feet touch and lift (the contact set changes), the base sways, no joint limit is met
    assert touched >= {7, 12, 17, 22}, touched  # the four foot spheres
    assert max(counts) >= 4 and min(counts) <= 2, (min(counts), max(counts))  # all four feet down at once (5 at times)
    assert sum(a != b for a, b in zip(counts, counts[1:])) >= 10
    assert np.abs(d.qpos[:3] - base_start).max() > 0.01
    assert limit_gap > 0.1
