"""The parser: round trip with str(), precedence, keywords vs identifiers, synonyms,
distribution literals, and errors (line, column, only ParseError) on malformed input."""

from __future__ import annotations

import pickle

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mitld_lp.logic.fragment import nnf
from mitld_lp.logic.parser import MAX_DEPTH, ParseError, parse, parse_distribution
from mitld_lp.logic.syntax import (
    FALSE,
    TRUE,
    DistLiteral,
    DistRef,
    DistSpec,
    Formula,
    Prop,
    always,
    conj,
    disj,
    dist,
    eventually,
    implies,
    neg,
    nxt,
    release,
    until,
)
from mitld_lp.testing.hypothesis import dist_specs, formulas, identifiers

p, q, r, s = Prop("p"), Prop("q"), Prop("r"), Prop("s")

PAPER = "(D[mu1] b1 & F(b1 & F[0,3] A)) | (D[mu2] b2 & F(b2 & F[0,3] B))"


# --------------------------------------------------------------------------- round trip


@given(formulas(max_depth=5, max_bound=6))
def test_round_trip(f: Formula) -> None:
    assert parse(str(f)) == f


@given(formulas(max_depth=4, with_dist=True))
def test_round_trip_with_distributions(f: Formula) -> None:
    assert parse(str(f)) == f


@given(
    st.lists(identifiers(), min_size=1, max_size=4, unique=True).flatmap(
        lambda names: formulas(props=names, max_depth=4)
    )
)
def test_round_trip_with_keyword_like_names(f: Formula) -> None:
    assert parse(str(f)) == f


@given(formulas(max_depth=4, co_safe=True))
def test_nnf_round_trips(f: Formula) -> None:
    g = nnf(f)
    assert parse(str(g)) == g


@given(dist_specs())
def test_distribution_round_trip(mu: DistSpec) -> None:
    assert parse_distribution(str(mu)) == mu
    assert parse(f"D[{mu}] a") == dist(mu, Prop("a"))


def test_paper_formula() -> None:
    b1, b2, a, b = Prop("b1"), Prop("b2"), Prop("A"), Prop("B")
    expected = disj(
        conj(dist(DistRef("mu1"), b1), eventually(conj(b1, eventually(a, (0, 3))))),
        conj(dist(DistRef("mu2"), b2), eventually(conj(b2, eventually(b, (0, 3))))),
    )
    assert parse(PAPER) == expected
    assert parse(str(expected)) == expected


# --------------------------------------------------------------------------- precedence


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("p | q & r", disj(p, conj(q, r))),
        ("p & q | r", disj(conj(p, q), r)),
        ("p & q U r", conj(p, until(q, r))),
        ("p U q & r", conj(until(p, q), r)),
        ("!p U q", until(neg(p), q)),
        ("!(p U q)", neg(until(p, q))),
        ("F p U q", until(eventually(p), q)),
        ("X p U q", until(nxt(p), q)),
        ("p U q U r", until(p, until(q, r))),
        ("p R q U r", release(p, until(q, r))),
        ("(p U q) U r", until(until(p, q), r)),
        ("p -> q | r", implies(p, disj(q, r))),
        ("p | q -> r", implies(disj(p, q), r)),
        ("p -> q -> r", implies(p, implies(q, r))),
        ("(p -> q) -> r", implies(implies(p, q), r)),
        ("p & q & r", conj(p, q, r)),
        ("p & (q & r)", conj(p, q, r)),
        ("!!p", p),
        ("!X p", neg(nxt(p))),
        ("X !p", nxt(neg(p))),
        ("F G[0,2] p", eventually(always(p, (0, 2)))),
        ("G[0,2] F p", always(eventually(p), (0, 2))),
        ("p & true", p),
        ("p | true", TRUE),
        ("false -> p", TRUE),
        ("D[mu] a & b", conj(dist(DistRef("mu"), Prop("a")), Prop("b"))),
        ("p\n&\nq", conj(p, q)),
        ("  p  ", p),
    ],
)
def test_precedence(text: str, expected: Formula) -> None:
    assert parse(text) == expected


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("F[0,3] p", eventually(p, (0, 3))),
        ("F<=3 p", eventually(p, (0, 3))),
        ("F <= 3 p", eventually(p, (0, 3))),
        ("G<=2 p", always(p, (0, 2))),
        ("G p", always(p)),
        ("p U<=4 q", until(p, q, (0, 4))),
        ("p U[2,5] q", until(p, q, (2, 5))),
        ("p U [ 2 , 5 ] q", until(p, q, (2, 5))),
        ("p R q", release(p, q)),
        ("p R[1,2] q", release(p, q, (1, 2))),
        ("p R<=2 q", release(p, q, (0, 2))),
        ("false R[0,2] p", release(FALSE, p, (0, 2))),
        ("F[3,3] p", eventually(p, (3, 3))),
        ("F[0,12345678901234567890] p", eventually(p, (0, 12345678901234567890))),
    ],
)
def test_intervals(text: str, expected: Formula) -> None:
    assert parse(text) == expected


