"""The policy jump's look-ahead (mitld_lp.solvers.policy_jump.improve_ahead) and the
NumPy sweeps' earlier forecast (mitld_lp.solvers.iteration._NUMPY_CHUNK): the policy
iteration still ends at the optimum, in fewer factorisations where plain policy
iteration carries an improvement one step a round, and the interval iteration's
bracket still holds the exact value.

Expected values from independent routes: every deterministic policy of a small block
evaluated in exact rational arithmetic (the optimum is the best over them, state by
state), and Storm's exact engine on the same models written in PRISM."""

from __future__ import annotations

import itertools
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import build_mdp
from storm_exact import storm_rational
from test_sweep_forecast import PRISM as RUIN
from test_sweep_forecast import _ruin

from mitld_lp import defaults
from mitld_lp.solvers import Status, interval_iteration, iteration
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.policy_jump import improve_ahead
from mitld_lp.solvers.topological import Block, Factors


def _block(rows: list[list[tuple[dict[int, Fraction], Fraction]]]):
    """A block from per-state choices ``({successor: p}, exit reward)`` (exact), as the
    policy jump sees it (its ``outer`` unused here), with the exact choices kept."""
    n = len(rows)
    r, c, v, reward, starts = [], [], [], [], []
    for choices in rows:
        starts.append(len(reward))
        for moves, gain in choices:
            for t, p in moves.items():
                r.append(len(reward)), c.append(t), v.append(float(p))
            reward.append(gain)
    m = len(reward)
    inner = sp.csr_array((v, (r, c)), shape=(m, n))
    outer = sp.csr_array((m, 1))
    block = Block(np.arange(n), np.arange(m), inner, outer, np.array(starts, dtype=np.int64),
                  np.array([float(g) for g in reward]))
    return block, reward


def _exact_values(rows, pick) -> list[Fraction]:
    """The values of the policy ``pick`` (a choice per state), ``x = r + M x`` solved by
    Gauss-Jordan elimination in Fractions."""
    n = len(rows)
    a = [[Fraction(int(i == j)) for j in range(n)] + [Fraction(0)] for i in range(n)]
    for i, k in enumerate(pick):
        moves, gain = rows[i][k]
        for t, p in moves.items():
            a[i][t] -= p
        a[i][n] = gain
    for col in range(n):
        piv = next(i for i in range(col, n) if a[i][col] != 0)
        a[col], a[piv] = a[piv], a[col]
        f = a[col][col]
        a[col] = [x / f for x in a[col]]
        for i in range(n):
            if i != col and a[i][col] != 0:
                g = a[i][col]
                a[i] = [x - g * y for x, y in zip(a[i], a[col], strict=True)]
    return [a[i][n] for i in range(n)]


def _exact_optimum(rows, sense: Sense) -> list[Fraction]:
    """The optimum, state by state, over every deterministic policy."""
    best: list[Fraction] | None = None
    for pick in itertools.product(*(range(len(ch)) for ch in rows)):
        values = _exact_values(rows, pick)
        best = values if best is None else [
            (max if sense is Sense.MAX else min)(b, x) for b, x in zip(best, values,
                                                                      strict=True)]
    assert best is not None
    return best


def _random_rows(rng: np.random.Generator, n: int):
    """A strongly connected block (a ring kept in every choice) of ``n`` states with two
    or three choices each, every choice leaving it with some probability."""
    rows = []
    for s in range(n):
        choices = []
        for _ in range(int(rng.integers(2, 4))):
            stay = Fraction(int(rng.integers(50, 95)), 100)
            other = int(rng.integers(0, n))
            ring = stay * Fraction(int(rng.integers(30, 90)), 100)
            moves = {(s + 1) % n: ring}
            moves[other] = moves.get(other, Fraction(0)) + (stay - ring)
            gain = (1 - stay) * Fraction(int(rng.integers(0, 101)), 100)
            choices.append((moves, gain))
        rows.append(choices)
    return rows


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", range(3))
def test_the_look_ahead_ends_at_every_policys_exact_optimum(sense, seed) -> None:
    rng = np.random.default_rng(seed)
    rows = _random_rows(rng, 5)
    block, _ = _block(rows)
    exact = _exact_optimum(rows, sense)
    start = np.asarray(block.starts)  # every state's first choice
    chosen, v, t = improve_ahead(block, block.to_target, start, sense=sense)
    for s, value in enumerate(exact):
        assert abs(Fraction(float(v[s])) - value) <= Fraction(1, 10**13), (s, v[s], value)
    # the policy returned is the one whose values were returned, and its exit times
    # are its chain's: t = 1 + M t
    m = block.inner.toarray()[chosen]
    assert np.allclose(np.asarray(t, dtype=float), 1.0 + m @ np.asarray(t, dtype=float))
    assert np.allclose(np.asarray(v, dtype=float),
                       block.to_target[chosen] + m @ np.asarray(v, dtype=float))


def _line(n: int):
    """A line where plain policy iteration from "stop everywhere" switches one state a
    round: state ``i`` stops for 1/2, or passes on to ``i + 1`` (0.97, 0.01 back to 0,
    0.02 out for nothing); the last state stops for 1 (its pass only goes back)."""
    half, p, back = Fraction(1, 2), Fraction(97, 100), Fraction(1, 100)
    rows = []
    for i in range(n - 1):
        moves = {i + 1: p}
        moves[0] = moves.get(0, Fraction(0)) + back
        rows.append([({}, half), (moves, Fraction(0))])
    rows.append([({}, Fraction(1)), ({0: half}, Fraction(0))])
    return rows


