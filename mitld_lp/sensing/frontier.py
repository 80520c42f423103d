"""The construction of the information-state product, a frontier at a time
(:mod:`mitld_lp.sensing.belief`'s module docs; tests/test_sensing_build.py builds the
same product one state at a time and compares every state, row, posterior and move).

The states found and not expanded yet (up to :data:`CHUNK` of them, one level at a time:
the states first found one step after the previous level's) are expanded together, as
numpy rows: each state's choices, the outcomes of its unsensed events, its hypotheses,
each one's sensed branches and the world's successors, one row per combination; the
automaton's step and where a hypothesis ends are looked up in tables indexed by small
integers (world states, event sets as bit masks, hypotheses' event times), which the
step rules (:mod:`mitld_lp.sensing.rules`) fill for the keys not met before. The rows
are grouped by what the robot observes into successor information states, their times
made canonical (:mod:`mitld_lp.sensing.merge`), and a state is found by an integer key:
its world state, clock, reports, pending events, number of hypotheses and a 64-bit hash
of its hypothesis set. A key met before is compared with the stored state hypothesis by
hypothesis (a hash collision is an internal error, never a merge) and weight by weight
(:data:`~mitld_lp.sensing.info.WEIGHT_TOL`, the posterior being a function of the key).
Python objects are made once per world state, event set and new information state; the
moves are kept as arrays (:class:`~mitld_lp.sensing.moves.Moves`). The budgets are
checked before each batch of new states is stored and, from an estimate of the final
size, at each level's end (:mod:`~mitld_lp.sensing.growth`)."""

from __future__ import annotations

import gc
import logging
from collections.abc import Hashable, Mapping
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.automata.dta import DTA
from mitld_lp.automata.sta import STA
from mitld_lp.mdp import ABSORB, MDP
from mitld_lp.product import Absorbing
from mitld_lp.sensing import compiled
from mitld_lp.sensing.chunks import CHUNK, RowGauge, chunk_end
from mitld_lp.sensing.growth import ALARM_PAST, Growth
from mitld_lp.sensing.info import (
    BYTES_PER_HYPOTHESIS,
    BYTES_PER_INFO_STATE,
    NOT_YET,
    WEIGHT_TOL,
    Belief,
    Ends,
    InfoSize,
)
from mitld_lp.sensing.keys import Columns, KeyedTable, Keys
from mitld_lp.sensing.merge import Counts, Shifts
from mitld_lp.sensing.moves import Moves, level_moves
from mitld_lp.sensing.rows import (
    COMPILED_MIN_ESTIMATE,
    COMPILED_MIN_STATES,
    Lookup,
    compiled_on,
    groups,
    grown,
    join_parts,
    lex_order,
    load_kernels,
    merged_entries,
    mix64,
    narrow,
    ordered_groups,
    scatter,
    spread,
)
from mitld_lp.sensing.rows import INT as _I
from mitld_lp.sensing.rules import StepRules
from mitld_lp.sensing.sensors import Sensor
from mitld_lp.sensing.states import InfoStates
from mitld_lp.util.progress import bar as progress_bar
from mitld_lp.worlds.game import Game

__all__ = ["FrontierBuilder"]

log = logging.getLogger("mitld_lp.sensing.belief")

_FAR = 1 << 60  # a clock past every bound (StepRules.clock_key caps at its argument)


