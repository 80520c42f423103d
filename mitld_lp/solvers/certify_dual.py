r"""An upper bound on a constrained optimum that holds in exact arithmetic: weak duality.

The constrained LP (:mod:`mitld_lp.solvers.constrained`) maximises the task's
probability ``w_0' v + u_0' z`` over occupancies ``v >= 0`` (per choice) and stays
``z >= 0`` (per state) subject to the flow rows ``A_eq (v, z) = e_init`` and the rows
``s_i (w_i' v + u_i' z) <= s_i b_i`` (``s_i = +1`` for ``<=``, ``-1`` for ``>=``).  For
any ``y`` and ``lam >= 0`` with ``A_eq' y + A_ub' lam >= (w_0, u_0)`` column by
column, every feasible point has value at most ``y(init) + sum_i lam_i s_i b_i``.  With
a probability's weight ``w_k(c) = sum_j p(c, j) a_k(j)`` over the absorbing states ``j``
(``a_k`` its verdict there) and a step or cost row's ``w_k(c)`` the charge of choice
``c``, a column's inequality reads

.. math:: Y(s) \ge R(c) + \sum_j p(c, j)\, Y(j), \qquad Y(s) \ge F(s) \text{ (a stay)}

with ``Y = y`` on the live states, ``Y(j) = a_0(j) - sum_i lam_i s_i a_i(j)`` on the
absorbing ones, ``R(c) = -sum_i lam_i s_i w_i(c) <= 0`` over the step and cost rows and
``F(s) = u_0(s) - sum_i lam_i s_i u_i(s)``: ``Y`` is a pre-fixed point of a Bellman
operator, checked as the certificates of :mod:`mitld_lp.solvers.certify` are (shifted
by a constant ``K`` to be nonnegative, which the rows' exact sums of 1 leave exact;
each expectation bounded above by :func:`~mitld_lp.solvers.rounding.above`, a choice
whose support lies below ``Y(s)`` passing as a convex combination).  The candidate is
the LP's own dual solution; a state where it falls short (the LP's tolerance) is raised
to what its choices need, levels downstream first, an end component's states together.
"""

from __future__ import annotations

from fractions import Fraction
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.checks import Check
from mitld_lp.solvers.graph import maximal_end_components
from mitld_lp.solvers.rounding import UNIT, above, float_up, rounding, support_extreme
from mitld_lp.solvers.rows import gather_ranges, row_entries

__all__ = ["dual_bound"]

ROUNDS = 64


