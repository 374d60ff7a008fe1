"""How the differentiable scene behaves as part of torch's graph (SPEC §3): repeated rollouts,
second backward, resets, torch.autograd.grad / gradcheck, a policy network between steps,
non-differentiable paths, memory per step and checkpointing."""
import numpy as np
import pytest
import torch

import genesis_lite as gs
from genesis_lite.solvers.rigid.data import INPUTS
from tests.conftest import asset

T = 20


@pytest.fixture
def pendulum(f64):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True))
    robot = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True))
    scene.build()
    return scene, robot


def _final_q_of_mass(scene, robot, mass, steps=T):
    scene.reset()
    if mass is not None:
        robot.set_links_mass(mass)
    robot.set_dofs_position([0.4, -0.3])
    for _ in range(steps):
        scene.step()
    return robot.get_dofs_position()[0]


def test_repeated_rollouts_bit_identical_and_fd(pendulum):
    scene, robot = pendulum
    m0 = robot.get_links_mass().detach().clone()
    grads = []
    for _ in range(20):
        mass = m0.clone().requires_grad_(True)
        _final_q_of_mass(scene, robot, mass).backward()
        grads.append(mass.grad.clone())
    for g in grads[1:]:
        assert torch.equal(g, grads[0]), "gradients changed between identical rollouts"
    direction = torch.tensor([0.0, 1.0, -0.5], dtype=torch.float64)
    with torch.no_grad():
        fd = (_final_q_of_mass(scene, robot, m0 + 1e-6 * direction)
              - _final_q_of_mass(scene, robot, m0 - 1e-6 * direction)) / 2e-6
    assert abs(float(grads[0] @ direction) - float(fd)) <= 1e-6 * abs(float(fd))


def test_second_backward_needs_retain_graph(pendulum):
    scene, robot = pendulum
    mass = robot.get_links_mass().detach().clone().requires_grad_(True)
    loss = _final_q_of_mass(scene, robot, mass)
    loss.backward(retain_graph=True)
    first = mass.grad.clone()
    mass.grad = None
    loss.backward()
    assert torch.equal(first, mass.grad)
    with pytest.raises(RuntimeError, match="second time|freed"):
        loss.backward()


def test_backward_after_reset_raises(pendulum):
    scene, robot = pendulum
    mass = robot.get_links_mass().detach().clone().requires_grad_(True)
    loss = _final_q_of_mass(scene, robot, mass)
    scene.reset()
    with pytest.raises(gs.GradientError, match="reset"):
        loss.backward()


def test_getter_under_no_grad_does_not_detach_a_later_one(pendulum):
    """A link getter called under torch.no_grad() (as a camera or a logger does) and then again
    with grad on the same state: the second is in the graph, its gradient that of a fresh read."""
    scene, robot = pendulum
    link = robot.get_link("link2")

    def tip(mass, peek):
        scene.reset()
        robot.set_links_mass(mass)
        robot.set_dofs_position([0.4, -0.3])
        for _ in range(T):
            scene.step()
        if peek:
            with torch.no_grad():
                link.get_pos()
        return link.get_pos().sum()

    grads = []
    for peek in (False, True):
        mass = robot.get_links_mass().detach().clone().requires_grad_(True)
        tip(mass, peek).backward()
        grads.append(mass.grad)
    assert grads[1].abs().sum() > 0 and torch.equal(grads[0], grads[1])


def test_step_under_no_grad_cutting_a_graph_warns_once(pendulum, caplog):
    """Steps under torch.no_grad() are not recorded (torch's rule): the mass set before them gets
    no gradient through them. Warned once a rollout, naming the step; not when nothing it could
    cut requires grad (a finite-difference evaluation)."""
    scene, robot = pendulum
    caplog.clear()
    _final_q_of_mass(scene, robot, robot.get_links_mass().detach().clone())
    with torch.no_grad():
        _final_q_of_mass(scene, robot, robot.get_links_mass().detach().clone())
    assert not any("no_grad" in r.getMessage() for r in caplog.records)
    for _ in range(2):
        mass = robot.get_links_mass().detach().clone().requires_grad_(True)
        scene.reset()
        robot.set_links_mass(mass)
        scene.step()
        with torch.no_grad():
            for _ in range(3):
                scene.step()
        scene.step()
        warnings = [r.getMessage() for r in caplog.records if "no_grad" in r.getMessage()]
        assert len(warnings) == 1 and "step 1" in warnings[0], warnings
        caplog.clear()


