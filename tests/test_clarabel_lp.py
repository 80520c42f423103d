"""The one Clarabel call (:mod:`mitld_lp.solvers.clarabel_lp`), its one status map, the
solve options' deadline, and what an ``AlmostSolved`` constrained LP becomes: LPs solved
by hand, statuses named by Clarabel's own enum, the hand-worked two-routes world."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.model import Model
from mitld_lp.solvers import Layout, Status, solve_lp
from mitld_lp.solvers import constrained as constrained_lp
from mitld_lp.solvers.clarabel_lp import CLARABEL_STATUS, solve_clarabel
from mitld_lp.solvers.constrained_model import Quantity
from mitld_lp.solvers.options import Deadline
from mitld_lp.synthesis import synthesize_constrained
from mitld_lp.testing import two_routes_world

clarabel = pytest.importorskip("clarabel")


def test_every_clarabel_status_word_has_one_meaning() -> None:
    words = {n for n in dir(clarabel.SolverStatus) if not n.startswith("_")}
    assert words == set(CLARABEL_STATUS)
    assert CLARABEL_STATUS["AlmostSolved"] is Status.INACCURATE
    assert CLARABEL_STATUS["MaxIterations"] is Status.MAX_ITERATIONS
    assert CLARABEL_STATUS["DualInfeasible"] is Status.UNBOUNDED


def _box() -> tuple[np.ndarray, sp.csc_array, np.ndarray]:
    """max x1 + 2 x2  s.t.  x1 + x2 = 1, x >= 0: by hand x = (0, 1) and the equality's
    dual 2 (the objective's rate along the row), the sign rows' duals (1, 0)."""
    a = sp.csc_array(np.array([[1.0, 1.0], [-1.0, 0.0], [0.0, -1.0]]))
    return -np.array([1.0, 2.0]), a, np.array([1.0, 0.0, 0.0])


def test_a_hand_lp_and_its_duals() -> None:
    q, a, b = _box()
    answer = solve_clarabel(q, a, b, zero=1, nonneg=2, settings={"tol_feas": 1e-10})
    assert answer.status is Status.OPTIMAL and answer.word == "Solved"
    assert answer.message == "clarabel: Solved" and answer.iterations > 0
    assert answer.x is not None and answer.z is not None
    assert np.allclose(answer.x, [0.0, 1.0], atol=1e-7)
    assert np.allclose(answer.z, [2.0, 1.0, 0.0], atol=1e-7)  # q + A'z = 0


def test_failures_are_statuses_in_the_one_vocabulary() -> None:
    q, a, b = _box()
    # x1 + x2 = 1 and x1 + x2 = 2: no point
    two = sp.csc_array(np.array([[1.0, 1.0], [1.0, 1.0], [-1.0, 0.0], [0.0, -1.0]]))
    infeasible = solve_clarabel(q, two, np.array([1.0, 2.0, 0, 0]), zero=2, nonneg=2,
                                settings={})
    assert infeasible.status is Status.INFEASIBLE and infeasible.x is None
    # max x1 with x1 >= 0 only: unbounded
    unbounded = solve_clarabel(-np.ones(1), sp.csc_array(-np.eye(1)), np.zeros(1), zero=0,
                               nonneg=1, settings={})
    assert unbounded.status is Status.UNBOUNDED and unbounded.word == "DualInfeasible"
    stopped = solve_clarabel(q, a, b, zero=1, nonneg=2, settings={"max_iter": 1})
    assert stopped.status is Status.MAX_ITERATIONS and stopped.x is None
    unknown = solve_clarabel(q, a, b, zero=1, nonneg=2, settings={"no_such": 1})
    assert unknown.status is Status.FAILED and "no_such" in unknown.message


def test_the_deadline_is_the_one_clock() -> None:
    assert Deadline().left() is None and not Deadline().passed()
    assert Deadline.after(None).left() is None
    gone = Deadline.after(0.0)
    assert gone.passed() and gone.left() == 0.0
    later = Deadline.after(100.0, start=time.perf_counter())
    left = later.left()
    assert left is not None and 99.0 < left <= 100.0 and not later.passed()


def test_layout_is_a_named_choice() -> None:
    from mitld_lp.testing import random_mdp

    mdp = random_mdp(40, seed=3, locality=None)
    by_name = solve_lp(mdp, mdp.target, layout="whole")
    by_member = solve_lp(mdp, mdp.target, layout=Layout.WHOLE)
    assert by_name.value == by_member.value and "block" not in by_name.message
    with pytest.raises(ValueError, match="nope"):
        solve_lp(mdp, mdp.target, layout="nope")


def _solved_as(monkeypatch: pytest.MonkeyPatch, word: str):
    """The two-routes world under ``P(F hazard) <= 0.15``, every Clarabel answer of the
    constrained LP reported as ``word`` (its solution kept when the word has one)."""
    real = constrained_lp.solve_clarabel
    status = CLARABEL_STATUS[word]

    def said(*args, **kwargs):
        answer = real(*args, **kwargs)
        if not status.has_solution:
            return replace(answer, status=status, word=word, x=None, z=None)
        return replace(answer, status=status, word=word)

    monkeypatch.setattr(constrained_lp, "solve_clarabel", said)
    return synthesize_constrained(Model.from_game(two_routes_world(), "F goal"),
                                  ["P(F hazard) <= 0.15"])


def test_an_almost_solved_constrained_lp_is_inaccurate_and_its_certificate_decides(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # by hand (tests/test_constraints.py): P(hazard) = 0.3 lam <= 0.15 gives lam = 1/2
    # and P(goal) = 0.9 / 2 + 0.5 / 2 = 0.7
    r = _solved_as(monkeypatch, "AlmostSolved")
    assert r.status == "optimal" and r.certified
    assert r.lower <= 0.7 <= r.upper and r.upper - r.lower < 1e-6
    lp_checks = {c.name: c for c in r.checks if c.name.endswith(" LP")}
    assert lp_checks["lower LP"].passed
    assert "AlmostSolved" in lp_checks["lower LP"].detail
    lp = constrained_lp.optimise(r.merged, Quantity("prob", 0, 0.0), True, [])
    assert lp.status is Status.INACCURATE and lp.prob is not None


def test_an_iteration_limit_of_the_constrained_lp_is_said_as_one(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    r = _solved_as(monkeypatch, "MaxIterations")
    assert r.status == "max_iterations" and not r.certified and r.controller is None
