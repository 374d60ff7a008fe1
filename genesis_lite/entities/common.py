"""What every entity kind shares: checked local and env indices, the batch axis of results, and
out-of-place writes into the simulator's (B, W) state and input tables (so autograd sees them)."""
import functools
import inspect
import itertools

import numpy as np
import torch

from ..solvers.core import InvalidInputError, runtime
from ..tensor import wrap


def replace_columns(table, envs, columns, values):
    """``table`` (B, W) with ``values`` (len(envs), len(columns)) written at (envs, columns),
    out of place so autograd sees it. A full overwrite is a copy of ``values``: nothing is saved
    for backward and the previous table drops out of the graph. Always a new tensor: values are
    taken at the call, as Genesis writes them into its fields, so a caller that refills its own
    tensor in place afterwards (a control buffer reused every step) changes neither the scene nor
    the graph that autograd checks."""
    columns = np.asarray(columns)
    if is_range(columns, table.shape[1]) and is_range(envs, table.shape[0]):
        return values.clone()
    rows = torch.as_tensor(envs, device=table.device)[:, None]
    cols = torch.as_tensor(columns, device=table.device)[None, :]
    return table.index_put((rows, cols), values)


def take(table, envs, index, axis=1):
    """A new tensor: ``table``'s (B, …) rows ``envs`` (int array; None: every row, not gathered)
    and its entries ``index`` (int array) along ``axis``. index_select: a getter's read in one or
    two torch calls (indexing with tensors cost four and an extra copy of the table)."""
    if envs is not None:
        table = table.index_select(0, torch.as_tensor(envs, device=table.device))
    return table.index_select(axis, torch.as_tensor(index, device=table.device))


def is_range(idx, n):
    """``idx`` (int numpy array) is exactly 0, 1, …, n − 1 (Python lists compare short arrays
    ~10× faster than numpy)."""
    if len(idx) != n:
        return False
    return idx.tolist() == list(range(n)) if n <= 64 else bool(np.array_equal(idx, np.arange(n)))


def broadcast(tensor, expected):
    """``tensor`` broadcast to the shape ``expected`` as Genesis broadcasts a setter's value (its
    broadcast_tensor), or None when it does not fit: a scalar fills it; a value of fewer dims whose
    trailing sizes are not ``expected``'s trailing ones goes to the last placement of its dims
    among ``expected``'s (each equal or 1) that fits, e.g. (B,) for one dof becomes (B, 1); then
    torch's expand (sizes of 1 repeat). Differentiable (torch's expand)."""
    if tensor.shape == expected:  # (a step's control: the hot path)
        return tensor
    if tensor.dim() > len(expected):
        return None
    if tensor.dim() == 0:
        tensor = tensor[None]
    elif tensor.dim() < len(expected) and tuple(tensor.shape) != tuple(expected[len(expected) - tensor.dim():]):
        for dims in reversed(list(itertools.combinations(range(len(expected)), tensor.dim()))):
            if all(tensor.shape[k] in (1, expected[d]) for k, d in enumerate(dims)):
                shape = [1] * len(expected)
                for k, d in enumerate(dims):
                    shape[d] = tensor.shape[k]
                tensor = tensor.reshape(shape)
                break
    try:
        return tensor.expand(expected)
    except RuntimeError:
        return None


def all_finite(tensor):
    """No NaN or inf in ``tensor`` (numpy's check is 3× cheaper than torch's on small CPU tensors)."""
    if tensor.device.type == "cpu":
        return bool(np.isfinite(tensor.numpy(force=True)).all())
    return bool(torch.isfinite(tensor).all())


