"""RigidEntity.attach (Genesis's): an entity's base hung from a link of an earlier entity, one
kinematic tree with it. The reference is the same robot written as one URDF, the hand joined to
the arm's flange by a fixed joint: attached, the two move as that one file does, to round-off (and
their gradients), wherever the hand's morph had placed it."""
import numpy as np
import pytest
import torch

import genesis_lite as gs
from genesis_lite.solvers.core import GradientError

INERTIAL = '<inertial><origin xyz="{com}"/><mass value="{mass}"/><inertia ixx="{i}" iyy="{i}" izz="{i}" ixy="0" ixz="0" iyz="0"/></inertial>'
BOX = '<collision><origin xyz="{com}"/><geometry><box size="{size}"/></geometry></collision>'


def _link(name, com, mass, size):
    return f'<link name="{name}">{INERTIAL.format(com=com, mass=mass, i=0.01 * mass)}{BOX.format(com=com, size=size)}</link>'


ARM = ('<link name="base"/>'
       '<joint name="j1" type="revolute"><parent link="base"/><child link="upper"/><origin xyz="0 0 0.5"/>'
       '<axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="100" velocity="10"/></joint>'
       + _link("upper", "0.2 0 0", 2.0, "0.4 0.06 0.06") +
       '<joint name="j2" type="revolute"><parent link="upper"/><child link="lower"/><origin xyz="0.4 0 0"/>'
       '<axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="100" velocity="10"/></joint>'
       + _link("lower", "0.15 0 0", 1.0, "0.3 0.05 0.05") +
       '<joint name="flange_joint" type="fixed"><parent link="lower"/><child link="flange"/><origin xyz="0.3 0 0"/></joint>'
       '<link name="flange"/>')
MOUNT_XYZ, MOUNT_RPY = (0.02, 0.0, 0.01), (0.3, 0.0, 0.2)
HAND = (_link("palm", "0.03 0 0", 0.5, "0.06 0.1 0.03") +
        '<joint name="finger_joint" type="prismatic"><parent link="palm"/><child link="finger"/>'
        '<origin xyz="0.06 0 0"/><axis xyz="0 1 0"/><limit lower="-0.04" upper="0.04" effort="20" velocity="1"/></joint>'
        + _link("finger", "0.02 0 0", 0.1, "0.04 0.01 0.02"))


def _write(tmp_path, name, body):
    path = tmp_path / f"{name}.urdf"
    path.write_text(f'<?xml version="1.0"?><robot name="{name}">{body}</robot>')
    return str(path)


def _rpy_quat(rpy):
    """URDF's fixed-axis roll-pitch-yaw as (w, x, y, z)."""
    (cr, sr), (cp, sp), (cy, sy) = [(np.cos(a / 2), np.sin(a / 2)) for a in rpy]
    return np.array([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
                     cr * cp * sy - sr * sp * cy])


def _scenes(tmp_path, how, merge=False, requires_grad=False, between=False):
    """(scene, entities whose dofs are the arm's then the hand's) with the hand attached ``how``:
    "morph" (the mount as the hand's morph pose), "mount" (attach's pos and quat, the morph elsewhere),
    or "file" (one URDF: the reference); between: a free box added between the arm and the hand."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.005, requires_grad=requires_grad),
                     rigid_options=gs.options.RigidOptions(enable_collision=False), show_viewer=False)
    xyz, rpy = " ".join(map(str, MOUNT_XYZ)), " ".join(map(str, MOUNT_RPY))
    if how == "file":
        joined = (ARM + f'<joint name="mount" type="fixed"><parent link="flange"/><child link="palm"/>'
                  f'<origin xyz="{xyz}" rpy="{rpy}"/></joint>' + HAND)
        robot = scene.add_entity(gs.morphs.URDF(file=_write(tmp_path, "joined", joined), fixed=True,
                                                merge_fixed_links=merge, default_armature=0.0))
        scene.build()
        return scene, [robot]
    arm = scene.add_entity(gs.morphs.URDF(file=_write(tmp_path, "arm", ARM), fixed=True, merge_fixed_links=merge,
                                          default_armature=0.0))
    if between:
        scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(2.0, 0.0, 1.0)))
    hand_file = _write(tmp_path, "hand", HAND)
    if how == "morph":
        hand = scene.add_entity(gs.morphs.URDF(file=hand_file, pos=MOUNT_XYZ, quat=_rpy_quat(MOUNT_RPY),
                                               merge_fixed_links=merge, default_armature=0.0))
        hand.attach(arm, "flange")
    elif merge:  # (the flange merged into the lower link, 0.3 m along it: the mount from there)
        hand = scene.add_entity(gs.morphs.URDF(file=hand_file, merge_fixed_links=True, default_armature=0.0))
        hand.attach(arm, "lower", pos=np.add(MOUNT_XYZ, (0.3, 0.0, 0.0)), quat=_rpy_quat(MOUNT_RPY))
    else:
        hand = scene.add_entity(gs.morphs.URDF(file=hand_file, pos=(2.0, 1.0, 0.3), euler=(10.0, 20.0, 30.0),
                                               merge_fixed_links=merge, default_armature=0.0))
        hand.attach(arm, "flange", pos=MOUNT_XYZ, quat=_rpy_quat(MOUNT_RPY))
    assert hand.n_dofs == 1 and not hand.is_free and [joint.name for joint in hand.joints] == ["finger_joint"]
    scene.build()
    return scene, [arm, hand]


def _drive(entities, t):
    """Position targets for the arm's two hinges and the finger."""
    targets = torch.tensor([0.8 * np.sin(3.0 * t), 0.5 * np.cos(2.0 * t), 0.03 * np.sin(5.0 * t)], dtype=torch.float64)
    if len(entities) == 1:
        entities[0].control_dofs_position(targets)
    else:
        entities[0].control_dofs_position(targets[:2])
        entities[1].control_dofs_position(targets[2:])


