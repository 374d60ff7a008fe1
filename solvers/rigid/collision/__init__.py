"""Narrow-phase colliders reproducing MuJoCo's, as Taichi functions on one environment.

One module per family of colliders (``primitive``: planes, spheres, capsules, cylinders;
``box``; ``convex``), all with the signature of ``contact/interfaces.md``; ``frame`` holds the
contact frame and the small geometry helpers they share.
"""
