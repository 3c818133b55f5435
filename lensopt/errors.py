"""One exception root for everything a person can act on (DESIGN.md rule 6).

Every message reads ``path.to.field: what is wrong (got X)`` so that the CLI can print it as one
line and exit with code 2. Ray failures are never exceptions: they are masks (see optics.trace).
"""

from __future__ import annotations

from typing import Any

__all__ = ["LensoptError", "SpecError", "MaterialError", "TraceError", "format_got"]


def format_got(value: Any) -> str:
    """Short, readable rendering of an offending value for error messages."""
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


class LensoptError(Exception):
    """Root of all lensopt errors. ``str(err)`` is a complete one-line message."""

    def __init__(self, message: str, *, path: str | None = None, got: Any = ...) -> None:
        self.path = path
        self.message = message
        self.got = got
        super().__init__(self._render())

    def _render(self) -> str:
        text = f"{self.path}: {self.message}" if self.path else self.message
        if self.got is not ...:
            text += f" (got {format_got(self.got)})"
        return text

    def at(self, path: str) -> LensoptError:
        """The same error re-rooted under ``path`` (``surfaces[2]`` + ``material`` ...)."""
        full = f"{path}.{self.path}" if self.path else path
        return type(self)(self.message, path=full, got=self.got)


class SpecError(LensoptError):
    """A spec or lens file is malformed or asks for something impossible."""


class MaterialError(SpecError):
    """Unknown glass, bad model-glass numbers, or a wavelength outside a glass's valid range."""


class TraceError(LensoptError):
    """A lens cannot be traced at all (e.g. no valid paraxial solution); per-ray failures are masks."""