class FrontierBuilder(StepRules):
    """The information states reachable from the initial one (module docs), under
    ``max_states`` and ``max_memory``, also as estimated at each level's end
    (:mod:`~mitld_lp.sensing.growth`; ``size``: what a state can hold, ``name``: the
    model's, for the messages); ``merge``: states whose futures are identical merged
    (:mod:`~mitld_lp.sensing.merge`)."""

    def __init__(self, game: Game[Any], dta: DTA, sta: STA, sensed: tuple[str, ...],
                 sensors: Mapping[str, Sensor], max_states: int, max_memory: int,
                 size: InfoSize, ends: Ends | None = None, name: str | None = None,
                 merge: bool = True) -> None:
        super().__init__(game, dta, sta, sensed, sensors, ends)
        self.bytes, self.growth = 0, Growth(max_states=max_states, max_memory=max_memory,
                                            size=size, sensors=sensors,
                                            points=sta.truncation_points, name=name,
                                            alarm_past=ALARM_PAST if self.alarms else 0)
        self.keys, self.gauge = Keys(6), RowGauge()  # the states' keys (match)
        self.nq = dta.n_states
        self.unsensed_order = tuple(sorted(self.unsensed))
        nu, ns = len(self.unsensed_order), len(sensed)
        self.nu = nu
        self.u_sets = [frozenset(a for b, a in enumerate(self.unsensed_order) if m >> b & 1)
                       for m in range(1 << nu)]
        self.s_sets = [frozenset(a for b, a in enumerate(sensed) if m >> b & 1)
                       for m in range(1 << ns)]
        self.atoms = tuple(sorted(dta.atoms))
        bit = {a: 1 << i for i, a in enumerate(self.atoms)}
        self.u_atoms = np.array([sum(bit.get(a, 0) for a in s) for s in self.u_sets], _I)
        self.s_atoms = np.array([sum(bit.get(a, 0) for a in s) for s in self.s_sets], _I)
        self.atom_bit = bit
        self.worlds: list[Hashable] = []
        self.world_id: dict[Hashable, int] = {}
        self.world_label: list[int] = []
        self.world_acts: dict[int, tuple[str, ...]] = {}
        self.act_names: list[str] = []
        self.act_id: dict[str, int] = {}
        self.times: list[tuple[int, ...]] = []
        self.times_id: dict[tuple[int, ...], int] = {}
        # with false alarms the times are not shifted (their report counts would be
        # read at the shifted steps); the counts are made canonical instead (Counts)
        self.shifts = Shifts(sta, sensed, sensors, self.times, self.time_id,
                             merge and not self.alarms)
        self.counts = Counts(ns, self.alarms, self.times, self.time_id)
        self.alarm_mask = sum(1 << i for i in self.alarms)  # never kept as reported
        self.outcomes = KeyedTable(3, (_I, np.float64, bool))
        self.branches = KeyedTable(6, (_I, _I, np.float64, bool, _I, _I))
        self.successors = KeyedTable(2, (_I, np.float64))
        self.step_table = Lookup(self.make_step)
        self.end_table = Lookup(self.make_end)  # -1 undecided, else a record
        self.need_table = Lookup(self.make_need)
        self.pending_need = Lookup(self.make_pending_need)
        self.actions = KeyedTable(1, (_I,))
        # the moves (Moves): per level its first choice and its runs of rows (choice,
        # world, occurred, new, target)
        self.n_choices = 0
        self.move_rows: list[tuple[int, Any]] = []  # Moves' levels (PackedRuns)
        # the absorbing records (ends, the truncation): id and state (-1 until stored)
        self.records: list[Hashable] = []
        self.record_id: dict[Hashable, int] = {}
        self.record_state: list[int] = []
        self.tid_rank = np.zeros(0, _I)  # each hypothesis times' rank in sorted order
        # per state: world, clock, reported, pending, first hypothesis, hypotheses;
        # -1 clock for an absorbing state
        self.cols = Columns(6)
        self.hyp_code = np.zeros(1024, _I)  # every state's hypotheses, in state order
        self.hyp_weight = np.zeros(1024, np.float64)
        self.n_hyps = 0
        self.row_work = (np.zeros((15, 0), _I), np.zeros((2, 0)))  # compiled.py's pages

    # ---------------------------------------------------------------- small tables

    def world(self, g: Hashable) -> int:
        i = self.world_id.get(g)
        if i is None:
            i = self.world_id[g] = len(self.worlds)
            self.worlds.append(g)
            self.world_label.append(sum(self.atom_bit.get(a, 0) for a in self.label(g)))
        return i

    def time_id(self, times: tuple[int, ...]) -> int:
        if times not in self.times_id:
            self.times_id[times] = len(self.times)
            self.times.append(times)
        return self.times_id[times]

    def make_acts(self, key: tuple[int]) -> list[tuple[int]]:
        """A world state's actions (ids), or the loop (-1) of an absorbing state."""
        (w,) = key
        if w < 0:
            return [(-1,)]
        names = self.world_acts[w] = tuple(self.game.actions(self.worlds[w]))
        for name in names:
            if name not in self.act_id:
                self.act_id[name] = len(self.act_names)
                self.act_names.append(name)
        return [(self.act_id[name],) for name in names]

    def make_pending_need(self, pending: int, _: int) -> int:
        return self.clock_key(_FAR, [], self.u_sets[pending], frozenset())

    def mask(self, events: frozenset[str], order: tuple[str, ...]) -> int:
        return sum(1 << i for i, a in enumerate(order) if a in events)

    def make_outcomes(self, key: tuple[int, int]) -> list[tuple[int, float, bool]]:
        pending, t = key
        return [(self.mask(o, self.unsensed_order), p, crossed)
                for o, p, crossed in self.unsensed_outcomes(self.u_sets[pending], t)]

    def make_branches(self, key: tuple[int, int, int]) -> list[tuple[Any, ...]]:
        tid, reported, t = key
        return [(self.time_id(times2), self.mask(new, self.sensed), p, cut,
                 self.mask(now, self.sensed), self.mask(waiting, self.sensed))
                for times2, new, p, cut, now, waiting in self._sensed_branches(
                    self.times[tid], self.s_sets[reported], t)]

    def make_successors(self, key: tuple[int, int, int]) -> list[tuple[int, float]]:
        w, act, occurred = key
        return [(self.world(g2), p) for g2, p in self.game.successors(
            self.worlds[w], self.act_names[act], self.u_sets[occurred]) if p > 0.0]

    def make_step(self, q: int, label: int) -> int:
        return self.automaton(q, frozenset(a for i, a in enumerate(self.atoms)
                                           if label >> i & 1))

    def make_end(self, q: int, left: int) -> int:
        events = self.u_sets[left & ((1 << self.nu) - 1)] | self.s_sets[left >> self.nu]
        end = self.end(q, events)
        return -1 if end is None else self.record(end)

    def make_need(self, tid: int, reported: int) -> int:
        return self.clock_key(_FAR, [self.times[tid]], frozenset(), self.s_sets[reported])

    # ---------------------------------------------------------------- states

    def record(self, record: Hashable) -> int:
        """The id of an absorbing record."""
        r = self.record_id.get(record)
        if r is None:
            r = self.record_id[record] = len(self.records)
            self.records.append(record)
            self.record_state.append(-1)
        return r

    def store_record(self, r: int) -> None:
        self.record_state[r] = self.cols.n
        self.cols.append((-1, -1, 0, 0, self.n_hyps, 0))
        self.bytes += BYTES_PER_INFO_STATE

    def order_key(self, tid: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Hypotheses in :class:`InfoState` order: by their times, then automaton state."""
        if len(self.tid_rank) < len(self.times):
            rank = np.empty(len(self.times), _I)
            rank[sorted(range(len(self.times)), key=self.times.__getitem__)] = np.arange(
                len(self.times))
            self.tid_rank = rank
        return self.tid_rank[tid] * self.nq + q

    def check(self, new: int, hyps: int) -> None:
        """Raise :class:`ProductTooLarge` before ``new`` states of ``hyps`` hypotheses in
        all are stored past a budget (:meth:`Growth.check`)."""
        self.growth.check(self.cols.n, self.bytes, new, hyps)

    def add_states(self, world: np.ndarray, clock: np.ndarray, reported: np.ndarray,
                   pending: np.ndarray, counts: np.ndarray, codes: np.ndarray,
                   weights: np.ndarray) -> None:
        """Store new information states (columns), their hypotheses' codes and weights
        concatenated in state order, each state's in :class:`InfoState` order."""
        starts = self.n_hyps + np.cumsum(counts) - counts
        self.cols.extend((world, clock, reported, pending, starts, counts))
        end = self.n_hyps + len(codes)
        if end > len(self.hyp_code):  # by doubling; the tail never written (no page
            # of it touched: np.resize filled it, 7.8 bytes a transition resident on
            # issue 45's sensed case where 3.3 of them held no hypothesis)
            size = max(end, 2 * len(self.hyp_code))
            self.hyp_code = grown(self.hyp_code, self.n_hyps, size)
            self.hyp_weight = grown(self.hyp_weight, self.n_hyps, size)
        self.hyp_code[self.n_hyps:end] = codes
        self.hyp_weight[self.n_hyps:end] = weights
        self.n_hyps = end
        self.bytes += BYTES_PER_INFO_STATE * len(world) + BYTES_PER_HYPOTHESIS * len(codes)

    def states(self) -> InfoStates:
        """The states stored so far (copied, narrowed), their records made when asked."""
        cols, codes = self.cols.data[:, :self.cols.n], self.hyp_code[:self.n_hyps]
        return InfoStates(narrow(cols, True), narrow(codes, True),
                          self.hyp_weight[:self.n_hyps].copy(), self.nq, self.times,
                          self.worlds, self.s_sets, self.u_sets,
                          {at: r for r, at in zip(self.records, self.record_state,
                                                  strict=True) if at >= 0})

    def release_levels(self) -> None:
        """Drop the rows' pages (compiled.py's), the states' keys and the step tables'
        rows once the last level is expanded, before the product is assembled."""
        self.row_work, self.keys = (np.zeros((15, 0), _I), np.zeros((2, 0))), Keys(6)
        for t in (self.outcomes, self.branches, self.successors, self.actions):
            t.clear()  # 2 bytes a transition on issue 45's sensed case

    def release(self) -> None:
        """Drop every array of the build once built (:meth:`release_levels`'s, the states'
        columns and hypotheses, which :meth:`states` copied): the builder lives in cycles
        until the collector's next full pass, and those would hold up the solve."""
        self.release_levels()
        self.cols = Columns(6)
        self.hyp_code, self.hyp_weight, self.n_hyps = np.zeros(0, _I), np.zeros(0), 0

    # ---------------------------------------------------------------- one level

    def expand(self, a: int, b: int) -> list[np.ndarray]:
        """Expand the states ``a .. b - 1``, new states stored: each state's number of
        choices, the choices' actions (in order) and numbers of transitions, and the
        transitions' columns and probabilities (choice by choice)."""
        cols = self.cols.rows(a, b)
        world, clock, reported, pending, hstart, hcount = cols
        # the choices: each state's actions, an absorbing state its loop
        c_state, (c_act,) = self.actions.rows(self.actions.find((world,), self.make_acts))
        row0 = self.n_choices
        self.n_choices += len(c_state)
        loops = np.flatnonzero(c_act < 0)
        loop = (loops, a + c_state[loops], np.ones(len(loops)))
        live = np.flatnonzero(c_act >= 0)  # the information states' choices
        st = c_state[live]
        t = clock[st]
        # the unsensed events' outcomes
        which = self.outcomes.find((pending[st], t), self.make_outcomes)
        parent, (occ, pu, crossed) = self.outcomes.rows(which)
        c = live[parent]
        o_seq = np.arange(len(c), dtype=_I)  # each row's place in the loops of one state
        trunc = self.record(Absorbing.TRUNCATED)
        none = np.full(int(crossed.sum()), -1, _I)
        ends = [(c[crossed], o_seq[crossed], none, none, np.full(len(none), trunc),
                 pu[crossed])]
        keep = ~crossed
        c, occ, pu, o_seq = (x[keep] for x in (c, occ, pu, o_seq))
        rows = None
        if compiled_on():
            rows = compiled.hypothesis_rows(self, cols, c_state, c_act, c, occ, pu, o_seq, trunc)
        if rows is None:
            rows = self.hypothesis_rows(cols, c_state, c_act, c, occ, pu, o_seq, trunc)
        more, ended, (c, occ, w2, new, tid2, q2, mass, s_seq), *done = rows
        self.gauge.made(int(hcount.sum()), len(c) + len(ended[0]))
        ends += more
        # the undecided hypotheses grouped by what the robot observes, their times
        # canonical (merge.py), each group's in InfoState order
        found = compiled_on() and compiled.observations(self, c, w2, occ, new, *done)
        obs, first = groups(c, w2, occ, new) if found is None else found[:2]
        tid2 = self.shifts.canonical(tid2, obs, c, c_state, reported, new, clock)
        tid2 = self.counts.canonical(tid2, obs)
        gst = c_state[c[first]]
        g_rep = reported[gst] | (new[first] & ~self.alarm_mask)
        hfirst, hobs, hcode, hmass, weight, total, g_count, g_hash, g_first, most = (
            compiled.grouped_hypotheses(self, found, obs, len(first), tid2, q2, mass, s_seq,
                                        g_rep))
        g_pend = pending[gst] & ~occ[first]
        pend_need = self.pending_need(g_pend, g_pend)
        g_clock = np.minimum(clock[gst] + 1, np.maximum(np.maximum(most, pend_need), 0))
        group = (w2[first], g_clock, g_rep, g_pend, g_count, g_hash.view(_I))
        target, reps = self.keys.match(group)  # -1 - k: the k-th new key
        g_start = np.cumsum(g_count) - g_count  # each group's first hypothesis
        flat = [np.concatenate(x) for x in zip(*ends, strict=True)]
        self.store(c[first], g_first, target, reps, group, g_start, hcode, weight, flat)
        self.verify(target, g_count, hobs, hcode, weight)
        self.record_moves(row0, (c[first], w2[first], occ[first], new[first]), target,
                          ended)
        lists = np.cumsum([0] + [len(x[0]) for x in ends])
        choice, col, val = self.transitions(loop, flat, lists, c[first], g_first, target,
                                            total)
        # kept until the product is assembled, each in the form the MDP keeps it: the
        # states' numbers of choices, the choices' actions and numbers of transitions,
        # the columns (int32, the matrix's) and probabilities in choice order
        return [np.bincount(c_state, minlength=b - a), c_act.astype(np.int32),
                np.bincount(choice, minlength=len(c_state)), col.astype(np.int32), val]

    def hypothesis_rows(self, cols: list[np.ndarray], c_state: np.ndarray,
                        c_act: np.ndarray, c: np.ndarray, occ: np.ndarray, pu: np.ndarray,
                        o_seq: np.ndarray, trunc: int) -> tuple[Any, ...]:
        """The rows of the outcomes ``(c, occ, pu, o_seq)`` (choice, unsensed events,
        probability, place) spread over each state's hypotheses, their sensed branches
        and the world's successors: the ends met (cut branches, then decided
        hypotheses), the decided rows' observations and records, and the undecided rows
        (choice, occurred, world, reported, times, automaton state, mass, place).
        :func:`mitld_lp.sensing.compiled.hypothesis_rows` gives the same, compiled."""
        world, clock, reported, pending, hstart, hcount = cols
        # each state's hypotheses
        st = c_state[c]
        parent, rank = spread(hcount[st])
        c, occ, pu, st, o_seq = (x[parent] for x in (c, occ, pu, st, o_seq))
        h = hstart[st] + rank
        code, w = self.hyp_code[h], self.hyp_weight[h]
        tid, q = code // self.nq, code % self.nq
        # each hypothesis's sensed branches
        t = clock[st]
        which = self.branches.find((tid, reported[st], t), self.make_branches)
        parent, (tid2, new, pc, cut, now, wait) = self.branches.rows(which)
        c, occ, pu, st, q, w, o_seq = (x[parent] for x in (c, occ, pu, st, q, w, o_seq))
        b_seq = np.arange(len(c), dtype=_I)
        base = w * pu * pc
        none = np.full(int(cut.sum()), -1, _I)
        ends = [(c[cut], o_seq[cut], b_seq[cut], none, np.full(len(none), trunc),
                     base[cut])]
        ok = ~cut
        c, occ, st, q, base, tid2, new, now, wait, o_seq, b_seq = (
            x[ok] for x in (c, occ, st, q, base, tid2, new, now, wait, o_seq, b_seq))
        # the world's successors (what the hypothesis saw happen and what may still
        # come, before they are spread)
        happened = self.u_atoms[occ] | self.s_atoms[now]
        left = (pending[st] & ~occ) | (wait << self.nu)
        which = self.successors.find((world[st], c_act[c], occ), self.make_successors)
        parent, (w2, pg) = self.successors.rows(which)
        c, occ, q, base, tid2, new, happened, left, o_seq, b_seq = (
            x[parent] for x in (c, occ, q, base, tid2, new, happened, left, o_seq, b_seq))
        s_seq = np.arange(len(c), dtype=_I)
        mass = base * pg
        label = np.asarray(self.world_label, _I)[w2] | happened
        q2 = self.step_table(q, label)
        end = self.end_table(q2, left)
        done = end >= 0
        ends.append((c[done], o_seq[done], b_seq[done], s_seq[done], end[done], mass[done]))
        ended = (c[done], w2[done], occ[done], new[done], end[done])
        u = ~done
        c, occ, w2, new, tid2, q2, mass, s_seq = (
            x[u] for x in (c, occ, w2, new, tid2, q2, mass, s_seq))
        return ends, ended, (c, occ, w2, new, tid2, q2, mass, s_seq)

    def transitions(self, loop: tuple[np.ndarray, ...], ends: list[np.ndarray],
                    lists: np.ndarray, c: np.ndarray, g_first: np.ndarray,
                    target: np.ndarray, total: np.ndarray) -> tuple[np.ndarray, ...]:
        """The expansion's transitions (choice, column, probability) in each choice's
        order one state at a time would make them, with the same sums: the absorbing
        records as the loops meet them (their mass summed in the loops' order), then
        the information states as their observations come, a choice's entries into one
        state made one (:func:`merged_entries`).  ``ends``: the rows that end in a record,
        concatenated from lists bounded by ``lists``."""
        c, g_first, target, total = merged_entries(c, g_first, target, total)
        found = compiled.end_sums(ends, lists)
        if found is not None:  # by the kernels: the lists merged, one pass
            g_c, g_r, mass, place = found
        else:
            c_end, o_end, b_end, s_end, r_end, m_end = ends
            order = np.lexsort((s_end, b_end, o_end, c_end))
            c_end, o_end, r_end, m_end = (x[order] for x in (c_end, o_end, r_end, m_end))
            ids, _ = ordered_groups(c_end, r_end)  # by choice: the lexsort's first key
            mass = np.bincount(ids, weights=m_end)
            place = np.full(len(mass), np.iinfo(_I).max, _I)
            scatter("min", place, ids, np.arange(len(ids), dtype=_I))  # first met, sorted
            g_c, g_r = c_end[place], r_end[place]
        col = np.asarray(self.record_state, _I)[g_r]
        cc = np.concatenate([loop[0], g_c, c])
        phase = np.concatenate([np.zeros(len(loop[0]) + len(place), _I),
                                np.ones(len(c), _I)])
        pos = np.concatenate([np.zeros(len(loop[0]), _I), place, g_first])
        order = lex_order(cc, phase, pos)
        return (cc[order], np.concatenate([loop[1], col, target])[order],
                np.concatenate([loop[2], mass, total])[order])

    def store(self, c: np.ndarray, g_first: np.ndarray, target: np.ndarray,
              reps: np.ndarray, group: tuple[np.ndarray, ...],
              g_start: np.ndarray, hcode: np.ndarray, weight: np.ndarray,
              ends: list[np.ndarray]) -> None:
        """Store the new states (records and information states, ``target`` updated) in
        the order one state at a time would: state by state and choice by choice, the
        records as the loops meet them, then the new information states as their
        observations' first rows come."""
        c_end, o_end, b_end, s_end, r_end, _ = ends
        fresh_record = np.asarray(self.record_state, _I)[r_end] < 0
        new_group = target < 0
        n_rec = len(self.records)
        item = np.concatenate([r_end[fresh_record], n_rec - 1 - target[new_group]])
        phase = np.concatenate([np.zeros(int(fresh_record.sum()), _I),
                                np.ones(int(new_group.sum()), _I)])
        order = lex_order(
            np.concatenate([c_end[fresh_record], c[new_group]]),
            phase,
            np.concatenate([o_end[fresh_record], g_first[new_group]]),
            np.concatenate([b_end[fresh_record], np.zeros(int(new_group.sum()), _I)]),
            np.concatenate([s_end[fresh_record], np.zeros(int(new_group.sum()), _I)]))
        _, at = np.unique(item[order], return_index=True)
        sequence = item[order][np.sort(at)]
        counts = group[4]
        self.check(len(sequence), int(counts[reps].sum()))
        index = np.empty(len(reps), _I)
        # the new states between two records stored together, each record in its place
        start = 0
        for x in np.flatnonzero(sequence < n_rec).tolist() + [len(sequence)]:
            if x > start:
                batch = sequence[start:x] - n_rec
                g = reps[batch]
                parent, rank = spread(counts[g])
                rows = g_start[g][parent] + rank
                index[batch] = self.cols.n + np.arange(len(batch), dtype=_I)
                self.add_states(*(y[g] for y in group[:5]), hcode[rows], weight[rows])
            if x < len(sequence):
                self.store_record(int(sequence[x]))
            start = x + 1
        self.keys.settle(index)
        target[new_group] = index[-1 - target[new_group]]

    def verify(self, target: np.ndarray, count: np.ndarray, hobs: np.ndarray,
               hcode: np.ndarray, weight: np.ndarray) -> None:
        """Check every group against its state, hypothesis by hypothesis: the same
        hypotheses (else two sets share a hash) and the same posterior."""
        starts = self.cols.col(4)[target]
        kernels = compiled_on()
        if kernels:
            collided, worst, row = kernels.verify(starts, count, hobs, hcode, weight,
                                                  self.hyp_code, self.hyp_weight)
        else:
            _, rank = spread(count)
            at = starts[hobs] + rank
            collided = not np.array_equal(self.hyp_code[at], hcode)
            gap = np.abs(self.hyp_weight[at] - weight)
            row = int(np.argmax(gap)) if len(gap) and not collided else -1
            worst = float(gap[row]) if row >= 0 else 0.0
        if collided:
            raise RuntimeError("internal error: two information states with one key "
                               "(a hash collision of their hypothesis sets)")
        if row >= 0 and worst > WEIGHT_TOL:
            bad = int(hobs[row])
            raise RuntimeError(
                f"internal error: information state {self.states()[int(target[bad])]!r} "
                f"reached with two posteriors (they differ by {worst:.3g})")

    def record_moves(self, base: int, grouped: tuple[np.ndarray, ...], target: np.ndarray,
                     ended: tuple[np.ndarray, ...]) -> None:
        """The controller's moves of the level's choices (:func:`level_moves`)."""
        self.move_rows.append(level_moves(self, base, grouped, target, ended,
                                          self.record(Absorbing.TRUNCATED)))

    def chunk_end(self, head: int, end: int) -> int:
        """The end of the chunk from ``head``, at most ``end`` (:func:`chunk_end`)."""
        return chunk_end(self.cols.data[5, head:end], head, self.gauge.limit())

    # ---------------------------------------------------------------- the MDP

    def build(self, progress: bool | None = None) -> Belief:
        game = self.game
        q0, first = self.initial_verdict()
        if first is not None:
            self.check(1, 0)
            self.store_record(self.record(first))
            initial = 0
        else:
            initial = self.cols.n
            times0 = self.time_id((NOT_YET,) * len(self.sensed) + (0,) * len(self.alarms))
            q0code = np.array([times0 * self.nq + q0], _I)
            one = np.array([1], _I)
            w0 = self.world(game.initial)
            clock0 = self.clock_key(0, [self.times[times0]], self.unsensed, frozenset())
            self.add_states(np.array([w0], _I), np.array([clock0], _I), np.zeros(1, _I),
                            np.array([self.mask(self.unsensed, self.unsensed_order)], _I),
                            one, q0code, np.ones(1))
            self.keys.add((w0, clock0, 0, int(self.mask(self.unsensed, self.unsensed_order)),
                           1, int(mix64(q0code).view(_I)[0])), initial)
        parts: list[list[np.ndarray]] = []
        head = 0
        self.growth.start(self.cols.n)
        shown = progress_bar(progress, total=None, unit=" states", desc="information states",
                             leave=False, mininterval=0.5)
        # many small objects, no reference cycles: the cyclic collector paused meanwhile
        collecting = gc.isenabled()
        gc.disable()
        try:
            level = self.cols.n  # a level: the states first found one step on
            while head < self.cols.n:
                end = min(level, head + CHUNK)
                if end - head >= COMPILED_MIN_STATES:
                    load_kernels()  # numba's load pays from here (rows.py)
                end = self.chunk_end(head, end)
                parts.append(self.expand(head, end))
                shown.update(end - head)
                head = end
                if head == level:  # a level done: its growth judged before the next
                    self.growth.level(self.cols.n - level, self.n_hyps, self.bytes)
                    level = self.cols.n
                    if self.growth.estimate >= COMPILED_MIN_ESTIMATE:
                        load_kernels()  # a large product foreseen (rows.py)
        finally:
            if collecting:
                gc.enable()
        shown.close()
        self.release_levels()
        n, n_choices = self.cols.n, self.n_choices
        index = np.int32 if max(sum(len(p[3]) for p in parts), n_choices) < 2**31 else _I
        indptr = np.zeros(n_choices + 1, index)
        np.cumsum(np.concatenate([p[2] for p in parts]), out=indptr[1:], dtype=index)
        per_state = np.zeros(n + 1, np.int64)
        np.cumsum(np.concatenate([p[0] for p in parts]), out=per_state[1:])
        act = np.concatenate([p[1] for p in parts])
        # int32 indices where they fit, as the plain product's (12 bytes a transition)
        matrix = sp.csr_array((join_parts(parts, 4, np.float64), join_parts(parts, 3, index),
                               indptr), shape=(n_choices, n))
        del parts
        # the actions numbered as the choices first show them
        used = np.flatnonzero(act >= 0)
        seen, at = np.unique(act[used], return_index=True)
        shown_first = seen[np.argsort(at)]
        number = np.full(len(self.act_names), -1, _I)
        number[shown_first] = np.arange(len(shown_first))
        names = tuple(self.act_names[k] for k in shown_first.tolist())
        act = np.where(act < 0, ABSORB, number[np.maximum(act, 0)]).astype(np.int32)
        sizes = (n, n_choices, matrix.nnz, self.shifts.merged)
        log.info("information-state product: %s states, %s choices, %s transitions (%s groups "
                 "shifted: merge.py)", *(f"{x:,}" for x in sizes))
        kind = np.zeros(n, np.int8)  # the records stored are the only absorbing states
        for record, at in zip(self.records, self.record_state, strict=True):
            if at >= 0 and isinstance(record, Absorbing):
                kind[at] = {Absorbing.TARGET: 1, Absorbing.SINK: 2,
                            Absorbing.TRUNCATED: 3}.get(record, 0)
        mdp = MDP(matrix=matrix, row_groups=per_state,
                  choice_actions=act, action_names=names,
                  initial=initial, target=kind == 1, sink=kind == 2, truncated=kind == 3,
                  states=self.states())
        moves = Moves(mdp.row_groups, narrow(self.cols.col(0), True), self.world_acts,
                      self.worlds, self.u_sets, self.s_sets, self.records, self.move_rows)
        return Belief(mdp, self.sta, self.sensed, self.sensors, moves)

