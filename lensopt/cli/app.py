"""The ``lensopt`` command line: the root of the CLI. It builds the typer app from the command modules, in
the order of ``lensopt --help``, and holds the options every command shares (``--verbose``,
``--max-memory``, ``--version``). Nothing imports it but the entry (``lensopt/__main__.py``) and tests.

Every ``LensoptError`` becomes one line on stderr and exit code 2 (DESIGN.md rule 6; ``common.handle_errors``).
"""

from __future__ import annotations

import logging
import sys
from typing import Annotated

import typer

from lensopt import __version__
from lensopt.cli import (
    design,
    formats,
    optimize,
    plot,
    plot_analyses,
    qa,
    restore,
    simulate,
    sweep,
    tolerance,
    trace,
    warmup,
)
from lensopt.cli.common import LensoptGroup, LowerLevelFormatter, invocation
from lensopt.cli.signals import state
from lensopt.errors import LensoptError

__all__ = ["app"]

# The commands in the order ``lensopt --help`` lists them (the ``plot`` group comes last).
ORDER = ("trace", "ray", "export-codev", "import-codev", "simulate", "check", "accuracy", "evaluate", "tolerance",
         "export-zemax", "import-zemax", "train-irm", "restore", "optimize", "sweep", "design", "warmup")
GROUPS = (trace, formats, simulate, qa, tolerance, restore, optimize, sweep, design, warmup)

app = typer.Typer(cls=LensoptGroup, add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  rich_markup_mode=None,
                  help="Differentiable lens design: trace, plot, optimize, simulate, export.")
_by_name = {c.name: c for group in GROUPS for c in group.commands.registered_commands}
if sorted(_by_name) != sorted(ORDER):  # a command added to a module must be placed in ORDER
    raise RuntimeError(f"lensopt.cli.app.ORDER is not the set of commands: {sorted(set(_by_name) ^ set(ORDER))}")
app.registered_commands = [_by_name[name] for name in ORDER]
# The plot group: plot.py's figures, then the designer's analyses (plot_analyses.py).
plot.plot_app.registered_commands += [c for c in plot_analyses.commands.registered_commands
                                      if c not in plot.plot_app.registered_commands]
app.add_typer(plot.plot_app, name="plot")


def _version(value: bool) -> None:
    if value:
        sys.stdout.write(f"lensopt {__version__}\n")
        raise typer.Exit(0)


@app.callback()
def main(verbose: Annotated[bool, typer.Option("--verbose", "-v", help="Debug logging; tracebacks of bugs.")] = False,
         max_memory: Annotated[str | None, typer.Option(
             "--max-memory", help="Memory budget, e.g. 4G (default: half the machine's memory).")] = None,
         version: Annotated[bool, typer.Option("--version", callback=_version, is_eager=True,
                                               help="Print the version and exit.")] = False) -> None:
    from lensopt.engine import parse_size

    state.verbose = verbose
    invocation.max_memory = None
    if max_memory is not None:
        try:
            invocation.max_memory = parse_size(max_memory)
        except LensoptError as err:
            raise typer.BadParameter(err.message + f" (got {max_memory!r})", param_hint="'--max-memory'") from None
    handler = logging.StreamHandler(sys.stderr)  # one plain line per message: "warning: ..."
    handler.setFormatter(LowerLevelFormatter("%(levelname)s: %(message)s"))
    logging.basicConfig(level=logging.DEBUG if verbose else logging.WARNING, handlers=[handler], force=True)
