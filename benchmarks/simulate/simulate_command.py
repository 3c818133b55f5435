"""``lensopt simulate`` as a user runs it, against DeepLens's whole process for the same job: a 4000 × 3000
RGB PNG in, a PNG out, each run its own process, timed whole (Python start and imports included: wall
from spawn to exit) with its peak RSS (VmHWM of that process, read at its exit), interleaved, medians.

    bash benchmarks/simulate/setup_deeplens_venv.sh /work/dl-venv        # once; the peer venv is not a dependency
    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/simulate/simulate_command.py --repeats 3 \\
        --peer-python /work/dl-venv/bin/python [--before /path/to/older/checkout] [--score] \\
        --json benchmarks/simulate/results_simulate_command.json

Scene: coffee.png mirrored to 4000 × 3000 (as benchmarks/bench_simulate.py), an 8-bit sRGB PNG.
lensopt: ``lensopt simulate specs/cooke_triplet.toml scene.png -o out.png --region full --grid 5x4
--effects -diffraction`` (full 4000 × 3000 sensor of 7.2 µm pixels, geometric PSFs, 2 048 rays per
PSF and wavelength, 23 × 23 kernels, R/G/B weights of the spec's 480/550/650 nm).
DeepLens 2.5.6: ``benchmarks/simulate/peer_deeplens.py ... whole`` — its own rendering example's steps (PIL read,
/255, ``psf_map_rgb`` 5 × 4 at 650/550/480 nm, 2 048 spp, 23 × 23, ``conv_psf_map``, torchvision's
``save_image`` steps, PIL PNG write), the same lens read from the .zmx that benchmarks/simulate/cooke_zmx.py
writes from the spec. Both with one thread by default (OMP_NUM_THREADS = MKL_NUM_THREADS = 1; DeepLens
also ``torch.set_num_threads(1)``; ``--threads N`` for N); each child reports the threads torch used.
``--before``: another checkout's ``lensopt simulate`` in the same run (e.g. main before a change); its
output PNG is compared code by code.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]

#: Runs ``lensopt simulate`` in this process and writes {VmHWM MB, torch threads} to $BENCH_HWM_FILE at exit.
_LENSOPT = """\
import atexit, json, os, sys
sys.path.insert(0, {bench!r})
from procmem import peak_rss_mb

def _report():
    t = sys.modules.get("torch")
    with open(os.environ["BENCH_HWM_FILE"], "w") as f:
        json.dump({{"peak_rss_mb": peak_rss_mb(), "torch_threads": t.get_num_threads() if t else None}}, f)

