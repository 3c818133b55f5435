"""What every ``lensopt`` command shares (CLI layer): the consoles, option aliases and their parsing, the
device and backend options, the command's ``Engine`` (``make_engine``), loading a lens, the error
contract (``handle_errors``, ``LensoptGroup``) and output paths. Light on purpose: nothing here imports torch,
so ``lensopt --help`` starts fast. Signals: ``lensopt.cli.signals``.

The contract (README, "Errors and exit codes"): 0 success; 3 ``optimize`` wrote a lens that violates its
constraints (``--allow-violations``: 0); 2 a problem the user can fix, printed as one
line ``error: path.to.field: what is wrong (got X)`` (bad input, usage errors, output paths, memory
budget); 130 Ctrl-C (SIGINT); 143 SIGTERM; 70 an internal error (a bug: one line, ``--verbose`` shows
the traceback). Never a traceback without ``--verbose``.
"""

from __future__ import annotations

import functools
import json
import logging
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, TypeVar

import typer
from rich.console import Console
from rich.markup import escape
from typer.core import TyperGroup

try:  # typer ≥ 0.20 vendors click
    from typer._click import exceptions as click_exc
except ImportError:  # pragma: no cover
    from click import exceptions as click_exc  # type: ignore[no-redef]

from lensopt.cli.signals import EX_SIGINT, command_signals, report_signal, state
from lensopt.cli.tables import fit_width
from lensopt.errors import LensoptError
from lensopt.files import json_safe

if TYPE_CHECKING:
    from lensopt.engine import Engine
    from lensopt.spec import Model

__all__ = ["AimOpt", "AimStepsOpt", "BackendOpt", "DeviceOpt", "EX_INTERNAL", "EX_VIOLATED", "JsonOpt", "LensArg",
           "LensoptGroup", "SchedulerOpt", "WorkersOpt", "check_scheduler",
           "LowerLevelFormatter", "SamplingOpt", "SeedOpt", "check_aim", "check_aim_steps", "check_output",
           "check_seed", "console", "err_console", "handle_errors", "load_model", "parse_frequencies",
           "invocation", "make_engine", "parse_sampling", "print_json"]

EX_USAGE, EX_VIOLATED, EX_INTERNAL = 2, 3, 70
F = TypeVar("F", bound=Callable[..., Any])


# Tables: COLUMNS, else the terminal, else 80 columns (``cli.tables.fit_width``, applied as each command starts).
console = Console(soft_wrap=True)  # lines of text are not cut into lines; tables fit the width
err_console = Console(stderr=True, width=None if sys.stderr.isatty() else 1000)


def check_seed(value: int | None) -> int | None:
    """typer callback: a seed torch and numpy accept (0 … 2**63 − 1)."""
    if value is not None and not 0 <= value < 2**63:
        raise typer.BadParameter(f"must be an integer from 0 to 2**63 - 1 (got {value})")
    return value


LensArg = Annotated[Path, typer.Argument(help="Lens spec (.toml) or resolved lens (.json).", show_default=False)]
SamplingOpt = Annotated[str, typer.Option("--sampling", help="Pupil sampling: gauss:N (weighted quadrature, 2N² "
                                          "rays), rings:N[:nojitter] (the seed's rings) or grid:N.")]
AimOpt = Annotated[str | None, typer.Option("--aim", help="Ray aiming: none | chief | full (default: the spec's).")]
AimStepsOpt = Annotated[int | None, typer.Option("--aim-steps",
                                                 help="Newton steps of full aiming (default: the spec's).")]
SeedOpt = Annotated[int, typer.Option("--seed", callback=check_seed,
                                      help="Seed of every random draw (pupil jitter), 0 to 2**63 - 1.")]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print one JSON object instead of tables.")]
SchedulerOpt = Annotated[str, typer.Option("--scheduler", help="auto (serial unless the tasks left after the first "
                                           "are estimated at 30 s or more and 2+ cores are free: then a "
                                           "LocalCluster), local (a Dask LocalCluster of --workers processes), "
                                           "serial, or a Dask scheduler address.")]
WorkersOpt = Annotated[int, typer.Option("--workers", min=1, max=64, help="LocalCluster workers.")]
DeviceOpt = Annotated[str, typer.Option("--device", help="cpu | cuda | cuda:N | auto: where the lens is traced and the "
                                        "images are computed.")]
BackendOpt = Annotated[str, typer.Option(
    "--backend", help="Trace backend: auto (the compiled trace when `lensopt warmup` compiled this lens "
    "structure, else eager) | eager | compiled.")]


def load_model(path: Path, device: Any = None) -> Model:
    """The built lens, its tensors on ``device`` (a torch.device; None: the CPU)."""
    from lensopt.spec import build, load_spec

    return build(load_spec(path), device=device)


