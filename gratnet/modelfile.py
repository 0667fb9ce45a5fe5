"""Trained model files: the MLP's weights, its input/output contract and the shader's weight texture.

A *model file* is what the offline stage hands to the runtime: the weights of a fully connected
network (``layer_sizes[0]`` encoded inputs → hidden layers → 3 outputs), the hidden and output
activations, the input encoding (:class:`~gratnet.encoding.EncodingSpec`), the output range transform
(:class:`~gratnet.encoding.RangeSpec`), the volume's sampling scheme (for the key → network-coordinate
transform) and free-form JSON metadata. With these, :func:`evaluate_keys` maps key vectors
``(u, v, w)`` to CIE XYZ exactly as the GLSL shader does.

File layout (a contract; also documented in ``docs/formats.md``, section "Model file (.npz)"):

* one ``.npz`` archive (``np.savez_compressed``: deflated members; files written before 2026-11-25 store them
  uncompressed, ``np.savez``, and read the same) holding
  ``metadata_json`` (0-d unicode array: one JSON object), ``weight_0``, ``weight_1``, … and
  ``bias_0``, ``bias_1``, … (``float32``; ``weight_k`` is ``(out, in)`` like ``torch.nn.Linear``)
  and ``texture`` (``float32``, ``(H, W, 4)``: the packed weights exactly as the shader uploads them);
* the JSON object has the keys ``format`` (``"gratnet-model"``), ``format_version`` (``1``),
  ``layer_sizes``, ``activation``, ``output_activation``, ``encoding``, ``range``, ``scheme``,
  ``texture_layout`` and ``metadata``.

A *feature-grid* model (docs/physics.md "Feature-grid network") has, in addition, ``grid_0``, ``grid_1``, …
(coarse to fine; ``float16`` or ``float32``, all of one dtype; ``(T_l, R_l, R_l, C)``: axes c_t, c_v, c_u,
feature, ``1 ≤ C ≤ 16`` the same for every level, every axis ≥ 2 nodes) and the JSON key ``grid``
(``{"levels": [[T_l, R_l, R_l, C], …], "dtype": "float16"|"float32"}``, and ``"interpolation":
"smoothstep"`` when the grids are interpolated so; absent means ``linear``); such files have ``format_version``
2 (a GratNet that reads only version 1 then says so), and ``layer_sizes[0]`` is ``L·C`` grid features plus
the encoding's features, grid features first. Pure-MLP files stay version 1, unchanged.

The weight texture's layout (a contract with the GLSL shader) is :mod:`gratnet.network`'s.

This module is runtime-side: it needs only numpy and never imports torch.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import zipfile
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import array_api_compat
import numpy as np
import numpy.typing as npt

from gratnet.atomic import atomic_path
from gratnet.codes import SCHEME
from gratnet.encoding import EncodingSpec, RangeSpec, encode, network_coordinates, range_inverse
from gratnet.errors import GratNetError, read_magic
from gratnet.featuregrid import INTERPOLATIONS, MAX_FEATURES, grid_features
from gratnet.jsontext import strict_json
from gratnet.network import (
    ACTIVATIONS,
    LEAKY_RELU_SLOPE,
    OUTPUT_ACTIVATIONS,
    OUTPUTS,
    check_choice,
    dense_forward,
    pack_weights,
    texture_forward,
    texture_layout,
)

__all__ = [
    "ACTIVATIONS",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "LEAKY_RELU_SLOPE",
    "OUTPUT_ACTIVATIONS",
    "SCHEMES",
    "ModelFile",
    "evaluate_keys",
    "load_model",
    "mlp_forward",
    "network_inputs",
    "pack_texture",
    "save_model",
    "texture_forward",
    "texture_layout",
    "validated",
]

FORMAT_NAME = "gratnet-model"
FORMAT_VERSION = 1
#: The format version of feature-grid model files (pure-MLP files keep :data:`FORMAT_VERSION`).
GRID_FORMAT_VERSION = 2
#: Storage dtypes of feature grids.
GRID_DTYPES = ("float16", "float32")

#: Sampling schemes of the source volume (see ``gratnet.encoding.key_to_grid``).
SCHEMES = SCHEME.names

_METADATA_ARRAY = "metadata_json"
_TEXTURE_ARRAY = "texture"
_ZIP_MAGIC = b"PK\x03\x04"
_EMPTY_ZIP_MAGIC = b"PK\x05\x06"
_NPY_MAGIC = b"\x93NUMPY"
_JSON_KEYS = (
    "format",
    "format_version",
    "layer_sizes",
    "activation",
    "output_activation",
    "encoding",
    "range",
    "scheme",
    "texture_layout",
    "metadata",
)
_GRID_KEY = "grid"
_LAYOUT_KEYS = ("row_offset", "in_blocks", "out_blocks", "inputs", "outputs")


@dataclass(eq=False)
class ModelFile:
    """A trained network with everything the runtime needs to evaluate it.

    Attributes:
        layer_sizes: widths of every layer, input first: ``[inputs, hidden…, 3]``, e.g.
            ``[163, 108, 66, 40, 24, 3]``. ``layer_sizes[0]`` must equal ``encoding.features``.
        weights: one ``float32`` array per linear layer; ``weights[k]`` has shape
            ``(layer_sizes[k+1], layer_sizes[k])`` (``torch.nn.Linear`` layout: out × in).
        biases: one ``float32`` array per linear layer; ``biases[k]`` has shape ``(layer_sizes[k+1],)``.
        activation: hidden-layer activation, one of :data:`ACTIVATIONS`.
        output_activation: activation after the last layer, one of :data:`OUTPUT_ACTIVATIONS`.
        encoding: the sinusoidal input encoding the network was trained with.
        range: the range transform of the XYZ targets (network outputs are in that domain).
        scheme: the source volume's sampling scheme (``regular``, ``simple`` or ``simple-max``),
            which defines the key vector → network coordinate transform.
        metadata: JSON-able dict: the source volume's physical parameters, training information, …
        grids: the feature grids of a feature-grid network, coarse to fine, each ``(T, R, R, C)`` ``float16``
            or ``float32`` (see the module docstring); empty (the default) for the paper's pure MLP.
        grid_interpolation: how the grids are interpolated between nodes, one of
            :data:`gratnet.featuregrid.INTERPOLATIONS` (``linear`` for a pure MLP).

    Two model files compare equal when every field is equal and the arrays are bit-identical.
    """

    layer_sizes: list[int]
    weights: list[np.ndarray]
    biases: list[np.ndarray]
    activation: str
    output_activation: str
    encoding: EncodingSpec
    range: RangeSpec
    scheme: str
    metadata: dict[str, Any] = field(default_factory=dict)
    grids: list[np.ndarray] = field(default_factory=list)
    grid_interpolation: str = "linear"

    @property
    def grid_feature_count(self) -> int:
        """Grid features at the network's input: Σ C over the levels (0 for a pure MLP)."""
        return sum(int(np.shape(grid)[-1]) for grid in self.grids)

    @property
    def grid_bytes(self) -> int:
        """Bytes of the stored feature grids (0 for a pure MLP)."""
        return sum(int(np.asarray(grid).nbytes) for grid in self.grids)

    @property
    def parameter_count(self) -> int:
        """Number of weights and biases: Σ (inputs·outputs + outputs) over the linear layers."""
        return sum(a * b + b for a, b in zip(self.layer_sizes[:-1], self.layer_sizes[1:], strict=False))

    @property
    def macs_per_evaluation(self) -> int:
        """Multiply-adds of one network evaluation (one pixel): Σ inputs·outputs over the layers."""
        return sum(a * b for a, b in zip(self.layer_sizes[:-1], self.layer_sizes[1:], strict=False))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, ModelFile):
            return NotImplemented
        return (
            list(self.layer_sizes) == list(other.layer_sizes)
            and _arrays_equal(self.weights, other.weights)
            and _arrays_equal(self.biases, other.biases)
            and self.activation == other.activation
            and self.output_activation == other.output_activation
            and self.encoding == other.encoding
            and self.range == other.range
            and self.scheme == other.scheme
            and self.metadata == other.metadata
            and _arrays_equal(self.grids, other.grids)
            and self.grid_interpolation == other.grid_interpolation
        )

    __hash__ = None  # type: ignore[assignment]  # mutable (holds arrays)