def test_parameters_a_reset_detached_warn_at_the_backward(pendulum, caplog):
    """A mass set once from a tensor requiring grad, then resets and a loop of reset, rollout,
    backward: the reset keeps the value, not the graph, so the mass's .grad stays None: warned at the first
    backward (naming the input), once; not when the loop sets it again after each reset, nor when
    the setter's value needed no gradient."""
    scene, robot = pendulum
    from tests.conftest import warns
    mass = robot.get_links_mass().detach().clone().requires_grad_(True)
    robot.set_links_mass(mass)
    scene.reset()  # (a reset before the loop's first: the mass is already detached there)
    velocity = torch.tensor([0.1, 0.2], dtype=torch.float64, requires_grad=True)
    for k in range(2):
        with warns(caplog, r"scene.reset\(\) detached .*\(RigidSolver's mass\).* set them after reset\(\)" if k == 0
                   else None):
            scene.reset()
            robot.set_dofs_velocity(velocity)
            for _ in range(3):
                scene.step()
            robot.get_dofs_position().sum().backward()
    assert mass.grad is None and velocity.grad is not None
    with warns(caplog, None):
        for _ in range(2):
            _final_q_of_mass(scene, robot, mass, steps=3).sum().backward()
            robot.set_dofs_kp(torch.ones(2, dtype=torch.float64))  # (no gradient: nothing detached)
    assert mass.grad is not None


def test_autograd_grad_equals_backward(pendulum):
    scene, robot = pendulum
    mass = robot.get_links_mass().detach().clone().requires_grad_(True)
    (grad,) = torch.autograd.grad(_final_q_of_mass(scene, robot, mass), [mass])
    _final_q_of_mass(scene, robot, mass).backward()
    assert torch.equal(grad, mass.grad)


def test_gradcheck(pendulum):
    scene, robot = pendulum

    def run(q0, forces, mass):
        # gradcheck differentiates its first output after evaluating the function again, so
        # the rollout starts by setting the whole state instead of scene.reset() (which would
        # close that first graph)
        robot.set_links_mass(mass)
        robot.set_dofs_position(q0)
        robot.set_dofs_velocity(torch.zeros(2, dtype=torch.float64))
        for t in range(10):
            robot.control_dofs_force(forces[t])
            scene.step()
        return torch.cat([robot.get_dofs_position(), robot.get_dofs_velocity()]).as_subclass(torch.Tensor)

    q0 = torch.tensor([0.3, -0.2], dtype=torch.float64, requires_grad=True)
    forces = (0.1 * torch.randn(10, 2, dtype=torch.float64, generator=torch.Generator().manual_seed(0)))
    mass = robot.get_links_mass().detach().clone()
    mass[0] += 1.0  # the base link is fixed: its mass has no effect, which gradcheck also confirms
    assert torch.autograd.gradcheck(run, (q0, forces.requires_grad_(True), mass.requires_grad_(True)),
                                    eps=1e-6, atol=1e-7, rtol=1e-5,
                                    # that probe re-runs single nodes of the first graph after its
                                    # buffers were used; the Jacobian comparison is what we check
                                    check_undefined_grad=False)


def test_policy_network_gradient_matches_fd(pendulum):
    scene, robot = pendulum
    torch.manual_seed(0)
    policy = torch.nn.Sequential(torch.nn.Linear(4, 8), torch.nn.Tanh(), torch.nn.Linear(8, 2)).double()

    def loss_fn():
        scene.reset()
        robot.set_dofs_position([0.4, -0.3])
        for _ in range(T):
            obs = torch.cat([robot.get_dofs_position(), robot.get_dofs_velocity()])
            robot.control_dofs_force(policy(obs))
            scene.step()
        return (robot.get_dofs_position() ** 2).sum()

    loss_fn().backward()
    weight = policy[0].weight
    direction = torch.randn_like(weight)
    analytic = float((weight.grad * direction).sum())
    with torch.no_grad():
        weight += 1e-6 * direction
        plus = float(loss_fn())
        weight -= 2e-6 * direction
        minus = float(loss_fn())
        weight += 1e-6 * direction
    numeric = (plus - minus) / 2e-6
    assert analytic != 0.0 and abs(analytic - numeric) <= 1e-6 * max(abs(numeric), 1e-3)


def test_non_differentiable_getter_raises_on_backward(pendulum):
    scene, robot = pendulum
    q0 = torch.tensor([0.3, 0.1], dtype=torch.float64, requires_grad=True)
    scene.reset()
    robot.set_dofs_position(q0)
    scene.step()
    loss = robot.get_mass_mat().sum()
    with pytest.raises(gs.GradientError, match="get_mass_mat"):
        loss.backward()


def _saved_bytes(scene, robot, steps, interval_scene=None):
    """Unique bytes torch keeps for backward over a rollout of ``steps`` steps."""
    storages = {}

    def pack(t):
        storages[t.untyped_storage().data_ptr()] = t.untyped_storage().nbytes()
        return t

    forces = torch.zeros(steps, robot.n_dofs, dtype=torch.float64, requires_grad=True)
    with torch.autograd.graph.saved_tensors_hooks(pack, lambda t: t):
        scene.reset()
        robot.set_dofs_position([0.2, 0.1])
        for t in range(steps):
            robot.control_dofs_force(forces[t])
            scene.step()
        loss = robot.get_dofs_position().sum()
    return sum(storages.values()), loss


