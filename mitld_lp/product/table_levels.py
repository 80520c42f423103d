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
from mitld_lp.product.budget import BYTES_PER_STATE, BYTES_PER_TRANSITION
from mitld_lp.product.layers import Layers
from mitld_lp.product.states import CODE, Absorbing
from mitld_lp.util.arrays import merge, unique
from mitld_lp.worlds.table import LATE

__all__ = ["Plain", "compiled_wanted", "load_pays", "loop_cached", "plain_table", "run_compiled"]

_MAX_STEPS = 1 << 16
"""The automaton's steps are tabulated where its memo (automaton states times the
letters of its atoms) has at most this many entries."""


class Plain:
    """What :meth:`expand` reads of a table world's layers, made once per build (after
    its first level, which expands the one situation)."""

    __slots__ = ("late", "n_q", "shift", "scale", "steps", "step_bits", "only", "distinct",
                 "act_start", "act_count", "row_start", "row_len", "row_succ", "row_prob",
                 "props", "slot_aid", "step", "table_steps", "batches", "widest", "room")

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
        self.widest = -1  # a bound on one state's entries (the loop's, when it runs)
        self.room = 0  # the entries the loop's last call had room for
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

LOAD_SECONDS = 0.02
"""The compiled loop's load the first time in a process, from a warm cache: the kernel
loader's pieces and the kernel linked by its own ELF linker (``experiments/numba_load.py``:
0.019-0.020 s; it was 0.03-0.045 s through llvmlite)."""

LOAD_BYTES = 3 << 20
"""What that load adds to the process's resident size: numba's helpers and the linked
code, about 3 MB (``numba_load.py``: 2.9-3.0 MB; it was 46-53 MB with llvmlite's LLVM).
None of it is traced by tracemalloc, all of it is in the synthesis's resident peak
(``bench_qvbs.py``'s bytes per transition)."""

COLD_LOAD_SECONDS, COLD_LOAD_BYTES = 0.04, 48 << 20
"""The figures the rule uses where the load is not known to be that cheap: the loop's
cache file is missing (numba would compile it) or the loader is off
(``MITLD_LP_KERNEL_LOADER=0``: numba's import).  They are the rule's figures from before
the ELF linker, so that a cold cache or the loader off loads the loop exactly where it
did then (a product of a million states and more still to come) and never makes a
smaller one pay numba's compile."""

BATCH_SECONDS, STATE_SECONDS = 75e-6, 0.08e-6
"""NumPy's levels: about 75 us of calls a batch whatever its size, and 0.08 us a state
(the same measurements: firewire_dl 3-600's 633 thin batches, csma 4-2's 600k states);
the compiled loop costs about 0.02 us a state."""

PAYS = 2.0
"""The compiled loop is loaded (not yet paid) where NumPy's levels still to come are
estimated at this many loads or more: it then saves at least one load, and an estimate
off by half still breaks even."""

LOAD_SHARE = 0.2
"""... and where the load's resident bytes are at most this share of the product's own
(its states still to come at the build budget's bytes a state and a transition).  With
the ELF linker's 3 MB (:data:`LOAD_BYTES`) that admits a product of about 110,000 states
and more (some 15 bytes a transition at most on a synthesis peak of ~100-240); with
llvmlite's 48 MiB (:data:`COLD_LOAD_BYTES`) it was 0.02 (2 bytes a transition), which
kept the loop to processes whose load was paid already on every QVBS instance this
project runs (at most 2 million states): the cold rule keeps that share
(:data:`COLD_LOAD_SHARE`)."""

COLD_LOAD_SHARE = 0.02

COMPILED_MIN_STATES = int(PAYS * LOAD_SECONDS / STATE_SECONDS)
"""States still to come (half a million) that pay a warm load by their per-state cost
alone: trusted before :data:`_SEEN` batches have shown the frontier's width."""

COLD_MIN_STATES = int(PAYS * COLD_LOAD_SECONDS / STATE_SECONDS)
"""The same on a cold cache or with the loader off (a million, the old rule's)."""

_SEEN = 32
"""NumPy's batches seen before the frontier's width is trusted for the estimate (a
breadth-first search's first levels are narrow however wide the later ones)."""

_CHUNK_STATES = 1 << 18
"""New states one call of the compiled loop may number before the budget is checked."""

_MIN_ENTRIES, _MAX_ENTRIES = 1 << 12, 1 << 22
"""The entries one call of the compiled loop has room for, at least and at most.  In
between, the room is the frontier's states times a bound on one state's entries (the
world's longest row times its most choices of a state), doubled after a call that
filled it, and never more than :data:`_SHARE`-th of the transitions built so far."""

