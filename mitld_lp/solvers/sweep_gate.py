"""Which sweeps a block of the interval iteration gets, forecast from the block itself:
NumPy's Jacobi sweeps (and the policy jump where they cannot close it) or the compiled
Gauss--Seidel kernel (and numba's load where it is not loaded yet).

:func:`use_compiled` (the iteration's gate) sends a block to the compiled kernel by size
alone from :data:`~mitld_lp.solvers.kernels.COMPILED_MIN_BLOCK_ENTRIES`
(:func:`mitld_lp.solvers.kernels.use_compiled`); below it, in a product of at least
:data:`~mitld_lp.solvers.kernels.COMPILED_MIN_ENTRIES`, it asks :func:`prefers_compiled`.
Sizes alone cannot tell the blocks apart:
``bus_scaled`` n64 d3's grid blocks (98,288 and 49,144 entries) are cheaper compiled
(1.79 -> 1.51 s solve, numba's load included), QVBS ``consensus`` 4-4's (at most 38,684)
dearer (0.55 -> 1.01 s).  What does tell them apart is the block's *depth* (the
eccentricity of its state graph without directions, :func:`~mitld_lp.solvers.jump_cost.
block_depth`): a Jacobi sweep carries a value one step, so a block deeper than
:data:`JACOBI_SWEEPS` steps is not closed by the NumPy sweeps, and the policy jump's
rounds of policy iteration grow with the depth too (each carries an improvement
:data:`~mitld_lp.solvers.jump_cost.LOOK_AHEAD` steps); a Gauss--Seidel sweep in the
block's value order (:mod:`mitld_lp.solvers.sweep_order`) carries it across.

Both sides in one unit, *entries touched by a compiled sweep* (as
:mod:`mitld_lp.solvers.jump_cost`; a sweep of a block touches ``sweep = inner.nnz +
choices``), no clock read (the same block decides the same on an idle and on a loaded
machine):

* NumPy: ``NUMPY_ENTRY * min(depth, JACOBI_SWEEPS) * sweep``, and where the depth
  exceeds :data:`JACOBI_SWEEPS`, the jump's rounds (``1 + depth / LOOK_AHEAD``) times
  a round's cost without its LU's multiplies (``ROUND_STATE * states + ROUND_ENTRY *
  entries``: a lower bound of the jump's, so that a doubt stays on NumPy, the route
  that loads nothing);
* compiled: the kernel's load (0 once it is loaded; :data:`LOADER_LOAD`, the kernel
  loader's link, where its cache file is there; :data:`NUMBA_LOAD` otherwise) plus
  ``GS_BASE + GS_PER_DEPTH * depth`` sweeps of ``sweep`` entries.

The depth costs two breadth-first searches of the block (2.5-5 ms on the blocks
above, more where the block holds many components: one search each, up to
:data:`~mitld_lp.solvers.jump_cost.SEARCHES`); a block too small for NumPy's forecast to
reach numba's load even at the greatest depth it could have (its states) is decided
without them, and so is a block whose largest part (:func:`largest_part`, the states of
its largest connected piece, one linear pass) is too small for a depth above
:data:`JACOBI_SWEEPS`: a depth counts steps inside one piece, at most its states less
one, and the gate sends no block of that depth or less to the compiled sweeps.  The
sensed case's two blocks (2,464 states of 154 pieces, the largest 16 states, depth 6)
were searched 3.5 ms each to be sent to NumPy; their largest part is read in 0.6-0.9 ms.

Calibrated on this machine (2 cores, CPU seconds, 2026-11-30, with
``experiments/gate_blocks.py``: every block of an instance swept by each route in a
process of its own; ``experiments/results/gate_blocks_sweep_gate.md``): see each
constant.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers import jump_cost, kernels
from mitld_lp.solvers.topological import Block

__all__ = ["FOUR_BASE", "Forecast", "GS_BASE", "GS_PER_DEPTH", "JACOBI_SWEEPS",
           "LOADER_LOAD", "NUMBA_LOAD", "NUMPY_ENTRY", "PAID_LOAD", "forecast",
           "largest_part", "load_is_cheap", "prefers_compiled", "prefers_four",
           "use_compiled"]

JACOBI_SWEEPS = 100
"""The NumPy sweeps before a block is jumped (the iteration's ``_SWEEPS_BEFORE_POLICY``):
a block deeper than this many steps is forecast to need the jump.  A block that is not
stays on NumPy whatever the forecast: QVBS ``consensus`` 4-4's blocks (depth 61-65; their
gap stays flat, a random walk's, and both routes end in a jump) cost 0.87-1.5x compiled
with numba loaded, 20x on its 488-state block (548 sweeps), where a forecast from the
depth alone would pick the compiled sweeps once numba is loaded."""
NUMPY_ENTRY = 3.0
"""What a NumPy (Jacobi) sweep costs an entry, in compiled sweeps' entries: 17-33 ns an
entry on the bus n64 d3 and consensus 4-4 blocks against 8.4-10 ns compiled."""
NUMBA_LOAD = 5.0e7
"""numba's load (its import, the registries, the kernel's first call from the cache) in
compiled sweeps' entries: 0.44 s (``experiments/numba_load.py``'s median, numba's import
and three kernels' first calls) over 8.6 ns an entry."""
LOADER_LOAD = 2.3e6
"""The kernel's load where the kernel loader links it from a warm cache (its ELF
linker: 0.020 s, ``experiments/numba_load.py``, loader-floor) over 8.6 ns an entry:
used in place of :data:`NUMBA_LOAD` where :func:`load_is_cheap`."""
GS_BASE = 16.0
"""Gauss--Seidel sweeps of a block whatever its depth (one chunk of the kernel)."""
GS_PER_DEPTH = 1.0
"""Gauss--Seidel sweeps a step of the block's depth, in the value order: an upper figure
of those measured, bus n64 d3 (depth 126) 96 (and an early jump) and 129, bus n128 d3
(depth 254) 200 and 265, QVBS ``zeroconf`` 1000-4 (depth 66) 39."""

