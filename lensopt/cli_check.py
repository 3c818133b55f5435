"""``lensopt check``: regression checks of lenses against a baseline, for CI (library: ``lensopt.qa.check``)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

DEFAULT_BASELINE = Path("lenses/check_baseline.json")


def register(app: typer.Typer) -> None:
    from lensopt.cli import console, err_console, handle_errors, print_json

    @app.command()
    @handle_errors
    def check(
        lenses: Annotated[list[Path], typer.Argument(help="Lenses (.json or .toml) to check.")],
        baseline: Annotated[Path, typer.Option("--baseline", help="Baseline JSON (lenses keyed by file name).")]
        = DEFAULT_BASELINE,
        update: Annotated[bool, typer.Option("--update", help="Rewrite these lenses' baseline entries "
                                             "(atomically) instead of comparing.")] = False,
        junit: Annotated[Path | None, typer.Option("--junit", help="Also write JUnit XML here (one test case "
                                                   "per lens and metric).")] = None,
        as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object instead of tables.")] = False,
    ) -> None:
        """Recompute each lens's metrics with the baseline's recorded settings and compare them with the
        baseline: exit 0 when every metric is within its tolerance, 1 on a regression, 2 on bad input."""
        from lensopt.io.files import write_text_atomic
        from lensopt.qa import check as qc

        # ``lensopt check lenses/*.json`` also matches the baseline itself when it lives there.
        lenses = [p for p in lenses if p.resolve() != baseline.resolve()]
        if update:
            data = qc.update_baseline(lenses, baseline)
            err_console.print(f"wrote {baseline} ({len(lenses)} lens(es) measured, {len(data['lenses'])} in all)",
                              highlight=False)
            return
        results = qc.check_lenses(lenses, qc.load_baseline(baseline))
        if junit is not None:
            write_text_atomic(junit, qc.junit_xml(results))
        if as_json:
            print_json(qc.as_json(results))
        else:
            for r in results:
                n_bad = sum(not m.passed for m in r.metrics)
                if n_bad == 0:
                    console.print(f"[green]ok[/] {r.key}: {len(r.metrics)} metrics within tolerance")
                    continue
                t = Table(title=f"{r.key} ({r.name}): {n_bad} of {len(r.metrics)} metrics moved",
                          title_justify="left")
                for col in ("metric", "baseline", "now", "Δ", "tolerance"):
                    t.add_column(col, justify="left" if col == "metric" else "right")
                for m in r.metrics:
                    if m.passed:
                        continue
                    t.add_row(m.metric, _fmt(m.baseline), _fmt(m.value),
                              "" if m.delta is None else f"{m.delta:+.3g}", f"{m.tolerance:.3g}")
                console.print(t)
        if not all(r.passed for r in results):
            raise typer.Exit(1)


def _fmt(v: float | None) -> str:
    return "—" if v is None else f"{v:.9g}"
