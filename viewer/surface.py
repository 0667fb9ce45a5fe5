"""What both render paths of a mesh share: the mesh on the GPU and the surface pass's camera and light.

``shaders/surface.glsl`` is drawn by the forward path (:mod:`viewer.forward`, the network in the fragment
shader) and, compiled with ``GBUFFER``, by the deferred path's first pass (:mod:`viewer.deferred`). Both
bind the same vertex buffers (:class:`MeshBuffers`, made once per mesh by :func:`upload_mesh`) to their own
program (:meth:`MeshBuffers.vertex_array_for`) and set the same uniforms (:func:`set_surface_uniforms`:
view-projection, eye, light, exposure, IOR; world +z up, metres).

Rendering only: no glfw, no imgui, no torch.
"""

from __future__ import annotations

import dataclasses
import math

import moderngl
import numpy as np

from gratnet.errors import GratNetError
from gratnet.lights import light_kind
from gratnet.shadowing import NO_SHADOWING, check_slope_covariance
from viewer.camera import Camera, Light
from viewer.meshes import Mesh
from viewer.renderer import ior_uniform, set_uniform

__all__ = ["MAX_IMAGE_SIZE", "MeshBuffers", "check_size", "set_surface_uniforms", "upload_mesh"]

#: Largest image side (pixels); GL implementations guarantee at least this much for render targets.
MAX_IMAGE_SIZE = 16384
#: The surface program's vertex attributes and the Mesh fields that feed them (float32 xyz each).
ATTRIBUTES = (("in_position", "positions"), ("in_normal", "normals"), ("in_tangent", "tangents"))


def check_size(size: tuple[int, int]) -> tuple[int, int]:
    """``(width, height)`` from a pair of positive integers ≤ :data:`MAX_IMAGE_SIZE`, else GratNetError."""
    try:
        width, height = size
    except (TypeError, ValueError):
        raise GratNetError(f"image size must be (width, height), got {size!r}") from None
    for value in (width, height):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 1 <= value <= MAX_IMAGE_SIZE:
            raise GratNetError(f"image width and height must be integers in 1 … {MAX_IMAGE_SIZE}, got {size!r}")
    return int(width), int(height)


@dataclasses.dataclass(eq=False)
class MeshBuffers:
    """A mesh uploaded to the GPU: one vertex buffer per attribute and the index buffer.

    Keep one for a mesh that is drawn many times (an interactive view); :meth:`release` frees it.

    Attributes:
        vertex_array: the buffers bound to the program they were uploaded for (the forward ``surface``
            program); ``None`` for a mesh without triangles.
        depth_vertex_array: the same buffers bound to the depth pre-pass's program (made on first use).
    """

    mesh: Mesh
    buffers: dict[str, moderngl.Buffer]
    index_buffer: moderngl.Buffer | None
    vertex_array: moderngl.VertexArray | None
    depth_vertex_array: moderngl.VertexArray | None = None

    @property
    def empty(self) -> bool:
        """No triangles: nothing to draw."""
        return self.vertex_array is None

    def vertex_array_for(self, program: moderngl.Program) -> moderngl.VertexArray:
        """A new vertex array binding these buffers to ``program``'s attributes (one that the compiler dropped
        is left out); the caller releases it."""
        return bind_vertex_array(program, self.buffers, self.index_buffer)

    def release(self) -> None:
        for vertex_array in (self.vertex_array, self.depth_vertex_array):
            if vertex_array is not None:
                vertex_array.release()
        for buffer in self.buffers.values():
            buffer.release()
        if self.index_buffer is not None:
            self.index_buffer.release()
        self.buffers.clear()
        self.vertex_array = self.depth_vertex_array = self.index_buffer = None


def bind_vertex_array(program: moderngl.Program, buffers: dict[str, moderngl.Buffer],
                      index_buffer: moderngl.Buffer | None) -> moderngl.VertexArray:
    """``buffers`` bound to ``program``'s attributes (32-bit indices)."""
    content = [(buffers[attribute], "3f", attribute) for attribute, _ in ATTRIBUTES if attribute in program]
    return program.ctx.vertex_array(program, content, index_buffer=index_buffer, index_element_size=4)


def upload_mesh(ctx: moderngl.Context, program: moderngl.Program, mesh: Mesh) -> MeshBuffers:
    """Upload ``mesh`` and bind it to ``program`` (the caller releases the result)."""
    if not isinstance(mesh, Mesh):
        raise GratNetError(f"expected a viewer.meshes.Mesh, got {type(mesh).__name__}")
    buffers: dict[str, moderngl.Buffer] = {}
    if mesh.triangle_count == 0:
        return MeshBuffers(mesh, buffers, None, None)
    for attribute, field in ATTRIBUTES:
        buffers[attribute] = ctx.buffer(np.ascontiguousarray(getattr(mesh, field)).tobytes())
    index_buffer = ctx.buffer(np.ascontiguousarray(mesh.indices).tobytes())
    return MeshBuffers(mesh, buffers, index_buffer, bind_vertex_array(program, buffers, index_buffer))


def set_surface_uniforms(program: moderngl.Program, camera: Camera, light: Light, width: int, height: int,
                         exposure: float, ior: float | None,
                         slope_covariance: tuple[float, float, float] = NO_SHADOWING) -> None:
    """The camera (view-projection for a ``width`` × ``height`` image, eye in metres), the light (kind,
    direction or position, irradiance), the exposure, the Fresnel IOR (``None`` or 0: off) and the material's
    slope covariance (Smith's shadowing, gratnet.shadowing) of ``shaders/surface.glsl``, checked first (one-line
    GratNetError)."""
    if not isinstance(camera, Camera):
        raise GratNetError(f"expected a viewer.camera.Camera, got {type(camera).__name__}")
    if not isinstance(light, Light):
        raise GratNetError(f"expected a viewer.camera.Light, got {type(light).__name__}")
    if not math.isfinite(exposure) or exposure < 0.0:
        raise GratNetError(f"exposure must be a finite number ≥ 0, got {exposure!r}")
    set_uniform(program, "u_view_projection", np.ascontiguousarray(camera.view_projection(width / height)))
    set_uniform(program, "u_eye", tuple(float(c) for c in camera.eye()))
    for name, value in light_kind(light.kind).uniforms(light.vector, light.intensity).items():  # shaders/lights.glsl
        set_uniform(program, name, value)
    set_uniform(program, "u_exposure", float(exposure))
    set_uniform(program, "u_ior", ior_uniform(ior))
    set_uniform(program, "u_slope_covariance", check_slope_covariance(slope_covariance))
