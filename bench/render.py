"""Camera rendering: milliseconds per 640×480 frame, and what recording a video adds to a rollout.

Frames (float32, CPU, contact-free scenes, camera 640×480, fov 40°, 3 m from the scene):

- "box on plane": a 0.4 m box on the ground plane, rgb only, then rgb + depth + segmentation +
  normal;
- "KUKA + 10k spheres + plane": the KUKA iiwa (pybullet_data ``kuka_iiwa/model.urdf``, its 8
  visual meshes, 14.8k triangles) on the plane with 10 000 debug spheres (radius 1 cm, uniform in
  a 1 m cube behind the arm) seen by a debug camera, rgb.

Each is timed after a warm-up render (kernels compiled, triangles built): ``--frames`` renders of
the same state per run, ``--repeats`` runs; the table gives the best and the slowest run's ms per
frame. Goal: KUKA + 10k spheres + plane < 50 ms.

Recording: a KUKA rollout of ``--record-frames`` steps (dt 0.01 s, the arm falling from random
joint positions and velocities, plane, no spheres) rendering a 640×480 rgb frame after every step:
its wall time alone, then with the frames recorded, either kept in memory and written by
``stop_recording("….mp4", fps=60)`` (the issue's form) or streamed to ffmpeg as they come
(Genesis 1.4.5's ``start_recording("….mp4", fps=100)``, whose steps take the frames: a frame a
step at dt 0.01 s, the rollout then calling no ``render()``); both times include writing the file.
``--repeats`` rollouts of each, interleaved. On a machine shared with other work a whole rollout's
wall time swings by 2× from run to run, so the overhead is taken from an estimate that such spells
barely move: the number of steps × the median wall time of a step + render (+ append) over all
rollouts of the mode, plus the median time of starting and finishing the file (for the buffered
form: encoding every frame). The table also gives each mode's best and slowest rollout wall time
and its best CPU time (user + system, of the process's threads and of ffmpeg). Goal: overhead of
the estimate < 20 %.

Run:  python bench/render.py [--repeats 5] [--frames 20] [--record-frames 300]
"""
import argparse
import os
import resource
import sys
import tempfile
import time

import numpy as np
import pybullet_data

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import genesis_lite as gs  # noqa: E402

KUKA = os.path.join(pybullet_data.getDataPath(), "kuka_iiwa", "model.urdf")
RES = (640, 480)
CAMERA = dict(res=RES, pos=(2.2, 1.6, 1.5), lookat=(0.0, 0.0, 0.5), fov=40)
NO_CONTACT = gs.options.RigidOptions(enable_collision=False)


def cpu_seconds():
    """User + system CPU seconds so far of this process (all its threads) and of its finished
    children (ffmpeg)."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def runs(work, repeats):
    """(best, slowest) wall seconds of ``repeats`` calls of work()."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        work()
        times.append(time.perf_counter() - t0)
    return min(times), max(times)


def frame_times(camera, frames, repeats, **flags):
    """(best, slowest) ms per frame over ``repeats`` runs of ``frames`` renders."""
    camera.render(**flags)  # warm-up: kernels, triangles

    def work():
        for _ in range(frames):
            camera.render(**flags)
    best, slowest = runs(work, repeats)
    return best / frames * 1e3, slowest / frames * 1e3


def box_scene():
    scene = gs.Scene(rigid_options=NO_CONTACT)
    scene.add_entity(gs.morphs.Plane())
    scene.add_entity(gs.morphs.Box(size=(0.4, 0.4, 0.4), pos=(0.0, 0.0, 0.2), fixed=True),
                     surface=gs.surfaces.Default(color=(0.8, 0.2, 0.2)))
    camera = scene.add_camera(**{**CAMERA, "lookat": (0.0, 0.0, 0.2)})
    scene.build()
    return scene, camera


def kuka_scene(debug=False):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01), rigid_options=NO_CONTACT)
    scene.add_entity(gs.morphs.Plane())
    robot = scene.add_entity(gs.morphs.URDF(file=KUKA, fixed=True))
    camera = scene.add_camera(**CAMERA, debug=debug)
    scene.build()
    return scene, robot, camera


