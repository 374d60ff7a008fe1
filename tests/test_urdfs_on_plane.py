"""Every pybullet_data URDF on a plane: it loads with its collision shapes, drops with a free
base onto the plane and steps 100 times (dt 0.01 s, Genesis's default options) to a finite
state, or raises a ``gs.GenesisException`` subclass naming the file or the entity.

Each file gets its own scene (a plane and the robot): since kernels compile once per process a
scene costs only its build, and one robot per scene keeps the dense per-env constraint solve at
that robot's size (many robots in one scene would make it grow with the square of their dofs
or worse). The robot is built with its base origin at z = 0, then lifted so that its lowest
collision point (the support of every collision shape, meshes by their convex hull, at the
initial pose) is GAP above the plane; a robot without collision shapes is dropped from 1 m.

Checks per file:
- the built entity has one collision geom per ``<collision>`` element of the URDF (fixed
  links fused into their parents keep theirs);
- after 100 steps qpos, qvel, link positions and orientations are finite (``check_nan`` is off:
  a non-finite state fails the test, it is not excused by an error);
- when every collision shape of the robot collides with the plane (a pair with it: all of them
  unless pair rules drop some), none is more than SINK below the plane after the steps: the
  shapes hold the robot up;
- an exception, at load, build or step, is a GenesisException naming the file or the entity.

The default run covers REPRESENTATIVE (the robots, toys and objects of every folder, and a few
of the 1000 random mesh blobs); ``-m slow`` runs all files. Meshes collide as their convex
hulls. Files that cannot be simulated raise a named AssetError at build: a singular mass matrix
(a massless root carrying a joint under the free base, as cartpole's; the random blobs'
inertia diag(1, 1, 0), which MuJoCo refuses too), malformed XML, missing meshes.
"""
import os
import re
import xml.etree.ElementTree as ET

import numpy as np
import pybullet_data
import pytest
import torch

import genesis_lite as gs
from genesis_lite.solvers.rigid.collision import convex
from genesis_lite.solvers.rigid.geometry import BOX, CAPSULE, CYLINDER, MESH, SPHERE
from tests.test_pybullet_urdfs import ALL  # every .urdf under pybullet_data, relative to it, sorted

DATA = pybullet_data.getDataPath()
N_STEPS, DT = 100, 0.01
GAP = 0.005  # m between the lowest collision point and the plane at the start
NO_GEOM_HEIGHT = 1.0  # m, base height of a robot without collision shapes
SINK = 0.005  # m, deepest a shape that collides with the plane may be below it after the steps
REPRESENTATIVE = [rel for rel in ALL if not rel.startswith("random_urdfs")] + [
    f"random_urdfs/{k:03d}/{k:03d}.urdf" for k in (0, 1, 250, 500, 999)]


def _quat_to_matrix(q):
    """(4,) (w, x, y, z) → (3, 3)."""
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _hull_vertices(model, mesh):
    """(V, 3) vertices (m, geom frame) of mesh number ``mesh``'s convex hull in the model."""
    field = {name: int(model.hull_int[k]) for k, name in enumerate(convex.HULL_INT_FIELDS)}
    start = int(model.hull_int[field["hull_vertadr"] + mesh])
    return model.hull_vec[start: start + int(model.hull_int[field["hull_vertnum"] + mesh])]


