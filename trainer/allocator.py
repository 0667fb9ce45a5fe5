"""Keep freed memory in the process during CPU training (glibc's malloc), instead of handing it back each step.

A training step on the CPU allocates and frees the same large buffers every time: the feature grids' gradients
(a 251² × 21 × 4 grid is 21 MB of float32) and the batch's activations. glibc serves an allocation above its
mmap threshold with a fresh ``mmap`` and trims the heap top above its trim threshold on ``free``, so every step
page-faults those buffers in anew: measured on this project's 2-core machine, 10,335 minor faults per step at
batch 2,048 and a third of the trainer's CPU time in the kernel (docs/benchmarks.md, "Trainer: page faults").
Raising both thresholds (the mmap one to glibc's 32 MB ceiling) keeps the pages: 31 faults per step.
Allocations above 32 MB are still mapped fresh each time (glibc allows no higher threshold).
"""

from __future__ import annotations

import ctypes
import sys

#: mallopt parameters (malloc.h).
M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
#: glibc's largest mmap threshold on 64-bit (DEFAULT_MMAP_THRESHOLD_MAX = 4 MiB · sizeof(long)).
MMAP_THRESHOLD_BYTES = 32 * 1024 * 1024
#: Freed memory at the heap's top kept rather than returned: the largest int mallopt takes.
TRIM_THRESHOLD_BYTES = 2**31 - 1


def keep_freed_memory() -> bool:
    """Raise glibc malloc's mmap and trim thresholds for this process; True if both took, False where the C
    library is not glibc (musl, macOS, Windows: nothing is changed)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL("libc.so.6").mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)) and bool(mallopt(M_TRIM_THRESHOLD,
                                                                                   TRIM_THRESHOLD_BYTES))
