"""The merged model of a constrained synthesis (:mod:`.constrained_model`) when some law is
known only within a band: nature's options per choice, the worst case over the bands of
a randomised policy's expected steps or cost, and the robot's robust policy for one
probability (docs/robust.md, "Constraints").

* **Options** (:func:`options`): per merged choice, the distributions nature may give it
  -- the vertex rows of its product choice (:func:`mitld_lp.product.imdp.vertex_rows`)
  mapped to merged states, or its one row (a *keep* choice, an absorbing self-loop).
  Nature choosing among them per choice and per step has at least the power of one
  hazard per step in each band.
* **Worst expected total** (:func:`worst_total`): against the randomised policy
  ``(prob, stay)``, nature maximises the expected steps (or cost) until the task is
  decided: an MDP's maximum of a positive total reward.  Nature's strategy is improved
  until no option of any choice is better (policy iteration); the bracket is sound in
  exact arithmetic: ``lower`` is that strategy's own value bounded from below
  (:func:`mitld_lp.solvers.constrained.certified_value` on the point model it leaves),
  ``upper`` a vector checked to be a super-solution of nature's Bellman operator
  (``U >= r + max_v P_v U`` in every state, with the float and model rounding bounded),
  which bounds the least fixed point -- the maximum -- from above.  ``inf`` when some
  law keeps the task undecided for ever with positive probability.
* **Robust policy for one probability** (:func:`robust_for`): the robot's deterministic
  policy maximising the worst case (or minimising the best case for nature) of one
  probability by robust interval iteration on the merged game; a feasibility candidate
  whose values the caller evaluates (a run nature traps undecided counts against the
  robot here, so the policy's true worst case is at least what this computes).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp

from mitld_lp.automata.joint import ACCEPTED
from mitld_lp.checks import Check
from mitld_lp.product.imdp import VertexRows
from mitld_lp.solvers.constrained_model import Merged, Quantity, columns, trapped_bottoms
from mitld_lp.solvers.robust_graph import RobustGame, gather

__all__ = ["Options", "options", "WorstTotal", "worst_total", "robust_for", "MAX_ROUNDS"]

MAX_ROUNDS = 200
"""Rounds of nature's strategy improvement before the bracket is given up (inf)."""


@dataclass(frozen=True, slots=True, eq=False)
class Options:
    """Nature's options: merged choice ``c``'s distributions are rows
    ``groups[c]:groups[c+1]`` of ``matrix`` (over merged states)."""

    matrix: sp.csr_array
    groups: np.ndarray


def options(merged: Merged, vr: VertexRows) -> Options:
    """Per merged choice, nature's options (module docs)."""
    mdp = merged.mdp
    n = mdp.n_choices
    origin = np.asarray(merged.choice_origin, dtype=np.int64)
    own = origin < 0
    counts = np.where(own, 1, np.diff(vr.groups)[np.maximum(origin, 0)])
    groups = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(counts, out=groups[1:])
    vm = sp.csr_array(vr.matrix)
    src = gather(np.asarray(vr.groups)[origin[~own]], np.asarray(vr.groups)[origin[~own] + 1])
    picked = vm[src].tocoo() if src.size else sp.coo_array((0, vm.shape[1]))
    mapped = merged.state_map[picked.col]
    if (mapped < 0).any():
        raise AssertionError("a vertex row leaves the merged model")
    # the vertex rows' places among the options: after the own rows before each choice
    slot = np.empty(src.size, dtype=np.int64)
    slot[:] = gather(groups[:-1][~own], groups[1:][~own])
    mine = sp.csr_array(mdp.matrix)[np.flatnonzero(own)].tocoo()
    rows = np.concatenate([slot[picked.row], groups[:-1][own][mine.row]])
    cols = np.concatenate([mapped, mine.col])
    vals = np.concatenate([picked.data, mine.data])
    matrix = sp.csr_array((vals, (rows, cols)), shape=(int(groups[-1]), mdp.n_states))
    matrix.sum_duplicates()
    return Options(matrix, groups)


