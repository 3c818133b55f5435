"""OPD fans and Zernike coefficients against optiland 0.6.3 on the Cooke triplet, the double Gauss and
the microscope objective (``optiland_peer``: same prescription, aperture, fields, wavelengths, indices).

Conventions: both tools reference W to the real chief ray with a sphere centred on its image point,
sign ahead-positive (``W = OPL(chief) − OPL(ray)``), pupil coordinates the normalized entrance-pupil
coordinates. They differ in one place, the reference sphere (``analysis.wavefront`` docstring):

1. Radius: lensopt's sphere passes through the real chief ray's exit-pupil point (CODE V), optiland's
   through the on-axis exit-pupil point (Zemax), R_Z = |P0 − (0, 0, z_XP)|.
2. Which crossing: optiland takes the first crossing met going *backwards* from the image; lensopt the
   one through the exit pupil, which lies *behind* the image when the exit pupil is virtual (the
   microscope objective: z_XP = 61.6 mm, image at 49.4 mm).

``_to_optiland`` reproduces optiland's W from lensopt's by hand, ray by ray: with s the distance back
along the ray from its image point to a sphere, ``OPL_sphere = OPL_image − n' s``, so
``W_optiland − W_lensopt = n' [(t − s) − (t_chief − s_chief)]`` with s on lensopt's sphere and t on
optiland's. After it the two agree to 1e-8 relative; without it the differences are 1e-5 … 6e-3 relative
(asserted too, so that the correction is known to matter).
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

pytest.importorskip("optiland")

from optiland.distribution import create_distribution  # noqa: E402
from optiland.wavefront import OPDFan, ZernikeOPD  # noqa: E402

from lensopt.analysis.wavefront import trace_to_sphere, wavefront  # noqa: E402
from lensopt.analysis.zernike import fit_zernike  # noqa: E402
from lensopt.optics.paraxial import first_order  # noqa: E402
from tests.analysis.optiland_peer import optic_from_model, peer_model  # noqa: E402

pytestmark = [pytest.mark.filterwarnings("ignore::DeprecationWarning"),
              pytest.mark.filterwarnings("ignore:.*:numba.core.errors.NumbaIRAssumptionWarning")]

PEERS = ("cooke", "double_gauss", "microscope")
REL_TOL = 1e-6


def _to_optiland(model, pupil: torch.Tensor, rel_field: torch.Tensor | None = None) -> tuple[torch.Tensor, ...]:
    """(lensopt W, W converted to optiland's sphere, valid), each (F, W, P), waves."""
    lens, system = model.lens, model.system
    fo = first_order(lens, system)
    st = trace_to_sphere(lens, system, pupil, fo=fo, rel_field=rel_field)
    wf = wavefront(lens, system, pupil, fo=fo, rel_field=rel_field)
    q, d = st.bundle.result.pos, st.bundle.result.dir  # (F, W, 1+P, 3), index 0 = chief
    c = st.center[:, :, None, :]
    rel = q - c
    b = (d * rel).sum(-1)
    cc = (rel * rel).sum(-1)

    def roots(radius: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        # |q − s d − c|² = R²  ⇔  s² − 2 b s + |q − c|² − R² = 0
        disc = (b * b - cc + radius[..., None] ** 2).clamp_min(0.0).sqrt()
        return b - disc, b + disc

    lo, hi = roots(st.radius)
    behind = float(fo.exit_pupil_z) > float(lens.vertex_z()[-1])  # virtual exit pupil
    s = lo if behind else hi  # lensopt: the crossing through the exit pupil
    xp = torch.tensor([0.0, 0.0, float(fo.exit_pupil_z)], dtype=lens.dtype)
    lo_z, hi_z = roots(torch.linalg.vector_norm(st.center - xp, dim=-1))
    t = torch.where(lo_z >= 0, lo_z, hi_z)  # optiland: first crossing going backwards
    n_img = lens.index[-1][None, :, None]
    lam = lens.wavelength_um[None, :, None] * 1e-3
    corr = n_img * ((t[..., 1:] - s[..., 1:]) - (t[..., :1] - s[..., :1])) / lam
    return wf.opd, wf.opd + corr, wf.valid


@pytest.mark.parametrize("name", PEERS)
def test_opd_fans_match_optiland(name: str) -> None:
    model = peer_model(name)
    points = 24  # even: optiland's cross distribution keeps both arms whole
    fan = OPDFan(optic_from_model(model), num_rays=points)
    v = torch.linspace(-1.0, 1.0, points, dtype=torch.float64)
    zero = torch.zeros_like(v)
    pupil = torch.cat([torch.stack([zero, v], -1), torch.stack([v, zero], -1)])  # optiland's order: y arm, x arm
    raw, converted, valid = _to_optiland(model, pupil)
    assert bool(valid.all())
    worst_raw = worst = 0.0
    for f, fp in enumerate(fan.fields):
        for w, wp in enumerate(fan.wavelengths):
            ref = np.asarray(fan.get_data(fp, wp).opd, dtype=float)
            scale = np.abs(ref).max()
            worst = max(worst, np.abs(converted[f, w].numpy() - ref).max() / scale)
            worst_raw = max(worst_raw, np.abs(raw[f, w].numpy() - ref).max() / scale)
    assert worst <= REL_TOL * 1e-2, worst
    assert worst_raw > 10 * worst  # the reference-sphere convention is what the conversion accounts for


@pytest.mark.parametrize("name", PEERS)
@pytest.mark.parametrize("ordering,theirs", [("fringe", "fringe"), ("noll", "noll"), ("ansi", "standard")])
def test_zernike_coefficients_match_optiland(name: str, ordering: str, theirs: str) -> None:
    model = peer_model(name)
    optic = optic_from_model(model)
    dist = create_distribution("hexapolar")
    dist.generate_points(8)
    pupil = torch.stack([torch.as_tensor(np.asarray(dist.x)), torch.as_tensor(np.asarray(dist.y))], -1).double()
    ref_w = model.system.reference
    fields = model.system.rel_field
    for u in (fields[1], fields[-1]):  # an intermediate and the full field
        _, converted, valid = _to_optiland(model, pupil, torch.tensor([u], dtype=torch.float64))
        # 36 Fringe terms: optiland's Z37 follows the index pattern, (6, 6), where the Fringe set has its
        # exception, 12th-order spherical (analysis.zernike); the first 36 are the same polynomials.
        terms = 36 if ordering == "fringe" else 37
        zo = ZernikeOPD(optic, field=(0.0, float(u)), wavelength=optic.primary_wavelength, num_rings=8,
                        zernike_type=theirs, num_terms=terms)
        fit = fit_zernike(pupil, converted[0, ref_w], valid[0, ref_w], ordering=ordering, terms=terms)
        expect = np.asarray(zo.coeffs, dtype=float)
        got = fit.coefficients.numpy()
        assert np.abs(got - expect).max() <= REL_TOL * np.abs(expect).max(), (u, got[:9], expect[:9])
