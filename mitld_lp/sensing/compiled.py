"""The rows of a level's hypotheses by one compiled kernel
(:func:`mitld_lp.sensing.kernels.hypothesis_rows`): what
:meth:`~mitld_lp.sensing.frontier.FrontierBuilder.hypothesis_rows` computes with NumPy
lines, row for row and bit for bit, without the dozen copies of every column that
spreading them level by level makes.

The step rules' tables are filled here first, for the keys the NumPy lines would meet
and in the order they would make them (the order numbers worlds, times and records):
the branches of the hypotheses of every state with an outcome row, the successors of
every outcome row with a branch not cut; the automaton's steps and where hypotheses
end are made as the kernel finds them missing (all missing steps at once, then all
missing ends, as the NumPy lines' two lookups), the kernel run again after each.
Where a table is too large to keep dense the NumPy lines run instead.

The level's other compiled passes are driven from here too (:func:`observations`,
:func:`grouped_hypotheses`, :func:`decided_alone`, :func:`end_sums`: the kernels of
:mod:`mitld_lp.sensing.group_kernels`), each giving what the NumPy lines of
:mod:`mitld_lp.sensing.frontier` give, to the bit, or None where those must run."""

from __future__ import annotations

from typing import Any

import numpy as np

from mitld_lp.sensing.rows import INT, compiled_on, fsum_by, groups, mix64, scatter, spread

__all__ = ["hypothesis_rows"]

_TRIES = 3  # the steps missing, then the ends missing, then every row found
GROUPED = True
"""Whether the hypothesis kernel also groups each choice's rows by observation (False:
:func:`observations` groups the level's rows after it, as before; the same groups)."""


