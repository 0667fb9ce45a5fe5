"""The exported web page's speed in headless chromium: time to its first picture and its frame time, per backend.

    python benchmarks/web_page.py [MATERIAL ...] [--size 512] [--backends llvmpipe,swiftshader] [--redraws 3]
                                  [--screenshot docs/images/export_web_page.png] [--json OUT.json]

Exports the materials (default: paper-cd) with ``gratnet export --format web``, serves the folder on 127.0.0.1 and
opens ``index.html?material=NAME&size=S,S`` in Debian's chromium (Playwright, no browser download) once per
WebGL2 backend (docs/export.md; shared/notes/browsers-and-shader-tools-here.md): ``first_picture_s`` from the
navigation to ``window.gratnetReady`` (shader compile, downloads and the first frame), ``first_frame_ms`` that
first frame as the page measures it (to a 1-pixel read-back), and ``frame_ms`` the median of ``--redraws`` later
frames, each triggered by an exposure change (the page redraws on any input). One JSON line per material and
backend; ``--screenshot`` saves the llvmpipe page of the first material with its panel (the README's picture).
CPU rasterizers follow the machine's load: say what else ran.
"""

from __future__ import annotations

import argparse
import functools
import http.server
import json
import os
import re
import shutil
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from export.web import CHROMIUM_BACKENDS
from gratnet.atomic import atomic_path, write_text_atomic
from gratnet.cli import main as gratnet_main

#: chromium's flags per WebGL2 backend (the ones the page's tests use).
BACKENDS = CHROMIUM_BACKENDS


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, format: str, *args: object) -> None:  # noqa: A002 - the base class's name
        pass


def measure(page: Any, url: str, redraws: int) -> dict[str, Any]:
    """First picture (s), the page's first frame (ms) and the median of ``redraws`` later frames (ms)."""
    started = time.monotonic()
    page.goto(url)
    page.wait_for_function("window.gratnetReady === true || window.gratnetError !== undefined", timeout=600_000)
    first_picture = time.monotonic() - started
    error = page.evaluate("window.gratnetError")
    if error:
        raise RuntimeError(f"the page reported: {error}")
    frames = []
    for index in range(redraws):
        before = page.evaluate("document.getElementById('frame-time').textContent")
        page.evaluate("(v) => { const e = document.getElementById('exposure'); e.value = String(Number(e.value) + v);"
                      " e.dispatchEvent(new Event('input')); }", 0.01 * (1 if index % 2 == 0 else -1))
        page.wait_for_function(f"document.getElementById('frame-time').textContent !== {json.dumps(before)}",
                               timeout=600_000)
        text = page.evaluate("document.getElementById('frame-time').textContent")
        match = re.search(r"frame: ([0-9.]+) ms", text)
        if match:
            frames.append(float(match.group(1)))
    return {"first_picture_s": round(first_picture, 3), "first_frame_ms": page.evaluate("window.gratnetFrameMs"),
            "frame_ms": statistics.median(frames) if frames else None, "frames_ms": frames}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("materials", nargs="*", default=["paper-cd"], metavar="MATERIAL")
    parser.add_argument("--size", type=int, default=512, help="canvas width and height (pixels)")
    parser.add_argument("--backends", default="llvmpipe,swiftshader", help=f"comma-separated: {', '.join(BACKENDS)}")
    parser.add_argument("--redraws", type=int, default=3)
    parser.add_argument("--screenshot", type=Path, help="save the first material's llvmpipe page here (PNG)")
    parser.add_argument("--json", type=Path, help="write the rows here too")
    arguments = parser.parse_args(argv)
    backends = [name.strip() for name in arguments.backends.split(",") if name.strip()]
    unknown = [name for name in backends if name not in BACKENDS]
    chromium = shutil.which("chromium")
    if unknown or chromium is None or not 16 <= arguments.size <= 4096 or arguments.redraws < 1:
        print("web_page: " + (f"unknown backend {unknown[0]!r}" if unknown else "no chromium on PATH (scripts/setup.sh)"
                              if chromium is None else "--size must be 16 … 4096 and --redraws ≥ 1"), file=sys.stderr)
        return 2
    import playwright.sync_api as playwright_api

    rows = []
    with tempfile.TemporaryDirectory(prefix="gratnet-web-") as folder:
        site = Path(folder) / "site"
        if gratnet_main(["export", *arguments.materials, "--format", "web", "--out", str(site), "--quiet"]) != 0:
            return 2
        server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_Quiet, directory=str(site)))
        threading.Thread(target=server.serve_forever, daemon=True).start()
        home = Path(folder) / "home"
        environment: dict[str, str | float | bool] = {
            **os.environ, "HOME": str(home), "XDG_CONFIG_HOME": str(home / "config"),
            "XDG_CACHE_HOME": str(home / "cache")}
        try:
            with playwright_api.sync_playwright() as playwright:
                for backend in backends:
                    browser = playwright.chromium.launch(executable_path=chromium, headless=True,
                                                         args=BACKENDS[backend], env=environment)
                    try:
                        for material in arguments.materials:
                            page = browser.new_page(viewport={"width": arguments.size + 300,
                                                              "height": arguments.size + 20})
                            url = (f"http://127.0.0.1:{server.server_port}/index.html?material={material}"
                                   f"&size={arguments.size},{arguments.size}")
                            row = {"material": material, "backend": backend, "size": arguments.size,
                                   "load_average_before": [round(v, 2) for v in os.getloadavg()],
                                   **measure(page, url, arguments.redraws)}
                            if arguments.screenshot and backend == "llvmpipe" and material == arguments.materials[0]:
                                with atomic_path(arguments.screenshot) as temporary:  # keeps the suffix
                                    page.screenshot(path=str(temporary))
                            page.close()
                            rows.append(row)
                            print(json.dumps(row), flush=True)
                    finally:
                        browser.close()
        finally:
            server.shutdown()
            server.server_close()
    if arguments.json:
        write_text_atomic(arguments.json, json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
