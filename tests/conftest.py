"""Shared fixtures: runtime precision and the robots we test on."""
import contextlib
import logging
import os
import re
import runpy
import shutil
import sys
import tempfile

import pybullet_data
import pytest

import genesis_lite as gs
from genesis_lite.solvers import launch
from genesis_lite.solvers.core import runtime

ASSETS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "assets")
PYBULLET = pybullet_data.getDataPath()


def asset(*parts):
    return os.path.join(ASSETS, *parts)


def pybullet(*parts):
    return os.path.join(PYBULLET, *parts)


FIRST = ("test_examples.py",)  # the longest file: started right after the float32 group
# batches past data.SERIAL_SOLVE_WORK: the thread-pool variants of the constraint solve and its
# reverse (~20 s of LLVM a worker, warm cache) load on one worker only; dealt out after FIRST
POOL = ("test_batch.py", "test_compile_once.py")
LAST = ("test_runtime.py",)  # restarts the runtime (gs.destroy, gs.init on another backend)
FLOAT32 = "float32"  # the xdist group of every float32 test
RESTARTS = "restarts"  # the mark of a test that restarts Taichi while it runs (gs.init with other options, gs.destroy)


def _file(item):
    """The test's file name."""
    return os.path.basename(str(item.fspath))


def _float32(item):
    """Whether the test runs in float32: on the f32 fixture, marked float32, or parametrized with
    precision "32"."""
    callspec = getattr(item, "callspec", None)
    return ("f32" in getattr(item, "fixturenames", ()) or item.get_closest_marker(FLOAT32) is not None
            or (callspec is not None and callspec.params.get("precision") == "32"))


def pytest_configure(config):
    """The asset cache (solvers/asset_cache.py) in a folder of the run's own (each xdist worker's):
    tests neither read what other runs or versions left there nor fill the user's. The constraint
    solve and its reverse compile at Taichi's opt_level 0 (launch.SOLVE_OPT_LEVEL): half the compile
    time of a cold suite went to them at 1, the users' level, which runs them faster and computes
    the same bits in the variants the slow
    test_light_kernels_compute_the_same_bits_at_taichi_default_opt_level runs (the suite runs the
    others at 0 only)."""
    launch.SOLVE_OPT_LEVEL = 0
    folder = tempfile.mkdtemp(prefix="genesis_lite_assets_")
    os.environ["GENESIS_LITE_CACHE_DIR"] = folder
    config.add_cleanup(lambda: shutil.rmtree(folder, ignore_errors=True))


@pytest.hookimpl(tryfirst=True)  # before xdist's hook, which names a group's tests by their mark
def pytest_collection_modifyitems(items):
    """Every float32 test in one group (xdist_group), run first; then FIRST's tests, POOL's (one
    group), the other files, and LAST; in each group the tests marked RESTARTS last. A change of
    precision restarts Taichi (gs.init), and every kernel the worker uses next pays LLVM's code
    generation again (15-20 s for `constrain` alone, warm cache); a kernel one worker compiles
    reaches the disk cache only when its Taichi stops, so float32 tests spread over both workers
    compiled the float32 kernels in each. Two restarts amid the float32 group made that worker
    load the float32 contact kernels three times (the suite: 4:18-4:51 → 3:51, measured)."""
    items.sort(key=lambda item: (not _float32(item), item.get_closest_marker(RESTARTS) is not None,
                                 _file(item) not in FIRST, _file(item) not in POOL, _file(item) in LAST))
    for item in items:
        if _float32(item):
            item.add_marker(pytest.mark.xdist_group(FLOAT32))
        elif _file(item) in POOL:
            item.add_marker(pytest.mark.xdist_group("pool"))
        elif item.get_closest_marker(RESTARTS) is not None and _file(item) not in LAST:
            item.add_marker(pytest.mark.xdist_group(RESTARTS))  # a unit dealt out last, not amid its file's


@pytest.hookimpl(wrapper=True)
def pytest_runtest_call(item):
    """A test that restarts Taichi more than once while it runs, or leaves it with other options
    than its group's (or stopped), must be marked RESTARTS (or be in LAST), so that it runs where
    that costs nothing: the suite would otherwise slow down unseen. (One switch to the test's own
    precision is a fixture's work done in the test body.) Checked only when the test passed: a
    failure keeps its own report."""
    epoch = runtime.epoch
    result = yield
    restarts = runtime.epoch - epoch
    options = runtime.options[1:] if runtime.initialized else None  # (precision, debug)
    if (restarts > 1 or (restarts == 1 and options != ("32" if _float32(item) else "64", False))) \
            and item.get_closest_marker(RESTARTS) is None and _file(item) not in LAST:
        pytest.fail(f"{item.nodeid} restarted Taichi {restarts} times and left it with (precision, debug) "
                    f"{options}: mark it @pytest.mark.{RESTARTS} (run last in its group)", pytrace=False)
    return result


@pytest.hookimpl(tryfirst=True, optionalhook=True)  # optional: pytest -p no:xdist has no such hook
def pytest_xdist_make_scheduler(config, log):
    """pyproject's --dist loadgroup, with one work unit per test file (as --dist loadfile) for the
    tests in no group, where xdist's loadgroup deals them out one by one."""
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadGroupScheduling

    class FileOrGroupScheduling(LoadGroupScheduling):
        def _split_scope(self, nodeid):
            scope = super()._split_scope(nodeid)  # the test's group, or its own nodeid in none
            return nodeid.split("::", 1)[0] if scope == nodeid else scope

    return FileOrGroupScheduling(config, log)


@contextlib.contextmanager
def warns(caplog, pattern=None):
    """The block logs a warning on the "genesis_lite" logger (every warning's channel) matching the
    regex ``pattern``, or, with None, logs none; yields the list its matching messages fill."""
    start, found = len(caplog.records), []
    yield found
    logged = [r.getMessage() for r in caplog.records[start:]
              if r.name == "genesis_lite" and r.levelno == logging.WARNING]
    if pattern is None:
        assert not logged, logged
    found += [message for message in logged if re.search(pattern, message)]
    assert pattern is None or found, f"no warning matching {pattern!r} among {logged}"


@pytest.fixture
def f64():
    gs.init(precision="64", logging_level="warning")


@pytest.fixture
def f32():
    gs.init(precision="32", logging_level="warning")


@pytest.fixture
def run_script(monkeypatch):
    """run_script(path, args): the script run inside the test process as ``python path *args``
    would (``__main__``, its folder on the path, the repository as working directory): the kernels
    it shares with other tests and scripts load once, where a process of its own paid Taichi's code
    generation again (20-60 s a script on a slow machine)."""
    def run(path, args):
        monkeypatch.chdir(os.path.dirname(ASSETS))
        monkeypatch.setattr(sys, "argv", [path, *args])
        monkeypatch.syspath_prepend(os.path.dirname(path))
        runpy.run_path(path, run_name="__main__")
    return run
