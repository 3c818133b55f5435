"""Named scene sources (issue 27): procedural / textured / photos / folders / '+' mixtures, the bundled
photographs split into a training and a held-out set, and the held-out tiles evaluate scores."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lensopt.errors import LensoptError
from lensopt.imaging.datasets import DeadLeaves, ImageFolder
from lensopt.imaging.evaluate import scene_source
from lensopt.imaging.sources import (
    PHOTOS_HELD_OUT,
    PHOTOS_TRAIN,
    Mixture,
    PhotoCrops,
    photo_dir,
    photo_tiles,
    training_sources,
)
from lensopt.imaging.textured import TexturedLeaves


def _linear(path) -> np.ndarray:
    """sRGB 8-bit file → linear float, read with scikit-image (independent of lensopt's OpenImageIO reader)."""
    import skimage.io

    v = skimage.io.imread(path)[..., :3].astype(np.float64) / 255.0
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def test_held_out_photographs_are_never_a_training_source() -> None:
    assert not set(PHOTOS_TRAIN) & set(PHOTOS_HELD_OUT)
    for text in ("photos", "textured+photos", "procedural+photos", "procedural+textured+photos"):
        train, val, _ = training_sources(text, 64, 0)
        parts = train.parts if isinstance(train, Mixture) else (train,)
        vparts = val.parts if isinstance(val, Mixture) else (val,)
        files = {p.name for s in (*parts, *vparts) if isinstance(s, PhotoCrops) for p in s.files}
        assert files == set(PHOTOS_TRAIN)


def test_named_sources_and_their_held_out_seeds(tmp_path) -> None:
    train, val, desc = training_sources("procedural", 64, 7)
    assert train == DeadLeaves(seed=7) and val == DeadLeaves(seed=7 + 1_000_003) and desc == "procedural"
    train, val, desc = training_sources("textured", 64, 7)
    assert train == TexturedLeaves(seed=7) and val == TexturedLeaves(seed=7 + 1_000_003)
    from lensopt.imaging.io import ImageInfo, write_image

    for k in range(3):
        write_image(tmp_path / f"im{k}.png", np.full((70, 70, 3), 0.1 * k, np.float32),
                    ImageInfo(70, 70, 3, 8, False, "sRGB", "png"))
    train, val, desc = training_sources(str(tmp_path), 64, 0)
    assert isinstance(train, ImageFolder) and isinstance(val, ImageFolder)
    assert len(train) + len(val) == 3


def test_mixture_draws_every_part_deterministically() -> None:
    train, _, desc = training_sources("textured+photos", 32, 0)
    assert isinstance(train, Mixture) and desc.startswith("textured+photos")
    g1, g2 = torch.Generator().manual_seed(3), torch.Generator().manual_seed(3)
    a = torch.stack([train.random_patch(32, g1) for _ in range(12)])
    b = torch.stack([train.random_patch(32, g2) for _ in range(12)])
    assert torch.equal(a, b) and a.shape == (12, 3, 32, 32)
    # Which part drew each patch: the first draw of each call (uniform over 2 parts); both must occur.
    g = torch.Generator().manual_seed(3)
    seen = set()
    for _ in range(12):
        state = g.get_state()
        seen.add(int(torch.randint(0, 2, (1,), generator=g)))
        g.set_state(state)
        train.random_patch(32, g)
    assert seen == {0, 1}


def _found_in(patch: np.ndarray, ref: np.ndarray) -> bool:
    """``patch`` [h, w, 3] is a window of ``ref`` [H, W, 3], possibly flipped (vectorized search)."""
    h, w = patch.shape[:2]
    H, W = ref.shape[:2]
    for cand in (patch, patch[:, ::-1], patch[::-1], patch[::-1, ::-1]):
        ok = np.ones((H - h + 1, W - w + 1), bool)
        for dy, dx in ((0, 0), (h - 1, w - 1), (h // 2, w // 3), (h // 3, w - 1), (h - 1, 0), (h // 2, w // 2)):
            ok &= np.abs(ref[dy:dy + H - h + 1, dx:dx + W - w + 1] - cand[dy, dx]).max(-1) < 1e-7
        if any(np.array_equal(ref[y:y + h, x:x + w], cand) for y, x in zip(*np.nonzero(ok), strict=True)):
            return True
    return False


def test_photo_crops_are_windows_of_the_training_photographs() -> None:
    src = PhotoCrops(PHOTOS_TRAIN)
    # lensopt's reader against scikit-image's on the PNG (JPEG decoders may differ in the last bit).
    ihc = PHOTOS_TRAIN.index("ihc.png")
    assert np.allclose(src.load(ihc).permute(1, 2, 0).double().numpy(), _linear(src.files[ihc]), atol=1e-6)
    refs = [src.load(i).permute(1, 2, 0).numpy() for i in range(len(src))]
    gen = torch.Generator().manual_seed(1)
    for _ in range(4):
        patch = src.random_patch(24, gen).permute(1, 2, 0).numpy()
        assert any(_found_in(patch, ref) for ref in refs)


def test_held_out_tiles_cover_each_photograph_on_a_centred_grid() -> None:
    # Sizes from the files: astronaut 512×512 → 4×4 tiles of 128², chelsea 451×300 → 3×2, coffee 600×400 → 4×3.
    loaders, names = photo_tiles(128)
    assert len(names) == 16 + 6 + 12
    assert names[0] == "astronaut.png@0,0" and names[16] == "chelsea.png@0,0" and names[-1] == "coffee.png@2,3"
    ref = _linear(photo_dir() / "chelsea.png")  # 300 × 451: grid offsets (300 − 256)/2 = 22, (451 − 384)/2 = 33
    tile = loaders[16 + 3 + 2]().permute(1, 2, 0).double().numpy()  # row 1, col 2
    assert np.allclose(tile, ref[22 + 128:22 + 256, 33 + 256:33 + 384], atol=1e-5)
    scenes, snames, desc = scene_source("photos", count=5, patch=128, seed=0)
    assert snames == names[:5] and "held-out" in desc and tuple(scenes(4).shape) == (3, 128, 128)
    with pytest.raises(LensoptError, match="--patch"):
        photo_tiles(600)


@pytest.mark.parametrize("text", ["nope", "textured+nope", "photos+photos", "", "+"])
def test_bad_names_are_one_error_naming_images(text: str) -> None:
    with pytest.raises(LensoptError, match="--images"):
        training_sources(text, 64, 0)
