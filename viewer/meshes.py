"""Triangle meshes with a tangent frame, for rendering a diffractive material on a surface.

The network is a function of the key vector in the surface's *tangent frame* (docs/physics.md "Units and
frames"): x = tangent, y = bitangent, z = normal. On a mesh that frame lives in the vertices: every vertex
carries a unit ``normal`` and a unit ``tangent`` perpendicular to it; the bitangent is never stored, it is
``cross(normal, tangent)`` (a right-handed frame, as in physics.md) in the shader and here. The tangent is
the direction of the height field's x axis (its columns) laid onto the surface, so it decides which way
the diffraction fans out: a grating whose grooves run along x diffracts along the bitangent.

Units: positions in metres (the renderer only needs consistent units; the camera's distance uses the
same). Texture coordinates ``uvs`` are kept for completeness (OBJ round trips, tangents from UVs); the
shaders do not read them. Triangles are counter-clockwise seen from the side their normals point to, so
OpenGL's front faces are the lit side.

Generators:

- :func:`compact_disc`: an annulus in the xy-plane facing +z with the tangent along the tracks;
- :func:`sphere`: a UV sphere, tangent along the latitude lines (eastwards);
- :func:`plane`: a square in the xy-plane facing +z, tangent +x;
- :func:`load_obj`: a Wavefront OBJ file, tangents from UV derivatives.

Runtime-side: numpy only (no GL here).
"""

from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path

import numpy as np

from gratnet.errors import GratNetError

__all__ = ["Mesh", "arbitrary_tangents", "compact_disc", "load_obj", "plane", "sphere"]

_UNIT_TOLERANCE = 1e-4  # |length − 1| and |t·n| allowed in a Mesh's frame (float32 data)
_DEGENERATE_AREA = 1e-12  # relative: a triangle with |e1 × e2| ≤ this × (|e1|² + |e2|²) is skipped


