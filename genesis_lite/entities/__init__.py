"""Entities: the user's handles on what a scene contains."""
from .drone_entity import DroneEntity
from .mpm_entity import MPMEntity, MPMEntityState
from .rigid_entity import RigidEntity, RigidEntityState, RigidJoint, RigidLink

__all__ = ["DroneEntity", "MPMEntity", "MPMEntityState", "RigidEntity", "RigidEntityState", "RigidJoint", "RigidLink"]
