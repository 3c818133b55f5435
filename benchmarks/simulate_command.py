"""``lensopt simulate`` as a user runs it: a 4000 × 3000 RGB PNG in, a PNG out, the whole process
timed (wall) with its peak RSS, for this tree's CLI without ``--score`` (the default now) and with it
(what every run did before scoring became optional), interleaved in the same run; optionally another
checkout's CLI (``--before``).

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/simulate_command.py --repeats 2 \\
        --json benchmarks/results_simulate_command.json

Scene: coffee.png mirrored to 4000 × 3000 (as benchmarks/bench_simulate.py); lens specs/cooke_triplet.toml
on its full sensor, 5 × 4 PSF grid, diffraction off. DeepLens's whole process is not run here (its venv
needs the network to build); compare with its numbers in the "4000 × 3000 RGB" section of RESULTS.md.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def run(tree: Path, args: list[str]) -> tuple[float, float]:
    """(wall s, peak RSS MB) of ``python -m lensopt simulate …`` with ``tree`` first on the path."""
    env = {**os.environ, "PYTHONPATH": str(tree), "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS", "1")}
    code = "import sys; from lensopt.cli import app; sys.argv[0] = 'lensopt'; app()"
    t0 = time.perf_counter()
    # cwd = the tree: ``python -c`` puts the working directory first on sys.path, before PYTHONPATH.
    proc = subprocess.Popen([sys.executable, "-c", code, "simulate", *args], env=env, cwd=tree,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    err = proc.stderr.read().decode() if proc.stderr else ""
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"simulate failed ({tree}): {err[-2000:]}")
    return wall, usage.ru_maxrss / 1024.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", type=Path, default=None, help="another checkout to run in the same session")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args()
    from lensopt.imaging.io import read_image, write_image

    tmp = Path(tempfile.mkdtemp(prefix="sim_cmd_"))
    img, info = read_image(ROOT / "lensopt" / "imaging" / "data" / "coffee.png")
    big = np.pad(img, ((0, 3000 - img.shape[0]), (0, 4000 - img.shape[1]), (0, 0)), mode="symmetric")
    src = tmp / "scene.png"
    write_image(src, big, info)
    common = [str(ROOT / "specs" / "cooke_triplet.toml"), str(src), "-o", str(tmp / "out.png"), "--region", "full",
              "--grid", "5x4", "--effects", "-diffraction"]
    variants = {"no scoring (the default now)": (ROOT, []),
                "--score (PSNR + SSIM against the input: what every run did before)": (ROOT, ["--score"])}
    if a.before is not None:
        variants = {f"{a.before} (scores by default)": (a.before, []), **variants}
    times: dict[str, list[tuple[float, float]]] = {k: [] for k in variants}
    load0 = os.getloadavg()
    for _ in range(a.repeats):
        for name, (tree, extra) in variants.items():  # interleaved
            times[name].append(run(tree, common + extra))
    load1 = os.getloadavg()
    rows = {k: {"wall_s": statistics.median(w for w, _ in v), "peak_rss_mb": statistics.median(m for _, m in v)}
            for k, v in times.items()}
    print(f"load average before/after: {load0} / {load1}; repeats {a.repeats}\n")
    print("| command | wall s (median) | peak RSS MB |\n| --- | ---: | ---: |")
    for k, r in rows.items():
        print(f"| {k} | {r['wall_s']:.1f} | {r['peak_rss_mb']:.0f} |")
    if a.json:
        from lensopt.io.files import write_text_atomic

        write_text_atomic(a.json, json.dumps({"rows": rows, "load_before": load0, "load_after": load1,
                                              "repeats": a.repeats}, indent=2) + "\n")


if __name__ == "__main__":
    main()
