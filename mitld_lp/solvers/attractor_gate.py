"""Whether the analysis's attractors run compiled before any kernel's load is paid.

:func:`~mitld_lp.solvers.walks.compiled_walks` sends a walk to the compiled kernels
(:mod:`~mitld_lp.solvers.compiled_graph`) from 150,000 entries once their load is paid,
and from 4 million entries otherwise: a rule made when that load was numba's import
(0.6-0.8 s of CPU).  On a warm cache the kernel loader's load is about 0.02 s, and of
the analysis's walks the attractor (``Prob0E``, ``Prob1E``, and a minimum's ``Prob1A``
on the quotient, its backward search) is the one whose NumPy rounds are thin: a round
a frontier, thousands of rounds on a deadline's product (QVBS firewire_dl 3-600: 0.020
-> 0.010 s compiled; consensus 4-4: 0.010 -> 0.001).  The components stay on SciPy's
walk where :func:`~mitld_lp.solvers.walks.compiled_walks` keeps them there: the compiled
Tarjan with its levels is no faster on those products (QVBS csma 4-2: 0.032 s SciPy's
components and reach against 0.057 compiled).

:func:`attractor_walks` is the one gate: the compiled walks wherever
:func:`~mitld_lp.solvers.walks.compiled_walks` gives them, and from
:data:`WARM_MIN_ENTRIES` entries where the attractor's kernel is warm in the loader's
cache (:func:`~mitld_lp.util.kernel_loader.cached`: the loader on, numba installed, a
cache file of the kernel not older than its module): a cold cache (numba's compile,
seconds), the loader off (``MITLD_LP_KERNEL_LOADER=0``: numba's import) or numba missing
keep the NumPy walk, which gives the same sets.  Imports nothing of the solvers but the
walks' gate (NumPy and the standard library)."""

from __future__ import annotations

from typing import Any

from mitld_lp.solvers.walks import compiled_walks, load_walks
from mitld_lp.util import kernel_loader

__all__ = ["KERNEL", "WARM_MIN_ENTRIES", "attractor_walks", "warm"]

WARM_MIN_ENTRIES = 100_000
"""Stored entries from which an attractor runs compiled on a warm cache before any
kernel's load is paid: the loader's load and the kernel's link (0.005-0.02 s of CPU)
against the NumPy rounds it saves (QVBS consensus 4-4, 144,349 entries: 0.009 s;
firewire_dl 3-600, 197,013 entries: 0.010-0.015 s)."""

KERNEL = ("mitld_lp.solvers.compiled_graph", "_backward")
"""The attractor's kernel (module, name): the one whose cache file is asked for."""

_WARM: list[bool] = []  # looked up once a process


def warm() -> bool:
    """Whether the attractor's kernel would be linked from the loader's cache
    (:func:`~mitld_lp.util.kernel_loader.module_cached`), looked up once a process."""
    if not _WARM:
        _WARM.append(kernel_loader.module_cached(*KERNEL))
    return _WARM[0]


def attractor_walks(entries: int) -> Any:
    """The module of compiled walks for an attractor (or a backward search) on a matrix
    of ``entries`` stored entries, or None where the NumPy walk is used (module docs)."""
    walks = compiled_walks(entries)
    if walks is not None or entries < WARM_MIN_ENTRIES or not warm():
        return walks
    return load_walks()
