"""The package's layers (DESIGN.md, "Layers"): every module of lensopt has a rank, imports only go down
the ranks, and there is no import cycle anywhere.

    9.5  lensopt/__main__.py, the command's entry
    9    cli (lensopt/cli/)
    8.5  qa, study
    8.2  design (every spec → engine adapter; the joint lens + network step composes optim and restore)
    8.1  interchange (CODE V, Zemax: the spec is their data model)
    8    spec
    7    tolerance
    6    optim
    5    restore (networks, their training and applying: imaging below it, no lens optimization)
    4    imaging, plot (beside each other: neither imports the other)
    3    analysis
    2.5  accel (the compiled traces and Jacobian; reached from below through the ``Engine``'s tracer)
    2    optics
    1    materials
    0.5  leaves: engine, parallel, devices, checkpoint, transforms (what the torch transforms watching the
         core allow it: they import only rank 0)
    0    errors, files (atomic writes), the package root (``lensopt/__init__.py``): they import nothing from lensopt

Two packages on the same rank must not import each other. typer, rich and pydantic appear only in the
cli and spec layers. The test reads every module's AST (no import side effects), so lazy imports inside
functions count, and it fails on a module without a rank.
"""

from __future__ import annotations

import ast
from pathlib import Path

PKG = Path(__file__).resolve().parents[1] / "lensopt"

RANK = {"lensopt": 0, "errors": 0, "files": 0,
        "engine": 0.5, "parallel": 0.5, "devices": 0.5, "checkpoint": 0.5, "transforms": 0.5,
        "materials": 1, "optics": 2, "accel": 2.5, "analysis": 3, "imaging": 4, "plot": 4, "restore": 5, "optim": 6,
        "tolerance": 7, "spec": 8, "interchange": 8.1, "design": 8.2, "qa": 8.5, "study": 8.5,
        "cli": 9, "__main__": 9.5}
UI_PACKAGES = ("typer", "rich", "pydantic")
UI_LAYERS = ("cli", "spec")

# Upward imports allowed by name: none. Adding one should be a deliberate decision, visible here.
KNOWN: set[tuple[str, str]] = set()
KNOWN_CYCLES: set[frozenset[str]] = set()
"""Import cycles allowed by name: none."""


def _layer(module: str) -> str | None:
    """The ranked layer of a module name (``lensopt.optics.trace`` → ``optics``); None if it has no rank."""
    parts = module.split(".")
    if parts[0] != "lensopt":
        return None
    top = parts[1] if len(parts) > 1 else "lensopt"
    return top if top in RANK else None


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PKG.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in sorted(PKG.rglob("*.py"))}


def _imports(path: Path, name: str, modules: set[str] | frozenset[str] = frozenset()) -> list[tuple[int, str]]:
    """(line, imported module) of every import in the file, lazy ones included; relative imports resolved.
    ``from a.b import c`` names ``a.b.c`` when that is a module of the package, else ``a.b``."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1])
                base = f"{base}.{node.module}" if node.module else base
            else:
                base = node.module or ""
            for a in node.names:
                sub = f"{base}.{a.name}"
                found.append((node.lineno, sub if sub in modules else base))
    return found


def _graph() -> dict[str, set[str]]:
    """Module → the lensopt modules it imports (an ``import a.b.c`` of a name that is not a module counts as
    its package)."""
    modules = _modules()
    names = set(modules)
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        targets = set()
        for _, target in _imports(path, name, names):
            while target and target not in names:
                target = target.rpartition(".")[0]
            if target.startswith("lensopt") and target != name:
                targets.add(target)
        graph[name] = targets
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[frozenset[str]]:
    """The strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out = []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            w = next(children, None)
            if w is not None:
                if w not in graph:
                    continue
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = set()
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.add(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(frozenset(comp))
    return out


def _violations() -> tuple[list[str], set[tuple[str, str]]]:
    bad, used_known = [], set()
    modules = _modules()
    for name, path in modules.items():
        src = _layer(name)
        for line, target in _imports(path, name, set(modules)):
            where = f"{path.relative_to(PKG.parent)}:{line} imports {target}"
            if target.split(".")[0] in UI_PACKAGES and src not in UI_LAYERS:
                bad.append(where + " (UI/pydantic below the CLI)")
                continue
            dst = _layer(target)
            if target.split(".")[0] != "lensopt" or dst == src or (dst is not None and RANK[dst] < RANK[src]):
                continue
            if (src, dst) in KNOWN:
                used_known.add((src, dst))
                continue
            bad.append(where + f" ({src} → {dst} goes {'sideways' if RANK.get(dst) == RANK[src] else 'up'})")
    return bad, used_known


def test_every_module_has_a_rank() -> None:
    unranked = sorted(n for n in _modules() if _layer(n) is None)
    assert not unranked, "modules without a rank (add their package to RANK):\n" + "\n".join(unranked)


def test_imports_only_go_down() -> None:
    bad, _ = _violations()
    assert not bad, "imports that do not go down:\n" + "\n".join(bad)


def test_known_exceptions_are_still_needed() -> None:
    # When an exception disappears from the code, drop it from KNOWN so that it cannot come back unseen.
    _, used = _violations()
    assert used == KNOWN, f"no longer needed: {sorted(KNOWN - used)}"


def test_no_import_cycle() -> None:
    cycles = set(_cycles(_graph()))
    assert cycles <= KNOWN_CYCLES, "import cycles:\n" + "\n".join(" <-> ".join(sorted(c))
                                                                  for c in cycles - KNOWN_CYCLES)
    assert cycles == KNOWN_CYCLES, f"no longer a cycle (drop it from KNOWN_CYCLES): {cycles ^ KNOWN_CYCLES}"


def test_the_checker_sees_lazy_relative_and_upward_imports_and_cycles(tmp_path: Path) -> None:
    # An import inside a function counts (the way imaging/commands.py once imported plot), and a relative one.
    f = tmp_path / "m.py"
    f.write_text("def f():\n    from lensopt.plot.psf import save_psf_figure\n    import pydantic\n"
                 "    from .trace import Rays\n    from . import bundle\n")
    modules = {"lensopt.optics.bundle"}
    targets = [t for _, t in _imports(f, "lensopt.optics.m", modules)]
    assert targets == ["lensopt.plot.psf", "pydantic", "lensopt.optics.trace", "lensopt.optics.bundle"]
    assert _layer("lensopt.imaging.simulate") == "imaging" and _layer("lensopt.cli.simulate") == "cli"
    assert _layer("lensopt.files") == "files" and _layer("lensopt") == "lensopt"
    assert _layer("lensopt.newthing") is None  # an unranked module fails test_every_module_has_a_rank
    assert RANK["plot"] >= RANK["imaging"] and RANK["analysis"] < RANK["spec"] < RANK["interchange"]
    cyc = _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": {"e"}})
    assert cyc == [frozenset({"a", "b", "c"})]
