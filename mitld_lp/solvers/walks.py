"""Which graph walks run compiled: the NumPy walks of :mod:`~mitld_lp.solvers.graph`
ask :func:`compiled_walks` for the module of compiled ones
(:mod:`~mitld_lp.solvers.compiled_graph`, run from the kernel loader's cache or by
numba), by the size of the graph and whether compiled kernels are loaded already
(:func:`~mitld_lp.util.kernel_loader.compiled_paid`); a small solve never loads them
(its walks give the same results, only later).  This module imports nothing of the
solvers but the kernel loader (NumPy and the standard library)."""

from __future__ import annotations

from typing import Any

from mitld_lp.util import kernel_loader

__all__ = ["COMPILED_LOADED_MIN_ENTRIES", "COMPILED_MIN_ENTRIES", "compiled_walks",
           "load_walks"]

COMPILED_MIN_ENTRIES = 4_000_000
"""Stored entries from which a walk runs compiled
(:mod:`~mitld_lp.solvers.compiled_graph`) even while numba is not loaded: loading it
and reading the kernels from the disk cache costs 0.6-0.8 s of CPU once a process,
which the analysis saves back from about 3-8 million entries (0.25, 0.23 and 0.09
microseconds an entry on QVBS zeroconf 20-4, csma 4-2 and ``bus_scaled`` n64)."""

COMPILED_LOADED_MIN_ENTRIES = 150_000
"""Stored entries from which a walk runs compiled once numba is loaded (by the sweeps
of an earlier solve, or by :func:`load_walks`): each kernel's first call still reads
it from the disk cache, about 0.03 s."""


def compiled_walks(entries: int) -> Any:
    """The module of compiled walks (:mod:`~mitld_lp.solvers.compiled_graph`) for a graph
    of ``entries`` stored entries, or None where the NumPy walks are used: below
    :data:`COMPILED_LOADED_MIN_ENTRIES`, below :data:`COMPILED_MIN_ENTRIES` while numba
    is not loaded (a small solve never loads it), and without numba."""
    if entries < COMPILED_LOADED_MIN_ENTRIES or (
            entries < COMPILED_MIN_ENTRIES and not kernel_loader.compiled_paid()):
        return None
    return load_walks()


def load_walks() -> Any:
    """The module of compiled walks, numba imported with it; None without numba."""
    try:
        from mitld_lp.solvers import compiled_graph
    except ImportError:  # pragma: no cover - numba is a dependency of the solvers
        return None
    return compiled_graph