# --------------------------------------------------------------------------- keywords


@pytest.mark.parametrize(
    "name", "F1 Fx Xp X1 G_a U1 Up R2 D1 Dx true_ falsey trueX _F FG A b1".split()
)
def test_keyword_like_identifiers_are_propositions(name: str) -> None:
    assert parse(name) == Prop(name)
    assert parse(f"F {name}") == eventually(Prop(name))
    assert parse(f"{name} U {name}2") == until(Prop(name), Prop(name + "2"))


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("F(p)", eventually(p)),
        ("F (p)", eventually(p)),
        ("X(p)", nxt(p)),
        ("G(p)", always(p)),
        ("!(p)", neg(p)),
        ("X!p", nxt(neg(p))),
        ("F!p", eventually(neg(p))),
        ("F[0,3](p)", eventually(p, (0, 3))),
        ("F[0,3]p", eventually(p, (0, 3))),
        ("D[mu](a)", dist(DistRef("mu"), Prop("a"))),
        ("(p)U(q)", until(p, q)),
        ("p&q|r", disj(conj(p, q), r)),
        ("p->q", implies(p, q)),
        ("FFp", Prop("FFp")),
        ("F F p", eventually(eventually(p))),
        ("XXp", Prop("XXp")),
        ("X X p", nxt(nxt(p))),
    ],
)
def test_operators_next_to_brackets_and_identifiers(text: str, expected: Formula) -> None:
    assert parse(text) == expected


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("¬p ∧ q ∨ r → ◇s", implies(disj(conj(neg(p), q), r), eventually(s))),
        ("□[0,2] p", always(p, (0, 2))),
        ("◇[1,4] p", eventually(p, (1, 4))),
        ("◇≤3 p", eventually(p, (0, 3))),
        ("p 𝒰 q", until(p, q)),
        ("p 𝒰[1,2] q", until(p, q, (1, 2))),
        ("⊤", TRUE),
        ("⊥", FALSE),
        ("~p", neg(p)),
        ("p && q || r", disj(conj(p, q), r)),
        ("□p", always(p)),
    ],
)
def test_unicode_and_ascii_synonyms(text: str, expected: Formula) -> None:
    assert parse(text) == expected


# --------------------------------------------------------------------------- distributions


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("mu1", DistRef("mu1")),
        (" mu ", DistRef("mu")),
        ("geometric(0.3)", DistLiteral("geometric", (0.3,))),
        ("geometric(1)", DistLiteral("geometric", (1,))),
        ("geometric(1e-3)", DistLiteral("geometric", (0.001,))),
        ("poisson(2.5E+2)", DistLiteral("poisson", (250.0,))),
        ("geometric(.5)", DistLiteral("geometric", (0.5,))),
        ("pmf(0.1, 0.3, 0.6)", DistLiteral("pmf", (0.1, 0.3, 0.6))),
        ("pmf(0, 1)", DistLiteral("pmf", (0, 1))),
        ("poisson(2.5)", DistLiteral("poisson", (2.5,))),
        ("uniform(1, 6)", DistLiteral("uniform", (1, 6))),
        ("exponential(0.5)", DistLiteral("exponential", (0.5,))),
        ("weibull(1.5, 3)", DistLiteral("weibull", (1.5, 3))),
        ("gamma(2, 0.5)", DistLiteral("gamma", (2, 0.5))),
        ("scipy(nbinom, 3, 0.5)", DistLiteral("scipy", ("nbinom", 3, 0.5))),
        ("scipy(expon)", DistLiteral("scipy", ("expon",))),
    ],
)
def test_distribution_literals(text: str, expected: DistSpec) -> None:
    got = parse_distribution(text)
    assert got == expected
    if isinstance(got, DistLiteral) and isinstance(expected, DistLiteral):
        assert [_kind(a) for a in got.args] == [_kind(a) for a in expected.args]
    assert parse(f"D[{text}] a") == dist(expected, Prop("a"))


def _kind(a: object) -> type:
    """int, float (a decimal read from text is a float that keeps its text), str."""
    return float if isinstance(a, float) else type(a)


def test_ints_and_floats_keep_their_type() -> None:
    mu = parse_distribution("pmf(0, 0.0, 1e0)")
    assert isinstance(mu, DistLiteral)
    assert [_kind(a) for a in mu.args] == [int, float, float]
    # a decimal keeps the text it was written as (an exact answer reads it)
    assert [getattr(a, "text", None) for a in mu.args] == [None, "0.0", "1e0"]
    assert str(mu) == "pmf(0, 0.0, 1.0)"


# --------------------------------------------------------------------------- errors

