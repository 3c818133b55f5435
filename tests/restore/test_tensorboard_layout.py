"""TensorBoard logs of train-irm and of a joint run (issue 11: scalars, custom-scalars layout, PSFs,
restored crops): tiny runs with --log-dir, the event files read back with tensorboard's own reader."""

from __future__ import annotations

from pathlib import Path

from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
from tensorboard.plugins.custom_scalar import layout_pb2
from typer.testing import CliRunner

from lensopt.cli.app import app
from lensopt.spec import parse_spec
from tests.restore.joint_spec import joint_data

LAYOUT_TAG = "custom_scalars__config__"  # tensorboard.plugins.custom_scalar.metadata.CONFIG_SUMMARY_TAG


def _read(log_dir: Path) -> tuple[EventAccumulator, layout_pb2.Layout]:
    acc = EventAccumulator(str(log_dir), size_guidance={"tensors": 0, "images": 0, "scalars": 0})
    acc.Reload()
    assert LAYOUT_TAG in acc.Tags()["tensors"], acc.Tags()
    events = acc.Tensors(LAYOUT_TAG)
    layout = layout_pb2.Layout.FromString(events[-1].tensor_proto.string_val[0])
    return acc, layout


def _charts(layout: layout_pb2.Layout) -> dict[str, list[str]]:
    return {c.title: list(c.multiline.tag) for cat in layout.category for c in cat.chart}


def test_train_irm_writes_layout_scalars_psfs_and_restored_crops(tiny_lens: Path, tmp_path: Path) -> None:
    tb = tmp_path / "tb"
    r = CliRunner().invoke(app, ["train-irm", str(tiny_lens), "-o", str(tmp_path / "ck"), "--fields", "3",
                                 "--psf-size", "9", "--sampling", "rings:4", "--steps", "2", "--validate-every", "2",
                                 "--log-dir", str(tb), "--json"])
    assert r.exit_code == 0, r.output
    acc, layout = _read(tb)
    assert [c.title for c in layout.category] == ["train-irm (network on a fixed lens)"]
    charts = _charts(layout)
    assert charts["MAE: training batch vs held-out"] == ["train-irm/loss", "train-irm/mae"]
    assert charts["held-out PSNR dB: raw capture vs restored"] == ["train-irm/psnr_raw", "train-irm/psnr_restored"]
    scalars = set(acc.Tags()["scalars"])
    # every tag a chart names is written (so no chart stays empty)
    assert {t for tags in charts.values() for t in tags} <= scalars
    assert [e.step for e in acc.Scalars("train-irm/loss")] == [1, 2]
    assert [e.step for e in acc.Scalars("train-irm/psnr_restored")] == [2]
    images = set(acc.Tags()["images"])
    assert {"train-irm/scene_capture_restored", "train-irm/conditioning_psf"} <= images
    crop = acc.Images("train-irm/scene_capture_restored")[-1]
    # scene | capture | restored side by side (three 32-pixel patches), the 2 held-out patches tiled in a row
    assert (crop.width, crop.height) == (2 * 3 * 32, 32)
    psf = acc.Images("train-irm/conditioning_psf")[-1]
    assert (psf.width, psf.height) == (2 * 9, 9)


def test_joint_run_writes_layout_scalars_psfs_and_restored_crops(tmp_path: Path) -> None:
    from lensopt.design.joint_run import run_joint

    tb = tmp_path / "tb"
    run_joint(parse_spec(joint_data(steps=2)), steps=2, evaluate=False, log_dir=tb, validate_every=2)
    acc, layout = _read(tb)
    assert [c.title for c in layout.category] == ["joint run (lens LM step + network Adam step)"]
    charts = _charts(layout)
    assert charts["PSNR dB: training batch (restored) vs held-out raw and restored"] == [
        "joint/psnr_batch_db", "joint/psnr_raw", "joint/psnr_restored"]
    assert charts["LM damping λ and step accepted"] == ["joint/damping", "joint/accepted"]
    assert charts["ESR µm (spot size of the lens)"] == ["joint/esr_um"]
    scalars = set(acc.Tags()["scalars"])
    assert {t for tags in charts.values() for t in tags} <= scalars
    assert [e.step for e in acc.Scalars("joint/damping")] == [1, 2]
    assert [e.step for e in acc.Scalars("joint/psnr_restored")] == [2]
    assert {"joint/scene_capture_restored", "joint/conditioning_psf"} <= set(acc.Tags()["images"])
    crop = acc.Images("joint/scene_capture_restored")[-1]
    assert (crop.width, crop.height) == (2 * 3 * 32, 32)  # validation = 2 patches
    psf = acc.Images("joint/conditioning_psf")[-1]
    assert (psf.width, psf.height) == (2 * 9, 9)
