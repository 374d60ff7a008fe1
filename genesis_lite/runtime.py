"""Process-wide runtime: Taichi initialisation, torch device and float dtypes.

``gs.init`` may be called again with other options: Taichi is then restarted and every
scene built before becomes unusable (using it raises :class:`SceneStateError`).
"""
import atexit
import ctypes
import gc
import logging
import weakref

import numpy as np
import taichi as ti
import torch
from taichi.lang import impl
from taichi.lang.misc import is_arch_supported

from .options import check_bool
from .solvers.core import MMAP_THRESHOLD, InvalidInputError, SceneStateError, runtime
from .solvers.launch import forget as forget_kernels
from .solvers.taichi_startup import skip_code_generation_passes

cpu = "cpu"
gpu = "gpu"

_LOG_LEVELS = {"debug": ti.DEBUG, "info": ti.INFO, "warning": ti.WARN, "error": ti.ERROR}


logger = logging.getLogger("genesis_lite")
_scenes = weakref.WeakSet()  # the scenes of the running runtime: ending it ends them


def track(scene):
    """Register a new scene: gs.destroy, a restarting gs.init and the interpreter's exit end it."""
    _scenes.add(scene)


# A scene and its entities refer to each other (entity.scene, as Genesis's), so a scene the user
# drops is freed by Python's cycle collector, which runs by counts of objects made, not by bytes:
# a loop rebuilding a 60 MiB MPM scene held every dead one (+815 MiB after 12 builds). So a build
# collects when the built scenes not destroyed hold this much more than after the last collection
# (a full collection took 0.1–0.15 s here after a scene's compiles; scenes kept alive on purpose only
# move the mark).
COLLECT_AFTER_BYTES = 256 << 20
_held_after_collection = 0


def free_dropped_scenes():
    """Before a scene allocates: collect the dropped scenes once they may hold COLLECT_AFTER_BYTES."""
    global _held_after_collection
    held = _held_bytes()
    _held_after_collection = min(_held_after_collection, held)  # (scenes destroyed since lower the mark)
    if held > _held_after_collection + COLLECT_AFTER_BYTES:
        gc.collect()
        _held_after_collection = _held_bytes()


def _held_bytes():
    return sum(scene._held_bytes() for scene in list(_scenes))


def _end_scenes():
    """Destroy every live scene (arrays freed, the cameras' recordings finished), as Genesis's
    gs.destroy does; every one, then the first error (a video file that could not be written)."""
    errors = []
    for scene in list(_scenes):
        if not scene._destroyed:
            try:
                scene.destroy()
            except Exception as exc:
                errors.append(exc)
    _scenes.clear()
    return errors


@atexit.register
def _finish_recordings():
    """At exit, finish the cameras' streamed recordings (a writer thread still held frames: the
    last ones were lost); Taichi itself is left to its own exit."""
    for scene in list(_scenes):
        scene._finish_recordings()


def init(backend=None, precision="32", seed=None, logging_level="warning", debug=False, *, eps=1e-15, theme="dark",
         logger_verbose_time=False, performance_mode=False, use_deterministic_algorithms=None):
    """Start the simulator runtime.

    backend: ``gs.cpu``, ``gs.gpu`` (CUDA; without it, one warning and the CPU), or None, as in
        Genesis: the GPU when CUDA is present, else the CPU.
    precision: "32" or "64" — the float width of every array and every returned tensor.
    seed: an int in [0, 2**32): seeds torch and numpy, and the MPM "random" sampler's draws (each
        entity's from the seed and the entity's index; without a seed, from the index alone, so that
        a scene samples the same particles in every run).
    debug: Taichi debug mode (bounds checks; slow).
    Genesis's other arguments are taken for its scripts, checked, with nothing to change here:
    theme and logger_verbose_time style Genesis's coloured log (this one logs plain lines);
    performance_mode picks how Genesis compiles its kernels (faster runs, slower compiles; ours
    compile one way); use_deterministic_algorithms (None, True or False): ours are deterministic
    always (the same bits on every run, thread count and x86-64 CPU). eps, Genesis's epsilon of
    its geometry, only at its default 1e-15 (the kernels' tolerances here are their own).

    Kernels are compiled without fast math: no reassociation or contraction, so a kernel gives
    the same bits whether its env loop runs on one thread or many, on any x86-64 CPU (batched
    scenes equal single-env ones bit for bit). They are also compiled without Taichi's CFG
    optimisation, whose cost grows superlinearly on the convex colliders (a kernel with
    collision/convex.py compiled in 156 s with it, 11 s without); measured on the CPU, the
    kernels run as fast without it and compile ~40 % faster. torch's device is always the one of
    the arch Taichi actually started on.
    """
    precision = str(precision)
    if precision not in ("32", "64"):
        raise InvalidInputError(f"gs.init: argument 'precision' must be '32' or '64', got {precision!r}")
    if backend not in (None, cpu, gpu):
        raise InvalidInputError(f"gs.init: argument 'backend' must be gs.cpu, gs.gpu or None, got {backend!r}")
    if logging_level not in _LOG_LEVELS:
        raise InvalidInputError(
            f"gs.init: argument 'logging_level' must be one of {sorted(_LOG_LEVELS)}, got {logging_level!r}")
    check_bool("gs.init", "debug", debug)
    _check_genesis_extras(eps, theme, logger_verbose_time, performance_mode, use_deterministic_algorithms)
    if seed is not None:
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**32:
            raise InvalidInputError(f"gs.init: argument 'seed' must be None or an int in [0, 2**32), got {seed!r}")
        torch.manual_seed(int(seed))
        np.random.seed(int(seed))
    runtime.seed = None if seed is None else int(seed)
    logger.setLevel(logging_level.upper())
    arch = _requested_arch(backend)
    options = (arch, precision, bool(debug))
    if runtime.initialized and runtime.options == options:
        return
    if runtime.initialized:
        for error in _end_scenes():  # (the restart goes on: the old scenes are over either way)
            logger.warning(f"gs.init: ending a scene of the runtime before: {type(error).__name__}: {error}")
        forget_kernels()
        ti.reset()
        runtime.initialized = False  # (until ti.init succeeds: a failed start is not the old runtime)
    ti_float = ti.f64 if precision == "64" else ti.f32
    ti.init(arch=arch, default_fp=ti_float, default_ip=ti.i32, debug=debug, fast_math=False, cfg_optimization=False,
            log_level=_LOG_LEVELS[logging_level], offline_cache=True)
    runtime.arch = impl.current_cfg().arch  # Taichi falls back to the CPU when CUDA fails to start
    if runtime.arch == ti.cpu:
        skip_code_generation_passes()  # loading cached kernels 3-5× faster (taichi_startup.py)
    if backend == gpu and runtime.arch != ti.cuda:
        logger.warning("gs.init: gs.gpu requested but CUDA is not available; running on the CPU")
    runtime.device = torch.device("cuda" if runtime.arch == ti.cuda else "cpu")
    runtime.initialized = True
    runtime.options = options
    runtime.epoch += 1
    runtime.ti_float = ti_float
    runtime.tc_float = torch.float64 if precision == "64" else torch.float32
    runtime.np_float = np.float64 if precision == "64" else np.float32


