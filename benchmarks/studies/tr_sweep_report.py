"""Table S8 on the best lens of each point of a TR sweep of the 5P telephoto (issue 15, session 23; issue 25).

    lensopt sweep specs/telephoto_5p_tr080.toml --vary 'optimize.solves[0].value=19.425,20.72,22.015,23.31' \
        --starts 3 --steps 400 --scheduler local --workers 2 -o out/tr_sweep
    for i in 0 1 2 3; do
        lensopt optimize out/tr_sweep/best_$i.json -o out/tr_cont_$i.json --steps 600 --seed 0 --full-weight
    done
    PYTHONPATH=. python benchmarks/studies/tr_sweep_report.py out/tr_sweep benchmarks/studies/results_tr_sweep.json \
        --continued 'out/tr_cont_{i}.json'

The seed's procedure (S4.2.1) at 5000 steps, reported under a key of the same file and compared with the curve above
(its points after the full-weight continuation); the TR 0.80 point is made by the same command (the sweep's start 0 of
that point; it was the shipped lens until the continuation below replaced it):

    lensopt sweep specs/telephoto_5p_tr080.toml --vary 'optimize.solves[0].value=19.425,22.015,23.31' \
        --starts 1 --steps 5000 --scheduler local --workers 2 -o out/tr_sweep5k
    lensopt optimize specs/telephoto_5p_tr080.toml --steps 5000 --seed 0 -o out/tele_5000.json
    PYTHONPATH=. python benchmarks/studies/tr_sweep_report.py out/tr_sweep5k benchmarks/studies/results_tr_sweep.json \
        --key procedure_5000 --point 20.72=out/tele_5000.json

A continuation (``lensopt sweep … --continuation``) is reported the same way: its points are the walk's stages, and
``--point`` adds the lens it started from (benchmarks/README.md, studies: key ``continuation_085_f11``).

For each point: TR = TTL / 25.9 mm, the best start's ESR (rings:24) and the seed's measure (11 fields), every
start's ESR and stop reason, and Table S8 checked on the dense sample and by the seed's definition
(``studies_report.lens_checks``, the TTL of that point). Also says whether the best ESR falls monotonically with TR,
the form of seed Figure S13, and with --key whether every point is below the file's earlier curve.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from benchmarks.studies.studies_report import lens_checks
from lensopt.spec import load_spec

EFL_MM = 25.9  # the spec's TTL = TR × 25.9 mm (specs/telephoto_5p_tr080.toml header)


def _falls(values: list[float]) -> bool:
    return all(b < a for a, b in zip(values, values[1:], strict=False))


def _checked(path: Path) -> dict:
    checks = lens_checks("telephoto_5p_tr080", load_spec(path))
    return {"esr_um_rings24_dense_check": checks["esr_um_rings24"], "seed_esr_um": checks["seed_esr_um"],
            "requirements_failed": checks["requirements_failed"], "requirements": checks["requirements"],
            "requirements_failed_seed_definition": checks["requirements_seed_definition"]["failed"],
            "glasses": checks["glasses"]}


def _rows(folder: str, points: dict[float, str]) -> list[dict]:
    sweep = json.loads((Path(folder) / "sweep.json").read_text())
    rows = []
    for i, row in enumerate(sweep["points"]):
        ttl = float(row["optimize.solves[0].value"])
        starts = sorted((r for r in sweep["starts"] if r["point"] == i), key=lambda r: r["start"])
        rows.append({"tr": ttl / EFL_MM, "ttl_mm": ttl, "point": i, "lens": str(Path(folder) / f"best_{i}.json"),
                     "best_start": row["best_start"], "best_esr_um": row["best_esr_um"],
                     "starts": [{"start": r["start"], "esr_um": r.get("esr_um"), "seed_esr_um": r.get("seed_esr_um"),
                                 "steps": r.get("steps"), "stop_reason": r.get("stop_reason"),
                                 "bound": r.get("bound"), "wall_s": r.get("wall_s")} for r in starts],
                     **_checked(Path(folder) / f"best_{i}.json")})
    for ttl, lens in points.items():  # points run outside the sweep by the same procedure
        checked = _checked(Path(lens))
        rows.append({"tr": ttl / EFL_MM, "ttl_mm": ttl, "lens": lens, "best_start": 0,
                     "best_esr_um": checked["esr_um_rings24_dense_check"], "starts": [], **checked})
    return sorted(rows, key=lambda r: r["ttl_mm"])


def _show(row: dict) -> None:
    print(f"TR {row['tr']:.3f} (TTL {row['ttl_mm']} mm, {row['lens']}): "
          f"ESR {row['esr_um_rings24_dense_check']:.3f} µm, "
          f"seed's measure {row['seed_esr_um']:.3f} µm, Table S8 failed: {row['requirements_failed']} "
          f"(seed's definition: {row['requirements_failed_seed_definition']})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder")
    ap.add_argument("out")
    ap.add_argument("--continued", help="the best lens of point i continued at full weight, e.g. out/tr_cont_{i}.json")
    ap.add_argument("--key", help="write under this key of OUT (kept with the file's earlier curve) and compare")
    ap.add_argument("--point", action="append", default=[], help="TTL=LENS: a point run outside the sweep")
    args = ap.parse_args()
    points = {float(p.split("=", 1)[0]): p.split("=", 1)[1] for p in args.point}
    rows = _rows(args.folder, points)
    for row in rows:
        _show(row)
        if args.continued and "point" in row:  # sweep point index (rows sorted by TTL; --point rows: none)
            lens = args.continued.format(i=row["point"])
            row["continued"] = {"lens": lens, **_checked(Path(lens))}
            print(f"    continued ({lens}): ESR {row['continued']['esr_um_rings24_dense_check']:.3f} µm")
    esr = [r["esr_um_rings24_dense_check"] for r in rows]
    result = {"folder": args.folder, "rows": rows, "monotone_decreasing": _falls(esr),
              "monotone_decreasing_seed_measure": _falls([r["seed_esr_um"] for r in rows])}
    print(f"ESR falls monotonically with TR: {result['monotone_decreasing']} "
          f"(seed's measure: {result['monotone_decreasing_seed_measure']})")
    out = Path(args.out)
    if not args.key:
        out.write_text(json.dumps(result, indent=1, ensure_ascii=False) + "\n")
        return
    data = json.loads(out.read_text())
    def curve(r: dict) -> float:  # a point of the earlier curve: its continued lens when there is one
        c = r.get("continued") or {}
        return c.get("esr_um", c.get("esr_um_rings24_dense_check", r["best_esr_um"]))

    before = {round(r["ttl_mm"], 3): curve(r) for r in data["rows"]}
    for row in rows:
        row["before_esr_um"] = before.get(round(row["ttl_mm"], 3))
    result["below_earlier_curve"] = all(
        r["before_esr_um"] is None or r["esr_um_rings24_dense_check"] < r["before_esr_um"] for r in rows)
    print("below the earlier curve at every point:", result["below_earlier_curve"],
          [(round(r["tr"], 2), r["before_esr_um"] and round(r["before_esr_um"], 3),
            round(r["esr_um_rings24_dense_check"], 3)) for r in rows])
    data[args.key] = result
    out.write_text(json.dumps(data, indent=1, ensure_ascii=False) + "\n")


if __name__ == "__main__":
    main()
