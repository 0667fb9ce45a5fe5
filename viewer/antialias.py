"""Sub-pixel sample positions for anti-aliasing (issue 12): one jittered key vector per sample.

A diffraction reflectance changes far faster across a pixel's footprint than one sample at the pixel
centre can show (track orders, speckle), so a pixel's value is the mean of N samples at positions spread
over its footprint. Every sample is a full evaluation at its own surface point: its own ωi, ωo and key
vector (docs/physics.md "Key vector"), never an interpolation of neighbours' network outputs.

Positions come from the Halton (2, 3) sequence, a low-discrepancy sequence: any prefix of it covers the
pixel evenly, so progressive accumulation (the viewer adds one sample per still frame) converges from
the first frames on, and N samples are the first N of the same sequence wherever they are taken.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import qmc

from gratnet.errors import GratNetError

__all__ = ["MAX_SAMPLES", "check_samples", "jitter_matrix", "sample_offsets"]

#: Largest sample count per pixel accepted anywhere (a render, the viewer's accumulation cap).
MAX_SAMPLES = 1024


def check_samples(samples: object) -> int:
    """``samples`` as an int in 1…:data:`MAX_SAMPLES`, else :class:`GratNetError`."""
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or not 1 <= samples <= MAX_SAMPLES:
        raise GratNetError(f"samples per pixel must be an integer in 1…{MAX_SAMPLES}, got {samples!r}")
    return int(samples)


def sample_offsets(samples: int) -> np.ndarray:
    """The first ``samples`` sub-pixel offsets, ``float64`` ``(samples, 2)``, in pixels, each in [−0.5, 0.5).

    Offset 0 is (0, 0), the pixel centre, so one sample per pixel is exactly the un-jittered render; the
    rest follow the Halton (2, 3) sequence (unscrambled, so the positions are the same on every run).
    """
    count = check_samples(samples)
    points = qmc.Halton(d=2, scramble=False).random(count)  # the first point is (0, 0)
    # A cyclic shift by half a pixel keeps the sequence's spread and maps its first point 0 to the centre.
    return np.mod(points + 0.5, 1.0) - 0.5


def jitter_matrix(offset_px: np.ndarray | tuple[float, float], width: int, height: int) -> np.ndarray:
    """Clip-space translation that moves the image by ``offset_px`` (x right, y up, in pixels).

    In pyrr's row-vector convention, as viewer/camera.py: ``camera.view_projection(W / H) @ jitter_matrix(o,
    W, H)``. One pixel is 2/W (2/H) in normalised device coordinates; the translation is scaled by the clip
    w, so it is one pixel at every depth. ``float32`` ``(4, 4)``.
    """
    dx, dy = (float(c) for c in offset_px)
    matrix = np.eye(4, dtype=np.float64)
    matrix[3, 0] = 2.0 * dx / width
    matrix[3, 1] = 2.0 * dy / height
    return matrix.astype(np.float32)
