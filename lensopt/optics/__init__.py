"""The differentiable core: pure batched torch functions over tensors; no printing, no global dtype/device
(DESIGN.md rules 1–3).

    lens.py        the traced lens and system: frozen dataclasses of tensors
    surfaces.py    sag, slope, normals, diffractive phase gradients
    intersect.py   ray–surface intersection: closed form and Newton
    interact.py    vector Snell and the generalized law of refraction
    placement.py   decentered and tilted surfaces (rigid frames)
    paraxial.py    first-order optics (y–ω transfer matrices)
    sampling.py    pupil sampling schemes and object-space ray bundles
    aiming.py      ray aiming (chief, full)
    vignetting.py  vignetting factors: the pupil per field and wavelength
    trace.py       the eager sequential trace, RayTrace, failure reasons
    bundle.py      trace a system: aiming + vignetting + trace (on the ``Engine``'s backend)
    transforms.py  what the core may do under torch transforms (early exits, forward mode)
    differential.py  forward-mode derivatives of a trace, surface by surface (the staged LM Jacobian)

The compiled traces (torch.compile, AOT packages) and the choice between them are ``lensopt.accel``.
"""
