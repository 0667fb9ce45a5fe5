"""Candidate designs for compiling the viewer's baked shader without blocking the window's thread.

    python docs/experiments/probes/compile_off_thread.py assets/blazed/model.npz

Each part uses its own empty Mesa shader cache (``MESA_SHADER_CACHE_DIR`` in a temporary folder) and
prints one JSON line:

- ``thread``: a thread makes its own headless context and compiles the baked ``surface`` program (link,
  then a 1×1 draw: llvmpipe JIT-compiles at the first draw) while the main thread ticks every 1 ms;
  ``main_thread_max_gap_s`` is the longest the main thread could not run (moderngl holds the GIL).
- ``child``: ``viewer.compile_worker`` compiles the same program in a child process (``child_s``), then
  a fresh process links and draws it (``after_link_s``, ``after_first_draw_s``): Mesa's disk-cache hit.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[3]
_FRESH = """
import sys, time, json
from gratnet.modelfile import load_model
from viewer.context import create_headless_context
from viewer.scene import SceneRenderer
from viewer.compile_worker import warm_group
ctx = create_headless_context()
scene = SceneRenderer(ctx, load_model(sys.argv[1]), weights_path="baked",
                      baked_source=open(sys.argv[2], encoding="utf-8").read())
t = time.perf_counter(); scene.program; scene.network.depth_only_program("surface"); link = time.perf_counter() - t
t = time.perf_counter(); warm_group(scene, "surface"); draw = time.perf_counter() - t
print(json.dumps({"after_link_s": link, "after_first_draw_s": draw}))
"""


def in_a_thread(model: str) -> dict[str, float]:
    from gratnet.modelfile import load_model
    from viewer.compile_worker import warm_group
    from viewer.context import create_headless_context
    from viewer.scene import SceneRenderer

    seconds: dict[str, float] = {}

    def work() -> None:
        ctx = create_headless_context()
        scene = SceneRenderer(ctx, load_model(model), weights_path="baked")
        started = time.perf_counter()
        warm_group(scene, "surface")
        seconds["thread_compile_s"] = time.perf_counter() - started

    thread = threading.Thread(target=work)
    thread.start()
    gap, last = 0.0, time.perf_counter()
    while thread.is_alive():
        time.sleep(0.001)
        now = time.perf_counter()
        gap, last = max(gap, now - last), now
    return {**seconds, "main_thread_max_gap_s": gap}


def in_a_child(model: str, environment: dict[str, str]) -> dict[str, float]:
    with tempfile.TemporaryDirectory() as folder:
        started = time.perf_counter()
        subprocess.run([sys.executable, "-m", "viewer.compile_worker", model, "--paths", "baked", "--groups",
                        "surface", "--folder", folder], env=environment, check=True, cwd=REPOSITORY,
                       stdout=subprocess.DEVNULL)
        child = time.perf_counter() - started
        result = subprocess.run([sys.executable, "-c", _FRESH, model, str(Path(folder) / "baked-mlp.glsl")],
                                env=environment, check=True, cwd=REPOSITORY, capture_output=True, text=True)
    return {"child_s": child, **json.loads(result.stdout)}


def main() -> int:
    model = str(Path(sys.argv[1]).resolve())
    if len(sys.argv) > 2 and sys.argv[2] == "--thread":  # run in a process of its own, with its own cache
        print(json.dumps({"part": "thread", **in_a_thread(model)}))
        return 0
    for part in ("thread", "child"):
        with tempfile.TemporaryDirectory() as cache:
            environment = {**os.environ, "MESA_SHADER_CACHE_DIR": cache}
            environment.pop("MESA_SHADER_CACHE_DISABLE", None)
            if part == "thread":
                subprocess.run([sys.executable, __file__, model, "--thread"], env=environment, check=True)
            else:
                print(json.dumps({"part": "child", **in_a_child(model, environment)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
