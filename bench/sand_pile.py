"""A sand column's collapse beside Genesis: the flank slope of the pile it leaves, per friction angle.

Issue 12 asks a sand column to settle to a slope within ±7° of its friction angle. This runs the
same column in both engines, so that what the slope owes to Genesis's sand model (Drucker–Prager
with Klár et al.'s volume correction, which we follow) is told apart from what it owes to our code:

- a cylinder (radius 15 cm, height 15 cm, aspect 1) of ``Sand(friction_angle=φ)`` (E 1e6, ν 0.2,
  ρ 1000, random sampler) released at rest 1 mm above a rough floor, float64, 32 cells/m
  (particle size 2 cm), dt 2 ms in 4 substeps (Genesis's bound 2e-2·dx), g 9.81 m/s², for 1 s;
- the floor: a rigid plane coupled to the particles in both engines (the legacy coupler's rule:
  Coulomb friction ``coup_friction`` on the particles' velocity towards the plane), run at two
  frictions, 5 and 100 (rough and rougher); ours also on a sticky floor wall (Genesis has slip
  walls only);
- the slope: ``pile_slope`` (also tests/test_mpm_physics.py's measure).

Measured (2026-11-28 and 12-01, Genesis 1.4.5, three runs; its random sampler draws other
particles in each run, ours the same): φ 30°: ours 21.3° (sticky wall; on the plane 21.3° at both
frictions), Genesis 20.3–22.2°; φ 45°: ours 28.5° (on the plane 26.0°), Genesis 26.8–29.6°
(friction 5: 26.8°, 26.9°, 29.2°; 100: 29.6°, 28.1°, 28.8°). The piles' profiles agree within a
few mm, and both engines' slopes lie below φ − 7° at 45° (and at 30°, by ~1°).

Run:  python bench/sand_pile.py [--only ours|genesis] [--angles 30 45] [--steps 500]
(engines are imported inside the worker: the same file runs in Genesis's interpreter.)
"""
import argparse
import json
import math
import os
import sys
import tempfile

import numpy as np

from mpm import genesis_python, init_engine, run_json

DENSITY, DT, SUBSTEPS, G = 32, 2e-3, 4, 9.81
RADIUS = HEIGHT = 0.15                       # m: the column
LOWER, UPPER = (-0.5, -0.5, 0.0), (0.5, 0.5, 0.4)
PLANE_FRICTIONS = (5.0, 100.0)               # the plane's coup_friction in the runs on a plane


def pile_slope(points, floor, dx):
    """(slope in degrees, radii, heights) of an axisymmetric pile of particles ``points`` (n, 3) m
    on the floor at height ``floor`` (m): the free surface's height per radial bin of width dx (the
    90th percentile of the particle heights in the bin, ≥ 3 particles) fitted by a line over the
    flank, the bins whose height lies between 20 % and 80 % of the top; the slope is NaN when fewer
    than two bins lie on the flank (a column that has not collapsed)."""
    r = np.hypot(points[:, 0] - points[:, 0].mean(), points[:, 1] - points[:, 1].mean())
    z = points[:, 2] - floor
    radii, heights = [], []
    for lo in np.arange(0.0, r.max() + dx, dx):
        inside = (r >= lo) & (r < lo + dx)
        if inside.sum() >= 3:
            radii.append(lo + dx / 2)
            heights.append(np.quantile(z[inside], 0.9))
    radii, heights = np.array(radii), np.array(heights)
    flank = (heights > 0.2 * heights.max()) & (heights < 0.8 * heights.max())
    if flank.sum() < 2:
        return math.nan, radii, heights
    slope = np.polyfit(radii[flank], heights[flank], 1)[0]
    return math.degrees(math.atan(-slope)), radii, heights


