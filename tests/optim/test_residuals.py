"""Residual terms (S37–S57) against closed forms and the analysis functions they build on."""

from __future__ import annotations

import dataclasses
import math

import pytest
import torch

from lensopt.analysis.spot import spot_stats
from lensopt.design import build_problem
from lensopt.materials import material_from_name
from lensopt.optim.rays import head
from lensopt.spec import parse_spec


def _plate(**constraints) -> dict:  # noqa: ANN003
    """Stop on a plane N-BK7 face, weak convex back (R = −50 mm); fields 0° and 30°."""
    return {
        "system": {"aperture": {"epd": 8.0}, "field": {"hfov_deg": 30.0, "relative": [0.0, 1.0]}},
        "spectrum": {"wavelengths_nm": [587.5618]},
        "surfaces": [
            {"type": "plane", "thickness": 2.0, "material": "N-BK7", "stop": True, "vary": ["thickness"]},
            {"type": "sphere", "radius": -50.0, "thickness": 60.0},
        ],
        "optimize": {"sampling": "rings:4:nojitter", "constraints": constraints},
    }


def test_tra_norm_is_the_effective_spot_radius(make_cooke) -> None:  # noqa: ANN001
    # S40 generalized to wavelength and field weights: ‖ℓ_TRA‖² = Σ_h f̂_h SR_h² = ESR² without failures.
    data = make_cooke(sampling="rings:5")
    data["system"]["field"]["weights"] = [1.0, 2.0, 0.5]
    data["spectrum"]["weights"] = [0.5, 1.0, 0.7]
    data["surfaces"][0]["vary"] = ["radius"]
    data["optimize"]["rim_rays"] = 0
    p = build_problem(parse_spec(data))
    lens, _ = p.lens(p.theta0)
    b = p.bundle(lens)
    stats = spot_stats(b, p.system.wavelength_weights, p.field_weights)
    r = p.terms(p.theta0)["tra"]
    assert float(torch.linalg.vector_norm(r)) == pytest.approx(float(stats.effective_radius), rel=1e-13)
    assert r.shape[0] == 2 * b.result.status.numel()
    # The rim rays (for the geometric constraints) do not enter the spot terms.
    data["optimize"]["rim_rays"] = 7
    with_rim = build_problem(parse_spec(data))
    assert with_rim.pupil.shape[0] == p.pupil.shape[0] + 7 + 1  # rim rays and the centre
    torch.testing.assert_close(with_rim.terms(with_rim.theta0)["tra"], r, rtol=0, atol=0)


def test_ray_angle_residual_at_a_plane_face_has_the_closed_form() -> None:
    # At the plane first face every ray of the 30° field meets the surface at exactly 30°, refracting
    # to sin θ' = sin 30° / n_d. With θ_max = 20°: ΔζI = cos²20° − cos²30°, ΔζR = ramp(cos²20° − cos²θ').
    p = build_problem(parse_spec(_plate(ray_angle={"max_deg": 20.0})))
    r = p.terms(p.theta0)["ray_angle"]
    n_r = p.pupil.shape[0] * 2
    blocks = r.view(4, 2, 1, -1) * math.sqrt(n_r)  # (interface × in/out, field, wavelength, pupil)
    c20, c30 = math.cos(math.radians(20)) ** 2, math.cos(math.radians(30)) ** 2
    n = float(material_from_name("N-BK7").index(torch.tensor([0.5875618], dtype=torch.float64)))
    cos2_r = 1 - 0.25 / n**2
    torch.testing.assert_close(blocks[0, 1], torch.full_like(blocks[0, 1], c20 - c30), rtol=1e-12, atol=1e-14)
    torch.testing.assert_close(blocks[1, 1], torch.full_like(blocks[1, 1], max(c20 - cos2_r, 0.0)), atol=1e-14,
                               rtol=0)
    assert float(blocks[0, 0].abs().max()) == 0.0  # on axis: normal incidence


