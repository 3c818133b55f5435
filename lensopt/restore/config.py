"""The restoration model's configuration as a plain dataclass (the core never sees pydantic; the
``[restore]`` spec section, ``lensopt.spec.restore``, becomes these in ``lensopt.design.restore``)."""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from typing import Any

__all__ = ["RestoreConfig", "TrainConfig"]


@dataclass(frozen=True)
class RestoreConfig:
    """Network architecture (defaults: the seed's code base, S3.2).

    Attributes:
        width: channels of the first NAFNet level (doubled at each downsampling).
        encoder_blocks: NAFNet blocks per encoder level (one downsampling after each level).
        middle_blocks: blocks at the lowest resolution.
        decoder_blocks: blocks per decoder level (one upsampling before each level).
        snr: initial signal-to-noise ratio of the Wiener stage (learned as log SNR).
        channels: image channels (3 for RGB).
    """

    width: int = 16
    encoder_blocks: tuple[int, ...] = (1, 1, 1, 4)
    middle_blocks: int = 1
    decoder_blocks: tuple[int, ...] = (1, 1, 1, 1)
    snr: float = 1000.0
    channels: int = 3

    def __post_init__(self) -> None:
        object.__setattr__(self, "encoder_blocks", tuple(int(b) for b in self.encoder_blocks))
        object.__setattr__(self, "decoder_blocks", tuple(int(b) for b in self.decoder_blocks))

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["encoder_blocks"] = list(self.encoder_blocks)
        d["decoder_blocks"] = list(self.decoder_blocks)
        return d

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> RestoreConfig:
        return cls(**{f.name: d[f.name] for f in dataclasses.fields(cls) if f.name in d})

    @property
    def multiple(self) -> int:
        """Image sides are padded to a multiple of this (2 ** number of downsamplings)."""
        return 2 ** len(self.encoder_blocks)


@dataclass(frozen=True)
class TrainConfig:
    """Training of the network (S3.3.1): Adam on MAE with a cosine learning-rate schedule.

    Attributes:
        steps: optimizer steps.
        batch: patches per step; patch: patch side (pixels).
        lr, betas: Adam settings; lr_min: the cosine schedule's final learning rate.
        noise_sigma: standard deviation of the additive Gaussian noise (fraction of full scale).
        checkpoint_every, validate_every: steps between checkpoints / validations (0: never).
        validation_patches: held-out patches evaluated at each validation.
        seed: seed of every random draw (data, regions, noise).
    """

    steps: int = 1000
    batch: int = 16
    patch: int = 256
    lr: float = 1e-3
    betas: tuple[float, float] = (0.9, 0.9)
    lr_min: float = 0.0
    noise_sigma: float = 0.005
    checkpoint_every: int = 100
    validate_every: int = 100
    validation_patches: int = 16
    seed: int = 0
    extra: dict[str, Any] = field(default_factory=dict)
