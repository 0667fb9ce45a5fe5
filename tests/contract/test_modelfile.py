"""Tests for gratnet.modelfile and gratnet.network: the model .npz format, the shader's weight texture, the numpy
evaluator."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from gratnet.encoding import EncodingSpec, RangeSpec, encode, network_coordinates
from gratnet.errors import GratNetError
from gratnet.modelfile import (
    FORMAT_NAME,
    FORMAT_VERSION,
    ModelFile,
    evaluate_keys,
    load_model,
    mlp_forward,
    pack_texture,
    save_model,
)
from gratnet.network import ACTIVATIONS, OUTPUT_ACTIVATIONS, texture_forward, texture_layout
from tests.helpers import REPO, flip_in_member

ENCODING = EncodingSpec.for_grid(101, 5)  # 163 features
METADATA = {
    "volume": {"source": "sine grating, period 2 µm", "sigma_s_um": 12.5, "slice_w": [0.0, None, -1.0]},
    "training": {"epochs": 3, "final": None, "flag": True},
    "big": 2**40,
}


def random_model(
    sizes: list[int] | None = None,
    activation: str = "relu",
    output_activation: str = "clamp",
    seed: int = 0,
    encoding: EncodingSpec = ENCODING,
    scheme: str = "regular",
    range_spec: RangeSpec | None = None,
) -> ModelFile:
    """A random network with He-scaled weights (activations stay of order 1 through the layers)."""
    sizes = sizes or [163, 12, 8, 3]
    rng = np.random.default_rng(seed)
    pairs = zip(sizes, sizes[1:], strict=False)
    weights = [rng.normal(0.0, math.sqrt(2.0 / a), (b, a)).astype(np.float32) for a, b in pairs]
    biases = [rng.normal(0.0, 0.3, b).astype(np.float32) for b in sizes[1:]]
    return ModelFile(
        layer_sizes=list(sizes),
        weights=weights,
        biases=biases,
        activation=activation,
        output_activation=output_activation,
        encoding=encoding,
        range=range_spec or RangeSpec(),
        scheme=scheme,
        metadata=json.loads(json.dumps(METADATA)),
    )


def random_inputs(width: int, count: int = 257, seed: int = 1) -> np.ndarray:
    return np.random.default_rng(seed).normal(0.0, 1.0, (count, width))


def torch_reference(model: ModelFile, encoded: np.ndarray, dtype: torch.dtype = torch.float32) -> np.ndarray:
    """The same network built from torch.nn.Linear layers and torch's own activations."""
    layers: list[torch.nn.Module] = []
    for k, (weight, bias) in enumerate(zip(model.weights, model.biases, strict=True)):
        linear = torch.nn.Linear(weight.shape[1], weight.shape[0]).to(dtype)
        with torch.no_grad():
            linear.weight.copy_(torch.from_numpy(weight))
            linear.bias.copy_(torch.from_numpy(bias))
        layers.append(linear)
        if k < len(model.weights) - 1:
            layers.append(
                {"relu": torch.nn.ReLU(), "leaky_relu": torch.nn.LeakyReLU(0.01), "silu": torch.nn.SiLU()}[
                    model.activation
                ]
            )
    network = torch.nn.Sequential(*layers)
    with torch.no_grad():
        out = network(torch.from_numpy(encoded).to(dtype))
        if model.output_activation == "clamp":
            out = out.clamp(0.0, 1.0)
        elif model.output_activation == "sigmoid":
            out = torch.sigmoid(out)
    return out.double().numpy()


def rewrite(source: Path, target: Path, header_changes: dict | None = None, **array_changes) -> None:
    """Copy a model .npz with some arrays replaced (None deletes) and/or header keys changed."""
    with np.load(source, allow_pickle=False) as archive:
        arrays = {name: archive[name] for name in archive.files}
    if header_changes:
        header = json.loads(str(arrays["metadata_json"][()]))
        header.update(header_changes)
        arrays["metadata_json"] = np.array(json.dumps(header))
    for name, value in array_changes.items():
        if value is None:
            arrays.pop(name)
        else:
            arrays[name] = value
    with target.open("wb") as handle:
        np.savez(handle, **arrays)


