"""lensopt side of benchmarks/bench_simulate.py: one simulation of IMAGE.npy (H, W, 3 linear) through
specs/cooke_triplet.toml on its full 4000 × 3000 sensor, timed by stage, peak RSS recorded.

    .venv/bin/python benchmarks/ours_simulate.py IMAGE.npy OUT.json [--grid 5x4] [--threads T]
        [--effects -diffraction] [--save-grid G.npy] [--save-image I.npy]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch
from procmem import peak_rss_mb

from lensopt.cli.simulate import parse_grid
from lensopt.imaging.plan import PlanOptions, parse_effects
from lensopt.imaging.simulate import plan_scene, run_plan
from lensopt.spec import build, camera_of, load_spec

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("image")
    ap.add_argument("out")
    ap.add_argument("--grid", default="5x4")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--rays", default="rings:32")
    ap.add_argument("--effects", default="-diffraction")
    ap.add_argument("--save-grid")
    ap.add_argument("--save-image")
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    img = np.load(a.image)
    t0 = time.perf_counter()
    model = build(load_spec(ROOT / "specs" / "cooke_triplet.toml"))
    opts = PlanOptions(sampling=a.rays, grid=parse_grid(a.grid))
    h, w, c = img.shape
    timings: dict[str, float] = {"load lens": time.perf_counter() - t0}
    plan, pilot, reg, sensor = plan_scene(camera_of(model), {"width": w, "height": h, "channels": c}, region="full",
                                          effects=parse_effects(a.effects), options=opts, timings=timings)
    with torch.inference_mode():
        res = run_plan(camera_of(model), plan, pilot, reg, sensor, img, opts, timings)
    timings["total"] = time.perf_counter() - t0
    if a.save_grid:
        np.save(a.save_grid, res.psf_grid.numpy())
    if a.save_image:
        np.save(a.save_image, res.image)
    rss = peak_rss_mb()
    Path(a.out).write_text(json.dumps({"timings": timings, "peak_rss_mb": rss,
                                       "psf_grid_shape": list(res.psf_grid.shape),
                                       "fields": len(plan.fields_relative), "plan": plan.as_json()}))


if __name__ == "__main__":
    main()
