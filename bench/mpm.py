"""MPM forward and forward+backward speed and memory, beside Genesis's MPM in the same run.

Scenes (one function, ``build``, makes them in either engine: genesis_lite follows Genesis's API):
Genesis's default domain, lower (-1, -1, 0) m, upper (1, 1, 1) m, ``grid_density`` 64 cells/m
(dx = 15.6 mm), particle_size 0.01 m (its default at that density), ``sampler="regular"``, dt = 2 ms
in 10 substeps (h = 0.2 ms, under Genesis's suggested limit 2e-2·dx = 0.31 ms), gravity −9.81
m/s², slip walls. Blocks are cubes 1 mm above the floor wall (3 cells = 47 mm up): the floor
nodes are in their bottom particles' stencils from the start, so they land at once. The regular
sampler puts round(side / 0.01) particles on each axis, so a 0.22 m cube has 22³ = 10 648
particles, a 0.37 m one 37³ = 50 653.

- ``neohooken`` / ``corotation``: one block of ``Elastic(E=3e5, nu=0.2, rho=1000, model=...)``;
- ``sand``: one block of ``Sand(E=1e6, nu=0.2, rho=1000, friction_angle=45)``;
- ``mixed``: four blocks side by side in one grid: an elastic jelly (``Elastic``, corotated,
  E 3e5), ``Sand``, water (``Liquid``, E 1e6, inviscid) and ``Snow`` (E 1e6); cubes of 0.14 m
  (4 × 2744 = 10 976 particles) or 0.23 m (4 × 12 167 = 48 668), 2 cm apart;
- ``grad-neohooken``: the 10k neo-Hookean block in a ``SimOptions(requires_grad=True)`` scene.
  A rollout: ``scene.reset()``, ``entity.set_velocity(v0)`` with v0 (N, 3) uniform in ±0.1 m/s
  requiring grad, K steps, loss = mean over particles of x_final · r (r a fixed (N, 3) normal
  draw), ``loss.backward()`` into v0. Final positions are read with ``get_particles_pos()`` in
  ours (SPEC §2: getters are differentiable) and ``get_state().pos`` in Genesis (its
  differentiable read-out). v0 and r come from ``np.random.RandomState(0)`` (a frozen stream), so
  both engines get the same.

Every case runs in a fresh process per engine (this file with ``--worker``): ours in this
interpreter, Genesis (genesis-world 1.4.5, backend cpu) in ``$GENESIS_PYTHON`` (default: the
virtualenv of bench/README.md, /work/peers/genesis/bin/python, when it exists). Cases run in
turn, ours then Genesis's, so both see the same load on a shared machine. Both run with
``OMP_WAIT_POLICY=PASSIVE`` (unless set): torch's OpenMP threads then do not spin on the cores the
engines' kernels run on after each torch op (genesis_lite's import sets it; Genesis's does not).

What is measured (both engines alike, float32 unless ``--precision 64``):
- forward: ``--repeats`` timed runs of S steps (10 for the 10k scenes, 2 for the 50k ones), each
  from the initial state (``scene.reset()`` before it, untimed), after an untimed warm-up run
  (the first step compiles or loads the kernels); "ms/substep" = best / (S · substeps),
  "spread" = (worst − best) / best; particle-substeps/s = N · S · substeps / best.
- fwd+bwd: a one-step warm-up rollout (it compiles or loads every kernel), then ``--repeats``
  rollouts of K = ``--horizon`` steps, each timed up to the loss (forward) and through
  ``loss.backward()``; "bwd/fwd" = backward / forward of the best rollout. Memory against the
  horizon, in the same process afterwards: one rollout each of K, 2K and 4K steps, the peak RSS
  restarted before each; "peak MiB" is its peak above the RSS before it (what the rollout and its
  backward held at most), "MiB/stp" and "B/p" the slope from K to 4K steps per step and per
  particle per step.
- peak RSS: the process's resident-set high-water mark (VmHWM of /proc/self/status), restarted
  after the warm-up ("5" into /proc/self/clear_refs) so that it holds the timed runs and leaves
  out the transient memory of compiling kernels: the whole process (interpreter, engine, torch,
  kernels, scene, and for fwd+bwd what the rollout keeps for the backward). "sim MiB" subtracts
  the RSS right after import + ``gs.init`` (VmRSS), i.e. what the scene and its runs added.
- time to first step: another fresh process, started after the timing one (so its kernel cache is
  warm), imports the engine, calls ``gs.init``, builds the scene and steps once; the seconds from
  the worker's first line (Python's own start-up excluded) to the end of that step.
- checks: particle counts (printed: equal in both engines, or the table says so), the final
  positions finite, and "max |Δx|" / "Δgrad" on Genesis's rows: the largest difference of its
  final positions from ours, and |g − g_ours| / |g_ours| of dL/dv0.

Goals (issues 12 and 13): forward ≥ 5× Genesis; ≥ 3e6 particle-substeps/s for 10k neo-Hookean
particles in float32; first step < 5 s with a warm cache; backward ≤ 2.5× forward; fwd+bwd ≥ 5×
faster than Genesis; memory side by side with Genesis's.

Run:  python bench/mpm.py [--only ours|genesis] [--cases neohooken-10k grad-neohooken-10k ...]
          [--precision 32|64] [--repeats 3] [--horizon 10] [--json results.json] [--no-first-step]
(engines are imported inside the worker functions: the same file runs in Genesis's interpreter.)
"""
import time

