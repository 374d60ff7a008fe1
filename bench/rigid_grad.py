"""Forward and forward+backward time of differentiable rigid rollouts.

Cases: (a) the 2-link pendulum ``assets/pendulum2.urdf``, 50 steps, no batch; (b) the KUKA iiwa
(pybullet_data ``kuka_iiwa/model.urdf``, 7 dofs, fixed) 100 steps at n_envs = 1 and 256.
Everything is float32, contact-free, joint limits off, dt = 0.01 s; the scene is built with
``SimOptions(requires_grad=True)``; a force-control tensor (n_steps, [n_envs,] n_dofs) requiring
grad drives every step, its rows taken with ``unbind`` (torch's backward of ``controls[t]``
builds and adds a zero tensor of the whole rollout's size at every step: a cost of
steps² × envs that is torch's, not the simulator's; Genesis gets the same); the loss is the
sum of squares of the final joint positions and velocities. "forward" is the rollout that
records the graph; "fwd+bwd" adds ``loss.backward()`` (gradients reach the controls and the
initial state). "bwd/fwd" = (fwd+bwd − fwd) / fwd.
"no-grad fwd" is the same rollout in a scene built without requires_grad (the cost of being
differentiable is the difference). Best of ``--repeats`` after one warm-up rollout.

Peers, Genesis (``genesis-world``) and Newton (``newton``, SolverFeatherstone), run the same rollout
(same URDF, dt, controls and q0, written to .npz files) through ``bench/peers.py`` in a subprocess:
with this interpreter if it imports the peer, else with the interpreter named by ``GENESIS_PYTHON``
/ ``NEWTON_PYTHON`` (virtualenvs set up as in ``bench/README.md``), else its row says "not
installed". Their rows add "fwd+bwd / ours" (the peer's fwd+bwd time over ours for the same case;
goal ≥ 10) and max |Δq| (rad), the largest difference of the final joint positions of the no-grad
rollouts from ours; a note under the table gives each peer's version, import and build times (s)
and how its rollout differs from ours.

Run:  [GENESIS_PYTHON=... NEWTON_PYTHON=...] python bench/rigid_grad.py [--repeats 5]
"""
import argparse
import importlib.util
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np
import pybullet_data
import torch

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import genesis_lite as gs  # noqa: E402

KUKA = os.path.join(pybullet_data.getDataPath(), "kuka_iiwa", "model.urdf")
PENDULUM = os.path.join(ROOT, "assets", "pendulum2.urdf")
DT = 0.01
CASES = [("pendulum2", PENDULUM, 0, 50), ("kuka", KUKA, 1, 100), ("kuka", KUKA, 256, 100)]
PEERS = [("Genesis", "genesis", "GENESIS_PYTHON"), ("Newton", "newton", "NEWTON_PYTHON")]


def make_scene(path, n_envs, requires_grad):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT, requires_grad=requires_grad),
                     rigid_options=gs.options.RigidOptions(enable_collision=False, enable_joint_limit=False))
    robot = scene.add_entity(gs.morphs.URDF(file=path, fixed=True, default_armature=0.0))  # (as the peers')
    scene.build(n_envs=n_envs)
    return scene, robot


def rollout(scene, robot, controls, q0):
    scene.reset()
    robot.set_dofs_position(q0)
    for force in controls.unbind(0):  # see the module docstring
        robot.control_dofs_force(force)
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
    inputs = {"urdf": path, "n_envs": n_envs, "dt": DT, "controls": plain_controls.cpu().numpy(),
              "q0": plain_q0.cpu().numpy(), "q_final": plain_robot.get_dofs_position().cpu().numpy()}
    plain_scene.destroy()
    return fwd, fwd_bwd, plain, finite, inputs


def peer_python(module, env_var):
    """The interpreter to run a peer with: this one if it imports ``module``, else ``$env_var`` (or None)."""
    return sys.executable if importlib.util.find_spec(module) is not None else os.environ.get(env_var)


