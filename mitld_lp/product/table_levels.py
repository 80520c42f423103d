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

from mitld_lp.mdp import ABSORB
from mitld_lp.product.layers import Layers
from mitld_lp.product.states import CODE, Absorbing
from mitld_lp.util.arrays import merge, unique
from mitld_lp.worlds.table import LATE

__all__ = ["Plain", "compiled_wanted", "plain_table", "run_compiled"]

_MAX_STEPS = 1 << 16
"""The automaton's steps are tabulated where its memo (automaton states times the
letters of its atoms) has at most this many entries."""


class Plain:
    """What :meth:`expand` reads of a table world's layers, made once per build (after
    its first level, which expands the one situation)."""

    __slots__ = ("late", "n_q", "shift", "scale", "steps", "step_bits", "only", "distinct",
                 "act_start", "act_count", "row_start", "row_len", "row_succ", "row_prob",
                 "props", "slot_aid", "step", "table_steps", "batches")

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
        self.table_steps: np.ndarray | None = None  # every step, by (q << bits) | letter
        self.batches = 0  # levels' batches expanded by NumPy so far
        self.only = -1  # the one ordinary automaton state, if there is one
        dta = f.dta
        live = np.array([s for s in range(n_q) if s not in (dta.accepting, dta.rejecting)],
                        dtype=np.int64)
        if (n_q << self.step_bits) <= _MAX_STEPS:  # a memo of 512 KB at most
            f.step(np.repeat(live, masks.size), np.tile(masks, live.size))
            table = f._delta.table
            if table is not None:
                self.steps = self.table_steps = table
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


COMPILED = True
"""Whether the levels may go to the compiled loop (:mod:`mitld_lp.product.bfs_kernels`;
False: NumPy's batches only, for tests and measurements)."""

LOAD_SECONDS = 0.04
"""The compiled loop's load the first time in a process (the kernel loader's pieces and
the kernel linked; ``experiments/bench_product.py --prism``: 0.03-0.045 s)."""

BATCH_SECONDS, STATE_SECONDS = 75e-6, 0.08e-6
"""NumPy's levels: about 75 us of calls a batch whatever its size, and 0.08 us a state
(the same measurements: firewire_dl 3-600's 633 thin batches, csma 4-2's 600k states);
the compiled loop costs about 0.02 us a state."""

PAYS = 2.0
"""The compiled loop is loaded (not yet paid) where NumPy's levels still to come are
estimated at this many loads or more: it then saves at least one load, and an estimate
off by half still breaks even."""

COMPILED_MIN_STATES = int(PAYS * LOAD_SECONDS / STATE_SECONDS)
"""A world of this many states (a million) is estimated to pay from the first level."""

_SEEN = 32
"""NumPy's batches seen before the frontier's width is trusted for the estimate (a
breadth-first search's first levels are narrow however wide the later ones)."""

_CHUNK_STATES = 1 << 18
"""New states one call of the compiled loop may number before the budget is checked."""

_MIN_ENTRIES, _MAX_ENTRIES = 1 << 16, 1 << 22
"""The entries one call of the compiled loop has room for: as many as the transitions
so far, within these bounds (its buffers, 24 bytes an entry, at most about 100 MB)."""


def compiled_wanted(lean: Plain, n_world: int, expanded: int, queued: int) -> bool:
    """Whether the compiled loop should expand the levels from here, with ``expanded``
    states expanded so far of a world of ``n_world`` and ``queued`` found and not yet
    expanded: its load is paid already, or the levels still to come are estimated to
    cost NumPy :data:`PAYS` loads or more (from the world's states before the work; then,
    once :data:`_SEEN` batches have let the frontier grow, from the queue's length as the
    frontier's width, the states not yet expanded taken as the world's, while fewer
    than half the world's are: a thin frontier's batches each cost
    :data:`BATCH_SECONDS`)."""
    if not COMPILED or lean.table_steps is None:
        return False
    if n_world >= COMPILED_MIN_STATES:
        return True
    if lean.batches >= _SEEN and 2 * expanded < n_world:  # past half the world, the
        left = n_world - expanded  # states left may never be reached: a guess too wide
        if left / max(queued, 1) * BATCH_SECONDS + left * STATE_SECONDS >= PAYS * LOAD_SECONDS:
            return True
    from mitld_lp.util import kernel_loader

    return kernel_loader.compiled_paid()


def run_compiled(lean: Plain, found: Any, head: int, budget: Any,
                 n_keys: int) -> tuple[tuple[np.ndarray, ...], int, int] | None:
    """Expand the queue from ``head`` by the compiled loop: ``(chunk, states expanded,
    entries)`` as :meth:`Plain.expand` returns a batch (the states found numbered in
    ``found``'s keys and dense index), or None where it cannot run (numba missing, the
    index not a dense array of every key); the budget is counted and checked as the
    batched build checks it (states found past ``budget.max_states`` stop the loop
    before they are stored: the batched build then finds them and refuses)."""
    index = found.index
    if index.dense is None or n_keys > index.dense_limit:
        return None
    try:
        from mitld_lp.product import bfs_kernels
    except ImportError:  # numba missing: NumPy's batches
        return None
    if index.dense.size < n_keys:
        bigger = np.full(n_keys, -1, dtype=np.int32)
        bigger[: index.dense.size] = index.dense
        index.dense = bigger
    keys = found.keys
    size = max(_MIN_ENTRIES, min(budget.transitions, _MAX_ENTRIES))
    n_found = keys.size
    if keys.data.size < n_found + size:
        bigger = np.empty(max(2 * keys.data.size, n_found + size), dtype=keys.data.dtype)
        bigger[:n_found] = keys.data[:n_found]
        keys.data = bigger
    cap = min(n_found + _CHUNK_STATES, budget.max_states)
    cols = np.empty(size, dtype=np.int32)
    vals = np.empty(size, dtype=np.float64)
    row_len = np.empty(size, dtype=np.int32)
    actions = np.empty(size, dtype=np.int32)
    choices = np.empty(size, dtype=np.int32)
    out = np.zeros(5, dtype=np.int64)
    bfs_kernels.table_levels(
        keys.data, n_found, head, 1 << 62, cap, index.dense,
        -CODE[Absorbing.TRUNCATED], lean.act_start, lean.act_count, lean.row_start,
        lean.row_succ, lean.row_prob, lean.props, lean.table_steps, lean.step_bits,
        lean.n_q, lean.scale, lean.distinct, lean.slot_aid, LATE if lean.late else 0,
        ABSORB, cols, vals, row_len, actions, choices, out)
    _, n_found, ne, nc, ns = (int(x) for x in out)
    keys.size = index.size = n_found
    if ns == 0:
        return None
    budget.expanded += ns
    budget.transitions += ne
    budget.check(n_found)
    parts = [cols[:ne], vals[:ne], row_len[:nc], actions[:nc], choices[:ns]]
    chunk = tuple(p.copy() if 2 * p.size < size else p for p in parts)
    return chunk, ns, ne
