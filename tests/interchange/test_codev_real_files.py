"""Real CODE V files (written by CODE V; see tests/interchange/data/codev/README.md) import and trace, and their
first-order data match what CODE V wrote: PIM-solved back focal distances in the .seq files, and
CODE V's own listing of the double Gauss (ag_dblgauss.lis: LIS, FIO, SSP output)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch

from lensopt.analysis.report import ray_report
from lensopt.errors import SpecError
from lensopt.interchange.codev.read import read_codev
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.paraxial import first_order, trace_paraxial
from lensopt.optics.sampling import PupilSampling
from lensopt.spec import build

DATA = Path(__file__).parent / "data" / "codev"
TRACEABLE = ["CODV_32327.seq", "CODV_49664.seq", "CODV_65564.seq", "CODV_65988.seq", "ag_dblgauss.seq"]


@pytest.fixture(scope="module")
def dblgauss():
    return build(read_codev(DATA / "ag_dblgauss.seq").spec)


@pytest.mark.parametrize("name", TRACEABLE)
def test_real_files_import_and_trace(name: str) -> None:
    model = build(read_codev(DATA / name).spec)
    pupil = PupilSampling.parse("rings:8").points(dtype=torch.float64)
    bundle = trace_bundle(model.lens, model.system, pupil)
    assert bool(bundle.result.valid.all())
    assert bool(torch.isfinite(bundle.result.pos).all())


@pytest.mark.parametrize(("name", "pim"), [
    ("CODV_32327.seq", 95.95194415183156),  # last S line: thickness solved by CODE V's PIM
    ("CODV_65564.seq", 0.9176749924408083),  # idem
    ("ag_dblgauss.seq", 61.4875364179821),  # idem (SI adds the defocus -0.40 after it)
])
def test_pim_solved_thickness_is_the_paraxial_back_focus(name: str, pim: float) -> None:
    # CODE V's PIM solve puts the last thickness at the paraxial focus of the reference wavelength,
    # i.e. it equals the BFL. The Schott Sellmeier data are the same in both programs, so the numbers
    # agree to a few ulp (measured: 2e-16 relative).
    model = build(read_codev(DATA / name).spec)
    fo = first_order(model.lens, model.system)
    assert float(fo.bfl) == pytest.approx(pim, rel=1e-12)


def test_dblgauss_first_order_data_match_the_codev_listing(dblgauss) -> None:
    # ag_dblgauss.lis, "INFINITE CONJUGATES" block (CODE V 10.8), printed to 4 decimals: compare to
    # half a unit of the last digit.
    fo = first_order(dblgauss.lens, dblgauss.system)
    tol = 0.5e-4
    assert float(fo.efl) == pytest.approx(100.0038, abs=tol)
    assert float(fo.bfl) == pytest.approx(61.4875, abs=tol)
    assert float(fo.ffl) == pytest.approx(-29.3208, abs=tol)
    assert float(fo.fnumber) == pytest.approx(2.0001, abs=tol)
    assert float(fo.image_distance) == pytest.approx(61.0873, abs=tol)  # IMG DIS (with SI defocus)
    z_last = float(fo.total_track - fo.image_distance)
    assert z_last == pytest.approx(77.9674, abs=tol)  # OAL: surface 1 to the last surface
    assert float(fo.epd) == pytest.approx(50.0, abs=tol)  # ENTRANCE PUPIL DIA
    assert float(fo.entrance_pupil_z) == pytest.approx(57.9120, abs=tol)  # ENTRANCE PUPIL THI
    assert float(fo.exit_pupil_diameter) == pytest.approx(57.3201, abs=tol)  # EXIT PUPIL DIA
    assert float(fo.exit_pupil_z) - z_last == pytest.approx(-53.1569, abs=tol)  # EXIT PUPIL THI (from S11)
    # PARAXIAL IMAGE HT is given on the paraxial image plane; lensopt's is on the (defocused) image
    # surface, which FIO lists as the chief ray's HCY at IMG (24.846684).
    assert float(fo.paraxial_image_height) == pytest.approx(24.846684, abs=0.5e-6)
    u_chief = 0.217488  # FIO: UCY at IMG
    at_focus = float(fo.paraxial_image_height) - u_chief * float(dblgauss.spec.image.defocus)
    assert at_focus == pytest.approx(24.9337, abs=tol)


# ag_dblgauss.lis, "REFRACTIVE INDICES" (656.30, 587.60, 486.10 nm), 6 decimals.
INDICES = {1: (1.618769, 1.622292, 1.630455), 3: (1.604134, 1.607379, 1.614860),
           4: (1.598744, 1.603417, 1.614617), 8: (1.617271, 1.620408, 1.627559)}


def test_dblgauss_catalog_indices_match_the_codev_listing(dblgauss) -> None:
    for surface, values in INDICES.items():
        got = dblgauss.lens.index[surface].tolist()  # medium after surface `surface`
        assert got == pytest.approx(values, abs=0.5e-6), surface


# ag_dblgauss.lis, FIO at 587.6 nm: HMY, UMY (marginal ray), HCY, UCY (chief ray at YAN 14°) at EP,
# surfaces 1…11 and IMG; the EP row holds the ray entering surface 1.
FIO = [
    (25.000000, -0.170628, -14.439084, 0.252237), (23.507005, -0.180751, -12.232008, 0.359218),
    (23.416630, -0.347265, -12.052399, 0.344338), (19.075817, -0.348123, -7.748170, 0.345189),
    (17.752950, -0.116096, -6.436452, 0.393199), (15.852527, -0.116096, 0.000000, 0.393199),
    (14.256448, 0.116660, 5.405685, 0.316914), (14.699756, 0.115437, 6.609960, 0.313591),
    (15.969559, -0.074185, 10.059465, 0.343587), (15.932466, -0.080166, 10.231259, 0.189957),
    (15.371307, -0.249991, 11.560961, 0.217488), (0.100063, -0.249991, 24.846684, 0.217488),
]


def test_dblgauss_paraxial_rays_match_codev_fio(dblgauss) -> None:
    lens, w = dblgauss.lens, dblgauss.system.reference
    fo = first_order(lens, dblgauss.system)
    n = lens.index[:, w]
    one = torch.tensor(1.0, dtype=torch.float64)
    y_m, om_m = trace_paraxial(lens, w, 25.0 * one, 0.0 * one)
    tan = math.tan(math.radians(14.0))
    y_c, om_c = trace_paraxial(lens, w, -tan * fo.entrance_pupil_z, tan * one)
    for s, (hmy, umy, hcy, ucy) in enumerate(FIO):
        # After surface s (1-based row s+1 of the table) the reduced angle is ω = n u.
        medium = min(s + 1, lens.num_surfaces)
        assert float(y_m[s]) == pytest.approx(hmy, abs=0.5e-6), s
        assert float(om_m[medium] / n[medium]) == pytest.approx(umy, abs=0.5e-6), s
        assert float(y_c[s]) == pytest.approx(hcy, abs=0.5e-6), s
        assert float(om_c[medium] / n[medium]) == pytest.approx(ucy, abs=0.5e-6), s


# ag_dblgauss.lis, SSP at 587.6 nm: the on-axis ray through the pupil edge in x. Per surface: X, local
# Z (sag), TAN X after the surface, angles of incidence and refraction (degrees, 2 decimals).
SSP = [
    (25.000000, 5.866433, -0.185302, 26.41, 15.91), (24.109772, 1.920632, -0.200953, 1.39, 2.25),
    (22.844992, 7.714534, -0.394267, 25.96, 15.80), (20.958242, 0.000000, -0.395393, 21.52, 21.57),
    (16.784894, 6.754936, -0.112583, 22.27, 37.42), (15.702464, 0.000000, -0.112583, 6.42, 6.42),
    (14.610682, -4.050377, 0.153430, 37.41, 22.27), (15.815163, 0.000000, 0.151784, 8.72, 8.63),
    (16.882946, -3.965091, -0.057039, 17.80, 29.70), (16.583956, 0.776812, -0.071127, 2.10, 1.30),
    (16.261006, -1.682704, -0.258832, 15.88, 26.33),
]


def test_dblgauss_real_ray_matches_codev_ssp(dblgauss) -> None:
    # The entrance pupil lies 57.9 mm behind surface 1, inside the lens; this ray found a core bug
    # (quadric root choice for rays starting behind the centre of curvature).
    report = ray_report(dblgauss, field_deg=0.0, px=1.0, py=0.0, wavelength_nm=587.6)
    assert report["status"] == "ok"
    vertex = dblgauss.lens.vertex_z().tolist()
    for surf, (x, z, tan_x, aoi, aor) in zip(report["surfaces"], SSP, strict=True):
        k = surf["surface"] - 1
        assert surf["x"] == pytest.approx(x, abs=0.5e-6), k
        assert surf["z"] - vertex[k] == pytest.approx(z, abs=0.5e-6), k
        assert surf["L"] / surf["N"] == pytest.approx(tan_x, abs=0.5e-6), k
        assert surf["aoi_deg"] == pytest.approx(aoi, abs=0.5e-2), k
        assert surf["aor_deg"] == pytest.approx(aor, abs=0.5e-2), k


def test_dblgauss_codes_and_vignetting_are_read() -> None:
    result = read_codev(DATA / "ag_dblgauss.seq")
    spec = result.spec
    assert result.warnings[0] == "ignored CODE V solves and variable codes: CCY, THC, PIM"
    assert spec.system.vignetting is not None
    assert spec.system.vignetting.superior == [0.0, 0.2, 0.4]  # VUY
    assert spec.system.vignetting.inferior == [0.0, 0.25, 0.4]  # VLY
    assert spec.image.defocus == -0.4002686453541377  # SI
    assert spec.surfaces[5].stop and spec.surfaces[5].type == "plane"
    assert spec.surfaces[0].radius == pytest.approx(1.0 / 0.01779284094091543, rel=1e-15)  # RDM N


def test_private_and_fictitious_glasses_of_edmund_files() -> None:
    hybrid = read_codev(DATA / "CODV_65988.seq").spec
    glass = hybrid.surfaces[0].material
    assert glass.name == "E48" and len(glass.wavelengths_nm) == 20
    model = build(hybrid)
    # 587.6 nm is not a lens wavelength here (587.5618), but 587.6 is a node: spline through it.
    assert float(model.media[1].index(torch.tensor(0.5876, dtype=torch.float64))) == 1.53116
    assert hybrid.surfaces[0].type == "diffractive" and hybrid.surfaces[0].base.type == "asphere"
    achromat = read_codev(DATA / "CODV_49664.seq").spec
    layer = achromat.surfaces[2].material  # 517000.520000: n_d 1.517, V_d 52.0
    assert (layer.nd, layer.vd, layer.dpgf) == (1.517, 52.0, 0.0)


def test_mirror_file_is_refused_with_a_clear_message() -> None:
    with pytest.raises(SpecError, match=r"CODV_35571\.seq: line \d+ .*mirrors \(REFL\) are not supported yet"):
        read_codev(DATA / "CODV_35571.seq")
