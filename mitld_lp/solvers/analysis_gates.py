"""Which of the analysis's walks run compiled, now that the kernel loader's load is cheap.

:func:`~mitld_lp.solvers.walks.compiled_walks` sends a walk to the compiled kernels
(:mod:`~mitld_lp.solvers.compiled_graph`) from 150,000 entries once a kernel's load is
paid, and from 4 million entries otherwise: a rule made when that load was numba's
import (0.6-0.8 s of CPU).  On a warm cache the kernel loader's load is 0.005-0.02 s,
and two of the analysis's walks pay it back on a mid-sized product:

* the **attractor** (``Prob0E``, ``Prob1E``, a minimum's ``Prob1A`` on the quotient,
  its backward search; :func:`attractor_walks`), whose NumPy rounds are thin (a round a
  frontier, thousands of rounds on a deadline's product): compiled from
  :data:`WARM_MIN_ENTRIES` entries where its kernel is warm, whether or not a load is
  paid (QVBS firewire_dl 3-600: 0.020 -> 0.010 s; consensus 4-4: 0.010 -> 0.001; csma
  4-2: 0.037 -> 0.012), and from :data:`PAID_MIN_ENTRIES` once a load is paid (the
  certificate's attractor on QVBS consensus 4-4, :func:`~mitld_lp.solvers.graph.
  attractor` over 75,780 entries: 0.020 s on NumPy);
* the **quotient's own levels** (:func:`level_walks`,
  :func:`~mitld_lp.solvers.quotient_order.quotient_blocks`): compiled from
  :data:`LEVELS_MIN_ENTRIES` once a load is paid and the kernel is warm, in place of SciPy's
  components and Dijkstra's search of thin levels.

The product's components and reach (:func:`component_walks`,
:func:`~mitld_lp.solvers.graph.components_reaching`) run compiled, once a load is paid,
only where the product has at least :data:`DENSE_ENTRIES` entries a state (or from
:data:`~mitld_lp.solvers.walks.COMPILED_MIN_ENTRIES` entries): since the quotient's
levels are found on the quotient alone, SciPy's components and a search of the reversed
graph cost less than the compiled Tarjan with the product's levels where a state has a
few entries (QVBS csma 4-2, 1.8 entries a state, its load paid by the product's build:
the analysis 0.104 -> 0.077 s; firewire_dl 3-600, 1.2: 0.024 -> 0.019; zeroconf 1000-4,
2.3: 0.161 -> 0.165; medians of 7 in one process), not where it has many (the sensed
bus case, 20.6 entries a state: 0.056 compiled against 0.064).

A kernel is warm where the loader would link it from its cache
(:func:`~mitld_lp.util.kernel_loader.cached`: the loader on, numba installed, a cache
file of the kernel not older than its module); a cold cache (numba's compile, seconds),
the loader off (``MITLD_LP_KERNEL_LOADER=0``) or numba missing keep the NumPy walks,
which give the same sets, components and numbering.

The load itself is paid at the analysis's start (:func:`pay_if_warm`) where the
certificate of the same product would pay it anyway
(:func:`~mitld_lp.solvers.certify_compiled.load_if_warm`: at least
:data:`~mitld_lp.solvers.certify_compiled.WARM_LOAD_MIN_ENTRIES` entries, its kernels
warm) and every kernel of :data:`ANALYSIS_KERNELS` is warm: no load is added to the
process, and the analysis's walks run compiled from the first (``bus_scaled`` n64 d3,
1.77 million entries, whose level blocks are too small for the analysis's guess of the
sweeps, :func:`~mitld_lp.solvers.analysis._sweeps_compiled`: its end components searched
by NumPy rounds and Python's Tarjan, its components by SciPy, where a second solve in
the same process ran them compiled).  Imports nothing of the solvers but the walks' gate
and, at the first such call, the certificate's gate (NumPy and the standard library)."""

from __future__ import annotations

from typing import Any

from mitld_lp.solvers import walks as _walks
from mitld_lp.solvers.walks import compiled_walks, load_walks
from mitld_lp.util import kernel_loader

__all__ = ["ANALYSIS_KERNELS", "ATTRACTOR", "DENSE_ENTRIES", "LEVELS", "LEVELS_MIN_ENTRIES",
           "PAID_MIN_ENTRIES",
           "WARM_MIN_ENTRIES", "attractor_walks", "component_walks", "level_walks",
           "pay_if_warm", "warm"]

WARM_MIN_ENTRIES = 100_000
"""Stored entries from which an attractor runs compiled on a warm cache before any
kernel's load is paid: the loader's load and the kernel's link (0.005-0.02 s of CPU)
against the NumPy rounds it saves (QVBS consensus 4-4, 144,349 entries: 0.009 s;
firewire_dl 3-600, 197,013 entries: 0.010-0.015 s)."""

