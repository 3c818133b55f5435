"""``lensopt train-irm`` and ``lensopt restore``, and ``optimize`` with ``objective = "restored"`` (CLI layer:
parse, call the library, render).

``train-irm`` trains the conditioned restoration network for a fixed lens (S4.3.2), checkpoints every
N steps and when stopped by Ctrl-C or SIGTERM (at a step boundary), and ``--resume`` continues the
checkpoint bit-identically. ``restore`` applies a trained network to a capture. ``optimize_restored``
runs the joint lens + network optimization (``design.joint_run``), under torchrun too.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

import typer

from lensopt.cli.common import LensArg, console, err_console, handle_errors, load_model, make_engine
from lensopt.cli.signals import stop_on_signals, stopped_at_step_boundary
from lensopt.errors import LensoptError

__all__ = ["commands", "optimize_restored", "network_beside", "parse_grid_text", "data_sources"]

commands = typer.Typer()  # its commands, put in order by lensopt.cli.app


@commands.command("train-irm")
@handle_errors
def train_irm_cmd(
    lens: LensArg,
    output: Annotated[Path, typer.Option("--output", "-o", help="Checkpoint folder to write.")],
    images: Annotated[str, typer.Option("--images", help="Training scenes: procedural (dead leaves) | textured "
                                        "(textured dead leaves) | photos (crops of the bundled training "
                                        "photographs) | an image folder (DIV2K layout or a hash split); mix "
                                        "with '+', e.g. textured+photos.")] = "procedural",
    steps: Annotated[int | None, typer.Option("--steps", min=1, help="Steps (default: [restore.train]).")] = None,
    batch: Annotated[int | None, typer.Option("--batch", min=1, help="Patches per step.")] = None,
    patch: Annotated[int | None, typer.Option("--patch", min=16, help="Patch side, pixels.")] = None,
    lr: Annotated[float | None, typer.Option("--lr", min=0.0, help="Adam learning rate.")] = None,
    checkpoint_every: Annotated[int | None, typer.Option("--checkpoint-every", min=0)] = None,
    validate_every: Annotated[int | None, typer.Option("--validate-every", min=0)] = None,
    val_patches: Annotated[int | None, typer.Option("--val-patches", min=1)] = None,
    fields: Annotated[int, typer.Option("--fields", min=1, max=64, help="Traced fields 0…1.")] = 9,
    sampling: Annotated[str, typer.Option("--sampling", help="Pupil sampling of the PSFs.")] = "rings:8",
    psf_size: Annotated[int, typer.Option("--psf-size", help="PSF side in pixels (odd).")] = 31,
    grid: Annotated[str, typer.Option("--grid", help="Sub-tile PSF grid per patch.")] = "3x3",
    resume: Annotated[bool, typer.Option("--resume", help="Continue the checkpoint at -o.")] = False,
    log_dir: Annotated[Path | None, typer.Option("--log-dir", help="TensorBoard log folder.")] = None,
    device: Annotated[str, typer.Option("--device", help="cpu | cuda | cuda:N | auto")] = "cpu",
    seed: Annotated[int, typer.Option("--seed", help="Seed of every random draw.")] = 0,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON summary.")] = False,
) -> None:
    """Train the restoration network for a fixed lens (S4.3.2): Adam on MAE, cosine schedule.

    The network restores the lens's colour channels, the ones simulate and evaluate render: R, G, B from
    spectrum.rgb_weights, else the seed's split of the spectrum (S4.1.2). The checkpoint records them and
    the lens structure; restore, evaluate --irm and tolerance --irm refuse a network that differs."""
    from lensopt.devices import resolve_device

    engine = make_engine()
    dev = resolve_device(device)
    model = load_model(lens)
    setup, net, cfg = _training_settings(model, patch=patch, batch=batch, lr=lr, checkpoint_every=checkpoint_every,
                                         validate_every=validate_every, val_patches=val_patches, seed=seed,
                                         fields=fields, sampling=sampling, psf_size=psf_size, grid=grid,
                                         engine=engine)
    source, val_source, data = data_sources(images, cfg.patch, seed, engine=engine)
    n_steps = steps or cfg.steps
    res, dist, dev = _train(model, setup, net, cfg, (source, val_source, data), steps=n_steps, output=output,
                            resume=resume, device=dev, log_dir=log_dir, show=None if as_json else _train_line(n_steps))
    if dist.rank == 0:
        summary = {"checkpoint": res.checkpoint, "steps": res.steps, "interrupted": res.interrupted,
                   "validation": res.validation, "device": str(dev), "processes": dist.world}
        if as_json:
            console.print_json(json.dumps(summary))
        else:
            msg = f"wrote {res.checkpoint} (step {res.steps}{', interrupted' if res.interrupted else ''})"
            console.print(msg, highlight=False)
    if res.interrupted:
        raise typer.Exit(stopped_at_step_boundary())


def _training_settings(model: Any, *, patch: int | None, batch: int | None, lr: float | None,
                       checkpoint_every: int | None, validate_every: int | None, val_patches: int | None, seed: int,
                       fields: int, sampling: str, psf_size: int, grid: str, engine: Any) -> tuple[Any, Any, Any]:
    """(imaging set-up, network config, training config) of ``train-irm``: the spec's ``[restore]`` with the
    options given on the command line."""
    import dataclasses

    from lensopt.design.restore import configs_from_spec
    from lensopt.restore.capture import imaging_setup

    net, cfg = configs_from_spec(model.spec.restore)
    over = {k: v for k, v in dict(batch=batch, patch=patch, lr=lr, checkpoint_every=checkpoint_every,
                                  validate_every=validate_every, validation_patches=val_patches).items()
            if v is not None}
    cfg = dataclasses.replace(cfg, seed=seed, **over)
    setup = imaging_setup(model.camera(), patch=cfg.patch, fields=fields, sampling=sampling, psf_size=psf_size,
                          grid=parse_grid_text(grid, "--grid"), noise_sigma=cfg.noise_sigma, device=None,
                          engine=engine)
    return setup, dataclasses.replace(net, channels=setup.channels), cfg


def _train_line(n_steps: int) -> Any:
    """The progress line of ``train-irm`` for one step record."""
    def show(rec: dict[str, Any]) -> None:
        line = f"step {rec['step']}/{n_steps}  MAE {rec['loss']:.5f}  lr {rec['lr']:.2e}  {rec['wall_s']:.2f} s"
        if "psnr_restored" in rec:
            line += f"  | held-out PSNR raw {rec['psnr_raw']:.2f} dB → restored {rec['psnr_restored']:.2f} dB"
        err_console.print(line, highlight=False)

    return show


def _train(model: Any, setup: Any, net: Any, cfg: Any, data: tuple[Any, Any, str], *, steps: int, output: Path,
           resume: bool, device: Any, log_dir: Path | None, show: Any) -> tuple[Any, Any, Any]:
    """Run ``train-irm`` (under torchrun: this rank's share; rank 0 writes and prints); returns (result,
    Dist, device)."""
    from lensopt.parallel import check_same_settings, distributed
    from lensopt.restore.train import train_irm
    from lensopt.spec import dump_json

    source, val_source, text = data
    with distributed(device) as (dist, dev):
        check_same_settings(dist.world, {"spec": model.spec.model_dump(mode="json"), "cfg": repr(cfg),
                                         "steps": steps, "data": text, "resume": resume, "output": str(output)})
        with stop_on_signals() as flag:
            res = train_irm(model.spec, dump_json(model.spec), (model.lens, model.system), setup, net, cfg,
                            source, val_source, steps=steps, data=text, output=output, resume=resume,
                            device=dev, log_dir=log_dir, stop=lambda: dist.any(flag[0]),
                            on_progress=show if dist.rank == 0 else None, dist=dist)
    return res, dist, dev


@commands.command("restore")
@handle_errors
def restore_cmd(
    lens: LensArg,
    checkpoint: Annotated[Path, typer.Argument(help="Checkpoint folder (train-irm or joint optimize).")],
    image: Annotated[Path, typer.Argument(help="Capture to restore.")],
    output: Annotated[Path, typer.Option("--output", "-o", help="Restored image to write.")],
    region: Annotated[str | None, typer.Option("--region", help="Where the capture lies on the sensor.")] = None,
    device: Annotated[str, typer.Option("--device", help="cpu | cuda | cuda:N | auto")] = "cpu",
) -> None:
    """Restore a capture of LENS with the network of CHECKPOINT.

    A gray capture through a colour network is restored as R = G = B and written back gray (with a note);
    a network trained for another lens structure or other channels is refused."""
    import numpy as np
    import torch

    from lensopt.devices import resolve_device
    from lensopt.imaging.io import read_image, write_image
    from lensopt.imaging.scene import parse_region
    from lensopt.restore.apply import load_restorer, match_channels, restore_image

    engine = make_engine()
    dev = resolve_device(device)
    model = load_model(lens)
    net, setup, tile = load_restorer(checkpoint, model, device=dev, option="CHECKPOINT", engine=engine)
    arr, info = read_image(image, engine=engine)
    reg = parse_region(region, setup.sensor, info.width, info.height)
    x, notice = match_channels(torch.from_numpy(arr).permute(2, 0, 1).to(dev), net.config.channels)
    if notice:
        err_console.print(f"note: IMAGE is {notice}, written back in {arr.shape[-1]} channel(s)", highlight=False)
    y = restore_image(net, model.lens, model.system, setup, x, reg, tile=tile)
    y, _ = match_channels(y, arr.shape[-1])
    desc = write_image(output, np.ascontiguousarray(y.clamp(0, 1).permute(1, 2, 0).cpu().numpy()), info)
    console.print(f"wrote {output} ({desc})", highlight=False)


def parse_grid_text(text: str, option: str) -> tuple[int, int]:
    try:
        a, b = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise LensoptError("must be WxH, e.g. 3x3", path=option, got=text) from None
    if a < 1 or b < 1:
        raise LensoptError("must be WxH with positive numbers", path=option, got=text)
    return a, b


def data_sources(images: str, patch: int, seed: int, *, engine: Any = None) -> tuple[Any, Any, str]:
    """(training source, held-out source, description) for ``--images`` (``imaging.sources``); ``engine``:
    the memory budget of every image read."""
    from lensopt.imaging.sources import training_sources

    return training_sources(images, patch, seed, engine=engine, option="--images")


def optimize_restored(start_spec: Any, output: Path, *, steps: int | None, seed: int, checkpoint: Path | None,
                      resume: bool, device: str, log_dir: Path | None, quiet: bool, as_json: bool,
                      engine: Any = None) -> None:
    """``lensopt optimize`` with ``objective = "restored"``: the joint run, then the lens and its network
    written (the network in the checkpoint folder ``checkpoint``, default ``network_beside(output)``); rank 0
    only writes and prints under torchrun."""
    from lensopt.design.joint_run import run_joint
    from lensopt.devices import resolve_device
    from lensopt.parallel import check_same_settings, distributed
    from lensopt.spec import save_json

    if output.suffix.lower() != ".json":
        raise LensoptError("the optimized lens is written as .json", path="--output", got=str(output))
    checkpoint = checkpoint or network_beside(output)
    with distributed(resolve_device(device)) as (dist, dev):
        check_same_settings(dist.world, {"spec": start_spec.model_dump(mode="json"), "steps": steps, "seed": seed,
                                         "checkpoint": str(checkpoint), "resume": resume})
        loud = dist.rank == 0 and not quiet and not as_json
        with stop_on_signals() as flag:
            res = run_joint(start_spec, steps=steps, seed=seed, checkpoint=checkpoint, resume=resume, device=dev,
                            log_dir=log_dir, dist=dist, stop=lambda: dist.any(flag[0]),
                            on_progress=_joint_line if loud else None, engine=engine)
        if dist.rank == 0:
            save_json(res.spec, output)
            summary = {"output": str(output), "checkpoint": str(checkpoint) if checkpoint else None,
                       "steps": res.steps, "interrupted": res.interrupted, "start": res.start, "final": res.final,
                       "elapsed_s": res.elapsed_s, "notes": res.notes, "processes": dist.world,
                       "device": str(dev)}
            if as_json:
                console.print_json(json.dumps(summary))
            else:
                _joint_summary(res, output, checkpoint)
    if res.interrupted:
        raise typer.Exit(stopped_at_step_boundary())


def network_beside(output: Path) -> Path:
    """Where a joint run writes its network when no --checkpoint is given: ``OUT.irm/`` beside ``OUT.json``
    (a checkpoint folder that ``restore``, ``evaluate --irm`` and ``tolerance --irm`` read)."""
    return output.with_suffix(".irm")


def _joint_line(rec: dict[str, Any]) -> None:
    """The progress line of a joint run for one step record."""
    line = (f"step {rec['step']}  batch PSNR after restoration {rec['psnr_batch_db']:.2f} dB  "
            f"MAE {rec['mae']:.4f}  λ {rec['damping']:.2e}  ESR {rec['esr_um']:.2f} µm  {rec['wall_s']:.2f} s")
    if "psnr_restored" in rec:
        line += f"  | held-out {rec['psnr_raw']:.2f} → {rec['psnr_restored']:.2f} dB"
    err_console.print(line, highlight=False)


def _joint_summary(res: Any, output: Path, checkpoint: Path | None) -> None:
    for n in res.notes:
        err_console.print(f"note: {n}", highlight=False)
    if res.start and res.final:
        console.print(f"held-out PSNR raw {res.start['psnr_raw']:.2f} → {res.final['psnr_raw']:.2f} dB, "
                      f"restored {res.start['psnr_restored']:.2f} → {res.final['psnr_restored']:.2f} dB",
                      highlight=False)
    console.print(f"wrote {output}" + (f" and {checkpoint}" if checkpoint else ""), highlight=False)
