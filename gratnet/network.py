"""The network's arithmetic on plain arrays: activations, the dense forward pass, and the weight texture the
GLSL shader reads (its layout, the packing, and an emulator of the shader's loop).

:mod:`gratnet.modelfile` applies these to a model file's weights; this module knows no file and no
:class:`~gratnet.modelfile.ModelFile`. numpy only (never torch).

Texture layout (a contract with the GLSL shader), for layer ``k`` with ``inputs`` → ``outputs``:
``in_blocks = ceil(inputs / 4)``, ``out_blocks = ceil(outputs / 4)``; the layer occupies rows
``row_offset_k … row_offset_k + out_blocks − 1``. Row ``row_offset_k + o`` holds output block ``o``
(outputs ``4o … 4o+3``): texel ``(row, 4i + j)`` is column ``j`` of the 4×4 weight block of input block
``i``, i.e. ``(W[4o, 4i+j], W[4o+1, 4i+j], W[4o+2, 4i+j], W[4o+3, 4i+j])``, so that
``mat4(t0, t1, t2, t3) * x_i`` is the block's contribution; texel ``(row, 4·in_blocks)`` is the bias
``vec4``. Padding (inputs/outputs beyond the layer's size) is 0. ``W = max(4·in_blocks + 1)``,
``H = Σ out_blocks``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from gratnet.codes import HIDDEN, OUTPUT
from gratnet.errors import GratNetError

__all__ = [
    "ACTIVATIONS",
    "LEAKY_RELU_SLOPE",
    "OUTPUTS",
    "OUTPUT_ACTIVATIONS",
    "check_choice",
    "dense_forward",
    "activate_hidden",
    "activate_output",
    "pack_weights",
    "texture_forward",
    "texture_layout",
]

#: Hidden-layer activations. ``leaky_relu`` has negative slope :data:`LEAKY_RELU_SLOPE`.
ACTIVATIONS = HIDDEN.names  # gratnet.codes: the names, their GLSL codes and expressions
#: Output activations: ``clamp`` clips to [0, 1], ``sigmoid`` is 1 / (1 + e^−x), ``none`` is the identity.
OUTPUT_ACTIVATIONS = OUTPUT.names
LEAKY_RELU_SLOPE = 0.01
#: Number of network outputs: the three range-transformed CIE XYZ channels.
OUTPUTS = 3


def check_choice(value: object, choices: tuple[str, ...], what: str, where: str) -> str:
    """``value`` when it is one of ``choices``, else a GratNetError naming ``where`` and ``what``."""
    if not isinstance(value, str) or value not in choices:
        raise GratNetError(f"{where}: unknown {what} {value!r}; choose one of {', '.join(choices)}")
    return value


# --------------------------------------------------------------------------------------------------
# Evaluation
# --------------------------------------------------------------------------------------------------


def _sigmoid(x: np.ndarray) -> np.ndarray:
    """Logistic function 1 / (1 + e^−x), written with tanh so that it never overflows."""
    return 0.5 * (1.0 + np.tanh(0.5 * x))


def activate_hidden(x: np.ndarray, name: str) -> np.ndarray:
    """A hidden layer's activation ``name`` (:data:`ACTIVATIONS`) applied elementwise."""
    if name == "relu":
        return np.maximum(x, 0.0)
    if name == "leaky_relu":
        return np.where(x > 0.0, x, LEAKY_RELU_SLOPE * x)
    if name == "silu":
        return x * _sigmoid(x)
    raise GratNetError(f"unknown hidden activation {name!r}; choose one of {', '.join(ACTIVATIONS)}")


def activate_output(x: np.ndarray, name: str) -> np.ndarray:
    """The output activation ``name`` (:data:`OUTPUT_ACTIVATIONS`) applied elementwise."""
    if name == "clamp":
        return np.clip(x, 0.0, 1.0)
    if name == "sigmoid":
        return _sigmoid(x)
    if name == "none":
        return x
    raise GratNetError(f"unknown output activation {name!r}; choose one of {', '.join(OUTPUT_ACTIVATIONS)}")


