"""Physics solvers of genesis_lite, installed as ``genesis_lite.solvers``. Each solver implements
:class:`base.Solver`; ``core`` holds what the API and the solvers share (errors, precision, device);
``taichi_startup`` removes start-up costs of Taichi (three before any kernel is defined)."""
from . import taichi_startup  # noqa: F401  (first: the kernels below are defined after it)
