"""Materials (Genesis names): ``Rigid`` and the ``MPM`` namespace."""
from dataclasses import dataclass

import numpy as np
import torch

from .options import named_keywords
from .solvers.core import InvalidInputError, refuse_grad


@named_keywords("use_visual_raycasting", "sdf_cell_size", "sdf_min_res", "sdf_max_res", "coup_type", "coup_links",
                "enable_coup_collision", "coup_collision_links", "contact_resistance")
@dataclass
class Rigid:
    """A rigid body. rho: density, kg/m³, of the shapes of links whose mass the asset does not
    state (primitives, meshes, URDF links without <inertial>; an MJCF's are MuJoCo's); None:
    Genesis's default, 1000 under RigidOptions(enable_mujoco_compatibility=True), else 600 for a
    plain object and 1500 for an articulated robot's links (urdf.load_urdf says which);
    friction: Coulomb coefficient of every collision shape of the entity, in [0.01, 5] as Genesis
    (None: the asset's, e.g. a URDF link's <contact><lateral_friction>, else 1.0); a contact
    takes the larger of its two shapes' values; friction_torsional, friction_rolling (m, ≥ 0):
    every shape's torsional and rolling friction (None: the asset's, an MJCF geom's friction's
    second and third, else MuJoCo's and Genesis's 0.005 and 0.0001), acting where a contact has
    condim 4 or 6 (RigidOptions' enable_torsional_friction, enable_rolling_friction, or the MJCF
    geom's condim); gravity_compensation: the share of every link's
    weight a force at its centre of mass cancels (Genesis's: 1 cancels gravity on the entity, 0
    none; above 1 lifts it, below 0 adds weight), None: the asset's (an MJCF body's ``gravcomp``,
    else 0). Coupling with MPM particles, as Genesis's (solvers/mpm/colliders.py): needs_coup
    whether the entity's shapes meet them, coup_friction (≥ 0) their Coulomb friction,
    coup_softness (m, ≥ 0) how far outside a shape its influence reaches, coup_restitution in
    [0, 1] the share of the normal velocity bounced back."""
    rho: float = None
    friction: float = None
    gravity_compensation: float = None
    friction_torsional: float = None
    friction_rolling: float = None
    needs_coup: bool = True
    coup_friction: float = 0.1
    coup_softness: float = 0.002
    coup_restitution: float = 0.0

    def __post_init__(self):
        rho, friction = _real("materials.Rigid", "rho", self.rho), _real("materials.Rigid", "friction", self.friction)
        compensation = _real("materials.Rigid", "gravity_compensation", self.gravity_compensation)
        if self.gravity_compensation is not None and not (compensation is not None and np.isfinite(compensation)):
            raise InvalidInputError(f"materials.Rigid: argument 'gravity_compensation' must be a finite number "
                                    f"(or None), got {self.gravity_compensation!r}")
        self.gravity_compensation = compensation
        if self.rho is not None and not (rho is not None and np.isfinite(rho) and rho > 0):
            raise InvalidInputError(f"materials.Rigid: argument 'rho' must be a positive finite number "
                                    f"(or None), got {self.rho!r}")
        if self.friction is not None and not (friction is not None and 0.01 <= friction <= 5.0):
            raise InvalidInputError(f"materials.Rigid: argument 'friction' must be a number in [0.01, 5.0] "
                                    f"(or None), got {self.friction!r}")
        self.rho, self.friction = None if self.rho is None else rho, friction
        for name in ("friction_torsional", "friction_rolling"):
            given = getattr(self, name)
            value = _real("materials.Rigid", name, given)
            if given is not None and not (value is not None and 0.0 <= value < float("inf")):
                raise InvalidInputError(f"materials.Rigid: argument '{name}' must be a finite number >= 0 (m) "
                                        f"(or None), got {given!r}")
            setattr(self, name, value)
        if not isinstance(self.needs_coup, (bool, np.bool_)):
            raise InvalidInputError(f"materials.Rigid: argument 'needs_coup' must be a bool, got {self.needs_coup!r}")
        self.needs_coup = bool(self.needs_coup)
        for name, upper in (("coup_friction", float("inf")), ("coup_softness", float("inf")),
                            ("coup_restitution", 1.0)):
            given = getattr(self, name)
            value = _real("materials.Rigid", name, given)
            if value is None or not 0.0 <= value <= upper or value == float("inf"):
                bound = "in [0, 1]" if upper == 1.0 else ">= 0"
                raise InvalidInputError(f"materials.Rigid: argument '{name}' must be a finite number {bound}, "
                                        f"got {given!r}")
            setattr(self, name, value)


