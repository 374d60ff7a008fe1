"""Quick start: the first snippet of Genesis's differentiable-simulation page, with genesis_lite.

A 3-dof arm (``assets/arm3.urdf``: revolute shoulder, prismatic slider, continuous wrist, fixed
base) starts from initial joint positions that require grad, runs 100 steps under force
control, and the loss is the squared distance of its end-effector link from a target.
``loss.backward()`` then fills ``initial_pos.grad`` (and ``forces.grad``): the gradient went
through every ``scene.step()``.

Differences from the page's snippet, and why:

* ``robot.get_pos()`` is the *base* link; on a fixed-base robot it never moves, so its gradient
  is zero. We use the end link, ``robot.get_link("ee").get_pos()``.
* ``forces`` is not defined on the page; here it is a constant (3,) force/torque command that
  also requires grad (it holds the slider against gravity and turns the shoulder and wrist).
* ``precision="64"`` so that the gradient can be checked against central finite differences.

Outputs (in ``--out DIR``, default ./outputs): ``quickstart.mp4``, the rollout (the target is the
green sphere), and ``quickstart_end_effector.png``, the end effector's coordinates over the
rollout beside the target's.

Run:  python examples/quickstart.py [--short] [--out DIR]     (or GS_EXAMPLES_SHORT=1)
The script ends with a check that raises if the gradient is not finite, is zero, or disagrees
with finite differences.
"""
import os
import time

import torch

import genesis_lite as gs
from example_run import TARGET_COLOR, ExampleRun

ASSETS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "assets")


def main():
    run = ExampleRun(__doc__, __file__)
    start = time.time()
    gs.init(precision="64")

    # -- the page's snippet ---------------------------------------------------------------------
    scene = gs.Scene(
        sim_options=gs.options.SimOptions(
            dt=0.01,
            requires_grad=True,  # enable differentiability
        ),
    )
    # "ee" hangs on a fixed joint: keep it as a link (fixed-joint links are merged by default)
    robot = scene.add_entity(gs.morphs.URDF(file=os.path.join(ASSETS, "arm3.urdf"), fixed=True, links_to_keep=["ee"]))
    camera = run.camera(scene, pos=(0.45, 0.75, 0.5), lookat=(0.15, 0.05, 0.08))
    scene.build()
    print(f"built in {time.time() - start:.1f} s: {robot.n_dofs} dofs "
          f"({', '.join(j.name for j in robot.joints)})")

    n_steps = 100
    target = torch.tensor([0.25, 0.15, 0.05], device=gs.device, dtype=gs.tc_float)
    # shoulder torque (N·m), slider force (N; the slider, hand and ee weigh 9.3 N: the slider has no
    # <inertial>, so it is weighed from its box at Genesis's density of a robot's links), wrist torque (N·m)
    forces = torch.tensor([0.1, 9.4, 0.001], device=gs.device, dtype=gs.tc_float, requires_grad=True)
    ee = robot.get_link("ee")

    def rollout(initial_pos, after_step=None):
        """(loss, final end-effector position (3,)) of one rollout from ``initial_pos`` (a fresh graph
        each time: scene.reset()). after_step: called after every step (the video's frames)."""
        scene.reset()
        robot.set_dofs_position(initial_pos)
        for i in range(n_steps):
            robot.control_dofs_force(forces)
            scene.step()
            if after_step is not None:
                after_step()
            if (i + 1) % 25 == 0 and torch.is_grad_enabled():
                print(f"  step {i + 1}/{n_steps}: dofs position {robot.get_dofs_position().detach().cpu().numpy()}")
        final_pos = ee.get_pos()
        return torch.nn.functional.mse_loss(final_pos, target), final_pos

    # forward simulation
    initial_pos = torch.tensor([0.0, 0.0, 0.0], requires_grad=True, device=gs.device, dtype=gs.tc_float)
    t0 = time.time()
    loss, final_pos = rollout(initial_pos)
    t1 = time.time()
    # backward through the simulation
    loss.backward()
    t2 = time.time()
    print(f"final end-effector position {final_pos.detach().cpu().numpy()}, loss {loss.item():.6f}")
    print(f"forward {t1 - t0:.2f} s, backward {t2 - t1:.2f} s")
    # access the gradients
    print("d loss / d initial_pos =", initial_pos.grad)
    print("d loss / d forces      =", forces.grad)

    # -- what to look at: the rollout and its end effector's path -----------------------------------
    scene.draw_debug_sphere(target, radius=0.02, color=TARGET_COLOR)
    ee_path = []

    def filmed_rollout(film_frame):
        """The rollout, filmed, gathering the end effector's position after every step."""
        def after_step():
            film_frame()
            ee_path.append(ee.get_pos().clone())
        return rollout(initial_pos.detach(), after_step)

    _, video = run.record(camera, filmed_rollout)
    ee_path = torch.stack(ee_path)
    plot = run.plot("end_effector", {axis: ee_path[:, k] for k, axis in enumerate("xyz")}, "step", "position (m)",
                    "quickstart: end effector under constant forces", targets=dict(zip("xyz", target.tolist())))
    print(f"wrote {video}, {plot}")

    # -- check: finite, non-zero, and equal to central finite differences ---------------------------
    test_final(rollout, initial_pos, run.short)
    print(f"quickstart OK in {time.time() - start:.1f} s")


def test_final(rollout, initial_pos, short):
    grad = initial_pos.grad
    if grad is None or not bool(torch.isfinite(grad).all()):
        raise AssertionError(f"d loss / d initial_pos must be finite, got {grad}")
    if not bool((grad.abs() > 0).any()):
        raise AssertionError(f"d loss / d initial_pos must be non-zero, got {grad}")
    eps = 1e-6
    dofs = [0] if short else range(len(grad))
    for k in dofs:
        with torch.no_grad():
            step = torch.zeros_like(initial_pos)
            step[k] = eps
            plus = rollout(initial_pos.detach() + step)[0].item()
            minus = rollout(initial_pos.detach() - step)[0].item()
        fd = (plus - minus) / (2 * eps)
        got = grad[k].item()
        print(f"  dof {k}: autograd {got:+.9e}  finite difference {fd:+.9e}")
        if abs(got - fd) > 1e-7 + 1e-4 * abs(fd):
            raise AssertionError(f"dof {k}: autograd gradient {got} disagrees with finite differences {fd}")


if __name__ == "__main__":
    main()