FOUR_BASE = 1.0
"""Gauss--Seidel sweeps of a two-model block (four columns, the kernels of
:mod:`mitld_lp.solvers.sweep_four`) beyond its depth (:func:`prefers_four`): the sensed
case's two blocks (depth 6) closed in 7 and 5 (``experiments/bench_sensed_gate.py``),
where its NumPy sweeps took 13 and 9."""
PAID_LOAD = 2.0e5
"""The Gauss--Seidel kernel's load where the kernel loader's run-time is set up already
(:func:`mitld_lp.util.kernel_loader.compiled_paid`: another kernel linked before, as the
sensed build's are): its own link and first call, 0.1 ms and about 1-1.5 ms on the
sensed case (``experiments/bench_sensed_gate.py``'s ``cold`` route against the kernel
loaded before the solve), taken as 1.7 ms over 8.6 ns an entry.  Counted by the
two-model rule (:func:`prefers_four`) only: the one-model rule keeps its load
(:data:`LOADER_LOAD`, calibrated with it)."""


@dataclass(frozen=True, slots=True)
class Forecast:
    """A block's forecast work by each route, in compiled sweeps' entries."""

    depth: int
    numpy: float
    compiled: float


def _numpy(states: int, entries: float, sweep: float, depth: int) -> float:
    work = NUMPY_ENTRY * min(depth, JACOBI_SWEEPS) * sweep
    if depth > JACOBI_SWEEPS:
        rounds = 1.0 + depth / jump_cost.LOOK_AHEAD
        work += rounds * (jump_cost.ROUND_STATE * states + jump_cost.ROUND_ENTRY * entries)
    return work


def _compiled(sweep: float, depth: int, loaded: bool) -> float:
    load = 0.0 if loaded else LOADER_LOAD if load_is_cheap() else NUMBA_LOAD
    return load + (GS_BASE + GS_PER_DEPTH * depth) * sweep


def load_is_cheap() -> bool:
    """Whether the Gauss--Seidel kernel's load is the loader's (:data:`LOADER_LOAD`):
    the loader on and the kernel's cache file there
    (:func:`~mitld_lp.util.kernel_loader.cached`), looked up once a process.  A cold
    cache (numba's compile, seconds), the loader off (numba's import) or numba missing:
    :data:`NUMBA_LOAD`, as before the loader's linker."""
    if not _CHEAP:
        from mitld_lp.util import kernel_loader

        _CHEAP.append(kernel_loader.module_cached("mitld_lp.solvers.compiled_kernels",
                                                  "gauss_seidel"))
    return _CHEAP[0]


_CHEAP: list[bool] = []


def forecast(block: Block, loaded: bool) -> Forecast:
    """The block's forecast work by each route (module docs); ``loaded``: numba's
    kernel is loaded already."""
    states = int(block.states.size)
    entries = float(block.inner.nnz)
    sweep = entries + float(block.choices.shape[0])
    depth = jump_cost.block_depth(block)
    return Forecast(depth, _numpy(states, entries, sweep, depth),
                    _compiled(sweep, depth, loaded))


