"""Rigid–MPM coupling beside Genesis: the same particles meeting the same rigid shapes at rest.

Not a timing. An elastic block (10 cm, Genesis's regular sampler, E 3e4 Pa, 32 cells/m, float64,
dt 2 ms in 4 substeps) thrown at (1.5, 0, −1) m/s onto a tilted plane (coup_friction 0.3,
coup_softness 4 mm, coup_restitution 0.1) towards a fixed sphere (coup_friction 0.5, Genesis's
other defaults) runs 100 steps in both engines; the table gives the largest distance between the
two engines' particles every 10 steps, and the block's centre at the end. Both engines take the
plane's and the sphere's signed distance analytically (Genesis samples other shapes' from SDF
grids), so the particles should agree to round-off amplified by the rollout.

Measured (2026-12-01, Genesis 1.4.5, two runs): 4.4e-13 and 5.5e-13 m after 10 steps, 3.6e-9 and
3.9e-9 m after 100.

``--save PATH`` writes Genesis's particle positions at steps 50 and 100 (JSON), the reference of
tests/test_mpm_coupling.py (tests/data/genesis_coupling.json).

Run:  GENESIS_PYTHON=/work/peers/genesis/bin/python python bench/coupling.py [--steps 100] [--save PATH]
"""
import argparse
import json
import os
import sys
import tempfile

import numpy as np

from mpm import genesis_python, init_engine, run_json

SNAPSHOT_EVERY = 10


def scene_of(gs):
    """(scene, block) of the module's docstring, built with n_envs = 0."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=2e-3, substeps=4, gravity=(0.0, 0.0, -9.81)),
                     mpm_options=gs.options.MPMOptions(lower_bound=(-0.5, -0.5, -0.2), upper_bound=(0.5, 0.5, 0.6),
                                                       grid_density=32),
                     show_viewer=False)
    scene.add_entity(gs.morphs.Plane(pos=(0.0, 0.0, 0.05), normal=(0.2, 0.1, 1.0)),
                     material=gs.materials.Rigid(coup_friction=0.3, coup_softness=0.004, coup_restitution=0.1))
    scene.add_entity(gs.morphs.Sphere(pos=(0.15, 0.0, 0.1), radius=0.06, fixed=True),
                     material=gs.materials.Rigid(coup_friction=0.5))
    block = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.2), size=(0.1, 0.1, 0.1)),
                             material=gs.materials.MPM.Elastic(E=3e4, sampler="regular"))
    scene.build()
    return scene, block


def worker(engine, steps, out):
    gs, version = init_engine(engine, "64")
    import torch
    scene, block = scene_of(gs)
    block.set_velocity(torch.tensor([1.5, 0.0, -1.0], dtype=torch.float64).repeat(block.n_particles, 1))
    snapshots = []
    for k in range(1, steps + 1):
        scene.step()
        if k % SNAPSHOT_EVERY == 0:
            snapshots.append(block.get_particles_pos().detach().cpu().numpy().reshape(-1, 3).tolist())
    with open(out, "w") as file:
        json.dump({"version": version, "snapshots": snapshots}, file)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", choices=["ours", "genesis"])
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--save", help="write Genesis's positions at steps 50 and 100 to this JSON file")
    parser.add_argument("--worker", nargs=2, metavar=("ENGINE", "OUT"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        return worker(args.worker[0], args.steps, args.worker[1])
    pythons = {"ours": sys.executable, "genesis": genesis_python()}
    engines = [e for e in ("ours", "genesis") if args.only in (None, e) and pythons[e] is not None]
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for engine in engines:
            out = os.path.join(tmp, f"{engine}.json")
            results[engine] = run_json([pythons[engine], os.path.abspath(__file__), "--steps", str(args.steps),
                                        "--worker", engine, out], out)
            if "error" in results[engine]:
                print(f"{engine}: {results[engine]['error']}")
                return
    print(f"elastic block on a tilted plane and a fixed sphere, float64, {args.steps} steps; Genesis: "
          f"{pythons['genesis'] or 'not installed (set GENESIS_PYTHON)'}")
    ours = np.array(results["ours"]["snapshots"]) if "ours" in results else None
    genesis = np.array(results["genesis"]["snapshots"]) if "genesis" in results else None
    print(f"{'step':>5} | {'largest distance, m':>20}")
    for k in range(args.steps // SNAPSHOT_EVERY):
        gap = np.linalg.norm(ours[k] - genesis[k], axis=1).max() if ours is not None and genesis is not None else None
        print(f"{(k + 1) * SNAPSHOT_EVERY:5d} | {'-' if gap is None else f'{gap:.2e}':>20}")
    for engine, snapshots in (("ours", ours), ("genesis", genesis)):
        if snapshots is not None and len(snapshots):
            print(f"{engine}: the block's centre at the end {np.round(snapshots[-1].mean(axis=0), 6).tolist()}")
    if args.save:
        if genesis is None or args.steps < 100:
            print("--save needs Genesis and at least 100 steps")
            return
        with open(args.save, "w") as file:
            json.dump({"genesis": results["genesis"]["version"], "steps": [50, 100],
                       "positions": [genesis[4].tolist(), genesis[9].tolist()]}, file)


if __name__ == "__main__":
    main()
