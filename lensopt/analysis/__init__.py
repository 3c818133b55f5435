"""Analyses of a traced lens (plain tensors in, plain data out; no spec).

    spot.py             centroids, RMS spot radius per field (S23–S24), effective spot radius (S4.2.1),
                        the seed's ESR measure (11 fields, dense pupil)
    spot_diagram.py     spot diagrams (S1.3.3): image-surface positions per field and wavelength
    fans.py             ray fans (S1.3.4): transverse aberrations along the pupil axes
    field.py            per-field summary: distortion, relative illumination, the pupil each field fills
    distortion.py       distortion per field (S48)
    illumination.py     relative illumination from image-space direction cosines (S51–S52)
    irradiance.py       reference relative illumination by flux counting (brute force)
    psf.py              geometric PSFs (S1.4.1–S1.4.2): ray counting and kernel density estimation
    psf_diffraction.py  the diffraction heuristic of S1.4.3
    psf_stack.py        PSF stacks K[F, W, S, S] of a lens (S1.4)
    psf_reference.py    reference diffraction PSF from the exit-pupil field (validation)
    wavefront.py        the one home of the OPD: reference sphere, fans, maps, RMS/P-V, differentiable RMS
    zernike.py          Zernike fits (Fringe, Noll/Standard, ANSI orderings)
    strehl.py           Strehl ratio from the PSF peak and the Maréchal estimate
    seidel.py           third-order (Seidel) sums per surface and total, axial and lateral colour
    field_curves.py     field curvature, distortion, lateral colour vs field; chromatic focal shift
    encircled.py        encircled and ensquared energy (geometric and diffraction)
    mtf.py              MTF from PSFs, sagittal and tangential, per field
    mtf_field.py        MTF vs field and through focus
    checks.py           argument checks of the analyses (field, frequency, wavelength): one-line errors
    layout.py           geometry and meridional ray paths of a 2D layout drawing
    requirements.py     a lens held to a table of requirements (Tables S8, S12)
    report.py           plain-data reports: trace_report, ray_report, mtf_report (``lensopt trace``/``ray``)
    wavefront_report.py plain-data wavefront (RMS, P-V, Strehl, Zernike) and Seidel reports (``trace --wavefront``)
    fft_size.py         5-smooth FFT lengths
"""
