"""Atomic output files: complete or absent, with ordinary permissions."""

from __future__ import annotations

import os
import stat

import pytest

from lensopt.files import atomic_path, write_text_atomic


def test_written_file_has_umask_permissions(tmp_path):
    """Regression: files came out 0600 (mkstemp's mode) instead of 0666 & ~umask like open() gives."""
    old = os.umask(0o022)
    try:
        write_text_atomic(tmp_path / "a.txt", "x")
        (tmp_path / "b.txt").write_text("x")
    finally:
        os.umask(old)
    mode = stat.S_IMODE((tmp_path / "a.txt").stat().st_mode)
    assert mode == stat.S_IMODE((tmp_path / "b.txt").stat().st_mode) == 0o644


def test_error_leaves_neither_target_nor_temporary(tmp_path):
    target = tmp_path / "sub" / "fig.png"
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        assert tmp.suffix == ".png" and tmp.parent == target.parent
        tmp.write_bytes(b"partial")
        raise RuntimeError("boom")
    assert list(target.parent.iterdir()) == []
