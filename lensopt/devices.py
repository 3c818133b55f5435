"""Device names → ``torch.device`` (a leaf: it imports nothing else from lensopt but the errors).

The one parser of ``--device`` for every command (trace-heavy commands, optimize, the restoration
network's training) and for ``design.optimize(device=...)``.
"""

from __future__ import annotations

import torch

from lensopt.errors import LensoptError

__all__ = ["resolve_device"]

_NAMES = "cpu, cuda, cuda:N, mps or auto"


def resolve_device(device: str | None) -> torch.device:
    """``cpu | cuda | cuda:N | mps | auto`` (any case, spaces around ignored; None: the CPU) → torch.device.

    ``auto`` is CUDA when this machine has it, else the CPU. A device this machine cannot use is a
    one-line ``LensoptError`` naming ``--device``.
    """
    if device is None:
        return torch.device("cpu")
    name = device.strip().lower()
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        dev = torch.device(name)
    except RuntimeError:
        raise LensoptError(f"must be {_NAMES}", path="--device", got=device) from None
    if dev.type not in ("cpu", "cuda", "mps"):
        raise LensoptError(f"must be {_NAMES}", path="--device", got=device)
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise LensoptError(f"CUDA is not available on this machine (torch {torch.__version__}, built "
                           f"{'with' if torch.version.cuda else 'without'} CUDA); use --device cpu",
                           path="--device", got=device)
    if dev.type == "cuda" and dev.index is not None and dev.index >= torch.cuda.device_count():
        raise LensoptError(f"this machine has {torch.cuda.device_count()} CUDA device(s)", path="--device",
                           got=device)
    if dev.type == "mps" and not torch.backends.mps.is_available():
        raise LensoptError("MPS is not available on this machine; use --device cpu", path="--device", got=device)
    return dev
