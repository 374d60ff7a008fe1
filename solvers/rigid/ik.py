"""Inverse kinematics of one entity in one launch: damped least squares on the solver's own
kinematics, every sample and iteration of every env inside the kernel (Genesis's method and
rules; genesis_lite/entities/kinematics.py states them and builds the arrays).

Per env (row r of ``envs``), sample after sample (``starts[k]`` where limits are respected, else
each from the last one's end), up to ``iterations`` steps:
the entity's links are posed at the trial qpos in the frame no step uses (the last: the link
getters' own, which recompute it from the state), each goal's error is its masked position
error (world) and rotation vector from the link to the target (link frame); where every goal is
within tolerance the sample stops with that qpos; else the Jacobian rows of the errors
(kinematics.dof_motion_at at the goal's point; rotation rows turned into the link frame, the
columns of the dofs that do not move zero) give the step Jᵀ (J Jᵀ + λ² I)⁻¹ err, scaled so that
no component exceeds ``max_step``, and the joints move (free joints' positions along the world
axes, quaternions turned about their own axes, scalar joints clipped to their limits when
respected). An unsolved sample's last qpos becomes the best where no goal's error is worse.

Arrays (r: row of ``envs``; K goals; D, Q the entity's dofs and qs):
  envs (R,) i32; sizes (9,) i32: q_start, dof_start, link_start, link_end, samples, iterations,
  limited, spread (the thread pool's loop: rows × spread iterations), n_joints;
  joints (n_joints, 4) i32: kind (FREE_MOVE, TURN, SCALAR), local dof, local q, scalar index;
  limits (R, n_scalar, 2); moving (D,) i32; goal_link (K,) i32 (solver link); goal_spec (K, 9):
  point in the link (3), error mask (6); targets (R, K, 7): pos (3), unit quat (4);
  starts (samples, R, Q) (limits respected; else (1, R, Q)); options (4,): damping, pos_tol, rot_tol, max_step;
  scratch: jac (R, 6K, D), gram (R, 6K, 6K), vec (R, 6K, 2), q (R, Q), step (R, D);
  out: best_q (R, Q), best_err (R, K, 6).
"""
import taichi as ti

from .data import ARENA_TYPES, bind
from .kinematics import dof_count, dof_motion_at, link_kinematics
from .spatial import mat_vec, quat_conj, quat_integrate, quat_mul, quat_rotation_vector, quat_to_mat

A = ti.types.ndarray()
I, F, V3, V4, M3 = ARENA_TYPES
FREE_MOVE, TURN, SCALAR = 0, 1, 2  # joints' kinds: a free joint's translation, a quaternion, one coordinate


@ti.kernel
def inverse_kinematics(serial: ti.template(), ints: I, f1: F, v3: V3, v4: V4, m3: M3, envs: A, sizes: A,
                       joints: A, limits: A, moving: A, goal_link: A, goal_spec: A, targets: A, starts: A,
                       options: A, jac: A, gram: A, vec: A, q: A, step: A, best_q: A, best_err: A):
    ti.loop_config(serialize=serial)
    for t in range(envs.shape[0] * sizes[7]):
        if t % sizes[7] == 0:
            d = bind(ints, f1, v3, v4, m3)
            r = t // sizes[7]
            _solve_row(d, r, envs[r], envs, sizes, joints, limits, moving, goal_link, goal_spec, targets, starts,
                       options, jac, gram, vec, q, step, best_q, best_err)


