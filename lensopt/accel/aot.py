"""Ahead-of-time compiled trace packages: compile a lens structure once per machine, load it in milliseconds.

``torch.compile`` (``accel.compiled``) pays Dynamo's tracing and Inductor's cache look-ups in *every*
process: ≈ 20 s per structure on the loaded 2-core machine even with a warm on-disk cache
(benchmarks/README.md, trace), while the commands' eager traces take under a second. So
those commands could never use it. AOTInductor instead writes the compiled kernel into a package (a
``.pt2`` zip holding a shared library), built from one fixed input shape: ``AOT_CHUNK`` rays in the
component-major layout of ``compiled.component_major_rays``. A later process loads it through
``torch._C._aoti`` (no Dynamo, no Inductor import) in milliseconds, and the trace helper
(``accel.dispatch``) feeds it fixed chunks, the last one padded.

Packages live in ``$TORCHINDUCTOR_CACHE_DIR/lensopt_aot/`` (default ``/tmp/torchinductor_$USER``), next
to Inductor's cache, one per *structure*: surface kinds, stop, ``upto``, ``record``, Newton cap, dtype,
device, the lens tensors' shapes, the chunk size, the torch version and a hash of the trace's source
files (a changed trace never runs a stale kernel). Values (radii, thicknesses, glasses) are inputs, so
one package serves every lens of that structure. Inference only: no autograd through a package (the
backend sends calls that need gradients elsewhere). CPU only for now.

``build_package`` makes one (export + AOTInductor: about 40 s of CPU on a 9-surface lens, minutes of
wall time on a loaded machine; written to a temporary file and renamed, so a package is never
half-written); ``lensopt warmup LENS`` builds those the ray-heavy commands use.
"""

from __future__ import annotations

import getpass
import hashlib
import os
import re
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any

import torch
from torch import Tensor

from lensopt.accel.compiled import near_only_surfaces
from lensopt.files import atomic_path
from lensopt.optics.intersect import NEWTON_ITERATIONS
from lensopt.optics.lens import Lens
from lensopt.optics.trace import KernelOptions, Rays, RayTrace, SurfaceHit, index_ratio, trace_kernel

__all__ = ["AOT_CHUNK", "package_dir", "package_path", "has_package", "is_loaded", "mark_broken", "build_package",
           "load_package", "unload_package",
           "aot_trace", "supported", "describe"]

AOT_CHUNK = 1 << 14
"""Rays per call of a package (its one input shape)."""

_LENS_TENSORS = ("curvature", "conic", "asphere", "phase", "thickness", "index", "wavelength_um", "semi_diameter")
_SOURCES = ("trace.py", "intersect.py", "interact.py", "surfaces.py", "lens.py", "placement.py")
"""The source files the kernel is compiled from (their hash is part of a package's key)."""
_MAX_FUSION_SIZE = 4096  # as ``compiled._MAX_FUSION_SIZE``: one fused loop over the surfaces
_loaded: dict[Path, Any] = {}
_broken: set[Path] = set()
_source_hash: str | None = None


def supported(lens: Lens) -> bool:
    """Whether this lens's trace can run from a package: on the CPU, no placement (the compiled trace
    does not take decentered or tilted lenses yet)."""
    return lens.placement is None and lens.device.type == "cpu"


def package_dir() -> Path:
    """``lensopt_aot`` in Inductor's cache directory (``$TORCHINDUCTOR_CACHE_DIR``, else
    ``<tmp>/torchinductor_<user>``: Inductor's own rule, repeated here so that finding a package does not
    import Inductor)."""
    root = os.environ.get("TORCHINDUCTOR_CACHE_DIR")
    if root is None:
        try:
            user = getpass.getuser()
        except (KeyError, ModuleNotFoundError, OSError):
            user = f"uid_{os.getuid()}" if hasattr(os, "getuid") else "unknown_user"
        root = os.path.join(tempfile.gettempdir(), "torchinductor_" + re.sub(r'[\\/:*?"<>|]', "_", user))
    return Path(os.path.abspath(root)) / "lensopt_aot"


def _sources() -> str:
    global _source_hash
    if _source_hash is None:
        here = Path(__file__).resolve().parents[1] / "optics"
        h = hashlib.sha256()
        for name in _SOURCES:
            h.update((here / name).read_bytes())
        _source_hash = h.hexdigest()[:16]
    return _source_hash


