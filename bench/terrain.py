"""Balls on generated terrain beside Genesis: the terrains' heights and the step's speed.

Both engines build gs.morphs.Terrain of 2 × 2 subterrains of 6 m (horizontal_scale 0.25 m,
vertical_scale 5 mm; Genesis's terrain_subterrain example) of one kind, or the example's four
kinds ("mixed"), and a sphere of 0.1 m radius per env dropped from 1 m over a 10 × 10 grid of
points 1 m apart (shifted 0.1 m off the grid's vertices), float32, dt 0.01 s. Printed per case:
the largest difference of the terrain's heights from ours (vertical_scale units: the kinds
without chance are Genesis's; the random kinds are drawn by other rules, genesis_lite/utils/
terrain.py, so they differ), and the time per step (best of --repeats × 100 steps, after 100
steps to land).

Run:  python bench/terrain.py [--only ours|genesis] [--kinds mixed sloped_terrain …] [--envs 100]
      [--repeats 3]   (Genesis in its own interpreter: $GENESIS_PYTHON or bench/README.md's
      virtualenv)
"""
import argparse
import json
import os
import sys
import tempfile
import time

import numpy as np

from mpm import genesis_python, init_engine, run_json

MIXED = [["flat_terrain", "random_uniform_terrain"], ["pyramid_sloped_terrain", "discrete_obstacles_terrain"]]
HS, VS, STEPS = 0.25, 0.005, 100


def worker(engine, kind, n_envs, repeats, out):
    gs, version = init_engine(engine, "32")
    import torch

    rigid = gs.options.RigidOptions(dt=0.01, constraint_solver=gs.constraint_solver.Newton)
    scene = gs.Scene(rigid_options=rigid, show_viewer=False) if engine == "genesis" else gs.Scene(rigid_options=rigid)
    kinds = MIXED if kind == "mixed" else kind
    terrain = scene.add_entity(gs.morphs.Terrain(n_subterrains=(2, 2), subterrain_size=(6.0, 6.0), horizontal_scale=HS,
                                                 vertical_scale=VS, subterrain_types=kinds))
    ball = scene.add_entity(gs.morphs.Sphere(pos=(1.0, 1.0, 1.0), radius=0.1))
    scene.build(n_envs=n_envs)
    side = int(np.ceil(np.sqrt(n_envs)))
    grid = torch.cartesian_prod(*(torch.arange(1, side + 1),) * 2, torch.tensor((1,)))[:n_envs]
    ball.set_pos(grid.to(gs.tc_float) + torch.tensor([0.1, 0.1, 0.0], dtype=gs.tc_float))
    for _ in range(STEPS):
        scene.step()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(STEPS):
            scene.step()
        times.append((time.perf_counter() - start) / STEPS)
    heights = terrain.morph.height_field if engine == "ours" else terrain.geoms[0].metadata["height_field"]
    np.save(out + ".npy", np.asarray(heights, dtype=np.float64))
    with open(out, "w") as file:
        json.dump({"version": version, "forward": times}, file)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", choices=("ours", "genesis"))
    parser.add_argument("--kinds", nargs="+", default=["mixed", "sloped_terrain", "pyramid_stairs_terrain"])
    parser.add_argument("--envs", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--worker", nargs=3, metavar=("ENGINE", "KIND", "OUT"))
    args = parser.parse_args()
    if args.worker:
        engine, kind, out = args.worker
        return worker(engine, kind, args.envs, args.repeats, out)
    pythons = {"ours": sys.executable, "genesis": genesis_python()}
    engines = [e for e in ("ours", "genesis") if args.only in (None, e) and pythons[e]]
    print(f"| terrain | engine | max Δheight (units) | ms/step, {args.envs} envs (best of {args.repeats}) | env-steps/s |")
    print("|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for kind in args.kinds:
            results = {}
            for engine in engines:
                out = os.path.join(tmp, f"{engine}-{kind}.json")
                command = [pythons[engine], os.path.abspath(__file__), "--worker", engine, kind, out,
                           "--envs", str(args.envs), "--repeats", str(args.repeats)]
                results[engine] = run_json(command, out)
                if "error" not in results[engine]:
                    results[engine]["heights"] = np.load(out + ".npy")
            ours = results.get("ours", {}).get("heights")
            for engine, result in results.items():
                if "error" in result:
                    print(f"| {kind} | {engine} | {result['error']} |")
                    continue
                apart = float("nan") if ours is None or ours.shape != result["heights"].shape else \
                    np.abs(result["heights"] - ours).max()
                best = min(result["forward"])
                print(f"| {kind} | {engine} {result['version']} | {apart:.2g} | {1e3 * best:.3f} | "
                      f"{args.envs / best:.3g} |")


if __name__ == "__main__":
    main()
