"""Gradients through contact on robots against central finite differences (float64), issue 11.

The check is tests/test_contact_gradients.py's: the directional derivative g·v of a scalar loss
along a random unit direction v against (L(x + εv) − L(x − εv)) / 2ε over the eps scan 1e-5 …
1e-8; the scan must converge (two neighbouring eps agree to 1e-5 of ‖g‖) and there the error
must be ≤ 1e-5 of ‖g‖. The constraint solve runs to round-off (``TOLERANCE``). Both scenes use
MuJoCo's default contact model (no ``smooth_contact``): their scans converge without it.

Scenes:

- ``kuka_push``: pybullet_data's KUKA iiwa (fixed base; its links collide as the convex hulls of
  their meshes) pushes a box sideways along a plane. The arm starts bent down (``Q0``) with its
  flange (link 7, a disk of radius 52 mm whose axis points down, 15 mm above the plane) 0.3 mm
  from the side of the box (its widest rim, at z 59 mm, meets the box's top edge, at z 60 mm);
  the input is the (steps, 7) joint-torque sequence, applied as
  ``control_dofs_force(x[t] + KP·(Q0 − q))``: x's nominal value is the gravity-compensating torque
  at Q0 (``−get_dofs_force()`` after a step from rest) plus PUSH N·m on the base joint, and the
  proportional term (torch, on the state) holds the arm's shape. The arm swings, the flange pushes the box
  along +y for the whole rollout (mesh–box contacts of the convex collider, 2 to 6 of them, from
  the 8th step on in 190 of 200 steps; counted), while the box slides on the plane (box–plane).
  Loss: a weighted sum of the box's final position.
- ``a1_stand``: pybullet_data's a1 quadruped (sphere feet, box links, cylinder hips; self-collision
  on) standing on a plane under PD servos (kp 100, kv 2) at dt 2 ms, from a settled stand. The
  input is the (steps, 12) PD target sequence: the standing pose plus a small sway per joint,
  which lifts a foot now and then (1 to 4 feet down; contacts make and break). Loss: a weighted
  sum of the base's final position. Its cylinder pairs stay apart (a contact would make the
  backward raise GradientError).

The default run differences each scene over 50 steps with each cone; ``-m slow`` runs the rest of
the issue's matrix (both cones, 50 and 200 (KUKA) or 250 (a1) steps, n_envs 0 and 4, substeps 2).
Repeated rollouts give bit-identical gradients.
"""
import os

import numpy as np
import pybullet_data
import pytest
import torch

import genesis_lite as gs
from tests.fd_scan import assert_converged, directional_errors

# The Newton solve runs until it stops improving (round-off). At 1e-14 the KUKA's elliptic solve
# stopped where a contact in the cone's middle zone (not piecewise quadratic, unlike every
# pyramidal row) left a residual whose derivative is ~1e-5 of the gradient: the differences saw
# that iterate rather than the solution (one step's velocity Jacobian off by 5e-6 … 2e-5, exact
# to 1e-9 at 1e-30; the pyramidal cone exact at either).
TOLERANCE = 1e-30
_SCENES = {}
KUKA = os.path.join(pybullet_data.getDataPath(), "kuka_iiwa", "model.urdf")
A1 = os.path.join(pybullet_data.getDataPath(), "a1", "a1.urdf")

# KUKA: flange straight down at (0.6, 0, 0.06) m (link 7's origin; its disk spans z 0.015-0.07)
Q0 = (0.0, 1.26232841, 0.0, -1.35617325, 0.0, 0.52309098, 0.0)  # rad
KP = (0.0, 300.0, 100.0, 300.0, 30.0, 30.0, 0.0)  # N·m/rad: holds the arm's shape, not the base joint
DAMPING = (5.0, 5.0, 2.0, 5.0, 1.0, 1.0, 0.2)  # N·m·s/rad (implicit: keeps the explicit P term stable)
PUSH = 10.0  # N·m on the base joint: the box (1.2 kg, μ = 1) needs ~7 N·m at 0.6 m to slide
BOX_HALF = (0.1, 0.1, 0.03)  # m
BOX_POS = (0.6, 0.052 + BOX_HALF[1] + 3e-4, BOX_HALF[2])  # 0.3 mm beside the flange's disk

# a1: standing pose (hip, thigh, calf per leg), PD gains, time step
A1_STAND = np.tile([0.0, 0.8, -1.5], 4)  # rad
A1_Z, A1_KP, A1_KV, A1_DT = 0.305, 100.0, 2.0, 0.002  # m, N·m/rad, N·m·s/rad, s
SWAY = np.tile([0.05, 0.1, 0.1], 4)  # rad: the targets' sinusoid amplitudes
SWAY_HZ = np.array([1.0, 1.3, 1.7, 1.1, 1.4, 1.9, 0.9, 1.2, 1.6, 1.05, 1.5, 1.8])
SWAY_PHASE = np.linspace(0.0, 2 * np.pi, 12, endpoint=False)


