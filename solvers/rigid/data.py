"""Taichi storage of the rigid solver: the model's constants, the per-step inputs, the state
frames of one step and every intermediate quantity, each indexed by substep frame.

Frame f of ``qpos``/``qvel`` is the state before substep f (frame S is the step's result).
Intermediates of substep f live at frame f, so after a single forward replay every substep's
values are there for its hand-written adjoint. The ``.grad`` fields are that adjoint's storage
(Taichi's autodiff is not used).
"""
import numpy as np
import taichi as ti

from ..core import runtime

BIG = 1e30  # stands for an absent bound
# Up to this many (env, link) pairs the kernels run on the calling thread. In a rollout, handing a
# loop to Taichi's thread pool costs ~100 µs here (its workers fall asleep between steps), while
# one thread does a link's substep in ~0.1 µs forward and ~0.3 µs reverse; measured on the KUKA,
# 256 envs (2048 pairs) ran 17% faster serial, 1024 envs 50% faster on two threads.
SERIAL_LINK_ENVS = 2048

# Per-step inputs: name → (width per env, differentiable). Their order is the packing order.
INPUTS = {
    "mass": ("links", True),        # kg
    "damping": ("dofs", True),      # N·m·s/rad or N·s/m
    "armature": ("dofs", True),     # kg·m² or kg
    "kp": ("dofs", True),           # N·m/rad or N/m
    "kv": ("dofs", True),           # N·m·s/rad or N·s/m
    "gravity": (3, True),           # m/s²
    "ctrl_force": ("dofs", True),   # N·m or N
    "ctrl_pos": ("dofs", True),     # rad or m
    "ctrl_vel": ("dofs", True),     # rad/s or m/s
    "force_lo": ("dofs", False),    # N·m or N
    "force_hi": ("dofs", False),
    "ctrl_mode": ("dofs", False),   # 0 force, 1 position, 2 velocity (see actuation.py)
}


