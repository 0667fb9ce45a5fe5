"""How the viewer spends a frame: the resolution policy, its cost model, and the pictures in progress.

A CPU rasterizer renders a full picture in seconds, so the viewer (:class:`viewer.app.ViewerApp`) renders
reduced while the view moves (:meth:`ResolutionPolicy.reduced_factor`), refines in bands of rows once it
stands still (:meth:`ResolutionPolicy.band_rows`, :class:`BandCamera`, :class:`Refinement`), then adds
sub-pixel samples band by band (:class:`Accumulation`). The cost model predicts a render's seconds from
the measured seconds per "effective pixel": a covered pixel counts 1, an uncovered one
:data:`UNCOVERED_COST` (the network runs only where the mesh covers). Pure numpy: no GL, no glfw, no imgui.

## How the viewer spends its frames (viewer.app)

Staying responsive on a CPU rasterizer (issue 35: Mesa llvmpipe, 2 cores; a covered pixel of a shipped
feature-grid network costs 30–75 µs, so a 512² disc holds ~9 s of work):

- The window renders on the deferred path there (:func:`viewer.compile_worker.window_render_path`: the
  network once per covered pixel), its renders padded to power-of-two sizes
  (:func:`viewer.scheduling.padded_size`: the compute kernels' variant the compile child warmed).
- While the state keeps changing (a slider or the mouse moving, and for ``idle_seconds`` after the last
  change), every new state is rendered at a reduced resolution: the smallest of 1/2 … 1/32 whose
  predicted cost fits ``interactive_budget_s`` (the cost model: measured seconds per covered pixel × the
  covered pixels of the last preview; before any measurement a preview of at most 1024 pixels).
  Previews of the built-in disc and sphere use coarser tessellations (on the forward path llvmpipe's
  cost per triangle dominates at low resolution).
- Once the state has stood still, the full-resolution picture is built in horizontal bands (the same
  camera with clip space cropped to the band's rows: the same pixel centres as one full render), one
  band per frame sized to ``refine_budget_s``; the window keeps handling input between bands, the
  preview stays on show under the bands not yet done, and any change abandons the refinement.
  (BRDF-slice mode doubles the resolution per level up to full, each level in bands of rows that fit
  ``refine_budget_s``: a scissor box limits the slice render to the band's rows.)
- Progressive anti-aliasing (issue 12; ``max_samples``, the panel's "samples" choice): once a mesh view's
  full-resolution picture is complete and the view stands still, each further step adds the next sub-pixel
  sample (:func:`viewer.antialias.sample_offsets`, the offsets of ``gratnet render --spp``) in bands of rows
  sized like the refinement's, into float32 sums, and shows their mean, until ``max_samples`` (not while a
  faster program for the view still compiles in the background: that compile gets the CPU); any change
  of the view starts again from the 1-sample preview. Previews and refinement bands are 1 sample (the pixel
  centre), so interaction costs what it did. The mean of k samples equals ``SceneRenderer.render(...,
  samples=k)`` (tests/runtime/test_viewer.py). BRDF-slice mode stays at 1 sample.
- When the picture is complete (and has its samples) and nothing changes, nothing is rendered, and the
  window sleeps in ``glfw.wait_events_timeout`` instead of spinning.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from viewer.camera import Camera

__all__ = ["UNCOVERED_COST", "Accumulation", "BandCamera", "Frame", "Refinement", "RenderStats", "ResolutionPolicy",
           "disc_coverage", "effective_pixels", "effective_pixels_per_row", "first_band_margin", "padded_size",
           "reduced_size", "upscale"]


#: Cost of a pixel the mesh does not cover, relative to a covered one (the network runs only where covered).
UNCOVERED_COST = 0.05


@dataclasses.dataclass(frozen=True)
class ResolutionPolicy:
    """When to render reduced, when and how fast to refine (see the module docstring).

    Attributes:
        idle_seconds: the state is "moving" until it has not changed for this long.
        interactive_budget_s: target time of one reduced-resolution render while moving.
        refine_budget_s: target time of the refinement work done in one frame (one band). Predictions
            were seen 1.7–2x short on a busy CPU, and a frame must stay under 150 ms (issue 11).
        factors: the allowed reductions (divisors of width and height), smallest first. On a CPU rasterizer
            a covered pixel of a feature-grid network costs 30–75 µs (Mesa llvmpipe, 2 cores; issue 35): a
            512² picture holds ~9 s of work, so a preview that fits the budget is 1/16 (32²).
        default_factor: used before anything has been measured for a material and mesh; ``None``: the
            smallest factor whose preview has at most ``first_preview_pixels`` pixels.
        first_preview_pixels: see ``default_factor`` (1024 pixels: ~40 ms at the slowest rate measured).
        band_multiple: band heights are multiples of this where the network runs per fragment (the forward
            path and the BRDF slice): llvmpipe shades pixels in 2×2 quads, so one row costs as much as two
            (a 512-pixel-wide slice of paper-cd: 1 row 83 ms, 2 rows 86, 4 rows 130, 8 rows 283 at load 6.7).
            The deferred path runs the network per covered pixel: its bands take any height.
    """

    idle_seconds: float = 0.25
    interactive_budget_s: float = 0.05
    refine_budget_s: float = 0.05  # with the frame's other work, a 3x margin to the 150 ms target
    factors: tuple[int, ...] = (2, 4, 8, 16, 32)
    default_factor: int | None = None
    first_preview_pixels: int = 1024
    band_multiple: int = 2

    def first_factor(self, size: tuple[int, int]) -> int:
        """The factor of a preview before anything was measured: ``default_factor``, or the smallest whose
        preview of a ``size`` picture has at most ``first_preview_pixels`` pixels (else the largest)."""
        if self.default_factor is not None:
            return self.default_factor
        for factor in self.factors:
            width, height = reduced_size(size, factor)
            if width * height <= self.first_preview_pixels:
                return factor
        return self.factors[-1]

    def reduced_factor(self, full_seconds: float | None, size: tuple[int, int] = (512, 512)) -> int:
        """The smallest factor whose render is predicted to fit the interactive budget (else the largest),
        given the predicted time of a full-resolution render of ``size`` (``None``: nothing measured yet:
        :meth:`first_factor`)."""
        if full_seconds is None:
            return self.first_factor(size)
        for factor in self.factors:
            if full_seconds / factor**2 <= self.interactive_budget_s:
                return factor
        return self.factors[-1]

    def band_rows(self, row_seconds: np.ndarray, multiple: int | None = None, power_of_two: bool = False) -> int:
        """Rows of the next refinement band: as many of the remaining rows (their predicted seconds, in
        order) as fit ``refine_budget_s``, rounded down to a multiple of ``multiple`` (default
        ``band_multiple``; at least that many) or, with ``power_of_two``, to a power of two; all the remaining
        rows when they fit or are fewer."""
        multiple = self.band_multiple if multiple is None else max(1, int(multiple))
        remaining = len(row_seconds)
        fits = int(np.searchsorted(np.cumsum(row_seconds), self.refine_budget_s, side="right"))
        if fits >= remaining:
            return max(1, remaining)
        if power_of_two:
            return min(remaining, 1 << max(0, fits.bit_length() - 1))
        rows = max(multiple, fits - fits % multiple)
        return max(1, min(remaining, rows))


def reduced_size(size: tuple[int, int], factor: int) -> tuple[int, int]:
    return max(1, math.ceil(size[0] / factor)), max(1, math.ceil(size[1] / factor))


@dataclasses.dataclass
class Frame:
    """The picture on show.

    Attributes:
        key: the state and size it shows (``ViewerApp.render_key``).
        pixels: display sRGB ``uint8`` ``(h, w, 3)``, row 0 at the top (``h, w`` = ``rendered_size`` for a
            preview, the full size while refining and when complete).
        full_size: ``(width, height)`` that the picture stands for (a preview is shown stretched to it).
        rendered_size: the resolution the newest pixels were computed at.
        complete: every pixel is at full resolution.
        progress: the fraction of the full-resolution picture done (1 when complete).
        version: increases whenever ``pixels`` change (the window re-uploads its texture then).
        samples: samples per pixel of the complete picture (progressive anti-aliasing: the mean of that many
            full-resolution samples; while the next one is added band by band, its rows already hold it).
    """

    key: tuple[Any, ...]
    pixels: np.ndarray
    full_size: tuple[int, int]
    rendered_size: tuple[int, int]
    complete: bool
    progress: float
    version: int
    samples: int = 1


@dataclasses.dataclass
class RenderStats:
    """Counts and times of the SceneRenderer calls (a band counts as one render)."""

    renders: int = 0
    preview_renders: int = 0
    refine_renders: int = 0
    last_kind: str = ""
    last_render_s: float = 0.0
    last_render_size: tuple[int, int] = (0, 0)
    last_preview_s: float | None = None
    last_preview_size: tuple[int, int] = (0, 0)
    last_full_s: float | None = None  # the sum of a completed refinement's renders
    last_sample_s: float | None = None  # the last band of progressive anti-aliasing (one more sample)
    #: The window's last frame from the end of its wait for input to the buffer swap: the work of the
    #: frame (events, panel, any render, drawing), not the idle wait (set by ViewerWindow).
    last_frame_s: float = 0.0
    weights_path: str = ""  # the weights path of the last render


@dataclasses.dataclass(frozen=True)
class BandCamera(Camera):
    """The camera restricted to rows ``[row0, row1)`` of a ``height``-row image: the same pixel centres,
    rasterized into a ``row1 − row0``-row target (a crop of clip space after the projection).

    ``width_fraction`` and ``height_fraction`` < 1 put that band into the top-left corner of a larger target
    (a ``width / width_fraction`` × ``(row1 − row0) / height_fraction`` one), its pixel centres unchanged: the
    viewer pads its deferred renders to power-of-two sizes (:func:`padded_size`)."""

    full_aspect: float = 1.0
    height: int = 1
    row0: int = 0
    row1: int = 1
    width_fraction: float = 1.0
    height_fraction: float = 1.0

    def view_projection(self, aspect: float) -> np.ndarray:  # noqa: ARG002 - the band's own aspect is wrong
        full = super().view_projection(self.full_aspect)
        scale = self.height / (self.row1 - self.row0)
        centre = 1.0 - (self.row0 + self.row1) / self.height  # band centre in NDC y (+1 = top row's edge)
        crop = np.eye(4, dtype=np.float64)
        crop[1, 1] = scale
        crop[3, 1] = -scale * centre  # row vectors: y' = scale · (y − centre · w)
        if self.width_fraction != 1.0 or self.height_fraction != 1.0:  # into the target's top-left corner
            corner = np.eye(4, dtype=np.float64)
            corner[0, 0], corner[3, 0] = self.width_fraction, self.width_fraction - 1.0
            corner[1, 1], corner[3, 1] = self.height_fraction, 1.0 - self.height_fraction
            crop = crop @ corner
        return np.asarray(full.astype(np.float64) @ crop, dtype=np.float32)


def padded_size(size: tuple[int, int]) -> tuple[int, int]:
    """The smallest power-of-two width and height that hold ``size``. Mesa llvmpipe compiles a compute shader
    anew for images whose sides are or are not powers of two (its variant key): the deferred path's network
    kernel took 0.6–1.0 s (paper-cd, texture weights; ~25 s for a baked net) at the first band of a size of
    the other kind, in the window's frame. Rendered padded, every picture uses the variant the compile child
    warmed (issue 35). The padding shows the scene beyond the picture, rendered too where the mesh reaches
    into it: the viewer's deferred bands take power-of-two heights (:meth:`ResolutionPolicy.band_rows`), so that
    a band of a picture of power-of-two width needs none."""
    width, height = (1 << max(0, int(side) - 1).bit_length() for side in size)
    return width, height


@dataclasses.dataclass
class Refinement:
    """A full-resolution picture being built band by band over the upscaled preview (slice mode: level
    by level, each half the reduction of the last)."""

    key: tuple[Any, ...]
    pixels: np.ndarray
    next_row: int = 0
    next_factor: int = 1  # slice mode: the next (smaller) reduction factor
    seconds: float = 0.0
    xyz: np.ndarray | None = None  # mesh mode: the full-resolution exposed XYZ so far (float32)


@dataclasses.dataclass
class Accumulation:
    """Progressive anti-aliasing of a still mesh view: float32 sums of the exposed XYZ of samples 0 … k−1
    (``sums``, ``k`` = ``samples``) and, for rows before ``next_row``, sample k (``partial``)."""

    key: tuple[Any, ...]
    sums: np.ndarray
    samples: int = 1
    next_row: int = 0
    partial: np.ndarray | None = None


def effective_pixels(coverage: np.ndarray) -> float:
    covered = float(np.count_nonzero(coverage > 0.5))
    return covered + UNCOVERED_COST * (coverage.size - covered)


def first_band_margin(row0: int) -> float:
    """Prediction factor for a band: 2 for a refinement's (or a slice level's) first band, whose prediction
    comes from renders at a lower resolution only (1.7× too short once, measured on a busy machine)."""
    return 2.0 if row0 == 0 else 1.0


def effective_pixels_per_row(coverage: np.ndarray) -> np.ndarray:
    return np.sum(np.where(coverage > 0.5, 1.0, UNCOVERED_COST), axis=1)


def disc_coverage(side: int, rows: tuple[int, int] | None = None) -> np.ndarray:
    """1 where a ``side``² BRDF slice's pixel centre lies inside the unit disc (where the network runs), else
    0; only ``rows`` (first, end) when given."""
    first, end = (0, side) if rows is None else rows
    centres = (np.arange(side) + 0.5) / side * 2.0 - 1.0
    y = centres[first:end, None]
    return (centres[None, :] ** 2 + y**2 <= 1.0).astype(np.float32)


def upscale(pixels: np.ndarray, width: int, height: int) -> np.ndarray:
    """Nearest-neighbour resize of an ``(h, w, 3)`` image to ``(height, width, 3)`` (a new array)."""
    rows = np.minimum((np.arange(height) * pixels.shape[0]) // height, pixels.shape[0] - 1)
    columns = np.minimum((np.arange(width) * pixels.shape[1]) // width, pixels.shape[1] - 1)
    return np.ascontiguousarray(pixels[rows][:, columns])
