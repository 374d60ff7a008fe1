"""Materials (Genesis names)."""
from dataclasses import dataclass

import numpy as np

from .solvers.core import InvalidInputError


@dataclass
class Rigid:
    """A rigid body. rho: density, kg/m³ (used where a link has no inertial);
    friction: Coulomb coefficient of every collision shape of the entity, in [0.01, 5] as Genesis
    (None: the asset's, e.g. a URDF link's <contact><lateral_friction>, else 1.0); a contact
    takes the larger of its two shapes' values."""
    rho: float = 200.0
    friction: float = None

    def __post_init__(self):
        if not (_is_real(self.rho) and np.isfinite(self.rho) and self.rho > 0):
            raise InvalidInputError(f"materials.Rigid: argument 'rho' must be a positive finite number, "
                                    f"got {self.rho!r}")
        if self.friction is not None and not (_is_real(self.friction) and 0.01 <= self.friction <= 5.0):
            raise InvalidInputError(f"materials.Rigid: argument 'friction' must be a number in [0.01, 5.0] "
                                    f"(or None), got {self.friction!r}")


def _is_real(value):
    """A real number (not a bool, string or array)."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))
