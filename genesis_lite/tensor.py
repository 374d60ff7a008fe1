"""Genesis tensors: ``gs.Tensor`` is a ``torch.Tensor`` that knows its scene.

Every getter returns one; every setter accepts it, a plain torch tensor, a numpy array or a
list. Creation ops put data on ``gs.device`` in ``gs.tc_float`` (integers keep their dtype).
"""
import numpy as np
import torch

from .solvers.core import runtime


class Tensor(torch.Tensor):
    """A torch tensor with a ``scene`` attribute (None when made by a creation op). What torch
    computes from one is a plain torch tensor, as Genesis 1.4.5's getters' results: torch's
    subclass dispatch, which would wrap every result, doubled the cost of each small op (10k
    ``p * 2 + 1`` on a getter's result: 0.20 against 0.11 s)."""
    scene = None
    __torch_function__ = torch._C._disabled_torch_function_impl

    def __repr__(self, *, tensor_contents=None):
        return "gs." + super().__repr__(tensor_contents=tensor_contents)

    def __format__(self, spec):
        # torch formats only plain 0-dim tensors with a spec like ".2f"
        return format(self.item(), spec) if self.dim() == 0 else super().__format__(spec)

    def __deepcopy__(self, memo):
        # torch's own needs new_empty to return this class. As torch's: a leaf's data (and grad)
        # copied, requires_grad kept, a non-leaf refused; the scene kept (it is not data)
        if not self.is_leaf:
            raise RuntimeError("Only Tensors created explicitly by the user (graph leaves) support the deepcopy "
                               "protocol at the moment")
        copied = wrap(self.detach().as_subclass(torch.Tensor).clone(), self.scene).requires_grad_(self.requires_grad)
        if self.grad is not None:
            copied.grad = self.grad.detach().clone()
        memo[id(self)] = copied
        return copied

    def __reduce_ex__(self, protocol):
        # saved (torch.save, pickle) as a plain torch tensor: loading it needs no genesis_lite, and
        # torch.load's default weights_only=True refuses classes it does not know
        return self.as_subclass(torch.Tensor).__reduce_ex__(protocol)


def wrap(value, scene=None):
    """View a torch tensor as a gs.Tensor of ``scene`` (autograd history is kept)."""
    out = value.as_subclass(Tensor)
    out.scene = scene
    return out


def _float_dtype(dtype):
    return runtime.tc_float if dtype is None else dtype


def tensor(data, dtype=None, requires_grad=False, scene=None):
    """Copy ``data`` (list, numpy or torch) into a new gs.Tensor on gs.device."""
    if isinstance(data, torch.Tensor):
        base = data.detach().clone().to(device=runtime.device)
        base = base.to(_float_dtype(dtype)) if (dtype is not None or base.is_floating_point()) else base
    else:
        arr = np.asarray(data)
        as_float = dtype is not None or arr.dtype.kind == "f"
        base = torch.as_tensor(arr, device=runtime.device)
        base = base.to(_float_dtype(dtype)) if as_float else base
    return wrap(base, scene).requires_grad_(requires_grad)


def from_numpy(array, requires_grad=False):
    """gs.Tensor from a numpy array."""
    return tensor(np.asarray(array), requires_grad=requires_grad)


def from_torch(value, detach=True, requires_grad=False):
    """gs.Tensor from a torch tensor. detach=False keeps its autograd history."""
    if detach:
        return tensor(value, requires_grad=requires_grad)
    moved = value.to(device=runtime.device, dtype=runtime.tc_float if value.is_floating_point() else value.dtype)
    return wrap(moved)


def _maker(fn):
    def make(*size, dtype=None, requires_grad=False, **kwargs):
        out = fn(*size, dtype=_float_dtype(dtype), device=runtime.device, **kwargs)
        return wrap(out).requires_grad_(requires_grad)
    make.__name__ = fn.__name__
    make.__doc__ = f"torch.{fn.__name__} on gs.device in gs.tc_float, as a gs.Tensor."
    return make


zeros = _maker(torch.zeros)
ones = _maker(torch.ones)
rand = _maker(torch.rand)
randn = _maker(torch.randn)


def zeros_like(value, dtype=None, requires_grad=False):
    """Zeros shaped like ``value`` on gs.device in gs.tc_float."""
    return zeros(*tuple(value.shape), dtype=dtype, requires_grad=requires_grad)


def ones_like(value, dtype=None, requires_grad=False):
    """Ones shaped like ``value`` on gs.device in gs.tc_float."""
    return ones(*tuple(value.shape), dtype=dtype, requires_grad=requires_grad)
