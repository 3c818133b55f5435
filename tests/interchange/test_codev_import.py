"""CODE V import: syntax, units, radius/curvature mode, apertures, fields, glasses, refusals."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch

from lensopt.errors import SpecError
from lensopt.interchange.codev.names import fictitious_glass
from lensopt.interchange.codev.read import import_codev
from lensopt.interchange.codev.syntax import split_commands
from lensopt.interchange.codev.write import export_codev
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.paraxial import first_order
from lensopt.optics.sampling import PupilSampling
from lensopt.spec import build, load_spec

DATA = Path(__file__).parent / "data"

SINGLET = """RDM Y
TITLE 'singlet'
DIM M
{aperture}
{field}
WL 486.1327 587.5618 656.2725
REF 2
SO 0 {object}
S 51.68 5.0 NBK7_SCHOTT
  STO
S -51.68 {image}
SI 0 0
GO
"""


def _singlet(aperture: str = "EPD 10", field: str = "YAN 0 5", obj: str = "1e10", image: str = "48.0") -> str:
    return SINGLET.format(aperture=aperture, field=field, object=obj, image=image)


def _intercepts(spec) -> torch.Tensor:
    model = build(spec)
    pts = PupilSampling.parse("rings:5:nojitter").points(dtype=torch.float64)
    return trace_bundle(model.lens, model.system, pts).result.pos


def test_syntax_semicolons_continuations_comments_quotes() -> None:
    text = "RDM;LEN ! comment; not a command\nTITLE 'a ; b ! c'\nA 1.0; B&\n   2.0\n  'E48' 1.5 1.6\n"
    cmds = [c.tokens for c in split_commands(text).commands]
    assert cmds == [("RDM",), ("LEN",), ("TITLE", "a ; b ! c"), ("A", "1.0"), ("B", "2.0"), ("E48", "1.5", "1.6")]


def test_curvature_mode_gives_the_same_lens() -> None:
    radius = _singlet()
    curvature = radius.replace("RDM Y", "RDM N").replace("S 51.68", f"S {1 / 51.68!r}").replace(
        "S -51.68", f"S {-1 / 51.68!r}")
    a, b = import_codev(radius).spec, import_codev(curvature).spec
    assert b.surfaces[0].radius == pytest.approx(a.surfaces[0].radius, rel=1e-15)
    assert torch.allclose(_intercepts(a), _intercepts(b), rtol=0, atol=1e-12)


def test_without_rdm_the_surface_lines_hold_curvatures() -> None:
    # CODE V's default is curvature mode; rayoptics reads it so too (its hand-written test files
    # singlet.seq and landscape_lens.seq have no RDM and give curvatures, e.g. "s 0.1 1 nbk7_schott").
    text = _singlet().replace("RDM Y\n", "").replace("S 51.68", f"S {1 / 51.68!r}").replace(
        "S -51.68", f"S {-1 / 51.68!r}").lower()
    spec = import_codev(text).spec
    assert spec.surfaces[0].radius == pytest.approx(51.68, rel=1e-15)
    assert spec.surfaces[0].material == "schott:N-BK7"


@pytest.mark.parametrize("name", ["asphere_plastic.toml", "hybrid_diffractive.toml", "finite_relay.toml"])
def test_inches_scale_every_length(name: str) -> None:
    # The same numbers read as inches make the same lens 25.4× larger: asphere (mm^(1−p)) and HCO
    # coefficients included. Wavelengths stay in nm; refraction and the grating law are scale-free.
    spec = load_spec(DATA / name)
    text = "\n".join(line for line in export_codev(spec).splitlines() if not line.startswith("!"))
    mm = import_codev(text).spec
    inch = import_codev(text.replace("DIM M", "DIM I")).spec
    fa, fb = (first_order(build(s).lens, build(s).system) for s in (mm, inch))
    assert float(fb.efl) == pytest.approx(25.4 * float(fa.efl), rel=1e-12)
    pa, pb = _intercepts(mm), _intercepts(inch)
    assert torch.allclose(pb, 25.4 * pa, rtol=1e-11, atol=1e-10)


def test_fictitious_glass_codes() -> None:
    # CODE V fictitious glass codes: integer part = digits of n_d − 1, fraction = V_d / 100; and the
    # six-digit MIL code nnnvvv (BK7 = 517642: n_d 1.517, V_d 64.2).
    assert fictitious_glass("516800.641700") == (1.5168, 64.17)
    assert fictitious_glass("517000.520000") == (1.517, 52.0)
    assert fictitious_glass("517642") == (1.517, 64.2)
    assert fictitious_glass("NBK7_SCHOTT") is None
    spec = import_codev(_singlet().replace("NBK7_SCHOTT", "516800.641700")).spec
    assert spec.surfaces[0].material.nd == 1.5168 and spec.surfaces[0].material.vd == 64.17


def test_solves_and_unmodelled_commands_give_one_warning_each() -> None:
    text = _singlet().replace("  STO", "  STO\n  CCY 0; THC 0\n  THI HMY 0\n  TEM 20")
    text = text.replace("SI 0 0", "  PIM\nSI 0 0")
    result = import_codev(text)
    assert result.warnings == ["ignored CODE V solves and variable codes: CCY, THC, THI HMY, PIM",
                               "ignored CODE V commands lensopt does not model: TEM"]


def test_unknown_glass_lists_close_catalog_matches() -> None:
    with pytest.raises(SpecError, match=r"line 9: CODE V glass 'NBK77_SCHOTT': .*close matches: N-BK7 \(schott\)"):
        import_codev(_singlet().replace("NBK7_SCHOTT", "NBK77_SCHOTT"))
    with pytest.raises(SpecError, match=r"unknown CODE V glass catalog 'ACME'"):
        import_codev(_singlet().replace("NBK7_SCHOTT", "NBK7_ACME"))


def test_catalog_names_without_suffix_and_with_hyphens() -> None:
    for name in ("NBK7", "N-BK7_SCHOTT", "nbk7_schott"):
        spec = import_codev(_singlet().replace("NBK7_SCHOTT", name)).spec
        assert spec.surfaces[0].material == "schott:N-BK7"


def test_object_height_field_becomes_the_angle_of_the_same_chief_ray() -> None:
    # CODE V's YOB h: object point at height h whose chief ray aims at the paraxial entrance pupil.
    spec = import_codev(_singlet(field="YOB 0 3 7.5", obj="250", image="60")).spec
    model = build(spec)
    pupil = torch.zeros(1, 2, dtype=torch.float64)
    bundle = trace_bundle(model.lens, model.system, pupil)
    start_y = bundle.rays.pos[:, 0, 0, 1].abs()
    assert start_y.tolist() == pytest.approx([0.0, 3.0, 7.5], abs=1e-12)
    assert float(bundle.rays.pos[0, 0, 0, 2]) == -250.0


@pytest.mark.parametrize(("aperture", "obj"), [("FNO 4", "300"), ("NA 0.1", "1e10"), ("NA 0.1", "300"),
                                               ("NAO 0.02", "300")])
def test_image_and_object_space_apertures(aperture: str, obj: str) -> None:
    spec = import_codev(_singlet(aperture=aperture, obj=obj)).spec
    model = build(spec)
    fo = first_order(model.lens, model.system)
    key, value = aperture.split()
    v = float(value)
    if key == "FNO":  # finite conjugates: CODE V's FNO is the working f-number
        assert float(fo.working_fnumber) == pytest.approx(v, rel=1e-12)
    elif key == "NA":  # paraxial marginal slope tan(asin(NA)) in image space (air)
        assert 1.0 / (2.0 * float(fo.working_fnumber)) == pytest.approx(math.tan(math.asin(v)), rel=1e-12)
    else:  # NAO: marginal slope in object space from the axial object point to the pupil edge
        slope = float(fo.epd) / 2.0 / (float(obj) + float(fo.entrance_pupil_z))
        assert slope == pytest.approx(math.tan(math.asin(v)), rel=1e-12)


def test_fno_with_an_infinite_object_is_the_fnumber() -> None:
    spec = import_codev(_singlet(aperture="FNO 5.5")).spec
    assert spec.system.aperture.fnumber == 5.5 and spec.system.object == "infinity"


def test_qualified_surface_commands_and_negative_fields() -> None:
    text = _singlet(field="YAN 0 -5").replace("GO", "RDY S1 60.0\nTHI S1 4.0\nGO")
    result = import_codev(text)
    assert result.spec.surfaces[0].radius == 60.0 and result.spec.surfaces[0].thickness == 4.0
    assert result.spec.system.field.hfov_deg == 5.0
    assert any("negative YAN" in w for w in result.warnings)


def test_diffractive_power_follows_codev_definition() -> None:
    # Hand derivation from CODE V's DOE definition (OPD = C1 r² lens units at HWL, order m, deflection
    # m (λ/λ0) ∇OPD): a thin lens of power P adds OPD −P r²/2, so P = −2 m C1 λ/λ0. With C1 = −0.001,
    # m = 2, λ = 600 nm, λ0 = 500 nm: P = 0.0048 /mm, EFL = 208.333… mm.
    text = """RDM Y
