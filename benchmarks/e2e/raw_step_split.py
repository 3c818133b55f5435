"""Time split of one image-driven LM step (specs/cmount_4p_raw.toml, objective "raw"): trace + Jacobian
(forward mode over the trace, every residual term incl. ℓ_GTRA), rendering (spot diagrams → PSFs →
captures → loss, forward), backward (reverse mode of the loss to the spot diagrams), LM solve (damped
least squares), trial evaluation; at batch 4 × 128² and 16 × 256². Best of ``--repeat`` runs.

    PYTHONPATH=$PWD OMP_NUM_THREADS=2 python benchmarks/e2e/raw_step_split.py
    # → benchmarks/e2e/results_raw_step_split.json
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import torch

from lensopt.design import build_problem
from lensopt.imaging.render import mse
from lensopt.optim.lm import damped_step
from lensopt.spec import load_spec

ROOT = Path(__file__).resolve().parents[2]


def split(batch: int, patch: int, repeat: int) -> dict[str, float]:
    spec = load_spec(ROOT / "specs" / "cmount_4p_raw.toml")
    image = spec.optimize.image.model_copy(update={"batch": batch, "patch": patch})
    spec.optimize = spec.optimize.model_copy(update={"image": image})
    p = build_problem(spec, seed=0)
    img = p.image
    theta = p.theta0
    best: dict[str, float] = {}
    for _ in range(repeat):
        t: dict[str, float] = {}
        T = time.perf_counter
        a = T()
        with torch.no_grad():
            lens, _ = p.lens(theta)
            spots = img.spots(lens)
        t["trace (spot diagrams)"] = T() - a
        a = T()
        xy = spots.xy.detach().clone().requires_grad_(True)
        loss = mse(img.render(xy, spots, None, img.images, img.regions), img.images)
        t["rendering (forward)"] = T() - a
        a = T()
        torch.autograd.grad(loss, xy)
        t["backward"] = T() - a
        img.update(lens)  # the GTRA target (same work as the three lines above)
        a = T()
        J, r = p.jacobian(theta)
        t["trace + Jacobian (forward mode)"] = T() - a
        a = T()
        D = torch.linalg.vector_norm(J, dim=0).clamp_min(1e-6)
        delta = damped_step(J, r, D, 1.0)
        t["LM solve"] = T() - a
        a = T()
        p.evaluate(theta + delta)
        t["trial evaluation"] = T() - a
        t["total"] = sum(t.values())
        best = t if not best else {k: min(v, best[k]) for k, v in t.items()}
    best["residual rows"] = float(J.shape[0])
    best["variables"] = float(J.shape[1])
    return best


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "e2e" / "results_raw_step_split.json"))
    args = ap.parse_args()
    load0 = os.getloadavg()
    res = {f"{b}x{p}^2": split(b, p, args.repeat) for b, p in ((4, 128), (16, 256))}
    out = {"threads": torch.get_num_threads(), "load_before": load0, "load_after": os.getloadavg(),
           "note": "loaded shared 2-core machine; best of --repeat", "results": res}
    Path(args.out).write_text(json.dumps(out, indent=1))
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
