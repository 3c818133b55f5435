"""Design sweeps with multi-start (seed Figure S13): a spec over a grid of values of one or more keys,
N starts per grid point, the best start kept per point. Library code: no printing; the CLI renders the
``SweepEvent`` records it receives.

- Grid: the full product of the ``Vary`` lists; point i's spec is the input spec with its values set
  (validated again, built once before any work).
- Starts: start 0 is the point's spec as written. Start k ≥ 1 perturbs the start θ0 of the point's
  ``optim.Problem`` (its scaled variables): θ0ᵢ + σ·max(|θ0ᵢ|, floor)·zᵢ with z ~ N(0, 1) drawn from
  ``numpy.random.default_rng([seed, i, k])``, written back into a spec with ``design.writeback.to_spec``,
  then ``design.optimize`` runs unchanged. A start that cannot run (the perturbed lens is unusable,
  a solve fails) is recorded as failed with its reason.
- Tasks: one per (point, start), serially or on Dask (``lensopt.parallel``); each sets torch to one
  thread, so a task's numbers do not depend on where it ran.
- Resume: ``OUTDIR/points/<i>_<k>.json`` (the record) and ``<i>_<k>.lens.json`` (the optimized lens)
  are written atomically as each task finishes; a run into the same folder skips the tasks whose record
  is there. ``OUTDIR/manifest.json`` holds a hash of the spec text and of every argument that changes
  the numbers; a run with other arguments is refused unless ``restart``.
- Best per point: the lowest final merit (½‖ℓ‖² of a fresh ``Problem`` of the optimized lens with the
  final weights) among the finished starts whose final lens is physical; ties go to the lower start.
- Continuation (``Settings.continuation``, one key): the points run in the order given, and point i ≥ 1
  starts from point i−1's best lens (on disk) with point i's value set, instead of from the input spec:
  a walk that carries a basin along the swept value (a total track stepped down from where the basin
  is good to where it is wanted). A point whose predecessor has no finished start fails, naming it.
"""

from __future__ import annotations

import csv
import functools
import hashlib
import io
import itertools
import json
import math
import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lensopt.engine import Engine
from lensopt.errors import LensoptError
from lensopt.files import json_safe, write_text_atomic
from lensopt.parallel import run_tasks
from lensopt.spec.io import dump_json, parse_spec
from lensopt.spec.models import LensSpec
from lensopt.study.keys import Value, Vary, format_value, set_key

__all__ = ["Settings", "Point", "Task", "SweepEvent", "SweepResult", "expand_grid", "perturbed_spec", "run_task",
           "manifest", "prepare_outdir", "check_continuation", "run_sweep", "best_of", "table", "MANIFEST_VERSION"]

MANIFEST_VERSION = 1


@dataclass(frozen=True)
class Settings:
    """What every task of a sweep shares (all of it enters the manifest hash).

    Attributes:
        starts: starts per point (start 0 unperturbed).
        sigma: relative standard deviation of the perturbation of θ0.
        floor: the scale of variables that start at (or near) zero: σ·max(|θ0ᵢ|, floor).
        steps: optimizer steps (None: the spec's ``optimize.steps``).
        seed: pupil jitter seed of ``optimize`` and first word of the perturbation seed.
        esr_sampling: pupil sampling of the reported ESR (``lensopt optimize`` reports gauss:16).
        full_weight: no weight schedules, every constraint group at its final weight from the first step
            (``lensopt optimize --full-weight``): how a basin hop continues a lens whose glasses are bound.
        continuation: each point starts from the previous point's best lens (module doc).
    """

    starts: int = 1
    sigma: float = 0.05
    floor: float = 0.1
    steps: int | None = None
    seed: int = 0
    esr_sampling: str = "gauss:16"
    full_weight: bool = False
    continuation: bool = False


@dataclass(frozen=True)
class Point:
    """Grid point ``index``: the swept values (key → value) and its spec (JSON text)."""

    index: int
    values: dict[str, Value]
    spec_json: str