def envs_mask_to_idx(envs_idx, n_envs, who):
    """A boolean mask over the envs (as Genesis takes one) → the indices it selects; any other
    ``envs_idx`` is returned as it is."""
    if isinstance(envs_idx, torch.Tensor) and envs_idx.device.type == "meta":
        raise InvalidInputError(f"{who}: argument 'envs_idx' must hold values, got a tensor on the meta device")
    mask = envs_idx.detach().cpu().numpy() if isinstance(envs_idx, torch.Tensor) else envs_idx
    if not (isinstance(mask, (np.ndarray, list, tuple)) and np.asarray(mask).dtype == np.bool_):
        return envs_idx
    if np.asarray(mask).shape != (n_envs,):
        raise InvalidInputError(f"{who}: argument 'envs_idx' as a boolean mask must have shape ({n_envs},), got "
                                f"{np.asarray(mask).shape}")
    return np.flatnonzero(mask)


class EntityIndexing:
    """Mixin of an entity with ``scene`` and ``name``: its checked indices and result shapes."""

    @property
    def _who(self):
        """Who error messages name."""
        return f"entity '{self.name}'"

    def _sim(self):
        return self.scene._require_built(self._who)

    def _local(self, idx, n, arg, distinct=False):
        """Indices (list/array/tensor/int/slice/None; local ones or envs) → validated int64 numpy
        array, as Genesis's: an index in [−n, 0) counts from the end, a boolean mask of shape (n,)
        selects. distinct (a setter's indices): an index given twice is refused, since which of its
        values would land is undefined (torch's index_put, like Genesis's parallel kernels, picks
        either)."""
        if idx is None:
            return np.arange(n)
        if isinstance(idx, slice):  # as Genesis takes them (its go2 example: slice(6, 18))
            if idx.step == 0:
                raise InvalidInputError(f"{self._who}: argument '{arg}' as a slice must have a non-zero step, "
                                        f"got {idx!r}")
            return np.arange(n)[idx]
        if isinstance(idx, torch.Tensor) and (idx.layout != torch.strided or idx.is_meta):
            raise InvalidInputError(f"{self._who}: argument '{arg}' must be a dense tensor with values, got a "
                                    f"{idx.layout} tensor on {idx.device}")
        arr = np.atleast_1d(idx.detach().cpu().numpy() if isinstance(idx, torch.Tensor) else np.asarray(idx))
        if arr.size == 0:  # no index (a list of none reads as floats): nothing selected, as in Genesis
            return np.zeros(0, dtype=np.int64)
        if arr.dtype == np.bool_ and arr.shape == (n,):
            arr = np.flatnonzero(arr)
        if arr.dtype.kind not in "iu" or arr.ndim != 1 or (arr.size and (arr.min() < -n or arr.max() >= n)):
            raise InvalidInputError(f"{self._who}: argument '{arg}' must be integers in [{-n}, {n}) or a boolean "
                                    f"mask of {n}, got {idx!r}")
        arr = np.where(arr < 0, arr + n, arr)
        if distinct and len(set(arr.tolist())) != arr.size:  # a set: ~10× cheaper than np.unique when short
            values, counts = np.unique(arr, return_counts=True)
            raise InvalidInputError(f"{self._who}: argument '{arg}' must not repeat an index in a write, "
                                    f"got {values[counts > 1].tolist()} more than once in {idx!r}")
        return arr.astype(np.int64)

    def _envs(self, envs_idx, distinct=False):
        n_envs = self.scene.n_envs
        if n_envs == 0:
            if envs_idx is not None:
                raise InvalidInputError(f"{self._who}: argument 'envs_idx' must be None in a scene built "
                                        f"with n_envs=0, got {envs_idx!r}")
            return np.zeros(1, dtype=np.int64)
        envs = envs_mask_to_idx(envs_idx, n_envs, self._who)
        return self._local(envs, n_envs, "envs_idx", distinct)

    def _out(self, value):
        """Solver rows → user shape: drop the batch axis when the scene is not batched."""
        if self.scene.n_envs == 0:
            value = value[0]
        return wrap(value, self.scene)

    def _tensor(self, value, arg, expected):
        """User values (list, numpy, torch) → a float tensor on gs.device in gs.tc_float, kept in
        the autograd graph; refused when it requires grad in a scene without gradients, or holds
        complex numbers or non-numbers (``expected``: the shape the message states)."""
        self._sim().check_grad_allowed(value, self.name, arg)
        if isinstance(value, torch.Tensor):
            kind = "complex" if value.is_complex() else "bool" if value.dtype == torch.bool else \
                f"a {value.layout} tensor" if value.layout != torch.strided else None
        else:
            try:  # (None, a string or a bool would become NaN, a number or 1.0 in a float conversion)
                array = np.asarray(value)
            except (ValueError, TypeError, RuntimeError) as err:  # ragged; tensors numpy cannot take
                raise InvalidInputError(f"{self._who}: argument '{arg}' must be numbers of shape {expected}, "
                                        f"got {type(value).__name__} ({err})") from None
            kind = None if array.dtype.kind in "iuf" else {"c": "complex", "b": "bool", "U": "strings", "S": "bytes"}.get(
                array.dtype.kind, type(value).__name__ if array.ndim == 0 else "objects that are not numbers")
        if kind is not None:
            raise InvalidInputError(f"{self._who}: argument '{arg}' must be real numbers of shape {expected}, "
                                    f"got {kind}")
        if isinstance(value, torch.Tensor):
            if value.is_meta:
                raise InvalidInputError(f"{self._who}: argument '{arg}' must hold values (a tensor on {runtime.device} "
                                        f"or another device with data), got a tensor on the meta device")
            if type(value) is not torch.Tensor:  # (gs tensors and other subclasses)
                value = value.as_subclass(torch.Tensor)
            return value.to(device=runtime.device, dtype=runtime.tc_float)
        return torch.as_tensor(array.astype(np.float64), dtype=runtime.tc_float, device=runtime.device)

    def _values(self, value, n_cols, envs, arg, infinite=False):
        """User values → (len(envs), n_cols) float tensor on gs.device; checked shape and finiteness
        (``infinite``: ±inf allowed, for bounds). Broadcast as Genesis broadcasts (``broadcast``):
        in a batched scene (n_cols,) values apply to every env of envs, a scalar to every entry."""
        expected = (n_cols,) if self.scene.n_envs == 0 else (len(envs), n_cols)
        given = self._tensor(value, arg, expected)
        tensor = broadcast(given, expected)
        if tensor is None:
            every_env = f" or {(n_cols,)} for every env" if self.scene.n_envs else ""
            raise InvalidInputError(f"{self._who}: argument '{arg}' must have shape {expected}{every_env} (or one "
                                    f"that broadcasts to it), got {tuple(given.shape)}")
        if bool(torch.isnan(tensor.detach()).any()) if infinite else not all_finite(tensor.detach()):
            what = "free of NaN" if infinite else "finite"
            raise InvalidInputError(f"{self._who}: argument '{arg}' must be {what}, got "
                                    f"{tensor.detach().cpu().numpy()}")
        return tensor if tensor.dim() == 2 else tensor.reshape(len(envs), n_cols)