def parse_sampling(text: str, seed: int, option: str = "--sampling", *, weighted: bool = True):  # noqa: ANN201
    """``weighted``: the command's statistics read quadrature weights (``gauss:N`` allowed)."""
    from lensopt.optics.sampling import PupilSampling

    return PupilSampling.parse(text, seed=seed, path=option, weighted=weighted)


def check_aim(aim: str | None) -> str | None:
    if aim is not None and aim not in ("none", "chief", "full"):
        raise LensoptError("must be none, chief or full", path="--aim", got=aim)
    return aim


def check_aim_steps(steps: int | None) -> int | None:
    if steps is not None and not 1 <= steps <= 100:
        raise LensoptError("must be an integer from 1 to 100", path="--aim-steps", got=steps)
    return steps


def parse_frequencies(text: str, path: str) -> list[float]:
    """Comma-separated frequencies (cycles/mm), e.g. ``--mtf 10,20``."""
    try:
        return [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise LensoptError("expected comma-separated numbers (cycles/mm)", path=path, got=text) from None


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _rank_prefix() -> str:
    """``rank N: `` under torchrun with two or more processes (every rank reports its own error), else ``""``."""
    try:
        world, rank = int(os.environ.get("WORLD_SIZE", "1")), int(os.environ.get("RANK", "0"))
    except ValueError:
        return ""
    return f"rank {rank}: " if world > 1 else ""


def error_line(message: str) -> None:
    """``error: message`` as one line on stderr (no markup, no wrapping; ``rank N: error: …`` under torchrun).
    The line, newline included, goes out in one write and is flushed, so that the lines of processes sharing
    the stream (torchrun's ranks) never run into each other."""
    with err_console.capture() as captured:
        err_console.print(f"{_rank_prefix()}[bold red]error:[/] {escape(_one_line(message))}", markup=True,
                          highlight=False, soft_wrap=True, emoji=False)
    line = captured.get()
    if not line.endswith("\n"):
        line += "\n"
    stream = err_console.file
    try:
        stream.write(line)
        stream.flush()
    except BrokenPipeError:  # nobody reads stderr any more: the exit code still says it
        pass


def handle_errors(fn: F) -> F:
    """Lensopt errors → one line, exit 2; Ctrl-C → 130 and SIGTERM → 143 with one line; anything else
    (a bug) → one line, exit 70 (``--verbose`` re-raises it with its traceback)."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except (typer.Exit, typer.Abort, click_exc.ClickException):
            raise
        except KeyboardInterrupt:
            raise typer.Exit(report_signal()) from None
        except BrokenPipeError:
            raise typer.Exit(0) from None
        except Exception as err:
            if state.signal_received:  # what the signal cut short failed after it (e.g. an import cut in half)
                raise typer.Exit(report_signal()) from None
            if isinstance(err, LensoptError):
                error_line(str(err))
                raise typer.Exit(EX_USAGE) from None
            if isinstance(err, RecursionError):
                error_line("input nested too deeply")
                raise typer.Exit(EX_USAGE) from None
            if isinstance(err, MemoryError):
                error_line("out of memory; lower the sampling, image size or grid (see --max-memory)")
                raise typer.Exit(EX_USAGE) from None
            if state.verbose:
                raise
            error_line(f"internal error ({type(err).__name__}: {err}); please report it, with the command and "
                       "input; --verbose shows the traceback")
            raise typer.Exit(EX_INTERNAL) from None

    return wrapper  # type: ignore[return-value]


def make_engine(backend: str | None = None, *, report_compiles: bool | None = None,
                retain_freed_memory: bool = False) -> Engine:
    """The command's ``Engine`` (``lensopt.engine``), made once per command from its options and the
    environment: the trace backend is ``backend`` (the command's ``--backend``), else ``$LENSOPT_BACKEND``,
    else auto; the memory budget is the root ``--max-memory``, else ``$LENSOPT_MAX_MEMORY``, else the
    default. ``report_compiles`` (default: when the command has ``--backend``) prints a first compilation
    of the trace on stderr."""
    from lensopt import accel
    from lensopt.engine import check_backend, parse_size

    if backend is None:
        name = check_backend(os.environ.get("LENSOPT_BACKEND", "auto"), path="LENSOPT_BACKEND")
    else:
        name = check_backend(backend)
    max_memory = invocation.max_memory
    if max_memory is None and os.environ.get("LENSOPT_MAX_MEMORY"):
        max_memory = parse_size(os.environ["LENSOPT_MAX_MEMORY"], path="LENSOPT_MAX_MEMORY")
    report = backend is not None if report_compiles is None else report_compiles
    return accel.engine(name, max_memory=max_memory, on_compile=_report_compile if report else None,
                        retain_freed_memory=retain_freed_memory)


class _Invocation:
    """The root options of the running ``lensopt`` invocation (set by ``lensopt.cli.app``'s callback, reset
    by ``LensoptGroup.main``)."""

    max_memory: int | None = None  # --max-memory, bytes


invocation = _Invocation()


def _report_compile(desc: str, seconds: float) -> None:
    err_console.print(f"compiled the trace for {desc} in {seconds:.1f} s (first time on this machine; cached on disk)",
                      highlight=False)


class LensoptGroup(TyperGroup):
    """The top-level command group: usage errors as one line, signals, exit codes (see the module doc)."""

    def format_commands(self, ctx: Any, formatter: Any) -> None:
        """Each command's first sentence in full (click cuts it at the terminal width with "...")."""
        rows = []
        for name in self.list_commands(ctx):
            cmd = self.get_command(ctx, name)
            if cmd is not None and not cmd.hidden:
                rows.append((name, cmd.get_short_help_str(limit=10_000)))
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)

    def main(self, args: Any = None, prog_name: str | None = None, complete_var: str | None = None,
             standalone_mode: bool = True, **extra: Any) -> Any:
        code = 0
        state.signal_exit, state.signal_reported, state.signal_received, state.verbose = EX_SIGINT, False, False, False
        fit_width(console, sys.stdout)
        invocation.max_memory = None
        try:
            with command_signals():
                rv = super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
            code = rv if isinstance(rv, int) and not isinstance(rv, bool) else 0
            if code == EX_SIGINT:  # typer turns a KeyboardInterrupt outside the commands into exit 130
                code = report_signal()
        except getattr(click_exc, "NoArgsIsHelpError", ()) as err:  # `lensopt`, `lensopt plot`: the help
            if err.ctx is not None:
                sys.stdout.write(err.ctx.get_help() + "\n")
            code = 0
        except click_exc.ClickException as err:
            hint = ""
            ctx = getattr(err, "ctx", None)
            if ctx is not None and isinstance(err, click_exc.UsageError):
                hint = f" (see {ctx.command_path} --help)"
            error_line(err.format_message() + hint)
            code = err.exit_code
        except (KeyboardInterrupt, typer.Abort):
            code = report_signal()
        except typer.Exit as err:
            code = err.exit_code
        if state.signal_received:  # a signal came during the command: its code and one line, whatever followed
            code = report_signal()
        if not standalone_mode:
            return code
        sys.exit(code)


# ---------------------------------------------------------------------------------- output paths


def check_output(path: Path, suffixes: tuple[str, ...] | None = None, *, option: str = "--output",
                 what: str = "file") -> Path:
    """Check before any work that ``path`` can be written: a supported suffix, not a directory, an existing
    writable parent folder. Raises one ``LensoptError`` naming ``option``."""
    if suffixes is not None and path.suffix.lower() not in suffixes:
        names = ", ".join(suffixes[:-1]) + (" or " if len(suffixes) > 1 else "") + suffixes[-1]
        article = "an" if what[0] in "aeiou" else "a"
        raise LensoptError(f"expected {article} {what} name ending in {names}", path=option, got=str(path))
    if path.is_dir():
        raise LensoptError("is a directory; give a file name", path=option, got=str(path))
    parent = path.parent if str(path.parent) else Path(".")
    probe = parent
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    if not probe.is_dir():
        raise LensoptError(f"{probe} is a file, not a folder", path=option, got=str(path))
    if not os.access(probe, os.W_OK | os.X_OK) or _is_pseudo_fs(probe):
        raise LensoptError(f"cannot write in {probe} (permission denied or read-only)", path=option, got=str(path))
    return path


def _is_pseudo_fs(folder: Path) -> bool:
    """/proc and /sys say writable but refuse new files."""
    parts = folder.resolve().parts
    return len(parts) > 1 and parts[1] in ("proc", "sys")


def print_json(obj: Any) -> None:
    sys.stdout.write(json.dumps(json_safe(obj), indent=2, allow_nan=False) + "\n")


class LowerLevelFormatter(logging.Formatter):
    """Log records as one plain line, ``warning: message``."""

    def format(self, record: logging.LogRecord) -> str:
        return " ".join(super().format(record).split()).replace(record.levelname, record.levelname.lower(), 1)


def check_scheduler(scheduler: str) -> str | None:
    """``--scheduler``: None for serial, else ``auto``, ``local`` or a Dask scheduler address."""
    if scheduler == "serial":
        return None
    if scheduler in ("auto", "local") or "://" in scheduler or (
            ":" in scheduler and scheduler.rsplit(":", 1)[1].isdigit()):
        return scheduler
    raise LensoptError("expected auto, local, serial or a Dask scheduler address (tcp://host:8786)",
                       path="--scheduler", got=scheduler)
