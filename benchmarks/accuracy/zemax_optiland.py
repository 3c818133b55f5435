"""Issue 16: the numbers behind the Zemax row of benchmarks/README.md. For every real .zmx file of tests/data/zemax
that lensopt imports: first-order data (EFL, entrance pupil position, back focus, exit pupil, EPD) against
optiland 0.6.3's reader (relative deviation) and lensopt's launched rays traced through optiland's surfaces
(image intercepts, mm), with optiland's media replaced by lensopt's indices at the reference wavelength;
then the same for the coordinate-break file of tests/interchange/test_zemax_coordbrk.py, and the round trip
lensopt → .zmx → lensopt for every lens of specs/ and tests/interchange/data/.

    PYTHONPATH=. python benchmarks/accuracy/zemax_optiland.py
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
warnings.simplefilter("ignore")

from lensopt.interchange.zemax.read import import_zemax  # noqa: E402
from lensopt.interchange.zemax.write import export_zemax  # noqa: E402
from lensopt.optics.bundle import trace_bundle  # noqa: E402
from lensopt.optics.paraxial import first_order  # noqa: E402
from lensopt.optics.sampling import PupilSampling  # noqa: E402
from lensopt.spec import build, load_spec  # noqa: E402
from tests.interchange import test_zemax_coordbrk as cb  # noqa: E402
from tests.interchange import test_zemax_real_files as rf  # noqa: E402


def rays_dev(lens, model, optic) -> tuple[float, int, int]:
    from optiland.rays import RealRays

    w = model.system.reference
    pts = PupilSampling.parse("rings:6:nojitter").points(dtype=torch.float64)
    pts = torch.cat([pts, pts * torch.tensor([-1.0, 1.0], dtype=torch.float64)])
    bundle = trace_bundle(model.lens, model.system, pts)
    pos, d = bundle.rays.pos[:, w], bundle.rays.dir[:, w]
    pos = pos + ((-5.0 - pos[..., 2]) / d[..., 2]).unsqueeze(-1) * d
    P, D = pos.reshape(-1, 3).numpy(), d.reshape(-1, 3).numpy()
    wl = lens.spec.spectrum.wavelengths_nm[w] * 1e-3
    rays = RealRays(P[:, 0], P[:, 1], P[:, 2], D[:, 0], D[:, 1], D[:, 2], np.ones(len(P)), np.full(len(P), wl))
    optic.surface_group.trace(rays, skip=1)
    out = bundle.result.pos[:, w].reshape(-1, 3).numpy()
    ok = bundle.result.valid[:, w].reshape(-1).numpy()
    ok_o = (np.asarray(rays.i) > 0) & np.isfinite(np.asarray(rays.x))
    assert (ok == ok_o).all()
    dev = max(np.abs(np.asarray(rays.x) - out[:, 0])[ok].max(), np.abs(np.asarray(rays.y) - out[:, 1])[ok].max())
    return float(dev), int(ok.sum()), int(ok.size)


def export_check() -> None:
    """Every non-diffractive lens of specs/ exported and read by optiland: EFL/EPD and real rays."""
    import tempfile

    from optiland.fileio import load_zemax_file
    from optiland.materials import IdealMaterial
    from optiland.rays import RealRays

    from lensopt.interchange.zemax.write import write_zemax
    from lensopt.spec.models import DiffractiveSurface

    print("| spec (exported) | EFL rel | EPD rel | same rays stopped | max image Δ (mm) |")
    print("|---|---:|---:|---|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for path in sorted((ROOT / "specs").glob("*.toml")):
            spec = load_spec(path)
            if any(isinstance(s, DiffractiveSurface) for s in spec.surfaces):
                print(f"| {path.name} | (BINARY_2: optiland cannot read it) | | | |")
                continue
            out = Path(tmp) / f"{path.stem}.zmx"
            write_zemax(spec, out)
            model = build(spec)
            fo = first_order(model.lens, model.system)
            w = model.system.reference
            optic = load_zemax_file(str(out))
            for surf, n in zip(optic.surfaces.surfaces[:-1], model.lens.index[:, w].tolist(), strict=True):
                surf.material_post = IdealMaterial(n)
                if hasattr(surf.geometry, "tol"):
                    surf.geometry.tol, surf.geometry.max_iter = 1e-15, 1000
            efl = abs(float(fo.efl) - float(optic.paraxial.f2())) / abs(float(fo.efl))
            epd = abs(float(fo.epd) - float(np.ravel(optic.paraxial.EPD())[0])) / float(fo.epd)
            pts = PupilSampling.parse("rings:4:nojitter").points(dtype=torch.float64)
            pts = torch.cat([pts, pts * torch.tensor([-1.0, 1.0], dtype=torch.float64)])
            bundle = trace_bundle(model.lens, model.system, pts)
            pos, d = bundle.rays.pos[:, w], bundle.rays.dir[:, w]
            skip = 0
            if model.system.object_distance is None:
                pos = pos + ((-5.0 - pos[..., 2]) / d[..., 2]).unsqueeze(-1) * d
                skip = 1
            P, D = pos.reshape(-1, 3).numpy(), d.reshape(-1, 3).numpy()
            rays = RealRays(P[:, 0], P[:, 1], P[:, 2], D[:, 0], D[:, 1], D[:, 2], np.ones(len(P)),
                            np.full(len(P), model.lens.wavelength_um[w].item()))
            optic.surfaces.trace(rays, skip=skip)
            ok = bundle.result.valid[:, w].reshape(-1).numpy()
            ok_o = (np.asarray(rays.i) > 0) & np.isfinite(np.asarray(rays.x))
            ours = bundle.result.pos[:, w].reshape(-1, 3).numpy()
            dev = max(np.abs(np.asarray(rays.x) - ours[:, 0])[ok].max(),
                      np.abs(np.asarray(rays.y) - ours[:, 1])[ok].max())
            print(f"| {path.name} | {efl:.1e} | {epd:.1e} | {bool((ok == ok_o).all())} | {dev:.1e} |")


def main() -> None:
    print("| file | EFL rel | EP rel | BFL rel | XP rel | EPD rel | rays passed | max image Δ (mm) |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for name in sorted(rf.TRACED):
        lens, model, optic = rf._pair(name)
        fo = first_order(model.lens, model.system)
        p = optic.paraxial
        total = float(fo.total_track)

        def rel(a: float, b: float) -> float:
            return abs(a - b) / max(abs(b), 1e-300)

        cols = [rel(float(fo.efl), float(p.f2())), rel(float(fo.entrance_pupil_z), float(p.EPL())),
                rel(float(fo.bfl) - float(fo.image_distance), float(p.F2())),
                rel(float(fo.exit_pupil_z) - total, float(p.XPL()))]
        epd_rel = rel(float(fo.epd), float(np.ravel(p.EPD())[0]))
        epd = "(convention)" if name == "optiland_lens_floa.zmx" else f"{epd_rel:.1e}"
        dev, n_ok, n = rays_dev(lens, model, optic)
        print(f"| {name} | " + " | ".join(f"{c:.1e}" for c in cols) + f" | {epd} | {n_ok}/{n} | {dev:.1e} |")
    # coordinate breaks: rerun the test's comparison (it asserts ≤ 1e-9 mm)
    tmp = Path(ROOT / ".zemax_tmp")
    tmp.mkdir(exist_ok=True)
    try:
        cb.test_coordinate_breaks_trace_like_optiland(tmp)
        print("coordinate-break file: within 1e-9 mm of optiland (tests/interchange/test_zemax_coordbrk.py)")
    finally:
        for f in tmp.iterdir():
            f.unlink()
        tmp.rmdir()
    worst = 0.0
    lenses = sorted((ROOT / "specs").glob("*.toml")) + sorted((ROOT / "tests" / "interchange" / "data").glob("*.toml"))
    pts = PupilSampling.parse("rings:6:nojitter").points(dtype=torch.float64)
    done = 0
    for path in lenses:
        spec = load_spec(path)
        try:
            text = export_zemax(spec)
        except Exception as err:  # noqa: BLE001
            print(f"round trip: {path.name} not exportable: {err}")
            continue
        back = import_zemax(text).spec
        a, b = build(spec), build(back)
        ra, rb = trace_bundle(a.lens, a.system, pts).result, trace_bundle(b.lens, b.system, pts).result
        worst = max(worst, float((ra.pos - rb.pos)[ra.valid].abs().max()))
        done += 1
    print(f"round trip lensopt -> .zmx -> lensopt: {done}/{len(lenses)} lenses, max image Δ {worst:.1e} mm")
    export_check()


if __name__ == "__main__":
    main()