atexit.register(_report)
from lensopt.cli.app import app
sys.argv[0] = "lensopt"
app()
"""


THREADS = 1


def _env(tree: Path | None, hwm: Path) -> dict[str, str]:
    n = str(THREADS)
    env = {**os.environ, "OMP_NUM_THREADS": n, "MKL_NUM_THREADS": n, "BENCH_HWM_FILE": str(hwm)}
    if tree is not None:
        env["PYTHONPATH"] = str(tree)
    return env


def timed(cmd: list[str], env: dict[str, str], cwd: Path) -> tuple[float, str]:
    """(wall seconds from spawn to exit, stdout); raises on failure."""
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{cmd[:3]} failed: {proc.stderr[-2000:]}")
    return wall, proc.stdout


def stage_table(stdout: str) -> dict[str, float]:
    """The ``stages`` table that ``lensopt simulate`` prints (rows ``│ name │ seconds │``)."""
    rows = re.findall(r"^[│┃|]\s*([A-Za-z][^│┃|]*?)\s*[│┃|]\s*([0-9]+\.[0-9]+)\s*[│┃|]\s*$", stdout, flags=re.M)
    return {name: float(sec) for name, sec in rows}


EFFECTS = "-diffraction"


def run_lensopt(tree: Path, scene: Path, out: Path, extra: list[str], tmp: Path) -> dict:
    hwm = tmp / "hwm.json"
    hwm.unlink(missing_ok=True)
    args = [str(ROOT / "specs" / "cooke_triplet.toml"), str(scene), "-o", str(out), "--region", "full",
            "--grid", "5x4", f"--effects={EFFECTS}", *extra]
    # cwd = the tree: ``python -c`` puts the working directory first on sys.path, before PYTHONPATH.
    wall, stdout = timed([sys.executable, "-c", _LENSOPT.format(bench=str(HERE.parent)), "simulate", *args],
                         _env(tree, hwm), tree)
    return {"wall_s": wall, **json.loads(hwm.read_text()), "stages": stage_table(stdout)}


def run_peer(python: str, zmx: Path, scene: Path, out: Path, tmp: Path, writer: str = "pil") -> dict:
    js = tmp / "peer.json"
    js.unlink(missing_ok=True)
    cmd = [python, str(HERE / "peer_deeplens.py"), str(zmx), str(scene), "whole", str(out), "--json", str(js),
           "--grid", "5x4", "--ks", "23", "--spp", "2048", "--threads", str(THREADS), "--writer", writer]
    wall, _ = timed(cmd, _env(None, tmp / "unused"), HERE)
    r = json.loads(js.read_text())
    return {"wall_s": wall, "peak_rss_mb": r["peak_rss_mb"], "torch_threads": r["threads"], "stages": r["timings"]}


def make_scene(path: Path) -> Path:
    """coffee.png mirrored to 4000 × 3000, written as an 8-bit sRGB PNG."""
    from lensopt.imaging.io import read_image, write_image

    img, info = read_image(ROOT / "lensopt" / "imaging" / "data" / "coffee.png")
    big = np.pad(img, ((0, 3000 - img.shape[0]), (0, 4000 - img.shape[1]), (0, 0)), mode="symmetric")
    write_image(path, big, info)
    return path


def read_codes(path: Path) -> np.ndarray:
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    spec = inp.spec()
    data = np.asarray(inp.read_image(0, 0, 0, spec.nchannels, "uint8")).reshape(spec.height, spec.width, -1)
    inp.close()
    return data


def main() -> None:
    global THREADS, EFFECTS
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--peer-python", default=None, help="python of the DeepLens venv (setup_deeplens_venv.sh)")
    ap.add_argument("--peer-cv2", action="store_true", help="also DeepLens with cv2.imwrite as the PNG writer")
    ap.add_argument("--before", type=Path, default=None, help="another checkout to run in the same session")
    ap.add_argument("--score", action="store_true", help="also time the `--score` variant (of --before too)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--effects", default=EFFECTS, help="lensopt's --effects (the DeepLens peer has none)")
    ap.add_argument("--threads", type=int, default=1, help="OMP/MKL threads of every run (DeepLens: set_num_threads)")
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args()
    THREADS, EFFECTS = a.threads, a.effects
    sys.path.insert(0, str(HERE))
    from cooke_zmx import cooke_zmx

    tmp = Path(tempfile.mkdtemp(prefix="sim_cmd_"))
    scene = make_scene(tmp / "scene.png")
    zmx = tmp / "cooke.zmx"
    zmx.write_text(cooke_zmx())

    variants: dict[str, tuple] = {}
    if a.peer_python:
        variants["DeepLens 2.5.6 (PIL in, psf_map_rgb + conv_psf_map, save_image out)"] = ("peer", "pil")
        if a.peer_cv2:
            variants["DeepLens 2.5.6, PNG written by cv2.imwrite (level 1)"] = ("peer", "cv2")
    variants["lensopt simulate (this tree)"] = ("lensopt", ROOT, [])
    if a.before is not None:
        variants[f"lensopt simulate ({a.before})"] = ("lensopt", a.before.resolve(), [])
    if a.score:
        variants["lensopt simulate --score (this tree)"] = ("lensopt", ROOT, ["--score"])
        if a.before is not None:
            variants[f"lensopt simulate --score ({a.before})"] = ("lensopt", a.before.resolve(), ["--score"])
    runs: dict[str, list[dict]] = {k: [] for k in variants}
    outs = {k: tmp / f"out{i}.png" for i, k in enumerate(variants)}
    load0 = os.getloadavg()
    for rep in range(a.repeats):
        for name, v in variants.items():  # interleaved
            if v[0] == "peer":
                runs[name].append(run_peer(a.peer_python, zmx, scene, outs[name], tmp, v[1]))
            else:
                runs[name].append(run_lensopt(v[1], scene, outs[name], v[2], tmp))
        print(f"round {rep + 1}/{a.repeats} done", file=sys.stderr)
    load1 = os.getloadavg()

    rows = {}
    for k, v in runs.items():
        walls = [r["wall_s"] for r in v]
        rows[k] = {"wall_s_median": statistics.median(walls), "wall_s_min": min(walls), "wall_s_max": max(walls),
                   "peak_rss_mb_median": statistics.median(r["peak_rss_mb"] for r in v),
                   "peak_rss_mb_max": max(r["peak_rss_mb"] for r in v),
                   "torch_threads": sorted({r["torch_threads"] for r in v}),
                   "output_mb": outs[k].stat().st_size / 1e6, "runs": v}
    ours = rows["lensopt simulate (this tree)"]
    compare = {}
    if a.before is not None:
        d = np.abs(read_codes(outs["lensopt simulate (this tree)"]).astype(np.int16)
                   - read_codes(outs[f"lensopt simulate ({a.before})"]))
        compare["this tree vs --before: codes that differ"] = int((d > 0).sum())
        compare["this tree vs --before: largest difference"] = int(d.max())
    print(f"load average before/after: {load0} / {load1}; repeats {a.repeats}; threads {a.threads} each\n")
    print("| process | wall s median | min–max | peak RSS MB (median) | torch threads | PNG MB |")
    print("| --- | ---: | ---: | ---: | ---: | ---: |")
    for k, r in rows.items():
        print(f"| {k} | {r['wall_s_median']:.2f} | {r['wall_s_min']:.2f}–{r['wall_s_max']:.2f} | "
              f"{r['peak_rss_mb_median']:.0f} | {r['torch_threads']} | {r['output_mb']:.1f} |")
    for k, r in rows.items():
        names = list(dict.fromkeys(n for run in r["runs"] for n in run["stages"]))
        r["stages_median_s"] = {n: statistics.median(run["stages"].get(n, 0.0) for run in r["runs"]) for n in names}
        inside = sum(v for n, v in r["stages_median_s"].items() if n != "in-process total")
        print(f"\n{k}, stage medians (s): " + ", ".join(f"{n} {v:.2f}" for n, v in r["stages_median_s"].items())
              + f"; the rest of the wall time (start-up, imports, exit): {r['wall_s_median'] - inside:.2f}")
    ratios = {}
    for k, r in rows.items():
        if k != "lensopt simulate (this tree)":
            ratios[k] = {"wall_ratio_other_over_ours": r["wall_s_median"] / ours["wall_s_median"],
                         "peak_ratio_ours_over_other": ours["peak_rss_mb_median"] / r["peak_rss_mb_median"]}
            print(f"\n{k}: wall {ratios[k]['wall_ratio_other_over_ours']:.2f}× this tree's; this tree's peak "
                  f"RSS is {ratios[k]['peak_ratio_ours_over_other']:.2f}× its")
    for k, v in compare.items():
        print(f"{k}: {v}")
    if a.json:
        from lensopt.files import write_text_atomic

        write_text_atomic(a.json, json.dumps({"rows": rows, "ratios": ratios, "compare": compare,
                                              "load_before": load0, "load_after": load1, "repeats": a.repeats,
                                              "threads": a.threads, "effects": a.effects,
                                              "cpu_count": os.cpu_count()}, indent=2) + "\n")


if __name__ == "__main__":
    main()
