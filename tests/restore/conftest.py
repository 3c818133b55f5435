"""A small lens + tiny network for fast training tests: the Cooke triplet (3 wavelengths → RGB) with a
[restore] section of width 4 and two levels."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.helpers import cooke_data

TINY_RESTORE = {"width": 4, "encoder_blocks": [1, 1], "middle_blocks": 1, "decoder_blocks": [1, 1],
                "train": {"batch": 2, "patch": 32, "steps": 4, "checkpoint_every": 2, "validate_every": 2,
                          "validation_patches": 2}}


def write_spec(path: Path, data: dict) -> Path:
    import json

    path.write_text(json.dumps(data), encoding="utf-8")
    return path


@pytest.fixture
def tiny_lens(tmp_path: Path) -> Path:
    """cooke_triplet.toml + a tiny [restore] section, as a JSON lens file."""
    data = cooke_data()
    data["sensor"]["resolution"] = [640, 480]
    data["restore"] = TINY_RESTORE
    return write_spec(tmp_path / "tiny.json", data)


@pytest.fixture
def other_lens(tmp_path: Path) -> Path:
    """The same with a conic first surface: another lens structure."""
    data = cooke_data()
    data["sensor"]["resolution"] = [640, 480]
    data["restore"] = TINY_RESTORE
    data["surfaces"][0]["type"] = "conic"
    return write_spec(tmp_path / "other.json", data)
