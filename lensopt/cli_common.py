"""What every ``lensopt`` command shares (CLI layer): the consoles, option aliases, the error contract
and signals. Light on purpose: nothing here imports torch, so ``lensopt --help`` starts fast.

The contract (README, "Errors and exit codes"): 0 success; 2 a problem the user can fix, printed as one
line ``error: path.to.field: what is wrong (got X)`` (bad input, usage errors, output paths, memory
budget); 130 Ctrl-C (SIGINT); 143 SIGTERM; 70 an internal error (a bug: one line, ``--verbose`` shows
the traceback). Never a traceback without ``--verbose``.
"""

from __future__ import annotations

import contextlib
import functools
import json
import logging
import os
import signal
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Annotated, Any, TypeVar

import typer
from rich.console import Console
from rich.markup import escape
from typer.core import TyperGroup

try:  # typer ≥ 0.20 vendors click
    from typer._click import exceptions as click_exc
except ImportError:  # pragma: no cover
    from click import exceptions as click_exc  # type: ignore[no-redef]

from lensopt.cli_process import EX_SIGINT, EX_SIGTERM, Interrupted, Terminated, is_cli_process, state
from lensopt.errors import LensoptError
from lensopt.io.files import json_safe

__all__ = ["AimOpt", "AimStepsOpt", "check_seed", "DeviceOpt", "EX_INTERNAL", "JsonOpt", "LensArg", "SamplingOpt",
           "SeedOpt",
           "Interrupted", "Terminated", "check_output", "console", "err_console", "handle_errors", "LensoptGroup",
           "report_signal", "signals_deferred", "state", "print_json", "LowerLevelFormatter"]

EX_USAGE, EX_INTERNAL = 2, 70
F = TypeVar("F", bound=Callable[..., Any])


# Wide enough for tables when the stream is a pipe or a file (rich would assume 80 columns).
console = Console(width=None if sys.stdout.isatty() else 160)
err_console = Console(stderr=True, width=None if sys.stderr.isatty() else 1000)


def check_seed(value: int | None) -> int | None:
    """typer callback: a seed torch and numpy accept (0 … 2**63 − 1)."""
    if value is not None and not 0 <= value < 2**63:
        raise typer.BadParameter(f"must be an integer from 0 to 2**63 - 1 (got {value})")
    return value


LensArg = Annotated[Path, typer.Argument(help="Lens spec (.toml) or resolved lens (.json).", show_default=False)]
SamplingOpt = Annotated[str, typer.Option("--sampling", help="Pupil sampling: rings:N[:nojitter] or grid:N.")]
AimOpt = Annotated[str | None, typer.Option("--aim", help="Ray aiming: none | chief | full (default: the spec's).")]
AimStepsOpt = Annotated[int | None, typer.Option("--aim-steps",
                                                 help="Newton steps of full aiming (default: the spec's).")]
SeedOpt = Annotated[int, typer.Option("--seed", callback=check_seed,
                                      help="Seed of every random draw (pupil jitter), 0 to 2**63 - 1.")]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print one JSON object instead of tables.")]
DeviceOpt = Annotated[str, typer.Option("--device", help="cpu | cuda | cuda:N | auto: where the lens is traced and the "
                                        "images are computed.")]


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def error_line(message: str) -> None:
    """``error: message`` as one line on stderr (no markup, no wrapping)."""
    err_console.print(f"[bold red]error:[/] {escape(_one_line(message))}", markup=True, highlight=False, soft_wrap=True,
                      emoji=False)


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


# ------------------------------------------------------------------------------------- signals


def report_signal(line: str | None = None) -> int:
    """Print the one line for the signal received (once) and return its exit code (130 or 143)."""
    if not state.signal_reported:
        state.signal_reported = True
        text = line or ("terminated" if state.signal_exit == EX_SIGTERM else "interrupted")
        err_console.print(text, highlight=False, markup=False, soft_wrap=True)
    return state.signal_exit


# Raising from a signal handler is safe in Python code, not while a module is being imported: extension
# modules run their initialisation through Python callbacks that cannot pass an exception on (torch's
# pybind11 code then calls std::terminate — exit −6 —, numpy's cannot be imported again). A signal that
# lands inside an import is delivered again RETRY_S later, until the import is over.
RETRY_S = 0.01
_retry_signal: list[int] = []
_retrying: list[bool] = []  # per nested _signal_handlers: whether signals are retried (the real process)
_unraisable_hooks: list[Any] = []  # the hook in force before the command's


