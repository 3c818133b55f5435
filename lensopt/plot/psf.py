"""PSF figure: RGB PSFs across the field (one panel per field), optionally on a square-root scale."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from lensopt.analysis.psf_stack import PsfStack
from lensopt.files import atomic_path

__all__ = ["psf_rgb", "save_psf_figure"]


def psf_rgb(stack: PsfStack, channel_weights: np.ndarray) -> np.ndarray:
    """(F, S, S, 3) RGB PSFs (K1 W_w, S1.5.1 step 2) in image orientation (+y up)."""
    k2 = torch.einsum("fwij,wc->fcij", stack.psf.detach(), torch.as_tensor(channel_weights, dtype=stack.psf.dtype))
    return torch.flip(k2, (-2,)).permute(0, 2, 3, 1).cpu().numpy()


def save_psf_figure(path: str | Path, stack: PsfStack, channel_weights: np.ndarray, *, title: str,
                    sqrt: bool = False, rms_um: list[float] | None = None, dpi: int = 150) -> None:
    """Write the figure atomically (format from the suffix)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rgb = psf_rgb(stack, channel_weights)
    num_f, size = rgb.shape[0], rgb.shape[1]
    half = size // 2 * stack.pitch_mm * 1e3
    fig, axes = plt.subplots(1, num_f, figsize=(2.6 * num_f + 0.4, 3.2), squeeze=False)
    for f in range(num_f):
        img = np.sqrt(np.clip(rgb[f], 0, None)) if sqrt else rgb[f]
        img = img / max(float(img.max()), 1e-300)
        ax = axes[0, f]
        ax.imshow(img, extent=(-half, half, -half, half), interpolation="nearest")
        label = f"{float(stack.field_deg[f]):.2f}°"
        if rms_um is not None:
            label += f"\nRMS {rms_um[f]:.1f} µm"
        ax.set_title(label, fontsize=9)
        ax.set_xlabel("x µm", fontsize=8)
        ax.tick_params(labelsize=7)
        if f == 0:
            ax.set_ylabel("y µm", fontsize=8)
    scale = "√ intensity" if sqrt else "intensity"
    fig.suptitle(f"{title} — PSFs ({scale}, each panel normalized; bins {stack.pitch_mm * 1e3:g} µm, "
                 f"{stack.settings.kernel}, diffraction {stack.settings.diffraction})", fontsize=9)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi)
    plt.close(fig)
