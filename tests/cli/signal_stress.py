"""Send SIGINT / SIGTERM to a real ``python -m lensopt trace`` process at many moments and count what
happens (issue 17: exit 130 / 143 with exactly one line, whenever the signal comes).

Windows: ``startup`` — a delay after the process has installed lensopt's handlers (read from
/proc/PID/status, so the interpreter's own start, before any lensopt code runs, is not counted), covering
the imports and the command; ``shutdown`` — a delay after the command printed its first line of output,
covering the end of the command and the interpreter's exit; ``pre-entry`` — no wait at all (the signal
may come before Python has run a line of lensopt: the default disposition applies there, and nothing in
the program can change that).

Outcomes: ``one_line`` (the exit code of the signal, stderr exactly "interrupted" / "terminated"),
``finished`` (exit 0, the complete table, nothing on stderr: the signal came after the process had
committed to its exit), anything else is a failure and is kept verbatim.

``python tests/cli/signal_stress.py [REPEATS] [--pre-entry]`` prints the counts (benchmarks/README.md, accuracy).
"""

from __future__ import annotations

import collections
import os
import signal
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
COOKE = ROOT / "specs" / "cooke_triplet.toml"
ENV = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""), "OMP_NUM_THREADS": "1"}
WORD = {signal.SIGINT: ("interrupted", 130), signal.SIGTERM: ("terminated", 143)}
DONE = "EFL"  # in the last table trace prints


def _handlers_installed(pid: int) -> bool:
    """lensopt's handlers are in place: the process catches SIGTERM (Python alone leaves it at default)."""
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return True  # gone already
    caught = int(next(ln.split()[1] for ln in text.splitlines() if ln.startswith("SigCgt:")), 16)
    return bool(caught >> (signal.SIGTERM - 1) & 1)


def one(sig: int, delay: float, window: str) -> str:
    """Run ``lensopt trace``, send ``sig`` ``delay`` seconds into ``window``, return the outcome's name."""
    proc = subprocess.Popen([sys.executable, "-m", "lensopt", "trace", str(COOKE)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=ENV)
    first = ""
    if window == "startup":
        t0 = time.monotonic()
        while not _handlers_installed(proc.pid) and time.monotonic() - t0 < 30:
            time.sleep(0.0005)
    elif window == "shutdown":
        first = proc.stdout.readline()
    time.sleep(delay)
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=120)
    out = first + out
    word, code = WORD[sig]
    if proc.returncode == code and err.strip() == word:
        return "one_line"
    if proc.returncode == 0 and not err.strip() and DONE in out:
        return "finished"
    text = err.strip()
    return f"rc={proc.returncode} stderr={text if len(text) < 700 else text[:400] + ' … ' + text[-250:]!r}"


def delays(window: str, count: int) -> list[float]:
    """``count`` delays spread over the window: 0–1.5 s after startup, 0–60 ms after the output began."""
    span = {"startup": 1.5, "shutdown": 0.06, "pre-entry": 0.0}[window]
    return [span * k / max(count - 1, 1) for k in range(count)]


def stress(window: str, count: int, repeats: int = 1, workers: int = 2) -> collections.Counter:
    """Outcome counts over ``repeats`` × ``count`` delays × both signals, ``workers`` processes at a time."""
    jobs = [(sig, d) for _ in range(repeats) for d in delays(window, count) for sig in WORD]
    with ThreadPoolExecutor(workers) as pool:
        got = list(pool.map(lambda job: (job[0], one(job[0], job[1], window)), jobs))
    return collections.Counter((signal.Signals(sig).name, outcome) for sig, outcome in got)


def entry_latency(runs: int = 10) -> list[float]:
    """Seconds from spawning ``python -m lensopt --version`` to lensopt's handlers being in place: the
    pre-entry window, where the operating system's default applies."""
    out = []
    for _ in range(runs):
        t0 = time.monotonic()
        proc = subprocess.Popen([sys.executable, "-m", "lensopt", "--version"], stdout=subprocess.DEVNULL, env=ENV)
        while not _handlers_installed(proc.pid):
            time.sleep(0.0002)
        out.append(time.monotonic() - t0)
        proc.wait()
    return out


if __name__ == "__main__":
    reps = int(sys.argv[1]) if len(sys.argv) > 1 else 3
    windows = [("startup", 31), ("shutdown", 13)] + ([("pre-entry", 1)] if "--pre-entry" in sys.argv else [])
    if "--pre-entry" in sys.argv:
        lat = sorted(entry_latency())
        print(f"pre-entry window: median {lat[len(lat) // 2] * 1e3:.0f} ms ({lat[0] * 1e3:.0f}–{lat[-1] * 1e3:.0f} ms, "
              f"{len(lat)} runs)")
    for name, n in windows:
        t0 = time.monotonic()
        counts = stress(name, n, repeats=reps if name != "pre-entry" else 10 * reps)
        print(f"{name}: {sum(counts.values())} runs in {time.monotonic() - t0:.0f} s")
        for key, v in sorted(counts.items()):
            print(f"  {key[0]:8s} {v:4d}  {key[1]}")
