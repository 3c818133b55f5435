"""The ``[restore]`` section of a spec as the restoration core's plain configs (``lensopt.restore.config``):
the network architecture and its training settings."""

from __future__ import annotations

from lensopt.restore.config import RestoreConfig, TrainConfig
from lensopt.spec.restore import RestoreSpec

__all__ = ["configs_from_spec"]


def configs_from_spec(section: RestoreSpec | None) -> tuple[RestoreConfig, TrainConfig]:
    """The core's plain configs from a ``[restore]`` section (None: the defaults)."""
    if section is None:
        return RestoreConfig(), TrainConfig()
    net = RestoreConfig(width=section.width, encoder_blocks=tuple(section.encoder_blocks),
                        middle_blocks=section.middle_blocks, decoder_blocks=tuple(section.decoder_blocks),
                        snr=section.snr)
    t = section.train
    train = TrainConfig(steps=t.steps, batch=t.batch, patch=t.patch, lr=t.lr, betas=tuple(t.betas), lr_min=t.lr_min,
                        noise_sigma=t.noise_sigma, checkpoint_every=t.checkpoint_every,
                        validate_every=t.validate_every, validation_patches=t.validation_patches)
    return net, train
