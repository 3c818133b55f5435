"""How the second microscope start (specs/microscope_8p_wd12_alt.toml) was chosen (issue 15, session 22).

1. Glass pairs: for every ordered pair (positive glass, negative glass) of the recommended Ohara glasses that
   lensopt can trace with the vendor's formula, the thin contact doublet of unit power at 550 nm whose power
   varies least over the Table S13 wavelengths (weighted least squares): the weighted standard deviation
   of the relative power (≈ the residual secondary spectrum, as a fraction of the focal length) and the
   positive element's power. Printed: the best pairs under a bound on that power.
2. Paraxial check of the start as written (EFL solve on the last radius applied here by bisection): EFL,
   back focus against the 12 mm working distance, axial focal shift per wavelength, marginal ray heights.

    PYTHONPATH=. python benchmarks/studies/microscope_start.py [LENS.json]

With a lens, also its paraxial axial focal shift per wavelength as written (e.g. lenses/microscope_8p_wd12.json).

Thin-lens and paraxial numbers from the glasses' dispersion formulas; independent of the optimizer.
"""

from __future__ import annotations

import itertools
import math
import sys

import numpy as np
import torch

from lensopt.materials import design_catalog, material_from_name
from lensopt.spec import build, load_spec

WL = np.array([400, 425, 450, 475, 500, 525, 550, 575, 600, 625, 650.0])
W = np.array([0.0550, 0.0676, 0.0827, 0.1000, 0.1094, 0.0895, 0.0725, 0.0788, 0.1363, 0.1122, 0.0960])
W = W / W.sum()
REF = 6  # 550 nm


def indices(name: str) -> np.ndarray:
    if name == "air":
        return np.ones_like(WL)
    return material_from_name(name).index(torch.tensor(WL / 1000, dtype=torch.float64)).numpy()


def glass_pairs() -> list[tuple[float, float, str, str]]:
    n = {}
    for g in design_catalog("ohara-recommended").names:
        try:
            n[g] = indices("ohara:" + g.replace(" ", ""))
        except Exception:  # noqa: BLE001 - a few catalog names have no formula in lensopt's data
            continue
    out = []
    for c, f in itertools.permutations(n, 2):
        g1 = (n[c] - 1) / (n[c][REF] - 1)
        g2 = (n[f] - 1) / (n[f][REF] - 1)
        d = g1 - g2 - (W * (g1 - g2)).sum()
        e = g2 - (W * g2).sum()
        a = -(W * d * e).sum() / (W * d * d).sum()  # power of the positive element (the doublet's is 1)
        if a > 1:
            out.append((math.sqrt((W * (e + a * d) ** 2).sum()), a, c, f))
    return sorted(out)


def paraxial(surfaces: list, wl: int, h0: float) -> tuple[float, float, list[float]]:
    """(EFL, BFL, heights) of a collimated marginal ray (height h0) through (radius, gap after, medium after);
    the medium is a glass name or an array of indices at WL."""
    y, u, n = h0, 0.0, 1.0
    hs = []
    for i, (r, t, m) in enumerate(surfaces):
        n2 = float((indices(m) if isinstance(m, str) else m)[wl])
        u = (n * u - y * (n2 - n) / r) / n2
        n = n2
        hs.append(y)
        if i < len(surfaces) - 1:
            y += t * u
    return -h0 / u, -y / u, hs


def main() -> None:
    pairs = glass_pairs()
    print("thin doublets, relative power spread over Table S13 (best per bound on the positive power):")
    for lim in (2.0, 2.5, 3.0, 4.0):
        for sd, a, c, f in [p for p in pairs if p[1] <= lim][:3]:
            print(f"  power ≤ {lim}: spread {1e6 * sd:6.1f}e-6, positive power {a:.2f}: + {c} / − {f}")
    spec = load_spec("specs/microscope_8p_wd12_alt.toml")
    surfs = []
    for s in spec.surfaces[1:]:  # after the stop (collimated light, so the stop gap does not matter)
        m = s.material if isinstance(s.material, str) else "air"
        surfs.append([s.radius, s.thickness, m])

    def efl(r: float) -> float:
        surfs[-1][0] = r
        return paraxial(surfs, REF, 4.0)[0] - 10.0

    lo, hi = -0.2, -0.02  # curvature bracket of the last surface
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if efl(1 / lo) * efl(1 / mid) <= 0:
            hi = mid
        else:
            lo = mid
    surfs[-1][0] = 1 / (0.5 * (lo + hi))
    f, bfl, hs = paraxial(surfs, REF, 4.0)
    shift = [paraxial(surfs, k, 4.0)[1] - bfl for k in range(len(WL))]
    print(f"start: last radius (EFL solve) {surfs[-1][0]:.3f} mm, EFL {f:.4f} mm, BFL {bfl:.3f} mm (WD 12 mm)")
    print("  axial focal shift µm at " + ", ".join(f"{w:.0f}: {1e3 * s:+.0f}" for w, s in zip(WL, shift, strict=True)))
    print("  marginal ray heights mm: " + " ".join(f"{h:.2f}" for h in hs))


def lens_shift(path: str) -> None:
    spec = load_spec(path)
    model = build(spec)  # the indices as lensopt traces them (model glasses included)
    assert [float(w) for w in spec.spectrum.wavelengths_nm] == WL.tolist()
    index = model.lens.index.detach().numpy()
    surfs = [[s.radius, s.thickness, index[i + 2]] for i, s in enumerate(spec.surfaces[1:])]
    f, bfl, _ = paraxial(surfs, REF, 4.0)
    shift = [paraxial(surfs, k, 4.0)[1] - bfl for k in range(len(WL))]
    mean = sum(w * s for w, s in zip(W, shift, strict=True))
    sd = math.sqrt(sum(w * (s - mean) ** 2 for w, s in zip(W, shift, strict=True)))
    print(f"{path}: EFL {f:.4f} mm, BFL {bfl:.3f} mm; weighted spread of the focal shift {1e3 * sd:.1f} µm")
    print("  axial focal shift µm at " + ", ".join(f"{w:.0f}: {1e3 * s:+.1f}" for w, s in zip(WL, shift, strict=True)))


if __name__ == "__main__":
    main()
    for lens in sys.argv[1:]:
        lens_shift(lens)
