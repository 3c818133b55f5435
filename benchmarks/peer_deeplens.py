"""DeepLens side of benchmarks/bench_simulate.py: run inside the DeepLens venv (setup_deeplens_venv.sh).

    python peer_deeplens.py ZMX IMAGE.npy {psf_map,render_ours} OUT.json [--grid 5x4] [--ks K] [--spp N]
        [--threads T] [--ours-grid GRID.npy]

``psf_map``: GeoLens.psf_map_rgb (geometric PSF per grid cell centre, R/G/B = 650/550/480 nm) +
imgsim.conv_psf_map (its non-overlapping patch convolution), timed by stage.
``render_ours``: imgsim.conv_psf_map with lensopt's PSF grid (same kernels), to compare the rendering alone.
Prints nothing else; writes timings, peak RSS and the rendered image (as .npy) for comparison.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import types

import numpy as np
import torch

for _name in ("torchvision", "torchvision.utils", "lpips"):  # unused here; no CPU torchvision build exists
    sys.modules.setdefault(_name, types.ModuleType(_name))
sys.modules["torchvision.utils"].save_image = None  # type: ignore[attr-defined]
sys.modules["torchvision.utils"].make_grid = None  # type: ignore[attr-defined]
sys.modules["torchvision"].utils = sys.modules["torchvision.utils"]  # type: ignore[attr-defined]

from deeplens import GeoLens  # noqa: E402
from deeplens.imgsim import conv_psf_map  # noqa: E402
from procmem import peak_rss_mb  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("zmx")
    ap.add_argument("image")
    ap.add_argument("mode", choices=["psf_map", "render_ours"])
    ap.add_argument("out")
    ap.add_argument("--grid", default="5x4")
    ap.add_argument("--ks", type=int, default=31)
    ap.add_argument("--spp", type=int, default=2048)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--ours-grid")
    ap.add_argument("--save-image")
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    gw, gh = (int(v) for v in a.grid.split("x"))
    img = torch.from_numpy(np.load(a.image)).permute(2, 0, 1)[None].contiguous()  # [1, 3, H, W] linear
    t: dict[str, float] = {}
    t0 = time.perf_counter()
    if a.mode == "psf_map":
        lens = GeoLens(filename=a.zmx, device=torch.device("cpu"), dtype=torch.float32)
        h, w = img.shape[-2:]
        lens.set_sensor(sensor_size=(round(w * 0.0072, 6), round(h * 0.0072, 6)), sensor_res=(w, h))
        lens.wvln_rgb = [0.650, 0.550, 0.480]
        t["load lens"] = time.perf_counter() - t0
        t1 = time.perf_counter()
        with torch.no_grad():
            psf_map = lens.psf_map_rgb(grid=(gw, gh), ks=a.ks, spp=a.spp)
        t["PSF map (trace + bin)"] = time.perf_counter() - t1
    else:
        psf_map = torch.from_numpy(np.load(a.ours_grid)).float()
    t2 = time.perf_counter()
    with torch.no_grad():
        out = conv_psf_map(img, psf_map)
    t["convolution"] = time.perf_counter() - t2
    t["total"] = time.perf_counter() - t0
    if a.save_image:
        np.save(a.save_image, out[0].permute(1, 2, 0).numpy())
    rss = peak_rss_mb()
    with open(a.out, "w") as f:
        json.dump({"timings": t, "peak_rss_mb": rss, "psf_map_shape": list(psf_map.shape)}, f)


if __name__ == "__main__":
    main()