@dataclass(frozen=True)
class Task:
    point: int
    start: int
    spec_json: str

    @property
    def name(self) -> str:
        return f"{self.point}_{self.start}"


@dataclass(frozen=True)
class SweepEvent:
    """A task finished (``kind`` ``done``) or was found on disk (``skipped``); ``record`` is its record."""

    kind: str
    point: int
    start: int
    record: dict[str, Any]


@dataclass
class SweepResult:
    """Everything a sweep produced (also written to OUTDIR).

    Attributes:
        points: the grid; records: (point, start) → record of every finished or failed task.
        rows: one table row per point (``table``); complete: every task has a record.
        skipped: tasks found on disk; computed: tasks run now; elapsed_s: wall time of this run.
    """

    points: list[Point]
    settings: Settings
    records: dict[tuple[int, int], dict[str, Any]]
    rows: list[dict[str, Any]]
    complete: bool
    skipped: int = 0
    computed: int = 0
    elapsed_s: float = 0.0
    interrupted: bool = False
    keys: list[str] = field(default_factory=list)


# ------------------------------------------------------------------------------------------ grid


def expand_grid(spec: LensSpec, varies: Sequence[Vary]) -> list[Point]:
    """The full grid (the last key varies fastest); each point's spec set, validated and built, so
    that a bad key, value or material fails here, naming ``--vary``, before any work."""
    from lensopt.spec.build import build

    if not varies:
        raise LensoptError("give at least one KEY=V1,V2,...", path="--vary")
    keys = [v.key for v in varies]
    if len(set(keys)) != len(keys):
        raise LensoptError("a key is given twice", path="--vary", got=keys)
    points = []
    for i, combo in enumerate(itertools.product(*(v.values for v in varies))):
        s = spec
        for key, value in zip(keys, combo, strict=True):
            s = set_key(s, key, value)
        shown = ", ".join(f"{k}={format_value(v)}" for k, v in zip(keys, combo, strict=True))
        try:
            build(s)
        except LensoptError as err:
            raise LensoptError(f"{shown} makes an unusable lens: {err}", path="--vary") from None
        if s.optimize is not None and s.optimize.objective == "restored":
            raise LensoptError(f"at {shown}: sweeps run the spot and raw objectives; objective = \"restored\" "
                               "trains a network per run (lensopt optimize --checkpoint)", path="optimize.objective")
        points.append(Point(i, dict(zip(keys, combo, strict=True)), dump_json(s)))
    return points


# ------------------------------------------------------------------------------------- starts


def perturbed_spec(spec: LensSpec, point: int, start: int, settings: Settings, *,
                   engine: Engine | None = None) -> LensSpec:
    """Start ``start`` of grid point ``point``: the spec itself for start 0, else θ0 perturbed (module
    doc) and written back. Deterministic in (settings.seed, point, start).

    Raises:
        LensoptError: the perturbed lens is unusable (the start is then recorded as failed).
    """
    if start == 0:
        return spec
    import torch

    from lensopt.design import build_problem, to_spec

    problem = build_problem(spec, seed=settings.seed, engine=engine)
    theta0 = problem.theta0
    rng = np.random.default_rng([settings.seed, point, start])
    z = torch.from_numpy(rng.standard_normal(theta0.shape[0])).to(theta0)
    scale = torch.clamp(theta0.abs(), min=settings.floor)
    theta = theta0 + settings.sigma * scale * z
    reason = problem.check(theta)  # e.g. a glass thickness ≤ 0, which no spec can hold
    if reason:
        raise LensoptError(f"the perturbed start is unusable: {reason}")
    try:
        return to_spec(problem, theta)
    except ValueError as err:  # the spec's validation of a written-back value
        raise LensoptError(f"the perturbed start is not a valid spec: {' '.join(str(err).split())}") from None


