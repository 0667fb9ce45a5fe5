"""The tiled compute MLP (shaders/mlp_tiled.glsl, viewer/tiled.py; issue 32) against the per-entry SHADE kernel
and numpy.

GPU tests need an OpenGL 4.3 context through EGL (Mesa llvmpipe on a CPU-only machine) and skip with the reason
when there is none. The kernels run on lists of key vectors chosen here (``DeferredRenderer.shade_keys``: no
G-buffer pass, no compaction), so the list lengths fall exactly at tile edges; a few renders check that the
tiled kernel drops into the deferred path (1×1, odd sizes, an empty mesh, several samples).

The bound between the two kernels (:func:`kernel_pair_bound`) is a float32 argument, not a fitted tolerance:
both kernels run the same encoding, feature-grid and eq. 7 code on the same float32 key; only the MLP's sums
may be ordered and fused differently.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest

from gratnet.encoding import network_coordinates, range_inverse
from gratnet.errors import GratNetError
from gratnet.modelfile import ModelFile, load_model, network_inputs
from gratnet.precision import OWN_KEYS, UNIT_ROUNDOFF, assert_within, driver_bound
from tests.helpers import ASSETS, parity_keys, random_model
from viewer.camera import Camera, Light
from viewer.meshes import Mesh, compact_disc, plane

if TYPE_CHECKING:
    import moderngl

    from viewer.deferred import DeferredRenderer

SHIPPED = sorted(path.parent.name for path in ASSETS.glob("*/model.npz"))
#: Each tiled form and the per-entry kernel reading the same stored weights.
PAIRS = {"tiled": "ssbo", "tiled-fp16": "ssbo-fp16"}
#: Largest slope of each activation (SiLU 1.0998 at x ≈ 2.4; sigmoid 1/4).
LIPSCHITZ = {"silu": 1.1, "relu": 1.0, "leaky_relu": 1.0, "sigmoid": 0.25, "clamp": 1.0, "none": 1.0}
DISC_CAMERA = Camera(distance=0.2, azimuth_deg=-90.0, elevation_deg=50.0)
DISC_LIGHT = Light.directional(40.0, 80.0)


def _gamma(terms: int) -> float:
    """Higham's γₙ: an n-term float32 dot product in any order, fused or not, errs by ≤ γₙ · Σ|terms|."""
    return terms * UNIT_ROUNDOFF / (1.0 - terms * UNIT_ROUNDOFF)


