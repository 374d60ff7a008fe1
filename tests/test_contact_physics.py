"""Contact physics against references no one here wrote: MuJoCo trajectories, closed-form
mechanics (Coulomb sliding, rolling on an incline), and rest. Every analytic case also runs in
MuJoCo inside the test, to show we are as close to the closed form as it is.

MuJoCo's defaults on both sides (``enable_mujoco_compatibility``), dt 2 ms, float64.
"""
import mujoco
import numpy as np
import pytest
import torch

import genesis_lite as gs
from genesis_lite.solvers.rigid import contact
from tests.contact_scenes import Body, ContactScene, a1_mujoco, build_mujoco, build_ours

G = 9.81


def _run(spec, steps, before_step=None, mujoco_spec=None):
    """(ours, MuJoCo's) qpos trajectories (steps + 1, nq) from the spec's initial state
    (MuJoCo's model from mujoco_spec when given)."""
    scene, entities = build_ours(spec)
    if before_step:
        before_step(scene, entities)
    m = build_mujoco(mujoco_spec or spec, scene._rigid_solver.model)
    d = mujoco.MjData(m)
    if before_step:
        m.opt.gravity[:] = scene._rigid_solver.default_inputs["gravity"][0].cpu().numpy()
        m.geom_friction[:] = scene.sim.inputs(scene._rigid_solver)["friction"][0].cpu().numpy().reshape(-1, 3)
    d.qpos[:] = np.concatenate([e.get_qpos().cpu().numpy() for e in entities])
    d.qvel[:] = np.concatenate([e.get_dofs_velocity().cpu().numpy() for e in entities])
    mujoco.mj_forward(m, d)
    ours, theirs = [d.qpos.copy()], [d.qpos.copy()]
    for _ in range(steps):
        scene.step()
        mujoco.mj_step(m, d)
        ours.append(np.concatenate([e.get_qpos().cpu().numpy() for e in entities]))
        theirs.append(d.qpos.copy())
    return np.array(ours), np.array(theirs), scene, entities


def _spin(entities, omega):
    for e in entities:
        e.set_dofs_velocity(torch.tensor([0.0, 0.0, 0.0, *omega], dtype=gs.tc_float))


@pytest.mark.parametrize("shape", ["box", "sphere", "capsule"])
def test_dropped_with_spin_follows_mujoco(f64, shape):
    """0.5 s: landing, bouncing and rolling, ≤ 1e-6 from MuJoCo's trajectory."""
    body = {"box": Body("box", (0.2, 0.3, 0.1), pos=(0, 0, 0.3), quat=(0.9, 0.3, 0.2, 0.1)),
            "sphere": Body("sphere", (0.1,), pos=(0, 0, 0.3)),
            "capsule": Body("capsule", (0.05, 0.2), pos=(0, 0, 0.3), quat=(0.8, 0.5, 0.3, 0.1))}[shape]
    ours, theirs, _, _ = _run(ContactScene([body]), 250, lambda scene, ents: _spin(ents, (3.0, -2.0, 5.0)))
    assert ours[-1][2] < 0.2, "it landed"
    assert np.abs(ours - theirs).max() < 1e-6


def test_box_rests(f64):
    """Penetration ≤ 1 mm, drift ≤ 1 mm over 5 s, speed < 1e-3 m/s after 2 s (MuJoCo alike)."""
    spec = ContactScene([Body("box", (0.2, 0.2, 0.2), pos=(0, 0, 0.1))])
    ours, theirs, scene, (box,) = _run(spec, 2500)
    for traj in (ours, theirs):
        assert 0.1 - traj[:, 2].min() <= 1e-3
        assert np.abs(traj[-1, :3] - traj[1000, :3]).max() <= 1e-3
    assert float(box.get_dofs_velocity().abs().max()) < 1e-3


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_sliding_box_stops_at_coulomb_distance(f64, cone):
    """1 kg-ish box launched at 1 m/s, μ 0.5: stops within 3 % of v²/(2μg)."""
    spec = ContactScene([Body("box", (0.1, 0.1, 0.1), pos=(0, 0, 0.05))], cone=cone)

    def launch(scene, entities):
        entities[0].set_friction(0.2)
        scene.entities[0].set_friction(0.5)  # the plane's: a contact takes the larger (MuJoCo's rule)
        entities[0].set_dofs_velocity(torch.tensor([1.0, 0, 0, 0, 0, 0], dtype=gs.tc_float))

    ours, theirs, _, _ = _run(spec, 300, launch)
    expected = 1.0 / (2 * 0.5 * G)
    for traj in (ours, theirs):
        assert abs(traj[-1, 0] - expected) <= 0.03 * expected, (traj[-1, 0], expected)


