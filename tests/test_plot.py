"""Pictures: the policy of any grid world (``mitld-lp plot MODEL``) and a sweep's column
(``mitld-lp plot RESULTS --x --y``); the sizes asked for, pictures that differ exactly
when the policies do, the docs' own pictures."""

from __future__ import annotations

import importlib
import struct
import sys
from pathlib import Path

import pytest

from mitld_lp import GridWorld, Model, load_model, synthesize
from mitld_lp.cli import main
from mitld_lp.plot import (
    PlotError,
    Situation,
    parse_situation,
    policy_figure,
    policy_map,
    save,
)

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
STORM_BUS = 0.9244053  # Storm's Pmax on the DRN of models/bus_grid.toml (test_experiments)


def png_size(path: Path) -> tuple[int, int]:
    """Width and height from the PNG's IHDR chunk (bytes 16..24)."""
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC and data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


def pixels(path: Path):
    from matplotlib.image import imread

    return imread(path)


# A corridor of 5 cells, the robot in the middle, A at the east end, B at the west end.
CORRIDOR = GridWorld.make(5, 1, start=(2, 0), regions={"A": [(4, 0)], "B": [(0, 0)]})


def test_the_policy_map_of_a_corridor_by_hand():
    # "eventually A" with no slip: success from every cell, so a deterministic policy
    # must walk east from every cell west of A (any other move at some cell traps the
    # robot in a loop that never reaches A); likewise west for B
    east = policy_map(synthesize(Model.from_game(CORRIDOR, "F A")))
    west = policy_map(synthesize(Model.from_game(CORRIDOR, "F B")))
    for x in range(4):
        assert east.cells[(x, 0)].kind == "open" and east.cells[(x, 0)].action == "E"
        assert east.cells[(x, 0)].value == pytest.approx(1.0)
    for x in range(1, 5):
        assert west.cells[(x, 0)].kind == "open" and west.cells[(x, 0)].action == "W"
    # reaching the region decides the task on arrival
    assert east.cells[(4, 0)].kind == "done" and west.cells[(0, 0)].kind == "done"
    # with a deadline the automaton counts the steps: at its first state only the start
    # is a product state; two moves east are needed, within 3 steps
    timed = policy_map(synthesize(Model.from_game(CORRIDOR, "F[0,3] A")))
    assert timed.cells[(2, 0)].value == pytest.approx(1.0)
    assert {timed.cells[(x, 0)].kind for x in (0, 1, 3)} == {"unreached"}


def test_policy_pictures_have_the_size_asked_and_differ_with_the_policy(tmp_path):
    east = synthesize(Model.from_game(CORRIDOR, "F A"))
    west = synthesize(Model.from_game(CORRIDOR, "F B"))
    paths = [tmp_path / f"{name}.png" for name in ("east", "east_again", "west")]
    for result, path in zip([east, east, west], paths, strict=True):
        save(policy_figure(result, size=(640, 300)), path)
        assert png_size(path) == (640, 300)
    a, again, b = (pixels(p) for p in paths)
    assert (a == again).all()  # the same policy draws the same picture
    assert a.shape == b.shape and (a != b).any()  # another policy, another picture


def test_the_start_cell_shows_the_certified_optimum():
    result = synthesize(load_model(MODELS / "bus_grid.toml"))
    pm = policy_map(result)
    assert pm.pending == {"b1", "b2"}
    assert pm.cells[(0, 0)].value == pytest.approx(STORM_BUS, abs=1e-6)
    # a bus arriving while the robot is at its station satisfies the task at once
    after_b1 = policy_map(result, parse_situation("occurred=b1"))
    assert after_b1.pending == {"b2"} and after_b1.cells[(1, 2)].kind == "done"
    # next to station A the policy heads for it
    assert after_b1.cells[(1, 1)].action == "N" and after_b1.cells[(1, 3)].action == "S"


def test_a_region_to_avoid_is_marked_failed():
    pm = policy_map(synthesize(load_model(MODELS / "red_light.toml")))
    assert pm.cells[(3, 0)].kind == "failed"  # entering the junction before green


