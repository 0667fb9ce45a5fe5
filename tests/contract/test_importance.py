"""gratnet.importance: light directions sampled from the material's own diffraction (issue 43).

- the formulas the GLSL side reproduces: which uniform number goes where, the cosine mapping, wi = −(u, v) − wo;
- the density: integrates over the hemisphere to the share of valid samples (computed from the table), and a χ²
  of sampled directions against it, in the key's (u, v) (exact per cell) and in solid angle;
- a synthetic material (Gaussian peaks in (u, v)) puts the table's mass at its peaks; so does a volume;
- invalid samples (|wi.xy| ≥ 1) are flagged with pdf 0; bad input is one GratNetError; the cache gives the same
  table back, from memory and from disk.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gratnet import importance
from gratnet.errors import GratNetError
from gratnet.importance import DEFENSIVE_SHARE, MaterialTable, luminance_table
from gratnet.modelfile import evaluate_keys
from gratnet.volume import Volume, volume_axes
from tests.helpers import random_model, solid_angle_chi2

#: Synthetic peaks: (u, v, σ, height); the specular one at the origin, two "orders" off it.
PEAKS = ((0.0, 0.0, 0.05, 1.0), (0.6, 0.0, 0.04, 0.5), (-0.3, 0.8, 0.06, 0.3))


def peaks_luminance(u: np.ndarray, v: np.ndarray, w: np.ndarray, peaks: tuple = PEAKS) -> np.ndarray:
    """A material whose CIE Y is a few Gaussian peaks in (u, v), the same at every w."""
    total = np.zeros(np.broadcast_shapes(np.shape(u), np.shape(v), np.shape(w)))
    for pu, pv, sigma, height in peaks:
        total = total + height * np.exp(-((u - pu) ** 2 + (v - pv) ** 2) / (2.0 * sigma**2))
    return total


@pytest.fixture(scope="module")
def table() -> MaterialTable:
    return luminance_table(peaks_luminance, 64, subsamples=2, progress=False)


def view(theta_degrees: float, phi_degrees: float = 0.0) -> np.ndarray:
    theta, phi = math.radians(theta_degrees), math.radians(phi_degrees)
    return np.array([math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), math.cos(theta)])


def disc_mass(table: MaterialTable, wo: np.ndarray, sub: int = 16) -> float:
    """The table's mass inside the unit disc around −wo.xy in (u, v): the share of table samples that are valid
    (exact per cell, midpoint rule on sub × sub points per cell only at the disc's edge)."""
    points = table.resolution * sub
    axis = table.key_min + (np.arange(points) + 0.5) * (table.span / points)
    u, v = np.meshgrid(axis, axis)
    inside = (u + wo[0]) ** 2 + (v + wo[1]) ** 2 < 1.0
    return float(np.sum(table.pdf_uv(u, v) * inside) * (table.span / points) ** 2)


# ------------------------------------------------------------------------------------------------
# The formulas (the GLSL contract)


def test_uniform_numbers_go_where_the_docstring_says(table: MaterialTable) -> None:
    rng = np.random.default_rng(0)
    count = 2000
    wo = view(35.0, 20.0)
    choice, row, column = rng.random(count), rng.random(count), rng.random(count)
    wi, pdf, valid = table.sample(wo, choice, row, column)
    cosine = choice < DEFENSIVE_SHARE
    assert 0 < cosine.sum() < count
    # Cosine branch: r = sqrt(ξr), φ = 2π ξk, z = sqrt(1 − ξr).
    expected = np.stack([np.sqrt(row) * np.cos(2 * np.pi * column), np.sqrt(row) * np.sin(2 * np.pi * column),
                         np.sqrt(1.0 - row)], axis=-1)
    np.testing.assert_allclose(wi[cosine], expected[cosine], atol=1e-12)
    # Table branch: (x, y) from the distribution with ξr for the row (v) and ξk for the column (u).
    x, y, _ = table.distribution.sample(row, column)
    u, v = table.key_min + x * table.span, table.key_min + y * table.span
    light = np.stack([-u - wo[0], -v - wo[1]], axis=-1)
    good = ~cosine & valid
    np.testing.assert_allclose(wi[good, :2], light[good], atol=1e-12)
    np.testing.assert_allclose(wi[good, 2], np.sqrt(1.0 - np.sum(light[good] ** 2, axis=-1)), atol=1e-12)
    # The density of every valid sample is pdf(wo, wi): (1 − d)·pdf_uv·cos θi + d·cos θi/π.
    np.testing.assert_allclose(pdf[valid], table.pdf(wo, wi[valid]), rtol=1e-12)
    key = -(wi[valid] + wo)
    manual = ((1 - DEFENSIVE_SHARE) * table.pdf_uv(key[:, 0], key[:, 1]) + DEFENSIVE_SHARE / np.pi) * wi[valid, 2]
    np.testing.assert_allclose(pdf[valid], manual, rtol=1e-12)
    # pdf_uv is the unit-square density over span².
    np.testing.assert_allclose(table.pdf_uv(u, v), table.distribution.pdf(x, y) / table.span**2, rtol=1e-12)


def test_pdf_is_zero_below_either_horizon(table: MaterialTable) -> None:
    below = np.array([[0.3, 0.0, -0.95]])
    assert table.pdf(view(30.0), below)[0] == 0.0
    assert table.pdf(below, view(30.0))[0] == 0.0
    wi, pdf, valid = table.sample(below[0], [0.5, 0.05], [0.3, 0.3], [0.4, 0.4])
    assert not valid.any() and np.all(pdf == 0.0)


# ------------------------------------------------------------------------------------------------
# The density against the samples


@pytest.mark.parametrize("theta", [0.0, 40.0, 80.0])
def test_pdf_integrates_to_the_share_of_valid_samples(table: MaterialTable, theta: float) -> None:
    """∫ pdf dω over the hemisphere (midpoint rule in cos θ, φ) = d + (1 − d)·(table mass in the reachable disc);
    the sampler's valid share agrees."""
    wo = view(theta, 30.0)
    bins_cos, bins_phi = 1200, 2400
    c = (np.arange(bins_cos) + 0.5) / bins_cos
    p = -np.pi + 2 * np.pi * (np.arange(bins_phi) + 0.5) / bins_phi
    cc, pp = np.meshgrid(c, p, indexing="ij")
    s = np.sqrt(1.0 - cc * cc)
    grid = np.stack([s * np.cos(pp), s * np.sin(pp), cc], -1).reshape(-1, 3)
    integral = float(table.pdf(wo, grid).sum() * (1.0 / bins_cos) * (2 * np.pi / bins_phi))
    share = DEFENSIVE_SHARE + (1 - DEFENSIVE_SHARE) * disc_mass(table, wo)
    assert share <= 1.0 + 1e-9
    assert integral == pytest.approx(share, abs=5e-3)
    rng = np.random.default_rng(1)
    count = 200_000
    _, _, valid = table.sample(wo, rng.random(count), rng.random(count), rng.random(count))
    assert abs(valid.mean() - share) < 5.0 * math.sqrt(share * (1 - share) / count) + 1e-4
    if theta == 80.0:
        assert share < 0.99  # the grazing view loses table samples: the check above is not trivial


def _uv_chi2_p_value(table: MaterialTable, wo: np.ndarray, wrong_share: float | None = None) -> float:
    """scipy χ² p-value of the valid samples' key (u, v) in the table's own cells against the density of valid
    samples there, ``(1 − d)·pdf_uv + d/π`` inside the reachable disc (exact per cell but for the disc's edge).
    ``wrong_share``: use that cosine share in the expected counts (a deliberately wrong density)."""
    from scipy import stats

    share = DEFENSIVE_SHARE if wrong_share is None else wrong_share
    rng = np.random.default_rng(2)
    count = 300_000
    wi, _, valid = table.sample(wo, rng.random(count), rng.random(count), rng.random(count))
    key = -(wi[valid] + wo)
    cells = table.resolution
    histogram, _, _ = np.histogram2d(key[:, 1], key[:, 0], bins=cells,
                                     range=[[table.key_min, table.key_max]] * 2)
    sub = 8
    points = cells * sub
    axis = table.key_min + (np.arange(points) + 0.5) * (table.span / points)
    u, v = np.meshgrid(axis, axis)
    inside = (u + wo[0]) ** 2 + (v + wo[1]) ** 2 < 1.0
    density = ((1 - share) * table.pdf_uv(u, v) + share / np.pi) * inside
    expected = density.reshape(cells, sub, cells, sub).sum(axis=(1, 3)) * (table.span / points) ** 2 * count
    order = np.argsort(expected.ravel())
    e, h = expected.ravel()[order], histogram.ravel()[order]
    keep = e >= 5.0  # pool the cells expected to hold fewer than 5 samples, as Mitsuba's test does
    pooled_e, pooled_h = np.append(e[keep], e[~keep].sum()), np.append(h[keep], h[~keep].sum())
    pooled_e *= pooled_h.sum() / pooled_e.sum()
    return float(stats.chisquare(pooled_h, pooled_e).pvalue)


@pytest.mark.parametrize("theta", [0.0, 50.0, 75.0])
def test_samples_match_the_pdf_chi2_in_uv(table: MaterialTable, theta: float) -> None:
    p_value = _uv_chi2_p_value(table, view(theta, 60.0))
    print(f"importance table θ={theta}°: χ² p-value in (u, v) {p_value:.3f}")
    assert p_value > 0.001


def test_the_uv_chi2_rejects_a_wrong_cosine_share(table: MaterialTable) -> None:
    assert _uv_chi2_p_value(table, view(50.0, 60.0), wrong_share=0.12) < 1e-6


def test_samples_match_the_pdf_chi2_in_solid_angle() -> None:
    """A histogram over (cos θ, φ), as tests/runtime/test_mitsuba.py's for the mixture, with wide peaks (so that
    the midpoint rule over each bin is accurate): checks the cos θi of the solid-angle density."""
    wide = luminance_table(lambda u, v, w: peaks_luminance(u, v, w, ((0.0, 0.0, 0.3, 1.0), (0.8, 0.3, 0.25, 0.6))),
                           32, subsamples=1, progress=False)
    wo = view(40.0, 10.0)
    rng = np.random.default_rng(3)
    count = 300_000
    wi, _, valid = wide.sample(wo, rng.random(count), rng.random(count), rng.random(count))
    p_value, expected = solid_angle_chi2(wi[valid], lambda grid: wide.pdf(wo, grid), count, (30, 60), 8)
    assert abs(expected - valid.sum()) < 5.0 * math.sqrt(count) + 2e-3 * count
    print(f"importance table: χ² p-value in solid angle {p_value:.3f}")
    assert p_value > 0.001


# ------------------------------------------------------------------------------------------------
# Where the mass goes


def test_the_table_puts_its_mass_at_the_peaks(table: MaterialTable) -> None:
    cells = table.resolution
    centres = table.key_min + (np.arange(cells) + 0.5) * (table.span / cells)
    u, v = np.meshgrid(centres, centres)
    mass = table.distribution.density / cells**2  # each cell's probability
    near = np.zeros_like(mass, dtype=bool)
    for pu, pv, sigma, _ in PEAKS:
        near |= (u - pu) ** 2 + (v - pv) ** 2 < (4.0 * sigma + table.span / cells) ** 2
    assert mass[near].sum() > 0.95
    # Each peak gets about its share of the luminance's integral (height · σ²), within the cells' blur.
    for pu, pv, sigma, height in PEAKS:
        around = (u - pu) ** 2 + (v - pv) ** 2 < (4.0 * sigma + table.span / cells) ** 2
        share = height * sigma**2 / sum(h * s**2 for _, _, s, h in PEAKS)
        assert mass[around].sum() == pytest.approx(share, rel=0.5)
    # No reachable cell is 0 (the floor); the unreachable corners are.
    edges = table.key_min + np.arange(cells + 1) * (table.span / cells)
    nearest = np.minimum(np.abs(edges[:-1]), np.abs(edges[1:])) * (np.sign(edges[:-1]) == np.sign(edges[1:]))
    reachable = nearest[:, None] ** 2 + nearest[None, :] ** 2 < 4.0
    assert np.all(table.distribution.density[reachable] > 0.0)
    assert np.all(table.distribution.density[~reachable] == 0.0)


def test_a_peak_between_evaluation_points_still_gets_its_cell() -> None:
    """A peak far narrower than a cell, between the cell's sub-samples, still weighs far above the floor."""
    cells = 32
    corner = -2.0 + 4.0 * 20 / cells  # a cell corner: as far from every cell's points as can be
    narrow = luminance_table(lambda u, v, w: peaks_luminance(u, v, w, ((corner, corner, 0.02, 1.0),)), cells,
                             subsamples=2, progress=False)
    density = narrow.distribution.density
    assert density[19:21, 19:21].sum() / density.sum() > 0.5


def test_a_volume_table_follows_the_volume() -> None:
    """volume_table: the reference look-up's Y; a volume with one bright sample puts the mass there."""
    resolution, slices = 65, 3
    axes = volume_axes(resolution)
    xyz = np.full((slices, resolution, resolution, 3), 1e-6, dtype=np.float32)
    row, column = 40, 20  # v* = axes[40], u* = axes[20] (regular: u = u*)
    xyz[:, row, column, :] = 1.0
    table = importance.volume_table(Volume(xyz, {"scheme": "regular"}), 64, cache=False, progress=False)
    cells = 64
    centres = -2.0 + (np.arange(cells) + 0.5) * (4.0 / cells)
    u, v = np.meshgrid(centres, centres)
    near = (np.abs(u - axes[column]) < 0.1) & (np.abs(v - axes[row]) < 0.1)
    assert (table.distribution.density / cells**2)[near].sum() > 0.9
    assert table.source == "volume"
    with pytest.raises(GratNetError, match="scheme"):
        importance.volume_table(Volume(xyz, {}), 64, cache=False, progress=False)


def test_model_luminance_is_the_contract_y() -> None:
    model = random_model([163, 24, 16, 3], scheme="simple-max")
    rng = np.random.default_rng(4)
    u, v = rng.uniform(-1.0, 1.0, (2, 500))
    w = -rng.uniform(0.1, 1.0, 500) * np.sqrt(4.0 - u * u - v * v)
    expected = evaluate_keys(model, u, v, w)[:, 1]
    np.testing.assert_allclose(importance.model_luminance(model)(u, v, w), expected, rtol=2e-3, atol=1e-30)


def test_colour_table_is_the_network_at_the_cells_and_the_luminance_the_same_evaluations() -> None:
    """material_weights evaluates once over the union of the fractions: its Y weights are luminance_weights', and the
    colour table (the control variate's, physics.md "Environment light") is the network's XYZ at each cell's points
    (their mean: 2² here) at COLOUR_W_FRACTIONS, 0 on cells outside the disc u² + v² < 4."""
    model = random_model([163, 24, 16, 3], scheme="simple-max", seed=9)
    size, sub = 32, 2
    weights, colour = importance.material_weights(importance.model_xyz(model), size, subsamples=sub, progress=False)
    np.testing.assert_array_equal(weights, importance.luminance_weights(importance.model_luminance(model), size,
                                                                        subsamples=sub, progress=False))
    assert colour.shape == (importance.COLOUR_SLICES, size, size, 3) and colour.dtype == np.float32
    points = size * sub
    axis = -2.0 + (np.arange(points) + 0.5) * (4.0 / points)
    u, v = np.meshgrid(axis, axis)
    inside = u * u + v * v < 4.0
    for j, t in enumerate(importance.COLOUR_W_FRACTIONS):
        w = -t * np.sqrt(np.clip(4.0 - u * u - v * v, 0.0, None))
        xyz = np.where(inside[..., None], evaluate_keys(model, u, v, w), 0.0)
        expected = xyz.reshape(size, sub, size, sub, 3).mean(axis=(1, 3))
        np.testing.assert_allclose(colour[j], expected, rtol=3e-3, atol=1e-6 * float(np.abs(expected).max()))
    table = importance.material_table(model, size, subsamples=sub, cache=False, progress=False)
    np.testing.assert_array_equal(table.colour, colour)
    assert importance.flat_table().colour is None  # no material: no control variate


# ------------------------------------------------------------------------------------------------
# Bad input and the cache


@pytest.mark.parametrize("resolution", [8, 100, 4096, 0, -16, 1.5, True, "256"])
def test_bad_resolution_is_one_error(resolution: object) -> None:
    with pytest.raises(GratNetError, match="power of two") as caught:
        luminance_table(peaks_luminance, resolution, progress=False)  # type: ignore[arg-type]
    assert "\n" not in str(caught.value)


def test_bad_shapes_are_one_error(table: MaterialTable) -> None:
    rng = np.random.default_rng(5)
    for call in (lambda: table.pdf(view(10.0), np.ones((4, 2))),
                 lambda: table.pdf(np.ones((3, 3)), np.ones((4, 3))),
                 lambda: table.pdf(view(10.0)[:2], np.ones((4, 3))),
                 lambda: table.sample(view(10.0), rng.random((2, 2)), rng.random(4), rng.random(4)),
                 lambda: table.sample(view(10.0), rng.random(3), rng.random(4), rng.random(4)),
                 lambda: table.sample(np.ones((5, 3)), rng.random(4), rng.random(4), rng.random(4))):
        with pytest.raises(GratNetError) as caught:
            call()
        assert "\n" not in str(caught.value)
    for bad in ({"subsamples": 0}, {"w_range": (1.5,)}, {"w_range": ()}, {"combine": "median"}):
        with pytest.raises(GratNetError):
            luminance_table(peaks_luminance, 16, progress=False, **bad)


def test_the_cache_gives_the_same_table(tmp_path: object, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    model = random_model([163, 16, 3], scheme="simple-max", seed=7)
    first = importance.material_table(model, 32, subsamples=1, progress=False)
    assert importance.material_table(model, 32, subsamples=1, progress=False) is first  # in memory
    files = list((importance.importance_cache_folder()).glob("*.npz"))
    assert [path.stem for path in files] == [first.digest]
    importance.clear_memory_cache()
    again = importance.material_table(model, 32, subsamples=1, progress=False)  # from disk
    assert again is not first
    np.testing.assert_array_equal(again.distribution.density, first.distribution.density)
    np.testing.assert_array_equal(again.colour, first.colour)
    assert (again.resolution, again.w_range, again.source) == (first.resolution, first.w_range, "model")
    other = importance.material_table(random_model([163, 16, 3], scheme="simple-max", seed=8), 32, subsamples=1,
                                      progress=False)
    assert other.digest != first.digest  # another model's content: another key
    # A corrupt cache file is rebuilt, not trusted.
    files[0].write_bytes(b"not an npz")
    importance.clear_memory_cache()
    rebuilt = importance.material_table(model, 32, subsamples=1, progress=False)
    np.testing.assert_array_equal(rebuilt.distribution.density, first.distribution.density)


def test_the_cached_look_never_builds(tmp_path: object, monkeypatch: pytest.MonkeyPatch) -> None:
    """cached_material_table: None while no table is cached (and still none on disk afterwards), the cached table
    once one is, from memory or from disk (the viewer's window reads its compile child's table this way)."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    importance.clear_memory_cache()
    model = random_model([163, 16, 3], scheme="simple-max", seed=9)
    assert importance.cached_material_table(model, 32, subsamples=1) is None
    assert not importance.importance_cache_folder().exists()
    built = importance.material_table(model, 32, subsamples=1, progress=False)
    assert importance.cached_material_table(model, 32, subsamples=1) is built
    importance.clear_memory_cache()
    found = importance.cached_material_table(model, 32, subsamples=1)
    assert found is not None and found.digest == built.digest
    np.testing.assert_array_equal(found.distribution.density, built.distribution.density)


def test_the_flat_table_is_uniform_over_the_reachable_cells() -> None:
    """flat_table: the same density in every cell that meets the disc u² + v² < 4, none outside; so the table
    branch's keys are uniform there, and every density above still holds (it is a table like any other)."""
    flat = importance.flat_table()
    assert flat.source == "flat" and flat.resolution == importance.FLAT_RESOLUTION and flat is importance.flat_table()
    cells = flat.resolution
    centres = flat.key_min + (np.arange(cells) + 0.5) * (flat.span / cells)
    u, v = np.meshgrid(centres, centres)
    density = flat.pdf_uv(u, v)
    half = flat.span / cells / 2  # a cell meets the disc when its nearest point to the origin lies inside it
    nearest_u, nearest_v = np.maximum(np.abs(u) - half, 0.0), np.maximum(np.abs(v) - half, 0.0)
    reachable = nearest_u**2 + nearest_v**2 < 4.0
    assert np.all(density[~reachable] == 0.0)
    np.testing.assert_allclose(density[reachable], 1.0 / (reachable.sum() * (flat.span / cells) ** 2), rtol=1e-9)
    assert _uv_chi2_p_value(flat, view(40.0, 60.0)) > 0.001
