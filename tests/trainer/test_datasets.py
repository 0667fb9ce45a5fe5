"""The paper's datasets as presets: each field's size, heights and period, the optics, and the CLI."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gratnet.errors import GratNetError
from trainer import datasets
from trainer.loaders import load_heightfield

# The table (the paper's Fig. 2 caption and §4): patch (µm), 4σs (µm), largest height (µm, or None).
PAPER_TABLE = {
    "paper-blazed": (100.0, 65.0, 0.25),
    "paper-cd": (65.0, 40.0, None),
    "paper-gaussian": (65.0, 65.0, 1.0),
    "paper-snake": (None, 65.0, None),
    "paper-sunbeam": (None, 65.0, None),
    "paper-scratches": (80.0, 65.0, 0.873),
    "paper-corner-cubes": (72.0, 40.0, 1.5),
    "paper-pits": (24.0, 15.556, None),
}


@pytest.fixture(scope="module")
def fields():
    return {name: preset.field() for name, preset in datasets.PRESETS.items()}


def test_every_paper_dataset_has_a_preset_with_the_papers_window():
    assert set(datasets.PRESETS) == set(PAPER_TABLE)
    for name, (_, four_sigma, _) in PAPER_TABLE.items():
        preset = datasets.PRESETS[name]
        assert preset.optics().sigma_s_um == pytest.approx(four_sigma / 4)
        assert preset.paper and preset.notes  # documented
        assert (preset.volume.resolution, preset.volume.slices) == (1001, 11)  # the paper's grid


@pytest.mark.parametrize("name", list(PAPER_TABLE))
def test_patch_size_and_heights(fields, name):
    field = fields[name]
    patch, _, max_height = PAPER_TABLE[name]
    width, height = field.size_um
    assert width == pytest.approx(height)
    if patch is not None:
        # Periodic generators snap the patch to whole periods: at most half a period (CD: 1.6 µm tracks) off.
        assert abs(width - patch) <= 0.8 + field.dx_um
    if max_height is not None:
        span = float(field.heights_um.max() - field.heights_um.min())
        # A sampled sawtooth misses its top by one sample's rise (dx / period of the tooth).
        assert span == pytest.approx(max_height, rel=0.04)
    assert float(field.heights_um.min()) >= 0.0


def _peak_period_um(profile: np.ndarray, dx_um: float) -> float:
    """The period (µm) of the strongest non-zero spatial frequency of a 1-D profile."""
    spectrum = np.abs(np.fft.rfft(profile - profile.mean()))
    frequencies = np.fft.rfftfreq(profile.size, dx_um)
    return 1.0 / frequencies[1 + int(np.argmax(spectrum[1:]))]


def test_blazed_grating_period_from_its_spectrum(fields):
    field = fields["paper-blazed"]
    assert _peak_period_um(field.heights_um[0], field.dx_um) == pytest.approx(2.5, rel=0.01)


def test_cd_track_pitch_from_its_spectrum_and_pit_depth(fields):
    field = fields["paper-cd"]
    across_tracks = field.heights_um.mean(axis=1)  # rows run along y, across the tracks
    assert _peak_period_um(across_tracks, field.dx_um) == pytest.approx(1.6, rel=0.01)
    assert float(np.ptp(field.heights_um)) == pytest.approx(0.11, rel=0.01)
    # Pits and lands along a track are whole channel bits (3T…11T): no run shorter than 3T (with the blur).
    track = field.heights_um[round(0.8 / field.dx_um)] < field.heights_um.max() - 0.055
    edges = np.flatnonzero(np.diff(track.astype(int)))
    assert np.diff(edges).min() * field.dx_um >= 3 * 0.2777 - 2 * field.dx_um


def test_pits_lattice_from_its_spectrum(fields):
    field = fields["paper-pits"]
    assert _peak_period_um(field.heights_um.mean(axis=0), field.dx_um) == pytest.approx(2.4, rel=0.01)


def test_corner_cubes_are_a_mirrored_24_um_design(fields):
    field = fields["paper-corner-cubes"]
    tile = round(24.0 / field.dx_um)
    heights = field.heights_um
    assert heights.shape == (3 * tile, 3 * tile)
    np.testing.assert_array_equal(heights[:tile, tile:2 * tile], heights[:tile, :tile][:, ::-1])
    np.testing.assert_array_equal(heights[tile:2 * tile, :tile], heights[:tile, :tile][::-1])
    np.testing.assert_array_equal(heights[2 * tile:, 2 * tile:], heights[:tile, :tile])


def test_scratches_are_damped_towards_the_edges(fields):
    field = fields["paper-scratches"]
    depth = field.heights_um.max() - field.heights_um  # cut depth below the flat surface (µm)
    samples = depth.shape[0]
    centre = depth[samples // 3: 2 * samples // 3, samples // 3: 2 * samples // 3]
    border = np.concatenate([depth[: samples // 10].ravel(), depth[-samples // 10:].ravel()])
    assert float(depth.max()) == pytest.approx(0.873)
    # The damping window exp(−r²/2σ²), σ = 80/6 µm, is below e^{−2.9} ≈ 0.06 in the outer tenth of the patch.
    assert border.max() < 0.1 * centre.max()


def test_the_snake_preset_is_the_real_scan_and_rebuilds_from_its_source(fields):
    field = fields["paper-snake"]
    assert field.shape == (100, 100) and field.dx_um == pytest.approx(0.1)
    assert 0 < float(field.heights_um.max()) <= 0.375
    assert field.source == "dataset:paper-snake"
    np.testing.assert_array_equal(load_heightfield(field.source).heights_um, field.heights_um)


def test_generated_presets_rebuild_exactly_from_their_recorded_source(fields):
    for name in ("paper-scratches", "paper-corner-cubes"):
        field = fields[name]
        assert field.source.startswith("generator:")
        np.testing.assert_array_equal(load_heightfield(field.source).heights_um, field.heights_um)


def test_preset_names_load_like_generators_and_unknown_ones_are_refused(fields):
    np.testing.assert_array_equal(load_heightfield("paper-pits").heights_um, fields["paper-pits"].heights_um)
    with pytest.raises(GratNetError, match="paper-cd"):
        load_heightfield("dataset:paper-nothing")
    with pytest.raises(GratNetError, match="paper dataset"):
        load_heightfield("no-such-surface")


def test_heightfield_list_shows_the_presets(capsys):
    from gratnet.cli import main

    assert main(["heightfield", "list"]) == 0
    output = capsys.readouterr().out
    for name in datasets.PRESETS:
        assert f"{name}:" in output


def test_groundtruth_of_the_smallest_preset_uses_its_window(tmp_path):
    """The one preset smoke run: paper-pits (24 µm) on a tiny grid and a coarse spectrum."""
    from gratnet.cli import main
    from gratnet.volume import read_volume

    out = tmp_path / "pits.exr"
    arguments = ["groundtruth", "paper-pits", "--res", "9", "--slices", "2", "--wavelength-step-nm", "100",
                 "--quiet", "--out"]
    assert main([*arguments, str(out)]) == 0
    metadata = read_volume(out).metadata
    assert metadata["sigma_s_um"] == pytest.approx(15.556 / 4)
    assert metadata["patch_size_um"] == pytest.approx([24.0, 24.0], rel=0.01)  # after any resampling
    assert metadata["source"].startswith("generator:pits(")
    # An explicit --sigma-s wins over the preset's.
    override = tmp_path / "pits5.exr"
    assert main([*arguments, str(override), "--sigma-s", "5"]) == 0
    assert read_volume(override).metadata["sigma_s_um"] == 5.0
    assert math.isclose(read_volume(tmp_path / "pits.exr").metadata["window_extent_um"], 6 * 15.556 / 4)


def test_evaluation_rebuilds_a_scan_preset_from_a_volumes_source(fields):
    """A volume of paper-snake records dataset:paper-snake; evaluation finds its height field from that."""
    from gratnet.cli import build_parser
    from trainer.train_cli import ground_truth_inputs

    arguments = build_parser(only="evaluate").parse_args(["evaluate", "model.npz", "--out", "report"])
    field, optics = ground_truth_inputs(arguments, {"source": "dataset:paper-snake", "sigma_s_um": 16.25})
    np.testing.assert_array_equal(field.heights_um, fields["paper-snake"].heights_um)
    assert optics.sigma_s_um == 16.25


def test_reproduce_script_replays_every_shipped_paper_models_recorded_training(tmp_path):
    """scripts/reproduce_paper_models.sh (DRY_RUN) rebuilds each assets/paper-* and each of its quality points
    (assets/NAME/POINT/, e.g. fast/) from its train_command.json: ground truth of the material's height field with the
    w-slices of the volume it was trained on, the same training flags, the evaluation."""
    import json
    import shlex
    import subprocess

    from gratnet.modelfile import load_model
    from tests.helpers import REPO

    assets = REPO / "assets"
    materials = sorted(path.parent.name for path in assets.glob("paper-*/train_command.json"))
    assert len(materials) == 8
    # The script's order: each material, then its points (sorted); a point shares its material's volume.
    names = [entry for material in materials for entry in [material, *sorted(
        f"{material}/{path.parent.name}" for path in (assets / material).glob("*/train_command.json"))]]
    result = subprocess.run(["bash", str(REPO / "scripts" / "reproduce_paper_models.sh")], capture_output=True,
                            text=True, env={"DRY_RUN": "1", "OUT": str(tmp_path), "PATH": "/usr/bin:/bin"},
                            check=True)
    commands = [shlex.split(line[2:]) for line in result.stdout.splitlines() if line.startswith("+ ")]
    volumes: dict[str, str] = {}
    index = 0
    for name in names:
        dataset = name.split("/")[0]
        recorded = shlex.split(json.loads((assets / name / "train_command.json").read_text())["command"])
        # The w-slices of the volume the model was trained on, as its model file records them.
        slices = str(load_model(assets / name / "model.npz").metadata["volume"]["slices"])
        if dataset not in volumes:  # the ground truth runs once per volume
            groundtruth = commands[index]
            index += 1
            assert groundtruth[1:3] == ["groundtruth", dataset]
            assert groundtruth[groundtruth.index("--slices") + 1] == slices
            volumes[dataset] = groundtruth[groundtruth.index("--out") + 1]
        volume = volumes[dataset]
        assert volume.endswith(f"-s{slices}.exr")
        train, evaluate = commands[index:index + 2]
        index += 2
        record = json.loads((assets / name / "train_command.json").read_text())
        environment = [f"{key}={value}" for key, value in record.get("environment", {}).items()]
        if environment:  # a recorded environment (a CPU training's thread count) is replayed through env
            assert train[:1 + len(environment)] == ["env", *environment]
            train = train[1 + len(environment):]
        assert train[1:3] == ["train", volume]
        out = recorded.index("--out")
        assert [word for word in train[3:] if word not in ("--out", str(tmp_path / "runs" / name))] == \
            recorded[3:out] + recorded[out + 2:]
        assert evaluate[1] == "evaluate" and "--views" in evaluate
        assert evaluate[evaluate.index("--volume") + 1] == volume
        assert evaluate[evaluate.index("--heightfield") + 1] == dataset
    assert index == len(commands)
    bad = subprocess.run(["bash", str(REPO / "scripts" / "reproduce_paper_models.sh"), "no-such"], capture_output=True,
                         text=True, env={"DRY_RUN": "1", "PATH": "/usr/bin:/bin"})
    assert bad.returncode == 2 and "no assets/no-such/train_command.json" in bad.stderr
