"""Inverse kinematics beside Genesis: time per call, and how many envs each engine solves.

Both engines load pybullet_data's ``franka_panda/panda.urdf`` (fixed base; the path is passed
to Genesis's interpreter), float32, and solve ``inverse_kinematics`` for the hand link
("panda_hand") with Genesis's defaults (50 samples, 20 iterations, damping 0.01, tolerances
5e-4 m and 5e-3 rad, limits respected) from the zero pose, in three cases per batch size:
- ``reachable``: each env's pose of the hand at its own random arm pose (uniform within the
  limits, one seeded draw shared by both engines, the pose from each engine's own kinematics);
- ``position``: the same positions only;
- ``far``: a point 3 m away that no sample reaches (every sample's every iteration runs).
Printed: ms per call (best of ``--repeats`` after one untimed call, which loads the kernels) and
the envs within both tolerances.

Run:  python bench/ik.py [--only ours|genesis] [--envs 0 64 1024] [--repeats 5]
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

CASES = ("reachable", "position", "far")


def worker(engine, urdf, n_envs, repeats, out):
    gs, version = init_engine(engine, "32")
    import torch

    scene = gs.Scene(show_viewer=False)
    robot = scene.add_entity(gs.morphs.URDF(file=urdf, fixed=True, links_to_keep=["panda_hand"]))
    scene.build(n_envs=n_envs)
    hand = robot.get_link("panda_hand")
    rows, arm = max(n_envs, 1), 7
    lower, upper = (torch.as_tensor(limit).reshape(-1, robot.n_dofs)[0, :arm] for limit in robot.get_dofs_limit())
    draw = torch.tensor(np.random.default_rng(0).uniform(0.0, 1.0, (rows, arm)), dtype=torch.float32)
    poses = torch.zeros(rows, robot.n_dofs)
    poses[:, :arm] = lower + draw * (upper - lower)
    robot.set_qpos(poses if n_envs else poses[0])
    pos, quat = hand.get_pos().clone(), hand.get_quat().clone()
    robot.set_qpos(torch.zeros_like(poses) if n_envs else torch.zeros(robot.n_dofs))
    goals = {"reachable": {"pos": pos, "quat": quat}, "position": {"pos": pos},
             "far": {"pos": pos + torch.tensor([3.0, 0.0, 0.0])}}
    result = {"version": version}
    for case, goal in goals.items():
        times = []
        for _ in range(repeats + 1):
            start = time.perf_counter()
            _, error = robot.inverse_kinematics(link=hand, return_error=True, **goal)
            times.append(time.perf_counter() - start)
        error = torch.as_tensor(error).reshape(rows, 6)
        solved = (error[:, :3].norm(dim=1) <= 5e-4) & (error[:, 3:].norm(dim=1) <= 5e-3)
        result[case] = {"ms": 1e3 * min(times[1:]), "solved": int(solved.sum()), "rows": rows}
    with open(out, "w") as file:
        json.dump(result, file)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", choices=("ours", "genesis"))
    parser.add_argument("--envs", type=int, nargs="+", default=[0, 64, 1024])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--worker", nargs=4, metavar=("ENGINE", "URDF", "N_ENVS", "OUT"))
    args = parser.parse_args()
    if args.worker:
        engine, urdf, n_envs, out = args.worker
        return worker(engine, urdf, int(n_envs), args.repeats, out)
    import pybullet_data
    urdf = os.path.join(pybullet_data.getDataPath(), "franka_panda", "panda.urdf")
    pythons = {"ours": sys.executable, "genesis": genesis_python()}
    engines = [e for e in ("ours", "genesis") if args.only in (None, e) and pythons[e]]
    print("| engine | envs | " + " | ".join(f"{case} ms (solved)" for case in CASES) + " |")
    print("|---|---|" + "---|" * len(CASES))
    with tempfile.TemporaryDirectory() as tmp:
        for n_envs in args.envs:
            for engine in engines:
                out = os.path.join(tmp, f"{engine}-{n_envs}.json")
                result = run_json([pythons[engine], os.path.abspath(__file__), "--worker", engine, urdf, str(n_envs),
                                   out, "--repeats", str(args.repeats)], out)
                if "error" in result:
                    print(f"| {engine} | {n_envs} | {result['error']} |")
                    continue
                cells = [f"{result[c]['ms']:.2f} ({result[c]['solved']}/{result[c]['rows']})" for c in CASES]
                print(f"| {engine} {result['version']} | {n_envs} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
