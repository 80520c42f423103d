"""The supported fragment: NNF, events and their distributions, co-safety, horizon, check."""

from __future__ import annotations

import pickle

import pytest
from hypothesis import given
from hypothesis import strategies as st

from mitld_lp.logic.fragment import (
    CO_SAFE,
    OBLIGATION,
    PERSISTENCE,
    REACTIVITY,
    RECURRENCE,
    SAFETY,
    SUPPORTED,
    FragmentError,
    FragmentReport,
    check,
    classify,
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
from mitld_lp.testing.hypothesis import formulas, traces

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
        ("G F p", "1:1: G F p is a recurrence formula"),
        ("p & (q R F p)", "1:6: q R F p is a recurrence formula"),
        ("!(!F p U q) | q", "1:1: !(!F p U q) is a recurrence formula"),
        ("!(r & G p U q)", "1:7: G p U q is under negation a recurrence formula"),
        ("F G p", "1:1: F G p is a persistence formula"),
        ("G F G p", "1:3: F G p is a persistence formula"),  # the innermost nesting
        ("q & (G p) U r", "1:5: G p U r is a persistence formula"),
        ("G F p | F G q", "1:1: G F p is a recurrence formula"),
        ("X\n  (p | G (q -> F r))", "2:8: G (!q | F r) is a recurrence formula"),
    ],
)
def test_check_names_the_subformula_outside_and_its_class(text: str, named: str) -> None:
    with pytest.raises(FragmentError) as info:
        check(text)
    assert str(info.value).startswith(named)
    assert "supported are co-safe, safety and obligation formulas" in str(info.value)
    assert "\n" not in str(info.value)
    # the formula alone (no text) names the same subformula, without a position
    with pytest.raises(FragmentError) as again:
        check(parse(text))
    assert str(again.value) == str(info.value).split(": ", 1)[1]
    assert again.value.line is None


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("p", CO_SAFE),
        ("F[0,3] p & X q", CO_SAFE),
        ("F p", CO_SAFE),
        ("D[mu] a & F(a & F[0,3] b)", CO_SAFE),
        ("!G p", CO_SAFE),
        ("G[0,3] F p", CO_SAFE),
        ("G p", SAFETY),
        ("G !h", SAFETY),
        ("G (p -> F[0,3] q)", SAFETY),
        ("!h W goal", SAFETY),
        ("!(p U q)", SAFETY),
        ("F[0,3] G p", SAFETY),
        ("X G p", SAFETY),
        ("q -> G p", SAFETY),
        ("G p R q", SAFETY),
        ("G !h & F goal", OBLIGATION),
        ("G !h & D[mu] bus & F(bus & F[0,3] stop)", OBLIGATION),
        ("G p | F q", OBLIGATION),
        ("X (G p | F q)", OBLIGATION),
        ("F[0,2] (G p | F q)", OBLIGATION),
        ("(G p | F q) & (G r | F s)", OBLIGATION),
        ("G F p", RECURRENCE),
        ("G (p | F q)", RECURRENCE),
        ("p W F q", RECURRENCE),
        ("!D[mu] a", SAFETY),  # counted by polarity (check refuses it for the negation)
        ("F G p", PERSISTENCE),
        ("G p U q", PERSISTENCE),
        ("p U (q & G r)", PERSISTENCE),
        ("G F p | F G p", REACTIVITY),
        ("G F G p", REACTIVITY),
    ],
)
def test_classify_by_hand(text: str, fragment: str) -> None:
    assert classify(parse(text)) == fragment
    assert is_co_safe(parse(text)) == (fragment == CO_SAFE)
    if fragment in SUPPORTED and "!D" not in text:
        report = check(text)
        assert report.fragment == fragment
        assert report.co_safe == (fragment == CO_SAFE)
    elif "!D" not in text:
        with pytest.raises(FragmentError):
            check(text)


def _unbounded(f: Formula) -> tuple[bool, bool]:
    """Whether the NNF of ``f`` (D read as F) has an unbounded until and an unbounded
    release, by walking it."""
    g = nnf(f)
    ops = [h for h in subformulas(g) if isinstance(h, Until | Release | Dist)]
    until = any(isinstance(h, Dist) or isinstance(h, Until) and h.interval is None for h in ops)
    rel = any(isinstance(h, Release) and h.interval is None for h in ops)
    return until, rel


def _nests(f: Formula) -> bool:
    """Whether in the NNF some unbounded until has an unbounded release below it or the
    other way round."""
    for h in subformulas(nnf(f)):
        if isinstance(h, Until | Release) and h.interval is None:
            below = [x for x in (h.left, h.right) for x in subformulas(x)]
            other = Release if isinstance(h, Until) else Until
            if any(isinstance(x, other) and x.interval is None for x in below):
                return True
    return False


@given(formulas(max_depth=5, max_bound=3))
def test_classify_agrees_with_the_negation_normal_form(f: Formula) -> None:
    fragment = classify(f)
    until, rel = _unbounded(f)
    if _nests(f):
        assert fragment in (PERSISTENCE, RECURRENCE, REACTIVITY)
    else:
        assert fragment == (OBLIGATION if until and rel else SAFETY if rel else CO_SAFE)


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
        check("G F p")
    again = pickle.loads(pickle.dumps(info.value))
    assert str(again) == str(info.value)
    assert again.subformula == info.value.subformula
    assert (again.line, again.column) == (info.value.line, info.value.column) == (1, 1)
