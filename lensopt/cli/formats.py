"""``lensopt import-codev | export-codev | import-zemax | export-zemax`` (CLI layer: argument parsing and
messages; the formats are ``lensopt.interchange``)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from lensopt.cli.common import LensArg, check_output, err_console, handle_errors
from lensopt.errors import LensoptError

__all__ = ["commands"]

commands = typer.Typer()  # its commands, put in order by lensopt.cli.app

OutputOpt = Annotated[Path, typer.Option("--output", "-o", help="Output file.")]


@commands.command("export-codev")
@handle_errors
def export_codev(
    lens: LensArg,
    output: OutputOpt,
    private_catalog: Annotated[bool, typer.Option(
        "--private-catalog", help="Write every glass as a private catalog of lensopt's indices.")] = False,
) -> None:
    """Write the lens as a CODE V sequence file (.seq)."""
    from lensopt.interchange.codev.write import write_codev
    from lensopt.spec import load_spec

    check_output(output, (".seq",), what="CODE V sequence file")
    write_codev(load_spec(lens), output, private_catalog=private_catalog)
    err_console.print(f"wrote {output}", highlight=False)


@commands.command("import-codev")
@handle_errors
def import_codev(
    seq: Annotated[Path, typer.Argument(help="CODE V sequence file (.seq).")],
    output: OutputOpt,
) -> None:
    """Read a CODE V sequence file into a lensopt lens (.json)."""
    from lensopt.interchange.codev.read import read_codev
    from lensopt.spec.io import save_json

    if output.suffix.lower() != ".json":
        raise LensoptError("the imported lens is written as JSON; name it *.json", path="--output",
                           got=str(output))
    check_output(output)
    result = read_codev(seq)
    for warning in result.warnings:
        err_console.print(f"[yellow]warning:[/] {warning}", markup=True, highlight=False, soft_wrap=True)
    save_json(result.spec, output)
    err_console.print(f"wrote {output}", highlight=False)


ZmxArg = Annotated[Path, typer.Argument(help="Zemax sequential lens file (.zmx, UTF-16 or ASCII).")]
CatalogOpt = Annotated[list[Path] | None, typer.Option(
    "--catalog", metavar="FILE.agf", help="Zemax AGF glass catalog to look glasses up in first (repeatable).")]


@commands.command("export-zemax")
@handle_errors
def export_zemax(lens: LensArg, output: OutputOpt) -> None:
    """Write the lens as a Zemax OpticStudio sequential file (.zmx)."""
    from lensopt.interchange.zemax.write import write_zemax
    from lensopt.spec import load_spec

    write_zemax(load_spec(lens), output)
    err_console.print(f"wrote {output}", highlight=False)


@commands.command("import-zemax")
@handle_errors
def import_zemax(zmx: ZmxArg, output: OutputOpt, catalog: CatalogOpt = None) -> None:
    """Read a Zemax .zmx file into a lensopt lens (.json); every ignored item is one warning line."""
    from lensopt.interchange.zemax.read import read_zemax
    from lensopt.spec.io import save_json

    if output.suffix.lower() != ".json":
        raise LensoptError("the imported lens is written as JSON; name it *.json", path="--output",
                           got=str(output))
    result = read_zemax(zmx, catalogs=tuple(catalog or ()))
    for warning in result.warnings:
        err_console.print(f"[yellow]warning:[/] {warning}", markup=True, highlight=False, soft_wrap=True)
    save_json(result.spec, output)
    err_console.print(f"wrote {output}", highlight=False)
