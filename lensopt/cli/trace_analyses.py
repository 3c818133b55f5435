"""The tables of ``lensopt trace --wavefront`` and ``--seidel`` (CLI layer: render the plain data of
``analysis.wavefront_report``; no physics). Each table fits 80 columns: one row per field (per field and
wavelength with ``--wide``), the surfaces as rows of the Seidel tables."""

from __future__ import annotations

from typing import Any

from rich import box
from rich.table import Table

from lensopt.cli.common import console

__all__ = ["render_wavefront", "render_seidel", "compact_table"]

# The primary aberrations' Zernike terms, by (n, m): their numbers follow the ordering.
PRIMARY = ((2, 0, "defocus"), (2, 2, "astig 0°"), (2, -2, "astig 45°"), (3, 1, "coma x"), (3, -1, "coma y"),
           (4, 0, "spher."))
SEIDEL_HEADERS = (("S_I", "spher."), ("S_II", "coma"), ("S_III", "astig."), ("S_IV", "Petzval"),
                  ("S_V", "distort."), ("C_I", "ax.col."), ("C_II", "lat.col."))


def compact_table(title: str) -> Table:
    """A table without vertical rules (columns two spaces apart), so that eight numeric columns fit 80."""
    return Table(title=title, title_justify="left", box=box.SIMPLE_HEAD, pad_edge=False, padding=(0, 1, 0, 0),
                 show_edge=False)


def _f(v: float | None, fmt: str) -> str:
    """``v`` formatted; None as a dash; a value that rounds to zero without a sign (symmetry zeros)."""
    if v is None:
        return "—"
    text = format(v, fmt)
    return text.lstrip("+-") if float(text) == 0.0 else text


def _rows(wf: dict[str, Any], wide: bool) -> list[tuple[dict[str, Any], dict[str, Any]]]:
    """(field, wavelength entry) pairs to show: every wavelength with ``wide``, else the reference."""
    ref = wf["wavelengths_nm"].index(wf["reference_nm"])
    return [(f, w) for f in wf["fields"] for i, w in enumerate(f["wavelengths"]) if wide or i == ref]


def render_wavefront(wf: dict[str, Any], *, wide: bool = False) -> None:
    """The wavefront table (RMS, P-V, Strehl) and the primary Zernike terms, per field."""
    where = "every wavelength" if wide else f"{wf['reference_nm']:g} nm (reference)"
    n = wf["pupil_grid"]
    t = compact_table(f"wavefront error (waves), {where}, pupil {n}×{n}")
    for col in ("field", "°", *(("λ nm",) if wide else ()), "RMS", "P-V", "RMS chief", "Strehl PSF", "Maréchal"):
        t.add_column(col, justify="right")
    rows = _rows(wf, wide)
    for f, w in rows:
        lam = (f"{w['wavelength_nm']:g}",) if wide else ()
        t.add_row(f"{f['relative']:.3f}", f"{f['angle_deg']:.3f}", *lam, _f(w["rms_waves"], ".4f"),
                  _f(w["pv_waves"], ".4f"), _f(w["rms_chief_waves"], ".4f"), _f(w["strehl_psf"], ".4f"),
                  _f(w["strehl_marechal"], ".4f"))
    console.print(t)
    z = wf["zernike"]
    nm = [tuple(x) for x in z["nm"]]
    cols = [(nm.index((n_, m_)), label) for n_, m_, label in PRIMARY if (n_, m_) in nm]
    norm = "edge amplitude" if z["ordering"] == "fringe" else "RMS-normalized"
    zt = compact_table(f"{z['ordering']} Zernike terms (waves, {norm}; all {len(nm)} in --json)")
    zt.add_column("field", justify="right")
    if wide:
        zt.add_column("λ nm", justify="right")
    for j, label in cols:
        zt.add_column(f"Z{z['numbers'][j]}\n{label}", justify="right")
    zt.add_column("resid.\nRMS", justify="right")
    for f, w in rows:
        c = w["zernike_waves"]
        lam = (f"{w['wavelength_nm']:g}",) if wide else ()
        zt.add_row(f"{f['relative']:.3f}", *lam, *[_f(None if c is None else c[j], "+.4f") for j, _ in cols],
                   _f(w["zernike_residual_rms_waves"], ".4f"))
    console.print(zt)
    console.print("RMS, P-V: piston and tilt removed (Maréchal's RMS); RMS chief: piston only.\n"
                  "W = OPL(chief) − OPL(ray), to the real chief ray's reference sphere (CODE V's)."
                  + ("" if wide else "\n--wide: every wavelength; --json: all numbers."), highlight=False)


def render_seidel(sd: dict[str, Any]) -> None:
    """Per-surface and total Seidel sums (mm) and wavefront coefficients (waves)."""
    short, long_ = sd["color_wavelengths_nm"]
    for key, total, names, unit, fmt in (
            ("surfaces_mm", "total_mm", [h[0] for h in SEIDEL_HEADERS], "mm", ".6f"),
            ("surfaces_waves", "total_waves", ["W040", "W131", "W222", "W220P", "W311", "W020", "W111"],
             f"waves at {sd['wavelength_nm']:g} nm", ".4f")):
        title = (f"Seidel sums ({unit}; colour {short:g}–{long_:g} nm)" if unit == "mm"
                 else f"wavefront coefficients ({unit})")
        t = compact_table(title)
        t.add_column("", justify="right")
        for name, (_, label) in zip(names, SEIDEL_HEADERS, strict=True):
            t.add_column(f"{name}\n{label}", justify="right")
        for i, row in enumerate(sd[key], start=1):
            t.add_row(f"S{i}", *[_f(row[k], fmt) for k in names])
        t.add_section()
        t.add_row("sum", *[_f(sd[total][k], fmt) for k in names], style="bold")
        console.print(t)
    tr = sd["total_transverse_mm"]
    items = [f"{k} {_f(v, '.6f')}" for k, v in tr.items()]
    console.print("transverse aberrations (mm): " + ", ".join(items[:3]) + ",\n  " + ", ".join(items[3:])
                  + f"\nLagrange invariant H = {sd['lagrange_invariant_mm']:.6f} mm", highlight=False)
