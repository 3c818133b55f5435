"""Where ``lensopt simulate`` holds its memory: the same command as benchmarks/simulate_command.py, run
in this process with the resident set (VmRSS) before and after each stage and the stage's own peak (VmHWM,
reset before the stage by writing 5 to /proc/self/clear_refs), so the stages' peaks can be told apart.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/simulate_memory.py [SCENE.png]
    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/simulate_memory.py --fft

Without SCENE.png, coffee.png mirrored to 4000 × 3000 is written to a temporary folder first.
``--fft``: the resident memory that torch's CPU FFT (MKL) keeps after repeated transforms of one 4000 × 3000
patch's size (3 × 960 × 1024 float32, the 5 × 4 grid's), batched over the 3 channels vs one channel at a
time, into the same output buffers, with the time per patch (forward + inverse).
"""

from __future__ import annotations

import functools
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from procmem import vm_kb  # noqa: E402

rows: list[str] = []
_inner: list[float] = []  # per open call: the highest peak of the calls nested in it (their resets hide it)


def _mb(field: str) -> float:
    return vm_kb(field) / 1024


def watch(module: object, name: str) -> None:
    """Replace ``module.name`` by a wrapper that records the memory around each call."""
    f = getattr(module, name)

    @functools.wraps(f)
    def wrapper(*args: object, **kwargs: object) -> object:
        before = _mb("VmRSS")
        _inner.append(0.0)
        Path("/proc/self/clear_refs").write_text("5")
        result = f(*args, **kwargs)
        peak = max(_mb("VmHWM"), _inner.pop())
        if _inner:
            _inner[-1] = max(_inner[-1], peak)
        rows.append(f"| {name} | {before:.0f} | {peak:.0f} | {_mb('VmRSS'):.0f} |")
        return result

    setattr(module, name, wrapper)


def fft_memory(which: str, rounds: int = 6) -> None:
    import time

    import torch

    x = torch.rand(3, 960, 1024)
    spec = torch.empty(3, 960, 513, dtype=torch.complex64)
    conv = torch.empty(3, 960, 1024)

    def batched() -> None:
        torch.fft.rfft2(x, out=spec)
        torch.fft.irfft2(spec, s=(960, 1024), out=conv)

    def planes() -> None:
        for c in range(3):
            torch.fft.rfft2(x[c], out=spec[c])
            torch.fft.irfft2(spec[c], s=(960, 1024), out=conv[c])

    for name, f in (("one channel at a time", planes), ("3 channels batched", batched)):
        if name != which:
            continue
        base = _mb("VmRSS")
        times = []
        for _ in range(rounds):
            t0 = time.perf_counter()
            f()
            times.append(time.perf_counter() - t0)
        print(f"{name}: RSS +{_mb('VmRSS') - base:.0f} MB after {rounds} patches; "
              f"median {sorted(times)[rounds // 2] * 1e3:.0f} ms per patch (torch threads {torch.get_num_threads()}, "
              f"MKL {torch.backends.mkl.is_available()})")


def main() -> None:
    if sys.argv[1:] == ["--fft"]:  # each variant in a fresh process: the first FFT of a size pays MKL's set-up
        import subprocess

        for which in ("one channel at a time", "3 channels batched"):
            subprocess.run([sys.executable, __file__, "--fft-one", which], check=True)
        return
    if sys.argv[1:2] == ["--fft-one"]:
        fft_memory(sys.argv[2])
        return
    if len(sys.argv) > 1:
        scene = Path(sys.argv[1])
    else:
        from simulate_command import make_scene

        scene = make_scene(Path(tempfile.mkdtemp(prefix="sim_mem_")) / "scene.png")
    start = _mb("VmRSS")
    import torch  # noqa: F401  (what every run imports first)

    import lensopt.imaging.io as iio
    import lensopt.imaging.simulate as sm
    from lensopt.cli.app import app

    after_imports = _mb("VmRSS")
    # lensopt.cli.simulate.run_simulate imports these when it runs: watch them where they are defined
    for module, name in ((iio, "read_image"), (sm, "plan_scene"), (sm, "run_plan"), (iio, "write_image")):
        watch(module, name)
    for name in ("compute_psfs", "build_psf_grid", "overlap_add_convolve"):
        watch(sm, name)
    out = Path(tempfile.mkdtemp(prefix="sim_mem_out_")) / "out.png"
    sys.argv = ["lensopt", "simulate", str(ROOT / "specs" / "cooke_triplet.toml"), str(scene), "-o", str(out),
                "--region", "full", "--grid", "5x4", "--effects", "-diffraction", "--json"]
    try:
        app()
    except SystemExit as e:
        if e.code:
            raise
    print(f"interpreter start {start:.0f} MB; after importing torch and the CLI {after_imports:.0f} MB",
          file=sys.stderr)
    print("| stage (nested calls listed first) | RSS before MB | peak during MB | RSS after MB |", file=sys.stderr)
    print("| --- | ---: | ---: | ---: |", file=sys.stderr)
    print("\n".join(rows), file=sys.stderr)


if __name__ == "__main__":
    main()
