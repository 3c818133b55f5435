"""The seed's design procedure as one run (S4.2.1: "for each configuration … we generate a rough starting
point …", optimized with the materials free and then bound, restarted until the results agree), and
basin hopping as the global search beyond it. Library code: no printing; the CLI renders the
``ProcedureEvent`` records it receives.

- A *start* is one ``lensopt optimize`` of the spec (both phases: glass variables free, then bound to the
  catalog at ``bind_at``) from a perturbed θ0 (``study.sweep.perturbed_spec``; start 0 is the spec as
  written), evaluated like a sweep's start (final merit with the final weights, ESR). Starts run in
  rounds of ``starts`` tasks, serially or on Dask (``lensopt.parallel``), each on one torch thread.
- **Multi-start** (``method = "multistart"``): round r runs starts r·n … r·n + n − 1.
- **Basin hopping** (``"basin"``): round 0 is a multi-start round; from round 1 on, chain c (one per
  start slot) starts from its current lens perturbed by ``hop_sigma`` (monotonic basin hopping: a hop is
  kept when its final merit is lower, Leary 2000), so the local solver LM explores the neighbourhood
  of the best basins instead of the crude start's. A hop runs at full weight (``--full-weight``).
- **Agreement** (the stated stopping rule): after each round, the run stops when at least
  ``agree_count`` finished starts reached a final merit within ``agree`` (relative) of the best one —
  the best basin was found more than once. Otherwise it stops after ``rounds`` rounds or when the
  starts' CPU time exceeds ``budget_cpu_h``.
- **Distinct minima**: the finished starts grouped by final merit (a new group where the merit rises by
  more than ``agree`` over the group's best), best first, as CODE V's Global Synthesis lists alternatives;
  each with its best start's ESR on ``esr_sampling`` and on the seed's measure (``seed_esr_um``).
- **Resume**: every finished start is written atomically as it finishes (``OUTDIR/points``, as a sweep's
  tasks); a run into the same folder with the same spec and settings skips them, and the basin chains
  are rebuilt from the records (the keep rule is deterministic). Ctrl-C keeps every finished start.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from lensopt.errors import LensoptError
from lensopt.files import json_safe, write_text_atomic
from lensopt.parallel import run_tasks
from lensopt.spec.io import dump_json
from lensopt.spec.models import LensSpec
from lensopt.study.sweep import Settings, Task, load_record, prepare_outdir, run_task, save_record

__all__ = ["ProcedureSettings", "ProcedureEvent", "ProcedureResult", "METHODS", "run_procedure", "minima",
           "agreement"]

METHODS = ("multistart", "basin")
MANIFEST_VERSION = 1


@dataclass(frozen=True)
class ProcedureSettings:
    """Everything that changes the numbers of a run (all of it enters the manifest hash).

    Attributes:
        method: ``multistart`` or ``basin``.
        starts: starts per round (basin: the number of chains).
        rounds: most rounds.
        agree: relative merit tolerance of the agreement rule and of the grouping into minima.
        agree_count: finished starts that must reach the best merit (within ``agree``) to stop.
        sigma, floor: the perturbation of θ0 of the multi-start starts (``study.sweep.Settings``).
        hop_sigma: the perturbation of a basin hop (relative, like ``sigma``).
        steps: optimizer steps per start (None: the spec's ``optimize.steps``).
        seed: pupil jitter seed and first word of every perturbation seed.
        budget_cpu_h: stop starting rounds once the finished starts used this much CPU (None: no limit).
        esr_sampling: pupil sampling of the reported ESR.
    """

    method: str = "multistart"
    starts: int = 4
    rounds: int = 3
    agree: float = 0.02
    agree_count: int = 2
    sigma: float = 0.05
    floor: float = 0.1
    hop_sigma: float = 0.02
    steps: int | None = None
    seed: int = 0
    budget_cpu_h: float | None = None
    esr_sampling: str = "rings:24"

    def task_settings(self, hop: bool) -> Settings:
        """The sweep settings one start runs with. A hop perturbs by ``hop_sigma`` and runs at full weight: it
        continues a chain's lens, whose glasses are bound, so the spec's weight schedules (constraints light
        while the glasses are free) would let it settle outside the constraints and lose to the chain."""
        return Settings(starts=1, sigma=self.hop_sigma if hop else self.sigma, floor=self.floor, steps=self.steps,
                        seed=self.seed, esr_sampling=self.esr_sampling, full_weight=hop)


@dataclass(frozen=True)
class ProcedureEvent:
    """A start finished (``done``), was found on disk (``skipped``), or a round ended (``round``: then
    ``record`` holds the round's summary)."""

    kind: str
    round: int
    record: dict[str, Any]


@dataclass
class ProcedureResult:
    """What a run produced (also written to OUTDIR/design.json; the best lens to OUTDIR/best.json)."""

    settings: ProcedureSettings
    records: list[dict[str, Any]]
    minima: list[dict[str, Any]]
    rounds: int
    agreed: bool
    stop_reason: str
    cpu_s: float
    elapsed_s: float
    interrupted: bool = False
    best: dict[str, Any] | None = None
    summaries: list[dict[str, Any]] = field(default_factory=list)


def _check(settings: ProcedureSettings) -> None:
    if settings.method not in METHODS:
        raise LensoptError(f"must be one of {', '.join(METHODS)}", path="--method", got=settings.method)
    for name, value, low in (("--starts", settings.starts, 1), ("--rounds", settings.rounds, 1),
                             ("--agree-count", settings.agree_count, 1)):
        if value < low:
            raise LensoptError(f"must be at least {low}", path=name, got=value)
    for name, value in (("--agree", settings.agree), ("--perturb", settings.sigma), ("--hop", settings.hop_sigma)):
        if not (math.isfinite(value) and value >= 0):
            raise LensoptError("must be a finite number ≥ 0", path=name, got=value)
    if settings.budget_cpu_h is not None and not (settings.budget_cpu_h > 0):
        raise LensoptError("must be a number of CPU-hours > 0", path="--budget-cpu-h", got=settings.budget_cpu_h)


def manifest(spec_text: str, settings: ProcedureSettings) -> dict[str, Any]:
    """What identifies a run: the spec text and the settings, and their SHA-256. The round limit and the
    CPU budget are left out: a run may be continued with more rounds or more time."""
    args = {k: v for k, v in asdict(settings).items() if k not in ("rounds", "budget_cpu_h")}
    digest = hashlib.sha256((spec_text + "\0" + json.dumps(args, sort_keys=True)).encode()).hexdigest()
    return {"version": MANIFEST_VERSION, "kind": "design", "hash": digest, "settings": args}


def _finished(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [r for r in records if r.get("status") == "finished" and r.get("merit") is not None
            and math.isfinite(r["merit"])]


def agreement(records: list[dict[str, Any]], agree: float) -> tuple[int, dict[str, Any] | None]:
    """(how many finished starts reached the best merit within ``agree`` relative, the best record)."""
    ok = sorted(_finished(records), key=lambda r: (r["merit"], r["round"], r["start"]))
    if not ok:
        return 0, None
    best = ok[0]
    return sum(r["merit"] <= best["merit"] * (1 + agree) + 1e-300 for r in ok), best


def minima(records: list[dict[str, Any]], agree: float) -> list[dict[str, Any]]:
    """The distinct local minima among the finished starts: groups by final merit, best first."""
    groups: list[dict[str, Any]] = []
    for r in sorted(_finished(records), key=lambda r: (r["merit"], r["round"], r["start"])):
        if groups and r["merit"] <= groups[-1]["merit"] * (1 + agree) + 1e-300:
            groups[-1]["count"] += 1
            groups[-1]["members"].append(r["name"])
            continue
        groups.append({"rank": len(groups) + 1, "merit": r["merit"], "esr_um": r.get("esr_um"),
                       "seed_esr_um": r.get("seed_esr_um"), "esr_opt_um": r.get("esr_opt_um"), "best": r["name"],
                       "count": 1, "members": [r["name"]]})
    return groups


def _tasks(spec: LensSpec, settings: ProcedureSettings, rnd: int, chains: list[str]) -> list[tuple[Task, bool]]:
    """The tasks of round ``rnd``: (task, is a hop). Multi-start (and basin round 0): point 0, starts
    rnd·n + i from the spec. Basin round r ≥ 1: chain c is point c + 1, start r, from the chain's lens."""
    n = settings.starts
    if settings.method == "multistart" or rnd == 0:
        text = dump_json(spec)
        return [(Task(0, rnd * n + i, text), False) for i in range(n)]
    return [(Task(c + 1, rnd, chains[c]), True) for c in range(n)]


def _run_one(shared: tuple[ProcedureSettings, dict[bool, Settings]], item: tuple[Task, bool]):  # noqa: ANN202
    """One start on a worker: ``study.sweep.run_task`` with this run's settings, and its CPU time."""
    settings, by_hop = shared
    task, hop = item
    c0 = time.process_time()
    record, lens = run_task(by_hop[hop], task)
    record["cpu_s"] = time.process_time() - c0
    return record, lens


def run_procedure(spec: LensSpec, spec_text: str, settings: ProcedureSettings, outdir: Path, *,
                  scheduler: str | None = None, workers: int = 2, restart: bool = False,
                  callback: Callable[[ProcedureEvent], None] | None = None) -> ProcedureResult:
    """Run (or resume) the procedure into ``outdir`` (module docstring) and write its outputs.

    Args:
        spec_text: the spec file's text (for the manifest hash).
        scheduler: None (serial), ``auto`` (``lensopt.parallel``), ``local`` or a Dask scheduler address.
    """
    t0 = time.perf_counter()
    _check(settings)
    if not any(s.vary for s in spec.surfaces):
        raise LensoptError("nothing to optimize: no surface has a vary list", path="surfaces")
    if spec.optimize is not None and spec.optimize.objective == "restored":
        raise LensoptError('runs the spot and raw objectives; objective = "restored" trains a network per run '
                           "(lensopt optimize --checkpoint)", path="optimize.objective")
    from lensopt.spec.build import build

    build(spec)  # a spec that cannot be built fails here, before any work
    prepare_outdir(outdir, manifest(spec_text, settings), restart=restart, what="design run")
    shared = (settings, {False: settings.task_settings(False), True: settings.task_settings(True)})
    records: list[dict[str, Any]] = []
    chains = [dump_json(spec)] * settings.starts
    chain_merit = [math.inf] * settings.starts
    result = ProcedureResult(settings, records, [], 0, False, "", 0.0, 0.0)
    stop = ""
    try:
        for rnd in range(settings.rounds):
            tasks = _tasks(spec, settings, rnd, chains)
            todo = []
            for i, (task, _) in enumerate(tasks):
                rec = load_record(outdir, task)
                if rec is None:
                    todo.append(i)
                    continue
                rec.setdefault("round", rnd)
                rec["name"] = task.name
                records.append(rec)
                if callback is not None:
                    callback(ProcedureEvent("skipped", rnd, rec))

            def done(j: int, out: tuple[dict[str, Any], str | None], rnd=rnd, tasks=tasks, todo=todo) -> None:
                task, _ = tasks[todo[j]]
                record, lens = out
                record.update(round=rnd, name=task.name)
                save_record(outdir, task, record, lens)
                records.append(record)
                if callback is not None:
                    callback(ProcedureEvent("done", rnd, record))

            run_tasks(_run_one, [tasks[i] for i in todo], shared=shared, scheduler=scheduler, workers=workers,
                      on_done=done)
            result.rounds = rnd + 1
            if settings.method == "basin":
                _advance_chains(outdir, tasks, records, chains, chain_merit, spec)
            count, best = agreement(records, settings.agree)
            cpu = sum(r.get("cpu_s", 0.0) for r in records)
            summary = {"round": rnd, "best_merit": None if best is None else best["merit"],
                       "best": None if best is None else best["name"], "agreeing": count, "cpu_s": cpu}
            result.summaries.append(summary)
            if callback is not None:
                callback(ProcedureEvent("round", rnd, summary))
            if count >= settings.agree_count:
                stop, result.agreed = f"agreed: {count} starts within {100 * settings.agree:g} % of the best", True
                break
            if settings.budget_cpu_h is not None and cpu >= 3600 * settings.budget_cpu_h:
                stop = f"CPU budget of {settings.budget_cpu_h:g} h spent"
                break
        else:
            stop = f"{settings.rounds} rounds without agreement"
    except KeyboardInterrupt:
        result.interrupted, stop = True, "interrupted"
    result.stop_reason = stop
    result.minima = minima(records, settings.agree)
    _, result.best = agreement(records, settings.agree)
    result.cpu_s = sum(r.get("cpu_s", 0.0) for r in records)
    result.elapsed_s = time.perf_counter() - t0
    write_outputs(outdir, result)
    return result


def _advance_chains(outdir: Path, tasks: list[tuple[Task, bool]], records: list[dict[str, Any]], chains: list[str],
                    chain_merit: list[float], spec: LensSpec) -> None:
    """After a round of basin hopping: each chain keeps its hop's lens if the hop's merit is lower. After
    round 0 (multi-start) the chains start from the best distinct results (the best one where fewer)."""
    by_name = {r["name"]: r for r in records}
    if all(not hop for _, hop in tasks):  # round 0: seed the chains with the best starts
        ranked = sorted(_finished([by_name[t.name] for t, _ in tasks if t.name in by_name]),
                        key=lambda r: (r["merit"], r["start"]))
        for c in range(len(chains)):
            if ranked:
                pick = ranked[c % len(ranked)]
                chains[c] = (outdir / "points" / f"{pick['name']}.lens.json").read_text()
                chain_merit[c] = pick["merit"]
        return
    for c, (task, _) in enumerate(tasks):
        rec = by_name.get(task.name)
        if rec is not None and rec.get("status") == "finished" and rec["merit"] < chain_merit[c]:
            chains[c] = (outdir / "points" / f"{task.name}.lens.json").read_text()
            chain_merit[c] = rec["merit"]


def write_outputs(outdir: Path, result: ProcedureResult) -> None:
    """design.json (settings, rounds, starts, minima) and best.json (the best lens), atomic each."""
    doc = {"settings": asdict(result.settings), "rounds": result.rounds, "agreed": result.agreed,
           "stop_reason": result.stop_reason, "cpu_s": result.cpu_s, "elapsed_s": result.elapsed_s,
           "interrupted": result.interrupted, "round_summaries": result.summaries, "minima": result.minima,
           "best": None if result.best is None else result.best["name"],
           "starts": sorted(result.records, key=lambda r: (r.get("round", 0), r["name"]))}
    write_text_atomic(outdir / "design.json", json.dumps(json_safe(doc), indent=2, allow_nan=False) + "\n")
    if result.best is not None:
        lens = (outdir / "points" / f"{result.best['name']}.lens.json").read_text()
        write_text_atomic(outdir / "best.json", lens)