def _structure(lens: Lens, upto: int | None, record: bool, newton_iterations: int) -> tuple:
    return (tuple(repr(s) for s in lens.shapes), lens.stop, upto, record, newton_iterations, str(lens.dtype),
            lens.device.type, tuple(tuple(getattr(lens, n).shape) for n in _LENS_TENSORS), AOT_CHUNK,
            near_only_surfaces(lens), "kernel", torch.__version__, _sources())


def describe(lens: Lens, upto: int | None = None, record: bool = False) -> str:
    """A short description of the structure, for messages."""
    kinds = "/".join(sorted({s.kind for s in lens.shapes}))
    return (f"{len(lens.shapes)} surfaces ({kinds}), {lens.index.shape[-1]} wavelength(s), "
            f"{str(lens.dtype).removeprefix('torch.')}{', recorded' if record else ''}"
            f"{'' if upto is None else f', up to surface {upto}'}")


def package_path(lens: Lens, *, upto: int | None = None, record: bool = False,
                 newton_iterations: int = NEWTON_ITERATIONS) -> Path:
    """Where the package of this lens structure lives (whether or not it exists)."""
    key = hashlib.sha256(repr(_structure(lens, upto, record, newton_iterations)).encode()).hexdigest()[:24]
    return package_dir() / f"trace_{key}.pt2"


def has_package(lens: Lens, *, upto: int | None = None, record: bool = False,
                newton_iterations: int = NEWTON_ITERATIONS) -> bool:
    """Whether a package for this structure is on disk (a ``stat``, nothing loaded)."""
    if not supported(lens):
        return False
    path = package_path(lens, upto=upto, record=record, newton_iterations=newton_iterations)
    return path not in _broken and path.exists()


def unload_package(path: Path) -> None:
    """Drop the loaded runner of ``path`` (a package rebuilt or found broken)."""
    _loaded.pop(path, None)


def mark_broken(lens: Lens, *, upto: int | None = None, record: bool = False,
                newton_iterations: int = NEWTON_ITERATIONS) -> None:
    """Stop using this structure's package in this process (it failed to load or run)."""
    path = package_path(lens, upto=upto, record=record, newton_iterations=newton_iterations)
    _broken.add(path)
    unload_package(path)


def is_loaded(lens: Lens, *, upto: int | None = None, record: bool = False,
              newton_iterations: int = NEWTON_ITERATIONS) -> bool:
    """Whether this structure's package is loaded in this process already (its next call costs no loading)."""
    return package_path(lens, upto=upto, record=record, newton_iterations=newton_iterations) in _loaded


class _Flat(torch.nn.Module):
    """The trace as a function of flat tensors (what is exported): lens tensors, rays, then the n/n' table.

    It is ``trace.trace_kernel``, the formulation ``accel.compiled`` compiles in process (the refraction
    table passed in, no far root on quadrics with 1 + κ ≥ 0, component-major outputs), not the reference
    ``trace``: exported from the reference, the package ran at a third of the in-process compiled
    trace's speed (issue 29; benchmarks/README.md, trace backends)."""

    def __init__(self, lens: Lens, upto: int | None, record: bool, newton_iterations: int) -> None:
        super().__init__()
        self.shapes, self.stop = lens.shapes, lens.stop
        self.upto, self.record, self.newton = upto, record, newton_iterations
        self.options = KernelOptions(near_only=near_only_surfaces(lens))

    def forward(self, *tensors: Tensor) -> tuple[Tensor, ...]:
        fields = dict(zip(_LENS_TENSORS, tensors[:len(_LENS_TENSORS)], strict=True))
        lens = Lens(shapes=self.shapes, stop=self.stop, **fields)
        pos, dir, wavelength, ratio = tensors[len(_LENS_TENSORS):]
        r = trace_kernel(lens, Rays(pos, dir, wavelength), self.options, upto=self.upto, record=self.record,
                         newton_iterations=self.newton, ratio=ratio)
        return _flatten(r)


def _flatten(r: RayTrace) -> tuple[Tensor, ...]:
    out = [r.pos, r.dir, r.status, r.backtrack] + ([] if r.failed_at is None else [r.failed_at])
    for h in r.hits:
        out += [h.pos, h.dir_in, h.dir_out, h.normal, h.t, h.cos2_in, h.cos2_out]
    return tuple(out)


