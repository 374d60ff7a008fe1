"""The MPM API without the MPM solver: MPMOptions and the MPM materials (Genesis 1.4.5's
arguments and defaults, named errors), particle sampling (volume, inside the shape, pose), and
MPMEntity's getters and setters on a fake simulator that holds the state and inputs as the real
one does (solvers/mpm/layout.py): shapes, values, out-of-place writes, gradients, errors.
"""
import ast
import logging
import os

import numpy as np
import pytest
import torch
import trimesh

import genesis_lite as gs
from genesis_lite.entities import MPMEntity
from genesis_lite.entities.common import replace_columns
from genesis_lite.entities.mpm_entity import sample_particles
from genesis_lite.simulator import Simulator
from genesis_lite.solvers.mpm import layout, sampling
from genesis_lite.solvers.rigid.shapes import quat_to_mat
from tests.conftest import warns

MPM = gs.materials.MPM
GENESIS = "/work/peers/genesis/lib/python3.11/site-packages/genesis"

# Genesis 1.4.5's defaults, from genesis/engine/materials/MPM/{base,elastic,elasto_plastic,snow,sand,liquid,
# muscle}.py (class attributes; Base.sampler is "pbs" on Linux x86, which we replace by "regular") and
# genesis/options/solvers.py (MPMOptions, with TimeBasedMixin.dt and GravityMixin.gravity).
BASE = {"E": 1e6, "nu": 0.2, "rho": 1000.0, "lam": None, "mu": None}
MATERIAL_DEFAULTS = {
    "Elastic": {**BASE, "E": 3e5, "model": "corotation"},
    "ElastoPlastic": {**BASE, "yield_lower": 2.5e-2, "yield_higher": 4.5e-3, "use_von_mises": True,
                      "von_mises_yield_stress": 10000.0},
    "Snow": {**BASE, "yield_lower": 2.5e-2, "yield_higher": 4.5e-3, "use_von_mises": False,
             "von_mises_yield_stress": 10000.0, "sampler": "random"},
    "Sand": {**BASE, "friction_angle": 45.0, "sampler": "random"},
    "Liquid": {**BASE, "viscous": False},
    "Muscle": {**BASE, "model": "neohooken", "n_groups": 1},
}
PARENT = {"Elastic": "Base", "ElastoPlastic": "Base", "Snow": "ElastoPlastic", "Sand": "Base", "Liquid": "Base",
          "Muscle": "Elastic", "Base": None}
FILES = {"Base": "base", "Elastic": "elastic", "ElastoPlastic": "elasto_plastic", "Snow": "snow", "Sand": "sand",
         "Liquid": "liquid", "Muscle": "muscle"}
OPTIONS_DEFAULTS = {"dt": None, "gravity": None, "particle_size": 0.01, "grid_density": 64, "enable_CPIC": False,
                    "lower_bound": (-1.0, -1.0, 0.0), "upper_bound": (1.0, 1.0, 1.0), "use_sparse_grid": False,
                    "leaf_block_size": 8}


def _class_defaults(path, name):
    """{field: default} of the annotated class attributes of class ``name`` in a Python file
    (read with ast: nothing of Genesis is imported)."""
    tree = ast.parse(open(path).read())
    cls = next(node for node in tree.body if isinstance(node, ast.ClassDef) and node.name == name)
    out = {}
    for node in cls.body:
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and node.value is not None:
            try:
                out[node.target.id] = ast.literal_eval(node.value)
            except ValueError:  # a computed default (e.g. DEFAULT_SAMPLER, Field(...))
                pass
    return out


def _genesis_material_defaults(name):
    chain = []
    while name is not None:
        chain.append(name)
        name = PARENT[name]
    merged = {}
    for cls in reversed(chain):
        merged.update(_class_defaults(os.path.join(GENESIS, "engine/materials/MPM", FILES[cls] + ".py"), cls))
    return merged


@pytest.mark.skipif(not os.path.isdir(GENESIS), reason="Genesis 1.4.5's sources are not on this machine")
def test_hard_coded_defaults_are_genesis_source():
    for name, ours in MATERIAL_DEFAULTS.items():
        theirs = _genesis_material_defaults(name)
        for key, value in ours.items():
            if key in theirs:
                assert theirs[key] == value, (name, key)
        assert set(ours) - {"sampler"} <= set(theirs), name
    options = _class_defaults(os.path.join(GENESIS, "options/solvers.py"), "MPMOptions")
    assert options == {"particle_size": None, "grid_density": 64, "enable_CPIC": False,
                       "lower_bound": (-1.0, -1.0, 0.0), "upper_bound": (1.0, 1.0, 1.0)}
    for mixin in ("TimeBasedMixin", "GravityMixin"):
        assert set(_class_defaults(os.path.join(GENESIS, "options/solvers.py"), mixin).values()) == {None}


def test_material_defaults_and_solver_view():
    for name, defaults in MATERIAL_DEFAULTS.items():
        material = getattr(MPM, name)()
        for key, value in defaults.items():
            if key not in ("lam", "mu"):
                assert getattr(material, key) == value, (name, key)
        assert material.sampler == defaults.get("sampler", "regular")
        assert material.solver_kind in layout.KIND
    E, nu = 3e5, 0.2
    elastic = MPM.Elastic()
    assert elastic.mu == pytest.approx(E / (2 * (1 + nu))) and elastic.lam == pytest.approx(E * nu / (1.2 * 0.6))
    assert [MPM.Elastic(model=m).solver_kind for m in ("corotation", "neohooken")] == ["corotation", "neohooken"]
    assert [MPM.Muscle(model=m).solver_kind for m in ("corotation", "neohooken")] == \
        ["muscle_corotation", "muscle_neohooken"]
    assert MPM.ElastoPlastic().solver_params() == {"yield_lower": 2.5e-2, "yield_higher": 4.5e-3,
                                                   "use_von_mises": True, "von_mises_yield_stress": 1e4}
    assert MPM.Snow().solver_params() == {"yield_lower": 2.5e-2, "yield_higher": 4.5e-3}
    assert MPM.Sand(friction_angle=30).solver_params() == {"friction_angle": 30.0}
    assert MPM.Liquid(viscous=True).solver_params() == {"viscous": True}
    assert MPM.Liquid().mu == 0.0 and MPM.Liquid(viscous=True).mu > 0  # Genesis zeroes mu when inviscid
    assert MPM.Sand().default_Jp == 0.0 and MPM.Snow().default_Jp == 1.0
    # lam and mu, when given, define the material: E and nu follow from them
    lame = MPM.Elastic(lam=1e5, mu=2e5)
    assert (lame.lam, lame.mu) == (1e5, 2e5)
    assert lame.E == pytest.approx(2e5 * (3e5 + 4e5) / 3e5) and lame.nu == pytest.approx(1e5 / 6e5)


