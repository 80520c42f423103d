"""What several tests share: the issue's rare 12-state PRISM MDP, the expected-reward
properties of tests/data/rewards.prism, random PRISM MDPs with a reward structure, and
Storm's exact value (or verdict) of a property on a PRISM (or JANI) file
(``build_model[stormpy.Rational]``, an exact solver environment), the independent value
certified brackets are compared with."""

from __future__ import annotations

import random
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


PROPS = ['R{"cost"}min=? [F "goal"]', 'R{"cost"}max=? [F "goal"]',
         'R{"cost"}min=? [F "stop"]', 'R{"cost"}max=? [F "stop"]',
         'R{"time"}min=? [F "stop"]', 'R{"time"}max=? [F "stop"]',
         'R{"time"}min=? [F x>=2 & !lost]', 'R{"time"}max=? [F (x>=2 | lost)]',
         'R{"cost"}min=? [F lost]', 'R{"cost"}max=? [F !lost]']


def exact_fraction(value: object) -> Fraction:
    """Storm's exact ``value`` (a rational) as a Fraction.  A chain of a few thousand
    states has values whose numerator runs past Python's 4,300-digit guard on
    ``int(str)`` (a guard against untrusted input; this is Storm's own output): the guard
    is lifted for the conversion alone."""
    import sys

    kept = sys.get_int_max_str_digits()
    sys.set_int_max_str_digits(0)
    try:
        return Fraction(str(value))
    finally:
        sys.set_int_max_str_digits(kept)


def drn_reach(path: Path, label: str) -> Fraction:
    """Storm's exact ``P=? [F "label"]`` at the initial state of the chain (a DTMC) in
    the DRN file ``path``, built in rational arithmetic."""
    import stormpy

    chain = stormpy.build_model_from_drn[stormpy.Rational](str(path))
    prop = stormpy.parse_properties(f'P=? [F "{label}"]')[0]
    return exact_fraction(stormpy.model_checking(chain, prop).get_value(
        chain.initial_states[0]))


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


def storm_result(path: str, prop: str, constants: dict, **options: bool) -> tuple:
    """Storm's built model (rational) and its result (an exact solver environment) for
    ``prop`` on the PRISM or JANI file ``path``, its open ``constants`` given."""
    import stormpy

    if path.endswith(".jani"):
        program, _ = stormpy.parse_jani_model(path)
    else:
        program = stormpy.parse_prism_program(path)
    props = stormpy.parse_properties(prop, program)
    if constants:
        program, props = stormpy.instantiate_constants(program, constants, props)
    model = stormpy.build_model[stormpy.Rational](program, props)
    env = stormpy.Environment()
    env.solver().force_exact = True
    return model, stormpy.model_checking(model, props[0], environment=env, **options)


def storm_value(path: str, prop: str, constants: dict) -> Fraction | None:
    """Storm's exact value of ``prop`` at the initial state of the PRISM or JANI file
    ``path``, its open ``constants`` given (only the initial state asked: Storm's
    reward-bounded until needs that); None for Storm's infinity."""
    model, result = storm_result(path, prop, constants, only_initial_states=True)
    text = str(result.get_value(model.initial_states[0]))
    return None if text == "inf" else Fraction(text)


def storm_holds(path: str, prop: str, constants: dict) -> bool:
    """Storm's own verdict of the bound ``prop`` (``R<=b``, ``P>=p``) at the initial
    state of ``path``."""
    model, result = storm_result(path, prop, constants)
    return model.initial_states[0] in set(result.get_truth_values_vector())


def random_prism(rng: random.Random, n: int, integer: bool = False) -> str:
    """A random MDP over ``s`` in ``[0..n-1]``: each state one to three commands with
    random rational branches and random action rewards (rationals, or integers 0..2 when
    ``integer``), a state reward on some states; the label "goal" is ``s = n-1``."""
    lines = ["mdp", "module m", f"  s : [0..{n - 1}] init 0;"]
    actions = []
    for s in range(n - 1):
        for k in range(rng.choice([1, 2, 3])):
            succ = rng.sample(range(n), rng.choice([1, 2, 3]))
            weights = [rng.randint(1, 5) for _ in succ]
            total = sum(weights)
            branches = " + ".join(f"{w}/{total} : (s'={t})"
                                  for w, t in zip(weights, succ, strict=True))
            lines.append(f"  [a{s}_{k}] s={s} -> {branches};")
            actions.append(f"a{s}_{k}")
    lines.append(f"  [end] s={n - 1} -> true;")
    lines.append("endmodule")
    lines.append('rewards "r"')
    for s in range(n - 1):
        if rng.random() < 0.5:
            lines.append(f"  s={s} : {rng.randint(0, 1 if integer else 3)};")
    for a in actions:
        if rng.random() < 0.6:
            reward = rng.randint(0, 2) if integer else f"{rng.randint(0, 4)}/{rng.randint(1, 3)}"
            lines.append(f"  [{a}] true : {reward};")
    lines.append("endrewards")
    lines.append(f'label "goal" = s={n - 1};')
    return "\n".join(lines) + "\n"


def storm_sound(prism: Path, prop: str) -> float:
    """Storm's sound interval iteration (absolute precision 1e-9) of ``prop`` on the PRISM
    file ``prism``, at its initial state: the peer value a float bracket is checked against
    where the exact engine is not needed."""
    import stormpy
    import stormpy.environments as envs

    program = stormpy.parse_prism_program(str(prism))
    formula = stormpy.parse_properties(prop, program)[0]
    model = stormpy.build_model(program, [formula])
    env = stormpy.Environment()
    env.solver().force_soundness = True
    minmax = env.solver().min_max()
    minmax.method = envs.MinMaxMethod.INTERVAL_ITERATION
    minmax.precision = stormpy.Rational("1/1000000000")
    minmax.relative_termination_criterion = False
    result = stormpy.model_checking(model, formula, environment=env)
    return float(result.get_value(model.initial_states[0]))
