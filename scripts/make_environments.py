"""Regenerate the shipped environment maps, assets/environments/{sky,studio}.exr (issue 43; README.md there).

    .venv/bin/python scripts/make_environments.py                # writes both into assets/environments/
    .venv/bin/python scripts/make_environments.py --out /tmp/env --check   # and compares with the shipped bytes

- **sky.exr**: Mitsuba 3's ``sunsky`` emitter (Hosek–Wilkie sky and sun; the ``mitsuba`` extra, ``scalar_rgb``)
  evaluated at each texel's own direction (gratnet.environment.texel_coordinates), in its RGB units
  (W·m⁻²·sr⁻¹, linear sRGB). The sun (a 0.5358° disc, about half a texel) is integrated separately and its
  irradiance put into the one texel at its centre, as value / (that texel's bilinear footprint in sr), so the map
  carries the sun's energy exactly (the disc is placed on a texel centre). Below the horizon, where the model
  has no light, a Lambertian ground of the model's albedo lit by the sky and sun.
- **studio.exr**: three white rectangular softboxes (rectangles on planes facing the origin, anti-aliased by
  4 × 4 supersampling over each texel) on a dim grey background; relative units.

Both are float16 (HALF) EXRs of 512 × 256 texels with a ``gratnet_source`` attribute (the provenance line that
``load_environment`` reports), written atomically. The same Mitsuba version gives the same bytes (``--check``).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gratnet.atomic import atomic_path  # noqa: E402
from gratnet.environment import ENVIRONMENTS_FOLDER, Environment, texel_coordinates  # noqa: E402

HEIGHT, WIDTH = 256, 512

#: The sun's target elevation and azimuth (degrees; azimuth φ from +x towards +y): oblique on a CD in the xy
#: plane, off the default camera's plane (it looks along +y); snapped to the nearest texel centre.
SUN_ELEVATION_DEGREES, SUN_AZIMUTH_DEGREES = 40.0, 75.0
TURBIDITY, ALBEDO = 3.0, 0.3

#: Studio softboxes: (azimuth°, elevation°, half width°, half height°, linear sRGB radiance) and the background.
SOFTBOXES = ((120.0, 40.0, 25.0, 18.0, 1.0),   # key
             (240.0, 20.0, 20.0, 15.0, 0.35),  # fill
             (0.0, 55.0, 20.0, 12.0, 0.6))     # top / rim
BACKGROUND = 0.02


def _identity(values: np.ndarray) -> Environment:
    return Environment("generator", values)


def _texel_directions() -> np.ndarray:
    x, y = texel_coordinates(HEIGHT, WIDTH)
    return _identity(np.ones((HEIGHT, WIDTH, 3), np.float32)).directions(x, y)


def _tent_solid_angle(row: int) -> float:
    """∫ of texel ``row``'s bilinear hat over the sphere (sr): Δφ · sin θ · 2(1 − cos Δθ)/Δθ, exact."""
    d_phi, d_theta = 2.0 * math.pi / WIDTH, math.pi / (HEIGHT - 1)
    return d_phi * math.sin(math.pi * row / (HEIGHT - 1)) * 2.0 * (1.0 - math.cos(d_theta)) / d_theta


def _sun_texel() -> tuple[int, int]:
    row = round((90.0 - SUN_ELEVATION_DEGREES) / 180.0 * (HEIGHT - 1))
    x = ((90.0 - SUN_AZIMUTH_DEGREES) / 360.0) % 1.0  # φ = 90° − 360°·x (gratnet.environment)
    return int(row), int(round(x * WIDTH - 0.5)) % WIDTH


