"""Hartmann dispersion model of seed S1.1 (eqs. S3–S7): closed forms, gradients, pole, dtypes."""

from __future__ import annotations

import itertools

import pytest
import torch

from lensopt.materials import (
    HARTMANN_RANGE_UM,
    LINE_C_UM,
    LINE_D_UM,
    LINE_F_UM,
    LINE_G_UM,
    CatalogGlass,
    hartmann_coefficients,
    hartmann_index,
    list_glasses,
)
from lensopt.materials.material import MODEL_DPGF_RANGE, MODEL_VD_RANGE

F64 = torch.float64
JIT_WARNING = "ignore:`torch.jit.script` is deprecated:DeprecationWarning"  # raised inside torch.func


def _glass_variables(n: int = 64, seed: int = 0) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    nd = 1.4 + 0.6 * torch.rand(n, generator=g, dtype=F64)
    vd = 15.0 + 80.0 * torch.rand(n, generator=g, dtype=F64)
    dpgf = -0.03 + 0.08 * torch.rand(n, generator=g, dtype=F64)
    return nd, vd, dpgf


def _lines(nd: torch.Tensor, vd: torch.Tensor, dpgf: torch.Tensor) -> torch.Tensor:
    wl = torch.tensor([LINE_D_UM, LINE_F_UM, LINE_C_UM, LINE_G_UM], dtype=F64)
    return hartmann_index(nd[:, None], vd[:, None], dpgf[:, None], wl)


def test_reproduces_nd_vd_pgf() -> None:
    # Oracle: the defining equations S1, S2, S3 that the coefficients S5–S7 are solved from.
    nd, vd, dpgf = _glass_variables()
    n = _lines(nd, vd, dpgf)
    n_d, n_f, n_c, n_g = n.unbind(-1)
    torch.testing.assert_close(n_d, nd, rtol=0, atol=1e-12)
    torch.testing.assert_close((n_d - 1) / (n_f - n_c), vd, rtol=1e-12, atol=0)
    torch.testing.assert_close((n_g - n_f) / (n_f - n_c), 0.6438 - 0.001682 * vd + dpgf, rtol=0, atol=1e-12)


def test_normal_dispersion_order() -> None:
    n = _lines(*_glass_variables())
    assert (n[:, 3] > n[:, 1]).all() and (n[:, 1] > n[:, 0]).all() and (n[:, 0] > n[:, 2]).all()


def test_fraunhofer_line_constants() -> None:
    # Oracle: the Fraunhofer lines as tabulated by the glass vendors (nm).
    assert (LINE_D_UM, LINE_F_UM, LINE_C_UM, LINE_G_UM) == (0.5875618, 0.4861327, 0.6562725, 0.4358343)


def test_gradients_match_central_differences() -> None:
    nd, vd, dpgf = (t[:8].clone().requires_grad_(True) for t in _glass_variables())
    wl = torch.tensor(0.45, dtype=F64)
    grads = torch.autograd.grad(hartmann_index(nd, vd, dpgf, wl).sum(), (nd, vd, dpgf))
    base = [nd.detach(), vd.detach(), dpgf.detach()]
    for i, (h, grad) in enumerate(zip((1e-6, 1e-4, 1e-6), grads, strict=True)):
        plus, minus = list(base), list(base)
        plus[i] = base[i] + h
        minus[i] = base[i] - h
        fd = (hartmann_index(*plus, wl) - hartmann_index(*minus, wl)) / (2 * h)
        torch.testing.assert_close(grad, fd, rtol=1e-7, atol=1e-10)


def test_gradcheck() -> None:
    nd, vd, dpgf = (t[:4].clone().requires_grad_(True) for t in _glass_variables())
    wl = torch.tensor([0.42, 0.55, 0.7, 0.95], dtype=F64, requires_grad=True)
    assert torch.autograd.gradcheck(hartmann_index, (nd, vd, dpgf, wl))
    assert torch.autograd.gradgradcheck(hartmann_index, (nd, vd, dpgf, wl))


