"""Markdown table cells shared by ``gratnet bench``'s and ``gratnet sweep``'s tables."""

from __future__ import annotations

__all__ = ["format_cell"]


def format_cell(value: object, digits: int = 3) -> str:
    """A markdown table cell: — for None, ``digits`` significant digits for a float (exponent form outside
    [1e-3, 1e5)), anything else as str (``gratnet bench``'s and ``gratnet sweep``'s tables)."""
    if value is None:
        return "—"
    if isinstance(value, float):
        if value == 0 or 1e-3 <= abs(value) < 1e5:
            return f"{value:.{digits}g}"
        return f"{value:.2e}"
    return str(value)
