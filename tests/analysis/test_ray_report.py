"""``ray_report`` (what ``lensopt ray`` prints) launches its ray exactly like ``trace_bundle``.

Regression: it used to place the ray on the paraxial entrance pupil of the ray's *own* wavelength, so
at 480 nm the Cooke triplet's (0, 0.5) ray at 14° landed 30 nm away from the same ray of ``trace``.
"""

from __future__ import annotations

import pytest
import torch

from lensopt.analysis.report import ray_report
from lensopt.optics.bundle import trace_bundle
from lensopt.spec import build
from lensopt.spec.io import parse_spec
from tests.helpers import cooke_data


def cooke(**system):
    data = cooke_data()
    data["system"].update(system)
    return build(parse_spec(data))


@pytest.mark.parametrize("aperture", [{"epd": 10.0}, {"fnumber": 4.0}])
@pytest.mark.parametrize(("w", "nm"), [(0, 480.0), (1, 550.0), (2, 650.0)])
def test_ray_report_matches_bundle_at_every_wavelength(aperture, w, nm):
    model = cooke(aperture=aperture)
    pupil = torch.tensor([[0.3, -0.8]], dtype=torch.float64)
    rel = torch.tensor([0.7], dtype=torch.float64)  # 14° of the 20° field
    with torch.no_grad():
        bundle = trace_bundle(model.lens, model.system, pupil, rel_field=rel, record=True)
    r = ray_report(model, field_deg=14.0, px=0.3, py=-0.8, wavelength_nm=nm)
    img = bundle.result.pos[0, w, 0]
    assert [r["image"][k] for k in "xyz"] == pytest.approx(img.tolist(), abs=1e-12)
    for s, hit in enumerate(bundle.result.hits):
        p = hit.pos[0, w, 0]
        assert [r["surfaces"][s][k] for k in "xyz"] == pytest.approx(p.tolist(), abs=1e-12)


def test_trace_report_esr_uses_the_spec_field_weights():
    """ESR = sqrt(Σ w_h SR_h² / Σ w_h) (S4.2.1) with the spec's ``field.weights``; uniform without them.
    Regression: ``trace_report`` used to ignore the weights."""
    from lensopt.analysis.report import trace_report
    from lensopt.optics.sampling import PupilSampling

    sampling = PupilSampling.parse("rings:6")
    plain = trace_report(cooke(), sampling)
    sr = [f["rms_spot_radius_weighted_um"] for f in plain["fields"]]
    assert plain["effective_spot_radius_um"] == pytest.approx((sum(v * v for v in sr) / 3) ** 0.5, rel=1e-12)
    weighted = trace_report(cooke(field={"hfov_deg": 20.0, "relative": [0.0, 0.7, 1.0],
                                         "weights": [1.0, 0.0, 3.0]}), sampling)
    expected = ((sr[0] ** 2 + 3 * sr[2] ** 2) / 4) ** 0.5
    assert weighted["effective_spot_radius_um"] == pytest.approx(expected, rel=1e-12)


def test_ray_at_a_wavelength_outside_a_glass_range_names_the_surface():
    # ray_report re-indexes the media at the asked wavelength (no spec rebuild): the glass's valid range
    # is still checked, and the error names the surface's material (Cooke: SK16 catalog data 0.4–0.7 µm).
    from lensopt.errors import LensoptError

    with pytest.raises(LensoptError, match=r"surfaces\[0\]\.material: wavelength 2.5 µm is outside"):
        ray_report(cooke(), field_deg=0.0, px=0.0, py=1.0, wavelength_nm=2500.0)
