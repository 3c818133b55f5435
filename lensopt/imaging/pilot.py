"""A cheap pilot trace that tells a scene plan how the lens behaves across the field: real image
heights (field map), blur size and asymmetry, lateral colour, distortion and relative illumination."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from lensopt.analysis.distortion import paraxial_heights
from lensopt.analysis.illumination import relative_illumination_std
from lensopt.analysis.spot import spot_stats
from lensopt.engine import Engine
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import first_order
from lensopt.optics.sampling import pupil_rings

__all__ = ["Pilot", "run_pilot"]


@dataclass(frozen=True)
class Pilot:
    """Per pilot field (arrays of length M, mm unless said): relative field ``u``, field angle,
    centroid height ``height`` (real), paraxial height, polychromatic RMS radius ``rms``, RMS spreads
    ``sigma_x``/``sigma_y`` about the centroid, relative illumination ``ri`` (S52), ray failure fraction;
    and the paraxial working f-number."""

    u: np.ndarray
    field_deg: np.ndarray
    height: np.ndarray
    paraxial: np.ndarray
    rms: np.ndarray
    sigma_x: np.ndarray
    sigma_y: np.ndarray
    ri: np.ndarray
    failed: np.ndarray
    working_fnumber: float

    def u_of_radius(self, r: np.ndarray | float) -> np.ndarray:
        """Relative field whose centroid lands at radius ``r`` (clamped to [u_min, u_max] traced)."""
        h = np.maximum.accumulate(np.abs(self.height))  # monotone envelope for interpolation
        return np.interp(r, h, self.u)

    def at(self, name: str, u: np.ndarray | float) -> np.ndarray:
        """Linear interpolation of attribute ``name`` at relative fields ``u``."""
        return np.interp(u, self.u, getattr(self, name))


@torch.no_grad()
def run_pilot(lens: Lens, system: System, weights: torch.Tensor, *, fields: int = 33, rings: int = 8,
              engine: Engine | None = None) -> Pilot:
    """Trace ``rings`` pupil rings (half pupil, mirrored by symmetry) at ``fields`` relative fields in
    [0, 1] for the wavelengths of ``lens`` with spectral ``weights`` (W,)."""
    u = torch.linspace(0.0, 1.0, fields, dtype=lens.dtype, device=lens.device)
    pupil = pupil_rings(rings, jitter=False, dtype=lens.dtype, device=lens.device)
    fo = first_order(lens, system)
    b = trace_bundle(lens, system, pupil, half_pupil=True, rel_field=u, fo=fo, engine=engine)
    stats = spot_stats(b, weights)
    res = b.result
    valid = res.valid
    w = weights.to(lens.dtype)[None, :, None] * valid.to(lens.dtype)
    total = w.sum((1, 2)).clamp_min(torch.finfo(lens.dtype).tiny)
    dx = res.pos[..., 0]  # centroid x = 0 by symmetry
    dy = res.pos[..., 1] - stats.centroid[:, None, None, 1]
    sx = torch.sqrt((w * torch.where(valid, dx, 0.0) ** 2).sum((1, 2)) / total)
    sy = torch.sqrt((w * torch.where(valid, dy, 0.0) ** 2).sum((1, 2)) / total)
    ri = relative_illumination_std(b, weights)
    par = paraxial_heights(lens, system, b)
    failed = 1.0 - valid.to(lens.dtype).mean((1, 2))

    def np_(t: torch.Tensor) -> np.ndarray:
        return t.detach().cpu().double().numpy()

    return Pilot(u=np_(u), field_deg=np_(torch.rad2deg(torch.atan(b.tan_field))), height=np_(stats.centroid[:, 1]),
                 paraxial=np_(par), rms=np_(stats.rms_radius), sigma_x=np_(sx), sigma_y=np_(sy),
                 ri=np.nan_to_num(np_(ri), nan=0.0), failed=np_(failed), working_fnumber=float(fo.working_fnumber))
