"""Lens specs, the data model: pydantic models, TOML/JSON loading with field-path errors, and the one
builder of the lens tensors. The adapters from a spec to the engines (optimization problem, tolerance
job, restoration configs) live in ``lensopt.design``.

    models.py     LensSpec and its parts (surfaces, materials, aperture, fields, spectrum, sensor, image plane)
    optim.py      the ``[optimize]`` section
    restore.py    the ``[restore]`` section
    tolerance.py  the ``[tolerance]`` section
    io.py         load/save TOML and JSON, field-path errors
    build.py      spec → tensors: Model, build, camera_of
"""

from lensopt.spec.build import Model, build, camera_of
from lensopt.spec.io import dump_json, load_spec, parse_spec, save_json
from lensopt.spec.models import LensSpec

__all__ = ["LensSpec", "Model", "build", "camera_of", "dump_json", "load_spec", "parse_spec", "save_json"]
