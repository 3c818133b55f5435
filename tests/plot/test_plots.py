"""Figures: the layout data is the traced geometry, plots draw what they are given (gaps for failed
rays), files are written atomically."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch
from matplotlib.figure import Figure

from lensopt.analysis.fans import ray_fans
from lensopt.analysis.layout import layout
from lensopt.analysis.report import auto_semi_diameters
from lensopt.analysis.spot_diagram import spot_diagram
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.sampling import PupilSampling
from lensopt.plot import plot_fans, plot_layout, plot_spots, save_figure, wavelength_color
from lensopt.spec import build
from lensopt.spec.io import parse_spec
from tests.helpers import cooke_data

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def vignetted():
    """EPD 12 mm with surface 5 clipped at 6 mm: the upper off-axis rays are lost at surface 5."""
    data = cooke_data()
    data["system"]["aperture"] = {"epd": 12.0}
    data["surfaces"][4].update(semi_diameter=6.0, clip=True)
    return build(parse_spec(data))


def test_layout_geometry_is_the_traced_lens(cooke):
    data = layout(cooke, rays_per_field=5)
    lens = cooke.lens
    assert torch.equal(data.vertex_z, lens.vertex_z())
    assert data.vertex_z[-1].item() == pytest.approx(60.17675, abs=1e-9)  # sum of the spec's thicknesses
    # No semi-diameter in the spec: every one comes from traced rays.
    assert not data.semi_diameter_given.any()
    assert data.semi_diameter.tolist() == pytest.approx(auto_semi_diameters(cooke), abs=0)
    assert data.glass_after == (True, False, True, False, True, False)
    assert data.stop == 2
    # Profiles: vertex at the centre sample, sphere sag R − sqrt(R² − y²) at the rim (closed form).
    mid = data.profile_y.shape[1] // 2
    assert torch.allclose(data.profile_z[:, mid], lens.vertex_z()[:-1], atol=1e-15)
    r0, h0 = 22.01359, float(data.semi_diameter[0])
    assert float(data.profile_z[0, -1]) == pytest.approx(r0 - math.sqrt(r0**2 - h0**2), abs=1e-12)
    # Ray paths: surface points and image points are those of the trace (reference wavelength, px = 0).
    with torch.no_grad():
        b = trace_bundle(lens, cooke.system, torch.stack([torch.zeros(5), torch.linspace(-1, 1, 5)], -1)
                         .double(), record=True)
    ref = cooke.system.reference
    assert data.reached.all()
    assert torch.allclose(data.rays[:, :, -1, 1], b.result.pos[:, ref, :, 1], atol=0)
    assert torch.allclose(data.rays[:, :, 3, 0], b.result.hits[2].pos[:, ref, :, 2], atol=0)
    assert float(data.image_half_height) >= float(b.result.pos[..., 1].abs().max())


def test_layout_stops_failed_rays_where_they_failed(vignetted):
    data = layout(vignetted, rays_per_field=9)
    lost = ~data.reached[..., -1]
    assert lost.any() and not lost[0].any()  # on axis nothing is clipped
    # Clipped at surface 5 (path index 5): they reach surface 4 but neither surface 5 nor the image.
    assert data.reached[lost][:, 4].all() and not data.reached[lost][:, 5:].any()
    assert data.semi_diameter_given.tolist() == [False, False, False, False, True, False]
    assert float(data.semi_diameter[4]) == 6.0


def _save(fig: Figure, path: Path) -> bytes:
    save_figure(fig, path, dpi=60)
    data = path.read_bytes()
    assert data.startswith(PNG_MAGIC) and len(data) > 5000
    assert [p.name for p in path.parent.iterdir()] == [path.name]  # no temporary file left
    return data


def test_plots_write_pngs(cooke, tmp_path):
    with torch.no_grad():
        fans = ray_fans(cooke.lens, cooke.system, points=21)
        spots = spot_diagram(cooke.lens, cooke.system, PupilSampling.parse("rings:8"))
    _save(plot_layout(layout(cooke, rays_per_field=3), title="t"), tmp_path / "a" / "layout.png")
    _save(plot_fans(fans), tmp_path / "b" / "fans.png")
    _save(plot_spots(spots, title="t", subtitle="s"), tmp_path / "c" / "spots.png")


def test_spot_figure_reports_the_library_numbers(cooke):
    with torch.no_grad():
        spots = spot_diagram(cooke.lens, cooke.system, PupilSampling.parse("rings:8"))
    fig = plot_spots(spots)
    titles = [ax.get_title() for ax in fig.axes if ax.get_title()]
    for h, title in enumerate(titles):  # panels in increasing field order: 0°, 14°, 20°
        assert f"RMS radius {1e3 * float(spots.stats.rms_radius[h]):.3f} µm" in title
    # Airy radius 1.22 λ N_w at 550 nm and the working f-number of a 50 mm f/5 lens at infinity.
    assert float(spots.airy_radius[1]) == pytest.approx(1.22 * 0.55e-3 * float(spots.working_fnumber), rel=1e-15)
    assert float(spots.working_fnumber) == pytest.approx(5.0, abs=1e-4)


def test_fan_plot_leaves_gaps_for_failed_rays(vignetted):
    with torch.no_grad():
        fans = ray_fans(vignetted.lens, vignetted.system, points=21)
    fig = plot_fans(fans)
    # Row 0 is the largest field; its tangential panel's curves carry NaN where rays failed.
    top_tangential = fig.axes[0]
    curves = [line for line in top_tangential.get_lines() if len(line.get_ydata()) == 21]
    assert len(curves) == 3
    for w, line in enumerate(curves):
        y = np.asarray(line.get_ydata(), dtype=float)
        assert np.array_equal(np.isnan(y), ~fans.tangential_valid[2, w].numpy())
        ok = ~np.isnan(y)
        assert np.allclose(y[ok], 1e3 * fans.tangential[2, w].numpy()[ok], rtol=0, atol=1e-9)


def test_save_figure_leaves_nothing_on_error(tmp_path):
    class Boom(Exception):
        pass

    fig = Figure()

    def broken(path, **kwargs):
        Path(path).write_bytes(b"half a png")
        raise Boom

    fig.savefig = broken  # type: ignore[method-assign]
    target = tmp_path / "out.png"
    with pytest.raises(Boom):
        save_figure(fig, target)
    assert list(tmp_path.iterdir()) == []


def test_wavelength_colours_follow_the_spectrum():
    blue, green, red = (wavelength_color(nm) for nm in (460.0, 540.0, 650.0))
    assert np.argmax(blue) == 2 and np.argmax(green) == 1 and np.argmax(red) == 0
    assert all(0.0 <= c <= 1.0 for nm in (300.0, 400.0, 1000.0, 2000.0) for c in wavelength_color(nm))


def _shipped_wavelengths_nm() -> list[float]:
    from lensopt.spec.io import load_spec

    root = Path(__file__).resolve().parents[2]
    found: set[float] = set()
    # Every spec and lens (not specs/stages: a stage starts from a run's output; not the check baseline).
    for path in sorted([*(root / "specs").glob("*.toml"), *(root / "lenses").glob("*.json")]):
        if path.name == "check_baseline.json":
            continue
        found.update(float(w) for w in load_spec(path).spectrum.wavelengths_nm)
    return sorted(found)


def test_wavelength_colours_have_contrast_on_white_for_every_shipped_spec():
    # WCAG 2 relative luminance and contrast computed here from the definition, not from the library's helpers.
    def lum(rgb):
        lin = [c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4 for c in rgb]
        return 0.2126 * lin[0] + 0.7152 * lin[1] + 0.0722 * lin[2]

    wavelengths = _shipped_wavelengths_nm()
    assert 587.6 in wavelengths and len(wavelengths) > 10
    for nm in [*wavelengths, 380.0, 546.1, 587.6, 1000.0]:
        rgb = wavelength_color(nm)
        assert all(0.0 <= c <= 1.0 for c in rgb)
        assert 1.05 / (lum(rgb) + 0.05) >= 3.0, (nm, rgb)
    # The d line stays a yellow (red and green both present, no blue), not a brown-black.
    r, g, b = wavelength_color(587.6)
    assert b == 0.0 and r > 0.5 and g > 0.45


def test_spot_dots_are_visible_and_scale_with_the_number_of_rays(cooke):
    with torch.no_grad():
        sparse = spot_diagram(cooke.lens, cooke.system, PupilSampling.parse("rings:6"))
        dense = spot_diagram(cooke.lens, cooke.system, PupilSampling.parse("rings:24"))
    size = [plot_spots(s).axes[0].collections[0].get_sizes()[0] for s in (sparse, dense)]
    assert size[0] > size[1] >= 2.0  # pt²: the rings:24 dots were 0.6 pt² before (issue 29)
