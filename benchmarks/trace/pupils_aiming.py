"""Full ray aiming (S21–S22): stop misses against the number of Newton steps, and the time it takes.

For every field and wavelength of a spec (its front aperture and fixed factors removed: they cut the
bundle elsewhere than at the stop), the launched bundle's marginal rays (pupil (0, ∓1) and
(1, 0)) are traced to the stop and compared with its edge (∓r, radius r), and the aimed chief ray with
its centre; the misses are measured by tracing, not taken from the aiming's own report.

    .venv/bin/python benchmarks/trace/pupils_aiming.py specs/wide_angle_laikin.toml --max-steps 5
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time

import torch

from lensopt.optics.bundle import trace_bundle
from lensopt.optics.sampling import launch
from lensopt.optics.trace import trace
from lensopt.spec import build, load_spec

MARGINAL = torch.tensor([[0.0, -1.0], [0.0, 1.0], [1.0, 0.0]], dtype=torch.float64)


def misses(model, steps: int) -> tuple[torch.Tensor, torch.Tensor, float]:
    """(F, 4) largest |miss| over wavelengths (inferior, superior, lateral, chief), mm; (F,) traced; s."""
    lens, system = model.lens, model.system
    with torch.no_grad():
        t0 = time.perf_counter()
        b = trace_bundle(lens, system, MARGINAL, aim="full", aim_steps=steps, record=True)
        elapsed = time.perf_counter() - t0
        r = b.pupil_aim.stop_radius_mm
        hit = b.result.hits[lens.stop].pos
        ok = b.result.valid.all(-1)
        m = torch.stack([hit[..., 0, 1] + r, hit[..., 1, 1] - r,
                         torch.linalg.vector_norm(hit[..., 2, :2], dim=-1) - r], -1)
        chief = torch.stack([torch.zeros_like(b.aim.offset), b.aim.offset], -1).unsqueeze(-2)
        c = trace(lens, launch(lens, system, chief, b.tan_field, epd=b.first_order.epd,
                               entrance_pupil_z=b.first_order.entrance_pupil_z), upto=lens.stop)
        m = torch.cat([m, c.pos[..., 0, 1].unsqueeze(-1)], -1).abs()
        ok = ok & c.valid[..., 0]
    return m.amax(1), ok.all(-1), elapsed


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("spec")
    ap.add_argument("--max-steps", type=int, default=5)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--tol", type=float, default=1e-9)
    args = ap.parse_args()
    model = build(load_spec(args.spec))
    # The aiming itself: without fixed factors or a front aperture, whose cuts are not at the stop.
    model = dataclasses.replace(model, system=dataclasses.replace(model.system, vignetting=(), front_aperture=None))
    angles = [u * model.system.field_max for u in model.system.rel_field]
    print(f"### {model.spec.name}: stop misses (mm, largest over wavelengths) vs aiming steps\n")
    print("| steps | " + " | ".join(f"{a:.3g}°" for a in angles) + f" | all ≤ {args.tol:.0e} mm | median s |")
    print("|---:|" + "---:|" * len(angles) + ":---:|---:|")
    needed = [None] * len(angles)
    misses(model, 1)  # warm-up (first forward-mode call imports and caches)
    for steps in range(1, args.max_steps + 1):
        times = []
        for _ in range(args.repeats):
            worst, ok, dt = misses(model, steps)
            times.append(dt)
        per_field = worst.amax(-1)
        for h in range(len(angles)):
            if needed[h] is None and bool(ok[h]) and float(per_field[h]) <= args.tol:
                needed[h] = steps
        cells = [f"{float(v):.1e}" if bool(o) else "lost" for v, o in zip(per_field, ok, strict=True)]
        flag = "yes" if bool(ok.all()) and float(per_field.max()) <= args.tol else "no"
        print(f"| {steps} | " + " | ".join(cells) + f" | {flag} | {statistics.median(times):.2f} |")
    print(f"\nsteps needed per field for ≤ {args.tol:.0e} mm: "
          + ", ".join(f"{a:.3g}°: {n if n is not None else '>' + str(args.max_steps)}"
                      for a, n in zip(angles, needed, strict=True)))


if __name__ == "__main__":
    main()
