"""Materials (Genesis names)."""
from dataclasses import dataclass

import numpy as np

from .solvers.core import InvalidInputError


@dataclass
class Rigid:
    """A rigid body. rho: density, kg/m³ (used where a link has no inertial);
    friction: Coulomb coefficient used by contacts (None: the solver default)."""
    rho: float = 200.0
    friction: float = None

    def __post_init__(self):
        if not (np.isscalar(self.rho) and np.isfinite(self.rho) and self.rho > 0):
            raise InvalidInputError(f"materials.Rigid: argument 'rho' must be a positive finite number, got {self.rho!r}")
        if self.friction is not None and not (np.isscalar(self.friction) and np.isfinite(self.friction)
                                              and self.friction >= 0):
            raise InvalidInputError(
                f"materials.Rigid: argument 'friction' must be a finite number ≥ 0, got {self.friction!r}")
