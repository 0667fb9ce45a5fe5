"""Where an environment render's noise comes from (docs/experiments/2026-11-27-environment-noise.md): paper-cd on the
CD at its default view under the shipped sky, the sky with its horizon band (θ > 75°) set to 0, and the sky with its
sun clipped to the 99.9th percentile; for each, FLIP of a 64-pass render (seed 1) against a 256-pass one (seed 2) at
the exposure the 256-pass picture calls for, 48².

    python docs/experiments/probes/environment_noise_sources.py
"""

import numpy as np

from gratnet.display import ldr_flip, xyz_to_display_srgb8
from gratnet.environment import Environment, load_environment, texel_coordinates
from gratnet.modelfile import load_model
from gratnet.showcase import suggest_exposure
from viewer.camera import Camera, Light
from viewer.catalog import build_mesh, resolve_material
from viewer.context import create_headless_context
from viewer.defaults import resolve_defaults
from viewer.scene import SceneRenderer

sky = load_environment("sky")
h, w = sky.shape
x, y = texel_coordinates(h, w)
theta = np.degrees(np.pi * y)
masked = sky.radiance_map.copy()
masked[theta > 75] = 0
nohor = Environment("sky-no-horizon", masked)
nosun = np.minimum(sky.radiance_map, np.percentile(sky.radiance_map, 99.9, axis=(0, 1)))
nosun_env = Environment("sky-no-sun", nosun)
d = resolve_defaults("paper-cd", "cd")
cam = Camera(d.camera_distance, d.camera_azimuth_degrees, d.camera_elevation_degrees)
ctx = create_headless_context()
sc = SceneRenderer(ctx, load_model(resolve_material("paper-cd")), render_path="forward")
mesh = sc.upload(build_mesh("cd"))
off = Light.directional(0, 0, 0.0)
for env in (sky, nohor, nosun_env):
    a = sc.render(mesh, cam, off, (48, 48), 1.0, 1.5, samples=64, environment=env, seed=1).astype(np.float64)
    b = sc.render(mesh, cam, off, (48, 48), 1.0, 1.5, samples=256, environment=env, seed=2).astype(np.float64)
    e = suggest_exposure(b, 1.0) or 1.0
    f, _ = ldr_flip(xyz_to_display_srgb8(b, e) / 255.0, xyz_to_display_srgb8(a, e) / 255.0)
    print(f"{env.name}: FLIP 64 vs 256 passes {f:.4f}, exposure {e:g}, brightest pixel / mean {a.max() / a.mean():.0f}")