def largest_part(block: Block) -> int:
    """The states of the block's largest weakly connected piece (its moves inside the
    block, directions dropped): a bound of its depth (:func:`jump_cost.block_depth`, a
    distance inside one piece) plus one, found without a search from each piece."""
    from scipy.sparse.csgraph import connected_components

    n = int(block.states.size)
    if n == 0:
        return 0
    inner = block.inner
    moves = sp.csr_array((np.ones(inner.nnz, dtype=bool), inner.indices,
                          inner.indptr[block.groups]), shape=(n, n))
    _, labels = connected_components(moves, directed=True, connection="weak")
    return int(np.bincount(labels).max())


def prefers_compiled(block: Block, loaded: bool) -> bool:
    """Whether the block's compiled sweeps are forecast to cost less than its NumPy
    sweeps and jump (module docs); ``loaded``: numba's kernel is loaded already."""
    states = int(block.states.size)
    entries = float(block.inner.nnz)
    sweep = entries + float(block.choices.shape[0])
    # the most NumPy could be forecast to cost (the depth at most the states) against
    # the least the compiled sweeps could: if even that does not pay, no search
    if (states <= JACOBI_SWEEPS
            or _numpy(states, entries, sweep, states) <= _compiled(sweep, 0, loaded)):
        return False
    # no piece deep enough for the compiled sweeps (a depth is at most a piece's states
    # less one): no search
    if largest_part(block) <= JACOBI_SWEEPS + 1:
        return False
    f = forecast(block, loaded)
    return f.depth > JACOBI_SWEEPS and f.compiled < f.numpy


def prefers_four(block: Block, loaded: bool) -> bool:
    """Whether a two-model block (four columns: :mod:`mitld_lp.solvers.sweep_four`'s
    kernels) is forecast cheaper compiled, at any depth: NumPy's forecast as
    :func:`prefers_compiled`'s (``NUMPY_ENTRY * min(depth, JACOBI_SWEEPS)`` sweeps, the
    jump's rounds past them), the compiled one ``FOUR_BASE + depth`` sweeps plus the
    kernel's load (0 once loaded; :data:`PAID_LOAD` where the loader's run-time is set
    up; else as the one-model rule).  Measured on the sensed case's blocks
    (``experiments/bench_sensed_gate.py``, CPU s): NumPy 13 and 9 sweeps, 0.0072-0.0114 s
    a block, compiled 7 and 5, 0.0015-0.0040 s with the kernel's load.  The one-model
    rule's depth floor (:data:`JACOBI_SWEEPS`) is not asked: it was set on one-model
    blocks whose gap a random walk keeps open (QVBS ``consensus``), where the compiled
    sweeps did not pay.  Up to that depth the forecasts' difference grows with the
    depth, so the block's least depth (1: its pieces hold two states or more) and its
    greatest (:func:`largest_part` less one) decide it without a search where they
    agree."""
    from mitld_lp.util import kernel_loader

    states = int(block.states.size)
    entries = float(block.inner.nnz)
    sweep = entries + float(block.choices.shape[0])
    load = (0.0 if loaded else PAID_LOAD if kernel_loader.compiled_paid()
            else LOADER_LOAD if load_is_cheap() else NUMBA_LOAD)

    def cheaper(depth: int) -> bool:
        return load + (FOUR_BASE + depth) * sweep < _numpy(states, entries, sweep, depth)

    top = largest_part(block) - 1
    if top < 1:
        return False
    if top <= JACOBI_SWEEPS:
        if cheaper(1):
            return True
        if not cheaper(top):
            return False
    return cheaper(jump_cost.block_depth(block))


def use_compiled(entries: int, block_entries: int, block: Block | None = None,
                 columns: int = 2) -> bool:
    """Whether a block of ``block_entries`` entries in a product of ``entries``
    transitions is swept with the compiled kernel (numba importable: imported here the
    first time).  A product below :data:`~mitld_lp.solvers.kernels.COMPILED_MIN_ENTRIES`
    never; a block of at least :data:`~mitld_lp.solvers.kernels.COMPILED_MIN_BLOCK_ENTRIES`
    always; a smaller one, when ``block`` is given, where :func:`prefers_compiled` (one
    model), or with ``columns`` 4 (two models) :func:`prefers_four` (numba's load
    counted unless the kernel is loaded already)."""
    if entries < kernels.COMPILED_MIN_ENTRIES:
        return False
    if block_entries < kernels.COMPILED_MIN_BLOCK_ENTRIES:
        if block is None:
            return False
        prefers = prefers_four if columns == 4 else prefers_compiled
        if not prefers(block, loaded=kernels.kernel_loaded()):
            return False
    return kernels.compiled_kernel() is not None