def _options(cone, substeps, dt):
    return dict(sim_options=gs.options.SimOptions(dt=dt, substeps=substeps, requires_grad=True),
                rigid_options=gs.options.RigidOptions(tolerance=TOLERANCE, friction_cone=cone), show_viewer=False)


def _every_env(value, n_envs):
    """value (k,) → a tensor (k,), or (n_envs, k) with the same row in every env."""
    value = torch.as_tensor(np.asarray(value, dtype=np.float64))
    return value.expand(n_envs, len(value)).clone() if n_envs else value


def _kuka_scene(cone, n_envs=0, substeps=1):
    """(scene, {"arm", "box", "hold"}): plane, fixed KUKA and box, registered at the start pose
    (scene.reset() returns there); hold: the joint torques (7,) holding Q0 at rest against gravity."""
    key = ("kuka", cone, n_envs, substeps, gs.runtime.epoch)
    if key not in _SCENES:
        scene = gs.Scene(**_options(cone, substeps, 0.01))
        scene.add_entity(gs.morphs.Plane())
        arm = scene.add_entity(gs.morphs.URDF(file=KUKA, fixed=True), name="kuka")
        box = scene.add_entity(gs.morphs.Box(size=tuple(2 * h for h in BOX_HALF), pos=BOX_POS),
                               material=gs.materials.Rigid(rho=500.0), name="box")
        scene.build(n_envs=n_envs)
        arm.set_dofs_damping(_every_env(DAMPING, n_envs))
        arm.set_dofs_position(_every_env(Q0, n_envs))
        start = scene.get_state()
        scene.step()  # from rest without controls: the last substep's force is (about) gravity's
        hold = -arm.get_dofs_force()
        scene.reset(start)
        _SCENES[key] = (scene, {"arm": arm, "box": box, "hold": hold[0] if n_envs else hold})
    return _SCENES[key]


def _kuka_nominal(scene, parts, steps):
    """Nominal torques (steps, 7), or (n_envs, steps, 7) with a 1 % spread per env."""
    push = torch.zeros(7, dtype=torch.float64)
    push[0] = PUSH
    value = (parts["hold"] + push).expand(steps, 7).clone()
    if not scene.n_envs:
        return value
    return value * (1.0 + 0.01 * torch.arange(scene.n_envs, dtype=torch.float64))[:, None, None]


def _kuka_push(scene, parts, x, steps, contacts=None):
    """Joint torques x (steps, 7) or (n_envs, steps, 7) → weighted final box position; contacts:
    a list given gets the number of arm–box contacts of each step (env 0)."""
    arm, box = parts["arm"], parts["box"]
    q0, kp = _every_env(Q0, scene.n_envs), torch.tensor(KP, dtype=torch.float64)
    for t in range(steps):
        arm.control_dofs_force(x[..., t, :] + kp * (q0 - arm.get_dofs_position()))
        scene.step()
        if contacts is not None:
            found = box.get_contacts(with_entity=arm)
            contacts.append(int(found["valid_mask"][0].sum()) if scene.n_envs else len(found["geom_a"]))
    return (box.get_pos() * torch.tensor([1.0, 2.0, 0.5], dtype=torch.float64)).sum()


def _a1_scene(cone, n_envs=0, substeps=1):
    """(scene, {"robot", "legs"}): plane and a1 (free base) under PD servos, registered at a
    stand settled for 0.3 s (scene.reset() returns there)."""
    key = ("a1", cone, n_envs, substeps, gs.runtime.epoch)
    if key not in _SCENES:
        scene = gs.Scene(**_options(cone, substeps, A1_DT))
        scene.add_entity(gs.morphs.Plane())
        robot = scene.add_entity(gs.morphs.URDF(file=A1, pos=(0, 0, A1_Z)), name="a1")
        scene.build(n_envs=n_envs)
        legs = np.arange(6, robot.n_dofs)
        robot.set_dofs_kp(_every_env(np.full(len(legs), A1_KP), n_envs), legs)
        robot.set_dofs_kv(_every_env(np.full(len(legs), A1_KV), n_envs), legs)
        robot.set_dofs_position(_every_env(A1_STAND, n_envs), legs)
        with torch.no_grad():
            robot.control_dofs_position(_every_env(A1_STAND, n_envs), legs)
            for _ in range(150):
                scene.step()
        scene.reset(scene.get_state())
        _SCENES[key] = (scene, {"robot": robot, "legs": legs})
    return _SCENES[key]


