"""A minimum solved as one, certified end to end (issue 40): through ``synthesize`` and
the command line, truncated and not, in floating point and with ``--exact``.

Every expected value is exact and independent of the code under test: a closed form in
``fractions.Fraction`` written here from the model's decimals, or Storm's exact engine
(``stormpy.build_model[stormpy.Rational]``) on the same PRISM program.  Every bracket is
compared as ``Fraction(lower) <= exact <= Fraction(upper)``, with no tolerance.
"""

from __future__ import annotations

import json
import math
from fractions import Fraction
from pathlib import Path

import pytest
from storm_exact import RARE, storm_rational

from mitld_lp import load_model, synthesize
from mitld_lp.cli import main

stormpy = pytest.importorskip("stormpy")
pytest.importorskip("flint")  # the exact answers

# The robot waits in x=0 for the task's event e and wants A (x=1) not to hold when e
# comes: a reaches A with 0.3 a step, b with 0.1; A is kept for ever.  The event's law
# has no constant hazard before its support ends (step 4).
FORK = """mdp
module w
  x : [0..1] init 0;
  [a] x=0 -> 0.3 : (x'=1) + 0.7 : (x'=0);
  [b] x=0 -> 0.1 : (x'=1) + 0.9 : (x'=0);
  [stay] x=1 -> true;
endmodule
label "A" = x=1;
"""
LAW = (Fraction(5, 10), Fraction(3, 10), Fraction(1, 10), Fraction(1, 10))

# Six stages, each passed by a slow fault (1e-7 a try, retried with 0.99 at the even
# stages, 0.5 at the odd ones) or a fast one (3e-6): the best stage by stage is slow
# at the even stages (1e-7 / 0.01 = 1e-5), fast at the odd ones (3e-6 > 2e-7).
CASCADE = """mdp
module cascade
  s : [0..7] init 0;
  [slow] s<6 & mod(s,2)=0 -> 0.0000001 : (s'=s+1) + 0.99 : (s'=s) + 0.0099999 : (s'=7);
  [slow] s<6 & mod(s,2)=1 -> 0.0000001 : (s'=s+1) + 0.5 : (s'=s) + 0.4999999 : (s'=7);
  [fast] s<6 -> 0.000003 : (s'=s+1) + 0.999997 : (s'=7);
  [done] s>=6 -> true;
endmodule
label "hit" = s=6;
"""

def model_file(tmp_path: Path, prism: str, spec: str, objective: str) -> Path:
    (tmp_path / "m.prism").write_text(prism)
    path = tmp_path / f"m_{objective}.toml"
    path.write_text(f'name = "m"\nspec = "{spec}"\nobjective = "{objective}"\n\n'
                    '[prism]\nfile = "m.prism"\n')
    return path


def storm_exact(tmp_path: Path, prism: str, prop: str) -> Fraction:
    path = tmp_path / "storm.prism"
    path.write_text(prism)
    return storm_rational(path, prop)


def inside(lower: float, exact: Fraction, upper: float) -> bool:
    return Fraction(lower) <= exact <= Fraction(upper)


def fork_minimum(steps: int | None) -> Fraction:
    """``Pmin(e comes while A holds)``: always b (every step's chance of A is least, and
    A is for ever); the event comes at step k with ``LAW[k-1]``, A holds by then with
    ``1 - 0.9^k``.  ``steps``: the event followed up to that step only (the truncation
    point), the rest of its mass left out."""
    upto = len(LAW) if steps is None else steps
    return sum(m * (1 - Fraction(9, 10) ** k) for k, m in enumerate(LAW[:upto], 1))


def played(r, state: int) -> str:
    return r.mdp.action_name(int(r.lower_model.policy[state]))


# ------------------------------------------------------------------ truncated minimum


def test_a_truncated_minimum_brackets_both_models_and_the_true_value(tmp_path) -> None:
    # The event followed for two steps: the runs where it comes later (mass 1/5) count
    # against the task in the lower model and for it in the upper one, the controller's
    path = model_file(tmp_path, FORK, "D[pmf(0.5, 0.3, 0.1, 0.1)] e & F(e & A)", "min")
    low_model, true = fork_minimum(2), fork_minimum(None)
    high_model = low_model + LAW[2] + LAW[3]
    assert (low_model, high_model, true) == (Fraction(107, 1000), Fraction(307, 1000),
                                             Fraction(16849, 100000))
    r = synthesize(load_model(path), truncation={"e": 2})
    assert r.certified, r.failed_checks
    assert r.sense == "min" and not r.complemented and r.sta.truncation_points == {"e": 2}
    # the controller's model is the upper one (what the policy guarantees at most)
    assert r.lower_model.which == "upper" and r.upper_model.which == "lower"
    assert played(r, r.mdp.initial) == "b"
    assert inside(r.lower, low_model, r.upper) and inside(r.lower, true, r.upper)
    assert inside(r.lower, high_model, r.upper)
    # each end is its model's optimum to the precision, the truncation's part apart
    assert Fraction(r.lower) >= low_model * (1 - Fraction(1, 10**6))
    assert Fraction(r.upper) <= high_model * (1 + Fraction(1, 10**6))
    assert r.width["truncation"] == pytest.approx(0.2, abs=1e-9)
    assert r.width["solver"] <= 1e-6 * r.lower