def run_task(settings: Settings, task: Task, *, engine: Engine | None = None) -> tuple[dict[str, Any], str | None]:
    """One (point, start): perturb, optimize, evaluate. Returns the record and the optimized lens as JSON
    text (None when the start failed). Runs on a Dask worker or in-process, with one torch thread."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    t0 = time.perf_counter()
    record: dict[str, Any] = {"point": task.point, "start": task.start}
    try:
        spec = parse_spec(json.loads(task.spec_json))
        try:
            start_spec = perturbed_spec(spec, task.point, task.start, settings, engine=engine)
            result = optimize(start_spec, steps=settings.steps, seed=settings.seed, full_weight=settings.full_weight,
                              engine=engine)
            if result.interrupted:  # Ctrl-C in a serial run: the start is not finished
                raise KeyboardInterrupt
            merit, physical, reason, esr_opt = _final_merit(result.spec, settings, engine=engine)
            esr, seed_esr = _report_esr(result.spec, settings, engine=engine) if physical else (None, None)
        except LensoptError as err:  # the start cannot run, or its result cannot be evaluated
            record.update(status="failed", reason=str(err), wall_s=time.perf_counter() - t0)
            return record, None
        record.update(status="finished" if physical else "failed", reason=reason, merit=merit,
                      esr_um=esr, seed_esr_um=seed_esr, esr_opt_um=esr_opt, steps=result.steps,
                      stop_reason=result.stop_reason, start_merit=result.start_merit,
                      start_esr_opt_um=result.start_esr_um, warning=result.warning,
                      bound=[b.name for b in result.bound], wall_s=time.perf_counter() - t0)
        return record, dump_json(result.spec)
    finally:
        torch.set_num_threads(threads)


def optimize(spec: LensSpec, *, steps: int | None, seed: int, full_weight: bool = False,
             engine: Engine | None = None):  # noqa: ANN201 - design.optimize, by name
    """``lensopt.design.optimize`` (a module-level name, so that tests can count the calls)."""
    from lensopt.design import optimize as run_optimize

    return run_optimize(spec, steps=steps, seed=seed, full_weight=full_weight, engine=engine)


def _final_merit(spec: LensSpec, settings: Settings, *, engine: Engine | None = None) -> tuple[float, bool, str, float]:
    """(½‖ℓ‖² with the final weights, physical, reason, ESR of the optimization rays µm) of a lens."""
    from lensopt.design import build_problem

    problem = build_problem(spec, seed=settings.seed, engine=engine)
    ev = problem.evaluate(problem.theta0)
    if not ev.physical:
        return math.nan, False, ev.reason, math.nan
    r = problem.row_scale(1.0) * ev.residuals
    return 0.5 * float((r**2).sum()), True, "", 1e3 * problem.esr_mm(ev.residuals)


def _report_esr(spec: LensSpec, settings: Settings, *,
                engine: Engine | None = None) -> tuple[float | None, float | None]:
    """(ESR in µm as ``lensopt trace`` / ``lensopt optimize`` report it, ESR in µm on the seed's measure
    (``analysis.report.seed_esr_um``)); None when rays fail."""
    from lensopt.analysis.report import seed_esr_um, trace_report
    from lensopt.optics.sampling import PupilSampling
    from lensopt.spec.build import build

    model = build(spec)
    rep = trace_report(model, PupilSampling.parse(settings.esr_sampling, seed=settings.seed, weighted=True),
                       engine=engine)
    return rep["effective_spot_radius_um"], seed_esr_um(model, engine=engine)


# ------------------------------------------------------------------------------- resume, output


def manifest(spec_text: str, varies: Sequence[Vary], settings: Settings) -> dict[str, Any]:
    """What identifies a sweep: the spec text, the grid and the settings, and their SHA-256."""
    fields = asdict(settings)
    if not settings.continuation:  # the manifests of sweeps written before the option keep their hash
        del fields["continuation"]
    args = {"vary": [[v.key, list(v.values)] for v in varies], "settings": fields}
    digest = hashlib.sha256((spec_text + "\0" + json.dumps(args, sort_keys=True)).encode()).hexdigest()
    return {"version": MANIFEST_VERSION, "hash": digest, **args}


def prepare_outdir(outdir: Path, man: dict[str, Any], *, restart: bool = False, what: str = "sweep") -> None:
    """Check that ``outdir`` is new, empty or a sweep of the same manifest (else ``LensoptError``,
    ``--output``); with ``restart`` clear a previous sweep there first. Writes the manifest."""
    mpath = outdir / "manifest.json"
    if outdir.exists() and not outdir.is_dir():
        raise LensoptError("is a file; give a folder", path="--output", got=str(outdir))
    if mpath.is_file():
        try:
            old = json.loads(mpath.read_text())
        except (OSError, ValueError):
            old = {}
        if old.get("hash") != man["hash"]:
            if not restart:
                raise LensoptError(f"holds a {what} made with another spec or other arguments (manifest hash "
                                   f"{str(old.get('hash'))[:12]} ≠ {man['hash'][:12]}); use --restart to start "
                                   "it over, or another folder", path="--output", got=str(outdir))
        elif not restart:
            return
        _clear(outdir)
    elif outdir.is_dir() and any(outdir.iterdir()):
        raise LensoptError(f"exists and is not a {what} folder (no manifest.json); give a new or empty folder",
                           path="--output", got=str(outdir))
    write_text_atomic(mpath, json.dumps(man, indent=2) + "\n")


def _clear(outdir: Path) -> None:
    """Remove what a sweep or a design run (``study.procedure``) writes (and nothing else)."""
    if (outdir / "points").is_dir():
        shutil.rmtree(outdir / "points")
    for p in outdir.iterdir():
        if p.name in ("manifest.json", "sweep.json", "sweep.csv", "sweep.png", "design.json", "best.json") or (
                p.name.startswith("best_") and p.suffix == ".json"):
            p.unlink()


def load_record(outdir: Path, task: Task) -> dict[str, Any] | None:
    """The record of ``task`` written by an earlier run into ``outdir`` (None if there is none, or if
    it says finished but its lens file is missing)."""
    path = outdir / "points" / f"{task.name}.json"
    if not path.is_file():
        return None
    try:
        rec = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if rec.get("status") == "finished" and not (outdir / "points" / f"{task.name}.lens.json").is_file():
        return None
    return rec


def save_record(outdir: Path, task: Task, record: dict[str, Any], lens_json: str | None) -> None:
    """Write a task's record (and its lens first: a record on disk means its lens is complete)."""
    if lens_json is not None:  # the lens first: a record on disk means its lens is complete
        write_text_atomic(outdir / "points" / f"{task.name}.lens.json", lens_json)
    write_text_atomic(outdir / "points" / f"{task.name}.json", json.dumps(record, indent=2) + "\n")


