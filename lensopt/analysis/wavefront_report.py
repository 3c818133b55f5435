"""Plain-data wavefront and Seidel reports (what ``lensopt trace --wavefront --json`` and ``--seidel --json``
print). The numbers come from ``analysis.strehl``, ``analysis.wavefront``, ``analysis.zernike`` and
``analysis.seidel`` unchanged; this module only samples once and lays them out.

Units: waves of each wavelength for wavefront numbers, nm for wavelengths, degrees for field angles.
"""

from __future__ import annotations

import math
from typing import Any

import torch

from lensopt.analysis.checks import fields_of, positive_int
from lensopt.analysis.report import LensModel
from lensopt.analysis.seidel import seidel_sums
from lensopt.analysis.strehl import strehl
from lensopt.analysis.wavefront import wavefront_stats
from lensopt.analysis.zernike import ORDERINGS, fit_zernike, zernike_indices
from lensopt.errors import LensoptError

__all__ = ["wavefront_report", "seidel_report", "ZERNIKE_NAMES", "CONVENTION"]

CONVENTION = ("W = OPL(chief) - OPL(ray) in waves of each wavelength, referenced to the sphere centred on the real "
              "chief ray's image point through its exit-pupil point (CODE V's); positive ahead of the sphere. "
              "rms/pv: piston and tilt removed; rms_chief/pv_chief: piston only.")

#: Short names of the low-order terms by (n, m) (m < 0: the sine term), for tables and figures.
ZERNIKE_NAMES = {(0, 0): "piston", (1, 1): "tilt x", (1, -1): "tilt y", (2, 0): "defocus", (2, 2): "astig 0°",
                 (2, -2): "astig 45°", (3, 1): "coma x", (3, -1): "coma y", (4, 0): "spherical",
                 (3, 3): "trefoil x", (3, -3): "trefoil y"}


def _nm(wavelength_um: float) -> float:
    return round(wavelength_um * 1e3, 9)


def _num(v: float) -> float | None:
    return v if math.isfinite(v) else None


def wavefront_report(model: LensModel, *, rel_field: list[float] | None = None, ordering: str = "fringe",
                     terms: int = 37, pupil_grid: int = 64) -> dict[str, Any]:
    """RMS and P-V wavefront error, Strehl ratio (PSF peak and Maréchal) and a Zernike fit per field and
    wavelength, from one ``pupil_grid`` × ``pupil_grid`` equal-area pupil sampling.

    Keys: ``convention``, ``pupil_grid``, ``wavelengths_nm``, ``reference_nm``, ``zernike`` (ordering,
    normalization, term numbers, their (n, m)), and ``fields``: one entry per field (``relative``,
    ``angle_deg``, ``wavelengths``: per wavelength ``wavelength_nm``, ``rms_waves``, ``pv_waves``,
    ``rms_chief_waves``, ``pv_chief_waves``, ``strehl_psf``, ``strehl_marechal``, ``zernike_waves`` (the
    coefficients in the order of ``zernike.numbers``), ``zernike_residual_rms_waves``, ``rays`` (valid
    samples)). Quantities of a field and wavelength whose rays all failed are None.
    """
    if ordering not in ORDERINGS:
        raise LensoptError(f"must be one of {', '.join(ORDERINGS)}", path="--zernike", got=ordering)
    positive_int(pupil_grid, path="--pupil-grid", minimum=4)
    lens, system = model.lens, model.system
    indices = zernike_indices(ordering, terms)
    rel = fields_of(lens, system, rel_field, path="--field")
    with torch.no_grad():
        s = strehl(lens, system, rel_field=rel, pupil_samples=pupil_grid)
        wf = s.wavefront
        st = wavefront_stats(wf)
        z = fit_zernike(wf.pupil, wf.opd, wf.valid, ordering=ordering, terms=terms)
    fields = []
    for f in range(wf.opd.shape[0]):
        per_w = []
        for w in range(wf.opd.shape[1]):
            n = int(st.count[f, w])
            ok = n > 0

            def val(t: torch.Tensor, ok: bool = ok) -> float | None:
                return _num(float(t)) if ok else None

            per_w.append({
                "wavelength_nm": _nm(float(wf.wavelength_um[w])),
                "rms_waves": val(st.rms[f, w]), "pv_waves": val(st.pv[f, w]),
                "rms_chief_waves": val(st.rms_chief[f, w]), "pv_chief_waves": val(st.pv_chief[f, w]),
                "strehl_psf": val(s.psf[f, w]), "strehl_marechal": val(s.marechal[f, w]),
                "zernike_waves": [_num(float(c)) for c in z.coefficients[f, w]] if ok else None,
                "zernike_residual_rms_waves": val(z.residual_rms[f, w]),
                "rays": n,
            })
        fields.append({"relative": float(wf.rel_field[f]), "angle_deg": float(wf.field_deg[f]), "wavelengths": per_w})
    return {
        "convention": CONVENTION,
        "pupil_grid": pupil_grid,
        "wavelengths_nm": [_nm(float(w)) for w in lens.wavelength_um],
        "reference_nm": _nm(float(lens.wavelength_um[system.reference])),
        "zernike": {"ordering": ordering,
                    "normalization": "none (edge amplitude)" if ordering == "fringe" else "rms (coefficient = RMS)",
                    "numbers": list(z.numbers), "nm": [list(i) for i in indices]},
        "fields": fields,
    }


def seidel_report(model: LensModel) -> dict[str, Any]:
    """``SeidelSums.as_dict`` of the lens (see ``analysis.seidel``): per surface and total sums in mm, the
    wavefront coefficients in waves of the reference wavelength, and the transverse aberrations."""
    with torch.no_grad():
        return seidel_sums(model.lens, model.system).as_dict()
