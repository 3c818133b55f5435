"""``lensopt optimize`` (CLI layer: rich lives here, no physics): the command, the live progress
display and the final summary."""

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
    EX_VIOLATED,
    JsonOpt,
    SeedOpt,
    check_output,
    console,
    err_console,
    handle_errors,
    make_engine,
    print_json,
)
from lensopt.cli.signals import report_signal, signal_word, signals_deferred, state
from lensopt.errors import LensoptError

if TYPE_CHECKING:
    from lensopt.engine import Engine
    from lensopt.optim.driver import OptimizeResult, Progress

__all__ = ["LiveProgress", "commands", "plain_line", "render_summary", "summary"]

commands = typer.Typer()  # its command, put in order by lensopt.cli.app


class LiveProgress:
    """A rich Live display fed with ``Progress`` records (refreshed at most ~8 times a second)."""

    def __init__(self, console: Console, *, enabled: bool = True, plain: bool | None = None,
                 interval_s: float = 10.0) -> None:
        self.console = console
        self.enabled = enabled
        # Not a terminal (CI logs, files): plain lines, at most one per ``interval_s``, plus the last step.
        self.plain = (not console.is_terminal) if plain is None else plain
        self.interval_s = interval_s
        self.live: Live | None = None
        self.last: Progress | None = None
        self.events: list[str] = []
        self._shown = 0.0
        self._printed = -math.inf
        self._events_shown = 0

    def __enter__(self) -> LiveProgress:
        if self.enabled and not self.plain:
            self.live = Live(Text("starting…"), console=self.console, refresh_per_second=8, transient=False)
            self.live.__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        if self.live is not None:
            if self.last is not None:
                self.live.update(self._render(self.last))
            self.live.__exit__(None, None, None)

    def __call__(self, p: Progress) -> None:
        self.last = p
        if self.live is None and p.step == 1:
            self.console.print("running… (Ctrl-C keeps the best lens so far)", highlight=False)
        if p.event and p.event != "merit rose":
            self.events.append(f"step {p.step}: {p.event}")
        now = time.monotonic()
        if self.enabled and self.plain and (now - self._printed >= self.interval_s or p.step == p.steps):
            self._printed = now
            new = self.events[self._events_shown:]
            self._events_shown = len(self.events)
            note = f"; {len(new)} event(s), last {new[-1]}" if new else ""
            self.console.print(plain_line(p) + note, highlight=False, soft_wrap=True, markup=False)
        if self.live is not None and (now - self._shown > 0.12 or p.step == p.steps):
            self._shown = now
            self.live.update(self._render(p))

    def _render(self, p: Progress) -> Group:
        t = Table(show_header=True, header_style="bold", title=f"lensopt optimize — {p.phase}")
        image = p.image_loss == p.image_loss
        cols = ["step", "merit ½‖ℓ‖²"] + (["image loss", "PSNR dB"] if image else [])
        for col in cols + ["λ", "ESR µm", "accepted", "rejected", "rays ok", "wall s"]:
            t.add_column(col, justify="right")
        lam = "—" if p.damping != p.damping else f"{p.damping:.2e}"
        extra = [f"{p.image_loss:.4e}", f"{p.psnr_db:.2f}"] if image else []
        t.add_row(f"{p.step}/{p.steps}", f"{p.merit:.6e}", *extra, lam, f"{p.esr_um:.3f}", str(p.accepted),
                  str(p.rejected), f"{100 * p.valid_fraction:.1f} %", f"{p.elapsed_s:.0f}")
        shares = Table(show_header=True, header_style="bold", title="share of the merit")
        names = [n for n, v in p.shares.items() if v > 0 or n == "tra"]
        for n in names:
            shares.add_column(n, justify="right")
        shares.add_row(*[f"{100 * p.shares[n]:.2f} %" for n in names])
        notes = Text("\n".join(self.events[-4:]))
        return Group(t, shares, notes)


