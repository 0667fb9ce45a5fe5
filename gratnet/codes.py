"""Every code that Python and the GLSL share, defined once (issue 45), and the weight forms of the render paths.

The shaders compare uniforms with named codes (``u_scheme == SCHEME_SIMPLE_MAX``), bind buffers at named
bindings (``binding = WEIGHTS_BINDING``) and count into named counters (``COUNTER_EVALUATIONS``); the renderer
sets those uniforms, binds those buffers and reads those counters. Both sides read the tables here:

- Python asks a table for a code (``SCHEME.code("simple-max")`` → 2) or reads a number (:data:`BINDINGS`);
- the GLSL includes ``"codes.glsl"`` (:data:`GLSL_INCLUDE`), which no file holds: ``viewer.glsl`` serves
  :func:`glsl_source`, one ``#define NAME value`` per code (:func:`glsl_defines`), at the top of the program.

A :class:`Codes` table numbers its names 0, 1, … in order; a name's define is the table's prefix and the name in
capitals, ``-`` as ``_`` (``simple-max`` → ``SCHEME_SIMPLE_MAX``). The light kinds' codes come from the light
registry, :mod:`gratnet.lights`, the area lights' from :mod:`gratnet.area_lights`. tests/contract/test_shared_codes.py
checks that the shaders use the generated names and type no code of their own, and that no Python module outside
these two types a table again.

Weight forms (``--deferred-weights``, ``--weights-path``): :class:`WeightForm`, parsed once from the flag's
string into typed fields (kernel, weight source, storage and arithmetic precision); :data:`WEIGHT_FORMS` lists
them in the flag's order.

Standard library only: ``gratnet --help`` and the flag declarations import this module.
"""

from __future__ import annotations

import dataclasses
import enum

from gratnet.area_lights import AREA_KINDS, MAX_AREA_LIGHTS
from gratnet.errors import GratNetError
from gratnet.lights import LIGHT_KINDS

__all__ = [
    "AREA",
    "BINDINGS",
    "COUNTER",
    "COUNTER_SLOTS",
    "DEFERRED_TILE",
    "DEFERRED_WEIGHTS",
    "DEFAULT_ENVIRONMENT_SAMPLING",
    "ENVIRONMENT_SAMPLING",
    "GLSL_INCLUDE",
    "HIDDEN",
    "LIGHT",
    "MODE",
    "OUTPUT",
    "RANGE",
    "RENDER_PATHS",
    "SCHEME",
    "TABLES",
    "TILED_WEIGHTS",
    "WEIGHTS_PATHS",
    "WEIGHT_FORMS",
    "Codes",
    "Kernel",
    "Precision",
    "WeightForm",
    "WeightSource",
    "choices_text",
    "glsl_defines",
    "glsl_source",
]


def choices_text(names: tuple[str, ...], last: str = "or") -> str:
    """``a, b or c`` (for messages)."""
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} {last} {names[-1]}"


@dataclasses.dataclass(frozen=True)
class Codes:
    """Names numbered 0, 1, … in order, each a GLSL ``#define PREFIX_NAME code``.

    Attributes:
        prefix: the defines' prefix, without the ``_`` (``SCHEME``).
        what: what a name is, for messages (``sampling scheme``).
        names: the names as Python and the files spell them, in code order.
        uniform: the GLSL uniform that holds one of the codes (``u_scheme``), or ``None`` (the counters).
        expressions: for the activations, each name's GLSL expression in ``vec4 x``: shaders/mlp.glsl computes it
            in the branch of its code; the baked MLP (viewer/baked.py) writes it in.
    """

    prefix: str
    what: str
    names: tuple[str, ...]
    uniform: str | None = None
    expressions: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if len(set(self.names)) != len(self.names) or (self.expressions and len(self.expressions) != len(self.names)):
            raise GratNetError(f"code table {self.prefix}: names must be distinct, one expression each")

    def __contains__(self, name: object) -> bool:
        return name in self.names

    @property
    def uniform_name(self) -> str:
        """:attr:`uniform`, of a table that has one (a GratNetError for the counters')."""
        if self.uniform is None:
            raise GratNetError(f"code table {self.prefix} has no uniform")
        return self.uniform

    def code(self, name: str) -> int:
        """The code of ``name`` (a one-line GratNetError for another name)."""
        if name not in self.names:
            raise GratNetError(f"unknown {self.what} {name!r}; choose {choices_text(self.names)}")
        return self.names.index(name)

    def define(self, name: str) -> str:
        """The GLSL name of ``name``'s code: ``SCHEME_SIMPLE_MAX``."""
        return f"{self.prefix}_{name.upper().replace('-', '_')}"

    def defines(self) -> dict[str, int]:
        """``{define: code}`` for every name."""
        return {self.define(name): code for code, name in enumerate(self.names)}

    def expression(self, name: str) -> str:
        """``name``'s GLSL expression in ``vec4 x`` (activations only)."""
        return self.expressions[self.code(name)]


