"""The product of the game with the STA: a finite MDP, built over reachable states only.

A product state is ``(game state, automaton state, pending events, clock)``.  From it
the robot picks an action ``a``; the environment's events ``E`` of the step are drawn
from the pending events' hazards (:meth:`STA.outcomes`); the game moves to ``s'`` with
probability ``P(s' | s, a, E)``; the automaton reads the label ``L(s') = props(s') | E``.
So the product's transitions are::

    P((s, q, Y, c) --a--> (s', q', Y \\ E, c'))  =  p_STA(E | Y, c) * P(s' | s, a, E)
    with q' = delta(q, props(s') | E) and c' = STA.advance(Y \\ E, c).

At step 0 no event has happened: the initial state is ``(s0, delta(q0, props(s0)), U, 0)``.
Accepting automaton states collapse into one absorbing ``target`` state, rejecting ones
into ``sink``, and outcomes that cross a truncation point into ``truncated``; the three
are kept apart in the MDP's masks, so one build yields both the lower model (truncated
loses) and the upper model (truncated wins).  They are the :class:`Absorbing` members.

The construction (:func:`product`) numbers every factor with integers -- game states,
situations ``(Y, c)``, automaton states -- asks each factor once per distinct question
(the game per (state, action, events), the STA per situation, the automaton per (state,
letter)) and joins the answers for a whole batch of product states at a time in numpy.
A product state is the integer ``(g * n_q + q) * n_sit + sid``; ``MDP.states`` makes its
record (:class:`ProductState`) when asked.  Budgets (:func:`estimate_size`, states,
memory) are checked before the work that would exceed them.
"""

from __future__ import annotations

import enum
import logging
import os
from collections.abc import Hashable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, overload

import numpy as np
import scipy.sparse as sp
from tqdm.auto import tqdm

from mitld_lp import defaults
from mitld_lp.arrays import unique
from mitld_lp.automata.sta import STA, TRUNCATED
from mitld_lp.game import Game
from mitld_lp.mdp import ABSORB, MDP

__all__ = [
    "Absorbing",
    "BYTES_PER_STATE",
    "BYTES_PER_TRANSITION",
    "SizeEstimate",
    "default_max_memory",
    "estimate_size",
    "ProductState",
    "ProductStates",
    "ProductTooLarge",
    "product",
    "component_counts",
]

log = logging.getLogger(__name__)


class Absorbing(enum.StrEnum):
    """The three absorbing product states (each a single self-loop in the MDP).

    A ``StrEnum`` so that the states print as their DRN labels (``target``, ...).
    """

    TARGET = "target"  # the automaton accepted
    SINK = "sink"  # the automaton rejected
    TRUNCATED = "truncated"  # an event clock ran past its truncation point


class ProductTooLarge(RuntimeError):
    """The product would exceed a budget (``max_states`` or ``max_memory``); a user
    error: the message names the numbers and what to change."""


@dataclass(frozen=True, slots=True)
class ProductState:
    """A non-absorbing product state.

    ``clock`` counts the steps taken, capped where no pending event's hazard changes
    any more (:meth:`mitld_lp.automata.sta.STA.advance`).
    """

    game: Hashable
    automaton: int
    pending: frozenset[str]
    clock: int


# Codes of the absorbing states in the arrays of the construction (ordinary states are
# coded by non-negative integers).
_CODE = {Absorbing.TARGET: -1, Absorbing.SINK: -2, Absorbing.TRUNCATED: -3}
_ABSORBING = {code: a for a, code in _CODE.items()}
_KIND = {-1: 1, -2: 2, -3: 3}  # code -> the MDP's mask (1 target, 2 sink, 3 truncated)
_BATCH_ENTRIES = 1 << 18  # transitions (before merging) per batch of expanded states
_MAX_INDEX = 2**31 - 1  # states: the matrix's column indices are int32


class _Grow:
    """A numpy array that grows by doubling (amortised O(1) appends of blocks)."""

    def __init__(self, dtype: Any) -> None:
        self.data = np.empty(64, dtype=dtype)
        self.size = 0

    def extend(self, values: Any) -> None:
        values = np.asarray(values, dtype=self.data.dtype)
        need = self.size + values.size
        if need > self.data.size:
            bigger = np.empty(max(need, 2 * self.data.size), dtype=self.data.dtype)
            bigger[: self.size] = self.data[: self.size]
            self.data = bigger
        self.data[self.size : need] = values
        self.size = need

    @property
    def view(self) -> np.ndarray:
        return self.data[: self.size]


_MISSING = np.iinfo(np.int64).min
_DENSE_LIMIT = 1 << 22  # keys below this are memoised in a plain array (32 MB at most)


