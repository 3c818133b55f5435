"""Vignetting factors (S1.3.2, S19–S20): reshape the unit entrance-pupil disc per field and wavelength.

With V_i, V_s, V_l the blocked fractions of the inferior (lower, −y), superior (upper, +y) and lateral
pupil halves::

    x' = (1 − V_l) x,     y' = (1 − (V_i + V_s)/2) y + (V_i − V_s)/2

so that the pupil spans y' ∈ [−1 + V_i, 1 − V_s], as the seed's text says ("V_i = 1, V_s = 0: light
passes through the centre and top, blocked between bottom and centre") and as CODE V's VLY/VUY do.
The printed S20 has the last term as (V_s − V_i)/2, which contradicts that text; we follow the text.
"""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["apply_vignetting"]


def apply_vignetting(pupil: Tensor, factors: Tensor) -> Tensor:
    """Apply S19–S20 (sign of S20's offset as in the seed's text, see the module doc) to pupil coordinates.

    Args:
        pupil: (F, W, P, 2) relative pupil coordinates.
        factors: (F, W, 3) or broadcastable (e.g. (F, 1, 3)) factors (V_i, V_s, V_l).

    Returns:
        (F, W, P, 2) reshaped pupil coordinates (differentiable in the factors).
    """
    v_i, v_s, v_l = (factors[..., k].unsqueeze(-1) for k in range(3))
    x = (1.0 - v_l) * pupil[..., 0]
    y = (1.0 - 0.5 * (v_i + v_s)) * pupil[..., 1] + 0.5 * (v_i - v_s)
    return torch.stack([x, y], -1)