def run_peer(python, engine, case_files, repeats):
    """Run ``bench/peers.py`` in ``python``; return its header dict and one result dict per case (times in s)."""
    command = [python, os.path.join(ROOT, "bench", "peers.py"), engine, *case_files, "--repeats", str(repeats)]
    proc = subprocess.run(command, capture_output=True, text=True)
    results = [json.loads(line[len("RESULT "):]) for line in proc.stdout.splitlines() if line.startswith("RESULT ")]
    if proc.returncode != 0 or len(results) != len(case_files) + 1:
        tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        raise RuntimeError(f"exit code {proc.returncode}: {tail}")
    return results[0], results[1:]


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=10)
    args = parser.parse_args()
    gs.init(backend=gs.cpu, precision="32", logging_level="warning")
    print(f"differentiable rigid rollouts, float32, contact-free, dt={DT}, best of {args.repeats}; "
          f"{os.cpu_count()} CPUs")

    rows, inputs = [], []
    for name, path, n_envs, n_steps in CASES:
        t0 = time.perf_counter()
        fwd, fwd_bwd, plain, finite, case_inputs = time_case(path, n_envs, n_steps, args.repeats)
        rows.append(("genesis_lite", name, n_envs, n_steps, fwd, fwd_bwd, plain, finite, None, None))
        inputs.append(case_inputs)
        print(f"  {name} n_envs={n_envs} done ({time.perf_counter() - t0:.1f} s with compilation)", flush=True)

    notes = []
    with tempfile.TemporaryDirectory() as tmp:
        case_files = [os.path.join(tmp, f"case{i}.npz") for i in range(len(CASES))]
        for case_file, case_inputs in zip(case_files, inputs):
            np.savez(case_file, **case_inputs)
        for label, engine, env_var in PEERS:
            python = peer_python(engine, env_var)
            if python is None:
                notes.append(f"{label}: not installed (set {env_var}, see bench/README.md)")
                continue
            t0 = time.perf_counter()
            try:
                info, results = run_peer(python, engine, case_files, args.repeats)
            except RuntimeError as error:
                notes.append(f"{label} ({python}): failed, {error}")
                continue
            for ours, case_inputs, r in zip(rows[:len(CASES)], inputs, results):
                _, name, n_envs, n_steps, _, ours_fwd_bwd = ours[:6]
                dq = float(np.abs(np.asarray(r["q_final"]) - case_inputs["q_final"]).max())
                rows.append((label, name, n_envs, n_steps, r["fwd"], r["fwd_bwd"], r["plain"], r["finite"],
                             r["fwd_bwd"] / ours_fwd_bwd, dq))
            builds = " / ".join(f"{r['build']:.1f}" for r in results)
            notes.append(f"{label} {info['version']} ({python}): import + init {info['import']:.1f} s, "
                         f"build {builds} s, whole run {time.perf_counter() - t0:.0f} s; {info['note']}")
            print(f"  {label} done ({time.perf_counter() - t0:.0f} s)", flush=True)

    print()
    header = (f"{'simulator':>12} | {'robot':>9} | {'n_envs':>6} | {'steps':>5} | {'forward ms':>10} | "
              f"{'fwd+bwd ms':>10} | {'bwd/fwd':>7} | {'no-grad fwd ms':>14} | {'fwd grad/no-grad':>16} | "
              f"{'env-steps/s fwd+bwd':>19} | {'grads finite':>12} | {'fwd+bwd / ours':>14} | {'max |Δq|':>8}")
    print(header)
    print("-" * len(header))
    for sim, robot, n_envs, n_steps, fwd, fwd_bwd, plain, finite, vs_ours, dq in rows:
        envs = max(1, n_envs)
        versus = "-" if vs_ours is None else f"{vs_ours:.2f}"
        delta = "-" if dq is None else f"{dq:.1e}"
        print(f"{sim:>12} | {robot:>9} | {n_envs:>6} | {n_steps:>5} | {fwd * 1e3:>10.1f} | {fwd_bwd * 1e3:>10.1f} | "
              f"{(fwd_bwd - fwd) / fwd:>7.2f} | {plain * 1e3:>14.1f} | {fwd / plain:>16.2f} | "
              f"{envs * n_steps / fwd_bwd:>19,.0f} | {str(finite):>12} | {versus:>14} | {delta:>8}")
    for note in notes:
        print(note)


if __name__ == "__main__":
    main()
