"""``lensopt trace`` and ``lensopt ray`` (CLI layer: parse, call ``analysis.report``, render with rich)."""

from __future__ import annotations

import math
from typing import Annotated, Any

import typer
from rich.table import Table

from lensopt.cli.common import (
    AimOpt,
    AimStepsOpt,
    BackendOpt,
    JsonOpt,
    LensArg,
    SamplingOpt,
    SeedOpt,
    check_aim,
    check_aim_steps,
    console,
    handle_errors,
    load_model,
    make_engine,
    parse_frequencies,
    parse_sampling,
    print_json,
)
from lensopt.cli.tables import compact_table, matrix_tables, show
from lensopt.errors import LensoptError

__all__ = ["commands"]

commands = typer.Typer()  # its commands, put in order by lensopt.cli.app


@commands.command("trace", short_help="First-order data, spot sizes, failures, distortion, illumination.")
@handle_errors
def trace(lens: LensArg, sampling: SamplingOpt = "gauss:16", aim: AimOpt = None, seed: SeedOpt = 0,
          as_json: JsonOpt = False, aim_steps: AimStepsOpt = None,
          mtf: Annotated[str | None, typer.Option("--mtf", help="Also MTF at these cycles/mm (comma-separated; "
                                                  "in --json as mtf).")] = None,
          backend: BackendOpt = "auto",
          wavefront: Annotated[bool, typer.Option(
              "--wavefront", help="Also the wavefront per field and wavelength: RMS and P-V (waves), Strehl (PSF "
              "and Maréchal), Zernike terms (in --json as wavefront).")] = False,
          seidel: Annotated[bool, typer.Option(
              "--seidel", help="Also the Seidel sums per surface and in total, mm and waves (in --json as "
              "seidel).")] = False,
          zernike: Annotated[str, typer.Option("--zernike", help="Zernike ordering of --wavefront: fringe | noll | "
                                               "ansi.")] = "fringe",
          pupil_grid: Annotated[int, typer.Option("--pupil-grid", min=4, max=512, metavar="N",
                                                  help="Pupil grid N×N of --wavefront.")] = 64,
          wide: Annotated[bool, typer.Option("--wide", help="Tables at their full width: every wavelength a "
                                             "column of one spot table, --wavefront tables for every wavelength "
                                             "(default: fit the terminal, COLUMNS, or 80 columns in a pipe; the "
                                             "reference wavelength).")] = False) -> None:
    """First-order data, RMS spot radius per field and wavelength, ray failures, distortion and
    relative illumination per field."""
    from lensopt.analysis.report import mtf_report, trace_report
    from lensopt.analysis.zernike import ORDERINGS

    if zernike not in ORDERINGS:
        raise LensoptError(f"must be one of {', '.join(ORDERINGS)}", path="--zernike", got=zernike)
    engine = make_engine(backend)
    model = load_model(lens)
    report = trace_report(model, parse_sampling(sampling, seed),
                          aim=check_aim(aim), aim_steps=check_aim_steps(aim_steps), engine=engine)
    if mtf is not None:
        report["mtf"] = mtf_report(model, parse_frequencies(mtf, "--mtf"), engine=engine)
    if wavefront or seidel:
        from lensopt.analysis.wavefront_report import seidel_report, wavefront_report

        if wavefront:
            report["wavefront"] = wavefront_report(model, ordering=zernike, pupil_grid=pupil_grid)
        if seidel:
            report["seidel"] = seidel_report(model)
    if as_json:
        print_json(report)
        return
    _render_trace(report, wide=wide)
    _render_field(report, wide=wide)
    if wavefront or seidel:
        from lensopt.cli.trace_analyses import render_seidel, render_wavefront

        if wavefront:
            render_wavefront(report["wavefront"], wide=wide)
        if seidel:
            render_seidel(report["seidel"])


