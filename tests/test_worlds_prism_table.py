"""A PRISM world read whole by the product (:meth:`PrismGame.as_table`): the table says
what the game's methods say, and the product built from it is the product built by
asking the game state by state (the same world behind a plain wrapper, and the
state-at-a-time reference construction), bit for bit."""

from __future__ import annotations

import importlib.util
from collections.abc import Hashable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mitld_lp.automata.sta import make_sta
from mitld_lp.automata.translate import to_dta
from mitld_lp.distributions.literal import from_table
from mitld_lp.model import Model
from mitld_lp.product import product, robust_product
from mitld_lp.testing import reference_product
from mitld_lp.worlds.prism import load_prism
from mitld_lp.worlds.table import table_of

pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("stormpy") is None, reason="needs stormpy: pip install -e '.[prism]'"
)

# Two synchronising modules, two [go] commands enabled together where x=1 (told apart by
# their commands), an unlabelled command, a deadlock once the robot is parked, a Boolean.
ROBOT = """mdp
module robot
  x : [0..4] init 0;
  parked : bool init false;
  [go] x<4 & !parked -> 0.6 : (x'=x+1) + 0.3 : true + 0.1 : (x'=max(x-1,0));
  [go] x=1 & !parked -> 0.5 : (x'=3) + 0.5 : (x'=0);
  [back] x>0 & !parked -> 0.9 : (x'=x-1) + 0.1 : true;
  [] x=2 & !parked -> (parked'=true);
endmodule
module door
  d : [0..2] init 0;
  [go] true -> 0.7 : (d'=min(d+1,2)) + 0.3 : (d'=0);
  [back] true -> (d'=0);
endmodule
label "goal" = x=4;
label "open" = d=2;
label "stuck" = parked;
"""


def write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "m.prism"
    p.write_text(text)
    return p


class StateByState:
    """The same world behind the game protocol alone (no ``as_table``): the product
    then asks it state by state."""

    def __init__(self, game: Any) -> None:
        self.g = game
        self.initial = game.initial
        self.proposition_names = game.proposition_names
        self.event_names = game.event_names
        self.n_states = game.n_states

    def actions(self, s: Hashable) -> tuple[str, ...]:
        return self.g.actions(s)

    def successors(self, s: Hashable, a: str, events: frozenset[str]) -> Any:
        return self.g.successors(s, a, events)

    def propositions(self, s: Hashable) -> frozenset[str]:
        return self.g.propositions(s)


