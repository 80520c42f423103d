"""The factors of the product, each asked once and kept as integer arrays.

The game is asked once per (state, action, events of the step), the STA once per
situation (pending events, clock), the automaton once per (state, letter); the answers
are numbered and stored in arrays that :mod:`mitld_lp.product.build` joins for a whole
batch of product states at a time.  A world that is already a table
(:mod:`mitld_lp.worlds.table`: a PRISM program) is read whole instead, by array
operations: its states are the game states in its own numbering, its choices the action
slots, its rows the successor rows; nothing is asked of it state by state.
"""

from __future__ import annotations

from collections.abc import Hashable
from typing import Any

import numpy as np

from mitld_lp.automata.sta import STA, TRUNCATED
from mitld_lp.product.budget import ProductTooLarge
from mitld_lp.product.states import CODE, Absorbing, KeyCodec
from mitld_lp.util.arrays import Grow, Memo, unique
from mitld_lp.worlds.game import Game, GameError, WorldMembers
from mitld_lp.worlds.successors import (
    as_probabilities,
    distribution_fault,
    distribution_faults,
    place,
)
from mitld_lp.worlds.table import LateNames, WorldTable, table_of

__all__ = ["Layers"]

_CHECK_ROWS = 4096  # successor rows checked together (numpy's cost per call amortised)
_ROW_ARRAYS = ("props", "act_start", "act_count", "slot_aid", "row_start", "row_len",
               "row_succ", "row_prob", "row_asked", "out_start", "out_count", "out_occ",
               "out_prob", "out_next", "out_branch", "band_start", "band_count", "band_lo",
               "band_hi", "band_event", "_faulty")
"""The arrays :meth:`Layers.release` drops once every row is expanded and checked."""