def test_smooth_contact_is_mujoco_with_zero_onset_impedance(f64):
    """RigidOptions(smooth_contact=True) is MuJoCo with solimp (0, 0.95, 0.001, 0.5, 2) and the
    elliptic cone: a tilted box dropped with spin follows MuJoCo's trajectory (0.5 s, ≤ 1e-6),
    then rests within 1 mm of its size (penetration, drift), and a box launched at 1 m/s with μ
    0.5 stops within 3 % of v²/(2μg)."""
    body = Body("box", (0.2, 0.3, 0.1), pos=(0, 0, 0.3), quat=(0.9, 0.3, 0.2, 0.1))
    ours_spec = ContactScene([body], cone="elliptic", options={"smooth_contact": True})
    mujoco_spec = ContactScene([body], cone="elliptic", solimp=(0.0, 0.95, 0.001, 0.5, 2.0))
    ours, theirs, _, _ = _run(ours_spec, 1500, lambda scene, ents: _spin(ents, (3.0, -2.0, 5.0)),
                              mujoco_spec)
    assert np.abs(ours[:251] - theirs[:251]).max() < 1e-6
    assert 0.05 - ours[1000:, 2].min() <= 1e-3 and np.abs(ours[-1, :3] - ours[1000, :3]).max() <= 1e-3

    slide = ContactScene([Body("box", (0.1, 0.1, 0.1), pos=(0, 0, 0.05))], cone="elliptic",
                         options={"smooth_contact": True})

    def launch(scene, entities):
        scene.entities[0].set_friction(0.5)
        entities[0].set_friction(0.2)
        entities[0].set_dofs_velocity(torch.tensor([1.0, 0, 0, 0, 0, 0], dtype=gs.tc_float))

    ours, theirs, _, _ = _run(slide, 300, launch, ContactScene(slide.bodies, cone="elliptic",
                                                               solimp=(0.0, 0.95, 0.001, 0.5, 2.0)))
    expected = 1.0 / (2 * 0.5 * G)
    for traj in (ours, theirs):
        assert abs(traj[-1, 0] - expected) <= 0.03 * expected, (traj[-1, 0], expected)


@pytest.mark.parametrize("rolling", [True, False])
def test_sphere_on_incline(f64, rolling):
    """Gravity tilted by 20°: a sphere rolls at (5/7) g sinθ with μ 1, slides at g sinθ with μ 0
    (a contact's friction is at least 1e-5, MuJoCo's floor)."""
    theta = np.radians(20.0)
    spec = ContactScene([Body("sphere", (0.1,), pos=(0, 0, 0.1))])

    def incline(scene, entities):
        for e in scene.entities:
            e.set_friction_ratio(np.ones(e.n_links) * (1.0 if rolling else 0.0))
        solver = scene._rigid_solver
        gravity = torch.tensor([G * np.sin(theta), 0.0, -G * np.cos(theta)], dtype=gs.tc_float)
        solver.default_inputs["gravity"][:] = gravity
        scene.sim.set_input(solver, "gravity", gravity.expand(1, 3).clone())

    steps, h = 250, 0.002
    ours, theirs, _, _ = _run(spec, steps, incline)
    expected = (5.0 / 7.0 if rolling else 1.0) * G * np.sin(theta)
    for traj in (ours, theirs):
        accel = 2 * (traj[-1, 0] - traj[0, 0]) / (h * h * steps * (steps + 1))
        assert abs(accel - expected) <= 0.01 * expected, (accel, expected)


@pytest.mark.parametrize("plane", [{"normal": (np.sin(np.radians(20.0)), 0.0, np.cos(np.radians(20.0)))},
                                   {"euler": (0.0, 20.0, 0.0)},
                                   {"quat": (0.0, 1.0, 0.0, 0.0), "normal": (np.sin(np.radians(20.0)), 0.0,
                                                                              -np.cos(np.radians(20.0)))}],
                         ids=["normal", "euler", "flipped_twice"])
