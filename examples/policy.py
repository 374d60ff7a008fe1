"""Policy learning through the simulator: a torch ``nn.Module`` drives the robot every step and is
trained by back-propagation through time.

The two-link pendulum (``assets/pendulum2.urdf``) runs in ``N_ENVS`` parallel environments
(``scene.build(n_envs=N_ENVS)``), each from its own initial joint positions and velocities. At
every step the policy reads the observed state — ``get_dofs_position()`` and
``get_dofs_velocity()``, (N_ENVS, 2) each — and outputs joint torques for
``control_dofs_force``. The loss, at the end of the rollout only, is the distance of the joints
from a target pose (which the policy must reach *and hold* against gravity) plus a little
final speed. ``loss.backward()`` goes through every step and every policy call; Adam updates
the network.

The initial states are the same every epoch, so the loss curve shows learning, not sampling
noise; an evaluation rollout without gradients after training gives the final loss.

Outputs (in ``--out DIR``, default ./outputs): ``policy.mp4``, the trained policy's evaluation
rollout in all ``N_ENVS`` environments (drawn ENV_SPACING apart), and ``policy_loss.png``, the
training loss per epoch.

Run:  python examples/policy.py [--short] [--out DIR]     (or GS_EXAMPLES_SHORT=1)
Both modes check final loss < 0.5 × initial loss (short: 10 epochs of 50 steps; full: 60
epochs of 80 steps).
"""
import os
import time

import numpy as np
import torch
import tqdm

import genesis_lite as gs
from example_run import ExampleRun

ASSETS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "assets")
N_ENVS = 16
ENV_SPACING = (1.2, 0.8)  # m between the envs as cameras draw them (x, y); the physics ignores it
TARGET = (0.6, -0.4)  # rad: the first link raised, the second bent back
VIEW_POS, VIEW_LOOKAT = np.array([4.6, 3.4, 2.2]), np.array([0.0, 0.0, -0.6])  # camera, m from the grid's centre


class Policy(torch.nn.Module):
    """(q, q̇) → joint torques, bounded by ``max_torque`` N·m. Starts at zero output."""

    def __init__(self, n_dofs, hidden=64, max_torque=10.0):
        super().__init__()
        self.net = torch.nn.Sequential(
            torch.nn.Linear(3 * n_dofs, hidden), torch.nn.Tanh(),
            torch.nn.Linear(hidden, hidden), torch.nn.Tanh(),
            torch.nn.Linear(hidden, n_dofs))
        torch.nn.init.zeros_(self.net[-1].weight)
        torch.nn.init.zeros_(self.net[-1].bias)
        self.max_torque = max_torque

    def forward(self, q, qd):
        features = torch.cat([torch.sin(q), torch.cos(q), 0.1 * qd], dim=-1)
        return self.max_torque * torch.tanh(self.net(features) / 3.0)


def main():
    run = ExampleRun(__doc__, __file__)
    n_epochs, n_steps = (10, 50) if run.short else (60, 80)
    start = time.time()
    gs.init(precision="32", seed=0)
    if gs.device.type == "cpu":
        # Tiny matrix products: one torch thread. Otherwise torch's OpenMP/MKL workers and Taichi's
        # CPU threads fight over the cores and an epoch can take 10-40x longer.
        torch.set_num_threads(1)

    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True))
    robot = scene.add_entity(gs.morphs.URDF(file=os.path.join(ASSETS, "pendulum2.urdf"), fixed=True))
    camera = run.camera(scene, pos=VIEW_POS, lookat=VIEW_LOOKAT)
    scene.build(n_envs=N_ENVS, env_spacing=ENV_SPACING)
    # a camera stands in the frame of its env (the first): aim it at the centre of the grid of envs
    centre = scene.envs_offset.mean(axis=0) - scene.envs_offset[0]
    camera.set_pose(pos=centre + VIEW_POS, lookat=centre + VIEW_LOOKAT)
    print(f"built {N_ENVS} environments in {time.time() - start:.1f} s")

    generator = torch.Generator().manual_seed(0)
    q0 = ((torch.rand(N_ENVS, robot.n_dofs, generator=generator) - 0.5) * 1.0).to(gs.device, gs.tc_float)
    qd0 = ((torch.rand(N_ENVS, robot.n_dofs, generator=generator) - 0.5) * 2.0).to(gs.device, gs.tc_float)
    target = torch.tensor(TARGET, device=gs.device, dtype=gs.tc_float)

    policy = Policy(robot.n_dofs).to(device=gs.device, dtype=gs.tc_float)
    optimizer = torch.optim.Adam(policy.parameters(), lr=3e-3)

    def rollout(after_step=None):
        """(loss, final joint positions (N_ENVS, n_dofs)) of the policy's rollout from (q0, qd0).
        after_step: called after every step (the video's frames)."""
        scene.reset()
        robot.set_dofs_position(q0)
        robot.set_dofs_velocity(qd0)
        for _ in range(n_steps):
            torque = policy(robot.get_dofs_position(), robot.get_dofs_velocity())
            robot.control_dofs_force(torque)
            scene.step()
            if after_step is not None:
                after_step()
        q, qd = robot.get_dofs_position(), robot.get_dofs_velocity()
        per_env = ((q - target) ** 2).sum(-1) + 0.01 * (qd ** 2).sum(-1)
        return per_env.mean(), q

    losses = []
    progress = tqdm.trange(n_epochs, desc="policy learning", unit="epoch")
    for _ in progress:
        loss, _ = rollout()
        optimizer.zero_grad()
        loss.backward()  # back-propagation through time: every step, every policy call
        optimizer.step()
        losses.append(loss.item())
        progress.set_postfix(loss=f"{loss.item():.4f}")
    progress.close()

    # evaluation (without gradients), filmed
    (final, q), video = run.record(camera, rollout)
    error = (q - target).abs().max().item()
    print(f"after training: loss {final.item():.4f} (initial {losses[0]:.4f}); worst joint error {error:.3f} rad; "
          f"{time.time() - start:.1f} s in all")
    plot = run.plot("loss", {"training loss": losses}, "epoch", "loss (rad², final pose error + speed)",
                    f"policy learning, {N_ENVS} envs: evaluation loss after training {final.item():.4f}")
    print(f"wrote {video}, {plot}")
    test_final(losses[0], final.item())


def test_final(initial, final):
    if not (final == final and final < 0.5 * initial):
        raise AssertionError(f"the loss must fall below half its initial value: {initial:.4f} → {final:.4f}")
    print(f"policy learning OK (loss × {final / initial:.2f})")


if __name__ == "__main__":
    main()