def best_of(records: Sequence[dict[str, Any]]) -> dict[str, Any] | None:
    """The finished start with the lowest merit (ties: the lower start), None if none finished."""
    ok = [r for r in records if r.get("status") == "finished" and r.get("merit") is not None
          and math.isfinite(r["merit"])]
    return min(ok, key=lambda r: (r["merit"], r["start"])) if ok else None


def table(points: Sequence[Point], records: dict[tuple[int, int], dict[str, Any]], starts: int) -> list[dict[str, Any]]:
    """One row per point: the swept values, the best start's ESR (µm; ``--esr-sampling`` and the seed's
    measure), merit, steps, stop reason, and how many starts finished or failed; ``wall_s`` is the sum over
    the point's tasks. A record written before the seed's measure was reported has none (None)."""
    rows = []
    for p in points:
        recs = [records[(p.index, k)] for k in range(starts) if (p.index, k) in records]
        best = best_of(recs)
        rows.append({
            "point": p.index, **{k: v for k, v in p.values.items()},
            "best_esr_um": best["esr_um"] if best else None,
            "best_merit": best["merit"] if best else None,
            "best_start": best["start"] if best else None,
            "best_steps": best["steps"] if best else None,
            "best_stop_reason": best["stop_reason"] if best else None,
            "starts_finished": sum(r["status"] == "finished" for r in recs),
            "starts_failed": sum(r["status"] == "failed" for r in recs),
            "wall_s": sum(r.get("wall_s", 0.0) for r in recs),
            # Last, so that the columns of sweep.csv before it keep their places.
            "best_seed_esr_um": best.get("seed_esr_um") if best else None,
        })
    return rows