# (input, line, column): the columns are counted by hand (1-based, a tab is one column).
MALFORMED = [
    ("", 1, 1),
    ("   ", 1, 4),
    ("p &", 1, 4),
    ("p & )", 1, 5),
    ("(p", 1, 3),
    ("((p)", 1, 5),
    ("p)", 1, 2),
    ("p q", 1, 3),
    ("true false", 1, 6),
    ("p & & q", 1, 5),
    ("p ∧∧ q", 1, 4),
    ("!", 1, 2),
    ("X", 1, 2),
    ("F", 1, 2),
    ("p -> ", 1, 6),
    ("p U[1,2]", 1, 9),
    ("F[3,1] p", 1, 2),
    ("p U[5,2] q", 1, 4),
    ("p & q\n  | F[4,2] r", 2, 6),
    ("F[0,] p", 1, 5),
    ("F[-1,3] p", 1, 3),
    ("F[0,3 p", 1, 7),
    ("F[a,3] p", 1, 3),
    ("F[0.5,3] p", 1, 3),
    ("p U[1,2,3] q", 1, 8),
    ("G<= p", 1, 5),
    ("p <= q", 1, 3),
    ("p - q", 1, 3),
    ("2", 1, 1),
    ("p $ q", 1, 3),
    ("p\t&\t#", 1, 5),
    ("p é", 1, 3),
    ("𝒰", 1, 1),
    ("F[0,3] [p]", 1, 8),
    ("D a", 1, 3),
    ("D[] a", 1, 3),
    ("D[mu a", 1, 6),
    ("D[mu]", 1, 6),
    ("D[foo(1)] a", 1, 3),
    ("D[geometric()] a", 1, 3),
    ("D[geometric(0.1, 0.2)] a", 1, 3),
    ("D[uniform(1)] a", 1, 3),
    ("D[uniform(1, 2.5)] a", 1, 14),
    ("D[scipy(3, 4)] a", 1, 9),
    ("D[pmf()] a", 1, 3),
    ("D[pmf(0.1,)] a", 1, 11),
    ("D[weibull(1, x)] a", 1, 14),
    ("D[pmf(0.1 0.2)] a", 1, 11),
    ("p\n&\n(q | )", 3, 6),
    ("F[2,1]", 1, 7),
]


@pytest.mark.parametrize(("text", "line", "column"), MALFORMED)
def test_malformed_input_reports_position(text: str, line: int, column: int) -> None:
    with pytest.raises(ParseError) as info:
        parse(text)
    err = info.value
    assert (err.line, err.column) == (line, column), str(err)
    assert str(err).startswith(f"{line}:{column}: ")
    assert "\n" not in str(err)
    assert isinstance(err, ValueError)


def test_error_messages_name_token_and_expectation() -> None:
    with pytest.raises(ParseError) as info:
        parse("p & (q | )")
    err = info.value
    assert str(err) == "1:10: unexpected ')'; expected a formula"
    assert err.text == ")"
    assert err.expected == ("a formula",)
    assert err.context() == "p & (q | )\n         ^"

    with pytest.raises(ParseError) as info:
        parse("(p")
    assert info.value.expected == ("')'",)
    assert "end of input" in str(info.value)

    with pytest.raises(ParseError, match=r"1:2: empty interval \[3,1\]"):
        parse("F[3,1] p")
    with pytest.raises(ParseError, match="unknown distribution family 'foo'"):
        parse("D[foo(1)] a")
    with pytest.raises(ParseError, match="geometric takes 1 number"):
        parse("D[geometric(1, 2)] a")


def test_parse_distribution_errors() -> None:
    with pytest.raises(ParseError) as info:
        parse_distribution("geometric(0.3) x")
    assert (info.value.line, info.value.column) == (1, 16)
    with pytest.raises(ParseError):
        parse_distribution("")
    with pytest.raises(ParseError):
        parse_distribution("uniform(1.5, 2)")


def test_deep_nesting_is_a_parse_error_not_a_crash() -> None:
    assert parse("X " * (MAX_DEPTH - 1) + "p") is not None
    for text in [
        "X " * 5000 + "p",
        "!" * 3 + "X " * 5000 + "p & q",
        "(" * 5000 + "p" + ")" * 4999,
        "F[0,1] (" * 3000 + "p" + ")" * 3000,
        "p U (" * 3000 + "q" + ")" * 3000,
    ]:
        with pytest.raises(ParseError):
            parse(text)
    assert parse("(" * 5000 + "p" + ")" * 5000) == p  # parentheses alone add no depth
    assert parse("!" * 5001 + "p") == neg(p)


