"""What a command line can name: shipped materials and built-in meshes, resolved and built.

- A material is a shipped name (``assets/NAME/model.npz``: :func:`shipped_materials`) or a model-file path
  (:func:`resolve_material`). A shipped material has one or more quality points (gratnet.quality: ``accurate``,
  its folder's ``model.npz``; ``fast``, ``fast/model.npz``), listed by :func:`material_points`; ``--quality``
  chooses one (:func:`material_point`). The rules, the same in every command:

  - no quality given: the accurate point (every material has it);
  - a quality the material has no point for: one line naming the points it has;
  - a quality with a model-file path: one line (the path is the model; nothing is chosen between points, and a
    flag that would be ignored is refused instead).

  The assets folder is :data:`ASSETS`, read at each call (tests set it to a folder of their own), or the
  ``assets`` argument.
- A mesh is ``cd``, ``sphere``, ``plane`` (:data:`MESHES`, built by :mod:`viewer.meshes`) or a Wavefront
  ``.obj`` file in metres, +z up (:func:`build_mesh`; :func:`check_mesh_spec` checks a name without
  building it).

``gratnet render``, ``gratnet view``, ``gratnet bench``, ``gratnet mitsuba-render``, the viewer and the
default-view algorithm all resolve names here. Imports nothing heavy until a mesh is built (``gratnet
--help`` stays quick). Runtime-side: no GL, no torch.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from gratnet.errors import GratNetError
from gratnet.quality import DEFAULT_QUALITY, POINT_FOLDERS, QUALITIES, check_quality

if TYPE_CHECKING:
    from viewer.meshes import Mesh

__all__ = ["ASSETS", "MESHES", "build_mesh", "check_mesh_spec", "material_point", "material_points", "model_label",
           "resolve_material", "shipped_materials"]

#: Shipped materials: ``assets/NAME/model.npz``.
ASSETS = Path(__file__).resolve().parents[1] / "assets"
#: Built-in meshes for ``--mesh``.
MESHES = ("cd", "sphere", "plane")


def shipped_materials(assets: Path | None = None) -> list[str]:
    """Names of the shipped materials (folders of ``assets/`` holding a ``model.npz``; a point's folder inside
    one, such as ``NAME/fast``, is not a material)."""
    return sorted(path.parent.name for path in (ASSETS if assets is None else assets).glob("*/model.npz"))


def _shipped_folder(material: str, assets: Path | None) -> Path | None:
    """``assets/NAME`` when ``material`` names a shipped material, else None."""
    if "/" in material or "\\" in material or material in ("", ".", ".."):
        return None
    folder = (ASSETS if assets is None else assets) / material
    return folder if (folder / "model.npz").is_file() else None


def material_points(material: str, assets: Path | None = None) -> dict[str, Path]:
    """A shipped material's quality points (gratnet.quality), fastest first: quality name → its model file
    (``accurate``: ``assets/NAME/model.npz``, always; ``fast``: ``assets/NAME/fast/model.npz`` where present).

    Raises:
        GratNetError: ``material`` is no shipped material (a model-file path has no points).
    """
    folder = _shipped_folder(material, assets)
    if folder is None:
        names = ", ".join(shipped_materials(assets)) or "none"
        raise GratNetError(f"{material!r} is not a shipped material (choose {names}); a model file has no quality "
                           "points")
    points = {quality: folder / POINT_FOLDERS[quality] / "model.npz" for quality in QUALITIES}
    return {quality: path for quality, path in points.items() if path.is_file()}


def material_point(material: str, quality: str | None = None, assets: Path | None = None) -> tuple[Path, str | None]:
    """The model file of ``material`` at ``quality`` and the point's quality name: for a shipped material its
    point (``None``: :data:`~gratnet.quality.DEFAULT_QUALITY`), for a model-file path the file itself and
    ``None`` (the module docstring has the rules).

    Raises:
        GratNetError: an unknown material, a quality the material has no point for, or a quality given with a
            model-file path; one line each.
    """
    if quality is not None:
        check_quality(quality)
    folder = _shipped_folder(material, assets)
    if folder is not None:
        points = material_points(material, assets)
        chosen = DEFAULT_QUALITY if quality is None else quality
        if chosen not in points:
            has = ", ".join(f"{name} ({path.relative_to(folder.parent)})" for name, path in points.items())
            raise GratNetError(f"--quality {chosen}: {material} has no {chosen} point; its points: {has}")
        return points[chosen], chosen
    path = Path(material).expanduser()
    if path.is_file():
        if quality is not None:
            raise GratNetError(f"--quality chooses between a shipped material's points; {material} is a model file "
                               "(leave out --quality, or name the material)")
        return path, None
    names = ", ".join(shipped_materials(assets)) or "none"
    raise GratNetError(
        f"unknown material {material!r}: neither a shipped material (choose {names}) nor an existing model file"
    )


def resolve_material(material: str, quality: str | None = None, assets: Path | None = None) -> Path:
    """A shipped material's model file (its ``quality`` point; ``None``: the accurate one), or ``material``
    itself when it names a file (:func:`material_point`)."""
    return material_point(material, quality, assets)[0]


def model_label(path: Path) -> str:
    """How messages name a model file: ``NAME`` for a material's accurate point (or any run folder's
    ``model.npz``), ``NAME (fast)`` for its fast point, else the file's name."""
    path = Path(path)
    if path.name != "model.npz":
        return path.name
    parents = path.absolute().parents
    material = parents[1] if len(parents) > 1 else parents[0]
    for quality, folder in POINT_FOLDERS.items():
        if folder and path.parent.name == folder and material != path.parent and (material / "model.npz").is_file():
            return f"{material.name} ({quality})"
    return path.parent.name


def check_mesh_spec(spec: str) -> None:
    """The cheap checks of :func:`build_mesh` (a built-in name, or an existing .obj file), without building it."""
    if spec in MESHES:
        return
    path = Path(spec).expanduser()
    if path.suffix.lower() != ".obj":
        raise GratNetError(f"unknown mesh {spec!r}: choose {', '.join(MESHES)} or the path of a Wavefront .obj file")
    if not path.is_file():
        raise GratNetError(f"mesh file {spec} does not exist")


def build_mesh(spec: str) -> Mesh:
    """The mesh named by ``--mesh``: a built-in name or an .obj path."""
    from viewer import meshes

    check_mesh_spec(spec)
    builders: dict[str, Callable[[], Mesh]] = {
        "cd": meshes.compact_disc, "sphere": meshes.sphere, "plane": meshes.plane}
    if spec in builders:
        return builders[spec]()
    return meshes.load_obj(Path(spec).expanduser())
