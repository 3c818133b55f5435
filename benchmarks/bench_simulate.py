"""Simulate a 4000 × 3000 RGB image through a 5 × 4 PSF grid (Cooke triplet, full 4000 × 3000 sensor of
7.2 µm pixels, geometric PSFs 2048 rays per PSF and wavelength) with lensopt and with DeepLens 2.5.6
(GeoLens.psf_map_rgb + imgsim.conv_psf_map, the same lens read from a .zmx, the same grid and kernel size),
each run in its own process: wall time per stage and peak RSS, medians of --repeats runs, ratios.

    bash benchmarks/setup_deeplens_venv.sh /tmp/dl-venv     # once
    .venv/bin/python benchmarks/bench_simulate.py [--repeats 3] [--threads 2] [--peer-python /tmp/dl-venv/bin/python]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent


def run_json(cmd: list[str], out: Path, threads: int) -> dict:
    env = dict(os.environ, OMP_NUM_THREADS=str(threads), MKL_NUM_THREADS=str(threads))
    subprocess.run(cmd, check=True, env=env, stdout=subprocess.DEVNULL)
    return json.loads(out.read_text())


def baseline_rss(python: str, code: str) -> float:
    r = subprocess.run([python, "-c", code + "\nprint([int(x.split()[1]) / 1024 for x in open('/proc/self/status') "
                        "if x.startswith('VmHWM:')][0])"], check=True, capture_output=True, text=True)
    return float(r.stdout.strip().splitlines()[-1])


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    a, b = np.clip(a, 0, 1), np.clip(b, 0, 1)
    return float(10 * np.log10(1.0 / np.mean((a.astype(np.float64) - b) ** 2)))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--grid", default="5x4")
    ap.add_argument("--peer-python", default="/tmp/dl-venv/bin/python")
    ap.add_argument("--json", type=Path, default=HERE / "results_simulate.json")
    a = ap.parse_args()
    sys.path.insert(0, str(HERE))
    from cooke_zmx import cooke_zmx

    from lensopt.imaging.io import read_image

    tmp = Path(tempfile.mkdtemp(prefix="bench_sim_"))
    img, _ = read_image(ROOT / "lensopt" / "imaging" / "data" / "coffee.png")
    big = np.pad(img, ((0, 3000 - img.shape[0]), (0, 4000 - img.shape[1]), (0, 0)), mode="symmetric")
    np.save(tmp / "img.npy", big.astype(np.float32))
    (tmp / "cooke.zmx").write_text(cooke_zmx())
    py = sys.executable
    ours, peer, peer_r = [], [], []
    for i in range(a.repeats):
        ours.append(run_json([py, str(HERE / "ours_simulate.py"), str(tmp / "img.npy"), str(tmp / "o.json"),
                              "--grid", a.grid, "--threads", str(a.threads), "--save-grid", str(tmp / "grid.npy"),
                              "--save-image", str(tmp / "ours.npy")], tmp / "o.json", a.threads))
        if Path(a.peer_python).exists():
            ks = ours[-1]["psf_grid_shape"][-1]
            peer.append(run_json([a.peer_python, str(HERE / "peer_deeplens.py"), str(tmp / "cooke.zmx"),
                                  str(tmp / "img.npy"), "psf_map", str(tmp / "p.json"), "--grid", a.grid, "--ks",
                                  str(ks), "--spp", "2048", "--threads", str(a.threads), "--save-image",
                                  str(tmp / "peer.npy")], tmp / "p.json", a.threads))
            peer_r.append(run_json([a.peer_python, str(HERE / "peer_deeplens.py"), str(tmp / "cooke.zmx"),
                                    str(tmp / "img.npy"), "render_ours", str(tmp / "r.json"), "--grid", a.grid,
                                    "--threads", str(a.threads), "--ours-grid", str(tmp / "grid.npy"),
                                    "--save-image", str(tmp / "peer_r.npy")], tmp / "r.json", a.threads))
        print(f"run {i + 1}/{a.repeats} done", file=sys.stderr)

    def med(runs: list[dict], key: str) -> float:
        return statistics.median(r["timings"][key] for r in runs)

    res: dict = {"threads": a.threads, "repeats": a.repeats, "grid": a.grid, "load": os.getloadavg(),
                 "lensopt": {k: med(ours, k) for k in ours[0]["timings"]},
                 "lensopt_peak_rss_mb": statistics.median(r["peak_rss_mb"] for r in ours),
                 "lensopt_fields_traced": ours[0]["fields"], "psf_grid_shape": ours[0]["psf_grid_shape"],
                 "lensopt_baseline_rss_mb": baseline_rss(py, "import torch, numpy, lensopt.imaging.simulate")}
    if peer:
        res["deeplens"] = {k: med(peer, k) for k in peer[0]["timings"]}
        res["deeplens_peak_rss_mb"] = statistics.median(r["peak_rss_mb"] for r in peer)
        res["deeplens_render_our_grid"] = {k: med(peer_r, k) for k in peer_r[0]["timings"]}
        res["deeplens_baseline_rss_mb"] = baseline_rss(a.peer_python, "import sys, types\n"
                                                       "[sys.modules.setdefault(n, types.ModuleType(n)) for n in "
                                                       "('torchvision', 'torchvision.utils', 'lpips')]\n"
                                                       "sys.modules['torchvision.utils'].save_image = None\n"
                                                       "sys.modules['torchvision.utils'].make_grid = None\n"
                                                       "import deeplens")
        res["ratio_total_deeplens_over_lensopt"] = res["deeplens"]["total"] / res["lensopt"]["total"]
        res["ratio_convolution_deeplens_over_lensopt"] = (res["deeplens_render_our_grid"]["convolution"]
                                                          / res["lensopt"]["convolution"])
        o, p, r = (np.load(tmp / f) for f in ("ours.npy", "peer.npy", "peer_r.npy"))
        res["psnr_db lensopt vs deeplens(our grid)"] = psnr(o, r)
        res["psnr_db lensopt vs deeplens(own PSF map)"] = psnr(o, p)
        res["psnr_db input vs lensopt"] = psnr(big, o)
    print(json.dumps(res, indent=1))
    a.json.write_text(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
