"""Narrow-phase colliders reproducing MuJoCo's, as Taichi functions on one environment.

One module per family of colliders (``primitive``: planes, spheres, capsules, cylinders;
``box``; ``convex``: meshes and cylinder pairs; ``hfield``: height fields, as prisms for
``convex``'s CCD), ``frame`` for the contact frame and the helpers they share, ``detect`` for the
stage that calls them.

A collider takes two geoms in MuJoCo's conventions (type codes ordered type 1 ≤ type 2; world
position (3,) m; rotation (3, 3) whose columns are the geom's axes; MuJoCo's sizes: radius, half
length, half extents) and the pair's margin (m), and returns (count, position (K, 3) m, normal
(K, 3) from geom 1 to geom 2, dist (K,) m, negative in penetration, feature (K,) ints), K its
contact budget, rows past count zero: the contacts MuJoCo emits, in its order. Each is a
"decide" (the discrete feature of each contact) and a closed-form "evaluate" of a contact from
the poses and its feature, which the forward uses and a backward can differentiate.
"""
