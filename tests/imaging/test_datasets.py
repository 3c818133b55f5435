"""Image data: dead-leaves scenes, image folders, crops/flips, batches, and the errors a user can act on."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from lensopt.errors import LensoptError
from lensopt.imaging.datasets import DeadLeaves, ImageFolder, center_crop, dead_leaves, random_crop_flip, sample_batch
from lensopt.imaging.io import ImageInfo, write_image


def _write(path: Path, arr: np.ndarray) -> None:
    h, w, c = arr.shape
    write_image(path, arr, ImageInfo(w, h, c, 8, False, "sRGB", "png"))


def _ramp(h: int, w: int) -> np.ndarray:
    """An image whose every pixel is distinct, so a crop's position can be recovered."""
    y, x = np.mgrid[0:h, 0:w]
    return np.stack([x / (w - 1), y / (h - 1), 0.5 * np.ones_like(x, dtype=float)], -1).astype(np.float32)


# ------------------------------------------------------------------------------------------ dead leaves

def test_dead_leaves_deterministic_and_seeded() -> None:
    a = dead_leaves(64, 48, seed=3)
    assert a.shape == (3, 64, 48) and a.dtype == torch.float32
    assert torch.equal(a, dead_leaves(64, 48, seed=3))
    assert not torch.equal(a, dead_leaves(64, 48, seed=4))
    assert float(a.min()) >= 0.0 and float(a.max()) <= 1.0


def test_dead_leaves_is_resolution_free() -> None:
    # Pixel centre (i + 1/2)/256 of the 256² rendering is the centre of pixel 3i + 1 of the 768² one:
    # the same point of the same scene, so the same colour (point sampling, radii in scene units).
    lo = dead_leaves(96, 128, seed=11)
    hi = dead_leaves(288, 384, seed=11)
    assert torch.equal(hi[:, 1::3, 1::3], lo)


def test_dead_leaves_occlusion_makes_flat_regions() -> None:
    # Opaque leaves: the scene is piecewise constant — most horizontal neighbours are equal — and holds
    # many distinct colours (not a smooth field, not a single leaf).
    img = dead_leaves(128, 128, seed=0)
    same = (img[:, :, 1:] == img[:, :, :-1]).all(0).float().mean()
    assert 0.5 < float(same) < 0.99
    colours = torch.unique(img.reshape(3, -1).T, dim=0)
    assert colours.shape[0] > 100


def test_dead_leaves_gray_and_dtype_device() -> None:
    g = dead_leaves(16, 16, seed=1, channels=1, dtype=torch.float64, device="cpu")
    assert g.shape == (1, 16, 16) and g.dtype == torch.float64


def test_dead_leaves_source_patches() -> None:
    src = DeadLeaves(seed=5)
    g1, g2 = torch.Generator().manual_seed(0), torch.Generator().manual_seed(0)
    b1 = sample_batch(src, 3, 32, g1, dtype=torch.float64)
    b2 = sample_batch(src, 3, 32, g2, dtype=torch.float64)
    assert b1.shape == (3, 3, 32, 32) and b1.dtype == torch.float64
    assert torch.equal(b1, b2)
    assert not torch.equal(b1[0], b1[1])
    assert torch.equal(src.scene(7, 20, 20), src.scene(7, 20, 20))


# ------------------------------------------------------------------------------------------ crops and flips

def test_random_crop_flip_is_a_window_of_the_image() -> None:
    img = torch.from_numpy(_ramp(40, 50)).permute(2, 0, 1)
    gen = torch.Generator().manual_seed(1)
    seen_flip = set()
    for _ in range(20):
        p = random_crop_flip(img, (8, 12), gen)
        assert p.shape == (3, 8, 12)
        xs, ys = p[0], p[1]
        fh = bool(xs[0, 0] > xs[0, -1])
        fv = bool(ys[0, 0] > ys[-1, 0])
        seen_flip.add((fh, fv))
        un = p.flip(-1) if fh else p
        un = un.flip(-2) if fv else un
        x0 = int(round(float(un[0, 0, 0]) * 49))
        y0 = int(round(float(un[1, 0, 0]) * 39))
        assert torch.equal(un, img[:, y0:y0 + 8, x0:x0 + 12])
    assert len(seen_flip) == 4  # both flips, each on and off


def test_center_crop() -> None:
    img = torch.arange(2 * 10 * 12, dtype=torch.float32).reshape(2, 10, 12)
    assert torch.equal(center_crop(img, 4), img[:, 3:7, 4:8])
    with pytest.raises(LensoptError, match="smaller than"):
        center_crop(img, 11)


# ------------------------------------------------------------------------------------------ image folders

def test_folder_split_is_deterministic_and_disjoint(tmp_path: Path) -> None:
    for k in range(10):
        _write(tmp_path / f"img{k:02d}.png", _ramp(20, 24))
    train = ImageFolder(tmp_path, split="train", patch=16, val_fraction=0.2)
    val = ImageFolder(tmp_path, split="val", patch=16, val_fraction=0.2)
    assert len(val) == 2 and len(train) == 8
    assert not set(train.files) & set(val.files)
    assert set(train.files) | set(val.files) == set(ImageFolder(tmp_path, patch=16).files)
    assert val.files == ImageFolder(tmp_path, split="val", patch=16, val_fraction=0.2).files
    # Adding a file does not move the others between splits (hash of the name, not the listing order)
    # unless the count of held-out files changes.
    _write(tmp_path / "zz.png", _ramp(20, 24))
    val2 = ImageFolder(tmp_path, split="val", patch=16, val_fraction=0.2)
    assert set(val.files) <= set(val2.files) or len(val2) == len(val)


