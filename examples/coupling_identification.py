"""Coupling identification: recover how a jelly block meets the ground — the ground's coupling
friction μ and restitution e — from the block's observed motion.

1. "Reality" (synthetic: the same simulator, so the fit can recover the truth exactly): a
   neo-Hookean jelly block (8 × 8 × 6 cm, E = 5e4 Pa) is thrown down and forwards onto a rigid
   ground plane whose coupling with the particles (Genesis's rigid–MPM rule: what
   ``gs.materials.Rigid``'s coup_friction and coup_restitution set at build, here set by the
   ground's ``set_coupling``) is ``TRUE_FRICTION`` and ``TRUE_RESTITUTION``: it bounces, slides
   and slows. We record the block's centre every 5 steps. That is the observation.
2. The model starts near Genesis's defaults (μ 0.1, e 0.05; theirs: 0.1, 0) and is fitted by
   L-BFGS (torch): each evaluation resets the scene, sets the candidates with ``set_coupling``
   (tensors that require grad), throws the block the same way and back-propagates the path's error
   through every substep of the particles meeting the ground into μ and e. Genesis cannot do this:
   it fixes its coupling parameters per shape at build, with no setter and no gradient.

Outputs (in ``--out DIR``, default ./outputs): ``coupling_identification.mp4``, the fitted model's
rollout beside the observed final centre (green sphere), and ``coupling_identification_fit.png``,
the loss and the relative errors of μ and e per L-BFGS evaluation.

Run:  python examples/coupling_identification.py [--short] [--out DIR]     (or GS_EXAMPLES_SHORT=1)
Full mode (0.2 s observed, 20 L-BFGS evaluations) and short mode (0.08 s, 16) check μ and e within
1 % of the truth (the line search may take an evaluation or two more).
"""
import time

import torch
import tqdm

import genesis_lite as gs
from example_run import TARGET_COLOR, ExampleRun

TRUE_FRICTION, TRUE_RESTITUTION = 0.6, 0.5  # reality's ground coupling
START_FRICTION, START_RESTITUTION = 0.1, 0.05  # the model's first guess
THROW = (1.5, 0.0, -1.0)  # m/s: every particle's initial velocity
OBSERVE_EVERY = 5  # steps between two observations of the centre


def main():
    run = ExampleRun(__doc__, __file__)
    n_steps, max_evals, tolerance = (40, 16, 0.01) if run.short else (100, 20, 0.01)
    start = time.time()
    gs.init(precision="64")
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=2e-3, substeps=4, requires_grad=True),
                     mpm_options=gs.options.MPMOptions(lower_bound=(-0.2, -0.2, -0.1), upper_bound=(0.6, 0.2, 0.3),
                                                       grid_density=40))
    ground = scene.add_entity(gs.morphs.Plane())
    block = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.06), size=(0.08, 0.08, 0.06)),
                             material=gs.materials.MPM.Elastic(E=5e4), surface=gs.surfaces.Default(color=(0.3, 0.55, 0.85)))
    camera = run.camera(scene, (0.15, -0.55, 0.1), (0.15, 0.0, 0.06))
    scene.build()
    f = gs.tc_float
    throw = torch.tensor(THROW, dtype=f, device=gs.device).expand(block.n_particles, 3)

    def rollout(friction, restitution, after_step=None):
        """The block's centre every OBSERVE_EVERY steps, (n_steps / OBSERVE_EVERY, 3) m."""
        scene.reset()
        ground.set_coupling(friction=friction, restitution=restitution)
        block.set_particles_vel(throw)
        path = []
        for k in range(n_steps):
            scene.step()
            if after_step is not None:
                after_step()
            if (k + 1) % OBSERVE_EVERY == 0:
                path.append(block.get_particles_pos().mean(dim=0))
        return torch.stack(path)

    with torch.no_grad():
        observed = rollout(torch.tensor(TRUE_FRICTION, dtype=f), torch.tensor(TRUE_RESTITUTION, dtype=f))
    print(f"built and observed in {time.time() - start:.1f} s: {block.n_particles} particles, {n_steps} steps; "
          f"the block's centre ends at {observed[-1].cpu().numpy().round(4)}")

    guess = torch.tensor([START_FRICTION, START_RESTITUTION], dtype=f, device=gs.device, requires_grad=True)
    optimizer = torch.optim.LBFGS([guess], lr=1.0, max_iter=max_evals, max_eval=max_evals,
                                  line_search_fn="strong_wolfe", tolerance_grad=0.0, tolerance_change=0.0)
    truth = torch.tensor([TRUE_FRICTION, TRUE_RESTITUTION], dtype=f)
    history = {"loss": [], "μ error": [], "e error": []}
    progress = tqdm.tqdm(total=max_evals, desc="coupling identification", unit="rollout")

    def candidate():
        """(μ, e) of the guess, kept in their ranges (μ ≥ 0, e in [0, 1]) when a line search overshoots."""
        return guess[0].clamp(min=0.0), guess[1].clamp(0.0, 1.0)

    def closure():
        optimizer.zero_grad()
        friction, restitution = candidate()
        loss = ((rollout(friction, restitution) - observed) ** 2).sum(dim=1).mean()
        loss.backward()
        fitted = torch.stack([friction, restitution]).detach().cpu()
        for name, value in zip(history, (loss.item(), *((fitted - truth).abs() / truth).tolist())):
            history[name].append(value)
        progress.set_postfix(loss=f"{loss.item():.2e}", mu=f"{fitted[0]:.4f}", e=f"{fitted[1]:.4f}", refresh=False)
        progress.update()
        return loss

    optimizer.step(closure)
    progress.close()
    friction, restitution = (float(v.detach()) for v in candidate())
    print(f"fitted μ = {friction:.4f} (truth {TRUE_FRICTION}), e = {restitution:.4f} (truth {TRUE_RESTITUTION}); "
          f"loss {history['loss'][0]:.3e} → {history['loss'][-1]:.3e} m² in {len(history['loss'])} rollouts, "
          f"{time.time() - start:.1f} s in all")

    scene.draw_debug_sphere(observed[-1], radius=0.012, color=TARGET_COLOR)
    with torch.no_grad():
        _, video = run.record(camera, lambda after_step: rollout(*candidate(), after_step))
    plot = run.plot("fit", history, "L-BFGS evaluation (one rollout and its backward each)",
                    "loss (m²) / relative error", "coupling identification: L-BFGS on μ and e", log_y=True)
    print(f"wrote {video}, {plot}")
    errors = abs(friction - TRUE_FRICTION) / TRUE_FRICTION, abs(restitution - TRUE_RESTITUTION) / TRUE_RESTITUTION
    if not max(errors) <= tolerance:
        raise AssertionError(f"μ and e must be within {tolerance:.0%} of the truth: μ {friction:.4f} "
                             f"({errors[0]:.2%}), e {restitution:.4f} ({errors[1]:.2%})")
    print(f"coupling identification OK (μ and e within {tolerance:.0%})")


if __name__ == "__main__":
    main()
