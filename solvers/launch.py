"""Launching Taichi kernels with little Python overhead.

A Taichi 1.7 kernel call spends ~30 µs in Python on this machine (template lookup, argument
checks, launch context), more than a small scene's whole step. A :class:`BoundKernel` lets
Taichi compile and check the first call of each signature as usual, and afterwards fills the
launch context itself; a launch that repeats one it met (the same scalars, or the same tensors
as the last call) reuses that context as it is, leaving ~2 µs of Taichi's own C++ a launch. The
compiled kernel is shared by every scene (the scene's data are array arguments), so the cache is
per kernel, not per scene. It uses Taichi 1.7's kernel internals (``_primal``, ``arguments``,
``compiled_kernels``, ``make_launch_context``), which is why pyproject.toml pins taichi 1.7.*.
"""
import contextlib
import operator

import taichi as ti
import torch
from taichi.lang import impl
from taichi.types.ndarray_type import NdarrayType

from .core import InvalidInputError

# kernel → {(template value, argument signature): (program, compiled kernel, code, on CUDA)}
_COMPILED = {}
# launch contexts a kernel of scalar arguments keeps (one per argument tuple: substep, frame...)
MAX_SCALAR_CONTEXTS = 256
# Taichi's opt_level (taichi_opt_level) of the rigid kernels that run no iterative solve and of the
# MPM's reverse kernels: 0 skips Taichi's whole-kernel common-subexpression elimination, which walks
# the whole kernel twice for each expression it removes (quadratic in a kernel's size): Taichi's
# scoped profiler gave it 4.5 of the 8.4 s Taichi took to compile a differentiable box on a plane's
# kernels (float64, empty cache; float32: at 0 the convex collider compiled in 15 s instead of 43,
# its reverse in 8 instead of 31). LLVM's own CSE still runs and the bits are the same
# (tests/test_compile_once.py). The rigid kernels measured run as fast at 0 (KUKA at 256 envs,
# contact scenes at 256 and 1024 envs); the constraint solve and its reverse do not (SOLVE_OPT_LEVEL). The
# MPM's reverse kernels ran as fast at 0 (10k neo-Hookean particles, fwd + bwd; their compile 3.0 →
# 0.75 and 2.3 → 0.56 s, float64), its forward kernels 8-17 % slower (they keep 1); the rigid–MPM
# coupler's kernels keep 1 (not measured).
LIGHT_OPT_LEVEL = 0
# Taichi's opt_level of the rigid constraint solve, its reverse and inverse kinematics: at 0 they
# compile in about half the time (at 1 the solve and its reverse took half the compile time of a
# cold test suite) and run slower where the solve dominates (at 1024 envs the box 9 %, the a1 5 %,
# the tower the same; 2026-12-02): 1 for users. The default test suite compiles them at 0
# (tests/conftest.py); a slow test checks that both levels compute the same bits
# (tests/test_compile_once.py).
SOLVE_OPT_LEVEL = 1


def forget():
    """Drop every compiled kernel (Taichi is restarting: they belong to the old program)."""
    _COMPILED.clear()


def _signature(args):
    """What Taichi compiles a kernel for: the dtypes and dims of its array arguments."""
    return tuple((a.dtype, a.dim()) if isinstance(a, torch.Tensor) else int for a in args)


@contextlib.contextmanager
def taichi_opt_level(level):
    """Taichi's opt_level for the kernels compiled inside (a kernel compiles at its first call):
    0 skips Taichi's whole-kernel common-subexpression elimination (LLVM's own still runs), most
    of Taichi's compile time on the largest kernels; 1 is Taichi's default. Set on the running
    program's config and restored, as Taichi itself sets it (kernel_impl.py). The offline cache
    keys a compiled kernel by it, but within a runtime Taichi keeps a kernel's first compile per
    template value (its kernel key is made once): a kernel serves one level until Taichi restarts."""
    config = impl.current_cfg()
    before = config.opt_level
    config.opt_level = level
    try:
        yield
    finally:
        config.opt_level = before