def same_mdp(a: Any, b: Any) -> None:
    # the names first: a world whose choices are named when first read gives the MDP
    # its actions' ids then (mitld_lp.product.late_names)
    assert a.action_names == b.action_names
    for name in ("row_groups", "choice_actions", "target", "sink", "truncated"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    ma = a.matrix if hasattr(a, "matrix") else a.branches
    mb = b.matrix if hasattr(b, "matrix") else b.branches
    assert ma.shape == mb.shape
    assert np.array_equal(ma.indptr, mb.indptr) and np.array_equal(ma.indices, mb.indices)
    assert ma.data.tobytes() == mb.data.tobytes()  # bit for bit
    assert a.action_names == b.action_names and a.initial == b.initial
    assert list(a.states) == list(b.states)


def test_the_table_says_what_the_game_says(tmp_path: Path) -> None:
    game = load_prism(write(tmp_path, ROBOT))
    table = table_of(game)
    assert table is not None and table.n_states == game.n_states
    assert table.states[table.initial] == game.initial
    seen = set()
    for i, s in enumerate(game.states):
        assert table.label_sets[int(table.label_of[i])] == game.propositions(s)
        lo, hi = int(table.choices[i]), int(table.choices[i + 1])
        names = tuple(table.action_names[k] for k in table.action_of[lo:hi].tolist())
        assert names == game.actions(s)
        seen.update(names)
        for c, a in zip(range(lo, hi), names, strict=True):
            b0, b1 = int(table.branches[c]), int(table.branches[c + 1])
            rows = tuple(zip((table.states[t] for t in table.targets[b0:b1].tolist()),
                             table.probabilities[b0:b1].tolist(), strict=True))
            assert rows == game.successors(s, a, frozenset())
    # the overlapping [go] commands are two actions where x=1, the unlabelled command one
    assert {"go@robot_cmd1+door_cmd1", "go@robot_cmd2+door_cmd1", "robot_cmd4"} <= seen
    assert game.robot_actions() == frozenset(seen)


@pytest.mark.parametrize("spec", [
    "F goal",
    "!stuck U[0,6] goal",
    "F (open & D[uniform(1, 3)] bell)",          # an event the world ignores, truncated
    "(F D[geometric(0.4)] bell) & F[0,5] goal",
])
def test_the_product_from_the_table_is_the_product_state_by_state(
    tmp_path: Path, spec: str
) -> None:
    game = load_prism(write(tmp_path, ROBOT))
    m = Model.from_game(game, spec, epsilon=1e-3)
    sta = make_sta(to_dta(m.spec), m.distributions, m.epsilon)
    fast = product(game, sta)
    same_mdp(fast, product(StateByState(game), sta))
    same_mdp(fast, reference_product(game, sta))  # the first construction, in Python
    assert fast.n_states > 10


def test_the_robust_product_from_the_table_is_the_same(tmp_path: Path) -> None:
    game = load_prism(write(tmp_path, ROBOT))
    band = from_table({"geometric": [0.2, 0.5]}, "distributions.mu")
    m = Model.from_game(game, "F (open & D[mu] bell)", distributions={"mu": band})
    sta = make_sta(to_dta(m.spec), m.distributions, m.epsilon)
    fast = robust_product(game, sta)
    slow = robust_product(StateByState(game), sta)
    same_mdp(fast, slow)
    for name in ("branch_groups", "band_groups", "band_lo", "band_hi"):
        assert np.array_equal(getattr(fast, name), getattr(slow, name)), name
    assert fast.ambiguous_choices > 0


def sta_of(game: Any, spec: str) -> Any:
    m = Model.from_game(game, spec)
    return make_sta(to_dta(m.spec), m.distributions, m.epsilon)


def test_a_row_beyond_the_products_tolerance_is_normalised_when_read(tmp_path: Path) -> None:
    # 1.000001: PRISM's tolerance (1e-5) accepts it, the product's (1e-9) does not: the
    # row is divided by its sum when the file is read (issue 41), wherever it is
    text = ROBOT.replace("endmodule\nmodule door", "  [dance] x=4 & d=2 -> 0.5 : (x'=3) + "
                         "0.500001 : true;\nendmodule\nmodule door")
    text += 'label "home" = x=0;\n'
    game = load_prism(write(tmp_path, text))
    assert game.normalised is not None and game.normalised.rows == 1
    assert game.normalised.largest == pytest.approx(1e-6, rel=1e-9)
    dance = next(s for s in game.states if "dance" in game.actions(s))
    row = sorted(p for _, p in game.successors(dance, "dance", frozenset()))
    assert row == pytest.approx([0.5 / 1.000001, 0.500001 / 1.000001], abs=1e-15)
    for spec in ("F goal", "F (goal & F home)"):
        sta = sta_of(game, spec)
        same_mdp(product(game, sta), product(StateByState(game), sta))


def test_a_world_changed_by_its_events_is_asked_state_by_state(tmp_path: Path) -> None:
    text = ROBOT.replace("  [back] true -> (d'=0);\n", "  [back] true -> (d'=0);\n"
                         "  [ring] !parked -> (d'=2);\n")
    game = load_prism(write(tmp_path, text), events=("ring",))
    assert table_of(game) is None  # its moves depend on the step's events
    sta = sta_of(game, "F (goal & D[geometric(0.3)] ring)")
    same_mdp(product(game, sta), reference_product(game, sta))


def test_the_states_are_storms_valuations_made_on_demand(tmp_path: Path) -> None:
    import json
    import pickle

    import stormpy

    source = write(tmp_path, ROBOT)
    game = load_prism(source)
    options = stormpy.BuilderOptions()
    options.set_build_state_valuations()
    model = stormpy.build_model(stormpy.parse_prism_program(str(source)), options=options)
    storm = [json.loads(str(model.state_valuations.to_json(i))) for i in range(model.nr_states)]
    expected = tuple(tuple(v[name] for name in game.variables) for v in storm)
    assert len(game.states) == len(expected) == model.nr_states
    assert game.states == expected and list(game.states) == list(expected)
    assert [game.states[i] for i in range(-2, 3)] == [expected[i] for i in range(-2, 3)]
    assert game.states[1:4] == expected[1:4]
    parked = game.variables.index("parked")  # a Boolean variable's value is a bool
    assert all(type(s[parked]) is bool and type(s[0 if parked else 1]) is int
               for s in game.states)
    assert pickle.loads(pickle.dumps(game.states)) == expected
    with pytest.raises(IndexError):
        game.states[len(expected)]