def _real(owner, name, value):
    """``value`` as a float where it is one real number — a Python or numpy scalar, or a 0-d numpy
    array or torch tensor — else None (a bool, a string, an array). A material is model data: a
    tensor that requires grad raises GradientError (set_material_params, set_friction... are the
    differentiable ways)."""
    refuse_grad(owner, name, value, "a material's values are model data; the entity's setters "
                "(set_material_params, set_friction, set_links_mass...) take differentiable ones")
    if isinstance(value, (bool, np.bool_)):
        return None
    if isinstance(value, (int, float, np.integer, np.floating)):
        return float(value)
    if isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "iuf":
        return float(value)
    if isinstance(value, torch.Tensor) and value.ndim == 0 and not (value.dtype.is_complex or value.dtype == torch.bool):
        return float(value)
    return None


# -- MPM ----------------------------------------------------------------------------------------------------------

#: the particle samplers genesis_lite implements (solvers/mpm/sampling.py)
MPM_SAMPLERS = ("regular", "random")


def _mpm_real(owner, name, value, ok, expected):
    """``value`` as a float after checking it is a finite real number (_real) with ``ok(value)``."""
    real = _real(owner, name, value)
    if not (real is not None and np.isfinite(real) and ok(real)):
        raise InvalidInputError(f"{owner}: argument '{name}' must be {expected}, got {value!r}")
    return real


def _mpm_bool(owner, name, value):
    if not isinstance(value, (bool, np.bool_)):
        raise InvalidInputError(f"{owner}: argument '{name}' must be True or False, got {value!r}")
    return bool(value)


def _mpm_choice(owner, name, value, choices):
    if value not in choices:
        raise InvalidInputError(f"{owner}: argument '{name}' must be one of {list(choices)}, got {value!r}")
    return value


def _mpm_sampler(owner, value):
    """Our samplers; Genesis's physics-based 'pbs' / 'pbs-<res>' raise rather than being replaced."""
    if isinstance(value, str) and (value == "pbs" or (value.startswith("pbs-") and value[4:].isdigit())):
        raise InvalidInputError(f"{owner}: argument 'sampler' {value!r} (Genesis's physics-based sampler) is not "
                                f"implemented in genesis_lite; expected one of {list(MPM_SAMPLERS)} ('regular': a "
                                f"lattice at particle_size spacing, the closest to pbs's even spacing)")
    return _mpm_choice(owner, "sampler", value, MPM_SAMPLERS)