def _in_import(frame: Any) -> bool:
    while frame is not None:
        if frame.f_code.co_filename.startswith("<frozen importlib._bootstrap"):
            return True
        frame = frame.f_back
    return False


def _deliver(signum: int, frame: Any, exc: type[KeyboardInterrupt], code: int) -> None:
    state.signal_exit, state.signal_received = code, True
    if _retrying and _retrying[-1] and _in_import(frame):
        _retry_signal[:] = [signum]
        signal.setitimer(signal.ITIMER_REAL, RETRY_S)  # → _on_retry
        return
    raise exc()


def _on_retry(signum: int, frame: Any) -> None:
    """SIGALRM: deliver the deferred signal again, to whatever handler is in force now."""
    if _retry_signal:
        signal.raise_signal(_retry_signal.pop())


def _on_unraisable(unraisable: Any) -> None:
    """A signal's exception raised inside a finalizer (``__del__``, a weakref or gc callback), where Python
    can only print it and drop it: deliver the signal again instead, outside the finalizer."""
    exc = unraisable.exc_value
    if isinstance(exc, Interrupted | Terminated) and _retrying and _retrying[-1]:
        _retry_signal[:] = [signal.SIGTERM if isinstance(exc, Terminated) else signal.SIGINT]
        signal.setitimer(signal.ITIMER_REAL, RETRY_S)
        return
    (_unraisable_hooks[-1] if _unraisable_hooks else sys.__unraisablehook__)(unraisable)


def _on_sigterm(signum: int, frame: Any) -> None:
    _deliver(signum, frame, Terminated, EX_SIGTERM)


def _on_sigint(signum: int, frame: Any) -> None:
    _deliver(signum, frame, Interrupted, EX_SIGINT)  # not KeyboardInterrupt itself: see lensopt/cli_process.py


@contextlib.contextmanager
def _signal_handlers(retry: bool | None = None) -> Iterator[None]:
    """SIGINT → Interrupted, SIGTERM → Terminated (both KeyboardInterrupts) while a command runs. With
    ``retry`` (default: in the real ``lensopt`` process only, so that in-process runs keep their SIGALRM
    and unraisable hook), a signal inside an import or a finalizer is delivered again when it can be
    raised (SIGALRM, ``RETRY_S``)."""
    retry = (is_cli_process() if retry is None else retry) and hasattr(signal, "setitimer")
    handlers = [(signal.SIGINT, _on_sigint), (signal.SIGTERM, _on_sigterm)]
    if retry:
        handlers.append((signal.SIGALRM, _on_retry))
    try:
        old = {s: signal.signal(s, h) for s, h in handlers}
    except ValueError:  # not the main thread (an embedding application): leave signals alone
        yield
        return
    _retrying.append(retry)
    if retry:
        _unraisable_hooks.append(sys.unraisablehook)
        sys.unraisablehook = _on_unraisable
    try:
        yield
    finally:
        if retry:
            signal.setitimer(signal.ITIMER_REAL, 0)  # a retry not yet due: the exit code already says it
            _retry_signal.clear()
            sys.unraisablehook = _unraisable_hooks.pop()
        _retrying.pop()
        for s, h in old.items():
            signal.signal(s, h)


@contextlib.contextmanager
def signals_deferred() -> Iterator[None]:
    """Hold SIGINT and SIGTERM until the block ends (then the first one is acted on), e.g. while writing the
    result. The Python handlers are swapped, not the thread's signal mask: a process-directed signal may
    land on any thread (torch's workers), and a mask would be inherited by subprocesses."""
    held: list[int] = []

    def hold(signum: int, frame: Any) -> None:
        held.append(signum)

    try:
        old = {s: signal.signal(s, hold) for s in (signal.SIGINT, signal.SIGTERM)}
    except ValueError:  # not the main thread: leave signals alone
        yield
        return
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        if held:
            handler = old[held[0]]
            if callable(handler):
                handler(held[0], None)
            elif handler == signal.SIG_DFL:
                signal.raise_signal(held[0])


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
        try:
            with _signal_handlers():
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
