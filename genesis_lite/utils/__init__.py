"""Helpers under Genesis's ``gs.utils`` names: ``geom``, rotations and rigid transforms on torch
tensors and numpy arrays."""
from . import geom

__all__ = ["geom"]
