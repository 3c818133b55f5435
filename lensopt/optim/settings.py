"""The settings of an optimization problem as plain frozen dataclasses: what ``Problem``, the residual
terms and the optimizers read (S2.1–S2.3, S3.1). The ``[optimize]`` section of a spec converts to these
in ``lensopt.design.setup`` (the spec layer's pydantic models carry the validation and the
documentation of every field; the defaults here are theirs, which ``tests/optim/test_settings.py``
holds equal). Units: mm, degrees, fractions.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = [
    "Knots",
    "TraSettings",
    "GapBound",
    "SpanBound",
    "RayPathSettings",
    "RayAngleSettings",
    "SurfaceNormalSettings",
    "DistortionSettings",
    "IlluminationSettings",
    "GlassMeshSettings",
    "GlassCatalogSettings",
    "RayFailureSettings",
    "ConstraintSettings",
    "LMSettings",
    "AdamSettings",
    "ImageSettings",
    "OptimizeSettings",
]

Knots = tuple[tuple[float, float], ...]
"""A weight schedule: (fraction of the steps, multiplier) knots, log-linear in between."""


@dataclass(frozen=True)
class TraSettings:
    """Transverse ray aberrations (S37–S39)."""

    weight: float = 1.0
    schedule: Knots | None = None


@dataclass(frozen=True)
class WavefrontSettings:
    """RMS wavefront error (``analysis.wavefront``: the real chief ray's reference sphere, piston and
    tilt removed) per field and wavelength as residuals, on an ``n`` × ``n`` pupil grid."""

    weight: float = 1.0
    schedule: Knots | None = None
    n: int = 12
    tilt: bool = True


@dataclass(frozen=True)
class GapBound:
    """Ray-path bounds (mm) of the gap after surface ``gap``."""

    gap: int
    min: float | None = None
    max: float | None = None


@dataclass(frozen=True)
class SpanBound:
    """Ray-path bounds (mm) from surface ``first`` to surface ``to`` (None: the image)."""

    first: int
    to: int | None = None
    min: float | None = None
    max: float | None = None


@dataclass(frozen=True)
class RayPathSettings:
    """Axial ray path per gap (S41–S42), mm."""

    weight: float = 1.0
    schedule: Knots | None = None
    glass_min: float = 0.0
    glass_max: float | None = None
    glass_ratio: float | None = None
    air_min: float = 0.0
    air_max: float | None = None
    image_min: float | None = 0.0
    image_max: float | None = None
    gaps: tuple[GapBound, ...] = ()
    spans: tuple[SpanBound, ...] | None = None


@dataclass(frozen=True)
class RayAngleSettings:
    """Angles of incidence and refraction (S43–S45), degrees."""

    weight: float = 1.0
    schedule: Knots | None = None
    max_deg: float = 60.0


@dataclass(frozen=True)
class SurfaceNormalSettings:
    """Surface normal angles (S46–S47), degrees."""

    weight: float = 1.0
    schedule: Knots | None = None
    max_deg: float = 30.0


@dataclass(frozen=True)
class DistortionSettings:
    """|distortion| per field (S48–S50), percent."""

    weight: float = 1.0
    schedule: Knots | None = None
    max_percent: float = 2.0


@dataclass(frozen=True)
class IlluminationSettings:
    """Relative illumination per field (S52–S54), fraction."""

    weight: float = 1.0
    schedule: Knots | None = None
    min: float = 0.7


@dataclass(frozen=True)
class GlassMeshSettings:
    """Glass variables to the catalog mesh (S55), edges longer than ``max_edge`` pruned."""

    weight: float = 1.0
    schedule: Knots | None = None
    max_edge: float = 1.25


@dataclass(frozen=True)
class GlassCatalogSettings:
    """Glass variables to the nearest catalog glass (S56–S57), weighted by ``schedule``."""

    schedule: Knots = ((0.0, 1e-4), (0.5, 1e-1))


@dataclass(frozen=True)
class RayFailureSettings:
    """A constant residual per failed ray (``penalty_mm``, default α); weight 0 turns it off."""

    weight: float = 1.0
    penalty_mm: float | None = None


@dataclass(frozen=True)
class ConstraintSettings:
    """Soft constraints; None = off (the glass groups and ray failures are on by default)."""

    ray_path: RayPathSettings | None = None
    ray_angle: RayAngleSettings | None = None
    surface_normal: SurfaceNormalSettings | None = None
    distortion: DistortionSettings | None = None
    relative_illumination: IlluminationSettings | None = None
    glass_mesh: GlassMeshSettings | None = field(default_factory=GlassMeshSettings)
    glass_catalog: GlassCatalogSettings | None = field(default_factory=GlassCatalogSettings)
    ray_failure: RayFailureSettings = field(default_factory=RayFailureSettings)


@dataclass(frozen=True)
class LMSettings:
    """Levenberg–Marquardt settings (Table S7) and stopping rules: initial damping λ0, floor ε of D0,
    running-max β of D (S64), increase/decrease factors IF/DF, step tolerance TF, the damping that stops
    the run, and the relative merit change over ``patience`` steps that stops it."""

    damping: float = 1.0
    epsilon: float = 1e-6
    beta: float = 0.99
    increase: float = 2.0
    decrease: float = 3.0
    tolerance: float = 1.0
    max_damping: float = 1e12
    merit_tolerance: float = 1e-10
    patience: int = 50


@dataclass(frozen=True)
class AdamSettings:
    """Adam (``torch.optim.Adam``) on ½‖ℓ‖² of the scaled variables."""

    lr: float = 1e-3
    beta1: float = 0.9
    beta2: float = 0.999


@dataclass(frozen=True)
class ImageSettings:
    """Rendering of training batches for image objectives (S1.5, S3.3.1): patch size and batch, PSF
    array side (odd, pixels), sub-tile grid, overlap, equidistant fields, rendering-ray sampling, KDE
    kernel, diffraction heuristic, noise σ (fraction of the maximum), image folder (None: dead leaves),
    held-out patches, seed."""

    weight: float = 1.0
    patch: int = 128
    batch: int = 4
    psf_size: int = 49
    grid: tuple[int, int] = (3, 3)
    overlap: float = 0.25
    fields: int = 11
    sampling: str = "rings:12"
    kernel: str = "triangular"
    diffraction: bool = False
    noise: float = 0.005
    images: str | None = None
    validation: int = 16
    seed: int = 0


@dataclass(frozen=True)
class OptimizeSettings:
    """How a problem is set up and run (the ``[optimize]`` section without its solves, which resolve to
    ``lensopt.optim.solves.Solve``)."""

    alpha: float | None = None
    sampling: str = "rings:6"
    sampling_after_binding: str | None = None
    rim_rays: int = 9
    asphere_basis: str = "monomial"
    catalog: str = "ohara-recommended"
    glass_parameters: int = 3
    bind_at: float = 0.5
    steps: int = 500
    optimizer: str = "lm"
    objective: str | None = None
    image: ImageSettings | None = None
    tra: TraSettings = field(default_factory=TraSettings)
    wavefront: WavefrontSettings | None = None
    constraints: ConstraintSettings = field(default_factory=ConstraintSettings)
    lm: LMSettings = field(default_factory=LMSettings)
    adam: AdamSettings = field(default_factory=AdamSettings)
