"""Every fenced ``lensopt ...`` line of README.md and docs/*.md runs and exits as documented.

The conventions of the docs, which this module checks:

- A fenced block tagged ``sh`` holds examples. Each line that starts with ``lensopt`` (after optional
  ``NAME=value`` environment assignments) is run in-process (the console script's typer app, through
  typer's CliRunner), in page order, in one temporary folder per page. The folder holds copies of what
  the examples read from the repository: ``specs/``, ``lenses/``, ``tests/data/``, ``tests/interchange/data/``,
  ``lensopt/imaging/data/`` and ``benchmarks/tolerance/*.toml``; examples write into ``out/`` there. A line
  ending in ``\\`` continues on the next; ``> FILE`` writes the standard output to FILE; shell globs
  (``lenses/*.json``) are expanded. A trailing comment ``# exit N`` says that the example demonstrates an
  error: it must exit with N and print exactly one ``error:`` line. Every other example must exit 0.
  Examples whose subject is the syntax use tiny budgets (``--steps 2``, small samplings, few scenes); the
  text next to them says what a real run uses.
- A block tagged ``sh slow`` holds examples that need more than about ten seconds (ahead-of-time builds,
  image-driven steps, real training). They run only with ``-m slow`` (``make test-slow``), so they may use
  the repository and what earlier slow examples of the same page wrote, never the output of a default one.
- A block tagged ``text`` holds synopses and printed output. A ``lensopt`` line there must carry an
  upper-case placeholder (``LENS``, ``SPEC``, ``FILE`` ...), so that no example hides from this test, and
  every ``--option`` it names must be one that the command's ``--help`` lists.

Every command of the app has an executed example in docs/commands.md (``test_every_command_has_an_example``).
"""

from __future__ import annotations

import glob
import re
import shlex
import shutil
from dataclasses import dataclass
from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
INPUTS = ["specs", "lenses", "tests/data", "tests/interchange/data", "lensopt/imaging/data"]
PLACEHOLDER = re.compile(r"\b[A-Z][A-Z0-9_]{2,}\b")
ENV_ASSIGNMENT = re.compile(r"^[A-Z_][A-Z0-9_]*=")


