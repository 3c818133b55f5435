"""What the tests share (kornia's ``testing`` module is the model): paths of the shipped lenses, the
tolerance table per dtype, a closeness check that uses it, central differences and a float64
``gradcheck`` for derivative tests, and small test lenses and ray sets used by several test files.

Fixtures (the Cooke triplet in its three forms, the C-mount lens, the device) are in ``tests/conftest.py``;
plain values and functions are here, so that module-level constants and ``parametrize`` lists can use
them too. Import as ``from tests.helpers import ...`` (the repository root is on the test path).
"""

from __future__ import annotations

import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch
from torch import Tensor

ROOT = Path(__file__).resolve().parents[1]
SPECS = ROOT / "specs"
LENSES = ROOT / "lenses"
DATA = ROOT / "tests" / "data"
SHARED = ROOT.parent / "shared"

COOKE = SPECS / "cooke_triplet.toml"
"""The classic Cooke triplet (f = 50 mm, f/5, SK16/F2, a 4000 × 3000 sensor): the suite's default lens."""
COOKE_OPT = SPECS / "cooke_triplet_opt.toml"
"""The Cooke triplet with vary lists and an ``[optimize]`` section (the demo's optimization)."""
CMOUNT = LENSES / "cmount_4p.json"
"""The seed's C-mount lens (9 surfaces, aspheres, 12 wavelengths): the large case."""

# --------------------------------------------------------------------------- tolerances per dtype

TOLERANCES: dict[torch.dtype, tuple[float, float]] = {
    torch.float64: (1e-12, 1e-12),
    torch.float32: (1e-5, 1e-6),
    torch.float16: (1e-2, 1e-3),
}
"""(rtol, atol) of two computations of the same quantity that differ only by rounding (operation order,
fused kernels), per dtype: about 5·10³ ulps of float64, 80 of float32 (kornia's ``_get_precision``
table, tightened for the float64 design work here). A test with a physical tolerance says so instead."""


def tolerance(dtype: torch.dtype) -> tuple[float, float]:
    """(rtol, atol) of ``dtype`` from ``TOLERANCES``."""
    return TOLERANCES[dtype]


def assert_close(actual: Tensor, expected: Tensor, *, rtol: float | None = None, atol: float | None = None,
                 msg: str | None = None) -> None:
    """``torch.testing.assert_close`` with the dtype table's tolerances unless given (dtype: ``actual``'s)."""
    r, a = tolerance(actual.dtype)
    torch.testing.assert_close(actual, expected, rtol=r if rtol is None else rtol, atol=a if atol is None else atol,
                               msg=msg)


# ---------------------------------------------------------------------------------- derivatives


def central_difference(fn: Callable[[Tensor], Tensor], x: Tensor, *, step: float = 1e-6) -> Tensor:
    """(*out, N) Jacobian of ``fn`` at the flat ``x`` (N,) by central differences (float64; truncation
    error O(step²), rounding O(ε / step): step 1e-6 gives ~1e-10 relative on smooth functions)."""
    x = x.detach().to(torch.float64)
    cols = []
    for i in range(x.numel()):
        e = torch.zeros_like(x)
        e[i] = step
        cols.append((fn(x + e) - fn(x - e)) / (2 * step))
    return torch.stack(cols, -1)


def gradcheck(fn: Callable[..., Any], inputs: tuple[Tensor, ...], **kwargs: Any) -> bool:
    """``torch.autograd.gradcheck`` of ``fn`` in float64 (inputs cast and made to require grad), as
    kornia's ``BaseTester.gradcheck``; extra ``kwargs`` go to gradcheck (e.g. ``check_forward_ad=True``)."""
    ins = tuple(t.detach().to(torch.float64).requires_grad_(t.is_floating_point()) for t in inputs)
    return torch.autograd.gradcheck(fn, ins, **{"eps": 1e-6, "atol": 1e-8, "rtol": 1e-6, **kwargs})


# ----------------------------------------------------------------------------------- test lenses


def cooke_data() -> dict[str, Any]:
    """The Cooke triplet as fresh plain spec data (``COOKE`` parsed)."""
    return tomllib.loads(COOKE.read_text())


def cooke_optimize_data(**optimize: Any) -> dict[str, Any]:
    """The Cooke triplet with a small ``[optimize]`` section (rings:3 sampling, 10 steps, and ``optimize``):
    few rays, few variables, so that optimization tests stay fast."""
    data = cooke_data()
    data["optimize"] = {"sampling": "rings:3", "steps": 10, **optimize}
    return data


def small_problem_data() -> dict[str, Any]:
    """A small optimization problem on the Cooke triplet (6 variables, 2 fields, rings:3) whose constraint
    rows are active: ray failure, distortion ≤ 0.01 %, relative illumination ≥ 0.99 (its reference field
    is picked by index, which a captured graph cannot read out of a traced tensor)."""
    data = cooke_optimize_data(constraints={"ray_failure": {"penalty_mm": 2.0}, "distortion": {"max_percent": 0.01},
                                            "relative_illumination": {"min": 0.99}})
    for s in (0, 2, 4):
        data["surfaces"][s]["vary"] = ["radius", "thickness"]
    data["system"]["field"]["relative"] = [0.0, 1.0]
    return data


