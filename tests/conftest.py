"""Shared fixtures: small spectral sets and small windows keep the physics tests fast."""

from __future__ import annotations

import signal
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from trainer.spectral import SpectralWeights, spectral_weights

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def coarse_spectrum() -> SpectralWeights:
    """Nine wavelengths, 380…780 nm every 50 nm, D65 × CIE 1931 2° weights."""
    return spectral_weights(380.0, 780.0, 50.0)



def pytest_configure(config: pytest.Config) -> None:
    """Let SIGINT through in xdist workers: they ignore it (the controller handles Ctrl-C), a child inherits an
    ignored signal across exec, and Python then installs no KeyboardInterrupt handler, so the Ctrl-C tests'
    commands (and the in-process ones) would never see their signal."""
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--regenerate-golden", action="store_true", default=False,
        help="rewrite the golden reference images (tests/golden/*.png) from the current renderer",
    )


@pytest.fixture(scope="module")
def ctx() -> Iterator[object]:
    """A headless GL context (EGL) for one test module; the module is skipped where none can be had."""
    from gratnet.errors import GratNetError
    from viewer.context import create_headless_context

    try:
        context = create_headless_context()
    except GratNetError as error:
        pytest.skip(f"no headless OpenGL 4.3 context: {error}")
    yield context
    context.release()


@pytest.fixture(scope="session")
def tiny_volume(tmp_path_factory: pytest.TempPathFactory) -> tuple[object, Path]:
    """A 21² × 5 blazed-grating volume (5 µm patch, σs = 1.5 µm, 100 nm steps) and its EXR: for training tests."""
    from gratnet.volume import write_volume
    from trainer.fourier import OpticsConfig
    from trainer.generators import generate
    from trainer.groundtruth import VolumeConfig, compute_volume

    optics = OpticsConfig(sigma_s_um=1.5, wavelength_step_nm=100.0)
    volume = compute_volume(generate("blazed", size_um=5.0), VolumeConfig(resolution=21, slices=5,
                            sampling="simple-max"), optics, progress=False)
    path = tmp_path_factory.mktemp("volume") / "blazed.exr"
    write_volume(path, volume)
    return volume, path


@pytest.fixture
def stop_in_epoch_two() -> Callable[[object], dict]:
    """A ``train(per_epoch=…)`` hook that interrupts the run after epoch 1's checkpoint and before epoch 2's, so
    that ``--resume`` starts from epoch 1 (its first call returns nothing to record; its second raises)."""
    calls: list[int] = []

    def hook(_model_file: object) -> dict:
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return {}

    return hook
