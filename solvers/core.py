"""What the API package and the solvers both need: the error classes, and the float
precision and device that ``gs.init`` chose. The solvers import nothing from the API package
(``genesis_lite``); imports run one way, from the API to the solvers, and the API re-exports
these names (``gs.GenesisException``, ``gs.device``...).

Every error a user can trigger is a :class:`GenesisException` subclass whose message
names the entity, the argument, what was expected and what was given.
"""
import logging
import math
import mmap
import sys

import numpy as np
import taichi as ti
import torch


class GenesisException(Exception):
    """Base class of every error genesis_lite raises on purpose."""


class InvalidInputError(GenesisException, ValueError):
    """A user-supplied value has the wrong shape, dtype, device, range or is not finite."""


class AssetError(GenesisException):
    """A file (URDF, mesh) is missing, malformed or uses something unsupported."""


class SceneStateError(GenesisException, RuntimeError):
    """The scene is used out of order (step before build, build twice, add after build...)."""


class GradientError(GenesisException, RuntimeError):
    """A gradient cannot be computed: non-differentiable path, stale graph, missing requires_grad."""


def _requires_grad(value):
    """Whether ``value`` is, or a list or tuple holds, a torch tensor that requires grad."""
    if isinstance(value, (list, tuple)):
        return any(_requires_grad(v) for v in value)
    return isinstance(value, torch.Tensor) and value.requires_grad


def refuse_grad(owner, name, value, instead):
    """Raise GradientError when ``value`` is (or a list or tuple holds) a torch tensor that requires
    grad: ``owner``'s argument ``name`` is read as plain numbers, so a graph through it would end
    there without a word; ``instead``: why, and where gradients do flow."""
    if _requires_grad(value):
        raise GradientError(f"{owner}: argument '{name}' is not differentiable, got a tensor that requires grad "
                            f"({instead}); pass it detached (.detach())")


def available_memory():
    """Bytes of memory free now (Linux's available physical pages), else None (unknown): what a
    large allocation is checked against before it is made, for a named error instead of a crash."""
    try:
        import os
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def warn_user(message):
    """A warning on the "genesis_lite" logger (every warning's channel, as Genesis logs its own;
    gs.init's logging_level silences it), ending with the user's line that led to it: the first
    caller outside genesis_lite, however many of its frames lie between."""
    frame = sys._getframe(1)
    while frame is not None and frame.f_globals.get("__name__", "").partition(".")[0] == "genesis_lite":
        frame = frame.f_back
    where = f" ({frame.f_code.co_filename}:{frame.f_lineno})" if frame is not None else ""
    logging.getLogger("genesis_lite").warning(f"{message}{where}")


class SimulationError(GenesisException, RuntimeError):
    """The simulation produced a non-finite state (raised when SimOptions(check_nan=True))."""


# glibc maps blocks of this size and more, fixed there for differentiable scenes
# (genesis_lite.runtime.keep_large_blocks_off_the_heap)
MMAP_THRESHOLD = 128 * 1024
# A step's state from this size up to MMAP_THRESHOLD may get pages of its own (new_state)
MAPPED_STATE_MIN = 16 * 1024


def new_state(shape, own_pages=False):
    """torch.empty(shape) in gs's float type and device, for a step's new state. With
    ``own_pages`` (a checkpointed differentiable scene, Solver.own_state_pages), on the CPU, a
    state of MAPPED_STATE_MIN bytes up to MMAP_THRESHOLD gets pages of its own (an anonymous
    mapping, unmapped with the tensor): from the heap, a freed state was a hole that the small
    long-lived allocations of the growing graph split, too small for the next state, so the
    rollout's memory grew by a state a step as if nothing were freed (512 MPM particles in
    float64, 100 KiB states, checkpoint_interval 100: 138 MiB over 1500 steps; mapped, 3 MiB).
    A mapping costs ~20-35 µs a state (its page faults, prefaulted at once: MAP_POPULATE), hence
    only there. Larger states glibc maps itself; smaller ones come from its bins, reused whole."""
    size = math.prod(shape) * runtime.tc_float.itemsize
    if not own_pages or runtime.device.type != "cpu" or not MAPPED_STATE_MIN <= size < MMAP_THRESHOLD:
        return torch.empty(shape, dtype=runtime.tc_float, device=runtime.device)
    pages = mmap.mmap(-1, size, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS | getattr(mmap, "MAP_POPULATE", 0))
    return torch.frombuffer(pages, dtype=runtime.tc_float).view(shape)


class Runtime:
    """What ``gs.init`` chose; ``epoch`` counts Taichi restarts so that stale scenes are detected.

    arch: the Taichi arch Taichi actually runs on (ti.cpu or ti.cuda); device: the torch device
    of every tensor the simulator makes, always the one matching ``arch``; seed: gs.init's (None:
    none given).
    """

    def __init__(self):
        self.initialized = False
        self.options = None
        self.epoch = 0
        self.arch = ti.cpu
        self.device = torch.device("cpu")
        self.tc_float = torch.float32
        self.np_float = np.float32
        self.ti_float = ti.f32
        self.tc_int, self.np_int = torch.int32, np.int32  # (Genesis's integer and boolean dtypes)
        self.tc_bool, self.np_bool = torch.bool, np.bool_
        self.seed = None


runtime = Runtime()