@pytest.mark.parametrize("cls, kwargs, fragment", [
    ("Elastic", {"nu": 0.5}, "'nu' must be a number in (−1, 0.5)"),
    ("Elastic", {"nu": -1.0}, "'nu'"),
    ("Elastic", {"E": 0.0}, "'E' must be a positive"),
    ("Sand", {"rho": -1.0}, "'rho' must be a positive"),
    ("Elastic", {"E": float("nan")}, "'E'"),
    ("Elastic", {"E": True}, "'E'"),
    ("Elastic", {"model": "stvk"}, "'model' must be one of"),
    ("Muscle", {"model": "stvk"}, "'model'"),
    ("Elastic", {"sampler": "pbs"}, "'sampler' 'pbs' (Genesis's physics-based sampler) is not implemented"),
    ("Sand", {"sampler": "pbs-64"}, "not implemented"),
    ("Liquid", {"sampler": "grid"}, "'sampler' must be one of ['regular', 'random']"),
    ("Sand", {"friction_angle": 0.0}, "'friction_angle' must be a number of degrees in (0, 90)"),
    ("Sand", {"friction_angle": 95.0}, "'friction_angle'"),
    ("Muscle", {"n_groups": 0}, "'n_groups' must be an integer ≥ 1"),
    ("Muscle", {"n_groups": 1.5}, "'n_groups'"),
    ("Muscle", {"mu": 1e5}, "'lam' and 'mu' are not supported for a muscle"),
    ("Snow", {"use_von_mises": True}, "'use_von_mises' must be False"),
    ("ElastoPlastic", {"yield_lower": 1.0}, "'yield_lower' must be a number in [0, 1)"),
    ("ElastoPlastic", {"von_mises_yield_stress": 0}, "'von_mises_yield_stress'"),
    ("ElastoPlastic", {"use_von_mises": 1}, "'use_von_mises' must be True or False"),
    ("Liquid", {"viscous": "yes"}, "'viscous'"),
    ("Elastic", {"lam": 1e5, "mu": -1.0}, "'lam' and 'mu' must give mu > 0"),
    ("Elastic", {"youngs": 1e5}, "MPM.Elastic: argument 'youngs' is unknown"),
    ("Base", {}, "base class of MPM materials"),
])
def test_material_errors(cls, kwargs, fragment):
    with pytest.raises(gs.InvalidInputError) as info:
        getattr(MPM, cls)(**kwargs)
    assert fragment in str(info.value)
    assert cls in str(info.value)


def test_materials_take_one_number_in_any_form():
    """A number given as a 0-d numpy array or torch tensor (int or float) is taken as a float, as a
    Python or numpy scalar is; an array of one, a bool one and a tensor that requires grad (the
    material is model data: set_material_params is differentiable) are refused by name."""
    for E in (2e5, 200000, np.float32(2e5), np.array(2e5), np.array(200000), torch.tensor(2e5), torch.tensor(200000)):
        material = MPM.Elastic(E=E)
        assert material.E == 2e5 and type(material.E) is float, repr(E)
    rigid = gs.materials.Rigid(rho=np.array(500.0), friction=torch.tensor(0.5))
    assert (rigid.rho, rigid.friction) == (500.0, 0.5) and type(rigid.friction) is float
    for bad in (np.array([2e5]), np.array(True), torch.tensor(True), torch.ones(1)):
        with pytest.raises(gs.InvalidInputError, match="argument 'E' must be a positive finite number"):
            MPM.Elastic(E=bad)
    with pytest.raises(gs.GradientError, match="materials.MPM.Elastic: argument 'E' is not differentiable"):
        MPM.Elastic(E=torch.tensor(2e5, requires_grad=True))
    with pytest.raises(gs.GradientError, match="materials.Rigid: argument 'friction' is not differentiable"):
        gs.materials.Rigid(friction=torch.tensor(0.5, requires_grad=True))


