"""``lensopt warmup``: compile a lens's trace once on this machine (library: ``lensopt.optics.aot``)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer


def register(app: typer.Typer) -> None:
    from lensopt.cli import console, err_console, handle_errors, load_model, print_json

    @app.command()
    @handle_errors
    def warmup(
        lenses: Annotated[list[Path], typer.Argument(help="Lens specs (.toml) or resolved lenses (.json).")],
        recorded: Annotated[bool, typer.Option("--recorded/--no-recorded", help="Also the recorded trace "
                                               "(per-surface hits: the report of `lensopt trace`).")] = True,
        as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object instead of lines.")] = False,
    ) -> None:
        """Compile the trace of each lens structure ahead of time (AOTInductor; about a minute of CPU each,
        once per machine): later commands (trace, plot psf, simulate, evaluate) then load it in milliseconds
        and trace on it by default (--backend auto). Compiled: the plain trace, the recorded one, and the
        lens restricted to the wavelengths an RGB simulation uses when that is fewer."""
        from lensopt.errors import LensoptError
        from lensopt.optics import aot

        rows = []
        for path in lenses:
            model = load_model(path)
            lens = model.lens
            if not aot.supported(lens):
                raise LensoptError("the compiled trace takes lenses without decentered or tilted surfaces, on "
                                   "the CPU", path=str(path), got="placement" if lens.placement is not None
                                   else str(lens.device))
            variants = [(lens, False, "")] + ([(lens, True, "")] if recorded else [])
            rgb = _rgb_lens(model)
            if rgb is not None:
                variants.append((rgb, False, " (the wavelengths an RGB simulation uses)"))
            for variant, record, why in variants:
                desc = aot.describe(variant, record=record) + why
                target = aot.package_path(variant, record=record)
                if target.exists():
                    rows.append({"lens": str(path), "structure": desc, "package": str(target), "built_s": None})
                    if not as_json:
                        console.print(f"{path}: {desc}: already compiled ({target})", highlight=False)
                    continue
                with err_console.status(f"compiling the trace of {path} ({desc}) …", spinner="dots"):
                    seconds = aot.build_package(variant, record=record)
                rows.append({"lens": str(path), "structure": desc, "package": str(target), "built_s": seconds})
                if not as_json:
                    console.print(f"{path}: {desc}: compiled in {seconds:.1f} s ({target})", highlight=False)
        if as_json:
            print_json({"packages": rows})


def _rgb_lens(model: Any) -> Any:
    """The lens restricted to the wavelengths that simulate/evaluate trace for an RGB image (those with a
    non-zero channel weight, ``imaging.plan``), when that is not all of them and the lens has a sensor."""
    from lensopt.analysis.psf_stack import select_wavelengths
    from lensopt.imaging.plan import channel_weights

    spec = model.spec
    if spec.sensor is None:
        return None
    wl = list(spec.spectrum.wavelengths_nm)
    try:
        ww = channel_weights(spec.spectrum, 3, wl)[0]
    except Exception:  # a spectrum simulate would refuse: nothing to warm up for it
        return None
    used = [i for i in range(len(wl)) if ww[i].sum() > 0]
    if len(used) == len(wl):
        return None
    return select_wavelengths(model.lens, model.system, used)[0]
