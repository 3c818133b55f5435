"""One step of the end-to-end design of a lens and its restoration network (``objective = "restored"``,
S3.3): lens optimization (``optim``) and network training (``restore``) composed.

Each iteration (S3.3.1) draws one minibatch (patches + pseudo-random sensor tiles, as the ``raw``
objective), then

1. lens step, network frozen: the GTRA target (S66–S68) of L = MSE(restore(capture(ε)), scene), where
   the gradient ∇_ε L runs back through the network, the conditioning PSF and the rendering; one
   Levenberg–Marquardt step on ℓ_GTRA + constraints;
2. network step, lens frozen: the captures of the same batch through the updated lens, one Adam step
   on the MAE (cosine learning rate).

Data parallel (``torch.distributed``, launched by torchrun): rank r renders and restores its share of
the batch; the image loss and its gradient w.r.t. ε are averaged over ranks before GTRA (so every rank
builds the same residuals and takes the same LM step, and θ is broadcast from rank 0 to remove any
doubt); the network is a ``DistributedDataParallel`` module (gradients averaged). With equal shares,
this is the single-process run on the combined batch, to rounding.
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Sequence
from typing import Any

import torch
from torch import Tensor, nn

from lensopt.engine import Engine
from lensopt.errors import LensoptError
from lensopt.imaging.camera import Camera
from lensopt.imaging.convolve import overlap_add_convolve
from lensopt.imaging.metrics import psnr_batch, psnr_of_mse, ssim
from lensopt.imaging.render import Spots, psfs_from_spots, weighted_centroid
from lensopt.imaging.scene import Region
from lensopt.optim.gtra import GtraTarget, gtra_target, psf_window
from lensopt.optim.image_objective import ImageObjective
from lensopt.optim.settings import ImageSettings
from lensopt.parallel import Dist
from lensopt.restore.capture import region_grids_for
from lensopt.restore.model import mean_patch_psf
from lensopt.restore.train import cosine_lr, network_step

__all__ = ["RestoredObjective", "joint_step", "evaluate_pair"]


def _seed(*parts: object) -> int:
    return int.from_bytes(hashlib.sha256(":".join(map(str, parts)).encode()).digest()[:8], "little") >> 1


class RestoredObjective(ImageObjective):
    """The ``raw`` image objective with the restoration network after the capture: L is the MSE of the
    restored patches. Noise is drawn per step (seeded by seed and step), PSF grids per patch give both
    the capture and the network's conditioning PSF (mean of the sub-tile PSFs)."""

    def __init__(self, camera: Camera, image: ImageSettings, net: nn.Module, *, dist: Dist | None = None,
                 device: torch.device | str = "cpu", dtype: torch.dtype = torch.float32,
                 engine: Engine | None = None) -> None:
        self.step_index = 0
        self.dist = dist or Dist()
        self.device = torch.device(device)
        self.noise_seed = 0
        super().__init__(camera, image, mode="gtra", dtype=dtype, engine=engine)
        if image.batch % self.dist.world:
            raise LensoptError(f"must be divisible by the number of processes ({self.dist.world})",
                               path="optimize.image.batch", got=image.batch)
        self.net = net

    # the combined batch of the step, then this rank's share
    def set_batch(self, step: int) -> None:
        images, regions = self.batch(step)
        sl = self.dist.share(len(regions))
        self.images, self.regions = images[sl].to(self.device), regions[sl]
        self.noise_seed = _seed("noise", self.spec.seed, step)
        self.noise_offset = sl.start
        self.target = None
        self.step_index = step

    def capture(self, xy: Tensor, spots: Spots, airy: Tensor | None, images: Tensor, regions: Sequence[Region],
                *, noise: bool = True) -> tuple[Tensor, Tensor]:
        """(captures (B, C, H, W), conditioning PSFs (B, C, K, K)) of ``images`` at ``regions`` for ε = ``xy``."""
        psf, center = psfs_from_spots(xy, spots.valid, spots.wavelength_weights, half=spots.half,
                                      pitch_mm=self.sensor.pitch_mm, settings=self.settings, airy=airy)
        grids = region_grids_for(psf, center, list(regions), self.sensor, self.channel_weights,
                                 self.settings).to(images.device, images.dtype)
        cap = torch.stack([overlap_add_convolve(img, g, overlap=self.settings.overlap)
                           for img, g in zip(images, grids, strict=True)])
        if noise and self.settings.noise_sigma > 0:
            z = torch.stack([torch.randn(img.shape, generator=torch.Generator().manual_seed(
                self.noise_seed + self.noise_offset + k), dtype=images.dtype) for k, img in enumerate(images)])
            peak = cap.detach().amax((1, 2, 3), keepdim=True).clamp_min(0.0)
            cap = cap + self.settings.noise_sigma * peak * z.to(images.device)
        return cap, mean_patch_psf(grids.flatten(1, 2))

    def render(self, xy: Tensor, spots: Spots, airy: Tensor | None, images: Tensor, regions: Sequence[Region],
               *, noise: bool = True) -> Tensor:
        cap, k = self.capture(xy, spots, airy, images, regions, noise=noise)
        return self.net(cap, k)

    def update(self, lens: Any) -> GtraTarget:
        """GTRA target (S66) of the restored MSE; with several ranks L and ∇_ε L are averaged first."""
        with torch.no_grad():
            spots = self.spots(lens)
        airy = self._airy(spots, lens)
        e0 = spots.xy.detach()

        def local(xy: Tensor) -> Tensor:
            out = self.render(xy, spots, airy, self.images, self.regions)
            return ((out - self.images) ** 2).mean()

        e = e0.clone().requires_grad_(True)
        with torch.enable_grad():
            loss = local(e)
            (grad,) = torch.autograd.grad(loss, e)
        loss = self.dist.mean(loss.detach().to(device=e0.device, dtype=e0.dtype))
        grad = self.dist.mean(torch.nan_to_num(grad.to(device=e0.device, dtype=e0.dtype)))

        def surrogate(xy: Tensor) -> Tensor:  # value L and gradient ∇L of the whole batch at ε₀, exactly
            return loss + (grad * (xy - e0)).sum()

        center = weighted_centroid(spots.xy, spots.valid, spots.wavelength_weights, spots.half)
        self.target = gtra_target(e0, spots.valid, surrogate,
                                  window=psf_window(center, self.settings.psf_size, self.sensor.pitch_mm))
        return self.target

    def network_batch(self, lens: Any) -> tuple[Tensor, Tensor]:
        """Captures and conditioning PSFs of the current batch through ``lens`` (no gradient)."""
        with torch.no_grad():
            spots = self.spots(lens)
            return self.capture(spots.xy, spots, self._airy(spots, lens), self.images, self.regions)


