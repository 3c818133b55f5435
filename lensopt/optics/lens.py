"""The traced lens: a frozen dataclass of tensors plus static structure (DESIGN.md rule 2).

A lens is N interfaces and the gap after each (thickness + medium), like ray-optics' sequential
model; the last gap ends on a flat image surface. Everything a designer may vary is a tensor here, so
an optimizer builds a new ``Lens`` with ``dataclasses.replace`` from its variables θ and the trace
stays differentiable end to end.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import torch
from torch import Tensor

from lensopt.optics.placement import Placement

__all__ = ["SurfaceShape", "Lens", "System", "FrontAperture"]

ShapeKind = Literal["plane", "sphere", "conic", "asphere"]


@dataclass(frozen=True)
class SurfaceShape:
    """Static description of one interface: which formulas the trace uses for it.

    Attributes:
        kind: base profile; ``asphere`` means Newton intersection, the others are closed form.
        diffractive: whether a phase profile φ(r) (S35) bends rays by the generalized law (S15).
        order: diffraction order m used with the phase profile.
        design_wavelength_um: construction wavelength of a diffractive surface (export only).
        clip: whether the semi-diameter clips rays (reported as its own failure reason).
    """

    kind: ShapeKind = "sphere"
    diffractive: bool = False
    order: int = 1
    design_wavelength_um: float | None = None
    clip: bool = False


@dataclass(frozen=True)
class Lens:
    """Sequential lens as tensors. S surfaces, W wavelengths, A asphere and D phase coefficients.

    Attributes:
        shapes: (S,) static surface descriptions.
        curvature: (S,) vertex curvature c = 1/R, 1/mm (0 for planes).
        conic: (S,) conic constant κ.
        asphere: (S, A) even-asphere coefficients a4, a6, … (mm^(1−2i)); zero rows where unused.
        phase: (S, D) diffractive phase coefficients d2, d4, … (rad/mm^(2i)); zero rows where unused.
        thickness: (S,) gap after each surface, mm; the last one ends on the image surface.
        index: (S+1, W) refractive index of object space, then of the medium after each surface.
        wavelength_um: (W,) wavelengths, µm.
        semi_diameter: (S,) clear semi-aperture, mm (0 where not given: derived from traced rays).
        stop: index of the aperture stop surface.
        placement: decenters and tilts of surfaces and elements (``optics.placement``), or None for a
            lens on its axis (the rotationally symmetric fast path).
    """

    shapes: tuple[SurfaceShape, ...]
    curvature: Tensor
    conic: Tensor
    asphere: Tensor
    phase: Tensor
    thickness: Tensor
    index: Tensor
    wavelength_um: Tensor
    semi_diameter: Tensor
    stop: int
    placement: Placement | None = None

    @property
    def num_surfaces(self) -> int:
        return len(self.shapes)

    @property
    def dtype(self) -> torch.dtype:
        return self.curvature.dtype

    @property
    def device(self) -> torch.device:
        return self.curvature.device

    def vertex_z(self) -> Tensor:
        """(S+1,) axial position of every vertex and of the image surface, from surface 1, mm."""
        zero = torch.zeros_like(self.thickness[:1])
        return torch.cat([zero, torch.cumsum(self.thickness, 0)])

    def to(self, dtype: torch.dtype) -> Lens:
        """The same lens with every floating tensor cast to ``dtype``."""
        cast = {
            name: getattr(self, name).to(dtype)
            for name in ("curvature", "conic", "asphere", "phase", "thickness", "index",
                         "wavelength_um", "semi_diameter")
        }
        placement = None if self.placement is None else self.placement.to(dtype)
        return Lens(shapes=self.shapes, stop=self.stop, placement=placement, **cast)


@dataclass(frozen=True)
class FrontAperture:
    """A circular mechanical aperture in object space (S1.3.2, S4.1.5), centred on the axis.

    Attributes:
        distance: axial position of its plane from the vertex of surface 1, mm (negative: before it).
            It acts on the object-space rays (straight lines), so it must lie where the rays it blocks
            have not yet met surface 1.
        diameter: opening diameter, mm.
        lateral: how the lateral factor V_l is chosen: ``inscribed`` (the seed's rule: the elliptical
            bundle stays inside the unblocked part of the pupil) or ``extent`` (CODE V's: the ellipse
            through the four extreme points of the unblocked part).
    """

    distance: float
    diameter: float
    lateral: Literal["inscribed", "extent"] = "inscribed"


@dataclass(frozen=True)
class System:
    """First-order specification that turns a lens into ray bundles (S1.3.1).

    Attributes:
        epd: entrance pupil diameter in mm, or None when the aperture is an f-number.
        fnumber: paraxial f-number EFL/EPD, or None when the aperture is an EPD.
        field_type: ``angle`` (object-space half field angle, degrees) or ``image_height`` (mm).
        field_max: the largest field, in degrees or mm.
        rel_field: relative field samples u_h in [0, 1].
        object_distance: distance from the object to surface 1 in mm, None for infinity.
        wavelength_weights: (W,) spectral weights W_w.
        reference: index of the reference wavelength.
        aim: ``none`` (fill the paraxial entrance pupil), ``chief`` (chief ray through the stop centre) or
            ``full`` (chief ray through the centre, marginal rays on the stop edge, S21–S22).
        field_weights: per-field weights for the effective spot radius (empty: uniform).
        vignetting: fixed vignetting factors (V_i, V_s, V_l) per field (S19–S20), or empty.
        aim_steps: Newton steps of ``full`` aiming (S21–S22; 1 as in the seed).
        front_aperture: an object-space aperture whose vignetting factors follow the lens, or None.
    """

    epd: float | None
    fnumber: float | None
    field_type: Literal["angle", "image_height"]
    field_max: float
    rel_field: tuple[float, ...]
    object_distance: float | None
    wavelength_weights: Tensor
    reference: int
    aim: Literal["none", "chief", "full"] = "none"
    field_weights: tuple[float, ...] = field(default=())
    vignetting: tuple[tuple[float, float, float], ...] = field(default=())
    aim_steps: int = 1
    front_aperture: FrontAperture | None = None

    @property
    def num_fields(self) -> int:
        return len(self.rel_field)
