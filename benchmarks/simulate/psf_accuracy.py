"""Accuracy vs time of PSF settings and of the PSF grid density.

A. PSFs of specs/cooke_triplet.toml (fields 0, 0.7, 1; 480/550/650 nm; bins = the 7.2 µm sensor pitch; no
   diffraction, to isolate the estimator): rays per PSF × estimator (ray counting, triangular and cosine
   KDE, support 2 or 4 bins), NRMSE (RMSE / peak of the reference, averaged) against a dense reference —
   ray counting with rings:256 (131 072 rays per field and wavelength), i.e. the pixel-integrated
   geometric PSF — and the median time of 5 runs.
B. Grid density: a 1000 × 750 RGB scene (coffee.png mirrored) on the sensor's top-right corner tile of a
   4 × 4 tiling (the fastest-changing region), simulated with PSF grids 1×1 … 8×6 and the plan's own
   choice, against a 16 × 12 grid with 48 traced fields; PSNR of each result against that reference and
   the median wall time of 3 runs (PSFs + grid + convolution).

    .venv/bin/python benchmarks/simulate/psf_accuracy.py [--threads 2] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import numpy as np
import torch

from lensopt.analysis.psf_stack import PsfSettings, compute_psfs
from lensopt.imaging.io import read_image
from lensopt.imaging.plan import PlanOptions, parse_effects
from lensopt.imaging.simulate import plan_scene, run_plan
from lensopt.spec import build, camera_of, load_spec

ROOT = Path(__file__).resolve().parents[2]


def timed(fn, repeats: int):  # type: ignore[no-untyped-def]
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return out, statistics.median(times)


def part_a(model) -> list[dict]:  # type: ignore[no-untyped-def]
    lens, system = model.lens, model.system
    rel = torch.tensor([0.0, 0.7, 1.0], dtype=torch.float64)
    size = 21

    def stack(sampling: str, kernel: str, support: int = 2) -> torch.Tensor:
        with torch.no_grad():
            return compute_psfs(lens, system, rel, PsfSettings(sampling=sampling, kernel=kernel, support=support,
                                                               pitch_mm=7.2e-3, size=size, diffraction="none")).psf

    ref = stack("rings:256", "count")
    rows = []
    for kernel, support in (("count", 2), ("triangular", 2), ("cosine", 2), ("triangular", 4)):
        for n in (4, 8, 16, 32, 64):
            psf, t = timed(lambda n=n, kernel=kernel, support=support: stack(f"rings:{n}", kernel, support), 5)
            err = ((psf - ref) ** 2).mean((-1, -2)).sqrt() / ref.amax((-1, -2))
            rows.append({"kernel": kernel, "support_bins": support, "rays_per_psf": 2 * n * n,
                         "nrmse": float(err.mean()), "time_s": t})
    return rows


def part_b(model) -> list[dict]:  # type: ignore[no-untyped-def]
    img, _ = read_image(ROOT / "lensopt" / "imaging" / "data" / "coffee.png")
    scene = np.pad(img, ((0, 750 - img.shape[0]), (0, 1000 - img.shape[1]), (0, 0)), mode="symmetric")
    h, w, c = scene.shape
    info = {"width": w, "height": h, "channels": c}

    def simulate(grid, fields=None):  # type: ignore[no-untyped-def]
        opts = PlanOptions(sampling="rings:32", grid=grid, fields=fields)
        plan, pilot, reg, sensor = plan_scene(camera_of(model), info, region="tile:3,0/4x4",
                                              effects=parse_effects(None), options=opts)
        with torch.inference_mode():
            return plan, run_plan(camera_of(model), plan, pilot, reg, sensor, scene, opts).image

    _, ref = simulate((16, 12), 48)
    rows = []
    for grid in ((1, 1), (2, 2), (3, 3), (5, 4), (8, 6), None):
        (plan, out), t = timed(lambda grid=grid: simulate(grid), 3)
        mse = float(np.mean((out.astype(np.float64) - ref) ** 2))
        rows.append({"grid": "plan: " + "x".join(map(str, plan.psf_grid)) if grid is None else f"{grid[0]}x{grid[1]}",
                     "fields": len(plan.fields_relative), "psnr_db_vs_16x12": 10 * np.log10(1.0 / mse),
                     "max_abs_diff": float(np.abs(out - ref).max()), "time_s": t})
    return rows


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--json", type=Path, default=ROOT / "benchmarks" / "simulate" / "results_psf_accuracy.json")
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    import os

    model = build(load_spec(ROOT / "specs" / "cooke_triplet.toml"))
    res = {"threads": a.threads, "load_before": os.getloadavg(), "psf_settings": part_a(model),
           "grid_density": part_b(model)}
    res["load_after"] = os.getloadavg()
    print(json.dumps(res, indent=1))
    a.json.write_text(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