def test_mpm_options(caplog):
    options = gs.options.MPMOptions()
    for key, value in OPTIONS_DEFAULTS.items():
        assert getattr(options, key) == value, key
    assert options.boundary_condition == "slip"
    assert gs.options.MPMOptions(grid_density=128).particle_size == pytest.approx(0.005)
    assert gs.options.MPMOptions(grid_density=128, particle_size=0.02).particle_size == 0.02
    lower, upper = gs.options.MPMOptions(grid_density=100).wall_bounds()
    np.testing.assert_allclose(lower, [-0.97, -0.97, 0.03])
    np.testing.assert_allclose(upper, [0.97, 0.97, 0.97])
    sim = gs.options.SimOptions(dt=1e-2)
    assert options.substeps(sim) == 1
    assert options.substeps(gs.options.SimOptions(dt=1e-2, substeps=4)) == 4
    assert gs.options.MPMOptions(dt=1e-3).substeps(sim) == 10
    assert gs.options.MPMOptions(dt=2.5e-3).substeps(gs.options.SimOptions(dt=1e-2, substeps=4)) == 4
    with pytest.raises(gs.InvalidInputError, match="'dt' must divide SimOptions.dt"):
        gs.options.MPMOptions(dt=3e-3).substeps(sim)
    with pytest.raises(gs.InvalidInputError, match="makes 10 substeps per step, but SimOptions.substeps = 5"):
        gs.options.MPMOptions(dt=1e-3).substeps(gs.options.SimOptions(dt=1e-2, substeps=5))
    bad = [({"enable_CPIC": True}, "'enable_CPIC' must be False"), ({"grid_density": 0}, "'grid_density'"),
           ({"particle_size": -0.01}, "'particle_size'"), ({"dt": 0.0}, "'dt'"), ({"gravity": (0, 0)}, "'gravity'"),
           ({"lower_bound": (0, 0, 0), "upper_bound": (1, 1, 0.05)}, "'lower_bound' and 'upper_bound'"),
           ({"lower_bound": "abc"}, "'lower_bound' must be 3 finite numbers, got 'abc'"),
           ({"grid_density": "64"}, "'grid_density'"),
           ({"boundary_condition": "free"}, "'boundary_condition' must be one of ['slip', 'sticky']"),
           ({"sparse": True}, "MPMOptions: argument 'sparse' is unknown"), ({"leaf_block_size": 8.0}, "leaf_block")]
    for kwargs, fragment in bad:
        with pytest.raises(gs.InvalidInputError) as info:
            gs.options.MPMOptions(**kwargs)
        assert fragment in str(info.value) and "MPMOptions" in str(info.value)
    with caplog.at_level(logging.WARNING, logger="genesis_lite"):
        gs.options.MPMOptions(use_sparse_grid=True, leaf_block_size=16)
    assert "'use_sparse_grid' is deprecated" in caplog.text and "'leaf_block_size' is deprecated" in caplog.text


def test_box_morph_corners():
    box = gs.morphs.Box(lower=(0.0, -0.1, 0.2), upper=(0.2, 0.1, 0.3))
    np.testing.assert_allclose(box.pos, [0.1, 0.0, 0.25])
    np.testing.assert_allclose(box.size, [0.2, 0.2, 0.1])
    plain = gs.morphs.Box(pos=(1, 2, 3), size=(0.2, 0.4, 0.6))  # what rigid boxes use is unchanged
    np.testing.assert_allclose(plain.size, [0.2, 0.4, 0.6])
    np.testing.assert_allclose(plain.pos, [1, 2, 3])
    np.testing.assert_allclose(plain.lower, [0.9, 1.8, 2.7])
    np.testing.assert_allclose(plain.upper, [1.1, 2.2, 3.3])
    with pytest.raises(gs.InvalidInputError, match="'lower' and 'upper' must be given together"):
        gs.morphs.Box(lower=(0, 0, 0))
    with pytest.raises(gs.InvalidInputError, match="'upper' must exceed 'lower'"):
        gs.morphs.Box(lower=(0, 0, 0), upper=(1, 0, 1))


# -- sampling ---------------------------------------------------------------------------------------------------

P = 0.01  # particle size, m
QUAT = np.array([np.cos(0.3), np.sin(0.3) * 0.6, 0.0, np.sin(0.3) * 0.8])  # a generic rotation
POS = np.array([0.1, -0.2, 0.4])


def _local(points):
    """World points → the shape's frame (inverse of sampling.place with POS, QUAT)."""
    return (points - POS) @ quat_to_mat(QUAT)


@pytest.fixture(scope="module")
def meshes(tmp_path_factory):
    folder = tmp_path_factory.mktemp("meshes")
    ball = trimesh.creation.icosphere(subdivisions=3, radius=0.1)
    ball.export(folder / "ball.obj")
    open_box = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    open_box.update_faces(np.arange(len(open_box.faces)) != 0)  # a hole
    open_box.export(folder / "open_box.stl")
    return {"ball": str(folder / "ball.obj"), "ball_volume": ball.volume, "open": str(folder / "open_box.stl")}


@pytest.mark.parametrize("sampler", ["regular", "random"])
def test_sampled_volume_and_inside(sampler, meshes):
    cases = [("box", {"size": (0.2, 0.1, 0.15)}, 0.2 * 0.1 * 0.15,
              lambda x: np.all(np.abs(x) <= [0.1, 0.05, 0.075], 1)),
             ("box", {"size": (0.123, 0.077, 0.2)}, 0.123 * 0.077 * 0.2,
              lambda x: np.all(np.abs(x) <= [0.0615, 0.0385, 0.1], 1)),
             ("sphere", {"radius": 0.1}, 4 / 3 * np.pi * 0.1 ** 3, lambda x: np.linalg.norm(x, axis=1) <= 0.1),
             ("cylinder", {"radius": 0.05, "height": 0.2}, np.pi * 0.05 ** 2 * 0.2,
              lambda x: (np.linalg.norm(x[:, :2], axis=1) <= 0.05) & (np.abs(x[:, 2]) <= 0.1)),
             ("mesh", {"file": meshes["ball"]}, meshes["ball_volume"], lambda x: np.linalg.norm(x, axis=1) <= 0.1)]
    for shape, dims, volume, inside in cases:
        world = sampling.sample(shape, P, sampler, seed=3, pos=POS, quat=QUAT, **dims)
        assert world.dtype == np.float64 and world.shape[1] == 3
        assert len(world) * P ** 3 == pytest.approx(volume, rel=0.03), shape
        assert inside(_local(world)).all(), shape
    # the regular lattice is Genesis's: spacing exactly P where the extent is a multiple of it, P/2 from the faces
    box = _local(sampling.sample("box", P, "regular", pos=POS, quat=QUAT, size=(0.2, 0.1, 0.15)))
    assert len(box) == 20 * 10 * 15
    np.testing.assert_allclose(box.min(0), [-0.095, -0.045, -0.07], atol=1e-12)
    np.testing.assert_allclose(np.unique(box[:, 0].round(12))[:2], [-0.095, -0.085], atol=1e-12)


