"""``[gym]`` and ``[python]`` worlds in model files: the command line, sweeps and batches
take any world the library takes; mistakes are one line naming the key path."""

from __future__ import annotations

import os
import re
import sys

import pytest
from test_worlds_gym import _bounded_reach

from mitld_lp import GridWorld, ModelError, load_model, synthesize
from mitld_lp.cli import main
from mitld_lp.sweep import run_sweep

FROZEN = """\
name = "lake"
spec = "F[0,{K}] goal"
[constants]
K = 6
[gym]
env = "FrozenLake-v1"
kwargs = { map_name = "4x4", is_slippery = true }
"""

FACTORY = '''\
from mitld_lp import GridWorld

CALLS = []

def corridor(n=3, slip=0.0):
    CALLS.append(n)
    return GridWorld.make(n, 1, start=(0, 0), slip=slip, regions={"goal": [(n - 1, 0)]})

def not_a_game():
    return 42
'''


@pytest.fixture()
def folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    yield tmp_path
    sys.modules.pop("myworld", None)  # each test's folder has its own module file


def test_frozen_lake_from_a_model_file_matches_value_iteration(folder):
    gym = pytest.importorskip("gymnasium")
    (folder / "lake.toml").write_text(FROZEN)
    model = load_model(folder / "lake.toml")
    assert model.game.actions(model.game.initial) == ("LEFT", "DOWN", "RIGHT", "UP")
    assert model.game.proposition_names == {"goal", "hole"}
    env = gym.make("FrozenLake-v1", map_name="4x4", is_slippery=True)
    desc = [[c.decode() for c in row] for row in env.unwrapped.desc]
    goal = {r * 4 + c for r, row in enumerate(desc) for c, x in enumerate(row) if x == "G"}
    hole = {r * 4 + c for r, row in enumerate(desc) for c, x in enumerate(row) if x == "H"}
    r = synthesize(model)
    assert r.certified
    assert r.lower == pytest.approx(_bounded_reach(env.unwrapped.P, goal, hole, 6)[0], abs=1e-7)


def test_a_gym_world_with_propositions_by_state(folder):
    pytest.importorskip("gymnasium")
    # CliffWalking has no map: name the states.  The start 36 and the goal 47 are the
    # ends of the bottom row, the cliff (37..46) between them: the shortest safe path is
    # up, 11 times right, down, 13 moves (no slip).
    text = ('name = "cliff"\nspec = "F[0,{K}] goal"\n[constants]\nK = 13\n[gym]\n'
            'env = "CliffWalking-v1"\npropositions = { goal = [47] }\n'
            'actions = ["UP", "RIGHT", "DOWN", "LEFT"]\n')
    (folder / "cliff.toml").write_text(text)
    assert synthesize(load_model(folder / "cliff.toml")).lower == pytest.approx(1.0)
    (folder / "cliff.toml").write_text(text.replace("K = 13", "K = 12"))
    assert synthesize(load_model(folder / "cliff.toml")).lower == pytest.approx(0.0)


def test_a_python_world_is_called_with_its_keyword_arguments(folder):
    (folder / "myworld.py").write_text(FACTORY)
    text = ('name = "py"\nspec = "F[0,{T}] goal"\n[constants]\nT = 2\n[python]\n'
            'world = "myworld:corridor"\nkwargs = { n = 3 }\n')
    (folder / "py.toml").write_text(text)
    model = load_model(folder / "py.toml")
    assert model.game == GridWorld.make(3, 1, start=(0, 0), regions={"goal": [(2, 0)]})
    assert synthesize(model).lower == pytest.approx(1.0)  # two moves east, no slip
    (folder / "py.toml").write_text(text.replace("T = 2", "T = 1"))
    assert synthesize(load_model(folder / "py.toml")).lower == pytest.approx(0.0)