def _arrays_equal(first: list[np.ndarray], second: list[np.ndarray]) -> bool:
    if len(first) != len(second):
        return False
    for a, b in zip(first, second, strict=True):
        a, b = np.asarray(a), np.asarray(b)
        if a.dtype != b.dtype or a.shape != b.shape or a.tobytes() != b.tobytes():
            return False
    return True


# --------------------------------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------------------------------


def _is_int(value: object) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def _check_layer_sizes(sizes: object, where: str) -> list[int]:
    if not isinstance(sizes, (list, tuple)) or not all(_is_int(s) for s in sizes):
        raise GratNetError(f"{where}: layer_sizes must be a list of integers, got {sizes!r}")
    result = [int(s) for s in sizes]
    if len(result) < 2:
        raise GratNetError(f"{where}: layer_sizes needs at least an input and an output width, got {result}")
    if min(result) < 1:
        raise GratNetError(f"{where}: every layer width must be at least 1, got {result}")
    if result[-1] != OUTPUTS:
        raise GratNetError(f"{where}: the last layer must have {OUTPUTS} outputs (X, Y, Z), got {result}")
    return result


def _encoding_from_dict(fields: object, where: str) -> EncodingSpec:
    """An :class:`EncodingSpec` from its JSON form, with every field checked."""
    names = [f.name for f in dataclasses.fields(EncodingSpec) if f.name != "diagonals"]
    if not isinstance(fields, dict) or set(fields) - {"diagonals"} != set(names):
        raise GratNetError(f"{where}: 'encoding' must be an object with exactly the keys {', '.join(names)} "
                           "(and optionally diagonals)")
    diagonals = fields.get("diagonals", True)
    if not isinstance(diagonals, bool):
        raise GratNetError(f"{where}: encoding diagonals must be true or false, got {diagonals!r}")
    frequencies, t_frequencies = fields["frequencies"], fields["t_frequencies"]
    if not _is_int(frequencies) or frequencies < 1 or not _is_int(t_frequencies) or t_frequencies < 0:
        raise GratNetError(
            f"{where}: encoding frequency counts must be integers ≥ 1 (frequencies) and ≥ 0 (t_frequencies), "
            f"got {frequencies!r}, {t_frequencies!r}"
        )
    for name in ("scale", "t_scale"):
        value = fields[name]
        if not _is_number(value) or not math.isfinite(value) or value <= 0:
            raise GratNetError(f"{where}: encoding {name} must be a finite number > 0, got {value!r}")
    return EncodingSpec(int(frequencies), int(t_frequencies), float(fields["scale"]), float(fields["t_scale"]),
                        diagonals)


