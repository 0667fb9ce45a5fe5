"""Anti-aliasing (issue 12): the sub-pixel offsets, the jittered forward path, ``gratnet render --spp``.

Analytic checks first (the Halton offsets against scipy's; the coverage of a mesh's edges equals the
fraction of the jittered sample points inside its projected outline, and converges to the pixel's area
fraction), then cross-checks (N samples = the mean of N one-sample renders with the jittered matrices,
built here independently; one sample = the render without anti-aliasing, bit for bit), then the CLI.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Iterator

import numpy as np
import pytest

from gratnet.cli import main
from gratnet.errors import GratNetError
from tests.helpers import ASSETS
from viewer.antialias import MAX_SAMPLES, check_samples, jitter_matrix, sample_offsets, sample_range_offsets
from viewer.camera import Camera, Light
from viewer.meshes import plane

BLAZED = ASSETS / "blazed" / "model.npz"
#: A tilted view of the 0.1 m plane: its projected outline is a trapezoid with slanted edges.
CAMERA = Camera(0.16, -70.0, 55.0)
LIGHT = Light.directional(30.0, 90.0)
SIZE = (40, 30)


# --------------------------------------------------------------------------------------------------
# Offsets


def test_offsets_are_scipys_halton_sequence_shifted_to_the_pixel_centre():
    from scipy.stats import qmc

    expected = np.mod(qmc.Halton(d=2, scramble=False).random(MAX_SAMPLES) + 0.5, 1.0) - 0.5
    offsets = sample_offsets(MAX_SAMPLES)
    np.testing.assert_allclose(offsets, expected, rtol=0, atol=1e-15)
    assert np.array_equal(offsets[0], [0.0, 0.0])  # one sample: the pixel centre
    assert offsets.min() >= -0.5 and offsets.max() < 0.5
    # Prefixes cover the pixel evenly: 16 samples put 2 in each eighth of x, 9 put 1 in each ninth of y.
    assert np.array_equal(np.histogram(offsets[:16, 0], bins=8, range=(-0.5, 0.5))[0], np.full(8, 2))
    assert np.array_equal(np.histogram(offsets[:9, 1], bins=9, range=(-0.5, 0.5))[0], np.full(9, 1))
    assert np.array_equal(sample_range_offsets(3, 5), offsets[5:8])


@pytest.mark.parametrize("value", [0, -1, 1.5, MAX_SAMPLES + 1, True, "4", None])
def test_bad_sample_counts_are_refused(value):
    with pytest.raises(GratNetError, match="samples per pixel"):
        check_samples(value)


def test_a_sample_range_past_the_sequence_or_a_negative_start_is_refused():
    with pytest.raises(GratNetError, match="run past"):
        sample_range_offsets(2, MAX_SAMPLES - 1)
    with pytest.raises(GratNetError, match="first sample"):
        sample_range_offsets(1, -1)


def test_jitter_matrix_moves_clip_space_by_whole_pixels_at_every_depth():
    width, height = 40, 30
    matrix = jitter_matrix((0.25, -0.5), width, height)
    for w in (0.5, 1.0, 7.0):
        clip = np.array([0.1 * w, -0.2 * w, 0.3 * w, w], dtype=np.float32) @ matrix  # pyrr: row vectors
        ndc_shift = clip[:2] / clip[3] - np.array([0.1, -0.2])
        np.testing.assert_allclose(ndc_shift * np.array([width, height]) / 2.0, [0.25, -0.5], atol=1e-6)


# --------------------------------------------------------------------------------------------------
# The forward path


@pytest.fixture(scope="module")
def renderer(ctx) -> Iterator[object]:
    from gratnet.modelfile import load_model
    from viewer.scene import SceneRenderer

    with SceneRenderer(ctx, load_model(BLAZED), weights_path="texture", render_path="forward") as scene:
        buffers = scene.upload(plane())
        yield scene, buffers
        buffers.release()


@dataclasses.dataclass(frozen=True)
class _JitteredCamera(Camera):
    """The camera with its image moved by ``offset`` pixels (x right, y up), built here from the docstring of
    viewer.antialias.jitter_matrix, independently of SceneRenderer's own loop."""

    offset: tuple[float, float] = (0.0, 0.0)
    size: tuple[int, int] = SIZE

    def view_projection(self, aspect: float) -> np.ndarray:
        return super().view_projection(aspect) @ jitter_matrix(self.offset, *self.size)


