"""Rigid–MPM coupling beside Genesis: the same particles meeting the same rigid shapes.

Not a timing. Three scenes, float64, each run in both engines:

- ``static``: an elastic block (10 cm, Genesis's regular sampler, E 3e4 Pa, 32 cells/m, dt 2 ms in
  4 substeps) thrown at (1.5, 0, −1) m/s onto a tilted plane (coup_friction 0.3, coup_softness 4 mm,
  coup_restitution 0.1) towards a fixed sphere (coup_friction 0.5, Genesis's other defaults), 100
  steps; the largest distance between the two engines' particles every 10 steps. Both engines take
  the plane's and the sphere's signed distance analytically (Genesis samples other shapes' from SDF
  grids), so the particles should agree to round-off amplified by the rollout.
- ``box``: a free rigid box (8 × 6 × 5 cm, ρ 400, coup_friction 0.3) thrown spinning (v (0.3, 0,
  −0.5) m/s, ω (1, 2, 8) rad/s) onto an elastic block (20 × 20 × 10 cm, E 3e4) resting on a coupled
  plane (coup_friction 0.5), 200 steps: both ways (solvers/coupler.py).
- ``pendulum``: a hinged rod with a sphere at its end (assets/mjcf/pendulum_bob.xml), released at
  1.2 rad, swings into the same block and is stopped by it, 400 steps.
- ``tumbler``: a free hub with a hinged arm ending in a ball (assets/mjcf/tumbler.xml), thrown down
  with the arm turning at 3 rad/s, lands on the block, 150 steps (shapes on a floating root and on
  the link below it).

For the moving scenes the table gives the largest differences of the rigid body's pose (COLUMNS)
and of the block's centre (m). The engines take the same coupling rule timed otherwise: Genesis
couples the grid with the rigid poses after the rigid substep and applies the force in the next
one; ours, with the poses at the substep's start, in the same substep (solvers/coupler.py).

Measured (2026-12-01, Genesis 1.4.5): static 4.4e-13 to 5.5e-13 m after 10 steps, 3.6e-9 to
3.9e-9 m after 100 (three runs); box: position 1.6e-3 m, quaternion 2.9e-2, block centre 2.6e-5 m
over 200 steps (its tumbling contact amplifies the half substep apart: 9.6e-4 m, 1.8e-2 over the
first 100); pendulum: 7.6e-5 rad, 9.1e-4 rad/s, block centre 8.1e-6 m over 400 steps (it meets the
block at step ~260 and swings back); tumbler: hub 9.8e-4 m and 1.2e-2 rad, elbow 4.1e-5 rad, block
centre 2.9e-5 m over 150 steps (it lands at step ~75).

``--save PATH`` writes Genesis's particle positions at steps 50 and 100 of ``static`` (JSON), the
reference of tests/test_mpm_coupling.py (tests/data/genesis_coupling.json); ``--save-moving PATH``
its trajectories of the moving scenes, that of tests/test_mpm_coupler.py
(tests/data/genesis_coupling_moving.json).

Run:  GENESIS_PYTHON=/work/peers/genesis/bin/python python bench/coupling.py [--save PATH] [--save-moving PATH]
"""
import argparse
import json
import os
import sys
import tempfile

import numpy as np

from mpm import genesis_python, init_engine, run_json

SNAPSHOT_EVERY = 10
STEPS = {"static": 100, "box": 200, "pendulum": 400, "tumbler": 150}
MJCF = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "assets", "mjcf")


def scene_of(gs, case):
    """(scene, block, rigid body or None) of the module's scene ``case``, built with n_envs = 0."""
    static = case == "static"
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=2e-3, substeps=4, gravity=(0.0, 0.0, -9.81)),
                     mpm_options=gs.options.MPMOptions(lower_bound=(-0.5, -0.5, -0.2), upper_bound=(0.5, 0.5, 0.6),
                                                       grid_density=32),
                     show_viewer=False)
    if static:
        scene.add_entity(gs.morphs.Plane(pos=(0.0, 0.0, 0.05), normal=(0.2, 0.1, 1.0)),
                         material=gs.materials.Rigid(coup_friction=0.3, coup_softness=0.004, coup_restitution=0.1))
        scene.add_entity(gs.morphs.Sphere(pos=(0.15, 0.0, 0.1), radius=0.06, fixed=True),
                         material=gs.materials.Rigid(coup_friction=0.5))
    else:
        scene.add_entity(gs.morphs.Plane(), material=gs.materials.Rigid(coup_friction=0.5))
    block = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.2 if static else 0.06),
                                           size=(0.1, 0.1, 0.1) if static else (0.2, 0.2, 0.1)),
                             material=gs.materials.MPM.Elastic(E=3e4, sampler="regular"))
    body = None
    if case == "box":
        body = scene.add_entity(gs.morphs.Box(pos=(0.02, 0.0, 0.25), size=(0.08, 0.06, 0.05)),
                                material=gs.materials.Rigid(rho=400, coup_friction=0.3))
    elif case == "pendulum":
        body = scene.add_entity(gs.morphs.MJCF(file=os.path.join(MJCF, "pendulum_bob.xml")),
                                material=gs.materials.Rigid(coup_friction=0.2))
    elif case == "tumbler":
        body = scene.add_entity(gs.morphs.MJCF(file=os.path.join(MJCF, "tumbler.xml")),
                                material=gs.materials.Rigid(coup_friction=0.3))
    scene.build()
    return scene, block, body


