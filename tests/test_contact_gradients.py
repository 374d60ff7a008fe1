"""Gradients through contact against central finite differences (float64), issue 11.

Every check compares the directional derivative g·v of a scalar loss along a random unit
direction v with central differences (L(x + εv) − L(x − εv)) / 2ε over an eps scan 1e-5 … 1e-8:
the scan must converge (two neighbouring eps agree to 1e-5 of ‖g‖) and there the error must be
≤ 1e-5 of ‖g‖. The map is our discrete step: the constraint solve runs to 1e-14, so that finite
differences see the solution rather than where a solve stopped; contacts come and go with the
perturbation only where a scan shows it (a kink: large eps disagree, small ones converge).

Scenes: a box on a plane (both cones), sliding, landing, tilted onto an edge, or resting; the
same box as a mesh on the plane and on a fixed box (the convex collider); a sphere rolling
(torch.autograd.gradcheck). The full matrix of the issue (50 and 200 steps,
n_envs 0 and 4, substeps 2) runs under ``-m slow``.
"""
import os
import tempfile

import numpy as np
import pytest
import torch
import trimesh

import genesis_lite as gs
from genesis_lite.solvers.rigid.data import SERIAL_SOLVE_WORK
from genesis_lite.solvers.rigid.solver import REPLAY_RECORD_STATES
from tests.conftest import pybullet
from tests.contact_scenes import GRIPPER
from tests.fd_scan import assert_converged, directional_errors

_SCENES = {}
HALF = (0.1, 0.15, 0.05)  # box half extents, m
SLAB = 0.04  # thickness (m) of the free slab the "mass" case's box lands on


def _scene(cone, n_envs=0, substeps=1, shape="box", tag="", smooth=False, ground="plane", condim=3):
    """One scene per configuration (building is the slow part). Parameters persist across
    reset(): each case sets its own, and ``tag`` gives a scene of its own. smooth:
    RigidOptions(smooth_contact=True). ground: "plane", "box": a fixed box whose top is the
    plane z = 0 (a mesh on it goes through the convex collider), "can": a fixed can (r 0.4 m) whose
    cap is that plane, "offcan": one (r 0.2 m) whose axis, 0.17 m off the box's centre, misses the
    box's face, "pedestal": a fixed 0.16 m wide box whose top is ("mesh pedestal": as a mesh), or
    "slab": the plane with a free
    0.6 × 0.6 m slab SLAB thick resting on it. condim 4 or 6: torsional (and rolling) friction on
    (SPIN_ROLL: large enough to act)."""
    key = (cone, n_envs, substeps, shape, tag, smooth, ground, condim, gs.runtime.epoch)
    if key not in _SCENES:
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, substeps=substeps, requires_grad=True),
                         rigid_options=gs.options.RigidOptions(tolerance=1e-14, friction_cone=cone,
                                                               smooth_contact=smooth,
                                                               enable_torsional_friction=condim >= 4,
                                                               enable_rolling_friction=condim == 6),
                         show_viewer=False)
        material = gs.materials.Rigid(friction_torsional=SPIN_ROLL[0], friction_rolling=SPIN_ROLL[1])
        if ground in ("plane", "slab"):
            scene.add_entity(gs.morphs.Plane())
            if ground == "slab":
                scene.add_entity(gs.morphs.Box(size=(0.6, 0.6, SLAB), pos=(0, 0, SLAB / 2)))
        elif ground == "can":
            scene.add_entity(gs.morphs.Cylinder(radius=0.4, height=0.2, pos=(0, 0, -0.1), fixed=True))
        elif ground == "offcan":
            scene.add_entity(gs.morphs.Cylinder(radius=0.2, height=0.2, pos=(0.03, 0.17, -0.1), fixed=True))
        elif ground == "pedestal":
            scene.add_entity(gs.morphs.Box(size=(0.16, 0.16, 0.2), pos=(0, 0, -0.1), fixed=True))
        elif ground == "mesh pedestal":
            path = os.path.join(tempfile.mkdtemp(), "pedestal.obj")
            trimesh.creation.box(extents=(0.16, 0.16, 0.2)).export(path)
            scene.add_entity(gs.morphs.Mesh(file=path, pos=(0, 0, -0.1), fixed=True))
        elif ground == "mesh":
            path = os.path.join(tempfile.mkdtemp(), "table.obj")
            trimesh.creation.box(extents=(2.0, 2.0, 0.2)).export(path)
            scene.add_entity(gs.morphs.Mesh(file=path, pos=(0, 0, -0.1), fixed=True))
        else:
            scene.add_entity(gs.morphs.Box(size=(2.0, 2.0, 0.2), pos=(0, 0, -0.1), fixed=True))
        if shape == "box":
            body = scene.add_entity(gs.morphs.Box(size=tuple(2 * h for h in HALF), pos=(0, 0, HALF[2])),
                                    material=material)
        elif shape == "mesh":  # the same box as a mesh: plane–mesh contacts (its hull's vertices)
            path = os.path.join(tempfile.mkdtemp(), "box.obj")
            trimesh.creation.box(extents=tuple(2 * h for h in HALF)).export(path)
            body = scene.add_entity(gs.morphs.Mesh(file=path, pos=(0, 0, HALF[2])))
        elif shape == "cylinder":  # a can as tall as the box: cylinder–box contacts on the "box" ground
            body = scene.add_entity(gs.morphs.Cylinder(radius=HALF[0], height=2 * HALF[2], pos=(0, 0, HALF[2])))
        else:
            body = scene.add_entity(gs.morphs.Sphere(radius=0.1, pos=(0, 0, 0.1)), material=material)
        scene.build(n_envs=n_envs)
        _SCENES[key] = (scene, body)
    return _SCENES[key]


def _batch(n_envs, value):
    """value (k,) → (n_envs, k) with a small spread per env (each env its own trajectory)."""
    if not n_envs:
        return value
    spread = 1.0 + 0.01 * torch.arange(n_envs, dtype=torch.float64)[:, None]
    return value[None, :] * spread


# case → (nominal input (k,), loss) ; each loss takes (scene, body, x) and runs one rollout
def _every_env(value, n_envs):
    value = torch.tensor(value, dtype=torch.float64)
    return value.expand(n_envs, len(value)) if n_envs else value


def _start(body, n_envs, pos, quat, vel, gravity=(0.0, 0.0, -9.81)):
    """The same start state and gravity in every env (the inputs under test differ per env)."""
    every_env = lambda value: _every_env(value, n_envs)  # noqa: E731
    body.scene.set_gravity(every_env(gravity))
    body.set_pos(every_env(pos), zero_velocity=False)
    body.set_quat(every_env(quat), zero_velocity=False)
    body.set_dofs_velocity(every_env(vel))


SLIDE = ((0, 0, HALF[2] - 1e-3), (1, 0, 0, 0), (1.0, 0.3, 0.0, 0.0, 0.0, 0.4))
SPIN_ROLL = (0.02, 0.01)  # the bodies' torsional and rolling friction, m (where condim 4 and 6 use them)


def _sliding_velocity(scene, body, x, steps):
    """A sliding box's initial velocity (6) → its final position and orientation."""
    _start(body, scene.n_envs, *SLIDE[:2], SLIDE[2])
    body.set_dofs_velocity(x)
    _roll(scene, steps)
    return (body.get_pos() * torch.tensor([1.0, -0.7, 3.0])).sum() + body.get_quat()[..., 1:].sum()


def _friction(scene, body, x, steps):
    """The box's friction (its ratio to the default; the pair takes the larger of box and plane,
    so > 1 acts) → sliding distance."""
    _start(body, scene.n_envs, *SLIDE)
    body.set_friction_ratio(x)
    _roll(scene, steps)
    return body.get_pos()[..., 0].sum() + 0.3 * body.get_pos()[..., 1].sum()


