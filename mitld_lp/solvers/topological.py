r"""The quotient solved block by block, downstream first.

The product of a timed task is almost acyclic: clocks and the automaton only move
forward, so most strongly connected components (SCCs) of the quotient's state graph are
single states and the graph of components is shallow.  The optimal value of a state
depends only on the states it can reach, so the components can be solved one *level* at
a time: level 0 are the components with no successor component, level ``k`` those whose
successor components all have levels below ``k``.  When a level is solved, every value
its choices can leave to is already known and enters as a constant (an *exit reward*).

A single-state component ``{s}`` is solved exactly: with exit reward
:math:`r(c) = \hat P(c, \mathit{target}) + \sum_{s' \ne s} \hat P(c, s')\, v(s')` and
self-loop probability :math:`p(c) = \hat P(c, s) < 1` (the quotient has no end
components), the Bellman equation :math:`v = \max_c r(c) + p(c)\, v` has the least
solution

.. math:: v(s) = \max_c \frac{r(c)}{1 - p(c)},

because :math:`r + p v \le v` iff :math:`v \ge r / (1 - p)` (for a minimum
:math:`\min_c`, the one solution of :math:`v = \min_c r(c) + p(c) v`).  All single-state
components of one level are updated at once (one sparse product and a segmented max).
The non-trivial components of a level are left to the caller (one occupancy LP, or
interval iteration, per level).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers import level_batches, level_gate
from mitld_lp.solvers.block_cut import Block
from mitld_lp.solvers.graph import (
    Blocks,
    Level,
    Sense,
    blocks_from,
    graph_blocks,
    graph_view,
    segmented_argmax,
)
from mitld_lp.solvers.level_batches import TIE
from mitld_lp.solvers.reduced import Quotient
from mitld_lp.solvers.rows import CSRRows, gather_ranges, off_diagonal_entries, rows_dot
from mitld_lp.util import kernel_loader
from mitld_lp.util.arrays import index_dtype

if TYPE_CHECKING:
    from scipy.sparse.linalg import SuperLU

__all__ = [
    "Block", "Blocks", "Level", "LevelUpdate", "blocks", "blocks_from", "Factors",
    "evaluate_chain", "gather_ranges", "graph_blocks", "solve_chain", "transient_solve",
    "improve_policy", "GAIN", "single_scores", "SingleLevels", "solve_single_states",
    "level_kernels",
]

POLICY_ROUNDS = 50
"""At most this many policy improvements per :func:`improve_policy` call."""


def state_graph(q: Quotient) -> sp.csr_array:
    """``(n, n)`` pattern of the quotient: ``s -> s'`` iff a choice of ``s`` may move to
    ``s'`` (its matrix stores no zeros)."""
    return graph_view(q.matrix, q.row_groups)


def blocks(q: Quotient) -> Blocks:
    """The SCCs of ``q``'s state graph and their levels: the order the analysis that
    made ``q`` found (:mod:`mitld_lp.solvers.analysis`), not computed again."""
    return q.order


@dataclass(frozen=True, slots=True, eq=False)
class LevelUpdate:
    """The exact values of single-state components and the choices that attain them."""

    states: np.ndarray
    values: np.ndarray
    choices: np.ndarray  # reduced choice per state


def solve_single_states(
    q: Quotient, b: Blocks, states: np.ndarray, values: np.ndarray, *, tie: float = TIE
) -> LevelUpdate:
    r"""Solve the single-state components ``states`` given ``values`` downstream.

    ``v(s) = max_c r(c) / (1 - p(c))`` (module docs; the min for a minimum), written
    into ``values[states]`` (what was there is ignored).  Ties (within ``tie``
    relative to the best score) go as in :func:`mitld_lp.solvers.quotient.
    greedy_choices`.
    """
    states = np.asarray(states, dtype=np.int64)
    if states.size == 0:
        empty = np.zeros(0, dtype=np.int64)
        return LevelUpdate(empty, np.zeros(0), empty)
    choices, score, groups = single_scores(q, b, states, q.to_target, values)
    prefer = q.to_target[choices]
    best = segmented_argmax(score, groups, tie=tie, sense=q.sense,
                            prefer=prefer if q.sense is Sense.MAX else -prefer)
    values[states] = score[best]
    return LevelUpdate(states, score[best], choices[best])


