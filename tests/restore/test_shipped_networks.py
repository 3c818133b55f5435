"""The Table S15 set shipped in ``lenses/`` (issue 27): the spot, raw and restored-optimized C-mount lenses,
each with its restoration network in ``lenses/networks/LENS/`` (made by ``benchmarks/e2e/table_s15.py
--ship``, see benchmarks/README.md): the restored lens meets S6.1, each network loads for its lens, records
the lens and how it was trained, restores photographs it never saw better than the unrestored capture, and
refuses a lens of another structure in one line naming both."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from lensopt.analysis.requirements import Requirements, check_requirements, failed
from lensopt.checkpoint import CheckpointError, load_checkpoint
from lensopt.cli.app import app
from lensopt.imaging.plan import lens_colour
from lensopt.restore import RestoreConfig
from lensopt.restore.apply import load_restorer, trained_colour
from lensopt.restore.checkpoint import network_fingerprint
from lensopt.spec import build, load_spec
from tests.helpers import imaging_oval

ROOT = Path(__file__).resolve().parents[2]
LENSES = ("cmount_4p", "cmount_4p_raw", "cmount_4p_restored")
runner = CliRunner()


def test_the_restored_cmount_lens_meets_s61() -> None:
    # S6.1 (as tests/analysis/test_requirements.py for the spot lens): glass 1–5 mm with edge/centre 1/3–3,
    # air ≥ 0.25 mm, image clearance ≥ 20 mm, angles ≤ 60°, |distortion| ≤ 2 %, recommended Ohara glasses,
    # EFL 28 mm; on the dense check (6 fields, a 31² pupil grid and the rim).
    spec = load_spec(ROOT / "lenses" / "cmount_4p_restored.json")
    model = build(spec)
    req = Requirements(glass_min=1.0, glass_max=5.0, glass_ratio=3.0, air_min=0.25, image_min=20.0,
                       max_angle_deg=60.0, max_distortion_percent=2.0, catalog="ohara-recommended", efl=28.0)
    checks = check_requirements(model.lens, model.system, req, glass_gaps=[not s.is_air for s in spec.surfaces],
                                materials=[s.material for s in spec.surfaces if not s.is_air], fields=6, grid=31)
    assert failed(checks) == [], [c for c in checks if not c.ok]
    # The same glasses as the spot lens it started from (the joint run and the polish bend no glass).
    spot = load_spec(ROOT / "lenses" / "cmount_4p.json")
    assert [s.material for s in spec.surfaces] == [s.material for s in spot.surfaces]


@pytest.mark.parametrize("lens", LENSES)
def test_a_shipped_network_loads_for_its_lens_and_records_it(lens: str) -> None:
    folder = ROOT / "lenses" / "networks" / lens
    spec = load_spec(ROOT / "lenses" / f"{lens}.json")
    net, setup, _ = load_restorer(folder, build(spec))
    assert net.config.channels == setup.channels == 3  # the lens's R, G, B
    ck = load_checkpoint(folder)
    # The fingerprint, recomputed from the shipped lens file and the recorded network configuration.
    assert ck.fingerprint == network_fingerprint(spec, RestoreConfig.from_dict(ck.meta["network_config"]))
    assert ck.meta["lens"] == f"lenses/{lens}.json"
    assert ck.meta["lens_sha256"] == hashlib.sha256(ck.lens_json.encode()).hexdigest()
    # The lens it was trained for is the shipped one: the same lens, spectrum and colour model included, to
    # every digit (the copy trained on adds only its [restore] section).
    trained = json.loads(ck.lens_json)
    shipped = json.loads((ROOT / "lenses" / f"{lens}.json").read_text())
    assert {k: v for k, v in trained.items() if k != "restore"} == {k: v for k, v in shipped.items() if k != "restore"}
    # One colour model end to end: the channel weights the network was trained in are the shipped lens's.
    w, source = trained_colour(ck.lens_json, 3)
    np.testing.assert_array_equal(w, lens_colour(spec.spectrum)[0])
    assert source == "spectrum.rgb_weights"
    # How it was trained (benchmarks/README.md, Table S15): 200 Adam steps of 4 × 64² crops of the bundled
    # training photographs.
    train = ck.meta["settings"]["train"]
    assert (ck.step, train["batch"], train["patch"]) == (200, 4, 64)
    assert ck.meta["settings"]["data"].startswith("photos")
    # Weights only, in float16: no Adam moments or generator states; a few MB.
    assert ck.state == {} and {v.dtype for v in ck.network.values()} == {torch.float16}
    params = sum(p.numel() for p in net.parameters())
    size = (folder / "network.safetensors").stat().st_size
    assert 2 * params <= size < 2 * params + 200_000  # 2 bytes a weight + the safetensors header


def test_a_shipped_network_refuses_a_lens_of_another_structure() -> None:
    # A one-surface lens with 3 wavelengths against the 9-surface, 12-wavelength C-mount network.
    with pytest.raises(CheckpointError) as err:
        load_restorer(ROOT / "lenses" / "networks" / "cmount_4p_restored", imaging_oval(rgb=True))
    msg = str(err.value)
    assert "\n" not in msg
    assert "9 surfaces" in msg and "12 wavelengths" in msg  # the network's lens
    assert "2 surfaces" in msg or "1 surfaces" in msg or "3 wavelengths" in msg  # and this one


def test_a_network_refuses_a_lens_with_other_colour_weights(tmp_path: Path) -> None:
    # The spot lens without its rgb_weights images by the seed's split (S4.1.2): same structure and channel
    # count, other weights (the split shares 480/510 and 570/600 nm between channels; the network's hard split
    # does not), so restoring through it would feed the network colours it never saw: one line naming both.
    data = json.loads((ROOT / "lenses" / "cmount_4p.json").read_text())
    del data["spectrum"]["rgb_weights"]
    lens = tmp_path / "no_rgb.json"
    lens.write_text(json.dumps(data))
    r = runner.invoke(app, ["evaluate", str(lens), "--irm", str(ROOT / "lenses" / "networks" / "cmount_4p"),
                            "--count", "1", "--patch", "64"])
    assert r.exit_code == 2, r.output
    assert len(r.output.strip().splitlines()) == 1 and "Traceback" not in r.output, r.output
    assert "trained with colour weights spectrum.rgb_weights" in r.output  # the network's
    assert "contiguous thirds of the spectrum" in r.output  # and the lens's
    assert not (tmp_path / "no_rgb.irm").exists() and sorted(p.name for p in tmp_path.iterdir()) == ["no_rgb.json"]


@pytest.mark.parametrize("lens", LENSES)
def test_a_shipped_network_makes_held_out_photographs_better(lens: str) -> None:
    # Issue 27's must-show: after restoration, photographs (held-out tiles of astronaut, chelsea, coffee,
    # never drawn in training) are not worse than the unrestored capture. Two 128² tiles here; all 34 in
    # benchmarks/e2e/results_table_s15.json.
    r = runner.invoke(app, ["evaluate", str(ROOT / "lenses" / f"{lens}.json"), "--irm",
                            str(ROOT / "lenses" / "networks" / lens), "--images",
                            "photos", "--patch", "128", "--count", "2", "--noise", "0.005", "--json"])
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)
    assert out["count"] == 2
    assert out["after_restoration"]["psnr_db"] > out["psnr_db"]
