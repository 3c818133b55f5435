"""``optim.driver.retain_freed_memory``: freed arrays stay in the process, so the next step's arrays of the
same size do not fault their pages in again (the kernel's count of minor page faults is the oracle)."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

SCRIPT = textwrap.dedent("""
    import resource
    import torch
    from lensopt.optim.driver import retain_freed_memory

    def faults():
        r0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
        for _ in range(20):
            x = torch.ones(6_000_000, dtype=torch.float64)  # 48 MB: above glibc's largest default mmap threshold
            del x
        return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - r0

    before = faults()
    ok = retain_freed_memory()
    again = retain_freed_memory()
    after = faults()
    print(before, after, ok, again)
""")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc mallopt: Linux only")
def test_freed_arrays_are_reused_without_page_faults() -> None:
    out = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, check=True, timeout=120)
    before, after, ok, again = out.stdout.split()
    if ok != "True":
        pytest.skip("mallopt unavailable (not glibc)")
    assert again == "True"  # once per process, same answer
    # 20 allocations of 48 MB: ~11,700 pages each when mapped afresh; reused, only the first faults.
    assert int(before) > 20 * 10_000
    assert int(after) < int(before) / 5
