"""Where an exact answer's probabilities come from: numbers as written (a model file's
and a formula's decimals keep their text), the laws' hazards in rationals (by hand from
the law's definition), a grid's and a PRISM world's moves in rationals (the PRISM ones
against Storm's exact build read independently, through its DRN export)."""

from __future__ import annotations

import pickle
from fractions import Fraction
from pathlib import Path

import pytest

from mitld_lp.distributions import families
from mitld_lp.distributions.law import DistributionError
from mitld_lp.model import loads_model
from mitld_lp.util.decimals import Written, exact_value
from mitld_lp.worlds.exact import exact_successors_of
from mitld_lp.worlds.grid import GridWorld


def test_exact_value_reads_text_ints_fractions_and_python_floats():
    assert exact_value(Written("0.10000000000000001")) == Fraction(10000000000000001, 10**17)
    assert exact_value(Written("1_000.5")) == Fraction(2001, 2)
    assert exact_value(Written("1e-3")) == Fraction(1, 1000)
    assert exact_value(3) == 3 and exact_value(Fraction(1, 3)) == Fraction(1, 3)
    # a float made in Python: the shortest decimal that rounds to it, as stormpy does
    assert exact_value(0.1) == Fraction(1, 10) != Fraction(0.1)
    assert exact_value(1 / 3) == Fraction("0.3333333333333333")
    for bad in (True, float("nan"), float("inf"), "0.1"):
        with pytest.raises(ValueError):
            exact_value(bad)


def test_a_written_number_is_its_float_and_keeps_its_text():
    w = Written("0.10000000000000001")
    assert w == 0.1 and hash(w) == hash(0.1) and repr(w) == "0.1"
    again = pickle.loads(pickle.dumps(w))
    assert again.text == w.text and again == w
    assert type(w * 2) is float  # arithmetic is a float's


def test_a_model_file_keeps_the_text_of_its_decimals():
    model = loads_model("""name = "m"
spec = "D[mu] b & F(b & A) & D[geometric(0.30000000000000001)] c & F c"
[grid]
size = [2, 1]
start = [0, 0]
slip = 0.10000000000000001
[regions]
A = [[1, 0]]
[distributions]
mu = { pmf = [0.25, 0.75000000000000001] }
""")
    assert model.game.slip == 0.1
    moves = dict(model.game.exact_successors((0, 0), "E"))
    assert moves == {(1, 0): 1 - 2 * Fraction("0.10000000000000001"),
                     (0, 0): 2 * Fraction("0.10000000000000001")}
    # the inline law read by the formula parser, the named one from the TOML reader
    assert model.distributions["c"].exact_hazard(4) == Fraction("0.30000000000000001")
    total = Fraction("0.25") + Fraction("0.75000000000000001")  # rescaled to 1 exactly
    assert model.distributions["b"].exact_hazard(1) == Fraction("0.25") / total


def test_the_laws_exact_hazards_are_their_definitions():
    # pmf: h(k) = m_k / (never + m_k + m_{k+1} + ...), h = 0 after the table (never > 0)
    p = families.pmf([Written("0.1"), Written("0.3"), Written("0.5")])
    m, never = [Fraction(1, 10), Fraction(3, 10), Fraction(1, 2)], Fraction(1, 10)
    want = [m[k] / (never + sum(m[k:])) for k in range(3)] + [Fraction(0)] * 2
    assert [p.exact_hazard(k) for k in range(1, 6)] == want
    assert p.exact_constant_from() == 4
    # uniform(2, 4): 0 before 2, 1/(4 - k + 1) on 2..4, then 1
    u = families.uniform(2, 4)
    assert [u.exact_hazard(k) for k in range(1, 7)] == [0, Fraction(1, 3), Fraction(1, 2),
                                                        1, 1, 1]
    long = families.uniform(5, 2**21)  # the closed form, not a table
    assert long.exact_hazard(2**21 - 1) == Fraction(1, 2) and long.exact_constant_from() == 2**21
    g = families.geometric(0.3)
    assert g.exact_hazard(7) == Fraction(3, 10) and g.exact_constant_from() == 1
    assert pickle.loads(pickle.dumps(p)).exact_hazard(2) == want[1]


@pytest.mark.parametrize("law", [families.poisson(2.5), families.exponential(0.5),
                                 families.weibull(2.0, 4.0)])
def test_laws_with_irrational_hazards_have_none(law):
    assert not law.exact_hazards
    with pytest.raises(DistributionError, match="not rational"):
        law.exact_hazard(1)


def test_a_grid_s_exact_moves_are_its_float_moves_as_fractions():
    grid = GridWorld.make(3, 3, slip=0.2, obstacles=[(1, 2)], stay=True)
    for cell in grid.cells:
        for action in grid.actions(cell):
            exact = grid.exact_successors(cell, action)
            floats = grid.successors(cell, action)
            assert [s for s, _ in exact] == [s for s, _ in floats]
            assert sum(p for _, p in exact) == 1
            assert all(abs(float(p) - q) < 1e-15 for (_, p), (_, q) in zip(exact, floats,
                                                                           strict=True))
    assert dict(grid.exact_successors((0, 0), "N")) == {(0, 1): Fraction(3, 5),
                                                        (1, 0): Fraction(1, 5),
                                                        (0, 0): Fraction(1, 5)}


PRISM = """mdp
const double p;
module m
  s : [0..3] init 0;
  [go] s<3 -> p : (s'=s+1) + 1-p : (s'=0);
  [jump] s<2 -> 1/3 : (s'=s+2) + 2/3 : (s'=s);
  [go] s=3 -> true;
endmodule
label "top" = s=3;
"""


def _drn_rationals(stormpy, path: Path, constants: dict) -> dict[tuple[int, int], Fraction]:
    """(choice, successor) -> probability, read from Storm's exact build's DRN text."""
    program = stormpy.parse_prism_program(str(path))
    program, _ = stormpy.instantiate_constants(program, constants)
    model = stormpy.build_model[stormpy.Rational](program)
    drn = path.with_suffix(".drn")
    stormpy.io.export_to_drn(model, str(drn))
    out, choice = {}, -1
    for line in drn.read_text().splitlines():
        words = line.split()
        if words[:1] == ["action"]:
            choice += 1
        elif len(words) == 3 and words[1] == ":":
            out[choice, int(words[0])] = Fraction(words[2])
    return out


def test_a_prism_world_s_exact_moves_are_storm_s_exact_build(tmp_path):
    pytest.importorskip("stormpy")
    import stormpy
    import stormpy.io  # noqa: F401 - the DRN export

    from mitld_lp.worlds.prism import load_prism

    path = tmp_path / "w.prism"
    path.write_text(PRISM)
    game = load_prism(path, constants={"p": Written("0.30000000000000001")})
    moves = exact_successors_of(game)
    assert moves is not None
    reference = _drn_rationals(stormpy, path, {"p": stormpy.Rational(
        "30000000000000001/100000000000000000")})
    index = {s: i for i, s in enumerate(game.states)}
    choice = 0
    for state in game.states:
        for action in game.actions(state):
            got = {index[t]: p for t, p in moves(state, action, frozenset())}
            want = {t: p for (c, t), p in reference.items() if c == choice}
            assert got == want
            choice += 1
    assert choice == len({c for c, _ in reference})
    assert dict(moves((0,), "go", frozenset()))[(1,)] == Fraction("0.30000000000000001")