T_START = time.perf_counter()  # the worker's time to first step counts from here

import argparse  # noqa: E402
import ctypes  # noqa: E402
import gc  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402
import runpy  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402

import numpy as np  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
GENESIS_VENV = "/work/peers/genesis/bin/python"
DT, SUBSTEPS, GRID_DENSITY = 2e-3, 10, 64
LOWER, UPPER = (-1.0, -1.0, 0.0), (1.0, 1.0, 1.0)
FLOOR = 3 / GRID_DENSITY + 0.001   # m: the blocks' bottom, 1 mm above the floor wall
GAP = 0.02                          # m: between the mixed scene's blocks
SIDE = {"10k": 0.22, "50k": 0.37}           # m: one block's side (22³, 37³ particles)
MIXED_SIDE = {"10k": 0.14, "50k": 0.23}     # m: each of the four blocks (4·14³, 4·23³)
MEMORY_HORIZONS = (1, 2, 4)                 # memory is measured at these multiples of K steps
STEPS = {"10k": 10, "50k": 2}               # steps per timed repeat
MATERIALS = ("neohooken", "corotation", "sand", "mixed")
CASES = [f"{m}-{size}" for m in MATERIALS for size in SIDE] + ["grad-neohooken-10k"]


# -- the scenes (both engines) ---------------------------------------------------------------------------

def material(gs, kind):
    """The MPM material ``kind`` (one of neohooken, corotation, jelly, sand, water, snow) of engine ``gs``."""
    MPM = gs.materials.MPM
    regular = {"sampler": "regular"}
    if kind in ("neohooken", "corotation", "jelly"):
        model = "corotation" if kind == "jelly" else kind
        return MPM.Elastic(E=3e5, nu=0.2, rho=1000.0, model=model, **regular)
    if kind == "sand":
        return MPM.Sand(E=1e6, nu=0.2, rho=1000.0, friction_angle=45.0, **regular)
    if kind == "water":
        return MPM.Liquid(E=1e6, nu=0.2, rho=1000.0, viscous=False, **regular)
    return MPM.Snow(E=1e6, nu=0.2, rho=1000.0, **regular)


def blocks(case):
    """[(material kind, centre (m), side (m))] of ``case`` ("neohooken-10k", "mixed-50k", "grad-…")."""
    kind, size = case.removeprefix("grad-").rsplit("-", 1)
    if kind != "mixed":
        side = SIDE[size]
        return [(kind, (0.0, 0.0, FLOOR + side / 2), side)]
    side = MIXED_SIDE[size]
    offset = (side + GAP) / 2
    corners = ((-1, -1), (1, -1), (-1, 1), (1, 1))
    return [(kind, (sx * offset, sy * offset, FLOOR + side / 2), side)
            for kind, (sx, sy) in zip(("jelly", "sand", "water", "snow"), corners)]


