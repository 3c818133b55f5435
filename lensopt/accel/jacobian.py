"""The LM Jacobian compiled: the forward-mode Jacobian of a problem's residual function captured once
as one graph of aten operations and compiled by Inductor (DESIGN.md "Speed").

The eager ``Problem.jacobian`` (``torch.func.jacfwd``) stays the reference. In eager mode one
Jacobian costs ~20–30 residual evaluations although its arithmetic is only ~N + 1 of them: the
optimization rays are few (hundreds to a few thousand), so every one of the thousands of small
vmapped dual-number operations costs its Python and dispatch overhead and writes its tangents to
memory. Here ``make_fx`` runs ``jacfwd`` once on real tensors and records the aten graph (vmap and the
jvp rules decomposed into plain batched operations, ~10⁴ nodes); Inductor compiles that graph into a few
fused C++ loops.

Backends:

- ``aot`` (the default on the CPU): the graph is exported and compiled by AOTInductor into a package
  (a ``.pt2`` zip holding a shared library) in ``accel.aot.package_dir()``, next to the trace packages,
  keyed by a digest of everything the residual function is built from (``problem_key``: the problem's
  setup — lens, system, media, variables, solves, settings —, its seed, the trace backend, the torch
  version and the source of the library). The first process builds it (capture + export + compile:
  1.5–3 minutes of CPU, the C++ compiler included, for the Cooke and C-mount problems on the 2-core
  development machine); every later process with the same problem loads it in milliseconds, with no
  capture and no compiler (benchmarks/README.md, optimize). A problem that cannot be keyed (an image
  objective, whose residual function changes with every batch; an object the digest does not know) is
  compiled in process (``inductor``).
- ``inductor``: the captured graph handed to Inductor in this process (``torch._inductor.compile``); paid
  by every process (a second process was seen lowering the graph again: no hit in Inductor's graph
  cache for graphs with tensor constants).
- ``dynamo``: ``torch.compile`` of the GraphModule, which first re-traces its 10⁴-line generated Python with
  Dynamo: more than twice the CPU time of ``inductor`` (git history of benchmarks/RESULTS.md).
- ``graph``: the captured graph run as Python, no compiler (for tests of the capture).

Safety of the capture: ``make_fx`` refuses data-dependent Python control flow on the traced values
(``.item()``, ``bool(tensor)`` of anything that depends on θ raises), so a residual function that
branches on θ cannot be baked into the graph silently; quantities that do not depend on θ (the
pupil sample, weights, the lens structure) become constants of the graph, which is therefore built per
problem. After a build or an in-process compile, the first call compares the compiled Jacobian and ℓ with
eager jacfwd's (relative 1e-9 of the largest entry); after a package is loaded, ℓ with one eager residual
evaluation (the Jacobian was checked when the package was built). On any failure the eager Jacobian is
used from then on and a warning is logged (a package that fails is not used again in the process; a build
that fails leaves ``jacobian_<key>.failed`` beside the packages, so that later processes go eager at once
instead of spending the build's minutes again — delete it to retry).
"""

from __future__ import annotations

import dataclasses
import enum
import hashlib
import logging
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor

from lensopt.accel import aot
from lensopt.files import atomic_path, write_text_atomic

Problem = Any
"""An ``optim.problem.Problem`` (the compiled Jacobian uses its residual function, Jacobian, evaluation,
setup, settings, seed, objective and engine; typed loosely so that this package sits below ``optim``)."""

__all__ = ["CompiledJacobian", "capture_jacobian", "problem_key", "package_path", "build_package"]

logger = logging.getLogger(__name__)

BACKENDS = ("aot", "inductor", "dynamo", "graph")

CHECK_RTOL = 1e-9
"""Agreement asked of the compiled Jacobian with the eager one at the first call (max |ΔJ| / max |J|)."""

_LIBRARY = Path(__file__).resolve().parents[1]
_library_digest: str | None = None
_broken: set[Path] = set()