def kernel_pair_bound(model: ModelFile, keys: np.ndarray, fp16_weights: bool = False) -> np.ndarray:
    """A bound on |XYZ_tiled − XYZ_SHADE| at float32 ``keys`` (N, 3), ``(N, 3)`` float64.

    - Inputs: the same encoding.glsl / featuregrid.glsl source on the same key and driver, but compiled into two
      programs, which may contract a·b + c differently outside ``precise``: 4 ulps of each encoded feature; a
      grid feature is an 8-term trilinear sum with rounded weights, so each side errs by γ₁₂ · Σ wᵢ|fᵢ| (the
      trilinear interpolation of |grid|), twice that between the two.
    - Layer k, z = b + Σᵢ wᵢ aᵢ over n inputs: each kernel's float32 sum lies within γ_{n+1} · (|b| + Σ|w||a|) of
      the exact sum of its own inputs (any order, fused or not: the tiled kernel adds the same terms, chunk by
      chunk, and tiled-half's emulation in partial sums per chunk), so the two differ by
      |W|·δa + 2 γ_{n+1} (|b| + |W||a|) — the bound ∝ ε·Σ|w||a| per layer.
    - Hidden activation: slope ≤ LIPSCHITZ on δz, plus each side's own rounding (SiLU: exp, 1 + e, division,
      product: 4 ulps each side). Output activation: its slope (clamp 1).
    - Eq. 7 (range.glsl, the same code): |XYZ(y ± δy) − XYZ(y)|, plus each side's pow/exp2 rounding
      (gratnet.precision's range part, twice).
    ``fp16_weights``: the weights as the buffer holds them (IEEE halves), where both kernels read those.
    """
    keys = np.asarray(keys, dtype=np.float64)
    coordinates = network_coordinates(keys[:, 0], keys[:, 1], keys[:, 2], model.scheme)
    a = network_inputs(model, coordinates)
    delta = 4.0 * UNIT_ROUNDOFF * np.abs(a)
    if model.grids:
        magnitudes = network_inputs(model, coordinates, grids=[np.abs(grid) for grid in model.grids])
        grid_columns = len(model.grids) * model.grids[0].shape[-1]  # the grid features come first
        delta[:, :grid_columns] = np.maximum(delta[:, :grid_columns],
                                             2.0 * _gamma(12) * magnitudes[:, :grid_columns])
    last = len(model.weights) - 1
    from gratnet.network import activate_hidden, activate_output

    for k, (weight, bias) in enumerate(zip(model.weights, model.biases, strict=True)):
        w = weight.astype(np.float16 if fp16_weights else np.float32).astype(np.float64)
        b = bias.astype(np.float16 if fp16_weights else np.float32).astype(np.float64)
        z = a @ w.T + b
        delta_z = delta @ np.abs(w).T + 2.0 * _gamma(w.shape[1] + 1) * (np.abs(a) @ np.abs(w).T + np.abs(b))
        if k == last:
            a = activate_output(z, model.output_activation)
            delta = LIPSCHITZ[model.output_activation] * delta_z
        else:
            a = activate_hidden(z, model.activation)
            delta = LIPSCHITZ[model.activation] * delta_z + 2.0 * 4.0 * UNIT_ROUNDOFF * np.abs(a)
    xyz = range_inverse(a, model.range)
    moved = np.maximum(np.abs(range_inverse(a + delta, model.range) - xyz),
                       np.abs(range_inverse(np.maximum(a - delta, 0.0), model.range) - xyz))
    own = driver_bound(model, keys[:, 0], keys[:, 1], keys[:, 2], OWN_KEYS).range_rounding
    return moved + 2.0 * own


def _keys(count: int | None = None) -> np.ndarray:
    """test_shader_parity's ~270 keys (random pairs, normal incidence, |w| → 0, u² + v² → 4), repeated to ``count``."""
    keys = np.stack(parity_keys(), axis=-1)
    return keys if count is None else np.resize(keys, (count, 3))


class Kernels:
    """One NetworkRenderer and a DeferredRenderer per weights form, on one model."""

    def __init__(self, ctx: moderngl.Context, model: ModelFile) -> None:
        from viewer.renderer import NetworkRenderer

        self.model = model
        self.network = NetworkRenderer(ctx, model, weights_path="texture")
        self.made: dict[str, DeferredRenderer] = {}

    def __getitem__(self, weights: str) -> DeferredRenderer:
        from viewer.deferred import DeferredRenderer

        if weights not in self.made:
            self.made[weights] = DeferredRenderer(self.network, weights)
        return self.made[weights]

    def release(self) -> None:
        for deferred in self.made.values():
            deferred.release()
        self.network.release()


@pytest.fixture(scope="module")
def cd_kernels(ctx) -> Iterator[Kernels]:
    kernels = Kernels(ctx, load_model(ASSETS / "cd" / "model.npz"))
    yield kernels
    kernels.release()


def assert_pair(tiled: np.ndarray, shade: np.ndarray, bound: np.ndarray, what: str) -> None:
    assert tiled.shape == shade.shape and tiled.dtype == np.float32
    assert np.all(np.isfinite(tiled))
    assert_within(tiled, shade.astype(np.float64), bound, what)


@pytest.mark.parametrize("material", SHIPPED)
def test_every_shipped_model_equals_the_shade_kernel_and_numpy(ctx, material):
    model = load_model(ASSETS / material / "model.npz")
    keys = _keys()
    kernels = Kernels(ctx, model)
    try:
        for tiled, per_entry in PAIRS.items():
            bound = kernel_pair_bound(model, keys, fp16_weights=tiled.endswith("-fp16"))
            actual = kernels[tiled].shade_keys(keys)
            assert_pair(actual, kernels[per_entry].shade_keys(keys), bound, f"{material} {tiled} vs {per_entry}")
            if tiled == "tiled":  # float32 weights: numpy's float64 forward pass, gratnet.precision's driver bound
                expected = driver_bound(model, keys[:, 0], keys[:, 1], keys[:, 2], OWN_KEYS)
                assert np.all(expected.xyz.max(axis=0) > 0)
                assert_within(actual, expected.xyz, expected.bound, f"{material} tiled vs numpy")
    finally:
        kernels.release()


