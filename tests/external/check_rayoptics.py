"""Optional test group: lensopt's CODE V export read back by rayoptics, an independent CODE V reader.

Not part of ``make test`` (the file name does not match ``test_*.py``); run it with
``make test-external``, which creates ``tests/external/.venv`` (Python ≥ 3.12, ``pip install
rayoptics``) and runs ``pytest tests/external/check_rayoptics.py``. Environment:

- ``LENSOPT_RAYOPTICS_PYTHON``: the rayoptics interpreter (default ``tests/external/.venv/bin/python``).
- ``refractiveindexinfodb``: opticalglass downloads the refractiveindex.info database on first import;
  without network access we point it to an empty stub (the comparison uses private catalogs, and
  opticalglass's vendor spreadsheets for the catalog-name check).

For every lens of specs/ and tests/interchange/data/: EFL, BFL and the paraxial image height (≤ 1e-9 relative)
and the image intercepts of lensopt's real rays traced by rayoptics (≤ 1e-9 mm). rayoptics limitations
(see ``rayoptics_side.py``) are patched where they bite, and the unpatched numbers are reported too.
The report goes to ``out/external/rayoptics_report.md``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from lensopt_side import ROOT, write_references  # noqa: E402

OUT = ROOT / "out" / "external"
PYTHON = Path(os.environ.get("LENSOPT_RAYOPTICS_PYTHON", Path(__file__).parent / ".venv" / "bin" / "python"))
REL_TOL = 1e-9
RAY_TOL_MM = 1e-9


def _limitations(ref: dict) -> list[str]:
    out = []
    if ref["infinite_object"]:
        out.append("1 (object at 1e10 mm: image height)")
    if ref["diffractive_surfaces"]:
        out.append("2 (paraxial DOE power)")
    if ref["hwl_not_reference"]:
        out.append("3 (HWL reset)")
    if ref["air_to_glass_doe"]:
        out.append("4 (air→glass DOE refraction)")
    if ref["image_height_field_with_defocus"]:
        out.append("5 (YIM ignores the SI defocus)")
    return out


@pytest.fixture(scope="module")
def results() -> list[tuple[dict, dict]]:
    if not PYTHON.exists():
        pytest.fail(f"no rayoptics interpreter at {PYTHON}; run `make test-external` (creates it)")
    refs_path = write_references(OUT)
    env = dict(os.environ)
    if "refractiveindexinfodb" not in env:
        stub = OUT / "rii-stub"
        (stub / "data").mkdir(parents=True, exist_ok=True)
        (stub / "catalog-nk.yml").write_text("[]\n")
        env["refractiveindexinfodb"] = str(stub)
    got_path = OUT / "rayoptics.json"
    proc = subprocess.run([str(PYTHON), str(Path(__file__).parent / "rayoptics_side.py"), str(refs_path),
                           str(got_path)], cwd=OUT, env=env, capture_output=True, text=True, timeout=1800)
    assert proc.returncode == 0, proc.stderr[-4000:]
    refs = json.loads(refs_path.read_text())
    got = {r["name"]: r for r in json.loads(got_path.read_text())}
    pairs = [(ref, got[ref["name"]]) for ref in refs]
    _write_report(pairs)
    return pairs


def _rel(a: float, b: float) -> float:
    return abs(abs(a) / abs(b) - 1.0)


def _write_report(pairs: list[tuple[dict, dict]]) -> None:
    rows = ["| lens | mode | EFL rel | BFL rel | paraxial image height rel | max ray Δ mm | rays | "
            "rayoptics limitations that bite |", "|---|---|---|---|---|---|---|---|"]
    for ref, got in pairs:
        for mode in ("as_read", "patched"):
            g = got[mode]
            rows.append(f"| {ref['spec']} | {mode} | {_rel(g['efl'], ref['efl']):.1e} | "
                        f"{_rel(g['bfl'], ref['bfl']):.1e} | {_rel(g['img_ht'], ref['img_ht']):.1e} | "
                        f"{g['ray_dev_mm']:.1e} | "
                        f"{ref['rays'] - g['ray_failed']}/{ref['rays']} | {', '.join(_limitations(ref)) or '—'} |")
    names = ["", "Catalog glass names (export without --private-catalog) read by rayoptics' own catalogs:", "",
             "| lens | glasses not found | EFL rel (rayoptics' vendor catalog data) |", "|---|---|---|"]
    for ref, got in pairs:
        c = got["catalog_names"]
        if "reader_error" in c:
            names.append(f"| {ref['spec']} | rayoptics failed: {c['reader_error']} | — |")
        else:
            names.append(f"| {ref['spec']} | {', '.join(c['glasses_not_found']) or '—'} | "
                         f"{_rel(c['efl'], ref['efl']):.1e} |")
    (OUT / "rayoptics_report.md").write_text("\n".join(rows + names) + "\n")
    print("\n" + "\n".join(rows + names))


def test_first_order_data_agree(results: list[tuple[dict, dict]]) -> None:
    for ref, got in results:
        for key in ("efl", "bfl", "img_ht"):
            assert _rel(got["patched"][key], ref[key]) <= REL_TOL, (ref["name"], key)
            if not _limitations(ref) or (key != "img_ht" and not ref["diffractive_surfaces"]):
                assert _rel(got["as_read"][key], ref[key]) <= REL_TOL, (ref["name"], key, "as read")


def test_real_ray_intercepts_agree(results: list[tuple[dict, dict]]) -> None:
    for ref, got in results:
        assert got["patched"]["ray_failed"] == 0, ref["name"]
        assert got["patched"]["ray_dev_mm"] <= RAY_TOL_MM, ref["name"]
        if not ref["diffractive_surfaces"]:
            assert got["as_read"]["ray_dev_mm"] <= RAY_TOL_MM, (ref["name"], "as read")


def test_private_catalog_glasses_are_all_found(results: list[tuple[dict, dict]]) -> None:
    for ref, got in results:
        assert got["as_read"]["glasses_not_found"] == [], ref["name"]
