"""Image data for image-driven design (S3.3.1, S4.3.1): procedural dead-leaves scenes and image folders.

Two sources of scenes, one interface (``random_patch`` / ``sample_batch``):

* ``DeadLeaves`` — the dead-leaves model (Matheron; Lee, Mumford & Huang 2001), the standard texture
  target of camera evaluation (ISO 19567-2, IEEE P1858): opaque disks with power-law radii
  p(r) ∝ r⁻³ on [r_min, r_max], each occluding the disks that fell before it, with random colours.
  Radii are fractions of the scene's shorter side, so a scene is resolution-free: the same seed rendered
  at 256² or 1024² shows the same disks. Seeded; no download needed.
* ``ImageFolder`` — any folder of PNG/JPEG/TIFF/EXR images read with OpenImageIO (linear light, see
  ``imaging.io``). The DIV2K layout (``train_HR/``, ``valid_HR/``) gives the split directly; otherwise
  a deterministic split by a hash of each file's relative path (stable when files are added).

Patches are ``[C, H, W]`` float tensors in linear light, in [0, 1] for 8/16-bit files. Every random
choice (scene seed, image, crop, flips) comes from a ``torch.Generator`` the caller seeds.
"""

from __future__ import annotations

import hashlib
import math
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import torch

from lensopt.engine import Engine
from lensopt.errors import LensoptError

__all__ = ["DeadLeaves", "ImageFolder", "IMAGE_SUFFIXES", "Leaves", "dead_leaves", "leaf_geometry", "is_div2k",
           "center_crop", "random_crop_flip", "sample_batch", "split_files"]

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".exr")
_DIV2K = {"train": ("train_HR", "DIV2K_train_HR"), "val": ("valid_HR", "DIV2K_valid_HR")}


def _srgb_to_linear(v: np.ndarray) -> np.ndarray:
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def dead_leaves(
    height: int,
    width: int,
    *,
    seed: int,
    channels: int = 3,
    r_min: float = 0.004,
    r_max: float = 0.25,
    coverage: float = 6.0,
    max_disks: int = 20000,
    device: torch.device | str | None = None,
    dtype: torch.dtype = torch.float32,
) -> torch.Tensor:
    """A dead-leaves scene, ``[channels, height, width]`` in linear light.

    Args:
        height, width: pixels; the scene spans the unit of the shorter side, so the content does not
            depend on the resolution (only its sampling does).
        seed: the scene (same seed, same disks at every resolution).
        r_min, r_max: radius range as fractions of the shorter side; radii follow p(r) ∝ r⁻³ (the
            scale-invariant law), drawn by inverse transform sampling.
        coverage: expected number of disks over each point (sets the disk count from the mean disk
            area); points no disk covers (≈ e^-coverage) show the background leaf.
        channels: 3 (colours uniform in sRGB-encoded [0, 1], then linearized) or 1 (gray).

    Disks are painted back to front (later disks occlude earlier ones); pixel centres are point-sampled.
    """
    rng, leaves = leaf_geometry(height, width, seed=seed, r_min=r_min, r_max=r_max, coverage=coverage,
                                max_disks=max_disks)
    n = leaves.count
    colour = _srgb_to_linear(rng.random((n + 1, channels)))
    img = torch.from_numpy(colour)[leaves.index]  # [H, W, C]
    return img.permute(2, 0, 1).to(device=device, dtype=dtype).contiguous()


@dataclass(frozen=True)
class Leaves:
    """The disks of a dead-leaves scene, in pixels (``count`` disks; leaf ``count`` is the background)."""

    radius: np.ndarray
    cx: np.ndarray
    cy: np.ndarray
    index: torch.Tensor  # [H, W] int64: the leaf seen at each pixel centre, in 0…count (count: background)

    @property
    def count(self) -> int:
        return int(self.radius.size)


