"""A Crazyflie flown by the same rotor speeds in both engines: agreement and speed beside Genesis.

Both engines load their own "urdf/drones/cf2x.urdf" (ours: genesis_lite's description of the same
figures: mass 0.027 kg, inertia, kf, km, rotor positions) as gs.morphs.Drone, start it at 1 m,
level, in the air (no ground: contact is not what this compares), and fly STEPS steps of
dt 0.01 s of one seeded schedule of speeds within ±8 % of hover (per env in a batch: the
schedule's rows shifted by the env's index). Printed per case: the largest difference of the
base's position (m) and quaternion from ours over the whole flight (env 0), and the forward
time per step (best of --repeats, after a warm-up flight), with env-steps/s; ours also with
gradients (requires_grad, a backward of the final position's loss into the speeds).

Run:  python bench/drone.py [--only ours|genesis] [--envs 0 1024] [--precision 64] [--repeats 3]
(engines are imported inside the worker: the same file runs in Genesis's interpreter,
$GENESIS_PYTHON or bench/README.md's virtualenv.)
"""
import argparse
import json
import os
import sys
import tempfile
import time

import numpy as np

from mpm import genesis_python, init_engine, run_json

DT, STEPS, G = 0.01, 200, 9.81


def schedule(n_envs, hover):
    """(STEPS, max(n_envs, 1), 4) rotor speeds, rpm: hover × (1 + 0.08 × a smooth random signal)."""
    rng = np.random.default_rng(0)
    knots = rng.uniform(-1.0, 1.0, size=(STEPS // 20 + 2, 4))
    t = np.arange(STEPS) / 20.0
    signal = np.stack([np.interp(t, np.arange(len(knots)), knots[:, k]) for k in range(4)], axis=1)
    rows = [np.roll(signal, 7 * e, axis=0) for e in range(max(n_envs, 1))]
    return hover * (1.0 + 0.08 * np.stack(rows, axis=1))


def fly(gs, drone, scene, rpm, n_envs):
    """One flight of the schedule; the base's (position, quaternion) of env 0 after each step."""
    import torch
    poses = []
    for step in range(STEPS):
        command = torch.as_tensor(rpm[step] if n_envs else rpm[step, 0], dtype=gs.tc_float, device=gs.device)
        drone.set_propellers_rpm(command)
        scene.step()
        poses.append(torch.cat([drone.get_pos().reshape(-1, 3)[0], drone.get_quat().reshape(-1, 4)[0]]))
    return torch.stack(poses)


def worker(engine, n_envs, precision, repeats, out):
    gs, version = init_engine(engine, precision)
    import torch

    def build(requires_grad):
        # Genesis's Euler integrator (ours, MuJoCo's): its default advances a lone free body by the
        # implicit midpoint rule, another integrator, whose first step from rest turns it half as far
        rigid = {} if engine == "ours" else {"rigid_options": gs.options.RigidOptions(integrator=gs.integrator.Euler)}
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT, requires_grad=requires_grad), show_viewer=False,
                         **rigid)
        drone = scene.add_entity(gs.morphs.Drone(file="urdf/drones/cf2x.urdf", pos=(0.0, 0.0, 1.0)))
        scene.build(n_envs=n_envs)
        return scene, drone

    scene, drone = build(False)
    rpm = schedule(n_envs, np.sqrt(float(drone.get_mass().reshape(-1)[0]) * G / (4.0 * drone.KF)))
    poses = fly(gs, drone, scene, rpm, n_envs).cpu().numpy()
    times = []
    for _ in range(repeats):
        scene.reset()
        start = time.perf_counter()
        fly(gs, drone, scene, rpm, n_envs)
        times.append((time.perf_counter() - start) / STEPS)
    result = {"version": version, "poses": poses.tolist(), "forward": times}
    if engine == "ours":
        scene, drone = build(True)
        grad_times = []
        for _ in range(repeats + 1):
            scene.reset()
            speeds = torch.as_tensor(rpm, dtype=gs.tc_float).requires_grad_(True)
            start = time.perf_counter()
            for step in range(STEPS):
                drone.set_propellers_rpm(speeds[step] if n_envs else speeds[step, 0])
                scene.step()
            (drone.get_pos() ** 2).sum().backward()
            grad_times.append((time.perf_counter() - start) / STEPS)
        result["grad"] = grad_times[1:]
    with open(out, "w") as file:
        json.dump(result, file)


def run_worker(python, engine, n_envs, args, tmp):
    out = os.path.join(tmp, f"{engine}-{n_envs}.json")
    command = [python, os.path.abspath(__file__), "--worker", engine, str(n_envs), out, "--precision", args.precision,
               "--repeats", str(args.repeats)]
    return run_json(command, out)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", choices=("ours", "genesis"))
    parser.add_argument("--envs", type=int, nargs="+", default=[0, 1024])
    parser.add_argument("--precision", choices=("32", "64"), default="64")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--worker", nargs=3, metavar=("ENGINE", "N_ENVS", "OUT"))
    args = parser.parse_args()
    if args.worker:
        engine, n_envs, out = args.worker
        return worker(engine, int(n_envs), args.precision, args.repeats, out)
    pythons = {"ours": sys.executable, "genesis": genesis_python()}
    engines = [e for e in ("ours", "genesis") if args.only in (None, e) and pythons[e]]
    print(f"| engine | envs | max Δpos m | max Δquat | forward ms/step (best of {args.repeats}) | env-steps/s | "
          f"fwd+bwd ms/step |")
    print("|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for n_envs in args.envs:
            results = {engine: run_worker(pythons[engine], engine, n_envs, args, tmp) for engine in engines}
            ours = np.array(results["ours"]["poses"]) if "poses" in results.get("ours", {}) else None
            for engine, result in results.items():
                if "error" in result:
                    print(f"| {engine} | {n_envs} | {result['error']} |")
                    continue
                poses = np.array(result["poses"])
                dpos = dquat = float("nan")
                if ours is not None:
                    dpos, dquat = np.abs(poses[:, :3] - ours[:, :3]).max(), np.abs(poses[:, 3:] - ours[:, 3:]).max()
                best = min(result["forward"])
                grad = f"{1e3 * min(result['grad']):.3f}" if "grad" in result else "–"
                print(f"| {engine} {result['version']} | {n_envs} | {dpos:.1e} | {dquat:.1e} | {1e3 * best:.3f} | "
                      f"{max(n_envs, 1) / best:.3g} | {grad} |")


if __name__ == "__main__":
    main()
