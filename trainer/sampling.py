"""Sampling schemes of the key-vector domain (docs/physics.md, "Sampling").

The volume is indexed by a uniform grid u*, v* on [−2, 2] (R samples, both ends included) and S
w-slices with t_s = s/(S−1). The schemes map grid coordinates to key vectors (u, v, w):

- ``regular``:    u = u*, v = v*, w = −2·t_s
- ``simple``:     u = 2·sign(u*)·(u*/2)², likewise v; w = −2·t_s  (denser near the specular peak u = v = 0)
- ``simple-max``: u, v as ``simple``; w = −t_s·sqrt(4 − u² − v²)  (w uniform on its reachable range)

Samples with u² + v² > 4 are physically impossible (|ωi + ωo| ≤ 2) and hold 0 in the volume.
"""

from __future__ import annotations

from typing import Literal, cast

import numpy as np

from gratnet.codes import SCHEME
from gratnet.errors import GratNetError
from gratnet.volume import volume_axes

Scheme = Literal["regular", "simple", "simple-max"]  # for type checkers; tests/contract/test_shared_codes ties it
SCHEMES: tuple[str, ...] = SCHEME.names  # gratnet.codes


def grid_axis(resolution: int) -> np.ndarray:
    """The uniform grid coordinate u* (= v*): ``resolution`` samples on [−2, 2], both ends included."""
    return volume_axes(resolution)


def slice_t(slices: int) -> np.ndarray:
    """The slice parameters t_s = s/(S−1), s = 0…S−1 (both ends included); one slice gives t = 0."""
    if slices < 1:
        raise GratNetError(f"slices must be at least 1, got {slices}")
    return np.linspace(0.0, 1.0, slices) if slices > 1 else np.zeros(1)


def check_scheme(scheme: str) -> Scheme:
    """Return ``scheme`` if known, else raise a clear error."""
    if scheme not in SCHEMES:
        raise GratNetError(f"unknown sampling scheme {scheme!r}; choose one of {', '.join(SCHEMES)}")
    return cast(Scheme, scheme)  # one of SCHEMES, checked above


def grid_to_key(grid: np.ndarray, scheme: Scheme) -> np.ndarray:
    """Map grid coordinates u* (or v*) to key-vector components u (or v).

    The inverse belongs to the network contract: :func:`gratnet.encoding.key_to_grid`.
    """
    check_scheme(scheme)
    if scheme == "regular":
        return np.asarray(grid, dtype=np.float64)
    return 2.0 * np.sign(grid) * (np.asarray(grid, dtype=np.float64) / 2.0) ** 2


def max_depth(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """sqrt(max(0, 4 − u² − v²)): the largest reachable |w| at (u, v) under |ωi + ωo| ≤ 2."""
    return np.sqrt(np.clip(4.0 - np.square(u) - np.square(v), 0.0, None))


def slice_w(scheme: Scheme, t: float, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """w of slice parameter ``t`` at key components u (columns) and v (rows): an array (rows, columns)."""
    check_scheme(scheme)
    u_grid, v_grid = np.meshgrid(u, v, indexing="xy")
    if scheme == "simple-max":
        return -t * max_depth(u_grid, v_grid)
    return np.full(u_grid.shape, -2.0 * t)


def physical_mask(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """True where u² + v² ≤ 4 (reachable by some pair of directions), as (rows = v, columns = u)."""
    u_grid, v_grid = np.meshgrid(u, v, indexing="xy")
    return np.square(u_grid) + np.square(v_grid) <= 4.0 + 1e-12
