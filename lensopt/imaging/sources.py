"""Named scene sources for training and evaluation (``--images``), the bundled photographs and mixtures.

Names (``train-irm --images``; mix several with ``+``, e.g. ``textured+photos``: each patch comes from
one of them, chosen uniformly):

* ``procedural`` — plain dead leaves (``datasets.DeadLeaves``), the default;
* ``textured`` — textured dead leaves (``textured.TexturedLeaves``);
* ``photos`` — random crops (with flips) of the TRAINING photographs below;
* anything else — an image folder (``datasets.ImageFolder``: DIV2K layout or a hash split).

The bundled photographs are scikit-image's sample images, read from the installed package (nothing is
copied): public domain or CC0 by their authors (see ``skimage.data``'s docstrings; the Middlebury
motorcycle images, whose licence is not stated, are not used).

* TRAINING (``PHOTOS_TRAIN``): rocket.jpg (SpaceX, public domain), hubble_deep_field.jpg (NASA, public
  domain), ihc.png (CMMI, no known copyright restrictions), retina.jpg (M. Häggström, CC0).
* HELD-OUT (``PHOTOS_HELD_OUT``), never drawn by any training source: astronaut.png (NASA, public domain),
  chelsea.png (S. van der Walt, CC0), coffee.png (R. Michetti, CC0) — everyday photographs (a person,
  a cat, a cup). ``evaluate --images photos`` scores all their non-overlapping ``patch``² tiles.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import torch

from lensopt.engine import Engine
from lensopt.errors import LensoptError
from lensopt.imaging.datasets import DeadLeaves, ImageFolder, random_crop_flip
from lensopt.imaging.textured import TexturedLeaves

__all__ = ["PatchSource", "PhotoCrops", "Mixture", "PHOTOS_TRAIN", "PHOTOS_HELD_OUT", "NAMES", "IMAGES_HELP",
           "photo_dir", "training_sources", "photo_tiles"]

PHOTOS_TRAIN = ("rocket.jpg", "hubble_deep_field.jpg", "ihc.png", "retina.jpg")
PHOTOS_HELD_OUT = ("astronaut.png", "chelsea.png", "coffee.png")
NAMES = ("procedural", "textured", "photos")
IMAGES_HELP = ("procedural (dead leaves) | textured (textured dead leaves) | photos (crops of the bundled "
               "training photographs) | an image folder; mix with '+', e.g. textured+photos")
_VAL_OFFSET = 1_000_003  # seed offset of the held-out procedural scenes (as before: DeadLeaves(seed + 1 000 003))


class PatchSource(Protocol):
    """What training draws from: ``random_patch(patch, generator) -> [C, H, W]`` linear float32."""

    def random_patch(self, patch: int | tuple[int, int], generator: torch.Generator) -> torch.Tensor: ...


def photo_dir() -> Path:
    """The folder of scikit-image's bundled sample images."""
    import skimage

    return Path(skimage.__file__).parent / "data"


class PhotoCrops:
    """Random crops (and flips) of a fixed list of photographs, decoded once to linear float32 ``[3, H, W]``."""

    def __init__(self, names: Sequence[str], *, folder: Path | None = None, option: str = "--images",
                 engine: Engine | None = None) -> None:
        folder = folder or photo_dir()
        self.files = [folder / n for n in names]
        missing = [str(p) for p in self.files if not p.is_file()]
        if missing:
            raise LensoptError("bundled photograph not found (is scikit-image installed?)", path=option,
                               got=missing[0])
        self.option, self.engine = option, engine
        self._images: dict[int, torch.Tensor] = {}

    def __len__(self) -> int:
        return len(self.files)

    def load(self, index: int) -> torch.Tensor:
        if index not in self._images:
            from lensopt.imaging.io import read_image

            arr, _ = read_image(self.files[index], option=self.option, engine=self.engine)
            img = torch.from_numpy(arr[..., :3]).permute(2, 0, 1).contiguous()
            self._images[index] = img.expand(3, -1, -1).contiguous() if img.shape[0] == 1 else img
        return self._images[index]

    def random_patch(self, patch: int | tuple[int, int], generator: torch.Generator) -> torch.Tensor:
        """A random photograph, a random crop of it, random flips."""
        index = int(torch.randint(0, len(self.files), (1,), generator=generator))
        return random_crop_flip(self.load(index), patch, generator)