def test_an_exact_truncated_minimum_is_the_two_models_fractions(tmp_path) -> None:
    path = model_file(tmp_path, FORK, "D[pmf(0.5, 0.3, 0.1, 0.1)] e & F(e & A)", "min")
    r = synthesize(load_model(path), truncation={"e": 2}, exact=True)
    assert r.certified, r.failed_checks
    assert (r.exact.lower, r.exact.upper) == (fork_minimum(2), fork_minimum(2) + Fraction(2, 10))
    # the two fractions rounded outward to their nearest floats
    assert Fraction(r.lower) <= r.exact.lower < Fraction(math.nextafter(r.lower, 1))
    assert Fraction(math.nextafter(r.upper, 0)) < r.exact.upper <= Fraction(r.upper)
    # the exact check proves the bracket in the float certificate's place
    names = [c.name for c in r.checks]
    assert "upper model: exact optimum" in names
    assert not any("bound:" in n for n in names)
    assert played(r, r.mdp.initial) == "b"


def test_an_exact_minimum_on_the_command_line(tmp_path, capsys) -> None:
    # untruncated (the law's support ends at step 4): one fraction, printed and in JSON
    path = model_file(tmp_path, FORK, "D[pmf(0.5, 0.3, 0.1, 0.1)] e & F(e & A)", "min")
    assert main(["solve", str(path), "--exact", "--json"]) == 0
    said = json.loads(capsys.readouterr().out)
    assert said["exact"] == "16849/100000" == str(fork_minimum(None))
    assert said["certified"] and inside(said["lower"], fork_minimum(None), said["upper"])
    assert main(["solve", str(path), "--exact"]) == 0
    assert "exact:        16849/100000" in capsys.readouterr().out


# ------------------------------------------------------------------ rare events


@pytest.mark.parametrize("objective", ["max", "min"])
def test_a_fault_cascade_is_bracketed_to_its_exact_optimum(tmp_path, objective) -> None:
    slow = (Fraction(1, 10**7) / (1 - Fraction(99, 100)), Fraction(1, 10**7) / Fraction(1, 2))
    fast = Fraction(3, 10**6)
    best = max if objective == "max" else min
    exact = math.prod(best(slow[s % 2], fast) for s in range(6))
    assert storm_exact(tmp_path, CASCADE, f'P{objective}=? [F "hit"]') == exact
    assert exact < Fraction(1, 10**30)
    path = model_file(tmp_path, CASCADE, "F hit", objective)
    for method in ("lp", "vi"):
        r = synthesize(load_model(path), method=method)
        assert r.certified, (method, r.failed_checks)
        assert inside(r.lower, exact, r.upper)
        # the policy's end within 1e-6 of the optimum (was 1e-35 for 2.7e-32: a policy a
        # thousand times worse), and the whole bracket too
        assert Fraction(r.upper) - Fraction(r.lower) <= Fraction(1, 10**6) * exact
        stages = {r.mdp.states[i].game[0]: played(r, i) for i in range(r.mdp.n_states)
                  if r.lower_model.policy[i] >= 0 and r.mdp.states[i].game[0] < 6}
        want = {s: ("slow" if (slow[s % 2] > fast) == (objective == "max") else "fast")
                for s in range(6)}
        assert stages == want


def test_an_exact_rare_maximum_plays_the_exact_optimal_policy(tmp_path) -> None:
    exact = storm_exact(tmp_path, CASCADE, 'Pmax=? [F "hit"]')
    r = synthesize(load_model(model_file(tmp_path, CASCADE, "F hit", "max")), exact=True)
    assert r.exact.value == exact and r.certified
    assert Fraction(r.lower) <= exact <= Fraction(r.upper)
    assert math.nextafter(r.lower, 1) >= r.upper  # the fraction's two neighbours
    assert [played(r, i) for i in range(r.mdp.n_states) if r.lower_model.policy[i] >= 0
            and r.mdp.states[i].game[0] < 6] == ["slow", "fast"] * 3


@pytest.mark.parametrize(("spec", "objective", "prop"), [
    ("F hit", "min", 'Pmin=? [F "hit"]'),
    ("F hit", "max", 'Pmax=? [F "hit"]'),
    ("G !hit", "min", 'Pmin=? [G !"hit"]'),
])
def test_the_issues_rare_model_at_default_settings(tmp_path, capsys, spec, objective,
                                                   prop) -> None:
    # through the command line, as a user runs it: certified, the exact value inside,
    # at most 1e-6 of it wide; G !hit keeps its complement's digits
    exact = storm_exact(tmp_path, RARE, prop)
    path = model_file(tmp_path, RARE, spec, objective)
    assert main(["solve", str(path), "--json"]) == 0
    said = json.loads(capsys.readouterr().out)
    assert said["certified"] and inside(said["lower"], exact, said["upper"])
    if spec == "G !hit":
        a, b = said["complement"]
        assert inside(a, 1 - exact, b) and Fraction(b) - Fraction(a) <= (1 - exact) / 10**6
        assert 0 < said["lower"] < 1
    else:
        assert said["complement"] is None and said["lower"] > 0
        width = Fraction(said["upper"]) - Fraction(said["lower"])
        assert width <= exact / 10**6
    assert main(["solve", str(path), "--exact", "--json"]) == 0
    said = json.loads(capsys.readouterr().out)
    assert Fraction(said["exact"]) == exact and inside(said["lower"], exact, said["upper"])