@pytest.mark.parametrize("substeps", [1, 4])
def test_memory_per_step_is_one_state(f64, substeps):
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, substeps=substeps, requires_grad=True))
    robot = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True))
    scene.build()
    state_bytes = (robot.n_qs + robot.n_dofs) * 8
    small, _ = _saved_bytes(scene, robot, 50)
    large, _ = _saved_bytes(scene, robot, 150)
    per_step = (large - small) / 100
    assert 0 < per_step <= 2 * state_bytes, f"{per_step} bytes per step for a {state_bytes}-byte state"


def test_checkpointing_bit_identical_and_smaller(f64):
    grads, per_step = {}, {}
    for interval in (1, 7):
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True, checkpoint_interval=interval))
        robot = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True))
        scene.build()
        forces = torch.linspace(-1, 1, 60 * 2, dtype=torch.float64).reshape(60, 2).requires_grad_(True)
        mass = robot.get_links_mass().detach().clone().requires_grad_(True)
        scene.reset()
        robot.set_links_mass(mass)
        robot.set_dofs_position([0.2, 0.1])
        for t in range(60):
            robot.control_dofs_force(forces[t])
            scene.step()
        (robot.get_dofs_position() ** 2).sum().backward()
        grads[interval] = (forces.grad.clone(), mass.grad.clone())
        small, _ = _saved_bytes(scene, robot, 35)
        large, _ = _saved_bytes(scene, robot, 105)
        per_step[interval] = (large - small) / 70
    assert torch.equal(grads[1][0], grads[7][0]) and torch.equal(grads[1][1], grads[7][1])
    assert per_step[7] < per_step[1]


def test_checkpointing_bit_identical_with_setters_between_steps(f64):
    """A setter between two steps replaces the state the next step starts from: that step keeps its
    start state even off the checkpoint grid, else the recomputation from the checkpoint before it
    would run without the setter (gradients 16-38 % off, silently, before the fix). Setters at
    steps 10 (a velocity requiring grad) and 23 (a position, velocity kept), interval 7: the same
    bits as interval 1."""
    grads = {}
    for interval in (1, 7):
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True, checkpoint_interval=interval))
        robot = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True))
        scene.build()
        forces = torch.linspace(-1, 1, 40 * 2, dtype=torch.float64).reshape(40, 2).requires_grad_(True)
        kick = torch.tensor([1.5, -2.0], dtype=torch.float64, requires_grad=True)
        scene.reset()
        robot.set_dofs_position([0.2, 0.1])
        for t in range(40):
            if t == 10:
                robot.set_dofs_velocity(kick)
            if t == 23:
                robot.set_dofs_position([-0.3, 0.4], zero_velocity=False)
            robot.control_dofs_force(forces[t])
            scene.step()
        (robot.get_dofs_position() ** 2).sum().backward()
        grads[interval] = (forces.grad.clone(), kick.grad.clone())
    assert torch.equal(grads[1][0], grads[7][0]) and torch.equal(grads[1][1], grads[7][1])
    assert bool((grads[1][1] != 0).all())


def test_a_checkpointed_closed_loop_rollout_is_freed_after_reset(f64):
    """Controls computed from the state (a closed loop) with checkpoint_interval 2: the rollout keeps
    each step's inputs for its recomputations, detached, else input → its graph → the step's node →
    the rollout would be a cycle inside torch's graph that Python's collector cannot see (the old
    rollout, its checkpoints and graph lived on after reset)."""
    import gc
    import weakref
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True, checkpoint_interval=2))
    robot = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True))
    scene.build()
    gain = torch.tensor(0.5, dtype=torch.float64, requires_grad=True)
    scene.reset()
    robot.set_dofs_position([0.2, 0.1])
    for _ in range(6):
        robot.control_dofs_force(-gain * robot.get_dofs_position())
        scene.step()
    (robot.get_dofs_position() ** 2).sum().backward()
    assert gain.grad != 0.0
    rollout = weakref.ref(scene.sim.rollout)
    scene.reset()
    scene.step()
    gc.collect()
    assert rollout() is None