class _Memo:
    """A memo ``key -> int`` for arrays of non-negative keys, filled on demand.

    ``compute(keys)`` gives the values of distinct, sorted, unknown keys.  While the
    keys stay below ``_DENSE_LIMIT`` the memo is a plain array (one gather per call);
    beyond, a hash index (:class:`_Index`), so that sparse keys cost no more memory than
    the entries stored.
    """

    def __init__(self, compute: Any, space: int = 0) -> None:
        self.compute = compute
        self.table: np.ndarray | None = None
        self.index: _Index | None = None
        if space <= _DENSE_LIMIT:
            self.table = np.full(max(space, min(64, _DENSE_LIMIT)), _MISSING)
        else:
            self.index = _Index()

    def _grow(self, top: int) -> None:
        assert self.table is not None
        if top <= _DENSE_LIMIT:
            bigger = np.full(max(top, 2 * self.table.size), _MISSING)
            bigger[: self.table.size] = self.table
            self.table = bigger
        else:  # too sparse for an array: move the entries to a hash index
            known = np.flatnonzero(self.table != _MISSING)
            self.index = _Index()
            self.index.insert(known, self.table[known])
            self.table = None

    def __call__(self, keys: np.ndarray) -> np.ndarray:
        if self.table is not None:
            top = int(keys.max(initial=-1)) + 1
            if top > self.table.size:
                self._grow(top)
        if self.table is not None:
            vals = self.table[keys]
            miss = vals == _MISSING
            if miss.any():
                new = unique(keys[miss])
                self.table[new] = self.compute(new)
                vals[miss] = self.table[keys[miss]]
            return vals
        assert self.index is not None
        uniq, inverse = np.unique(keys, return_inverse=True)
        vals = self.index.find(uniq, absent=_MISSING)
        miss = vals == _MISSING
        if miss.any():
            vals[miss] = self.compute(uniq[miss])
            self.index.insert(uniq[miss], vals[miss])
        return vals[inverse]


class _Index:
    """Product state ids by key: open addressing over arrays, probed for a whole batch
    of keys at once (linear probing, load at most 1/2, Fibonacci hashing)."""

    _EMPTY = -(1 << 62)

    def __init__(self) -> None:
        self.bits = 16
        self.keys = np.full(1 << self.bits, self._EMPTY, dtype=np.int64)
        self.ids = np.zeros(1 << self.bits, dtype=np.int32)
        self.size = 0

    def _home(self, keys: np.ndarray) -> np.ndarray:
        h = np.ascontiguousarray(keys, dtype=np.int64).view(np.uint64) * np.uint64(
            0x9E3779B97F4A7C15
        )
        return (h >> np.uint64(64 - self.bits)).view(np.int64)

    def find(self, keys: np.ndarray, absent: int = -1) -> np.ndarray:
        """The id of each key, ``absent`` where absent."""
        at = self._home(keys)
        found = self.keys[at]
        hit = found == keys
        out = np.where(hit, self.ids[at], np.int64(absent)).astype(np.int64)
        todo = np.flatnonzero(~hit & (found != self._EMPTY))
        mask = (1 << self.bits) - 1
        at = at[todo]
        while todo.size:
            at = (at + 1) & mask
            found = self.keys[at]
            hit = found == keys[todo]
            out[todo[hit]] = self.ids[at[hit]]
            go_on = ~hit & (found != self._EMPTY)
            todo, at = todo[go_on], at[go_on]
        return out

    def insert(self, keys: np.ndarray, ids: np.ndarray) -> None:
        """Add distinct keys that are not in the index yet."""
        if 2 * (self.size + keys.size) > (1 << self.bits):
            old_keys, old_ids = self.keys[self.keys != self._EMPTY], self.ids[
                self.keys != self._EMPTY]
            while 2 * (self.size + keys.size) > (1 << self.bits):
                self.bits += 1
            self.keys = np.full(1 << self.bits, self._EMPTY, dtype=np.int64)
            self.ids = np.zeros(1 << self.bits, dtype=np.int32)
            self.size = 0
            self.insert(old_keys, old_ids)
        pos = self._home(keys)
        todo = np.arange(keys.size)
        mask = (1 << self.bits) - 1
        while todo.size:
            at = pos[todo]
            free = self.keys[at] == self._EMPTY
            # one winner per free slot; the others probe on
            _, first = np.unique(at[free], return_index=True)
            win = todo[free][first]
            self.keys[pos[win]] = keys[win]
            self.ids[pos[win]] = ids[win]
            placed = np.zeros(keys.size, dtype=bool)
            placed[win] = True
            todo = todo[~placed[todo]]
            pos[todo] = (pos[todo] + 1) & mask
        self.size += keys.size


