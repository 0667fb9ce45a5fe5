"""Fidelity diagnostics: the interpolation oracle, the error split by region, and training curves.

* **Interpolation oracle.** What the training grid itself can deliver: the volume's own samples,
  trilinearly interpolated at a BRDF slice's exact key vectors, scored like the network. A network
  cannot be expected to beat it much; if the network is far above it, the loss is in the network, not
  in the grid. The volume is uniform in its *grid* coordinates (u*, v*, t) (docs/physics.md,
  "Sampling"), not in the key vector (u, v, w) for the ``simple`` schemes, so a key vector is mapped to
  grid coordinates by the runtime's own contract (:func:`gratnet.encoding.network_coordinates`: c_u =
  u*/2, c_v = v*/2, c_t = 2t − 1, each in [−1, 1]) and interpolated there with SciPy's
  ``RegularGridInterpolator``. Grid samples with u² + v² > 4 hold 0, so the oracle too darkens slightly
  near the rim of the reachable disc.
* **Regions** of a ground-truth BRDF slice (exposed XYZ, pixels inside the view disc), a partition:
  ``specular``: pixels whose key (u, v) lies within ρ of the specular key (0, 0), ρ = the larger of
  3 standard deviations of the specular lobe at 780 nm, 3·λ/(2π σs) (the Gaussian window of std σs
  blurs spatial frequency u/λ with std 1/(2π σs)), and 3 pixel pitches (2/size each in u);
  ``dark``: the rest with exposed Y below :data:`DARK_Y` (shows as near-black: sRGB code ≲ 6/255);
  ``orders``: the rest with Y ≥ :data:`ORDER_FRACTION` × the 99th percentile of Y over these lit,
  non-specular pixels (the diffraction orders / bright features); ``floor``: the remaining lit pixels
  (speckle and scattering floor). Each region reports its pixel fraction, mean FLIP (of the whole
  image's FLIP map, averaged over the region) and relative L1 of exposed XYZ, Σ|pred − ref| / Σ|ref|.
* **Training curves**: loss and, where recorded, the per-epoch slice FLIP against the epoch.
"""

from __future__ import annotations

import math
import os
from typing import Any

import numpy as np

from gratnet.codes import SCHEME
from gratnet.encoding import network_coordinates
from gratnet.errors import GratNetError
from gratnet.volume import Volume
from trainer.brdfslice import SliceConfig, expose_slice, slice_geometry

REGIONS: tuple[str, ...] = ("specular", "orders", "floor", "dark")
#: Exposed luminance Y below which a pixel counts as dark background (display sRGB code ≈ 6/255).
DARK_Y = 2e-3
#: Lit, non-specular pixels at least this fraction of their 99th-percentile Y are "orders".
ORDER_FRACTION = 0.1
#: Longest wavelength (µm) for the specular lobe's width.
LONGEST_WAVELENGTH_UM = 0.78