class BoundKernel:
    """``kernel(template, *arrays, *args)``: a kernel with one compile-time argument, then a scene's
    arrays (contiguous torch tensors whose trailing ``element_dims`` dims are each element's shape,
    as the kernel annotates them), then Python ints and contiguous torch tensors. A tensor passed
    again as the same object is taken to be the same array: never resize or re-stride one in place
    between launches (the solvers pass their own tensors). opt_level: Taichi's for this kernel
    (see ``taichi_opt_level``)."""

    def __init__(self, kernel, template, arrays, element_dims, opt_level=1):
        self.kernel, self.template, self.arrays = kernel, template, list(arrays)
        self.opt_level = opt_level
        self.arrays_signature = _signature(self.arrays)
        self._check(self.arrays, impl.current_cfg().arch == ti.cuda, first=0)
        # what a launch context takes of each array (Taichi wants its shape without the element's)
        self.array_args = [(a.data_ptr(), a.element_size() * a.numel(), tuple(a.shape[: a.dim() - n]))
                           for a, n in zip(self.arrays, element_dims)]
        self.compiled = _COMPILED.setdefault(kernel, {})
        self.contexts = {}  # compiled entry → its launch context with the arrays already set
        # A repeated launch only launches (~2 µs saved a launch): a kernel whose other arguments
        # are all scalars keeps a launch context per argument tuple it met, every argument set;
        # another keeps its last call's arguments (alive, so the same objects are the same arrays)
        parameters = kernel._primal.arguments[1 + len(self.arrays):]
        self.scalars_only = not any(isinstance(p.annotation, NdarrayType) for p in parameters)
        self.by_scalars = {}  # scalar arguments → (program, code, launch context)
        self.last = None      # (program, arguments, code, launch context, on CUDA) of the last call

    def __call__(self, *args):
        program = impl.get_runtime().prog
        if self.scalars_only:
            ready = self.by_scalars.get(args)
            if ready is not None and ready[0] is program:
                program.launch_kernel(ready[1], ready[2])
                return
        elif (last := self.last) is not None and last[0] is program and len(args) == len(last[1]):
            if all(map(operator.is_, args, last[1])):
                program.launch_kernel(last[2], last[3])
                return
            if self._relaunch(args, last):
                return
        key = (self.template, self.arrays_signature + _signature(args))
        entry = self.compiled.get(key)
        if entry is None or entry[0] is not program:
            self._check(args, program.config().arch == ti.cuda)
            with taichi_opt_level(self.opt_level):
                self.kernel(self.template, *self.arrays, *args)  # compiles and checks the arguments
                self.compiled[key] = self._resolve(program, args)
            return
        _, kernel, code, on_cuda = entry
        if self.scalars_only:
            if len(self.by_scalars) >= MAX_SCALAR_CONTEXTS:
                self.by_scalars.clear()
            context = self._new_context(entry)
            self._set_args(context, args, range(len(args)))
            self.by_scalars[args] = (program, code, context)  # (once set: an argument that raised leaves none)
        else:
            self._check(args, on_cuda)
            context = self._context(entry)
            self.last = None  # (until every argument is set: one that raised leaves the context unrecorded)
            self._set_args(context, args, range(len(args)))
            self.last = (program, args, code, context, on_cuda)
        program.launch_kernel(code, context)

    def _relaunch(self, args, last):
        """Launch with the last call's context, setting again only the arguments that are other
        objects, when each is of the same kind (a tensor of the same dtype and dims, or an int): the
        compiled kernel is then the same. A differentiable step downloads into a new state tensor
        and a backward's launches take new gradient tensors: setting every argument again cost
        ~7 µs such a launch. False (nothing done) when some argument changed kind."""
        program, held, code, context, on_cuda = last
        changed = [k for k, (arg, before) in enumerate(zip(args, held)) if arg is not before]
        for k in changed:
            arg, before = args[k], held[k]
            if isinstance(arg, torch.Tensor) != isinstance(before, torch.Tensor) or (
                    isinstance(arg, torch.Tensor) and (arg.dtype != before.dtype or arg.dim() != before.dim())):
                return False
        for k in changed:
            self._check((args[k],), on_cuda, first=len(self.arrays) + k)
        self.last = None  # (as in __call__)
        self._set_args(context, args, changed)
        self.last = (program, args, code, context, on_cuda)
        program.launch_kernel(code, context)
        return True

    def _set_args(self, context, args, which):
        """Set args[k] (after the arrays) in ``context`` for each k in ``which``."""
        for k in which:
            arg, index = args[k], len(self.arrays) + k
            if isinstance(arg, torch.Tensor):
                context.set_arg_external_array_with_shape((index,), arg.data_ptr(), arg.element_size() * arg.numel(),
                                                          tuple(arg.shape), 0)
            else:
                context.set_arg_int((index,), int(arg))

    def _context(self, entry):
        """A launch context of the compiled ``entry`` holding this scene's arrays. It is made once
        and reused: a launch only reads it, and setting the five arrays cost ~4 µs a launch."""
        cached = self.contexts.get(key := id(entry))
        if cached is None or cached[0] is not entry:
            cached = self.contexts[key] = (entry, self._new_context(entry))
        return cached[1]

    def _new_context(self, entry):
        """A launch context of the compiled ``entry`` with this scene's arrays set. The arrays never
        move: this object keeps them alive."""
        context = entry[1].make_launch_context()
        for k, (pointer, size, shape) in enumerate(self.array_args):
            context.set_arg_external_array_with_shape((k,), pointer, size, shape, 0)
        return context

    def _check(self, args, on_cuda, first=None):
        """Tensors must be contiguous and on the kernels' device: never device memory to CPU code.
        first: the kernel parameter index of args[0] (default: after the arrays)."""
        for k, arg in enumerate(args, start=len(self.arrays) if first is None else first):
            if not isinstance(arg, torch.Tensor):
                continue
            if arg.is_cuda != on_cuda:
                raise InvalidInputError(f"{self.kernel.__name__}: argument {k} must be a tensor on "
                                        f"{'cuda' if on_cuda else 'the cpu'}, got one on {arg.device}")
            if not arg.is_contiguous():
                raise InvalidInputError(f"{self.kernel.__name__}: argument {k} must be a contiguous tensor, got one "
                                        f"with strides {arg.stride()} for shape {tuple(arg.shape)}")

    def _resolve(self, program, args):
        primal = self.kernel._primal
        kernel = primal.compiled_kernels[primal.ensure_compiled(self.template, *self.arrays, *args)]
        code = program.compile_kernel(program.config(), program.get_device_caps(), kernel)
        return program, kernel, code, program.config().arch == ti.cuda


class BoundKernels:
    """Kernels bound to one scene's arrays: ``kernels.read_state(0, out)``."""

    def __init__(self, template, arrays, element_dims, *kernels, opt_level=1):
        self.bind(template, arrays, element_dims, *kernels, opt_level=opt_level)

    def bind(self, template, arrays, element_dims, *kernels, opt_level=1):
        """Bind more kernels (or bind them again), with their own compile-time argument and Taichi's
        opt_level (see BoundKernel); returns self."""
        for kernel in kernels:
            setattr(self, kernel.__name__, BoundKernel(kernel, template, arrays, element_dims, opt_level))
        return self
