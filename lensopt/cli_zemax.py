"""``lensopt import-zemax`` and ``lensopt export-zemax`` (CLI layer only: argument parsing and messages).

Imported at the bottom of ``lensopt.cli`` (after the shared options exist), which calls :func:`register`.
"""

from pathlib import Path
from typing import Annotated

import typer

from lensopt.cli import LensArg, err_console, handle_errors
from lensopt.errors import LensoptError

__all__ = ["register"]

OutputOpt = Annotated[Path, typer.Option("--output", "-o", help="Output file.")]
ZmxArg = Annotated[Path, typer.Argument(help="Zemax sequential lens file (.zmx, UTF-16 or ASCII).")]
CatalogOpt = Annotated[list[Path] | None, typer.Option(
    "--catalog", help="Zemax AGF glass catalog to look glasses up in first (repeatable).")]


@handle_errors
def export_zemax(lens: LensArg, output: OutputOpt) -> None:
    """Write the lens as a Zemax OpticStudio sequential file (.zmx)."""
    from lensopt.io.zemax_export import write_zemax
    from lensopt.spec import load_spec

    write_zemax(load_spec(lens), output)
    err_console.print(f"wrote {output}", highlight=False)


@handle_errors
def import_zemax(zmx: ZmxArg, output: OutputOpt, catalog: CatalogOpt = None) -> None:
    """Read a Zemax .zmx file into a lensopt lens (.json); every ignored item is one warning line."""
    from lensopt.io.zemax_import import read_zemax
    from lensopt.spec.io import save_json

    if output.suffix.lower() != ".json":
        raise LensoptError("the imported lens is written as JSON; name it *.json", path="--output",
                           got=str(output))
    result = read_zemax(zmx, catalogs=tuple(catalog or ()))
    for warning in result.warnings:
        err_console.print(f"[yellow]warning:[/] {warning}", markup=True, highlight=False, soft_wrap=True)
    save_json(result.spec, output)
    err_console.print(f"wrote {output}", highlight=False)


def register(app: typer.Typer) -> None:
    """Add the Zemax commands to ``app``."""
    app.command("export-zemax")(export_zemax)
    app.command("import-zemax")(import_zemax)
