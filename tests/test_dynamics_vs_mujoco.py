"""Joint-space dynamics against MuJoCo loading the same URDF (tests/mujoco_ref.py).

* The mass matrix (``get_mass_mat``, armature excluded) and the bias forces C(q, q̇)q̇ + g(q)
  equal MuJoCo's to 1e-10 in float64 at random states. There is no bias getter: with zero
  control, damping and armature, one semi-implicit Euler step gives q̈ = (q̇' − q̇)/dt and
  M q̈ = −bias, so bias = −M (q̇' − q̇)/dt.
* float32: a KUKA trajectory stays within 1e-4 rad of MuJoCo's (float64) over 2 s.

Dofs are matched by joint name; a free base's dofs 0-5 are MuJoCo's "__base__:0..5"
(world linear velocity, then body-frame angular velocity).
"""
import mujoco
import numpy as np
import pytest
import torch

import genesis_lite as gs
from tests import mujoco_ref
from tests.conftest import asset, pybullet
from tests.robot_states import limit_free_scene, random_state, scalar_joints, set_state

DT = 0.01
N_STATES = 5
TOL = 1e-10
ROBOTS = {
    "cartpole": (pybullet("cartpole.urdf"), False),
    "kuka": (pybullet("kuka_iiwa", "model.urdf"), False),
    "kuka_free": (pybullet("kuka_iiwa", "model_free_base.urdf"), True),
    "quadruped": (asset("quadruped.urdf"), True),
}


def _our_dof(robot, names):
    """Our local dof index of each MuJoCo dof name."""
    by_joint = {j.name: j.dofs_idx_local[0] for j in scalar_joints(robot)}
    out = []
    for name in names:
        if name.startswith(mujoco_ref.BASE + ":"):
            assert robot.is_free
            out.append(int(name.split(":")[1]))
        else:
            out.append(by_joint[name])
    return np.array(out)


@pytest.mark.parametrize("name", list(ROBOTS))
def test_mass_matrix_and_bias_match_mujoco_f64(f64, name):
    path, free = ROBOTS[name]
    scene, robot = limit_free_scene(path, free, DT)
    try:
        n = robot.n_dofs
        robot.set_dofs_damping(np.zeros(n))
        robot.set_dofs_armature(np.zeros(n))
        model = mujoco_ref.load_model(path, free_base=free, dt=DT)  # armature 0 by default
        rng = np.random.default_rng(42)
        for k in range(N_STATES):
            joints, base = random_state(robot, rng, free, q_range=1.5)
            scene.reset()
            set_state(robot, joints, base)
            mass = robot.get_mass_mat().numpy()
            qvel0 = robot.get_dofs_velocity().numpy()
            scene.step()  # zero control (reset clears controls), no damping, no armature
            qacc = (robot.get_dofs_velocity().numpy() - qvel0) / DT
            bias = -mass @ qacc

            m_ref, b_ref, names = mujoco_ref.mass_matrix_and_bias(
                model, {j: v[0] for j, v in joints.items()}, {j: v[1] for j, v in joints.items()},
                base_qpos=None if base is None else base[0], base_qvel=None if base is None else base[1])
            perm = _our_dof(robot, names)
            assert sorted(perm) == list(range(n)), f"{name}: dofs {names} do not cover ours"
            mass, bias = mass[np.ix_(perm, perm)], bias[perm]
            err_m, err_b = np.abs(mass - m_ref).max(), np.abs(bias - b_ref).max()
            assert err_m <= TOL, f"{name} state {k}: max |M - M_mujoco| = {err_m:.3g} (max |M| {np.abs(m_ref).max():.3g})"
            assert err_b <= TOL, (
                f"{name} state {k}: max |bias - bias_mujoco| = {err_b:.3g} (max |bias| {np.abs(b_ref).max():.3g})")
            assert np.allclose(mass, mass.T, rtol=0, atol=1e-12)
    finally:
        scene.destroy()


