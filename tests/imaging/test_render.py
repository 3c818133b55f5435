"""Differentiable rendering of training batches (lensopt.imaging.render): equal to ``lensopt simulate`` on
the same region and settings, uniform scenes stay uniform, gradients match central finite differences."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from lensopt.analysis.psf_stack import select_wavelengths
from lensopt.errors import LensoptError
from lensopt.imaging.plan import PlanOptions, parse_effects
from lensopt.imaging.render import RenderSettings, airy_for, psfs_from_spots, render_batch, render_lens, trace_spots
from lensopt.imaging.scene import Region, Sensor
from lensopt.imaging.simulate import plan_scene, run_plan
from lensopt.optics.paraxial import first_order
from lensopt.optics.sampling import PupilSampling


@pytest.mark.parametrize("region", ["corner", "tile:20,5/32x24"])
def test_rendered_patch_equals_lensopt_simulate(cooke, region: str) -> None:
    model = cooke
    img = np.random.default_rng(1).random((40, 40, 3), dtype=np.float32)
    options = PlanOptions(sampling="rings:8", grid=(3, 3))
    plan, pilot, reg, sensor = plan_scene(model, {"width": 40, "height": 40, "channels": 3}, region=region,
                                          effects=parse_effects("+convolution,-distortion,-ri,noise=0.005"),
                                          options=options)
    sim = run_plan(model, plan, pilot, reg, sensor, img, options)
    assert plan.effects["convolution"]["on"] and plan.effects["noise"]["on"]
    # The same settings through the batch renderer.
    lens, system = select_wavelengths(model.lens, model.system, plan.wavelength_index)
    rel = torch.tensor(plan.fields_relative, dtype=torch.float64)
    sampling = PupilSampling.parse("rings:8", seed=0)
    spots = trace_spots(lens, system, rel, sampling.points(dtype=torch.float64), half=sampling.half,
                        fo=first_order(model.lens, model.system))
    pitch = plan.psf["pitch_um"] * 1e-3
    settings = RenderSettings(psf_size=sim.psfs.psf.shape[-1], grid=(3, 3), overlap=plan.overlap,
                              noise_sigma=plan.effects["noise"]["sigma"], seed=plan.effects["noise"]["seed"],
                              diffraction=plan.diffraction["on"])
    airy = airy_for(spots, lens.wavelength_um, pitch, float(lens.index[-1, 0])) if settings.diffraction else None
    psf, center = psfs_from_spots(spots.xy, spots.valid, spots.wavelength_weights, half=spots.half, pitch_mm=pitch,
                                  settings=settings, airy=airy)
    torch.testing.assert_close(psf, sim.psfs.psf, rtol=0, atol=1e-12)
    ww = torch.tensor(plan.channel_weights, dtype=torch.float64)
    scene = torch.from_numpy(img).permute(2, 0, 1)[None]
    out = render_batch(psf, center, scene, [reg], sensor, ww, settings, pitch_mm=pitch)
    ref = torch.from_numpy(np.ascontiguousarray(sim.image)).permute(2, 0, 1)
    torch.testing.assert_close(out[0], ref, rtol=0, atol=1e-6)  # float32 rounding


def test_uniform_white_stays_uniform_away_from_the_borders(cooke) -> None:
    model = cooke
    sensor = Sensor(model.spec.sensor.pixel_pitch_um * 1e-3, 320, 240)
    regs = [Region(0.0, 0.0, 64, 64, 64, 64, "corner"), Region(128.0, 88.0, 64, 64, 64, 64, "centre")]
    white = torch.ones(2, 3, 64, 64)
    ww = torch.eye(3, dtype=torch.float64)[[2, 1, 0]]  # 480 → B, 550 → G, 650 → R
    settings = RenderSettings(psf_size=15, noise_sigma=0.0)
    out = render_lens(model.lens, model.system, torch.tensor([0.0, 0.5, 1.0], dtype=torch.float64),
                      PupilSampling.parse("rings:6"), white, regs, sensor, ww, settings)
    inner = out[..., 8:-8, 8:-8]
    assert float((inner - 1.0).abs().max()) < 1e-5


def test_gradient_wrt_a_curvature_equals_central_differences(cooke) -> None:
    model = cooke
    sensor = Sensor(model.spec.sensor.pixel_pitch_um * 1e-3, 320, 240)
    regs = [Region(250.0, 10.0, 24, 24, 24, 24, "edge")]
    scene = torch.rand(1, 3, 24, 24, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    probe = torch.rand(1, 3, 24, 24, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    ww = torch.eye(3, dtype=torch.float64)[[2, 1, 0]]
    settings = RenderSettings(psf_size=15, noise_sigma=0.0)
    rel = torch.tensor([0.0, 0.5, 1.0], dtype=torch.float64)
    sampling = PupilSampling.parse("rings:6")

    def f(c1: torch.Tensor) -> torch.Tensor:
        curv = torch.cat([model.lens.curvature[:1], c1.reshape(1), model.lens.curvature[2:]])
        lens = dataclasses.replace(model.lens, curvature=curv)
        return (render_lens(lens, model.system, rel, sampling, scene, regs, sensor, ww, settings) * probe).sum()

    c = model.lens.curvature[1].detach().clone().requires_grad_(True)
    (g,) = torch.autograd.grad(f(c), c)
    h = 1e-7 * abs(float(c.detach()))
    with torch.no_grad():
        fd = (f(c + h) - f(c - h)) / (2 * h)
    assert float(g) != 0.0
    assert abs(float(g) - float(fd)) <= 1e-4 * abs(float(fd))


@pytest.mark.parametrize("size", [0, -3, 48])
def test_psf_size_must_be_positive_and_odd(size: int) -> None:
    with pytest.raises(LensoptError, match="psf_size"):
        RenderSettings(psf_size=size)
