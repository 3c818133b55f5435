"""Time split and peak memory of one joint (lens + network) step, objective = "restored" (S3.3.1).

    PYTHONPATH=. OMP_NUM_THREADS=2 python benchmarks/e2e/joint_step.py --batch 16 --patch 256 \
        --out benchmarks/e2e/results_joint_step_16x256.json --key cpu_2_threads
    PYTHONPATH=. python benchmarks/e2e/joint_step.py --batch 16 --patch 256 --repeat 3 --device cuda \
        --out benchmarks/e2e/results_joint_step_16x256.json --key cuda

Lens: the C-mount 4P of lenses/cmount_4p.json with an RGB split of its camera spectrum (see
``cmount_rgb_data``), radii and thicknesses varying, glasses fixed. Network: the seed's default
(width 16, encoder [1,1,1,4], one middle block, decoder [1,1,1,1]). Each part is timed on its own
(median of --repeat runs) and one whole ``joint_step`` is timed as well; peak memory is the process's
VmHWM (Linux), which includes Python and torch themselves (the baseline after set-up is reported too).
"""

# ruff: noqa: B023  (the lambdas are called at once, inside the loop iteration that defines them)
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: procmem
from procmem import peak_rss_mb, vm_kb  # noqa: E402

from lensopt.design import build_problem  # noqa: E402
from lensopt.design.joint import RestoredObjective, joint_step  # noqa: E402
from lensopt.optim.lm import LevenbergMarquardt, Trial, damped_step  # noqa: E402
from lensopt.restore import ConditionedRestorer, RestoreConfig  # noqa: E402
from lensopt.restore.config import TrainConfig  # noqa: E402
from lensopt.restore.train import network_optimizer, network_step  # noqa: E402
from lensopt.spec import parse_spec  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
# Hard split of the camera spectrum (Figure S35 weights of the spec) into R, G, B channels by wavelength
# (B < 490 nm ≤ G < 590 nm ≤ R): an approximation of the Bayer filters, which overlap in reality.
BOUNDS_NM = (490.0, 590.0)


