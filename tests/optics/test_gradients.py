"""Gradients of the trace: autograd (reverse and forward mode) against finite differences.

The lenses are written here as TOML strings (independent of the example specs in ``specs/``): a
spherical triplet with catalog glasses, a conic + even-asphere singlet in a model glass (Newton
intersection), a singlet with a diffractive surface on a spherical base, and a hybrid triplet that
has all of these with the stop inside (chief-ray aiming through the Newton and diffractive paths).

Every radius (through its curvature c = 1/R), thickness, conic, asphere and phase coefficient and
the glass variables nd, vd of every glass are differentiated; the glasses enter as Hartmann model
glasses (``hartmann_index``) that replace the index rows of the ``Lens``.

Finite differences (float64) use the fourth-order central stencil
``f'(x) ≈ [f(x−2h) − 8 f(x−h) + 8 f(x+h) − f(x+2h)] / (12 h)``, truncation error O(h⁴), with a step
per variable ``h = step · scale``: scale = |value| (nd − 1 for nd; for asphere coefficients at least
the value that moves the sag by 1 µm at the pupil radius). Step 1e-3 for the TRA residuals (nearly
linear in the variables; measured agreement ≤ 3e-10 of each Jacobian column's largest entry) and
1e-4 for the RMS spot radius (a norm of those residuals, which curves faster: at 1e-3 the truncation
error reaches 2e-6, at 1e-4 the measured agreement is ≤ 2.4e-10, below that rounding, ~eps · |image
coordinates| / h, takes over). Tolerance: 1e-8 relative, 30× above what is measured; a dropped or
wrong derivative term would have to be smaller than 1e-8 of the gradient to go unnoticed.
"""

from __future__ import annotations

import dataclasses
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest
import torch
from torch import Tensor

from lensopt.analysis.spot import spot_stats
from lensopt.materials import Air, hartmann_index
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.lens import Lens
from lensopt.optics.sampling import pupil_rings
from lensopt.spec import Model, build, parse_spec

D = torch.float64
FD_STEP_TRA = 1e-3
FD_STEP_SPOT = 1e-4
FD_RTOL = 1e-8

SPHERICAL = """
name = "spherical triplet"
[system]
aperture = { epd = 8.0 }
field = { hfov_deg = 12.0, relative = [0.0, 1.0] }
[spectrum]
wavelengths_nm = [486.1, 587.6, 656.3]
weights = [1.0, 2.0, 1.0]
reference_nm = 587.6
[[surfaces]]
type = "sphere"
radius = 21.0
thickness = 3.0
material = "N-SK16"
[[surfaces]]
type = "sphere"
radius = -160.0
thickness = 5.0
[[surfaces]]
type = "sphere"
radius = -20.0
thickness = 1.0
material = "F2"
stop = true
[[surfaces]]
type = "sphere"
radius = 19.0
thickness = 4.5
[[surfaces]]
type = "sphere"
radius = 80.0
thickness = 3.0
material = "N-SK16"
[[surfaces]]
type = "sphere"
radius = -18.0
thickness = 41.0
"""

ASPHERIC = """
name = "conic + asphere singlet, model glass"
[system]
aperture = { epd = 10.0 }
field = { hfov_deg = 5.0, relative = [0.0, 1.0] }
[spectrum]
wavelengths_nm = [486.1, 587.6, 656.3]
reference_nm = 587.6
[[surfaces]]
type = "conic"
radius = 30.0
conic = -0.6
thickness = 5.0
material = { nd = 1.583, vd = 46.5 }
[[surfaces]]
type = "asphere"
radius = -60.0
conic = 2.0
coefficients = { 4 = 2.0e-5, 6 = -1.5e-7, 8 = 3.0e-10 }
thickness = 33.0
stop = true
"""

DIFFRACTIVE = """
name = "diffractive singlet"
[system]
aperture = { epd = 8.0 }
field = { hfov_deg = 6.0, relative = [0.0, 1.0] }
[spectrum]
wavelengths_nm = [486.1, 587.6, 656.3]
reference_nm = 587.6
[[surfaces]]
type = "sphere"
radius = 40.0
thickness = 4.0
material = "N-BK7"
[[surfaces]]
type = "diffractive"
base = { type = "sphere", radius = -120.0 }
phase = { 2 = -30.0, 4 = 0.05 }
design_wavelength_nm = 587.6
thickness = 43.0
stop = true
"""

HYBRID = Path(__file__).resolve().parents[1] / "data" / "hybrid_triplet.toml"


def hybrid_chief_full_field() -> Model:
    """The shared hybrid test lens at full field only, chief-ray aimed."""
    data = tomllib.loads(HYBRID.read_text())
    data["system"]["field"]["relative"] = [1.0]
    data["system"]["aim"] = "chief"
    return build(parse_spec(data), dtype=D)


