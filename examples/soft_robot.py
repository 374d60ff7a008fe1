"""Soft robot: a 3-D muscle robot learns to walk forward (+x), by gradients through MPM.

The robot is one ``gs.materials.MPM.Muscle`` body (E = 30 kPa, ν = 0.2, ρ = 1000 kg/m³): a
24 × 12 × 6 cm slab on four 6 cm legs, made of 3 cm blocks. Each leg is two vertical muscles, its
back half and its front half (fibres along z; 8 muscle groups), the slab is passive. The floor is
MPMOptions' sticky wall (DiffTaichi's): a foot pressed on it does not slide, a lifted foot moves
freely, so a leg that bends while it stands pushes the body along.

The actuation of muscle g at time t is DiffTaichi's open-loop pattern

    actu_g(t) = ramp(t) · STRENGTH · tanh(Σ_k W[g, k] · sin(2π t / PERIOD + 2π k / N_WAVES) + bias[g]),

set before every step (a differentiable input); ramp(t) = min(1, t / PERIOD) eases it in over the
first period, so that the robot does not jump at t = 0 (which would make the first steps' lurch,
not the gait, decide where a short rollout ends). The loss is −(x displacement of the centre of mass
after the rollout); Adam fits W (8 × 4) and bias (8,) by back-propagating through every MPM
substep. The first pattern is a weak gait made by hand, every leg's back half a quarter period
ahead of its front half (plus a little seeded noise): it creeps forward about a centimetre.

Settings: float32 (its backward is ~10 % faster than float64's here), a 4 ms step of 8 substeps
(0.5 ms: within the solver's stability limit), grid 32 cells/m, 768 particles 1.5 cm apart, 1 s
rollouts (4 periods of 0.25 s), 30 Adam iterations at lr 0.1. The gradient is that of the rollout
as computed, each floor node's stop-or-free decision held as it was (DiffTaichi's too): the
distance is rough on the scale of micrometres, so finite differences do not reproduce it, yet it
points uphill.

Outputs (in ``--out DIR``, default ./outputs): ``soft_robot.mp4``, the learned gait beside a ruler
(a tick per cm, a post every 5 cm), and ``soft_robot_loss.png``, the distance walked per iteration.

Run:  python examples/soft_robot.py [--short] [--out DIR]     (or GS_EXAMPLES_SHORT=1)
Full mode checks that the distance after the 30th iteration is ≥ 3× the first pattern's (> 0);
short mode (grid 24 cells/m, 0.4 s rollouts, 10 iterations) checks ≥ 2×.
"""
import math
import os
import tempfile
import time

import numpy as np
import torch
import tqdm
import trimesh

import genesis_lite as gs
from example_run import ExampleRun

BLOCK = 0.03  # m: the robot is made of cubes of this edge
BODY = (8, 4, 2)  # blocks along x, y, z: the slab, on top of the legs
LEG = (2, 2, 2)  # blocks: each leg, split along x into a back and a front muscle
LEG_CORNERS = ((0, 0), (6, 0), (0, 2), (6, 2))  # (x, y) block of each leg's back-left corner
PARTICLE = 0.015  # m: particle spacing (half a block: 768 particles)
E, NU, RHO = 3e4, 0.2, 1000.0  # Pa, -, kg/m³: soft, so the elastic wave speed allows 0.5 ms substeps
N_GROUPS = 2 * len(LEG_CORNERS) + 1  # two muscles per leg, then the passive slab
N_WAVES, PERIOD, STRENGTH = 4, 0.25, 0.3  # sine phases, s, the largest |actuation|
STEP = 4e-3  # s per scene step
LEARNING_RATE, SEED = 0.1, 0
RULER_COLOR = (0.8, 0.8, 0.8)  # the ruler drawn on the floor in front of the robot