def _mass(scene, body, x, steps):
    """Box mass → landing position (dropped 2 cm onto a free slab, moving sideways, spinning): the
    mass enters M and, through body_invweight0, the box–slab contact rows' R (diagA = 1/m_box +
    1/m_slab; a lone free body's motion does not depend on its mass, as in MuJoCo)."""
    _start(body, scene.n_envs, (0, 0, SLAB + HALF[2] + 0.02), (1, 0, 0, 0), (0.5, -0.2, 0.0, 0.3, 0.2, 1.0))
    body.set_links_mass(x)
    _roll(scene, steps)
    return (body.get_pos() * torch.tensor([1.0, 1.0, 10.0])).sum() + body.get_quat()[..., 1:].sum()


def _tilted(scene, body, x, steps):
    """Initial height and orientation (3 + 4) of a tilted box dropped on an edge → final pose:
    corners touch one after another, contacts make and break."""
    _start(body, scene.n_envs, (0, 0, 0.09), (1, 0, 0, 0), (0.2, 0.0, 0.0, 0.0, 0.0, 0.0))
    body.set_pos(x[..., :3], zero_velocity=False)
    body.set_quat(x[..., 3:], zero_velocity=False)
    _roll(scene, steps)
    return (body.get_pos() * torch.tensor([1.0, 2.0, 5.0])).sum() + (body.get_quat() * torch.tensor(
        [0.3, 1.0, -1.0, 0.5])).sum()


def _softness(scene, body, x, steps):
    """sol_params (solref 2, solimp 5) of the box → its resting penetration (the plane keeps the
    defaults; a contact averages the two)."""
    _start(body, scene.n_envs, (0, 0, HALF[2]), (1, 0, 0, 0), (0.0,) * 6)
    body.set_sol_params(x)
    _roll(scene, steps)
    return 1e3 * body.get_pos()[..., 2].sum()


def _sliding_softness(scene, body, x, steps):
    """sol_params of a box kept sliding by a sideways pull (impedance width 1 cm: its rows' R
    moves with the depth) → sliding distance and depth: the elliptic cone's middle zone through
    R and μ."""
    _start(body, scene.n_envs, *SLIDE, gravity=(11.0, 0.0, -9.81))  # pulled along faster than μg: it keeps sliding
    body.set_sol_params(x)
    _roll(scene, steps)
    return body.get_pos()[..., 0].sum() + 1e2 * body.get_pos()[..., 2].sum()


def _rolling(scene, body, x, steps, base=0.0):
    """A sphere rolling and spinning on the plane (or on a ground whose top is at ``base`` m): its
    initial velocity (6), torsional and rolling friction (m) → its final position, orientation and
    velocity (the spin slows under the torsional row, the roll under the rolling rows; in a
    pyramid each edge mixes them with the normal)."""
    _start(body, scene.n_envs, (0, 0, 0.1 - 1e-4 + base), (1, 0, 0, 0), (0.0,) * 6)
    body.set_dofs_velocity(x[..., :6])
    body.set_friction_torsional(x[6])
    body.set_friction_rolling(x[7])
    _roll(scene, steps)
    return ((body.get_pos() * torch.tensor([1.0, -0.7, 30.0])).sum() + body.get_quat()[..., 1:].sum()
            + (body.get_dofs_velocity() * torch.tensor([0.3, 0.2, 1.0, 0.05, -0.04, 0.1])).sum())


def _creep(scene, body, x, steps):
    """A resting sphere turned by a torque below what its torsional and rolling friction (x (2,),
    m) hold (0.2 N·m about z, 0.1 about x: μ_t N ≈ 0.49 and μ_r N ≈ 0.25 N·m) → how far it creeps:
    the soft contact's stuck rows give way at a rate set by their R, in an elliptic cone R_k =
    R_1 μ² / μ_k² (the gradient in μ_k goes through R_k), in a pyramid through its edges."""
    _start(body, scene.n_envs, (0, 0, 0.1 - 1e-4), (1, 0, 0, 0), (0.0,) * 6)
    body.set_friction_torsional(x[0])
    body.set_friction_rolling(x[1])
    for _ in range(steps):
        body.apply_links_external_wrench(torque=torch.tensor([[0.1, 0.0, 0.2]], dtype=torch.float64))
        scene.step()
    return 1e3 * ((body.get_pos() * torch.tensor([1.0, -1.0, 1.0])).sum() + body.get_quat()[..., 1:].sum())


CASES = {"sliding_velocity": (_sliding_velocity, lambda: torch.tensor(SLIDE[2], dtype=torch.float64)),
         "friction": (_friction, lambda: torch.tensor([1.3], dtype=torch.float64)),
         "mass": (_mass, lambda: torch.tensor([1.4], dtype=torch.float64)),
         "tilted": (_tilted, lambda: torch.tensor([0.0, 0.0, 0.1, 0.96, 0.2, 0.15, 0.05], dtype=torch.float64)),
         # time constants whose average with the plane's stays above 2h (held there, no gradient)
         "softness": (_softness, lambda: torch.tensor([0.05, 0.9, 0.8, 0.95, 0.004, 0.4, 2.5], dtype=torch.float64)),
         "sliding_softness": (_sliding_softness,
                              lambda: torch.tensor([0.05, 1.1, 0.8, 0.95, 0.01, 0.5, 2.0], dtype=torch.float64)),
         # rolling at 0.8 m/s (ω = v/r) and spinning at 5 rad/s; frictions SPIN_ROLL
         "rolling": (_rolling, lambda: torch.tensor([0.8, 0.3, 0.0, -3.0, 8.0, 5.0, *SPIN_ROLL], dtype=torch.float64)),
         "creep": (_creep, lambda: torch.tensor(SPIN_ROLL, dtype=torch.float64)),
         # on the free slab, which tilts and slides under it: the contact frame moves with the slab
         "rolling_on_slab": (lambda scene, body, x, steps: _rolling(scene, body, x, steps, base=SLAB),
                             lambda: torch.tensor([0.8, 0.3, 0.0, -3.0, 8.0, 5.0, *SPIN_ROLL], dtype=torch.float64))}


BOX_CASES = [case for case in CASES if case not in ("rolling", "creep", "rolling_on_slab")]  # (these: a sphere)


def _roll(scene, steps):
    for _ in range(steps):
        scene.step()


GROUND = {"mass": "slab", "rolling_on_slab": "slab"}  # the cases that need another ground than the plane


def _check(case, cone, steps, n_envs=0, substeps=1, seed=0, shape="box", smooth=False, ground="plane", condim=3):
    scene, body = _scene(cone, n_envs, substeps, shape, smooth=smooth, ground=GROUND.get(case, ground),
                         condim=condim)
    loss_of, nominal = CASES[case]

    def loss(x):
        scene.reset()
        return loss_of(scene, body, x, steps)

    assert_converged(directional_errors(loss, _batch(n_envs, nominal()), seed), f"{case} {cone} T={steps}")


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
@pytest.mark.parametrize("case", BOX_CASES)
def test_box_on_plane(f64, case, cone):
    _check(case, cone, steps=50)


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
@pytest.mark.parametrize("condim", [4, 6])
@pytest.mark.parametrize("case", ["sliding_velocity", "rolling", "creep", "rolling_on_slab"])
def test_torsional_and_rolling_friction(f64, case, condim, cone):
    """Contacts of condim 4 and 6 (RigidOptions' enable_torsional_friction, enable_rolling_friction):
    a box sliding and spinning on its four corners, a sphere rolling and spinning whose torsional
    and rolling friction are inputs too (set_friction_torsional, set_friction_rolling), one held by
    them against a torque, and one rolling on a free slab (the angular rows' frame moves: their
    adjoint into the frame)."""
    _check(case, cone, steps=50, shape="box" if case == "sliding_velocity" else "sphere", condim=condim)


