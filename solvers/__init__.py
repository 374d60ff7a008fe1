"""Physics solvers of genesis_lite, installed as ``genesis_lite.solvers``. Each solver implements
:class:`base.Solver`; ``core`` holds what the API and the solvers share (errors, precision, device)."""
