"""Where a differentiable rollout spends its time: each rigid kernel's total inside the rollout.

KUKA iiwa (pybullet_data ``kuka_iiwa/model.urdf``, fixed), float32, contact-free, dt = 0.01 s,
100 steps with force controls requiring grad, loss on the final joint positions, then
``backward()``; best of ``--repeats`` after a warm-up. Every launch through
``solvers/launch.BoundKernel`` is timed where it happens, so kernels are measured with the cache
and thread-pool state of a real rollout (a kernel timed in a tight loop of its own can run at
another speed). Prints ms per rollout: forward, forward + backward, and each kernel's sum.

Run:  python bench/kernel_times.py [--envs 256] [--repeats 8]
"""
import argparse
import os
import sys
import time

import pybullet_data
import torch

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import genesis_lite as gs  # noqa: E402
from genesis_lite.solvers.launch import BoundKernel  # noqa: E402

KUKA = os.path.join(pybullet_data.getDataPath(), "kuka_iiwa", "model.urdf")


def timed_launches(totals):
    """Wrap BoundKernel.__call__ so that each kernel's wall time adds up in ``totals`` (s)."""
    launch = BoundKernel.__call__

    def timed(self, *args):
        start = time.perf_counter()
        launch(self, *args)
        name = self.kernel.__name__
        totals[name] = totals.get(name, 0.0) + time.perf_counter() - start

    BoundKernel.__call__ = timed


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", type=int, default=256)
    parser.add_argument("--repeats", type=int, default=8)
    args = parser.parse_args()
    gs.init(backend=gs.cpu, precision="32", logging_level="warning")
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True),
                     rigid_options=gs.options.RigidOptions(enable_collision=False, enable_joint_limit=False))
    robot = scene.add_entity(gs.morphs.URDF(file=KUKA, fixed=True))
    scene.build(n_envs=args.envs)
    batch = (args.envs,) if args.envs else ()
    controls = (0.5 * torch.randn((100, *batch, robot.n_dofs), generator=torch.Generator().manual_seed(0)))
    controls.requires_grad_(True)

    def rollout():
        scene.reset()
        for force in controls.unbind(0):
            robot.control_dofs_force(force)
            scene.step()
        return robot.get_dofs_position().pow(2).sum()

    rollout().backward()  # compiles every kernel
    totals, best = {}, {}
    timed_launches(totals)
    for _ in range(args.repeats):
        totals.clear()
        start = time.perf_counter()
        loss = rollout()
        forward = time.perf_counter() - start
        loss.backward()
        totals.update({"forward (all)": forward, "fwd + bwd (all)": time.perf_counter() - start})
        best = {name: min(best.get(name, float("inf")), value) for name, value in totals.items()}
    print(f"KUKA, {args.envs} envs, 100 steps, float32, best of {args.repeats}: ms per rollout")
    for name, value in sorted(best.items(), key=lambda item: -item[1]):
        print(f"  {name:22s} {value * 1e3:8.1f}")


if __name__ == "__main__":
    main()