def _unflatten(out: list[Tensor], record: bool) -> RayTrace:
    pos, dir, status, backtrack = out[:4]
    failed_at = out[4] if record else None
    rest = out[5:] if record else out[4:]
    hits = tuple(SurfaceHit(*rest[i:i + 7]) for i in range(0, len(rest), 7))
    return RayTrace(pos=pos, dir=dir, status=status, backtrack=backtrack, hits=hits, failed_at=failed_at)


def _example(lens: Lens) -> tuple[Tensor, ...]:
    """Inputs of the exported shape and layout: the lens tensors (contiguous), ``AOT_CHUNK`` axial rays,
    positions and directions component-major ((n, 3) views of (3, n) planes), wavelength indices int64,
    and the (S, W) n/n' table."""
    n = AOT_CHUNK
    pos = torch.zeros(3, n, dtype=lens.dtype, device=lens.device)
    dir = torch.zeros(3, n, dtype=lens.dtype, device=lens.device)
    dir[2] = 1.0
    wavelength = torch.arange(n, device=lens.device) % lens.index.shape[-1]
    return (*(getattr(lens, name).detach().contiguous() for name in _LENS_TENSORS), pos.t(), dir.t(), wavelength,
            index_ratio(lens).detach().contiguous())


def build_package(lens: Lens, *, upto: int | None = None, record: bool = False,
                  newton_iterations: int = NEWTON_ITERATIONS) -> float:
    """Export and AOT-compile the trace of this lens structure into its package; the seconds it took.
    Raises when the structure is not ``supported`` or compilation fails (nothing is left on disk then)."""
    if not supported(lens):
        raise ValueError("AOT trace packages need a lens without placement, on the CPU")
    import torch._inductor  # noqa: F401  (heavy: only when building)

    path = package_path(lens, upto=upto, record=record, newton_iterations=newton_iterations)
    path.parent.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)  # torch-internal deprecations printed by export
        program = torch.export.export(_Flat(lens, upto, record, newton_iterations), _example(lens), strict=False)
        with atomic_path(path) as tmp:
            torch._inductor.aoti_compile_and_package(program, package_path=str(tmp),
                                                     inductor_configs={"max_fusion_size": _MAX_FUSION_SIZE})
    unload_package(path)
    _broken.discard(path)
    return time.perf_counter() - start


def load_package(path: Path) -> Any:
    """The loaded runner of the package at ``path`` (loaded once per process; ``.run(list of tensors)``).
    Also used for the LM Jacobian's packages (``accel.jacobian``)."""
    runner = _loaded.get(path)
    if runner is None:
        # (package, model name, run single-threaded, runners, device index): the C++ loader, no Python
        # Inductor import (torch._inductor.aoti_load_package costs seconds of imports per process).
        runner = _loaded[path] = torch._C._aoti.AOTIModelPackageLoader(str(path), "model", False, 1, -1)
    return runner


def aot_trace(lens: Lens, rays: Rays, *, upto: int | None = None, record: bool = False,
              newton_iterations: int = NEWTON_ITERATIONS) -> RayTrace:
    """``trace(lens, rays, ...)`` through this structure's package, for exactly ``AOT_CHUNK`` rays (a (n, 3)
    batch; the backend chunks and pads). The package must exist (``has_package``); no autograd."""
    path = package_path(lens, upto=upto, record=record, newton_iterations=newton_iterations)
    n = AOT_CHUNK
    pos, dir = torch.broadcast_tensors(rays.pos, rays.dir)
    if pos.shape != (n, 3):
        raise ValueError(f"aot_trace takes exactly {n} rays, got batch {tuple(pos.shape[:-1])}")
    # The compiled code assumes the exported layout: component-major rays, contiguous lens tensors.
    pos, dir = (v if v.movedim(-1, 0).is_contiguous() else v.movedim(-1, 0).contiguous().movedim(0, -1)
                for v in (pos, dir))
    args = [getattr(lens, name).detach().contiguous() for name in _LENS_TENSORS]
    args += [pos, dir, torch.broadcast_to(rays.wavelength, (n,)).to(torch.long).contiguous(),
             index_ratio(lens).detach().contiguous()]
    return _unflatten(load_package(path).run(args), record)
