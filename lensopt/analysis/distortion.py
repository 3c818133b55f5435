"""Distortion per field (S48): the spot centroid against the paraxial image height,
``D_h = (ȳ_h − y'_h) / y'_{n_h}``, relative to the paraxial image height of the outermost field."""

from __future__ import annotations

import torch
from torch import Tensor

from lensopt.analysis.spot import SpotStats
from lensopt.optics.bundle import Bundle
from lensopt.optics.lens import Lens, System
from lensopt.optics.paraxial import chief_image_height

__all__ = ["paraxial_heights", "distortion", "centroid_distortion"]


def paraxial_heights(lens: Lens, system: System, bundle: Bundle) -> Tensor:
    """(F,) paraxial chief-ray heights y'_h on the image surface for the bundle's fields, mm."""
    return chief_image_height(lens, system, bundle.tan_field, ep_z=bundle.first_order.entrance_pupil_z)


def distortion(lens: Lens, system: System, bundle: Bundle, stats: SpotStats) -> Tensor:
    """(F,) relative distortion D_h (S48), a fraction (0.02 = 2 %), differentiable.

    The denominator is the paraxial height of the field with the largest |y'| (the outermost field).
    """
    return centroid_distortion(lens, system, bundle, stats.centroid)


def centroid_distortion(lens: Lens, system: System, bundle: Bundle, centroid: Tensor) -> Tensor:
    """``distortion`` from the fields' spot centroids (F, 2) (``spot_stats``' or ``spot_centroid``'s)."""
    y_par = paraxial_heights(lens, system, bundle)
    # gather with a tensor index, not y_par[tensor]: no .item(), so torch.compile keeps one graph.
    outer = y_par.gather(0, torch.argmax(y_par.detach().abs()).reshape(1)).squeeze(0)
    return (centroid[:, 1] - y_par) / outer
