"""Registers the fuzz tally report (see fuzz_harness.py)."""

from fuzz_harness import _report  # noqa: F401
