"""Image restoration (S3.2): Wiener deconvolution with a learnable SNR, NAFNet blocks, and the
single-stage conditioned model NAFNet → Wiener(patch PSF) → NAFNet. Functions first, thin modules on top.

    config.py   the network's configuration (plain dataclasses)
    wiener.py   Wiener deconvolution with a learnable SNR
    nafnet.py   NAFNet blocks
    model.py    the conditioned restorer (ConditionedRestorer)
"""

from lensopt.restore.config import RestoreConfig
from lensopt.restore.model import ConditionedRestorer, mean_patch_psf, restore_patches
from lensopt.restore.nafnet import NAFNet, nafnet_block
from lensopt.restore.wiener import Wiener, wiener_deconvolve

__all__ = ["ConditionedRestorer", "NAFNet", "RestoreConfig", "Wiener", "mean_patch_psf", "nafnet_block",
           "restore_patches", "wiener_deconvolve"]
