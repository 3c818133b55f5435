"""Signals of the ``lensopt`` process itself, outside the commands (CLI layer, imports only the standard
library: ``lensopt/__init__.py`` installs it before anything else is imported).

The contract (README, "Errors and exit codes"): Ctrl-C exits 130 and SIGTERM 143, with exactly one line,
whenever the signal comes. Inside a command, ``cli_common`` turns the signal into an exception so that
the command can keep its best state. Outside it there are three windows, handled here, and only in the
real process (``lensopt …``, ``python -m lensopt …``, ``torchrun … -m lensopt``): in-process runs
(typer's CliRunner, an embedding program) keep their own signal handling and see none of this.

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
import os
import signal
import sys
from typing import Any

__all__ = ["EX_SIGINT", "EX_SIGTERM", "Interrupted", "Terminated", "commit_exit", "install", "is_cli_process",
           "state"]

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
    """Windows 1–3 for the real process. Called from ``lensopt/__init__.py`` before other imports, so that
    ``commit_exit`` is the first exit function registered, hence the last to run."""
    try:
        signal.signal(signal.SIGINT, _exit_on_signal)
        signal.signal(signal.SIGTERM, _exit_on_signal)
    except ValueError:  # pragma: no cover - not the main thread
        return
    atexit.register(commit_exit)
