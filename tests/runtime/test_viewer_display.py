"""viewer.srgb: the window's colour-science-free display conversion is gratnet.display's, byte for byte."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

from gratnet.display import xyz_to_display_srgb8, xyz_to_linear_srgb
from tests.helpers import REPO
from viewer.srgb import XYZ_TO_LINEAR_SRGB, display_srgb8, linear_srgb


def test_the_numpy_conversion_equals_gratnet_display_bit_for_bit():
    import colour

    np.testing.assert_array_equal(XYZ_TO_LINEAR_SRGB, colour.RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB)
    rng = np.random.default_rng(35)
    xyz = np.concatenate([
        rng.random((64, 64, 3)),  # in range
        rng.normal(0.0, 3.0, (64, 64, 3)),  # out of gamut, negative, over white
        10.0 ** rng.uniform(-8.0, 1.0, (64, 64, 3)),  # dark tails and highlights
        np.zeros((1, 64, 3)),
    ]).astype(np.float32)
    # The same operations, but numpy's matmul kernels differ between CPUs (SIMD width, FMA): the linear values
    # agree to float64 rounding, and the display bytes below exactly.
    np.testing.assert_allclose(linear_srgb(xyz), xyz_to_linear_srgb(xyz), rtol=1e-12, atol=1e-12)  # inputs up to ~10
    for exposure in (1.0, 39.3, 1e-3):
        np.testing.assert_array_equal(display_srgb8(xyz, exposure), xyz_to_display_srgb8(xyz, exposure))
    # Values at the transfer function's knee and at the rounding steps.
    linear = np.concatenate([np.linspace(0.0, 0.01, 4001), np.linspace(0.0, 1.0, 4001)])
    xyz = np.linalg.solve(XYZ_TO_LINEAR_SRGB, np.stack([linear] * 3, axis=0)).T
    np.testing.assert_array_equal(display_srgb8(xyz), xyz_to_display_srgb8(xyz))


def test_the_window_side_never_imports_colour_science():
    code = ("import sys, viewer.app, viewer.srgb, viewer.default_view, viewer.scene_supply; "
            "print('colour' in sys.modules)")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            cwd=REPO, check=True)
    assert result.stdout.strip() == "False"
