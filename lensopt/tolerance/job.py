"""A tolerance study (S6.2) and its trials: the ``Job`` (what every trial shares), the scalar metric of a
trial, and trials evaluated in chunks, serially or on Dask.

Every number of a run follows from the seed: the (K, T) table of drawn values is made once, up front,
from the seed; chunks of it are evaluated in any order and on any worker (a Dask ``LocalCluster`` or an
existing scheduler) and put back in trial order, so serial and distributed runs give the same results.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import Tensor

from lensopt.optics.lens import Lens, System
from lensopt.parallel import run_tasks
from lensopt.tolerance.evaluate import EvalSetup, evaluate
from lensopt.tolerance.model import Tolerance, TrialParams, perturb
from lensopt.tolerance.psnr import PsnrSetup, trial_lens, trial_psnr

__all__ = ["Job", "run_trials", "scalar_metric", "HIGHER_IS_BETTER", "nominal_metrics"]

HIGHER_IS_BETTER = {"esr": False, "rms": False, "mtf": True, "distortion": False, "psnr": True}


@dataclass(frozen=True)
class Job:
    """A tolerance study: what every trial shares, the tolerances, and the data ``perturb`` needs.

    Attributes:
        setup: the evaluation setup (lens, system, pupil, compensator, MTF frequency).
        tols: the T tolerances.
        nd: (S+1,) d-line indices of the media (Abbe-number changes).
        semi_aperture: (S,) semi-apertures, mm (fringes).
        metric: the metric of the yield table and the sensitivities: esr, rms, mtf or distortion.
        chunk: trials per vmapped call.
        psnr: imaging of every trial for the ``psnr`` metric (``tolerance.psnr``), or None.
        compiled: run the vmapped evaluation under ``torch.compile`` (one compilation per process and
            chunk size, minutes on a loaded 2-core machine; then ~3× faster per trial at rings:24). The
            last chunk is padded to the chunk size so that it does not compile again.
    """

    setup: EvalSetup
    tols: tuple[Tolerance, ...]
    nd: Tensor
    semi_aperture: Tensor
    metric: str = "esr"
    chunk: int = 25
    compiled: bool = False
    psnr: PsnrSetup | None = None

    @property
    def lens(self) -> Lens:
        return self.setup.lens

    @property
    def system(self) -> System:
        return self.setup.system

    def params(self, values: Tensor) -> TrialParams:
        return perturb(self.lens, list(self.tols), values, nd=self.nd, semi_aperture=self.semi_aperture)


def scalar_metric(out: dict[str, np.ndarray], metric: str) -> np.ndarray:
    """(K,) one number per trial: ESR (µm), worst-field RMS (µm), worst MTF over fields and S/T,
    |distortion| at the full field (%), or PSNR (dB; after restoration when a network is given)."""
    if metric == "esr":
        return out["esr"] * 1e3
    if metric == "rms":
        return out["rms"].max(-1) * 1e3
    if metric == "mtf":
        if "mtf_s" not in out:
            raise ValueError("the mtf metric needs an MTF frequency")
        return np.minimum(out["mtf_s"], out["mtf_t"]).min(-1)
    if metric == "distortion":
        return np.abs(out["distortion"])
    if metric == "psnr":
        if "psnr_pre" not in out:
            raise ValueError("the psnr metric needs the imaging setup (Job.psnr)")
        return out["psnr_post"] if "psnr_post" in out else out["psnr_pre"]
    raise ValueError(f"metric must be one of {tuple(HIGHER_IS_BETTER)}, got {metric!r}")


_COMPILED: dict[int, Any] = {}


def _chunk_eval(job: Job, values: Tensor) -> dict[str, np.ndarray]:
    """Evaluate one chunk (runs on a Dask worker or in-process)."""
    k = values.shape[0]
    with torch.no_grad():
        if job.compiled:
            fn = _COMPILED.get(id(job))
            if fn is None:
                fn = _COMPILED[id(job)] = torch.compile(lambda p: evaluate(job.setup, p))
            if k < job.chunk:  # pad with copies of the last row: same shapes, no recompilation
                values = torch.cat([values, values[-1:].expand(job.chunk - k, -1)])
            out = fn(job.params(values))
        else:
            out = evaluate(job.setup, job.params(values))
    res = {name: v[:k].cpu().numpy() for name, v in out.items()}
    if job.psnr is not None:
        res.update(_chunk_psnr(job, values[:k], res))
    return res


def _chunk_psnr(job: Job, values: Tensor, res: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """PSNR of every trial of a chunk (a loop over trials: image simulation is not batched)."""
    params = job.params(values)
    lenses = [trial_lens(job.lens, job.setup.placement, params.select(slice(i, i + 1)), float(res["focus_shift"][i]),
                         res["lm_offsets"][i] if "lm_offsets" in res else None, job.psnr)
              for i in range(values.shape[0])]
    return trial_psnr(job.psnr, lenses)


def run_trials(job: Job, values: Tensor, *, scheduler: str | None = None, workers: int = 2,
               on_plan: Callable[[str], None] | None = None) -> dict[str, np.ndarray]:
    """Metrics of the trials in ``values`` ((K, T)), chunk by chunk.

    Args:
        scheduler: None (serial, in this process), ``auto`` (serial unless the chunks left after the
            first are worth a cluster, ``lensopt.parallel``), ``local`` (a fresh Dask LocalCluster with
            ``workers`` single-threaded worker processes) or a scheduler address (``tcp://…``).
        on_plan: told in words how the chunks run.
    """
    chunks = [values[i:i + job.chunk] for i in range(0, values.shape[0], job.chunk)]
    parts = run_tasks(_chunk_eval, chunks, shared=job, scheduler=scheduler, workers=workers, on_plan=on_plan)
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def nominal_metrics(job: Job) -> dict[str, np.ndarray]:
    """The nominal lens's metrics with the compensator (one trial of zeros)."""
    return run_trials(job, torch.zeros(1, len(job.tols), dtype=torch.float64))