def leaf_geometry(height: int, width: int, *, seed: int, r_min: float, r_max: float, coverage: float,
                  max_disks: int, path: str = "dead_leaves") -> tuple[np.random.Generator, Leaves]:
    """The disks of ``dead_leaves`` (its documented draws, in order) and the generator after them."""
    if height < 1 or width < 1:
        raise LensoptError("scene size must be positive", path=path, got=(height, width))
    if not 0 < r_min < r_max:
        raise LensoptError("need 0 < r_min < r_max", path=path, got=(r_min, r_max))
    rng = np.random.default_rng(int(seed))
    side = min(height, width)
    aspect_w, aspect_h = width / side, height / side
    # Mean disk area under p(r) ∝ r^-3 on [a, b]: E[r²] = 2 ln(b/a) / (a^-2 - b^-2).
    mean_r2 = 2.0 * math.log(r_max / r_min) / (r_min**-2 - r_max**-2)
    # Disks centred up to r_max outside the frame still cover it.
    area = (aspect_w + 2 * r_max) * (aspect_h + 2 * r_max)
    n = int(min(max_disks, math.ceil(coverage * area / (math.pi * mean_r2))))
    u = rng.random(n)
    radius = (r_min**-2 - u * (r_min**-2 - r_max**-2)) ** -0.5
    cx = rng.uniform(-r_max, aspect_w + r_max, n)
    cy = rng.uniform(-r_max, aspect_h + r_max, n)
    top = _paint_order(radius * side, cx * side, cy * side, height, width)
    return rng, Leaves(radius * side, cx * side, cy * side, torch.where(top < 0, n, top))


