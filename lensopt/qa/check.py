"""Regression checks of lenses against a recorded baseline (``lensopt check``).

Each lens is measured with fixed, recorded settings (``CheckSettings``: pupil sampling, seed, eager
float64 trace) — first-order data (EFL, BFL, f/#, TTL), ESR, the ESR on the seed's measure
(``analysis.report.seed_esr_um``: 11 fields, grid:61, whatever the settings' sampling), RMS spot radius,
distortion, relative illumination and failed rays per field, and the margins of the constraints its
``[optimize]`` section declares — and compared with a baseline JSON, each metric against an absolute
tolerance (defaults ``spec.models.CHECK_METRICS``, overridable per lens in ``[check] tolerances``).

Baseline file (``lenses/check_baseline.json``)::

    {"lensopt_check": 1, "settings": {"sampling": "gauss:16", "seed": 0, "backend": "eager"},
     "lenses": {"cooke_triplet_opt.json": {"name": ..., "identity": {...}, "metrics": {"efl_mm": 50.0, ...}}}}

Lenses are keyed by file name; ``identity`` (name, surfaces, wavelengths, fields) tells a baseline of
another lens from a changed lens (the first is bad input, the second a regression).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any
from xml.etree import ElementTree as ET

from lensopt.accel import on_backend
from lensopt.engine import Engine
from lensopt.errors import LensoptError
from lensopt.files import write_text_atomic
from lensopt.optics.sampling import PupilSampling
from lensopt.spec.build import build
from lensopt.spec.io import load_spec
from lensopt.spec.models import CHECK_METRICS, LensSpec

__all__ = ["CheckSettings", "MetricResult", "LensCheck", "measure", "load_baseline", "check_lenses",
           "update_baseline", "junit_xml", "FORMAT"]

FORMAT = 1


@dataclass(frozen=True)
class CheckSettings:
    """How the metrics are measured (recorded in the baseline, reused from it)."""

    sampling: str = "gauss:16"
    seed: int = 0
    backend: str = "eager"


@dataclass(frozen=True)
class MetricResult:
    metric: str
    baseline: float | None
    value: float | None
    tolerance: float
    passed: bool

    @property
    def delta(self) -> float | None:
        if self.baseline is None or self.value is None:
            return None
        return self.value - self.baseline


@dataclass
class LensCheck:
    key: str
    name: str
    metrics: list[MetricResult] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return all(m.passed for m in self.metrics)


def family(metric: str) -> str:
    """``rms_um@0.70`` → ``rms_um``; ``margin.ray_angle_deg`` → ``margin``."""
    return metric.split("@")[0].split(".")[0]


def identity(spec: LensSpec) -> dict[str, Any]:
    return {"name": spec.name, "surfaces": len(spec.surfaces),
            "wavelengths_nm": list(spec.spectrum.wavelengths_nm), "fields": list(spec.system.field.relative)}


def measure(spec: LensSpec, settings: CheckSettings, *, engine: Engine | None = None) -> dict[str, float]:
    """Every metric of one lens, with ``settings`` (floats; counts as floats too), traced on the baseline's
    backend (``settings.backend``) within ``engine``'s memory budget."""
    from lensopt.analysis.report import seed_esr_um, trace_report

    engine = on_backend(engine, settings.backend)
    sampling = PupilSampling.parse(settings.sampling, seed=settings.seed, path="settings.sampling", weighted=True)
    model = build(spec)
    rep = trace_report(model, sampling, engine=engine)
    out: dict[str, float] = {}
    fo = rep["first_order"]
    out.update(efl_mm=fo["efl"], bfl_mm=fo["bfl"], fnumber=fo["fnumber"], ttl_mm=fo["total_track"],
               esr_um=rep["effective_spot_radius_um"], seed_esr_um=_num(seed_esr_um(model, engine=engine)))
    for f in rep["fields"]:
        at = f"@{f['relative']:.2f}"
        out["rms_um" + at] = f["rms_spot_radius_weighted_um"]
        out["distortion_percent" + at] = _num(f["distortion_percent"])
        out["ri" + at] = _num(f["relative_illumination"]["std"])
        out["failed_rays" + at] = float(f["failed_rays"])
    out.update(_margins(spec, sampling, engine))
    return out


