"""The supported fragment: NNF, events and their distributions, co-safety, horizon, check."""

from __future__ import annotations

import pickle

import pytest
from hypothesis import given
from hypothesis import strategies as st

from mitld_lp.hypothesis import formulas, traces
from mitld_lp.logic.fragment import (
    FragmentError,
    FragmentReport,
    check,
    event_distributions,
    horizon,
    is_co_safe,
    nnf,
)
from mitld_lp.logic.parser import parse
from mitld_lp.logic.semantics import Verdict, holds
from mitld_lp.logic.syntax import (
    FALSE,
    And,
    Dist,
    DistLiteral,
    DistRef,
    Formula,
    Interval,
    Next,
    Not,
    Or,
    Prop,
    Release,
    Until,
    subformulas,
)

PAPER = "(D[mu1] b1 & F(b1 & F[0,3] A)) | (D[mu2] b2 & F(b2 & F[0,3] B))"
p, q = Prop("p"), Prop("q")


# --------------------------------------------------------------------------- NNF


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("!(p & q)", "!p | !q"),
        ("!(p | q)", "!p & !q"),
        ("!(p -> q)", "p & !q"),
        ("!(p U[1,3] q)", "!p R[1,3] !q"),
        ("!(p R q)", "!p U !q"),
        ("!(p R[0,2] !q)", "!p U[0,2] q"),
        ("G[0,3] p", "false R[0,3] p"),
        ("!G[1,2] p", "F[1,2] !p"),
        ("!F[0,2] p", "false R[0,2] !p"),
        ("!X p", "X !p"),
        ("!X (p & X !q)", "X (!p | X q)"),
        ("!(D[mu] a | p)", None),
        ("D[mu] a & !p", "D[mu] a & !p"),
        ("!true", "false"),
    ],
)
def test_nnf_by_hand(text: str, expected: str | None) -> None:
    f = parse(text)
    if expected is None:
        with pytest.raises(FragmentError, match="D\\[mu\\] a"):
            nnf(f)
    else:
        assert nnf(f) == parse(expected)


def _is_nnf(f: Formula) -> bool:
    return all(not isinstance(g, Not) or isinstance(g.arg, Prop) for g in subformulas(f))


@given(formulas(max_depth=5, max_bound=4))
def test_nnf_shape_and_idempotence(f: Formula) -> None:
    g = nnf(f)
    assert _is_nnf(g)
    assert nnf(g) == g


@given(formulas(max_depth=4, max_bound=4), traces(min_len=0, max_len=10))
def test_nnf_keeps_the_verdict(f: Formula, w: tuple[frozenset[str], ...]) -> None:
    g = nnf(f)
    for t in range(len(w) + 2):
        assert holds(g, w, t) == holds(f, w, t)


# --------------------------------------------------------------------------- events


def test_paper_events() -> None:
    assert event_distributions(parse(PAPER)) == {"b1": DistRef("mu1"), "b2": DistRef("mu2")}


@pytest.mark.parametrize(
    ("text", "events"),
    [
        ("p", {}),
        ("D[geometric(0.3)] a & F a", {"a": DistLiteral("geometric", (0.3,))}),
        ("D[mu] a & X D[mu] a", {"a": DistRef("mu")}),
        ("D[mu] a | D[nu] b", {"a": DistRef("mu"), "b": DistRef("nu")}),
        ("G[0,3] D[mu] a", {"a": DistRef("mu")}),
        ("!!D[mu] a", {"a": DistRef("mu")}),
        ("p -> D[mu] a", {"a": DistRef("mu")}),
        ("!(D[mu] a -> p)", {"a": DistRef("mu")}),
        ("p U D[mu] a", {"a": DistRef("mu")}),
    ],
)
def test_events(text: str, events: dict) -> None:
    assert event_distributions(parse(text)) == events


@pytest.mark.parametrize(
    ("text", "named", "why"),
    [
        ("!D[mu] a", "!D[mu] a", "under negation"),
        ("D[mu] a -> p", "!D[mu] a", "under negation"),
        ("!(p | D[mu] a)", "D[mu] a", "under negation"),
        ("!(p U D[mu] a)", "D[mu] a", "under negation"),
        ("G[0,2] !D[mu] a", "D[mu] a", "under negation (in !F[0,2] D[mu] a)"),
        ("!(p | D[mu] a)", "D[mu] a", "under negation (in !(p | D[mu] a))"),
        ("D[mu] (a & b)", "D[mu] (a & b)", "directly to an event"),
        ("D[mu] X a", "D[mu] X a", "directly to an event"),
        ("D[mu] D[mu] a", "D[mu] D[mu] a", "directly to an event"),
        ("D[mu] a & D[nu] a", "D[", "already has the distribution"),
        ("D[pmf(0.5)] a | D[pmf(0.6)] a", "D[pmf(0.", "already has the distribution"),
    ],
)
def test_event_errors(text: str, named: str, why: str) -> None:
    with pytest.raises(FragmentError) as info:
        event_distributions(parse(text))
    assert str(info.value).startswith(named)
    assert why in str(info.value)
    with pytest.raises(FragmentError):
        check(parse(text))


@given(formulas(max_depth=4, with_dist=True))
def test_generated_distributions_are_accepted(f: Formula) -> None:
    found = event_distributions(f)
    for g in subformulas(f):
        if isinstance(g, Dist):
            assert isinstance(g.arg, Prop) and found[g.arg.name] == g.mu


