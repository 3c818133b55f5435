"""``lensopt evaluate LENS [--images DIR]``: pre-restoration PSNR/SSIM of a lens (seed S4.3.1).

CLI layer: parses options, calls ``lensopt.imaging.evaluate``, renders with rich. ``register(app)`` is
called from the bottom of ``lensopt.cli``. (No ``from __future__ import annotations`` here: typer reads the
command's annotations, which name the option types imported inside ``register``.)
"""

from pathlib import Path
from typing import Annotated, Any

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn
from rich.table import Table

from lensopt.errors import LensoptError

__all__ = ["register"]


def register(app: typer.Typer, plot_app: typer.Typer | None = None) -> None:
    """Add the ``evaluate`` command to ``app`` (and ``plot regions`` to ``plot_app``)."""
    from lensopt.cli import DeviceOpt, JsonOpt, LensArg, console, err_console, handle_errors, load_model, print_json
    from lensopt.cli_backend import BackendOpt, with_backend

    if plot_app is not None:
        _register_plot(plot_app)

    @app.command()
    @handle_errors
    @with_backend(err_console)
    def evaluate(
        lens: LensArg,
        images: Annotated[Path | None, typer.Option("--images", help="Folder of PNG/JPEG/TIFF/EXR images (DIV2K: "
                                                    "its valid_HR/); default: procedural dead-leaves scenes.")] = None,
        count: Annotated[int, typer.Option("--count", help="Number of scenes (images: the first N by name).")] = 100,
        patch: Annotated[int, typer.Option("--patch", help="Central crop and sensor tile size, pixels.")] = 256,
        rays: Annotated[str, typer.Option("--rays", help="Pupil sampling per PSF (rings:N = 2N² rays).")] = "rings:32",
        kernel: Annotated[str, typer.Option("--kernel", help="count | triangular | cosine (S1.4).")] = "triangular",
        grid: Annotated[str | None, typer.Option("--grid", help="Force the PSF grid per tile, e.g. 3x3 "
                                                 "(default: the simulation plan's choice).")] = None,
        noise: Annotated[float, typer.Option("--noise", help="Additive Gaussian noise σ, fraction of the maximum "
                                             "(the seed's training value: 0.005).")] = 0.0,
        rings: Annotated[int, typer.Option("--rings", help="Rings of relative tile radius in the breakdown.")] = 4,
        seed: Annotated[int, typer.Option("--seed", help="Seed of the scene ↔ tile pairing, the dead-leaves "
                                          "scenes, the noise and the pupil jitter.")] = 0,
        as_json: JsonOpt = False,
        irm: Annotated[Path | None, typer.Option("--irm", help="Restoration network checkpoint (train-irm or "
                                                 "joint): score before and after restoration.")] = None,
        backend: BackendOpt = "auto",
        device: DeviceOpt = "cpu",
    ) -> None:
        """Pre-restoration PSNR and SSIM of central crops, each paired with a sensor tile (S4.3.1)."""
        from lensopt.cli_imaging import parse_grid
        from lensopt.cli_restore import resolve_device
        from lensopt.imaging.evaluate import evaluate as run_evaluate
        from lensopt.imaging.evaluate import scene_source
        from lensopt.imaging.plan import PlanOptions
        from lensopt.optics.sampling import PupilSampling
        from lensopt.spec import camera_of

        dev = resolve_device(device)
        if patch < 8:
            raise LensoptError("must be at least 8 pixels", path="--patch", got=patch)
        PupilSampling.parse(rays, path="--rays")
        from lensopt.analysis.psf import KERNELS

        if kernel not in KERNELS:
            raise LensoptError(f"must be one of {', '.join(KERNELS)}", path="--kernel", got=kernel)
        from lensopt.imaging.regions import tile_grid
        from lensopt.imaging.simulate import sensor_of

        model = load_model(lens, dev)
        camera = camera_of(model)
        tile_grid(sensor_of(camera, patch, patch)[0], patch, option="--patch")  # bad sensor/patch: before the bar
        scenes, names, desc = scene_source(images, count=count, patch=patch, seed=seed)
        options = PlanOptions(sampling=rays, kernel=kernel, grid=parse_grid(grid), seed=seed)
        hooks: list[Any] = [None]
        if irm is not None:
            from lensopt.cli_restore import irm_hook

            hooks.append(irm_hook(model, irm))
        results = []
        for hook in hooks:
            with Progress(TextColumn("evaluating" if hook is None else "restoring"), BarColumn(),
                          MofNCompleteColumn(), TimeElapsedColumn(), TimeRemainingColumn(), console=err_console,
                          transient=True, disable=as_json) as bar:
                task = bar.add_task("scenes", total=len(names))
                results.append(run_evaluate(camera, scenes, names, patch=patch, seed=seed, options=options,
                                            noise_sigma=noise, rings=rings, images=desc, restore=hook,
                                            progress=lambda done, total, b=bar, t=task: b.update(t, completed=done)))
        if as_json:
            out = results[0].as_json()
            if len(results) > 1:
                out["after_restoration"] = results[1].as_json()
            print_json(out)
        else:
            for result in results:
                _render(console, result.as_json())


