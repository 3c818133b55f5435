"""Image simulation (S1.5): scene plans, PSF grids, spatially varying convolution, effects, image I/O;
image data (procedural dead leaves, image folders), sensor regions (S3.3.1), RGB weights (S4.1.2) and
evaluation (S4.3.1). Everything here takes plain tensors and dataclasses (``camera.Camera``), never a spec."""
