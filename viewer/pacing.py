"""Long GPU work in short GL calls, so that Ctrl-C is answered within a second (issue 36).

moderngl holds the GIL through every GL call, and a CPU rasterizer (Mesa llvmpipe) runs a whole draw or
dispatch inside the call that submits it (or the ``finish`` after it): a 1024² mesh draw of the shipped
network takes tens of seconds there, and a SIGINT only becomes a ``KeyboardInterrupt`` once the call returns.
The renderers therefore split their work into *pieces* — bands of rows drawn with a scissor box, ranges of the
deferred path's pixel list — and finish each one (``ctx.finish()``) before the next: Python gets control
between pieces, raises a pending ``KeyboardInterrupt``, and the renderer's ``finally`` blocks free the GL
objects. A scissor box and a sub-range of a list change which pixels a call computes, never how: the pieces
together give the unsplit result bit for bit.

:class:`Pacer` sizes the pieces from measured time: each piece is predicted to take :data:`PIECE_SECONDS`
from the rate (seconds per unit of cost) of the piece before, starting small and growing at most
:data:`GROWTH` times per piece. Costs are per unit and differ between units, since the network runs only where
the mesh covers a pixel: a uniform guess grew over cheap background into pieces of seconds once it reached the
mesh. So the units are weighed: the forward path's shading pass by the pixels its depth pass covered, per
:class:`Blocks` of 64×4 pixels (rows alone would not do: 4 rows of a 16384-pixel-wide image are seconds of
network on llvmpipe); a BRDF slice's blocks by their pixels inside the unit disc; the passes before any
coverage is known (the depth pass, the deferred G-buffer and compaction) by rows, from the mesh's triangles
projected on the CPU (:func:`projected_row_costs`). Read-backs go in pieces too (:func:`read_rows`).

Two calls must not be interrupted half-way at all (:func:`sigint_deferred`): moderngl's program creation, which
calls back into Python (a KeyboardInterrupt there crashed the process), and tqdm's refresh. A shader's first
compile on llvmpipe is one long call that cannot be split (~25 s for a baked 28k-MAC network on a cold Mesa
cache): the ``gratnet`` command's supervisor (gratnet/interrupts.py) stops it within a second of Ctrl-C.

Rendering only: no glfw, no imgui, no torch.
"""

from __future__ import annotations

import contextlib
import math
import signal
import time
from collections.abc import Callable, Iterator

import moderngl
import numpy as np

__all__ = ["BLOCK", "GROWTH", "PIECE_SECONDS", "READ_BYTES", "Blocks", "Pacer", "Progress", "covered_block_costs",
           "disc_block_costs", "projected_row_costs", "read_rows", "sigint_deferred"]

#: The time one piece of GPU work is sized to take (seconds): a Ctrl-C waits for the piece under way.
PIECE_SECONDS = 0.2
#: The most a piece's predicted cost may exceed the cost of the piece measured before it.
GROWTH = 4.0

#: A render's progress report: the fraction of its work done, 0 … 1.
Progress = Callable[[float], None]


