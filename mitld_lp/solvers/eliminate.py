r"""A block LP's single-choice states eliminated before the solver (issue 45).

After pruning (:func:`mitld_lp.solvers.lp_blocks.may_be_optimal`) most states of a block keep
one column: on ``bus_scaled`` n64 d3, 4,005 of the 4,096 states of one block and 7,047
of the 8,192 of the other.  Their flow is not a decision.  With ``S`` those states and
``M`` the others, the value of ``S`` is :math:`v_S = a + B v_M`, with
:math:`a = (I - P_{SS})^{-1} r_S` and :math:`B = (I - P_{SS})^{-1} P_{SM}`, so the block's
occupancy LP (``b = 1``) is the LP over ``M`` alone whose choices ``c`` move by
:math:`\tilde P(c, \cdot) = P(c, M) + P(c, S) B` and earn
:math:`\tilde r(c) = r(c) + P(c, S) a`, with start weights :math:`\tilde b = 1 + P_{SM}^T
x_0`, :math:`x_0 = (I - P_{SS})^{-T} \mathbf 1` (the unit flow of every ``S`` state
routed on to ``M``).  Its optimum plus :math:`r_S' x_0` is the block LP's; its duals
are :math:`v_M`, and its occupancies are the block LP's on the columns of ``M``.
:meth:`Elimination.lift` gives back the whole block: :math:`v_S` from :math:`v_M`, and the
flow of ``S`` from the occupancies of ``M``: :math:`x_S = (I - P_{SS})^{-T}(\mathbf 1 +
P_{MS}^T y_M)`.

``B`` is formed only on the rows the choices of ``M`` enter (and the states below them
in ``S``), by a sparse accumulator over ``S``'s own strongly connected components,
downstream first (:mod:`.compiled_elimination`, numba): a single state by its
self-loop, a cyclic component (the grid's back-and-forth moves make most of them:
339 components on the 8,192-state block above, up to 314 states) by one dense solve
over the columns of ``M`` it reaches.  A cyclic component of more than
:data:`DENSE_LIMIT` states is not eliminated: its states stay in the LP as ``M``
states with their one column (and if more than :data:`MAX_KEPT_SHARE` of ``S`` would
stay, or every one, they are all eliminated by one sparse LU instead,
:mod:`mitld_lp.solvers.sparse_elimination`).  If ``B`` would hold more than
:data:`FILL_FACTOR` times
the block's kept entries, or its dense solves more than :data:`WORK_PER_ENTRY`
operations per kept entry (checked before each solve), the block's whole LP is solved
instead.

The exported LP (``export --lp``, :func:`mitld_lp.solvers.export.write_lp`) and the
constrained LP are the whole LP; this is a presolve of one block's solve, whose
answer the crossover (:func:`mitld_lp.solvers.crossover.polish`) makes exact over every
choice of the block, and the certificate checks independently.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers.graph import levels
from mitld_lp.solvers.kernels import COMPILED_MIN_BLOCK_ENTRIES, COMPILED_MIN_ENTRIES
from mitld_lp.solvers.sparse_elimination import (
    ReducedBlock,
    SparseElimination,
    sparse_eliminate,
)

__all__ = ["DENSE_LIMIT", "FILL_FACTOR", "MIN_BLOCK_ENTRIES", "MIN_ENTRIES",
           "MIN_PRODUCT_ENTRIES", "MAX_KEPT_SHARE", "WORK_PER_ENTRY", "Elimination", "eliminate",
           "worth_eliminating"]

logger = logging.getLogger(__name__)

MIN_PRODUCT_ENTRIES = COMPILED_MIN_ENTRIES
MIN_BLOCK_ENTRIES = COMPILED_MIN_BLOCK_ENTRIES
"""A block is reduced in a quotient of at least :data:`MIN_PRODUCT_ENTRIES` entries when
it has at least :data:`MIN_BLOCK_ENTRIES` (the compiled sweeps' thresholds,
:mod:`mitld_lp.solvers.kernels`: numba is loaded and warm by then).  Loading numba and
its first call cost 0.6-1.1 s of CPU, more than the whole Clarabel solve of a smaller
block (0.23 s for both blocks of ``bus_scaled`` n64 d3, 98,288 and 49,144 entries)."""

MIN_ENTRIES = 5_000
"""A block's kept entries (after pruning) from which it is reduced."""

DENSE_LIMIT = 400
"""States of a cyclic component of ``S`` solved dense (about 20 MFlop at this size);
a larger component stays in the LP."""

MAX_KEPT_SHARE = 0.2
"""The largest share of the single-choice states that may stay in the LP (in components
past :data:`DENSE_LIMIT`) for the compiled walk to reduce the block (past it, one sparse
LU eliminates them all, :mod:`mitld_lp.solvers.sparse_elimination`): every state kept widens
the rows of ``B`` of the states upstream (``bus_scaled`` n128 d3's smaller block: 5,995
of its 15,063 would stay, the reduced LP has 7,316 rows and its elimination costs 2-3x
Clarabel's solve of the whole block; its larger block keeps 1,142 of 22,296)."""

