r"""The constrained occupancy LP: one LP over the whole merged product, solved by Clarabel.

Variables: ``x_c >= 0`` per choice of a non-absorbing state (the expected number of
times the choice is taken) and ``z_s >= 0`` per state where a run may stay for ever
(the probability of staying there; see :mod:`mitld_lp.solvers.constrained_model`).
Rows::

    sum_{c of s} x_c + z_s - sum_c P(s | c) x_c = [s = initial]   per non-absorbing s
    sum_c w_i(c) x_c + sum_s u_i(s) z_s  <= b_i  (or >= b_i)      per constraint i

and the objective ``max sum_c w_0(c) x_c + sum_s u_0(s) z_s`` (the task's probability),
or ``min`` expected steps / cost for the lexicographic second stage.  The constraint rows
couple every part of the product, so the block-by-block decomposition of the
unconstrained LP does not apply: the LP is solved whole.

The policy read off a solution is randomised and stationary (with a stay):
``pi(c | s) = x_c / (sum_{c' of s} x_c' + z_s)`` and ``pi(stay | s) = z_s / (...)``.
Its values are then computed exactly on its Markov chain
(:func:`~mitld_lp.solvers.constrained_model.evaluate`), never taken from the LP.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers.clarabel_lp import ClarabelAnswer, solve_clarabel
from mitld_lp.solvers.constrained_model import Merged, Quantity, columns, evaluate
from mitld_lp.solvers.result import Status

__all__ = ["Row", "Solved", "optimise", "OPTIMAL", "INFEASIBLE", "FAILED", "certified_value"]

OPTIMAL, INFEASIBLE, FAILED, TIME_LIMIT = (Status.OPTIMAL, Status.INFEASIBLE, Status.FAILED,
                                          Status.TIME_LIMIT)

_ZERO_SHARE = 1e-9  # a choice with less than this share of its state's visits is dropped


@dataclass(frozen=True, slots=True)
class Row:
    """A constraint row: ``quantity sense bound``."""

    quantity: Quantity
    sense: str
    bound: float


@dataclass(frozen=True, slots=True, eq=False)
class Solved:
    """One LP and the policy read off it.

    Attributes:
        status: how the LP's solve ended (:data:`~mitld_lp.solvers.clarabel_lp.CLARABEL_STATUS`);
            a solution comes with ``OPTIMAL`` and ``INACCURATE``
            (``status.has_solution``), whose policy the caller's certificate judges.
        objective: the LP's optimum (nan without a solution).
        prob: per merged choice, the probability the policy takes it.
        stay: per merged state, the probability the policy stays there for ever.
        values: the exact value on the policy's chain of the objective, then of each row.
        message: the solver's word.
        duals: the LP's dual solution, ``(y, lam)``: ``y`` per merged state (0 where
            absorbing), ``lam >= 0`` per row (``None`` without a solution).
        allowed: per merged choice, whether the LP could take it (a ``P(phi) <= 0`` row
            closes the choices that may reach ``phi``: :func:`never_reaching`).
    """

    status: Status
    objective: float
    prob: np.ndarray | None
    stay: np.ndarray | None
    values: tuple[float, ...]
    message: str
    duals: tuple[np.ndarray, np.ndarray] | None = None
    allowed: np.ndarray | None = None


def _counts_steps(q: Quantity) -> bool:
    return q.kind in ("steps", "cost")


def _clarabel(c: np.ndarray, a_eq: sp.csc_array, b_eq: np.ndarray, a_ub: sp.csc_array,
              b_ub: np.ndarray, tol: float, time_limit: float | None = None,
              ) -> ClarabelAnswer:
    """``min c'v  s.t.  a_eq v = b_eq, a_ub v <= b_ub, v >= 0`` by Clarabel (form
    ``Av + s = b, s in {0}^n x R_+^m``): its answer, whose dual solution satisfies
    ``A'z + c = 0`` (the equality rows' duals first); ``time_limit`` seconds (status
    ``time_limit`` past it, the limit then said in the message)."""
    n = c.size
    a = sp.vstack([a_eq, a_ub, -sp.eye_array(n, format="csc")], format="csc")
    b = np.concatenate([b_eq, b_ub, np.zeros(n)])
    settings: dict[str, Any] = {key: tol for key in ("tol_gap_abs", "tol_gap_rel", "tol_feas")}
    settings["max_iter"] = 500
    if time_limit is not None:
        settings["time_limit"] = max(float(time_limit), 1e-3)
    return solve_clarabel(c, a, b, zero=b_eq.size, nonneg=b_ub.size + n, settings=settings)


def optimise(
    merged: Merged,
    objective: Quantity,
    maximise: bool,
    rows: list[Row],
    *,
    costs: np.ndarray | None = None,
    tol: float = 1e-10,
    time_limit: float | None = None,
) -> Solved:
    """Optimise ``objective`` over the randomised stationary policies (with stays) of
    ``merged`` subject to ``rows`` (the LP of the module docstring); the policy's exact
    values come with it.  Stays in undecided states are closed when the objective or a
    row counts steps or costs."""
    mdp = merged.mdp
    quantities = [objective, *(r.quantity for r in rows)]
    timed = any(_counts_steps(q) for q in quantities)
    allow_stay = merged.stay_ok & ~(merged.undecided & timed)
    cols = [columns(merged, q, costs) for q in quantities]
    cs = mdp.choice_state()
    live = ~merged.absorbing
    allowed, stay_allowed = never_reaching(merged, rows)
    live_choices = np.flatnonzero(live[cs] & allowed)
    stays = np.flatnonzero(allow_stay & stay_allowed)
    if not live[mdp.initial]:  # decided before any step
        prob = np.zeros(mdp.n_choices)
        stay = np.zeros(mdp.n_states)
        values = _exact(merged, prob, stay, quantities, cols)
        feasible = all(_meets(r, v) for r, v in zip(rows, values[1:], strict=True))
        return Solved(OPTIMAL if feasible else INFEASIBLE, values[0], prob, stay, values,
                      "decided at the initial state")
    states = np.flatnonzero(live)
    pos = np.full(mdp.n_states, -1, dtype=np.int64)
    pos[states] = np.arange(states.size)
    sub = mdp.matrix[live_choices]
    # flow rows: out - in = [s = initial]
    owner = sp.csr_array(
        (np.ones(live_choices.size), (pos[cs[live_choices]], np.arange(live_choices.size))),
        shape=(states.size, live_choices.size),
    )
    inflow = sp.csr_array(sub.T)[states]
    stay_cols = sp.csr_array(
        (np.ones(stays.size), (pos[stays], np.arange(stays.size))),
        shape=(states.size, stays.size),
    )
    a_eq = sp.csc_array(sp.hstack([owner - inflow, stay_cols], format="csc"))
    b_eq = np.zeros(states.size)
    b_eq[pos[mdp.initial]] = 1.0
    # value rows
    def vec(i: int) -> np.ndarray:
        per_choice, per_stay = cols[i]
        return np.concatenate([per_choice[live_choices], per_stay[stays]])

    ub_rows, ub_b = [], []
    for i, r in enumerate(rows, start=1):
        sign = 1.0 if r.sense == "<=" else -1.0
        ub_rows.append(sign * vec(i))
        ub_b.append(sign * r.bound)
    n_var = live_choices.size + stays.size
    a_ub = sp.csc_array(np.array(ub_rows).reshape(len(rows), n_var))
    c = vec(0) * (-1.0 if maximise else 1.0)
    answer = _clarabel(c, a_eq, b_eq, a_ub, np.array(ub_b, dtype=np.float64), tol, time_limit)
    v, z, message = answer.x, answer.z, answer.message
    if answer.status is Status.TIME_LIMIT:
        message = f"{message} (time limit {time_limit} s)"
    if v is None or z is None:
        return Solved(answer.status, float("nan"), None, None, (), message)
    lp_value = float(vec(0) @ v)
    prob, stay = _policy(mdp.n_choices, mdp.n_states, live_choices, stays, cs, v, allowed)
    prob, stay = _exits_kept(merged, prob, stay, live_choices, stays, v, allowed)
    values = _exact(merged, prob, stay, quantities, cols)
    # Clarabel's duals satisfy A'z + c = 0 with c = -objective for a maximum: the flow
    # rows' duals y and the rows' lam >= 0 (a cone's duals) give A_eq'y + A_ub'lam >=
    # objective, weak duality's certificate (mitld_lp.solvers.certify_dual)
    y = np.zeros(mdp.n_states)
    y[states] = z[:states.size] if maximise else -z[:states.size]
    lam = np.maximum(z[states.size:states.size + len(rows)], 0.0)
    return Solved(answer.status, lp_value, prob, stay, values, message, (y, lam), allowed)


def never_reaching(merged: Merged, rows: list[Row]) -> tuple[np.ndarray, np.ndarray]:
    """The choices and stays a policy may use under the rows ``P(phi) <= 0``: from the
    states where some policy keeps ``phi`` from holding for ever (a greatest fixed point
    on the graph), the choices whose support stays there and the stays where it has not
    held.  An interior-point LP spreads a little flow over every optimal column, so a
    zero bound met to its tolerance (3.8e-8 on bus_risk) would not hold exactly: the
    graph decides it instead.  Every choice and stay where no row is such a bound."""
    from mitld_lp.automata.joint import ACCEPTED

    mdp = merged.mdp
    cs = mdp.choice_state()
    allowed = np.ones(mdp.n_choices, dtype=bool)
    stays = np.ones(mdp.n_states, dtype=bool)
    m = sp.csr_array(mdp.matrix)
    owner = np.repeat(np.arange(mdp.n_choices), np.diff(m.indptr))
    for r in rows:
        q = r.quantity
        if q.kind != "prob" or r.sense != "<=" or r.bound > 0:
            continue
        sat = merged.verdicts[:, q.component] == ACCEPTED
        bad = sat.copy()
        bad[merged.truncated] = q.truncated > 0
        keep = ~bad
        while True:
            inside = np.ones(mdp.n_choices, dtype=bool)
            np.logical_and.at(inside, owner, keep[m.indices])
            ok = np.zeros(mdp.n_states, dtype=bool)
            np.logical_or.at(ok, cs, inside)
            nxt = keep & (ok | merged.absorbing)
            if np.array_equal(nxt, keep):
                break
            keep = nxt
        allowed &= ~keep[cs] | inside
        stays &= ~sat
    return allowed, stays


def _meets(row: Row, value: float, tol: float = 1e-9) -> bool:
    return value <= row.bound + tol if row.sense == "<=" else value >= row.bound - tol


def _policy(n_choices: int, n_states: int, live_choices: np.ndarray, stays: np.ndarray,
            cs: np.ndarray, v: np.ndarray, allowed: np.ndarray,
            ) -> tuple[np.ndarray, np.ndarray]:
    """``pi(c | s)`` and ``pi(stay | s)`` from the occupancy ``v``; shares below
    :data:`_ZERO_SHARE` of a state's visits are dropped (interior-point noise), and a
    state the solution never visits takes its first ``allowed`` choice (its first
    choice when none is)."""
    x = np.zeros(n_choices)
    x[live_choices] = np.maximum(v[: live_choices.size], 0.0)
    z = np.zeros(n_states)
    z[stays] = np.maximum(v[live_choices.size:], 0.0)
    total = np.bincount(cs, weights=x, minlength=n_states) + z
    x[x < _ZERO_SHARE * total[cs]] = 0.0
    z[z < _ZERO_SHARE * total] = 0.0
    total = np.bincount(cs, weights=x, minlength=n_states) + z
    empty = total <= 0
    first = np.zeros(n_choices, dtype=bool)
    starts = np.flatnonzero(np.diff(np.concatenate([[-1], cs])))  # first choice per state
    rank = np.where(allowed, np.arange(n_choices), n_choices)
    best = np.minimum.reduceat(rank, starts)
    first[np.where(best < n_choices, best, starts)] = True
    x[first & empty[cs]] = 1.0
    total[empty] = 1.0
    return x / total[cs], z / total


def _exits_kept(merged: Merged, prob: np.ndarray, stay: np.ndarray,
                live_choices: np.ndarray, stays: np.ndarray, v: np.ndarray,
                allowed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The policy with no state trapped.  Where its chain closes a class of states
    that reaches neither an absorbing state nor a stay, each state of the class plays
    instead the solution's choices (and stay) that leave the class, by their flows; a
    state the solution leaves by none plays its first allowed keep (a stay choice of
    the model) that leaves, else its first allowed choice that leaves; until no class
    is closed.  By flow conservation no solution flow enters a set of states its own
    choices never leave, so such a class is the interior point's circulation (a
    self-loop's flow of 5e-8 beside a keep's of nothing, at an information state the
    policy reaches by a path of tiny flows) or a state the solution never visits, never
    an optimum's; left in, the chain stays there for ever, and where the task is
    undecided its expected steps are infinite.  The states that only lead into such a
    class keep their choices: they leave it once it is mended."""
    from scipy.sparse.csgraph import connected_components

    from mitld_lp.solvers.graph import backward_reachable
    from mitld_lp.solvers.rows import gather_ranges

    mdp = merged.mdp
    n = mdp.n_states
    cs = mdp.choice_state()
    m = sp.csr_array(mdp.matrix)
    fixed = np.asarray(merged.absorbing, dtype=bool)
    x = np.zeros(mdp.n_choices)
    x[live_choices] = np.maximum(v[: live_choices.size], 0.0)
    z = np.zeros(n)
    z[stays] = np.maximum(v[live_choices.size:], 0.0)
    owner = np.repeat(np.arange(mdp.n_choices), np.diff(m.indptr))
    keep = np.asarray(merged.keep, dtype=bool)
    prob, stay = prob.copy(), stay.copy()
    while True:
        used = np.flatnonzero((prob > 0) & ~fixed[cs])
        lo, hi = m.indptr[used], m.indptr[used + 1]
        src = np.repeat(cs[used], hi - lo)
        dst = np.asarray(m.indices[gather_ranges(lo, hi)], dtype=np.int64)
        trapped = ~fixed & ~backward_reachable(n, src, dst, fixed | (stay > 0))
        if not trapped.any():
            return prob, stay
        _, comp = connected_components(sp.csr_array(
            (np.ones(src.size), (src, dst)), shape=(n, n)), directed=True,
            connection="strong")
        closed = np.ones(comp.max() + 1, dtype=bool)
        closed[comp[src[comp[src] != comp[dst]]]] = False
        at = trapped & closed[comp]  # the closed classes (every trapped path ends in one)
        leaves = np.zeros(mdp.n_choices, dtype=bool)  # a successor outside its class
        np.logical_or.at(leaves, owner, comp[m.indices] != comp[cs[owner]])
        leaves &= at[cs]
        flow = np.where(leaves, x, 0.0)
        out = np.bincount(cs, weights=flow, minlength=n) + np.where(at, z, 0.0)
        for pick in (leaves & allowed & keep, leaves & allowed):
            bare = np.bincount(cs, weights=flow, minlength=n) <= 0
            none = np.flatnonzero(pick & bare[cs] & (out[cs] <= 0))
            flow[none[np.flatnonzero(np.diff(np.concatenate([[-1], cs[none]])))]] = 1.0
        z_out = np.where(at & (out > 0), z, 0.0)
        total = np.bincount(cs, weights=flow, minlength=n) + z_out
        mended = at & (total > 0)
        if not mended.any():  # no way out of what is left: the certificate says so
            return prob, stay
        mine = mended[cs]
        prob[mine] = flow[mine] / total[cs[mine]]
        stay[mended] = z_out[mended] / total[mended]


