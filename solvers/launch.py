"""Launching Taichi kernels with little Python overhead.

A Taichi 1.7 kernel call spends ~30 µs in Python on this machine (template lookup, argument
checks, launch context), more than a small scene's whole step. A :class:`BoundKernel` lets
Taichi compile and check the first call of each signature as usual, and afterwards fills the
launch context itself: a few µs a launch. The compiled kernel is shared by every scene (the
scene's data are array arguments), so the cache is per kernel, not per scene. It uses Taichi
1.7's kernel internals (``_primal``, ``compiled_kernels``, ``make_launch_context``), which is
why pyproject.toml pins taichi 1.7.*.
"""
import torch
from taichi.lang import impl
from taichi.lang._ndarray import Ndarray

# kernel → {(template value, argument signature): (program, compiled kernel, code)}
_COMPILED = {}


def _signature(args):
    """What Taichi compiles a kernel for: the kinds, dtypes and dims of its array arguments."""
    return tuple((a.dtype, a.dim()) if isinstance(a, torch.Tensor) else
                 (a.dtype, a.element_shape, len(a.shape)) if isinstance(a, Ndarray) else int
                 for a in args)


class BoundKernel:
    """``kernel(template, *arrays, *args)``: a kernel with one compile-time argument, then a scene's
    arenas (Taichi ndarrays), then Python ints and contiguous torch tensors."""

    def __init__(self, kernel, template, arrays):
        self.kernel, self.template, self.arrays = kernel, template, list(arrays)
        self.compiled = _COMPILED.setdefault(kernel, {})

    def __call__(self, *args):
        program = impl.get_runtime().prog
        key = (self.template, _signature(self.arrays) + _signature(args))
        entry = self.compiled.get(key)
        if entry is None or entry[0] is not program:
            self.kernel(self.template, *self.arrays, *args)  # compiles and checks the arguments
            self.compiled[key] = self._resolve(program, args)
            return
        _, kernel, code = entry
        context = kernel.make_launch_context()
        for k, array in enumerate(self.arrays):
            context.set_arg_ndarray((k,), array.arr)
        for k, arg in enumerate(args, start=len(self.arrays)):
            if isinstance(arg, torch.Tensor):
                if not arg.is_contiguous():
                    raise ValueError(f"{self.kernel.__name__}: argument {k} must be a contiguous tensor")
                context.set_arg_external_array_with_shape((k,), arg.data_ptr(), arg.element_size() * arg.numel(),
                                                          tuple(arg.shape), 0)
            else:
                context.set_arg_int((k,), int(arg))
        program.launch_kernel(code, context)

    def _resolve(self, program, args):
        primal = self.kernel._primal
        kernel = primal.compiled_kernels[primal.ensure_compiled(self.template, *self.arrays, *args)]
        return program, kernel, program.compile_kernel(program.config(), program.get_device_caps(), kernel)


class BoundKernels:
    """Kernels bound to one scene's arrays: ``kernels.read_state(0, out)``."""

    def __init__(self, template, arrays, *kernels):
        for kernel in kernels:
            setattr(self, kernel.__name__, BoundKernel(kernel, template, arrays))
