"""Forward throughput of the rigid solver beside MuJoCo, and time to first step.

KUKA iiwa (pybullet_data ``kuka_iiwa/model.urdf``, fixed base, 7 dofs), float32, contact-free
(``RigidOptions(enable_collision=False)``; joint limits off too, as in the MuJoCo model), dt =
0.01 s, no controls. For n_envs in (1, 64, 1024) both simulators start from the same random
joint positions and velocities and run ``--steps`` steps after a warm-up; the best of
``--repeats`` timings is reported as env-steps/s. MuJoCo is ``mujoco.rollout`` with 2 threads
(one MjData per thread) on the same URDF, loaded by ``tests/mujoco_ref.load_model`` (contacts
and limits off, float64); the "MuJoCo 1 thread" column (env-steps/s) is the same rollout in
the calling thread (at n_envs = 1 the 2-thread rollout mostly measures its thread start-up).
The max |Δq| column compares the final joint positions of the two (float32 against float64: a
sanity check, not an accuracy test).

Time to first step: a fresh ``python`` subprocess imports genesis_lite, calls gs.init, builds
the KUKA scene and steps once; it runs twice so the second run has a warm Taichi kernel cache,
and the second is reported (with its parts).

Goals: ≥ 2× MuJoCo's throughput at 1024 envs; first step < 5 s.

Run:  python bench/rigid_forward.py [--steps 100] [--repeats 10] [--envs 1 64 1024]
"""
import argparse
import json
import os
import subprocess
import sys
import time

import mujoco
import numpy as np
import pybullet_data
from mujoco import rollout

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import genesis_lite as gs  # noqa: E402
from tests import mujoco_ref  # noqa: E402

KUKA = os.path.join(pybullet_data.getDataPath(), "kuka_iiwa", "model.urdf")
DT = 0.01
MJ_THREADS = 2

FIRST_STEP = r"""
import time, json
t0 = time.perf_counter()
import genesis_lite as gs
t1 = time.perf_counter()
gs.init(backend=gs.cpu, precision="32")
t2 = time.perf_counter()
scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01),
                 rigid_options=gs.options.RigidOptions(enable_collision=False, enable_joint_limit=False))
robot = scene.add_entity(gs.morphs.URDF(file=%r, fixed=True))
scene.build()
t3 = time.perf_counter()
scene.step()
robot.get_dofs_position()
t4 = time.perf_counter()
print("RESULT" + json.dumps({"import": t1 - t0, "init": t2 - t1, "build": t3 - t2, "step": t4 - t3, "total": t4 - t0}))
"""


