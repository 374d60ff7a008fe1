"""A drone's flight planned through the simulator: rotor speeds optimised by gradient descent.

A Crazyflie 2.x (``gs.morphs.Drone(file="urdf/drones/cf2x.urdf")``, 27 g, shipped with
genesis_lite) hovers at 1 m. We plan its four rotors' speeds so that after 1.5 s it is at
``target`` (0.4 m sideways and 0.2 m up), level and still. Nothing in the plan says how a
quadrotor moves sideways (tilt, accelerate, tilt back, brake): Adam on the gradients of the loss
through 150 steps of rigid-body dynamics (thrust kf ω² along each rotor's axis, drag torque
km ω²) finds it. The loss: squared distance to the target (m²) + 0.1 × squared final velocity and
turn rate + 0.1 × squared final tilt (the base's z axis from vertical).

The plan: ``u`` (10, 4), knots 1/6 s apart, linearly interpolated to every step, of the four
channels a flight controller mixes (collective thrust, roll, pitch, yaw):
ω_k² = hover² (1 + 0.3 tanh c + 0.05 (r_k tanh r + p_k tanh p) + 0.05 s_k tanh y), r_k, p_k the
signs of rotor k's lever about x and y, s_k its spin. In those channels the loss is far better
conditioned than in the four speeds (a roll is a small difference of two large thrusts).

Settings: dt = 0.01 s, 150 steps, float64, Adam lr = 0.02.

Outputs (in ``--out DIR``, default ./outputs): ``drone_flight.mp4``, the optimised flight (the
target is the green sphere), and ``drone_flight_loss.png``, the loss per epoch.

Run:  python examples/drone_flight.py [--short] [--out DIR]     (or GS_EXAMPLES_SHORT=1)
Full mode (150 epochs) checks loss(last) ≤ loss(first) / 30; short mode (50 epochs) a 5× drop.
"""
import time

import torch
import tqdm

import genesis_lite as gs
from example_run import TARGET_COLOR, ExampleRun, check_loss_drop

START, TARGET = (0.0, 0.0, 1.0), (0.4, 0.0, 1.2)


def main():
    run = ExampleRun(__doc__, __file__)
    n_epochs, required_drop = (50, 5.0) if run.short else (150, 30.0)
    start = time.time()
    gs.init(precision="64")

    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True))
    scene.add_entity(gs.morphs.Plane())
    drone = scene.add_entity(gs.morphs.Drone(file="urdf/drones/cf2x.urdf", pos=START))
    camera = run.camera(scene, (0.2, -0.55, 1.25), (0.2, 0.0, 1.1), fov=60)
    scene.build()
    print(f"built in {time.time() - start:.1f} s")

    n_steps, n_knots = 150, 10
    hover = (float(drone.get_mass()) * 9.81 / (4.0 * drone.KF)) ** 0.5  # rpm holding its weight
    # each rotor's share of roll (its lever's y sign), pitch (−x sign) and yaw (its spin)
    lever = drone.get_links_COM()[drone.propellers_idx - drone.link_start]
    mix = torch.stack([lever[:, 1].sign(), -lever[:, 0].sign(), drone.propellers_spin])  # (3, 4)
    u = torch.zeros(n_knots, 4, requires_grad=True, device=gs.device, dtype=gs.tc_float)
    optimizer = torch.optim.Adam([u], lr=0.02)
    target = torch.tensor(TARGET, device=gs.device, dtype=gs.tc_float)

    def speeds():
        """(n_steps, 4) rpm of the plan u."""
        channels = torch.tanh(torch.nn.functional.interpolate(u.T[None], size=n_steps, mode="linear",
                                                              align_corners=True)[0].T)  # (n_steps, 4)
        squared = 1.0 + 0.3 * channels[:, :1] + 0.05 * channels[:, 1:] @ mix
        return hover * squared.sqrt()

    def rollout(after_step=None):
        """Fly the plan from hover at START; the loss at the end. after_step: called after every
        step (the video's frames)."""
        scene.reset()
        rpm = speeds()
        for t in range(n_steps):
            drone.set_propellers_rpm(rpm[t])
            scene.step()
            if after_step is not None:
                after_step()
        w, x, y, z = drone.get_quat()
        tilt = torch.stack([2 * (x * z + w * y), 2 * (y * z - w * x), -2 * (x * x + y * y)])  # body z − world z
        motion = (drone.get_vel() ** 2).sum() + (drone.get_ang() ** 2).sum()
        return ((drone.get_pos() - target) ** 2).sum() + 0.1 * motion + 0.1 * (tilt ** 2).sum()

    losses = []
    progress = tqdm.trange(n_epochs, desc="drone flight", unit="epoch")
    for _ in progress:
        loss = rollout()
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
        progress.set_postfix(loss=f"{loss.item():.3e}")
    progress.close()
    print(f"loss {losses[0]:.4e} → {losses[-1]:.4e} ({losses[0] / losses[-1]:.0f}× lower) "
          f"in {n_epochs} epochs, {time.time() - start:.1f} s in all")

    scene.draw_debug_sphere(target, radius=0.02, color=TARGET_COLOR)
    final_loss, video = run.record(camera, rollout)
    plot = run.plot("loss", {"loss": losses}, "epoch", "loss (m², distance² + motion and tilt terms)",
                    f"drone flight: Adam on a {n_knots}-knot plan of {n_steps} steps' rotor speeds", log_y=True)
    print(f"final position {drone.get_pos().detach().cpu().numpy().round(3)} (target {TARGET}); wrote {video}, "
          f"{plot}")
    check_loss_drop(losses, required_drop, "drone flight")


if __name__ == "__main__":
    main()
