"""A deterministic policy's chain solved for the certificates (:mod:`mitld_lp.solvers.
certify`): its values, the slack ``W`` of the candidates, and the three sets its graph
decides (reached almost surely, unreachable, transient)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from mitld_lp.mdp import MDP, MDPShape
from mitld_lp.solvers.certify_blocks import compiled_chain_blocks
from mitld_lp.solvers.certify_compiled import (
    compiled_chain_parts,
    compiled_chain_sets,
    compiled_cycling,
)
from mitld_lp.solvers.chain_levels import keep_within, walk_of
from mitld_lp.solvers.graph import Blocks, Reversed, attractor, blocks_from, graph_view, levels
from mitld_lp.solvers.result import Lifted, read_only
from mitld_lp.solvers.rounding import Rounding
from mitld_lp.solvers.rows import gather_ranges, row_columns, row_entries
from mitld_lp.solvers.topological import level_kernels
from mitld_lp.solvers.walks import load_walks
from mitld_lp.util import kernel_loader
from mitld_lp.util.sparsetools import sparsetools

__all__ = ["CHAIN_KERNEL_MIN_LEVELS", "Chain", "RowModel", "full_values", "support_layers", "chain",
           "attracted", "cycling_among", "escapes", "CYCLING_BATCH"]

CHAIN_KERNEL_MIN_LEVELS = 200
"""The fewest levels of a chain whose single states are solved by the compiled walk
whatever its size, once a compiled kernel's load is paid in the process (the kernel's
own first read, about 2 ms, against some 10 microseconds a level of NumPy calls); the
same values to the last bit (:mod:`mitld_lp.solvers.level_kernels`)."""


@dataclass(frozen=True, slots=True, eq=False)
class Chain:
    """A policy's chain solved for the certificates: ``v`` (its values on the ``solved``
    states, in their order, within [0, 1]; :attr:`values` every state's, 1 on ``sure``
    and 0 elsewhere), ``w`` (the slack ``W`` on the ``solved`` states, in their
    order), each a float a solved state, not one a state held through both sides of
    the certificate (QVBS csma 4-2 solves 678 of 600,267 states), and the three sets of
    its graph: ``sure`` (the target reached almost surely, the target included),
    ``never`` (the target unreachable) and ``solved`` (the rest: transient).  Given a
    ``v`` or a ``w`` of every state (0 outside ``solved`` for ``w``), it keeps the
    ``solved`` states' entries."""

    v: np.ndarray
    w: np.ndarray
    solved: np.ndarray
    sure: np.ndarray
    never: np.ndarray
    policy: np.ndarray
    target: np.ndarray

    def __post_init__(self) -> None:
        solved = np.asarray(self.solved, dtype=bool)
        count = int(np.count_nonzero(solved))
        for name in ("v", "w"):  # one a state: kept compact
            got = np.asarray(getattr(self, name))
            if got.shape[0] != count:
                object.__setattr__(self, name, read_only(got[solved]))

    @property
    def values(self) -> np.ndarray:
        """The policy's float values on every state: ``v`` on the ``solved`` states, 1
        on ``sure``, 0 elsewhere (made on each call)."""
        return full_values(self.v, self.solved, self.sure)

    @property
    def slack(self) -> np.ndarray:
        """``W`` on every state, 0 outside ``solved`` (made on each call)."""
        out = np.zeros(self.solved.shape[0])
        out[np.asarray(self.solved, dtype=bool)] = self.w
        return out


def full_values(v: np.ndarray, solved: np.ndarray, sure: np.ndarray) -> np.ndarray:
    """A chain's values on every state (:attr:`Chain.values`) from its solved states'
    ``v`` and its ``solved`` and ``sure`` sets."""
    out = np.where(np.asarray(sure, dtype=bool), 1.0, 0.0)
    out[np.asarray(solved, dtype=bool)] = v
    return out


@dataclass(frozen=True, slots=True, eq=False)
class RowModel(MDPShape):
    """A model the certificates read that is not an :class:`~mitld_lp.mdp.MDP`: the
    ``matrix``'s rows grouped into states' choices by ``row_groups``, an ``initial``
    state (for a robust game: nature's rows under a fixed robot policy, or the vertex
    rows with the robot's choices as ``row_groups``); its sizes and choice-to-state are
    :class:`~mitld_lp.mdp.MDPShape`'s."""

    matrix: sp.csr_array
    row_groups: np.ndarray
    initial: int