FILL_FACTOR = 32.0
"""``B``'s entries allowed, in multiples of the block's kept entries."""

WORK_PER_ENTRY = 2_500.0
"""The dense solves' floating-point operations allowed per kept entry of the block,
checked before each component's solve (about a third of Clarabel's time on the whole
block's LP: 0.67 s for the 53,000 kept entries of ``bus_scaled`` n128 d3's smaller
block, whose elimination would cost 1-2 s with its components of 1,300-2,000 states
kept in the LP)."""

_KERNELS: Any = None  # the compiled module once imported, False without numba


def _kernels() -> Any:
    global _KERNELS
    if _KERNELS is None:
        try:
            from mitld_lp.solvers import compiled_elimination

            _KERNELS = compiled_elimination
        except ImportError:
            logger.info("numba is not installed: block LPs are solved whole")
            _KERNELS = False
    return _KERNELS or None


def worth_eliminating(product_entries: int, block_entries: int, kept_entries: int) -> bool:
    """Whether a block of ``block_entries`` entries, ``kept_entries`` of them in the
    columns left after pruning, in a quotient of ``product_entries``, is reduced (all
    large enough, and numba importable: imported here the first time)."""
    return (product_entries >= MIN_PRODUCT_ENTRIES and block_entries >= MIN_BLOCK_ENTRIES
            and kept_entries >= MIN_ENTRIES and _kernels() is not None)