def test_gradient_finite_at_zero_joint_angles(f64):
    """Stand-in values of unused joint branches must not leak NaN into gradients (q = 0)."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True))
    robot = scene.add_entity(gs.morphs.URDF(file=asset("arm3.urdf"), fixed=True))
    scene.build()

    def loss_of(q0):
        scene.reset()
        robot.set_dofs_position(q0)
        for _ in range(10):
            scene.step()
        return robot.get_links_pos()[-1].sum()

    q0 = torch.zeros(robot.n_dofs, dtype=torch.float64, requires_grad=True)
    loss_of(q0).backward()
    assert bool(torch.isfinite(q0.grad).all())
    direction = torch.tensor([1.0, -0.5, 0.3], dtype=torch.float64)
    with torch.no_grad():
        fd = (loss_of(1e-6 * direction) - loss_of(-1e-6 * direction)) / 2e-6
    assert abs(float(q0.grad @ direction) - float(fd)) <= 1e-6 * max(abs(float(fd)), 1e-3)


def test_finished_scenes_are_freed(f64):
    """The autograd graph must not keep scenes alive through a cycle torch's nodes hide."""
    import gc

    from genesis_lite.simulator import Simulator

    def rollout():
        scene = gs.Scene(sim_options=gs.options.SimOptions(requires_grad=True))
        robot = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True))
        scene.build()
        q0 = torch.tensor([0.1, 0.2], dtype=torch.float64, requires_grad=True)
        robot.set_dofs_position(q0)
        scene.step()
        robot.get_links_pos().sum().backward()

    gc.collect()
    before = sum(type(o) is Simulator for o in gc.get_objects())
    for _ in range(3):
        rollout()
    gc.collect()
    assert sum(type(o) is Simulator for o in gc.get_objects()) == before


def test_checkpointing_bit_identical_with_constraint_rows(f64):
    """The quadruped with joint limits and friction loss from a random pose and velocity, the
    solve at its default tolerance: a checkpointed step's recompute and every replay start their
    solve from the warm start the forward step started from, so the gradients equal the
    uncheckpointed ones bit for bit (from another warm start they differ by ~1e-16 here)."""
    grads = {}
    for interval in (1, 3):
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True, checkpoint_interval=interval),
                         rigid_options=gs.options.RigidOptions(enable_collision=False))
        robot = scene.add_entity(gs.morphs.URDF(file=asset("quadruped.urdf"), fixed=False))
        scene.build()
        scene.reset()
        robot.set_dofs_frictionloss(torch.full((robot.n_dofs,), 0.05, dtype=torch.float64))
        rng = np.random.default_rng(7)
        q0 = torch.tensor(rng.uniform(-0.3, 0.3, robot.n_dofs))
        q0[:3] = 0.0
        velocity = torch.tensor(rng.uniform(-0.5, 0.5, robot.n_dofs), requires_grad=True)
        robot.set_dofs_position(q0)
        robot.set_dofs_velocity(velocity)
        for _ in range(12):
            scene.step()
        ((robot.get_dofs_position() ** 2).sum() + robot.get_dofs_velocity().cos().sum()).backward()
        grads[interval] = velocity.grad.clone()
    assert torch.equal(grads[1], grads[3]), (grads[1] - grads[3]).abs().max()


@pytest.mark.parametrize("through", ["step", "getter"])
@pytest.mark.parametrize("how", ["backward", "grad_with_inputs"])
def test_second_derivatives_raise_rather_than_drop_out(pendulum, through, how):
    """The step and the link getters are differentiable once: a gradient taken with create_graph
    and differentiated again raises GradientError (it was a constant: the simulator's second-order
    part dropped out of a Hessian-vector product without a word). Also where
    torch.autograd.grad(..., inputs=...) prunes what does not lead to its inputs: with torch's
    once_differentiable, whose error node hangs off the gradient alone, a mixed derivative through
    a user-side scale s lost the simulator's part silently (5.6 % off the finite difference: the
    value was the scale's own term, found by an adversarial pass)."""
    scene, robot = pendulum
    scene.reset()
    velocity = torch.tensor([0.3, 0.1], dtype=torch.float64, requires_grad=True)
    scale = torch.tensor(1.5, dtype=torch.float64, requires_grad=True)
    robot.set_dofs_velocity(velocity * scale)
    for _ in range(5):
        scene.step()
    loss = (robot.get_dofs_position() ** 2).sum() if through == "step" else robot.get_links_pos().sum()
    (grad,) = torch.autograd.grad(loss, velocity, create_graph=True)
    with pytest.raises(gs.GradientError, match="second derivatives through the simulator"):
        if how == "backward":
            (grad ** 2).sum().backward()
        else:
            torch.autograd.grad(grad.sum(), scale)