@ti.func
def _solve_row(d: ti.template(), r, e, envs: ti.template(), sizes: ti.template(), joints: ti.template(),
               limits: ti.template(), moving: ti.template(), goal_link: ti.template(), goal_spec: ti.template(),
               targets: ti.template(), starts: ti.template(), options: ti.template(), jac: ti.template(),
               gram: ti.template(), vec: ti.template(), q: ti.template(), step: ti.template(),
               best_q: ti.template(), best_err: ti.template()):
    """Row r (env e): the samples in turn until one is solved → best_q[r], best_err[r]."""
    f = d.substeps  # the getters' frame
    for k in range(d.n_qs):  # the other entities (a parent one's links) as the state has them
        d.qpos[f, e, k] = d.qpos[0, e, k]
    for l in range(sizes[2]):
        link_kinematics(d, f, e, l)
    Q = best_q.shape[1]
    for k in range(Q):
        best_q[r, k] = starts[0, r, k]
    for g, c in ti.ndrange(best_err.shape[1], 6):
        best_err[r, g, c] = ti.math.inf
    solved = False
    for sample in range(sizes[4]):
        if not solved:
            if sample == 0 or sizes[6] != 0:  # without limits a sample goes on from the last one's end
                for k in range(Q):
                    q[r, k] = starts[sample, r, k]
            iteration = 0
            while iteration <= sizes[5] and not solved:
                _pose(d, f, e, r, sizes, q)
                if _errors(d, f, e, r, goal_link, goal_spec, targets, vec, options):
                    solved = True
                    _keep(r, q, vec, best_q, best_err)
                elif iteration < sizes[5]:
                    _jacobian(d, f, e, r, sizes, moving, goal_link, goal_spec, jac)
                    _damped_step(r, jac, gram, vec, step, options)
                    _move(r, sizes, joints, limits, moving, q, step)
                iteration += 1
            if not solved and _improved(r, vec, best_err):
                _keep(r, q, vec, best_q, best_err)


@ti.func
def _pose(d: ti.template(), f, e, r, sizes: ti.template(), q: ti.template()):
    """The entity's links posed at qpos q[r] in frame f (their parents outside it are posed)."""
    for k in range(q.shape[1]):
        d.qpos[f, e, sizes[0] + k] = q[r, k]
    for l in range(sizes[2], sizes[3]):
        link_kinematics(d, f, e, l)


@ti.func
def _goal_point(d: ti.template(), f, e, goal_link: ti.template(), goal_spec: ti.template(), g):
    """(world point (3,), link rotation (3, 3)) of goal g's point on its link."""
    l = goal_link[g]
    rot = quat_to_mat(d.xquat[f, e, l])
    local = ti.Vector([goal_spec[g, 0], goal_spec[g, 1], goal_spec[g, 2]])
    return d.xpos[f, e, l] + mat_vec(rot, local), rot


@ti.func
def _errors(d: ti.template(), f, e, r, goal_link: ti.template(), goal_spec: ti.template(), targets: ti.template(),
            vec: ti.template(), options: ti.template()):
    """vec[r, :, 0] ← each goal's masked (position error, rotation vector); whether every goal is
    within the tolerances."""
    within = True
    for g in range(goal_link.shape[0]):
        point, _rot = _goal_point(d, f, e, goal_link, goal_spec, g)
        target = ti.Vector([targets[r, g, 3], targets[r, g, 4], targets[r, g, 5], targets[r, g, 6]])
        turn = quat_rotation_vector(quat_mul(quat_conj(d.xquat[f, e, goal_link[g]]), target))
        pos_sq, rot_sq = 0.0, 0.0
        for c in ti.static(range(3)):
            pos_c = (targets[r, g, c] - point[c]) * goal_spec[g, 3 + c]
            rot_c = turn[c] * goal_spec[g, 6 + c]
            vec[r, 6 * g + c, 0], vec[r, 6 * g + 3 + c, 0] = pos_c, rot_c
            pos_sq += pos_c * pos_c
            rot_sq += rot_c * rot_c
        if not (ti.sqrt(pos_sq) <= options[1] and ti.sqrt(rot_sq) <= options[2]):  # (NaN: not within)
            within = False
    return within


@ti.func
def _jacobian(d: ti.template(), f, e, r, sizes: ti.template(), moving: ti.template(), goal_link: ti.template(),
              goal_spec: ti.template(), jac: ti.template()):
    """jac[r] ← the errors' rows (6K, D): the moving dofs on each goal's link's path to the entity's
    root move its point (linear, world) and turn it (angular, link frame), masked."""
    for i, j in ti.ndrange(jac.shape[1], jac.shape[2]):
        jac[r, i, j] = 0.0
    for g in range(goal_link.shape[0]):
        point, rot = _goal_point(d, f, e, goal_link, goal_spec, g)
        link = goal_link[g]
        while link >= sizes[2]:
            for i in range(d.link_dof0[link], d.link_dof0[link] + dof_count(d, link)):
                local = i - sizes[1]
                if moving[local]:
                    linear, angular = dof_motion_at(d, f, e, i, point)
                    turn = mat_vec(rot.transpose(), angular)
                    for c in ti.static(range(3)):
                        jac[r, 6 * g + c, local] = linear[c] * goal_spec[g, 3 + c]
                        jac[r, 6 * g + 3 + c, local] = turn[c] * goal_spec[g, 6 + c]
            link = d.link_parent[link]


