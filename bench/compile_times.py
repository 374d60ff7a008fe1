"""How long a user waits for compiled kernels: seconds from building a scene to its first backward.

Each case runs in a fresh ``python`` subprocess, float64, a differentiable rollout of 5 steps
with force controls requiring grad and a backward:

- empty caches (new, empty folders for Taichi's offline cache and genesis_lite's asset cache):
  the first KUKA scene, then in the same process a second live KUKA scene, then a quadruped scene
  (another robot);
- warm caches: the same three, and a fresh process's import + init + build + first step.

Goals (issue "Solid ground"): second scene of the same robot < 1 s with an empty cache; another
robot < 5 s with a warm cache; fresh process < 3 s with a warm cache.

Run:  python bench/compile_times.py
"""
import json
import os
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

_CHILD = r"""
import json, sys, time
t0 = time.perf_counter()
import torch
import genesis_lite as gs
gs.init(precision="64", logging_level="error")
t_import = time.perf_counter() - t0
KUKA = sys.argv[1]
QUADRUPED = sys.argv[2]

def first_backward(path, fixed):
    start = time.perf_counter()
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True))
    robot = scene.add_entity(gs.morphs.URDF(file=path, fixed=fixed))
    scene.build()
    force = torch.full((robot.n_dofs,), 0.1, dtype=torch.float64, requires_grad=True)
    robot.control_dofs_force(force)
    for _ in range(5):
        scene.step()
    robot.get_links_pos().sum().backward()
    return scene, time.perf_counter() - start

def first_step():
    start = time.perf_counter()
    scene = gs.Scene()
    scene.add_entity(gs.morphs.URDF(file=KUKA, fixed=True))
    scene.build()
    scene.step()
    return time.perf_counter() - start

if sys.argv[3] == "step":
    print(json.dumps({"fresh process: import + init + build + first step": t_import + first_step()}))
else:
    first, t_first = first_backward(KUKA, True)
    second, t_second = first_backward(KUKA, True)
    _, t_other = first_backward(QUADRUPED, False)
    print(json.dumps({"first KUKA scene": t_first, "second live KUKA scene": t_second,
                      "quadruped scene (another robot)": t_other}))
"""


def run(cache, mode):
    import pybullet_data
    kuka = os.path.join(pybullet_data.getDataPath(), "kuka_iiwa", "model.urdf")
    quadruped = os.path.join(ROOT, "assets", "quadruped.urdf")
    # both caches in `cache`: Taichi's kernels and genesis_lite's assets (URDF links, meshes, hulls);
    # Python's bytecode cache as a user has it (pip compiles an installed package; a machine that
    # sets PYTHONDONTWRITEBYTECODE compiles genesis_lite's ~70 modules in every process, +0.17 s)
    env = {**os.environ, "TI_OFFLINE_CACHE_FILE_PATH": cache, "GENESIS_LITE_CACHE_DIR": os.path.join(cache, "assets")}
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    out = subprocess.run([sys.executable, "-c", _CHILD, kuka, quadruped, mode], cwd=ROOT, env=env,
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    with tempfile.TemporaryDirectory() as cache:
        cold = run(cache, "backward")
        warm = run(cache, "backward")
        fresh = run(cache, "step")
    print("seconds to the first backward (float64, 5 steps), each column a fresh process")
    print(f"{'':40s} | {'empty cache':>11s} | {'warm cache':>10s}")
    for name in cold:
        print(f"{name:40s} | {cold[name]:11.2f} | {warm[name]:10.2f}")
    for name, value in fresh.items():
        print(f"{name:40s} | {'':11s} | {value:10.2f}")


if __name__ == "__main__":
    main()