PAID_MIN_ENTRIES = 20_000
"""Stored entries from which an attractor or the quotient's levels run compiled on a
warm cache once a kernel's load is paid (only the kernel's link is left, 1-3 ms once a
process): below, the plain walks' 4-5 ms (:data:`~mitld_lp.util.traversal.SMALL`)."""

LEVELS_MIN_ENTRIES = 1_000
"""Stored entries from which the quotient's levels run compiled on a warm cache once a
load is paid: the plain walk of QVBS csma 4-2's quotient (678 states, 1,343 entries)
took 3-5 ms of CPU in Python's Tarjan, the compiled one a call's cost (the same
components, numbered alike, and levels)."""

DENSE_ENTRIES = 8
"""Entries a state from which the product's components run compiled once a load is paid
(between QVBS zeroconf 1000-4's 2.3, SciPy's walk no slower, and the sensed bus case's
20.6, the compiled walk 13% faster)."""

ATTRACTOR = ("mitld_lp.solvers.compiled_graph", "_backward")
LEVELS = ("mitld_lp.solvers.compiled_graph", "state_levels")
"""The kernels (module, name) whose cache files are asked for."""

ANALYSIS_KERNELS = (ATTRACTOR, LEVELS, ("mitld_lp.solvers.compiled_graph", "closed_among"))
"""The compiled walks a maximum's analysis runs once a load is paid (the attractor, the
components with their levels, the end components' test): :func:`pay_if_warm` pays the
load only where each has a cache file, so that paying it early makes the analysis compile
none of them (numba's compile, seconds).  The end components' compiled search, run only
where the test finds one, is left to its cache as after the sweeps' load
(:func:`~mitld_lp.solvers.walks.compiled_walks`)."""

_WARM: dict[tuple[str, str], bool] = {}  # looked up once a process


def warm(kernel: tuple[str, str] = ATTRACTOR) -> bool:
    """Whether ``kernel`` would be linked from the loader's cache
    (:func:`~mitld_lp.util.kernel_loader.module_cached`), looked up once a process."""
    if kernel not in _WARM:
        _WARM[kernel] = kernel_loader.module_cached(*kernel)
    return _WARM[kernel]


def attractor_walks(entries: int) -> Any:
    """The module of compiled walks for an attractor (or a backward search) on a matrix
    of ``entries`` stored entries, or None where the NumPy walk is used (module docs)."""
    walks = compiled_walks(entries)
    if walks is not None or entries < PAID_MIN_ENTRIES or not warm(ATTRACTOR):
        return walks
    if entries < WARM_MIN_ENTRIES and not kernel_loader.compiled_paid():
        return None
    return load_walks()


def level_walks(entries: int) -> Any:
    """The module of compiled walks for the quotient's components and levels on a matrix
    of ``entries`` stored entries, or None where SciPy's walk is used (module docs)."""
    walks = compiled_walks(entries)
    if (walks is not None or entries < LEVELS_MIN_ENTRIES or not kernel_loader.compiled_paid()
            or not warm(LEVELS)):
        return walks
    return load_walks()


def component_walks(entries: int, states: int) -> Any:
    """The module of compiled walks for the product's components and reach on a matrix of
    ``entries`` stored entries over ``states`` states: :func:`~mitld_lp.solvers.walks.
    compiled_walks`'s from :data:`~mitld_lp.solvers.walks.COMPILED_MIN_ENTRIES` entries or
    from :data:`DENSE_ENTRIES` entries a state, else None (SciPy's walk, module docs)."""
    if entries < _walks.COMPILED_MIN_ENTRIES and entries < DENSE_ENTRIES * states:
        return None
    return compiled_walks(entries)


def pay_if_warm(entries: int) -> bool:
    """Whether a kernel's load is paid for the analysis of a product of ``entries``
    stored entries, paying it now where every kernel of :data:`ANALYSIS_KERNELS` is warm
    and the product's certificate would pay it anyway
    (:func:`~mitld_lp.solvers.certify_compiled.load_if_warm`, whose rule decides: the
    same load, earlier).  Only which walk runs changes, not a set, component or number."""
    if kernel_loader.compiled_paid():
        return True
    from mitld_lp.solvers.certify_compiled import WARM_LOAD_MIN_ENTRIES, load_if_warm

    if entries < WARM_LOAD_MIN_ENTRIES:  # before the warmth checks, which hash files
        return False
    if not all(warm(k) for k in ANALYSIS_KERNELS):
        return False

    return load_if_warm(entries)
