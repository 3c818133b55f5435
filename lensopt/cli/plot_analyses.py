"""``lensopt plot opd | wavefront | field-curves | focal-shift | encircled | mtf-field | through-focus``: the
designer's analyses as figures (CLI layer: parse, check, call ``lensopt.analysis``, draw with
``lensopt.plot``). ``app.py`` appends these commands to the ``plot`` group after those of ``plot.py``.

Fields are relative (0 = axis, 1 = the spec's full field, as in the spec), wavelengths in nm and one of
the spec's, frequencies in cycles/mm; a value outside these is one line and exit 2 (``analysis.checks``).
Every figure is written atomically (``plot.style.save_figure``).
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Annotated

import typer

from lensopt.cli.common import (
    AimOpt,
    LensArg,
    SamplingOpt,
    check_aim,
    err_console,
    handle_errors,
    load_model,
)
from lensopt.cli.plot import DpiOpt, OutOpt, _check_output, _titles
from lensopt.errors import LensoptError

if TYPE_CHECKING:
    from torch import Tensor

    from lensopt.spec import Model

__all__ = ["commands"]

commands = typer.Typer()  # its commands go into the plot group (lensopt.cli.app)

FieldOpt = Annotated[str | None, typer.Option(
    "--field", help="Relative fields, comma-separated: 0 = axis, 1 = the spec's full field (default: the spec's "
    "fields).")]
MethodOpt = Annotated[str, typer.Option("--method", help="MTF method: heuristic | geometric | reference.")]
FrequenciesOpt = Annotated[str | None, typer.Option(
    "--frequencies", help="Spatial frequencies, cycles/mm, comma-separated (default: a quarter, half and all of "
    "the sensor's Nyquist frequency, without a sensor a tenth, quarter and half of the diffraction cutoff).")]
FocusFrequenciesOpt = Annotated[str | None, typer.Option(
    "--frequencies", help="Spatial frequencies, cycles/mm, comma-separated, one panel each (default: half the "
    "sensor's Nyquist frequency, without a sensor a quarter of the diffraction cutoff).")]


def _numbers(text: str, option: str, what: str) -> list[float]:
    try:
        vals = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise LensoptError(f"expected comma-separated numbers ({what})", path=option, got=text) from None
    if not vals:
        raise LensoptError(f"expected comma-separated numbers ({what})", path=option, got=text)
    return vals


def _fields(model: Model, text: str | None) -> Tensor:
    from lensopt.analysis.checks import relative_fields

    vals = None if text is None else _numbers(text, "--field", "relative fields")
    return relative_fields(model.system, vals, path="--field", dtype=model.lens.dtype)


def _wavelengths(model: Model, text: str | None, *, one: bool = False) -> list[int] | None:
    from lensopt.analysis.checks import wavelength_indices

    if text is None:
        return None
    vals = _numbers(text, "--wavelength", "nm")
    if one and len(vals) != 1:
        raise LensoptError("expected one wavelength in nm", path="--wavelength", got=text)
    return wavelength_indices(model.lens, vals, path="--wavelength")


def _frequencies(model: Model, text: str | None, *, nyquist: tuple[float, ...], cutoff: tuple[float, ...]
                 ) -> list[float]:
    """Checked frequencies; by default the fractions ``nyquist`` of the sensor's Nyquist frequency, or
    without a sensor the fractions ``cutoff`` of the diffraction cutoff (3 significant digits)."""
    from lensopt.analysis.checks import frequencies

    if text is not None:
        return frequencies(_numbers(text, "--frequencies", "cycles/mm"), path="--frequencies").tolist()
    if model.spec.sensor is not None:
        top, fractions = 1.0 / (2e-3 * model.spec.sensor.pixel_pitch_um), nyquist
    else:
        top, fractions = _cutoff(model), cutoff
    return [float(f"{top * f:.3g}") for f in fractions]


def _cutoff(model: Model) -> float:
    from lensopt.optics.paraxial import first_order

    wn = abs(float(first_order(model.lens, model.system).working_fnumber))
    return 1.0 / (float(model.lens.wavelength_um.min()) * 1e-3 * wn)


def _method(method: str) -> str:
    from lensopt.analysis.mtf import MTF_METHODS

    if method not in MTF_METHODS:
        raise LensoptError(f"must be one of {', '.join(MTF_METHODS)}", path="--method", got=method)
    return method


def _sampling(text: str) -> str:
    from lensopt.optics.sampling import PupilSampling

    PupilSampling.parse(text, path="--sampling")
    return text


def _airy_um(model: Model) -> float:
    from lensopt.optics.paraxial import first_order

    wn = abs(float(first_order(model.lens, model.system).working_fnumber))
    ref = model.system.reference
    return 1.22 * float(model.lens.wavelength_um[ref]) * wn / float(model.lens.index[-1, ref])


def _wrote(output: object) -> None:
    err_console.print(f"wrote {output}", highlight=False)


@commands.command("opd", short_help="OPD fans: wavefront error along the pupil axes per field.")
@handle_errors
def plot_opd_cmd(lens: LensArg, output: OutOpt, field: FieldOpt = None,
                 wavelength: Annotated[str | None, typer.Option(
                     "--wavelength", help="Wavelengths in nm, comma-separated, of the spec's (default: all).")] = None,
                 points: Annotated[int, typer.Option("--points", min=3, max=2001, help="Rays per fan.")] = 65,
                 dpi: DpiOpt = 150) -> None:
    """Tangential and sagittal OPD fans (waves) per field, one curve per wavelength, referenced to the real
    chief ray's sphere (docs/analyses.md)."""
    import torch

    from lensopt.analysis.wavefront import opd_fans
    from lensopt.plot.opd import opd_fans_figure
    from lensopt.plot.style import save_figure

    out = _check_output(output)
    model = load_model(lens)
    rel = _fields(model, field)
    keep = _wavelengths(model, wavelength)
    with torch.no_grad():
        fans = opd_fans(model.lens, model.system, points=points, rel_field=rel)
    if keep is not None:
        idx = torch.tensor(keep)
        ref = keep.index(fans.reference) if fans.reference in keep else -1
        fans = dataclasses.replace(
            fans, tangential=fans.tangential[:, idx], tangential_valid=fans.tangential_valid[:, idx],
            sagittal=fans.sagittal[:, idx], sagittal_valid=fans.sagittal_valid[:, idx],
            wavelength_um=fans.wavelength_um[idx], reference=ref)
    title, sub = _titles(model)
    save_figure(opd_fans_figure(fans, title=title, subtitle=sub), out, dpi=dpi)
    _wrote(output)


