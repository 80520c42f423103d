"""The Game protocol, ExplicitGame's validation and check_game."""

from __future__ import annotations

import math

import pytest

from mitld_lp.worlds.game import ExplicitGame, Game, GameCheck, GameError, check_game


def coin_game() -> ExplicitGame:
    """s0 --go--> s1 (0.3) or s2 (0.7); s1, s2 loop; the event 'rain' sends go to s2."""
    return ExplicitGame(
        initial="s0",
        transitions={
            "s0": {"go": {"s1": 0.3, "s2": 0.7}, "wait": {"s0": 1.0}},
            "s1": {"stay": {"s1": 1.0}},
            "s2": {"stay": [("s2", 0.5), ("s2", 0.5)]},
        },
        labels={"s1": {"goal"}},
        event_transitions={("s0", "go", frozenset({"rain"})): {"s2": 1.0}},
    )


def test_explicit_game_implements_the_protocol() -> None:
    g = coin_game()
    assert isinstance(g, Game)
    assert g.initial == "s0"
    assert g.actions("s0") == ("go", "wait")
    assert dict(g.successors("s0", "go", frozenset())) == {"s1": 0.3, "s2": 0.7}
    assert g.successors("s0", "go", frozenset({"rain"})) == (("s2", 1.0),)
    # an override applies to exactly its event set
    assert dict(g.successors("s0", "go", frozenset({"rain", "wind"}))) == {"s1": 0.3, "s2": 0.7}
    assert g.successors("s2", "stay", frozenset()) == (("s2", 1.0),)  # pairs merged
    assert g.propositions("s1") == frozenset({"goal"})
    assert g.propositions("s0") == frozenset()
    assert g.proposition_names == frozenset({"goal"})
    assert g.states == ("s0", "s1", "s2")


def test_explicit_game_is_a_frozen_value() -> None:
    g, h = coin_game(), coin_game()
    assert g == h and hash(g) == hash(h)
    with pytest.raises(AttributeError):
        g.initial = "s1"  # type: ignore[misc]
    with pytest.raises(TypeError):
        g.transitions["s0"] = {}  # type: ignore[index]


def test_zero_probabilities_are_dropped() -> None:
    g = ExplicitGame(initial=0, transitions={0: {"a": {0: 1.0, 1: 0.0}}})
    assert g.successors(0, "a", frozenset()) == ((0, 1.0),)


@pytest.mark.parametrize(
    "transitions, match",
    [
        ({"s": {"a": {"s": 0.5}}}, r"state 's', action 'a': probabilities must sum to 1"),
        ({"s": {"a": {"s": 1.2, "t": -0.2}}}, r"probability of 's' must be in \[0, 1\]"),
        ({"s": {"a": {"s": math.nan}}}, "must be a number"),
        ({"s": {"a": {"s": True}}}, "must be a number"),
        ({"s": {"a": {}}}, "probabilities must sum to 1"),
        ({"s": {}}, "state 's': needs a non-empty mapping"),
        ({"s": {"a": {"t": 1.0}}}, "successor 't' has no transitions"),
        ({"t": {"a": {"t": 1.0}}}, "initial state 's' has no transitions"),
        ({"s": {1: {"s": 1.0}}}, "action 1 is not a string"),
        ({"s": {"a": [("s",)]}}, "expected \\(next_state, probability\\)"),
    ],
)
def test_explicit_game_rejects(transitions: dict, match: str) -> None:
    with pytest.raises(GameError, match=match):
        ExplicitGame(initial="s", transitions=transitions)


def test_explicit_game_rejects_bad_labels_and_overrides() -> None:
    t = {"s": {"a": {"s": 1.0}}}
    with pytest.raises(GameError, match="not in proposition_names"):
        ExplicitGame("s", t, labels={"s": {"p"}}, proposition_names=frozenset({"q"}))
    with pytest.raises(GameError, match="set of proposition names"):
        ExplicitGame("s", t, labels={"s": "p"})
    with pytest.raises(GameError, match="is not in transitions"):
        ExplicitGame("s", t, event_transitions={("s", "b", frozenset()): {"s": 1.0}})
    with pytest.raises(GameError, match="events \\['e'\\]: probabilities must sum to 1"):
        ExplicitGame("s", t, event_transitions={("s", "a", frozenset({"e"})): {"s": 0.9}})
    g = ExplicitGame("s", t, proposition_names=frozenset({"p", "q"}))
    assert g.proposition_names == frozenset({"p", "q"})


def test_error_is_a_value_error() -> None:
    assert issubclass(GameError, ValueError)


def test_check_game_counts() -> None:
    report = check_game(coin_game(), events={"rain"})
    # 3 states; choices: s0 has 2 actions, s1 and s2 one each.
    # transitions: s0/go 2 (no events) + 1 (rain); s0/wait 1 + 1; s1 1 + 1; s2 1 + 1.
    assert report == GameCheck(
        states=3,
        choices=4,
        transitions=3 + 2 + 2 + 2,
        actions=frozenset({"go", "wait", "stay"}),
        propositions=frozenset({"goal"}),
    )


class Broken:
    """A hand-written game with a fault selected by ``fault``."""

    def __init__(self, fault: str) -> None:
        self.fault = fault
        self.initial = 0
        self.proposition_names = frozenset({"p"})

    def actions(self, state: int) -> tuple[str, ...]:
        if self.fault == "no_actions" and state == 1:
            return ()
        if self.fault == "dup_actions":
            return ("a", "a")
        return ("a",)

    def successors(self, state: int, action: str, events: frozenset[str]):
        if self.fault == "sum" and state == 1:
            return ((2, 0.5), (0, 0.4))
        if self.fault == "event_sum" and "e" in events:
            return ((0, 0.7),)
        if self.fault == "dup_next":
            return ((0, 0.5), (0, 0.5))
        if self.fault == "zero":
            return ((0, 1.0), (1, 0.0))
        if self.fault == "unhashable":
            return (([state], 1.0),)
        if self.fault == "infinite":
            return ((state + 1, 1.0),)
        return (((state + 1) % 3, 1.0),)

    def propositions(self, state: int) -> frozenset[str]:
        if self.fault == "label":
            return frozenset({"q"})
        return frozenset()


def test_broken_is_structurally_a_game() -> None:
    assert isinstance(Broken("none"), Game)
    assert check_game(Broken("none")).states == 3


@pytest.mark.parametrize(
    "fault, match",
    [
        ("no_actions", "state 1: actions must be a non-empty tuple"),
        ("dup_actions", "state 0: actions must be distinct strings"),
        ("sum", r"state 1, action 'a': probabilities sum to 0.9"),
        ("event_sum", r"state 0, action 'a', events \['e'\]: probabilities sum to 0.7"),
        ("dup_next", "next state 0 is listed twice"),
        ("zero", r"probability of 1 must be in \(0, 1\]"),
        ("unhashable", "next state \\[0\\] is not hashable"),
        ("infinite", "more than 50 reachable states"),
        ("label", "state 0: propositions \\['q'\\] are not in proposition_names"),
    ],
)
def test_check_game_names_the_fault(fault: str, match: str) -> None:
    with pytest.raises(GameError, match=match):
        check_game(Broken(fault), events={"e"}, max_states=50)
