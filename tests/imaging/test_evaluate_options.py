"""``lensopt evaluate``'s --backend (issue 13) and --device (issue 11) options."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from lensopt.cli import app

ROOT = Path(__file__).resolve().parents[2]
CMOUNT = ROOT / "lenses" / "cmount_4p.json"
SMALL = ["--count", "2", "--patch", "64", "--rays", "rings:4", "--json"]
runner = CliRunner()


def _spy(monkeypatch: pytest.MonkeyPatch) -> list[dict]:
    """Record the trace backend in force and the camera's device when the library's evaluate runs."""
    import lensopt.imaging.evaluate as ev
    from lensopt.optics.backend import current_backend

    seen: list[dict] = []
    real = ev.evaluate

    def spy(camera, *args, **kwargs):  # noqa: ANN001, ANN002, ANN003, ANN202
        seen.append({"backend": current_backend(), "device": str(camera.lens.device)})
        return real(camera, *args, **kwargs)

    monkeypatch.setattr(ev, "evaluate", spy)
    return seen


@pytest.mark.parametrize(("args", "backend"), [([], "auto"), (["--backend", "eager"], "eager")])
def test_backend_option_is_in_force_while_evaluating(monkeypatch: pytest.MonkeyPatch, args: list[str],
                                                     backend: str) -> None:
    seen = _spy(monkeypatch)
    r = runner.invoke(app, ["evaluate", str(CMOUNT), *SMALL, *args])
    assert r.exit_code == 0, r.stderr
    assert [s["backend"] for s in seen] == [backend]


def test_bad_backend_is_one_line_exit_2() -> None:
    r = runner.invoke(app, ["evaluate", str(CMOUNT), *SMALL, "--backend", "fast"])
    assert r.exit_code == 2 and r.stderr.startswith("error: ") and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "backend" in r.stderr
