"""Spec → tensors: the one builder that turns a validated ``LensSpec`` into a ``Lens`` and ``System``
(DESIGN.md rule 5: units converted here, once — nm → µm, radii → curvatures)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch

from lensopt.errors import LensoptError
from lensopt.imaging.camera import Camera, SpectrumData
from lensopt.materials import Material, ModelGlass, TabulatedGlass, material_from_name
from lensopt.optics.lens import FrontAperture, Lens, SurfaceShape, System
from lensopt.optics.placement import Placement
from lensopt.spec.models import (
    AgfGlassSpec,
    DiffractiveSurface,
    LensSpec,
    ModelGlassSpec,
    TabulatedGlassSpec,
    curvature_of,
)

__all__ = ["Model", "build", "camera_of", "placement_of", "resolve_material"]


@dataclass(frozen=True)
class Model:
    """A built lens: tensors for the trace, the system, and the materials of every medium.

    Attributes:
        lens: the traced lens.
        system: aperture, field, object, weights.
        media: (S+1) materials: object space, then the medium after every surface.
        spec: the spec it was built from.
    """

    lens: Lens
    system: System
    media: tuple[Material, ...]
    spec: LensSpec

    @property
    def name(self) -> str:
        """The lens's name (what ``analysis.report`` reads instead of the spec)."""
        return self.spec.name

    def camera(self) -> Camera:
        """The plain-data view imaging works on (``camera_of``)."""
        return camera_of(self)


def resolve_material(value: str | ModelGlassSpec | TabulatedGlassSpec | AgfGlassSpec, *, path: str,
                     wavelengths_um: Sequence[float] | None = None) -> Material:
    """Material object for a spec's ``material`` value; errors and notices name ``path``. A bare glass
    name takes the first vendor whose data cover ``wavelengths_um`` (``materials.resolve_glass``)."""
    try:
        if isinstance(value, ModelGlassSpec):
            return ModelGlass(value.nd, value.vd, value.dpgf, name=value.name)
        if isinstance(value, TabulatedGlassSpec):
            return TabulatedGlass(value.name, tuple(w * 1e-3 for w in value.wavelengths_nm), tuple(value.index))
        if isinstance(value, AgfGlassSpec):
            from lensopt.materials.agf import agf_glass

            return agf_glass(value.catalog, value.glass)
        return material_from_name(value, wavelengths_um, path=path)
    except LensoptError as err:
        raise err.at(path) from None


def build(spec: LensSpec, *, dtype: torch.dtype = torch.float64, device: torch.device | None = None) -> Model:
    """Build the traced lens. Raises ``SpecError``/``MaterialError`` naming the field on bad input."""
    opts = {"dtype": dtype, "device": device}
    wavelengths_um = [w * 1e-3 for w in spec.spectrum.wavelengths_nm]
    media: list[Material] = [material_from_name("air")]
    for i, surf in enumerate(spec.surfaces):
        path = f"surfaces[{i}].material"
        mat = resolve_material(surf.material, path=path, wavelengths_um=wavelengths_um)
        mat.check_wavelengths(wavelengths_um, path=path)
        media.append(mat)
    wl = torch.tensor(wavelengths_um, **opts)
    index = torch.stack([m.index(wl) for m in media])

    shapes, curv, conic, asph, phase = [], [], [], [], []
    for surf in spec.surfaces:
        base = surf.base if isinstance(surf, DiffractiveSurface) else surf
        shapes.append(
            SurfaceShape(
                kind=base.type,
                diffractive=isinstance(surf, DiffractiveSurface),
                order=surf.order if isinstance(surf, DiffractiveSurface) else 1,
                design_wavelength_um=(surf.design_wavelength_nm * 1e-3
                                      if isinstance(surf, DiffractiveSurface) else None),
                clip=surf.clip,
            )
        )
        curv.append(curvature_of(base))
        conic.append(getattr(base, "conic", 0.0))
        asph.append(getattr(base, "coefficients", {}))
        phase.append(surf.phase if isinstance(surf, DiffractiveSurface) else {})
    thickness = [s.thickness for s in spec.surfaces]
    thickness[-1] += spec.image.defocus
    lens = Lens(
        shapes=tuple(shapes),
        curvature=torch.tensor(curv, **opts),
        conic=torch.tensor(conic, **opts),
        asphere=_coefficient_table(asph, first_power=4, **opts),
        phase=_coefficient_table(phase, first_power=2, **opts),
        thickness=torch.tensor(thickness, **opts),
        index=index,
        wavelength_um=wl,
        semi_diameter=torch.tensor([s.semi_diameter or 0.0 for s in spec.surfaces], **opts),
        stop=spec.stop_index,
        placement=placement_of(spec, **opts),
    )
    sysm = spec.system
    fld = sysm.field
    system = System(
        epd=sysm.aperture.epd,
        fnumber=sysm.aperture.fnumber,
        field_type="angle" if fld.hfov_deg is not None else "image_height",
        field_max=fld.hfov_deg if fld.hfov_deg is not None else fld.image_height,
        rel_field=tuple(fld.relative),
        object_distance=None if sysm.object == "infinity" else sysm.object.distance,
        wavelength_weights=torch.tensor(spec.spectrum.weights_or_uniform, **opts),
        reference=spec.spectrum.reference_index,
        aim=sysm.aim,
        field_weights=tuple(fld.weights) if fld.weights is not None else (),
        vignetting=(tuple(zip(sysm.vignetting.inferior, sysm.vignetting.superior, sysm.vignetting.lateral,
                              strict=True)) if sysm.vignetting is not None else ()),
        aim_steps=sysm.aim_steps,
        front_aperture=(FrontAperture(sysm.front_aperture.distance, sysm.front_aperture.diameter,
                                      sysm.front_aperture.lateral) if sysm.front_aperture is not None else None),
    )
    return Model(lens=lens, system=system, media=tuple(media), spec=spec)


