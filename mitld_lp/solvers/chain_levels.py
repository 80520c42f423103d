r"""A transient chain ``x = rhs + Q x`` solved level by level over its *own* strongly
connected components, the factorisations kept for further right-hand sides.

The quotient's components are the union of every policy's: one deterministic (or
randomised) policy's chain inside a block of the quotient is far more acyclic than the
block.  On QVBS ``zeroconf`` 1000-4-false the 213,268-state block's greedy chain splits
into 208,702 components (the largest 4,567 states) over 95 levels: one sparse LU of the
whole chain took 0.7 s, the level walk over its own components about 0.1 s.  The
policy's flow (:func:`mitld_lp.solvers.lp_blocks.policy_flow`, the transposed chain:
its components are the same, its levels reversed) and the certificates' chain
(:mod:`mitld_lp.solvers.certify_chain`: its values, then its slack ``W`` on the same
factorisations) are both solved so.  One walk serves a chain and its transpose
(:meth:`ChainLevels.solve_transposed`: the levels upstream first, a cyclic level by
the transposed solve of the same LU): the flow of a block's greedy policy reuses the
walk :mod:`mitld_lp.solvers.greedy_block` found for the policy's values, instead of
finding the same components again (on QVBS ``zeroconf`` 20-8-false, 1,241,065 block
states, that search is most of the flow's chain solve).

Downstream first: a single state by
:math:`x(s) = (b(s) + \sum_{s' \ne s} Q(s, s') x(s')) / (1 - Q(s, s))` (its own entry
reads ``x(s)`` still 0, so the sum sees only below), the cyclic components of one level
together by one sparse LU of their size
(:func:`~mitld_lp.solvers.topological.chain_lu`).  No iterative method: the answer is
that of a direct solve, up to rounding, whatever the conditioning of the levels.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers.graph import Blocks, graph_blocks
from mitld_lp.solvers.rows import row_columns, row_entries, rows_dot
from mitld_lp.solvers.topological import DenseLU, chain_lu, level_kernels

if TYPE_CHECKING:
    from scipy.sparse.linalg import SuperLU

__all__ = ["WALK_MIN_STATES", "ChainLevels", "Extended", "chain_solve", "forget", "keep_within",
           "offer", "walk_of"]


WALK_MIN_STATES = 32_768
"""The fewest states of a chain walked over its components; a smaller one is one LU.
Measured on policies' chains: QVBS ``consensus`` 4-4's 8,302-state block, one LU 17 ms
against the walk's 26 ms (6,719 components over 30 levels); ``bus_scaled`` n64 d3's
32,768-state block 118 against 115 ms, its 8,192-state one 20 against 43 ms;
``zeroconf`` 1000-4-false's 213,268 states 0.7 s against 0.1 s."""