def _jittered(offset: np.ndarray) -> Camera:
    return _JitteredCamera(CAMERA.distance, CAMERA.azimuth_deg, CAMERA.elevation_deg, CAMERA.target, CAMERA.fov_deg,
                           CAMERA.near, CAMERA.far, offset=(float(offset[0]), float(offset[1])))


def test_one_sample_is_the_render_without_antialiasing_bit_for_bit(renderer):
    scene, buffers = renderer
    plain = scene.render_rgba(buffers, CAMERA, LIGHT, SIZE, 5000.0)
    assert np.array_equal(scene.render_rgba(buffers, CAMERA, LIGHT, SIZE, 5000.0, samples=1), plain)
    assert np.array_equal(scene.render_rgba(buffers, _jittered(np.zeros(2)), LIGHT, SIZE, 5000.0), plain)
    layers = scene.render_layers(buffers, CAMERA, LIGHT, SIZE, 5000.0, samples=1)
    assert np.array_equal(layers[0], plain)


def test_n_samples_are_the_mean_of_n_renders_with_the_jittered_matrices(renderer):
    scene, buffers = renderer
    count = 6
    singles = [scene.render_rgba(buffers, _jittered(offset), LIGHT, SIZE, 5000.0) for offset in sample_offsets(count)]
    mean = scene.render_rgba(buffers, CAMERA, LIGHT, SIZE, 5000.0, samples=count)
    scale = float(np.abs(mean[..., :3]).max())
    assert scale > 0 and not np.array_equal(singles[0], singles[1])  # the offsets change the picture
    np.testing.assert_allclose(mean, np.mean(singles, axis=0), rtol=1e-5, atol=1e-6 * scale)
    # Progressive accumulation's pieces: samples k … k + n − 1 alone, then together, are the same mean.
    parts = [scene.render_rgba(buffers, CAMERA, LIGHT, SIZE, 5000.0, first_sample=k) for k in range(count)]
    np.testing.assert_allclose(np.mean(parts, axis=0), mean, rtol=1e-5, atol=1e-6 * scale)
    rest = scene.render_rgba(buffers, CAMERA, LIGHT, SIZE, 5000.0, samples=count - 2, first_sample=2)
    np.testing.assert_allclose((2 * np.mean(parts[:2], axis=0) + (count - 2) * rest) / count, mean, rtol=1e-5,
                               atol=1e-6 * scale)


def _outline_pixels(size: tuple[int, int]) -> np.ndarray:
    """The plane's corners in pixel coordinates of the un-jittered image (x right, y up, pixel centres at
    i + 0.5), counter-clockwise."""
    width, height = size
    corners = np.array([[-0.05, -0.05, 0.0, 1.0], [0.05, -0.05, 0.0, 1.0], [0.05, 0.05, 0.0, 1.0],
                        [-0.05, 0.05, 0.0, 1.0]])
    clip = corners @ CAMERA.view_projection(width / height).astype(np.float64)
    ndc = clip[:, :2] / clip[:, 3:]
    outline = (ndc + 1.0) / 2.0 * np.array([width, height])
    area = np.sum(outline[:, 0] * np.roll(outline[:, 1], -1) - np.roll(outline[:, 0], -1) * outline[:, 1])
    return outline if area > 0 else outline[::-1]


