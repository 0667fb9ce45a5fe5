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

from gratnet.errors import GratNetError

__all__ = ["check_offsets", "MAX_SAMPLES", "check_samples", "jitter_matrix", "sample_offsets", "sample_range_offsets"]

#: Largest sample count per pixel accepted anywhere (a render, the viewer's accumulation cap).
MAX_SAMPLES = 4096


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
    points = np.stack([_radical_inverse(count, 2), _radical_inverse(count, 3)], axis=1)  # the first is (0, 0)
    # A cyclic shift by half a pixel keeps the sequence's spread and maps its first point 0 to the centre.
    return np.mod(points + 0.5, 1.0) - 0.5


def _radical_inverse(count: int, base: int) -> np.ndarray:
    """The first ``count`` points of the van der Corput sequence in ``base`` (index 0 → 0), ``float64``.

    The same numbers as ``scipy.stats.qmc.Halton(scramble=False)`` (tests/runtime/test_antialias.py checks it);
    written out because importing scipy.stats takes 1.2–1.4 s on this machine, which the viewer (it must
    never block) and every ``gratnet render`` would pay on first use.
    """
    index = np.arange(count, dtype=np.int64)
    result = np.zeros(count, dtype=np.float64)
    scale = 1.0 / base
    while np.any(index > 0):
        result += (index % base) * scale
        index //= base
        scale /= base
    return result


def sample_range_offsets(samples: int, first_sample: int = 0) -> np.ndarray:
    """The offsets of samples ``first_sample`` … ``first_sample + samples − 1`` of :func:`sample_offsets`,
    ``float64`` ``(samples, 2)``, pixels (progressive accumulation renders one index at a time); the range
    must end within :data:`MAX_SAMPLES`, else :class:`GratNetError`."""
    count = check_samples(samples)
    if isinstance(first_sample, bool) or not isinstance(first_sample, (int, np.integer)) or first_sample < 0:
        raise GratNetError(f"the first sample index must be an integer ≥ 0, got {first_sample!r}")
    if first_sample + count > MAX_SAMPLES:
        raise GratNetError(f"samples {first_sample} … {first_sample + count - 1} run past the sequence's "
                           f"{MAX_SAMPLES} samples per pixel")
    return sample_offsets(first_sample + count)[first_sample:]


def check_offsets(offsets_px: object) -> np.ndarray:
    """``offsets_px`` as a finite ``float64`` ``(N ≥ 1, 2)`` array of pixel offsets, else :class:`GratNetError`."""
    offsets = np.asarray(offsets_px, dtype=np.float64)
    if offsets.ndim != 2 or offsets.shape[1] != 2 or offsets.shape[0] < 1 or not np.all(np.isfinite(offsets)):
        raise GratNetError(f"sample offsets must be a finite (N ≥ 1, 2) array of pixels, got shape {offsets.shape}")
    return offsets


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