def main():
    run = ExampleRun(__doc__, __file__)
    density, substeps, n_steps, n_iterations, required = (24, 5, 100, 10, 2.0) if run.short else \
        (32, 8, 250, 30, 3.0)
    start = time.time()
    gs.init(precision="32")
    scene, robot = build_scene(density, substeps)
    camera = run.camera(scene, (0.2, -0.5, 0.12), (0.2, 0.06, 0.05))
    scene.build()
    robot.set_muscle(muscle_group=muscle_groups(robot.get_particles_pos().detach().cpu().numpy()),
                     muscle_direction=(0.0, 0.0, 1.0))
    print(f"built in {time.time() - start:.1f} s: {robot.n_particles} particles, {n_steps} steps of "
          f"{substeps} substeps")

    def rollout(weights, bias, after_step=None):
        """x displacement (a 0-d tensor, m) of the centre of mass after n_steps."""
        scene.reset()
        x0 = robot.get_particles_pos()[:, 0].mean()
        for i in range(n_steps):
            robot.set_actuation(actuation(weights, bias, i * STEP))
            scene.step()
            if after_step is not None:
                after_step()
        return robot.get_particles_pos()[:, 0].mean() - x0

    weights, bias = first_pattern()
    optimizer = torch.optim.Adam([weights, bias], lr=LEARNING_RATE)
    distances = []
    progress = tqdm.tqdm(range(n_iterations), desc="soft robot", unit="iteration")
    for _ in progress:
        optimizer.zero_grad()
        distance = rollout(weights, bias)
        (-distance).backward()
        optimizer.step()
        distances.append(distance.item())
        progress.set_postfix(distance=f"{100 * distance.item():.2f} cm", refresh=False)

    scene.draw_debug_spheres(ruler(), radius=0.002, color=RULER_COLOR)
    distance, video = run.record(camera, lambda after_step: rollout(weights.detach(), bias.detach(), after_step))
    distances.append(distance.item())
    print(f"learned in {time.time() - start:.1f} s: {100 * distances[0]:.2f} cm → {100 * distances[-1]:.2f} cm; "
          f"per iteration (cm): {' '.join(f'{100 * d:.2f}' for d in distances)}")
    plot = run.plot("loss", {"distance": distances}, "Adam iteration (one rollout and its backward each)",
                    "x displacement of the centre of mass (m)", "soft robot: distance walked in "
                    f"{n_steps * STEP:g} s", targets={"distance": required * distances[0]})
    print(f"wrote {video}, {plot}")
    test_final(distances, required)


def build_scene(density, substeps):
    """The scene (MPM only, sticky floor at z = 0, a tight domain around the robot's path) and the
    robot entity; grid ``density`` cells/m, ``substeps`` per STEP."""
    pad = 3.0 / density  # the walls stand 3 cells inside the domain
    size = np.array(BODY) * BLOCK
    options = gs.options.MPMOptions(lower_bound=(-0.1 - pad, -0.03 - pad, -pad),
                                    upper_bound=(size[0] + 0.4 + pad, size[1] + 0.03 + pad, 0.2 + pad),
                                    grid_density=density, particle_size=PARTICLE, boundary_condition="sticky")
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=STEP, substeps=substeps, requires_grad=True),
                     mpm_options=options)
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "robot.obj")
        robot_mesh().export(path)
        robot = scene.add_entity(gs.morphs.Mesh(file=path),
                                 material=gs.materials.MPM.Muscle(E=E, nu=NU, rho=RHO, n_groups=N_GROUPS),
                                 surface=gs.surfaces.Default(color=(0.85, 0.45, 0.3)))
    return scene, robot


def ruler():
    """(n, 3) m: the ticks of a ruler on the floor along the robot's path, 1 cm apart, in front of
    it (y < 0); every 5 cm a post of three ticks, 5 mm apart. The robot starts between x = 0 and
    BODY[0] · BLOCK."""
    ticks = [(0.01 * i, -0.015, 0.005 * k) for i in range(41) for k in range(3 if i % 5 == 0 else 1)]
    return np.array(ticks)


