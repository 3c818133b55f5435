"""Image simulation (S1.5): scene plans, PSF grids, spatially varying convolution, effects, image I/O."""
