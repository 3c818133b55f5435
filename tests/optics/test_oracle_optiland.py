"""Agreement with an independent tracer: every spec in ``specs/`` traced by lensopt and by optiland.

Oracle: optiland 0.6.3 (the ``oracle`` extra), a separate numpy implementation of sequential real-ray
tracing. For each spec the same lens is built in optiland from lensopt's resolved prescription, with
``IdealMaterial(n)`` per wavelength set to the indices lensopt computed (so the comparison is of the
trace, independent of glass data), and exactly the same object-space rays (lensopt's ``Bundle.rays``,
all fields, ``rings:24`` and ``grid:41``) are traced with ``optic.surfaces.trace(RealRays(...))``.
Reference values are produced at test time by optiland; nothing is hard-coded.

Conventions mapped here (read from optiland's source):
- ``EvenAsphere`` coefficients start at r²: ``coefficients[i]`` multiplies r^(2i+2), so lensopt's
  (a4, a6, …) become ``[0, a4, a6, …]``. Its Newton tolerance defaults to 1e-6 through
  ``add_surface``; it is set to 1e-15 (residual, mm) here.
- ``RadialPhaseProfile([c2, c4, …])``: φ = Σ c_{2i} r^{2i} in radians, r in mm, no normalisation
  radius and no diffraction order; the interaction adds ∇φ to the tangential wavevector,
  k0 n' d'_t = k0 n d_t + (∇φ)_t with k0 = 2π/λ, i.e. lensopt's law with m = 1. The order is folded
  into the coefficients (c = m d). On a curved base both tools project the transverse gradient
  (∂φ/∂x, ∂φ/∂y, 0) onto the local tangent plane, so they agree there too (measured 1e-14 mm).
- optiland's paraxial tracer (``raytrace/paraxial_ray_tracer.trace_generic``) uses only (n'−n)/R
  and thin-lens ``paraxial`` surfaces: it ignores phase surfaces, so its f2() etc. miss the DOE
  power. (Its ``PhaseInteractionModel.interact_paraxial_rays`` also has the opposite sign of its real
  trace.) For lenses with a DOE, the paraxial oracle therefore gets the DOE as an optiland thin-lens
  surface of power K = −m λ d2/π, and that power is checked separately against optiland's *real*
  trace in the paraxial limit (``test_doe_power_real_ray_limit``).
- Positions: optiland's EPL and F1 are from surface 1 (as lensopt), XPL and F2 from the image
  surface (lensopt: exit pupil from surface 1, BFL from the last surface).
"""

from __future__ import annotations

import dataclasses
import math
from functools import cache
from pathlib import Path

import numpy as np
import pytest
import torch

pytest.importorskip("optiland")

from optiland import optic as ol_optic  # noqa: E402
from optiland.materials import IdealMaterial, Material  # noqa: E402
from optiland.phase import RadialPhaseProfile  # noqa: E402
from optiland.rays import RealRays  # noqa: E402

from lensopt.analysis.spot import spot_stats  # noqa: E402
from lensopt.materials import CatalogGlass  # noqa: E402
from lensopt.optics.bundle import Bundle, trace_bundle  # noqa: E402
from lensopt.optics.paraxial import first_order  # noqa: E402
from lensopt.optics.sampling import PupilSampling  # noqa: E402
from lensopt.spec import build, load_spec  # noqa: E402
from lensopt.spec.build import Model  # noqa: E402

pytestmark = [
    pytest.mark.filterwarnings("ignore::DeprecationWarning"),
    pytest.mark.filterwarnings("ignore:.*:numba.core.errors.NumbaIRAssumptionWarning"),
]

SPECS = sorted((Path(__file__).resolve().parents[2] / "specs").glob("*.toml"))
SAMPLINGS = ("rings:24", "grid:41")
INTERCEPT_TOL_MM = 1e-9
RMS_REL_TOL = 1e-9
FIRST_ORDER_REL_TOL = 1e-10


def _ids(paths: list[Path]) -> list[str]:
    return [p.stem for p in paths]


@cache
def _model(path: Path) -> Model:
    return build(load_spec(path))


