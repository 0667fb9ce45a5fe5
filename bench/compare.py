"""``gratnet compare``: a material's network against its ground truth where users look — rendered on meshes.

    gratnet compare paper-cd --reference paper-cd.exr --out out/compare-cd

Every figure GratNet reported before was measured on BRDF slices. This command renders the material twice per
view — the network, and the reference look-up of its ground-truth volume (:mod:`viewer.reference`: the same
rasterizer, key vectors, A-term, Fresnel, exposure and samples per pixel; only the material differs) — and scores
the pair with LDR-FLIP (``trainer.metrics``, display sRGB at FLIP's default 67 pixels per degree).

Views (:func:`views`): for each mesh, the default view ``gratnet render`` takes for the material (light, camera and
exposure of viewer.defaults) and two more that no default aims: the light turned 90° in azimuth about the normal,
and the camera 60° further round and 25° lower (light kept). Every view keeps the default's exposure.

Under ``--environment`` or ``--area-light`` (``gratnet render``'s flags: "error where users look", under real light;
area lights the same in every view) both renders are
lit by it (the light off unless ``--light-intensity``), each view's environment aimed at its light as ``gratnet
render`` aims it (or turned by ``--environment-rotation``, and 90° more for the light-turned view), and each view's
exposure comes from the reference's picture (gratnet.showcase.suggest_exposure); ``--spp`` is then also the number
of light samples, the same passes and seed for both renders.

``--quality fast|accurate`` chooses which of a shipped material's points is scored (gratnet.quality; default: the
accurate one); the views are the material's either way (worked out from its accurate point), so the two points are
scored on the same scenes. compare.config.json records the point (``compare.quality``) and its ``model_file``.

The mean FLIP is over the pixels the mesh covers (in the reference render); over the whole frame it would count
the black background as agreement. Writes OUT/compare.md (the table), OUT/compare.json (every figure and the views),
OUT/compare.png (reference | network | FLIP per view) and OUT/compare.config.json, together (nothing half-written).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from gratnet.config import add_arguments, add_quiet_flag, config_field, from_arguments
from gratnet.errors import GratNetError
from gratnet.quality import QUALITIES, QUALITY_HELP
from viewer.defaults import SceneDefaults
from viewer.scene_config import MAX_SAMPLES, LightingConfig, check_lighting, lighting_help, quality_help

__all__ = ["CompareConfig", "View", "register", "run", "views"]

#: The extra views' changes (degrees): the light's azimuth turn, then the camera's azimuth turn and elevation drop.
LIGHT_TURN_DEGREES = 90.0
CAMERA_TURN_DEGREES = 60.0
CAMERA_DROP_DEGREES = 25.0
_MIN_ELEVATION_DEGREES = 10.0


@dataclasses.dataclass
class CompareConfig(LightingConfig):
    """Network against reference renders on meshes (under the views' directional light, or an environment)."""

    reference: str = config_field("", "the material's ground-truth volume (gratnet groundtruth's EXR; the "
                                  "material's own surface and σs, checked)")
    meshes: str = config_field("cd,sphere,plane", "meshes, comma-separated: cd, sphere, plane or .obj files")
    width: int = config_field(384, "image width, pixels")
    height: int = config_field(384, "image height, pixels")
    spp: int = config_field(4, f"samples per pixel of both renders (anti-aliasing and, under --environment, light "
                            f"samples; 1 … {MAX_SAMPLES})")
    reference_precision: str = config_field("float16", "storage of the reference texture: float16 or float32",
                                            choices=("float16", "float32"))
    weights_path: str = config_field("auto", "where the network's shader reads its weights: texture, baked or auto "
                                     "(as gratnet render)", choices=("auto", "texture", "baked"))
    # None when not given (the accurate point); in the saved config the point scored (None for a model file).
    quality: str | None = config_field(None, QUALITY_HELP, choices=QUALITIES)


@dataclasses.dataclass(frozen=True)
class View(SceneDefaults):
    """One scene: a mesh and a directional light, orbit camera and exposure (:class:`~viewer.defaults.SceneDefaults`,
    the flags' units), named for the table."""

    mesh: str = "cd"
    name: str = "default"


def views(material: str, mesh: str) -> list[View]:
    """The default view of ``material`` on ``mesh`` and the two further views (module docstring)."""
    from viewer.defaults import resolve_defaults

    d = resolve_defaults(material, mesh)
    base = View(**dataclasses.asdict(d), mesh=mesh, name="default")
    turned = dataclasses.replace(base, name=f"light φ{LIGHT_TURN_DEGREES:+g}°",
                                 light_phi_degrees=d.light_phi_degrees + LIGHT_TURN_DEGREES)
    camera = dataclasses.replace(
        base, name=f"camera {CAMERA_TURN_DEGREES:+g}°, {-CAMERA_DROP_DEGREES:+g}°",
        camera_azimuth_degrees=d.camera_azimuth_degrees + CAMERA_TURN_DEGREES,
        camera_elevation_degrees=max(_MIN_ELEVATION_DEGREES, d.camera_elevation_degrees - CAMERA_DROP_DEGREES))
    return [base, turned, camera]


def _view_environment(config: CompareConfig, view: View) -> Any:
    """The environment of ``view`` (None without one), aimed at the view's light unless ``--environment-rotation``
    is given (then the light-turned view turns it by the same angle as its light)."""
    from viewer.scene_config import environment_of, environment_rotation

    if not config.has_environment:
        return None
    if config.environment_rotation is None:
        rotation = environment_rotation(config, view.light_phi_degrees)
    else:
        rotation = config.environment_rotation + (LIGHT_TURN_DEGREES if view.name.startswith("light") else 0.0)
    return environment_of(dataclasses.replace(config, environment_rotation=rotation))


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``compare`` subcommand."""
    parser = subparsers.add_parser(
        "compare", help="score a material's network against its ground-truth volume on meshes (FLIP, table + picture)",
        description="Render a material on meshes twice per view — the network, and its ground-truth volume looked "
        "up per pixel (gratnet render --reference) — at the default view and two more per mesh, and score each "
        "pair with LDR-FLIP over the covered pixels.",
        epilog="typical use:\n  gratnet groundtruth paper-cd --sampling simple-max --out paper-cd.exr\n"
        "  gratnet compare paper-cd --reference paper-cd.exr --out out/compare-cd",
    )
    parser.add_argument("material", metavar="MATERIAL", help="shipped material name or model-file path")
    parser.add_argument("--out", required=True, metavar="DIR",
                        help="output folder (compare.md, compare.json, compare.png)")
    add_quiet_flag(parser)
    actions = add_arguments(parser, CompareConfig)
    lighting_help(actions)
    quality_help(actions)
    parser.set_defaults(handler=run)


def _check(config: CompareConfig, material: str) -> tuple[Path, CompareConfig, list[str]]:
    """The flags checked before any reading or rendering: sizes, samples, precision, meshes; the material's model
    file at its ``--quality`` point, and the config with the point resolved."""
    from gratnet.reference import check_precision
    from viewer.catalog import check_mesh_spec, material_point
    from viewer.surface import check_size

    if not config.reference:
        raise GratNetError("--reference VOLUME.exr is required: the material's ground-truth volume")
    check_size((config.width, config.height))
    if isinstance(config.spp, bool) or not 1 <= config.spp <= MAX_SAMPLES:
        raise GratNetError(f"--spp must be an integer in 1 … {MAX_SAMPLES}, got {config.spp}")
    check_lighting(config)
    check_precision(config.reference_precision)
    meshes = [part.strip() for part in config.meshes.split(",") if part.strip()]
    if not meshes:
        raise GratNetError("--meshes names no mesh")
    for mesh in meshes:
        check_mesh_spec(mesh)
    model_path, quality = material_point(material, config.quality)
    return model_path, dataclasses.replace(config, quality=quality), meshes


def run(arguments: argparse.Namespace) -> int:
    """Check every input, render every view twice, score, write the table, the figures and the picture together."""
    from tqdm import tqdm

    from gratnet.atomic import check_output_folder
    from gratnet.modelfile import load_model
    from gratnet.showcase import suggest_exposure
    from trainer.metrics import show_pair
    from viewer.camera import Camera, Light
    from viewer.catalog import build_mesh
    from viewer.context import create_headless_context
    from viewer.scene import SceneRenderer
    from viewer.scene_config import load_reference

    config = from_arguments(CompareConfig, arguments)
    model_path, config, meshes = _check(config, arguments.material)
    out = check_output_folder(arguments.out)
    volume = load_reference(config.reference, config.reference_precision, arguments.material)
    scenes = [view for mesh in meshes for view in views(arguments.material, mesh)]
    model = load_model(model_path)
    rows: list[dict[str, Any]] = []
    panels = []
    size = (config.width, config.height)
    area_lights = config.area_lights  # the same lights in every view (world space)
    ctx = create_headless_context()
    try:
        with (SceneRenderer(ctx, model, weights_path=config.weights_path, render_path="forward") as network,
              SceneRenderer(ctx, volume, reference_precision=config.reference_precision) as reference):
            for view in tqdm(scenes, desc="compare", unit="view", disable=arguments.quiet, file=sys.stderr):
                mesh = build_mesh(view.mesh)
                camera = Camera(view.camera_distance, view.camera_azimuth_degrees, view.camera_elevation_degrees)
                light = Light.directional(view.light_theta_degrees, view.light_phi_degrees,
                                          config.effective_light_intensity)
                lit = _view_environment(config, view)
                sampled = lit is not None or bool(area_lights)
                exposure = 1.0 if sampled else view.exposure  # under sampled light: from the picture
                truth, guess = (scene.render_rgba(mesh, camera, light, size, exposure, 1.5, samples=config.spp,
                                                  environment=lit, seed=config.seed, area_lights=area_lights)
                                for scene in (reference, network))
                if sampled:
                    exposure = suggest_exposure(truth[..., :3], 1.0) or 1.0
                    truth, guess = (np.concatenate([image[..., :3] * exposure, image[..., 3:]], axis=-1)
                                    for image in (truth, guess))
                    view = dataclasses.replace(view, exposure=exposure)
                shown = show_pair(truth[..., :3], guess[..., :3])
                covered = truth[..., 3] > 0.0
                rows.append({**dataclasses.asdict(view),
                             "flip_covered": float(shown.flip_map[covered].mean()) if covered.any() else 0.0,
                             "flip_frame": shown.mean_flip, "covered_fraction": float(covered.mean())})
                panels.append((view, shown, rows[-1]["flip_covered"]))
    finally:
        ctx.release()
    _write(out, arguments.material, config, rows, panels, model_path, volume.metadata)
    print(f"wrote {out / 'compare.md'}, {out / 'compare.json'}, {out / 'compare.png'}: mean FLIP (covered pixels) "
          f"{np.mean([row['flip_covered'] for row in rows]):.4f} over {len(rows)} views")
    return 0


def table(material: str, rows: list[dict[str, Any]]) -> str:
    """The Markdown table of one material's views."""
    lines = [f"| {material}: mesh | view | light θ, φ (°) | camera dist (m), az, el (°) | exposure | FLIP (covered) "
             "| FLIP (frame) |", "|---|---|---|---|---|---|---|"]
    for row in rows:
        lines.append(f"| {row['mesh']} | {row['name']} | {row['light_theta_degrees']:g}, {row['light_phi_degrees']:g} "
                     f"| {row['camera_distance']:g}, {row['camera_azimuth_degrees']:g}, "
                     f"{row['camera_elevation_degrees']:g} | {row['exposure']:g} | {row['flip_covered']:.4f} "
                     f"| {row['flip_frame']:.4f} |")
    mean = np.mean([row["flip_covered"] for row in rows])
    lines.append(f"| **mean** | | | | | **{mean:.4f}** | |")
    return "\n".join(lines) + "\n"


def _write(out: Path, material: str, config: CompareConfig, rows: list[dict[str, Any]], panels: list[Any],
           model_path: Path, volume_metadata: dict[str, Any]) -> None:
    """compare.md, compare.json, compare.png and compare.config.json, landing together."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from gratnet.atomic import atomic_paths
    from gratnet.config import config_text

    figure, axes = plt.subplots(len(panels), 3, figsize=(9.0, 3.0 * len(panels) + 0.4), squeeze=False,
                                layout="constrained")
    for row_axes, (view, shown, flip) in zip(axes, panels, strict=True):
        row_axes[0].imshow(shown.reference_srgb)
        row_axes[0].set_title(f"reference: {view.mesh}, {view.name}", fontsize=8)
        row_axes[1].imshow(shown.test_srgb)
        row_axes[1].set_title("network", fontsize=8)
        heat = row_axes[2].imshow(shown.flip_map, cmap="magma", vmin=0.0, vmax=1.0)
        row_axes[2].set_title(f"FLIP, mean {flip:.4f} (covered)", fontsize=8)
        for axis in row_axes:
            axis.set_axis_off()
    figure.colorbar(heat, ax=axes[:, 2].tolist(), shrink=0.3, label="LDR-FLIP")
    label = material if config.quality is None else f"{material} ({config.quality})"  # a shipped point is named
    figure.suptitle(f"{label}: ground-truth volume (reference) against the network", fontsize=10)
    documents = {"compare": config, "material": material, "model_file": str(model_path),
                 "reference_source": volume_metadata.get("source")}
    out.mkdir(parents=True, exist_ok=True)
    with atomic_paths(out / "compare.md", out / "compare.json", out / "compare.png",
                      out / "compare.config.json") as (markdown, figures, picture, settings):
        markdown.write_text(table(material, rows), encoding="utf-8")
        summary = {"material": material, "quality": config.quality,
                   "volume": f"{volume_metadata.get('resolution')}² × {volume_metadata.get('slices')} "
                             f"{volume_metadata.get('scheme')}, {config.reference_precision}",
                   "image": f"{config.width}×{config.height}, {config.spp} spp", "views": rows}
        figures.write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
        figure.savefig(picture, format="png", dpi=80)
        settings.write_text(config_text(out / "compare.json", **documents), encoding="utf-8")
    plt.close(figure)
