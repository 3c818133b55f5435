"""Lens specs: pydantic models, TOML/JSON loading with field-path errors, and the tensor builder.

    models.py           LensSpec and its parts (surfaces, materials, aperture, fields, spectrum, sensor)
    optim.py            the ``[optimize]`` section
    restore.py          the ``[restore]`` section → restore.config
    tolerance.py        the ``[tolerance]`` section
    io.py               load/save TOML and JSON, field-path errors
    build.py            spec → tensors: Model, build, camera_of
    tolerance_build.py  spec → tolerance Job, trial specs
"""

from lensopt.spec.build import Model, build, camera_of
from lensopt.spec.io import dump_json, load_spec, parse_spec, save_json
from lensopt.spec.models import LensSpec

__all__ = ["LensSpec", "Model", "build", "camera_of", "dump_json", "load_spec", "parse_spec", "save_json"]
