"""gs.init and gs.destroy: the backend actually started decides torch's device, a missing GPU
gives one warning and the CPU for both, no path hands device memory to CPU kernels, and kernels
are compiled without fast math; torch's OpenMP threads wait passively unless the user says otherwise."""
import gc
import importlib
import logging
import os
import subprocess
import sys
import types
import weakref

import numpy as np
import pytest
import taichi as ti
import torch

import genesis_lite as gs
from genesis_lite.solvers.launch import BoundKernel
from tests.conftest import asset


def _warnings(caplog):
    return [r for r in caplog.records if r.levelno == logging.WARNING and r.name == "genesis_lite"]


def _pendulum():
    """Without self-collision: no contact pairs, so no contact kernels to load again after each
    restart of the runtime here."""
    scene = gs.Scene(rigid_options=gs.options.RigidOptions(enable_self_collision=False))
    robot = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True))
    scene.build()
    return scene, robot


def test_gpu_without_cuda_warns_once_and_runs_on_cpu(caplog, monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    gs.destroy()
    with caplog.at_level(logging.WARNING, logger="genesis_lite"):
        gs.init(backend=gs.gpu, precision="64")
    assert len(_warnings(caplog)) == 1 and "CUDA is not available" in _warnings(caplog)[0].getMessage()
    assert gs.runtime.arch == ti.cpu and gs.device == torch.device("cpu")
    scene, robot = _pendulum()
    scene.step()
    assert robot.get_dofs_position().device.type == "cpu"


def test_taichi_falling_back_to_cpu_decides_torch_device(caplog, monkeypatch):
    """torch sees CUDA but Taichi cannot start it (here: no driver): both run on the CPU."""
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(importlib.import_module("genesis_lite.runtime"), "is_arch_supported", lambda arch: True)
    gs.destroy()
    with caplog.at_level(logging.WARNING, logger="genesis_lite"):
        gs.init(backend=gs.gpu, precision="64")
    if gs.runtime.arch == ti.cuda:  # a machine with a working GPU
        assert gs.device.type == "cuda"
        return
    assert gs.device == torch.device("cpu")
    assert len(_warnings(caplog)) == 1


def test_default_backend_on_a_cpu_machine_is_quiet(caplog, monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    gs.destroy()
    with caplog.at_level(logging.WARNING, logger="genesis_lite"):
        gs.init(precision="64")
    assert not _warnings(caplog)
    assert gs.device == torch.device("cpu")


def test_kernels_refuse_memory_of_another_device(f64):
    """Every launch checks each tensor against the arch its kernel was compiled for: here the
    compiled entry is marked as CUDA code, and a CPU tensor is refused before any launch."""
    scene, _ = _pendulum()
    kernel = scene.sim.slots[0].solver.kernels.read_state
    out = torch.zeros(1, 4, dtype=torch.float64)
    kernel(0, out)  # compiles
    assert isinstance(kernel, BoundKernel) and kernel.compiled
    for key, (program, compiled, code, _) in list(kernel.compiled.items()):
        kernel.compiled[key] = (program, compiled, code, True)
    kernel.last = None  # a repeat of the last call (same program, same tensors) would launch unchecked
    try:
        with pytest.raises(gs.InvalidInputError, match="argument 6 must be a tensor on cuda, got one on cpu"):
            kernel(0, out)
    finally:
        for key, (program, compiled, code, _) in list(kernel.compiled.items()):
            kernel.compiled[key] = (program, compiled, code, False)
    with pytest.raises(gs.InvalidInputError, match="argument 6 must be a contiguous tensor"):
        kernel(0, torch.zeros(4, 2, dtype=torch.float64)[:, :1].t())


@ti.kernel
def _write_scalars(offset: ti.template(), arena: ti.types.ndarray(), s: ti.i32, k: ti.i32):
    for _ in range(1):
        arena[s] = k + offset


@ti.kernel
def _copy_element(offset: ti.template(), arena: ti.types.ndarray(), out: ti.types.ndarray(), s: ti.i32):
    for _ in range(1):
        out[0] = arena[s] + offset


def test_repeated_launches_take_each_calls_arguments(f64):
    """A BoundKernel reuses launch contexts (per scalar-argument tuple; the last call's tensors):
    every call still runs with its own arguments, in any order of repeats and changes."""
    arena = torch.zeros(4, dtype=torch.float64)
    write = BoundKernel(_write_scalars, 10, [arena], [0])
    assert write.scalars_only
    for s, k in [(0, 1), (1, 2), (0, 3), (0, 3), (2, 4), (1, 5), (1, 5), (0, 6)]:
        write(s, k)
        assert arena[s] == k + 10, (s, k, arena)
    assert arena.tolist() == [16.0, 15.0, 14.0, 0.0]
    copy = BoundKernel(_copy_element, 100, [arena], [0])
    assert not copy.scalars_only
    a, b = torch.zeros(1, dtype=torch.float64), torch.zeros(1, dtype=torch.float64)
    for out, s in [(a, 0), (a, 0), (b, 1), (b, 1), (a, 1), (a, 2), (b, 2), (b, 0)]:
        out.zero_()
        copy(out, s)
        assert out[0] == arena[s] + 100, (s, out)
    # a tensor of another dtype is another compiled kernel; each call still writes its own output
    c = torch.zeros(1, dtype=torch.float32)
    for out, s in [(c, 0), (a, 1), (c, 2), (c, 1), (b, 0)]:
        out.zero_()
        copy(out, s)
        assert out[0] == arena[s] + 100, (s, out)
    # a new tensor where the last call had another is checked as on a first call
    with pytest.raises(gs.InvalidInputError, match="argument 1 must be a contiguous tensor"):
        copy(torch.zeros(2, 2, dtype=torch.float64)[:, :1].t()[0], 0)


def test_destroy_ends_scenes_and_init_starts_again(f64):
    scene, robot = _pendulum()
    scene.step()
    unbuilt = gs.Scene()
    unbuilt.add_entity(gs.morphs.Box())
    gs.destroy()
    with pytest.raises(gs.SceneStateError, match="gs.init"):
        scene.step()
    with pytest.raises(gs.SceneStateError, match="gs.init"):
        gs.Scene()
    with pytest.raises(gs.SceneStateError, match="scene.build: call gs.init"):  # (an AttributeError)
        unbuilt.build()
    gs.destroy()  # twice is harmless
    gs.init(precision="64")
    scene, robot = _pendulum()
    scene.step()
    assert torch.isfinite(robot.get_dofs_position()).all()


def test_destroy_after_a_scene_whose_options_raised(f64):
    """A scene whose constructor raised is no scene gs.destroy ends (it was tracked before its
    fields were set: destroy raised AttributeError and left Taichi running)."""
    with pytest.raises(gs.InvalidInputError) as raised:
        gs.Scene(show_viewer=True)
    gs.destroy()  # the traceback in ``raised`` keeps the half-made scene alive
    assert raised.value is not None
    gs.init(precision="64")


def test_a_failed_restart_leaves_no_half_runtime(f64, monkeypatch):
    """gs.init with other options stops Taichi before starting it again: a start that fails there
    leaves the runtime uninitialised (it was left marked as the old one, so the next gs.init with
    those options did nothing and a build met a stopped Taichi)."""
    def refuse(*args, **kwargs):
        raise RuntimeError("no backend")

    monkeypatch.setattr(ti, "init", refuse)
    with pytest.raises(RuntimeError, match="no backend"):
        gs.init(precision="32")
    monkeypatch.undo()
    with pytest.raises(gs.SceneStateError, match="gs.init"):
        gs.Scene()
    gs.init(precision="64")
    scene, robot = _pendulum()
    scene.step()
    assert torch.isfinite(robot.get_dofs_position()).all()


def test_a_build_frees_the_dropped_scenes_once_they_hold_enough(f64, monkeypatch):
    """A dropped scene is freed by Python's cycle collector (it and its entities refer to each other),
    which counts objects, not bytes: a loop rebuilding a large scene kept every dead one. A build
    collects once the built scenes hold COLLECT_AFTER_BYTES more than after the last collection; scenes
    kept alive move that mark, so they do not make every later build collect."""
    rt = importlib.import_module("genesis_lite.runtime")  # (gs.runtime is the runtime object)
    footprint = _pendulum()[0]._held_bytes()
    assert footprint > 0
    gc.collect()
    collections = []
    monkeypatch.setattr(rt, "gc", types.SimpleNamespace(collect=lambda: collections.append(gc.collect())))
    monkeypatch.setattr(rt, "_held_after_collection", rt._held_bytes())
    monkeypatch.setattr(rt, "COLLECT_AFTER_BYTES", 2.5 * footprint)
    gc.disable()
    try:
        dropped = [weakref.ref(_pendulum()[0]) for _ in range(4)]  # the fourth build collects the first three
        assert len(collections) == 1 and [ref() is None for ref in dropped] == [True] * 3 + [False]
        kept = [_pendulum()[0] for _ in range(6)]
        assert len(collections) == 3  # building the 3rd and the 6th: the mark follows the scenes kept
        assert all(scene._held_bytes() == footprint for scene in kept)
        for scene in kept:
            scene.destroy()  # (holds nothing more: the mark comes down)
        dropped = [weakref.ref(_pendulum()[0]) for _ in range(4)]
        assert len(collections) == 4 and [ref() is None for ref in dropped] == [True] * 3 + [False]
    finally:
        gc.enable()


@ti.kernel
def _running_sum(x: ti.types.ndarray(), out: ti.types.ndarray()):
    for i in range(1):
        total = 0.0
        for k in range(x.shape[0]):
            total += x[k]
        out[0] = total


def test_destroyed_scene_says_it_was_destroyed(f64):
    scene = gs.Scene()
    scene.add_entity(gs.morphs.Box())
    scene.build()
    gs.destroy()
    with pytest.raises(gs.SceneStateError, match="scene.step: the scene was destroyed .*gs.destroy"):
        scene.step()
    gs.init(precision="64", logging_level="warning")


def test_kernels_never_reassociate(f64):
    """gs.init compiles without fast math, so a running sum adds in program order, as IEEE
    says: LLVM may not split it into vector lanes (4 doubles with AVX2, 8 with AVX-512, and
    differently for the serial and the parallel compilation of a loop). That is the ground of
    batched = single env bit for bit on any CPU. With fast math on, this test fails here (the sum
    differs in its last bits)."""
    rng = np.random.default_rng(1)
    values = rng.uniform(-1, 1, 257) * 10.0 ** rng.integers(-8, 9, 257)
    in_order = 0.0
    for v in values:
        in_order += v
    out = torch.zeros(1, dtype=torch.float64)
    _running_sum(torch.tensor(values), out)
    assert out.item() == in_order, f"the kernel summed out of order: {out.item()!r} != {in_order!r}"


# -- solvers/taichi_startup.py: start-up costs removed, Taichi's behaviour kept -----------------------
@ti.func
def _misspelt(x):
    return x + undefined_name  # noqa: F821  (the compile error under test)


def test_compile_error_names_file_line_and_source(f64):
    """Taichi's source positions, written without text wrapping, still say where an error is: the
    file, the line, the function and the source line with a caret under the culprit."""
    @ti.kernel
    def calls_misspelt() -> ti.f64:
        return _misspelt(1.0)

    with pytest.raises(ti.TaichiCompilationError) as error:
        calls_misspelt()
    message = str(error.value)
    line = 1 + open(__file__).read().split("\n").index("    return x + undefined_name  # noqa: F821  (the compile error under test)")
    assert f'{__file__}", line {line}, in _misspelt' in message
    assert "return x + undefined_name" in message and "^^^^^^^^^^^^^^" in message


@ti.func
def _twice(x):
    return 2.0 * x


def test_an_inlined_functions_lines_are_wrapped_once(f64):
    """The transform passes a ti.func's source lines through textwrap.fill at every inlining;
    taichi_startup remembers each line's: inlining _twice a second time is all hits, no new miss
    for its lines, and the kernel computes as before."""
    from taichi.lang import kernel_impl

    @ti.kernel
    def quadruple(x: ti.f64) -> ti.f64:
        return _twice(_twice(x))

    before = kernel_impl.textwrap.fill.cache_info()
    assert quadruple(1.5) == 6.0
    after = kernel_impl.textwrap.fill.cache_info()
    assert after.hits - before.hits >= 3 and after.misses - before.misses <= 4 + 3  # (the kernel's lines, _twice's once)


@ti.data_oriented
class _Counter:
    def __init__(self):
        self.total = ti.field(ti.i32, shape=())

    @ti.kernel
    def add(self, n: ti.i32):
        self.total[None] += n


def test_kernels_defined_in_classes_still_bind_to_their_instance(f64):
    """Taichi tells a kernel defined in a class body from a module-level one by reading its caller's
    frame (the lookup taichi_startup makes fast): a data-oriented class's kernel binds to its
    instance, a module-level kernel runs as a plain function."""
    counter = _Counter()
    counter.add(3)
    counter.add(4)
    assert counter.total[None] == 7


_CODEGEN_OPTIONS = """
import ctypes, sys
import genesis_lite as gs
from genesis_lite.solvers import taichi_startup
library = sys.modules["taichi._lib.core.taichi_python"]
names = ("PyInit_taichi_python", "_ZL10DisableLSR", "_ZL28DisableX86DomainReassignment", "_ZL21EnablePostRAScheduler")
values = taichi_startup._symbol_values(library.__file__, names)
base = ctypes.cast(ctypes.CDLL(library.__file__).PyInit_taichi_python, ctypes.c_void_p).value - values[names[0]][0]
option = lambda: [ctypes.string_at(base + values[name][0], 64) for name in names[1:]]  # (the cl::opt<bool>s)
before = option()
{init}
first = option()
gs.init(backend=gs.cpu, precision="64"); gs.destroy(); gs.init(backend=gs.cpu, precision="32")
print(all(a != b for a, b in zip(first, before)), option() == first)
"""


def _taichi_symbols(*names):
    """The values of ``names`` in Taichi's library's symbol table; the test skips where the library
    is no ELF with one (another platform, a stripped build: genesis_lite then skips nothing)."""
    from genesis_lite.solvers import taichi_startup

    values = taichi_startup._symbol_values(sys.modules["taichi._lib.core.taichi_python"].__file__, names)
    if len(values) != len(names):
        pytest.skip("Taichi's library has no ELF symbol table with these symbols")
    return values


def test_cpu_runtime_skips_code_generation_passes():
    """gs.init on the CPU sets LLVM's -disable-lsr, -disable-x86-domain-reassignment and
    -post-RA-scheduler=false inside Taichi's library (loading cached kernels 3-5× faster): each
    option's object in the library's memory changes at the first start and stays as it is through
    later starts (the options are given once a process)."""
    _taichi_symbols("PyInit_taichi_python", "_ZL10DisableLSR", "_ZL28DisableX86DomainReassignment",
                    "_ZL21EnablePostRAScheduler", "LLVMParseCommandLineOptions")
    code = _CODEGEN_OPTIONS.format(init="gs.init(backend=gs.cpu)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split()[-2:] == ["True", "True"]


def test_symbol_table_reader(tmp_path):
    """The ELF reader finds Taichi's exported and hidden symbols at the addresses the library has
    (the exported one checked against the dynamic loader), and nothing in a file that is no ELF."""
    from genesis_lite.solvers import taichi_startup

    library = sys.modules["taichi._lib.core.taichi_python"]
    names = ("PyInit_taichi_python", "LLVMParseCommandLineOptions", "_ZL10DisableLSR", "no_such_symbol_anywhere")
    _taichi_symbols(*names[:3])
    values = taichi_startup._symbol_values(library.__file__, names)
    assert sorted(values) == sorted(names[:3])
    assert values["PyInit_taichi_python"][0] != values["LLVMParseCommandLineOptions"][0]
    assert values["_ZL10DisableLSR"][1] is None  # (.bss: no bytes in the file)
    assert taichi_startup._loaded_entry(library.__file__) is not None  # (the file is the loaded library)
    not_elf = tmp_path / "not_elf.so"
    not_elf.write_bytes(b"#!/bin/sh\n" * 20)
    assert taichi_startup._symbol_values(str(not_elf), names) == {}


@pytest.mark.parametrize("preset", [None, "ACTIVE"])
def test_torch_openmp_threads_wait_passively_unless_set(preset):
    """Importing genesis_lite (first, as libgomp reads the policy when torch loads it) sets
    OMP_WAIT_POLICY=PASSIVE, so that torch's threads do not spin on the cores of the next Taichi
    kernel; a policy already set is kept."""
    env = {key: value for key, value in os.environ.items() if key != "OMP_WAIT_POLICY"}
    if preset:
        env["OMP_WAIT_POLICY"] = preset
    code = "import genesis_lite, os; print(os.environ['OMP_WAIT_POLICY'])"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.strip().splitlines()[-1] == (preset or "PASSIVE")


@pytest.mark.parametrize("collecting", [True, False])
def test_the_import_leaves_the_garbage_collector_as_it_found_it(collecting):
    """The import runs with the collector off (its full passes over torch's objects took a third of
    it) and turns it back on only if it was on, without a name left behind."""
    code = (f"import gc, torch; {'' if collecting else 'gc.disable(); '}import genesis_lite; "
            "print(gc.isenabled(), hasattr(genesis_lite, '_collecting'))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip().splitlines()[-1] == f"{collecting} False"


def test_gs_logger_is_genesis_lite_s_logger(caplog):
    """gs.logger (Genesis's examples log through it): the 'genesis_lite' logger, Genesis's calls."""
    with caplog.at_level(logging.INFO, logger="genesis_lite"):
        gs.logger.info("from a script")
        gs.logger.warning("careful")
    assert [record.getMessage() for record in caplog.records][-2:] == ["from a script", "careful"]
    assert all(callable(getattr(gs.logger, name)) for name in ("debug", "info", "warning", "error", "critical"))