def capture_jacobian(residuals: Callable[[Tensor], Tensor], theta: Tensor) -> torch.fx.GraphModule:
    """The aten graph of θ ↦ (J, ℓ) = (jacfwd(residuals)(θ), residuals(θ)), traced at ``theta``.

    Raises a RuntimeError when ``residuals`` branches on values that depend on θ.
    """
    from torch.fx.experimental.proxy_tensor import make_fx

    def both(t: Tensor) -> tuple[Tensor, Tensor]:
        r = residuals(t)
        return r, r

    return make_fx(torch.func.jacfwd(both, has_aux=True), tracing_mode="real")(theta)


# ------------------------------------------------------------------------------------------ package key

def _library() -> str:
    """Digest of the library's files (its Python sources and data, the command-line modules excepted):
    a changed residual function, trace or glass catalog never runs a stale package."""
    global _library_digest
    if _library_digest is None:
        h = hashlib.sha256()
        for f in sorted(_LIBRARY.rglob("*")):
            rel = f.relative_to(_LIBRARY).as_posix()
            if not f.is_file() or "__pycache__" in rel or rel.startswith("cli"):
                continue
            h.update(rel.encode() + b"\0" + f.read_bytes())
        _library_digest = h.hexdigest()
    return _library_digest


def _feed(h: Any, obj: Any, depth: int = 0) -> None:
    """Hash ``obj`` by value: plain values, tensors and arrays (dtype, shape and bytes), and containers and
    dataclasses of them. Anything else raises TypeError (it could hold state the digest would miss)."""
    if depth > 64:
        raise TypeError("nested too deeply to fingerprint")
    if obj is None or isinstance(obj, (bool, int, float, complex, str, bytes)):
        h.update(f"{type(obj).__name__}:{obj!r};".encode())
    elif isinstance(obj, enum.Enum):
        h.update(f"{type(obj).__qualname__}.{obj.name};".encode())
    elif isinstance(obj, Tensor):
        t = obj.detach().to("cpu").contiguous()
        h.update(f"tensor:{t.dtype}:{tuple(t.shape)}:{obj.device.type};".encode())
        h.update(t.view(torch.uint8).numpy().tobytes() if t.numel() else b"")
    elif isinstance(obj, np.ndarray):
        h.update(f"array:{obj.dtype}:{obj.shape};".encode())
        h.update(np.ascontiguousarray(obj).tobytes())
    elif isinstance(obj, (torch.dtype, torch.device, Path)):
        h.update(f"{type(obj).__name__}:{obj};".encode())
    elif dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        h.update(f"{type(obj).__module__}.{type(obj).__qualname__}(".encode())
        for f in dataclasses.fields(obj):
            h.update(f.name.encode() + b"=")
            _feed(h, getattr(obj, f.name), depth + 1)
        h.update(b")")
    elif isinstance(obj, (tuple, list, frozenset, set)):
        items = sorted(obj, key=repr) if isinstance(obj, (set, frozenset)) else obj
        h.update(f"{type(obj).__name__}[{len(items)}](".encode())
        for item in items:
            _feed(h, item, depth + 1)
        h.update(b")")
    elif isinstance(obj, dict):
        h.update(f"dict[{len(obj)}](".encode())
        for k in sorted(obj, key=repr):
            _feed(h, k, depth + 1)
            _feed(h, obj[k], depth + 1)
        h.update(b")")
    else:
        raise TypeError(f"cannot fingerprint a {type(obj).__module__}.{type(obj).__qualname__}")


