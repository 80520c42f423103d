"""The controlled chain of a controller that acts on sensor reports where some event's
law is known only within a band: an interval model for Storm's robust check, and the
controller's worst case over the band read from it.

Its states are those of :mod:`mitld_lp.running.sensed_chain` (the truth: world state,
automaton state on the true events, pending events, clock, unreported sensed events;
the controller's memory: its information state, moved by its own tables), its labels
too.  At every step nature picks each pending band event's hazard inside the band at
the true clock (docs/robust.md, "What is solved": the adversary who has seen everything,
the robot's action included), the events then happen independently: the same semantics
as the robust route's interval MDP (:mod:`mitld_lp.product.imdp`).  The value of a step
is multilinear in the hazards, so nature's best reply is at a corner of the box of
hazards: each state has one choice per corner (named ``act/b1=lo``, ``act/b1=hi``), each
the exact distribution of the step at that corner, written as point intervals; the file
is an interval MDP whose every choice is nature's (the form
:mod:`mitld_lp.running.band_chain` writes for two band events at once).  Storm's
``Pmin=? [F "accept"]`` with the uncertainty resolved to the minimum is the
controller's worst case over the band; :func:`worst_case` computes it here by value
iteration from below (every iterate is the worst case of reaching ``accept`` within that
many steps, so a sound lower bound), less an allowance for the floats' rounding.
"""

from __future__ import annotations

import logging
import os
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.files import drn
from mitld_lp.files import write as files
from mitld_lp.running.band_chain import BAND_PROPERTY, BandChain, band_chain_drn
from mitld_lp.running.sensed_corners import sensed_corner_unfolding

