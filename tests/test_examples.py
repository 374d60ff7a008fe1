"""Examples double as tests: each runs in its short mode and ends with its own check."""
import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLES = ["quickstart.py", "trajectory_optimization.py", "system_identification.py", "policy.py"]


@pytest.mark.parametrize("name", EXAMPLES)
def test_example_short(name):
    result = subprocess.run([sys.executable, os.path.join(ROOT, "examples", name), "--short"], cwd=ROOT,
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, f"{name} failed:\n{result.stdout[-3000:]}\n{result.stderr[-3000:]}"