@dataclass(frozen=True, slots=True, eq=False)
class Elimination(ReducedBlock):
    """A :class:`~mitld_lp.solvers.sparse_elimination.ReducedBlock` by the compiled walk
    over ``S``'s components, and what :meth:`lift` needs."""

    _comps: tuple[np.ndarray, np.ndarray]
    _s_rows: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]  # ptr, idx, val, rew
    _m_rows: tuple[np.ndarray, np.ndarray, np.ndarray]  # ptr, idx, val

    def lift(self, y_m: np.ndarray, v_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The block's occupancy per column (0 on the pruned ones) and value per state
        from the reduced LP's occupancies ``y_m`` (per ``m_cols``) and duals ``v_m``."""
        k = _kernels()
        ptr, idx, val, rew = self._s_rows
        row = np.repeat(np.arange(self.s_states.size), np.diff(ptr))
        to_m = idx < 0
        base_v = rew + np.bincount(row[to_m], weights=val[to_m] * v_m[-1 - idx[to_m]],
                                   minlength=self.s_states.size)
        v = np.zeros(self.n_states)
        v[self.m_states] = v_m
        v[self.s_states] = k.downstream(*self._comps, ptr, idx, val, base_v)
        c_ptr, c_idx, c_val = self._m_rows
        c_row = np.repeat(np.arange(self.m_cols.size), np.diff(c_ptr))
        to_s = c_idx >= 0
        base_x = 1.0 + np.bincount(c_idx[to_s], weights=c_val[to_s] * y_m[c_row[to_s]],
                                   minlength=self.s_states.size)
        y = np.zeros(self.n_choices)
        y[self.m_cols] = y_m
        y[self.s_cols] = np.maximum(k.upstream(*self._comps, ptr, idx, val, base_x), 0.0)
        return y, v


def _split(groups: np.ndarray, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per state, whether it keeps one column; per state, its first kept column."""
    n = groups.size - 1
    cols = np.flatnonzero(keep)
    owner = np.repeat(np.arange(n), np.diff(groups))[cols]
    return np.bincount(owner, minlength=n) == 1, cols


def eliminate(inner: sp.csr_array, reward: np.ndarray, groups: np.ndarray,
              keep: np.ndarray) -> Elimination | SparseElimination | None:
    """The reduced LP of a block (``inner``: its choices' moves inside it, ``reward``
    their exit rewards, ``groups`` its states' ranges of choices, ``keep`` the columns
    left after pruning), or ``None`` when nothing is eliminated or ``B`` would fill past
    its budget (module docs).  Where too many of the single-choice states lie in
    components past :data:`DENSE_LIMIT`, they are all eliminated by one sparse LU
    instead (:mod:`mitld_lp.solvers.sparse_elimination`, on its own budget)."""
    k = _kernels()
    if k is None:
        return None
    n = groups.size - 1
    single, cols = _split(groups, keep)
    owner_all = np.repeat(np.arange(n), np.diff(groups))
    if not single.any():
        return None
    # S's own graph: its components (kept in the LP past DENSE_LIMIT) and their order
    s_states = np.flatnonzero(single)
    s_cols = cols[single[owner_all[cols]]]
    local = np.full(n, -1, np.int64)
    local[s_states] = np.arange(s_states.size)
    rows = sp.csr_array(inner[s_cols])
    succ = local[rows.indices]
    row_of = np.repeat(np.arange(s_states.size), np.diff(rows.indptr))
    inside = succ >= 0
    found = levels(sp.csr_array((np.ones(int(inside.sum()), bool),
                                 (row_of[inside], succ[inside])),
                                shape=(s_states.size, s_states.size)))
    size = np.bincount(found.component)
    big = size[found.component] > DENSE_LIMIT
    if np.count_nonzero(big) > MAX_KEPT_SHARE * s_states.size or big.all():
        logger.info("no compiled elimination: %d of the %d single-choice states lie in "
                    "components of more than %d: one sparse LU instead",
                    np.count_nonzero(big), s_states.size, DENSE_LIMIT)
        return sparse_eliminate(inner, reward, groups, keep)
    if big.any():
        single[s_states[big]] = False
    return _reduce(k, inner, reward, groups, cols, single, owner_all,
                   found.component[~big], found.level[found.component[~big]],
                   int(rows.nnz))


def _reduce(k: Any, inner: sp.csr_array, reward: np.ndarray, groups: np.ndarray,
            cols: np.ndarray, single: np.ndarray, owner_all: np.ndarray,
            component: np.ndarray, level: np.ndarray, s_entries: int) -> Elimination | None:
    """:func:`eliminate` once ``S`` (``single``) is fixed; ``component`` and ``level``
    per state of ``S`` (in state order)."""
    n = groups.size - 1
    s_states, m_states = np.flatnonzero(single), np.flatnonzero(~single)
    code = np.empty(n, np.int64)  # S: its S-local id; M: -1 - its M-local id
    code[s_states] = np.arange(s_states.size)
    code[m_states] = -1 - np.arange(m_states.size)
    is_s = single[owner_all[cols]]
    s_cols, m_cols = cols[is_s], cols[~is_s]
    rows_s = sp.csr_array(inner[s_cols])
    s_ptr, s_idx = rows_s.indptr.astype(np.int64), code[rows_s.indices]
    s_rew = np.ascontiguousarray(reward[s_cols], dtype=np.float64)
    # components downstream first, as runs of comp_states
    order = np.lexsort((component, level))
    comp_sorted = component[order]
    starts = np.flatnonzero(np.diff(comp_sorted, prepend=-1))
    comp_ptr = np.append(starts, order.size).astype(np.int64)
    comp_of = np.empty(s_states.size, np.int64)
    comp_of[order] = np.repeat(np.arange(starts.size), np.diff(comp_ptr))
    rows_m = sp.csr_array(inner[m_cols])
    c_ptr, c_idx = rows_m.indptr.astype(np.int64), code[rows_m.indices]
    seed = np.zeros(s_states.size, bool)
    seed[c_idx[c_idx >= 0]] = True
    needed, port = k.reach(comp_ptr, order, comp_of, s_ptr, s_idx, seed)
    budget = int(FILL_FACTOR * (s_entries + rows_m.nnz))
    a, row_ptr, row_len, b_idx, b_val, work, ok = k.boundary_rows(
        comp_ptr, order, needed, port, s_ptr, s_idx, rows_s.data, s_rew, m_states.size,
        budget, WORK_PER_ENTRY * (s_entries + rows_m.nnz))
    logger.debug("elimination of %d states: work %.3g", s_states.size, work)
    if not ok:
        logger.info("elimination of %d states stopped: past its budget of %d entries or "
                    "%.3g operations", s_states.size, budget,
                    WORK_PER_ENTRY * (s_entries + rows_m.nnz))
        return None
    out_ptr, o_idx, o_val, rew = k.reduced_rows(c_ptr, c_idx, rows_m.data, reward[m_cols],
                                                a, row_ptr, row_len, b_idx, b_val,
                                                m_states.size)
    moves = sp.csr_array((o_val, o_idx, out_ptr), shape=(m_cols.size, m_states.size))
    x0 = k.upstream(comp_ptr, order, s_ptr, s_idx, rows_s.data, np.ones(s_states.size))
    to_m = s_idx < 0
    s_row = np.repeat(np.arange(s_states.size), np.diff(s_ptr))
    b_eq = 1.0 + np.bincount(-1 - s_idx[to_m], weights=rows_s.data[to_m] * x0[s_row[to_m]],
                             minlength=m_states.size)
    owner = -1 - code[owner_all[m_cols]]
    return Elimination(n, groups[-1], m_states, m_cols, s_states, s_cols, owner, moves, rew,
                       b_eq, float(x0 @ s_rew), (comp_ptr, order),
                       (s_ptr, s_idx, rows_s.data, s_rew), (c_ptr, c_idx, rows_m.data))
