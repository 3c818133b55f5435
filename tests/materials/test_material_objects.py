"""Runtime material objects: Air, CatalogGlass, ModelGlass, material_from_name, wavelength checks."""

from __future__ import annotations

import math

import pytest
import torch

from lensopt.errors import MaterialError
from lensopt.materials import (
    HARTMANN_RANGE_UM,
    LINE_C_UM,
    LINE_D_UM,
    LINE_F_UM,
    Air,
    CatalogGlass,
    Material,
    ModelGlass,
    find_glass,
    hartmann_index,
    material_from_name,
)

F64 = torch.float64
DTYPES = [torch.float32, torch.float64]


def test_air_is_exactly_one() -> None:
    air = material_from_name(" AIR ")
    assert isinstance(air, Air) and isinstance(air, Material) and air == Air()
    wl = torch.rand(3, 4, dtype=F64) + 0.4
    n = air.index(wl)
    assert n.shape == (3, 4) and n.dtype == F64 and bool((n == 1.0).all())
    assert air.nd == 1.0 and math.isinf(air.vd)
    air.check_wavelengths([0.2, 5.0], path="surfaces[0].material")


@pytest.mark.parametrize("dtype", DTYPES)
def test_index_follows_input_dtype_and_shape(dtype: torch.dtype) -> None:
    wl = torch.full((2, 5), 0.55, dtype=dtype)
    for name in ["air", "N-BK7", "SK16", "S-LAH79", "BSC7", "H-K9L", "K-BK7", "OKP1"]:
        n = material_from_name(name).index(wl)
        assert n.dtype == dtype and n.shape == (2, 5) and n.device == wl.device, name
    n = ModelGlass(1.6, 40.0).index(wl)
    assert n.dtype == dtype and n.shape == (2, 5)


def test_catalog_glass_reproduces_nd_vd() -> None:
    glass = material_from_name("N-SK16")
    assert isinstance(glass, CatalogGlass) and glass.label == "N-SK16 (schott)"
    assert (glass.name, glass.nd, glass.vd) == ("N-SK16", 1.62041, 60.32)  # Schott catalog
    n_d, n_f, n_c = glass.index(torch.tensor([LINE_D_UM, LINE_F_UM, LINE_C_UM], dtype=F64)).tolist()
    assert abs(n_d - 1.62041) < 1e-5 and abs((n_d - 1) / (n_f - n_c) - 60.32) < 0.01
    assert glass.valid_range_um == find_glass("N-SK16").range_um


def test_catalog_glass_is_differentiable_in_wavelength() -> None:
    glass = material_from_name("F2")
    wl = torch.tensor([0.5, 0.6], dtype=F64, requires_grad=True)
    assert torch.autograd.gradcheck(glass.index, (wl,))


def test_model_glass_is_hartmann() -> None:
    m = ModelGlass(nd=1.62, vd=60.3, dpgf=0.002, name="crown")
    assert m.label == "crown (Hartmann model)" and m.valid_range_um == HARTMANN_RANGE_UM
    wl = torch.linspace(0.4, 0.9, 11, dtype=F64)
    expected = hartmann_index(torch.tensor(1.62, dtype=F64), torch.tensor(60.3, dtype=F64), 0.002, wl)
    torch.testing.assert_close(m.index(wl), expected, rtol=0, atol=1e-14)
    assert abs(m.index(torch.tensor(LINE_D_UM, dtype=F64)).item() - 1.62) < 1e-14
    assert ModelGlass(1.62, 60.3).name == "model(nd=1.62, vd=60.3, dpgf=0)"
    assert m.hartmann_abc[1] < HARTMANN_RANGE_UM[0]


@pytest.mark.parametrize(
    ("kwargs", "path"),
    [
        ({"nd": 1.0, "vd": 50.0}, "nd"),
        ({"nd": 3.0, "vd": 50.0}, "nd"),
        ({"nd": float("nan"), "vd": 50.0}, "nd"),
        ({"nd": 1.5, "vd": 0.0}, "vd"),
        ({"nd": 1.5, "vd": 9.0}, "vd"),
        ({"nd": 1.5, "vd": 150.0}, "vd"),
        ({"nd": 1.5, "vd": 50.0, "dpgf": 0.2}, "dpgf"),
        ({"nd": "1.5", "vd": 50.0}, "nd"),
    ],
)
def test_model_glass_validation(kwargs: dict[str, object], path: str) -> None:
    with pytest.raises(MaterialError) as info:
        ModelGlass(**kwargs)  # type: ignore[arg-type]
    assert info.value.path == path and "model glass" in str(info.value)
    rerooted = info.value.at("surfaces[1].material")
    assert str(rerooted).startswith(f"surfaces[1].material.{path}: model glass {path} must be")


def test_plastics_are_model_glasses() -> None:
    okp1 = material_from_name("okp1")
    assert okp1 == ModelGlass(nd=1.642, vd=22.4, dpgf=0.0, name="OKP1")  # seed Table S10
    assert material_from_name("plastics:EP8000").nd == 1.661


def test_wavelength_range_errors() -> None:
    bk7 = material_from_name("N-BK7")
    bk7.check_wavelengths([0.3, 0.55, 2.5], path="surfaces[2].material")
    with pytest.raises(MaterialError) as info:
        bk7.check_wavelengths([0.55, 0.25], path="surfaces[2].material")
    assert str(info.value) == (
        "surfaces[2].material: wavelength 0.25 µm is outside the valid range 0.3–2.5 µm of N-BK7 (schott)"
    )
    with pytest.raises(MaterialError, match="wavelength 1.2 µm is outside the valid range 0.38–1 µm of OKP1"):
        material_from_name("OKP1").check_wavelengths([1.2], path="surfaces[4].material")
    with pytest.raises(MaterialError, match="wavelength nan µm"):
        ModelGlass(1.5, 60.0).check_wavelengths([float("nan")], path="x")


def test_unknown_material_and_bad_wavelength_tensor() -> None:
    with pytest.raises(MaterialError, match="unknown glass 'N-BK8'; close matches: N-BK7"):
        material_from_name("N-BK8")
    with pytest.raises(MaterialError, match="floating-point tensor"):
        material_from_name("N-BK7").index(torch.tensor([1, 2]))


def test_materials_are_frozen_and_hashable() -> None:
    m = material_from_name("N-BK7")
    with pytest.raises(AttributeError):
        m.nd = 1.7  # type: ignore[misc]
    assert len({m, material_from_name("n-bk7"), Air(), ModelGlass(1.5, 60.0)}) == 3
