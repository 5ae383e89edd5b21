"""One table writer for every table RehabBot prints or publishes.

The CLI's summaries, the clinical evaluator's comparison, the sweep listing and every
benchmark's results table are rows of cells rendered here, so a published Markdown table
and the same table in a terminal look alike and a test can render a table again from the
JSON it came from and compare text.

- :func:`markdown_table`: a GitHub-flavoured Markdown table (padded columns; ``|`` in a
  cell escaped).
- :func:`text_table`: the same rows as aligned plain text for a terminal.
- :func:`format_cell`: how one value is written (``None`` as ``-``, floats to ``digits``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

Cell = str | int | float | None
Align = Literal["left", "right", "center"]

__all__ = ["Align", "Cell", "format_cell", "markdown_table", "text_table"]

MISSING = "-"


def format_cell(value: Cell, digits: int | None = None) -> str:
    """One cell as text: ``None`` (no value) as ``-``; a float to ``digits`` decimals when
    given, else Python's shortest round-trip form; anything else with ``str``."""
    if value is None:
        return MISSING
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float) and digits is not None:
        return f"{value:.{digits}f}"
    return str(value)


def _cells(header: Sequence[str], rows: Sequence[Sequence[Cell]],
           digits: int | None) -> list[list[str]]:
    if not header:
        raise ValueError("a table needs at least one column; header is empty")
    table = [[str(h) for h in header]]
    for index, row in enumerate(rows):
        if len(row) != len(header):
            raise ValueError(f"row {index} has {len(row)} cells, the header {len(header)}: "
                             f"{list(row)!r}")
        table.append([format_cell(cell, digits) for cell in row])
    return table


def _widths(table: Sequence[Sequence[str]]) -> list[int]:
    return [max(len(row[i]) for row in table) for i in range(len(table[0]))]


def _pad(text: str, width: int, align: Align) -> str:
    if align == "right":
        return text.rjust(width)
    if align == "center":
        return text.center(width)
    return text.ljust(width)


def _alignments(align: Sequence[Align] | None, columns: int) -> list[Align]:
    if align is None:
        return ["left"] * columns
    if len(align) != columns:
        raise ValueError(f"align has {len(align)} entries for {columns} columns: {list(align)!r}")
    for value in align:
        if value not in ("left", "right", "center"):
            raise ValueError(f"align {value!r} is not one of 'left', 'right', 'center'")
    return list(align)


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[Cell]], *,
                   align: Sequence[Align] | None = None, digits: int | None = None) -> str:
    """A GitHub-flavoured Markdown table of ``rows`` under ``header`` (no trailing newline).

    Columns are padded to a common width so the source reads as a table too; a ``|`` in a
    cell is escaped. ``align`` gives each column's alignment (default: left)."""
    table = [[cell.replace("|", "\\|") for cell in row] for row in _cells(header, rows, digits)]
    alignments = _alignments(align, len(header))
    widths = [max(3, w) for w in _widths(table)]

    def rule(width: int, how: Align) -> str:
        if how == "right":
            return "-" * (width - 1) + ":"
        if how == "center":
            return ":" + "-" * (width - 2) + ":"
        return "-" * width

    def line(cells: Sequence[str]) -> str:
        return "| " + " | ".join(_pad(c, w, a) for c, w, a in
                                 zip(cells, widths, alignments, strict=True)) + " |"

    separator = "| " + " | ".join(rule(w, a) for w, a in zip(widths, alignments, strict=True)) \
        + " |"
    return "\n".join([line(table[0]), separator, *(line(row) for row in table[1:])])


def text_table(header: Sequence[str], rows: Sequence[Sequence[Cell]], *,
               align: Sequence[Align] | None = None, digits: int | None = None) -> str:
    """The rows as aligned plain text for a terminal: columns two spaces apart, a dashed rule
    under the header, no trailing spaces (no trailing newline)."""
    table = _cells(header, rows, digits)
    alignments = _alignments(align, len(header))
    widths = _widths(table)

    def line(cells: Sequence[str]) -> str:
        return "  ".join(_pad(c, w, a) for c, w, a in
                         zip(cells, widths, alignments, strict=True)).rstrip()

    return "\n".join([line(table[0]), "  ".join("-" * w for w in widths),
                      *(line(row) for row in table[1:])])
