"""Ground-truth volumes: every scheme against a brute-force integral, metadata, and the CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gratnet.cli import main
from gratnet.volume import read_volume
from trainer.fourier import OpticsConfig, prepare_surface
from trainer.generators import generate
from trainer.groundtruth import VolumeConfig, compute_volume, volume_key_vectors
from trainer.reference import brute_force_xyz
from trainer.spectral import spectral_weights

TINY_OPTICS = OpticsConfig(sigma_s_um=1.5, wavelength_step_nm=100.0)
TINY_FLAGS = ["--res", "21", "--slices", "3", "--sigma-s", "1.5", "--wavelength-step-nm", "100", "--quiet"]


@pytest.mark.parametrize("scheme", ["regular", "simple", "simple-max"])
def test_volume_matches_brute_force_integral(scheme):
    field = generate("cd", size_um=8.0)
    config = VolumeConfig(resolution=15, slices=3, sampling=scheme)
    surface = prepare_surface(field, TINY_OPTICS)
    volume = compute_volume(field, config, TINY_OPTICS, progress=False, surface=surface)
    u, v, w_slices = volume_key_vectors(config)
    spectrum = spectral_weights(380.0, 780.0, 100.0)
    u_grid, v_grid = np.meshgrid(u, v)
    for index, w in enumerate(w_slices):
        w_grid = np.broadcast_to(w, u_grid.shape)
        reference = brute_force_xyz(surface, u_grid, v_grid, w_grid, spectrum).reshape(15, 15, 3)
        reference[u_grid**2 + v_grid**2 > 4] = 0
        error = np.linalg.norm(volume.xyz[index] - reference) / np.linalg.norm(reference)
        assert error <= 0.01, (scheme, index, error)


def test_volume_zeroes_impossible_samples_and_records_parameters():
    volume = compute_volume(generate("blazed", size_um=5.0), VolumeConfig(resolution=11, slices=2),
                            TINY_OPTICS, progress=False)
    axis = np.linspace(-2, 2, 11)
    u_grid, v_grid = np.meshgrid(axis, axis)
    assert np.all(volume.xyz[:, u_grid**2 + v_grid**2 > 4 + 1e-9] == 0)
    assert np.all(volume.xyz[:, u_grid**2 + v_grid**2 <= 4 + 1e-9, 1] > 0)
    metadata = volume.metadata
    assert metadata["scheme"] == "regular" and metadata["slice_w"] == [0.0, -2.0]
    assert metadata["sigma_s_um"] == 1.5 and len(metadata["wavelengths_nm"]) == 5
    assert metadata["source"].startswith("generator:blazed(")
    # The relief's slopes for Smith's shadowing (gratnet.shadowing), of the field as loaded.
    assert metadata["slope_covariance"] == list(generate("blazed", size_um=5.0).slope_covariance())
    assert metadata["slope_covariance"][0] > 0.1 and metadata["slope_covariance"][2] == 0.0


def test_groundtruth_cli_writes_volume_config_and_preview(tmp_path):
    out = tmp_path / "blazed.exr"
    code = main(["groundtruth", "blazed", "--out", str(out), "--preview", str(tmp_path / "p.png"),
                 "--sampling", "simple-max", *TINY_FLAGS])
    assert code == 0
    volume = read_volume(out)
    assert volume.xyz.shape == (3, 21, 21, 3) and volume.metadata["scheme"] == "simple-max"
    config = json.loads((tmp_path / "blazed.config.json").read_text())
    assert config["volume"]["resolution"] == 21 and config["optics"]["sigma_s_um"] == 1.5
    assert (tmp_path / "p.png").stat().st_size > 1000


@pytest.mark.parametrize("arguments, message", [
    (["no-such-generator-or-file"], "no-such-generator-or-file"),
    (["blazed", "--res", "1"], "--res"),
    (["blazed", "--sigma-s", "-1"], "--sigma-s"),
])
def test_groundtruth_cli_bad_input_is_one_line_and_writes_nothing(tmp_path, capsys, arguments, message):
    out = tmp_path / "v.exr"
    assert main(["groundtruth", *arguments, "--out", str(out), "--quiet"]) == 2
    error = capsys.readouterr().err.strip()
    assert message in error and len(error.splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


def test_interrupted_groundtruth_leaves_no_file(tmp_path, monkeypatch):
    import trainer.groundtruth_cli as cli_module
    from gratnet import volume as volume_module

    def interrupted_write(path, volume):
        # Start writing through the real atomic path, then stop as Ctrl-C would.
        with volume_module.atomic_path(path) as temporary:
            temporary.write_bytes(b"partial")
            raise KeyboardInterrupt

    monkeypatch.setattr(cli_module, "write_volume", interrupted_write)
    out = tmp_path / "v.exr"
    assert main(["groundtruth", "blazed", "--out", str(out), *TINY_FLAGS]) == 130
    assert list(tmp_path.iterdir()) == []


def test_interrupted_groundtruth_resumes_to_the_uninterrupted_volume(tmp_path, monkeypatch, capsys):
    """A run stopped after two of five wavelengths leaves its checkpoint; --resume ends bit-identical to a run
    that was never stopped (Chebyshev-interpolated slices included), and removes the checkpoint."""
    from trainer.fourier import FTerm

    flags = ["cd", "--sampling", "simple-max", *TINY_FLAGS, "--checkpoint-minutes", "1e-9"]
    whole = tmp_path / "whole.exr"
    assert main(["groundtruth", *flags, "--out", str(whole)]) == 0
    assert not (tmp_path / "whole.exr.partial.npz").exists()

    real_kernel, calls = FTerm._kernel, []

    def stopping_kernel(self, *arguments):
        calls.append(1)
        if len(calls) == 5:  # the third wavelength's first kernel: Ctrl-C
            raise KeyboardInterrupt
        return real_kernel(self, *arguments)

    out = tmp_path / "v.exr"
    monkeypatch.setattr(FTerm, "_kernel", stopping_kernel)
    assert main(["groundtruth", *flags, "--out", str(out)]) == 130
    assert "holds 2 wavelengths" in capsys.readouterr().err
    assert sorted(path.name for path in tmp_path.iterdir()) == ["v.exr.partial.npz", "whole.config.json", "whole.exr"]
    monkeypatch.setattr(FTerm, "_kernel", real_kernel)

    # Another computation (another σs) must not continue this sum.
    assert main(["groundtruth", *flags, "--sigma-s", "2", "--out", str(out), "--resume"]) == 2
    assert "written for another" in capsys.readouterr().err
    assert main(["groundtruth", *flags, "--out", str(out), "--resume"]) == 0
    assert not (tmp_path / "v.exr.partial.npz").exists()
    np.testing.assert_array_equal(read_volume(out).xyz, read_volume(whole).xyz)


def test_groundtruth_resume_without_checkpoint_is_refused_before_work(tmp_path, capsys):
    assert main(["groundtruth", "blazed", "--out", str(tmp_path / "v.exr"), "--resume", *TINY_FLAGS]) == 2
    error = capsys.readouterr().err.strip()
    assert "there is no" in error and "partial.npz" in error and len(error.splitlines()) == 1
    assert main(["groundtruth", "blazed", "--out", str(tmp_path / "v.exr"), "--checkpoint-minutes", "0",
                 *TINY_FLAGS]) == 2
    assert list(tmp_path.iterdir()) == []


def test_brdfslice_cli_writes_png(tmp_path):
    out = tmp_path / "slice.png"
    assert main(["brdfslice", "blazed", "--light", "30,0", "--size", "32", "--sigma-s", "1.5",
                 "--wavelength-step-nm", "100", "--out", str(out), "--quiet"]) == 0
    from PIL import Image

    image = np.asarray(Image.open(out))
    assert image.shape == (32, 32, 3) and image.max() > 0 and image[0, 0].sum() == 0


def test_real_afm_scan_through_groundtruth(tmp_path):
    from tests.helpers import SHARED_DATA

    scan = SHARED_DATA / "elaphe_guttata_afm_100x100.png"
    if not scan.exists():
        pytest.skip("shared AFM example not present")
    out = tmp_path / "afm.exr"
    # ~0.1 µm pixels, 0.375 µm full scale (approximate, per shared/data/README.md); mirrored repeat.
    assert main(["groundtruth", str(scan), "--dx-um", "0.1", "--height-scale-um", "0.375", "--repeat", "mirror",
                 "--out", str(out), *TINY_FLAGS]) == 0
    volume = read_volume(out)
    assert "elaphe_guttata" in volume.metadata["source"] and volume.metadata["repeat"] == "mirror"
    assert volume.metadata["patch_size_um"] == pytest.approx([10.0, 10.0])
    assert np.isfinite(volume.xyz).all() and volume.xyz[..., 1].max() > 0
