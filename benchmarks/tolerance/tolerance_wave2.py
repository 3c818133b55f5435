"""Issue 12, wave 2: two-dimensional fields, chief-ray aiming of placed trials and the PSNR metric on
the C-mount lens (numbers for benchmarks/README.md).

    PYTHONPATH=. OMP_NUM_THREADS=1 python benchmarks/tolerance/tolerance_wave2.py [--trials 100] [--psnr-trials 20] \
        > benchmarks/tolerance/results_tolerance_wave2.json

Prints one JSON object:
- ``fields``: S6.2 + element decenters (±0.02 mm) and tilts (±1 arcmin), back-focus compensator,
  ``trials`` Monte-Carlo trials with ``fields = "y"`` and ``"xy"``: ESR statistics and yields, seconds
  per trial (batched, serial), and how much the −y/±x fields of the decentered trials differ from +y.
- ``aim``: S6.2 + a ±0.05 mm stop decenter in x and y, ``aim = none`` vs ``chief``: ESR statistics,
  yields and seconds per trial.
- ``aim_error``: the chief ray's miss of the stop centre, unaimed and aimed, for the C-mount with its
  stop decentered by (0.03, 0.05) mm and for a Cooke triplet whose first element is tilted 20′ and
  decentered 0.05 mm (and the centred Cooke triplet, whose pupil aberration alone makes the unaimed
  chief ray miss); the full-field chief ray's image position aimed vs unaimed.
- ``timing``: seconds per trial of y vs xy fields and aim none vs chief on the same 50 decentered
  trials, interleaved, fastest of 3 repeats.
- ``psnr``: S6.2 with metric = "psnr" (4 dead-leaves scenes of 64 px, rings:8, pre-restoration),
  nominal, Monte-Carlo statistics and yields, seconds per trial.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import time
from pathlib import Path

import numpy as np
import torch

from lensopt.design.tolerance import tolerance_job
from lensopt.optics.aiming import aim_chief, stop_hit
from lensopt.optics.paraxial import field_tangents, first_order
from lensopt.optics.placement import Placement
from lensopt.optics.sampling import launch
from lensopt.optics.trace import trace
from lensopt.spec import build, load_spec
from lensopt.spec.tolerance import ToleranceSpec
from lensopt.tolerance.job import nominal_metrics, scalar_metric
from lensopt.tolerance.monte_carlo import monte_carlo

ROOT = Path(__file__).resolve().parents[2]
ARCMIN = math.pi / (180 * 60)


def _mc(model, settings: dict, trials: int) -> dict:
    job = tolerance_job(model, ToleranceSpec.model_validate(settings))
    nominal = float(scalar_metric(nominal_metrics(job), job.metric)[0])
    t0 = time.perf_counter()
    mc = monte_carlo(job, trials, 0)
    dt = time.perf_counter() - t0
    yields = {f"{int(100 * y['level'])}%": y["value"] for y in mc.yields}
    return {"nominal": nominal, "stats": mc.stats, "yields": yields,
            "seconds_per_trial": dt / trials, "metrics": mc.metrics}


def fields_study(model, trials: int) -> dict:
    base = {"profile": "s6.2", "items": [{"kind": "element_decenter_x", "limit": 0.02},
                                         {"kind": "element_decenter_y", "limit": 0.02},
                                         {"kind": "element_tilt_x", "limit": 1.0},
                                         {"kind": "element_tilt_y", "limit": 1.0}], "sampling": "rings:12"}
    out = {}
    for f in ("y", "xy"):
        r = _mc(model, {**base, "fields": f}, trials)
        rms = r.pop("metrics")["rms"] * 1e3  # (K, F) µm
        out[f] = r
        if f == "xy":
            # Columns: 0, then (0, h), (0, −h), (h, 0), (−h, 0) per non-zero system field; the full field last.
            full = rms[:, -4:]
            out[f]["full_field_rms_um_mean"] = {k: float(full[:, i].mean()) for i, k in
                                                enumerate(("+y", "-y", "+x", "-x"))}
            out[f]["full_field_max_abs_diff_vs_plus_y_um"] = float(np.abs(full[:, 1:] - full[:, :1]).max())
    return out


def aim_study(model, trials: int) -> dict:
    base = {"profile": "s6.2", "items": [{"kind": "decenter_x", "limit": 0.05, "surfaces": [0]},
                                         {"kind": "decenter_y", "limit": 0.05, "surfaces": [0]}],
            "sampling": "rings:12"}
    out = {}
    for aim in ("none", "chief"):
        r = _mc(model, {**base, "aim": aim}, trials)
        r.pop("metrics")
        out[aim] = r
    return out


def _placed(lens, **kw):
    num = lens.num_surfaces
    zeros = torch.zeros(num, 2, dtype=torch.float64)
    args = {"decenter": zeros, "tilt": zeros.clone(), "basic": (False,) * num, **kw}
    return dataclasses.replace(lens, placement=Placement(**args))


def _aim_case(lens, system) -> dict:
    fo = first_order(lens, system)
    tan = field_tangents(lens, system, torch.tensor([1.0], dtype=torch.float64))
    a = aim_chief(lens, system, tan, epd=fo.epd, entrance_pupil_z=fo.entrance_pupil_z)
    w = system.reference
    res = {}
    for name, (px, py) in {"unaimed": (0.0, 0.0), "aimed": (float(a.offset_x[0, w]), float(a.offset[0, w]))}.items():
        pupil = torch.tensor([[[[px, py]]]], dtype=torch.float64)
        rays = launch(lens, system, pupil, tan, epd=fo.epd, entrance_pupil_z=fo.entrance_pupil_z)
        x, y, _ = stop_hit(lens, rays)
        img = trace(lens, rays).pos[0, w, 0]
        res[name] = {"pupil": [px, py], "stop_miss_mm": [float(x[0, w, 0]), float(y[0, w, 0])],
                     "image_xy_mm": [float(img[0]), float(img[1])]}
    d = np.subtract(res["aimed"]["image_xy_mm"], res["unaimed"]["image_xy_mm"])
    res["image_shift_aimed_vs_unaimed_um"] = float(np.hypot(*d) * 1e3)
    return res


def aim_error() -> dict:
    cm = build(load_spec(ROOT / "lenses" / "cmount_4p.json"))
    dec = torch.zeros(cm.lens.num_surfaces, 2, dtype=torch.float64)
    dec[0] = torch.tensor([0.03, 0.05], dtype=torch.float64)
    ck = build(load_spec(ROOT / "specs" / "cooke_triplet.toml"))
    tilted = _placed(ck.lens, groups=((0, 1),), group_decenter=torch.tensor([[0.05, 0.0]], dtype=torch.float64),
                     group_tilt=torch.tensor([[20 * ARCMIN, 0.0]], dtype=torch.float64))
    return {"cmount_stop_decenter_0.03_0.05": _aim_case(_placed(cm.lens, decenter=dec), cm.system),
            "cooke_nominal": _aim_case(_placed(ck.lens), ck.system),
            "cooke_element0_tilt20arcmin_dec0.05": _aim_case(tilted, ck.system)}


def psnr_study(model, trials: int) -> dict:
    r = _mc(model, {"profile": "s6.2", "metric": "psnr", "sampling": "rings:12"}, trials)
    m = r.pop("metrics")
    r["esr_um_mean"] = float(m["esr"].mean() * 1e3)
    r["corr_psnr_esr"] = float(np.corrcoef(m["psnr_pre"], m["esr"])[0, 1])
    return r


def timing_study(model, trials: int, repeats: int = 3) -> dict:
    """Seconds per trial (serial, batched in chunks of 25), the configurations interleaved and repeated,
    the fastest repeat kept (the machine is shared: load varies between runs)."""
    from lensopt.tolerance.job import run_trials
    from lensopt.tolerance.model import draw

    dec = [{"kind": "element_decenter_x", "limit": 0.02}, {"kind": "element_decenter_y", "limit": 0.02},
           {"kind": "element_tilt_x", "limit": 1.0}, {"kind": "element_tilt_y", "limit": 1.0},
           {"kind": "decenter_x", "limit": 0.05, "surfaces": [0]}, {"kind": "decenter_y", "limit": 0.05,
                                                                     "surfaces": [0]}]
    configs = {"fields=y aim=none": {"fields": "y"}, "fields=xy aim=none": {"fields": "xy"},
               "fields=y aim=chief": {"aim": "chief"}, "fields=xy aim=chief": {"fields": "xy", "aim": "chief"}}
    jobs = {k: tolerance_job(model, ToleranceSpec.model_validate({"profile": "s6.2", "items": dec, **c}))
            for k, c in configs.items()}
    values = draw(list(next(iter(jobs.values())).tols), trials, 0)
    best = {k: math.inf for k in jobs}
    for _ in range(repeats):
        for k, job in jobs.items():
            t0 = time.perf_counter()
            run_trials(job, values)
            best[k] = min(best[k], (time.perf_counter() - t0) / trials)
    return {"trials": trials, "repeats": repeats, "seconds_per_trial": best}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--trials", type=int, default=100)
    ap.add_argument("--psnr-trials", type=int, default=20)
    args = ap.parse_args()
    torch.set_num_threads(1)
    model = build(load_spec(ROOT / "lenses" / "cmount_4p.json"))
    out = {"threads": torch.get_num_threads(), "trials": args.trials, "fields": fields_study(model, args.trials),
           "aim": aim_study(model, args.trials), "aim_error": aim_error(),
           "psnr": psnr_study(model, args.psnr_trials), "timing": timing_study(model, 50)}
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
