"""Trajectory optimisation: the "轨迹优化" example of Genesis's differentiable-simulation page.

A two-link pendulum (``assets/pendulum2.urdf``, fixed base, swinging about y under gravity)
starts hanging at rest. We optimise its whole joint-torque sequence, ``controls`` of shape
(n_steps, n_dofs), with Adam so that the tip of the second link is at ``target`` at the end of
the rollout. Every epoch resets the scene (a fresh autograd graph), replays the controls,
computes the loss and back-propagates through all ``n_steps`` steps.

The tip is 0.4 m down the second link's frame (where its sphere is); its world position is
computed in torch from the link's pose by ``point_on_link`` (pos + rotate(quat, offset)): any
torch code on simulator outputs is differentiated through.

Settings (chosen for a robust ≥ 100× loss drop in 100 epochs): dt = 0.01 s, 100 steps,
float64, Adam lr = 0.1 N·m. The page uses lr = 0.01; with torques of a few N·m needed to lift
the pendulum, that needs far more epochs.

Outputs (in ``--out DIR``, default ./outputs): ``trajectory_optimization.mp4``, the optimised
rollout (the target is the green sphere), and ``trajectory_optimization_loss.png``, the loss per
epoch.

Run:  python examples/trajectory_optimization.py [--short] [--out DIR]     (or GS_EXAMPLES_SHORT=1)
Full mode checks loss(last) ≤ loss(first) / 100; short mode (20 epochs) checks a 10× drop.
"""
import os
import time

import torch
import tqdm

import genesis_lite as gs
from example_run import PENDULUM_VIEW, TARGET_COLOR, ExampleRun, check_loss_drop, point_on_link

ASSETS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "assets")


def main():
    run = ExampleRun(__doc__, __file__)
    n_epochs, required_drop = (20, 10.0) if run.short else (100, 100.0)
    start = time.time()
    gs.init(precision="64")

    scene = gs.Scene(
        sim_options=gs.options.SimOptions(
            dt=0.01,
            requires_grad=True,
        ),
    )
    robot = scene.add_entity(gs.morphs.URDF(file=os.path.join(ASSETS, "pendulum2.urdf"), fixed=True))
    camera = run.camera(scene, *PENDULUM_VIEW)
    scene.build()
    print(f"built in {time.time() - start:.1f} s")

    # optimise the control sequence
    n_steps = 100
    n_dofs = robot.n_dofs
    controls = torch.zeros(n_steps, n_dofs, requires_grad=True, device=gs.device, dtype=gs.tc_float)
    optimizer = torch.optim.Adam([controls], lr=0.1)
    target = torch.tensor([0.5, 0.1, -0.5], device=gs.device, dtype=gs.tc_float)
    link = robot.get_link("link2")
    tip_offset = torch.tensor([0.0, 0.0, -0.4], device=gs.device, dtype=gs.tc_float)

    def rollout(after_step=None):
        """Replay ``controls`` from rest; the tip's final world position (3,). after_step: called
        after every step (the video's frames)."""
        scene.reset()
        for t in range(n_steps):
            robot.control_dofs_force(controls[t])
            scene.step()
            if after_step is not None:
                after_step()
        return point_on_link(link, tip_offset)

    losses = []
    progress = tqdm.trange(n_epochs, desc="trajectory optimisation", unit="epoch")
    for _ in progress:
        # forward simulation, loss on the final tip position
        final_pos = rollout()
        loss = torch.nn.functional.mse_loss(final_pos, target)
        # optimise
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
        progress.set_postfix(loss=f"{loss.item():.3e}")
    progress.close()
    print(f"loss {losses[0]:.4e} → {losses[-1]:.4e} ({losses[0] / losses[-1]:.0f}× lower) "
          f"in {n_epochs} epochs, {time.time() - start:.1f} s in all")

    # what to look at: the optimised rollout, the loss curve
    scene.draw_debug_sphere(target, radius=0.03, color=TARGET_COLOR)  # the tip (0.04) covers it
    final_pos, video = run.record(camera, rollout)
    plot = run.plot("loss", {"loss": losses}, "epoch", "loss (m², mean squared tip error)",
                    f"trajectory optimisation: Adam on {n_steps} × {n_dofs} joint torques", log_y=True)
    print(f"optimised tip {final_pos.cpu().numpy().round(4)} (target {target.cpu().numpy()}); wrote {video}, {plot}")
    check_loss_drop(losses, required_drop, "trajectory optimisation")


if __name__ == "__main__":
    main()
