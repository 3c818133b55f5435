"""Tolerance sensitivities against independent physics (issue 12, "Must show").

- A thickness change δ of gap s moves the paraxial image by ΔBFL = −δ n_s u_s² / (n' u'²) (the rear
  group's longitudinal magnification m² n'/n_s with m = n_s u_s / (n' u'), applied to an object
  displacement −δ; e.g. Welford, *Aberrations of Optical Systems*, §2.5). The marginal-ray slopes
  u_s, u' come from a y–nu trace written out here in numpy, independent of lensopt's paraxial module.
- A surface decenter moves the image centroid as optiland (0.6.3, its own coordinate systems) says,
  for the same rays: ≤ 1e-9 mm.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch

from lensopt.design.tolerance import tolerance_job
from lensopt.optics.paraxial import first_order
from lensopt.spec import build, load_spec
from lensopt.spec.tolerance import ToleranceSpec
from lensopt.tolerance.evaluate import evaluate
from lensopt.tolerance.model import params_lens

ROOT = Path(__file__).resolve().parents[2]


def _ynu_slopes(curv: list[float], thick: list[float], n: list[float], epd: float) -> list[float]:
    """Marginal-ray slopes u after every surface (object at infinity), by y' = y + t u, n'u' = n u − y φ."""
    y, nu = epd / 2, 0.0
    slopes = []
    for s, c in enumerate(curv):
        nu = nu - y * (n[s + 1] - n[s]) * c
        u = nu / n[s + 1]
        slopes.append(u)
        y = y + thick[s] * u
    return slopes


def _settings(**kw) -> ToleranceSpec:
    base = {"items": [{"kind": "thickness", "limit": 0.05, "surfaces": [0]}], "sampling": "rings:12",
            "compensator": "focus"}
    base.update(kw)
    return ToleranceSpec.model_validate(base)


@pytest.mark.parametrize("gap", [0, 1])
def test_thickness_moves_paraxial_focus_by_the_formula(gap: int) -> None:
    model = build(load_spec(ROOT / "specs" / "achromat_f10.toml"))
    lens, system = model.lens, model.system
    w = system.reference
    n = lens.index[:, w].tolist()
    slopes = _ynu_slopes(lens.curvature.tolist(), lens.thickness.tolist(), n, float(first_order(lens, system).epd))
    u_s, u_img = slopes[gap], slopes[-1]
    per_mm = -n[gap + 1] * u_s**2 / (n[-1] * u_img**2)  # ΔBFL / δ
    job = tolerance_job(model, _settings(items=[{"kind": "thickness", "limit": 0.05, "surfaces": [gap]}]))
    bfl0 = float(first_order(lens, system).bfl)
    # Paraxial: the trial lens's own back focal length, for a small δ (the formula is first order).
    delta = 1e-3
    p = job.params(torch.tensor([[delta]], dtype=torch.float64))
    trial = params_lens(lens, None, p.select(0))
    shift = float(first_order(trial, system).bfl) - bfl0
    assert shift == pytest.approx(per_mm * delta, rel=2e-3)
    # Real rays: the closed-form back-focus compensator of the tolerance run moves the image plane by
    # the same amount (f/10, near diffraction-limited: aberrations shift the best focus only slightly).
    values = torch.tensor([[-0.05], [0.0], [0.05]], dtype=torch.float64)
    out = evaluate(job.setup, job.params(values))
    comp = (out["focus_shift"] - out["focus_shift"][1]).numpy()
    assert comp[0] == pytest.approx(-0.05 * per_mm, rel=0.03)
    assert comp[2] == pytest.approx(0.05 * per_mm, rel=0.03)


def test_surface_decenter_moves_centroid_as_optiland_says(cooke) -> None:
    pytest.importorskip("optiland")
    from optiland import optic as ol_optic
    from optiland.materials import IdealMaterial
    from optiland.rays import RealRays

    from lensopt.optics.bundle import trace_bundle

    model = cooke
    lens, system = model.lens, model.system
    settings = _settings(items=[{"kind": "decenter_y", "limit": 0.1, "surfaces": [2]},
                                {"kind": "decenter_x", "limit": 0.1, "surfaces": [2]}], compensator="none",
                         sampling="rings:8")
    job = tolerance_job(model, settings)
    values = torch.tensor([[0.0, 0.0], [0.1, -0.05]], dtype=torch.float64)  # (dy, dx) of surface 2, mm
    params = job.params(values)
    ours = evaluate(job.setup, params)["centroid"].numpy()  # (K, F, 2)
    trial = params_lens(lens, job.setup.placement, params.select(1))
    bundle = trace_bundle(trial, system, job.setup.pupil, half_pupil=job.setup.half, aim="none")
    assert not bundle.half_pupil  # a decentered lens is traced on the full pupil
    weights = system.wavelength_weights.numpy()
    z = lens.vertex_z().tolist()
    sums = np.zeros((len(system.rel_field), 2))
    for w in range(lens.wavelength_um.shape[0]):
        index = lens.index[:, w].tolist()
        o = ol_optic.Optic()
        o.surfaces.add(index=0, radius=math.inf, thickness=math.inf, material=IdealMaterial(n=index[0]))
        for i in range(lens.num_surfaces):
            c = float(lens.curvature[i])
            kw = {"dx": -0.05, "dy": 0.1} if i == 2 else {}
            o.surfaces.add(index=i + 1, radius=math.inf if c == 0 else 1.0 / c, thickness=float(lens.thickness[i]),
                           is_stop=(i == lens.stop), material=IdealMaterial(n=index[i + 1]), **kw)
        o.surfaces.add(index=lens.num_surfaces + 1)
        assert abs(float(o.surfaces.surfaces[3].geometry.cs.z) - z[2]) < 1e-12
        shape = bundle.result.pos[:, w].shape
        pos = bundle.rays.pos[:, w].expand(shape).reshape(-1, 3).numpy()
        d = bundle.rays.dir[:, w].expand(shape).reshape(-1, 3).numpy()
        t = np.minimum(0.0, (-1.0 - pos[:, 2]) / d[:, 2])
        pos = pos + t[:, None] * d
        count = pos.shape[0]
        rays = RealRays(*(np.ascontiguousarray(a) for a in (*pos.T, *d.T)), np.ones(count),
                        np.full(count, float(lens.wavelength_um[w])))
        o.surfaces.trace(rays)
        xy = np.stack([np.asarray(rays.x), np.asarray(rays.y)], -1).reshape(*shape[:-1], 2)
        sums += weights[w] * xy.mean(1)
    theirs = sums / weights.sum()
    assert np.abs(ours[1] - theirs).max() <= 1e-9
    moved = np.abs(ours[1] - ours[0]).max()
    assert moved > 1e-3  # the decenter really moves the image (tens of µm here)
