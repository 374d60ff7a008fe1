"""What the MPM scene *is*: the grid, the walls, and each particle's material, built once at
``scene.build()`` from the entities (plain numpy; the solver turns it into kernel arrays)."""
from dataclasses import dataclass, field

import numpy as np

from ..core import InvalidInputError
from . import layout

WALL_CELLS = 3  # the walls stand this many cells inside the bounds (Genesis's padding)


@dataclass
class Grid:
    """The background grid: cells of dx = 1/density m; nodes at integer multiples of dx from
    ``lowest`` (3, cells) to ``lowest + res − 1``; walls ``wall_lower``/``wall_upper`` (3,) m."""
    density: float
    lower_bound: np.ndarray
    upper_bound: np.ndarray

    def __post_init__(self):
        self.dx = 1.0 / self.density
        self.lowest = np.round(self.density * self.lower_bound).astype(np.int64)
        self.res = np.round(self.density * self.upper_bound).astype(np.int64) - self.lowest + 1
        self.wall_lower = self.lower_bound + WALL_CELLS * self.dx
        self.wall_upper = self.upper_bound - WALL_CELLS * self.dx
        self.n_nodes = int(np.prod(self.res))


@dataclass
class EntitySpec:
    """One MPM entity: its particles' initial positions (n, 3) m, its material's kind name
    (layout.KIND) and non-differentiable parameters, E (Pa), nu, rho (kg/m³), and the initial
    plastic volume ratio Jp (1; Genesis's Sand starts at 0)."""
    name: str
    kind: str
    params: dict
    E: float
    nu: float
    rho: float
    Jp: float
    positions: np.ndarray
    start: int = 0


@dataclass
class MPMModel:
    """Per particle (N): kinds (N,) int, consts (N, N_CONSTS), defaults E/nu/rho (N,), pos0 (N, 3) m,
    Jp0 (N,); plus the grid, the particle volume vol (m³) and the walls' kind."""
    grid: Grid
    vol: float
    sticky: bool
    entities: list = field(default_factory=list)

    def finish(self, encode):
        """Concatenate the entities' particles; encode(kind, params) → (code, consts)."""
        self.n_particles = sum(len(s.positions) for s in self.entities)
        self.kinds = np.zeros(self.n_particles, dtype=np.int32)
        self.consts = np.zeros((self.n_particles, layout.N_CONSTS))
        self.pos0 = np.zeros((self.n_particles, 3))
        self.Jp0 = np.ones(self.n_particles)
        self.defaults = {name: np.zeros(self.n_particles) for name in ("E", "nu", "rho")}
        for spec in self.entities:
            rows = slice(spec.start, spec.start + len(spec.positions))
            code, consts = encode(spec.kind, spec.params)
            self.kinds[rows], self.consts[rows], self.pos0[rows], self.Jp0[rows] = code, consts, spec.positions, spec.Jp
            for name in self.defaults:
                self.defaults[name][rows] = getattr(spec, name)
        return self

    def check_inside(self, name, positions, what):
        """Every position (n, 3) m within the walls, else a named error."""
        outside = ~np.all((positions >= self.grid.wall_lower) & (positions <= self.grid.wall_upper), axis=-1)
        if outside.any():
            first = np.argwhere(outside)[0]
            raise InvalidInputError(
                f"entity '{name}': {what} must lie inside the MPM domain's walls, between {self.grid.wall_lower.tolist()} "
                f"and {self.grid.wall_upper.tolist()} m (MPMOptions bounds less {WALL_CELLS} cells), got "
                f"{int(outside.sum())} particle(s) outside, e.g. particle {first.tolist()} at "
                f"{np.asarray(positions)[tuple(first)].tolist()}")