def problem_key(problem: Problem) -> str | None:
    """Digest of everything ``problem``'s residual function is built from: its setup (lens, system, media,
    variables, solves, settings, defocus), its current settings, seed and objective, the trace backend,
    dtype, device, the torch version and the library's files. None when the problem cannot be keyed: an
    image objective (its residual function changes with every batch) or a setup holding an object the
    digest does not know."""
    if getattr(problem, "image", None) is not None:
        return None
    h = hashlib.sha256()
    try:
        # Under a forward-mode transform ``auto`` traces eagerly (accel.dispatch): only ``compiled`` differs.
        backend = "compiled" if problem.engine.trace_backend == "compiled" else "eager"
        _feed(h, (problem.setup, problem.opt, problem.seed, problem.objective, backend,
                  str(problem.dtype), problem.device.type, torch.__version__, _library()))
    except (TypeError, AttributeError) as err:
        logger.info("compiled Jacobian: no package key (%s)", err)
        return None
    return h.hexdigest()[:32]


def package_path(key: str) -> Path:
    """Where the Jacobian package of the problem with digest ``key`` lives (whether or not it exists)."""
    return aot.package_dir() / f"jacobian_{key}.pt2"


def build_package(problem: Problem, theta: Tensor, key: str | None = None) -> tuple[Path, float]:
    """Capture θ ↦ (J, ℓ) of ``problem`` at ``theta``, export it and compile it with AOTInductor into its
    package (written to a temporary file and renamed: never half-written). Returns the package path and
    the seconds it took. Raises when the problem cannot be keyed or the capture or compile fails."""
    key = key or problem_key(problem)
    if key is None:
        raise ValueError("this problem cannot be keyed (an image objective, or an unknown object in its setup)")
    import torch._inductor  # noqa: F401  (heavy: only when building)

    path = package_path(key)
    path.parent.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    gm = capture_jacobian(problem.residuals, theta)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # torch-internal deprecation notices printed by export
        program = torch.export.export(gm, (theta,), strict=False)
        with atomic_path(path) as tmp:
            torch._inductor.aoti_compile_and_package(program, package_path=str(tmp))
    aot.unload_package(path)
    _broken.discard(path)
    return path, time.perf_counter() - start


def _reason(err: Exception) -> str:
    return f"{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}"


def _remember_failed_build(marker: Path, err: Exception) -> None:
    """Leave ``jacobian_<key>.failed`` (the reason) beside the packages: later processes go eager at once."""
    try:
        write_text_atomic(marker, _reason(err) + "\n")
    except OSError:
        pass


def _load(path: Path) -> Callable[[Tensor], tuple[Tensor, Tensor]]:
    runner = aot.load_package(path)

    def call(t: Tensor) -> tuple[Tensor, Tensor]:
        J, r = runner.run([t.contiguous()])
        return J, r

    return call


# --------------------------------------------------------------------------------------------- compile

def _compile(gm: torch.fx.GraphModule, theta: Tensor, backend: str) -> Callable[[Tensor], tuple[Tensor, Tensor]]:
    """The captured graph as a callable: compiled by Inductor (``inductor``: the aten graph as it is,
    no Dynamo re-trace of its generated Python), through ``torch.compile`` (``dynamo``), or as is."""
    if backend == "graph":
        return gm
    if backend == "dynamo":
        return torch.compile(gm, fullgraph=True, dynamic=False)
    from torch._inductor import compile as inductor_compile

    compiled = inductor_compile(gm, [theta])

    def call(t: Tensor) -> tuple[Tensor, Tensor]:
        J, r = compiled(t)
        return J, r

    return call