#: Sampling schemes of a volume (physics.md "Sampling"): shaders/encoding.glsl's key → network coordinates.
SCHEME = Codes("SCHEME", "sampling scheme", ("regular", "simple", "simple-max"), "u_scheme")
#: Hidden-layer activations (``leaky_relu``'s slope: the LEAKY_RELU_SLOPE define, gratnet.network.LEAKY_RELU_SLOPE).
HIDDEN = Codes("HIDDEN", "hidden activation", ("relu", "leaky_relu", "silu"), "u_hidden_activation",
               ("max(x, 0.0)", "max(x, LEAKY_RELU_SLOPE * x)", "x * sigmoid(x)"))
#: Output activations: ``clamp`` to [0, 1], ``sigmoid``, ``none`` (the identity).
OUTPUT = Codes("OUTPUT", "output activation", ("clamp", "sigmoid", "none"), "u_output_activation",
               ("clamp(x, 0.0, 1.0)", "sigmoid(x)", "x"))
#: Range transforms of the network's outputs (physics.md eq. 7): shaders/range.glsl.
RANGE = Codes("RANGE", "range transform", ("power-log", "log", "log1p"), "u_range_kind")
#: What shaders/evaluate_keys.glsl computes per pixel (viewer.renderer.NetworkRenderer's key evaluations).
MODE = Codes("MODE", "evaluation mode", ("xyz", "network", "encoding", "a_term"), "u_mode")
#: The work counters (shaders/counters.glsl), in slot order; their names are a render's ``statistics`` keys.
COUNTER = Codes("COUNTER", "work counter",
                ("fragments", "evaluations", "skipped_a_zero", "skipped_bound", "background"))
#: Light kinds, from the light registry (gratnet.lights): shaders/lights.glsl.
LIGHT = Codes("LIGHT", "light kind", tuple(kind.name for kind in LIGHT_KINDS), "u_light_kind")
#: How an environment light is sampled (shaders/environment.glsl): both strategies weighted by multiple importance
#: sampling (``mis``), one alone (``light``: the map's luminance; ``material``: the material's table), or
#: ``resampled``: candidates from both, one kept in proportion to the expected shading (resampled importance
#: sampling; the GL renderer's default).
ENVIRONMENT_SAMPLING = Codes("SAMPLING", "environment sampling", ("mis", "light", "material", "resampled"),
                             "u_environment_sampling")
#: The GL renderer's sampling when none is asked for (the least noise per pass: docs/benchmarks.md).
DEFAULT_ENVIRONMENT_SAMPLING = "resampled"
#: The most candidates one pass of ``resampled`` sampling may draw (shaders/environment.glsl's loop bound).
MAX_CANDIDATES = 64
#: Area light kinds, from their registry (gratnet.area_lights): shaders/area_lights.glsl.
AREA = Codes("AREA", "area light kind", tuple(kind.name for kind in AREA_KINDS), "u_area_kind")
#: Every table, for the generated defines and the tests.
TABLES = (SCHEME, HIDDEN, OUTPUT, RANGE, MODE, COUNTER, LIGHT, ENVIRONMENT_SAMPLING, AREA)

#: Slots of the counter buffer (``COUNTER_COUNT``): room for counters to come.
COUNTER_SLOTS = 8
#: SSBO bindings and image units of the programs, by define name.
BINDINGS = {
    "SKIP_COUNTER_BINDING": 5,  # the work counters (shaders/counters.glsl; viewer.shading)
    "WEIGHTS_BINDING": 6,  # the weight buffer of the deferred path's ssbo/shared/tiled forms (shaders/mlp.glsl)
    "DEFERRED_LIST_BINDING": 7,  # the deferred path's list of pixels to shade (shaders/deferred.glsl)
    "GBUFFER_IMAGE_BINDING": 0,  # image unit of the deferred path's G-buffer (shaders/deferred.glsl)
    "RESOLVED_IMAGE_BINDING": 1,  # image unit of its resolved picture (several samples)
    "OFFSET_IMAGE_BINDING": 2,  # image unit of its control-variate terms under sampled light (the TINT kernel)
}
#: Texels per side of the deferred path's COMPACT and RESOLVE work groups.
DEFERRED_TILE = 8
#: The virtual include that serves :func:`glsl_source` (viewer.glsl).
GLSL_INCLUDE = "codes.glsl"


def glsl_defines() -> dict[str, int]:
    """Every generated define: the tables' codes, ``COUNTER_COUNT``, the bindings and ``DEFERRED_TILE``."""
    entries = [item for table in TABLES for item in table.defines().items()]
    entries += [("COUNTER_COUNT", COUNTER_SLOTS), *BINDINGS.items(), ("DEFERRED_TILE", DEFERRED_TILE),
                ("MAX_AREA_LIGHTS", MAX_AREA_LIGHTS), ("MAX_CANDIDATES", MAX_CANDIDATES)]
    defines = dict(entries)
    if len(defines) != len(entries):
        raise GratNetError("gratnet.codes: two codes have the same GLSL name")
    return defines


