"""The LM Jacobian compiled: the forward-mode Jacobian of a problem's residual function captured once
as one graph of aten operations and compiled by Inductor (DESIGN.md "Speed").

The eager ``Problem.jacobian`` (``torch.func.jacfwd``) stays the reference. In eager mode one
Jacobian costs ~20–30 residual evaluations although its arithmetic is only ~N + 1 of them: the
optimization rays are few (hundreds to a few thousand), so every one of the thousands of small
vmapped dual-number operations costs its Python and dispatch overhead. Here ``make_fx`` runs
``jacfwd`` once on real tensors and records the aten graph (vmap and the jvp rules decomposed into
plain batched operations, ~10⁴ nodes); Inductor compiles that graph into a few fused C++ loops. The
graph goes to Inductor as it is (``torch._inductor.compile``): ``torch.compile`` of the GraphModule
would first re-trace its generated Python with Dynamo, which cost the Cooke graph more than twice the
CPU time of the direct compile (benchmarks/RESULTS.md, issue 14 session 21).

Safety of the capture: ``make_fx`` refuses data-dependent Python control flow on the traced values
(``.item()``, ``bool(tensor)`` of anything that depends on θ raises), so a residual function that
branches on θ cannot be baked into the graph silently; quantities that do not depend on θ (the
pupil sample, weights, the lens structure) become constants of the graph, which is built per
``Problem``. The first call compares the compiled Jacobian with the eager one (relative 1e-9 of
the largest entry); on any failure the eager Jacobian is used from then on and a warning is logged.

Cost: the capture and compile take minutes of CPU per problem on the 2-core development machine (Cooke:
~2 minutes of CPU, direct compile); a second process with the same cache directory was seen lowering
the graph again (no hit in Inductor's graph cache); it pays on long runs, not on a 20-step test, and
not on one C-mount design, whose whole eager run (73–85 s of CPU) costs less than one compile of the
smaller Cooke graph (114 s), and which would compile two graphs (glass binding builds a second problem).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import TYPE_CHECKING

import torch
from torch import Tensor

if TYPE_CHECKING:
    from lensopt.optim.problem import Problem

__all__ = ["CompiledJacobian", "capture_jacobian"]

logger = logging.getLogger(__name__)

BACKENDS = ("inductor", "dynamo", "graph")

CHECK_RTOL = 1e-9
"""Agreement asked of the compiled Jacobian with the eager one at the first call (max |ΔJ| / max |J|)."""


def capture_jacobian(residuals: Callable[[Tensor], Tensor], theta: Tensor) -> torch.fx.GraphModule:
    """The aten graph of θ ↦ (J, ℓ) = (jacfwd(residuals)(θ), residuals(θ)), traced at ``theta``.

    Raises a RuntimeError when ``residuals`` branches on values that depend on θ.
    """
    from torch.fx.experimental.proxy_tensor import make_fx

    def both(t: Tensor) -> tuple[Tensor, Tensor]:
        r = residuals(t)
        return r, r

    return make_fx(torch.func.jacfwd(both, has_aux=True), tracing_mode="real")(theta)


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
        problem: the optimization problem (its residual function is captured at the first call).
        backend: ``inductor`` (the captured aten graph handed to Inductor directly: compiled C++/Triton
            kernels), ``dynamo`` (the same graph through ``torch.compile``, which first re-traces its
            Python code with Dynamo: more than twice the compile time; kept for comparison)
            or ``graph`` (the captured graph run as Python, no compiler: for tests of the capture).
        check: compare the first compiled Jacobian with the eager one.
    """

    def __init__(self, problem: Problem, *, backend: str = "inductor", check: bool = True) -> None:
        if backend not in BACKENDS:
            raise ValueError(f"backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
        self.problem = problem
        self.backend = backend
        self.check = check
        self._fn: Callable[[Tensor], tuple[Tensor, Tensor]] | None = None
        self.failed: str = ""

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

    def _build(self, theta: Tensor) -> None:
        try:
            gm = capture_jacobian(self.problem.residuals, theta)
            fn = _compile(gm, theta, self.backend)
            J, r = fn(theta)
            if self.check:
                J0, r0 = self.problem.jacobian(theta)
                scale = float(J0.abs().max()) or 1.0
                dj = float((J - J0).abs().max()) / scale
                dr = float((r - r0).abs().max()) / (float(r0.abs().max()) or 1.0)
                if not (dj <= CHECK_RTOL and dr <= CHECK_RTOL):
                    raise RuntimeError(f"compiled Jacobian differs from eager: {dj:.1e} (J), {dr:.1e} (ℓ)")
        except Exception as err:  # noqa: BLE001 - any capture/compile failure falls back to eager
            self.failed = f"{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}"
            logger.warning("compiled Jacobian unavailable (%s); using the eager Jacobian", self.failed)
            return
        self._fn = fn
