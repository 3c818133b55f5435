"""BINARY_2 (Zemax's rotationally symmetric diffractive phase Φ = M Σ Aᵢ ρ²ⁱ, ρ = r/R, Aᵢ in radians) against
the closed form of that definition: a flat binary surface in air with A₁ has focal length π R² / (M λ |A₁|)
and deflects a ray at height r by sin θ = (λ/2π) dΦ/dr = λ M A₁ r / (π R²). (No Python peer reads BINARY_2,
so the file layout — PARM 0 order, XDAT 1 terms, XDAT 2 = R, XDAT 3… = Aᵢ — is the one lensopt writes.)"""

from __future__ import annotations

import math

import pytest
import torch

from lensopt.interchange.zemax.read import import_zemax
from lensopt.interchange.zemax.write import export_zemax
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.paraxial import first_order
from lensopt.spec import build

R, LAM_UM, A1 = 10.0, 0.55, -1000.0
TEXT = f"""MODE SEQ
UNIT MM X W X CM MR CPMM
ENPD 4
FTYP 0 0 1 1 0 0 0
YFLN 0
WAVM 1 {LAM_UM} 1
PWAV 1
SURF 0
  TYPE STANDARD
  CURV 0
  DISZ INFINITY
SURF 1
  STOP
  TYPE BINARY_2
  CURV 0
  PARM 0 {{order}}
  XDAT 1 2
  XDAT 2 {R}
  XDAT 3 {A1}
  XDAT 4 0
  DISZ 500
SURF 2
  TYPE STANDARD
  CURV 0
  DISZ 0
"""


@pytest.mark.parametrize("order", [1, 2])
def test_binary2_power_and_deflection_follow_zemax_definition(order: int) -> None:
    spec = import_zemax(TEXT.format(order=order)).spec
    surf = spec.surfaces[0]
    assert surf.type == "diffractive" and surf.order == order
    model = build(spec)
    lam_mm = LAM_UM * 1e-3
    assert float(first_order(model.lens, model.system).efl) == pytest.approx(
        math.pi * R * R / (order * lam_mm * abs(A1)), rel=1e-12)
    bundle = trace_bundle(model.lens, model.system, torch.tensor([[0.0, 0.5]], dtype=torch.float64))
    r = 1.0  # pupil 0.5 of a 4 mm EPD
    assert float(bundle.result.dir[0, 0, 0, 1]) == pytest.approx(lam_mm * order * A1 * r / (math.pi * R * R), rel=1e-12)


def test_binary2_round_trip() -> None:
    spec = import_zemax(TEXT.format(order=1)).spec
    back = import_zemax(export_zemax(spec)).spec
    assert back.surfaces[0].phase == spec.surfaces[0].phase
    assert back.surfaces[0].order == 1
