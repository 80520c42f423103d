"""Monte-Carlo rollouts (``mitld_lp.running.simulate``): the Wilson interval against its defining
equation, the ends of the interval at true values 0 and 1, and argument checks."""

from __future__ import annotations

import pytest

from mitld_lp import GridWorld, Model, synthesize
from mitld_lp.running.simulate import simulate
from mitld_lp.util.rollouts import wilson as _wilson

Z = 1.959963984540054


@pytest.mark.parametrize("n", [1, 7, 40, 333, 1000])
def test_wilson_bounds_solve_the_score_equation(n):
    # the Wilson bounds are the roots p of (k/n - p)^2 = z^2 p (1 - p) / n
    for k in range(1, n):
        for p in _wilson(k, n):
            assert (k / n - p) ** 2 == pytest.approx(Z * Z * p * (1 - p) / n, rel=1e-9)


def test_wilson_interval_contains_the_end_point_it_contains_in_exact_arithmetic():
    for n in range(1, 2000):
        low, high = _wilson(0, n)
        assert low == 0.0 and 0.0 < high < 1.0
        low, high = _wilson(n, n)
        assert high == 1.0 and 0.0 < low < 1.0
        # the other end, from the score equation with k = 0: p = z^2 / (n + z^2)
        assert _wilson(0, n)[1] == pytest.approx(Z * Z / (n + Z * Z), rel=1e-12)


def _model_and_result(spec: str):
    world = GridWorld.make(4, 1, start=(0, 0), regions={"A": [(3, 0)]})  # no slip
    model = Model.from_game(world, spec)
    return model, synthesize(model)


@pytest.mark.parametrize(
    ("spec", "value", "runs"),
    [("F[0,3] A", 1.0, 13), ("F[0,2] A", 0.0, 12)],  # A is 3 moves east
)
def test_a_true_value_of_exactly_0_or_1_is_inside_the_interval(spec, value, runs):
    model, r = _model_and_result(spec)
    assert r.lower == r.upper == value
    sim = simulate(model, r.controller, runs=runs, seed=1)
    assert sim.successes == runs * value
    assert sim.ci_low <= r.upper and r.lower <= sim.ci_high  # what the CLI calls consistent


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"runs": -5}, r"runs: must be in 1\.\.100,000,000, got -5"),
        ({"runs": 0}, "runs: must be in 1"),
        ({"runs": 10**12}, "runs: must be in 1"),
        ({"runs": 2.5}, "runs: must be an integer, got 2.5"),
        ({"runs": True}, "runs: must be an integer"),
        ({"max_steps": -1}, r"max_steps: must be in 0\.\.1,000,000, got -1"),
        ({"max_steps": 10**7}, r"max_steps: must be in 0\.\.1,000,000, got 10000000"),
        ({"seed": -1}, "seed: must be >= 0, got -1"),
    ],
)
def test_bad_arguments_are_refused_naming_the_argument(kwargs, message):
    model, r = _model_and_result("F[0,3] A")
    with pytest.raises(ValueError, match=message):
        simulate(model, r.controller, **kwargs)
