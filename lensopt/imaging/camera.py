"""What imaging needs to know about a lens, as plain data (no spec, no pydantic): the traced lens and
system, the spectrum with its optional RGB weights, and the sensor. ``lensopt.spec.camera_of(model)``
builds one from a spec; the core (simulation, rendering, evaluation) takes only this."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from lensopt.optics.lens import Lens, System

__all__ = ["Camera", "SpectrumData", "ProvidesCamera", "as_camera"]


@dataclass(frozen=True)
class SpectrumData:
    """Wavelengths (nm), spectral weights (None = uniform) and an optional n_w × 3 RGB weight matrix."""

    wavelengths_nm: tuple[float, ...]
    weights: tuple[float, ...] | None = None
    rgb_weights: tuple[tuple[float, ...], ...] | None = None

    @property
    def weights_or_uniform(self) -> list[float]:
        return list(self.weights) if self.weights is not None else [1.0] * len(self.wavelengths_nm)


@dataclass(frozen=True)
class Camera:
    """A lens on a sensor.

    Attributes:
        name: the lens's name (plans and reports).
        lens, system: the traced lens and its aperture/field/weights.
        spectrum: wavelengths, weights, RGB weights.
        pixel_pitch_um: sensor pitch (None: no sensor given).
        resolution: sensor (W_s, H_s) pixels (None: an image is taken to cover the sensor pixel for pixel).
    """

    name: str
    lens: Lens
    system: System
    spectrum: SpectrumData
    pixel_pitch_um: float | None = None
    resolution: tuple[int, int] | None = None


class ProvidesCamera(Protocol):
    """Anything that can give its ``Camera`` (``lensopt.spec.Model`` does: ``model.camera()``)."""

    def camera(self) -> Camera: ...


def as_camera(obj: Camera | ProvidesCamera) -> Camera:
    """``obj`` itself if it is a ``Camera``, else ``obj.camera()`` (so callers may pass a built model)."""
    return obj if isinstance(obj, Camera) else obj.camera()