def support_layers(mdp: MDP | RowModel) -> tuple[np.ndarray, np.ndarray]:
    """The components of ``mdp``'s support graph and their levels (the analysis's
    ``Quotient.layers``, for a caller without one)."""
    found = levels(graph_view(sp.csr_array(mdp.matrix), mdp.row_groups))
    return found.component, found.level


def chain(mdp: MDP, target: np.ndarray, policy: np.ndarray, rnd: Rounding,
          layers: tuple[np.ndarray, np.ndarray] | None = None,
          guess: np.ndarray | None = None) -> Chain:
    """The values of ``policy`` (a choice row per state, ``-1`` on the target and the
    absorbing states) and the slack ``W`` of its certificates (module docs), solved
    level by level, a non-trivial component of the layers by the walk over the chain's
    own components there (:class:`~mitld_lp.solvers.chain_levels.ChainLevels`), its
    factorisations serving both.  ``layers``:
    the components and levels of ``mdp``'s support graph (:func:`support_layers`; a
    level -1 where unknown: the chain's own levels are found then);
    ``guess``: an estimate of the values (every state), to solve ``W`` beside them."""
    m = sp.csr_array(mdp.matrix)
    n = mdp.n_states
    target = np.asarray(target, dtype=bool)
    policy = np.asarray(policy, dtype=np.int64)
    acting = (policy >= 0) & ~target
    states = np.flatnonzero(acting)
    index = np.int32 if n < np.iinfo(np.int32).max else np.int64  # 4 bytes if it can
    # the sets and the solved states' chain by one compiled call where paid (the same
    # arrays as the NumPy gather below: QVBS zeroconf 1000-4's 164,171 solved states,
    # some ten NumPy passes over their rows)
    got = compiled_chain_parts(m, states, policy[states], target)
    if got is not None:
        never, sure, idx, b, vals, cols, ptr = got
        del got, states
        solved = acting & ~never & ~sure
        sub = sp.csr_array((vals, cols, ptr), shape=(idx.size,) * 2) if idx.size else None
        del vals, cols, ptr
    else:
        never, sure = _sets(m, n, states, policy[states], target, index)
        del states
        solved = acting & ~never & ~sure
        idx = np.flatnonzero(solved).astype(index, copy=False)  # 4 bytes a state if it can
        b, sub = _gathered(m, policy, idx, solved, sure, index) if idx.size else (None, None)
    del acting
    # the LP's offered walks that no chain among the solved states can take, freed
    # before this chain's own walk is made (:func:`~mitld_lp.solvers.chain_levels.offer`)
    keep_within(idx)
    v = w = None
    if sub is not None:
        kappa = 1.0 - rnd.low_of[rnd.count[policy[idx]]]
        v, w = _solve(sub, b, kappa, _solved_layers(layers, idx),
                      None if guess is None else _Gathered(guess, idx), idx)
        del sub, b, kappa
    # the solved states' values alone (:attr:`Chain.values` makes every state's)
    values = np.zeros(idx.size)
    slack = np.zeros(idx.size)
    if v is not None:
        np.clip(v, 0.0, 1.0, out=values)
        np.maximum(w, 0.0, out=slack)
    return Chain(read_only(values), read_only(slack), read_only(solved), read_only(sure),
                 read_only(never), read_only(policy), read_only(target.copy()))


