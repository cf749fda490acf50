"""Plain-text and Markdown tables whose columns are as wide as their content.

Every table the toolkit prints (benchmark summaries, the IK examples beside the paper) and the
tables generated into the docs go through :func:`format_table`, so a long cell (``no
(no_progress)``) widens its column instead of shifting the row.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

__all__ = ["format_cell", "format_table"]


def format_cell(value: object) -> str:
    """A value as a table cell: floats to 4 significant digits, booleans as yes/no, None as -."""
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.4g}" if math.isfinite(value) else str(value)
    return str(value)


def _is_number(text: str) -> bool:
    if text == "-":  # a missing value sits in number columns too
        return True
    try:
        float(text)
    except ValueError:
        return False
    return True


def format_table(
    headers: Sequence[str], rows: Sequence[Sequence[object]], markdown: bool = False
) -> str:
    """Rows under headers, each column as wide as its widest cell.

    Args:
        headers: Column titles.
        rows: One sequence of cells per row, as long as ``headers``; cells go through
            :func:`format_cell`.
        markdown: A Markdown (GitHub) table instead of space-separated columns.

    Returns:
        The table, lines joined by newlines, no trailing newline: the header line, (in Markdown
        its rule,) then one line per row. Columns whose cells are all
        numbers (or ``-``) are right-aligned, the others left-aligned.

    Raises:
        ValueError: A row's length differs from the number of headers.
    """
    cells = [[format_cell(c) for c in row] for row in rows]
    for i, row in enumerate(cells):
        if len(row) != len(headers):
            raise ValueError(f"row {i} has {len(row)} cells for {len(headers)} headers")
    columns = list(zip(*cells, strict=True)) if cells else [() for _ in headers]
    widths = [max([len(h), *map(len, col)]) for h, col in zip(headers, columns, strict=True)]
    right = [any(c != "-" for c in col) and all(map(_is_number, col)) for col in columns]

    def line(values: Sequence[str]) -> str:
        padded = [
            v.rjust(w) if r else v.ljust(w) for v, w, r in zip(values, widths, right, strict=True)
        ]
        return f"| {' | '.join(padded)} |" if markdown else "  ".join(padded).rstrip()

    lines = [line(headers)]
    if markdown:
        lines.append("|" + "|".join(("-" * (w + 1) + ":") if r else "-" * (w + 2)
                                    for w, r in zip(widths, right, strict=True)) + "|")  # fmt: skip
    lines += [line(row) for row in cells]
    return "\n".join(lines)
