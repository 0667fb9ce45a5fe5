"""Shader programs compiled off the viewer's thread: a child process warms Mesa's disk shader cache.

The viewer never compiles a program it has not seen compiled already. :class:`CompileWorker` starts
``python -m viewer.compile_worker MODEL --paths texture,baked --groups surface,slice``: the child makes its
own headless EGL context, builds a :class:`~viewer.scene.SceneRenderer` per weights path and draws each
program group once at 1×1 pixel with exactly the draws the viewer makes (:func:`warm_group`). Mesa keeps
the linked programs and llvmpipe's JIT-compiled draw code in its disk shader cache (``MESA_SHADER_CACHE_DIR``
or ``~/.cache/mesa_shader_cache``; the child inherits the window's environment, hence its cache), so the
window's own compile of the same program text afterwards is a cache hit. The child prints one line per
group, ``ready PATH GROUP SECONDS``, as soon as it is warm; the window polls those lines without blocking.
The baked ``mlp.glsl`` text the child generated is written to a file that the window reads back
(:attr:`CompileWorker.baked_source`): the same text, so the same cache key, without generating it again.

Why a child process and not a thread (measured on Mesa 22.3 llvmpipe, 2 cores; docs/benchmarks.md
"Viewer: a window that never blocks"): moderngl holds the GIL through glLinkProgram and the draw that
JIT-compiles the program (its extension never releases the GIL), so a baked compile in a thread stopped
the main thread for 25.5 s. In the child the same compile takes 4 s (link) + 21–27 s (first draw), and
the window's compile afterwards takes 0.1 s (link) + tens of ms (first draw).

Groups: ``surface`` (the ``surface`` program and its depth pre-pass program, drawn as
:meth:`SceneRenderer.render` draws them), ``slice`` (``brdf_slice``) and, for ``gratnet view --environment``,
``environment`` (the ``surface`` program's ``ENVIRONMENT`` variant on the window's render path, drawn with the
viewer's environment and the flat importance table). After the first path's groups the child builds the material's
importance table, which gratnet.importance caches on disk, and reports ``ready PATH importance SECONDS``: the
window samples with the flat table until then and loads the material's own in milliseconds afterwards, instead of
building it for seconds. Rendering only: no glfw, no
imgui.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from gratnet.errors import GratNetError

__all__ = ["ENVIRONMENT_GROUP", "GROUPS", "IMPORTANCE", "CompileWorker", "shader_cache_enabled", "warm_group"]

#: Program groups, each warmed and reported as one (a viewer without an environment warms these).
GROUPS = ("surface", "slice")
#: The group of the surface program's environment-light variant (gratnet view --environment).
ENVIRONMENT_GROUP = "environment"
#: Not a program group: reported (``ready PATH importance SECONDS``) once the material's importance table is in the
#: disk cache, built after the first path's groups when the environment group is among them.
IMPORTANCE = "importance"
_ALL_GROUPS = (*GROUPS, ENVIRONMENT_GROUP)
#: Niceness the child adds before the long (baked) compiles: on a 2-core machine the window's thread
#: then wins the CPU whenever both want it.
_BAKED_NICENESS = 10
_BAKED_SOURCE = "baked-mlp.glsl"
_REPOSITORY = Path(__file__).resolve().parents[1]


def shader_cache_enabled(environment: Mapping[str, str] | None = None) -> bool:
    """Whether Mesa's disk shader cache is on (``MESA_SHADER_CACHE_DISABLE`` / ``MESA_GLSL_CACHE_DISABLE``
    unset or false): without it a child's compile cannot spare the window its own."""
    variables = os.environ if environment is None else environment
    for name in ("MESA_SHADER_CACHE_DISABLE", "MESA_GLSL_CACHE_DISABLE"):
        if variables.get(name, "").strip().lower() in ("1", "true", "yes", "y"):
            return False
    return True


