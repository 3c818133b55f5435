"""Vignetting factors reshape the pupil (S19–S20 with the seed text's sign, = CODE V VLY/VUY/VUX)."""


import pytest
import torch

from lensopt.errors import SpecError
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.vignetting import apply_vignetting
from lensopt.spec import build, parse_spec
from tests.helpers import cooke_data


@pytest.mark.parametrize(("v_i", "v_s", "v_l"), [(0.0, 0.0, 0.0), (0.3, 0.0, 0.1), (0.2, 0.4, 0.25), (1.0, 0.0, 0.0)])
def test_pupil_edges_move_by_the_blocked_fractions(v_i: float, v_s: float, v_l: float) -> None:
    # By definition the kept pupil spans y ∈ [−1 + V_i, 1 − V_s] and x ∈ [−(1 − V_l), 1 − V_l]; the map is
    # affine, so the centre goes to the middle of that span.
    pts = torch.tensor([[0.0, -1.0], [0.0, 1.0], [1.0, 0.0], [-1.0, 0.0], [0.0, 0.0]], dtype=torch.float64)
    out = apply_vignetting(pts.view(1, 1, 5, 2), torch.tensor([v_i, v_s, v_l], dtype=torch.float64).view(1, 1, 3))
    out = out.view(5, 2)
    assert out[0, 1] == pytest.approx(-1.0 + v_i, abs=1e-15)
    assert out[1, 1] == pytest.approx(1.0 - v_s, abs=1e-15)
    assert out[2, 0] == pytest.approx(1.0 - v_l, abs=1e-15)
    assert out[3, 0] == pytest.approx(-(1.0 - v_l), abs=1e-15)
    assert out[4, 1] == pytest.approx(0.5 * ((-1.0 + v_i) + (1.0 - v_s)), abs=1e-15)


def _cooke(vig: dict | None) -> dict:
    data = cooke_data()
    if vig is not None:
        data["system"]["vignetting"] = vig
    return data


def test_spec_factors_reach_the_launched_bundle() -> None:
    vig = {"inferior": [0.0, 0.1, 0.2], "superior": [0.0, 0.0, 0.05], "lateral": [0.0, 0.05, 0.1]}
    model = build(parse_spec(_cooke(vig)))
    pupil = torch.tensor([[0.0, -1.0], [0.0, 1.0], [1.0, 0.0]], dtype=torch.float64)
    bundle = trace_bundle(model.lens, model.system, pupil)
    for h in range(3):
        lo, hi, lat = bundle.pupil[h, 0, 0, 1], bundle.pupil[h, 0, 1, 1], bundle.pupil[h, 0, 2, 0]
        assert float(lo) == pytest.approx(-1.0 + vig["inferior"][h])
        assert float(hi) == pytest.approx(1.0 - vig["superior"][h])
        assert float(lat) == pytest.approx(1.0 - vig["lateral"][h])


def test_factor_count_must_match_fields() -> None:
    with pytest.raises(SpecError, match=r"^system\.vignetting\.lateral: needs one factor per relative field"):
        parse_spec(_cooke({"inferior": [0, 0, 0], "superior": [0, 0, 0], "lateral": [0, 0]}))