_SHARE = 8
"""The buffers (24 bytes an entry) and the rows copied out of them (16) stay under 5
bytes a transition of the product so far, on top of the batches' rows it holds: the
matrix's assembly, which holds those rows twice, stays the build's peak.  (Half the
transitions, 20 bytes a transition, raised csma 4-2's traced peak by 10.6.)"""

_SPARSE = 8
"""The dense index grows for the loop, as for NumPy's batches
(:class:`mitld_lp.util.arrays.Index`), while it holds at most this many slots per state
found (past 64K slots); past that, NumPy's batches take over and the index turns into a
hash table."""


def compiled_wanted(lean: Plain, n_world: int, expanded: int, queued: int,
                    per_state: float = 1.0) -> bool:
    """Whether the compiled loop should expand the levels from here, with ``expanded``
    states expanded so far of a world of ``n_world``, ``queued`` found and not yet
    expanded, and ``per_state`` transitions a state so far: its load is paid already
    (:func:`~mitld_lp.util.kernel_loader.compiled_paid`), or it is estimated to pay for
    itself in time and memory both.  Time: NumPy's levels still to come estimated at
    :data:`PAYS` loads or more, from the states not yet expanded taken as the world's
    (at :data:`STATE_SECONDS` each), and once :data:`_SEEN` batches have let the
    frontier grow, the queue's length as the frontier's width (a batch each
    :data:`BATCH_SECONDS`), while fewer than half the world's states are expanded (past
    that, the states left may never be reached).  Memory: the load's
    :data:`LOAD_BYTES` at most :data:`LOAD_SHARE` of the product still to come."""
    if not COMPILED or lean.table_steps is None:
        return False
    from mitld_lp.util import kernel_loader

    if kernel_loader.compiled_paid():
        return True
    warm = loop_cached()
    return load_pays(n_world - expanded, expanded, queued, lean.batches, per_state,
                     *((LOAD_SECONDS, LOAD_BYTES, LOAD_SHARE, COMPILED_MIN_STATES) if warm
                       else (COLD_LOAD_SECONDS, COLD_LOAD_BYTES, COLD_LOAD_SHARE,
                             COLD_MIN_STATES)))


def loop_cached() -> bool:
    """Whether the compiled loop's load is the cheap one: the kernel loader on and a
    cache file of the loop (:func:`~mitld_lp.util.kernel_loader.cached`); False without
    numba.  Looked up once a process (the gate asks it before each NumPy batch; a file
    this process writes comes with the load paid)."""
    if not _CACHED:
        from mitld_lp.util import kernel_loader

        _CACHED.append(kernel_loader.module_cached("mitld_lp.product.bfs_kernels",
                                                   "table_levels"))
    return _CACHED[0]


_CACHED: list[bool] = []


def load_pays(left: int, expanded: int, queued: int, batches: int, per_state: float,
              load_seconds: float, load_bytes: int, share: float, min_states: int) -> bool:
    """:func:`compiled_wanted`'s rule where the load is not paid, for a load of
    ``load_seconds`` and ``load_bytes`` (at most ``share`` of the product's bytes still
    to come; ``min_states`` states still to come pay it by their per-state cost alone):
    ``left`` states still to come of the world's
    (``expanded`` so far), ``queued`` in the queue, after ``batches`` NumPy batches."""
    if 2 * expanded >= left + expanded:
        return False
    if load_bytes > share * left * (BYTES_PER_STATE + per_state * BYTES_PER_TRANSITION):
        return False
    if left >= min_states:  # by their per-state cost alone
        return True
    return batches >= _SEEN and (left / max(queued, 1) * BATCH_SECONDS
                                 + left * STATE_SECONDS >= PAYS * load_seconds)


