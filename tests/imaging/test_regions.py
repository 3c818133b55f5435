"""Sensor-region tiles and pseudo-random stratified sampling (seed S3.3.1, Figure S8; S4.3.1)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch

from lensopt.errors import LensoptError
from lensopt.imaging.regions import RegionSampler, ring_of, stratified_draw, tile_grid
from lensopt.imaging.scene import Sensor, parse_region


def test_seed_telephoto_sensor_has_768_tiles() -> None:
    # Seed Figure S8 / S4.1.1: 8192×6144 px sensor, 256 px patches → 32×24 = 768 regions.
    g = tile_grid(Sensor(0.001, 8192, 6144), 256)
    assert (g.cols, g.rows, len(g)) == (32, 24, 768)
    # The four tiles around the centre come first, at (128, 128) px from the axis.
    assert torch.allclose(g.radius_mm[:4], torch.full((4,), math.hypot(0.128, 0.128), dtype=torch.float64))
    assert bool((g.radius_mm[1:] >= g.radius_mm[:-1]).all())
    # The last tiles are the four corners: centre at (8192/2 − 128, 6144/2 − 128) px.
    assert abs(float(g.radius_mm[-1]) - math.hypot(3.968, 2.944)) < 1e-12
    assert float(g.radius_rel[-1]) == 1.0


def test_tiles_partition_the_sensor() -> None:
    sensor = Sensor(0.0055, 96, 64)
    g = tile_grid(sensor, 16)
    cover = np.zeros((64, 96), int)
    for k in range(len(g)):
        x0, y0 = (int(v) for v in g.origin_px[k])
        cover[y0:y0 + 16, x0:x0 + 16] += 1
    assert (cover == 1).all()
    # centre in mm: X = (sx − W/2)·p, Y = (H/2 − sy)·p (imaging.scene's convention)
    cx, cy = g.center_px[5].tolist()
    assert g.center_mm[5].tolist() == pytest.approx([(cx - 48) * 0.0055, (32 - cy) * 0.0055])


def test_remainder_margins_are_centred() -> None:
    g = tile_grid(Sensor(0.001, 100, 70), 32)  # 3×2 tiles, margins 2 px and 3 px
    assert (g.cols, g.rows) == (3, 2)
    assert float(g.origin_px[:, 0].min()) == 2.0 and float(g.origin_px[:, 1].min()) == 3.0


def test_region_matches_simulate_tile_syntax() -> None:
    sensor = Sensor(0.0055, 2048, 2048)
    g = tile_grid(sensor, 256)
    for k in (0, 17, len(g) - 1):
        reg = g.region(k)
        ref = parse_region(f"tile:{int(g.col[k])},{int(g.row[k])}/8x8", sensor, 256, 256)
        assert (reg.x0, reg.y0, reg.w, reg.h) == (ref.x0, ref.y0, ref.w, ref.h)


def test_stratified_batch_covers_the_field_evenly() -> None:
    # 768 tiles, batch 16: exactly one tile in each sixteenth of the distance-sorted list.
    gen = torch.Generator().manual_seed(0)
    for _ in range(5):
        d = stratified_draw(768, 16, gen)
        assert sorted((d // 48).tolist()) == list(range(16))
    # Positions are shuffled: over draws the first slot is not always the most central stratum.
    firsts = {int(stratified_draw(768, 16, gen)[0]) // 48 for _ in range(30)}
    assert len(firsts) > 3


def test_more_draws_than_tiles_repeat_every_tile() -> None:
    d = stratified_draw(64, 100, torch.Generator().manual_seed(1))  # the C-mount sensor, 100 images
    counts = torch.bincount(d, minlength=64)
    assert int(counts.min()) == 1 and int(counts.max()) == 2 and int(counts.sum()) == 100
    twice = torch.nonzero(counts == 2).ravel()
    # the 36 extra draws are stratified: one per stratum of 64/36 tiles
    bounds = torch.linspace(0, 64, 37).round().long()
    assert sorted(torch.bucketize(twice, bounds[1:-1], right=True).tolist()) == list(range(36))


def test_sampler_is_seeded() -> None:
    g = tile_grid(Sensor(0.001, 512, 512), 64)
    a, b = RegionSampler(g, seed=3), RegionSampler(g, seed=3)
    assert torch.equal(a.sample(8), b.sample(8)) and torch.equal(a.sample(8), b.sample(8))
    assert not torch.equal(RegionSampler(g, seed=4).sample(8), RegionSampler(g, seed=3).sample(8))


def test_rings_and_errors() -> None:
    assert ring_of(np.array([0.0, 0.24, 0.25, 0.99, 1.0]), 4).tolist() == [0, 0, 1, 3, 3]
    with pytest.raises(LensoptError, match="larger than"):
        tile_grid(Sensor(0.001, 100, 100), 256)
    with pytest.raises(LensoptError, match="positive"):
        tile_grid(Sensor(0.001, 100, 100), 0)


def test_plot_regions_figure_and_cli(tmp_path) -> None:
    from matplotlib.patches import Rectangle
    from typer.testing import CliRunner

    from lensopt.cli.app import app
    from lensopt.plot.regions import plot_regions

    g = tile_grid(Sensor(0.001, 8192, 6144), 256)
    draw = RegionSampler(g, seed=0).sample(16)
    fig = plot_regions(g, draw)
    boxes = [p for p in fig.axes[0].patches if isinstance(p, Rectangle)]
    assert len(boxes) == 16  # one outline per drawn tile (16 distinct tiles: one per stratum)
    assert {(b.get_x(), b.get_y()) for b in boxes} == {tuple(g.origin_px[int(k)].tolist()) for k in draw}
    out = tmp_path / "regions.png"
    spec = str(Path(__file__).resolve().parents[2] / "specs" / "cooke_triplet.toml")
    r = CliRunner().invoke(app, ["plot", "regions", spec, "-o", str(out), "--patch", "500", "--batch", "8"])
    assert r.exit_code == 0, r.output
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
