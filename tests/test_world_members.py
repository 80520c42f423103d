"""The members a world declares beyond the Game protocol (``mitld_lp.worlds.game.WorldMembers``).

Every world kind says which events its moves react to, and an event it reacts to that
the spec gives no law is refused for every kind with one message.  Before, a PRISM
world (whose member was called ``events``) and a user's class without ``event_names``
were accepted, and the event silently never happened.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from mitld_lp import ExplicitGame, GridWorld, Model, ModelError, load_model, synthesize
from mitld_lp.automata.sta import make_sta
from mitld_lp.automata.translate import to_dta
from mitld_lp.distributions import geometric
from mitld_lp.logic import parse
from mitld_lp.product import estimate_size, product
from mitld_lp.worlds.game import GameError, WorldMembers, world_members
from mitld_lp.worlds.gym import from_transition_table
from mitld_lp.worlds.task import BindError

needs_storm = pytest.mark.skipif(
    importlib.util.find_spec("stormpy") is None, reason="stormpy is not installed"
)

LAWLESS = (
    "the game reacts to event {e!r} but the spec gives it no distribution "
    "(add D[mu] {e} to the spec)"
)


class _Door:
    """A corridor 0 -> 1 -> 2 whose last step needs the event 'door' (A at 2)."""

    initial = 0
    proposition_names = frozenset({"A"})
    event_names = frozenset({"door"})

    def actions(self, state):
        return ("E",)

    def successors(self, state, action, events):
        return ((min(state + 1, 2), 1.0),) if state < 1 or "door" in events else ((state, 1.0),)

    def propositions(self, state):
        return frozenset({"A"}) if state == 2 else frozenset()


class _DoorMisspelt:
    """The same world, its events under the name PRISM worlds used (``events``)."""

    initial = 0
    proposition_names = frozenset({"A"})
    events = frozenset({"door"})
    actions = _Door.actions
    successors = _Door.successors
    propositions = _Door.propositions


class _Silent:
    """The same world, saying nothing about events (as docs/worlds.md's once did)."""

    initial = 0
    proposition_names = frozenset({"A"})
    actions = _Door.actions
    successors = _Door.successors
    propositions = _Door.propositions


def _refusals(world, spec: str) -> tuple[str, str]:
    """What ``Model.from_game`` and ``product`` (on an STA with the spec's laws) say."""
    with pytest.raises(ModelError) as lib:
        Model.from_game(world, spec)
    formula = parse(spec)
    laws = {e: geometric(0.5) for e in ("door", "jolt") if e in str(formula)}
    with pytest.raises(ValueError) as prod:
        product(world, make_sta(to_dta(formula), laws, 0.01))
    for err in (lib, prod):
        assert "\n" not in str(err.value)
    return str(lib.value), str(prod.value)


def test_a_user_world_reacting_to_an_event_without_a_law_is_refused_on_every_route():
    lib, prod = _refusals(_Door(), "F[0,4] A")
    assert lib == f"<spec>: spec: {LAWLESS.format(e='door')}"
    assert prod == LAWLESS.format(e="door")
    # with a law it is solved: cell 1 after step 1; on to 2 in step k >= 2 iff the
    # door opens in step k (it opens once), so K in {2, 3, 4}: 1/4 + 1/8 + 1/16
    r = synthesize(Model.from_game(_Door(), "D[geometric(0.5)] door & F[0,4] A"))
    assert r.lower == pytest.approx(0.4375, abs=1e-7)


def test_a_user_world_with_its_events_under_another_name_is_refused_naming_them():
    # Accepted before, with F[0,4] A answered 0.0 "certified": the door never opened.
    lib, prod = _refusals(_DoorMisspelt(), "F[0,4] A")
    assert lib.startswith("<spec>: game: _DoorMisspelt does not say which events")
    assert "_DoorMisspelt.events = ['door'] is not a member of a world" in lib
    assert "give it event_names" in prod


def test_a_user_world_that_says_nothing_about_events_is_refused():
    lib, _ = _refusals(_Silent(), "F[0,4] A")
    assert lib == (
        "<spec>: game: _Silent does not say which events its moves react to: give it "
        "event_names (a frozenset of event names, frozenset() if none) or "
        "ignores_events = True"
    )


def test_an_explicit_game_gets_the_same_message():
    table = ExplicitGame(
        initial=0,
        transitions={0: {"E": {1: 1.0}}, 1: {"E": {1: 1.0}}, 2: {"E": {2: 1.0}}},
        labels={2: {"A"}},
        event_transitions={(1, "E", frozenset({"door"})): {2: 1.0}},
    )
    lib, prod = _refusals(table, "F[0,4] A")
    assert prod == LAWLESS.format(e="door") and lib.endswith(prod)


LIFT = """mdp
module lift
  level : [0..2] init 0;
  [up]   level < 2 -> (level'=level+1);
  [wait] true -> true;
  [jolt] level = 2 -> (level'=0);
endmodule
label "top" = level = 2;
"""


@needs_storm
def test_a_prism_world_reacting_to_an_event_without_a_law_is_refused(tmp_path: Path):
    from mitld_lp.worlds.prism import load_prism

    (tmp_path / "lift.prism").write_text(LIFT)
    lift = load_prism(tmp_path / "lift.prism", events=["jolt"])
    # Accepted before (PrismGame called the member `events`): the jolt never happened.
    lib, prod = _refusals(lift, "F[0,2] top")
    assert prod == LAWLESS.format(e="jolt") and lib == f"<spec>: spec: {prod}"
    (tmp_path / "m.toml").write_text(
        'name = "lift"\nspec = "F[0,2] top"\n[prism]\nfile = "lift.prism"\nevents = ["jolt"]\n'
    )
    with pytest.raises(ModelError) as file_err:
        load_model(tmp_path / "m.toml")
    assert str(file_err.value) == f"{tmp_path / 'm.toml'}: spec: {prod}"
    assert world_members(lift) == WorldMembers(frozenset({"jolt"}), False, 3)


def test_every_kind_declares_its_members():
    grid = GridWorld.make(3, 2, start=(0, 0), obstacles=[(1, 1)])
    assert world_members(grid) == WorldMembers(frozenset(), True, 5)
    chain = from_transition_table(
        {0: {0: [(1.0, 1, 0.0, True)]}, 1: {0: [(1.0, 0, 0.0, False)]}}, 0
    )
    assert world_members(chain) == WorldMembers(frozenset(), False, 2)
    assert world_members(_Door()) == WorldMembers(frozenset({"door"}), False, None)


def _world(**members):
    """A _Silent world with ``members`` set on its class."""
    return type("W", (_Silent,), members)()


@pytest.mark.parametrize(
    "members, message",
    [
        ({"ignore_events": True}, r"W.ignore_events is not a member of a world; did you "
                                  r"mean ignores_events\?"),
        ({"event_name": frozenset()}, r"W.event_name is not a member .* event_names\?"),
        ({"event_names": frozenset(), "nstates": 3}, r"W.nstates .* mean n_states\?"),
        ({"event_names": "door"}, r"W.event_names must be a frozenset of names"),
        ({"event_names": frozenset({1})}, r"W.event_names must be a frozenset of names"),
        ({"ignores_events": 1}, r"W.ignores_events must be True or False, got 1"),
        ({"ignores_events": True, "event_names": frozenset({"door"})},
         r"W says ignores_events = True but reacts to events \['door'\]"),
        ({"event_names": frozenset(), "n_states": -1}, r"W.n_states must be a non-negative"),
        ({"event_names": frozenset(), "n_states": True}, r"W.n_states must be a non-negative"),
    ],
)
def test_a_wrong_or_misspelt_member_is_refused_not_defaulted(members, message):
    world = _world(**members)
    with pytest.raises(GameError, match=message):
        world_members(world)
    sta = make_sta(to_dta(parse("F[0,4] A")), {}, 0.01)
    with pytest.raises(GameError, match=message):  # the product reads them the same way
        product(world, sta)
    with pytest.raises(GameError, match=message):
        estimate_size(world, sta)


def test_declared_members_are_used():
    sta = make_sta(to_dta(parse("F[0,4] A")), {}, 0.01)
    assert estimate_size(_world(event_names=frozenset()), sta).game_states is None
    assert estimate_size(_world(event_names=frozenset(), n_states=3), sta).game_states == 3
    calls: list[frozenset[str]] = []

    class Counting(_Silent):
        ignores_events = True

        def successors(self, state, action, events):
            calls.append(events)
            return _Door.successors(self, state, action, events)

    sta = make_sta(to_dta(parse("D[geometric(0.5)] b & F(b & F[0,4] A)")),
                   {"b": geometric(0.5)}, 0.01)
    product(Counting(), sta)
    assert calls and all(e == frozenset() for e in calls)  # asked without the events


def test_bind_error_is_a_value_error_with_a_key():
    with pytest.raises(BindError) as err:
        product(_Door(), make_sta(to_dta(parse("F[0,4] A")), {}, 0.01))
    assert err.value.key == ("spec",) and isinstance(err.value, ValueError)
