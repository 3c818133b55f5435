"""The requirement checker (``lensopt.analysis.requirements``) on a lens whose numbers are known by hand,
and on the shipped C-mount lens against the S6.1 list that ``tests/test_lenses.py`` checks its own way."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch

from lensopt.analysis.requirements import Requirements, check_requirements, failed
from lensopt.materials import material_from_name
from lensopt.spec import build, parse_spec

ROOT = Path(__file__).resolve().parents[2]


def _plate():  # noqa: ANN202
    """Stop on a plane N-BK7 face (z = 0), 2 mm thick, back sphere R = −50 mm, image plane 60 mm after
    the back vertex (z = 62); EPD 8 mm, fields up to 30°."""
    spec = parse_spec({
        "system": {"aperture": {"epd": 8.0}, "field": {"hfov_deg": 30.0, "relative": [0.0, 1.0]}},
        "spectrum": {"wavelengths_nm": [587.5618]},
        "surfaces": [
            {"type": "plane", "thickness": 2.0, "material": "N-BK7", "stop": True},
            {"type": "sphere", "radius": -50.0, "thickness": 60.0},
        ],
    })
    return build(spec), spec


def _check(req: Requirements) -> dict:
    model, spec = _plate()
    checks = check_requirements(model.lens, model.system, req, glass_gaps=[True, False],
                                materials=["N-BK7"], fields=5, grid=21, rim=32)
    return {c.name: c for c in checks}


def test_the_checker_finds_exactly_the_requirements_a_hand_made_lens_breaks() -> None:
    # By hand: rays enter the plane face at their field angle (worst 30°), so angles ≤ 20° fail. The stop
    # is the plane face: every field fills the same 4 mm circle there. The shortest glass path is the rim
    # ray of the 30° field that leans outwards: inside the glass it runs at θ' (sin θ' = sin 30°/n) from
    # height 4 mm, so its path t solves t = 2 + sag(4 + t tan θ'), sag(h) = c h²/(1 + √(1 − c²h²)),
    # c = −1/50 (≈ 1.7858 mm): thickness ≥ 1.9 fails, ≥ 1.75 holds; edge/centre ≈ 0.893 fails 1/1.05 and
    # holds 1/1.15. Front face to image is exactly 62 mm for every ray (a span).
    n = float(material_from_name("N-BK7").index(torch.tensor([0.5875618], dtype=torch.float64)))
    tan_t = math.tan(math.asin(0.5 / n))
    t = 2.0
    for _ in range(60):
        h = 4.0 + t * tan_t
        t = 2.0 - (1 / 50) * h**2 / (1 + math.sqrt(1 - h**2 / 2500))
    bad = _check(Requirements(glass_min=1.9, glass_ratio=1.05, max_angle_deg=20.0, spans=((0, None, 62.5, None),),
                              catalog=frozenset({"S-BSL7"})))
    assert set(failed(list(bad.values()))) == {
        "glass 0 thickness ≥ 1.9 mm", "glass 0 edge/centre ratio in [1/1.05, 1.05]",
        "angles of incidence/refraction", "span surface 0 → image", "catalog glasses"}
    assert bad["glass 0 thickness ≥ 1.9 mm"].value == pytest.approx(t, abs=1e-9)
    assert bad["angles of incidence/refraction"].value >= 30.0 - 1e-9
    assert bad["no failed rays"].ok
    good = _check(Requirements(glass_min=1.75, glass_max=2.0, glass_ratio=1.15, image_min=60.0, max_angle_deg=60.0,
                               spans=((0, None, 61.999, 62.001),), catalog=frozenset({"N-BK7"}), total_track=62.0))
    assert failed(list(good.values())) == []
    assert good["gap 1 (image) ≥ 60 mm"].value == pytest.approx(60.0, abs=1e-9)  # the axial ray: sag 0


def test_the_checker_passes_the_shipped_cmount_lens_on_its_table() -> None:
    # S6.1: glass 1–5 mm with edge/centre 1/3–3, air ≥ 0.25 mm, image clearance ≥ 20 mm, angles ≤ 60°,
    # |distortion| ≤ 2 %, recommended Ohara glasses, EFL 28 mm (tests/test_lenses.py checks the same lens
    # with its own code).
    from lensopt.spec import load_spec

    spec = load_spec(ROOT / "lenses" / "cmount_4p.json")
    model = build(spec)
    req = Requirements(glass_min=1.0, glass_max=5.0, glass_ratio=3.0, air_min=0.25, image_min=20.0,
                       max_angle_deg=60.0, max_distortion_percent=2.0,
                       catalog="ohara-recommended", efl=28.0)
    checks = check_requirements(model.lens, model.system, req, glass_gaps=[not s.is_air for s in spec.surfaces],
                                materials=[s.material for s in spec.surfaces if not s.is_air], fields=6, grid=31)
    assert failed(checks) == []
    assert {c.name for c in checks} >= {"no failed rays", "|distortion|", "catalog glasses", "EFL"}


def _plate_on_axis_only():  # noqa: ANN202
    """``_plate`` with one design field, the axis (the dense sample still runs fields 0 … 30°)."""
    model, spec = _plate()
    import dataclasses

    return dataclasses.replace(model.system, rel_field=(0.0,), field_weights=()), model


def test_the_seed_sample_probes_the_optimizers_rays_and_the_dense_sample_every_field() -> None:
    # By hand, on axis (the seed's sample: the design fields, here only the axis, and the optimizer's
    # rings, whose outer ring lies on the pupil rim): rays cross the plane stop face at normal incidence
    # and meet the back sphere (R = −50 mm) at height 4ρ; the worst ray, ρ = 1, meets it at 4 mm:
    # surface normal asin(4/50), incidence in the glass asin(4/50), refraction asin(n·4/50) (the worst
    # angle), glass path 2 − (50 − √(2500 − 16)) mm. The dense sample adds the 30° field,
    # whose incidence on the plane face alone is 30°.
    from lensopt.optics.sampling import PupilSampling

    system, model = _plate_on_axis_only()
    n = float(material_from_name("N-BK7").index(torch.tensor([0.5875618], dtype=torch.float64)))
    req = Requirements(glass_min=1.9, max_angle_deg=60.0, max_normal_deg=30.0)
    seed = {c.name: c for c in check_requirements(model.lens, system, req, glass_gaps=[True, False], sample="seed",
                                                  sampling=PupilSampling.parse("rings:6"))}
    dense = {c.name: c for c in check_requirements(model.lens, system, req, glass_gaps=[True, False], fields=5,
                                                   grid=21, rim=32)}
    assert seed["surface normals"].value == pytest.approx(math.degrees(math.asin(4 / 50)), abs=1e-9)
    assert seed["angles of incidence/refraction"].value == pytest.approx(math.degrees(math.asin(n * 4 / 50)),
                                                                         abs=1e-9)
    assert seed["glass 0 thickness ≥ 1.9 mm"].value == pytest.approx(2 - (50 - math.sqrt(2500 - 16)), abs=1e-9)
    assert dense["angles of incidence/refraction"].value >= 30.0 - 1e-9
    assert dense["surface normals"].value > seed["surface normals"].value  # off-axis rays reach higher


def test_the_seed_sample_needs_the_optimization_sampling() -> None:
    system, model = _plate_on_axis_only()
    with pytest.raises(ValueError, match="sampling"):
        check_requirements(model.lens, system, Requirements(), glass_gaps=[True, False], sample="seed")
    with pytest.raises(ValueError, match="dense"):
        check_requirements(model.lens, system, Requirements(), glass_gaps=[True, False], sample="sparse")
