"""Lenses and images for imaging tests."""

from __future__ import annotations

import copy
from typing import Any

from lensopt.spec import Model, build, parse_spec


def oval_model(*, pitch_um: float = 30.0, resolution: tuple[int, int] | None = (64, 48), epd: float = 10.0,
               rgb: bool = False) -> Model:
    """A Cartesian oval (one ellipsoidal refracting surface, κ = −1/n², image at its far focus in glass): its
    on-axis geometric PSF is a Dirac delta (Descartes; Born & Wolf §4.2.3). With a tiny field (1e-4°) every
    PSF stays within a pixel."""
    wl = [480.0, 550.0, 650.0] if rgb else [587.5618]
    spec: dict[str, Any] = {
        "name": "Cartesian oval",
        "system": {"aperture": {"epd": epd}, "field": {"hfov_deg": 1e-4, "relative": [0.0, 1.0]}},
        "spectrum": {"wavelengths_nm": wl},
        "sensor": {"pixel_pitch_um": pitch_um, "resolution": list(resolution) if resolution else None},
        "surfaces": [{"type": "conic", "radius": 50.0, "conic": -1 / 1.5**2, "thickness": 150.0,
                      "material": {"nd": 1.5, "vd": 100.0}, "stop": True}],
    }
    model = build(parse_spec(copy.deepcopy(spec)))
    n = float(model.lens.index[1, len(wl) // 2])
    spec["surfaces"][0]["conic"] = -1.0 / n**2
    spec["surfaces"][0]["thickness"] = n * 50.0 / (n - 1.0)
    return build(parse_spec(spec))
