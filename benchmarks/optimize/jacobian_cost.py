"""Cost of the LM Jacobian: forward mode (torch.func.jacfwd, what LM uses) against reverse mode
(jacrev) and finite differences (forward N+1 and central 2N residual evaluations), on the optimization
problems of specs/cooke_triplet_opt.toml and specs/cmount_4p.toml (start points).

    .venv/bin/python benchmarks/optimize/jacobian_cost.py --repeats 5 \
        --json benchmarks/optimize/results_jacobian_cost.json
    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/optimize/jacobian_cost.py --compiled --no-fd --jacrev-max-rows 0 \
        --json benchmarks/optimize/results_jacobian_compiled.json

``--compiled`` adds the compiled forward-mode Jacobian (``accel.jacobian``: make_fx of jacfwd,
compiled by Inductor; ``--compiled-backend`` picks how) with its one-off capture + compile time (wall
and this process's CPU time);
every row also gives its cost in units of one eager residual evaluation measured in the same run.

Prints a markdown table: median wall time per Jacobian, ratio to jacfwd, and the largest difference
from jacfwd relative to the largest Jacobian entry. Reverse mode is skipped for problems with more than
``--jacrev-max-rows`` residuals (it costs one backward pass per residual row).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import torch

from lensopt.design import build_problem
from lensopt.spec import load_spec

SPECS = Path(__file__).resolve().parents[2] / "specs"


CLOCK = {"now": time.perf_counter}


def _time(fn, repeats: int) -> tuple[float, torch.Tensor]:  # noqa: ANN001
    out = fn()  # warm-up (functorch's first call builds its rules)
    times = []
    now = CLOCK["now"]
    for _ in range(repeats):
        t0 = now()
        out = fn()
        times.append(now() - t0)
    return statistics.median(times), out


def _cpu_with_children() -> float:
    """CPU seconds of this process and its finished children (the C++ compiler that Inductor runs)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def bench(spec_name: str, repeats: int, jacrev_max_rows: int, compiled: bool = False, fd: bool = True,
          backend: str = "inductor") -> dict:
    p = build_problem(load_spec(SPECS / spec_name))
    theta = p.theta0
    N, M = p.num_variables, p.size
    h = 1e-6

    def forward_fd() -> torch.Tensor:
        with torch.no_grad():
            r0 = p.residuals(theta)
            cols = []
            for n in range(N):
                e = torch.zeros_like(theta)
                e[n] = h
                cols.append((p.residuals(theta + e) - r0) / h)
        return torch.stack(cols, 1)

    def central_fd() -> torch.Tensor:
        with torch.no_grad():
            cols = []
            for n in range(N):
                e = torch.zeros_like(theta)
                e[n] = h
                cols.append((p.residuals(theta + e) - p.residuals(theta - e)) / (2 * h))
        return torch.stack(cols, 1)

    rows = {}
    t_res, _ = _time(lambda: p.residuals(theta).detach(), repeats)
    rows["one residual evaluation"] = (t_res, None)
    t_fwd, J = _time(lambda: p.jacobian_jacfwd(theta)[0], repeats)
    rows["jacfwd (forward mode)"] = (t_fwd, J)
    rows["forward mode in stages (Problem.jacobian)"] = _time(lambda: p.jacobian(theta)[0], repeats)
    extra = {}
    if compiled:
        from torch.fx.experimental.proxy_tensor import make_fx  # noqa: F401 - imported before the clock

        from lensopt.accel.jacobian import CompiledJacobian

        cj = CompiledJacobian(p, check=False, backend=backend)
        t0, c0 = time.perf_counter(), _cpu_with_children()
        cj(theta)
        extra["compile_s"], extra["compile_cpu_s"] = time.perf_counter() - t0, _cpu_with_children() - c0
        extra["compiled"] = cj.compiled
        extra["compile_backend"] = backend
        extra["compile_source"] = cj.source
        label = {"aot": "AOTInductor package", "inductor": "make_fx + Inductor", "dynamo": "make_fx + torch.compile",
                 "graph": "make_fx graph, no compiler"}
        rows[f"jacfwd compiled ({label[backend]})"] = _time(lambda: cj(theta)[0], repeats)
        # The compile takes minutes: time the eager references again right beside the compiled row, so
        # that a change of machine load during the compile does not bias the ratios.
        t_res, _ = _time(lambda: p.residuals(theta).detach(), repeats)
        rows["one residual evaluation"] = (t_res, None)
        t_fwd, J = _time(lambda: p.jacobian_jacfwd(theta)[0], repeats)
        rows["jacfwd (forward mode)"] = (t_fwd, J)
    if M <= jacrev_max_rows:
        rows["jacrev (reverse mode)"] = _time(lambda: torch.func.jacrev(p.residuals)(theta), max(1, repeats // 2))
    if fd:
        rows[f"forward differences (N+1 = {N + 1} evaluations)"] = _time(forward_fd, repeats)
        rows[f"central differences (2N = {2 * N} evaluations)"] = _time(central_fd, repeats)
    scale = float(J.abs().max())
    out = {"spec": spec_name, "variables": N, "residuals": M, "rows": [], **extra}
    for name, (t, Jx) in rows.items():
        diff = None if Jx is None or Jx is J else float((Jx - J).abs().max()) / scale
        out["rows"].append({"method": name, "median_s": t, "ratio_to_jacfwd": t / t_fwd,
                            "residual_evaluations": t / t_res, "max_rel_diff": diff})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--jacrev-max-rows", type=int, default=20000)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--compiled", action="store_true", help="add the compiled forward-mode Jacobian")
    ap.add_argument("--no-fd", action="store_true", help="skip the finite-difference rows")
    ap.add_argument("--compiled-backend", choices=["aot", "inductor", "dynamo", "graph"], default="aot",
                    help="how --compiled compiles the captured graph (CompiledJacobian's backend)")
    ap.add_argument("--clock", choices=["wall", "cpu"], default="wall",
                    help="time each call by wall time or by this process's CPU time (load-robust)")
    ap.add_argument("--specs", default="cooke_triplet_opt.toml,cmount_4p.toml")
    args = ap.parse_args()
    if args.clock == "cpu":
        CLOCK["now"] = time.process_time
    from lensopt.engine import retain_freed_memory

    retain_freed_memory()  # as `lensopt optimize` runs
    results = {
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count(), "torch": torch.__version__,
                    "threads": torch.get_num_threads(), "loadavg_before": os.getloadavg(),
                    "clock": args.clock},
        "problems": [],
    }
    for spec in args.specs.split(","):  # each table printed as soon as it is measured
        prob = bench(spec, args.repeats, args.jacrev_max_rows, args.compiled, not args.no_fd, args.compiled_backend)
        results["problems"].append(prob)
        print(f"\n{prob['spec']}: N = {prob['variables']} variables, M = {prob['residuals']} residuals")
        if "compile_s" in prob:
            print(f"compiled Jacobian ({prob['compile_backend']}, {prob['compile_source']}): first call "
                  f"{prob['compile_s']:.1f} s wall, "
                  f"{prob['compile_cpu_s']:.0f} s CPU (compiled: {prob['compiled']})")
        print("\n| method | median s | × jacfwd | residual evaluations | max |ΔJ| / max |J| |")
        print("| --- | ---: | ---: | ---: | ---: |")
        for r in prob["rows"]:
            d = "—" if r["max_rel_diff"] is None else f"{r['max_rel_diff']:.1e}"
            print(f"| {r['method']} | {r['median_s']:.4f} | {r['ratio_to_jacfwd']:.2f} | "
                  f"{r['residual_evaluations']:.1f} | {d} |")
        sys.stdout.flush()
        results["machine"]["loadavg_after"] = os.getloadavg()
        if args.json:  # after each problem: a long compile cut short keeps what was measured
            from lensopt.files import write_text_atomic

            write_text_atomic(args.json, json.dumps(results, indent=2) + "\n")
    print(f"\nload average before/after: {results['machine']['loadavg_before']} / "
          f"{results['machine']['loadavg_after']}, torch threads {results['machine']['threads']}")


if __name__ == "__main__":
    main()
