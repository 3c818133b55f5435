"""The ``Engine`` (``lensopt.engine``): one frozen value for how work runs. Its memory budget refuses
work over it with one line naming what to lower; it travels to Dask workers without the CLI's listener;
``retain_freed_memory`` keeps freed arrays in the process, so the next optimizer step's arrays of the same
size do not fault their pages in again (the kernel's count of minor page faults is the oracle)."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

SCRIPT = textwrap.dedent("""
    import resource
    import torch
    import lensopt.optim.driver  # noqa: F401 - the heap of an optimizing process (the imports shape it)
    from lensopt.engine import retain_freed_memory

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
    assert again == "True"  # a process setting, made once: the same answer
    # 20 allocations of 48 MB: ~11,700 pages each when mapped afresh; reused, only the first faults.
    assert int(before) > 20 * 10_000
    assert int(after) < int(before) / 5


def test_the_budget_refuses_with_one_line_naming_what_to_lower() -> None:
    import pickle

    from lensopt.engine import Engine, format_bytes
    from lensopt.errors import LensoptError

    e = Engine(max_memory=3_000_000)
    assert e.budget == 3_000_000
    e.require(3_000_000, "x", lower="y")  # at the budget: fine
    with pytest.raises(LensoptError, match=r"^--z: tracing needs about 3\.5 MB, over the memory budget of 3 MB; "
                                           r"lower the rays \(or raise --max-memory\)"):
        e.require(3_500_000, "tracing", lower="the rays", path="--z")
    assert format_bytes(2.5e9) == "2.5 GB" and format_bytes(999) == "0.999 kB"
    with pytest.raises(LensoptError, match="max_memory"):
        Engine(max_memory=0)
    # A Dask worker gets the engine without the CLI's listener (a lambda would not pickle).
    back = pickle.loads(pickle.dumps(Engine(backend="eager", max_memory=5, on_compile=lambda d, s: None)))
    assert back == Engine(backend="eager", max_memory=5) and back.on_compile is None
