"""``[constants]`` in model files: ``{name}`` in the spec stands for a value."""

from __future__ import annotations

from pathlib import Path

import pytest

from mitld_lp import ModelError, loads_model, synthesize

BUS = (Path(__file__).resolve().parent.parent / "models" / "bus_grid.toml").read_text()
TEMPLATE = BUS.replace("F[0,3]", "F[0,{T}]")


@pytest.mark.parametrize("deadline", [1, 2])
def test_a_constant_gives_the_same_model_as_the_literal(deadline):
    with_constant = loads_model(TEMPLATE + f"\n[constants]\nT = {deadline}\n")
    literal = loads_model(BUS.replace("F[0,3]", f"F[0,{deadline}]"))
    assert with_constant.spec == literal.spec
    assert with_constant.spec_text == literal.spec_text  # what the model prints
    a, b = synthesize(with_constant), synthesize(literal)
    assert (a.lower, a.upper) == (b.lower, b.upper)


def test_constants_of_every_kind_of_value():
    text = """
name = "c"
spec = "D[geometric({p})] b & F[0,{T}] {goal}"
[constants]
p = 0.5
T = 2
goal = "A"
[grid]
size = [3, 1]
start = [0, 0]
[regions]
A = [[2, 0]]
"""
    model = loads_model(text)
    assert model.spec_text == "D[geometric(0.5)] b & F[0,2] A"


@pytest.mark.parametrize(
    "extra, spec, expected",
    [
        ("", None, "x.toml: spec: 1:25: {T} names no constant under [constants] (defined: none)"),
        ("T = 2\nU = 1", None, "x.toml: constants.U: defined but not used by spec (it has no {U})"),
        ("T = [2]", None, "x.toml: constants.T: must be a number, a boolean or a string, got "
                          "list [2]"),
        ('"a b" = 1\nT = 2', None, 'x.toml: constants."a b": a constant\'s name must be letters, '
                                   "digits and _ (not starting with a digit)"),
        ("T = 2", "F[0,{T}}] A", "x.toml: spec: 1:8: a lone '}': write a constant as {name}"),
        ("T = 2", "F[0,{T}] A &\n{ A", "x.toml: spec: 2:1: a lone '{': write a constant as {name}"),
    ],
)
def test_constant_errors_name_the_key_path(extra, spec, expected):
    text = TEMPLATE if spec is None else TEMPLATE.replace(
        '"(D[mu1] b1 & F(b1 & F[0,{T}] A)) | (D[mu2] b2 & F(b2 & F[0,{T}] B))"',
        '"""' + spec + '"""').replace("[distributions]\nmu1 = { geometric = 0.8 }\n"
                                      "mu2 = { geometric = 0.3 }\n", "")
    if extra:
        text += "\n[constants]\n" + extra + "\n"
    with pytest.raises(ModelError) as info:
        loads_model(text, "x.toml")
    assert str(info.value) == expected
