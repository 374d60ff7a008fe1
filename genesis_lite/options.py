"""Scene options (Genesis names). Values are validated when the options are made."""
from dataclasses import dataclass

import numpy as np

from .solvers.core import InvalidInputError


def _check_vec3(owner, name, value):
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise InvalidInputError(f"{owner}: argument '{name}' must be 3 finite numbers, got {value!r}")
    return tuple(float(v) for v in arr)


def _check_positive(owner, name, value, integer=False):
    ok = np.isscalar(value) and np.isfinite(value) and value > 0 and (not integer or int(value) == value)
    if not ok:
        kind = "a positive integer" if integer else "a positive finite number"
        raise InvalidInputError(f"{owner}: argument '{name}' must be {kind}, got {value!r}")


@dataclass
class SimOptions:
    """Time stepping and differentiability.

    dt: step length, s. substeps: integration substeps per step (substep = dt / substeps).
    gravity: (3,) m/s². requires_grad: build the torch autograd graph through every step.
    check_nan: stop at the first non-finite state, naming the step and entity.
    checkpoint_interval: with requires_grad, keep the state of every k-th step only and
        recompute the others during backward (memory ÷ k, about one extra forward pass).
    """
    dt: float = 1e-2
    substeps: int = 1
    gravity: tuple = (0.0, 0.0, -9.81)
    requires_grad: bool = False
    check_nan: bool = False
    checkpoint_interval: int = 1

    def __post_init__(self):
        _check_positive("SimOptions", "dt", self.dt)
        _check_positive("SimOptions", "substeps", self.substeps, integer=True)
        _check_positive("SimOptions", "checkpoint_interval", self.checkpoint_interval, integer=True)
        self.gravity = _check_vec3("SimOptions", "gravity", self.gravity)
        self.substeps = int(self.substeps)
        self.checkpoint_interval = int(self.checkpoint_interval)


@dataclass
class RigidOptions:
    """Rigid solver switches.

    enable_collision: contact between shapes (contact is not implemented yet: see README).
    enable_joint_limit: soft joint-limit forces (time constant limit_timeconst s, critically damped).
    """
    enable_collision: bool = True
    enable_joint_limit: bool = True
    limit_timeconst: float = 0.02

    def __post_init__(self):
        _check_positive("RigidOptions", "limit_timeconst", self.limit_timeconst)