def test_folder_batches(tmp_path: Path) -> None:
    _write(tmp_path / "a.png", _ramp(40, 50))
    sub = tmp_path / "nested"
    sub.mkdir()
    gray = np.linspace(0, 1, 30 * 30, dtype=np.float32).reshape(30, 30, 1)
    _write(sub / "b.png", gray)
    ds = ImageFolder(tmp_path, patch=16)
    assert len(ds) == 2
    assert ds.load(1).shape[0] == 3  # gray repeated to RGB
    b = sample_batch(ds, 5, 16, torch.Generator().manual_seed(0))
    assert b.shape == (5, 3, 16, 16) and b.dtype == torch.float32
    assert torch.equal(b, sample_batch(ds, 5, 16, torch.Generator().manual_seed(0)))
    # linear light: a file byte of 128 (sRGB-encoded 0.50196) reads as 0.21586 (IEC 61966-2-1 formula)
    import OpenImageIO as oiio

    raw = tmp_path / "raw" / "c.png"
    raw.parent.mkdir()
    out = oiio.ImageOutput.create(str(raw))
    out.open(str(raw), oiio.ImageSpec(20, 20, 3, oiio.UINT8))
    out.write_image(np.full((20, 20, 3), 128, np.uint8))
    out.close()
    v = float(ImageFolder(raw.parent, patch=16).load(0).mean())
    assert abs(v - ((128 / 255 + 0.055) / 1.055) ** 2.4) < 1e-6


def test_exr_and_tiff_are_read_linear(tmp_path: Path) -> None:
    arr = _ramp(20, 24) * 0.8
    write_image(tmp_path / "a.exr", arr, ImageInfo(24, 20, 3, 32, True, "linear", "exr"))
    write_image(tmp_path / "b.tif", arr, ImageInfo(24, 20, 3, 32, True, "linear", "tiff"))
    ds = ImageFolder(tmp_path, patch=8)
    assert [p.suffix for p in ds.files] == [".exr", ".tif"]
    for k in range(2):
        assert torch.equal(ds.load(k), torch.from_numpy(arr).permute(2, 0, 1))  # float files: no transfer curve


def test_div2k_layout(tmp_path: Path) -> None:
    for name, n in (("train_HR", 3), ("valid_HR", 2)):
        (tmp_path / name).mkdir()
        for k in range(n):
            _write(tmp_path / name / f"{k:04d}.png", _ramp(20, 20))
    assert len(ImageFolder(tmp_path, split="train", patch=8)) == 3
    val = ImageFolder(tmp_path, split="val", patch=8)
    assert len(val) == 2 and all(p.parent.name == "valid_HR" for p in val.files)


def test_folder_errors_name_the_folder_or_file(tmp_path: Path) -> None:
    with pytest.raises(LensoptError, match=r"--images: no such image folder.*missing"):
        ImageFolder(tmp_path / "missing")
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "notes.txt").write_text("not an image")
    with pytest.raises(LensoptError, match=r"--images: no images.*empty"):
        ImageFolder(empty)
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "broken.png").write_bytes(b"this is not a PNG file")
    with pytest.raises(LensoptError, match=r"cannot read image.*broken\.png"):
        ImageFolder(bad, patch=4)
    small = tmp_path / "small"
    small.mkdir()
    _write(small / "tiny.png", _ramp(10, 12))
    with pytest.raises(LensoptError, match=r"--images: image 12×10 is smaller than the 16×16 patch.*tiny\.png"):
        ImageFolder(small, patch=16)


def test_dead_leaves_equals_a_painters_algorithm() -> None:
    # Oracle: paint the same disks back to front, one by one (later disks occlude earlier ones); the
    # vectorized scatter-max must give the same pixels. Same draws as dead_leaves (its documented law).
    import math

    h, w, seed, r_min, r_max = 40, 56, 9, 0.02, 0.3
    rng = np.random.default_rng(seed)
    side = min(h, w)
    mean_r2 = 2.0 * math.log(r_max / r_min) / (r_min**-2 - r_max**-2)
    n = math.ceil(6.0 * (w / side + 2 * r_max) * (h / side + 2 * r_max) / (math.pi * mean_r2))
    radius = (r_min**-2 - rng.random(n) * (r_min**-2 - r_max**-2)) ** -0.5
    cx, cy = rng.uniform(-r_max, w / side + r_max, n), rng.uniform(-r_max, h / side + r_max, n)
    colour = rng.random((n + 1, 3))
    colour = np.where(colour <= 0.04045, colour / 12.92, ((colour + 0.055) / 1.055) ** 2.4)
    img = np.empty((h, w, 3))
    img[...] = colour[n]
    yy, xx = np.mgrid[0:h, 0:w] + 0.5
    for k in range(n):
        img[(xx - cx[k] * side) ** 2 + (yy - cy[k] * side) ** 2 <= (radius[k] * side) ** 2] = colour[k]
    got = dead_leaves(h, w, seed=seed, r_min=r_min, r_max=r_max, dtype=torch.float64)
    assert torch.equal(got, torch.from_numpy(img).permute(2, 0, 1))
