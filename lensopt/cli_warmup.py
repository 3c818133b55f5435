"""``lensopt warmup``: compile a lens's trace once on this machine (library: ``lensopt.optics.aot``)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer


def register(app: typer.Typer) -> None:
    from lensopt.cli import console, err_console, handle_errors, load_model, print_json

    @app.command()
    @handle_errors
    def warmup(
        lenses: Annotated[list[Path], typer.Argument(help="Lens specs (.toml) or resolved lenses (.json).")],
        recorded: Annotated[bool, typer.Option("--recorded/--no-recorded", help="Also the recorded trace "
                                               "(per-surface hits: the report of `lensopt trace`).")] = True,
        as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object instead of lines.")] = False,
    ) -> None:
        """Compile the trace of each lens structure ahead of time (AOTInductor; about a minute of CPU each,
        once per machine): later commands (trace, plot psf, simulate, evaluate) then load it in milliseconds
        and trace on it by default (--backend auto)."""
        from lensopt.errors import LensoptError
        from lensopt.optics import aot

        rows = []
        for path in lenses:
            lens = load_model(path).lens
            if not aot.supported(lens):
                raise LensoptError("the compiled trace takes lenses without decentered or tilted surfaces, on "
                                   "the CPU", path=str(path), got="placement" if lens.placement is not None
                                   else str(lens.device))
            for record in (False, True) if recorded else (False,):
                desc = aot.describe(lens, record=record)
                target = aot.package_path(lens, record=record)
                if target.exists():
                    rows.append({"lens": str(path), "structure": desc, "package": str(target), "built_s": None})
                    if not as_json:
                        console.print(f"{path}: {desc}: already compiled ({target})", highlight=False)
                    continue
                with err_console.status(f"compiling the trace of {path} ({desc}) …", spinner="dots"):
                    seconds = aot.build_package(lens, record=record)
                rows.append({"lens": str(path), "structure": desc, "package": str(target), "built_s": seconds})
                if not as_json:
                    console.print(f"{path}: {desc}: compiled in {seconds:.1f} s ({target})", highlight=False)
        if as_json:
            print_json({"packages": rows})