def robot_cells():
    """The robot's blocks: a set of (i, j, k) integer block coordinates (block i spans
    [i, i + 1] · BLOCK on x; the legs are blocks k < LEG[2], the slab sits on them)."""
    cells = {(i, j, LEG[2] + k) for i in range(BODY[0]) for j in range(BODY[1]) for k in range(BODY[2])}
    for i0, j0 in LEG_CORNERS:
        cells |= {(i0 + i, j0 + j, k) for i in range(LEG[0]) for j in range(LEG[1]) for k in range(LEG[2])}
    return cells


def robot_mesh():
    """The robot's closed surface (trimesh, m): every face of a block that no other block covers,
    two triangles each, wound outwards."""
    cells = robot_cells()
    quads = []
    for cell in cells:
        for axis in range(3):
            u, v = np.eye(3)[(axis + 1) % 3], np.eye(3)[(axis + 2) % 3]
            for side in (0, 1):
                neighbour = list(cell)
                neighbour[axis] += 2 * side - 1
                if tuple(neighbour) in cells:
                    continue
                corner = np.array(cell, dtype=np.float64) + side * np.eye(3)[axis]
                quad = [corner, corner + u, corner + u + v, corner + v]  # counter-clockwise seen from +axis
                quads.append(quad if side else quad[::-1])
    vertices = np.array(quads).reshape(-1, 3) * BLOCK
    first = 4 * np.arange(len(quads))[:, None]
    faces = np.concatenate([first + [0, 1, 2], first + [0, 2, 3]])
    return trimesh.Trimesh(vertices, faces, process=True)  # process: merge the shared corners


def muscle_groups(pos):
    """(n,) muscle group of each particle at pos (n, 3) m: leg m's back half 2m, its front half
    2m + 1, the slab N_GROUPS − 1."""
    block = np.floor(pos / BLOCK).astype(np.int64)
    groups = np.full(len(pos), N_GROUPS - 1)
    for m, (i0, j0) in enumerate(LEG_CORNERS):
        i, j, k = block[:, 0] - i0, block[:, 1] - j0, block[:, 2]
        in_leg = (0 <= i) & (i < LEG[0]) & (0 <= j) & (j < LEG[1]) & (k < LEG[2])
        groups[in_leg] = 2 * m + (i[in_leg] >= LEG[0] // 2)
    return groups


def actuation(weights, bias, t):
    """(N_GROUPS,) actuation at time t s: the open-loop pattern of the docstring for the leg
    muscles (weights (N_GROUPS − 1, N_WAVES), bias (N_GROUPS − 1,)), 0 for the slab."""
    phases = 2 * math.pi * (t / PERIOD + torch.arange(N_WAVES, dtype=weights.dtype) / N_WAVES)
    legs = min(1.0, t / PERIOD) * STRENGTH * torch.tanh(weights @ torch.sin(phases) + bias)
    return torch.cat([legs, legs.new_zeros(1)])


def first_pattern():
    """(weights (N_GROUPS − 1, N_WAVES), bias (N_GROUPS − 1,)), leaves that require grad: the
    hand-made first gait, every leg's back muscle on the wave k = 0 and its front muscle on k = 3
    (a quarter period behind), plus noise of standard deviation 0.1 seeded by SEED."""
    generator = torch.Generator().manual_seed(SEED)
    weights = 0.1 * torch.randn(N_GROUPS - 1, N_WAVES, generator=generator, dtype=gs.tc_float)
    weights[0::2, 0] += 1.0
    weights[1::2, 3] += 1.0
    return weights.requires_grad_(), torch.zeros(N_GROUPS - 1, dtype=gs.tc_float, requires_grad=True)


def test_final(distances, required):
    """The example's check: every distance finite, the first one forward (> 0) and the last
    ≥ required × the first."""
    if not all(math.isfinite(d) for d in distances):
        raise AssertionError(f"a distance is not finite: {distances}")
    if not (distances[0] > 0 and distances[-1] >= required * distances[0]):
        raise AssertionError(f"the robot must walk forward (first distance > 0) and ≥ {required:g}× further after "
                             f"learning: {distances[0]:.4f} m → {distances[-1]:.4f} m")
    print(f"soft robot OK (walks {distances[-1] / distances[0]:.1f}× further than at first, ≥ {required:g}×)")


if __name__ == "__main__":
    main()