def build(gs, case, requires_grad):
    """(scene, entities) of ``case`` in engine ``gs`` (genesis_lite or genesis), built with n_envs = 0."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=DT, substeps=SUBSTEPS, requires_grad=requires_grad),
                     mpm_options=gs.options.MPMOptions(lower_bound=LOWER, upper_bound=UPPER,
                                                       grid_density=GRID_DENSITY),
                     show_viewer=False)
    entities = [scene.add_entity(gs.morphs.Box(pos=centre, size=(side,) * 3), material=material(gs, kind))
                for kind, centre, side in blocks(case)]
    scene.build(n_envs=0)
    return scene, entities


# -- the worker (one case, one engine, one fresh process) -----------------------------------------------

def rss_now_mb():
    """The process's resident set now (MiB), VmRSS of /proc/self/status."""
    return proc_status_mb("VmRSS:")


def peak_rss_mb():
    """The process's resident-set high-water mark since the last ``reset_peak_rss`` (MiB), VmHWM."""
    return proc_status_mb("VmHWM:")


def proc_status_mb(key):
    """A memory line of /proc/self/status, in MiB."""
    with open("/proc/self/status") as status:
        return int(next(line for line in status if line.startswith(key)).split()[1]) / 1024


def reset_peak_rss():
    """Restart the high-water mark from the current RSS (Linux ≥ 4.0: "5" into /proc/self/clear_refs),
    so that a peak leaves out what compiling the kernels took."""
    with open("/proc/self/clear_refs", "w") as clear_refs:
        clear_refs.write("5")


def init_engine(engine, precision):
    """Import and initialise ``engine`` ("ours" or "genesis") at ``precision``, on the CPU (a worker
    run inline: on the backend gs.init picks by default, as the test process's runtime); return
    (gs, version)."""
    if engine == "ours":
        sys.path.insert(0, ROOT)
        import genesis_lite as gs
    else:
        import genesis as gs
    inline = engine == "ours" and os.environ.get("GENESIS_LITE_BENCH_INLINE")
    gs.init(backend=None if inline else gs.cpu, precision=precision, logging_level="warning")
    return gs, getattr(gs, "__version__", "?")


def final_positions(entities, engine, requires_grad):
    """(N, 3) positions of all entities' particles; in a requires_grad scene, the engine's
    differentiable read-out (ours: get_particles_pos; Genesis: get_state().pos)."""
    import torch
    if requires_grad and engine == "genesis":
        return torch.cat([entity.get_state().pos.reshape(-1, 3) for entity in entities])
    return torch.cat([entity.get_particles_pos().reshape(-1, 3) for entity in entities])


def time_forward(scene, n_steps, repeats):
    """Seconds of each of ``repeats`` runs of ``n_steps`` steps from the scene's initial state (each
    after an untimed ``scene.reset()``), after a warm-up run; the peak RSS restarts after the warm-up."""
    def run():
        scene.reset()
        t0 = time.perf_counter()
        for _ in range(n_steps):
            scene.step()
        return time.perf_counter() - t0

    run()
    reset_peak_rss()
    return [run() for _ in range(repeats)]


def rollout_inputs(n_particles, dtype):
    """(v0 (N, 3) m/s requiring grad, r (N, 3)): the same arrays in every engine and process."""
    import torch
    draws = np.random.RandomState(0)
    v0 = draws.uniform(-0.1, 0.1, (n_particles, 3))
    r = draws.standard_normal((n_particles, 3))
    as_tensor = lambda a: torch.from_numpy(a).to(dtype)  # noqa: E731
    return as_tensor(v0).requires_grad_(True), as_tensor(r)


def time_gradients(scene, entities, engine, horizon, repeats, precision):
    """Forward and backward seconds of ``repeats`` rollouts of ``horizon`` steps, after a one-step
    warm-up rollout (it compiles or loads every kernel; the peak RSS restarts after it); dL/dv0 and
    the loss of the last."""
    import torch
    entity = entities[0]
    v0, r = rollout_inputs(entity.n_particles, torch.float64 if precision == "64" else torch.float32)

    def rollout(n_steps):
        v0.grad = None
        t0 = time.perf_counter()
        scene.reset()
        entity.set_velocity(v0)
        for _ in range(n_steps):
            scene.step()
        loss = (final_positions(entities, engine, True) * r).sum() / entity.n_particles
        t1 = time.perf_counter()
        loss.backward()
        return t1 - t0, time.perf_counter() - t1, float(loss.detach())

    rollout(1)
    reset_peak_rss()
    fwd, bwd, loss = zip(*[rollout(horizon) for _ in range(repeats)])
    grad = v0.grad.detach().double().numpy()
    return list(fwd), list(bwd), grad, loss[-1], [peak_growth(rollout, k * horizon) for k in MEMORY_HORIZONS]