def _as_batch(encoded: object, width: int) -> tuple[np.ndarray, tuple[int, ...]]:
    array = np.asarray(encoded, dtype=np.float64)
    if array.ndim < 1 or array.shape[-1] != width:
        raise GratNetError(f"network input must have shape (…, {width}), got {array.shape}")
    return array.reshape(-1, width), array.shape[:-1]


def dense_forward(weights: Sequence[np.ndarray], biases: Sequence[np.ndarray], activation: str,
                  output_activation: str, encoded: object) -> np.ndarray:
    """The fully connected network on inputs ``(…, inputs)``, in ``float64``: ``weights[k]`` is ``(out, in)``
    (``torch.nn.Linear``'s layout), the hidden ``activation`` after every layer but the last,
    ``output_activation`` after the last. Returns ``(…, outputs)`` (range-transformed XYZ for a GratNet model)."""
    x, batch_shape = _as_batch(encoded, int(np.shape(weights[0])[1]))
    last = len(weights) - 1
    for k, (weight, bias) in enumerate(zip(weights, biases, strict=True)):
        x = x @ weight.astype(np.float64).T + bias.astype(np.float64)
        x = activate_output(x, output_activation) if k == last else activate_hidden(x, activation)
    return x.reshape(*batch_shape, x.shape[-1])


# --------------------------------------------------------------------------------------------------
# The weight texture (the contract with the GLSL shader)
# --------------------------------------------------------------------------------------------------