def test_gs_init_seed_seeds_the_random_sampler():
    """gs.init(seed) changes the "random" sampler's draws (the same seed: the same particles, as
    Genesis, whose sampler draws from numpy's seeded global generator); without a seed a scene
    samples the same particles in every run; a seed that is not an int in [0, 2**32) is refused."""
    def sand(**init):
        gs.init(precision="64", logging_level="warning", **init)
        scene = gs.Scene(mpm_options=gs.options.MPMOptions(lower_bound=(-0.2, -0.2, 0.0), upper_bound=(0.2, 0.2, 0.3)))
        scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.1), size=(0.05, 0.05, 0.05)),
                         material=MPM.Sand(sampler="random"))
        return scene.entities[0].init_particles
    unseeded, zero, one, two = sand(), sand(seed=0), sand(seed=1), sand(seed=2)
    np.testing.assert_array_equal(one, sand(seed=1))
    np.testing.assert_array_equal(unseeded, sand())
    assert not any(np.array_equal(a, b) for a, b in ((one, two), (unseeded, one), (unseeded, zero), (zero, one)))
    for seed in (-1, 2**32, 1.5, True):
        with pytest.raises(gs.InvalidInputError,
                           match=r"gs.init: argument 'seed' must be None or an int in \[0, 2\*\*32\)"):
            gs.init(precision="64", seed=seed)


def test_random_sampler_is_seeded_and_mesh_errors(meshes):
    one = sampling.sample("sphere", P, "random", seed=1, radius=0.05)
    np.testing.assert_array_equal(one, sampling.sample("sphere", P, "random", seed=1, radius=0.05))
    assert not np.array_equal(one[:10], sampling.sample("sphere", P, "random", seed=2, radius=0.05)[:10])
    with pytest.raises(gs.AssetError, match="open_box.stl' is not watertight"):
        sampling.sample("mesh", P, "regular", file=meshes["open"])
    with pytest.raises(gs.AssetError, match="does not exist"):
        sampling.sample("mesh", P, "regular", file="/nonexistent.obj")
    # a shape smaller than a particle: one candidate, in the middle on the lattice (Genesis's sits at
    # lower + p/2, outside this sphere), anywhere in the bounding box at random (seed 0 draws it outside)
    np.testing.assert_array_equal(sampling.sample("sphere", P, "regular", radius=0.004), np.zeros((1, 3)))
    with pytest.raises(gs.InvalidInputError, match="sampling: the sphere holds no particle at particle_size = 0.01"):
        sampling.sample("sphere", P, "random", seed=0, radius=0.004)


def test_sample_particles_from_morphs(meshes):
    walls = (np.array([-0.5, -0.5, 0.0]), np.array([0.5, 0.5, 1.0]))
    box = sample_particles(gs.morphs.Box(lower=(0, 0, 0.1), upper=(0.1, 0.2, 0.3)), MPM.Elastic(), P, *walls, 0,
                           "jelly")
    assert len(box) == 10 * 20 * 20 and np.allclose(box.min(0), [0.005, 0.005, 0.105])
    cyl = sample_particles(gs.morphs.Cylinder(pos=(0, 0, 0.5), radius=0.05, height=0.2, euler=(90, 0, 0)),
                           MPM.Sand(), P, *walls, 0, "pile")
    assert np.ptp(cyl[:, 1]) > 0.18 and np.ptp(cyl[:, 2]) < 0.1  # the axis turned from z to y
    mesh = sample_particles(gs.morphs.Mesh(file=meshes["ball"], pos=(0, 0, 0.5), scale=0.5), MPM.Liquid(), P, *walls,
                            0, "drop")
    assert np.linalg.norm(mesh - [0, 0, 0.5], axis=1).max() <= 0.05
    with pytest.raises(gs.InvalidInputError, match="entity 'low': argument 'morph' must put every particle "
                                                   "strictly inside the MPM walls"):
        sample_particles(gs.morphs.Box(pos=(0, 0, 0.02), size=(0.1, 0.1, 0.1)), MPM.Elastic(), P, *walls, 0, "low")
    for morph in (gs.morphs.Capsule(), gs.morphs.Plane()):
        with pytest.raises(gs.InvalidInputError, match="must be gs.morphs.Box, Sphere, Cylinder or Mesh"):
            sample_particles(morph, MPM.Elastic(), P, *walls, 0, "bad")
    with pytest.raises(gs.InvalidInputError, match="entity 'pinned': argument 'fixed' of gs.morphs.Box must be False "
                                                   "for an MPM entity"):
        sample_particles(gs.morphs.Box(pos=(0, 0, 0.5), size=(0.1, 0.1, 0.1), fixed=True), MPM.Elastic(), P, *walls,
                         0, "pinned")
    with pytest.raises(gs.AssetError, match="entity 'leaky': argument 'file' of gs.morphs.Mesh: .*not watertight"):
        sample_particles(gs.morphs.Mesh(file=meshes["open"], pos=(0, 0, 0.5)), MPM.Elastic(), P, *walls, 0, "leaky")