class MPM:
    """``gs.materials.MPM``: the MPM materials (Genesis 1.4.5's classes, arguments and defaults).

    Every material takes E (Young's modulus, Pa, > 0), nu (Poisson ratio, in (−1, 0.5)),
    rho (density, kg/m³, > 0), lam / mu (Lamé parameters, Pa; None: from E and nu) and sampler,
    keywords only. The solver reads: ``solver_kind`` (a layout.KIND name), ``solver_params()``
    (the material's non-differentiable constants, Genesis's names), ``E``, ``nu``, ``rho`` (the
    per-particle inputs' initial values) and ``default_Jp`` (the particles' initial Jp).

    Differences from Genesis:
    - sampler: "regular" (a lattice, Genesis's "regular" layout) or "random" (uniform, from a
      generator seeded per entity: deterministic). Genesis's default "pbs" (physics-based, Linux
      x86 only) is not implemented and raises; the default is "regular" where Genesis's is
      "pbs", and "random" where Genesis's is (Snow, Sand).
    - lam / mu, when given, define the material: E and nu are recomputed from them (Genesis's
      stress reads lam and mu and ignores E and nu), since our solver takes E and nu per
      particle. Muscle refuses them (its fibre stiffness is E).
    - ranges Genesis does not check: yield_lower in [0, 1) (1 − yield_lower clamps singular
      values, which must stay positive), friction_angle in (0°, 90°).
    """

    @named_keywords()
    @dataclass(kw_only=True)
    class Base:
        """The base class of MPM materials (not to be made directly, as in Genesis)."""
        E: float = 1e6
        nu: float = 0.2
        rho: float = 1000.0
        lam: float = None
        mu: float = None
        sampler: str = "regular"

        def __post_init__(self):
            owner = self._owner()
            if type(self) is MPM.Base:
                raise InvalidInputError(f"{owner}: the base class of MPM materials cannot be used itself; use "
                                        f"MPM.Elastic, ElastoPlastic, Snow, Sand, Liquid or Muscle")
            self.E = _mpm_real(owner, "E", self.E, lambda v: v > 0, "a positive finite number (Pa)")
            self.nu = _mpm_real(owner, "nu", self.nu, lambda v: -1.0 < v < 0.5, "a number in (−1, 0.5)")
            self.rho = _mpm_real(owner, "rho", self.rho, lambda v: v > 0, "a positive finite number (kg/m³)")
            self.sampler = _mpm_sampler(owner, self.sampler)
            self._check(owner)
            self._resolve_lame(owner)

        def _owner(self):
            return f"materials.MPM.{type(self).__name__}"

        def _check(self, owner):
            """Checks of a subclass's own arguments."""

        def _resolve_lame(self, owner):
            """lam and mu from E and nu (Genesis's formulas), or E and nu from a given lam / mu."""
            given = [name for name in ("lam", "mu") if getattr(self, name) is not None]
            for name in given:
                setattr(self, name, _mpm_real(owner, name, getattr(self, name), lambda v: True, "a finite number (Pa)"))
            E, nu = self.E, self.nu
            mu = self.mu if self.mu is not None else E / (2.0 * (1.0 + nu))
            lam = self.lam if self.lam is not None else E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
            if given:
                # E > 0 and nu in (−1, 0.5) ⟺ mu > 0 and 3 lam + 2 mu > 0
                if not (mu > 0 and 3.0 * lam + 2.0 * mu > 0):
                    raise InvalidInputError(f"{owner}: arguments 'lam' and 'mu' must give mu > 0 and 3·lam + 2·mu > 0 "
                                            f"(E > 0, nu in (−1, 0.5)), got lam={lam!r}, mu={mu!r}")
                self.E = mu * (3.0 * lam + 2.0 * mu) / (lam + mu)
                self.nu = lam / (2.0 * (lam + mu))
            self.lam, self.mu = lam, mu

        @property
        def default_Jp(self):
            """The particles' Jp at rest (a volume ratio; Sand's is a log-volume correction, 0)."""
            return 1.0

        @property
        def solver_kind(self):
            """The constitutive model's name in solvers/mpm/layout.KIND."""
            raise NotImplementedError

        def solver_params(self):
            """{name: value} of the material's non-differentiable constants (Genesis's names)."""
            return {}

    @named_keywords()
    @dataclass(kw_only=True)
    class Elastic(Base):
        """Elastic material: model "corotation" (corotated linear) or "neohooken" (neo-Hookean)."""
        E: float = 3e5
        model: str = "corotation"

        def _check(self, owner):
            _mpm_choice(owner, "model", self.model, ("corotation", "neohooken"))

        @property
        def solver_kind(self):
            return self.model

    @named_keywords()
    @dataclass(kw_only=True)
    class ElastoPlastic(Base):
        """Elasto-plastic material: von Mises yield (use_von_mises, von_mises_yield_stress, Pa) or,
        without it, singular values of F clamped to [1 − yield_lower, 1 + yield_higher].
        von_mises_yield_stress σ_y is Genesis's parameter: the deviatoric log strain's norm is held
        at σ_y / 2μ, so a bar in uniaxial tension or compression yields at √(3/2)·σ_y ≈ 1.22 σ_y
        (measured 1214 Pa at σ_y 1e3, as Genesis); pass σ_uniaxial / 1.22 for a textbook yield."""
        yield_lower: float = 2.5e-2
        yield_higher: float = 4.5e-3
        use_von_mises: bool = True
        von_mises_yield_stress: float = 10000.0

        def _check(self, owner):
            self.yield_lower = _mpm_real(owner, "yield_lower", self.yield_lower, lambda v: 0 <= v < 1,
                                         "a number in [0, 1)")
            self.yield_higher = _mpm_real(owner, "yield_higher", self.yield_higher, lambda v: v >= 0,
                                          "a finite number ≥ 0")
            self.use_von_mises = _mpm_bool(owner, "use_von_mises", self.use_von_mises)
            self.von_mises_yield_stress = _mpm_real(owner, "von_mises_yield_stress", self.von_mises_yield_stress,
                                                    lambda v: v > 0, "a positive finite number (Pa)")

        @property
        def solver_kind(self):
            return "elastoplastic"

        def solver_params(self):
            return {"yield_lower": self.yield_lower, "yield_higher": self.yield_higher,
                    "use_von_mises": self.use_von_mises, "von_mises_yield_stress": self.von_mises_yield_stress}

    @named_keywords()
    @dataclass(kw_only=True)
    class Snow(ElastoPlastic):
        """Snow: ElastoPlastic's clamp and Lamé parameters scaled by exp(10 (1 − Jp)), Jp the
        plastic volume ratio (as Genesis): harder where compressed (Jp < 1), softer where stretched
        (Jp > 1: a block crushed without confinement, whose sides stretch, loses its strength); no
        von Mises."""
        sampler: str = "random"
        use_von_mises: bool = False

        def _check(self, owner):
            if self.use_von_mises is not False:
                raise InvalidInputError(f"{owner}: argument 'use_von_mises' must be False (Snow does not support "
                                        f"von Mises yield), got {self.use_von_mises!r}")
            super()._check(owner)

        @property
        def solver_kind(self):
            return "snow"

        def solver_params(self):
            return {"yield_lower": self.yield_lower, "yield_higher": self.yield_higher}

    @named_keywords()
    @dataclass(kw_only=True)
    class Sand(Base):
        """Sand: Drucker–Prager plasticity (Klár et al. 2016) with ``friction_angle`` degrees."""
        sampler: str = "random"
        friction_angle: float = 45.0

        def _check(self, owner):
            self.friction_angle = _mpm_real(owner, "friction_angle", self.friction_angle, lambda v: 0 < v < 90,
                                            "a number of degrees in (0, 90)")

        @property
        def default_Jp(self):
            return 0.0

        @property
        def solver_kind(self):
            return "sand"

        def solver_params(self):
            return {"friction_angle": self.friction_angle}

    @named_keywords()
    @dataclass(kw_only=True)
    class Liquid(Base):
        """Liquid: pressure lam·J·(J − 1); ``viscous`` keeps the shear term (else mu = 0, as Genesis)."""
        viscous: bool = False

        def _check(self, owner):
            self.viscous = _mpm_bool(owner, "viscous", self.viscous)

        def _resolve_lame(self, owner):
            super()._resolve_lame(owner)
            if not self.viscous:
                self.mu = 0.0

        @property
        def solver_kind(self):
            return "liquid"

        def solver_params(self):
            return {"viscous": self.viscous}

    @named_keywords()
    @dataclass(kw_only=True)
    class Muscle(Elastic):
        """Muscle: Elastic (model "neohooken" by default) plus the active fibre stress
        E · actu · F (d ⊗ d) Fᵀ, with ``n_groups`` actuation groups (entity.set_muscle,
        entity.set_actuation)."""
        E: float = 1e6
        model: str = "neohooken"
        n_groups: int = 1

        def _check(self, owner):
            super()._check(owner)
            if not (isinstance(self.n_groups, (int, np.integer)) and not isinstance(self.n_groups, (bool, np.bool_))
                    and self.n_groups >= 1):
                raise InvalidInputError(f"{owner}: argument 'n_groups' must be an integer ≥ 1, got {self.n_groups!r}")
            self.n_groups = int(self.n_groups)
            if self.lam is not None or self.mu is not None:
                raise InvalidInputError(f"{owner}: arguments 'lam' and 'mu' are not supported for a muscle (its fibre "
                                        f"stiffness is E, as Genesis); give E and nu, got lam={self.lam!r}, "
                                        f"mu={self.mu!r}")

        @property
        def solver_kind(self):
            return f"muscle_{self.model}"
