"""The viewer pads its deferred renders to power-of-two sizes (viewer.scheduling.padded_size, issue 35): the
picture in the padded target's corner has the pixel centres, hence the pixels, of the unpadded render."""

from __future__ import annotations

import numpy as np
import pytest

from viewer.scheduling import BandCamera, padded_size
from viewer.state import ViewerState

SPHERE = ViewerState(mesh="sphere", camera_distance=0.2, camera_elevation=30.0, light_theta=50.0, light_phi=-60.0,
                     exposure=2000.0)


def test_padded_sizes_are_powers_of_two_and_so_are_deferred_bands():
    from viewer.scheduling import ResolutionPolicy

    assert padded_size((512, 512)) == (512, 512)
    assert padded_size((48, 3)) == (64, 4)
    assert padded_size((1, 1)) == (1, 1) and padded_size((513, 2)) == (1024, 2)
    policy = ResolutionPolicy(refine_budget_s=0.1)
    assert policy.band_rows(np.full(100, 0.01), multiple=1, power_of_two=True) == 8  # 10 fit
    assert policy.band_rows(np.full(100, 0.5), multiple=1, power_of_two=True) == 1
    assert policy.band_rows(np.full(5, 0.001), multiple=1, power_of_two=True) == 5  # the last rows, all


@pytest.mark.parametrize("rows", [None, (7, 10)], ids=["whole picture", "band of 3 rows"])
def test_a_padded_render_holds_the_unpadded_one_in_its_corner(ctx, rows):
    from gratnet.modelfile import load_model
    from viewer.catalog import build_mesh, resolve_material
    from viewer.scene import SceneRenderer

    width, height = 48, 40
    camera = SPHERE.camera()
    band = BandCamera(camera.distance, camera.azimuth_deg, camera.elevation_deg, camera.target, camera.fov_deg,
                      camera.near, camera.far, full_aspect=width / height, height=height,
                      row0=0 if rows is None else rows[0], row1=height if rows is None else rows[1])
    size = (width, band.row1 - band.row0)
    target = padded_size(size)
    padded_camera = BandCamera(**{**band.__dict__, "width_fraction": size[0] / target[0],
                                  "height_fraction": size[1] / target[1]})
    with SceneRenderer(ctx, load_model(resolve_material("blazed")), render_path="deferred",
                       measure_render_path=False) as scene:
        buffers = scene.upload(build_mesh("sphere"))
        try:
            plain = scene.render_rgba(buffers, band, SPHERE.light(), size, SPHERE.exposure, SPHERE.effective_ior)
            padded = scene.render_rgba(buffers, padded_camera, SPHERE.light(), target, SPHERE.exposure,
                                       SPHERE.effective_ior)
        finally:
            buffers.release()
    assert target != size and np.count_nonzero(plain[..., 3]) > 20
    corner = padded[:size[1], :size[0]]
    np.testing.assert_array_equal(corner[..., 3], plain[..., 3])  # the same coverage
    scale = float(np.abs(plain[..., :3]).max())
    close = np.isclose(corner[..., :3], plain[..., :3], rtol=1e-3, atol=1e-5 * scale).all(axis=2)
    assert np.mean(~close) <= 0.01, f"{np.count_nonzero(~close)} pixels differ"
