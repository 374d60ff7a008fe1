"""Forward and forward+backward time of differentiable rollouts with contact, beside Genesis.

Scenes, both on a plane, float32, dt = 2 ms (as bench/rigid_contact.py), 256 envs, 100 steps:
(1) box: a 0.2 × 0.2 × 0.1 m box resting on the plane (0.03 mm deep, its rest) and launched
along it, so it slides, spins and stops (μ = 1 stops 1 m/s in 0.1 s); while it slides the soft
contact lifts it (by 2 mm at 1 m/s, as in MuJoCo with either cone), so its four corner contacts
break and remake, 0 to 4 per env and step; (2) a1: the pybullet_data ``a1`` quadruped, free base
at 0.305 m, legs at the standing pose under position servos (kp 100, kv 2; targets set every
step), kicked by a small initial velocity: the base settles and sways (height 0.3046 to
0.3078 m), on its four feet (4 contacts in every env and step). Each env gets its own initial
velocity v0 (box: vx, vy in ±1 m/s, yaw rate ±2 rad/s; a1: base vx, vy ±0.3 m/s, yaw rate
±0.5 rad/s, legs ±1 rad/s); the a1 with ``URDF(default_armature=0.0)`` in both (the URDF's own
dynamics; Genesis's default adds a 0.1 rotor, ours too). Both engines run with their default RigidOptions (ours are
Genesis's: pyramidal cone, impratio 1, time constant 0.01 s, MuJoCo's default solimp, friction 1,
Newton with at most 25 iterations; tolerance 1e-5 in ours, 1e-6 in Genesis on its own scale).

The scene is built with ``SimOptions(requires_grad=True)``; v0 requires grad and is set with
``set_dofs_velocity`` after ``scene.reset()``; the loss is sum(qpos_final²) + sum(qvel_final²)
over all envs (qpos with the free base's quaternion). "forward" is the rollout that records the
graph, up to the loss; "fwd+bwd" adds ``loss.backward()`` into v0. The input is v0 in both
scenes because Genesis refuses gradients of PD targets ("not supported yet"). Times are per
step (ms); "bwd/fwd" = (fwd+bwd − fwd) / fwd of the best times; "spread" = (worst − best) / best
over the repeats; "no-grad fwd" is the same rollout in a scene built without requires_grad.
One warm-up rollout (compilation) before ``--repeats`` timed ones.

The a1 keeps self-collision on in both engines. Its cylinder–cylinder and cylinder–box self-pairs
go through our convex collider, whose contacts have exact gradients but for a few features (two
cylinders touching rim on rim, among others), where a backward raises GradientError. Standing,
the a1 never touches itself (its contacts are the feet on the plane).

Genesis (``genesis-world`` 1.4.5) runs the same scenes and v0 (written to .npz files) in its own
interpreter, this script with ``--peer``: this interpreter if it imports ``genesis``, else
``$GENESIS_PYTHON`` (virtualenv: bench/README.md), else its rows say "not installed". Genesis,
backend cpu, differs from ours in: its integrator (``approximate_implicitfast``, the only one it
differentiates; ours makes damping and servo kv implicit as it does, but solves contact with M and
integrates the constraint force through the damped matrix, as MuJoCo's implicitfast), its own
colliders (ours: MuJoCo's), legs set with a grad-requiring tensor (given one that does not, 1.4.5 ignores
``set_dofs_position`` or crashes in a requires_grad scene) and its differentiable read-out
``rigid_solver.get_state()``. Its rows add "vs ours" (its fwd+bwd time / ours; goal ≥ 10),
max |Δq| (largest difference of the final qpos from ours) and "Δgrad" (|g − g_ours| / |g_ours|
of dL/dv0, all envs): same scene, different integrators, so close but not equal.

Goals (issue "Gradients through contact"): bwd/fwd ≤ 2; Genesis fwd+bwd / ours ≥ 10.

Run:  [GENESIS_PYTHON=/work/peers/genesis/bin/python] python bench/rigid_contact_grad.py [--repeats 3]
          [--envs 256] [--steps 100]
(the engines are imported inside the functions that use them: the same file runs in Genesis's
interpreter, which has no Taichi.)
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
import torch

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DT, N_ENVS, N_STEPS = 0.002, 256, 100
BOX_SIZE, BOX_Z = (0.2, 0.2, 0.1), 0.04997   # m: full extents, centre height (resting: 0.03 mm deep)
A1_Z, KP, KV = 0.305, 100.0, 2.0             # m, N·m/rad, N·m·s/rad
A1_STAND = np.tile([0.0, 0.8, -1.5], 4)      # hip, thigh, calf of each leg (rad)
SCENES = ("box", "a1")


def a1_urdf():
    import pybullet_data
    return os.path.join(pybullet_data.getDataPath(), "a1", "a1.urdf")


def initial_velocity(scene, n_envs, n_dofs):
    """(n_envs, n_dofs) float32 v0, seeded: base linear x, y and yaw rate (+ leg joints for the a1)."""
    rng = np.random.default_rng(0)
    v0 = np.zeros((n_envs, n_dofs), dtype=np.float32)
    linear, yaw, legs = (1.0, 2.0, 0.0) if scene == "box" else (0.3, 0.5, 1.0)
    v0[:, 0:2] = rng.uniform(-linear, linear, (n_envs, 2))
    v0[:, 5] = rng.uniform(-yaw, yaw, n_envs)
    v0[:, 6:] = rng.uniform(-legs, legs, (n_envs, n_dofs - 6))
    return v0


def build(gs, case, requires_grad, ours):
    """(scene, entity, legs) of ``case`` in engine ``gs`` (genesis_lite or genesis, same API)."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT, requires_grad=requires_grad),
                     rigid_options=gs.options.RigidOptions(enable_self_collision=bool(case["self_collision"])),
                     show_viewer=False)
    scene.add_entity(gs.morphs.Plane())
    if case["scene"] == "box":
        entity = scene.add_entity(gs.morphs.Box(size=BOX_SIZE, pos=(0.0, 0.0, BOX_Z)))
    else:
        # no rotor armature in either engine (Genesis's default adds 0.1 a dof), as the URDF
        entity = scene.add_entity(gs.morphs.URDF(file=str(case["urdf"]), pos=(0.0, 0.0, A1_Z), default_armature=0.0))
    n_envs = int(case["n_envs"])
    scene.build(n_envs=n_envs)
    legs = None
    if case["scene"] == "a1":
        legs = np.arange(6, entity.n_dofs)
        for setter, value in ((entity.set_dofs_kp, KP), (entity.set_dofs_kv, KV)):
            gains = np.full(len(legs), value)
            setter(np.tile(gains, (n_envs, 1)) if ours else gains, legs)  # ours takes per-env gains, Genesis shared
    return scene, entity, legs


