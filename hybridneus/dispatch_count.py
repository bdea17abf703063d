"""Counting what a piece of PyTorch code dispatches: operations, kernels, device read-backs.

On a GPU a pure-PyTorch training step is bound by kernel launches, and every read-back
(``.item()``, ``float(tensor)``, ``bool(tensor)``, boolean-mask indexing, data-dependent
shapes) stops the host until the device has caught up. Both show on any device, so they
can be counted, and tested, on a CPU.
"""

from __future__ import annotations

import torch
from torch.utils._python_dispatch import TorchDispatchMode

#: Operations that hand a value to the host, or whose output size depends on the data.
READ_BACKS = frozenset({
    "aten::_local_scalar_dense", "aten::nonzero", "aten::is_nonzero", "aten::masked_select",
    "aten::unique", "aten::_unique2", "aten::equal",
})


def _bool_mask(args) -> bool:
    return any(isinstance(a, (list, tuple)) and any(
        isinstance(t, torch.Tensor) and t.dtype == torch.bool for t in a) for a in args)


class DispatchCount(TorchDispatchMode):
    """``with DispatchCount() as c: ...`` counts what the block dispatches.

    Attributes:
        ops: operations dispatched.
        kernels: those that are not views (each at least one kernel launch on a GPU).
        reads: names (``aten::...``, overload dropped) of the read-backs, in order; indexing
            with a boolean mask counts as one.
    """

    def __init__(self) -> None:
        super().__init__()
        self.ops = self.kernels = 0
        self.reads: list[str] = []

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        self.ops += 1
        self.kernels += not func.is_view
        name = func.name().split(".")[0]
        if name in READ_BACKS or (name.startswith("aten::index") and _bool_mask(args)):
            self.reads.append(name)
        return func(*args, **(kwargs or {}))