class VolumeOracle:
    """Trilinear interpolation of a volume's XYZ at key vectors: the interpolation oracle.

    Interpolates in grid coordinates (u*, v*, t), where the volume is uniform; a one-slice volume is
    interpolated bilinearly in (u*, v*). Keys outside [−2, 2]² are clamped to the grid's edge. Built once
    per volume (the samples are used in place, as float32).
    """

    def __init__(self, volume: Volume) -> None:
        from scipy.interpolate import RegularGridInterpolator

        scheme = volume.metadata.get("scheme")
        if scheme not in SCHEME.names:
            raise GratNetError(f"volume has no known sampling scheme in its metadata (got {scheme!r})")
        self.scheme = scheme
        self.one_slice = volume.slices == 1
        axis = np.linspace(-1.0, 1.0, volume.resolution)  # c = u*/2 of volume_axes (linspace(−2, 2, R))
        if self.one_slice:
            self._interpolator = RegularGridInterpolator((axis, axis), volume.xyz[0], method="linear")
        else:
            t_values = np.asarray(volume.metadata.get("slice_t") or np.linspace(0.0, 1.0, volume.slices), np.float64)
            # xyz is (S, rows = v*, columns = u*, 3)
            self._interpolator = RegularGridInterpolator((2.0 * t_values - 1.0, axis, axis), volume.xyz,
                                                         method="linear")

    def __call__(self, u: np.ndarray, v: np.ndarray, w: np.ndarray) -> np.ndarray:
        """XYZ (…, 3) at key vectors (u, v, w) of equal shapes."""
        coordinates = np.clip(network_coordinates(np.asarray(u, np.float64), np.asarray(v, np.float64),
                                                  np.asarray(w, np.float64), self.scheme), -1.0, 1.0)
        order = [1, 0] if self.one_slice else [2, 1, 0]  # (c_t,) c_v, c_u: the volume's axis order
        return np.asarray(self._interpolator(coordinates[..., order]), np.float64)

    def brdf_slice(self, config: SliceConfig) -> np.ndarray:
        """exposure · A · XYZ_oracle for every pixel of a BRDF slice (size, size, 3); 0 outside the disc."""
        light, views, inside = slice_geometry(config)
        key = -(light + views)
        xyz = np.zeros(views.shape)
        xyz[inside] = self(key[inside][:, 0], key[inside][:, 1], key[inside][:, 2])
        return expose_slice(config, light, views, inside, xyz)


def interpolate_volume(volume: Volume, u: np.ndarray, v: np.ndarray, w: np.ndarray) -> np.ndarray:
    """:class:`VolumeOracle` of ``volume`` at key vectors (u, v, w) → (…, 3) (one-off use)."""
    return VolumeOracle(volume)(u, v, w)


def oracle_brdf_slice(volume: Volume, config: SliceConfig) -> np.ndarray:
    """:meth:`VolumeOracle.brdf_slice` of ``volume`` (one-off use)."""
    return VolumeOracle(volume).brdf_slice(config)


def specular_radius(sigma_s_um: float, size: int) -> float:
    """ρ (key units) of the specular region: max(3·λmax/(2π σs), 3 pixel pitches of 2/size)."""
    return max(3.0 * LONGEST_WAVELENGTH_UM / (2.0 * math.pi * sigma_s_um), 3.0 * 2.0 / size)


def region_labels(reference_xyz: np.ndarray, config: SliceConfig, sigma_s_um: float) -> np.ndarray:
    """Index into :data:`REGIONS` per pixel (size, size); −1 outside the view disc (see the module doc)."""
    light, views, inside = slice_geometry(config)
    key = -(light + views)
    luminance = np.asarray(reference_xyz, np.float64)[..., 1]
    labels = np.full(inside.shape, -1, dtype=np.int8)
    specular = inside & (np.hypot(key[..., 0], key[..., 1]) <= specular_radius(sigma_s_um, config.size))
    dark = inside & ~specular & (luminance < DARK_Y)
    lit = inside & ~specular & ~dark
    threshold = ORDER_FRACTION * float(np.percentile(luminance[lit], 99.0)) if lit.any() else math.inf
    labels[specular] = REGIONS.index("specular")
    labels[dark] = REGIONS.index("dark")
    labels[lit & (luminance >= threshold)] = REGIONS.index("orders")
    labels[lit & (luminance < threshold)] = REGIONS.index("floor")
    return labels


