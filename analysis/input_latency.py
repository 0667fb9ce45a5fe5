"""Which frame answered each input: injected pointer motions matched to the first frame whose picture reflects
them (benchmarks/viewer_latency.py records the frames and the motions; issue 35: the old matching by summed drag
pixels reported latencies down to −12.3 s)."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any


@dataclasses.dataclass
class FrameRecord:
    """One window frame as the benchmark saw it.

    Attributes:
        swapped: ``time.perf_counter()`` right after its buffer swap (the picture is on screen).
        pointer_x: the pointer's screen column of the last drag the frame applied (None: it applied none).
        shown_state_frame: the index of the frame whose input produced the state of the picture on show
            (None: no picture yet).
    """

    swapped: float
    pointer_x: float | None = None
    shown_state_frame: int | None = None


def match_inputs(injected: Sequence[tuple[float, float]], frames: Sequence[FrameRecord]) -> dict[str, Any]:
    """Each injected motion (``(time stamp, screen column)``, in order) matched to the first frame whose
    picture reflects it.

    Frame f *consumed* motions 0 … j when the last drag it applied left the pointer at motion j's column
    (searched forward from the motion consumed before: the path goes right and back, so a column recurs,
    but never between two frames that both see it; a column that no motion from there on has is counted in
    ``unmatched_drags``). A picture reflects the motions consumed by the frame that made its state; motion k
    is answered by the first frame (in order) on whose swap a picture reflecting k is on show. Its latency
    is that swap's time minus k's stamp (taken before the motion was sent: never negative, else the match
    is wrong and ``negative`` counts it).

    Returns:
        ``{"latency_s": [seconds or None per motion], "answered_by": [frame index or None], "consumed":
        [motions consumed through each frame], "unmatched_drags": int, "negative": int, "applied_s": [seconds
        to the swap of the frame that consumed each motion (its state changed then; its picture may follow
        later, e.g. while a new material's shader compiles), or None]}``.
    """
    columns = [column for _, column in injected]
    consumed: list[int] = []
    count = unmatched = 0
    for frame in frames:
        if frame.pointer_x is not None:
            found = next((index for index in range(count, len(columns))
                          if abs(columns[index] - frame.pointer_x) < 0.5), None)
            if found is None:
                unmatched += 1
            else:
                count = found + 1
        consumed.append(count)
    applied: list[float | None] = [None] * len(injected)  # the swap of the frame that consumed it
    next_motion = 0
    for index, frame in enumerate(frames):
        while next_motion < min(consumed[index], len(injected)):
            applied[next_motion] = frame.swapped - injected[next_motion][0]
            next_motion += 1
    latency: list[float | None] = [None] * len(injected)
    answered_by: list[int | None] = [None] * len(injected)
    next_motion = 0
    for index, frame in enumerate(frames):
        if frame.shown_state_frame is None:
            continue
        reflected = consumed[frame.shown_state_frame]
        while next_motion < min(reflected, len(injected)):
            latency[next_motion] = frame.swapped - injected[next_motion][0]
            answered_by[next_motion] = index
            next_motion += 1
    negative = sum(1 for value in latency if value is not None and value < 0.0)
    return {"latency_s": latency, "answered_by": answered_by, "consumed": consumed, "unmatched_drags": unmatched,
            "negative": negative, "applied_s": applied}