def test_index_at_d_line_depends_only_on_nd() -> None:
    # Invariant: n(λd) = nd for every vd, dpgf, so ∂n(λd)/∂nd = 1 and ∂n(λd)/∂(vd, dpgf) = 0.
    x = torch.tensor([1.62, 60.3, 0.004], dtype=F64, requires_grad=True)
    (grad,) = torch.autograd.grad(hartmann_index(x[0], x[1], x[2], torch.tensor(LINE_D_UM, dtype=F64)), x)
    torch.testing.assert_close(grad, torch.tensor([1.0, 0.0, 0.0], dtype=F64), rtol=0, atol=1e-12)


@pytest.mark.filterwarnings(JIT_WARNING)
def test_jacfwd_matches_reverse_mode() -> None:
    wl = torch.tensor([0.45, 0.55, 0.65], dtype=F64)
    x = torch.tensor([1.7, 40.0, 0.01], dtype=F64)

    def f(v: torch.Tensor) -> torch.Tensor:
        return hartmann_index(v[0], v[1], v[2], wl)

    jf = torch.func.jacfwd(f)(x)
    jr = torch.autograd.functional.jacobian(f, x)
    assert jf.shape == (3, 3)
    torch.testing.assert_close(jf, jr, rtol=1e-12, atol=1e-14)
    batched = torch.func.vmap(torch.func.jacfwd(f))(torch.stack([x, x + 0.01]))
    assert batched.shape == (2, 3, 3)


def test_pole_stays_below_valid_range() -> None:
    # The documented ModelGlass range: B <= 0.29 µm over the accepted (vd, dpgf) box, and B
    # increases with PgF, so the extremes sit at the box corners.
    corners = torch.tensor(list(itertools.product(MODEL_VD_RANGE, MODEL_DPGF_RANGE)), dtype=F64)
    dense = torch.cartesian_prod(
        torch.linspace(*MODEL_VD_RANGE, 23, dtype=F64), torch.linspace(*MODEL_DPGF_RANGE, 21, dtype=F64)
    )
    for vd_dpgf in (corners, dense):
        _, b, _ = hartmann_coefficients(torch.full_like(vd_dpgf[:, 0], 1.6), vd_dpgf[:, 0], vd_dpgf[:, 1])
        assert b.max() < 0.29 <= HARTMANN_RANGE_UM[0] - 0.09


def test_close_to_real_glasses_in_valid_range() -> None:
    # Invariant behind the documented accuracy: given a real glass's nd, vd, dPgF, Hartmann stays
    # within 1.5e-3 of its catalog formula over HARTMANN_RANGE_UM (Schott preferred glasses).
    wl = torch.linspace(*HARTMANN_RANGE_UM, 32, dtype=F64)
    worst = 0.0
    for glass in list_glasses("schott"):
        if glass.status != "preferred" or glass.dpgf is None:
            continue
        nd, vd = torch.tensor(glass.nd, dtype=F64), torch.tensor(glass.vd, dtype=F64)
        err = (hartmann_index(nd, vd, glass.dpgf, wl) - CatalogGlass(glass).index(wl)).abs().max()
        worst = max(worst, float(err))
    assert worst < 1.5e-3


def test_float32_in_float32_out_and_broadcast() -> None:
    nd = torch.tensor([1.5, 1.6], dtype=torch.float32)
    vd = torch.tensor([[60.0], [40.0], [30.0]], dtype=torch.float32)
    out = hartmann_index(nd, vd, 0.0, torch.tensor(0.5, dtype=torch.float32))
    assert out.dtype == torch.float32 and out.shape == (3, 2)
    ref = hartmann_index(nd.double(), vd.double(), 0.0, torch.tensor(0.5, dtype=F64))
    torch.testing.assert_close(out.double(), ref, rtol=0, atol=1e-5)
    a, b, c = hartmann_coefficients(nd, vd, 0.0)
    assert a.dtype == b.dtype == c.dtype == torch.float32