def test_particles_too_coarse_for_their_shape_warn(meshes, caplog):
    """Particles whose volume (count · particle_size³, which makes the mass) is off the morph's by
    more than 2× warn, naming entity, morph, ratio and a particle_size that fits; the shapes'
    volumes (sampling.shape_volume) are exact, a mesh's from its surface."""
    walls = (np.array([-0.5, -0.5, 0.0]), np.array([0.5, 0.5, 1.0]))
    assert sampling.shape_volume("mesh", file=meshes["ball"], scale=(1.0, 2.0, -0.5)) == pytest.approx(
        meshes["ball_volume"])
    assert sampling.shape_volume("cylinder", radius=0.1, height=0.3) == pytest.approx(np.pi * 0.003)
    cases = [(gs.morphs.Box(pos=(0, 0, 0.5), size=(0.3, 0.3, 0.3)), 0.2, "1 particle(s) of particle_size 0.2 m hold "
              "0.296× the volume of its Box (0.027 m³)"),
             (gs.morphs.Sphere(pos=(0, 0, 0.5), radius=0.04), 0.05, "8 particle(s)"),
             (gs.morphs.Mesh(file=meshes["ball"], pos=(0, 0, 0.5)), 0.12, "8 particle(s)")]
    for morph, size, fragment in cases:
        with warns(caplog, r"entity 'coarse': its .*too coarse.*at most") as found:
            sample_particles(morph, MPM.Elastic(), size, *walls, 0, "coarse")
        assert fragment in found[0], found[0]
    with warns(caplog, None):
        for morph, size, _ in cases:
            sample_particles(morph, MPM.Elastic(), size / 4, *walls, 0, "fine")
    # two box shells overlapping: the volume counts the overlap twice, ray parity leaves it empty
    # (0.39× then; offset along every axis: rays along coplanar faces hit them either way, and the
    # count of a shift along x alone varied from 0.26× to 0.6× between runs)
    box = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    path = os.path.join(os.path.dirname(meshes["ball"]), "shells.obj")
    trimesh.util.concatenate([box, box.copy().apply_translation((0.02, 0.013, 0.011))]).export(path)
    with warns(caplog, "too coarse for the shape or its surface overlaps itself"):
        sample_particles(gs.morphs.Mesh(file=path, pos=(0, 0, 0.5)), MPM.Elastic(), 0.005, *walls, 0, "shells")


# -- the entity, on a fake simulator ------------------------------------------------------------------------------

class FakeSolver:
    """What MPMEntity asks of the MPM solver."""
    wall_lower, wall_upper = np.array([-0.5, -0.5, 0.0]), np.array([0.5, 0.5, 1.0])
    particle_size = P
    checked = None

    def check_substep(self, E, nu, rho):
        self.checked = (E, nu, rho)

    def check_speed(self, speed, who):
        pass


class FakeSim:
    """The simulator's state/input interface: (B, N·WIDTH) state, (B, N) per-particle inputs."""
    check_grad_allowed = Simulator.check_grad_allowed

    def __init__(self, n_batch, n_particles, requires_grad=True):
        self.requires_grad = requires_grad
        self.generation = 0  # resets so far
        rows = torch.rand(n_batch, n_particles, layout.WIDTH, dtype=torch.float64)
        rows[..., 0:3] = rows[..., 0:3] * 0.2 + torch.tensor([0.0, 0.0, 0.3], dtype=torch.float64)
        self._state = rows.reshape(n_batch, -1)
        full = lambda value: torch.full((n_batch, n_particles), value, dtype=torch.float64)
        self._inputs = {"E": full(3e5), "nu": full(0.2), "rho": full(1000.0), "actu": full(0.0),
                        "gravity": torch.zeros(n_batch, 3, dtype=torch.float64),
                        "fiber": torch.tensor(layout.DEFAULT_FIBER, dtype=torch.float64).repeat(n_batch, n_particles)}

    def state(self, solver):
        return self._state

    def set_state(self, solver, state, envs=None):
        self._state = state

    def write_state(self, solver, envs, columns, values):
        self._state = replace_columns(self._state, envs, columns, values)

    def inputs(self, solver):
        return self._inputs

    def set_input(self, solver, name, value):
        self._inputs = {**self._inputs, name: value}


class FakeScene:
    def __init__(self, n_envs, sim):
        self.n_envs, self.sim = n_envs, sim

    def _require_built(self, what):
        if self.sim is None:
            raise gs.SceneStateError(f"{what}: call scene.build() first")
        return self.sim


def _scene(n_envs, requires_grad=True, muscle_groups=1):
    """A fake scene holding two entities: a Sand box (particles 0-7) then a Muscle/Elastic box (8-15)."""
    sim = FakeSim(max(1, n_envs), 16, requires_grad)
    scene, solver = FakeScene(n_envs, sim), FakeSolver()
    morph = gs.morphs.Box(pos=(0.0, 0.0, 0.4), size=(0.02, 0.02, 0.02))
    particles = sampling.sample("box", P, "regular", pos=morph.pos, size=morph.size)
    sand = MPMEntity(scene, 0, "sand", morph, MPM.Sand(), None, solver, 0, 8, particles)
    muscle = MPMEntity(scene, 1, "muscle", morph, MPM.Muscle(n_groups=muscle_groups), None, solver, 8, 8, particles)
    return scene, sim, sand, muscle


def _rows(sim):
    return sim.state(None).reshape(sim.state(None).shape[0], -1, layout.WIDTH)