def single_scores(q: Quotient, b: Blocks, states: np.ndarray, rewards: np.ndarray,
                  values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r"""The choices of the single-state components ``states`` scored against
    ``values`` downstream: :math:`(r(c) + \sum_{s' \ne s} P(c, s') v(s')) / (1 - p(c))`
    clipped to [0, 1], with ``r = rewards[c]`` the one-step probability of the target and
    ``p(c)`` the choice's self-loop (module docs).  ``rewards`` and ``values`` may carry
    a column per model (the iteration's bounds): every column is scored at once.
    Returns the choices, their scores and the first position of each state's choices
    (its last entry the total); ``values[states]`` is set to 0 (their own successors are
    not summed)."""
    lo, hi = q.row_groups[states], q.row_groups[states + 1]
    choices = gather_ranges(lo, hi)
    values[states] = 0.0
    reward = rewards[choices] + rows_dot(q.matrix, choices, values)
    leave = 1.0 - b.self_loop[choices]
    if reward.ndim == 2:
        leave = leave[:, None]
    # leave > 0 on the quotient (no end components); the guard keeps rounding harmless.
    score = np.divide(reward, leave, out=np.zeros_like(reward), where=leave > 0)
    np.clip(score, 0.0, 1.0, out=score)
    return choices, score, np.concatenate([[0], np.cumsum(hi - lo)])


LEVEL_KERNEL_MIN_ENTRIES = 100_000
"""Quotient entries from which the single-state levels are walked by the compiled
kernels (:mod:`mitld_lp.solvers.level_kernels`), if numba is loaded already (for a
block's sweeps) or there are at least :data:`LEVEL_KERNEL_MIN_LEVELS` levels."""

LEVEL_KERNEL_MIN_LEVELS = 3_000
"""Levels from which the compiled walks pay numba's load.  Measured on QVBS
``firewire_dl`` 3-600 (168,064 states, 635 levels; CPU seconds): the kernels took the
solve stage from 0.41 s to 0.28 s once loaded, but numba's import (0.15 s) and its first
cached kernel (0.22 s: LLVM's set-up) made the first solve 0.75 s; the NumPy runs of
levels cost some 60 microseconds a level and walk, four walks a solve."""

_LEVEL_KERNELS: Any = None  # the compiled module once imported, False without numba


def level_kernels(entries: int, n_levels: int, compiled: bool | None = None, *,
                  singles: bool = False) -> Any:
    """The compiled level walks (:mod:`mitld_lp.solvers.level_kernels`, imported here
    the first time) for a quotient of ``entries`` entries over ``n_levels`` levels, or
    ``None`` for the NumPy walks: a small product, a shallow one while numba is not
    loaded, numba not installed, or ``compiled=False`` (``True``: whatever the size, if
    numba is installed); ``singles`` (the single-state walks) deep enough for
    :func:`mitld_lp.solvers.level_gate.deep` whatever its size.  Both walks give the
    same answers to the last bit."""
    global _LEVEL_KERNELS
    if compiled is False or (compiled is None and (
            entries < LEVEL_KERNEL_MIN_ENTRIES or (n_levels < LEVEL_KERNEL_MIN_LEVELS
                                                   and not kernel_loader.compiled_paid()))
            and not (singles and level_gate.deep(n_levels))):
        return None
    if _LEVEL_KERNELS is None:
        try:
            from mitld_lp.solvers import level_kernels as compiled_levels

            _LEVEL_KERNELS = compiled_levels
        except ImportError:
            _LEVEL_KERNELS = False
    return _LEVEL_KERNELS or None


class SingleLevels:
    """The single-state components of a quotient's levels, gathered once for a walk
    that solves them level by level (:func:`single_scores`' formula): a product with a
    deadline clock has a thousand levels and more (QVBS ``zeroconf_dl`` 1000-1-30:
    91,929 single states over 1,164 levels, not one non-trivial component), where
    gathering each level's choices and entries anew cost more than the arithmetic.
    Each level's single states, their choices and the entries of those (a choice's
    self-loop left out: it is divided out) are contiguous slices of the arrays made
    here, so a level costs a few NumPy calls on its slice.  The compiled walks copy no
    entry: they read each choice's row of the quotient's CSR arrays (:attr:`rows`) in
    place and skip the state's self-loop, the same terms in the same order (single-85b).
    ``skip``: states left out (they keep what they have)."""

    __slots__ = ("states", "choices", "_local", "cols", "vals", "leave", "level_state",
                 "state_choice", "choice_entry", "sense", "kernels", "positive", "runs",
                 "run_at", "first_choice", "owner_at", "ptr", "rows")

    def __init__(self, q: Quotient, b: Blocks, skip: np.ndarray | None = None, *,
                 compiled: bool | None = None) -> None:
        order = b.by_level
        level_of = np.repeat(np.arange(b.n_levels), np.diff(b.level_starts))
        one = b.size[b.component[order]] == 1
        if skip is not None:
            one &= ~skip[order]
        # the compiled walks (:func:`level_kernels`): the same answers, one call a run
        self.kernels = level_kernels(q.matrix.nnz, b.n_levels, compiled, singles=True)
        # the NumPy walks index with any integer type: their states, choices and
        # pointers in 4 bytes where the sizes allow (index_dtype); the compiled walks'
        # signatures take int64's
        wide = self.kernels is not None
        self.states = order[one]
        if not wide:
            self.states = self.states.astype(index_dtype(q.matrix.shape[1]), copy=False)
        self.level_state = np.searchsorted(level_of[one], np.arange(b.n_levels + 1))
        lo, hi = q.row_groups[self.states], q.row_groups[self.states + 1]
        self.choices = gather_ranges(lo, hi)
        if not wide:
            self.choices = self.choices.astype(index_dtype(q.matrix.shape[0]))
        counts = hi - lo  # per state, its choices
        del lo, hi
        self.state_choice = np.concatenate([[0], np.cumsum(counts)])
        self.leave = 1.0 - b.self_loop[self.choices]
        self.positive = bool(np.all(self.leave > 0))  # no choice to guard (no loop of 1)
        self.sense = q.sense
        # the quotient's CSR arrays (not the matrix object: a kept SingleLevels must
        # not keep it alive, :mod:`~mitld_lp.solvers.shared_levels`): the compiled
        # walks read its rows in place, each choice's self-loop skipped (no copy of the
        # rows: 12-15 bytes a transition at the solve's peak on issue 45's sensed
        # case); :meth:`entries` copies them
        self.rows = CSRRows(q.matrix.indptr, q.matrix.indices, q.matrix.data)
        if wide:
            self._local = self.cols = self.vals = self.ptr = self.choice_entry = None
            self.runs = self.run_at = self.first_choice = self.owner_at = None
            return
        self.state_choice = self.state_choice.astype(index_dtype(self.choices.size))
        # the self-loops left out (divided out), read in batches, ``local`` int32 where
        # the choices' count allows; no per-choice owner is kept (the flow's walk makes
        # a group's own, :func:`~mitld_lp.solvers.level_batches.flow`)
        self._local, self.cols, self.vals = off_diagonal_entries(
            q.matrix, self.choices, np.repeat(self.states, counts))
        # each choice's first entry: its kept entries counted (``local`` is sorted)
        self.choice_entry = np.zeros(self.choices.size + 1, dtype=np.int64)
        np.cumsum(np.bincount(self._local, minlength=self.choices.size),
                  out=self.choice_entry[1:])
        # the choices' entry pointers in the columns' index type: a level's sums (and
        # the flow's scatter) are then one call of SciPy's compiled CSR (CSC) product
        # on the walk's arrays as they are (:mod:`~mitld_lp.solvers.level_batches`)
        fits = (self.cols.dtype in (np.int32, np.int64) and self.vals.dtype == np.float64
                and self.cols.size < np.iinfo(self.cols.dtype).max)
        self.ptr = self.choice_entry.astype(self.cols.dtype) if fits else None
        if self.ptr is not None:  # one array of pointers, not two
            self.choice_entry = self.ptr
        # the NumPy walks' slices, once: per level with single states its states',
        # choices' and entries' bounds (``runs``, ``run_at[k]`` the first run of level
        # ``k`` or above); per state its first choice and per choice its state, both
        # counted from the start of their level (a level's segments without arithmetic)
        at = self.level_state
        marks = np.flatnonzero(np.diff(at))
        a, z = at[marks], at[marks + 1]
        ca, cz = self.state_choice[a], self.state_choice[z]
        self.runs = list(zip(a.tolist(), z.tolist(), ca.tolist(), cz.tolist(),
                             self.choice_entry[ca].tolist(), self.choice_entry[cz].tolist(),
                             strict=True))
        self.run_at = np.searchsorted(marks, np.arange(b.n_levels + 1)).tolist()
        # 4 bytes an index where the choices' count fits (a level's offsets are below it)
        small = np.int32 if self.choices.size < np.iinfo(np.int32).max else np.int64
        level_first = np.repeat(ca, z - a)  # per state, its level's first choice
        self.first_choice = (self.state_choice[:-1] - level_first).astype(small)
        # per choice its state counted from its level's first state
        self.owner_at = np.repeat((np.arange(self.states.size, dtype=small)
                                   - np.repeat(a, z - a).astype(small)), counts)

    @property
    def local(self) -> np.ndarray:
        """Per kept entry, its choice (a position in :attr:`choices`), in the entries'
        order (the NumPy walks' copy of the rows; :meth:`entries` for the compiled
        walks')."""
        if self._local is None:
            raise ValueError("SingleLevels.local: the compiled walks keep no copy of "
                             "the rows (use entries())")
        return self._local

    def entries(self) -> tuple[np.ndarray | None, np.ndarray, np.ndarray, np.ndarray]:
        """The choices' rows without their self-loops as ``(ptr, local, cols, vals)``
        (:func:`~mitld_lp.solvers.rows.off_diagonal_entries`; ``ptr`` each choice's
        first entry, None where the columns' type cannot hold the count): the NumPy
        walks' arrays, or for the compiled walks (which read the quotient's rows in
        place and keep none) a copy made on each call, for a caller that reads them
        whole (:func:`~mitld_lp.solvers.settled_levels.settled_by_bounds`)."""
        if self._local is not None:
            return self.ptr, self._local, self.cols, self.vals
        counts = np.diff(self.state_choice)
        local, cols, vals = off_diagonal_entries(self.rows, self.choices,
                                                 np.repeat(self.states, counts))
        ptr = None
        if (cols.dtype in (np.int32, np.int64) and vals.dtype == np.float64
                and cols.size < np.iinfo(cols.dtype).max):
            ptr = np.zeros(self.choices.size + 1, dtype=cols.dtype)
            np.cumsum(np.bincount(local, minlength=self.choices.size), out=ptr[1:])
        return ptr, local, cols, vals

    def solve(self, first: int, stop: int, rewards: np.ndarray,
              bounds: np.ndarray) -> None:
        """The single states of levels ``first`` to ``stop - 1``, in that order, each
        from the values below it: ``bounds[s] = max_c (r(c) + sum_{s' != s} P(c, s')
        bounds[s']) / (1 - p(c))`` clipped to [0, 1] (the min for a minimum), every
        column of ``rewards`` (per quotient choice) and ``bounds`` at once."""
        at = self.level_state
        lo_s, hi_s = int(at[first]), int(at[stop])
        if lo_s == hi_s:
            return
        if self.kernels is not None:
            m = self.rows
            self.kernels.single_bounds(lo_s, hi_s, self.state_choice, m.indptr,
                                       self.states, self.choices, m.indices, m.data,
                                       self.leave, np.asarray(rewards, dtype=np.float64),
                                       bounds, self.sense is Sense.MIN)
            return
        runs = self._runs(first, stop)
        if runs and self.positive:  # the same sums, fewer NumPy calls a level
            level_batches.bounds(self, runs, np.asarray(rewards, dtype=np.float64), bounds)
            return
        rewards = np.asarray(rewards, dtype=np.float64)
        for a, z, ca, cz, ea, ez in runs:
            rows = self.local[ea:ez] - ca
            terms = self.vals[ea:ez, None] * bounds[self.cols[ea:ez]]
            score = rewards[self.choices[ca:cz]]  # a copy (fancy indexing)
            for j in range(bounds.shape[1]):
                score[:, j] += np.bincount(rows, weights=terms[:, j], minlength=cz - ca)
            leave = self.leave[ca:cz, None]
            if self.positive:
                np.divide(score, leave, out=score)
            else:
                np.divide(score, leave, out=score, where=leave > 0)
                score[np.broadcast_to(leave <= 0, score.shape)] = 0.0
            np.clip(score, 0.0, 1.0, out=score)
            bounds[self.states[a:z]] = (score if cz - ca == z - a else  # one choice each
                                        self.sense.reduce(score, self.first_choice[a:z]))

    def _runs(self, first: int, stop: int) -> list[tuple[int, int, int, int, int, int]]:
        """The levels ``first`` to ``stop - 1`` that have single states, as the slices
        of their states, choices and entries."""
        return self.runs[self.run_at[first]:self.run_at[stop]]

    def values(self, first: int, stop: int, to_target: np.ndarray, skip: np.ndarray,
               values: np.ndarray, reduced_choice: np.ndarray, weights: np.ndarray) -> None:
        """:func:`solve_single_states` on the single states of levels ``first`` to
        ``stop - 1`` but the ``skip`` ones, in that order (the same sums in the same
        order, the same choice among ties): their ``values``, their ``reduced_choice``
        and that choice's weight 1."""
        at = self.level_state
        if at[first] == at[stop]:
            return
        if self.kernels is not None:
            m = self.rows
            self.kernels.single_values(int(at[first]), int(at[stop]), self.state_choice,
                                       m.indptr, self.states, self.choices,
                                       m.indices, m.data, self.leave, to_target, skip,
                                       values, reduced_choice, weights, TIE,
                                       self.sense is Sense.MIN)
            return
        level_batches.values(self, self._runs(first, stop), to_target, ~skip[self.states],
                             values, reduced_choice, weights)

    def flow(self, first: int, stop: int, self_loop: np.ndarray, weights: np.ndarray,
             x: np.ndarray) -> None:
        """The flow of the randomised policy ``weights`` through the single states of
        levels ``stop - 1`` down to ``first`` (upstream first): each state's inflow in
        ``x`` divided by what its choices do not keep, then added to its successors
        along its choices' entries in their order
        (:func:`mitld_lp.solvers.lp_blocks.policy_flow`)."""
        at = self.level_state
        if at[first] == at[stop]:
            return
        if self.kernels is not None:
            m = self.rows
            self.kernels.single_flow(first, stop, at, self.state_choice, m.indptr,
                                     self.states, self.choices, m.indices, m.data,
                                     self_loop, weights, x)
            return
        runs = self._runs(first, stop)
        if runs:  # each state's divisor and each entry's weight gathered once
            level_batches.flow(self, runs, self_loop, weights, x)


# ---------------------------------------------------------------------------------------
# Non-trivial blocks: their matrices and exact policy iteration on them.
# ---------------------------------------------------------------------------------------


DENSE_LU_STATES = 256
"""Chains of at most this many states are factorised dense (:class:`DenseLU`)."""


class DenseLU:
    """``I - Q`` of a small chain kept dense and solved by LAPACK's partial-pivoting LU
    (``numpy.linalg.solve``, a few milliseconds at 256 states): SuperLU would need
    ``scipy.sparse.linalg``, whose import (with ``scipy.linalg``) is 0.18 s of CPU, a
    third of a whole ``mitld-lp solve`` of the bundled case, whose chains are all
    smaller.  It answers ``solve`` as SciPy's ``SuperLU`` does."""

    __slots__ = ("a",)

    def __init__(self, a: sp.csc_array) -> None:
        self.a = a.toarray()

    def solve(self, rhs: np.ndarray, trans: str = "N") -> np.ndarray:
        return np.linalg.solve(self.a.T if trans == "T" else self.a, rhs)


def chain_lu(a: sp.csc_array, *, dense: bool = True) -> SuperLU | DenseLU:
    """LU of ``I - Q`` for a sub-stochastic ``Q`` (a chain's, or its transpose): dense
    up to :data:`DENSE_LU_STATES` states (unless ``dense=False``), else SuperLU's, the
    diagonal pivoted on (``I - Q`` is diagonally dominant) in a minimum-degree order of
    ``A + A'``, which on the product's blocks fills a third less than SuperLU's default
    column order and factorises in 0.7-0.8x its time."""
    if dense and a.shape[0] <= DENSE_LU_STATES:
        return DenseLU(a)
    import scipy.sparse.linalg as spla

    return spla.splu(a, permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True})


