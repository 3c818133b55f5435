"""Signals of the ``lensopt`` command: the one home of Ctrl-C and SIGTERM handling (CLI layer; imports only
the standard library, so that ``lensopt/__main__.py`` installs the process part before anything slow loads).

The contract (README, "Errors and exit codes"): Ctrl-C exits 130 and SIGTERM 143, with exactly one line,
whenever the signal comes.

Inside a command (``command_signals``, installed by ``common.LensoptGroup``), the signal becomes an
exception (``Interrupted`` / ``Terminated``) so that the command can keep its best state;
``signals_deferred`` holds signals while a result is written; ``stop_on_signals`` turns them into a flag
that long runs check at step boundaries (train-irm, the joint optimization).

Outside a command there are three windows, handled by ``install`` and only in the real process
(``lensopt …``, ``python -m lensopt …``, ``torchrun … -m lensopt``): in-process runs (typer's CliRunner,
an embedding program) keep their own signal handling and see none of this.

1. Startup, while the modules load (before the command's handlers are installed), and 2. the end,
after the command returned, while Python joins threads and runs its exit functions: the signal prints
its line (unless the command already printed one) and ends the process at once with 130 / 143.
3. After the last exit function, ``commit_exit`` sets both signals to "ignore": Python's teardown
resets handlers to the default disposition (that was the "−2 with no line" at shutdown), so a signal
there would kill the finished process. From that point the exit status is the command's, already
decided; a signal later than that is too late to change it.

Why the signals raise ``Interrupted``/``Terminated`` and not ``KeyboardInterrupt`` itself: CPython 3.11
sets a process-wide "unhandled KeyboardInterrupt" flag whenever an exception of exactly that type leaves
code run by ``exec(string)`` (``dataclasses``, ``typing`` and torch's imports do that) — even when the
program catches it later — and ``python -m`` then kills itself with SIGINT at exit whatever ``sys.exit``
said: the "interrupted" line followed by returncode −2. A subclass is caught by every
``except KeyboardInterrupt`` but does not trip that flag.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import signal
import sys
from collections.abc import Iterator
from typing import Any

__all__ = ["EX_SIGINT", "EX_SIGTERM", "Interrupted", "Terminated", "command_signals", "commit_exit", "install",
           "is_cli_process", "report_signal", "signal_word", "signals_deferred", "state", "stop_on_signals",
           "stopped_at_step_boundary"]

EX_SIGINT, EX_SIGTERM = 130, 143


class Interrupted(KeyboardInterrupt):
    """Ctrl-C (SIGINT). A subclass so that CPython does not take it for an unhandled KeyboardInterrupt."""


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C so that every ``except KeyboardInterrupt`` keeps the best state."""


class _State:
    verbose = False
    signal_exit = EX_SIGINT  # the exit code of the last signal received
    signal_received = False  # a signal came while the command ran (its exit code wins over what followed)
    signal_reported = False  # its one line is printed


state = _State()


def is_cli_process(argv: list[str] | None = None, orig_argv: list[str] | None = None) -> bool:
    """Whether this process is the ``lensopt`` command: the console script or ``python -m lensopt``."""
    argv = getattr(sys, "argv", []) if argv is None else argv
    orig = getattr(sys, "orig_argv", argv) if orig_argv is None else orig_argv
    script = argv[0].replace("\\", "/").rsplit("/", 1)[-1] if argv else ""
    return script in ("lensopt", "lensopt.exe") or any(
        a == "-m" and i + 1 < len(orig) and orig[i + 1] == "lensopt" for i, a in enumerate(orig))


def _exit_on_signal(signum: int, frame: Any) -> None:
    """Outside a command: the line (once), what the command already printed, and the exit code, at once."""
    code = EX_SIGTERM if signum == signal.SIGTERM else EX_SIGINT
    if state.signal_reported:  # a signal already ended the command and printed its line
        code = state.signal_exit
    else:
        for stream in (sys.stdout, sys.stderr):  # a finished command's output is complete
            try:
                stream.flush()
            except Exception:  # noqa: BLE001 - closed, a broken pipe, or a write this handler interrupted
                pass
        try:
            os.write(2, b"terminated\n" if code == EX_SIGTERM else b"interrupted\n")
        except OSError:
            pass
    os._exit(code)


def commit_exit() -> None:
    """The process's last exit function: signals are ignored from here on (see the module doc, window 3).
    ``signal.signal`` first runs the handler of a signal that has already arrived, so none is lost."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            signal.signal(sig, signal.SIG_IGN)
        except (ValueError, OSError):  # pragma: no cover - not the main thread
            pass


def install() -> None:
    """Windows 1–3 for the real process. Called by ``lensopt/__main__.py`` (the ``lensopt`` command's entry)
    before other imports, so that ``commit_exit`` is the first exit function registered, hence the last to
    run."""
    try:
        signal.signal(signal.SIGINT, _exit_on_signal)
        signal.signal(signal.SIGTERM, _exit_on_signal)
    except ValueError:  # pragma: no cover - not the main thread
        return
    atexit.register(commit_exit)


# ------------------------------------------------------------------------------- inside a command


def signal_word() -> str:
    """``terminated`` (SIGTERM) or ``interrupted`` (Ctrl-C): the last signal received."""
    return "terminated" if state.signal_exit == EX_SIGTERM else "interrupted"


def report_signal(line: str | None = None) -> int:
    """Print the one line for the signal received (once, on stderr) and return its exit code (130 or 143)."""
    if not state.signal_reported:
        state.signal_reported = True
        sys.stderr.write((line or signal_word()) + "\n")
        sys.stderr.flush()
    return state.signal_exit


# Raising from a signal handler is safe in Python code, not while a module is being imported: extension
# modules run their initialisation through Python callbacks that cannot pass an exception on (torch's
# pybind11 code then calls std::terminate — exit −6 —, numpy's cannot be imported again). A signal that
# lands inside an import is delivered again RETRY_S later, until the import is over.
RETRY_S = 0.01
_retry_signal: list[int] = []
_retrying: list[bool] = []  # per nested command_signals: whether signals are retried (the real process)
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
    _deliver(signum, frame, Interrupted, EX_SIGINT)  # not KeyboardInterrupt itself: see the module doc


@contextlib.contextmanager
def command_signals(retry: bool | None = None) -> Iterator[None]:
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


@contextlib.contextmanager
def stop_on_signals() -> Iterator[list[bool]]:
    """Yield a flag list set on the first Ctrl-C or SIGTERM (the run stops at the next step boundary and
    checkpoints); a second Ctrl-C interrupts at once."""
    flag = [False]
    old = {}

    def handler(signum: int, frame: Any) -> None:
        if flag[0] and signum == signal.SIGINT:
            raise Interrupted  # not KeyboardInterrupt itself: see the module doc
        state.signal_exit, state.signal_received = (EX_SIGTERM if signum == signal.SIGTERM else EX_SIGINT), True
        flag[0] = True

    for sig in (signal.SIGINT, signal.SIGTERM):
        old[sig] = signal.signal(sig, handler)
    try:
        yield flag
    finally:
        for sig, h in old.items():
            signal.signal(sig, h)


def stopped_at_step_boundary() -> int:
    """Exit code of a run stopped by a signal at a step boundary (130 Ctrl-C, 143 SIGTERM), its line printed."""
    return report_signal(f"{signal_word()}: stopped at a step boundary, checkpoint written")
