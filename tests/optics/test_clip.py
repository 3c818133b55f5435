"""Clear apertures that clip (``clip = true``): rays outside the semi-diameter fail with their own
reason, and exactly the rays a single-ray bisection predicts are kept."""


import torch

from lensopt.optics.bundle import trace_bundle
from lensopt.optics.sampling import launch, pupil_grid
from lensopt.optics.trace import REASONS, Status, failure_counts, trace
from lensopt.spec import build, parse_spec
from tests.helpers import cooke_data

F64 = torch.float64
STOP_SD = 3.0  # the Cooke triplet's axial beam is ~4.7 mm high on its stop (surface 3)


def _cooke_clipped() -> dict:
    data = cooke_data()
    data["surfaces"][2].update(semi_diameter=STOP_SD, clip=True)
    return data


def test_axial_bundle_keeps_exactly_the_rays_inside_the_clear_aperture() -> None:
    m = build(parse_spec(_cooke_clipped()))
    lens, system = m.lens, m.system
    pupil = pupil_grid(61, dtype=F64)
    b = trace_bundle(lens, system, pupil, rel_field=torch.zeros(1, dtype=F64))
    # Bisection on one meridional ray (unclipped lens): the pupil radius ρ* whose ray meets the stop at
    # height STOP_SD; by rotational symmetry the axial rays kept are those with ρ < ρ*.
    free = m.lens.__class__(**{**lens.__dict__, "shapes": tuple(
        s.__class__(**{**s.__dict__, "clip": False}) for s in lens.shapes)})
    lo, hi = 0.0, 1.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        p = torch.tensor([[[[0.0, mid]]]], dtype=F64)
        h = trace(free, launch(free, system, p, torch.zeros(1, dtype=F64), epd=b.first_order.epd,
                               entrance_pupil_z=b.first_order.entrance_pupil_z), upto=lens.stop).pos[0, 0, 0, 1]
        lo, hi = (mid, hi) if float(h) < STOP_SD else (lo, mid)
    rho = torch.linalg.vector_norm(pupil, dim=-1)
    for w in range(lens.wavelength_um.shape[0]):
        status = b.result.status[0, w]
        expect_clipped = rho > lo
        # Heights on the stop differ slightly between wavelengths; stay away from the boundary there.
        sure = (rho - lo).abs() > 2e-3
        assert torch.equal((status == Status.CLIPPED)[sure], expect_clipped[sure])
        assert bool((status[~expect_clipped & sure] == Status.OK).all())
    assert REASONS[Status.CLIPPED] == "clipped by aperture"
    assert failure_counts(b.result)["clipped by aperture"] == int((b.result.status == Status.CLIPPED).sum()) > 0


def test_clipped_rays_keep_finite_values_and_gradients() -> None:
    m = build(parse_spec(_cooke_clipped()))
    curv = m.lens.curvature.clone().requires_grad_()
    lens = m.lens.__class__(**{**m.lens.__dict__, "curvature": curv})
    b = trace_bundle(lens, m.system, pupil_grid(15, dtype=F64))
    assert bool(torch.isfinite(b.result.pos).all())
    loss = torch.where(b.result.valid, b.result.pos[..., 1], 0.0).pow(2).sum()
    (g,) = torch.autograd.grad(loss, curv)
    assert bool(torch.isfinite(g).all())