@dataclass(slots=True, eq=False)
class Factors:
    """The last factorisation of a sequence of transient solves on one block (mutable:
    :func:`transient_solve` reuses or replaces it): a chain equal to the factorised one
    (``base``) is solved on its LU, refined exactly as a new one would be.  The policy
    jump's three policy iterations end and start on the same policy, so two of their
    evaluations need no factorisation.  ``reused`` / ``factorised`` count both.

    What else was measured on the polish's chains of ``bus_scaled`` n128 d3 (21
    evaluations over blocks of 32,768 and 16,384 states) and dropped:

    * the LU of a chain that differs in a few rows, corrected by the
      Sherman--Morrison--Woodbury formula: a changed row costs a pair of triangular
      solves, about 1/60 of a new LU at 32,768 states, and the rows policy iteration
      changes add up to 450 and 1,600 on the two blocks (215, 107, 68, 29, 19, 8, 2 per
      round on the first).  Measured again as a hybrid (Woodbury only while at most 64
      rows differ from the factorised policy, the unit columns' solves kept for later
      rounds, the refined answer taken only at a new LU's residual, 2e-19): on n64 d3
      the evaluations took 0.74 s against 0.37 s, as SuperLU solves a block of unit
      columns at 0.4 ms a column (8,192 states, an LU 12 ms) and 3-4 ms a column
      (32,768 states, an LU 76-87 ms, a solve 2-3.6 ms): 64 columns cost 2-3 LUs;
    * the policy's own chain solved level by level (its 32,768 states split into 257
      components, the largest 9,600, over 97 levels): 115 ms against the one LU's
      118 ms, and slower on the smaller blocks (43 against 20 ms at 8,192 states);
    * SuperLU's other orderings and options on the 32,768-state chain: no pivoting
      threshold, no equilibration, larger supernodes: 85-86 ms against 87 ms;
      ``COLAMD`` / ``MMD_ATA``: 90-94 ms and 2.3-2.5x the fill (slower solves);
    * the last policy's LU as the preconditioner of the extended-precision refinement,
      started from the last policy's values: the refinement contracted by 0.3-0.5 a
      round on one block and diverged on the other (its error grew 1e-10 -> 3e-9);
    * the first factorisation's symmetric order kept for the later ones (SuperLU told
      ``NATURAL`` on the permuted matrix): the same fill, and 1.22-1.25 s against
      1.17-1.18 s for the 21 refined evaluations;
    * a look-ahead of 10-40 Bellman sweeps (float64) before each improvement: not one
      round fewer, as the later rounds' gains (1e-17 to 1e-12) are below float64's
      resolution of the values.
    """

    lu: SuperLU | DenseLU | None = None
    base: sp.csr_array | None = None
    reused: int = 0
    factorised: int = 0