def plain_line(p: Progress) -> str:
    """One progress line for logs: ``step 12/200 [phase] merit 1.234e-02, ESR 12.345 µm, …``."""
    lam = "—" if p.damping != p.damping else f"{p.damping:.2e}"
    esr = "—" if not math.isfinite(p.esr_um) else f"{p.esr_um:.3f} µm"
    rays = "—" if not math.isfinite(p.valid_fraction) else f"{100 * p.valid_fraction:.1f} %"
    image = f", image loss {p.image_loss:.4e}, PSNR {p.psnr_db:.2f} dB" if math.isfinite(p.image_loss) else ""
    return (f"step {p.step}/{p.steps} [{p.phase}] merit {p.merit:.6e}{image}, ESR {esr}, λ {lam}, "
            f"accepted {p.accepted}, rejected {p.rejected}, rays ok {rays}, {p.elapsed_s:.0f} s")


def summary(result: OptimizeResult, start: dict[str, Any], final: dict[str, Any],
            constraints: dict[str, Any], output: str,
            seed_esr_um: tuple[float | None, float | None] = (None, None)) -> dict[str, Any]:
    """The machine-readable summary (``--json``): start and final trace reports of the written lens, and
    both lenses' ESR on the seed's measure (``seed_esr_um``: start, final; ``analysis.report.seed_esr_um``)."""
    from lensopt.analysis.spot import SEED_FIELDS, SEED_SAMPLING

    return {
        "output": output,
        "steps": result.steps,
        "stop_reason": result.stop_reason,
        "interrupted": result.interrupted,
        "elapsed_s": result.elapsed_s,
        "start": {"effective_spot_radius_um": start["effective_spot_radius_um"], "seed_esr_um": seed_esr_um[0],
                  "first_order": start["first_order"]},
        "final": {"effective_spot_radius_um": final["effective_spot_radius_um"], "seed_esr_um": seed_esr_um[1],
                  "first_order": final["first_order"], "fields": final["fields"], "sampling": final["sampling"]},
        "seed_measure": {"fields": SEED_FIELDS, "sampling": SEED_SAMPLING},
        "bound_glasses": [{"surface": b.surface, "name": b.name,
                           "material": b.material if isinstance(b.material, str) else b.material.model_dump(),
                           "distance": b.distance} for b in result.bound],
        "constraints": constraints,
        "warning": result.warning,
        "held_out_psnr_db": {"start": result.start_psnr_db, "final": result.final_psnr_db},
        "image_history": [list(h) for h in result.image_history],
        "history": [list(h) for h in result.history],
    }


def _um(v: float | None) -> str:
    return "— (rays fail)" if v is None else f"{v:.4f} µm"