@commands.command("wavefront", short_help="Wavefront maps with RMS, P-V, Strehl and Zernike terms.")
@handle_errors
def plot_wavefront_cmd(lens: LensArg, output: OutOpt, field: FieldOpt = None,
                       wavelength: Annotated[str | None, typer.Option(
                           "--wavelength", help="One of the spec's wavelengths, nm (default: the reference).")] = None,
                       samples: Annotated[int, typer.Option("--samples", min=8, max=512,
                                                            help="Pupil grid N×N.")] = 64,
                       zernike: Annotated[str, typer.Option("--zernike", help="Zernike ordering: fringe | noll | "
                                                            "ansi.")] = "fringe",
                       terms: Annotated[int, typer.Option("--terms", min=4, max=231,
                                                          help="Zernike terms fitted (Fringe: at most 37).")] = 37,
                       dpi: DpiOpt = 150) -> None:
    """Wavefront map per field at one wavelength, with RMS and P-V (waves), the Strehl ratio (PSF and
    Maréchal) and the largest Zernike terms of a least-squares fit."""
    import torch

    from lensopt.analysis.strehl import strehl
    from lensopt.analysis.wavefront import WavefrontMap, map_grid, wavefront_stats
    from lensopt.analysis.zernike import ORDERINGS, fit_zernike, zernike_indices
    from lensopt.plot.style import save_figure
    from lensopt.plot.wavefront import wavefront_figure

    out = _check_output(output)
    if zernike not in ORDERINGS:
        raise LensoptError(f"must be one of {', '.join(ORDERINGS)}", path="--zernike", got=zernike)
    if zernike == "fringe" and terms > 37:
        raise LensoptError("the Fringe set has 37 terms (use noll or ansi for more)", path="--terms", got=terms)
    zernike_indices(zernike, terms)
    inside = int(map_grid(samples, dtype=torch.float64)[1].sum())
    if terms > inside:
        raise LensoptError(f"more terms than the {inside} pupil samples of --samples {samples}; raise --samples",
                           path="--terms", got=terms)
    model = load_model(lens)
    rel = _fields(model, field)
    picked = _wavelengths(model, wavelength, one=True)
    w = model.system.reference if picked is None else picked[0]
    with torch.no_grad():
        s = strehl(model.lens, model.system, rel_field=rel, pupil_samples=samples)
        wf = s.wavefront
        shape = (*wf.opd.shape[:2], samples, samples)
        wm = WavefrontMap(wavefront=wf, opd=wf.opd.reshape(shape), valid=wf.valid.reshape(shape))
        fit = fit_zernike(wf.pupil, wf.opd, wf.valid, ordering=zernike, terms=terms)
        stats = wavefront_stats(wf)
    title, sub = _titles(model)
    save_figure(wavefront_figure(wm, w, stats=stats, strehl=s, zernike=fit, title=title, subtitle=sub), out, dpi=dpi)
    _wrote(output)