@pytest.fixture
def saved(tmp_path: Path) -> Path:
    path = tmp_path / "model.npz"
    save_model(path, random_model())
    return path


# --- round trip -------------------------------------------------------------------------------------


def test_round_trip_is_exact(tmp_path):
    model = random_model(activation="silu", output_activation="sigmoid", scheme="simple-max",
                         range_spec=RangeSpec(kind="log", bits=40.0))
    path = tmp_path / "model.npz"
    save_model(path, model)
    loaded = load_model(path)
    assert loaded == model
    assert loaded.layer_sizes == [163, 12, 8, 3]
    assert all(w.dtype == np.float32 for w in loaded.weights + loaded.biases)
    assert loaded.encoding == ENCODING and loaded.range == RangeSpec(kind="log", bits=40.0)
    assert isinstance(loaded.range.white, tuple)
    assert loaded.metadata == METADATA
    assert (loaded.activation, loaded.output_activation, loaded.scheme) == ("silu", "sigmoid", "simple-max")


def test_an_eq_6a_encoding_round_trips_and_old_headers_stay_as_they_were(tmp_path):
    """``diagonals`` is written only when False: a file of an eq. 6 model keeps its header key for key."""
    axes = EncodingSpec.for_grid(101, 5, diagonals=False)
    model = random_model([axes.features, 12, 3], encoding=axes)
    save_model(tmp_path / "axes.npz", model)
    loaded = load_model(tmp_path / "axes.npz")
    assert loaded == model and loaded.encoding.diagonals is False and loaded.layer_sizes[0] == 87
    header = json.loads(str(np.load(tmp_path / "axes.npz")["metadata_json"]))
    assert header["encoding"]["diagonals"] is False
    save_model(tmp_path / "full.npz", random_model())
    assert "diagonals" not in json.loads(str(np.load(tmp_path / "full.npz")["metadata_json"]))["encoding"]
    with pytest.raises(GratNetError, match="layer_sizes"):
        save_model(tmp_path / "wrong.npz", random_model(encoding=axes))  # 163 inputs for an 87-feature encoding


def test_file_contents_follow_the_documented_layout(saved):
    model = random_model()
    with np.load(saved, allow_pickle=False) as archive:
        names = set(archive.files)
        header = json.loads(str(archive["metadata_json"][()]))
        texture = archive["texture"]
        weight_1 = archive["weight_1"]
    assert names == {"metadata_json", "texture", "weight_0", "weight_1", "weight_2", "bias_0", "bias_1", "bias_2"}
    assert sorted(header) == sorted(["format", "format_version", "layer_sizes", "activation", "output_activation",
                                     "encoding", "range", "scheme", "texture_layout", "metadata"])
    assert header["format"] == FORMAT_NAME == "gratnet-model" and header["format_version"] == FORMAT_VERSION == 1
    assert header["encoding"] == {"frequencies": 19, "t_frequencies": 4, "scale": ENCODING.scale,
                                  "t_scale": ENCODING.t_scale}
    assert header["range"] == {"kind": "power-log", "bits": 48.0, "power": 8.0, "white": list(RangeSpec().white)}
    expected_texture, layout = pack_texture(model)
    assert header["texture_layout"] == layout
    np.testing.assert_array_equal(texture, expected_texture)
    assert texture.dtype == np.float32 and weight_1.dtype == np.float32
    np.testing.assert_array_equal(weight_1, model.weights[1])


def test_members_are_deflated_and_uncompressed_files_still_load(saved, tmp_path):
    """Model files are written deflated (np.savez_compressed); files written before, with np.savez, load the same."""
    import zipfile

    with zipfile.ZipFile(saved) as archive:
        assert {member.compress_type for member in archive.infolist()} == {zipfile.ZIP_DEFLATED}
    with np.load(saved, allow_pickle=False) as archive:
        arrays = {name: archive[name] for name in archive.files}
    stored = tmp_path / "stored.npz"
    np.savez(stored, **arrays)
    with zipfile.ZipFile(stored) as archive:
        assert {member.compress_type for member in archive.infolist()} == {zipfile.ZIP_STORED}
    assert load_model(stored) == load_model(saved) == random_model()


