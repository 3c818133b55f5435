"""Report on the seed's case studies (S4 telephoto, S4.2.2 hybrid, S5 microscope): for each spec and the
lens a short ``lensopt optimize`` run wrote from it, the ESR on a dense pupil (rings:24, as
``lensopt trace``) and on the seed's measure (``seed_esr_um``: 11 fields, grid:61), the study table's
requirements checked on a dense ray sample and on the seed's definition (the optimizer's rays at 11
fields; ``lensopt.analysis.requirements``), the glasses, and for a diffractive surface its phase range
over the used aperture. Writes benchmarks/studies/results_studies.json.

    PYTHONPATH=. python benchmarks/studies/studies_report.py lenses/telephoto_5p_tr080.json \
        lenses/telephoto_5p1_middle_tr075.json lenses/microscope_8p_wd12.json

Each lens is matched to its spec by file name (specs/<stem>.toml, a suffix _s<steps> dropped).
The seed's published ESRs (as issue 15 reads them off its figures): 5P at TR 0.80 ≈ 1.75 µm
(Figure S13), 5P+1 (middle) at TR 0.75 ≈ 2.6 µm (Figure S16), 8P microscope at WD 12 mm ≈ 0.85 µm
(Figure S32).
"""

from __future__ import annotations

import json
import math
import re
import sys
from pathlib import Path

import torch

from lensopt.analysis.report import seed_esr_um, trace_report
from lensopt.analysis.requirements import check_requirements, failed, table_s8, table_s12
from lensopt.analysis.spot import SEED_FIELDS
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.sampling import PupilSampling
from lensopt.spec import build, load_spec

ROOT = Path(__file__).resolve().parents[2]
PUBLISHED_UM = {"telephoto_5p_tr080": 1.75, "telephoto_5p1_middle_tr075": 2.6, "microscope_8p_wd12": 0.85}


def _material_name(m: object) -> str | None:
    if isinstance(m, str):
        return m
    return getattr(m, "name", None)


def table_for(stem: str, spec) -> object:  # noqa: ANN001
    """The study table of a spec: Table S8 for the telephotos, Table S12 for the microscope."""
    if stem.startswith("telephoto"):
        labels = [s.label or "" for s in spec.surfaces]
        last_lens = max(i for i, lab in enumerate(labels) if lab.startswith("E"))
        filt = labels.index("IR filter front")
        ttl = next(s.value for s in spec.optimize.solves if s.type == "ttl")
        return table_s8(flange_from=last_lens, filter_gap=filt, total_track=ttl)
    return table_s12()


def lens_checks(stem: str, spec) -> dict:  # noqa: ANN001
    model = build(spec)
    rep = trace_report(model, PupilSampling.parse("rings:24"))
    req = table_for(stem, spec)
    lens_glass = [s for s in spec.surfaces if not s.is_air and not (s.label or "").startswith("IR")]
    kw = {"glass_gaps": [not s.is_air for s in spec.surfaces],
          "materials": [_material_name(s.material) for s in lens_glass]}
    checks = check_requirements(model.lens, model.system, req, **kw)
    # The seed's definition (S2.2.2): the optimizer's rays, i.e. the spec's optimization pupil sampling (the
    # one after binding when the spec polishes on another), at the seed code base's 11 equally spaced fields.
    sampling = spec.optimize.sampling_after_binding or spec.optimize.sampling
    fields = [i / (SEED_FIELDS - 1) for i in range(SEED_FIELDS)]
    seed = check_requirements(model.lens, model.system, req, sample="seed", sampling=PupilSampling.parse(sampling),
                              rel_field=fields, **kw)
    out = {
        "esr_um_rings24": rep["effective_spot_radius_um"],
        "seed_esr_um": seed_esr_um(model),
        "first_order": rep["first_order"],
        "glasses": [_material_name(s.material) for s in lens_glass],
        "requirements": [{"name": c.name, "value": c.value, "limit": c.limit, "ok": c.ok} for c in checks],
        "requirements_failed": failed(checks),
        "requirements_seed_definition": {"sampling": sampling, "fields": fields,
                                         "checks": [{"name": c.name, "value": c.value, "limit": c.limit, "ok": c.ok}
                                                    for c in seed],
                                         "failed": failed(seed)},
    }
    phases = []
    for s, shape in enumerate(model.lens.shapes):
        if not shape.diffractive:
            continue
        grid = PupilSampling.parse("grid:41").points(dtype=torch.float64)
        with torch.no_grad():
            b = trace_bundle(model.lens, model.system, grid, record=True)
        h = b.result.hits[s].pos[..., :2].norm(dim=-1)[b.result.valid]
        r = torch.linspace(0, float(h.max()), 2001, dtype=torch.float64)
        d = model.lens.phase[s]
        phi = sum(d[i] * r ** (2 * i + 2) for i in range(d.shape[0]))
        rng = float(phi.max() - phi.min())
        phases.append({"surface": s, "used_radius_mm": float(h.max()), "phase_range_rad": rng,
                       "phase_range_waves": rng / (2 * math.pi),
                       "coefficients": [float(x) for x in d]})
    if phases:
        out["diffractive"] = phases
    return out


def main(paths: list[str]) -> None:
    results = {}
    for p in paths:
        key = Path(p).stem
        stem = re.sub(r"_s\d+$", "", key)  # out/telephoto_5p_tr080_s320.json: the spec's lens after 320 steps
        spec_path = ROOT / "specs" / f"{stem}.toml"
        start = lens_checks(stem, _solved_start(spec_path))
        end = lens_checks(stem, load_spec(p))
        results[key] = {"spec": str(spec_path.relative_to(ROOT)), "lens": p,
                         "published_esr_um": PUBLISHED_UM.get(stem), "start": start, "end": end}
        print(f"{key}: ESR {start['esr_um_rings24']:.3f} → {end['esr_um_rings24']:.3f} µm, seed's measure "
              f"{_um(start['seed_esr_um'])} → {_um(end['seed_esr_um'])} µm (published ≈ {PUBLISHED_UM.get(stem)}); "
              f"failed: {end['requirements_failed']}")
    out = ROOT / "benchmarks" / "studies" / "results_studies.json"
    old = json.loads(out.read_text()) if out.exists() else {}
    old.update(results)
    out.write_text(json.dumps(old, indent=1, ensure_ascii=False) + "\n")


def _um(v: float | None) -> str:
    return "—" if v is None else f"{v:.3f}"


def _solved_start(spec_path: Path):  # noqa: ANN202
    """The spec's crude start with its solves applied (what the optimizer starts from)."""
    from lensopt.design import build_problem, to_spec

    spec = load_spec(spec_path)
    p = build_problem(spec)
    return to_spec(p, p.theta0)


if __name__ == "__main__":
    main(sys.argv[1:])
