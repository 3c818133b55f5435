"""CODE V round trip: export → import → export is byte-identical, and the imported lens traces to the
same image intercepts as the original (≤ 1e-10 mm), for every lens in specs/ and tests/interchange/data/.

The folder globs pick up lenses other engineers add to specs/ without changes here.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from lensopt.interchange.codev.read import import_codev
from lensopt.interchange.codev.write import export_codev
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.paraxial import first_order
from lensopt.optics.sampling import PupilSampling
from lensopt.spec import LensSpec, build, dump_json, load_spec

ROOT = Path(__file__).resolve().parents[2]
LENSES = sorted((ROOT / "specs").glob("*.toml")) + sorted((Path(__file__).parent / "data").glob("*.toml"))
IDS = [p.relative_to(ROOT).as_posix() for p in LENSES]
PUPIL = PupilSampling.parse("rings:6:nojitter")
INTERCEPT_TOL_MM = 1e-10


def _intercepts(spec: LensSpec) -> tuple[torch.Tensor, torch.Tensor]:
    model = build(spec)
    pts = PUPIL.points(dtype=torch.float64)
    # Full pupil (both halves), so that rays on both sides of the meridional plane are compared.
    pts = torch.cat([pts, pts * torch.tensor([-1.0, 1.0], dtype=torch.float64)])
    bundle = trace_bundle(model.lens, model.system, pts)
    return bundle.result.pos[..., :2], bundle.result.valid


_ORIGINAL: dict[str, tuple[torch.Tensor, torch.Tensor]] = {}


def _assert_same_trace(a: LensSpec, b: LensSpec) -> float:
    key = dump_json(a)
    if key not in _ORIGINAL:  # the original's trace is shared by the tests of one lens
        _ORIGINAL[key] = _intercepts(a)
    pos_a, ok_a = _ORIGINAL[key]
    pos_b, ok_b = _intercepts(b)
    assert torch.equal(ok_a, ok_b), "the two lenses fail different rays"
    assert ok_a.any(), "no ray reaches the image"
    dev = float((pos_a - pos_b)[ok_a].abs().max())
    assert dev <= INTERCEPT_TOL_MM, f"image intercepts differ by {dev:.3e} mm"
    return dev


def _strip_comments(text: str) -> str:
    return "\n".join(line for line in text.splitlines() if not line.lstrip().startswith("!")) + "\n"


def test_the_lens_folders_are_not_empty() -> None:
    assert (ROOT / "specs" / "cooke_triplet.toml") in LENSES
    assert len(LENSES) >= 4


@pytest.mark.parametrize("private", [False, True], ids=["catalog", "private"])
@pytest.mark.parametrize("path", LENSES, ids=IDS)
def test_export_import_export_is_byte_identical(path: Path, private: bool) -> None:
    spec = load_spec(path)
    first = export_codev(spec, private_catalog=private)
    again = export_codev(import_codev(first).spec, private_catalog=private)
    assert again == first


@pytest.mark.parametrize("path", LENSES, ids=IDS)
def test_imported_lens_traces_like_the_original(path: Path) -> None:
    spec = load_spec(path)
    imported = import_codev(export_codev(spec)).spec
    _assert_same_trace(spec, imported)
    # With lensopt's comments the import restores the spec itself (catalog names, model glasses,
    # exact phase coefficients and relative fields, f-number apertures); [optimize] and [restore] are
    # lensopt run settings, not part of the lens, and do not travel.
    assert dump_json(imported) == dump_json(spec.model_copy(update={"optimize": None, "restore": None}))


@pytest.mark.parametrize("path", LENSES, ids=IDS)
def test_the_codev_data_alone_define_the_same_lens(path: Path) -> None:
    # Without the "! lensopt:" comments only CODE V's own commands are read: private glasses become
    # tabulated glasses, phases come from HCO, fields from YAN/YIM. The only settings CODE V has no
    # command for are lensopt's aim mode and steps (CODE V files default to chief-ray aiming) and the
    # object-space front aperture.
    spec = load_spec(path)
    for private in (False, True):
        imported = import_codev(_strip_comments(export_codev(spec, private_catalog=private))).spec
        imported.system.aim = spec.system.aim
        imported.system.aim_steps = spec.system.aim_steps
        imported.system.front_aperture = spec.system.front_aperture
        _assert_same_trace(spec, imported)


@pytest.mark.parametrize("path", LENSES, ids=IDS)
def test_first_order_data_survive_the_round_trip(path: Path) -> None:
    spec = load_spec(path)
    for private in (False, True):
        imported = import_codev(_strip_comments(export_codev(spec, private_catalog=private))).spec
        a, b = (build(s) for s in (spec, imported))
        fa, fb = first_order(a.lens, a.system), first_order(b.lens, b.system)
        for name in ("efl", "bfl", "epd", "entrance_pupil_z", "exit_pupil_z", "working_fnumber"):
            va, vb = float(getattr(fa, name)), float(getattr(fb, name))
            assert vb == pytest.approx(va, rel=1e-12, abs=1e-12), name