def test_save_casts_to_float32_and_leaves_the_input_alone(tmp_path):
    model = random_model()
    model.weights = [w.astype(np.float64) for w in model.weights]
    model.metadata = {"count": np.int64(3), "value": np.float32(0.5), "pair": (1, 2)}
    save_model(tmp_path / "m.npz", model)
    loaded = load_model(tmp_path / "m.npz")
    assert model.weights[0].dtype == np.float64  # not modified in place
    np.testing.assert_array_equal(loaded.weights[0], model.weights[0].astype(np.float32))
    assert loaded.metadata == {"count": 3, "value": 0.5, "pair": [1, 2]}


def test_save_overwrites_atomically_and_leaves_no_temporary_files(tmp_path):
    path = tmp_path / "model.npz"
    save_model(path, random_model(seed=1))
    save_model(path, random_model(seed=2))
    assert load_model(path) == random_model(seed=2)
    bad = random_model(seed=3)
    bad.weights[0][0, 0] = np.nan
    with pytest.raises(GratNetError):
        save_model(path, bad)
    assert load_model(path) == random_model(seed=2)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model.npz"]


def test_path_is_used_as_given(tmp_path):
    path = tmp_path / "sub" / "weights.bin"
    save_model(path, random_model())
    assert sorted(p.name for p in path.parent.iterdir()) == ["weights.bin"]
    assert load_model(path) == random_model()


def test_parameter_and_mac_counts():
    sizes = [163, 108, 66, 40, 24, 3]
    model = ModelFile(sizes, [], [], "relu", "clamp", ENCODING, RangeSpec(), "regular", {})
    macs = 163 * 108 + 108 * 66 + 66 * 40 + 40 * 24 + 24 * 3
    assert model.macs_per_evaluation == macs == 28404
    assert model.parameter_count == macs + 108 + 66 + 40 + 24 + 3
    small = random_model()
    assert small.parameter_count == sum(w.size + b.size for w, b in zip(small.weights, small.biases, strict=True))


# --- texture packing ----------------------------------------------------------------------------------


