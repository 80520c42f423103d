"""A PRISM world explored as the product reaches it (LazyPrismGame) answers as the whole
build does: the same product, the same bracket, bit for bit; the budget stops it before
Storm explores past max_states; the exact answer is refused by name."""

from __future__ import annotations

import pickle

import pytest

pytest.importorskip("stormpy")

from storm_exact import storm_rational  # noqa: E402

import mitld_lp  # noqa: E402
from mitld_lp.logic.parser import parse  # noqa: E402
from mitld_lp.worlds import WorldError  # noqa: E402
from mitld_lp.worlds.exact import exact_successors_of  # noqa: E402
from mitld_lp.worlds.prism import LazyPrismGame, PrismGame, PrismTooLarge, load_prism  # noqa: E402


def _grid(tmp_path, n: int, goal: tuple[int, int] = (3, 2)):
    """An n x n grid: four moves that slip (stay) with probability 1/10, a goal cell."""
    text = f"""mdp
const int N = {n - 1};
module robot
  x : [0..N] init 0;
  y : [0..N] init 0;
  [east]  x<N -> 0.9:(x'=x+1) + 0.1:(x'=x);
  [west]  x>0 -> 0.9:(x'=x-1) + 0.1:(x'=x);
  [north] y<N -> 0.9:(y'=y+1) + 0.1:(y'=y);
  [south] y>0 -> 0.8:(y'=y-1) + 0.2:(y'=y);
endmodule
label "goal" = x={goal[0]} & y={goal[1]};
label "wall" = x=2 & y<2;
"""
    path = tmp_path / f"grid{n}.prism"
    path.write_text(text)
    return path


def _answer(game, spec):
    r = mitld_lp.synthesize(mitld_lp.Model.from_game(game, spec))
    return r.lower, r.upper, r.mdp.n_states, r.mdp.n_choices, r.value


@pytest.mark.parametrize("spec", ["F[0,6] goal", "!wall U[0,7] goal", "G[0,4] !wall"])
def test_lazy_world_gives_the_full_builds_answer_bit_for_bit(tmp_path, spec):
    path = _grid(tmp_path, 12)
    task = parse(spec)
    full = load_prism(path, task=task, explore="full")
    lazy = load_prism(path, task=task, explore="lazy", first_states=4)
    assert type(full) is PrismGame and isinstance(lazy, LazyPrismGame)
    assert lazy.n_states is None  # unknown: the product counts its states as it builds
    a, b = _answer(full, spec), _answer(lazy, spec)
    assert a == b  # same product size, same bracket and value, no tolerance
    assert 4 < lazy.explored < full.n_states == 144  # explored further, not the whole grid


def test_auto_explores_lazily_only_a_bounded_task(tmp_path):
    path = _grid(tmp_path, 12)
    bounded = load_prism(path, task=parse("F[0,3] goal"), first_states=8)
    unbounded = load_prism(path, task=parse("F goal"), first_states=8)
    assert isinstance(bounded, LazyPrismGame)
    assert type(unbounded) is PrismGame and unbounded.n_states == 144
    # a world Storm explores whole within first_states is the plain game
    assert type(load_prism(path, task=parse("F[0,3] goal"))) is PrismGame


def test_lazy_unbounded_task_agrees_with_the_full_build(tmp_path):
    # the product reaches every state not decided: the lazy world explores it all
    path = _grid(tmp_path, 6, goal=(5, 5))
    task = parse("!wall U goal")
    full = load_prism(path, task=task, explore="full")
    lazy = load_prism(path, task=task, explore="lazy", first_states=2)
    assert _answer(full, "!wall U goal") == _answer(lazy, "!wall U goal")
    assert lazy.n_states == full.n_states  # explored to the end: now known


def test_lazy_world_states_and_moves_are_the_full_builds(tmp_path):
    # Storm numbers states breadth first: the prefix explored is the whole build's
    path = _grid(tmp_path, 9)
    full = load_prism(path, explore="full")
    lazy = load_prism(path, task=parse("F[0,2] goal"), explore="lazy", first_states=3)
    for k in range(lazy.explored):
        s = full.states[k]
        assert lazy.states[k] == s
        assert lazy.actions(s) == full.actions(s)
        assert lazy.propositions(s) == full.propositions(s)
        for a in full.actions(s):
            assert lazy.successors(s, a, frozenset()) == full.successors(s, a, frozenset())
    assert lazy.robot_actions() == full.robot_actions()


