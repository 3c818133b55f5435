"""The ``[optimize]`` section of a lens spec: variables settings, solves, residual terms, optimizer.

Which surface quantities vary is declared per surface (``vary = [...]``); this section says how they
are scaled (S2.1, Table S4), which solves remove variables (Table S5), which residuals make the merit
function (S2.2, Table S6) and how the optimizer runs (S2.3, Table S7). Units: mm, degrees, fractions.
"""

from __future__ import annotations

import re
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

__all__ = [
    "SolveSpec",
    "GapBoundSpec",
    "SpanBoundSpec",
    "TraSpec",
    "RayPathSpec",
    "RayAngleSpec",
    "SurfaceNormalSpec",
    "DistortionSpec",
    "IlluminationSpec",
    "GlassMeshSpec",
    "GlassCatalogSpec",
    "RayFailureSpec",
    "ConstraintsSpec",
    "LMSpec",
    "AdamSpec",
    "ImageSpec",
    "WavefrontSpec",
    "OptimizeSpec",
]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True)


# ------------------------------------------------------------------------------------------ solves


class SolveSpec(_Model):
    """One solve (Table S5), evaluated inside the residual function (so always satisfied).

    - ``efl``: curvature of ``surface`` such that the EFL equals ``value`` (mm).
    - ``image_height``: curvature of ``surface`` (after the stop) such that the paraxial full-field
      image height on the image surface equals ``value`` (mm): the image-height-consistency focal
      length of S2.1.3, which keeps the image height when the image is defocused.
    - ``ttl``: last airspace such that the total track (surface 1 to image) equals ``value`` (mm).
    - ``focus``: last airspace to the paraxial focus of the marginal ray (plus ``image.defocus``).

    ``surface`` is a 0-based surface index (negative counts from the end, −1 = last surface).
    """

    type: Literal["efl", "image_height", "ttl", "focus"]
    surface: int | None = None
    value: float | None = None

    @model_validator(mode="after")
    def _fields(self) -> SolveSpec:
        if self.type in ("efl", "image_height", "ttl") and self.value is None:
            raise ValueError(f"@value: a {self.type} solve needs a target value")
        if self.type in ("efl", "image_height", "ttl") and not (self.value is not None and 0 < self.value <= 1e6):
            raise ValueError(f"@value: must be positive and at most 1e6 mm (got {self.value})")
        if self.type in ("ttl", "focus") and self.surface is not None:
            raise ValueError(f"@surface: a {self.type} solve acts on the last airspace; leave surface out")
        if self.type == "focus" and self.value is not None:
            raise ValueError("@value: a focus solve takes no value (use image.defocus)")
        return self


# ------------------------------------------------------------------------------------------ terms


def _check_knots(v: list[tuple[float, float]] | None) -> list[tuple[float, float]] | None:
    if v is None:
        return v
    for frac, weight in v:
        if not 0.0 <= frac <= 1.0:
            raise ValueError(f"schedule fractions must lie in [0, 1] (got {frac})")
        if not weight > 0:
            raise ValueError(f"schedule weights must be positive (got {weight})")
    if any(b[0] < a[0] for a, b in zip(v, v[1:], strict=False)):
        raise ValueError("schedule fractions must be increasing")
    return v


class _Weighted(_Model):
    """``weight`` of the group; ``schedule`` (optional) multiplies it over the run: (fraction of the
    steps, multiplier) knots, log-linear in between, flat outside (e.g. ``[[0.0, 0.01], [0.5, 1.0]]``
    enforces a constraint gently while glasses are free and fully after binding)."""

    weight: float = Field(default=1.0, ge=0)
    schedule: list[tuple[float, float]] | None = Field(default=None, min_length=1)

    @field_validator("schedule")
    @classmethod
    def _knots(cls, v: list[tuple[float, float]] | None) -> list[tuple[float, float]] | None:
        return _check_knots(v)


class TraSpec(_Weighted):
    """Transverse ray aberrations (S37–S39), wavelength- and field-weighted so that ‖ℓ_TRA‖ = ESR."""


class WavefrontSpec(_Weighted):
    """RMS wavefront error per field and wavelength as residuals (waves; the real chief ray's reference
    sphere, piston and tilt removed; ``analysis.wavefront``), beside the TRA or alone (``tra.weight =
    0``): the merit for lenses near the diffraction limit. ``n``: the rays, an n × n grid over the pupil
    (the points inside the circle); ``tilt``: remove tilt as well as piston (a tilt is a shift of the
    image, which the spot centroid and distortion already describe)."""

    n: int = Field(default=12, ge=2, le=64)
    tilt: bool = True


