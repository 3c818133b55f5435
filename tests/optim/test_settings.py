"""The plain settings (``lensopt.optim.settings``) that ``Problem`` and the optimizers read, against the
spec's pydantic models they are converted from (``lensopt.design.setup.settings_of``): the same defaults
and, for a real spec, every field carried over."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from lensopt.design.setup import _KINDS, settings_of
from lensopt.optim import settings as st
from lensopt.spec import load_spec
from lensopt.spec import optim as so

SPECS = Path(__file__).resolve().parents[2] / "specs"


def test_defaults_are_the_specs_defaults() -> None:
    # Every settings model of the spec converts to its dataclass; with no input the two agree field by field
    # (the dataclasses' own defaults are what LM/Adam use when given no settings).
    for model, kind in _KINDS.items():
        required = {n for n, f in model.model_fields.items() if f.is_required()}
        if required:  # gap/span bounds: no default instance
            continue
        assert settings_of(model()) == kind(), kind.__name__
    assert settings_of(so.OptimizeSpec()) == st.OptimizeSettings()


def test_a_spec_converts_field_by_field() -> None:
    opt = load_spec(SPECS / "cmount_4p_raw.toml").optimize
    plain = settings_of(opt)
    assert isinstance(plain, st.OptimizeSettings) and isinstance(plain.image, st.ImageSettings)
    assert plain.constraints.ray_path.glass_ratio == 2.99 and plain.constraints.distortion.max_percent == 1.98
    assert plain.image.grid == (3, 3) and plain.image.fields == 9 and plain.steps == 54
    assert plain.constraints.ray_path.gaps == () and plain.constraints.ray_path.spans is None
    # nothing pydantic is left anywhere in the tree
    def walk(x: object) -> None:
        assert not hasattr(x, "model_fields"), type(x)
        if dataclasses.is_dataclass(x):
            for f in dataclasses.fields(x):
                walk(getattr(x, f.name))
        elif isinstance(x, tuple):
            for v in x:
                walk(v)
    walk(plain)


def test_every_settings_dataclass_has_the_models_fields() -> None:
    for model, kind in _KINDS.items():
        names = {f.name for f in dataclasses.fields(kind)}
        assert names == set(model.model_fields) - ({"solves"} if model is so.OptimizeSpec else set()), kind.__name__
