"""The construction: breadth first over the reachable product states, a batch of
states at a time (see :mod:`mitld_lp.product` for the semantics)."""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp import defaults
from mitld_lp.automata.sta import STA
from mitld_lp.mdp import ABSORB, MDP
from mitld_lp.product.budget import BuildBudget, default_max_memory, estimate_size
from mitld_lp.product.imdp import IntervalMDP
from mitld_lp.product.late_names import LateActionNames
from mitld_lp.product.layers import Layers
from mitld_lp.product.states import CODE, MASK_OF_CODE, Absorbing, ProductStates
from mitld_lp.product.table_levels import Plain, compiled_wanted, plain_table, run_compiled
from mitld_lp.util.arrays import (
    DENSE_LIMIT,
    Grow,
    Index,
    concatenate,
    merge,
    narrow_copy,
    ranks,
)
from mitld_lp.util.progress import bar as progress_bar
from mitld_lp.worlds.game import Game
from mitld_lp.worlds.table import LATE
from mitld_lp.worlds.task import check_alphabet

__all__ = ["product", "robust_product"]

log = logging.getLogger(__name__)

BATCH_ENTRIES = 1 << 18
"""Transitions (before merging) per batch of expanded states."""

LEAN_TABLES = True
"""Whether a plain table world's levels are built by :mod:`~mitld_lp.product.table_levels`
(the same arrays in fewer NumPy calls; False: every level by :func:`_expand`, for tests)."""


def product(
    game: Game[Any],
    sta: STA,
    *,
    max_states: int = defaults.MAX_STATES,
    max_memory: int | None = None,
    progress: bool | None = None,
) -> MDP:
    """Build the reachable product MDP of ``game`` and ``sta`` (see the module docstring).

    States are numbered breadth first from the initial state, successors in the order
    (action, event outcome, game successor); a row's entries in the order they first
    appear, entries to one product state summed in that order.  The queue is expanded
    in batches of states whose transitions are computed as arrays: each factor (the
    game's rows per (state, action, events), the STA's outcomes per situation, the
    automaton's steps per (state, letter)) is asked once and then joined in numpy.

    Budgets, checked before the work: :func:`estimate_size` bounds the product from its
    factors; when the bound is within ``max_states`` nothing more can go wrong, else
    (the reachable part may still be small) the states are counted exactly per batch,
    before a batch's new states are stored, against ``max_states`` and against
    ``max_memory`` bytes (default :func:`default_max_memory`) at
    :data:`BYTES_PER_STATE` per state plus :data:`BYTES_PER_TRANSITION` per transition,
    the transitions per state as measured so far.  Either raises
    :class:`ProductTooLarge` naming the numbers.
    ``progress``: show a progress bar (None: only on a terminal, for large builds).

    Raises :class:`mitld_lp.worlds.task.BindError` (a ``ValueError``) when the task does not fit
    the game (:func:`mitld_lp.worlds.task.check_alphabet`: a proposition the automaton reads
    that is neither a proposition of the game nor an event of the STA, an event with a
    proposition's name, an event the game reacts to without a law).
    """
    built = _build(game, sta, max_states, max_memory, progress, robust=False)
    assert isinstance(built, MDP)
    return built


def robust_product(
    game: Game[Any],
    sta: STA,
    *,
    max_states: int = defaults.MAX_STATES,
    max_memory: int | None = None,
    progress: bool | None = None,
) -> IntervalMDP:
    """The product as an interval MDP (:mod:`mitld_lp.product.imdp`) when some event's law is a
    band: built like :func:`product`, but a choice's rows are kept apart by which
    ambiguous events happened (its branches), each weighted by the events known exactly
    only, and each choice carries the hazard intervals of its ambiguous events.  With no
    band every choice has one branch, its row in :func:`product`, bit for bit."""
    built = _build(game, sta, max_states, max_memory, progress, robust=True)
    assert isinstance(built, IntervalMDP)
    return built


