"""Fixtures every test directory may use: the shipped lenses in their usual forms and the device the
tests run on (``--device cpu|cuda``, kornia's habit). Plain values and helpers: ``tests/helpers.py``."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest
import torch

from tests.helpers import CMOUNT, COOKE, cooke_data, cooke_optimize_data


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


@pytest.fixture(scope="session")
def cooke() -> Any:
    """The Cooke triplet (``specs/cooke_triplet.toml``) built: a ``lensopt.spec.Model`` (frozen, shared by the
    session). Its file is ``tests.helpers.COOKE``; fresh spec data: ``cooke_dict``."""
    from lensopt.spec import build, load_spec

    return build(load_spec(COOKE))


@pytest.fixture
def cooke_dict() -> dict[str, Any]:
    """The Cooke triplet as fresh plain spec data (edit it freely)."""
    return cooke_data()


@pytest.fixture
def cooke_opt() -> dict[str, Any]:
    """The Cooke triplet as fresh spec data with a small ``[optimize]`` section (rings:3, 10 steps)."""
    return cooke_optimize_data()


@pytest.fixture
def make_cooke() -> Callable[..., dict[str, Any]]:
    """``make_cooke(**optimize)``: fresh Cooke triplet data with extra ``[optimize]`` settings."""
    return cooke_optimize_data


@pytest.fixture(scope="session")
def cmount() -> Any:
    """The seed's C-mount lens (``lenses/cmount_4p.json``) built (frozen, shared by the session)."""
    from lensopt.spec import build, load_spec

    return build(load_spec(CMOUNT))
