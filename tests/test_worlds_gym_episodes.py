"""gymnasium worlds as the environment means them: rewards and termination as
propositions, the environment's TimeLimit, integer actions in the real environment, and
the table's budget checked before it is built.

Independent routes: Storm on a PRISM program written here from the environment's own
table (a ``fell`` flag set by the -100 transitions), value iteration with the horizon
written here, rollouts in the real environment, and a hand calculation."""

from __future__ import annotations

import importlib.util
import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from mitld_lp import Model, synthesize
from mitld_lp.running.gym import GymAgent
from mitld_lp.worlds import WorldError
from mitld_lp.worlds.gym import (
    FROZEN_LAKE_ACTIONS,
    GymTooLarge,
    from_env,
    from_transition_table,
    map_labels,
    time_limit_of,
)

ROOT = Path(__file__).resolve().parent.parent
needs_gym = pytest.mark.skipif(importlib.util.find_spec("gymnasium") is None,
                               reason="needs gymnasium")
needs_storm = pytest.mark.skipif(importlib.util.find_spec("stormpy") is None,
                                 reason="needs stormpy")


# --------------------------------------------------------------------------- by hand


# 0 --go--> 1 with 0.5 (reward -5: a "bump"), else 2 ending the episode (reward 1)
TABLE = {
    0: {0: [(0.5, 1, -5.0, False), (0.5, 2, 1.0, True)], 1: [(1.0, 0, 0.0, False)]},
    1: {0: [(1.0, 0, 0.0, False)], 1: [(1.0, 1, 0.0, False)]},
    2: {0: [(1.0, 0, 0.0, False)], 1: [(1.0, 2, 0.0, False)]},
}


def test_reward_and_done_labels_hold_where_the_transition_leads() -> None:
    game = from_transition_table(TABLE, 0, reward_labels={"bump": -5, "paid": (0.5, 2)},
                                 done_label="done", action_names=["go", "wait"])
    assert game.proposition_names == {"bump", "paid", "done"}
    start = game.initial
    assert start == (0, 0, (), False) and game.propositions(start) == frozenset()
    succ = dict(game.successors(start, "go", frozenset()))
    assert succ == {(1, 0, ("bump",), False): 0.5, (2, 0, ("done", "paid"), True): 0.5}
    # the ended state is absorbing; the bump holds for one step only
    assert dict(game.successors((2, 0, ("done", "paid"), True), "go", frozenset())) == {
        (2, 0, ("done", "paid"), True): 1.0}
    assert game.propositions((1, 0, (), False)) == frozenset()
    # by hand: the bump comes at step 1 with 0.5; the other half ends the episode in 2
    # (absorbing), so no later bump: F[0,k] bump = 0.5 for every k >= 1, and
    # F[0,1] (bump | done) = 1
    for spec, value in (("F[0,1] bump", 0.5), ("F[0,5] bump", 0.5), ("F[0,1] (bump | done)", 1.0)):
        r = synthesize(Model.from_game(game, spec))
        assert r.lower == pytest.approx(value, abs=1e-9)
    # a time limit of 2 steps: done within the episode at most 0.5 + 0.5 * 0 = 0.5 ...
    short = from_transition_table(TABLE, 0, done_label="done", horizon=2,
                                  action_names=["go", "wait"])
    assert synthesize(Model.from_game(short, "F done")).lower == pytest.approx(0.5, abs=1e-9)
    # ... and 0.75 with 4 steps (go, back, go)
    longer = from_transition_table(TABLE, 0, done_label="done", horizon=4,
                                   action_names=["go", "wait"])
    r = synthesize(Model.from_game(longer, "F done"))
    assert r.lower == pytest.approx(0.75, abs=1e-9)


def test_bad_reward_labels_and_budgets_are_refused() -> None:
    with pytest.raises(WorldError, match=r"reward_labels.x: must be a reward or an interval"):
        from_transition_table(TABLE, 0, reward_labels={"x": (3, 1)})
    with pytest.raises(WorldError, match=r"horizon: must be a positive integer"):
        from_transition_table(TABLE, 0, horizon=0)
    with pytest.raises(GymTooLarge, match=r"3 states, .*more than max_states = 2"):
        from_transition_table(TABLE, 0, max_states=2)
    with pytest.raises(GymTooLarge, match=r"time limit of 10 steps, at least 33 game states"):
        from_transition_table(TABLE, 0, horizon=10, max_states=20)
    with pytest.raises(GymTooLarge, match=r"more than max_memory = 100 bytes"):
        from_transition_table(TABLE, 0, max_memory=100)


