"""Ground-truth reflectance volumes (physics.md, "Sampling" and "The volume file").

``compute_volume`` samples XYZ(u, v, w) of a height field on the grid of a sampling scheme; the
result is a :class:`gratnet.volume.Volume` ready for :func:`gratnet.volume.write_volume`.
"""

from __future__ import annotations

import dataclasses
import datetime
import hashlib
import json
import os
import time
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from gratnet import __version__
from gratnet.atomic import atomic_path
from gratnet.config import config_field
from gratnet.errors import GratNetError
from gratnet.shadowing import METADATA_KEY as SLOPE_COVARIANCE_KEY
from gratnet.volume import Volume
from trainer.fourier import FTerm, OpticsConfig, PreparedSurface, prepare_surface
from trainer.heightfield import HeightField
from trainer.sampling import Scheme, check_scheme, grid_axis, grid_to_key, physical_mask, slice_t, slice_w
from trainer.spectral import ILLUMINANT, OBSERVER, spectral_weights


@dataclasses.dataclass(frozen=True)
class VolumeConfig:
    """The ground-truth volume's grid: resolution, slices and sampling scheme."""

    resolution: int = config_field(1001, "samples R along u* and v* on [−2, 2], both ends included", flag="--res")
    slices: int = config_field(11, "number S of w-slices, t_s = s/(S−1)", flag="--slices")
    sampling: Scheme = config_field("regular", "sampling scheme of the key-vector domain", flag="--sampling")

    def __post_init__(self) -> None:
        check_scheme(self.sampling)
        if self.resolution < 2:
            raise GratNetError(f"--res must be at least 2, got {self.resolution}")
        if self.slices < 1:
            raise GratNetError(f"--slices must be at least 1, got {self.slices}")


@dataclasses.dataclass(frozen=True)
class ComputeConfig:
    """Where the F-term's matrix products run (the volume does not depend on it beyond float32 rounding)."""

    device: str = config_field(
        "auto", "auto (CUDA when torch sees a GPU, else cpu), cpu (numpy: the reference) or cuda[:N] (torch on "
        "the GPU: the same complex64 products and float64 sums, equal to cpu to float32 rounding)",
    )
    checkpoint_minutes: float = config_field(
        10.0, "save the partial sum over wavelengths to VOLUME.exr.partial.npz at most this often, in minutes of wall "
        "time, > 0; --resume continues from it, and it is removed when the volume is written",
    )

    def __post_init__(self) -> None:
        if self.device not in ("auto", "cpu") and not self.device.startswith("cuda"):
            raise GratNetError(f"--device must be auto, cpu or cuda[:N], got {self.device!r}")
        if not self.checkpoint_minutes > 0:
            raise GratNetError(f"--checkpoint-minutes must be > 0, got {self.checkpoint_minutes:g}")

    def resolve(self) -> str | None:
        """The torch device for :class:`trainer.fourier.FTerm`, or None for numpy; checked before any work."""
        if self.device == "cpu":
            return None
        try:
            from trainer.train import pick_device  # the trainer's --device rule: auto is CUDA when present
        except ImportError:
            if self.device == "auto":
                return None
            raise GratNetError("--device cuda needs torch: pip install 'gratnet[trainer]'") from None
        device = pick_device(self.device)
        return None if device.type == "cpu" else str(device)


def volume_key_vectors(config: VolumeConfig) -> tuple[np.ndarray, np.ndarray, list[float | np.ndarray]]:
    """The key components u (columns), v (rows) and each slice's w (scalar or per-sample array)."""
    grid = grid_axis(config.resolution)
    u = grid_to_key(grid, config.sampling)
    v = u.copy()
    w_slices: list[float | np.ndarray] = []
    for t in slice_t(config.slices):
        w = slice_w(config.sampling, float(t), u, v)
        w_slices.append(float(w.flat[0]) if config.sampling != "simple-max" else w)
    return u, v, w_slices


def wavelength_blocks(optics: OpticsConfig, parts: int) -> list[range]:
    """The spectral samples of ``optics`` in ``parts`` contiguous blocks of near-equal size (indices).

    A volume is the sum of its blocks' :func:`compute_volume_part` results (XYZ is a sum over λ), so
    the blocks of one large volume can be computed on different workers and added.
    """
    count = len(spectral_weights(optics.wavelength_start_nm, optics.wavelength_end_nm,
                                 optics.wavelength_step_nm).wavelengths_nm)
    if not 1 <= parts <= count:
        raise GratNetError(f"cannot split {count} wavelengths into {parts} blocks (1 … {count})")
    edges = np.linspace(0, count, parts + 1).round().astype(int)
    return [range(int(low), int(high)) for low, high in zip(edges[:-1], edges[1:], strict=True)]


