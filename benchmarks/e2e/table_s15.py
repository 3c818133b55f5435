"""Seed Table S15 (spot / raw / restored C-mount lenses, each with its own restoration network) at a
budget that fits a shared 2-core CPU.

The three rows:

- spot: ``lenses/cmount_4p.json`` (shipped), its network trained by ``lensopt train-irm``;
- raw: ``lenses/cmount_4p_raw.json`` (shipped), its network trained by ``lensopt train-irm``;
- restored: ``lensopt optimize`` of a copy of ``specs/cmount_4p_restored.toml`` (joint LM lens step +
  Adam network step from the spot lens), at the small batch, patch and step count given here.

Fair comparison: the two ``train-irm`` networks get the same number of Adam steps, batch, patch, PSF
size, fields, pupil sampling, PSF grid, noise, learning rate and schedule as the joint run's network.
Every copy here gets the restored spec's ``rgb_weights`` (the hard R/G/B split of the spectrum, which does
not touch the geometry; the shipped spot and raw lenses carry the same since 2026-11-28), so that all three
networks restore the same 3 channels.

Evaluation: ``lensopt evaluate LENS --irm CKPT --noise 0.005 --json`` (before and after restoration) on
held-out dead-leaves scenes of a seed used by no training source, and on the held-out photographs
(``evaluate --images photos --patch 128``: every 128² tile of astronaut, chelsea and coffee, which no
training source draws; until 2026-11-28 the central 256² crops of 8 scikit-image photographs); ESR
from ``lensopt trace LENS --json`` (rings:24).

    PYTHONPATH=. python benchmarks/e2e/table_s15.py --steps 500 --batch 4 --patch 64 --control --extra-seeds 1
    # → out/table_s15/ (lenses, checkpoints, logs) and benchmarks/e2e/results_table_s15.json

The restored run and the two ``train-irm`` runs go as two processes side by side (``--parallel 2``,
one thread each). ``--skip-main`` re-uses the three main runs of an earlier call in the same ``--work`` (the extra and
control runs are re-used whenever their checkpoint has reached ``--steps``).
``--control`` adds a fourth row: the restored lens with a fresh ``train-irm`` network of the same
budget (is the gain the lens's or the joint training's?).

Issue 27's multi-seed table (every network trained on the bundled training photographs, ``--images photos``;
the joint run too, through ``[optimize.image] images``; rows spot / raw / restored = the polished joint lens,
seeds 0, 1, 2 each; ``multi_seed`` in ``--out``), as run on 2026-11-28 in stages on a loaded machine:

    PYTHONPATH=. python benchmarks/e2e/table_s15.py --steps 200 --joint-steps 40 --images photos \
        --extra-seeds 0 1 2 --polish --polish-seeds 1 2 --parallel 2 --work out/t15 --ship
    # (the joint run was stopped at step 40 of 100 with Ctrl-C; --joint-steps 40 records that budget)
    PYTHONPATH=. python benchmarks/e2e/table_s15.py --evaluate-only --steps 200 --joint-steps 40 --images photos \
        --extra-seeds 0 1 2 --polish --polish-seeds 1 2 --parallel 4 --work out/t15
    # then the joint run resumed to its end (lensopt optimize START --checkpoint out/t15/ck_restored --resume, START
    # the checkpoint's start_spec, 100 steps), and the restored rows made again from it (the spot/raw rows kept):
    PYTHONPATH=. python benchmarks/e2e/table_s15.py --skip-main --steps 200 --joint-steps 100 --images photos \
        --extra-seeds 0 1 2 --polish --polish-seeds 1 2 --work out/t15 --reuse-rows --reuse-from ROWS.json --ship

``--ship`` writes ``lenses/cmount_4p_restored.json`` and ``lenses/networks/LENS/`` (seed-0 networks, float16).

``--sources procedural textured photos textured+photos`` runs instead the transfer study of issue 27: the
spot lens's network trained by ``train-irm --images SOURCE`` (same steps, batch, patch, seed for every
source), each scored by ``evaluate --irm --noise 0.005 --patch 128`` on the held-out photographs (every
128² tile of astronaut, chelsea, coffee: ``evaluate --images photos``, never drawn in training), on
held-out dead leaves and on held-out textured dead leaves (seed 424242); written to the key
``scenes_transfer`` of ``--out`` (the Table S15 rows there are kept, and a Table S15 run keeps it).

    PYTHONPATH=. python benchmarks/e2e/table_s15.py --steps 500 --batch 4 --patch 64 \
        --sources procedural textured photos textured+photos --work out/scenes_transfer
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
EVAL_SEED = 424242  # dead-leaves seed of the held-out scenes: training uses seeds 0 and 1 000 003


def _python() -> list[str]:
    return [sys.executable, "-m", "lensopt"]


def write_inputs(work: Path, a: argparse.Namespace) -> dict[str, Path]:
    """The three start files in ``work``: spot and raw lenses with the restored spec's RGB split and
    ``[restore]`` section, and the restored spec at this budget."""
    sys.path.insert(0, str(ROOT))
    from lensopt.spec import load_spec

    restored = load_spec(ROOT / "specs/cmount_4p_restored.toml")
    img = restored.optimize.image.model_copy(update={"batch": a.batch, "patch": a.patch, "psf_size": a.psf_size,
                                                     "validation": a.val_patches,
                                                     "images": None if a.images == "procedural" else a.images})
    train = restored.restore.train.model_copy(update={
        "steps": a.steps, "batch": a.batch, "patch": a.patch, "validation_patches": a.val_patches,
        "checkpoint_every": a.checkpoint_every, "validate_every": a.validate_every})
    rest = restored.restore.model_copy(update={"train": train})
    opt = restored.optimize.model_copy(update={"image": img, "steps": a.joint_steps or a.steps})
    out = {}
    spec = restored.model_copy(update={"optimize": opt, "restore": rest})
    out["restored_start"] = work / "cmount_4p_restored_start.json"
    out["restored_start"].write_text(spec.model_dump_json(indent=1, exclude_none=True))
    for seed in a.joint_seeds:  # the same run with other batches, held-out patches and network initialisation
        o = opt.model_copy(update={"image": img.model_copy(update={"seed": seed})})
        out[f"restored_start_seed{seed}"] = work / f"cmount_4p_restored_start_seed{seed}.json"
        out[f"restored_start_seed{seed}"].write_text(
            restored.model_copy(update={"optimize": o, "restore": rest}).model_dump_json(indent=1, exclude_none=True))
    for name, path in (("spot", "lenses/cmount_4p.json"), ("raw", "lenses/cmount_4p_raw.json")):
        lens = load_spec(ROOT / path)
        spectrum = lens.spectrum.model_copy(update={"rgb_weights": restored.spectrum.rgb_weights})
        lens = lens.model_copy(update={"spectrum": spectrum, "restore": rest})
        out[name] = work / f"{name}.json"
        out[name].write_text(lens.model_dump_json(indent=1, exclude_none=True))
    return out


def _run(cmd: list[str], log: Path, *, append: bool = False) -> subprocess.Popen:
    env = dict(os.environ, OMP_NUM_THREADS=str(1), PYTHONPATH=str(ROOT))
    print("$ " + " ".join(cmd), flush=True)
    return subprocess.Popen(cmd, stdout=log.open("a" if append else "w"), stderr=subprocess.STDOUT, env=env, cwd=ROOT)


def _wait(procs: list[tuple[str, subprocess.Popen, float]], times: dict[str, float]) -> None:
    for name, p, t0 in procs:
        rc = p.wait()
        times[name] = time.perf_counter() - t0
        if rc != 0:
            raise SystemExit(f"{name} failed (exit {rc}); see its log in the work folder")


def _irm_opts(a: argparse.Namespace) -> list[str]:
    """train-irm options that give the network the joint run's budget and rendering."""
    return ["--steps", str(a.steps), "--batch", str(a.batch), "--patch", str(a.patch),
            "--psf-size", str(a.psf_size), "--fields", "9", "--sampling", "rings:8", "--grid", "3x3",
            "--checkpoint-every", str(a.checkpoint_every), "--validate-every", str(a.validate_every),
            "--val-patches", str(a.val_patches), "--images", a.images]


