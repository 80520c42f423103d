"""The exact answer (``synthesize(..., exact=True)``, ``solve --exact``): the optimum as
a fraction, compared with Storm's exact engine (``build_model[stormpy.Rational]`` and an
exact environment) on PRISM models, with fractions computed by hand on grids, and the
exact policy iteration with a brute force over every policy in rationals."""

from __future__ import annotations

import itertools
import json
import random
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from conftest import build_mdp
from storm_exact import RARE, storm_rational

from mitld_lp import defaults
from mitld_lp.cli import main
from mitld_lp.exact.errors import ExactError, ExactTooLarge
from mitld_lp.model import load_model
from mitld_lp.problem import ProblemError
from mitld_lp.synthesis import synthesize
from mitld_lp.testing.exact import chain_values

flint = pytest.importorskip("flint")

# end components (s=1 may stay forever: Pmin(F goal) = 0 there; s=0 may loop), cycles
# through 0, 1, 2 and decimal probabilities
LOOPS = """mdp
module m
  s : [0..4] init 0;
  [a] s=0 -> 0.3 : (s'=1) + 0.7 : (s'=2);
  [b] s=0 -> 0.45 : (s'=0) + 0.55 : (s'=4);
  [a] s=1 -> 0.6 : (s'=0) + 0.25 : (s'=3) + 0.15 : (s'=4);
  [b] s=1 -> true;
  [a] s=2 -> 0.9 : (s'=2) + 0.1 : (s'=1);
  [b] s=2 -> 0.5 : (s'=0) + 0.375 : (s'=3) + 0.125 : (s'=4);
  [a] s>=3 -> true;
endmodule
label "goal" = s=3;
"""

# cycles through 0, 1, 2 with exits everywhere: no end component, so Pmin > 0
CYCLES = """mdp
module m
  s : [0..4] init 0;
  [a] s=0 -> 0.3 : (s'=1) + 0.7 : (s'=2);
  [b] s=0 -> 0.45 : (s'=0) + 0.2 : (s'=3) + 0.35 : (s'=4);
  [a] s=1 -> 0.6 : (s'=0) + 0.25 : (s'=3) + 0.15 : (s'=4);
  [b] s=1 -> 0.5 : (s'=1) + 0.5 : (s'=3);
  [a] s=2 -> 0.9 : (s'=2) + 0.1 : (s'=1);
  [b] s=2 -> 0.5 : (s'=0) + 0.375 : (s'=3) + 0.125 : (s'=4);
  [a] s>=3 -> true;
endmodule
label "goal" = s=3;
"""

WALK = """mdp
module walk
  x : [0..12] init 7;
  [l] x>0 & x<12 -> 0.7:(x'=x-1) + 0.2:(x'=x) + 0.1:(x'=x+1);
  [r] x>0 & x<12 -> 0.7:(x'=x+1) + 0.2:(x'=x) + 0.1:(x'=x-1);
  [stop] x=0 | x=12 -> true;
endmodule
label "home" = x=0;
label "lost" = x=12;
"""


def _prism_model(tmp_path: Path, program: str, spec: str, objective: str = "max") -> Path:
    (tmp_path / "w.prism").write_text(program)
    path = tmp_path / "m.toml"
    path.write_text(f'name = "m"\nspec = "{spec}"\nobjective = "{objective}"\n'
                    '[prism]\nfile = "w.prism"\n')
    return path


def _storm_exact(tmp_path: Path, prop: str) -> Fraction:
    pytest.importorskip("stormpy")
    return storm_rational(tmp_path / "w.prism", prop)


@pytest.mark.parametrize(("spec", "objective", "prop", "closed"), [
    ("F hit", "max", 'Pmax=? [F "hit"]', Fraction("0.0011") ** 10),
    ("F hit", "min", 'Pmin=? [F "hit"]', Fraction("0.001") ** 10),
    ("G !hit", "min", 'Pmin=? [G !"hit"]', 1 - Fraction("0.0011") ** 10),
    ("G !hit", "max", 'Pmax=? [G !"hit"]', 1 - Fraction("0.001") ** 10),
    ("F[0,5] hit", "max", 'Pmax=? [F<=5 "hit"]', Fraction(0)),
])
def test_rare_events_are_storm_s_exact_fraction(tmp_path, spec, objective, prop, closed):
    path = _prism_model(tmp_path, RARE, spec, objective)
    result = synthesize(load_model(path), exact=True)
    assert result.exact.value == _storm_exact(tmp_path, prop) == closed
    assert result.certified
    assert Fraction(result.lower) <= closed <= Fraction(result.upper)