def initial_states(n_envs, n_dofs, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(-1.0, 1.0, (n_envs, n_dofs)), rng.uniform(-1.0, 1.0, (n_envs, n_dofs))


def bench_ours(scene, robot, q0, qd0, n_steps, repeats):
    """Best env-steps/s over ``repeats`` timed runs of n_steps, and the final joint positions."""
    def start():
        scene.reset()
        robot.set_dofs_position(q0)
        robot.set_dofs_velocity(qd0)

    start()
    for _ in range(10):  # warm-up: compile, first uploads
        scene.step()
    best = float("inf")
    for _ in range(repeats):
        start()
        robot.get_dofs_position()  # make sure the start state is in place before timing
        t0 = time.perf_counter()
        for _ in range(n_steps):
            scene.step()
        q = robot.get_dofs_position()  # the work is done once the state is read
        best = min(best, time.perf_counter() - t0)
    return len(q0) * n_steps / best, best, q.detach().cpu().numpy().astype(np.float64)


def bench_mujoco(model, q0, qd0, order, n_steps, repeats, n_threads=MJ_THREADS):
    """Best env-steps/s of mujoco.rollout (n_threads MjData, one per thread; 1: the calling thread),
    and the final qpos in our dof order."""
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    data = mujoco.MjData(model)
    n = len(q0)
    x0 = np.empty((n, mujoco.mj_stateSize(model, spec)))
    for i in range(n):
        mujoco.mj_resetData(model, data)
        data.qpos[order] = q0[i]
        data.qvel[order] = qd0[i]
        mujoco.mj_getState(model, data, x0[i], spec)
    datas = [mujoco.MjData(model) for _ in range(n_threads)] if n_threads > 1 else mujoco.MjData(model)
    out = np.empty((n, n_steps, x0.shape[1]))
    rollout.rollout(model, datas, x0, nstep=min(n_steps, 10), state=out[:, : min(n_steps, 10)])  # warm-up
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        rollout.rollout(model, datas, x0, nstep=n_steps, state=out)
        best = min(best, time.perf_counter() - t0)
    qpos = out[:, -1, 1: 1 + model.nq]  # FULLPHYSICS: time, qpos, qvel, ...
    return n * n_steps / best, best, qpos[:, order]


def first_step_time():
    """Time to first step in fresh subprocesses; returns the runs' measured parts (second = warm)."""
    runs = []
    for _ in range(2):
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-c", FIRST_STEP % KUKA], capture_output=True, text=True, cwd=ROOT)
        wall = time.perf_counter() - t0
        line = [s for s in proc.stdout.splitlines() if s.startswith("RESULT")]
        if proc.returncode != 0 or not line:
            raise RuntimeError(f"first-step subprocess failed:\n{proc.stdout}\n{proc.stderr}")
        parts = json.loads(line[0][len("RESULT"):])
        parts["process wall"] = wall
        runs.append(parts)
    return runs


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=10)
    parser.add_argument("--envs", type=int, nargs="+", default=[1, 64, 1024])
    parser.add_argument("--skip-first-step", action="store_true")
    args = parser.parse_args()

    print(f"KUKA iiwa forward, float32, contact-free, dt={DT}, {args.steps} steps, best of {args.repeats}; "
          f"{os.cpu_count()} CPUs; MuJoCo {mujoco.__version__} rollout with {MJ_THREADS} threads")
    gs.init(backend=gs.cpu, precision="32", logging_level="warning")
    model = mujoco_ref.load_model(KUKA, dt=DT)
    mj_names = mujoco_ref.dof_names(model)

    rows = []
    for n_envs in args.envs:
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT),
                         rigid_options=gs.options.RigidOptions(enable_collision=False, enable_joint_limit=False))
        robot = scene.add_entity(gs.morphs.URDF(file=KUKA, fixed=True, default_armature=0.0))  # (as MuJoCo's)
        t0 = time.perf_counter()
        scene.build(n_envs=n_envs)
        build = time.perf_counter() - t0
        names = [j.name for j in robot.joints if j.n_dofs == 1]
        order = [mj_names.index(name) for name in names]  # MuJoCo dof of each of ours
        q0, qd0 = initial_states(n_envs, robot.n_dofs)
        ours, ours_t, q_ours = bench_ours(scene, robot, q0, qd0, args.steps, args.repeats)
        mj, mj_t, q_mj = bench_mujoco(model, q0, qd0, order, args.steps, args.repeats)
        mj1 = bench_mujoco(model, q0, qd0, order, args.steps, args.repeats, n_threads=1)[0]
        diff = float(np.abs(q_ours.reshape(n_envs, -1) - q_mj).max())
        rows.append((n_envs, ours, mj, ours / mj, ours_t / args.steps * 1e3, mj_t / args.steps * 1e3, mj1, diff,
                     build))
        print(f"  n_envs={n_envs} done (build {build:.2f} s)", flush=True)
        scene.destroy()

    print()
    header = (f"{'n_envs':>7} | {'ours env-steps/s':>16} | {'MuJoCo env-steps/s':>18} | {'ours/MuJoCo':>11} | "
              f"{'ours ms/step':>12} | {'MuJoCo ms/step':>14} | {'MuJoCo 1 thread':>15} | {'max |Δq| rad':>12} | "
              f"{'build s':>7}")
    print(header)
    print("-" * len(header))
    for n_envs, ours, mj, ratio, ours_ms, mj_ms, mj1, diff, build in rows:
        print(f"{n_envs:>7} | {ours:>16,.0f} | {mj:>18,.0f} | {ratio:>11.2f} | {ours_ms:>12.3f} | {mj_ms:>14.3f} | "
              f"{mj1:>15,.0f} | {diff:>12.2e} | {build:>7.2f}")
    big = [r for r in rows if r[0] == 1024]
    if big:
        verdict = "met" if big[0][3] >= 2.0 else "NOT met"
        print(f"goal ≥ 2× MuJoCo at 1024 envs: {big[0][3]:.2f}× — {verdict}")

    if not args.skip_first_step:
        runs = first_step_time()
        print()
        print("time to first step (fresh process: import genesis_lite + gs.init + build KUKA + one step), s")
        keys = ["import", "init", "build", "step", "total", "process wall"]
        print(f"{'run':>14} | " + " | ".join(f"{k:>12}" for k in keys))
        for label, run in zip(("1 (cold-ish)", "2 (warm cache)"), runs):
            print(f"{label:>14} | " + " | ".join(f"{run[k]:>12.2f}" for k in keys))
        verdict = "met" if runs[1]["total"] < 5.0 else "NOT met"
        print(f"goal first step < 5 s (warm cache, import → first step): {runs[1]['total']:.2f} s — {verdict}")


if __name__ == "__main__":
    main()
