"""Applying a trained restoration network: loading it for a lens with the imaging set-up it was trained
with, restoring a whole capture tile by tile (``lensopt restore``), and the restoration hook of
``imaging.evaluate`` and of the tolerance ``psnr`` metric (``--irm``)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor

from lensopt.checkpoint import CheckpointError
from lensopt.engine import Engine
from lensopt.errors import LensoptError
from lensopt.imaging.camera import SpectrumData
from lensopt.imaging.plan import channel_weights
from lensopt.imaging.scene import Region
from lensopt.restore.capture import ImagingSetup, imaging_setup, lens_psfs, region_grids
from lensopt.restore.checkpoint import load_network
from lensopt.restore.model import ConditionedRestorer, mean_patch_psf

__all__ = ["load_restorer", "restoration_hook", "restore_image", "match_channels"]


def load_restorer(path: Path, model: Any, *, device: torch.device | str = "cpu",
                  option: str = "CKPT", engine: Engine | None = None) -> tuple[ConditionedRestorer, ImagingSetup, int]:
    """The network of a checkpoint for ``model`` (a built lens spec: ``lensopt.spec.Model``), on ``device``,
    with the imaging set-up it was trained with and its tile size (``restore_image``'s ``tile``).

    Refused (one line naming both) unless the network was trained for this lens structure and restores
    the channels of the lens's colour model (``imaging.plan.lens_colour``)."""
    net, ck = load_network(path, model.spec, device=device, option=option)
    im = ck.meta.get("settings", {}).get("imaging", {})
    setup = imaging_setup(model.camera(), patch=16, fields=int(im.get("fields", 9)),
                          sampling=im.get("sampling", "rings:8"), psf_size=int(im.get("psf_size", 31)),
                          grid=tuple(im.get("grid", (3, 3))), engine=engine)
    if net.config.channels != setup.channels:
        raise CheckpointError(f"its network restores {net.config.channels}-channel images, but the lens images in "
                              f"{setup.channels} channels ({setup.colour}); train it again with this lensopt",
                              path=option, got=str(path))
    trained = trained_colour(ck.lens_json, net.config.channels)
    mine = setup.channel_weights.detach().cpu().double().numpy()
    if trained is not None and (trained[0].shape != mine.shape
                                or not np.allclose(trained[0], mine, rtol=0.0, atol=1e-6)):
        raise CheckpointError(f"its network was trained with colour weights {trained[1]}, but the lens images with "
                              f"{setup.colour}; restore through the lens it was trained for, or train it again",
                              path=option, got=str(path))
    return net, setup, int(im.get("patch", 256))


def trained_colour(lens_json: str, channels: int) -> tuple[np.ndarray, str] | None:
    """(W_w, where it came from) of the lens a checkpoint was trained for (its ``lens.json``), in
    ``channels`` channels, by the rule every command images with (``imaging.plan.channel_weights``); None
    when that lens has no spectrum."""
    spectrum = json.loads(lens_json).get("spectrum")
    if not spectrum or not spectrum.get("wavelengths_nm"):
        return None
    data = SpectrumData(tuple(spectrum["wavelengths_nm"]),
                        None if spectrum.get("weights") is None else tuple(spectrum["weights"]),
                        None if spectrum.get("rgb_weights") is None else tuple(map(tuple, spectrum["rgb_weights"])))
    w, _, source = channel_weights(data, channels, list(data.wavelengths_nm))
    return w, source


def match_channels(image: Tensor, channels: int) -> tuple[Tensor, str | None]:
    """``image`` (C, H, W) in ``channels`` channels, and a notice when it was converted (None if not):
    gray (1 channel) → R = G = B; colour → gray as the mean of its channels."""
    c = image.shape[0]
    if c == channels:
        return image, None
    if c == 1:
        return image.expand(channels, -1, -1).contiguous(), (f"a 1-channel (gray) capture: restored as {channels} "
                                                             "equal channels")
    if channels == 1:
        return image.mean(0, keepdim=True), f"a {c}-channel capture: restored as its mean (1 channel)"
    raise LensoptError(f"cannot convert a {c}-channel capture to the network's {channels} channels", path="IMAGE")


def restoration_hook(model: Any, path: Path, *, option: str = "--irm",
                     engine: Engine | None = None) -> Callable[[Tensor, dict[str, Any]], Tensor]:
    """The ``restore`` hook of ``imaging.evaluate`` (and of the tolerance ``psnr`` metric): the checkpoint's
    network restores each capture (1, C, H, W) at its sensor region ``info["region"]`` (``--irm``)."""
    device = model.lens.device
    net, setup, tile = load_restorer(path, model, device=device, option=option, engine=engine)

    def hook(capture: Tensor, info: dict[str, Any]) -> Tensor:
        x, _ = match_channels(capture[0], net.config.channels)
        out = restore_image(net, model.lens, model.system, setup, x.to(device), info["region"], tile=tile)
        back, _ = match_channels(out, capture.shape[1])
        return back[None].cpu()

    return hook


def restore_image(model: ConditionedRestorer, lens: Any, system: Any, setup: ImagingSetup, image: Tensor,
                  region: Any, *, tile: int = 256, margin: int = 32) -> Tensor:
    """Restore a whole capture (C, H, W) covering ``region`` of the sensor: tiles of ``tile`` pixels,
    each restored with ``margin`` pixels of context and the mean PSF of its own sub-tile grid."""
    c, h, w = image.shape
    with torch.no_grad():
        psf, center = lens_psfs(lens, system, setup)
        out = torch.zeros_like(image)
        sx, sy = region.w / region.image_w, region.h / region.image_h
        for y0 in range(0, h, tile):
            for x0 in range(0, w, tile):
                y1, x1 = min(h, y0 + tile), min(w, x0 + tile)
                ya, yb, xa, xb = max(0, y0 - margin), min(h, y1 + margin), max(0, x0 - margin), min(w, x1 + margin)
                sub = Region(region.x0 + xa * sx, region.y0 + ya * sy, (xb - xa) * sx, (yb - ya) * sy, xb - xa, yb - ya,
                             "tile")
                grids = region_grids(psf, center, [sub], setup)
                k = mean_patch_psf(grids.flatten(1, 2)).to(image.device, image.dtype)
                k = _fit_psf(k, min(yb - ya, xb - xa))
                res = model(image[None, :, ya:yb, xa:xb], k)[0]
                out[:, y0:y1, x0:x1] = res[:, y0 - ya:y1 - ya, x0 - xa:x1 - xa]
    return out


def _fit_psf(k: Tensor, side: int) -> Tensor:
    """Crop an odd PSF to at most ``side`` − 1 (odd) pixels so that it fits a small tile; renormalise."""
    n = k.shape[-1]
    m = min(n, side - 1 if side % 2 == 0 else side - 2)
    if m >= n or m < 1:
        return k
    a = (n - m) // 2
    k = k[..., a:a + m, a:a + m]
    return k / k.sum((-2, -1), keepdim=True)
