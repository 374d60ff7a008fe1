"""Genesis's generated terrains: a grid of subterrains (flat, slopes, pyramids, waves, stairs,
random blocks, stepping stones, fractal noise) as one height field, for gs.morphs.Terrain.

Heights are in units of the terrain's vertical_scale, at grid points horizontal_scale apart; a
subterrain of subterrain_size (x, y) m has size / horizontal_scale + 1 points a side, and
neighbours share their edge points (the higher one is kept), as Genesis lays them out (IsaacGym's
terrain kinds). The kinds without chance (flat, sloped, pyramid_sloped, wave, stairs,
pyramid_stairs) give Genesis 1.4.5's heights (bench/terrain.py: equal, to Genesis's float32
rounding); those drawn at random (random_uniform, discrete_obstacles, stepping_stones, fractal)
are the same kinds of ground drawn by this module's own rules, from a generator seeded 0 unless
``randomize`` (Genesis seeds numpy's global generator with 0 likewise): not Genesis's heights.
"""
import numpy as np

# each kind's parameters and their defaults (Genesis 1.4.5's), m or dimensionless
DEFAULTS = {
    "flat_terrain": {},
    "fractal_terrain": {"levels": 8, "scale": 5.0},
    "random_uniform_terrain": {"min_height": -0.1, "max_height": 0.1, "step": 0.1, "downsampled_scale": 0.5},
    "sloped_terrain": {"slope": -0.5},
    "pyramid_sloped_terrain": {"slope": -0.1},
    "discrete_obstacles_terrain": {"max_height": 0.05, "min_size": 1.0, "max_size": 5.0, "num_rects": 20},
    "wave_terrain": {"num_waves": 2.0, "amplitude": 0.1},
    "stairs_terrain": {"step_width": 0.75, "step_height": -0.1},
    "pyramid_stairs_terrain": {"step_width": 0.75, "step_height": -0.1},
    "stepping_stones_terrain": {"stone_size": 1.0, "stone_distance": 0.25, "max_height": 0.2, "platform_size": 0.0},
}
PLATFORM = 1.0  # m: the flat square left at the centre of the pyramids and obstacle fields (IsaacGym's default)
STONE_DEPTH = -10.0  # m: the ground between stepping stones
MAX_LEVELS = 20  # fractal octaves (each halves the spacing: 2^20 cells apart is beyond any grid)


# each kind's conditions on its parameters: (name, holds(values, horizontal_scale), what is expected)
_RULES = {
    "fractal_terrain": [("levels", lambda v, hs: float(v["levels"]).is_integer() and 1 <= v["levels"] <= MAX_LEVELS,
                         f"an integer in [1, {MAX_LEVELS}]")],
    "random_uniform_terrain": [("max_height", lambda v, hs: v["max_height"] >= v["min_height"], "at least min_height"),
                               ("step", lambda v, hs: v["step"] > 0, "positive"),
                               ("downsampled_scale", lambda v, hs: v["downsampled_scale"] > 0, "positive")],
    "discrete_obstacles_terrain": [("min_size", lambda v, hs: v["min_size"] >= hs, "at least horizontal_scale"),
                                   ("max_size", lambda v, hs: v["max_size"] >= v["min_size"], "at least min_size"),
                                   ("num_rects",
                                    lambda v, hs: float(v["num_rects"]).is_integer() and v["num_rects"] >= 0,
                                    "an integer >= 0")],
    "wave_terrain": [("num_waves", lambda v, hs: v["num_waves"] >= 0, ">= 0")],
    "stairs_terrain": [("step_width", lambda v, hs: v["step_width"] >= hs, "at least horizontal_scale")],
    "pyramid_stairs_terrain": [("step_width", lambda v, hs: v["step_width"] >= hs, "at least horizontal_scale")],
    "stepping_stones_terrain": [("stone_size", lambda v, hs: v["stone_size"] >= hs, "at least horizontal_scale"),
                                ("stone_distance", lambda v, hs: v["stone_distance"] >= 0, ">= 0"),
                                ("platform_size", lambda v, hs: v["platform_size"] >= 0, ">= 0")],
}


