"""Which quotients have their single-state level walks compiled because they are deep:
a deadline's product is acyclic up to self-loops after the quotient, its levels a chain
of hundreds (QVBS ``firewire_dl`` 3-600: 450 levels; ``zeroconf_dl`` 1000-1-30: 719)
of a few dozen states each, so the NumPy walks of
:class:`~mitld_lp.solvers.topological.SingleLevels` cost their calls a level (15-60
microseconds a level and walk, three walks a solve: the iteration's bounds, the LP's
values and its flow), not their arithmetic, whatever the quotient's size.

:func:`~mitld_lp.solvers.topological.level_kernels` sends a quotient to the compiled
walks (:mod:`~mitld_lp.solvers.level_kernels`) by its size and numba's load
(:data:`~mitld_lp.solvers.topological.LEVEL_KERNEL_MIN_ENTRIES`, and
:data:`~mitld_lp.solvers.topological.LEVEL_KERNEL_MIN_LEVELS` while no kernel's load is
paid); those quotients are below its entries (34,110 and 35,766).  :func:`deep` adds the
quotients of at least :data:`DEEP_LEVELS` levels whatever their size, where the kernel
loader would link the walks from its cache (:func:`~mitld_lp.util.kernel_loader.cached`:
a warm cache; a cold one would pay numba's compile, seconds, and keeps NumPy): the
loader's link costs 1-3 ms once a kernel's load is paid (the analysis's attractor pays it
on these products), 5-20 ms where nothing is loaded yet, against the 3-35 ms the NumPy
walks of 200 levels and more cost.  Both walks give the same answers to the last bit.

Imports nothing of the solvers (NumPy and the standard library, the kernel loader)."""

from __future__ import annotations

from mitld_lp.util import kernel_loader

__all__ = ["DEEP_LEVELS", "WALKS", "deep", "warm"]

DEEP_LEVELS = 200
"""Levels from which a quotient's single-state walks run compiled on a warm cache.
Measured (CPU, compiled against NumPy walks, the kernels' load paid by the analysis):
the iteration's bounds walk 0.7-0.8 ms against 6-18 ms on ``zeroconf_dl`` 1000-1-30
(719 levels), and a level costs NumPy 15-60 microseconds a walk: at 200 levels, three
walks cost 9-36 ms, above the loader's load where nothing is paid yet."""

WALKS = ("single_bounds", "single_bounds_values", "single_values", "single_flow")
"""The kernels of :mod:`~mitld_lp.solvers.level_kernels` a quotient's walks call, each
asked for its cache file."""

_WARM: list[bool] = []  # looked up once a process


def warm() -> bool:
    """Whether the kernel loader would link every walk of :data:`WALKS` from its cache
    (:func:`~mitld_lp.util.kernel_loader.module_cached`), looked up once a process."""
    if not _WARM:
        _WARM.append(all(kernel_loader.module_cached("mitld_lp.solvers.level_kernels", k)
                         for k in WALKS))
    return _WARM[0]


def deep(n_levels: int) -> bool:
    """Whether a quotient of ``n_levels`` levels has its single-state walks compiled for
    its depth (module docs): at least :data:`DEEP_LEVELS` levels and a warm cache."""
    return n_levels >= DEEP_LEVELS and warm()
