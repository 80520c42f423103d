"""The information-state product's growth estimate (:mod:`mitld_lp.sensing.growth`): a
build that will not fit its budget stops at the end of an early level, its message
naming the model, the sensed event and the cause; one that fits is never stopped by it.
The sizes it is judged against are the products built in full here."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from mitld_lp import load_model
from mitld_lp.automata.translate import to_dta
from mitld_lp.product import ProductTooLarge
from mitld_lp.sensing import Sensor
from mitld_lp.sensing.belief import belief_product
from mitld_lp.sensing.growth import projected

MODELS = Path(__file__).resolve().parents[1] / "models"


def test_the_projection_by_hand():
    # levels 1, 10, 20, 40, 80: factors 2, 2, 2, steady: carried from level 4 past the
    # clock's step 6 by two levels, to 8: 160, 320, 640 and 1280 more, 151 found
    assert projected([1, 10, 20, 40, 80], 6) == (151 + 2400, 2.0, 8)
    # factors 3, 2, 1.5, not steady: the least 1.5 shrinking by 1.5 / 2 = 0.75 a level,
    # 1.125 then 0.84375, to the clock's step 6 only: 108 * 1.125 = 121.5 and 121.5 *
    # 0.84375 = 102.515625 more, 229 found
    assert projected([1, 12, 36, 72, 108], 6) == (229 + 224, 1.5, 6)
    # factors 1.1: steady but slow, to the clock's step 6 only: 1331 * 1.1 = 1464.1 and
    # 1610.51 more
    assert projected([1, 1000, 1100, 1210, 1331], 6) == (4642 + 3074, 1.1, 6)
    # at or past the last level nothing more is expected
    assert projected([1, 10, 20, 40, 80], 2) == (151, 2.0, 4)
    # too few levels, or before the clock's half-way step: the states so far
    assert projected([1, 10, 20], 3) == (31, 0.0, 2)
    assert projected([1, 10, 20, 40, 80], 9) == (151, 0.0, 4)


def test_false_alarms_carry_the_growth_past_the_clock():
    """With false alarms the growth seen at the clock's last step or after is carried
    ``alarm_past`` levels past it, steady or not, while it stays above 1 (shrunk): the
    levels of the bus case's camera on bus 2 with false alarms (``detect = 0.8,
    false_alarm = 0.05``, epsilon 0.05, clock 9; 193,856 states built)."""
    sizes = [1, 12, 72, 269, 834, 1957, 4353, 9517, 21953, 25621, 29935]
    # level 10: factors 29935/25621, 25621/21953, 21953/9517; the least, 25621/21953,
    # shrinks by min(1, first/second) = 1: carried two levels on, to 9 + 3
    f = 25621 / 21953
    assert projected(sizes, 9, alarm_past=3) == (
        sum(sizes) + int(29935 * f + 29935 * f * f), f, 12)
    assert projected(sizes, 9) == (sum(sizes), f, 10)  # none past it without alarms
    # level 9: 25621/21953 shrunk by its ratio to 21953/9517 (about 0.5): below 1, none
    assert projected(sizes[:10], 9, alarm_past=3) == projected(sizes[:10], 9)
    # every level's estimate under the true size, the one at level 10 within 13% of it
    estimates = [projected(sizes[:k], 9, alarm_past=3)[0] for k in range(4, 12)]
    assert max(estimates) < 193_856 and estimates[-1] > 0.87 * 193_856


def _build(max_states: int):
    model = load_model(MODELS / "bus_grid.toml")
    return belief_product(model.game, to_dta(model.spec), model.distributions,
                          {"b2": Sensor(0.5)}, 0.1, max_states=max_states, name=model.name)


def test_a_product_that_will_not_fit_stops_early_and_says_why():
    full = _build(10**6).mdp.n_states  # the product in full
    budget = 2_000
    assert full > budget
    with pytest.raises(ProductTooLarge) as caught:
        _build(budget)
    said = str(caught.value)
    assert "of model 'bus_grid' will not fit" in said
    assert "when b2 (sensors.b2: detect 0.5, delay 0; truncated at step 7) happened" in said
    assert "max_states 2,000" in said
    stopped = int(re.search(r"stopped after ([\d,]+) states", said)[1].replace(",", ""))
    # stopped at a level's end well before the budget's exact check would have
    assert stopped < budget // 2
    # the same product at a budget it fits: the estimate does not stop it
    assert _build(full).mdp.n_states == full