def test_numbers_out_of_range() -> None:
    with pytest.raises(ParseError, match="integer too long") as info:
        parse("F[0," + "9" * 5000 + "] p")
    assert (info.value.line, info.value.column) == (1, 5)
    with pytest.raises(ParseError, match="integer too long"):
        parse("D[pmf(" + "7" * 5000 + ")] a")
    with pytest.raises(ParseError, match="out of range") as info:
        parse("D[geometric(1e999)] a")
    assert (info.value.line, info.value.column) == (1, 13)


def test_errors_pickle() -> None:
    with pytest.raises(ParseError) as info:
        parse("p &")
    again = pickle.loads(pickle.dumps(info.value))
    assert isinstance(again, ParseError)
    assert (again.line, again.column, str(again)) == (1, 4, str(info.value))
    assert again.context() == info.value.context()


def test_non_string_input_is_a_type_error() -> None:
    with pytest.raises(TypeError):
        parse(None)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- fuzzing

TOKENS = (
    "p q F1 Xp true false ! & | -> U R X F G D ( ) [ ] , <= 0 3 1.5 - mu geometric pmf "
    "uniform scipy ¬ ◇ □ 𝒰 ⊤ && || ~ [0,3] [3,1] [mu] (0.3) 1e5 #"
).split() + ["\n", " "]


def _parse_or_parse_error(text: str) -> None:
    try:
        f = parse(text)
    except ParseError as err:
        assert err.line >= 1 and err.column >= 1
        assert str(err).startswith(f"{err.line}:{err.column}: ")
        return
    assert parse(str(f)) == f


@settings(max_examples=300)
@given(st.text(max_size=40))
def test_garbage_text_only_raises_parse_error(text: str) -> None:
    _parse_or_parse_error(text)


@settings(max_examples=500)
@given(st.lists(st.sampled_from(TOKENS), max_size=25), st.sampled_from([" ", ""]))
def test_token_soup_only_raises_parse_error(tokens: list[str], sep: str) -> None:
    _parse_or_parse_error(sep.join(tokens))


@settings(max_examples=200)
@given(st.lists(st.sampled_from(TOKENS), max_size=15))
def test_distribution_soup_only_raises_parse_error(tokens: list[str]) -> None:
    try:
        parse_distribution(" ".join(tokens))
    except ParseError:
        pass


# --------------------------------------------------------------------------- source


def test_parse_source_keeps_the_laws_the_simplification_drops() -> None:
    from mitld_lp.logic.parser import parse_source

    text = "(D[mu] e & false) |\n  !(F(e & A) -> D[nu] x)"
    src = parse_source(text)
    assert src.formula == parse(text)
    assert [(str(s.dist), s.positive, s.negation, s.line, s.column) for s in src.laws] == [
        ("D[mu] e", True, None, 1, 2),
        ("D[nu] x", False, "!(F(e & A) -> D[nu] x)", 2, 17),
    ]
    # where each subformula is first written (1-based line and column)
    assert src.position(parse("F(e & A)")) == (2, 5)
    assert src.position(parse("e & A")) == (2, 7)
    assert src.position(parse("A")) == (2, 11)
    assert src.position(parse("q")) is None


def test_parse_source_refuses_a_deep_operand_the_simplification_drops() -> None:
    from mitld_lp.logic.parser import parse_source

    deep = "X " * (MAX_DEPTH + 5) + "p"
    with pytest.raises(ParseError, match="nested too deeply"):
        parse_source(f"(D[mu] ({deep}) & false) | q")


# --------------------------------------------------------------------------- weak until


def test_weak_until_is_a_release_and_prints_back() -> None:
    from mitld_lp.logic.syntax import weak

    h, goal = Prop("h"), Prop("goal")
    assert parse("!h W goal") == release(goal, disj(neg(h), goal))
    assert str(parse("!h W goal")) == "!h W goal"
    assert parse("p W q W r") == weak(p, weak(q, r))  # right-associative like U and R
    assert parse("p & q W r | s") == disj(conj(p, weak(q, r)), s)
    assert parse("F p W q") == weak(eventually(p), q)  # unary binds tighter
    assert str(parse("(p | q) W r")) == "(p | q) W r"
    assert str(parse("p W p")) == "p W p"
    # the same node written as a release prints as W, and the operand order is kept
    assert str(parse("r R (p | r)")) == "p W r"
    assert str(parse("r R (r | p)")) == "r R (r | p)"


@given(formulas(max_depth=3), formulas(max_depth=3))
def test_weak_until_round_trips(a: Formula, b: Formula) -> None:
    from mitld_lp.logic.syntax import weak

    f = weak(a, b)
    assert parse(str(f)) == f
    g = disj(p, weak(a, b), q)
    assert parse(str(g)) == g


@pytest.mark.parametrize("text", ["p W[0,3] q", "p W<=3 q"])
def test_weak_until_takes_no_interval(text: str) -> None:
    with pytest.raises(ParseError, match=r"^1:4: .*the weak until W takes no interval"):
        parse(text)