def sky() -> tuple[np.ndarray, str]:
    """The sunsky map and its provenance line."""
    import mitsuba as mi

    mi.set_variant("scalar_rgb")  # one lookup at a time: the same bytes wherever the same Mitsuba runs
    directions = _texel_directions()
    row, column = _sun_texel()
    sun = directions[row, column]

    def emitter(**extra: float) -> object:
        return mi.load_dict({"type": "sunsky", "sun_direction": [float(c) for c in sun], "turbidity": TURBIDITY,
                             "albedo": ALBEDO, **extra})

    def evaluate(source: object, towards: np.ndarray) -> np.ndarray:
        interaction = mi.SurfaceInteraction3f()
        result = np.empty((len(towards), 3))
        for index, direction in enumerate(towards):
            interaction.wi = mi.Vector3f(*(-direction))
            value = source.eval(interaction)  # type: ignore[attr-defined]
            result[index] = (value[0], value[1], value[2])
        return result

    values = np.zeros((HEIGHT, WIDTH, 3))
    upper = directions[..., 2] >= 0.0
    values[upper] = evaluate(emitter(sun_scale=0.0), directions[upper])

    # The sun alone, integrated over its disc on rings around its centre (midpoint rule in γ and ψ).
    aperture = math.radians(0.5358) / 2.0
    rings, spokes = 600, 48
    gamma = (np.arange(rings) + 0.5) * (1.2 * aperture / rings)
    psi = (np.arange(spokes) + 0.5) * (2.0 * math.pi / spokes)
    tangent = np.cross(sun, [0.0, 0.0, 1.0])
    tangent /= np.linalg.norm(tangent)
    bitangent = np.cross(sun, tangent)
    g, p = np.meshgrid(gamma, psi, indexing="ij")
    disc = (np.cos(g)[..., None] * sun + np.sin(g)[..., None] * (np.cos(p)[..., None] * tangent
                                                                 + np.sin(p)[..., None] * bitangent))
    weights = np.sin(g) * (1.2 * aperture / rings) * (2.0 * math.pi / spokes)
    sun_radiance = evaluate(emitter(sky_scale=0.0), disc.reshape(-1, 3))
    irradiance = np.sum(np.maximum(sun_radiance, 0.0) * weights.reshape(-1, 1), axis=0)  # W·m⁻², facing the sun
    values[row, column] += irradiance / _tent_solid_angle(row)

    # Ground: Lambertian, albedo ALBEDO, lit by the sky (tent quadrature of the map) and the sun.
    rows = np.arange(HEIGHT)
    cos_theta = np.cos(math.pi * rows / (HEIGHT - 1))
    sky_only = np.where(upper[..., None], values, 0.0)
    sky_only[row, column] -= irradiance / _tent_solid_angle(row)
    tents = np.array([_tent_solid_angle(r) for r in range(HEIGHT)])
    horizontal = np.einsum("rcj,r->j", sky_only, np.maximum(cos_theta, 0.0) * tents) + irradiance * sun[2]
    values[~upper] = ALBEDO / math.pi * horizontal

    elevation = 90.0 - 180.0 * row / (HEIGHT - 1)
    azimuth = (90.0 - 360.0 * (column + 0.5) / WIDTH) % 360.0
    rgb = ", ".join(f"{v:.4g}" for v in irradiance)
    source = (f"Mitsuba {mi.__version__} sunsky (Hosek-Wilkie sky and sun), turbidity {TURBIDITY:g}, albedo "
              f"{ALBEDO:g}, sun at elevation {elevation:.3f} deg, azimuth {azimuth:.3f} deg (from +x towards +y), "
              f"sun irradiance {rgb} (linear sRGB, W/m^2) in one texel; below the horizon a Lambertian ground of "
              "albedo 0.3; units as Mitsuba's RGB sunsky, W/(m^2 sr nm); scripts/make_environments.py")
    return values, source


def studio() -> tuple[np.ndarray, str]:
    """The softbox studio map and its provenance line."""
    samples = 4
    values = np.zeros((HEIGHT, WIDTH, 3))
    x, y = texel_coordinates(HEIGHT, WIDTH)
    frame = _identity(np.ones((HEIGHT, WIDTH, 3), np.float32))
    for a in range(samples):
        for b in range(samples):
            dx, dy = (a + 0.5) / samples - 0.5, (b + 0.5) / samples - 0.5
            sample_y = np.clip(y + dy / (HEIGHT - 1), 0.0, 1.0)
            directions = frame.directions(x + dx / WIDTH, sample_y)
            radiance = np.full(directions.shape[:2], BACKGROUND)
            for azimuth, elevation, half_width, half_height, level in SOFTBOXES:
                phi, theta = math.radians(azimuth), math.radians(90.0 - elevation)
                normal = np.array([math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), math.cos(theta)])
                across = np.array([-math.sin(phi), math.cos(phi), 0.0])
                up = np.cross(normal, across)
                facing = directions @ normal
                with np.errstate(divide="ignore", invalid="ignore"):
                    u, v = (directions @ across) / facing, (directions @ up) / facing
                inside = ((facing > 0.0) & (np.abs(u) <= math.tan(math.radians(half_width)))
                          & (np.abs(v) <= math.tan(math.radians(half_height))))
                radiance = np.where(inside, level, radiance)
            values += radiance[..., None] / samples**2
    boxes = "; ".join(f"azimuth {a:g}, elevation {e:g}, {2 * w:g}x{2 * h:g} deg, radiance {r:g}"
                      for a, e, w, h, r in SOFTBOXES)
    source = (f"procedural studio: white rectangular softboxes ({boxes}) on grey {BACKGROUND:g}, 4x4 supersampled; "
              "relative units; scripts/make_environments.py")
    return values, source


def write_map(path: Path, values: np.ndarray, source: str) -> None:
    """A float16 EXR (R, G, B), ZIP-compressed, with the ``gratnet_source`` attribute; atomic."""
    import OpenEXR

    half = values.astype(np.float16)
    if not np.all(np.isfinite(half)):
        raise SystemExit(f"{path.name}: a value does not fit float16 (max {np.max(values):g})")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage, "gratnet_source": source}
    with atomic_path(path) as temporary, OpenEXR.File(header, {"RGB": half}) as exr:
        exr.write(str(temporary))


def main(arguments: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=ENVIRONMENTS_FOLDER, help="folder (default: the shipped one)")
    parser.add_argument("--check", action="store_true", help="compare the written files with the shipped ones")
    options = parser.parse_args(arguments)
    options.out.mkdir(parents=True, exist_ok=True)
    differ = []
    for name, make in (("sky", sky), ("studio", studio)):
        values, source = make()
        target = options.out / f"{name}.exr"
        write_map(target, values, source)
        print(f"wrote {target}: {target.stat().st_size} bytes, {WIDTH}x{HEIGHT}, max {np.max(values):.4g}")
        shipped = ENVIRONMENTS_FOLDER / f"{name}.exr"
        if options.check and target.resolve() != shipped.resolve():
            same = shipped.is_file() and shipped.read_bytes() == target.read_bytes()
            print(f"  {'same bytes as' if same else 'DIFFERS from'} {shipped}")
            differ += [] if same else [name]
    return 1 if differ else 0


if __name__ == "__main__":
    raise SystemExit(main())