def test_sphere_rolls_down_a_tilted_plane(f64, plane):
    """A plane tilted by 20° about y, by its ``normal`` (Genesis's argument, in the morph's frame),
    by euler, or by a half turn about x of a plane whose normal points down (the two cancel): a
    sphere released on it rolls downhill (+x) at (5/7) g sin θ, as on the tilted-gravity incline
    above."""
    theta, radius, h, steps = np.radians(20.0), 0.1, 0.002, 250
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=h))
    scene.add_entity(gs.morphs.Plane(**plane))
    normal = np.array([np.sin(theta), 0.0, np.cos(theta)])
    sphere = scene.add_entity(gs.morphs.Sphere(radius=radius, pos=tuple(normal * radius)))
    scene.build()
    start = sphere.get_pos().numpy().copy()
    for _ in range(steps):
        scene.step()
    travel = sphere.get_pos().numpy() - start
    downhill = np.array([np.cos(theta), 0.0, -np.sin(theta)])
    accel = 2 * (travel @ downhill) / (h * h * steps * (steps + 1))
    expected = 5.0 / 7.0 * G * np.sin(theta)
    assert abs(accel - expected) <= 0.01 * expected, (accel, expected)
    assert abs(travel @ normal) < 1e-3 and abs(travel[1]) < 1e-9  # on the plane, straight down it


def test_tower_of_boxes_stands(f64):
    """10 boxes stacked, 5 s: the tower stands and comes to rest (max |qvel| < 1e-5)."""
    bodies = [Body("box", (0.2, 0.2, 0.2), pos=(0, 0, 0.1 + 0.2 * k)) for k in range(10)]
    ours, theirs, scene, entities = _run(ContactScene(bodies), 2500)
    assert np.abs(ours[-1, 0::7]).max() < 1e-3 and np.abs(ours[-1, 1::7]).max() < 1e-3  # no sideways drift
    assert ours[-1, 7 * 9 + 2] > 1.8  # the top box is still on top
    speed = max(float(e.get_dofs_velocity().abs().max()) for e in entities)
    assert speed < 1e-5


A1_STAND = np.tile([0.0, 0.8, -1.5], 4)  # hip, thigh, calf of each leg (rad)


def test_quadruped_holds_its_standing_pose(f64):
    """pybullet_data's a1 on a plane, PD servos holding a standing pose for 5 s: the base stays
    within 2 cm of its start height (MuJoCo, with position actuators of the same gains, too)."""
    from tests.conftest import pybullet
    path, z, kp, kv, dt = pybullet("a1", "a1.urdf"), 0.305, 100.0, 2.0, 0.002
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=dt),
                     rigid_options=gs.options.RigidOptions(enable_mujoco_compatibility=True), show_viewer=False)
    scene.add_entity(gs.morphs.Plane())
    robot = scene.add_entity(gs.morphs.URDF(file=path, pos=(0, 0, z)))
    scene.build()
    legs = np.arange(6, robot.n_dofs)
    robot.set_dofs_position(A1_STAND, legs)
    robot.set_dofs_kp(np.full(len(legs), kp), legs)
    robot.set_dofs_kv(np.full(len(legs), kv), legs)
    robot.control_dofs_position(A1_STAND, legs)
    m, d = a1_mujoco(path, z, A1_STAND, kp, kv, dt)
    for _ in range(2500):
        scene.step()
        mujoco.mj_step(m, d)
    assert abs(float(robot.get_pos()[2]) - z) < 0.02
    assert abs(d.qpos[2] - z) < 0.02
    assert len(robot.get_contacts(with_entity=scene.entities[0])["geom_a"]) == 4  # four feet


@pytest.mark.parametrize("shape", ["box", "sphere", "capsule"])
def test_float32_lands_and_rests(f32, shape):
    """float32: the same drops land without exploding and come to rest (speed < 1e-3)."""
    body = {"box": Body("box", (0.2, 0.3, 0.1), pos=(0, 0, 0.3), quat=(0.9, 0.3, 0.2, 0.1)),
            "sphere": Body("sphere", (0.1,), pos=(0, 0, 0.3)),
            "capsule": Body("capsule", (0.05, 0.2), pos=(0, 0, 0.3), quat=(0.8, 0.5, 0.3, 0.1))}[shape]
    scene, (entity,) = build_ours(ContactScene([body]))
    for _ in range(1500):
        scene.step()
    assert torch.isfinite(entity.get_qpos()).all()
    assert 0.0 < float(entity.get_pos()[2]) < 0.2
    assert float(entity.get_dofs_velocity().abs().max()) < 1e-3


