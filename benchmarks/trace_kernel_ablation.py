"""Each change to the compiled trace's kernel, measured (issue 14, session 21): the Cooke triplet at
1e6 rays, float64, one thread, every variant compiled by Inductor as ``accel.compiled`` compiles it
and timed interleaved with the fused sketch (``soa_sketch.py``) in the same run.

Variants, cumulative (``trace.KernelOptions``):

1. ``reference``: the eager trace's formulation (``bend_xyz``, the full quadric solve, interleaved
   outputs) — what main's compiled trace ran, plus this session's two exact changes that the eager
   trace shares (float64 hit flags, the normal oriented by the sign of cos θ');
2. ``+ planes``: outputs written component-major;
3. ``+ near root``: no far root on quadrics with 1 + κ ≥ 0 (all six Cooke surfaces);
4. ``+ n/n' table``: refraction from one per-wavelength ratio (``refract_ratio_xyz``), the table
   computed inside the graph;
5. ``+ hoisted``: the table computed outside the kernel and passed in (what ``compiled_trace`` runs).

``--before DIR`` adds the compiled trace of another checkout (e.g. main) as row 0. For each variant:
the number of ``auto tmpN`` values in the generated C++ kernel's vector loop (Inductor's SSA
temporaries: a deterministic count of the work per block of rays, read from the code that
``torch._inductor.utils.run_and_get_code`` returns; "–" when Inductor served the kernel from its
cache without code), the median time, and time / the sketch's.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/trace_kernel_ablation.py --repeats 9 --before /work/main
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import re
import statistics
import time
import types
from collections.abc import Callable
from pathlib import Path

import torch
from soa_sketch import sketch_runner
from trace_speed import SPEC, import_before, make_rays

from lensopt.accel.compiled import _MAX_FUSION_SIZE, component_major_rays, near_only_surfaces
from lensopt.optics.lens import Lens
from lensopt.optics.trace import KernelOptions, Rays, index_ratio, trace, trace_kernel


def _kernel_temporaries(codes: list[str]) -> str:
    """``auto tmpN`` definitions in the body of the largest loop over rays in the generated C++
    (the vectorized main loop; its scalar tail repeats the same work and is not counted)."""
    best = 0
    for code in codes:
        for loop in code.split("for(int64_t x0=")[1:]:
            body = loop.split(".store(")[0]
            best = max(best, len(re.findall(r"auto tmp\d+ =", body)))
    return str(best) if best else "–"


def _variant(options: KernelOptions, hoist: bool, tag: str) -> Callable[..., tuple]:
    def flat(curvature, conic, asphere, phase, thickness, index, wavelength_um, semi_diameter, pos, dir,
             wavelength, ratio):  # noqa: ANN001, ANN202 - mirrors compiled._make_compiled's flat_trace
        lens = Lens(shapes=SHAPES, curvature=curvature, conic=conic, asphere=asphere, phase=phase,
                    thickness=thickness, index=index, wavelength_um=wavelength_um, semi_diameter=semi_diameter,
                    stop=STOP)
        r = trace_kernel(lens, Rays(pos, dir, wavelength), options, ratio=ratio if hoist else None)
        return r.pos, r.dir, r.status, r.backtrack

    # One code object per variant (Dynamo caches per code object), as compiled._make_compiled does.
    code = flat.__code__.replace(co_name=f"ablation_{tag}")
    fresh = types.FunctionType(code, flat.__globals__, code.co_name, None, flat.__closure__)
    return torch.compile(fresh, fullgraph=True, options={"max_fusion_size": _MAX_FUSION_SIZE})


SHAPES: tuple = ()
STOP = 0


def main() -> None:
    global SHAPES, STOP
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rays", type=float, default=1e6)
    ap.add_argument("--repeats", type=int, default=9)
    ap.add_argument("--before", type=Path, default=None, help="root of another checkout: its compiled trace too")
    args = ap.parse_args()
    torch.set_num_threads(1)
    model, rays = make_rays(SPEC, int(args.rays))
    lens = model.lens
    SHAPES, STOP = lens.shapes, lens.stop
    r = component_major_rays(rays)
    tensors = [getattr(lens, f) for f in ("curvature", "conic", "asphere", "phase", "thickness", "index",
                                          "wavelength_um", "semi_diameter")]
    call_args = [*tensors, r.pos, r.dir, r.wavelength, index_ratio(lens)]
    near = near_only_surfaces(lens)
    off = tuple(False for _ in near)
    variants: dict[str, tuple[Callable[..., object], list]] = {}
    if args.before is not None:
        import_before(args.before)
        from lensopt_before.optics import compiled as old_compiled
        from lensopt_before.optics import lens as old_lens
        from lensopt_before.optics import trace as old_trace

        old = old_lens.Lens(**{f.name: getattr(lens, f.name) for f in dataclasses.fields(lens)})
        old_rays = old_trace.Rays(r.pos, r.dir, r.wavelength)
        variants["0. before (--before)"] = (lambda: old_compiled.compiled_trace(old, old_rays, fallback=False), [])
    specs = [("1. reference", KernelOptions(off, ratio_refraction=False, component_major=False), False),
             ("2. + planes", KernelOptions(off, ratio_refraction=False), False),
             ("3. + near root", KernelOptions(near, ratio_refraction=False), False),
             ("4. + n/n' table", KernelOptions(near), False),
             ("5. + hoisted (compiled_trace)", KernelOptions(near), True)]
    for i, (name, options, hoist) in enumerate(specs):
        fn = _variant(options, hoist, str(i))
        variants[name] = ((lambda fn=fn: fn(*call_args)), [])
    variants["sketch"] = (sketch_runner(lens, rays), [])

    from torch._inductor.utils import run_and_get_code

    load_before = os.getloadavg()
    ref = trace(lens, rays)
    temps: dict[str, str] = {}
    notes = []
    with torch.no_grad():
        for name, (fn, _) in variants.items():
            t0 = time.perf_counter()
            out, codes = run_and_get_code(fn)
            notes.append(f"first call of {name}: {time.perf_counter() - t0:.1f} s")
            temps[name] = _kernel_temporaries(codes)
            if name.startswith(("1", "2", "3", "4", "5")):
                pos, status = out[0], out[2]
                ok = ref.valid
                diff = float((pos[ok, :2] - ref.pos[ok, :2]).abs().max())
                notes.append(f"{name}: max |Δ image x, y| vs eager {diff:.1e} mm, same statuses: "
                             f"{torch.equal(status, ref.status)}")
        names = list(variants)
        for rep in range(args.repeats):
            k = rep % len(names)
            for name in names[k:] + names[:k]:
                fn, times = variants[name]
                t0 = time.perf_counter()
                fn()
                times.append(time.perf_counter() - t0)
    load_after = os.getloadavg()
    sketch_times = variants["sketch"][1]
    print(f"Cooke triplet, {ref.pos.shape[0]:.1e} rays, float64, 1 thread; medians of {args.repeats} interleaved "
          f"repeats; load {load_before[0]:.1f} → {load_after[0]:.1f}\n")
    print("| variant | kernel temporaries | median s | × sketch (medians) | × sketch (median per repeat) |")
    print("|---|---:|---:|---:|---:|")
    for name in names:
        times = variants[name][1]
        per = statistics.median(t / s for t, s in zip(times, sketch_times, strict=True))
        print(f"| {name} | {temps[name]} | {statistics.median(times):.4f} | "
              f"{statistics.median(times) / statistics.median(sketch_times):.2f} | {per:.2f} |")
    print()
    for n in notes:
        print(f"- {n}")


if __name__ == "__main__":
    main()