@commands.command("field-curves", short_help="Field curvature, distortion and lateral colour against field.")
@handle_errors
def plot_field_curves_cmd(lens: LensArg, output: OutOpt, aim: AimOpt = None,
                          samples: Annotated[int, typer.Option("--samples", min=2, max=401,
                                                               help="Fields from axis to full field.")] = 21,
                          dpi: DpiOpt = 150) -> None:
    """Tangential and sagittal field curvature (real rays about the chief ray), real chief-ray distortion
    and lateral colour against field, every wavelength."""
    import torch

    from lensopt.analysis.field_curves import field_curves
    from lensopt.plot.field_curves import field_curves_figure
    from lensopt.plot.style import save_figure

    out = _check_output(output)
    model = load_model(lens)
    rel = torch.linspace(0.0, 1.0, samples, dtype=model.lens.dtype)
    with torch.no_grad():
        fc = field_curves(model.lens, model.system, rel, aim=check_aim(aim))
    title, sub = _titles(model)
    save_figure(field_curves_figure(fc, title=title, subtitle=sub, airy_um=_airy_um(model)), out, dpi=dpi)
    _wrote(output)


@commands.command("focal-shift", short_help="Chromatic focal shift against wavelength.")
@handle_errors
def plot_focal_shift_cmd(lens: LensArg, output: OutOpt,
                         samples: Annotated[int, typer.Option("--samples", min=2, max=2001,
                                                              help="Wavelengths across the spec's range.")] = 41,
                         dpi: DpiOpt = 150) -> None:
    """Paraxial focus against wavelength relative to the reference wavelength, the spec's wavelengths marked
    and the diffraction depth of focus shaded."""
    import torch

    from lensopt.analysis.field_curves import chromatic_focal_shift
    from lensopt.optics.paraxial import first_order
    from lensopt.plot.focal_shift import focal_shift_figure
    from lensopt.plot.style import save_figure

    out = _check_output(output)
    model = load_model(lens)
    with torch.no_grad():
        fs = chromatic_focal_shift(model.lens, model.system, media=model.media, samples=samples)
        wn = abs(float(first_order(model.lens, model.system).working_fnumber))
    title, sub = _titles(model)
    save_figure(focal_shift_figure(fs, working_fnumber=wn, title=title, subtitle=sub), out, dpi=dpi)
    _wrote(output)


@commands.command("encircled", short_help="Encircled (or ensquared) energy per field.")
@handle_errors
def plot_encircled_cmd(
    lens: LensArg, output: OutOpt, field: FieldOpt = None,
    method: Annotated[str, typer.Option("--method", help="geometric (rays) | diffraction (Debye PSF).")]
    = "geometric",
    ensquared: Annotated[bool, typer.Option("--ensquared", help="Energy in squares (half-width) instead of "
                                            "circles.")] = False,
    wavelength: Annotated[str | None, typer.Option(
        "--wavelength", help="One of the spec's wavelengths, nm (default: polychromatic, the spectral "
        "weights).")] = None,
    center: Annotated[str, typer.Option("--center", help="centroid | chief: the centre of the circles.")]
    = "centroid",
    sampling: SamplingOpt = "rings:32",
    samples: Annotated[int | None, typer.Option("--samples", min=8, max=512, help="Pupil grid N×N of "
                                                "--method diffraction (default: enough for the radii).")] = None,
    dpi: DpiOpt = 150,
) -> None:
    """Fraction of the energy within a radius (or a square) about the centroid or the chief ray, per field,
    beside the diffraction limit."""
    import torch

    from lensopt.analysis.encircled import CENTERS, diffraction_energy, geometric_energy
    from lensopt.plot.encircled import encircled_figure
    from lensopt.plot.style import save_figure

    out = _check_output(output)
    if method not in ("geometric", "diffraction"):
        raise LensoptError("must be geometric or diffraction", path="--method", got=method)
    if center not in CENTERS:
        raise LensoptError(f"must be one of {', '.join(CENTERS)}", path="--center", got=center)
    _sampling(sampling)
    model = load_model(lens)
    rel = _fields(model, field)
    picked = _wavelengths(model, wavelength, one=True)
    with torch.no_grad():
        if method == "geometric":
            curves = geometric_energy(model.lens, model.system, rel_field=rel, sampling=sampling, center=center)
        else:
            curves = diffraction_energy(model.lens, model.system, rel_field=rel, pupil_samples=samples,
                                        center=center, sampling=sampling)
    if picked is not None:
        w = picked[0]
        curves = dataclasses.replace(curves, encircled=curves.encircled_w[:, w], ensquared=curves.ensquared_w[:, w])
    title, sub = _titles(model)
    if picked is not None:
        sub += f" · {1e3 * float(model.lens.wavelength_um[picked[0]]):g} nm only"
    save_figure(encircled_figure(curves, ensquared=ensquared, title=title, subtitle=sub), out, dpi=dpi)
    _wrote(output)