def _register_plot(plot_app: typer.Typer) -> None:
    from lensopt.cli import LensArg, err_console, handle_errors, load_model

    @plot_app.command("regions")
    @handle_errors
    def plot_regions_cmd(
        lens: LensArg,
        output: Annotated[Path, typer.Option("--output", "-o", help="Figure file (png, pdf, svg).")],
        patch: Annotated[int, typer.Option("--patch", help="Tile size, pixels.")] = 256,
        batch: Annotated[int, typer.Option("--batch", help="Tiles drawn (one batch).")] = 16,
        seed: Annotated[int, typer.Option("--seed", help="Seed of the draw.")] = 0,
        dpi: Annotated[int, typer.Option("--dpi", help="Raster resolution.")] = 150,
    ) -> None:
        """Sensor tiles by distance from the centre and one pseudo-random batch of them (S3.3.1, Figure S8)."""
        from lensopt.imaging.regions import RegionSampler, tile_grid
        from lensopt.imaging.simulate import sensor_of
        from lensopt.plot.regions import plot_regions
        from lensopt.plot.style import save_figure
        from lensopt.spec import camera_of

        camera = camera_of(load_model(lens))
        grid = tile_grid(sensor_of(camera, patch, patch)[0], patch, option="--patch")
        if batch < 1:
            raise LensoptError("must be at least 1", path="--batch", got=batch)
        tiles = RegionSampler(grid, seed=seed).sample(batch)
        save_figure(plot_regions(grid, tiles), output, dpi=dpi)
        err_console.print(f"wrote {output}")


def _render(console: Any, r: dict[str, Any]) -> None:
    s = r["sensor"]
    title = (f"{r['lens']}: {r['images']}, central {r['patch']}² crops on {r['tiles']} tiles "
             f"({s['grid'][0]}×{s['grid'][1]} of a {s['resolution'][0]}×{s['resolution'][1]} sensor, "
             f"{s['pixel_pitch_um']:g} µm)")
    t = Table(title=title)
    for col in ("ring (relative radius)", "tiles", "scenes", "PSNR dB", "SSIM"):
        t.add_column(col, justify="left" if col.startswith("ring") else "right")
    for row in r["rings"]:
        lo, hi = row["radius_rel"]
        t.add_row(f"{row['ring']} ({lo:.2f}–{hi:.2f})", str(row["tiles"]), str(row["count"]),
                  "—" if row["psnr_db"] is None else f"{row['psnr_db']:.2f}",
                  "—" if row["ssim"] is None else f"{row['ssim']:.4f}")
    t.add_row("[bold]all[/]", str(r["tiles"]), str(r["count"]), f"[bold]{r['psnr_db']:.2f}[/]",
              f"[bold]{r['ssim']:.4f}[/]")
    console.print(t)
    what = "restored" if r["restored"] else "pre-restoration"
    noise = f", noise σ = {r['noise_sigma']:g}" if r["noise_sigma"] > 0 else ", no noise"
    console.print(f"{what} PSNR {r['psnr_db']:.2f} dB, SSIM {r['ssim']:.4f} ({r['space']}{noise}; seed {r['seed']})")
    for note in r["notes"]:
        console.print(f"note: {note}")
    console.print("time: " + ", ".join(f"{k} {v:.1f} s" for k, v in r["timings"].items()))
