"""Run under torchrun (2 ranks): rank 1 asks for other settings; every rank must fail with one line (the CLI's
``error_line``: ``rank N: error: …`` on stderr), exit 2."""

import sys

import torch

from lensopt.cli.common import error_line
from lensopt.errors import LensoptError
from lensopt.parallel import check_same_settings, init_distributed

dist = init_distributed(torch.device("cpu"))
rank, world = dist.rank, dist.world
try:
    check_same_settings(world, {"steps": 3 + rank})
except LensoptError as err:
    error_line(str(err))
    sys.exit(2)
print(f"rank {rank}: no error")
