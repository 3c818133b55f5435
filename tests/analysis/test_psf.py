"""Geometric PSFs (S1.4.1–S1.4.2): ray counting, equal-energy KDE, normalization, gradients."""

from __future__ import annotations

import pytest
import torch

from lensopt.analysis.psf import bin_down, kde, kernel_1d, mirror_half_pupil, ray_count
from lensopt.analysis.psf_stack import PsfSettings, compute_psfs
from lensopt.errors import LensoptError

F64 = torch.float64


@pytest.mark.parametrize("kernel", ["triangular", "cosine"])
@pytest.mark.parametrize("support", [2, 4, 6])
def test_kde_each_ray_deposits_exactly_its_energy(kernel: str, support: int) -> None:
    # S1.4.2: with support an even multiple of the bin, the kernel sampled at bin centres is a partition of
    # unity, so a ray well inside the grid leaves nothing to redistribute: no uniform floor (min = 0) and sum 1.
    gen = torch.Generator().manual_seed(1)
    xy = (torch.rand(500, 1, 2, generator=gen, dtype=F64) - 0.5) * 6e-3  # sub-bin positions all over
    center = torch.zeros(500, 2, dtype=F64)
    psf = kde(xy, torch.ones(500, 1, dtype=torch.bool), center, pitch=1e-3, size=21, kernel=kernel, support=support)
    assert torch.allclose(psf.sum((-1, -2)), torch.ones(500, dtype=F64), atol=1e-13)
    # No missing energy was spread: the emptiest bins hold only rounding (a kernel that does not sum to 1
    # would leave a floor of ~1e-3 here).
    assert float(psf.amin((-1, -2)).abs().max()) < 1e-15


def test_triangular_kde_keeps_the_ray_position_as_centroid() -> None:
    # Hand derivation: σ = 2 bins triangular KDE is bilinear splatting, whose first moment is the ray position.
    xy = torch.tensor([[[0.37e-3, -1.81e-3]]], dtype=F64)
    psf = kde(xy, torch.ones(1, 1, dtype=torch.bool), torch.zeros(1, 2, dtype=F64), pitch=1e-3, size=9)[0]
    c = torch.arange(9, dtype=F64) - 4
    assert float((psf.sum(0) * c).sum()) == pytest.approx(0.37, abs=1e-12)
    assert float((psf.sum(1) * c).sum()) == pytest.approx(-1.81, abs=1e-12)


def test_kernels_are_antisymmetric_about_a_quarter_support() -> None:
    t = torch.linspace(0, 1, 101, dtype=F64)
    for kind in ("triangular", "cosine"):
        assert torch.allclose(kernel_1d(t, kind) + kernel_1d(1 - t, kind), torch.ones_like(t), atol=1e-15)


def test_ray_count_bins_and_redistributes_failed_and_missing_rays() -> None:
    # 4 rays: one at bin (row 2, col 3) of a 5×5 grid, one failed, one outside the grid, one at the centre.
    xy = torch.tensor([[[1.2e-3, 0.1e-3], [0.0, 0.0], [9e-3, 0.0], [0.2e-3, -0.3e-3]]], dtype=F64)
    valid = torch.tensor([[True, False, True, True]])
    psf = ray_count(xy, valid, torch.zeros(1, 2, dtype=F64), pitch=1e-3, size=5)[0]
    floor = 0.5 / 25  # two of four rays' energy spread over 25 bins (S1.4.1)
    assert float(psf[2, 3]) == pytest.approx(0.25 + floor, abs=1e-15)
    assert float(psf[2, 2]) == pytest.approx(0.25 + floor, abs=1e-15)
    assert float(psf[0, 0]) == pytest.approx(floor, abs=1e-15)
    assert float(psf.sum()) == pytest.approx(1.0, abs=1e-15)


def test_kde_gradient_matches_finite_differences_and_is_zero_for_failed_rays() -> None:
    gen = torch.Generator().manual_seed(3)
    xy = ((torch.rand(1, 6, 2, generator=gen, dtype=F64) - 0.5) * 4e-3).requires_grad_(True)
    valid = torch.tensor([[True, True, True, False, True, True]])
    weights = torch.rand(11, 11, generator=gen, dtype=F64)

    def f(p: torch.Tensor) -> torch.Tensor:
        return (kde(p, valid, torch.zeros(1, 2, dtype=F64), pitch=1e-3, size=11, kernel="cosine") * weights).sum()

    assert torch.autograd.gradcheck(f, (xy,), eps=1e-9, atol=1e-6)
    (g,) = torch.autograd.grad(f(xy), xy)
    assert torch.isfinite(g).all() and float(g[0, 3].abs().sum()) == 0.0


