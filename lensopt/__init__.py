"""lensopt: differentiable, processing-aware lens design (see DESIGN.md for the map)."""

import sys as _sys

__version__ = "0.1.0"


def _startup_signals() -> None:
    """When this process is the ``lensopt`` command: Ctrl-C or SIGTERM while it is still importing (before
    the CLI installs its handlers) exits with one line (130 / 143), not a KeyboardInterrupt traceback."""
    import os
    import signal

    def quit_(signum: int, frame: object) -> None:
        os.write(2, b"interrupted\n" if signum == signal.SIGINT else b"terminated\n")
        os._exit(130 if signum == signal.SIGINT else 143)

    try:
        signal.signal(signal.SIGINT, quit_)
        signal.signal(signal.SIGTERM, quit_)
    except ValueError:  # pragma: no cover - not the main thread
        pass


def _is_cli() -> bool:
    argv = getattr(_sys, "orig_argv", _sys.argv)
    script = _sys.argv[0].replace("\\", "/").rsplit("/", 1)[-1] if _sys.argv else ""
    return script in ("lensopt", "lensopt.exe") or any(
        a == "-m" and i + 1 < len(argv) and argv[i + 1] == "lensopt" for i, a in enumerate(argv))


if _is_cli():
    _startup_signals()