def test_entity_getters(f64):
    for n_envs in (0, 3):
        scene, sim, sand, muscle = _scene(n_envs)
        rows = _rows(sim)
        pos, vel = muscle.get_particles_pos(), muscle.get_particles_vel()
        assert isinstance(pos, gs.Tensor) and pos.scene is scene
        expected = rows[:, 8:16] if n_envs else rows[0, 8:16]
        torch.testing.assert_close(pos, expected[..., 0:3], rtol=0, atol=0)
        torch.testing.assert_close(vel, expected[..., 3:6], rtol=0, atol=0)
        state = muscle.get_state()  # a leading env axis, of 1 without envs, as Genesis's
        every = rows[:, 8:16]
        torch.testing.assert_close(state.F, every[..., 15:24].reshape(*every.shape[:-1], 3, 3), rtol=0, atol=0)
        torch.testing.assert_close(state.C[..., 2, 1], every[..., 6 + 7], rtol=0, atol=0)  # row-major
        assert state.Jp.shape == (max(1, n_envs), 8) and state.pos.shape == (max(1, n_envs), 8, 3)
        assert muscle.n_particles == 8 and muscle.particle_end == 16
    scene, sim, sand, muscle = _scene(3)
    assert sand.get_particles_pos(envs_idx=[2, 0]).shape == (2, 8, 3)
    torch.testing.assert_close(sand.get_particles_pos(envs_idx=[2]), _rows(sim)[[2], 0:8, 0:3])
    assert sand.get_mass().shape == (3,) and float(sand.get_mass()[0]) == pytest.approx(8 * 1000.0 * P ** 3)
    scene.sim = None
    with pytest.raises(gs.SceneStateError, match="entity 'sand': call scene.build"):
        sand.get_particles_pos()


def test_set_particles_pos_resets_and_differentiates(f64):
    scene, sim, sand, muscle = _scene(2)
    before = _rows(sim).clone()
    target = (torch.rand(2, 3, 3, dtype=torch.float64) * 0.1 + 0.3).requires_grad_()
    sand.set_particles_pos(target, particles_idx_local=[1, 4, 6])
    after = _rows(sim)
    torch.testing.assert_close(after[:, [1, 4, 6], 0:3], target.detach())
    assert (after[:, [1, 4, 6], 3:15] == 0).all()  # vel, C
    np.testing.assert_array_equal(after[:, [1, 4, 6], 15:24].detach().numpy(), np.tile(np.eye(3).ravel(), (2, 3, 1)))
    assert (after[:, [1, 4, 6], 24] == 0).all()  # Sand's rest Jp is 0
    untouched = [k for k in range(16) if k not in (1, 4, 6)]
    torch.testing.assert_close(after[:, untouched], before[:, untouched], rtol=0, atol=0)
    weights = torch.rand(2, 8, 3, dtype=torch.float64)
    grad, = torch.autograd.grad((sand.get_particles_pos() * weights).sum(), target)
    torch.testing.assert_close(grad, weights[:, [1, 4, 6]])
    # one env, every particle, and a value for every env
    sand.set_particles_pos(torch.full((8, 3), 0.3, dtype=torch.float64), envs_idx=[1])
    assert (_rows(sim)[1, 0:8, 0:3] == 0.3).all() and not (_rows(sim)[0, 0:8, 0:3] == 0.3).all()
    muscle.set_particles_pos([0.1, 0.1, 0.5])
    assert (_rows(sim)[:, 8:16, 0:3] == torch.tensor([0.1, 0.1, 0.5], dtype=torch.float64)).all()
    assert (_rows(sim)[:, 8:16, 24] == 1).all()  # an elastic body's rest Jp is 1


def test_set_position_velocity(f64):
    scene, sim, sand, muscle = _scene(0)
    centre = torch.tensor([0.1, -0.1, 0.6], dtype=torch.float64, requires_grad=True)
    sand.set_position(centre)
    expected = torch.as_tensor(sand.init_particles) - torch.tensor([0.0, 0.0, 0.4], dtype=torch.float64) + centre
    torch.testing.assert_close(sand.get_particles_pos(), expected)
    grad, = torch.autograd.grad(sand.get_particles_pos()[:, 2].sum(), centre)
    torch.testing.assert_close(grad, torch.tensor([0.0, 0.0, 8.0], dtype=torch.float64))
    sand.set_position(centre.detach()[None])  # (1, 3) in a scene without envs: a centre (as Genesis)
    torch.testing.assert_close(sand.get_particles_pos(), expected.detach(), rtol=0, atol=0)
    per_particle = torch.rand(8, 3, dtype=torch.float64) * 0.1 + 0.3
    sand.set_position(per_particle)
    torch.testing.assert_close(sand.get_particles_pos(), per_particle)
    velocity = torch.tensor([0.0, 1.0, -2.0], dtype=torch.float64, requires_grad=True)
    muscle.set_velocity(velocity)
    torch.testing.assert_close(muscle.get_particles_vel(), velocity.detach().expand(8, 3))
    grad, = torch.autograd.grad(muscle.get_particles_vel().sum(), velocity)
    torch.testing.assert_close(grad, torch.full((3,), 8.0, dtype=torch.float64))
    batched_scene, batched_sim, batched_sand, _ = _scene(2)
    batched_sand.set_position([[0.0, 0.0, 0.3], [0.0, 0.0, 0.7]])  # one centre per env
    torch.testing.assert_close(batched_sand.get_particles_pos()[:, :, 2].mean(1),
                               torch.tensor([0.3, 0.7], dtype=torch.float64))
    per_env = torch.tensor([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0]], dtype=torch.float64)
    batched_sand.set_velocity(per_env)  # one velocity per env (Genesis's broadcast_tensor)
    torch.testing.assert_close(batched_sand.get_particles_vel(), per_env[:, None].expand(2, 8, 3))
    batched_sand.set_particles_vel(per_env[[1]], particles_idx_local=[0, 3], envs_idx=[0])
    torch.testing.assert_close(batched_sand.get_particles_vel()[0, [0, 3]], per_env[[1, 1]])
    # no env selected (RL code passes done.nonzero()[:, 0], empty on most steps): nothing changes
    before = _rows(batched_sim).clone()
    none = torch.zeros(0, dtype=torch.long)
    batched_sand.set_particles_vel([0.0, 0.0, 5.0], envs_idx=none)
    batched_sand.set_particles_pos(torch.zeros(0, 8, 3), envs_idx=none)
    batched_sand.set_position([0.0, 0.0, 0.3], envs_idx=[])
    torch.testing.assert_close(_rows(batched_sim), before, rtol=0, atol=0)