def train(work: Path, files: dict[str, Path], a: argparse.Namespace) -> dict[str, float]:
    """The joint run and the two train-irm runs; wall seconds of each."""
    irm_opts = _irm_opts(a)
    jobs = {
        "restored": _python() + ["optimize", str(files["restored_start"]), "-o", str(work / "restored.json"),
                                 "--checkpoint", str(work / "ck_restored"), "--log-dir", str(work / "tb_restored")],
        "spot": _python() + ["train-irm", str(files["spot"]), "-o", str(work / "ck_spot"),
                             "--log-dir", str(work / "tb_spot")] + irm_opts,
        "raw": _python() + ["train-irm", str(files["raw"]), "-o", str(work / "ck_raw"),
                            "--log-dir", str(work / "tb_raw")] + irm_opts,
    }
    for name in jobs:
        for p in (work / f"ck_{name}", work / f"tb_{name}"):
            shutil.rmtree(p, ignore_errors=True)
    times: dict[str, float] = {}
    if a.parallel >= 2:
        # The joint step costs about two network steps: the joint run beside spot-then-raw.
        t0 = time.perf_counter()
        pr = _run(jobs["restored"], work / "restored.log")
        ps = _run(jobs["spot"], work / "spot.log")
        ts = time.perf_counter()
        rc = ps.wait()
        times["spot"] = time.perf_counter() - ts
        if rc != 0:
            raise SystemExit("spot train-irm failed; see spot.log")
        tr = time.perf_counter()
        _wait([("raw", _run(jobs["raw"], work / "raw.log"), tr), ("restored", pr, t0)], times)
    else:
        for name, cmd in jobs.items():
            _wait([(name, _run(cmd, work / f"{name}.log"), time.perf_counter())], times)
    return times


def _finished(ck: Path, steps: int) -> bool:
    """A checkpoint of a finished run (re-used, not trained again)."""
    from lensopt.checkpoint import load_checkpoint

    return ck.exists() and load_checkpoint(ck).step == steps


