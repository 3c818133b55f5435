"""The documentation keeps its shape: a short README, links that resolve, a benchmarks folder whose
results page names only scripts and records that exist (issue 26)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), ROOT / "benchmarks" / "README.md"]
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = heading.strip().lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(page: Path) -> set[str]:
    out, fence = set(), False
    for line in page.read_text().splitlines():
        if line.startswith("```"):
            fence = not fence
        elif not fence and line.startswith("#"):
            out.add(slug(line.lstrip("#")))
    return out


def test_readme_and_results_page_are_short() -> None:
    assert len((ROOT / "README.md").read_text().splitlines()) <= 400
    assert len((ROOT / "benchmarks" / "README.md").read_text().splitlines()) <= 400


def test_benchmarks_hold_at_most_60_files() -> None:
    files = [p for p in (ROOT / "benchmarks").rglob("*") if p.is_file() and "__pycache__" not in p.parts]
    assert len(files) <= 60, len(files)


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_links_resolve(page: Path) -> None:
    for target in LINK.findall(page.read_text()):
        if re.match(r"[a-z]+:", target):
            continue
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        assert dest.exists(), f"{page.name}: link to a missing file {target}"
        if anchor and dest.suffix == ".md":
            assert anchor in anchors(dest), f"{page.name}: no heading for #{anchor} in {dest.name}"


def test_results_page_names_existing_scripts_and_records() -> None:
    text = (ROOT / "benchmarks" / "README.md").read_text()
    named = set(re.findall(r"benchmarks/[\w/.\-]+\.(?:py|sh|json|toml)", text))
    assert named, "the results page names no script"
    missing = sorted(n for n in named if not (ROOT / n).exists())
    assert not missing, missing


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_named_repository_files_exist(page: Path) -> None:
    """Scripts, records, specs and tests the pages name (``benchmarks/…``, ``specs/…``, ``tests/….py``) exist."""
    text = page.read_text()
    named = set(re.findall(r"(?<![\w/])(?:benchmarks|specs|lenses|tests)/[\w/.\-]+\.(?:py|sh|json|toml|md|zmx|seq|agf)",
                           text))
    named.discard("benchmarks/RESULTS.md")  # the old diary, named for `git log`
    missing = sorted(n for n in named if not (ROOT / n).exists())
    assert not missing, missing
