"""trainer/allocator.py: after keep_freed_memory, a step's large buffers are reused, not page-faulted in anew."""

from __future__ import annotations

import subprocess
import sys

import pytest

# A training step's pattern in miniature: a few buffers of a grid gradient's size (20 MB) allocated, written and
# freed together, again and again; prints the minor page faults per cycle. Run in a fresh interpreter: mallopt
# settings are process-wide and one-way, so the default allocator can only be measured in a process of its own.
CYCLES = """
import resource, sys
import numpy as np
if sys.argv[1] == "keep":
    from trainer.allocator import keep_freed_memory
    assert keep_freed_memory()
def cycle():
    buffers = [np.ones(5 << 20, dtype=np.float32) for _ in range(3)]
    del buffers
cycle()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(20):
    cycle()
print((resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / 20)
"""


def _faults_per_cycle(mode: str) -> float:
    done = subprocess.run([sys.executable, "-c", CYCLES, mode], capture_output=True, text=True, check=True)
    return float(done.stdout.strip())


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt: Linux only")
def test_freed_buffers_are_kept_instead_of_faulted_in_each_time():
    default, kept = _faults_per_cycle("default"), _faults_per_cycle("keep")
    assert default > 200  # glibc's own thresholds hand the pages back and fault them in again (measured ~1,000)
    assert kept < 20