def run_compiled(lean: Plain, found: Any, head: int, budget: Any,
                 n_keys: int) -> tuple[tuple[np.ndarray, ...], int, int] | None:
    """Expand the queue from ``head`` by the compiled loop: ``(chunk, states expanded,
    entries)`` as :meth:`Plain.expand` returns a batch (the states found numbered in
    ``found``'s keys and dense index), or None where it cannot run (numba missing, the
    index not a dense array, or a key the index would hold only as a hash table); the
    budget is counted and checked as the batched build checks it (states found past
    ``budget.max_states`` stop the loop before they are stored: the batched build then
    finds them and refuses).

    Its buffers are sized from what the build knows before the call: the frontier's
    states, the world's widest state and the transitions so far (:data:`_MIN_ENTRIES`);
    the rows it wrote are copied out at their length, so that nothing of the buffers
    outlives the call.  Where it stopped for lack of room, that room is doubled (the
    entries', within the bound above; the keys' array and the dense index, as the
    batched build grows them) and the loop called again."""
    index = found.index
    if index.dense is None or n_keys > index.dense_limit:
        return None
    try:
        from mitld_lp.product import bfs_kernels
    except ImportError:  # numba missing: NumPy's batches
        return None
    keys = found.keys
    n_found = keys.size
    if lean.widest < 0:  # a bound on one state's entries: no array of the world's size
        lean.widest = max(int(lean.row_len.max(initial=1)) * int(lean.act_count.max(
            initial=1)), 1)
    frontier = n_found - head
    high = max(_MIN_ENTRIES, lean.widest + 1, min(budget.transitions // _SHARE, _MAX_ENTRIES))
    room = min(max(_MIN_ENTRIES, frontier * lean.widest, lean.room), high)
    cap = min(n_found + _CHUNK_STATES, budget.max_states)
    out = np.zeros(7, dtype=np.int64)
    most = budget.estimate.states  # the product's states at most, from its factors
    parts: list[list[np.ndarray]] = [[], [], [], [], []]
    ns_all = ne_all = 0
    while True:
        if keys.data.size < n_found + lean.widest:  # room for one state's new keys at least
            _grow(keys, n_found + lean.widest, most)
        cols = np.empty(room, dtype=np.int32)
        vals = np.empty(room, dtype=np.float64)
        row_len = np.empty(room, dtype=np.int32)
        actions = np.empty(room, dtype=np.int32)
        choices = np.empty(room, dtype=np.int32)
        bfs_kernels.table_levels(
            keys.data, n_found, head, 1 << 62, cap, index.dense,
            -CODE[Absorbing.TRUNCATED], lean.act_start, lean.act_count, lean.row_start,
            lean.row_succ, lean.row_prob, lean.props, lean.table_steps, lean.step_bits,
            lean.n_q, lean.scale, lean.distinct, lean.slot_aid, LATE if lean.late else 0,
            ABSORB, cols, vals, row_len, actions, choices, out)
        head, n_found, ne, nc, ns, why, need = (int(x) for x in out)
        keys.size = index.size = n_found
        for part, buf, n in zip(parts, (cols, vals, row_len, actions, choices),
                                (ne, ne, nc, nc, ns), strict=True):
            if n:
                part.append(buf[:n].copy())  # the buffer goes with this call
        del cols, vals, row_len, actions, choices
        ns_all += ns
        ne_all += ne
        if why == 1 and room < high:  # filled: twice the room next time
            room = min(2 * room, high)
            if ns == 0:
                continue
        lean.room = room
        if why == 2:  # the keys' array full
            _grow(keys, n_found + lean.widest, most)
            if ns == 0:
                continue
        if why == 3:  # the dense index grown by doubling, within Index's rule
            dense = index.dense
            if need > min(index.dense_limit, max(1 << 16, _SPARSE * n_found)):
                break  # NumPy's batch next: its insert turns the index into a hash table
            # never past every key's slot (NumPy's batches would double past it)
            bigger = np.full(min(max(need, 2 * dense.size), index.dense_limit, n_keys), -1,
                             dtype=np.int32)
            bigger[: dense.size] = dense
            index.dense = dense = bigger
            if ns == 0:
                continue
        break
    if ns_all == 0:
        return None
    budget.expanded += ns_all
    budget.transitions += ne_all
    budget.check(n_found)
    chunk = tuple(p[0] if len(p) == 1 else (np.concatenate(p) if p else
                                             np.zeros(0, dtype=d))
                  for p, d in zip(parts, (np.int32, np.float64, np.int32, np.int32, np.int32),
                                  strict=True))
    return chunk, ns_all, ne_all


def _grow(keys: Any, need: int, most: int | None) -> None:
    """The found keys' array (a :class:`~mitld_lp.util.arrays.Grow`) at least ``need``
    long, grown as ``Grow.extend`` grows it (to twice its length, or ``need``) but not
    past ``most``, the product's states at most (:class:`~mitld_lp.product.budget.
    SizeEstimate`; csma 4-2: 608,085 for 600,267, where doubling made 1,048,576 near the
    end of the levels, 3.4 MB more than NumPy's batches, which grow it to what a wide
    batch needs)."""
    longer = 2 * keys.data.size if most is None else min(2 * keys.data.size, most)
    bigger = np.empty(max(need, longer), dtype=keys.data.dtype)
    bigger[: keys.size] = keys.data[: keys.size]
    keys.data = bigger