def rollout(scene, robot, camera, n_steps, mode, folder):
    """One rollout from the same start, rendering after every step; mode: None (no recording),
    "buffered" or "streamed". Returns (wall s, CPU s, wall s of each step + render (n_steps,),
    wall s of starting and finishing the file)."""
    rng = np.random.default_rng(0)
    scene.reset()
    robot.set_dofs_position(rng.uniform(-1.0, 1.0, robot.n_dofs))
    robot.set_dofs_velocity(rng.uniform(-1.0, 1.0, robot.n_dofs))
    path = os.path.join(folder, f"{mode}.mp4")
    t0, c0 = time.perf_counter(), cpu_seconds()
    if mode is not None:
        camera.start_recording(path if mode == "streamed" else None, 100 if mode == "streamed" else None)
    file_time = time.perf_counter() - t0
    steps = np.empty(n_steps)
    for k in range(n_steps):
        t_step = time.perf_counter()
        scene.step()  # (streamed: the step renders and records its frame)
        if mode != "streamed":
            camera.render()
        steps[k] = time.perf_counter() - t_step
    t_stop = time.perf_counter()
    if mode is not None:
        camera.stop_recording(*((path, 60) if mode == "buffered" else ()))
    file_time += time.perf_counter() - t_stop
    return time.perf_counter() - t0, cpu_seconds() - c0, steps, file_time


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--frames", type=int, default=20)
    parser.add_argument("--record-frames", type=int, default=300)
    args = parser.parse_args()
    print(f"camera rendering, {RES[0]}×{RES[1]}, float32, {os.cpu_count()} CPUs; best of {args.repeats} runs")
    gs.init(backend=gs.cpu, precision="32", logging_level="warning")

    rows = []
    scene, camera = box_scene()
    rows.append(("box on plane, rgb", *frame_times(camera, args.frames, args.repeats)))
    rows.append(("box on plane, rgb+depth+seg+normal",
                 *frame_times(camera, args.frames, args.repeats, depth=True, segmentation=True, normal=True)))
    scene.destroy()
    scene, robot, camera = kuka_scene(debug=True)
    rng = np.random.default_rng(1)
    scene.draw_debug_spheres(rng.uniform(0.0, 1.0, (10_000, 3)) - [1.2, 1.2, 0.0], radius=0.01,
                             color=(0.2, 0.5, 1.0))
    kuka = frame_times(camera, args.frames, args.repeats)
    rows.append(("KUKA + 10k spheres + plane, rgb", *kuka))
    scene.destroy()

    print()
    header = f"{'frame':<36} | {'best ms/frame':>13} | {'slowest run':>11}"
    print(header)
    print("-" * len(header))
    for name, best, slowest in rows:
        print(f"{name:<36} | {best:>13.1f} | {slowest:>11.1f}")
    print(f"goal KUKA + 10k spheres + plane < 50 ms: {kuka[0]:.1f} ms — {'met' if kuka[0] < 50 else 'NOT met'}")

    scene, robot, camera = kuka_scene()
    modes = {None: "no recording", "buffered": "buffered, then stop_recording(.mp4)",
             "streamed": "streamed (start_recording(.mp4))"}
    samples = {mode: [] for mode in modes}
    with tempfile.TemporaryDirectory() as folder:
        rollout(scene, robot, camera, 5, None, folder)  # warm-up
        for _ in range(args.repeats):  # interleaved, so that a busy spell of the machine hits every mode alike
            for mode in modes:
                samples[mode].append(rollout(scene, robot, camera, args.record_frames, mode, folder))
    print()
    print(f"{args.record_frames}-step KUKA rollout rendering every step, {args.repeats} rollouts of each")
    header = (f"{'':<36} | {'step ms':>7} | {'file s':>6} | {'estimate s':>10} | {'overhead':>8} | "
              f"{'best wall s':>11} | {'slowest':>7} | {'best CPU s':>10}")
    print(header)
    print("-" * len(header))
    estimate = {}
    for mode, label in modes.items():
        walls, cpus, steps, files = zip(*samples[mode])
        step, file = float(np.median(np.concatenate(steps))), float(np.median(files))
        estimate[mode] = args.record_frames * step + file
        overhead = "" if mode is None else f"{estimate[mode] / estimate[None] - 1:+.1%}"
        print(f"{label:<36} | {step * 1e3:>7.2f} | {file:>6.2f} | {estimate[mode]:>10.2f} | {overhead:>8} | "
              f"{min(walls):>11.2f} | {max(walls):>7.2f} | {min(cpus):>10.2f}")
    worst = max(estimate["buffered"], estimate["streamed"]) / estimate[None] - 1
    verdict = "met" if worst < 0.2 else "NOT met"
    print(f"goal recording overhead < 20 %: {worst:.1%}, the worse of the two — {verdict}")

if __name__ == "__main__":
    main()