def _a1_nominal(scene, parts, steps):
    """Nominal PD targets (steps, 12): the stand plus a sway; (n_envs, steps, 12) with a 1 %
    spread of the sway per env."""
    time = A1_DT * np.arange(1, steps + 1)[:, None]
    sway = torch.tensor(SWAY * np.sin(2 * np.pi * SWAY_HZ * time + SWAY_PHASE))
    stand = torch.tensor(A1_STAND)
    if not scene.n_envs:
        return stand + sway
    return stand + sway * (1.0 + 0.01 * torch.arange(scene.n_envs, dtype=torch.float64))[:, None, None]


def _a1_stand(scene, parts, x, steps, contacts=None):
    """PD targets x (steps, 12) or (n_envs, steps, 12) → weighted final base position."""
    robot, legs = parts["robot"], parts["legs"]
    for t in range(steps):
        robot.control_dofs_position(x[..., t, :], legs)
        scene.step()
        if contacts is not None:
            found = robot.get_contacts()
            contacts.append(int(found["valid_mask"][0].sum()) if scene.n_envs else len(found["geom_a"]))
    return (robot.get_pos() * torch.tensor([1.0, -2.0, 5.0], dtype=torch.float64)).sum()


SCENES = {"kuka_push": (_kuka_scene, _kuka_nominal, _kuka_push),
          "a1_stand": (_a1_scene, _a1_nominal, _a1_stand)}


def _check(name, cone, steps, n_envs=0, substeps=1, seed=0):
    """The eps scan must converge to ≤ 1e-5 of ‖g‖; returns the contacts per step (env 0) of the
    gradient's rollout."""
    make, nominal, loss_of = SCENES[name]
    scene, parts = make(cone, n_envs, substeps)
    contacts = []

    def loss(x):
        scene.reset()
        return loss_of(scene, parts, x, steps, contacts if x.requires_grad else None)

    errors = directional_errors(loss, nominal(scene, parts, steps), seed)
    assert_converged(errors, f"{name} {cone} T={steps} n_envs={n_envs} substeps={substeps}")
    return contacts


def _check_kuka(cone, steps, n_envs=0, substeps=1):
    contacts = _check("kuka_push", cone, steps, n_envs, substeps)
    # the flange reaches the box within 0.1 s and pushes it from then on
    assert sum(n > 0 for n in contacts) >= 0.75 * steps, f"arm–box contacts per step: {contacts}"


def _check_a1(cone, steps, n_envs=0, substeps=1):
    contacts = _check("a1_stand", cone, steps, n_envs, substeps)
    assert min(contacts) >= 1 and max(contacts) == 4, f"a1 contacts per step: {contacts}"  # it stands on its feet


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_kuka_pushes_box(f64, cone):
    _check_kuka(cone, steps=50)


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_a1_stands(f64, cone):
    _check_a1(cone, steps=50)


# the rest of the matrix ("long": 200 KUKA steps, 2 s; 250 a1 steps, 0.5 s)
MATRIX = [(50, 4, 1), (50, 0, 2), ("long", 0, 1), ("long", 4, 1), ("long", 0, 2)]


@pytest.mark.slow
@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
@pytest.mark.parametrize("steps,n_envs,substeps", MATRIX)
def test_kuka_pushes_box_matrix(f64, cone, steps, n_envs, substeps):
    _check_kuka(cone, 200 if steps == "long" else steps, n_envs, substeps)


@pytest.mark.slow
@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
@pytest.mark.parametrize("steps,n_envs,substeps", MATRIX)
def test_a1_stands_matrix(f64, cone, steps, n_envs, substeps):
    _check_a1(cone, 250 if steps == "long" else steps, n_envs, substeps)  # 0.5 s


def _gradient(name, cone, steps):
    make, nominal, loss_of = SCENES[name]
    scene, parts = make(cone)
    x = nominal(scene, parts, steps).requires_grad_(True)
    scene.reset()
    loss_of(scene, parts, x, steps).backward()
    return x.grad


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
@pytest.mark.parametrize("name", list(SCENES))
def test_repeated_rollouts_bit_identical(f64, name, cone):
    first, second = _gradient(name, cone, 30), _gradient(name, cone, 30)
    assert torch.equal(first, second)


