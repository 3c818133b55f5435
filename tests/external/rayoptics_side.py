"""rayoptics' half of the cross-check: read lensopt's exported .seq files with rayoptics (an independent
CODE V reader, BSD, by M. J. Hayford) and compute the same numbers. Runs in tests/external/.venv
(Python ≥ 3.12, ``pip install rayoptics``); needs neither torch nor lensopt.

Usage: ``python rayoptics_side.py lensopt.json rayoptics.json``

Every number is computed twice: "as read" (rayoptics unchanged) and "patched", with the fixes for
these rayoptics limitations, each applied only where it bites:

1. infinite object: rayoptics reads CODE V's infinite distance (1e10, and ``inf``) as a finite object
   1e10 mm away (``cmdproc.post_process_input``), which moves its paraxial image plane by EFL²/1e10
   and changes image heights and f-number apertures by ~(z_EP − z_F)/1e10 relative. Patched: the
   first-order data are recomputed with the object 1e15 mm away.
2. diffractive surfaces, paraxial: ``Surface.optical_power`` ignores the phase element, so EFL, BFL
   and image heights leave out the DOE. Patched: the DOE's paraxial power −2 m C1 λ/λ0 is added.
3. diffractive surfaces, HWL: ``SequentialModel.update_model`` resets every DOE's construction
   wavelength to the system's central wavelength. Patched: the HWL written in the file is restored.
4. diffractive surfaces, air → glass: ``DiffractiveElement.phase`` only refracts into the next medium
   when the incoming index is not 1, so a DOE on an air → glass surface skips the refraction.
   Patched: the refraction into the glass is applied after the diffraction.
5. image-height fields (``YIM``) with an ``SI`` defocus: rayoptics places the field's image height on
   the image plane without the defocus (it keeps ``SI``'s thickness apart as a focus shift), CODE V
   and lensopt on the image surface. Patched: the defocus is folded into the last thickness.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np
from rayoptics.codev import cmdproc
from rayoptics.elem import surface as rsurf
from rayoptics.oprops import doe
from rayoptics.raytr import raytrace as rt
from rayoptics.raytr.traceerror import TraceError

FAR_OBJECT = 1e15

_ORIGINAL_PHASE = doe.DiffractiveElement.phase
_ORIGINAL_POWER = rsurf.Surface.optical_power
_PATCH = {"on": False, "wvl": 550.0}


def _patched_phase(self, pt, in_dir, srf_nrml, ifc_cntxt):
    out_dir, dW = _ORIGINAL_PHASE(self, pt, in_dir, srf_nrml, ifc_cntxt)
    _, _, n_in, n_out, _ = ifc_cntxt
    if _PATCH["on"] and n_in == 1.0 and n_out != 1.0:  # limitation 4
        out_dir = rt.bend(out_dir, srf_nrml, 1.0, n_out)
    return out_dir, dW


def _patched_power(self):
    power = _ORIGINAL_POWER.fget(self)
    element = getattr(self, "phase_element", None)
    if _PATCH["on"] and isinstance(element, doe.DiffractiveElement) and element.coefficients:  # limitation 2
        lam0 = getattr(element, "file_hwl", element.ref_wl)
        power += -2.0 * element.order * element.coefficients[0] * _PATCH["wvl"] / lam0
    return power


doe.DiffractiveElement.phase = _patched_phase
rsurf.Surface.optical_power = property(_patched_power, _ORIGINAL_POWER.fset)


def _file_hwl(seq: str) -> dict[int, float]:
    """Construction wavelength (nm) per surface number, as written in the file."""
    out: dict[int, float] = {}
    surface = 0
    for line in Path(seq).read_text().splitlines():
        tokens = line.split("!")[0].split()
        if not tokens:
            continue
        if tokens[0].upper() == "S":
            surface += 1
        elif tokens[0].upper() == "HWL":
            out[surface] = float(tokens[1])
    return out


def _restore_hwl(opm: Any, hwl: dict[int, float]) -> None:
    for surface, wl in hwl.items():  # limitation 3
        element = opm["seq_model"].ifcs[surface].phase_element
        element.ref_wl = element.file_hwl = wl


def _first_order(opm: Any) -> dict[str, float]:
    fod = opm["analysis_results"]["parax_data"].fod
    return {"efl": float(fod.efl), "bfl": float(fod.bfl), "img_ht": float(fod.img_ht)}


def _trace(opm: Any, ref: dict[str, Any], hwl: dict[int, float]) -> tuple[float, int]:
    """Largest |intercept difference| (mm) over rays lensopt traced, and rays rayoptics failed.

    The rays start where lensopt's start, on rayoptics' object plane: for an infinite object that
    plane is moved to lensopt's start plane in front of the lens (the model is updated so that its
    coordinate transforms follow), since a start 1e10 mm away would cost 1e-6 mm of precision.
    """
    sm = opm["seq_model"]
    focus_shift = float(opm["optical_spec"]["focus"].focus_shift)
    sm.gaps[0].thi = ref["object_plane"]
    opm.update_model()
    if _PATCH["on"]:
        _restore_hwl(opm, hwl)
    worst, failed = 0.0, 0
    if True:
        start, direction, image, valid = (np.asarray(ref[k]) for k in ("start", "dir", "image", "valid"))
        for f in range(start.shape[0]):
            for w, wvl in enumerate(ref["wavelengths_nm"]):
                for p in range(start.shape[2]):
                    if not valid[f, w, p]:
                        continue
                    pt0 = start[f, w, p].copy()
                    pt0[2] = 0.0  # on the object plane (its local coordinates)
                    try:
                        ray, _, _ = rt.trace(sm, pt0, direction[f, w, p], wvl)
                    except (TraceError, ValueError):
                        failed += 1
                        continue
                    pt, d = np.asarray(ray[-1][0]), np.asarray(ray[-1][1])
                    pt = pt + d * (focus_shift / d[2])  # SI defocus
                    worst = max(worst, float(np.abs(pt[:2] - image[f, w, p][:2]).max()))
    return worst, failed


def compare(ref: dict[str, Any]) -> dict[str, Any]:
    """rayoptics' numbers for one exported lens, as read and patched."""
    hwl = _file_hwl(ref["seq"])
    out: dict[str, Any] = {"name": ref["name"]}
    for mode in ("as_read", "patched"):
        _PATCH["on"] = mode == "patched"
        opm, info = cmdproc.read_lens(Path(ref["seq"]))
        _PATCH["wvl"] = float(opm["optical_spec"]["wvls"].central_wvl)
        if _PATCH["on"] and hwl:
            _restore_hwl(opm, hwl)
            opm.update_model()
        focus = opm["optical_spec"]["focus"]
        if _PATCH["on"] and focus.focus_shift != 0 and opm["optical_spec"]["fov"].key[0] == "image":
            opm["seq_model"].gaps[-1].thi += focus.focus_shift  # limitation 5
            focus.focus_shift = 0.0
            opm.update_model()
        if _PATCH["on"] and ref["infinite_object"]:  # limitation 1
            opm["seq_model"].gaps[0].thi = FAR_OBJECT
            opm.update_model()
        data = _first_order(opm)
        data["ray_dev_mm"], data["ray_failed"] = _trace(opm, ref, hwl)
        data["glasses_not_found"] = sorted(info[1]) if info[1] else []
        out[mode] = data
    _PATCH["on"] = False
    # The same lens with catalog glass names (NBK7_SCHOTT, ...): which names rayoptics' own catalogs
    # (opticalglass's vendor spreadsheets) resolve, and how far their indices move the EFL.
    try:
        opm, info = cmdproc.read_lens(Path(ref["catalog_seq"]))
    except Exception as err:  # rayoptics' own failures on names it cannot resolve
        out["catalog_names"] = {"reader_error": f"{type(err).__name__}: {err}"}
        return out
    if hwl:
        _PATCH["on"] = True
        _restore_hwl(opm, hwl)
        opm.update_model()
        _PATCH["on"] = False
    out["catalog_names"] = {"glasses_not_found": sorted(info[1]) if info[1] else [],
                            "efl": _first_order(opm)["efl"]}
    return out


def main(argv: list[str]) -> None:
    refs = json.loads(Path(argv[1]).read_text())
    results = [compare(ref) for ref in refs]
    Path(argv[2]).write_text(json.dumps(results, indent=1))
    assert all(math.isfinite(r["as_read"]["efl"]) for r in results)


if __name__ == "__main__":
    main(sys.argv)
