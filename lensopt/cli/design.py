"""``lensopt design`` (CLI layer: rich lives here): the seed's design procedure — rounds of perturbed starts
(multi-start or basin hopping) until the best results agree — with a live table of starts and the
distinct minima found. The engine is ``lensopt.study.procedure``."""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.console import Console, Group
from rich.live import Live
from rich.table import Table
from rich.text import Text

from lensopt.cli.common import (
    JsonOpt,
    SchedulerOpt,
    SeedOpt,
    WorkersOpt,
    check_scheduler,
    console,
    err_console,
    handle_errors,
    print_json,
)
from lensopt.cli.signals import report_signal, signal_word, state

if TYPE_CHECKING:
    from lensopt.study.procedure import ProcedureEvent, ProcedureResult

__all__ = ["DesignProgress", "commands", "render_result"]

commands = typer.Typer()  # its command, put in order by lensopt.cli.app


def _num(v: Any, fmt: str = "{:.4g}") -> str:
    return "—" if v is None or (isinstance(v, float) and not math.isfinite(v)) else fmt.format(v)


class DesignProgress:
    """The starts as they finish (round, start, status, ESR, merit, steps, CPU) and each round's best. A
    rich Live table on a terminal; otherwise one plain line per finished start and per round."""

    def __init__(self, console: Console, *, enabled: bool = True, plain: bool | None = None,
                 rows: int = 12) -> None:
        self.console = console
        self.enabled = enabled
        self.plain = (not console.is_terminal) if plain is None else plain
        self.rows = rows
        self.records: list[dict[str, Any]] = []
        self.rounds: list[dict[str, Any]] = []
        self.t0 = time.monotonic()
        self.live: Live | None = None

    def __enter__(self) -> DesignProgress:
        if self.enabled and not self.plain:
            self.live = Live(self._render(), console=self.console, refresh_per_second=2, transient=False)
            self.live.__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        if self.live is not None:
            self.live.update(self._render())
            self.live.__exit__(None, None, None)

    def __call__(self, e: ProcedureEvent) -> None:
        if e.kind == "round":
            self.rounds.append(e.record)
        else:
            self.records.append(e.record)
        if not self.enabled:
            return
        if self.live is not None:
            self.live.update(self._render())
        elif e.kind == "round":
            r = e.record
            self.console.print(f"round {r['round']}: best merit {_num(r['best_merit'], '{:.6e}')} ({r['best']}), "
                               f"{r['agreeing']} start(s) agree, {r['cpu_s'] / 3600:.2f} CPU-h", highlight=False,
                               markup=False)
        elif e.kind == "done":
            self.console.print(self._line(e.record), highlight=False, markup=False)

    @staticmethod
    def _line(r: dict[str, Any]) -> str:
        if r.get("status") != "finished":
            return f"start {r['name']} (round {r.get('round')}): failed — {r.get('reason', '')}"
        return (f"start {r['name']} (round {r.get('round')}): ESR {_num(r.get('esr_um'))} µm (seed's measure "
                f"{_num(r.get('seed_esr_um'))} µm), merit "
                f"{_num(r.get('merit'), '{:.6e}')}, {r.get('steps')} steps, {_num(r.get('cpu_s'), '{:.0f}')} s CPU")

    def _render(self) -> Group:
        t = Table(title=f"lensopt design — {len(self.records)} start(s), {time.monotonic() - self.t0:.0f} s",
                  header_style="bold")
        for col in ("start", "round", "status", "ESR µm", "seed's\nESR µm", "merit", "steps", "CPU s"):
            t.add_column(col, justify="right")
        ranked = sorted(self.records, key=lambda r: (r.get("status") != "finished",
                                                      r.get("merit") if r.get("merit") is not None else math.inf))
        for r in ranked[:self.rows]:
            ok = r.get("status") == "finished"
            t.add_row(r["name"], str(r.get("round")), "ok" if ok else "[red]failed[/]", _num(r.get("esr_um")),
                      _num(r.get("seed_esr_um")), _num(r.get("merit"), "{:.6e}"), str(r.get("steps", "—")),
                      _num(r.get("cpu_s"), "{:.0f}"))
        parts: list[Any] = [t]
        if len(ranked) > self.rows:
            parts.append(Text(f"… {len(ranked) - self.rows} more (worse) start(s)"))
        if self.rounds:
            r = self.rounds[-1]
            parts.append(Text(f"after round {r['round']}: {r['agreeing']} start(s) within the agreement tolerance "
                              f"of the best ({r['best']})"))
        return Group(*parts)