def dual_bound(merged: Any, quantities: list[Any], senses: list[str], bounds: list[float],
               duals: tuple[np.ndarray, np.ndarray], stay_ok: np.ndarray,
               costs: np.ndarray | None, eta: float,
               allowed: np.ndarray | None = None) -> tuple[float, Check]:
    """An upper bound on the maximum of ``quantities[0]`` subject to the rows
    ``quantities[i] senses[i-1] bounds[i-1]`` over ``merged``'s randomised policies with
    stays (allowed where ``stay_ok``), from the LP's ``duals`` (module docs).
    ``allowed``: the choices a feasible policy may take at all (a choice that may reach
    ``phi`` under ``P(phi) <= 0``: every policy using it is infeasible, so its column
    is not in the LP and needs no dual inequality)."""
    from mitld_lp.automata.joint import ACCEPTED
    from mitld_lp.solvers.certify import support_layers
    from mitld_lp.solvers.constrained_model import columns

    name = "upper bound: the constrained optimum (weak duality)"
    mdp = merged.mdp
    m = sp.csr_array(mdp.matrix)
    n = mdp.n_states
    cs = mdp.choice_state()
    live = ~np.asarray(merged.absorbing, dtype=bool)
    y, lam = duals
    signs = [1.0 if s == "<=" else -1.0 for s in senses]
    # the absorbing states' values, exactly, and the stays' and the charges' terms
    ends = np.flatnonzero(~live)
    terminal = {int(j): Fraction(0) for j in ends}
    floor = np.full(n, -np.inf)
    stays = np.asarray(stay_ok, dtype=bool) & live
    floor[stays] = 0.0
    spread = np.zeros(n)  # the sum of the stay terms' magnitudes: their rounding's scale
    charge = np.zeros(m.shape[0])
    weights = [(1.0, quantities[0])] + [(-float(lam[i]) * signs[i], q)
                                        for i, q in enumerate(quantities[1:])]
    for wt, q in weights:
        if wt == 0.0:
            continue
        if q.kind == "prob":
            sat = (merged.verdicts[:, q.component] == ACCEPTED).astype(np.float64)
            value = np.where(merged.absorbing, sat, 0.0)
            value[merged.truncated] = q.truncated
            for j in ends.tolist():
                terminal[j] += Fraction(wt) * Fraction(float(value[j]))
            floor[stays] += wt * sat[stays]
            spread[stays] += abs(wt) * sat[stays]
        else:  # a step or cost row, a "<=" one: its weight is -lam, a charge
            charged, _ = columns(merged, q, costs)
            charge += -wt * charged
    k = len(weights) + 2
    # R(c) = -charge(c) <= 0, bounded above (charges within eta, k roundings)
    reward = -charge * (1.0 - eta - 4.0 * k * UNIT)
    floor_up = floor + 4.0 * k * UNIT * spread
    lowest = min([0.0, *(float(t) for t in terminal.values()),
                  float(np.min(floor_up[stays], initial=0.0)),
                  float(np.min(y[live], initial=0.0))])
    shift = float_up(-Fraction(lowest)) + 1.0  # every value >= 1: no underflow near 0
    x = np.zeros(n)
    x[live] = y[live] + shift  # a candidate: any float will do
    for j, t in terminal.items():  # the absorbing states' values: exact, rounded up
        x[j] = float_up(t + Fraction(shift))
    floors = np.where(stays, np.nextafter(floor_up + shift, np.inf), -np.inf)
    x = np.maximum(x, floors)
    rnd = rounding(m, eta)
    layers = support_layers(mdp)
    level_of = np.asarray(layers[1])[np.asarray(layers[0])]
    mecs = maximal_end_components(mdp, live).mec_of
    if allowed is not None:  # a closed choice: no inequality to meet
        reward = np.where(allowed, reward, -np.inf)
    settled = _settle(m, np.asarray(mdp.row_groups, dtype=np.int64), cs, rnd, x, reward,
                      floors, live, level_of, mecs)
    if not settled:
        return float("inf"), Check(name, False, (
            "the LP's dual solution did not settle into a checked pre-fixed point; no "
            "upper bound is certified"))
    bound = Fraction(float(x[mdp.initial])) - Fraction(shift) + sum(
        (Fraction(float(lam[i])) * Fraction(signs[i]) * Fraction(float(bounds[i]))
         for i in range(len(bounds))), Fraction(0))
    upper = float_up(bound)
    return upper, Check(name, True, (
        f"the LP's dual solution, raised where it fell short, is a pre-fixed point of the "
        f"Lagrangian Bellman operator checked in exact arithmetic on {int(live.sum())} "
        f"states and every choice and stay: {upper!r}"))


def _settle(m: sp.csr_array, groups: np.ndarray, cs: np.ndarray, rnd: Any, x: np.ndarray,
            reward: np.ndarray, floors: np.ndarray, live: np.ndarray, level_of: np.ndarray,
            mecs: np.ndarray) -> bool:
    """Raise ``x`` on the live states, levels downstream first, until every choice and
    stay is below it (rounding up); False when a level does not settle."""
    states_all = np.flatnonzero(live)
    order = np.argsort(level_of[states_all], kind="stable")
    states_all = states_all[order]
    lv = level_of[states_all]
    cuts = np.flatnonzero(np.diff(lv)) + 1
    for states in np.split(states_all, cuts):
        for _ in range(ROUNDS):
            need = _needed(m, groups, rnd, x, states, reward, floors)
            low = need > x[states]
            if not low.any():
                break
            x[states[low]] = need[low]
            inside = mecs[states]
            touched = np.unique(inside[low & (inside >= 0)])
            for mec in touched.tolist():  # an end component's states together
                members = states[inside == mec]
                x[members] = np.max(x[members])
        else:
            return False
    return True


def _needed(m: sp.csr_array, groups: np.ndarray, rnd: Any, x: np.ndarray,
            states: np.ndarray, reward: np.ndarray, floors: np.ndarray) -> np.ndarray:
    """Per state: the least value its choices and its stay allow (rounded up)."""
    rows = gather_ranges(groups[states], groups[states + 1])
    local, cols, vals = row_entries(m, rows)
    sums = np.bincount(local, weights=vals * x[cols], minlength=rows.size)
    each = np.nextafter(reward[rows] + above(rnd, rows, sums), np.inf)
    # R <= 0: a choice's value is at most the largest value of its support (a closed
    # choice, R = -inf, asks nothing)
    each = np.minimum(each, np.where(np.isfinite(reward[rows]),
                                     support_extreme(m, rows, x, largest=True), -np.inf))
    starts = np.concatenate([[0], np.cumsum(groups[states + 1] - groups[states])[:-1]])
    return np.maximum(np.maximum.reduceat(each, starts), floors[states])
