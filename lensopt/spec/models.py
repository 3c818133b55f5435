"""The lens spec: pydantic models shared by the TOML spec a person writes and the JSON lens lensopt
writes (one schema, two serializations). Units are those a designer uses: mm, nm, degrees.

Surface kinds are a discriminated union on ``type``. Every field that an optimizer may vary can be
named in the surface's ``vary`` list (checked here, used by ``lensopt optimize``).
"""

from __future__ import annotations

import math
import re
import typing
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from lensopt.spec.optim import OptimizeSpec
from lensopt.spec.restore import RestoreSpec
from lensopt.spec.tolerance import ToleranceSpec

__all__ = [
    "ApertureSpec",
    "FieldSpec",
    "ObjectSpec",
    "SystemSpec",
    "VignettingSpec",
    "FrontApertureSpec",
    "SpectrumSpec",
    "SensorSpec",
    "ModelGlassSpec",
    "TabulatedGlassSpec",
    "AgfGlassSpec",
    "PlaneShape",
    "SphereShape",
    "ConicShape",
    "AsphereShape",
    "BaseShape",
    "PlaneSurface",
    "SphereSurface",
    "ConicSurface",
    "AsphereSurface",
    "DiffractiveSurface",
    "SurfaceSpec",
    "ImagePlaneSpec",
    "ElementPlacementSpec",
    "LensSpec",
    "curvature_of",
]


#: Largest gap or clear semi-diameter accepted, mm (1 km): beyond it a lens is a typo, and float64 ray
#: arithmetic on 1e308 mm overflows to NaN.
MAX_LENGTH_MM = 1e6
_SCALARS = {float: "a valid number", int: "a valid integer", bool: "true or false"}


def _scalar_kind(annotation: Any) -> str | None:
    """``a number`` for float / float | None fields (likewise int, bool); None for anything else."""
    if annotation in _SCALARS:
        return _SCALARS[annotation]
    args = [a for a in typing.get_args(annotation) if a is not type(None)]
    return _SCALARS.get(args[0]) if len(args) == 1 and args[0] in _SCALARS else None


class _Model(BaseModel):
    # Numbers must be finite (TOML accepts inf and nan); only a radius may be inf (a flat surface).
    model_config = ConfigDict(extra="forbid", validate_assignment=True, ser_json_inf_nan="constants",
                              allow_inf_nan=False)

    @model_validator(mode="before")
    @classmethod
    def _no_text_numbers(cls, data: Any) -> Any:
        """``radius = "1e999"`` or ``stop = "yes"`` are typos, not numbers or flags (pydantic would coerce)."""
        if isinstance(data, dict):
            for name, info in cls.model_fields.items():
                value = data.get(name)
                if isinstance(value, str) and (kind := _scalar_kind(info.annotation)) is not None:
                    raise ValueError(f"@{name}: must be {kind}, not text (got {value!r})")
        return data


# --------------------------------------------------------------------------------------- system


class ApertureSpec(_Model):
    """Exactly one of: entrance pupil diameter (mm) or paraxial f-number (EFL/EPD)."""

    epd: float | None = Field(default=None, gt=0)
    fnumber: float | None = Field(default=None, gt=0)

    @model_validator(mode="after")
    def _exactly_one(self) -> ApertureSpec:
        if (self.epd is None) == (self.fnumber is None):
            raise ValueError("give exactly one of epd (mm) or fnumber")
        return self


class FieldSpec(_Model):
    """Half field angle in degrees (object space) or paraxial image height in mm, with relative
    field samples u_h in [0, 1] and optional field weights (for the effective spot radius)."""

    hfov_deg: float | None = Field(default=None, gt=0, lt=90)
    image_height: float | None = Field(default=None, gt=0)
    relative: list[float] = Field(default_factory=lambda: [0.0, 0.7, 1.0], min_length=1)
    weights: list[float] | None = None

    @field_validator("relative")
    @classmethod
    def _relative_range(cls, v: list[float]) -> list[float]:
        for i, x in enumerate(v):
            if not 0.0 <= x <= 1.0:
                raise ValueError(f"@[{i}]: a relative field must lie in [0, 1] (got {x})")
        return v

    @model_validator(mode="after")
    def _exactly_one(self) -> FieldSpec:
        if (self.hfov_deg is None) == (self.image_height is None):
            raise ValueError("give exactly one of hfov_deg or image_height")
        if self.weights is not None:
            if len(self.weights) != len(self.relative):
                raise ValueError(f"@weights: needs one entry per relative field ({len(self.relative)} fields, "
                                 f"got {len(self.weights)} weights)")
            if any(w < 0 for w in self.weights) or sum(self.weights) <= 0:
                raise ValueError(f"@weights: must be non-negative with a positive sum (got {self.weights})")
        return self


