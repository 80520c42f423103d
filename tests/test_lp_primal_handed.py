"""The LP's primal point (the policy's flow over the quotient's levels) made only for the
controller's model: ``solve_lp(..., primal=False)`` gives the same values, policy and
dual objective to the bit and a NaN primal objective, and a two-model synthesis asks for
the primal point of the controller's model alone (the lower truncation model of a
maximum, the upper one of a minimum), the one the report reads."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mitld_lp import GridWorld, Model, synthesize
from mitld_lp.report import models_summary
from mitld_lp.solvers import analysis
from mitld_lp.solvers import lp as L
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.testing import random_mdp


def _reach_by_sweeps(mdp, target: np.ndarray, policy: np.ndarray) -> np.ndarray:
    """The probability of reaching ``target`` under the deterministic ``policy``, by
    plain value iteration from 0 written here (a dense loop over the policy's rows),
    not by the package's evaluation."""
    rows = np.asarray(policy)
    m = mdp.matrix.toarray()
    x = target.astype(np.float64)
    for _ in range(20_000):
        nxt = np.where(target, 1.0, 0.0)
        live = (rows >= 0) & ~target
        nxt[live] = m[rows[live]] @ x
        if np.max(np.abs(nxt - x)) < 1e-15:
            break
        x = nxt
    return x


@pytest.mark.parametrize("everywhere", [False, True])
@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_no_primal_same_answer_to_the_bit(seed: int, sense: Sense, everywhere: bool) -> None:
    mdp = random_mdp(150, seed=seed, locality=None if seed % 2 else 8)
    q = analysis.analyse(mdp, mdp.target, sense=sense)[0]
    it = interval_iteration(mdp, mdp.target, quotient=q, sense=sense, tol=1e-10,
                            precision=None, gap="max")
    got = {p: L.solve_lp(mdp, mdp.target, quotient=q, sense=sense,
                         bounds=(it.lower, it.upper), flows=False, primal=p,
                         everywhere=everywhere)
           for p in (True, False)}
    full, bare = got[True], got[False]
    assert bare.status is full.status
    assert bare.policy.tobytes() == full.policy.tobytes()
    assert bare.values.tobytes() == full.values.tobytes()
    for f in ("value", "dual_objective"):
        assert np.float64(getattr(bare, f)).tobytes() == np.float64(getattr(full, f)).tobytes()
    assert math.isnan(bare.primal_objective)
    if q.initial < 0 or everywhere:  # no LP, or an objective over every state
        return
    # the primal objective made is the policy's own reach probability from the start,
    # by sweeps written here; and the value (strong duality at the optimum)
    reach = _reach_by_sweeps(mdp, np.asarray(mdp.target), full.policy)[mdp.initial]
    assert abs(full.primal_objective - reach) <= 1e-7
    assert abs(full.primal_objective - full.value) <= 1e-7


def test_flows_need_the_primal_point() -> None:
    mdp = random_mdp(40, seed=1)
    with pytest.raises(ValueError, match="flows=True needs primal=True"):
        L.solve_lp(mdp, mdp.target, primal=False)


@pytest.mark.parametrize("objective", ["max", "min"])
def test_two_models_only_the_controller_makes_its_flow(objective: str) -> None:
    """A truncated Poisson event: two models.  The controller's (``lower_model``, the
    upper truncation model for a minimum) has its primal objective, equal to its value
    at the start (an everywhere LP's objective is over more states, so only where it
    is an initial-state LP); the bound's model has NaN, and the report reads the
    controller's."""
    world = GridWorld.make(4, 1, start=(0, 0), slip=0.1, regions={"A": [(3, 0)]})
    r = synthesize(Model.from_game(world, "D[poisson(2.0)] b & F(b & F[0,1] A)"),
                   epsilon=0.05, objective=objective)
    assert r.certified, r.failed_checks
    assert r.lower_model is not r.upper_model
    mine, other = r.lower_model.lp, r.upper_model.lp
    assert math.isfinite(mine.primal_objective)
    assert abs(mine.primal_objective - mine.dual_objective) <= 1e-7
    assert math.isnan(other.primal_objective)
    assert math.isfinite(other.dual_objective)
    assert models_summary(r)["lp"]["primal_objective"] == mine.primal_objective
    # the bracket is the task's: a maximum's lower end is the controller's value
    value = r.lower if objective == "max" else r.upper
    assert abs(mine.value - value) <= 1e-7
