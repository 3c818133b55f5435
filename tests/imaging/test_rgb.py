"""RGB weights from a spectrum (seed S4.1.2): the rule's defining properties, optimality of its extent
against a linear-programming oracle, Table S9's spectrum, and `lensopt simulate` on a lens without
rgb_weights (the C-mount lens, 12 wavelengths)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import linprog

from lensopt.errors import LensoptError
from lensopt.imaging.rgb import channel_extent_nm, rgb_weights_from_spectrum

ROOT = Path(__file__).resolve().parents[2]

# Seed Table S9 (telephoto, 11 wavelengths); columns R, G, B; the "Average" column is the spectrum.
S9_WL = np.arange(425.0, 676.0, 25.0)
S9 = np.array([[0, 0, .0355], [0, 0, .0425], [0, .0046, .0703], [0, 0, .2299], [0, .0321, .4951],
               [0, .5584, .1267], [.4002, .2467, 0], [.2946, .1541, 0], [.2052, .0041, 0], [.0739, 0, 0],
               [.0261, 0, 0]])
S9_AVG = np.array([0.0119, 0.0142, 0.0250, 0.0766, 0.1757, 0.2284, 0.2156, 0.1495, 0.0698, 0.0246, 0.0087])


def _check_rule(wl: np.ndarray, s: np.ndarray, w: np.ndarray) -> None:
    s = s / s.sum()
    assert w.shape == (wl.size, 3) and (w >= 0).all()
    assert np.allclose(w.sum(axis=0), 1.0, atol=1e-12)  # each channel normalized (S1.5.1)
    assert np.allclose(w.sum(axis=1), 3.0 * s, atol=1e-12)  # channels sum to the spectrum
    lo, hi = np.argmin(wl), np.argmax(wl)
    if s[lo] <= 1 / 3:
        assert w[lo, 0] == 0 and w[lo, 1] == 0  # all of the shortest wavelength to B
    if s[hi] <= 1 / 3:
        assert w[hi, 1] == 0 and w[hi, 2] == 0  # all of the longest to R


def test_table_s9_spectrum_properties_and_documented_difference() -> None:
    # The table's own rows sum to 3 × its "Average" column (the spectrum) to its 4-digit rounding.
    assert np.allclose(S9.sum(axis=1), 3 * S9_AVG, atol=2e-4)
    w = rgb_weights_from_spectrum(S9_WL, S9_AVG)
    _check_rule(S9_WL, S9_AVG, w)
    # Same spectrum, same constraints; the contiguous split's channels are narrower on average than the
    # table's overlapping ones (README "RGB weights": the table's digits are not reproduced).
    ours, table = channel_extent_nm(S9_WL, w).mean(), channel_extent_nm(S9_WL, S9).mean()
    assert ours < table - 3.0  # 21.5 nm against 25.5 nm
    # Where the table is unambiguous it agrees: 425–500 nm only in B (our 475 nm is all B, the table
    # gives G 0.0046 of it), 650–675 nm only in R.
    assert np.allclose(w[[0, 1, 3], :2], 0) and np.allclose(w[[9, 10], 1:], 0)
    assert np.allclose(w[[0, 1, 3], 2], S9[[0, 1, 3], 2], atol=2e-4)
    assert np.allclose(w[[9, 10], 0], S9[[9, 10], 0], atol=2e-4)


def _lp_vertex(s: np.ndarray, cost: np.ndarray) -> np.ndarray:
    n = s.size
    a_eq, b_eq = [], []
    for i in range(n):
        row = np.zeros((n, 3))
        row[i] = 1
        a_eq.append(row.ravel())
        b_eq.append(3 * s[i])
    for c in range(3):
        row = np.zeros((n, 3))
        row[:, c] = 1
        a_eq.append(row.ravel())
        b_eq.append(1.0)
    res = linprog(cost, A_eq=np.array(a_eq), b_eq=np.array(b_eq), bounds=[(0, None)] * (3 * n), method="highs")
    assert res.status == 0
    return res.x.reshape(n, 3)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_extent_is_minimal_among_feasible_vertices(seed: int) -> None:
    # The mean channel standard deviation is concave in W, so its minimum over the feasible polytope
    # (row sums 3·s, column sums 1, W ≥ 0) is at a vertex. Vertices from an independent LP solver
    # (random costs) never beat the rule's matrix.
    rng = np.random.default_rng(seed)
    wl = np.sort(rng.uniform(380, 720, 9))
    s = rng.random(9)
    s /= s.sum()
    best = channel_extent_nm(wl, rgb_weights_from_spectrum(wl, s)).mean()
    for _ in range(60):
        v = _lp_vertex(s, rng.normal(size=27))
        assert channel_extent_nm(wl, v).mean() >= best - 1e-9


def test_any_order_zero_weights_and_errors() -> None:
    # The C-mount spectrum: 11 wavelengths and the 550 nm reference with weight 0, appended last.
    wl = [390, 420, 450, 480, 510, 540, 570, 600, 630, 660, 690, 550]
    s = [0.024, 0.0765, 0.0962, 0.1083, 0.1222, 0.1104, 0.0858, 0.1248, 0.1089, 0.1048, 0.0381, 0.0]
    w = rgb_weights_from_spectrum(wl, s)
    _check_rule(np.array(wl, float), np.array(s), w)
    assert (w[-1] == 0).all()
    perm = np.random.default_rng(0).permutation(12)
    assert np.allclose(rgb_weights_from_spectrum(np.array(wl)[perm], np.array(s)[perm]), w[perm])
    # One wavelength: every channel is that wavelength.
    assert np.allclose(rgb_weights_from_spectrum([550.0], None), [[1, 1, 1]])
    with pytest.raises(LensoptError, match="spectrum.weights"):
        rgb_weights_from_spectrum([500, 600], [1.0, -1.0])


def test_simulate_cmount_without_rgb_weights(tmp_path: Path) -> None:
    # Before issue 10 this exited 2 ("spectrum.rgb_weights: needed to simulate an RGB image").
    from typer.testing import CliRunner

    from lensopt.cli.app import app
    from lensopt.imaging.io import ImageInfo, write_image

    # The shipped C-mount lens carries the rgb_weights of its networks; without them: the seed's rule.
    lens = json.loads((ROOT / "lenses" / "cmount_4p.json").read_text())
    del lens["spectrum"]["rgb_weights"]
    assert len(lens["spectrum"]["wavelengths_nm"]) == 12
    (tmp_path / "cmount.json").write_text(json.dumps(lens))
    scene = np.random.default_rng(0).random((32, 32, 3)).astype(np.float32)
    write_image(tmp_path / "in.png", scene, ImageInfo(32, 32, 3, 8, False, "sRGB", "png"))
    r = CliRunner().invoke(app, ["simulate", str(tmp_path / "cmount.json"), str(tmp_path / "in.png"),
                                 "-o", str(tmp_path / "out.png"), "--region", "center", "--rays", "rings:6",
                                 "--json"])
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)
    assert (tmp_path / "out.png").is_file()
    assert any("contiguous thirds of the spectrum" in note for note in out["plan"]["notes"])  # S4.1.2
    assert out["plan"]["channels"] == ["R", "G", "B"]
    assert 550.0 not in out["plan"]["wavelengths_nm"]  # its weight is 0: not traced
