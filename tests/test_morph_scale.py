"""URDF(scale=s) and MJCF(scale=s): the robot grown by s, of the same densities (Genesis's morph scale).

Pinned by dynamic similarity, which needs nothing of ours: a body s times larger of the same
density, under the same gravity, moves as the original at √s its pace. Every joint torque and
inertia then scales together (masses s³, inertias s⁵, lengths s), so the two trajectories agree
to round-off only when all three are scaled right; a mass left unscaled, an inertia scaled as s³
or a shape as s² breaks it. Beside it: the kinematics, masses, bounding boxes and limits of a
mesh robot (the KUKA), the mimic rows' coefficients, and the named errors.
"""
import math

import numpy as np
import pytest
import torch

import genesis_lite as gs
from genesis_lite.solvers.core import InvalidInputError
from genesis_lite.solvers.rigid.scale import scaled_links
from genesis_lite.solvers.rigid.spec import LinkSpec
from genesis_lite.vis.visuals import scene_shapes
from tests.conftest import pybullet

KUKA = pybullet("kuka_iiwa", "model.urdf")

# a chain of a revolute, a prismatic and a revolute joint, off-axis shapes and inertias: links with
# <inertial> and links weighed from their collision shapes (a box, a cylinder, a sphere)
CHAIN = """<?xml version="1.0"?>
<robot name="chain">
  <link name="base"><inertial><mass value="2"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/>
    </inertial></link>
  <link name="upper">
    <inertial><origin xyz="0.12 0.01 -0.02"/><mass value="0.9"/>
      <inertia ixx="0.003" ixy="0.0004" ixz="0" iyy="0.011" iyz="0.0002" izz="0.010"/></inertial>
    <collision><origin xyz="0.12 0 0"/><geometry><box size="0.24 0.04 0.05"/></geometry></collision>
  </link>
  <link name="slider">
    <collision><origin xyz="0 0.02 0" rpy="0.3 0 0"/><geometry><cylinder radius="0.03" length="0.2"/></geometry>
    </collision>
  </link>
  <link name="tip">
    <collision><origin xyz="0.05 0 0.01"/><geometry><sphere radius="0.04"/></geometry></collision>
    <collision><origin xyz="0.0 0 0"/><geometry><box size="0.02 0.1 0.02"/></geometry></collision>
  </link>
  <joint name="shoulder" type="continuous">
    <parent link="base"/><child link="upper"/><origin xyz="0 0 0.5" rpy="0.2 0.1 0"/><axis xyz="0 1 0"/>
  </joint>
  <joint name="extend" type="prismatic">
    <parent link="upper"/><child link="slider"/><origin xyz="0.24 0 0" rpy="0 0.4 0"/><axis xyz="1 0 0.2"/>
    <limit lower="-0.5" upper="0.5" effort="50" velocity="1"/>
  </joint>
  <joint name="elbow" type="revolute">
    <parent link="slider"/><child link="tip"/><origin xyz="0.1 0.03 0" rpy="0 0 0.5"/><axis xyz="0.3 1 0"/>
    <limit lower="-3" upper="3" effort="50" velocity="1"/>
  </joint>
</robot>
"""
LENGTH_DOFS = np.array([False, True, False])  # the chain's dofs whose coordinate is a length (m)


def _chain(tmp_path):
    path = tmp_path / "chain.urdf"
    path.write_text(CHAIN)
    return str(path)


def _scene(file, s, dt, **rigid):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=dt, gravity=(0.0, 0.0, -9.81)),
                     rigid_options=gs.options.RigidOptions(enable_collision=False, **rigid))
    robot = scene.add_entity(gs.morphs.URDF(file=file, fixed=True, scale=s, default_armature=0.0))
    scene.build()
    return scene, robot


def _assert_similar(original, grown, length, rate, steps, what):
    """Step both scenes ``steps`` times: the grown robot's positions ÷ length and velocities ÷ rate
    (each coordinate's scale) are the original's to round-off at every step, and it moved."""
    worst, travel, q0 = 0.0, 0.0, original.get_dofs_position()
    for _ in range(steps):
        original.scene.step()
        grown.scene.step()
        q = original.get_dofs_position()
        worst = max(worst, float((grown.get_dofs_position() / length - q).abs().max()),
                    float((grown.get_dofs_velocity() / rate - original.get_dofs_velocity()).abs().max()))
        travel = max(travel, float((q - q0).abs().max()))
    print(f"\n{what}: worst |Δ| {worst:.2e} over a travel of {travel:.2f}")
    assert travel > 0.2  # it moved
    assert worst < 1e-9, worst


