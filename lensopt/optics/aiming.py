"""Ray aiming (S1.3.2). Mode ``chief``: shift each (field, wavelength) bundle on the entrance pupil so
that its chief ray passes through the centre of the real aperture stop, by Newton's method on the
real ray with the derivative from forward-mode autodiff.

The shift is a relative pupil offset δ (in units of EPD/2) added to every pupil y coordinate. Newton
runs on detached values; one final step on the attached lens makes δ exactly differentiable in the
lens parameters at convergence (implicit function theorem), as for the asphere intersection.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from lensopt.optics.lens import Lens, System
from lensopt.optics.sampling import launch
from lensopt.optics.trace import trace

__all__ = ["ChiefAim", "aim_chief"]


@dataclass(frozen=True)
class ChiefAim:
    """Result of chief-ray aiming.

    Attributes:
        offset: (F, W) relative pupil y offsets δ.
        residual_mm: (F, W) chief-ray height on the stop after aiming, mm.
        converged: (F, W) bool, residual below tolerance and the chief ray traced.
        iterations: Newton iterations used.
    """

    offset: Tensor
    residual_mm: Tensor
    converged: Tensor
    iterations: int


def aim_chief(
    lens: Lens,
    system: System,
    tan_field: Tensor,
    *,
    epd: Tensor,
    entrance_pupil_z: Tensor,
    iterations: int = 8,
    tol_mm: float | None = None,
) -> ChiefAim:
    """Pupil offsets that put the real chief ray of every field and wavelength on the stop centre.

    Args:
        tan_field: (F,) object-space chief-ray slopes.
        epd, entrance_pupil_z: paraxial entrance pupil diameter and position, mm.
        iterations: Newton iterations (fixed count; the residual is reported).
        tol_mm: convergence tolerance on the stop, default 1e3·eps·(1 + EPD).
    """
    num_f, num_w = tan_field.shape[0], lens.wavelength_um.shape[0]

    def stop_y(delta: Tensor, lens_: Lens, tan_: Tensor, epd_: Tensor, ep_z: Tensor) -> tuple[Tensor, Tensor]:
        pupil = torch.stack([torch.zeros_like(delta), delta], -1).unsqueeze(-2)  # (F, W, 1, 2)
        rays = launch(lens_, system, pupil, tan_, epd=epd_, entrance_pupil_z=ep_z)
        hit = trace(lens_, rays, upto=lens_.stop)
        return hit.pos[..., 0, 1], hit.valid[..., 0]

    detached = _detach_lens(lens)
    args = (detached, tan_field.detach(), epd.detach(), entrance_pupil_z.detach())
    delta = torch.zeros(num_f, num_w, dtype=lens.dtype, device=lens.device)
    ones = torch.ones_like(delta)

    def newton_terms(d: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        y, slope = torch.func.jvp(lambda v: stop_y(v, *args)[0], (d,), (ones,))
        ok = slope.abs() > 1e-12
        return y, torch.where(ok, slope, torch.ones_like(slope)), ok

    for _ in range(iterations - 1):
        y, slope, ok = newton_terms(delta)
        delta = torch.where(ok, delta - y / slope, delta)
    # Final step on the attached lens: exact first derivatives of δ at convergence.
    y_det, slope, ok = newton_terms(delta)
    y, valid = stop_y(delta, lens, tan_field, epd, entrance_pupil_z)
    offset = torch.where(ok, delta - y / slope, delta)
    tol = tol_mm if tol_mm is not None else 1e3 * torch.finfo(lens.dtype).eps * (1.0 + epd.detach())
    converged = valid & (y_det.abs() <= tol)
    return ChiefAim(offset=offset, residual_mm=y_det, converged=converged, iterations=iterations)


def _detach_lens(lens: Lens) -> Lens:
    """The same lens with every tensor detached (no gradient, no forward-mode tangent)."""
    names = ("curvature", "conic", "asphere", "phase", "thickness", "index", "wavelength_um", "semi_diameter")
    return Lens(shapes=lens.shapes, stop=lens.stop, **{n: getattr(lens, n).detach() for n in names})
