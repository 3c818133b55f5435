"""DeepLens side of benchmarks/bench_simulate.py: run inside the DeepLens venv (setup_deeplens_venv.sh).

    python peer_deeplens.py ZMX IMAGE.npy {psf_map,render_ours} OUT.json [--grid 5x4] [--ks K] [--spp N]
        [--threads T] [--ours-grid GRID.npy]
    python peer_deeplens.py ZMX IN.png whole OUT.png [--json STAGES.json] [--grid 5x4] [--ks 23] [--spp 2048]

``psf_map``: GeoLens.psf_map_rgb (geometric PSF per grid cell centre, R/G/B = 650/550/480 nm) +
imgsim.conv_psf_map (its non-overlapping patch convolution), timed by stage.
``render_ours``: imgsim.conv_psf_map with lensopt's PSF grid (same kernels), to compare the rendering alone.
``whole``: what a DeepLens user does for this job, as its own ``GeoLens.analysis(render=True)`` →
``analysis_rendering`` path does it: read the 8-bit PNG with PIL (``Image.open(..).convert("RGB")``,
``np.array``), ``torch.from_numpy(..).permute(2, 0, 1).unsqueeze(0).float() / 255``, PSF map
(``psf_map_rgb``), ``conv_psf_map``, and write the PNG as torchvision's ``save_image`` does
(``mul(255).add_(0.5).clamp_(0, 255)`` → uint8 → PIL ``Image.save``, PNG at PIL's default zlib level;
``--writer cv2``: ``cv2.imwrite`` instead, OpenCV's default PNG level 1);
torchvision is not installed here, so those three lines are inlined. No PSNR/SSIM (``lensopt simulate``
does not score by default either). The whole process (Python start and imports included) is timed by the
caller (benchmarks/simulate/simulate_command.py); ``--json`` gets the stage times and VmHWM.
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

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1]))  # benchmarks/: procmem
from procmem import peak_rss_mb  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("zmx")
    ap.add_argument("image")
    ap.add_argument("mode", choices=["psf_map", "render_ours", "whole"])
    ap.add_argument("out")
    ap.add_argument("--grid", default="5x4")
    ap.add_argument("--ks", type=int, default=31)
    ap.add_argument("--spp", type=int, default=2048)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--ours-grid")
    ap.add_argument("--save-image")
    ap.add_argument("--json")
    ap.add_argument("--writer", choices=["pil", "cv2"], default="pil",
                    help="whole: PNG writer (pil = save_image's; cv2 = cv2.imwrite, zlib level 1 by default)")
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    gw, gh = (int(v) for v in a.grid.split("x"))
    if a.mode == "whole":
        whole(a, gw, gh)
        return
    img = torch.from_numpy(np.load(a.image)).permute(2, 0, 1)[None].contiguous()  # [1, 3, H, W] linear
    t: dict[str, float] = {}
    t0 = time.perf_counter()
    if a.mode == "psf_map":
        lens = _lens(a.zmx, img)
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


def _lens(zmx: str, img: torch.Tensor) -> GeoLens:
    """The lens from its .zmx on a sensor of 7.2 µm pixels the size of ``img`` ([1, 3, H, W]), R/G/B at
    650/550/480 nm (the settings of issue 4's comparison)."""
    lens = GeoLens(filename=zmx, device=torch.device("cpu"), dtype=torch.float32)
    h, w = img.shape[-2:]
    lens.set_sensor(sensor_size=(round(w * 0.0072, 6), round(h * 0.0072, 6)), sensor_res=(w, h))
    lens.wvln_rgb = [0.650, 0.550, 0.480]
    return lens


def whole(a: argparse.Namespace, gw: int, gh: int) -> None:
    """PNG in, PNG out, as DeepLens's own rendering example does it (see the module docstring)."""
    from PIL import Image

    t: dict[str, float] = {}
    t0 = time.perf_counter()
    img_org = np.array(Image.open(a.image).convert("RGB"))
    img = torch.from_numpy(img_org).permute(2, 0, 1).unsqueeze(0).float() / 255.0
    del img_org
    t["read image"] = time.perf_counter() - t0
    t1 = time.perf_counter()
    lens = _lens(a.zmx, img)
    t["load lens"] = time.perf_counter() - t1
    t1 = time.perf_counter()
    with torch.no_grad():
        psf_map = lens.psf_map_rgb(grid=(gw, gh), ks=a.ks, spp=a.spp)
        t["PSF map (trace + bin)"] = time.perf_counter() - t1
        t1 = time.perf_counter()
        out = conv_psf_map(img, psf_map)
        t["convolution"] = time.perf_counter() - t1
    del img
    t1 = time.perf_counter()
    # torchvision.utils.save_image(out, path) for one image: make_grid returns it; then these lines.
    ndarr = out[0].mul(255).add_(0.5).clamp_(0, 255).permute(1, 2, 0).to("cpu", torch.uint8).numpy()
    if a.writer == "pil":
        Image.fromarray(ndarr).save(a.out)
    else:  # what a user who wants a fast write might use instead (OpenCV's default PNG level is 1)
        import cv2

        if not cv2.imwrite(a.out, cv2.cvtColor(ndarr, cv2.COLOR_RGB2BGR)):
            raise SystemExit(f"cv2.imwrite failed: {a.out}")
    t["write image"] = time.perf_counter() - t1
    t["in-process total"] = time.perf_counter() - t0
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"timings": t, "peak_rss_mb": peak_rss_mb(), "threads": torch.get_num_threads(),
                       "psf_map_shape": list(psf_map.shape)}, f)


if __name__ == "__main__":
    main()
