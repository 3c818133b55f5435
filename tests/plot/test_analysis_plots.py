"""Figures of the designer's analyses draw the numbers they are given (the analysis results, untouched),
leave gaps where rays failed, and write files."""

from __future__ import annotations

import dataclasses

import numpy as np
import torch
from matplotlib.figure import Figure

from lensopt.analysis.encircled import geometric_energy
from lensopt.analysis.field_curves import chromatic_focal_shift, field_curves
from lensopt.analysis.mtf_field import mtf_vs_field, through_focus_mtf
from lensopt.analysis.wavefront import opd_fans, wavefront_map, wavefront_stats
from lensopt.analysis.zernike import fit_zernike
from lensopt.plot.encircled import encircled_figure
from lensopt.plot.field_curves import field_curves_figure
from lensopt.plot.focal_shift import focal_shift_figure
from lensopt.plot.mtf_field import mtf_field_figure
from lensopt.plot.opd import opd_fans_figure
from lensopt.plot.style import save_figure
from lensopt.plot.through_focus import through_focus_figure
from lensopt.plot.wavefront import wavefront_figure

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _lines(ax) -> list[np.ndarray]:
    return [np.asarray(line.get_ydata(), dtype=float) for line in ax.get_lines()]


def test_opd_fans_draw_the_fans_with_gaps(cooke, tmp_path) -> None:
    fans = opd_fans(cooke.lens, cooke.system, points=21)
    # one failed ray: its point becomes a gap, the rest is drawn as computed
    valid = fans.tangential_valid.clone()
    valid[2, 1, 3] = False
    fans = dataclasses.replace(fans, tangential_valid=valid)
    fig = opd_fans_figure(fans, title="Cooke")
    top_left = fig.axes[0]  # the largest field on top, tangential on the left
    curves = [y for y in _lines(top_left) if y.size == 21]
    np.testing.assert_array_equal(curves[1][np.isfinite(curves[1])], np.delete(fans.tangential[2, 1].numpy(), 3))
    assert np.isnan(curves[1][3])
    save_figure(fig, tmp_path / "opd.png")
    assert (tmp_path / "opd.png").read_bytes()[:8] == PNG_MAGIC


def test_wavefront_map_shows_the_map_and_its_numbers(cooke) -> None:
    wm = wavefront_map(cooke.lens, cooke.system, n=24)
    st = wavefront_stats(wm.wavefront)
    z = fit_zernike(wm.wavefront.pupil, wm.wavefront.opd, wm.wavefront.valid, ordering="fringe", terms=16)
    fig = wavefront_figure(wm, 1, stats=st, zernike=z, title="Cooke")
    images = [im for ax in fig.axes for im in ax.get_images()]
    assert len(images) == 3
    shown = np.ma.filled(images[0].get_array().astype(float), np.nan)
    expect = np.where(wm.valid[0, 1].numpy(), wm.opd[0, 1].numpy(), np.nan)
    np.testing.assert_array_equal(shown, expect)
    texts = " ".join(t.get_text() for ax in fig.axes for t in ax.texts)
    assert f"RMS {float(st.rms[0, 1]):.3f} λ" in texts and "Z4 defocus" in texts


def test_field_curves_and_focal_shift_figures(cooke, tmp_path) -> None:
    fc = field_curves(cooke.lens, cooke.system, torch.linspace(0.0, 1.0, 11, dtype=torch.float64))
    fig = field_curves_figure(fc, airy_um=3.4)
    ax_f, ax_d, _ = fig.axes[:3]
    xs = [np.asarray(line.get_xdata(), dtype=float) for line in ax_f.get_lines() if len(line.get_xdata()) == 11]
    np.testing.assert_array_equal(xs[0], fc.tangential_mm[:, 0].numpy())
    np.testing.assert_array_equal(xs[1], fc.sagittal_mm[:, 0].numpy())
    dist = [np.asarray(line.get_xdata(), dtype=float) for line in ax_d.get_lines() if len(line.get_xdata()) == 11]
    np.testing.assert_allclose(dist[0], 100 * fc.distortion.numpy(), rtol=0, atol=0)
    fs = chromatic_focal_shift(cooke.lens, cooke.system, media=cooke.media, samples=21)
    fig2 = focal_shift_figure(fs, working_fnumber=5.0)
    assert isinstance(fig2, Figure)
    save_figure(fig2, tmp_path / "focal.svg")
    assert (tmp_path / "focal.svg").read_text().lstrip().startswith("<?xml")


def test_energy_mtf_and_through_focus_figures(cooke) -> None:
    e = geometric_energy(cooke.lens, cooke.system, rel_field=torch.tensor([0.0, 1.0], dtype=torch.float64),
                         sampling="rings:16")
    fig = encircled_figure(e)
    curves = [y for y in _lines(fig.axes[0]) if y.size == e.radius_mm.shape[0]]
    np.testing.assert_array_equal(curves[0], e.encircled[0].numpy())  # the diffraction limit is sampled finer
    m = mtf_vs_field(cooke.lens, cooke.system, [10.0, 30.0], fields=5, sampling="rings:16")
    fig = mtf_field_figure(m)
    np.testing.assert_array_equal(_lines(fig.axes[0])[0], m.tangential[:, 0].numpy())
    tf = through_focus_mtf(cooke.lens, cooke.system, [20.0, 40.0], sampling="rings:16",
                           focus_mm=torch.linspace(-0.1, 0.1, 5, dtype=torch.float64))
    fig = through_focus_figure(tf)
    assert len(fig.axes) == 2
    np.testing.assert_array_equal(_lines(fig.axes[1])[1], tf.sagittal[:, 0, 1].numpy())
