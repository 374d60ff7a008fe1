"""Process-wide runtime: Taichi initialisation, torch device and float dtypes.

``gs.init`` may be called again with other options: Taichi is then restarted and every
scene built before becomes unusable (using it raises :class:`SceneStateError`).
"""
import logging

import numpy as np
import taichi as ti
import torch

from .solvers.core import InvalidInputError, SceneStateError, runtime

cpu = "cpu"
gpu = "gpu"

_LOG_LEVELS = {"debug": ti.DEBUG, "info": ti.INFO, "warning": ti.WARN, "error": ti.ERROR}


logger = logging.getLogger("genesis_lite")


def init(backend=cpu, precision="32", seed=None, logging_level="warning", debug=False):
    """Start the simulator runtime.

    backend: ``gs.cpu`` or ``gs.gpu`` (CUDA when present, else a warning and CPU).
    precision: "32" or "64" — the float width of every field and every returned tensor.
    seed: seeds torch and numpy when given.
    debug: Taichi debug mode (bounds checks; slow).
    """
    precision = str(precision)
    if precision not in ("32", "64"):
        raise InvalidInputError(f"gs.init: argument 'precision' must be '32' or '64', got {precision!r}")
    if backend not in (cpu, gpu):
        raise InvalidInputError(f"gs.init: argument 'backend' must be gs.cpu or gs.gpu, got {backend!r}")
    if logging_level not in _LOG_LEVELS:
        raise InvalidInputError(
            f"gs.init: argument 'logging_level' must be one of {sorted(_LOG_LEVELS)}, got {logging_level!r}")
    options = (backend, precision, bool(debug))
    if seed is not None:
        torch.manual_seed(seed)
        np.random.seed(seed)
    logger.setLevel(logging_level.upper())
    if runtime.initialized and runtime.options == options:
        return
    if runtime.initialized:
        ti.reset()
    arch = ti.cpu
    device = torch.device("cpu")
    if backend == gpu:
        if torch.cuda.is_available():
            arch, device = ti.cuda, torch.device("cuda")
        else:
            logger.warning("gs.init: gs.gpu requested but CUDA is not available; using the CPU")
    ti_float = ti.f64 if precision == "64" else ti.f32
    ti.init(arch=arch, default_fp=ti_float, default_ip=ti.i32, debug=debug, log_level=_LOG_LEVELS[logging_level],
            offline_cache=True)
    runtime.initialized = True
    runtime.options = options
    runtime.epoch += 1
    runtime.device = device
    runtime.ti_float = ti_float
    runtime.tc_float = torch.float64 if precision == "64" else torch.float32
    runtime.np_float = np.float64 if precision == "64" else np.float32


def require_init(what):
    """Raise a clear error when ``gs.init`` has not been called before ``what``."""
    if not runtime.initialized:
        raise SceneStateError(f"{what}: call gs.init() first")