class GapBoundSpec(_Model):
    """Ray-path bounds for one gap (the gap after surface ``gap``, 0-based), overriding the defaults."""

    gap: int
    min: float | None = None
    max: float | None = None


class SpanBoundSpec(_Model):
    """Ray-path bounds on a run of consecutive gaps: the axial distance each ray travels from its hit on
    surface ``first`` to its hit on surface ``to`` (0-based; negative counts from the end; ``to`` left
    out: the image). E.g. a mechanical flange distance from the last lens surface to the sensor across
    an IR filter: ``{ first = 10, min = 5.1 }``."""

    first: int
    to: int | None = None
    min: float | None = None
    max: float | None = None

    @model_validator(mode="after")
    def _some_bound(self) -> SpanBoundSpec:
        if self.min is None and self.max is None:
            raise ValueError("@min: a span needs a min or a max (mm)")
        return self


class RayPathSpec(_Weighted):
    """Ray path residuals (S41–S42) on the axial distance t_z each ray travels in every gap, mm.

    Glass gaps: ``max(glass_min, CT/glass_ratio) ≤ t_z ≤ min(glass_max, glass_ratio·CT)`` with CT the
    centre thickness. Air gaps: ``air_min ≤ t_z ≤ air_max``. The last gap (to the image) uses
    ``image_min``/``image_max`` (image clearance) instead. ``gaps`` override single gaps; ``spans``
    bound the sum over several consecutive gaps (e.g. a flange distance across a filter), as extra rows.
    """

    glass_min: float = 0.0
    glass_max: float | None = None
    glass_ratio: float | None = Field(default=None, gt=1.0)
    air_min: float = 0.0
    air_max: float | None = None
    image_min: float | None = 0.0
    image_max: float | None = None
    gaps: list[GapBoundSpec] = Field(default_factory=list)
    spans: list[SpanBoundSpec] | None = None  # None (not []): absent from written lenses


class RayAngleSpec(_Weighted):
    """Angles of incidence and refraction at every interface within ±``max_deg`` (S43–S45)."""

    max_deg: float = Field(default=60.0, gt=0, lt=90)


class SurfaceNormalSpec(_Weighted):
    """Angle between refracting-surface normals (where rays hit) and the axis ≤ ``max_deg`` (S46–S47)."""

    max_deg: float = Field(default=30.0, gt=0, lt=90)


class DistortionSpec(_Weighted):
    """|D_h| ≤ ``max_percent`` % for every field (S48–S50)."""

    max_percent: float = Field(default=2.0, gt=0)


class IlluminationSpec(_Weighted):
    """Relative illumination (all-ray estimate S52) ≥ ``min`` for every field (S53–S54)."""

    min: float = Field(default=0.7, gt=0, le=1)


class GlassMeshSpec(_Weighted):
    """Distance of each glass variable to the catalog's Delaunay mesh (S55), edges longer than
    ``max_edge`` (whitened units) pruned."""

    max_edge: float = Field(default=1.25, gt=0)


class GlassCatalogSpec(_Model):
    """Distance of each glass variable to its nearest catalog glass (S56–S57), weighted by a piecewise
    exponential schedule: ``schedule`` holds (fraction of the run, weight) knots; the weight is
    interpolated log-linearly between knots and held constant outside them."""

    schedule: list[tuple[float, float]] = Field(default_factory=lambda: [(0.0, 1e-4), (0.5, 1e-1)], min_length=1)

    @field_validator("schedule")
    @classmethod
    def _knots(cls, v: list[tuple[float, float]]) -> list[tuple[float, float]]:
        return _check_knots(v)


class RayFailureSpec(_Model):
    """Every ray that fails adds a constant residual ``penalty_mm``/√n_r (default α): no step may buy
    a smaller spot with failed rays. ``weight = 0`` turns it off."""

    weight: float = Field(default=1.0, ge=0)
    penalty_mm: float | None = Field(default=None, gt=0)


class ConstraintsSpec(_Model):
    """Soft constraints; a group left out is off (glass groups and ray failures are on by default)."""

    ray_path: RayPathSpec | None = None
    ray_angle: RayAngleSpec | None = None
    surface_normal: SurfaceNormalSpec | None = None
    distortion: DistortionSpec | None = None
    relative_illumination: IlluminationSpec | None = None
    glass_mesh: GlassMeshSpec | None = Field(default_factory=GlassMeshSpec)
    glass_catalog: GlassCatalogSpec | None = Field(default_factory=GlassCatalogSpec)
    ray_failure: RayFailureSpec = Field(default_factory=RayFailureSpec)


# -------------------------------------------------------------------------------------- optimizers