@pytest.mark.slow
@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
@pytest.mark.parametrize("case,steps,n_envs,substeps", [
    ("sliding_velocity", 200, 0, 1), ("sliding_velocity", 50, 4, 1), ("sliding_velocity", 200, 4, 1),
    ("sliding_velocity", 50, 0, 2), ("rolling", 200, 0, 1), ("rolling", 50, 0, 2), ("creep", 200, 0, 1),
    ("creep", 50, 0, 2)])
def test_torsional_and_rolling_friction_matrix(f64, case, cone, steps, n_envs, substeps):
    """The issue's matrix at condim 6 (the sphere cases set one friction for every env: n_envs 0)."""
    _check(case, cone, steps, n_envs, substeps, shape="box" if case == "sliding_velocity" else "sphere", condim=6)


@pytest.mark.parametrize("case", ["sliding_velocity", "tilted"])
def test_mesh_on_plane(f64, case):
    _check(case, "elliptic", steps=50, shape="mesh")


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
@pytest.mark.parametrize("case", ["sliding_velocity", "tilted"])
def test_mesh_on_box(f64, case, cone):
    """The box as a mesh on a fixed box: mesh–box contacts of the convex collider (GJK, EPA and
    face clipping between polytopes, whose replay is the forward's own closed form)."""
    _check(case, cone, steps=50, shape="mesh", ground="box")


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
@pytest.mark.parametrize("case", ["sliding_velocity", "tilted"])
def test_cylinder_on_box(f64, case, cone):
    """A can on a fixed box: sliding and spinning on its cap, or dropped tilted on its rim until it
    stands — its contacts with the face are four rim points (convex.KIND_FACE_CAP) once it stands."""
    _check(case, cone, steps=50, shape="cylinder", ground="box")


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
@pytest.mark.parametrize("case", ["sliding_velocity", "tilted"])
def test_cylinder_on_plane(f64, case, cone):
    """A can on the plane, sliding and spinning on its cap from exactly upright, or dropped tilted
    on its rim until it stands: four rim points once it stands (primitive.STANDING); MuJoCo's
    inscribed triangle turns with the tilt's direction, a map discontinuous at upright, where the
    differences did not converge."""
    _check(case, cone, steps=50, shape="cylinder", ground="plane")


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
@pytest.mark.parametrize("case", ["sliding_velocity", "tilted"])
def test_cylinder_on_a_mesh(f64, case, cone):
    """The can on a fixed mesh table: four rim points on the mesh's face once it stands
    (convex._face_cap on a mesh polygon)."""
    _check(case, cone, steps=50, shape="cylinder", ground="mesh")


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
@pytest.mark.parametrize("case", ["sliding_velocity", "tilted"])
def test_face_on_a_cap_of_another_size(f64, case, cone):
    """The box on a wider fixed can (its face's corners on the cap: convex.CORNER), on one whose
    axis misses its face (corners within the cap, rim points and the one toward the face's centre:
    convex.TOWARD), and a can (r 0.1 m) on a narrower fixed box (0.16 m: its cap's points under the
    box's edges, convex.EDGE, and rim points where the box reaches beyond the rim)."""
    _check(case, cone, steps=50, shape="box", ground="can")
    _check(case, cone, steps=50, shape="box", ground="offcan")
    _check(case, cone, steps=50, shape="cylinder", ground="pedestal")


@pytest.mark.slow
@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
@pytest.mark.parametrize("case", ["sliding_velocity", "tilted"])
def test_mesh_face_on_a_cap_of_another_size(f64, case, cone):
    """(Slow: 80 s; test_adjoints_convex checks these closed forms' adjoints in the default run.)
    As above with a mesh: the box as a mesh on the wider can (its polygon's vertices on the cap,
    convex.CORNER), on the one whose axis misses it (its vertices within the cap, the cap's points
    under its edges, convex.EDGE through `_clip_line`, and the rim point toward its middle), and the
    can on the pedestal as a mesh (the points under the polygon's edges)."""
    _check(case, cone, steps=50, shape="mesh", ground="can")
    _check(case, cone, steps=50, shape="mesh", ground="offcan")
    _check(case, cone, steps=50, shape="cylinder", ground="mesh pedestal")


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_time_constant_at_its_floor(f64, cone):
    """A pair's time constant exactly at its floor 2h, as the defaults make it (0.01 s for both
    geoms, dt 0.01 s, two substeps): the kink passes half of the gradient through it, which central
    differences converge to (all of it made the time constant's part twice theirs)."""
    scene, body = _scene(cone, substeps=2)
    timeconst = 2 * scene.dt / scene.substeps

    def loss(x):
        scene.reset()
        return _sliding_softness(scene, body, x, 5)

    nominal = torch.tensor([timeconst, 1.1, 0.8, 0.95, 0.01, 0.5, 2.0], dtype=torch.float64)
    along_timeconst = torch.zeros(7, dtype=torch.float64)
    along_timeconst[0] = 1.0
    for direction in (None, along_timeconst):
        assert_converged(directional_errors(loss, nominal, direction=direction), f"{cone} at the floor")


def test_default_tolerance_converges_an_elliptic_slide_for_its_gradient(f64):
    """pybullet's Panda finger (a convex mesh, 1e6 kg/m³) driven at 0.3 m/s into a fixed box with
    the elliptic cone at the default tolerance, one step: four contacts of one face, one sliding
    (its force on the cone). At Genesis's 1e-8 MuJoCo's Newton-decrement test stopped the solve
    after 11 iterations (decrement 4e-9, scaled gradient 5e-4) and the initial pose's gradient
    missed the forward map's derivative by 9e-4 of its norm; the float64 default (1e-12) takes
    the solve to its solution, where the implicit gradient is the map's."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True, gravity=(0, 0, 0)),
                     rigid_options=gs.options.RigidOptions(friction_cone=gs.friction_cone.elliptic))
    scene.add_entity(gs.morphs.Box(pos=(0.62, 0.0, 0.04), size=(0.08, 0.08, 0.08), fixed=True))
    finger = scene.add_entity(gs.morphs.Mesh(file=pybullet("franka_panda", "meshes", "collision", "finger.obj"),
                                             pos=(0.5737357, -0.0198982, 0.0886440), quat=(3.79279e-5, 0.999939318,
                                                                                           2.44788e-5, -0.011016294)),
                              material=gs.materials.Rigid(rho=1e6))
    scene.build()
    start = finger.get_dofs_position().detach().clone()
    weights = torch.tensor([0.3, -1.3, 0.3, -1.2, 1.3, -0.6, 0.4, 0.9, -0.1, 0.5, 1.1, -0.7], dtype=torch.float64)

    def loss(q):
        scene.reset()
        finger.set_dofs_position(q)
        finger.set_dofs_velocity(torch.tensor([0.3, 0.0, 0.0, 0.0, 0.0, 0.0], dtype=torch.float64))
        scene.step()
        return (torch.cat([finger.get_dofs_position(), finger.get_dofs_velocity()]) * weights).sum()

    loss(start)
    assert len(finger.get_contacts()["geom_a"]) == 4
    for seed in range(2):
        assert_converged(directional_errors(loss, start, seed), f"finger pose, direction {seed}")


def test_a_loose_tolerance_keeps_the_pyramidal_solve_exact(f64):
    """The KUKA pushing a box under moving PD targets, pyramidal cone, at tolerance 1e-5 (float32's
    default) and 1e-12 in lockstep: a stop on a small improvement right after the rows' states
    changed left the line search's point (the two parted by 1.2e-3 m/s at step 30, and 200
    steps' gradient was 31 % off); one more Newton step with the final states ends the piecewise-
    quadratic solve exactly, so the loose solve stays on the tight one's trajectory."""
    q0 = np.array([0.0, 1.26232841, 0.0, -1.35617325, 0.0, 0.52309098, 0.0])

    def make(tolerance):
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01),
                         rigid_options=gs.options.RigidOptions(tolerance=tolerance))
        scene.add_entity(gs.morphs.Plane())
        arm = scene.add_entity(gs.morphs.URDF(file=pybullet("kuka_iiwa", "model.urdf"), fixed=True))
        box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.2, 0.06), pos=(0.6, 0.1523, 0.03)),
                               material=gs.materials.Rigid(rho=500.0))
        scene.build()
        arm.set_dofs_kp(torch.tensor([3000.0, 3000.0, 1000.0, 2000.0, 300.0, 300.0, 50.0], dtype=torch.float64))
        arm.set_dofs_kv(torch.tensor([300.0, 300.0, 100.0, 200.0, 30.0, 30.0, 5.0], dtype=torch.float64))
        arm.set_dofs_position(torch.tensor(q0))
        return scene, arm, box

    tight, loose = make(1e-12), make(1e-5)
    worst, touched = 0.0, False
    for t in range(60):
        s = t / 2000.0
        target = torch.tensor(q0 + [0.25 * s, 0.02 * np.sin(6 * np.pi * s), 0.0, 0.02 * np.sin(4 * np.pi * s), 0.0,
                                    0.02 * np.sin(10 * np.pi * s), 0.1 * np.sin(2 * np.pi * s)])
        for scene, arm, _ in (tight, loose):
            arm.control_dofs_position(target)
            scene.step()
        touched |= len(tight[2].get_contacts(with_entity=tight[1])["geom_a"]) > 0
        worst = max(worst, float((tight[2].get_dofs_velocity() - loose[2].get_dofs_velocity()).abs().max()))
    assert touched  # the arm pushes the box
    assert worst < 1e-9


