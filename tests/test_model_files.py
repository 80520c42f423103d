"""Model files: every file in models/ loads to the expected game and bindings, and bad
files fail with a ModelError naming the source, the key path and the bad value."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import pytest

import mitld_lp.model as model_module
from mitld_lp.game_tables import GameKind
from mitld_lp.logic.syntax import (
    DistRef,
    Prop,
    atoms,
    conj,
    disj,
    dist,
    eventually,
    neg,
    until,
)
from mitld_lp.model import DEFAULT_EPSILON, Model, ModelError, load_model, loads_model
from mitld_lp.worlds.grid import GridWorld

MODELS = Path(__file__).resolve().parent.parent / "models"
BUS_GRID = MODELS / "bus_grid.toml"
BUS_GRID_CASE2 = MODELS / "bus_grid_case2.toml"
PATROL = MODELS / "patrol.toml"
RED_LIGHT = MODELS / "red_light.toml"


def pmfs(d, n: int) -> list[float]:
    return [float(d.pmf(k)) for k in range(1, n + 1)]


def close(a: list[float], b: list[float]) -> bool:
    if len(a) != len(b):
        return False
    return all(math.isclose(x, y, abs_tol=1e-12) for x, y in zip(a, b, strict=True))


def geometric(p: float, n: int) -> list[float]:
    return [(1 - p) ** (k - 1) * p for k in range(1, n + 1)]


# --------------------------------------------------------------------------- the files


def test_every_model_file_loads() -> None:
    files = sorted(MODELS.glob("*.toml"))
    assert {f.name for f in files} >= {
        "bus_grid.toml",
        "bus_grid_case2.toml",
        "patrol.toml",
        "red_light.toml",
    }
    for f in files:
        m = load_model(f)
        assert isinstance(m, Model)
        assert m.source == f
        assert m.name == f.stem
        # every proposition of the spec is a region or an event, events are not regions
        assert atoms(m.spec) <= m.game.proposition_names | m.events
        assert not (m.game.proposition_names & m.events)
        assert f.read_text().startswith("#"), "each model file opens with a comment header"


def bus_spec():
    b1, b2, a, b = Prop("b1"), Prop("b2"), Prop("A"), Prop("B")
    return disj(
        conj(dist(DistRef("mu1"), b1), eventually(conj(b1, eventually(a, (0, 3))))),
        conj(dist(DistRef("mu2"), b2), eventually(conj(b2, eventually(b, (0, 3))))),
    )


@pytest.mark.parametrize("path, p1, p2", [(BUS_GRID, 0.8, 0.3), (BUS_GRID_CASE2, 0.4, 0.7)])
def test_bus_grid(path: Path, p1: float, p2: float) -> None:
    m = load_model(path)
    assert m.spec == bus_spec()
    assert m.spec_text == "(D[mu1] b1 & F(b1 & F[0,3] A)) | (D[mu2] b2 & F(b2 & F[0,3] B))"
    assert m.epsilon == 0.01
    assert m.game == GridWorld(
        width=4,
        height=4,
        start=(0, 0),
        slip=0.1,
        obstacles=frozenset(),
        regions=(("A", frozenset({(1, 2)})), ("B", frozenset({(3, 0)}))),
    )
    assert m.events == frozenset({"b1", "b2"})
    assert close(pmfs(m.distributions["b1"], 6), geometric(p1, 6))
    assert close(pmfs(m.distributions["b2"], 6), geometric(p2, 6))


def test_patrol() -> None:
    m = load_model(PATROL)
    g = m.game
    assert isinstance(g, GridWorld)
    assert (g.width, g.height, g.start, g.slip) == (6, 6, (0, 0), 0.1)
    assert g.obstacles == frozenset({(2, 2), (2, 3), (3, 2), (3, 3)})
    assert g.region_map == {
        "S1": frozenset({(0, 5)}),
        "S2": frozenset({(5, 5)}),
        "S3": frozenset({(5, 0)}),
    }
    f = [Prop(f"f{i}") for i in (1, 2, 3)]
    s = [Prop(f"S{i}") for i in (1, 2, 3)]
    want = conj(
        *(dist(DistRef(f"m{i + 1}"), f[i]) for i in range(3)),
        *(eventually(conj(f[i], eventually(s[i], (0, d)))) for i, d in enumerate((6, 8, 7))),
    )
    assert m.spec == want
    assert m.events == frozenset({"f1", "f2", "f3"})
    assert close(pmfs(m.distributions["f1"], 6), [0.2, 0.3, 0.3, 0.2, 0.0, 0.0])
    # 1 + Poisson(7): P(K = k) = e^-7 7^(k-1) / (k-1)!
    poisson = [math.exp(-7) * 7 ** (k - 1) / math.factorial(k - 1) for k in range(1, 15)]
    assert close(pmfs(m.distributions["f2"], 14), poisson)
    assert close(pmfs(m.distributions["f3"], 20), [0.0] * 11 + [1 / 7] * 7 + [0.0] * 2)


def test_red_light() -> None:
    m = load_model(RED_LIGHT)
    g = m.game
    assert isinstance(g, GridWorld)
    assert (g.width, g.height, g.start, g.slip, g.obstacles) == (7, 1, (0, 0), 0.1, frozenset())
    assert g.region_map == {"box": frozenset({(3, 0)}), "far": frozenset({(5, 0), (6, 0)})}
    gr = Prop("g")
    assert m.spec == conj(
        dist(DistRef("w"), gr),
        until(neg(Prop("box")), conj(gr, eventually(Prop("far"), (0, 4)))),
    )
    # discretised Weibull(shape 2, scale 4): F(k) - F(k-1), F(x) = 1 - exp(-(x/4)^2)
    cdf = [1 - math.exp(-((x / 4) ** 2)) for x in range(0, 13)]
    want = [cdf[k] - cdf[k - 1] for k in range(1, 13)]
    assert close(pmfs(m.distributions["g"], 12), want)


def test_loads_model_defaults_and_inline_literal() -> None:
    text = """
