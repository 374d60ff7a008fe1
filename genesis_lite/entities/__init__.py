"""Entities: the user's handles on what a scene contains."""
from .rigid_entity import RigidEntity, RigidJoint, RigidLink

__all__ = ["RigidEntity", "RigidJoint", "RigidLink"]
