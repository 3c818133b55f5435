"""CODE V sequence-file syntax: splitting text into commands, and writing derived numbers.

A ``.seq`` file is a list of commands, one or several per line separated by ``;``. ``!`` starts a
comment, ``&`` at the end of a line continues the command on the next one, and strings are quoted
with ``'`` or ``"`` (as CODE V writes them and as rayoptics' ``codev/reader.py`` reads them).
lensopt keeps its own data that CODE V has no command for in comment lines ``! lensopt: {json}``,
which CODE V and other readers skip.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

from lensopt.errors import SpecError

__all__ = ["Command", "SeqFile", "split_commands", "EXTRAS_PREFIX"]

EXTRAS_PREFIX = "! lensopt: "


@dataclass(frozen=True)
class Command:
    """One command: its line number (1-based, where it starts) and its tokens (quotes removed)."""

    line: int
    tokens: tuple[str, ...]

    @property
    def name(self) -> str:
        return self.tokens[0].upper()

    @property
    def args(self) -> tuple[str, ...]:
        return self.tokens[1:]


@dataclass
class SeqFile:
    """The commands of a file and the lensopt extras found in its comments."""

    commands: list[Command]
    extras: dict[str, Any] = field(default_factory=dict)


def _strip_comment(line: str) -> str:
    quote = ""
    for i, ch in enumerate(line):
        if quote:
            if ch == quote:
                quote = ""
        elif ch in "'\"":
            quote = ch
        elif ch == "!":
            return line[:i]
    return line


def _split_tokens(text: str, line: int, source: str) -> list[list[str]]:
    """Split one logical line into commands (``;``) and tokens (blanks, quotes)."""
    commands: list[list[str]] = [[]]
    token: list[str] = []
    quote = ""
    has_token = False

    def flush() -> None:
        nonlocal token, has_token
        if has_token:
            commands[-1].append("".join(token))
        token, has_token = [], False

    for ch in text:
        if quote:
            if ch == quote:
                quote = ""
            else:
                token.append(ch)
            continue
        if ch in "'\"":
            quote, has_token = ch, True
        elif ch == ";":
            flush()
            commands.append([])
        elif ch.isspace() or ch == ",":
            flush()
        else:
            token.append(ch)
            has_token = True
    if quote:
        raise SpecError(f"line {line}: unterminated string", path=source)
    flush()
    return [c for c in commands if c]


def split_commands(text: str, *, source: str = "seq") -> SeqFile:
    """Parse the text of a ``.seq`` file into commands and lensopt extras.

    Raises:
        SpecError: an unterminated string or a malformed ``! lensopt:`` comment.
    """
    commands: list[Command] = []
    extras: dict[str, Any] = {}
    pending, start = "", 0
    for number, raw in enumerate(text.splitlines(), start=1):
        if raw.startswith(EXTRAS_PREFIX):
            try:
                data = json.loads(raw[len(EXTRAS_PREFIX):])
            except json.JSONDecodeError as err:
                raise SpecError(f"line {number}: malformed lensopt comment: {err}", path=source) from None
            if not isinstance(data, dict):
                raise SpecError(f"line {number}: a lensopt comment must hold a JSON object", path=source)
            extras.update(data)
            continue
        body = _strip_comment(raw).rstrip()
        if not pending:
            start = number
        if body.endswith("&"):
            pending += body[:-1]
            continue
        logical, pending = pending + body, ""
        for tokens in _split_tokens(logical, start, source):
            commands.append(Command(start, tuple(tokens)))
    if pending:
        for tokens in _split_tokens(pending, start, source):
            commands.append(Command(start, tuple(tokens)))
    return SeqFile(commands, extras)
