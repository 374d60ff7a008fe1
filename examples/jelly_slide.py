"""Jelly slide: optimise how a jelly block is thrown down a rigid ramp so that it lands on a target.

A neo-Hookean jelly cube (8 cm, E = 5e4 Pa, ρ = 1000 kg/m³, MPM) lies at the top of a fixed
rigid ramp (a box tilted 25°) above a rigid ground plane. Both rigid shapes couple with the
particles by Genesis's rule (``gs.materials.Rigid``'s coup_friction: 0.2 on the ramp, 0.4 on the
ground): the jelly slides down the ramp, lands and slides on. We optimise its initial velocity
v0 (3,) so that its centre ends, after ``n_steps`` steps, at ``TARGET`` on the ground. The loss
depends on v0 only through the jelly's contacts with the ramp and the ground: every gradient
flows through the rigid–MPM coupling, back through every substep.

Settings: dt = 2 ms in 5 substeps, float64, 40 cells/m (216 particles); L-BFGS (strong Wolfe line
search), each evaluation one rollout and its backward.

Outputs (in ``--out DIR``, default ./outputs): ``jelly_slide.mp4``, the optimised throw (the
target is the green sphere), and ``jelly_slide_loss.png``, the loss per iteration.

Run:  python examples/jelly_slide.py [--short] [--out DIR]     (or GS_EXAMPLES_SHORT=1)
Full mode (30 rollouts) checks loss(last) ≤ loss(first) / 1e4; short mode (12) a 100× drop.
"""
import time

import torch
import tqdm

import genesis_lite as gs
from example_run import TARGET_COLOR, ExampleRun, check_loss_drop

TARGET = (0.45, 0.1)  # m, on the ground
START_V0 = (0.3, 0.0, 0.0)  # m/s: the first guess, a gentle push down the ramp


def main():
    run = ExampleRun(__doc__, __file__)
    n_iterations, required_drop, n_steps = (12, 100.0, 150) if run.short else (30, 1e4, 200)
    start = time.time()
    gs.init(precision="64")
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=2e-3, substeps=5, requires_grad=True),
                     mpm_options=gs.options.MPMOptions(lower_bound=(-0.6, -0.4, -0.1), upper_bound=(0.8, 0.4, 0.5),
                                                       grid_density=40, particle_size=0.0125))
    scene.add_entity(gs.morphs.Plane(), material=gs.materials.Rigid(coup_friction=0.4))
    scene.add_entity(gs.morphs.Box(pos=(-0.25, 0.0, 0.1), size=(0.4, 0.3, 0.02), euler=(0, 25, 0), fixed=True),
                     material=gs.materials.Rigid(coup_friction=0.2),
                     surface=gs.surfaces.Default(color=(0.6, 0.45, 0.3)))
    jelly = scene.add_entity(gs.morphs.Box(pos=(-0.33, 0.0, 0.25), size=(0.08, 0.08, 0.08), euler=(0, 25, 0)),
                             material=gs.materials.MPM.Elastic(E=5e4, rho=1000.0, model="neohooken"),
                             surface=gs.surfaces.Default(color=(0.85, 0.35, 0.3)))
    camera = run.camera(scene, (0.05, -1.2, 0.3), (0.05, 0.0, 0.08))
    scene.build()
    print(f"built in {time.time() - start:.1f} s: {jelly.n_particles} particles, {n_steps} steps a rollout")

    f = gs.tc_float
    target = torch.tensor(TARGET, dtype=f, device=gs.device)
    v0 = torch.tensor(START_V0, dtype=f, device=gs.device, requires_grad=True)
    optimizer = torch.optim.LBFGS([v0], lr=1.0, max_iter=n_iterations, max_eval=n_iterations, history_size=10,
                                  line_search_fn="strong_wolfe", tolerance_grad=1e-12, tolerance_change=1e-16)

    def rollout(after_step=None):
        """Throw the jelly at v0 from its start; its centre (3,) after n_steps steps."""
        scene.reset()
        jelly.set_velocity(v0)
        for _ in range(n_steps):
            scene.step()
            if after_step is not None:
                after_step()
        return jelly.get_particles_pos().mean(dim=0)

    losses = []
    progress = tqdm.tqdm(total=n_iterations, desc="jelly slide", unit="rollout")

    def closure():
        optimizer.zero_grad()
        loss = ((rollout()[:2] - target) ** 2).sum()
        loss.backward()
        losses.append(loss.item())
        progress.set_postfix(loss=f"{loss.item():.3e}", v0=v0.detach().cpu().numpy().round(3).tolist(), refresh=False)
        progress.update()
        return loss

    optimizer.step(closure)
    progress.close()
    print(f"loss {losses[0]:.4e} → {min(losses):.4e} in {len(losses)} rollouts, {time.time() - start:.1f} s in all; "
          f"v0 = {v0.detach().cpu().numpy().round(4)} m/s")

    scene.draw_debug_sphere(torch.cat([target, target.new_tensor([0.04])]), radius=0.02, color=TARGET_COLOR)
    centre, video = run.record(camera, rollout)
    plot = run.plot("loss", {"loss": losses}, "L-BFGS evaluation (one rollout and its backward each)",
                    "loss (m², squared distance to the target)", "jelly slide: L-BFGS on the throw", log_y=True)
    print(f"the jelly's centre ends at {centre.cpu().numpy().round(4)} (target {TARGET}); wrote {video}, {plot}")
    check_loss_drop(losses, required_drop, "jelly slide")


if __name__ == "__main__":
    main()