@ti.func
def _damped_step(r, jac: ti.template(), gram: ti.template(), vec: ti.template(), step: ti.template(),
                 options: ti.template()):
    """step[r] ← Jᵀ (J Jᵀ + λ² I)⁻¹ err (Cholesky), scaled so that no component exceeds max_step."""
    n, D = jac.shape[1], jac.shape[2]
    for a in range(n):
        for b in range(a + 1):
            total = options[0] * options[0] if a == b else 0.0
            for k in range(D):
                total += jac[r, a, k] * jac[r, b, k]
            gram[r, a, b] = total
    for a in range(n):  # L Lᵀ in the lower triangle
        for b in range(a + 1):
            total = gram[r, a, b]
            for k in range(b):
                total -= gram[r, a, k] * gram[r, b, k]
            gram[r, a, b] = ti.sqrt(total) if a == b else total / gram[r, b, b]
    for a in range(n):  # L y = err
        total = vec[r, a, 0]
        for k in range(a):
            total -= gram[r, a, k] * vec[r, k, 1]
        vec[r, a, 1] = total / gram[r, a, a]
    for back in range(n):  # Lᵀ x = y
        a = n - 1 - back
        total = vec[r, a, 1]
        for k in range(a + 1, n):
            total -= gram[r, k, a] * vec[r, k, 1]
        vec[r, a, 1] = total / gram[r, a, a]
    largest = options[3]
    for k in range(D):
        total = 0.0
        for a in range(n):
            total += jac[r, a, k] * vec[r, a, 1]
        step[r, k] = total
        largest = ti.max(largest, ti.abs(total))
    for k in range(D):
        step[r, k] *= options[3] / largest


@ti.func
def _move(r, sizes: ti.template(), joints: ti.template(), limits: ti.template(), moving: ti.template(),
          q: ti.template(), step: ti.template()):
    """q[r] moved by step[r]: a free joint's position along the world axes, a moving quaternion
    turned about its own axes (q ⊗ exp(ω/2)), a scalar joint by its step, clipped to its limits
    where they are respected and it moves."""
    for j in range(sizes[8]):
        kind, dof, at = joints[j, 0], joints[j, 1], joints[j, 2]
        if kind == FREE_MOVE:
            for c in ti.static(range(3)):
                q[r, at + c] += step[r, dof + c]
        elif kind == TURN:
            if moving[dof] or moving[dof + 1] or moving[dof + 2]:  # (a turn by zero would still normalise
                # the quaternion of one that does not move)
                quat = quat_integrate(ti.Vector([q[r, at + c] for c in ti.static(range(4))]),
                                      ti.Vector([step[r, dof + c] for c in ti.static(range(3))]), 1.0)
                for c in ti.static(range(4)):
                    q[r, at + c] = quat[c]
        else:
            value = q[r, at] + step[r, dof]
            if sizes[6] and moving[dof]:
                value = ti.min(ti.max(value, limits[r, joints[j, 3], 0]), limits[r, joints[j, 3], 1])
            q[r, at] = value


@ti.func
def _improved(r, vec: ti.template(), best_err: ti.template()):
    """Whether no goal's position or rotation error (vec[r, :, 0]) is longer than the best's."""
    better = True
    for g in range(best_err.shape[1]):
        now_pos, now_rot, best_pos, best_rot = 0.0, 0.0, 0.0, 0.0
        for c in ti.static(range(3)):
            now_pos += vec[r, 6 * g + c, 0] ** 2
            now_rot += vec[r, 6 * g + 3 + c, 0] ** 2
            best_pos += best_err[r, g, c] ** 2
            best_rot += best_err[r, g, 3 + c] ** 2
        if not (now_pos <= best_pos and now_rot <= best_rot):  # (NaN: not better)
            better = False
    return better


@ti.func
def _keep(r, q: ti.template(), vec: ti.template(), best_q: ti.template(), best_err: ti.template()):
    for k in range(q.shape[1]):
        best_q[r, k] = q[r, k]
    for g, c in ti.ndrange(best_err.shape[1], 6):
        best_err[r, g, c] = vec[r, 6 * g + c, 0]