def make_rollout(scene, entity, legs, n_steps, final_state, stand, target):
    """(scene, forward): forward(v0) → (loss, final qpos): reset, legs to ``stand``, velocity v0, n_steps steps
    (PD targets ``target`` set every step), loss = sum(qpos²) + sum(qvel²) of ``final_state()``."""
    def forward(v0):
        scene.reset()
        if legs is not None:
            entity.set_dofs_position(stand, legs)
        entity.set_dofs_velocity(v0)
        for _ in range(n_steps):
            if legs is not None:
                entity.control_dofs_position(target, legs)
            scene.step()
        qpos, qvel = final_state()
        return qpos.pow(2).sum() + qvel.pow(2).sum(), qpos
    return scene, forward


def time_rollouts(make, case, repeats):
    """Time one case in one engine: ``make(requires_grad)`` → (scene, forward(v0)). Returns a
    dict of per-repeat times (s), the final qpos, dL/dv0 and whether it is finite."""
    t0 = time.perf_counter()
    scene, forward = make(requires_grad=True)
    build_s = time.perf_counter() - t0
    v0 = torch.from_numpy(case["v0"]).requires_grad_(True)
    forward(v0)[0].backward()  # warm-up: compiles every kernel
    fwd, fwd_bwd = [], []
    for _ in range(repeats):
        v0.grad = None
        t0 = time.perf_counter()
        loss, qpos = forward(v0)
        t1 = time.perf_counter()
        loss.backward()
        t2 = time.perf_counter()
        fwd.append(t1 - t0)
        fwd_bwd.append(t2 - t0)
    grad, q_final = v0.grad.detach().cpu().numpy(), qpos.detach().cpu().numpy()
    scene.destroy()

    scene, plain_forward = make(requires_grad=False)
    plain_v0 = v0.detach()
    plain_forward(plain_v0)[0].item()
    plain = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        plain_forward(plain_v0)[0].item()
        plain.append(time.perf_counter() - t0)
    scene.destroy()
    return {"build": build_s, "fwd": fwd, "fwd_bwd": fwd_bwd, "plain": plain,
            "q_final": q_final.reshape(len(grad), -1).tolist(),
            "grad": grad.tolist(), "finite": bool(np.isfinite(grad).all())}


