"""Lens specs: pydantic models, TOML/JSON loading with field-path errors, and the tensor builder."""

from lensopt.spec.build import Model, build, camera_of
from lensopt.spec.io import dump_json, load_spec, parse_spec, save_json
from lensopt.spec.models import LensSpec

__all__ = ["LensSpec", "Model", "build", "camera_of", "dump_json", "load_spec", "parse_spec", "save_json"]