def _range_from_dict(fields: object, where: str) -> RangeSpec:
    """A :class:`RangeSpec` from its JSON form, with every field checked."""
    names = [f.name for f in dataclasses.fields(RangeSpec)]
    if not isinstance(fields, dict) or sorted(fields) != sorted(names):
        raise GratNetError(f"{where}: 'range' must be an object with exactly the keys {', '.join(names)}")
    for name in ("bits", "power"):
        value = fields[name]
        if not _is_number(value) or not math.isfinite(value):
            raise GratNetError(f"{where}: range {name} must be a finite number, got {value!r}")
    white = fields["white"]
    if (
        not isinstance(white, (list, tuple))
        or len(white) != 3
        or not all(_is_number(c) and math.isfinite(c) and c > 0 for c in white)
    ):
        raise GratNetError(f"{where}: range white must be three finite numbers > 0 (XYZ), got {white!r}")
    try:
        return RangeSpec(
            kind=fields["kind"],
            bits=float(fields["bits"]),
            power=float(fields["power"]),
            white=(float(white[0]), float(white[1]), float(white[2])),
        )
    except GratNetError as error:
        raise GratNetError(f"{where}: {error}") from error


def _plain_metadata(metadata: object, where: str) -> dict[str, Any]:
    """Check that ``metadata`` is a JSON-able dict; return it as plain Python values."""
    if not isinstance(metadata, dict):
        raise GratNetError(f"{where}: model metadata must be a dict, got {type(metadata).__name__}")
    if any(not isinstance(key, str) for key in metadata):
        raise GratNetError(f"{where}: model metadata keys must be strings")
    text = strict_json(metadata, f"{where}: model metadata")
    return json.loads(text)


def _check_parameters(
    label: str, values: object, expected_shape: tuple[int, ...], where: str, *, from_file: bool
) -> np.ndarray:
    """Check one weight or bias array; return it as C-contiguous ``float32``."""
    array = np.asarray(values)
    if from_file:
        if array.dtype != np.float32:
            raise GratNetError(f"{where}: {label} must be float32, got {array.dtype}; the file is corrupt")
    elif array.dtype.kind not in "biuf":
        raise GratNetError(f"{where}: {label} must hold real numbers, got dtype {array.dtype}")
    if array.shape != expected_shape:
        raise GratNetError(
            f"{where}: {label} has shape {array.shape} but layer_sizes call for {expected_shape} "
            f"(weights are (outputs, inputs) like torch.nn.Linear)"
        )
    with np.errstate(over="ignore", invalid="ignore"):
        array = np.ascontiguousarray(array, dtype=np.float32)
    finite = np.isfinite(array)
    if not finite.all():
        count = int(finite.size - np.count_nonzero(finite))
        first = tuple(int(i) for i in np.argwhere(~finite)[0])
        reason = "NaN or inf" if from_file else "NaN, inf, or too large for float32"
        raise GratNetError(
            f"{where}: {label} has {count} non-finite value(s) ({reason}), "
            f"first at index {first}: {array[first]}"
        )
    return array