# -- ours -----------------------------------------------------------------------------------------------

def ours_case(scene_name, n_envs, n_steps):
    """The case dict of ``scene_name`` for both engines, with v0."""
    import genesis_lite as gs
    case = {"scene": scene_name, "n_envs": n_envs, "n_steps": n_steps, "self_collision": True, "urdf": a1_urdf()}
    scene, entity, _ = build(gs, case, requires_grad=True, ours=True)
    case["v0"] = initial_velocity(scene_name, n_envs, entity.n_dofs)
    scene.destroy()
    return case


def ours_make(case):
    import genesis_lite as gs
    stand = torch.from_numpy(np.tile(A1_STAND, (int(case["n_envs"]), 1)).astype(np.float32))

    def make(requires_grad):
        scene, entity, legs = build(gs, case, requires_grad, ours=True)
        final = lambda: (entity.get_qpos(), entity.get_dofs_velocity())  # noqa: E731
        return make_rollout(scene, entity, legs, int(case["n_steps"]), final, stand, stand)
    return make


# -- Genesis (runs in its own interpreter: --peer) ------------------------------------------------------

def genesis_make(case):
    import genesis as gs
    target = torch.from_numpy(np.tile(A1_STAND, (int(case["n_envs"]), 1)).astype(np.float32))
    # the legs' start: a tensor that requires grad (given one that does not, 1.4.5 ignores
    # set_dofs_position or crashes in a requires_grad scene: bench/peers.py; its .grad stays None);
    # the PD targets must not (it raises: no gradient of PD targets)
    stand = target.clone().requires_grad_(True)

    def make(requires_grad):
        scene, entity, legs = build(gs, case, requires_grad, ours=False)

        def final():
            state = scene.sim.rigid_solver.get_state()
            return state.qpos, state.dofs_vel
        return make_rollout(scene, entity, legs, int(case["n_steps"]), final,
                            stand if requires_grad else target, target)
    return make


def peer_main(case_files, repeats):
    """Genesis's side: prints "RESULT {json}" lines, a header then one per case (or its error)."""
    t0 = time.perf_counter()
    import genesis as gs
    gs.init(backend=gs.cpu, precision="32", logging_level="warning")
    print("RESULT " + json.dumps({"version": gs.__version__, "import": time.perf_counter() - t0}), flush=True)
    for path in case_files:
        case = dict(np.load(path))
        try:
            result = time_rollouts(genesis_make(case), case, repeats)
        except Exception as error:  # record what Genesis does, and go on with the next case
            result = {"error": f"{type(error).__name__}: {str(error).strip().splitlines()[-1][:300]}"}
        print("RESULT " + json.dumps(result), flush=True)


def peer_python(module, env_var):
    """The interpreter to run a peer with: this one if it imports ``module``, else ``$env_var`` (or None)."""
    return sys.executable if importlib.util.find_spec(module) is not None else os.environ.get(env_var)


def run_genesis(python, case_files, repeats):
    """Run this script with --peer in ``python``; return its header and one result dict per case."""
    command = [python, os.path.abspath(__file__), "--peer", *case_files, "--repeats", str(repeats)]
    proc = subprocess.run(command, capture_output=True, text=True)
    results = [json.loads(line[len("RESULT "):]) for line in proc.stdout.splitlines() if line.startswith("RESULT ")]
    if len(results) < 1 + len(case_files):  # a crash: say how it ended
        tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        results += [{"error": f"exit code {proc.returncode}: {tail}"}] * (1 + len(case_files) - len(results))
    return results[0], results[1:]


# -- table ----------------------------------------------------------------------------------------------