def _dofs(entities):
    """The dofs' positions, then their velocities (the arm's, then the finger's)."""
    return torch.cat([e.get_dofs_position() for e in entities] + [e.get_dofs_velocity() for e in entities])


@pytest.mark.parametrize("how, between", [("morph", False), ("mount", False), ("morph", True)])
def test_attached_hand_moves_as_the_one_file_robot(f64, tmp_path, how, between):
    """Under gravity and servos on all three joints, 300 steps: the arm's and the finger's positions and
    velocities, and the palm's pose, equal the one-file robot's to round-off (the mount's quaternion
    is made from the roll-pitch-yaw by another route than the URDF reader's), also with another
    entity added between the two (its dofs between theirs)."""
    attached, joined = _scenes(tmp_path, how, between=between), _scenes(tmp_path, "file")
    worst = 0.0
    for step in range(300):
        for scene, entities in (attached, joined):
            _drive(entities, step * 0.005)
            scene.step()
        worst = max(worst, float((_dofs(attached[1]) - _dofs(joined[1])).abs().max()))
    palm, reference = attached[1][1].get_link("palm"), joined[1][0].get_link("palm")
    print(f"\nattached by {how}: largest joint difference from the one-file robot {worst:.1e}")
    assert worst < 1e-12
    assert torch.allclose(palm.get_pos(), reference.get_pos(), rtol=0, atol=1e-13)
    assert torch.allclose(palm.get_quat(), reference.get_quat(), rtol=0, atol=1e-13)
    assert float(_dofs(joined[1]).abs().max()) > 0.1  # (it moved)


def test_attached_hand_with_merged_links_moves_as_the_merged_file(f64, tmp_path):
    """merge_fixed_links=True: the one file merges the palm into the arm's last link, the attached hand
    keeps it (entities are not merged): the same motion, to round-off."""
    attached, joined = _scenes(tmp_path, "mount", merge=True), _scenes(tmp_path, "file", merge=True)
    assert [link.name for link in attached[1][0].links] == ["base", "upper", "lower"]
    for step in range(300):
        for scene, entities in (attached, joined):
            _drive(entities, step * 0.005)
            scene.step()
    assert torch.allclose(_dofs(attached[1]), _dofs(joined[1]), rtol=0, atol=1e-10)


def test_gradients_through_an_attached_hand_are_the_one_file_robots(f64, tmp_path):
    """A differentiable rollout (Genesis refuses one with attached entities): the gradient of the
    palm's final position w.r.t. the initial joint velocities equals the one-file robot's (to
    round-off, as the trajectory), and repeats bit for bit."""
    grads = []
    for how in ("morph", "file", "morph"):
        scene, entities = _scenes(tmp_path, how, requires_grad=True)
        v0 = torch.tensor([0.5, -0.3, 0.02], dtype=torch.float64, requires_grad=True)
        if len(entities) == 1:
            entities[0].set_dofs_velocity(v0)
        else:
            entities[0].set_dofs_velocity(v0[:2])
            entities[1].set_dofs_velocity(v0[2:])
        for step in range(60):
            _drive(entities, step * 0.005)
            scene.step()
        (entities[-1].get_link("palm").get_pos() * torch.tensor([1.0, -2.0, 0.5])).sum().backward()
        grads.append(v0.grad)
    assert grads[0].abs().min() > 0 and torch.equal(grads[0], grads[2])
    assert torch.allclose(grads[0], grads[1], rtol=1e-10, atol=0)


