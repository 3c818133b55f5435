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
from lensopt.io.zemax_import import import_zemax
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
    be.set_precision("float64")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        optic = ZemaxToOpticConverter(ZemaxDataParser(str(path)).parse()).convert()
    surfaces = optic.surfaces.surfaces
    media = [n for i, n in enumerate(index) if i == 0 or (i - 1) not in dummies]
    assert len(surfaces) == len(media) + 1
    for surf, n in zip(surfaces[:-1], media, strict=True):
        surf.material_post = IdealMaterial(n)

    pts = PupilSampling.parse("rings:6:nojitter").points(dtype=torch.float64)
    pts = torch.cat([pts, pts * torch.tensor([-1.0, 1.0], dtype=torch.float64)])
    bundle = trace_bundle(model.lens, model.system, pts)
    pos, d = bundle.rays.pos[:, w], bundle.rays.dir[:, w]
    pos = pos + ((-5.0 - pos[..., 2]) / d[..., 2]).unsqueeze(-1) * d
    P, D = pos.reshape(-1, 3).numpy(), d.reshape(-1, 3).numpy()
    wl = spec.spectrum.wavelengths_nm[w] * 1e-3
    rays = RealRays(P[:, 0], P[:, 1], P[:, 2], D[:, 0], D[:, 1], D[:, 2], np.ones(len(P)), np.full(len(P), wl))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        optic.surfaces.trace(rays, skip=1)
        surfaces[-1].geometry.cs.localize(rays)  # image intercepts in the image surface's own frame
    ours = bundle.result.pos[:, w].reshape(-1, 3).numpy()
    ok = bundle.result.valid[:, w].reshape(-1).numpy()
    assert ok.all()
    dev = max(np.abs(np.asarray(rays.x) - ours[:, 0]).max(), np.abs(np.asarray(rays.y) - ours[:, 1]).max())
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
    from lensopt.io.zemax_export import export_zemax

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
    from lensopt.io.zemax_export import export_zemax
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