def test_ray_path_residual_in_the_glass_has_the_closed_form() -> None:
    # On axis the rays cross the plane face undeviated at height h and meet the back sphere at
    # z = 2 + sag(h), sag = c h²/(1 + √(1 − c²h²)), c = −1/50: t_z = 2 + sag. With glass_min = 1.95
    # the residual is ramp(1.95 − t_z)/√n_r.
    p = build_problem(parse_spec(_plate(ray_path={"glass_min": 1.95, "image_min": 0.0})))
    r = p.terms(p.theta0)["ray_path"]
    n_r = p.pupil.shape[0] * 2
    glass_rows = r.view(2, 2, 1, -1)[0, 0, 0] * math.sqrt(n_r)  # gap 0, field 0
    h = torch.linalg.vector_norm(p.pupil, dim=-1) * 4.0
    c = -1.0 / 50.0
    sag = c * h**2 / (1 + torch.sqrt(1 - c**2 * h**2))
    torch.testing.assert_close(glass_rows, torch.clamp_min(1.95 - (2.0 + sag), 0.0), rtol=1e-12, atol=1e-13)
    assert float(glass_rows.max()) > 0  # the outer rays violate it


def test_edge_bounds_follow_the_centre_thickness() -> None:
    # glass_ratio 3: CT/3 ≤ t_z ≤ 3 CT; a thin 0.6 mm plate gives bounds [0.2, 1.8] besides glass_min.
    data = _plate(ray_path={"glass_min": 0.1, "glass_ratio": 3.0, "air_min": 0.25, "image_min": 5.0})
    data["surfaces"][0]["thickness"] = 0.6
    p = build_problem(parse_spec(data))
    lo, hi = p.gap_bounds(p.lens(p.theta0)[0])
    assert lo.tolist() == pytest.approx([0.2, 5.0])
    assert hi[0].item() == pytest.approx(1.8)


