"""The one-line error is one write (issue 27): processes sharing stderr (torchrun's ranks) never run their lines
into each other; under torchrun with 2+ processes each line names its rank."""

from __future__ import annotations

import sys

import pytest

from lensopt.cli.common import error_line


class _Recorder:
    """A stderr that records each write call."""

    def __init__(self) -> None:
        self.writes: list[str] = []
        self.flushes = 0

    def write(self, text: str) -> int:
        self.writes.append(text)
        return len(text)

    def flush(self) -> None:
        self.flushes += 1

    def isatty(self) -> bool:
        return False


@pytest.mark.parametrize(("env", "prefix"), [({}, ""), ({"WORLD_SIZE": "1", "RANK": "0"}, ""),
                                             ({"WORLD_SIZE": "2", "RANK": "1"}, "rank 1: ")])
def test_error_line_is_one_write_of_the_whole_line(monkeypatch: pytest.MonkeyPatch, env: dict[str, str],
                                                    prefix: str) -> None:
    monkeypatch.delenv("WORLD_SIZE", raising=False)
    monkeypatch.delenv("RANK", raising=False)
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    rec = _Recorder()
    monkeypatch.setattr(sys, "stderr", rec)
    error_line("torchrun: processes were started with\ndifferent settings [1]")
    # (rich's capture ends with an empty write: no bytes reach the stream)
    line = f"{prefix}error: torchrun: processes were started with different settings [1]\n"
    assert [w for w in rec.writes if w] == [line]
    assert rec.flushes >= 1
