"""Chief-ray aiming of decentered and tilted lenses (issue 12: aiming honours the placement).

The stop centre of a placed lens is the stop surface's own vertex; ``aim_chief`` finds the pupil offset
(δ_x, δ_y) whose chief ray meets it, on the placed lens. Checked against

- a closed form: the C-mount lens has its stop in front, on the entrance-pupil plane, so a stop
  decentered by (dx, dy) needs exactly δ = (dx, dy) / (EPD/2), and the unaimed chief ray misses the
  stop centre by exactly (−dx, −dy);
- a brute-force search: scipy's least_squares (finite differences, no autodiff) over the pupil point
  whose ray meets the stop centre, on a Cooke triplet whose first element is tilted and decentered.

The size of the error that aiming removes is recorded (benchmarks/README.md, tolerance): the
unaimed trial traces the nominal pupil through a moved stop, and a y-only aim leaves the x miss.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest
import scipy.optimize as scipy_opt
import torch

from lensopt.design.tolerance import tolerance_job
from lensopt.optics.aiming import aim_chief, stop_hit
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.paraxial import field_tangents, first_order
from lensopt.optics.placement import Placement
from lensopt.optics.sampling import launch
from lensopt.spec import build, load_spec
from lensopt.spec.tolerance import ToleranceSpec
from lensopt.tolerance.evaluate import evaluate

ROOT = Path(__file__).resolve().parents[2]
ARCMIN = math.pi / (180 * 60)


def _placed(lens, *, decenter=None, groups=(), group_decenter=None, group_tilt=None):
    num = lens.num_surfaces
    zeros = torch.zeros(num, 2, dtype=torch.float64)
    p = Placement(decenter=zeros if decenter is None else decenter, tilt=zeros.clone(), basic=(False,) * num,
                  groups=groups, group_decenter=group_decenter, group_tilt=group_tilt)
    return dataclasses.replace(lens, placement=p)


def _on_stop(lens, system, tan: float, px: float, py: float) -> tuple[float, float]:
    """Where the ray of pupil point (px, py) at the reference wavelength meets the stop, in its frame."""
    fo = first_order(lens, system)
    pupil = torch.tensor([[[[px, py]]]], dtype=torch.float64)
    rays = launch(lens, system, pupil, torch.tensor([tan], dtype=torch.float64), epd=fo.epd,
                  entrance_pupil_z=fo.entrance_pupil_z)
    x, y, _ = stop_hit(lens, rays)
    w = system.reference
    return float(x[0, w, 0]), float(y[0, w, 0])


def _cmount_stop_decentered(dx: float, dy: float):
    model = build(load_spec(ROOT / "lenses" / "cmount_4p.json"))
    lens = model.lens
    assert lens.stop == 0 and float(first_order(lens, model.system).entrance_pupil_z) == 0.0
    dec = torch.zeros(lens.num_surfaces, 2, dtype=torch.float64)
    dec[0] = torch.tensor([dx, dy], dtype=torch.float64)
    return model, _placed(lens, decenter=dec)


def test_cmount_stop_decenter_closed_form() -> None:
    dx, dy = 0.03, 0.05
    model, lens = _cmount_stop_decentered(dx, dy)
    system = model.system
    radius = float(first_order(lens, system).epd) / 2  # 7 mm
    tan = field_tangents(lens, system, torch.tensor(system.rel_field, dtype=torch.float64))
    # Unaimed: the chief ray of every field goes through the nominal stop centre, (−dx, −dy) in the stop's frame.
    for f in range(tan.shape[0]):
        assert _on_stop(lens, system, float(tan[f]), 0.0, 0.0) == pytest.approx((-dx, -dy), abs=1e-15)
    fo = first_order(lens, system)
    aim = aim_chief(lens, system, tan, epd=fo.epd, entrance_pupil_z=fo.entrance_pupil_z)
    assert aim.converged.all() and float(aim.residual_mm.max()) < 1e-12
    assert torch.allclose(aim.offset_x, torch.full_like(aim.offset_x, dx / radius), rtol=0, atol=1e-14)
    assert torch.allclose(aim.offset, torch.full_like(aim.offset, dy / radius), rtol=0, atol=1e-14)
    # Differentiable in the placement: d δ / d(dx, dy) = 1 / (EPD/2), by the final attached Newton step.
    dec = lens.placement.decenter.clone().requires_grad_(True)
    moved = dataclasses.replace(lens, placement=dataclasses.replace(lens.placement, decenter=dec))
    a2 = aim_chief(moved, system, tan[-1:], epd=fo.epd, entrance_pupil_z=fo.entrance_pupil_z)
    gx, = torch.autograd.grad(a2.offset_x[0, system.reference], dec)
    assert float(gx[0, 0]) == pytest.approx(1 / radius, rel=1e-12) and abs(float(gx[0, 1])) < 1e-12


def test_cmount_stop_decenter_in_tolerance_trials(cmount) -> None:
    """With aim = none a stop decenter does nothing (the nominal pupil is traced through a flat air
    surface); with aim = chief the beam follows the stop, and the trial's ESR changes."""
    model = cmount
    items = [{"kind": "decenter_x", "limit": 0.05, "surfaces": [0]}, {"kind": "decenter_y", "limit": 0.05,
                                                                       "surfaces": [0]}]
    values = torch.tensor([[0.0, 0.0], [0.03, 0.05]], dtype=torch.float64)
    out = {}
    for aim in ("none", "chief"):
        job = tolerance_job(model, ToleranceSpec.model_validate({"items": items, "aim": aim, "sampling": "rings:6"}))
        out[aim] = evaluate(job.setup, job.params(values))
    none, chief = out["none"]["esr"] * 1e3, out["chief"]["esr"] * 1e3
    assert abs(float(none[1] - none[0])) < 1e-12  # blind to the stop decenter
    assert abs(float(chief[0] - none[0])) < 1e-12  # nominal: the chief rays already meet the stop centre
    assert float(chief[1] - chief[0]) > 0.05  # µm: the decentered beam is worse