def validated(model: object, where: str = "model", *, from_file: bool = False) -> ModelFile:
    """Check every field of ``model``; return a copy with ``float32`` arrays and plain lists.

    Raises:
        GratNetError: naming ``where`` and the first problem found.
    """
    if not isinstance(model, ModelFile):
        raise GratNetError(f"{where}: expected a gratnet.modelfile.ModelFile, got {type(model).__name__}")
    sizes = _check_layer_sizes(model.layer_sizes, where)
    activation = check_choice(model.activation, ACTIVATIONS, "hidden activation", where)
    output_activation = check_choice(model.output_activation, OUTPUT_ACTIVATIONS, "output activation", where)
    scheme = check_choice(model.scheme, SCHEMES, "sampling scheme", where)
    if not isinstance(model.encoding, EncodingSpec):
        raise GratNetError(f"{where}: encoding must be a gratnet.encoding.EncodingSpec")
    if not isinstance(model.range, RangeSpec):
        raise GratNetError(f"{where}: range must be a gratnet.encoding.RangeSpec")
    encoding = _encoding_from_dict(model.encoding.as_dict(), where)
    range_spec = _range_from_dict(dataclasses.asdict(model.range), where)
    grids = _check_grids(model.grids, where, from_file=from_file)
    interpolation = model.grid_interpolation
    if interpolation not in INTERPOLATIONS or (interpolation != "linear" and not grids):
        raise GratNetError(f"{where}: grid interpolation must be one of {', '.join(INTERPOLATIONS)} (linear for a "
                           f"pure MLP), got {interpolation!r}")
    grid_width = sum(grid.shape[-1] for grid in grids)
    if sizes[0] != encoding.features + grid_width:
        extra = f" plus {grid_width} grid features" if grids else ""
        raise GratNetError(
            f"{where}: layer_sizes[0] is {sizes[0]} but the encoding (L = {encoding.frequencies}, "
            f"L_t = {encoding.t_frequencies}) produces {encoding.features} features{extra}"
        )
    layers = len(sizes) - 1
    for name, values in (("weights", model.weights), ("biases", model.biases)):
        if not isinstance(values, (list, tuple)) or len(values) != layers:
            count = len(values) if isinstance(values, (list, tuple)) else type(values).__name__
            raise GratNetError(f"{where}: layer_sizes {sizes} call for {layers} {name} arrays, got {count}")
    weights = [
        _check_parameters(f"weight_{k}", model.weights[k], (sizes[k + 1], sizes[k]), where, from_file=from_file)
        for k in range(layers)
    ]
    biases = [
        _check_parameters(f"bias_{k}", model.biases[k], (sizes[k + 1],), where, from_file=from_file)
        for k in range(layers)
    ]
    return ModelFile(
        layer_sizes=sizes,
        weights=weights,
        biases=biases,
        activation=activation,
        output_activation=output_activation,
        encoding=encoding,
        range=range_spec,
        scheme=scheme,
        metadata=_plain_metadata(model.metadata, where),
        grids=grids,
        grid_interpolation=interpolation,
    )


