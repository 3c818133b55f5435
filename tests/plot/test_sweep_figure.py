"""The sweep figure keeps the best-of-starts curve readable when a start stalled far above it."""

from __future__ import annotations

from lensopt.plot.sweep import sweep_figure


def test_a_stalled_start_goes_to_the_top_edge_and_does_not_set_the_scale() -> None:
    series = {"": [(19.4, 10.3), (20.7, 4.8), (22.0, 3.2), (23.3, 1.7)]}
    starts = [(19.4, 10.3), (19.4, 11.2), (22.0, 3.2), (22.0, 1200.0), (23.3, 716.0)]
    ax = sweep_figure(series, starts, xlabel="TTL").axes[0]
    assert ax.get_ylim() == (0.0, 2 * 10.3)
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "2 start(s) above 20.6, up to 1.2e+03" in labels
    inside, above = ax.collections
    assert len(inside.get_offsets()) == 3 and len(above.get_offsets()) == 2
    assert max(y for _, y in above.get_offsets()) < 2 * 10.3


def test_without_outliers_every_start_is_a_faint_dot() -> None:
    ax = sweep_figure({"": [(1.0, 2.0), (2.0, 1.0)]}, [(1.0, 2.0), (1.0, 3.0), (2.0, 1.0)], xlabel="x").axes[0]
    assert len(ax.collections) == 1 and len(ax.collections[0].get_offsets()) == 3
