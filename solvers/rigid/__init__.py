"""Articulated rigid bodies in reduced coordinates.

Stages of one substep, one module each: kinematics → dynamics (bias forces, mass matrix) →
actuation → linalg (solve for accelerations) → integrator. ``step.py`` fuses them for the
forward pass and runs their gradients in reverse; ``solver.py`` is the Python-side owner.
"""