name = "tiny"
spec = "D[geometric(0.5)] e & F(e & F[0,1] goal)"
[grid]
size = [2, 1]
start = [0, 0]
[regions]
goal = [[1, 0]]
"""
    m = loads_model(text)
    assert m.source is None
    assert m.epsilon == DEFAULT_EPSILON
    assert m.game == GridWorld(2, 1, (0, 0), 0.0, frozenset(), (("goal", frozenset({(1, 0)})),))
    assert close(pmfs(m.distributions["e"], 4), geometric(0.5, 4))


def test_unused_region_is_allowed() -> None:
    m = loads_model(
        'name = "n"\nspec = "F A"\n[grid]\nsize = [2, 2]\nstart = [0, 0]\n'
        "[regions]\nA = [[1, 1]]\nB = [[0, 1]]\n"
    )
    assert m.game.proposition_names == frozenset({"A", "B"})
    assert m.distributions == {}


def test_same_distribution_twice_for_an_event_is_fine() -> None:
    m = loads_model(
        'name = "n"\nspec = "(D[mu] e & F(e & A)) | (D[mu] e & F(e & F[0,1] A))"\n'
        "[grid]\nsize = [2, 2]\nstart = [0, 0]\n[regions]\nA = [[1, 1]]\n"
        "[distributions]\nmu = { geometric = 0.5 }\n"
    )
    assert m.events == frozenset({"e"})


# --------------------------------------------------------------------------- bad files

GOOD = """\
name = "bad"
spec = "(D[mu1] b1 & F(b1 & F[0,3] A)) | (D[mu2] b2 & F(b2 & F[0,3] B))"
epsilon = 0.01

[grid]
size = [4, 4]
start = [0, 0]
slip = 0.1
obstacles = [[2, 2]]

[regions]
A = [[1, 2]]
B = [[3, 0]]

