"""``lensopt.parallel``'s ``auto`` scheduler (issue 29: a Dask LocalCluster was the default for jobs it
slows down). The rule: a cluster pays only when the work left is more than its start-up × W/(W − 1);
``auto`` times the first task, estimates the rest, and stays serial below ``AUTO_SERIAL_BELOW_S`` or
with fewer than two usable cores."""

from __future__ import annotations

import pytest

from lensopt.parallel import AUTO_SERIAL_BELOW_S, auto_plan, run_tasks


def _square(shared: int, item: int) -> int:
    return shared + item * item


@pytest.mark.parametrize(("first_s", "left", "workers", "cores", "expected"), [
    (0.12, 39, 2, 2, None),  # tolerance cmount s6.2, 200 trials: ~5 s of work left → serial
    (AUTO_SERIAL_BELOW_S / 10 + 0.01, 10, 2, 2, "local"),  # just over the threshold → cluster
    (AUTO_SERIAL_BELOW_S / 10 - 0.01, 10, 2, 2, None),  # just under → serial
    (100.0, 10, 2, 1, None),  # one core: nothing to gain
    (100.0, 10, 1, 16, None),  # one worker asked for
    (5.0, 0, 2, 2, None),  # nothing left
])
def test_auto_plan_follows_the_stated_rule(first_s: float, left: int, workers: int, cores: int,
                                           expected: str | None) -> None:
    sched, why = auto_plan(first_s, left, workers, cores)
    assert sched == expected
    assert why.startswith("serial" if expected is None else "local cluster")


def test_auto_runs_short_jobs_in_this_process_in_order() -> None:
    seen: list[tuple[int, int]] = []
    plan: list[str] = []
    out = run_tasks(_square, list(range(6)), shared=10, scheduler="auto", on_done=lambda i, r: seen.append((i, r)),
                    on_plan=plan.append)
    assert out == [10 + i * i for i in range(6)]
    assert seen == list(enumerate(out))  # every result reported once, with its own index
    assert len(plan) == 1 and plan[0].startswith("serial")
    assert run_tasks(_square, [], shared=0, scheduler="auto") == []