# --------------------------------------------------------------------------- CliffWalking


def cliff_prism(P: dict, start: int) -> str:
    """The environment's table as PRISM, written independently of mitld_lp: ``fell`` is
    true exactly after a -100 transition, ``done`` after a terminated one (absorbing)."""
    lines = ["mdp", "module cliff", f"  s : [0..{len(P) - 1}] init {start};",
             "  fell : bool init false;", "  done : bool init false;"]
    for s, acts in P.items():
        for a, outcomes in acts.items():
            ups = " + ".join(
                f"{float(p)!r} : (s'={int(n)}) & (fell'={'true' if r == -100 else 'false'}) & "
                f"(done'={'true' if t else 'false'})" for p, n, r, t in outcomes)
            lines.append(f"  [a{a}] s={s} & !done -> {ups};")
    lines += ["  [end] done -> true;", "endmodule",
              'label "cliff" = fell;', f'label "goal" = s={len(P) - 1};']
    return "\n".join(lines) + "\n"


def storm_value(path: Path, prop: str) -> float:
    import stormpy

    program = stormpy.parse_prism_program(str(path))
    props = stormpy.parse_properties(prop, program)
    model = stormpy.build_model(program, props)
    return float(stormpy.model_checking(model, props[0]).get_value_vector()[
        model.initial_states[0]])


@needs_gym
@needs_storm
@pytest.mark.parametrize("slippery", [False, True])
def test_cliff_walking_falls_are_seen_and_agree_with_storm(tmp_path: Path, slippery: bool
                                                           ) -> None:
    import gymnasium

    env = gymnasium.make("CliffWalking-v1", is_slippery=slippery)
    assert time_limit_of(env) is None
    game = from_env(env, propositions={47: {"goal"}}, proposition_names={"goal"},
                    reward_labels={"cliff": -100})
    src = tmp_path / "cliff.prism"
    src.write_text(cliff_prism(env.unwrapped.P, 36))
    cases = [("G !cliff", '1-Pmin=? [F "cliff"]'), ("F[0,1] cliff", 'Pmax=? [F<=1 "cliff"]'),
             ("!cliff U goal", 'Pmax=? [!"cliff" U "goal"]'),
             ("!cliff U[0,20] goal", 'Pmax=? [!"cliff" U<=20 "goal"]')]
    for spec, prop in cases:
        r = synthesize(Model.from_game(game, spec))
        want = (1.0 - storm_value(src, prop[2:])) if prop.startswith("1-") else storm_value(
            src, prop)
        assert r.certified
        assert r.lower - 1e-7 <= want <= r.upper + 1e-7, (spec, want, r.lower, r.upper)
    # the falls are seen: reaching the cliff in one step is possible (right from the start)
    assert synthesize(Model.from_game(game, "F[0,1] cliff")).lower > 0.3


# --------------------------------------------------------------------------- TimeLimit


def reach_within(P: dict, goal: set[int], hole: set[int], k: int) -> float:
    """Value iteration written here: max probability of the goal within k steps, the
    goal and holes ending the episode."""
    v = np.array([1.0 if s in goal else 0.0 for s in range(len(P))])
    for _ in range(k):
        v = np.array([1.0 if s in goal else 0.0 if s in hole else
                      max(sum(p * v[t] for p, t, _, _ in P[s][a]) for a in P[s])
                      for s in range(len(P))])
    return float(v[0])


@needs_gym
def test_frozen_lake_time_limit_is_honoured_and_rollouts_agree() -> None:
    import gymnasium

    env = gymnasium.make("FrozenLake-v1", map_name="4x4", is_slippery=True)
    assert time_limit_of(env) == 100
    desc = env.unwrapped.desc
    labels = map_labels(desc)
    goal = {s for s, n in labels.items() if "goal" in n}
    hole = {s for s, n in labels.items() if "hole" in n}
    game = from_env(env, propositions=labels, action_names=FROZEN_LAKE_ACTIONS)
    assert game.horizon == 100
    r = synthesize(Model.from_game(game, "!hole U goal"))
    within = reach_within(env.unwrapped.P, goal, hole, 100)
    unlimited = reach_within(env.unwrapped.P, goal, hole, 5000)
    assert r.certified and r.lower == pytest.approx(within, abs=1e-6)
    assert within < unlimited - 0.05  # the limit matters: the answer is the limited one
    ignored = from_env(env, propositions=labels, action_names=FROZEN_LAKE_ACTIONS,
                       time_limit="ignore")
    assert synthesize(Model.from_game(ignored, "!hole U goal")).lower == pytest.approx(
        unlimited, abs=1e-6)

    # the controller in the real environment, its TimeLimit included
    agent = GymAgent(r.controller, game)
    runs, wins = 600, 0
    for seed in range(runs):
        obs, _ = env.reset(seed=seed)
        action = agent.reset(obs)
        while action is not None:
            assert isinstance(action, int | np.integer) and env.action_space.contains(action)
            obs, reward, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                wins += int(obs in goal)
                break
            action = agent.step(obs, reward, terminated)
        else:
            wins += int(agent.controller.status.value == "accepted")
    p = r.lower
    assert abs(wins / runs - p) <= 4 * math.sqrt(p * (1 - p) / runs)  # 4 sigma