def _paint_order(r: np.ndarray, x: np.ndarray, y: np.ndarray, height: int, width: int) -> torch.Tensor:
    """``[H, W]`` index of the last disk (by draw order) whose interior holds each pixel centre, −1 if none.

    Disks (pixels: radius ``r``, centre ``x, y``) are grouped by radius into buckets of half-size R = 1, 2,
    4, …; each bucket tests the (2R+1)² candidate pixels of all its disks at once and a scatter-max keeps
    the topmost disk per pixel (the same result as painting back to front, in one pass).
    """
    top = torch.full((height * width,), -1, dtype=torch.int64)
    idx_all = np.arange(r.size)
    lo = 0.0
    size = 1
    while lo < r.max(initial=0.0):
        sel = idx_all[(r > lo) & (r <= size)] if lo > 0 else idx_all[r <= size]
        lo, half = float(size), size
        size *= 2
        if sel.size == 0:
            continue
        off = np.arange(2 * half + 1)
        c0 = np.ceil(x[sel] - r[sel] - 0.5).astype(np.int64)
        r0 = np.ceil(y[sel] - r[sel] - 0.5).astype(np.int64)
        keep = (c0 + 2 * half >= 0) & (c0 < width) & (r0 + 2 * half >= 0) & (r0 < height)
        sel, c0, r0 = sel[keep], c0[keep], r0[keep]
        for start in range(0, sel.size, max(1, 2_000_000 // off.size**2)):
            s_ = slice(start, start + max(1, 2_000_000 // off.size**2))
            cols = c0[s_, None, None] + off[None, None, :]
            rows = r0[s_, None, None] + off[None, :, None]
            dx = cols + 0.5 - x[sel[s_], None, None]
            dy = rows + 0.5 - y[sel[s_], None, None]
            inside = ((dx * dx + dy * dy) <= (r[sel[s_], None, None] ** 2)) & (cols >= 0) & (cols < width)
            inside &= (rows >= 0) & (rows < height)
            pix = (rows * width + cols)[inside]
            who = np.broadcast_to(sel[s_, None, None], inside.shape)[inside]
            top.scatter_reduce_(0, torch.from_numpy(pix), torch.from_numpy(who), reduce="amax")
    return top.view(height, width)


def _check_patch(patch: int | tuple[int, int]) -> tuple[int, int]:
    ph, pw = (patch, patch) if isinstance(patch, int) else patch
    if ph < 1 or pw < 1:
        raise LensoptError("patch size must be positive", path="patch", got=patch)
    return int(ph), int(pw)


def random_crop_flip(img: torch.Tensor, patch: int | tuple[int, int], generator: torch.Generator, *,
                     flips: bool = True) -> torch.Tensor:
    """A random ``patch`` crop of ``img`` ``[C, H, W]`` with random horizontal and vertical flips."""
    ph, pw = _check_patch(patch)
    _, h, w = img.shape
    if h < ph or w < pw:
        raise LensoptError(f"image {w}×{h} is smaller than the {pw}×{ph} patch", path="patch", got=(w, h))
    y = int(torch.randint(0, h - ph + 1, (1,), generator=generator))
    x = int(torch.randint(0, w - pw + 1, (1,), generator=generator))
    out = img[:, y:y + ph, x:x + pw]
    if flips:
        fh, fv = (torch.rand(2, generator=generator) < 0.5).tolist()
        if fh:
            out = out.flip(-1)
        if fv:
            out = out.flip(-2)
    return out


def center_crop(img: torch.Tensor, patch: int | tuple[int, int]) -> torch.Tensor:
    """The central ``patch`` crop of ``img`` ``[C, H, W]`` (S4.3.1: central 256×256 of each image)."""
    ph, pw = _check_patch(patch)
    _, h, w = img.shape
    if h < ph or w < pw:
        raise LensoptError(f"image {w}×{h} is smaller than the {pw}×{ph} patch", path="patch", got=(w, h))
    y, x = (h - ph) // 2, (w - pw) // 2
    return img[:, y:y + ph, x:x + pw]


@dataclass(frozen=True)
class DeadLeaves:
    """Procedural scenes: scene ``k`` of this source is ``dead_leaves(..., seed=hash(seed, k))``."""

    seed: int = 0
    channels: int = 3
    r_min: float = 0.004
    r_max: float = 0.25
    tag: ClassVar[str] = "dead-leaves"  # the scene seeds' namespace

    def scene_seed(self, index: int) -> int:
        return int.from_bytes(hashlib.sha256(f"{self.tag}:{self.seed}:{index}".encode()).digest()[:8], "little")

    def render(self, height: int, width: int, *, seed: int) -> torch.Tensor:
        """One scene of seed ``seed`` (``dead_leaves``; a subclass renders another kind)."""
        return dead_leaves(height, width, seed=seed, channels=self.channels, r_min=self.r_min, r_max=self.r_max)

    def scene(self, index: int, height: int, width: int) -> torch.Tensor:
        """Scene ``index`` rendered at ``height × width``, ``[C, H, W]`` float32."""
        return self.render(height, width, seed=self.scene_seed(index))

    def random_patch(self, patch: int | tuple[int, int], generator: torch.Generator) -> torch.Tensor:
        """A fresh scene (its index drawn from ``generator``) rendered directly at the patch size."""
        ph, pw = _check_patch(patch)
        index = int(torch.randint(0, 2**62, (1,), generator=generator))
        return self.scene(index, ph, pw)


def is_div2k(root: str | Path) -> bool:
    """``root`` has the DIV2K layout (a ``train_HR/`` or ``valid_HR/`` subfolder)."""
    root = Path(root)
    return any((root / n).is_dir() for pair in _DIV2K.values() for n in pair)


def split_files(files: list[Path], root: Path, split: str, val_fraction: float) -> list[Path]:
    """Deterministic split: files ordered by SHA-1 of their path relative to ``root``; the first
    ``round(val_fraction·n)`` (at least one when n ≥ 2 and val_fraction > 0) are validation."""
    if split == "all":
        return sorted(files)
    keyed = sorted(files, key=lambda p: hashlib.sha1(p.relative_to(root).as_posix().encode()).hexdigest())
    n = len(keyed)
    n_val = int(round(val_fraction * n))
    if val_fraction > 0 and n >= 2:
        n_val = min(max(n_val, 1), n - 1)
    chosen = keyed[:n_val] if split == "val" else keyed[n_val:]
    return sorted(chosen)


class ImageFolder:
    """Images under ``root`` (recursively), a deterministic split, header-checked at construction.

    Args:
        root: folder of images, or a DIV2K-style folder holding ``train_HR/`` and ``valid_HR/``
            (then ``split`` picks the subfolder and ``val_fraction`` is not used).
        split: ``train`` | ``val`` | ``all``.
        patch: the smallest size an image may have (pixels, int or (H, W)); smaller images are an error.
        val_fraction: share of files held out for validation when the folder has no DIV2K layout.
        option: the CLI option or spec field named in errors.
        cache: decoded images kept in memory (least recently used dropped first; a DIV2K image is
            ≈ 33 MB as float32, so keep it small).
        engine: whose memory budget every image read must fit (default ``Engine()``).
    """

    def __init__(self, root: str | Path, *, split: str = "all", patch: int | tuple[int, int] = 256,
                 val_fraction: float = 0.1, option: str = "--images", cache: int = 4,
                 engine: Engine | None = None) -> None:
        if split not in ("train", "val", "all"):
            raise LensoptError("split must be train, val or all", path=option, got=split)
        if not 0 <= val_fraction < 1:
            raise LensoptError("val_fraction must lie in [0, 1)", path=option, got=val_fraction)
        root = Path(root)
        if not root.exists():
            raise LensoptError("no such image folder", path=option, got=str(root))
        if not root.is_dir():
            raise LensoptError("not a folder", path=option, got=str(root))
        self.option = option
        self.engine = engine
        self.patch = _check_patch(patch)
        sub = self._div2k_folder(root, split)
        if sub is not None:
            self.layout = f"DIV2K ({sub.name}/)"
            files = self._list(sub)
            self.files = sorted(files)
        else:
            self.layout = "flat" if split == "all" else f"hash split ({val_fraction:.0%} validation)"
            files = self._list(root)
            self.files = split_files(files, root, split, val_fraction)
        if not self.files:
            raise LensoptError(f"no images ({', '.join(IMAGE_SUFFIXES)}) in the {split} split", path=option,
                               got=str(root))
        self.root = root
        self.sizes = [self._check_header(p) for p in self.files]
        self._cache: OrderedDict[int, torch.Tensor] = OrderedDict()
        self._cache_size = max(0, int(cache))

    def _list(self, folder: Path) -> list[Path]:
        files = [p for p in folder.rglob("*") if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES
                 and not p.name.startswith(".")]
        if not files:
            raise LensoptError(f"no images ({', '.join(IMAGE_SUFFIXES)}) in the folder", path=self.option,
                               got=str(folder))
        return files

    @staticmethod
    def _div2k_folder(root: Path, split: str) -> Path | None:
        if not is_div2k(root):
            return None
        if split == "all":
            raise LensoptError("a DIV2K-style folder (train_HR/, valid_HR/): choose split train or val",
                               path="split", got=str(root))
        for name in _DIV2K[split]:
            if (root / name).is_dir():
                return root / name
        raise LensoptError(f"DIV2K-style folder without {_DIV2K[split][0]}/", path="--images", got=str(root))

    def _check_header(self, path: Path) -> tuple[int, int]:
        import OpenImageIO as oiio

        inp = oiio.ImageInput.open(str(path))
        if inp is None:
            raise LensoptError(f"cannot read image: {oiio.geterror().strip()}", path=self.option, got=str(path))
        try:
            spec = inp.spec()
            w, h = int(spec.width), int(spec.height)
        finally:
            inp.close()
        ph, pw = self.patch
        if w < pw or h < ph:
            raise LensoptError(f"image {w}×{h} is smaller than the {pw}×{ph} patch", path=self.option,
                               got=str(path))
        return h, w

    def __len__(self) -> int:
        return len(self.files)

    def load(self, index: int) -> torch.Tensor:
        """Image ``index`` as ``[3, H, W]`` float32 linear light (gray images repeated to 3 channels)."""
        if index in self._cache:
            self._cache.move_to_end(index)
            return self._cache[index]
        from lensopt.imaging.io import read_image

        arr, _ = read_image(self.files[index], option=self.option, engine=self.engine)
        img = torch.from_numpy(arr).permute(2, 0, 1).contiguous()
        if img.shape[0] == 1:
            img = img.expand(3, -1, -1).contiguous()
        if self._cache_size:
            self._cache[index] = img
            while len(self._cache) > self._cache_size:
                self._cache.popitem(last=False)
        return img

    def random_patch(self, patch: int | tuple[int, int], generator: torch.Generator) -> torch.Tensor:
        """A random image, a random crop of it, random flips."""
        index = int(torch.randint(0, len(self.files), (1,), generator=generator))
        try:
            return random_crop_flip(self.load(index), patch, generator)
        except LensoptError as err:
            raise LensoptError(err.message, path=self.option, got=str(self.files[index])) from None


def sample_batch(
    source: Any,
    batch: int,
    patch: int | tuple[int, int],
    generator: torch.Generator,
    *,
    device: torch.device | str | None = None,
    dtype: torch.dtype = torch.float32,
) -> torch.Tensor:
    """``[batch, C, H, W]`` patches from ``source`` (anything with ``random_patch(patch, generator)``: random
    scenes/crops/flips drawn from ``generator``)."""
    if batch < 1:
        raise LensoptError("batch size must be positive", path="batch", got=batch)
    patches = [source.random_patch(patch, generator) for _ in range(batch)]
    return torch.stack(patches).to(device=device, dtype=dtype)
