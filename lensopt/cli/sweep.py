"""``lensopt sweep`` (CLI layer: rich lives here): a spec over a grid of values with multi-start
optimization, on Dask or serially; the live per-point display and the final table. The engine is
``lensopt.study.sweep``."""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.console import Console
from rich.live import Live
from rich.table import Table

from lensopt.cli.common import (
    JsonOpt,
    SchedulerOpt,
    SeedOpt,
    WorkersOpt,
    check_scheduler,
    console,
    err_console,
    handle_errors,
    make_engine,
    print_json,
)
from lensopt.cli.signals import report_signal, signal_word, state
from lensopt.cli.tables import compact_table, show
from lensopt.errors import LensoptError

if TYPE_CHECKING:
    from lensopt.study.sweep import Point, SweepEvent, SweepResult

__all__ = ["SweepProgress", "commands", "render_table"]

commands = typer.Typer()  # its command, put in order by lensopt.cli.app


def _fmt(v: Any) -> str:
    if v is None:
        return "—"
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


def _esr(v: float | None) -> str:
    return "—" if v is None else f"{v:.4g}"


class SweepProgress:
    """Per grid point: starts done / failed / pending and the best ESR so far. A rich Live table on a
    terminal; otherwise a plain line at most every ``interval_s`` (and when the last task finishes)."""

    def __init__(self, console: Console, points: list[Point], starts: int, *, enabled: bool = True,
                 plain: bool | None = None, interval_s: float = 10.0) -> None:
        self.console = console
        self.points = points
        self.starts = starts
        self.enabled = enabled
        self.plain = (not console.is_terminal) if plain is None else plain
        self.interval_s = interval_s
        self.done = {p.index: 0 for p in points}
        self.failed = {p.index: 0 for p in points}
        self.best: dict[int, tuple[float, float | None, int]] = {}  # point → (merit, ESR µm, start)
        self.t0 = time.monotonic()
        self._printed = -math.inf
        self.live: Live | None = None

    @property
    def total(self) -> int:
        return len(self.points) * self.starts

    @property
    def finished(self) -> int:
        return sum(self.done.values()) + sum(self.failed.values())

    def __enter__(self) -> SweepProgress:
        if self.enabled and not self.plain:
            self.live = Live(self._render(), console=self.console, refresh_per_second=4, transient=False)
            self.live.__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        if self.live is not None:
            self.live.update(self._render())
            self.live.__exit__(None, None, None)

    def __call__(self, e: SweepEvent) -> None:
        rec = e.record
        if rec.get("status") == "finished":
            self.done[e.point] += 1
            merit = rec.get("merit")
            old = self.best.get(e.point)
            if merit is not None and (old is None or (merit, e.start) < (old[0], old[2])):
                self.best[e.point] = (merit, rec.get("esr_um"), e.start)
        else:
            self.failed[e.point] += 1
        if not self.enabled:
            return
        if self.live is not None:
            self.live.update(self._render())
        elif e.kind == "done":
            now = time.monotonic()
            if now - self._printed >= self.interval_s or self.finished == self.total:
                self._printed = now
                self.console.print(self.line(), highlight=False, markup=False, soft_wrap=True)

    def line(self) -> str:
        """``sweep 5/12 tasks, 12 s; best ESR µm per point: 0: 1.234 (start 2), 1: —, …``."""
        parts = []
        for p in self.points:
            b = self.best.get(p.index)
            esr = "—" if b is None or b[1] is None else f"{b[1]:.4g} (start {b[2]})"
            parts.append(f"{p.index}: {esr}")
        return (f"sweep {self.finished}/{self.total} tasks, {time.monotonic() - self.t0:.0f} s; "
                "best ESR µm per point: " + ", ".join(parts))

    def _render(self) -> Table:
        keys = list(self.points[0].values) if self.points else []
        t = Table(title=f"lensopt sweep — {self.finished}/{self.total} tasks, "
                        f"{time.monotonic() - self.t0:.0f} s", header_style="bold")
        for col in ["point", *keys, "done", "failed", "pending", "best ESR µm", "best start"]:
            t.add_column(col, justify="right")
        for p in self.points:
            b = self.best.get(p.index)
            pending = self.starts - self.done[p.index] - self.failed[p.index]
            t.add_row(str(p.index), *[_fmt(p.values[k]) for k in keys], str(self.done[p.index]),
                      str(self.failed[p.index]), str(pending), _fmt(b[1]) if b else "—", str(b[2]) if b else "—")
        return t


