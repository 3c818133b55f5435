"""Even PSF oversampling (issue 13 bug: ``PsfSettings(oversample=2)`` failed with "size must be odd").

The fine grid has S·o bins of pitch p/o centred on the same point as the S coarse bins, so it tiles them
exactly: coarse bin j (|u − j| < ½ in coarse units) is the union of fine bins o·j … o·j + o − 1 for any
o, odd or even (for even o the grid centre falls on a fine-bin corner). Hence ray counting on the fine
grid, summed over o×o blocks, equals ray counting on the coarse grid bin for bin — the independent
expectation these tests use — and an on-axis PSF stays centred (symmetric under flips).
"""

from __future__ import annotations

import pytest
import torch

from lensopt.analysis.psf import deposit
from lensopt.analysis.psf_stack import PsfSettings, compute_psfs

F64 = torch.float64


@pytest.mark.parametrize("o", [2, 4])
def test_even_oversampled_ray_count_equals_coarse_count(cooke, o: int) -> None:
    model = cooke
    rel = torch.tensor([0.0, 0.7, 1.0], dtype=F64)
    kw = dict(sampling="rings:12:nojitter", kernel="count", pitch_mm=4e-3, diffraction="none", size=31)
    coarse = compute_psfs(model.lens, model.system, rel, PsfSettings(**kw)).psf
    fine = compute_psfs(model.lens, model.system, rel, PsfSettings(**kw, oversample=o)).psf
    assert fine.shape == coarse.shape == (3, 3, 31, 31)
    assert torch.allclose(fine, coarse, rtol=0, atol=1e-14)
    assert float(coarse.amax()) < 0.9  # a real spread over several bins, not a trivial delta


def test_even_fine_grid_puts_a_ray_in_the_hand_computed_bin() -> None:
    """Pitch 1, 4 fine bins: edges at −2, −1, 0, 1, 2 (centre on the corner between bins 1 and 2)."""
    xy = torch.tensor([[[-1.5, 0.5], [0.25, -0.75], [1.9, 1.1]]], dtype=F64)
    grid = deposit(xy, torch.ones(1, 3, dtype=torch.bool), torch.zeros(1, 2, dtype=F64), pitch=1.0, size=4,
                   kernel="count", allow_even=True)
    want = torch.zeros(1, 4, 4, dtype=F64)
    for x_bin, y_bin in ((0, 2), (2, 1), (3, 3)):  # floor(x + 2), floor(y + 2)
        want[0, y_bin, x_bin] += 1 / 3
    assert torch.equal(grid, want)
    with pytest.raises(Exception, match="odd"):  # without the opt-in, an even grid is still refused
        deposit(xy, torch.ones(1, 3, dtype=torch.bool), torch.zeros(1, 2, dtype=F64), pitch=1.0, size=4)


@pytest.mark.parametrize("diffraction", ["none", "heuristic"])
def test_even_oversampled_on_axis_psf_is_centred(oval, diffraction: str) -> None:  # noqa: ANN001
    """The Cartesian oval's axial image is a point (tests.helpers.oval_model): with a triangular KDE and
    o = 2 the point falls on the corner of four fine bins of the centre coarse bin, so the geometric PSF is
    all in the centre bin; with diffraction it is a centred Airy pattern (symmetric under both flips)."""
    st = compute_psfs(oval.lens, oval.system, torch.tensor([0.0], dtype=F64),
                      PsfSettings(sampling="rings:16:nojitter", pitch_mm=2e-3, size=15, diffraction=diffraction,
                                  oversample=2))
    psf = st.psf[0, 0]
    assert psf.shape == (15, 15) and abs(float(psf.sum()) - 1) < 1e-12
    if diffraction == "none":
        assert float(psf[7, 7]) == pytest.approx(1.0, abs=1e-9)
    else:
        assert torch.allclose(psf, psf.flip(-1), atol=1e-12) and torch.allclose(psf, psf.flip(-2), atol=1e-12)
        assert int(psf.argmax()) == 7 * 15 + 7
