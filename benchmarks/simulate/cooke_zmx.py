"""Write specs/cooke_triplet.toml as a Zemax .zmx file that DeepLens's reader accepts (STANDARD surfaces,
ENPD, YFLN, catalog glasses, clear semi-diameters from lensopt's traced rays, image DIAM = sensor half
diagonal). Glasses: DeepLens resolves SK16 and F2 in its own catalogs."""

from __future__ import annotations

import math
import sys
from pathlib import Path

from lensopt.analysis.report import auto_semi_diameters
from lensopt.spec import build, load_spec

ROOT = Path(__file__).resolve().parents[2]


def cooke_zmx() -> str:
    model = build(load_spec(ROOT / "specs" / "cooke_triplet.toml"))
    spec = model.spec
    sd = auto_semi_diameters(model)
    lines = ["VERS 190513 80 123457", "MODE SEQ", "UNIT MM X W X CM MR CPMM", f"ENPD {spec.system.aperture.epd}",
             f"YFLN 0.0 {0.7 * spec.system.field.hfov_deg} {spec.system.field.hfov_deg}",
             "SURF 0", "  TYPE STANDARD", "  CURV 0.0", "  DISZ INFINITY"]
    for i, s in enumerate(spec.surfaces, start=1):
        lines += [f"SURF {i}", "  TYPE STANDARD", f"  CURV {1.0 / s.radius:.12g}", f"  DISZ {s.thickness:.12g}"]
        if not s.is_air:
            lines.append(f"  GLAS {s.material} 0 0 1.5 50")
        lines.append(f"  DIAM {1.02 * sd[i - 1]:.6g}")
        if s.stop:
            lines.append("  STOP")
    half_diag = 0.5 * 7.2e-3 * math.hypot(4000, 3000)
    lines += [f"SURF {len(spec.surfaces) + 1}", "  TYPE STANDARD", "  CURV 0.0", f"  DIAM {half_diag:.6g}"]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    Path(sys.argv[1]).write_text(cooke_zmx())