def column(gs, friction_angle, friction=None):
    """(scene, sand entity, floor height m) of the column in engine ``gs``: with friction None
    (ours only), on sticky walls, the floor wall 3 cells above the lower bound; else on a plane at
    z = 0 with coup_friction ``friction``, the walls below; built with n_envs = 0."""
    sim = gs.options.SimOptions(dt=DT, substeps=SUBSTEPS, gravity=(0.0, 0.0, -G))
    if friction is None:
        floor, lower = LOWER[2] + 3.0 / DENSITY, LOWER
        mpm = gs.options.MPMOptions(lower_bound=lower, upper_bound=UPPER, grid_density=DENSITY,
                                    boundary_condition="sticky")
    else:
        floor, lower = 0.0, (LOWER[0], LOWER[1], -0.1)
        mpm = gs.options.MPMOptions(lower_bound=lower, upper_bound=UPPER, grid_density=DENSITY)
    scene = gs.Scene(sim_options=sim, mpm_options=mpm, show_viewer=False)
    if friction is not None:
        scene.add_entity(gs.morphs.Plane(), material=gs.materials.Rigid(coup_friction=friction))
    sand = scene.add_entity(gs.morphs.Cylinder(pos=(0.0, 0.0, floor + HEIGHT / 2 + 0.001), radius=RADIUS,
                                               height=HEIGHT),
                            material=gs.materials.MPM.Sand(friction_angle=friction_angle))
    scene.build()
    return scene, sand, floor


def collapse(scene, sand, floor, steps):
    """Run ``steps`` steps; (slope°, radii, heights) of the pile (see pile_slope)."""
    for _ in range(steps):
        scene.step()
    points = sand.get_particles_pos().detach().cpu().numpy().astype(np.float64).reshape(-1, 3)
    return pile_slope(points, floor, 1.0 / DENSITY)


def worker(engine, friction_angle, friction, steps, out):
    gs, version = init_engine(engine, "64")
    scene, sand, floor = column(gs, friction_angle, friction)
    slope, radii, heights = collapse(scene, sand, floor, steps)
    with open(out, "w") as file:
        json.dump({"version": version, "n": sand.n_particles, "slope": slope, "radii": radii.tolist(),
                   "heights": heights.tolist()}, file)


def run_worker(python, engine, friction_angle, friction, steps, tmp):
    out = os.path.join(tmp, f"{engine}-{friction_angle}-{friction}.json")
    command = [python, os.path.abspath(__file__), "--steps", str(steps),
               "--worker", engine, str(friction_angle), str(friction), out]
    return run_json(command, out)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", choices=["ours", "genesis"])
    parser.add_argument("--angles", nargs="+", type=float, default=[30.0, 45.0], help="friction angles, degrees")
    parser.add_argument("--steps", type=int, default=500, help="steps of 2 ms")
    parser.add_argument("--frictions", nargs="*", type=float, default=list(PLANE_FRICTIONS),
                        help="the plane's coup_friction in the runs on a plane (both engines)")
    parser.add_argument("--worker", nargs=4, metavar=("ENGINE", "ANGLE", "FRICTION", "OUT"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        engine, angle, friction, out = args.worker
        return worker(engine, float(angle), None if friction == "None" else float(friction), args.steps, out)

    pythons = {"ours": sys.executable, "genesis": genesis_python()}
    runs = [("ours", f) for f in (None, *args.frictions)] * (args.only != "genesis") + [
        ("genesis", f) for f in args.frictions] * (args.only != "ours" and pythons["genesis"] is not None)
    print(f"sand column r {RADIUS} m, h {HEIGHT} m, {DENSITY} cells/m, float64, {args.steps} steps of {DT} s; "
          f"Genesis: {pythons['genesis'] or 'not installed (set GENESIS_PYTHON)'}", flush=True)
    print(f"{'φ °':>5} | {'engine':>8} | {'floor':>24} | {'N':>5} | {'slope °':>7} | {'φ − slope':>9} | heights (cm) per 3.1 cm of radius")
    with tempfile.TemporaryDirectory() as tmp:
        for angle in args.angles:
            for engine, friction in runs:
                r = run_worker(pythons[engine], engine, angle, friction, args.steps, tmp)
                floor = "sticky wall" if friction is None else f"plane, coup_friction {friction:g}"
                if "error" in r:
                    print(f"{angle:5.0f} | {engine:>8} | {floor:>24} | {r['error']}")
                    continue
                heights = " ".join(f"{100 * h:.1f}" for h in r["heights"])
                print(f"{angle:5.0f} | {engine:>8} | {floor:>24} | {r['n']:5d} | {r['slope']:7.1f} | "
                      f"{angle - r['slope']:9.1f} | {heights}", flush=True)


if __name__ == "__main__":
    main()
