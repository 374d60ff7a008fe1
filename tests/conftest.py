"""Shared fixtures: runtime precision and the robots we test on."""
import os

import pybullet_data
import pytest

import genesis_lite as gs

ASSETS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "assets")
PYBULLET = pybullet_data.getDataPath()


def asset(*parts):
    return os.path.join(ASSETS, *parts)


def pybullet(*parts):
    return os.path.join(PYBULLET, *parts)


FIRST = ("test_examples.py",)  # the longest file: started first
LAST = ("test_runtime.py",)  # restarts the runtime (gs.destroy, gs.init on another backend)


def _float32(item):
    return "f32" in getattr(item, "fixturenames", ())


def pytest_collection_modifyitems(items):
    """Run FIRST's tests before the rest: the suite runs on two workers, one test file to a worker
    (pyproject's addopts), and a long file dealt out last would run alone at the end. Then the
    files without tests on the f32 fixture, those with, and LAST; in a file, the others first. A
    change of precision restarts Taichi (gs.init), and every kernel the worker uses next pays
    LLVM's optimisation and code generation again (~20 s for `constrain` on a slow machine)."""
    mixed = {item.fspath for item in items if _float32(item)}
    items.sort(key=lambda item: (os.path.basename(str(item.fspath)) not in FIRST,
                                 os.path.basename(str(item.fspath)) in LAST, item.fspath in mixed, _float32(item)))


@pytest.fixture
def f64():
    gs.init(precision="64", logging_level="warning")


@pytest.fixture
def f32():
    gs.init(precision="32", logging_level="warning")