def _same(a: sp.csr_array, b: sp.csr_array) -> bool:
    return (a.shape == b.shape and a.nnz == b.nnz and np.array_equal(a.indptr, b.indptr)
            and np.array_equal(a.indices, b.indices) and np.array_equal(a.data, b.data))


def transient_solve(chain: sp.csr_array | sp.csc_array, rhs: np.ndarray, *,
                    refine: int = 0, factors: Factors | None = None) -> np.ndarray:
    """The one transient solve: ``x = rhs + Q x`` for a transient sub-stochastic ``Q``
    (``chain``, square; a chain's rows, or a flow's transposed ones) by one sparse LU
    of ``I - Q`` (:func:`chain_lu`).  ``rhs`` may have a column per right-hand side;
    ``refine`` rounds of iterative refinement in extended precision return the answer
    as ``longdouble`` (without, ``float64``).  ``factors``: the factorisation of the
    previous chain, used if this chain is the same (:class:`Factors`), else replaced."""
    k = chain.shape[0]
    rhs = np.asarray(rhs, dtype=np.float64)
    chain = sp.csr_array(chain)
    if factors is not None and factors.lu is not None and factors.base is not None \
            and _same(chain, factors.base):
        lu = factors.lu
        factors.reused += 1
    else:
        lu = chain_lu(sp.csc_array(sp.eye_array(k, format="csc") - chain))
        if factors is not None:
            factors.lu, factors.base = lu, chain
            factors.factorised += 1
    x = lu.solve(rhs)
    if not refine:
        return np.asarray(x, dtype=np.float64)
    q_ld = chain.astype(np.longdouble)
    x = x.astype(np.longdouble)
    b_ld = rhs.astype(np.longdouble)
    for _ in range(refine):
        residual = b_ld + q_ld @ x - x
        x += lu.solve(np.asarray(residual, dtype=np.float64))
    return x


