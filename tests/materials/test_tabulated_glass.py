"""Tabulated glasses (CODE V private catalog entries): exact at the nodes, a cubic spline between."""

from __future__ import annotations

import pytest
import torch

from lensopt.errors import MaterialError, SpecError
from lensopt.materials import TabulatedGlass
from lensopt.spec import build, parse_spec
from tests.helpers import cooke_data


def _cubic(w: float) -> float:
    return 1.5 + 0.01 * w - 0.003 * w**2 + 0.0004 * w**3


def test_nodes_are_returned_exactly() -> None:
    wl = (0.45, 0.5, 0.55, 0.6, 0.65)
    n = (1.5312345678901234, 1.5255, 1.5211, 1.5178, 1.5151)
    glass = TabulatedGlass("T", wl, n)
    got = glass.index(torch.tensor(wl, dtype=torch.float64)).tolist()
    assert got == list(n)  # bitwise: the nodes are the data, not a fit
    got32 = glass.index(torch.tensor(wl, dtype=torch.float32))
    assert got32.dtype == torch.float32
    assert torch.equal(got32, torch.tensor(n, dtype=torch.float32))


def test_spline_reproduces_a_cubic_between_nodes() -> None:
    # Closed form: a not-a-knot cubic spline through samples of a cubic polynomial is that polynomial.
    wl = (0.4, 0.47, 0.55, 0.61, 0.7, 0.8)
    glass = TabulatedGlass("cubic", wl, tuple(_cubic(w) for w in wl))
    probe = torch.linspace(0.4, 0.8, 41, dtype=torch.float64)
    want = torch.tensor([_cubic(float(w)) for w in probe], dtype=torch.float64)
    assert torch.allclose(glass.index(probe), want, rtol=0, atol=1e-14)


def test_two_points_are_linear_and_one_is_constant() -> None:
    two = TabulatedGlass("two", (0.5, 0.6), (1.6, 1.58))
    assert float(two.index(torch.tensor(0.55, dtype=torch.float64))) == pytest.approx(1.59, abs=1e-15)
    one = TabulatedGlass("one", (0.55,), (1.7,))
    assert float(one.index(torch.tensor(0.55, dtype=torch.float64))) == 1.7


def test_nd_and_vd_from_the_table() -> None:
    wl = (0.4, 0.47, 0.55, 0.61, 0.7, 0.8)
    glass = TabulatedGlass("cubic", wl, tuple(_cubic(w) for w in wl))
    nd, nf, nc = (_cubic(w) for w in (0.5875618, 0.4861327, 0.6562725))
    assert glass.nd == pytest.approx(nd, abs=1e-14)
    assert glass.vd == pytest.approx((nd - 1) / (nf - nc), rel=1e-10)


@pytest.mark.parametrize(("wl", "n"), [((0.5, 0.5), (1.5, 1.5)), ((0.6, 0.5), (1.5, 1.6)), ((0.5,), (1.5, 1.6)),
                                        ((0.5, 0.6), (1.5, -1.0))])
def test_bad_tables_are_rejected(wl: tuple[float, ...], n: tuple[float, ...]) -> None:
    with pytest.raises(MaterialError):
        TabulatedGlass("bad", wl, n)


def _cooke_with(material: object) -> dict:
    data = cooke_data()
    data["surfaces"][0]["material"] = material
    return data


def test_a_spec_may_name_a_tabulated_glass() -> None:
    table = {"name": "E48", "wavelengths_nm": [450.0, 550.0, 650.0, 700.0], "index": [1.54, 1.531, 1.527, 1.525]}
    model = build(parse_spec(_cooke_with(table)))
    assert float(model.lens.index[1, 1]) == 1.531  # 550 nm is a node
    with pytest.raises(SpecError, match=r"surfaces\[0\]\.material: wavelength 0\.4 µm is outside"):
        data = _cooke_with(table)
        data["spectrum"] = {"wavelengths_nm": [400.0, 550.0], "reference_nm": 550.0}
        build(parse_spec(data))


def test_bad_tabulated_spec_names_the_field() -> None:
    table = {"name": "E48", "wavelengths_nm": [450.0, 550.0], "index": [1.54]}
    with pytest.raises(SpecError, match=r"surfaces\[0\]\.material\.index: needs one index per wavelength"):
        parse_spec(_cooke_with(table))
