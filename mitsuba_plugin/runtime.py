"""Importing Mitsuba 3 lazily, choosing a variant and registering the ``gratnet`` BSDF for it.

The BSDF evaluates the network with numpy (``gratnet.modelfile.evaluate_keys``), so Dr.Jit must hand it
evaluated arrays, not symbolic ones: in JIT variants :func:`set_variant` turns off Dr.Jit's symbolic loops
and calls (``JitFlag.SymbolicLoops``, ``JitFlag.SymbolicCalls``; process-wide flags). Mitsuba then calls the
BSDF once per bounce for all lanes that hit it (``llvm_ad_rgb``: wide numpy batches), or once per lookup in
``scalar_rgb``.

Dr.Jit's LLVM back end needs LLVM ≥ 18 here: with Debian 12's LLVM 14 and 15 every kernel containing a
float maximum aborts the process ("Cannot select: fmaximum"); Debian's ``libllvm19`` works. ``auto`` picks
``llvm_ad_rgb`` when such an LLVM is found, else ``scalar_rgb``.

Mitsuba reports a Python plugin's errors inside its own ("failed to instantiate ... plugin of type gratnet",
then a traceback), and a Ctrl-C inside a render as a RuntimeError of ``drjit.custom``:
:func:`plugin_errors` turns the first back into the plugin's one line, :func:`interrupted` recognises the second.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from types import ModuleType

from gratnet.errors import GratNetError

__all__ = ["MIN_LLVM", "VARIANTS", "import_mitsuba", "interrupted", "llvm_usable", "plugin_errors",
           "resolve_variant", "set_variant"]

#: Variants the plugin supports: RGB ones (the network's XYZ is converted to linear sRGB).
VARIANTS = ("auto", "llvm_ad_rgb", "scalar_rgb")
#: Oldest LLVM whose x86 back end selects the llvm.maximum intrinsic that Dr.Jit 1.x emits.
MIN_LLVM = (18, 0, 0)


@contextlib.contextmanager
def _interrupt_after() -> Iterator[None]:
    """Inside: a Ctrl-C waits until the block is done, then raises KeyboardInterrupt. For the loading of
    Dr.Jit's and Mitsuba's extensions (≈ 0.1 s each): a KeyboardInterrupt inside their initialisation turns into
    an ImportError ("Encountered an error while initializing the extension") and the interpreter aborts at exit."""
    if threading.current_thread() is not threading.main_thread() or signal.getsignal(signal.SIGINT) is None:
        yield
        return
    received: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda number, frame: received.append(number))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if received:
        raise KeyboardInterrupt


def import_mitsuba() -> ModuleType:
    """``mitsuba``, or one GratNetError saying how to install it."""
    try:
        with _interrupt_after():
            import mitsuba
    except ImportError as error:
        raise GratNetError(
            f"Mitsuba 3 is not installed ({error}); install the extra: pip install -e '.[mitsuba]'") from None
    return mitsuba


def llvm_usable() -> bool:
    """True when Dr.Jit's LLVM back end loads an LLVM ≥ :data:`MIN_LLVM` (older ones abort on the first kernel)."""
    with _interrupt_after():
        import drjit as dr

        try:
            if not dr.has_backend(dr.JitBackend.LLVM):
                return False
            return tuple(dr.detail.llvm_version()) >= MIN_LLVM
        except Exception:  # no LLVM at all: Dr.Jit raises while loading it
            return False


def resolve_variant(name: str) -> str:
    """``auto`` → ``llvm_ad_rgb`` when usable, else ``scalar_rgb``; an unusable or unknown choice is refused."""
    import_mitsuba()
    if name not in VARIANTS:
        raise GratNetError(f"unknown Mitsuba variant {name!r}; choose one of {', '.join(VARIANTS)}")
    if name == "auto":
        return "llvm_ad_rgb" if llvm_usable() else "scalar_rgb"
    if name == "llvm_ad_rgb" and not llvm_usable():
        raise GratNetError(f"llvm_ad_rgb needs Dr.Jit to find LLVM ≥ {MIN_LLVM[0]} (Debian: apt-get install "
                           "libllvm19; or set DRJIT_LIBLLVM_PATH); use --variant scalar_rgb")
    return name


def set_variant(name: str = "auto") -> ModuleType:
    """Set the Mitsuba variant (see :func:`resolve_variant`), put Dr.Jit in evaluated mode, register the
    ``gratnet`` BSDF plugin for that variant and return the ``mitsuba`` module."""
    mi = import_mitsuba()
    variant = resolve_variant(name)
    with _interrupt_after():
        mi.set_variant(variant)
        import drjit as dr

    if dr.is_jit_v(mi.Float):
        dr.set_flag(dr.JitFlag.SymbolicLoops, False)
        dr.set_flag(dr.JitFlag.SymbolicCalls, False)
    from mitsuba_plugin.bsdf import register

    register(mi)
    return mi


@contextlib.contextmanager
def plugin_errors() -> Iterator[None]:
    """Inside: an error Mitsuba raised while loading a ``gratnet`` BSDF comes out as the plugin's own message,
    one GratNetError line (``mi.load_dict``/``mi.load_file`` wrap it in their own message and a traceback).
    Other errors pass unchanged."""
    from mitsuba_plugin.bsdf import plugin_message

    try:
        yield
    except RuntimeError as error:
        message = plugin_message(error)
        if message is None:
            raise
        raise GratNetError(message) from None


def interrupted(error: BaseException) -> bool:
    """Whether ``error`` is a KeyboardInterrupt or wraps one (Dr.Jit's ``custom`` operation, which ``mi.render``
    runs, reports a Ctrl-C that arrives inside a plugin as a RuntimeError caused by it)."""
    seen: set[int] = set()
    current: BaseException | None = error
    while current is not None and id(current) not in seen:
        if isinstance(current, KeyboardInterrupt):
            return True
        seen.add(id(current))
        current = current.__cause__ or current.__context__
    return False