class ObjectSpec(_Model):
    """Object at a finite distance (mm) before the first surface; ``"infinity"`` in the spec otherwise."""

    distance: float = Field(gt=0)


class VignettingSpec(_Model):
    """Fixed vignetting factors per field (S19–S20; CODE V's VLY/VUY/VUX): the fraction of the lower
    (inferior) and upper (superior) half and of each lateral half of the entrance pupil that is blocked."""

    inferior: list[float]
    superior: list[float]
    lateral: list[float]

    @model_validator(mode="after")
    def _ranges(self) -> VignettingSpec:
        for name in ("inferior", "superior", "lateral"):
            for v in getattr(self, name):
                if not -1.0 < v < 1.0:
                    raise ValueError(f"@{name}: vignetting factors must lie in (−1, 1) (got {v})")
        return self


class FrontApertureSpec(_Model):
    """A circular aperture in object space (S4.1.5): its plane lies ``distance`` mm after the vertex of
    surface 1 (negative: before it), its opening is ``diameter`` mm. Its vignetting factors are computed
    from the lens for every field (V_i, V_s by geometry; V_l ``inscribed``: the bundle stays inside the
    unblocked pupil, as in the seed, or ``extent``: through its widest point, as CODE V's VUX/VLX)."""

    distance: float
    diameter: float = Field(gt=0)
    lateral: Literal["inscribed", "extent"] = "inscribed"

    @field_validator("distance")
    @classmethod
    def _finite(cls, v: float) -> float:
        if not math.isfinite(v):
            raise ValueError(f"must be a finite distance in mm (got {v})")
        return v


class SystemSpec(_Model):
    aperture: ApertureSpec
    field: FieldSpec
    object: ObjectSpec | Literal["infinity"] = "infinity"
    aim: Literal["none", "chief", "full"] = "none"
    aim_steps: int = Field(default=1, ge=1, le=100)
    vignetting: VignettingSpec | None = None
    front_aperture: FrontApertureSpec | None = None

    @model_validator(mode="after")
    def _front_aperture_after_object(self) -> SystemSpec:
        fa, obj = self.front_aperture, self.object
        if fa is not None and not isinstance(obj, str) and fa.distance <= -obj.distance:
            raise ValueError(f"@front_aperture.distance: the aperture must lie after the object at "
                             f"{-obj.distance:g} mm (got {fa.distance:g})")
        return self

    @model_validator(mode="after")
    def _vignetting_per_field(self) -> SystemSpec:
        if self.vignetting is not None:
            n = len(self.field.relative)
            for name in ("inferior", "superior", "lateral"):
                if len(getattr(self.vignetting, name)) != n:
                    raise ValueError(f"@vignetting.{name}: needs one factor per relative field ({n})")
        return self


class SpectrumSpec(_Model):
    """Wavelengths (nm) with spectral weights, the reference wavelength (first-order data, solves) and
    an optional wavelength→RGB weight matrix (n_w rows × 3 columns, each column summing to 1)."""

    wavelengths_nm: list[float] = Field(min_length=1)
    weights: list[float] | None = None
    reference_nm: float | None = None
    rgb_weights: list[list[float]] | None = None

    @field_validator("wavelengths_nm")
    @classmethod
    def _positive(cls, v: list[float]) -> list[float]:
        for i, x in enumerate(v):
            if not (x > 0 and math.isfinite(x)):
                raise ValueError(f"@[{i}]: a wavelength must be positive, in nm (got {x})")
        if len(set(v)) != len(v):
            raise ValueError(f"wavelengths must be distinct (got {v})")
        return v

    @model_validator(mode="after")
    def _consistent(self) -> SpectrumSpec:
        n = len(self.wavelengths_nm)
        if self.weights is not None:
            if len(self.weights) != n:
                raise ValueError(f"@weights: needs one entry per wavelength ({n} wavelengths, "
                                 f"got {len(self.weights)} weights)")
            if any(w < 0 for w in self.weights) or sum(self.weights) <= 0:
                raise ValueError(f"@weights: must be non-negative with a positive sum (got {self.weights})")
        if self.reference_nm is not None and self.reference_nm not in self.wavelengths_nm:
            raise ValueError(f"@reference_nm: must be one of wavelengths_nm {self.wavelengths_nm} "
                             f"(got {self.reference_nm})")
        if self.rgb_weights is not None:
            if len(self.rgb_weights) != n or any(len(row) != 3 for row in self.rgb_weights):
                raise ValueError(f"@rgb_weights: must be {n} rows (one per wavelength) of 3 (R, G, B) weights")
            for col, name in enumerate("RGB"):
                total = sum(row[col] for row in self.rgb_weights)
                if abs(total - 1.0) > 1e-3:
                    raise ValueError(f"@rgb_weights: column {name} must sum to 1 (got {total:.4f})")
        return self

    @property
    def weights_or_uniform(self) -> list[float]:
        return list(self.weights) if self.weights is not None else [1.0] * len(self.wavelengths_nm)

    @property
    def reference_index(self) -> int:
        if self.reference_nm is None:
            return (len(self.wavelengths_nm) - 1) // 2
        return self.wavelengths_nm.index(self.reference_nm)