def train_extra_seeds(work: Path, files: dict[str, Path], a: argparse.Namespace) -> dict[str, float]:
    """Networks for the spot and raw lenses again with other seeds (initial weights, scenes, tiles, noise
    and the train-irm validation patches): how much of a row's score is the draw of one training run."""
    times: dict[str, float] = {}
    for seed in a.extra_seeds:
        for name in ("spot", "raw"):
            tag = f"{name}_seed{seed}"
            if _finished(work / f"ck_{tag}", a.steps):
                continue
            cmd = _python() + ["train-irm", str(files[name]), "-o", str(work / f"ck_{tag}"), "--log-dir",
                               str(work / f"tb_{tag}"), "--seed", str(seed)] + _irm_opts(a)
            for p in (work / f"ck_{tag}", work / f"tb_{tag}"):
                shutil.rmtree(p, ignore_errors=True)
            a.pending.append((tag, cmd))
    return times


def run_pending(work: Path, a: argparse.Namespace) -> dict[str, float]:
    """The queued train-irm runs, ``a.parallel`` side by side (one thread each)."""
    times: dict[str, float] = {}
    for k in range(0, len(a.pending), a.parallel):
        _wait([(tag, _run(cmd, work / f"{tag}.log"), time.perf_counter()) for tag, cmd in a.pending[k:k + a.parallel]],
              times)
    a.pending.clear()
    return times


def train_joint_seeds(work: Path, files: dict[str, Path], a: argparse.Namespace) -> dict[str, float]:
    """The joint run again with other seeds (``[optimize.image] seed`` and ``--seed``)."""
    times: dict[str, float] = {}
    for seed in a.joint_seeds:
        tag = f"restored_seed{seed}"
        if _finished(work / f"ck_{tag}", a.steps):
            continue
        for p in (work / f"ck_{tag}", work / f"tb_{tag}"):
            shutil.rmtree(p, ignore_errors=True)
        cmd = _python() + ["optimize", str(files[f"restored_start_seed{seed}"]), "-o", str(work / f"{tag}.json"),
                           "--checkpoint", str(work / f"ck_{tag}"), "--log-dir", str(work / f"tb_{tag}"),
                           "--seed", str(seed)]
        _wait([(tag, _run(cmd, work / f"{tag}.log"), time.perf_counter())], times)
    return times


def train_control(work: Path, a: argparse.Namespace) -> float:
    """A fourth row: a fresh network trained by train-irm (same budget) for the lens the joint run wrote,
    to tell the lens's share of the restored row's gain from the joint training's."""
    lens = work / "restored.json"
    if _finished(work / "ck_restored_irm", a.steps):
        return 0.0
    cmd = _python() + ["train-irm", str(lens), "-o", str(work / "ck_restored_irm"), "--log-dir",
                       str(work / "tb_restored_irm")] + _irm_opts(a)
    for p in (work / "ck_restored_irm", work / "tb_restored_irm"):
        shutil.rmtree(p, ignore_errors=True)
    times: dict[str, float] = {}
    _wait([("restored_irm", _run(cmd, work / "restored_irm.log"), time.perf_counter())], times)
    return times["restored_irm"]


POLISH = ROOT / "specs" / "stages" / "cmount_4p_raw_polish.toml"


def polish(work: Path, a: argparse.Namespace) -> dict[str, float]:
    """A fifth row: the joint run's lens made to meet the 2 % distortion requirement by the raw lens's own
    polish stage (the ``[optimize]`` of ``specs/stages/cmount_4p_raw_polish.toml``: 4 LM steps on the raw
    image loss with the distortion weight 1000 and ``max_percent = 1.95``), then a fresh ``train-irm``
    network of the same budget for the polished lens (as ``--control`` does for the unpolished one)."""
    import tomllib

    from lensopt.spec import load_spec
    from lensopt.spec.optim import OptimizeSpec

    times: dict[str, float] = {}
    lens_out = work / "restored_polished.json"
    if not lens_out.exists():
        opt = OptimizeSpec.model_validate(tomllib.loads(POLISH.read_text())["optimize"])
        weight, max_percent = a.polish_distortion
        dist = opt.constraints.distortion.model_copy(update={"weight": weight, "max_percent": max_percent})
        opt = opt.model_copy(update={"steps": a.polish_steps,
                                     "constraints": opt.constraints.model_copy(update={"distortion": dist})})
        start = work / "restored_polish_start.json"
        start.write_text(load_spec(work / "restored.json").model_copy(update={"optimize": opt})
                         .model_dump_json(indent=1, exclude_none=True))
        # S6.1 allows 2 %: a lens within it but above the polish's tighter 1.9 % is kept (exit 3 otherwise)
        cmd = _python() + ["optimize", str(start), "-o", str(lens_out), "--seed", "0", "--allow-violations"]
        _wait([("restored_polish", _run(cmd, work / "restored_polish.log"), time.perf_counter())], times)
    if not _finished(work / "ck_restored_polished", a.steps):
        for p in (work / "ck_restored_polished", work / "tb_restored_polished"):
            shutil.rmtree(p, ignore_errors=True)
        cmd = _python() + ["train-irm", str(lens_out), "-o", str(work / "ck_restored_polished"), "--log-dir",
                           str(work / "tb_restored_polished")] + _irm_opts(a)
        a.pending.append(("restored_polished_irm", cmd))
    for seed in a.polish_seeds:  # the polished lens's network with other seeds
        tag = f"restored_polished_seed{seed}"
        if _finished(work / f"ck_{tag}", a.steps):
            continue
        for p in (work / f"ck_{tag}", work / f"tb_{tag}"):
            shutil.rmtree(p, ignore_errors=True)
        cmd = _python() + ["train-irm", str(lens_out), "-o", str(work / f"ck_{tag}"), "--log-dir",
                           str(work / f"tb_{tag}"), "--seed", str(seed)] + _irm_opts(a)
        a.pending.append((tag, cmd))
    return times


