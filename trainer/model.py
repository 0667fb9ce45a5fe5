"""The funnel MLP (torch): widest layer first, each next ≈ previous/φ, down to 16, then 3 outputs.

The paper's default (163, 464, 288, 176, 108, 68, 40, 24, 16, 3) is ``funnel_sizes(464)``: 464/φᵏ
rounded to a multiple of 4 (which also fills the shader's vec4 blocks exactly).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch
from torch import nn

from gratnet.codes import HIDDEN, OUTPUT
from gratnet.encoding import EncodingSpec, encode
from gratnet.errors import GratNetError
from gratnet.featuregrid import check_interpolation, smoothstep_coordinates
from gratnet.modelfile import ModelFile

GOLDEN_RATIO = (1.0 + math.sqrt(5.0)) / 2.0


def funnel_sizes(widest: int, narrowest: int = 16, multiple: int = 4) -> list[int]:
    """Hidden widths widest, widest/φ, widest/φ², … rounded to ``multiple``, ending at ``narrowest``."""
    if widest < narrowest or narrowest < 1:
        raise GratNetError(f"a funnel needs widest ≥ narrowest ≥ 1, got {widest}, {narrowest}")
    sizes = []
    for step in range(64):
        width = max(narrowest, multiple * round(widest / GOLDEN_RATIO**step / multiple))
        sizes.append(width)
        if width <= narrowest:
            break
    return sizes


# Hidden widths of the paper's network sizes (the input width comes from the encoding, the output is 3).
PRESETS: dict[str, list[int]] = {
    "paper": funnel_sizes(464),  # 464-288-176-108-68-40-24-16: the paper's default (~290k parameters)
    "funnel-176": funnel_sizes(176),  # 176-108-68-40-24-16: the widest funnel within 60k parameters
    "medium": [280, 100, 48, 16],
    "small": [108, 66, 40, 24],
    "tiny": [21, 21],
}


def parse_hidden(preset: str, hidden: str = "") -> list[int]:
    """Hidden widths from a preset name, or from an explicit comma list (which wins)."""
    if hidden:
        try:
            sizes = [int(part) for part in hidden.split(",") if part.strip()]
        except ValueError:
            raise GratNetError(
                f"--hidden must be comma-separated widths such as 108,66,40,24; got {hidden!r}"
            ) from None
        if not sizes or min(sizes) < 1:
            raise GratNetError(f"--hidden widths must be positive, got {hidden!r}")
        return sizes
    if preset not in PRESETS:
        raise GratNetError(f"--preset {preset!r} is unknown; choose one of {', '.join(PRESETS)}")
    return list(PRESETS[preset])


#: The hidden activations the trainer builds, and the output activations (what the runtime applies last).
ACTIVATIONS = tuple(sorted(HIDDEN.names, key=lambda name: name != "silu"))  # gratnet.codes; the measured best first
OUTPUT_ACTIVATIONS = OUTPUT.names


def check_network(preset: str, hidden: str, activation: str, output_activation: str) -> list[int]:
    """The hidden widths of a training's network; its options checked first (one GratNetError naming the flag),
    so that a bad one is refused before any work, not when the network is built."""
    if activation not in ACTIVATIONS:
        raise GratNetError(f"--activation must be one of {', '.join(ACTIVATIONS)}; got {activation!r}")
    if output_activation not in OUTPUT_ACTIVATIONS:
        raise GratNetError(f"--output-activation must be one of {', '.join(OUTPUT_ACTIVATIONS)}; "
                           f"got {output_activation!r}")
    return parse_hidden(preset, hidden)


def _activation(name: str) -> nn.Module:
    if name == "relu":
        return nn.ReLU()
    if name == "leaky_relu":
        return nn.LeakyReLU(0.01)
    if name == "silu":
        return nn.SiLU()
    raise GratNetError(f"unknown activation {name!r}; choose {', '.join(ACTIVATIONS)}")


class FunnelMLP(nn.Module):
    """Linear layers with a hidden activation; 3 outputs in the range-transformed domain.

    ``forward`` returns raw outputs (what the loss sees); :meth:`predict` applies the output
    activation exactly as the runtime does ('clamp' clips to [0, 1], 'sigmoid', or 'none').
    """

    def __init__(
        self, inputs: int, hidden: list[int], activation: str = "relu", output_activation: str = "clamp"
    ) -> None:
        super().__init__()
        sizes = [inputs, *hidden, 3]
        layers: list[nn.Module] = []
        for index, (fan_in, fan_out) in enumerate(zip(sizes[:-1], sizes[1:], strict=True)):
            layers.append(nn.Linear(fan_in, fan_out))
            if index < len(sizes) - 2:
                layers.append(_activation(activation))
        self.network = nn.Sequential(*layers)
        self.sizes = sizes
        self.activation = activation
        if output_activation not in OUTPUT_ACTIVATIONS:
            raise GratNetError(f"unknown output activation {output_activation!r}; choose "
                               f"{', '.join(OUTPUT_ACTIVATIONS)}")
        self.output_activation = output_activation

    def forward(self, encoded: torch.Tensor) -> torch.Tensor:
        """Raw outputs (…, 3); for 'sigmoid' the sigmoid is part of the model and applied here."""
        raw = self.network(encoded)
        return torch.sigmoid(raw) if self.output_activation == "sigmoid" else raw

    def predict(self, encoded: torch.Tensor) -> torch.Tensor:
        """Outputs as the runtime computes them (clamped to [0, 1] for 'clamp')."""
        out = self.forward(encoded)
        return out.clamp(0.0, 1.0) if self.output_activation == "clamp" else out

    @property
    def parameter_count(self) -> int:
        """Number of trainable parameters (weights and biases)."""
        return sum(parameter.numel() for parameter in self.parameters())

    def linear_layers(self) -> list[nn.Linear]:
        """The Linear layers in order."""
        return [layer for layer in self.network if isinstance(layer, nn.Linear)]

    def to_model_file(self, **fields: Any) -> ModelFile:
        """A runtime model file of these weights; ``fields`` gives encoding, range, scheme, metadata."""
        layers = self.linear_layers()
        return ModelFile(
            layer_sizes=list(self.sizes),
            weights=[layer.weight.detach().cpu().numpy().astype(np.float32) for layer in layers],
            biases=[layer.bias.detach().cpu().numpy().astype(np.float32) for layer in layers],
            activation=self.activation,
            output_activation=self.output_activation,
            **fields,
        )


class GridNetwork(nn.Module):
    """Learned feature grids → (features, encoding) → a funnel MLP (docs/physics.md "Feature-grid network").

    Each level is a dense grid of ``C`` features over the network coordinates, stored ``(C, T, R, R)`` for
    ``grid_sample`` (``align_corners=True``: node ``i`` of ``N`` sits at ``c = −1 + 2i/(N − 1)``, as in
    :mod:`gratnet.featuregrid`, which the runtime uses and a parity test ties to this). Unlike
    :class:`FunnelMLP`, ``forward`` and ``predict`` take network coordinates ``(N, 3)``, not encoded inputs.
    """

    def __init__(self, encoding: EncodingSpec, shapes: list[tuple[int, int, int, int]], hidden: list[int],
                 activation: str = "silu", output_activation: str = "clamp", init: float = 1e-4,
                 grid_dtype: str = "float16", interpolation: str = "linear") -> None:
        super().__init__()
        self.encoding = encoding
        self.grid_dtype = grid_dtype
        self.interpolation = check_interpolation(interpolation)
        self.grids = nn.ParameterList(
            [nn.Parameter(torch.empty(c, t, r_v, r_u).uniform_(-init, init)) for t, r_v, r_u, c in shapes]
        )
        self.mlp = FunnelMLP(sum(shape[3] for shape in shapes) + encoding.features, hidden, activation,
                             output_activation)
        self.sizes = self.mlp.sizes
        self.activation = activation
        self.output_activation = output_activation

    def features(self, coordinates: torch.Tensor) -> torch.Tensor:
        """Trilinearly interpolated features of every level, level 0 first: (N, 3) → (N, Σ C)."""
        # grid_sample's (x, y, z) index (W, H, D) = (u, v, t): exactly the order of the network coordinates.
        flat = coordinates.reshape(-1, 3)
        parts = []
        for grid in self.grids:
            # Smoothstep: the same trilinear lookup at coordinates moved within their cell (gratnet.featuregrid).
            moved = (smoothstep_coordinates(flat, (grid.shape[3], grid.shape[2], grid.shape[1]))
                     if self.interpolation == "smoothstep" else flat)
            parts.append(nn.functional.grid_sample(grid[None], moved.reshape(1, -1, 1, 1, 3), mode="bilinear",
                                                   padding_mode="border", align_corners=True)[0, :, :, 0, 0].T)
        return torch.cat(parts, dim=-1)

    def inputs(self, coordinates: torch.Tensor) -> torch.Tensor:
        """The MLP's input: grid features, then the sinusoidal encoding."""
        return torch.cat([self.features(coordinates), encode(coordinates, self.encoding)], dim=-1)

    def forward(self, coordinates: torch.Tensor) -> torch.Tensor:
        """Raw outputs (…, 3) at network coordinates (…, 3) (see :meth:`FunnelMLP.forward`)."""
        return self.mlp(self.inputs(coordinates))

    def predict(self, coordinates: torch.Tensor) -> torch.Tensor:
        """Outputs as the runtime computes them (see :meth:`FunnelMLP.predict`)."""
        return self.mlp.predict(self.inputs(coordinates))

    @property
    def parameter_count(self) -> int:
        """Trainable parameters of the MLP (the grids are counted in bytes: :attr:`grid_bytes`)."""
        return self.mlp.parameter_count

    @property
    def grid_bytes(self) -> int:
        """Bytes of the grids as stored in the model file (``grid_dtype``)."""
        return sum(grid.numel() for grid in self.grids) * np.dtype(self.grid_dtype).itemsize

    def to_model_file(self, **fields: Any) -> ModelFile:
        """A runtime model file: the MLP's weights and the grids, ``(T, R, R, C)`` in ``grid_dtype``."""
        model_file = self.mlp.to_model_file(**fields)
        model_file.grids = [grid.detach().cpu().permute(1, 2, 3, 0).contiguous().numpy().astype(self.grid_dtype)
                            for grid in self.grids]
        model_file.grid_interpolation = self.interpolation
        return model_file


def log_cosh_loss(prediction: torch.Tensor, target: torch.Tensor, weight: torch.Tensor | None = None) -> torch.Tensor:
    """Mean log(cosh(prediction − target)), computed stably as |d| + softplus(−2|d|) − log 2; with ``weight``
    (one per sample, shape (N,)) the weighted mean Σ w·l / Σ w over the samples."""
    difference = (prediction - target).abs()
    loss = difference + nn.functional.softplus(-2.0 * difference) - math.log(2.0)
    if weight is None:
        return loss.mean()
    return (loss.mean(dim=-1) * weight).sum() / weight.sum()
