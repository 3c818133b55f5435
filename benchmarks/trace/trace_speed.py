"""Trace speed (issue 2): rays × surfaces per second through the Cooke triplet, lensopt vs optiland.

Every configuration traces the *same* object-space rays (3 fields × 3 wavelengths × random pupil
points, started on the plane z = −5 mm before surface 1) to the image plane, CPU only:

- ``optiland``: optiland 0.6.3's real-ray tracer (numpy backend), ``optic.surfaces.trace`` on
  ``RealRays`` (ray generation excluded, as for lensopt), float64;
- ``eager``: ``lensopt.optics.trace.trace``;
- ``compiled``: ``lensopt.accel.compiled.compiled_trace`` (``torch.compile``, Inductor C++);
- ``sketch``: ``benchmarks/trace/soa_sketch.py``, a compiled component-wise sphere + Snell loop — not
  lensopt, the ceiling a component-wise formulation of the trace would reach (``--no-ceiling``).

lensopt gets the rays stored component-major (``component_major_rays``), as optiland's ``RealRays``
store them. Repeats are interleaved (every repeat runs every configuration once, in a rotating order) so all
see the same machine load; the table gives medians and ratios to optiland's median in this run.
Compilation / JIT warm-up is excluded from the timings and reported separately.

    .venv/bin/python benchmarks/trace/trace_speed.py --rays 1e5,1e6 --repeats 7 --dtype float64,float32

prints a ready-to-paste markdown section (table, agreement checks, profile, peak memory).

``--before DIR`` adds the eager and compiled traces of another checkout's ``lensopt`` package (DIR is
that checkout's root, e.g. ``git worktree add /tmp/before main``), imported under another name, so
that a change to the trace is timed before and after in the same run.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import statistics
import subprocess
import sys
import time
import types
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: procmem
from procmem import vm_kb  # noqa: E402
from soa_sketch import sketch_runner  # noqa: E402

from lensopt.accel.compiled import compiled_trace, component_major_rays  # noqa: E402
from lensopt.optics.trace import Rays, trace  # noqa: E402
from lensopt.spec import build, load_spec  # noqa: E402

SPEC = Path(__file__).resolve().parents[2] / "specs" / "cooke_triplet.toml"
START_Z = -5.0
"""Start plane of the rays (mm from surface 1): in front of the lens for both tracers."""
DTYPES = {"float64": torch.float64, "float32": torch.float32}
# The spec's glasses, as optiland names them (the spec says SK16 is Hikari's SK16, F2 is Schott's).
OPTILAND_GLASS = {"SK16": ("SK16", "hikari"), "F2": ("F2", "schott")}


def make_rays(spec_path: Path, n: int, seed: int = 0) -> tuple[object, Rays]:
    """The lens (float64) and ~n rays: every field × wavelength × n // (F W) uniform pupil points."""
    from lensopt.optics.paraxial import field_tangents, first_order
    from lensopt.optics.sampling import launch

    model = build(load_spec(spec_path))
    lens, system = model.lens, model.system
    fo = first_order(lens, system)
    tan = field_tangents(lens, system, torch.tensor(system.rel_field, dtype=torch.float64))
    per = max(1, n // (len(system.rel_field) * lens.wavelength_um.shape[0]))
    g = torch.Generator().manual_seed(seed)
    r = torch.sqrt(torch.rand(per, generator=g, dtype=torch.float64))
    phi = 2 * torch.pi * torch.rand(per, generator=g, dtype=torch.float64)
    pupil = torch.stack([r * torch.cos(phi), r * torch.sin(phi)], -1)
    rays = launch(lens, system, pupil, tan, epd=fo.epd, entrance_pupil_z=fo.entrance_pupil_z)
    pos, d = torch.broadcast_tensors(rays.pos, rays.dir)
    wl = rays.wavelength.expand(pos.shape[:-1]).reshape(-1).contiguous()
    pos, d = pos.reshape(-1, 3), d.reshape(-1, 3).contiguous()
    pos = (pos + ((START_Z - pos[:, 2]) / d[:, 2]).unsqueeze(-1) * d).contiguous()
    return model, Rays(pos=pos, dir=d, wavelength=wl)


def optiland_lens(model) -> object:
    """The spec's lens rebuilt in optiland, surface by surface (object at infinity, same stop)."""
    from optiland.optic import Optic

    op = Optic()
    op.surfaces.add(index=0, radius=np.inf, thickness=np.inf)
    for i, s in enumerate(model.spec.surfaces, start=1):
        material = "air" if s.material == "air" else OPTILAND_GLASS[s.material]
        op.surfaces.add(index=i, radius=s.radius, thickness=s.thickness, material=material, is_stop=s.stop)
    op.surfaces.add(index=len(model.spec.surfaces) + 1)
    op.set_aperture(aperture_type="EPD", value=10.0)
    op.fields.set_type(field_type="angle")
    op.fields.add(y=0)
    op.wavelengths.add(value=0.55, is_primary=True)
    return op


class Peer:
    """optiland's tracer on the benchmark rays (one ``surfaces.trace`` call over all rays)."""

    def __init__(self, model, rays: Rays) -> None:
        from optiland.rays import RealRays

        self._real_rays = RealRays
        self.op = optiland_lens(model)
        self.p = rays.pos.numpy()
        self.d = rays.dir.numpy()
        self.w = model.lens.wavelength_um[rays.wavelength].numpy()
        self.rays = None

    def prepare(self) -> None:
        p, d = self.p, self.d
        self.rays = self._real_rays(p[:, 0].copy(), p[:, 1].copy(), p[:, 2].copy(), d[:, 0].copy(),
                                    d[:, 1].copy(), d[:, 2].copy(), np.ones(len(self.w)), self.w.copy())

    def __call__(self) -> np.ndarray:
        self.op.surfaces.trace(self.rays, record=False)
        return np.stack([self.rays.x, self.rays.y], -1)


def import_before(root: Path) -> types.ModuleType:
    """``root``/lensopt imported as the package ``lensopt_before`` (a renamed copy in a temp dir)."""
    import importlib
    import re
    import shutil
    import tempfile

    dest = Path(tempfile.mkdtemp(prefix="lensopt_before_")) / "lensopt_before"
    shutil.copytree(root / "lensopt", dest, ignore=shutil.ignore_patterns("__pycache__"))
    for f in dest.rglob("*.py"):
        text = re.sub(r"\b(from|import) lensopt\b", r"\1 lensopt_before", f.read_text())
        f.write_text(re.sub(r"\blensopt\.", "lensopt_before.", text))
    sys.path.insert(0, str(dest.parent))
    return importlib.import_module("lensopt_before")


def lensopt_runner(model, rays: Rays, dtype: torch.dtype, compiled: bool, before: Path | None = None
                   ) -> Callable[[], object]:
    lens = model.lens.to(dtype)
    # Component-major storage, as optiland's RealRays keep x, y, z (and L, M, N) as separate arrays.
    r = component_major_rays(Rays(pos=rays.pos.to(dtype), dir=rays.dir.to(dtype), wavelength=rays.wavelength))
    if before is not None:
        import_before(before)
        from lensopt_before.optics import compiled as old_compiled
        from lensopt_before.optics import lens as old_lens
        from lensopt_before.optics import trace as old_trace

        lens = old_lens.Lens(**{f.name: getattr(lens, f.name) for f in dataclasses.fields(lens)})
        r = old_trace.Rays(r.pos, r.dir, r.wavelength)
        if compiled:
            return lambda: old_compiled.compiled_trace(lens, r, fallback=False)
        return lambda: old_trace.trace(lens, r)
    if compiled:
        return lambda: compiled_trace(lens, r, fallback=False)
    return lambda: trace(lens, r)


def timed(fn: Callable[[], object], prepare: Callable[[], None] | None = None) -> tuple[float, object]:
    if prepare is not None:
        prepare()
    t0 = time.perf_counter()
    with torch.no_grad():
        out = fn()
    return time.perf_counter() - t0, out


def child_main(task: str, mode: str, dtype: str, n: int) -> None:
    """Run in a fresh process: ``memory`` prints the peak RSS growth of one call (MB); ``kernels``
    prints the per-kernel profile of the compiled trace."""
    model, rays = make_rays(SPEC, n)
    fn = lensopt_runner(model, rays, DTYPES[dtype], mode == "compiled")
    timed(fn)  # warm-up / compile
    if task == "kernels":
        print(profile_table(fn, 12, name_width=70))
        return
    # Peak RSS of the process during the call minus RSS before it: /proc/self/clear_refs "5" resets
    # VmHWM; the parent sets MALLOC_MMAP_THRESHOLD_ so every array is returned to the OS when freed.
    Path("/proc/self/clear_refs").write_text("5")
    before = vm_kb("VmRSS")
    timed(fn)
    print(f"{(vm_kb('VmHWM') - before) / 1024:.0f}")


def run_child(task: str, mode: str, dtype: str, n: int) -> str:
    env = dict(os.environ, MALLOC_MMAP_THRESHOLD_="65536", TORCHINDUCTOR_CPP_ENABLE_KERNEL_PROFILE="1")
    if task == "memory":
        env.pop("TORCHINDUCTOR_CPP_ENABLE_KERNEL_PROFILE")
    cmd = [sys.executable, __file__, "--child", f"{task},{mode},{dtype},{n}", "--threads", str(torch.get_num_threads())]
    res = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    if res.returncode != 0:
        return f"(failed: {res.stderr.strip().splitlines()[-1] if res.stderr.strip() else res.returncode})"
    return res.stdout.strip()


def profile_table(fn: Callable[[], object], rows: int, name_width: int = 40) -> str:
    """Top ops by self CPU time of one call, as markdown rows."""
    from torch.profiler import ProfilerActivity, profile

    with torch.no_grad(), profile(activities=[ProfilerActivity.CPU]) as prof:
        fn()
    stats = [s for s in prof.key_averages() if s.self_cpu_time_total > 0]
    total = sum(s.self_cpu_time_total for s in stats)
    stats.sort(key=lambda s: s.self_cpu_time_total, reverse=True)
    lines = ["| op | calls | self CPU ms | share |", "|---|---:|---:|---:|"]
    for s in stats[:rows]:
        key = s.key if len(s.key) <= name_width else s.key[: name_width - 1] + "…"
        lines.append(f"| `{key}` | {s.count} | {s.self_cpu_time_total / 1e3:.1f} | "
                     f"{100 * s.self_cpu_time_total / total:.0f}% |")
    lines.append(f"| total | | {total / 1e3:.1f} | |")
    return "\n".join(lines)


def measure(n: int, args: argparse.Namespace, notes: list[str]) -> list[str]:
    """Warm up, check agreement, time interleaved repeats; the table rows for ``n`` rays."""
    model, rays = make_rays(SPEC, n)
    n_rays = rays.pos.shape[0]
    configs: dict[str, tuple[Callable[[], object], Callable[[], None] | None]] = {}
    if not args.no_peer:
        peer = Peer(model, rays)
        configs["optiland|float64"] = (peer, peer.prepare)
    for mode in args.modes:
        for dt in args.dtypes:
            configs[f"lensopt {mode}|{dt}"] = (lensopt_runner(model, rays, DTYPES[dt], mode == "compiled"), None)
            if args.before is not None:
                configs[f"lensopt {mode}, before|{dt}"] = (
                    lensopt_runner(model, rays, DTYPES[dt], mode == "compiled", args.before), None)
    if args.ceiling:
        configs["sketch (ceiling, not lensopt)|float64"] = (sketch_runner(model.lens, rays), None)
    # Warm-up (compilation, numba JIT) and agreement with the eager float64 trace.
    results = {}
    for name, (fn, prep) in configs.items():
        t, results[name] = timed(fn, prep)
        if "compiled" in name or "optiland" in name or "sketch" in name:
            notes.append(f"first call (compile / JIT warm-up) of {name.replace('|', ' ')} at {n_rays:.1e} rays: "
                         f"{t:.1f} s")
    ref = results.get("lensopt eager|float64") or trace(model.lens, rays)
    ok = ref.valid
    for name, res in results.items():
        if name == "lensopt eager|float64":
            continue
        plain = isinstance(res, np.ndarray | torch.Tensor)
        xy = torch.as_tensor(res) if plain else res.pos[:, :2].double()
        diff = (xy[ok] - ref.pos[ok, :2]).abs().max().item()
        same = "" if plain else f", same statuses: {torch.equal(res.status, ref.status)}"
        notes.append(f"max |Δ image x, y| of {name.replace('|', ' ')} vs lensopt eager float64 at {n_rays:.1e} "
                     f"rays ({int(ok.sum())} valid): {diff:.1e} mm{same}")
    times: dict[str, list[float]] = {name: [] for name in configs}
    names = list(configs)
    for rep in range(args.repeats):
        k = rep % len(names)  # rotate the order so no configuration always runs first
        for name in names[k:] + names[:k]:
            fn, prep = configs[name]
            times[name].append(timed(fn, prep)[0])
    peer_rate = None if args.no_peer else n_rays / statistics.median(times["optiland|float64"])
    sketch = "sketch (ceiling, not lensopt)|float64"
    if sketch in times:
        # Issue 14's goal is a ratio to the sketch in the same run: median time / the sketch's median,
        # and the median of the per-repeat ratios (each repeat runs every configuration once).
        base = statistics.median(times[sketch])
        for name in names:
            if name.startswith("lensopt compiled"):
                per = statistics.median(t / b for t, b in zip(times[name], times[sketch], strict=True))
                notes.append(f"time / the sketch's at {n_rays:.1e} rays, {name.replace('|', ' ')}: "
                             f"{statistics.median(times[name]) / base:.2f}× (medians), {per:.2f}× (median of "
                             f"the {len(times[name])} per-repeat ratios)")
    rows = []
    for name in names:
        tracer, dt = name.split("|")
        med = statistics.median(times[name])
        rate = n_rays / med
        ratio = f"**{rate / peer_rate:.2f}**" if peer_rate else "–"
        rows.append(f"| {n_rays:.1e} | {tracer} | {dt} | {med:.4f} | {min(times[name]):.4f}–{max(times[name]):.4f} | "
                    f"{rate / 1e6:.2f} | {6 * rate / 1e6:.1f} | {ratio} |")
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rays", default="1e5,1e6", help="comma-separated ray counts (default 1e5,1e6)")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--dtype", default="float64,float32", help="lensopt dtypes (optiland is float64)")
    ap.add_argument("--modes", default="eager,compiled", help="lensopt modes: eager, compiled")
    ap.add_argument("--threads", type=int, default=0, help="torch intra-op threads (default: torch's choice)")
    ap.add_argument("--no-peer", action="store_true", help="skip optiland")
    ap.add_argument("--no-ceiling", dest="ceiling", action="store_false",
                    help="skip the component-wise sketch (benchmarks/trace/soa_sketch.py)")
    ap.add_argument("--no-profile", action="store_true", help="skip the profile and memory sections")
    ap.add_argument("--profile-rows", type=int, default=10)
    ap.add_argument("--before", type=Path, default=None,
                    help="root of another checkout: time its eager/compiled trace too (same run)")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    warnings.filterwarnings("ignore")  # numba's pedantic IR warnings inside optiland
    if args.child:
        task, mode, dt, n = args.child.split(",")
        child_main(task, mode, dt, int(n))
        return
    counts = [int(float(x)) for x in args.rays.split(",")]
    args.dtypes = [d.strip() for d in args.dtype.split(",")]
    args.modes = [m.strip() for m in args.modes.split(",")]

    load_before = os.getloadavg()
    cpu = next((ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                if ln.startswith("model name")), platform.processor())
    from importlib.metadata import version

    threads = f" --threads {args.threads}" if args.threads else ""
    out = ["## Trace speed (issue 2)", "",
           f"- Machine: {os.cpu_count()} cores, {cpu}; torch {torch.__version__} "
           f"(intra-op threads: {torch.get_num_threads()}), optiland {version('optiland')} (numpy {np.__version__}, "
           f"numba kernels), Python {platform.python_version()}.",
           "- Workload: Cooke triplet (`specs/cooke_triplet.toml`), 3 fields × 3 wavelengths × uniform random "
           f"pupil points, all rays started on z = {START_Z} mm and traced through the 6 surfaces to the image "
           "plane; *rays×surf* counts the 6 refracting surfaces.",
           "- Command: `.venv/bin/python benchmarks/trace/trace_speed.py "
           f"--rays {args.rays} --repeats {args.repeats} --dtype {args.dtype} --modes {','.join(args.modes)}"
           f"{threads}{' --before DIR' if args.before else ''}`"]
    table = ["| rays | tracer | dtype | median s | min–max s | M rays/s | M rays×surf/s | × optiland |",
             "|---:|---|---|---:|---:|---:|---:|---:|"]
    notes: list[str] = []
    for n in counts:
        table += measure(n, args, notes)
    load_after = os.getloadavg()
    out.append(f"- Load average (1/5/15 min) before: {load_before[0]:.2f}/{load_before[1]:.2f}/{load_before[2]:.2f}, "
               f"after: {load_after[0]:.2f}/{load_after[1]:.2f}/{load_after[2]:.2f}; "
               f"medians of {args.repeats} interleaved repeats; ratios against optiland's median in this run.")
    out += ["", *table, "", *[f"- {x}" for x in notes]]
    if not args.no_profile:
        n = counts[-1]
        model, rays = make_rays(SPEC, n)
        n_rays = rays.pos.shape[0]
        out += ["", f"### Peak memory of one trace call at {n_rays:.1e} rays", "",
                "Peak RSS growth during the call (fresh process, after warm-up; inputs excluded).", "",
                "| tracer | dtype | peak MB |", "|---|---|---:|"]
        for mode in args.modes:
            for dt in args.dtypes:
                out.append(f"| lensopt {mode} | {dt} | {run_child('memory', mode, dt, n)} |")
        if "eager" in args.modes:
            fn = lensopt_runner(model, rays, torch.float64, compiled=False)
            timed(fn)
            out += ["", f"### Profile: lensopt eager float64, {n_rays:.1e} rays (torch.profiler, self CPU)", "",
                    profile_table(fn, args.profile_rows)]
        if "compiled" in args.modes:
            out += ["", f"### Profile: lensopt compiled float64, {n_rays:.1e} rays (Inductor kernels, self CPU)", "",
                    run_child("kernels", "compiled", "float64", n)]
    print("\n".join(out))


if __name__ == "__main__":
    main()