def _lowest_point(robot, geoms=None):
    """Lowest world z (m) of the robot's collision shapes ``geoms`` (global indices; None: all of
    them) at its current pose; None without any."""
    model = robot.scene._rigid_solver.model
    link_pos = robot.get_links_pos().cpu().numpy()
    link_quat = robot.get_links_quat().cpu().numpy()
    lowest = None
    for g in range(robot.geom_start, robot.geom_start + robot.n_geoms) if geoms is None else geoms:
        link = model.geom_link[g] - robot.link_start
        link_rot = _quat_to_matrix(link_quat[link])
        rot = link_rot @ _quat_to_matrix(model.geom_quat[g])
        centre = link_pos[link] + link_rot @ model.geom_pos[g]
        kind, size, up = model.geom_type[g], model.geom_size[g], rot[2]  # up: world z in the geom frame
        if kind == MESH:
            z = centre[2] + float((_hull_vertices(model, model.geom_mesh[g]) @ up).min())
        elif kind == BOX:
            z = centre[2] - float(np.abs(up) @ size)
        elif kind == SPHERE:
            z = centre[2] - size[0]
        elif kind == CAPSULE:
            z = centre[2] - size[0] - size[1] * abs(up[2])
        elif kind == CYLINDER:
            z = centre[2] - size[0] * np.hypot(up[0], up[1]) - size[1] * abs(up[2])
        else:
            raise AssertionError(f"geom type {kind} has no support function here")
        lowest = z if lowest is None else min(lowest, z)
    return lowest


def _collision_elements(path):
    """Number of <collision> elements with a <geometry> in the URDF file."""
    with open(path, encoding="utf-8") as f:
        root = ET.fromstring(f.read().strip())  # some files start with a blank line
    return sum(1 for link in root.iter("link") for c in link.findall("collision") if c.find("geometry") is not None)


def _plane_held(robot, plane):
    """The robot's geoms (global indices) that collide with the plane: those of a candidate
    pair with it that the solver simulates (pairs without a collider are dropped at build)."""
    model = robot.scene._rigid_solver.model
    pairs = zip(model.pair_geom1.tolist(), model.pair_geom2.tolist())
    return sorted({a + b - plane.geom_start for a, b in pairs if plane.geom_start in (a, b)})


def _finite(robot):
    """qpos, qvel and the link poses hold no NaN or inf."""
    parts = [robot.get_qpos(), robot.get_dofs_velocity(), robot.get_links_pos(), robot.get_links_quat()]
    return all(bool(torch.isfinite(p).all()) for p in parts)


def _check_error(rel, exc):
    """``exc`` raised for file ``rel`` is a GenesisException that names the file or the entity."""
    assert isinstance(exc, gs.GenesisException), f"{rel}: expected a GenesisException, got {exc!r}"
    named = re.search(re.escape(os.path.basename(rel)) + "|entity '|entities: ", str(exc))
    assert named, f"{rel}: the error names neither the file nor the entity: {exc}"


def _drop_and_step(rel):
    """Load ``rel`` with a free base above a plane and step it N_STEPS times; asserts the checks of
    the module docstring."""
    path = os.path.join(DATA, rel)
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT), show_viewer=False)
    try:
        plane = scene.add_entity(gs.morphs.Plane())
        try:
            robot = scene.add_entity(gs.morphs.URDF(file=path, fixed=False), name="robot")
            scene.build()
        except Exception as exc:  # noqa: BLE001 — judged: only a named GenesisException may stop a load
            _check_error(rel, exc)
            return "load error"
        assert robot.n_geoms == _collision_elements(path), (robot.n_geoms, _collision_elements(path))
        lowest = _lowest_point(robot)
        lift = NO_GEOM_HEIGHT if lowest is None else GAP - lowest
        robot.set_pos(robot.get_pos() + torch.tensor([0.0, 0.0, lift], dtype=gs.tc_float))
        try:
            for _ in range(N_STEPS):
                scene.step()
        except Exception as exc:  # noqa: BLE001
            _check_error(rel, exc)
            return "step error"
        assert _finite(robot), f"{rel}: non-finite state after {N_STEPS} steps"
        held = _plane_held(robot, plane)
        if held and len(held) == robot.n_geoms:  # every shape collides with the plane: none sinks far
            assert _lowest_point(robot) > -SINK, (rel, _lowest_point(robot))
        return "ok"
    finally:
        scene.destroy()


@pytest.mark.parametrize("rel", REPRESENTATIVE)
def test_urdf_on_plane(f64, rel):
    _drop_and_step(rel)


@pytest.mark.slow
@pytest.mark.parametrize("rel", [rel for rel in ALL if rel not in REPRESENTATIVE])
def test_every_urdf_on_plane(f64, rel):
    _drop_and_step(rel)
