"""The seed's case-study specs in ``specs/`` (S4 telephoto, S4.2.2 hybrid, S5 microscope objective): each
parses, builds, holds its solves, encodes its table's numbers, traces its optimization rays with no
failure at its crude start, and takes an LM step with a finite merit."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch

from lensopt.design import build_problem, optimize
from lensopt.optics.paraxial import first_order
from lensopt.optim import Problem
from lensopt.spec import build, load_spec

SPECS = Path(__file__).resolve().parents[1] / "specs"
STUDIES = ["telephoto_5p_tr080.toml", "telephoto_5p1_middle_tr075.toml", "microscope_8p_wd12.toml",
           "microscope_8p_wd12_alt.toml"]


@pytest.fixture(scope="module", params=STUDIES)
def study(request: pytest.FixtureRequest) -> tuple[str, Problem]:
    spec = load_spec(SPECS / request.param)
    build(spec)
    return request.param, build_problem(spec)


def test_a_study_starts_with_every_optimization_ray_traced(study: tuple[str, Problem]) -> None:
    name, p = study
    failed, total, reasons = p.failure_summary(p.theta0)
    assert total > 0 and failed == 0, reasons
    ev = p.evaluate(p.theta0)
    assert ev.physical and bool(torch.isfinite(ev.residuals).all())


def test_a_study_holds_its_solves_and_first_order_numbers(study: tuple[str, Problem]) -> None:
    name, p = study
    lens, ok = p.lens(p.theta0)
    assert bool(ok)
    fo = first_order(lens, p.system)
    if name.startswith("telephoto"):
        # Table S8: EPD 9.25 mm, FOV 22.3° (HFOV 11.155°), image height 5.1 mm (solve), TTL = TR × 25.9 mm.
        tr = 0.80 if "tr080" in name else 0.75
        assert float(fo.epd) == pytest.approx(9.25)
        assert p.system.field_max == pytest.approx(22.3 / 2)
        assert float(fo.paraxial_image_height) == pytest.approx(5.1, rel=1e-12)
        assert float(fo.total_track) == pytest.approx(tr * 25.9, rel=1e-12)
        fa = p.system.front_aperture
        assert fa is not None and fa.diameter == pytest.approx(9.25) and fa.distance == pytest.approx(1.0)
        assert p.system.aim == "full"
    else:
        # Table S12: EFL 10 mm (solve), EPD 8 mm (f/1.25, NA 0.4), FOV 5.90° (HFOV 2.95°), WD 12 mm last gap.
        assert float(fo.efl) == pytest.approx(10.0, rel=1e-12)
        assert float(fo.epd) == pytest.approx(8.0)
        assert float(fo.fnumber) == pytest.approx(1.25, rel=1e-12)
        assert 2 * p.system.field_max == pytest.approx(5.90)
        assert float(lens.thickness[-1]) == 12.0
        assert p.spec.stop_index == 0 and p.system.front_aperture is None


def test_a_study_has_the_seeds_variables(study: tuple[str, Problem]) -> None:
    name, p = study
    kinds = [v.kind for v in p.param.variables]
    count = {k: kinds.count(k) for k in set(kinds)}
    if name == "telephoto_5p_tr080.toml":
        # S4.1.5: 90 variables = 11 spacings + 9 curvatures + 10 × 6 aspheric coefficients + 5 × 2 glass.
        assert p.num_variables == 90
        assert (count["thickness"], count["curvature"], count["asphere"]) == (11, 9, 60)
        assert p.num_glasses == 5 and p.space is not None and p.space.dims == 2
    elif name.startswith("telephoto_5p1"):
        # The 5P's 90, plus the diffractive plane's 4 phase coefficients and its place in the E4–E5
        # airspace (S4.2.2: the phase on its own plane in air between E4 and E5, as the published design).
        assert count["phase"] == 4 and count["thickness"] == 12 and p.num_variables == 95
        doe = [s for s, shape in enumerate(p.setup.lens.shapes) if shape.diffractive]
        assert len(doe) == 1 and p.setup.lens.shapes[doe[0]].kind == "plane"
        assert p.spec.surfaces[doe[0] - 1].is_air and p.spec.surfaces[doe[0]].is_air  # in air on both sides
    else:
        # S5.1.4: 16 spacings (of 17), 15 curvatures (of 16); all 8 glasses vary with ΔPgF (8 × 3).
        assert (count["thickness"], count["curvature"], p.num_glasses) == (16, 15, 8)
        assert p.space is not None and p.space.dims == 3


def test_a_study_spectrum_is_its_tables_average_channel(study: tuple[str, Problem]) -> None:
    # Tables S9 and S13 list R, G, B and their average: the spot-size weights must be the average
    # column, i.e. the mean of the RGB rows (to the tables' 4 decimals), over the tables' wavelengths.
    name, p = study
    spec = p.spec.spectrum
    rgb = torch.tensor(spec.rgb_weights, dtype=torch.float64)
    torch.testing.assert_close(torch.tensor(spec.weights, dtype=torch.float64), rgb.mean(1), atol=1e-4, rtol=0)
    start, step = (425.0, 25.0) if name.startswith("telephoto") else (400.0, 25.0)
    assert spec.wavelengths_nm == [start + step * i for i in range(11)]
    assert all(abs(float(c) - 1.0) < 2e-3 for c in rgb.sum(0))


def test_a_study_takes_an_lm_step_with_a_finite_merit(study: tuple[str, Problem]) -> None:
    # One step of the spec's own optimizer on a coarser pupil (rings:2) to keep the test short; no glass
    # binding (a run with a binding needs 10 steps per phase).
    name, _ = study
    spec = load_spec(SPECS / name)
    spec.optimize.sampling = "rings:2"
    spec.optimize.bind_at = 1.0
    res = optimize(spec, steps=1)
    merit = res.history[-1][2]
    assert res.steps == 1 and math.isfinite(res.start_merit) and math.isfinite(merit)
