"""Peer rollouts for ``bench/rigid_grad.py``: Genesis (``genesis-world``) and Newton (``newton``).

Runs in the peer's own interpreter (see ``bench/README.md`` for the virtualenvs):

    PYTHON bench/peers.py {genesis,newton} CASE.npz [CASE.npz ...] [--repeats 3]

Each CASE.npz holds ``urdf`` (path, fixed base), ``n_envs`` (0 = unbatched), ``dt`` (s),
``controls`` (n_steps, [n_envs,] n_dofs) joint forces (N·m) and ``q0`` ([n_envs,] n_dofs) initial
joint positions (rad); velocities start at zero. The rollout is the one of ``rigid_grad.py``:
float32, contact-free, joint limits off, gravity −9.81 m/s² along z, one control per step, loss =
sum(q_final²) + sum(qd_final²), gradients into the controls (and q0 where the engine allows).

- Genesis: backend cpu, ``SimOptions(dt, requires_grad)``, its default integrator
  (``approximate_implicitfast``, the only one it differentiates) and ``URDF(default_armature=0.0)``
  (its default adds 0.1 kg·m² of armature to every dof). Its differentiable inputs are setters such
  as ``control_dofs_force``, not ``set_dofs_position``, so gradients reach the controls only; its
  differentiable read-out is ``rigid_solver.get_state()``. In a requires_grad scene genesis-world
  1.4.5 crashes (segfault) or ignores ``set_dofs_position`` given a tensor that does not require
  grad, so q0 is passed requiring grad (its .grad stays None).
- Newton: ``SolverFeatherstone`` (no angular damping) on device "cpu", worlds replicated with
  ``ModelBuilder.replicate``, one State per step recorded on a ``wp.Tape``; joint limits are off
  through zero limit stiffness and damping. Featherstone applies joint damping D explicitly, which
  diverges here (the KUKA URDF's 0.5 N·m·s/rad on its 0.001 kg·m² last link at dt = 0.01 s); adding
  dt·D to the joint armature makes it implicit, (M + dt·D) qdd = tau − D·qd, as ours and MuJoCo's
  Euler integrator do.

Prints lines "RESULT {json}" on stdout (engine logs may share it): first the engine's version, a
note on how its rollout differs and its import + init time (s); then per case the build time of
the differentiable scene (s), forward, fwd+bwd and no-grad forward times (s, best of ``--repeats``
after a warm-up rollout), the final joint positions of the no-grad rollout and whether all
gradients are finite.
"""
import argparse
import contextlib
import json
import time

import numpy as np


def genesis_engine():
    """Import and initialise Genesis; return (version, note, make) where make builds one case."""
    import genesis as gs
    import torch

    gs.init(backend=gs.cpu, precision="32", logging_level="warning")

    def make(urdf, n_envs, dt, controls, q0, requires_grad):
        scene = gs.Scene(sim_options=gs.options.SimOptions(dt=dt, requires_grad=requires_grad),
                         rigid_options=gs.options.RigidOptions(enable_collision=False, enable_joint_limit=False),
                         show_viewer=False)
        robot = scene.add_entity(gs.morphs.URDF(file=urdf, fixed=True, default_armature=0.0))
        scene.build(n_envs=n_envs)
        u = torch.from_numpy(controls).requires_grad_(requires_grad)
        q = torch.from_numpy(q0).requires_grad_(requires_grad)  # see the module docstring
        final = {}

        def forward():
            scene.reset()
            robot.set_dofs_position(q)
            for force in u.unbind(0):  # as rigid_grad.py does
                robot.control_dofs_force(force)
                scene.step()
            state = scene.sim.rigid_solver.get_state()
            final["q"] = state.qpos
            return state.qpos.pow(2).sum() + state.dofs_vel.pow(2).sum()

        def backward(loss):
            u.grad = None
            loss.backward()
            return [u.grad.numpy()]

        return forward, backward, lambda: final["q"].detach().numpy().reshape(q0.shape)

    return gs.__version__, "gradients reach the controls only (q0 is not a differentiable input)", make