@pytest.mark.parametrize("override", [False, True])
def test_edge_bounds_take_the_derivative_of_the_tied_thickness_alone(override: bool) -> None:
    # glass_ratio 3 on a 3 mm plate: lower bound CT/3 = 1 (above glass_min), upper 3 CT = 9: d/dCT = 1/3
    # and 3; the air gap's bounds are numbers (derivative 0). A gap's own max (2.5) replaces the tie.
    data = _plate(ray_path={"glass_min": 0.1, "glass_ratio": 3.0, "air_min": 0.25, "image_min": 5.0})
    data["surfaces"][0]["thickness"] = 3.0
    if override:
        data["optimize"]["constraints"]["ray_path"]["gaps"] = [{"gap": 0, "max": 2.5}]
    p = build_problem(parse_spec(data))
    lens = p.lens(p.theta0)[0]
    one = torch.zeros_like(lens.thickness)
    one[0] = 1.0

    def bounds(t: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return p.gap_bounds(dataclasses.replace(lens, thickness=lens.thickness + t * one))

    (lo, hi), (dlo, dhi) = torch.func.jvp(bounds, (torch.zeros((), dtype=torch.float64),),
                                          (torch.ones((), dtype=torch.float64),))
    assert lo.tolist() == pytest.approx([1.0, 5.0]) and dlo.tolist() == pytest.approx([1.0 / 3.0, 0.0])
    assert hi[0].item() == pytest.approx(2.5 if override else 9.0)
    assert dhi.tolist() == pytest.approx([0.0 if override else 3.0, 0.0])


def test_distortion_and_failure_terms(make_cooke) -> None:  # noqa: ANN001
    from lensopt.analysis.distortion import distortion

    data = make_cooke(constraints={"distortion": {"max_percent": 0.05}, "ray_failure": {"penalty_mm": 2.0}})
    data["surfaces"][0]["vary"] = ["radius"]
    p = build_problem(parse_spec(data))
    lens, _ = p.lens(p.theta0)
    b = head(p.bundle(lens), p.num_spot)  # the spot sample, without the rim rays
    d = distortion(lens, p.system, b, spot_stats(b, p.system.wavelength_weights, p.field_weights))
    t = p.terms(p.theta0)
    expected = torch.clamp_min(d.abs() - 5e-4, 0.0) / math.sqrt(3)
    torch.testing.assert_close(t["distortion"], expected, rtol=1e-13, atol=0)
    assert float(t["ray_failure"].abs().max()) == 0.0  # the Cooke triplet passes every ray


def test_failed_rays_cost_a_constant_plus_their_margin() -> None:
    # A 2 mm semi-diameter clipping aperture on the back face fails every ray above h = 2 mm there;
    # each costs penalty (1 + h²/sd² − 1)/√n_r = penalty h²/sd²/√n_r (the clipped margin), the others 0.
    data = _plate(ray_failure={"penalty_mm": 3.0})
    data["surfaces"][1].update({"semi_diameter": 2.0, "clip": True})
    p = build_problem(parse_spec(data))
    lens, _ = p.lens(p.theta0)
    b = p.bundle(lens)
    r = p.terms(p.theta0)["ray_failure"].view(b.result.status.shape)
    n_r = b.result.status.numel()
    bad = ~b.result.valid
    assert int(bad.sum()) > 0
    assert (b.result.failed_at[bad] == 1).all()
    h2 = (b.result.hits[1].pos[..., :2] ** 2).sum(-1)
    torch.testing.assert_close(r[bad], 3.0 * h2[bad] / 4.0 / math.sqrt(n_r), rtol=1e-12, atol=0)
    assert float(r[~bad].abs().max()) == 0.0


def test_ray_path_span_sums_the_gaps_it_covers() -> None:
    # The plane front face sits at z = 0 and the image plane at z = 2 + 60 = 62 mm, so every ray travels
    # exactly 62 mm axially from surface 0 to the image, whatever it does in between: a span
    # { first = 0, min = 62.5 } costs (62.5 − 62)/√n_r per ray, and a span of surface 0 → 1 (the glass
    # alone) with max = 1.9 costs ramp(t_z − 1.9) with t_z = 2 + sag(h) as in the glass test above.
    spans = [{"first": 0, "min": 62.5}, {"first": 0, "to": 1, "max": 1.9}, {"first": -2, "max": 70.0}]
    p = build_problem(parse_spec(_plate(ray_path={"image_min": 0.0, "spans": spans})))
    r = p.terms(p.theta0)["ray_path"]
    n_r = p.pupil.shape[0] * 2
    per_gap, span_rows = r[: 2 * n_r], r[2 * n_r:].view(3, 2, 1, -1) * math.sqrt(n_r)
    assert float(per_gap.abs().max()) == 0.0
    torch.testing.assert_close(span_rows[0], torch.full_like(span_rows[0], 0.5), rtol=1e-12, atol=1e-12)
    h = torch.linalg.vector_norm(p.pupil, dim=-1) * 4.0
    c = -1.0 / 50.0
    sag = c * h**2 / (1 + torch.sqrt(1 - c**2 * h**2))
    torch.testing.assert_close(span_rows[1, 0, 0], torch.clamp_min(2.0 + sag - 1.9, 0.0), rtol=1e-12, atol=1e-13)
    assert float(span_rows[2].abs().max()) == 0.0  # 62 mm ≤ 70 mm


def test_ray_path_span_errors_name_the_field() -> None:
    from lensopt.errors import SpecError

    with pytest.raises(SpecError, match=r"ray_path\.spans\[0\]\.first: no such surface"):
        build_problem(parse_spec(_plate(ray_path={"spans": [{"first": 5, "min": 1.0}]})))
    with pytest.raises(SpecError, match=r"ray_path\.spans\[0\]\.to: `to` must come after"):
        build_problem(parse_spec(_plate(ray_path={"spans": [{"first": 1, "to": 0, "min": 1.0}]})))
    with pytest.raises(SpecError, match=r"spans\[0\]\.min: a span needs a min or a max"):
        parse_spec(_plate(ray_path={"spans": [{"first": 1}]}))
