"""The differentiable core: pure batched torch functions over tensors; no printing, no global dtype/device
(DESIGN.md rules 1–3).

    lens.py        the traced lens and system: frozen dataclasses of tensors
    surfaces.py    sag, slope, normals, diffractive phase gradients
    intersect.py   ray–surface intersection: closed form and Newton
    interact.py    vector Snell and the generalized law of refraction
    placement.py   decentered and tilted surfaces (rigid frames)
    paraxial.py    first-order optics (y–ω transfer matrices)
    sampling.py    pupil sampling schemes and object-space ray bundles
    aiming.py      ray aiming (chief, full); its detached solves can be handed back (ChiefSolve, FullSolve)
    vignetting.py  vignetting factors: the pupil per field and wavelength
    trace.py       the eager sequential trace (one step function per surface), RayTrace, failure reasons
    bundle.py      trace a system: aiming + vignetting (launch_bundle) + trace (finish_bundle), on the
                   ``Engine``'s backend
    transforms.py  what the core may do under torch transforms: stop solves early, skip derivative-only work
    differential.py  the trace's derivatives surface by surface (local derivatives chained): the LM Jacobian

The compiled traces (torch.compile, AOT packages) and the choice between them are ``lensopt.accel``.
"""
