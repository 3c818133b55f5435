"""Fixtures for PSF tests."""

from __future__ import annotations

import pytest
from psf_lenses import build_oval

from lensopt.spec import Model


@pytest.fixture(scope="session")
def oval() -> Model:
    return build_oval()
