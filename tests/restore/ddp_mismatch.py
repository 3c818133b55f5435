"""Run under torchrun (2 ranks): rank 1 asks for other settings; every rank must fail with one line, exit 2."""

import sys

import torch

from lensopt.errors import LensoptError
from lensopt.parallel import check_same_settings, init_distributed

dist = init_distributed(torch.device("cpu"))
rank, world = dist.rank, dist.world
try:
    check_same_settings(world, {"steps": 3 + rank})
except LensoptError as err:
    print(f"rank {rank}: error: {err}")
    sys.exit(2)
print(f"rank {rank}: no error")
