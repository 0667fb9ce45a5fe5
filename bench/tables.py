"""Markdown table cells shared by ``gratnet bench``'s and ``gratnet sweep``'s tables."""

from __future__ import annotations

from typing import Any

from gratnet.cost import megabytes

__all__ = ["COST_HEADER", "cost_cells", "format_cell"]

#: The cost columns of ``gratnet bench``'s tables (gratnet.cost; MB = 10⁶ bytes), in :func:`cost_cells`' order.
COST_HEADER = "MACs/pixel | grid values read | MB on disk | MB on GPU"


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


def cost_cells(row: dict[str, Any]) -> list[str]:
    """The :data:`COST_HEADER` cells of a bench row holding ``gratnet.cost.ModelCost.to_dict()``'s keys."""
    disk, gpu = row.get("bytes_on_disk"), row.get("bytes_gpu")
    return [format_cell(row["macs_per_pixel"]), format_cell(row.get("grid_values_read_per_pixel")),
            "—" if disk is None else megabytes(int(disk)), "—" if gpu is None else megabytes(int(gpu))]