def window_render_path(requested: str, software: bool) -> str:
    """The render path the viewer's window takes (and so the one to warm for it). ``auto`` is deferred on a
    software rasterizer: Mesa llvmpipe runs a fragment shader on whole 4×4 pixel blocks per triangle, so on the
    forward path the network ran 5–10 times per covered pixel of the viewer's small previews and thin disc
    triangles (paper-cd, 32²: 210 ms forward against 22 ms deferred, whose compute pass runs it once per
    covered pixel; issue 35). Its programs are warmed by the compile child like the forward ones (the 0.3–0.6 s
    of JIT work once seen in a frame after a switch are the child's now). On a GPU ``auto`` is the cached,
    measured verdict. An explicit path is kept."""
    return "deferred" if requested == "auto" and software else requested


def warm_group(scene: Any, group: str, buffers: Any = None, environment: Any = None) -> None:
    """Compile ``group``'s programs on ``scene`` (a :class:`~viewer.scene.SceneRenderer`) and draw them once
    at 1×1 pixel, as the viewer draws them (llvmpipe compiles a program's draw code at its first draw).
    ``buffers``: an uploaded mesh for the surface draw (default: a plane, uploaded and freed here).
    ``environment``: the :class:`gratnet.environment.Environment` of the ``environment`` group's draws (default:
    a constant one: every map has the same texture formats, hence the same draw code)."""
    from viewer.camera import Camera, Light

    if group == "slice":
        scene.render_brdf_slice(20.0, 90.0, 1, 1.0, 1.5)
    elif group in ("surface", ENVIRONMENT_GROUP):
        if group == ENVIRONMENT_GROUP and environment is None:
            from gratnet.environment import load_environment

            environment = load_environment("1")
        uploaded = buffers
        if uploaded is None:
            from viewer.meshes import plane

            uploaded = scene.upload(plane())
        try:
            # Twice: on the deferred path the first render at a size above 1×1 still cost 0.35 s of JIT work
            # (measured, tiny net on llvmpipe) when only a 1×1 render had warmed it; a 2×2 one takes it.
            lit = group == ENVIRONMENT_GROUP
            for size in ((1, 1), (2, 2)):  # sampled light on the scene's own path, as the window renders it
                scene.render_rgba(uploaded, Camera(0.18, -90.0, 50.0), Light.directional(20.0, 90.0), size, 1.0, 1.5,
                                  environment=environment if lit else None,
                                  render_path=scene.render_path if lit else None)
        finally:
            if buffers is None:
                uploaded.release()
    else:
        raise GratNetError(f"unknown program group {group!r}: choose {', '.join(_ALL_GROUPS)}")
    scene.ctx.finish()