def test_panda_presses_a_small_box_pose_gradient(f64):
    """pybullet_data's Panda (self-collision off, Genesis's tutorial gains, force range ±1e4)
    driven down onto a fixed 8 cm box for 5 steps (dt 10 ms): 8 mesh–box contacts, 4 per finger,
    the box's edges clipping the fingers' contact patches. One more step from there: the gradient
    of a weighted sum of the new state in the start joint positions, against central differences.
    It missed them by 1.1e-4 of its norm (5e-4 … 1.7e-3 per joint, 3.6e-2 with the elliptic
    cone; the velocity gradient was exact): the corner of the box's face clipped on the left
    finger's hull polygon, which is not planar (merged facets, ~1e-4 m), was the forward's
    interpolation along the polygon's edges while the backward differentiated the closed form on
    the plane of its vertex 0 (1.1e-4 m apart). convex.iterated now counts such corners, so the
    forward's contact is that closed form (detect.converge_contacts): 1.6e-10 … 3.5e-7 at five
    states, elliptic ≤ 1.9e-8. Found by an exploratory pass (session 21)."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True),
                     rigid_options=gs.options.RigidOptions(enable_self_collision=False, tolerance=1e-14))
    arm = scene.add_entity(gs.morphs.URDF(file=os.path.join(pybullet_data.getDataPath(), "franka_panda", "panda.urdf"),
                                          fixed=True))
    scene.add_entity(gs.morphs.Box(pos=(0.62, 0.0, 0.04), size=(0.08, 0.08, 0.08), fixed=True))
    scene.build()
    arm.set_dofs_kp(torch.tensor([4500, 4500, 3500, 3500, 2000, 2000, 2000, 100, 100], dtype=torch.float64))
    arm.set_dofs_kv(torch.tensor([450, 450, 350, 350, 200, 200, 200, 10, 10], dtype=torch.float64))
    arm.set_dofs_force_range(torch.full((9,), -1e4, dtype=torch.float64), torch.full((9,), 1e4, dtype=torch.float64))
    q0 = torch.tensor([0.0, 0.55, 0.0, -2.1, 0.0, 2.65, 0.785, 0.02, 0.02], dtype=torch.float64)
    sweep = torch.tensor([0.0, 0.25, 0.0, 0.35, 0.0, -0.1, 0.0, 0.0, 0.0], dtype=torch.float64) / 60

    with torch.no_grad():
        arm.set_dofs_position(q0)
        for t in range(5):
            arm.control_dofs_position(q0 + sweep * t)
            scene.step()
        q5, v5 = arm.get_dofs_position().clone(), arm.get_dofs_velocity().clone()
    weights = torch.tensor(np.random.default_rng(1).normal(size=18))

    def loss(q):
        scene.reset()
        arm.set_dofs_position(q)
        arm.set_dofs_velocity(v5)
        arm.control_dofs_position(q0 + sweep * 5)
        scene.step()
        return (torch.cat([arm.get_dofs_position(), arm.get_dofs_velocity()]) * weights).sum()

    loss(q5)
    assert len(arm.get_contacts()["geom_a"]) == 8
    assert_converged(directional_errors(loss, q5), "Panda pose")


def test_husky_drives_with_the_elliptic_cone_at_the_default_tolerance(f64):
    """pybullet_data's husky under velocity servos on its four wheels drives on a plane for 40
    steps (dt 10 ms, substeps 2), elliptic cone, every solve option at its default: the gradient
    of its final pose in the wheels' kv against central differences. MuJoCo's stop left each
    solve ~√tolerance from its solution, where the near-sticking wheels' cone Hessian changes
    fast, and the gradient (the solution's) missed the simulated map's derivative by 6.4 % of
    its norm (flat over eps 1e-4 … 1e-8; exact at tolerance 1e-30); one Newton step past the
    stop (constraint/solver.py): 6e-8. Found by an exploratory pass (session 34)."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, substeps=2, requires_grad=True),
                     rigid_options=gs.options.RigidOptions(friction_cone=gs.friction_cone.elliptic),
                     show_viewer=False)
    scene.add_entity(gs.morphs.Plane())
    robot = scene.add_entity(gs.morphs.URDF(file=os.path.join(pybullet_data.getDataPath(), "husky", "husky.urdf"),
                                            pos=(0, 0, 0.14)))
    scene.build()
    wheels = list(range(6, robot.n_dofs))
    with torch.no_grad():
        for _ in range(30):
            scene.step()
    q0, v0 = robot.get_dofs_position().detach().clone(), robot.get_dofs_velocity().detach().clone()
    targets = torch.tensor([3.0, 4.0, 3.0, 4.0], dtype=torch.float64)

    def loss(kv):
        scene.reset()
        robot.set_dofs_position(q0)
        robot.set_dofs_velocity(v0)
        robot.set_dofs_kv(kv, wheels)
        for _ in range(40):
            robot.control_dofs_velocity(targets, wheels)
            scene.step()
        return ((robot.get_pos() * torch.tensor([1.0, -0.7, 3.0])).sum()
                + (robot.get_quat() * torch.tensor([0.2, 1.0, 0.5, -0.4])).sum())

    kv = torch.tensor([20.0, 22.0, 18.0, 21.0], dtype=torch.float64)
    assert_converged(directional_errors(loss, kv), "husky wheels' kv")
