"""Image files through OpenImageIO, with the colour encoding made explicit.

8/16-bit files (PNG, JPEG, integer TIFF) are taken as sRGB-encoded unless the file says it is linear,
and are linearized (IEC 61966-2-1 transfer function) before any simulation; float files (EXR, float
TIFF) are taken as linear. Writing re-encodes to sRGB for integer formats and keeps float formats
linear. ``ImageInfo.encoding`` says which, so the CLI can print it.

Large images are cheap in time and memory: integer files are read in their own pixel type and decoded
through a lookup table of the same float32 transfer function (no float copy of the whole file, no
per-pixel power), straight into a channel-planar buffer (``read_image`` returns an (H, W, C) view of
a (C, H, W) array, the layout the simulation convolves); integer files are written from an integer
buffer encoded in row bands and rounded as OpenImageIO rounds, so the files hold the same codes as
converting the whole float image at once (up to exact float32 ties, see ``encode_integer``); PNGs are
compressed at zlib level 1 with the Paeth filter (``PNG_OPTIONS``; OpenImageIO's default is level 6
with adaptive filtering: files ≈ 13 % smaller, several times slower to write; both lossless).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lensopt.engine import Engine
from lensopt.errors import LensoptError
from lensopt.files import atomic_path

log = logging.getLogger("lensopt")

__all__ = ["ImageInfo", "check_image_size", "check_pixels", "read_image", "write_image", "encode_integer",
           "srgb_to_linear", "linear_to_srgb", "output_encoding", "PNG_OPTIONS"]

_FLOAT_EXT = {".exr", ".hdr", ".pfm"}
_INT_BITS = {"uint8": 8, "uint16": 16}
#: PNG encoder settings: zlib level 1 and the Paeth filter (libpng PNG_FILTER_PAETH = 0x80).
PNG_OPTIONS = {"png:compressionLevel": 1, "png:filter": 0x80}
#: Rows per band when encoding or decoding: temporaries stay a few MB for any image width up to ~20k.
_BAND_ROWS = 128


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


def _decode_table(bits: int, linear: bool) -> np.ndarray:
    """Linear float32 value of every integer code: OpenImageIO's conversion (code × float32(1/max)),
    then ``srgb_to_linear`` unless the file is linear — the same values as converting the pixels."""
    top = (1 << bits) - 1
    v = np.arange(top + 1, dtype=np.float32) * np.float32(1.0 / top)
    return v if linear else srgb_to_linear(v)


def _oiio():  # imported lazily: the PSF analysis does not need it
    import OpenImageIO as oiio

    return oiio


def read_image(path: str | Path, *, option: str = "IMAGE",
               engine: Engine | None = None) -> tuple[np.ndarray, ImageInfo]:
    """Read ``path`` as linear float32 (H, W, C) with C = 1 or 3 (alpha and extra channels dropped).

    The array is a view of a channel-planar (C, H, W) buffer (``arr.transpose(2, 0, 1)`` is contiguous).
    """
    oiio = _oiio()
    path = Path(path)
    if not path.is_file():
        raise LensoptError("no such image file", path=option, got=str(path))
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise LensoptError(f"cannot read image: {oiio.geterror()}", path=option, got=str(path))
    try:
        spec = inp.spec()
        check_image_size(spec.width, spec.height, option=option, path=path, engine=engine)
        base = str(spec.format)
        native = base in _INT_BITS  # 8/16-bit: read as is, decode through a table
        data = inp.read_image(0, 0, 0, spec.nchannels, base if native else "float")
        fmt = inp.format_name()
    finally:
        inp.close()
    if data is None:
        raise LensoptError("cannot decode image pixels", path=option, got=str(path))
    is_float = base in ("half", "float", "double")
    bits = {"half": 16, "float": 32, "double": 64}.get(base, _INT_BITS.get(base, 8))
    cs = spec.get_string_attribute("oiio:ColorSpace", "").lower()
    linear = is_float or any(tag in cs for tag in ("linear", "lin_", "scene_linear", "acescg"))
    channels = 1 if spec.nchannels in (1, 2) else 3
    info = ImageInfo(spec.width, spec.height, channels, bits, is_float, "linear" if linear else "sRGB", fmt)
    if native:
        raw = np.asarray(data).reshape(spec.height, spec.width, spec.nchannels)
        check_pixels(raw, list(spec.channelnames), option=option, path=path)  # integers: only extra channels
        table = _decode_table(_INT_BITS[base], linear)
        planar = np.empty((channels, spec.height, spec.width), dtype=np.float32)
        for c in range(channels):  # mode="clip": every code is in the table (the default checks each, 10× slower)
            for y in range(0, spec.height, _BAND_ROWS):
                np.take(table, raw[y:y + _BAND_ROWS, :, c], out=planar[c, y:y + _BAND_ROWS], mode="clip")
        return planar.transpose(1, 2, 0), info
    arr = np.asarray(data, dtype=np.float32).reshape(spec.height, spec.width, spec.nchannels)
    arr = check_pixels(arr, list(spec.channelnames), option=option, path=path)
    arr = arr[..., :channels]  # extra channels were reported by check_pixels
    if not linear:
        arr = srgb_to_linear(arr)
    return np.ascontiguousarray(arr.transpose(2, 0, 1)).transpose(1, 2, 0), info


#: Peak bytes per pixel through a simulation (float32 RGB copies: linearized scene, padded patches, blurred,
#: distorted, sRGB-encoded output; ~18 copies measured: 11.6 GB for a 9000×6000 image).
SIM_BYTES_PER_PIXEL = 240


def check_image_size(width: int, height: int, *, option: str = "IMAGE", path: str | Path = "",
                     engine: Engine | None = None) -> None:
    """Refuse empty images and images too large for the engine's memory budget, before reading pixels."""
    if width < 1 or height < 1:
        raise LensoptError(f"image is {width}×{height} pixels", path=option, got=str(path))
    (engine or Engine()).require(width * height * SIM_BYTES_PER_PIXEL, f"simulating a {width}×{height} image",
                                 lower="the image size (downscale or crop it)", path=option)