def camera_of(model: Model) -> Camera:
    """The plain-data view imaging works on (``lensopt.imaging.camera``): no pydantic below this line."""
    spec = model.spec
    sp = spec.spectrum
    spectrum = SpectrumData(
        wavelengths_nm=tuple(float(w) for w in sp.wavelengths_nm),
        weights=tuple(float(w) for w in sp.weights) if sp.weights is not None else None,
        rgb_weights=tuple(tuple(float(v) for v in row) for row in sp.rgb_weights) if sp.rgb_weights else None,
    )
    sensor = spec.sensor
    return Camera(name=spec.name, lens=model.lens, system=model.system, spectrum=spectrum,
                  pixel_pitch_um=sensor.pixel_pitch_um if sensor is not None else None,
                  resolution=(int(sensor.resolution[0]), int(sensor.resolution[1]))
                  if sensor is not None and sensor.resolution is not None else None)


def _coefficient_table(rows: list[dict[int, float]], *, first_power: int, dtype, device) -> torch.Tensor:
    """(S, K) table of even-power coefficients; column j holds power ``first_power + 2j``."""
    top = max((max(r) for r in rows if r), default=first_power - 2)
    width = (top - first_power) // 2 + 1
    table = torch.zeros(len(rows), max(width, 0), dtype=dtype, device=device)
    for i, r in enumerate(rows):
        for power, value in r.items():
            table[i, (power - first_power) // 2] = value
    return table


def placement_of(spec: LensSpec, *, dtype: torch.dtype, device: torch.device | None) -> Placement | None:
    """The spec's surface and element decenters/tilts (degrees → radians), or None when every surface
    and element sits on the axis (the trace then takes the symmetric fast path)."""
    surfs, elements = spec.surfaces, spec.elements or []
    zero = (0.0, 0.0)
    dec = [s.decenter or zero for s in surfs]
    tilt = [s.tilt_deg or zero for s in surfs]
    moved = [e for e in elements if e.decenter != zero or e.tilt_deg != zero]
    if all(d == zero for d in dec) and all(t == zero for t in tilt) and not moved:
        return None
    rad = torch.pi / 180.0
    opts = {"dtype": dtype, "device": device}
    return Placement(
        decenter=torch.tensor(dec, **opts),
        tilt=torch.tensor(tilt, **opts) * rad,
        basic=tuple(s.decenter_mode == "basic" for s in surfs),
        groups=tuple((e.surfaces[0], e.surfaces[1]) for e in elements),
        group_decenter=torch.tensor([list(e.decenter) for e in elements], **opts).reshape(-1, 2),
        group_tilt=torch.tensor([list(e.tilt_deg) for e in elements], **opts).reshape(-1, 2) * rad,
    )
