"""Front-aperture vignetting factors (S1.3.2, S4.1.5) against brute force, every field.

Brute force: the lens behind a real clipping plane of the aperture's diameter at its distance (a dummy
first surface; the lens follows at −d), a dense cell-centred grid over the whole entrance pupil (and,
with full aiming, a clipping stop at the radius of the axial beam and a grid of ±1.3 pupil radii),
traced up to the last aperture; the extents of the pupil points whose rays pass are compared with the
factors lensopt launches with. Differences in % of the pupil radius.

    .venv/bin/python benchmarks/trace/pupils_vignetting.py specs/telephoto_plastic.toml --grid 1001
"""

from __future__ import annotations

import argparse
import copy
import time
import tomllib
from pathlib import Path

import torch

from lensopt.optics.bundle import trace_bundle
from lensopt.optics.paraxial import field_tangents, first_order
from lensopt.optics.sampling import launch, pupil_grid
from lensopt.optics.trace import trace
from lensopt.spec import build, parse_spec

F64 = torch.float64


def lens_data(path: str, lateral: str, aim: str, steps: int) -> dict:
    data = tomllib.loads(Path(path).read_text())
    ref = data["spectrum"].get("reference_nm", data["spectrum"]["wavelengths_nm"][0])
    data["spectrum"] = {"wavelengths_nm": [ref]}  # the aperture's geometry does not depend on λ
    data["system"].update(aim=aim, aim_steps=steps)
    data["system"]["front_aperture"]["lateral"] = lateral
    return data


def kept_extents(data: dict, grid: int, half: float, centres: torch.Tensor, stop_radius: float | None) -> torch.Tensor:
    d = copy.deepcopy(data)
    fa = d["system"].pop("front_aperture")
    d["system"]["aim"] = "none"
    d["surfaces"].insert(0, {"type": "plane", "thickness": -fa["distance"], "clip": True,
                             "semi_diameter": fa["diameter"] / 2 * (1 + 1e-9)})
    if stop_radius is not None:
        next(s for s in d["surfaces"] if s.get("stop")).update(semi_diameter=stop_radius, clip=True)
    m = build(parse_spec(d))
    fo = first_order(m.lens, m.system)
    g = pupil_grid(grid, dtype=F64) * half
    out = []
    for h, rel in enumerate(m.system.rel_field):
        pts = (g + torch.tensor([0.0, float(centres[h])], dtype=F64)).view(1, 1, -1, 2)
        tan = field_tangents(m.lens, m.system, torch.tensor([rel], dtype=F64))
        rays = launch(m.lens, m.system, pts, tan, epd=fo.epd, entrance_pupil_z=fo.entrance_pupil_z)
        keep = trace(m.lens, rays, upto=m.lens.stop if stop_radius is not None else 0).valid[0, 0]
        p = pts[0, 0][keep]
        out.append(torch.stack([p[:, 1].min(), p[:, 1].max(), p[:, 0].abs().max()]))
    return torch.stack(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("spec")
    ap.add_argument("--grid", type=int, default=1001)
    ap.add_argument("--aim-steps", type=int, default=3)
    args = ap.parse_args()
    if "front_aperture" not in tomllib.loads(Path(args.spec).read_text())["system"]:
        ap.error(f"{args.spec} has no system.front_aperture: nothing to compare")
    for aim in ("none", "full"):
        half = 1.0 if aim == "none" else 1.3
        t0 = time.perf_counter()
        res = {}
        for lateral in ("extent", "inscribed"):
            data = lens_data(args.spec, lateral, aim, args.aim_steps)
            m = build(parse_spec(data))
            with torch.no_grad():
                b = trace_bundle(m.lens, m.system, torch.zeros(1, 2, dtype=F64))
            res[lateral] = (b.vignetting[:, 0], b)
        v_ext, b = res["extent"]
        v_ins = res["inscribed"][0]
        r = float(b.pupil_aim.stop_radius_mm) if aim == "full" else None
        centres = 0.5 * (v_ext[:, 0] - v_ext[:, 1]) if aim == "full" else torch.zeros(v_ext.shape[0], dtype=F64)
        with torch.no_grad():
            kept = kept_extents(lens_data(args.spec, "extent", aim, args.aim_steps), args.grid, half, centres, r)
        dt = time.perf_counter() - t0
        cell = 2 * half / args.grid
        print(f"#### aim {aim}" + (f" ({args.aim_steps} steps, stop radius {r:.6f} mm)" if r else "")
              + f": {args.grid}×{args.grid} grid over ±{half:g} pupil radii (cell {100 * cell:.3f} %), {dt:.0f} s\n")
        print("| field ° | V_i | 1 + y_min (BF) | Δ % | V_s | 1 − y_max (BF) | Δ % | V_l extent | 1 − x_max (BF) "
              "| Δ % | V_l inscribed |")
        print("|---:|" + "---:|" * 10)
        for h in range(v_ext.shape[0]):
            vi, vs, vl = (float(x) for x in v_ext[h])
            bi, bs, bl = 1 + float(kept[h, 0]), 1 - float(kept[h, 1]), 1 - float(kept[h, 2])
            ang = float(torch.rad2deg(torch.atan(b.tan_field[h])))
            print(f"| {ang:.3f} | {vi:.4f} | {bi:.4f} | {100 * (vi - bi):+.3f} | {vs:.4f} | {bs:.4f} | "
                  f"{100 * (vs - bs):+.3f} | {vl:.4f} | {bl:.4f} | {100 * (vl - bl):+.3f} | {float(v_ins[h, 2]):.4f} |")
        print()


if __name__ == "__main__":
    main()