class Pacer:
    """Consecutive pieces of one kind of GPU work, each about :data:`PIECE_SECONDS` long (see the module
    docstring). One pacer may serve several jobs of the same kind (a render's samples, its chunks): the rate
    measured in one sizes the first piece of the next.

    Args:
        ctx: the context whose work is finished after each piece.
        first_cost: the cost of the first piece (in the units' cost; units of cost 1 when uniform).
        seconds: the time a piece is sized to take.
    """

    def __init__(self, ctx: moderngl.Context, first_cost: float, seconds: float = PIECE_SECONDS) -> None:
        if not (first_cost > 0.0 and seconds > 0.0):
            raise ValueError(f"first_cost and seconds must be positive, got {first_cost!r}, {seconds!r}")
        self.ctx = ctx
        self.seconds = seconds
        self.rate: float | None = None  # seconds per unit of cost, of the last measured piece
        self.budget = float(first_cost)  # the next piece's cost
        self.pieces_done = 0
        self.longest = 0.0  # the longest piece so far (seconds, submission to finish)

    def fits(self, cost: float) -> bool:
        """Whether work of this cost makes one piece: then its costs per unit need not be worked out."""
        return self.budget >= cost

    def pieces(self, total: int, costs: np.ndarray | None = None, multiple: int = 1,
               done: Callable[[int], None] | None = None) -> Iterator[tuple[int, int]]:
        """``(start, end)`` ranges covering ``0 … total``; the caller submits the GPU work of each before asking
        for the next, and the pacer finishes it and times it then.

        Args:
            costs: the relative cost of each unit (``(total,)``; default 1 each), e.g. the covered pixels of a row.
            multiple: piece boundaries fall on multiples of this (the last piece ends at ``total``).
            done: called with ``end`` after each piece is finished.
        """
        cumulative = None if costs is None else np.concatenate(([0.0], np.cumsum(np.asarray(costs, np.float64))))
        start = 0
        while start < total:
            end = self._end(start, total, cumulative, max(1, int(multiple)))
            began = time.perf_counter()
            yield start, end
            self.ctx.finish()
            elapsed = time.perf_counter() - began
            self.longest = max(self.longest, elapsed)
            cost = float(end - start) if cumulative is None else float(cumulative[end] - cumulative[start])
            self._measured(cost, elapsed)
            start = end
            if done is not None:
                done(end)

    def _end(self, start: int, total: int, cumulative: np.ndarray | None, multiple: int) -> int:
        """The end of the piece from ``start`` whose cost fits :attr:`budget` (at least ``multiple`` units)."""
        if cumulative is None:
            end = start + int(self.budget)
        else:
            end = int(np.searchsorted(cumulative, cumulative[start] + self.budget, side="right")) - 1
        end = max(start + multiple, end - end % multiple)
        return min(total, end)

    def _measured(self, cost: float, elapsed: float) -> None:
        """Size the next piece from this one: :attr:`seconds` at this piece's rate, at most :data:`GROWTH`
        times this piece's cost (and never less than a 16th of it: one slow piece on a busy CPU must not
        shrink the rest to slivers)."""
        self.pieces_done += 1
        if cost <= 0.0:
            return
        self.rate = max(elapsed, 1e-6) / cost
        target = self.seconds / self.rate
        self.budget = max(1.0, min(GROWTH * max(cost, self.budget), max(target, cost / 16.0)))
        if not math.isfinite(self.budget):
            self.budget = cost


#: The smallest piece of a 2-D pass: columns × rows (llvmpipe bins 64×64 tiles and shades 4×4 blocks).
BLOCK = (64, 4)
#: Bytes one ``glReadPixels`` of :func:`read_rows` reads at most (a whole 8192² RGBA32F image is 1 GiB).
READ_BYTES = 1 << 25