def _csv(rows: list[dict[str, Any]]) -> str:
    buf = io.StringIO()
    if rows:
        w = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({k: ("" if v is None else repr(v) if isinstance(v, float) else v) for k, v in r.items()})
    return buf.getvalue()


def write_outputs(outdir: Path, result: SweepResult, *, spec_name: str, plot: bool = True) -> None:
    """sweep.json, sweep.csv, best_<i>.json and sweep.png (atomic each)."""
    starts = [result.records[k] for k in sorted(result.records)]
    doc = {"spec": spec_name, "keys": result.keys, "settings": asdict(result.settings),
           "complete": result.complete, "points": result.rows, "starts": starts}
    write_text_atomic(outdir / "sweep.json", json.dumps(json_safe(doc), indent=2, allow_nan=False) + "\n")
    write_text_atomic(outdir / "sweep.csv", _csv(result.rows))
    for row in result.rows:
        if row["best_start"] is not None:
            lens = (outdir / "points" / f"{row['point']}_{row['best_start']}.lens.json").read_text()
            write_text_atomic(outdir / f"best_{row['point']}.json", lens)
    if plot:
        from lensopt.plot.style import save_figure
        from lensopt.plot.sweep import sweep_figure

        key = result.keys[0]
        others = result.keys[1:]
        series: dict[str, list[tuple[float, float]]] = {}
        for row in result.rows:
            label = ", ".join(f"{k}={format_value(row[k])}" for k in others)
            if row["best_esr_um"] is not None and _is_num(row[key]):
                series.setdefault(label, []).append((float(row[key]), row["best_esr_um"]))
        dots = [(float(next(p.values[key] for p in result.points if p.index == r["point"])), r["esr_um"])
                for r in starts if r.get("status") == "finished" and r.get("esr_um") is not None
                and _is_num(result.points[r["point"]].values[key])]
        if series or dots:
            save_figure(sweep_figure(series, dots, xlabel=key, title=spec_name), outdir / "sweep.png", dpi=150)


