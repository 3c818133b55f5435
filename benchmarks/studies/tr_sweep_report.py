"""Table S8 on the best lens of each point of a TR sweep of the 5P telephoto (issue 15, session 23).

    lensopt sweep specs/telephoto_5p_tr080.toml --vary 'optimize.solves[0].value=19.425,20.72,22.015,23.31' \
        --starts 3 --steps 400 --scheduler local --workers 2 -o out/tr_sweep
    for i in 0 1 2 3; do
        lensopt optimize out/tr_sweep/best_$i.json -o out/tr_cont_$i.json --steps 600 --seed 0 --full-weight
    done
    PYTHONPATH=. python benchmarks/studies/tr_sweep_report.py out/tr_sweep benchmarks/studies/results_tr_sweep.json \
        'out/tr_cont_{i}.json'

For each point: TR = TTL / 25.9 mm, the best start's ESR (rings:24), every start's ESR and stop reason, and
Table S8 checked on the dense sample (``studies_report.lens_checks``, the TTL of that point). Also says
whether the best ESR falls monotonically with TR, the form of seed Figure S13.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from benchmarks.studies.studies_report import lens_checks
from lensopt.spec import load_spec

EFL_MM = 25.9  # the spec's TTL = TR × 25.9 mm (specs/telephoto_5p_tr080.toml header)


def _falls(values: list[float]) -> bool:
    return all(b < a for a, b in zip(values, values[1:], strict=False))


def main(folder: str, out: str, continued: str | None = None) -> None:
    sweep = json.loads((Path(folder) / "sweep.json").read_text())
    rows = []
    for i, row in enumerate(sweep["points"]):
        ttl = float(row["optimize.solves[0].value"])
        checks = lens_checks("telephoto_5p_tr080", load_spec(Path(folder) / f"best_{i}.json"))
        starts = sorted((r for r in sweep["starts"] if r["point"] == i), key=lambda r: r["start"])
        rows.append({"tr": ttl / EFL_MM, "ttl_mm": ttl, "best_start": row["best_start"],
                     "best_esr_um": row["best_esr_um"], "esr_um_rings24_dense_check": checks["esr_um_rings24"],
                     "starts": [{"start": r["start"], "esr_um": r.get("esr_um"), "stop_reason": r.get("stop_reason"),
                                 "bound": r.get("bound"), "wall_s": r.get("wall_s")} for r in starts],
                     "requirements_failed": checks["requirements_failed"], "requirements": checks["requirements"],
                     "glasses": checks["glasses"]})
        print(f"TR {ttl / EFL_MM:.3f} (TTL {ttl} mm): best ESR {row['best_esr_um']:.3f} µm "
              f"(start {row['best_start']}), "
              f"starts {[round(s['esr_um'], 3) for s in rows[-1]['starts']]}, Table S8 failed: "
              f"{checks['requirements_failed']}")
        if continued:  # the best lens continued at full weight: e.g. out/tr_cont_{i}.json
            more = lens_checks("telephoto_5p_tr080", load_spec(continued.format(i=i)))
            rows[-1]["continued"] = {"lens": continued.format(i=i), "esr_um": more["esr_um_rings24"],
                                     "requirements_failed": more["requirements_failed"],
                                     "requirements": more["requirements"], "glasses": more["glasses"]}
            print(f"    continued ({continued.format(i=i)}): ESR {more['esr_um_rings24']:.3f} µm, Table S8 failed: "
                  f"{more['requirements_failed']}")
    esr = [r["best_esr_um"] for r in rows]
    monotone = _falls(esr)
    print(f"best ESR falls monotonically with TR: {monotone}")
    if continued:
        print(f"continued ESR falls monotonically with TR: {_falls([r['continued']['esr_um'] for r in rows])}")
    Path(out).write_text(json.dumps({"folder": folder, "settings": sweep.get("settings"), "rows": rows,
                                     "monotone_decreasing": monotone}, indent=1, ensure_ascii=False) + "\n")


if __name__ == "__main__":
    main(*sys.argv[1:4])