@pytest.mark.parametrize("program", [LOOPS, CYCLES], ids=["end-components", "cycles"])
@pytest.mark.parametrize(("spec", "objective", "prop"), [
    ("F goal", "max", 'Pmax=? [F "goal"]'),
    ("F goal", "min", 'Pmin=? [F "goal"]'),
    ("F[0,4] goal", "max", 'Pmax=? [F<=4 "goal"]'),
    ("F[0,4] goal", "min", 'Pmin=? [F<=4 "goal"]'),
    ("G !goal", "min", 'Pmin=? [G !"goal"]'),
])
def test_end_components_and_cycles_match_storm(tmp_path, program, spec, objective, prop):
    path = _prism_model(tmp_path, program, spec, objective)
    expected = _storm_exact(tmp_path, prop)
    assert synthesize(load_model(path), exact=True).exact.value == expected
    if prop == 'Pmin=? [F "goal"]':  # an end component (stay at s=1) makes it 0
        assert (expected == 0) == (program is LOOPS)


@pytest.mark.parametrize("objective", ["max", "min"])
def test_bounded_until_matches_storm(tmp_path, objective):
    path = _prism_model(tmp_path, WALK, "!lost U[0,15] home", objective)
    expected = _storm_exact(tmp_path, f'P{objective}=? [!"lost" U<=15 "home"]')
    result = synthesize(load_model(path), exact=True)
    assert result.exact.value == expected
    assert Fraction(result.lower) <= expected <= Fraction(result.upper)


GRID = """name = "g"
spec = "D[mu] b & F(b & A)"
[grid]
size = [2, 1]
start = [0, 0]
slip = {slip}
stay = true
[regions]
A = [[1, 0]]
[distributions]
mu = {{ pmf = [0.25, 0.5, 0.25] }}
"""


def test_a_grid_with_a_pmf_law_is_the_fraction_by_hand(tmp_path):
    # E from (0, 0) reaches A = (1, 0) w.p. 1 - 2 slip = 4/5 (the slips leave the grid:
    # stay); once there the robot stays.  b happens at step k w.p. m_k and the task
    # holds when the robot is at A then: sum_k m_k (1 - (1/5)^k).
    path = tmp_path / "g.toml"
    path.write_text(GRID.format(slip="0.1"))
    expected = sum(Fraction(m) * (1 - Fraction(1, 5) ** k)
                   for k, m in enumerate(["0.25", "0.5", "0.25"], start=1))
    assert expected == Fraction(116, 125)
    result = synthesize(load_model(path), exact=True)
    assert result.exact.value == expected
    assert (result.exact.lower, result.exact.upper) == (expected, expected)


def test_a_decimal_keeps_every_digit_as_written(tmp_path):
    # 17 significant digits: the float is 0.1, the number written is not
    path = tmp_path / "g.toml"
    path.write_text(GRID.format(slip="0.10000000000000001"))
    p = 1 - 2 * Fraction("0.10000000000000001")
    expected = sum(Fraction(m) * (1 - (1 - p) ** k)
                   for k, m in enumerate(["0.25", "0.5", "0.25"], start=1))
    assert synthesize(load_model(path), exact=True).exact.value == expected != Fraction(116, 125)


def test_a_truncated_law_gives_both_models_fractions(tmp_path):
    # truncated at step 2: a run still waiting for b after step 2 (mass 1/4) loses in
    # the lower model and wins in the upper one
    path = tmp_path / "g.toml"
    path.write_text(GRID.format(slip="0.1"))
    result = synthesize(load_model(path), exact=True, truncation={"b": 2})
    low = Fraction("0.25") * Fraction(4, 5) + Fraction("0.5") * Fraction(24, 25)
    assert (result.exact.lower, result.exact.upper) == (low, low + Fraction(1, 4))
    assert result.exact.value is None
    assert Fraction(result.lower) <= low and Fraction(result.upper) >= low + Fraction(1, 4)


