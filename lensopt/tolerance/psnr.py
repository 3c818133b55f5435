"""PSNR before and after restoration as a tolerance metric (S6.2's figure; ``metric = "psnr"``).

Every trial lens is imaged through ``lensopt evaluate``'s path (``imaging.evaluate``: a small fixed set
of seeded dead-leaves scenes, each on its sensor tile, ``lensopt simulate``'s PSF grid and convolution,
optional noise) and scored with PSNR on sRGB-encoded values; with a restoration network (``restore``,
e.g. ``--irm CKPT``) each capture is also restored and scored again. The network is the nominal design's:
it does not know the trial's errors (what a manufactured camera would run).

Compensators: the trial is imaged with its compensators applied *relative to the nominal lens* — the
back focus moves by the trial's best-focus change Δz_k − Δz_0 (the closed-form ESR refocus of
``tolerance.evaluate`` for the trial minus that of the nominal lens), LM offsets likewise — so the
nominal lens is imaged exactly as designed and its PSNR equals ``lensopt evaluate``'s.

This is a per-trial loop (image simulation is not batched over trials): seconds per trial. The imaging
path assumes a rotationally symmetric lens (PSFs along +y, turned to each tile's azimuth), so decenter
and tilt tolerances are refused with this metric.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import Tensor

from lensopt.engine import Engine
from lensopt.imaging.camera import Camera
from lensopt.imaging.evaluate import evaluate as evaluate_images
from lensopt.imaging.evaluate import scene_source
from lensopt.imaging.plan import PlanOptions
from lensopt.optics.lens import Lens
from lensopt.tolerance.model import TrialParams, params_lens

__all__ = ["PsnrSetup", "trial_lens", "trial_psnr", "psnr_failure"]

Restore = Callable[[Tensor, dict[str, Any]], Tensor]


@dataclass(frozen=True)
class PsnrSetup:
    """How trials are imaged.

    Attributes:
        camera: the nominal camera (lens, system, spectrum, sensor).
        count: dead-leaves scenes (seeded by ``seed``), each ``patch`` × ``patch`` pixels.
        seed: scenes, scene ↔ tile pairing, noise and pupil jitter (as ``lensopt evaluate --seed``).
        sampling: pupil sampling per PSF (``evaluate --rays``).
        noise_sigma: additive Gaussian noise, fraction of the maximum.
        restore: the restoration hook of ``imaging.evaluate`` (None: pre-restoration only).
        focus_reference: the nominal lens's compensator focus shift Δz_0, mm.
        lm_reference: the nominal lens's LM offsets (V,), or None.
        lm_vars: the LM compensators (kind, surface), as in ``EvalSetup``.
        engine: trace backend and memory budget of the imaging (default ``Engine()``).
    """

    camera: Camera
    count: int = 4
    patch: int = 64
    seed: int = 0
    sampling: str = "rings:8"
    noise_sigma: float = 0.0
    restore: Restore | None = None
    focus_reference: float = 0.0
    lm_reference: tuple[float, ...] | None = None
    lm_vars: tuple[tuple[str, int], ...] = ()
    engine: Engine | None = None

    def evaluate_kwargs(self) -> dict[str, Any]:
        """The settings of ``imaging.evaluate`` (those of ``lensopt evaluate --count --patch --rays --noise
        --seed`` with the default kernel and rings)."""
        return {"patch": self.patch, "seed": self.seed, "noise_sigma": self.noise_sigma,
                "options": PlanOptions(sampling=self.sampling, seed=self.seed), "engine": self.engine}


def trial_lens(lens: Lens, placement: Any, params: TrialParams, focus_shift: float,
               lm_offsets: np.ndarray | None = None, setup: PsnrSetup | None = None) -> Lens:
    """One trial's lens (``params`` with K = 1) with its compensators applied relative to the nominal
    (see the module docstring)."""
    p = {f.name: getattr(params, f.name)[0] for f in dataclasses.fields(params)}
    curv, thick = p["curvature"].clone(), p["thickness"].clone()
    if setup is not None and lm_offsets is not None and setup.lm_vars:
        ref = setup.lm_reference or (0.0,) * len(setup.lm_vars)
        for v, (kind, s) in enumerate(setup.lm_vars):
            target = curv if kind == "curvature" else thick
            target[s] = target[s] + float(lm_offsets[v]) - ref[v]
    ref_dz = setup.focus_reference if setup is not None else 0.0
    thick[-1] = thick[-1] + (focus_shift - ref_dz)
    return params_lens(lens, placement, {**p, "curvature": curv, "thickness": thick})


def trial_psnr(setup: PsnrSetup, lenses: list[Lens]) -> dict[str, np.ndarray]:
    """(K,) ``psnr_pre`` (dB) and, with a restoration hook, ``psnr_post`` of each lens.

    A trial whose simulation fails (e.g. every ray of a field lost) scores −inf (the worst; never NaN;
    ``psnr_failure`` says why). An error of the restoration hook is not a bad trial but a network that does
    not fit the lens: it is raised.
    """
    scenes, names, desc = scene_source(None, count=setup.count, patch=setup.patch, seed=setup.seed)
    kw = setup.evaluate_kwargs()
    pre, post = [], []
    for lens in lenses:
        camera = dataclasses.replace(setup.camera, lens=lens)
        captures: dict[int, Tensor] = {}
        hook = None
        if setup.restore is not None:
            def hook(capture: Tensor, info: dict[str, Any], _c: dict[int, Tensor] = captures) -> Tensor:
                _c[int(info["index"])] = capture.clone()
                try:
                    return setup.restore(capture, info)
                except Exception as err:
                    raise _HookError(err) from err
        try:
            with torch.no_grad():
                ev = evaluate_images(camera, scenes, names, images=desc, restore=hook, **kw)
        except _HookError as err:
            raise err.error from None
        except Exception:  # noqa: BLE001 — a broken trial lens is a bad trial, not a crashed run
            pre.append(-math.inf)
            post.append(-math.inf)
            continue
        if setup.restore is None:
            pre.append(ev.psnr_db)
            continue
        post.append(ev.psnr_db)
        pre.append(_pre_from_captures(scenes, captures, len(names)))
    out = {"psnr_pre": np.asarray(pre, dtype=np.float64)}
    if setup.restore is not None:
        out["psnr_post"] = np.asarray(post, dtype=np.float64)
    return out


class _HookError(Exception):
    """An error of the restoration hook (carried through ``imaging.evaluate`` to be raised as is)."""

    def __init__(self, error: Exception) -> None:
        super().__init__(str(error))
        self.error = error


def psnr_failure(setup: PsnrSetup, lens: Lens) -> str | None:
    """Why ``lens`` cannot be imaged for the psnr metric (its error, one line), or None if it can: what
    ``trial_psnr`` scores as −inf, explained (run again, so only when a score is not finite)."""
    scenes, names, desc = scene_source(None, count=setup.count, patch=setup.patch, seed=setup.seed)
    camera = dataclasses.replace(setup.camera, lens=lens)
    try:
        with torch.no_grad():
            evaluate_images(camera, scenes, names, images=desc, restore=setup.restore, **setup.evaluate_kwargs())
    except Exception as err:  # noqa: BLE001 — the reason is the message
        return (str(err).strip().splitlines() or [type(err).__name__])[0]
    return None


def _pre_from_captures(scenes: Callable[[int], Tensor], captures: dict[int, Tensor], count: int) -> float:
    """Mean pre-restoration PSNR of the captures the restoration hook saw (``imaging.evaluate``'s own
    scoring: sRGB-encoded scene against sRGB-encoded capture), so that each trial is simulated once."""
    from lensopt.imaging.io import linear_to_srgb
    from lensopt.imaging.metrics import psnr

    scores = []
    for k in range(count):
        ref = linear_to_srgb(scenes(k).to(torch.float32).permute(1, 2, 0).contiguous().numpy())
        out = linear_to_srgb(captures[k][0].permute(1, 2, 0).numpy())
        scores.append(psnr(ref, out))
    return float(np.mean(scores))