def _render_trace(r: dict[str, Any], *, wide: bool = False) -> None:
    """Prescription, first-order data, then the spot sizes: a per-field summary first, the per-wavelength
    detail after it as a matrix that fits the width (``--wide``: one table, every wavelength a column)."""
    ref = r["wavelengths_nm"].index(r["reference_nm"])
    console.print(f"[bold]{r['name']}[/]")
    _print(_prescription_table(r["surfaces"], ref, r["reference_nm"]), wide)
    _coefficient_tables(r["surfaces"], wide)
    fo = r["first_order"]
    t = compact_table(f"first-order data ({r['reference_nm']:g} nm)", [("quantity", "left"), ("value", "right"),
                                                                         ("unit", "left")])
    labels = {"efl": "EFL", "bfl": "BFL (last surface to focus)", "ffl": "FFL (front focus from surface 1)",
              "epd": "EPD", "entrance_pupil_z": "entrance pupil z (from surface 1)",
              "exit_pupil_z": "exit pupil z (from surface 1)", "exit_pupil_diameter": "exit pupil diameter",
              "fnumber": "f-number (EFL/EPD)", "working_fnumber": "working f-number",
              "paraxial_image_height": "paraxial image height", "total_track": "total track"}
    for key, label in labels.items():
        t.add_row(label, f"{fo[key]:.6f}", "" if "fnumber" in key else "mm")
    _print(t)
    wl = r["wavelengths_nm"]
    how = f"{r['sampling']}, aim {r['aim']}"
    if wide:
        s = compact_table(f"RMS spot radius (µm), {how}; RMS weighted over the spectrum",
                          [("field °", "right"), *((f"{w:g} nm", "right") for w in wl), ("weighted", "right"),
                           ("centroid y mm", "right"), ("chief y mm", "right"), ("failed rays", "right")])
        for f in r["fields"]:
            s.add_row(f"{f['angle_deg']:.3f}", *[_num(v) for v in f["rms_spot_radius_um"]],
                      _num(f["rms_spot_radius_weighted_um"]), _num(f["centroid_y_mm"], ".6f"),
                      _num(f["chief_ray_y_mm"], ".6f"), f"{f['failed_rays']}/{f['rays']}")
        _print(s, wide=True)
    else:
        s = compact_table(f"spot size per field ({how})",
                          [("field °", "right"), ("RMS radius\nµm", "right"), ("centroid y\nmm", "right"),
                           ("chief ray y\nmm", "right"), ("failed rays", "right")])
        for f in r["fields"]:
            s.add_row(f"{f['angle_deg']:.3f}", _num(f["rms_spot_radius_weighted_um"]), _num(f["centroid_y_mm"], ".6f"),
                      _num(f["chief_ray_y_mm"], ".6f"), f"{f['failed_rays']}/{f['rays']}")
        _print(s)
        _render_per_wavelength(r)
    esr = r["effective_spot_radius_um"]
    console.print(f"effective spot radius: [bold]{esr:.4f} µm[/]" if esr is not None else
                  "effective spot radius: — (no ray reaches the image at some field or wavelength: see the "
                  "failures below)")
    failures: dict[str, int] = {}
    for f in r["fields"]:
        for reason, n in f["failures"].items():
            failures[reason] = failures.get(reason, 0) + n
        if f["backtracking_rays"]:
            failures["backtracking (flagged, still traced)"] = (
                failures.get("backtracking (flagged, still traced)", 0) + f["backtracking_rays"])
    if failures:
        console.print("ray failures: " + ", ".join(f"{k}: {v}" for k, v in failures.items()))
    else:
        console.print("ray failures: none")


def _render_per_wavelength(r: dict[str, Any]) -> None:
    """RMS spot radius per field and wavelength, the longer of the two down the rows (12 wavelengths of 5
    fields: a wavelength per row), the columns folded into blocks that fit the width."""
    wl, fields = r["wavelengths_nm"], r["fields"]
    angles = [f"{f['angle_deg']:.3f}°" for f in fields]
    names = [f"{w:g} nm" for w in wl]
    values = [[_num(v) for v in f["rms_spot_radius_um"]] for f in fields]  # [field][wavelength]
    title = "RMS spot radius per wavelength, µm"
    if len(wl) >= len(fields):
        cells = [[values[h][w] for h in range(len(fields))] for w in range(len(wl))]
        tables = matrix_tables(title + ", fields across", "wavelength", names, angles, cells, width=console.width)
    else:
        tables = matrix_tables(title + ", wavelengths across", "field", angles, names, values, width=console.width)
    for t in tables:
        _print(t)


def _print(table: Table, wide: bool = False) -> None:
    show(console, table, wide=wide)