def _json_out(cmd: list[str]) -> dict[str, Any]:
    env = dict(os.environ, OMP_NUM_THREADS=str(1), PYTHONPATH=str(ROOT))
    print("$ " + " ".join(cmd), flush=True)
    r = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT)
    if r.returncode != 0:
        raise SystemExit(f"failed: {' '.join(cmd)}\n{r.stderr[-2000:]}")
    return json.loads(r.stdout)


def _brief(e: dict[str, Any]) -> dict[str, Any]:
    return {"psnr_db": e["psnr_db"], "ssim": e["ssim"], "count": e["count"], "images": e["images"],
            "rings_psnr_db": [g["psnr_db"] for g in e["rings"]], "space": e["space"],
            "items_psnr_db": [i["psnr_db"] for i in e["items"]], "items_ssim": [i["ssim"] for i in e["items"]]}


def paired(rows: dict[str, Any], key: str, when: str, a: str, b: str) -> dict[str, float]:
    """Mean per-scene PSNR difference b − a (same scenes, same sensor tiles, same noise) and its
    standard error over the scenes."""
    import statistics

    d = [y - x for x, y in zip(rows[a][key][when]["items_psnr_db"], rows[b][key][when]["items_psnr_db"], strict=True)]
    se = statistics.stdev(d) / len(d) ** 0.5 if len(d) > 1 else float("nan")
    return {"mean_db": statistics.fmean(d), "stderr_db": se, "scenes": len(d), "wins": sum(x > 0 for x in d)}


def requirements(lens: Path) -> dict[str, Any]:
    """The S6.1 requirements measured on every ray of a dense pupil grid plus the rim (as
    tests/test_lenses.py does for the shipped C-mount lenses): glass 1–5 mm, air ≥ 0.25 mm, image
    clearance ≥ 20 mm, angles ≤ 60°, |distortion| ≤ 2 %, EFL 28 mm, f/2."""
    import math

    import torch

    from lensopt.analysis.report import trace_report
    from lensopt.optics.bundle import trace_bundle
    from lensopt.optics.sampling import PupilSampling
    from lensopt.spec import build, load_spec

    model = build(load_spec(lens))
    rep = trace_report(model, PupilSampling.parse("rings:24"))
    grid = PupilSampling.parse("grid:41").points(dtype=torch.float64)
    phi = torch.linspace(0, 2 * math.pi, 65, dtype=torch.float64)[:-1]
    b = trace_bundle(model.lens, model.system, torch.cat([grid, torch.stack([phi.cos(), phi.sin()], -1)]),
                     record=True)
    z = [h.pos[..., 2] for h in b.result.hits] + [b.result.pos[..., 2]]
    glass, air, image = [], [], None
    for i, surf in enumerate(model.spec.surfaces):
        tz = z[i + 1] - z[i]
        if i == len(model.spec.surfaces) - 1:
            image = float(tz.min())
        elif surf.material == "air":
            air.append(float(tz.min()))
        else:
            glass += [float(tz.min()), float(tz.max())]
    cos2 = torch.stack([torch.stack([h.cos2_in, h.cos2_out]) for h in b.result.hits])
    out = {"all_rays_valid": bool(b.result.valid.all()), "glass_min_mm": min(glass), "glass_max_mm": max(glass),
           "air_min_mm": min(air), "image_clearance_mm": image,
           "max_angle_deg": math.degrees(math.acos(math.sqrt(float(cos2.min())))),
           "max_abs_distortion_percent": max(abs(f["distortion_percent"]) for f in rep["fields"]),
           "efl_mm": rep["first_order"]["efl"], "fnumber": rep["first_order"]["fnumber"]}
    out["met"] = (out["all_rays_valid"] and out["glass_min_mm"] >= 1.0 and out["glass_max_mm"] <= 5.0
                  and out["air_min_mm"] >= 0.25 and image >= 20.0 and out["max_angle_deg"] <= 60.0
                  and out["max_abs_distortion_percent"] <= 2.0 and abs(out["efl_mm"] / 28.0 - 1) <= 1e-3)
    return out


