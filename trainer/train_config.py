"""The training run's configuration (torch-free, so that the CLI can list its flags without torch).

``--preset`` names a network size (trainer.model.PRESETS: paper, funnel-176, medium, small, tiny: hidden widths
only) or a recipe (:data:`RECIPES`: ``fast``, the fast point of a shipped material, gratnet.quality), which sets
the architecture, widths, grid and encoding. Options given explicitly win over a recipe's, as ``--hidden`` wins
over a size preset: ``gratnet train`` knows which flags were given (:func:`mark_recipe_flags`,
:func:`config_from_arguments`), code says it with :func:`preset_config`'s keywords.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import re
from collections.abc import Mapping
from typing import Any, Literal

import numpy as np

from gratnet.config import config_field, flat_fields, flat_keywords, nested_field
from gratnet.encoding import EncodingSpec, RangeSpec, range_forward
from gratnet.errors import GratNetError
from gratnet.quality import FAST
from gratnet.volume import Volume

#: Presets that are whole recipes, by flat field name (``grid_levels``: ``--grid-levels``). ``fast``: a feature-grid
#: network of at most a fifth of the shipped paper models' multiply-adds per pixel, the recipe that the fifth pass
#: of the screen on paper-cd chose (docs/experiments/2026-11-27-fast-models-screen.md): every frequency on the axes
#: alone (eq. 6a) into a 40-24-12 funnel, the unseen features silenced.
RECIPES: dict[str, dict[str, Any]] = {
    FAST: {"architecture": "grid", "hidden": "40,24,12", "grid_levels": 3, "grid_resolution": 251,
           "grid_t_resolution": 5, "grid_features": 8, "frequencies": 19, "t_frequencies": 2,
           "diagonal_frequencies": False},
}
#: Every field some recipe sets (their flags' defaults mean "not given" on gratnet train's command line).
RECIPE_FIELDS = tuple(sorted({name for recipe in RECIPES.values() for name in recipe}))
#: The fast recipe as the flags that spell it (the preset's help).
_FAST_FLAGS = " ".join((f"--{'' if value else 'no-'}{name.replace('_', '-')}" if isinstance(value, bool)
                        else f"--{name.replace('_', '-')} {value}") for name, value in RECIPES[FAST].items())


@dataclasses.dataclass(frozen=True)
class GridConfig:
    """The feature grids of ``--architecture grid`` (``TrainConfig.grid``; flags ``--grid-*``, keys ``grid_*``):
    their levels and nodes, features, initialisation, optimiser and storage. Checked by TrainConfig, and only for
    that architecture (an mlp run accepts any)."""

    levels: int = config_field(3, "grid: levels, each half the u*/v* node intervals of the next")
    resolution: int = config_field(251, "grid: nodes per u*/v* axis of the finest level (251 = every 4th of a "
                                   "1001² volume's samples)")
    t_resolution: int = config_field(11, "grid: nodes along t of every level (11 = the volume's slices)")
    level_t: str = config_field("", "grid: nodes along t per level, coarse to fine, comma-separated (overrides "
                                "--grid-t-resolution; e.g. 11,11,2 for a fine level that varies little in t)")
    level_step: int = config_field(2, "grid: ratio of u*/v* node intervals between neighbouring levels (2: "
                                   "each coarser level has half the intervals of the next)")
    features: int = config_field(2, "grid: features per level, C (1 to 16: the shader reads a level as "
                                 "ceil(C/4) RGBA textures, features 4k..4k+3 in the k-th; 2 keeps the default "
                                 "grid at 3.65 MB as float16)")
    init: float = config_field(1e-4, "grid: initial features uniform in ±this")
    learning_rate: float = config_field(1e-2, "grid: Adam's initial learning rate of the grids (same schedule)")
    dtype: Literal["float16", "float32"] = config_field("float16", "grid: storage dtype in the model file")
    interpolation: Literal["linear", "smoothstep"] = config_field(
        "linear", "grid: between nodes, linear (trilinear, C⁰) or smoothstep (C¹: f → f²(3 − 2f) per axis; the "
        "same cost)"
    )
    adam_epsilon: float = config_field(
        1e-8, "grid: Adam's ε of the grids (their sqrt(v) ends near 1e-10, so at 1e-8 ε sets their step; "
        "instant-NGP uses 1e-15)"
    )

    def check(self) -> None:
        """The checks of a grid run's options (the sizes, features, initialisation, rate, interpolation, dtype);
        ``adam_epsilon`` is TrainConfig's to check, beside the MLP's."""
        from gratnet.featuregrid import MAX_FEATURES, check_interpolation

        self.shapes()  # checks the sizes
        if not 1 <= self.features <= MAX_FEATURES:
            raise GratNetError(f"--grid-features must be from 1 to {MAX_FEATURES}, got {self.features}")
        if not (self.init >= 0 and self.learning_rate > 0):
            raise GratNetError(f"--grid-init must be ≥ 0 and --grid-learning-rate > 0, got {self.init}, "
                               f"{self.learning_rate}")
        check_interpolation(self.interpolation)
        if self.dtype not in ("float16", "float32"):
            raise GratNetError(f"--grid-dtype must be float16 or float32, got {self.dtype!r}")

    def shapes(self) -> list[tuple[int, int, int, int]]:
        """(T, R, R, C) of every level, coarse to fine."""
        from gratnet.featuregrid import level_resolutions

        t_nodes: int | list[int] = self.t_resolution
        if self.level_t.strip():
            try:
                t_nodes = [int(part) for part in self.level_t.split(",")]
            except ValueError:
                raise GratNetError(f"--grid-level-t must be comma-separated integers (one per level), got "
                                   f"{self.level_t!r}") from None
        return [(t, r, r, self.features) for r, t in level_resolutions(self.levels, self.resolution, t_nodes,
                                                                        self.level_step)]


@flat_keywords
@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """Network, encoding, range transform and optimisation of one training run.

    The grid options are nested (``config.grid``, a :class:`GridConfig`) under flat public names: the flags
    ``--grid-levels`` …, the keywords and sweep keys ``grid_levels`` … (``TrainConfig(grid_levels=2)`` is
    ``TrainConfig(grid=GridConfig(levels=2))``), and a config saved with flat keys, before the nesting, loads.
    """

    architecture: Literal["mlp", "grid"] = config_field(
        "mlp", "network: mlp (the paper's funnel MLP on the encoding) or grid (learned feature grids over "
        "(u*, v*, t) interpolated trilinearly, then the encoding, into a small funnel MLP; docs/physics.md)"
    )
    preset: str = config_field("small", "network preset: a size (hidden widths) paper, funnel-176, medium, small, "
                               "tiny, or fast: a recipe of architecture, widths, grid and encoding, a shipped "
                               f"material's fast point ({_FAST_FLAGS}; each of those given explicitly wins)")
    hidden: str = config_field("", "explicit hidden widths, comma-separated (overrides --preset)")
    activation: str = config_field("silu", "hidden activation: silu (measured best), relu, leaky_relu")
    output_activation: str = config_field("clamp", "output activation: clamp (to [0, 1]), sigmoid, none")
    frequencies: int = config_field(19, "encoding frequencies L for u*, v*, u*+v*, u*−v*")
    t_frequencies: int = config_field(4, "encoding frequencies L_t for t")
    diagonal_frequencies: bool = config_field(
        True, "encode u*+v* and u*−v* too (eq. 6); --no-diagonal-frequencies: u* and v* alone (eq. 6a), half the "
        "spatial encoding terms and first-layer inputs")
    range_kind: str = config_field("power-log", "range transform: power-log, log, log1p")
    range_bits: float = config_field(48.0, "B of the log range transforms")
    range_power: float = config_field(8.0, "n of the power-log range transform")
    split: Literal["slices", "random", "all"] = config_field(
        "slices", "held-out data: whole slices, random samples, none"
    )
    test_slices: str = config_field("4,7,10", "held-out slice indices for --split slices")
    test_fraction: float = config_field(0.1, "held-out fraction for --split random")
    grid: GridConfig = nested_field(GridConfig, "grid")
    loss_visible_y: str = config_field(
        "", "display-weighted loss: 'LOW,HIGH', a band of CIE Y (the volume's units, 1 = a perfect mirror's peak) "
        "whose samples weigh --loss-visible-weight in the LogCosh mean; e.g. 6e-8,5e-4 is what sRGB shows at "
        "2000-5000 RU (empty: every sample weighs 1)"
    )
    loss_visible_weight: float = config_field(1.0, "weight of the samples in --loss-visible-y's band (1: off)")
    off_lattice: float = config_field(
        0.0, "fraction F in [0, 1) of each epoch's samples drawn afresh between the volume's samples: uniform points "
        "of u*/v* cells whose four corners are training samples, with the corners' bilinear value (in the "
        "range-transformed y) as target (trainer/offlattice.py); the epoch keeps its size, a random 1 − F of the "
        "lattice samples filling the rest (0: the lattice samples only)"
    )
    zero_unseen_features: bool = config_field(
        True, "give the encoding's features that vanish at every training sample (the sines of the top frequencies, "
        "at the lattice's Nyquist rate) zero first-layer weights, kept at zero: the loss never sees them, so random "
        "initial weights there only draw stripes and rings between the samples (trainer/model.py "
        "silence_unseen_features; docs/physics.md \"Network\"). With --off-lattice every feature is seen and none is "
        "silenced. --no-zero-unseen-features: train them as before 2026-11-28")
    epochs: int = config_field(6, "passes over the training samples")
    batch_size: int = config_field(32768, "samples per optimisation step (feature grids trained markedly better "
                                          "at 4096-8192 on a GPU: docs/experiments/2026-11-23-smaller-batches-h100.md)")
    learning_rate: float = config_field(3e-3, "Adam's initial learning rate")
    final_learning_rate_ratio: float = config_field(0.02, "cosine schedule ends at learning_rate × this")
    adam_epsilon: float = config_field(
        1e-8, "Adam's ε of the MLP (torch's default 1e-8). The LogCosh loss of range-transformed targets is ~1e-6, "
        "so many weights' sqrt(v) sits below 1e-8 and ε, not sqrt(v), sets their step: it keeps the encoding's "
        "near-Nyquist weights, which the samples hardly constrain, from growing "
        "(docs/experiments/2026-11-25-scratches-adam-epsilon.md)"
    )
    seed: int = config_field(0, "seed of initialisation, shuffling and the random split")
    device: str = config_field("auto", "torch device: auto (CUDA when present), cpu, cuda")
    cuda_graph: Literal["auto", "on", "off"] = config_field(
        "auto", "replay each training step as one CUDA graph (trainer/cudagraph.py): auto (on a CUDA device), on, "
        "off; the same step, launched at a fraction of the cost, which small batches are bound by"
    )
    max_train_samples: int = config_field(0, "use at most this many training samples (0: all)")
    epoch_flip_size: int = config_field(0, "if > 0, after each epoch score the BRDF slice (0°, 0°) 2000 RU at this "
                                        "size (pixels, e.g. 128) with mean FLIP into history.json (needs the "
                                        "height field; 0: off)")

    def __post_init__(self) -> None:
        if self.epochs < 1 or self.batch_size < 1:
            raise GratNetError(f"--epochs and --batch-size must be ≥ 1, got {self.epochs}, {self.batch_size}")
        if not self.learning_rate > 0:
            raise GratNetError(f"--learning-rate must be positive, got {self.learning_rate}")
        for flag, epsilon in (("--adam-epsilon", self.adam_epsilon), ("--grid-adam-epsilon", self.grid.adam_epsilon)):
            if not (math.isfinite(epsilon) and epsilon > 0):
                raise GratNetError(f"{flag} must be a positive number, got {epsilon}")
        if not 0 <= self.epoch_flip_size <= 1024:
            raise GratNetError(f"--epoch-flip-size must be from 0 (off) to 1024 pixels, got {self.epoch_flip_size}")
        if self.architecture not in ("mlp", "grid"):
            raise GratNetError(f"--architecture must be mlp or grid, got {self.architecture!r}")
        if self.architecture == "grid":
            self.grid.check()
        if not (math.isfinite(self.loss_visible_weight) and self.loss_visible_weight > 0):
            raise GratNetError(f"--loss-visible-weight must be a positive number, got {self.loss_visible_weight}")
        self.visible_band()  # checks the band
        if not (math.isfinite(self.off_lattice) and 0 <= self.off_lattice < 1):
            raise GratNetError(f"--off-lattice must be a fraction in [0, 1), got {self.off_lattice}")
        if self.cuda_graph not in ("auto", "on", "off"):
            raise GratNetError(f"--cuda-graph must be auto, on or off, got {self.cuda_graph!r}")
        if self.cuda_graph == "on" and self.device == "cpu":
            raise GratNetError("--cuda-graph on needs a CUDA device; --device cpu was asked for")
        if self.split not in ("slices", "random", "all"):
            raise GratNetError(f"--split must be slices, random or all, got {self.split!r}")
        self.check_before_work()

    def check_before_work(self) -> None:
        """The options that used to be checked only when training began (the network, the range transform, the
        split, the device): refused here, when the config is made, so that nothing is loaded or computed first."""
        from trainer.model import check_network  # torch: when a config is made, never to list the flags

        recipe = RECIPES.get(self.preset)
        if recipe is not None and not self.hidden:  # a recipe always sets the widths: TrainConfig(preset=...) alone
            raise GratNetError(f"--preset {self.preset} sets several options: make its config with "
                               "trainer.train_config.preset_config (gratnet train does)")
        if recipe is not None and self.architecture != recipe["architecture"]:
            raise GratNetError(f"--preset {self.preset} is a feature-grid recipe (--architecture "
                               f"{recipe['architecture']}); leave out --architecture {self.architecture}, or take a "
                               "size preset (paper, funnel-176, medium, small, tiny)")
        check_network(self.preset, self.hidden, self.activation, self.output_activation)
        try:
            self.range_spec()  # RangeSpec checks its kind, B and n
        except GratNetError as error:
            raise GratNetError(f"{error} (--range-kind {self.range_kind}, --range-bits {self.range_bits:g}, "
                               f"--range-power {self.range_power:g})") from None
        if self.frequencies < 1 or self.t_frequencies < 0:
            raise GratNetError(f"--frequencies must be ≥ 1 and --t-frequencies ≥ 0, got {self.frequencies}, "
                               f"{self.t_frequencies}")
        if self.split == "slices":
            self.held_out_slices()
        if self.split == "random" and not 0 < self.test_fraction < 1:
            raise GratNetError(f"--test-fraction must lie in (0, 1), got {self.test_fraction}")
        if self.max_train_samples < 0:
            raise GratNetError(f"--max-train-samples must be ≥ 0 (0: all), got {self.max_train_samples}")
        if not (math.isfinite(self.final_learning_rate_ratio) and self.final_learning_rate_ratio >= 0):
            raise GratNetError(f"--final-learning-rate-ratio must be a number ≥ 0, "
                               f"got {self.final_learning_rate_ratio}")
        if self.seed < 0:
            raise GratNetError(f"--seed must be ≥ 0, got {self.seed}")
        if not re.fullmatch(r"auto|cpu|cuda(:[0-9]+)?", self.device):
            raise GratNetError(f"--device must be auto, cpu, cuda or cuda:N, got {self.device!r}")

    def held_out_slices(self, slices: int | None = None) -> list[int]:
        """The slice indices of ``test_slices`` (for ``split`` slices), sorted; with ``slices``, the volume's slice
        count, each is checked to be one of its slices."""
        try:
            held_out = sorted({int(part) for part in self.test_slices.split(",") if part.strip()})
        except ValueError:
            raise GratNetError(f"--test-slices must be comma-separated integers, got {self.test_slices!r}") from None
        if not held_out or min(held_out) < 0:
            raise GratNetError(f"--test-slices must name slices, indices from 0, got {self.test_slices!r}")
        if slices is not None and max(held_out) >= slices:
            raise GratNetError(f"--test-slices {self.test_slices} out of range for a {slices}-slice volume")
        return held_out

    def encoding_for(self, volume: Volume) -> EncodingSpec:
        """Encoding scales for this volume's grid (top frequency at its Nyquist rate)."""
        return EncodingSpec.for_grid(volume.resolution, volume.slices, self.frequencies, self.t_frequencies,
                                     self.diagonal_frequencies)

    def grid_shapes(self) -> list[tuple[int, int, int, int]]:
        """(T, R, R, C) of every grid level, coarse to fine ([] for the mlp architecture)."""
        return self.grid.shapes() if self.architecture == "grid" else []

    def visible_band(self) -> tuple[float, float] | None:
        """The display-weighted loss's band as range-transformed targets (y_low, y_high) of CIE Y, or None when
        every sample weighs the same. The transform is monotone, so a target is in the band iff its Y is."""
        if not self.loss_visible_y.strip():
            return None
        try:
            low, high = (float(part) for part in self.loss_visible_y.split(","))
        except ValueError:
            raise GratNetError(
                f"--loss-visible-y must be 'LOW,HIGH' (two numbers), got {self.loss_visible_y!r}"
            ) from None
        if not (0 < low < high and math.isfinite(high)):
            raise GratNetError(f"--loss-visible-y needs 0 < LOW < HIGH, got {self.loss_visible_y!r}")
        y_low, y_high = (float(range_forward(np.full((1, 3), value), self.range_spec())[0, 1]) for value in (low, high))
        # Beyond the transform's floor (2^-B) or ceiling (the white's Y) the band's edges collapse onto the
        # clipped ends, where they would select every sample clipped there.
        if not (0 < y_low < y_high and (self.range_kind == "log1p" or y_high < 1)):
            raise GratNetError(f"--loss-visible-y {self.loss_visible_y!r} must lie inside what the range "
                               f"transform resolves: from 2^-{self.range_bits:g} to 1 (a perfect mirror's Y)")
        return y_low, y_high

    def range_spec(self) -> RangeSpec:
        """The range transform of the targets."""
        return RangeSpec(self.range_kind, self.range_bits, self.range_power)