def _check_grids(grids: object, where: str, *, from_file: bool) -> list[np.ndarray]:
    """Check the feature grids (module docstring); return them C-contiguous, dtype kept."""
    if not isinstance(grids, (list, tuple)):
        raise GratNetError(f"{where}: grids must be a list of arrays, got {type(grids).__name__}")
    checked: list[np.ndarray] = []
    for level, values in enumerate(grids):
        array = np.asarray(values)
        label = f"grid_{level}"
        if array.dtype.name not in GRID_DTYPES:
            corrupt = "; the file is corrupt" if from_file else ""
            raise GratNetError(f"{where}: {label} must be float16 or float32, got {array.dtype}{corrupt}")
        if array.ndim != 4 or min(array.shape[:3]) < 2 or not 1 <= array.shape[3] <= MAX_FEATURES:
            raise GratNetError(f"{where}: {label} has shape {array.shape}; a feature grid is (T, R, R, C) with "
                               f"T, R ≥ 2 nodes and 1 ≤ C ≤ {MAX_FEATURES} features (the shader reads a level "
                               f"as ceil(C/4) RGBA textures)")
        if array.shape[1] != array.shape[2]:
            raise GratNetError(f"{where}: {label} has shape {array.shape}; u* and v* need the same node count")
        if checked and (array.dtype != checked[0].dtype or array.shape[3] != checked[0].shape[3]):
            raise GratNetError(f"{where}: {label} is {array.dtype} with {array.shape[3]} features, but grid_0 is "
                               f"{checked[0].dtype} with {checked[0].shape[3]}: every level must match")
        finite = np.isfinite(array)
        if not finite.all():
            raise GratNetError(f"{where}: {label} has {int(finite.size - np.count_nonzero(finite))} non-finite "
                               f"value(s) (NaN or inf)")
        checked.append(np.ascontiguousarray(array))
    return checked


# --------------------------------------------------------------------------------------------------
# Texture packing (the contract with the GLSL shader)
# --------------------------------------------------------------------------------------------------


def pack_texture(model: ModelFile) -> tuple[np.ndarray, list[dict[str, int]]]:
    """Pack the weights and biases into the shader's RGBA32F weight texture.

    Returns:
        ``(texture, layout)``: ``texture`` is ``float32`` of shape ``(H, W, 4)`` (row ``y``, column
        ``x``, RGBA), to be uploaded as is (array row 0 = texture row ``y = 0`` of ``texelFetch``);
        ``layout`` is :func:`texture_layout` of the model's layer sizes.

    Raises:
        GratNetError: the model is invalid (shapes, non-finite values, …).
    """
    valid = validated(model)
    layout = texture_layout(valid.layer_sizes)
    return pack_weights(valid.weights, valid.biases, layout), layout


# --------------------------------------------------------------------------------------------------
# Evaluation
# --------------------------------------------------------------------------------------------------


def mlp_forward(model: ModelFile, encoded: np.ndarray) -> np.ndarray:
    """Evaluate the network on encoded inputs, in ``float64``.

    Args:
        model: the network.
        encoded: ``(…, layer_sizes[0])`` encoded network inputs (see :func:`gratnet.encoding.encode`).

    Returns:
        ``float64`` ``(…, 3)``: the network outputs after the output activation, i.e. range-transformed
        XYZ (``range_inverse`` turns them into CIE XYZ).
    """
    return _forward(validated(model), encoded)


def _forward(valid: ModelFile, encoded: object) -> np.ndarray:
    """:func:`mlp_forward` of an already validated model."""
    return dense_forward(valid.weights, valid.biases, valid.activation, valid.output_activation, encoded)


def network_inputs(model: ModelFile, coordinates: Any, grids: Sequence[Any] | None = None) -> Any:
    """The network's input at network coordinates ``(…, 3)``: the grid features (feature-grid models;
    :func:`gratnet.featuregrid.grid_features`) followed by the encoding (:func:`gratnet.encoding.encode`).

    numpy arrays or torch tensors alike (array-api-compat); ``grids``: the model's grids as arrays of the
    coordinates' kind and device (default: ``model.grids``, numpy), e.g. torch tensors for a torch evaluation."""
    encoded = encode(coordinates, model.encoding)
    grids = model.grids if grids is None else grids
    if not grids:
        return encoded
    xp = array_api_compat.array_namespace(coordinates)
    return xp.concat([grid_features(grids, coordinates, model.grid_interpolation), encoded], axis=-1)


def evaluate_keys(model: ModelFile, u: npt.ArrayLike, v: npt.ArrayLike, w: npt.ArrayLike) -> np.ndarray:
    """CIE XYZ predicted for key vectors ``(u, v, w)``: the whole runtime pipeline, in ``float64``.

    ``network_coordinates(u, v, w, scheme)`` → :func:`network_inputs` (``encode``, after the grid
    features of a feature-grid model) → :func:`mlp_forward` → ``range_inverse``.

    Args:
        u, v, w: key vector components (dimensionless direction-cosine sums as in docs/physics.md;
            ``u, v ∈ [−2, 2]``, ``w ∈ [−2, 0]``); numpy arrays or scalars, broadcast together.

    Returns:
        ``float64`` ``(…, 3)``: CIE XYZ of the D65-normalised reflectance (a flat mirror's specular
        peak has ``Y = 1``), ``…`` the broadcast shape of ``u, v, w``.
    """
    valid = validated(model)
    u, v, w = np.broadcast_arrays(*(np.asarray(c, dtype=np.float64) for c in (u, v, w)))
    coordinates = network_coordinates(u, v, w, valid.scheme)
    return range_inverse(_forward(valid, network_inputs(valid, coordinates)), valid.range)


