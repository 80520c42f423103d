r"""Sweeps of a block's interval bounds: compiled (numba) for large products, NumPy else.

A sweep updates a block's lower and upper bounds (a column each per model) by the
Bellman operator with every choice's *self-loop solved exactly*, as a single state's
is (:mod:`mitld_lp.solvers.topological`):

.. math:: x(s) \leftarrow \max_c \frac{e(c) + \sum_{s' \ne s} P(c, s')\, x(s')}{1 - p(c)}

(:math:`\min_c` for a minimum) with :math:`e(c)` the choice's exit reward and
:math:`p(c) = P(c, s)` its self-loop.
If :math:`x \le v^*` the right-hand side is :math:`\le v^*` too (for each choice,
:math:`v^*(s)(1 - p(c)) \ge e(c) + \sum_{s' \ne s} P(c, s') v^*(s')`), and if
:math:`x \ge v^*` it is :math:`\ge v^*` (take an optimal choice), so every update keeps a
lower bound below and an upper bound above the optimum; a lower bound is only raised
and an upper one only lowered.  A state that waits for an event (a self-loop of
probability 0.98) is settled in one update instead of hundreds.

* **NumPy** (:func:`numpy_sweeps`): Jacobi, every state from the previous sweep's
  bounds, one sparse product per sweep for all columns.
* **compiled** (:func:`compiled_sweeps`, numba): Gauss--Seidel, each state from the
  bounds already updated in this sweep, from the block's last state to its first
  (:func:`sweep_order`; an order breadth first from the exits took 10% fewer sweeps
  than the forward one on the bus blocks and, jumping through memory, 5x the time).
  A block is swept by it only in a product of at least
  :data:`COMPILED_MIN_ENTRIES` entries and when the block itself has at least
  :data:`COMPILED_MIN_BLOCK_ENTRIES`, or is forecast cheaper so from its depth
  (:mod:`mitld_lp.solvers.sweep_gate`); numba is imported at the first such block, so a
  product whose blocks are all small never loads it; without numba the NumPy path runs.
  What loading it costs, measured in a solve with SciPy loaded (numba 0.68, CPU
  seconds on a loaded 2-core machine): ``import numba`` 0.14-0.25 s; the first call of
  any kernel 0.23-0.31 s even from the on-disk cache, which numba spends on its typing
  and target registries once a process (0.39-0.43 s when ``scipy.linalg`` is not yet
  imported: numba imports it to find BLAS); each further kernel, or signature of one,
  5-10 ms; 74 MB.  Part by part (``experiments/numba_load.py``): the import 0.26 s, the
  typing registries 0.05 s, the CPU target's registries 0.34-0.37 s (numba refreshes
  them before it loads any kernel from its cache), the block kernel itself 0.03 s and a
  level kernel 0.01 s.  The target's registries are for compiling: a kernel loaded
  from the cache needs only numba's runtime of them, and
  :mod:`mitld_lp.util.numba_narrow` (put in place by every compiled module as it is
  imported) loads it so, 0.2-0.25 s less CPU; it now skips the typing context's
  refresh too (cffi's C parser among it) and imports numba without PyYAML: numba's
  import and a graph, block and level kernel's first calls 0.54 -> 0.44 s
  (``experiments/results/numba_load_numba_gate.txt``); since the numba-load branch the first call
  reads numba's runtime as machine code and skips ``numba.np.arrayobj``
  (:mod:`mitld_lp.util.nrt_cache`, :mod:`mitld_lp.util.numba_narrow`).  Every kernel is loaded
  at its first call only (a dispatcher each), so loading fewer kernels saves their hundredths of a
  second, not numba's registries. A new checkout compiles every kernel it calls once (for one index
  type: :func:`kernel_index`; 2.5 s more on the first solve of QVBS ``zeroconf`` 20-4-false, the
  index files then under each module's ``__pycache__``, keyed by the source file's time stamp). The
  NumPy path is no way round that load where a large block needs the kernel: that instance's solve
  takes 25 s by it against 1.6 s compiled, its load included.

**Guessed and verified bounds** (the compiled kernel only; optimistic value iteration,
Hartmanns & Kaminski, CAV 2020, with the guess extrapolated).  A block that mixes slowly
closes its gap by a steady ratio ``q`` a sweep (QVBS ``consensus`` 6-2: 0.983, some
1,200 sweeps from ``[0, 1]`` to 1e-9).  Where each bound's largest change keeps that
ratio for two sweeps running (after :data:`~mitld_lp.solvers.compiled_kernels.WATCH_SWEEPS`
sweeps), its error is about its last change times ``q / (1 - q)``: the kernel
extrapolates both bounds so, and guesses a lower and an upper bound a margin outside
the two extrapolations (a share of the correction, halved after each verified guess,
doubled after a failed one).  The guesses are then swept beside the proven bounds, in
the same pass over the entries, each choice's value widened by a bound on its rounding
error (every term is non-negative, so a sum of ``m`` terms is within ``m`` units of its
last place): a sweep in which no upper guess rose is a proof that the swept guess ``U``
is an upper bound (each ``U(s)`` is at least the update of a vector at least ``U``, so
``T(U) <= U``, and on a quotient, without end components, ``T(U) <= U`` implies
``U >= `` the optimum), and one in which no lower guess fell proves a lower bound the
same way (``L <= T(L)``).  Only then is a guess written into the bounds, a lower bound
raised and an upper one lowered; a guess that crosses the other side's proven bound,
or is not proven within :data:`~mitld_lp.solvers.compiled_kernels.VERIFY_SWEEPS`
sweeps, is dropped.  The bounds the kernel returns are proven ones only, wherever it
stops.  QVBS ``consensus`` 6-2 c2: its blocks of 87,225 and 139,566 states close in 358
and 391 sweeps where the plain sweeps took 800 each and then the policy jump; the
interval iteration 1,217 sweeps instead of 2,512, the solve stage's CPU in
``experiments/results/bench_qvbs_solve_kernels.md``.  A verifying sweep reads two
vectors at every entry, and about half of the sweeps verify.  Where many modes decay
at nearly the same rate (a ring of 40 states left once in 300 steps) the extrapolation
is poor and the guesses gain little (5,616 -> 4,507 sweeps); on a ring of 10, 4,699 ->
344.

Both paths give sound bounds; they differ in how many sweeps the gap takes to close.
They stop when every state's gap is below its threshold: the absolute ``tol``, and with
a relative ``precision`` also ``precision`` times the state's lower bound (a value of
1e-30 is known to six digits only once its gap is below 1e-36; :func:`thresholds`).
What they return is the largest ratio of a gap to its threshold (below 1: converged).
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers.graph import Sense
from mitld_lp.util.arrays import index_dtype

__all__ = ["COMPILED_MIN_BLOCK_ENTRIES", "COMPILED_MIN_ENTRIES", "FLOOR", "compiled_kernel",
           "compiled_sweeps", "excess", "kernel_loaded", "numpy_sweeps", "put_rows",
           "sweep_order", "take_rows", "thresholds", "use_compiled", "watch_again"]

logger = logging.getLogger(__name__)

COMPILED_MIN_ENTRIES = 150_000
"""Quotient entries (transitions) from which the compiled sweeps are used: no more than a
block worth them needs (:data:`COMPILED_MIN_BLOCK_ENTRIES`).  It was 1e6, and QVBS
``zeroconf`` 1000-4-false (697,823 transitions, one block of most of them) was swept by
NumPy, jumped after 100 sweeps, and its jump's factorisations took 65 s of interval
iteration, where the compiled sweeps close it in 39 (2 s, numba's load included)."""

COMPILED_MIN_BLOCK_ENTRIES = 150_000
"""A block's own entries from which it is swept by the compiled kernel.  What the kernel
saves on a block is the policy jump's factorisations, which grow faster than the block.
CPU seconds of the solve stage on ``bus_scaled``, numba's load included, two runs each:
n64 d10 (blocks of 98,288 and 49,144 entries) 2.07 / 1.93 s compiled against 2.08 /
1.97 s with NumPy, with 11 more bytes a transition at the peak (65 against 54); blocks
of 393,200 and 196,600 entries 6.0 / 6.5 s against 10.7 / 13.9 s (n128 d3) and 9.2 /
12.0 s against 14.3 / 15.9 s (n128 d10).

Measured again on every instance of the benchmarks that could load numba
(``experiments/profile_solve.py --numpy-sweeps --compiled-sweeps``, 2026-11-30,
``experiments/results/profile_solve_numba_gate.md``): only QVBS ``zeroconf`` 20-4 and
1000-4 do (one block of 483,692 entries), and there NumPy loses by 26-85x: its Jacobi
sweeps give up after 16 and the policy jump's factorisations take 50 s (20-4
``correct_max``: 1.9 s compiled, 53 s NumPy).  ``consensus`` 4-4 (blocks of at most
38,684 entries), ``csma`` 4-2 (no block) and ``bus_scaled`` n64 d3 (98,288 and 49,144)
stay on NumPy; swept compiled, consensus 4-4 takes 1.01 s against 0.57 and bus n64 d3
1.47 s against 1.72 (its NumPy sweeps give up after 8 and jump): there the sizes pick
the slower side by 0.25 s, which only a forecast of the sweeps would see.  A block below
this size is now asked that forecast (:mod:`mitld_lp.solvers.sweep_gate`, from the
block's depth): bus n64 d3's blocks (depth 126) are swept compiled, consensus's (depth
45-65; 6-2's block of 106,860 entries among them) stay on NumPy."""

_KERNEL: Any = None  # the compiled kernel once built, False if numba is not available

FLOOR = 2.0**-1000
"""The least gap threshold (about 9e-302): a value below it (or a lower bound not yet
above 0) is not asked for relative precision, so an optimum that underflows float64
cannot keep the sweeps going."""


def thresholds(lower: np.ndarray, tol: float, precision: float | None) -> np.ndarray:
    """Per entry of ``lower`` (the lower bounds), the gap below which it is known:
    ``tol``, and with ``precision`` also ``precision * lower`` (never below
    :data:`FLOOR`)."""
    if precision is None:
        return np.full(lower.shape, float(tol))
    return np.minimum(float(tol), np.maximum(precision * lower, FLOOR))


def excess(local: np.ndarray, tol: float, precision: float | None) -> float:
    """The largest ratio of a gap of ``local`` (even columns lower, odd upper bounds) to
    its threshold (:func:`thresholds`): below 1 when every gap is closed."""
    gaps = local[:, 1::2] - local[:, 0::2]
    if precision is None:
        return float(np.max(gaps, initial=0.0)) / tol
    return float(np.max(gaps / thresholds(local[:, 0::2], tol, precision), initial=0.0))


def take_rows(a: np.ndarray, index: np.ndarray) -> np.ndarray:
    """``a[index]`` (rows of a 2-D array: the bounds a column each, a block's exit
    rewards), the same new C-contiguous array to the bit, by ``take`` along the first
    axis: NumPy's fancy index of a 2-D array's rows goes through its general path, an
    index a row, ``take`` copies the rows as blocks.  QVBS ``zeroconf`` 1000-4's block
    (299,444 choices, two columns): its exits taken in the sweeps' order 8.5 ms against
    0.3-0.5; 163,751 rows of bounds 1.2-4.8 ms against 0.1-0.2."""
    index = np.asarray(index)
    return a[index] if index.dtype == bool else a.take(index, axis=0)


def put_rows(a: np.ndarray, index: np.ndarray, rows: np.ndarray) -> None:
    """``a[index] = rows`` (rows of a 2-D array, :func:`take_rows`' converse), the same
    writes: where both are C-contiguous of one dtype, each row written as one item of a
    1-D view of ``a`` whose items are its rows (NumPy's 1-D fancy assignment, an index a
    row, not its general path; a repeated index: the last row written wins, as there)."""
    index = np.asarray(index)
    if (index.dtype != bool and a.ndim == 2 and rows.ndim == 2 and a.shape[0] > 0
            and rows.shape[0] > 0
            and a.shape[1] > 0 and a.shape[1] == rows.shape[1] and a.dtype == rows.dtype
            and a.flags.c_contiguous and rows.flags.c_contiguous):
        _as_items(a)[index] = _as_items(rows)
    else:
        a[index] = rows


def _as_items(a: np.ndarray) -> np.ndarray:
    """A C-contiguous 2-D ``a`` as a 1-D view of its rows (each an opaque item)."""
    return a.view(np.dtype((np.void, a.shape[1] * a.itemsize))).reshape(-1)


def use_compiled(entries: int, block_entries: int) -> bool:
    """Whether a block of ``block_entries`` entries in a product of ``entries``
    transitions is swept with the compiled kernel by size alone (both large enough to
    pay numba's import and memory, and numba importable: imported here the first time).
    The iteration asks :func:`mitld_lp.solvers.sweep_gate.use_compiled`, which also
    sends a smaller block there where its forecast work is less."""
    return (entries >= COMPILED_MIN_ENTRIES and block_entries >= COMPILED_MIN_BLOCK_ENTRIES
            and compiled_kernel() is not None)


def kernel_loaded() -> bool:
    """Whether the compiled kernel is loaded already (its load paid in this process)."""
    return bool(_KERNEL)


def compiled_kernel() -> Any:
    """The numba kernel (compiled on the first call, cached on disk), or None if numba
    cannot be imported."""
    global _KERNEL
    if _KERNEL is None:
        try:
            _KERNEL = _build()
        except ImportError:
            logger.info("numba is not installed: the NumPy sweeps run")
            _KERNEL = False
    return _KERNEL or None


def _build() -> Any:
    # numba is imported (without PyYAML, narrowly) only where a kernel misses the
    # loader's cache (mitld_lp.util.kernel_loader); ImportError without numba
    from mitld_lp.solvers import compiled_kernels

    return compiled_kernels.gauss_seidel


def kernel_index(matrix: sp.csr_array) -> tuple[np.ndarray, np.ndarray]:
    """``matrix``'s ``indptr`` and ``indices`` as :func:`~mitld_lp.util.arrays.index_dtype`
    of its entries and columns: int32 where they fit, as SciPy gives them, else int64.
    The compiled kernel is then compiled for one index type a run (numba compiles one
    machine code per argument type: 12 s each on a cold cache), not for int32 and int64
    both; an array of the other type is copied once a block, one that has it is not."""
    dtype = index_dtype(max(int(matrix.indptr[-1]), matrix.shape[1]))
    return (matrix.indptr.astype(dtype, copy=False),
            matrix.indices.astype(dtype, copy=False))


def sweep_order(n: int) -> np.ndarray:
    """The order in which the Gauss--Seidel sweeps visit a block's ``n`` states: from
    the last to the first, as Storm's ``ValueIterationOperator`` does.  A block's states
    keep the product's order, the order of its exploration from the initial state
    (breadth first in Storm's build of a PRISM world), so the last states are the
    farthest from the initial one and, where the values flow back towards it, a value
    reaches its predecessors in the same sweep, where the forward order moves it one
    step a sweep.
    QVBS ``zeroconf`` 1000-4-false (301,219 states, the block of values near 4e-5):
    ``correct_max`` closes in 39 sweeps, ``correct_min`` in 46."""
    return np.arange(n - 1, -1, -1, dtype=np.int64)


class Prepared:
    """A block's matrix prepared for the sweeps: each choice's ``1 - self-loop`` and,
    for the NumPy sweeps, the matrix without its diagonal."""

    __slots__ = ("inner", "leave", "starts", "groups", "_order", "_diag", "_off", "guess",
                 "track", "_index", "closing", "_fold", "reverse", "loops", "_exit_rows")

    def __init__(self, inner: sp.csr_array, groups: np.ndarray) -> None:
        self.inner = inner
        self.groups = np.asarray(groups, dtype=np.int64)
        self.starts = self.groups[:-1]
        n_choices = inner.shape[0]
        n = self.groups.size - 1
        # each entry's owner state in the matrix's index type, the rows of the diagonal
        # entries alone found after (not an int64 owner and row an entry)
        owner = np.repeat(np.arange(n, dtype=inner.indices.dtype),
                          np.diff(np.asarray(inner.indptr)[self.groups]))
        diag = inner.indices == owner
        del owner
        self._diag = np.flatnonzero(diag)
        del diag
        row = np.searchsorted(inner.indptr, self._diag, side="right") - 1
        self_loop = np.bincount(row, weights=inner.data[self._diag], minlength=n_choices)
        self.leave = 1.0 - self_loop
        self._off: sp.csr_array | None = None
        self.loops = bool(self._diag.size)  # an entry on the diagonal (compiled sweeps)
        self.order = sweep_order(self.groups.size - 1)
        self._exit_rows: tuple[np.ndarray, np.ndarray] | None = None
        self.guess: np.ndarray | None = None  # the compiled sweeps' guesses, made there
        self.track: np.ndarray | None = None
        self.closing = False  # the guesses turned off near the end (iteration._close_out)
        self._index: tuple[np.ndarray, np.ndarray] | None = None
        self._fold: tuple[int, bool] | None = None

    @property
    def order(self) -> np.ndarray:
        """The states in the order the compiled sweeps visit them (:func:`sweep_order`'s
        unless set); :attr:`reverse` says whether it is that reversed range."""
        return self._order

    @order.setter
    def order(self, order: np.ndarray) -> None:
        self._order = order
        n = self.groups.size - 1
        self.reverse = bool(order.shape[0] == n
                            and np.array_equal(order, np.arange(n - 1, -1, -1)))

    def exit_rows(self, exits: np.ndarray) -> np.ndarray:
        """The choices whose row of ``exits`` (one model's two columns, C-contiguous
        float64) is not +0.0 in every bit, ascending: listed once a block for the
        one-model sweeps (kept for the same ``exits`` object, which a block never
        writes), which start every other choice's sums at 0.0, the same bits."""
        if self._exit_rows is None or self._exit_rows[0] is not exits:
            bits = exits.view(np.int64)
            odd = bits[:, 0] != 0  # a byte a choice, not the eight of an int64 "or"
            odd |= bits[:, 1] != 0
            self._exit_rows = (exits, np.flatnonzero(odd))
        return self._exit_rows[1]

    @property
    def fold(self) -> tuple[int, bool]:
        """For the NumPy sweeps: the number of choices of every state if all have the
        same (else 0), and whether every choice leaves (``leave > 0``: no guard)."""
        if self._fold is None:
            n, m = self.groups.size - 1, int(self.groups[-1])
            width = m // n if n and m % n == 0 else 0
            if width and not np.array_equal(self.starts, np.arange(0, m, width)):
                width = 0
            self._fold = (width, bool(np.all(self.leave > 0)))
        return self._fold

    @property
    def index(self) -> tuple[np.ndarray, np.ndarray]:
        """The matrix's ``indptr`` and ``indices`` in the one index type the compiled
        kernel is compiled for (:func:`kernel_index`; no copy where they have it already,
        as SciPy's int32 blocks of the solver do)."""
        if self._index is None:
            self._index = kernel_index(self.inner)
        return self._index

    @property
    def off(self) -> sp.csr_array:
        """The matrix without its diagonal entries (made for the NumPy sweeps only: the
        compiled kernel skips them in place)."""
        if self._off is None:
            data = self.inner.data.copy()
            data[self._diag] = 0.0
            self._off = sp.csr_array((data, self.inner.indices, self.inner.indptr),
                                     shape=self.inner.shape)
        return self._off


def numpy_sweeps(prep: Prepared, exits: np.ndarray, local: np.ndarray, tol: float,
                 max_sweeps: int, sense: Sense = Sense.MAX,
                 precision: float | None = None) -> tuple[int, float]:
    """At most ``max_sweeps`` Jacobi sweeps of ``local`` (in place; even columns lower,
    odd upper bounds) for the optimum in ``sense`` until every gap is below its
    threshold (module docs); the sweeps done and the largest gap over its threshold."""
    leave = prep.leave[:, None]
    width, positive = prep.fold
    op = np.maximum if sense is Sense.MAX else np.minimum
    done = 0
    over = excess(local, tol, precision)
    while done < max_sweeps and over >= 1.0:
        num = prep.off @ local
        num += exits  # in place: the same sums as exits + off @ local
        if positive:  # every choice leaves: the division alone, in place
            score = np.divide(num, leave, out=num)
        else:
            score = np.divide(num, leave, out=np.zeros_like(num), where=leave > 0)
        if width:  # each state's choices folded column by column: reduceat's operands
            rows = score.reshape(-1, width, score.shape[1])  # in its order, its floats
            new = rows[:, 0].copy()
            for j in range(1, width):
                op(new, rows[:, j], out=new)
        else:
            new = sense.reduce(score, prep.starts)
        np.clip(new, 0.0, 1.0, out=new)
        np.maximum(local[:, 0::2], new[:, 0::2], out=local[:, 0::2])
        np.minimum(local[:, 1::2], new[:, 1::2], out=local[:, 1::2])
        done += 1
        over = excess(local, tol, precision)
    return done, over


def compiled_sweeps(prep: Prepared, exits: np.ndarray, local: np.ndarray, tol: float,
                    max_sweeps: int, sense: Sense = Sense.MAX,
                    precision: float | None = None) -> tuple[int, float]:
    """As :func:`numpy_sweeps`, by the compiled Gauss--Seidel kernel (module docs)."""
    kernel = compiled_kernel()
    if kernel is None:  # pragma: no cover - the caller asked use_compiled first
        return numpy_sweeps(prep, exits, local, tol, max_sweeps, sense, precision)
    over = excess(local, tol, precision)
    if over < 1.0 or max_sweeps <= 0:
        return 0, over
    inner = prep.inner
    indptr, indices = prep.index
    if prep.guess is None or prep.guess.shape != local.shape:
        prep.guess = np.zeros_like(local)
        prep.track = _new_track(local.shape[1], OPTIMISTIC)
    exits = np.ascontiguousarray(exits, dtype=np.float64)
    listed = prep.reverse and local.shape[1] == 2  # one model: its exit rows listed
    rows = prep.exit_rows(exits) if listed else _NO_ROWS
    done, over = kernel(indptr, indices, inner.data, prep.groups, prep.leave, exits, local,
                        prep.order, int(max_sweeps), float(tol), sense is Sense.MIN,
                        -1.0 if precision is None else float(precision), FLOOR,
                        prep.guess, prep.track, rows, listed, prep.loops)
    return int(done), float(over)


_NO_ROWS = np.empty(0, dtype=np.int64)

OPTIMISTIC = True
"""Whether the compiled sweeps guess and verify bounds (module docs)."""


def _new_track(k: int, optimistic: bool) -> np.ndarray:
    """The compiled kernel's state between calls for ``k`` columns (its layout:
    :data:`mitld_lp.solvers.compiled_kernels.OFF`): watching (or plain sweeps), the
    guesses' first margin 1/16 of the extrapolated correction."""
    track = np.zeros(8 + 6 * k)
    track[0] = 0.0 if optimistic else -1.0
    track[5] = 1.0 / 16.0
    return track


def watch_again(track: np.ndarray, k: int) -> None:
    """``track`` (:func:`_new_track`'s, ``k`` columns) watching again for guesses after
    plain sweeps: its watched sweeps and each column's changes and ratios from before
    them cleared (a guess is made only from ratios read in watched sweeps in a row)."""
    track[0] = 0.0
    track[4] = 0.0
    track[8:8 + 3 * k] = 0.0