def recipe_values(given: Mapping[str, Any]) -> dict[str, Any]:
    """:class:`TrainConfig` keywords (flat names) from the options given explicitly: under a recipe preset
    (:data:`RECIPES`) its values for the options not in ``given``; otherwise ``given`` as it is."""
    preset = given.get("preset", TrainConfig.__dataclass_fields__["preset"].default)
    return {**RECIPES.get(preset, {}), **given}


def preset_config(**given: Any) -> TrainConfig:
    """The :class:`TrainConfig` of the options ``given`` (flat names), a recipe preset's values filled in
    (:func:`recipe_values`): ``preset_config(preset="fast", frequencies=12)``."""
    return TrainConfig(**recipe_values(given))


def mark_recipe_flags(actions: Mapping[str, argparse.Action]) -> None:
    """The flags of :data:`RECIPE_FIELDS` (``add_arguments``' actions for TrainConfig) default to ``None``, "not
    given", so that :func:`config_from_arguments` tells an explicit value from a recipe's; their help gives each
    recipe's value beside the default."""
    for name in RECIPE_FIELDS:
        action = actions[name]
        action.default = None
        values = "; ".join(f"--preset {preset}: {recipe[name]}" for preset, recipe in RECIPES.items() if name in recipe)
        action.help = f"{(action.help or '').removesuffix(')')}; {values})"


def config_from_arguments(arguments: argparse.Namespace) -> TrainConfig:
    """The run's config from ``gratnet train``'s flags (:func:`mark_recipe_flags`): a recipe preset's values for
    the recipe's options left out, every option given as given."""
    given = {name: getattr(arguments, name) for name in flat_fields(TrainConfig) if hasattr(arguments, name)}
    return preset_config(**{name: value for name, value in given.items()
                            if not (name in RECIPE_FIELDS and value is None)})