def release_free_heap():
    """Return the C heap's free memory to the system (glibc's malloc_trim), so that what an earlier
    rollout freed is not resident any more and a rollout's RSS growth counts all it holds."""
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass


def peak_growth(rollout, n_steps):
    """(n_steps, MiB): the peak RSS of a rollout of n_steps and its backward above the RSS before it."""
    gc.collect()
    release_free_heap()
    before = rss_now_mb()
    reset_peak_rss()
    rollout(n_steps)
    return n_steps, peak_rss_mb() - before


def worker(engine, mode, case, args, out):
    """Run ``case`` in ``engine``: mode "first" (time to first step), "forward" or "grad"; results to
    ``out`` (.json, and final positions or dL/dv0 in ``out``.npy)."""
    gs, version = init_engine(engine, args.precision)
    result = {"version": version, "import_init": time.perf_counter() - T_START, "rss_init": rss_now_mb()}
    requires_grad = mode == "grad"
    t0 = time.perf_counter()
    scene, entities = build(gs, case, requires_grad)
    result["build"] = time.perf_counter() - t0
    result["n_particles"] = [entity.n_particles for entity in entities]
    n = sum(result["n_particles"])
    if mode == "first":
        scene.step()
        result["first_step"] = time.perf_counter() - T_START
    elif mode == "forward":
        n_steps = STEPS[case.rsplit("-", 1)[1]]
        result.update(steps=n_steps, times=time_forward(scene, n_steps, args.repeats))
        array = final_positions(entities, engine, False).double().numpy()
    else:
        result["horizon"] = args.horizon
        result["fwd"], result["bwd"], array, result["loss"], result["memory"] = time_gradients(
            scene, entities, engine, args.horizon, args.repeats, args.precision)
    if mode != "first":
        result["finite"] = bool(np.isfinite(array).all())
        np.save(out + ".npy", array.reshape(n, 3))
    result["peak_rss"] = peak_rss_mb()
    with open(out, "w") as file:
        json.dump(result, file)


# -- the parent: runs workers, prints the tables ---------------------------------------------------------

def genesis_python():
    """Genesis's interpreter: $GENESIS_PYTHON, else the README's virtualenv if present, else None."""
    python = os.environ.get("GENESIS_PYTHON")
    return python or (GENESIS_VENV if os.path.exists(GENESIS_VENV) else None)


def run_worker(python, engine, mode, case, args, tmp):
    """Run one worker process; return its result dict (with "array" when it saved one) or {"error": …}."""
    out = os.path.join(tmp, f"{engine}-{mode}-{case}.json")
    command = [python, os.path.abspath(__file__), "--worker", engine, mode, case, out,
               "--precision", args.precision, "--repeats", str(args.repeats), "--horizon", str(args.horizon)]
    result = run_json(command, out)
    if "error" not in result and os.path.exists(out + ".npy"):
        result["array"] = np.load(out + ".npy")
    return result


def run_json(command, out):
    """Run a worker process ``command`` that writes its result to the JSON file ``out``; return the
    result, or {"error": …} with the last line of its stderr. Torch's OpenMP threads wait passively
    in both engines (genesis_lite's import sets it where torch comes in through it; Genesis's does
    not): neither engine's kernels share the cores with spinning threads.
    With $GENESIS_LITE_BENCH_INLINE set (tests/test_bench.py), a worker on this interpreter runs in
    this process instead: on the kernels it has loaded, and its errors raise (its timings and memory
    are not a fresh process's)."""
    if os.environ.get("GENESIS_LITE_BENCH_INLINE") and command[0] == sys.executable:
        argv, sys.argv = sys.argv, command[1:]
        try:
            runpy.run_path(command[1], run_name="__main__")
        finally:
            sys.argv = argv
        with open(out) as file:
            return json.load(file)
    env = {**os.environ, "OMP_WAIT_POLICY": os.environ.get("OMP_WAIT_POLICY", "PASSIVE")}
    proc = subprocess.run(command, capture_output=True, text=True, env=env)
    if proc.returncode != 0 or not os.path.exists(out):
        lines = [line for line in proc.stderr.strip().splitlines() if line.strip()] or ["no output"]
        return {"error": f"exit code {proc.returncode}: {lines[-1][:300]}"}
    with open(out) as file:
        return json.load(file)