class ChainLevels:
    """The level walk of one transient chain (module docs): its components found once
    (:func:`~mitld_lp.solvers.graph.graph_blocks` on its pattern), each level's cyclic
    components factorised at the first :meth:`solve` and kept for the next.  A chain of
fewer than :data:`WALK_MIN_STATES` states is one LU
(:func:`~mitld_lp.solvers.topological.chain_lu`: dense when small)."""

    __slots__ = ("chain", "self_loop", "blocks", "_cyclic", "_kernels", "_singles",
                 "_upstream", "states")

    def same_chain(self, other: sp.csr_array) -> bool:
        """Whether ``other`` (CSR) has this walk's chain entry for entry (its rows'
        pointers, columns and values), so that this walk's components and
        factorisations are its own."""
        c = self.chain
        return (other.shape == c.shape and other.nnz == c.nnz
                and np.array_equal(other.indptr, c.indptr)
                and np.array_equal(other.indices, c.indices)
                and np.array_equal(other.data, c.data))

    def __init__(self, chain: sp.csr_array | sp.csc_array) -> None:
        self.chain = _walked(sp.csr_array(chain))
        self.self_loop = self.chain.diagonal()
        # a smaller chain is one LU, faster than finding its components
        self.blocks: Blocks | None = (
            None if self.chain.shape[0] < WALK_MIN_STATES else
            graph_blocks(_support(self.chain), self.self_loop))
        # per level with cyclic states: (their rows, the LU of I - their block)
        self._cyclic: dict[int, tuple[sp.csr_array, SuperLU | DenseLU]] = {}
        # the single states' runs of levels by one compiled call each, where the
        # quotient's level walks are compiled (numba loaded, or many levels)
        self._kernels = (None if self.blocks is None else
                         level_kernels(self.chain.nnz, self.blocks.n_levels))
        self._singles: tuple[np.ndarray, np.ndarray, list[int]] | None = None
        self._upstream: np.ndarray | None = None  # made at the first transposed solve
        # the states the chain's rows are, in a numbering the certificate shares (the
        # product's, increasing), where :func:`offer` was told them
        self.states: np.ndarray | None = None

    def _factor(self, level: int, states: np.ndarray) -> tuple[sp.csr_array,
                                                              SuperLU | DenseLU]:
        got = self._cyclic.get(level)
        if got is None and self.blocks is not None:
            got = self._cyclic[level] = self._level_factor(states)
        if got is None:  # the whole chain, one LU (no walk: ``states`` are all)
            rows = sp.csr_array(self.chain[states])
            inner = sp.csc_array(rows[:, states])
            del rows
            a = sp.csc_array(sp.eye_array(states.size, format="csc") - inner)
            del inner
            # SuperLU even for a small component when walking: the dense LU's solve is
            # LAPACK's, whose threads crawled on a loaded machine (16 solves of about
            # 100 states: 0.8 s against 0.02 s for SciPy's whole-chain solve).  The
            # rows kept beside the LU are the chain itself (every row, the same
            # entries), not a copy of it held with the walk until the certificate's
            # chain takes it (:func:`offer`); the copies made for ``I - Q`` are freed
            # before SuperLU allocates
            got = self.chain, chain_lu(a, dense=self.blocks is None)
            self._cyclic[level] = got
        return got

    def _level_factor(self, states: np.ndarray) -> tuple[sp.csr_array, SuperLU]:
        """:meth:`_factor` of a walked chain's level (its chain canonical: no two
        entries of a row in one column), from the chain's arrays: its rows by the
        compiled row gather (the entries of ``chain[states]`` in their order, so
        ``rows @ x`` sums as before) and ``I - Q`` on the level's ``states`` made in
        canonical form directly, the matrix SciPy's ``eye - inner`` gave (that drops an
        entry whose difference is 0; SuperLU canonicalises its input), not through
        SciPy's indexing and sparse arithmetic: 120 levels with cyclic components on
        ``bus_scaled`` n128 d3's 32,768-state policy chain, each level a few SciPy
        constructions and checks."""
        c = self.chain
        n, k = c.shape[0], states.size
        cols, vals = row_columns(c, states)
        counts = c.indptr[states + 1] - c.indptr[states]
        ptr = np.zeros(k + 1, dtype=c.indptr.dtype)
        np.cumsum(counts, out=ptr[1:])
        rows = sp.csr_array((vals, cols, ptr), shape=(k, n))
        # each entry's column as a local index (-1: off the level), by a search of the
        # level's states, not an array of the chain's size
        order = np.argsort(states, kind="stable")
        ranked = states[order]
        at = np.minimum(np.searchsorted(ranked, cols), k - 1)
        inside = ranked[at] == cols
        r = np.repeat(np.arange(k), counts)[inside]
        to, q = order[at[inside]], vals[inside]
        diag = r == to
        one = np.ones(k)
        one[r[diag]] = 1.0 - q[diag]  # eye - inner on the diagonal, as SciPy subtracts
        off = ~diag
        r_all = np.concatenate([np.arange(k), r[off]])
        c_all = np.concatenate([np.arange(k), to[off]])
        v_all = np.concatenate([one, -q[off]])
        keep = v_all != 0.0
        a = sp.csc_array((v_all[keep], (r_all[keep], c_all[keep])), shape=(k, k))
        a.sum_duplicates()
        return rows, chain_lu(a, dense=False)  # type: ignore[return-value]

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """``x = rhs + Q x`` in float64 (``rhs``: a vector, or a column per right-hand
        side)."""
        rhs = np.asarray(rhs, dtype=np.float64)
        if self.blocks is None:
            everything = np.arange(self.chain.shape[0])
            return np.asarray(self._factor(0, everything)[1].solve(rhs), dtype=np.float64)
        if self._kernels is not None:
            return self._compiled(rhs, transposed=False)
        x = np.zeros(rhs.shape)
        loop = self.self_loop if rhs.ndim == 1 else self.self_loop[:, None]
        for level in self.blocks.walk():
            one, cyclic = level.single, level.rest
            x[one] = (rhs[one] + rows_dot(self.chain, one, x)) / (1.0 - loop[one])
            if cyclic.size:
                rows, lu = self._factor(level.index, cyclic)
                # the level's own cyclic states are still 0 in x: rows @ x sees below
                x[cyclic] = np.asarray(lu.solve(rhs[cyclic] + rows @ x), dtype=np.float64)
        return x

    def solve_transposed(self, rhs: np.ndarray) -> np.ndarray:
        """``x = rhs + Q^T x`` in float64 (a flow through the chain: ``rhs`` a vector,
        or a column per right-hand side), over the same components and factorisations
        as :meth:`solve`: the levels upstream first, a single state divided by its
        self-loop's complement, a cyclic level by the transposed solve of its LU, then
        each solved state's flow pushed along its row to the levels below."""
        x = np.array(rhs, dtype=np.float64)  # the inflow, added level by level
        if self.blocks is None:
            everything = np.arange(self.chain.shape[0])
            lu = self._factor(0, everything)[1]
            return np.asarray(lu.solve(x, trans="T"), dtype=np.float64)
        if self._kernels is not None:
            return self._compiled(x, transposed=True)
        blk = self.blocks
        loop = self.self_loop if x.ndim == 1 else self.self_loop[:, None]
        for level in blk.walk(upstream_first=True):
            one, cyclic = level.single, level.rest
            x[one] /= 1.0 - loop[one]
            if cyclic.size:
                lu = self._factor(level.index, cyclic)[1]
                x[cyclic] = np.asarray(lu.solve(x[cyclic], trans="T"), dtype=np.float64)
            row, col, val = row_entries(self.chain, level.states)
            out = blk.level[blk.component[col]] != level.index  # below: no edge across
            flow = x[level.states[row[out]]]
            np.add.at(x, col[out], flow * (val[out] if x.ndim == 1 else val[out, None]))
        return x

    def _runs(self) -> tuple[np.ndarray, np.ndarray, list[int]]:
        """The single states downstream first (in level order), where each level's
        start among them, and the levels with cyclic components; gathered once.  Their
        upstream order is :meth:`_upstream_singles`', made only for a transposed solve
        (the certificates' chains are solved forward alone: QVBS ``zeroconf``
        1000-4's 166,000 single states sorted for nothing)."""
        if self._singles is None:
            blk = self.blocks
            assert blk is not None
            order = blk.by_level
            one = blk.single(order)
            states = np.ascontiguousarray(order[one])
            level_of = np.repeat(np.arange(blk.n_levels), np.diff(blk.level_starts))[one]
            at = np.searchsorted(level_of, np.arange(blk.n_levels + 1))
            self._singles = (states, at, np.unique(blk.level[blk.size > 1]).tolist())
        return self._singles

    def _upstream_singles(self) -> np.ndarray:
        """The single states of :meth:`_runs` upstream first: the levels last to first,
        each level's states in their order there (as a stable sort of them by
        decreasing level gives them); made at the first call and kept."""
        if self._upstream is None:
            states, at, _ = self._runs()
            total = int(at[-1])
            sizes = np.diff(at)
            # level ``l``'s states start at ``total - at[l + 1]`` upstream first
            shift = np.repeat(total - at[1:] - at[:-1], sizes)
            dest = np.arange(total, dtype=np.int64) + shift
            upstream = np.empty_like(states)
            upstream[dest] = states
            self._upstream = upstream
        return self._upstream

    def _compiled(self, rhs: np.ndarray, *, transposed: bool) -> np.ndarray:
        """:meth:`solve` (``rhs``) or :meth:`solve_transposed` (``rhs``: a copy, the
        flow added into it) with each run of single-state levels between two cyclic
        ones in one call of :mod:`mitld_lp.solvers.level_kernels`: a policy's chain is
        mostly single states (QVBS ``zeroconf`` 20-4-false's greedy chain: 212,793 of
        213,268 states, over 380 levels of which one has a cyclic component), where the
        NumPy walk costs a few calls per level."""
        blk, kern, c = self.blocks, self._kernels, self.chain
        assert blk is not None
        states, at, cyclic_levels = self._runs()
        b = np.ascontiguousarray(rhs.reshape(rhs.shape[0], -1))
        total = int(at[-1])
        if transposed:
            upstream = self._upstream_singles()
            x = b
            stop = blk.n_levels
            for lv in reversed(cyclic_levels):
                # levels lv to stop - 1, upstream first: their flows are complete
                kern.chain_flow(upstream[total - at[stop]:total - at[lv]], c.indptr,
                                c.indices, c.data, self.self_loop, x)
                cyclic = blk.states_at(lv)
                cyclic = cyclic[~blk.single(cyclic)]
                lu = self._factor(lv, cyclic)[1]
                x[cyclic] = np.asarray(lu.solve(x[cyclic], trans="T"),
                                       dtype=np.float64).reshape(cyclic.size, -1)
                row, col, val = row_entries(c, cyclic)
                out = blk.level[blk.component[col]] != lv
                np.add.at(x, col[out], val[out, None] * x[cyclic[row[out]]])
                stop = lv
            kern.chain_flow(upstream[total - at[stop]:], c.indptr, c.indices, c.data,
                            self.self_loop, x)
        else:
            x = np.zeros(b.shape)
            done = 0
            for lv in cyclic_levels:
                kern.chain_solve(states[at[done]:at[lv + 1]], c.indptr, c.indices, c.data,
                                 self.self_loop, b, x)
                cyclic = blk.states_at(lv)
                cyclic = cyclic[~blk.single(cyclic)]
                rows, lu = self._factor(lv, cyclic)
                x[cyclic] = np.asarray(lu.solve(b[cyclic] + rows @ x),
                                       dtype=np.float64).reshape(cyclic.size, -1)
                done = lv + 1
            kern.chain_solve(states[at[done]:], c.indptr, c.indices, c.data,
                             self.self_loop, b, x)
        return x if rhs.ndim == 2 else x[:, 0]