def test_the_look_ahead_takes_fewer_factorisations_on_a_one_step_a_round_line() -> None:
    rows = _line(12)
    block, _ = _block(rows)
    start = np.asarray(block.starts)
    plain, ahead = Factors(), Factors()
    p0, v0, _ = improve_ahead(block, block.to_target, start, factors=plain, sweeps=0)
    p1, v1, _ = improve_ahead(block, block.to_target, start, factors=ahead)
    # the optimum, certified exactly (4,096 policies are too many to try here): the
    # policy's values in Fractions, and no choice better on them (Bellman's optimality,
    # which on a chain that always leaves has one fixpoint)
    pick = [int(c - block.starts[i]) for i, c in enumerate(p1)]
    exact = _exact_values(rows, pick)
    for i, choices in enumerate(rows):
        for moves, gain in choices:
            assert gain + sum(p * exact[t] for t, p in moves.items()) <= exact[i]
    for s, value in enumerate(exact):
        for v in (v0, v1):
            assert abs(Fraction(float(v[s])) - value) <= Fraction(1, 10**13), (s, value)
    # plain: the improvement moves back one state a round (one LU each)
    assert plain.factorised >= 10, plain.factorised
    assert ahead.factorised <= 3, ahead.factorised


# ------------------------------------------------------------ the whole iteration


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_the_ruin_jumped_early_holds_storms_exact_value(tmp_path: Path, sense) -> None:
    """tests/test_sweep_forecast.py's gambler's ruin (one block whose upper bound leaves
    1 slowly), maximum and minimum: jumped at the NumPy sweeps' first forecast."""
    pytest.importorskip("stormpy")
    path = tmp_path / "ruin.prism"
    path.write_text(RUIN, encoding="utf-8")
    exact = storm_rational(path, f'P{sense.value}=? [F "goal"]')
    mdp = _ruin()
    r = interval_iteration(mdp, mdp.target, sense=sense, progress=False, compiled=False)
    assert r.status is Status.OPTIMAL, r.message
    lo, hi = Fraction(r.value_lower), Fraction(r.value_upper)
    # rounded to nearest, the lower bound may sit one rounding above the exact value
    # (tests/test_rare_events.py), the upper one not below it
    assert lo <= exact * (1 + Fraction(1, 2**50)) and exact <= hi, (lo, exact, hi)
    assert hi - lo <= Fraction(defaults.TOL)
    assert r.iterations <= 4 * iteration._NUMPY_FORECAST_FROM, r.iterations


LINE = """mdp
module line
  i : [0..13] init 0;
  [stop] i<11 -> 0.5 : (i'=12) + 0.5 : (i'=13);
  [pass] i<11 -> 0.97 : (i'=i+1) + 0.01 : (i'=0) + 0.02 : (i'=13);
  [stop] i=11 -> (i'=12);
  [pass] i=11 -> 0.5 : (i'=0) + 0.5 : (i'=13);
endmodule
label "goal" = i=12;
"""


def test_the_line_holds_storms_exact_value(tmp_path: Path) -> None:
    """The one-step-a-round line as a whole model (a stop reaches the goal with what it
    pays, 1/2, and 1 at the last state): the bracket of the iteration, its block jumped
    with the look-ahead, around Storm's exact maximum."""
    pytest.importorskip("stormpy")
    path = tmp_path / "line.prism"
    path.write_text(LINE, encoding="utf-8")
    exact = storm_rational(path, 'Pmax=? [F "goal"]')
    states = []
    for i in range(11):
        states.append([("stop", {12: 0.5, 13: 0.5}),
                       ("pass", {i + 1: 0.97, 0: 0.01, 13: 0.02})])
    states.append([("stop", {12: 1.0}), ("pass", {0: 0.5, 13: 0.5})])
    mdp = build_mdp(states + [[], []], initial=0, target=[12], sink=[13])
    r = interval_iteration(mdp, mdp.target, progress=False, compiled=False)
    assert r.status is Status.OPTIMAL, r.message
    lo, hi = Fraction(r.value_lower), Fraction(r.value_upper)
    assert lo <= exact * (1 + Fraction(1, 2**50)) and exact <= hi, (lo, exact, hi)
    assert hi - lo <= Fraction(defaults.TOL)


def test_a_slower_tied_choice_makes_the_jump_seek_the_slowest_totals(monkeypatch) -> None:
    """State 0 stops for 1/2 at once (1 step) or moves to a pair of states that pay 1/2
    too, one step in fifty (by hand: v = 0.01 + 0.98 v = 1/2, 50 steps to leave): the two
    choices tie, so the upper bound's shift by the policy's own exit times (1 at state
    0) is refused by the check over every choice (the slow one's image is larger), and
    the jump proves it with the slowest choices' totals (state 0: 1 + 50)."""
    from mitld_lp.solvers import policy_jump

    half, p, q = Fraction(1, 2), Fraction(98, 100), Fraction(1, 100)
    rows = [[({}, half), ({1: Fraction(1)}, Fraction(0))],
            [({2: p}, q)],
            [({1: p}, q)]]
    block, _ = _block(rows)
    block = Block(block.states, block.choices, block.inner, sp.csr_array((4, 3)),
                  block.starts, block.to_target)
    calls = []
    real = policy_jump.improve_ahead

    def spy(*args, **kwargs):
        calls.append(len(args) > 3 and args[3] is not None)
        return real(*args, **kwargs)

    monkeypatch.setattr(policy_jump, "improve_ahead", spy)
    lo, hi = np.zeros(3), np.ones(3)
    tol = 1e-9
    assert policy_jump.jump(block, lo, hi, tol, None, Sense.MAX)
    for s in range(3):
        assert Fraction(lo[s]) <= half <= Fraction(hi[s]), (s, lo[s], hi[s])
        assert hi[s] - lo[s] <= tol
    assert calls[-1] is True  # the slowest totals, over the tied choices
