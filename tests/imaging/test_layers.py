"""The package's layers (DESIGN.md, common rules): cli → qa (check, accuracy: whole lenses from their specs)
→ design (a spec's optimization problem, its write-back and drivers) → spec (pydantic models + the builder)
→ tolerance → optim → restore → imaging / plot / io → analysis → optics → materials → errors. Imports only go down (not
sideways between imaging, plot and io); typer, rich and pydantic appear only in the CLI and spec layers.
Lazy imports inside functions count.

The test walks every module's AST (no import side effects) and fails on an upward import that is not a
known, named exception below.
"""

from __future__ import annotations

import ast
from pathlib import Path

PKG = Path(__file__).resolve().parents[2] / "lensopt"

RANK = {"errors": 0, "materials": 1, "optics": 2, "analysis": 3, "imaging": 4, "plot": 4, "io": 4, "restore": 5,
        "optim": 6, "tolerance": 7, "spec": 8, "design": 8.2, "qa": 8.5, "study": 8.5,
        "cli": 9}
# Leaf utilities usable from any layer (they import nothing else from lensopt).
MODULE_RANK = {"lensopt.io.files": 0, "lensopt.parallel": 0}
UI_PACKAGES = ("typer", "rich", "pydantic")

# Upward imports that predate issue 10 and belong to other work (each names why). Adding a new one
# should be a deliberate decision, visible in this list.
KNOWN = {
    # CODE V import/export turns files into specs and back (spec is its data model).
    ("io", "spec"),
}


def _rank(module: str) -> int:
    return MODULE_RANK.get(module, RANK[_layer(module) or "errors"])


def _layer(module: str) -> str | None:
    parts = module.split(".")
    if parts[0] != "lensopt" or len(parts) < 2:
        return None
    top = parts[1]
    if top == "cli" or top.startswith("cli_") or top == "__main__":
        return "cli"
    return top if top in RANK else None


def _module_name(path: Path) -> str:
    rel = path.relative_to(PKG.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _imports(path: Path) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text(), filename=str(path))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.append((node.lineno, node.module))
    return found


def _violations() -> tuple[list[str], set[tuple[str, str]]]:
    bad, used_known = [], set()
    for path in sorted(PKG.rglob("*.py")):
        name = _module_name(path)
        src = _layer(name)
        if src is None:
            continue
        for line, target in _imports(path):
            where = f"{path.relative_to(PKG.parent)}:{line} imports {target}"
            if target.split(".")[0] in UI_PACKAGES and src not in ("cli", "spec"):
                bad.append(where + " (UI/pydantic below the CLI)")
                continue
            dst = _layer(target)
            if dst is None or dst == src or _rank(target) < _rank(name):
                continue
            if (src, dst) in KNOWN:
                used_known.add((src, dst))
                continue
            bad.append(where + f" ({src} → {dst} goes up)")
    return bad, used_known


def test_imports_only_go_down() -> None:
    bad, _ = _violations()
    assert not bad, "upward imports:\n" + "\n".join(bad)


def test_known_exceptions_are_still_needed() -> None:
    # When an exception disappears from the code, drop it from KNOWN so that it cannot come back unseen.
    _, used = _violations()
    assert used == KNOWN, f"no longer needed: {sorted(KNOWN - used)}"


def test_the_checker_sees_lazy_and_upward_imports(tmp_path: Path) -> None:
    # The walker must catch an import inside a function (the way imaging/commands.py imported plot).
    f = tmp_path / "m.py"
    f.write_text("def f():\n    from lensopt.plot.psf import save_psf_figure\n    import pydantic\n")
    targets = [t for _, t in _imports(f)]
    assert targets == ["lensopt.plot.psf", "pydantic"]
    assert _layer("lensopt.imaging.simulate") == "imaging" and _layer("lensopt.cli_imaging") == "cli"
    assert RANK[_layer("lensopt.plot.psf")] >= RANK["imaging"] and RANK["analysis"] < RANK["spec"]
