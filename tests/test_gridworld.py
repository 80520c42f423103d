"""GridWorld: successor distributions against cells worked by hand, and invariants over
random grids."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from mitld_lp.worlds.game import Game, check_game
from mitld_lp.worlds.grid import ACTIONS, GridError, GridWorld


def dist(g: GridWorld, cell: tuple[int, int], action: str) -> dict[tuple[int, int], float]:
    out = g.successors(cell, action, frozenset())
    assert len({c for c, _ in out}) == len(out), "next cells must be distinct"
    return dict(out)


def assert_dist(got: dict, want: dict) -> None:
    assert set(got) == set(want)
    for c, p in want.items():
        assert math.isclose(got[c], p, abs_tol=1e-12), (c, got[c], p)


def test_is_a_game_and_hashable() -> None:
    g = GridWorld(4, 4, (0, 0), 0.1, frozenset(), (("A", frozenset({(1, 2)})),))
    assert isinstance(g, Game)
    h = GridWorld.make(4, 4, slip=0.1, regions={"A": [[1, 2]]})
    assert g == h and hash(g) == hash(h)
    assert {g: 1}[h] == 1
    assert g.initial == (0, 0)
    assert g.actions((2, 2)) == ("N", "S", "E", "W")
    assert g.proposition_names == frozenset({"A"})


def test_interior_cell() -> None:
    g = GridWorld.make(4, 4, slip=0.1)
    # N from (1,1): intended (1,2) 0.8; perpendicular E (2,1) and W (0,1) 0.1 each.
    assert_dist(dist(g, (1, 1), "N"), {(1, 2): 0.8, (2, 1): 0.1, (0, 1): 0.1})
    assert_dist(dist(g, (1, 1), "E"), {(2, 1): 0.8, (1, 2): 0.1, (1, 0): 0.1})
    assert_dist(dist(g, (1, 1), "S"), {(1, 0): 0.8, (2, 1): 0.1, (0, 1): 0.1})
    assert_dist(dist(g, (1, 1), "W"), {(0, 1): 0.8, (1, 2): 0.1, (1, 0): 0.1})


def test_corner_cell() -> None:
    g = GridWorld.make(4, 4, slip=0.1)
    # At (0,0): S is off the grid (stay 0.8), slips W off the grid (stay 0.1), E to (1,0).
    assert_dist(dist(g, (0, 0), "S"), {(0, 0): 0.9, (1, 0): 0.1})
    # W: off the grid 0.8, slips N (0,1) 0.1, S off the grid 0.1.
    assert_dist(dist(g, (0, 0), "W"), {(0, 0): 0.9, (0, 1): 0.1})
    assert_dist(dist(g, (0, 0), "N"), {(0, 1): 0.8, (1, 0): 0.1, (0, 0): 0.1})
    # Top-right corner (3,3), E: all but the S slip stay.
    assert_dist(dist(g, (3, 3), "E"), {(3, 3): 0.9, (3, 2): 0.1})


def test_edge_cell() -> None:
    g = GridWorld.make(4, 4, slip=0.1)
    # (2,0) on the south edge, E: intended (3,0); slip N (2,1); slip S off the grid.
    assert_dist(dist(g, (2, 0), "E"), {(3, 0): 0.8, (2, 1): 0.1, (2, 0): 0.1})
    # S into the wall: stay 0.8, slips E (3,0) and W (1,0).
    assert_dist(dist(g, (2, 0), "S"), {(2, 0): 0.8, (3, 0): 0.1, (1, 0): 0.1})


def test_obstacle_neighbour() -> None:
    g = GridWorld.make(4, 4, slip=0.2, obstacles=[(2, 1), (1, 2)])
    # From (1,1): N enters obstacle (1,2) -> stay 0.6; E slip into obstacle (2,1) -> stay
    # 0.2; W slip to (0,1) 0.2.
    assert_dist(dist(g, (1, 1), "N"), {(1, 1): 0.8, (0, 1): 0.2})
    # E: intended obstacle (2,1) stays 0.6, N slip obstacle stays 0.2, S slip (1,0) 0.2.
    assert_dist(dist(g, (1, 1), "E"), {(1, 1): 0.8, (1, 0): 0.2})
    assert (2, 1) not in g.cells and len(g.cells) == 14
    with pytest.raises(ValueError, match="not a free cell"):
        g.successors((2, 1), "N", frozenset())


def test_slip_zero_is_deterministic() -> None:
    g = GridWorld.make(3, 2, slip=0.0)
    assert g.successors((0, 0), "E", frozenset()) == (((1, 0), 1.0),)
    assert g.successors((0, 0), "W", frozenset()) == (((0, 0), 1.0),)
    assert g.successors((2, 1), "N", frozenset()) == (((2, 1), 1.0),)


def test_slip_half_never_goes_straight() -> None:
    g = GridWorld.make(3, 3, slip=0.5)
    assert_dist(dist(g, (1, 1), "N"), {(2, 1): 0.5, (0, 1): 0.5})


def test_events_are_ignored() -> None:
    g = GridWorld.make(3, 3, slip=0.1)
    for ev in (frozenset(), frozenset({"b1"}), frozenset({"b1", "b2"})):
        assert g.successors((1, 1), "N", ev) == g.successors((1, 1), "N", frozenset())


def test_propositions_from_regions() -> None:
    g = GridWorld.make(3, 3, regions={"A": [(0, 0), (1, 1)], "B": [(1, 1)]})
    assert g.propositions((0, 0)) == frozenset({"A"})
    assert g.propositions((1, 1)) == frozenset({"A", "B"})
    assert g.propositions((2, 2)) == frozenset()
    assert g.region_map["A"] == frozenset({(0, 0), (1, 1)})
    assert g.regions == (("A", frozenset({(0, 0), (1, 1)})), ("B", frozenset({(1, 1)})))


@pytest.mark.parametrize(
    "kwargs, path, match",
    [
        ({"width": 0, "height": 3}, "width", "must be a positive integer, got 0"),
        ({"width": 3, "height": -1}, "height", "must be a positive integer"),
        ({"width": True, "height": 3}, "width", "must be a positive integer"),
        ({"width": 3, "height": 3, "slip": 0.6}, "slip", r"must be in \[0, 0.5\], got 0.6"),
        ({"width": 3, "height": 3, "slip": -0.1}, "slip", r"must be in \[0, 0.5\]"),
        ({"width": 3, "height": 3, "slip": True}, "slip", "must be a number"),
        ({"width": 3, "height": 3, "start": (3, 0)}, "start",
         r"cell \(3, 0\) is off the 3x3 grid \(x in 0..2, y in 0..2\)"),
        ({"width": 3, "height": 3, "start": (1, 1), "obstacles": frozenset({(1, 1)})},
         "start", r"cell \(1, 1\) is an obstacle"),
        ({"width": 3, "height": 3, "obstacles": frozenset({(0, 5)})}, "obstacles", "off"),
        ({"width": 3, "height": 3, "obstacles": [(0, 1), (0, 5)]}, "obstacles[1]", "off"),
        ({"width": 3, "height": 3, "obstacles": [(0, 1), (2, 2), (0, 1)]}, "obstacles[2]",
         r"cell \(0, 1\) is listed twice"),
        ({"width": 3, "height": 3, "regions": (("A", frozenset({(9, 9)})),)}, "regions.A",
         "off"),
        ({"width": 3, "height": 3, "regions": {"A": [(0, 0), (2, 2)]}, "obstacles": [(2, 2)]},
         "regions.A[1]", r"cell \(2, 2\) is an obstacle"),
        ({"width": 3, "height": 3, "regions": (("A", {(1, 1)}), ("A", {(1, 2)}))},
         "regions.A", "given twice"),
        # names a formula cannot write, and empty regions (issue 12)
        ({"width": 3, "height": 3, "regions": {"F": [(1, 1)]}}, "regions.F",
         r'region name "F" is not a proposition name .*not one of D, F, G, R, U, W, X'),
        ({"width": 3, "height": 3, "regions": {"a b": [(1, 1)]}}, 'regions."a b"',
         "not a proposition name"),
        ({"width": 3, "height": 3, "regions": {"true": [(1, 1)]}}, "regions.true",
         "not a proposition name"),
        ({"width": 3, "height": 3, "regions": {"2A": [(1, 1)]}}, "regions.2A",
         "not a proposition name"),
        ({"width": 3, "height": 3, "regions": {"A": []}}, "regions.A",
         "must list at least one cell"),
        ({"width": 3, "height": 3, "stay": 1}, "stay", "must be True or False"),
    ],
)
def test_invalid(kwargs: dict, path: str, match: str) -> None:
    with pytest.raises(GridError, match=match) as err:
        GridWorld(**kwargs)
    assert err.value.path == path
    assert str(err.value).startswith(f"{path}: ")


def test_make_names_the_index_of_a_bad_cell() -> None:
    with pytest.raises(GridError) as err:
        GridWorld.make(4, 4, regions={"A": [(1, 1), (1, 1)]})
    assert err.value.parts == ("regions", "A", 1) and "listed twice" in str(err.value)


def test_stay_is_an_extra_exact_action() -> None:
    plain = GridWorld.make(3, 3, slip=0.2)
    assert plain.actions((1, 1)) == ACTIONS
    with pytest.raises(ValueError, match="no move 'stay'"):
        plain.successors((1, 1), "stay", frozenset())
    g = GridWorld.make(3, 3, slip=0.2, stay=True)
    assert g.actions((1, 1)) == ("N", "S", "E", "W", "stay")
    assert g.successors((1, 1), "stay", frozenset()) == (((1, 1), 1.0),)
    assert g.successors((1, 1), "N", frozenset()) == plain.successors((1, 1), "N", frozenset())
    assert check_game(g).choices == 5 * 9
    assert g != plain


def test_a_huge_grid_is_not_tabulated() -> None:
    import tracemalloc

    tracemalloc.start()
    try:
        g = GridWorld.make(2000, 2000, start=(5, 5), obstacles=[(1, 1)], regions={"A": [(0, 0)]})
        assert g.n_states == 2000 * 2000 - 1
        assert g.successors((5, 5), "E", frozenset()) == (((6, 5), 1.0),)
        assert g.propositions((0, 0)) == frozenset({"A"}) and g.propositions((7, 7)) == set()
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 5e6  # a table of 4e6 cells x 4 moves would take gigabytes


@st.composite
def grids(draw: st.DrawFn) -> GridWorld:
    w = draw(st.integers(1, 7))
    h = draw(st.integers(1, 7))
    cells = [(x, y) for x in range(w) for y in range(h)]
    start = draw(st.sampled_from(cells))
    obstacles = draw(st.sets(st.sampled_from(cells), max_size=len(cells) - 1))
    obstacles.discard(start)
    slip = draw(st.one_of(st.just(0.0), st.just(0.5), st.floats(0.0, 0.5)))
    return GridWorld.make(w, h, start=start, slip=slip, obstacles=obstacles)


@given(grids())
def test_every_distribution_sums_to_one(g: GridWorld) -> None:
    for cell in g.cells:
        for action in ACTIONS:
            out = g.successors(cell, action, frozenset())
            assert out, (cell, action)
            assert math.isclose(sum(p for _, p in out), 1.0, abs_tol=1e-12)
            assert all(p > 0 for _, p in out)
            assert len({c for c, _ in out}) == len(out)
            for (x, y), _ in out:
                assert (x, y) in g.cells  # never off the grid, never on an obstacle
                assert abs(x - cell[0]) + abs(y - cell[1]) <= 1
    assert check_game(g).states <= len(g.cells)


@given(grids())
def test_matches_a_naive_rule(g: GridWorld) -> None:
    """Recompute each distribution by summing the three outcomes with no merging logic
    shared with the implementation."""
    step = {"N": (0, 1), "S": (0, -1), "E": (1, 0), "W": (-1, 0)}
    side = {"N": "EW", "S": "EW", "E": "NS", "W": "NS"}
    free = set(g.cells)
    for cell in g.cells:
        for a in ACTIONS:
            want: dict[tuple[int, int], float] = {}
            for d, p in [(a, 1 - 2 * g.slip), (side[a][0], g.slip), (side[a][1], g.slip)]:
                t = (cell[0] + step[d][0], cell[1] + step[d][1])
                t = t if t in free else cell
                want[t] = want.get(t, 0.0) + p
            want = {c: p for c, p in want.items() if p > 0}
            assert_dist(dict(g.successors(cell, a, frozenset())), want)


MODEL = """
name = "t"
spec = "F[0,3] A"
[grid]
size = [3, 3]
start = [0, 0]
{extra}
[regions]
A = [[2, 2]]
"""


def test_model_files_get_the_stay_action_and_the_grid_errors_with_key_paths() -> None:
    from mitld_lp.model import ModelError, loads_model

    world = loads_model(MODEL.format(extra="stay = true"), "m.toml").game
    assert world.actions((0, 0))[-1] == "stay"
    assert loads_model(MODEL.format(extra=""), "m.toml").game.actions((0, 0)) == ACTIONS
    with pytest.raises(ModelError, match=r"^m\.toml: grid\.stay: must be a boolean, got an "
                                         r"integer 1$"):
        loads_model(MODEL.format(extra="stay = 1"), "m.toml")
    with pytest.raises(ModelError, match=r"^m\.toml: grid\.obstacles\[1\]: cell \[2, 2\] is "
                                         r"listed twice$"):
        loads_model(MODEL.format(extra="obstacles = [[2, 2], [2, 2]]"), "m.toml")