def evaluate(work: Path, files: dict[str, Path], a: argparse.Namespace) -> dict[str, Any]:
    rows: dict[str, Any] = {}
    todo = [(n, f, ck) for n, f, ck in (("spot", files["spot"], "ck_spot"), ("raw", files["raw"], "ck_raw"),
                                         ("restored", work / "restored.json", "ck_restored"))
            if (work / ck).exists() and (n != "restored" or a.joint_steps in (None, a.steps))]
    if (work / "ck_restored_irm").exists():
        todo.append(("restored_lens_irm", work / "restored.json", "ck_restored_irm"))
    if a.polish and (work / "ck_restored_polished").exists():
        todo.append(("restored_polished", work / "restored_polished.json", "ck_restored_polished"))
    for seed in a.joint_seeds:
        if (work / f"ck_restored_seed{seed}").exists():
            todo.append((f"restored_seed{seed}", work / f"restored_seed{seed}.json", f"ck_restored_seed{seed}"))
    for seed in a.extra_seeds:
        for name in ("spot", "raw"):
            if (work / f"ck_{name}_seed{seed}").exists():
                todo.append((f"{name}_seed{seed}", files[name], f"ck_{name}_seed{seed}"))
    for seed in a.polish_seeds:
        if (work / f"ck_restored_polished_seed{seed}").exists():
            todo.append((f"restored_polished_seed{seed}", work / "restored_polished.json",
                         f"ck_restored_polished_seed{seed}"))
    keys = {"dead_leaves": ["--count", str(a.eval_count), "--seed", str(EVAL_SEED)],
            "photos": ["--images", "photos", "--patch", str(a.eval_patch), "--count", "1000", "--seed", "0"]}
    jobs: dict[tuple[str, str], list[str]] = {}
    for name, lens, ck in todo:
        if not _finished(work / ck, a.steps):
            print(f"skipped {name}: {ck} has not reached {a.steps} steps", flush=True)
            continue
        if name in a.reused_rows:
            rows[name] = a.reused_rows[name]
            continue
        rows[name] = {"lens": str(lens.relative_to(ROOT) if lens.is_relative_to(ROOT) else lens)}
        jobs[(name, "trace")] = _python() + ["trace", str(lens), "--json"]
        for key, extra in keys.items():
            jobs[(name, key)] = _python() + ["evaluate", str(lens), "--irm", str(work / ck), "--noise", "0.005",
                                             "--json"] + extra
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(a.parallel) as pool:  # every evaluation of every row, a.parallel side by side
        done = dict(zip(jobs, pool.map(_json_out, jobs.values()), strict=True))
    for (name, key), e in done.items():
        if key == "trace":
            rows[name]["esr_um"] = e["effective_spot_radius_um"]
            rows[name]["requirements"] = requirements(ROOT / rows[name]["lens"])
        else:
            rows[name][key] = {"before": _brief(e), "after": _brief(e["after_restoration"]),
                               "gain_db": e["after_restoration"]["psnr_db"] - e["psnr_db"]}
    return rows


def _items_diff(after: list[float], before: list[float]) -> dict[str, float]:
    import statistics

    d = [y - x for x, y in zip(before, after, strict=True)]
    se = statistics.stdev(d) / len(d) ** 0.5 if len(d) > 1 else float("nan")
    return {"mean_db": statistics.fmean(d), "stderr_db": se, "scenes": len(d), "wins": sum(x > 0 for x in d)}


SEED_PAPER = {"spot": {"esr_um": 12.9, "psnr_after_db": 34.3}, "raw": {"esr_um": 15.5, "psnr_after_db": 36.5},
              "restored": {"esr_um": 18.5, "psnr_after_db": 37.3}}  # seed Table S15 (DIV2K, full budget)


def multi_seed(rows: dict[str, Any], a: argparse.Namespace) -> dict[str, Any]:
    """Table S15 over training seeds: per row (spot, raw, restored = the polished lens), the rows of its
    seeds (``spot_seed0`` …, ``restored_polished`` = seed 0, ``restored_polished_seed1`` …). For each scene
    set: PSNR before (the lens's, equal for every seed), after (mean over seeds), the paired gain after −
    before with two standard errors (over the seeds' mean gains; over the scenes of the seed-averaged
    per-scene gain), the worst seed's mean gain, and the paired differences of the after-PSNR between rows."""
    import statistics

    groups = {"spot": [f"spot_seed{s}" for s in a.extra_seeds], "raw": [f"raw_seed{s}" for s in a.extra_seeds],
              "restored": ["restored_polished"] + [f"restored_polished_seed{s}" for s in a.polish_seeds]}
    groups = {g: [n for n in names if n in rows] for g, names in groups.items()}

    def se(x: list[float]) -> float:
        return statistics.stdev(x) / len(x) ** 0.5 if len(x) > 1 else float("nan")

    def per_scene_after(names: list[str], key: str) -> list[float]:
        items = [rows[n][key]["after"]["items_psnr_db"] for n in names]
        return [statistics.fmean(col) for col in zip(*items, strict=True)]

    out: dict[str, Any] = {"groups": groups, "seed_paper": SEED_PAPER, "rows": {}, "between": {}}
    for g, names in groups.items():
        if not names:
            continue
        r: dict[str, Any] = {"seeds": len(names), "esr_um": rows[names[0]]["esr_um"],
                             "requirements_met": rows[names[0]]["requirements"]["met"]}
        for key in ("photos", "dead_leaves"):
            before = rows[names[0]][key]["before"]["items_psnr_db"]
            gains = [statistics.fmean(y - x for x, y in zip(before, rows[n][key]["after"]["items_psnr_db"],
                                                             strict=True)) for n in names]
            scene = [y - x for x, y in zip(before, per_scene_after(names, key), strict=True)]
            r[key] = {"before_db": rows[names[0]][key]["before"]["psnr_db"],
                      "after_db": statistics.fmean(rows[n][key]["after"]["psnr_db"] for n in names),
                      "after_per_seed_db": [rows[n][key]["after"]["psnr_db"] for n in names],
                      "gain_db": statistics.fmean(gains), "gain_se_seeds_db": se(gains),
                      "gain_se_scenes_db": se(scene), "gain_per_seed_db": gains, "worst_seed_gain_db": min(gains),
                      "scenes": len(before), "scenes_improved_seed_mean": sum(d > 0 for d in scene)}
        out["rows"][g] = r
    for x, y in (("spot", "raw"), ("raw", "restored"), ("spot", "restored")):
        if not (groups.get(x) and groups.get(y)):
            continue
        for key in ("photos", "dead_leaves"):
            d = [b - c for c, b in zip(per_scene_after(groups[x], key), per_scene_after(groups[y], key), strict=True)]
            seeds = [statistics.fmean(rows[m][key]["after"]["items_psnr_db"]) - statistics.fmean(
                rows[n][key]["after"]["items_psnr_db"]) for n, m in zip(groups[x], groups[y], strict=False)]
            out["between"][f"{key}/after/{y}-{x}"] = {"mean_db": statistics.fmean(d), "se_scenes_db": se(d),
                                                      "se_seeds_db": se(seeds), "wins": sum(v > 0 for v in d),
                                                      "scenes": len(d)}
    out["photos_never_worse"] = all(r["photos"]["worst_seed_gain_db"] >= 0 for r in out["rows"].values())
    return out