def test_float32_upright_cylinders_stand_whatever_their_yaw(f32):
    """float32, MuJoCo's plane–cylinder rule: cylinders standing on the plane, turned about their
    axis by 0–80°, stay on it for 0.4 s at their half height, touching it at every step. A turned
    unit axis is off unit by ~1e-7 in float32, which once made the rim the axis: no contact, and
    the larger can fell 0.37 m through the floor."""
    yaws = np.radians([0.0, 15.0, 30.0, 45.0, 60.0, 80.0])
    sizes = ((0.41, 0.22), (0.1, 0.1), (0.05, 0.2))  # (radius, half height) m
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002), show_viewer=False,
                     rigid_options=gs.options.RigidOptions(enable_mujoco_compatibility=True))
    scene.add_entity(gs.morphs.Plane())
    cans = [scene.add_entity(gs.morphs.Cylinder(radius=r, height=2 * h, pos=(2.0 * k, 0.0, h)))
            for k, (r, h) in enumerate(sizes)]
    scene.build(n_envs=len(yaws))
    turned = torch.tensor(np.stack([np.cos(yaws / 2), 0 * yaws, 0 * yaws, np.sin(yaws / 2)], 1), dtype=gs.tc_float)
    for can in cans:
        can.set_quat(turned)
    for _ in range(200):
        scene.step()
        for can in cans:
            assert (can.get_contacts()["valid_mask"].sum(1) >= 3).all()
    for can, (_, h) in zip(cans, sizes):
        assert torch.allclose(can.get_pos()[:, 2], torch.full((len(yaws),), h, dtype=gs.tc_float), rtol=0, atol=1e-3)


def test_contact_readouts_of_a_batch_with_and_without_contacts(f64):
    """Two envs: a 2 kg box resting on the plane (four corner contacts) and one 1 m up (none). The
    contact rows past an env's count are geom −1 and zeros, so no read-out carries garbage: the net
    contact force on the resting box balances its weight, the flying box's is exactly 0."""
    mass, g = 2.0, 9.81
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002), show_viewer=False)
    scene.add_entity(gs.morphs.Plane())
    box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.2, 0.1), pos=(0.0, 0.0, 0.05)))
    scene.build(n_envs=2)
    box.set_links_mass(torch.tensor([[mass], [mass]], dtype=gs.tc_float))
    box.set_pos(torch.tensor([[0.0, 0.0, 0.05], [0.0, 0.0, 1.0]], dtype=gs.tc_float))
    for _ in range(200):  # settled; the second box falls 0.2 m, still in the air
        scene.step()
    solver = scene._rigid_solver
    raw = torch.full((2, solver.data.size["C"], 12), float("nan"), dtype=gs.tc_float)
    solver.kernels.read_contacts(0, raw)  # every element written, the unused rows too
    assert torch.equal(raw, solver.contacts())
    unused = raw[..., 0] < 0
    assert unused[1].all() and (~unused[0]).sum() == 4
    assert torch.all(raw[unused][:, 1] == -1) and torch.all(raw[unused][:, 2:] == 0)
    force = box.get_links_net_contact_force()
    assert torch.allclose(force[0, 0], torch.tensor([0.0, 0.0, mass * g], dtype=gs.tc_float), rtol=0, atol=1e-6)
    assert torch.equal(force[1], torch.zeros(1, 3, dtype=gs.tc_float))
    found = box.get_contacts()
    assert found["valid_mask"].sum(1).tolist() == [4, 0]
    # as Genesis, trimmed to the most contacts in one env (4 here, not the slots); is_padded keeps the slots
    assert found["geom_a"].shape == (2, 4) and found["position"].shape == (2, 4, 3)
    assert box.get_contacts(is_padded=True)["valid_mask"].shape == (2, solver.data.size["C"])
    assert torch.all(found["position"][~found["valid_mask"]] == 0)
    empty = found["geom_a"] < 0  # an empty slot's geoms and links are -1, as Genesis pads (not link 0's)
    assert empty[1].all() and all(torch.all(found[k][empty] == -1) for k in ("geom_b", "link_a", "link_b"))
    with pytest.raises(gs.InvalidInputError, match="argument 'with_entity' must be a rigid entity of the same scene"):
        box.get_contacts(with_entity=0)
    with pytest.raises(gs.InvalidInputError, match="argument 'exclude_self_contact' must be True or False"):
        box.get_contacts(exclude_self_contact="no")
    with pytest.raises(gs.InvalidInputError, match="argument 'is_padded' must be True or False"):
        box.get_contacts(is_padded=1)


