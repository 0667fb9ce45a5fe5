"""The GLSL runtime against its numpy references (docs/physics.md eq. 5–7, docs/formats.md texture layout).

GPU tests need an OpenGL 4.3 context through EGL (Mesa llvmpipe on a CPU-only machine) and skip with the
reason when there is none; the preprocessor tests need no GPU. Renders are tiny (≤ 32×32, ~300 keys) and
nets small, so the whole file runs in seconds on llvmpipe.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gratnet.brdf import a_term, direction, slice_view_directions
from gratnet.encoding import EncodingSpec, encode, network_coordinates
from gratnet.errors import GratNetError
from gratnet.modelfile import evaluate_keys
from gratnet.precision import OWN_KEYS, UNIT_ROUNDOFF, DriverErrors, assert_within, driver_bound
from tests.helpers import FULLSCREEN, PROGRAM, RELATIVE, SPEC, assert_relative, parity_keys, random_model, write_shaders
from viewer.glsl import LINE_STRIDE, compile_program, load_program_source, map_error_log, preprocess

# ------------------------------------------------------------------------------------------------
# (a) the whole pipeline: key vector → XYZ


@pytest.mark.parametrize(
    ("sizes", "activation", "output_activation", "scheme", "range_kind", "spec"),
    [
        ([163, 21, 21, 3], "silu", "clamp", "regular", "power-log", SPEC),
        ([163, 21, 21, 3], "relu", "sigmoid", "simple", "log", SPEC),
        ([163, 21, 21, 3], "leaky_relu", "none", "simple-max", "log1p", SPEC),
        ([163, 21, 21, 3], "silu", "clamp", "simple-max", "power-log", SPEC),
        ([163, 9, 3], "leaky_relu", "sigmoid", "simple", "power-log", SPEC),
        ([27, 13, 6, 5, 3], "relu", "clamp", "regular", "power-log", EncodingSpec(3, 0, 2.0, 1.0)),
        # eq. 6a: the axes alone (no c_u ± c_v groups)
        ([87, 21, 21, 3], "silu", "clamp", "simple-max", "power-log", EncodingSpec.for_grid(101, 5, diagonals=False)),
    ],
)
def test_gpu_evaluate_keys_matches_numpy(ctx, sizes, activation, output_activation, scheme, range_kind, spec):
    from viewer.renderer import NetworkRenderer

    model = random_model(sizes, activation, output_activation, scheme, range_kind, spec)
    u, v, w = parity_keys()
    expected = evaluate_keys(model, u, v, w)
    renderer = NetworkRenderer(ctx, model)
    try:
        actual = renderer.evaluate_keys(u, v, w)
        raw = renderer.network_outputs(u, v, w)
    finally:
        renderer.release()
    assert actual.shape == expected.shape == (u.size, 3) and actual.dtype == np.float32
    assert np.all(expected.max(axis=0) > 0)  # the test exercises non-trivial outputs
    # At the float32 keys the shader got: sin/cos and rounding only (docs/physics.md, "Float32 error budget").
    assert_within(actual, expected, driver_bound(model, u, v, w, OWN_KEYS).bound, "XYZ values", floor=1e-30)
    assert raw.shape == (u.size, 3) and np.all(np.isfinite(raw))


def test_gpu_evaluate_keys_keeps_the_broadcast_shape_and_ignores_the_callers_blending(ctx):
    import moderngl

    from viewer.renderer import NetworkRenderer

    model = random_model([163, 9, 3])
    renderer = NetworkRenderer(ctx, model)
    ctx.enable(moderngl.BLEND)  # as a window drawing a GUI might leave it; the outputs' alpha is 0
    try:
        u = np.linspace(-0.5, 0.5, 6).reshape(2, 3)
        actual = renderer.evaluate_keys(u, 0.1, -1.0)
        empty = renderer.evaluate_keys(np.zeros(0), 0.0, -1.0)
    finally:
        ctx.disable(moderngl.BLEND)
        renderer.release()
    assert actual.shape == (2, 3, 3) and empty.shape == (0, 3)
    expected = evaluate_keys(model, u.astype(np.float32), np.float32(0.1), -1.0)
    assert_relative(actual, expected, RELATIVE, floor=1e-12)


# ------------------------------------------------------------------------------------------------
# (b) the encoding alone (eq. 6)


@pytest.mark.parametrize("scheme", ["regular", "simple", "simple-max"])
@pytest.mark.parametrize("spec", [SPEC, EncodingSpec.for_grid(1001, 11),
                                  EncodingSpec.for_grid(1001, 11, diagonals=False)],
                         ids=["R101", "R1001", "R1001-axes"])
def test_gpu_encoding_matches_numpy(ctx, scheme, spec):
    from viewer.renderer import NetworkRenderer

    model = random_model([spec.features, 5, 3], scheme=scheme, spec=spec)
    u, v, w = parity_keys()
    expected = encode(network_coordinates(u, v, w, scheme), spec)
    renderer = NetworkRenderer(ctx, model)
    try:
        actual = renderer.encode_keys(u, v, w)
    finally:
        renderer.release()
    assert actual.shape == expected.shape == (u.size, spec.features)
    # Top phase π·s^(L−1) is 157 rad (R = 101) or 1571 rad (R = 1001): a plain float32 product would
    # miss 1e-4 there; the shader's exact range reduction leaves the driver's sin/cos error (the bound's
    # sinusoid_error, 2^-20) and c_t's float32 arithmetic (t_coordinate_error: for simple-max a square root and
    # a division, measured 2.6 u on llvmpipe) times the t frequency π·s_t^j (docs/physics.md, "Float32 error
    # budget"). c_u, c_v are exact pairs in the shader, rounded once.
    errors = DriverErrors()
    allowed = np.full(spec.features, errors.sinusoid_error)
    allowed[:3] = [UNIT_ROUNDOFF, UNIT_ROUNDOFF, errors.t_coordinate_error]
    _, omega_t = spec.angular_frequencies()
    first_t = 3 + 2 * spec.groups * spec.frequencies
    allowed[first_t:] += np.tile(omega_t, 2) * errors.t_coordinate_error
    assert_within(actual, expected, np.broadcast_to(allowed, actual.shape), "encoded features")


# ------------------------------------------------------------------------------------------------
# (c) a BRDF slice


@pytest.mark.parametrize("scheme", ["regular", "simple-max"])
@pytest.mark.parametrize(("theta", "phi", "exposure", "ior"), [(30.0, 40.0, 2.0, 1.5), (0.0, 0.0, 1.0, None),
                                                               (75.0, 250.0, 0.5, 1.33)])
def test_gpu_brdf_slice_matches_numpy(ctx, scheme, theta, phi, exposure, ior):
    from viewer.renderer import NetworkRenderer

    size = 32
    model = random_model([163, 21, 21, 3], scheme=scheme)
    views, inside = slice_view_directions(size)
    light = direction(theta, phi)
    key = -(light + views)
    xyz = evaluate_keys(model, key[..., 0], key[..., 1], key[..., 2]) * inside[..., None]
    expected = exposure * a_term(light, views, ior)[..., None] * xyz
    renderer = NetworkRenderer(ctx, model)
    try:
        exposed, network = renderer.render_brdf_slice_layers(theta, phi, size, exposure, ior)
        again = renderer.render_brdf_slice(theta, phi, size, exposure, ior)
    finally:
        renderer.release()
    assert exposed.shape == (size, size, 3) and exposed.dtype == np.float32
    np.testing.assert_array_equal(again, exposed)
    assert np.all(exposed[~inside] == 0.0) and np.all(network[~inside] == 0.0)
    assert_relative(exposed, expected, RELATIVE, floor=1e-3 * float(np.abs(expected).max()))
    assert_relative(network, xyz, RELATIVE, floor=1e-12)


# ------------------------------------------------------------------------------------------------
# (d) preprocessor and compile errors that name the real file and line


@pytest.mark.parametrize(
    ("body", "line"),
    [
        ("// helper\nfloat helper() {\n    return undefined_name * 2.0;\n}\n", 3),  # semantic: Mesa says '0:'
        ("// helper\n\n\nfloat helper() { return 1.0 }\n", 4),  # syntax error: Mesa reports the source
    ],
    ids=["undeclared", "syntax"],
)
def test_compile_error_names_the_included_file_and_line(ctx, tmp_path, body, line):
    root = write_shaders(tmp_path, {"prog.glsl": PROGRAM, "fullscreen_test.glsl": FULLSCREEN, "broken.glsl": body})
    with pytest.raises(GratNetError) as caught:
        compile_program(ctx, "prog", {"MAX_THINGS": 4}, shader_root=root)
    message = str(caught.value)
    assert "broken.glsl:" in message and f"broken.glsl:{line}:" in message, message
    assert "fragment" in message and "\n" not in message


def test_an_nvidia_compile_log_names_the_included_file_and_line_as_mesas_does(tmp_path):
    """The message format does not depend on the driver: an NVIDIA-style log ("S(L) : error C…", source string S
    and line L as the preprocessor's #line set them) reads "broken.glsl:LINE: error …" like Mesa's."""
    import moderngl

    root = write_shaders(tmp_path, {"prog.glsl": PROGRAM, "fullscreen_test.glsl": FULLSCREEN,
                                    "broken.glsl": "// helper\nfloat helper() {\n    return q * 2.0;\n}\n"})
    files = preprocess("prog", "fragment", {"MAX_THINGS": 4}, root).files
    file_id = 1 + [Path(name).name for name in files].index("broken.glsl")

    class NvidiaContext:
        def program(self, **_: str) -> None:
            raise moderngl.Error("GLSL Compiler failed\n\nfragment_shader\n===============\n"
                                 f"{file_id}({file_id * LINE_STRIDE + 3}) : error C1008: undefined variable \"q\"\n")

    with pytest.raises(GratNetError) as caught:
        compile_program(NvidiaContext(), "prog", {"MAX_THINGS": 4}, shader_root=root)  # type: ignore[arg-type]
    message = str(caught.value)
    assert "broken.glsl:3: error C1008: undefined variable" in message, message
    assert "the fragment stage" in message and "\n" not in message


def test_error_logs_map_to_files_in_mesa_and_parenthesised_forms():
    files = (Path("/nowhere/prog.glsl"), Path("/nowhere/inc.glsl"))
    log = (
        "GLSL Compiler failed\n\nfragment_shader\n===============\n"
        f"0:{2 * LINE_STRIDE + 7}(3): error: `q' undeclared\n"  # Mesa, source number lost
        "2:9(1): preprocessor error: #error stop\n"  # Mesa, source kept (plain line number)
        f"1({LINE_STRIDE + 4}) : error C0000: syntax error\n"  # NVIDIA style
        "0:3(1): error: bad define\n"  # the generated header
    )
    assert map_error_log(log, files) == [
        "/nowhere/inc.glsl:7:3: error: `q' undeclared",
        "/nowhere/inc.glsl:9:1: preprocessor error: #error stop",
        "/nowhere/prog.glsl:4: error C0000: syntax error",
        "<generated header>:3:1: error: bad define",
    ]


def test_context_failures_are_one_line_naming_the_packages(monkeypatch):
    import viewer.context as context

    def missing_egl(**_: object) -> None:
        raise Exception("libEGL.so.1: cannot open shared object file:\nNo such file or directory")

    monkeypatch.setattr(context.moderngl, "create_context", missing_egl)
    for factory in (context.create_headless_context, context.context_from_current):
        with pytest.raises(GratNetError) as caught:
            factory()
        message = str(caught.value)
        assert "\n" not in message and "libEGL.so.1" in message
        assert "libegl1 libegl-mesa0 libgbm1 libgl1 libgl1-mesa-dri" in message


def test_program_source_header_defines_and_line_directives(tmp_path):
    root = write_shaders(tmp_path, {"prog.glsl": PROGRAM, "fullscreen_test.glsl": FULLSCREEN,
                                    "broken.glsl": "float helper() { return 1.0; }\n"})
    text = load_program_source("prog", "fragment", {"MAX_BLOCKS": 41, "SLOPE": 0.01, "NEGATIVE": -2}, root)
    lines = text.splitlines()
    assert lines[0] == "#version 430 core"
    assert lines[1] == "#define FRAGMENT_SHADER"
    assert lines[2:5] == ["#define MAX_BLOCKS 41", "#define SLOPE 0.01", "#define NEGATIVE (-2)"]
    source = preprocess("prog", "vertex", {}, root)
    assert [path.name for path in source.files] == ["prog.glsl", "fullscreen_test.glsl", "broken.glsl"]
    assert "#include" not in source.text and "#define VERTEX_SHADER" in source.text
    # After an include, the including file resumes at its own next line (line 3 of prog.glsl).
    assert f"#line {1 * LINE_STRIDE + 3} 1" in source.text


def test_include_once_cycles_and_missing_files(tmp_path):
    root = write_shaders(tmp_path, {
        "twice.glsl": '#include "a.glsl"\n#include "a.glsl"\n',
        "a.glsl": "float a_function() { return 1.0; }\n",
        "cycle.glsl": '#include "b.glsl"\n',
        "b.glsl": '// b\n#include "cycle.glsl"\n',
        "missing.glsl": '\n\n#include "nowhere.glsl"\n',
        "bad.glsl": "#include <angle.glsl>\n",
        "versioned.glsl": "#version 330\n",
    })
    assert load_program_source("twice", "fragment", {}, root).count("a_function") == 1
    with pytest.raises(GratNetError, match=r"b\.glsl:2: include cycle"):
        load_program_source("cycle", "fragment", {}, root)
    with pytest.raises(GratNetError, match=r'missing\.glsl:3: included file "nowhere\.glsl" not found'):
        load_program_source("missing", "fragment", {}, root)
    with pytest.raises(GratNetError, match="malformed include"):
        load_program_source("bad", "fragment", {}, root)
    with pytest.raises(GratNetError, match="remove #version"):
        load_program_source("versioned", "fragment", {}, root)
    with pytest.raises(GratNetError, match="not found"):
        load_program_source("no_such_program", "fragment", {}, root)
    with pytest.raises(GratNetError, match="unknown shader stage"):
        load_program_source("twice", "geometry", {}, root)
    for defines in ({"1BAD": 1}, {"GL_THING": 1}, {"X": "text"}, {"X": True}, {"X": float("nan")},
                    {"FRAGMENT_SHADER": 1}):
        with pytest.raises(GratNetError):
            load_program_source("twice", "fragment", defines, root)


def test_repository_programs_preprocess():
    for name in ("brdf_slice", "evaluate_keys", "display"):
        for stage in ("vertex", "fragment"):
            text = load_program_source(name, stage, {"MAX_BLOCKS": 41, "MAX_LAYERS": 5, "MAX_FREQUENCIES": 19,
                                                     "LEAKY_RELU_SLOPE": 0.01})
            assert text.startswith("#version 430 core\n") and "#include" not in text


# ------------------------------------------------------------------------------------------------
# (e) the A-term (eq. 5)


def direction_pairs() -> tuple[np.ndarray, np.ndarray]:
    """Normal, oblique, grazing (incl. nearly opposite), |w| around 1e-6 and below-horizon pairs of directions."""
    pairs = [
        ((0, 0), (0, 0)), ((45, 10), (30, 190)), ((20, 0), (70, 90)), ((60, 200), (-5, 0)),
        ((89, 0), (89, 180)), ((89.9, 180), (89.9, 0)), ((89.99, 0), (85, 180)), ((89, 0), (89, 0)),
        ((90, 0), (90, 180)), ((89.99999, 0), (89.99999, 180)), ((89.9999, 0), (89.9999, 90)),
        ((95, 0), (10, 0)), ((30, 0), (120, 45)), ((180, 0), (0, 0)),
    ]
    rng = np.random.default_rng(3)
    for _ in range(20):
        pairs.append(((rng.uniform(0, 89.5), rng.uniform(0, 360)), (rng.uniform(0, 89.5), rng.uniform(0, 360))))
    light = np.array([direction(*first) for first, _ in pairs])
    view = np.array([direction(*second) for _, second in pairs])
    # The reference gets the exact unit vectors: rounded to float32 they are no longer unit, and for
    # nearly opposite grazing pairs 1 + ωi·ωo then loses digits in float64 too; the shader's
    # |ωi + ωo|²/2 form of it does not, so it is compared with the exact value.
    return light, view


# 1 ± 1e-5 and 1 + 2⁻²³: the direct R/R0 was 12–57 % off there in float32 (issue 11); 1: its limit. Near 1
# the ratio grows like 1/(n − 1)² at grazing angles, so the IOR is one the float32 uniform holds exactly.
@pytest.mark.parametrize("ior", [1.5, None, 1.33, 0.7, *(float(np.float32(n)) for n in (1 + 1e-5, 1 - 1e-5)),
                                 1 + 2.0**-23, 1.0])
def test_gpu_a_term_matches_numpy(ctx, ior):
    from viewer.renderer import NetworkRenderer

    light, view = direction_pairs()
    expected = a_term(light, view, ior)
    renderer = NetworkRenderer(ctx, random_model([163, 9, 3]))
    try:
        actual = renderer.a_term(light, view, ior)
    finally:
        renderer.release()
    assert actual.shape == expected.shape == (light.shape[0],)
    assert expected[0] == pytest.approx(1.0) and actual[0] == pytest.approx(1.0, rel=1e-6)
    assert np.all(actual[expected == 0.0] == 0.0) and np.count_nonzero(expected == 0.0) == 5
    assert_relative(actual, expected, RELATIVE, floor=1e-12)


@pytest.mark.parametrize("covariance", [(0.0, 0.0, 0.0), (0.0069, 0.0, 0.030), (0.146, 0.0, 0.0), (0.86, 0.3, 0.85)])
def test_gpu_shadowing_matches_numpy(ctx, covariance):
    """brdf.glsl's smith_shadowing against gratnet.shadowing, from normal incidence to within 1e-6 of the horizon."""
    import dataclasses

    from gratnet.shadowing import smith_shadowing
    from viewer.renderer import NetworkRenderer

    rng = np.random.default_rng(5)
    thetas = np.concatenate([rng.uniform(0.0, 90.0, 3000), 90.0 - np.logspace(-4, 0, 200), [0.0, 90.0, 95.0]])
    phis = rng.uniform(0.0, 360.0, thetas.size)
    light = np.array([direction(t, p) for t, p in zip(thetas, phis, strict=True)])
    view = np.array([direction(t, p) for t, p in zip(rng.uniform(0.0, 89.9, thetas.size), phis[::-1], strict=True)])
    base = random_model([163, 9, 3])
    model = dataclasses.replace(base, metadata={"volume": {"slope_covariance": list(covariance)}})
    expected = smith_shadowing(light.astype(np.float32), view.astype(np.float32), covariance)
    renderer = NetworkRenderer(ctx, model)
    try:
        actual = renderer.shadowing(light, view)
    finally:
        renderer.release()
    assert actual.shape == expected.shape and np.all(actual[expected == 0.0] == 0.0)
    assert np.count_nonzero(expected == 0.0) == 2  # at and below the horizon
    np.testing.assert_allclose(actual, expected, rtol=2e-5, atol=1e-6)


# ------------------------------------------------------------------------------------------------
# colour.glsl against gratnet.display


def test_gpu_display_srgb_matches_colour_science(ctx):
    colour = pytest.importorskip("colour")
    from gratnet.display import xyz_to_linear_srgb
    from viewer.renderer import NetworkRenderer

    xyz = np.random.default_rng(5).uniform(0.0, 1.2, (7, 9, 3))
    xyz[0, 0] = 0.0
    expected = colour.cctf_encoding(np.clip(xyz_to_linear_srgb(xyz) * 1.3, 0.0, 1.0), function="sRGB")
    renderer = NetworkRenderer(ctx, random_model([163, 9, 3]))
    try:
        actual = renderer.display_srgb(xyz, exposure=1.3)
    finally:
        renderer.release()
    assert actual.shape == (7, 9, 3)
    np.testing.assert_allclose(actual, expected, rtol=0.0, atol=2e-6)