SHIP = {"cmount_4p": "ck_spot_seed0", "cmount_4p_raw": "ck_raw_seed0", "cmount_4p_restored": "ck_restored_polished"}


def ship(work: Path) -> dict[str, Any]:
    """``--ship``: the polished restored lens as ``lenses/cmount_4p_restored.json`` (re-saved by lensopt), and
    each row's seed-0 network as ``lenses/networks/LENS/`` (``restore.checkpoint.ship_network``: float16
    weights, no Adam moments); their sizes in bytes."""
    from lensopt.files import write_text_atomic
    from lensopt.restore.checkpoint import ship_network
    from lensopt.spec import dump_json, load_spec

    lens_text = dump_json(load_spec(work / "restored_polished.json"))
    write_text_atomic(ROOT / "lenses" / "cmount_4p_restored.json", lens_text)
    sizes = {}
    for lens, ck in SHIP.items():
        dst = ship_network(work / ck, ROOT / "lenses" / "networks" / lens, lens=f"lenses/{lens}.json")
        sizes[lens] = sum(f.stat().st_size for f in dst.iterdir())
    return sizes


def transfer(work: Path, files: dict[str, Path], a: argparse.Namespace) -> None:
    """Issue 27's transfer study (see the module doc): one network per training source, scored on held-out
    photographs, dead leaves and textured dead leaves; CPU seconds of every child process."""
    from lensopt.files import write_text_atomic

    cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    times: dict[str, float] = {}
    todo = [s for s in a.sources if not _finished(work / f"ck_src_{s.replace('+', '_')}", a.steps)]
    for k in range(0, len(todo), a.parallel):  # a.parallel runs side by side, one thread each
        procs = []
        for src in todo[k:k + a.parallel]:
            tag = "src_" + src.replace("+", "_")
            cmd = _python() + ["train-irm", str(files["spot"]), "-o", str(work / f"ck_{tag}"), "--images", src,
                               "--seed", "0"] + _irm_opts(a)
            if (work / f"ck_{tag}").exists():  # an interrupted run: continued bit-identically
                cmd.append("--resume")
            procs.append((tag, _run(cmd, work / f"{tag}.log", append=True), time.perf_counter()))
        _wait(procs, times)
    cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    evals = {"photos": ["--images", "photos", "--count", "1000", "--seed", "0"],
             "dead_leaves": ["--count", str(a.eval_count), "--seed", str(EVAL_SEED)],
             "textured": ["--images", "textured", "--count", str(a.eval_count), "--seed", str(EVAL_SEED)]}
    from concurrent.futures import ThreadPoolExecutor

    jobs = {(src, key): _python() + ["evaluate", str(files["spot"]), "--irm",
                                     str(work / f"ck_src_{src.replace('+', '_')}"), "--noise", "0.005", "--patch",
                                     str(a.eval_patch), "--json"] + extra
            for src in a.sources for key, extra in evals.items()}
    t0 = time.perf_counter()
    with ThreadPoolExecutor(a.parallel) as pool:  # a.parallel evaluate processes side by side
        done = dict(zip(jobs, pool.map(_json_out, jobs.values()), strict=True))
    eval_wall = time.perf_counter() - t0
    rows: dict[str, Any] = {}
    for src in a.sources:
        tag = "src_" + src.replace("+", "_")
        row: dict[str, Any] = {"checkpoint": f"ck_{tag}"}
        for key in evals:
            e = done[(src, key)]
            before, after = _brief(e), _brief(e["after_restoration"])
            row[key] = {"before": before, "after": after,
                        "after_minus_before": _items_diff(after["items_psnr_db"], before["items_psnr_db"])}
        from lensopt.checkpoint import load_checkpoint

        hist = load_checkpoint(work / f"ck_{tag}").meta.get("history") or []
        row["train_sum_step_wall_s"] = sum(h.get("wall_s", 0.0) for h in hist)
        row["train_last_validation"] = next((h for h in reversed(hist) if "psnr_restored" in h), None)
        rows[src] = row
    cpu2 = resource.getrusage(resource.RUSAGE_CHILDREN)
    first = a.sources[0]
    vs = {f"{key}/after/{src}-{first}": _items_diff(rows[src][key]["after"]["items_psnr_db"],
                                                   rows[first][key]["after"]["items_psnr_db"])
          for src in a.sources[1:] for key in evals}
    section = {
        "date": time.strftime("%Y-%m-%d"), "lens": "lenses/cmount_4p.json with the restored spec's rgb_weights",
        "budget": {"steps": a.steps, "batch": a.batch, "patch": a.patch, "psf_size": a.psf_size, "fields": 9,
                   "sampling": "rings:8", "grid": [3, 3], "seed": 0, "threads_per_process": 1},
        "evaluation": {"noise": 0.005, "patch": a.eval_patch, "dead_leaves_seed": EVAL_SEED,
                       "count_procedural": a.eval_count, "photos": "every tile of the held-out photographs"},
        "train_wall_s": times, "evaluate_wall_s": eval_wall, "parallel": a.parallel,
        "train_cpu_s": (cpu1.ru_utime + cpu1.ru_stime) - (cpu0.ru_utime + cpu0.ru_stime),
        "evaluate_cpu_s": (cpu2.ru_utime + cpu2.ru_stime) - (cpu1.ru_utime + cpu1.ru_stime),
        "load_avg_at_end": os.getloadavg(), "rows": rows, "paired_against_first": vs}
    from lensopt.imaging.sources import PHOTOS_HELD_OUT, PHOTOS_TRAIN

    section["photos_train"], section["photos_held_out"] = list(PHOTOS_TRAIN), list(PHOTOS_HELD_OUT)
    result = json.loads(a.out.read_text()) if a.out.exists() else {}
    result["scenes_transfer"] = section
    write_text_atomic(a.out, json.dumps(result, indent=1) + "\n")
    print("| training scenes | photos before → after (Δ ± se) | dead leaves before → after | textured before → after |")
    print("|---|---|---|---|")
    for src, r in rows.items():
        cells = []
        for key in evals:
            d = r[key]["after_minus_before"]
            cells.append(f"{r[key]['before']['psnr_db']:.2f} → {r[key]['after']['psnr_db']:.2f} "
                         f"({d['mean_db']:+.2f} ± {d['stderr_db']:.2f})")
        print(f"| {src} | " + " | ".join(cells) + " |")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--steps", type=int, default=500, help="network Adam steps (and joint steps) per row")
    p.add_argument("--batch", type=int, default=4)
    p.add_argument("--images", default="procedural", help="training scenes of every network and of the joint "
                   "run (train-irm --images, [optimize.image] images): procedural | textured | photos | a+b")
    p.add_argument("--joint-steps", type=int, default=None, help="steps of the joint run (default: --steps)")
    p.add_argument("--patch", type=int, default=64)
    p.add_argument("--psf-size", type=int, default=49, help="as specs/cmount_4p_restored.toml")
    p.add_argument("--val-patches", type=int, default=8)
    p.add_argument("--validate-every", type=int, default=50)
    p.add_argument("--checkpoint-every", type=int, default=25)
    p.add_argument("--eval-count", type=int, default=50, help="held-out dead-leaves scenes")
    p.add_argument("--parallel", type=int, default=2, choices=(1, 2, 3, 4), help="processes side by side "
                   "(Table S15: 1 or 2; --sources: up to 4)")
    p.add_argument("--work", type=Path, default=ROOT / "out" / "table_s15")
    p.add_argument("--skip-main", action="store_true",
                   help="skip the three main training runs (use those in --work)")
    p.add_argument("--no-evaluate", action="store_true", help="train only")
    p.add_argument("--evaluate-only", action="store_true", help="train nothing: score the checkpoints in --work "
                   "that have reached --steps (the rows of --extra-seeds, --polish-seeds ... that exist)")
    p.add_argument("--extra-seeds", type=int, nargs="*", default=[],
                   help="also train the spot and raw networks with these seeds (more rows)")
    p.add_argument("--joint-seeds", type=int, nargs="*", default=[],
                   help="also run the joint optimization with these seeds (batches, held-out set, network init)")
    p.add_argument("--control", action="store_true",
                   help="also train a fresh train-irm network for the restored lens (a fourth row)")
    p.add_argument("--polish", action="store_true",
                   help="also polish the restored lens to its distortion limit, with a fresh network (a fifth row)")
    p.add_argument("--polish-steps", type=int, default=8, help="LM steps of the polish (--polish)")
    p.add_argument("--polish-seeds", type=int, nargs="*", default=[],
                   help="also train the polished lens's network with these seeds (--polish)")
    p.add_argument("--polish-distortion", type=float, nargs=2, default=[10000.0, 1.9],
                   metavar=("WEIGHT", "MAX_PERCENT"), help="the distortion constraint of the polish")
    p.add_argument("--ship", action="store_true", help="write lenses/cmount_4p_restored.json (the polished lens) "
                   "and lenses/networks/LENS/ (each row's seed-0 network, float16 weights only)")
    p.add_argument("--reuse-rows", action="store_true",
                   help="keep the rows already in --out (same --work) and evaluate only the missing ones")
    p.add_argument("--reuse-from", type=Path, default=None, help="read the rows of --reuse-rows from this file "
                   "instead of --out")
    p.add_argument("--sources", nargs="*", default=[],
                   help="the transfer study instead: train-irm --images SOURCE for the spot lens, per source")
    p.add_argument("--eval-patch", type=int, default=128, help="patch of the held-out photograph tiles (and of "
                   "every --sources evaluation)")
    p.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "e2e" / "results_table_s15.json")
    a = p.parse_args()
    reuse = a.reuse_from or a.out
    a.reused_rows = json.loads(reuse.read_text()).get("rows", {}) if a.reuse_rows and reuse.exists() else {}
    a.work.mkdir(parents=True, exist_ok=True)
    files = write_inputs(a.work, a)
    if a.sources:
        return transfer(a.work, files, a)
    if a.evaluate_only:  # nothing is trained (nor deleted): the finished checkpoints in --work are scored
        a.skip_main, a.control = True, False
    t0 = time.perf_counter()
    times = {} if a.skip_main else train(a.work, files, a)
    t_train = time.perf_counter() - t0
    if a.control:
        times["restored_irm"] = train_control(a.work, a)
    a.pending = []
    if a.polish and not a.evaluate_only:
        times.update(polish(a.work, a))
    if not a.evaluate_only:
        times.update(train_extra_seeds(a.work, files, a))
        times.update(run_pending(a.work, a))
        times.update(train_joint_seeds(a.work, files, a))
    if a.ship:
        print("shipped (bytes):", ship(a.work))
    if a.no_evaluate:
        return
    rows = evaluate(a.work, files, a)
    cpu = resource.getrusage(resource.RUSAGE_CHILDREN)
    result = {
        "budget": {"steps": a.steps, "batch": a.batch, "patch": a.patch, "psf_size": a.psf_size, "fields": 9,
                   "sampling": "rings:8", "grid": [3, 3], "noise": 0.005, "val_patches": a.val_patches,
                   "parallel": a.parallel, "threads_per_process": 1},
        "train_wall_s": times, "train_total_wall_s": t_train if not a.skip_main else None,
        "children_cpu_s": cpu.ru_utime + cpu.ru_stime, "load_avg_at_end": os.getloadavg(),
        "evaluation": {"noise": 0.005, "dead_leaves_seed": EVAL_SEED, "dead_leaves_count": a.eval_count,
                       "photos": f"every {a.eval_patch}² tile of the held-out photographs (--images photos)"},
        "rows": rows,
        "paired_differences": {f"{key}/{when}/{y}-{x}": paired(rows, key, when, x, y)
                               for key in ("dead_leaves", "photos") for when in ("before", "after")
                               for x, y in (("spot", "raw"), ("raw", "restored"), ("spot", "restored"),
                                            ("spot", "restored_lens_irm"), ("restored_lens_irm", "restored"),
                                            ("spot", "restored_polished"), ("raw", "restored_polished"))
                                 + tuple((n, f"{n}_seed{s}") for s in a.extra_seeds for n in ("spot", "raw"))
                                 + tuple(("restored", f"restored_seed{s}") for s in a.joint_seeds)
                                 + tuple((f"raw_seed{s}", f"restored_seed{s}") for s in a.joint_seeds)
                               if x in rows and y in rows},
    }
    from lensopt.checkpoint import load_checkpoint
    from lensopt.files import write_text_atomic

    for name in (["restored", "spot", "raw", "restored_irm", "restored_polished"]
                 + [f"{n}_seed{s}" for s in a.extra_seeds for n in ("spot", "raw")]
                 + [f"restored_seed{s}" for s in a.joint_seeds]):
        if not (a.work / f"ck_{name}").exists():
            continue
        ck = load_checkpoint(a.work / f"ck_{name}")
        hist = ck.meta.get("history") or []
        result.setdefault("histories", {})[name] = {
            "step": ck.step, "sum_step_wall_s": sum(h.get("wall_s", 0.0) for h in hist),
            "validation": [{k: h[k] for k in ("step", "psnr_raw", "psnr_restored") if k in h}
                           for h in hist if "psnr_restored" in h],
            "history_every_10th_step": [h for h in hist if h["step"] % 10 == 0]}
    result["multi_seed"] = multi_seed(rows, a)
    if a.out.exists() and "scenes_transfer" in (old := json.loads(a.out.read_text())):
        result["scenes_transfer"] = old["scenes_transfer"]
    write_text_atomic(a.out, json.dumps(result, indent=1) + "\n")
    print("| lens | ESR µm | dead leaves before → after (gain) | photos before → after (gain) |")
    print("|---|---:|---|---|")
    for name, r in rows.items():
        d, f = r["dead_leaves"], r["photos"]
        print(f"| {name} | {r['esr_um']:.2f} | {d['before']['psnr_db']:.2f} → {d['after']['psnr_db']:.2f} "
              f"({d['gain_db']:+.2f}) | {f['before']['psnr_db']:.2f} → {f['after']['psnr_db']:.2f} "
              f"({f['gain_db']:+.2f}) |")
    print(json.dumps(result["multi_seed"]["rows"], indent=1))
    print(json.dumps(result["multi_seed"]["between"], indent=1))


if __name__ == "__main__":
    main()
