"""The ``[tolerance]`` section of a lens spec (also the top level of a ``--tolerances FILE``): which
manufacturing errors ``lensopt tolerance`` applies, how they are distributed, the compensator and the
Monte-Carlo settings. Units follow ``lensopt.tolerance.model`` (%, fringes, mm, index, %, arcmin)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

__all__ = ["ToleranceItemSpec", "ToleranceSpec", "PROFILES"]

PROFILES = ("s6.2",)

_Kind = Literal["curvature", "radius", "fringes", "thickness", "airspace", "index", "abbe", "decenter_x",
                "decenter_y", "tilt_x", "tilt_y", "element_decenter_x", "element_decenter_y", "element_tilt_x",
                "element_tilt_y"]
_Dist = Literal["uniform", "normal", "truncnormal"]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True, allow_inf_nan=False)


class ToleranceItemSpec(_Model):
    """One kind of tolerance on some surfaces (default: every surface it applies to) or elements.

    ``thickness`` applies to glass gaps, ``airspace`` to air gaps (both ± mm); ``curvature``/``radius``
    skip flat surfaces; ``index``/``abbe`` act on the glass after the surface; ``element_*`` act on
    elements given as [first, last] surfaces (default: every element found in the lens).
    """

    kind: _Kind
    limit: float = Field(gt=0)
    surfaces: list[int] | None = None
    elements: list[tuple[int, int]] | None = None
    distribution: _Dist | None = None

    @model_validator(mode="after")
    def _targets(self) -> ToleranceItemSpec:
        if self.kind.startswith("element_") and self.surfaces is not None:
            raise ValueError("@surfaces: element tolerances take elements = [[first, last], …]")
        if not self.kind.startswith("element_") and self.elements is not None:
            raise ValueError("@elements: only element_* tolerances act on elements")
        return self


class ToleranceSpec(_Model):
    """Settings of ``lensopt tolerance``; ``profile`` starts from a named set (S6.2), ``items`` add to it.
    ``compensator = "lm"``: the back focus in closed form plus the spec's variables (``vary`` radius and
    thickness entries) re-optimized by ``lm_steps`` Levenberg–Marquardt steps per trial.
    ``fields``: ``y`` (the system's +y fields), ``xy`` (each system field h at (0, ±h) and (±h, 0), its
    weight shared among the four) or a list of relative (x, y) field points (uniform weights).
    ``aim = "chief"``: every trial's chief rays aimed at the centre of its own (decentered, tilted) stop.
    ``metric = "psnr"``: ``psnr_count`` seeded dead-leaves scenes of ``psnr_patch`` pixels imaged as
    ``lensopt evaluate`` does (``psnr_sampling`` rays per PSF, ``psnr_noise``), restored by ``--irm``'s
    network when given (``lensopt.tolerance.psnr``)."""

    profile: Literal["s6.2"] | None = None
    items: list[ToleranceItemSpec] = Field(default_factory=list)
    distribution: _Dist = "uniform"
    trials: int = Field(default=100, ge=0, le=1_000_000)  # 0: the sensitivity table alone (--trials 0)
    seed: int = 0
    compensator: Literal["none", "focus", "lm"] = "focus"
    lm_steps: int = Field(default=5, ge=1, le=100)
    focus_range: float = Field(default=1.0, gt=0)
    metric: Literal["esr", "rms", "mtf", "distortion", "psnr"] = "esr"
    mtf_frequency: float | None = Field(default=None, gt=0)
    sampling: str = "rings:12"
    fields: Literal["y", "xy"] | list[tuple[float, float]] = "y"
    aim: Literal["none", "chief"] = "none"
    chunk: int = Field(default=25, ge=1, le=10_000)
    psnr_count: int = Field(default=4, ge=1, le=10_000)
    psnr_patch: int = Field(default=64, ge=8, le=4096)
    psnr_sampling: str = "rings:8"
    psnr_noise: float = Field(default=0.0, ge=0.0, lt=1.0)

    @model_validator(mode="after")
    def _something(self) -> ToleranceSpec:
        if self.profile is None and not self.items:
            raise ValueError("give a profile (\"s6.2\") or at least one item")
        if isinstance(self.fields, list) and not self.fields:
            raise ValueError("@fields: give \"y\", \"xy\" or at least one [x, y] relative field")
        if self.metric == "mtf" and self.mtf_frequency is None:
            raise ValueError("@mtf_frequency: the mtf metric needs a frequency (cycles/mm)")
        return self