def test_a_python_world_in_a_sweep_and_a_batch(folder, capsys):
    (folder / "myworld.py").write_text(FACTORY)
    (folder / "py.toml").write_text(
        'name = "py"\nspec = "F[0,3] goal"\n[python]\nworld = "myworld:corridor"\n'
        "kwargs = { n = 3, slip = 0.0 }\n")
    (folder / "s.toml").write_text(
        'name = "s"\nmodel = "py.toml"\n[vary]\npython.kwargs.n = [2, 3, 4, 5]\n')
    run = run_sweep(folder / "s.toml")
    # a corridor of n cells needs n - 1 moves: within 3 steps for n <= 4
    assert [r["lower"] for r in run.rows] == pytest.approx([1.0, 1.0, 1.0, 0.0])
    assert main(["solve", "py.toml", "py.toml", "-q"]) == 0  # a batch of one, given twice
    assert capsys.readouterr().out.count("certified yes") == 1


@pytest.mark.parametrize(
    "table, expected",
    [
        ('[gym]\nenv = "NoSuchEnv-v0"', "m.toml: gym.env: gymnasium cannot make 'NoSuchEnv-v0': "),
        ('[gym]\nenv = "FrozenLake-v1"\nkwargs = { speed = 2 }',
         "m.toml: gym.kwargs: gymnasium.make('FrozenLake-v1', ...) failed: TypeError: "),
        ('[gym]\nenv = "FrozenLake-v1"\nlabels = { G = "F" }',
         "m.toml: gym.labels.G: 'F' is not a name a formula can write"),
        ('[gym]\nenv = "CliffWalking-v1"',
         "m.toml: gym.labels: CliffWalking-v1 has no map with one cell per state"),
        ('[gym]\nenv = "FrozenLake-v1"\nterminal = "stop"',
         'm.toml: gym.terminal: must be "absorb" or "keep"'),
        ('[gym]\nenv = "FrozenLake-v1"\nspeed = 1', "m.toml: gym.speed: unknown key"),
        ('[python]\nworld = "myworld.corridor"',
         'm.toml: python.world: must be "package.module:factory", got \'myworld.corridor\''),
        ('[python]\nworld = "no_such_module_x:f"',
         "m.toml: python.world: cannot import no_such_module_x: No module named"),
        ('[python]\nworld = "myworld:nothing"',
         "m.toml: python.world: myworld has no attribute nothing"),
        ('[python]\nworld = "myworld:not_a_game"',
         "m.toml: python.world: myworld:not_a_game returned int, not a game"),
        ('[python]\nworld = "myworld:corridor"\nkwargs = { width = 3 }',
         "m.toml: python.kwargs: myworld:corridor(**kwargs) raised TypeError: "),
        ('[python]\nworld = "myworld:corridor"\n[grid]\nsize = [2, 2]\nstart = [0, 0]',
         "m.toml: exactly one game table is allowed, got [grid], [python]"),
    ],
)
def test_world_errors_name_the_key_path(folder, capsys, table, expected):
    if "[gym]" in table:
        pytest.importorskip("gymnasium")
    (folder / "myworld.py").write_text(FACTORY)
    (folder / "m.toml").write_text(f'name = "m"\nspec = "F[0,2] goal"\n{table}\n')
    with pytest.raises(ModelError) as info:
        load_model("m.toml")
    assert str(info.value).startswith(expected), str(info.value)
    assert main(["solve", "m.toml"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == f"mitld-lp: error: {info.value}"


@pytest.mark.parametrize("kind, make", [("a FIFO (named pipe)", os.mkfifo),
                                        ("a directory", os.mkdir)])
def test_a_python_world_module_that_is_no_regular_file_is_named(folder, kind, make):
    # issue 41, defect 11's other places: Python passes over a module file that is no
    # regular file in silence ("No module named"); the error says what is there
    make(folder / "fifoworld.py")
    (folder / "m.toml").write_text('name = "m"\nspec = "F[0,2] goal"\n[python]\n'
                                   'world = "fifoworld:corridor"\n')
    with pytest.raises(ModelError, match=re.escape(
            f"m.toml: python.world: cannot import fifoworld: No module named 'fifoworld' "
            f"(fifoworld.py is {kind}, not a regular file)")):
        load_model("m.toml")
