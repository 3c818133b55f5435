"""lensopt: differentiable, processing-aware lens design (DESIGN.md has the map and the layers).

    errors.py       LensoptError and its subclasses: a field path and the bad value
    resources.py    the memory budget checked before large allocations
    parallel.py     independent tasks serially or on Dask; torch.distributed (torchrun) set-up
    files.py        atomic writes of files and folders (temporary + rename): the one atomic writer; json_safe
    devices.py      ``--device`` names → torch.device
    checkpoint.py   run checkpoints (safetensors + JSON, atomic folder)
    materials/      dispersion, glass catalogs, AGF, runtime materials, glass space
    optics/         the differentiable core: surfaces, intersection, paraxial, sampling, aiming, trace, backends
    analysis/       spot, fans, field, illumination, PSFs, MTF, reports of a traced lens
    imaging/        image simulation, rendering, regions, datasets, evaluation, image files
    plot/           matplotlib figures
    restore/        restoration networks (Wiener, NAFNet, the conditioned model)
    optim/          θ, solves, residual terms, LM/Adam, the driver; image objectives; network training
    tolerance/      perturbed lenses, vmapped metrics, sensitivity, Monte Carlo
    spec/           pydantic lens specs, TOML/JSON, the builder (spec → tensors)
    interchange/    CODE V and Zemax files ↔ specs
    design/         spec → optimization problem → optimized spec; the joint run
    qa/             regression checks, accuracy cost
    study/          design sweeps
    cli/            the ``lensopt`` command line
    __main__.py     the command's entry (``python -m lensopt``, the console script)
"""

__version__ = "0.1.0"