def joint_step(problem: Any, lm: Any, obj: RestoredObjective, net: nn.Module, adam: torch.optim.Optimizer,
               step: int, total: int, *, lr: float, lr_min: float, dist: Dist | None = None,
               timings: dict[str, float] | None = None) -> dict[str, Any]:
    """One iteration of S3.3.1 (lens LM step, then network Adam step, same batch). Returns a record."""
    dist = dist or Dist()
    t = time.perf_counter
    t0 = t()
    obj.set_batch(step)
    with torch.no_grad():
        lens, _ = problem.lens(lm.theta)
    target = obj.update(lens)
    t1 = t()
    lm.invalidate()
    info = lm.step(problem.row_scale(step / max(total, 1)))
    if dist.active:
        lm.theta = dist.broadcast(lm.theta)
    t2 = t()
    with torch.no_grad():
        lens, _ = problem.lens(lm.theta)
    cap, kpsf = obj.network_batch(lens)
    lr_now = cosine_lr(step, total, lr, lr_min)
    mae = network_step(net, adam, cap, kpsf.to(cap.dtype), obj.images, lr_now)
    mae = float(dist.mean(torch.tensor(mae, dtype=torch.float64)))
    t3 = t()
    if timings is not None:
        for k, v in (("gtra_target", t1 - t0), ("lm_step", t2 - t1), ("network_step", t3 - t2)):
            timings[k] = timings.get(k, 0.0) + v
    return {"step": step + 1, "loss_restored_mse": float(target.loss), "psnr_batch_db": psnr_of_mse(float(target.loss)),
            "merit": info.merit, "damping": info.damping, "accepted": bool(info.accepted), "mae": mae,
            "lr": lr_now, "wall_s": t3 - t0}


def evaluate_pair(obj: RestoredObjective, lens: Any, net: nn.Module, count: int, *, chunk: int = 4,
                  with_ssim: bool = False, examples: dict[str, Tensor] | None = None) -> dict[str, float]:
    """Held-out patches (``obj``'s held-out source and pseudo-random tiles, fixed noise): mean PSNR
    (and SSIM) of the captures and of their restorations."""
    images, regions = obj.batch(-1, held_out=True, size=count)
    images = images.to(obj.device)
    saved = obj.noise_seed, obj.noise_offset
    raw, rest, s_raw, s_rest = [], [], [], []
    with torch.no_grad():
        spots = obj.spots(lens)
        airy = obj._airy(spots, lens)
        for i in range(0, count, chunk):
            obj.noise_seed, obj.noise_offset = _seed("noise", obj.spec.seed, "held-out"), i
            cap, k = obj.capture(spots.xy, spots, airy, images[i:i + chunk], regions[i:i + chunk])
            out = net(cap, k.to(cap.dtype))
            if examples is not None and i == 0:
                examples.update(scene=images[:chunk], capture=cap, restored=out, psf=k)
            raw.append(psnr_batch(images[i:i + chunk], cap))
            rest.append(psnr_batch(images[i:i + chunk], out))
            if with_ssim:
                for a, b, c in zip(images[i:i + chunk], cap, out, strict=True):
                    ref = a.permute(1, 2, 0).cpu().numpy()
                    s_raw.append(ssim(ref, b.clamp(0, 1).permute(1, 2, 0).cpu().numpy()))
                    s_rest.append(ssim(ref, c.clamp(0, 1).permute(1, 2, 0).cpu().numpy()))
    obj.noise_seed, obj.noise_offset = saved
    res = {"psnr_raw": float(torch.cat(raw).mean()), "psnr_restored": float(torch.cat(rest).mean())}
    if with_ssim:
        res["ssim_raw"] = sum(s_raw) / len(s_raw)
        res["ssim_restored"] = sum(s_rest) / len(s_rest)
    return res