def load(text: str) -> Model:
    return build(parse_spec(tomllib.loads(text)), dtype=D)


@dataclass(frozen=True)
class Variables:
    """A flat θ of every variable of a lens and the pure map θ → Lens (functional, vmap-safe)."""

    names: tuple[str, ...]
    theta0: Tensor
    scale: Tensor
    assemble: Callable[[Tensor], Lens]


def variables(model: Model) -> Variables:
    lens = model.lens
    assert model.system.epd is not None
    rho = model.system.epd / 2  # mm, the ray heights the coefficients act at
    names: list[str] = []
    values: list[float] = []
    scales: list[float] = []
    # kind -> [(column in θ, *index into the Lens tensor)]
    maps: dict[str, list[tuple[int, ...]]] = {k: [] for k in ("curvature", "thickness", "conic", "asphere", "phase")}

    def add(kind: str, where: tuple[int, ...], value: float, scale: float) -> None:
        maps[kind].append((len(names), *where))
        names.append(f"{kind}{list(where)}")
        values.append(value)
        scales.append(scale)

    for s, shape in enumerate(lens.shapes):
        if shape.kind != "plane":
            add("curvature", (s,), float(lens.curvature[s]), abs(float(lens.curvature[s])))
        add("thickness", (s,), float(lens.thickness[s]), abs(float(lens.thickness[s])))
        if shape.kind in ("conic", "asphere"):
            add("conic", (s,), float(lens.conic[s]), max(abs(float(lens.conic[s])), 0.1))
        if shape.kind == "asphere":
            for j, a in enumerate(lens.asphere[s].tolist()):
                if a != 0.0:  # floor: the coefficient that moves the sag at the pupil radius by 1 µm
                    add("asphere", (s, j), a, max(abs(a), 1e-3 / rho ** (2 * j + 4)))
        if shape.diffractive:
            for j, p in enumerate(lens.phase[s].tolist()):
                if p != 0.0:
                    add("phase", (s, j), p, abs(p))
    glass_rows = [m for m, mat in enumerate(model.media) if not isinstance(mat, Air)]
    first_glass = len(names)
    for m in glass_rows:
        nd, vd = model.media[m].nd, model.media[m].vd
        names += [f"nd[{m}]", f"vd[{m}]"]
        values += [nd, vd]
        scales += [nd - 1.0, vd]
    theta0 = torch.tensor(values, dtype=D)
    n_theta = len(values)

    # Fixed 0/1 selection matrices: entry = P @ θ exactly (one 1 per selected row).
    selections = []
    for kind, entries in maps.items():
        base = getattr(lens, kind)
        sel = torch.zeros(base.numel(), n_theta, dtype=D)
        mask = torch.zeros(base.numel(), dtype=torch.bool)
        for column, *where in entries:
            flat = sum(i * st for i, st in zip(where, base.stride(), strict=True))
            sel[flat, column] = 1.0
            mask[flat] = True
        selections.append((kind, base, sel, mask.view(base.shape)))

    def assemble(theta: Tensor) -> Lens:
        fields = {kind: torch.where(mask, (sel @ theta).view(base.shape), base)
                  for kind, base, sel, mask in selections}
        rows = list(lens.index.unbind(0))
        for g, m in enumerate(glass_rows):
            nd, vd = theta[first_glass + 2 * g], theta[first_glass + 2 * g + 1]
            rows[m] = hartmann_index(nd, vd, 0.0, lens.wavelength_um)
        return dataclasses.replace(lens, index=torch.stack(rows), **fields)

    return Variables(tuple(names), theta0, torch.tensor(scales, dtype=D), assemble)


def central_difference(f: Callable[[Tensor], Tensor], theta: Tensor, i: int, h: float) -> Tensor:
    """Fourth-order central difference of ``f`` along coordinate ``i``."""

    def at(k: int) -> Tensor:
        x = theta.clone()
        x[i] += k * h
        return f(x)

    return (at(-2) - 8 * at(-1) + 8 * at(1) - at(2)) / (12 * h)


def spot_radius_fn(model: Model, var: Variables, field: int, aim: str = "none") -> Callable[[Tensor], Tensor]:
    pupil = pupil_rings(6, jitter=True, seed=1, dtype=D)

    def f(theta: Tensor) -> Tensor:
        bundle = trace_bundle(var.assemble(theta), model.system, pupil, half_pupil=True, aim=aim)
        return spot_stats(bundle, model.system.wavelength_weights).rms_radius[field]

    return f


