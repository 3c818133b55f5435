"""Binding varied glasses: a varied catalog glass stays in its own vendor's design catalog unless
``[optimize] catalog`` says otherwise, and the choice is one notice line (issue 29, item 5).

Independent oracle: the start glasses N-SK16 and F2 are Schott glasses of status "preferred" (read from
the catalog record), so in the Schott design catalog each is its own nearest glass: bound at the start
θ, each must come back as itself at distance 0; bound to the Ohara catalog, each must become an Ohara
glass.
"""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from lensopt.design import build_problem
from lensopt.design.writeback import bind_glasses
from lensopt.materials import catalog as cat_mod
from lensopt.materials import design_catalog, find_glass
from lensopt.spec.io import load_spec
from lensopt.spec.models import LensSpec, ModelGlassSpec

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(autouse=True)
def _fresh_notices(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(cat_mod, "_told", set())


def _cooke(first: str | ModelGlassSpec, catalog: str | None = None) -> LensSpec:
    spec = load_spec(ROOT / "specs" / "cooke_triplet_opt.toml")
    spec.surfaces[0].material = first
    for i in (0, 2):
        spec.surfaces[i].vary = [*spec.surfaces[i].vary, "material"]
    if catalog is not None:
        spec.optimize = spec.optimize.model_copy(update={"catalog": catalog})
    return spec


def _notices(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.getMessage().startswith("optimize.catalog")]


def test_schott_glasses_stay_schott(caplog: pytest.LogCaptureFixture) -> None:
    assert find_glass("schott:N-SK16").status == find_glass("schott:F2").status == "preferred"
    with caplog.at_level(logging.WARNING):
        problem = build_problem(_cooke("schott:N-SK16"))
        spec, bound = bind_glasses(problem, problem.theta0)
    assert problem.opt.catalog == "schott-preferred"
    assert [(b.surface, b.material) for b in bound] == [(0, "schott:N-SK16"), (2, "schott:F2")]
    assert all(b.distance < 1e-9 for b in bound)
    assert spec.optimize.catalog == "schott-preferred"  # the written lens records it
    assert _notices(caplog) == [
        "optimize.catalog: the glass variables start as schott glasses (surfaces 0, 2); they bind to "
        "schott-preferred, their vendor's design catalog; set [optimize] catalog to choose another"]


def test_spec_catalog_overrides_the_vendor(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING):
        problem = build_problem(_cooke("schott:N-SK16", catalog="ohara-recommended"))
        _, bound = bind_glasses(problem, problem.theta0)
    assert problem.opt.catalog == "ohara-recommended"
    ohara = set(design_catalog("ohara-recommended").names)
    assert all(b.name in ohara and str(b.material).startswith("ohara:") for b in bound)
    assert _notices(caplog) == [
        "optimize.catalog: the glass variables start as schott glasses (surfaces 0, 2); they bind to "
        "ohara-recommended, as [optimize] catalog says"]


def test_same_vendor_catalog_set_in_the_spec_is_silent(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING):
        problem = build_problem(_cooke("schott:N-SK16", catalog="schott-preferred"))
    assert problem.opt.catalog == "schott-preferred"
    assert _notices(caplog) == []


def test_mixed_or_model_starts_take_the_default_and_say_why(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING):
        mixed = build_problem(_cooke("SK16"))  # Hikari's SK16 (no Hikari design catalog) and Schott F2
        model = build_problem(_cooke(ModelGlassSpec(nd=1.62, vd=60.3)))
    assert mixed.opt.catalog == model.opt.catalog == "ohara-recommended"
    assert _notices(caplog) == [
        "optimize.catalog: the glass variables start as hikari glasses (surface 0), schott glasses "
        "(surface 2); they bind to ohara-recommended, the default design catalog, as lensopt has no design "
        "catalog of hikari; set [optimize] catalog to choose another",
        "optimize.catalog: the glass variables start as model glasses (surface 0), schott glasses "
        "(surface 2); they bind to ohara-recommended, the default design catalog, as they are not all from "
        "one vendor; set [optimize] catalog to choose another"]


def test_catalog_glass_missing_from_vendor_data_is_told(caplog: pytest.LogCaptureFixture) -> None:
    """A design-catalog glass that lensopt's vendor data lack is written as a model glass, with a notice."""
    missing = "S-NBM52"
    with pytest.raises(Exception, match="unknown glass"):
        find_glass(f"ohara:{missing}")
    i = design_catalog("ohara-recommended").names.index(missing)
    nd, vd, dpgf = design_catalog("ohara-recommended").values[i]
    spec = _cooke(ModelGlassSpec(nd=float(nd), vd=float(vd), dpgf=float(dpgf)), catalog="ohara-recommended")
    with caplog.at_level(logging.WARNING):
        problem = build_problem(spec)
        _, bound = bind_glasses(problem, problem.theta0)
    assert bound[0].name == missing and isinstance(bound[0].material, ModelGlassSpec)
    told = [r.getMessage() for r in caplog.records if r.getMessage().startswith("surfaces[0].material")]
    assert told == [f"surfaces[0].material: {missing} of ohara-recommended is not in lensopt's ohara data; "
                    f"written as a model glass (nd={nd:.5f}, vd={vd:.2f}, dpgf={dpgf:.4f})"]