class SensorSpec(_Model):
    pixel_pitch_um: float = Field(gt=0, le=1e4)
    resolution: tuple[int, int] | None = None

    @field_validator("resolution")
    @classmethod
    def _res(cls, v: tuple[int, int] | None) -> tuple[int, int] | None:
        if v is not None and (v[0] < 1 or v[1] < 1):
            raise ValueError(f"resolution must be two positive pixel counts (got {v})")
        return v


# ------------------------------------------------------------------------------------ materials


class ModelGlassSpec(_Model):
    """A model glass dispersed by the Hartmann formula (S3–S7) from n_d, V_d and ΔP_g,F."""

    nd: float = Field(gt=1.0, lt=3.0)
    vd: float = Field(ge=10.0, le=120.0)
    dpgf: float = Field(default=0.0, ge=-0.1, le=0.1)
    name: str | None = None


class TabulatedGlassSpec(_Model):
    """A glass given by its indices at a few wavelengths (nm), e.g. a CODE V private catalog entry:
    exact at those wavelengths, a cubic spline between them, valid only inside their range."""

    name: str
    wavelengths_nm: list[float] = Field(min_length=1)
    index: list[float] = Field(min_length=1)

    @model_validator(mode="after")
    def _consistent(self) -> TabulatedGlassSpec:
        if len(self.index) != len(self.wavelengths_nm):
            raise ValueError(f"@index: needs one index per wavelength ({len(self.wavelengths_nm)})")
        if any(not (w > 0 and math.isfinite(w)) for w in self.wavelengths_nm) or any(
                b <= a for a, b in zip(self.wavelengths_nm, self.wavelengths_nm[1:], strict=False)):
            raise ValueError(f"@wavelengths_nm: must be positive and increasing (got {self.wavelengths_nm})")
        if any(not (x > 0 and math.isfinite(x)) for x in self.index):
            raise ValueError(f"@index: indices must be positive (got {self.index})")
        return self


class AgfGlassSpec(_Model):
    """A glass of a Zemax AGF catalog file: ``{ catalog = "path/to/file.agf", glass = "N-BK7" }``. A relative
    path is taken from the working directory. Wavelengths outside the catalog's range are accepted (the
    formula extrapolates); ``lensopt import-zemax`` warns about them."""

    catalog: str = Field(min_length=1)
    glass: str = Field(min_length=1)


MaterialSpec = Annotated[str | ModelGlassSpec | TabulatedGlassSpec | AgfGlassSpec,
                         Field(union_mode="left_to_right")]


# ------------------------------------------------------------------------------- surface shapes

_RADIUS_DOC = "radius of curvature in mm (non-zero; inf for a flat base)"


def _check_radius(v: float) -> float:
    if math.isnan(v):
        raise ValueError("must be a number in mm (inf or type = \"plane\" for a flat surface)")
    if v == 0:
        raise ValueError("must be non-zero (use inf or type = \"plane\" for a flat surface)")
    return v


def _check_even_powers(v: dict[int, float], first: int, what: str) -> dict[int, float]:
    for p in v:
        if p < first or p % 2:
            raise ValueError(f"{what} keys must be even powers ≥ {first} (got {p})")
    return dict(sorted(v.items()))


class PlaneShape(_Model):
    type: Literal["plane"]