class Layers:
    """The factors of the product, each expanded once and kept as integer arrays.

    * the game: states interned as ``g``; per ``g`` its action slots (``act_start[g]``
      ``.. + act_count[g]`` index ``slot_action``) and its propositions as a bit mask
      over the automaton's atoms; per (slot, event outcome) one successor row
      (``row_start``/``row_len`` into ``row_succ``/``row_prob``; ``row_asked``: the
      memo key it was first asked for), row ``cut_row`` (0; after the rows of a
      table) standing for "the outcome crossed a truncation point"; every row is checked
      to be a distribution (:meth:`check_rows`);
    * the events: situations ``(pending, clock)`` interned as ``sid``; per ``sid`` its
      outcomes (``out_*``: the events that happened as a bit mask over the STA's events,
      the probability, the next situation or -1 when truncated);
    * the automaton: ``delta[(q << A) | letter]`` with ``letter`` a bit mask over the
      ``A`` atoms, coded as the next state or an absorbing code.
    """

    def __init__(
        self, game: Game[Any], members: WorldMembers, sta: STA, robust: bool = False
    ) -> None:
        self.game, self.sta, self.dta = game, sta, sta.dta
        self.robust = robust
        self.ignores_events = members.ignores_events
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
        self.props = Grow(np.int64)
        self.act_start = Grow(np.int64)
        self.act_count = Grow(np.int64)  # -1: actions not asked yet
        self.slot_action: list[str] = []  # per action slot: its name, game state, action id
        self.slot_owner: list[int] = []
        self.slot_aid = Grow(np.int64)
        self.late = False  # the table's choices named when first read (late_names)
        self.late_names: LateNames | None = None
        self.action_id: dict[str, int] = {}
        self._rows = Memo(self._new_rows)
        self.row_by_object: dict[int, tuple[Any, int]] = {}  # id(answer) -> (answer, row)
        self.row_start, self.row_len = Grow(np.int64), Grow(np.int64)
        self.row_succ, self.row_prob = Grow(np.int64), Grow(np.float64)
        self.row_asked = Grow(np.int64)
        self.row_start.extend([0])
        self.row_len.extend([1])
        self.row_succ.extend([-1])
        self.row_prob.extend([1.0])
        self.row_asked.extend([-1])
        self.rows_checked = 1
        self.cut_row = 0  # the row of an outcome that crossed a truncation point
        # events
        self.sid: dict[tuple[frozenset[str], int], int] = {}
        self.situations: list[tuple[frozenset[str], int]] = []
        self.out_start, self.out_count = Grow(np.int64), Grow(np.int64)
        self.single_outcome = True  # every situation expanded so far has one outcome
        self.out_occ, self.out_prob, self.out_next = (
            Grow(np.int64), Grow(np.float64), Grow(np.int64)
        )
        # robust: each outcome's branch, each situation's hazard intervals (band_*)
        self.out_branch = Grow(np.int64)
        self.band_start, self.band_count = Grow(np.int64), Grow(np.int64)
        self.band_lo, self.band_hi, self.band_event = (
            Grow(np.float64), Grow(np.float64), Grow(np.int64)
        )
        # product keys (KeyCodec); n_sit bounds the situations
        caps = max((c.cap for c in sta.clocks.values()), default=0)
        self.codec = KeyCodec(self.dta.n_states, n_occ * (caps + 1))
        # automaton
        self._delta = Memo(self._new_steps, self.dta.n_states << len(self.atoms))
        # a world that is a table: read whole (its rows are then one per robot choice)
        self.table: WorldTable | None = None
        self._faulty = np.zeros(0, dtype=np.int64)
        table = table_of(game)
        if table is not None and self.codec.fits(table.n_states):
            self._read_table(table)

    def _read_table(self, t: WorldTable) -> None:
        """Every game state's entries from the table at once: game state ``g`` is the
        table's state ``g``, action slot ``c`` its robot choice ``c``, row ``c`` that
        choice's successors, in the table's own arrays (the truncation row after them:
        its length alone is stored, its entry is never read).  The rows that are not
        distributions are found here (unless the table's rows were checked where it was
        made: :attr:`~mitld_lp.worlds.table.WorldTable.checked`), and refused when the
        product first reads one."""
        self.table = t
        self.game_states = t.states  # type: ignore[assignment]  # a sequence, not copied
        masks = np.array(
            [sum(1 << i for a, i in self.atoms.items() if a in labels) for labels in t.label_sets],
            dtype=np.int64,
        )
        self.props = Grow.of(masks[t.label_of])
        self.act_start = Grow.of(t.choices[:-1].astype(np.int64, copy=False))
        self.act_count = Grow.of(np.diff(t.choices).astype(np.int64, copy=False))
        self.action_id = {a: i for i, a in enumerate(t.action_names)}
        self.slot_aid = Grow.of(t.action_of)  # int32, as the MDP keeps them
        # choices named when first read: robot choice c's id is LATE + c (product.build)
        self.late = isinstance(t.action_names, LateNames)
        # the names a late-named table makes when first read: kept past release()
        self.late_names = t.action_names if self.late else None
        # row c: robot choice c, the table's own arrays (not copied); the truncation row
        # after them, its entry never read
        lengths = np.diff(t.branches).astype(np.int64, copy=False)
        self.cut_row = lengths.size
        self.row_start = Grow.of(t.branches.astype(np.int64, copy=False))
        self.row_len = Grow.of(np.concatenate((lengths, [1]), dtype=np.int64))
        self.row_succ = Grow.of(t.targets.astype(np.int64, copy=False))
        self.row_prob = Grow.of(t.probabilities.astype(np.float64, copy=False))
        if not t.checked:  # else every row was checked where the table was made
            self._faulty = distribution_faults(lengths, self.row_prob.view)
        self.rows_checked = self.row_len.size

    def release(self) -> None:
        """Drop the memos, whose bound methods refer back to this object (without them
        the layers are freed as soon as the build lets go of them, not at the next
        cyclic garbage collection), and every per-row, per-slot and per-outcome array:
        the world's rows read whole are int64 copies of the table's (8 bytes a world
        transition each for the successors and the starts), which the assembly of the
        matrix need not share its peak with.  What the assembly and the states' records
        still read stays: the action ids, the game states, the situations, the codec,
        the events."""
        del self._rows, self._delta
        for name in _ROW_ARRAYS:
            setattr(self, name, None)
        self.table = None
        self.gid, self.row_by_object, self.sid = {}, {}, {}
        self.slot_action, self.slot_owner = [], []

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
        if self.table is not None:  # the table's own numbering
            if s == self.table.states[self.table.initial]:
                return self.table.initial
            if not self.gid:
                self.gid = {x: i for i, x in enumerate(self.table.states)}
            return self.gid[s]
        g = self.gid.get(s)
        if g is None:
            g = len(self.game_states)
            if not self.codec.fits(g + 1):
                raise ProductTooLarge(
                    f"more than {g:,} game states with {self.codec.n_q} automaton states and "
                    f"{self.codec.n_sit:,} event situations: too many to number"
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
        if self.table is not None:  # every state's actions are in the table
            return
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

    def _add_rows(self, rows: list[tuple[tuple[Any, float], ...]], asked: list[int]) -> None:
        """Store successor rows (pairs ``(game state, probability)``) as rows of ``g``;
        ``asked``: the memo key of each.  Answers that are not pairs of a hashable state
        and a number are refused here; the probabilities are checked in
        :meth:`check_rows`.  Raises :class:`mitld_lp.worlds.game.GameError`."""
        gid = self.gid
        try:
            lengths = np.array([len(r) for r in rows], dtype=np.int64)
            probs = as_probabilities([p for r in rows for _, p in r])
            succ = [gid[s] if s in gid else self.game_state(s) for r in rows for s, _ in r]
        except (TypeError, ValueError):  # not pairs of a hashable state and a number?
            for row, key in zip(rows, asked, strict=True):
                why = distribution_fault(row)
                if why:
                    raise GameError(f"{self._place(key)}: {why}") from None
            raise  # no: an error of the world's own (its propositions)
        starts = np.cumsum(lengths) - lengths + self.row_succ.size
        self.row_start.extend(starts)
        self.row_len.extend(lengths)
        self.row_succ.extend(succ)
        self.row_prob.extend(probs)
        self.row_asked.extend(asked)
        if self.row_len.size - self.rows_checked >= _CHECK_ROWS:
            self.check_rows()

    def check_rows(self) -> None:
        """Check that the rows stored since the last call are distributions, all at once
        (:func:`mitld_lp.worlds.game.distribution_faults`); the build calls it once more at
        its end.  Raises :class:`mitld_lp.worlds.game.GameError` naming the state, action and
        events of the first row that is not."""
        first = self.rows_checked
        if first == self.row_len.size:
            return
        lengths = self.row_len.view[first:]
        probs = self.row_prob.view[int(self.row_start.view[first]) :]
        faults = distribution_faults(lengths, probs)
        if faults.size:
            i = first + int(faults[0])
            start = int(self.row_start.view[i])
            at = slice(start, start + int(self.row_len.view[i]))
            nexts = [self.game_states[g] for g in self.row_succ.view[at].tolist()]
            row = tuple(zip(nexts, self.row_prob.view[at].tolist(), strict=True))
            why = distribution_fault(row) or "not a distribution"
            raise GameError(f"{self._place(int(self.row_asked.view[i]))}: {why}")
        self.rows_checked = self.row_len.size

    def _place(self, key: int) -> str:
        """The state, action and events of a row's memo key, for messages."""
        t = self.table
        if t is not None:  # the key is the robot choice; its row ignores the events
            return place(t.states[t.owner(key)], t.action_names[int(t.action_of[key])])
        slot, o = (key, 0) if self.ignores_events else divmod(key, self.n_occ)
        events = () if self.ignores_events else self.occ_set(o)
        return place(self.game_states[self.slot_owner[slot]], self.slot_action[slot], events)

    def rows(self, slots: np.ndarray, occ: np.ndarray) -> np.ndarray:
        """The successor row of each (action slot, event outcome)."""
        if self.table is not None:  # one row per robot choice, whatever the events
            if self._faulty.size:
                self._refuse(slots)
            return slots
        if self.ignores_events:  # one row per slot, asked with no events
            return self._rows(slots)
        return self._rows(slots * self.n_occ + occ)

    def _refuse(self, slots: np.ndarray) -> None:
        """Raise :class:`GameError` for the first of the table's rows in ``slots`` that
        is not a distribution (if any)."""
        hit = np.intersect1d(slots, self._faulty)
        if hit.size:
            c = int(hit[0])
            assert self.table is not None
            lo, hi = int(self.table.branches[c]), int(self.table.branches[c + 1])
            nexts = [self.table.states[g] for g in self.table.targets[lo:hi].tolist()]
            row = tuple(zip(nexts, self.table.probabilities[lo:hi].tolist(), strict=True))
            why = distribution_fault(row) or "not a distribution"
            raise GameError(f"{self._place(c)}: {why}")

    def _new_rows(self, keys: np.ndarray) -> np.ndarray:
        """Ask the game once per (action slot, event outcome) ``keys``; a game that
        answers with the very same object for several of them, as a precomputed table
        does, gets one row for them."""
        new_rows: list[tuple[tuple[Any, float], ...]] = []
        asked: list[int] = []
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
                asked.append(key)
            out[i] = hit[1]
        if new_rows:
            self._add_rows(new_rows, asked)
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
            self.band_start.extend([0])
            self.band_count.extend([0])
        return i

    def ensure_outcomes(self, sids: np.ndarray) -> None:
        """The STA's outcomes of the situations ``sids`` not yet expanded
        (:attr:`single_outcome` stays true while each has one outcome)."""
        new = self.out_count.view[sids] < 0
        if not new.any():
            return
        missing = unique(sids[new])
        bit = {e: 1 << i for i, e in enumerate(self.events)}
        for i in missing.tolist():
            pending, clock = self.situations[i]
            if self.robust:
                outs, amb = self.sta.robust_outcomes(pending, clock)
                self.out_branch.extend([o.branch for o in outs])
                self.band_start.data[i] = self.band_lo.size
                self.band_count.data[i] = len(amb.events)
                self.band_lo.extend(amb.lo)
                self.band_hi.extend(amb.hi)
                self.band_event.extend([self.events.index(e) for e in amb.events])
            else:
                outs = self.sta.outcomes(pending, clock)
            self.out_start.data[i] = self.out_occ.size
            self.out_count.data[i] = len(outs)
            self.single_outcome &= len(outs) == 1
            self.out_occ.extend([sum(bit[e] for e in o.occurred) for o in outs])
            self.out_prob.extend([o.probability for o in outs])
            self.out_next.extend(
                [-1 if o.clock == TRUNCATED else self.situation(o.pending, o.clock) for o in outs]
            )

    # ---------------------------------------------------------------- automaton
    def step(self, q: np.ndarray, letter: np.ndarray) -> np.ndarray:
        """``delta(q, letter)`` coded: the next state, or the code of ``target`` (accepting)
        or ``sink`` (rejecting)."""
        return self._delta((q << len(self.atoms)) | letter)

    def _new_steps(self, keys: np.ndarray) -> np.ndarray:
        dta, names, n = self.dta, self.dta.atoms, len(self.atoms)
        accept, reject = CODE[Absorbing.TARGET], CODE[Absorbing.SINK]
        out = np.empty(keys.size, dtype=np.int64)
        for i, key in enumerate(keys.tolist()):
            word = frozenset(a for j, a in enumerate(names) if key >> j & 1)
            nxt = dta.step(key >> n, word)
            out[i] = accept if nxt == dta.accepting else reject if nxt == dta.rejecting else nxt
        return out