def _exact(merged: Merged, prob: np.ndarray, stay: np.ndarray, quantities: list[Quantity],
           cols: list[tuple[np.ndarray, np.ndarray]]) -> tuple[float, ...]:
    asked = [(pc, ps, _counts_steps(q)) for q, (pc, ps) in zip(quantities, cols, strict=True)]
    return evaluate(merged, prob, stay, asked).values


def certified_value(merged: Merged, prob: np.ndarray, stay: np.ndarray, q: Quantity,
                    name: str, *, costs: np.ndarray | None = None,
                    eta: float | None = None) -> Any:
    """Bounds in exact arithmetic on ``q`` under the randomised policy ``prob`` /
    ``stay`` (:func:`mitld_lp.solvers.certify_mixture.mixture_bounds`): a probability
    is the verdict of the absorbing state reached (truncation worth ``q.truncated``) or
    of staying for ever; steps and costs a reward per choice."""
    from mitld_lp.automata.joint import ACCEPTED
    from mitld_lp.solvers.certify_mixture import mixture_bounds
    from mitld_lp.solvers.rounding import ETA

    mdp = merged.mdp
    per_choice, per_stay = columns(merged, q, costs)
    if q.kind == "prob":
        sat = (merged.verdicts[:, q.component] == ACCEPTED).astype(np.float64)
        fixed = np.where(merged.absorbing, sat, 0.0)
        fixed[merged.truncated] = q.truncated
        reward = np.zeros(mdp.n_choices)
    else:
        fixed = np.zeros(mdp.n_states)
        reward = per_choice
    return mixture_bounds(mdp, prob, stay, merged.absorbing, fixed, reward, per_stay, name,
                          counts_steps=_counts_steps(q), undecided=merged.undecided,
                          eta=ETA if eta is None else eta)
