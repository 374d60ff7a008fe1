"""Exceptions raised by genesis_lite.

Every error a user can trigger is a :class:`GenesisException` subclass whose message
names the entity, the argument, what was expected and what was given.
"""


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


class SimulationError(GenesisException, RuntimeError):
    """The simulation produced a non-finite state (raised when SimOptions(check_nan=True))."""