def render_table(console: Console, result: SweepResult, outdir: Path) -> None:
    """The final table: one row per point; then the files that are on disk (named, after they are written)."""
    keys = result.keys
    heads = [k.replace(".", ".\n") if len(k) > 12 else k for k in keys]  # long dotted keys wrap at the dots
    # ESRs to 4 digits (the JSON and CSV keep every digit), so that the seed's measure fits in 80 columns.
    cols = ["point", *heads, "ESR µm", "seed's\nESR µm", "merit", "best\nstart", "steps", "stop", "starts\nok/fail",
            "wall s"]
    t = compact_table("best of starts per point", [(c, "left" if c == "stop" else "right") for c in cols])
    for r in result.rows:
        t.add_row(str(r["point"]), *[_fmt(r[k]) for k in keys], _esr(r["best_esr_um"]), _esr(r["best_seed_esr_um"]),
                  "—" if r["best_merit"] is None else f"{r['best_merit']:.4e}", _fmt(r["best_start"]),
                  _fmt(r["best_steps"]), _fmt(r["best_stop_reason"]),
                  f"{r['starts_finished']}/{r['starts_failed']}", f"{r['wall_s']:.1f}")
    show(console, t, wrap=("stop",))
    best = [f"best_{r['point']}.json" for r in result.rows if r["best_start"] is not None]
    names = ["sweep.json", "sweep.csv", *best, "sweep.png"]
    written = [n for n in names if (outdir / n).is_file()]
    if len(written) > 6:
        written = [*written[:3], f"… ({len(written) - 5} more)", *written[-2:]]
    console.print(f"{result.computed} task(s) run, {result.skipped} found in {outdir}, {result.elapsed_s:.1f} s; "
                  f"in {outdir}: " + (", ".join(written) or "nothing written"), highlight=False)
    reasons = sorted({rec["reason"] for rec in result.records.values() if rec.get("status") == "failed"})
    for why in reasons[:5]:
        console.print(f"[yellow]failed start:[/] {why}", highlight=False)


@commands.command("sweep", short_help="Run a spec over a grid of values with multi-start optimization (Dask or "
                                     "serial); resumable.")
@handle_errors
def sweep(
    spec: Annotated[Path, typer.Argument(help="Lens spec (.toml or .json) with vary lists and an optimize "
                                         "section.")],
    vary: Annotated[list[str], typer.Option("--vary", help="KEY=V1,V2,... or KEY=START:STOP:STEP (inclusive; a "
                                            "negative STEP descends); "
                                            "KEY a dotted path such as optimize.solves[0].value or "
                                            "surfaces[3].thickness. Several: the full grid.")],
    output: Annotated[Path, typer.Option("--output", "-o", help="Folder for the sweep (resumed when it holds "
                                         "the same sweep).")],
    starts: Annotated[int, typer.Option("--starts", min=1, max=1000, help="Starts per point (start 0: the "
                                        "spec as written).")] = 1,
    perturb: Annotated[float, typer.Option("--perturb", min=0.0, help="Relative Gaussian perturbation of "
                                           "the scaled variables for starts ≥ 1.")] = 0.05,
    steps: Annotated[int | None, typer.Option("--steps", min=1, help="Optimizer steps (default: the "
                                              "spec's).")] = None,
    scheduler: SchedulerOpt = "auto",
    workers: WorkersOpt = 2,
    restart: Annotated[bool, typer.Option("--restart", help="Start over in a folder that holds another "
                                          "sweep (its files are removed).")] = False,
    continuation: Annotated[bool, typer.Option("--continuation", help="Walk along one --vary key: the points "
                                               "in the order given, each starting from the previous point's best "
                                               "lens with its value set.")] = False,
    full_weight: Annotated[bool, typer.Option("--full-weight", help="No weight schedules: every constraint "
                                              "group at the weight its schedule ends on from the first step "
                                              "of every start (as optimize --full-weight).")] = False,
    esr_sampling: Annotated[str, typer.Option("--esr-sampling", help="Pupil sampling of the reported ESR.")]
    = "gauss:16",
    seed: SeedOpt = 0,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress display.")] = False,
    as_json: JsonOpt = False,
) -> None:
    """Optimize SPEC at every point of a grid of values (--vary), with --starts perturbed starts each;
    keep the best start per point; write sweep.json, sweep.csv, best_<i>.json and sweep.png. With
    --continuation each point starts from the previous point's best lens (a walk that carries a basin)."""
    from lensopt.optics.sampling import PupilSampling
    from lensopt.spec import load_spec
    from lensopt.study.keys import parse_vary
    from lensopt.study.sweep import Settings, check_continuation, expand_grid, run_sweep

    sched = check_scheduler(scheduler)
    engine = make_engine(retain_freed_memory=True)
    base = load_spec(spec)
    try:
        text = spec.read_text(encoding="utf-8")
    except OSError as err:
        raise LensoptError(f"cannot read the file: {err.strerror}", path=str(spec)) from None
    PupilSampling.parse(esr_sampling, seed=seed, path="--esr-sampling", weighted=True)
    varies = [parse_vary(v) for v in vary]
    if continuation:
        check_continuation(varies)
    points = expand_grid(base, varies)
    settings = Settings(starts=starts, sigma=perturb, steps=steps, seed=seed, esr_sampling=esr_sampling,
                        full_weight=full_weight, continuation=continuation)
    with SweepProgress(err_console, points, starts, enabled=not quiet) as progress:
        result = run_sweep(base, text, varies, settings, output, scheduler=sched, workers=workers,
                           restart=restart, spec_name=base.name or spec.name, callback=progress, points=points,
                           on_plan=None if quiet or as_json else lambda why: err_console.print(
                               f"sweep: the tasks run {why}", highlight=False), engine=engine)
    if as_json:
        print_json({"output": str(output), "complete": result.complete, "interrupted": result.interrupted,
                    "computed": result.computed, "skipped": result.skipped, "elapsed_s": result.elapsed_s,
                    "keys": result.keys, "points": result.rows})
    else:
        render_table(console, result, output)
    if result.interrupted:
        state.signal_reported = False
        raise typer.Exit(report_signal(f"{signal_word()}: "
                                       f"{len(result.records)} of {len(points) * starts} tasks finished; "
                                       f"run the same command again to resume"))
