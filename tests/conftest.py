"""Shared fixtures: small spectral sets and small windows keep the physics tests fast."""

from __future__ import annotations

from pathlib import Path

import pytest

from trainer.spectral import SpectralWeights, spectral_weights

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def coarse_spectrum() -> SpectralWeights:
    """Nine wavelengths, 380…780 nm every 50 nm, D65 × CIE 1931 2° weights."""
    return spectral_weights(380.0, 780.0, 50.0)



def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--regenerate-golden", action="store_true", default=False,
        help="rewrite the golden reference images (tests/golden/*.png) from the current renderer",
    )
