"""Real public .zmx files (tests/data/zemax/README.md) imported and compared with optiland 0.6.3's Zemax
reader and tracer: first-order data ≤ 1e-9 relative, real-ray image intercepts ≤ 1e-9 mm, and the same
rays vignetted by the apertures.

To compare geometry and not two glass databases, every optiland medium is replaced by an ideal material
with lensopt's index at the reference wavelength (the indices themselves are compared separately, to the
agreement of the two catalog sources). The rays are lensopt's own launched rays, traced through
optiland's surfaces from a plane 5 mm before surface 1.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

from lensopt.interchange.zemax.read import read_zemax
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.paraxial import first_order
from lensopt.optics.sampling import PupilSampling
from lensopt.spec import build

optiland = pytest.importorskip("optiland")
be = pytest.importorskip("optiland.backend")
from optiland.fileio import load_zemax_file  # noqa: E402
from optiland.materials import IdealMaterial  # noqa: E402
from optiland.rays import RealRays  # noqa: E402

DATA = Path(__file__).resolve().parents[1] / "data" / "zemax"
AGF = DATA / "RPO_TEST.agf"
TRACED = {
    # file: (catalogs, what it shows)
    "optiland_lens1.zmx": ((), "Cooke-like triplet, ENPD, angle fields, Schott glasses"),
    "optiland_lens_floa.zmx": ((), "FLOA (aperture from the stop's semi-diameter)"),
    "optiland_lens_thorlabs_iso_8859_1.zmx": ((), "Thorlabs AL1815-C: EVENASPH r⁴…r¹⁶ with a conic, FLAP, Latin-1"),
    "rayoptics_US00583336-2-scaled.zmx": ((), "double Gauss: FNUM, vignetting VDYN/VCYN/VCXN, FLAP apertures"),
    "rayoptics_US08427765-1.zmx": ((AGF,), "EVENASPH, FLAP apertures, real-image-height fields, an AGF glass"),
}
REL_TOL = 1e-9
MM_TOL = 1e-9


_IMPORTED: dict[str, object] = {}


def _import(name: str):
    if name not in _IMPORTED:  # the FTYP 3 file solves its fields by real ray traces: import once
        _IMPORTED[name] = read_zemax(DATA / name, catalogs=TRACED[name][0])
    return _IMPORTED[name]


def _pair(name: str):
    lens = _import(name)
    model = build(lens.spec)
    be.set_precision("float64")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        optic = load_zemax_file(str(DATA / name))
    w = model.system.reference
    n = model.lens.index[:, w].tolist()
    surfaces = optic.surfaces.surfaces if hasattr(optic.surfaces, "surfaces") else optic.surface_group.surfaces
    assert len(surfaces) == len(n) + 1  # object, lens surfaces, image
    for i, surf in enumerate(surfaces[:-1]):
        surf.material_post = IdealMaterial(n[i])
        geometry = surf.geometry
        if hasattr(geometry, "tol"):  # optiland's Newton default (1e-10 on the sag residual) stops early
            geometry.tol, geometry.max_iter = 1e-15, 1000
    return lens, model, optic


@pytest.mark.parametrize("name", sorted(TRACED))
def test_first_order_matches_optiland(name: str) -> None:
    lens, model, optic = _pair(name)
    fo = first_order(model.lens, model.system)
    p = optic.paraxial
    assert float(fo.efl) == pytest.approx(float(p.f2()), rel=REL_TOL)
    assert float(fo.entrance_pupil_z) == pytest.approx(float(p.EPL()), rel=REL_TOL)
    total = float(fo.total_track)
    # optiland measures the back focus and the exit pupil from the image surface, lensopt from the last
    # surface and surface 1.
    assert float(fo.bfl) - float(fo.image_distance) == pytest.approx(float(p.F2()), rel=REL_TOL, abs=1e-12 * total)
    assert float(fo.exit_pupil_z) - total == pytest.approx(float(p.XPL()), rel=REL_TOL)
    if name != "optiland_lens_floa.zmx":
        assert float(fo.epd) == pytest.approx(float(np.ravel(p.EPD())[0]), rel=REL_TOL)


def test_floating_stop_fills_the_stop_semi_diameter() -> None:
    # Zemax's DIAM is a semi-diameter (OpticStudio's "Semi-Diameter" column); optiland 0.6.3 reads the
    # FLOA stop value as a diameter and gets half our EPD. Independent check: give optiland our EPD and
    # its paraxial marginal ray must reach the stop at the file's DIAM 8.5.
    lens, model, optic = _pair("optiland_lens_floa.zmx")
    fo = first_order(model.lens, model.system)
    optic.set_aperture(aperture_type="EPD", value=float(fo.epd))
    y, _u = optic.paraxial.marginal_ray()
    stop = model.lens.stop + 1  # optiland counts the object surface
    assert float(np.ravel(y[stop])[0]) == pytest.approx(8.5, rel=1e-12)
    assert float(np.ravel(optiland.paraxial.Paraxial(optic).EPD())[0]) == pytest.approx(float(fo.epd) / 1, rel=1e-12)


@pytest.mark.parametrize("name", sorted(TRACED))
def test_real_rays_match_optiland(name: str) -> None:
    lens, model, optic = _pair(name)
    w = model.system.reference
    pts = PupilSampling.parse("rings:6:nojitter").points(dtype=torch.float64)
    pts = torch.cat([pts, pts * torch.tensor([-1.0, 1.0], dtype=torch.float64)])
    bundle = trace_bundle(model.lens, model.system, pts)
    pos, d = bundle.rays.pos[:, w], bundle.rays.dir[:, w]
    pos = pos + ((-5.0 - pos[..., 2]) / d[..., 2]).unsqueeze(-1) * d
    P, D = pos.reshape(-1, 3).numpy(), d.reshape(-1, 3).numpy()
    wl = lens.spec.spectrum.wavelengths_nm[w] * 1e-3
    rays = RealRays(P[:, 0], P[:, 1], P[:, 2], D[:, 0], D[:, 1], D[:, 2], np.ones(len(P)), np.full(len(P), wl))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        optic.surface_group.trace(rays, skip=1)
    out = bundle.result.pos[:, w].reshape(-1, 3).numpy()
    ok_l = bundle.result.valid[:, w].reshape(-1).numpy()
    ok_o = (np.asarray(rays.i) > 0) & np.isfinite(np.asarray(rays.x))
    assert (ok_l == ok_o).all(), "lensopt and optiland vignette different rays"
    assert ok_l.sum() >= 8  # lens_floa: its 40 mm EPD on a 20 mm radius lens passes only the inner ring
    dev = max(np.abs(np.asarray(rays.x) - out[:, 0])[ok_l].max(), np.abs(np.asarray(rays.y) - out[:, 1])[ok_l].max())
    assert dev <= MM_TOL, f"image intercepts differ by {dev:.3e} mm"
    if name == "rayoptics_US00583336-2-scaled.zmx":
        assert not ok_l.all()  # the FLAP apertures vignette some of these rays, in both programs


def test_real_image_height_fields_land_where_the_file_says() -> None:
    # FTYP 3: YFLN 8.0 and 13.6 mm are real image heights; the imported angles' real chief rays land there.
    lens = _import("rayoptics_US08427765-1.zmx")
    model = build(lens.spec)
    bundle = trace_bundle(model.lens, model.system, torch.zeros(1, 2, dtype=torch.float64))
    y = bundle.result.pos[:, model.system.reference, 0, 1].abs().tolist()
    assert y == pytest.approx([0.0, 8.0, 13.6], abs=1e-9)


def test_glass_indices_agree_with_optilands_catalog() -> None:
    # Same glass names looked up in two databases (lensopt's refractiveindex.info snapshot, optiland's):
    # agreement to the catalogs' own precision, not to 1e-9.
    from optiland.materials import Material

    lens = _import("rayoptics_US00583336-2-scaled.zmx")
    model = build(lens.spec)
    wl = model.lens.wavelength_um.tolist()
    for i, surf in enumerate(lens.spec.surfaces):
        if surf.is_air:
            continue
        name = surf.material.split(":")[1]
        ref = Material(name, "schott")
        for j, x in enumerate(wl):
            assert float(model.lens.index[i + 1, j]) == pytest.approx(float(np.ravel(ref.n(x))[0]), abs=2e-5)


def _finite(aperture: str) -> str:
    # optiland_lens1.zmx at a finite object (200 mm) with object-height fields (FTYP 1) and another aperture.
    text = (DATA / "optiland_lens1.zmx").read_text().replace("ENPD 8.333333969116211", aperture)
    text = text.replace("  DISZ INFINITY", "  DISZ 200").replace("FTYP 0 0 3 3", "FTYP 1 0 3 3")
    return text.replace("YFLN 0.0 8.485281610363037 12.000000333930423", "YFLN 0 10 20")


@pytest.mark.parametrize("aperture", ["OBNA 0.05 0", "FNUM 3.5 0"])
def test_object_na_and_object_height_fields_match_optiland(tmp_path: Path, aperture: str) -> None:
    from optiland.fileio.zemax.reader.converter import ZemaxToOpticConverter
    from optiland.fileio.zemax.reader.parser import ZemaxDataParser

    from lensopt.interchange.zemax.read import import_zemax

    text = _finite(aperture)
    model = build(import_zemax(text).spec)
    path = tmp_path / "finite.zmx"
    path.write_text(text)
    be.set_precision("float64")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        optic = ZemaxToOpticConverter(ZemaxDataParser(str(path)).parse()).convert()
    w = model.system.reference
    for surf, n in zip(optic.surfaces.surfaces[:-1], model.lens.index[:, w].tolist(), strict=True):
        surf.material_post = IdealMaterial(n)
    fo = first_order(model.lens, model.system)
    assert float(fo.epd) == pytest.approx(float(np.ravel(optic.paraxial.EPD())[0]), rel=REL_TOL)
    # Chief rays of the object-height fields (0, 10, 20 mm): same image heights in both programs.
    bundle = trace_bundle(model.lens, model.system, torch.zeros(1, 2, dtype=torch.float64))
    ours = bundle.result.pos[:, w, 0, 1].abs().tolist()
    wl = model.lens.wavelength_um[w].item()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        theirs = [abs(float(np.ravel(optic.trace_generic(0.0, h, 0.0, 0.0, wl).y)[0])) for h in (0.0, 0.5, 1.0)]
    assert ours == pytest.approx(theirs, abs=MM_TOL)


def test_paraxial_working_fnumber() -> None:
    from lensopt.interchange.zemax.read import import_zemax

    model = build(import_zemax(_finite("FNUM 3.5 1")).spec)
    assert float(first_order(model.lens, model.system).working_fnumber) == pytest.approx(3.5, rel=1e-12)


def test_vignetting_factors_follow_zemax_definition() -> None:
    # OpticStudio: the pupil coordinate y becomes VDY + (1 − VCY) y, x becomes VDX + (1 − VCX) x. The
    # double Gauss's VDYN/VCYN/VCXN applied by lensopt (S19–S20) map the pupil's edges there.
    from lensopt.optics.vignetting import apply_vignetting

    lens = _import("rayoptics_US00583336-2-scaled.zmx")
    model = build(lens.spec)
    vdy = [0.0, 6.208442661354e-2, 5.473246586901e-2]
    vcy = [0.0, 1.556542586327e-1, 3.64762539196e-1]
    vcx = [0.0, 2.455956935883e-3, 2.0477435112e-3]
    factors = torch.tensor(model.system.vignetting, dtype=torch.float64).unsqueeze(1)  # (F, 1, 3)
    edges = torch.tensor([[0.0, 1.0], [0.0, -1.0], [1.0, 0.0]], dtype=torch.float64).expand(3, 1, 3, 2)
    got = apply_vignetting(edges, factors)[:, 0]
    for f in range(3):
        assert float(got[f, 0, 1]) == pytest.approx(vdy[f] + (1 - vcy[f]), abs=1e-15)
        assert float(got[f, 1, 1]) == pytest.approx(vdy[f] - (1 - vcy[f]), abs=1e-15)
        assert float(got[f, 2, 0]) == pytest.approx(1 - vcx[f], abs=1e-15)
