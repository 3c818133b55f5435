"""Image restoration (S3.2) and everything about its network: the model (Wiener deconvolution with a
learnable SNR, NAFNet blocks, the single-stage conditioned model NAFNet → Wiener(patch PSF) → NAFNet),
its training on a fixed lens, its checkpoints, and applying it to captures. Functions first, thin
modules on top. The joint lens + network step composes this package with ``lensopt.optim`` in
``lensopt.design.joint``.

    config.py       the network's and its training's configuration (plain dataclasses)
    wiener.py       Wiener deconvolution with a learnable SNR
    nafnet.py       NAFNet blocks
    model.py        the conditioned restorer (ConditionedRestorer), the mean patch PSF
    capture.py      training batches: imaging set-up, lens PSFs, PSF grids of regions, captures, seeded draws
    train.py        one network step, validation, the training loop, a whole ``train-irm`` run
    checkpoint.py   network checkpoints: fingerprint, run state, ``--resume``, loading a trained network
    tensorboard.py  TensorBoard layouts and example images of ``train-irm`` and joint runs
    apply.py        restoring a whole capture; the ``--irm`` restoration hook
"""

from lensopt.restore.config import RestoreConfig
from lensopt.restore.model import ConditionedRestorer, mean_patch_psf, restore_patches
from lensopt.restore.nafnet import NAFNet, nafnet_block
from lensopt.restore.wiener import Wiener, wiener_deconvolve

__all__ = ["ConditionedRestorer", "NAFNet", "RestoreConfig", "Wiener", "mean_patch_psf", "nafnet_block",
           "restore_patches", "wiener_deconvolve"]
