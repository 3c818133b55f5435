"""Held-out raw image quality (`lensopt evaluate`'s method, seed S4.3.1) of the spot-optimized C-mount lens
and of the raw-image-quality lens optimized from it (benchmarks/e2e/run_cmount_raw.py): 100 procedural
dead-leaves scenes (seed 0; the run trained on other dead-leaves scenes) and the 8 colour photographs
bundled with scikit-image (never seen in training).

    PYTHONPATH=. OMP_NUM_THREADS=1 python benchmarks/e2e/evaluate_cmount_raw.py
    # → benchmarks/e2e/results_evaluate_cmount_raw.json, a Markdown table on stdout
"""

from __future__ import annotations

import json
import shutil
import tempfile
import time
from pathlib import Path

import skimage

from lensopt.files import write_text_atomic
from lensopt.imaging.evaluate import evaluate, scene_source
from lensopt.imaging.plan import PlanOptions
from lensopt.spec import build, camera_of, load_spec

ROOT = Path(__file__).resolve().parents[2]
PHOTOS = ["astronaut.png", "chelsea.png", "coffee.png", "rocket.jpg", "motorcycle_left.png",
          "hubble_deep_field.jpg", "ihc.png", "retina.jpg"]
LENSES = ["lenses/cmount_4p.json", "lenses/cmount_4p_raw.json"]


def run(lens: str, images: Path | None, count: int) -> dict:
    camera = camera_of(build(load_spec(ROOT / lens)))
    scenes, names, desc = scene_source(images, count=count, patch=256, seed=0)
    t0 = time.perf_counter()
    out = evaluate(camera, scenes, names, patch=256, seed=0, options=PlanOptions(), images=desc).as_json()
    out["wall_s"] = time.perf_counter() - t0
    out["lens_file"] = lens
    return out


def main() -> None:
    data = Path(skimage.__file__).parent / "data"
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in PHOTOS:
            shutil.copy(data / name, Path(tmp) / name)
        for lens in LENSES:
            results.append(run(lens, None, 100))
            r = run(lens, Path(tmp), 100)
            r["images"] = f"{r['count']} scikit-image photographs"
            results.append(r)
    write_text_atomic(ROOT / "benchmarks" / "e2e" / "results_evaluate_cmount_raw.json",
                      json.dumps(results, indent=1) + "\n")
    print("| lens | scenes | PSNR dB | SSIM | " + " | ".join(f"ring {i}" for i in range(4)) + " | wall s |")
    print("|---|---|---:|---:|" + "---:|" * 5)
    for r in results:
        rings = " | ".join("—" if g["psnr_db"] is None else f"{g['psnr_db']:.2f} ({g['count']})" for g in r["rings"])
        print(f"| {r['lens_file']} | {r['images']} | {r['psnr_db']:.3f} | {r['ssim']:.4f} | {rings} | "
              f"{r['wall_s']:.0f} |")


if __name__ == "__main__":
    main()
