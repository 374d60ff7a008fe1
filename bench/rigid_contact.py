"""Forward throughput with contact, beside MuJoCo: env-steps/s of three scenes at n_envs 1, 64
and 1024, float32 here and float64 in MuJoCo, dt 2 ms, MuJoCo's contact defaults on both sides
(``RigidOptions(enable_mujoco_compatibility=True)``, pyramidal cone).

Scenes: a 0.2 m box resting on a plane; the pybullet_data ``a1`` quadruped on a plane holding
a standing pose with position servos (kp 100, kv 2; MuJoCo: position actuators with the same
gains); a tower of 10 boxes. Each is timed resting (after a warm-up), as a scene runs on.
MuJoCo is ``mujoco.rollout`` with 2 threads on the same models (built by tests/contact_scenes
for the boxes; the a1 URDF with a plane and a free joint). Best of ``--repeats`` runs of
``--steps`` steps after a warm-up.

Goals (issue "Contact"): ≥ 2× MuJoCo at 1024 envs; within 2× of MuJoCo at 1 env.

Run:  python bench/rigid_contact.py [--steps 200] [--repeats 3] [--envs 1 64 1024]
"""
import argparse
import os
import sys
import time

import mujoco
import numpy as np
import pybullet_data
from mujoco import rollout

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import genesis_lite as gs  # noqa: E402
from tests.contact_scenes import Body, ContactScene, a1_mujoco, build_mujoco, build_ours  # noqa: E402

A1 = os.path.join(pybullet_data.getDataPath(), "a1", "a1.urdf")
DT = 0.002
MJ_THREADS = 2


def box_scene():
    return ContactScene([Body("box", (0.2, 0.2, 0.2), pos=(0, 0, 0.0995))], dt=DT)


def tower_scene():
    return ContactScene([Body("box", (0.2, 0.2, 0.2), pos=(0, 0, 0.1 + 0.2 * k - 0.0005 * (k + 1)))
                         for k in range(10)], dt=DT)


A1_STAND = np.tile([0.0, 0.8, -1.5], 4)  # hip, thigh, calf per leg (rad)
A1_Z, KP, KV = 0.305, 100.0, 2.0


def a1_ours(n_envs):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT),
                     rigid_options=gs.options.RigidOptions(enable_mujoco_compatibility=True), show_viewer=False)
    scene.add_entity(gs.morphs.Plane())
    robot = scene.add_entity(gs.morphs.URDF(file=A1, pos=(0, 0, A1_Z)))
    scene.build(n_envs=n_envs)
    legs = np.arange(6, robot.n_dofs)
    batch = lambda row: row if n_envs == 0 else np.tile(row, (n_envs, 1))  # noqa: E731
    robot.set_dofs_position(batch(A1_STAND), legs)
    robot.set_dofs_kp(batch(np.full(len(legs), KP)), legs)
    robot.set_dofs_kv(batch(np.full(len(legs), KV)), legs)
    robot.control_dofs_position(batch(A1_STAND), legs)
    return scene


def time_ours(scene, steps, repeats):
    for _ in range(50):  # compile, settle
        scene.step()
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(steps):
            scene.step()
        scene._rigid_solver.download_state()  # the work is done when the state can be read
        best = min(best, time.perf_counter() - start)
    return best


def time_mujoco(m, d, n_envs, steps, repeats):
    for _ in range(50):  # settle, as ours
        mujoco.mj_step(m, d)
    state = np.zeros((n_envs, mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_FULLPHYSICS)))
    mujoco.mj_getState(m, d, state[0], mujoco.mjtState.mjSTATE_FULLPHYSICS)
    state[:] = state[0]
    datas = [mujoco.MjData(m) for _ in range(MJ_THREADS)]
    best = float("inf")
    with rollout.Rollout(nthread=MJ_THREADS) as runner:
        control = np.tile(d.ctrl, (n_envs, steps, 1))
        warm = min(5, steps)
        runner.rollout([m] * n_envs, datas, state, control[:, :warm], nstep=warm)
        for _ in range(repeats):
            start = time.perf_counter()
            runner.rollout([m] * n_envs, datas, state, control, nstep=steps)
            best = min(best, time.perf_counter() - start)
    return best


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--envs", type=int, nargs="+", default=[1, 64, 1024])
    args = parser.parse_args()
    gs.init(backend=gs.cpu, precision="32", logging_level="warning")
    print(f"{'scene':8} {'n_envs':>6} {'ours env-steps/s':>17} {'MuJoCo env-steps/s':>19} {'ratio':>6}")
    for name in ("box", "a1", "tower"):
        for n_envs in args.envs:
            if name == "a1":
                scene, (m, d) = a1_ours(n_envs if n_envs > 1 else 0), a1_mujoco(A1, A1_Z, A1_STAND, KP, KV, DT)
            else:
                spec = box_scene() if name == "box" else tower_scene()
                spec.n_envs = n_envs if n_envs > 1 else 0
                scene, _ = build_ours(spec)
                m = build_mujoco(spec, scene._rigid_solver.model)
                d = mujoco.MjData(m)
            ours = n_envs * args.steps / time_ours(scene, args.steps, args.repeats)
            theirs = n_envs * args.steps / time_mujoco(m, d, n_envs, args.steps, args.repeats)
            print(f"{name:8} {n_envs:6d} {ours:17.0f} {theirs:19.0f} {ours / theirs:6.2f}", flush=True)


if __name__ == "__main__":
    main()