def _inside(points: np.ndarray, outline: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Whether each point lies inside the convex outline, and its distance to the nearest edge (pixels)."""
    inside = np.ones(points.shape[:-1], dtype=bool)
    nearest = np.full(points.shape[:-1], np.inf)
    for a, b in zip(outline, np.roll(outline, -1, axis=0), strict=True):
        edge = b - a
        cross = edge[0] * (points[..., 1] - a[1]) - edge[1] * (points[..., 0] - a[0])
        inside &= cross > 0
        nearest = np.minimum(nearest, np.abs(cross) / np.hypot(*edge))
    return inside, nearest


def test_edge_coverage_is_the_fraction_of_jittered_sample_points_inside_the_outline(renderer):
    """The rasterizer covers a sample where its point (pixel centre − offset, in the un-jittered image) lies
    inside the projected plane: pins the offsets' size and sign (x right, y up) per pixel."""
    scene, buffers = renderer
    width, height = SIZE
    count = 16
    outline = _outline_pixels(SIZE)
    centres = np.stack(np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5, indexing="xy"), axis=-1)
    points = centres[:, :, None, :] - sample_offsets(count)[None, None]  # (H, W, N, 2), rows from the bottom
    inside, nearest = _inside(points, outline)
    expected = inside.mean(axis=2)[::-1]  # row 0 at the top, as the render
    ambiguous = (nearest < 1e-3).any(axis=2)[::-1]  # a sample on an edge: the fill rule decides
    coverage = scene.render_rgba(buffers, CAMERA, LIGHT, SIZE, 5000.0, samples=count)[..., 3]
    edge = (expected > 0) & (expected < 1)
    assert np.count_nonzero(edge) > 40  # the outline crosses many pixels
    assert np.array_equal(coverage[~ambiguous], expected[~ambiguous].astype(np.float32))
    # The opposite sign of the offsets would give another coverage on most edge pixels.
    flipped = _inside(centres[:, :, None, :] + sample_offsets(count)[None, None], outline)[0].mean(axis=2)[::-1]
    assert np.mean(flipped[edge] != expected[edge]) > 0.3


def test_edge_coverage_converges_to_the_pixels_area_fraction(renderer):
    scene, buffers = renderer
    width, height = SIZE
    outline = _outline_pixels(SIZE)
    grid = (np.arange(32) + 0.5) / 32.0  # a 32 × 32 sub-grid per pixel for the area fraction
    xs = (np.arange(width)[:, None] + grid[None, :]).ravel()
    ys = (np.arange(height)[:, None] + grid[None, :]).ravel()
    fine = _inside(np.stack(np.meshgrid(xs, ys, indexing="xy"), axis=-1), outline)[0]
    area = fine.reshape(height, 32, width, 32).mean(axis=(1, 3))[::-1]
    edge = (area > 0.02) & (area < 0.98)
    errors = {}
    for count in (1, 64):
        coverage = scene.render_rgba(buffers, CAMERA, LIGHT, SIZE, 5000.0, samples=count)[..., 3]
        errors[count] = np.abs(coverage - area)[edge]
    assert errors[1].mean() > 0.15  # one sample: coverage is 0 or 1
    assert errors[64].max() < 0.1 and errors[64].mean() < 0.03


# --------------------------------------------------------------------------------------------------
# gratnet render --spp


def test_render_spp_writes_the_mean_and_records_it(tmp_path, capsys):
    out = tmp_path / "plane.exr"
    common = ["render", "--material", str(BLAZED), "--mesh", "plane", "--size", "24,18", "--camera", "0.16,-70,55",
              "--light", "30,90", "--exposure", "5000", "--weights-path", "texture", "--quiet"]
    assert main([*common, "--spp", "4", "--out", str(out)]) == 0
    assert main([*common, "--out", str(tmp_path / "one.exr")]) == 0
    config = json.loads((tmp_path / "plane.config.json").read_text())["render"]
    assert config["spp"] == 4
    assert json.loads((tmp_path / "one.config.json").read_text())["render"]["spp"] == 1
    assert "4 spp" in capsys.readouterr().out


def test_render_spp_flag_is_the_samples_flag(tmp_path):
    from viewer.scene_config import MAX_SAMPLES as CLI_MAX

    assert CLI_MAX == MAX_SAMPLES  # the CLI repeats the limit (it defers numpy)
    assert main(["render", "--material", str(BLAZED), "--mesh", "plane", "--size", "8,8", "--samples", "2",
                 "--weights-path", "texture", "--quiet", "--out", str(tmp_path / "a.png")]) == 0
    assert json.loads((tmp_path / "a.config.json").read_text())["render"]["spp"] == 2