def test_situations_parse_and_are_checked():
    s = parse_situation("pending=b2; occurred = b1 ;automaton=3; clock=0")
    assert s == Situation(pending=frozenset({"b2"}), occurred=frozenset({"b1"}), automaton=3,
                          clock=0)
    assert parse_situation("") == Situation() == parse_situation("initial")
    assert parse_situation("pending=") == Situation(pending=frozenset())
    for bad in ("speed=1", "automaton=x", "clock=1; clock=2", "b1"):
        with pytest.raises(PlotError, match="situation"):
            parse_situation(bad)
    result = synthesize(load_model(MODELS / "bus_grid.toml"))
    with pytest.raises(PlotError, match="'zz' is not an event of the spec"):
        policy_map(result, Situation(occurred=frozenset({"zz"})))
    with pytest.raises(PlotError, match="automaton: no state 999"):
        policy_map(result, Situation(automaton=999))


def test_plot_a_model_from_the_command_line(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    bus = str(MODELS / "bus_grid.toml")
    assert main(["plot", bus, "-o", "p.png", "--size", "900x400", "-q",
                 "--situation", "initial", "--situation", "occurred=b2"]) == 0
    assert png_size(tmp_path / "p.png") == (900, 400)
    before = (tmp_path / "p.png").read_bytes()
    assert main(["plot", bus, "-o", "p.png", "-q"]) == 2  # exists: --force to replace
    assert (tmp_path / "p.png").read_bytes() == before
    capsys.readouterr()
    for argv, message in [
        ([str(MODELS / "corridor.toml"), "-o", "c.png"], "its world is a PrismGame, not a grid"),
        ([bus, "-o", "c.png", "--situation", "occurred=zz"], "'zz' is not an event"),
        ([bus, "-o", "c.png", "--x", "T"], "--x applies to a results file"),
        ([bus, "-o", "c.txt"], "the suffix must be one of .png, .svg, .pdf"),
        ([bus, "-o", "c.png", "--size", "10x10"], "must be WIDTHxHEIGHT"),
    ]:
        assert main(["plot", *argv, "-q"]) == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], (argv, err)
        assert not (tmp_path / "c.png").exists()


SWEEP = """\
name = "s"
model = "m.toml"
[vary]
grid.slip = [0.0, 0.1, 0.2]
constants.T = [1, 2]
"""
MODEL = """\
name = "m"
spec = "F[0,{T}] A"
[constants]
T = 2
[grid]
size = [3, 1]
start = [0, 0]
[regions]
A = [[2, 0]]
"""


def test_plot_a_sweep_from_the_command_line(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "m.toml").write_text(MODEL)
    (tmp_path / "s.toml").write_text(SWEEP)
    assert main(["sweep", "s.toml", "-q"]) == 0
    assert main(["plot", "s.csv", "--x", "slip", "--y", "lower", "-o", "a.png",
                 "--size", "500x400", "-q"]) == 0
    assert png_size(tmp_path / "a.png") == (500, 400)
    assert main(["plot", "s.csv", "--x", "T", "--y", "states", "-o", "b.png", "-q"]) == 0
    assert png_size(tmp_path / "b.png") == (800, 600)
    assert (pixels(tmp_path / "a.png").shape != pixels(tmp_path / "b.png").shape)
    capsys.readouterr()
    for argv, message in [
        (["--x", "speed", "--y", "lower"], "--x 'speed' is not a column of the results "
                                           "(columns: grid.slip, constants.T)"),
        (["--x", "slip"], "a results file needs --x and --y"),
        (["--x", "slip", "--y", "lower", "--situation", "occurred=b"],
         "--situation applies to a model file"),
        # model options on a results file were accepted and ignored
        (["--x", "slip", "--y", "lower", "--epsilon", "0.1"],
         "--epsilon applies to a model file"),
        (["--x", "slip", "--y", "lower", "--max-states", "3"],
         "--max-states applies to a model file"),
    ]:
        assert main(["plot", "s.csv", *argv, "-o", "c.png", "-q"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], err


def test_the_docs_pictures_are_the_script_s(tmp_path, capsys):
    """The pictures docs/sweeps.md shows are experiments/docs_figures.py's: the test
    suite runs the script, and the committed pictures have the sizes it draws."""
    experiments = ROOT / "experiments"
    if str(experiments) not in sys.path:
        sys.path.insert(0, str(experiments))
    written = importlib.import_module("docs_figures").main(["--quick", "--out", str(tmp_path)])
    capsys.readouterr()
    expected = {"bus_policy.png": (1200, 430), "bus_sweep.png": (720, 480)}
    assert {p.name for p in written.values()} == set(expected)
    for name, size in expected.items():
        assert png_size(tmp_path / name) == size
        committed = ROOT / "docs" / "img" / name
        assert png_size(committed) == size
        assert f"img/{name}" in (ROOT / "docs" / "sweeps.md").read_text()