def test_entity_state_errors(f64):
    scene, sim, sand, muscle = _scene(2)
    on_walls = torch.tensor([[-0.5, 0.5, 0.0], [0.5, -0.5, 1.0]], dtype=torch.float64).repeat(4, 1)
    sand.set_particles_pos(on_walls)  # where the solver keeps particles that reach a wall: accepted
    assert torch.equal(sand.get_particles_pos(), on_walls.expand(2, 8, 3))
    cases = [(lambda: sand.set_particles_pos(torch.full((2, 8, 3), -0.6, dtype=torch.float64)), gs.InvalidInputError,
              "entity 'sand': argument 'poss' must put every particle inside the MPM walls (or on them)"),
             # (the message names set_position's argument and the value given, not set_particles_pos's)
             (lambda: sand.set_position([0.0, 0.0, 0.999]), gs.InvalidInputError,
              "entity 'sand': argument 'value' must put every particle inside the MPM walls"),
             (lambda: sand.set_position([[0.0, 0.0, 0.3]] * 3), gs.InvalidInputError,
              "entity 'sand': argument 'value' must have shape (2, 3) or (3,) for every env (or one that broadcasts "
              "to it), got (3, 3)"),
             (lambda: sand.set_particles_vel(torch.zeros(3, 8, 3)), gs.InvalidInputError,
              "entity 'sand': argument 'vels' must have shape (2, 8, 3)"),
             (lambda: sand.set_particles_vel(torch.zeros(8, 2)), gs.InvalidInputError, "'vels' must have shape"),
             (lambda: sand.set_particles_vel([0.0, float("nan"), 0.0]), gs.InvalidInputError, "'vels' must be finite"),
             (lambda: sand.set_particles_pos(torch.zeros(8, 3), particles_idx_local=[8]), gs.InvalidInputError,
              "'particles_idx_local' must be integers in [-8, 8)"),
             (lambda: sand.get_particles_pos(envs_idx=[2]), gs.InvalidInputError, "'envs_idx' must be integers"),
             (lambda: sand.set_particles_vel(torch.zeros(3, dtype=torch.complex128)), gs.InvalidInputError,
              "complex"),
             # values a float conversion would turn into NaN, 2e5 and 1.0, and a ragged list
             (lambda: sand.set_particles_vel(None), gs.InvalidInputError,
              "entity 'sand': argument 'vels' must be real numbers of shape (2, 8, 3), got NoneType"),
             (lambda: muscle.set_material_params(E="2e5"), gs.InvalidInputError, "'E' must be real numbers"),
             (lambda: muscle.set_material_params(E=True), gs.InvalidInputError, "got bool"),
             (lambda: sand.set_particles_vel([[0.0, 0.0, 1.0], [0.0, 1.0]]), gs.InvalidInputError,
              "'vels' must be numbers of shape (2, 8, 3), got list"),
             (lambda: sand.set_position([0.0, 0.0, 0.3, 1.0]), gs.InvalidInputError,
              "entity 'sand': argument 'value' must be a centre (3,) or (len(envs_idx), 3) or the particles' "
              "positions (8, 3), got (4,)")]
    for call, error, fragment in cases:
        with pytest.raises(error) as info:
            call()
        assert fragment in str(info.value)
    scene, sim, sand, muscle = _scene(0, requires_grad=False)
    with pytest.raises(gs.InvalidInputError, match=r"'value' must be a centre \(3,\) or the particles' positions "
                                                   r"\(8, 3\), got \(2, 3\)"):  # two centres, one env
        sand.set_position([[0.0, 0.0, 0.3], [0.0, 0.0, 0.2]])
    with pytest.raises(gs.GradientError, match="entity 'sand': argument 'vels' requires grad .*requires_grad=True"):
        sand.set_particles_vel(torch.zeros(3, requires_grad=True))
    with pytest.raises(gs.InvalidInputError, match="'envs_idx' must be None in a scene built with n_envs=0"):
        sand.set_velocity([0.0, 0.0, 0.0], envs_idx=[0])


def test_material_params(f64):
    scene, sim, sand, muscle = _scene(2)
    E = torch.tensor(2e5, dtype=torch.float64, requires_grad=True)
    nu = torch.linspace(0.1, 0.3, 8, dtype=torch.float64, requires_grad=True)
    rho = torch.full((2, 8), 500.0, dtype=torch.float64, requires_grad=True)
    muscle.set_material_params(E=E, nu=nu, rho=rho)
    inputs = sim.inputs(None)
    assert (inputs["E"][:, 8:] == 2e5).all() and (inputs["E"][:, :8] == 3e5).all()
    torch.testing.assert_close(inputs["nu"][:, 8:], nu.detach().expand(2, 8))
    torch.testing.assert_close(muscle.get_mass(), torch.full((2,), 8 * 500.0 * P ** 3, dtype=torch.float64))
    loss = (inputs["E"] * 2.0).sum() + (inputs["nu"] ** 2).sum() + muscle.get_mass().sum()
    gE, gnu, grho = torch.autograd.grad(loss, (E, nu, rho))
    assert float(gE) == 2.0 * 16
    torch.testing.assert_close(gnu, 4.0 * nu.detach())
    torch.testing.assert_close(grho, torch.full((2, 8), P ** 3, dtype=torch.float64))
    sand.set_material_params(rho=[[800.0] * 8], envs_idx=[1], particles_idx_local=None)
    assert (sim.inputs(None)["rho"][1, :8] == 800).all() and (sim.inputs(None)["rho"][0, :8] == 1000).all()
    E_checked, nu_checked, rho_checked = sand._solver.checked  # the substep checked against the envs set
    assert E_checked.shape == (1, 8) and (E_checked == 3e5).all() and (rho_checked == 800).all()
    held = {name: value.clone() for name, value in sim.inputs(None).items()}
    for kwargs, fragment in [({"E": 1e5, "nu": 0.5}, "'nu' must be in (−1, 0.5), got values from 0.5"),
                             ({"E": torch.zeros(8)}, "'E' must be > 0 (Pa)"), ({"rho": -1.0}, "'rho' must be > 0"),
                             ({"nu": [-1.0] * 8}, "'nu'"), ({"E": torch.ones(3, 8)}, "'E' must have shape (2, 8)"),
                             ({"rho": float("inf")}, "'rho' must be finite")]:
        with pytest.raises(gs.InvalidInputError) as info:
            sand.set_material_params(**kwargs)
        assert fragment in str(info.value) and "entity 'sand'" in str(info.value)
    for name, value in held.items():  # nothing was written by a call that raised
        torch.testing.assert_close(sim.inputs(None)[name], value, rtol=0, atol=0)