class LMSpec(_Model):
    """Levenberg–Marquardt settings (Table S7 defaults) and stopping rules."""

    damping: float = Field(default=1.0, gt=0, description="λ0, initial damping factor")
    epsilon: float = Field(default=1e-6, gt=0, description="floor of the initial damping matrix D0")
    beta: float = Field(default=0.99, ge=0, lt=1, description="running-max parameter of D (S64)")
    increase: float = Field(default=2.0, gt=1, description="IF: λ ← IF·λ when the merit rises")
    decrease: float = Field(default=3.0, gt=1, description="DF: λ ← λ/DF when the merit falls")
    tolerance: float = Field(default=1.0, ge=1, description="TF: reject steps with L_new > TF·L")
    max_damping: float = Field(default=1e12, gt=0, description="stop when λ exceeds this")
    merit_tolerance: float = Field(default=1e-10, ge=0,
                                   description="stop when the merit fell by less than this (relative) "
                                               "over the last `patience` steps")
    patience: int = Field(default=50, ge=1)


class AdamSpec(_Model):
    """Adam (torch.optim.Adam) on ½‖ℓ‖² for comparison."""

    lr: float = Field(default=1e-3, gt=0)
    beta1: float = Field(default=0.9, ge=0, lt=1)
    beta2: float = Field(default=0.999, ge=0, lt=1)


class ImageSpec(_Model):
    """``[optimize.image]``: how image-driven objectives (``objective = "raw"``) render training batches
    (S1.5, S3.3.1).

    Attributes:
        weight: weight of the image term (ℓ_GTRA for LM, the scalar loss for Adam).
        patch: patch size in sensor pixels (square); the sensor is cut into tiles of this size.
        batch: patches per step.
        psf_size: PSF array side in sensor pixels (odd; the seed's C-mount study: 49).
        grid: sub-tile PSF grid per patch (W_g, H_g).
        overlap: overlap of neighbouring sub-tiles (S1.5.2).
        fields: number of equidistant relative fields (0 … 1) whose PSFs render the patches.
        sampling: pupil sampling of the rendering rays (its spot diagrams are ε of GTRA).
        kernel: KDE kernel (S1.4.2).
        diffraction: apply the diffraction heuristic (S1.4.3) to the PSFs.
        noise: σ of the additive Gaussian noise, fraction of the maximum (S3.3.1).
        images: training scenes, as ``train-irm --images``: procedural | textured | photos (the bundled
            training photographs) | a folder of images (DIV2K layout or a hash split) | a mixture
            ``a+b``; absent: procedural dead-leaves scenes.
        validation: held-out patches used for the PSNR reported at the end.
        seed: seed of scenes, crops, regions and noise.
    """

    weight: float = Field(default=1.0, gt=0)
    patch: int = Field(default=128, ge=8)
    batch: int = Field(default=4, ge=1)
    psf_size: int = 49
    grid: tuple[int, int] = (3, 3)
    overlap: float = Field(default=0.25, ge=0, le=1)
    fields: int = Field(default=11, ge=2, le=64)
    sampling: str = "rings:12"
    kernel: Literal["triangular", "cosine"] = "triangular"
    diffraction: bool = False
    noise: float = Field(default=0.005, ge=0, lt=1)
    images: str | None = None
    validation: int = Field(default=16, ge=1)
    seed: int = 0

    @field_validator("psf_size")
    @classmethod
    def _odd(cls, v: int) -> int:
        if v < 1 or v % 2 == 0:
            raise ValueError(f"must be a positive odd number of pixels (got {v})")
        return v

    @field_validator("grid")
    @classmethod
    def _grid(cls, v: tuple[int, int]) -> tuple[int, int]:
        if min(v) < 1:
            raise ValueError(f"must be two positive integers (got {list(v)})")
        return v

    @field_validator("sampling")
    @classmethod
    def _sampling(cls, v: str) -> str:
        return _check_sampling(v)


def _check_sampling(v: str) -> str:
    m = re.fullmatch(r"(rings|grid):(\d+)(:nojitter)?", v.strip())
    if not m or int(m.group(2)) < 1 or (m.group(1) == "grid" and m.group(3)):
        raise ValueError(f"expected rings:N, rings:N:nojitter or grid:N with N ≥ 1 (got {v!r})")
    return v.strip()