def tra_fn(model: Model, var: Variables, aim: str) -> Callable[[Tensor], Tensor]:
    """θ → the full TRA residual vector: image (x, y) of every ray minus its field's centroid (masked)."""
    pupil = pupil_rings(3, jitter=True, seed=1, dtype=D)

    def f(theta: Tensor) -> Tensor:
        bundle = trace_bundle(var.assemble(theta), model.system, pupil, half_pupil=True, aim=aim)
        stats = spot_stats(bundle, model.system.wavelength_weights)
        xy = bundle.result.pos[..., :2]
        valid = bundle.result.valid.unsqueeze(-1)
        return torch.where(valid, xy - stats.centroid[:, None, None, :], 0.0).reshape(-1)

    return f


LENSES = {"spherical": SPHERICAL, "aspheric": ASPHERIC, "diffractive": DIFFRACTIVE}


@pytest.mark.parametrize("name", list(LENSES))
def test_spot_radius_gradient_equals_finite_differences(name: str) -> None:
    model = load(LENSES[name])
    var = variables(model)
    f = spot_radius_fn(model, var, field=1)
    theta = var.theta0.clone().requires_grad_(True)
    value = f(theta)
    assert bool(model.lens.curvature.isfinite().all()) and 1e-3 < float(value) < 1.0  # a real, blurred spot
    (grad,) = torch.autograd.grad(value, theta)
    with torch.no_grad():
        for i, label in enumerate(var.names):
            fd = central_difference(f, var.theta0, i, FD_STEP_SPOT * float(var.scale[i]))
            # Relative to the gradient, with a floor at 1e-8 of the spot radius per unit of scale
            # (derivatives that are nearly zero for a variable are compared in absolute terms).
            tol = FD_RTOL * max(abs(float(grad[i])), float(value) / float(var.scale[i]))
            assert abs(float(grad[i]) - float(fd)) <= tol, (label, float(grad[i]), float(fd))
    kinds = {n.split("[")[0] for n in var.names}
    expected = {"spherical": {"curvature", "thickness", "nd", "vd"},
                "aspheric": {"curvature", "thickness", "conic", "asphere", "nd", "vd"},
                "diffractive": {"curvature", "thickness", "phase", "nd", "vd"}}[name]
    assert kinds == expected


@pytest.mark.parametrize("name", list(LENSES))
def test_tra_jacobian_forward_reverse_and_finite_differences(name: str) -> None:
    model = load(LENSES[name])
    var = variables(model)
    f = tra_fn(model, var, aim="none")
    jac_fwd = torch.func.jacfwd(f)(var.theta0)
    jac_rev = torch.func.jacrev(f)(var.theta0)
    assert jac_fwd.shape == (2 * 3 * 9 * 2, len(var.names))
    assert bool(jac_fwd.isfinite().all())
    torch.testing.assert_close(jac_fwd, jac_rev, rtol=1e-12, atol=1e-12 * float(jac_fwd.abs().max()))
    with torch.no_grad():
        for i, label in enumerate(var.names):
            fd = central_difference(f, var.theta0, i, FD_STEP_TRA * float(var.scale[i]))
            col = jac_fwd[:, i]
            err = float((fd - col).abs().max())
            assert err <= FD_RTOL * float(col.abs().max()), (label, err, float(col.abs().max()))


def test_tra_jacobian_through_chief_aiming_newton_and_diffractive_paths() -> None:
    model = hybrid_chief_full_field()
    assert model.system.aim == "chief"
    shapes = model.lens.shapes
    assert shapes[0].kind == "asphere" and shapes[4].diffractive and model.lens.stop == 2
    var = variables(model)
    f = tra_fn(model, var, aim="chief")
    jac_fwd = torch.func.jacfwd(f)(var.theta0)
    jac_rev = torch.func.jacrev(f)(var.theta0)
    assert bool(jac_fwd.isfinite().all())
    torch.testing.assert_close(jac_fwd, jac_rev, rtol=1e-12, atol=1e-12 * float(jac_fwd.abs().max()))
    # Finite differences along a random direction v in scaled variables, which checks every column at
    # once (one chief-aimed trace costs ~1 s here, too slow for column-by-column differences). Second-
    # order central difference with step 1e-5: truncation ~1e-10 relative, measured 1.3e-10.
    v = torch.randn(len(var.names), generator=torch.Generator().manual_seed(0), dtype=D) * var.scale
    h = 1e-5
    with torch.no_grad():
        fd = (f(var.theta0 + h * v) - f(var.theta0 - h * v)) / (2 * h)
    jv = jac_fwd @ v
    assert float((fd - jv).abs().max()) <= FD_RTOL * float(jv.abs().max())
