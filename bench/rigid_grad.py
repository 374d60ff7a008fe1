"""Forward and forward+backward time of differentiable rigid rollouts.

Cases: (a) the 2-link pendulum ``assets/pendulum2.urdf``, 50 steps, no batch; (b) the KUKA iiwa
(pybullet_data ``kuka_iiwa/model.urdf``, 7 dofs, fixed) 100 steps at n_envs = 1 and 256.
Everything is float32, contact-free, joint limits off, dt = 0.01 s; the scene is built with
``SimOptions(requires_grad=True)``; a force-control tensor (n_steps, [n_envs,] n_dofs) requiring
grad drives every step; the loss is the sum of squares of the final joint positions and
velocities. "forward" is the rollout that records the graph; "fwd+bwd" adds ``loss.backward()``
(gradients reach the controls and the initial state). "bwd/fwd" = (fwd+bwd − fwd) / fwd.
"no-grad fwd" is the same rollout in a scene built without requires_grad (the cost of being
differentiable is the difference). Best of ``--repeats`` after one warm-up rollout.

Peers (Genesis ``genesis-world``, Newton ``newton``) are timed only if importable; they are not
installed here, so their rows say so.

Run:  python bench/rigid_grad.py [--repeats 3]
"""
import argparse
import importlib.util
import os
import sys
import time

import pybullet_data
import torch

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import genesis_lite as gs  # noqa: E402

KUKA = os.path.join(pybullet_data.getDataPath(), "kuka_iiwa", "model.urdf")
PENDULUM = os.path.join(ROOT, "assets", "pendulum2.urdf")
DT = 0.01
CASES = [("pendulum2", PENDULUM, 0, 50), ("kuka", KUKA, 1, 100), ("kuka", KUKA, 256, 100)]


def make_scene(path, n_envs, requires_grad):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT, requires_grad=requires_grad),
                     rigid_options=gs.options.RigidOptions(enable_collision=False, enable_joint_limit=False))
    robot = scene.add_entity(gs.morphs.URDF(file=path, fixed=True))
    scene.build(n_envs=n_envs)
    return scene, robot


def rollout(scene, robot, controls, q0):
    scene.reset()
    robot.set_dofs_position(q0)
    for t in range(len(controls)):
        robot.control_dofs_force(controls[t])
        scene.step()
    return robot.get_dofs_position().pow(2).sum() + robot.get_dofs_velocity().pow(2).sum()


def time_case(path, n_envs, n_steps, repeats):
    batch = (n_envs,) if n_envs else ()
    generator = torch.Generator().manual_seed(0)

    scene, robot = make_scene(path, n_envs, requires_grad=True)
    shape = (n_steps, *batch, robot.n_dofs)
    controls = (0.5 * torch.randn(shape, generator=generator)).to(gs.device, gs.tc_float).requires_grad_(True)
    q0 = (0.5 * torch.randn((*batch, robot.n_dofs), generator=generator)).to(gs.device, gs.tc_float)
    q0.requires_grad_(True)

    rollout(scene, robot, controls, q0).backward()  # warm-up: compiles every kernel
    fwd = fwd_bwd = float("inf")
    for _ in range(repeats):
        controls.grad = q0.grad = None
        t0 = time.perf_counter()
        loss = rollout(scene, robot, controls, q0)
        t1 = time.perf_counter()
        loss.backward()
        t2 = time.perf_counter()
        fwd, fwd_bwd = min(fwd, t1 - t0), min(fwd_bwd, t2 - t0)
    finite = bool(torch.isfinite(controls.grad).all() and torch.isfinite(q0.grad).all())
    scene.destroy()

    plain_scene, plain_robot = make_scene(path, n_envs, requires_grad=False)
    plain_controls, plain_q0 = controls.detach(), q0.detach()
    rollout(plain_scene, plain_robot, plain_controls, plain_q0)
    plain = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        rollout(plain_scene, plain_robot, plain_controls, plain_q0).item()
        plain = min(plain, time.perf_counter() - t0)
    plain_scene.destroy()
    return fwd, fwd_bwd, plain, finite


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    gs.init(backend=gs.cpu, precision="32", logging_level="warning")
    print(f"differentiable rigid rollouts, float32, contact-free, dt={DT}, best of {args.repeats}; "
          f"{os.cpu_count()} CPUs")

    rows = []
    for name, path, n_envs, n_steps in CASES:
        t0 = time.perf_counter()
        fwd, fwd_bwd, plain, finite = time_case(path, n_envs, n_steps, args.repeats)
        rows.append(("genesis_lite", name, n_envs, n_steps, fwd, fwd_bwd, plain, finite))
        print(f"  {name} n_envs={n_envs} done ({time.perf_counter() - t0:.1f} s with compilation)", flush=True)
    peers = [("Genesis", "genesis"), ("Newton", "newton")]
    for label, module in peers:
        if importlib.util.find_spec(module) is None:
            rows.append((label, "-", None, None, None, None, None, None))
        else:  # pragma: no cover - not installed in this environment
            rows.append((label, "installed but not benchmarked by this script", None, None, None, None, None, None))

    print()
    header = (f"{'simulator':>12} | {'robot':>9} | {'n_envs':>6} | {'steps':>5} | {'forward ms':>10} | "
              f"{'fwd+bwd ms':>10} | {'bwd/fwd':>7} | {'no-grad fwd ms':>14} | {'fwd grad/no-grad':>16} | "
              f"{'env-steps/s fwd+bwd':>19} | {'grads finite':>12}")
    print(header)
    print("-" * len(header))
    for sim, robot, n_envs, n_steps, fwd, fwd_bwd, plain, finite in rows:
        if fwd is None:
            note = "not installed" if robot == "-" else robot
            print(f"{sim:>12} | {note}")
            continue
        envs = max(1, n_envs)
        print(f"{sim:>12} | {robot:>9} | {n_envs:>6} | {n_steps:>5} | {fwd * 1e3:>10.1f} | {fwd_bwd * 1e3:>10.1f} | "
              f"{(fwd_bwd - fwd) / fwd:>7.2f} | {plain * 1e3:>14.1f} | {fwd / plain:>16.2f} | "
              f"{envs * n_steps / fwd_bwd:>19,.0f} | {str(finite):>12}")


if __name__ == "__main__":
    main()