def glsl_source() -> str:
    """The text of ``codes.glsl``: one ``#define NAME value`` per entry of :func:`glsl_defines`."""
    lines = ["// Generated by gratnet/codes.py (issue 45): the codes Python and the GLSL share. Do not edit; no file",
             "// holds it: viewer/glsl.py puts it at the top of every program that includes \"codes.glsl\"."]
    lines += [f"#define {name} {value}" for name, value in glsl_defines().items()]
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------------------------
# Weight forms


class Kernel(enum.Enum):
    """The deferred path's shading kernel (shaders/deferred.glsl)."""

    ENTRY = "entry"  #: ``SHADE``: one invocation per list entry
    TILED = "tiled"  #: ``SHADE_TILED``: a work group per tile of entries, a matrix product (shaders/mlp_tiled.glsl)


class WeightSource(enum.Enum):
    """Where the network's weights are read; the values are ``--weights-path``'s choices and the per-entry forms'."""

    AUTO = "auto"  #: chosen by the renderer
    TEXTURE = "texture"  #: the packed RGBA32F texture
    BUFFER = "ssbo"  #: the same texels in a std430 buffer (``WEIGHTS_SSBO``)
    SHARED = "shared"  #: that buffer copied into each work group's shared memory (``WEIGHTS_SHARED``)
    BAKED = "baked"  #: literals in a generated shader (viewer/baked.py)


class Precision(enum.Enum):
    """Bits of a stored weight, or of the kernel's arithmetic."""

    FLOAT32 = "float32"
    FLOAT16 = "float16"


@dataclasses.dataclass(frozen=True)
class WeightForm:
    """One ``--deferred-weights`` choice, parsed (:meth:`parse`): the kernel and where and how it reads the weights.

    Attributes:
        name: the flag's spelling, as configs save it (``ssbo-fp16``).
        source: where the weights are read (``AUTO``: the renderer chooses a form).
        kernel: the per-entry ``SHADE`` kernel or the tiled one.
        storage: a buffer's weights as float32 or IEEE halves (``WEIGHTS_FP16``; texture and baked: float32).
        arithmetic: the tiled kernel's products in float32 or in half precision (``TILED_HALF``).
    """

    name: str
    source: WeightSource
    kernel: Kernel = Kernel.ENTRY
    storage: Precision = Precision.FLOAT32
    arithmetic: Precision = Precision.FLOAT32

    @property
    def buffer(self) -> bool:
        """Whether the weights come from the std430 buffer (directly or through shared memory)."""
        return self.source in (WeightSource.BUFFER, WeightSource.SHARED)

    @property
    def texel_bytes(self) -> int:
        """Bytes of one weight texel (four weights) as stored."""
        return 8 if self.storage is Precision.FLOAT16 else 16

    @classmethod
    def reading(cls, source: WeightSource) -> WeightForm:
        """The per-entry float32 form that reads the weights from ``source``."""
        return next(form for form in WEIGHT_FORMS if form.source is source and form.kernel is Kernel.ENTRY
                    and form.storage is Precision.FLOAT32)

    @classmethod
    def parse(cls, text: str | WeightForm) -> WeightForm:
        """The form named ``text`` (a form passes through), or a one-line GratNetError."""
        if isinstance(text, WeightForm):
            return text
        for form in WEIGHT_FORMS:
            if form.name == text:
                return form
        raise GratNetError(f"deferred weights must be one of {', '.join(DEFERRED_WEIGHTS)}, got {text!r}")


_SSBO, _SHARED, _TILED, _HALF = WeightSource.BUFFER, WeightSource.SHARED, Kernel.TILED, Precision.FLOAT16
#: ``--deferred-weights``' forms, in the flag's order (viewer/deferred.py's module docstring says what each does).
WEIGHT_FORMS = (
    WeightForm("auto", WeightSource.AUTO),
    WeightForm("texture", WeightSource.TEXTURE),
    WeightForm("ssbo", _SSBO),
    WeightForm("shared", _SHARED),
    WeightForm("baked", WeightSource.BAKED),
    WeightForm("ssbo-fp16", _SSBO, storage=_HALF),
    WeightForm("shared-fp16", _SHARED, storage=_HALF),
    WeightForm("tiled", _SSBO, _TILED),
    WeightForm("tiled-fp16", _SSBO, _TILED, storage=_HALF),
    WeightForm("tiled-half", _SSBO, _TILED, storage=_HALF, arithmetic=_HALF),
)
#: ``--deferred-weights`` choices (viewer.deferred and viewer.scene_config re-export them).
DEFERRED_WEIGHTS = tuple(form.name for form in WEIGHT_FORMS)
#: The tiled kernel's forms.
TILED_WEIGHTS = tuple(form.name for form in WEIGHT_FORMS if form.kernel is Kernel.TILED)
#: ``--weights-path`` choices: where the forward path's shaders read the weights (viewer.renderer.choose_weights_path).
WEIGHTS_PATHS = tuple(source.value for source in (WeightSource.AUTO, WeightSource.TEXTURE, WeightSource.BAKED))
#: ``--render-path`` choices (viewer.scene.choose_render_path).
RENDER_PATHS = ("auto", "forward", "deferred")
