"""Freed memory handed back to the operating system after the product is built.

The builder allocates and frees arrays of one entry per transition or choice, megabytes
to hundreds of megabytes each. glibc serves most of them from its heap (its threshold
for a separate mapping rises to 32 MB once such a mapping is freed) and keeps what the
builder frees as holes that the solvers' arrays, of other sizes, do not fit: the process
stays larger than what it holds. ``malloc_trim(0)`` returns every free page inside the
heap to the system; :func:`release_free_memory` is called between the build and the
analysis, after the interval iteration (larger products), and after each LP
(``routes/plain._trimmed``), for products of at least a million transitions. On the
events family at 1.56M states (39M transitions) the first took the peak from 60.5 to
53.8 bytes a transition, for the trim's 38 ms and the pages the analysis then touches
afresh. Trimming again between the later stages freed no more at peak there and cost
5-10% of the solve stage at 1e5 states in pages touched again
(``experiments/bench_sweeps.py``); on bus n64 d10 (8.3M transitions) a trim before the
certificate took the peak from 54.6-55.1 to 49.1-50.5 bytes a transition for 10-14% more
solve time, and on events n32 d4 nothing. On issue 45's sensed case (1.08M transitions,
two LPs, the peak at the LPs' ends; its moves not packed yet) the trims after the LPs
took the peak from 112 to 103 bytes a transition for some 3% of its solve stage
(``experiments/bench_qvbs.py``); after the interval iteration nothing there (the first
LP fills its pages again), but on the bus family, whose LPs keep their chains' SuperLU
factorisations for the certificates, a trim after the iteration took the peak at the
LP's end from 51.5 to 46.6-48.0 bytes a transition (n64 d3) and from 49.9 to 44.2-45.8
(n128 d3), for a 2 and a 7 ms trim (``experiments/bench_sweeps.py``); the n64 trim cost
4.5-5.3% of its solve CPU in pages faulted in again (about 3% measured again later,
for a peak under 50 bytes a transition), n128's nothing, so the plain route trims there
from 1M transitions (``routes/plain.TRIM_BEFORE_LP_FROM``). A fixed
``M_MMAP_THRESHOLD`` of 128 KiB (every larger array its own mapping, handed back when
freed) took bus n64 d10 from 66 to 54.5 bytes a transition (numba loaded then, as it no
longer is there) but the product build to 2.1-2.5x its CPU, every array faulted in
afresh; 1-16 MiB saved nothing. On the sensed case, set to 1 MiB from the analysis on,
it took that peak from 103 to 93 bytes a transition for 10-20% more solve CPU, and it
cannot be undone (glibc's threshold stays fixed for the process), so it is not done.
Dask's workers trim the same way. With another C library (macOS, musl) it does nothing.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from functools import cache

__all__ = ["release_free_memory"]


@cache
def _malloc_trim() -> Callable[[int], int] | None:
    """glibc's ``malloc_trim``, or None where the C library has none."""
    if not sys.platform.startswith("linux"):
        return None
    import ctypes

    try:
        trim = ctypes.CDLL(None).malloc_trim  # the C library the process runs on
    except (OSError, AttributeError):  # musl and others have no malloc_trim
        return None
    trim.argtypes = [ctypes.c_size_t]
    trim.restype = ctypes.c_int
    return trim


def release_free_memory() -> bool:
    """Give the heap's free pages back to the system; whether the C library could."""
    trim = _malloc_trim()
    if trim is None:
        return False
    trim(0)
    return True
