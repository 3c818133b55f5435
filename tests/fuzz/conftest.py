"""Registers the fuzz tally report (see fuzz_harness.py)."""

from tests.fuzz.fuzz_harness import _report  # noqa: F401
