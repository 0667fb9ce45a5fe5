"""The funnel MLP as GLSL with the model's weights baked in as literals: a faster stand-in for mlp.glsl.

:func:`baked_mlp_source` writes ``vec3 mlp_evaluate()`` with the same signature and meaning as
``shaders/mlp.glsl`` — inputs: a feature-grid model's grid features (featuregrid.glsl, which the including
shader includes before mlp.glsl: a generated source includes nothing), then the encoding (eq. 6) of the key set
by ``encoding_set_key``, the hidden activation after
every layer but the last, the output activation after the last, returns the range-transformed XYZ
(eq. 7 domain) — but declares no uniforms and reads no texture: every 4×4 weight block is a ``mat4``
literal. It computes the encoding itself, from encoding.glsl's per-frequency functions (the only uniforms
it reads are encoding.glsl's frequency table ``u_frequency``, at constant indices).

Shape (measured on Mesa llvmpipe; see :func:`viewer.renderer.choose_weights_path` for when it is used):
straight-line code, no loops and no arrays, one ``vec4`` variable per block, ``a = bias; a += mat4(…) * x_i;
…``, output block by output block, leaving out blocks that are all zero (padding, or pruned weights).
Straight-line literals let LLVM keep each weight as an immediate operand; the JIT time grows with the net
(≈25 s for 28k MACs, once: Mesa's disk shader cache keeps it). Only ``vec4``/``mat4`` forms: llvmpipe
miscompiles scalar ``float[]`` scratch arrays written at a variable index
(shared/notes/opengl-on-this-machine.md). Literals are the shortest decimal strings that round-trip to
the float32 weights, so the shader multiplies exactly the weights that numpy does.
"""

from __future__ import annotations

import numpy as np

from gratnet.codes import HIDDEN, OUTPUT
from gratnet.errors import GratNetError
from gratnet.featuregrid import CHUNK_FEATURES, grid_chunks
from gratnet.modelfile import ModelFile, texture_layout

__all__ = ["baked_encoded_inputs", "baked_mlp_source", "float_literal"]


def float_literal(value: float | np.floating) -> str:
    """A GLSL float literal that parses to exactly ``float32(value)``: numpy's shortest round-trip form."""
    single = np.float32(value)
    if not np.isfinite(single):
        raise GratNetError(f"cannot bake a non-finite weight ({value!r}) into GLSL")
    if single == 0:
        return "0.0"  # also for -0.0: the sum is the same
    # The shortest digits that round-trip to this float32 ('0.1', '-3.0', '1.5e-05'); str() would not do:
    # it prints large values with 6 digits only.
    if 1e-4 <= abs(single) < 1e7:
        return np.format_float_positional(single, unique=True, trim="0")
    return np.format_float_scientific(single, unique=True, trim="0")


def _vec4(values: np.ndarray) -> str:
    return "vec4(" + ", ".join(float_literal(v) for v in values) + ")"


def _mat4(block: np.ndarray) -> str:
    """``block[r, j]`` = W[4o + r, 4i + j]; GLSL's mat4 takes columns, so column j is block[:, j]."""
    return "mat4(" + ", ".join(float_literal(v) for v in block.T.reshape(-1)) + ")"


def baked_encoded_inputs(model: ModelFile) -> list[tuple[str, str, list[int]]]:
    """The baked layer 1's input vec4s: ``(GLSL declaration, variable, eq. 6 feature index per lane)``,
    a lane -1 holding no feature. Together they hold every feature of ``model.encoding`` once."""
    spatial, temporal, groups = model.encoding.frequencies, model.encoding.t_frequencies, model.encoding.groups
    inputs = [("vec4 coordinates = vec4(g_coordinates, 0.0);", "coordinates", [0, 1, 2, -1])]
    for j in range(spatial):
        inputs.append((f"vec4 sin_{j}, cos_{j}; encoded_spatial_frequency({j}, sin_{j}, cos_{j});", f"sin_{j}",
                       [3 + 2 * spatial * g + j if g < groups else -1 for g in range(4)]))
        inputs.append(("", f"cos_{j}", [3 + 2 * spatial * g + spatial + j if g < groups else -1 for g in range(4)]))
    first_t = 3 + 2 * groups * spatial  # eq. 6a: lanes 2 and 3 (the diagonals) hold no feature
    for j0 in range(0, temporal, 4):
        lanes = list(range(j0, min(j0 + 4, temporal)))
        a = ", ".join([f"u_frequency[{j}].z" for j in lanes] + ["0.0"] * (4 - len(lanes)))
        b = ", ".join([f"u_frequency[{j}].w" for j in lanes] + ["0.0"] * (4 - len(lanes)))
        inputs.append((f"vec4 t_sin_{j0}, t_cos_{j0}; encoded_t_frequencies(vec4({a}), vec4({b}), t_sin_{j0}, "
                       f"t_cos_{j0});", f"t_sin_{j0}", [first_t + j for j in lanes] + [-1] * (4 - len(lanes))))
        inputs.append(("", f"t_cos_{j0}", [first_t + temporal + j for j in lanes] + [-1] * (4 - len(lanes))))
    return inputs


