"""``python -m lensopt`` (and ``torchrun ... -m lensopt``): the command line."""

from lensopt.cli import app

app(prog_name="lensopt")