def test_net_contact_force_of_each_link_is_the_sum_of_its_contacts(f64):
    """Three boxes stacked on the plane in two envs (the middle one is geom 1 of one pair and geom 2
    of another): get_links_net_contact_force (a kernel's sum per link) equals the sum of
    every contact's force_a on link_a and force_b on link_b (get_contacts' rows, the entity's or not),
    per env and link; each box's net contact force holds its own weight (the bottom one's: the
    plane's push of all three less the two boxes above)."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002), show_viewer=False)
    scene.add_entity(gs.morphs.Plane())
    boxes = [scene.add_entity(gs.morphs.Box(size=(0.2, 0.2, 0.1), pos=(0.01 * k, 0.0, 0.05 + 0.1 * k)))
             for k in range(3)]
    scene.build(n_envs=2)
    for _ in range(100):
        scene.step()
    found = boxes[0].get_contacts()
    n_links = scene._rigid_solver.model.n_links
    expected = torch.zeros(2, n_links, 3, dtype=gs.tc_float)
    for side in ("a", "b"):
        links, forces = found[f"link_{side}"].long(), found[f"force_{side}"] * (found["geom_a"] >= 0)[..., None]
        expected.scatter_add_(1, links.clamp(min=0)[..., None].expand(-1, -1, 3), forces)
    for box in boxes:
        torch.testing.assert_close(box.get_links_net_contact_force()[:, 0], expected[:, box.link_start], rtol=0,
                                   atol=1e-9)
    weight = float(boxes[0].get_mass()[0]) * 9.81
    np.testing.assert_allclose(boxes[0].get_links_net_contact_force()[:, 0, 2].numpy(), [weight] * 2, rtol=1e-3)
    np.testing.assert_allclose(boxes[2].get_links_net_contact_force()[:, 0, 2].numpy(), [weight] * 2, rtol=1e-3)


def test_contacts_of_envs_a_reset_or_setter_replaced_are_gone_until_the_next_step(f64):
    """Two envs with a box resting on the plane: after reset(envs_idx=[1]) and after set_pos, the
    envs whose state was replaced report no contact and no contact force (the last step's held
    for a box now in the air: stale observations right after a reset), the others keep theirs; the
    next step finds contacts again (Genesis clears its collider when a state is set)."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002), show_viewer=False)
    scene.add_entity(gs.morphs.Plane())
    box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.2, 0.1), pos=(0.0, 0.0, 0.05)))
    scene.build(n_envs=2)

    def counts():
        return box.get_contacts()["valid_mask"].sum(1).tolist(), box.get_links_net_contact_force()[:, 0, 2].tolist()

    for _ in range(20):
        scene.step()
    assert counts()[0] == [4, 4]
    scene.reset(envs_idx=[1])
    found, force = counts()
    assert found == [4, 0] and force[0] > 0.0 and force[1] == 0.0
    scene.step()
    assert counts()[0] == [4, 4]  # reset to where it rests: in contact again
    box.set_pos([0.0, 0.0, 1.0], envs_idx=[0])
    assert counts() == ([0, 4], [0.0, counts()[1][1]])
    scene.step()
    assert counts()[0] == [0, 4]