def compute_volume_part(
    surface: PreparedSurface,
    config: VolumeConfig,
    optics: OpticsConfig,
    wavelengths: range | None = None,
    progress: bool = False,
    device: str | None = None,
) -> tuple[np.ndarray, int]:
    """The float64 XYZ sum (S, R, R, 3) over the spectral samples ``wavelengths`` (all when None), and the
    Chebyshev node count used; :func:`volume_from_sum` turns the sum of all parts into a volume. ``device``: as
    :class:`trainer.fourier.FTerm`'s (None: numpy)."""
    spectral = spectral_weights(optics.wavelength_start_nm, optics.wavelength_end_nm, optics.wavelength_step_nm)
    u, v, w_slices = volume_key_vectors(config)
    engine = FTerm(surface, spectral, optics.tolerance, device=device)
    xyz = engine.xyz_grid(u, v, w_slices, progress="ground truth" if progress else False, wavelengths=wavelengths)
    return xyz, engine.last_node_count


def checkpoint_path_for(out: str | os.PathLike[str]) -> Path:
    """Where ``gratnet groundtruth --out VOLUME.exr`` keeps its partial sum while it runs: VOLUME.exr.partial.npz."""
    out = Path(out)
    return out.with_name(out.name + ".partial.npz")


def checkpoint_fingerprint(surface: PreparedSurface, config: VolumeConfig, optics: OpticsConfig,
                           device: str | None) -> str:
    """What a partial sum depends on (the grid, the optics, the prepared heights, the device's rounding), as a
    SHA-256: a checkpoint is continued only by the computation that wrote it."""
    digest = hashlib.sha256()
    settings = {"volume": dataclasses.asdict(config), "optics": dataclasses.asdict(optics),
                "device": _device_name(device), "dx_um": surface.dx_um, "half_span_um": surface.half_span_um}
    digest.update(json.dumps(settings, sort_keys=True).encode("utf-8"))
    for array in (surface.heights_um, surface.x_um, surface.y_um, surface.window_x, surface.window_y):
        digest.update(np.ascontiguousarray(array).tobytes())
    return digest.hexdigest()


def compute_volume_sum_resumable(
    surface: PreparedSurface,
    config: VolumeConfig,
    optics: OpticsConfig,
    checkpoint: Path,
    resume: bool,
    save_every_s: float = 600.0,
    progress: bool = True,
    device: str | None = None,
) -> tuple[np.ndarray, int]:
    """:func:`compute_volume_part` over all wavelengths, its partial sum saved to ``checkpoint`` (atomically,
    at most every ``save_every_s`` seconds) so that an interrupted run continues with ``resume`` instead of
    starting again; the sum is the uninterrupted run's, bit for bit. The checkpoint is removed at the end."""
    spectral = spectral_weights(optics.wavelength_start_nm, optics.wavelength_end_nm, optics.wavelength_step_nm)
    count = len(spectral.wavelengths_nm)
    fingerprint = checkpoint_fingerprint(surface, config, optics, device)
    start, initial = 0, None
    if resume:
        start, initial = read_checkpoint(checkpoint, fingerprint)
    u, v, w_slices = volume_key_vectors(config)
    engine = FTerm(surface, spectral, optics.tolerance, device=device)
    last_save = time.monotonic()

    def save(done: int, fetch: Callable[[], np.ndarray]) -> None:
        nonlocal last_save
        if start + done < count and time.monotonic() - last_save >= save_every_s:
            with atomic_path(checkpoint, output=False) as temporary, open(temporary, "wb") as stream:
                np.savez(stream, xyz=fetch(), done=start + done, fingerprint=fingerprint)
            last_save = time.monotonic()

    label = "ground truth" if start == 0 else f"ground truth ({start} of {count} λ from the checkpoint)"
    xyz = engine.xyz_grid(u, v, w_slices, progress=label if progress else False, wavelengths=range(start, count),
                          initial=initial, after_wavelength=save)
    checkpoint.unlink(missing_ok=True)
    return xyz, engine.last_node_count


def _stored(checkpoint: Path, *names: str) -> list[np.ndarray]:
    """The members ``names`` of a checkpoint (only those are read); one clear error where there is none or it is
    unreadable."""
    if not checkpoint.is_file():
        raise GratNetError(f"--resume: there is no {checkpoint} to continue from; leave out --resume to start afresh")
    try:
        with np.load(checkpoint) as stored:
            return [stored[name] for name in names]
    except (OSError, KeyError, ValueError, zipfile.BadZipFile) as error:
        raise GratNetError(f"--resume: {checkpoint} is unreadable ({error}); leave out --resume to start "
                           "afresh") from error