def region_errors(reference_xyz: np.ndarray, test_xyz: np.ndarray, labels: np.ndarray) -> dict[str, dict[str, Any]]:
    """Per region: pixel fraction (of the disc), mean FLIP, relative L1 of exposed XYZ (None where Σ|ref| = 0)."""
    from trainer.metrics import flip

    _, error_map = flip(reference_xyz, test_xyz)
    reference, test = np.asarray(reference_xyz, np.float64), np.asarray(test_xyz, np.float64)
    disc = int((labels >= 0).sum())
    results: dict[str, dict[str, Any]] = {}
    for index, name in enumerate(REGIONS):
        selected = labels == index
        count = int(selected.sum())
        total = float(np.abs(reference[selected]).sum())
        results[name] = {
            "fraction": count / disc if disc else 0.0,
            "flip": float(error_map[selected].mean()) if count else None,
            "relative_l1": float(np.abs(test[selected] - reference[selected]).sum()) / total if total > 0 else None,
        }
    return results


#: Colours of the region map: specular, orders, floor, dark (outside the disc: white).
REGION_COLOURS = ("#e41a1c", "#ffbf00", "#4daf4a", "#1f2a44")


def region_figure(path: str | os.PathLike[str], rows: list[tuple[str, np.ndarray]]) -> None:
    """A PNG of the region maps (one panel per ``(label, labels)``), with a legend of :data:`REGIONS`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    from gratnet.figures import save_figure

    if not rows:
        raise GratNetError("region_figure needs at least one (label, labels) panel")
    colormap = ListedColormap(["#ffffff", *REGION_COLOURS])
    figure, axes = plt.subplots(1, len(rows), figsize=(2.4 * len(rows), 3.0), dpi=120, squeeze=False,
                                layout="constrained")
    try:
        for axis, (label, labels) in zip(axes[0], rows, strict=True):
            axis.imshow(labels + 1, cmap=colormap, vmin=0, vmax=len(REGIONS), interpolation="nearest")
            axis.set_title(label, fontsize=8)
            axis.set_xticks([])
            axis.set_yticks([])
        handles = [Patch(color=colour, label=name) for name, colour in zip(REGIONS, REGION_COLOURS, strict=True)]
        figure.legend(handles=handles, loc="outside lower center", ncol=len(REGIONS), fontsize=8)
        figure.suptitle("Regions of the ground-truth BRDF slices (trainer/diagnostics.py)", fontsize=9)
        save_figure(figure, path)
    finally:
        plt.close(figure)


def plot_history(history: dict[str, Any], path: str | os.PathLike[str]) -> bool:
    """Write loss (log scale) and, where recorded, per-epoch slice FLIP against the epoch as a PNG.

    Returns False (and writes nothing) when ``history`` has no epochs.
    """
    epochs = history.get("epochs") or []
    if not epochs:
        return False
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from gratnet.figures import save_figure

    numbers = [record["epoch"] for record in epochs]
    figure, loss_axis = plt.subplots(figsize=(6.0, 3.6), dpi=120, layout="constrained")
    try:
        for key, style in (("train_loss", "-"), ("held_out_loss", "--")):
            values = [record.get(key) for record in epochs]
            if any(value is not None for value in values):
                loss_axis.plot(numbers, [math.nan if x is None else x for x in values], style, color="tab:blue",
                               marker=".", label=key.replace("_", " "))
        loss_axis.set_yscale("log")
        loss_axis.set_xlabel("epoch")
        loss_axis.set_ylabel("LogCosh loss (range-transformed XYZ)", color="tab:blue")
        handles, names = loss_axis.get_legend_handles_labels()
        flips = [record.get("slice_flip") for record in epochs]
        if any(value is not None for value in flips):
            flip_axis = loss_axis.twinx()
            flip_axis.plot(numbers, [math.nan if x is None else x for x in flips], "-", color="tab:red", marker="o",
                           label=str(history.get("slice_flip_label", "slice FLIP")))
            flip_axis.set_ylabel("mean FLIP", color="tab:red")
            more_handles, more_names = flip_axis.get_legend_handles_labels()
            handles, names = handles + more_handles, names + more_names
        loss_axis.legend(handles, names, fontsize=8, loc="upper right")
        loss_axis.set_title("Training curves", fontsize=10)
        save_figure(figure, path)
    finally:
        plt.close(figure)
    return True