def _num(v: float | None, fmt: str = ".4f") -> str:
    return "—" if v is None else format(v, fmt)


def _render_field(r: dict[str, Any], *, wide: bool = False) -> None:
    """Distortion and relative illumination per field; the vignetting factors (and full aiming's stop
    misses) in a table of their own, shown when a factor is not 0 (``--wide``: all in one table)."""
    from lensopt.analysis.field import AIM_NOTE_FRACTION

    full = r["aim"] == "full"
    ref = f"{r['reference_nm']:g} nm"
    limit = 1e3 * AIM_NOTE_FRACTION * r["stop_radius_mm"] if full else 0.0
    main = [("field °", "right"), ("distortion\n%", "right"), ("rel. illum.\n3 rays", "right"),
            ("rel. illum.\nall rays", "right")]
    pupil = [("vignetting\ninferior (V_i)", "right"), ("vignetting\nsuperior (V_s)", "right"),
             ("vignetting\nlateral (V_l)", "right")] + ([("stop miss\nµm", "right")] if full else [])
    shown = any(any(f["vignetting"][k] for k in ("inferior", "superior", "lateral")) for f in r["fields"]) or full
    t = compact_table("distortion and relative illumination per field", main + (pupil if wide else []))
    p = compact_table(f"pupil per field (vignetting factors at {ref})", [("field °", "right"), *pupil])
    for f in r["fields"]:
        v = f["vignetting"]
        ri = f["relative_illumination"]
        row = [_num(f["distortion_percent"]), _num(ri["three_ray"]), _num(ri["std"])]
        prow = [f"{v['inferior']:.4f}", f"{v['superior']:.4f}", f"{v['lateral']:.4f}"]
        if full:
            miss = 1e3 * max(v["aim_residual_mm"].values())
            prow.append(f"{miss:.2e}" + ("" if v["aim_rays_traced"] and miss <= limit else " (!)"))
        t.add_row(f"{f['angle_deg']:.3f}", *row, *(prow if wide else []))
        p.add_row(f"{f['angle_deg']:.3f}", *prow)
    _print(t, wide)
    if not wide and shown:
        _print(p)
    elif not wide:
        console.print(f"vignetting factors: none (0 at every field, {ref})")
    if full:
        console.print(f"full aiming: {r['aim_steps']} Newton step(s) onto the stop, radius "
                      f"{r['stop_radius_mm']:.6f} mm")
    for note in r["notes"]:
        console.print(f"[yellow]note:[/] {note}", highlight=False)


def _prescription_table(surfaces: list[dict[str, Any]], ref: int, ref_nm: float) -> Table:
    """The resolved prescription as traced: one row per surface (the ``surfaces`` of ``trace --json``);
    conic, aspheric and diffractive surfaces are named in the notes, their coefficients listed by
    ``_coefficient_tables``."""
    cols = [("surf", "right"), ("type", "left"), ("radius", "right"), ("thickness", "right"), ("material", "left"),
            (f"n {ref_nm:g} nm", "right"), ("semi-\ndiam.", "right"), ("notes", "left")]
    t = compact_table("prescription (lengths in mm)", cols)
    for i, sf in enumerate(surfaces, start=1):
        radius = "inf" if math.isinf(sf["radius"]) else f"{sf['radius']:.6f}"
        notes = []
        if sf["stop"]:
            notes.append("stop")
        if sf["conic"] or sf["asphere"]:
            notes.append("asph" if sf["asphere"] else "conic")
        if "diffractive" in sf:
            notes.append("DOE")
        t.add_row(str(i), sf["type"], radius, f"{sf['thickness']:.6f}", sf["material"], f"{sf['index'][ref]:.6f}",
                  f"{sf['semi_diameter']:.4f}", ", ".join(notes))
    return t


