"""Sand push: optimise a paddle's path so that it pushes a sand pile onto a target.

A blade (a rigid box, 5 × 14 × 8 cm, 1 kg) on an x–y carriage (two slide joints,
``assets/mjcf/paddle.xml``) stands 2 mm above a rigid ground plane, behind a pile of sand (a 10 cm
square, 6 cm high: ``gs.materials.MPM.Sand``, Drucker–Prager, friction angle 30°). The carriage's
position servos (kp 2000 N/m, kv 90 N·s/m) track a path through ``N_WAYPOINTS`` waypoints, passed in
equal times (linear in between), from the blade's start. We optimise the waypoints so that the
sand's centre ends, after ``n_steps`` steps, at ``TARGET`` (x, y) on the ground. The blade moves
the sand only through the two-way rigid–MPM coupling of a moving link (Genesis's rule: the
particles meet the moving blade, and the momentum they lose pushes it back through its joints),
and the sand slides on the coupled ground: every gradient flows from the servo targets through
the servos, the rigid dynamics, the coupling and the sand's plasticity, back through every substep.

Settings: dt = 2 ms in 5 substeps, float64, 40 cells/m (320 particles of 1.25 cm); Adam with a
decaying step, each iteration one rollout and its backward. (L-BFGS's line search took steps of
metres here, and the pile flew.)

Outputs (in ``--out DIR``, default ./outputs): ``sand_push.mp4``, the optimised push (the target
is the green sphere), and ``sand_push_loss.png``, the loss per iteration.

Run:  python examples/sand_push.py [--short] [--out DIR]     (or GS_EXAMPLES_SHORT=1)
Full mode (200 steps, 20 rollouts) checks loss(last) ≤ loss(first) / 100; short mode (100 steps,
10 rollouts) a 10× drop.
"""
import os
import time

import torch
import tqdm

import genesis_lite as gs
from example_run import TARGET_COLOR, ExampleRun, check_loss_drop

PADDLE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "assets", "mjcf", "paddle.xml")
START = (-0.12, 0.0)  # m: the blade's start (x, y), behind the pile centred at the origin
TARGET = (0.2, 0.06)  # m: where the sand's centre should end (x, y)
N_WAYPOINTS = 4
KP, KV = 2000.0, 90.0  # the carriage's servo gains, N/m and N·s/m
# Adam: each waypoint moves by about LEARNING_RATE m in the first iteration, DECAY times less in each
# next; its momentum low (β1 0.5): with the default 0.9 it carried the waypoints past the optimum
LEARNING_RATE, DECAY, BETAS = 0.03, 0.85, (0.5, 0.99)


def waypoint_path(waypoints, n_steps):
    """(n_steps, 2) servo targets (the carriage's dofs: displacement from the start, m): from 0
    through the rows of ``waypoints`` (N, 2), each reached after an equal share of the steps,
    linear in between (differentiable in ``waypoints``)."""
    points = torch.cat([waypoints.new_zeros(1, 2), waypoints])
    t = torch.arange(1, n_steps + 1, dtype=waypoints.dtype, device=waypoints.device) / n_steps * len(waypoints)
    first = t.floor().long().clamp(max=len(waypoints) - 1)
    share = (t - first).unsqueeze(1)
    return (1.0 - share) * points[first] + share * points[first + 1]


def main():
    run = ExampleRun(__doc__, __file__)
    n_steps, n_iterations, required_drop = (100, 10, 10.0) if run.short else (200, 20, 100.0)
    start = time.time()
    gs.init(precision="64")
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=2e-3, substeps=5, requires_grad=True),
                     mpm_options=gs.options.MPMOptions(lower_bound=(-0.3, -0.3, -0.1), upper_bound=(0.5, 0.3, 0.3),
                                                       grid_density=40, particle_size=0.0125))
    scene.add_entity(gs.morphs.Plane(), material=gs.materials.Rigid(coup_friction=0.5))
    paddle = scene.add_entity(gs.morphs.MJCF(file=PADDLE, pos=(*START, 0.0)),
                              material=gs.materials.Rigid(coup_friction=0.3),
                              surface=gs.surfaces.Default(color=(0.35, 0.45, 0.6)))
    sand = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.035), size=(0.1, 0.1, 0.06)),
                            material=gs.materials.MPM.Sand(friction_angle=30.0),
                            surface=gs.surfaces.Default(color=(0.85, 0.7, 0.4)))
    camera = run.camera(scene, (0.1, -0.75, 0.45), (0.1, 0.0, 0.0))
    scene.build()
    f = gs.tc_float
    paddle.set_dofs_kp(torch.full((2,), KP, dtype=f, device=gs.device))
    paddle.set_dofs_kv(torch.full((2,), KV, dtype=f, device=gs.device))
    print(f"built in {time.time() - start:.1f} s: {sand.n_particles} particles of sand, {n_steps} steps a rollout")

    target = torch.tensor(TARGET, dtype=f, device=gs.device)
    # the first guess: straight ahead, 20 cm in all
    waypoints = torch.zeros(N_WAYPOINTS, 2, dtype=f, device=gs.device)
    waypoints[:, 0] = torch.linspace(0.05, 0.2, N_WAYPOINTS, dtype=f)
    waypoints.requires_grad_(True)
    optimizer = torch.optim.Adam([waypoints], lr=LEARNING_RATE, betas=BETAS)
    # smaller steps as the pile nears the target: the push's landscape is rough at a grain's scale
    schedule = torch.optim.lr_scheduler.ExponentialLR(optimizer, gamma=DECAY)

    def rollout(after_step=None):
        """Push along the waypoints' path from the start; the sand's centre (3,) after n_steps steps."""
        scene.reset()
        for servo_target in waypoint_path(waypoints, n_steps):
            paddle.control_dofs_position(servo_target)
            scene.step()
            if after_step is not None:
                after_step()
        return sand.get_particles_pos().mean(dim=0)

    losses = []
    progress = tqdm.tqdm(total=n_iterations, desc="sand push", unit="rollout")

    for _ in range(n_iterations):
        optimizer.zero_grad()
        loss = ((rollout()[:2] - target) ** 2).sum()
        loss.backward()
        optimizer.step()
        schedule.step()
        losses.append(loss.item())
        progress.set_postfix(loss=f"{loss.item():.3e}", refresh=False)
        progress.update()
    progress.close()
    print(f"loss {losses[0]:.4e} → {min(losses):.4e} in {len(losses)} rollouts, {time.time() - start:.1f} s in all; "
          f"waypoints (m from the start) {waypoints.detach().cpu().numpy().round(3).tolist()}")

    scene.draw_debug_sphere(torch.cat([target, target.new_tensor([0.03])]), radius=0.015, color=TARGET_COLOR)
    centre, video = run.record(camera, rollout)
    plot = run.plot("loss", {"loss": losses}, "Adam iteration (one rollout and its backward each)",
                    "loss (m², squared distance to the target)", "sand push: Adam on the paddle's path",
                    log_y=True)
    print(f"the sand's centre ends at {centre.cpu().numpy().round(4)} (target {TARGET}); wrote {video}, {plot}")
    check_loss_drop(losses, required_drop, "sand push")


if __name__ == "__main__":
    main()