def test_kuka_trajectory_matches_mujoco_f32(f32):
    path = pybullet("kuka_iiwa", "model.urdf")
    scene, robot = limit_free_scene(path, False, DT)
    try:
        assert robot.get_qpos().dtype == torch.float32
        rng = np.random.default_rng(0)
        joints = {j.name: (rng.uniform(-1, 1), rng.uniform(-2, 2)) for j in scalar_joints(robot)}
        set_state(robot, joints, None)
        n_steps = int(round(2.0 / DT))
        ours = [robot.get_qpos().numpy()]
        for _ in range(n_steps):
            scene.step()
            ours.append(robot.get_qpos().numpy())
        ours = np.array(ours, dtype=np.float64)

        model = mujoco_ref.load_model(path, dt=DT)  # the URDF's own damping applies on both sides
        ref = mujoco_ref.rollout(model, {k: v[0] for k, v in joints.items()}, {k: v[1] for k, v in joints.items()},
                                 n_steps)
        for joint in scalar_joints(robot):
            err = np.max(np.abs(ours[:, joint.qs_idx_local[0]] - ref.qpos[joint.name]))
            assert err <= 1e-4, f"joint {joint.name}: max |q - q_mujoco| = {err:.3g} rad over 2 s in float32"
    finally:
        scene.destroy()


def _rows_scale(robot):
    """Our (body_invweight0 (1, L) translational, rotational, dof_invweight0 (1, D)) at the build's
    masses, armature 0 (these robots have no tendon)."""
    solver = robot._solver
    mass = solver.default_inputs["mass"]
    return solver.invweight_basis(mass, solver.default_inputs["inertia"],
                                  torch.zeros((1, robot.n_dofs), dtype=mass.dtype), solver.check_positive_definite)[:3]


@pytest.mark.parametrize("name", list(ROBOTS))
def test_rows_scale_matches_mujoco_invweight0_f64(f64, name):
    """The constraint rows' scale — MuJoCo's body_invweight0 (translation, rotation) and dof_invweight0, made
    from M at the initial pose (contact.InvweightBasis, which assembles M from the links' centre-of-
    mass Jacobians) — equals mj_setConst's, a free base turned so that no link's frame is the world's."""
    path, free = ROBOTS[name]
    scene = gs.Scene(rigid_options=gs.options.RigidOptions(enable_collision=False))
    robot = scene.add_entity(gs.morphs.URDF(file=path, fixed=not free, pos=(0.1, -0.2, 0.3), euler=(30, -50, 70),
                                            default_armature=0.0))
    scene.build()
    try:
        invweight_link, invweight_turn, invweight_dof = _rows_scale(robot)
        model = mujoco_ref.load_model(path, free_base=free, dt=DT)  # armature 0
        if free:
            model.qpos0[:7] = robot.get_qpos().numpy()[:7]
        mujoco.mj_setConst(model, mujoco.MjData(model))
        perm = _our_dof(robot, mujoco_ref.dof_names(model))
        assert np.allclose(invweight_dof[0].numpy()[perm], model.dof_invweight0, rtol=1e-10, atol=0)
        ours = {link.name: (invweight_link[0, link.idx_local].item(), invweight_turn[0, link.idx_local].item())
                for link in robot.links}
        moving = [b for b in range(1, model.nbody) if model.body(b).name in ours and model.body_invweight0[b, 0] > 0]
        assert len(moving) >= 2
        for b in moving:
            name = model.body(b).name
            assert np.allclose(ours[name], model.body_invweight0[b], rtol=1e-10, atol=0), name
    finally:
        scene.destroy()


