"""Wavefront maps: W over the pupil at one wavelength, one map per field (largest field right), on one
diverging colour scale centred on 0, with RMS / P-V / Strehl under each map and the fitted Zernike
coefficients (largest first) beside it."""

from __future__ import annotations

import matplotlib
import numpy as np
from matplotlib.figure import Figure

from lensopt.analysis.strehl import StrehlResult
from lensopt.analysis.wavefront import WavefrontMap, WavefrontStats
from lensopt.analysis.zernike import ZernikeFit
from lensopt.plot.fans import _round_up
from lensopt.plot.style import RC, new_figure

__all__ = ["wavefront_figure"]

_NAMES = {(0, 0): "piston", (1, 1): "tilt x", (1, -1): "tilt y", (2, 0): "defocus", (2, 2): "astig 0°",
          (2, -2): "astig 45°", (3, 1): "coma x", (3, -1): "coma y", (4, 0): "spherical", (3, 3): "trefoil x",
          (3, -3): "trefoil y", (4, 2): "2nd astig 0°", (4, -2): "2nd astig 45°", (5, 1): "2nd coma x",
          (5, -1): "2nd coma y", (6, 0): "2nd spherical", (4, 4): "tetrafoil 0°", (4, -4): "tetrafoil 22.5°",
          (8, 0): "3rd spherical", (10, 0): "4th spherical", (12, 0): "5th spherical"}


def wavefront_figure(wm: WavefrontMap, wavelength: int, *, stats: WavefrontStats | None = None,
                     strehl: StrehlResult | None = None, zernike: ZernikeFit | None = None, title: str = "",
                     subtitle: str = "", top_terms: int = 6) -> Figure:
    """Maps of ``wm`` at wavelength index ``wavelength``.

    Args:
        stats: RMS and P-V per field and wavelength (printed under the maps).
        strehl: Strehl ratios from the PSF and Maréchal's estimate (both printed).
        zernike: a fit of ``wm.wavefront`` with coefficients (F, W, J): the ``top_terms`` largest
            (piston and tilt excluded) are listed under each map.
    """
    opd = wm.opd[:, wavelength].detach().cpu().numpy()
    valid = wm.valid[:, wavelength].cpu().numpy()
    maps = np.where(valid, opd, np.nan)
    num_f = maps.shape[0]
    finite = maps[np.isfinite(maps)]
    scale = _round_up(max(float(np.abs(finite).max()) if finite.size else 0.0, 0.01))
    wf = wm.wavefront
    lam_nm = 1e3 * float(wf.wavelength_um[wavelength])
    order = np.argsort(wf.rel_field.cpu().numpy(), kind="stable")
    per_row = 3  # maps per row: more fields wrap onto further rows
    ncols = min(num_f, per_row)
    nrows = -(-num_f // per_row)
    with matplotlib.rc_context(RC):
        rows = 3 + (zernike is not None) * top_terms
        fig = new_figure(1.2 + 3.3 * ncols, (3.0 + 0.14 * rows) * nrows + 0.6)
        grid = fig.subplots(2 * nrows, ncols, squeeze=False, height_ratios=[3.0, 0.16 * rows + 0.1] * nrows)
        axes = [grid[2 * (i // per_row), i % per_row] for i in range(num_f)]
        notes = [grid[2 * (i // per_row) + 1, i % per_row] for i in range(num_f)]
        for i in range(num_f, nrows * ncols):  # empty cells of the last row
            grid[2 * (i // per_row), i % per_row].axis("off")
            grid[2 * (i // per_row) + 1, i % per_row].axis("off")
        image = None
        for col, f in enumerate(order):
            ax = axes[col]
            image = ax.imshow(maps[f], origin="lower", extent=(-1, 1, -1, 1), cmap="RdBu_r", vmin=-scale, vmax=scale,
                              interpolation="nearest")
            t = np.linspace(0, 2 * np.pi, 200)
            ax.plot(np.cos(t), np.sin(t), color="0.4", lw=0.6)
            ax.set_xticks([-1, 0, 1])
            ax.set_yticks([-1, 0, 1])
            ax.set_xlabel("px")
            if col % per_row == 0:
                ax.set_ylabel("py")
            ax.set_title(f"{float(wf.field_deg[f]):.2f}° (rel. {float(wf.rel_field[f]):.2f})")
            lines = []
            if stats is not None:
                rms, pv = float(stats.rms[f, wavelength]), float(stats.pv[f, wavelength])
                lines.append(f"RMS {rms:.3f} λ   P-V {pv:.3f} λ")
                lines.append(f"(to chief: RMS {float(stats.rms_chief[f, wavelength]):.3f} λ)")
            if strehl is not None:
                lines.append(f"Strehl {float(strehl.psf[f, wavelength]):.3f} (PSF), "
                             f"{float(strehl.marechal[f, wavelength]):.3f} (Maréchal)")
            if zernike is not None:
                c = zernike.coefficients[f, wavelength].detach().cpu().numpy()
                keep = [j for j, nm in enumerate(zernike.indices) if nm[0] > 1 and abs(c[j]) >= 5e-4]  # shown ≠ 0
                top = sorted(keep, key=lambda j: -abs(c[j]))[:top_terms]
                first = zernike.numbers[0]
                lines.append(f"{zernike.ordering} Zernike (waves):")
                lines += [f"Z{j + first} {_NAMES.get(zernike.indices[j], str(zernike.indices[j]))}: {c[j]:+.3f}"
                          for j in top]
            notes[col].axis("off")
            notes[col].text(0.0, 1.0, "\n".join(lines), transform=notes[col].transAxes, va="top", ha="left",
                            fontsize=7.5, family="monospace")
        if image is not None:
            fig.colorbar(image, ax=list(axes), shrink=0.8 if nrows == 1 else 0.5, label="W (waves)")
        note = (f"{lam_nm:g} nm · W = OPL(chief) − OPL(ray) to the chief ray's reference sphere (ahead-positive) · "
                "RMS and P-V with tilt removed")
        fig.suptitle("\n".join(x for x in (title or "Wavefront map", subtitle, note) if x), fontsize=10)
    return fig
