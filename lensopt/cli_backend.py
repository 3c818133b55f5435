"""The ``--backend`` option shared by the commands that trace many rays (trace, plot psf, simulate, evaluate)."""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Annotated, Any, TypeVar

import typer
from rich.console import Console

F = TypeVar("F", bound=Callable[..., Any])

BackendOpt = Annotated[str, typer.Option(
    "--backend", help="Trace backend: auto (the compiled trace when `lensopt warmup` compiled this lens "
    "structure, else eager) | eager | compiled.")]


def with_backend(err_console: Console) -> Callable[[F], F]:
    """Run the command with its ``backend`` argument as the trace backend (``use_backend``) and report a
    first compilation on stderr; goes under ``handle_errors`` so that a bad name is one line, exit 2."""

    def decorate(fn: F) -> F:
        @functools.wraps(fn)
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            from lensopt.optics.backend import on_compile, use_backend  # torch: imported when a command runs

            remove = on_compile(lambda desc, s: err_console.print(
                f"compiled the trace for {desc} in {s:.1f} s (first time on this machine; cached on disk)",
                highlight=False))
            try:
                with use_backend(kwargs.get("backend", "auto")):
                    return fn(*args, **kwargs)
            finally:
                remove()

        return wrapper  # type: ignore[return-value]

    return decorate