def newton_engine():
    """Import Newton and Warp; return (version, note, make) where make builds one case."""
    import newton
    import warp as wp

    wp.config.quiet = True

    @wp.kernel
    def sum_squares(q: wp.array(dtype=float), qd: wp.array(dtype=float), loss: wp.array(dtype=float)):
        i = wp.tid()
        wp.atomic_add(loss, 0, q[i] * q[i] + qd[i] * qd[i])

    def make(urdf, n_envs, dt, controls, q0, requires_grad):
        robot = newton.ModelBuilder(up_axis=newton.Axis.Z, gravity=(0.0, 0.0, -9.81))
        robot.add_urdf(urdf, floating=False, hide_visuals=True, enable_self_collisions=False)
        robot.joint_limit_ke = [0.0] * robot.joint_dof_count
        robot.joint_limit_kd = [0.0] * robot.joint_dof_count
        # Implicit joint damping, as ours and MuJoCo's Euler: (M + dt·D) qdd = tau − D·qd.
        robot.joint_armature = [a + dt * d for a, d in zip(robot.joint_armature, robot.joint_damping)]
        builder = newton.ModelBuilder(up_axis=newton.Axis.Z, gravity=(0.0, 0.0, -9.81))
        builder.replicate(robot, max(n_envs, 1))
        model = builder.finalize(device="cpu", requires_grad=requires_grad)
        solver = newton.solvers.SolverFeatherstone(model, angular_damping=0.0)
        n_steps = len(controls)
        states = [model.state(requires_grad=requires_grad) for _ in range(n_steps + 1)]
        u = wp.array(controls.reshape(n_steps, -1), dtype=float, device="cpu", requires_grad=requires_grad)
        q = wp.array(q0.reshape(-1), dtype=float, device="cpu", requires_grad=requires_grad)
        step_controls = []
        for t in range(n_steps):
            step_controls.append(model.control())
            step_controls[t].joint_f = u[t]  # a view: its gradient lands in u.grad
        loss = wp.zeros(1, dtype=float, device="cpu", requires_grad=requires_grad)

        def forward():
            tape = wp.Tape() if requires_grad else contextlib.nullcontext()
            with tape:
                wp.copy(states[0].joint_q, q)
                states[0].joint_qd.zero_()
                for t in range(n_steps):
                    states[t].clear_forces()
                    solver.step(states[t], states[t + 1], step_controls[t], None, dt)
                loss.zero_()
                final = states[-1]
                wp.launch(sum_squares, dim=model.joint_dof_count, inputs=[final.joint_q, final.joint_qd, loss])
            return tape

        def backward(tape):
            tape.backward(loss)
            grads = [u.grad.numpy().copy(), q.grad.numpy().copy()]
            tape.zero()  # the next rollout reuses these arrays
            return grads

        return forward, backward, lambda: states[-1].joint_q.numpy().reshape(q0.shape)

    note = "joint damping made implicit through armature dt·damping (explicit, it diverges)"
    return f"{newton.__version__} (warp {wp.__version__})", note, make


def time_case(make, case, repeats):
    """Time one case; return a dict of seconds, the final q (list) and whether the gradients are finite."""
    args = str(case["urdf"]), int(case["n_envs"]), float(case["dt"]), case["controls"], case["q0"]
    t0 = time.perf_counter()
    forward, backward, _ = make(*args, requires_grad=True)
    build = time.perf_counter() - t0
    backward(forward())  # warm-up: compiles every kernel
    fwd = fwd_bwd = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = forward()
        t1 = time.perf_counter()
        grads = backward(out)
        t2 = time.perf_counter()
        fwd, fwd_bwd = min(fwd, t1 - t0), min(fwd_bwd, t2 - t0)
    finite = all(bool(np.isfinite(g).all()) for g in grads)

    plain_forward, _, final_q = make(*args, requires_grad=False)
    plain_forward()
    plain = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        plain_forward()
        plain = min(plain, time.perf_counter() - t0)
    return {"build": build, "fwd": fwd, "fwd_bwd": fwd_bwd, "plain": plain, "finite": finite,
            "q_final": final_q().tolist()}


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("engine", choices=["genesis", "newton"])
    parser.add_argument("cases", nargs="+", help=".npz files written by rigid_grad.py")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    t0 = time.perf_counter()
    version, note, make = {"genesis": genesis_engine, "newton": newton_engine}[args.engine]()
    print("RESULT " + json.dumps({"version": version, "note": note, "import": time.perf_counter() - t0}), flush=True)
    for path in args.cases:
        print("RESULT " + json.dumps(time_case(make, np.load(path), args.repeats)), flush=True)


if __name__ == "__main__":
    main()
