"""lensopt: differentiable, processing-aware lens design (see DESIGN.md for the map)."""

from lensopt import cli_process as _cli_process  # the standard library only

__version__ = "0.1.0"

if _cli_process.is_cli_process():
    # The `lensopt` command: its signals behave from here to the end of the process (lensopt/cli_process.py).
    _cli_process.install()
