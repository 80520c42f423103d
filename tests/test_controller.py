"""Controllers, games and automata survive a pickle round trip and act the same after it."""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest

from mitld_lp import GridWorld, Observation, synthesize
from mitld_lp.game import ExplicitGame, check_game
from mitld_lp.model import load_model
from mitld_lp.product import ProductState
from mitld_lp.simulate import simulate

MODELS = Path(__file__).resolve().parent.parent / "models"


def roundtrip(obj):
    return pickle.loads(pickle.dumps(obj))


def test_explicit_game_pickles_with_its_tables():
    g = ExplicitGame(
        initial=0,
        transitions={0: {"a": {1: 1.0}, "b": {0: 0.25, 1: 0.75}}, 1: {"a": {0: 1.0}}},
        labels={1: {"A"}},
        event_transitions={(0, "a", frozenset({"e"})): {0: 1.0}},
    )
    h = roundtrip(g)
    assert h == g and hash(h) == hash(g)
    assert h.successors(0, "a", frozenset({"e"})) == ((0, 1.0),)
    assert h.successors(0, "b", frozenset()) == ((0, 0.25), (1, 0.75))
    assert h.propositions(1) == frozenset({"A"}) and h.proposition_names == frozenset({"A"})
    assert check_game(h, events=["e"]) == check_game(g, events=["e"])


def test_grid_world_pickles_after_use():
    g = GridWorld.make(5, 4, start=(1, 1), slip=0.1, obstacles=[(2, 2)],
                       regions={"A": [(0, 3)]}, stay=True)
    g.successors((1, 1), "N", frozenset())  # fills the lazy cache
    h = roundtrip(g)
    assert h == g and hash(h) == hash(g)
    for cell in g.cells:
        for a in g.actions(cell):
            assert h.successors(cell, a, frozenset()) == g.successors(cell, a, frozenset())
        assert h.propositions(cell) == g.propositions(cell)


@pytest.mark.parametrize("name", ["bus_grid.toml", "red_light.toml"])  # red_light: truncated
def test_controller_and_its_automaton_act_the_same_after_a_round_trip(name):
    m = load_model(MODELS / name)
    r = synthesize(m)
    sta = roundtrip(r.sta)
    assert sta.truncation_points == r.sta.truncation_points
    assert sta.epsilon_achieved == r.sta.epsilon_achieved
    for q in range(sta.dta.n_states):
        assert sta.dta.delta[q] == r.sta.dta.delta[q]
    copy = roundtrip(r.controller)
    # same answers on every product state the policy covers: act from a fresh run where
    # the state is the initial one, and look up every record
    states = r.controller.mdp.states
    for i, s in enumerate(states):
        if isinstance(s, ProductState):
            assert copy.mdp.states.position(s) == i
    assert np.array_equal(copy.policy, r.controller.policy)
    # the same rollouts from the same seed
    a = simulate(m, r.controller, runs=200, seed=3)
    b = simulate(roundtrip(m), copy, runs=200, seed=3)
    assert (a.successes, a.beyond_model, a.undecided) == (b.successes, b.beyond_model, b.undecided)
    copy.reset()
    r.controller.reset()
    first = Observation(state=m.game.initial)
    assert copy.act(first) == r.controller.act(first)