def render_summary(console: Console, s: dict[str, Any]) -> None:
    """Final tables: spot size start → end, first-order data, constraint values, glasses."""
    fin, st = s["final"], s["start"]
    head = "interrupted — best lens so far" if s["interrupted"] else f"stopped: {s['stop_reason']}"
    console.print(f"[bold]{head}[/] after {s['steps']} steps, {s['elapsed_s']:.1f} s; written to {s['output']}")
    console.print(f"effective spot radius ({fin['sampling']}): {_um(st['effective_spot_radius_um'])} → "
                  f"[bold]{_um(fin['effective_spot_radius_um'])}[/]")
    m = s["seed_measure"]
    console.print(f"ESR, seed's measure ({m['fields']} fields, {m['sampling']}): {_um(st['seed_esr_um'])} → "
                  f"[bold]{_um(fin['seed_esr_um'])}[/]")
    psnr = s.get("held_out_psnr_db", {})
    if psnr and psnr["start"] is not None and psnr["start"] == psnr["start"]:  # NaN (None in --json): no image
        console.print(f"held-out raw PSNR: {psnr['start']:.3f} dB → [bold]{psnr['final']:.3f} dB[/]")
    fo = fin["first_order"]
    console.print(f"EFL {fo['efl']:.6f} mm, f/{fo['fnumber']:.4f}, total track {fo['total_track']:.4f} mm, "
                  f"paraxial image height {fo['paraxial_image_height']:.4f} mm")
    c = s["constraints"]
    if "gaps" in c:
        t = Table(title=f"ray path per gap (mm; {c['sampling']}, valid rays)", header_style="bold")
        for col in ("gap", "kind", "centre", "min t_z", "max t_z", "bounds", "ok"):
            t.add_column(col, justify="right")
        for g in c["gaps"]:
            upper = "∞" if g["upper"] is None else f"{g['upper']:.3f}"
            t.add_row(str(g["gap"]), g["kind"], f"{g['centre']:.4f}", f"{g['min']:.4f}", f"{g['max']:.4f}",
                      f"[{g['lower']:.3f}, {upper}]", "yes" if g["satisfied"] else "[red]no[/]")
        console.print(t)
    dist = max(abs(v) for v in c["distortion_percent"])
    console.print(f"max angle of incidence/refraction {c['max_angle_deg']:.2f}°, max surface normal "
                  f"{c['max_normal_deg']:.2f}°, max |distortion| {dist:.3f} %, min relative illumination "
                  f"{min(c['relative_illumination']):.3f}, failed rays {c['failed_rays']}/{c['rays']}")
    mats = ", ".join(f"{m['material']} (nd {m['nd']:.5f}, vd {m['vd']:.2f})" for m in c["materials"])
    console.print(f"materials: {mats}")
    console.print("constraints satisfied: " + ("[green]yes[/]" if c["satisfied"] else "[red]no[/]"))
    if s["warning"]:
        console.print(f"[yellow]warning:[/] {s['warning']}")