# --------------------------------------------------------------------------- budget


@needs_gym
def test_large_lake_is_refused_before_its_game_is_built(tmp_path: Path) -> None:
    # gymnasium builds its own table (about 0.4 GB) in make; the game would need more
    # again. The address space is capped just above what the process uses after make,
    # so building the game would fail with MemoryError instead of the budget's refusal.
    script = textwrap.dedent("""
        import resource, sys
        import gymnasium
        from mitld_lp.worlds.gym import GymTooLarge, from_env
        desc = ["S" + "F" * 399] + ["F" * 400] * 398 + ["F" * 399 + "G"]
        env = gymnasium.make("FrozenLake-v1", desc=desc, is_slippery=True)
        with open("/proc/self/statm") as f:
            used = int(f.read().split()[0]) * resource.getpagesize()
        resource.setrlimit(resource.RLIMIT_AS, (used + (150 << 20), resource.RLIM_INFINITY))
        for kwargs in ({"max_states": 1000, "max_memory": 10 << 20},
                       {"max_memory": 10 << 20, "time_limit": "ignore"}):
            try:
                from_env(env, **kwargs)
            except GymTooLarge as exc:
                print("refused:", exc)
        """)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         timeout=300, env=env)
    assert run.returncode == 0, run.stderr[-2000:]
    lines = run.stdout.splitlines()
    assert len(lines) == 2
    assert "160,000 states, with its time limit of 100 steps, at least 16,160,000" in lines[0]
    assert "max_states = 1,000" in lines[0]
    assert "more than max_memory = 10.5 MB" in lines[1]


@needs_gym
def test_a_gym_model_file_names_rewards_and_is_budgeted_before_make(tmp_path: Path) -> None:
    """[gym] reward_labels make CliffWalking's falls a proposition in a model file (the
    same answer as from_env with reward_labels, the route checked against Storm above);
    a 160,000-state lake under --max-memory 10M is refused before gymnasium builds its
    table: run under an address-space limit far below what that table takes."""
    import gymnasium

    from mitld_lp import Model, load_model, synthesize
    from mitld_lp.worlds.gym import from_env

    path = tmp_path / "cliff.toml"
    path.write_text('name = "cliff"\nspec = "G !cliff & F[0,20] goal"\n[gym]\n'
                    'env = "CliffWalking-v1"\nkwargs = { is_slippery = true }\n'
                    "reward_labels = { cliff = -100 }\npropositions = { goal = [47] }\n")
    from_file = synthesize(load_model(path))
    env = gymnasium.make("CliffWalking-v1", is_slippery=True)
    game = from_env(env, reward_labels={"cliff": -100}, propositions={47: {"goal"}},
                    proposition_names=["goal"])
    direct = synthesize(Model.from_game(game, "G !cliff & F[0,20] goal"))
    assert 0 < from_file.lower < 0.5  # the falls count: not the vacuous 1.0
    assert from_file.lower == pytest.approx(direct.lower, abs=1e-12)

    desc = ["S" + "F" * 399] + ["F" * 400] * 398 + ["F" * 399 + "G"]
    big = tmp_path / "lake.toml"
    big.write_text('name = "lake"\nspec = "F goal"\n[gym]\nenv = "FrozenLake-v1"\n'
                   "kwargs = { desc = [" + ", ".join(f'"{r}"' for r in desc) + "] }\n")
    script = textwrap.dedent(f"""
        import resource, sys
        from mitld_lp.cli import main
        with open("/proc/self/statm") as f:
            used = int(f.read().split()[0]) * resource.getpagesize()
        resource.setrlimit(resource.RLIMIT_AS, (used + (200 << 20), resource.RLIM_INFINITY))
        sys.exit(main(["solve", {str(big)!r}, "--max-memory", "10M", "-q"]))
        """)
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         timeout=300, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert run.returncode == 3, run.stderr[-2000:]
    assert "160,000 states" in run.stderr and "before it is built" in run.stderr
