"""MuJoCo's soft constraints for the rigid solver: rows (rows.py: Jacobian, R, aref of contacts,
joint limits and dof friction loss) and their primal Newton solve (solver.py)."""