def test_contacts_after_a_backward_are_the_last_steps(f64):
    """A backward replays steps over the solver's contact arrays: the read-outs after it still give
    the last step's contacts and dofs forces (they gave the first replayed step's: a landed box read
    none), and an env replaced before it still has none."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002, requires_grad=True), show_viewer=False)
    scene.add_entity(gs.morphs.Plane())
    box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.2, 0.1), pos=(0.0, 0.0, 0.1)))
    scene.build(n_envs=2)
    velocity = torch.zeros(2, 6, dtype=torch.float64, requires_grad=True)
    box.set_dofs_velocity(velocity)
    for _ in range(60):  # falls 5 cm, lands
        scene.step()
    landed = box.get_contacts()["valid_mask"].sum(1).tolist()
    assert landed == [4, 4]
    force = box.get_dofs_force().detach().clone()  # the step's, contacts included
    assert float(force[0, 2]) > -0.5 * 9.81 * float(box.get_mass()[0])  # the contacts hold most of the weight
    loss = box.get_pos().sum()
    box.set_pos([0.0, 0.0, 1.0], envs_idx=[1])
    loss.backward()
    assert box.get_contacts()["valid_mask"].sum(1).tolist() == [4, 0]
    assert torch.equal(box.get_dofs_force().detach(), torch.stack([force[0], torch.zeros_like(force[1])]))


def test_contact_readouts_refuse_a_backward_in_a_differentiable_scene(f64):
    """get_contacts() and get_links_net_contact_force() are read-outs of the step's solve, not
    differentiable: a loss through them raises GradientError at backward (it backpropagated and
    left their term out, silently), detached they are plain values."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002, requires_grad=True), show_viewer=False)
    scene.add_entity(gs.morphs.Plane())
    box = scene.add_entity(gs.morphs.Box(size=(0.2, 0.2, 0.1), pos=(0.0, 0.0, 0.05)))
    scene.build()
    velocity = torch.tensor([0.5, 0.0, 0.0, 0.0, 0.0, 0.0], dtype=torch.float64, requires_grad=True)
    for read in (lambda: box.get_links_net_contact_force().sum(), lambda: box.get_contacts()["force_b"].sum(),
                 lambda: box.get_contacts()["position"].sum()):
        scene.reset()
        box.set_dofs_velocity(velocity)
        for _ in range(5):
            scene.step()
        assert read().requires_grad  # in the graph: a loss through it would build
        with pytest.raises(gs.GradientError, match="is not differentiable"):
            (box.get_pos().sum() + read()).backward()
    scene.reset()
    box.set_dofs_velocity(velocity)
    for _ in range(5):
        scene.step()
    (box.get_pos().sum() + box.get_links_net_contact_force().detach().sum()).backward()
    assert velocity.grad[0] > 0.0


def test_contact_stages_run_only_in_substeps_that_need_them(f64, monkeypatch):
    """The colliders and the constraint solve, and their adjoints, run only in substeps where some
    env has a near pair, or a row to form: two envs drop a sphere from 12 and 20 cm (radius 5 cm,
    2 substeps of 5 ms; its bounding sphere is itself, so near is touching), a differentiable
    rollout; build finds the touching pairs without the solve. Every step whose substeps have no
    contact in either env launches none of them; each one that has launches them once per
    substep with a contact."""
    from genesis_lite.solvers.launch import BoundKernel
    launched = []
    original = BoundKernel.__call__

    def counting(self, *args):
        name = self.kernel.__name__
        launched.append(f"{name}:{self.template[1]}" if name == "reverse_dynamics" else name)
        original(self, *args)

    monkeypatch.setattr(BoundKernel, "__call__", counting)
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, substeps=2, requires_grad=True), show_viewer=False)
    scene.add_entity(gs.morphs.Plane())
    ball = scene.add_entity(gs.morphs.Sphere(radius=0.05, pos=(0.0, 0.0, 0.12)))
    scene.build(n_envs=2)
    assert "constrain" not in launched and "smooth_substep" in launched  # the colliders ran at build
    z0 = torch.tensor([[0.0, 0.0, 0.12], [0.0, 0.0, 0.20]], dtype=gs.tc_float, requires_grad=True)
    ball.set_pos(z0)
    solves, collides, touching = [], [], []
    for _ in range(25):
        launched.clear()
        scene.step()
        solves.append(launched.count("constrain"))
        collides.append(launched.count("collide"))
        touching.append(sum(bool((scene._rigid_solver.contacts(substep=s)[:, :, 0] >= 0).any()) for s in range(2)))
    assert solves == touching and collides == touching, (solves, collides, touching)
    assert touching[0] == 0 and touching[-1] == 2  # in the air, then resting
    launched.clear()
    ball.get_pos()[:, 2].sum().backward()
    assert launched.count("reverse_dynamics:1") == launched.count("collide_adjoint") == sum(touching)
    assert launched.count("reverse_dynamics:0") == 2 * len(touching) - sum(touching)
    assert torch.isfinite(z0.grad).all()


