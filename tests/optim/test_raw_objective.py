"""``objective = "raw"`` end to end on a small Cooke triplet: LM on GTRA and Adam on the scalar loss run
through ``lensopt optimize``; bad input is one line naming the field, exit 2, nothing written."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from lensopt.cli.app import app
from lensopt.spec import parse_spec, save_json

runner = CliRunner()
SMALL = {"patch": 32, "batch": 2, "psf_size": 15, "fields": 3, "sampling": "rings:4", "validation": 2}


def _raw(make_cooke, **image: Any) -> dict[str, Any]:  # noqa: ANN001
    data = make_cooke(objective="raw", rim_rays=0, image={**SMALL, **image})
    for i in (0, 2):
        data["surfaces"][i]["vary"] = ["radius"]
    return data


def _write(tmp_path: Path, data: dict) -> Path:
    path = tmp_path / "start.json"
    save_json(parse_spec(data), path)
    return path


@pytest.mark.parametrize("optimizer", ["lm", "adam"])
def test_raw_objective_runs_and_reports_psnr(tmp_path: Path, make_cooke, optimizer: str) -> None:  # noqa: ANN001
    start = _write(tmp_path, _raw(make_cooke))
    out = tmp_path / "lens.json"
    r = runner.invoke(app, ["optimize", str(start), "-o", str(out), "--steps", "2", "--optimizer", optimizer,
                            "--json", "-q"])
    assert r.exit_code == 0, r.output
    s = json.loads(r.stdout)
    assert s["steps"] == 2 and out.exists()
    psnr = s["held_out_psnr_db"]
    assert 5.0 < psnr["start"] < 60.0 and 5.0 < psnr["final"] < 60.0
    assert len(s["image_history"]) == 2


@pytest.mark.parametrize(("change", "field"), [
    ({"image": {"psf_size": 48}}, "optimize.image.psf_size"),
    ({"image": {"psf_size": -3}}, "optimize.image.psf_size"),
    ({"image": {"images": "/nonexistent/folder"}}, "optimize.image.images"),
    ({"image": {"images": "photo"}}, "optimize.image.images"),  # not a source name (photos), not a folder
    ({"image": {"images": "photos+photos"}}, "optimize.image.images"),
    ({"sensor": None}, "sensor"),
])
def test_bad_raw_input_is_one_line_naming_the_field(tmp_path: Path, make_cooke, change: dict, field: str) -> None:  # noqa: ANN001
    data = _raw(make_cooke)
    if "image" in change:
        data["optimize"]["image"].update(change["image"])
    else:
        data.pop("sensor")
    path = tmp_path / "start.json"
    path.write_text(json.dumps(data))
    out = tmp_path / "lens.json"
    r = runner.invoke(app, ["optimize", str(path), "-o", str(out), "--steps", "1", "-q"])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and field in lines[0], r.output
    assert not out.exists()


@pytest.mark.parametrize("size", [16, 64])
def test_an_image_folder_trains_and_small_images_are_refused(tmp_path: Path, make_cooke, size: int) -> None:  # noqa: ANN001
    import numpy as np

    from lensopt.imaging.io import ImageInfo, write_image

    folder = tmp_path / "images"
    folder.mkdir()
    rng = np.random.default_rng(0)
    for k in range(12):  # hash split: some of them held out
        write_image(folder / f"img{k:02d}.png", rng.random((size, size, 3), dtype=np.float32),
                    ImageInfo(size, size, 3, 8, False, "sRGB", "png"))
    start = _write(tmp_path, _raw(make_cooke, images=str(folder)))
    out = tmp_path / "lens.json"
    r = runner.invoke(app, ["optimize", str(start), "-o", str(out), "--steps", "1", "--json", "-q"])
    if size < SMALL["patch"]:
        assert r.exit_code == 2 and "optimize.image.images" in r.output, r.output
        assert not out.exists()
    else:
        assert r.exit_code == 0, r.output
        assert json.loads(r.stdout)["steps"] == 1


def test_a_named_scene_source_trains_the_image_objective(tmp_path: Path, make_cooke) -> None:  # noqa: ANN001
    # optimize.image.images takes train-irm's --images names: the bundled training photographs here.
    from lensopt.design import build_problem
    from lensopt.imaging.sources import PHOTOS_TRAIN
    from lensopt.spec import load_spec

    start = _write(tmp_path, _raw(make_cooke, images="photos"))
    train = build_problem(load_spec(start)).image.train
    assert [p.name for p in train.files] == list(PHOTOS_TRAIN)
    out = tmp_path / "lens.json"
    r = runner.invoke(app, ["optimize", str(start), "-o", str(out), "--steps", "1", "--json", "-q"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["steps"] == 1
