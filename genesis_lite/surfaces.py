"""Surfaces: how an entity looks to cameras."""
from dataclasses import dataclass


@dataclass
class Default:
    """A plain surface; color (r, g, b) in [0, 1]."""
    color: tuple = (0.6, 0.6, 0.6)