def hypothesis_rows(fb: Any, cols: list[np.ndarray], c_state: np.ndarray,
                    c_act: np.ndarray, c: np.ndarray, occ: np.ndarray, pu: np.ndarray,
                    o_seq: np.ndarray, trunc: int) -> tuple[Any, ...] | None:
    """:meth:`FrontierBuilder.hypothesis_rows` of ``fb``, the frontier builder that calls
    this (the same arguments and answer; not imported here: frontier.py imports this
    module), by the kernel, or None where the NumPy lines must run (a table not dense)."""
    kernels = compiled_on()
    world, clock, reported, pending, hstart, hcount = cols
    st = c_state[c]
    # the branches of the hypotheses of every state with an outcome row
    states = np.unique(st)
    parent, rank = spread(hcount[states])
    h = hstart[states][parent] + rank
    code = fb.hyp_code[h]
    hs = states[parent]
    which = fb.branches.find((code // fb.nq, reported[hs], clock[hs]), fb.make_branches)
    h0 = int(hstart[0]) if len(hstart) else 0
    h_branch = np.zeros(max(int((hstart + hcount).max(initial=h0)) - h0, 1), INT)
    h_branch[h - h0] = which
    b_start, b_len, (b_tid, b_new, b_pc, b_cut, b_now, b_wait) = fb.branches.flat()
    # the successors of every outcome row with a branch not cut
    key_live = np.bincount(np.repeat(np.arange(len(b_len), dtype=INT), b_len),
                           weights=~b_cut, minlength=len(b_len)) > 0
    state_live = np.zeros(len(world), bool)
    state_live[hs[key_live[which]]] = True
    reach = np.flatnonzero(state_live[st])
    o_succ = np.zeros(len(c), INT)
    o_succ[reach] = fb.successors.find((world[st[reach]], c_act[c[reach]], occ[reach]),
                                       fb.make_successors)
    s_start, s_len, (s_w2, s_pg) = fb.successors.flat()
    label = np.asarray(fb.world_label, INT)
    empty = np.full((0, 0), -2, INT)
    for _ in range(_TRIES):
        step, ends = fb.step_table.dense, fb.end_table.dense
        out = kernels.hypothesis_rows(
            c, st, occ, pu, o_seq, o_succ, hstart, hcount, fb.hyp_code, fb.hyp_weight,
            fb.nq, h0, h_branch, b_start, b_len, b_tid, b_new, b_pc, b_cut, b_now, b_wait,
            s_start, s_len, s_w2, s_pg, label, fb.u_atoms, fb.s_atoms, pending, fb.nu,
            empty if step is None else step, empty if ends is None else ends,
            np.int64(len(fb.sensed) if GROUPED and _fits(fb) else -1), *fb.row_work)
        cut_c, cut_o, cut_b, cut_m, d_i, d_new, d_m, u_i, u_m, of_step, ma, mb = out[:12]
        n_obs, obs, first, perm = out[12:16]
        fb.row_work = out[16:]  # the rows' pages kept for the next level (the kernel's)
        if len(ma) == 0:
            none = np.full(len(cut_c), -1, INT)
            more = [(cut_c, cut_o, cut_b, none, np.full(len(none), trunc), cut_m),
                    (d_i[0], d_i[1], d_i[2], d_i[3], d_i[4], d_m)]
            ended = (d_i[0], d_i[5], d_i[6], d_new, d_i[4])
            grouped = (obs, first, perm) if n_obs >= 0 else None  # observations'
            return more, ended, (*u_i[:6], u_m, u_i[6]), grouped
        (fb.step_table if of_step else fb.end_table)(ma, mb)
    return None


def observations(fb: Any, c: np.ndarray, w2: np.ndarray, occ: np.ndarray,
                 new: np.ndarray, done: tuple[np.ndarray, ...] | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The undecided rows grouped by observation ``(c, w2, occ, new)`` by the kernels
    (:func:`~mitld_lp.sensing.group_kernels.by_observation`: each row's group, a row of
    each, the rows in the groups' order), the observation made one word from its parts'
    widths where they fit; None where the rows must be grouped otherwise.  ``done``:
    the same grouping made by the hypothesis kernel as it made the rows (returned as it
    is; None where it did not)."""
    from mitld_lp.sensing import group_kernels as gk

    if done is not None:
        return done
    if _fits(fb):
        return gk.by_observation_bits(c, w2, occ, new, fb.nu, len(fb.sensed))
    return gk.by_observation(compiled_on(), c, w2, occ, new)


def _fits(fb: Any) -> bool:
    """Whether an observation of ``fb``'s build fits one word: world, unsensed events and
    new reports (:func:`~mitld_lp.sensing.group_kernels.by_observation_bits`)."""
    return len(fb.worlds) < 1 << (62 - fb.nu - len(fb.sensed))


def decided_alone(fb: Any, ended: tuple[np.ndarray, ...], grouped: tuple[np.ndarray, ...]
                  ) -> tuple[np.ndarray, np.ndarray] | None:
    """:meth:`FrontierBuilder.record_moves`'s observations with nothing undecided left
    with them, by one kernel pass (:func:`~mitld_lp.sensing.group_kernels.decided_alone`):
    a row of each in ``ended``, and its record where all its rows ended in one (-1
    where they disagree); None where the NumPy lines must find them."""
    if not compiled_on() or not _fits(fb):
        return None
    from mitld_lp.sensing import group_kernels as gk

    cols = tuple(np.ascontiguousarray(x, dtype=INT) for x in (*ended, *grouped))
    return gk.decided_alone(*cols, np.int64(fb.nu), np.int64(len(fb.sensed)))


def grouped_hypotheses(fb: Any, found: tuple[np.ndarray, ...] | None, obs: np.ndarray,
                       n_obs: int, tid: np.ndarray, q: np.ndarray, mass: np.ndarray,
                       s_seq: np.ndarray, rep: np.ndarray) -> tuple[Any, ...]:
    """A level's undecided rows (``obs`` each one's observation of ``n_obs``; ``found``:
    :func:`observations`' answer, None where the rows were grouped otherwise) made into
    the new states' hypotheses: a row of each hypothesis (``hfirst``), its observation,
    code ``tid * nq + q`` and mass (summed in the rows' order), its weight, each
    observation's total (correctly rounded: :func:`~mitld_lp.sensing.rows.fsum_by`),
    number of hypotheses, hash of its set and first row's place ``s_seq``, and the
    largest need (``fb.need_table``) of its hypotheses' times with its reports ``rep``
    (-1 if none): by one kernel pass
    (:func:`~mitld_lp.sensing.group_kernels.level_hypotheses`) where ``found`` is
    given, else by NumPy lines (the same arrays, to the bit); the needs by the table's
    own lookup where the kernel finds a pair the table has not made yet."""
    if found is not None:
        from mitld_lp.sensing import group_kernels as gk

        fb.order_key(tid[:0], q[:0])  # the times' ranks made for the new ones
        need = fb.need_table.dense
        *out, most, missing = gk.level_hypotheses(
            found[2], obs, n_obs, tid, q, mass, s_seq, fb.tid_rank, fb.nq,
            _EMPTY if need is None else need, np.ascontiguousarray(rep, dtype=INT))
        if len(missing):  # the pairs not made yet: by the table (which makes them)
            hobs = out[1][missing]
            scatter("max", most, hobs, fb.need_table(tid[out[0][missing]], rep[hobs]))
        return (*out, most)
    hid, hfirst = groups(obs, fb.order_key(tid, q))
    hmass = np.bincount(hid, weights=mass)  # in the loops' order, as one at a time
    hobs, hcode = obs[hfirst], tid[hfirst] * fb.nq + q[hfirst]
    total = fsum_by(hobs, hmass, n_obs)
    g_count = np.bincount(hobs, minlength=n_obs)
    g_hash = np.zeros(n_obs, np.uint64)
    scatter("add", g_hash, hobs, mix64(hcode))
    g_first = np.full(n_obs, np.iinfo(INT).max, INT)  # each group's first row
    scatter("min", g_first, obs, s_seq)
    return (hfirst, hobs, hcode, hmass, hmass / total[hobs], total, g_count, g_hash,
            g_first, _most_need(fb, tid[hfirst], rep, hobs, n_obs))


_EMPTY = np.full((0, 0), -2, INT)  # no dense table yet: every pair missing


def _most_need(fb: Any, htid: np.ndarray, rep: np.ndarray, hobs: np.ndarray,
               n_obs: int) -> np.ndarray:
    """Per observation the largest ``fb.need_table`` value of its hypotheses' times
    ``htid`` (``hobs`` each one's observation) with its reports ``rep``, -1 if none,
    by the table's lookup (which makes the pairs not met before)."""
    most = np.full(n_obs, -1, INT)
    scatter("max", most, hobs, fb.need_table(htid, rep[hobs]))
    return most


def end_sums(ends: list[np.ndarray], lists: np.ndarray
             ) -> tuple[np.ndarray, ...] | None:
    """:meth:`FrontierBuilder.transitions`' records of each choice by one kernel pass
    (:func:`~mitld_lp.sensing.group_kernels.end_sums`): the rows that end in a record
    (``ends``: choice, outcome, branch, successor, record, mass; concatenated from
    lists bounded by ``lists``, each in the loops' order) merged into the loops' order
    and grouped by (choice, record): each group's choice, record, mass and first row's
    place in that order; None where the NumPy lines must sort them."""
    if not compiled_on():
        return None
    from mitld_lp.sensing import group_kernels as gk

    cols = tuple(np.ascontiguousarray(x, dtype=INT) for x in ends[:5])
    ok, g_c, g_r, mass, place = gk.end_sums(*cols, np.ascontiguousarray(ends[5],
                                                                          dtype=np.float64),
                                            np.asarray(lists, INT))
    return (g_c, g_r, mass, place) if ok else None