class CompiledJacobian:
    """θ ↦ (J (M, N), ℓ (M,)) of ``problem`` through one compiled graph; a drop-in for
    ``problem.jacobian`` (same values to ~1e-14 relative).

    Args:
        problem: the optimization problem (its residual function is captured at the first call, or its
            package loaded).
        backend: ``aot`` (default: this problem's AOTInductor package, built by the first process that
            needs it and loaded by the later ones; on devices other than the CPU, and for problems that
            cannot be keyed, ``inductor``), ``inductor``, ``dynamo`` or ``graph`` (see the module text).
        check: compare the first compiled Jacobian with the eager one.

    Attributes:
        failed: why the eager Jacobian is used ("" while the compiled one is).
        source: where the compiled Jacobian came from: ``package loaded``, ``package built``,
            ``compiled in process``, or "" before the first call.
        build_s: seconds spent capturing and compiling (0 when a package was loaded).
    """

    def __init__(self, problem: Problem, *, backend: str = "aot", check: bool = True) -> None:
        if backend not in BACKENDS:
            raise ValueError(f"backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
        self.problem = problem
        self.backend = backend
        self.check = check
        self._fn: Callable[[Tensor], tuple[Tensor, Tensor]] | None = None
        self.failed: str = ""
        self.source: str = ""
        self.build_s: float = 0.0

    @property
    def compiled(self) -> bool:
        """Whether the compiled graph is in use (False before the first call and after a failure)."""
        return self._fn is not None

    def __call__(self, theta: Tensor) -> tuple[Tensor, Tensor]:
        if self._fn is None and not self.failed:
            self._build(theta)
        if self._fn is None:
            return self.problem.jacobian(theta)
        J, r = self._fn(theta)
        return J, r

    def _package_key(self, theta: Tensor) -> str | None:
        if self.backend != "aot" or theta.device.type != "cpu":
            return None
        return problem_key(self.problem)

    def _build(self, theta: Tensor) -> None:
        key = self._package_key(theta)
        path = package_path(key) if key is not None else None
        if path is not None and path in _broken:
            self.failed = f"its package {path} failed earlier in this process"
            return
        marker = path.with_suffix(".failed") if path is not None else None
        if marker is not None and marker.exists() and not path.exists():
            reason = marker.read_text(errors="replace").strip()
            self.failed = f"building its package failed on this machine before ({reason}); delete {marker} to retry"
            logger.warning("compiled Jacobian unavailable (%s); using the eager Jacobian", self.failed)
            return
        start = time.perf_counter()
        try:
            if path is not None and path.exists():
                fn, self.source = _load(path), "package loaded"
            elif path is not None:
                try:
                    build_package(self.problem, theta, key)
                except Exception as err:  # a build that failed would fail again: remember it
                    _remember_failed_build(marker, err)
                    raise
                fn, self.source = _load(path), "package built"
            else:
                gm = capture_jacobian(self.problem.residuals, theta)
                backend = "inductor" if self.backend == "aot" else self.backend
                fn, self.source = _compile(gm, theta, backend), "compiled in process"
            J, r = fn(theta)
            if self.check and self.source == "package loaded":
                # The Jacobian was checked against eager jacfwd when the package was built; its key holds
                # everything the function is made of. ℓ against one eager evaluation catches a package
                # that is not this problem's (constants differ) at the cost of a residual evaluation.
                r0 = self.problem.residuals(theta)
                dr = float((r - r0).abs().max()) / (float(r0.abs().max()) or 1.0)
                if not dr <= CHECK_RTOL:
                    raise RuntimeError(f"the package's residuals differ from eager: {dr:.1e}")
            elif self.check:
                J0, r0 = self.problem.jacobian(theta)
                scale = float(J0.abs().max()) or 1.0
                dj = float((J - J0).abs().max()) / scale
                dr = float((r - r0).abs().max()) / (float(r0.abs().max()) or 1.0)
                if not (dj <= CHECK_RTOL and dr <= CHECK_RTOL):
                    raise RuntimeError(f"compiled Jacobian differs from eager: {dj:.1e} (J), {dr:.1e} (ℓ)")
        except Exception as err:  # noqa: BLE001 - any capture/compile/load failure falls back to eager
            if path is not None:
                _broken.add(path)
                aot.unload_package(path)
            self.failed = _reason(err)
            logger.warning("compiled Jacobian unavailable (%s); using the eager Jacobian", self.failed)
            return
        self.build_s = 0.0 if self.source == "package loaded" else time.perf_counter() - start
        self._fn = fn
