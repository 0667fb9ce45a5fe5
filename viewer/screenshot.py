"""What a viewer writes and what drives it: a screenshot with the ``gratnet render`` settings that reproduce it,
and a slider moved as a user drags it (tests and benchmarks drive the viewer through it).

No glfw, no imgui (a :class:`~viewer.window.ViewerWindow` passes for its app through :class:`HasApp`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from pathlib import Path
from typing import Protocol

from gratnet.errors import GratNetError
from viewer.app import ViewerApp
from viewer.state import SLIDERS

__all__ = ["HasApp", "drive_slider", "next_screenshot_path", "save_screenshot"]


def save_screenshot(app: ViewerApp, path: str | Path) -> Path:
    """Write ``app``'s current picture at full resolution as a display-sRGB PNG (atomically), and beside it
    ``NAME.config.json`` with the ``gratnet render`` settings that reproduce it. Returns the path."""
    from PIL import Image

    from gratnet.atomic import atomic_path
    from gratnet.config import save_config

    path = Path(path)
    if path.suffix.lower() != ".png":
        raise GratNetError(f"a screenshot is a .png file, got {path}")
    pixels = app.render_full()
    samples = app.samples
    accumulated = app.accumulated_xyz() if samples > 1 else None
    if accumulated is not None:  # the complete samples only (a sample being added band by band is left out)
        pixels = app.display_pixels(accumulated)
    with atomic_path(path) as temporary:
        Image.fromarray(pixels).save(temporary, format="PNG")
    width, height = app.full_size()
    config = app.state.render_config(width, height, samples)
    shading = app.state.shading if app.reference_available() else "network"
    if shading != "network" and app.reference is not None:  # gratnet render --reference draws the truth
        config = dataclasses.replace(config, reference=app.reference.loaded.path,
                                     reference_precision=app.reference.loaded.precision)
    model_file, quality = app.point()
    config = dataclasses.replace(config, quality=quality)
    save_config(path, render=config, model_file=str(model_file),
                view={"shading": shading, "flip_mean_covered": app.flip_mean})
    return path

def next_screenshot_path(folder: str | Path) -> Path:
    """``folder/gratnet-view-NNN.png``, the first number not taken."""
    folder = Path(folder)
    for number in range(1, 100000):
        candidate = folder / f"gratnet-view-{number:03d}.png"
        if not candidate.exists():
            return candidate
    raise GratNetError(f"no free screenshot name in {folder}")


class HasApp(Protocol):
    """A shell around a :class:`ViewerApp` (``viewer.window.ViewerWindow``)."""

    @property
    def app(self) -> ViewerApp: ...

    def frame(self) -> bool: ...


def drive_slider(target: ViewerApp | HasApp, name: str, values: Iterable[float], frame: bool = True) -> int:
    """Move slider ``name`` through ``values`` as a user dragging it would: set each value and, with
    ``frame``, run one frame after each (``target.frame()``: a window frame or an app step). Returns the
    number of values that changed the state."""
    app = target if isinstance(target, ViewerApp) else target.app
    if name not in SLIDERS:
        raise GratNetError(f"unknown slider {name!r}: choose {', '.join(SLIDERS)}")
    changed = 0
    for value in values:
        changed += bool(app.set(**{name: value}))
        if frame:
            target.frame()
    return changed
