"""Fixtures for PSF tests."""

from __future__ import annotations

import pytest

from lensopt.spec import Model
from tests.helpers import oval_model


@pytest.fixture(scope="session")
def oval() -> Model:
    return oval_model()
