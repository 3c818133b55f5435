"""The peer tool for the analysis tests: a lensopt model rebuilt as an optiland 0.6.3 ``Optic``.

The optic gets lensopt's resolved prescription (radii, conics, thicknesses, stop), the same aperture
(EPD), angle fields and wavelengths (the reference wavelength primary), and a ``TabulatedMaterial`` per
medium that returns exactly the refractive indices lensopt computed at those wavelengths, so the
comparisons test the analyses, not glass data. Importing this module needs optiland (callers use
``pytest.importorskip("optiland")`` first).
"""

from __future__ import annotations

import math
from functools import cache
from pathlib import Path

import numpy as np
import optiland.backend as be
from optiland import optic as ol_optic
from optiland.materials.base import BaseMaterial

from lensopt.spec import build, load_spec
from lensopt.spec.build import Model

ROOT = Path(__file__).resolve().parents[2]
PEER_LENSES = {
    "cooke": ROOT / "specs" / "cooke_triplet.toml",
    "double_gauss": ROOT / "specs" / "double_gauss.toml",
    "microscope": ROOT / "lenses" / "microscope_8p_wd12.json",
}


@cache
def peer_model(name: str) -> Model:
    return build(load_spec(PEER_LENSES[name]))


class TabulatedMaterial(BaseMaterial):
    """A medium with given indices at given wavelengths (µm); any other wavelength is an error."""

    def __init__(self, wavelengths_um: list[float], indices: list[float]) -> None:
        super().__init__()
        self.table = dict(zip(wavelengths_um, indices, strict=True))

    def _cache_state(self) -> tuple | None:
        return None

    def _lookup(self, w: float) -> float:
        for key, n in self.table.items():
            if abs(key - w) <= 1e-12:
                return n
        raise KeyError(f"no index tabulated at {w} µm")

    def _calculate_n(self, wavelength, **kwargs):
        arr = np.asarray(be.to_numpy(wavelength), dtype=float)
        if arr.ndim == 0:
            return be.array(self._lookup(float(arr)))
        return be.array(np.vectorize(self._lookup)(arr))

    def _calculate_k(self, wavelength, **kwargs):
        arr = np.asarray(be.to_numpy(wavelength), dtype=float)
        return be.zeros_like(be.array(arr)) if arr.ndim else be.array(0.0)


def optic_from_model(model: Model, *, fields: list[float] | None = None) -> ol_optic.Optic:
    """``model`` as an optiland Optic; ``fields``: relative fields (default: the system's)."""
    lens, system = model.lens, model.system
    wl = [float(w) for w in lens.wavelength_um]
    media = [TabulatedMaterial(wl, lens.index[s].tolist()) for s in range(lens.index.shape[0])]
    o = ol_optic.Optic()
    obj = math.inf if system.object_distance is None else system.object_distance
    o.surfaces.add(index=0, radius=math.inf, thickness=obj, material=media[0])
    for i, shape in enumerate(lens.shapes):
        if shape.diffractive or shape.kind == "asphere":
            raise ValueError("the peer lenses are spherical/conic")
        c = float(lens.curvature[i])
        kw: dict = {"radius": math.inf if c == 0 else 1.0 / c}
        if shape.kind == "conic":
            kw["conic"] = float(lens.conic[i])
        o.surfaces.add(index=i + 1, thickness=float(lens.thickness[i]), is_stop=(i == lens.stop),
                       material=media[i + 1], **kw)
    o.surfaces.add(index=lens.num_surfaces + 1)
    from lensopt.optics.paraxial import first_order

    o.set_aperture(aperture_type="EPD", value=float(first_order(lens, system).epd))
    assert system.field_type == "angle"
    o.fields.set_type(field_type="angle")
    for u in (system.rel_field if fields is None else fields):
        o.fields.add(y=float(u) * system.field_max)
    for w, lam in enumerate(wl):
        o.wavelengths.add(value=lam, is_primary=(w == system.reference))
    return o
