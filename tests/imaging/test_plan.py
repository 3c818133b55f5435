"""The scene plan: only the fields, channels and effects a scene calls for."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from lensopt.errors import LensoptError
from lensopt.imaging.plan import PlanOptions, parse_effects
from lensopt.imaging.scene import parse_region
from lensopt.imaging.simulate import plan_scene
from lensopt.spec import build, camera_of, load_spec
from tests.helpers import imaging_oval

SPECS = Path(__file__).resolve().parents[2] / "specs"


def plan_for(model, w: int, h: int, channels: int, region: str | None = None, effects: str | None = None,
             **opts):
    info = {"width": w, "height": h, "channels": channels}
    plan, *_ = plan_scene(camera_of(model), info, region=region, effects=parse_effects(effects),
                          options=PlanOptions(**opts))
    return plan.as_json()


def test_grayscale_scene_plans_one_channel_with_the_spectrum_summed(cooke) -> None:
    p = plan_for(cooke, 600, 400, 1, region="corner")
    assert p["channels"] == ["Y"]
    assert all(len(row) == 1 for row in p["channel_weights"])
    assert sum(row[0] for row in p["channel_weights"]) == pytest.approx(1.0)
    assert p["wavelengths_nm"] == [480.0, 550.0, 650.0]
    rgb = plan_for(cooke, 600, 400, 3, region="corner")
    assert rgb["channels"] == ["R", "G", "B"] and len(rgb["channel_weights"][0]) == 3


def test_centre_crop_traces_no_corner_field(cooke) -> None:
    centre = plan_for(cooke, 600, 400, 3, region="center")
    corner = plan_for(cooke, 600, 400, 3, region="corner")
    # The 600×400 centre crop of 7.2 µm pixels reaches hypot(300, 200)·7.2 µm = 2.60 mm from the axis: about
    # atan(2.60/50) ≈ 3.0° for this f = 50 mm lens; the corner crop starts at 14.4° (its nearest point).
    assert max(centre["fields_deg"]) < 3.2
    assert min(corner["fields_deg"]) > 14.0
    assert centre["radius_range_mm"][0] == 0.0
    assert centre["radius_range_mm"][1] == pytest.approx(math.hypot(300, 200) * 7.2e-3, rel=1e-9)
    # The blur changes faster in the corner: more fields, and at least as dense a grid.
    assert len(corner["fields_deg"]) > len(centre["fields_deg"])
    assert corner["psf_grid"][0] * corner["psf_grid"][1] >= centre["psf_grid"][0] * centre["psf_grid"][1]


def test_pass_through_when_the_psf_is_within_a_pixel() -> None:
    p = plan_for(imaging_oval(pitch_um=30.0), 64, 48, 1)
    assert p["effects"]["convolution"]["on"] is False
    assert "pass-through" in p["effects"]["convolution"]["reason"]
    assert p["psf_grid"] is None and p["fields_deg"] == []
    assert p["diffraction"]["on"] is False


def test_diffraction_decision_follows_airy_radius_against_pixel_and_blur(cooke) -> None:
    achromat = build(load_spec(SPECS / "achromat_f10.toml"))
    p = plan_for(achromat, 400, 300, 3, region="center")  # 1.5 µm pixels, Airy radius 8 µm at 650 nm
    assert p["diffraction"]["on"] is True
    q = plan_for(cooke, 600, 400, 3)  # fit: 48 µm image pixels
    assert q["diffraction"]["on"] is False and "half a pixel" in q["diffraction"]["reason"]
    forced = plan_for(cooke, 600, 400, 3, effects="+diffraction,+convolution")
    assert forced["diffraction"]["on"] is True and "forced" in forced["diffraction"]["reason"]


def test_effects_are_off_unless_asked_and_forced_grid_is_kept(cooke) -> None:
    p = plan_for(cooke, 600, 400, 3, region="corner", grid=(5, 4))
    assert p["psf_grid"] == [5, 4]
    for name in ("distortion", "relative_illumination", "noise"):
        assert p["effects"][name]["on"] is False
    q = plan_for(cooke, 600, 400, 3, region="corner", effects="distortion,ri,noise=0.01")
    assert q["effects"]["distortion"]["on"] and q["effects"]["relative_illumination"]["on"]
    assert q["effects"]["noise"] == {"on": True, "reason": q["effects"]["noise"]["reason"], "sigma": 0.01, "seed": 0}


def test_bad_effects_and_regions_name_the_option(cooke) -> None:
    with pytest.raises(LensoptError, match="--effects"):
        parse_effects("sharpen")
    with pytest.raises(LensoptError, match="--effects"):
        parse_effects("noise=lots")
    from lensopt.imaging.scene import Sensor

    s = Sensor(0.0072, 4000, 3000)
    with pytest.raises(LensoptError, match="--region"):
        parse_region("10,10,5000,10", s, 100, 100)
    with pytest.raises(LensoptError, match="aspect"):
        parse_region("0,0,200,100", s, 100, 100)
    r = parse_region("tile:31,0/32x24", s, 125, 125)
    assert (r.x0, r.y0, r.w, r.h) == (3875.0, 0.0, 125.0, 125.0)
