"""Small lenses for the optimization tests (few rays, few variables: the suite stays fast)."""

from __future__ import annotations

import copy
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

SPECS = Path(__file__).resolve().parents[2] / "specs"


def cooke_data(**optimize: Any) -> dict[str, Any]:
    """The classic Cooke triplet as plain spec data, with a small [optimize] section."""
    data = tomllib.loads((SPECS / "cooke_triplet.toml").read_text())
    data["optimize"] = {"sampling": "rings:3", "steps": 10, **optimize}
    return data


@pytest.fixture
def cooke() -> dict[str, Any]:
    return copy.deepcopy(cooke_data())


@pytest.fixture
def make_cooke() -> Callable[..., dict[str, Any]]:
    """``make_cooke(**optimize)``: fresh Cooke triplet data with extra [optimize] settings."""
    return cooke_data