def problem(kind, values, horizontal_scale):
    """What is wrong with a kind's parameters ``values`` {name: value} (complete), as a phrase
    for an error message ("'name' of kind must be …, got …"), or None. Every value is a finite
    real number; lengths that become cell counts are at least one cell (horizontal_scale)."""
    for name, value in values.items():
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)) \
                or not np.isfinite(value):
            return f"'{name}' of {kind} must be a finite number, got {value!r}"
    for name, holds, expected in _RULES.get(kind, []):
        if not holds(values, horizontal_scale):
            return f"'{name}' of {kind} must be {expected}, got {values[name]!r}"
    return None


def height_field(n_subterrains, subterrain_size, subterrain_types, parameters, horizontal_scale, vertical_scale,
                 rng):
    """The (nx, ny) heights (vertical_scale units) of n_subterrains (2,) subterrains of
    subterrain_size (2,) m, kinds subterrain_types[i][j] with ``parameters`` {kind: {name: value}}
    (complete: DEFAULTS' merged with the user's), drawn from ``rng`` (numpy Generator)."""
    rows, cols = (int(round(size / horizontal_scale)) + 1 for size in subterrain_size)
    heights = np.full((n_subterrains[0] * (rows - 1) + 1, n_subterrains[1] * (cols - 1) + 1), -np.inf)
    for i in range(n_subterrains[0]):
        for j in range(n_subterrains[1]):
            kind = subterrain_types[i][j]
            block = _KINDS[kind](rows, cols, horizontal_scale, vertical_scale, rng, **parameters[kind])
            view = heights[i * (rows - 1): i * (rows - 1) + rows, j * (cols - 1): j * (cols - 1) + cols]
            np.maximum(view, block, out=view)
    return heights


def _flat(rows, cols, hs, vs, rng):
    return np.zeros((rows, cols))


def _sloped(rows, cols, hs, vs, rng, slope):
    """Rising along x from 0 by int(slope · hs / vs · rows) over the subterrain's rows."""
    top = int(slope * (hs / vs) * rows)
    return np.repeat((top * np.arange(rows) / rows)[:, None], cols, axis=1)


def _tent(n):
    """(n,): 0 at the ends, 1 at the centre int(n / 2), linear between."""
    centre = int(n / 2)
    return (centre - np.abs(centre - np.arange(n))) / centre