@dataclass(frozen=True, slots=True)
class WorstTotal:
    """A randomised policy's expected steps (cost) at the worst law of the bands:
    ``value`` nature's best strategy's float value, ``lower``/``upper`` bounds in exact
    arithmetic (``inf`` when some law keeps the task undecided for ever), ``check``
    whether both were proved."""

    value: float
    lower: float
    upper: float
    check: Check


def _chain(prob: np.ndarray, stay: np.ndarray, cs: np.ndarray, rows: sp.csr_array,
           m: int) -> tuple[sp.csr_array, np.ndarray]:
    """The policy's chain over merged states with the choice rows ``rows``, and each
    state's share of choices (``1 - stay`` normalised)."""
    total = np.bincount(cs, weights=prob, minlength=m) + stay
    share = np.where(total[cs] > 0, prob / np.where(total > 0, total, 1.0)[cs], 0.0)
    owner = sp.csr_array((share, (cs, np.arange(cs.size))), shape=(m, cs.size))
    return sp.csr_array(owner @ rows), total


def _values(merged: Merged, chain: sp.csr_array, reward: np.ndarray, stays: np.ndarray,
            stuck: np.ndarray) -> np.ndarray:
    """Expected total ``reward`` per state on ``chain`` (absorbing states 0); ``inf``
    where a state of ``stuck`` (stays for ever with a reward or undecided) is reached
    with positive probability, or a closed set of undecided states is; a positive
    ``stays`` ends the run there, worth 0."""
    from mitld_lp.solvers.quotient import backward_reachable

    m = chain.shape[0]
    live = ~merged.absorbing
    coo = chain.tocoo()
    pos = coo.data > 0
    bottom = trapped_bottoms(chain, live, merged.absorbing | stays)
    bad = stuck | (bottom & merged.undecided)
    infinite = backward_reachable(m, coo.row[pos], coo.col[pos], bad)
    v = np.zeros(m)
    v[infinite] = np.inf
    free = live & ~infinite & ~bottom
    f = np.flatnonzero(free)
    if f.size:
        import scipy.sparse.linalg as spla

        q = chain[f][:, f]
        a = (sp.eye_array(f.size, format="csc") - q).tocsc()
        v[f] = np.atleast_1d(spla.spsolve(a, reward[f]))
    return v


def worst_total(merged: Merged, opts: Options, prob: np.ndarray, stay: np.ndarray,
                q: Quantity, *, costs: np.ndarray | None = None,
                eta: float) -> WorstTotal:
    """The worst case over the bands of the expected steps (``q.kind == "steps"``) or
    cost (``"cost"``) of the randomised policy ``(prob, stay)`` (module docs)."""
    from mitld_lp.solvers.constrained import certified_value

    if q.kind not in ("steps", "cost"):
        raise ValueError("worst_total: expected steps or cost only")
    mdp = merged.mdp
    m = mdp.n_states
    cs = mdp.choice_state()
    per_choice, _ = columns(merged, q, costs)
    name = f"worst expected {q.kind} over the bands"
    used = np.flatnonzero((prob > 0) & ~merged.absorbing[cs])
    om = opts.matrix
    strategy = opts.groups[:-1].copy()  # nature's option per choice: its first
    stuck = (stay > 0) & merged.undecided
    value = np.zeros(m)
    rounds = 0
    while True:
        rows = sp.csr_array(om[strategy])
        chain, total = _chain(prob, stay, cs, rows, m)
        share = np.where(total[cs] > 0, prob / np.where(total > 0, total, 1.0)[cs], 0.0)
        reward = np.bincount(cs, weights=share * per_choice, minlength=m)
        value = _values(merged, chain, reward, stay > 0, stuck)
        if not np.isfinite(value[mdp.initial]) or rounds >= MAX_ROUNDS:
            break
        scores = _scores(om, value)
        better = strategy.copy()
        for c in used.tolist():  # nature's best option, kept unless strictly better
            lo, hi = int(opts.groups[c]), int(opts.groups[c + 1])
            if hi - lo < 2:
                continue
            k = lo + int(np.argmax(scores[lo:hi]))
            if scores[k] > scores[strategy[c]] + 1e-12 * (1.0 + abs(scores[strategy[c]])):
                better[c] = k
        if np.array_equal(better, strategy):
            break
        strategy, rounds = better, rounds + 1
    v0 = float(value[mdp.initial])
    if not np.isfinite(v0) or rounds >= MAX_ROUNDS:
        inf = float("inf")
        why = ("a law of the bands keeps the task undecided for ever with positive "
               "probability" if not np.isfinite(v0) else "nature's strategy did not settle")
        return WorstTotal(inf, v0 if not np.isfinite(v0) else 0.0, inf,
                          Check(name, not np.isfinite(v0), why))
    point = replace(merged, mdp=replace(mdp, matrix=sp.csr_array(om[strategy])))
    low = certified_value(point, prob, stay, q, name, costs=costs, eta=eta)
    upper, ok, detail = _super_solution(merged, opts, prob, stay, per_choice, value, used,
                                        eta)
    passed = bool(low.check.passed and ok)
    return WorstTotal(v0, float(low.lower), upper,
                      Check(name, passed, f"{low.check.detail}; {detail}"))