OFFER_MAX = 4
"""The most walks :func:`offer` keeps at a time (the oldest dropped first)."""

OFFER_MIN_LEVELS = 16
"""The fewest factorised levels of a walk over its components that :func:`offer`
keeps when it is not told the walk's states (a chain of one LU, below
:data:`WALK_MIN_STATES` states, is always kept)."""

_OFFERED: list[ChainLevels] = []


def offer(walk: ChainLevels, states: np.ndarray | None = None) -> None:
    """Keep ``walk`` (its components and factorisations) for a later chain equal to its
    own, or extending it (:func:`walk_of`).  The LP stage offers the walk of each block
    its greedy policy settles (:func:`mitld_lp.solvers.lp_blocks.solve_decomposed`):
    the certificate's chain on that block is the same policy's chain, entry for entry,
    on ``bus_scaled`` n128 d3 both blocks' (32,768 states over 120 levels with cyclic
    components, and 16,384 states), and on QVBS ``zeroconf`` 1000-6-false min (550,097
    states, one cyclic level), which it used to factorise a second time; on
    ``zeroconf`` 1000-4-false max the certificate's chain is the greedy one with 420
    single states upstream of it (:class:`Extended`).

    ``states``: the product states of the walk's rows (increasing), given where the
    block settles whole (the LP's policy there is the walk's; told once the LP stage's
    flow is made, whose upstream order is dropped then): the certificate then
    drops the walk as soon as its own solved states show it cannot be asked for
    (:func:`keep_within`), before its chain's walk is made, so the walk is kept
    whatever its levels.  Without them the walk's chain is matched entry for entry
    alone, and a walk over its components that factorised fewer than
    :data:`OFFER_MIN_LEVELS` levels is not kept: holding it through the certificate
    costs more than it saves (QVBS ``zeroconf`` 1000-4-false's greedy chain held
    unmatched was 27 bytes a transition more at the certificate's traced peak).  At
    most :data:`OFFER_MAX` are kept; :func:`forget` drops them (the certificate, at
    its end)."""
    if states is not None:  # 4 bytes a state where they fit
        states = np.asarray(states)
        small = states.size == 0 or int(states[-1]) < np.iinfo(np.int32).max
        walk.states = states.astype(np.int32 if small else np.int64, copy=False)
        walk._upstream = None  # the flow's order: the certificate solves forward only
    elif walk.blocks is not None and len(walk._cyclic) < OFFER_MIN_LEVELS:
        return
    _OFFERED.append(walk)
    del _OFFERED[:-OFFER_MAX]


