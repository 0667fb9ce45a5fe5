"""The viewer's ground truth: a material's volume beside its network, and the FLIP heat map between them.

``gratnet view --material paper-cd --reference paper-cd.exr`` loads the material's ground-truth volume (checked
against the material like ``gratnet render --reference``). The panel then shows one of :data:`SHADINGS`:

- ``network``: the trained network (as always);
- ``reference``: the volume looked up per pixel (:mod:`viewer.reference`), drawn with the network's own mesh
  buffers, camera, light, exposure, samples and bands, so that only the material differs;
- ``flip``: both, and LDR-FLIP between their display images as a heat map (magma, 0 black … 1 white); the
  panel shows the mean over the covered pixels. A band being refined is scored on its own rows (FLIP looks at
  neighbourhoods, so a band's edge rows differ slightly from a whole-picture score until the picture is complete,
  when the whole picture is scored again).

The volume belongs to one material: switching to another shows the network only. Rendering only: no glfw,
no imgui, no torch.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from gratnet.errors import GratNetError

__all__ = ["SHADINGS", "LoadedReference", "ReferenceView", "flip_heat_map"]

#: What the viewer shows: the network, the reference look-up, or the FLIP heat map between them.
SHADINGS = ("network", "reference", "flip")


@dataclasses.dataclass(frozen=True)
class LoadedReference:
    """A checked ground-truth volume (``viewer.scene_config.load_reference``) and what it belongs to."""

    volume: Any  # gratnet.volume.Volume
    path: str
    material: str
    precision: str = "float16"


def flip_heat_map(network_xyz: np.ndarray, reference_xyz: np.ndarray,
                  covered: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """``(pixels, mean)``: LDR-FLIP between the display images of two exposed XYZ images ``(H, W, 3)`` as an 8-bit
    magma heat map ``(H, W, 3)``, and its mean over ``covered`` (all pixels when None; 0 when none is covered)."""
    from matplotlib import colormaps

    from gratnet.display import ldr_flip, xyz_to_display_srgb8

    try:
        reference = xyz_to_display_srgb8(np.asarray(reference_xyz, dtype=np.float64)) / 255.0
        network = xyz_to_display_srgb8(np.asarray(network_xyz, dtype=np.float64)) / 255.0
        _, error = ldr_flip(reference, network)
    except ImportError as missing:
        raise GratNetError("the FLIP view needs flip-evaluator: pip install flip-evaluator") from missing
    pixels = (255.0 * colormaps["magma"](np.clip(error, 0.0, 1.0))[..., :3] + 0.5).astype(np.uint8)
    selected = error if covered is None else error[np.asarray(covered, dtype=bool)]
    return pixels, float(selected.mean()) if selected.size else 0.0


class ReferenceView:
    """The reference scene of one material on the viewer's context (compiled on first use; no MLP, so quick)."""

    def __init__(self, ctx: Any, loaded: LoadedReference) -> None:
        self.ctx = ctx
        self.loaded = loaded
        self._scene: Any = None

    def available(self, material: str) -> bool:
        """Whether the volume is ``material``'s (the only one it is the truth of)."""
        return material == self.loaded.material

    def scene(self) -> Any:
        """The reference :class:`~viewer.scene.SceneRenderer`, made on first use."""
        if self._scene is None:
            from viewer.scene import SceneRenderer

            self._scene = SceneRenderer(self.ctx, self.loaded.volume, reference_precision=self.loaded.precision)
        return self._scene

    def release(self) -> None:
        if self._scene is not None:
            self._scene.release()
            self._scene = None