def texture_layout(layer_sizes: list[int]) -> list[dict[str, int]]:
    """Where each layer lies in the weight texture (see the module docstring).

    Returns one dict per linear layer ``k`` with ``row_offset`` (first texture row of the layer),
    ``in_blocks = ceil(inputs / 4)``, ``out_blocks = ceil(outputs / 4)``, ``inputs`` and ``outputs``
    (the layer's true widths). Layers are stacked top to bottom in order, with no gaps.
    """
    layout = []
    row = 0
    for inputs, outputs in zip(layer_sizes[:-1], layer_sizes[1:], strict=False):
        in_blocks, out_blocks = -(-int(inputs) // 4), -(-int(outputs) // 4)
        layout.append(
            {"row_offset": row, "in_blocks": in_blocks, "out_blocks": out_blocks,
             "inputs": int(inputs), "outputs": int(outputs)}
        )
        row += out_blocks
    return layout


def pack_weights(weights: list[np.ndarray], biases: list[np.ndarray], layout: list[dict[str, int]]) -> np.ndarray:
    """Pack already-validated ``float32`` weights (``(out, in)`` each) and biases into the ``(H, W, 4)`` texture
    of ``layout`` (:func:`texture_layout`)."""
    width = max(4 * entry["in_blocks"] + 1 for entry in layout)
    height = sum(entry["out_blocks"] for entry in layout)
    texture = np.zeros((height, width, 4), dtype=np.float32)
    for weight, bias, entry in zip(weights, biases, layout, strict=True):
        row, in_blocks, out_blocks = entry["row_offset"], entry["in_blocks"], entry["out_blocks"]
        padded = np.zeros((4 * out_blocks, 4 * in_blocks), dtype=np.float32)
        padded[: entry["outputs"], : entry["inputs"]] = weight
        # texture[row + o, c, r] = padded[4o + r, c]: texel c = 4i + j is column j of block (o, i).
        texture[row : row + out_blocks, : 4 * in_blocks, :] = padded.reshape(out_blocks, 4, 4 * in_blocks).transpose(
            0, 2, 1
        )
        padded_bias = np.zeros(4 * out_blocks, dtype=np.float32)
        padded_bias[: entry["outputs"]] = bias
        texture[row : row + out_blocks, 4 * in_blocks, :] = padded_bias.reshape(out_blocks, 4)
    return texture


def texture_forward(
    texture: np.ndarray,
    layout: list[dict[str, int]],
    activation: str,
    output_activation: str,
    encoded: np.ndarray,
    dtype: type[np.floating] | np.dtype = np.float64,
) -> np.ndarray:
    """Shader emulator: evaluate the MLP reading ONLY the packed texture, block by block like the GLSL.

    For each layer (``row_offset``, ``in_blocks``, ``out_blocks`` from ``layout``) and output block
    ``o``, the shader does::

        vec4 acc = texelFetch(weights, ivec2(4 * in_blocks, row_offset + o), 0);          // bias
        for (int i = 0; i < in_blocks; ++i)
            acc += mat4(texelFetch(weights, ivec2(4 * i + 0, row_offset + o), 0),
                        texelFetch(weights, ivec2(4 * i + 1, row_offset + o), 0),
                        texelFetch(weights, ivec2(4 * i + 2, row_offset + o), 0),
                        texelFetch(weights, ivec2(4 * i + 3, row_offset + o), 0)) * x[i];
        y[o] = activation(acc);

    where ``x[i]`` is the ``vec4`` of inputs ``4i … 4i+3`` (zero beyond the layer's inputs). Here the
    same sums are computed for all points at once: ``acc[n, o, r] = bias[o, r] + Σ_i Σ_j
    texel(o, 4i+j)[r] · x[n, i, j]`` (``mat4 * vec4`` = Σ_j column_j · x_j).

    Args:
        texture: ``(H, W, 4)`` packed weights (:func:`pack_weights`, :func:`gratnet.modelfile.pack_texture`).
        layout: the per-layer layout dicts (:func:`texture_layout`).
        activation, output_activation: as in :class:`gratnet.modelfile.ModelFile`.
        encoded: ``(…, layout[0]["inputs"])`` encoded inputs.
        dtype: arithmetic precision; ``float64`` (default) for exact comparisons, ``float32`` to
            mimic the GPU's precision.

    Returns:
        ``(…, layout[-1]["outputs"])`` network outputs after the output activation, in ``dtype``.
    """
    check_choice(activation, ACTIVATIONS, "hidden activation", "texture_forward")
    check_choice(output_activation, OUTPUT_ACTIVATIONS, "output activation", "texture_forward")
    texture = np.asarray(texture)
    if texture.ndim != 3 or texture.shape[2] != 4:
        raise GratNetError(f"weight texture must have shape (H, W, 4), got {texture.shape}")
    if not layout:
        raise GratNetError("texture layout has no layers")
    dtype = np.dtype(dtype)
    x, batch_shape = _as_batch(encoded, int(layout[0]["inputs"]))
    x = x.astype(dtype)
    last = len(layout) - 1
    for k, entry in enumerate(layout):
        row, in_blocks, out_blocks = entry["row_offset"], entry["in_blocks"], entry["out_blocks"]
        if row + out_blocks > texture.shape[0] or 4 * in_blocks + 1 > texture.shape[1]:
            raise GratNetError(f"texture layout of layer {k} ({entry}) does not fit a {texture.shape} texture")
        # The layer's input vector, padded with zeros to in_blocks vec4s.
        padded = np.zeros((x.shape[0], 4 * in_blocks), dtype=dtype)
        width = min(x.shape[1], 4 * in_blocks)
        padded[:, :width] = x[:, :width]
        inputs = padded.reshape(-1, in_blocks, 4)  # [n, i, j]
        band = texture[row : row + out_blocks].astype(dtype)
        blocks = band[:, : 4 * in_blocks, :].reshape(out_blocks, in_blocks, 4, 4)  # [o, i, j (column), r (row)]
        bias = band[:, 4 * in_blocks, :]  # [o, r]
        accumulated = bias[None, :, :] + np.einsum("oijr,nij->nor", blocks, inputs)
        y = accumulated.reshape(-1, 4 * out_blocks)
        y = activate_output(y, output_activation) if k == last else activate_hidden(y, activation)
        x = y if k == last else y.astype(dtype)
    outputs = int(layout[-1]["outputs"])
    return x[:, :outputs].reshape(*batch_shape, outputs)