def named_argument_errors(cls):
    """Class decorator: a public method (or the constructor) called with arguments its signature
    does not take raises InvalidInputError naming the owner, the method and the arguments it takes,
    where Python's TypeError named neither (a Genesis argument genesis_lite does not have yet, such
    as ``skip_forward`` or ``relative``, docs/genesis_api.md). A call that binds pays one frame: the
    signature is checked only after a TypeError, and one raised inside the method passes on."""
    for name, member in list(vars(cls).items()):
        if inspect.isfunction(member) and (name == "__init__" or not name.startswith("_")):
            setattr(cls, name, _checked_arguments(member))
    return cls


def _checked_arguments(method):
    signature = inspect.signature(method)

    @functools.wraps(method)
    def call(self, *args, **kwargs):
        try:
            return method(self, *args, **kwargs)
        except TypeError:
            try:
                signature.bind(self, *args, **kwargs)
            except TypeError as error:
                who = getattr(self, "_who", None) or f"gs.{type(self).__name__}"
                where = who if method.__name__ == "__init__" else f"{who}: {method.__name__}"
                raise InvalidInputError(f"{where}: {error}; it takes {list(signature.parameters)[1:]} (Genesis's "
                                        f"arguments not offered yet are listed in docs/genesis_api.md)") from None
            raise
    return call