def rollout(case, scene, block, body):
    """Run ``case``'s scene (scene_of's) from its start; returns its record: the block's particles
    every SNAPSHOT_EVERY steps (static), else per step the body's pose (box: position, quaternion;
    pendulum: angle, rate; tumbler: its 7 dofs' positions, get_dofs_position) and the block's centre."""
    import torch
    if case == "static":
        block.set_velocity(torch.tensor([1.5, 0.0, -1.0], dtype=torch.float64).repeat(block.n_particles, 1))
    elif case == "box":
        body.set_dofs_velocity(torch.tensor([0.3, 0.0, -0.5, 1.0, 2.0, 8.0], dtype=torch.float64))
    elif case == "pendulum":
        body.set_dofs_position(torch.tensor([1.2], dtype=torch.float64))
    else:
        body.set_dofs_velocity(torch.tensor([0.2, 0.0, -0.5, 0.0, 1.0, 0.0, 3.0], dtype=torch.float64))
    record = []
    for k in range(1, STEPS[case] + 1):
        scene.step()
        if case == "static":
            if k % SNAPSHOT_EVERY == 0:
                record.append(block.get_particles_pos().detach().cpu().numpy().reshape(-1, 3).tolist())
            continue
        pose = ([body.get_pos(), body.get_quat()] if case == "box" else
                [body.get_dofs_position()] + ([body.get_dofs_velocity()] if case == "pendulum" else []))
        record.append([float(v) for t in pose for v in t.detach().cpu().numpy().ravel()] +
                      block.get_particles_pos().detach().cpu().numpy().reshape(-1, 3).mean(axis=0).tolist())
    return record


def worker(engine, case, out):
    """Run ``case`` in ``engine``; write its record (rollout's, JSON)."""
    gs, version = init_engine(engine, "64")
    with open(out, "w") as file:
        json.dump({"version": version, "record": rollout(case, *scene_of(gs, case))}, file)


def _print_static(ours, genesis):
    print(f"static: elastic block on a tilted plane and a fixed sphere, {STEPS['static']} steps")
    print(f"{'step':>5} | {'largest distance, m':>20}")
    for k in range(STEPS["static"] // SNAPSHOT_EVERY):
        gap = np.linalg.norm(ours[k] - genesis[k], axis=1).max() if ours is not None and genesis is not None else None
        print(f"{(k + 1) * SNAPSHOT_EVERY:5d} | {'-' if gap is None else f'{gap:.2e}':>20}")
    for engine, snapshots in (("ours", ours), ("genesis", genesis)):
        if snapshots is not None and len(snapshots):
            print(f"{engine}: the block's centre at the end {np.round(snapshots[-1].mean(axis=0), 6).tolist()}")


# per moving case: (name, first column, end column) of its record's column groups (rollout)
COLUMNS = {"box": (("position m", 0, 3), ("quaternion", 3, 7), ("block centre m", 7, 10)),
           "pendulum": (("angle rad", 0, 1), ("rate rad/s", 1, 2), ("block centre m", 2, 5)),
           "tumbler": (("hub position m", 0, 3), ("hub turn rad", 3, 6), ("elbow rad", 6, 7),
                       ("block centre m", 7, 10))}


def _print_moving(case, ours, genesis):
    print(f"{case}: largest differences over {STEPS[case]} steps (and over the first half)")
    if ours is None or genesis is None:
        print("  - (needs both engines)")
        return
    for name, first, end in COLUMNS[case]:
        gap = np.abs(ours[:, first:end] - genesis[:, first:end])
        print(f"  {name:>16}: {gap.max():.2e} ({gap[: len(gap) // 2].max():.2e})")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", choices=["ours", "genesis"])
    parser.add_argument("--cases", nargs="+", choices=list(STEPS), default=list(STEPS))
    parser.add_argument("--steps", type=int, help="at most this many steps a scene (a quick run)")
    parser.add_argument("--save", help="write Genesis's positions at steps 50 and 100 of 'static' to this JSON file")
    parser.add_argument("--save-moving", help="write Genesis's records of the moving scenes to this JSON file")
    parser.add_argument("--worker", nargs=3, metavar=("ENGINE", "CASE", "OUT"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.steps is not None:
        STEPS.update({case: min(steps, args.steps) for case, steps in STEPS.items()})
    if args.worker:
        return worker(*args.worker)
    pythons = {"ours": sys.executable, "genesis": genesis_python()}
    engines = [e for e in ("ours", "genesis") if args.only in (None, e) and pythons[e] is not None]
    print(f"Genesis: {pythons['genesis'] or 'not installed (set GENESIS_PYTHON)'}")
    records = {}
    with tempfile.TemporaryDirectory() as tmp:
        for case in args.cases:
            for engine in engines:
                out = os.path.join(tmp, f"{engine}_{case}.json")
                result = run_json([pythons[engine], os.path.abspath(__file__), "--worker", engine, case, out,
                                   *(["--steps", str(args.steps)] if args.steps is not None else [])], out)
                if "error" in result:
                    print(f"{engine}, {case}: {result['error']}")
                    return
                records[engine, case] = result
    record = {key: np.array(value["record"]) for key, value in records.items()}
    for case in args.cases:
        show = _print_static if case == "static" else lambda *pair, case=case: _print_moving(case, *pair)
        show(record.get(("ours", case)), record.get(("genesis", case)))
    if args.save:
        if ("genesis", "static") not in record or len(record["genesis", "static"]) < 10:
            print("--save needs Genesis and the static case's 100 steps")
        else:
            with open(args.save, "w") as file:
                json.dump({"genesis": records["genesis", "static"]["version"], "steps": [50, 100],
                           "positions": [record["genesis", "static"][4].tolist(),
                                         record["genesis", "static"][9].tolist()]}, file)
    if args.save_moving:
        moving = [case for case in COLUMNS if ("genesis", case) in record]
        with open(args.save_moving, "w") as file:
            json.dump({"genesis": records["genesis", moving[0]]["version"],
                       **{case: record["genesis", case].tolist() for case in moving}}, file)


if __name__ == "__main__":
    main()
