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
    # levels 1, 10, 20, 40: factors 2 and 2, the least 2; carried to level 5: levels 4
    # and 5 hold 80 and 160 more, 71 found
    assert projected([1, 10, 20, 40], 5) == (71 + 80 + 160, 2.0, 5)
    # the least of the last two factors: 6 / 3 = 2 and 9 / 6 = 1.5
    assert projected([1, 3, 6, 9], 4) == (19 + 13, 1.5, 4)  # 9 * 1.5 = 13.5, floored
    # at or past the clock's end nothing more is expected
    assert projected([1, 10, 20, 40], 3) == (71, 2.0, 3)
    # too few levels to judge
    assert projected([1, 10], 9) == (11, 0.0, 1)


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