# --------------------------------------------------------------------------------------------------
# Saving
# --------------------------------------------------------------------------------------------------


def _header(model: ModelFile, layout: list[dict[str, int]]) -> dict[str, Any]:
    header: dict[str, Any] = {
        "format": FORMAT_NAME,
        "format_version": GRID_FORMAT_VERSION if model.grids else FORMAT_VERSION,
        "layer_sizes": list(model.layer_sizes),
        "activation": model.activation,
        "output_activation": model.output_activation,
        "encoding": model.encoding.as_dict(),
        "range": {**dataclasses.asdict(model.range), "white": list(model.range.white)},
        "scheme": model.scheme,
        "texture_layout": layout,
        "metadata": model.metadata,
    }
    if model.grids:
        header[_GRID_KEY] = {"levels": [list(grid.shape) for grid in model.grids], "dtype": model.grids[0].dtype.name}
        if model.grid_interpolation != "linear":  # absent means linear: older files read unchanged
            header[_GRID_KEY]["interpolation"] = model.grid_interpolation
    return header


def save_model(path: str | os.PathLike[str], model: ModelFile) -> None:
    """Write ``model`` to ``path`` as a GratNet model ``.npz`` (layout in the module docstring).

    The model is validated first (layer sizes, activations, scheme, encoding width, weight and bias
    shapes, finite values after casting to ``float32``, JSON-able metadata); the file is written
    atomically, so on any failure nothing appears at ``path`` (an existing file there is untouched).
    The path is used as given (no ``.npz`` is appended).

    Raises:
        GratNetError: invalid model, or the file cannot be written.
    """
    target = Path(path)
    valid = validated(model, f"cannot save model {target}")
    layout = texture_layout(valid.layer_sizes)
    arrays: dict[str, np.ndarray] = {
        _METADATA_ARRAY: np.array(json.dumps(_header(valid, layout), allow_nan=False, ensure_ascii=False)),
    }
    for k, (weight, bias) in enumerate(zip(valid.weights, valid.biases, strict=True)):
        arrays[f"weight_{k}"] = weight
        arrays[f"bias_{k}"] = bias
    arrays[_TEXTURE_ARRAY] = pack_weights(valid.weights, valid.biases, layout)
    for level, grid in enumerate(valid.grids):
        arrays[f"grid_{level}"] = grid
    with atomic_path(target) as temporary:
        try:
            with temporary.open("wb") as handle:
                # Deflated: float16 grids shrink 7–10 %, MLP weights 24 %; the tracked models must fit the
                # working tree a lent GPU machine receives (64 MiB), and np.load reads either kind. mypy
                # checks **arrays against the stub's `allow_pickle: bool`, a keyword older supported numpy lacks.
                np.savez_compressed(handle, **arrays)  # type: ignore[arg-type]  # **arrays vs allow_pickle
        except OSError as error:
            raise GratNetError(f"cannot write model {target}: {error.strerror or error}") from error


def _array_bytes(path: Path) -> dict[str, tuple[str, tuple[int, ...], bytes]]:
    """Every array of a model archive except the JSON header, as raw bytes with dtype and shape."""
    with np.load(path, allow_pickle=False) as archive:
        return {name: (str(archive[name].dtype), archive[name].shape, archive[name].tobytes())
                for name in archive.files if name != _METADATA_ARRAY}


def rewrite_metadata(path: str | os.PathLike[str], metadata: dict[str, Any]) -> None:
    """Replace the ``metadata`` of the model file at ``path`` in place; only its JSON header changes.

    The rewritten file's weights, biases, grids and packed texture are checked to be bit-identical to the
    original's; otherwise the original is put back and a GratNetError raised."""
    import shutil
    import tempfile

    target = Path(path)
    before = _array_bytes(target)
    model = load_model(target)
    with tempfile.TemporaryDirectory() as folder:
        backup = Path(folder) / "original.npz"
        shutil.copy2(target, backup)
        save_model(target, dataclasses.replace(model, metadata=metadata))
        if _array_bytes(target) != before:
            shutil.copy2(backup, target)
            raise GratNetError(f"{target}: the rewritten arrays differ from the original; restored the original")