def test_second_derivatives_raise_with_checkpointing(f64):
    """With checkpoint_interval > 1 a step that kept no start state recomputes it, detached, from
    the checkpoint: there is nothing to attach its gradient to, and a mixed derivative through a
    force set at such a step lost the simulator's part without a word (it returned the user term
    [1, 0]; FD [1.0000006, 4.3e-5]; found by a review). Its backward raises under create_graph."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True, checkpoint_interval=4))
    robot = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True))
    scene.build()
    velocity = torch.tensor([0.3, 0.1], dtype=torch.float64, requires_grad=True)
    force = torch.tensor([0.5, -0.2], dtype=torch.float64, requires_grad=True)
    robot.set_dofs_velocity(velocity)
    for t in range(4):
        if t == 1:
            robot.control_dofs_force(force)
        scene.step()
    loss = robot.get_dofs_position()[0] + (velocity * force).sum()
    with pytest.raises(gs.GradientError, match="checkpoint_interval > 1 create_graph=True raises at once"):
        torch.autograd.grad(loss, force, create_graph=True)


def test_first_derivatives_with_create_graph_are_the_plain_ones(pendulum):
    """create_graph=True changes no first derivative: the same bits as a plain backward."""
    scene, robot = pendulum
    grads = []
    for create_graph in (False, True):
        scene.reset()
        velocity = torch.tensor([0.3, 0.1], dtype=torch.float64, requires_grad=True)
        robot.set_dofs_velocity(velocity)
        for _ in range(5):
            scene.step()
        loss = (robot.get_dofs_position() ** 2).sum() + robot.get_links_pos().sum()
        grads.append(torch.autograd.grad(loss, velocity, create_graph=create_graph)[0].detach())
    assert torch.equal(grads[0], grads[1])


def test_a_step_packs_its_inputs_into_one_kept_buffer(f64):
    """The rigid step hands its inputs to the kernels packed in a buffer kept per layout, not a new
    tensor a step: with glibc's mmap threshold fixed at 128 KiB (keep_large_blocks_off_the_heap),
    a new (256, 167) float32 tensor a step was a new memory mapping, 18 % of a KUKA's 256-env
    differentiable rollout. The packed values are those of torch.cat (only the parts that changed
    are copied again), and a forward step and its reverse (state and output gradient around the
    inputs) each get their own buffer."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True))
    robot = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True))
    scene.build(n_envs=3)
    solver = scene.sim.slots[0].solver
    packs = []
    for forces in torch.randn(4, 3, robot.n_dofs, dtype=torch.float64).requires_grad_(True).unbind(0):
        robot.control_dofs_force(forces)
        scene.step()
        inputs = scene.sim.slots[0].inputs
        state = scene.sim.state(solver)
        packs.append((solver._pack_inputs(inputs), solver._pack_inputs(inputs, state, 2.0 * state)))
        expected = torch.cat([inputs[name] for name in INPUTS], dim=1).detach()
        assert torch.equal(packs[-1][0], expected)
        assert torch.equal(packs[-1][1], torch.cat([state, expected, 2.0 * state], dim=1).detach())
    assert len({(a.data_ptr(), b.data_ptr()) for a, b in packs}) == 1
    assert packs[0][0].data_ptr() != packs[0][1].data_ptr()


def test_a_checkpointed_rollout_records_an_input_given_again_once(f64):
    """With checkpoint_interval > 1 the rollout records each step's inputs for its recomputations:
    an input given again (a parameter, a held control) shares the step before's record, instead of
    a new detached view every step (a pendulum's graph held 11.7 KB a step with checkpoints, 7.7
    without); a new control gets its own. Gradients as without checkpoints, bit for bit."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True, checkpoint_interval=4))
    robot = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True))
    scene.build()
    forces = torch.zeros(8, 2, dtype=torch.float64, requires_grad=True)

    def gradient():
        scene.reset()
        robot.set_dofs_position([0.2, 0.1])
        for t, force in enumerate(forces.unbind(0)):
            if t < 6:  # the last two steps keep the sixth's control
                robot.control_dofs_force(force)
            scene.step()
        final = robot.get_dofs_position()
        (final ** 2).sum().backward()
        grad, forces.grad = forces.grad.clone(), None
        return grad, final

    checkpointed, final = gradient()
    assert sorted(scene.sim.rollout.inputs) == [4, 5, 6, 7]  # (the rollout keeps an interval: the node the rest)
    records = _segment_node(final).segment.replay
    shared = [sum(a is b for a, b in zip(records[k], records[k + 1])) for k in range(7)]
    assert all(n == len(records[0]) - 1 for n in shared[:5]) and shared[6] == len(records[0])
    assert shared[5] == len(records[0])
    scene.sim.options.checkpoint_interval = 1
    plain, _ = gradient()
    assert scene.sim.rollout.interval == 1 and torch.equal(checkpointed, plain)


def _segment_node(tensor):
    """The first step node (autograd._Segment) of the graph of ``tensor``, depth first."""
    stack = [tensor.grad_fn]
    while stack:
        fn = stack.pop()
        if type(fn).__name__ == "_SegmentBackward":
            return fn
        stack.extend(following for following, _ in fn.next_functions if following is not None)
    return None


def _segment_nodes(tensor):
    """How many step nodes (autograd._Segment) the graph of ``tensor`` holds."""
    seen, stack, count = set(), [tensor.grad_fn], 0
    while stack:
        fn = stack.pop()
        if fn is None or id(fn) in seen:
            continue
        seen.add(id(fn))
        count += type(fn).__name__ == "_SegmentBackward"
        stack.extend(following for following, _ in fn.next_functions)
    return count


@pytest.mark.parametrize("checkpoint_interval", [1, 3])
def test_the_steps_between_two_reads_are_one_node(f64, checkpoint_interval):
    """A rollout whose state is read at its end is one graph node (torch's per-node costs once,
    not a step); read every step, a node a step. Both give the same gradients bit for bit, of the
    initial state, a control per step and a parameter every step shares (its gradient summed over
    the steps by the node, by torch across nodes), with checkpoints too."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True,
                                                       checkpoint_interval=checkpoint_interval))
    robot = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True))
    scene.build()
    q0 = torch.tensor([0.4, -0.3], dtype=torch.float64, requires_grad=True)
    damping = torch.tensor([0.2, 0.3], dtype=torch.float64, requires_grad=True)
    forces = torch.linspace(-1.0, 1.0, 2 * T, dtype=torch.float64).reshape(T, 2).requires_grad_(True)

    def gradients(read_every_step):
        scene.reset()
        robot.set_dofs_damping(damping)
        robot.set_dofs_position(q0)
        for force in forces.unbind(0):
            robot.control_dofs_force(force)
            scene.step()
            if read_every_step:
                robot.get_dofs_velocity()
        q = robot.get_dofs_position()
        nodes = _segment_nodes(q)
        q.pow(2).sum().backward()
        grads = tuple(t.grad.clone() for t in (q0, damping, forces))
        for t in (q0, damping, forces):
            t.grad = None
        return nodes, grads

    (once, at_end), (each, every_step) = gradients(False), gradients(True)
    assert (once, each) == (1, T)
    assert all(torch.equal(a, b) for a, b in zip(at_end, every_step))
    assert all(bool((g != 0).any()) for g in at_end)


