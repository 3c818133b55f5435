"""lensopt: differentiable, processing-aware lens design (DESIGN.md has the map and the layers).

    errors.py       LensoptError and its subclasses: a field path and the bad value
    engine.py       the Engine: trace backend, memory budget, allocator setting (made by the CLI, passed down)
    parallel.py     independent tasks serially or on Dask; torch.distributed (torchrun) set-up
    files.py        atomic writes of files and folders (temporary + rename): the one atomic writer; json_safe
    devices.py      ``--device`` names → torch.device
    checkpoint.py   run checkpoints (safetensors + JSON, atomic folder)
    materials/      dispersion, glass catalogs, AGF, runtime materials, glass space
    optics/         the differentiable core: surfaces, intersection, paraxial, sampling, aiming, trace, bundles
    accel/          the compiled traces (torch.compile, AOT packages) and the compiled LM Jacobian; which runs
    analysis/       spot, fans, field, illumination, PSFs, MTF, reports of a traced lens
    imaging/        image simulation, rendering, regions, datasets, evaluation, image files
    plot/           matplotlib figures
    restore/        restoration: networks (Wiener, NAFNet, the conditioned model), training, checkpoints, applying
    optim/          lens optimization: θ, solves, residual terms, LM/Adam, the driver; image objectives
    tolerance/      perturbed lenses, vmapped metrics, sensitivity, Monte Carlo
    spec/           the data model: pydantic lens specs, TOML/JSON, the builder (spec → tensors)
    interchange/    CODE V and Zemax files ↔ specs
    design/         every spec → engine adapter (problem, tolerance job, restore configs); optimize a spec;
                    the joint lens + network step and run; a tolerance study
    qa/             regression checks, accuracy cost
    study/          design sweeps
    cli/            the ``lensopt`` command line
    __main__.py     the command's entry (``python -m lensopt``, the console script)
"""

__version__ = "0.1.0"