def _coefficient_tables(surfaces: list[dict[str, Any]], wide: bool) -> None:
    """Conic constants k and aspheric coefficients a_2i (sag terms a_2i r^2i, mm), and diffractive phase
    coefficients d_2i, one row per surface that has them, folded to the width (``--wide``: one table each)."""
    for key, letter, what in (("asphere", "a", "conic constant k and aspheric coefficients (sag a_2i r^2i, mm)"),
                              ("diffractive", "d", "diffractive phase coefficients (d_2i r^2i, rad)")):
        rows = [(i, {p: v for p, v in (sf.get(key) or {}).items() if p.isdigit()})
                for i, sf in enumerate(surfaces, start=1)]
        rows = [(i, c) for i, c in rows if c or (key == "asphere" and surfaces[i - 1]["conic"])]
        if not rows:
            continue
        powers = sorted({int(p) for _, c in rows for p in c})
        names = [f"{letter}{p}" for p in powers]
        cells = [[f"{c[str(p)]:.6g}" if str(p) in c else "" for p in powers] for _, c in rows]
        if key == "asphere":
            names.insert(0, "k")
            for row, (i, _) in zip(cells, rows, strict=True):
                row.insert(0, f"{surfaces[i - 1]['conic']:.6g}")
        if key == "diffractive":  # the design wavelength and order of each DOE
            names += ["design nm", "order"]
            for row, (i, _) in zip(cells, rows, strict=True):
                d = surfaces[i - 1]["diffractive"]
                row += [f"{d['design_wavelength_nm']:g}", str(d["order"])]
        labels = [str(i) for i, _ in rows]
        for t in matrix_tables(what, "surf", labels, names, cells, width=10**6 if wide else console.width):
            _print(t, wide)


@commands.command("ray", short_help="One real ray, surface by surface (like CODE V's RSI).")
@handle_errors
def ray(
    lens: LensArg,
    field: Annotated[float, typer.Option("--field", help="Field angle in degrees.")] = 0.0,
    pupil: Annotated[tuple[float, float], typer.Option("--pupil", help="Relative pupil PX PY, within the unit "
                                                       "circle (1: the pupil edge).")] = (0.0, 1.0),
    wavelength: Annotated[float | None, typer.Option("--wavelength", help="nm (default: reference).")] = None,
    aim: AimOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """One real ray, surface by surface: position, direction cosines, angles (like CODE V's RSI)."""
    from lensopt.analysis.report import ray_report

    if not (math.isfinite(field) and abs(field) < 90.0):
        raise LensoptError("must be a field angle in degrees, strictly between -90 and 90", path="--field", got=field)
    if not all(math.isfinite(p) for p in pupil):
        raise LensoptError("must be two finite relative pupil coordinates", path="--pupil", got=pupil)
    if math.hypot(*pupil) > 1.0 + 1e-12:
        raise LensoptError("relative pupil coordinates must lie within the unit circle, px² + py² ≤ 1 (1 is the "
                           "pupil edge)", path="--pupil", got=f"{pupil[0]:g} {pupil[1]:g}")
    model = load_model(lens)
    if wavelength is None:
        wavelength = model.spec.spectrum.wavelengths_nm[model.system.reference]
    if not (math.isfinite(wavelength) and wavelength > 0):
        raise LensoptError("must be a positive wavelength in nm", path="--wavelength", got=wavelength)
    r = ray_report(model, field_deg=field, px=pupil[0], py=pupil[1], wavelength_nm=wavelength,
                   aim=check_aim(aim) or model.system.aim)
    if as_json:
        print_json(r)
        return
    t = Table(title=f"real ray: field {field:g}°, pupil ({r['pupil'][0]:g}, {r['pupil'][1]:.6g}), "
                    f"{wavelength:g} nm, aim {r['aim']}")
    for col in ("surf", "x", "y", "z", "L", "M", "N", "AOI °", "AOR °"):
        t.add_column(col, justify="right")
    for s in r["surfaces"]:
        aor = "TIR" if s["aor_deg"] is None and s["aoi_deg"] is not None else _num(s["aor_deg"])
        t.add_row(str(s["surface"]), *[_num(s[k], ".6f") for k in ("x", "y", "z", "L", "M", "N")],
                  _num(s["aoi_deg"]), aor)
    im = r["image"]
    t.add_row("image", *[_num(im[k], ".6f") for k in ("x", "y", "z", "L", "M", "N")], "", "")
    console.print(t)
    at = f" at surface {r['failed_at_surface']}" if r.get("failed_at_surface") else ""
    console.print(f"status: {r['status']}{at}" + (" (backtracking flagged)" if r["backtracking"] else ""))