def test_a_checkpointed_rollout_holds_one_interval_and_its_nodes_the_rest(f64):
    """With checkpoint_interval k the rollout holds the newest checkpoint and the inputs since (at
    most k steps); each node saves the checkpoints its recomputations start from with torch, which
    frees them with the backward. The rollout kept every step's inputs and every checkpoint until
    scene.reset(): an evaluation under torch.no_grad() and a training loop that cut its graph by
    setters instead of resets grew without bound, and a backwarded graph that stayed referenced
    (losses kept in a list) kept its checkpoints (an independent probe, 2026-12-02). A jelly (its
    particle setters replace its whole state: the graph is cut); gradients as with k = 1, bit for
    bit, chunk after chunk."""
    import gc
    import weakref
    grads = {}
    for interval in (1, 4):
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=1e-3, substeps=2, requires_grad=True,
                                                           checkpoint_interval=interval),
                         mpm_options=gs.options.MPMOptions(lower_bound=(-0.3, -0.3, 0.0), upper_bound=(0.3, 0.3, 0.6),
                                                           grid_density=32))
        jelly = scene.add_entity(gs.morphs.Box(pos=(0.0, 0.0, 0.2), size=(0.06, 0.06, 0.06)),
                                 material=gs.materials.MPM.Elastic(E=1e4))
        scene.build()
        rollout = scene.sim.rollout
        with torch.no_grad():  # an evaluation
            for _ in range(12):
                scene.step()
        assert len(rollout.inputs) <= interval and len(rollout.checkpoints) <= 1
        kicks = torch.linspace(-0.5, 0.5, 3 * 3, dtype=torch.float64).reshape(3, 3).requires_grad_(True)
        losses, checkpoints = [], []
        for kick in kicks:  # truncated backpropagation through time: no reset
            jelly.set_particles_pos(jelly.get_particles_pos().detach())  # (cuts the graph)
            jelly.set_particles_vel(kick)
            for _ in range(6):
                scene.step()
                checkpoints += [weakref.ref(s) for states, _ in rollout.checkpoints.values() for s in states]
            losses.append(jelly.get_particles_pos()[:, 2].mean())
            losses[-1].backward()  # (the loss kept: its graph stays referenced)
            assert len(rollout.inputs) <= interval and len(rollout.checkpoints) <= 1
        gc.collect()
        newest = [id(s) for states, _ in rollout.checkpoints.values() for s in states]
        assert bool(checkpoints) == (interval > 1)
        assert all(ref() is None or id(ref()) in newest for ref in checkpoints)  # freed by the backwards
        grads[interval] = kicks.grad
        scene.destroy()
    assert torch.equal(grads[1], grads[4]) and bool((grads[4][:, 2] != 0).all())


