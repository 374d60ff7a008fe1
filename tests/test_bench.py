"""The benchmark scripts still run, ours only, at their smallest sizes: every one but
compile_times.py (which starts processes on empty kernel caches). A bench is not a timed test, but
one that breaks goes unnoticed: rigid_contact_grad.py read a solver attribute that had been removed
and crashed for several sessions. Peers are left out (their interpreters are unset). They run
inside the test process (conftest's run_script), and so do the workers a bench starts for our
engine (GENESIS_LITE_BENCH_INLINE, bench/mpm.py's run_json): they use the kernels the process has
loaded, and a worker's error fails the test (a worker process's only printed a line). Each runs at
the precision its workers take (FLOAT64: float64, else float32)."""
import os

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SMALLEST = {
    "rigid_contact_grad": ["--envs", "2", "--steps", "2", "--repeats", "1"],
    "rigid_contact": ["--envs", "1", "--steps", "2", "--repeats", "1"],
    "rigid_forward": ["--envs", "1", "--steps", "2", "--repeats", "1", "--skip-first-step"],
    "rigid_grad": ["--repeats", "1"],
    "kernel_times": ["--envs", "4", "--repeats", "1"],
    "render": ["--repeats", "1", "--frames", "2", "--record-frames", "2"],
    "mpm": ["--only", "ours", "--cases", "neohooken-10k", "--repeats", "1", "--no-first-step"],
    "sand_pile": ["--only", "ours", "--angles", "30", "--steps", "2", "--frictions", "5"],
    "coupling": ["--only", "ours", "--steps", "10", "--cases", "static", "box"],  # (a snapshot every 10 steps)
    "ik": ["--only", "ours", "--envs", "0", "--repeats", "1"],
    "drone": ["--only", "ours", "--envs", "0", "--repeats", "1"],
    "terrain": ["--only", "ours", "--kinds", "sloped_terrain", "--envs", "4", "--repeats", "1"],
}
FLOAT64 = ("sand_pile", "coupling", "drone")  # their workers run in float64


@pytest.mark.parametrize("name", [pytest.param(name, marks=[] if name in FLOAT64 else [pytest.mark.float32])
                                  for name in SMALLEST])
def test_bench_runs(name, run_script, monkeypatch):
    monkeypatch.delenv("GENESIS_PYTHON", raising=False)
    monkeypatch.delenv("NEWTON_PYTHON", raising=False)
    monkeypatch.setenv("GENESIS_LITE_BENCH_INLINE", "1")
    run_script(os.path.join(ROOT, "bench", f"{name}.py"), SMALLEST[name])
