"""COORDBRK: coordinate breaks imported as dummy plane surfaces with a ``basic`` decenter/tilt (the axis
follows) and traced against optiland 0.6.3's reading of the same file (its converter nests a coordinate
system per break). No public refractive .zmx with a coordinate break was found, so the file is
tests/data/zemax/optiland_lens1.zmx with breaks inserted (a decenter + tilt about x before the stop, a tilt
about y after the last lens). Rays: lensopt's launched rays, image intercepts compared in the image
surface's own frame."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

from lensopt.errors import SpecError
from lensopt.interchange.zemax.read import import_zemax
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.sampling import PupilSampling
from lensopt.spec import build

pytest.importorskip("optiland")
import optiland.backend as be  # noqa: E402
from optiland.fileio.zemax.reader.converter import ZemaxToOpticConverter  # noqa: E402
from optiland.fileio.zemax.reader.parser import ZemaxDataParser  # noqa: E402
from optiland.materials import IdealMaterial  # noqa: E402
from optiland.rays import RealRays  # noqa: E402

DATA = Path(__file__).resolve().parents[1] / "data" / "zemax"
LENS1 = (DATA / "optiland_lens1.zmx").read_text()
CB1 = ("SURF 5\n  TYPE COORDBRK\n  PARM 1 0\n  PARM 2 0.2\n  PARM 3 1.5\n  PARM 4 0\n  PARM 5 0\n  PARM 6 0\n"
       "  DISZ 0.1\n")
CB2 = "SURF 9\n  TYPE COORDBRK\n  PARM 1 0.1\n  PARM 2 0\n  PARM 3 0\n  PARM 4 -0.8\n  PARM 5 0\n  PARM 6 0\n  DISZ 0\n"


def _file() -> str:
    text = LENS1.replace("SURF 8\n", "SURF 10\n").replace("SURF 7\n", "SURF 8\n").replace("SURF 6\n", "SURF 7\n")
    text = text.replace("SURF 5\n  STOP", CB1 + "SURF 6\n  STOP")
    return text.replace("SURF 10\n", CB2 + "SURF 10\n")


def _optiland_optic(path: Path, media: list[float]):  # noqa: ANN202
    """optiland's reading of the file at ``path``, its media replaced by lensopt's indices (one per gap), so
    that the geometry is compared and not two glass databases."""
    be.set_precision("float64")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        optic = ZemaxToOpticConverter(ZemaxDataParser(str(path)).parse()).convert()
    surfaces = optic.surfaces.surfaces
    assert len(surfaces) == len(media) + 1
    for surf, n in zip(surfaces[:-1], media, strict=True):
        surf.material_post = IdealMaterial(n)
    return optic


def _intercepts(optic, model, pts: torch.Tensor) -> tuple[float, np.ndarray, np.ndarray]:  # noqa: ANN001
    """lensopt's launched rays at the reference wavelength traced by optiland from z = −5 mm: the largest
    |Δx|, |Δy| of the image intercepts (in the image surface's own frame) over the rays lensopt passes,
    lensopt's intercepts and their validity."""
    w = model.system.reference
    bundle = trace_bundle(model.lens, model.system, pts)
    pos, d = bundle.rays.pos[:, w], bundle.rays.dir[:, w]
    pos = pos + ((-5.0 - pos[..., 2]) / d[..., 2]).unsqueeze(-1) * d
    P, D = pos.reshape(-1, 3).numpy(), d.reshape(-1, 3).numpy()
    rays = RealRays(P[:, 0], P[:, 1], P[:, 2], D[:, 0], D[:, 1], D[:, 2], np.ones(len(P)),
                    np.full(len(P), model.lens.wavelength_um[w].item()))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        optic.surfaces.trace(rays, skip=1)
        optic.surfaces.surfaces[-1].geometry.cs.localize(rays)
    ours = bundle.result.pos[:, w].reshape(-1, 3).numpy()
    ok = bundle.result.valid[:, w].reshape(-1).numpy()
    dev = max(np.abs(np.asarray(rays.x) - ours[:, 0])[ok].max(), np.abs(np.asarray(rays.y) - ours[:, 1])[ok].max())
    return dev, ours, ok


def test_coordinate_breaks_trace_like_optiland(tmp_path: Path) -> None:
    text = _file()
    result = import_zemax(text)
    spec = result.spec
    dummies = [i for i, s in enumerate(spec.surfaces) if (s.label or "").startswith("COORDBRK")]
    assert len(dummies) == 2
    assert sum("coordinate break imported" in w for w in result.warnings) == 2
    assert spec.surfaces[dummies[0]].decenter == (0.0, 0.2) and spec.surfaces[dummies[0]].tilt_deg == (1.5, 0.0)
    model = build(spec)
    w = model.system.reference
    index = model.lens.index[:, w].tolist()

    path = tmp_path / "cb.zmx"
    path.write_text(text)
    optic = _optiland_optic(path, [n for i, n in enumerate(index) if i == 0 or (i - 1) not in dummies])
    pts = PupilSampling.parse("rings:6:nojitter").points(dtype=torch.float64)
    pts = torch.cat([pts, pts * torch.tensor([-1.0, 1.0], dtype=torch.float64)])
    dev, ours, ok = _intercepts(optic, model, pts)
    assert ok.all()
    assert dev <= 1e-9, f"image intercepts differ by {dev:.3e} mm"
    # The breaks matter: the centred lens lands elsewhere by far more than the tolerance.
    plain = build(import_zemax(LENS1).spec)
    centred = trace_bundle(plain.lens, plain.system, pts).result.pos[:, w].reshape(-1, 3).numpy()
    assert np.abs(centred[:, 1] - ours[:, 1]).max() > 1e-2


def test_unsupported_coordinate_breaks_are_refused() -> None:
    with pytest.raises(SpecError, match="tilt about z"):
        import_zemax(_file().replace("  PARM 5 0\n  PARM 6 0\n  DISZ 0.1", "  PARM 5 3\n  PARM 6 0\n  DISZ 0.1"))
    with pytest.raises(SpecError, match="order flag"):
        import_zemax(_file().replace("  PARM 5 0\n  PARM 6 0\n  DISZ 0.1", "  PARM 5 0\n  PARM 6 1\n  DISZ 0.1"))


def test_basic_decenters_export_as_coordinate_breaks_and_come_back() -> None:
    from lensopt.interchange.zemax.write import export_zemax

    spec = import_zemax(_file()).spec
    text = export_zemax(spec)
    assert text.count("TYPE COORDBRK") == 2
    back = import_zemax(text).spec
    a, b = build(spec), build(back)
    pts = PupilSampling.parse("rings:4:nojitter").points(dtype=torch.float64)
    pa = trace_bundle(a.lens, a.system, pts).result.pos
    pb = trace_bundle(b.lens, b.system, pts).result.pos
    assert float((pa - pb).abs().max()) <= 1e-10


def test_lensopt_notes_stay_with_their_surfaces_after_a_break() -> None:
    from lensopt.interchange.zemax.write import export_zemax
    from lensopt.spec import load_spec

    spec = load_spec(Path(__file__).resolve().parents[2] / "specs" / "cooke_triplet.toml")
    surfaces = list(spec.surfaces)
    surfaces[2] = surfaces[2].model_copy(update={"decenter": (0.0, 0.1), "decenter_mode": "basic"})
    moved = spec.model_copy(update={"surfaces": surfaces})
    back = import_zemax(export_zemax(moved)).spec
    assert len(back.surfaces) == len(spec.surfaces) + 1  # the break's dummy plane
    originals = [s.material for s in spec.surfaces]
    imported = [s.material for s in back.surfaces if not (s.label or "").startswith("COORDBRK")]
    assert imported == originals


@pytest.mark.parametrize("move", [{"decenter": (0.0, 0.1)}, {"tilt_deg": (0.7, 0.0)},
                                  {"decenter": (0.05, -0.1), "tilt_deg": (0.3, -0.4)}])
def test_decenter_and_return_round_trip(move: dict, tmp_path: Path) -> None:
    # Written as Zemax's break pair (order 0, then order flag 1 with negated values) and read back as one
    # decenter-and-return surface: the same lens, every ray within 1e-10 mm.
    from lensopt.interchange.zemax.write import export_zemax
    from lensopt.spec import load_spec

    spec = load_spec(Path(__file__).resolve().parents[2] / "specs" / "cooke_triplet.toml")
    surfaces = list(spec.surfaces)
    surfaces[2] = surfaces[2].model_copy(update=move)  # decenter_mode None: decenter-and-return
    moved = spec.model_copy(update={"surfaces": surfaces})
    text = export_zemax(moved)
    assert text.count("TYPE COORDBRK") == 2 and "PARM 6 1" in text
    result = import_zemax(text)
    back = result.spec
    assert len(back.surfaces) == len(spec.surfaces)
    assert back.surfaces[2].decenter_mode == "return"
    assert sum("decenter-and-return" in w for w in result.warnings) == 1
    a, b = build(moved), build(back)
    pts = PupilSampling.parse("rings:4:nojitter").points(dtype=torch.float64)
    ra, rb = trace_bundle(a.lens, a.system, pts).result, trace_bundle(b.lens, b.system, pts).result
    assert torch.equal(ra.valid, rb.valid)
    assert float((ra.pos - rb.pos)[ra.valid].abs().max()) <= 1e-10
    assert export_zemax(back) == text
    if "tilt_deg" in move and "decenter" in move:
        return  # optiland ignores the order flag: its inverse break is exact only for one kind of motion
    # Independent check: optiland's reading of the same file (its nested coordinate systems).
    path = tmp_path / "return.zmx"
    path.write_text(text)
    optic = _optiland_optic(path, a.lens.index[:, a.system.reference].tolist())
    dev, _, _ = _intercepts(optic, a, torch.cat([pts, pts * torch.tensor([-1.0, 1.0], dtype=torch.float64)]))
    assert dev <= 1e-9, f"image intercepts differ by {dev:.3e} mm"


@pytest.mark.parametrize("move", [{"tilt_deg": (0.5, 0.0)}, {"decenter": (0.0, 0.08)},
                                  {"decenter": (0.03, 0.05), "tilt_deg": (0.2, -0.3)}])
def test_moved_element_round_trip(move: dict, tmp_path: Path) -> None:
    # A rigid element (cooke triplet's middle lens, surfaces 2..3) written as Zemax's element breaks
    # (break, the element with its last gap moved to a −L dummy, inverse break) and read back as the same
    # [[elements]] entry: same rays within 1e-10 mm; for a pure tilt or decenter also against optiland.
    from lensopt.interchange.zemax.write import export_zemax
    from lensopt.spec import load_spec
    from lensopt.spec.models import ElementPlacementSpec

    spec = load_spec(Path(__file__).resolve().parents[2] / "specs" / "cooke_triplet.toml")
    moved = spec.model_copy(update={"elements": [ElementPlacementSpec(surfaces=(2, 3), **move)]})
    text = export_zemax(moved)
    assert text.count("TYPE COORDBRK") == 2
    result = import_zemax(text)
    back = result.spec
    assert len(back.surfaces) == len(spec.surfaces)
    assert back.elements is not None and back.elements[0].surfaces == (2, 3)
    assert sum("element of surfaces 2..3" in w for w in result.warnings) == 1
    a, b = build(moved), build(back)
    pts = PupilSampling.parse("rings:4:nojitter").points(dtype=torch.float64)
    ra, rb = trace_bundle(a.lens, a.system, pts).result, trace_bundle(b.lens, b.system, pts).result
    assert torch.equal(ra.valid, rb.valid)
    assert float((ra.pos - rb.pos)[ra.valid].abs().max()) <= 1e-10
    centred = trace_bundle(build(spec).lens, build(spec).system, pts).result
    assert float((ra.pos - centred.pos)[ra.valid].abs().max()) > 1e-4  # the element really moved
    if "tilt_deg" in move and "decenter" in move:
        return  # optiland ignores the order flag: exact only for one kind of motion
    path = tmp_path / "element.zmx"
    path.write_text(text)
    index = a.lens.index[:, a.system.reference].tolist()
    media = index[:4] + [index[4]] + index[4:]  # the −L dummy after surface 3 sits in surface 3's medium
    optic = _optiland_optic(path, media)
    dev, _, _ = _intercepts(optic, a, torch.cat([pts, pts * torch.tensor([-1.0, 1.0], dtype=torch.float64)]))
    assert dev <= 1e-9, f"image intercepts differ by {dev:.3e} mm"
