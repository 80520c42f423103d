"""release_free_memory gives the heap's free pages back (on glibc): in a fresh process,
a heap with 100 MB of holes shrinks by most of them."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

PROBE = """
import os
import numpy as np
from mitld_lp.util.heap import release_free_memory

def resident():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")

import ctypes
# glibc serves allocations below M_MMAP_THRESHOLD (-3) from its heap.  Set here: the
# threshold glibc raises on its own when a 20 MB mapping is freed (what this probe did
# before) stayed low in two whole-suite runs of five on two workers, the 1 MB arrays were
# mappings of their own, freed at once, and there were no holes to give back
assert ctypes.CDLL(None).mallopt(-3, 32 << 20) == 1
arrays = [np.ones(1_000_000 // 8 + i) for i in range(200)]  # 200 MB of 1 MB arrays
del arrays[::2]  # every other one freed: 100 MB of holes inside the heap
before = resident()
print(release_free_memory(), before, resident())
"""


def _glibc() -> bool:
    import ctypes

    try:
        ctypes.CDLL(None).malloc_trim  # noqa: B018 - only whether the symbol exists
    except (OSError, AttributeError):
        return False
    return True


@pytest.mark.skipif(not (sys.platform.startswith("linux") and _glibc()),
                    reason="malloc_trim is glibc's")
def test_free_pages_inside_the_heap_go_back_to_the_system():
    run = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True,
                         cwd=ROOT, timeout=120, check=True)
    done, before, after = run.stdout.split()
    assert done == "True"
    assert int(before) > 200e6  # the 100 MB of holes are in the heap, resident
    assert int(before) - int(after) > 80e6  # of the 100 MB of holes


def test_elsewhere_it_says_it_could_not(monkeypatch):
    from mitld_lp.util import heap

    monkeypatch.setattr(heap.sys, "platform", "darwin")
    heap._malloc_trim.cache_clear()
    try:
        assert heap.release_free_memory() is False
    finally:
        heap._malloc_trim.cache_clear()
