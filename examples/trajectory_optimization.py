"""Trajectory optimisation: the "轨迹优化" example of Genesis's differentiable-simulation page.

A two-link pendulum (``assets/pendulum2.urdf``, fixed base, swinging about y under gravity)
starts hanging at rest. We optimise its whole joint-torque sequence, ``controls`` of shape
(n_steps, n_dofs), with Adam so that the tip of the second link is at ``target`` at the end of
the rollout. Every epoch resets the scene (a fresh autograd graph), replays the controls,
computes the loss and back-propagates through all ``n_steps`` steps.

The tip is 0.4 m down the second link's frame (where its sphere is); its world position is
computed in torch from the link's pose, ``link.get_pos() + rotate(link.get_quat(), offset)``:
any torch code on simulator outputs is differentiated through.

Settings (chosen for a robust ≥ 100× loss drop in 100 epochs): dt = 0.01 s, 100 steps,
float64, Adam lr = 0.1 N·m. The page uses lr = 0.01; with torques of a few N·m needed to lift
the pendulum, that needs far more epochs.

Run:  python examples/trajectory_optimization.py [--short]     (or GS_EXAMPLES_SHORT=1)
Full mode checks loss(last) ≤ loss(first) / 100; short mode (20 epochs) checks a 10× drop.
"""
import os
import time

import torch

import genesis_lite as gs
from example_args import short_mode

ASSETS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "assets")


def rotate(quat, vec):
    """Rotate ``vec`` by the unit quaternion ``quat`` (w, x, y, z)."""
    w, u = quat[..., :1], quat[..., 1:]
    t = 2.0 * torch.cross(u, vec.expand_as(u), dim=-1)
    return vec + w * t + torch.cross(u, t, dim=-1)


def main():
    short = short_mode(__doc__)
    n_epochs, required_drop = (20, 10.0) if short else (100, 100.0)
    start = time.time()
    gs.init(precision="64")

    scene = gs.Scene(
        sim_options=gs.options.SimOptions(
            dt=0.01,
            requires_grad=True,
        ),
    )
    robot = scene.add_entity(gs.morphs.URDF(file=os.path.join(ASSETS, "pendulum2.urdf"), fixed=True))
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

    losses = []
    for epoch in range(n_epochs):
        t0 = time.time()
        scene.reset()
        # forward simulation
        for t in range(n_steps):
            robot.control_dofs_force(controls[t])
            scene.step()
        # loss on the final tip position
        final_pos = link.get_pos() + rotate(link.get_quat(), tip_offset)
        loss = torch.nn.functional.mse_loss(final_pos, target)
        # optimise
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
        print(f"Epoch {epoch}: loss = {loss.item():.4e}  tip = {final_pos.detach().cpu().numpy().round(4)}  "
              f"({time.time() - t0:.2f} s)")

    print(f"loss {losses[0]:.4e} → {losses[-1]:.4e} ({losses[0] / losses[-1]:.0f}× lower) "
          f"in {n_epochs} epochs, {time.time() - start:.1f} s in all")
    test_final(losses, required_drop)


def test_final(losses, required_drop):
    if not all(torch.isfinite(torch.tensor(losses))):
        raise AssertionError(f"a loss is not finite: {losses}")
    if not losses[-1] * required_drop <= losses[0]:
        raise AssertionError(f"the loss must fall ≥ {required_drop:.0f}×: {losses[0]:.4e} → {losses[-1]:.4e} "
                             f"({losses[0] / losses[-1]:.1f}×)")
    print(f"trajectory optimisation OK (≥ {required_drop:.0f}× drop)")


if __name__ == "__main__":
    main()