def _gathered(m: sp.csr_array, policy: np.ndarray, idx: np.ndarray, solved: np.ndarray,
              sure: np.ndarray, index: type) -> tuple[np.ndarray, sp.csr_array]:
    """The ``idx`` (solved) states' mass into ``sure`` (``b``) and their chain among
    themselves (``sub``, CSR in ``index``), from their policy rows' positive entries in
    the rows' order (:func:`chain`'s NumPy path)."""
    n = solved.shape[0]
    # the chain in the edges' index type, as the greedy block's chains are: the
    # level kernels load one variant, not one per type (each a compilation on a
    # fresh cache and a load per process), and 4 bytes an entry when it can
    at = np.full(n, -1, dtype=index)
    at[idx] = np.arange(idx.size, dtype=index)
    # the solved states' rows gathered again, their positive entries in the rows'
    # order: the entries the edges above held for them (each its local row)
    rows = policy[idx]
    s_loc = np.repeat(np.arange(idx.size, dtype=index),
                      m.indptr[rows + 1] - m.indptr[rows])
    d, p = row_columns(m, rows)
    d = d.astype(index, copy=False)
    del rows
    pos = p > 0
    if not pos.all():
        s_loc, d, p = s_loc[pos], d[pos], p[pos]
    del pos
    into = solved[d]
    b = np.bincount(s_loc[sure[d]], weights=p[sure[d]], minlength=idx.size)
    # the entries come row by row in the states' order: the CSR arrays directly
    rows_of = s_loc[into]
    del s_loc
    indptr = np.concatenate([[0], np.cumsum(np.bincount(rows_of, minlength=idx.size))])
    del rows_of
    if indptr[-1] <= np.iinfo(index).max:
        indptr = indptr.astype(index)
    # the entries' copies and the map freed before the chain's own components are
    # searched (QVBS zeroconf 1000-4: the certificate's traced peak, in the walk)
    return b, sp.csr_array((p[into], at[d[into]], indptr), shape=(idx.size,) * 2)


def _sets(m: sp.csr_array, n: int, states: np.ndarray, rows: np.ndarray,
          target: np.ndarray, index: type) -> tuple[np.ndarray, np.ndarray]:
    """The chain's ``never`` and ``sure`` sets (:class:`Chain`) from its edges, the
    positive entries of row ``rows[i]`` out of state ``states[i]``: by one compiled
    call where the kernels' load is paid
    (:func:`~mitld_lp.solvers.certify_compiled.compiled_chain_sets`), else the edges
    reversed once (:class:`~mitld_lp.solvers.graph.Reversed`) and searched twice; the
    same sets."""
    got = compiled_chain_sets(m, states, rows, target)
    if got is not None:
        return got
    counts = m.indptr[rows + 1] - m.indptr[rows]
    dst, pos = _columns(m, rows, counts, index)
    del rows
    if pos is None:  # the chain's edges as a CSR over the states: no source an edge
        # in the reversal's index type where it fits: it reads them without a copy
        small = n + dst.size < np.iinfo(np.int32).max
        starts = np.zeros(n + 1, dtype=np.int32 if small else np.int64)
        starts[states + 1] = counts
        np.cumsum(starts, out=starts, dtype=starts.dtype)
        del states, counts
        edges = Reversed(n, None, dst, starts=starts)
        del starts
    else:  # its positive entries (in the rows' order), each with its source
        src = np.repeat(states.astype(index), counts)
        del states, counts
        src, dst = src[pos], dst[pos]
        del pos
        edges = Reversed(n, src, dst)
        del src
    del dst  # reversed: its own copy (QVBS csma 4-2: the certificate's peak here)
    never = ~edges.reaching(target)
    sure = ~edges.reaching(never)
    return never, sure


COLUMNS_BATCH = 1 << 14
"""Rows whose entries :func:`_columns` gathers at a time (its memory bound)."""


def _columns(m: sp.csr_array, rows: np.ndarray, counts: np.ndarray, index: type,
             ) -> tuple[np.ndarray, np.ndarray | None]:
    """The columns of ``m``'s ``rows`` (``counts``: their stored entries), row after row
    in their stored order, as ``index`` (:func:`~mitld_lp.solvers.rows.row_columns`'
    entries), and which are positive (None: all are).  Gathered
    :data:`COLUMNS_BATCH` rows at a time into the one output: the rows' pointers, the
    columns and the float values of every row at once were the certificate's traced
    peak on QVBS csma 4-2; the same entries in the same order."""
    dst = np.empty(int(counts.sum()), dtype=index)
    pos = None
    at = 0
    for a in range(0, rows.size, COLUMNS_BATCH):
        cols, vals = row_columns(m, rows[a:a + COLUMNS_BATCH])
        z = at + cols.size
        dst[at:z] = cols  # (each column below the states' count: it fits ``index``)
        positive = vals > 0
        if pos is None and not positive.all():
            pos = np.ones(dst.size, dtype=bool)
        if pos is not None:
            pos[at:z] = positive
        at = z
        del cols, vals, positive
    return dst, pos