def test_rows_scale_per_tree_equals_the_dense_formula_f64(f64):
    """contact.InvweightBasis keeps and inverts M per kinematic tree (trees of one shape batched):
    in a scene of trees of three shapes — a free quadruped, a fixed 2-link pendulum (its base
    welded to the world), and three free boxes and a free capsule — its rows' scale equals the dense
    formula (M of every dof from the links' centre-of-mass Jacobians, one inverse) to round-off,
    with masses, inertias and armature off their defaults; and it holds each tree's block only (its dense K
    took links × dofs² numbers: 36 GiB for 512 free bodies, which could not be built)."""
    scene = gs.Scene(rigid_options=gs.options.RigidOptions(enable_collision=False), show_viewer=False)
    scene.add_entity(gs.morphs.Box(size=(0.1, 0.2, 0.3), pos=(1.0, 0.0, 0.5), euler=(10, 20, 30)))
    scene.add_entity(gs.morphs.URDF(file=asset("quadruped.urdf"), pos=(0.0, 0.0, 0.6), euler=(5, -10, 20)))
    scene.add_entity(gs.morphs.Box(size=(0.3, 0.1, 0.1), pos=(-1.0, 0.0, 0.5)))
    scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True, pos=(0.0, 1.0, 1.0)))
    scene.add_entity(gs.morphs.Capsule(radius=0.05, height=0.2, pos=(0.0, -1.0, 0.5), euler=(0, 40, 0)))
    scene.add_entity(gs.morphs.Box(size=(0.2, 0.2, 0.2), pos=(2.0, 0.0, 0.5)))
    scene.build()
    solver = scene._rigid_solver
    m, basis = solver.model, solver.invweight_basis
    assert len(basis.groups) == 3
    held = sum(group[2].numel() for group in basis.groups)
    assert held < 0.2 * m.n_links * m.n_dofs ** 2  # (its trees: 0.11)
    rng = np.random.default_rng(0)
    mass = torch.tensor(m.link_mass0 * rng.uniform(0.5, 2.0, m.n_links))[None]
    inertia = m.link_inertia * rng.uniform(0.5, 2.0, m.n_links)[:, None, None]
    armature = torch.tensor(rng.uniform(0.0, 0.1, m.n_dofs))[None]
    invweight_t, invweight_r, invweight_dof, _ = basis(mass, torch.tensor(inertia.reshape(1, -1)), armature,
                                                       solver.check_positive_definite)

    jac = torch.empty((1, m.n_links, 6, m.n_dofs), dtype=torch.float64)
    solver.kernels.read_com_jacobians(jac)
    J = jac[0].numpy()
    M = (np.einsum("l,lki,lkj->ij", mass[0].numpy(), J[:, :3], J[:, :3])
         + np.einsum("lki,lkn,lnj->ij", J[:, 3:], inertia, J[:, 3:]) + np.diag(armature[0]))
    inverse = np.linalg.inv(M)
    expected_t, expected_r = (np.einsum("lri,ij,lrj->l", J[:, rows], inverse, J[:, rows]) / 3.0 * (m.link_static == 0)
                              for rows in (slice(0, 3), slice(3, 6)))
    expected_dof = np.diag(inverse).copy()
    for first in np.flatnonzero(m.dof_q < 0)[::3]:  # a free joint's translations, then its rotations
        expected_dof[first: first + 3] = expected_dof[first: first + 3].mean()
    np.testing.assert_allclose(invweight_t[0].numpy(), expected_t, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(invweight_r[0].numpy(), expected_r, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(invweight_dof[0].numpy(), expected_dof, rtol=1e-12, atol=1e-15)
    assert (invweight_t[0].numpy()[m.link_static == 0] > 0).all()


# Prismatic fingers on a fixed base, one per case: MuJoCo scales the rows of a sliding leaf (its
# body_simple = 2) by 1 / mass, every other body by the mean translational diagonal of J M⁻¹ Jᵀ.
# name: (inertia ixx iyy izz ixy, centre of mass, axis, parent, child) of the finger
FINGERS = {
    "simple": ((3e-5, 2.5e-5, 1.5e-5, 0), (0, 0, 0), (0, 1, 0), "base", False),
    "equal_moments": ((1e-5, 1e-5, 1e-5, 0), (0, 0, 0), (0, 0, -1), "base", False),
    "product_under_1e-12": ((3e-5, 2.5e-5, 1.5e-5, 5e-13), (0, 0, 0), (1, 0, 0), "base", False),
    "moments_ascending": ((1.5e-5, 2.5e-5, 3e-5, 0), (0, 0, 0), (0, 1, 0), "base", False),
    "product": ((3e-5, 2.5e-5, 1.5e-5, 1e-6), (0, 0, 0), (0, 1, 0), "base", False),
    "com_off_origin": ((3e-5, 2.5e-5, 1.5e-5, 0), (0.01, 0, 0), (0, 1, 0), "base", False),
    "tilted_axis": ((3e-5, 2.5e-5, 1.5e-5, 0), (0, 0, 0), (0, 0.6, 0.8), "base", False),
    "carries_a_link": ((3e-5, 2.5e-5, 1.5e-5, 0), (0, 0, 0), (0, 1, 0), "base", True),
    "on_a_moving_link": ((3e-5, 2.5e-5, 1.5e-5, 0), (0, 0, 0), (0, 1, 0), "arm", False),
}
SIMPLE_FINGERS = {"simple", "equal_moments", "product_under_1e-12"}


def _fingers_urdf(path):
    """A root link named "world" (MuJoCo's URDF reader takes it for the world), a base welded to
    it, a hinged arm on the base, and one prismatic finger per FINGERS case."""
    def inertial(mass, moments, com):
        ixx, iyy, izz, ixy = moments
        return (f'<inertial><origin xyz="{com[0]} {com[1]} {com[2]}"/><mass value="{mass}"/><inertia ixx="{ixx}" '
                f'iyy="{iyy}" izz="{izz}" ixy="{ixy}" ixz="0" iyz="0"/></inertial>')
    links = ['<link name="world"/>', f'<link name="base">{inertial(1.0, (0.01, 0.01, 0.01, 0), (0, 0, 0))}</link>',
             f'<link name="arm">{inertial(0.5, (3e-3, 2.5e-3, 1.5e-3, 0), (0, 0, 0))}</link>']
    joints = ['<joint name="weld" type="fixed"><parent link="world"/><child link="base"/><origin xyz="0 0 0.5"/></joint>',
              '<joint name="arm_joint" type="revolute"><parent link="base"/><child link="arm"/><origin xyz="0 0 0.3"/>'
              '<axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="10" velocity="1"/></joint>']
    for k, (name, (moments, com, axis, parent, child)) in enumerate(FINGERS.items()):
        links.append(f'<link name="{name}">{inertial(0.02 + 0.01 * k, moments, com)}</link>')
        joints.append(f'<joint name="{name}_slide" type="prismatic"><parent link="{parent}"/><child link="{name}"/>'
                      f'<origin xyz="{0.05 * k} 0.1 0.2"/><axis xyz="{axis[0]} {axis[1]} {axis[2]}"/>'
                      f'<limit lower="-0.05" upper="0.05" effort="10" velocity="1"/></joint>')
        if child:
            links.append(f'<link name="{name}_tip">{inertial(0.01, (2e-6, 2e-6, 1e-6, 0), (0, 0, 0.01))}</link>')
            joints.append(f'<joint name="{name}_tip_hinge" type="revolute"><parent link="{name}"/>'
                          f'<child link="{name}_tip"/><origin xyz="0 0 0.03"/><axis xyz="1 0 0"/>'
                          f'<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>')
    path.write_text('<?xml version="1.0"?>\n<robot name="fingers">' + "".join(links + joints) + "</robot>")
    return str(path)


@pytest.mark.parametrize("merge", [True, False], ids=["merged", "unmerged"])
def test_rows_scale_of_sliding_leaves_matches_mujoco_f64(f64, tmp_path, merge):
    """MuJoCo takes body_invweight0 and dof_invweight0 of a sliding leaf (prismatic joints along
    link axes, no child, on a base welded to the world, centre of mass at the link origin, principal
    axes the link's in descending order of moment: its body_simple = 2) as 1 / mass, where the
    mean diagonal of J M⁻¹ Jᵀ gives a third of that for a single slider: a gripper's contacts 3×
    stiffer than MuJoCo's. Ours equals MuJoCo's in every case of FINGERS, the simple ones (MuJoCo's
    verdict checked) and the ones one condition away from it; with the fixed links merged (as
    MuJoCo's fusestatic) and kept (the "world" root and the base apart: MuJoCo's without it)."""
    path = _fingers_urdf(tmp_path / "fingers.urdf")
    scene = gs.Scene(rigid_options=gs.options.RigidOptions(enable_collision=False))
    robot = scene.add_entity(gs.morphs.URDF(file=path, fixed=True, merge_fixed_links=merge, default_armature=0.0))
    scene.build()
    try:
        invweight_link, invweight_turn, invweight_dof = _rows_scale(robot)
        spec = mujoco_ref.bare_spec(path)
        spec.compiler.fusestatic = merge
        model = spec.compile()
        simple = {model.body(b).name for b in range(model.nbody) if model.body_simple[b] == 2}
        assert simple == SIMPLE_FINGERS
        perm = _our_dof(robot, mujoco_ref.dof_names(model))
        np.testing.assert_allclose(invweight_dof[0].numpy()[perm], model.dof_invweight0, rtol=1e-10, atol=0)
        for link in robot.links:
            if link.name not in ("world", "base"):
                assert np.isclose(invweight_link[0, link.idx_local].item(), model.body(link.name).invweight0[0],
                                  rtol=1e-10, atol=0), link.name
    finally:
        scene.destroy()


@pytest.mark.parametrize("name", ["kuka", "quadruped"])
def test_links_at_their_centres_of_mass_match_mujoco_f64(f64, name):
    """get_links_pos/get_links_vel at gs.link_ref_frame.link_COM equal MuJoCo's body inertial
    frames (xipos, mj_objectVelocity of mjOBJ_BODY), and at root_COM the robot's centre of mass
    (subtree_com of MuJoCo's root body), at random states; a link MuJoCo fuses into its parent is
    left out."""
    path, free = ROBOTS[name]
    scene, robot = limit_free_scene(path, free, DT)
    try:
        model = mujoco_ref.load_model(path, free_base=free, dt=DT)
        data = mujoco.MjData(model)
        rng = np.random.default_rng(7)
        for _ in range(3):
            joints, base = random_state(robot, rng, free, q_range=1.5)
            set_state(robot, joints, base)
            mujoco_ref._set_state(model, data, {j: v[0] for j, v in joints.items()}, {j: v[1] for j, v in joints.items()},
                                  None if base is None else base[0], None if base is None else base[1])
            mujoco.mj_forward(model, data)
            com = robot.get_links_pos(ref=gs.link_ref_frame.link_COM).numpy()
            com_vel = robot.get_links_vel(ref=gs.link_ref_frame.link_COM).numpy()
            tree = robot.get_links_pos(ref=gs.link_ref_frame.root_COM).numpy()
            compared = 0
            for k, link in enumerate(robot.links):
                body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, link.name)
                if body < 0 or model.body_mass[body] == 0.0:
                    continue
                velocity = np.zeros(6)
                mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_BODY, body, velocity, 0)
                assert np.abs(com[k] - data.xipos[body]).max() < 1e-12, link.name
                assert np.abs(com_vel[k] - velocity[3:]).max() < 1e-11, link.name
                compared += 1
            assert compared >= 5
            root = int(model.body_rootid[1])
            assert np.abs(tree - data.subtree_com[root]).max() < 1e-12
    finally:
        scene.destroy()