def row(sim, case, r, ours=None):
    """One table line of result ``r`` (per-step ms); ``ours``: our result of the same case."""
    steps = int(case["n_steps"])
    head = f"{sim:>12} | {case['scene']:>5} | {int(case['n_envs']):>6} | {steps:>5} | "
    if "error" in r:
        return head + r["error"]
    ms = lambda times: 1e3 * min(times) / steps  # noqa: E731
    spread = lambda times: f"{100 * (max(times) - min(times)) / min(times):.0f}%"  # noqa: E731
    fwd, fwd_bwd = min(r["fwd"]), min(r["fwd_bwd"])
    line = (f"{ms(r['fwd']):>7.2f} {spread(r['fwd']):>5} | {ms(r['fwd_bwd']):>7.2f} {spread(r['fwd_bwd']):>5} | "
            f"{(fwd_bwd - fwd) / fwd:>7.2f} | {ms(r['plain']):>7.2f} | "
            f"{int(case['n_envs']) * steps / fwd_bwd:>14,.0f} | {str(r['finite']):>6} | ")
    if ours is None:
        return head + line + f"{'-':>7} | {'-':>8} | {'-':>7}"
    dq = np.abs(np.asarray(r["q_final"]) - np.asarray(ours["q_final"])).max()
    g, g_ours = np.asarray(r["grad"]), np.asarray(ours["grad"])
    dgrad = np.linalg.norm(g - g_ours) / np.linalg.norm(g_ours)
    return head + line + f"{fwd_bwd / min(ours['fwd_bwd']):>7.2f} | {dq:>8.1e} | {dgrad:>7.1e}"


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--envs", type=int, default=N_ENVS)
    parser.add_argument("--steps", type=int, default=N_STEPS)
    parser.add_argument("--peer", nargs="+", metavar="CASE.npz", help=argparse.SUPPRESS)  # Genesis's side
    args = parser.parse_args()
    if args.peer:
        return peer_main(args.peer, args.repeats)

    sys.path.insert(0, ROOT)
    import genesis_lite as gs
    gs.init(backend=gs.cpu, precision="32", logging_level="warning")
    print(f"differentiable rollouts with contact, float32, dt={DT}, {args.envs} envs, {args.steps} steps, "
          f"loss into v0, best of {args.repeats}; {os.cpu_count()} CPUs", flush=True)
    cases, ours, notes = [], [], []
    for name in SCENES:
        t0 = time.perf_counter()
        case = ours_case(name, args.envs, args.steps)
        cases.append(case)
        ours.append(time_rollouts(ours_make(case), case, args.repeats))
        print(f"  ours {name} done ({time.perf_counter() - t0:.0f} s with compilation)", flush=True)

    python = peer_python("genesis", "GENESIS_PYTHON")
    peers = [None] * len(cases)
    if python is None:
        notes.append("Genesis: not installed (set GENESIS_PYTHON, see bench/README.md)")
    else:
        t0 = time.perf_counter()
        with tempfile.TemporaryDirectory() as tmp:
            case_files = [os.path.join(tmp, f"{case['scene']}.npz") for case in cases]
            for path, case in zip(case_files, cases):
                np.savez(path, **case)
            info, peers = run_genesis(python, case_files, args.repeats)
        builds = " / ".join("-" if "error" in r else f"{r['build']:.0f}" for r in peers)
        notes.append(f"Genesis {info.get('version', '?')} ({python}): import + init {info.get('import', 0):.0f} s, "
                     f"build {builds} s, whole run {time.perf_counter() - t0:.0f} s" if "error" not in info
                     else f"Genesis ({python}): {info['error']}")
        print(f"  Genesis done ({time.perf_counter() - t0:.0f} s)", flush=True)

    print()
    header = (f"{'simulator':>12} | {'scene':>5} | {'n_envs':>6} | {'steps':>5} | {'fwd ms/step':>13} | "
              f"{'fwd+bwd ms/step':>15} | {'bwd/fwd':>7} | {'no-grad':>7} | {'env-steps/s fb':>14} | "
              f"{'finite':>6} | {'vs ours':>7} | {'max |Δq|':>8} | {'Δgrad':>7}")
    print(header)
    print(f"{'':>12} | {'':>5} | {'':>6} | {'':>5} | {'best spread':>13} | {'best spread':>15} | {'':>7} | "
          f"{'fwd ms':>7} |")
    print("-" * len(header))
    for case, mine, peer in zip(cases, ours, peers):
        print(row("genesis_lite", case, mine))
        if peer is not None:
            print(row("Genesis", case, peer, mine))
    for note in notes:
        print(note)


if __name__ == "__main__":
    main()