def _unsupported(model: Model) -> str | None:
    """Why optiland cannot represent this spec as lensopt traces it (None if it can)."""
    clipped = [i for i, s in enumerate(model.spec.surfaces) if s.clip]
    if clipped:
        return f"surfaces {clipped} clip at their semi-diameter; clipping apertures are not mapped to optiland"
    return None


def _require(model: Model) -> None:
    reason = _unsupported(model)
    if reason is not None:
        pytest.skip(f"optiland cannot represent this spec: {reason}")


def optiland_lens(model: Model, w: int, *, doe_as_thin_lens: bool = False) -> ol_optic.Optic:
    """The lens as an optiland Optic at wavelength index ``w``, with lensopt's indices.

    With ``doe_as_thin_lens`` every diffractive surface is preceded (zero gap, same medium) by an
    optiland ``paraxial`` thin-lens surface of power K = −m λ d2/π, for optiland's paraxial module,
    which ignores phase profiles.
    """
    lens, system = model.lens, model.system
    index = lens.index[:, w].tolist()
    lam_mm = float(lens.wavelength_um[w]) * 1e-3
    o = ol_optic.Optic()
    obj = math.inf if system.object_distance is None else system.object_distance
    o.surfaces.add(index=0, radius=math.inf, thickness=obj, material=IdealMaterial(n=index[0]))
    k = 1
    for i, shape in enumerate(lens.shapes):
        c = float(lens.curvature[i])
        kw: dict = {"radius": math.inf if c == 0 else 1.0 / c}
        if shape.kind in ("conic", "asphere"):
            kw["conic"] = float(lens.conic[i])
        if shape.kind == "asphere":
            kw.update(surface_type="even_asphere", tol=1e-15, max_iter=100,
                      coefficients=[0.0] + lens.asphere[i].tolist())
        if shape.diffractive:
            coeffs = [shape.order * d for d in lens.phase[i].tolist()]
            power = -lam_mm * coeffs[0] / math.pi if coeffs else 0.0  # K = −m λ d2 / π
            if doe_as_thin_lens and power != 0.0:
                o.surfaces.add(index=k, surface_type="paraxial", f=1.0 / power, thickness=0.0,
                               material=IdealMaterial(n=index[i]))
                k += 1
            if not doe_as_thin_lens:
                kw["phase_profile"] = RadialPhaseProfile(coeffs)
        o.surfaces.add(index=k, thickness=float(lens.thickness[i]), is_stop=(i == lens.stop),
                       material=IdealMaterial(n=index[i + 1]), **kw)
        k += 1
    o.surfaces.add(index=k)
    return o


def optiland_trace(model: Model, bundle: Bundle) -> np.ndarray:
    """(F, W, P, 3) image-surface intercepts of ``bundle.rays`` traced by optiland."""
    lens = model.lens
    out = np.empty(bundle.result.pos.shape)
    for w in range(lens.wavelength_um.shape[0]):
        o = optiland_lens(model, w)
        pos = bundle.rays.pos[:, w].expand(bundle.result.pos[:, w].shape).reshape(-1, 3).numpy()
        d = bundle.rays.dir[:, w].expand(bundle.result.pos[:, w].shape).reshape(-1, 3).numpy()
        # optiland loses rays that start deep inside the lens (the wide-angle's entrance pupil lies 38 mm
        # behind surface 1: 499 of 2880 rays came back NaN); moving the start back along the straight
        # object-space ray to z = −1 mm changes nothing physically and optiland traces them all.
        t = np.minimum(0.0, (-1.0 - pos[:, 2]) / d[:, 2])
        pos = pos + t[:, None] * d
        n = pos.shape[0]
        rays = RealRays(*(np.ascontiguousarray(a) for a in (*pos.T, *d.T)), np.ones(n),
                        np.full(n, float(lens.wavelength_um[w])))
        o.surfaces.trace(rays)
        xyz = np.stack([np.asarray(rays.x), np.asarray(rays.y), np.asarray(rays.z)], -1)
        assert np.all(np.asarray(rays.i) > 0) and np.all(np.isfinite(xyz)), "optiland lost rays"
        out[:, w] = xyz.reshape(out[:, w].shape)
    return out


