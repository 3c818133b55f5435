"""Image files through OpenImageIO, with the colour encoding made explicit.

8/16-bit files (PNG, JPEG, integer TIFF) are taken as sRGB-encoded unless the file says it is linear,
and are linearized (IEC 61966-2-1 transfer function) before any simulation; float files (EXR, float
TIFF) are taken as linear. Writing re-encodes to sRGB for integer formats and keeps float formats
linear. ``ImageInfo.encoding`` says which, so the CLI can print it.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lensopt.errors import LensoptError
from lensopt.io.files import atomic_path
from lensopt.resources import require

log = logging.getLogger("lensopt")

__all__ = ["ImageInfo", "check_image_size", "check_pixels", "read_image",
           "write_image", "srgb_to_linear", "linear_to_srgb", "output_encoding"]

_FLOAT_EXT = {".exr", ".hdr", ".pfm"}
_INT_BITS = {"uint8": 8, "uint16": 16}


@dataclass(frozen=True)
class ImageInfo:
    """What was read.

    Attributes:
        width, height, channels: size (alpha dropped).
        bits: 8, 16 for integer files; 16 (half) or 32 for float files.
        is_float: float pixel data.
        encoding: ``sRGB`` (linearized on read) or ``linear``.
        format: file format name from OpenImageIO.
    """

    width: int
    height: int
    channels: int
    bits: int
    is_float: bool
    encoding: str
    format: str


def srgb_to_linear(v: np.ndarray) -> np.ndarray:
    """sRGB-encoded values in [0, 1] → linear light."""
    v = np.clip(v, 0.0, 1.0)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4).astype(np.float32)


def linear_to_srgb(v: np.ndarray) -> np.ndarray:
    """Linear light → sRGB-encoded values in [0, 1] (clipped)."""
    v = np.clip(v, 0.0, 1.0)
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * np.power(v, 1 / 2.4) - 0.055).astype(np.float32)


def _oiio():  # imported lazily: the PSF analysis does not need it
    import OpenImageIO as oiio

    return oiio


def read_image(path: str | Path, *, option: str = "IMAGE") -> tuple[np.ndarray, ImageInfo]:
    """Read ``path`` as linear float32 (H, W, C) with C = 1 or 3 (alpha and extra channels dropped)."""
    oiio = _oiio()
    path = Path(path)
    if not path.is_file():
        raise LensoptError("no such image file", path=option, got=str(path))
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise LensoptError(f"cannot read image: {oiio.geterror()}", path=option, got=str(path))
    try:
        spec = inp.spec()
        check_image_size(spec.width, spec.height, option=option, path=path)
        data = inp.read_image(0, 0, 0, spec.nchannels, "float")
        fmt = inp.format_name()
    finally:
        inp.close()
    if data is None:
        raise LensoptError("cannot decode image pixels", path=option, got=str(path))
    arr = np.asarray(data, dtype=np.float32).reshape(spec.height, spec.width, spec.nchannels)
    arr = check_pixels(arr, list(spec.channelnames), option=option, path=path)
    base = str(spec.format)
    is_float = base in ("half", "float", "double")
    bits = {"half": 16, "float": 32, "double": 64}.get(base, _INT_BITS.get(base, 8))
    cs = spec.get_string_attribute("oiio:ColorSpace", "").lower()
    linear = is_float or any(tag in cs for tag in ("linear", "lin_", "scene_linear", "acescg"))
    channels = 1 if spec.nchannels in (1, 2) else 3
    arr = arr[..., :channels]  # extra channels were reported by check_pixels
    if not linear:
        arr = srgb_to_linear(arr)
    info = ImageInfo(spec.width, spec.height, channels, bits, is_float, "linear" if linear else "sRGB", fmt)
    return np.ascontiguousarray(arr), info


#: Peak bytes per pixel through a simulation (float32 RGB copies: linearized scene, padded patches, blurred,
#: distorted, sRGB-encoded output; ~18 copies measured: 11.6 GB for a 9000×6000 image).
SIM_BYTES_PER_PIXEL = 240


def check_image_size(width: int, height: int, *, option: str = "IMAGE", path: str | Path = "") -> None:
    """Refuse empty images and images too large for the memory budget, before reading pixels."""
    if width < 1 or height < 1:
        raise LensoptError(f"image is {width}×{height} pixels", path=option, got=str(path))
    require(width * height * SIM_BYTES_PER_PIXEL, f"simulating a {width}×{height} image",
            lower="the image size (downscale or crop it)", path=option)


def check_pixels(arr: np.ndarray, names: list[str], *, option: str = "IMAGE", path: str | Path = "") -> np.ndarray:
    """(H, W, C) pixels as read: refuse NaN/inf, clamp negative light to 0, and say which channels are unused
    (alpha and channels beyond RGB are not simulated). Warnings go to the ``lensopt`` logger."""
    bad = ~np.isfinite(arr)
    if bad.any():
        raise LensoptError(f"{int(bad.sum())} pixel values are NaN or infinite; replace them (e.g. by 0) and retry",
                           path=option, got=str(path))
    neg = arr < 0
    if neg.any():
        log.warning("%s: %d negative pixel values set to 0 (light is not negative)", path, int(neg.sum()))
        arr = np.maximum(arr, 0.0)
    used = 1 if arr.shape[-1] in (1, 2) else 3
    if arr.shape[-1] > used:
        extra = [names[i] if i < len(names) and names[i] else f"#{i}" for i in range(used, arr.shape[-1])]
        log.warning("%s: channel%s %s not simulated (only %s)", path, "s" * (len(extra) > 1), ", ".join(extra),
                    "gray" if used == 1 else "RGB")
    return arr


def output_encoding(path: str | Path, source: ImageInfo) -> tuple[str, str]:
    """(pixel type, encoding) used to write ``path``: float files stay linear, integer files sRGB."""
    ext = Path(path).suffix.lower()
    if ext in _FLOAT_EXT or (ext in (".tif", ".tiff") and source.is_float):
        return "float", "linear"
    if ext in (".png", ".tif", ".tiff") and source.bits == 16 and not source.is_float:
        return "uint16", "sRGB"
    return "uint8", "sRGB"


def write_image(path: str | Path, linear: np.ndarray, source: ImageInfo, *, option: str = "--output") -> str:
    """Write a linear (H, W, C) image atomically, encoded per ``output_encoding``; returns a description."""
    oiio = _oiio()
    pixel_type, encoding = output_encoding(path, source)
    arr = np.asarray(linear, dtype=np.float32)
    if arr.ndim == 2:
        arr = arr[..., None]
    if encoding == "sRGB":
        arr = linear_to_srgb(arr)
    h, w, c = arr.shape
    fmt = {"uint8": oiio.UINT8, "uint16": oiio.UINT16, "float": oiio.FLOAT}[pixel_type]
    with atomic_path(path) as tmp:
        out = oiio.ImageOutput.create(str(tmp))
        if out is None:
            raise LensoptError(f"cannot write this image format: {oiio.geterror()}", path=option, got=str(path))
        spec = oiio.ImageSpec(w, h, c, fmt)
        spec.attribute("oiio:ColorSpace", "sRGB" if encoding == "sRGB" else "lin_rec709")
        if not out.open(str(tmp), spec):
            raise LensoptError(f"cannot write image: {out.geterror()}", path=option, got=str(path))
        ok = out.write_image(np.ascontiguousarray(arr))
        out.close()
        if not ok:
            raise LensoptError(f"cannot write image: {out.geterror()}", path=option, got=str(path))
    return f"{pixel_type} {encoding}"