@dataclasses.dataclass(frozen=True, eq=False)
class Mesh:
    """An indexed triangle mesh with a per-vertex tangent frame.

    Attributes:
        positions: ``float32`` ``(N, 3)``, metres.
        normals: ``float32`` ``(N, 3)``, unit, pointing out of the lit side.
        tangents: ``float32`` ``(N, 3)``, unit and perpendicular to the normal: the height field's x
            direction on the surface. The bitangent is ``cross(normal, tangent)``.
        uvs: ``float32`` ``(N, 2)`` texture coordinates (0 where the source had none).
        indices: ``uint32`` ``(M, 3)``, counter-clockwise seen from the normals' side.

    Construction validates shapes, dtypes, finiteness, the frame (unit, orthogonal, to 1e-4) and the
    index range; a violation raises :class:`~gratnet.errors.GratNetError`.
    """

    positions: np.ndarray
    normals: np.ndarray
    tangents: np.ndarray
    uvs: np.ndarray
    indices: np.ndarray

    def __post_init__(self) -> None:
        count: int | None = None
        for name, width in (("positions", 3), ("normals", 3), ("tangents", 3), ("uvs", 2)):
            array = np.ascontiguousarray(getattr(self, name), dtype=np.float32)
            if array.ndim != 2 or array.shape[1] != width:
                raise GratNetError(f"mesh {name} must have shape (N, {width}), got {array.shape}")
            if count is None:
                count = array.shape[0]
            elif array.shape[0] != count:
                raise GratNetError(f"mesh {name} has {array.shape[0]} rows, positions have {count}")
            if not np.all(np.isfinite(array)):
                raise GratNetError(f"mesh {name} contain NaN or inf")
            object.__setattr__(self, name, array)
        assert count is not None  # set by the loop's first array (positions)
        indices = np.asarray(self.indices)
        if indices.size == 0:
            indices = indices.reshape(0, 3)
        if indices.ndim != 2 or indices.shape[1] != 3:
            raise GratNetError(f"mesh indices must have shape (M, 3), got {indices.shape}")
        if indices.size and (not np.issubdtype(indices.dtype, np.integer) or indices.min() < 0
                             or indices.max() >= count):
            raise GratNetError(f"mesh indices must be integers in 0 … {count - 1}")
        object.__setattr__(self, "indices", np.ascontiguousarray(indices, dtype=np.uint32))
        normal_error = np.abs(np.linalg.norm(self.normals, axis=1) - 1.0)
        tangent_error = np.abs(np.linalg.norm(self.tangents, axis=1) - 1.0)
        dot_error = np.abs(np.sum(self.normals * self.tangents, axis=1))
        worst = max((float(e.max()) if e.size else 0.0) for e in (normal_error, tangent_error, dot_error))
        if worst > _UNIT_TOLERANCE:
            raise GratNetError(f"mesh frame is not unit and orthogonal (error {worst:.2g} > {_UNIT_TOLERANCE:g})")

    @property
    def bitangents(self) -> np.ndarray:
        """``cross(normal, tangent)`` per vertex, ``float32`` ``(N, 3)``: the height field's y direction."""
        return np.cross(self.normals, self.tangents).astype(np.float32)

    @property
    def vertex_count(self) -> int:
        return int(self.positions.shape[0])

    @property
    def triangle_count(self) -> int:
        return int(self.indices.shape[0])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounding box ``(minimum, maximum)`` of the positions (metres)."""
        if self.vertex_count == 0:
            return np.zeros(3, np.float32), np.zeros(3, np.float32)
        return self.positions.min(axis=0), self.positions.max(axis=0)


def _normalized(vectors: np.ndarray) -> np.ndarray:
    length = np.linalg.norm(vectors, axis=-1, keepdims=True)
    return vectors / np.where(length > 0.0, length, 1.0)


def arbitrary_tangents(normals: np.ndarray) -> np.ndarray:
    """A unit tangent perpendicular to each unit normal, a smooth function of the normal (no branch cut
    except at n = (0, 0, −1)): the first column of Duff et al.'s orthonormal basis ("Building an
    Orthonormal Basis, Revisited", JCGT 2017). The shader's fallback (shaders/surface.glsl) is the same."""
    n = np.asarray(normals, dtype=np.float64)
    sign = np.where(n[..., 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[..., 2])
    b = n[..., 0] * n[..., 1] * a
    tangent = np.stack([1.0 + sign * n[..., 0] ** 2 * a, sign * b, -sign * n[..., 0]], axis=-1)
    return _normalized(tangent)


def _orthogonalize(tangents: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Gram–Schmidt: t − (t·n) n, normalised; an arbitrary tangent where that is (nearly) zero."""
    t = np.asarray(tangents, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float64)
    t = t - np.sum(t * n, axis=-1, keepdims=True) * n
    length = np.linalg.norm(t, axis=-1)
    good = length > 1e-6 * np.maximum(np.linalg.norm(tangents, axis=-1), 1e-30)
    good &= length > 1e-20
    result = arbitrary_tangents(n)
    result[good] = t[good] / length[good, None]
    return result


def _checked_count(name: str, value: object, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise GratNetError(f"{name} must be an integer ≥ {minimum}, got {value!r}")
    return int(value)


def _checked_length(name: str, value: float, allow_zero: bool = False) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise GratNetError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(number) or number < 0.0 or (number == 0.0 and not allow_zero):
        raise GratNetError(f"{name} must be a finite number {'≥' if allow_zero else '>'} 0, got {value!r}")
    return number


def _grid_indices(columns: int, rows: int) -> np.ndarray:
    """Two counter-clockwise triangles per cell of a (rows + 1) × (columns + 1) vertex grid, vertex
    ``r * (columns + 1) + c``, when +column × +row points along the normal."""
    c, r = np.meshgrid(np.arange(columns), np.arange(rows), indexing="xy")
    stride = columns + 1
    a = (r * stride + c).ravel()
    b, d = a + 1, a + stride
    e = d + 1
    return np.concatenate([np.stack([a, b, e], 1), np.stack([a, e, d], 1)]).astype(np.uint32)


def compact_disc(inner_radius: float = 0.0075, outer_radius: float = 0.06, segments: int = 256,
                 rings: int = 8) -> Mesh:
    """A compact disc: an annulus in the xy-plane (z = 0) facing +z, centred at the origin (metres).

    The defaults are a real CD's data area: 15 mm centre hole (7.5 mm radius), 120 mm diameter.

    Frame: normal +z; the tangent runs **along the tracks**, i.e. the azimuthal direction
    ``(−sin φ, cos φ, 0)`` (counter-clockwise seen from +z). The CD height field's tracks run along its x
    axis, so laying x along the tracks makes the grooves circles around the centre and the diffraction
    orders fan out radially: a point light gives the familiar rainbow arcs. The bitangent
    ``cross(normal, tangent) = (−cos φ, −sin φ, 0)`` points towards the centre.

    UVs: ``u = φ / 2π`` (increases along the tangent), ``v = (outer − r) / (outer − inner)`` (increases
    along the bitangent). The seam at φ = 0 is duplicated, so there are ``(rings + 1) · (segments + 1)``
    vertices and ``2 · rings · segments`` triangles (``segments`` fewer for a full disc, ``inner_radius=0``,
    whose centre cells are single triangles).
    """
    inner = _checked_length("inner_radius", inner_radius, allow_zero=True)
    outer = _checked_length("outer_radius", outer_radius)
    if not inner < outer:
        raise GratNetError(f"inner_radius must be smaller than outer_radius, got {inner:g} and {outer:g}")
    segments = _checked_count("segments", segments, 3)
    rings = _checked_count("rings", rings, 1)
    phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    phi[-1] = 0.0  # the seam's copy is the same point exactly (its u is 1)
    radius = np.linspace(inner, outer, rings + 1)
    phi_grid, radius_grid = np.meshgrid(phi, radius, indexing="xy")  # (rings + 1, segments + 1)
    cos_phi, sin_phi = np.cos(phi_grid), np.sin(phi_grid)
    positions = np.stack([radius_grid * cos_phi, radius_grid * sin_phi, np.zeros_like(phi_grid)], -1)
    normals = np.broadcast_to([0.0, 0.0, 1.0], positions.shape)
    tangents = np.stack([-sin_phi, cos_phi, np.zeros_like(phi_grid)], -1)
    u = np.broadcast_to(np.arange(segments + 1) / segments, phi_grid.shape)
    v = (outer - radius_grid) / (outer - inner)
    uvs = np.stack([u, v], -1)
    # Column step: +φ (tangent); row step: +r (= −bitangent). tangent × radial = −z, so the grid's
    # (a, b, e) order is clockwise from +z: flip each triangle.
    indices: np.ndarray = _grid_indices(segments, rings)[:, [0, 2, 1]].reshape(2, rings * segments, 3)
    if inner == 0.0:  # a full disc: the innermost ring is the centre; drop the (a, e, b) triangles there
        indices = np.concatenate([indices[0, segments:], indices[1]])
    indices = indices.reshape(-1, 3)
    return Mesh(positions.reshape(-1, 3), normals.reshape(-1, 3), tangents.reshape(-1, 3), uvs.reshape(-1, 2),
                indices)


def sphere(radius: float = 0.05, segments: int = 64, rings: int = 32) -> Mesh:
    """A UV sphere of ``radius`` metres centred at the origin, poles on ±z.

    Frame: the outward normal; the tangent runs **along the latitude lines** (parallels), eastwards:
    ``(−sin φ, cos φ, 0)`` at azimuth φ, which is defined at the poles too (each pole is ``segments``
    vertices, one per azimuth, all at the pole). The bitangent ``cross(normal, tangent)`` points north
    along the meridians (longitude lines). So a height field's x axis wraps around the sphere like a
    lathe's grooves around the z axis.

    UVs: ``u = φ / 2π`` (along the tangent), ``v = 1 − θ / π`` with θ the polar angle from +z (along the
    bitangent). ``(rings + 1) · (segments + 1)`` vertices (seam duplicated), ``2 · rings · segments``
    triangles (the pole caps' zero-area triangles are dropped).
    """
    radius = _checked_length("radius", radius)
    segments = _checked_count("segments", segments, 3)
    rings = _checked_count("rings", rings, 2)
    phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    phi[-1] = 0.0
    theta = np.linspace(0.0, np.pi, rings + 1)
    phi_grid, theta_grid = np.meshgrid(phi, theta, indexing="xy")  # row 0: north pole
    cos_phi, sin_phi = np.cos(phi_grid), np.sin(phi_grid)
    sin_theta, cos_theta = np.sin(theta_grid), np.cos(theta_grid)
    sin_theta[0], sin_theta[-1] = 0.0, 0.0  # poles exactly
    cos_theta[0], cos_theta[-1] = 1.0, -1.0
    normals = np.stack([sin_theta * cos_phi, sin_theta * sin_phi, cos_theta], -1)
    positions = radius * normals
    tangents = np.stack([-sin_phi, cos_phi, np.zeros_like(phi_grid)], -1)
    uvs = np.stack([np.broadcast_to(np.arange(segments + 1) / segments, phi_grid.shape), 1.0 - theta_grid / np.pi], -1)
    # Column step: east (tangent); row step: south (−bitangent); east × south = −outward: flip.
    indices = _grid_indices(segments, rings)[:, [0, 2, 1]].reshape(2, rings, segments, 3)
    # Drop the degenerate triangle of each pole cell: (a, e, b) in the top row has a, b at the pole;
    # (a, d, e) in the bottom row has d, e at the pole.
    keep = np.ones((2, rings, segments), dtype=bool)
    keep[0, 0, :] = False
    keep[1, -1, :] = False
    return Mesh(positions.reshape(-1, 3), normals.reshape(-1, 3), tangents.reshape(-1, 3), uvs.reshape(-1, 2),
                indices[keep])


def plane(size: float = 0.1, subdivisions: int = 1) -> Mesh:
    """A ``size`` × ``size`` metre square in the xy-plane (z = 0), centred at the origin, facing +z.

    Frame: normal +z, tangent +x, bitangent +y: the surface frame is the world frame, so world
    directions are the height field's directions. UVs ``(x / size + ½, y / size + ½)``.
    ``subdivisions`` cells per side.
    """
    size = _checked_length("size", size)
    subdivisions = _checked_count("subdivisions", subdivisions, 1)
    steps = np.linspace(-0.5 * size, 0.5 * size, subdivisions + 1)
    x, y = np.meshgrid(steps, steps, indexing="xy")  # rows: +y; columns: +x; +x × +y = +z (CCW)
    positions = np.stack([x, y, np.zeros_like(x)], -1).reshape(-1, 3)
    count = positions.shape[0]
    normals = np.broadcast_to([0.0, 0.0, 1.0], (count, 3))
    tangents = np.broadcast_to([1.0, 0.0, 0.0], (count, 3))
    uvs = positions[:, :2] / size + 0.5
    return Mesh(positions, normals, tangents, uvs, _grid_indices(subdivisions, subdivisions))


# ----------------------------------------------------------------------------------------------------
# Wavefront OBJ
# ----------------------------------------------------------------------------------------------------


def _obj_error(path: Path, number: int, message: str) -> GratNetError:
    return GratNetError(f"{path}:{number}: {message}")


def _parse_floats(parts: list[str], count: int, path: Path, number: int, what: str) -> list[float]:
    if len(parts) < count:
        raise _obj_error(path, number,
                         f"{what} needs {count} numbers, got {len(parts)}; the file is truncated or not OBJ")
    try:
        values = [float(p) for p in parts[:count]]
    except ValueError:
        raise _obj_error(path, number, f"{what} has a non-numeric value in {' '.join(parts)!r}") from None
    if not all(math.isfinite(value) for value in values):
        raise _obj_error(path, number, f"{what} has a non-finite value in {' '.join(parts)!r}")
    return values


def _resolve_index(text: str, size: int, path: Path, number: int, what: str) -> int:
    """An OBJ index (1-based, negative = from the end) → 0-based, checked against the ``size`` so far."""
    try:
        index = int(text)
    except ValueError:
        raise _obj_error(path, number, f"bad {what} index {text!r}") from None
    resolved = index - 1 if index > 0 else size + index
    if index == 0 or not 0 <= resolved < size:
        raise _obj_error(path, number, f"{what} index {index} out of range (1 … {size} defined so far)")
    return resolved


def load_obj(path: str | os.PathLike[str]) -> Mesh:
    """Read a Wavefront OBJ file (``v``, ``vt``, ``vn``, ``f``; other statements are ignored).

    - Faces ``v``, ``v/vt``, ``v//vn``, ``v/vt/vn`` with 1-based or negative indices; polygons are
      triangulated as fans. Each distinct (v, vt, vn) corner becomes one vertex, so UV and normal
      seams stay sharp.
    - Degenerate triangles (repeated or collinear corners) are skipped.
    - Normals missing from a corner are the area-weighted average of the adjacent face normals.
    - Winding: a triangle whose face normal disagrees with its corners' normals is flipped, so front
      faces are always the lit side.
    - Tangent = ∂position/∂u from each triangle's UV derivatives (Lengyel's method), accumulated per
      vertex, then Gram–Schmidt orthogonalised against the normal. Where that is undefined (no UVs,
      or UVs that do not vary), an arbitrary stable tangent ⟂ normal (:func:`arbitrary_tangents`).

    Positions are taken as metres.

    Raises:
        GratNetError: the file is missing or unreadable, a statement is malformed or truncated, an
            index is out of range, or no non-degenerate triangle remains.
    """
    source = Path(path)
    try:
        text = source.read_text(encoding="utf-8", errors="replace")
    except OSError as error:
        raise GratNetError(f"cannot read mesh {source}: {error.strerror or error}") from error
    if "\x00" in text:
        raise GratNetError(f"{source} is not a Wavefront OBJ text file")
    positions: list[list[float]] = []
    texcoords: list[list[float]] = []
    normals: list[list[float]] = []
    corners: dict[tuple[int, int, int], int] = {}
    corner_list: list[tuple[int, int, int]] = []
    triangles: list[tuple[int, int, int]] = []
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        keyword, *parts = line.split()
        if keyword == "v":
            positions.append(_parse_floats(parts, 3, source, number, "vertex"))
        elif keyword == "vt":
            values = _parse_floats(parts, min(max(len(parts), 1), 2), source, number, "texture coordinate")
            texcoords.append((values + [0.0])[:2])  # "vt u" alone means v = 0
        elif keyword == "vn":
            normals.append(_parse_floats(parts, 3, source, number, "normal"))
        elif keyword == "f":
            if len(parts) < 3:
                raise _obj_error(source, number, f"a face needs at least 3 corners, got {len(parts)}")
            face = []
            for part in parts:
                fields = part.split("/")
                if len(fields) > 3 or not fields[0]:
                    raise _obj_error(source, number, f"malformed face corner {part!r}")
                v = _resolve_index(fields[0], len(positions), source, number, "vertex")
                t = _resolve_index(fields[1], len(texcoords), source, number, "texture") if len(fields) > 1 and \
                    fields[1] else -1
                n = _resolve_index(fields[2], len(normals), source, number, "normal") if len(fields) > 2 and \
                    fields[2] else -1
                key = (v, t, n)
                if key not in corners:
                    corners[key] = len(corner_list)
                    corner_list.append(key)
                face.append(corners[key])
            triangles += [(face[0], face[k], face[k + 1]) for k in range(1, len(face) - 1)]
        # Other statements (o, g, s, usemtl, mtllib, l, p, …) carry nothing the renderer uses.
    if not triangles:
        raise GratNetError(f"{source} has no faces (is it a Wavefront OBJ file?)")
    keys = np.array(corner_list, dtype=np.int64)
    point = np.asarray(positions, dtype=np.float64)[keys[:, 0]]
    has_uv = keys[:, 1] >= 0
    uv_table = np.asarray(texcoords, dtype=np.float64).reshape(-1, 2)
    uv = np.zeros((len(keys), 2))
    uv[has_uv] = uv_table[keys[has_uv, 1]]
    has_normal = keys[:, 2] >= 0
    normal_table = _normalized(np.asarray(normals, dtype=np.float64).reshape(-1, 3))
    given_normal = np.zeros((len(keys), 3))
    given_normal[has_normal] = normal_table[keys[has_normal, 2]]
    has_normal &= np.linalg.norm(given_normal, axis=1) > 0.5  # a zero "vn" counts as missing

    tri = np.asarray(triangles, dtype=np.int64)
    e1 = point[tri[:, 1]] - point[tri[:, 0]]
    e2 = point[tri[:, 2]] - point[tri[:, 0]]
    cross = np.cross(e1, e2)
    area2 = np.linalg.norm(cross, axis=1)
    scale = np.sum(e1 * e1, axis=1) + np.sum(e2 * e2, axis=1)
    distinct = (tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 0] != tri[:, 2])
    keep = distinct & (area2 > _DEGENERATE_AREA * scale) & (scale > 0.0)
    if not np.any(keep):
        raise GratNetError(f"{source}: every face is degenerate (zero area)")
    tri, e1, e2, cross = tri[keep], e1[keep], e2[keep], cross[keep]

    # Winding against the given normals: flip triangles whose face normal points away from them.
    corner_normals = given_normal[tri].sum(axis=1)
    flip = np.sum(cross * corner_normals, axis=1) < 0.0
    if np.any(flip):
        tri[flip] = tri[flip][:, [0, 2, 1]]
        e1[flip], e2[flip] = e2[flip].copy(), e1[flip].copy()
        cross[flip] = -cross[flip]

    # Missing normals: area-weighted face normals (|cross| = 2 · area).
    accumulated = np.zeros_like(point)
    for k in range(3):
        np.add.at(accumulated, tri[:, k], cross)
    vertex_normal = np.where(has_normal[:, None], given_normal, _normalized(accumulated))
    lost = np.linalg.norm(vertex_normal, axis=1) < 0.5  # unused corners, or normals that cancelled
    vertex_normal[lost] = [0.0, 0.0, 1.0]

    # Tangents from UV derivatives: e1 = Δu1 T + Δv1 B, e2 = Δu2 T + Δv2 B → T = (Δv2 e1 − Δv1 e2) / det.
    duv1 = uv[tri[:, 1]] - uv[tri[:, 0]]
    duv2 = uv[tri[:, 2]] - uv[tri[:, 0]]
    det = duv1[:, 0] * duv2[:, 1] - duv2[:, 0] * duv1[:, 1]
    mapped = has_uv[tri].all(axis=1) & (np.abs(det) > 1e-12 * (np.sum(duv1**2, 1) + np.sum(duv2**2, 1)))
    mapped &= np.abs(det) > 0.0
    direction = np.zeros_like(e1)
    direction[mapped] = (duv2[mapped, 1, None] * e1[mapped] - duv1[mapped, 1, None] * e2[mapped]) \
        * np.sign(det[mapped])[:, None]
    # Only the direction of ∂P/∂u counts (|det| dropped, its sign kept): normalise per triangle and
    # weight by area, so that large triangles dominate and a stretched mapping does not.
    direction = _normalized(direction) * (0.5 * np.linalg.norm(cross, axis=1))[:, None]
    accumulated_tangent = np.zeros_like(point)
    for k in range(3):
        np.add.at(accumulated_tangent, tri[:, k], direction)
    vertex_tangent = _orthogonalize(accumulated_tangent, vertex_normal)

    used = np.unique(tri)
    remap = np.full(len(keys), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return Mesh(point[used], vertex_normal[used], vertex_tangent[used], uv[used], remap[tri])
