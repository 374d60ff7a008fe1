"""The MPM particle solver (MLS-MPM): solver.py owns it, kernels.py runs a substep."""