DIM M
EPD 5
YAN 0 1
WL 600
SO 0 1e10
S 0 200
  STO
  DIF DOE
  HOR 2
  HWL 500; HCT R
  HCO C1 -0.001
SI 0 0
GO
"""
    spec = import_codev(text).spec
    model = build(spec)
    assert float(first_order(model.lens, model.system).efl) == pytest.approx(1 / 0.0048, rel=1e-13)
    assert spec.surfaces[0].phase == {2: pytest.approx(-0.001 * 2 * math.pi / 500e-6, rel=1e-15)}


@pytest.mark.parametrize(("edit", "message"), [
    (("  STO", "  STO\n  YDE 0.5"), "decentered or tilted surfaces are not supported"),
    (("SI 0 0", "SI -100 0"), "curved image surfaces are not supported"),
    (("YAN 0 5", "YAN 0 5\nXAN 0 2"), "x fields are not supported"),
    (("YAN 0 5", "YRI 0 5"), "real-image-height fields are not supported"),
    (("  STO", "  STO\n  DIF HOE"), "only DIF DOE"),
    (("S -51.68", "S -51.68 0.0 REFL\nS 0"), r"mirrors \(REFL\) are not supported yet"),
    (("EPD 10", ""), "no aperture"),
    (("WL 486.1327 587.5618 656.2725", ""), "no wavelengths"),
])
def test_unsupported_content_is_refused(edit: tuple[str, str], message: str) -> None:
    with pytest.raises(SpecError, match=message):
        import_codev(_singlet().replace(*edit))


def test_zero_decenters_are_accepted() -> None:
    import_codev(_singlet().replace("  STO", "  STO\n  XDE 0.0; YDE 0.0; ZDE 0.0"))


def test_formula_private_glasses_are_refused_only_when_used() -> None:
    prv = "PRV\nPWL 550.0\n'NOA61' LAU 2.36 0.0 0.025\nEND\n"
    import_codev(prv + _singlet())  # defined but unused: fine
    with pytest.raises(SpecError, match="private glass 'NOA61' is given by a formula"):
        import_codev(prv + _singlet().replace("NBK7_SCHOTT", "'NOA61'"))


def test_stale_lensopt_comments_are_ignored() -> None:
    # A comment that no longer agrees with the CODE V data (someone edited the file) is not used.
    spec = load_spec(DATA / "hybrid_diffractive.toml")
    text = export_codev(spec).replace("HCO C1 -0.00088837696599873", "HCO C1 -0.0009")
    imported = import_codev(text).spec
    assert imported.surfaces[0].phase[2] == pytest.approx(-0.0009 * 2 * math.pi / 587.5618e-6, rel=1e-14)
    text = export_codev(spec).replace("'LOMODEL' 1.6168604781814935", "'LOMODEL' 1.6168")
    assert imported.surfaces[0].material != import_codev(text).spec.surfaces[0].material