def _reachable(m: int, initial: int, cs: np.ndarray, used: np.ndarray,
               opts: Options) -> np.ndarray:
    """The states some law of the bands reaches from ``initial`` under the policy's
    ``used`` choices."""
    from scipy.sparse.csgraph import breadth_first_order

    picked = sp.csr_array(opts.matrix[gather(opts.groups[used], opts.groups[used + 1])])
    counts = np.diff(opts.groups)[used]
    coo = picked.tocoo()
    src = np.repeat(cs[used], counts)[coo.row]
    graph = sp.csr_array((np.ones(src.size), (src, coo.col)), shape=(m, m))
    order = breadth_first_order(graph, initial, directed=True, return_predecessors=False)
    seen = np.zeros(m, dtype=bool)
    seen[order] = True
    return seen


def _scores(om: sp.csr_array, value: np.ndarray) -> np.ndarray:
    """``P_v . value`` per option, ``inf`` where an option reaches an infinite state."""
    finite = np.where(np.isfinite(value), value, 0.0)
    scores = om @ finite
    hits = om @ (~np.isfinite(value)).astype(np.float64)
    return np.where(hits > 0, np.inf, scores)


def _super_solution(merged: Merged, opts: Options, prob: np.ndarray, stay: np.ndarray,
                    per_choice: np.ndarray, value: np.ndarray, used: np.ndarray,
                    eta: float) -> tuple[float, bool, str]:
    """An upper bound on nature's maximum: ``U = value (1 + d) + d`` (0 where the task
    is decided) checked to satisfy ``U(s) >= sum_c pi(c|s) (r_c + max_v P_v . U)`` in
    every undecided state reached, the float sums' rounding and the model's (each
    probability within ``eta`` of its float) bounded; ``d`` grows tenfold until it
    holds (a few times)."""
    from mitld_lp.solvers.rounding import UNIT

    mdp = merged.mdp
    m = mdp.n_states
    cs = mdp.choice_state()
    om = opts.matrix
    nnz = np.diff(om.indptr)
    total = np.bincount(cs, weights=prob, minlength=m) + stay
    # decided states are worth 0 under every law: their successors are decided too, and
    # their reachability is read on the middle law's support, which holds every law's
    live = merged.undecided & ~merged.absorbing & _reachable(m, mdp.initial, cs, used, opts)
    for d in (1e-9, 1e-7, 1e-5, 1e-3):
        u = np.where(live, value * (1.0 + d) + d, 0.0)
        best = np.maximum.reduceat(om @ u, opts.groups[:-1]) if om.shape[0] else np.zeros(0)
        width = int(nnz.max(initial=1)) + 2
        slack = (eta * nnz + 2.0 * width * UNIT)
        slack_best = np.maximum.reduceat(slack, opts.groups[:-1]) * float(u.max(initial=0.0))
        term = np.zeros(mdp.n_choices)
        term[used] = prob[used] * (per_choice[used] + best[used] + slack_best[used])
        rhs = np.bincount(cs, weights=term, minlength=m)
        k = int(np.diff(mdp.row_groups).max(initial=1)) + 2
        rhs = rhs / np.where(total > 0, total, 1.0) * (1.0 + 2.0 * k * UNIT) \
            + 4.0 * k * UNIT * np.abs(rhs)
        if bool((u[live] >= rhs[live]).all()):
            return float(u[mdp.initial]), True, f"upper bound a checked super-solution (d={d:g})"
    return float("inf"), False, "no super-solution of nature's maximum was found"