@pytest.mark.parametrize("checkpoint_interval", [1, 3])
def test_setters_that_write_the_whole_state_cut_its_graph(f64, checkpoint_interval):
    """Truncated backpropagation through time without resets: each chunk starts from the state the
    last one left, set again detached by two setters (positions keeping the velocities, then the
    velocities), and backwards its own loss. Together they write every entry of the state, which is
    then made of their writes alone: it led back through their index_put to the previous chunk's
    graph, already freed, and the third chunk's backward raised torch's "backward through the graph
    a second time". Each chunk's gradient equals a fresh rollout's from the same state, bit for bit."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True,
                                                       checkpoint_interval=checkpoint_interval))
    robot = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True))
    scene.build()
    forces = torch.linspace(-1, 1, 4 * 5 * 2, dtype=torch.float64).reshape(4, 5, 2).requires_grad_(True)

    def chunk(k):
        for force in forces[k]:
            robot.control_dofs_force(force)
            scene.step()
        loss = (robot.get_dofs_position() ** 2).sum()
        loss.backward()
        return loss.detach()

    robot.set_dofs_position([0.2, 0.1])
    starts, losses = [], []
    for k in range(4):
        q, v = robot.get_dofs_position().detach(), robot.get_dofs_velocity().detach()
        starts.append((q, v))
        robot.set_dofs_position(q, zero_velocity=False)
        robot.set_dofs_velocity(v)
        losses.append(chunk(k))
    truncated, forces.grad = forces.grad.clone(), None
    for k, (q, v) in enumerate(starts):
        scene.reset()
        robot.set_dofs_position(q, zero_velocity=False)
        robot.set_dofs_velocity(v)
        assert torch.equal(chunk(k), losses[k])
    assert torch.equal(truncated, forces.grad) and bool((truncated != 0).all())


def test_setters_completing_the_state_take_each_write_as_it_was_made(f64):
    """The state a setter completes (every column written since the last step) is made of the writes
    as they were made (a review of its first version, which replayed them then): a value refilled
    in place after its setter, a write under torch.no_grad() and a write that raised change nothing
    later. Each case against the same writes completed in a scene whose state is in no graph."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True))
    robot = scene.add_entity(gs.morphs.URDF(file=asset("pendulum2.urdf"), fixed=True))
    scene.build(n_envs=2)
    force = torch.full((2, 2), 0.5, dtype=torch.float64, requires_grad=True)
    v0 = torch.tensor([[2.0], [4.0]], dtype=torch.float64, requires_grad=True)
    for in_graph in (True, False):
        scene.reset()
        if in_graph:
            robot.control_dofs_force(force)
        scene.step()
        assert robot.get_dofs_position().requires_grad == in_graph
        buffer = torch.tensor([[1.0, 5.0], [3.0, 6.0]], dtype=torch.float64)
        robot.set_dofs_velocity(buffer)
        buffer.fill_(7.0)  # (refilled after the setter took it)
        with torch.no_grad():
            robot.set_dofs_velocity(v0, dofs_idx_local=[1])
        with pytest.raises(gs.SceneStateError), torch.inference_mode():
            robot.set_dofs_velocity(torch.zeros(2, 2))
        robot.set_dofs_position(torch.zeros(2, 2), zero_velocity=False)  # completes the state
        assert robot.get_dofs_velocity().tolist() == [[1.0, 2.0], [3.0, 4.0]]
        assert not robot.get_dofs_velocity().requires_grad  # (v0 was set under no_grad)


def test_a_checkpointed_backward_leaves_the_rollout_as_it_was(f64):
    """A backward whose steps are recomputed from a checkpoint (checkpoint_interval > 1) overwrites
    the solver's last-step contacts and warm start: they are held before the first recompute, so
    the contacts read after the backward and the steps taken after it are those without a backward,
    bit for bit (a box sliding and turning on a plane: the warm start moves the solve's end)."""
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01, requires_grad=True, checkpoint_interval=4),
                     show_viewer=False)
    scene.add_entity(gs.morphs.Plane())
    box = scene.add_entity(gs.morphs.Box(size=(0.1, 0.1, 0.1), pos=(0.0, 0.0, 0.05)))
    scene.build()
    velocity = torch.tensor([0.5, 0.2, 0.0, 0.0, 0.0, 0.5], dtype=torch.float64, requires_grad=True)

    def rollout(backward):
        scene.reset()
        box.set_dofs_velocity(velocity)
        for _ in range(10):  # (it hops from step 2 to 5, lands at 6; step 9 is recomputed from 8)
            scene.step()
        loss = box.get_dofs_position().sum()  # (a state read: no getter's node holds them first)
        if backward:
            loss.backward()
        contacts = box.get_contacts()["position"].detach().clone()
        for _ in range(5):
            scene.step()
        return contacts, box.get_dofs_position().detach(), box.get_dofs_velocity().detach()

    plain, after_backward = rollout(False), rollout(True)
    assert plain[0].numel() > 0 and velocity.grad is not None
    assert all(torch.equal(a, b) for a, b in zip(plain, after_backward))