class _Curved(_Model):
    radius: float = Field(description=_RADIUS_DOC, allow_inf_nan=True)

    @field_validator("radius")
    @classmethod
    def _nonzero(cls, v: float) -> float:
        return _check_radius(v)


class SphereShape(_Curved):
    type: Literal["sphere"]


class ConicShape(_Curved):
    type: Literal["conic"]
    conic: float = 0.0


class AsphereShape(_Curved):
    """Even asphere (S31, S33): conic base plus a4 r⁴ + a6 r⁶ + … (keys are the powers)."""

    type: Literal["asphere"]
    conic: float = 0.0
    coefficients: dict[int, float] = Field(default_factory=dict)

    @field_validator("coefficients")
    @classmethod
    def _powers(cls, v: dict[int, float]) -> dict[int, float]:
        return _check_even_powers(v, 4, "coefficients")


BaseShape = Annotated[PlaneShape | SphereShape | ConicShape | AsphereShape, Field(discriminator="type")]


def curvature_of(shape: Any) -> float:
    """Vertex curvature 1/R of a shape (0 for planes and infinite radii)."""
    radius = getattr(shape, "radius", math.inf)
    return 0.0 if math.isinf(radius) else 1.0 / radius


# ------------------------------------------------------------------------------------- surfaces

_VARY_RE = re.compile(r"^(radius|thickness|conic|material|coefficients|phase)(\.\d+)?$")


class _Interface(_Model):
    """What every surface has: the gap after it, its medium, clear aperture, stop flag, variables."""

    thickness: float = Field(ge=-MAX_LENGTH_MM, le=MAX_LENGTH_MM)
    material: MaterialSpec = "air"
    semi_diameter: float | None = Field(default=None, gt=0, le=MAX_LENGTH_MM)
    stop: bool = False
    clip: bool = False
    vary: list[str] = Field(default_factory=list)
    label: str | None = None
    # Placement (lensopt.optics.placement); None = on the axis (kept out of the written JSON).
    decenter: tuple[float, float] | None = None  # (dx, dy), mm
    tilt_deg: tuple[float, float] | None = None  # (α about x, β about the new y), degrees
    decenter_mode: Literal["return", "basic"] | None = None  # None: "return" (decenter-and-return)

    def _allowed_vary(self) -> set[str]:
        return {"thickness", "material"}

    @model_validator(mode="after")
    def _check_vary(self) -> _Interface:
        allowed = self._allowed_vary()
        for item in self.vary:
            m = _VARY_RE.match(item)
            if not m or m.group(1) not in allowed or (m.group(2) and m.group(1) not in ("coefficients", "phase")):
                raise ValueError(f"@vary: {item!r} is not a variable of this surface; allowed: "
                                 + ", ".join(sorted(allowed)))
        if self.clip and self.semi_diameter is None:
            raise ValueError("@clip: clip = true needs a semi_diameter")
        if not self.is_air and not self.thickness > 0:
            raise ValueError(f"@thickness: a glass element needs a positive thickness (got {self.thickness})")
        return self

    @property
    def is_air(self) -> bool:
        return isinstance(self.material, str) and self.material.strip().lower() == "air"


class PlaneSurface(_Interface, PlaneShape):
    pass


class SphereSurface(_Interface, SphereShape):
    def _allowed_vary(self) -> set[str]:
        return {"thickness", "material", "radius"}


class ConicSurface(_Interface, ConicShape):
    def _allowed_vary(self) -> set[str]:
        return {"thickness", "material", "radius", "conic"}


class AsphereSurface(_Interface, AsphereShape):
    def _allowed_vary(self) -> set[str]:
        return {"thickness", "material", "radius", "conic", "coefficients"}


class DiffractiveSurface(_Interface):
    """A phase profile φ(r) = Σ d_{2i} r^{2i} (radians, r in mm; S35) on a base shape, bending rays by
    the generalized law of refraction (S15) into diffraction order ``order``. ``design_wavelength_nm``
    is the construction wavelength (used when exporting, e.g. CODE V's HWL)."""

    type: Literal["diffractive"]
    base: BaseShape
    phase: dict[int, float] = Field(default_factory=dict)
    design_wavelength_nm: float = Field(gt=0)
    order: int = 1

    @field_validator("phase")
    @classmethod
    def _powers(cls, v: dict[int, float]) -> dict[int, float]:
        return _check_even_powers(v, 2, "phase")

    def _allowed_vary(self) -> set[str]:
        allowed = {"thickness", "material", "phase"}
        allowed |= {"radius"} if self.base.type != "plane" else set()
        allowed |= {"conic"} if self.base.type in ("conic", "asphere") else set()
        allowed |= {"coefficients"} if self.base.type == "asphere" else set()
        return allowed