def check_pixels(arr: np.ndarray, names: list[str], *, option: str = "IMAGE", path: str | Path = "") -> np.ndarray:
    """(H, W, C) pixels as read: refuse NaN/inf, clamp negative light to 0, and say which channels are unused
    (alpha and channels beyond RGB are not simulated). Warnings go to the ``lensopt`` logger. Unsigned
    integer pixels are neither NaN nor negative: only their channels are checked."""
    if arr.dtype.kind != "u":
        bad = ~np.isfinite(arr)
        if bad.any():
            raise LensoptError(f"{int(bad.sum())} pixel values are NaN or infinite; replace them (e.g. by 0) and "
                               "retry", path=option, got=str(path))
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


def encode_integer(linear: np.ndarray, pixel_type: str) -> np.ndarray:
    """Linear (H, W, C) → sRGB-encoded uint8/uint16 (H, W, C), contiguous, in row bands: ``linear_to_srgb``
    in float32, then × max code rounded to nearest, ties to even — as OpenImageIO's vectorized float →
    integer conversion does, so the codes are those of writing the float sRGB image (its scalar path
    rounds exact k + ½ ties up instead: a float32 product exactly on a tie is rare, and one code off)."""
    dtype = np.dtype(pixel_type)
    top = np.float32(np.iinfo(dtype).max)
    out = np.empty(linear.shape, dtype=dtype)
    for y in range(0, linear.shape[0], _BAND_ROWS):
        out[y:y + _BAND_ROWS] = np.rint(linear_to_srgb(linear[y:y + _BAND_ROWS]) * top)
    return out


def write_image(path: str | Path, linear: np.ndarray, source: ImageInfo, *, option: str = "--output") -> str:
    """Write a linear (H, W, C) image atomically, encoded per ``output_encoding``; returns a description."""
    oiio = _oiio()
    pixel_type, encoding = output_encoding(path, source)
    arr = np.asarray(linear, dtype=np.float32)
    if arr.ndim == 2:
        arr = arr[..., None]
    arr = encode_integer(arr, pixel_type) if encoding == "sRGB" else np.ascontiguousarray(arr)
    h, w, c = arr.shape
    fmt = {"uint8": oiio.UINT8, "uint16": oiio.UINT16, "float": oiio.FLOAT}[pixel_type]
    with atomic_path(path) as tmp:
        out = oiio.ImageOutput.create(str(tmp))
        if out is None:
            raise LensoptError(f"cannot write this image format: {oiio.geterror()}", path=option, got=str(path))
        spec = oiio.ImageSpec(w, h, c, fmt)
        spec.attribute("oiio:ColorSpace", "sRGB" if encoding == "sRGB" else "lin_rec709")
        for key, value in PNG_OPTIONS.items():  # read only by the PNG writer
            spec.attribute(key, value)
        if not out.open(str(tmp), spec):
            raise LensoptError(f"cannot write image: {out.geterror()}", path=option, got=str(path))
        ok = out.write_image(arr)
        out.close()
        if not ok:
            raise LensoptError(f"cannot write image: {out.geterror()}", path=option, got=str(path))
    return f"{pixel_type} {encoding}"
