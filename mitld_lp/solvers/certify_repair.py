"""The repair of a Bellman candidate (:mod:`mitld_lp.solvers.certify`): a failing
state's bound moved to what its choices need, levels downstream first, an end
component's states together, and the states reading a moved one taken up after it.
The bounds it moves are checked again by the caller: the repair only proposes.  The
rows the Bellman checks read (:class:`Rows`) are defined here, beside the repair that
walks them, and :mod:`~mitld_lp.solvers.certify` imports them (one way, no circle)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mitld_lp.solvers.certify_chain import RowModel, support_layers
from mitld_lp.solvers.certify_compiled import compiled_needs, compiled_rounds
from mitld_lp.solvers.certify_repair_index import (  # noqa: F401 - Rows re-exported
    Rows,
    readers_by_column,
    stable_order,
    state_groups,
)
from mitld_lp.solvers.rounding import Rounding, above, below
from mitld_lp.solvers.rows import gather_ranges, row_entries
from mitld_lp.util.sparsetools import sparsetools

__all__ = ["CLOSED_SLICE", "KEEP_READS", "PASSES", "ROUNDS", "SPARSE_LEVEL", "Rows",
           "closed_at_zero", "readers_by_column", "repair_levels"]


PASSES = True
"""Whether a repair whose levels read only lower ones is made pass by pass over the
states that can move (:meth:`Repair._passes`) rather than level by level: the same
bounds (QVBS ``zeroconf_dl`` 1000-1-30: 14 passes for its 775 levels, the repair
0.060 -> 0.030 s); False walks every level (kept for the tests that compare the two)."""

KEEP_READS = True
"""Whether a repair with large levels keeps the readers of the states it moved as flags,
level after level (:meth:`Repair.run`), rather than searching the readers of every
state moved so far again at each large level: the same states to do, so the same
bounds (False: the search, kept for the tests that compare the two)."""

ROUNDS = 64
"""Repair rounds on one level of non-trivial components before giving up."""

SPARSE_LEVEL = 4096
"""States of a level from which the repair reads only the rows of the states it takes
up and finds their readers by column (a large component's rounds move few of its
states: QVBS zeroconf 1000-4's 213,268-state level, 3,497 failing), not the slices of
every state of the level (:class:`_Walk`)."""

CLOSED_SLICE = 4096
"""The states of ``zero`` whose rows :func:`closed_at_zero` reads at a time (their
entries' index, column and membership arrays are its temporaries)."""


def repair_levels(st: Rows, level_of: np.ndarray, x: np.ndarray, free: np.ndarray,
                   zero: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """The levels the repair walks, and the states it holds fixed (``free`` and more).
    A state without a level (-1: outside the analysis's quotient, ``Quotient.layers``)
    is held where its bound cannot need a move: at its extreme (1 for an upper bound,
    ``zero`` None; 0 for a lower one), where the repair never moves a bound past, or,
    for an upper bound, in ``zero`` (a maximum's prob-0 set) when every stored entry
    of its rows stays in it and it is all 0 (:func:`closed_at_zero`).  Holding a state
    is sound whatever it is: the caller checks again every state that failed and every
    reader of a moved one.  If some other state has no level, the levels of the whole
    support graph are found (:func:`support_layers`)."""
    unknown = level_of < 0
    if not unknown.any():
        return level_of, free
    still = (x == 1.0) if zero is not None else (x == 0.0)
    if zero is not None and closed_at_zero(st, zero, x):
        still |= zero
    held = free | (unknown & still)
    if not bool(np.any(unknown & ~held)):
        return level_of, held
    comp, level = support_layers(RowModel(st.matrix, state_groups(st), 0))
    return np.asarray(level)[np.asarray(comp)], free


def closed_at_zero(st: Rows, zero: np.ndarray, x: np.ndarray) -> bool:
    """Whether every ``zero`` state passes the upper check at 0 for ever: all 0 in ``x``,
    every stored entry of their rows (nature's included) in ``zero``.  The graph reads
    no stored zero, the check does: a 0 entry out of it (the sensed chain models') makes
    the rule ask the rounded sum's bound, above 0 (``test_levels_quotient_stored_zero``)."""
    states = np.flatnonzero(zero)
    if bool(np.any(x[states] != 0.0)):
        return False
    # a state's rows (nature's too) are consecutive, so its entries are one range of
    # the matrix's arrays: read there, not gathered row by row (the same entries)
    # a slice of states at a time (:data:`CLOSED_SLICE`): the whole set's entries
    # gathered at once, an int64 index an entry twice over, were the certificate's
    # traced peak on ``bus_scaled`` n64 d3 (7 bytes a transition); the same test
    first = state_groups(st)
    m = st.matrix
    ptr = m.indptr[first]
    del first
    for lo in range(0, states.size, CLOSED_SLICE):
        part = states[lo:lo + CLOSED_SLICE]
        if not bool(np.all(zero[m.indices[gather_ranges(ptr[part], ptr[part + 1])]])):
            return False
    return True


def _needed(st: Rows, rnd: Rounding, x: np.ndarray, states: np.ndarray,
            upper: bool) -> np.ndarray:
    """Per state of ``states``: the least (``upper``) / largest value its choices allow,
    ``max_c min_rows min(above, max support)`` / ``min_c max(below, min support)``."""
    got = compiled_needs(st, rnd, x, states, upper)
    if got is not None:
        return got
    rows, choice_starts, state_starts = st.rows_of(states)
    local, cols, vals = row_entries(st.matrix, rows)
    return _need_of(rnd, x, local, cols, vals, rows, choice_starts, state_starts, upper)


def _need_of(rnd: Rounding, x: np.ndarray, local: np.ndarray, cols: np.ndarray,
             vals: np.ndarray, rows: np.ndarray, choice_starts: np.ndarray | None,
             state_starts: np.ndarray, upper: bool,
             compiled: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
             ) -> np.ndarray:
    """:func:`_needed` from the rows' entries (``local``: each one's position in
    ``rows``), read once for both: their sums (rows_dot) and the extreme of ``x`` over
    their supports (support_extreme), each as those compute it.  ``compiled``: the
    rows' entry pointers (no row empty) with the whole walk's columns and values, for
    SciPy's compiled CSR product (the same sums: each row's from 0 in its entries'
    order) and a segmented extreme (the same extreme) in place of ``bincount`` and
    ``ufunc.at``, a few calls fewer on a level."""
    reached = x[cols]
    if compiled is not None:
        ptr, all_cols, all_vals = compiled
        sums = np.zeros(rows.size)
        sparsetools.csr_matvec(rows.size, x.shape[0], ptr, all_cols, all_vals, x, sums)
        ext = (np.maximum if upper else np.minimum).reduceat(reached, ptr[:-1] - ptr[0])
    else:
        sums = np.bincount(local, weights=vals * reached, minlength=rows.size)
        ext = np.full(rows.size, -np.inf if upper else np.inf)
        (np.maximum if upper else np.minimum).at(ext, local, reached)
    each = np.minimum(above(rnd, rows, sums), ext) if upper else \
        np.maximum(below(rnd, rows, sums), ext)
    if choice_starts is not None:
        each = np.minimum.reduceat(each, choice_starts)
    return (np.maximum if upper else np.minimum).reduceat(each, state_starts)


class _Walk:
    """The live states of the levels a repair walks (from the lowest failing one up),
    in level order, with their rows and the rows' entries gathered once: a level's
    states, rows and entries are contiguous slices here, so a round on a level costs a
    few NumPy calls on its slices, not a gather of its rows and of their readers (a
    deadline clock makes a thousand levels: QVBS ``zeroconf_dl`` 1000-1-30)."""

    __slots__ = ("states", "level_at", "rows", "choice_starts", "state_starts", "local",
                 "cols", "vals", "entry_state", "row_at", "entry_at", "choice_at",
                 "row_entry", "filled", "inward", "_factors", "every", "downward")

    def __init__(self, st: Rows, states: np.ndarray, levels: np.ndarray) -> None:
        self.states = states
        bounds = np.flatnonzero(np.diff(levels)) + 1
        self.level_at = np.concatenate([[0], bounds, [states.size]]).astype(np.int64)
        rows, choice_starts, state_starts = st.rows_of(states)
        self.rows, self.choice_starts, self.state_starts = rows, choice_starts, state_starts
        self.local, self.cols, self.vals = row_entries(st.matrix, rows)
        if choice_starts is None:  # a choice a row: the states' first choices are rows
            self.choice_at = None
            self.row_at = np.append(state_starts, rows.size)
        else:  # per state its first choice, and that choice's first row
            self.choice_at = np.append(state_starts, choice_starts.size)
            self.row_at = np.append(choice_starts, rows.size)[self.choice_at]
        row_state = np.repeat(np.arange(states.size), np.diff(self.row_at))
        self.entry_state = row_state[self.local]
        # per row its first entry: the rows' lengths counted (``local`` is sorted), not
        # a binary search of every row in ``local``: the same pointers; per state, its
        # first row's.  In the columns' index type below, for SciPy's compiled product
        # (:func:`_need_of`); ``None`` where a row is empty or the types differ
        row_entry = np.zeros(rows.size + 1, dtype=np.int64)
        np.cumsum(np.bincount(self.local, minlength=rows.size), out=row_entry[1:])
        self.entry_at = row_entry[self.row_at]
        fits = (sparsetools is not None and self.cols.dtype in (np.int32, np.int64)
                and self.vals.dtype == np.float64 and bool(np.all(np.diff(row_entry) > 0))
                and self.cols.size < np.iinfo(self.cols.dtype).max)
        self.row_entry = row_entry.astype(self.cols.dtype) if fits else None
        self.filled = bool(np.all(np.diff(self.entry_at) > 0))  # every state an entry
        # per state: whether a row of its level holds a state of that level (a cycle,
        # or a self-loop).  A level without one has nothing to take up again after a
        # round: the states it moved are read only from the levels above (QVBS
        # ``zeroconf_dl`` 1000-1-30: none of its 920 walked levels has one)
        level = np.repeat(np.arange(self.level_at.size - 1), np.diff(self.level_at))
        where = np.full(st.n_states, -1, dtype=np.int64)
        where[states] = level
        above_it = where[self.cols] - level[self.entry_state]  # >= 0: not below
        same = above_it == 0
        # whether every entry reads a state below its own level or none the walk moves:
        # each state's need then depends on lower levels alone (:meth:`Repair._passes`)
        self.downward = not bool(np.any(above_it >= 0))
        del above_it
        self.inward = (np.bincount(level[self.entry_state[same]],
                                   minlength=self.level_at.size - 1) > 0)[level]
        self._factors: tuple[Rounding, bool, np.ndarray, np.ndarray] | None = None
        # whether every state has a choice and (with nature) every choice a row: then a
        # slice with as many rows (choices) as states has one each
        self.every = bool(np.all(np.diff(self.row_at) > 0)) and (
            choice_starts is None or bool(np.all(np.diff(self.choice_at) > 0)))

    def factors(self, rnd: Rounding, upper: bool) -> tuple[np.ndarray, np.ndarray]:
        """Per row of the walk, the rounding's slack and factor of :func:`above`
        (``upper``) or :func:`below`, gathered once for every level (a level then reads
        slices of them: the same operands, so the same bits)."""
        f = self._factors
        if f is None or f[0] is not rnd or f[1] != upper:
            count = rnd.count[self.rows]
            f = self._factors = (rnd, upper, rnd.slack_of[count],
                                 (rnd.high_of if upper else rnd.low_of)[count])
        return f[2], f[3]

    def needed(self, rnd: Rounding, x: np.ndarray, a: int, z: int,
               upper: bool) -> np.ndarray:
        """:func:`_needed` of the states ``a:z`` of the walk, read from its slices: the
        same operations on the same operands (:func:`_need_of`), with the rounding's
        factors sliced from :meth:`factors`, and no reduction over states that have one
        row each (each state's need is its row's)."""
        ra, rz = int(self.row_at[a]), int(self.row_at[z])
        if rz == ra:  # no row to read: nothing to move
            return np.full(z - a, -np.inf if upper else np.inf)
        if not (self.row_entry is not None and x.dtype == np.float64
                and x.flags.c_contiguous and x.ndim == 1):
            return self._needed_of(rnd, x, a, z, ra, rz, upper)
        ea, ez = int(self.entry_at[a]), int(self.entry_at[z])
        ptr = self.row_entry[ra:rz + 1]
        sums = np.zeros(rz - ra)
        sparsetools.csr_matvec(rz - ra, x.shape[0], ptr, self.cols, self.vals, x, sums)
        pick = np.maximum if upper else np.minimum
        ext = pick.reduceat(x[self.cols[ea:ez]], ptr[:-1] - ptr[0])
        slack, factor = self.factors(rnd, upper)
        if upper:  # above(): (sums + slack) * high
            sums += slack[ra:rz]
            sums *= factor[ra:rz]
            each = np.minimum(sums, ext, out=ext)
        else:  # below(): max((sums - slack) * low, 0)
            sums -= slack[ra:rz]
            sums *= factor[ra:rz]
            each = np.maximum(np.maximum(sums, 0.0, out=sums), ext, out=ext)
        if self.choice_at is not None:
            ca, cz = int(self.choice_at[a]), int(self.choice_at[z])
            each = np.minimum.reduceat(each, self.choice_starts[ca:cz] - ra)
            if self.every and cz - ca == z - a:  # one choice a state
                return each
            return pick.reduceat(each, self.state_starts[a:z] - ca)
        if self.every and rz - ra == z - a:  # one row a state
            return each
        return pick.reduceat(each, self.state_starts[a:z] - ra)

    def _needed_of(self, rnd: Rounding, x: np.ndarray, a: int, z: int, ra: int,
                   rz: int, upper: bool) -> np.ndarray:
        """:meth:`needed` by ``bincount`` and ``ufunc.at`` (:func:`_need_of`), where
        SciPy's product does not apply."""
        ea, ez = int(self.entry_at[a]), int(self.entry_at[z])
        if self.choice_at is not None:
            ca, cz = int(self.choice_at[a]), int(self.choice_at[z])
            choice_starts = self.choice_starts[ca:cz] - ra
            state_starts = self.state_starts[a:z] - ca
        else:
            choice_starts, state_starts = None, self.state_starts[a:z] - ra
        return _need_of(rnd, x, self.local[ea:ez] - ra, self.cols[ea:ez],
                        self.vals[ea:ez], self.rows[ra:rz], choice_starts, state_starts,
                        upper)

    def reading(self, mark: np.ndarray, a: int, z: int) -> np.ndarray:
        """Per state ``a:z``: whether a row of its choices holds a ``mark`` state (one
        segmented ``or`` where every state of the walk has an entry)."""
        ea, ez = int(self.entry_at[a]), int(self.entry_at[z])
        if self.filled:
            return np.logical_or.reduceat(mark[self.cols[ea:ez]],
                                          self.entry_at[a:z] - ea)
        hit = self.entry_state[ea:ez][mark[self.cols[ea:ez]]]
        out = np.zeros(z - a, dtype=bool)
        out[hit - a] = True
        return out


def _downward(st: Rows, live: np.ndarray, lv: np.ndarray, level_of: np.ndarray) -> bool:
    """:attr:`_Walk.downward` of the ``live`` states (their levels ``lv``, ascending)
    without the walk: whether no stored entry of their rows reads a ``live`` state of
    their own level or above.  A state's rows are consecutive (nature's too), so its
    entries are one range of the matrix's arrays: read there, not gathered row by row."""
    m = st.matrix
    first = st.groups[live] if st.nature is None else st.nature[st.groups[live]]
    stop = st.groups[live + 1] if st.nature is None else st.nature[st.groups[live + 1]]
    a, z = m.indptr[first], m.indptr[stop]
    cols = m.indices[gather_ranges(a, z)]
    in_walk = np.zeros(st.n_states, dtype=bool)
    in_walk[live] = True
    return not bool(np.any(in_walk[cols] & (level_of[cols] >= np.repeat(lv, z - a))))


@dataclass(slots=True, eq=False)
class Repair:
    """The repair of a candidate (module docs): a failing state's bound moved to what its
    choices need, levels downstream first (one pass over the levels above the lowest
    failing one, a level's states taken again while they move, at most :data:`ROUNDS`
    times), an end component's states together."""

    st: Rows
    rnd: Rounding
    free: np.ndarray
    level_of: np.ndarray
    mec_of: np.ndarray | None
    upper: bool
    members: tuple[np.ndarray, np.ndarray] | None = None
    moved: int = 0
    readers_of: tuple[np.ndarray, np.ndarray] | None = None
    in_mec: np.ndarray | None = None  # ``mec_of >= 0``, made at the first call
    # the compiled rounds' scratch (-1 a state) and whether ``x`` was found finite: made
    # at a run's first large level, kept through its others (a move keeps ``x`` finite:
    # a need past a finite bound, capped at 1 or 0; an end component's extreme)
    at: np.ndarray | None = None
    finite: bool | None = None

    def together(self, x: np.ndarray, states: np.ndarray) -> np.ndarray:
        """Bring each end component touched by ``states`` to its members' extreme value;
        the states whose value moved."""
        if self.mec_of is None:
            return states
        if self.in_mec is None:
            self.in_mec = self.mec_of >= 0
        if not self.in_mec[states].any():  # (most moves, on a deadline's levels)
            return states
        mecs = np.unique(self.mec_of[states])
        mecs = mecs[mecs >= 0]
        if mecs.size == 0:
            return states
        if self.members is None:
            order = np.argsort(self.mec_of, kind="stable")
            self.members = (order, self.mec_of[order])
        order, sorted_ids = self.members
        lo = np.searchsorted(sorted_ids, mecs, side="left")
        hi = np.searchsorted(sorted_ids, mecs, side="right")
        inside = order[gather_ranges(lo, hi)]
        group = np.repeat(np.arange(mecs.size), hi - lo)
        best = np.full(mecs.size, -np.inf if self.upper else np.inf)
        (np.maximum if self.upper else np.minimum).at(best, group, x[inside])
        new = best[group]
        changed = inside[new != x[inside]]
        x[inside] = new
        return np.union1d(states, changed)

    def readers(self, moved: np.ndarray, states: np.ndarray,
                scratch: np.ndarray) -> np.ndarray:
        """Per state of ``states``: whether a row of its choices holds a ``moved`` state,
        from the matrix's pattern by column (made at the first call): a few states moved
        in a large level, whose rows are not all read again to find their readers."""
        found = self._read_by(moved)
        scratch[found] = True
        out = scratch[states]
        scratch[found] = False
        return out

    def _passes(self, x: np.ndarray, failing: np.ndarray, live: np.ndarray) -> None:
        """:meth:`run` on ``live`` states whose rows read only states of lower levels (or
        states it does not move), none in an end component: every state whose value
        can move read at once, then the readers of those that moved, pass after pass,
        instead of level after level (a deadline's thousand levels: QVBS
        ``zeroconf_dl``'s moves run a few levels up from each failing state).  The same
        bounds and count: a state's need depends on lower levels alone and only grows
        (shrinks, for a lower bound) as they move, so its last pass reads them settled
        and gives ``max(x, min(need, 1))`` (``min(x, max(need, 0))``) of their final
        values, as the level's one round does; a state whose rows read no moved state
        and that passed the check needs no move (its need is what the check read), so
        only the readers are taken up; and the states moved are counted once each, as
        in one round a level.  Where the rounds' kernel runs, its passes are one call
        (:func:`~mitld_lp.solvers.certify_compiled.compiled_rounds` on every ``live``
        state as one level, until none moves: the same needs read before any move, the
        same moves and readers, a pass's order aside, which no need reads)."""
        if self.readers_of is None:
            self.readers_of = readers_by_column(self.st)
        ever = np.zeros(x.shape[0], dtype=bool)
        if compiled_rounds(self.st, self.rnd, x, live, failing[live], self.upper,
                           self.readers_of, ever, 1 << 62) is not None:
            self.moved += int(np.count_nonzero(ever))
            return
        in_walk = np.zeros(x.shape[0], dtype=bool)
        in_walk[live] = True
        todo = np.flatnonzero(failing & in_walk)
        while todo.size:
            changed = self._move(x, todo, _needed(self.st, self.rnd, x, todo, self.upper))
            if changed.size == 0:
                break
            ever[changed] = True
            todo = self.reader_states(changed, in_walk)
        self.moved += int(np.count_nonzero(ever))

    def _move(self, x: np.ndarray, states: np.ndarray, need: np.ndarray,
              among: np.ndarray | None = None) -> np.ndarray:
        """The ``states`` (of the mask ``among``) whose ``need`` is past their bound in
        ``x``, their bounds moved to it (at most 1; at least 0 for a lower bound)."""
        move = (need > x[states]) if self.upper else (need < x[states])
        if among is not None:
            move &= among
        changed = states[move]
        if changed.size:
            x[changed] = (np.minimum(need[move], 1.0) if self.upper else
                          np.maximum(need[move], 0.0))
        return changed

    def reader_states(self, moved: np.ndarray, among: np.ndarray) -> np.ndarray:
        """The states of the mask ``among`` with a row holding a ``moved`` state,
        increasing."""
        found = self._read_by(moved)
        return np.unique(found[among[found]])

    def _read_by(self, moved: np.ndarray) -> np.ndarray:
        """The state of each row holding a ``moved`` state (with repeats), from the
        matrix's pattern by column (made at the first call)."""
        if self.readers_of is None:
            self.readers_of = readers_by_column(self.st)
        col_ptr, col_state = self.readers_of
        return col_state[gather_ranges(col_ptr[moved], col_ptr[moved + 1])]

    def _compiled(self, x: np.ndarray, mine: np.ndarray, todo: np.ndarray,
                  moved: np.ndarray) -> bool | None:
        """The rounds of :meth:`run` on the large level ``mine`` from ``todo`` by one
        compiled call (:func:`~mitld_lp.solvers.certify_compiled.compiled_rounds`: the
        same needs, moves, readers and count, so the same bounds), flagging the states
        it moves in ``moved``: whether the level settled; None where the NumPy rounds
        run instead (the kernel's refusals, or a state of the level in an end
        component: :meth:`together` moves those)."""
        if self.mec_of is not None and bool(np.any(self.mec_of[mine] >= 0)):
            return None
        if not todo.any():
            return True
        if self.readers_of is None:
            self.readers_of = readers_by_column(self.st)
        if self.finite is None:
            self.finite = bool(np.isfinite(x).all())
        if not self.finite:
            return None  # (the kernel's refusal, found once)
        if self.at is None:
            self.at = np.full(x.shape[0], -1, dtype=np.int64)
        got = compiled_rounds(self.st, self.rnd, x, mine, todo, self.upper,
                              self.readers_of, moved, ROUNDS, self.at, True)
        if got is None:
            return None
        moves, settled = got
        self.moved += moves
        return settled

    def run(self, x: np.ndarray, failing: np.ndarray) -> bool:
        """Move the bounds of the ``failing`` states and of whatever they move upstream
        (a state is taken up when a row of its choices holds a moved state); False when
        a level does not settle within :data:`ROUNDS` rounds.  A level of fewer than
        :data:`SPARSE_LEVEL` states is read from slices gathered once for all of them
        (:class:`_Walk`), a larger one state by state: the rows of the states taken up,
        their readers from the pattern by column, all its rounds in one compiled call
        where that kernel is cached and no state of the level is in an end component
        (:meth:`_compiled`: the same bounds, moves and verdict).  Where every level is small and
        reads only lower ones, and no state is in an end component, the repair goes
        pass by pass instead (:meth:`_passes`, :data:`PASSES`): the same bounds."""
        self.finite = None  # (``x`` is this run's: looked at again at its first level)
        live = np.flatnonzero(~self.free)
        lv = self.level_of[live]
        first = int(self.level_of[failing].min())
        live, lv = live[lv >= first], lv[lv >= first]
        order = stable_order(lv)
        live, lv = live[order], lv[order]
        del order
        at = np.concatenate([[0], np.flatnonzero(np.diff(lv)) + 1, [lv.size]])
        sizes = np.diff(at)
        small = sizes < SPARSE_LEVEL
        walked = np.repeat(small, sizes)
        if (PASSES and bool(small.all())
                and (self.mec_of is None or not bool(np.any(self.mec_of[live] >= 0)))
                and _downward(self.st, live, lv, self.level_of)):
            # (the walk's own test, without gathering its slices: the passes read none)
            self._passes(x, failing, live)
            return True
        walk = _Walk(self.st, live[walked], lv[walked])
        del lv, walked  # (the levels' bounds are in ``at``: not held through the rounds)
        walk_at = np.concatenate([[0], np.cumsum(np.where(small, sizes, 0))]).tolist()
        moved = np.zeros(x.shape[0], dtype=bool)  # every state moved so far
        fresh = np.zeros(x.shape[0], dtype=bool)  # scratch: those of one round
        # the states with a row holding a moved state, kept as the levels move them,
        # where a large level is still to come: its first states to do, not the
        # readers of every state moved so far searched again at each large level
        # (QVBS csma 3-4 all_before_max: 35 large levels, each a pass over every
        # state's flag and the readers of all moved so far)
        large = np.flatnonzero(~small)
        last_large = int(large[-1]) if large.size else -1
        reads = (np.zeros(x.shape[0], dtype=bool) if KEEP_READS and last_large > 0
                 else None)
        bounds = at.tolist()
        for k, is_small in enumerate(small.tolist()):
            mine = live[bounds[k]:bounds[k + 1]]
            a, z = walk_at[k], walk_at[k + 1]
            todo = failing[mine] | (walk.reading(moved, a, z) if is_small else
                                    reads[mine] if reads is not None else
                                    self.readers(np.flatnonzero(moved), mine, fresh))
            if not is_small:
                before = moved[mine] if reads is not None and k < last_large else None
                done = self._compiled(x, mine, todo, moved)
                if done is not None:  # the same rounds in one call
                    if not done:
                        return False
                    if before is not None:  # (the kernel moves the level's states)
                        self._reading(reads, mine[moved[mine] & ~before])
                    continue
            for r in range(ROUNDS):
                if not todo.any():
                    break
                if is_small:  # the level's slices, the states not to do masked
                    changed = self._move(x, mine, walk.needed(self.rnd, x, a, z,
                                                              self.upper), todo)
                else:  # the rows of the states to do
                    doing = mine[todo]
                    changed = self._move(x, doing, _needed(self.st, self.rnd, x, doing,
                                                           self.upper))
                if changed.size == 0:
                    break
                self.moved += int(changed.size)
                now = self.together(x, changed)
                moved[now] = True
                if reads is not None and k < last_large:
                    self._reading(reads, now)
                # within the level (its cycles): the states reading those just moved
                if is_small:
                    if not walk.inward[a] and r + 1 < ROUNDS:
                        break  # no row of the level reads it: none to take up again
                    fresh[now] = True
                    todo = walk.reading(fresh, a, z)
                    fresh[now] = False
                else:
                    todo = self.readers(now, mine, fresh)
            else:
                return False
        return True

    def _reading(self, reads: np.ndarray, moved: np.ndarray) -> None:
        """Flag in ``reads`` the state of each row holding a ``moved`` state (the
        :meth:`readers` of those states, kept across the levels)."""
        if moved.size:
            reads[self._read_by(moved)] = True
