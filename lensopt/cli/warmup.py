"""``lensopt warmup``: compile a lens's trace once on this machine (library: ``lensopt.accel.aot``), and with
``--jacobian`` the LM Jacobian of a spec's optimization problem (``lensopt.accel.jacobian``)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from lensopt.cli.common import console, err_console, handle_errors, load_model, make_engine, print_json
from lensopt.errors import LensoptError

__all__ = ["commands"]

commands = typer.Typer()  # its command, put in order by lensopt.cli.app


@commands.command("warmup")
@handle_errors
def warmup(
    lenses: Annotated[list[Path], typer.Argument(help="Lens specs (.toml) or resolved lenses (.json).")],
    recorded: Annotated[bool, typer.Option("--recorded/--no-recorded", help="Also the recorded trace "
                                           "(per-surface hits: the report of `lensopt trace`).")] = True,
    jacobian: Annotated[bool, typer.Option("--jacobian", help="Also the LM Jacobian of each spec's optimization "
                                           "problem (its first phase), which `optimize --jacobian compiled` "
                                           "then loads.")] = False,
    seed: Annotated[int, typer.Option("--seed", min=0, help="--jacobian: the seed `optimize` will get (the "
                                      "pupil jitter is part of the problem).")] = 0,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object instead of lines.")] = False,
) -> None:
    """Compile the trace of each lens structure ahead of time (AOTInductor; about a minute of CPU each,
    once per machine): later commands (trace, plot psf, simulate, evaluate) then load it in milliseconds
    and trace on it by default (--backend auto). Compiled: the plain trace, the recorded one, and the
    lens restricted to the wavelengths an RGB simulation uses when that is fewer. With --jacobian, also the
    compiled LM Jacobian of each spec's optimization problem (minutes of CPU; `optimize --jacobian
    compiled` with the same spec and seed then loads it instead of compiling)."""
    from lensopt.accel import aot

    rows = []
    models = {path: load_model(path) for path in lenses}  # every input checked before any work
    engine = make_engine() if jacobian else None  # the engine `optimize` gets: its backend is in the package key
    problems = {path: _jacobian_problem(path, m.spec, seed, engine) for path, m in models.items()} if jacobian else {}
    for path, model in models.items():
        lens = model.lens
        if not aot.supported(lens):
            raise LensoptError("the compiled trace takes lenses without decentered or tilted surfaces, on "
                               "the CPU", path=str(path), got="placement" if lens.placement is not None
                               else str(lens.device))
    for path, model in models.items():
        lens = model.lens
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
        if jacobian:
            rows.append(_jacobian_package(path, *problems[path], as_json))
    if as_json:
        print_json({"packages": rows})


def _jacobian_problem(path: Path, spec: Any, seed: int, engine: Any) -> tuple[Any, str]:
    """``spec``'s optimization problem as ``optimize`` builds it, and its package key; a one-line error when
    it has none."""
    from lensopt.accel import jacobian as cj
    from lensopt.design import build_problem

    problem = build_problem(spec, seed=seed, engine=engine)
    if problem.num_variables == 0:
        raise LensoptError("nothing to optimize: no surface has a vary list", path=str(path))
    key = cj.problem_key(problem)
    if key is None:
        raise LensoptError("this optimization problem has no Jacobian package (image objectives change their "
                           "residual function with every batch)", path=f"{path}: optimize.objective")
    return problem, key


def _jacobian_package(path: Path, problem: Any, key: str, as_json: bool) -> dict[str, Any]:
    """Build (or find) the Jacobian package of ``problem``."""
    from lensopt.accel import jacobian as cj

    desc = f"LM Jacobian (N = {problem.num_variables}, M = {problem.size}, seed {problem.seed})"
    target = cj.package_path(key)
    seconds = None
    if target.exists():
        if not as_json:
            console.print(f"{path}: {desc}: already compiled ({target})", highlight=False)
    else:
        with err_console.status(f"compiling the {desc} of {path} …", spinner="dots"):
            _, seconds = cj.build_package(problem, problem.theta0, key)
        if not as_json:
            console.print(f"{path}: {desc}: compiled in {seconds:.1f} s ({target})", highlight=False)
    return {"lens": str(path), "structure": desc, "package": str(target), "built_s": seconds}


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