def cmount_rgb_data(lens: Path = ROOT / "lenses" / "cmount_4p.json") -> dict:
    data = json.loads(lens.read_text())
    wl, w = data["spectrum"]["wavelengths_nm"], data["spectrum"]["weights"]
    cols = [[0.0] * len(wl) for _ in range(3)]  # R, G, B
    for i, (lam, wi) in enumerate(zip(wl, w, strict=True)):
        cols[0 if lam >= BOUNDS_NM[1] else (1 if lam >= BOUNDS_NM[0] else 2)][i] = wi
    cols = [[v / sum(c) for v in c] for c in cols]
    data["spectrum"]["rgb_weights"] = [[cols[c][i] for c in range(3)] for i in range(len(wl))]
    for s in data["surfaces"]:
        s["vary"] = [v for v in s.get("vary", []) if v != "material"]
    return data


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--batch", type=int, default=16)
    ap.add_argument("--patch", type=int, default=256)
    ap.add_argument("--psf-size", type=int, default=31)
    ap.add_argument("--fields", type=int, default=9)
    ap.add_argument("--sampling", default="rings:8")
    ap.add_argument("--opt-sampling", default="rings:4", help="[optimize] sampling (constraint rays)")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", type=Path)
    ap.add_argument("--key", help="store the result under this key of --out, keeping the file's other runs")
    ap.add_argument("--parts-only", action="store_true", help="no warm-up and no whole joint step (large sizes)")
    ap.add_argument("--device", default="cpu", help="where the network, patches and rendering live (the lens "
                    "problem stays on the CPU in float64, as `lensopt optimize --device` runs it)")
    a = ap.parse_args()
    data = cmount_rgb_data()
    data["optimize"] = {**data.get("optimize", {}), "objective": "restored", "sampling": a.opt_sampling,
                        "sampling_after_binding": None,
                        "image": {"patch": a.patch, "batch": a.batch, "psf_size": a.psf_size, "fields": a.fields,
                                  "sampling": a.sampling}}
    spec = parse_spec(data)
    problem = build_problem(spec, method="lm")
    torch.manual_seed(0)
    dev = torch.device(a.device)
    net = ConditionedRestorer(RestoreConfig()).to(dev)
    obj = RestoredObjective(problem.setup.camera, problem.opt.image, net, device=dev)
    problem.image = obj
    cfg = TrainConfig()
    adam = network_optimizer(net, cfg)

    def evaluate(t: torch.Tensor) -> Trial:
        ev = problem.evaluate(t)
        return Trial(ev.residuals, ev.physical, ev.reason)

    lm = LevenbergMarquardt(problem.theta0, problem.jacobian, evaluate, problem.opt.lm)
    base_mb = vm_kb("VmRSS") / 1024
    # one warm-up joint step (allocations, first-call costs), then the parts one by one
    if not a.parts_only:
        joint_step(problem, lm, obj, net, adam, 0, 10, lr=cfg.lr, lr_min=0.0)
    times: dict[str, list[float]] = {}
    cpu: dict[str, list[float]] = {}

    def sync() -> None:
        if dev.type == "cuda":
            torch.cuda.synchronize(dev)

    def timed(name: str, fn):  # noqa: ANN001, ANN202
        sync()
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        sync()
        times.setdefault(name, []).append(time.perf_counter() - t0)
        cpu.setdefault(name, []).append(time.process_time() - c0)
        print(f"{name}: wall {times[name][-1]:.2f} s, CPU {cpu[name][-1]:.2f} s, peak RSS {peak_rss_mb():.0f} MB",
              flush=True)  # as it goes: a large run may be stopped before the end
        return out

    whole = []
    for k in range(a.repeat):
        obj.set_batch(k + 1)
        lens, _ = problem.lens(lm.theta)
        with torch.no_grad():
            spots = timed("trace (rendering rays)", lambda: obj.spots(lens))
            airy = obj._airy(spots, lens)
            cap, kpsf = timed("rendering forward (PSFs, grids, convolution, noise)",
                              lambda: obj.capture(spots.xy, spots, airy, obj.images, obj.regions))
        x = cap.clone().requires_grad_(True)

        def net_fb() -> None:
            out = net(x, kpsf)
            ((out - obj.images) ** 2).mean().backward()

        timed("network forward + backward", net_fb)
        net.zero_grad(set_to_none=True)
        timed("GTRA target (render + network forward, backward to ε)", lambda: obj.update(lens))
        J, r = timed("trace + Jacobian (forward mode, all residuals)", lambda: problem.jacobian(lm.theta))
        D = torch.linalg.vector_norm(J, dim=0).clamp_min(1e-6)
        delta = timed("LM solve (damped least squares)", lambda: damped_step(J, r, D, 1.0))
        timed("LM trial evaluation (trace, residuals)", lambda: problem.evaluate(lm.theta + delta))
        timed("network Adam step (forward, backward, update)",
              lambda: network_step(net, adam, cap, kpsf, obj.images, 1e-4))
        if not a.parts_only:
            sync()
            t0 = time.perf_counter()
            joint_step(problem, lm, obj, net, adam, k + 1, 10, lr=cfg.lr, lr_min=0.0)
            sync()
            whole.append(time.perf_counter() - t0)
    med = {k: statistics.median(v) for k, v in times.items()}
    res = {"opt_sampling": a.opt_sampling,
           "batch": a.batch, "patch": a.patch, "psf_size": a.psf_size, "fields": a.fields, "sampling": a.sampling,
           "wavelengths": len(data["spectrum"]["wavelengths_nm"]), "variables": problem.num_variables,
           "residuals": problem.size, "network_parameters": sum(p.numel() for p in net.parameters()),
           "threads": torch.get_num_threads(), "repeat": a.repeat, "median_s": med,
           "median_cpu_s": {k: statistics.median(v) for k, v in cpu.items()},
           "joint_step_median_s": statistics.median(whole) if whole else None, "joint_step_s": whole,
           "rss_after_setup_mb": base_mb, "peak_rss_mb": peak_rss_mb(), "device": str(dev)}
    if dev.type == "cuda":
        res["cuda"] = {"name": torch.cuda.get_device_name(dev), "torch": torch.__version__,
                       "peak_allocated_mb": torch.cuda.max_memory_allocated(dev) / 2**20,
                       "peak_reserved_mb": torch.cuda.max_memory_reserved(dev) / 2**20}
    print(json.dumps(res, indent=1))
    if a.out and a.key:
        runs = json.loads(a.out.read_text()) if a.out.exists() else {}
        runs[a.key] = res
        res = runs
    if a.out:
        a.out.write_text(json.dumps(res, indent=1) + "\n")


if __name__ == "__main__":
    main()