# --------------------------------------------------------------------------- co-safety


@pytest.mark.parametrize(
    ("text", "co_safe"),
    [
        ("p", True),
        ("F p", True),
        ("p U q", True),
        ("G[0,5] p", True),
        ("p R[1,3] q", True),
        ("!(p U[0,4] q)", True),
        ("!G p", True),
        ("D[mu] a", True),
        ("G p", False),
        ("p R q", False),
        ("!(p U q)", False),
        ("!F p", False),
        ("F G p", False),
        ("!D[mu] a", False),
        ("X G p", False),
        ("!(!p R q)", True),
        ("G p -> q", True),
        ("q -> G p", False),
        ("G[0,3] F p", True),
        ("F[0,3] G p", False),
    ],
)
def test_is_co_safe(text: str, co_safe: bool) -> None:
    assert is_co_safe(parse(text)) is co_safe


@given(formulas(max_depth=5, co_safe=True))
def test_co_safe_strategy_yields_co_safe_formulas(f: Formula) -> None:
    assert is_co_safe(f)
    unbounded_release = [
        g for g in subformulas(nnf(f)) if isinstance(g, Release) and g.interval is None
    ]
    assert unbounded_release == []


@pytest.mark.parametrize(
    ("text", "named"),
    [
        ("G p", "G p is not co-safe"),
        ("p & (q R p)", "q R p is not co-safe"),
        ("!(p U q) | q", "!(p U q) is not co-safe"),
        ("!(r & p U q)", "p U q is not co-safe: under negation (in !(r & p U q)) it is an"),
        ("F G p", "G p is not co-safe"),
    ],
)
def test_check_names_the_non_co_safe_subformula(text: str, named: str) -> None:
    with pytest.raises(FragmentError) as info:
        check(parse(text))
    assert str(info.value).startswith(named)
    assert "finite prefix" in str(info.value)


# --------------------------------------------------------------------------- horizon


@pytest.mark.parametrize(
    ("text", "h"),
    [
        ("p", 0),
        ("true", 0),
        ("X p", 1),
        ("X X p", 2),
        ("p & X X q", 2),
        ("!X p", 1),
        ("F[0,3] p", 3),
        ("F[2,5] X p", 6),
        ("G[1,2] X p", 3),
        ("F[0,2] F[1,3] p", 5),
        ("p U[1,4] X X q", 6),  # max(4 + 2, 3 + 0)
        ("X p U[0,2] q", 2),  # max(2 + 0, 1 + 1)
        ("X X X p U[0,2] q", 4),  # max(2 + 0, 1 + 3)
        ("p U[0,0] X X q", 2),
        ("X X p U[0,0] q", 0),  # the left operand is never read
        ("X X p R[0,0] q", 0),
        ("p R[2,3] q", 3),
        ("F p", None),
        ("p U q", None),
        ("D[mu] a", None),
        ("F[0,3] p & G p", None),
        ("X F p", None),
    ],
)
def test_horizon_by_hand(text: str, h: int | None) -> None:
    assert horizon(parse(text)) == h


@st.composite
def _bounded_with_two_traces(draw: st.DrawFn):
    """A bounded formula and two traces that agree on the steps 0..horizon and differ
    (randomly) after."""
    f = draw(formulas(max_depth=4, max_bound=4).filter(lambda g: horizon(g) is not None))
    h = horizon(f)
    assert h is not None
    common = draw(traces(min_len=h + 1, max_len=h + 1))
    tail1 = draw(traces(max_len=5))
    tail2 = draw(traces(max_len=5))
    return f, common + tail1, common + tail2


@given(_bounded_with_two_traces())
def test_horizon_steps_decide_the_formula(case) -> None:
    f, w1, w2 = case
    v = holds(f, w1)
    assert v is not Verdict.UNKNOWN
    assert holds(f, w2) == v


# --------------------------------------------------------------------------- check


def test_check_report() -> None:
    f = parse(PAPER)
    report = check(f)
    assert isinstance(report, FragmentReport)
    assert report.formula is f
    assert report.nnf == f
    assert report.events == (("b1", DistRef("mu1")), ("b2", DistRef("mu2")))
    assert report.co_safe is True
    assert report.horizon is None
    with pytest.raises(AttributeError):
        report.horizon = 3  # type: ignore[misc]


def test_check_bounded() -> None:
    report = check(parse("G[0,3] (p -> X q)"))
    expected_nnf = Release(FALSE, Or((Not(p), Next(q))), Interval(0, 3))
    assert report.nnf == expected_nnf
    assert report.horizon == 4
    assert report.events == ()


def test_check_until_with_lower_bound() -> None:
    report = check(parse("!(p U[2,4] q)"))
    assert report.nnf == Release(Not(p), Not(q), Interval(2, 4))
    assert report.horizon == 4
    assert isinstance(parse("p U[2,4] q"), Until)
    assert isinstance(parse("p & q"), And)


def test_fragment_error_pickles() -> None:
    with pytest.raises(FragmentError) as info:
        check(parse("G p"))
    again = pickle.loads(pickle.dumps(info.value))
    assert str(again) == str(info.value)
    assert again.subformula == info.value.subformula