def forget() -> None:
    """Drop every walk :func:`offer` kept (their factorisations freed)."""
    _OFFERED.clear()


def keep_within(states: np.ndarray) -> None:
    """Drop the offered walks told their states (:func:`offer`) that are not all among
    ``states`` (increasing): the certificate's solved states, every chain it walks
    among them, so no such walk can serve it (freed before its own walk is made)."""
    _OFFERED[:] = [w for w in _OFFERED if w.states is None or _within(w.states, states)]


def _within(inner: np.ndarray, outer: np.ndarray) -> bool:
    """Whether every one of ``inner`` is in ``outer`` (both increasing)."""
    if inner.size > outer.size:
        return False
    if inner.size == 0:
        return True
    at = np.minimum(np.searchsorted(outer, inner), outer.size - 1)
    return bool(np.array_equal(outer[at], inner))


class Extended:
    """The walk of a chain ``c`` that extends an offered walk's chain (:func:`offer`) by
    single states upstream of it: ``c``'s rows at ``inside`` (increasing) are the walk's
    rows entry for entry, their columns mapped to ``inside`` (so nothing of the walk
    leads out of it), and the other states, ``order`` (downstream first), form no cycle
    but their self-loops.  A new walk of ``c`` finds the walk's components at the same
    levels (a level counts down from the sinks, and nothing below changed), the same
    cyclic states in each in the same order (the same LUs), and each single state's
    value from its row and the final values below it: the same sums in the same order.
    So :meth:`solve` gives a new walk's bits: the offered walk's solve on ``inside``,
    then the other states by the same single-state formula, in one compiled call (or a
    level of them at a time by NumPy, the same bits)."""

    __slots__ = ("walk", "chain", "inside", "order", "starts", "self_loop")

    def __init__(self, walk: ChainLevels, chain: sp.csr_array, inside: np.ndarray,
                 order: np.ndarray, starts: np.ndarray) -> None:
        self.walk, self.chain, self.inside = walk, chain, inside
        self.order, self.starts = order, starts
        self.self_loop = chain.diagonal()

    @staticmethod
    def of(walk: ChainLevels, c: sp.csr_array, states: np.ndarray) -> Extended | None:
        """``c`` (canonical, its rows the product states ``states``, increasing) as an
        extension of ``walk`` (told its states), or None where it is not one (the
        class docs)."""
        mine = walk.states
        g = walk.chain
        n = c.shape[0]
        if (mine is None or walk.blocks is None or mine.size >= n
                or not _within(mine, states)):
            return None
        inside = np.searchsorted(states, mine)
        if not np.array_equal(np.diff(c.indptr)[inside], np.diff(g.indptr)):
            return None
        cols, vals = row_columns(c, inside)
        if not (np.array_equal(vals, g.data) and np.array_equal(cols, inside[g.indices])):
            return None
        del cols, vals
        above = np.ones(n, dtype=bool)
        above[inside] = False
        upper = np.flatnonzero(above)
        del above
        among = sp.csr_array(sp.csr_array(c[upper])[:, upper])
        blk = graph_blocks(_support(among), among.diagonal())
        if bool(np.any(blk.size > 1)):  # a cycle among them: a new walk's own LUs
            return None
        return Extended(walk, c, inside, upper[blk.by_level], blk.level_starts)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """``x = rhs + Q x`` in float64 (``rhs``: a vector, or a column per right-hand
        side), with a new walk's bits (the class docs)."""
        rhs = np.asarray(rhs, dtype=np.float64)
        x = np.zeros(rhs.shape)
        x[self.inside] = self.walk.solve(rhs[self.inside])
        c, kern = self.chain, self.walk._kernels
        if kern is not None:
            n = rhs.shape[0]
            out = x.reshape(n, -1)  # a view: x is contiguous
            kern.chain_solve(self.order, c.indptr, c.indices, c.data, self.self_loop,
                             np.ascontiguousarray(rhs.reshape(n, -1)), out)
            return x
        loop = self.self_loop if rhs.ndim == 1 else self.self_loop[:, None]
        for a, z in zip(self.starts[:-1].tolist(), self.starts[1:].tolist(), strict=True):
            one = self.order[a:z]
            x[one] = (rhs[one] + rows_dot(c, one, x)) / (1.0 - loop[one])
        return x