def test_budget_stops_a_lazy_world_before_storm_explores_past_it(tmp_path):
    path = _grid(tmp_path, 30, goal=(20, 20))
    task = parse("F[0,12] goal")  # within 12 steps: 91 states; max_states 40
    game = load_prism(path, task=task, explore="lazy", first_states=5, max_states=40)
    with pytest.raises(PrismTooLarge, match="max_states = 40"):
        mitld_lp.synthesize(mitld_lp.Model.from_game(game, "F[0,12] goal"))
    assert game.explored <= 40


def test_exact_answer_and_event_effects_refused_by_name_on_a_lazy_world(tmp_path):
    path = _grid(tmp_path, 12)
    game = load_prism(path, task=parse("F[0,4] goal"), explore="lazy", first_states=4)
    assert exact_successors_of(game) is None  # refused before any work (the CLI test)
    with pytest.raises(WorldError, match="explored as the task reaches it"):
        game._moves((0, 0), "east", frozenset(), exact=True)
    with pytest.raises(WorldError, match="explore='lazy' takes no event effects"):
        load_prism(path, events=["east"], explore="lazy")
    with pytest.raises(TypeError, match="does not pickle"):
        pickle.dumps(game)
    with pytest.raises(ValueError, match="explore must be"):
        load_prism(path, explore="some")


def test_lazy_bracket_holds_storms_step_bounded_value(tmp_path):
    path = _grid(tmp_path, 40)
    lazy = load_prism(path, task=parse("F[0,9] goal"), explore="lazy", first_states=16)
    lower, upper, *_ = _answer(lazy, "F[0,9] goal")
    exact = storm_rational(path, 'Pmax=? [F<=9 "goal"]')  # Storm's exact engine
    assert lower <= exact <= upper and upper - lower < 1e-6  # a Fraction against floats
    assert lazy.explored < 1600


def test_auto_explores_the_horizon_before_the_product(tmp_path):
    # F[0,6]: the states within 6 moves of (0,0) are the 28 with x + y <= 6 (counted by
    # hand); auto explores them all before the product, which then needs nothing more
    path = _grid(tmp_path, 30)
    game = load_prism(path, task=parse("F[0,6] goal"), first_states=4)
    assert isinstance(game, LazyPrismGame)
    assert 28 <= game.explored < 900
    before = game.limit
    full = load_prism(path, task=parse("F[0,6] goal"), explore="full")
    assert _answer(game, "F[0,6] goal") == _answer(full, "F[0,6] goal")
    assert game.limit == before  # no exploration during the product


def _model(tmp_path, explore: str | None, spec: str = "F[0,5] goal") -> str:
    prism = _grid(tmp_path, 80)  # 6,400 states: more than load_prism's first 4,096
    key = "" if explore is None else f'explore = "{explore}"\n'
    path = tmp_path / "m.toml"
    path.write_text(f'name = "g"\nspec = "{spec}"\n[prism]\nfile = "{prism.name}"\n{key}')
    return str(path)


def test_model_file_explore_key_and_the_exact_refusal(tmp_path, capsys):
    from mitld_lp.cli import main

    model = _model(tmp_path, None)
    assert isinstance(mitld_lp.load_model(model).game, LazyPrismGame)
    # --exact is refused before any work, naming the world and the key that fixes it
    assert main(["solve", model, "--exact"]) == 2
    err = capsys.readouterr().err
    assert "explored as the task reaches it" in err and 'explore = \\"full\\"' not in err
    assert '[prism] explore = "full"' in err and "LP optimal" not in err
    full = _model(tmp_path, "full")
    assert type(mitld_lp.load_model(full).game) is PrismGame
    assert main(["solve", full, "--exact", "--json"]) == 0
    capsys.readouterr()
    assert main(["solve", _model(tmp_path, "eager")]) == 2
    assert 'prism.explore: must be "auto", "full" or "lazy"' in capsys.readouterr().err


def test_door_answers_a_bounded_property_on_a_lazy_world(tmp_path, capsys):
    from mitld_lp.cli import main

    prism = str(_grid(tmp_path, 80))
    assert main(["solve", prism, "--prop", 'Pmax=? [F<=5 "goal"]']) == 0
    said = capsys.readouterr().out
    # (0,0) -> (3,2) in 5 moves: all five succeed, 0.9^3 (east) * 0.9^2 (north) = 0.59049
    assert "[0.5904899, 0.5904901]" in said or "[0.59049, 0.59049]" in said
    explored = int(said.split(" world states")[0].rsplit(" ", 1)[-1])
    assert 21 <= explored < 6400  # every state within 5 moves (21), not the whole grid
