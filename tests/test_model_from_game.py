"""``Model.from_game``: the Python route to a model checks what the file loader checks."""

from __future__ import annotations

import pytest

from mitld_lp import GridWorld, Model, ModelError, synthesize
from mitld_lp.distributions import geometric

WORLD = GridWorld.make(3, 1, start=(0, 0), regions={"A": [(2, 0)]})


def test_a_typo_in_a_proposition_is_refused_with_the_known_names():
    # 'a' is neither the region 'A' nor an event: before, synthesize answered 0.0 certified.
    with pytest.raises(ModelError, match=r"proposition 'a' is neither a proposition nor an "
                                         r"event \(propositions: A; events: none\)"):
        Model.from_game(WORLD, "F[0,5] a")


def test_an_event_is_not_a_proposition_of_the_game():
    with pytest.raises(ModelError, match="'A' has the name of an event"):
        Model.from_game(WORLD, "D[geometric(0.5)] A & F A")


def test_named_laws_must_be_laws_and_used():
    with pytest.raises(ModelError, match=r"distributions\.mu: must be a distribution"):
        Model.from_game(WORLD, "D[mu] b & F(b & F[0,2] A)", distributions={"mu": 0.5})
    with pytest.raises(ModelError, match=r"distributions\.nu: defined but not used"):
        Model.from_game(WORLD, "D[mu] b & F(b & F[0,2] A)",
                        distributions={"mu": geometric(0.5), "nu": geometric(0.5)})
    with pytest.raises(ModelError, match="'mu' .* is not defined"):
        Model.from_game(WORLD, "D[mu] b & F(b & F[0,2] A)")


@pytest.mark.parametrize("eps", [0, 1, -1, float("nan"), float("inf"), "0.1", True])
def test_epsilon_outside_the_open_unit_interval_is_refused(eps):
    with pytest.raises(ModelError, match="epsilon: must be a number in"):
        Model.from_game(WORLD, "F A", epsilon=eps)


@pytest.mark.parametrize("game", [None, 3, "grid", {"initial": 0}])
def test_something_that_is_no_game_is_refused(game):
    with pytest.raises(ModelError, match="game: must implement the Game protocol"):
        Model.from_game(game, "F A")


def test_syntax_errors_keep_line_and_column():
    with pytest.raises(ModelError, match=r"<spec>: spec: 1:6: unexpected end of input"):
        Model.from_game(WORLD, "F A &")


def test_a_model_pickles_and_keeps_its_laws():
    import pickle

    # (a world reacting to an event: tests/test_world_members.py)
    model = Model.from_game(WORLD, "D[geometric(0.5)] door & F(door & F[0,4] A)", name="door")
    back = pickle.loads(pickle.dumps(model))
    assert back.name == "door" and back.spec == model.spec
    assert dict(back.distributions).keys() == {"door"}
    assert back.distributions["door"].hazard(3) == pytest.approx(0.5)
    with pytest.raises(TypeError):
        back.distributions["x"] = None  # still read-only


def test_an_explicit_game_declares_the_events_of_its_event_transitions():
    from mitld_lp import ExplicitGame

    game = ExplicitGame(
        initial=0,
        transitions={0: {"go": {0: 1.0}}, 1: {"go": {1: 1.0}}},
        labels={1: {"A"}},
        event_transitions={(0, "go", frozenset({"door"})): {1: 1.0}},
    )
    assert game.event_names == {"door"}
    # Before, F[0,3] A here was 0.0 "certified": the door event never happened.
    with pytest.raises(ModelError, match="reacts to event 'door'"):
        Model.from_game(game, "F[0,3] A")
    # With a law it opens at step K ~ geometric(1/2) and the robot is through at once:
    # A within 3 steps iff K <= 3.
    r = synthesize(Model.from_game(game, "D[geometric(0.5)] door & F[0,3] A"))
    assert r.lower == pytest.approx(1 - 0.5**3, abs=1e-9)
