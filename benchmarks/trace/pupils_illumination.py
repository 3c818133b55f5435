"""Relative illumination per field: Rimmer's three rays (S51), the all-ray std estimate (S52), and the
flux-counting reference (``analysis.irradiance``: passing pupil area on a large, fine grid over the
image-area Jacobian of the centroids), on the same aimed pupils.

    .venv/bin/python benchmarks/trace/pupils_illumination.py specs/telephoto_plastic.toml --grid 401
    # ~17 min on 2 cores
"""

from __future__ import annotations

import argparse
import time

import torch

from lensopt.analysis.field import field_summary
from lensopt.analysis.irradiance import relative_illumination_flux
from lensopt.optics.sampling import PupilSampling
from lensopt.spec import build, load_spec


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("spec")
    ap.add_argument("--aim", default=None, help="aiming of the S51/S52 bundles (default: the spec's)")
    ap.add_argument("--aim-steps", type=int, default=None)
    ap.add_argument("--sampling", default="rings:32")
    ap.add_argument("--grid", type=int, default=401)
    ap.add_argument("--fields", default=None, help="comma-separated relative fields (default: the spec's)")
    args = ap.parse_args()
    model = build(load_spec(args.spec))
    lens, system = model.lens, model.system
    rel = [float(v) for v in args.fields.split(",")] if args.fields else list(system.rel_field)
    t0 = time.perf_counter()
    s = field_summary(lens, system, PupilSampling.parse(args.sampling), rel_field=rel, aim=args.aim,
                      aim_steps=args.aim_steps)
    t1 = time.perf_counter()
    bf = relative_illumination_flux(lens, system, rel, grid=args.grid)
    t2 = time.perf_counter()
    axis_first = 0 if rel[0] == 0 else 1
    ri_bf = bf.relative_illumination[axis_first:] if rel[0] != 0 else bf.relative_illumination
    mode = args.aim or system.aim
    fa = system.front_aperture
    print(f"### {model.spec.name}: relative illumination (aim {mode}"
          + (f", front aperture {fa.diameter:g} mm at {fa.distance:g} mm, V_l {fa.lateral}" if fa else "") + ")\n")
    print(f"S51/S52: `{args.sampling}` bundle, {s.vignetting.shape[1]} wavelengths; brute force: "
          f"{args.grid}×{args.grid} pupil grid per field and wavelength ({bf.rays_per_field * 3:,} rays per field "
          f"with the two Jacobian neighbours), passing rays on the grid border: {int(bf.edge_hits.sum())}.\n")
    print("| field ° | V_i | V_l | RI S51 | RI S52 | RI brute force | S51 − BF | S52 − BF |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    ref = system.reference
    for h in range(len(rel)):
        a, b, c = float(s.ri_three_ray[h]), float(s.ri_std[h]), float(ri_bf[h])
        v = s.vignetting[h, ref]
        print(f"| {float(s.angle_deg[h]):.3f} | {float(v[0]):.4f} | {float(v[2]):.4f} | {a:.4f} | {b:.4f} | "
              f"{c:.4f} | {a - c:+.4f} | {b - c:+.4f} |")
    print(f"\ntime: S51+S52 {t1 - t0:.1f} s, brute force {t2 - t1:.1f} s")


if __name__ == "__main__":
    torch.set_num_threads(max(1, torch.get_num_threads()))
    main()
