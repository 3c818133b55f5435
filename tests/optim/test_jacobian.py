"""The LM Jacobian: forward mode (jacfwd) equals reverse mode (jacrev) and central differences."""

from __future__ import annotations

import torch

from lensopt.design import build_problem
from lensopt.spec import parse_spec


def test_forward_mode_jacobian_equals_reverse_mode_and_finite_differences(make_cooke) -> None:  # noqa: ANN001
    # A small case touching every kind of variable and residual: radii, a thickness, a glass (3
    # whitened variables), an EFL solve; TRA, ray path (active in the thin glass), ray angle, distortion,
    # glass mesh and catalog distances.
    data = make_cooke(sampling="rings:2", catalog="schott-preferred", constraints={
        "ray_path": {"glass_min": 2.0, "air_min": 0.5, "image_min": 5.0},
        "ray_angle": {"max_deg": 25.0},
        "distortion": {"max_percent": 0.01},
        "glass_catalog": {"schedule": [[0.0, 0.3]]},
    }, solves=[{"type": "efl", "surface": -1, "value": 50.0}])
    data["surfaces"][0]["vary"] = ["radius", "thickness"]
    data["surfaces"][2]["vary"] = ["radius", "material"]
    p = build_problem(parse_spec(data))
    theta = p.theta0 + 1e-3 * torch.linspace(-1, 1, p.num_variables, dtype=torch.float64)
    J, r = p.jacobian(theta)
    torch.testing.assert_close(r, p.residuals(theta), rtol=0, atol=0)
    active = {name: float(r[sl].abs().max()) for name, sl in p.slices.items()}
    assert all(active[k] > 0 for k in ("tra", "ray_path", "ray_angle", "distortion", "glass_catalog")), active
    Jr = torch.func.jacrev(p.residuals)(theta)
    torch.testing.assert_close(J, Jr, rtol=1e-10, atol=1e-13)
    h = 1e-6
    for n in range(p.num_variables):
        e = torch.zeros_like(theta)
        e[n] = h
        fd = (p.residuals(theta + e) - p.residuals(theta - e)) / (2 * h)
        torch.testing.assert_close(J[:, n], fd, rtol=1e-5, atol=2e-8)