def _build(
    game: Game[Any], sta: STA, max_states: int, max_memory: int | None,
    progress: bool | None, *, robust: bool,
) -> MDP | IntervalMDP:
    members = check_alphabet(game, sta.dta.atoms, sta.events)
    budget = BuildBudget(
        max_states,
        default_max_memory() if max_memory is None else max_memory,
        estimate_size(game, sta),
    )
    log.info("product: %s", budget.estimate)
    f = Layers(game, members, sta, robust)
    states = _Found(f, budget)
    g0 = f.game_state(game.initial)
    f.flush()
    q0 = f.step(np.array([sta.dta.initial]), f.props.view[[g0]])
    sid0 = f.situation(sta.events, 0)
    if robust:  # every event pending: the widest choices nature's vertices may have
        f.ensure_outcomes(np.array([sid0]))
        budget.check_start(int(f.band_count.view[sid0]))
    initial = int(states.intern(q0 if q0[0] < 0 else f.codec.key(g0, q0, sid0))[0])

    # per batch: cols, vals, row lengths, actions (robust: then branches and bands per
    # choice, the bands' lo, hi and events)
    chunks: list[tuple[np.ndarray, ...]] = []
    state_choices = Grow(np.int32)  # choices per state: row_groups sums them in int64
    bar = progress_bar(progress, total=None, unit=" states", leave=False, mininterval=0.5,
                       desc="product")
    head, batch = 0, 256
    lean: Plain | None = None
    n_keys = f.codec.key(f.table.n_states, 0, 0) + _SHIFT if f.table is not None else 0
    compiled = False  # the levels go to the compiled loop (table_levels.run_compiled)
    while head < states.keys.size:
        if lean is None and LEAN_TABLES and head and plain_table(f):
            lean = Plain(f)  # after the first level: its situation is expanded
        if lean is not None and (compiled or compiled_wanted(
                lean, n_keys // f.codec.n_q, budget.expanded, states.keys.size - head,
                budget.transitions / max(budget.expanded, 1))):
            ran = run_compiled(lean, states, head, budget, n_keys)
            compiled = ran is not None
            if ran is not None:  # else (numba missing, no progress) a batch of NumPy's
                chunks.append(ran[0])
                state_choices.extend(ran[0][4])
                bar.update(ran[1])
                head += ran[1]
                continue
        keys = states.keys.view[head : head + batch].copy()
        if lean is not None and int(keys.min()) >= 0:
            chunk, n_entries = lean.expand(keys, states.intern)
            lean.batches += 1
        else:
            chunk, n_entries = _expand(f, keys, head, states.intern)
        chunks.append(chunk)
        state_choices.extend(chunk[4])
        budget.expanded += keys.size
        budget.transitions += chunk[0].size
        if robust:  # nature's vertex rows of these choices, before any more is built
            budget.add_vertices(*_vertex_cost(chunk))
            budget.check(states.keys.size)
        bar.update(keys.size)
        head += keys.size
        batch = min(max(BATCH_ENTRIES * keys.size // max(n_entries, 1), 16), 1 << 20)
    bar.close()
    lean = None  # its views of the table's arrays go with the layers' below
    f.check_rows()  # the rows not checked yet: every distribution read is checked
    # the states' keys in 4 bytes where they fit (the product keeps them, one a state)
    keys = narrow_copy(states.keys.view)
    del states  # the index is not needed any more: free it before the matrix is assembled
    f.release()  # the world's rows and the memos go before the matrix is assembled
    return _assemble(f, chunks, state_choices.view, keys, initial)


def _vertex_cost(chunk: tuple[np.ndarray, ...]) -> tuple[int, int, int, int]:
    """Nature's vertex distributions of a robust batch's choices
    (:func:`mitld_lp.product.imdp.vertex_rows`): ``(entries, rows, weights, widest)``.  A choice
    with ``k`` ambiguous events has ``2^k`` vertex rows, each over the union of the
    successors of its ``2^k`` branches, and ``4^k`` weights."""
    cols, row_len, n_branch, n_bands = chunk[0], chunk[2], chunk[5], chunk[6]
    n_branch = n_branch.astype(np.int64)
    if not n_bands.size or not n_bands.any():  # one vertex row per choice: its row
        return int(cols.size), int(n_branch.sum()), int(n_branch.sum()), 0
    branch_choice = np.repeat(np.arange(n_branch.size, dtype=np.int64), n_branch)
    entry_choice = np.repeat(branch_choice, row_len.astype(np.int64))
    pairs = np.unique((entry_choice << 32) | cols.astype(np.int64))
    support = np.bincount(pairs >> 32, minlength=n_branch.size)
    return (int((n_branch * support).sum()), int(n_branch.sum()),
            int((n_branch * n_branch).sum()), int(n_bands.max()))


class _Found:
    """The product states found so far: their keys in the order found, and an index
    (a plain array by key while the keys are dense: :class:`~mitld_lp.util.arrays.Index`)."""

    def __init__(self, f: Layers, budget: BuildBudget) -> None:
        self.f, self.budget = f, budget
        self.index = Index(DENSE_LIMIT)
        self.keys = Grow(np.int64)  # per state: its key (>= 0) or absorbing code (< 0)

    def intern(self, keys: np.ndarray) -> np.ndarray:
        """Product state ids of ``keys``, new ones numbered in order of first occurrence.
        The budget is checked before the new states are stored."""
        # shifted past the absorbing codes (-3 .. -1), so that every key is >= 0
        shifted = keys + _SHIFT
        dense = self.index.dense
        if dense is not None and shifted.size and int(shifted.max()) < dense.size:
            ids = dense[shifted].astype(np.int64)  # Index.find's answer, in one gather
            miss = np.flatnonzero(ids < 0)
            if miss.size:
                self._add_dense(dense, shifted[miss], miss, ids)
            return ids
        ids = self.index.find(shifted)
        miss = np.flatnonzero(ids < 0)
        if miss.size:
            # the distinct missing keys, each's first occurrence and each entry's
            # distinct key, as np.unique(..., return_index, return_inverse) gives them
            # (by one stable sort: fewer NumPy calls, as a thin frontier's batch is small)
            missing = keys[miss]
            order = np.argsort(missing, kind="stable")
            ordered = missing[order]
            head = np.empty(ordered.size, dtype=bool)
            head[0] = True
            np.not_equal(ordered[1:], ordered[:-1], out=head[1:])
            uniq, first = ordered[head], order[head]  # stable: the first occurrence
            inverse = np.empty(missing.size, dtype=np.int64)
            inverse[order] = np.cumsum(head) - 1
            n = self.keys.size
            self.budget.check(n + uniq.size)
            found = np.argsort(first, kind="stable")  # the distinct keys as first found
            new = np.empty(uniq.size, dtype=np.int64)
            new[found] = np.arange(n, n + uniq.size)
            self.index.insert(uniq + _SHIFT, new)
            self.keys.extend(uniq[found])
            ids[miss] = new[inverse]
        return ids

    def _add_dense(
        self, dense: np.ndarray, missing: np.ndarray, miss: np.ndarray, ids: np.ndarray
    ) -> None:
        """Number the distinct keys of ``missing`` (shifted, all inside the index's dense
        array, none in it yet) in order of first occurrence and write each entry's id
        at ``ids[miss]``: the first occurrence of each key is found with the dense array
        as scratch (its entries at ``missing`` are -1 before and after), a minimum per
        key, instead of two sorts."""
        m = missing.size
        pos = np.arange(m, dtype=dense.dtype)
        dense[missing] = m
        np.minimum.at(dense, missing, pos)  # each key's first position in missing
        first_at = dense[missing]
        dense[missing] = -1  # the scratch undone before anything may raise
        first = np.flatnonzero(first_at == pos)  # in order of first occurrence
        n = self.keys.size
        self.budget.check(n + first.size)
        new = np.empty(m, dtype=np.int64)
        new[first] = np.arange(n, n + first.size)
        uniq = missing[first]
        self.index.insert(uniq, new[first])
        self.keys.extend(uniq - _SHIFT)
        ids[miss] = new[first_at]


_SHIFT = -min(CODE.values())
"""Added to a key in the index: the absorbing codes become 0 .. 2, every key >= 0."""


def _expand(
    f: Layers, keys: np.ndarray, first_id: int, intern: Any
) -> tuple[tuple[np.ndarray, ...], int]:
    """The rows of the product states ``keys`` (ids ``first_id, first_id + 1, ...``).

    Returns (cols, vals, row lengths, choice actions, choices per state) and the number
    of entries before merging (to size the next batch).
    """
    ordinary = keys >= 0
    plain = bool(ordinary.all())  # no absorbing state in the batch (nearly always)
    g, q, sid = f.codec.unkey(keys if plain else keys[ordinary])
    f.ensure_actions(g)
    f.ensure_outcomes(sid)
    # A thin frontier makes small batches, whose time is NumPy's cost per call: the
    # steps below skip the calls that would do nothing (one outcome per situation, no
    # truncation point crossed, no event), with the same numbers.
    # choices: one per (state, action slot)
    n_act = f.act_count.view[g]
    c_state = np.repeat(np.arange(g.size), n_act)
    c_slot = f.act_start.view[g][c_state] + ranks(n_act)
    # pairs: one per (choice, event outcome)
    c_sid = sid[c_state]
    if f.single_outcome:  # one outcome per situation: a pair is its choice
        p_choice = np.arange(c_slot.size)
        p_out = f.out_start.view[c_sid]
    else:
        n_out = f.out_count.view[c_sid]
        p_choice = np.repeat(np.arange(c_slot.size), n_out)
        p_out = f.out_start.view[c_sid][p_choice] + ranks(n_out)
    p_occ = f.out_occ.view[p_out]
    p_next = f.out_next.view[p_out]
    alive = p_next >= 0
    every = bool(alive.all())  # no outcome crossed a truncation point
    if every:
        p_row = f.rows(c_slot[p_choice], p_occ)
    else:
        p_row = np.full(p_choice.size, f.cut_row, dtype=np.int64)  # crossed one
        p_row[alive] = f.rows(c_slot[p_choice[alive]], p_occ[alive])
    # entries: one per (pair, game successor); the truncation row's one entry has
    # probability 1 and no successor (neither is read)
    n_succ = f.row_len.view[p_row]
    e_pair = np.repeat(np.arange(p_choice.size), n_succ)
    e_at = f.row_start.view[p_row][e_pair] + ranks(n_succ)
    vals = f.out_prob.view[p_out][e_pair]
    f.flush()
    if every:
        vals *= f.row_prob.view[e_at]
        g2 = f.row_succ.view[e_at]
        e_pm = e_pair
    else:
        moving = alive[e_pair]
        vals[moving] *= f.row_prob.view[e_at[moving]]
        g2 = f.row_succ.view[e_at[moving]]
        e_pm = e_pair[moving]
    letter = f.props.view[g2]
    if f.events:  # the events that occurred, as letters
        letter = letter | f.occ_letter(p_occ[e_pm])
    q2 = f.step(q[c_state[p_choice[e_pm]]], letter)
    moved = np.where(q2 < 0, q2, f.codec.key(g2, q2, p_next[e_pm]))
    if every:
        e_key = moved
    else:
        e_key = np.full(e_pair.size, CODE[Absorbing.TRUNCATED], dtype=np.int64)
        e_key[moving] = moved
    cols = intern(e_key).astype(np.int32)
    e_choice = p_choice[e_pair]
    extra: list[np.ndarray] = []
    if f.robust:  # one row per (choice, branch), with the choice's hazard intervals
        n_bands = f.band_count.view[c_sid]
        n_branch = np.left_shift(1, n_bands)
        first_branch = np.cumsum(n_branch) - n_branch
        p_branch = first_branch[p_choice] + f.out_branch.view[p_out]
        e_branch = p_branch[e_pair]
        grouped = np.argsort(e_branch, kind="stable")  # a branch's entries together, in order
        cols, vals, row_len = merge(e_branch[grouped], cols[grouped], vals[grouped],
                                    int(n_branch.sum()))
        at = np.repeat(f.band_start.view[c_sid], n_bands) + ranks(n_bands)
        extra = [n_branch, n_bands, f.band_lo.view[at], f.band_hi.view[at],
                 f.band_event.view[at]]
    else:
        cols, vals, row_len = merge(e_choice, cols, vals, c_slot.size)
    # a table's action slot c is its robot choice c (named when first read: LATE + c)
    actions = c_slot + LATE if f.late else f.slot_aid.view[c_slot]
    if plain:
        return (cols, vals, row_len.astype(np.int32), actions.astype(np.int32),
                n_act.astype(np.int32), *extra), int(e_key.size)
    choices = np.ones(keys.size, dtype=np.int32)
    choices[ordinary] = n_act
    # the absorbing states of the batch (at most three in the whole product): one
    # self-loop each, inserted where their state falls in the order
    for i in np.flatnonzero(~ordinary).tolist():
        before = int(np.count_nonzero(ordinary[:i]))
        at_choice = int(n_act[:before].sum())
        at_row = int(extra[0][:at_choice].sum()) if extra else at_choice
        at_entry = int(row_len[:at_row].sum())
        cols = np.insert(cols, at_entry, first_id + i)
        vals = np.insert(vals, at_entry, 1.0)
        row_len = np.insert(row_len, at_row, 1)
        actions = np.insert(actions, at_choice, ABSORB)
        if extra:  # one branch, no hazard interval
            extra[0] = np.insert(extra[0], at_choice, 1)
            extra[1] = np.insert(extra[1], at_choice, 0)
        n_act = np.insert(n_act, before, 1)
        ordinary = ordinary.copy()
        ordinary[i] = True
    return (cols, vals, row_len.astype(np.int32), actions.astype(np.int32), choices,
            *extra), int(e_key.size)


def _assemble(
    f: Layers,
    chunks: list[tuple[np.ndarray, ...]],
    state_choices: np.ndarray,
    keys: np.ndarray,
    initial: int,
) -> MDP | IntervalMDP:
    """The MDP (or the interval MDP) from the batches' rows, with a record per state."""
    columns = [list(c) for c in zip(*chunks, strict=True)]
    chunks.clear()
    cols = concatenate(columns[0], np.int32)
    vals = concatenate(columns[1], np.float64)
    row_len = concatenate(columns[2], np.int32)
    actions = concatenate(columns[3], np.int32)
    n_rows = row_len.size
    # int32 indices where they fit: 12 bytes a transition, not 16
    index = np.int32 if max(cols.size, keys.size) < 2**31 else np.int64
    indptr = np.zeros(n_rows + 1, dtype=index)
    np.cumsum(row_len, out=indptr[1:], dtype=index)
    del row_len
    names: Any
    if f.late:  # named when first read, in order of first use (product.late_names)
        assert f.late_names is not None  # kept by Layers past its release()
        choice_actions = actions  # LATE + the world's robot choice, ABSORB
        names = LateActionNames(f.late_names, choice_actions)
    else:  # action ids in order of first use, as names
        used = actions >= 0
        uniq, first = np.unique(actions[used], return_index=True)
        order = uniq[np.argsort(first)]
        remap = np.full(max(len(f.action_id), 1), -1, dtype=np.int32)
        remap[order] = np.arange(order.size, dtype=np.int32)
        choice_actions = np.full(actions.size, ABSORB, dtype=np.int32)
        choice_actions[used] = remap[actions[used]]
        by_id = {i: a for a, i in f.action_id.items()}
        names = tuple(by_id[int(i)] for i in order)
    kind = np.zeros(keys.size, dtype=np.int8)
    for code, k in MASK_OF_CODE.items():
        kind[keys == code] = k
    n = keys.size
    matrix = sp.csr_array((vals, cols.astype(index, copy=False), indptr), shape=(n_rows, n))
    row_groups = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(state_choices, out=row_groups[1:])
    common: dict[str, Any] = dict(
        row_groups=row_groups,
        choice_actions=choice_actions,
        action_names=names,
        initial=initial,
        target=kind == 1,
        sink=kind == 2,
        truncated=kind == 3,
        # the MDP's field is typed as a tuple; the lazy sequence answers len, [i] and
        # iteration as a tuple would
        states=ProductStates(keys, f.game_states, f.situations, f.codec),
    )
    if f.robust:
        branch_groups, band_groups = (
            np.concatenate([[0], np.cumsum(concatenate(c, np.int64))]) for c in columns[5:7])
        imdp = IntervalMDP(
            branches=matrix, branch_groups=branch_groups, band_groups=band_groups,
            band_lo=concatenate(columns[7], np.float64),
            band_hi=concatenate(columns[8], np.float64),
            band_events=tuple(f.events[int(i)] for i in concatenate(columns[9], np.int64)),
            **common,
        )
        log.info("robust product: %d states, %d choices (%d with ambiguous events), %d "
                 "branches", n, imdp.n_choices, imdp.ambiguous_choices, imdp.n_branches)
        return imdp
    mdp = MDP(matrix=matrix, **common)
    log.info(
        "product: %d states, %d choices, %d transitions", n, mdp.n_choices, mdp.n_transitions
    )
    return mdp