def test_a_solve_stopped_at_its_iteration_limit_warns_in_a_differentiable_scene(f64, caplog):
    """A differentiable step whose constraint solve stops at RigidOptions(iterations) before its
    tolerance warns once, naming the option: its backward differentiates the converged solution
    (a box sliding 30 steps with iterations=2: dx/dv0 0.67 off, its sign flipped); at the default
    limit this scene converges and nothing is said, nor in a scene without gradients."""
    def slide(iterations, requires_grad=True, jelly=False):
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=requires_grad),
                         rigid_options=gs.options.RigidOptions(iterations=iterations),
                         mpm_options=gs.options.MPMOptions(lower_bound=(2.0, 2.0, 0.0), upper_bound=(2.5, 2.5, 0.5),
                                                           grid_density=16))
        scene.add_entity(gs.morphs.Plane())
        box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.3, 0.1), pos=(0.0, 0.0, 0.0495)))
        if jelly:  # (a scene of two solvers steps them in the shared substep loop)
            scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(2.25, 2.25, 0.25)),
                             material=gs.materials.MPM.Elastic(), name="jelly")
        scene.build()
        box.set_dofs_velocity([1.0, 0.3, 0.0, 0.0, 0.0, 0.4])
        caplog.clear()
        for _ in range(30):
            scene.step()
        return [r.getMessage() for r in caplog.records if "iteration limit" in r.getMessage()]
    for jelly in (False, True):
        capped = slide(2, jelly=jelly)
        assert len(capped) == 1 and "RigidOptions(iterations=2)" in capped[0]
        assert "entities: plane_0, box_1" in capped[0]
    assert slide(None) == [] and slide(2, requires_grad=False) == []


@pytest.mark.parametrize("case", ["tilted", "mass"])
def test_smooth_contact(f64, case):
    """RigidOptions(smooth_contact=True) (elliptic; impedance from zero at contact onset): a
    tilted box landing on one corner after another, contacts making and breaking; a box's mass."""
    _check(case, "elliptic", steps=50, smooth=True)


@pytest.mark.slow
@pytest.mark.parametrize("case", ["tilted", "mass", "sliding_velocity", "softness"])
@pytest.mark.parametrize("steps,n_envs,substeps", [(200, 0, 1), (50, 4, 1), (200, 4, 1), (50, 0, 2), (200, 0, 2)])
def test_smooth_contact_matrix(f64, case, steps, n_envs, substeps):
    _check(case, "elliptic", steps, n_envs, substeps, smooth=True)


@pytest.mark.slow
@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
@pytest.mark.parametrize("case", BOX_CASES)
@pytest.mark.parametrize("steps,n_envs,substeps", [(200, 0, 1), (50, 4, 1), (200, 4, 1), (50, 0, 2), (200, 0, 2)])
def test_box_on_plane_matrix(f64, case, cone, steps, n_envs, substeps):
    if case == "sliding_softness" and steps > 50:
        # the pulled box speeds up, and its corners lift and touch down again and again (as in
        # MuJoCo): over 2 s every such event is a kink of the map, and no eps scan converges
        pytest.skip("no smooth map to difference over 200 steps of a pulled box")
    _check(case, cone, steps, n_envs, substeps)


PRIORITY_MJCF = """<mujoco><worldbody>
  <geom type="plane" size="0 0 1" condim="3" friction="0.6 0.001 0.00001"/>
  <body pos="0 0 0.0999"><freejoint/><geom type="sphere" size="0.1" condim="6" priority="1" friction="0.9 0.02 0.01"/></body>
</worldbody></mujoco>"""


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_priority_pair_torsional_and_rolling_gradients(f64, cone, tmp_path):
    """An MJCF sphere of priority 1 and condim 6 on a plane of priority 0 and condim 3: the pair
    copies the sphere's condim and frictions (MuJoCo's mj_contactParam), so their gradients go
    through the copy path to the sphere's geom alone. Inputs: initial velocity, then the entity's
    torsional and rolling friction (set_friction_torsional/rolling: every geom of the file's
    entity, the plane's included, whose values the pair ignores)."""
    path = tmp_path / "priority.xml"
    path.write_text(PRIORITY_MJCF)
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True),
                     rigid_options=gs.options.RigidOptions(tolerance=1e-14, friction_cone=cone), show_viewer=False)
    entity = scene.add_entity(gs.morphs.MJCF(file=str(path)))
    scene.build()
    assert scene._rigid_solver.model.pair_condim.tolist() == [6]

    def loss(x):
        scene.reset()
        entity.set_dofs_velocity(x[:6])
        entity.set_friction_torsional(x[6])
        entity.set_friction_rolling(x[7])
        for _ in range(50):
            entity.apply_links_external_wrench(torque=torch.tensor([[0.0, 0.0, 0.0], [0.05, 0.0, 0.1]],
                                                                   dtype=torch.float64))
            scene.step()
        return ((entity.get_dofs_position() * torch.tensor([1.0, -0.7, 30.0, 0.3, 0.2, 1.0])).sum()
                + (entity.get_dofs_velocity() * torch.tensor([0.3, 0.2, 1.0, 0.05, -0.04, 0.1])).sum())

    nominal = torch.tensor([0.5, 0.2, 0.0, -2.0, 5.0, 3.0, 0.02, 0.01], dtype=torch.float64)
    assert_converged(directional_errors(loss, nominal), f"priority pair {cone}")


def test_rolling_sphere_gradcheck(f64):
    """torch.autograd.gradcheck of a sphere rolling on a plane for 10 steps: initial velocity →
    final state (elliptic cone)."""
    scene, ball = _scene("elliptic", shape="sphere")

    scene.reset()

    def final_state(velocity):  # no reset: gradcheck differentiates its first call after the others
        ball.set_pos(torch.tensor([0.0, 0.0, 0.0995], dtype=torch.float64), zero_velocity=False)
        ball.set_quat(torch.tensor([1.0, 0.0, 0.0, 0.0], dtype=torch.float64), zero_velocity=False)
        ball.set_dofs_velocity(velocity)
        _roll(scene, 10)
        return torch.cat([ball.get_pos(), ball.get_quat(), ball.get_dofs_velocity()])

    velocity = torch.tensor([0.5, -0.2, -0.05, 1.0, 2.0, -0.3], dtype=torch.float64, requires_grad=True)
    # check_undefined_grad: a step's backward is always given its output's gradient (zeros materialised)
    assert torch.autograd.gradcheck(final_state, (velocity,), eps=1e-6, atol=1e-7, rtol=1e-5,
                                    check_undefined_grad=False)