def test_an_attached_free_body_rides_its_link_and_weighs_on_it(f64, tmp_path):
    """A free box attached to the arm's flange loses its six dofs and rides the flange at the mount, and
    it loads the arm as a box link in the arm's file would (0.5 kg at the mount): the arm swings down
    under gravity onto the plane in both scenes alike (the box meets neither the arm's link it is
    welded to nor that link's parent, as a link of the file would not)."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.005), show_viewer=False)
    scene.add_entity(gs.morphs.Plane())
    arm = scene.add_entity(gs.morphs.URDF(file=_write(tmp_path, "arm", ARM), fixed=True, merge_fixed_links=False,
                                          default_armature=0.0))
    box = scene.add_entity(gs.morphs.Box(size=(0.06, 0.1, 0.03), pos=(0.0, 0.0, 3.0)),
                           material=gs.materials.Rigid(rho=0.5 / (0.06 * 0.1 * 0.03)))
    box.attach(arm, pos=(0.03, 0.0, 0.0))
    assert box.n_dofs == 0 and box.n_qs == 0 and box.joints == []
    scene.build()
    reference = gs.Scene(sim_options=gs.options.SimOptions(dt=0.005), show_viewer=False)
    reference.add_entity(gs.morphs.Plane())
    joined = ARM + ('<joint name="mount" type="fixed"><parent link="flange"/><child link="palm"/></joint>'
                    + _link("palm", "0.03 0 0", 0.5, "0.06 0.1 0.03").replace('ixx="0.005" iyy="0.005" izz="0.005"', (
                        'ixx="{:.17g}" iyy="{:.17g}" izz="{:.17g}"'.format(*(0.5 / 12 * np.array(
                            [0.1 ** 2 + 0.03 ** 2, 0.06 ** 2 + 0.03 ** 2, 0.06 ** 2 + 0.1 ** 2]))))))
    same = reference.add_entity(gs.morphs.URDF(file=_write(tmp_path, "joined", joined), fixed=True,
                                               merge_fixed_links=False, default_armature=0.0))
    reference.build()
    for _ in range(200):
        scene.step()
        reference.step()
    assert torch.allclose(arm.get_dofs_position(), same.get_dofs_position(), rtol=0, atol=1e-12)
    flange = arm.get_link("flange")
    expected = flange.get_pos() + torch.tensor(gs.utils.geom.quat_to_R(flange.get_quat().numpy())) @ torch.tensor(
        [0.03, 0.0, 0.0], dtype=torch.float64)
    assert torch.allclose(box.get_pos(), expected, rtol=0, atol=1e-14)
    assert torch.allclose(box.get_quat(), flange.get_quat(), rtol=0, atol=1e-14)
    assert float(arm.get_dofs_position().abs().max()) > 0.5  # (it fell under gravity, box and all)


def test_attach_arguments_are_checked(f64, tmp_path):
    scene = gs.Scene(show_viewer=False)
    arm = scene.add_entity(gs.morphs.URDF(file=_write(tmp_path, "arm", ARM), fixed=True, merge_fixed_links=False))
    box = scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(0.3, 0.2, 0.1)))
    later = scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(1.0, 0.0, 0.0)))
    other = gs.Scene(show_viewer=False).add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1)))
    checks = [(lambda: box.attach(box), "added before this one"), (lambda: box.attach(later), "added before this one"),
              (lambda: box.attach(other), "same scene"), (lambda: box.attach("arm"), "same scene"),
              (lambda: box.attach(arm, "nowhere"), "must be one of"),
              (lambda: box.attach(arm, pos=(0.0, 0.0)), "'pos' must be 3 finite"),
              (lambda: box.attach(arm, quat=(0.0, 0.0, 0.0, 0.0)), "non-zero quaternion")]
    for call, said in checks:
        with pytest.raises(gs.InvalidInputError, match=said):
            call()
    with pytest.raises(GradientError, match="'pos' is not differentiable"):
        box.attach(arm, pos=torch.zeros(3, dtype=torch.float64, requires_grad=True))
    box.attach(arm)  # (after the failed calls above: the morph's pose, which none of them touched)
    assert box.attached_to == (arm, arm.get_link("flange"))  # (the last link: Genesis's default)
    assert box._specs[0].pos.tolist() == [0.3, 0.2, 0.1] and box._specs[0].quat.tolist() == [1.0, 0.0, 0.0, 0.0]
    with pytest.raises(gs.InvalidInputError, match="already attached to entity"):
        box.attach(arm)
    scene.build()
    with pytest.raises(gs.SceneStateError, match="attach entities before scene.build"):
        later.attach(arm)


def test_a_mount_replaces_the_files_own_base_pose_as_genesis(f64, tmp_path):
    """attach(pos, quat) is the base's pose in the parent link's frame, whatever the morph and the file
    put it at: an MJCF whose base body the file puts at (0.1, 0, 0.05), turned 90°, hangs exactly at the
    mount (Genesis 1.4.5, measured on a body at (0, 0, 1) with pos=(0.2, 0, 0): the tool at (0.2, 0,
    1.0), unturned). Without pos and quat, the file's pose stays after the morph's, as at load."""
    body = ('<mujoco><worldbody><body name="tool" pos="0.1 0 0.05" euler="0 0 90"><freejoint/>'
            '<geom type="box" size="0.02 0.03 0.04"/></body></worldbody></mujoco>')
    path = tmp_path / "tool.xml"
    path.write_text(body)
    scene = gs.Scene(rigid_options=gs.options.RigidOptions(enable_collision=False), show_viewer=False)
    arm = scene.add_entity(gs.morphs.URDF(file=_write(tmp_path, "arm", ARM), fixed=True, merge_fixed_links=False))
    mounted = scene.add_entity(gs.morphs.MJCF(file=str(path), pos=(1.0, 2.0, 3.0), euler=(30.0, 0.0, 0.0)))
    placed = scene.add_entity(gs.morphs.MJCF(file=str(path), pos=MOUNT_XYZ, quat=_rpy_quat(MOUNT_RPY)))
    mount_quat = _rpy_quat(MOUNT_RPY)
    mounted.attach(arm, "flange", pos=MOUNT_XYZ, quat=mount_quat)
    placed.attach(arm, "flange")
    scene.build()
    flange = arm.get_link("flange")
    rotate = gs.utils.geom.transform_by_quat
    for tool, at, turn in ((mounted, np.array(MOUNT_XYZ), mount_quat),
                           (placed, np.array(MOUNT_XYZ) + rotate(np.array([0.1, 0.0, 0.05]), mount_quat),
                            gs.utils.geom.transform_quat_by_quat(np.array([np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)]),
                                                                 mount_quat))):
        expected = flange.get_pos().numpy() + rotate(at, flange.get_quat().numpy())
        np.testing.assert_allclose(tool.get_pos().numpy(), expected, atol=1e-14)
        expected_quat = gs.utils.geom.transform_quat_by_quat(turn, flange.get_quat().numpy())
        assert abs(abs(tool.get_quat().numpy() @ expected_quat) - 1.0) < 1e-14


def test_a_camera_follows_an_attached_entity_from_where_it_hangs(f64, tmp_path):
    """A camera told before build to follow an attached entity measures its offset from where the base
    hangs once built, not from the morph's position (where this camera stands)."""
    scene = gs.Scene(show_viewer=False)
    arm = scene.add_entity(gs.morphs.URDF(file=_write(tmp_path, "arm", ARM), fixed=True, merge_fixed_links=False))
    box = scene.add_entity(gs.morphs.Box(size=(0.05, 0.05, 0.05), pos=(2.0, 0.0, 1.0)))
    box.attach(arm, pos=(0.03, 0.0, 0.0))
    camera = scene.add_camera(pos=(2.0, 0.0, 1.0), lookat=(0.0, 0.0, 0.5), res=(32, 32))
    camera.follow_entity(box)
    scene.build()
    np.testing.assert_allclose(camera._follow[1], np.array([2.0, 0.0, 1.0]) - box.get_pos().numpy(), atol=1e-12)


def test_inverse_kinematics_of_an_attached_hand_starts_from_its_parents_pose(f64, tmp_path):
    """The hand's IK (its finger only) poses the arm it hangs from as the state has it, not as the
    last link getter left the frame the solve uses: the finger's point with the arm at pose A is
    reached (finger at 0.02 m) after the arm was read at pose B and set back to A unread."""
    scene, (arm, hand) = _scenes(tmp_path, "mount")
    finger = hand.get_link("finger")
    pose_a, pose_b = torch.tensor([0.4, -0.7], dtype=torch.float64), torch.tensor([-0.9, 1.1], dtype=torch.float64)
    out = torch.tensor([0.02], dtype=torch.float64)
    arm.set_qpos(pose_a)
    hand.set_qpos(out)
    target = finger.get_pos().clone()
    arm.set_qpos(pose_b)
    assert (finger.get_pos() - target).norm() > 0.1  # (the frame now holds pose B)
    arm.set_qpos(pose_a)
    hand.set_qpos(torch.zeros(1, dtype=torch.float64))
    qpos, error = hand.inverse_kinematics(finger, pos=target, pos_tol=1e-10, return_error=True)
    assert error.norm() <= 1e-6 and abs(float(qpos[0]) - 0.02) <= 1e-6
