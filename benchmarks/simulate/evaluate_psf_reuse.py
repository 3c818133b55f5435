"""`lensopt evaluate` with and without PSF reuse (issue 10): each PSF stack is computed once per set of
traced fields and each tile's PSF grid once, instead of once per scene (``imaging.simulate.PsfCache``).

C-mount lens, default settings (rings:32, the plan's grid), 256² crops on its 8×8 tiles: the 8 colour
photographs bundled with scikit-image (a small image set: 8 scenes on 8 tiles, little to share) and
100 dead-leaves scenes (seed 0; `evaluate`'s default count: every tile used once or twice). After one
warm-up evaluation (discarded: first-call costs), each set is evaluated without and with reuse,
alternating, REPEATS times, in one process; the scores must be identical (checked here) and the ratio of
the median times is the speed-up. The machine may be loaded: compare the two columns of one run.

    PYTHONPATH=. OMP_NUM_THREADS=1 python benchmarks/simulate/evaluate_psf_reuse.py [REPEATS]

Writes benchmarks/simulate/results_evaluate_psf_reuse.json (atomically) and prints a Markdown table.
"""

from __future__ import annotations

import json
import shutil
import statistics
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


def timed(camera, images: Path | None, count: int, reuse: bool) -> tuple[float, dict]:  # noqa: ANN001
    scenes, names, desc = scene_source(images, count=count, patch=256, seed=0)
    t0 = time.perf_counter()
    ev = evaluate(camera, scenes, names, patch=256, seed=0, options=PlanOptions(), images=desc, reuse_psfs=reuse)
    return time.perf_counter() - t0, ev.as_json()


def main() -> None:
    repeats = int(sys.argv[1]) if len(sys.argv) > 1 else 3
    camera = camera_of(build(load_spec(ROOT / "lenses" / "cmount_4p.json")))
    data = Path(skimage.__file__).parent / "data"
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in PHOTOS:
            shutil.copy(data / name, Path(tmp) / name)
        timed(camera, Path(tmp), 8, False)  # warm-up
        for label, images, count in (("8 scikit-image photographs", Path(tmp), 8),
                                     ("100 dead-leaves scenes", None, 100)):
            walls: dict[bool, list[float]] = {False: [], True: []}
            sims: dict[bool, list[float]] = {False: [], True: []}
            out: dict[bool, dict] = {}
            for _ in range(repeats):
                for reuse in (False, True):
                    wall, ev = timed(camera, images, count, reuse)
                    walls[reuse].append(wall)
                    sims[reuse].append(ev["timings"]["simulation"])
                    out[reuse] = ev
            assert out[True]["items"] == out[False]["items"], "reuse changed a score"
            note = next(n for n in out[True]["notes"] if n.startswith("PSF stacks:"))
            med = {k: statistics.median(v) for k, v in walls.items()}
            med_sim = {k: statistics.median(v) for k, v in sims.items()}
            rows.append({"scenes": label, "count": count, "repeats": repeats, "psnr_db": out[True]["psnr_db"],
                         "identical_scores": True, "psf_stacks": note,
                         "wall_s": {"per_scene": walls[False], "reused": walls[True]},
                         "simulation_s": {"per_scene": sims[False], "reused": sims[True]},
                         "speedup_wall": med[False] / med[True], "speedup_simulation": med_sim[False] / med_sim[True]})
    write_text_atomic(ROOT / "benchmarks" / "simulate" / "results_evaluate_psf_reuse.json",
                      json.dumps(rows, indent=1) + "\n")
    print("| scenes | wall s per scene / reused | × | simulation s per scene / reused | × | PSF stacks |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        w, s = r["wall_s"], r["simulation_s"]
        print(f"| {r['scenes']} | {statistics.median(w['per_scene']):.1f} / {statistics.median(w['reused']):.1f} | "
              f"{r['speedup_wall']:.2f} | {statistics.median(s['per_scene']):.1f} / "
              f"{statistics.median(s['reused']):.1f} | {r['speedup_simulation']:.2f} | {r['psf_stacks']} |")


if __name__ == "__main__":
    main()