def _gradient(scene, body, case, steps):
    loss_of, nominal = CASES[case]
    x = _batch(scene.n_envs, nominal()).requires_grad_(True)
    scene.reset()
    loss_of(scene, body, x, steps).backward()
    return x.grad


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_repeated_rollouts_bit_identical(f64, cone):
    scene, body = _scene(cone)
    for case in ("tilted", "friction"):
        first, second = _gradient(scene, body, case, 30), _gradient(scene, body, case, 30)
        assert torch.equal(first, second), case


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_repeated_rollouts_bit_identical_with_torsional_and_rolling_friction(f64, cone):
    scene, body = _scene(cone, shape="sphere", condim=6)
    for case in ("rolling", "creep"):
        first, second = _gradient(scene, body, case, 30), _gradient(scene, body, case, 30)
        assert torch.equal(first, second), case


def test_set_friction_is_the_differentiable_ratio_input(f64):
    """set_friction with a 0-d tensor requiring grad (it took numbers only) writes the input that
    set_friction_ratio scales (the box's build friction is 1): the same loss and gradient bits,
    so the ratio's finite-difference test covers it."""
    scene, body = _scene("pyramidal")
    assert scene._rigid_solver.model.geom_friction[body.geom_start, 0] == 1.0
    results = []
    ones = torch.ones(body.n_links, dtype=torch.float64)  # (the scene is shared: another test's ratio is kept)
    for set_friction in (lambda x: (body.set_friction_ratio(ones), body.set_friction(x[0])),
                         lambda x: (body.set_friction(1.0), body.set_friction_ratio(x))):  # (the first's 1.3 kept)
        x = torch.tensor([1.3], dtype=torch.float64, requires_grad=True)
        scene.reset()
        _start(body, scene.n_envs, *SLIDE)
        set_friction(x)
        _roll(scene, 30)
        loss = body.get_pos()[..., 0].sum()
        loss.backward()
        results.append((loss.detach(), x.grad))
    assert results[1][1].abs() > 0
    assert torch.equal(results[0][0], results[1][0]) and torch.equal(results[0][1], results[1][1])


def test_friction_is_friction_times_ratio_whichever_is_set_last(f32):
    """Genesis's rule: a geom's friction is its friction (set_friction) × its per-env ratio
    (set_friction_ratio), each kept when the other is set (the ratio scaled the build's friction and
    set_friction dropped the ratio: 0.25 then ratio 2 gave 2.0, ratio 0.5 then 0.8 gave 0.8). In
    float32, whose 0.01 lies below 0.01, set_friction takes its documented lower bound."""
    scene = gs.Scene(show_viewer=False)
    scene.add_entity(gs.morphs.Plane())
    box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.2, 0.1), pos=(0.0, 0.0, 0.05)))
    scene.build(n_envs=2)

    def friction(kind=0):  # (0 sliding, 1 torsional, 2 rolling)
        return scene.sim.inputs(scene._rigid_solver)["friction"][:, 3 * box.geom_start + kind].tolist()

    box.set_friction(0.25)
    box.set_friction_ratio([[2.0], [3.0]])
    assert friction() == pytest.approx([0.5, 0.75])
    assert friction(1) == pytest.approx([0.01, 0.015]) and friction(2) == pytest.approx([2e-4, 3e-4])  # (as Genesis)
    box.set_friction_torsional(0.02)
    box.set_friction_rolling(0.001)
    assert friction(1) == pytest.approx([0.04, 0.06]) and friction(2) == pytest.approx([0.002, 0.003])
    assert friction() == pytest.approx([0.5, 0.75])
    box.set_friction(0.8)
    assert friction() == pytest.approx([1.6, 2.4])
    box.set_friction_ratio([0.5], envs_idx=[1])
    assert friction() == pytest.approx([1.6, 0.4])
    box.set_friction(0.01)


def test_friction_and_ratio_set_in_one_rollout_are_detached_by_reset(f64):
    """The entity keeps friction and ratio between calls; a reset detaches them as the scene's
    parameters, so a later rollout's backward does not run through the earlier one's graph (it
    raised 'backward through the graph a second time')."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True), show_viewer=False)
    scene.add_entity(gs.morphs.Plane())
    box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.2, 0.1), pos=(0.0, 0.0, 0.05)))
    scene.build()
    ratio = torch.tensor([1.5], dtype=torch.float64, requires_grad=True)
    friction = torch.tensor(0.9, dtype=torch.float64, requires_grad=True)
    grads = []
    for set_param in (lambda: box.set_friction_ratio(ratio), lambda: box.set_friction(friction)):
        scene.reset()
        set_param()
        box.set_dofs_velocity([1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
        for _ in range(5):
            scene.step()
        box.get_pos()[0].backward()
        grads.append(ratio.grad.clone())
    assert grads[0] != 0.0 and friction.grad != 0.0  # (0.9 × 1.5 above the plane's 1.0: the box's friction acts)
    assert torch.equal(grads[1], grads[0])  # the second rollout reaches the ratio no more


def test_batched_equals_single_with_contact(f64):
    assert_batch_equals_single(4)


def test_batched_equals_single_with_torsional_and_rolling_friction(f64):
    """The same with condim 6 contacts (elliptic cone), a box sliding and spinning."""
    assert_batch_equals_single(3, cone="elliptic", condim=6, case="sliding_velocity")


def assert_batch_equals_single(n_envs, cone="pyramidal", condim=3, case="tilted"):
    """A batch of n_envs gives each env's gradient of a single-env scene, bit for bit (with n_envs ×
    dofs past SERIAL_SOLVE_WORK the solve runs on the thread pool: tests/test_compile_once.py)."""
    batched_scene, batched_body = _scene(cone, n_envs=n_envs, tag="batched", condim=condim)
    on_calling_thread = batched_scene.sim.slots[0].solver.data.solve_schedule[0]
    assert on_calling_thread == (n_envs * batched_scene._rigid_solver.model.n_dofs <= SERIAL_SOLVE_WORK)
    batched = _gradient(batched_scene, batched_body, case, 30)
    scene, body = _scene(cone, tag="batched", condim=condim)  # both with the build's parameters
    loss_of, nominal = CASES[case]
    for e in sorted({0, n_envs // 3, 2 * n_envs // 3, n_envs - 1}):
        x = _batch(n_envs, nominal())[e].clone().requires_grad_(True)
        scene.reset()
        loss_of(scene, body, x, 30).backward()
        assert torch.equal(x.grad, batched[e]), e


# curved convex pairs: a body dropped with a spin onto a fixed ground → its final pose; (ground, body)
CURVED_SCENES = {
    "cylinder-box side": ("box", lambda: gs.morphs.Cylinder(radius=0.05, height=0.2, pos=(0, 0, 0.049),
                                                            euler=(90, 0, 0))),
    "cylinder-box rim": ("box", lambda: gs.morphs.Cylinder(radius=0.05, height=0.2, pos=(0, 0, 0.12),
                                                           euler=(30, 10, 0))),
    "cylinder-cylinder tipped onto a cap": ("cylinder", lambda: gs.morphs.Cylinder(radius=0.05, height=0.2,
                                                                            pos=(0.05, 0, 0.12), euler=(30, 10, 0))),
    "cylinder-box cap": ("box", lambda: gs.morphs.Cylinder(radius=0.05, height=0.2, pos=(0, 0, 0.099))),
    "cylinder-cylinder cap on cap": ("cylinder", lambda: gs.morphs.Cylinder(radius=0.05, height=0.2,
                                                                            pos=(0.05, 0, 0.099))),
    "cylinder-capsule rim on a line": ("capsule", lambda: gs.morphs.Cylinder(radius=0.05, height=0.2,
                                                                              pos=(0, 0, 0.16), euler=(0, 40, 0))),
    "cylinder-mesh rim on face": ("mesh", lambda: gs.morphs.Cylinder(radius=0.05, height=0.2, pos=(0.05, 0, 0.3),
                                                                     euler=(30, 10, 0))),
}
SPIN = (0.3, 0.1, -0.2, 0.5, 0.4, 1.0)


def _curved_scene(ground, morph, cone="pyramidal", compat=False, n_envs=0):
    """A fixed ground (a 1 m box or a 0.3 m-radius cylinder with their tops at z = 0, an
    octahedron mesh 0.25 m tall whose top vertex is at z = 0.1875, or a capsule of radius 5 cm
    lying along y at z = 0) and a free body on it."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True),
                     rigid_options=gs.options.RigidOptions(tolerance=1e-14, friction_cone=cone,
                                                           enable_mujoco_compatibility=compat), show_viewer=False)
    if ground == "box":
        scene.add_entity(gs.morphs.Box(size=(1.0, 1.0, 0.2), pos=(0, 0, -0.1), fixed=True))
    elif ground == "cylinder":
        scene.add_entity(gs.morphs.Cylinder(radius=0.3, height=0.2, pos=(0, 0, -0.1), fixed=True))
    elif ground == "capsule":
        scene.add_entity(gs.morphs.Capsule(radius=0.05, height=0.6, euler=(90, 0, 0), fixed=True))
    else:
        path = os.path.join(tempfile.mkdtemp(), "octahedron.obj")
        vertices = [(0.5, 0, 0), (-0.5, 0, 0), (0, 0.75, 0), (0, -0.75, 0), (0, 0, 0.25), (0, 0, -0.25)]
        trimesh.Trimesh(vertices).convex_hull.export(path)
        scene.add_entity(gs.morphs.Mesh(file=path, pos=(0, 0, -0.0625), fixed=True))
    body = scene.add_entity(morph)
    scene.build(n_envs=n_envs)
    return scene, body