def test_tile_edges_odd_lengths_pieces_and_the_empty_list(cd_kernels):
    tiled = cd_kernels["tiled"]
    tile = tiled.tile_plan.pixels
    keys = _keys(3 * 256 + tile + 3)
    bound = kernel_pair_bound(cd_kernels.model, keys)
    whole = cd_kernels["ssbo"].shade_keys(keys)
    for count in sorted({1, 3, tile - 1, tile, tile + 1, 2 * tile - 1, 2 * tile + 1, 5 * tile + 3, 257}):
        assert_pair(tiled.shade_keys(keys[:count]), whole[:count], bound[:count], f"{count} entries")
    # Pieces of 256 entries, as a render shades a long list: each piece's tiles start again at its first entry.
    assert_pair(tiled.shade_keys(keys, piece_entries=256), whole, bound, "pieces of 256")
    assert tiled.shade_keys(keys[:0]).shape == (0, 3)  # one dispatch over an empty list: no group runs past it
    # Timed repeats (benchmarks/shade_kernels.py) upload the keys and the list again: the same outputs.
    timings: list[tuple[float, float]] = []
    again = tiled.shade_keys(keys, piece_entries=256, timings=timings, repeats=2)
    assert len(timings) == 2 and all(wall > 0 for _, wall in timings)
    assert_pair(again, whole, bound, "timed repeats")


@pytest.mark.parametrize(("budget", "max_pixels", "group"),
                         [(8192, 32, 8),  # 4 pixels, the 108-wide layer in 21 chunks of 2 input blocks
                          (32768, 8, 16),  # 8 pixels, 4 items per invocation
                          (32768, 32, 256)])  # more invocations than items: idle ones, 12 encoding each pixel
def test_other_plans_give_the_same_outputs(ctx, cd_kernels, budget, max_pixels, group):
    from viewer.deferred import DeferredRenderer
    from viewer.tiled import plan_tiles

    keys = _keys(2 * 37 + 1)
    deferred = DeferredRenderer(cd_kernels.network, "tiled")
    try:
        deferred.tile_plan = plan_tiles(cd_kernels.network.layout, budget, 1024, max_pixels=max_pixels, group=group)
        assert deferred.tile_plan.shared_bytes <= budget
        assert_pair(deferred.shade_keys(keys), cd_kernels["ssbo"].shade_keys(keys),
                    kernel_pair_bound(cd_kernels.model, keys), deferred.tile_plan.describe(cd_kernels.network.layout))
    finally:
        deferred.release()


def test_half_arithmetic_path_compiled_in_float_and_refused_without_the_extension(ctx, cd_kernels):
    from viewer.deferred import DeferredRenderer
    from viewer.tiled import half_extension

    keys = _keys(45)
    emulated = DeferredRenderer(cd_kernels.network, "tiled-half", half_as_float=True)
    try:  # tiled-half's code (fp16 storage, partial sums per chunk) with float types: the same bound
        assert_pair(emulated.shade_keys(keys), cd_kernels["ssbo-fp16"].shade_keys(keys),
                    kernel_pair_bound(cd_kernels.model, keys, fp16_weights=True), "tiled-half as float")
    finally:
        emulated.release()
    if half_extension(ctx) is None:
        with pytest.raises(GratNetError, match="tiled-half.*GL_NV_gpu_shader5.*use tiled or tiled-fp16"):
            DeferredRenderer(cd_kernels.network, "tiled-half")


