"""Tables that fit the output (CLI layer): the console width rule, compact tables, matrices folded into
column blocks that fit, and ``--wide`` printing.

The width rule (``fit_width``): ``COLUMNS`` when set, else the terminal's width, else (a pipe or a file)
80 columns. A table wider than that is not cut: a matrix (per field × per wavelength) puts its longer
dimension down the rows and splits its columns into blocks that fit (``matrix_tables``); ``--wide``
prints everything in one table at its natural width (``print_wide``).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import IO

from rich import box
from rich.console import Console, RenderableType
from rich.table import Table

__all__ = ["PIPE_WIDTH", "fit_width", "compact_table", "matrix_tables", "show", "print_wide"]

PIPE_WIDTH = 80
"""Columns of output that goes to a pipe or a file when ``COLUMNS`` is not set."""


def fit_width(console: Console, stream: IO[str] | None = None) -> None:
    """Set ``console``'s width by the rule of the module doc, read now (``COLUMNS`` may change between
    commands run in one process, as under a test runner)."""
    cols = os.environ.get("COLUMNS", "").strip()
    if cols.isdigit() and int(cols) > 0:
        console.width = int(cols)
        return
    stream = stream if stream is not None else console.file
    try:
        tty = stream.isatty()
    except (AttributeError, ValueError):
        tty = False
    console.width = None if tty else PIPE_WIDTH  # type: ignore[assignment]  # None: ask the terminal


def compact_table(title: str, columns: Sequence[tuple[str, str]]) -> Table:
    """A table with a rule under its header and no outer frame, two spaces between cells: ``columns`` are
    (header, justify) pairs; a header may hold a line break. Print it with ``show`` (title on a line of
    its own, cells whole)."""
    t = Table(title=title, box=box.SIMPLE_HEAD, show_edge=False, pad_edge=False, padding=(0, 0, 0, 1),
              header_style="bold")
    for name, justify in columns:
        t.add_column(name, justify=justify)  # type: ignore[arg-type]
    return t


def matrix_tables(title: str, corner: str, rows: Sequence[str], columns: Sequence[str],
                  cells: Sequence[Sequence[str]], *, width: int) -> list[Table]:
    """``cells[i][j]`` (row ``rows[i]``, column ``columns[j]``) as compact tables no wider than ``width``:
    the columns are split into blocks that fit, each block repeating the row labels and saying which
    columns it holds. Cells are never cut."""
    label_w = max([len(corner), *(len(r) for r in rows)])
    col_w = [max([len(c), *(len(row[j]) for row in cells)]) for j, c in enumerate(columns)]
    blocks: list[list[int]] = [[]]
    used = label_w
    for j, w in enumerate(col_w):
        if blocks[-1] and used + 2 + w > width:
            blocks.append([])
            used = label_w
        blocks[-1].append(j)
        used += 2 + w
    out = []
    for k, block in enumerate(blocks):
        span = columns[block[0]] + ("" if len(block) == 1 else f" … {columns[block[-1]]}")
        part = "" if len(blocks) == 1 else f" ({k + 1}/{len(blocks)}: {span})"
        t = compact_table(title + part, [(corner, "right"), *((columns[j], "right") for j in block)])
        for label, row in zip(rows, cells, strict=True):
            t.add_row(label, *(row[j] for j in block))
        out.append(t)
    return out


def show(console: Console, table: Table, *, wide: bool = False, wrap: Sequence[str] = ("notes",)) -> None:
    """Print ``table`` with its title as a line of its own (wrapped at the console's width, not the
    table's) and every cell whole: each column is as wide as its longest cell or header word, the ``wrap``
    columns take the rest and wrap at spaces, so a short width wraps headers and notes, never cuts a
    number (below the sum of those widths rich crops the right edge). ``wide``: ``print_wide``."""
    title, table.title = table.title, None
    cols = table.columns
    cells = [[c for c in col.cells if isinstance(c, str)] for col in cols]
    flex = [str(col.header) in wrap for col in cols]
    # The wrap columns take what the others leave, wrapping at spaces: their longest word whole.
    least = [max([len(w) for c in cs for w in c.split()] + [len(str(col.header))]) if f else 0
             for col, cs, f in zip(cols, cells, flex, strict=True)]
    # The others are exactly as wide as their longest cell and header line; when that is too wide for the
    # console, as their longest cell and header word (headers wrap at spaces; cells never do).
    for split in (lambda h: h.split("\n"), str.split):
        widths = [max([len(c) for c in cs] + [len(w) for w in split(str(col.header))])
                  for col, cs in zip(cols, cells, strict=True)]
        total = sum(lo if f else w for w, lo, f in zip(widths, least, flex, strict=True)) + 2 * (len(cols) - 1)
        if total <= console.width:
            break
    for col, w, lo, f in zip(cols, widths, least, flex, strict=True):
        if f:
            col.min_width = lo or None
        else:
            col.width = w or None
    if title:
        console.print(f"[bold]{title}[/]", highlight=False)
    if wide:
        print_wide(console, table)
    else:
        console.print(table)


def print_wide(console: Console, renderable: RenderableType) -> None:
    """Print at the renderable's natural width even past the console's (``--wide``): nothing shrunk or cut."""
    need = console.measure(renderable, options=console.options.update_width(10**6)).maximum
    saved = console.width
    console.width = max(need, saved)
    try:
        console.print(renderable, crop=False)
    finally:
        console.width = saved
