"""Image simulation (S1.5) and image data. Everything here takes plain tensors and dataclasses
(``camera.Camera``), never a spec.

    camera.py     what imaging needs of a lens, as plain data
    scene.py      where a scene lies on the sensor: regions, pixel ↔ sensor-mm geometry
    pilot.py      a cheap pilot trace that tells a plan how the lens behaves across the field
    plan.py       the scene plan: what a simulation has to compute
    simulate.py   run a plan: PSFs, PSF grid, convolution, effects
    psf_grid.py   the PSF grid of S1.5.1 (RGB, sensor regions, rotation)
    rgb.py        wavelength → RGB weights (S4.1.2)
    rotate.py     energy-preserving PSF rotation (three shears)
    convolve.py   spatially varying convolution by overlap-add (S1.5.2)
    effects.py    distortion warp, relative illumination, sensor noise
    render.py     differentiable training batches (S1.5, S3.3.1)
    regions.py    sensor tiles and stratified draws (S3.3.1)
    datasets.py   dead-leaves scenes and image folders
    textured.py   textured dead leaves (photograph-like statistics), the power-spectrum slope
    sources.py    named scene sources (procedural, textured, photos, '+' mixtures), the bundled photographs
    evaluate.py   PSNR/SSIM of simulated captures (S4.3.1)
    metrics.py    PSNR and SSIM
    io.py         image files (OpenImageIO), colour encodings
"""