def test_mirror_half_pupil_and_bin_down() -> None:
    xy = torch.tensor([[[1.0, 2.0]]], dtype=F64)
    full, v = mirror_half_pupil(xy, torch.tensor([[True]]))
    assert full.tolist() == [[[1.0, 2.0], [-1.0, 2.0]]] and v.tolist() == [[True, True]]
    x = torch.rand(2, 6, 6, dtype=F64)
    assert torch.allclose(bin_down(x, 3).sum((-1, -2)), x.sum((-1, -2)))


@pytest.mark.parametrize("kernel", ["count", "triangular", "cosine"])
@pytest.mark.parametrize("diffraction", ["none", "heuristic", "incoherent"])
def test_cooke_triplet_psfs_sum_to_one(cooke, kernel: str, diffraction: str) -> None:
    model = cooke
    rel = torch.tensor([0.0, 1.0], dtype=F64)
    st = compute_psfs(model.lens, model.system, rel, PsfSettings(sampling="rings:8", kernel=kernel,
                                                                   pitch_mm=2e-3, diffraction=diffraction))
    assert st.psf.shape[:2] == (2, 3) and st.psf.shape[-1] % 2 == 1
    assert torch.allclose(st.psf.sum((-1, -2)), torch.ones(2, 3, dtype=F64), atol=1e-12)
    assert float(st.psf.min()) >= -1e-15


def test_psf_gradient_wrt_lens_is_finite_with_failing_rays(cooke) -> None:
    # Clip the stop so that some rays fail: the KDE PSF must stay differentiable with finite gradients.
    import dataclasses

    model = cooke
    lens = model.lens
    curv = lens.curvature.clone().requires_grad_(True)
    shapes = tuple(dataclasses.replace(s, clip=(i == 0)) for i, s in enumerate(lens.shapes))
    sd = lens.semi_diameter.clone()
    sd[0] = 4.6  # the full-field beam is wider than this on surface 1
    lens2 = dataclasses.replace(lens, curvature=curv, shapes=shapes, semi_diameter=sd)
    st = compute_psfs(lens2, model.system, torch.tensor([0.0, 1.0], dtype=F64),
                      PsfSettings(sampling="rings:6", pitch_mm=4e-3, size=15, diffraction="heuristic"))
    assert float(st.failed.max()) > 0
    loss = (st.psf[..., 7, 7]).sum()
    (g,) = torch.autograd.grad(loss, curv)
    assert torch.isfinite(g).all() and float(g.abs().sum()) > 0


def test_bad_settings_name_the_field() -> None:
    with pytest.raises(LensoptError, match="psf.kernel"):
        PsfSettings(kernel="gaussian")
    with pytest.raises(LensoptError, match="support"):
        kde(torch.zeros(1, 1, 2), torch.ones(1, 1, dtype=torch.bool), torch.zeros(1, 2), pitch=1.0, size=5, support=3)


def test_psf_gradient_wrt_curvature_matches_finite_differences(cooke) -> None:
    # The KDE path is differentiable in the lens: autograd against central differences (float64). The cosine
    # kernel is C¹ (the triangular one has kinks at bin centres, which central differences straddle once a
    # ray crosses one); diffraction is off so the check covers trace → KDE → centroid-centred grid.
    import dataclasses

    model = cooke
    lens, system = model.lens, model.system
    rel = torch.tensor([0.0, 1.0], dtype=F64)
    weights = torch.rand(2, 3, 15, 15, generator=torch.Generator().manual_seed(5), dtype=F64)
    settings = PsfSettings(sampling="rings:6", kernel="cosine", pitch_mm=4e-3, size=15, diffraction="none")

    def loss(c2: torch.Tensor) -> torch.Tensor:
        curv = torch.cat([lens.curvature[:2], c2.view(1), lens.curvature[3:]])
        st = compute_psfs(dataclasses.replace(lens, curvature=curv), system, rel, settings)
        return (st.psf * weights).sum()

    c2 = lens.curvature[2].clone().requires_grad_(True)
    (g,) = torch.autograd.grad(loss(c2), c2)
    with torch.no_grad():
        fd = [(loss(c2 + h) - loss(c2 - h)) / (2 * h) for h in (1e-7, 1e-8)]
    assert float(g) == pytest.approx(float(fd[0]), rel=1e-4)
    assert float(g) == pytest.approx(float(fd[1]), rel=1e-4)
