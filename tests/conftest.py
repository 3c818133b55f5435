"""Fixtures every test directory may use: the shipped lenses in their usual forms and the device the
tests run on (``--device cpu|cuda``, kornia's habit). Plain values and helpers: ``tests/helpers.py``."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import torch

from tests.helpers import CMOUNT, COOKE, cooke_data


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--device", default="cpu", help="device of the tests that take the ``device`` fixture "
                     "(cpu, cuda, cuda:N); a device this machine lacks skips them")


@pytest.fixture
def device(request: pytest.FixtureRequest) -> torch.device:
    """The device of ``--device`` (default CPU); tests skip when this machine does not have it."""
    dev = torch.device(request.config.getoption("--device"))
    if dev.type == "cuda" and not torch.cuda.is_available():
        pytest.skip("no CUDA device on this machine")
    return dev


@pytest.fixture
def cooke_path() -> Path:
    """The Cooke triplet spec file (``specs/cooke_triplet.toml``)."""
    return COOKE


@pytest.fixture
def cooke() -> dict[str, Any]:
    """The Cooke triplet as fresh plain spec data (edit it freely)."""
    return cooke_data()


@pytest.fixture(scope="session")
def cooke_model() -> Any:
    """The Cooke triplet built (``lensopt.spec.Model``: frozen, shared by the session)."""
    from lensopt.spec import build, load_spec

    return build(load_spec(COOKE))


@pytest.fixture(scope="session")
def cmount_model() -> Any:
    """The seed's C-mount lens built (frozen, shared by the session)."""
    from lensopt.spec import build, load_spec

    return build(load_spec(CMOUNT))