@pytest.mark.parametrize("s", [0.35, 2.5])
def test_scaled_chain_moves_as_the_original_at_root_s_its_pace(f64, tmp_path, s):
    """q_s(t) = q(t / √s) for angles, s · q(t / √s) for lengths: the scaled chain stepped with
    dt·√s from the scaled state gives, step for step, the original's state (its lengths s times),
    over 0.5 s of swinging (no damping, no contacts; the limits off: their rows' softness is a time
    constant of the scene's, not the robot's)."""
    file, dt, steps = _chain(tmp_path), 0.002, 250
    length = torch.tensor(np.where(LENGTH_DOFS, s, 1.0))  # each coordinate's scale
    rate = length / math.sqrt(s)  # each velocity's (time runs √s slower)
    rng = np.random.default_rng(3)
    q0, v0 = torch.tensor(rng.uniform(-0.4, 0.4, 3)), torch.tensor(rng.normal(size=3))
    _, original = _scene(file, 1.0, dt, enable_joint_limit=False)
    _, grown = _scene(file, s, dt * math.sqrt(s), enable_joint_limit=False)
    for robot, scale, velocity_scale in ((original, 1.0, 1.0), (grown, length, rate)):
        robot.set_dofs_position(q0 * scale)
        robot.set_dofs_velocity(v0 * velocity_scale)
    _assert_similar(original, grown, length, rate, steps, f"URDF scale {s}")


@pytest.mark.parametrize("s", [0.5, 3.0])
def test_scaled_kuka_kinematics_masses_boxes_and_limits(f64, s):
    """The KUKA (meshes, merged fixed links): at random joint positions every link origin is s
    times as far from the base, turned the same; masses × s³; the entity's bounding box (its mesh
    hulls) × s; what cameras draw (its <visual> meshes) × s; revolute limits, effort and damping
    the file's."""
    original_scene, original = _scene(KUKA, 1.0, 0.01)
    grown_scene, grown = _scene(KUKA, s, 0.01)
    q = torch.tensor(np.random.default_rng(0).uniform(-1.0, 1.0, original.n_dofs))
    for robot in (original, grown):
        robot.set_dofs_position(q)
    np.testing.assert_allclose(grown.get_links_pos(), s * original.get_links_pos(), rtol=0, atol=1e-12)
    np.testing.assert_allclose(grown.get_links_quat(), original.get_links_quat(), rtol=0, atol=1e-12)
    np.testing.assert_allclose(grown.get_links_mass(), s ** 3 * original.get_links_mass(), rtol=1e-12)
    np.testing.assert_allclose(grown.get_AABB(), s * original.get_AABB(), rtol=0, atol=1e-12)
    drawn = [(scene_shapes(scene)) for scene in (original_scene, grown_scene)]
    assert len(drawn[0]) == len(drawn[1]) > 0
    for before, after in zip(*drawn):
        np.testing.assert_allclose(after.mesh[0], s * before.mesh[0], rtol=0, atol=1e-12)
    for getter in ("get_dofs_limit", "get_dofs_force_range", "get_dofs_damping"):
        np.testing.assert_array_equal(getattr(grown, getter)(), getattr(original, getter)())


def test_scaled_chain_limits_and_shapes(f64, tmp_path):
    """A prismatic joint's limits are lengths: × s (the revolute's stay); the primitive shapes
    (box, cylinder, sphere) grow by s: the chain's bounding box, at the same pose (its prismatic
    coordinate × s), is s times the original's."""
    _, original = _scene(_chain(tmp_path), 1.0, 0.01)
    _, grown = _scene(_chain(tmp_path), 2.0, 0.01)
    lower, upper = original.get_dofs_limit()
    scale = torch.tensor(np.where(LENGTH_DOFS, 2.0, 1.0))
    np.testing.assert_array_equal(torch.stack(grown.get_dofs_limit()), torch.stack((lower * scale, upper * scale)))
    q = torch.tensor([0.7, 0.2, -1.1])
    original.set_dofs_position(q)
    grown.set_dofs_position(q * scale)
    np.testing.assert_allclose(grown.get_AABB(), 2.0 * original.get_AABB(), rtol=0, atol=1e-12)


