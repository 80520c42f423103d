"""A breadth-first level of a table world's product in few NumPy calls.

The plain PRISM task (a world read whole as a :class:`~mitld_lp.worlds.table.WorldTable`,
no event, one situation, a task that is not robust) builds its product level by level;
a level of a thin frontier holds a few hundred states, so the time of a level is NumPy's
fixed cost per call, not the states.  :meth:`Plain.expand` is :func:`mitld_lp.product.
build._expand` for that case with the steps that do nothing there left out:

* a state's choices are contiguous in the table, and so are their rows: the entries of
  the level's states are gathered as one run per state (``branches[choices[g]]`` up to
  ``branches[choices[g + 1]]``), not per choice and then per row;
* the one situation has one outcome that crosses no truncation point: no pair, no
  outcome, no event letter;
* the automaton's steps from every ordinary automaton state on every label of the table
  are asked once, where its memo stays small (:data:`_MAX_STEPS`), so a level reads them
  by one gather (by the letter alone where one automaton state is ordinary, as in
  ``F goal``);
* a level's new states are numbered in ``intern`` by a minimum per key in the dense
  index (:meth:`mitld_lp.product.build._Found._add_dense`), not by two sorts (every
  world's levels use it);
* entries to one product state within one choice are merged (:func:`~mitld_lp.util.
  arrays.merge`) only where they can meet: at an absorbing state, or where a row of the
  table names one successor twice (checked once for the whole table).

The same arrays as :func:`~mitld_lp.product.build._expand`, bit for bit (the tests compare
the products built either way, and with one built by a breadth-first search state by
state); the budgets are checked where the old path checks them (the new states, in
``intern``, before they are stored; the memory per batch in the build's loop).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mitld_lp.product.layers import Layers
from mitld_lp.util.arrays import merge, unique
from mitld_lp.worlds.table import LATE

__all__ = ["Plain", "plain_table"]

_MAX_STEPS = 1 << 16
"""The automaton's steps are tabulated where its memo (automaton states times the
letters of its atoms) has at most this many entries."""


class Plain:
    """What :meth:`expand` reads of a table world's layers, made once per build (after
    its first level, which expands the one situation)."""

    __slots__ = ("late", "n_q", "shift", "scale", "steps", "step_bits", "only", "distinct",
                 "act_start", "act_count", "row_start", "row_len", "row_succ", "row_prob",
                 "props", "slot_aid", "step")

    def __init__(self, f: Layers) -> None:
        t = f.table
        assert t is not None
        n_q = f.codec.n_q
        self.n_q = n_q
        self.shift = n_q.bit_length() - 1 if n_q & (n_q - 1) == 0 else -1
        self.scale = float(f.out_prob.view[f.out_start.view[0]])  # the one outcome's (1.0)
        # a table's arrays are read whole and never grow: kept here as views (the build
        # lets go of this object before the layers are released)
        self.late = f.late
        self.act_start, self.act_count = f.act_start.view, f.act_count.view
        self.row_start, self.row_len = f.row_start.view, f.row_len.view
        self.row_succ, self.row_prob = f.row_succ.view, f.row_prob.view
        self.props, self.slot_aid = f.props.view, f.slot_aid.view
        self.step = f.step
        # every automaton step from every ordinary automaton state on every label of the
        # table, coded as Layers.step codes them, in the automaton's memo (a dense array)
        masks = unique(np.array(
            [sum(1 << i for a, i in f.atoms.items() if a in labels) for labels in t.label_sets],
            dtype=np.int64))
        self.step_bits = len(f.atoms)
        self.steps: np.ndarray | None = None
        self.only = -1  # the one ordinary automaton state, if there is one
        dta = f.dta
        live = np.array([s for s in range(n_q) if s not in (dta.accepting, dta.rejecting)],
                        dtype=np.int64)
        if (n_q << self.step_bits) <= _MAX_STEPS:  # a memo of 512 KB at most
            f.step(np.repeat(live, masks.size), np.tile(masks, live.size))
            table = f._delta.table
            if table is not None:
                self.steps = table
                if live.size == 1:  # its row of steps alone, read by the letter
                    self.only = int(live[0])
                    self.steps = table[self.only << self.step_bits:]
        self.distinct = _rows_distinct(t.targets, t.branches)

    def expand(self, keys: np.ndarray, intern: Any) -> tuple[tuple[np.ndarray, ...], int]:
        """The rows of the product states ``keys`` (all ordinary): as
        :func:`mitld_lp.product.build._expand` returns them."""
        n_q, shift = self.n_q, self.shift
        if self.only >= 0:  # every ordinary key is g * n_q + only
            g = keys >> shift if shift >= 0 else keys // n_q
            q = None
        elif shift >= 0:
            g, q = keys >> shift, keys & (n_q - 1)
        else:
            g, q = np.divmod(keys, n_q)
        c_lo = self.act_start[g]
        n_act = self.act_count[g]
        row_start = self.row_start
        e_lo = row_start[c_lo]
        n_ent = row_start[c_lo + n_act] - e_lo  # the state's entries: one run
        ends = n_ent.cumsum()
        n_e = int(ends[-1])
        e_at = np.arange(n_e) + (e_lo - ends + n_ent).repeat(n_ent)
        vals = self.row_prob[e_at]
        if self.scale != 1.0:
            vals = vals * self.scale
        g2 = self.row_succ[e_at]
        letter = self.props[g2]
        if q is None:  # (only with the steps tabulated)
            q2 = self.steps[letter]
        elif self.steps is not None:
            q2 = self.steps[(q.repeat(n_ent) << self.step_bits) | letter]
        else:
            q2 = self.step(q.repeat(n_ent), letter)
        ends_c = n_act.cumsum()
        n_c = int(ends_c[-1])
        c_slot = np.arange(n_c) + (c_lo - ends_c + n_act).repeat(n_act)
        n_succ = self.row_len[c_slot]
        absorbed = q2 < 0
        meet = bool(absorbed.any())
        moved = (g2 << shift if shift >= 0 else g2 * n_q) + q2
        if meet:
            moved = np.where(absorbed, q2, moved)
        cols = intern(moved).astype(np.int32)
        if meet or not self.distinct:
            e_choice = np.arange(n_c).repeat(n_succ)
            cols, vals, row_len = merge(e_choice, cols, vals, n_c)
        else:  # every entry of a choice goes to a state of its own
            row_len = n_succ
        actions = c_slot + LATE if self.late else self.slot_aid[c_slot]
        return (cols, vals, row_len.astype(np.int32), actions.astype(np.int32),
                n_act.astype(np.int32)), n_e


def plain_table(f: Layers) -> bool:
    """Whether :class:`Plain` builds ``f``'s levels: a table world read whole whose rows
    are all distributions, no event, one situation expanded with one outcome that
    crosses no truncation point, not robust."""
    if f.table is None or f.robust or f.events or f.codec.n_sit != 1 or f._faulty.size:
        return False
    if f.out_count.size == 0 or f.out_count.view[0] != 1:
        return False
    return bool(f.out_next.view[f.out_start.view[0]] >= 0)


def _rows_distinct(targets: np.ndarray, branches: np.ndarray) -> bool:
    """Whether no row ``targets[branches[c]:branches[c + 1]]`` names a state twice
    (checked as: every row strictly increasing, as Storm's sparse rows are; a row that
    is not counts as one that might repeat)."""
    if targets.size < 2:
        return True
    up = targets[1:] > targets[:-1]
    inner = branches[1:-1]
    inner = inner[(inner > 0) & (inner < targets.size)]
    up[inner - 1] = True  # a row's first entry follows another row's last
    return bool(up.all())