SurfaceSpec = Annotated[
    PlaneSurface | SphereSurface | ConicSurface | AsphereSurface | DiffractiveSurface,
    Field(discriminator="type"),
]


class ElementPlacementSpec(_Model):
    """A rigid decenter (mm) and tilt (degrees: α about x, then β about the new y) of the element made of
    surfaces ``surfaces[0]..surfaces[1]`` (0-based, inclusive), about the vertex of its first surface;
    later surfaces stay in place (see ``lensopt.optics.placement``)."""

    surfaces: tuple[int, int]
    decenter: tuple[float, float] = (0.0, 0.0)
    tilt_deg: tuple[float, float] = (0.0, 0.0)

    @field_validator("surfaces")
    @classmethod
    def _order(cls, v: tuple[int, int]) -> tuple[int, int]:
        if v[0] < 0 or v[1] < v[0]:
            raise ValueError(f"must be [first, last] surface indices with 0 ≤ first ≤ last (got {list(v)})")
        return v


class ImagePlaneSpec(_Model):
    """``[image]``: the flat image surface after the last gap; ``defocus`` (mm) moves it along the axis."""

    defocus: float = 0.0


CHECK_METRICS = {
    "efl_mm": 1e-5, "bfl_mm": 1e-5, "fnumber": 1e-6, "ttl_mm": 1e-5, "esr_um": 1e-3, "seed_esr_um": 1e-3,
    "rms_um": 1e-3, "distortion_percent": 1e-4, "ri": 1e-5, "failed_rays": 0.0, "margin": 1e-3,
}
"""Metric families of ``lensopt check`` and their default absolute tolerances (in the metric's unit:
mm, µm, %, a fraction, a ray count; margins in their constraint's unit). The metrics are computed with
fixed, seeded settings, so only rounding differences across platforms must pass: a 0.01 mm change of
one thickness or a swapped glass moves several of them far past these."""


class CheckSpec(_Model):
    """``[check]``: tolerances of ``lensopt check`` per metric family (absolute; see ``CHECK_METRICS``)."""

    tolerances: dict[str, float] = Field(default_factory=dict)

    @field_validator("tolerances")
    @classmethod
    def _known(cls, v: dict[str, float]) -> dict[str, float]:
        for k, tol in v.items():
            if k not in CHECK_METRICS:
                raise ValueError(f"@{k}: unknown metric; one of {', '.join(CHECK_METRICS)}")
            if not tol >= 0:
                raise ValueError(f"@{k}: a tolerance must be ≥ 0, got {tol}")
        return v


class LensSpec(_Model):
    """A complete lens: system, spectrum, optional sensor, surfaces in order, image, and the optional
    ``[optimize]`` section read by ``lensopt optimize`` (see ``lensopt.spec.optim``) and the optional
    ``[restore]`` section of the restoration network (``lensopt.spec.restore``)."""

    name: str = "lens"
    system: SystemSpec
    spectrum: SpectrumSpec
    sensor: SensorSpec | None = None
    surfaces: list[SurfaceSpec] = Field(min_length=1)
    image: ImagePlaneSpec = Field(default_factory=ImagePlaneSpec)
    elements: list[ElementPlacementSpec] | None = None
    optimize: OptimizeSpec | None = None
    tolerance: ToleranceSpec | None = None
    check: CheckSpec | None = None
    restore: RestoreSpec | None = None

    @model_validator(mode="after")
    def _structure(self) -> LensSpec:
        stops = [i for i, s in enumerate(self.surfaces) if s.stop]
        if not stops:
            raise ValueError("@surfaces: no surface has stop = true; mark the aperture stop")
        if len(stops) > 1:
            raise ValueError(f"@surfaces[{stops[1]}].stop: stop = true on several surfaces {stops}; "
                             "exactly one is the aperture stop")
        for i, el in enumerate(self.elements or []):
            if el.surfaces[1] >= len(self.surfaces):
                raise ValueError(f"@elements[{i}].surfaces: last surface {el.surfaces[1]} is beyond the "
                                 f"{len(self.surfaces)} surfaces")
        return self

    @property
    def stop_index(self) -> int:
        return next(i for i, s in enumerate(self.surfaces) if s.stop)
