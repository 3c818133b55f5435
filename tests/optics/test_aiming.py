"""Chief-ray aiming (``aim = "chief"``, S1.3.2): the aimed chief ray passes through the centre of the
real aperture stop. Checked by re-tracing the aimed rays to the stop with the plain trace."""

from __future__ import annotations

import dataclasses

import torch

from lensopt.optics.bundle import trace_bundle
from lensopt.optics.paraxial import first_order
from lensopt.optics.trace import trace


def test_chief_ray_hits_stop_centre_on_cooke_triplet_at_20_degrees(cooke) -> None:
    model = cooke
    lens, system = model.lens, model.system
    rel = torch.tensor([0.7, 1.0], dtype=lens.dtype)  # 14° and 20° (HFOV = 20°)
    bundle = trace_bundle(lens, system, torch.zeros(1, 2, dtype=lens.dtype), rel_field=rel, aim="chief")
    assert bundle.aim is not None and bool(bundle.aim.converged.all())
    at_stop = trace(lens, bundle.rays, upto=lens.stop)
    assert bool(at_stop.valid.all())
    y_stop = at_stop.pos[..., 1]
    x_stop = at_stop.pos[..., 0]
    assert float(y_stop.abs().max()) <= 1e-9, y_stop
    assert float(x_stop.abs().max()) == 0.0
    # The stop surface is surface 3 (index 2): the chief ray meets it at its vertex plane z = 9.26651 mm
    # (3.25896 + 6.00755 from the prescription), since its sag is 0 at r = 0.
    z_stop = at_stop.pos[..., 2]
    torch.testing.assert_close(z_stop, torch.full_like(z_stop, 3.25896 + 6.00755), rtol=0, atol=1e-9)
    # Aiming is needed at all: the unaimed (paraxial entrance pupil) chief ray misses the stop centre
    # at 20° by pupil aberration, by more than a micrometre.
    plain = trace_bundle(lens, system, torch.zeros(1, 2, dtype=lens.dtype), rel_field=rel, aim="none")
    y_plain = trace(lens, plain.rays, upto=lens.stop).pos[..., 1]
    assert float(y_plain[1].abs().min()) > 1e-3


def test_aiming_offsets_are_zero_on_axis_and_follow_the_system(cooke) -> None:
    model = cooke
    lens, system = model.lens, model.system
    fo = first_order(lens, system)
    bundle = trace_bundle(lens, system, torch.zeros(1, 2, dtype=lens.dtype), aim="chief", fo=fo)
    assert bundle.aim is not None
    # Field 0 (on axis): the chief ray is the axis, no shift by symmetry.
    assert float(bundle.aim.offset[0].abs().max()) == 0.0
    # Off-axis fields need a non-zero shift; wavelengths differ (pupil chromatism) but stay close.
    off = bundle.aim.offset[1:]
    assert bool((off.abs() > 0).all())


def test_stop_radius_takes_the_callers_paraxial_fallback_with_the_same_numbers(cooke) -> None:
    # ``stop_radius(…, paraxial_mm=)``: the caller's first-order stop semi-diameter instead of a second
    # paraxial trace. The real marginal ray's height where it reaches the stop, the paraxial one where it
    # is lost (an entrance pupil 8× too large: the marginal ray misses a front element), the same
    # numbers and first derivatives (in the lens thicknesses) either way.
    from lensopt.optics.aiming import stop_radius

    lens, system = cooke.lens, cooke.system
    fo = first_order(lens, system)
    for scale, lost in ((1.0, False), (8.0, True)):
        def radius(thickness: torch.Tensor, given: bool, scale: float = scale) -> torch.Tensor:
            moved = dataclasses.replace(lens, thickness=thickness)
            f = first_order(moved, system)
            return stop_radius(moved, system, epd=scale * f.epd, entrance_pupil_z=f.entrance_pupil_z,
                               paraxial_mm=f.stop_semi_diameter if given else None)

        at, along = (lens.thickness,), (torch.ones_like(lens.thickness),)
        plain, d_plain = torch.func.jvp(lambda t: radius(t, False), at, along)
        given, d_given = torch.func.jvp(lambda t: radius(t, True), at, along)
        assert torch.equal(plain, given) and torch.equal(d_plain, d_given) and float(d_plain) != 0
        assert torch.equal(plain, fo.stop_semi_diameter) == lost