class OptimizeSpec(_Model):
    """How ``lensopt optimize`` runs on this spec.

    Attributes:
        alpha: scale factor α of the variables (mm); default EPD/2 (S2.1).
        sampling: pupil sampling of the optimization rays (``rings:N`` or ``grid:N``).
        sampling_after_binding: the sampling from the binding of the glasses on (a finer one polishes
            the final design at a higher cost per step); default: ``sampling``.
        rim_rays: extra rays per field and wavelength on the pupil rim (top, lateral, bottom and
            between), plus one at the pupil centre, for the geometric constraints and failures; not
            part of the spot size (0: none).
        asphere_basis: ``monomial`` (a'_2i = α^2i a_2i) or ``bezier`` (Bernstein control points of
            the same polynomial, a linear re-parameterization, S2.1.3).
        catalog: design catalog of the glass variables: ohara-recommended | schott-preferred |
            plastics | path/to/file.csv. When not set, varied catalog glasses stay in their own vendor's
            catalog (schott → schott-preferred, ohara → ohara-recommended, plastics → plastics) if they
            all start from one such vendor, else ohara-recommended; the choice is one notice.
        glass_parameters: 2 (nd, vd; ΔPgF = 0) or 3 (nd, vd, ΔPgF).
        bind_at: fraction of the steps after which glasses are bound to their nearest catalog
            entry, frozen, and the optimizer reset (S4.1.3); 1 = never.
        steps: number of optimizer steps (the CLI's --steps overrides).
        optimizer: ``lm`` or ``adam`` (the CLI's --optimizer overrides).
        objective: ``spot`` (TRA, spot size; the default, also when None) or ``raw`` (MSE of the simulated
            capture against the scene, through GTRA for LM, S3.1; needs ``[sensor]``; rendering set by
            ``image``) or ``restored`` (MSE after the restoration network of ``[restore]``, lens and network
            optimized jointly, S3.3; LM only).
        image: ``[optimize.image]``, the rendering of training batches for image objectives.
        tra: ``[optimize.tra]``, the spot-size term (``weight = 0``: off).
        wavefront: ``[optimize.wavefront]``, the RMS wavefront error term (absent: off).
    """

    alpha: float | None = Field(default=None, gt=0)
    sampling: str = "rings:6"
    sampling_after_binding: str | None = None
    rim_rays: int = Field(default=9, ge=0, le=64)
    asphere_basis: Literal["monomial", "bezier"] = "monomial"
    catalog: str = "ohara-recommended"
    glass_parameters: Literal[2, 3] = 3
    bind_at: float = Field(default=0.5, ge=0, le=1)
    steps: int = Field(default=500, ge=1)
    optimizer: Literal["lm", "adam"] = "lm"
    objective: Literal["spot", "raw", "restored"] | None = None
    image: ImageSpec | None = None
    solves: list[Annotated[SolveSpec, Field()]] = Field(default_factory=list)
    tra: TraSpec = Field(default_factory=TraSpec)
    wavefront: WavefrontSpec | None = None
    constraints: ConstraintsSpec = Field(default_factory=ConstraintsSpec)
    lm: LMSpec = Field(default_factory=LMSpec)
    adam: AdamSpec = Field(default_factory=AdamSpec)

    @field_validator("sampling", "sampling_after_binding")
    @classmethod
    def _sampling(cls, v: str | None) -> str | None:
        if v is None:
            return v
        m = re.fullmatch(r"(rings|grid):(\d+)(:nojitter)?", v.strip())
        if not m or int(m.group(2)) < 1 or (m.group(1) == "grid" and m.group(3)):
            raise ValueError(f"expected rings:N, rings:N:nojitter or grid:N with N ≥ 1 (got {v!r})")
        return v.strip()

    def at_full_weight(self) -> OptimizeSpec:
        """A copy whose TRA and constraint groups have no ``schedule``: each group at the weight its schedule
        ends on (``weight`` × the last knot's multiplier), in force from the first step. For continuing a
        written lens, where a restarted schedule would relax the constraints it already meets.
        ``glass_catalog`` keeps its schedule: it is the pull towards the catalog before binding."""

        def settled(group: _Weighted) -> _Weighted:
            if group.schedule is None:
                return group
            return group.model_copy(update={"weight": group.weight * group.schedule[-1][1], "schedule": None})

        cons = self.constraints
        groups = {name: settled(getattr(cons, name)) for name in type(cons).model_fields
                  if isinstance(getattr(cons, name), _Weighted)}
        update = {"tra": settled(self.tra), "constraints": cons.model_copy(update=groups)}
        if self.wavefront is not None:
            update["wavefront"] = settled(self.wavefront)
        return self.model_copy(update=update)

    @model_validator(mode="after")
    def _one_solve_per_kind(self) -> OptimizeSpec:
        last_gap = [i for i, s in enumerate(self.solves) if s.type in ("ttl", "focus")]
        if len(last_gap) > 1:
            raise ValueError(f"@solves[{last_gap[1]}]: only one solve (ttl or focus) may set the last airspace")
        types = {s.type for s in self.solves}
        if "image_height" in types and "focus" in types:
            raise ValueError("@solves: an image_height solve cannot be combined with a focus solve "
                             "(at focus the image height is EFL·tan θ: use an efl solve)")
        return self