[distributions]
mu1 = { geometric = 0.8 }
mu2 = { geometric = 0.3 }
"""


def edit(old: str, new: str) -> str:
    assert GOOD.count(old) == 1, old
    return GOOD.replace(old, new)


def test_good_base_loads() -> None:
    assert loads_model(GOOD).name == "bad"


# (case id, file text, fragments the message must contain after "SOURCE: ")
BAD: list[tuple[str, str, tuple[str, ...]]] = [
    ("unknown top-level table", GOOD + "[weather]\nrain = 1\n", ("weather: unknown key",)),
    ("unknown top-level key before tables", "foo = 1\n" + GOOD, ("foo: unknown key",)),
    ("unknown nested key", edit("slip = 0.1", "slip = 0.1\nwind = 2"), ("grid.wind: unknown key",)),
    (
        "unknown key in a distribution",
        edit("{ geometric = 0.8 }", "{ geometric = 0.8, p = 1 }"),
        ("distributions.mu1",),
    ),
    (
        "unknown distribution family",
        edit("{ geometric = 0.8 }", "{ normal = 0.8 }"),
        ("distributions.mu1", "normal"),
    ),
    (
        "distribution not a table",
        edit("mu1 = { geometric = 0.8 }", "mu1 = 0.8"),
        ("distributions.mu1", "0.8"),
    ),
    ("size wrong type", edit("size = [4, 4]", 'size = "4x4"'), ("grid.size", '"4x4"')),
    (
        "size float",
        edit("size = [4, 4]", "size = [4.0, 4]"),
        ("grid.size[0]: must be an integer", "4.0"),
    ),
    ("size one number", edit("size = [4, 4]", "size = [4]"), ("grid.size", "[4]")),
    (
        "negative size",
        edit("size = [4, 4]", "size = [-4, 4]"),
        ("grid.size[0]: must be a positive integer", "-4"),
    ),
    ("zero size", edit("size = [4, 4]", "size = [4, 0]"), ("grid.size[1]", "0")),
    ("bool slip", edit("slip = 0.1", "slip = true"), ("grid.slip: must be a number", "true")),
    (
        "bool epsilon",
        edit("epsilon = 0.01", "epsilon = false"),
        ("epsilon: must be a number", "false"),
    ),
    (
        "bool cell coordinate",
        edit("start = [0, 0]", "start = [true, 0]"),
        ("grid.start[0]: must be an integer", "true"),
    ),
    ("string slip", edit("slip = 0.1", 'slip = "0.1"'), ("grid.slip: must be a number", '"0.1"')),
    (
        "slip too large",
        edit("slip = 0.1", "slip = 0.7"),
        ("grid.slip: must be in [0, 0.5], got 0.7",),
    ),
    ("slip negative", edit("slip = 0.1", "slip = -0.1"), ("grid.slip", "-0.1")),
    ("slip nan", edit("slip = 0.1", "slip = nan"), ("grid.slip", "nan")),
    (
        "start off the grid",
        edit("start = [0, 0]", "start = [4, 0]"),
        ("grid.start: cell [4, 0] is off the 4x4 grid",),
    ),
    ("start not a pair", edit("start = [0, 0]", "start = 0"), ("grid.start", "got 0")),
    ("start missing", edit("start = [0, 0]\n", ""), ("grid.start: missing",)),
    ("size missing", edit("size = [4, 4]\n", ""), ("grid.size: missing",)),
    (
        "start on an obstacle",
        edit("start = [0, 0]", "start = [2, 2]"),
        ("grid.start: cell [2, 2] is an obstacle",),
    ),
    (
        "obstacle off the grid",
        edit("obstacles = [[2, 2]]", "obstacles = [[2, 2], [0, 9]]"),
        ("grid.obstacles[1]: cell [0, 9] is off the 4x4 grid",),
    ),
    (
        "obstacles not an array",
        edit("obstacles = [[2, 2]]", "obstacles = 3"),
        ("grid.obstacles: must be an array", "3"),
    ),
    (
        "duplicate obstacle",
        edit("obstacles = [[2, 2]]", "obstacles = [[2, 2], [2, 2]]"),
        ("grid.obstacles[1]: cell [2, 2] is listed twice",),
    ),
    (
        "region off the grid",
        edit("A = [[1, 2]]", "A = [[1, 2], [-1, 0]]"),
        ("regions.A[1]: cell [-1, 0] is off the 4x4 grid",),
    ),
    (
        "region on an obstacle",
        edit("A = [[1, 2]]", "A = [[2, 2]]"),
        ("regions.A[0]: cell [2, 2] is an obstacle",),
    ),
    ("region empty", edit("A = [[1, 2]]", "A = []"), ("regions.A: must list at least one cell",)),
    ("region a bare cell", edit("A = [[1, 2]]", "A = [1, 2]"), ("regions.A[0]", "got 1")),
    (
        "region name reserved",
        edit("B = [[3, 0]]", "B = [[3, 0]]\nF = [[0, 1]]"),
        ("regions.F", '"F"', "not a proposition name"),
    ),
    (
        "region name not an identifier",
        edit("B = [[3, 0]]", 'B = [[3, 0]]\n"a b" = [[0, 1]]'),
        ('regions."a b"', "not a proposition name"),
    ),
    (
        "regions not a table",
        GOOD.replace("[regions]\nA = [[1, 2]]\nB = [[3, 0]]\n", "").replace(
            "epsilon = 0.01", "epsilon = 0.01\nregions = 3"
        ),
        ("regions: must be a table", "3"),
    ),
    (
        "region named like an event",
        edit("B = [[3, 0]]", "B = [[3, 0]]\nb1 = [[0, 3]]"),
        ("regions.b1", "'b1'", "event"),
    ),
    (
        "undefined distribution name",
        edit("D[mu2] b2", "D[mu3] b2"),
        ("spec", "'mu3'", "not defined"),
    ),
    (
        "pmf over 1",
        edit("{ geometric = 0.8 }", "{ pmf = [0.5, 0.4, 0.3] }"),
        ("distributions.mu1.pmf",),
    ),
    (
        "geometric p of 0",
        edit("{ geometric = 0.3 }", "{ geometric = 0.0 }"),
        ("distributions.mu2.geometric",),
    ),
    (
        "geometric p bool",
        edit("{ geometric = 0.3 }", "{ geometric = true }"),
        ("distributions.mu2.geometric",),
    ),
    (
        "bad inline literal",
        edit("D[mu2] b2 &", "D[geometric(0)] b2 &").replace("mu2 = { geometric = 0.3 }\n", ""),
        ("spec", "D[geometric(0)] b2"),
    ),
    (
        "two distributions for one event",
        edit("D[mu2] b2 &", "D[mu2] b1 & D[mu1] b2 &"),
        ("spec", "b1", "exactly one"),
    ),
    (
        "missing spec",
        "\n".join(x for x in GOOD.split("\n") if not x.startswith("spec")),
        ("spec: missing",),
    ),
    ("empty name", edit('name = "bad"', 'name = ""'), ("name: must not be empty",)),
    ("name not a string", edit('name = "bad"', "name = 3"), ("name: must be a string", "3")),
    (
        "spec not a string",
        edit('spec = "(D', 'spec = ["(D').replace('B))"\n', 'B))"]\n'),
        ("spec: must be a string",),
    ),
    ("spec syntax error", edit("F(b1 & F[0,3] A)", "F(b1 & F[0,3] A"), ("spec: 1:",)),
    (
        "spec syntax error on line 2",
        edit(
            'spec = "(D[mu1] b1 & F(b1 & F[0,3] A)) | (D[mu2] b2 & F(b2 & F[0,3] B))"',
            'spec = """(D[mu1] b1 & F(b1 & F[0,3] A))\n  | (D[mu2] b2 & & F(b2 & F[0,3] B))"""',
        ),
        ("spec: 2:18:",),
    ),  # the second "&" of line 2
    (
        "recurrence spec",
        edit("F(b1 & F[0,3] A)", "F(b1 & F[0,3] A) & G F B"),
        ("spec", "G F B is a recurrence formula"),
    ),
    (
        "proposition neither region nor event",
        edit("F[0,3] B)", "F[0,3] C)"),
        ("spec: proposition 'C' is neither a region nor an event",),
    ),
    (
        "epsilon too large",
        edit("epsilon = 0.01", "epsilon = 1.5"),
        ("epsilon: must be a number in (0, 1), got 1.5",),
    ),
    ("epsilon zero", edit("epsilon = 0.01", "epsilon = 0"),
     ("epsilon: must be a number in (0, 1), got 0",)),
    (
        "epsilon a string",
        edit("epsilon = 0.01", 'epsilon = "small"'),
        ("epsilon: must be a number", '"small"'),
    ),
    (
        "no game table",
        GOOD.split("[grid]")[0]
        + GOOD.split("obstacles = [[2, 2]]\n")[1].replace("A = [[1, 2]]", "A = [[1, 2]]"),
        ("no game table", "[grid]"),
    ),
    (
        "grid not a table",
        edit("epsilon = 0.01", "epsilon = 0.01\ngrid = 3").split("[grid]")[0],
        ("grid: must be a table", "3"),
    ),
    ("misspelt game table", GOOD.replace("[grid]", "[gird]"), ("gird: unknown key",)),
    (
        "unused distribution",
        edit("mu2 = { geometric = 0.3 }", "mu2 = { geometric = 0.3 }\nmu3 = { poisson = 2.5 }"),
        ("distributions.mu3: defined but not used",),
    ),
]


@pytest.mark.parametrize("text, fragments", [(t, f) for _, t, f in BAD], ids=[c for c, _, _ in BAD])
def test_bad_model(text: str, fragments: tuple[str, ...]) -> None:
    with pytest.raises(ModelError) as info:
        loads_model(text, source="models/x.toml")
    message = str(info.value)
    assert message.startswith("models/x.toml:"), message
    for fragment in fragments:
        assert fragment in message, (fragment, message)


def test_bad_model_count() -> None:
    assert len(BAD) >= 20


def test_toml_syntax_error_gives_line_and_column(tmp_path: Path) -> None:
    path = tmp_path / "broken.toml"
    path.write_text(edit("slip = 0.1", "slip = 0.1.2"))
    with pytest.raises(ModelError) as info:
        load_model(path)
    message = str(info.value)
    assert message.startswith(f"{path}:8:"), message
    assert re.search(r"line 8, column \d+", message), message
    assert isinstance(info.value, ValueError)


def test_toml_error_at_end_of_file() -> None:
    with pytest.raises(ModelError, match=r"^<string>:2:1: TOML syntax error at line 2"):
        loads_model("a = [1,\n")


def test_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "nope.toml"
    with pytest.raises(ModelError, match=re.escape(f"{path}: cannot read")):
        load_model(path)


def test_errors_start_with_the_path(tmp_path: Path) -> None:
    path = tmp_path / "m.toml"
    path.write_text(edit("slip = 0.1", "slip = 0.7"))
    with pytest.raises(ModelError) as info:
        load_model(str(path))
    assert str(info.value) == f"{path}: grid.slip: must be in [0, 0.5], got 0.7"


def _never_built(doc: dict[str, Any], ctx: Any) -> GridWorld:
    raise AssertionError("the maze kind is never built in these tests")


@pytest.fixture
def with_maze_kind(monkeypatch: pytest.MonkeyPatch) -> None:
    """A game kind registered for the test (beside [grid] and [prism]), to check the
    dispatch."""
    maze = GameKind(table="maze", extra_tables=(), proposition_noun="room", build=_never_built)
    monkeypatch.setattr(model_module, "GAME_KINDS", (*model_module.GAME_KINDS, maze))


@pytest.mark.usefixtures("with_maze_kind")
def test_two_game_tables() -> None:
    with pytest.raises(ModelError, match=r"^<string>: exactly one game table .*\[grid\], \[maze\]"):
        loads_model(GOOD + "\n[maze]\nrooms = 3\n")


@pytest.mark.usefixtures("with_maze_kind")
def test_regions_without_their_game_kind() -> None:
    """A table owned by another game kind is an unknown key."""
    text = 'name = "n"\nspec = "F A"\n[maze]\nrooms = 3\n[regions]\nA = [[0, 0]]\n'
    with pytest.raises(ModelError, match=r"^<string>: regions: unknown key"):
        loads_model(text)