class _Layers:
    """The factors of the product, each expanded once and kept as integer arrays.

    * the game: states interned as ``g``; per ``g`` its action slots (``act_start[g]``
      ``.. + act_count[g]`` index ``slot_action``) and its propositions as a bit mask
      over the automaton's atoms; per (slot, event outcome) one successor row
      (``row_start``/``row_len`` into ``row_succ``/``row_prob``), row 0 standing for
      "the outcome crossed a truncation point";
    * the events: situations ``(pending, clock)`` interned as ``sid``; per ``sid`` its
      outcomes (``out_*``: the events that happened as a bit mask over the STA's events,
      the probability, the next situation or -1 when truncated);
    * the automaton: ``delta[(q << A) | letter]`` with ``letter`` a bit mask over the
      ``A`` atoms, coded as the next state or an absorbing code.
    """

    def __init__(self, game: Game[Any], sta: STA) -> None:
        self.game, self.sta, self.dta = game, sta, sta.dta
        self.ignores_events = getattr(game, "ignores_events", False) is True
        self.atoms = {a: i for i, a in enumerate(self.dta.atoms)}
        self.events = sorted(sta.events)
        if len(self.atoms) > 62 or len(self.events) > 30:
            raise ProductTooLarge(
                f"the automaton reads {len(self.atoms)} propositions and the task has "
                f"{len(self.events)} events: more than this construction encodes (62, 30)"
            )
        n_occ = 1 << len(self.events)
        self.n_occ = n_occ
        self._occ_sets: dict[int, frozenset[str]] = {}
        # game
        self.gid: dict[Hashable, int] = {}
        self.game_states: list[Hashable] = []
        self._new_props: list[int] = []
        self.props = _Grow(np.int64)
        self.act_start = _Grow(np.int64)
        self.act_count = _Grow(np.int64)  # -1: actions not asked yet
        self.slot_action: list[str] = []  # per action slot: its name, game state, action id
        self.slot_owner: list[int] = []
        self.slot_aid = _Grow(np.int64)
        self.action_id: dict[str, int] = {}
        self._rows = _Memo(self._new_rows)
        self.row_by_object: dict[int, tuple[Any, int]] = {}  # id(answer) -> (answer, row)
        self.row_start, self.row_len = _Grow(np.int64), _Grow(np.int64)
        self.row_succ, self.row_prob = _Grow(np.int64), _Grow(np.float64)
        self.row_start.extend([0])
        self.row_len.extend([1])
        self.row_succ.extend([-1])
        self.row_prob.extend([1.0])
        # events
        self.sid: dict[tuple[frozenset[str], int], int] = {}
        self.situations: list[tuple[frozenset[str], int]] = []
        self.out_start, self.out_count = _Grow(np.int64), _Grow(np.int64)
        self.out_occ, self.out_prob, self.out_next = (
            _Grow(np.int64), _Grow(np.float64), _Grow(np.int64)
        )
        # product keys: ((g * n_q) + q) * n_sit + sid; n_sit bounds the situations
        self.n_q = self.dta.n_states
        caps = max((c.cap for c in sta.clocks.values()), default=0)
        self.n_sit = n_occ * (caps + 1)
        # automaton
        self._delta = _Memo(self._new_steps, self.dta.n_states << len(self.atoms))

    def key(self, g: Any, q: Any, sid: Any) -> Any:
        """The product key of ``(g, q, sid)`` (arrays or ints)."""
        return (g * self.n_q + q) * self.n_sit + sid

    def unkey(self, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        rest, sid = np.divmod(keys, self.n_sit)
        g, q = np.divmod(rest, self.n_q)
        return g, q, sid

    def occ_set(self, mask: int) -> frozenset[str]:
        """The events of an outcome's bit mask (over the sorted events)."""
        hit = self._occ_sets.get(mask)
        if hit is None:
            hit = self._occ_sets[mask] = frozenset(
                e for i, e in enumerate(self.events) if mask >> i & 1
            )
        return hit

    def occ_letter(self, masks: np.ndarray) -> np.ndarray:
        """The events of outcome bit masks as bit masks over the automaton's atoms."""
        out = np.zeros(masks.size, dtype=np.int64)
        for i, e in enumerate(self.events):
            if e in self.atoms:
                out |= ((masks >> i) & 1) << self.atoms[e]
        return out

    # ---------------------------------------------------------------- game
    def game_state(self, s: Hashable) -> int:
        g = self.gid.get(s)
        if g is None:
            g = len(self.game_states)
            if (g + 1) * self.n_q * self.n_sit >= 1 << 62:
                raise ProductTooLarge(
                    f"more than {g:,} game states with {self.n_q} automaton states and "
                    f"{self.n_sit:,} event situations: too many to number"
                )
            self.gid[s] = g
            self.game_states.append(s)
            props = self.game.propositions(s)
            self._new_props.append(sum(1 << i for a, i in self.atoms.items() if a in props))
        return g

    def flush(self) -> None:
        """Give the game states interned since the last call their array entries."""
        new = self._new_props
        if new:
            self.props.extend(new)
            self.act_start.extend(np.zeros(len(new), dtype=np.int64))
            self.act_count.extend(np.full(len(new), -1, dtype=np.int64))
            new.clear()

    def ensure_actions(self, gs: np.ndarray) -> None:
        """Ask the game for the actions of the game states ``gs`` not yet asked."""
        self.flush()
        missing = unique(gs[self.act_count.view[gs] < 0])
        aids = []
        for g in missing.tolist():
            acts = self.game.actions(self.game_states[g])
            self.act_start.data[g] = len(self.slot_action)
            self.act_count.data[g] = len(acts)
            for a in acts:
                self.slot_action.append(a)
                self.slot_owner.append(g)
                aids.append(self.action_id.setdefault(a, len(self.action_id)))
        self.slot_aid.extend(aids)

    def _add_rows(self, rows: list[tuple[tuple[Any, float], ...]]) -> None:
        """Store successor rows (pairs ``(game state, probability)``) as rows of ``g``."""
        lengths = [len(r) for r in rows]
        starts = np.cumsum([0, *lengths[:-1]], dtype=np.int64) + self.row_succ.size
        self.row_start.extend(starts)
        self.row_len.extend(lengths)
        gid = self.gid
        self.row_succ.extend(
            [gid[s] if s in gid else self.game_state(s) for r in rows for s, _ in r]
        )
        self.row_prob.extend([p for r in rows for _, p in r])

    def rows(self, slots: np.ndarray, occ: np.ndarray) -> np.ndarray:
        """The successor row of each (action slot, event outcome)."""
        if self.ignores_events:  # one row per slot, asked with no events
            return self._rows(slots)
        return self._rows(slots * self.n_occ + occ)

    def _new_rows(self, keys: np.ndarray) -> np.ndarray:
        """Ask the game once per (action slot, event outcome) ``keys``; a game that
        answers with the very same object for several of them, as a precomputed table
        does, gets one row for them."""
        new_rows: list[tuple[tuple[Any, float], ...]] = []
        same = self.row_by_object
        base = self.row_start.size
        owner, names, occ_set = self.slot_owner, self.slot_action, self.occ_set
        out = np.empty(keys.size, dtype=np.int64)
        for i, key in enumerate(keys.tolist()):
            slot, o = (key, 0) if self.ignores_events else divmod(key, self.n_occ)
            succ = self.game.successors(self.game_states[owner[slot]], names[slot], occ_set(o))
            hit = same.get(id(succ))
            if hit is None or hit[0] is not succ:
                hit = same[id(succ)] = (succ, base + len(new_rows))
                new_rows.append(succ)
            out[i] = hit[1]
        if new_rows:
            self._add_rows(new_rows)
        return out

    # ---------------------------------------------------------------- events
    def situation(self, pending: frozenset[str], clock: int) -> int:
        key = (pending, clock)
        i = self.sid.get(key)
        if i is None:
            i = self.sid[key] = len(self.situations)
            self.situations.append(key)
            self.out_count.extend([-1])
            self.out_start.extend([0])
        return i

    def ensure_outcomes(self, sids: np.ndarray) -> None:
        """The STA's outcomes of the situations ``sids`` not yet expanded."""
        missing = unique(sids[self.out_count.view[sids] < 0])
        bit = {e: 1 << i for i, e in enumerate(self.events)}
        for i in missing.tolist():
            pending, clock = self.situations[i]
            outs = self.sta.outcomes(pending, clock)
            self.out_start.data[i] = self.out_occ.size
            self.out_count.data[i] = len(outs)
            self.out_occ.extend([sum(bit[e] for e in o.occurred) for o in outs])
            self.out_prob.extend([o.probability for o in outs])
            self.out_next.extend(
                [-1 if o.clock == TRUNCATED else self.situation(o.pending, o.clock) for o in outs]
            )

    # ---------------------------------------------------------------- automaton
    def step(self, q: np.ndarray, letter: np.ndarray) -> np.ndarray:
        """``delta(q, letter)`` coded: the next state, or -1 (accepting) / -2 (rejecting)."""
        return self._delta((q << len(self.atoms)) | letter)

    def _new_steps(self, keys: np.ndarray) -> np.ndarray:
        dta, names, n = self.dta, self.dta.atoms, len(self.atoms)
        out = np.empty(keys.size, dtype=np.int64)
        for i, key in enumerate(keys.tolist()):
            word = frozenset(a for j, a in enumerate(names) if key >> j & 1)
            nxt = dta.step(key >> n, word)
            out[i] = -1 if nxt == dta.accepting else -2 if nxt == dta.rejecting else nxt
        return out


# Peak bytes of the construction, measured with experiments/bench_product.py on builds
# of 0.3-3.5M states (tracemalloc, numpy's buffers included): about 30 bytes per
# transition (the matrix, the batches' rows, the merge) and 80 per state (the index at
# load 1/4-1/2, the keys, the rows per choice); rounded up.
BYTES_PER_TRANSITION = 32
BYTES_PER_STATE = 96


def default_max_memory() -> int:
    """Half the machine's physical memory, in bytes (8 GiB if the system cannot say)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2
    except (AttributeError, ValueError, OSError):
        return 8 << 30


@dataclass(frozen=True, slots=True)
class SizeEstimate:
    """An upper bound on the product's states from its factors, before anything is built.

    ``states = game_states * automaton_states * situations + 3``: every ordinary product
    state is a game state, a non-absorbing automaton state and a situation (the pending
    events and a clock value at most ``cap(pending)``), plus the three absorbing states.
    ``game_states`` is None (and so is ``states``) for a game that does not say how many
    states it has (an ``n_states`` attribute).
    """

    game_states: int | None
    automaton_states: int
    situations: int

    @property
    def states(self) -> int | None:
        if self.game_states is None:
            return None
        return self.game_states * self.automaton_states * self.situations + 3

    def __str__(self) -> str:
        game = "?" if self.game_states is None else f"{self.game_states:,}"
        total = "unknown" if self.states is None else f"{self.states:,}"
        return (
            f"at most {total} states from the factors: {game} game states x "
            f"{self.automaton_states:,} automaton states x {self.situations:,} event "
            "situations (pending events, clock)"
        )


def estimate_size(game: Game[Any], sta: STA) -> SizeEstimate:
    """:class:`SizeEstimate` of ``product(game, sta)``, in time linear in the events.

    The situations are counted exactly: with the events' caps sorted,
    ``c_0 <= ... <= c_{k-1}``, the pending sets whose largest cap is ``c_i`` (ties broken
    by the order) are ``2^i``, each with clock values ``0..c_i``; the empty set has one.
    """
    dta = sta.dta
    automaton = dta.n_states - (dta.accepting is not None) - (dta.rejecting is not None)
    caps = sorted(c.cap for c in sta.clocks.values())
    situations = 1 + sum((1 << i) * (c + 1) for i, c in enumerate(caps))
    n = getattr(game, "n_states", None)
    game_states = n if isinstance(n, int) and not isinstance(n, bool) and n >= 0 else None
    return SizeEstimate(game_states, max(automaton, 0), situations)


def _check_alphabet(game: Game[Any], sta: STA) -> None:
    props = frozenset(game.proposition_names)
    unknown = sorted(set(sta.dta.atoms) - props - sta.events)
    if unknown:
        raise ValueError(
            f"proposition {unknown[0]!r} of the formula is neither a proposition of the game "
            f"({', '.join(sorted(props)) or 'none'}) nor an event "
            f"({', '.join(sorted(sta.events)) or 'none'})"
        )
    lawless = sorted(frozenset(getattr(game, "event_names", ())) - sta.events)
    if lawless:
        raise ValueError(f"the game reacts to event {lawless[0]!r}, which has no distribution")


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

    Raises ``ValueError`` when the automaton reads a proposition that is neither a
    proposition of the game nor an event of the STA (it could never be true, so the
    answer would be a silent 0), or when the game reacts to events (``event_names``)
    the STA gives no distribution.
    """
    _check_alphabet(game, sta)
    budget = _Budget(
        max_states,
        default_max_memory() if max_memory is None else max_memory,
        estimate_size(game, sta),
    )
    log.info("product: %s", budget.estimate)
    f = _Layers(game, sta)
    states = _Found(f, budget)
    g0 = f.game_state(game.initial)
    f.flush()
    q0 = f.step(np.array([sta.dta.initial]), f.props.view[[g0]])
    sid0 = f.situation(sta.events, 0)
    initial = int(states.intern(q0 if q0[0] < 0 else f.key(g0, q0, sid0))[0])

    chunks: list[tuple[np.ndarray, ...]] = []  # per batch: cols, vals, row lengths, actions
    state_choices = _Grow(np.int64)
    bar = None if progress is False else tqdm(
        total=None, unit=" states", disable=None if progress is None else not progress,
        leave=False, mininterval=0.5, desc="product",
    )
    head, batch = 0, 256
    while head < states.keys.size:
        keys = states.keys.view[head : head + batch].copy()
        chunk, n_entries = _expand(f, keys, head, states.intern)
        chunks.append(chunk)
        state_choices.extend(chunk[4])
        budget.expanded += keys.size
        budget.transitions += chunk[0].size
        if bar is not None:
            bar.update(keys.size)
        head += keys.size
        batch = int(np.clip(_BATCH_ENTRIES * keys.size // max(n_entries, 1), 16, 1 << 20))
    if bar is not None:
        bar.close()
    keys = states.keys.view.copy()
    del states  # the index is not needed any more: free it before the matrix is assembled
    return _assemble(f, chunks, state_choices.view, keys, initial)


@dataclass(slots=True)
class _Budget:
    """The limits of one build and what the build has used so far."""

    max_states: int
    max_memory: int
    estimate: SizeEstimate
    expanded: int = 0  # states whose rows are built
    transitions: int = 0  # their transitions

    def check(self, states: int) -> None:
        """Raise :class:`ProductTooLarge` if ``states`` states would exceed a budget."""
        if states > _MAX_INDEX:  # the matrix's column indices are int32
            raise ProductTooLarge(
                f"the product has more than {_MAX_INDEX:,} states ({self.estimate}), more "
                "than an MDP can index; loosen epsilon or shrink the model"
            )
        if states > self.max_states:
            raise ProductTooLarge(
                f"the product has more than {self.max_states:,} reachable states "
                f"({states:,} found; {self.estimate}); raise max_states, loosen epsilon, "
                "or shrink the model"
            )
        per_state = self.transitions / self.expanded if self.expanded else 0.0
        need = states * (BYTES_PER_STATE + per_state * BYTES_PER_TRANSITION)
        if need > self.max_memory:
            raise ProductTooLarge(
                f"the product would need about {_bytes(need)}, more than max_memory = "
                f"{_bytes(self.max_memory)} ({states:,} states found, {per_state:.1f} "
                f"transitions each, {BYTES_PER_STATE} bytes per state and "
                f"{BYTES_PER_TRANSITION} per transition); raise max_memory, loosen "
                "epsilon, or shrink the model"
            )


def _bytes(n: float) -> str:
    for unit, size in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= size:
            return f"{n / size:.1f} {unit}"
    return f"{n:.0f} bytes"


class _Found:
    """The product states found so far: their keys in the order found, and an index."""

    def __init__(self, f: _Layers, budget: _Budget) -> None:
        self.f, self.budget = f, budget
        self.index = _Index()
        self.keys = _Grow(np.int64)  # per state: its key (>= 0) or absorbing code (< 0)

    def intern(self, keys: np.ndarray) -> np.ndarray:
        """Product state ids of ``keys``, new ones numbered in order of first occurrence.
        The budget is checked before the new states are stored."""
        uniq, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
        ids = self.index.find(uniq)
        new = np.flatnonzero(ids < 0)
        if new.size:
            n = self.keys.size
            self.budget.check(n + new.size)
            new = new[np.argsort(first[new], kind="stable")]
            ids[new] = np.arange(n, n + new.size)
            self.index.insert(uniq[new], ids[new])
            self.keys.extend(uniq[new])
        return ids[inverse]


def _expand(
    f: _Layers, keys: np.ndarray, first_id: int, intern: Any
) -> tuple[tuple[np.ndarray, ...], int]:
    """The rows of the product states ``keys`` (ids ``first_id, first_id + 1, ...``).

    Returns (cols, vals, row lengths, choice actions, choices per state) and the number
    of entries before merging (to size the next batch).
    """
    ordinary = keys >= 0
    g, q, sid = f.unkey(keys[ordinary])
    f.ensure_actions(g)
    f.ensure_outcomes(sid)
    # choices: one per (state, action slot)
    n_act = f.act_count.view[g]
    c_state = np.repeat(np.arange(g.size), n_act)
    c_slot = f.act_start.view[g][c_state] + _ranks(n_act)
    # pairs: one per (choice, event outcome)
    c_sid = sid[c_state]
    n_out = f.out_count.view[c_sid]
    p_choice = np.repeat(np.arange(c_slot.size), n_out)
    p_out = f.out_start.view[c_sid][p_choice] + _ranks(n_out)
    p_occ = f.out_occ.view[p_out]
    p_next = f.out_next.view[p_out]
    p_row = np.zeros(p_choice.size, dtype=np.int64)  # row 0: crossed a truncation point
    alive = p_next >= 0
    p_row[alive] = f.rows(c_slot[p_choice[alive]], p_occ[alive])
    # entries: one per (pair, game successor)
    n_succ = f.row_len.view[p_row]
    e_pair = np.repeat(np.arange(p_choice.size), n_succ)
    e_at = f.row_start.view[p_row][e_pair] + _ranks(n_succ)
    vals = f.out_prob.view[p_out][e_pair] * f.row_prob.view[e_at]
    e_key = np.full(e_pair.size, _CODE[Absorbing.TRUNCATED], dtype=np.int64)
    moving = alive[e_pair]
    g2 = f.row_succ.view[e_at[moving]]
    e_pm = e_pair[moving]
    f.flush()
    q2 = f.step(q[c_state[p_choice[e_pm]]], f.props.view[g2] | f.occ_letter(p_occ[e_pm]))
    e_key[moving] = np.where(q2 < 0, q2, f.key(g2, q2, p_next[e_pm]))
    cols = intern(e_key).astype(np.int32)
    e_choice = p_choice[e_pair]
    cols, vals, row_len = _merge(e_choice, cols, vals, c_slot.size)
    actions = f.slot_aid.view[c_slot]
    choices = np.ones(keys.size, dtype=np.int64)
    choices[ordinary] = n_act
    # the absorbing states of the batch (at most three in the whole product): one
    # self-loop each, inserted where their state falls in the order
    for i in np.flatnonzero(~ordinary).tolist():
        before = int(np.count_nonzero(ordinary[:i]))
        at_choice = int(n_act[:before].sum())
        at_entry = int(row_len[:at_choice].sum())
        cols = np.insert(cols, at_entry, first_id + i)
        vals = np.insert(vals, at_entry, 1.0)
        row_len = np.insert(row_len, at_choice, 1)
        actions = np.insert(actions, at_choice, ABSORB)
        n_act = np.insert(n_act, before, 1)
        ordinary = ordinary.copy()
        ordinary[i] = True
    return (cols, vals, row_len.astype(np.int32), actions.astype(np.int32), choices), int(
        e_key.size
    )


def _ranks(counts: np.ndarray) -> np.ndarray:
    """``0 .. counts[i] - 1`` for each ``i``, concatenated."""
    total = int(counts.sum())
    starts = np.cumsum(counts) - counts
    return np.arange(total, dtype=np.int64) - np.repeat(starts, counts)


def _merge(
    choice: np.ndarray, cols: np.ndarray, vals: np.ndarray, n_choices: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sum the entries of one choice that go to one state, in the order they come (so the
    sums are bit for bit those of a loop), keeping each row's first-occurrence order.
    Returns the merged cols, vals and the length of each choice's row."""
    key = choice * (int(cols.max(initial=0)) + 1) + cols
    order = np.argsort(key, kind="stable")
    sk = key[order]
    start = np.ones(sk.size, dtype=bool)
    start[1:] = sk[1:] != sk[:-1]
    if start.all():
        return cols, vals, np.bincount(choice, minlength=n_choices)
    group = np.cumsum(start) - 1
    heads = np.flatnonzero(start)
    rank = np.arange(sk.size) - heads[group]
    sv = vals[order]
    total = np.zeros(heads.size)
    for r in range(int(rank.max()) + 1):  # a handful of rounds: summation order kept
        at = rank == r
        total[group[at]] += sv[at]
    first = order[heads]  # each group's first entry in stream order
    keep = np.argsort(first, kind="stable")
    kept = first[keep]
    return cols[kept], total[keep], np.bincount(choice[kept], minlength=n_choices)


def _concatenate(parts: list[Any], dtype: Any) -> np.ndarray:
    """``np.concatenate(parts)``, freeing each part once copied (peak: the result plus
    one part, not twice the result)."""
    out = np.empty(sum(p.size for p in parts), dtype=dtype)
    at = 0
    for i, part in enumerate(parts):
        out[at : at + part.size] = part
        at += part.size
        parts[i] = None
    return out


def _assemble(
    f: _Layers,
    chunks: list[tuple[np.ndarray, ...]],
    state_choices: np.ndarray,
    keys: np.ndarray,
    initial: int,
) -> MDP:
    """The MDP from the batches' rows, with a record per state."""
    columns = [list(c) for c in zip(*chunks, strict=True)]
    chunks.clear()
    cols = _concatenate(columns[0], np.int32)
    vals = _concatenate(columns[1], np.float64)
    row_len = _concatenate(columns[2], np.int64)
    actions = _concatenate(columns[3], np.int32)
    indptr = np.zeros(row_len.size + 1, dtype=np.int64)
    np.cumsum(row_len, out=indptr[1:])
    del row_len
    # action ids in order of first use, as names
    used = actions >= 0
    uniq, first = np.unique(actions[used], return_index=True)
    order = uniq[np.argsort(first)]
    remap = np.full(max(len(f.action_id), 1), -1, dtype=np.int32)
    remap[order] = np.arange(order.size, dtype=np.int32)
    choice_actions = np.full(actions.size, ABSORB, dtype=np.int32)
    choice_actions[used] = remap[actions[used]]
    by_id = {i: a for a, i in f.action_id.items()}
    kind = np.zeros(keys.size, dtype=np.int8)
    for code, k in _KIND.items():
        kind[keys == code] = k
    n = keys.size
    matrix = sp.csr_array((vals, cols, indptr), shape=(actions.size, n))
    row_groups = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(state_choices, out=row_groups[1:])
    mdp = MDP(
        matrix=matrix,
        row_groups=row_groups,
        choice_actions=choice_actions,
        action_names=tuple(by_id[int(i)] for i in order),
        initial=initial,
        target=kind == 1,
        sink=kind == 2,
        truncated=kind == 3,
        # the MDP's field is typed as a tuple; the lazy sequence answers len, [i] and
        # iteration as a tuple would
        states=ProductStates(keys, f.game_states, f.situations, f.n_q, f.n_sit),
    )
    log.info(
        "product: %d states, %d choices, %d transitions", n, mdp.n_choices, mdp.n_transitions
    )
    return mdp


class ProductStates(Sequence[Hashable]):
    """The records of a product's states, made on demand from their integer codes.

    Item ``i`` is a :class:`ProductState` or an :class:`Absorbing` member; a million
    records would cost more time and memory than the rest of the construction, and most
    are never looked at.  :meth:`position` maps a record back to its state index.
    """

    __slots__ = ("_keys", "_games", "_situations", "_n_q", "_n_sit", "_sorted", "_where")

    def __init__(
        self,
        keys: np.ndarray,
        games: list[Hashable],
        situations: list[tuple[frozenset[str], int]],
        n_q: int,
        n_sit: int,
    ) -> None:
        self._keys = keys
        self._keys.flags.writeable = False
        self._games, self._situations = games, situations
        self._n_q, self._n_sit = n_q, n_sit
        self._sorted: np.ndarray | None = None
        self._where: tuple[dict[Hashable, int], dict[tuple[frozenset[str], int], int]] | None
        self._where = None

    def __len__(self) -> int:
        return int(self._keys.size)

    def _record(self, key: int) -> Hashable:
        if key < 0:
            return _ABSORBING[key]
        rest, sid = divmod(key, self._n_sit)
        g, q = divmod(rest, self._n_q)
        pending, clock = self._situations[sid]
        return ProductState(self._games[g], q, pending, clock)

    @overload
    def __getitem__(self, i: int) -> Hashable: ...
    @overload
    def __getitem__(self, i: slice) -> tuple[Hashable, ...]: ...
    def __getitem__(self, i: int | slice) -> Hashable | tuple[Hashable, ...]:
        if isinstance(i, slice):
            return tuple(self._record(k) for k in self._keys[i].tolist())
        return self._record(int(self._keys[i]))

    def __iter__(self) -> Iterator[Hashable]:
        return (self._record(k) for k in self._keys.tolist())

    def __eq__(self, other: object) -> bool:
        if isinstance(other, ProductStates | tuple | list):
            return len(self) == len(other) and all(a == b for a, b in zip(self, other, strict=True))
        return NotImplemented

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return f"ProductStates(<{len(self)} states>)"

    def __contains__(self, state: object) -> bool:
        return self.position(state) is not None

    def index(self, state: Any, start: int = 0, stop: int | None = None) -> int:
        """The index of ``state`` (its record) in ``[start, stop)``; ValueError if none."""
        i = self.position(state)
        if i is None or i < start or (stop is not None and i >= stop):
            raise ValueError(f"{state!r} is not a state of this product")
        return i

    def distinct_factors(self) -> tuple[int, int, int, int, int]:
        """Ordinary states, and the distinct game states, automaton states, pending sets
        and clock values among them."""
        keys = self._keys[self._keys >= 0]
        rest, sid = np.divmod(keys, self._n_sit)
        g, q = np.divmod(rest, self._n_q)
        sits = [self._situations[i] for i in unique(sid).tolist()]
        return (
            int(keys.size),
            int(unique(g).size),
            int(unique(q).size),
            len({p for p, _ in sits}),
            len({c for _, c in sits}),
        )

    def automaton_states(self) -> np.ndarray:
        """``(n_states,)`` int64: the automaton state of each state, -1 for the absorbing
        ones (from the integer codes, no records made)."""
        keys = self._keys
        out = np.full(keys.size, -1, dtype=np.int64)
        ordinary = keys >= 0
        out[ordinary] = (keys[ordinary] // self._n_sit) % self._n_q
        return out

    def position(self, state: object) -> int | None:
        """The index of the state whose record is ``state``, None if there is none."""
        if isinstance(state, Absorbing):
            key = _CODE[state]
        elif isinstance(state, ProductState):
            if self._where is None:
                self._where = (
                    {s: i for i, s in enumerate(self._games)},
                    {s: i for i, s in enumerate(self._situations)},
                )
            games, sits = self._where
            g = games.get(state.game)
            sid = sits.get((state.pending, state.clock))
            if g is None or sid is None or not 0 <= state.automaton < self._n_q:
                return None
            key = (g * self._n_q + state.automaton) * self._n_sit + sid
        else:
            return None
        if self._sorted is None:
            self._sorted = np.argsort(self._keys, kind="stable")
        at = int(np.searchsorted(self._keys, key, sorter=self._sorted))
        if at < self._sorted.size and self._keys[self._sorted[at]] == key:
            return int(self._sorted[at])
        return None


def component_counts(mdp: MDP) -> Mapping[str, int]:
    """Sizes for people: states by kind, distinct game states, automaton states, pending
    sets and clock values among the ordinary states."""
    states = mdp.states
    if isinstance(states, ProductStates):  # from the integer codes, no records made
        distinct = states.distinct_factors()
    else:
        ordinary = [s for s in states if isinstance(s, ProductState)]
        distinct = (
            len(ordinary),
            len({s.game for s in ordinary}),
            len({s.automaton for s in ordinary}),
            len({s.pending for s in ordinary}),
            len({s.clock for s in ordinary}),
        )
    return {
        "states": mdp.n_states,
        "choices": mdp.n_choices,
        "transitions": mdp.n_transitions,
        "ordinary_states": distinct[0],
        "target_states": int(mdp.target.sum()),
        "sink_states": int(mdp.sink.sum()),
        "truncated_states": int(mdp.truncated.sum()),
        "game_states": distinct[1],
        "automaton_states": distinct[2],
        "event_situations": distinct[3],
        "clock_values": distinct[4],
    }