def run_case(python, engine, case, args, tmp):
    """All of one engine's workers for ``case``: a dict of the timing result (+ first step, + 2K memory)."""
    mode = "grad" if case.startswith("grad-") else "forward"
    result = run_worker(python, engine, mode, case, args, tmp)
    if "error" in result:
        return result
    if mode == "forward" and not args.no_first_step:
        first = run_worker(python, engine, "first", case, args, tmp)
        result["first"] = first.get("first_step", float("nan"))
        result["first_parts"] = first
    return result


def spread(times):
    """(worst − best) / best, in %."""
    return 100 * (max(times) - min(times)) / min(times)


def forward_row(engine, case, r, ours):
    """One line of the forward table; ``ours``: our result of the same case (for the Genesis row's checks)."""
    head = f"{case:>15} | {engine:>12} | "
    if "error" in r:
        return head + r["error"]
    n, substeps = sum(r["n_particles"]), r["steps"] * SUBSTEPS
    best = min(r["times"])
    line = (f"{n:>7} | {1e3 * best / substeps:>7.2f} {spread(r['times']):>5.0f}% | {n * substeps / best:>10.3g} | "
            f"{r['peak_rss']:>7.0f} {r['peak_rss'] - r['rss_init']:>7.0f} | {r.get('first', float('nan')):>6.1f} | "
            f"{str(r['finite']):>6} | ")
    return head + line + comparison(r, ours, lambda x: min(x["times"]) / sum(x["n_particles"]))


def comparison(r, ours, cost):
    """The Genesis row's tail: its cost / ours (speed-up), its peak RSS / ours and max |Δx| or Δgrad."""
    if ours is None or "error" in ours:
        return f"{'-':>7} | {'-':>6} | {'-':>8}"
    if ours["n_particles"] != r["n_particles"]:
        return f"particle counts differ: ours {ours['n_particles']}, Genesis {r['n_particles']}"
    a, b = ours["array"], r["array"]
    if "fwd" in r:
        diff = np.linalg.norm(b - a) / np.linalg.norm(a)
    else:
        diff = np.abs(b - a).max()
    return f"{cost(r) / cost(ours):>7.2f} | {r['peak_rss'] / ours['peak_rss']:>6.2f} | {diff:>8.1e}"


def grad_row(engine, case, r, ours):
    """One line of the fwd+bwd table (per-step ms)."""
    head = f"{case:>18} | {engine:>12} | "
    if "error" in r:
        return head + r["error"]
    n, k = sum(r["n_particles"]), r["horizon"]
    rollout = [f + b for f, b in zip(r["fwd"], r["bwd"])]
    best = int(np.argmin(rollout))
    (k0, m0), (k1, m1) = r["memory"][0], r["memory"][-1]
    per_step = 2**20 * (m1 - m0) / (k1 - k0)  # bytes
    ms = lambda times: f"{1e3 * min(times) / k:>8.1f} {spread(times):>4.0f}%"  # noqa: E731
    line = (f"{n:>6} | {k:>3} | {ms(r['fwd'])} | {ms(r['bwd'])} | {ms(rollout)} | "
            f"{r['bwd'][best] / r['fwd'][best]:>7.2f} | {r['peak_rss']:>7.0f} {r['peak_rss'] - r['rss_init']:>7.0f} | "
            f"{' '.join(f'{m:>5.0f}' for _, m in r['memory'])} | {per_step / 2**20:>7.2f} {per_step / n:>6.0f} | "
            f"{str(r['finite']):>6} | ")
    return head + line + comparison(r, ours, lambda x: min(f + b for f, b in zip(x["fwd"], x["bwd"])))


