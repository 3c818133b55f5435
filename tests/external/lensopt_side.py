"""lensopt's half of the rayoptics cross-check: export every lens of specs/ (and tests/interchange/data/) to CODE V
with a private catalog, and record lensopt's first-order data and real rays for comparison.

Run by ``check_rayoptics.py`` in the lensopt venv; ``rayoptics_side.py`` reads what this writes.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import torch

from lensopt.interchange.codev.write import write_codev
from lensopt.optics.bundle import trace_bundle
from lensopt.optics.paraxial import field_tangents, first_order, trace_paraxial
from lensopt.optics.sampling import PupilSampling
from lensopt.spec import build, load_spec
from lensopt.spec.models import DiffractiveSurface

ROOT = Path(__file__).resolve().parents[2]
#: Pupil samples per field and wavelength: rings:6 on both pupil halves (72 rays).
PUPIL = "rings:6:nojitter"


def lens_paths() -> list[Path]:
    """Every lens of specs/ (whatever other engineers add) and the CODE V test lenses."""
    return sorted((ROOT / "specs").glob("*.toml")) + sorted((ROOT / "tests" / "interchange" / "data").glob("*.toml"))


def _image_height_at_paraxial_image(model: Any, fo: Any) -> float:
    """Chief-ray height of the largest field on the paraxial image plane (the definition of CODE V's
    "PARAXIAL IMAGE HT" and rayoptics' ``img_ht``; lensopt's own is on the image surface)."""
    lens, system = model.lens, model.system
    w = system.reference
    n = lens.index[:, w]
    one = torch.ones((), dtype=lens.dtype)
    top = max(system.rel_field)
    tan = field_tangents(lens, system, top * one)
    y_c, om_c = trace_paraxial(lens, w, -tan * fo.entrance_pupil_z, n[0] * tan)
    h = fo.epd / 2
    if system.object_distance is None:
        y_m, om_m = trace_paraxial(lens, w, h, 0.0 * one)
    else:
        u0 = h / (fo.entrance_pupil_z + system.object_distance)
        y_m, om_m = trace_paraxial(lens, w, h - u0 * fo.entrance_pupil_z, n[0] * u0)
    shift = -y_m[-1] / (om_m[-1] / n[-1])  # image surface -> paraxial image plane
    return float(y_c[-1] + om_c[-1] / n[-1] * shift)


def reference(path: Path, out_dir: Path) -> dict[str, Any]:
    """Export ``path`` to ``out_dir`` and return lensopt's numbers for it."""
    spec = load_spec(path)
    seq = out_dir / f"{path.stem}.seq"
    write_codev(spec, seq, private_catalog=True)
    catalog_seq = out_dir / f"{path.stem}_catalog.seq"
    write_codev(spec, catalog_seq)
    model = build(spec)
    lens, system = model.lens, model.system
    fo = first_order(lens, system)
    pts = PupilSampling.parse(PUPIL).points(dtype=torch.float64)
    pts = torch.cat([pts, pts * torch.tensor([-1.0, 1.0], dtype=torch.float64)])
    bundle = trace_bundle(lens, system, pts)
    pos, d = bundle.rays.pos, bundle.rays.dir
    if system.object_distance is None:
        # Start the rays on a plane in front of the lens (rayoptics starts on its object plane, which
        # the script moves there: the real 1e10 mm would cost 1e-6 mm of precision).
        plane = 100.0 + 2.0 * abs(float(fo.entrance_pupil_z))
        s = (-plane - pos[..., 2]) / d[..., 2]
        pos = pos + s.unsqueeze(-1) * d
    else:
        plane = system.object_distance
    doe = [i for i, s in enumerate(spec.surfaces) if isinstance(s, DiffractiveSurface)]
    media = lens.index[:, system.reference].tolist()
    return {
        "name": path.stem,
        "spec": str(path.relative_to(ROOT)),
        "seq": str(seq),
        "catalog_seq": str(catalog_seq),
        "infinite_object": system.object_distance is None,
        "image_height_field_with_defocus": system.field_type == "image_height" and spec.image.defocus != 0,
        "diffractive_surfaces": [i + 1 for i in doe],
        "air_to_glass_doe": [i + 1 for i in doe if media[i] == 1.0 and media[i + 1] != 1.0],
        "hwl_not_reference": [i + 1 for i in doe if spec.surfaces[i].design_wavelength_nm
                              != spec.spectrum.wavelengths_nm[spec.spectrum.reference_index]],
        "efl": float(fo.efl),
        "bfl": float(fo.bfl),
        "img_ht": _image_height_at_paraxial_image(model, fo),
        "object_plane": plane,
        "wavelengths_nm": list(spec.spectrum.wavelengths_nm),
        "start": pos.tolist(),
        "dir": d.tolist(),
        "image": bundle.result.pos.tolist(),
        "valid": bundle.result.valid.tolist(),
        "rays": int(bundle.result.valid.numel()),
    }


def write_references(out_dir: Path) -> Path:
    """Export every lens and write ``lensopt.json`` with the references; returns its path."""
    out_dir.mkdir(parents=True, exist_ok=True)
    refs = [reference(p, out_dir) for p in lens_paths()]
    target = out_dir / "lensopt.json"
    target.write_text(json.dumps(refs, allow_nan=False))
    return target


if __name__ == "__main__":  # pragma: no cover
    print(write_references(ROOT / "out" / "external"))