__all__ = ["SensedBandValue", "NatureMax", "chain_floor", "is_sensed_band", "nature_max",
           "reach_from_below", "sensed_band_chain",
           "sensed_band_chain_of", "sensed_band_drn", "sensed_band_unfolding",
           "sensed_band_unfolding_of",
           "sensed_band_claim", "reach_min", "tail_sta", "worst_case",
           "write_sensed_band_chain", "BAND_PROPERTY"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class SensedBandValue:
    """The controller's worst case over the band on its chain: ``lower`` a sound lower
    bound (the iterate less the rounding allowance), ``last_change`` the iteration's
    last change (how far from converged it stopped), ``iterations``, ``n_states``;
    ``truncated_won`` the same worst case with the runs past a truncation point counted
    as reaching ``accept`` (the upper truncation model's reading: how much of the gap to
    an upper bound is the truncation's, not the band's)."""

    lower: float
    last_change: float
    iterations: int
    n_states: int
    truncated_won: float = float("nan")


def is_sensed_band(result: Any) -> bool:
    """Whether ``result`` answers a problem with sensors that miss events and a band (its
    route's part says its lower end is a worst case over the band)."""
    return bool(getattr(getattr(result, "part", None), "band_worst", False))


def sensed_band_claim(result: Any) -> tuple[float, str]:
    """What Storm's check of the file gives against ``result``'s bracket: the bound and
    the sentence the command line prints."""
    how = f"{BAND_PROPERTY} with uncertainty MINIMIZE"
    if result.complemented:  # the complement's automaton: "accept" marks failing runs
        bound = result.complement[0] if result.complement is not None else 1 - result.upper
        return bound, (f"{how} >= the complement's lower = {bound!r}: for a minimised "
                       "task \"accept\" marks the runs that fail it (1 - it is upper, the "
                       "controller's worst case over the bands)")
    return result.lower, (f"{how} >= lower = {result.lower!r}, the controller's worst "
                          "case over the bands")


def sensed_band_chain(game: Any, dta: Any, sta: Any, sensors: Any, controller: Any,
                      max_states: int | None = None, *, ends: Any = None,
                      reading: str = "worst") -> BandChain:
    """The interval chain (module docs) of ``controller`` in ``game`` with the task's
    automaton ``dta``, the events' clocks ``sta`` (bands included) and the ``sensors``
    (at most ``max_states`` states, else :class:`~mitld_lp.util.memory.ProductTooLarge`);
    ``ends``: a joint automaton's (:mod:`mitld_lp.running.sensed_joint`); ``reading``:
    the band read for its worst law or its best (:func:`tail_sta`)."""
    return sensed_band_unfolding(game, dta, sta, sensors, controller, max_states,
                                 ends=ends, reading=reading)[0]


def sensed_band_unfolding(game: Any, dta: Any, sta: Any, sensors: Any, controller: Any,
                          max_states: int | None = None, *, ends: Any = None,
                          reading: str = "worst"
                          ) -> tuple[BandChain, tuple[tuple[str, np.ndarray], ...]]:
    """:func:`sensed_band_chain` and its reward models (a joint automaton's ``steps``
    and ``cost``, the same for every corner: each state's); a band with no truncation
    point drawn past its step as :func:`tail_sta` says for ``reading``."""
    chain, choices = sensed_corner_unfolding(game, dta, tail_sta(sta, reading), sensors,
                                             controller, max_states, ends=ends)
    rows = [row for here in choices for _, row in here]
    names = tuple(name for here in choices for name, _ in here)
    n = len(choices)
    indptr = np.zeros(len(rows) + 1, dtype=np.int64)
    np.cumsum([len(r) for r in rows], out=indptr[1:])
    cols = np.fromiter((c for r in rows for c in sorted(r)), dtype=np.int64,
                       count=int(indptr[-1]))
    vals = np.fromiter((r[c] for r in rows for c in sorted(r)), dtype=np.float64,
                       count=int(indptr[-1]))
    matrix = sp.csr_array((vals, cols, indptr), shape=(len(rows), n))
    groups = np.zeros(n + 1, dtype=np.int64)
    np.cumsum([len(h) for h in choices], out=groups[1:])
    return (BandChain(matrix, vals.copy(), groups, names, chain.labels, chain.valuations,
                      chain.origin), chain.rewards)


def tail_sta(sta: Any, reading: str = "worst") -> Any:
    """``sta`` with the clock of each sensed band that no truncation serves (its clock's
    law a :class:`~mitld_lp.distributions.band.TailBand`,
    :func:`mitld_lp.sensing.belief.sensed_sta`) kept exact: the chain's clock runs to
    the band's step ``K`` and stays there, nothing truncated, nature picking the
    hazard of every later step in a constant interval.  For the worst law
    (``reading = "worst"``) the outer one, holding every later interval of the band:
    nature may do more than it can, so the chain's worst case is a sound lower bound of
    the controller's (exact where the band is constant past ``K``).  For the best law
    the inner one, within every later interval: nature may do less, so the chain's best
    case is a sound lower bound of the controller's; where no constant interval lies
    within every later one, the band's own intervals up to step ``K + 1`` and a run
    still pending after it cut (counted as failure).  Other clocks unchanged."""
    from mitld_lp.automata.sta import STA
    from mitld_lp.distributions.band import TailBand, tail_bands

    clocks, changed = dict(sta.clocks), False
    for a, c in sta.clocks.items():
        d = c.distribution
        if not isinstance(d, TailBand):
            continue
        changed, K, c0 = True, d.step, d.base.constant_hazard_from
        cap = K if c0 is None else min(K, max(c0 - 1, 0))  # constant before K already
        law, cut = d, None
        if reading == "best":
            inner = tail_bands(d.base, K)[1]
            if inner is None:
                law, cap, cut = d.base, K, K + 1
            else:
                law = replace(inner, nominal=d.nominal)
        clocks[a] = replace(c, distribution=law, cap=cap, truncation=cut, keeps_never=False,
                            report_limit=None, report_tail=0.0)
    return STA(sta.dta, clocks) if changed else sta


def chain_floor(mdp: Any, policy: np.ndarray, dta: Any) -> tuple[int, int]:
    """A lower bound on the states of the interval chain of the controller of ``policy``
    (a choice row per state, -1 where none) on the information-state product ``mdp`` of
    the automaton ``dta``, from the product alone (before the chain is unfolded): every
    information state the policy reaches holds hypotheses of positive weight, each a
    truth the chain reaches at some law of the band; those with the same automaton state
    (not an end) and the same events still pending are one.  Returns the bound and the
    information states reached."""
    from scipy.sparse.csgraph import breadth_first_order

    from mitld_lp.sensing.belief import NOT_YET

    n = mdp.n_states
    chosen = np.asarray(policy, dtype=np.int64)
    at = np.flatnonzero(chosen >= 0)
    rows = sp.csr_array(mdp.matrix[chosen[at]])
    coo = rows.tocoo()
    graph = sp.csr_array((np.ones(coo.nnz), (at[coo.row], coo.col)), shape=(n, n))
    reached = breadth_first_order(graph, int(mdp.initial), return_predecessors=False)
    ends = {dta.accepting, dta.rejecting}
    truths = 0
    for i in reached.tolist():
        hypotheses = getattr(mdp.states[i], "hypotheses", ())
        truths += len({(q, tuple(k == NOT_YET for k in times)) for times, q in hypotheses
                       if q not in ends})
    return truths, int(reached.size)


def sensed_band_chain_of(result: Any, controller: Any = None,
                         max_states: int | None = None, *,
                         costs: Mapping[str, float] | None = None,
                         reading: str | None = None) -> BandChain:
    """The interval chain of a sensed answer whose laws include a band, under its
    controller or ``controller`` (one of the same model), at most ``max_states``; a
    randomised controller's (constraints, ``then``) over the joint automaton, whose
    labels ``c<i>`` mark each constraint's formula accepted (``costs``: the actions'
    costs, default the model's); ``reading``: the band's worst law or its best
    (:func:`tail_sta`; default the answer's)."""
    return sensed_band_unfolding_of(result, controller, max_states, costs=costs,
                                    reading=reading)[0]


def sensed_band_unfolding_of(result: Any, controller: Any = None,
                             max_states: int | None = None, *,
                             costs: Mapping[str, float] | None = None,
                             reading: str | None = None
                             ) -> tuple[BandChain, tuple[tuple[str, np.ndarray], ...]]:
    """:func:`sensed_band_chain_of` and its reward models."""
    if reading is None:
        reading = getattr(result.part, "reading", "worst")
    c = controller if controller is not None else result.controller
    if c is None:
        raise ValueError(f"no controller to export: the synthesis is {result.status}")
    if getattr(result.part, "randomised", False):  # the joint automaton's ends
        from mitld_lp.running.sensed_joint import joint_ends

        ends = joint_ends(result.joint, [v.constraint for v in result.constraints],
                          result.belief, result.model.costs if costs is None else costs)
        return sensed_band_unfolding(result.model.game, result.joint.dta, result.sta,
                                     result.sensors, c, max_states, ends=ends,
                                     reading=reading)
    return sensed_band_unfolding(result.model.game, result.dta, result.sta, result.sensors,
                                 c, max_states, reading=reading)


def worst_case(chain: BandChain, *, tol: float = 1e-13, max_iterations: int = 1_000_000
               ) -> SensedBandValue:
    """``Pmin(F accept)`` of ``chain`` from its state 0, nature minimising over each
    state's choices: value iteration from below until no value changes by more than
    ``tol`` (module docs); and ``Pmin(F (accept | truncated))`` the same way."""
    accept = chain.accepting()
    truncated = np.array(["truncated" in x for x in chain.labels], dtype=bool)
    low, change, k = _from_below(chain, accept, tol, max_iterations)
    high = _from_below(chain, accept | truncated, tol, max_iterations)[0]
    return SensedBandValue(low, change, k, chain.n_states, high)


def reach_min(chain: BandChain, target: np.ndarray, *, tol: float = 1e-13,
              max_iterations: int = 1_000_000) -> float:
    """Nature's least probability of reaching ``target`` from state 0, a sound lower
    bound: nature's best strategy's value (:func:`_min_strategy`), lowered by a margin
    and proven a sub-solution; where that proof fails, value iteration from below
    (until no value changes by more than ``tol``, at most ``max_iterations`` rounds),
    less the floats' rounding allowance.  Both start from the states every strategy of
    nature leads to ``target`` almost surely (:func:`_sure`, a fact of the graph: their
    value is 1).  (Value iteration alone crawls where the controller keeps a run in a
    loop it leaves with a tiny probability, as a kept safety task's does, or one that
    waits for ever on a sensor with false alarms, its mixed decision's other actions an
    interior-point solution's residue.)"""
    target = np.asarray(target, dtype=bool)
    goal = target | _sure(chain, target)
    proven = _min_strategy(chain, goal)
    if proven is not None:
        return proven
    return _from_below(chain, goal, tol, max_iterations)[0]


def _sure(chain: BandChain, target: np.ndarray) -> np.ndarray:
    """The states outside ``target`` from which every strategy of nature reaches it with
    probability 1: those with no path (a positive probability under some corner at each
    step, through states outside ``target``) to :func:`_avoiders`.  A strategy that
    keeps runs out of ``target`` for ever with positive probability has them end in an
    end component outside ``target`` (the pairs a run repeats for ever form one, almost
    surely), and every such component lies among the avoiders, so such a path exists."""
    n, groups = chain.n_states, chain.row_groups
    owner = np.repeat(np.arange(n), np.diff(groups))
    coo = chain.matrix.tocoo()
    edge = (coo.data > 0.0) & ~target[owner[coo.row]]  # a path ends at the target
    src, dst = owner[coo.row[edge]], coo.col[edge]
    graph = sp.csr_array((np.ones(src.size), (src, dst)), shape=(n, n))
    return ~target & ~_live(graph, _avoiders(chain, target))


def _avoiders(chain: BandChain, target: np.ndarray) -> np.ndarray:
    """The states from which nature keeps the run out of ``target`` for ever: the
    greatest set of non-target states each with a choice whose every successor is in
    it (their least probability is 0; every end component of nature's outside
    ``target`` lies in it)."""
    m, starts = chain.matrix, chain.row_groups[:-1]
    inside = ~target
    while True:
        leaks = m @ (~inside).astype(np.float64)
        ok = np.maximum.reduceat((leaks == 0.0).astype(np.int8), starts) > 0 \
            if m.shape[0] else np.zeros(0, dtype=bool)
        now = inside & ok
        if np.array_equal(now, inside):
            return inside
        inside = now


def _min_strategy(chain: BandChain, target: np.ndarray,
                  margins: tuple[float, ...] = (1e-15, 1e-14, 1e-13, 1e-12),
                  max_rounds: int = 200) -> float | None:
    """Nature's least probability of reaching ``target`` from state 0 by strategy
    improvement, the states of :func:`_avoiders` held at 0 (the rest then has no end
    component, so the one-step operator has one fixed point there and any vector below
    every corner's one-step image, a sub-solution, is below it): the value lowered by a
    margin times one plus nature's greatest expected number of steps before the run
    reaches ``target`` or those states (each state then has a slack of the margin below
    every corner's step), checked to be a sub-solution, the least of ``margins`` that
    passes (the floats' rounding eats the smaller ones on a large chain); None where
    none does."""
    n = chain.n_states
    zero = _avoiders(chain, target)
    rest = ~zero & ~target
    v, _ = _strategy_value(chain, target, np.zeros(n), True, max_rounds, minimise=True,
                           zero=zero)
    steps, _ = _strategy_value(chain, np.zeros(n, dtype=bool), rest.astype(np.float64),
                               False, max_rounds, zero=zero | target)
    if not (np.all(np.isfinite(v)) and np.all(np.isfinite(steps))):
        return None
    m, groups = chain.matrix, chain.row_groups
    for margin in margins:
        w = np.where(rest, np.maximum(v - margin * (1.0 + steps), 0.0), 0.0)
        w[target] = 1.0
        step = np.minimum.reduceat(m @ w, groups[:-1]) if m.shape[0] else w
        if np.all(w[rest] <= step[rest]):
            return float(w[0])
    log.info("nature's least reaching probability not proven by its strategy; value "
             "iteration from below instead")
    return None


@dataclass(frozen=True, slots=True)
class NatureMax:
    """Nature's greatest probability of reaching a target (or expected total reward)
    from state 0: ``value`` its best strategy's (strategy improvement, each strategy's
    chain solved exactly in floats), ``upper`` a sound upper bound (``value`` raised by a
    margin and proven a super-solution of every corner's step: no strategy of nature
    does better; 1 for a probability, infinity for a total where the proof fails),
    ``proven`` whether it held, ``rounds`` the strategies tried."""

    value: float
    upper: float
    proven: bool
    rounds: int


def nature_max(chain: BandChain, *, target: np.ndarray | None = None,
               reward: np.ndarray | None = None, margin: float = 1e-12,
               max_rounds: int = 200) -> NatureMax:
    """Nature maximising, over each state's choices, the probability of reaching
    ``target`` or (``reward`` given instead) the expected total reward from state 0
    (:class:`NatureMax`).  Any vector at least every corner's one-step image (a
    super-solution) bounds the least fixed point, the value, from above; the proof's
    vector is the value raised by ``margin`` times nature's greatest expected number of
    steps before the run is decided (each state then has a slack of ``margin`` over every
    corner's step, which the floats' rounding does not eat)."""
    n = chain.n_states
    prob = target is not None
    goal = np.asarray(target, dtype=bool) if prob else np.zeros(n, dtype=bool)
    gain = np.zeros(n) if prob else np.asarray(reward, dtype=np.float64)
    v, rounds = _strategy_value(chain, goal, gain, prob, max_rounds)
    if not np.isfinite(v[0]):
        return NatureMax(float("inf"), float("inf"), False, rounds)
    m, groups = chain.matrix, chain.row_groups
    owner = np.repeat(np.arange(n), np.diff(groups))
    union = sp.csr_array((np.ones(m.nnz), m.indices, m.indptr), shape=m.shape).tocoo()
    reach = sp.csr_array((np.ones(union.nnz), (owner[union.row], union.col)), shape=(n, n))
    live = _live(reach, goal if prob else gain > 0) & ~goal
    # nature's greatest expected steps among the live states (each worth 1)
    steps, _ = _strategy_value(chain, np.zeros(n, dtype=bool), live.astype(np.float64),
                               False, max_rounds)
    if not np.all(np.isfinite(steps[live])):
        return NatureMax(float(v[0]), 1.0 if prob else float("inf"), False, rounds)
    w = np.where(live, v + margin * (1.0 + steps), 0.0)
    if prob:
        w = np.minimum(w, 1.0)
        w[goal] = 1.0
    step = np.maximum.reduceat(m @ w + gain[owner], groups[:-1]) if m.shape[0] else w
    free = live & (w < 1.0) if prob else live  # 1 bounds a probability by itself
    proven = bool(np.all(w[free] >= step[free]))
    upper = float(w[0]) if proven else (1.0 if prob else float("inf"))
    return NatureMax(float(v[0]), upper, proven, rounds)


def _live(rows: sp.csr_array, seeds: np.ndarray) -> np.ndarray:
    """The states from which some state of ``seeds`` is reachable on ``rows``'s graph
    (``seeds`` included)."""
    from scipy.sparse.csgraph import breadth_first_order

    n = rows.shape[0]
    back = sp.csr_array(rows.T)
    live = np.zeros(n, dtype=bool)
    starts = np.flatnonzero(seeds)
    if not starts.size:
        return live
    # one search from a state n added before every seed (an edge to each), not one
    # search a seed: the same states, found in one pass over the graph
    indptr = np.append(back.indptr, back.indptr[-1] + starts.size)
    indices = np.concatenate([back.indices, starts.astype(back.indices.dtype)])
    data = np.concatenate([back.data, np.ones(starts.size, dtype=back.data.dtype)])
    joined = sp.csr_array((data, indices, indptr), shape=(n + 1, n + 1))
    found = breadth_first_order(joined, n, return_predecessors=False)
    live[found[found < n]] = True
    return live


def _endless(rows: sp.csr_array, gain: np.ndarray) -> np.ndarray:
    """The states of the chain ``rows`` (a row may be empty: a state held at 0) from which
    it reaches a bottom strongly connected component holding a positive ``gain``: their
    expected total is infinite (solving for it would meet a singular system)."""
    from scipy.sparse.csgraph import connected_components

    n = rows.shape[0]
    n_comp, comp = connected_components(rows, directed=True, connection="strong")
    coo = rows.tocoo()
    on = coo.data > 0.0
    src, dst = coo.row[on], coo.col[on]
    bottom = np.ones(n_comp, dtype=bool)
    bottom[comp[src[comp[src] != comp[dst]]]] = False
    has_exit = np.zeros(n, dtype=bool)
    has_exit[src] = True
    rewarded = np.zeros(n_comp, dtype=bool)
    rewarded[comp[(gain > 0) & has_exit]] = True  # an empty row ends the run
    seeds = bottom[comp] & rewarded[comp]
    return _live(rows, seeds) if seeds.any() else seeds


def _strategy_value(chain: BandChain, goal: np.ndarray, gain: np.ndarray, prob: bool,
                    max_rounds: int, *, minimise: bool = False,
                    zero: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """Nature's best strategy's values by strategy improvement: each strategy's chain
    solved exactly (in floats), improved where some corner does better by more than
    1e-12; reaching ``goal`` (``prob``) or the total ``gain``, the greatest (or the
    least, ``minimise``); the states of ``zero`` held at 0 (their rows dropped);
    infinite where a strategy keeps a reward for ever."""
    from scipy.sparse.linalg import spsolve

    m, groups, n = chain.matrix, chain.row_groups, chain.n_states
    owner = np.repeat(np.arange(n), np.diff(groups))
    keep = None if zero is None else sp.diags_array((~zero).astype(np.float64))

    def solve(rows: sp.csr_array) -> np.ndarray:
        if keep is not None:
            rows = sp.csr_array(keep @ rows)
        v = goal.astype(np.float64)
        live_at = _live(rows, goal if prob else gain > 0) & ~goal
        if not prob:  # a reward for ever where a bottom component holds one
            endless = _endless(rows, gain)
            v[endless] = np.inf
            live_at &= ~endless
        live = np.flatnonzero(live_at)
        if live.size:
            sub = sp.csc_array(sp.eye(live.size) - rows[live][:, live])
            b = (rows[live][:, np.flatnonzero(goal)].sum(axis=1) if prob else gain[live])
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore")  # a singular system: a reward for ever
                try:
                    x = np.atleast_1d(spsolve(sub, np.asarray(b, dtype=np.float64).ravel()))
                except RuntimeError:  # SuperLU's word for an exactly singular one
                    x = np.full(live.size, np.inf)
            v[live] = np.where(np.isfinite(x) & (x >= -1e-12), np.maximum(x, 0.0), np.inf)
        return v

    strategy = groups[:-1].copy()
    v, rounds = solve(sp.csr_array(m[strategy])), 1
    while rounds < max_rounds and np.all(np.isfinite(v)):
        q = m @ v + gain[owner]
        better = strategy.copy()
        sign = -1.0 if minimise else 1.0
        for s in np.flatnonzero(np.diff(groups) > 1).tolist():
            lo, hi = int(groups[s]), int(groups[s + 1])
            k = lo + int(np.argmax(sign * q[lo:hi]))
            if sign * (q[k] - q[strategy[s]]) > 1e-12 * (1.0 + abs(q[strategy[s]])):
                better[s] = k
        if np.array_equal(better, strategy):
            break
        strategy = better
        v, rounds = solve(sp.csr_array(m[strategy])), rounds + 1
    return v, rounds


def reach_from_below(chain: BandChain, target: np.ndarray, tol: float, max_iterations: int,
                     *, maximise: bool) -> tuple[np.ndarray, float, int]:
    """Nature's least (or, ``maximise``, greatest) probability of reaching ``target``
    from every state, by value iteration from below (each iterate: within that many
    steps); the last change; the iterations."""
    m = chain.matrix
    starts = chain.row_groups[:-1]
    best = np.maximum if maximise else np.minimum
    v = target.astype(np.float64)
    change, k = 1.0, 0
    while change > tol and k < max_iterations:
        nxt = best.reduceat(m @ v, starts) if m.shape[0] else v
        nxt[target] = 1.0
        change = float(np.max(nxt - v)) if v.size else 0.0
        v, k = nxt, k + 1
    return v, change, k


def _from_below(chain: BandChain, target: np.ndarray, tol: float, max_iterations: int
                ) -> tuple[float, float, int]:
    """Nature's least probability of reaching ``target`` from state 0, from below, less
    the floats' rounding allowance; the last change; the iterations."""
    v, change, k = reach_from_below(chain, target, tol, max_iterations, maximise=False)
    allowance = 4.0 * np.finfo(np.float64).eps * (k + 1)
    return max(float(v[0]) - allowance, 0.0), change, k


def sensed_band_drn(result: Any, controller: Any = None) -> drn.DrnModel:
    """The interval chain of a sensed answer with a band (:func:`sensed_band_chain_of`)
    as Storm's DRN, with its reward models: a randomised controller's (constraints,
    ``then``) ``steps`` and ``cost``, the same on every corner, each state's (Storm's
    ``R{"steps"}max=? [F "done"]`` with uncertainty MAXIMIZE is the worst expected steps
    over the band, the answer's ``steps``)."""
    chain, rewards = sensed_band_unfolding_of(result, controller)
    return replace(band_chain_drn(chain), rewards=tuple(
        drn.Reward(name, state=values) for name, values in rewards))


def write_sensed_band_chain(result: Any, path: str | os.PathLike[str], *,
                            controller: Any = None, overwrite: bool = False) -> Path:
    """Write the interval chain of a sensed answer with a band (:func:`sensed_band_drn`)
    to ``path`` (``.drn``) under the package's rule for output files; Storm's
    ``Pmin=? [F "accept"]`` with uncertainty MINIMIZE reads it."""
    out = files.writable_path(path, overwrite=overwrite, suffixes=drn.SUFFIXES)
    return drn.write(sensed_band_drn(result, controller), out, overwrite=overwrite)