def test_geometric_laws_in_the_formula_keep_their_decimals(tmp_path):
    # b ~ geometric(0.3), memoryless: P(b within steps 1..2) = 1 - 0.7^2, whatever the robot
    path = tmp_path / "g.toml"
    path.write_text(GRID.format(slip="0.1").replace('spec = "D[mu] b & F(b & A)"',
                                                   'spec = "D[geometric(0.3)] b & F[0,2] b"')
                    .replace("[distributions]\nmu = { pmf = [0.25, 0.5, 0.25] }\n", ""))
    assert synthesize(load_model(path), exact=True).exact.value == 1 - Fraction("0.7") ** 2


# ----------------------------------------------------------------------------- policy iteration


def _brute_force(choices, target, sense):
    """The optimum at state 0 over every deterministic policy, each evaluated by
    Gauss-Jordan elimination in Fractions (the states that cannot reach the target 0)."""
    n = len(choices)
    acting = [s for s in range(n) if s not in target and choices[s]]
    best = None
    for pick in itertools.product(*(range(len(choices[s])) for s in acting)):
        rows = {s: choices[s][c] for s, c in zip(acting, pick, strict=True)}
        reach = set(target)
        while True:
            more = {s for s, row in rows.items() if s not in reach and set(row) & reach}
            if not more:
                break
            reach |= more
        unknown = [s for s in rows if s in reach]
        solved = chain_values(rows, unknown, target)
        value = Fraction(1) if 0 in target else solved.get(0, Fraction(0))
        if best is None or (value > best if sense == "max" else value < best):
            best = value
    return best


def _random_mdp(rng):
    n = rng.randint(3, 6)
    target = {n - 1}
    choices = []
    for s in range(n):
        if s in target or (s == n - 2 and rng.random() < 0.5):  # absorbing target / sink
            choices.append([])
            continue
        row_set = []
        for _ in range(rng.randint(1, 3)):
            succ = rng.sample(range(n), rng.randint(1, min(3, n)))
            weights = [rng.randint(1, 9) for _ in succ]
            row_set.append({t: Fraction(w, sum(weights)) for t, w in zip(succ, weights,
                                                                         strict=True)})
        choices.append(row_set)
    return choices, target


@pytest.mark.parametrize("sense", ["max", "min"])
def test_policy_iteration_from_any_policy_reaches_the_brute_force_optimum(sense):
    from mitld_lp.exact.rows import rational
    from mitld_lp.exact.solve import solve_exact

    rng = random.Random(40)
    for _ in range(60):
        choices, target = _random_mdp(rng)
        n = len(choices)
        sink = [s for s in range(n) if not choices[s] and s not in target]
        mdp = build_mdp([[(f"c{i}", {t: float(p) for t, p in row.items()})
                          for i, row in enumerate(rows)] for rows in choices],
                        target=sorted(target), sink=sink)
        exact = {}
        for s in range(n):
            for i, row in enumerate(choices[s] or [{s: Fraction(1)}]):
                for t, p in row.items():
                    exact[int(mdp.row_groups[s]) + i, t] = p
        m = mdp.matrix
        owner = np.repeat(np.arange(mdp.n_choices), np.diff(m.indptr))
        values = [rational(exact[int(c), int(t)]) for c, t in zip(owner, m.indices,
                                                                   strict=True)]
        start = np.array([int(mdp.row_groups[s]) + rng.randrange(max(len(choices[s]), 1))
                          for s in range(n)])
        mask = np.zeros(n, dtype=bool)
        mask[list(target)] = True
        got = solve_exact(mdp, values, mask, sense, start, max_block=50).values[0]
        assert Fraction(int(got.p), int(got.q)) == _brute_force(choices, target, sense)


# ----------------------------------------------------------------------------- refusals, budget


def test_laws_without_rational_hazards_and_float_worlds_are_refused_by_name(tmp_path):
    path = tmp_path / "g.toml"
    path.write_text(GRID.format(slip="0.1").replace("{ pmf = [0.25, 0.5, 0.25] }",
                                                   "{ poisson = 2.5 }"))
    with pytest.raises(ProblemError, match=r"b ~ poisson\(2.5\).*not rational"):
        synthesize(load_model(path), exact=True)
    from mitld_lp.model import Model
    from mitld_lp.worlds.game import ExplicitGame

    game = ExplicitGame(0, {0: {"go": {0: 0.5, 1: 0.5}}, 1: {"stay": {1: 1.0}}},
                        labels={1: {"A"}})
    with pytest.raises(ProblemError, match="ExplicitGame world"):
        synthesize(Model.from_game(game, "F A"), exact=True)
    with pytest.raises(ProblemError, match="constrained route"):
        path.write_text(GRID.format(slip="0.1"))
        synthesize(load_model(path), exact=True, constraints=["P(F A) >= 0.1"])


