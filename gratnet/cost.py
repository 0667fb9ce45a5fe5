"""The cost of a model, per pixel and in bytes: one definition for every report (docs/formats.md, "Cost of a model").

Counted from the model file alone (numpy, no torch, no GL):

- ``mlp_macs``: multiply-adds of the MLP per evaluation (one pixel): Σ inputs·outputs over the linear layers
  (:attr:`gratnet.modelfile.ModelFile.macs_per_evaluation`).
- ``grid_interpolation_macs``: multiply-adds of a feature-grid model's interpolation per pixel: each of the C
  features of each level is a weighted sum of its :data:`GRID_CORNERS` = 8 corner values (eq. 6g; smoothstep
  interpolation has the same eight corners, only other weights). 0 for a pure MLP.
- ``macs_per_pixel``: the two together.
- ``encoding_terms``: sines and cosines the sinusoidal encoding evaluates per pixel, 2·(G·L + L_t) (G = 4 spatial
  groups, 2 without the diagonals: physics.md eq. 6a).
- ``grid_values_read``: grid values (texels' channels) read per pixel: 8 corners × C features per level.
- ``weight_texture_bytes``, ``grid_texture_bytes``, ``bytes_gpu``: what :class:`viewer.renderer.NetworkRenderer`
  uploads: the packed RGBA32F weight texture (docs/formats.md, "Weight texture layout": H × W texels of 16 bytes)
  and per level ⌈C/4⌉ 3-D textures of the grid values at their stored precision (2 bytes per value for float16
  grids, 4 for float32; a last partial chunk holds only its own channels). Not counted: the baked weights path
  holds the weights as shader code instead of the texture, and the deferred path's buffer forms
  (``--deferred-weights ssbo`` and others) hold a second copy of the texels (half of it in fp16).
- ``bytes_on_disk``: the model file's size, when its path is known.

Decimal units in the human summary: 1 MB = 10⁶ bytes.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any

import numpy as np

from gratnet.errors import GratNetError
from gratnet.modelfile import ModelFile, load_model, validated
from gratnet.network import texture_layout

__all__ = ["GRID_CORNERS", "MEGABYTE", "TEXEL_BYTES", "ModelCost", "grid_texture_bytes", "megabytes",
           "weight_texture_bytes"]

#: Corners of a grid cell that trilinear (and smoothstep) interpolation weighs: 2³.
GRID_CORNERS = 8
#: Bytes of one texel of the weight texture: RGBA, float32 each.
TEXEL_BYTES = 16
#: Bytes per decimal megabyte (the summary's MB).
MEGABYTE = 1_000_000


def weight_texture_bytes(layer_sizes: list[int]) -> int:
    """Bytes of the RGBA32F weight texture of a net of ``layer_sizes``: (Σ out_blocks rows) × (max 4·in_blocks + 1
    texels per row) × 16 (docs/formats.md, "Weight texture layout")."""
    layout = texture_layout(list(layer_sizes))
    rows = sum(entry["out_blocks"] for entry in layout)
    width = max(4 * entry["in_blocks"] + 1 for entry in layout)
    return rows * width * TEXEL_BYTES


def grid_texture_bytes(grids: list[Any]) -> int:
    """Bytes of a feature-grid model's 3-D grid textures: per level T·R_v·R_u·C values, each 2 bytes for a float16
    grid and 4 for a float32 one (the renderer uploads float16 grids as half-float textures, others as float)."""
    total = 0
    for grid in grids:
        shape = np.shape(grid)
        value_bytes = 2 if np.asarray(grid).dtype == np.float16 else 4
        total += int(np.prod(shape, dtype=np.int64)) * value_bytes
    return total


@dataclasses.dataclass(frozen=True)
class ModelCost:
    """What one model costs per pixel and in memory (module docstring for each definition).

    Attributes:
        mlp_macs: MLP multiply-adds per pixel.
        grid_interpolation_macs: grid-interpolation multiply-adds per pixel (0 for a pure MLP).
        encoding_terms: sin and cos evaluations per pixel.
        grid_values_read: grid values read per pixel (0 for a pure MLP).
        weight_texture_bytes: bytes of the packed RGBA32F weight texture on the GPU.
        grid_texture_bytes: bytes of the grid textures on the GPU (0 for a pure MLP).
        bytes_on_disk: bytes of the model file, ``None`` when no path was given.
    """

    mlp_macs: int
    grid_interpolation_macs: int
    encoding_terms: int
    grid_values_read: int
    weight_texture_bytes: int
    grid_texture_bytes: int
    bytes_on_disk: int | None = None

    @property
    def macs_per_pixel(self) -> int:
        """Multiply-adds per pixel: MLP and grid interpolation."""
        return self.mlp_macs + self.grid_interpolation_macs

    @property
    def bytes_gpu(self) -> int:
        """Bytes the renderer uploads for the model: weight texture and grid textures."""
        return self.weight_texture_bytes + self.grid_texture_bytes

    @classmethod
    def of(cls, model: ModelFile, path: str | os.PathLike[str] | None = None) -> ModelCost:
        """The cost of ``model``; ``path``: its file, for :attr:`bytes_on_disk`. An invalid model or a path that is
        not a readable file is one :class:`GratNetError`."""
        model = validated(model)
        features = model.grid_feature_count
        levels = [np.shape(grid) for grid in model.grids]
        reads = sum(GRID_CORNERS * int(shape[-1]) for shape in levels)  # 8 corners of each level's 3-D cell
        spec = model.encoding
        return cls(
            mlp_macs=model.macs_per_evaluation,
            grid_interpolation_macs=GRID_CORNERS * features,
            encoding_terms=2 * (spec.groups * spec.frequencies + spec.t_frequencies),
            grid_values_read=reads,
            weight_texture_bytes=weight_texture_bytes(model.layer_sizes),
            grid_texture_bytes=grid_texture_bytes(model.grids),
            bytes_on_disk=None if path is None else _file_size(path),
        )

    @classmethod
    def of_file(cls, path: str | os.PathLike[str]) -> ModelCost:
        """The cost of the model file at ``path`` (loaded and checked by :func:`gratnet.modelfile.load_model`)."""
        return cls.of(load_model(path), path)

    def to_dict(self) -> dict[str, int | None]:
        """Every figure by name, units in the names (JSON-ready)."""
        return {
            "macs_per_pixel": self.macs_per_pixel,
            "mlp_macs_per_pixel": self.mlp_macs,
            "grid_interpolation_macs_per_pixel": self.grid_interpolation_macs,
            "encoding_terms_per_pixel": self.encoding_terms,
            "grid_values_read_per_pixel": self.grid_values_read,
            "bytes_on_disk": self.bytes_on_disk,
            "bytes_gpu": self.bytes_gpu,
            "weight_texture_bytes_gpu": self.weight_texture_bytes,
            "grid_texture_bytes_gpu": self.grid_texture_bytes,
        }

    def summary(self) -> str:
        """One line for people, e.g. '5,752 MACs/pixel (5,000 MLP + 752 grid), 166 sin/cos, 192 grid values read,
        6.25 MB on disk, 7.1 MB on the GPU' (MB = 10⁶ bytes; the disk part only when the file size is known)."""
        parts = [f"{self.macs_per_pixel:,} MACs/pixel ({self.mlp_macs:,} MLP + {self.grid_interpolation_macs:,} grid)",
                 f"{self.encoding_terms:,} sin/cos", f"{self.grid_values_read:,} grid values read"]
        if self.bytes_on_disk is not None:
            parts.append(f"{megabytes(self.bytes_on_disk)} MB on disk")
        parts.append(f"{megabytes(self.bytes_gpu)} MB on the GPU")
        return ", ".join(parts)


def megabytes(count: int) -> str:
    """``count`` bytes in decimal megabytes, 3 significant digits ('6.25', '0.0471')."""
    return f"{count / MEGABYTE:.3g}"


def _file_size(path: str | os.PathLike[str]) -> int:
    source = Path(path)
    if not source.is_file():
        raise GratNetError(f"model file {source} does not exist or is not a regular file: cannot count its bytes")
    try:
        return source.stat().st_size
    except OSError as error:
        raise GratNetError(f"cannot read the size of model file {source}: {error.strerror or error}") from error