class CompileWorker:
    """The parent's handle on one child process that warms the programs of one model (see the module
    docstring). Never blocks: :meth:`poll` reads what the child has reported so far.

    Args:
        model_path: the model file (``.npz``).
        paths: weights paths to warm, in order (e.g. ``("texture", "baked")``: the quick one first); ``auto``
            is resolved by the child on its own context (:func:`viewer.renderer.choose_weights_path`), so the
            child can start before the window has a context.
        groups: program groups to warm for each path, in order (the one on show first).
        label: how status lines name the model.
        niceness: added to the child's niceness at its start (the baked compiles add ``_BAKED_NICENESS``
            more): a child started while the window is on screen yields the CPU to it.
        environment: the environment spec the ``environment`` group is drawn with (default: a constant one).
    """

    def __init__(self, model_path: str | os.PathLike[str], paths: Sequence[str], groups: Sequence[str],
                 label: str = "", niceness: int = 0, render_path: str = "auto",
                 environment: str | None = None) -> None:
        self.model_path = Path(model_path)
        self.paths = tuple(paths)
        self.groups = tuple(groups)
        self.label = label or self.model_path.stem
        self.started = time.perf_counter()
        #: ``(path, group)`` pairs the child has warmed (cache hits for the window from now on).
        self.ready: set[tuple[str, str]] = set()
        #: Seconds the child took per ``(path, group)``.
        self.seconds: dict[tuple[str, str], float] = {}
        #: ``time.perf_counter()`` when the window read each report.
        self.ready_at: dict[tuple[str, str], float] = {}
        #: The child's failure (its last stderr line), once it exited with an error.
        self.error: str | None = None
        self._folder = tempfile.TemporaryDirectory(prefix="gratnet-compile-")
        self._stderr = open(Path(self._folder.name) / "stderr.txt", "w+b")  # noqa: SIM115 - closed in close()
        self._buffer = b""
        self._exited = False
        self._baked_source: str | None = None
        variables = dict(os.environ)
        variables["PYTHONPATH"] = os.pathsep.join(
            [str(_REPOSITORY), *filter(None, variables.get("PYTHONPATH", "").split(os.pathsep))])
        command = [sys.executable, "-m", "viewer.compile_worker", str(self.model_path), "--paths", ",".join(self.paths),
                   "--groups", ",".join(self.groups), "--folder", self._folder.name, "--nice", str(int(niceness)),
                   "--render-path", render_path]
        if environment is not None:
            command += ["--environment", environment]
        self._process: subprocess.Popen[bytes] | None = subprocess.Popen(
            command, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=self._stderr, env=variables,
            cwd=str(_REPOSITORY))
        assert self._process.stdout is not None
        os.set_blocking(self._process.stdout.fileno(), False)

    @property
    def running(self) -> bool:
        return self._process is not None and self._process.poll() is None

    @property
    def finished(self) -> bool:
        """The child is done (its reports read), or failed."""
        return self.error is not None or self._exited

    def elapsed(self) -> float:
        """Seconds since the child was started."""
        return time.perf_counter() - self.started

    def poll(self) -> set[tuple[str, str]]:
        """Read the child's reports without waiting; returns the pairs that became ready now."""
        process = self._process
        if process is None:
            return set()
        new: set[tuple[str, str]] = set()
        assert process.stdout is not None
        with contextlib.suppress(BlockingIOError):
            chunk = process.stdout.read()
            if chunk:
                self._buffer += chunk
        *lines, self._buffer = self._buffer.split(b"\n")
        for line in lines:
            words = line.decode(errors="replace").split()
            if len(words) == 4 and words[0] == "ready":
                pair = (words[1], words[2])
                self.ready.add(pair)
                self.seconds[pair] = float(words[3])
                self.ready_at[pair] = time.perf_counter()
                new.add(pair)
        code = process.poll()
        if code is not None and not self.finished:
            with contextlib.suppress(BlockingIOError):
                rest = process.stdout.read()
                if rest:  # reports written just before the exit: read at the next poll
                    self._buffer += rest
                    return new
            self._exited = True
            if code != 0:
                self._stderr.seek(0)
                errors = [text for text in self._stderr.read().decode(errors="replace").splitlines() if text.strip()]
                self.error = errors[-1].strip() if errors else f"exited with status {code}"
        return new

    @property
    def baked_source(self) -> str | None:
        """The baked ``mlp.glsl`` the child generated (``None`` until it wrote it)."""
        if self._baked_source is None:
            path = Path(self._folder.name) / _BAKED_SOURCE
            if path.is_file():
                self._baked_source = path.read_text(encoding="utf-8")
        return self._baked_source

    def close(self) -> None:
        """Stop the child (if still running) and remove its files."""
        process, self._process = self._process, None
        if process is not None:
            if process.poll() is None:
                process.kill()
            process.wait()
            if process.stdout is not None:
                process.stdout.close()
        if not self._stderr.closed:
            self._stderr.close()
        self._folder.cleanup()

    def __del__(self) -> None:
        with contextlib.suppress(Exception):
            self.close()


