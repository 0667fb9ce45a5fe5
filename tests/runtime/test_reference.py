"""The reference look-up (issue 33): the ground-truth volume rendered where the network would run.

Analytic checks first (the numpy look-up is exact at the samples, linear between them, float16 storage within
its stated rounding), then the GLSL look-up against the numpy one (exact on the lattice, 1e-5 of the peak at
random pixels of BRDF slices and mesh renders), then ``gratnet render --reference``: mismatched, corrupt and
oversized volumes refused in one line before any GL work, nothing written.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gratnet.brdf import a_term, direction, slice_view_directions
from gratnet.cli import main
from gratnet.errors import GratNetError
from gratnet.modelfile import load_model
from gratnet.reference import (
    FLOAT16_SCALE,
    check_volume_matches,
    reference_xyz,
    stored_values,
    texture_bytes,
)
from gratnet.volume import Volume, read_volume_header, volume_axes, write_volume
from tests.helpers import REPO
from viewer.screenshot import save_screenshot

CD_MODEL = REPO / "assets" / "cd" / "model.npz"
SCHEMES = ("regular", "simple", "simple-max")


def random_values(slices: int, resolution: int, seed: int = 0) -> np.ndarray:
    """A volume-like array: positive, spanning many decades like a diffraction lobe."""
    rng = np.random.default_rng(seed)
    return (10.0 ** rng.uniform(-9.0, 0.0, size=(slices, resolution, resolution, 3))).astype(np.float32)


def sample_keys(resolution: int, slices: int, scheme: str) -> tuple[np.ndarray, ...]:
    """Key vectors (u, v, w) at every sample of a volume (inverse of eq. 6's coordinates), grids (S, R, R)."""
    axis = volume_axes(resolution)
    t = np.linspace(0.0, 1.0, slices) if slices > 1 else np.zeros(1)
    tt, vv, uu = np.meshgrid(t, axis, axis, indexing="ij")
    if scheme == "regular":
        u, v = uu, vv
    else:
        u, v = 2.0 * np.sign(uu) * (uu / 2.0) ** 2, 2.0 * np.sign(vv) * (vv / 2.0) ** 2
    w = -2.0 * tt if scheme != "simple-max" else -tt * np.sqrt(np.clip(4.0 - u * u - v * v, 0.0, None))
    return u, v, w


# --------------------------------------------------------------------------------------------------
# The numpy look-up (no GPU)


@pytest.mark.parametrize("scheme", SCHEMES)
def test_lookup_is_exact_at_the_samples(scheme):
    values = random_values(5, 17)
    u, v, w = sample_keys(17, 5, scheme)
    looked_up = reference_xyz(values, scheme, u, v, w)
    reachable = u * u + v * v + w * w <= 4.0  # simple-max's t is undefined where 4 − u² − v² = 0
    if scheme == "simple-max":
        reachable &= 4.0 - u * u - v * v > 1e-9
    # Exact up to the float64 rounding of the key → coordinate transform (a fraction of ~1e-15 of a neighbour).
    np.testing.assert_allclose(looked_up[reachable], values[reachable], rtol=1e-6, atol=0.0)


def test_lookup_is_linear_between_samples_and_constant_along_t_for_one_slice():
    values = random_values(3, 9, seed=1).astype(np.float64)
    # Halfway between u* samples 4 and 5 of slice 1 (regular: u = u*, t = 0.5 ⇔ w = −1).
    axis = volume_axes(9)
    middle = reference_xyz(values, "regular", 0.5 * (axis[4] + axis[5]), axis[2], -1.0)
    np.testing.assert_allclose(middle, 0.5 * (values[1, 2, 4] + values[1, 2, 5]), rtol=1e-12)
    single = values[:1]
    np.testing.assert_allclose(reference_xyz(single, "regular", axis[3], axis[6], [-0.3, -1.7]),
                               [single[0, 6, 3]] * 2, rtol=1e-12)


def test_float16_storage_keeps_eleven_bits_over_the_visible_range():
    values = random_values(2, 33, seed=2)
    stored = stored_values(values, "float16")
    relative = np.abs(stored / values - 1.0)
    normal = values * FLOAT16_SCALE >= 2.0**-14  # half floats' normal range
    assert relative[normal].max() <= 2.0**-11
    assert np.all(np.abs(stored - values)[~normal] <= 2.0**-25 / FLOAT16_SCALE)  # subnormal steps: 2^-24 / scale
    assert stored_values(values, "float32") is not None and np.array_equal(stored_values(values, "float32"), values)
    with pytest.raises(GratNetError, match="float32"):
        stored_values(np.full((1, 2, 2, 3), 3.0, dtype=np.float32), "float16")
    assert texture_bytes(41, 1001) == 41 * 1001**2 * 6  # the 41-slice example: 246 MB as float16
    assert texture_bytes(41, 1001, "float32") == 2 * texture_bytes(41, 1001)


def test_a_volume_must_come_from_the_materials_surface():
    trained = {"source": "generator:cd(seed=0)", "sigma_s_um": 16.25}
    check_volume_matches({"source": "generator:cd(seed=0)", "sigma_s_um": 16.25, "resolution": 257}, trained, "v", "m")
    with pytest.raises(GratNetError, match="source 'generator:cd\\(seed=1\\)' against"):
        check_volume_matches({"source": "generator:cd(seed=1)", "sigma_s_um": 16.25}, trained, "v", "m")
    with pytest.raises(GratNetError, match="sigma_s_um 10.0 against 16.25"):
        check_volume_matches({"source": "generator:cd(seed=0)", "sigma_s_um": 10.0}, trained, "v", "m")
    with pytest.raises(GratNetError, match="records no sigma_s_um"):
        check_volume_matches({"source": "generator:cd(seed=0)"}, trained, "v", "m")


# --------------------------------------------------------------------------------------------------
# The GLSL look-up against numpy


@pytest.mark.parametrize("scheme", SCHEMES)
@pytest.mark.parametrize("precision", ["float16", "float32"])
def test_brdf_slice_matches_the_numpy_lookup(ctx, scheme, precision):
    from viewer.reference import ReferenceRenderer

    values = random_values(5, 41, seed=3)
    with ReferenceRenderer(ctx, Volume(values, {"scheme": scheme}), precision=precision) as renderer:
        theta, phi, exposure = 35.0, -60.0, 3.0
        exposed, looked_up = renderer.render_brdf_slice_layers(theta, phi, 48, exposure, ior=1.5)
        light = direction(theta, phi)
        view, inside = slice_view_directions(48)
        key = -(light + view)
        expected = reference_xyz(renderer.values, scheme, key[..., 0], key[..., 1], key[..., 2])
        expected[~inside] = 0.0
        peak = expected.max()
        np.testing.assert_allclose(looked_up, expected, rtol=0.0, atol=1e-5 * peak)
        a = a_term(np.broadcast_to(light, view.shape), view, 1.5)
        shaded = exposure * a[..., None] * expected  # float32 A-term near the rim: 2e-5 relative (test_brdf.py)
        np.testing.assert_allclose(exposed, shaded, rtol=5e-5, atol=1e-5 * shaded.max())
        assert (looked_up[inside] > 0).all()


def test_brdf_slice_is_exact_on_the_lattice(ctx):
    """Normal light, size 8: every pixel's u, v = −ωo,xy is a multiple of 1/8, a sample of a 33² lattice; one slice,
    so t is moot: the shader returns the stored samples bit for bit."""
    from viewer.reference import ReferenceRenderer

    values = random_values(1, 33, seed=4)
    with ReferenceRenderer(ctx, Volume(values, {"scheme": "regular"}), precision="float32") as renderer:
        _, looked_up = renderer.render_brdf_slice_layers(0.0, 0.0, 8, 1.0, ior=None)
    _, inside = slice_view_directions(8)
    axis = volume_axes(33)
    centres = 1.0 - (2 * np.arange(8) + 1) / 8.0  # u = −x_j (columns), v = −y_i with y_i = 1 − (2i+1)/8 (rows)
    columns = np.searchsorted(axis, centres[::-1])[::-1]
    rows = np.searchsorted(axis, -centres)
    np.testing.assert_array_equal(axis[columns], centres)
    expected = values[0][np.ix_(rows, columns)]
    assert np.array_equal(looked_up[inside], expected[inside])


def test_mesh_render_matches_the_numpy_lookup_at_every_pixel(ctx):
    from viewer.camera import Camera, Light
    from viewer.meshes import compact_disc
    from viewer.scene import SceneRenderer

    values = random_values(4, 65, seed=5)
    volume = Volume(values, {"scheme": "simple-max"})
    camera, light = Camera(0.2, -90.0, 50.0), Light.directional(30.0, 180.0)
    with SceneRenderer(ctx, volume, reference_precision="float16") as scene:
        assert scene.render_path == "forward" and scene.network is None
        rgba, key_a = scene.render_layers(compact_disc(segments=48), camera, light, (40, 30), 2.0, 1.5)
        with pytest.raises(GratNetError, match="forward path only"):
            scene.render_rgba(compact_disc(segments=8), camera, light, (8, 8), render_path="deferred")
        stored = scene.reference.values
    lit = key_a[..., 3] > 0
    assert lit.sum() > 100
    key = key_a[lit, :3].astype(np.float64)
    expected = 2.0 * key_a[lit, 3:4] * reference_xyz(stored, "simple-max", key[:, 0], key[:, 1], key[:, 2])
    np.testing.assert_allclose(rgba[lit, :3], expected, rtol=0.0, atol=2e-5 * expected.max())


# --------------------------------------------------------------------------------------------------
# gratnet render --reference


def cd_volume(path: Path, **overrides: object) -> Path:
    """A small volume that claims the shipped cd material's surface (its source and σs)."""
    trained = load_model(CD_MODEL).metadata["volume"]
    metadata = {"scheme": "simple-max", "source": trained["source"], "sigma_s_um": trained["sigma_s_um"], **overrides}
    write_volume(path, Volume(random_values(3, 33, seed=6) * 1e-3, metadata))
    return path


def test_a_reference_volume_shadows_with_its_own_slopes_or_else_its_materials(ctx, tmp_path):
    """Smith's shadowing (gratnet.shadowing) in a --reference render: the volume's recorded slope covariance, or,
    for a volume made before it was recorded, the material's; without a material, none."""
    from viewer.reference import ReferenceRenderer
    from viewer.scene_config import load_reference

    materials = load_model(CD_MODEL).metadata["volume"]["slope_covariance"]
    older = load_reference(cd_volume(tmp_path / "older.exr"), "float16", "cd")
    assert older.metadata["slope_covariance"] == materials
    own = [0.2, 0.01, 0.1]
    recorded = load_reference(cd_volume(tmp_path / "own.exr", slope_covariance=own), "float16", "cd")
    assert recorded.metadata["slope_covariance"] == own
    alone = load_reference(cd_volume(tmp_path / "alone.exr"), "float16")
    for volume, expected in ((older, materials), (recorded, own), (alone, [0.0, 0.0, 0.0])):
        renderer = ReferenceRenderer(ctx, volume)
        try:
            assert list(renderer.slope_covariance) == expected
        finally:
            renderer.release()


def test_render_reference_writes_png_and_config(tmp_path, capsys):
    volume = cd_volume(tmp_path / "cd.exr")
    out = tmp_path / "truth.png"
    assert main(["render", "--material", "cd", "--reference", str(volume), "--size", "32,24", "--spp", "2",
                 "--out", str(out)]) == 0
    assert out.exists() and (tmp_path / "truth.config.json").exists()
    text = (tmp_path / "truth.config.json").read_text()
    assert '"reference"' in text and '"precision": "float16"' in text
    alone = tmp_path / "alone.exr"
    assert main(["render", "--reference", str(volume), "--slice", "--size", "16,16", "--out", str(alone)]) == 0
    assert "reference cd.exr" in capsys.readouterr().out


@pytest.mark.parametrize("case", ["mismatch", "no-scheme", "corrupt", "not-exr", "too-big"])
def test_bad_reference_is_refused_before_any_gl_work(tmp_path, monkeypatch, capsys, case):
    import viewer.context

    def no_context(*args: object, **kwargs: object) -> None:
        raise AssertionError("a GL context was made for a bad --reference")

    monkeypatch.setattr(viewer.context, "create_headless_context", no_context)
    path = tmp_path / "volume.exr"
    if case == "mismatch":
        cd_volume(path, source="generator:cd(seed=7)")
    elif case == "no-scheme":
        cd_volume(path, scheme="")
    elif case == "corrupt":
        cd_volume(path)
        data = bytearray(path.read_bytes())
        data[-200:-100] = bytes(100)  # pixel bytes of the last part: its checksum no longer matches
        path.write_bytes(bytes(data))
    elif case == "not-exr":
        path.write_text("not a volume")
    else:
        monkeypatch.setattr("viewer.reference.MAX_TEXTURE_BYTES", 1000)
        cd_volume(path)
    out = tmp_path / "out.png"
    assert main(["render", "--material", "cd", "--reference", str(path), "--size", "16,16", "--out", str(out)]) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and "error" in error, error
    assert not out.exists() and not (tmp_path / "out.config.json").exists()
    assert [p.name for p in tmp_path.iterdir()] == ["volume.exr"]


def test_reference_header_is_read_without_pixels(tmp_path):
    path = cd_volume(tmp_path / "v.exr")
    header = read_volume_header(path)
    assert (header.slices, header.resolution, header.metadata["scheme"]) == (3, 33, "simple-max")


# --------------------------------------------------------------------------------------------------
# gratnet compare


def test_compare_scores_the_network_against_the_reference(tmp_path):
    import json

    volume = cd_volume(tmp_path / "cd.exr")
    out = tmp_path / "compare"
    assert main(["compare", "cd", "--reference", str(volume), "--meshes", "plane", "--width", "24", "--height", "20",
                 "--spp", "1", "--weights-path", "texture", "--quiet", "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["compare.config.json", "compare.json", "compare.md", "compare.png"]
    rows = json.loads((out / "compare.json").read_text())["views"]
    assert [row["name"] for row in rows][0] == "default" and len(rows) == 3
    # A random volume is not the cd network's truth: the scores must see that (a test that can fail).
    assert all(0.0 < row["flip_covered"] <= 1.0 for row in rows)
    assert "| **mean** |" in (out / "compare.md").read_text()


def test_compare_under_an_environment(tmp_path):
    """``gratnet compare --environment``: both renders lit by it (the volume's own importance table for the
    reference), the light-turned view turns the environment, exposures from the reference's picture."""
    import json

    volume = cd_volume(tmp_path / "cd.exr")
    out = tmp_path / "compare"
    assert main(["compare", "cd", "--reference", str(volume), "--meshes", "plane", "--width", "20", "--height", "16",
                 "--spp", "4", "--environment", "studio", "--weights-path", "texture", "--quiet",
                 "--out", str(out)]) == 0
    document = json.loads((out / "compare.json").read_text())
    rows = document["views"]
    assert len(rows) == 3 and all(0.0 < row["flip_covered"] <= 1.0 for row in rows)
    assert len({row["exposure"] for row in rows}) > 1  # each from its own picture, not the default's
    config = json.loads((out / "compare.config.json").read_text())
    assert config["compare"]["environment"] == "studio"


def test_compare_refuses_a_foreign_volume_before_rendering(tmp_path, capsys):
    volume = cd_volume(tmp_path / "cd.exr", sigma_s_um=3.0)
    assert main(["compare", "cd", "--reference", str(volume), "--out", str(tmp_path / "c")]) == 2
    assert "sigma_s_um 3.0 against" in capsys.readouterr().err
    assert not (tmp_path / "c").exists()


def test_the_lookup_is_the_interpolation_oracle():
    """trainer.diagnostics.VolumeOracle (scipy, the oracle of every slice figure) and the reference look-up are
    the same trilinear interpolation in (u*, v*, t): one truth between samples for slices and meshes alike."""
    from trainer.diagnostics import VolumeOracle

    rng = np.random.default_rng(8)
    for scheme in SCHEMES:
        values = random_values(6, 21, seed=9)
        volume = Volume(values, {"scheme": scheme, "slice_t": list(np.linspace(0.0, 1.0, 6))})
        light = rng.normal(size=(500, 3))
        view = rng.normal(size=(500, 3))
        light[:, 2], view[:, 2] = np.abs(light[:, 2]), np.abs(view[:, 2])
        light /= np.linalg.norm(light, axis=1, keepdims=True)
        view /= np.linalg.norm(view, axis=1, keepdims=True)
        key = -(light + view)
        expected = VolumeOracle(volume)(key[:, 0], key[:, 1], key[:, 2])
        np.testing.assert_allclose(reference_xyz(values, scheme, key[:, 0], key[:, 1], key[:, 2]), expected,
                                   rtol=1e-9, atol=1e-15)


def test_non_uniform_slices_are_refused():
    from gratnet.reference import check_uniform_slices

    check_uniform_slices({"slice_t": [0.0, 0.5, 1.0]}, 3)
    check_uniform_slices({}, 3)
    with pytest.raises(GratNetError, match="not at t = s/"):
        check_uniform_slices({"slice_t": [0.0, 0.2, 1.0]}, 3)


# --------------------------------------------------------------------------------------------------
# The viewer: network / reference / FLIP


def test_viewer_shows_the_reference_and_the_flip_heat_map(ctx, tmp_path):
    from viewer.app import ViewerApp
    from viewer.reference_view import LoadedReference
    from viewer.scene_config import load_reference
    from viewer.state import ViewerState

    path = cd_volume(tmp_path / "cd.exr")
    loaded = LoadedReference(load_reference(path, "float16", "cd"), str(path), "cd")
    state = ViewerState(material="cd", mesh="plane", camera_distance=0.15, camera_elevation=50.0, light_theta=30.0,
                        light_phi=90.0, exposure=3.0)
    viewer = ViewerApp(ctx, state, size=(40, 32), weights_path="texture", reference=loaded)
    try:
        network = viewer.render_full().copy()
        assert viewer.flip_mean is None
        assert viewer.set(shading="reference")
        shown = viewer.render_full().copy()
        renderer, buffers = viewer.supply.scene(viewer.state, preview=False)
        truth = viewer.reference.scene().render_srgb8(buffers, state.camera(), state.light(), (40, 32), 3.0, 1.5)
        assert np.array_equal(shown, truth) and not np.array_equal(shown, network)
        assert viewer.set(shading="flip")
        heat = viewer.render_full().copy()
        assert heat.shape == (32, 40, 3) and not np.array_equal(heat, shown)
        assert 0.0 < viewer.flip_mean <= 1.0  # a random volume is not the network's truth
        screenshot = save_screenshot(viewer, tmp_path / "flip.png")
        assert '"shading": "flip"' in screenshot.with_suffix(".config.json").read_text()
        with pytest.raises(GratNetError, match="shading must be one of"):
            viewer.set(shading="truth")
        assert viewer.set(material="blazed") and viewer.state.shading == "network"  # the volume is cd's only
        assert not viewer.set(shading="reference") and "cd's, not blazed's" in viewer.message
    finally:
        viewer.release()


def test_view_refuses_a_foreign_volume_before_any_window(tmp_path, monkeypatch, capsys):
    import viewer.window

    def no_window(*args: object, **kwargs: object) -> None:
        raise AssertionError("a window was opened for a bad --reference")

    monkeypatch.setattr(viewer.window, "ViewerWindow", no_window)
    volume = cd_volume(tmp_path / "cd.exr", source="generator:cd(seed=3)")
    assert main(["view", "--material", "cd", "--reference", str(volume), "--screenshot-dir", str(tmp_path)]) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and "not the ground truth of cd" in error, error


def test_reference_refuses_the_deferred_path_in_one_line(tmp_path, capsys):
    volume = cd_volume(tmp_path / "cd.exr")
    out = tmp_path / "x.png"
    assert main(["render", "--material", "cd", "--reference", str(volume), "--render-path", "deferred", "--size",
                 "16,16", "--out", str(out)]) == 2
    assert "takes the forward path" in capsys.readouterr().err and not out.exists()