def _link(name, parent, joint, joint_type, mimic=None):
    return LinkSpec(name, parent, joint, joint_type, np.zeros(3), np.array([1.0, 0, 0, 0]), np.array([0, 0, 1.0]),
                    1.0, np.zeros(3), np.eye(3), mimic=mimic)


@pytest.mark.parametrize("follower, followed, multiplier, offset", [
    ("prismatic", "revolute", 2.0 * 3.0, 0.1 * 3.0),   # m per rad: × s; offset in m: × s
    ("revolute", "prismatic", 2.0 / 3.0, 0.1),         # rad per m: ÷ s; offset in rad
    ("prismatic", "prismatic", 2.0, 0.1 * 3.0),        # m per m; offset in m
    ("revolute", "revolute", 2.0, 0.1),                # rad per rad
])
def test_scaled_mimic_keeps_its_meaning(follower, followed, multiplier, offset):
    """q_f = multiplier · q_d + offset in the scaled coordinates (lengths × s) is the file's
    relation: the multiplier takes s_f / s_d, the offset s_f."""
    links = [_link("base", -1, "", "fixed"), _link("a", 0, "driver", followed),
             _link("b", 1, "follower", follower, mimic=("driver", 2.0, 0.1))]
    scaled = scaled_links(links, 3.0)
    assert scaled[2].mimic[0] == "driver"
    np.testing.assert_allclose(scaled[2].mimic[1:], (multiplier, offset), rtol=1e-15)
    assert links[2].mimic == ("driver", 2.0, 0.1) and links[1].mass == 1.0  # the file's specs untouched


@pytest.mark.parametrize("scale", [0.0, -1.0, float("nan"), (1.0, 2.0, 1.0), (1.0, 1.0), "big", "2", True])
def test_bad_scale_is_a_named_error(f64, scale):
    with pytest.raises(InvalidInputError, match=r"URDF: argument 'scale'"):
        gs.morphs.URDF(file=KUKA, scale=scale)


def test_isotropic_triple_is_taken(f64):
    assert gs.morphs.URDF(file=KUKA, scale=(2.0, 2.0, 2.0)).scale == 2.0


# -- MJCF(scale) -----------------------------------------------------------------------------------
# a hinge, slide, hinge chain whose tip holds a free box by a connect (no violation at the start:
# MuJoCo's anchor on the box is where the tip's is at q0), a fixed tendon of a hinge and the slide
# (not met), and a position actuator; the connect's impedance constant (dmin = dmax) and its time
# constant TC, so that a scaled file with TC·√s is dynamically similar
CHAIN_MJCF = """<mujoco>
  <worldbody>
    <body name="arm" pos="0 0 1">
      <joint name="shoulder" type="hinge" axis="0 1 0"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"/>
      <body name="slider" pos="0.3 0 0" euler="0 20 0">
        <joint name="extend" type="slide" axis="1 0 0"/>
        <geom type="box" size="0.05 0.02 0.02"/>
        <body name="tip" pos="0.1 0 0">
          <joint name="elbow" type="hinge" axis="0 0 1"/>
          <geom type="sphere" size="0.04" pos="0.05 0 0"/>
        </body>
      </body>
    </body>
    <body name="box" pos="0.55 0.02 0.93">
      <freejoint/>
      <geom type="box" size="0.05 0.03 0.02"/>
    </body>
  </worldbody>
  <equality>
    <connect body1="tip" body2="box" anchor="0.1 0 0" solref="TC 1" solimp="0.95 0.95 0.001 0.5 2"/>
  </equality>
  <tendon>
    <fixed name="reach" limited="true" range="-5 5">
      <joint joint="shoulder" coef="1"/><joint joint="extend" coef="2"/>
    </fixed>
  </tendon>
  <actuator><position joint="shoulder" kp="50"/></actuator>
</mujoco>
"""
MJCF_LENGTH_DOFS = np.array([False, True, False, True, True, True, False, False, False])  # the box's x, y, z


def _mjcf(tmp_path, name, timeconst):
    path = tmp_path / name
    path.write_text(CHAIN_MJCF.replace("TC", repr(timeconst)))
    return str(path)


