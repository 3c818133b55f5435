"""Run under torchrun (2 ranks): rank 1 asks for other settings; every rank must fail with one line, exit 2."""

import sys

import torch

from lensopt.cli_restore import check_same_settings, init_distributed
from lensopt.errors import LensoptError

dist = init_distributed(torch.device("cpu"))
try:
    check_same_settings(dist, {"steps": 3 + dist.rank})
except LensoptError as err:
    print(f"rank {dist.rank}: error: {err}")
    sys.exit(2)
print(f"rank {dist.rank}: no error")
