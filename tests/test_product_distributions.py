"""The product checks every distribution it reads from the world (issue 16, item 3).

Before, a world whose outcomes summed to 0.99 was solved and certified (0.0 0.0
certified=True); only ``check_game`` would have caught it.  Now the product refuses any
answer of ``successors`` that is not a distribution -- empty, a probability not finite
or negative, a total off 1 by more than 1e-9 -- naming the state, the action and the
step's events.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mitld_lp import Model, make_sta, parse, synthesize, to_dta
from mitld_lp.product import product
from mitld_lp.worlds.game import GameError
from mitld_lp.worlds.successors import distribution_fault, distribution_faults


class _Line:
    """0 -> 1 -> 2 (A at 2); ``bad`` replaces the answer at (1, 'go', events)."""

    initial = 0
    proposition_names = frozenset({"A"})
    event_names = frozenset({"e"})

    def __init__(self, bad, when=frozenset()):
        self.bad, self.when = bad, when

    def actions(self, state):
        return ("go", "stay")

    def successors(self, state, action, events):
        if state == 1 and action == "go" and events == self.when:
            return self.bad
        if action == "stay":
            return ((state, 1.0),)
        return ((min(state + 1, 2), 0.5), (state, 0.5))

    def propositions(self, state):
        return frozenset({"A"}) if state == 2 else frozenset()


SPEC = "D[geometric(0.5)] e & F[0,6] A"


@pytest.mark.parametrize(
    "bad, why",
    [
        (((2, 0.5), (1, 0.49)), "probabilities sum to 0.99, not 1"),
        (((2, 1.5), (1, -0.5)), "probability of 1 must be finite and non-negative, got -0.5"),
        (((2, math.nan),), "probability of 2 must be finite and non-negative, got nan"),
        (((2, math.inf),), "probability of 2 must be finite and non-negative, got inf"),
        ((), "successors must not be empty"),
        (((2, "1"),), "probability of 2 must be finite and non-negative, got '1'"),
        ((([2], 1.0),), "expected (next_state, probability) with a hashable state, got ([2], 1.0)"),
        (((2, 1.0, 0.0),), "expected (next_state, probability) with a hashable state"),
    ],
)
def test_a_world_answer_that_is_no_distribution_is_refused_naming_state_and_action(bad, why):
    with pytest.raises(GameError) as err:
        synthesize(Model.from_game(_Line(bad), SPEC))
    message = str(err.value)
    assert message.startswith("state 1, action 'go': ") and why in message
    assert "\n" not in message


def test_the_events_of_the_step_are_named_too():
    with pytest.raises(GameError, match=r"^state 1, action 'go', events \['e'\]: probabilities "
                                        r"sum to 0\.99, not 1$"):
        synthesize(Model.from_game(_Line(((2, 0.99),), frozenset({"e"})), SPEC))


def test_a_total_within_the_tolerance_is_accepted():
    # 0.1 + 0.2 + 0.7 is 0.9999999999999999 in floating point
    ok = ((2, 0.1), (1, 0.2), (0, 0.7))
    r = synthesize(Model.from_game(_Line(ok), "D[geometric(0.5)] e & F[0,1] A"))
    assert r.certified


def test_the_batch_rule_agrees_with_the_one_row_rule():
    rng = np.random.default_rng(0)
    rows = []
    for _ in range(300):
        k = int(rng.integers(0, 4))
        p = rng.dirichlet(np.ones(k)) if k else np.array([])
        pick = rng.integers(0, 6)
        if k and pick == 0:
            p[0] = -p[0]
        elif k and pick == 1:
            p[-1] = np.nan
        elif k and pick == 2:
            p = p * 0.999
        elif k and pick == 3:
            p[0] += 2e-9
        rows.append(tuple((i, float(x)) for i, x in enumerate(p)))
    lengths = np.array([len(r) for r in rows])
    probs = np.array([p for r in rows for _, p in r], dtype=float)
    by_batch = set(distribution_faults(lengths, probs).tolist())
    by_row = {i for i, r in enumerate(rows) if distribution_fault(r)}
    assert by_batch == by_row and 0 < len(by_row) < len(rows)


class _Tree:
    """States 0 .. n - 1, state s moving to 2s + 1 and 2s + 2 (mod n): all reached within
    a few breadth-first levels, a fresh answer per state; the answer at ``bad`` sums to
    0.99."""

    proposition_names = frozenset({"A"})
    event_names = frozenset()
    initial = 0

    def __init__(self, n, bad):
        self.n, self.bad = n, bad

    def actions(self, state):
        return ("go",)

    def successors(self, state, action, events):
        left, right = (2 * state + 1) % self.n, (2 * state + 2) % self.n
        return ((left, 0.5), (right, 0.49 if state == self.bad else 0.5))

    def propositions(self, state):
        return frozenset({"A"}) if state == self.n - 1 else frozenset()


@pytest.mark.parametrize("bad", [3, 12345, 19997])
def test_a_fault_is_found_among_thousands_of_rows_wherever_it_is(bad):
    # rows are checked in batches of thousands and once more at the end of the build
    with pytest.raises(GameError, match=rf"^state {bad}, action 'go': probabilities sum to 0\.99"):
        product(_Tree(20000, bad), make_sta(to_dta(parse("F[0,40] A")), {}, 0.01))
    product(_Tree(20000, None), make_sta(to_dta(parse("F[0,40] A")), {}, 0.01))