def _warm(model_path: Path, paths: Sequence[str], groups: Sequence[str], folder: Path,
          render_path: str = "auto", environment_spec: str | None = None) -> None:
    """The child: warm every group of every path, reporting each on stdout once it is on disk; then, for
    ``render_path`` ``auto`` on a GPU with no cached verdict, time the two render paths (viewer.deferred) so
    that the window (which never measures) finds the verdict from its next material or start on."""
    from gratnet.atomic import atomic_path
    from gratnet.modelfile import load_model
    from viewer.context import create_headless_context, release_headless_context
    from viewer.renderer import choose_weights_path, is_software_rasterizer
    from viewer.scene import SceneRenderer

    model = load_model(model_path)
    environment = None  # read before the environment group's first draw (not before the quick surface group)
    ctx = None
    done: set[str] = set()
    software = False
    yielded = False  # the environment group lowered the child's priority
    table_built = False
    for requested in paths:
        ctx = ctx or create_headless_context()
        software = is_software_rasterizer(ctx)
        path = choose_weights_path(ctx, model, requested)
        if path in done:
            continue
        done.add(path)
        source = None
        for group in groups:
            started = time.perf_counter()
            ctx = ctx or create_headless_context()
            scene = SceneRenderer(ctx, model, weights_path=path, baked_source=source,
                                  render_path=window_render_path(render_path, software),
                                  measure_render_path=False)
            if source is None and scene.network is not None and scene.network.baked_source is not None:
                source = scene.network.baked_source
                with atomic_path(folder / _BAKED_SOURCE) as temporary:
                    Path(temporary).write_text(source, encoding="utf-8")
                with contextlib.suppress(OSError):
                    os.nice(_BAKED_NICENESS)
            if group == ENVIRONMENT_GROUP:
                if not yielded:  # the window is up by now: its first picture waits on a default-view worker at +5,
                    yielded = True  # which the table's seconds of numpy starved by 2.5 s at niceness 0 (measured)
                    with contextlib.suppress(OSError):
                        os.nice(_BAKED_NICENESS)
                # Drawn with the flat table, as the window's first passes are: the material's own table (seconds of
                # numpy) is built after this group is reported, so the environment's first picture never waits on it.
                scene.provisional_importance = True
                if environment is None:
                    from gratnet.environment import load_environment

                    environment = (load_environment(environment_spec or "1", what="--environment")
                                   or load_environment("1"))
            warm_group(scene, group, environment=environment)
            scene.release()
            # Mesa writes the cache entries on a thread: reported only once they are on disk (the window's
            # compile would otherwise miss them and take the full compile time).
            release_headless_context(ctx)
            ctx = None
            print(f"ready {path} {group} {time.perf_counter() - started:.3f}", flush=True)
        if ENVIRONMENT_GROUP in groups and not table_built:  # after the first path's groups (the slice's too), once:
            from gratnet.importance import material_table  # the table is the network's, not a path's

            started = time.perf_counter()
            material_table(model)  # cached on disk, where the window finds it (viewer.scene_supply)
            table_built = True
            print(f"ready {path} {IMPORTANCE} {time.perf_counter() - started:.3f}", flush=True)
    # On a CPU the window's auto is deferred: no probe.
    if render_path == "auto" and "surface" in groups and not software:
        with contextlib.suppress(OSError):
            os.nice(_BAKED_NICENESS)  # the window is up by now: the probe must not slow it
        for path in done:
            ctx = ctx or create_headless_context()
            with SceneRenderer(ctx, model, weights_path=path, baked_source=source) as scene:
                print(f"render-path {path} {scene.render_path}", flush=True)  # measured and cached (or read)
    if ctx is not None:
        release_headless_context(ctx)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m viewer.compile_worker",
                                     description="Warm Mesa's shader cache with a model's viewer programs.")
    parser.add_argument("model")
    parser.add_argument("--paths", default="texture")
    parser.add_argument("--groups", default=",".join(GROUPS))
    parser.add_argument("--folder", required=True, help="where to write the baked mlp.glsl")
    parser.add_argument("--nice", type=int, default=0, help="niceness to add at start")
    parser.add_argument("--render-path", default="auto", help="the viewer's render path (auto: measure it here)")
    parser.add_argument("--environment", default=None, help="the environment the environment group is drawn with")
    arguments = parser.parse_args(argv)
    if arguments.nice > 0:
        with contextlib.suppress(OSError):
            os.nice(arguments.nice)
    try:
        _warm(Path(arguments.model), arguments.paths.split(","), arguments.groups.split(","), Path(arguments.folder),
              arguments.render_path, arguments.environment)
    except GratNetError as error:
        print(f"compile worker: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
