"""The policy is optimal in every state, not only where it goes, on every route (the
decomposed LP, one monolithic LP, interval iteration), and certification checks it over
all states (one Bellman sweep).  The reference is value iteration written here on the
product's matrix, run to a fixed point."""

from __future__ import annotations

import numpy as np
import pytest

from mitld_lp import loads_model, synthesize
from mitld_lp.solvers import lp as lp_module

# A 2x3 grid where one monolithic LP used to leave a state the optimal policy never
# visits with a worse action (W, worth 0.368, where S gives 0.411), and certify it.
GRID = """
name = "g23"
spec = "D[geometric(0.8)] e1 & F(e1 & F<=2 A)"
[grid]
size = [2, 3]
start = [1, 0]
slip = 0.25
[regions]
A = [[0, 0]]
"""


def optimal_values(mdp, target) -> np.ndarray:
    """max_c P(c) . V iterated from 0 (the least fixed point) until it stops moving."""
    v = np.where(target, 1.0, 0.0)
    for _ in range(100_000):
        new = np.where(target, 1.0, np.maximum.reduceat(mdp.matrix @ v, mdp.row_groups[:-1]))
        if np.max(np.abs(new - v)) < 1e-15:
            return new
        v = new
    raise AssertionError("value iteration did not settle")


@pytest.mark.parametrize("route", [dict(decompose=True), dict(decompose=False),
                                   dict(method="vi")], ids=["decomposed", "monolithic", "vi"])
def test_the_policy_is_optimal_in_every_state(route) -> None:
    r = synthesize(loads_model(GRID), **route)
    mdp = r.mdp
    best = optimal_values(mdp, mdp.target)
    mine = np.where(mdp.target, 1.0, r.lower_model.policy_values)
    assert r.certified
    assert np.max(np.abs(mine - best)) < 1e-9
    # the state of the report: pending e1 at (0, 2) before the automaton moved
    s = next(i for i, st in enumerate(mdp.states) if getattr(st, "game", None) == (0, 2)
             and st.pending == frozenset({"e1"}) and st.automaton == 0)
    assert mine[s] == pytest.approx(best[s], abs=1e-9)


def test_a_policy_optimal_only_where_it_goes_is_not_certified(monkeypatch) -> None:
    """Without the crossover, the one LP's policy is wrong off its path; the Bellman
    check over all states must catch it."""
    monkeypatch.setattr(lp_module, "crossover", lambda q, start: start)
    r = synthesize(loads_model(GRID), decompose=False)
    assert not r.certified
    assert {c.name for c in r.failed_checks} == {"policy optimal in every state"}
