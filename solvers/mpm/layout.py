"""What the MPM solver's tensors hold, shared by the solver, its kernels and the entity API.

State: one torch tensor (B, n_particles · WIDTH) per scene; viewed as (B, n_particles, WIDTH),
each particle's row holds STATE's fields (row-major 3×3 matrices):
- pos (3): position, m (world);
- vel (3): velocity, m/s;
- C (9): APIC affine velocity field, 1/s;
- F (9): deformation gradient (elastic part), no unit;
- Jp (1): plastic volume ratio (Snow's hardening, Sand's volume correction), 1 at rest.

Inputs (name → (B, width) tensor): E (B, n) Young's modulus, Pa; nu (B, n) Poisson ratio;
rho (B, n) density, kg/m³; actu (B, n) muscle actuation, no unit (0 for other materials);
gravity (B, 3) m/s²; coupling (B, 3R): each of the scene's R rigid entities' coupling friction μ,
softness ς (m) and restitution e (its material's coup_friction, coup_softness, coup_restitution;
the colliders' rule, colliders.py), per env; fiber (B, n · 3) muscle fibre directions (as given: not unit), the same in every env (the
kernels read row 0; an input, not model data, so that every step records the directions it ran
with and its backward replays them: set_muscle may change them between steps). Parameters and
fibres and couplings keep their value across scene.reset(); actu is a control, but part of the state as
Genesis keeps it: a reset writes it again from each muscle's group actuation in the registered
state (MPMEntity.restore_groups). fiber has no
gradient.

Material kinds: each particle has a kind code (KIND) and N_CONSTS constants whose meaning
depends on the kind (solvers/mpm/constitutive.py: encode).
"""
import numpy as np

#: field → (first column, last column + 1) of a particle's state row
STATE = {"pos": (0, 3), "vel": (3, 6), "C": (6, 15), "F": (15, 24), "Jp": (24, 25)}
WIDTH = 25
#: a replay's SVD of F_tmp per particle: U (9, row-major), σ (3), V (9)
SVD_WIDTH = 21

#: per-particle inputs (B, n_particles)
PARTICLE_INPUTS = ("E", "nu", "rho", "actu")
#: per-env inputs, side by side in the kernels' ``env_in`` (B, 3 + 3R): gravity (3), then coupling
ENV_INPUTS = ("gravity", "coupling")
PERSISTENT_INPUTS = ("E", "nu", "rho", "gravity", "coupling", "fiber")


#: env_in's first column of the input coupling (gravity's 3 come first)
COUPLING_AT = 3


def coupling_columns(entity):
    """(3,) int: rigid entity number ``entity``'s (μ, ς, e) columns in the input coupling (B, 3R)
    (in env_in: COUPLING_AT more)."""
    return 3 * entity + np.arange(3)


#: a muscle's fibre direction until set_muscle sets it (Genesis's)
DEFAULT_FIBER = (0.0, 0.0, 1.0)

#: material kind → code of the kernels' runtime branch
KIND = {"corotation": 0, "neohooken": 1, "elastoplastic": 2, "snow": 3, "sand": 4, "liquid": 5,
        "muscle_corotation": 6, "muscle_neohooken": 7}
N_CONSTS = 4
