"""The single place that creates OpenGL contexts for the runtime (no glfw, no imgui here).

Every context is OpenGL 4.3 core or newer (the shaders are ``#version 430 core``). Headless rendering
goes through EGL (on a machine without a GPU: Mesa llvmpipe); a window's context is wrapped with
:func:`context_from_current`. A missing EGL/Mesa stack raises :class:`~gratnet.errors.GratNetError`
with a one-line message that names the Debian packages to install.
"""

from __future__ import annotations

import moderngl

from gratnet.errors import GratNetError

__all__ = ["GL_REQUIRE", "MESA_PACKAGES", "context_from_current", "create_headless_context",
           "release_headless_context"]

#: OpenGL version the shaders need, in moderngl's encoding (4.3 → 430).
GL_REQUIRE = 430
#: Debian packages that provide headless EGL with Mesa's software (llvmpipe) and GPU drivers.
MESA_PACKAGES = "libegl1 libegl-mesa0 libgbm1 libgl1 libgl1-mesa-dri"


def _one_line(error: BaseException) -> str:
    """The error's text squeezed onto one line (the CLI prints messages on one line)."""
    text = " ".join(str(error).split())
    return text or type(error).__name__


def create_headless_context() -> moderngl.Context:
    """A standalone OpenGL ≥ 4.3 core context on EGL (no window, no display server needed).

    Raises:
        GratNetError: EGL or the Mesa libraries are missing, or the driver offers less than GL 4.3.
    """
    try:
        # moderngl passes backend="egl" on to glcontext as is.
        return moderngl.create_context(standalone=True, require=GL_REQUIRE,
                                       backend="egl")  # type: ignore[arg-type]  # stubs: each **settings a dict
    except Exception as error:  # glcontext raises plain Exception (library not found, no display, …)
        raise GratNetError(
            f"cannot create a headless OpenGL 4.3 context through EGL ({_one_line(error)}); "
            f"install EGL and Mesa: apt-get install {MESA_PACKAGES}"
        ) from error


def release_headless_context(ctx: moderngl.Context) -> None:
    """Release a :func:`create_headless_context` context and terminate its EGL display (for the whole
    process): Mesa writes its disk shader cache entries on a background thread, and only the display's
    termination waits for them (seen: the last entry of a program landed after the draw that made it had
    returned). A later :func:`create_headless_context` initialises the display again."""
    import ctypes

    egl = ctypes.CDLL("libEGL.so.1")
    egl.eglGetCurrentDisplay.restype = ctypes.c_void_p
    egl.eglMakeCurrent.argtypes = [ctypes.c_void_p] * 4
    egl.eglMakeCurrent.restype = ctypes.c_uint
    egl.eglTerminate.argtypes = [ctypes.c_void_p]
    egl.eglTerminate.restype = ctypes.c_uint
    display = egl.eglGetCurrentDisplay()
    ctx.release()
    if display:
        egl.eglMakeCurrent(display, None, None, None)
        egl.eglTerminate(display)


def context_from_current() -> moderngl.Context:
    """Wrap the OpenGL context that is current on this thread (e.g. a glfw window's) for moderngl.

    Raises:
        GratNetError: no context is current, or it offers less than GL 4.3.
    """
    try:
        return moderngl.create_context(require=GL_REQUIRE)
    except Exception as error:  # same failure modes as above, plus "no current context"
        raise GratNetError(
            f"cannot use the current OpenGL context ({_one_line(error)}); it must be OpenGL 4.3 core or newer, "
            f"and on Debian the drivers come from: apt-get install {MESA_PACKAGES}"
        ) from error
