"""export-zemax read back by an independent reader: every lens of specs/ written by lensopt and loaded by
optiland 0.6.3's Zemax reader has the same EFL and EPD (≤ 1e-9 relative) and sends lensopt's real rays to the
same image intercepts (≤ 1e-9 mm), with the same rays stopped. optiland's media are replaced by lensopt's
indices at the reference wavelength (geometry and system data are compared, not glass databases).
optiland has no BINARY_2 surface: the diffractive lenses are checked to be refused by it, and are covered
by the closed-form tests of tests/interchange/test_zemax_binary2.py."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

from lensopt.interchange.zemax.write import write_zemax
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.paraxial import first_order
from lensopt.optics.sampling import PupilSampling
from lensopt.spec import build, load_spec
from lensopt.spec.models import DiffractiveSurface

pytest.importorskip("optiland")
import optiland.backend as be  # noqa: E402
from optiland.fileio import load_zemax_file  # noqa: E402
from optiland.materials import IdealMaterial  # noqa: E402
from optiland.rays import RealRays  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
SPECS = sorted((ROOT / "specs").glob("*.toml"))


@pytest.mark.parametrize("path", SPECS, ids=[p.name for p in SPECS])
def test_exported_lens_reads_the_same_in_optiland(path: Path, tmp_path: Path) -> None:
    spec = load_spec(path)
    out = tmp_path / f"{path.stem}.zmx"
    write_zemax(spec, out)
    be.set_precision("float64")
    if any(isinstance(s, DiffractiveSurface) for s in spec.surfaces):
        with pytest.raises(ValueError, match="(?i)binary_2"), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            load_zemax_file(str(out))
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        optic = load_zemax_file(str(out))
    model = build(spec)
    w = model.system.reference
    surfaces = optic.surfaces.surfaces
    index = model.lens.index[:, w].tolist()
    assert len(surfaces) == len(index) + 1
    for surf, n in zip(surfaces[:-1], index, strict=True):
        surf.material_post = IdealMaterial(n)
        if hasattr(surf.geometry, "tol"):  # optiland's default Newton tolerance leaves ~1e-7 mm on aspheres
            surf.geometry.tol, surf.geometry.max_iter = 1e-15, 1000
    fo = first_order(model.lens, model.system)
    assert float(fo.efl) == pytest.approx(float(optic.paraxial.f2()), rel=1e-9)
    assert float(fo.epd) == pytest.approx(float(np.ravel(optic.paraxial.EPD())[0]), rel=1e-9)

    pts = PupilSampling.parse("rings:4:nojitter").points(dtype=torch.float64)
    pts = torch.cat([pts, pts * torch.tensor([-1.0, 1.0], dtype=torch.float64)])
    bundle = trace_bundle(model.lens, model.system, pts)
    pos, d = bundle.rays.pos[:, w], bundle.rays.dir[:, w]
    skip = 0
    if model.system.object_distance is None:  # start on a plane before surface 1, skip the object at infinity
        pos = pos + ((-5.0 - pos[..., 2]) / d[..., 2]).unsqueeze(-1) * d
        skip = 1
    P, D = pos.reshape(-1, 3).numpy(), d.reshape(-1, 3).numpy()
    wl = model.lens.wavelength_um[w].item()
    rays = RealRays(P[:, 0], P[:, 1], P[:, 2], D[:, 0], D[:, 1], D[:, 2], np.ones(len(P)), np.full(len(P), wl))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        optic.surfaces.trace(rays, skip=skip)
    ok = bundle.result.valid[:, w].reshape(-1).numpy()
    ok_o = (np.asarray(rays.i) > 0) & np.isfinite(np.asarray(rays.x))
    assert (ok == ok_o).all()
    ours = bundle.result.pos[:, w].reshape(-1, 3).numpy()
    dev = max(np.abs(np.asarray(rays.x) - ours[:, 0])[ok].max(), np.abs(np.asarray(rays.y) - ours[:, 1])[ok].max())
    assert dev <= 1e-9, f"image intercepts differ by {dev:.3e} mm"