def _check_genesis_extras(eps, theme, logger_verbose_time, performance_mode, use_deterministic_algorithms):
    """gs.init's Genesis-only arguments (see init): their types, and eps at Genesis's default."""
    check_bool("gs.init", "logger_verbose_time", logger_verbose_time)
    check_bool("gs.init", "performance_mode", performance_mode)
    if use_deterministic_algorithms is not None:
        check_bool("gs.init", "use_deterministic_algorithms", use_deterministic_algorithms)
    if theme not in ("dark", "light", "raw"):  # (Genesis's styles.THEME)
        raise InvalidInputError(f"gs.init: argument 'theme' must be 'dark', 'light' or 'raw', got {theme!r}")
    if isinstance(eps, bool) or not isinstance(eps, (int, float, np.floating)) or eps != 1e-15:
        raise InvalidInputError(f"gs.init: argument 'eps' other than Genesis's default 1e-15 is not supported "
                                f"(the kernels' tolerances are their own), got {eps!r}")


def _requested_arch(backend):
    """CUDA only when torch can use it too (torch's tensors are the kernels' arguments), and Taichi
    was built with it; else the CPU. Asked in this order: Taichi's check warns without a driver."""
    if backend != cpu and torch.cuda.is_available() and is_arch_supported(ti.cuda):
        return ti.cuda
    return ti.cpu


def destroy():
    """End the runtime (Genesis's ``gs.destroy``): every scene is destroyed (its cameras' streamed
    recordings finished) and becomes unusable (using one raises SceneStateError), Taichi stops,
    and ``gs.init`` may be called again."""
    if runtime.initialized:
        errors = _end_scenes()
        forget_kernels()
        ti.reset()
        runtime.initialized = False
        runtime.options = None
        runtime.epoch += 1
        if errors:
            raise errors[0]


def keep_large_blocks_off_the_heap():
    """Fix glibc malloc's mmap threshold at its default (128 KiB); called once a differentiable
    scene is built. Each time a large block is freed glibc raises the threshold (up to 32 MiB),
    after which per-step states (~0.1–10 MB) come from the heap, where the small long-lived
    allocations made between them (the graph's step records, inputs) pin the freed holes: a checkpointed
    rollout's RSS then grew by one state per step as if nothing were freed (1000 MPM particles,
    float64, checkpoint_interval 100: 196 KB a step; with the threshold fixed, 2.9 KB). Process-
    wide, as malloc is: blocks of 128 KiB and more are mapped and unmapped, as before glibc's first
    adjustment, so a hot path should not allocate one a step (the rigid solver keeps its packed
    inputs' buffers: RigidSolver._pack_inputs). Nothing happens off glibc."""
    global _threshold_fixed
    if _threshold_fixed:
        return
    _threshold_fixed = True
    try:
        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)
    except (OSError, AttributeError):
        pass


_M_MMAP_THRESHOLD = -3  # glibc's malloc.h
_threshold_fixed = False


def require_init(what):
    """Raise a clear error when ``gs.init`` has not been called before ``what``."""
    if not runtime.initialized:
        raise SceneStateError(f"{what}: call gs.init() first")
