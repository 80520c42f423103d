"""Toy-text transition tables as games: a table written by hand, and (when gymnasium is
installed) FrozenLake-v1 against value iteration written here on the same table."""

from __future__ import annotations

import numpy as np
import pytest

from mitld_lp import Model, synthesize
from mitld_lp.worlds import WorldError
from mitld_lp.worlds.game import check_game
from mitld_lp.worlds.gym import FROZEN_LAKE_ACTIONS, from_env, from_transition_table, map_labels

# A three-state chain: from 0, "go" (1) reaches 1 with 0.6 (else stays, listed twice to
# be merged); from 1, "go" ends the episode in 2 (the goal); "back" (0) returns to 0.
TABLE = {
    0: {0: [(1.0, 0, 0.0, False)], 1: [(0.6, 1, 0.0, False), (0.2, 0, 0.0, False),
                                       (0.2, 0, 0.0, False)]},
    1: {0: [(1.0, 0, 0.0, False)], 1: [(0.5, 2, 1.0, True), (0.5, 1, 0.0, False)]},
    2: {0: [(1.0, 0, 0.0, False)], 1: [(1.0, 0, 0.0, False)]},  # as if reset: absorbed
}


def test_hand_table() -> None:
    game = from_transition_table(TABLE, 0, propositions={2: {"goal"}},
                                 action_names=("back", "go"))
    assert game.actions(0) == ("back", "go")
    assert dict(game.successors(0, "go", frozenset())) == pytest.approx({1: 0.6, 0: 0.4})
    # the state the terminated transition enters is absorbing
    assert dict(game.successors(2, "back", frozenset())) == {2: 1.0}
    assert game.propositions(2) == {"goal"} and game.propositions(1) == frozenset()
    assert check_game(game).states == 3
    # F[0,3] goal: go, go, go must reach 1 then 2: by hand, the first success of "go"
    # from 0 (0.6) at step 1 or 2, then 0.5 per step at 1:
    # P = 0.6*(0.5 + 0.5*0.5) + 0.4*0.6*0.5 = 0.45 + 0.12 = 0.57
    r = synthesize(Model.from_game(game, "F[0,3] goal"))
    assert r.lower == pytest.approx(0.57, abs=1e-9) and r.upper == pytest.approx(0.57, abs=1e-9)
    kept = from_transition_table(TABLE, 0, propositions=lambda s: {"goal"} if s == 2 else (),
                                 terminal="keep")
    assert dict(kept.successors(2, "1", frozenset())) == {0: 1.0}
    assert kept.proposition_names == {"goal"}


def test_hand_table_errors() -> None:
    with pytest.raises(WorldError, match=r"initial state 7 is not a state"):
        from_transition_table(TABLE, 7)
    with pytest.raises(WorldError, match=r"no name for action 1"):
        from_transition_table(TABLE, 0, action_names=["only"])
    with pytest.raises(WorldError, match=r"state 0: two actions are named 'a'"):
        from_transition_table(TABLE, 0, action_names={0: "a", 1: "a"})
    with pytest.raises(WorldError, match=r"successor 9 has no transitions"):
        from_transition_table({0: {0: [(1.0, 9, 0, False)]}}, 0)
    with pytest.raises(WorldError, match=r"probabilities must sum to 1"):
        from_transition_table({0: {0: [(0.5, 0, 0, False)]}}, 0)
    with pytest.raises(WorldError, match=r"expected \(probability, next_state, reward"):
        from_transition_table({0: {0: [(1.0, 0)]}}, 0)
    with pytest.raises(WorldError, match=r"got the string 'goal'"):
        from_transition_table(TABLE, 0, propositions={2: "goal"})
    # state 1 is entered both by a terminated transition and by an ordinary one
    mixed = {0: {0: [(0.5, 1, 0, True), (0.5, 2, 0, False)]}, 1: {0: [(1.0, 1, 0, False)]},
             2: {0: [(1.0, 1, 0, False)]}}
    with pytest.raises(WorldError, match=r"state 1 ends an episode .* terminal='keep'"):
        from_transition_table(mixed, 0)
    assert check_game(from_transition_table(mixed, 0, terminal="keep")).states == 3


def test_map_labels_reads_letters() -> None:
    labels = map_labels(["SF", "HG"])
    assert labels == {2: {"hole"}, 3: {"goal"}}
    assert map_labels([[b"S", b"G"]], {"S": "start"}) == {0: {"start"}}


def _bounded_reach(P: dict, goal: set[int], hole: set[int], k: int | None) -> np.ndarray:
    """Plain value iteration on the gym table: V_0 = [goal]; V_{j+1}(s) = 1 on goal,
    0 on holes (the episode ended there), else max_a sum_t p V_j(t).  k=None iterates
    to a fixed point (unbounded reachability)."""
    n = len(P)
    v = np.array([1.0 if s in goal else 0.0 for s in range(n)])
    for j in range(10**6):
        if k is not None and j == k:
            break
        w = np.array([
            1.0 if s in goal else 0.0 if s in hole else
            max(sum(p * v[t] for p, t, _, _ in P[s][a]) for a in P[s])
            for s in range(n)
        ])
        if k is None and np.max(np.abs(w - v)) < 1e-14:
            return w
        v = w
    return v


@pytest.mark.parametrize("map_name", ["4x4", "8x8"])
def test_frozen_lake_matches_value_iteration(map_name: str) -> None:
    gym = pytest.importorskip("gymnasium")
    env = gym.make("FrozenLake-v1", map_name=map_name, is_slippery=True)
    desc = env.unwrapped.desc
    # the table without the environment's TimeLimit (its own test below)
    game = from_env(env, propositions=map_labels(desc), action_names=FROZEN_LAKE_ACTIONS,
                    time_limit="ignore")
    labels = map_labels(desc)
    goal = {s for s, n in labels.items() if "goal" in n}
    hole = {s for s, n in labels.items() if "hole" in n}
    assert game.initial == 0 and game.actions(0) == FROZEN_LAKE_ACTIONS
    for k in (6, 14):
        r = synthesize(Model.from_game(game, f"F[0,{k}] goal"))
        vi = _bounded_reach(env.unwrapped.P, goal, hole, k)[0]
        assert r.certified
        assert r.lower == pytest.approx(vi, abs=1e-7) and r.upper == pytest.approx(vi, abs=1e-7)
    r = synthesize(Model.from_game(game, "!hole U goal"))
    vi = _bounded_reach(env.unwrapped.P, goal, hole, None)[0]
    assert r.lower == pytest.approx(vi, abs=1e-6)
    assert 0.0 < vi < 1.0
