"""The eager trace of this checkout against another checkout's, bit for bit (issue 14): six shipped
specs, 150,000 rays each over 1.3× the field and 1.2× the pupil (so rays miss, clip, hit TIR and fail
Newton), with and without ``record``, under ``torch.no_grad`` (the chunked path) and with autograd
on (the one-pass path). Every output tensor must be ``torch.equal``.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/trace_before_after.py --before /path/to/old/checkout
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import torch
from trace_speed import import_before

from lensopt.optics.paraxial import field_tangents, first_order
from lensopt.optics.sampling import launch
from lensopt.optics.trace import trace
from lensopt.spec import build, load_spec

SPECS = Path(__file__).resolve().parents[1] / "specs"
NAMES = ("cooke_triplet", "cmount_4p", "hybrid_asphere", "telephoto_plastic", "wide_angle_laikin", "asphere_singlet")


def outputs(r) -> list[torch.Tensor]:  # noqa: ANN001 - a RayTrace of either checkout
    out = [r.pos, r.dir, r.status, r.backtrack] + ([] if r.failed_at is None else [r.failed_at])
    for h in r.hits:
        out += [h.pos, h.dir_in, h.dir_out, h.normal, h.t, h.cos2_in, h.cos2_out]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", type=Path, required=True, help="root of the other checkout")
    args = ap.parse_args()
    import_before(args.before)
    from lensopt_before.optics import lens as old_lens
    from lensopt_before.optics import trace as old_trace

    print("| spec | rays | failed | record | no_grad (chunked) | autograd (one pass) |\n"
          "| --- | ---: | ---: | --- | --- | --- |")
    all_equal = True
    for name in NAMES:
        model = build(load_spec(SPECS / f"{name}.toml"))
        lens, system = model.lens, model.system
        fo = first_order(lens, system)
        tan = field_tangents(lens, system, torch.tensor(system.rel_field, dtype=torch.float64) * 1.3)
        g = torch.Generator().manual_seed(1)
        per = 150_000 // (len(system.rel_field) * lens.wavelength_um.shape[0])
        pupil = (torch.rand(per, 2, generator=g, dtype=torch.float64) * 2 - 1) * 1.2
        rays = launch(lens, system, pupil, tan, epd=fo.epd, entrance_pupil_z=fo.entrance_pupil_z)
        old = old_lens.Lens(**{f.name: getattr(lens, f.name) for f in dataclasses.fields(lens)})
        old_rays = old_trace.Rays(rays.pos, rays.dir, rays.wavelength)
        for record in (False, True):
            same = []
            for grad in (False, True):
                lens_g = dataclasses.replace(lens, curvature=lens.curvature.clone().requires_grad_(grad))
                with torch.set_grad_enabled(grad):
                    new_r = trace(lens_g, rays, record=record)
                    old_r = old_trace.trace(old, old_rays, record=record)
                same.append(all(torch.equal(a.detach(), b.detach()) for a, b in
                                zip(outputs(new_r), outputs(old_r), strict=True)))
            all_equal &= all(same)
            print(f"| {name} | {new_r.status.numel():,} | {int((new_r.status != 0).sum()):,} | {record} | "
                  f"{'equal' if same[0] else 'DIFFERENT'} | {'equal' if same[1] else 'DIFFERENT'} |")
    print(f"\nall equal: {all_equal}")


if __name__ == "__main__":
    main()