def test_plans_follow_the_limits():
    from gratnet.modelfile import texture_layout
    from viewer.tiled import plan_tiles

    layout = texture_layout([163, 108, 66, 40, 24, 3])  # act blocks max(41 + 27, …) = 68: 1088 bytes per pixel
    llvmpipe, nvidia = plan_tiles(layout, 32768), plan_tiles(layout, 49152)
    assert (llvmpipe.pixels, nvidia.pixels) == (20, 32)
    for plan in (llvmpipe, nvidia):
        assert plan.shared_bytes == plan.budget and plan.chunk_blocks(41, 27) >= 4
        assert plan.items * plan.group >= 27 * plan.pixels // 4
    assert plan_tiles(layout, 49152, half=True).pixels == 32  # halves: twice the weights staged
    with pytest.raises(GratNetError, match="at least 6080 bytes"):
        plan_tiles(layout, 4096)


def _pixel_pair_bound(scene: object, model: ModelFile, size: tuple[int, int], shade: np.ndarray) -> np.ndarray:
    """The kernel-pair bound of a deferred image ``shade`` (H, W, 4), per pixel and channel. Both kernels scale
    their XYZ by the same G-buffer factor f, so |tiled − shade| ≤ f·B(key) = B/XYZ_SHADE · |shade|, where
    XYZ_SHADE ≥ XYZ − D (D: gratnet.precision's bound of the SHADE kernel against numpy, which the kernel-level
    test holds). The keys: the forward path's key layer (the same surface.glsl code as the G-buffer pass)."""
    _, key_a = scene.render_layers(compact_disc(), DISC_CAMERA, DISC_LIGHT, size, 1.0)  # type: ignore[attr-defined]
    covered = key_a[..., 3] > 0
    bound = np.zeros(shade.shape[:2] + (3,))
    keys = key_a[..., :3][covered].astype(np.float64)
    if keys.size:
        xyz = driver_bound(model, keys[:, 0], keys[:, 1], keys[:, 2], OWN_KEYS)
        relative = kernel_pair_bound(model, keys) / np.maximum(xyz.xyz - xyz.bound, 1e-300)
        bound[covered] = relative * np.abs(shade[..., :3][covered])
    return bound


def test_renders_with_the_tiled_kernel_equal_the_per_entry_kernel(ctx):
    from viewer.scene import SceneRenderer

    model = random_model([163, 16, 8, 3], activation="silu", scheme="simple-max", seed=4)
    scenes = {weights: SceneRenderer(ctx, model, weights_path="texture", render_path="deferred",
                                     deferred_weights=weights) for weights in ("ssbo", "tiled")}
    try:
        base = plane(0.1)
        empty = Mesh(base.positions, base.normals, base.tangents, base.uvs, np.zeros((0, 3), dtype=np.uint32))
        assert np.all(scenes["tiled"].render_rgba(empty, DISC_CAMERA, DISC_LIGHT, (8, 6), 3.0) == 0.0)
        for size in ((1, 1), (2, 3), (7, 5), (33, 17)):
            tiled, shade = (scenes[name].render_rgba(compact_disc(), DISC_CAMERA, DISC_LIGHT, size, 3.0)
                            for name in ("tiled", "ssbo"))
            assert tiled.shape == (size[1], size[0], 4)
            np.testing.assert_array_equal(tiled[..., 3], shade[..., 3])
            np.testing.assert_array_equal(tiled[..., :3] == 0, shade[..., :3] == 0)
            assert_within(tiled[..., :3], shade[..., :3].astype(np.float64),
                          _pixel_pair_bound(scenes["ssbo"], model, size, shade), f"{size} image")
        assert np.count_nonzero(tiled[..., :3]) > 100  # the last image is mostly lit disc
    finally:
        for scene in scenes.values():
            scene.release()


def test_render_and_bench_take_the_tiled_kernel(ctx, tmp_path):
    from bench.devices import fp32_tmac_per_s
    from viewer.deferred import DEFERRED_WEIGHTS
    from viewer.scene_config import DEFERRED_WEIGHTS as FLAG_CHOICES

    assert FLAG_CHOICES == DEFERRED_WEIGHTS  # the flag's copy (scene_config defers moderngl)
    try:
        _render_and_bench(tmp_path)
    finally:
        # Each command made its own context and released it, leaving another one current: make the module's
        # context current again for the tests after this one (their programs live there).
        ctx.__enter__()
    assert fp32_tmac_per_s("NVIDIA H100 80GB HBM3/PCIe/SSE2") == pytest.approx(33.45)
    assert fp32_tmac_per_s("NVIDIA H100 PCIe/PCIe/SSE2") == pytest.approx(25.6)
    assert fp32_tmac_per_s("llvmpipe (LLVM 15.0.6, 256 bits)") is None
    with pytest.raises(GratNetError, match="--deferred-weights takes"):
        from bench.slices import BenchConfig

        BenchConfig(deferred_weights="tiled,fast").deferred_weights_list()


