"""``--method vi`` certifies a policy optimal in every state, also in the states the
initial state cannot reach in the quotient's graph (they hang behind a state the graph
decides).  Interval iteration used to stop at the initial state's gap there, so those
states kept the bracket [0, 1], the greedy policy picked any choice, and the check
"policy optimal in every state" failed: NOT certified, exit 3 (seen on QVBS wlan_dl).
The expected value is Storm's exact engine on the same PRISM text."""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import pytest

stormpy = pytest.importorskip("stormpy")

from mitld_lp.cli import main  # noqa: E402

# s=1 is Prob0E (it may stay for ever), so the quotient cuts it off and s=2..4 are
# unreachable from s=0 there, though undecided.  At s=2 both choices lead to undecided
# states (upper bound 1 before any iteration), so only iterating them tells c1 (worth
# 1/2) from c2 (worth 1/10, the minimum).  Pmin from s=0: 1/2 * 0 + 1/2 * 1 = 1/2.
BEHIND = """mdp
module m
  s : [0..6] init 0;
  [] s=0 -> 0.5 : (s'=1) + 0.5 : (s'=5);
  [stay] s=1 -> true;
  [go] s=1 -> (s'=2);
  [c1] s=2 -> (s'=3);
  [c2] s=2 -> (s'=4);
  [] s=3 -> 0.5 : (s'=5) + 0.5 : (s'=6);
  [] s=4 -> 0.1 : (s'=5) + 0.9 : (s'=6);
  [] s>=5 -> true;
endmodule
label "goal" = s=5;
"""
PROP = 'Pmin=? [F "goal"]'


def test_vi_is_certified_where_the_initial_state_cannot_reach(capsys, tmp_path: Path):
    path = tmp_path / "behind.prism"
    path.write_text(BEHIND)
    program = stormpy.parse_prism_program(str(path))
    props = stormpy.parse_properties(PROP, program)
    model = stormpy.build_model[stormpy.Rational](program, props)
    result = stormpy.model_checking(model, props[0], only_initial_states=True)
    exact = Fraction(str(result.get_value(model.initial_states[0])))
    assert exact == Fraction(1, 2)  # the hand calculation above

    code = main(["solve", str(path), "--prop", PROP, "--method", "vi", "--json", "-q"])
    [answer] = [json.loads(line) for line in capsys.readouterr().out.strip().splitlines()]
    assert answer["method"] == "vi"
    assert answer["certified"], answer["failed_checks"]
    assert code == 0
    assert Fraction(answer["lower"]) <= exact <= Fraction(answer["upper"])
