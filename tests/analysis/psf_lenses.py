"""Lenses for PSF tests."""

from __future__ import annotations

import copy
from typing import Any

from lensopt.spec import Model, build, parse_spec


def oval_spec(*, wavelengths_nm: list[float] | None = None, epd: float = 10.0, hfov_deg: float = 0.01,
              pitch_um: float = 1.0) -> dict[str, Any]:
    """A single refracting ellipsoid (Cartesian oval) with its far focus on the image surface, in glass:
    conic κ = −1/n² images an axial point at infinity without aberration (Descartes; e.g. Born & Wolf
    §4.2.3), so its geometric PSF is a Dirac delta on axis. R = 50 mm, n = 1.5: f' = n R/(n − 1) = 150 mm,
    NA = n sin u' ≈ EPD/(2 f'/n) = 0.05 for EPD 10 mm."""
    n = 1.5
    return {
        "name": "Cartesian oval",
        "system": {"aperture": {"epd": epd}, "field": {"hfov_deg": hfov_deg, "relative": [0.0, 1.0]}},
        "spectrum": {"wavelengths_nm": wavelengths_nm or [587.5618]},
        "sensor": {"pixel_pitch_um": pitch_um},
        "surfaces": [{"type": "conic", "radius": 50.0, "conic": -1.0 / n**2, "thickness": n * 50.0 / (n - 1.0),
                      "material": {"nd": n, "vd": 60.0}, "stop": True}],
    }


def build_oval(**kw: Any) -> Model:
    spec = oval_spec(**kw)
    model = build(parse_spec(copy.deepcopy(spec)))
    n = float(model.lens.index[1, 0])  # the model glass index at the wavelength (= nd at the d line)
    spec["surfaces"][0]["conic"] = -1.0 / n**2
    spec["surfaces"][0]["thickness"] = n * 50.0 / (n - 1.0)
    return build(parse_spec(spec))