def _solved_layers(layers: tuple[np.ndarray, np.ndarray] | None, idx: np.ndarray,
                   ) -> tuple[np.ndarray, np.ndarray] | None:
    """The components and levels of the ``idx`` states from ``layers``; None (the
    chain's own, :func:`_solve`) where one of them has no level (-1: the analysis's
    quotient left its component out, ``Quotient.layers``)."""
    if layers is None:
        return None
    comp, level = np.asarray(layers[0])[idx], np.asarray(layers[1])
    return None if bool(np.any(level[comp] < 0)) else (comp, level)


def _solve(sub: sp.csr_array, b: np.ndarray, kappa: np.ndarray,
           layers: tuple[np.ndarray, np.ndarray] | None,
           guess: np.ndarray | _Gathered | None = None,
           states: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``v = b + Q v`` and ``W = delta v + Q W`` on a transient chain ``Q`` (``sub``),
    level by level downstream first; ``delta`` per state is twice its relative residual
    plus its rounding bound ``kappa`` (module docs).  ``guess``: an estimate of ``v``
    (the iteration's lower bound) positive on a block: its ``W`` is solved with ``v``
    as a second right-hand side, ``2 kappa guess``, scaled after by what the residuals
    ask (one factorisation, one solve).  Where one component of ``layers`` holds every
    state (:func:`one_component`), that component is the only level with a block and
    no state is single: its block is solved directly, the layers' blocks and the
    single states' set-up not made (QVBS zeroconf 1000-4's 164,171 solved states, some
    7 ms); the same operations on the same operands, so the same bits.  ``states``:
    the product states of ``sub``'s rows (increasing), for the LP's offered walks
    (:func:`~mitld_lp.solvers.chain_levels.walk_of`)."""
    from mitld_lp.solvers.graph import graph_blocks

    k = b.shape[0]
    v, w = np.zeros(k), np.zeros(k)
    if layers is not None and one_component(layers[0]):
        _block(sub, b, kappa, np.arange(k), guess, v, w, states)
        return v, w
    diag = sub.diagonal()
    # the layers' blocks by one compiled call where paid: the same arrays as NumPy's
    # (QVBS csma 3-4 all_before_max's 718,348 solved states: two id tables, a gather
    # and a radix sort, some 30 ms)
    blk = (graph_blocks(sp.csr_array(sub != 0, dtype=np.float64), diag) if layers is None
           else compiled_chain_blocks(layers[0], layers[1], diag)
           or blocks_from(layers[0], layers[1], diag))
    singles = _Singles(sub, blk)
    done = 0
    for index in np.unique(blk.level[blk.size > 1]).tolist():  # the levels with blocks
        singles.solve(done, index + 1, b, kappa, diag, v, w)
        done = index + 1
        inner = blk.states_at(index)
        _block(sub, b, kappa, inner[~blk.single(inner)], guess, v, w, states)
    singles.solve(done, blk.n_levels, b, kappa, diag, v, w)
    return v, w


def one_component(comp: np.ndarray) -> bool:
    """Whether ``comp`` (the solved states' components) names one component, of at
    least two states: then it is a block, and the only one."""
    return comp.shape[0] >= 2 and int(comp.min()) == int(comp.max())


def _block(sub: sp.csr_array, b: np.ndarray, kappa: np.ndarray, inner: np.ndarray,
           guess: np.ndarray | _Gathered | None, v: np.ndarray, w: np.ndarray,
           states: np.ndarray | None = None) -> None:
    """``v`` and ``w`` (:func:`_solve`) of the ``inner`` states (increasing): the
    non-single states of one level, every state below it solved (``states``: the
    product states of ``sub``'s rows, or None)."""
    k = b.shape[0]
    if (inner.size == k and sub.has_canonical_format
            and bool(np.all(inner[1:] > inner[:-1]))):
        # every state of the chain in one level's components (``inner`` ascending:
        # ``arange(k)``): its rows and its block are the chain itself, entry for
        # entry, in its order; not two copies beside it (QVBS zeroconf 1000-4's
        # 166,000-state chain, at the certificate's traced peak).  Canonical: the
        # walk keeps it as it is (:func:`~mitld_lp.solvers.chain_levels.walk_of`).
        # Every state: its vectors read whole (views), not gathered by an index of
        # every state
        rows = block = sub
        inner = slice(None)
        mine = states
    else:
        mine = None if states is None else states[inner]
        rows = sp.csr_array(sub[inner])
        block = sp.csr_array(rows[:, inner])
    known = b[inner] + rows @ v
    g = None if guess is None else guess[inner]
    if g is not None and not bool(np.all(g > 0)):
        g = None  # not read: W solved on its own (not held through the walk)
    joint = None
    # the chain's own components: one walk, both solves.  The greedy block's walk
    # (solve stage) where it is this chain entry for entry (:func:`~mitld_lp.
    # solvers.chain_levels.walk_of`: bus_scaled n128 d3, both blocks; QVBS zeroconf
    # 1000-6-false min) or this chain less single states upstream of it (zeroconf
    # 1000-4-false max: 420 of 164,171), not on QVBS zeroconf 20-4-false, where the
    # chain here is the policy's transient states only (168,388 of the block's
    # 213,268 states)
    walk = walk_of(block, mine)
    if g is not None:
        pair = walk.solve(np.column_stack([known, 2.0 * kappa[inner] * g + rows @ w]))
        v[inner], joint = pair[:, 0], pair[:, 1]
        del pair
    else:
        v[inner] = walk.solve(known)
    del known  # each temporary a float of the chain's states, freed before the next
    residual = np.abs(v[inner] - (b[inner] + rows @ v))
    with np.errstate(divide="ignore", invalid="ignore"):
        need = np.where(v[inner] > 0, 2.0 * (residual + kappa[inner] * v[inner]), 0.0)
        del residual
        if joint is not None:
            ratio = need / (2.0 * kappa[inner] * g)  # type: ignore[operator]
            w[inner] = joint * max(1.0, float(np.max(ratio, initial=1.0)))
        else:
            need += rows @ w  # need + rows @ w in place: the same sums
            w[inner] = walk.solve(need)
    del need


class _Gathered:
    """The ``idx`` entries of ``full`` (a vector of every state), read as ``full[idx]``
    would be, a selection at a time: :func:`_solve`'s ``guess`` without its copy on
    every solved state held through the walk (QVBS zeroconf 1000-4's certificate
    peak, where it is not read at all: the guess is not positive on its block)."""

    __slots__ = ("full", "idx")

    def __init__(self, full: np.ndarray, idx: np.ndarray) -> None:
        self.full = full if isinstance(full, Lifted) else np.asarray(full, dtype=np.float64)
        self.idx = idx  # (a Lifted vector read where gathered: lift-84)

    def __getitem__(self, at: np.ndarray | slice) -> np.ndarray:
        return self.full[self.idx[at]]


class _Singles:
    """The single states of a chain's levels (``blk``), in level order, with their rows'
    entries gathered once, solved a run of levels at a time (a deadline makes a
    thousand levels): a state's own entry reads its ``v`` and ``w`` still 0, so the
    sums see only below; its formula's residual is a rounding, within ``kappa``.
    Compiled (:mod:`mitld_lp.solvers.level_kernels`) where the quotient's walks are
    (:func:`~mitld_lp.solvers.topological.level_kernels`), the same arithmetic."""

    def __init__(self, sub: sp.csr_array, blk: Blocks) -> None:
        order = blk.by_level
        if blk.n_components == order.shape[0]:
            # every component one state (QVBS csma 3-4 all_before_max's 718,348): every
            # state single, each level's first position the blocks' own; the same
            # arrays (copies: writable, as the kernels' signatures read them) without
            # two gathers, a mask and a search of every state (some 8 ms)
            self.order = order.copy()
            self.at = np.array(blk.level_starts, dtype=np.int64)
        else:
            single = blk.single(order)
            self.order = order[single]
            level_of = np.repeat(np.arange(blk.n_levels), np.diff(blk.level_starts))[single]
            self.at = np.searchsorted(level_of, np.arange(blk.n_levels + 1))
        self.sub = sub
        # compiled as the quotient's walks are, or wherever a compiled kernel's load is
        # paid and the levels are many (QVBS zeroconf_dl 1000-1-30: 920 levels, some
        # 5 ms of NumPy calls against one call)
        self.kernels = level_kernels(sub.nnz, blk.n_levels, True if (
            blk.n_levels >= CHAIN_KERNEL_MIN_LEVELS and kernel_loader.compiled_paid())
            else None)
        if self.kernels is None:  # (the kernel reads the chain itself: nothing gathered)
            self._gather()

    def _gather(self) -> None:
        """The single states' rows' entries, each state's first entry and, where SciPy's
        product takes them, the entries' pointers: what the NumPy levels read."""
        self.local, self.cols, self.vals = row_entries(self.sub, self.order)
        # each state's first entry: its row's length counted (``local`` is sorted), not
        # a binary search of every state in ``local``: the same pointers
        self.entry_at = np.zeros(self.order.size + 1, dtype=np.int64)
        np.cumsum(np.bincount(self.local, minlength=self.order.size),
                  out=self.entry_at[1:])
        fits = (sparsetools is not None and self.cols.dtype in (np.int32, np.int64)
                and self.vals.dtype == np.float64
                and self.cols.size < np.iinfo(self.cols.dtype).max)
        # entry pointers of the columns' type: SciPy's product sums a level's rows
        self.ptr = self.entry_at.astype(self.cols.dtype) if fits else None

    def solve(self, first: int, stop: int, b: np.ndarray, kappa: np.ndarray,
              diag: np.ndarray, v: np.ndarray, w: np.ndarray) -> None:
        """``v`` and ``w`` of the single states of levels ``first`` to ``stop - 1``."""
        at = self.at
        if at[first] == at[stop]:
            return
        if self.kernels is not None:
            s = self.sub
            self.kernels.chain_values(self.order[at[first]:at[stop]], s.indptr,
                                      s.indices, s.data, diag, b, kappa, v, w)
            return
        marks = np.flatnonzero(np.diff(at[first:stop + 1])) + first  # levels with states
        n = v.shape[0]
        # what no level's sums change, gathered once for the run (the same operands, so
        # the same bits): each state's b, its 2 kappa and what its self-loop leaves
        lo_s, hi_s = int(at[first]), int(at[stop])
        states = self.order[lo_s:hi_s]
        b_of, twice_kappa = b[states], 2.0 * kappa[states]
        leave = 1.0 - diag[states]
        del states
        for lv in marks.tolist():
            a, z = int(at[lv]), int(at[lv + 1])
            if self.ptr is not None:  # one compiled call a sum: from 0, in the entries' order
                down_v, down_w = np.zeros(z - a), np.zeros(z - a)
                sparsetools.csr_matvec(z - a, n, self.ptr[a:z + 1], self.cols, self.vals, v, down_v)
                sparsetools.csr_matvec(z - a, n, self.ptr[a:z + 1], self.cols, self.vals, w, down_w)
            else:
                ea, ez = int(self.entry_at[a]), int(self.entry_at[z])
                local, cols, vals = self.local[ea:ez] - a, self.cols[ea:ez], self.vals[ea:ez]
                down_v = np.bincount(local, weights=vals * v[cols], minlength=z - a)
                down_w = np.bincount(local, weights=vals * w[cols], minlength=z - a)
            one, r = self.order[a:z], slice(a - lo_s, z - lo_s)
            value = (b_of[r] + down_v) / leave[r]
            v[one] = value
            w[one] = (twice_kappa[r] * value + down_w) / leave[r]


def attracted(m: sp.csr_array, groups: np.ndarray, inside: np.ndarray) -> bool:
    """Whether every ``inside`` state (each with a choice) is in the attractor of the
    other states: ``attractor(m, groups, ~inside)[inside].all()``, walked on the
    ``inside`` states' rows only.  Every other state is a seed, so a choice of an
    ``inside`` state with an entry out of them is hit from the start, and the rest of
    the least fixed point lies among them: the attractor of no seed on their rows with
    their columns (those hits given), the same set on them.  QVBS ``consensus`` 4-4
    ``c2``: 19,157 of 43,133 states, whose first round of the whole walk read the
    predecessors of every other state.  Where the compiled kernels' load is paid, the
    compiled attractor of the other states on the whole matrix
    (:func:`~mitld_lp.solvers.compiled_graph.backward`, the walk
    :func:`~mitld_lp.solvers.graph.attractor` runs on a large graph: the same set), one
    pass with nothing gathered."""
    if kernel_loader.compiled_paid():
        walks = load_walks()
        if walks is not None:
            got = walks.backward(m.indptr, m.indices, groups, ~inside,
                                 np.zeros(m.shape[0], dtype=bool), True)
            return bool(np.all(got[inside]))
    states = np.flatnonzero(inside)
    lo, hi = groups[states], groups[states + 1]
    choices = gather_ranges(lo, hi)
    starts, stops = m.indptr[choices], m.indptr[choices + 1]
    entries = gather_ranges(starts, stops)
    at = np.full(inside.size, -1, dtype=np.int64)  # a column's place among them
    at[states] = np.arange(states.size)
    cols = at[m.indices[entries]]
    del entries
    kept = cols >= 0
    counts = stops - starts
    row_of = np.repeat(np.arange(choices.size), counts)
    hit = np.zeros(choices.size, dtype=bool)
    hit[row_of[~kept]] = True  # an entry out of them: a seed is a successor
    ptr = np.zeros(choices.size + 1, dtype=np.int64)
    np.cumsum(np.bincount(row_of[kept], minlength=choices.size), out=ptr[1:])
    # the product's index types (a compiled walk loads one variant, not one a type)
    sub = sp.csr_array((np.ones(int(ptr[-1])), cols[kept].astype(m.indices.dtype),
                        ptr.astype(m.indptr.dtype)), shape=(choices.size, states.size))
    sub_groups = np.zeros(states.size + 1, dtype=np.int64)
    np.cumsum(hi - lo, out=sub_groups[1:])
    return bool(np.all(attractor(sub, sub_groups, np.zeros(states.size, dtype=bool),
                                 hit)))


def cycling_among(m: sp.csr_array, groups: np.ndarray, comp: np.ndarray,
                  left: np.ndarray) -> np.ndarray:
    """``left & may_cycle(mdp, comp)`` (:func:`~mitld_lp.solvers.analysis.may_cycle`:
    the states an end component may hold) for the model of matrix ``m`` and
    ``groups``, read on the ``left`` states' choices alone: a ``left`` state of a
    non-trivial component, or one with a choice that has entries all in its own column
    (its first entry there, then every entry read).  Not the choices' states and the
    first entries of every choice of the model (QVBS csma 4-2: 658,129 choices, of
    which a minimum's certificate asks about 232,810 states').  By one compiled call
    where the kernels' load is paid
    (:func:`~mitld_lp.solvers.certify_compiled.compiled_cycling`): the same set."""
    got = compiled_cycling(m, groups, comp, left)
    if got is not None:
        return got
    size = np.bincount(comp, minlength=int(comp.max(initial=-1)) + 1)
    out = left & (size > 1)[comp]
    rest = np.flatnonzero(left & ~out)
    if rest.size == 0 or m.nnz == 0:
        return out
    # :data:`CYCLING_BATCH` states at a time: their choices, owners and pointers (an
    # int64 each a choice, four of them) were the certificate's traced peak on QVBS
    # csma 4-2 (232,810 states' choices); each state's verdict reads its own alone
    for a in range(0, rest.size, CYCLING_BATCH):
        _pure_loops(m, groups, rest[a:a + CYCLING_BATCH], out)
    return out


CYCLING_BATCH = 1 << 15
"""States whose choices :func:`cycling_among` reads at a time (its memory bound)."""


def _pure_loops(m: sp.csr_array, groups: np.ndarray, rest: np.ndarray,
                out: np.ndarray) -> None:
    """Set ``out`` on the ``rest`` states with a choice whose stored entries are all in
    their own column (:func:`cycling_among`)."""
    lo, hi = groups[rest], groups[rest + 1]
    choices = gather_ranges(lo, hi)
    own = np.repeat(rest, hi - lo)
    start, stop = m.indptr[choices], m.indptr[choices + 1]
    del choices
    cand = np.flatnonzero((stop > start) & (m.indices[np.minimum(start, m.nnz - 1)] == own))
    start, stop, own = start[cand], stop[cand], own[cand]
    apart = m.indices[gather_ranges(start, stop)] != np.repeat(own, stop - start)
    pure = np.ones(cand.size, dtype=bool)
    pure[np.repeat(np.arange(cand.size), stop - start)[apart]] = False
    out[own[pure]] = True


def escapes(m: sp.csr_array, groups: np.ndarray, comp: np.ndarray, left: np.ndarray) -> bool:
    """:func:`~mitld_lp.solvers.certify._escapes` on the model of matrix ``m`` and
    ``groups`` (int64): False where ``m`` stores a zero, else whether every ``left``
    state that may hold an end component (:func:`cycling_among`) and has a choice is
    :func:`attracted` by the others (a state with no choice is a seed)."""
    if m.nnz and not bool(np.all(m.data > 0)):
        return False
    inside = cycling_among(m, groups, comp, left) & (np.diff(groups) > 0)
    return True if not inside.any() else attracted(m, groups, inside)
