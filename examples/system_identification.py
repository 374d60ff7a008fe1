"""System identification: recover link masses and joint damping from an observed trajectory.

1. "Reality": the two-link pendulum of ``assets/pendulum2.urdf`` with *other* masses and joint
   damping than its URDF says (``TRUE_MASS_SCALE``, ``TRUE_DAMPING``) is driven by a known
   excitation (a sum of sines per joint) for ``n_steps`` steps; we record its joint positions
   and velocities at every step. That is the observation.
2. The model starts from the URDF values and is fitted by L-BFGS (torch) to reproduce the
   observation: each evaluation resets the scene, sets the candidate parameters with
   ``set_links_mass`` / ``set_dofs_damping`` (tensors that require grad), replays the same
   excitation and back-propagates the trajectory error through every step into the parameters.

Parameters live in log-space (positive by construction, relative steps). Joint 1's URDF damping
is 0, which has no logarithm, so its estimate starts at 0.01 N·m·s/rad. ``set_links_mass`` leaves
each link's rotational inertia as it is (Genesis's rule; ``set_links_inertia`` would set it), so
two masses and two damping coefficients describe the whole difference between model and reality.
The base link is fixed, its mass has no effect and is not fitted.

Outputs (in ``--out DIR``, default ./outputs): ``system_identification.mp4``, the fitted model's
rollout, its tip retracing the observed tip's path (green dots), and
``system_identification_loss.png``, the trajectory error per L-BFGS evaluation.

Run:  python examples/system_identification.py [--short] [--out DIR]     (or GS_EXAMPLES_SHORT=1)
Full mode (≤ 80 rollouts) checks every parameter within 1 % of the truth; short mode (≤ 40
rollouts) within 2 %.
"""
import math
import os
import time

import torch
import tqdm

import genesis_lite as gs
from example_run import PENDULUM_VIEW, TARGET_COLOR, ExampleRun, point_on_link

ASSETS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "assets")
LINKS = [1, 2]  # link1, link2 (link 0 is the fixed base)
TRUE_MASS_SCALE = (1.25, 0.8)  # reality's masses / URDF masses
TRUE_DAMPING = (0.08, 0.03)  # N·m·s/rad (URDF: 0 and 0.05)
TIP = (0.0, 0.0, -0.4)  # m, in link2's frame: the centre of its sphere


def excitation(n_steps, dt, dtype):
    """Known joint torques (n_steps, 2), N·m: two sines per joint, moderate amplitude so the
    motion stays far from the chaotic regime of a double pendulum (a smooth loss landscape)."""
    t = torch.arange(n_steps, dtype=dtype, device=gs.device) * dt
    tau1 = 1.0 * torch.sin(2 * math.pi * 1.0 * t) + 0.5 * torch.sin(2 * math.pi * 2.7 * t + 0.3)
    tau2 = 0.4 * torch.sin(2 * math.pi * 1.7 * t + 1.0) + 0.2 * torch.sin(2 * math.pi * 3.1 * t)
    return torch.stack([tau1, tau2], dim=1)