@pytest.mark.parametrize("case, cone", [(case, "pyramidal") for case in CURVED_SCENES] + [("cylinder-box rim",
                                                                                        "elliptic")])
def test_curved_convex_pairs(f64, case, cone):
    """Contacts of a cylinder through the convex collider, which iterates on its rim: the forward
    takes the converged closed form of each contact's feature (converge_contacts), so the step is
    that closed form's map and its reverse is exact. A body with an initial spin (6) → its pose
    after 40 steps; it touches the ground in at least 10 of them (some roll or slide off)."""
    ground, morph = CURVED_SCENES[case]
    scene, body = _curved_scene(ground, morph(), cone)
    touching = []

    def loss(x):
        scene.reset()
        body.set_dofs_velocity(x)
        touching.clear()
        for _ in range(40):
            scene.step()
            touching.append(bool((scene._rigid_solver.contacts()[..., 0] >= 0).any()))
        return (body.get_pos() * torch.tensor([1.0, 2.0, 5.0])).sum() + body.get_quat()[1:].sum()

    assert_converged(directional_errors(loss, torch.tensor(SPIN, dtype=torch.float64)), f"{case} {cone}")
    assert sum(touching) >= 10, f"{case}: the body touched the ground in {sum(touching)} of 40 steps"


def test_curved_convex_gradients_repeat_and_batch(f64):
    """Through converged contacts (a cylinder tipping onto its rim, then its side, on a box, and
    standing on its cap), a repeated rollout gives the same gradient bit for bit, and n_envs = 3
    gives each env's gradient of a single-env scene."""
    velocity = _batch(3, torch.tensor(SPIN, dtype=torch.float64))

    def gradients(scene, body, x):
        x = x.clone().requires_grad_(True)
        scene.reset()
        body.set_dofs_velocity(x)
        _roll(scene, 40)
        (body.get_pos().sum() + body.get_quat()[..., 1:].sum()).backward()
        return x.grad

    for case in ("cylinder-box rim", "cylinder-box cap"):
        ground, morph = CURVED_SCENES[case]
        batched = gradients(*_curved_scene(ground, morph(), n_envs=3), velocity)
        single = _curved_scene(ground, morph())
        for e in range(3):
            first = gradients(*single, velocity[e])
            assert torch.equal(first, batched[e]) and torch.equal(first, gradients(*single, velocity[e])), (case, e)


def test_mujoco_compatible_curved_contacts_refuse_a_backward(f64):
    """Under enable_mujoco_compatibility a curved convex contact stays MuJoCo's iterate (a can tilted
    0.3 rad on its rim on a box; standing or lying flat it takes rim points, closed forms): a
    backward over it says so, never a silent zero or an approximate gradient, and names the step,
    the contact's shapes, links and entities, its env and substep (it listed every pair kind of
    the scene that could be inexact)."""
    tilt = 0.3
    morph = gs.morphs.Cylinder(radius=0.05, height=0.2, pos=(0, 0, 0.1 * np.cos(tilt) + 0.05 * np.sin(tilt) - 1e-3),
                               euler=(np.degrees(tilt), 0, 0))
    scene, can = _curved_scene("box", morph, compat=True)
    velocity = torch.zeros(6, dtype=torch.float64, requires_grad=True)
    can.set_dofs_velocity(velocity)
    scene.step()
    with pytest.raises(gs.GradientError, match="enable_mujoco_compatibility") as raised:
        can.get_pos().sum().backward()
    assert str(raised.value).startswith("step 0's backward")
    assert ("the cylinder–box contact of link 'cylinder' of entity 'cylinder_1' and link 'box' of entity 'box_0' "
            "(env 0, substep 0)") in str(raised.value)


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
@pytest.mark.parametrize("shape", ["capsule", "cylinder"])
@pytest.mark.parametrize("width", [1.0, 0.12])
def test_lying_on_a_mesh_face(f64, shape, cone, width):
    """A capsule or a can lying on a fixed mesh table, sliding, turning and (the can) rolling: its
    contacts are the two ends of its line (convex._lying_on_mesh, closed forms of the core's kind),
    or on a table narrower than it (0.12 m along its axis) where the line crosses the table's edges.
    Initial velocity → final pose."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True),
                     rigid_options=gs.options.RigidOptions(tolerance=1e-14, friction_cone=cone), show_viewer=False)
    path = os.path.join(tempfile.mkdtemp(), "table.obj")
    trimesh.creation.box(extents=(1.0, width, 0.2)).export(path)
    scene.add_entity(gs.morphs.Mesh(file=path, pos=(0, 0, -0.1), fixed=True))
    morph = gs.morphs.Capsule if shape == "capsule" else gs.morphs.Cylinder
    body = scene.add_entity(morph(radius=0.04, height=0.2, pos=(0, 0, 0.04 - 1e-3), euler=(90, 0, 0)))
    scene.build()

    def loss(velocity):
        scene.reset()
        body.set_dofs_velocity(velocity)
        for _ in range(50):
            scene.step()
        return (body.get_pos() * torch.tensor([1.0, -0.7, 3.0])).sum() + body.get_quat()[1:].sum()

    start = torch.tensor([0.6, 0.2, 0.0, 0.0, 0.0, 0.5], dtype=torch.float64)
    loss(start)
    assert len(body.get_contacts()["position"]) == 2
    assert_converged(directional_errors(loss, start, 0), f"{shape} lying on a mesh face, {cone}")


def _poison_unkept(solver):
    """Every frame's solver_H and efc_J ← NaN: what the solve keeps of them is rewritten each
    substep, and nothing else of them may be read (constraint/solver.py, rows.py)."""
    data = solver.data
    floats, stride = data.arenas[1], data.start["stride:f:False"]
    count = {"solver_H": data.size["B"] * data.size["D"] ** 2,
             "efc_J": data.size["B"] * data.size["R"] * data.size["D"]}
    for frame in range(data.size["S"] + 1):
        for name, n in count.items():
            begin = data.start[f"frame:{name}"] + frame * stride
            floats[begin: begin + n] = float("nan")


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_the_solve_reads_only_what_it_keeps(f64, cone):
    """The solve factors H within each island's envelope and forms a row's Jacobian in its own
    columns, leaving the rest of both arrays as they were (zeroing them cost dofs² and rows × dofs
    a substep). With all of both set to NaN before every step, a rollout in which islands form and
    part (a box sliding into a second one, a sphere landing on a third, a tree no row touches, a
    dof with friction loss), in 2 envs, gives the same states and gradients bit for bit."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, substeps=2, requires_grad=True),
                     rigid_options=gs.options.RigidOptions(tolerance=1e-14, friction_cone=cone),
                     show_viewer=False)
    scene.add_entity(gs.morphs.Plane())
    bodies = [scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(x, 0.0, 0.0499))) for x in (0.0, 0.3, 0.8)]
    bodies.append(scene.add_entity(gs.morphs.Sphere(radius=0.04, pos=(0.8, 0.02, 0.2))))
    bodies.append(scene.add_entity(gs.morphs.Box(size=(0.05, 0.05, 0.05), pos=(2.0, 0.0, 1.0))))  # falling freely
    scene.build(n_envs=2)
    bodies[1].set_dofs_frictionloss(torch.full((2, 6), 0.05, dtype=torch.float64))
    velocity = torch.tensor([[2.0, 0.1, 0.0, 0.0, 0.0, 1.0], [2.2, -0.1, 0.0, 0.0, 0.0, -1.0]],
                            dtype=torch.float64)

    def rollout(poisoned):
        v = velocity.clone().requires_grad_(True)
        scene.reset()
        bodies[0].set_dofs_velocity(v)
        for _ in range(30):
            if poisoned:
                _poison_unkept(scene._rigid_solver)
            scene.step()
        end = torch.cat([body.get_pos() for body in bodies], dim=1)
        (end * torch.linspace(0.5, 1.5, end.shape[1], dtype=torch.float64)).sum().backward()
        return end.detach(), v.grad

    (clean_end, clean_grad), (end, grad) = rollout(False), rollout(True)
    assert bodies[1].get_pos()[:, 0].min() > 0.301  # (the first box pushed the second)
    assert torch.isfinite(grad).all() and grad.abs().sum() > 0
    assert torch.equal(end, clean_end) and torch.equal(grad, clean_grad)


