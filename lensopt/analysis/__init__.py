"""Analyses of a traced lens (plain tensors in, frozen dataclasses of tensors out).

Spots and fans: ``spot``, ``spot_diagram``, ``fans``; per-field summary: ``field``, ``distortion``,
``illumination``, ``irradiance``; PSFs: ``psf``, ``psf_diffraction``, ``psf_stack``, ``psf_reference``;
MTF: ``mtf``, ``mtf_field`` (vs field, through focus); the designer's wavefront set: ``wavefront`` (the
one home of the OPD: reference sphere, fans, maps, RMS/P-V, the differentiable RMS), ``zernike``,
``strehl``, ``seidel``, ``field_curves`` (field curvature, distortion, lateral colour, focal shift),
``encircled``; argument checks: ``checks``; reports and requirements: ``report``, ``requirements``,
``layout``.
"""