def evaluate_chain(inner: sp.csr_array, chosen: np.ndarray, reward: np.ndarray,
                   factors: Factors | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Value ``v = r + M v`` and exit time ``t = 1 + M t`` of the chain of ``chosen``
    rows, in extended precision (one LU, refined twice: :func:`transient_solve`)."""
    k = chosen.shape[0]
    both = transient_solve(sp.csr_array(inner[chosen]),
                           np.column_stack([reward[chosen], np.ones(k)]), refine=2,
                           factors=factors)
    return both[:, 0], both[:, 1]


def improve_policy(block: Block, reward: np.ndarray, chosen: np.ndarray,
                   allowed: np.ndarray | None = None, *,
                   factors: Factors | None = None,
                   sense: Sense = Sense.MAX) -> tuple[np.ndarray, ...]:
    """Policy iteration on the block with exit rewards ``reward`` from ``chosen`` (local
    choice indices) to a fixpoint, maximising (or minimising, ``sense``), over the
    ``allowed`` choices only if given.  Returns the policy, its values and its expected
    exit times (extended precision).

    Scores are compared in extended precision, so that at the fixpoint no choice beats
    the policy by more than :data:`GAIN` of the values compared, *relative* to them (a
    state of value 1e-30 is improved as one of value 0.5 is; the verified bounds of
    interval iteration rely on that); a switch needs a gain above that, so rounding
    cannot make it cycle.  ``factors``: shared by the caller across calls on the same
    block, so that a call starting where the last one ended reuses its factorisation."""
    inner = block.inner.astype(np.longdouble)
    factors = Factors() if factors is None else factors
    for _ in range(POLICY_ROUNDS):
        v, t, nxt = policy_round(block, inner, reward, chosen, allowed, factors, sense)
        if np.array_equal(nxt, chosen):
            return chosen, v, t
        chosen = nxt
    return chosen, v, t


def policy_round(block: Block, inner: np.ndarray, reward: np.ndarray, chosen: np.ndarray,
                 allowed: np.ndarray | None, factors: Factors,
                 sense: Sense) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One round of :func:`improve_policy` (``inner``: the block's rows in extended
    precision): the policy's values and exit times, and the next policy (a state's best
    choice where it beats ``chosen`` by more than :data:`GAIN`, else its own)."""
    worst = -np.inf if sense is Sense.MAX else np.inf
    v, t = evaluate_chain(block.inner, chosen, reward, factors)
    score = reward + inner @ v
    if allowed is not None:
        score = np.where(allowed, score, worst)
    better = segmented_argmax(score, block.groups, sense=sense)
    gain = sense.gain(score[better], score[chosen])
    scale = np.maximum(np.abs(score[better]), np.abs(score[chosen]))
    return v, t, np.where(gain > GAIN * scale, better, chosen)


GAIN = 1e-17
"""The least gain, relative to the scores compared, for which policy iteration switches
a choice (extended precision resolves about 1e-19 of a value)."""


def solve_chain(chain: sp.csr_array, b: np.ndarray,
                layers: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    r"""Solve ``x = b + Q x`` for a transient sub-stochastic ``Q`` (``chain``), level by
    level downstream first: a single state by :math:`x(s) = (b(s) + \sum_{s' \ne s}
    Q(s, s') x(s')) / (1 - Q(s, s))`, a non-trivial component by one sparse LU of its
    own size (:func:`transient_solve`).  No iterative method and no multi-threaded
    BLAS call, so a loaded machine cannot make it crawl, and no fill-in across
    components.  ``layers``: the component
    of each state and the level of each component in a graph that contains the chain's
    (the analysis of its MDP, :func:`blocks_from`); else the chain is decomposed here.
    A level's states in non-trivial components are solved together by one LU."""
    chain = sp.csr_array(chain)
    blk = (graph_blocks(sp.csr_array(chain != 0, dtype=np.float64), chain.diagonal())
           if layers is None else blocks_from(layers[0], layers[1], chain.diagonal()))
    x = np.zeros(b.shape[0])
    b = np.asarray(b, dtype=np.float64)
    for level in blk.walk():
        one, inner = level.single, level.rest
        # the level's own states are still 0 in x: the right-hand sides see only below
        x[one] = (b[one] + rows_dot(chain, one, x)) / (1.0 - blk.self_loop[one])
        if inner.size:
            rows = sp.csr_array(chain[inner])
            x[inner] = transient_solve(sp.csr_array(rows[:, inner]), b[inner] + rows @ x)
    return x