def _forget_the_solves(solver):
    """Every frame's qacc_constrained and solver_jar ← NaN (what a replay given the record reads)."""
    for s in range(solver.data.size["S"] + 1):
        for name in ("qacc_constrained", "solver_jar"):
            solver.data.frame(name, s).fill_(float("nan"))


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_a_replay_from_the_solutions_repeats_a_replay_from_the_warm_start(f64, cone):
    """A backward replays its step to refill the frames. Given the step's solutions (the solver's
    replay_record) the replay makes the solve's outputs from them without iterating; given the
    warm start instead it solves again, as the forward did. At the default tolerance (a solution
    that a further iteration would move), in a rollout in which islands form and part, with
    friction loss, 2 envs and 2 substeps, both give the same gradients bit for bit, every step."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, substeps=2, requires_grad=True),
                     rigid_options=gs.options.RigidOptions(friction_cone=cone), show_viewer=False)
    scene.add_entity(gs.morphs.Plane())
    bodies = [scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(x, 0.0, 0.0499))) for x in (0.0, 0.3)]
    bodies.append(scene.add_entity(gs.morphs.Sphere(radius=0.04, pos=(0.3, 0.02, 0.2))))
    scene.build(n_envs=2)
    bodies[1].set_dofs_frictionloss(torch.full((2, 6), 0.05, dtype=torch.float64))
    bodies[0].set_dofs_velocity(torch.tensor([[2.0, 0.1, 0.0, 0.0, 0.0, 1.0], [2.2, -0.1, 0.0, 0.0, 0.0, -1.0]],
                                             dtype=torch.float64))
    solver, generator = scene._rigid_solver, torch.Generator().manual_seed(0)
    inputs = scene.sim.inputs(solver)
    state, replays = scene.sim.state(solver), 0
    for _ in range(30):
        warm_start = solver.warm_start()
        following = solver.advance(inputs, download=True)
        record, next_warm_start = solver.replay_record(), solver.warm_start()
        seed = torch.randn(following.shape, dtype=torch.float64, generator=generator)
        _forget_the_solves(solver)
        replayed = solver.backward(state, inputs, seed, record=record)
        solved = solver.backward(state, inputs, seed, warm_start=warm_start)
        assert torch.equal(solved[0], replayed[0])
        assert all(torch.equal(solved[1][name], replayed[1][name]) for name in solved[1])
        replays += record is not None
        solver.upload_state(following)  # (the replays overwrote the forward's end)
        solver.set_warm_start(next_warm_start)
        state = following
    assert replays > 20 and state[:, 7].min() > 0.301  # (the first box pushed the second: its x)


def _replay_bytes(node):
    """Bytes of the replay records (or warm starts) the graph's step nodes (autograd._Segment: the
    steps between two reads of the state) from ``node`` down keep; 0 for a node whose saved
    tensors torch has freed."""
    seen, stack, total = set(), [node], 0
    while stack:
        fn = stack.pop()
        if fn is None or id(fn) in seen:
            continue
        seen.add(id(fn))
        if hasattr(fn, "segment"):
            try:
                saved = fn.saved_tensors
                total += sum(saved[k].numel() * saved[k].element_size() for step in fn.segment.steps
                             for k in _leaves(step.layout))
            except RuntimeError as error:  # ("... after they have already been freed")
                assert "freed" in str(error)
        stack.extend(following for following, _ in fn.next_functions)
    return total


def _leaves(layout):
    """The saved tensors' indices in a step's replay layout (nested tuples of ints and Nones)."""
    if isinstance(layout, int):
        return [layout]
    return [k for branch in layout for k in _leaves(branch)] if isinstance(layout, tuple) else []


@pytest.mark.parametrize("boxes, substeps", [(1, 1), (3, 10)])
def test_replay_records_are_bounded_and_freed_with_the_graph(f64, boxes, substeps):
    """A kept step's replay record (the solve's qacc and jar per substep) is saved by torch, so a
    backward frees it; a record over REPLAY_RECORD_STATES states an env (three touching boxes,
    10 substeps: ~17) is not kept, the step's warm start is (a dof count an env), and its replay
    solves again: the same gradient bits as a rollout whose steps all solve again (checkpoints)."""
    def rollout(interval):
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, substeps=substeps, requires_grad=True,
                                                           checkpoint_interval=interval), show_viewer=False)
        scene.add_entity(gs.morphs.Plane())
        bodies = [scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(0.1 * k, 0.0, 0.0499)))
                  for k in range(boxes)]
        scene.build(n_envs=2)
        v = torch.tensor([[1.0, 0.2, 0.0, 0.0, 0.0, 0.5], [0.8, -0.2, 0.0, 0.0, 0.0, -0.5]], dtype=torch.float64)
        v.requires_grad_(True)
        bodies[0].set_dofs_velocity(v)
        for _ in range(10):
            scene.step()
        loss = sum((body.get_pos() * torch.tensor([1.0, 0.5, 2.0])).sum() for body in bodies)
        state = scene.sim.state(scene._rigid_solver)
        kept = _replay_bytes(state.grad_fn)
        loss.backward()
        return v.grad, kept, _replay_bytes(state.grad_fn), state[0].numel() * state.element_size()

    grad, kept, after, state_bytes = rollout(1)
    assert after == 0
    if boxes == 1:  # qacc and the rows' jar, 2 envs, 10 steps
        assert 10 * 2 * 6 * 8 < kept <= 10 * 2 * REPLAY_RECORD_STATES * state_bytes
    else:  # the warm start alone (2 envs × 18 dofs a step)
        assert kept == 10 * 2 * 18 * 8
    assert torch.equal(grad, rollout(1000)[0])


def test_a_backward_that_stops_midway_leaves_the_next_steps_as_they_were(f64, monkeypatch):
    """A backward that raises during its replay (an error, an interrupt) left the replay's
    settings behind: the next forward step ran uncommitted and took the replay's solutions
    (Simulator.backward_step ends every backward with Solver.end_backward). The steps after it
    equal those of a rollout that took no backward, bit for bit."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True), show_viewer=False)
    scene.add_entity(gs.morphs.Plane())
    box = scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(0.0, 0.0, 0.0499)))
    scene.build(n_envs=2)
    velocity = torch.tensor([[1.0, 0.2, 0.0, 0.0, 0.0, 0.5], [0.8, -0.2, 0.0, 0.0, 0.0, -0.5]], dtype=torch.float64)

    def rollout(interrupted):
        scene.reset()
        box.set_dofs_velocity(velocity.clone().requires_grad_(True))
        for _ in range(5):
            scene.step()
        if interrupted:
            def stop(*args):  # (the replay's constraint stage)
                raise KeyboardInterrupt
            monkeypatch.setattr(scene._rigid_solver, "constrain", stop)
            with pytest.raises(KeyboardInterrupt):
                box.get_pos().sum().backward()
            monkeypatch.undo()
        for _ in range(5):
            scene.step()
        return box.get_dofs_velocity().detach()

    assert torch.equal(rollout(True), rollout(False))


