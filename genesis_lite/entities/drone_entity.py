"""A multirotor: a rigid entity flown by its rotors' speeds (Genesis's DroneEntity).

Each rotor k turning at ω_k rpm pushes its link along the link's z axis with the thrust
kf·ω_k² (N) at the link's centre of mass, and turns it about that axis with the drag torque
spin_k·km·ω_k² (N·m) (reversed for model "RACE"), as Genesis's drones. The rotors' wrench is
an external wrench for the next step (RigidEntity.apply_links_external_wrench): differentiable
in the speeds, and through the link poses it is computed from, in the state.
"""
import numpy as np
import torch

from ..morphs import rotor_coefficients
from ..runtime import runtime
from ..solvers.core import InvalidInputError, SceneStateError
from .common import named_argument_errors
from ..utils.rotations import rotate
from .rigid_entity import RigidEntity


@named_argument_errors
class DroneEntity(RigidEntity):
    """A rigid entity from gs.morphs.Drone. Units: rpm, N, N·m."""

    def __init__(self, scene, idx, name, morph, material, surface, link_specs, solver):
        super().__init__(scene, idx, name, morph, material, surface, link_specs, solver)
        self._KF, self._KM = rotor_coefficients(morph.file, f"entity '{name}'")
        names = [link.name for link in self.links]  # (the rotors' among them: scene._check_rotors)
        self._propellers_local = np.array([names.index(n) for n in morph.propellers_link_name], dtype=np.int64)
        # the drag torque's sign per rotor (Genesis's model "RACE" turns the other way)
        sign = -1.0 if morph.model == "RACE" else 1.0
        self._torque_sign = sign * torch.tensor(morph.propellers_spin, dtype=runtime.tc_float, device=runtime.device)
        self._rpm_set_at = None  # the simulator's transient_clears at the last set_propellers_rpm: once a step

    @property
    def KF(self):
        """Thrust coefficient kf, N/rpm² (the URDF's <properties kf>)."""
        return self._KF

    @property
    def KM(self):
        """Drag torque coefficient km, N·m/rpm² (the URDF's <properties km>)."""
        return self._KM

    @property
    def model(self):
        """The morph's model: "CF2X", "CF2P" or "RACE"."""
        return self.morph.model

    @property
    def n_propellers(self):
        """The number of rotors."""
        return len(self._propellers_local)

    @property
    def propellers_idx(self):
        """The rotors' links, scene-wide indices (Genesis's)."""
        return torch.as_tensor(self.link_start + self._propellers_local, device=runtime.device)

    @property
    def propellers_spin(self):
        """Each rotor's spin: 1 counter-clockwise, −1 clockwise (the morph's)."""
        return torch.tensor(self.morph.propellers_spin, dtype=runtime.tc_float, device=runtime.device)

    def set_propellers_rpm(self, propellers_rpm):
        """The rotors' speeds for the next step, rpm ≥ 0: (n_propellers,) or, batched, (n_envs,
        n_propellers) (or what broadcasts to it); at most one call a step (Genesis's rule: a second
        would add its wrench to the first's). Differentiable."""
        sim = self._sim()
        who = f"entity '{self.name}': set_propellers_rpm"
        if self._rpm_set_at == sim.transient_clears:
            raise SceneStateError(f"{who} can only be called once per step (Genesis's rule), got a second call before "
                                  f"scene.step() (a reset of some envs keeps the others' rotor speeds)")
        envs = self._envs(None)
        rpm = self._values(propellers_rpm, self.n_propellers, envs, "propellers_rpm")  # (B, n) finite
        if bool((rpm.detach() < 0).any()):
            raise InvalidInputError(f"entity '{self.name}': argument 'propellers_rpm' must be ≥ 0 (rpm), got "
                                    f"{rpm.detach().cpu().numpy()}")
        self._add_wrench(self._propellers_local, envs, self._rotors_wrench(rpm))
        self._rpm_set_at = sim.transient_clears

    def _rotors_wrench(self, rpm):
        """(B, 6 n) N, N·m: each rotor's force and moment about its link's origin, world axes, from
        its speed ``rpm`` (B, n). In the link's axes the thrust (0, 0, F) acts at the centre of mass
        c, so its moment about the origin is c × (0, 0, F) = (c_y F, −c_x F, 0), and the drag
        torque is (0, 0, τ): one rotation by the link's quaternion turns both into the world's."""
        squared = rpm * rpm
        thrust, drag = self._KF * squared, self._KM * self._torque_sign * squared
        com = self._links_com(self._propellers_local, None)  # (B, n, 3) m, link axes
        zero = torch.zeros_like(thrust)
        local = torch.stack([zero, zero, thrust, com[..., 1] * thrust, -com[..., 0] * thrust, drag], dim=-1)
        quat = self._link_rows(self._propellers_local, None, slice(3, 7))  # (B, n, 4)
        return rotate(quat[..., None, :], local.reshape(*rpm.shape, 2, 3)).reshape(len(rpm), -1)
