"""Pre-restoration image quality of the C-mount lens (`lensopt evaluate`, seed S4.3.1) on two scene sets:
100 procedural dead-leaves scenes (seed 0) and the 8 colour photographs bundled with scikit-image
(astronaut, chelsea, coffee, rocket, motorcycle_left, hubble_deep_field, ihc, retina; all ≥ 256 px).

    PYTHONPATH=. OMP_NUM_THREADS=1 python benchmarks/simulate/evaluate_cmount.py [LENS ...]

Writes benchmarks/simulate/results_evaluate.json (atomically) and prints a Markdown table for benchmarks/README.md.
"""

from __future__ import annotations

import json
import shutil
import sys
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


def run(lens: Path, images: Path | None, count: int) -> dict:
    camera = camera_of(build(load_spec(lens)))
    scenes, names, desc = scene_source(images, count=count, patch=256, seed=0)
    t0 = time.perf_counter()
    ev = evaluate(camera, scenes, names, patch=256, seed=0, options=PlanOptions(), images=desc)
    out = ev.as_json()
    out["wall_s"] = time.perf_counter() - t0
    out["lens_file"] = str(lens.relative_to(ROOT))
    return out


def main() -> None:
    lenses = [Path(p).resolve() for p in sys.argv[1:]] or [ROOT / "lenses" / "cmount_4p.json"]
    data = Path(skimage.__file__).parent / "data"
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in PHOTOS:
            shutil.copy(data / name, Path(tmp) / name)
        for lens in lenses:
            results.append(run(lens, None, 100))
            results.append(run(lens, Path(tmp), 100))  # all 8
    for r in results:
        if "dead-leaves" not in r["images"]:
            r["images"] = f"{r['count']} scikit-image photographs ({', '.join(PHOTOS)})"
    write_text_atomic(ROOT / "benchmarks" / "simulate" / "results_evaluate.json", json.dumps(results, indent=1) + "\n")
    print("| lens | scenes | PSNR dB | SSIM | " + " | ".join(f"ring {i} PSNR" for i in range(4)) + " | wall s |")
    print("|---|---|---|---|" + "---|" * 5)
    for r in results:
        rings = " | ".join("—" if g["psnr_db"] is None else f"{g['psnr_db']:.2f} ({g['count']})" for g in r["rings"])
        print(f"| {r['lens_file']} | {r['images']} | {r['psnr_db']:.2f} | {r['ssim']:.4f} | {rings} | "
              f"{r['wall_s']:.0f} |")


if __name__ == "__main__":
    main()
