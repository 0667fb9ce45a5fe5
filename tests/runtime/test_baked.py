"""The baked weight path (viewer/baked.py): the MLP with its weights as GLSL literals.

Parity against numpy (``gratnet.modelfile.evaluate_keys``) and against the texture path, the ``auto``
rule, generated sources in the preprocessor, and compile errors naming the generated file. Nets are tiny
(few encoding frequencies, hidden widths that are not multiples of 4) so each compile takes ~1 s on llvmpipe.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from gratnet.encoding import EncodingSpec
from gratnet.errors import GratNetError
from gratnet.modelfile import evaluate_keys
from tests.helpers import (
    FULLSCREEN,
    PROGRAM,
    RELATIVE,
    SPEC,
    assert_relative,
    parity_keys,
    random_model,
    write_shaders,
)
from viewer.baked import baked_encoded_inputs, baked_mlp_source, float_literal
from viewer.glsl import GeneratedSource, compile_program, load_program_source, preprocess
from viewer.renderer import BAKED_MAX_MACS, WEIGHTS_PATHS, NetworkRenderer, choose_weights_path

SMALL = EncodingSpec(3, 1, 2.0, 1.5)  # 3 + 8·3 + 2·1 = 29 features: 8 input blocks


@pytest.mark.parametrize(
    ("sizes", "activation", "output_activation", "scheme", "range_kind", "spec"),
    [
        ([29, 21, 21, 3], "silu", "clamp", "regular", "power-log", SMALL),
        ([29, 12, 8, 3], "relu", "sigmoid", "simple", "log", SMALL),
        ([29, 13, 6, 5, 3], "leaky_relu", "none", "simple-max", "log1p", SMALL),
        ([163, 9, 3], "silu", "clamp", "simple-max", "power-log", SPEC),
        # No t frequencies; five (a full and a partial vec4 of t sines/cosines); one spatial frequency.
        ([19, 7, 3], "silu", "sigmoid", "simple-max", "power-log", EncodingSpec(2, 0, 1.7, 1.0)),
        ([29, 10, 3], "relu", "clamp", "regular", "log", EncodingSpec(2, 5, 1.7, 1.3)),
        ([13, 6, 3], "silu", "clamp", "simple", "power-log", EncodingSpec(1, 1, 1.0, 1.0)),
        # eq. 6a: the sin/cos vec4s of a frequency hold two features (lanes 2 and 3 empty)
        ([17, 9, 3], "silu", "clamp", "simple-max", "power-log", EncodingSpec(3, 1, 2.0, 1.5, diagonals=False)),
    ],
)
def test_baked_evaluate_keys_matches_numpy_and_the_texture_path(ctx, sizes, activation, output_activation, scheme,
                                                                 range_kind, spec):
    model = random_model(sizes, activation, output_activation, scheme, range_kind, spec)
    u, v, w = parity_keys()
    expected = evaluate_keys(model, u, v, w)
    results = {}
    for path in ("baked", "texture"):
        renderer = NetworkRenderer(ctx, model, weights_path=path)
        try:
            assert renderer.weights_path == path
            results[path] = (renderer.evaluate_keys(u, v, w), renderer.network_outputs(u, v, w))
        finally:
            renderer.release()
    baked, texture = results["baked"], results["texture"]
    assert baked[0].shape == expected.shape and baked[0].dtype == np.float32
    assert np.all(expected.max(axis=0) > 0)
    assert_relative(baked[0], expected, RELATIVE, floor=1e-12)
    # The same float32 sums in a different order: the paths agree to a few float32 ulps.
    np.testing.assert_allclose(baked[1], texture[1], rtol=2e-6, atol=2e-6)


def test_baked_brdf_slice_matches_the_texture_path(ctx):
    model = random_model([29, 21, 21, 3], "silu", "clamp", "simple-max", spec=SMALL)
    images = {}
    for path in ("baked", "texture"):
        renderer = NetworkRenderer(ctx, model, weights_path=path)
        try:
            renderer.use_weights(0)  # a no-op on the baked path
            images[path] = renderer.render_brdf_slice_layers(30.0, 40.0, 16, 2.0, 1.5)
        finally:
            renderer.release()
    (baked, baked_network), (texture, texture_network) = images["baked"], images["texture"]
    assert np.count_nonzero(baked) > 0
    assert_relative(baked, texture.astype(np.float64), 1e-5, floor=1e-3 * float(np.abs(texture).max()))
    assert_relative(baked_network, texture_network.astype(np.float64), 1e-5, floor=1e-12)


def test_baked_programs_have_no_weight_uniforms_and_the_scene_passes_the_path_through(ctx):
    from viewer.scene import SceneRenderer

    model = random_model([29, 12, 8, 3], spec=SMALL)
    scene = SceneRenderer(ctx, model, weights_path="baked")
    try:
        assert scene.network.weights_path == "baked"
        program = scene.network.program("evaluate_keys")
        for name in ("u_weights", "u_layers", "u_layer_count", "u_hidden_activation"):
            assert name not in program
        assert "u_frequency" in program
    finally:
        scene.release()


def test_the_auto_rule():
    small = random_model([29, 12, 8, 3], spec=SMALL)
    shipped = random_model([163, 108, 66, 40, 24, 3])  # the shipped size (28.4k MACs) is baked on llvmpipe
    big = random_model([163, 200, 100, 3])
    assert small.macs_per_evaluation <= shipped.macs_per_evaluation <= BAKED_MAX_MACS < big.macs_per_evaluation
    llvmpipe = SimpleNamespace(info={"GL_RENDERER": "llvmpipe (LLVM 15.0.6, 256 bits)"})
    softpipe = SimpleNamespace(info={"GL_RENDERER": "softpipe"})
    gpu = SimpleNamespace(info={"GL_RENDERER": "NVIDIA GeForce RTX 4090/PCIe/SSE2"})
    assert choose_weights_path(llvmpipe, small) == "baked"  # type: ignore[arg-type]
    assert choose_weights_path(softpipe, small, "auto") == "baked"  # type: ignore[arg-type]
    assert choose_weights_path(llvmpipe, shipped) == "baked"  # type: ignore[arg-type]
    assert choose_weights_path(llvmpipe, big) == "texture"  # type: ignore[arg-type]
    assert choose_weights_path(gpu, small) == "texture"  # type: ignore[arg-type]
    for path in ("texture", "baked"):
        assert choose_weights_path(gpu, big, path) == path  # type: ignore[arg-type]
    assert WEIGHTS_PATHS == ("auto", "texture", "baked")
    with pytest.raises(GratNetError, match="weights path must be one of auto, texture, baked"):
        choose_weights_path(gpu, small, "literal")  # type: ignore[arg-type]


def test_auto_on_this_context(ctx):
    model = random_model([29, 12, 8, 3], spec=SMALL)
    renderer = NetworkRenderer(ctx, model)
    try:
        software = any(name in ctx.info["GL_RENDERER"].lower() for name in ("llvmpipe", "softpipe", "swrast"))
        assert renderer.weights_path == ("baked" if software else "texture")
    finally:
        renderer.release()
    with pytest.raises(GratNetError, match="weights path"):
        NetworkRenderer(ctx, model, weights_path="fast")


def test_float_literals_round_trip_to_the_float32_weights():
    rng = np.random.default_rng(3)
    values = np.concatenate([rng.standard_normal(2000) * 10.0 ** rng.integers(-30, 30, 2000),
                             [0.0, -0.0, 1.0, -2.5, 1e-5, 3.4028235e38, 1.17549435e-38]]).astype(np.float32)
    for value in values:
        text = float_literal(value)
        assert np.float32(text) == value, (value, text)
        assert "." in text or "e" in text  # a float literal, not an int
    with pytest.raises(GratNetError, match="non-finite"):
        float_literal(np.inf)


@pytest.mark.parametrize("spec", [SMALL, SPEC, EncodingSpec(1, 0, 1.0, 1.0), EncodingSpec(2, 5, 1.7, 1.3),
                                  EncodingSpec(3, 8, 1.5, 1.2), EncodingSpec(3, 5, 1.5, 1.2, diagonals=False)])
def test_baked_inputs_hold_every_encoded_feature_once(spec):
    model = random_model([spec.features, 5, 3], spec=spec)
    lanes = [feature for _, _, features in baked_encoded_inputs(model) for feature in features]
    assert len(lanes) % 4 == 0
    assert sorted(feature for feature in lanes if feature >= 0) == list(range(spec.features))
    assert lanes.count(-1) == len(lanes) - spec.features  # the rest is padding


def test_generated_source_skips_zero_blocks_and_has_no_uniforms():
    model = random_model([29, 21, 21, 3], spec=SMALL)
    model.weights[1][:, 4:8] = 0.0  # input block 1 of layer 2: all zero
    text = baked_mlp_source(model, "test")
    assert not any(line.startswith("uniform") for line in text.splitlines())
    assert "texelFetch" not in text and "float[" not in text
    assert "a2_0 += mat4(" in text and "* a1_1;" not in text and "* a1_2;" in text


# ------------------------------------------------------------------------------------------------
# Generated sources in the preprocessor


def test_generated_include_replaces_the_file_once_and_is_named_in_line_mapping(tmp_path):
    root = write_shaders(tmp_path, {"prog.glsl": PROGRAM + '#include "broken.glsl"\n',  # included twice
                                    "fullscreen_test.glsl": FULLSCREEN, "broken.glsl": "this file is not read\n"})
    generated = GeneratedSource("<generated broken>", "float helper() { return 2.0; }\n")
    source = preprocess("prog", "fragment", {}, root, {"broken.glsl": generated})
    assert source.text.count("return 2.0") == 1 and "not read" not in source.text
    assert source.files[-1] == "<generated broken>"
    plain = load_program_source("prog", "fragment", {}, root)
    assert "not read" in plain  # without overrides: the file, as before
    with pytest.raises(GratNetError, match="no #version or #include"):
        preprocess("prog", "fragment", {}, root, {"broken.glsl": GeneratedSource("<g>", '#include "a.glsl"\n')})
    with pytest.raises(GratNetError, match="GeneratedSource"):
        preprocess("prog", "fragment", {}, root, {"broken.glsl": "float helper() { return 2.0; }"})  # type: ignore[dict-item]


def test_compile_error_in_generated_source_names_it(ctx, tmp_path):
    root = write_shaders(tmp_path, {"prog.glsl": PROGRAM, "fullscreen_test.glsl": FULLSCREEN,
                                    "broken.glsl": "float helper() { return 1.0; }\n"})
    body = "// generated\nfloat helper() {\n    return undefined_name * 2.0;\n}\n"
    with pytest.raises(GratNetError) as caught:
        compile_program(ctx, "prog", {}, root, {"broken.glsl": GeneratedSource("<baked mlp.glsl: test>", body)})
    message = str(caught.value)
    assert "<baked mlp.glsl: test>:3:" in message and "\n" not in message, message
