"""Image restoration (S3.2): Wiener deconvolution with a learnable SNR, NAFNet blocks, and the
single-stage conditioned model NAFNet → Wiener(patch PSF) → NAFNet. Functions first, thin modules on top."""

from lensopt.restore.config import RestoreConfig
from lensopt.restore.model import ConditionedRestorer, mean_patch_psf, restore_patches
from lensopt.restore.nafnet import NAFNet, nafnet_block
from lensopt.restore.wiener import Wiener, wiener_deconvolve

__all__ = ["ConditionedRestorer", "NAFNet", "RestoreConfig", "Wiener", "mean_patch_psf", "nafnet_block",
           "restore_patches", "wiener_deconvolve"]
