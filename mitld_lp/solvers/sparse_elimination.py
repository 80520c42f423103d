r"""A block LP's single-choice states eliminated by one sparse LU (issue 45): the
fallback of :func:`mitld_lp.solvers.eliminate.eliminate` where its compiled walk refuses
because too many of those states lie in cyclic components too large to solve dense.

The algebra is :mod:`mitld_lp.solvers.eliminate`'s: with ``S`` the states left one
column after pruning and ``M`` the others, ``A = I - P_SS`` (invertible: every policy
leaves the quotient's blocks almost surely), the LP over ``M`` has the rows
:math:`P(c, M) + P(c, S) A^{-1} P_{SM}`, the rewards :math:`r(c) + P(c, S) A^{-1} r_S`
and the start weights :math:`1 + P_{SM}^T x_0`, :math:`x_0 = A^{-T}\mathbf 1`; its
optimum plus :math:`r_S' x_0` is the block LP's.  Here ``A`` is factored once by SuperLU
(SciPy), whatever the components of ``S``, and only the rows of :math:`A^{-1}` of the
*ports* (the states of ``S`` that a choice of ``M`` enters) are formed: on
``bus_scaled`` n128 d3's 16,384-state block, 226 ports of 15,063 eliminated states
(5,995 of them in cyclic components of more than 400 states, where the compiled
walk's dense solves would cost more than the LP), 187 columns of ``M`` reached.

The work is estimated before it is done: the ports' dense rows are checked against
:data:`FILL_FACTOR` times the block's kept entries before anything is factored; once the
factor is made (its cost, one SuperLU factorisation, is the one step taken before its
check: SuperLU tells no fill before it factors), its fill is checked against the same, and
the port solves (two operations per entry of the factor and right-hand side) against
:data:`WORK_PER_ENTRY` per kept entry; past either, the block's whole LP is solved as
before.  :meth:`SparseElimination.
lift` gives back the block: :math:`v_S = A^{-1}(r_S + P_{SM} v_M)` and the flow of ``S``,
:math:`x_S = A^{-T}(\mathbf 1 + P_{MS}^T y_M)`, by the same factor.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

__all__ = ["FILL_FACTOR", "WORK_PER_ENTRY", "ReducedBlock", "SparseElimination",
           "sparse_eliminate"]

logger = logging.getLogger(__name__)

FILL_FACTOR = 16.0
"""The LU factor's entries allowed, in multiples of the block's kept entries (n128 d3's
smaller block: 311,349 for 53,000 kept entries, about 6)."""

WORK_PER_ENTRY = 6_000.0
"""The port solves' operations (two per entry of the factor and right-hand side)
allowed per kept entry of the block.  SuperLU's solves run at a few hundred MFlop/s
here; at this budget they cost at most about half of Clarabel's interior-point solve of
the whole block (measured on n128 d3's smaller block: 1.3e8 operations, 0.4 s for the
whole elimination against 0.94 s for Clarabel on the block)."""


@dataclass(frozen=True, slots=True, eq=False)
class ReducedBlock:
    """What a block's reduction gives the LP (both eliminations'): the LP over ``M``
    (``moves``, ``objective``, ``b_eq``; columns ``m_cols`` owned by ``owner``,
    ``M``-local) and the block's partition (block-local ids).

    Attributes:
        offset: :math:`r_S' x_0`: the reduced objective plus it is the block LP's.
    """

    n_states: int
    n_choices: int
    m_states: np.ndarray
    m_cols: np.ndarray
    s_states: np.ndarray
    s_cols: np.ndarray  # the one kept column of each S state
    owner: np.ndarray
    moves: sp.csr_array
    objective: np.ndarray
    b_eq: np.ndarray
    offset: float

    @property
    def n_m(self) -> int:
        return int(self.m_states.size)


@dataclass(frozen=True, slots=True, eq=False)
class SparseElimination(ReducedBlock):
    """A :class:`ReducedBlock` by one sparse LU, and what :meth:`lift` needs.

    Attributes:
        b_eq: the start weights divided by ``scale`` (their mean): the flow through the
            eliminated states makes them run to hundreds, where Clarabel stopped at its
            reduced tolerances on the LP as it comes (n128 d3's smaller block), and the
            duals (the values) do not depend on it.
        offset: :math:`r_S' x_0`: ``scale`` times the reduced objective plus it is the
            block LP's.
    """

    scale: float
    _lu: _Factor  # A = I - P_SS factored
    _p_sm: sp.csr_array
    _p_ms: sp.csr_array  # the M columns' rows into S
    _r_s: np.ndarray

    def lift(self, y_m: np.ndarray, v_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The block's occupancy per column (0 on the pruned ones) and value per state
        from the reduced LP's occupancies ``y_m`` (per ``m_cols``) and duals ``v_m``."""
        v = np.zeros(self.n_states)
        v[self.m_states] = v_m
        v[self.s_states] = self._lu.solve(self._r_s + self._p_sm @ v_m)
        y = np.zeros(self.n_choices)
        y[self.m_cols] = y_m * self.scale
        x_s = self._lu.solve_t(1.0 + self._p_ms.T @ y[self.m_cols])
        y[self.s_cols] = np.maximum(x_s, 0.0)
        return y, v


def sparse_eliminate(inner: sp.csr_array, reward: np.ndarray, groups: np.ndarray,
                     keep: np.ndarray) -> SparseElimination | None:
    """The reduced LP of a block (``inner``: its choices' moves inside it, ``reward``
    their exit rewards, ``groups`` its states' ranges of choices, ``keep`` the columns
    left after pruning, each state keeping one at least), or ``None`` when no state is
    left one column, every state is, or the factor or its solves would pass their
    budgets (module docs)."""
    from scipy.sparse.linalg import splu

    n = groups.size - 1
    owner_all = np.repeat(np.arange(n), np.diff(groups))
    cols = np.flatnonzero(keep)
    single = np.bincount(owner_all[cols], minlength=n) == 1
    s_states, m_states = np.flatnonzero(single), np.flatnonzero(~single)
    if s_states.size == 0 or m_states.size == 0:
        return None
    is_s = single[owner_all[cols]]
    s_cols, m_cols = cols[is_s], cols[~is_s]  # S's columns in S's order (one a state)
    kept = int(np.diff(inner.indptr)[cols].sum())
    rows_s, rows_m = sp.csr_array(inner[s_cols]), sp.csr_array(inner[m_cols])
    p_ss, p_sm = rows_s[:, s_states], sp.csr_array(rows_s[:, m_states])
    p_ms, p_mm = sp.csc_array(rows_m[:, s_states]), rows_m[:, m_states]
    ports = np.flatnonzero(np.diff(p_ms.indptr))  # S states a column of M enters
    used = np.flatnonzero(np.diff(sp.csc_array(p_sm).indptr))  # M columns S enters
    a = sp.csc_array(sp.eye_array(s_states.size, format="csc") - p_ss)
    # fewer ports than columns reached: their rows of A^-1 as columns of A^-T, by a
    # factor of A^T; else the columns reached (and the rewards) through A's
    transposed = ports.size < used.size + 1
    dense = ports.size * (used.size + 1)  # the ports' rows, held dense
    if dense > FILL_FACTOR * kept:  # known before the factor: refused before it
        logger.info("no sparse elimination of %d states: %d ports' dense rows of %d "
                    "entries (budget %.3g entries)", s_states.size, ports.size,
                    used.size + 1, FILL_FACTOR * kept)
        return None
    try:
        # the symmetric pattern's minimum degree: on the bus grid's blocks 0.7x the fill
        # of COLAMD (SuperLU's default), and the solves are what the elimination costs
        lu = _Factor(splu(sp.csc_array(a.T) if transposed else a,
                          permc_spec="MMD_AT_PLUS_A"), transposed)
    except RuntimeError as exc:  # singular: S would keep flow for ever (not a quotient)
        logger.info("no sparse elimination of %d states: %s", s_states.size, exc)
        return None
    fill = lu.fill
    # the port solves by the side with fewer right-hand sides, x0 and the two lifts
    work = 2.0 * fill * (min(ports.size, used.size + 1) + 3)
    if fill > FILL_FACTOR * kept or work > WORK_PER_ENTRY * kept:
        logger.info("no sparse elimination of %d states: a factor of %d entries, %.3g "
                    "operations for %d ports (budgets %.3g entries, %.3g operations)",
                    s_states.size, fill, work, ports.size, FILL_FACTOR * kept,
                    WORK_PER_ENTRY * kept)
        return None
    r_s = np.ascontiguousarray(reward[s_cols], dtype=np.float64)
    b_ports, a_ports = _port_rows(lu, p_sm, r_s, ports, used)
    p_mp = sp.csr_array(p_ms[:, ports])
    reach = sp.csr_array((b_ports.ravel(), (np.repeat(np.arange(ports.size), used.size),
                                             np.tile(used, ports.size))),
                         shape=(ports.size, m_states.size))
    moves = sp.csr_array(p_mm + p_mp @ reach)
    moves.sum_duplicates()
    moves.eliminate_zeros()
    objective = reward[m_cols] + p_mp @ a_ports
    x0 = lu.solve_t(np.ones(s_states.size))
    b_eq = 1.0 + p_sm.T @ x0
    scale = float(np.mean(b_eq))
    owner = np.searchsorted(m_states, owner_all[m_cols])
    logger.info("sparse elimination of %d single-choice states (%d ports, a factor of %d "
                "entries): an LP of %d states and %d columns", s_states.size, ports.size,
                fill, m_states.size, m_cols.size)
    return SparseElimination(n, int(groups[-1]), m_states, m_cols, s_states, s_cols, owner,
                             moves, objective, b_eq / scale, float(x0 @ r_s), scale, lu, p_sm,
                             sp.csr_array(p_ms), r_s)


BATCH = 256
"""Right-hand sides solved at a time (a dense block of this many columns per state), at
most :data:`BLOCK_FLOATS` floats in all."""

BLOCK_FLOATS = 1 << 22
"""The largest block of right-hand sides solved at once, in floats (32 MB)."""


class _Factor:
    """A sparse LU of ``A`` or of ``A^T`` (SuperLU's, ``transposed``), solving with
    either; a block of right-hand sides goes through the compiled triangular solves
    (:func:`~mitld_lp.solvers.compiled_elimination.lu_solve`) on the side factored."""

    def __init__(self, lu: Any, transposed: bool) -> None:
        self.lu, self.transposed = lu, transposed
        self.fill = int(lu.L.nnz + lu.U.nnz)

    def solve(self, b: np.ndarray) -> np.ndarray:
        """``A^-1 b``."""
        return self.lu.solve(b, trans="T") if self.transposed else self.lu.solve(b)

    def solve_t(self, b: np.ndarray) -> np.ndarray:
        """``A^-T b``."""
        return self.lu.solve(b) if self.transposed else self.lu.solve(b, trans="T")

    def block(self, rhs: np.ndarray) -> np.ndarray:
        """``F^-1 rhs`` for the matrix factored (``A``, or ``A^T`` if transposed) and a
        dense block ``rhs`` (a row a state).  SuperLU's ``Pr F Pc = L U``: the rows
        permuted by ``perm_r``, both triangles, the result read through ``perm_c``."""
        try:
            from mitld_lp.solvers.compiled_elimination import lu_solve
        except ImportError:  # no numba: SuperLU's own solve
            return np.asarray(self.lu.solve(np.asfortranarray(rhs)))
        x = np.empty(rhs.shape)
        x[self.lu.perm_r] = rhs
        low, up = self.lu.L, self.lu.U
        lu_solve(low.indptr, low.indices, low.data, up.indptr, up.indices, up.data, x)
        return x[self.lu.perm_c]


def _port_rows(lu: _Factor, p_sm: sp.csr_array, r_s: np.ndarray, ports: np.ndarray,
               used: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The ports' rows of ``A^-1 [P_SM, r_S]``: ``(ports, used)`` dense and the rewards
    ``(ports,)``, by the side :func:`sparse_eliminate` factored (the ports' unit vectors
    through ``A^T``, or the used columns and the rewards through ``A``), :data:`BATCH`
    right-hand sides at a time (fewer past :data:`BLOCK_FLOATS`)."""
    n_s = r_s.size
    step = max(1, min(BATCH, BLOCK_FLOATS // max(n_s, 1)))
    if lu.transposed:
        rhs_p = sp.csc_array(p_sm[:, used])
        b = np.empty((ports.size, used.size))
        a = np.empty(ports.size)
        for lo in range(0, ports.size, step):
            hi = min(lo + step, ports.size)
            unit = np.zeros((n_s, hi - lo))
            unit[ports[lo:hi], np.arange(hi - lo)] = 1.0
            cols = lu.block(unit)  # columns of A^-T: the ports' rows of A^-1
            b[lo:hi] = (rhs_p.T @ cols).T
            a[lo:hi] = r_s @ cols
        return b, a
    rhs = sp.csc_array(sp.hstack([p_sm[:, used], sp.csc_array(r_s[:, None])]))
    out = np.empty((ports.size, used.size + 1))
    for lo in range(0, used.size + 1, step):
        hi = min(lo + step, used.size + 1)
        out[:, lo:hi] = lu.block(rhs[:, lo:hi].toarray())[ports]
    return out[:, :-1], out[:, -1]
