"""The eps-scan check of gradients through contact (test support): a directional derivative
against central finite differences at several eps.

The map is a discrete simulation, smooth between kinks (a contact making or breaking, a row
changing state): near one, large eps straddle it and disagree, while small eps converge to the
derivative. So the check asks for convergence, not for one eps to agree.
"""
import numpy as np
import torch

EPS = (1e-5, 1e-6, 1e-7, 1e-8)
BAR = 1e-5  # relative to ‖g‖


def directional_errors(loss, value, seed=0, eps=EPS, direction=None):
    """{ε: (g·v − (L(x + εv) − L(x − εv)) / 2ε) / ‖g‖} for each ε of ``eps`` at x = value for a random
    unit v (or the unit ``direction``), where g = ∇L(x) by backward. loss(x) runs one rollout from
    its start (it resets the scene). ``eps`` in x's units: an input of another scale than 1 takes
    EPS scaled alike."""
    if direction is None:
        direction = torch.tensor(np.random.default_rng(seed).normal(size=value.shape))
    direction = direction / direction.norm()
    x = value.clone().requires_grad_(True)
    loss(x).backward()
    analytic, scale = float((x.grad * direction).sum()), float(x.grad.norm())
    assert scale > 0.0, "zero gradient cannot be checked"
    errors = {}
    with torch.no_grad():
        for step in eps:
            central = (float(loss(value + step * direction)) - float(loss(value - step * direction))) / (2 * step)
            errors[step] = (analytic - central) / scale
    return errors


def assert_converged(errors, what):
    """Two neighbouring eps (the scan's, in its order) agree to BAR, and there the error is ≤ BAR."""
    scan = ", ".join(f"{eps:.0e}: {err:.1e}" for eps, err in errors.items())
    steps = list(errors)
    converged = [min(abs(errors[a]), abs(errors[b])) for a, b in zip(steps, steps[1:])
                 if abs(errors[a] - errors[b]) < BAR]
    assert converged and min(converged) <= BAR, f"{what}: relative errors per eps {scan}"


def checked_gradient(loss, value, what, seeds=2):
    """The gradient of loss at ``value``, after checking it against central differences along
    ``seeds`` random directions (assert_converged) and that a repeated rollout keeps its bits."""
    for seed in range(seeds):
        assert_converged(directional_errors(loss, value, seed), f"{what}, direction {seed}")
    grads = []
    for _ in range(2):
        x = value.clone().requires_grad_(True)
        loss(x).backward()
        grads.append(x.grad)
    assert torch.equal(grads[0], grads[1]), f"{what}: a repeated rollout's gradient changed"
    return grads[0]


def repeated_gradients(scene, robot, velocity, rollout):
    """The gradients of ``rollout()`` (a loss) in the robot's initial dof velocities ``velocity``
    (numpy) from two rollouts, each after scene.reset(): a repeat's gradient must keep its bits."""
    grads = []
    for _ in range(2):
        scene.reset()
        start = torch.tensor(velocity, requires_grad=True)
        robot.set_dofs_velocity(start)
        rollout().backward()
        grads.append(start.grad)
    return grads


def pose_loss(scene, robot, weights, steps, start):
    """loss(x): ``start(x)`` after scene.reset() (it sets the rollout's input), ``steps`` steps,
    then every link's pose (position, quaternion) weighted by ``weights`` (n_links, 7) and summed."""
    def loss(x):
        scene.reset()
        start(x)
        for _ in range(steps):
            scene.step()
        return (torch.cat([robot.get_links_pos(), robot.get_links_quat()], -1) * weights).sum()
    return loss