@commands.command("optimize", short_help="Optimize a spec (LM or Adam); Ctrl-C or SIGTERM keeps the best lens.")
@handle_errors
def optimize(
    spec: Annotated[Path, typer.Argument(help="Lens spec (.toml or .json) with vary lists and an optimize "
                                         "section.")],
    output: Annotated[Path, typer.Option("--output", "-o", help="Where to write the optimized lens (.json).")],
    optimizer: Annotated[str | None, typer.Option("--optimizer", help="lm | adam (default: the spec's).")] = None,
    steps: Annotated[int | None, typer.Option("--steps", min=1, help="Steps (default: the spec's).")] = None,
    seed: SeedOpt = 0,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No live display.")] = False,
    as_json: JsonOpt = False,
    device: Annotated[str, typer.Option("--device", help="cpu | cuda | cuda:N | auto: where the optimization "
                                        "runs.")] = "cpu",
    jacobian: Annotated[str, typer.Option("--jacobian", help="eager | compiled (LM Jacobian; compiled: same "
                                          "values, faster steps; built once per problem and machine, "
                                          "minutes, then loaded).")] = "eager",
    full_weight: Annotated[bool, typer.Option("--full-weight", help="No weight schedules: every constraint "
                                              "group at the weight its schedule ends on from the first "
                                              "step (to continue a written lens); the written lens keeps "
                                              "the schedules.")] = False,
    checkpoint: Annotated[Path | None, typer.Option("--checkpoint", help="Checkpoint folder: the run's state "
                                                    "(θ, damping, schedule position, bound glasses; restored: "
                                                    "the network too), written every 30 s, at the end and on "
                                                    "Ctrl-C or SIGTERM (restored, by default: OUTPUT with the "
                                                    "suffix .irm, e.g. out.irm/ beside out.json).")] = None,
    resume: Annotated[bool, typer.Option("--resume", help="Continue the run in --checkpoint (the same spec and "
                                         "options): the lens is the uninterrupted run's, bit for bit.")] = False,
    log_dir: Annotated[Path | None, typer.Option("--log-dir", help="restored: TensorBoard folder.")] = None,
    allow_violations: Annotated[bool, typer.Option("--allow-violations", help="Exit 0 when the written lens "
                                                   "violates its constraints (default: exit 3, the lens "
                                                   "written all the same).")] = False,
) -> None:
    """Levenberg–Marquardt (or Adam) for spot size with solves and constraints; Ctrl-C keeps the best lens."""
    from lensopt.design import optimize as run_optimize
    from lensopt.spec import load_spec, save_json

    if output.suffix.lower() != ".json":
        raise LensoptError("the optimized lens is written as .json", path="--output", got=str(output))
    check_output(output)
    start_spec = load_spec(spec)
    engine = make_engine(retain_freed_memory=True)
    if start_spec.optimize is not None and start_spec.optimize.objective == "restored":
        if full_weight:
            raise LensoptError("applies to the spot and raw objectives (restored has no weight schedules)",
                               path="--full-weight")
        from lensopt.cli.restore import optimize_restored

        return optimize_restored(start_spec, output, steps=steps, seed=seed, checkpoint=checkpoint, resume=resume,
                                 device=device, log_dir=log_dir, quiet=quiet, as_json=as_json, engine=engine)
    if jacobian == "compiled" and not quiet:
        err_console.print("compiled LM Jacobian: loaded from this machine's package for the problem, or built at "
                          "the first step of each phase when there is none (minutes of CPU; `lensopt "
                          "warmup SPEC --jacobian` builds the first phase's ahead)", highlight=False)
    try:
        with LiveProgress(err_console, enabled=not quiet) as live:
            result = run_optimize(start_spec, optimizer=optimizer, steps=steps, seed=seed, callback=live,
                                  device=device, jacobian=jacobian, full_weight=full_weight, engine=engine,
                                  checkpoint=checkpoint, resume=resume)
    except KeyboardInterrupt:  # Ctrl-C or SIGTERM before the first step: the best lens is the start lens
        with signals_deferred():
            save_json(start_spec, output)
        line = f"{signal_word()} before the first step; wrote the start lens to {output}"
        raise typer.Exit(report_signal(line)) from None
    if checkpoint is not None and not quiet:
        err_console.print(f"wrote {checkpoint}", highlight=False)
    with signals_deferred():  # a second signal waits until the file is complete
        save_json(result.spec, output)  # atomic
    s = _summary_of(start_spec, result, seed, str(output), engine)
    if as_json:
        print_json(s)
    else:
        render_summary(console, s)
    if result.interrupted:  # the summary above says so
        state.signal_reported = True
        raise typer.Exit(state.signal_exit)
    if not s["constraints"]["satisfied"] and not allow_violations:
        why = ", ".join(s["constraints"]["violated"])
        err_console.print(f"warning: {output} violates its constraints ({why}); "
                          f"exit {EX_VIOLATED} (--allow-violations: 0)", highlight=False, markup=False)
        raise typer.Exit(EX_VIOLATED)


def _summary_of(start_spec: Any, result: OptimizeResult, seed: int, output: str, engine: Engine) -> dict[str, Any]:
    """``summary`` of a finished run: both lenses traced as ``lensopt trace`` does (its default sampling)
    and on the seed's measure, the final lens's constraint margins."""
    from lensopt.analysis.report import seed_esr_um, trace_report
    from lensopt.design import build_problem
    from lensopt.optics.sampling import DEFAULT_REPORT_SAMPLING, PupilSampling
    from lensopt.optim.report import constraint_report
    from lensopt.spec import build

    sampling = PupilSampling.parse(DEFAULT_REPORT_SAMPLING, seed=seed, weighted=True)
    final_problem = build_problem(result.spec, seed=seed, engine=engine)
    start, final = build(start_spec), build(result.spec)
    return summary(result, trace_report(start, sampling, engine=engine), trace_report(final, sampling, engine=engine),
                   constraint_report(final_problem, final_problem.theta0, sampling), output,
                   (seed_esr_um(start, engine=engine), seed_esr_um(final, engine=engine)))
