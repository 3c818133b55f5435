"""MTF against field at chosen frequencies, and MTF through focus (``analysis.mtf`` computes each MTF).

**MTF vs field**: the sagittal and tangential MTF (polychromatic, spectral weights) at a few spatial
frequencies, over a dense set of relative fields 0 … 1.

**Through focus**: the same at a few fields while the image surface moves along the axis by
``focus_mm`` (positive: away from the lens); the last gap (image distance) changes, nothing else.
The frequency of the curves is one or a few chosen ones; the best focus of each curve is reported.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import torch
from torch import Tensor

from lensopt.analysis.checks import fields_of
from lensopt.analysis.checks import frequencies as check_frequencies
from lensopt.analysis.mtf import MTF_METHODS, lens_mtf
from lensopt.engine import Engine
from lensopt.errors import LensoptError
from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import field_tangents

__all__ = ["MtfField", "mtf_vs_field", "ThroughFocus", "through_focus_mtf", "defocused"]


@dataclass(frozen=True)
class MtfField:
    """MTF at K frequencies over F fields.

    Attributes:
        frequency: (K,) cycles/mm.
        rel_field: (F,); field_deg: (F,) object-space field angles.
        sagittal, tangential: (F, K).
        method: the ``analysis.mtf`` method; cutoff: incoherent cutoff, cycles/mm.
    """

    frequency: Tensor
    rel_field: Tensor
    field_deg: Tensor
    sagittal: Tensor
    tangential: Tensor
    method: str
    cutoff: float


def _method(method: str) -> str:
    if method not in MTF_METHODS:
        raise LensoptError(f"must be one of {', '.join(MTF_METHODS)}", path="mtf.method", got=method)
    return method


@torch.no_grad()
def mtf_vs_field(lens: Lens, system: System, frequency: Tensor | list[float], *, fields: int | Tensor = 11,
                 method: str = "heuristic", sampling: str = "rings:32", engine: Engine | None = None) -> MtfField:
    """Sagittal/tangential MTF at ``frequency`` (cycles/mm, each > 0) over ``fields`` relative fields
    (a count spread over 0 … 1, or the (F,) fields themselves)."""
    nu = check_frequencies(frequency, path="frequency", dtype=lens.dtype, device=lens.device)
    rel = (torch.linspace(0.0, 1.0, int(fields), dtype=lens.dtype, device=lens.device)
           if isinstance(fields, int) else fields_of(lens, system, fields))
    res = lens_mtf(lens, system, nu, rel_field=rel, method=_method(method), sampling=sampling, engine=engine)
    deg = torch.rad2deg(torch.atan(field_tangents(lens, system, rel)))
    return MtfField(frequency=nu, rel_field=rel, field_deg=deg, sagittal=res.sagittal, tangential=res.tangential,
                    method=method, cutoff=res.cutoff)


def defocused(lens: Lens, shift_mm: float | Tensor) -> Lens:
    """``lens`` with its image surface moved by ``shift_mm`` along the axis (the last gap changes)."""
    step = torch.zeros_like(lens.thickness)
    step[-1] = 1.0
    return dataclasses.replace(lens, thickness=lens.thickness + step * shift_mm)


@dataclass(frozen=True)
class ThroughFocus:
    """MTF against focus position.

    Attributes:
        focus_mm: (Z,) image-surface shifts.
        frequency: (K,); rel_field: (F,); field_deg: (F,).
        sagittal, tangential: (Z, F, K).
        best_focus_mm: (F, K, 2) focus of the sagittal and tangential maxima (on the sampled shifts).
        method: the ``analysis.mtf`` method.
    """

    focus_mm: Tensor
    frequency: Tensor
    rel_field: Tensor
    field_deg: Tensor
    sagittal: Tensor
    tangential: Tensor
    best_focus_mm: Tensor
    method: str


@torch.no_grad()
def through_focus_mtf(lens: Lens, system: System, frequency: Tensor | list[float], *, focus_mm: Tensor,
                      rel_field: Tensor | None = None, method: str = "heuristic",
                      sampling: str = "rings:32", engine: Engine | None = None) -> ThroughFocus:
    """MTF at ``frequency`` at every image shift ``focus_mm`` ((Z,) mm) for ``rel_field`` (default: the
    system's fields)."""
    nu = check_frequencies(frequency, path="frequency", dtype=lens.dtype, device=lens.device)
    rel_field = fields_of(lens, system, rel_field)
    focus = focus_mm.to(lens.dtype)
    if focus.dim() != 1 or focus.shape[0] < 1:
        raise LensoptError("needs a list of focus shifts", path="focus", got=focus.tolist())
    sag, tan = [], []
    for dz in focus:
        r = lens_mtf(defocused(lens, dz), system, nu, rel_field=rel_field, method=_method(method), sampling=sampling,
                     engine=engine)
        sag.append(r.sagittal)
        tan.append(r.tangential)
    s, t = torch.stack(sag), torch.stack(tan)
    best = torch.stack([focus[s.argmax(0)], focus[t.argmax(0)]], -1)
    deg = torch.rad2deg(torch.atan(field_tangents(lens, system, rel_field)))
    return ThroughFocus(focus_mm=focus, frequency=nu, rel_field=rel_field, field_deg=deg, sagittal=s,
                        tangential=t, best_focus_mm=best, method=method)
