"""What a command line can name: shipped materials and built-in meshes, resolved and built.

- A material is a shipped name (``assets/NAME/model.npz``: :func:`shipped_materials`) or a model-file path
  (:func:`resolve_material`).
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

if TYPE_CHECKING:
    from viewer.meshes import Mesh

__all__ = ["ASSETS", "MESHES", "build_mesh", "check_mesh_spec", "resolve_material", "shipped_materials"]

#: Shipped materials: ``assets/NAME/model.npz``.
ASSETS = Path(__file__).resolve().parents[1] / "assets"
#: Built-in meshes for ``--mesh``.
MESHES = ("cd", "sphere", "plane")


def shipped_materials() -> list[str]:
    """Names of the shipped materials (folders of ``assets/`` holding a ``model.npz``)."""
    return sorted(path.parent.name for path in ASSETS.glob("*/model.npz"))


def resolve_material(material: str) -> Path:
    """A shipped material's model file, or ``material`` itself when it names a file."""
    shipped = ASSETS / material / "model.npz"
    if "/" not in material and "\\" not in material and shipped.is_file():
        return shipped
    path = Path(material).expanduser()
    if path.is_file():
        return path
    names = ", ".join(shipped_materials()) or "none"
    raise GratNetError(
        f"unknown material {material!r}: neither a shipped material (choose {names}) nor an existing model file"
    )


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