@commands.command("mtf-field", short_help="MTF against field at a few frequencies.")
@handle_errors
def plot_mtf_field_cmd(lens: LensArg, output: OutOpt, frequencies: FrequenciesOpt = None,
                       samples: Annotated[int, typer.Option("--samples", min=2, max=101,
                                                            help="Fields from axis to full field.")] = 21,
                       method: MethodOpt = "heuristic", sampling: SamplingOpt = "rings:32",
                       dpi: DpiOpt = 150) -> None:
    """Tangential and sagittal MTF (polychromatic) against field at the chosen frequencies."""
    from lensopt.analysis.mtf_field import mtf_vs_field
    from lensopt.plot.mtf_field import mtf_field_figure
    from lensopt.plot.style import save_figure

    out = _check_output(output)
    _method(method)
    _sampling(sampling)
    model = load_model(lens)
    nu = _frequencies(model, frequencies, nyquist=(0.25, 0.5, 1.0), cutoff=(0.1, 0.25, 0.5))
    res = mtf_vs_field(model.lens, model.system, nu, fields=samples, method=method, sampling=sampling)
    title, sub = _titles(model)
    save_figure(mtf_field_figure(res, title=title, subtitle=sub), out, dpi=dpi)
    _wrote(output)


@commands.command("through-focus", short_help="MTF through focus at a few fields.")
@handle_errors
def plot_through_focus_cmd(
    lens: LensArg, output: OutOpt, frequencies: FocusFrequenciesOpt = None, field: FieldOpt = None,
    focus_range: Annotated[float | None, typer.Option(
        "--focus-range", help="Half-width of the focus sweep, µm (default: 4 × the diffraction depth of focus "
        "2λN²).")] = None,
    samples: Annotated[int, typer.Option("--samples", min=3, max=401, help="Focus positions.")] = 21,
    method: MethodOpt = "heuristic", sampling: SamplingOpt = "rings:32", dpi: DpiOpt = 150,
) -> None:
    """Tangential and sagittal MTF (polychromatic) against the image-surface position, one panel per
    frequency, one colour per field, the best focus of each curve marked."""
    import torch

    from lensopt.analysis.mtf_field import through_focus_mtf
    from lensopt.optics.paraxial import first_order
    from lensopt.plot.style import save_figure
    from lensopt.plot.through_focus import through_focus_figure

    out = _check_output(output)
    if focus_range is not None and not (math.isfinite(focus_range) and focus_range > 0):
        raise LensoptError("must be a positive half-width in µm", path="--focus-range", got=focus_range)
    _method(method)
    _sampling(sampling)
    model = load_model(lens)
    rel = _fields(model, field)
    nu = _frequencies(model, frequencies, nyquist=(0.5,), cutoff=(0.25,))
    lens_, system = model.lens, model.system
    if focus_range is None:
        wn = abs(float(first_order(lens_, system).working_fnumber))
        focus_range = 4.0 * 2.0 * float(lens_.wavelength_um[system.reference]) * wn**2
    focus = torch.linspace(-focus_range, focus_range, samples, dtype=lens_.dtype) * 1e-3
    tf = through_focus_mtf(lens_, system, nu, focus_mm=focus, rel_field=rel, method=method, sampling=sampling)
    title, sub = _titles(model)
    save_figure(through_focus_figure(tf, title=title, subtitle=sub), out, dpi=dpi)
    _wrote(output)