def test_more_contacts_than_slots_is_a_named_error(f64, caplog):
    """Two boxes resting on the plane, one on the other (up to 8 contacts a face each), with 6
    contact slots: build warns, the first step raises naming max_contacts and the pairs' worst
    case (plane-box 8 each, box-box 8), which is enough."""
    def boxes(max_contacts):
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.002),
                         rigid_options=gs.options.RigidOptions(max_contacts=max_contacts))
        scene.add_entity(gs.morphs.Plane())
        scene.add_entity(gs.morphs.Box(size=(0.2, 0.2, 0.2), pos=(0.0, 0.0, 0.1)), name="low")
        scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(0.0, 0.0, 0.25)), name="high")
        scene.build()
        return scene

    caplog.clear()
    scene = boxes(6)
    worst = contact.worst_case_contacts(scene._rigid_solver.model)
    assert any("max_contacts" in r.getMessage() and f"up to {worst}" in r.getMessage() for r in caplog.records)
    with pytest.raises(gs.SimulationError, match=rf"entities: .*low, high.* more contacts than the 6 slots per env.*"
                                                 rf"max_contacts=.*up to {worst}"):
        scene.step()
    scene = boxes(worst)
    for _ in range(5):
        scene.step()


def _pile(max_contacts, requires_grad=False):
    """3 × 3 boxes (0.25 m, 1 mm apart) on the plane, 2 × 2 above them, side by side (0.25 mm into
    each other), each over the corners of four lower ones, and one over the corners of those, each
    layer 5 cm above the one below (two envs, each its own start), 4 substeps a step: landing, each
    upper box touches four lower ones, and the pile comes to more contacts than the 8 per moving
    link the slots start at."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, substeps=4, requires_grad=requires_grad),
                     rigid_options=gs.options.RigidOptions(max_contacts=max_contacts))
    scene.add_entity(gs.morphs.Plane())
    size = 0.25
    lower = [(1.004 * size * i, 1.004 * size * j, 0.5 * size) for j in range(3) for i in range(3)]
    upper = [(0.999 * size * (i - 0.5) + 1.004 * size, 0.999 * size * (j - 0.5) + 1.004 * size, 1.7 * size)
             for j in range(2) for i in range(2)]
    top = [(1.004 * size, 1.004 * size, 2.9 * size)]
    boxes = [scene.add_entity(gs.morphs.Box(size=(size,) * 3, pos=pos)) for pos in lower + upper + top]
    scene.build(n_envs=2)
    return scene, boxes


def test_contact_slots_grow_as_a_pile_forms_and_keep_its_trajectory(f64):
    """RigidOptions(max_contacts=None): the slots double whenever a substep's colliders find more
    contacts than they hold (on the CPU), instead of the step raising; the pile then moves bit for bit
    as in a scene sized for the pairs' worst case from the start, and its gradients are those too."""
    grown, sized = _pile(None), _pile(10 ** 4)
    start = grown[0]._rigid_solver.data.size["C"]
    velocity = torch.tensor(np.random.default_rng(0).normal(size=(2, 6)) * 0.05)
    for scene, boxes in (grown, sized):
        for box in boxes:
            box.set_dofs_velocity(velocity)
    for step in range(60):
        for scene, boxes in (grown, sized):  # (the step's wrench flag rides through the growth too)
            boxes[-1].apply_links_external_wrench(torch.tensor([[[2.0, 1.0, 0.0]]] * 2))
            scene.step()
        for a, b in zip(grown[1], sized[1]):
            assert torch.equal(a.get_qpos(), b.get_qpos()), step
    slots = grown[0]._rigid_solver.data.size["C"]
    assert slots > start and max(int(n) for n in grown[0]._rigid_solver.contacts(substep=3)[:, :, 0].ge(0).sum(1)) > start
    assert slots < sized[0]._rigid_solver.data.size["C"]  # (the worst case: what the pile never needed)

    grads = []
    for max_contacts in (None, 10 ** 4):
        scene, boxes = _pile(max_contacts, requires_grad=True)
        v0 = velocity.clone().requires_grad_(True)
        for box in boxes:
            box.set_dofs_velocity(v0)
        for _ in range(40):
            scene.step()
        sum(box.get_pos()[:, 2].sum() for box in boxes).backward()
        grads.append(v0.grad)
    assert torch.isfinite(grads[0]).all() and torch.equal(grads[0], grads[1])
