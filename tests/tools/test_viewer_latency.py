"""analysis.input_latency, benchmarks/viewer_latency.py's input matching: each injected motion goes to the first
frame whose picture reflects it (issue 35: the old matching by summed drag pixels reported latencies down to
−12.3 s)."""

from __future__ import annotations

import pytest

from analysis.input_latency import FrameRecord, match_inputs


def test_a_motion_is_answered_by_the_first_picture_that_reflects_it():
    injected = [(1.00, 102.0), (1.10, 104.0), (1.20, 106.0)]
    frames = [
        FrameRecord(swapped=0.9, shown_state_frame=0),  # before any motion: a picture of the start state
        FrameRecord(swapped=1.05, pointer_x=102.0, shown_state_frame=1),  # consumed and shown motion 0
        FrameRecord(swapped=1.5, pointer_x=106.0, shown_state_frame=1),  # consumed 1 and 2; the picture is old
        FrameRecord(swapped=1.6, shown_state_frame=2),  # the picture of frame 2's state
    ]
    matched = match_inputs(injected, frames)
    assert matched["consumed"] == [0, 1, 3, 3]
    assert matched["answered_by"] == [1, 3, 3]
    assert matched["latency_s"] == pytest.approx([0.05, 0.5, 0.4])
    assert matched["applied_s"] == pytest.approx([0.05, 0.4, 0.3])  # the frames that consumed them
    assert matched["negative"] == 0 and matched["unmatched_drags"] == 0


def test_a_column_on_the_way_back_matches_forward_only():
    # Right to 104, then back: 102 recurs; the frame after the turn has consumed the later 102.
    injected = [(1.0, 102.0), (1.1, 104.0), (2.0, 102.0), (2.1, 100.0)]
    frames = [FrameRecord(1.2, pointer_x=104.0, shown_state_frame=0),
              FrameRecord(2.05, pointer_x=102.0, shown_state_frame=1),
              FrameRecord(2.2, pointer_x=100.0, shown_state_frame=2)]
    matched = match_inputs(injected, frames)
    assert matched["consumed"] == [2, 3, 4]
    assert matched["latency_s"] == pytest.approx([0.2, 0.1, 0.05, 0.1])


def test_motions_never_shown_stay_unanswered_and_strange_columns_are_counted():
    injected = [(1.0, 102.0), (1.1, 104.0)]
    frames = [FrameRecord(1.05, pointer_x=102.0, shown_state_frame=None),  # no picture yet
              FrameRecord(1.2, pointer_x=999.0, shown_state_frame=0)]  # a column no motion had
    matched = match_inputs(injected, frames)
    assert matched["latency_s"] == [pytest.approx(0.2), None]
    assert matched["unmatched_drags"] == 1 and matched["negative"] == 0
