"""A tolerance ``Job`` from a traced lens, its system and media, and ``[tolerance]``-like settings (any
object with the ``ToleranceSpec`` attributes; this layer does not import the spec package —
``lensopt.design.tolerance`` ties a built spec to it and writes trials back as specs).

``tolerances_for`` expands the settings' items (kind, limit, surfaces or elements, distribution)
against the lens: default targets are every surface a kind applies to.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch

from lensopt.engine import Engine
from lensopt.errors import LensoptError
from lensopt.materials import Material
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.lens import Lens, System
from lensopt.optics.sampling import PupilSampling
from lensopt.tolerance.evaluate import EvalSetup
from lensopt.tolerance.job import Job
from lensopt.tolerance.model import KINDS, Tolerance, elements_of, glass_gaps, nominal_params, s62_profile

__all__ = ["tolerances_for", "make_job", "semi_apertures", "d_line_indices", "field_points"]

D_LINE_UM = 0.5875618


def tolerances_for(lens: Lens, settings: Any) -> list[Tolerance]:
    """Expand ``settings`` (a ``ToleranceSpec``-like object: profile, items, distribution) for this lens.

    Raises ``LensoptError`` naming ``tolerance.items[i]…`` for targets that do not exist.
    """
    glass = glass_gaps(lens)
    elements = elements_of(lens)
    num = lens.num_surfaces
    tols: list[Tolerance] = []
    if settings.profile == "s6.2":
        tols += s62_profile(lens, distribution=settings.distribution)
    for i, item in enumerate(settings.items):
        path = f"tolerance.items[{i}]"
        dist = item.distribution or settings.distribution
        kind = item.kind
        if kind.startswith("element_"):
            targets = [tuple(e) for e in item.elements] if item.elements is not None else elements
            for e in targets:
                if e not in elements:
                    raise LensoptError(f"not an element of this lens (elements: {elements})", path=f"{path}.elements",
                                       got=list(e))
                tols.append(Tolerance(kind, e, item.limit, dist, f"{_short(kind)} e{e[0]}-{e[1]}"))
            continue
        if item.surfaces is not None:
            for s in item.surfaces:
                if not 0 <= s < num:
                    raise LensoptError(f"surface index must be in 0..{num - 1}", path=f"{path}.surfaces", got=s)
            targets = list(item.surfaces)
        elif kind in ("curvature", "radius", "fringes"):
            targets = [s for s in range(num) if float(lens.curvature[s]) != 0.0]
        elif kind == "thickness":
            targets = [s for s in range(num - 1) if glass[s]]
        elif kind == "airspace":
            targets = [s for s in range(num - 1) if not glass[s]]
        elif kind in ("index", "abbe"):
            targets = [s for s in range(num) if glass[s]]
        else:
            targets = list(range(num))
        for s in targets:
            if kind in ("index", "abbe") and not glass[s]:
                raise LensoptError("the medium after this surface is air", path=f"{path}.surfaces", got=s)
            core = "thickness" if kind == "airspace" else kind
            tols.append(Tolerance(core, s, item.limit, dist, f"{_short(kind)} s{s}"))
    if not tols:
        raise LensoptError("no tolerance applies to this lens", path="tolerance")
    return tols


def _short(kind: str) -> str:
    return {"curvature": "CUR", "radius": "RAD", "fringes": "FRN", "thickness": "THI", "airspace": "AIR",
            "index": "IND", "abbe": "ABB", "decenter_x": "DCX", "decenter_y": "DCY", "tilt_x": "TLX",
            "tilt_y": "TLY", "element_decenter_x": "EDX", "element_decenter_y": "EDY", "element_tilt_x": "ETX",
            "element_tilt_y": "ETY"}.get(kind, kind)


def d_line_indices(media: Sequence[Material], *, dtype: torch.dtype = torch.float64) -> torch.Tensor:
    """(S+1,) index of every medium at the d line (587.56 nm)."""
    wl = torch.tensor([D_LINE_UM], dtype=dtype)
    return torch.stack([m.index(wl)[0] for m in media]).to(dtype)


def semi_apertures(lens: Lens, system: System, *, engine: Engine | None = None) -> torch.Tensor:
    """(S,) semi-aperture per surface: the lens's semi_diameter, else the largest height of the nominal
    rays (full pupil edge, every field and wavelength)."""
    pupil = PupilSampling.parse("rings:4:nojitter").points(dtype=lens.dtype, engine=engine)
    b = trace_bundle(lens, system, pupil, half_pupil=True, record=True, aim="none", engine=engine)
    out = []
    for s, hit in enumerate(b.result.hits):
        r = torch.linalg.vector_norm(hit.pos[..., :2], dim=-1)
        traced = float(torch.where(b.result.valid, r, 0.0).max())
        given = float(lens.semi_diameter[s])
        out.append(given if given > 0 else max(traced, 1e-6))
    return torch.tensor(out, dtype=lens.dtype)


def field_points(system: System, fields: Any) -> tuple[list[tuple[float, float]], tuple[float, ...]] | None:
    """Two-dimensional relative fields (x, y) and their ESR weights for ``fields`` (``ToleranceSpec.fields``):
    None for ``y`` (the system's +y fields); ``xy``: every system field h at (0, h), (0, −h), (h, 0),
    (−h, 0) (once for h = 0), each with a quarter of h's weight (so a rotationally symmetric lens keeps
    its +y ESR); a list: those points, equal weights."""
    if fields == "y":
        return None
    if fields == "xy":
        given = system.field_weights or (1.0,) * len(system.rel_field)
        pts, weights = [], []
        for h, w in zip(system.rel_field, given, strict=True):
            here = [(0.0, h)] if h == 0 else [(0.0, h), (0.0, -h), (h, 0.0), (-h, 0.0)]
            pts += here
            weights += [w / len(here)] * len(here)
        return pts, tuple(weights)
    pts = [(float(x), float(y)) for x, y in fields]
    return pts, (1.0,) * len(pts)


def make_job(lens: Lens, system: System, media: Sequence[Material], settings: Any, *,
             lm_vars: tuple[tuple[str, int], ...] = (), tols: list[Tolerance] | None = None,
             engine: Engine | None = None) -> Job:
    """The ``Job`` of a lens and its tolerance settings (``ToleranceSpec``-like); ``lm_vars``: the LM
    compensators (``curvature``/``thickness``, surface) of ``compensator = "lm"``; ``engine``: trace backend
    and memory budget of every trial."""
    tols = tolerances_for(lens, settings) if tols is None else tols
    placed = lens.placement is not None or any(t.kind not in ("curvature", "radius", "fringes", "thickness",
                                                              "index", "abbe") for t in tols)
    for t in tols:
        if t.kind not in KINDS:
            raise LensoptError(f"unknown kind; one of {', '.join(KINDS)}", path="tolerance.items.kind", got=t.kind)
    placement = nominal_params(lens)[1] if placed else None
    sampling = PupilSampling.parse(settings.sampling, seed=settings.seed, path="tolerance.sampling")
    pupil = sampling.points(dtype=lens.dtype, engine=engine)
    half = sampling.half
    fields_2d = field_points(system, getattr(settings, "fields", "y"))
    field_xy = field_w = None
    if fields_2d is not None:
        field_xy = torch.tensor(fields_2d[0], dtype=lens.dtype)
        field_w = fields_2d[1]
        if half:  # x fields break the mirror symmetry x → −x: the mirrored half too
            pupil = torch.cat([pupil, pupil * torch.tensor([-1.0, 1.0], dtype=pupil.dtype)], -2)
            half = False
    lm_vars = tuple(lm_vars) if settings.compensator == "lm" else ()
    if settings.compensator == "lm" and not lm_vars:
        raise LensoptError("compensator = \"lm\" needs spec variables (vary = [\"radius\"] or [\"thickness\"] "
                           "on some surface other than the last)", path="tolerance.compensator", got="lm")
    setup = EvalSetup(lens, system, placement, pupil, half,
                      compensate=settings.compensator, focus_range=settings.focus_range,
                      mtf_frequency=settings.mtf_frequency, lm_vars=lm_vars,
                      lm_steps=getattr(settings, "lm_steps", 5), field_xy=field_xy, field_weights=field_w,
                      aim=getattr(settings, "aim", "none"), engine=engine)
    return Job(setup, tuple(tols), d_line_indices(media, dtype=lens.dtype), semi_apertures(lens, system, engine=engine),
               settings.metric, settings.chunk)


