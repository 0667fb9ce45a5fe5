"""Strict JSON for file metadata: numpy values become plain numbers and lists; NaN and inf are refused."""

from __future__ import annotations

import json

import numpy as np

from gratnet.errors import GratNetError


def json_default(value: object) -> object:
    """Let ``json.dumps`` accept numpy scalars, numpy arrays and tuples (as Python numbers / lists)."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, tuple):
        return list(value)
    raise TypeError(f"{type(value).__name__} is not JSON-serialisable")


def strict_json(value: object, what: str) -> str:
    """``value`` as strict JSON text, or one GratNetError naming ``what`` and the reason."""
    try:
        return json.dumps(value, allow_nan=False, default=json_default)
    except (TypeError, ValueError) as error:
        raise GratNetError(
            f"{what} must be JSON-able (dicts with string keys, lists, str, int, float, bool, None; "
            f"no NaN or inf - use null for a missing value): {error}"
        ) from error
