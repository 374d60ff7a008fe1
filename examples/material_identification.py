"""Material identification: recover an elastic block's Young's modulus E and Poisson ratio ν
from its observed particle trajectory (density ρ given).

1. "Reality": a neo-Hookean jelly block (``TRUE_E``, ``TRUE_NU``, ρ = 1000 kg/m³) is thrown
   spinning onto the floor; we record every particle's position every step. That is the
   observation.
2. The model starts from E = 1e5 Pa, ν = 0.2 and is fitted by L-BFGS (torch): each evaluation
   resets the scene, sets the candidate parameters with ``set_material_params`` (tensors that
   require grad), throws the block the same way and back-propagates the trajectory error through
   every MPM substep into E and ν. Genesis cannot do this: its material parameters are
   compile-time constants.

E lives in log-space; ν = 0.5·tanh(z) stays inside (−0.5, 0.5). E and ρ are not jointly
identifiable from motion alone (the dynamics depend on E/ρ), which is why ρ is given.

Outputs (in ``--out DIR``, default ./outputs): ``material_identification.mp4``, the fitted model's
rollout beside the observed final particles (green dots), and ``material_identification_fit.png``,
the loss and the relative errors of E and ν per L-BFGS evaluation.

Run:  python examples/material_identification.py [--short] [--out DIR]     (or GS_EXAMPLES_SHORT=1)
Both modes check E and ν within 1 % of the truth (short: a coarser grid, fewer steps).
"""
import math
import time

import torch
import tqdm

import genesis_lite as gs
from example_run import TARGET_COLOR, ExampleRun

TRUE_E, TRUE_NU = 2.5e5, 0.32  # Pa, reality's
START_E, START_NU = 1e5, 0.2  # the model's first guess
RHO = 1000.0  # kg/m³, given


def main():
    run = ExampleRun(__doc__, __file__)
    density, n_steps, max_evals = (24, 40, 30) if run.short else (32, 100, 40)
    start = time.time()
    gs.init(precision="64")
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=2e-3, substeps=6, requires_grad=True),
                     mpm_options=gs.options.MPMOptions(lower_bound=(-0.4, -0.4, 0.0), upper_bound=(0.4, 0.4, 0.6),
                                                       grid_density=density))
    block = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.24), size=(0.16, 0.16, 0.16)),
                             material=gs.materials.MPM.Elastic(E=START_E, nu=START_NU, rho=RHO, model="neohooken"),
                             surface=gs.surfaces.Default(color=(0.85, 0.35, 0.3)))
    camera = run.camera(scene, (0.9, -0.9, 0.6), (0.0, 0.0, 0.12))
    scene.build()
    f = gs.tc_float
    pos0 = block.get_particles_pos().detach()
    centre = pos0.mean(dim=0)
    # thrown down and sideways, spinning about a tilted axis: it lands, squashes, rebounds
    spin = torch.cross(torch.tensor([1.0, 2.0, 4.0], dtype=f, device=gs.device).expand_as(pos0), pos0 - centre, dim=1)
    throw = spin + torch.tensor([0.4, 0.0, -1.5], dtype=f, device=gs.device)

    def rollout(E, nu, after_step=None):
        """Every particle's position after every step, (n_steps, n, 3)."""
        scene.reset()
        block.set_particles_vel(throw)
        block.set_material_params(E=E, nu=nu)
        frames = []
        for _ in range(n_steps):
            scene.step()
            frames.append(block.get_particles_pos())
            if after_step is not None:
                after_step()
        return torch.stack(frames)

    with torch.no_grad():
        observed = rollout(torch.tensor(TRUE_E, dtype=f), torch.tensor(TRUE_NU, dtype=f))
    scale = (observed - observed.mean(dim=1, keepdim=True)).pow(2).mean()
    print(f"built and observed in {time.time() - start:.1f} s: {block.n_particles} particles, {n_steps} steps; "
          f"truth E = {TRUE_E:.4g} Pa, ν = {TRUE_NU}")

    log_E = torch.tensor(math.log(START_E), dtype=f, requires_grad=True)
    z_nu = torch.tensor(math.atanh(START_NU / 0.5), dtype=f, requires_grad=True)
    optimizer = torch.optim.LBFGS([log_E, z_nu], lr=1.0, max_iter=max_evals, max_eval=max_evals, history_size=20,
                                  line_search_fn="strong_wolfe", tolerance_grad=1e-14, tolerance_change=1e-18)
    history = {"loss": [], "E error": [], "ν error": []}
    progress = tqdm.tqdm(total=max_evals, desc="material identification", unit="rollout")

    def closure():
        optimizer.zero_grad()
        E, nu = torch.exp(log_E), 0.5 * torch.tanh(z_nu)
        loss = ((rollout(E, nu) - observed) ** 2).mean() / scale
        loss.backward()
        history["loss"].append(loss.item())
        history["E error"].append(abs(E.item() / TRUE_E - 1))
        history["ν error"].append(abs(nu.item() / TRUE_NU - 1))
        progress.set_postfix(loss=f"{loss.item():.2e}", E=f"{E.item():.4g}", nu=f"{nu.item():.4f}", refresh=False)
        progress.update()
        return loss

    optimizer.step(closure)
    progress.close()
    E, nu = torch.exp(log_E).item(), (0.5 * torch.tanh(z_nu)).item()
    print(f"fitted E = {E:.6g} Pa, ν = {nu:.6f} after {len(history['loss'])} rollouts, {time.time() - start:.1f} s")

    scene.draw_debug_spheres(observed[-1], radius=0.004, color=TARGET_COLOR)
    _, video = run.record(camera, lambda after_step: rollout(torch.tensor(E, dtype=f), torch.tensor(nu, dtype=f),
                                                             after_step))
    plot = run.plot("fit", history, "L-BFGS evaluation (one rollout and its backward each)",
                    "loss; relative errors", "material identification: E and ν of a jelly", log_y=True)
    print(f"wrote {video}, {plot}")
    test_final(E, nu)


def test_final(E, nu, tolerance=0.01):
    errors = {"E": abs(E / TRUE_E - 1), "ν": abs(nu / TRUE_NU - 1)}
    for name, err in errors.items():
        print(f"  {name}: error {100 * err:.4f} %")
    if not (math.isfinite(E) and math.isfinite(nu)) or max(errors.values()) > tolerance:
        raise AssertionError(f"E and ν must be within {100 * tolerance:.0f} % of the truth; errors {errors}")
    print(f"material identification OK (E and ν within {100 * tolerance:.0f} %)")


if __name__ == "__main__":
    main()