def test_a_clock_reduction_found_only_in_floats_is_refused(tmp_path):
    # hazards 1, 1 at steps 2, 3 in floats; exactly 0.4 / (0.4 + 1e-20) < 1 at step 2
    path = tmp_path / "g.toml"
    path.write_text(GRID.format(slip="0.1").replace("[0.25, 0.5, 0.25]", "[0.6, 0.4, 1e-20]"))
    with pytest.raises(ProblemError, match="constant from step 2 in floating point but "
                                           "are so only from step 3"):
        synthesize(load_model(path), exact=True)
    # without it the float product drops the outcome "b not yet at step 2" (1 - h(2) is
    # 0.0 in floats, 1e-20 / (0.4 + 1e-20) exactly): refused, not answered for another model
    with pytest.raises(ExactError, match="truncated is reached with positive exact "
                                         "probability but is not in the product"):
        synthesize(load_model(path), exact=True, clock_reduction=False)


def test_the_budget_is_checked_before_the_exact_work(tmp_path, monkeypatch):
    import mitld_lp.exact.stage as stage

    called = []
    monkeypatch.setattr(stage, "exact_rows", lambda *a: called.append(a))
    path = _prism_model(tmp_path, WALK, "!lost U[0,15] home")
    monkeypatch.setattr(defaults, "EXACT_MAX_TRANSITIONS", 100)
    with pytest.raises(ExactTooLarge, match="764 transitions, more than the 100"):
        synthesize(load_model(path), exact=True)
    monkeypatch.setattr(defaults, "EXACT_MAX_TRANSITIONS", 10**6)
    monkeypatch.setattr(defaults, "EXACT_MAX_BLOCK", 1)
    path = _prism_model(tmp_path, LOOPS, "F goal")
    with pytest.raises(ExactTooLarge, match=r"cyclic block of \d+ states, more than the 1 "):
        synthesize(load_model(path), exact=True)
    assert not called


# ----------------------------------------------------------------------------- command line


def test_the_command_line_prints_the_fraction_and_json_gives_p_over_q(tmp_path, capsys):
    path = _prism_model(tmp_path, RARE, "F hit")
    assert main(["solve", str(path), "--exact", "--json", "-q"]) == 0
    out = json.loads(capsys.readouterr().out)
    expected = Fraction("0.0011") ** 10
    assert out["exact"] == f"{expected.numerator}/{expected.denominator}"
    assert out["exact_bracket"] == [out["exact"], out["exact"]]
    assert main(["solve", str(path), "--exact", "-q"]) == 0
    assert f"exact:        {expected.numerator}/{expected.denominator}" in capsys.readouterr().out
    assert main(["solve", str(path), "--json", "-q"]) == 0
    assert json.loads(capsys.readouterr().out)["exact"] is None


def test_the_command_line_says_the_truncation_leaves_two_fractions(tmp_path, capsys):
    path = tmp_path / "g.toml"
    path.write_text(GRID.format(slip="0.1"))
    # every law truncated, at the first step whose tail is at most 0.3: step 2, tail 1/4
    cut = ["--no-clock-reduction", "--epsilon", "0.3"]
    assert main(["solve", str(path), "--exact", *cut, "--json", "-q"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["exact"] is None
    assert out["exact_bracket"] == ["17/25", "93/100"]  # as in the test above
    assert main(["solve", str(path), "--exact", *cut, "-q"]) == 0
    assert "the optima of the two truncation models" in capsys.readouterr().out


def test_a_batch_line_shows_the_fraction(tmp_path, capsys):
    path = _prism_model(tmp_path, RARE, "F hit", "min")
    other = tmp_path / "m2.toml"
    other.write_text(path.read_text().replace('"min"', '"max"'))
    assert main(["solve", str(path), str(other), "--exact", "-q"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].endswith(" exact 1/1000000000000000000000000000000")
    assert lines[1].endswith(f" exact {Fraction('0.0011') ** 10}")


def test_past_the_time_limit_there_is_no_exact_answer_and_no_certificate(tmp_path):
    path = _prism_model(tmp_path, RARE, "F hit")
    result = synthesize(load_model(path), exact=True, time_limit=1e-9)
    assert result.exact is None and str(result.status) == "time_limit"
    assert not result.certified and "exact optimum" in result.failed_checks[-1].name