def _small_model_file(path: Path) -> Path:
    """A 28-12-8-3 net saved with a volume source (gratnet render's defaults aim the light by it)."""
    from gratnet.encoding import EncodingSpec
    from gratnet.modelfile import save_model

    model = random_model([EncodingSpec.for_grid(33, 5, frequencies=3, t_frequencies=2).features, 12, 8, 3],
                         scheme="simple-max", spec=EncodingSpec.for_grid(33, 5, frequencies=3, t_frequencies=2), seed=3)
    model.metadata = {"volume": {"source": "generator:sinusoidal(period_um=1.6667)"}}
    save_model(path, model)
    return path


def _render_and_bench(tmp_path: Path) -> None:
    import json

    from gratnet.cli import main

    model = _small_model_file(tmp_path / "tiny" / "model.npz")
    out = tmp_path / "disc.exr"
    assert main(["render", "--material", str(model), "--mesh", "cd", "--size", "9,7", "--weights-path", "texture",
                 "--render-path", "deferred", "--deferred-weights", "tiled", "--out", str(out)]) == 0
    config = json.loads((tmp_path / "disc.config.json").read_text())
    assert config["render"]["deferred_weights"] == "tiled"
    assert config["render_path"] == {"path": "deferred", "reason": "requested"}
    assert config["deferred_weights"] == "tiled"
    bench = tmp_path / "bench"
    assert main(["bench", str(model), "--out", str(bench), "--no-slices", "--scene-sizes", "12x12", "--spp", "1",
                 "--weights-paths", "texture", "--render-paths", "forward,deferred", "--deferred-weights",
                 "ssbo,tiled", "--repeats", "1", "--quiet"]) == 0
    rows = [json.loads(line) for line in (bench / "scenes.jsonl").read_text().splitlines()]
    assert [(row["render_path"], row["deferred_weights"]) for row in rows] == [
        ("forward", None), ("deferred", "ssbo"), ("deferred", "tiled")]
    assert rows[2]["tile_plan"].startswith("tile ") and rows[1]["tile_plan"] is None
    for row in rows:
        assert row["tmac_per_s"] > 0 and row["fp32_share"] is None  # llvmpipe: no FP32 figure
    table = (bench / "scenes.md").read_text()
    assert "| TMAC/s | of FP32 peak |" in table and "| tiled (" in table and " px, 64 inv., 32 KiB) |" in table


def test_the_plan_variable_overrides_tile_group_and_shared_memory(ctx, cd_kernels, monkeypatch):
    from viewer.deferred import DeferredRenderer
    from viewer.tiled import GL_MINIMUM_SHARED_BYTES, PLAN_VARIABLE, max_compute_shared_bytes

    assert max_compute_shared_bytes(ctx) >= GL_MINIMUM_SHARED_BYTES  # asked of the driver: 32768 on llvmpipe
    monkeypatch.setenv(PLAN_VARIABLE, "pixels=8, group=32, shared=16384")
    deferred = DeferredRenderer(cd_kernels.network, "tiled")
    try:
        plan = deferred.tile_plan
        assert (plan.pixels, plan.group, plan.budget) == (8, 32, 16384) and plan.shared_bytes <= 16384
        keys = _keys(29)
        assert_pair(deferred.shade_keys(keys), cd_kernels["ssbo"].shade_keys(keys),
                    kernel_pair_bound(cd_kernels.model, keys), "GRATNET_TILE_PLAN")
    finally:
        deferred.release()
    for bad in ("pixels=6", "tile=8", "shared=1000000", "group=4096"):
        monkeypatch.setenv(PLAN_VARIABLE, bad)
        with pytest.raises(GratNetError, match=PLAN_VARIABLE):
            DeferredRenderer(cd_kernels.network, "tiled")