def checkpoint_wavelengths(checkpoint: Path) -> int:
    """How many wavelengths a checkpoint holds (its partial sum is not read); GratNetError where there is none or
    it is unreadable."""
    (done,) = _stored(checkpoint, "done")
    return int(done)


def read_checkpoint(checkpoint: Path, fingerprint: str) -> tuple[int, np.ndarray]:
    """The wavelengths done and the partial sum of a checkpoint written for ``fingerprint``; one clear error
    where there is none, it is unreadable, or it belongs to another computation."""
    done, xyz, written_for = _stored(checkpoint, "done", "xyz", "fingerprint")
    if str(written_for) != fingerprint:
        raise GratNetError(f"--resume: {checkpoint} was written for another height field, grid, optics or device; "
                           "leave out --resume to start afresh")
    return int(done), xyz


def compute_volume(
    field: HeightField,
    config: VolumeConfig,
    optics: OpticsConfig,
    report: Callable[[str], None] | None = None,
    progress: bool = True,
    surface: PreparedSurface | None = None,
    device: str | None = None,
    checkpoint: Path | None = None,
    resume: bool = False,
    save_every_s: float = 600.0,
) -> Volume:
    """Sample CIE XYZ(u, v, w) of ``field`` on ``config``'s grid (eq. 1–3 of physics.md); ``device`` as
    :class:`trainer.fourier.FTerm`'s (None: numpy), recorded in the metadata. With ``checkpoint`` the partial
    sum is kept there as it grows and ``resume`` continues from it (:func:`compute_volume_sum_resumable`)."""
    surface = surface or prepare_surface(field, optics, report)
    if checkpoint is None:
        xyz, node_count = compute_volume_part(surface, config, optics, progress=progress, device=device)
    else:
        xyz, node_count = compute_volume_sum_resumable(surface, config, optics, checkpoint, resume, save_every_s,
                                                       progress, device)
    volume = volume_from_sum(field, config, optics, surface, xyz, node_count)
    volume.metadata["compute_device"] = _device_name(device)
    return volume


def _device_name(device: str | None) -> str:
    """"cpu (numpy)" or the GPU's name, for the volume's metadata."""
    if device is None:
        return "cpu (numpy)"
    import torch

    torch_device = torch.device(device)
    if torch_device.type == "cuda":
        return f"{device} (torch, {torch.cuda.get_device_name(torch_device)})"
    return f"{device} (torch)"


def volume_from_sum(
    field: HeightField,
    config: VolumeConfig,
    optics: OpticsConfig,
    surface: PreparedSurface,
    xyz: np.ndarray,
    node_count: int,
) -> Volume:
    """The volume (float32, unreachable samples zeroed, metadata) from the XYZ sum over all wavelengths."""
    spectral = spectral_weights(optics.wavelength_start_nm, optics.wavelength_end_nm, optics.wavelength_step_nm)
    u, v, w_slices = volume_key_vectors(config)
    xyz[:, ~physical_mask(u, v)] = 0.0  # u² + v² > 4: no pair of directions reaches it
    grid_samples = surface.heights_um.shape
    metadata = {
        "scheme": config.sampling,
        "resolution": config.resolution,
        "slices": config.slices,
        "slice_t": [float(t) for t in slice_t(config.slices)],
        "slice_w": [w if isinstance(w, float) else None for w in w_slices],
        "sigma_s_um": optics.sigma_s_um,
        "window_extent_um": optics.extent_um,
        "window_extent_sigmas": optics.window_extent_sigmas,
        "dx_um": surface.dx_um,
        "patch_size_um": [float(size) for size in surface.source_patch_um],
        "grid_samples": [int(n) for n in grid_samples],
        "height_span_um": 2.0 * surface.half_span_um,
        "repeat": optics.repeat,
        "wavelengths_nm": [float(x) for x in spectral.wavelengths_nm],
        "illuminant": ILLUMINANT,
        "observer": OBSERVER,
        "chebyshev_nodes": node_count,
        "interpolation_tolerance": optics.tolerance,
        "source": field.source,
        SLOPE_COVARIANCE_KEY: list(field.slope_covariance()),  # Smith's shadowing (physics.md)
        "preparation_notes": list(surface.notes),
        "gratnet_version": __version__,
        "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "host_cpus": os.cpu_count() or 0,
    }
    return Volume(xyz.astype(np.float32), metadata)
