"""Pushing a box: optimise a robot arm's joint torques through its contacts with a box.

pybullet_data's KUKA iiwa (fixed base, on a plane; its links collide as the convex hulls of their
meshes) starts bent down, its flange (link 7, a disk of radius 52 mm pointing down) 0.3 mm beside
a 20 × 20 × 10 cm box (1.2 kg) lying on the plane; every contact has friction 0.3. Every step the
arm gets the joint torques

    τ_t = hold + SCALE · controls[t] + KP · (Q0 − q_t)

where ``hold`` holds the start pose Q0 against gravity (``−robot.get_dofs_force()`` after a step
from rest), the proportional term (torch, on the simulator's state) keeps the arm's shape, and
SCALE (N·m per unit, per joint) puts the controls of the strong shoulder joints and of the light
wrist on one scale: Adam moves every entry by about lr. We optimise the whole sequence ``controls`` of shape
(n_steps, 7) so that the box ends at ``target`` on the plane. It starts as a constant torque on
the base joint: the arm swings and its flange pushes the box sideways, but not far enough. The
loss only depends on the box, so every gradient flows through the arm–box contacts (the convex
collider between the flange's hull and the box) and the box's contacts with the plane; each
epoch resets the scene, replays the controls and back-propagates through all ``n_steps`` steps.

Pushing a box with a round tool is touchy: the box turns one way or the other at the slightest
change (the loss curve is not smooth). Low friction keeps the box sliding (no stick-slip), and the
learning rate decays to zero (cosine) so that the last epochs settle.

Settings: dt = 0.01 s, 100 steps (1 s), float64, pyramidal friction cone (Genesis's default),
Adam lr = 0.02 (0.2 N·m on the shoulder), cosine decay over the epochs.

Outputs (in ``--out DIR``, default ./outputs): ``push_box.mp4``, the optimised rollout (the target
is the green sphere), and ``push_box_loss.png``, the loss per epoch.

Run:  python examples/push_box.py [--short] [--out DIR]     (or GS_EXAMPLES_SHORT=1)
Full mode (40 epochs) checks loss(last) ≤ loss(first) / 10; short mode (10 epochs) checks a 2× drop.
"""
import os
import time

import pybullet_data
import torch
import tqdm

import genesis_lite as gs
from example_run import TARGET_COLOR, ExampleRun, check_loss_drop

KUKA = os.path.join(pybullet_data.getDataPath(), "kuka_iiwa", "model.urdf")
Q0 = (0.0, 1.26232841, 0.0, -1.35617325, 0.0, 0.52309098, 0.0)  # rad: the flange points down at (0.6, 0, 0.06) m
KP = (0.0, 300.0, 100.0, 300.0, 30.0, 30.0, 0.0)  # N·m/rad: holds the arm's shape, not the base joint
DAMPING = (5.0, 5.0, 2.0, 5.0, 1.0, 1.0, 0.2)  # N·m·s/rad
SCALE = (10.0, 10.0, 5.0, 5.0, 1.0, 1.0, 0.2)  # N·m per unit of the controls
BOX_HALF = (0.1, 0.1, 0.05)  # m
BOX_POS = (0.6, 0.052 + BOX_HALF[1] + 3e-4, BOX_HALF[2])  # m: 0.3 mm beside the flange's disk (radius 52 mm)
FRICTION = 0.3  # of every shape (a contact takes the larger of its two)
PUSH = 4.0  # N·m on the base joint to start with: the box slides from about 2 N·m


def main():
    run = ExampleRun(__doc__, __file__)
    n_epochs, required_drop = (10, 2.0) if run.short else (40, 10.0)
    start = time.time()
    gs.init(precision="64")

    scene = gs.Scene(
        sim_options=gs.options.SimOptions(
            dt=0.01,
            requires_grad=True,
        ),
    )
    scene.add_entity(gs.morphs.Plane(), material=gs.materials.Rigid(friction=FRICTION))
    robot = scene.add_entity(gs.morphs.URDF(file=KUKA, fixed=True), material=gs.materials.Rigid(friction=FRICTION))
    box = scene.add_entity(gs.morphs.Box(size=tuple(2 * h for h in BOX_HALF), pos=BOX_POS),
                           material=gs.materials.Rigid(rho=300.0, friction=FRICTION),
                           surface=gs.surfaces.Default(color=(0.85, 0.6, 0.3)))  # wood, apart from the grey floor
    camera = run.camera(scene, pos=(1.6, -0.6, 0.95), lookat=(0.4, 0.2, 0.22))
    scene.build()
    print(f"built in {time.time() - start:.1f} s")

    # the start pose (scene.reset() returns to it) and the torques holding it against gravity
    q0, kp, scale = (torch.tensor(v, device=gs.device, dtype=gs.tc_float) for v in (Q0, KP, SCALE))
    robot.set_dofs_damping(torch.tensor(DAMPING, device=gs.device, dtype=gs.tc_float))
    robot.set_dofs_position(q0)
    start_state = scene.get_state()
    scene.step()  # from rest without controls: the step's dofs force is gravity's alone (nothing touches)
    hold = -robot.get_dofs_force()
    scene.reset(start_state)

    # optimise the torque sequence on top of the hold
    n_steps = 100
    controls = torch.zeros(n_steps, robot.n_dofs, device=gs.device, dtype=gs.tc_float)
    controls[:, 0] = PUSH / SCALE[0]
    controls.requires_grad_(True)
    optimizer = torch.optim.Adam([controls], lr=0.02)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, n_epochs)
    target = torch.tensor([0.62, 0.40], device=gs.device, dtype=gs.tc_float)  # m, on the plane

    def rollout(after_step=None):
        """Replay ``controls`` from the start pose; the box's final position (3,). after_step:
        called after every step (the video's frames)."""
        scene.reset()
        for t in range(n_steps):
            robot.control_dofs_force(hold + scale * controls[t] + kp * (q0 - robot.get_dofs_position()))
            scene.step()
            if after_step is not None:
                after_step()
        return box.get_pos()

    losses = []
    progress = tqdm.trange(n_epochs, desc="push box", unit="epoch")
    for _ in progress:
        # forward simulation, loss on where the box ends
        final_pos = rollout()
        loss = torch.nn.functional.mse_loss(final_pos[:2], target)
        # optimise
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        schedule.step()
        losses.append(loss.item())
        progress.set_postfix(loss=f"{loss.item():.3e}")
    progress.close()
    print(f"loss {losses[0]:.4e} → {losses[-1]:.4e} ({losses[0] / losses[-1]:.0f}× lower) "
          f"in {n_epochs} epochs, {time.time() - start:.1f} s in all")

    # what to look at: the optimised rollout, the loss curve
    scene.draw_debug_sphere(torch.cat([target, target.new_tensor([2 * BOX_HALF[2]])]), radius=0.03,
                            color=TARGET_COLOR)  # on the box's top face where its centre should end
    final_pos, video = run.record(camera, rollout)
    plot = run.plot("loss", {"loss": losses}, "epoch", "loss (m², mean squared box position error)",
                    f"push box: Adam on {n_steps} × {robot.n_dofs} joint torques", log_y=True)
    print(f"box ends at {final_pos.cpu().numpy().round(4)} (target {target.cpu().numpy()}); wrote {video}, {plot}")
    check_loss_drop(losses, required_drop, "push box")


if __name__ == "__main__":
    main()
