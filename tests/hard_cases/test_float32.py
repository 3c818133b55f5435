"""Whole lenses traced in float32 against float64: the Cooke triplet (``specs/cooke_triplet.toml``) and
a lens with an even asphere (Newton), a diffractive surface on a conic base and the stop inside,
with and without chief-ray aiming.

Tolerance from ``torch.finfo(float32).eps``: every surface adds a few ulps of direction error, which
grows linearly over the remaining path, so image coordinates may differ by about
S · eps · (total track); the tests allow twice that (Cooke triplet: 8.6e-5 mm; measured 1.3e-5 mm).
The RMS spot radius about the centroid is 1-Lipschitz in the image coordinates (centering is a
projection), so it may differ by no more than the same absolute amount.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import torch

from lensopt.analysis.spot import spot_stats
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.sampling import pupil_rings
from lensopt.optics.trace import failure_counts
from lensopt.spec import build, load_spec
from lensopt.spec.models import LensSpec
from tests.helpers import COOKE

HYBRID = Path(__file__).resolve().parents[1] / "data" / "hybrid_triplet.toml"


def _spec(name: str) -> LensSpec:
    return load_spec(COOKE) if name == "cooke" else load_spec(HYBRID)


def _run(spec: LensSpec, dtype: torch.dtype, aim: str):
    model = build(spec, dtype=dtype)
    leaves = {n: getattr(model.lens, n).clone().requires_grad_(True) for n in ("curvature", "thickness", "index")}
    lens = dataclasses.replace(model.lens, **leaves)
    bundle = trace_bundle(lens, model.system, pupil_rings(8, dtype=dtype), half_pupil=True, aim=aim)
    stats = spot_stats(bundle, model.system.wavelength_weights)
    grads = torch.autograd.grad(stats.effective_radius, list(leaves.values()))
    return model, bundle, stats, grads


@pytest.mark.parametrize(("name", "aim"), [("cooke", "none"), ("cooke", "chief"), ("hybrid", "chief")])
def test_float32_trace_matches_float64(name: str, aim: str) -> None:
    spec = _spec(name)
    m64, b64, s64, g64 = _run(spec, torch.float64, aim)
    m32, b32, s32, g32 = _run(spec, torch.float32, aim)
    assert b32.result.pos.dtype == torch.float32 and s32.rms_radius.dtype == torch.float32
    for out in (b32.result.pos, b32.result.dir, s32.rms_radius, *g32):
        assert bool(torch.isfinite(out).all())
    assert failure_counts(b32.result) == failure_counts(b64.result)
    eps = torch.finfo(torch.float32).eps
    track = float(m64.lens.thickness.sum())
    tol = 2 * m64.lens.num_surfaces * eps * track
    err = float((b32.result.pos[..., :2].double() - b64.result.pos[..., :2]).abs().max())
    assert err <= tol, (err, tol)
    rms_err = float((s32.rms_radius.double() - s64.rms_radius).abs().max())
    assert rms_err <= tol, (rms_err, tol)
    # The gradient of the spot radius is Σ (x − x̄) ∂x/∂θ / SR: its relative error is about the position
    # error over the spot radius (Cooke triplet: bound 6e-3, measured 1e-3).
    bound = tol / float(s64.effective_radius)
    for a, b in zip(g32, g64, strict=True):
        assert float((a.double() - b).norm() / b.norm()) <= bound
