"""Shared fixtures: small spectral sets and small windows keep the physics tests fast. Shared helpers that are
not fixtures (paths, random models, reference geometry): tests/helpers.py."""

from __future__ import annotations

import ctypes
import shutil
import signal
import subprocess
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from trainer.spectral import SpectralWeights, spectral_weights


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
        help="rewrite the golden reference images (tests/runtime/golden/*.png) from the current renderer",
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


# --------------------------------------------------------------------------------------------------
# A virtual X server for the viewer's window tests (runtime/test_viewer.py, runtime/test_viewer_window.py)


def _free_display_numbers() -> Iterator[int]:
    for number in range(90, 400):
        if not (Path(f"/tmp/.X{number}-lock").exists() or Path(f"/tmp/.X11-unix/X{number}").exists()):
            yield number


def _connect(libx11: ctypes.CDLL, display: str, process: subprocess.Popen, timeout: float) -> int | None:
    """An X connection to ``display`` once the server accepts one (None if it exited or timed out)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and process.poll() is None:
        connection = libx11.XOpenDisplay(display.encode())
        if connection:
            return connection
        time.sleep(0.05)
    return None


@pytest.fixture(scope="module")
def xvfb(tmp_path_factory) -> Iterator[str]:
    """``:N`` of a virtual X server started for this module on a free display number, and always stopped.

    Xvfb runs with ``-terminate`` (it exits when its last client disconnects) and this fixture holds one
    connection open: should the test process die without running this teardown (Xlib exits the process
    on some X errors), its connection closes and Xvfb still goes away.
    """
    executable = shutil.which("Xvfb")
    if executable is None:
        pytest.skip("Xvfb is not installed (apt-get install xvfb; scripts/setup.sh installs it)")
    try:
        libx11 = ctypes.CDLL("libX11.so.6")
    except OSError as error:
        pytest.skip(f"libX11 is not installed: {error}")
    libx11.XOpenDisplay.restype = ctypes.c_void_p
    libx11.XOpenDisplay.argtypes = [ctypes.c_char_p]
    libx11.XCloseDisplay.argtypes = [ctypes.c_void_p]
    log = tmp_path_factory.mktemp("xvfb") / "xvfb.log"
    process = connection = None
    for attempt, number in enumerate(_free_display_numbers()):
        if attempt == 5:
            break
        with open(log, "wb") as output:
            process = subprocess.Popen(
                [executable, f":{number}", "-screen", "0", "1024x768x24", "-nolisten", "tcp", "-terminate"],
                stdout=output, stderr=subprocess.STDOUT)
        connection = _connect(libx11, f":{number}", process, timeout=10.0)
        if connection:
            break
        process.kill()  # the number was taken meanwhile, or Xvfb failed: try the next one
        process.wait()
        process = None
    if process is None:
        pytest.fail(f"Xvfb did not start: {log.read_text(errors='replace')[-500:]}")
    try:
        yield f":{number}"
    finally:
        libx11.XCloseDisplay(connection)
        process.terminate()
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


@pytest.fixture
def display(xvfb, monkeypatch) -> str:
    monkeypatch.setenv("DISPLAY", xvfb)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    return xvfb
