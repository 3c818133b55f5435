"""``lensopt evaluate`` computes each PSF stack once and reuses it across scenes (issue 10): the scores are
identical to the per-scene path, which recomputes every scene's PSFs as ``lensopt simulate`` does."""

from __future__ import annotations

import numpy as np
import torch

from lensopt.imaging.evaluate import evaluate, scene_source
from lensopt.imaging.plan import Effects, PlanOptions
from lensopt.imaging.regions import tile_grid
from lensopt.imaging.simulate import PsfCache, plan_scene, run_plan, sensor_of
from lensopt.spec import build, camera_of, load_spec
from tests.helpers import CMOUNT


def test_reused_psfs_give_the_per_scene_scores_exactly() -> None:
    camera = camera_of(build(load_spec(CMOUNT)))
    scenes, names, _ = scene_source(None, count=10, patch=256, seed=4)
    opts = PlanOptions(sampling="rings:6")
    fresh = evaluate(camera, scenes, names, patch=256, seed=4, options=opts, reuse_psfs=False)
    reused = evaluate(camera, scenes, names, patch=256, seed=4, options=opts)
    assert reused.items == fresh.items  # every scene's tile, PSNR and SSIM, bit for bit
    note = next(n for n in reused.notes if n.startswith("PSF stacks:"))
    computed, hits = (int(w) for w in note.replace(",", "").split() if w.isdigit())
    assert computed + hits == 10 and hits >= 1, note  # some were reused


def test_mirror_tiles_share_their_stack_and_get_the_same_image_as_recomputed() -> None:
    """Tiles (c, r) and its mirror images lie at the same distance from the axis: one stack serves all four,
    and each simulated image equals the one made without the cache (the grids differ: each is rotated to
    its own tile's azimuth)."""
    camera = camera_of(build(load_spec(CMOUNT)))
    sensor, _ = sensor_of(camera, 256, 256)
    grid = tile_grid(sensor, 256)
    opts = PlanOptions(sampling="rings:6")
    scene = scene_source(None, count=1, patch=256, seed=0)[0](0).permute(1, 2, 0).contiguous().numpy()
    info = {"width": 256, "height": 256, "channels": 3}
    c, r = 1, 2
    tiles = [(c, r), (grid.cols - 1 - c, r), (c, grid.rows - 1 - r), (grid.cols - 1 - c, grid.rows - 1 - r)]
    cache, pilot = PsfCache(), None
    with torch.inference_mode():
        for col, row in tiles:
            k = next(i for i in range(len(grid)) if (int(grid.col[i]), int(grid.row[i])) == (col, row))
            plan, pilot, reg, sens = plan_scene(camera, info, region=grid.region(k), effects=Effects(), options=opts,
                                                pilot=pilot)
            a = run_plan(camera, plan, pilot, reg, sens, scene, opts, cache=cache).image
            b = run_plan(camera, plan, pilot, reg, sens, scene, opts).image
            assert np.array_equal(a, b)
    assert (cache.misses, cache.hits) == (1, 3) and len(cache.grids) == 4