@cache
def _traced(path: Path, sampling: str) -> tuple[Bundle, np.ndarray]:
    model = _model(path)
    scheme = PupilSampling.parse(sampling)
    bundle = trace_bundle(model.lens, model.system, scheme.points(dtype=torch.float64), half_pupil=scheme.half)
    return bundle, optiland_trace(model, bundle)


@pytest.mark.parametrize("sampling", SAMPLINGS)
@pytest.mark.parametrize("path", SPECS, ids=_ids(SPECS))
def test_image_intercepts(path: Path, sampling: str) -> None:
    _require(_model(path))
    bundle, theirs = _traced(path, sampling)
    assert int((~bundle.result.valid).sum()) == 0, "spec must trace without failed rays at its nominal fields"
    ours = bundle.result.pos.numpy()
    assert np.abs(ours - theirs).max() <= INTERCEPT_TOL_MM


def _rms_s23(xy: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Seed S23/S24 in numpy: (F, W, P, 2) intercepts → (F,) wavelength-weighted RMS radius.

    x̄ = 0 by axial symmetry (S24); all rays valid (checked), so n_p is the same for every w.
    """
    ww = weights[None, :, None]
    n_p = xy.shape[2]
    y_bar = (ww * xy[..., 1]).sum((1, 2)) / (n_p * weights.sum())
    d2 = xy[..., 0] ** 2 + (xy[..., 1] - y_bar[:, None, None]) ** 2
    return np.sqrt((ww * d2).sum((1, 2)) / (n_p * weights.sum()))


@pytest.mark.parametrize("sampling", SAMPLINGS)
@pytest.mark.parametrize("path", SPECS, ids=_ids(SPECS))
def test_rms_spot_radius(path: Path, sampling: str) -> None:
    model = _model(path)
    _require(model)
    bundle, theirs = _traced(path, sampling)
    weights = model.system.wavelength_weights
    ours = spot_stats(bundle, weights).rms_radius.numpy()
    reference = _rms_s23(theirs[..., :2], weights.numpy())
    assert np.abs(ours / reference - 1).max() <= RMS_REL_TOL


def _optiland_first_order(model: Model) -> dict[str, float]:
    lens, system = model.lens, model.system
    fo = first_order(lens, system)
    o = optiland_lens(model, system.reference, doe_as_thin_lens=True)
    o.set_aperture("EPD", float(fo.epd))
    if system.field_type == "angle":
        o.fields.set_type("angle")
    else:
        o.fields.set_type("paraxial_image_height")
    for r in system.rel_field:
        o.fields.add(y=r * system.field_max)
    o.wavelengths.add(value=float(lens.wavelength_um[system.reference]), is_primary=True)
    pa = o.paraxial
    image_distance = float(lens.thickness[-1])
    total_track = float(lens.vertex_z()[-1])
    values = {
        "efl": pa.f2(),
        "bfl": pa.F2() + image_distance,  # F2 is from the image surface
        "ffl": pa.F1(),  # front focal point from surface 1
        "epd": pa.EPD(),
        "entrance_pupil_z": pa.EPL(),  # from surface 1
        "exit_pupil_z": pa.XPL() + total_track,  # XPL is from the image surface
        "exit_pupil_diameter": abs(float(np.ravel(pa.XPD())[0])),
        "fnumber": pa.FNO(),
        "paraxial_image_height": pa.chief_ray()[0][-1],
    }
    return {k: float(np.ravel(v)[0]) for k, v in values.items()}


@pytest.mark.parametrize("path", SPECS, ids=_ids(SPECS))
def test_first_order(path: Path) -> None:
    model = _model(path)
    _require(model)
    ours = first_order(model.lens, model.system).as_dict()
    theirs = _optiland_first_order(model)
    scale = abs(ours["efl"])  # positions that can be 0 (pupil on surface 1) are compared against |EFL|
    for key, value in theirs.items():
        assert abs(ours[key] - value) <= FIRST_ORDER_REL_TOL * max(abs(value), scale), key


# Specs whose diffractive surfaces carry phase power (a crude start with every phase term 0 has none to test).
DOE_SPECS = [p for p in SPECS if any(s.diffractive for s in _model(p).lens.shapes) and bool(_model(p).lens.phase.any())]


@pytest.mark.parametrize("path", DOE_SPECS, ids=_ids(DOE_SPECS))
def test_doe_power_real_ray_limit(path: Path) -> None:
    """EFL and BFL including the DOE power K = −m λ d2/π, against optiland's *real* trace.

    A ray parallel to the axis at height h gives f(h) = h / tan u' and the image-space axis crossing;
    both are even in h, so Richardson extrapolation (4 f(h/2) − f(h)) / 3 removes the h² term.
    """
    model = _model(path)
    _require(model)
    lens, system = model.lens, model.system
    w = system.reference
    o = optiland_lens(model, w)
    z_image = float(lens.vertex_z()[-1])
    z_last = z_image - float(lens.thickness[-1])

    def efl_bfl(h: float) -> tuple[float, float]:
        rays = RealRays(np.array([0.0]), np.array([h]), np.array([-1.0]), np.array([0.0]), np.array([0.0]),
                        np.array([1.0]), np.ones(1), np.full(1, float(lens.wavelength_um[w])))
        o.surfaces.trace(rays)
        slope = float(rays.M[0]) / float(rays.N[0])
        return -h / slope * float(lens.index[-1, w]), z_image - float(rays.y[0]) / slope - z_last

    h = 1e-3 * float(first_order(lens, system).epd)
    (f1, b1), (f2, b2) = efl_bfl(h), efl_bfl(h / 2)
    efl, bfl = (4 * f2 - f1) / 3, (4 * b2 - b1) / 3
    ours = first_order(lens, system)
    assert efl == pytest.approx(float(ours.efl), rel=FIRST_ORDER_REL_TOL)
    assert bfl == pytest.approx(float(ours.bfl), rel=FIRST_ORDER_REL_TOL)
    # The DOE really contributes: dropping its power moves the EFL far more than the tolerance.
    refractive = first_order(dataclasses.replace(lens, phase=torch.zeros_like(lens.phase)), system)
    assert abs(float(refractive.efl) / float(ours.efl) - 1) > 1e-3


def _catalog_glasses() -> list[tuple[str, CatalogGlass, float]]:
    found: dict[str, tuple[str, CatalogGlass, float]] = {}
    for path in SPECS:
        model = _model(path)
        for medium in model.media:
            if isinstance(medium, CatalogGlass):
                for lam in model.lens.wavelength_um.tolist():
                    found[f"{medium.glass.name}@{lam:.4f}"] = (path.stem, medium, lam)
    return sorted(found.values(), key=lambda t: (t[1].glass.name, t[2]))


GLASSES = _catalog_glasses()


@pytest.mark.parametrize(("spec", "glass", "wavelength_um"), GLASSES,
                         ids=[f"{g.glass.name}-{lam * 1e3:.1f}nm" for _, g, lam in GLASSES])
def test_catalog_index_vs_optiland_database(spec: str, glass: CatalogGlass, wavelength_um: float) -> None:
    """lensopt's catalog index vs optiland's material database for every glass of the specs.

    Both tools ship the dispersion coefficients of the refractiveindex.info database (CC0), so this
    is the same vendor data read and evaluated by two independent code paths (catalog extraction,
    formula selection, Sellmeier/polynomial evaluation); with identical coefficients the only
    difference is float64 round-off, hence 1e-12. The vendor must be named: optiland's lookup by
    name alone resolves e.g. F2 to Hikari's F2, 3e-3 away from Schott's.
    """
    theirs = Material(glass.glass.name, reference=glass.glass.vendor)
    assert glass.glass.vendor in str(theirs.filename).lower()
    ours = float(glass.index(torch.tensor([wavelength_um], dtype=torch.float64))[0])
    assert ours == pytest.approx(float(np.ravel(theirs.n(wavelength_um))[0]), abs=1e-12)
