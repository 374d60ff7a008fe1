"""The same contact scene in genesis_lite and in MuJoCo (test support).

A scene is a plane (optional) and free bodies, each one primitive shape. The MuJoCo model takes
every body's mass, centre of mass and inertia from our built model, so the two agree on mass
properties whatever each derives from the shape; the shapes, friction, solref and solimp are
MuJoCo's defaults unless given. State layout is the same in both: per body qpos (pos, quat)
and qvel (world linear velocity, body angular velocity), bodies in order.
"""
from dataclasses import dataclass, field

import mujoco
import numpy as np

import genesis_lite as gs


@dataclass
class Body:
    shape: str          # "box" | "sphere" | "capsule" | "cylinder"
    size: tuple         # ours: box full extents; sphere (r,); capsule/cylinder (r, length)
    pos: tuple = (0.0, 0.0, 0.5)
    quat: tuple = (1.0, 0.0, 0.0, 0.0)


@dataclass
class ContactScene:
    bodies: list
    plane: bool = True
    dt: float = 0.002
    cone: str = "pyramidal"
    impratio: float = 1.0
    solref: tuple = None   # every geom's, None: MuJoCo's default
    solimp: tuple = None
    sol_per_geom: list = None  # one (solref, solimp) 7-tuple per geom (plane first): overrides solref/solimp
    n_envs: int = 0
    options: dict = field(default_factory=dict)
    condim: int = 3        # every geom's: 4 and 6 by RigidOptions' enable_torsional/rolling_friction
    friction: tuple = None  # every geom's (sliding, torsional, rolling), None: MuJoCo's default


def _morph(body):
    kw = dict(pos=body.pos, quat=body.quat)
    if body.shape == "box":
        return gs.morphs.Box(size=body.size, **kw)
    if body.shape == "sphere":
        return gs.morphs.Sphere(radius=body.size[0], **kw)
    if body.shape == "capsule":
        return gs.morphs.Capsule(radius=body.size[0], height=body.size[1], **kw)
    return gs.morphs.Cylinder(radius=body.size[0], height=body.size[1], **kw)


def build_ours(spec):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=spec.dt),
                     rigid_options=gs.options.RigidOptions(enable_mujoco_compatibility=True,
                                                           friction_cone=spec.cone, impratio=spec.impratio,
                                                           enable_torsional_friction=spec.condim >= 4,
                                                           enable_rolling_friction=spec.condim == 6,
                                                           **spec.options),
                     show_viewer=False)
    material = None
    if spec.friction is not None:
        material = gs.materials.Rigid(friction=spec.friction[0], friction_torsional=spec.friction[1],
                                      friction_rolling=spec.friction[2])
    plane = scene.add_entity(gs.morphs.Plane(), material=material) if spec.plane else None
    entities = [scene.add_entity(_morph(b), material=material) for b in spec.bodies]
    scene.build(n_envs=spec.n_envs)
    for entity, params in zip(([plane] if spec.plane else []) + entities, _sol_params(spec)):
        if params is not None:
            entity.set_sol_params(params)
    return scene, entities


def _sol_params(spec):
    """Each geom's 7 sol params (None: MuJoCo's defaults), plane first."""
    n = len(spec.bodies) + bool(spec.plane)
    if spec.sol_per_geom is not None:
        return list(spec.sol_per_geom)
    if spec.solref is None and spec.solimp is None:
        return [None] * n
    return [(*(spec.solref or (0.02, 1.0)), *(spec.solimp or (0.9, 0.95, 0.001, 0.5, 2.0)))] * n


def _sol_xml(params):
    if params is None:
        return ""
    return f' solref="{params[0]} {params[1]}" solimp="' + " ".join(str(v) for v in params[2:]) + '"'



def _geom_xml(body):
    s = np.asarray(body.size, dtype=float)
    if body.shape == "box":
        return f'type="box" size="{s[0] / 2} {s[1] / 2} {s[2] / 2}"'
    if body.shape == "sphere":
        return f'type="sphere" size="{s[0]}"'
    return f'type="{body.shape}" size="{s[0]} {s[1] / 2}"'