def _support(c: sp.csr_array) -> sp.csr_array:
    """The graph whose components and levels :class:`ChainLevels` walks: ``c`` itself
    where it is canonical and stores no zero (the search reads its pattern alone), else
    its nonzero pattern as a float matrix (``c != 0``), as it always was.  Not a boolean
    copy of the pattern and a float copy of that beside the chain: QVBS ``zeroconf``
    1000-4's greedy chain of the LP stage, where the solve's traced memory peaked."""
    if c.has_canonical_format and np.count_nonzero(c.data) == c.nnz:
        return c
    return sp.csr_array(c != 0, dtype=np.float64)


def _walked(c: sp.csr_array) -> sp.csr_array:
    """``c`` as :class:`ChainLevels` keeps it: a chain it walks over its components in
    canonical form (each row's columns sorted, no duplicates; in place, as SciPy's
    ``c != 0`` for the component search always did), a smaller one as it comes."""
    if c.shape[0] >= WALK_MIN_STATES:
        c.sum_duplicates()
    return c


def walk_of(chain: sp.csr_array | sp.csc_array,
            states: np.ndarray | None = None) -> ChainLevels | Extended:
    """The walk of ``chain``: an offered one whose chain is ``chain`` entry for entry as
    :class:`ChainLevels` would keep it (:meth:`ChainLevels.same_chain`; taken out of
    the offers), its components and factorisations those of ``chain`` itself, so every
    solve on it has the bits of a new walk's; else, where ``states`` (the product states
    of ``chain``'s rows, increasing) are given, an offered walk that ``chain`` extends
    by single states upstream (:class:`Extended`: a new walk's bits too); else a new
    :class:`ChainLevels`."""
    c = _walked(sp.csr_array(chain))
    for k, walk in enumerate(_OFFERED):
        if walk.same_chain(c):
            return _OFFERED.pop(k)
    if states is not None and c.shape[0] >= WALK_MIN_STATES:
        for k, walk in enumerate(_OFFERED):
            got = Extended.of(walk, c, np.asarray(states))
            if got is not None:
                del _OFFERED[k]
                return got
    return ChainLevels(c)


def chain_solve(chain: sp.csr_array | sp.csc_array, rhs: np.ndarray) -> np.ndarray:
    """``x = rhs + Q x`` for the transient sub-stochastic ``Q`` of ``chain`` (or its
    transpose), level by level over its own components (:class:`ChainLevels`)."""
    return ChainLevels(chain).solve(rhs)
