"""What the core may do depending on the torch transforms watching it.

- Stop an iterative solve early: the fixed-count loops of the core (the asphere intersection, chief
  ray aiming) run to convergence and stop there when the values can be looked at (``all_settled``).
- Skip work that only derivatives need (``carries_derivatives``): e.g. an attached copy of a detached
  solve, which has the same values when nothing asks for derivatives.

Looking at values (``bool(mask.all())``) is allowed in eager code, under forward-mode AD on detached
values included (``torch.func.jacfwd``: the detached primal is a plain, unbatched tensor). It is not
allowed while a graph is captured (``torch.compile``, ``make_fx``: a branch on data would be baked
into the graph) nor on values that ``vmap`` batches (e.g. the tolerance trials); those keep the fixed
iteration count, so the same computation gives the same numbers either way up to rounding.
"""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["capturing", "vmapped", "all_settled", "carries_derivatives"]


def capturing() -> bool:
    """Whether a graph is being captured (Dynamo or make_fx): no branches on tensor values then."""
    from torch.fx.experimental.proxy_tensor import get_proxy_mode

    return torch.compiler.is_compiling() or get_proxy_mode() is not None


def vmapped(*tensors: Tensor) -> bool:
    """Whether any of ``tensors`` holds values batched by a ``vmap`` (e.g. the tolerance trials): their
    values may not be looked at, and ops without a batching rule run a slow per-sample loop."""
    from torch._C._functorch import is_batchedtensor

    return any(is_batchedtensor(t) for t in tensors)


def all_settled(done: Tensor) -> bool:
    """True when every entry of the bool mask ``done`` holds and the values may be looked at (see the
    module docstring); False otherwise, and the caller runs its fixed count."""
    if capturing() or vmapped(done):
        return False
    try:
        return bool(done.all())
    except RuntimeError:  # a value batched deeper inside a functorch wrapper (vmap of a jvp, ...)
        return False


def carries_derivatives(*tensors: Tensor) -> bool:
    """Whether any of ``tensors`` takes part in differentiation: reverse mode (``requires_grad`` with
    grad enabled), a functorch transform (``jacfwd``, ``vmap``, ``grad``) or forward-mode dual tensors.
    False means plain values: work whose only purpose is derivatives can be skipped."""
    from torch._C._functorch import is_functorch_wrapped_tensor
    from torch.autograd.forward_ad import unpack_dual

    grad = torch.is_grad_enabled()
    return any((grad and t.requires_grad) or is_functorch_wrapped_tensor(t) or unpack_dual(t).tangent is not None
               for t in tensors)