def oval_spec(*, wavelengths_nm: list[float] | None = None, epd: float = 10.0, hfov_deg: float = 0.01,
              pitch_um: float = 1.0, resolution: tuple[int, int] | None = None, vd: float = 60.0) -> dict[str, Any]:
    """A single refracting ellipsoid (Cartesian oval) with its far focus on the image surface, in glass:
    conic κ = −1/n² images an axial point at infinity without aberration (Descartes; e.g. Born & Wolf
    §4.2.3), so its geometric PSF is a Dirac delta on axis. R = 50 mm, n = 1.5: f' = n R/(n − 1) = 150 mm,
    NA = n sin u' ≈ EPD/(2 f'/n) = 0.05 for EPD 10 mm. (``oval_model`` puts κ and the image at the model
    glass's index.)"""
    n = 1.5
    sensor: dict[str, Any] = {"pixel_pitch_um": pitch_um}
    if resolution is not None:
        sensor["resolution"] = list(resolution)
    return {
        "name": "Cartesian oval",
        "system": {"aperture": {"epd": epd}, "field": {"hfov_deg": hfov_deg, "relative": [0.0, 1.0]}},
        "spectrum": {"wavelengths_nm": wavelengths_nm or [587.5618]},
        "sensor": sensor,
        "surfaces": [{"type": "conic", "radius": 50.0, "conic": -1.0 / n**2, "thickness": n * 50.0 / (n - 1.0),
                      "material": {"nd": n, "vd": vd}, "stop": True}],
    }


def oval_model(**kw: Any) -> Any:
    """``oval_spec(**kw)`` built, with κ = −1/n² and the image at n R/(n − 1) for the model glass's index n at
    the middle wavelength: on axis, the rays of that wavelength meet in a point."""
    import copy

    from lensopt.spec import build, parse_spec

    spec = oval_spec(**kw)
    model = build(parse_spec(copy.deepcopy(spec)))
    n = float(model.lens.index[1, model.lens.index.shape[1] // 2])
    spec["surfaces"][0]["conic"] = -1.0 / n**2
    spec["surfaces"][0]["thickness"] = n * 50.0 / (n - 1.0)
    return build(parse_spec(spec))


def imaging_oval(*, rgb: bool = False, **kw: Any) -> Any:
    """The oval as the imaging tests use it: a field so small (1e-4°) that every PSF stays within a pixel
    (30 µm, a 64 × 48 sensor unless ``kw`` says otherwise); ``rgb``: 480, 550 and 650 nm."""
    base = {"hfov_deg": 1e-4, "vd": 100.0, "pitch_um": 30.0, "resolution": (64, 48),
            "wavelengths_nm": [480.0, 550.0, 650.0] if rgb else None}
    return oval_model(**{**base, **kw})


MIXED: dict[str, Any] = {
    "name": "mixed",
    "system": {"aperture": {"epd": 12.0}, "field": {"hfov_deg": 10.0, "relative": [0.0, 1.0]}, "object": "infinity"},
    "spectrum": {"wavelengths_nm": [486.1, 587.6, 656.3], "reference_nm": 587.6},
    "surfaces": [
        {"type": "asphere", "radius": 15.0, "conic": -0.5, "coefficients": {4: -4e-4, 6: 2e-6}, "thickness": 4.0,
         "material": "N-BK7"},
        {"type": "sphere", "radius": -40.0, "thickness": 2.0, "stop": True},
        {"type": "conic", "radius": -20.0, "conic": -2.5, "thickness": 2.0, "material": "N-SF5",
         "semi_diameter": 8.0, "clip": True},
        {"type": "diffractive", "base": {"type": "plane"}, "phase": {2: -30.0, 4: 0.05},
         "design_wavelength_nm": 587.6, "thickness": 30.0},
    ],
}
"""One lens that takes every code path of the trace in a single compile: Newton on an even asphere,
closed-form sphere and hyperboloid (κ < −1), a clipping clear aperture, a diffractive surface, TIR at the
glass–air exits, rays that miss, and rays where Newton does not converge (with ``mixed_rays``)."""


def mixed_rays(n: int = 400) -> Any:
    """Rays for ``MIXED``: from z = −2 mm over a ±9 mm square at 0–60° in the meridional plane, random
    wavelengths (seeded)."""
    from lensopt.optics.trace import Rays

    g = torch.Generator().manual_seed(1)
    xy = (torch.rand(n, 2, generator=g, dtype=torch.float64) * 2 - 1) * 9.0
    ang = torch.deg2rad(torch.rand(n, generator=g, dtype=torch.float64) * 60.0)
    d = torch.stack([torch.zeros_like(ang), torch.sin(ang), torch.cos(ang)], -1)
    pos = torch.cat([xy, torch.full((n, 1), -2.0, dtype=torch.float64)], -1)
    return Rays(pos=pos, dir=d, wavelength=torch.randint(0, 3, (n,), generator=g))


def microscope_table_s12(spec: Any) -> tuple[Any, list[Any], list[Any]]:
    """A microscope lens spec against Table S12 on a dense sample (grid 31): (model, its glass surfaces,
    the checks), shared by the tests that hold the shipped microscope lenses."""
    from lensopt.analysis.requirements import check_requirements, table_s12
    from lensopt.spec import build

    model = build(spec)
    glass = [s for s in spec.surfaces if not s.is_air]
    names = [s.material if isinstance(s.material, str) else s.material.name for s in glass]
    checks = check_requirements(model.lens, model.system, table_s12(), glass_gaps=[not s.is_air for s in spec.surfaces],
                                materials=names, grid=31)
    return model, glass, checks
