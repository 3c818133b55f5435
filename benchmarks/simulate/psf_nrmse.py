"""NRMSE of geometric, naive (incoherent Airy) and heuristic (coherent Airy, S1.4.3) PSFs against the
reference diffraction PSF (exit-pupil OPD → Fourier transform), as the seed reports in S7.1.

Lenses: specs/achromat_f10.toml (near diffraction-limited: RMS spot ~2 µm vs Airy radius 6.7 µm) and
specs/cooke_triplet.toml (aberrated: RMS spot 5–16 µm vs Airy radius 3.4 µm). Fields 0, 0.7, 1 of each
spec; the spec's three wavelengths; 1 µm bins (the seed's pitch). NRMSE of one PSF = RMSE / (max − min of
the reference PSF); the table averages over fields × wavelengths.

    .venv/bin/python benchmarks/simulate/psf_nrmse.py [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import torch

from lensopt.analysis.psf_reference import diffraction_psf
from lensopt.analysis.psf_stack import PsfSettings, compute_psfs
from lensopt.spec import build, load_spec

ROOT = Path(__file__).resolve().parents[2]
CASES = {"achromat_f10": ("near diffraction-limited", 61), "cooke_triplet": ("aberrated", 121)}
METHODS = {"geometric": "none", "naive (incoherent Airy)": "incoherent", "heuristic (coherent Airy)": "heuristic"}


def nrmse(est: torch.Tensor, ref: torch.Tensor) -> torch.Tensor:
    rmse = ((est - ref) ** 2).mean((-1, -2)).sqrt()
    return rmse / (ref.amax((-1, -2)) - ref.amin((-1, -2)))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--json", type=Path)
    ap.add_argument("--rays", default="rings:64")
    ap.add_argument("--pupil", type=int, default=192, help="pupil samples per diameter of the reference")
    args = ap.parse_args()
    torch.set_num_threads(1)
    results = {}
    for name, (kind, size) in CASES.items():
        model = build(load_spec(ROOT / "specs" / f"{name}.toml"))
        rel = torch.tensor(model.system.rel_field, dtype=torch.float64)
        row: dict[str, object] = {"kind": kind, "grid": size, "pitch_um": 1.0}
        stacks = {}
        for label, mode in METHODS.items():
            t0 = time.perf_counter()
            with torch.no_grad():
                stacks[label] = compute_psfs(model.lens, model.system, rel, PsfSettings(
                    sampling=args.rays, pitch_mm=1e-3, size=size, diffraction=mode))
            row[f"time_s {label}"] = time.perf_counter() - t0
        center = stacks["geometric"].center
        t0 = time.perf_counter()
        ref = diffraction_psf(model.lens, model.system, rel, center, pitch_mm=1e-3, size=size,
                              pupil_samples=args.pupil, subsamples=3)
        row["time_s reference"] = time.perf_counter() - t0
        ref_coarse = diffraction_psf(model.lens, model.system, rel, center, pitch_mm=1e-3, size=size,
                                     pupil_samples=args.pupil // 2, subsamples=3)
        row["reference self-check (half the pupil samples)"] = float(nrmse(ref_coarse, ref).mean())
        c, h = size // 2, 24  # the seed's 49 × 49 µm crop (S4.4.3), renormalized
        crop = slice(c - h, c + h + 1)

        def cropped(p: torch.Tensor, crop: slice = crop) -> torch.Tensor:
            p = p[..., crop, crop]
            return p / p.sum((-1, -2), keepdim=True)

        for label in METHODS:
            e = nrmse(stacks[label].psf, ref)
            row[label] = float(e.mean())
            row[f"{label} per field"] = [float(v) for v in e.mean(1)]
            row[f"{label} 49x49 crop"] = float(nrmse(cropped(stacks[label].psf), cropped(ref)).mean())
        results[name] = row
    print(f"{'lens':16} {'kind':26} " + " ".join(f"{m:>27}" for m in METHODS))
    for name, row in results.items():
        print(f"{name:16} {row['kind']:26} " + " ".join(f"{100 * row[m]:26.1f}%" for m in METHODS))
        print(f"{'  49x49 crop':43} " + " ".join(f"{100 * row[m + ' 49x49 crop']:26.1f}%" for m in METHODS))
    print(json.dumps(results, indent=1))
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