# --------------------------------------------------------------------------------------------------
# Loading
# --------------------------------------------------------------------------------------------------


def _read_arrays(source: Path) -> dict[str, np.ndarray]:
    """Every array of the ``.npz`` at ``source``, read eagerly so that corruption shows up here."""
    magic = read_magic(source, "model file", 6)
    if magic.startswith(_NPY_MAGIC):
        raise GratNetError(f"{source} is a single .npy array, not a GratNet model file (.npz)")
    if not (magic.startswith(_ZIP_MAGIC) or magic.startswith(_EMPTY_ZIP_MAGIC)):
        raise GratNetError(f"{source} is not a GratNet model file (not an .npz archive)")
    try:
        with np.load(source, allow_pickle=False) as archive:
            return {name: archive[name] for name in archive.files}
    except (zipfile.BadZipFile, zipfile.LargeZipFile, zlib.error, EOFError, ValueError, KeyError, OSError,
            NotImplementedError, RuntimeError) as error:
        raise GratNetError(f"model file {source} is truncated or corrupt: {error}") from error


def _read_header(source: Path, arrays: dict[str, np.ndarray]) -> dict[str, Any]:
    """The decoded ``metadata_json`` object, after the format name and version checks."""
    if _METADATA_ARRAY not in arrays:
        raise GratNetError(f"{source} is not a GratNet model file (no '{_METADATA_ARRAY}' array)")
    text_array = arrays[_METADATA_ARRAY]
    if text_array.shape != () or text_array.dtype.kind != "U":
        raise GratNetError(f"{source}: '{_METADATA_ARRAY}' must be a 0-d string array; the file is corrupt")
    try:
        header = json.loads(str(text_array[()]))
    except ValueError as error:
        raise GratNetError(f"{source}: '{_METADATA_ARRAY}' is not valid JSON: {error}") from error
    if not isinstance(header, dict):
        raise GratNetError(f"{source}: '{_METADATA_ARRAY}' must hold a JSON object")
    if header.get("format") != FORMAT_NAME:
        raise GratNetError(
            f"{source} is not a GratNet model file (format is {header.get('format')!r}, expected {FORMAT_NAME!r})"
        )
    version = header.get("format_version")
    if version not in (FORMAT_VERSION, GRID_FORMAT_VERSION) or not _is_int(version):
        raise GratNetError(
            f"{source} is a {FORMAT_NAME} file of format version {version!r}, but this GratNet reads only "
            f"version {FORMAT_VERSION} (pure MLP) and version {GRID_FORMAT_VERSION} (feature grid); "
            f"read it with the GratNet version that wrote it, "
            f"or re-train with this one"
        )
    required = _JSON_KEYS + ((_GRID_KEY,) if version == GRID_FORMAT_VERSION else ())
    missing = [key for key in required if key not in header]
    if missing:
        raise GratNetError(f"{source}: '{_METADATA_ARRAY}' lacks key(s) {', '.join(missing)}; the file is corrupt")
    return header


def _grid_header(header: dict[str, Any], where: str) -> list[list[int]]:
    """The grid levels' shapes from the header's ``grid`` (version 2), or [] for a pure-MLP file (its
    ``interpolation`` is checked by :func:`validated`)."""
    if header["format_version"] == FORMAT_VERSION:
        if _GRID_KEY in header:
            raise GratNetError(f"{where}: a format version {FORMAT_VERSION} file has a 'grid' entry; "
                               f"the file is corrupt")
        return []
    grid = header[_GRID_KEY]
    levels = grid.get("levels") if isinstance(grid, dict) else None
    if (not isinstance(grid, dict) or sorted(set(grid) - {"interpolation"}) != ["dtype", "levels"]
            or grid["dtype"] not in GRID_DTYPES
            or not isinstance(levels, list) or not levels
            or not all(isinstance(shape, list) and len(shape) == 4 and all(_is_int(n) for n in shape)
                       for shape in levels)):
        raise GratNetError(f"{where}: 'grid' must be {{\"levels\": [[T, R, R, C], …], \"dtype\": \"float16\" or "
                           f"\"float32\"}} with at least one level, got {grid!r}; the file is corrupt")
    return [[int(n) for n in shape] for shape in levels]