def read_rows(framebuffer: moderngl.Framebuffer, size: tuple[int, int], attachment: int = 0,
              components: int = 4) -> np.ndarray:
    """``framebuffer``'s ``attachment`` (−1: the depth) as ``float32`` ``(H, W, components)`` in GL row order
    (row 0 at the bottom), read in pieces of at most :data:`READ_BYTES` (each a short call)."""
    width, height = size
    out = np.empty((height, width, components), dtype=np.float32)
    rows = max(1, READ_BYTES // (4 * components * width))
    for first in range(0, height, rows):
        count = min(rows, height - first)
        framebuffer.read_into(out[first:first + count], viewport=(0, first, width, count), components=components,
                              attachment=attachment, dtype="f4")
    return out


class Blocks:
    """A rectangle of pixels cut into blocks of :data:`BLOCK` (the last column and row of blocks may be smaller),
    numbered row by row: the units of a 2-D pass's pieces. Rows of blocks alone would not do: 4 rows of a
    16384-pixel-wide image are 65536 pixels, seconds of network on llvmpipe.

    Args:
        width: the rectangle's width (from x = 0).
        rows: ``(first, end)`` GL rows (from the bottom) of the rectangle.
    """

    def __init__(self, width: int, rows: tuple[int, int]) -> None:
        self.width = width
        self.first, self.end = rows
        self.columns = -(-width // BLOCK[0])
        self.block_rows = -(-(self.end - self.first) // BLOCK[1])
        self.count = self.columns * self.block_rows

    def rectangles(self, start: int, end: int) -> list[tuple[int, int, int, int]]:
        """Blocks ``start … end − 1`` as at most three scissor boxes ``(x, y, width, height)`` (GL pixels): the
        rest of a first row of blocks, whole rows, the start of a last row."""
        boxes = []
        while start < end:
            row, column = divmod(start, self.columns)
            if column == 0 and end - start >= self.columns:  # whole rows of blocks
                rows = (end - start) // self.columns
                boxes.append(self._box(row, rows, 0, self.columns))
                start += rows * self.columns
            else:  # a part of one row of blocks
                stop = min(end - row * self.columns, self.columns)
                boxes.append(self._box(row, 1, column, stop))
                start = row * self.columns + stop
        return boxes

    def _box(self, row: int, rows: int, column: int, stop: int) -> tuple[int, int, int, int]:
        y = self.first + row * BLOCK[1]
        x = column * BLOCK[0]
        return x, y, min(self.width, stop * BLOCK[0]) - x, min(self.end, y + rows * BLOCK[1]) - y

    def costs(self, counts: np.ndarray) -> np.ndarray:
        """Per block (in order), the cost of shading it: 1 per pixel where the network runs,
        :data:`viewer.scheduling.UNCOVERED_COST` per other pixel, from ``counts`` (``(rows, columns)``: per row
        of the rectangle, its pixels where the network runs in each column of blocks)."""
        from viewer.scheduling import UNCOVERED_COST

        rows = counts.shape[0]
        padded = np.zeros((self.block_rows * BLOCK[1], self.columns), dtype=np.float64)
        padded[:rows] = counts
        inside = padded.reshape(self.block_rows, BLOCK[1], self.columns).sum(axis=1)
        heights = np.minimum(BLOCK[1], rows - BLOCK[1] * np.arange(self.block_rows))
        widths = np.minimum(BLOCK[0], self.width - BLOCK[0] * np.arange(self.columns))
        return (inside + UNCOVERED_COST * (heights[:, None] * widths[None, :] - inside)).ravel()


def covered_block_costs(framebuffer: moderngl.Framebuffer, blocks: Blocks) -> np.ndarray:
    """:meth:`Blocks.costs` of the pixels ``framebuffer``'s depth covers (depth < 1, the clear value), read in
    pieces of at most :data:`READ_BYTES`."""
    rows = max(BLOCK[1], READ_BYTES // (4 * blocks.width) // BLOCK[1] * BLOCK[1])  # whole rows of blocks each
    padded = np.zeros((min(rows, blocks.end - blocks.first), blocks.columns * BLOCK[0]), dtype=bool)
    counts = np.empty((blocks.end - blocks.first, blocks.columns), dtype=np.int64)
    for first in range(blocks.first, blocks.end, rows):
        count = min(rows, blocks.end - first)
        depth = np.empty((count, blocks.width), dtype=np.float32)
        framebuffer.read_into(depth, viewport=(0, first, blocks.width, count), components=1, attachment=-1,
                              dtype="f4")
        padded[:count, :blocks.width] = depth < 1.0
        counts[first - blocks.first:first - blocks.first + count] = (
            padded[:count].reshape(count, blocks.columns, BLOCK[0]).sum(axis=2))
    return blocks.costs(counts)


def disc_block_costs(size: int, blocks: Blocks) -> np.ndarray:
    """:meth:`Blocks.costs` of a ``size``² BRDF slice: the pixels whose centre lies in the unit disc (where the
    material runs; the disc is symmetric, so GL rows count as rows from the top)."""
    centres = (np.arange(size, dtype=np.float64) + 0.5) / size * 2.0 - 1.0
    reach = np.sqrt(np.maximum(0.0, 1.0 - centres[blocks.first:blocks.end] ** 2))  # |x| ≤ reach inside the disc
    low = np.searchsorted(centres, -reach, side="left")[:, None]  # per row, the columns [low, high) are inside
    high = np.searchsorted(centres, reach, side="right")[:, None]
    starts = BLOCK[0] * np.arange(blocks.columns)[None, :]
    return blocks.costs(np.clip(np.minimum(high, starts + BLOCK[0]) - np.maximum(low, starts), 0, None))


def projected_row_costs(positions: np.ndarray, indices: np.ndarray, view_projection: np.ndarray,
                        size: tuple[int, int]) -> np.ndarray:
    """Per GL row (bottom up) of a ``size`` image of a mesh, the cost of rasterizing it, estimated on the CPU
    before anything is drawn: 1 per pixel of the row's 64-pixel column blocks that the triangles' bounding boxes
    (widened by a pixel for sub-pixel sample offsets) reach, :data:`viewer.scheduling.UNCOVERED_COST` per other
    pixel. A triangle reaching behind the camera counts as covering everything. ``view_projection``: world →
    clip, row vectors (viewer.camera's convention)."""
    from viewer.scheduling import UNCOVERED_COST

    width, height = size
    columns = -(-width // BLOCK[0])
    clip = np.c_[np.asarray(positions, np.float64), np.ones(len(positions))] @ np.asarray(view_projection, np.float64)
    triangles = np.asarray(indices, dtype=np.int64).reshape(-1, 3)
    w = clip[triangles, 3]
    ahead = np.all(w > 1e-9, axis=1)
    if not np.all(ahead):
        return np.full(height, float(width))
    x = (clip[triangles, 0] / w + 1.0) * 0.5 * width
    y = (clip[triangles, 1] / w + 1.0) * 0.5 * height
    x0 = (np.clip(np.floor(x.min(axis=1)) - 1, 0, width) // BLOCK[0]).astype(np.int64)
    x1 = (-(-np.clip(np.ceil(x.max(axis=1)) + 1, 0, width) // BLOCK[0])).astype(np.int64)
    y0 = np.clip(np.floor(y.min(axis=1)) - 1, 0, height).astype(np.int64)
    y1 = np.clip(np.ceil(y.max(axis=1)) + 1, 0, height).astype(np.int64)
    visible = (x1 > x0) & (y1 > y0)
    x0, x1, y0, y1 = x0[visible], x1[visible], y0[visible], y1[visible]
    stride, cells = columns + 1, (height + 1) * (columns + 1)  # a 2-D difference array of the boxes
    corners = np.concatenate((y0 * stride + x0, y1 * stride + x1, y0 * stride + x1, y1 * stride + x0))
    signs = np.repeat([1, 1, -1, -1], len(x0))
    boxes = np.bincount(corners, weights=signs, minlength=cells).reshape(height + 1, stride)
    reached = np.cumsum(np.cumsum(boxes, axis=0), axis=1)[:height, :columns] > 0.5
    block_widths = np.minimum(BLOCK[0], width - BLOCK[0] * np.arange(columns))
    covered = reached.astype(np.float64) @ block_widths
    return covered + UNCOVERED_COST * (width - covered)


@contextlib.contextmanager
def sigint_deferred() -> Iterator[None]:
    """A SIGINT (Ctrl-C) inside the block is handled right after it, by the handler that was in place (Python's
    raises KeyboardInterrupt); outside the main thread nothing is deferred.

    For calls that must not see a KeyboardInterrupt half-way: moderngl's program creation calls back into Python
    after the link, and a KeyboardInterrupt raised there crashed the process (segmentation fault, seen 0.3–2 s
    after Ctrl-C during a baked shader's compile on llvmpipe); tqdm's refresh leaves its bar on the screen.
    (Blocking the signal would not do: the process's other threads, e.g. llvmpipe's, would take it.)"""
    held: list[int] = []
    try:
        previous = signal.signal(signal.SIGINT, lambda number, _frame: held.append(number))
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if held and callable(previous):
            previous(signal.SIGINT, None)
        elif held and previous == signal.SIG_DFL:
            raise KeyboardInterrupt