def _num(v: float | None) -> float:
    return math.nan if v is None else float(v)


def _margins(spec: LensSpec, sampling: PupilSampling, engine: Engine) -> dict[str, float]:
    """Constraint margins (positive: inside the limit) of the constraints the spec declares."""
    if spec.optimize is None:
        return {}
    from lensopt.design import build_problem
    from lensopt.optim.report import constraint_report

    cons = spec.optimize.constraints
    problem = build_problem(spec, seed=sampling.seed, engine=engine)
    rep = constraint_report(problem, problem.theta0, sampling)
    out: dict[str, float] = {}
    if "gaps" in rep:
        m = math.inf
        for g in rep["gaps"]:
            m = min(m, g["min"] - g["lower"])
            if g["upper"] is not None:
                m = min(m, g["upper"] - g["max"])
        out["margin.ray_path_mm"] = m
    if cons.ray_angle is not None:
        out["margin.ray_angle_deg"] = cons.ray_angle.max_deg - rep["max_angle_deg"]
    if cons.surface_normal is not None:
        out["margin.surface_normal_deg"] = cons.surface_normal.max_deg - rep["max_normal_deg"]
    if cons.distortion is not None:
        out["margin.distortion_percent"] = cons.distortion.max_percent - max(abs(v) for v in rep["distortion_percent"])
    if cons.relative_illumination is not None:
        out["margin.relative_illumination"] = min(rep["relative_illumination"]) - cons.relative_illumination.min
    return out


def load_baseline(path: Path) -> dict[str, Any]:
    """The baseline file, validated (bad input: ``LensoptError`` naming ``--baseline``)."""
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise LensoptError("no such baseline file (write one with --update)", path="--baseline",
                           got=str(path)) from None
    except (OSError, UnicodeDecodeError, ValueError) as err:
        raise LensoptError(f"not a readable JSON baseline ({type(err).__name__}: {str(err).splitlines()[0]})",
                           path="--baseline", got=str(path)) from None
    ok = (isinstance(data, dict) and data.get("lensopt_check") == FORMAT and isinstance(data.get("lenses"), dict)
          and isinstance(data.get("settings"), dict)
          and all(isinstance(e, dict) and isinstance(e.get("metrics"), dict) and isinstance(e.get("identity"), dict)
                  for e in data["lenses"].values()))
    if not ok:
        raise LensoptError(f"not a lensopt check baseline (expected lensopt_check = {FORMAT}, settings, lenses "
                           "with identity and metrics)", path="--baseline", got=str(path))
    try:
        CheckSettings(**data["settings"])
    except TypeError:
        raise LensoptError("unknown settings in the baseline", path="--baseline",
                           got=sorted(data["settings"])) from None
    return data


def _load_lens(path: Path) -> LensSpec:
    return load_spec(path)


def _keys(paths: list[Path]) -> list[str]:
    keys = [p.name for p in paths]
    dup = {k for k in keys if keys.count(k) > 1}
    if dup:
        raise LensoptError("lenses are keyed by file name in the baseline; two have the same name", path="LENS",
                           got=sorted(dup))
    return keys


