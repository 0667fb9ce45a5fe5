"""PNG previews of ground-truth volumes: one w-slice in display sRGB at a chosen exposure."""

from __future__ import annotations

import os

import numpy as np

from gratnet.display import xyz_to_display_srgb8
from gratnet.errors import GratNetError
from gratnet.figures import save_figure
from gratnet.volume import Volume, volume_axes


def save_slice_preview(volume: Volume, path: str | os.PathLike[str], slice_index: int, exposure: float) -> None:
    """Write a PNG figure of slice ``slice_index`` (display sRGB, ×exposure) with u*, v* axes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not -volume.slices <= slice_index < volume.slices:
        raise GratNetError(f"--preview-slice {slice_index} is out of range: the volume has {volume.slices} slices")
    slice_index %= volume.slices
    image = xyz_to_display_srgb8(volume.xyz[slice_index], exposure)
    axis = volume_axes(volume.resolution)
    metadata = volume.metadata
    w_values = metadata.get("slice_w") or [None] * volume.slices
    t_values = metadata.get("slice_t") or [None] * volume.slices
    w_text = f"w = {w_values[slice_index]:.3g}" if w_values[slice_index] is not None else (
        f"t = {t_values[slice_index]:.3g} (w = −t·√(4−u²−v²))")
    figure, axes = plt.subplots(figsize=(6.4, 6.0), dpi=150)
    # Row index = v* ascending: origin="lower" puts v* = −2 at the bottom, as in a plot.
    axes.imshow(image, origin="lower", extent=(axis[0], axis[-1], axis[0], axis[-1]), interpolation="nearest")
    axes.set_xlabel("u* (grid coordinate)")
    axes.set_ylabel("v* (grid coordinate)")
    source = str(metadata.get("source", "?"))
    axes.set_title(
        f"{source[:60]}\nslice {slice_index}: {w_text}, scheme {metadata.get('scheme', '?')}, "
        f"exposure {exposure:g} (display sRGB)", fontsize=8,
    )
    figure.tight_layout()
    save_figure(figure, path)
    plt.close(figure)


def max_luminance(volume: Volume) -> np.ndarray:
    """Largest Y of each slice (for choosing an exposure)."""
    return volume.xyz[..., 1].reshape(volume.slices, -1).max(axis=1)
