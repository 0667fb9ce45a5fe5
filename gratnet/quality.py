"""The quality points of a shipped material, named once (issue 42): where each point's run folder lies and what the
``--quality`` flag of ``gratnet render``, ``compare``, ``mitsuba-render`` and ``view`` chooses.

A shipped material (``assets/NAME/``) is one or more points of the speed/accuracy front, each a full run folder
(``model.npz`` with its ``train_command.json``, ``metrics.json``, ``report.md``, …):

- :data:`ACCURATE`: ``assets/NAME/model.npz``, the material's own folder (every material has it; every path that
  named a shipped model before keeps naming this one);
- :data:`FAST`: ``assets/NAME/fast/model.npz``, a network of at most a fifth of the accurate one's multiply-adds
  per pixel (trained with ``gratnet train --preset fast``).

The readers: ``viewer.catalog`` (a material's points, a name and a quality to a model file), the scene configs of
``viewer.scene_config``, ``bench.compare`` and ``mitsuba_plugin.render_cli`` (the ``--quality`` field), and
``viewer.view_cli`` (which adds :data:`AUTO`). Adding a point: its name in :data:`QUALITIES` and its folder in
:data:`POINT_FOLDERS`.

Standard library only: the flag declarations import this module.
"""

from __future__ import annotations

from gratnet.errors import GratNetError

__all__ = ["ACCURATE", "AUTO", "DEFAULT_QUALITY", "FAST", "POINT_FOLDERS", "QUALITIES", "QUALITY_HELP",
           "VIEW_QUALITIES", "check_quality"]

FAST = "fast"
ACCURATE = "accurate"
#: ``gratnet view`` only: the fast point while the view moves, the accurate one once it stands still. For now it
#: shows the accurate point throughout (viewer.view_cli says why).
AUTO = "auto"

#: A material's points, fastest first.
QUALITIES = (FAST, ACCURATE)
#: What ``gratnet view --quality`` takes.
VIEW_QUALITIES = (*QUALITIES, AUTO)
#: The point of an offline picture (render, compare, mitsuba-render) when ``--quality`` is left out: the most
#: accurate one, as a demanding user expects of a picture that is written to disk.
DEFAULT_QUALITY = ACCURATE
#: Each point's run folder, relative to the material's folder (``""``: the folder itself).
POINT_FOLDERS = {FAST: FAST, ACCURATE: ""}

#: ``--quality``'s help, the same in every command that takes it.
QUALITY_HELP = ("which of a shipped material's points renders it: accurate (assets/NAME/model.npz) or fast "
                "(assets/NAME/fast/model.npz: at most a fifth of the work per pixel, less faithful); only for a "
                "shipped material name, not for a model-file path")


def check_quality(quality: str, allowed: tuple[str, ...] = QUALITIES, flag: str = "--quality") -> str:
    """``quality`` if it is one of ``allowed``, else a one-line GratNetError naming ``flag`` and the choices."""
    if quality not in allowed:
        raise GratNetError(f"{flag} must be one of {', '.join(allowed)}, got {quality!r}")
    return quality
