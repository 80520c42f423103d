"""The interval iteration's policy made at its first read (``IterationResult.policy``):
the same policy as the one made eagerly, greedy on the quotient's bound and lifted;
made once, read-only, resolved when pickled; and a clear error where a solve let it go
(the plain route, once the LP's policy is the answer and the quotient is released)."""

from __future__ import annotations

import pickle
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from conftest import build_mdp

from mitld_lp.solvers import iteration as I
from mitld_lp.solvers.evaluation import evaluate_policy
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.quotient import lift_policy, reduce
from mitld_lp.solvers.reduced import greedy_choices
from mitld_lp.testing import random_mdp

STORM = 0.9244053  # Storm's value of models/bus_grid.toml (tests/test_lp.py)


def _with_eager(monkeypatch: pytest.MonkeyPatch) -> list[np.ndarray]:
    """The iteration's results built with, beside each, the policy made eagerly as it
    was before (greedy on the pass's bound, a maximum's lower and a minimum's upper,
    lifted), at the moment the result is built: collected in the returned list."""
    made: list[np.ndarray] = []
    build = I._result

    def result(mdp, q, bounds, *args):
        known = bounds[:, 0] if q.sense is Sense.MAX else bounds[:, 1]
        made.append(lift_policy(mdp, q, greedy_choices(q, known.copy())))
        return build(mdp, q, bounds, *args)

    monkeypatch.setattr(I, "_result", result)
    return made


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_lazy_policy_is_the_eager_one(seed: int, sense: Sense,
                                      monkeypatch: pytest.MonkeyPatch) -> None:
    eager = _with_eager(monkeypatch)
    mdp = random_mdp(300, seed=seed, locality=None if seed % 2 else 12)
    q = reduce(mdp, mdp.target, sense=sense)
    r = interval_iteration(mdp, mdp.target, quotient=q, sense=sense, tol=1e-10,
                           precision=None, gap="max")
    assert callable(r.greedy)  # not made by the iteration
    (want,) = eager
    got = r.policy
    assert got.dtype == np.int64 and got.tobytes() == want.tobytes()
    assert r.policy is got and not got.flags.writeable  # made once, kept read-only
    # and it is a good policy: its value within the iteration's bracket where it acts
    value = evaluate_policy(mdp, mdp.target, got)
    if sense is Sense.MAX:
        assert np.all(value >= r.lower - 1e-9) and np.all(value <= r.upper + 1e-9)
    else:
        assert np.all(value <= r.upper + 1e-9) and np.all(value >= r.lower - 1e-9)


def test_lazy_policy_on_a_hand_mdp() -> None:
    """State 0 chooses between a sure step to the target and a fair coin between the
    target and a sink (values 1 and 1/2, by hand): the greedy policy takes the sure
    step, its first choice."""
    half = float(Fraction(1, 2))
    mdp = build_mdp([[("sure", {1: 1.0}), ("coin", {1: half, 2: half})], [], []],
                    target=[1], sink=[2])
    r = interval_iteration(mdp, mdp.target, tol=1e-12)
    assert not callable(r.greedy)  # made: the quotient was the call's own
    assert r.policy[0] == 0 and r.value_lower == r.value_upper == 1.0
    assert r.policy[1] == -1  # the target: no choice


def test_pickled_and_released() -> None:
    mdp = random_mdp(120, seed=7)
    q = reduce(mdp, mdp.target)
    r = interval_iteration(mdp, mdp.target, quotient=q, tol=1e-10)
    back = pickle.loads(pickle.dumps(r))  # the policy made to pickle it
    assert not callable(back.greedy) and np.array_equal(back.policy, r.policy)
    fresh = interval_iteration(mdp, mdp.target, quotient=q, tol=1e-10)
    assert callable(fresh.greedy)
    gone = fresh.without_greedy()
    assert gone.greedy is None and np.array_equal(gone.lower, fresh.lower)
    with pytest.raises(AttributeError, match="not kept"):
        gone.policy  # noqa: B018
    assert r.without_greedy() is r  # made already: kept


def test_plain_route_reads_the_iteration_policy_only_without_the_lp() -> None:
    """The plain route with the LP: the iteration's policy let go unread with the
    quotient; with method "vi" it is the answer's policy (made while the quotient
    lived).  Both brackets hold Storm's value of the bundled grid."""
    from mitld_lp import load_model, synthesize

    model = load_model(Path(__file__).resolve().parent.parent / "models" / "bus_grid.toml")
    with_lp = synthesize(model)
    low = with_lp.lower_model
    assert low.lp is not None and low.iteration.greedy is None
    vi = synthesize(model, method="vi")
    low_vi = vi.lower_model
    assert low_vi.lp is None and not callable(low_vi.iteration.greedy)
    assert np.array_equal(low_vi.policy, low_vi.iteration.policy)
    for r in (with_lp, vi):
        assert r.certified
        assert r.lower <= STORM + 1e-7 and STORM - 1e-7 <= r.upper