def main():
    run = ExampleRun(__doc__, __file__)
    n_steps, max_evals, tolerance = (100, 40, 0.02) if run.short else (100, 80, 0.01)
    start = time.time()
    gs.init(precision="64")
    dt = 0.01
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=dt, requires_grad=True))
    robot = scene.add_entity(gs.morphs.URDF(file=os.path.join(ASSETS, "pendulum2.urdf"), fixed=True))
    camera = run.camera(scene, *PENDULUM_VIEW)
    scene.build()
    f = gs.tc_float

    urdf_mass = robot.get_links_mass(LINKS).detach().clone()
    urdf_damping = robot.get_dofs_damping().detach().clone()
    true_mass = urdf_mass * torch.tensor(TRUE_MASS_SCALE, dtype=f, device=gs.device)
    true_damping = torch.tensor(TRUE_DAMPING, dtype=f, device=gs.device)
    forces = excitation(n_steps, dt, f)

    def rollout(mass, damping, after_step=None):
        """Joint positions and velocities after every step, (n_steps, 2 · n_dofs). after_step: called
        after every step (the video's frames, the tip's path)."""
        scene.reset()
        robot.set_links_mass(mass, LINKS)
        robot.set_dofs_damping(damping)
        states = []
        for t in range(n_steps):
            robot.control_dofs_force(forces[t])
            scene.step()
            states.append(torch.cat([robot.get_dofs_position(), robot.get_dofs_velocity()]))
            if after_step is not None:
                after_step()
        return torch.stack(states)

    # 1. the observation (and where the tip went, for the video)
    tip, tip_offset = robot.get_link("link2"), torch.tensor(TIP, dtype=f, device=gs.device)
    observed_tip = []
    with torch.no_grad():
        observed = rollout(true_mass, true_damping, lambda: observed_tip.append(point_on_link(tip, tip_offset)))
    weight = 1.0 / observed.var(dim=0)  # each channel counts the same, whatever its unit
    print(f"built and observed in {time.time() - start:.1f} s: {n_steps} steps, "
          f"|q|max = {observed[:, :2].abs().max().item():.2f} rad, |q̇|max = {observed[:, 2:].abs().max().item():.2f} rad/s")
    print(f"truth:  mass {true_mass.cpu().numpy()} kg, damping {true_damping.cpu().numpy()} N·m·s/rad")
    print(f"URDF:   mass {urdf_mass.cpu().numpy()} kg, damping {urdf_damping.cpu().numpy()} N·m·s/rad")

    # 2. the fit
    log_mass = torch.log(urdf_mass).clone().requires_grad_(True)
    log_damping = torch.log(urdf_damping.clamp_min(0.01)).clone().requires_grad_(True)
    optimizer = torch.optim.LBFGS([log_mass, log_damping], lr=1.0, max_iter=max_evals, max_eval=max_evals,
                                  history_size=20, line_search_fn="strong_wolfe",
                                  tolerance_grad=1e-15, tolerance_change=1e-18)
    evals = []
    progress = tqdm.tqdm(total=max_evals, desc="system identification", unit="rollout")

    def closure():
        optimizer.zero_grad()
        mass, damping = torch.exp(log_mass), torch.exp(log_damping)
        loss = (weight * (rollout(mass, damping) - observed) ** 2).mean()
        loss.backward()
        evals.append(loss.item())
        progress.set_postfix(loss=f"{loss.item():.3e}", refresh=False)
        progress.update()
        return loss

    optimizer.step(closure)
    progress.close()
    mass, damping = torch.exp(log_mass).detach(), torch.exp(log_damping).detach()
    print(f"fitted: mass {mass.cpu().numpy()} kg, damping {damping.cpu().numpy()} N·m·s/rad "
          f"after {len(evals)} rollouts, {time.time() - start:.1f} s in all")

    # 3. what to look at: the fitted model retracing the observed tip's path, the loss curve
    scene.draw_debug_spheres(torch.stack(observed_tip), radius=0.01, color=TARGET_COLOR)
    _, video = run.record(camera, lambda after_step: rollout(mass, damping, after_step))
    plot = run.plot("loss", {"loss": evals}, "L-BFGS evaluation (one rollout and its backward each)",
                    "loss (weighted mean squared state error)", "system identification: masses and damping",
                    log_y=True)
    print(f"wrote {video}, {plot}")
    test_final(torch.cat([mass, damping]), torch.cat([true_mass, true_damping]), tolerance)


def test_final(fitted, truth, tolerance):
    names = ["mass link1", "mass link2", "damping joint1", "damping joint2"]
    errors = (fitted / truth - 1).abs()
    for name, got, want, err in zip(names, fitted.tolist(), truth.tolist(), errors.tolist()):
        print(f"  {name:15s} fitted {got:.6f}  true {want:.6f}  error {100 * err:.4f} %")
    if not bool(torch.isfinite(fitted).all()) or not bool((errors <= tolerance).all()):
        raise AssertionError(f"every parameter must be within {100 * tolerance:.0f} % of the truth; errors "
                             f"{(100 * errors).tolist()} %")
    print(f"system identification OK (every parameter within {100 * tolerance:.0f} %)")


if __name__ == "__main__":
    main()
