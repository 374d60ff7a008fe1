"""Entities: the user's handles on what a scene contains."""
from .mpm_entity import MPMEntity, MPMEntityState
from .rigid_entity import RigidEntity, RigidEntityState, RigidJoint, RigidLink

__all__ = ["MPMEntity", "MPMEntityState", "RigidEntity", "RigidEntityState", "RigidJoint", "RigidLink"]