def _is_num(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


# ------------------------------------------------------------------------------------------- run


def check_continuation(varies: Sequence[Vary]) -> None:
    """A continuation walks along exactly one key (else ``LensoptError`` naming ``--continuation``)."""
    if len(varies) != 1:
        raise LensoptError("a continuation walks along one key: give one --vary", path="--continuation",
                           got=[v.key for v in varies])


def _continued_spec(outdir: Path, point: Point, points: Sequence[Point], records: dict[tuple[int, int], dict[str, Any]],
                    starts: int) -> tuple[str | None, str]:
    """(the start spec of ``point`` in a continuation as JSON text, "") — point 0: its own spec; point i:
    point i−1's best lens with point i's value set — or (None, why) when there is nothing to continue from."""
    if point.index == 0:
        return point.spec_json, ""
    prev = points[point.index - 1]
    best = best_of([records[(prev.index, k)] for k in range(starts) if (prev.index, k) in records])
    if best is None:
        return None, f"the continuation stopped: point {prev.index} has no finished start"
    from lensopt.spec.build import build

    lens = parse_spec(json.loads((outdir / "points" / f"{prev.index}_{best['start']}.lens.json").read_text()))
    (key, value), = point.values.items()
    shown = f"{key}={format_value(value)}"
    try:
        lens = set_key(lens, key, value)
        build(lens)
    except LensoptError as err:
        return None, f"point {prev.index}'s lens with {shown} is unusable: {err}"
    return dump_json(lens), ""


def run_sweep(spec: LensSpec, spec_text: str, varies: Sequence[Vary], settings: Settings, outdir: Path, *,
              scheduler: str | None = None, workers: int = 2, restart: bool = False, spec_name: str = "",
              callback: Callable[[SweepEvent], None] | None = None, plot: bool = True,
              points: list[Point] | None = None, on_plan: Callable[[str], None] | None = None,
              engine: Engine | None = None) -> SweepResult:
    """Run (or resume) a sweep into ``outdir`` and write its outputs.

    Args:
        spec_text: the spec file's text (for the manifest hash).
        scheduler: None (serial), ``auto``, ``local`` or a Dask scheduler address (``lensopt.parallel``).
        points: the grid if already expanded (``expand_grid``).
        on_plan: told in words how the tasks run (what ``auto`` chose and why).

    A KeyboardInterrupt (Ctrl-C) stops the run: the finished tasks stay on disk, the table of what
    finished is written (no plot) and the result says ``interrupted``.
    """
    t0 = time.perf_counter()
    if settings.starts < 1:
        raise LensoptError("must be at least 1", path="--starts", got=settings.starts)
    if not (settings.sigma >= 0 and math.isfinite(settings.sigma)):
        raise LensoptError("must be a finite number ≥ 0", path="--perturb", got=settings.sigma)
    if not any(s.vary for s in spec.surfaces):
        raise LensoptError("nothing to optimize: no surface has a vary list", path="surfaces")
    if settings.continuation:
        check_continuation(varies)
    points = points if points is not None else expand_grid(spec, varies)
    prepare_outdir(outdir, manifest(spec_text, varies, settings), restart=restart)
    records: dict[tuple[int, int], dict[str, Any]] = {}
    n_tasks = len(points) * settings.starts
    result = SweepResult(points, settings, records, [], False, keys=[v.key for v in varies])
    plans: set[str] = set()

    def plan(why: str) -> None:  # said once (a continuation runs its points one after another)
        if on_plan is not None and why not in plans:
            on_plan(why)
        plans.add(why)

    def run(tasks: list[Task], failed: str = "") -> None:
        """Run the tasks without a record on disk; with ``failed``, record them as failed for that reason."""
        todo = []
        for t in tasks:
            rec = load_record(outdir, t)
            if rec is None:
                todo.append(t)
            else:
                records[(t.point, t.start)] = rec
                result.skipped += 1
                if callback is not None:
                    callback(SweepEvent("skipped", t.point, t.start, rec))

        def done(i: int, out: tuple[dict[str, Any], str | None]) -> None:
            t = todo[i]
            record, lens_json = out
            save_record(outdir, t, record, lens_json)
            records[(t.point, t.start)] = record
            result.computed += 1
            if callback is not None:
                callback(SweepEvent("done", t.point, t.start, record))

        if failed:
            for i, t in enumerate(todo):
                done(i, ({"point": t.point, "start": t.start, "status": "failed", "reason": failed, "wall_s": 0.0},
                         None))
            return
        run_tasks(functools.partial(run_task, engine=engine), todo, shared=settings, scheduler=scheduler,
                  workers=workers, on_done=done, on_plan=plan)

    try:
        if settings.continuation:
            for p in points:  # nothing to continue from (``why``): the point's starts fail, naming why
                start_json, why = _continued_spec(outdir, p, points, records, settings.starts)
                run([Task(p.index, k, start_json or p.spec_json) for k in range(settings.starts)], failed=why)
        else:
            run([Task(p.index, k, p.spec_json) for p in points for k in range(settings.starts)])
    except KeyboardInterrupt:
        result.interrupted = True
    result.rows = table(points, records, settings.starts)
    result.complete = len(records) == n_tasks
    result.elapsed_s = time.perf_counter() - t0
    write_outputs(outdir, result, spec_name=spec_name, plot=plot and not result.interrupted)
    return result