@dataclass(frozen=True)
class Mixture:
    """Each patch from one of ``parts``, chosen uniformly by the generator."""

    parts: tuple[Any, ...]

    def random_patch(self, patch: int | tuple[int, int], generator: torch.Generator) -> torch.Tensor:
        k = int(torch.randint(0, len(self.parts), (1,), generator=generator))
        return self.parts[k].random_patch(patch, generator)


def _one(name: str, patch: int, seed: int, engine: Engine | None, option: str) -> tuple[Any, Any, str]:
    if name == "procedural":
        return DeadLeaves(seed=seed), DeadLeaves(seed=seed + _VAL_OFFSET), "procedural"
    if name == "textured":
        return TexturedLeaves(seed=seed), TexturedLeaves(seed=seed + _VAL_OFFSET), "textured"
    if name == "photos":
        # Validation: other crops of the training photographs; the held-out ones are for evaluate only.
        train = PhotoCrops(PHOTOS_TRAIN, option=option, engine=engine)
        return train, train, "photos (training: " + ", ".join(PHOTOS_TRAIN) + ")"
    path = Path(name)
    if not path.exists():
        raise LensoptError(f"no such image folder; a name must be one of {', '.join(NAMES)} (mix with '+')",
                           path=option, got=name)
    train = ImageFolder(path, split="train", patch=patch, option=option, engine=engine)
    val = ImageFolder(path, split="val", patch=patch, option=option, engine=engine)
    return train, val, str(path.resolve())


def training_sources(images: str, patch: int, seed: int, *, engine: Engine | None = None,
                     option: str = "--images") -> tuple[Any, Any, str]:
    """(training source, validation source, description) of ``--images`` (see the module doc)."""
    text = images.strip()
    if not text:
        raise LensoptError(f"expected {IMAGES_HELP}", path=option, got=images)
    if Path(text).exists() or "+" not in text:
        return _one(text, patch, seed, engine, option)
    names = [t.strip() for t in text.split("+")]
    bad = [t for t in names if t not in NAMES]
    if bad or len(set(names)) != len(names):
        raise LensoptError(f"a mixture joins distinct names of {', '.join(NAMES)} with '+'", path=option, got=images)
    parts = [_one(t, patch, seed, engine, option) for t in names]
    return Mixture(tuple(p[0] for p in parts)), Mixture(tuple(p[1] for p in parts)), "+".join(p[2] for p in parts)


def photo_tiles(patch: int, *, engine: Engine | None = None,
                option: str = "--images") -> tuple[list[Callable[[], torch.Tensor]], list[str]]:
    """The held-out photographs cut into every non-overlapping ``patch``² tile (a centred grid per image),
    in file then row-major order: ``(loaders, names)``; ``name`` = ``file@row,col``."""
    photos = PhotoCrops(PHOTOS_HELD_OUT, option=option, engine=engine)
    loaders: list[Callable[[], torch.Tensor]] = []
    names: list[str] = []
    for i, path in enumerate(photos.files):
        import OpenImageIO as oiio

        inp = oiio.ImageInput.open(str(path))
        if inp is None:
            raise LensoptError(f"cannot read image: {oiio.geterror().strip()}", path=option, got=str(path))
        h, w = int(inp.spec().height), int(inp.spec().width)
        inp.close()
        rows, cols = h // patch, w // patch
        y0, x0 = (h - rows * patch) // 2, (w - cols * patch) // 2
        for r in range(rows):
            for c in range(cols):
                y, x = y0 + r * patch, x0 + c * patch
                loaders.append(lambda i=i, y=y, x=x: photos.load(i)[:, y:y + patch, x:x + patch])
                names.append(f"{path.name}@{r},{c}")
    if not loaders:
        raise LensoptError("larger than every held-out photograph", path="--patch", got=patch)
    return loaders, names

