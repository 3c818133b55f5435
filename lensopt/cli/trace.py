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
from lensopt.errors import LensoptError

__all__ = ["commands"]

commands = typer.Typer()  # its commands, put in order by lensopt.cli.app


@commands.command("trace", short_help="First-order data, spot sizes, failures, distortion, illumination.")
@handle_errors
def trace(lens: LensArg, sampling: SamplingOpt = "rings:24", aim: AimOpt = None, seed: SeedOpt = 0,
          as_json: JsonOpt = False, aim_steps: AimStepsOpt = None,
          mtf: Annotated[str | None, typer.Option("--mtf", help="Also MTF at these cycles/mm (comma-separated; "
                                                  "in --json as mtf).")] = None,
          backend: BackendOpt = "auto") -> None:
    """First-order data, RMS spot radius per field and wavelength, ray failures, distortion and
    relative illumination per field."""
    from lensopt.analysis.report import mtf_report, trace_report

    engine = make_engine(backend)
    model = load_model(lens)
    report = trace_report(model, parse_sampling(sampling, seed),
                          aim=check_aim(aim), aim_steps=check_aim_steps(aim_steps), engine=engine)
    if mtf is not None:
        report["mtf"] = mtf_report(model, parse_frequencies(mtf, "--mtf"), engine=engine)
    if as_json:
        print_json(report)
        return
    _render_trace(report)
    _render_field(report)


def _render_trace(r: dict[str, Any]) -> None:
    ref = r["wavelengths_nm"].index(r["reference_nm"])
    console.print(f"[bold]{r['name']}[/]")
    console.print(_prescription_table(r["surfaces"], ref, r["reference_nm"]))
    fo = r["first_order"]
    t = Table(title=f"first-order data ({r['reference_nm']:g} nm)", title_justify="left")
    t.add_column("quantity")
    t.add_column("value", justify="right")
    t.add_column("unit")
    labels = {"efl": "EFL", "bfl": "BFL (last surface to focus)", "ffl": "FFL (front focus from S1)",
              "epd": "EPD", "entrance_pupil_z": "entrance pupil z (from S1)",
              "exit_pupil_z": "exit pupil z (from S1)", "exit_pupil_diameter": "exit pupil diameter",
              "fnumber": "f-number (EFL/EPD)", "working_fnumber": "working f-number",
              "paraxial_image_height": "paraxial image height", "total_track": "total track"}
    for key, label in labels.items():
        t.add_row(label, f"{fo[key]:.6f}", "" if "fnumber" in key else "mm")
    console.print(t)
    wl = r["wavelengths_nm"]
    s = Table(title=f"RMS spot radius (µm), sampling {r['sampling']}, aim {r['aim']}", title_justify="left")
    s.add_column("field °", justify="right")
    for w in wl:
        s.add_column(f"{w:g} nm", justify="right")
    s.add_column("weighted", justify="right", style="bold")
    s.add_column("centroid y mm", justify="right")
    s.add_column("chief y mm", justify="right")
    s.add_column("failed", justify="right")
    for f in r["fields"]:
        s.add_row(f"{f['angle_deg']:.3f}", *[_num(v) for v in f["rms_spot_radius_um"]],
                  _num(f["rms_spot_radius_weighted_um"]), _num(f["centroid_y_mm"], ".6f"),
                  _num(f["chief_ray_y_mm"], ".6f"), f"{f['failed_rays']}/{f['rays']}")
    console.print(s)
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


def _num(v: float | None, fmt: str = ".4f") -> str:
    return "—" if v is None else format(v, fmt)


def _render_field(r: dict[str, Any]) -> None:
    from lensopt.analysis.field import AIM_NOTE_FRACTION

    full = r["aim"] == "full"
    t = Table(title=f"Distortion, relative illumination, pupil (V factors at {r['reference_nm']:g} nm)"
                    + (f", full aiming {r['aim_steps']} step(s), stop radius {r['stop_radius_mm']:.6f} mm"
                       if full else ""))
    for col in ("field °", "distortion %", "RI S51", "RI S52", "V_i", "V_s", "V_l"):
        t.add_column(col, justify="right")
    if full:
        t.add_column("stop miss µm", justify="right")
        limit = 1e3 * AIM_NOTE_FRACTION * r["stop_radius_mm"]
    for f in r["fields"]:
        v = f["vignetting"]
        ri = f["relative_illumination"]
        row = [f"{f['angle_deg']:.3f}", _num(f["distortion_percent"]), _num(ri["three_ray"]), _num(ri["std"]),
               f"{v['inferior']:.4f}", f"{v['superior']:.4f}", f"{v['lateral']:.4f}"]
        if full:
            miss = 1e3 * max(v["aim_residual_mm"].values())
            row.append(f"{miss:.2e}" + ("" if v["aim_rays_traced"] and miss <= limit else " (!)"))
        t.add_row(*row)
    console.print(t)
    for note in r["notes"]:
        console.print(f"[yellow]note:[/] {note}", highlight=False)


def _prescription_table(surfaces: list[dict[str, Any]], ref: int, ref_nm: float) -> Table:
    """The resolved prescription as traced: one row per surface (the ``surfaces`` of ``trace --json``)."""
    t = Table(title="prescription (lengths in mm)", title_justify="left")
    for col, just in (("surf", "right"), ("type", "left"), ("radius", "right"), ("thickness", "right"),
                      ("material", "left"), (f"n {ref_nm:g} nm", "right"), ("semi-diam.", "right"),
                      ("notes", "left")):
        t.add_column(col, justify=just)  # type: ignore[arg-type]
    for i, sf in enumerate(surfaces, start=1):
        radius = "inf" if math.isinf(sf["radius"]) else f"{sf['radius']:.6f}"
        notes = []
        if sf["stop"]:
            notes.append("stop")
        if sf["conic"]:
            notes.append(f"k={sf['conic']:g}")
        if sf["asphere"]:
            notes.append("asph " + " ".join(f"a{p}={v:.4g}" for p, v in sf["asphere"].items()))
        if "diffractive" in sf:
            d = sf["diffractive"]
            notes.append("DOE " + " ".join(f"d{p}={v:.4g}" for p, v in d.items() if p.isdigit())
                         + f" @{d['design_wavelength_nm']:g} nm m={d['order']}")
        t.add_row(str(i), sf["type"], radius, f"{sf['thickness']:.6f}", sf["material"],
                  f"{sf['index'][ref]:.6f}", f"{sf['semi_diameter']:.4f}", ", ".join(notes))
    return t


@commands.command("ray", short_help="One real ray, surface by surface (like CODE V's RSI).")
@handle_errors
def ray(
    lens: LensArg,
    field: Annotated[float, typer.Option("--field", help="Field angle in degrees.")] = 0.0,
    pupil: Annotated[tuple[float, float], typer.Option("--pupil", help="Relative pupil PX PY.")] = (0.0, 1.0),
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
