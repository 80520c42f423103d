"""What several tests share: the issue's rare 12-state PRISM MDP and Storm's exact value
of a property on a PRISM file (``build_model[stormpy.Rational]``, an exact solver
environment), the independent value certified brackets are compared with."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

# ten steps, each passed with 0.001 or 0.0011: Pmin(F hit) = 1e-30, Pmax = 0.0011**10
RARE = """mdp
module m
  k : [0..11] init 0;
  [a] k<10 -> 0.001 : (k'=k+1) + 0.999 : (k'=11);
  [b] k<10 -> 0.0011 : (k'=k+1) + 0.9989 : (k'=11);
  [end] k>=10 -> true;
endmodule
label "hit" = k=10;
"""


def storm_rational(prism: Path, prop: str) -> Fraction:
    """Storm's exact value of ``prop`` at the initial state of the PRISM file ``prism``."""
    import stormpy

    program = stormpy.parse_prism_program(str(prism))
    props = stormpy.parse_properties(prop, program)
    model = stormpy.build_model[stormpy.Rational](program, props)
    env = stormpy.Environment()
    env.solver().force_exact = True
    result = stormpy.model_checking(model, props[0], environment=env)
    return Fraction(str(result.get_value(model.initial_states[0])))
