"""The paper's datasets as named presets: a height field (generator + parameters, or a scan) and its optics.

Each preset reproduces one dataset of the paper (its Fig. 2 caption and §4 "Datasets"): patch size (µm),
coherence window 4σs (µm), heights (µm). A preset name is accepted wherever a height field is
(``gratnet groundtruth paper-cd --out cd.exr``; ``gratnet heightfield convert paper-cd --out cd.npz``):
the ground-truth commands then take the preset's σs unless ``--sigma-s`` is given. ``gratnet heightfield
list`` lists them. Every preset uses the paper's volume grid, 1001² × 11 (``VolumeConfig()``).

Where the paper leaves a parameter open (the random field's correlation length, the scratches' count and
tip, the pits' lattice) the value here is this project's choice, said so in the preset's ``notes``.

A generated preset records its generator source (``generator:NAME(...)``), so models trained on it rebuild
the exact field for evaluation; the scan-based one records ``dataset:NAME``, resolved by
:func:`trainer.loaders.load_heightfield`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from types import MappingProxyType
from typing import Any

from gratnet.errors import GratNetError
from trainer.fourier import OpticsConfig
from trainer.groundtruth import VolumeConfig
from trainer.heightfield import HeightField
from trainer.heightfile import LoadOptions, read_heightfield_file

_DATA = Path(__file__).resolve().parents[1] / "assets" / "data"


@dataclasses.dataclass(frozen=True)
class ScanSource:
    """A measured height field shipped in assets/data (credit and scale: assets/data/README.md): the image, its
    pixel pitch and the height of white (µm; both from the scan's source, approximate)."""

    path: Path
    dx_um: float
    white_um: float


#: The real corn-snake (Elaphe guttata) AFM crop.
SNAKE_SCAN = ScanSource(_DATA / "elaphe_guttata_afm_100x100.png", dx_um=0.1, white_um=0.375)
#: The real sunbeam-snake (Xenopeltis unicolor) AFM crop, from the same source; its maximum height there is
#: 4.4345e-1 µm (the source's matlab/ComputeFFTImages.m).
SUNBEAM_SCAN = ScanSource(_DATA / "xenopeltis_unicolor_afm_100x100.png", dx_um=0.1, white_um=0.4435)

SOURCE_PREFIX = "dataset:"


@dataclasses.dataclass(frozen=True)
class DatasetPreset:
    """One of the paper's datasets: where it comes from, its height field and its optics.

    ``generator`` names a built-in generator (trainer/generators.py) run with ``parameters``; ``None``
    means the measured ``scan`` (:data:`SNAKE_SCAN`, :data:`SUNBEAM_SCAN`). ``patch_um`` and
    ``max_height_um`` are the paper's nominal values (µm; ``None`` where the paper gives none; the snakes'
    65 µm are the paper's scans, of which only 10 µm crops are available here); ``four_sigma_s_um`` is its
    coherence window 4σs.
    """

    name: str
    title: str
    paper: str
    four_sigma_s_um: float
    patch_um: float
    max_height_um: float | None
    generator: str | None
    parameters: Mapping[str, float] = dataclasses.field(default_factory=lambda: MappingProxyType({}))
    notes: str = ""
    volume: VolumeConfig = VolumeConfig()
    scan: ScanSource | None = None
    #: The paper's table: this dataset's own column and its mean FLIP at (0°, 0°) 2000 RU (the target), if any.
    paper_column: str = ""
    paper_flip: float | None = None
    #: The group of like structures whose speed/error figure it shares (docs/results.md, analysis.pareto).
    family: str = ""

    @property
    def sigma_s_um(self) -> float:
        """σs (µm) of the Gaussian coherence window."""
        return self.four_sigma_s_um / 4.0

    def optics(self) -> OpticsConfig:
        """The ground truth's optics: the paper's σs, every other setting at its default."""
        return OpticsConfig(sigma_s_um=self.sigma_s_um)

    def field(self) -> HeightField:
        """Build the height field (heights and spacing in µm)."""
        if self.generator is not None:
            from trainer import generators

            return generators.generate(self.generator, **self.parameters)
        if self.scan is None:
            raise GratNetError(f"dataset {self.name} names neither a generator nor a scan")
        options = LoadOptions(dx_um=self.scan.dx_um, height_scale_um=self.scan.white_um)
        scan = read_heightfield_file(self.scan.path, options)
        return HeightField(scan.heights_um, scan.dx_um, SOURCE_PREFIX + self.name)


def _preset(**values: Any) -> DatasetPreset:
    parameters = values.pop("parameters", {})
    return DatasetPreset(parameters=MappingProxyType(dict(parameters)), **values)


PRESETS: dict[str, DatasetPreset] = {
    preset.name: preset
    for preset in (
        _preset(
            paper_column="blazed grating", paper_flip=0.0021,
            name="paper-blazed", title="blazed grating, 100 µm patch", paper="§4 Datasets; Fig. 2 (crop shown: 20 µm)",
            family="gratings",
            four_sigma_s_um=65.0, patch_um=100.0, max_height_um=0.25, generator="blazed",
            parameters={"period_um": 2.5, "max_height_um": 0.25, "size_um": 100.0},
            notes="sawtooth, period 2.5 µm, tooth height 250 nm",
        ),
        _preset(
            paper_column="CD", paper_flip=0.0178,
            name="paper-cd", title="synthetic compact disc, 65 µm patch", paper="§4 Datasets; Fig. 2",
            family="gratings",
            four_sigma_s_um=40.0, patch_um=65.0, max_height_um=None, generator="cd",
            parameters={"size_um": 65.0},
            notes="tracks every 1.6 µm, pits/lands of 3T…11T (T = 0.2777 µm), 110 nm deep; the patch is "
            "snapped to 41 whole tracks (65.6 µm); pit depth and width are this project's (CD standard) values",
        ),
        _preset(
            name="paper-gaussian", title="Gaussian random field, 65 µm patch", paper="§4 Datasets",
            family="random and scratched surfaces",
            four_sigma_s_um=65.0, patch_um=65.0, max_height_um=1.0, generator="gaussian",
            parameters={"size_um": 65.0, "max_height_um": 1.0},
            notes="heights rescaled to [0, 1 µm]; the correlation length (1.5 µm) is this project's choice",
        ),
        _preset(
            paper_column="corn snake (Elaphe)", paper_flip=0.0221,
            name="paper-snake", title="corn snake skin (AFM scan)", paper="§4 Datasets; Fig. 2 (crop 12.5 µm)",
            family="snake skins",
            four_sigma_s_um=65.0, patch_um=65.0, max_height_um=None, generator=None,
            notes="the real Elaphe guttata AFM crop in assets/data (100 × 100 px, dx ≈ 0.1 µm, white ≈ 0.375 µm, "
            "both approximate), repeated periodically under the window: the paper's full 65 µm scan is not "
            "available here", scan=SNAKE_SCAN,
        ),
        _preset(
            paper_column="sunbeam snake (Xenopeltis)", paper_flip=0.0318,
            name="paper-sunbeam", title="sunbeam snake skin (AFM scan)", paper="§4 Datasets (the Xenopeltis column)",
            family="snake skins",
            four_sigma_s_um=65.0, patch_um=65.0, max_height_um=None, generator=None,
            notes="the real Xenopeltis unicolor AFM crop in assets/data (100 × 100 px, dx ≈ 0.1 µm, white ≈ "
            "0.4435 µm, both approximate), repeated periodically under the window: the paper's full 65 µm scan is "
            "not available here", scan=SUNBEAM_SCAN,
        ),
        _preset(
            paper_column="scratches", paper_flip=0.0123,
            name="paper-scratches", title="ball-pen tip scratches, 80 µm patch", paper="§4 Datasets; Fig. 2",
            family="random and scratched surfaces",
            four_sigma_s_um=65.0, patch_um=80.0, max_height_um=0.873, generator="scratches",
            parameters={"size_um": 80.0, "count": 60, "tip_radius_um": 2.0, "depth_um": 0.5, "depth_jitter": 0.3,
                        "min_length_um": 10.0, "max_length_um": 60.0, "damping_sigma_um": 80.0 / 6.0,
                        "max_depth_um": 0.873},
            notes="synthetic (the paper's AFM scan is not available): 60 random scratches, Gaussian damping "
            "window σ = 13.3 µm (the patch edge at 3σ; the paper gives no σ), deepest cut rescaled to 873 nm",
        ),
        _preset(
            paper_column="corner cubes", paper_flip=0.0751,
            name="paper-corner-cubes", title="corner cubes, 72 µm patch", paper="§4 Datasets; Fig. 2",
            family="pits and corner cubes",
            four_sigma_s_um=40.0, patch_um=72.0, max_height_um=1.5, generator="corner_cube",
            parameters={"size_um": 72.0, "mirror_tile_um": 24.0, "max_height_um": 1.5},
            notes="a 24 µm corner-cube design mirrored to 3 × 3 tiles, 1.5 µm peak to valley",
        ),
        _preset(
            paper_column="pits", paper_flip=0.0878,
            name="paper-pits", title="spherical pits, 24 µm patch", paper="§4 Datasets; Fig. 2",
            family="pits and corner cubes",
            four_sigma_s_um=15.556, patch_um=24.0, max_height_um=None, generator="pits",
            parameters={"size_um": 24.0, "spacing_um": 2.4, "radius_um": 0.8},
            notes="semi-spherical pits with mild random size (±10 %) and placement (±5 %); the 2.4 µm lattice "
            "(10 × 10 pits) and 0.8 µm radius are this project's choice (the paper gives none)",
        ),
    )
}


def preset(name: str) -> DatasetPreset:
    """The preset ``name`` (also accepted as ``dataset:NAME``), or a clear error listing them."""
    key = name.removeprefix(SOURCE_PREFIX)
    if key not in PRESETS:
        raise GratNetError(f"unknown dataset {name!r}; the paper's datasets: {', '.join(PRESETS)}")
    return PRESETS[key]


def is_preset(name: str) -> bool:
    """Whether ``name`` (or ``dataset:NAME``) names a preset."""
    return str(name).removeprefix(SOURCE_PREFIX) in PRESETS


def listing() -> str:
    """Human-readable lines for ``gratnet heightfield list``."""
    lines = ["paper datasets (height field + optics; gratnet groundtruth NAME --out NAME.exr):"]
    for item in PRESETS.values():
        height = "—" if item.max_height_um is None else f"{item.max_height_um:g} µm"
        lines.append(f"{item.name}: {item.title} — 4σs {item.four_sigma_s_um:g} µm, max height {height} "
                     f"({item.paper})")
        lines.append(f"    {item.notes}")
    return "\n".join(lines)
