"""Generalized transverse ray aberrations (GTRA, S3.1, eqs. S66–S68): a scalar loss of the spot
diagrams turned into per-ray least-squares residuals, so that Levenberg–Marquardt can minimise an
image loss.

From the current spot diagrams ε₀, the scalar loss L = L(ε₀) and its gradient g = ∇_ε L(ε₀) (reverse
mode through rendering and loss only):

    w  = ‖g‖² / (2L),        ε′ = ε₀ − 2L g / ‖g‖²,        ℓ_GTRA(θ) = √w (ε(θ) − ε′).

At θ₀, ½‖ℓ_GTRA‖² = L and Jᵀℓ_GTRA = (∂ε/∂θ)ᵀ g = ∇_θ L (S66). The Jacobian of ℓ_GTRA needs forward
mode over the ray trace only, since ε′ and w are constants of the step.

Bounding control values (S3.1): ε′ is clipped to each field's PSF window (control values outside it
would ask for rays the PSF array cannot hold); w is then rescaled so that ½‖√w (ε₀ − ε′)‖² = L still
holds. Failed rays (at ε₀ or at θ) carry no residual.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import Tensor

__all__ = ["GtraTarget", "gtra_target", "gtra_residual", "psf_window"]


@dataclass(frozen=True)
class GtraTarget:
    """ε′ and w of one step.

    Attributes:
        control: (F, W, P, 2) control values ε′, mm (ε₀ where a ray failed).
        weight: () w (after the rescaling for clipped control values).
        valid: (F, W, P) rays that reached the image at ε₀.
        loss: () L(ε₀).
        grad: (F, W, P, 2) ∇_ε L(ε₀).
        clipped: number of control coordinates that were clipped.
    """

    control: Tensor
    weight: Tensor
    valid: Tensor
    loss: Tensor
    grad: Tensor
    clipped: int


def psf_window(center: Tensor, size: int, pitch_mm: float) -> tuple[Tensor, Tensor]:
    """(F, 1, 1, 2) lower and upper corners of each field's PSF array (outermost bin centres), mm,
    around the grid centres ``center`` (F, 2)."""
    half = (size - 1) / 2 * pitch_mm
    c = center.detach()[:, None, None, :]
    return c - half, c + half


def gtra_target(eps0: Tensor, valid: Tensor, loss_fn: Callable[[Tensor], Tensor], *,
                window: tuple[Tensor, Tensor] | None = None) -> GtraTarget:
    """Control values and weight of GTRA (S66–S68) from the spot diagrams ε₀.

    Args:
        eps0: (F, W, P, 2) spot diagrams at the current lens (detached here).
        valid: (F, W, P) rays that reached the image.
        loss_fn: ε ↦ scalar loss L(ε) (rendering + image loss); differentiated once in reverse mode.
        window: (lower, upper) bounds broadcastable to ``eps0`` (``psf_window``): clip ε′ to them.
    """
    e = eps0.detach().clone().requires_grad_(True)
    with torch.enable_grad():
        loss = loss_fn(e)
        (grad,) = torch.autograd.grad(loss, e)
    loss = loss.detach().to(eps0.dtype)
    grad = torch.where(valid.unsqueeze(-1), torch.nan_to_num(grad.to(eps0.dtype)), 0.0)
    g2 = (grad**2).sum()
    e0 = eps0.detach()
    if not bool(g2 > 0) or not bool(loss > 0):
        zero = torch.zeros((), dtype=eps0.dtype, device=eps0.device)
        return GtraTarget(e0.clone(), zero, valid, loss, grad, 0)
    control = e0 - 2.0 * loss * grad / g2
    weight = g2 / (2.0 * loss)
    clipped = 0
    if window is not None:
        lo, hi = window
        bounded = torch.maximum(torch.minimum(control, hi.to(control.dtype)), lo.to(control.dtype))
        bounded = torch.where(valid.unsqueeze(-1), bounded, e0)
        clipped = int((bounded != control).logical_and(valid.unsqueeze(-1)).sum())
        if clipped:
            # Rescale so that ½ w ‖ε₀ − ε′‖² = L is kept (S3.1, "Bounding control values").
            d2 = ((e0 - bounded) ** 2).sum()
            weight = 2.0 * loss / d2 if bool(d2 > 0) else torch.zeros_like(weight)
        control = bounded
    control = torch.where(valid.unsqueeze(-1), control, e0)
    return GtraTarget(control, weight, valid, loss, grad, clipped)


def gtra_residual(eps: Tensor, valid: Tensor, target: GtraTarget) -> Tensor:
    """(2·F·W·P,) ℓ_GTRA = √w (ε − ε′) (S68); 0 for rays failed at ε₀ or now (fixed length).

    Args:
        eps: (F, W, P, 2) spot diagrams at θ (differentiable); valid: (F, W, P) rays reaching the image.
    """
    ok = (valid & target.valid).unsqueeze(-1)
    d = torch.where(ok, eps - target.control.to(eps.dtype), 0.0)
    return (torch.sqrt(target.weight).to(eps.dtype) * d).reshape(-1)