def test_a_jacobian_with_one_grad_outputs_buffer_refilled_in_place(pendulum):
    """Row by row, torch.autograd.grad with one grad_outputs buffer the caller refills in place
    (a state's clone hands it to the step's backward as it is): each row is the one a fresh tensor
    gives (found by an adversarial pass: the reverse step's packing took the buffer for one it held
    already, and every row repeated the first)."""
    scene, robot = pendulum
    scene.reset()
    v0 = torch.tensor([0.3, -0.2], dtype=torch.float64, requires_grad=True)
    robot.set_dofs_position([0.4, -0.3])
    robot.set_dofs_velocity(v0)
    scene.step()
    x1 = scene.get_state().rigid
    buffer, reused, fresh = torch.zeros_like(x1), [], []
    for i in range(x1.shape[1]):
        buffer.zero_()
        buffer[0, i] = 1.0
        reused.append(torch.autograd.grad(x1, v0, grad_outputs=buffer, retain_graph=True)[0])
    for i in range(x1.shape[1]):
        fresh.append(torch.autograd.grad(x1, v0, grad_outputs=torch.eye(x1.shape[1], dtype=x1.dtype)[i:i + 1],
                                         retain_graph=True)[0])
    assert torch.equal(torch.stack(reused), torch.stack(fresh))
    assert torch.linalg.matrix_rank(torch.stack(fresh)) == 2


def test_steps_before_anything_requires_grad_keep_nothing(pendulum):
    """In a scene built with requires_grad, steps before which and in which no tensor requires grad
    (an evaluation, a warm-up) keep no state for a backward (torch makes no node of one: a segment
    held a state a step until the next read, an MPM block's 100 KB a step, found by an adversarial
    pass); a control requiring grad given later gets the gradient it gets with a read between."""
    scene, robot = pendulum
    force = torch.tensor([0.3, -0.2], dtype=torch.float64, requires_grad=True)

    def gradient(read_before_the_control):
        scene.reset()
        robot.set_dofs_position([0.4, -0.3])
        for _ in range(5):
            scene.step()
        if read_before_the_control:
            robot.get_dofs_position()
        else:
            assert scene.sim.segment is not None and not scene.sim.segment.saved
        robot.control_dofs_force(force)
        for _ in range(5):
            scene.step()
        (g,) = torch.autograd.grad(robot.get_dofs_position().pow(2).sum(), force)
        return g

    without, with_read = gradient(False), gradient(True)
    assert torch.equal(without, with_read) and bool((without != 0).all())


def test_a_read_that_fails_to_make_the_node_leaves_the_steps_to_the_next(pendulum):
    """Reading the state makes the node of the steps before it; when that raises (a saved-tensor
    hook of the caller's, an interrupt), the steps stay for the next read to make it: the gradient
    is the one without the failure (found by a review: the steps were dropped, and the state kept
    a half-made node with nothing saved, whose backward raised an IndexError)."""
    scene, robot = pendulum
    v0 = torch.tensor([0.3, -0.2], dtype=torch.float64, requires_grad=True)

    def refuse(tensor):
        raise KeyboardInterrupt

    def gradient(fail_once):
        scene.reset()
        robot.set_dofs_velocity(v0)
        for _ in range(5):
            scene.step()
        if fail_once:
            with pytest.raises(KeyboardInterrupt), torch.autograd.graph.saved_tensors_hooks(refuse, lambda t: t):
                robot.get_dofs_position()
        for _ in range(3):
            scene.step()
        (g,) = torch.autograd.grad(robot.get_dofs_position().sum(), v0)
        return g

    assert torch.equal(gradient(True), gradient(False))


def test_a_gradient_of_a_late_input_reverses_only_the_steps_after_it(pendulum, monkeypatch):
    """torch prunes a graph to the paths that reach what a backward asks for: the gradient of a
    control given at step 15 alone reverses the steps from 15 on, as with a node a step (found by
    an adversarial pass: the segment reversed all its steps, and an earlier one without an exact
    gradient raised), and equals a whole backward's bit for bit."""
    scene, robot = pendulum
    reversed_steps, backward_step = [], type(scene.sim).backward_step
    monkeypatch.setattr(type(scene.sim), "backward_step",
                        lambda sim, *args: reversed_steps.append(1) or backward_step(sim, *args))
    v0 = torch.tensor([0.3, -0.2], dtype=torch.float64, requires_grad=True)
    early = torch.tensor([0.5, 0.1], dtype=torch.float64, requires_grad=True)
    late = torch.tensor([0.2, -0.3], dtype=torch.float64, requires_grad=True)

    def loss():
        scene.reset()
        robot.set_dofs_velocity(v0)
        robot.control_dofs_force(early)
        for t in range(T):
            if t == 15:
                robot.control_dofs_force(late)
            scene.step()
        return robot.get_dofs_position().sum()

    (of_late,) = torch.autograd.grad(loss(), [late])
    assert len(reversed_steps) == T - 15
    torch.autograd.grad(loss(), [early])
    assert len(reversed_steps) == 2 * T - 15
    loss().backward()
    assert torch.equal(of_late, late.grad) and bool((of_late != 0).all())