def _mjcf_scene(file, s, dt):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=dt, gravity=(0.0, 0.0, -9.81)),
                     rigid_options=gs.options.RigidOptions(enable_collision=False, enable_joint_limit=False))
    robot = scene.add_entity(gs.morphs.MJCF(file=file, scale=s, default_armature=0.0))
    scene.build()
    return scene, robot


@pytest.mark.parametrize("s", [0.4, 3.0])
def test_scaled_mjcf_with_a_connect_moves_as_the_original_at_root_s_its_pace(f64, tmp_path, s):
    """As the URDF chain above, for an MJCF with a free body held by a connect: the scaled file
    (its connect's time constant × √s, a property of the scene rather than of the robot) moves as
    the original at √s its pace, the connect holding, over 0.5 s."""
    dt, steps, timeconst = 0.002, 250, 0.02
    _, original = _mjcf_scene(_mjcf(tmp_path, "a.xml", timeconst), 1.0, dt)
    _, grown = _mjcf_scene(_mjcf(tmp_path, "b.xml", timeconst * math.sqrt(s)), s, dt * math.sqrt(s))
    assert original.n_dofs == len(MJCF_LENGTH_DOFS)
    length = torch.tensor(np.where(MJCF_LENGTH_DOFS, s, 1.0))
    rate = length / math.sqrt(s)
    rng = np.random.default_rng(5)
    v0 = torch.tensor(rng.normal(size=original.n_dofs) * 0.5)
    original.set_dofs_velocity(v0)
    grown.set_dofs_velocity(v0 * rate)
    _assert_similar(original, grown, length, rate, steps, f"MJCF scale {s}")


def test_scaled_mjcf_gains_tendon_and_anchors(f64, tmp_path):
    """Genesis's MJCF rule for an actuator: kp × s³; the tendon of a hinge and a slide keeps its
    hinge's unit (the slide's coefficient ÷ s, its range the file's); a connect's anchor × s."""
    file = _mjcf(tmp_path, "a.xml", 0.02)
    _, original = _mjcf_scene(file, 1.0, 0.01)
    _, grown = _mjcf_scene(file, 2.0, 0.01)
    np.testing.assert_allclose(grown.get_dofs_kp()[0], 8.0 * original.get_dofs_kp()[0], rtol=1e-15)
    from genesis_lite.solvers.rigid import mjcf
    links = mjcf.load_mjcf(file)
    (tendon,) = [t for link in links for t in link.tendons]
    (connect,) = [c for link in links for c in link.connects]
    scaled = scaled_links(links, 2.0, gains=8.0)
    (scaled_tendon,) = [t for link in scaled for t in link.tendons]
    (scaled_connect,) = [c for link in scaled for c in link.connects]
    assert scaled_tendon[1] == (tendon[1][0], tendon[1][1] / 2.0) and scaled_tendon[2:4] == tendon[2:4]
    np.testing.assert_array_equal(scaled_connect[1], 2.0 * np.asarray(connect[1]))


def test_scaled_slide_tendon_is_a_length():
    """A tendon of slide joints only is a length: its range, held length and spring's rest range × s,
    its coefficients, stiffness, damping and friction loss the file's; a hinge's keeps its unit."""
    links = [_link("base", -1, "", "fixed"), _link("a", 0, "x", "prismatic"), _link("b", 1, "y", "prismatic")]
    links[1].tendons = ((("x", "y"), (1.0, -0.5), -0.2, 0.3, None, (0.05, None), (7.0, 0.5, -0.01, 0.02), (0.4, None)),)
    (tendon,) = scaled_links(links, 3.0)[1].tendons
    assert tendon[1] == (1.0, -0.5) and np.allclose(tendon[2:4], (-0.6, 0.9)) and np.isclose(tendon[5][0], 0.15)
    assert tendon[6][:2] == (7.0, 0.5) and np.allclose(tendon[6][2:], (-0.03, 0.06)) and tendon[7] == (0.4, None)
    links[2].joint_type = "revolute"
    (tendon,) = scaled_links(links, 3.0)[1].tendons
    assert tendon[1] == (1.0 / 3.0, -0.5) and tendon[6] == (7.0, 0.5, -0.01, 0.02)