def test_cooke_tilted_element_aim_matches_brute_force(cooke) -> None:
    model = cooke
    system = model.system
    lens = _placed(model.lens, groups=((0, 1),), group_decenter=torch.tensor([[0.05, 0.0]], dtype=torch.float64),
                   group_tilt=torch.tensor([[20 * ARCMIN, 0.0]], dtype=torch.float64))
    tan = field_tangents(lens, system, torch.tensor([0.0, 1.0], dtype=torch.float64))
    fo = first_order(lens, system)
    aim = aim_chief(lens, system, tan, epd=fo.epd, entrance_pupil_z=fo.entrance_pupil_z)
    w = system.reference
    for f in range(2):
        t = float(tan[f])
        brute = scipy_opt.least_squares(lambda v, t=t: _on_stop(lens, system, t, v[0], v[1]), [0.0, 0.0],
                                        xtol=1e-15, ftol=1e-15, gtol=1e-15)
        assert max(abs(v) for v in brute.fun) < 1e-12
        assert float(aim.offset_x[f, w]) == pytest.approx(brute.x[0], abs=1e-9)
        assert float(aim.offset[f, w]) == pytest.approx(brute.x[1], abs=1e-9)
        hit = _on_stop(lens, system, t, float(aim.offset_x[f, w]), float(aim.offset[f, w]))
        assert max(map(abs, hit)) < 1e-12
        # What aiming removes: the unaimed chief ray misses the stop centre by tenths of a mm at full
        # field, in x as well as y (a y-only aim, as before, left the x miss of ~13 µm).
        if f == 1:
            miss = _on_stop(lens, system, t, 0.0, 0.0)
            assert abs(miss[0]) > 0.01 and abs(miss[1]) > 0.1
            y_only = scipy_opt.least_squares(lambda v, t=t: [_on_stop(lens, system, t, 0.0, v[0])[1]], [0.0],
                                             xtol=1e-15, ftol=1e-15, gtol=1e-15)
            assert abs(_on_stop(lens, system, t, 0.0, float(y_only.x[0]))[0]) > 0.01
    # trace_bundle with aim = chief launches the aimed pupil (x offset included).
    b = trace_bundle(lens, system, torch.zeros(1, 2, dtype=torch.float64), aim="chief",
                     rel_field=torch.tensor([0.0, 1.0], dtype=torch.float64))
    assert torch.allclose(b.pupil[:, :, 0, 0], aim.offset_x, atol=1e-15)
    assert torch.allclose(b.pupil[:, :, 0, 1], aim.offset, atol=1e-15)


def test_cmount_stop_decenter_full_aim_closed_form() -> None:
    """``full`` aiming of the decentered front stop: the ellipse is the unit disc moved by (dx, dy)/(EPD/2)
    (V_i = dy/R, V_s = −dy/R, V_l = 0, x offset dx/R) for every field and wavelength, and the marginal
    rays of the launched bundle meet the stop edge r = R (the stop keeps its size)."""
    dx, dy = 0.03, 0.05
    model, lens = _cmount_stop_decentered(dx, dy)
    system = model.system
    radius = float(first_order(lens, system).epd) / 2
    pupil = torch.tensor([[0.0, -1.0], [0.0, 1.0], [1.0, 0.0], [-1.0, 0.0], [0.6, 0.8]], dtype=torch.float64)
    b = trace_bundle(lens, system, pupil, aim="full", record=True)
    assert b.pupil_aim is not None and b.pupil_aim.converged.all()
    assert float(b.pupil_aim.stop_radius_mm) == pytest.approx(radius, abs=1e-12)
    want = torch.tensor([dy / radius, -dy / radius, 0.0], dtype=torch.float64)
    assert torch.allclose(b.vignetting, want.expand_as(b.vignetting), rtol=0, atol=1e-12)
    assert torch.allclose(b.pupil_aim.chief.offset_x, torch.full_like(b.pupil_aim.chief.offset_x, dx / radius),
                          rtol=0, atol=1e-14)
    hit = b.result.hits[0].pos  # the stop (surface 0), global; its frame is the global frame moved by (dx, dy)
    rho = torch.sqrt((hit[..., 0] - dx) ** 2 + (hit[..., 1] - dy) ** 2)
    assert torch.allclose(rho, torch.full_like(rho, radius), rtol=0, atol=1e-12)