def reference_pack_check(model: ModelFile, texture: np.ndarray, layout: list[dict]) -> None:
    """Scalar loops straight from the documented layout: every texel of every layer, padding 0."""
    sizes = model.layer_sizes
    assert texture.dtype == np.float32
    assert texture.shape == (sum(-(-b // 4) for b in sizes[1:]), max(4 * -(-a // 4) + 1 for a in sizes[:-1]), 4)
    covered = np.zeros(texture.shape[:2], dtype=bool)
    row = 0
    for k, (weight, bias) in enumerate(zip(model.weights, model.biases, strict=True)):
        inputs, outputs = sizes[k], sizes[k + 1]
        in_blocks, out_blocks = -(-inputs // 4), -(-outputs // 4)
        assert layout[k] == {"row_offset": row, "in_blocks": in_blocks, "out_blocks": out_blocks,
                             "inputs": inputs, "outputs": outputs}
        for o in range(out_blocks):
            for i in range(in_blocks):
                for j in range(4):
                    texel = texture[row + o, 4 * i + j]
                    for r in range(4):
                        out, inp = 4 * o + r, 4 * i + j
                        expected = weight[out, inp] if out < outputs and inp < inputs else 0.0
                        assert texel[r] == expected, (k, o, i, j, r)
            bias_texel = texture[row + o, 4 * in_blocks]
            for r in range(4):
                assert bias_texel[r] == (bias[4 * o + r] if 4 * o + r < outputs else 0.0)
            covered[row + o, : 4 * in_blocks + 1] = True
        row += out_blocks
    assert not texture[~covered].any()  # texels used by no layer are 0


@pytest.mark.parametrize("sizes", [[163, 12, 8, 3], [163, 21, 21, 3], [163, 3], [163, 464, 288, 16, 3]])
def test_packing_matches_the_documented_layout(sizes):
    model = random_model(sizes)
    texture, layout = pack_texture(model)
    reference_pack_check(model, texture, layout)
    assert layout == texture_layout(sizes)


def test_worked_example_of_the_docs():
    """docs/formats.md: a 5 → 6 layer (in_blocks = 2, out_blocks = 2) with W[o, i] = 10·o + i, b[o] = 100 + o."""
    encoding = EncodingSpec(frequencies=1, t_frequencies=0)  # 11 features
    sizes = [11, 5, 6, 3]
    model = random_model(sizes, encoding=encoding)
    model.weights[1] = (10.0 * np.arange(6)[:, None] + np.arange(5)[None, :]).astype(np.float32)
    model.biases[1] = (100.0 + np.arange(6)).astype(np.float32)
    texture, layout = pack_texture(model)
    assert layout[1] == {"row_offset": 2, "in_blocks": 2, "out_blocks": 2, "inputs": 5, "outputs": 6}
    assert texture.shape == (2 + 2 + 1, 4 * 3 + 1, 4)
    band = texture[2:4, :9]
    np.testing.assert_array_equal(band[0, 0], [0, 10, 20, 30])  # column 0 of block (o=0, i=0)
    np.testing.assert_array_equal(band[0, 3], [3, 13, 23, 33])
    np.testing.assert_array_equal(band[0, 4], [4, 14, 24, 34])  # block (0, 1): only input 4 is real
    np.testing.assert_array_equal(band[0, 5:8], 0)
    np.testing.assert_array_equal(band[0, 8], [100, 101, 102, 103])  # bias at column 4·in_blocks = 8
    np.testing.assert_array_equal(band[1, 0], [40, 50, 0, 0])  # outputs 4, 5, then padding
    np.testing.assert_array_equal(band[1, 4], [44, 54, 0, 0])
    np.testing.assert_array_equal(band[1, 8], [104, 105, 0, 0])


@pytest.mark.parametrize("activation", ACTIVATIONS)
@pytest.mark.parametrize("output_activation", OUTPUT_ACTIVATIONS)
def test_texture_forward_equals_mlp_forward(activation, output_activation):
    model = random_model([163, 21, 21, 3], activation, output_activation, seed=5)
    texture, layout = pack_texture(model)
    encoded = random_inputs(163)
    expected = mlp_forward(model, encoded)
    emulated = texture_forward(texture, layout, activation, output_activation, encoded)
    assert emulated.shape == expected.shape == (257, 3)
    np.testing.assert_allclose(emulated, expected, rtol=1e-6, atol=1e-12)
    # With float32 arithmetic (the GPU's precision) the difference stays at float32 rounding.
    emulated32 = texture_forward(texture, layout, activation, output_activation, encoded, dtype=np.float32)
    np.testing.assert_allclose(emulated32, expected, rtol=1e-4, atol=1e-5)


def test_texture_forward_reads_only_the_texture():
    model = random_model([163, 12, 8, 3], seed=2)
    texture, layout = pack_texture(model)
    encoded = random_inputs(163, count=16)
    before = texture_forward(texture, layout, "relu", "none", encoded)
    texture[layout[1]["row_offset"], 0, 0] += 1.0  # W1[0, 0]
    after = texture_forward(texture, layout, "relu", "none", encoded)
    assert not np.allclose(before, after)


def test_texture_forward_keeps_batch_shape():
    model = random_model()
    texture, layout = pack_texture(model)
    encoded = random_inputs(163, count=12).reshape(3, 4, 163)
    assert texture_forward(texture, layout, "relu", "clamp", encoded).shape == (3, 4, 3)
    assert texture_forward(texture, layout, "relu", "clamp", encoded[0, 0]).shape == (3,)


# --- numpy evaluator --------------------------------------------------------------------------------


@pytest.mark.parametrize("activation", ACTIVATIONS)
@pytest.mark.parametrize("output_activation", OUTPUT_ACTIVATIONS)
def test_mlp_forward_equals_torch(activation, output_activation):
    model = random_model([163, 21, 21, 3], activation, output_activation, seed=7)
    encoded = random_inputs(163)
    result = mlp_forward(model, encoded)
    assert result.dtype == np.float64 and result.shape == (257, 3)
    np.testing.assert_allclose(result, torch_reference(model, encoded, torch.float32), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(result, torch_reference(model, encoded, torch.float64), rtol=1e-12, atol=1e-12)


def test_mlp_forward_shapes_and_errors():
    model = random_model()
    encoded = random_inputs(163, count=6)
    batched = mlp_forward(model, encoded.reshape(2, 3, 163))
    assert batched.shape == (2, 3, 3)
    np.testing.assert_array_equal(batched.reshape(6, 3), mlp_forward(model, encoded))
    assert mlp_forward(model, encoded[0]).shape == (3,)
    with pytest.raises(GratNetError, match="163"):
        mlp_forward(model, np.zeros((4, 160)))


def manual_pipeline(model: ModelFile, u: np.ndarray, v: np.ndarray, w: np.ndarray) -> np.ndarray:
    """physics.md eqs. 6 and 7 written out by hand, with the torch network in float64."""
    if model.scheme == "regular":
        u_star, v_star, t = u, v, -w / 2.0
    else:
        u_star = np.sign(u) * 2.0 * np.sqrt(np.abs(u) / 2.0)
        v_star = np.sign(v) * 2.0 * np.sqrt(np.abs(v) / 2.0)
        t = -w / 2.0 if model.scheme == "simple" else -w / np.sqrt(4.0 - u**2 - v**2)
    t = np.clip(t, 0.0, 1.0)
    c_u, c_v, c_t = u_star / 2.0, v_star / 2.0, 2.0 * t - 1.0
    spec = model.encoding
    features = [c_u, c_v, c_t]
    for c in (c_u, c_v, c_u + c_v, c_u - c_v):
        features += [np.sin(spec.scale**j * np.pi * c) for j in range(spec.frequencies)]
        features += [np.cos(spec.scale**j * np.pi * c) for j in range(spec.frequencies)]
    features += [np.sin(spec.t_scale**j * np.pi * c_t) for j in range(spec.t_frequencies)]
    features += [np.cos(spec.t_scale**j * np.pi * c_t) for j in range(spec.t_frequencies)]
    encoded = np.stack(features, axis=-1)
    y = np.clip(torch_reference(model, encoded, torch.float64), 0.0, 1.0)
    bits, power = model.range.bits, model.range.power
    x = np.where(y > 0.0, 2.0 ** (bits * (y ** (1.0 / power) - 1.0)), 0.0)
    return x * np.array(model.range.white)


@pytest.mark.parametrize("scheme", ["regular", "simple", "simple-max"])
def test_evaluate_keys_equals_the_manual_pipeline(scheme):
    # Output activation 'none' with a bias pushing outputs into (0, 1) so that XYZ is not all 0 or white.
    model = random_model([163, 24, 12, 3], "leaky_relu", "none", seed=11, scheme=scheme)
    model.weights[-1] *= 0.1
    model.biases[-1] = np.full(3, 0.9, np.float32)
    rng = np.random.default_rng(4)
    angle, radius = rng.uniform(0, 2 * np.pi, (5, 7)), rng.uniform(0, 1.4, (5, 7))
    u, v = radius * np.cos(angle), radius * np.sin(angle)
    w = -rng.uniform(0.0, 1.0, (5, 7)) * np.sqrt(4.0 - u**2 - v**2)
    xyz = evaluate_keys(model, u, v, w)
    assert xyz.shape == (5, 7, 3) and xyz.dtype == np.float64
    expected = manual_pipeline(model, u, v, w)
    assert np.all(expected > 0) and np.all(expected < 1.2)
    np.testing.assert_allclose(xyz, expected, rtol=1e-9, atol=1e-15)
    # The same through the public building blocks.
    encoded = encode(network_coordinates(u, v, w, scheme), model.encoding)
    np.testing.assert_allclose(mlp_forward(model, encoded), torch_reference(model, encoded, torch.float64),
                               rtol=1e-12, atol=1e-12)


def test_evaluate_keys_broadcasts():
    model = random_model()
    u = np.linspace(-1, 1, 4)[:, None]
    assert evaluate_keys(model, u, 0.0, np.full(5, -0.5)).shape == (4, 5, 3)
    assert evaluate_keys(model, 0.1, 0.2, -0.3).shape == (3,)


# --- invalid models (saving) ------------------------------------------------------------------------


def broken(change: str) -> ModelFile:
    model = random_model()
    if change == "nan weight":
        model.weights[1][2, 3] = np.nan
    elif change == "inf bias":
        model.biases[0][1] = np.inf
    elif change == "too large for float32":
        model.weights[0] = model.weights[0].astype(np.float64)
        model.weights[0][0, 0] = 1e39
    elif change == "transposed weight":
        model.weights[1] = model.weights[1].T.copy()
    elif change == "wrong bias length":
        model.biases[2] = np.zeros(4, np.float32)
    elif change == "missing layer":
        model.weights.pop()
    elif change == "input width":
        model.layer_sizes[0] = 160
        model.weights[0] = model.weights[0][:, :160]
    elif change == "four outputs":
        model.layer_sizes[-1] = 4
    elif change == "activation":
        model.activation = "tanh"
    elif change == "output activation":
        model.output_activation = "relu"
    elif change == "scheme":
        model.scheme = "spherical"
    elif change == "metadata object":
        model.metadata = {"when": object()}
    elif change == "metadata nan":
        model.metadata = {"loss": float("nan")}
    elif change == "metadata key":
        model.metadata = {1: "one"}
    elif change == "complex weights":
        model.weights[0] = model.weights[0].astype(np.complex64)
    return model


BROKEN = ["nan weight", "inf bias", "too large for float32", "transposed weight", "wrong bias length",
          "missing layer", "input width", "four outputs", "activation", "output activation", "scheme",
          "metadata object", "metadata nan", "metadata key", "complex weights"]


@pytest.mark.parametrize("change", BROKEN)
def test_save_refuses_invalid_models(tmp_path, change):
    path = tmp_path / "model.npz"
    with pytest.raises(GratNetError) as info:
        save_model(path, broken(change))
    assert "\n" not in str(info.value)
    assert list(tmp_path.iterdir()) == []


def test_save_errors_name_the_problem(tmp_path):
    with pytest.raises(GratNetError, match=r"weight_1 has 1 non-finite value.*index \(2, 3\)"):
        save_model(tmp_path / "m.npz", broken("nan weight"))
    with pytest.raises(GratNetError, match=r"weight_1 has shape \(12, 8\).*\(8, 12\)"):
        save_model(tmp_path / "m.npz", broken("transposed weight"))
    with pytest.raises(GratNetError, match="produces 163 features"):
        save_model(tmp_path / "m.npz", broken("input width"))
    with pytest.raises(GratNetError, match="relu, leaky_relu, silu"):
        save_model(tmp_path / "m.npz", broken("activation"))


def test_evaluation_refuses_invalid_models():
    with pytest.raises(GratNetError):
        mlp_forward(broken("transposed weight"), np.zeros((1, 163)))
    with pytest.raises(GratNetError):
        pack_texture(broken("nan weight"))
    with pytest.raises(GratNetError):
        evaluate_keys(broken("scheme"), 0.0, 0.0, -1.0)


# --- bad files (loading) ----------------------------------------------------------------------------


def load_error(path: Path) -> str:
    with pytest.raises(GratNetError) as info:
        load_model(path)
    message = str(info.value)
    assert "\n" not in message
    return message


def test_missing_file(tmp_path):
    assert "does not exist" in load_error(tmp_path / "nope.npz")
    assert "not a regular file" in load_error(tmp_path)


def test_truncated_file(tmp_path, saved):
    data = saved.read_bytes()
    for size in (len(data) // 2, len(data) - 1, 10, 0):
        cut = tmp_path / f"cut{size}.npz"
        cut.write_bytes(data[:size])
        message = load_error(cut)
        assert "truncated or corrupt" in message or "not an .npz" in message, message
    cut = tmp_path / "half.npz"
    cut.write_bytes(data[: len(data) // 2])
    assert "truncated or corrupt" in load_error(cut)


@pytest.mark.parametrize("offset", [17, 200, 600])
def test_flipped_bytes_are_detected(tmp_path, saved, offset):
    """A flipped bit inside a member's deflated data (zlib's error or the member's CRC), and inside the stored
    weights of an uncompressed file written before compression (the CRC), are both reported as corrupt."""
    bad = tmp_path / "bad.npz"
    bad.write_bytes(flip_in_member(saved, "weight_0.npy", offset))
    assert "corrupt" in load_error(bad)

    stored = tmp_path / "stored.npz"
    with np.load(saved, allow_pickle=False) as archive:
        np.savez(stored, **{name: archive[name] for name in archive.files})
    data = bytearray(stored.read_bytes())
    position = bytes(data).find(random_model().weights[0].tobytes()[:64])
    assert position > 0
    data[position + offset % 64] ^= 0x40
    stored.write_bytes(bytes(data))
    assert "corrupt" in load_error(stored)


def test_not_a_zip(tmp_path):
    text = tmp_path / "model.npz"
    text.write_text("layer_sizes = [163, 3]\n")
    assert "not a GratNet model file" in load_error(text)
    npy = tmp_path / "array.npz"
    with npy.open("wb") as handle:
        np.save(handle, np.zeros(3))
    assert "single .npy array" in load_error(npy)


def test_other_npz_archives(tmp_path):
    other = tmp_path / "other.npz"
    np.savez(other, heights_um=np.zeros((4, 4)), dx_um=np.array(1.0))
    assert "not a GratNet model file" in load_error(other)
    empty = tmp_path / "empty.npz"
    np.savez(empty)
    assert "not a GratNet model file" in load_error(empty)


def test_wrong_format_name(tmp_path, saved):
    bad = tmp_path / "bad.npz"
    rewrite(saved, bad, {"format": "gratnet-volume"})
    assert "not a GratNet model file" in load_error(bad)


def test_format_version_999(tmp_path, saved):
    bad = tmp_path / "future.npz"
    rewrite(saved, bad, {"format_version": 999})
    message = load_error(bad)
    assert "999" in message and "version 1" in message


@pytest.mark.parametrize("version", ["1", 1.0, True, None])
def test_format_version_must_be_the_integer_1(tmp_path, saved, version):
    bad = tmp_path / "bad.npz"
    rewrite(saved, bad, {"format_version": version})
    assert "format version" in load_error(bad)


def test_nan_weight_in_file(tmp_path, saved):
    weight = load_model(saved).weights[1].copy()
    weight[0, 0] = np.nan
    bad = tmp_path / "nan.npz"
    rewrite(saved, bad, weight_1=weight)
    message = load_error(bad)
    assert "weight_1" in message and "non-finite" in message


def test_mismatched_shapes_in_file(tmp_path, saved):
    model = load_model(saved)
    bad = tmp_path / "shape.npz"
    rewrite(saved, bad, weight_1=model.weights[1].T.copy())
    assert "weight_1 has shape (12, 8)" in load_error(bad)
    rewrite(saved, bad, bias_2=np.zeros(4, np.float32))
    assert "bias_2 has shape (4,)" in load_error(bad)
    rewrite(saved, bad, {"layer_sizes": [163, 12, 9, 3]})
    assert "shape" in load_error(bad)
    rewrite(saved, bad, {"layer_sizes": [163, 12, 3]})
    assert "unexpected array(s) bias_2, weight_2" in load_error(bad)


def test_missing_or_extra_arrays(tmp_path, saved):
    bad = tmp_path / "bad.npz"
    rewrite(saved, bad, bias_1=None)
    assert "lacks array(s) bias_1" in load_error(bad)
    rewrite(saved, bad, texture=None)
    assert "lacks array(s) texture" in load_error(bad)
    rewrite(saved, bad, weight_3=np.zeros((3, 3), np.float32))
    assert "unexpected array(s) weight_3" in load_error(bad)


def test_wrong_dtype_in_file(tmp_path, saved):
    bad = tmp_path / "bad.npz"
    rewrite(saved, bad, weight_0=load_model(saved).weights[0].astype(np.float64))
    assert "float32" in load_error(bad)


def test_tampered_texture(tmp_path, saved):
    with np.load(saved, allow_pickle=False) as archive:
        texture = archive["texture"].copy()
    bad = tmp_path / "tampered.npz"
    tampered = texture.copy()
    tampered[1, 2, 3] += 0.25
    rewrite(saved, bad, texture=tampered)
    assert "differs from the weights in 1 texel(s)" in load_error(bad)
    rewrite(saved, bad, texture=texture[:, :-1])
    assert "texture" in load_error(bad)
    rewrite(saved, bad, texture=texture.astype(np.float64))
    assert "texture" in load_error(bad)
    layout = json.loads(str(np.load(saved)["metadata_json"][()]))["texture_layout"]
    layout[1]["row_offset"] += 1
    rewrite(saved, bad, {"texture_layout": layout})
    assert "texture_layout" in load_error(bad)


@pytest.mark.parametrize(
    "changes",
    [
        {"activation": "gelu"},
        {"output_activation": "softplus"},
        {"scheme": "polar"},
        {"encoding": {"frequencies": 19, "t_frequencies": 4, "scale": 1.4}},
        {"encoding": {"frequencies": 18, "t_frequencies": 4, "scale": 1.4, "t_scale": 1.7}},
        {"encoding": {"frequencies": 19, "t_frequencies": 4, "scale": -1.0, "t_scale": 1.7}},
        {"range": {"kind": "cubic", "bits": 48.0, "power": 8.0, "white": [1, 1, 1]}},
        {"range": {"kind": "log", "bits": 48.0, "power": 8.0, "white": [1, 1]}},
        {"layer_sizes": "163,12,8,3"},
        {"layer_sizes": [163, 12, 8, 4]},
        {"metadata": [1, 2]},
    ],
)
def test_invalid_header_fields(tmp_path, saved, changes):
    bad = tmp_path / "bad.npz"
    rewrite(saved, bad, changes)
    load_error(bad)


def test_invalid_metadata_json(tmp_path, saved):
    bad = tmp_path / "bad.npz"
    rewrite(saved, bad, metadata_json=np.array("{not json"))
    assert "not valid JSON" in load_error(bad)
    rewrite(saved, bad, metadata_json=np.array(["{}"]))
    assert "0-d string array" in load_error(bad)
    with np.load(saved, allow_pickle=False) as archive:
        header = json.loads(str(archive["metadata_json"][()]))
    del header["scheme"]
    rewrite(saved, bad, metadata_json=np.array(json.dumps(header)))
    assert "lacks key(s) scheme" in load_error(bad)


# --- runtime side: no torch -------------------------------------------------------------------------


def test_module_never_imports_torch(saved):
    code = (
        "import sys\n"
        "import gratnet.modelfile as m\n"
        "import gratnet.network as n\n"
        "assert 'torch' not in sys.modules, 'imported by gratnet.modelfile'\n"
        "model = m.load_model(sys.argv[1])\n"
        "texture, layout = m.pack_texture(model)\n"
        "xyz = m.evaluate_keys(model, 0.1, -0.2, -0.5)\n"
        "n.texture_forward(texture, layout, model.activation, model.output_activation, [[0.0] * 163])\n"
        "m.save_model(sys.argv[1], model)\n"
        "assert 'torch' not in sys.modules, 'imported while using gratnet.modelfile'\n"
        "print(xyz.shape)\n"
    )
    result = subprocess.run([sys.executable, "-c", code, str(saved)], capture_output=True, text=True, cwd=REPO)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "(3,)"
