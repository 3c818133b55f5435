"""``lensopt.devices.resolve_device``: the one parser of ``--device`` accepts the union of the names the
commands and ``design.optimize`` accepted before the house move (issue 26): cpu, cuda, cuda:N, mps, auto,
None, in any case; a device this machine cannot use, or no device name, is one ``LensoptError`` naming
``--device``. And ``lensopt.parallel``'s torchrun set-up outside torchrun: one process."""

from __future__ import annotations

import pytest
import torch

from lensopt.devices import resolve_device
from lensopt.errors import LensoptError
from lensopt.parallel import Dist, check_same_settings, init_distributed


@pytest.mark.parametrize("name", [None, "cpu", "CPU", " cpu ", "cpu:0"])
def test_cpu_names(name: str | None) -> None:
    assert resolve_device(name).type == "cpu"


def test_auto_is_cuda_exactly_when_there_is_cuda() -> None:
    assert resolve_device("auto").type == ("cuda" if torch.cuda.is_available() else "cpu")
    assert resolve_device("AUTO").type == resolve_device("auto").type


@pytest.mark.parametrize("name", ["gpu", "cuda:x", "", "xpu", "meta"])
def test_not_a_device_name_is_one_error_naming_the_option(name: str) -> None:
    with pytest.raises(LensoptError) as err:
        resolve_device(name)
    assert str(err.value).startswith("--device: must be cpu, cuda, cuda:N, mps or auto")


@pytest.mark.skipif(torch.cuda.is_available(), reason="CUDA is available here: the error path cannot be reached")
@pytest.mark.parametrize("name", ["cuda", "CUDA", "cuda:0", "cuda:3"])
def test_cuda_without_cuda(name: str) -> None:
    with pytest.raises(LensoptError, match=r"^--device: CUDA is not available on this machine"):
        resolve_device(name)


@pytest.mark.skipif(torch.backends.mps.is_available(), reason="MPS is available here: the error path cannot be reached")
def test_mps_without_mps() -> None:
    with pytest.raises(LensoptError, match=r"^--device: MPS is not available on this machine"):
        resolve_device("mps")


def test_one_process_outside_torchrun(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("WORLD_SIZE", raising=False)
    assert init_distributed(torch.device("cpu")) == Dist(rank=0, world=1, device="cpu")
    check_same_settings(1, {"anything": object()})  # one process: nothing to compare, no collective