def _pyramid_sloped(rows, cols, hs, vs, rng, slope):
    """A pyramid of slope ``slope`` (its top int(slope · hs / vs · rows / 2)), cut flat at the
    height it has at the corner of a central platform of PLATFORM m."""
    top = int(slope * (hs / vs) * (rows / 2))
    heights = top * _tent(rows)[:, None] * _tent(cols)[None, :]
    half = int(PLATFORM / hs / 2)
    corner = heights[max(rows // 2 - half, 0), max(cols // 2 - half, 0)]  # (a subterrain narrower than it: 0)
    return np.clip(heights, min(corner, 0), max(corner, 0))


def _wave(rows, cols, hs, vs, rng, num_waves, amplitude):
    """a·cos(j / d) + a·sin(i / d), a = amplitude / 2 / vs, d = cols / (2π num_waves)."""
    if not num_waves > 0:
        return np.zeros((rows, cols))
    a, d = 0.5 * amplitude / vs, cols / (num_waves * np.pi * 2)
    return a * np.cos(np.arange(cols)[None, :] / d) + a * np.sin(np.arange(rows)[:, None] / d)


def _stairs(rows, cols, hs, vs, rng, step_width, step_height):
    """Steps along x, each int(step_width / hs) rows wide and int(step_height / vs) higher than the
    last, the first one step up; rows past the last whole step stay at 0."""
    width, rise = int(step_width / hs), int(step_height / vs)
    heights = np.zeros((rows, cols))
    steps = rows // width
    heights[: steps * width] = np.repeat(rise * np.arange(1, steps + 1), width)[:, None]
    return heights


def _pyramid_stairs(rows, cols, hs, vs, rng, step_width, step_height):
    """Concentric square steps inward, one rise per int(step_width / hs) cells, until the inner
    square is no wider than the PLATFORM."""
    width, rise, platform = int(step_width / hs), int(step_height / vs), int(PLATFORM / hs)
    heights = np.zeros((rows, cols))
    x0, x1, y0, y1, level = 0, rows, 0, cols, 0
    while x1 - x0 > platform and y1 - y0 > platform:
        x0, x1, y0, y1, level = x0 + width, x1 - width, y0 + width, y1 - width, level + rise
        heights[x0:x1, y0:y1] = level
    return heights


def _random_uniform(rows, cols, hs, vs, rng, min_height, max_height, step, downsampled_scale):
    """Heights drawn uniformly from min_height … max_height in steps of ``step`` (m, as whole
    vertical_scale units) at points downsampled_scale m apart, interpolated linearly between them
    and rounded to whole units."""
    low, high, unit = int(min_height / vs), int(max_height / vs), max(int(step / vs), 1)
    levels = np.arange(low, high + unit, unit)
    coarse = [max(int(n * hs / downsampled_scale), 2) for n in (rows, cols)]
    samples = rng.choice(levels, size=coarse).astype(np.float64)
    along_x = np.linspace(0, coarse[0] - 1, rows)
    along_y = np.linspace(0, coarse[1] - 1, cols)
    by_row = np.array([np.interp(along_y, np.arange(coarse[1]), line) for line in samples])
    fine = np.array([np.interp(along_x, np.arange(coarse[0]), column) for column in by_row.T]).T
    return np.rint(fine)


def _platform(heights, hs, size, value=0.0):
    """The central square of ``size`` m set to ``value`` (in place)."""
    half = int(size / hs) // 2
    rows, cols = heights.shape
    heights[max(rows // 2 - half, 0): rows // 2 + half, max(cols // 2 - half, 0): cols // 2 + half] = value


def _discrete_obstacles(rows, cols, hs, vs, rng, max_height, min_size, max_size, num_rects):
    """num_rects blocks of sides drawn from min_size … max_size m, each ±max_height or
    ±max_height / 2 high, at random places; a flat PLATFORM at the centre."""
    heights = np.zeros((rows, cols))
    tall = int(max_height / vs)
    smallest, largest = max(int(min_size / hs), 1), max(int(max_size / hs), 1)
    for _ in range(int(num_rects)):
        width, length = (int(rng.integers(smallest, max(largest, smallest + 1))) for _ in range(2))
        x, y = int(rng.integers(0, max(rows - width, 1))), int(rng.integers(0, max(cols - length, 1)))
        heights[x: x + width, y: y + length] = rng.choice([-tall, -tall // 2, tall // 2, tall])
    _platform(heights, hs, PLATFORM)
    return heights


def _stepping_stones(rows, cols, hs, vs, rng, stone_size, stone_distance, max_height, platform_size):
    """Square stones of stone_size m, stone_distance m apart, each of a height drawn from
    −max_height … max_height, in rows with a random shift, over ground STONE_DEPTH m down; a flat
    square of platform_size m at the centre."""
    size, gap = max(int(stone_size / hs), 1), int(stone_distance / hs)
    tall = int(max_height / vs)
    heights = np.full((rows, cols), float(int(STONE_DEPTH / vs)))
    for x in range(0, rows, size + gap):
        shift = int(rng.integers(0, size))
        for y in range(-shift, cols, size + gap):
            heights[x: x + size, max(y, 0): y + size] = rng.integers(-tall, tall + 1) if tall > 0 else 0
    if platform_size > 0:
        _platform(heights, hs, platform_size)
    return heights


def _fractal(rows, cols, hs, vs, rng, levels, scale):
    """Value noise over ``levels`` octaves: at octave l, values drawn from ±2^−l · scale m at points
    2^(levels − l) cells apart, interpolated linearly, summed (in vertical_scale units)."""
    heights = np.zeros((rows, cols))
    for level in range(1, int(levels) + 1):
        spacing = 2 ** (int(levels) - level)
        points = [np.arange(0, n + spacing, spacing) for n in (rows, cols)]
        values = rng.uniform(-1.0, 1.0, (len(points[0]), len(points[1]))) * 2.0 ** (-level) * scale
        by_row = np.array([np.interp(np.arange(cols), points[1], line) for line in values])
        heights += np.array([np.interp(np.arange(rows), points[0], column) for column in by_row.T]).T
    return heights / vs


_KINDS = {"flat_terrain": _flat, "fractal_terrain": _fractal, "random_uniform_terrain": _random_uniform,
          "sloped_terrain": _sloped, "pyramid_sloped_terrain": _pyramid_sloped,
          "discrete_obstacles_terrain": _discrete_obstacles, "wave_terrain": _wave, "stairs_terrain": _stairs,
          "pyramid_stairs_terrain": _pyramid_stairs, "stepping_stones_terrain": _stepping_stones}
