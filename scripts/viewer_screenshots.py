"""Screenshots of the viewer window as a newcomer sees it: soon after launch (the quick texture path, the
status line about the faster shader compiling) and once the baked program has taken over.

    MESA_SHADER_CACHE_DIR=$(mktemp -d) xvfb-run -a -s "-screen 0 1280x800x24" \\
        python scripts/viewer_screenshots.py --out docs/images/viewer_first_look.png

Starts like ``gratnet view --material cd --mesh cd --size 480,400`` (its defaults included), captures the
window (glReadPixels) at ``--at`` seconds after the window opens, and writes the captures side by side.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from PIL import Image

from gratnet.atomic import atomic_path
from gratnet.cli import build_parser
from viewer.view_cli import starting_state
from viewer.window import ViewerWindow


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True, help="PNG of the captures side by side")
    parser.add_argument("--at", default="3,45", help="seconds after the window opens, comma-separated")
    parser.add_argument("--material", default="cd")
    parser.add_argument("--mesh", default="cd")
    arguments = parser.parse_args()
    times = sorted(float(value) for value in arguments.at.split(","))
    view = build_parser(only="view").parse_args(
        ["view", "--material", arguments.material, "--mesh", arguments.mesh, "--size", "480,400"])
    captures: list[np.ndarray] = []
    with ViewerWindow(starting_state(view), (480, 400)) as window:
        started = time.perf_counter()
        while len(captures) < len(times):
            window.frame(capture=True)
            elapsed = time.perf_counter() - started
            if elapsed >= times[len(captures)]:
                assert window.last_capture is not None  # the frame above captured
                captures.append(window.last_capture.copy())
                print(f"{elapsed:.1f} s: {window.app.status or 'no status'}", flush=True)
    gap = np.full((captures[0].shape[0], 8, 3), 255, np.uint8)
    sheet = np.concatenate([part for capture in captures for part in (capture, gap)][:-1], axis=1)
    with atomic_path(arguments.out) as temporary:
        Image.fromarray(sheet).save(temporary, format="PNG")
    print(f"wrote {arguments.out}")


if __name__ == "__main__":
    main()