def robust_for(merged: Merged, opts: Options, q: Quantity, *, maximise: bool,
               tol: float) -> tuple[np.ndarray, np.ndarray]:
    """The robot's deterministic policy ``(prob, stay)`` for the probability ``q``
    against every law of the bands: maximising its worst case (``maximise``) or
    minimising its worst case (nature maximising it), by robust interval iteration on
    the merged game with a stay choice in each state of an end component (module docs)."""
    from mitld_lp.solvers.robust import robust_interval_iteration, robust_policy, sweep_budget

    mdp = merged.mdp
    m = mdp.n_states
    sat = merged.verdicts[:, q.component] == ACCEPTED
    holds = merged.absorbing & sat
    holds[merged.truncated] = q.truncated == 1.0
    good = holds if maximise else merged.absorbing & ~holds
    stays = np.flatnonzero(merged.stay_ok & ~merged.absorbing)
    stay_win = sat[stays] if maximise else ~sat[stays]
    om = opts.matrix
    per_state = np.diff(mdp.row_groups) + np.isin(np.arange(m), stays)
    row_groups = np.zeros(m + 3, dtype=np.int64)
    np.cumsum(np.concatenate([per_state, [1, 1]]), out=row_groups[1:])
    # the game's choices in state order: the merged choices, then the stay
    cs = mdp.choice_state()
    n_c = int(row_groups[-1])
    slot = np.arange(mdp.n_choices) + np.searchsorted(stays, cs)  # choices before, stays before
    n_opts = np.diff(opts.groups)
    counts = np.ones(n_c, dtype=np.int64)
    counts[slot] = n_opts
    vgroups = np.zeros(n_c + 1, dtype=np.int64)
    np.cumsum(counts, out=vgroups[1:])
    coo = om.tocoo()
    owner = np.repeat(np.arange(mdp.n_choices), n_opts)
    row_of = vgroups[slot][owner] + (np.arange(om.shape[0]) - opts.groups[owner])
    stay_slot = row_groups[stays + 1] - 1
    sinks = [vgroups[n_c - 2], vgroups[n_c - 1]]
    rows = np.concatenate([row_of[coo.row], vgroups[stay_slot], sinks])
    cols = np.concatenate([coo.col, np.where(stay_win, m, m + 1), [m, m + 1]])
    vals = np.concatenate([coo.data, np.ones(stays.size), [1.0, 1.0]])
    matrix = sp.csr_array((vals, (rows, cols)), shape=(int(vgroups[-1]), m + 2))
    game = RobustGame(matrix, vgroups, row_groups)
    target = np.concatenate([good, [True, False]])
    it = robust_interval_iteration(game, target, tol=tol, max_sweeps=sweep_budget(game))
    choice = robust_policy(game, target, it.lower, tie=max(tol, 1e-12))[:m]
    prob = np.zeros(mdp.n_choices)
    stay = np.zeros(m)
    is_stay = np.zeros(n_c, dtype=bool)
    is_stay[stay_slot] = True
    merged_of = np.full(n_c, -1, dtype=np.int64)
    merged_of[slot] = np.arange(mdp.n_choices)
    stay[is_stay[choice]] = 1.0
    prob[merged_of[choice[~is_stay[choice]]]] = 1.0
    return prob, stay
