"""``python -m lensopt`` (and ``torchrun ... -m lensopt``): the command line."""

from lensopt.cli import app

if __name__ == "__main__":  # not when a worker process (Dask, multiprocessing spawn) imports this module
    app(prog_name="lensopt")
