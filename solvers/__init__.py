"""Physics solvers of genesis_lite. Each solver implements :class:`solvers.base.Solver`."""
