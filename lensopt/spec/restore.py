"""The ``[restore]`` spec section: the image restoration network (S3.2) and its training (S3.3.1).

Read by ``lensopt train-irm`` and by ``lensopt optimize`` with ``objective = "restored"``; the core
receives plain dataclasses (``lensopt.restore.config``, converted by ``lensopt.design.restore``), never
these models.
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field, model_validator

__all__ = ["RestoreSpec", "RestoreTrainSpec"]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True, allow_inf_nan=False)


class RestoreTrainSpec(_Model):
    """Training of the network: Adam on the MAE with a cosine learning-rate schedule (S3.3.1).

    Attributes:
        steps: optimizer steps (the CLI's --steps overrides).
        batch: patches per step; patch: patch side in pixels (seed: 16 × 256²).
        lr, betas, lr_min: Adam and the cosine schedule (lr → lr_min over the steps).
        noise_sigma: additive Gaussian noise, fraction of full scale (seed: 0.5 %).
        checkpoint_every, validate_every: steps between checkpoints / validations (0: never).
        validation_patches: held-out patches per validation.
    """

    steps: int = Field(default=1000, ge=1)
    batch: int = Field(default=16, ge=1)
    patch: int = Field(default=256, ge=16, le=4096)
    lr: float = Field(default=1e-3, gt=0)
    betas: tuple[float, float] = (0.9, 0.9)
    lr_min: float = Field(default=0.0, ge=0)
    noise_sigma: float = Field(default=0.005, ge=0, le=1)
    checkpoint_every: int = Field(default=100, ge=0)
    validate_every: int = Field(default=100, ge=0)
    validation_patches: int = Field(default=16, ge=1)

    @model_validator(mode="after")
    def _betas(self) -> RestoreTrainSpec:
        if not all(0 <= b < 1 for b in self.betas):
            raise ValueError(f"@betas: each must be in [0, 1) (got {list(self.betas)})")
        return self


class RestoreSpec(_Model):
    """The conditioned restoration model NAFNet → Wiener(patch PSF) → NAFNet (S3.2).

    Attributes:
        width: channels of the first level (doubled at each of the len(encoder_blocks) downsamplings).
        encoder_blocks, middle_blocks, decoder_blocks: NAFNet blocks per level (seed: [1,1,1,4], 1, [1,1,1,1]).
        snr: initial Wiener signal-to-noise ratio (learned, stored as log SNR).
        train: training settings.
    """

    width: int = Field(default=16, ge=1, le=512)
    encoder_blocks: list[int] = Field(default_factory=lambda: [1, 1, 1, 4], min_length=1, max_length=8)
    middle_blocks: int = Field(default=1, ge=0)
    decoder_blocks: list[int] = Field(default_factory=lambda: [1, 1, 1, 1], min_length=1, max_length=8)
    snr: float = Field(default=1000.0, gt=0)
    train: RestoreTrainSpec = Field(default_factory=RestoreTrainSpec)

    @model_validator(mode="after")
    def _levels(self) -> RestoreSpec:
        if len(self.encoder_blocks) != len(self.decoder_blocks):
            raise ValueError(f"@decoder_blocks: needs as many levels as encoder_blocks ({len(self.encoder_blocks)}) "
                             f"(got {len(self.decoder_blocks)})")
        if any(b < 0 for b in self.encoder_blocks + self.decoder_blocks):
            raise ValueError("@encoder_blocks: block counts must be ≥ 0")
        return self