def build_mujoco(spec, model):
    """MuJoCo's model of the scene, mass properties from our RigidModel ``model``."""
    friction = "" if spec.friction is None else ' friction="' + " ".join(map(str, spec.friction)) + '"'
    sols = [_sol_xml(params) + f' condim="{spec.condim}"' + friction for params in _sol_params(spec)]
    plane_sol, body_sols = (sols[0], sols[1:]) if spec.plane else ("", sols)
    moving = [l for l in range(model.n_links) if model.link_jtype[l] != 0]
    bodies = []
    for k, (body, link, sol) in enumerate(zip(spec.bodies, moving, body_sols)):
        inertia = model.link_inertia0[link]
        com = model.link_com[link]
        bodies.append(
            f'<body name="b{k}" pos="{" ".join(map(str, body.pos))}" quat="{" ".join(map(str, body.quat))}">'
            f'<freejoint/><inertial pos="{com[0]} {com[1]} {com[2]}" mass="{model.link_mass0[link]}" '
            f'fullinertia="{inertia[0, 0]} {inertia[1, 1]} {inertia[2, 2]} {inertia[0, 1]} {inertia[0, 2]} '
            f'{inertia[1, 2]}"/><geom {_geom_xml(body)}{sol}/></body>')
    plane = f'<geom type="plane" size="0 0 1"{plane_sol}/>' if spec.plane else ""
    xml = (f'<mujoco><option timestep="{spec.dt}" cone="{spec.cone}" impratio="{spec.impratio}"/>'
           f'<worldbody>{plane}{"".join(bodies)}</worldbody></mujoco>')
    return mujoco.MjModel.from_xml_string(xml)


def a1_mujoco(path, z, stand, kp, kv, dt, ground=None):
    """MuJoCo's model and data of a URDF quadruped (pybullet_data's a1) on a plane (or what
    ``ground(spec)`` adds to the MjSpec's worldbody instead): a free base at height z (m), position
    actuators (kp, kv) on every other joint, targets and joints at ``stand`` (rad); the
    implicitfast integrator."""
    spec = mujoco.MjSpec.from_file(path)
    spec.compiler.fusestatic = True
    spec.compiler.alignfree = False
    root = spec.worldbody.bodies[0]
    root.add_freejoint()
    root.pos = [0.0, 0.0, z]
    if ground is None:
        spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 1])
    else:
        ground(spec)
    spec.option.timestep = dt
    # the servos' kv implicit, as ours (actuation.py): MuJoCo's implicitfast (no force range here, so no
    # actuator is clamped, where implicitfast would drop its kv); its Euler treats only damping so
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    for joint in spec.joints:
        if joint.type != mujoco.mjtJoint.mjJNT_FREE:
            spec.add_actuator(target=joint.name, trntype=mujoco.mjtTrn.mjTRN_JOINT).set_to_position(kp=kp, kv=kv)
    m = spec.compile()
    d = mujoco.MjData(m)
    d.qpos[7:] = d.ctrl[:] = stand
    return m, d


# Two box fingers on prismatic joints of a fixed palm (sliding leaves: MuJoCo's body_simple 2)
GRIPPER = """<?xml version="1.0"?>
<robot name="gripper">
  <link name="palm"><inertial><mass value="1.0"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/>
    </inertial><collision><origin xyz="0 0 0.2"/><geometry><box size="0.05 0.2 0.02"/></geometry></collision></link>
  <link name="left"><inertial><mass value="0.02"/><inertia ixx="1e-5" iyy="1e-5" izz="1e-5" ixy="0" ixz="0" iyz="0"/>
    </inertial><collision><geometry><box size="0.02 0.01 0.05"/></geometry></collision></link>
  <link name="right"><inertial><mass value="0.03"/><inertia ixx="2e-5" iyy="1.5e-5" izz="1e-5" ixy="0" ixz="0"
    iyz="0"/></inertial><collision><geometry><box size="0.02 0.01 0.05"/></geometry></collision></link>
  <joint name="left_slide" type="prismatic"><parent link="palm"/><child link="left"/><origin xyz="0 0.025 0.1"/>
    <axis xyz="0 -1 0"/><limit lower="-0.05" upper="0.05" effort="100" velocity="1"/></joint>
  <joint name="right_slide" type="prismatic"><parent link="palm"/><child link="right"/><origin xyz="0 -0.025 0.1"/>
    <axis xyz="0 1 0"/><limit lower="-0.05" upper="0.05" effort="100" velocity="1"/></joint>
</robot>
"""
