"""The factors of the product, each asked once and kept as integer arrays.

The game is asked once per (state, action, events of the step), the STA once per
situation (pending events, clock), the automaton once per (state, letter); the answers
are numbered and stored in arrays that :mod:`mitld_lp.product.build` joins for a whole
batch of product states at a time.
"""

from __future__ import annotations

from collections.abc import Hashable
from typing import Any

import numpy as np

from mitld_lp.arrays import Grow, Memo, unique
from mitld_lp.automata.sta import STA, TRUNCATED
from mitld_lp.game import Game, WorldMembers
from mitld_lp.product.budget import ProductTooLarge
from mitld_lp.product.states import CODE, Absorbing, KeyCodec

__all__ = ["Layers"]


class Layers:
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

    def __init__(self, game: Game[Any], members: WorldMembers, sta: STA) -> None:
        self.game, self.sta, self.dta = game, sta, sta.dta
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
        self.action_id: dict[str, int] = {}
        self._rows = Memo(self._new_rows)
        self.row_by_object: dict[int, tuple[Any, int]] = {}  # id(answer) -> (answer, row)
        self.row_start, self.row_len = Grow(np.int64), Grow(np.int64)
        self.row_succ, self.row_prob = Grow(np.int64), Grow(np.float64)
        self.row_start.extend([0])
        self.row_len.extend([1])
        self.row_succ.extend([-1])
        self.row_prob.extend([1.0])
        # events
        self.sid: dict[tuple[frozenset[str], int], int] = {}
        self.situations: list[tuple[frozenset[str], int]] = []
        self.out_start, self.out_count = Grow(np.int64), Grow(np.int64)
        self.out_occ, self.out_prob, self.out_next = (
            Grow(np.int64), Grow(np.float64), Grow(np.int64)
        )
        # product keys (KeyCodec); n_sit bounds the situations
        caps = max((c.cap for c in sta.clocks.values()), default=0)
        self.codec = KeyCodec(self.dta.n_states, n_occ * (caps + 1))
        # automaton
        self._delta = Memo(self._new_steps, self.dta.n_states << len(self.atoms))

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