def content_digest(model: ModelFile) -> str:
    """SHA-256 (hex) of what a model computes: its weights, biases and grids (as float32 bytes) and its contract
    (layer sizes, activations, scheme, encoding, range, grid interpolation): the key of the caches built from a
    model (gratnet.bounds, gratnet.importance)."""
    import hashlib

    digest = hashlib.sha256()
    for array in (*model.weights, *model.biases, *model.grids):
        digest.update(np.ascontiguousarray(array, dtype=np.float32).tobytes())
    contract = {"layer_sizes": list(model.layer_sizes), "activation": model.activation,
                "output_activation": model.output_activation, "scheme": model.scheme,
                "encoding": model.encoding.as_dict(), "range": dataclasses.asdict(model.range),
                "grid_interpolation": model.grid_interpolation}
    digest.update(json.dumps(contract, sort_keys=True).encode("utf-8"))
    return digest.hexdigest()


def load_model(path: str | os.PathLike[str]) -> ModelFile:
    """Read and fully validate a GratNet model file written by :func:`save_model`.

    Checks the archive, the format name and version, every header field, the presence, dtype
    (``float32``), shape and finiteness of every weight and bias array, that no unexpected arrays
    are present, and that the stored ``texture`` and ``texture_layout`` are exactly what packing the
    weights gives (a mismatch means a corrupt file).

    Returns:
        the :class:`ModelFile` (``float32`` arrays, ``metadata`` decoded from JSON).

    Raises:
        GratNetError: the file is missing, not an ``.npz`` archive, truncated or corrupt, not a
            GratNet model, of another format version (the message names both versions), or
            inconsistent (shapes, NaN / inf, texture mismatch, invalid settings).
    """
    source = Path(path)
    arrays = _read_arrays(source)
    header = _read_header(source, arrays)
    where = f"model file {source}"
    sizes = _check_layer_sizes(header["layer_sizes"], where)
    layers = len(sizes) - 1
    expected = {_METADATA_ARRAY, _TEXTURE_ARRAY} | {f"{kind}_{k}" for kind in ("weight", "bias") for k in range(layers)}
    grid_shapes = _grid_header(header, where)
    expected |= {f"grid_{level}" for level in range(len(grid_shapes))}
    missing = sorted(expected - set(arrays))
    if missing:
        raise GratNetError(f"{where}: lacks array(s) {', '.join(missing)} required by layer_sizes {sizes}")
    unexpected = sorted(set(arrays) - expected)
    if unexpected:
        raise GratNetError(
            f"{where}: has unexpected array(s) {', '.join(unexpected)} for layer_sizes {sizes}; the file is corrupt"
        )
    model = validated(
        ModelFile(
            layer_sizes=sizes,
            weights=[arrays[f"weight_{k}"] for k in range(layers)],
            biases=[arrays[f"bias_{k}"] for k in range(layers)],
            activation=header["activation"],
            output_activation=header["output_activation"],
            encoding=_encoding_from_dict(header["encoding"], where),
            range=_range_from_dict(header["range"], where),
            scheme=header["scheme"],
            metadata=header["metadata"],
            grids=[arrays[f"grid_{level}"] for level in range(len(grid_shapes))],
            grid_interpolation=str(header[_GRID_KEY].get("interpolation", "linear")) if grid_shapes else "linear",
        ),
        where,
        from_file=True,
    )
    stored_shapes = [list(grid.shape) for grid in model.grids]
    if stored_shapes != grid_shapes or (model.grids and model.grids[0].dtype.name != header[_GRID_KEY]["dtype"]):
        raise GratNetError(f"{where}: the grid arrays ({stored_shapes}) do not match the header's grid "
                           f"{header[_GRID_KEY]!r}; the file is corrupt")
    layout = texture_layout(sizes)
    if header["texture_layout"] != layout:
        raise GratNetError(
            f"{where}: texture_layout {header['texture_layout']!r} does not match layer_sizes {sizes} "
            f"(expected {layout!r}); the file is corrupt"
        )
    stored = arrays[_TEXTURE_ARRAY]
    packed = pack_weights(model.weights, model.biases, layout)
    if stored.dtype != np.float32 or stored.shape != packed.shape:
        raise GratNetError(
            f"{where}: texture is {stored.dtype} {stored.shape}, expected float32 {packed.shape}; the file is corrupt"
        )
    if stored.tobytes() != packed.tobytes():
        mismatched = int(np.count_nonzero(np.any(stored.view(np.uint32) != packed.view(np.uint32), axis=-1)))
        raise GratNetError(
            f"{where}: the stored weight texture differs from the weights in {mismatched} texel(s); the file is corrupt"
        )
    return model