def test_muscle_groups_set_after_the_actuation_take_their_groups_actuation(f64):
    """set_muscle(muscle_group=...) after set_actuation moves each particle to its new group's
    actuation at once, as Genesis (which reads a particle's group at every step; the groups were
    read at set_actuation only, so the call had no effect until the next one), in the graph;
    an env whose actuation a reset cleared keeps none."""
    scene, sim, sand, muscle = _scene(2, muscle_groups=2)
    actu = torch.tensor([[0.5, -0.25], [1.0, 2.0]], dtype=torch.float64, requires_grad=True)
    muscle.set_actuation(actu)
    muscle.set_muscle(muscle_group=np.array([1, 0] * 4))
    per_particle = sim.inputs(None)["actu"]
    torch.testing.assert_close(per_particle[:, 8:], actu.detach()[:, [1, 0] * 4], rtol=0, atol=0)
    grad, = torch.autograd.grad(per_particle[:, 8:].sum(), actu)
    torch.testing.assert_close(grad, torch.full((2, 2), 4.0, dtype=torch.float64))
    sim.generation += 1  # scene.reset(envs_idx=[0]): that env's controls cleared, a new graph
    sim.set_input(None, "actu", torch.cat([torch.zeros(1, 16, dtype=torch.float64), per_particle[1:].detach()]))
    muscle.set_muscle(muscle_group=np.array([1] * 8))
    per_particle = sim.inputs(None)["actu"]
    assert (per_particle[0, 8:] == 0).all() and (per_particle[1, 8:] == 2.0).all()


def test_muscle_actuation(f64):
    scene, sim, sand, muscle = _scene(2, muscle_groups=2)
    fiber = sim.inputs(None)["fiber"].reshape(2, 16, 3)
    assert (fiber == torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)).all()  # Genesis's default
    muscle.set_muscle(muscle_group=np.array([0, 1] * 4), muscle_direction=[2.0, 0.0, 0.0])
    fiber = sim.inputs(None)["fiber"].reshape(2, 16, 3)
    # as given, every env: the active stress grows with its squared length, as Genesis's (it was normalised)
    assert (fiber[:, 8:] == torch.tensor([2.0, 0.0, 0.0], dtype=torch.float64)).all()
    assert (fiber[:, :8] == torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)).all()  # the sand's untouched
    actu = torch.tensor([[0.5, -0.25], [1.0, 2.0]], dtype=torch.float64, requires_grad=True)
    muscle.set_actuation(actu)
    per_particle = sim.inputs(None)["actu"]
    torch.testing.assert_close(per_particle[:, 8:], actu.detach()[:, [0, 1] * 4])
    assert (per_particle[:, :8] == 0).all()
    weights = torch.rand(2, 16, dtype=torch.float64)
    grad, = torch.autograd.grad((per_particle * weights).sum(), actu)
    torch.testing.assert_close(grad, torch.stack([weights[:, 8::2].sum(1), weights[:, 9::2].sum(1)], dim=1))
    muscle.set_actuation(0.3, envs_idx=[1])
    assert (sim.inputs(None)["actu"][1, 8:] == 0.3).all() and (sim.inputs(None)["actu"][0, 8:] != 0.3).any()
    assert muscle.get_muscle_group().tolist() == [0, 1] * 4
    cases = [(lambda: sand.set_actuation([1.0]), "entity 'sand': set_actuation needs a gs.materials.MPM.Muscle entity, "
                                                 "got MPM.Sand"),
             (lambda: sand.set_muscle(muscle_group=[0] * 8), "set_muscle needs a gs.materials.MPM.Muscle"),
             (lambda: muscle.set_actuation([1.0, 2.0, 3.0]), "'actus' must have shape (2, 2)"),
             (lambda: muscle.set_actuation(actus=[np.nan, 0.0]), "'actus' must be finite"),  # (Genesis's name)
             (lambda: muscle.set_muscle(muscle_group=[0, 2] * 4), "'muscle_group' must be 8 integers in [0, 2)"),
             (lambda: muscle.set_muscle(muscle_group=[0.0] * 8), "'muscle_group'"),
             (lambda: muscle.set_muscle(muscle_direction=[np.nan, 0.0, 1.0]), "'muscle_direction' must hold finite"),
             (lambda: muscle.set_muscle(muscle_direction=np.ones((7, 3))), "'muscle_direction' must have shape")]
    for call, fragment in cases:
        with pytest.raises(gs.InvalidInputError) as info:
            call()
        assert fragment in str(info.value)
    # fibres and groups are model data: a tensor that requires grad raises (it was detached without a
    # word: direction.grad stayed None though the loss depends on it; found by an adversarial pass)
    for name, value in (("muscle_direction", torch.ones(3, dtype=torch.float64, requires_grad=True)),
                        ("muscle_group", torch.zeros(8, dtype=torch.float64, requires_grad=True))):
        with pytest.raises(gs.GradientError, match=f"entity 'muscle': argument '{name}' is not differentiable"):
            muscle.set_muscle(**{name: value})