@ti.data_oriented
class RigidData:
    """Fields of one scene's rigid solver. B envs, S substeps; sizes from the model."""

    def __init__(self, model, n_batch, substeps, requires_grad, limits_enabled):
        self.n_batch, self.substeps = n_batch, substeps
        self.limits_enabled = bool(limits_enabled)  # compile-time switch of the limit forces
        self.serial = n_batch * max(1, model.n_links) <= SERIAL_LINK_ENVS  # compile-time, see above
        self.n_links, self.n_dofs, self.n_qs = model.n_links, model.n_dofs, model.n_qs
        self.n_pairs = len(model.pairs)
        self.widths = {"links": self.n_links, "dofs": self.n_dofs}
        self._builder = ti.FieldsBuilder()
        self.grad_fields = []  # every field with a gradient, inputs first
        self._place_model(model)
        self._place_inputs(requires_grad)
        self._place_frames(requires_grad)
        self._builder.finalize()
        inputs = {id(f) for f in self.input_fields}
        frames = [f.grad for f in self.grad_fields if id(f) not in inputs] + self.grad_only_fields
        self.grad_frame_groups = [tuple(frames[k: k + 32]) for k in range(0, len(frames), 32)]
        self._fill_model(model)

    # -- allocation -------------------------------------------------------------------------
    def _new(self, shape, n=None, m=None, dtype=None, grad=False):
        """Allocate a scalar (n None), vector (n) or matrix (n, m) field; zero-size axes padded to 1."""
        dtype = dtype or runtime.ti_float
        if n is None:
            fld = ti.field(dtype, needs_grad=grad)
        elif m is None:
            fld = ti.Vector.field(n, dtype, needs_grad=grad)
        else:
            fld = ti.Matrix.field(n, m, dtype, needs_grad=grad)
        shape = tuple(max(1, int(s)) for s in shape)
        self._builder.dense(ti.axes(*range(len(shape))), shape).place(fld)
        if grad:
            # a block of its own (lazy_grad would interleave it with the values): the forward
            # then never drags gradients through the cache, and zeroing them is one sweep
            self._builder.dense(ti.axes(*range(len(shape))), shape).place(fld.grad)
            self.grad_fields.append(fld)
        return fld

    def _place_model(self, model):
        L, D, P = self.n_links, self.n_dofs, self.n_pairs
        i32 = ti.i32
        self.link_parent, self.link_jtype = self._new((L,), dtype=i32), self._new((L,), dtype=i32)
        self.link_static = self._new((L,), dtype=i32)
        self.link_dof0, self.link_q0 = self._new((L,), dtype=i32), self._new((L,), dtype=i32)
        self.link_pos0, self.link_quat0 = self._new((L,), 3), self._new((L,), 4)
        self.link_axis, self.link_com = self._new((L,), 3), self._new((L,), 3)
        self.link_inertia0, self.link_inv_mass0 = self._new((L,), 3, 3), self._new((L,))
        self.dof_link, self.dof_q = self._new((D,), dtype=i32), self._new((D,), dtype=i32)
        self.dof_parent = self._new((D,), dtype=i32)
        self.dof_lower, self.dof_upper = self._new((D,)), self._new((D,))
        self.pair_i, self.pair_j = self._new((P,), dtype=i32), self._new((P,), dtype=i32)
        # substep h (s), limit stiffness (1/s²) and damping (1/s): runtime values, so a new dt
        # does not recompile the kernels
        self.consts = self._new((3,))

    def _place_inputs(self, requires_grad):
        self.inputs = {}
        for name, (width, differentiable) in INPUTS.items():
            fld = self._new((self.n_batch, self.width(name)), grad=requires_grad and differentiable)
            setattr(self, name, fld)
            self.inputs[name] = fld
        self.input_fields = list(self.inputs.values())
        self.input_widths = [self.width(name) for name in INPUTS]
        self.input_offsets = [sum(self.input_widths[:k]) for k in range(len(INPUTS))]
        self.input_total = sum(self.input_widths)
        # gradients are read out after the state's (Q + D) columns
        names = [name for name, (_, differentiable) in INPUTS.items() if differentiable and requires_grad]
        self.grad_input_names = names
        self.grad_input_fields = [self.inputs[name] for name in names]
        self.grad_input_widths = [self.width(name) for name in names]
        start = self.n_qs + self.n_dofs
        self.grad_input_offsets = [start + sum(self.grad_input_widths[:k]) for k in range(len(names))]

    def _place_frames(self, g):
        F, B, L, D, Q = self.substeps + 1, self.n_batch, self.n_links, self.n_dofs, self.n_qs
        self.qpos, self.qvel = self._new((F, B, Q), grad=g), self._new((F, B, D), grad=g)
        self.xpos, self.xquat = self._new((F, B, L), 3, grad=g), self._new((F, B, L), 4)
        # a link's rotation is differentiated as a small world-frame turn δθ, not through its
        # quaternion (see kinematics.py): xrot_grad is ∂L/∂δθ, a gradient with no value field
        self.xrot_grad = self._new((F, B, L), 3)
        self.grad_only_fields = [self.xrot_grad] if g else []
        # a link's own inertia has no gradient field: its gradient is its subtree sum's (crb)
        self.cinert_m, self.crb_m = self._new((F, B, L)), self._new((F, B, L), grad=g)
        self.cinert_h, self.crb_h = self._new((F, B, L), 3), self._new((F, B, L), 3, grad=g)
        self.cinert_i, self.crb_i = self._new((F, B, L), 3, 3), self._new((F, B, L), 3, 3, grad=g)
        self.cdof_w, self.cdof_v = self._new((F, B, D), 3, grad=g), self._new((F, B, D), 3, grad=g)
        self.cvel_w, self.cvel_v = self._new((F, B, L), 3, grad=g), self._new((F, B, L), 3, grad=g)
        self.cacc_w, self.cacc_v = self._new((F, B, L), 3, grad=g), self._new((F, B, L), 3, grad=g)
        self.cfrc_n, self.cfrc_f = self._new((F, B, L), 3, grad=g), self._new((F, B, L), 3, grad=g)
        self.dof_force_n, self.dof_force_f = self._new((F, B, D), 3), self._new((F, B, D), 3)
        self.mass_mat = self._new((F, B, D, D), grad=g)
        self.qfrc_bias, self.qfrc_smooth = self._new((F, B, D), grad=g), self._new((F, B, D), grad=g)
        self.qacc = self._new((F, B, D), grad=g)
        self.factor = self._new((F, B, D, D))  # LᵀDL factor of M + diag(armature + h·damping)
        self.nonfinite = self._new((1,), dtype=ti.i32)  # set by the NaN check

    def width(self, name):
        width = INPUTS[name][0]
        return self.widths.get(width, width)

    def _fill_model(self, model):
        f = runtime.np_float
        for name in ("link_parent", "link_jtype", "link_static", "link_dof0", "link_q0", "dof_link", "dof_q",
                     "dof_parent"):
            values = getattr(model, name)
            if len(values):
                getattr(self, name).from_numpy(values.astype(np.int32))
        for name in ("link_pos0", "link_quat0", "link_axis", "link_com", "link_inertia0", "link_inv_mass0",
                     "dof_lower", "dof_upper"):
            values = np.clip(getattr(model, name), -BIG, BIG)  # finite, so no inf·0 in gradients
            if len(values):
                getattr(self, name).from_numpy(values.astype(f))
        if self.n_pairs:
            self.pair_i.from_numpy(model.pairs[:, 0].copy())
            self.pair_j.from_numpy(model.pairs[:, 1].copy())

    def refill(self, model):
        """Take a new model of the same sizes (data reused from the pool)."""
        self._fill_model(model)
        self.mass_mat.fill(0)  # entries off the new dof tree must read as zero
        self.nonfinite.fill(0)


# Kernels are compiled per RigidData object (Taichi keys template arguments by identity) and
# their code is never freed, so data of finished scenes is kept here and handed to the next
# scene of the same sizes: no recompilation, no growth when a process builds many scenes.
_POOL = {}


def _signature(model, n_batch, substeps, requires_grad, limits_enabled):
    return (runtime.epoch, n_batch, substeps, bool(requires_grad), bool(limits_enabled), model.n_links,
            model.n_dofs, model.n_qs, len(model.pairs))


def acquire(model, n_batch, substeps, requires_grad, limits_enabled):
    """RigidData for ``model``: a released one of the same sizes, or a new one."""
    key = _signature(model, n_batch, substeps, requires_grad, limits_enabled)
    free = _POOL.get(key)
    if free:
        data = free.pop()
        data.refill(model)
        return data
    data = RigidData(model, n_batch, substeps, requires_grad, limits_enabled)
    data.signature = key
    return data


def release(data):
    """Return data whose scene is gone; dropped if Taichi was restarted since."""
    if data.signature[0] == runtime.epoch:
        _POOL.setdefault(data.signature, []).append(data)


@ti.func
def accumulate(fld: ti.template(), index, value):
    """fld[index] += value without an atomic. The step kernels give each env to one thread, so
    nothing else writes there, and Taichi's ``+=`` on a field is an atomic costing several
    plain adds on CPU."""
    fld[index] = fld[index] + value