def print_tables(cases, results, args):
    """The forward table, then the fwd+bwd table, then notes."""
    forward = [c for c in cases if not c.startswith("grad-")]
    grad = [c for c in cases if c.startswith("grad-")]
    if forward:
        header = (f"{'case':>15} | {'engine':>12} | {'N':>7} | {'ms/substep':>14} | {'p·substep/s':>10} | "
                  f"{'RSS MiB':>7} {'sim MiB':>7} | {'first':>6} | {'finite':>6} | {'G / us':>7} | {'RSS G/us':>6} | "
                  f"{'max |Δx|':>8}")
        print(f"\nforward, {args.precision}-bit: best of {args.repeats}, spread (worst − best) / best; "
              f"first = import + init + build + first step (s, warm cache)")
        print(header + "\n" + "-" * len(header))
        for case in forward:
            ours = results[case].get("ours")
            for engine in ("ours", "genesis"):
                if engine in results[case]:
                    print(forward_row(engine, case, results[case][engine], ours if engine == "genesis" else None))
    if grad:
        header = (f"{'case':>18} | {'engine':>12} | {'N':>6} | {'K':>3} | {'fwd ms/step':>14} | "
                  f"{'bwd ms/step':>14} | {'fwd+bwd ms/step':>14} | {'bwd/fwd':>7} | {'RSS MiB':>7} {'sim MiB':>7} | "
                  f"{'peak MiB K,2K,4K':>17} | {'MiB/stp':>7} {'B/p':>6} | {'finite':>6} | {'G / us':>7} | {'RSS G/us':>6} | "
                  f"{'Δgrad':>8}")
        print(f"\nforward + backward (loss into v0), {args.precision}-bit: best of {args.repeats}; peak MiB: a "
              f"rollout's peak RSS above the RSS before it at horizons {', '.join(f'{k}K' for k in MEMORY_HORIZONS)}; "
              f"MiB/stp = its slope per step, B/p per particle per step")
        print(header + "\n" + "-" * len(header))
        for case in grad:
            ours = results[case].get("ours")
            for engine in ("ours", "genesis"):
                if engine in results[case]:
                    print(grad_row(engine, case, results[case][engine], ours if engine == "genesis" else None))


def save_json(path, results):
    """``results`` without the arrays, as JSON."""
    plain = {case: {engine: {k: v for k, v in r.items() if k != "array"} for engine, r in per.items()}
             for case, per in results.items()}
    with open(path, "w") as file:
        json.dump(plain, file, indent=1)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", choices=["ours", "genesis"])
    parser.add_argument("--cases", nargs="+", choices=CASES, default=CASES)
    parser.add_argument("--precision", choices=["32", "64"], default="32")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--horizon", type=int, default=10, help="K, steps of a differentiable rollout")
    parser.add_argument("--json", help="also write the results (no arrays) to this file")
    parser.add_argument("--no-first-step", action="store_true", help="skip the time-to-first-step processes")
    parser.add_argument("--worker", nargs=4, metavar=("ENGINE", "MODE", "CASE", "OUT"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        return worker(*args.worker[:3], args, args.worker[3])

    pythons = {"ours": sys.executable, "genesis": genesis_python()}
    engines = [args.only] if args.only else ["ours", "genesis"]
    print(f"MPM bench: dt {DT} s, {SUBSTEPS} substeps, grid {GRID_DENSITY}/m over {LOWER}–{UPPER}, "
          f"{os.cpu_count()} CPUs; Genesis: {pythons['genesis'] or 'not installed (set GENESIS_PYTHON)'}", flush=True)
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for case in args.cases:
            results[case] = {}
            for engine in engines:
                if pythons[engine] is None:
                    continue
                t0 = time.perf_counter()
                results[case][engine] = run_case(pythons[engine], engine, case, args, tmp)
                print(f"  {case} {engine}: {time.perf_counter() - t0:.0f} s", flush=True)
    print_tables(args.cases, results, args)
    versions = {e: r.get("version") for per in results.values() for e, r in per.items() if "version" in r}
    print("versions: " + ", ".join(f"{e} {v}" for e, v in versions.items()))
    if args.json:
        save_json(args.json, results)


if __name__ == "__main__":
    main()