def check_lenses(paths: list[Path], baseline: dict[str, Any], *, engine: Engine | None = None) -> list[LensCheck]:
    """Measure each lens with the baseline's settings and compare (bad input raises ``LensoptError``)."""
    settings = CheckSettings(**baseline["settings"])
    out = []
    for key, path in zip(_keys(paths), paths, strict=True):
        spec = _load_lens(path)
        entry = baseline["lenses"].get(key)
        if entry is None:
            raise LensoptError("no baseline for this lens (add it with --update)", path="LENS", got=str(path))
        ident = identity(spec)
        if entry["identity"] != ident:
            diff = [k for k in ident if entry["identity"].get(k) != ident[k]]
            raise LensoptError(f"the baseline entry {key!r} is of another lens ({', '.join(diff)} differ: "
                               f"{entry['identity'].get('name')!r} vs {spec.name!r})", path="--baseline", got=key)
        tol = dict(CHECK_METRICS)
        if spec.check is not None:
            tol.update(spec.check.tolerances)
        now = measure(spec, settings, engine=engine)
        res = LensCheck(key, spec.name)
        for metric in sorted(set(now) | set(entry["metrics"]), key=_order):
            b = entry["metrics"].get(metric)
            v = now.get(metric)
            t = tol[family(metric)] if family(metric) in tol else 0.0
            res.metrics.append(MetricResult(metric, b, v, t, _passes(b, v, t)))
        out.append(res)
    return out


def _order(metric: str) -> tuple[int, str]:
    fams = list(CHECK_METRICS)
    f = family(metric)
    return (fams.index(f) if f in fams else len(fams), metric)


def _passes(b: float | None, v: float | None, tol: float) -> bool:
    if b is None or v is None:
        return False  # a metric appeared or vanished: something changed in what the lens declares
    if math.isnan(b) or math.isnan(v):
        return math.isnan(b) and math.isnan(v)
    return abs(v - b) <= tol


def update_baseline(paths: list[Path], baseline_path: Path, *, settings: CheckSettings | None = None,
                    engine: Engine | None = None) -> dict:
    """Measure the lenses and (re)write their entries in the baseline atomically; other entries stay."""
    data: dict[str, Any]
    if baseline_path.exists():
        try:
            data = load_baseline(baseline_path)
        except LensoptError:
            data = {}
    else:
        data = {}
    if settings is None:
        settings = CheckSettings(**data["settings"]) if data else CheckSettings()
    if data.get("settings") != asdict(settings):
        data = {}  # other settings: the old entries are not comparable
    data = {"lensopt_check": FORMAT, "settings": asdict(settings), "lenses": dict(data.get("lenses", {}))}
    for key, path in zip(_keys(paths), paths, strict=True):
        spec = _load_lens(path)
        data["lenses"][key] = {"identity": identity(spec), "metrics": measure(spec, settings, engine=engine)}
    data["lenses"] = dict(sorted(data["lenses"].items()))
    write_text_atomic(baseline_path, json.dumps(data, indent=1, allow_nan=True) + "\n")
    return data


def junit_xml(results: list[LensCheck]) -> str:
    """JUnit XML: one test suite per lens, one test case per metric (failures carry the numbers)."""
    suites = ET.Element("testsuites", name="lensopt check", tests=str(sum(len(r.metrics) for r in results)),
                        failures=str(sum(not m.passed for r in results for m in r.metrics)))
    for r in results:
        suite = ET.SubElement(suites, "testsuite", name=r.key, tests=str(len(r.metrics)),
                              failures=str(sum(not m.passed for m in r.metrics)))
        for m in r.metrics:
            case = ET.SubElement(suite, "testcase", classname=f"lensopt.check.{r.key}", name=m.metric)
            if not m.passed:
                f = ET.SubElement(case, "failure", message=describe(m))
                f.text = describe(m)
    return ET.tostring(suites, encoding="unicode", xml_declaration=True) + "\n"


def describe(m: MetricResult) -> str:
    if m.baseline is None:
        return f"{m.metric}: new metric (= {m.value:.6g}), not in the baseline"
    if m.value is None:
        return f"{m.metric}: in the baseline (= {m.baseline:.6g}) but no longer measured"
    return f"{m.metric}: {m.baseline:.9g} → {m.value:.9g} (Δ {m.value - m.baseline:+.3g}, tolerance {m.tolerance:.3g})"


def as_json(results: list[LensCheck]) -> dict[str, Any]:
    return {"passed": all(r.passed for r in results),
            "lenses": [{"lens": r.key, "name": r.name, "passed": r.passed,
                        "metrics": [{**asdict(m), "delta": m.delta} for m in r.metrics]} for r in results]}