@dataclass(frozen=True)
class Example:
    page: Path
    line: int
    text: str  # the command as written (continuations joined)
    slow: bool

    @property
    def id(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"


@dataclass(frozen=True)
class Block:
    page: Path
    line: int  # line of the opening fence
    info: str  # the fence's info string ("sh", "sh slow", "text", ...)
    lines: tuple[str, ...]


def blocks(page: Path) -> list[Block]:
    out, info, start, body = [], None, 0, []
    for n, line in enumerate(page.read_text().splitlines(), 1):
        if line.startswith("```"):
            if info is None:
                info, start, body = line[3:].strip(), n, []
            else:
                out.append(Block(page, start, info, tuple(body)))
                info = None
        elif info is not None:
            body.append(line)
    assert info is None, f"{page.name}: fence opened at line {start} is never closed"
    return out


def is_command(line: str) -> bool:
    words = line.strip().split()
    while words and ENV_ASSIGNMENT.match(words[0]):
        words = words[1:]
    return bool(words) and words[0] == "lensopt"


def examples(page: Path) -> list[Example]:
    out = []
    for block in blocks(page):
        tags = block.info.split()
        if not tags or tags[0] != "sh":
            continue
        pending, first = "", 0
        for i, line in enumerate(block.lines):
            if not pending:
                first = block.line + 1 + i
            pending += line.rstrip()
            if pending.endswith("\\"):
                pending = pending[:-1] + " "
                continue
            if is_command(pending):
                out.append(Example(page, first, pending.strip(), "slow" in tags[1:]))
            pending = ""
    return out


ALL = [ex for page in PAGES for ex in examples(page)]


@pytest.fixture(scope="session")
def workdirs(tmp_path_factory: pytest.TempPathFactory) -> dict[Path, Path]:
    return {}


def workdir(workdirs: dict[Path, Path], factory: pytest.TempPathFactory, page: Path) -> Path:
    if page not in workdirs:
        d = factory.mktemp(page.stem)
        for rel in INPUTS:
            shutil.copytree(ROOT / rel, d / rel)
        (d / "benchmarks" / "tolerance").mkdir(parents=True)
        for toml in (ROOT / "benchmarks" / "tolerance").glob("*.toml"):
            shutil.copy(toml, d / "benchmarks" / "tolerance" / toml.name)
        (d / "out").mkdir()
        workdirs[page] = d
    return workdirs[page]


def app() -> typer.Typer:
    """The typer app the ``lensopt`` console script runs (``lensopt.__main__.main`` runs it after
    installing the signal handlers, which an in-process test leaves alone)."""
    from lensopt.cli.app import app as typer_app

    return typer_app


def parse(text: str, cwd: Path) -> tuple[dict[str, str], list[str], Path | None, int]:
    """Environment, argv after ``lensopt``, the ``>`` target and the expected exit code of an example."""
    m = re.search(r"#\s*exit\s+(\d+)\s*$", text)
    expected = int(m.group(1)) if m else 0
    words = shlex.split(text, comments=True)
    env = {}
    while ENV_ASSIGNMENT.match(words[0]):
        key, value = words.pop(0).split("=", 1)
        env[key] = value
    assert words.pop(0) == "lensopt"
    redirect = None
    if ">" in words:
        i = words.index(">")
        redirect, words = cwd / words[i + 1], words[:i] + words[i + 2:]
    argv = []
    for w in words:
        hits = sorted(glob.glob(w, root_dir=cwd)) if any(c in w for c in "*?[") and "=" not in w else []
        argv.extend(hits or [w])
    return env, argv, redirect, expected


@pytest.mark.parametrize("example", [pytest.param(ex, id=ex.id, marks=[pytest.mark.slow] if ex.slow else [])
                                     for ex in ALL])
def test_example_runs(example: Example, workdirs, tmp_path_factory, monkeypatch) -> None:
    cwd = workdir(workdirs, tmp_path_factory, example.page)
    env, argv, redirect, expected = parse(example.text, cwd)
    monkeypatch.chdir(cwd)
    # The examples share this process: under the default backend `auto` its count of rays per lens
    # structure (summed over every example) would switch to an in-process torch.compile, which a
    # separate `lensopt` process per command never reaches. So the eager trace, unless an example says.
    result = CliRunner().invoke(app(), argv, env={"LENSOPT_BACKEND": "eager", **env})
    out = result.stdout + result.stderr
    assert result.exit_code == expected, f"{example.id}: {example.text}\nexit {result.exit_code}\n{out[-3000:]}"
    if expected == 2:
        errors = [line for line in result.stderr.splitlines() if line.startswith("error:")]
        assert len(errors) == 1, f"{example.id}: one error line expected\n{result.stderr}"
    if redirect is not None:
        redirect.write_text(result.stdout)


def help_options(argv: list[str]) -> set[str]:
    """The option names ``lensopt ARGV --help`` lists (global options included)."""
    result = CliRunner().invoke(app(), [*argv, "--help"], env={"COLUMNS": "250"})
    assert result.exit_code == 0, result.output
    top = CliRunner().invoke(app(), ["--help"], env={"COLUMNS": "250"}).output
    return set(re.findall(r"--[a-z][a-z0-9-]*", result.output + top))


def command_path(words: list[str]) -> list[str]:
    """``plot psf`` or ``trace`` from the words after ``lensopt`` (global options skipped)."""
    while words and words[0].startswith("-"):
        words = words[2:] if words[0] == "--max-memory" else words[1:]
    return words[:2] if words and words[0] == "plot" else words[:1]


def synopsis_lines() -> list[tuple[str, str]]:
    out = []
    for page in PAGES:
        for block in blocks(page):
            if block.info.split()[:1] == ["sh"]:
                continue
            for i, line in enumerate(block.lines):
                text = line.strip().removeprefix("$ ")
                if is_command(text):
                    out.append((f"{page.relative_to(ROOT)}:{block.line + 1 + i}", text))
    return out


@pytest.mark.parametrize("where,line", synopsis_lines(), ids=[w for w, _ in synopsis_lines()])
def test_synopsis_has_placeholders_and_real_options(where: str, line: str) -> None:
    assert PLACEHOLDER.search(line), f"{where}: a lensopt line outside an sh block must be a synopsis: {line}"
    words = line.split()
    words = words[words.index("lensopt") + 1:]
    known = help_options(command_path(words))
    named = set(re.findall(r"(?<![\w-])--[a-z][a-z0-9-]*", line))
    assert named <= known, f"{where}: options not in --help: {sorted(named - known)}"


def test_every_command_has_an_example() -> None:
    group = typer.main.get_command(app())
    names = []
    for name, cmd in group.commands.items():
        sub = getattr(cmd, "commands", None)
        names += [f"{name} {s}" for s in sub] if sub else [name]
    ran = set()
    for ex in examples(ROOT / "docs" / "commands.md"):
        words = shlex.split(ex.text, comments=True)
        while not words[0] == "lensopt":
            words.pop(0)
        ran.add(" ".join(command_path(words[1:])))
    assert set(names) <= ran, f"commands without an example in docs/commands.md: {sorted(set(names) - ran)}"


def test_there_are_examples_on_every_page() -> None:
    for page in PAGES:
        if page.name not in ("architecture.md", "library.md"):
            assert examples(page), f"{page.name} has no sh example"