def render_result(console: Console, result: ProcedureResult, outdir: Path) -> None:
    """The distinct minima found and why the run stopped."""
    t = Table(title="distinct local minima (by final merit)", header_style="bold")
    for col in ("rank", "merit", "ESR µm", "seed's\nESR µm", "starts", "best start"):
        t.add_column(col, justify="right")
    for m in result.minima[:10]:
        t.add_row(str(m["rank"]), f"{m['merit']:.6e}", _num(m["esr_um"]), _num(m.get("seed_esr_um")), str(m["count"]),
                  m["best"])
    console.print(t)
    extra = f"; {len(result.minima) - 10} more" if len(result.minima) > 10 else ""
    console.print(f"{result.rounds} round(s), {len(result.records)} start(s), {result.cpu_s / 3600:.2f} CPU-h, "
                  f"{result.elapsed_s:.0f} s; {result.stop_reason}{extra}", highlight=False)
    if result.best is not None:
        console.print(f"best: start {result.best['name']}, ESR {_num(result.best.get('esr_um'))} µm (seed's "
                      f"measure {_num(result.best.get('seed_esr_um'))} µm); wrote {outdir}/best.json and design.json",
                      highlight=False)


@commands.command("design", short_help="The seed's design procedure: rounds of perturbed starts (multi-start or "
                                      "basin hopping) until the best agree; resumable.")
@handle_errors
def design(
    spec: Annotated[Path, typer.Argument(help="Lens spec (.toml or .json) with vary lists and an optimize "
                                         "section.")],
    output: Annotated[Path, typer.Option("--output", "-o", help="Folder for the run (resumed when it holds "
                                         "the same run).")],
    method: Annotated[str, typer.Option("--method", help="multistart (every round from the spec's start) or "
                                        "basin (rounds after the first hop from each chain's best).")]
    = "multistart",
    starts: Annotated[int, typer.Option("--starts", min=1, max=1000, help="Starts per round (basin: chains).")]
    = 4,
    rounds: Annotated[int, typer.Option("--rounds", min=1, max=1000, help="Most rounds.")] = 3,
    agree: Annotated[float, typer.Option("--agree", min=0.0, help="Relative merit tolerance: the run stops when "
                                         "--agree-count starts reach the best merit within it.")] = 0.02,
    agree_count: Annotated[int, typer.Option("--agree-count", min=1, help="Starts that must agree.")] = 2,
    perturb: Annotated[float, typer.Option("--perturb", min=0.0, help="Relative Gaussian perturbation of the "
                                           "scaled variables (starts ≥ 1).")] = 0.05,
    hop: Annotated[float, typer.Option("--hop", min=0.0, help="basin: the relative perturbation of a hop.")]
    = 0.02,
    steps: Annotated[int | None, typer.Option("--steps", min=1, help="Optimizer steps per start (default: the "
                                              "spec's).")] = None,
    budget_cpu_h: Annotated[float | None, typer.Option("--budget-cpu-h", help="Stop starting rounds once the "
                                                       "starts used this many CPU-hours.")] = None,
    scheduler: SchedulerOpt = "auto",
    workers: WorkersOpt = 2,
    restart: Annotated[bool, typer.Option("--restart", help="Start over in a folder that holds another run "
                                          "(its files are removed).")] = False,
    esr_sampling: Annotated[str, typer.Option("--esr-sampling", help="Pupil sampling of the reported ESR.")]
    = "rings:24",
    seed: SeedOpt = 0,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress display.")] = False,
    as_json: JsonOpt = False,
) -> None:
    """Optimize SPEC from --starts perturbed starts per round (both phases: glasses free, then bound), round
    after round, until --agree-count starts reach the best merit (within --agree) or --rounds / the CPU
    budget run out; list the distinct minima; write design.json and best.json. Run it again to resume."""
    from lensopt.errors import LensoptError
    from lensopt.optics.sampling import PupilSampling
    from lensopt.spec import load_spec
    from lensopt.study.procedure import ProcedureSettings, run_procedure

    sched = check_scheduler(scheduler)
    base = load_spec(spec)
    try:
        text = spec.read_text(encoding="utf-8")
    except OSError as err:
        raise LensoptError(f"cannot read the file: {err.strerror}", path=str(spec)) from None
    PupilSampling.parse(esr_sampling, seed=seed, path="--esr-sampling")
    settings = ProcedureSettings(method=method, starts=starts, rounds=rounds, agree=agree, agree_count=agree_count,
                                 sigma=perturb, hop_sigma=hop, steps=steps, seed=seed, budget_cpu_h=budget_cpu_h,
                                 esr_sampling=esr_sampling)
    with DesignProgress(err_console, enabled=not quiet) as progress:
        result = run_procedure(base, text, settings, output, scheduler=sched, workers=workers, restart=restart,
                               callback=progress)
    if as_json:
        print_json({"output": str(output), "rounds": result.rounds, "agreed": result.agreed,
                    "stop_reason": result.stop_reason, "interrupted": result.interrupted, "cpu_s": result.cpu_s,
                    "elapsed_s": result.elapsed_s, "best": None if result.best is None else result.best["name"],
                    "minima": result.minima, "starts": result.records})
    else:
        render_result(console, result, output)
    if result.interrupted:
        state.signal_reported = False
        raise typer.Exit(report_signal(f"{signal_word()}: {len(result.records)} start(s) finished and kept; run the "
                                       "same command again to resume"))