def baked_mlp_source(model: ModelFile, name: str = "model") -> str:
    """GLSL for ``vec3 mlp_evaluate()`` with ``model``'s weights as literals (replaces ``mlp.glsl``).

    Args:
        model: a validated network (``ModelFile``); its encoding must be the one encoding.glsl is set up for.
        name: how the header comment names the model (e.g. its file name).
    """
    sizes = list(model.layer_sizes)
    layout = texture_layout(sizes)
    if model.activation not in HIDDEN or model.output_activation not in OUTPUT:
        raise GratNetError(f"cannot bake activations {model.activation!r}/{model.output_activation!r}")
    lines = [
        f"// Generated by viewer/baked.py from {name}: the funnel MLP {'-'.join(map(str, sizes))} with its weights",
        "// as literals (same contract as shaders/mlp.glsl, no weight texture). Do not edit.",
        "",
        "vec4 sigmoid(vec4 x) {",
        "    return 1.0 / (1.0 + exp(-clamp(x, -80.0, 80.0)));  // clamp before exp: no overflow to inf",
        "}",
        "",
        # gratnet/codes.py's expressions, as mlp.glsl's branches compute them (LEAKY_RELU_SLOPE: the model's define)
        f"vec4 hidden_activation(vec4 x) {{ return {HIDDEN.expression(model.activation)}; }}",
        f"vec4 output_activation(vec4 x) {{ return {OUTPUT.expression(model.output_activation)}; }}",
        "",
        "vec3 mlp_evaluate() {",
    ]
    last = len(layout) - 1
    padded = []
    for entry, weight, bias in zip(layout, model.weights, model.biases, strict=True):
        outputs, inputs = weight.shape
        w = np.zeros((4 * entry["out_blocks"], 4 * entry["in_blocks"]), dtype=np.float32)
        w[:outputs, :inputs] = weight
        b = np.zeros(4 * entry["out_blocks"], dtype=np.float32)
        b[:outputs] = bias
        padded.append((w, b))

    def block(k: int, o: int, i: int) -> np.ndarray:
        return padded[k][0][4 * o:4 * o + 4, 4 * i:4 * i + 4]

    def out_blocks(k: int) -> int:
        return 1 if k == last else layout[k]["out_blocks"]  # the last layer: outputs 0-2 only

    def activation(k: int) -> str:
        return "output_activation" if k == last else "hidden_activation"

    # Layer 1 (the widest: encoded inputs -> first hidden layer), straight-line like the later layers. Its
    # inputs are not eq. 6's blocks but what is cheap to compute (encoding.glsl): the sines (and cosines) of
    # one frequency for all four spatial groups, four t frequencies at once; the weight columns are
    # permuted to match, so each sum is eq. 6's. All inputs first, then one output block at a time over
    # them (output-major): on llvmpipe at 28k MACs this ran 2x faster than input-major with SiLU. No loop
    # and no array: a const mat4[] indexed in a loop over encoded_block(i) took minutes of JIT at 28k MACs.
    ob = out_blocks(0)
    # A feature-grid model's inputs are its grid features first (featuregrid.glsl fetches chunk k of level l,
    # the level's features 4k … 4k + 3, into g_grid_features[l * chunks + k]; a last chunk's lanes beyond C
    # hold none), then the encoding: its columns follow the grids'.
    grid_width = model.grid_feature_count
    channels = int(model.grids[0].shape[-1]) if model.grids else 0
    chunks = grid_chunks(channels)
    encoded = [("", f"g_grid_features[{level * chunks + k}]",
                [level * channels + c if c < channels else -1
                 for c in range(CHUNK_FEATURES * k, CHUNK_FEATURES * (k + 1))])
               for level in range(len(model.grids)) for k in range(chunks)]
    encoded += [(declaration, name, [f + grid_width if f >= 0 else -1 for f in features])
                for declaration, name, features in baked_encoded_inputs(model)]
    lines.append(f"    // layer 1: {model.weights[0].shape[1]} -> {model.weights[0].shape[0]}")
    if model.grids:
        lines.append("    grid_set_key();  // featuregrid.glsl: this key's features of every level")
    lines += [f"    {declaration}" for declaration, _, _ in encoded if declaration]
    for o in range(ob):
        lines.append(f"    vec4 a1_{o} = {_vec4(padded[0][1][4 * o:4 * o + 4])};")
        for _, name, features in encoded:
            weights = padded[0][0][4 * o:4 * o + 4, [max(f, 0) for f in features]]
            weights[:, [f < 0 for f in features]] = 0.0  # lanes that hold no feature (padding) weigh nothing
            if np.any(weights != 0):
                lines.append(f"    a1_{o} += {_mat4(weights)} * {name};")
    lines += [f"    a1_{o} = {activation(0)}(a1_{o});" for o in range(ob)]
    for k in range(1, last + 1):
        outputs, inputs = model.weights[k].shape
        lines.append(f"    // layer {k + 1}: {inputs} -> {outputs}")
        for o in range(out_blocks(k)):
            lines.append(f"    vec4 a{k + 1}_{o} = {_vec4(padded[k][1][4 * o:4 * o + 4])};")
            for i in range(layout[k]["in_blocks"]):
                if np.any(block(k, o, i) != 0):  # padding blocks add nothing
                    lines.append(f"    a{k + 1}_{o} += {_mat4(block(k, o, i))} * a{k}_{i};")
            lines.append(f"    a{k + 1}_{o} = {activation(k)}(a{k + 1}_{o});")
    lines += [f"    return a{last + 1}_0.xyz;", "}", ""]
    return "\n".join(lines)
