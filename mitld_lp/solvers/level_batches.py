r"""The NumPy walks of :class:`~mitld_lp.solvers.topological.SingleLevels` with as few
NumPy calls a level as the recurrence allows.

A product with a deadline clock has a thousand levels and more of some hundred single
states each (QVBS ``zeroconf_dl`` 1000-1-30: 1,164 levels, 91,929 single states), so a
walk's cost is its NumPy calls a level (each some microseconds whatever its size), not
its arithmetic.  :func:`bounds` (the interval iteration's walk) and :func:`flow` (the
LP's policy flow) do once for the whole walk, not per level, whatever does not depend
on the values below a level -- each choice's one-step reward gathered, the flow's
divisors (they depend only on the policy) -- with the same floating-point operations on
the same operands in the same order as the plain walks, so the same bits.

A level's sums are one call of SciPy's compiled CSR product (``csr_matvec``, or
``csr_matvecs`` for the bounds' columns) on the walk's own arrays, the level's choices'
entry pointers a slice (:attr:`SingleLevels.ptr`), and the flow's scatter one call of
the CSC product (``csc_matvec``, a choice a column): each sum starts from 0 and adds its
entries' products in their order, as ``bincount`` and ``ufunc.at`` did, so the same
bits (where the index types do not allow it, the ``bincount`` walks are kept).

:func:`values` (the LP's values walk) needs each state's *chosen* score: the choice
among near-ties (within :data:`TIE`, the larger one-step reward preferred, then the
first) is a level's own where a tied choice scores below the top (466 of
``zeroconf_dl`` 1000-1-30's 1,099 levels with several choices a state).  Where every
tied choice scores the top exactly (or none ties), the value is the top whichever is
picked: those levels' picks are made after the walk, all at once (:func:`_picked`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mitld_lp.solvers import level_sweeps
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.rows import gather_ranges
from mitld_lp.util.sparsetools import sparsetools

try:  # the ufunc ``np.clip`` calls on floats: its Python wrappers cost two to three
    # times the clip of a level's scores (some 10 microseconds a level and walk)
    from numpy._core.umath import clip as _clip
except ImportError:  # pragma: no cover - a NumPy without it: np.clip, the same ufunc
    _clip = np.clip

SingleLevels = Any  # :class:`~mitld_lp.solvers.topological.SingleLevels` (which imports
# this module: its annotation here would make a circle)

__all__ = ["TIE", "bounds", "values", "flow"]

_LAST = np.iinfo(np.int64).max

TIE = 1e-12
"""A single state's choices within this of the best score, relative to it, are tied
(:func:`~mitld_lp.solvers.topological.solve_single_states`; re-exported there)."""


def _flat(sl: SingleLevels, out: np.ndarray) -> np.ndarray | None:
    """``out`` as the flat float64 vector SciPy's compiled CSR/CSC products
    (``scipy.sparse._sparsetools``) read and write in place, or ``None`` where they
    cannot be used (no entry pointers of the walk's index type, a strided ``out``)."""
    if (sparsetools is None or sl.ptr is None or out.dtype != np.float64
            or not out.flags.c_contiguous):
        return None
    return out.reshape(-1)


def _relative_choices(runs: list[tuple[int, ...]]) -> np.ndarray:
    """Each choice of ``runs`` (from the first run's first choice on) counted from the
    first choice of its level."""
    ca = np.array([r[2] for r in runs], dtype=np.int64)
    cz = np.array([r[3] for r in runs], dtype=np.int64)
    return np.arange(ca[0], cz[-1]) - np.repeat(ca, cz - ca)


def bounds(sl: SingleLevels, runs: list[tuple[int, ...]], rewards: np.ndarray,
           out: np.ndarray) -> None:
    """:meth:`SingleLevels.solve`'s NumPy walk over ``runs`` (``sl``'s choices have no
    self-loop of 1): each level's sums for all ``k`` columns of ``out`` by one
    ``bincount`` (bin ``k * choice + column``: each bin sums its entries in their order
    from 0, as the plain walk's ``bincount`` a column does).  The runs are walked in
    consecutive groups (:func:`_groups`), upward: a level reads only the levels below."""
    for group in _groups(runs):
        _bounds(sl, group, rewards, out)


GROUP_ENTRIES = 1 << 16
"""The entries (and choices) of the runs a walk gathers at once: its per-entry and
per-choice arrays are a group's, not the whole walk's (a run of more is gathered
alone).  Every level's arithmetic is the same whatever the groups: the same bits."""


def _groups(runs: list[tuple[int, ...]]) -> list[list[tuple[int, ...]]]:
    """``runs`` (in their order) cut into consecutive groups of at most
    :data:`GROUP_ENTRIES` entries and as many choices; a run of more is a group alone."""
    out: list[list[tuple[int, ...]]] = []
    ca0 = ea0 = 0
    for r in runs:
        if not out or r[5] - ea0 > GROUP_ENTRIES or r[3] - ca0 > GROUP_ENTRIES:
            out.append([])
            ca0, ea0 = r[2], r[4]
        out[-1].append(r)
    return out


def _bounds(sl: SingleLevels, runs: list[tuple[int, ...]], rewards: np.ndarray,
            out: np.ndarray) -> None:
    """:func:`bounds` on one group of consecutive runs."""
    k = out.shape[1]
    ca0, cz1, ea0, ez1 = runs[0][2], runs[-1][3], runs[0][4], runs[-1][5]
    reward = rewards[sl.choices[ca0:cz1]]  # (choices, k), a copy: the scores' storage
    leave = sl.leave[:, None]
    reduce = np.maximum if sl.sense is Sense.MAX else np.minimum
    flat = _flat(sl, out)
    if flat is None:
        rel = _relative_choices(runs)[np.asarray(sl.local[ea0:ez1], dtype=np.int64) - ca0]
        bins = (rel[:, None] * k + np.arange(k)).ravel()
        del rel
    n = out.shape[0]
    for a, z, ca, cz, ea, ez in runs:
        if flat is not None:  # SciPy's compiled product: one call, the same sums
            sums = np.zeros((cz - ca, k))
            sparsetools.csr_matvecs(cz - ca, n, k, sl.ptr[ca:cz + 1], sl.cols, sl.vals, flat,
                            sums.reshape(-1))
        else:
            terms = sl.vals[ea:ez, None] * out[sl.cols[ea:ez]]
            sums = np.bincount(bins[(ea - ea0) * k:(ez - ea0) * k], weights=terms.ravel(),
                               minlength=(cz - ca) * k).reshape(cz - ca, k)
        score = reward[ca - ca0:cz - ca0]
        score += sums
        np.divide(score, leave[ca:cz], out=score)
        _clip(score, 0.0, 1.0, out=score)
        out[sl.states[a:z]] = (score if cz - ca == z - a else
                               reduce.reduceat(score, sl.first_choice[a:z], axis=0))


def values(sl: SingleLevels, runs: list[tuple[int, ...]], to_target: np.ndarray,
           live_of: np.ndarray, out: np.ndarray, reduced_choice: np.ndarray,
           weights: np.ndarray) -> None:
    """The plain walk of :meth:`SingleLevels.values` (:func:`~mitld_lp.solvers.
    topological.solve_single_states` a level at a time): each level's choice picked
    before the next level is scored.  ``live_of``: per single state, whether it is
    solved (not skipped).  The runs are walked in consecutive groups (:func:`_groups`),
    upward, each group's deferred picks made at its end: a level's value reads only the
    levels below, and a pick only its own level."""
    every = bool(live_of.all())
    for group in _groups(runs):
        _values(sl, group, to_target, live_of, every, out, reduced_choice, weights)


def _values(sl: SingleLevels, runs: list[tuple[int, ...]], to_target: np.ndarray,
            live_of: np.ndarray, every: bool, out: np.ndarray, reduced_choice: np.ndarray,
            weights: np.ndarray) -> None:
    """:func:`values` on one group of consecutive runs (``every``: no state skipped)."""
    maximum = sl.sense is Sense.MAX
    reduce = np.maximum if maximum else np.minimum
    # what no level's values change, gathered once: the choices' rewards, the
    # preference among ties, the positions; the choices written after the walk
    ca0, cz1 = runs[0][2], runs[-1][3]
    reward_of = to_target[sl.choices[ca0:cz1]]
    prefer_of = reward_of if maximum else -reward_of
    index = np.arange(max(cz - ca for _, _, ca, cz, _, _ in runs))
    done_states, done_picks = [], []
    deferred: list[tuple[int, int, int, int, np.ndarray]] = []
    flat, n = _flat(sl, out), out.shape[0]
    for a, z, ca, cz, ea, ez in runs:
        if flat is not None:  # SciPy's compiled product: one call, the same sums
            sums = np.zeros(cz - ca)
            sparsetools.csr_matvec(cz - ca, n, sl.ptr[ca:cz + 1], sl.cols, sl.vals, flat, sums)
        else:
            sums = np.bincount(sl.local[ea:ez] - ca, minlength=cz - ca,
                               weights=sl.vals[ea:ez] * out[sl.cols[ea:ez]])
        ch = sl.choices[ca:cz]
        reward = reward_of[ca - ca0:cz - ca0] + sums
        leave = sl.leave[ca:cz]
        score = (reward / leave if sl.positive else
                 np.divide(reward, leave, out=np.zeros_like(reward), where=leave > 0))
        _clip(score, 0.0, 1.0, out=score)
        if cz - ca == z - a:  # one choice a state: each its own best
            best, pick = score, ch
        else:  # segmented_argmax's ties and preference, on the level's segments
            starts, own = sl.first_choice[a:z], sl.owner_at[ca:cz]
            best = reduce.reduceat(score, starts)
            top = best[own]
            tied = (score - top if maximum else top - score) >= -TIE * np.abs(top)
            if (tied & (score != top)).any():  # a near-tie: the pick sets the value
                key = np.where(tied, prefer_of[ca - ca0:cz - ca0], -np.inf)
                tied &= key >= np.maximum.reduceat(key, starts)[own]
                at = np.minimum.reduceat(np.where(tied, index[:cz - ca], _LAST), starts)
                best, pick = score[at], ch[at]
            else:  # every tied choice scores the top: the value is the top whichever
                # is picked, and the pick is made after the walk (:func:`_picked`)
                deferred.append((a, z, ca, cz, tied))
                pick = None
        states = sl.states[a:z]
        if not every:
            live = live_of[a:z]
            states, best = states[live], best[live]
        out[states] = best
        if pick is not None:
            done_states.append(states)
            done_picks.append(pick if every else pick[live])
    if deferred:
        states, pick = _picked(sl, deferred, prefer_of, ca0)
        if not every:
            live = live_of[states]
            states, pick = sl.states[states[live]], pick[live]
        else:
            states = sl.states[states]
        done_states.append(states)
        done_picks.append(pick)
    picks = np.concatenate(done_picks)
    reduced_choice[np.concatenate(done_states)] = picks
    weights[picks] = 1.0


def _picked(sl: SingleLevels, deferred: list[tuple[int, int, int, int, np.ndarray]],
            prefer_of: np.ndarray, ca0: int) -> tuple[np.ndarray, np.ndarray]:
    """The choices of the levels whose value did not wait for their pick (``deferred``:
    each level's slices and its choices within TIE of their state's top), picked at once
    by the walk's rule on the levels' segments laid end to end: among the tied, the
    largest preference, then the first.  Returns the positions of their states in
    ``sl.states`` and each one's choice."""
    a, z, ca, cz, masks = (list(t) for t in zip(*deferred, strict=True))
    tied = np.concatenate(masks)
    at = gather_ranges(np.asarray(ca), np.asarray(cz))  # the choices' positions in sl
    per_level = np.asarray(cz) - np.asarray(ca)
    size = np.asarray(z) - np.asarray(a)
    where = gather_ranges(np.asarray(a), np.asarray(z))  # the states' positions in sl
    starts = (np.asarray(sl.first_choice[where], dtype=np.int64)
              + np.repeat(np.cumsum(per_level) - per_level, size))
    own = np.repeat(np.arange(where.size), np.diff(np.append(starts, tied.size)))
    key = np.where(tied, prefer_of[at - ca0], -np.inf)
    tied &= key >= np.maximum.reduceat(key, starts)[own]
    first = np.minimum.reduceat(np.where(tied, np.arange(tied.size), _LAST), starts)
    return where, sl.choices[at[first]]


def flow(sl: SingleLevels, runs: list[tuple[int, ...]], self_loop: np.ndarray,
         weights: np.ndarray, x: np.ndarray) -> None:
    """:meth:`SingleLevels.flow`'s NumPy walk over ``runs`` (upstream first): each
    state's divisor (what its choices do not keep, a ``bincount`` a state in its
    choices' order) and each entry's weight gathered once for a group of runs
    (:func:`_groups`); then a level divides its states' inflow and adds it along its
    entries.  The groups are walked downward as the levels are: the last group first."""
    groups = _groups(runs)
    if level_sweeps.flow(sl, groups, self_loop, weights, x):  # linear: a compiled call
        return  # a group
    for group in reversed(groups):  # upstream first
        _flow(sl, group, self_loop, weights, x)


def _flow(sl: SingleLevels, runs: list[tuple[int, ...]], self_loop: np.ndarray,
          weights: np.ndarray, x: np.ndarray) -> None:
    """:func:`flow` on one group of consecutive runs (its last level first)."""
    a0, z1, ca0, cz1 = runs[0][0], runs[-1][1], runs[0][2], runs[-1][3]
    ea0, ez1 = runs[0][4], runs[-1][5]
    ch = sl.choices[ca0:cz1]
    # per choice its state, counted from the group's first state (built per group:
    # the walk keeps no int64 a choice for it)
    owner = np.repeat(np.arange(z1 - a0, dtype=np.int64), np.diff(sl.state_choice[a0:z1 + 1]))
    w = weights[ch]
    keep = 1.0 - np.bincount(owner, weights=w * self_loop[ch], minlength=z1 - a0)
    local = np.asarray(sl.local[ea0:ez1], dtype=np.int64) - ca0
    flat, n = _flat(sl, x), x.shape[0]
    if flat is not None:  # per choice its state's inflow times its weight, then SciPy's
        # compiled scatter along the choice's entries (CSC by choice: the same order)
        choice_state = sl.states[a0:z1][owner]
        del local, owner
        for a, z, ca, cz, _, _ in reversed(runs):
            states = sl.states[a:z]
            x[states] /= keep[a - a0:z - a0]
            y = w[ca - ca0:cz - ca0] * x[choice_state[ca - ca0:cz - ca0]]
            sparsetools.csc_matvec(n, cz - ca, sl.ptr[ca:cz + 1], sl.cols, sl.vals, y, flat)
        return
    entry_state = sl.states[a0:z1][owner[local]]  # whose inflow each entry carries
    entry_weight = w[local]
    del local, owner, w
    for a, z, _, _, ea, ez in reversed(runs):
        states = sl.states[a:z]
        x[states] /= keep[a - a0:z - a0]
        y = entry_weight[ea - ea0:ez - ea0] * x[entry_state[ea - ea0:ez - ea0]]
        np.add.at(x, sl.cols[ea:ez], sl.vals[ea:ez] * y)

