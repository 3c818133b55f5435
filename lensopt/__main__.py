"""``python -m lensopt``: the command line (same as the ``lensopt`` script)."""

from lensopt.cli import app

app(prog_name="lensopt")