@pytest.mark.parametrize("setter, interval, loss_at", [(False, 1, 8), (True, 1, 8), (False, 4, 8), (True, 4, 8),
                                                     (False, 1, 4)])
def test_a_rollout_steps_on_after_a_backward_as_without_it(f64, setter, interval, loss_at):
    """A backward's replays overwrite the constraint solve's warm start, and the next forward step
    started from a cleared one (a stack of boxes: 1.8e-17 m/s apart after 8 steps): the simulator
    keeps the forward's before anything of the backward runs (Simulator.hold_before_backward: the
    recomputation of a checkpointed segment, interval 4, and the upload of an older state by a
    getter's backward, a loss read at step 4 only, come first) and puts it back on the next upload
    (_sync_state), also for the envs a setter leaves alone. The steps after a backward equal those
    of a rollout without it, bit for bit."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True, checkpoint_interval=interval),
                     show_viewer=False)
    scene.add_entity(gs.morphs.Plane())
    boxes = [scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(0.01 * k, 0.0, 0.05 + 0.1 * k),
                                            euler=(0, 0, 10 * k))) for k in range(3)]
    scene.build(n_envs=2)
    velocity = torch.tensor([[0.3, 0.2, 0.0, 0.0, 0.0, 0.5], [0.2, -0.2, 0.0, 0.0, 0.0, -0.5]], dtype=torch.float64)

    def rollout(backward):
        scene.reset()
        boxes[0].set_dofs_velocity(velocity.clone().requires_grad_(True))
        for step in range(8):
            scene.step()
            if step + 1 == loss_at:
                loss = boxes[2].get_pos().sum()
        if backward:
            loss.backward()
        if setter:  # env 1's middle box stopped: env 0 steps on from the forward's warm start
            boxes[1].set_dofs_velocity(torch.zeros(1, 6, dtype=torch.float64), envs_idx=[1])
        for _ in range(8):
            scene.step()
        return torch.cat([box.get_dofs_velocity().detach() for box in boxes], 1)

    assert torch.equal(rollout(True), rollout(False))


def test_a_mesh_resting_on_a_mesh_by_a_polygon_vertex(f64, tmp_path):
    """A small convex mesh (5-vertex hull) tipped onto a fixed mesh slab, pyramidal cone: its
    contacts are clipped-polygon vertices (no side plane in their feature), whose closed form read
    a clipping-face vertex at index −256 (convex._clip_terms) and crashed the backward (a
    segfault here). The initial pose's gradient of the final pose agrees with finite
    differences."""
    trimesh.creation.box(extents=(0.4, 0.4, 0.06)).export(tmp_path / "slab.obj")
    trimesh.convex.convex_hull(np.array([[0.05, 0, 0], [-0.04, 0.04, 0], [-0.04, -0.05, 0.01], [0, 0, 0.07],
                                         [0.01, 0.02, -0.03]])).export(tmp_path / "tip.obj")
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True),
                     rigid_options=gs.options.RigidOptions(tolerance=1e-14), show_viewer=False)
    scene.add_entity(gs.morphs.Mesh(file=str(tmp_path / "slab.obj"), pos=(0, 0, 0.03), fixed=True))
    body = scene.add_entity(gs.morphs.Mesh(file=str(tmp_path / "tip.obj"), pos=(0, 0, 0.11), euler=(10, 5, 0)))
    scene.build()
    start = torch.tensor([0.0249, -0.0015, 0.0743, 0.5654, 0.1719, 0.0833], dtype=torch.float64)
    spin = torch.tensor([0.115, -0.06, -0.041, 4.28, 6.63, -4.0], dtype=torch.float64)

    def loss(q):
        scene.reset()
        body.set_dofs_position(q)
        body.set_dofs_velocity(spin)
        for _ in range(15):
            scene.step()
        return (body.get_pos() * torch.tensor([1.0, -0.7, 3.0])).sum() + (body.get_quat() * 0.3).sum()

    assert_converged(directional_errors(loss, start), "mesh on mesh")


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_finger_masses_reach_a_squeezed_cube_through_the_sliding_leaves_scale(f64, cone, tmp_path):
    """The fingers' masses → where a cube they squeeze slips to: a sliding leaf's contact rows are
    scaled by 1 / its mass (MuJoCo's body_simple 2; contact.sliding_leaves), so the mass reaches
    the rows' R there as well as M. Central FD, eps scan (fails with that 1 / mass held constant)."""
    path = tmp_path / "gripper.urdf"
    path.write_text(GRIPPER)
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002, requires_grad=True), show_viewer=False,
                     rigid_options=gs.options.RigidOptions(friction_cone=cone))
    gripper = scene.add_entity(gs.morphs.URDF(file=str(path), fixed=True))
    cube = scene.add_entity(gs.morphs.Box(size=(0.04, 0.04, 0.04), pos=(0.0, 0.0, 0.1)))
    scene.build()
    assert scene._rigid_solver.invweight_basis.simple_links.tolist() == [1, 2]
    fingers = [link.idx_local for link in gripper.links if link.name in ("left", "right")]

    def loss(masses):
        scene.reset()
        gripper.set_links_mass(masses, fingers)
        gripper.control_dofs_force(torch.tensor([0.5, 0.4], dtype=torch.float64))
        _roll(scene, 40)
        return 1e3 * (cube.get_pos() * torch.tensor([1.0, 2.0, 3.0])).sum()
    try:
        assert_converged(directional_errors(loss, torch.tensor([0.02, 0.03], dtype=torch.float64)), f"{cone} masses")
    finally:
        scene.destroy()


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_tied_frictions_share_the_gradient_as_central_differences_do(f64, cone):
    """A box and the plane at the same friction (both Genesis's default 1.0): the pair's μ, the
    larger, follows either upward and neither downward, so central differences in either alone
    converge to half the pair's derivative; the gradient gives each half (given all to the plane,
    the box's friction had a gradient of exactly zero). Scanned along two random directions of
    (box ratio, plane ratio), which pin both components."""
    scene, body = _scene(cone, tag="tie")
    plane = scene.entities[0]

    def loss(ratios):
        _start(body, 0, *SLIDE)
        body.set_friction_ratio(ratios[:1])
        plane.set_friction_ratio(ratios[1:])
        _roll(scene, 20)
        return body.get_pos()[0] + 0.3 * body.get_pos()[1]
    tie = torch.tensor([1.0, 1.0], dtype=torch.float64)
    for seed in (0, 1):
        assert_converged(directional_errors(loss, tie, seed=seed), f"{cone} tie, direction {seed}")
    ratios = tie.clone().requires_grad_(True)
    loss(ratios).backward()
    assert ratios.grad[0] != 0.0 and ratios.grad[0] == ratios.grad[1]
