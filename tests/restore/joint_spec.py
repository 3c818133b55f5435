"""A tiny joint problem: the Cooke triplet, two varying radii, 32-pixel patches, a two-level network."""

from __future__ import annotations

import copy
from typing import Any

from tests.helpers import cooke_data


def joint_data(*, batch: int = 2, noise: float = 0.005, steps: int = 3, psf_size: int = 9) -> dict[str, Any]:
    data = cooke_data()
    data["sensor"]["resolution"] = [640, 480]
    data["surfaces"][0]["vary"] = ["radius"]
    data["surfaces"][2]["vary"] = ["radius"]
    data["optimize"] = {"objective": "restored", "sampling": "rings:3", "steps": steps,
                        "image": {"patch": 32, "batch": batch, "psf_size": psf_size, "fields": 3, "sampling": "rings:4",
                                  "validation": 2, "noise": noise}}
    data["restore"] = {"width": 4, "encoder_blocks": [1, 1], "decoder_blocks": [1, 1],
                       "train": {"checkpoint_every": 1, "validate_every": 0}}
    return copy.deepcopy(data)
